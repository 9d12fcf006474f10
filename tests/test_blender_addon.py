"""Add-on registration, the solve operator (with a stand-in solver), errors, cancel and undo."""
import os
import threading
import traceback
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import blender_manikin  # noqa: E402
from blender_manikin.blender import keying, solve_job  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import (PanelLayout, fresh_scene, modal_operator, stub_solver, synthetic_result,  # noqa: E402
                          write_recording_csv)


@pytest.fixture
def addon(monkeypatch):
    fresh_scene()
    blender_manikin.register()
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    yield
    blender_manikin.unregister()


@pytest.fixture
def recording(tmp_path):
    res = synthetic_result(T=48, fps=24.0)
    return str(write_recording_csv(tmp_path / "take.csv", res, jitter=0.002, rates={"head": 72.0}))


def _settings(path):
    s = bpy.context.scene.manikin
    s.source = 'FILE'
    s.filepath = path
    s.calibration = 'MEASURE'
    s.height = 1.8
    s.create_trackers = True
    return s


def test_register_unregister_register():
    fresh_scene()
    for _ in range(2):
        blender_manikin.register()
        assert hasattr(bpy.types.Scene, "manikin")
        assert bpy.context.scene.manikin.source == 'FILE'
        for name in ("MANIKIN_OT_solve_full_body", "MANIKIN_OT_find_tpose", "MANIKIN_OT_load_offsets_preset",
                     "MANIKIN_PT_solve", "MANIKIN_PT_calibration", "MANIKIN_PT_output"):
            assert hasattr(bpy.types, name), name
        from blender_manikin.blender.properties import MANIKIN_Settings
        assert MANIKIN_Settings.is_registered
        assert bpy.types.MANIKIN_PT_solve.bl_category == "MANIKIN"
        assert bpy.types.MANIKIN_OT_solve_full_body.bl_options == {'REGISTER', 'UNDO'}
        assert bpy.ops.manikin.solve_full_body.idname() == "MANIKIN_OT_solve_full_body"
        blender_manikin.unregister()
        assert not hasattr(bpy.types.Scene, "manikin")
        assert not hasattr(bpy.types, "MANIKIN_OT_solve_full_body")


def test_unregister_stops_a_modal_solve_and_its_timer(recording, monkeypatch):
    """The add-on disabled while a modal solve runs: Blender frees the operator without its
    cancel(), so unregister stops the worker and removes the window's timer and status text."""
    from blender_manikin.operators import solve as solve_op
    fresh_scene()
    blender_manikin.register()
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    _settings(recording)
    op = modal_operator(solve_op.MANIKIN_OT_solve_full_body)
    queue = op.start_modal()
    removed = []
    solve_op._ACTIVE["leftovers"] = {"timer": removed}         # stands in for the window's timer
    monkeypatch.setattr(solve_op, "abort_active", lambda context, f=solve_op.abort_active: (
        removed.append("aborted"), f(SimpleNamespace(window_manager=_WM(removed), temp_override=None))))
    blender_manikin.unregister()
    assert removed == ["aborted", "timer removed", "progress ended"] and queue.cancelled
    assert solve_op._ACTIVE == {"job": None, "leftovers": None}


class _WM:
    def __init__(self, log):
        self.log, self.windows = log, []

    def event_timer_remove(self, timer):
        self.log.append("timer removed")

    def progress_end(self):
        self.log.append("progress ended")


def test_addon_utils_enable_disable():
    import addon_utils
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(blender_manikin.__file__)))
    assert root in sys.path
    fresh_scene()
    mod = addon_utils.enable("blender_manikin", default_set=False, handle_error=None)
    assert mod is not None and hasattr(bpy.types.Scene, "manikin")
    addon_utils.disable("blender_manikin", default_set=False, handle_error=None)
    assert not hasattr(bpy.types.Scene, "manikin")
    mod = addon_utils.enable("blender_manikin", default_set=False, handle_error=None)
    assert hasattr(bpy.types.Scene, "manikin")
    addon_utils.disable("blender_manikin", default_set=False, handle_error=None)


def test_solve_operator_file(addon, recording):
    s = _settings(recording)
    s.live_rig = False            # plain FK keys; the live rig is checked below
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    obj = s.armature
    assert obj is not None and obj.type == 'ARMATURE'
    act = obj.animation_data.action
    # named after the take, with what was solved on it (the Action editor lists many takes)
    assert act.name == "MANIKIN_solve_take" and act["manikin_source"] == recording
    fcs = keying.action_fcurves(act, obj)
    n = len(fcs[0].keyframe_points)
    assert n == 48 and all(len(fc.keyframe_points) == n for fc in fcs)
    sc = bpy.context.scene
    assert (sc.frame_start, sc.frame_end) == (1, 48)
    assert "swivel_left_arm" in obj.keys()
    assert abs(obj.data.bones["head"].head_local[2] - sk.make_body(1.8).rest_positions()[15, 2]) < 1e-5
    assert set(o.name for o in bpy.data.collections["MANIKIN trackers"].objects) == {
        "MANIKIN_head", "MANIKIN_left_hand", "MANIKIN_right_hand"}
    assert "frames" in s.last_report
    # the head target and the head joint agree (stand-in solver pins the head)
    sc.frame_set(10)
    head = np.array(obj.matrix_world) @ np.append(np.array(obj.pose.bones["head"].head), 1)
    tracker = np.array(bpy.data.objects["MANIKIN_head"].matrix_world)[:3, 3]
    assert np.max(np.abs(head[:3] - tracker)) < 1e-4

    # re-solve: same body -> same armature, new action; the first one is kept intact
    first_action = act
    first_keys = [tuple(kp.co) for fc in fcs for kp in fc.keyframe_points]
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert s.armature == obj and obj.animation_data.action != first_action
    assert first_action.name in bpy.data.actions
    assert first_keys == [tuple(kp.co) for fc in keying.action_fcurves(first_action, None)
                          for kp in fc.keyframe_points]


def test_solve_operator_builds_live_rig_by_default(addon, recording):
    """The live rig (limbs driven by controls + swivel) reproduces the solved FK pose."""
    from blender_manikin.blender import live_rig
    s = _settings(recording)
    assert s.live_rig
    # the raw samples: the stub solver's arms are fully straight, where an elbow on its hinge is
    # most sensitive to the reach, and smoothing this recording's 2 mm jitter moves the reach
    # there by amounts Blender's float32 turns into 0.2 mm at the elbow (core/smoothing.py has
    # its own tests)
    s.smoothing_mode, s.smoothing = 'WINDOW', 0.0
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    obj = s.armature
    live_action = obj.animation_data.action
    assert live_action.name == "MANIKIN_live_take" and live_rig.is_live_rig(obj)
    assert live_action["manikin_source"] == recording
    # the live rig's action is the only one keyed (Bake makes plain FK keys when wanted)
    assert [a.name for a in bpy.data.actions if a.name.startswith(("MANIKIN_solve", "MANIKIN_live"))] == \
        [live_action.name]
    sc = bpy.context.scene
    names = ["left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_knee", "left_ankle"]

    def joints(frames):
        out = []
        for f in frames:
            sc.frame_set(f)
            mw = np.array(obj.matrix_world)
            out.append([(mw @ np.append(np.array(obj.pose.bones[n].head), 1))[:3] for n in names])
        return np.array(out)

    frames = (5, 20, 40)
    live = joints(frames)
    # the same solve as plain FK keys (re-solved onto the same armature: the rig is switched off)
    s.live_rig = False
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert s.armature == obj and obj.animation_data.action.name.startswith("MANIKIN_solve")
    fk = joints(frames)
    assert np.max(np.abs(live - fk)) < 1e-4


def test_errors_are_reported(addon, tmp_path):
    s = _settings(str(tmp_path / "missing.csv"))
    n = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="missing.csv: no such file"):
        bpy.ops.manikin.solve_full_body()
    bad = tmp_path / "bad.csv"
    bad.write_text("time,device,px\n0,head,1\n")
    s.filepath = str(bad)
    with pytest.raises(RuntimeError, match="bad.csv"):
        bpy.ops.manikin.solve_full_body()
    s.filepath = ""
    with pytest.raises(RuntimeError, match="no recording file"):
        bpy.ops.manikin.solve_full_body()
    assert len(bpy.data.objects) == n
    # the panel's box says the solve failed, and why (not the summary of the solve before)
    assert s.last_report.startswith("Solve failed: ") and "no recording file" in s.last_report


def test_the_summary_box_shows_one_item_a_line():
    from blender_manikin.panels.main import report_items
    assert report_items("210 frames at 30 fps; model head and hands (manikin_s.onnx); offsets openxr_generic "
                        "(auto: from the file; checked); stature 1.75 m") == [
        "210 frames at 30 fps", "model head and hands (manikin_s.onnx)",
        "offsets openxr_generic (auto: from the file; checked)", "stature 1.75 m"]
    assert report_items("Solve failed: no such file") == ["Solve failed: no such file"]


def test_undo_restores_scene(addon, recording):
    _settings(recording)
    bpy.ops.ed.undo_push(message="before solve")
    names = sorted(o.name for o in bpy.data.objects)
    n_act = len(bpy.data.actions)
    # called from Python an operator pushes its undo step only when asked (2nd argument),
    # as the UI does for operators with bl_options UNDO
    assert bpy.ops.manikin.solve_full_body('EXEC_DEFAULT', True) == {'FINISHED'}
    assert len(bpy.data.objects) > len(names)
    bpy.ops.ed.undo()
    assert sorted(o.name for o in bpy.data.objects) == names
    assert len(bpy.data.actions) == n_act
    assert bpy.context.scene.manikin.armature is None
    bpy.ops.ed.redo()
    assert any(o.type == 'ARMATURE' for o in bpy.data.objects)


def test_cancel_leaves_nothing(addon, recording, monkeypatch):
    """The modal path: compute in a worker thread, cancel while it runs, nothing written."""
    started, release = threading.Event(), threading.Event()

    def slow_solver(targets, body, progress=None):
        started.set()
        release.wait(5)
        progress(0.5)               # raises SolveCancelled after cancel()
        return stub_solver(targets, body, progress)

    monkeypatch.setattr(solve_job, "run_solver", slow_solver)
    _settings(recording)
    from blender_manikin.blender.properties import config_from_settings
    before = (len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures))
    job = solve_job.SolveJob(config_from_settings(bpy.context))
    job.gather(bpy.context)
    job.start_background()
    assert started.wait(5)
    assert 0.0 < job.progress < 1.0
    job.cancel()
    release.set()
    job.join(5)
    assert job.done and isinstance(job.error, solve_job.SolveCancelled)
    with pytest.raises(solve_job.SolveCancelled):
        job.write(bpy.context)
    assert (len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures)) == before


def _reader_test_file(kind, tmp_path):
    """A small file of ``kind`` (wide CSV, JSON frames, keypoint CSV, native CSV) and its source."""
    import json
    from blender_manikin.core import rotations as rot
    from fixtures_keypoints import hinge_motion, write_layout_csv
    from fixtures_recordings import write_wide_poses
    if kind == "keypoint_csv":
        body, pos, world = hinge_motion(frames=60)
        write_layout_csv(tmp_path / "kp.csv", "halpe26", body, pos, world)
        return str(tmp_path / "kp.csv"), "KEYPOINTS"
    res = synthetic_result(T=48, fps=24.0)
    if kind == "native_csv":
        return str(write_recording_csv(tmp_path / "take.csv", res)), "FILE"
    t = res.t0 + np.arange(res.num_frames) / res.fps
    quat = {d: rot.matrix_to_quat(res.targets.rot[d]) for d in res.targets.devices}
    if kind == "wide_csv":
        return str(write_wide_poses(tmp_path / "wide.csv", t, res.targets.pos, quat,
                                    {d: d for d in res.targets.devices}, axes="blender")), "FILE"
    frames = [{"time": float(t[k]), **{d: {"position": res.targets.pos[d][k].tolist(),
                                           "rotation": [*quat[d][k, 1:].tolist(), float(quat[d][k, 0])]}
                                       for d in res.targets.devices}} for k in range(len(t))]
    (tmp_path / "frames.json").write_text(json.dumps({"frames": frames}, indent=1))
    return str(tmp_path / "frames.json"), "FILE"


@pytest.mark.parametrize("kind,reader", [("wide_csv", "io_wide_csv"), ("native_csv", "io_csv"),
                                         ("json", "io_json"), ("keypoint_csv", "io_keypoints")])
def test_cancel_stops_the_read(addon, tmp_path, monkeypatch, kind, reader):
    """Esc while a file is read (not solved): the reader checks the job's cancel between chunks
    of rows, so the read stops there, inside the reader, and nothing is kept."""
    from blender_manikin.core import io_csv, recording as rec
    monkeypatch.setattr(rec, "CHECK_ROWS", 8)              # a small file read in several chunks
    monkeypatch.setattr(io_csv, "BLOCK_BYTES", 512)
    path, source = _reader_test_file(kind, tmp_path)
    job = solve_job.SolveJob(solve_job.SolveConfig(filepath=path, source=source, fps=24.0, calibration="MEASURE",
                                                   height=1.8))
    real, checks = solve_job._check_cancel, []

    def check(flag):                 # the job's cancel check; Esc at the third one made while reading
        if job.stage.startswith("reading"):
            checks.append(job.stage)
            if len(checks) == 3:
                job.cancel()
        real(flag)
    monkeypatch.setattr(solve_job, "_check_cancel", check)
    with pytest.raises(solve_job.SolveCancelled) as e:
        job.compute()
    assert len(checks) == 3                  # the stage's own check, then two chunks read
    assert any(f.filename.endswith(os.path.join("core", f"{reader}.py")) for f in traceback.extract_tb(e.tb))
    assert job.recording is None and job.result is None


def test_scene_objects_as_trackers(addon):
    """Keyed empties mapped to devices are sampled and solved like a recording."""
    sc = bpy.context.scene
    sc.render.fps = 24
    res = synthetic_result(T=30, fps=24.0)
    from blender_manikin.blender import writer
    src = writer.write_result(res, writer.WriteOptions(create_trackers=True))   # keyed empties
    s = bpy.context.scene.manikin
    s.source = 'SCENE'
    for dev, empty in src.trackers.items():
        getattr(s, dev).object = empty
    s.calibration = 'MEASURE'
    s.height = 1.8
    s.create_trackers = False
    s.use_scene_range = False
    s.frame_start, s.frame_end = 1, 30
    s.reuse_armature = False
    # the sampling must be exact: no filter (Auto would take this synthetic take's 2 Hz swings of
    # every joint for noise and choose a 0.2 s window)
    s.smoothing_mode, s.smoothing = 'WINDOW', 0.0
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    out = s.armature
    assert out != src.armature
    act = out.animation_data.action
    assert act.name.startswith("MANIKIN_live_scene")
    assert act["manikin_source"].startswith("scene objects: head MANIKIN_head")
    sc.frame_set(12)
    head = np.array(out.matrix_world) @ np.append(np.array(out.pose.bones["head"].head), 1)
    np.testing.assert_allclose(head[:3], res.targets.pos["head"][11], atol=1e-4)


def write_tpose_recording(path, lift=0.0):
    """A 3 s recording at 24 fps (a 1.8 m body) holding a clean T-pose on frames 20-50 (arms
    straight out, identity rotations: more than 1 s), every device moved up by ``lift`` metres."""
    res = synthetic_result(T=72, fps=24.0)
    res.local_rot[20:51] = np.eye(3)
    res.root_pos[20:51] = res.body.root_rest
    res._fk = None
    pos, wr = res.fk()
    for dev, j in (("head", "head"), ("left_hand", "left_wrist"), ("right_hand", "right_wrist")):
        res.targets.pos[dev] = pos[:, sk.J[j]] + np.array([0.0, 0.0, lift])
        res.targets.rot[dev] = wr[:, sk.J[j]].copy()
    return write_recording_csv(path, res)


def test_find_tpose_and_offsets_preset(addon, tmp_path):
    path = write_tpose_recording(tmp_path / "tpose.csv")
    s = _settings(str(path))
    s.calibration = 'AUTO'
    assert bpy.ops.manikin.find_tpose() == {'FINISHED'}
    assert s.calibration == 'TPOSE' and 26 / 24 - 1e-6 <= s.tpose_time <= 44 / 24 + 1e-6
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert s.armature["manikin_body"] is not None
    bones = s.armature.data.bones
    assert s.sole == pytest.approx(sk.SOLE)
    stature = (bones["head"].head_local[2] - sk.SOLE) / sk.PROPORTIONS["head_height"]
    assert abs(stature - 1.8) < 0.02
    ball = bones["left_foot"].head_local[2]
    assert ball == pytest.approx(sk.PROPORTIONS["foot_height"] * stature + sk.SOLE, abs=1e-4)
    # barefoot: the same head height is a taller body whose feet stand on the floor
    first = s.armature
    s.sole = 0.0
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert s.armature != first and first.name in bpy.data.objects      # a new armature, the old kept
    bones = s.armature.data.bones
    bare = bones["head"].head_local[2] / sk.PROPORTIONS["head_height"]
    assert bare - stature == pytest.approx(sk.SOLE / sk.PROPORTIONS["head_height"], abs=2e-3)
    assert bones["left_foot"].head_local[2] == pytest.approx(sk.PROPORTIONS["foot_height"] * bare, abs=1e-4)
    s.offsets_preset = 'quest_touch'
    assert bpy.ops.manikin.load_offsets_preset() == {'FINISHED'}
    assert s.offsets_text is not None and '"left_hand"' in s.offsets_text.as_string()
    s.offsets_text.clear()
    s.offsets_text.write("{not json")
    with pytest.raises(RuntimeError, match="not valid JSON"):
        bpy.ops.manikin.solve_full_body()


def test_floor_setting_finds_the_tpose_and_stands_the_body_on_the_ground(addon, tmp_path):
    """A T-pose recording whose origin is at eye level (floor at -1.5 m): with the floor left at
    0 the solve finds it under the performer its T-pose's arm span gives; the Floor setting (At
    Height, Under Performer) reaches the solve and the T-pose finder, and the armature stands on
    Blender's ground."""
    from blender_manikin.panels import main as panels
    from blender_manikin.blender.properties import config_from_settings
    from types import SimpleNamespace
    s = _settings(str(write_tpose_recording(tmp_path / "eyes.csv", lift=-1.5)))
    s.calibration = 'AUTO'
    assert s.floor_mode == 'ZERO' and config_from_settings(bpy.context).floor == 0.0
    assert bpy.ops.manikin.find_tpose() == {'FINISHED'}          # Find T-Pose sees the floor the solve finds
    assert s.calibration == 'TPOSE' and 26 / 24 - 1e-6 <= s.tpose_time <= 44 / 24 + 1e-6
    s.calibration = 'AUTO'
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "the recording's origin is at eye level: under a 1.80 m performer, from the T-pose's arm span" \
        in s.last_report
    bones = s.armature.data.bones
    assert abs((bones["head"].head_local[2] - sk.SOLE) / sk.PROPORTIONS["head_height"] - 1.8) < 0.02
    s.floor_mode, s.floor_height = 'OFFSET', -1.5
    assert config_from_settings(bpy.context).floor == -1.5
    assert bpy.ops.manikin.find_tpose() == {'FINISHED'}
    assert s.calibration == 'TPOSE' and 26 / 24 - 1e-6 <= s.tpose_time <= 44 / 24 + 1e-6
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    bones = s.armature.data.bones
    stature = (bones["head"].head_local[2] - sk.SOLE) / sk.PROPORTIONS["head_height"]
    assert abs(stature - 1.8) < 0.02 and "floor at -1.500 m (as set) moved to 0" in s.last_report
    # under the performer: the typed height is used (whatever Override Height says) and places the floor
    s.floor_mode, s.use_height, s.height = 'PERFORMER', False, 1.8
    cfg = config_from_settings(bpy.context)
    assert cfg.floor == "height" and cfg.height == pytest.approx(1.8)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "under the 1.80 m performer" in s.last_report
    # the panel shows the floor's height only when it is typed, and the height when it places the floor
    for mode, shown_props in (('ZERO', ()), ('OFFSET', ("floor_height",)), ('PERFORMER', ("height",))):
        s.floor_mode = mode
        log = []
        panels.MANIKIN_PT_calibration.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
        assert ("prop", "floor_mode") in log
        assert (("prop", "floor_height") in log) == (mode == 'OFFSET')
        for name in shown_props:
            assert ("prop", name) in log
    # keypoints find their floor under the feet: the tracker setting does not reach them
    s.source = 'KEYPOINTS'
    s.floor_mode = 'OFFSET'
    assert config_from_settings(bpy.context).floor == 0.0


def test_panels_draw(addon):
    from blender_manikin.panels import main as panels
    from types import SimpleNamespace
    s = bpy.context.scene.manikin
    arm = bpy.data.objects.new("rig", bpy.data.armatures.new("rig"))
    bpy.context.scene.collection.objects.link(arm)
    s.last_report = "40 frames"
    for source in ('FILE', 'SCENE'):
        s.source = source
        s.left_hand.object = arm
        for cal in ('AUTO', 'TPOSE', 'MEASURE'):
            s.calibration = cal
            for cls in (panels.MANIKIN_PT_solve, panels.MANIKIN_PT_calibration, panels.MANIKIN_PT_output):
                assert cls.poll(bpy.context)
                log = []
                cls.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
                assert log
    log = []
    s.source = 'FILE'
    panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("operator", "manikin.solve_full_body") in log and ("prop", "filepath") in log
    # the Smoothing setting is shown for tracker recordings (and scene objects) as for keypoints,
    # and its window only when one is set; the solve gets it whatever the source
    from blender_manikin.blender.properties import config_from_settings
    assert ("prop", "smoothing_mode") in log and ("prop", "smoothing") not in log
    s.smoothing_mode, s.smoothing = 'WINDOW', 0.25
    for source in ('FILE', 'SCENE'):
        s.source = source
        log = []
        panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
        assert ("prop", "smoothing_mode") in log and ("prop", "smoothing") in log
    s.source = 'FILE'
    assert config_from_settings(bpy.context).smoothing == pytest.approx(0.25)
    s.smoothing_mode = 'AUTO'
    assert config_from_settings(bpy.context).smoothing == "auto"


def test_the_summary_is_wrapped_to_the_sidebar_without_losing_a_word(addon):
    """Blender labels do not wrap and cut a long one in the middle with "...": the summary box
    gets lines that fit the region (measured in the UI font where Blender can, else estimated),
    every word kept, in order; a narrower sidebar gets shorter lines."""
    from blender_manikin.panels import main as panels
    from types import SimpleNamespace
    text = ("168 frames at 24 fps; model head and hands (manikin_s.onnx); stature 1.75 m; calibrated on "
            "a T-pose at 0.62 s: stature 1.75 m, arm span 1.53 m; offsets openxr_generic (auto: from the file)")
    prefs = bpy.context.preferences
    wide = panels.wrapped(text, SimpleNamespace(region=SimpleNamespace(width=400), preferences=prefs))
    narrow = panels.wrapped(text, SimpleNamespace(region=SimpleNamespace(width=250), preferences=prefs))
    assert " ".join(wide) == text and " ".join(narrow) == text
    assert len(narrow) > len(wide) > 1
    scale = prefs.system.ui_scale or 1.0
    measure = panels._text_measure(SimpleNamespace(preferences=prefs), scale)
    assert max(measure(line) for line in narrow) <= 250 - 96 * scale
    assert panels.wrapped("a\n\nb", SimpleNamespace(region=None, preferences=prefs)) == ["a", "", "b"]


def test_panel_overlap_reaches_the_solver(addon, recording, monkeypatch):
    """The panel's Overlap (network windows per frame) is shown with the pose model and reaches
    the solver; the default (2) calls it as before."""
    from blender_manikin.panels import main as panels
    from blender_manikin.blender.properties import config_from_settings
    from types import SimpleNamespace
    calls = []

    def spy(targets, body, progress=None, **kw):
        calls.append(kw)
        return stub_solver(targets, body, progress=progress)
    monkeypatch.setattr(solve_job, "run_solver", spy)
    s = _settings(recording)
    s.live_rig = False
    log = []
    panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("prop", "overlap") in log
    assert s.overlap == '2' and config_from_settings(bpy.context).overlap == 2
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert calls and all("overlap" not in kw for kw in calls)
    s.overlap = '3'
    assert config_from_settings(bpy.context).overlap == 3
    calls.clear()
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert calls and all(kw.get("overlap") == 3 for kw in calls)


def test_modal_progress_cancel_and_finish(addon, recording, monkeypatch):
    """Drive the operator's modal() with timer / Esc events (no UI event loop in background)."""
    from types import SimpleNamespace
    from blender_manikin.operators import solve as solve_op
    cls = solve_op.MANIKIN_OT_solve_full_body
    gate, started = threading.Event(), threading.Event()

    def gated_solver(targets, body, progress=None):
        progress(0.3)
        started.set()
        gate.wait(5)
        return stub_solver(targets, body, progress)

    monkeypatch.setattr(solve_job, "run_solver", gated_solver)
    _settings(recording)
    timer = SimpleNamespace(type='TIMER', value='NOTHING')
    esc = SimpleNamespace(type='ESC', value='PRESS')
    mouse = SimpleNamespace(type='MOUSEMOVE', value='NOTHING')
    before = len(bpy.data.objects)

    # cancelled while the worker runs
    op = modal_operator(cls)
    queue = op.start_modal()
    assert not cls.poll(bpy.context)                       # one solve at a time
    assert started.wait(5)
    assert op.modal(bpy.context, timer) == {'RUNNING_MODAL'}
    assert 0.0 < queue.progress < 1.0
    assert op.modal(bpy.context, mouse) == {'PASS_THROUGH'}
    assert op.modal(bpy.context, esc) == {'CANCELLED'}
    gate.set()
    assert solve_op._ACTIVE["job"] is None and cls.poll(bpy.context)
    assert len(bpy.data.objects) == before
    assert op.reports[-1][0] == {'WARNING'} and "nothing was written" in op.reports[-1][1]

    # runs to the end: the timer tick after the worker finishes writes the result
    op = modal_operator(cls)
    queue = op.start_modal()
    queue.job.join(5)
    assert op.modal(bpy.context, timer) == {'FINISHED'}
    assert len(bpy.data.objects) > before and solve_op._ACTIVE["job"] is None
    assert op.reports[-1][0] == {'INFO'} and "MANIKIN_live" in op.reports[-1][1]      # the live rig (default)

    # a failing worker is reported as an error
    monkeypatch.setattr(solve_job, "run_solver", lambda *a, **k: (_ for _ in ()).throw(ValueError("boom")))
    n = len(bpy.data.objects)
    op = modal_operator(cls)
    queue = op.start_modal()
    queue.job.join(5)
    assert op.modal(bpy.context, timer) == {'CANCELLED'}
    assert op.reports[-1] == ({'ERROR'}, "MANIKIN: boom") and len(bpy.data.objects) == n


def test_a_failed_modal_solve_redraws_the_panel(addon, recording, monkeypatch):
    """A modal solve that fails ends CANCELLED, which redraws nothing: in a real window the
    panel's "Solve failed: ..." box was not drawn (a single EasyMocap frame file picked, the
    mouse then over the sidebar: only the status bar said it).  Its end tags the 3D Views (the
    sidebar's areas) for a redraw, whatever way it ends."""
    from blender_manikin.operators import solve as solve_op
    log = []

    class Area:
        def __init__(self, kind):
            self.type = kind

        def tag_redraw(self):
            log.append(self.type)

    wm = _WM(log)
    wm.progress_update = lambda value: None
    wm.windows = [SimpleNamespace(screen=SimpleNamespace(areas=[Area('VIEW_3D'), Area('OUTLINER'),
                                                                Area('VIEW_3D')]))]

    class Context:                          # bpy.context with the window manager of a window
        window_manager = wm

        def __getattr__(self, name):
            return getattr(bpy.context, name)

    monkeypatch.setattr(solve_job, "run_solver", lambda *a, **k: (_ for _ in ()).throw(ValueError("boom")))
    _settings(recording)
    op = modal_operator(solve_op.MANIKIN_OT_solve_full_body)
    queue = op.start_modal()
    queue.job.join(5)
    assert op.modal(Context(), SimpleNamespace(type='TIMER', value='NOTHING')) == {'CANCELLED'}
    assert bpy.context.scene.manikin.last_report == "Solve failed: boom"
    assert log == ["progress ended", "VIEW_3D", "VIEW_3D"]


def test_a_modal_solve_is_written_in_the_scene_it_was_started_in(addon, recording):
    """The user shows another scene while the solve runs: the solve waits for its own scene (its
    settings, frame rate and armature are that scene's) instead of being written into the other."""
    from types import SimpleNamespace
    from blender_manikin.operators import solve as solve_op
    cls = solve_op.MANIKIN_OT_solve_full_body
    timer = SimpleNamespace(type='TIMER', value='NOTHING')
    _settings(recording)
    start, other = bpy.context.scene, bpy.data.scenes.new("Other")
    op = modal_operator(cls)
    queue = op.start_modal()
    queue.job.join(10)
    with bpy.context.temp_override(scene=other):
        assert op.modal(bpy.context, timer) == {'RUNNING_MODAL'}        # not written into Other
        assert len(other.objects) == 0 and queue.job is not None
    assert op.modal(bpy.context, timer) == {'FINISHED'}                 # back in its scene
    assert start.manikin.armature is not None and start.manikin.armature.name in start.objects
    assert len(other.objects) == 0 and other.manikin.last_report == ""

    # its scene deleted while it runs: nothing written anywhere, the solve ends
    op = modal_operator(cls)
    queue = op.start_modal()
    queue.job.join(10)
    with bpy.context.temp_override(scene=other):
        bpy.data.scenes.remove(start)
        assert op.modal(bpy.context, timer) == {'CANCELLED'}
    assert solve_op._ACTIVE["job"] is None and len(other.objects) == 0


def test_panel_teleports_keep_the_body_where_the_recording_jumps(addon, tmp_path, monkeypatch):
    """A take whose app teleported the player 2 m at 3.5 s: with Teleports at Keep (the default)
    the solved body jumps with it, its pose unbroken; at Remove its path is continuous."""
    from types import SimpleNamespace
    from blender_manikin.core.formats import load_recording
    from blender_manikin.core.io_csv import write_csv
    from blender_manikin.core.recording import Recording, TrackerStream
    from blender_manikin.panels import main as panels
    from blender_manikin.blender.properties import config_from_settings
    monkeypatch.setattr(solve_job, "run_solver", solve_job.core_solve.default_solver)   # the real network
    ex = load_recording(os.path.join(os.path.dirname(os.path.dirname(__file__)), "examples", "example_recording.csv"))
    t0 = ex.time_range()[0]
    streams = {}
    for d, st in ex.streams.items():
        p = st.pos.copy()
        p[st.time >= t0 + 3.5] += [2.0, 0.0, 0.0]
        streams[d] = TrackerStream(d, st.time, p, st.quat, st.valid)
    path = tmp_path / "teleport.csv"
    write_csv(path, Recording(streams=streams, metadata=dict(ex.metadata)))
    s = bpy.context.scene.manikin
    s.source, s.filepath, s.live_rig = 'FILE', str(path), False
    log = []
    panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("prop", "teleports") in log and s.teleports == 'KEEP'
    assert config_from_settings(bpy.context).teleports == "keep"
    sc = bpy.context.scene
    travel = {}
    for mode in ('KEEP', 'REMOVE'):
        s.teleports = mode
        assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
        assert ("1 teleport (first at" in s.last_report) and ("put back" in s.last_report) == (mode == 'KEEP')
        arm = bpy.context.view_layer.objects.active
        fps = sc.render.fps / sc.render.fps_base
        xs = []
        for f in (1 + int(3.3 * fps), 1 + int(3.7 * fps)):
            sc.frame_set(f)
            xs.append((arm.matrix_world @ arm.pose.bones["pelvis"].head).x)
        travel[mode] = xs[1] - xs[0]
    assert travel['KEEP'] == pytest.approx(2.0 + travel['REMOVE'], abs=0.05)
    assert abs(travel['REMOVE']) < 0.3


def test_panel_trim_reaches_the_solve(addon, monkeypatch):
    """Frames and Output's Trim Start / Trim End solve a part of a recording, in seconds."""
    from types import SimpleNamespace
    from blender_manikin.panels import main as panels
    from blender_manikin.blender.properties import config_from_settings
    monkeypatch.setattr(solve_job, "run_solver", solve_job.core_solve.default_solver)
    s = bpy.context.scene.manikin
    s.source = 'FILE'
    s.filepath = os.path.join(os.path.dirname(os.path.dirname(__file__)), "examples", "example_recording.csv")
    s.live_rig = False
    log = []
    panels.MANIKIN_PT_output.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("prop", "use_trim_start") in log and ("prop", "trim_end") in log
    cfg = config_from_settings(bpy.context)
    assert cfg.start is None and cfg.end is None
    s.use_trim_start, s.trim_start, s.use_trim_end, s.trim_end = True, 2.0, True, 5.0
    cfg = config_from_settings(bpy.context)
    assert (cfg.start, cfg.end) == (2.0, 5.0)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "trimmed to 2.00-5.00 s" in s.last_report
    import re
    assert not re.search(r"\b(read|solve|resample) \d+\.\d+s", s.last_report)     # no timings in the box
    fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
    assert f"{int(round(3.0 * fps)) + 1} frames at {fps:g} fps" in s.last_report


def test_panel_posture_reaches_the_solve(addon, recording):
    from types import SimpleNamespace
    from blender_manikin.panels import main as panels
    from blender_manikin.blender.properties import config_from_settings
    s = _settings(recording)
    log = []
    panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("prop", "posture") in log and s.posture == 'STANDING'
    assert config_from_settings(bpy.context).posture == "standing"
    assert ("prop", "fix_sides") in log                      # controllers swapped back, for trackers too
    s.fix_sides = False
    assert config_from_settings(bpy.context).fix_sides is False
    s.fix_sides = True
    s.posture = 'SEATED'
    assert config_from_settings(bpy.context).posture == "seated"
    s.live_rig = False
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    arm = bpy.context.view_layer.objects.active
    sc = bpy.context.scene
    sc.frame_set(10)
    for side in ("left", "right"):          # seated: thigh forward and level-ish, shin about upright
        hip = arm.matrix_world @ arm.pose.bones[f"{side}_hip"].head
        knee = arm.matrix_world @ arm.pose.bones[f"{side}_knee"].head
        ankle = arm.matrix_world @ arm.pose.bones[f"{side}_ankle"].head
        # the feet stay planted while the hips sway (this take's are a standing performer's)
        assert abs(knee.x - ankle.x) < 0.1 and abs(knee.y - ankle.y) < 0.1
        assert (knee - hip).length > 0.3 and abs(knee.z - hip.z) < (knee - hip).length
