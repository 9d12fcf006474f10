"""Solve Several Files from the UI: the files are solved one after another in a worker thread
while Blender stays responsive (progress per file in the status bar), and Esc stops the file
being solved and the rest, keeping the files solved before.  The operator's modal() is driven
with timer / Esc events, as Blender's event loop would (there is none in background mode); the
synchronous path (scripts, ``-b``) is tested in test_blender_marks.py."""
import os
import shutil
import time
from types import SimpleNamespace

import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.operators import solve as solve_op  # noqa: E402

from blender_util import PanelLayout, modal_operator  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")
TIMER = SimpleNamespace(type='TIMER', value='NOTHING')
ESC = SimpleNamespace(type='ESC', value='PRESS')
CLS = solve_op.MANIKIN_OT_solve_files


def _takes(tmp_path, names):
    for n in names:
        if n.startswith("broken"):
            (tmp_path / n).write_text("time,device,px\n0,head,1\n")
        else:
            shutil.copy(EXAMPLE, tmp_path / n)
    return dict(directory=str(tmp_path), files=[SimpleNamespace(name=n) for n in names])


def _tick(op, until, timeout=120.0):
    """Timer events until ``until(result)`` holds; returns the last modal() result."""
    t_end = time.monotonic() + timeout
    while True:
        res = op.modal(bpy.context, TIMER)
        if until(res):
            return res
        assert res == {'RUNNING_MODAL'} and time.monotonic() < t_end
        time.sleep(0.02)


def _armatures():
    return sorted(o.name for o in bpy.data.objects if o.type == 'ARMATURE')


def test_files_are_solved_one_after_another_with_progress(addon, tmp_path):
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    sc.manikin.set_scene_range = True
    op = modal_operator(CLS, **_takes(tmp_path, ["walk.csv", "broken.csv", "again.csv"]))
    queue = op.start_modal()
    assert not solve_op.MANIKIN_OT_solve_full_body.poll(bpy.context)     # one solve at a time
    seen, stages = [queue.progress], {queue.stage.split(":")[0]}

    def finished(res):
        seen.append(queue.progress)
        stages.add(queue.stage.split(":")[0])
        return res != {'RUNNING_MODAL'}

    assert _tick(op, finished) == {'FINISHED'}
    assert all(b >= a for a, b in zip(seen, seen[1:])) and seen[-1] == 1.0      # progress only grows
    assert {"file 1 of 3 (walk.csv)", "file 3 of 3 (again.csv)"} <= stages
    assert _armatures() == ["MANIKIN_again", "MANIKIN_walk"]
    report = sc.manikin.last_report
    assert report.startswith("2 of 3 files solved") and "failed: broken.csv, line 1: header is missing" in report
    assert report.count("broken.csv") == 1, report         # the reader's own "path: ..." not led by it again
    assert (sc.frame_start, sc.frame_end) == (1, 210)
    assert solve_op._ACTIVE["job"] is None and solve_op.MANIKIN_OT_solve_full_body.poll(bpy.context)
    assert sc.manikin.armature.name == "MANIKIN_again"                   # the swivel panel's: the last
    kinds = [k for k, _ in op.reports]
    assert {'WARNING'} in kinds and op.reports[-1][0] == {'INFO'}


def test_esc_keeps_the_files_solved_and_stops_the_rest(addon, tmp_path):
    sc = bpy.context.scene
    op = modal_operator(CLS, **_takes(tmp_path, ["first.csv", "second.csv", "third.csv"]))
    queue = op.start_modal()
    _tick(op, lambda res: len(queue.solved) == 1)         # the second one is running now
    assert queue.job is not None and queue.job.config.filepath.endswith("second.csv")
    second = queue.job
    assert op.modal(bpy.context, ESC) == {'FINISHED'}
    second.join(30)
    assert _armatures() == ["MANIKIN_first"]                              # nothing of the second
    assert sc.manikin.last_report.endswith("cancelled (Esc), 2 file(s) not solved")
    assert solve_op._ACTIVE["job"] is None
    n = len(bpy.data.objects)
    time.sleep(0.2)                                                       # no late write
    assert len(bpy.data.objects) == n


def test_a_take_undone_while_the_next_is_solved(addon, tmp_path):
    """Ctrl+Z while the files are solved frees what was written before (Blender reloads its
    data): the end report still names every take solved, from what it recorded then."""
    op = modal_operator(CLS, **_takes(tmp_path, ["first.csv", "second.csv"]))
    queue = op.start_modal()
    _tick(op, lambda res: len(queue.solved) == 1)
    bpy.data.objects.remove(bpy.data.objects["MANIKIN_first"])          # as an undo frees it
    assert _tick(op, lambda res: res != {'RUNNING_MODAL'}) == {'FINISHED'}
    report = bpy.context.scene.manikin.last_report
    assert report.startswith("2 of 2 files solved: MANIKIN_first / MANIKIN_live_first, MANIKIN_second")


def test_files_confirmed_while_a_solve_runs_are_not_solved_beside_it(addon, tmp_path):
    """The file browser's execute skips poll(): files confirmed in a browser opened before
    another solve started must not start a second modal solve beside the running one."""
    running = modal_operator(CLS, **_takes(tmp_path, ["first.csv"]))
    queue = running.start_modal()
    second = modal_operator(CLS, interactive=True, **_takes(tmp_path, ["second.csv"]))
    assert CLS._start(second, bpy.context, modal=True) == {'CANCELLED'}
    assert second.reports[-1][0] == {'ERROR'} and "already running" in second.reports[-1][1]
    assert solve_op._ACTIVE["job"] is queue
    assert _tick(running, lambda res: res != {'RUNNING_MODAL'}) == {'FINISHED'}
    assert _armatures() == ["MANIKIN_first"]


def test_esc_before_any_file_is_solved_cancels(addon, tmp_path):
    op = modal_operator(CLS, **_takes(tmp_path, ["first.csv", "second.csv"]))
    queue = op.start_modal()
    assert op.modal(bpy.context, ESC) == {'CANCELLED'}
    assert queue.cancelled and not queue.solved and _armatures() == []
    assert op.reports[-1][0] == {'WARNING'} and "0 of 2 files solved" in op.reports[-1][1]


def test_every_file_failing_is_an_error(addon, tmp_path):
    op = modal_operator(CLS, **_takes(tmp_path, ["broken1.csv", "broken2.csv"]))
    queue = op.start_modal()
    assert _tick(op, lambda res: res != {'RUNNING_MODAL'}) == {'CANCELLED'}
    assert len(queue.failed) == 2 and _armatures() == []
    assert op.reports[-1][0] == {'ERROR'} and "broken2.csv" in op.reports[-1][1]


class _IconLayout(PanelLayout):
    """:class:`blender_util.PanelLayout` whose labels are logged with their icons."""

    def label(self, **k):
        self.log.append(("label", k.get("icon"), k.get("text")))


def _summary_box(context):
    """The solve panel's summary box as ``[(icon, first line of the item)]``."""
    from blender_manikin.panels import main as panels
    log = []
    panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=_IconLayout(log)), context)
    return [(icon, text) for kind, icon, text in (e for e in log if e[0] == "label") if icon != 'BLANK1']


def test_every_file_failing_is_said_without_an_empty_list(addon, tmp_path):
    """No file solved: the summary says so and goes on to the failures (it said "0 of 2 files
    solved: ; failed: ...", the box's first item a dangling "0 of 2 files solved:")."""
    op = modal_operator(CLS, **_takes(tmp_path, ["broken1.csv", "broken2.csv"]))
    op.start_modal()
    assert _tick(op, lambda res: res != {'RUNNING_MODAL'}) == {'CANCELLED'}
    report = bpy.context.scene.manikin.last_report
    assert report.startswith("0 of 2 files solved; failed: broken1.csv, line 1: "), report
    assert op.reports[-1][1] == f"MANIKIN: {report}"


def test_a_failed_file_is_flagged_in_the_summary_box(addon, tmp_path):
    """Solve Several Files with two broken files: the box's items for them are marked with the
    error icon, the solved files' with a bullet (they had bullets like the files solved)."""
    names = ["walk.csv", "broken1.csv", "broken2.csv"]
    t = _takes(tmp_path, names)
    assert bpy.ops.manikin.solve_files(directory=t["directory"], files=[{"name": n} for n in names]) == {'FINISHED'}
    box = _summary_box(bpy.context)
    assert len(box) == 3 and box[0][0] == 'DOT' and box[0][1].startswith("1 of 3 files solved"), box
    assert box[1][1].startswith("failed: broken1.csv") and box[2][1].startswith("broken2.csv"), box
    assert [icon for icon, _ in box[1:]] == ['ERROR', 'ERROR'], box


def test_scripts_get_the_files_solved_before_the_call_returns(addon, tmp_path):
    """Called from a script (EXEC_DEFAULT, the file browser not involved) the operator is
    synchronous even in a session with a window: ``interactive`` is set only by invoke."""
    t = _takes(tmp_path, ["one.csv"])
    res = bpy.ops.manikin.solve_files(directory=t["directory"], files=[{"name": "one.csv"}])
    assert res == {'FINISHED'} and _armatures() == ["MANIKIN_one"]
