"""Keypoints → keyed armature in Blender: the panel's Keypoints source, the live rig, the CLI."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin import cli  # noqa: E402
from blender_manikin.blender import keying, live_rig  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.solve import SolveSettings, solve_recording  # noqa: E402

from fixtures_keypoints import hinge_motion, write_freemocap, write_layout_npy  # noqa: E402


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=90, seed=1)


def _bone_heads(obj, frame, names):
    bpy.context.scene.frame_set(frame)
    mw = np.array(obj.matrix_world)
    return np.array([(mw @ np.append(np.array(obj.pose.bones[n].head), 1.0))[:3] for n in names])


def test_panel_keypoints_source_keys_a_live_rig_that_follows_the_solve(addon, tmp_path, motion):
    folder, _ = write_freemocap(str(tmp_path / "session"), *motion, sigma=0.01, drop=0.02, seed=2)
    npy = os.path.join(folder, "output_data", "mediapipe_body_3d_xyz.npy")
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path = 'KEYPOINTS', npy
    assert s.smoothing_mode == 'AUTO'            # the default: each point's filter from its noise
    s.smoothing_mode, s.smoothing, s.ik = 'WINDOW', 0.3, 'ADAPTIVE'
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    obj = s.armature
    assert obj is not None and live_rig.is_live_rig(obj)
    assert s.last_report.startswith("keypoints: mediapipe33 (33 points, from the file); FreeMoCap folder")
    assert "no twist information: left_foot, right_foot" in s.last_report
    action = obj.animation_data.action
    paths = {fc.data_path for fc in keying.action_fcurves(action, obj)}
    assert {f'["swivel_{limb}"]' for limb in sk.LIMB_NAMES} <= paths
    # the same solve without Blender: the evaluated (live-rig) joints sit where its FK puts them
    ref = solve_recording(npy, SolveSettings(fps=30.0, smoothing=0.3)).result.fk()[0]
    names = ["left_wrist", "right_wrist", "left_elbow", "right_knee", "left_ankle", "head", "pelvis"]
    for k in (0, 33, 89):
        got = _bone_heads(obj, 1 + k, names)
        np.testing.assert_allclose(got, ref[k, [sk.J[n] for n in names]], atol=1e-3)
    # and a swivel edit moves the elbow, the wrist stays
    before = _bone_heads(obj, 34, ["left_elbow", "left_wrist"])
    fc = live_rig.swivel_fcurve(obj, "left_arm")
    for kp in fc.keyframe_points:
        kp.co[1] += 0.5
    fc.update()
    after = _bone_heads(obj, 34, ["left_elbow", "left_wrist"])
    assert np.linalg.norm(after[0] - before[0]) > 0.02
    np.testing.assert_allclose(after[1], before[1], atol=1e-3)


def test_panel_solves_a_coco_array_with_gaps_into_a_new_armature(addon, tmp_path, motion):
    body, pos, world = motion
    write_layout_npy(tmp_path / "coco.npy", "coco17", body, pos, world, sigma=0.01, drop=0.03, scale=1000.0)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.keypoint_layout = 'KEYPOINTS', str(tmp_path / "coco.npy"), 'COCO17'
    s.live_rig = False
    before = set(bpy.data.objects.keys())
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    obj = s.armature
    assert obj.name not in before and obj.animation_data.action is not None
    assert "keypoints: coco17 (17 points, as set)" in s.last_report and "gap(s) bridged" in s.last_report
    assert "no twist information: left_wrist, right_wrist, left_foot, right_foot" in s.last_report
    fcs = keying.action_fcurves(obj.animation_data.action, obj)
    assert all(len(fc.keyframe_points) == 90 for fc in fcs)
    # the left/right swap fix and the spike removal are on by default, shown with the keypoint
    # options, and reach the solve
    from types import SimpleNamespace
    from blender_manikin.blender.properties import config_from_settings
    from blender_manikin.panels import main as panels
    from blender_util import PanelLayout
    log = []
    panels.MANIKIN_PT_solve.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("prop", "fix_sides") in log and ("prop", "despike") in log
    cfg = config_from_settings(bpy.context)
    assert s.fix_sides and s.despike and cfg.fix_sides is True and cfg.despike is True
    s.fix_sides = s.despike = False
    cfg = config_from_settings(bpy.context)
    assert cfg.fix_sides is False and cfg.despike is False


def test_cli_in_blender_writes_a_blend_from_a_coco_array(tmp_path, motion):
    body, pos, world = motion
    write_layout_npy(tmp_path / "coco.npy", "coco17", body, pos, world, sigma=0.01, drop=0.03, scale=1000.0)
    out = tmp_path / "out"
    assert cli.main(["solve", str(tmp_path / "coco.npy"), "--out", str(out), "--format", "blend,json",
                     "--fps", "30"]) == 0
    assert (out / "coco.blend").stat().st_size > 0 and (out / "coco.json").stat().st_size > 0
    bpy.ops.wm.open_mainfile(filepath=str(out / "coco.blend"))
    arm = [o for o in bpy.data.objects if o.type == 'ARMATURE']
    assert len(arm) == 1 and arm[0].animation_data.action is not None


def test_panel_person_field_solves_one_person_of_a_group_file(addon, tmp_path, motion):
    """A (people, frames, points, 3) array: the Keypoints tab's Person field picks the one solved
    (trimmed to the frames they are seen)."""
    from blender_manikin.core import keypoint_layouts as kl
    from fixtures_keypoints import to_y_up
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    X = np.stack([to_y_up(clean), to_y_up(clean + [1.5, 0.0, 0.0])])
    X[1, 60:] = np.nan                           # person 1 leaves after 60 frames
    path = tmp_path / "group.npy"
    np.save(path, X)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.live_rig = 'KEYPOINTS', str(path), False
    assert s.keypoint_person == "all"
    s.keypoint_person = "1"
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "person 1 of 2 (0, 1), frames 0-59" in s.last_report
    fcs = keying.action_fcurves(s.armature.animation_data.action, s.armature)
    assert all(len(fc.keyframe_points) == 60 for fc in fcs)


def _group_npy(tmp_path, motion):
    """``group.npy``: three people (people, frames, points, 3), +Y up: person 1 leaves after 60
    frames, person 2 enters at frame 20."""
    from blender_manikin.core import keypoint_layouts as kl
    from fixtures_keypoints import to_y_up
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    X = np.stack([to_y_up(clean + [1.5 * k, 0.0, 0.0]) for k in range(3)])
    X[1, 60:] = np.nan
    X[2, :20] = np.nan
    path = tmp_path / "group.npy"
    np.save(path, X)
    return path


def test_panel_person_all_solves_each_person_onto_their_own_armature_in_one_undo_step(addon, tmp_path, motion):
    """Person "all" on a file with three people: one new armature per person, named as the command
    line's outputs (MANIKIN_<take>_p<label>), each with its own action keyed over the frames that
    person is seen, the box listing them; made in one undo step (one undo removes all three)."""
    path = _group_npy(tmp_path, motion)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.live_rig = 'KEYPOINTS', str(path), False
    assert s.keypoint_person == "all"
    from blender_manikin.blender import solve_job as sj
    from blender_manikin.blender.properties import config_from_settings
    q = sj.SolveQueue(sj.person_configs(config_from_settings(bpy.context)))
    q.index = 1                                  # the modal operator's status bar, on the second person
    assert len(q) == 3 and q.stage == "person 2 of 3 (1): done"
    bpy.ops.ed.undo_push(message="before solve")
    names = sorted(o.name for o in bpy.data.objects)
    n_act = len(bpy.data.actions)
    assert bpy.ops.manikin.solve_full_body('EXEC_DEFAULT', True) == {'FINISHED'}
    arms = sorted((o for o in bpy.data.objects if o.type == 'ARMATURE'), key=lambda o: o.name)
    assert [o.name for o in arms] == ["MANIKIN_group_p0", "MANIKIN_group_p1", "MANIKIN_group_p2"]
    acts = [o.animation_data.action for o in arms]
    assert [a.name for a in acts] == ["MANIKIN_solve_group_p0", "MANIKIN_solve_group_p1", "MANIKIN_solve_group_p2"]
    for obj, act, n in zip(arms, acts, (90, 60, 70)):
        assert {len(fc.keyframe_points) for fc in keying.action_fcurves(act, obj)} == {n}
    assert s.last_report.startswith("3 of 3 people of group.npy solved: MANIKIN_group_p0 / MANIKIN_solve_group_p0, "
                                    "MANIKIN_group_p1 / MANIKIN_solve_group_p1, MANIKIN_group_p2 / ")
    assert s.armature == arms[-1]
    bpy.ops.ed.undo()
    assert sorted(o.name for o in bpy.data.objects) == names
    assert len(bpy.data.actions) == n_act


def test_person_all_a_person_that_fails_leaves_nothing_and_is_named(addon, tmp_path, motion, monkeypatch):
    """One person's solve failing while it is written (its live rig) removes what was made for
    that person only; the others are kept and the box names the one that failed."""
    path = _group_npy(tmp_path, motion)
    real = live_rig.build_live_rig

    def build(obj, *a, **kw):
        if obj.name.endswith("_p1"):
            raise RuntimeError("rig refused")
        return real(obj, *a, **kw)

    monkeypatch.setattr(live_rig, "build_live_rig", build)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.live_rig = 'KEYPOINTS', str(path), True
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert sorted(o.name for o in bpy.data.objects if o.type == 'ARMATURE') == ["MANIKIN_group_p0",
                                                                                 "MANIKIN_group_p2"]
    assert not [a for a in bpy.data.actions if "group_p1" in a.name]
    assert not [o for o in bpy.data.objects if "group_p1" in o.name]
    assert not [d for d in list(bpy.data.meshes) + list(bpy.data.armatures) if "group_p1" in d.name]
    assert s.last_report.startswith("2 of 3 people of group.npy solved: MANIKIN_group_p0 / MANIKIN_live_group_p0, "
                                    "MANIKIN_group_p2 / MANIKIN_live_group_p2; failed: person 1: rig refused")


def test_solve_several_files_splits_a_group_file_as_solve_full_body_does(addon, tmp_path, motion):
    """*Solve Several Files* with Person ``all`` and a keypoint file with three people beside a
    one-person file: each person onto an armature of their own (``MANIKIN_group_p<label>``, as
    *Solve Full Body* names them), the other file onto its own (the group file was refused:
    "3 people in the file (0, 1, 2): choose one ...")."""
    from blender_manikin.core import keypoint_layouts as kl
    from fixtures_keypoints import to_y_up
    _group_npy(tmp_path, motion)
    body, pos, world = motion
    np.save(tmp_path / "solo.npy", to_y_up(kl.keypoints_from_body22(pos, world, "coco17", body.stature)))
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.live_rig = 'KEYPOINTS', False
    assert s.keypoint_person == "all"
    res = bpy.ops.manikin.solve_files(directory=str(tmp_path), files=[{"name": "group.npy"}, {"name": "solo.npy"}])
    assert res == {'FINISHED'}
    arms = sorted(o.name for o in bpy.data.objects if o.type == 'ARMATURE')
    assert arms == ["MANIKIN_group_p0", "MANIKIN_group_p1", "MANIKIN_group_p2", "MANIKIN_solo"]
    assert s.last_report.startswith("4 of 4 takes solved: MANIKIN_group_p0 / MANIKIN_solve_group_p0, ")
    obj = bpy.data.objects["MANIKIN_group_p1"]
    assert {len(fc.keyframe_points) for fc in keying.action_fcurves(obj.animation_data.action, obj)} == {60}


def test_panel_solves_a_lower_body_plugin_gait_trc(addon, tmp_path):
    """A Plug-in Gait lower-body trial (no upper-body markers) in the Keypoints tab: solved, the
    trunk, arms and head on the pelvis at rest, said in the report.  Before: refused ("joint(s)
    pelvis, spine1, ... cannot be placed")."""
    from test_lower_body import _pig_trc
    path = _pig_trc(tmp_path / "lower.trc", hinge_motion(frames=150, seed=3), True)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 60, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.keypoint_layout = 'KEYPOINTS', str(path), 'AUTO'
    s.live_rig = False
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    obj = s.armature
    assert obj is not None and obj.animation_data.action is not None
    assert "lower body only: the trunk, arms and head follow the pelvis at rest" in s.last_report, s.last_report
    ref = solve_recording(str(path), SolveSettings(fps=60.0)).result.fk()[0]
    names = ["left_knee", "right_ankle", "head", "left_wrist"]
    got = _bone_heads(obj, 1 + 40, names)
    np.testing.assert_allclose(got, ref[40, [sk.J[n] for n in names]], atol=1e-3)


def test_only_files_that_may_hold_several_people_are_read_to_list_them(tmp_path, motion, monkeypatch):
    """Solve Full Body / Solve Several Files list a keypoint file's people on Blender's own thread:
    a file surely holding one person (a 3-D ``.npy``, told by its header) and a chosen person
    are not read there (the solve's background job reads them, so a big file leaves the window
    live); a group file is still read once and split."""
    from blender_manikin.blender import solve_job as sj
    from blender_manikin.core import io_keypoints as ik
    single = tmp_path / "one.npy"
    write_layout_npy(single, "coco17", *motion)
    group = _group_npy(tmp_path, motion)
    real, reads = ik.read_keypoint_people, []

    def counted(path, **kw):
        reads.append(os.path.basename(str(path)))
        return real(path, **kw)
    monkeypatch.setattr(ik, "read_keypoint_people", counted)
    one = sj.SolveConfig(source="KEYPOINTS", filepath=str(single), fps=30)
    assert not sj.may_hold_people(one) and reads == []
    chosen = sj.SolveConfig(source="KEYPOINTS", filepath=str(group), fps=30, person="1")
    assert not sj.may_hold_people(chosen) and reads == []
    everyone = sj.SolveConfig(source="KEYPOINTS", filepath=str(group), fps=30)
    assert sj.may_hold_people(everyone) and reads == []
    everyone = sj.person_configs(everyone)
    assert [c.take for c in everyone] == ["group_p0", "group_p1", "group_p2"] and reads == ["group.npy"]


def _solved_takes():
    """Each armature's name → its action's name and keys (``{(data path, index): (n, 2) co}``)."""
    out = {}
    for obj in bpy.data.objects:
        if obj.type == 'ARMATURE':
            act = obj.animation_data.action
            keys = {(fc.data_path, fc.array_index): np.array([k.co[:] for k in fc.keyframe_points])
                    for fc in keying.action_fcurves(act, obj)}
            out[obj.name] = (act.name, keys)
    return out


def _wipe_solves():
    for coll in (bpy.data.objects, bpy.data.armatures, bpy.data.meshes, bpy.data.actions):
        for block in list(coll):
            coll.remove(block)
    bpy.context.scene.timeline_markers.clear()


def _modal_run(cls, monkeypatch, **props):
    """Run operator ``cls`` modally (timer events, as Blender's event loop would send them) with
    :func:`read_keypoint_people` recording the thread it runs on; returns (the stages the status
    bar showed, the reading threads, the operator's last result)."""
    import threading
    import time
    from types import SimpleNamespace
    from blender_manikin.core import io_keypoints as ik
    from blender_util import modal_operator
    real, threads = ik.read_keypoint_people, []

    def recorded(*a, **kw):
        threads.append(threading.current_thread())
        return real(*a, **kw)
    monkeypatch.setattr(ik, "read_keypoint_people", recorded)
    op = modal_operator(cls, **props)
    queue = op.start_modal()
    stages, seen, t_end = [queue.stage], [queue.progress], time.monotonic() + 300
    while True:
        res = op.modal(bpy.context, SimpleNamespace(type='TIMER', value='NOTHING'))
        stages.append(queue.stage)
        seen.append(queue.progress)
        if res != {'RUNNING_MODAL'}:
            break
        assert time.monotonic() < t_end
        time.sleep(0.02)
    monkeypatch.setattr(ik, "read_keypoint_people", real)
    assert all(b >= a for a, b in zip(seen, seen[1:])) and seen[-1] == 1.0      # progress only grows
    return stages, threads, res


def _assert_same_takes(a, b):
    assert sorted(a) == sorted(b)
    for name in a:
        assert a[name][0] == b[name][0] and sorted(a[name][1]) == sorted(b[name][1])
        for key in a[name][1]:
            np.testing.assert_allclose(a[name][1][key], b[name][1][key], atol=1e-6)


def test_modal_solve_full_body_reads_a_group_file_in_its_worker_thread(addon, tmp_path, motion, monkeypatch):
    """Solve Full Body from the UI (modal) on a file with three people: the file is read (its
    people listed) in the solve's worker thread, not on Blender's main thread (which froze the
    window with no progress and no Esc); the status bar counts the people and the armatures,
    actions and keys are those of the synchronous run (EXEC_DEFAULT), with the same report."""
    import threading
    from blender_manikin.operators import solve as solve_op
    path = _group_npy(tmp_path, motion)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.live_rig = 'KEYPOINTS', str(path), False
    assert bpy.ops.manikin.solve_full_body('EXEC_DEFAULT') == {'FINISHED'}
    sync, sync_report = _solved_takes(), s.last_report
    assert sorted(sync) == ["MANIKIN_group_p0", "MANIKIN_group_p1", "MANIKIN_group_p2"]
    _wipe_solves()
    stages, threads, res = _modal_run(solve_op.MANIKIN_OT_solve_full_body, monkeypatch)
    assert res == {'FINISHED'}
    assert threads and all(t is not threading.main_thread() for t in threads), threads
    assert any(st.startswith("person 2 of 3 (1): ") for st in stages), stages
    _assert_same_takes(_solved_takes(), sync)
    assert s.last_report == sync_report
    assert solve_op._ACTIVE["job"] is None


def test_modal_solve_several_files_reads_a_group_file_in_its_worker_thread(addon, tmp_path, motion, monkeypatch):
    """Solve Several Files from the UI on a group file beside a one-person file: the group file
    is read in the worker thread and split into one solve per person there, giving the
    armatures, actions and keys of the synchronous run."""
    import threading
    from types import SimpleNamespace
    from blender_manikin.core import keypoint_layouts as kl
    from blender_manikin.operators import solve as solve_op
    from fixtures_keypoints import to_y_up
    _group_npy(tmp_path, motion)
    body, pos, world = motion
    np.save(tmp_path / "solo.npy", to_y_up(kl.keypoints_from_body22(pos, world, "coco17", body.stature)))
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.live_rig = 'KEYPOINTS', False
    names = ["solo.npy", "group.npy"]
    res = bpy.ops.manikin.solve_files(directory=str(tmp_path), files=[{"name": n} for n in names])
    assert res == {'FINISHED'}
    sync, sync_report = _solved_takes(), s.last_report
    assert len(sync) == 4 and sync_report.startswith("4 of 4 takes solved")
    _wipe_solves()
    stages, threads, res = _modal_run(solve_op.MANIKIN_OT_solve_files, monkeypatch, directory=str(tmp_path),
                                      files=[SimpleNamespace(name=n) for n in names])
    assert res == {'FINISHED'}
    assert threads and all(t is not threading.main_thread() for t in threads), threads
    assert any(st.startswith("file 4 of 4 (group.npy): ") for st in stages), stages
    _assert_same_takes(_solved_takes(), sync)
    assert s.last_report == sync_report


def test_esc_while_a_group_file_is_read_writes_nothing(addon, tmp_path, motion, monkeypatch):
    """Esc while the modal Solve Full Body is still reading a group file (in its worker thread;
    the status bar says so): the solve stops, nothing is written, then or when the read ends."""
    import threading
    import time
    from types import SimpleNamespace
    from blender_manikin.blender import solve_job as sj
    from blender_manikin.core import io_keypoints as ik
    from blender_manikin.operators import solve as solve_op
    from blender_util import modal_operator
    path = _group_npy(tmp_path, motion)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.live_rig = 'KEYPOINTS', str(path), False
    real, started, release = ik.read_keypoint_people, threading.Event(), threading.Event()

    def slow(*a, **kw):
        started.set()
        release.wait(10)
        return real(*a, **kw)
    monkeypatch.setattr(ik, "read_keypoint_people", slow)
    op = modal_operator(solve_op.MANIKIN_OT_solve_full_body)
    queue = op.start_modal()
    assert started.wait(10)
    job = queue.job
    assert job is not None and queue.stage == "reading the file's people" and queue.progress == 0.0
    assert op.modal(bpy.context, SimpleNamespace(type='ESC', value='PRESS')) == {'CANCELLED'}
    release.set()
    job.join(30)
    assert isinstance(job.error, sj.SolveCancelled) and job.people is None
    time.sleep(0.2)                                                       # no late write
    assert not [o for o in bpy.data.objects if o.type == 'ARMATURE']
    assert op.reports[-1] == ({'WARNING'}, "MANIKIN: solve cancelled, nothing was written")
    assert solve_op._ACTIVE["job"] is None


def test_solve_several_files_solves_a_group_file_with_one_person_seen_as_solve_full_body(addon, tmp_path, motion):
    """A file with two people of whom one is seen in too few frames: *Solve Several Files* solves
    the one seen, as *Solve Full Body* does (it refused the file before: "2 people in the file
    (0, 1): choose one")."""
    from blender_manikin.core import keypoint_layouts as kl
    from fixtures_keypoints import to_y_up
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    X = np.stack([to_y_up(clean), to_y_up(clean + [1.5, 0.0, 0.0])])
    X[1, 3:] = np.nan                            # person 1: three frames, left out
    np.save(tmp_path / "pair.npy", X)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_path, s.live_rig = 'KEYPOINTS', str(tmp_path / "pair.npy"), False
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    full = _solved_takes()
    assert sorted(full) == ["MANIKIN_body"]
    _wipe_solves()
    assert bpy.ops.manikin.solve_files(directory=str(tmp_path), files=[{"name": "pair.npy"}]) == {'FINISHED'}
    several = _solved_takes()
    assert sorted(several) == ["MANIKIN_pair"] and s.last_report.startswith("1 of 1 files solved")
    _assert_same_takes({"pair": several["MANIKIN_pair"]}, {"pair": full["MANIKIN_body"]})


def test_a_group_file_that_cannot_be_read_fails_with_the_readers_error(addon, tmp_path, motion):
    """Solve Several Files (and Solve Full Body) on a group file whose people cannot be read (one
    person's legs never seen: the units cannot be told): that file fails with the reader's
    reason, the other file is solved.  Before: the file was solved whole, which only said "3 people
    in the file (0, 1, 2): choose one", though Person was already "all"."""
    from blender_manikin.core import keypoint_layouts as kl
    from fixtures_keypoints import to_y_up
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    X = np.stack([to_y_up(clean + [1.5 * k, 0.0, 0.0]) for k in range(3)])
    lay = kl.LAYOUTS["coco17"]
    X[1][:, [lay.index(p) for p in lay.points if p.endswith(("_hip", "_knee", "_ankle"))]] = np.nan
    np.save(tmp_path / "group.npy", X)
    np.save(tmp_path / "solo.npy", to_y_up(clean))
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.live_rig = 'KEYPOINTS', False
    assert bpy.ops.manikin.solve_files(directory=str(tmp_path), files=[{"name": "solo.npy"}, {"name": "group.npy"}]) \
        == {'FINISHED'}
    assert sorted(_solved_takes()) == ["MANIKIN_solo"]
    assert s.last_report.startswith("1 of 2 files solved") and "cannot tell the units" in s.last_report, \
        s.last_report
    assert "choose one" not in s.last_report
    _wipe_solves()
    s.keypoint_path = str(tmp_path / "group.npy")
    with pytest.raises(RuntimeError, match="group.npy: cannot tell the units"):
        bpy.ops.manikin.solve_full_body('EXEC_DEFAULT')
    assert "cannot tell the units" in s.last_report and "choose one" not in s.last_report, s.last_report
    assert not _solved_takes()


def test_panel_reads_the_folder_of_a_picked_per_frame_json_file(addon, tmp_path, motion):
    """A file browser picks files: one EasyMocap frame file picked in the panel is read as its
    folder, the take (it was refused, 'give its folder'); the command line still names the
    folder rather than guess, so a glob of frame files is not solved once per file."""
    import json
    from blender_manikin.core import keypoint_layouts as kl
    from blender_manikin.core.io_keypoints import frames_folder_of
    from blender_manikin.core.recording import RecordingError
    body, pos, world = motion
    points = kl.keypoints_from_body22(pos, world, "body25", body.stature)
    folder = tmp_path / "out" / "keypoints3d"
    folder.mkdir(parents=True)
    for f, k in enumerate(points):
        (folder / f"{f:06d}.json").write_text(json.dumps([{"id": 0, "keypoints3d": [list(p) + [1.0] for p in k]}]))
    picked = folder / "000012.json"
    assert frames_folder_of(picked) == str(folder)
    assert frames_folder_of(folder) is None and frames_folder_of(tmp_path / "missing.json") is None
    with pytest.raises(RecordingError, match="give its folder"):
        solve_recording(str(picked), SolveSettings(fps=30.0))
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.keypoint_from, s.keypoint_path = 'KEYPOINTS', 'FILE', str(picked)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}, s.last_report
    assert "90 EasyMocap JSON files" in s.last_report, s.last_report
    action = s.armature.animation_data.action
    frames = [kp.co[0] for fc in keying.action_fcurves(action, s.armature) for kp in fc.keyframe_points]
    assert max(frames) - min(frames) == pytest.approx(89)
