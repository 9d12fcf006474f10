"""Keypoints from an animated armature (the Keypoints source's *Armature*,
blender/scene_trackers.py sample_armature_keypoints, core/rig_keypoints.py): a Mixamo-named
character keyed with a known motion is solved, and the MANIKIN armature's joints follow its
bones' heads."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying  # noqa: E402
from blender_manikin.core import bone_maps, rotations as rot  # noqa: E402
from blender_manikin.core.skeleton import JOINT_NAMES  # noqa: E402

from blender_util import mixamo_style_character  # noqa: E402

T = 60
MIXAMO = bone_maps.preset("mixamo").bones


def _deltas(t):
    """joint -> ``(T, 3, 3)`` rotation of its bone relative to its parent's, about armature axes
    (the character faces -Y, +X its left): a walk-like swing of the legs with bending knees, the
    elbows bending forward, the trunk bending and turning, the hips travelling and bobbing."""
    w = 2.0 * np.pi * t / T
    X, Y, Z = np.eye(3)
    R = rot.axis_angle_rotation
    ones = np.ones_like(t)
    return {
        "pelvis": R(np.broadcast_to(Z, (len(t), 3)), 0.3 * np.sin(w)),
        "spine2": R(np.broadcast_to(X, (len(t), 3)), -0.25 * (1 - np.cos(w))),
        "left_hip": R(np.broadcast_to(X, (len(t), 3)), -0.5 * np.sin(w)),
        "right_hip": R(np.broadcast_to(X, (len(t), 3)), 0.5 * np.sin(w)),
        "left_knee": R(np.broadcast_to(X, (len(t), 3)), 0.9 * (1 - np.cos(w)) * ones),
        "right_knee": R(np.broadcast_to(X, (len(t), 3)), 0.6 * (1 + np.sin(w))),
        "left_elbow": R(np.broadcast_to(Z, (len(t), 3)), -0.8 * (1 - np.cos(w)) - 0.2),
        "right_elbow": R(np.broadcast_to(Z, (len(t), 3)), 0.5 * (1 + np.sin(w)) + 0.2),
        "left_shoulder": R(np.broadcast_to(Y, (len(t), 3)), 0.4 * np.sin(w)),
    }


def animate(obj, frames=T):
    """Key ``obj``'s bones (quaternions, frames 1..T) with :func:`_deltas` and its hips' location,
    in the character's own frame (its facing, the object's turn and scale taken out).  Returns the
    action."""
    t = np.arange(frames, dtype=np.float64)
    W = np.array(obj.matrix_world, np.float64)[:3, :3]
    scale = np.linalg.norm(W[:, 0])
    head, hips_ = (np.array(obj.data.bones[MIXAMO[j]].head_local) for j in ("head", "pelvis"))
    F = np.diag([1.0, 1.0, 1.0])
    left = W @ (np.array(obj.data.bones[MIXAMO["left_hip"]].head_local) - hips_)
    if left[0] < 0:                                     # facing +Y: turned half-way round
        F = np.diag([-1.0, -1.0, 1.0])
    assert (W @ (head - hips_))[2] > 0
    C = (W / scale).T @ F                               # the character's frame → armature axes
    act = keying.new_action(f"{obj.name}_take")
    keying.assign_action(obj, act)
    channels = []
    for joint, D in _deltas(t).items():
        pb = obj.pose.bones[MIXAMO[joint]]
        Rr = np.array(pb.bone.matrix_local, np.float64)[:3, :3]      # rest, armature space
        D = C @ D @ C.T
        q = rot.matrix_to_quat(np.einsum("ji,tjk,kl->til", Rr, D, Rr))   # Rr^T D Rr
        q = rot.quat_continuous(q, axis=0)
        pb.rotation_mode = 'QUATERNION'
        channels += [(f'pose.bones["{pb.name}"].rotation_quaternion', i, pb.name, q[:, i]) for i in range(4)]
    hips = obj.pose.bones[MIXAMO["pelvis"]]
    Rr = np.array(hips.bone.matrix_local, np.float64)[:3, :3]
    travel = np.stack([0.3 * np.sin(2 * np.pi * t / T), -0.8 * t / T, -0.04 * (1 - np.cos(4 * np.pi * t / T))], -1)
    loc = (travel @ C.T / scale) @ Rr                                      # → armature → the bone's rest axes
    channels += [(f'pose.bones["{hips.name}"].location', i, hips.name, loc[:, i]) for i in range(3)]
    keying.key_channels(act, obj, np.arange(1, frames + 1, dtype=np.float64), channels)
    return act


def heads(obj, frame, names):
    bpy.context.scene.frame_set(frame)
    W = np.array(obj.matrix_world)
    return np.array([(W @ np.append(np.array(obj.pose.bones[n].head), 1.0))[:3] for n in names])


def _scene():
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    sc.frame_start, sc.frame_end = 1, T
    return sc


def _bend_axis(arm, parent, child, frames):
    """``(angles (F,), axes (F, 3))``: the bend of ``child`` against ``parent`` on ``frames``, the
    angle between the two bones and the normal of their plane, in the parent's frame (a forearm's
    own twist, the hand's roll carried by it, left out)."""
    angles, axes = [], []
    pb_p, pb_c = arm.pose.bones[parent], arm.pose.bones[child]
    for f in frames:
        bpy.context.scene.frame_set(f)
        Mp, Mc = np.array(pb_p.matrix)[:3, :3], np.array(pb_c.matrix)[:3, :3]
        yc = Mp.T @ Mc[:, 1]                       # the child's axis in the parent's frame
        ax = np.cross([0.0, 1.0, 0.0], yc)
        angles.append(np.arctan2(np.linalg.norm(ax), yc[1]))
        axes.append(ax / max(np.linalg.norm(ax), 1e-12))
    return np.array(angles), np.array(axes)


def _limb_angle(P, a, b, c):
    u, v = P[a] - P[b], P[c] - P[b]
    return np.degrees(np.arccos(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1, 1)))


@pytest.mark.parametrize("fbx_cm", [False, True])
def test_the_solve_follows_the_armature_bones(addon, fbx_cm):
    sc = _scene()
    ch = mixamo_style_character("Hero", fbx_cm=fbx_cm)
    act = animate(ch)
    # the source's state, to check that nothing of it changes
    bpy.ops.object.select_all(action='DESELECT')
    ch.select_set(True)
    bpy.context.view_layer.objects.active = ch
    sc.frame_set(7)
    before_pose = {pb.name: tuple(pb.rotation_quaternion) + tuple(pb.location) for pb in ch.pose.bones}
    before_keys = [tuple(fc.keyframe_points[k].co) for fc in keying.action_fcurves(act, ch)
                   for k in (0, len(fc.keyframe_points) - 1)]
    s = sc.manikin
    s.source, s.keypoint_from, s.keypoint_armature = 'KEYPOINTS', 'ARMATURE', ch
    s.live_rig, s.reuse_armature = True, False      # default settings: Shoe Soles 3 cm, Floor Auto (kept)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}, s.last_report
    assert s.last_report.startswith("keypoints: 22 joints from armature 'Hero' (mixamo map, guessed); ")
    assert f"; {T} frames at 30 fps" in s.last_report
    # untouched: action, keys, pose at the current frame, the frame
    assert ch.animation_data.action == act and sc.frame_current == 7
    assert [tuple(fc.keyframe_points[k].co) for fc in keying.action_fcurves(act, ch)
            for k in (0, len(fc.keyframe_points) - 1)] == before_keys
    assert {pb.name: tuple(pb.rotation_quaternion) + tuple(pb.location) for pb in ch.pose.bones} == before_pose
    out = s.armature
    assert out is not ch
    # the MANIKIN joints on the source bones' heads
    frames = range(1, T + 1, 3)
    err, bend = [], []
    for f in frames:
        src = heads(ch, f, [MIXAMO[j] for j in JOINT_NAMES])
        got = heads(out, f, JOINT_NAMES)
        err.append(np.linalg.norm(src - got, axis=-1))
        J = {j: k for k, j in enumerate(JOINT_NAMES)}
        bend.append([(_limb_angle(P, J[f"{s_}_{a}"], J[f"{s_}_{b}"], J[f"{s_}_{c}"]))
                     for P in (src, got) for s_ in ("left", "right")
                     for a, b, c in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle"))])
    err = np.array(err)
    assert err.max() < 0.005 and err.mean() < 0.001, (err.max(), err.mean())      # 5 mm, 1 mm mean
    bend = np.array(bend)
    np.testing.assert_allclose(bend[:, 4:], bend[:, :4], atol=5.0)   # bend, degrees (a planted ankle held: 4.2)
    # elbows and knees are hinges: each bends about one axis of its parent bone (the forearm's
    # twist, a source's hand roll carried, aside)
    for parent, child in (("left_shoulder", "left_elbow"), ("right_shoulder", "right_elbow"),
                          ("left_hip", "left_knee"), ("right_hip", "right_knee")):
        ang, ax = _bend_axis(out, parent, child, frames)
        bent = ang > np.radians(15)
        assert bent.sum() >= 5
        assert np.abs(ax[bent] @ ax[bent][0]).min() > 0.999, (child, ax[bent])


def test_joints_without_bones_are_placed_and_said(addon):
    sc = _scene()
    ch = mixamo_style_character("Hero")
    animate(ch)
    from blender_manikin.blender.scene_trackers import sample_armature_keypoints
    import json
    import tempfile
    import os
    m = dict(MIXAMO)
    for j in ("spine1", "spine3", "left_collar", "right_collar"):
        del m[j]
    path = os.path.join(tempfile.mkdtemp(), "one_spine.json")
    with open(path, "w") as f:
        json.dump({"name": "one_spine", "bones": m}, f)
    rec = sample_armature_keypoints(sc, ch, 1, T, "file", path)
    assert ("keypoints: 22 joints from armature 'Hero' (map 'one_spine' from one_spine.json; without a bone: "
            "spine1, spine3 along the spine chain; left_collar, right_collar from the neck and shoulder "
            "(rest body))") in rec.metadata["detected"]
    from blender_manikin.core.skeleton import J
    P = rec.points
    np.testing.assert_allclose(P[:, J["spine1"]], 0.5 * (P[:, J["pelvis"]] + P[:, J["spine2"]]), atol=1e-9)
    np.testing.assert_allclose(P[:, J["spine3"]], 0.5 * (P[:, J["spine2"]] + P[:, J["neck"]]), atol=1e-9)
    src = np.array([heads(ch, f, [MIXAMO["left_collar"]])[0] for f in (1, 30)])
    assert np.linalg.norm(P[[0, 29], J["left_collar"]] - src, axis=-1).max() < 0.06   # near the real clavicle


def test_the_armature_errors_name_the_problem(addon):
    from blender_manikin.blender.properties import config_from_settings
    from blender_manikin.blender.solve_job import SolveError
    sc = _scene()
    s = sc.manikin
    s.source, s.keypoint_from = 'KEYPOINTS', 'ARMATURE'
    with pytest.raises(SolveError, match="choose the animated armature whose bones give the keypoints"):
        config_from_settings(bpy.context)
    still = mixamo_style_character("Statue")
    s.keypoint_armature = still
    with pytest.raises(RuntimeError, match=r"armature 'Statue': its bones do not move on frames 1\.\.60: "
                                           "it has no animation there"):
        bpy.ops.manikin.solve_full_body()
    hero = mixamo_style_character("Hero")
    act = animate(hero)
    s.keypoint_armature, s.keypoint_bone_map = hero, 'UE5'
    with pytest.raises(RuntimeError, match=r"armature 'Hero': bone map 'ue5' leaves joint\(s\) "
                                           r"left_hip \('thigh_l' not in the rig\), .*head \('head' not in the rig\) "
                                           "without a bone; the hips, knees, ankles, shoulders, elbows, wrists and "
                                           "head are needed"):
        bpy.ops.manikin.solve_full_body()
    assert hero.animation_data.action == act
    assert not [o for o in bpy.data.objects if o.name.startswith("MANIKIN")]      # nothing written


def test_the_panel_shows_the_armature_and_its_map(addon):
    from blender_manikin.panels import main as panels
    from blender_util import drawn_props
    s = bpy.context.scene.manikin
    s.source, s.keypoint_from = 'KEYPOINTS', 'ARMATURE'
    drawn = {}
    for m in ('AUTO', 'FILE'):
        s.keypoint_bone_map = m
        drawn[m] = drawn_props(panels.MANIKIN_PT_solve, bpy.context)
    assert {"keypoint_armature", "keypoint_bone_map"} <= drawn['AUTO']
    assert "keypoint_path" not in drawn['AUTO'] and "keypoint_map_file" not in drawn['AUTO']
    assert "keypoint_map_file" in drawn['FILE']
    # the picker offers animated characters, not a MANIKIN solve's own armature
    from blender_manikin.blender.properties import _character_poll
    ch = mixamo_style_character("Hero")
    assert _character_poll(s, ch)
    ch["manikin_body"] = "{}"
    assert not _character_poll(s, ch)


def _solve_err(sc, ch, frames=range(1, T + 1, 3)):
    """Solve ``ch`` as keypoints (the scene's settings as they are); ``(T', 22)`` metres between
    each MANIKIN joint and its source bone's head, and the output armature."""
    s = sc.manikin
    s.source, s.keypoint_from, s.keypoint_armature = 'KEYPOINTS', 'ARMATURE', ch
    s.live_rig, s.reuse_armature = True, False
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}, s.last_report
    out = s.armature
    err = [np.linalg.norm(heads(ch, f, [MIXAMO[j] for j in JOINT_NAMES]) - heads(out, f, JOINT_NAMES), axis=-1)
           for f in frames]
    return np.array(err), out


def test_the_armature_keeps_its_floor_on_shoe_soles(addon):
    """Default settings (Shoe Soles 3 cm), the source standing on a platform 0.5 m up: the
    MANIKIN joints stay on the bone heads (the source's floor is the scene's), not lifted by the
    soles or moved to the floor found under the feet."""
    sc = _scene()
    ch = mixamo_style_character("Hero")
    ch.location.z = 0.5
    animate(ch)
    assert abs(sc.manikin.sole_m - 0.03) < 1e-9
    err, _ = _solve_err(sc, ch)
    assert err.max() < 0.005 and err.mean() < 0.001, (err.max(), err.mean())      # 5 mm, 1 mm mean
    assert "heights kept as given" in sc.manikin.last_report, sc.manikin.last_report


def test_the_armature_floor_can_be_found_under_the_feet(addon):
    """Floor: Under the Feet asks for the keypoint files' floor: the body stands on z = 0 on its soles."""
    sc = _scene()
    ch = mixamo_style_character("Hero")
    ch.location.z = 0.5
    animate(ch)
    sc.manikin.keypoint_floor = 'FEET'
    err, out = _solve_err(sc, ch)
    dz = []
    for f in range(1, T + 1, 3):
        dz.append(heads(ch, f, [MIXAMO["pelvis"]])[0, 2] - heads(out, f, ["pelvis"])[0, 2])
    assert 0.45 < np.median(dz) < 0.5, np.median(dz)          # moved down by the platform, up by the soles



#: twists keyed on the end bones (radians about the bone's own Y axis, at the take's end; ramped)
_ROLLS = {"left_wrist": np.pi / 2, "right_wrist": -np.pi / 3, "head": 0.6, "left_ankle": 0.35, "right_ankle": -0.3}


def _rest_pose_turn(ch, joint):
    """The world turn taking the body's rest T-pose bone of ``joint`` to the character's rest one
    (its arms turned down in an A-pose; head and feet as the body's): the arm's rest direction,
    shoulder to elbow, against the T-pose's ±X, the known way ``mixamo_style_character`` turns them."""
    if not joint.endswith("wrist"):
        return np.eye(3)
    side = joint.split("_")[0]
    W = np.array(ch.matrix_world)[:3, :3]
    d = W @ (np.array(ch.data.bones[MIXAMO[f"{side}_elbow"]].head_local)
             - np.array(ch.data.bones[MIXAMO[f"{side}_shoulder"]].head_local))
    return rot.rotation_between(np.array([1.0 if side == "left" else -1.0, 0.0, 0.0]), d)


@pytest.mark.parametrize("arm_down", [0.0, 45.0])
def test_hand_head_and_foot_rolls_carry_over(addon, arm_down):
    """Hands turned palm-up, the head turned, the feet rolled (keyed about each bone's own axis),
    on a character resting in a T-pose and in an A-pose, every bone rolled at random: the MANIKIN
    wrists', head's and ankles' world orientations are the source's (it rested palm-down)."""
    sc = _scene()
    ch = mixamo_style_character("Hero", arm_down_deg=arm_down)
    act = animate(ch)
    t = np.arange(T, dtype=np.float64) / (T - 1)
    channels = []
    for joint, ang in _ROLLS.items():
        pb = ch.pose.bones[MIXAMO[joint]]
        pb.rotation_mode = 'QUATERNION'
        q = np.stack([np.cos(0.5 * ang * t), 0 * t, np.sin(0.5 * ang * t), 0 * t], -1)   # about the bone's Y
        channels += [(f'pose.bones["{pb.name}"].rotation_quaternion', i, pb.name, q[:, i]) for i in range(4)]
    keying.key_channels(act, ch, np.arange(1, T + 1, dtype=np.float64), channels)
    err, out = _solve_err(sc, ch)
    assert err.max() < 0.01, err.max()
    assert "no twist information" not in sc.manikin.last_report, sc.manikin.last_report
    W, Wo = np.array(ch.matrix_world)[:3, :3], np.array(out.matrix_world)[:3, :3]
    W = W / np.linalg.norm(W[:, 0])
    worst = {}
    for joint in _ROLLS:
        pb, po = ch.pose.bones[MIXAMO[joint]], out.pose.bones[joint]
        G0 = W @ np.array(pb.bone.matrix_local)[:3, :3]
        O0 = Wo @ np.array(po.bone.matrix_local)[:3, :3]
        A = _rest_pose_turn(ch, joint)
        angles = []
        for f in (1, 20, 40, T):
            sc.frame_set(f)
            truth = W @ np.array(pb.matrix)[:3, :3] @ G0.T @ A          # body convention: rest = I
            got = Wo @ np.array(po.matrix)[:3, :3] @ O0.T
            angles.append(np.degrees(rot.geodesic_angle(got, truth)))
        worst[joint] = max(angles)
    assert max(worst.values()) < 1.0, worst        # degrees (measured: 0.07; the rest twist: 17-95)
