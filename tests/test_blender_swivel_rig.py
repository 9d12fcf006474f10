"""Live swivel rig (real Blender): live pose = numpy FK, swivel edits, hand/foot controls,
hinges, reach, save/reload (also without the add-on), bake to FK, render, swivel tools."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import armature as am  # noqa: E402
from blender_manikin.blender import keying, live_rig as lr, writer  # noqa: E402
from blender_manikin.core import limb_solver as ls  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.pose_result import PoseResult  # noqa: E402

from blender_util import evaluated_heads, fresh_scene, smooth_local_rotations  # noqa: E402

T = 24
TOL = 1e-4          # 0.1 mm
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def consistent_result(T=T, seed=0, fps=24.0, stature=1.75, pronation=0.6):
    """A PoseResult whose limbs come from ``solve_limbs`` (as the pipeline's do): smooth random
    torso, wrist/ankle targets from a random FK pose, swivel = measured + a smooth offset,
    hands with up to ±``pronation`` rad extra twist (so the forearm twist is exercised)."""
    body = sk.make_body(stature)
    local = smooth_local_rotations(T, seed, spread=0.5)
    t = np.arange(T) / fps
    root = body.root_rest + np.stack([0.2 * np.sin(t), 0.3 * t, 0.03 * np.sin(3 * t)], -1)
    pos, wrot = sk.forward_kinematics(local, root, body)
    rng = np.random.default_rng(seed + 1)
    end_rot = wrot[:, ls.LIMB_END].copy()
    for li in (0, 1):
        ang = pronation * np.sin(2 * np.pi * (0.7 + 0.3 * li) * t + rng.uniform(0, 6))
        end_rot[:, li] = end_rot[:, li] @ rot.axis_angle_rotation(np.broadcast_to(ls.A0[li], (T, 3)), ang)
    sw = ls.swivel_from_positions(pos[:, ls.LIMB_BASE], pos[:, ls.LIMB_MID], pos[:, ls.LIMB_END],
                                  wrot[:, ls.LIMB_PARENT])
    sw = sw + 0.4 * np.sin(np.pi * t[:, None] + np.arange(4))
    sol = ls.solve_limbs(pos[:, ls.LIMB_BASE], pos[:, ls.LIMB_END], sw, body.limb_lengths(),
                         wrot[:, ls.LIMB_PARENT], end_rot=end_rot)
    local = local.copy()
    local[:, ls.LIMB_BASE] = sol.base_local
    local[:, ls.LIMB_MID] = sol.mid_local
    local[:, ls.LIMB_END] = sol.end_local
    return PoseResult(fps=fps, body=body, local_rot=local, root_pos=root, swivel=sw,
                      contacts=np.zeros((T, 2), bool))


@pytest.fixture
def live():
    """(result, armature, solve action, live action, frames) on a fresh scene at 24 fps."""
    scene = fresh_scene()
    scene.render.fps, scene.render.fps_base = 24, 1.0
    res = consistent_result()
    out = writer.write_result(res, writer.WriteOptions(frame_start=3))
    action = lr.build_live_rig(out.armature, res)
    return res, out.armature, out.action, action, out.frames


def analytic_mid(res, k, li, swivel, end_pos=None):
    """Elbow/knee world position for ``swivel`` on frame k (limb_solver.mid_from_swivel)."""
    pos, wrot = res.fk()
    _, b, m, e = sk.LIMBS[li]
    end = pos[k, e] if end_pos is None else end_pos
    return ls.mid_from_swivel(pos[k, [b]], np.asarray(end)[None], np.array([swivel]),
                              res.body.limb_lengths()[[li]], wrot[k, [sk.PARENTS[b]]], limb_ids=[li])[0]


def pose_now(obj):
    """World heads (22, 3) and rotations (22, 3, 3) of the joint bones, current evaluation."""
    mw = np.array(obj.matrix_world)
    h = np.empty((sk.NUM_JOINTS, 3))
    r = np.empty((sk.NUM_JOINTS, 3, 3))
    for j, name in enumerate(sk.JOINT_NAMES):
        m = mw @ np.array(obj.pose.bones[name].matrix)
        h[j], r[j] = m[:3, 3], m[:3, :3]
    return h, r


# ---------------------------------------------------------------------------
def test_live_pose_equals_numpy_fk(live):
    res, obj, solve_action, action, frames = live
    assert lr.is_live_rig(obj)
    assert action != solve_action and obj.animation_data.action == action
    assert solve_action.use_fake_user                  # the solve action is kept, unchanged
    assert len(keying.action_fcurves(solve_action, obj)) == 22 * 4 + 3 + 4 + 2
    paths = {fc.data_path for fc in keying.action_fcurves(action, obj)}
    for r in lr.LIMB_RIGS:                             # limbs are driven, not keyed
        assert not any(f'"{n}"' in p for n in (r.base, r.mid, r.end) for p in paths)
        assert f'pose.bones["{r.ctrl}"].location' in paths
        assert not obj.data.bones[r.ctrl].use_deform
    for fc in obj.animation_data.drivers:              # no Python needed to evaluate
        assert fc.driver.is_simple_expression, fc.driver.expression
    heads, rots = evaluated_heads(obj, frames)
    pos, wrot = res.fk()
    err = np.linalg.norm(heads - pos, axis=-1)
    print(f"live vs numpy: max joint error {1e3 * err.max():.4f} mm "
          f"(elbows/knees {1e3 * err[:, ls.LIMB_MID].max():.4f}, wrists/ankles {1e3 * err[:, ls.LIMB_END].max():.4f})")
    assert err.max() < TOL
    # orientations too (forearm pronation included)
    _, B = am.rest_matrices(obj)
    assert np.abs(rots - wrot @ B[None]).max() < 1e-4


def test_swivel_key_edit_moves_mid_joint_only(live):
    """Graph-Editor style edit of one swivel key: the elbow/knee goes to the analytic position for
    the new angle; wrist/ankle position and orientation stay."""
    res, obj, _, _, frames = live
    pos, wrot = res.fk()
    k = 9
    for li, limb in enumerate(sk.LIMB_NAMES):
        fc = lr.swivel_fcurve(obj, limb)
        kp = fc.keyframe_points[k]
        assert kp.co[0] == frames[k]
        new = kp.co[1] + (1.2 if li % 2 == 0 else -0.9)
        kp.co[1] = new
        kp.handle_left[1] = new
        kp.handle_right[1] = new
        fc.update()
        bpy.context.scene.frame_set(int(frames[k]))
        h, r = pose_now(obj)
        _, b, m, e = sk.LIMBS[li]
        target = analytic_mid(res, k, li, new)
        assert np.linalg.norm(target - pos[k, m]) > 0.01          # it really moved
        assert np.linalg.norm(h[m] - target) < TOL
        assert np.linalg.norm(h[e] - pos[k, e]) < TOL
        assert np.abs(r[e] - wrot[k, e] @ am.rest_matrices(obj)[1][e]).max() < 1e-4
        assert np.linalg.norm(h[b] - pos[k, b]) < TOL


def test_slider_edit_is_live_on_current_frame(live):
    res, obj, _, _, frames = live
    k = 5
    scene = bpy.context.scene
    scene.frame_set(int(frames[k]))
    # what the slider does: set the value, RNA update tags the object (a bare ID-property
    # assignment from Python does not tag, hence update_tag)
    obj[writer.SWIVEL_PROPS["left_leg"]] = float(res.swivel[k, 2]) + 0.8
    obj.update_tag()
    bpy.context.view_layer.update()
    h, _ = pose_now(obj)
    assert np.linalg.norm(h[sk.J["left_knee"]] - analytic_mid(res, k, 2, res.swivel[k, 2] + 0.8)) < TOL
    assert np.linalg.norm(h[sk.J["left_ankle"]] - res.positions[k, sk.J["left_ankle"]]) < TOL


def test_moving_hand_control_resolves_arm_keeping_swivel(live):
    res, obj, _, _, frames = live
    k = 12
    scene = bpy.context.scene
    scene.frame_set(int(frames[k]))
    r = lr.LIMB_RIGS[1]                                       # right arm
    pb = obj.pose.bones[r.ctrl]
    B = np.array(obj.data.bones[r.ctrl].matrix_local)[:3, :3]
    delta = np.array([0.05, -0.12, 0.08])                     # world move, metres
    pb.location = np.array(pb.location) + B.T @ delta         # what G does (bone rest frame)
    bpy.context.view_layer.update()
    h, _ = pose_now(obj)
    target = res.positions[k, sk.J[r.end]] + delta
    assert np.linalg.norm(h[sk.J[r.end]] - target) < TOL
    assert np.linalg.norm(h[sk.J[r.mid]] - analytic_mid(res, k, 1, res.swivel[k, 1], target)) < TOL
    # the other limbs did not move
    for other in (0, 2, 3):
        e = sk.LIMBS[other][3]
        assert np.linalg.norm(h[e] - res.positions[k, e]) < TOL


def _hinge_parts(obj, r):
    """(swing angle about local X, off-axis swing, twist about Y) of the mid bone relative to the base."""
    pbs = obj.pose.bones
    rel = np.array(pbs[r.base].matrix)[:3, :3].T @ np.array(pbs[r.mid].matrix)[:3, :3]
    q = rot.matrix_to_quat(rel)
    sw, _, twist = rot.swing_twist(q, np.array([0.0, 1.0, 0.0]))
    aa = rot.quat_to_axis_angle(sw)
    return aa[0], math.hypot(aa[1], aa[2]), twist


def test_hinges_stay_hinges_and_limits(live):
    res, obj, _, _, frames = live
    scene = bpy.context.scene
    for k in (0, 7, 15, 23):
        scene.frame_set(int(frames[k]))
        for r in lr.LIMB_RIGS:
            flex, off_axis, twist = _hinge_parts(obj, r)
            assert off_axis < 1e-4                          # never bends sideways
            assert -1e-4 <= flex <= ls.FLEX_MAX[r.index] + 1e-4
            if not r.is_arm:
                assert abs(twist) < 1e-4                    # knees: pure X rotation
            else:
                assert abs(twist) <= ls.TWIST_RANGE[0, 1] + 1e-4
            mch = obj.pose.bones[r.lower]                   # the IK hinge itself is pure X
            q = rot.matrix_to_quat(np.array(obj.pose.bones[r.upper].matrix)[:3, :3].T
                                   @ np.array(mch.matrix)[:3, :3])
            assert np.abs(q[2:]).max() < 1e-5
    # target far too close: the elbow stops at its 150 degree limit, it never folds further
    k = 4
    scene.frame_set(int(frames[k]))
    r = lr.LIMB_RIGS[0]
    base = res.positions[k, sk.J[r.base]]
    pb = obj.pose.bones[r.ctrl]
    B = np.array(obj.data.bones[r.ctrl].matrix_local)[:3, :3]
    head = np.array(obj.data.bones[r.ctrl].head_local)
    pb.location = B.T @ (base + np.array([0.0, -0.02, 0.0]) - head)
    bpy.context.view_layer.update()
    flex, off_axis, _ = _hinge_parts(obj, r)
    assert off_axis < 1e-4 and abs(flex - ls.FLEX_MAX[0]) < 1e-3


def test_out_of_reach_target_extends_limb(live):
    res, obj, _, _, frames = live
    k = 8
    bpy.context.scene.frame_set(int(frames[k]))
    for li in (0, 3):
        r = lr.LIMB_RIGS[li]
        base = res.positions[k, sk.J[r.base]]
        l1, l2 = res.body.limb_lengths()[li]
        direction = rot.normalize(np.array([0.3, -0.8, 0.2 if li == 0 else -0.9]))
        goal = base + 1.5 * (l1 + l2) * direction
        pb = obj.pose.bones[r.ctrl]
        B = np.array(obj.data.bones[r.ctrl].matrix_local)[:3, :3]
        pb.location = B.T @ (goal - np.array(obj.data.bones[r.ctrl].head_local))
        bpy.context.view_layer.update()
        h, _ = pose_now(obj)
        assert np.linalg.norm(h[sk.J[r.end]] - (base + (l1 + l2) * direction)) < TOL
        assert np.linalg.norm(h[sk.J[r.mid]] - (base + l1 * direction)) < TOL


_NO_ADDON = r"""
import json, sys
import bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[1], use_scripts=False)
assert not any(m.startswith("blender_manikin") for m in sys.modules)
obj = bpy.data.objects[sys.argv[2]]
bag = [fc for fc in (obj.animation_data.action.fcurves if hasattr(obj.animation_data.action, "fcurves")
       else obj.animation_data.action.layers[0].strips[0].channelbag(obj.animation_data.action_slot).fcurves)
       if fc.data_path == '["swivel_left_arm"]'][0]
kp = bag.keyframe_points[int(sys.argv[3])]
kp.co[1] += 1.0; kp.handle_left[1] += 1.0; kp.handle_right[1] += 1.0
bag.update()
bpy.context.scene.frame_set(int(kp.co[0]))
mw = obj.matrix_world
print("RESULT" + json.dumps({n: list(mw @ obj.pose.bones[n].head) for n in ("left_elbow", "left_wrist")}))
"""


def test_save_reload_and_without_addon(live, tmp_path):
    from blender_manikin.operators import swivel_tools
    from blender_manikin.panels import swivel_panel
    res, obj, _, _, frames = live
    name = obj.name
    path = str(tmp_path / "live.blend")
    swivel_tools.register()
    swivel_panel.register()
    bpy.ops.wm.save_as_mainfile(filepath=path)
    swivel_panel.unregister()
    swivel_tools.unregister()                   # the add-on's classes are gone from here on
    bpy.ops.wm.open_mainfile(filepath=path)
    obj = bpy.data.objects[name]
    k = 6
    fc = lr.swivel_fcurve(obj, "right_leg")
    kp = fc.keyframe_points[k]
    new = kp.co[1] - 1.3
    kp.co[1] = new
    kp.handle_left[1] = kp.handle_right[1] = new
    fc.update()
    bpy.context.scene.frame_set(int(frames[k]))
    h, _ = pose_now(obj)
    assert np.linalg.norm(h[sk.J["right_knee"]] - analytic_mid(res, k, 3, new)) < TOL
    assert np.linalg.norm(h[sk.J["right_ankle"]] - res.positions[k, sk.J["right_ankle"]]) < TOL
    # a separate Blender that never imports blender_manikin, with Python auto-run disabled
    k = 11
    proc = subprocess.run([sys.executable, "-c", _NO_ADDON, path, name, str(k)], capture_output=True,
                          text=True, timeout=120, cwd=str(tmp_path))
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.split("RESULT", 1)[1].strip().splitlines()[0])
    fc0 = float(res.swivel[k, 0])
    keyed = writer.unwrap_swivel(res.swivel)[k, 0]
    assert abs(np.angle(np.exp(1j * (keyed - fc0)))) < 1e-6
    assert np.linalg.norm(np.array(out["left_elbow"]) - analytic_mid(res, k, 0, keyed + 1.0)) < TOL
    assert np.linalg.norm(np.array(out["left_wrist"]) - res.positions[k, sk.J["left_wrist"]]) < TOL


def test_bake_matches_live(live):
    res, obj, _, _, frames = live
    k = 3
    fc = lr.swivel_fcurve(obj, "left_arm")       # an edited swivel must be baked too
    fc.keyframe_points[k].co[1] += 0.7
    fc.update()
    f0, f1 = int(frames[0]), int(frames[-1])
    baked = lr.bake_live_rig(obj, f0, f1)
    assert baked != obj and baked.type == 'ARMATURE'
    assert sorted(b.name for b in baked.data.bones) == sorted(sk.JOINT_NAMES)
    assert all(len(pb.constraints) == 0 for pb in baked.pose.bones)
    assert baked.animation_data.drivers.__len__() == 0
    fcs = keying.action_fcurves(baked.animation_data.action, baked)
    assert len(fcs) == 22 * 4 + 3
    assert all(len(fc.keyframe_points) == f1 - f0 + 1 for fc in fcs)
    live_h, live_r = evaluated_heads(obj, frames)
    bake_h, bake_r = evaluated_heads(baked, frames)
    err = np.linalg.norm(bake_h - live_h, axis=-1).max()
    print(f"baked vs live: max joint error {1e3 * err:.4f} mm")
    assert err < TOL
    assert np.abs(bake_r - live_r).max() < 1e-4
    assert np.linalg.norm(live_h[k, sk.J["left_elbow"]] - res.positions[k, sk.J["left_elbow"]]) > 0.03


def test_render_one_frame_workbench(live, tmp_path):
    res, obj, _, _, frames = live
    scene = bpy.context.scene
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    cam.location = (0.0, -6.0, 1.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.camera = cam
    scene.render.engine = 'BLENDER_WORKBENCH'
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.resolution_percentage = 100
    scene.render.filepath = str(tmp_path / "frame.png")
    scene.frame_set(int(frames[4]))
    lr.swivel_fcurve(obj, "right_arm").keyframe_points[4].co[1] += 0.5
    bpy.ops.render.render(write_still=True)
    assert os.path.getsize(str(tmp_path / "frame.png")) > 0


def test_key_swivel_keeps_other_sliders_unkeyed_edits(live):
    """Key Swivel writes its key as Blender's own Insert Keyframe does (an animation update that
    does not evaluate the rig's animation again): an unkeyed edit of another slider stays after
    the scene is evaluated, and the same tag is what Ctrl+Z replays (tools/gui_userdata_check.py
    shows the keyed slider's unkeyed value kept after Ctrl+Z in a real window)."""
    from blender_manikin.operators import swivel_tools
    res, obj, _, _, frames = live
    swivel_tools.register()
    try:
        scene = bpy.context.scene
        bpy.context.view_layer.objects.active = obj
        k = 7
        scene.frame_set(int(frames[k]))
        fc = lr.swivel_fcurve(obj, "left_arm")
        fc.keyframe_points[k + 1].interpolation = 'BEZIER'
        fc.keyframe_points[k].interpolation = 'CONSTANT'
        fc.keyframe_points[k].type = 'BREAKDOWN'
        fc.update()
        bpy.context.view_layer.update()
        right = obj[writer.SWIVEL_PROPS["right_arm"]] + 0.7
        obj[writer.SWIVEL_PROPS["right_arm"]] = right       # moved, not keyed
        obj[writer.SWIVEL_PROPS["left_arm"]] = 2.5
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        bpy.context.view_layer.update()
        assert abs(obj[writer.SWIVEL_PROPS["right_arm"]] - right) < 1e-6
        # the key as before: value set, its own attributes kept, the evaluated rig shows it
        kp = lr.swivel_fcurve(obj, "left_arm").keyframe_points
        assert len(kp) == T and abs(kp[k].co[1] - 2.5) < 1e-6
        assert (kp[k].interpolation, kp[k].type, kp[k + 1].interpolation) == ('CONSTANT', 'BREAKDOWN', 'BEZIER')
        scene.frame_set(int(frames[k + 2]))
        scene.frame_set(int(frames[k]))
        assert abs(obj[writer.SWIVEL_PROPS["left_arm"]] - 2.5) < 1e-6
        # a new key between frames: the interpolation of the key before it
        scene.frame_set(int(frames[k]), subframe=0.5)
        obj[writer.SWIVEL_PROPS["left_arm"]] = 1.25
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        kp = lr.swivel_fcurve(obj, "left_arm").keyframe_points
        assert len(kp) == T + 1
        assert abs(kp[k + 1].co[0] - (frames[k] + 0.5)) < 1e-4 and abs(kp[k + 1].co[1] - 1.25) < 1e-6
        assert kp[k + 1].interpolation == 'CONSTANT'
        assert abs(lr.swivel_fcurve(obj, "left_arm").evaluate(frames[k] + 0.5) - 1.25) < 1e-6
    finally:
        swivel_tools.unregister()


def test_swivel_tools_operators(live):
    from blender_manikin.operators import swivel_tools
    from blender_manikin.panels import swivel_panel
    res, obj, _, _, frames = live
    swivel_tools.register()
    swivel_panel.register()
    try:
        scene = bpy.context.scene
        bpy.context.view_layer.objects.active = obj
        solved = writer.unwrap_swivel(res.swivel)
        # key: a slider edit on frame k becomes a key
        k = 10
        scene.frame_set(int(frames[k]))
        obj[writer.SWIVEL_PROPS["left_arm"]] = 2.5
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        f, v = lr.read_keys(lr.swivel_fcurve(obj, "left_arm"))
        assert len(f) == T and abs(v[k] - 2.5) < 1e-6
        scene.frame_set(int(frames[k + 1]))
        scene.frame_set(int(frames[k]))
        assert abs(obj[writer.SWIVEL_PROPS["left_arm"]] - 2.5) < 1e-6
        # smooth: a spike on one key is spread out; range respected
        scene.frame_start, scene.frame_end = int(frames[4]), int(frames[16])
        assert bpy.ops.manikin.smooth_swivel(limb='left_arm', sigma=2.0) == {'FINISHED'}
        f2, v2 = lr.read_keys(lr.swivel_fcurve(obj, "left_arm"))
        assert abs(v2[k] - 2.5) > 0.1
        outside = (f2 < frames[4]) | (f2 > frames[16])
        np.testing.assert_allclose(v2[outside], v[outside], atol=1e-6)
        ref = lr.smooth_values(f, v, 2.0, 'GAUSSIAN', ~outside)
        np.testing.assert_allclose(v2, ref, atol=1e-5)
        # reset: back to the solved curve
        assert bpy.ops.manikin.reset_swivel(limb='ALL', scope='ALL') == {'FINISHED'}
        for li, limb in enumerate(sk.LIMB_NAMES):
            f3, v3 = lr.read_keys(lr.swivel_fcurve(obj, limb))
            np.testing.assert_allclose(v3, solved[:, li], atol=1e-6)
        heads, _ = evaluated_heads(obj, frames[[k]])
        assert np.abs(heads[0] - res.positions[k]).max() < TOL
        # bake through the operator
        n_obj = len(bpy.data.objects)
        assert bpy.ops.manikin.bake_live_rig(use_scene_range=True) == {'FINISHED'}
        assert len(bpy.data.objects) == n_obj + 1
    finally:
        swivel_panel.unregister()
        swivel_tools.unregister()


def test_swivel_tools_keep_the_animators_other_keys(live):
    """Key / Smooth / Reset Swivel change the keys they are about and no other: the interpolation,
    handles, key type and easing an animator gave other keys of the curve in the Graph Editor stay."""
    from blender_manikin.operators import swivel_tools
    res, obj, _, _, frames = live
    swivel_tools.register()
    try:
        scene = bpy.context.scene
        bpy.context.view_layer.objects.active = obj
        fc = lr.swivel_fcurve(obj, "left_arm")
        kp = fc.keyframe_points
        kp[2].interpolation = 'BEZIER'
        kp[2].handle_right_type = kp[2].handle_left_type = 'FREE'
        kp[2].handle_right = (kp[2].co[0] + 0.5, kp[2].co[1] + 0.7)
        kp[3].interpolation = 'CONSTANT'
        kp[4].type = 'BREAKDOWN'
        kp[5].easing = 'EASE_IN'
        fc.update()

        def edited():
            k = lr.swivel_fcurve(obj, "left_arm").keyframe_points
            return (k[2].interpolation, k[2].handle_right_type, tuple(k[2].handle_right), k[3].interpolation,
                    k[4].type, k[5].easing, [tuple(k[i].co) for i in range(2, 6)])
        before = edited()
        # a slider edit keyed on a later frame
        scene.frame_set(int(frames[15]))
        obj[writer.SWIVEL_PROPS["left_arm"]] = 1.5
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        f, v = lr.read_keys(lr.swivel_fcurve(obj, "left_arm"))
        assert len(f) == T and abs(v[15] - 1.5) < 1e-6
        assert edited() == before
        # smoothing frames 12-20 and resetting the current frame leave keys 2-5 as they were
        scene.frame_start, scene.frame_end = int(frames[12]), int(frames[20])
        assert bpy.ops.manikin.smooth_swivel(limb='left_arm', sigma=2.0) == {'FINISHED'}
        assert edited() == before
        assert bpy.ops.manikin.reset_swivel(limb='left_arm', scope='CURRENT') == {'FINISHED'}
        f, v = lr.read_keys(lr.swivel_fcurve(obj, "left_arm"))
        assert len(f) == T and abs(v[15] - writer.unwrap_swivel(res.swivel)[15, 0]) < 1e-5
        assert edited() == before
    finally:
        swivel_tools.unregister()


def test_swivel_tools_in_nla_tweak_mode_key_the_strips_frame(live):
    """The take pushed into an NLA strip moved to start at frame 101, edited in tweak mode (Tab):
    Key Swivel keys the action frame the strip shows at the current frame (as Blender's own
    keying does), so the edit shows there; Reset on the current frame restores that key."""
    from blender_manikin.operators import swivel_tools
    res, obj, _, action, frames = live
    swivel_tools.register()
    try:
        scene = bpy.context.scene
        bpy.context.view_layer.objects.active = obj
        ad = obj.animation_data
        ad.action = None
        strip = ad.nla_tracks.new().strips.new("take", 101, action)
        ad.use_tweak_mode = True
        assert ad.use_tweak_mode and ad.action == action
        k = 7
        shown = int(round(strip.frame_start + frames[k] - action.frame_range[0]))
        prop = writer.SWIVEL_PROPS["left_arm"]
        scene.frame_set(shown)
        solved = float(obj[prop])
        assert abs(solved - writer.unwrap_swivel(res.swivel)[k, 0]) < 1e-5
        obj[prop] = solved + 1.0
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        f, v = lr.read_keys(lr.swivel_fcurve(obj, "left_arm"))
        assert len(f) == T and f.max() == frames[-1]          # no key past the take
        assert abs(v[k] - (solved + 1.0)) < 1e-6
        scene.frame_set(shown)
        assert abs(float(obj[prop]) - (solved + 1.0)) < 1e-5
        assert bpy.ops.manikin.reset_swivel(limb='left_arm', scope='CURRENT') == {'FINISHED'}
        scene.frame_set(shown)
        assert abs(float(obj[prop]) - solved) < 1e-5
    finally:
        ad.use_tweak_mode = False
        swivel_tools.unregister()


def test_swivel_tools_on_a_slotted_action_without_the_objects_slot_are_refused(live):
    """Blender 4.4+ slotted actions.  A linked duplicate (Shift+D) shares the action and its slot:
    a swivel keyed on one shows on both, as in any shared action.  An object whose action has
    no slot of it assigned (here the original, its slot now only the duplicate's) is refused by
    Key / Smooth / Reset with a message, and the duplicate's keys are left as they were (the
    slot found by the object's name is the duplicate's)."""
    from blender_manikin.operators import swivel_tools
    res, obj, _, action, frames = live
    if not keying.is_slotted(action):
        pytest.skip("legacy actions (Blender < 4.4) have no slots")
    scene = bpy.context.scene
    prop = writer.SWIVEL_PROPS["left_arm"]
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    swivel_tools.register()
    try:
        assert bpy.ops.object.duplicate(linked=True) == {'FINISHED'}
        dup = bpy.context.active_object
        assert dup != obj and dup.animation_data.action_slot == obj.animation_data.action_slot
        k = 6
        scene.frame_set(int(frames[k]))
        solved = float(obj[prop])
        dup[prop] = solved + 1.0
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        scene.frame_set(int(frames[k]))
        assert abs(float(obj[prop]) - (solved + 1.0)) < 1e-5          # shared slot: shared keys
        obj.animation_data.action_slot = None
        bpy.context.view_layer.objects.active = obj
        keys = lr.read_keys(lr.swivel_fcurve(dup, "left_arm"))
        obj[prop] = solved - 1.0
        for op in (bpy.ops.manikin.key_swivel, bpy.ops.manikin.smooth_swivel, bpy.ops.manikin.reset_swivel):
            with pytest.raises(RuntimeError, match="no slot of it assigned"):
                op(limb='left_arm')
        after = lr.read_keys(lr.swivel_fcurve(dup, "left_arm"))
        assert np.array_equal(keys[0], after[0]) and np.array_equal(keys[1], after[1])
        assert [s.identifier for s in action.slots] == [dup.animation_data.action_slot.identifier]
    finally:
        swivel_tools.unregister()


def test_make_live_from_fk_solve_operator():
    """The 'Make Live Rig' button reads a plain solve action back and converts it exactly."""
    from blender_manikin.operators import swivel_tools
    scene = fresh_scene()
    scene.render.fps, scene.render.fps_base = 24, 1.0
    res = consistent_result(T=12, seed=3)
    out = writer.write_result(res, writer.WriteOptions(frame_start=1))
    obj = out.armature
    swivel_tools.register()
    try:
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.manikin.make_live_rig() == {'FINISHED'}
    finally:
        swivel_tools.unregister()
    assert lr.is_live_rig(obj) and obj.animation_data.action != out.action
    heads, _ = evaluated_heads(obj, out.frames)
    assert np.linalg.norm(heads - res.positions, axis=-1).max() < TOL
    # re-running on a live rig is idempotent
    lr.build_live_rig(obj, res, frames=out.frames)
    assert sum(1 for b in obj.data.bones if b.name.startswith("ctrl_")) == 4
    heads, _ = evaluated_heads(obj, out.frames)
    assert np.linalg.norm(heads - res.positions, axis=-1).max() < TOL


def test_smooth_values_unwraps():
    f = np.arange(10.0)
    v = np.where(f < 5, 3.1, -3.1)            # crosses ±pi: the mean must stay near pi
    out = lr.smooth_values(f, v, 2.0, 'BOX')
    assert np.all(np.abs(np.angle(np.exp(1j * (out - np.pi)))) < 0.1)


class _FakeLayout:
    """Records what a panel draws (no UI in background mode)."""
    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        if name in ("row", "column", "box", "split"):
            return lambda *a, **k: _FakeLayout(self.log)
        if name in ("prop", "label", "separator"):
            return lambda *a, **k: self.log.append((name, a, k))
        if name == "operator":
            def op(idname, **k):
                self.log.append(("operator", idname, k))
                return type("OpProps", (), {})()
            return op
        raise AttributeError(name)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


def test_panel_draws_sliders_and_tools(live):
    from blender_manikin.panels import swivel_panel
    from blender_manikin.operators import swivel_tools
    res, obj, _, _, _ = live
    bpy.context.view_layer.objects.active = obj
    swivel_tools.register()
    swivel_panel.register()
    try:
        assert swivel_panel.MANIKIN_PT_swivel.poll(bpy.context)
        log = []
        fake = type("P", (), {"layout": _FakeLayout(log)})()
        swivel_panel.MANIKIN_PT_swivel.draw(fake, bpy.context)
        props = [a[1] for kind, a, k in log if kind == "prop"]
        assert props == [f'["swivel_{limb}"]' for limb in sk.LIMB_NAMES]
        ops = {a for kind, a, k in log if kind == "operator"}
        assert {"manikin.key_swivel", "manikin.smooth_swivel", "manikin.reset_swivel",
                "manikin.bake_live_rig"} <= ops
        for idname in ops:
            mod, name = idname.split(".")
            assert hasattr(getattr(bpy.ops, mod), name)
    finally:
        swivel_panel.unregister()
        swivel_tools.unregister()


def test_never_writes_into_the_current_action(live):
    res, obj, solve_action, action, frames = live
    keying.assign_action(obj, solve_action)
    with pytest.raises(ValueError):
        lr.build_live_rig(obj, res, action=solve_action)
    assert len(keying.action_fcurves(solve_action, obj)) == 22 * 4 + 3 + 4 + 2
    # the rig can be muted to play the plain FK solve again
    assert lr.set_rig_enabled(obj, False) > 0
    heads, _ = evaluated_heads(obj, frames[:3])
    assert np.abs(heads - res.positions[:3]).max() < TOL
    lr.set_rig_enabled(obj, True)
    lr.build_live_rig(obj, res, action=action)            # its own live action may be rewritten
    assert obj.animation_data.action == action


@pytest.mark.parametrize("blend", ["ADD", "COMBINE", "REPLACE_HALF", "ACTIVE_OVER_TRACK"])
def test_key_swivel_through_nla_blending_keys_what_the_slider_shows(live, blend):
    """The take is an NLA strip edited in tweak mode over a base track keying the swivel at 0.5 rad
    (blended Add, Combine, or Replace with influence 0.5), or the take is the active action
    blended at influence 0.5 over that track: Key Swivel keys the strip value that makes Blender
    *show* the slider's value (as Blender's own keying remaps it), the other limbs' unkeyed
    edits are kept, and a strip that has no effect there is refused with a message."""
    from blender_manikin.operators import swivel_tools
    res, obj, _, action, frames = live
    scene = bpy.context.scene
    bpy.context.view_layer.objects.active = obj
    ad = obj.animation_data
    prop, other = writer.SWIVEL_PROPS["left_arm"], writer.SWIVEL_PROPS["right_leg"]
    base = keying.new_action("base")
    keying.assign_action(obj, base)
    keying.set_keys(keying.ensure_fcurve(base, f'["{prop}"]', 0, "", obj), [0, 200], [0.5, 0.5])
    ad.action = None
    ad.nla_tracks.new().strips.new("base", 1, base)
    if blend == "ACTIVE_OVER_TRACK":
        keying.assign_action(obj, action)
        ad.action_influence = 0.5
    else:
        track = ad.nla_tracks.new()
        strip = track.strips.new("take", int(frames[0]), action)   # strip frame = action frame
        strip.blend_type = 'ADD' if blend == "ADD" else 'COMBINE' if blend == "COMBINE" else 'REPLACE'
        if blend == "REPLACE_HALF":
            strip.use_animated_influence = True
            strip.fcurves[0].keyframe_points.insert(int(frames[9]), 0.5)
        ad.nla_tracks.active = track
        ad.use_tweak_mode = True
        assert ad.use_tweak_mode and ad.action == action
    swivel_tools.register()
    try:
        k = 9
        scene.frame_set(int(frames[k]))
        before = float(obj[prop])
        assert abs(before - writer.unwrap_swivel(res.swivel)[k, 0]) > 0.05     # the blend shows
        obj[prop] = before + 1.0
        obj[other] = float(obj[other]) + 0.25                                # an unkeyed edit
        edit = float(obj[other])
        assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
        assert abs(float(obj[other]) - edit) < 1e-6
        for f in (int(frames[k]), int(frames[k + 3]), int(frames[k])):
            scene.frame_set(f)
        assert abs(float(obj[prop]) - (before + 1.0)) < 1e-5
        fk, v = lr.read_keys(lr.swivel_fcurve(obj, "left_arm"))
        assert len(fk) == T
        if blend in ("ADD", "COMBINE"):
            assert abs(v[k] - (before + 1.0 - 0.5)) < 1e-5
        if blend == "ADD":
            lr.swivel_fcurve(obj, "left_arm").mute = True    # the strip shows nothing: refused
            with pytest.raises(RuntimeError, match="cannot be keyed"):
                bpy.ops.manikin.key_swivel(limb='left_arm')
    finally:
        ad.use_tweak_mode = False
        swivel_tools.unregister()
