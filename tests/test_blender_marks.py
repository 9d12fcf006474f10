"""Timeline markers where a solve is worth a look (blender/writer.py mark_timeline, the solve's
Mark Problems): made at the right scene frames, replacing only an earlier solve's in its range;
and Solve Several Files, whose takes keep their markers apart."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import writer  # noqa: E402
from blender_manikin.core.formats import load_recording  # noqa: E402
from blender_manikin.core.io_csv import write_csv  # noqa: E402
from blender_manikin.core.recording import Recording, TrackerStream  # noqa: E402
from blender_manikin.core.review_marks import ReviewMark  # noqa: E402


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def test_markers_replace_only_an_earlier_solves_in_range(addon):
    sc = bpy.context.scene
    mine = sc.timeline_markers.new("my cue", frame=20)                  # the animator's own
    old = sc.timeline_markers.new("MANIKIN: left hand out of reach", frame=30)
    far = sc.timeline_markers.new("MANIKIN: teleport", frame=500)       # another take's, elsewhere
    frames = 10.0 + np.arange(100) * 1.25                                # 24 fps scene, 30 fps solve
    made = writer.mark_timeline(sc, [ReviewMark(8, "head lost 1.0 s")], frames)
    names = sorted((m.name, m.frame) for m in sc.timeline_markers)
    assert names == [("MANIKIN: head lost 1.0 s", 20), ("MANIKIN: teleport", 500), ("my cue", 20)]
    assert mine.name == "my cue" and far.frame == 500 and len(made) == 1
    del old


def test_a_solve_marks_a_hand_thrown_out_of_reach(addon, tmp_path):
    """The example with its right controller thrown 1.5 m away for 0.4 s: a marker where it
    leaves the hand's reach; Mark Problems off: none."""
    rec = load_recording(EXAMPLE)
    s = dict(rec.streams)
    r = s["right_hand"]
    pos = r.pos.copy()
    away = (r.time > 3.0) & (r.time < 3.4)
    pos[away] += np.array([1.5, 0.0, 0.0])
    s["right_hand"] = TrackerStream("right_hand", r.time, pos, r.quat, r.valid)
    path = str(tmp_path / "thrown.csv")
    write_csv(path, Recording(streams=s, source="thrown", metadata=dict(rec.metadata)), axes="openxr", units="m")
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    st = sc.manikin
    st.source, st.filepath, st.frame_start = 'FILE', path, 1
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    marks = [(m.name, m.frame) for m in sc.timeline_markers]
    hits = [f for n, f in marks if n == "MANIKIN: right hand out of reach"]
    assert len(hits) == 1 and abs(hits[0] - (1 + 3.0 * 30)) <= 3, marks
    st.mark_problems = False
    for m in list(sc.timeline_markers):
        sc.timeline_markers.remove(m)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert len(sc.timeline_markers) == 0


def test_the_command_line_can_leave_the_markers_out():
    from blender_manikin import cli
    p = cli.build_parser()
    assert cli._config("t.csv", p.parse_args(["solve", "t.csv", "--out", "o"])).mark_problems is True
    assert cli._config("t.csv", p.parse_args(["solve", "t.csv", "--out", "o", "--no-marks"])).mark_problems is False


def test_several_files_are_solved_each_onto_its_own_armature(addon, tmp_path):
    """Solve Several Files: each recording onto MANIKIN_<file> with MANIKIN_live_<file>, markers
    per take, one bad file reported without stopping the others; the scene range covers all."""
    import shutil
    rec = load_recording(EXAMPLE)
    shutil.copy(EXAMPLE, tmp_path / "walk.csv")
    s = dict(rec.streams)
    r = s["right_hand"]
    pos = r.pos.copy()
    pos[(r.time > 3.0) & (r.time < 3.4)] += np.array([1.5, 0.0, 0.0])
    s["right_hand"] = TrackerStream("right_hand", r.time, pos, r.quat, r.valid)
    write_csv(str(tmp_path / "thrown.csv"), Recording(streams=s, source="thrown", metadata=dict(rec.metadata)),
              axes="openxr", units="m")
    (tmp_path / "broken.csv").write_text("time,device,px\n0,head,1\n")
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    sc.timeline_markers.new("MANIKIN: from an earlier solve", frame=10)
    res = bpy.ops.manikin.solve_files(directory=str(tmp_path),
                                      files=[{"name": "walk.csv"}, {"name": "broken.csv"}, {"name": "thrown.csv"}])
    assert res == {'FINISHED'}
    arms = sorted(o.name for o in bpy.data.objects if o.type == 'ARMATURE')
    assert arms == ["MANIKIN_thrown", "MANIKIN_walk"]
    for take in ("walk", "thrown"):
        act = bpy.data.objects[f"MANIKIN_{take}"].animation_data.action
        assert act.name == f"MANIKIN_live_{take}" and act["manikin_source"].endswith(f"{take}.csv")
    report = sc.manikin.last_report
    assert report.startswith("2 of 3 files solved") and "failed: broken.csv, line 1:" in report
    names = {m.name for m in sc.timeline_markers}
    assert "MANIKIN thrown: right hand out of reach" in names and "MANIKIN: from an earlier solve" in names
    assert (sc.frame_start, sc.frame_end) == (1, 210)
    assert not [o for o in bpy.data.objects if o.type == 'EMPTY']      # no tracker empties for a batch
