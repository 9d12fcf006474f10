"""Retargeting core (numpy only): bone maps, rest alignment, pose-bone bases, root motion, limb re-solve.

Target rigs are described directly by rest matrices (armature space, bone Y along the bone, as
Blender's ``bone.matrix_local``), no bpy.
"""
import numpy as np
import pytest

from blender_manikin.blender import armature as am        # bone_layout / pose_bone_quaternions: no bpy
from blender_manikin.core import bone_maps as bmaps
from blender_manikin.core import limb_solver as ls
from blender_manikin.core import retarget as rt
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core.export_bvh import end_site_offsets
from tests.fixtures_bvh import synthetic_motion
from tests.pose_sampling import random_pose

J = sk.J
JN = sk.JOINT_NAMES


def _smooth_source(frames=60, seed=0):
    body, local, root, pos, wrot = synthetic_motion(frames=frames, seed=seed, fixed=())
    return body, local, root, pos, wrot


def _swivel(pos, wrot):
    b = pos[:, ls.LIMB_BASE]
    return ls.swivel_from_positions(b, pos[:, ls.LIMB_MID], pos[:, ls.LIMB_END], wrot[:, ls.LIMB_PARENT],
                                    base_rot=wrot[:, ls.LIMB_BASE])


def _hinge_source(T=40, seed=3):
    """Random poses with hinge elbows / knees (what the solver produces), and their swivel."""
    body = sk.make_body(1.75)
    rng = np.random.default_rng(seed)
    local = random_pose(rng, T, spread=0.3)
    root = body.root_rest + rng.normal(size=(T, 3)) * [0.3, 0.3, 0.05]
    pos, wrot = sk.forward_kinematics(local, root, body)
    return body, local, root, pos, wrot, _swivel(pos, wrot)


def _frame(y, rng=None):
    """Rest rotation with Y along ``y``, X perpendicular, rolled about Y by a random angle."""
    y = rot.normalize(np.asarray(y, float))
    helper = np.array([0.0, 0, 1]) if abs(y[2]) < 0.9 else np.array([1.0, 0, 0])
    x = rot.normalize(np.cross(y, helper))
    B = np.stack([x, y, np.cross(x, y)], -1)
    if rng is not None:
        B = B @ rot.axis_angle_rotation(np.array([0, 1.0, 0]), np.array(rng.uniform(-np.pi, np.pi)))
    return B


MIX = {"pelvis": "Hips", "spine1": "Spine", "spine2": "Spine1", "spine3": "Spine2", "neck": "Neck", "head": "Head"}
for _s, _S in (("left", "Left"), ("right", "Right")):
    MIX.update({f"{_s}_collar": f"{_S}Shoulder", f"{_s}_shoulder": f"{_S}Arm", f"{_s}_elbow": f"{_S}ForeArm",
                f"{_s}_wrist": f"{_S}Hand", f"{_s}_hip": f"{_S}UpLeg", f"{_s}_knee": f"{_S}Leg",
                f"{_s}_ankle": f"{_S}Foot", f"{_s}_foot": f"{_S}ToeBase"})

ARM_JOINTS = {"left": ("left_elbow", "left_wrist"), "right": ("right_elbow", "right_wrist")}
ARMS = ("collar", "shoulder", "elbow", "wrist")
LEGS = ("hip", "knee", "ankle", "foot")


def _scales(arm=1.15, leg=0.92, torso=1.05):
    s = np.full(sk.NUM_JOINTS, torso)
    for side in ("left", "right"):
        for n in ("elbow", "wrist"):
            s[J[f"{side}_{n}"]] = arm
        for n in ("knee", "ankle", "foot"):
            s[J[f"{side}_{n}"]] = leg
    return s


def _joint_rig_geometry(body, scales, apose_deg=45.0):
    """Rest joint positions (world, metres) of a differently proportioned body in an A-pose,
    and each joint's bone Y direction (towards its chain child / end site)."""
    P = np.zeros((sk.NUM_JOINTS, 3))
    P[0] = body.root_rest
    for j in range(1, sk.NUM_JOINTS):
        P[j] = P[sk.PARENTS[j]] + scales[j] * body.offsets[j]
    leaf = end_site_offsets(body)
    ydir = np.zeros((sk.NUM_JOINTS, 3))
    for j in range(sk.NUM_JOINTS):
        c = rt.PRIMARY_CHILD[j]
        ydir[j] = P[c] - P[j] if c >= 0 else leaf[j]
    for side, sgn in (("left", 1.0), ("right", -1.0)):
        Ra = rot.axis_angle_rotation(np.array([0, 1.0, 0]), np.array(sgn * np.radians(apose_deg)))
        s = P[J[f"{side}_shoulder"]]
        for n in ("elbow", "wrist"):
            j = J[f"{side}_{n}"]
            P[j] = s + Ra @ (P[j] - s)
        for n in ("shoulder", "elbow", "wrist"):
            ydir[J[f"{side}_{n}"]] = Ra @ ydir[J[f"{side}_{n}"]]
    # feet on the floor
    P[:, 2] -= P[J["left_ankle"], 2] - scales[J["left_ankle"]] * body.rest_positions()[J["left_ankle"], 2]
    return P, ydir


def mixamo_rig(body, seed=1, prefix="mixamorig:", scales=None, extra=True, apose_deg=45.0):
    """A Mixamo-named rig: A-pose, random bone rolls, different proportions (returns rig, map, P)."""
    rng = np.random.default_rng(seed)
    scales = _scales() if scales is None else scales
    P, ydir = _joint_rig_geometry(body, scales, apose_deg)
    names, parents, B, heads = [], [], [], []
    for j in range(sk.NUM_JOINTS):
        names.append(prefix + MIX[JN[j]])
        parents.append(None if sk.PARENTS[j] < 0 else prefix + MIX[JN[sk.PARENTS[j]]])
        B.append(_frame(ydir[j], rng))
        heads.append(P[j])
    if extra:                                   # unmapped leaf bones
        for n, par, off in (("HeadTop_End", "Head", [0, 0, 0.15]), ("LeftHandIndex1", "LeftHand", [0.08, 0, -0.05]),
                            ("RightHandIndex1", "RightHand", [-0.08, 0, -0.05])):
            k = names.index(prefix + par)
            names.append(prefix + n)
            parents.append(prefix + par)
            B.append(_frame(off, rng))
            heads.append(heads[k] + np.array(off))
    rig = rt.TargetRig(names, parents, np.array(B), np.array(heads))
    bmap = bmaps.BoneMap("mixamo", {j: prefix + b for j, b in MIX.items()})
    return rig, bmap, P


def _seg_dirs(res, rig, bmap, pos, wrot, body):
    """Angles (rad) between target segment / leaf directions and the source's, (T, n)."""
    bm = bmaps.as_bone_map(bmap)
    hw = res.world_heads()
    Gw = res.world_orientations()
    leaf = end_site_offsets(body)
    out = []
    for jn, b in bm.bones.items():
        j = J[jn]
        c = rt.PRIMARY_CHILD[j]
        while c >= 0 and JN[c] not in bm.bones:
            c = rt.PRIMARY_CHILD[c]
        if c >= 0:
            t_dir = hw[:, rig.index[bm.bones[JN[c]]]] - hw[:, rig.index[b]]
            s_dir = pos[:, c] - pos[:, j]
        else:
            t_dir = Gw[:, rig.index[b], :, 1]
            s_dir = wrot[:, j] @ leaf[j]
        cos = np.sum(rot.normalize(t_dir) * rot.normalize(s_dir), -1)
        out.append(np.arccos(np.clip(cos, -1, 1)))
    return np.stack(out, -1)


# ---------------------------------------------------------------------- (a) identity
def test_body_model_as_target_reproduces_the_source_exactly():
    body, local, root, pos, wrot = _smooth_source()
    heads, _, B, _ = am.bone_layout(body)
    rig = rt.TargetRig(JN, sk.PARENTS, B, heads)
    bmap = {j: j for j in JN}
    res = rt.retarget(wrot, pos, body, rig, bmap, root_motion="as_is")
    assert np.abs(res.world_heads() - pos).max() < 1e-9
    assert np.abs(res.world_orientations() - wrot @ B).max() < 1e-9
    q_ref = am.pose_bone_quaternions(local, B)
    dots = np.abs(np.sum(res.quaternions * q_ref, -1))
    assert np.abs(dots - 1).max() < 1e-9
    assert np.abs(res.root_location - am.root_locations(root, heads[0], B[0])).max() < 1e-9
    assert res.keyed.all() and res.root_bone == "pelvis"
    # a same-size body: "scaled" is "as_is"
    res2 = rt.retarget(wrot, pos, body, rig, bmap, root_motion="scaled")
    assert abs(res2.plan.leg_ratio - 1) < 1e-12
    assert np.abs(res2.world_heads() - pos).max() < 1e-9
    # keep_ends on the body itself lands exactly
    sw = _swivel(pos, wrot)
    res3 = rt.keep_ends_on_targets(res, wrot, pos, sw)
    ends = [J[n] for n in ("left_wrist", "right_wrist", "left_ankle", "right_ankle")]
    assert np.abs(res3.world_heads()[:, ends] - pos[:, ends]).max() < 1e-9


def test_in_place_and_scaled_root_motion():
    body, local, root, pos, wrot = _smooth_source()
    rig, bmap, P = mixamo_rig(body)
    k = rig.index["mixamorig:Hips"]
    rest = rig.rest_world_heads()[k]
    d = root - body.root_rest
    res_s = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    r = res_s.plan.leg_ratio
    assert abs(r - 0.92) < 1e-9            # thigh + shank scaled by 0.92
    assert np.abs(res_s.world_heads()[:, k] - (rest + r * d)).max() < 1e-12
    res_i = rt.retarget(wrot, pos, body, rig, bmap, "in_place")
    h = res_i.world_heads()[:, k]
    assert np.abs(h[:, :2] - rest[:2]).max() < 1e-12
    assert np.abs(h[:, 2] - (rest[2] + r * d[:, 2])).max() < 1e-12
    res_a = rt.retarget(wrot, pos, body, rig, bmap, "as_is")
    assert np.abs(res_a.world_heads()[:, k] - (rest + d)).max() < 1e-12
    # the location channel puts the bone's head there (parentless bone: head = rest + B loc)
    assert np.abs(rig.heads[k] + res_a.root_location @ rig.rest_rot[k].T - res_a.heads[:, k]).max() < 1e-12
    with pytest.raises(ValueError, match="root_motion"):
        rt.retarget(wrot, pos, body, rig, bmap, "sideways")


# ---------------------------------------------------------------------- (b) A-pose Mixamo rig
def test_apose_mixamo_rig_with_rolls_and_other_proportions():
    body, local, root, pos, wrot = _smooth_source(frames=90, seed=2)
    rig, bmap, P = mixamo_rig(body)
    res = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    # every mapped segment (and the leaf bones' Y axes) points where the source's does
    ang = _seg_dirs(res, rig, bmap, pos, wrot, body)
    assert ang.max() < 1e-7, ang.max()
    # ends after proportion scaling: limb vectors scale by their limb's ratio (1.15 arms,
    # 0.92 legs), head relative to hips by the torso's (1.05)
    hw = res.world_heads()
    i = rig.index
    worst = 0.0
    for side, S in (("left", "Left"), ("right", "Right")):
        e = hw[:, i[f"mixamorig:{S}Hand"]] - hw[:, i[f"mixamorig:{S}Arm"]]
        worst = max(worst, np.abs(e - 1.15 * (pos[:, J[f"{side}_wrist"]] - pos[:, J[f"{side}_shoulder"]])).max())
        e = hw[:, i[f"mixamorig:{S}Foot"]] - hw[:, i[f"mixamorig:{S}UpLeg"]]
        worst = max(worst, np.abs(e - 0.92 * (pos[:, J[f"{side}_ankle"]] - pos[:, J[f"{side}_hip"]])).max())
    e = hw[:, i["mixamorig:Head"]] - hw[:, i["mixamorig:Hips"]]
    worst = max(worst, np.abs(e - 1.05 * (pos[:, J["head"]] - pos[:, J["pelvis"]])).max())
    assert worst < 0.01
    assert worst < 1e-9                    # in fact exact
    # the source's rest T-pose gives the A-pose rig a T-pose
    T0 = np.broadcast_to(np.eye(3), (1, 22, 3, 3))
    p0 = body.rest_positions()[None]
    r0 = rt.retarget(T0, p0, body, rig, bmap, "as_is")
    h0 = r0.world_heads()[0]
    arm = h0[i["mixamorig:LeftHand"]] - h0[i["mixamorig:LeftArm"]]
    assert np.abs(rot.normalize(arm) - [1, 0, 0]).max() < 1e-12
    # rolls kept: the upper arm's rest X axis is only swung (no twist about the bone)
    Gw = r0.world_orientations()[0, i["mixamorig:LeftArm"]]
    sw = rot.rotation_between(rig.rest_world_rot()[i["mixamorig:LeftArm"]][:, 1], [1, 0, 0])
    assert np.abs(Gw - sw @ rig.rest_world_rot()[i["mixamorig:LeftArm"]]).max() < 1e-12
    # unmapped bones keep identity pose bases and are not keyed
    extra = [i["mixamorig:HeadTop_End"], i["mixamorig:LeftHandIndex1"]]
    assert not res.keyed[extra].any()
    assert np.abs(res.quaternions[:, extra] - [1, 0, 0, 0]).max() < 1e-12


def test_keep_ends_on_targets_mixamo():
    body, local, root, pos, wrot, sw = _hinge_source()
    rig, bmap, P = mixamo_rig(body)
    res = rt.retarget(wrot, pos, body, rig, bmap, "as_is")
    out = rt.keep_ends_on_targets(res, wrot, pos, sw)
    hw = out.world_heads()
    ends = {"left_arm": "LeftHand", "right_arm": "RightHand", "left_leg": "LeftFoot", "right_leg": "RightFoot"}
    reached_any = 0
    for li, (limb, bone) in enumerate(ends.items()):
        e = sk.LIMBS[li][3]
        err = np.linalg.norm(hw[:, rig.index["mixamorig:" + bone]] - pos[:, e], axis=-1)
        ok = out.reach_error[:, li] < 1e-9
        reached_any += ok.sum()
        assert ok.mean() > 0.3, (limb, ok.mean())
        assert err[ok].max() < 1e-4, (limb, err[ok].max())                  # 0.1 mm
        assert np.abs(err[~ok] - out.reach_error[~ok, li]).max() < 1e-6      # misses are reported
    # the swivel is kept: the target's elbow / knee lies on the source's swivel angle
    base_ids = [rig.index["mixamorig:" + n] for n in ("LeftArm", "RightArm", "LeftUpLeg", "RightUpLeg")]
    mid_ids = [rig.index["mixamorig:" + n] for n in ("LeftForeArm", "RightForeArm", "LeftLeg", "RightLeg")]
    end_ids = [rig.index["mixamorig:" + n] for n in ("LeftHand", "RightHand", "LeftFoot", "RightFoot")]
    phi = ls.swivel_from_positions(hw[:, base_ids], hw[:, mid_ids], hw[:, end_ids], wrot[:, ls.LIMB_PARENT])
    d = np.angle(np.exp(1j * (phi - sw)))
    bent = out.reach_error < 1e-9          # a straight (out of reach) limb has no swivel to measure
    assert np.abs(d[bent]).max() < 1e-6
    # hands / feet keep the transferred world orientation
    assert np.abs(out.world_orientations()[:, end_ids] - res.world_orientations()[:, end_ids]).max() < 1e-9


def _planted_left_foot_source():
    """``(body, pos, wrot, sw, anchor)``: a hinge source whose pelvis bobs (knees bent) while its
    left ankle stays planted at ``anchor`` (its left leg re-solved onto that fixed point)."""
    body, local, root, pos, wrot, sw = _hinge_source(T=30, seed=5)
    anchor = np.array([0.10, -0.05, 0.09])
    root = np.broadcast_to(body.root_rest, (30, 3)).copy()
    root[:, 0] += 0.03 * np.cos(np.arange(30) / 4)
    root[:, 2] += -0.08 + 0.03 * np.sin(np.arange(30) / 5)
    pos, wrot = sk.forward_kinematics(local, root, body)
    sol = ls.solve_limbs(pos[:, None, J["left_hip"]], np.broadcast_to(anchor, (30, 1, 3)), sw[:, 2:3],
                         body.limb_lengths()[2:3], wrot[:, None, J["pelvis"]], limb_ids=[2])
    local = local.copy()
    local[:, J["left_hip"]] = sol.base_local[:, 0]
    local[:, J["left_knee"]] = sol.mid_local[:, 0]
    pos, wrot = sk.forward_kinematics(local, root, body)
    assert np.abs(pos[:, J["left_ankle"]] - anchor).max() < 1e-9
    return body, pos, wrot, sw, anchor


def test_keep_ends_scaled_targets_and_planted_foot():
    """ends='scaled' follows the scaled root; a foot planted in the source stays planted."""
    body, pos, wrot, sw, anchor = _planted_left_foot_source()
    rig, bmap, P = mixamo_rig(body, scales=_scales(arm=1.1, leg=1.1, torso=1.1))
    res = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    out = rt.keep_ends_on_targets(res, wrot, pos, sw, limbs=("left_leg",), ends="scaled")
    foot = out.world_heads()[:, rig.index["mixamorig:LeftFoot"]]
    assert np.all(out.reach_error[:, 2] < 1e-9)
    assert np.isnan(out.reach_error[:, [0, 1, 3]]).all()
    assert np.abs(foot - foot[0]).max() < 1e-9             # planted
    assert np.abs(foot[0] - (rig.rest_world_heads()[rig.index["mixamorig:Hips"]]
                             + 1.1 * (anchor - body.root_rest))).max() < 1e-9


def test_scaled_hands_follow_the_characters_own_arms():
    """Keep-ends with scaled root motion on a character whose arms and legs have other ratios to
    the performer's (legs 0.75, arms 1.25: short legs, long arms; Rigify's metarig is 15 cm off the
    same way): the hands' targets were the pelvis plus the *leg* ratio times the performer's
    pelvis-to-wrist offset, out of the long arms' reach or folded into them (the bundled example:
    elbows bent 113° on average where the performer's bent 47°; Rigify's right arm straight on
    every frame, 15 cm out of reach).  Now a hand goes to the character's shoulder plus its arm
    ratio times the performer's shoulder-to-wrist offset: always reachable, and with the
    performer's upper-arm : forearm proportion the elbow bends as the performer's."""
    body, local, root, pos, wrot, sw = _hinge_source(T=30, seed=5)
    rig, bmap, P = mixamo_rig(body, scales=_scales(arm=1.25, leg=0.75, torso=1.0))
    res = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    out = rt.keep_ends_on_targets(res, wrot, pos, sw, ends="scaled")
    assert np.nanmax(out.reach_error[:, :2]) < 1e-6, np.nanmax(out.reach_error[:, :2])
    hw = out.world_heads()
    for side, S in (("left", "Left"), ("right", "Right")):
        sh, el, wr = (hw[:, rig.index[f"mixamorig:{S}{n}"]] for n in ("Arm", "ForeArm", "Hand"))
        js, je, jw = (J[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist"))
        np.testing.assert_allclose(wr, sh + 1.25 * (pos[:, jw] - pos[:, js]), atol=1e-6)
        bend_c = np.sum(rot.normalize(el - sh) * rot.normalize(wr - el), -1)
        bend_s = np.sum(rot.normalize(pos[:, je] - pos[:, js]) * rot.normalize(pos[:, jw] - pos[:, je]), -1)
        np.testing.assert_allclose(bend_c, bend_s, atol=1e-6)


def test_scaled_feet_stand_on_the_legs_whatever_bone_starts_the_hips():
    """Blender's Human metarig (and the rig Rigify generates from it) starts its hips bone
    (``spine``) 6 cm *below* its thighs' heads; the body model's pelvis sits 5 cm above its hips.
    Measured from the hips bone, the scaled feet were out of the legs' reach (13 cm on the
    bundled example: the knees never bent).  The feet's targets are the character's own rest
    ankles plus the leg ratio times the performer's ankles' travel: reachable, a planted foot
    planted, the knees bent."""
    body, pos, wrot, sw, anchor = _planted_left_foot_source()
    rig, bmap, P = mixamo_rig(body, scales=_scales(arm=1.1, leg=1.1, torso=1.1))
    heads = rig.heads.copy()
    heads[rig.index["mixamorig:Hips"]] = P[J["left_hip"]] * [0, 1, 1] - [0, 0, 0.06]   # 6 cm below the thighs
    rig = rt.TargetRig(rig.names, rig.parents, rig.rest_rot, heads)
    res = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    out = rt.keep_ends_on_targets(res, wrot, pos, sw, limbs=("left_leg",), ends="scaled")
    assert np.nanmax(out.reach_error[:, 2]) < 1e-9, np.nanmax(out.reach_error[:, 2])
    foot = out.world_heads()[:, rig.index["mixamorig:LeftFoot"]]
    assert np.abs(foot - foot[0]).max() < 1e-9             # planted
    rest_ankle = body.rest_positions()[J["left_ankle"]]
    assert np.abs(foot[0] - (P[J["left_ankle"]] + 1.1 * (anchor - rest_ankle))).max() < 1e-9
    thigh, shin, ankle = (out.world_heads()[:, rig.index[f"mixamorig:Left{n}"]] for n in ("UpLeg", "Leg", "Foot"))
    knee = np.degrees(np.arccos(np.sum(rot.normalize(shin - thigh) * rot.normalize(ankle - shin), -1)))
    assert knee.min() > 10.0, knee.min()                  # the knee bends (it was straight)


# ---------------------------------------------------------------------- (c) forward +Y, scale 0.01
def test_rig_facing_plus_y_in_centimetres_with_y_up_data():
    body, local, root, pos, wrot = _smooth_source(frames=30)
    rig_m, bmap, _ = mixamo_rig(body)
    Rz = rot.axis_angle_rotation(np.array([0, 0, 1.0]), np.array(np.pi))
    M = rot.axis_angle_rotation(np.array([1.0, 0, 0]), np.array(np.pi / 2))      # Y-up data -> Z-up
    # the same character turned to face +Y, stored as Y-up centimetres, object rot X 90 and scale 0.01
    A = np.tile(np.eye(4), (rig_m.num_bones, 1, 1))
    A[:, :3, :3] = M.T @ Rz @ rig_m.rest_rot
    A[:, :3, 3] = 100.0 * rig_m.heads @ (M.T @ Rz).T
    W = np.eye(4)
    W[:3, :3] = 0.01 * M
    parents = [None if p < 0 else rig_m.names[p] for p in rig_m.parents]
    rig_c = rt.TargetRig.from_matrices(rig_m.names, parents, A, W)
    assert abs(rig_c.world_scale - 0.01) < 1e-12
    assert np.abs(rig_c.rest_world_heads() - rig_m.rest_world_heads() @ Rz.T).max() < 1e-12
    for mode in ("scaled", "as_is"):
        rm = rt.retarget(wrot, pos, body, rig_m, bmap, mode)
        rc = rt.retarget(wrot, pos, body, rig_c, bmap, mode)
        assert abs(np.degrees(np.arctan2(rc.plan.F[1, 0], rc.plan.F[0, 0])) - 180) < 1e-9
        # the character performs facing +Y: everything turned half-way round about the origin
        assert np.abs(rc.world_heads() - rm.world_heads() @ Rz.T).max() < 1e-9
        assert np.abs(rc.world_orientations() - Rz @ rm.world_orientations()).max() < 1e-9
        # pose-bone rotations are the same numbers; locations are in centimetres
        assert np.abs(np.abs(np.sum(rc.quaternions * rm.quaternions, -1)) - 1).max() < 1e-9
        assert np.abs(rc.root_location - 100 * rm.root_location).max() < 1e-7
    # walking: the source goes towards -Y, the +Y-facing character towards +Y
    k = rig_c.index["mixamorig:Hips"]
    assert rc.world_heads()[-1, k, 1] - rc.world_heads()[0, k, 1] > 0.3
    # explicit facing overrides the detection
    rf = rt.retarget(wrot, pos, body, rig_c, bmap, "as_is", facing_yaw=0.0)
    assert np.abs(rf.plan.F - np.eye(3)).max() < 1e-12
    with pytest.raises(ValueError, match="non-uniform"):
        rt.TargetRig.from_matrices(rig_m.names, parents, A, np.diag([1.0, 2.0, 1.0, 1.0]))


# ---------------------------------------------------------------------- (d) no flips
def _ue_rig(body, seed=4, version=5):
    """A UE-mannequin-like rig: root bone, 5 spine bones (UE5), twist bones, A-pose, rolls."""
    rng = np.random.default_rng(seed)
    P, ydir = _joint_rig_geometry(body, _scales(1.0, 1.05, 0.95), 40.0)
    bm = bmaps.preset(f"ue{version}")
    names, parents, B, heads = ["root"], [None], [_frame([0, 0, 1.0], rng)], [np.zeros(3)]

    def add(name, parent, head, y):
        names.append(name)
        parents.append(parent)
        B.append(_frame(y, rng))
        heads.append(np.asarray(head, float))

    add("pelvis", "root", P[0], P[J["spine1"]] - P[0])
    nspine = 5 if version == 5 else 3
    sp = [P[0] + (P[J["neck"]] - P[0]) * (i + 1) / (nspine + 1) for i in range(nspine)]
    prev = "pelvis"
    for i in range(nspine):
        nxt = sp[i + 1] if i + 1 < nspine else P[J["neck"]]
        add(f"spine_{i + 1:02d}", prev, sp[i], nxt - sp[i])
        prev = f"spine_{i + 1:02d}"
    add("neck_01", prev, P[J["neck"]], P[J["head"]] - P[J["neck"]])
    add("head", "neck_01", P[J["head"]], [0, 0, 1.0])
    for side, s in (("left", "l"), ("right", "r")):
        add(f"clavicle_{s}", prev, P[J[f"{side}_collar"]], ydir[J[f"{side}_collar"]])
        for part, nm, par in (("shoulder", "upperarm", "clavicle"), ("elbow", "lowerarm", "upperarm"),
                              ("wrist", "hand", "lowerarm")):
            add(f"{nm}_{s}", f"{par}_{s}", P[J[f"{side}_{part}"]], ydir[J[f"{side}_{part}"]])
        for part, nm, par in (("hip", "thigh", None), ("knee", "calf", "thigh"), ("ankle", "foot", "calf"),
                              ("foot", "ball", "foot")):
            add(f"{nm}_{s}", "pelvis" if par is None else f"{par}_{s}", P[J[f"{side}_{part}"]],
                ydir[J[f"{side}_{part}"]])
        for main, part in (("upperarm", "shoulder"), ("lowerarm", "elbow"), ("thigh", "hip"), ("calf", "knee")):
            for t in bm.twist[f"{side}_{part}"]:
                f = 0.3 if t.endswith(f"01_{s}") else 0.6
                k = names.index(f"{main}_{s}")
                add(t, f"{main}_{s}", heads[k] + f * (P[rt.PRIMARY_CHILD[J[f'{side}_{part}']]] - heads[k]),
                    ydir[J[f"{side}_{part}"]])
    return rt.TargetRig(names, parents, np.array(B), np.array(heads)), bm


def test_no_flips_on_smooth_motion():
    body, local, root, pos, wrot = _smooth_source(frames=90, seed=6)
    src_step = rot.geodesic_angle(wrot[1:], wrot[:-1]).max()
    rig_x, bm_x, _ = mixamo_rig(body)
    rig_u, bm_u = _ue_rig(body)
    # a VRM-like rig without UpperChest and collars: spine3 and collars are folded
    rig_f, bm_f, _ = mixamo_rig(body, seed=8)
    bm_f = bmaps.BoneMap("folded", {j: b for j, b in bm_f.bones.items()
                                     if j not in ("spine3", "left_collar", "right_collar")})
    src_steps = rot.geodesic_angle(wrot[1:], wrot[:-1])            # (T-1, 22)
    for rig, bm in ((rig_x, bm_x), (rig_u, bm_u), (rig_f, bm_f)):
        res = rt.retarget(wrot, pos, body, rig, bm, "scaled")
        G = res.world_orientations()[:, res.keyed]
        step = rot.geodesic_angle(G[1:], G[:-1])
        assert step.max() < np.radians(90)
        assert step.max() < 2.0 * src_step + 1e-9, (step.max(), src_step)
        # a mapped bone (not folded) turns between frames exactly as much as its source joint
        for j in range(sk.NUM_JOINTS):
            k = res.plan.bone_of[j]
            if k >= 0 and j not in res.plan.folded and k not in res.plan.twist_main:
                Gk = res.world_orientations()[:, k]
                assert np.abs(rot.geodesic_angle(Gk[1:], Gk[:-1]) - src_steps[:, j]).max() < 1e-6
        q = res.quaternions
        assert np.sum(q[1:] * q[:-1], -1).min() > 0            # sign-continuous for keying
        assert np.isfinite(q).all()


def test_a_rig_restricted_to_the_driven_bones_retargets_them_alike():
    """TargetRig.restricted_to keeps the driven bones and those above them (UE5: root, the
    extra spine bones, twist bones), drops the leaves below (a hand's fingers, a prop); the
    retarget of those bones and keep-ends are the same on either rig."""
    body, local, root, pos, wrot = _smooth_source(frames=30, seed=3)
    rig, bm = _ue_rig(body, version=5)
    leaves = [("index_01_l", "hand_l"), ("index_02_l", "index_01_l"), ("weapon_r", "hand_r")]
    names = list(rig.names) + [n for n, _ in leaves]
    parents = [rig.names[p] if p >= 0 else None for p in rig.parents] + [p for _, p in leaves]
    hand = [rig.index["hand_l"], rig.index["hand_l"], rig.index["hand_r"]]
    full = rt.TargetRig(names, parents, np.concatenate([rig.rest_rot, rig.rest_rot[hand]]),
                        np.concatenate([rig.heads, rig.heads[hand] + 0.05]))
    small = full.restricted_to(bm.target_bones())
    assert set(small.names) == set(rig.names) and len(small.names) == len(full.names) - 3
    assert {"root", "spine_02", "spine_04"} <= set(small.names)
    a = rt.keep_ends_on_targets(rt.retarget(wrot, pos, body, full, bm, "scaled"), wrot, pos,
                                np.zeros((pos.shape[0], 4)), ends="scaled")
    b = rt.keep_ends_on_targets(rt.retarget(wrot, pos, body, small, bm, "scaled"), wrot, pos,
                                np.zeros((pos.shape[0], 4)), ends="scaled")
    ia = [a.bone_names.index(n) for n in small.names]
    np.testing.assert_allclose(b.quaternions, a.quaternions[:, ia], atol=1e-12)
    np.testing.assert_allclose(b.world_heads(), a.world_heads()[:, ia], atol=1e-12)
    np.testing.assert_allclose(b.root_location, a.root_location, atol=1e-12)
    assert [b.bone_names[k] for k in np.flatnonzero(b.keyed)] == [a.bone_names[k] for k in np.flatnonzero(a.keyed)]


def test_twist_shares_ramp_along_the_segment():
    assert np.allclose(rt.twist_shares([0.5]), [0.25, 0.75])                 # one twist bone half-way
    assert np.allclose(rt.twist_shares([0.0, 0.5]), [0.0, 0.25, 0.75])       # CC: Twist01 at the head
    assert np.allclose(rt.twist_shares([1 / 3, 2 / 3]), [1 / 6, 0.5, 5 / 6])
    assert np.allclose(rt.twist_shares([1.3]), [0.5, 1.0])                   # past the tip: clamped
    assert np.allclose(rt.twist_shares([0.6, 0.4]), [0.3, 0.6, 0.8])         # out of order: kept monotone


def test_twist_bones_share_the_twist():
    """Each twist bone (and the segment's bone) takes the twist of the middle of the stretch of
    the segment it spans: a ramp from none at the segment's base to all at its tip."""
    body, local, root, pos, wrot = _smooth_source(frames=40, seed=7)
    rig, bm = _ue_rig(body, version=4)
    plain = bmaps.BoneMap("no twist", dict(bm.bones))
    r0 = rt.retarget(wrot, pos, body, rig, plain, "as_is")
    r1 = rt.retarget(wrot, pos, body, rig, bm, "as_is")
    i = rig.index
    ey = np.array([0, 1.0, 0])
    heads = rig.rest_world_heads()
    for main, tw, nxt in (("lowerarm_l", "lowerarm_twist_01_l", "hand_l"),
                          ("upperarm_r", "upperarm_twist_01_r", "lowerarm_r"),
                          ("calf_l", "calf_twist_01_l", "foot_l")):
        tau = np.unwrap(rot.twist_angle(r0.basis_rot[:, i[main]], ey))
        assert np.ptp(tau) > 0.2                 # the motion does twist these segments
        # the twist ramps along the segment: the main bone keeps the twist of the middle of its
        # stretch (base to the twist bone), the twist bone that of the middle of the rest
        d = heads[i[nxt]] - heads[i[main]]
        t = float((heads[i[tw]] - heads[i[main]]) @ d / (d @ d))
        s_main, s_tw = t / 2, (t + 1) / 2
        assert 0.1 < t < 0.9
        # the main bone keeps its share (relative to the parent's unshared orientation)
        G0m = r0.orientations[:, i[main]]
        assert np.abs(r1.orientations[:, i[main]]
                      - G0m @ rot.axis_angle_rotation(ey, -(1 - s_main) * tau)).max() < 1e-9
        # the twist bone sits on the main bone turned by the difference about the bone's axis
        rel = np.swapaxes(r1.orientations[:, i[main]], -1, -2) @ r1.orientations[:, i[tw]]
        rest_rel = rig.rest_rot[i[main]].T @ rig.rest_rot[i[tw]]
        expect = rot.axis_angle_rotation(ey, (s_tw - s_main) * tau) @ rest_rel
        assert np.abs(rel - expect).max() < 1e-9
        # the direction of the main bone is unchanged
        assert np.abs(r1.orientations[:, i[main], :, 1] - r0.orientations[:, i[main], :, 1]).max() < 1e-9
        assert r1.keyed[i[tw]] and not r0.keyed[i[tw]]
    # bones below the segment are unaffected
    for b in ("hand_l", "foot_l", "hand_r", "head"):
        assert np.abs(r1.world_orientations()[:, i[b]] - r0.world_orientations()[:, i[b]]).max() < 1e-9
    # the extra spine bones (UE5) keep identity bases, mapped ones follow the source
    rig5, bm5 = _ue_rig(body, version=5)
    r5 = rt.retarget(wrot, pos, body, rig5, bm5, "scaled")
    for b in ("spine_02", "spine_04", "root"):
        assert np.abs(r5.quaternions[:, rig5.index[b]] - [1, 0, 0, 0]).max() < 1e-12
    assert _seg_dirs(r5, rig5, bm5, pos, wrot, body).max() < 1e-7


def test_folded_spine_points_at_the_next_mapped_joint():
    body, local, root, pos, wrot = _smooth_source(frames=30, seed=9)
    rig, bm, _ = mixamo_rig(body)
    bm = bmaps.BoneMap("folded", {j: b for j, b in bm.bones.items() if j not in ("spine3", "left_collar")})
    res = rt.retarget(wrot, pos, body, rig, bm, "as_is")
    assert set(res.plan.folded) == {J["spine2"]}
    assert _seg_dirs(res, rig, bm, pos, wrot, body).max() < 1e-7
    # the neck and the upper arm carry the source's world orientation (the unmapped joints' rest
    # of rotation is in their local rotation)
    for j, b in (("neck", "mixamorig:Neck"), ("left_shoulder", "mixamorig:LeftArm")):
        G = res.world_orientations()[:, rig.index[b]]
        A = res.plan.align[J[j]]
        assert np.abs(G - wrot[:, J[j]] @ A).max() < 1e-9


# ---------------------------------------------------------------------- (e) save / load
def test_save_load_round_trip(tmp_path):
    body, local, root, pos, wrot = _smooth_source(frames=20)
    rig, bm = _ue_rig(body, version=5)
    path = tmp_path / "ue5_map.json"
    bmaps.save_bone_map(path, bm)
    back = bmaps.load_bone_map(path)
    assert back.to_dict() == bm.to_dict()
    r0 = rt.retarget(wrot, pos, body, rig, bm)
    r1 = rt.retarget(wrot, pos, body, rig, back)
    assert np.array_equal(r0.quaternions, r1.quaternions)
    assert np.array_equal(r0.root_location, r1.root_location)
    # flat dicts are accepted too
    flat = dict(bm.bones, name="flat", twist=bm.twist)
    assert bmaps.validate_bone_map(flat).bones == bm.bones
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        bmaps.load_bone_map(tmp_path / "bad.json")


def test_presets_are_valid():
    for name in bmaps.PRESETS:
        bm = bmaps.validate_bone_map(bmaps.preset(name))
        # every joint has a bone, but in a generated Rigify rig's FK controls spine1 (folded: its
        # FK spine hangs from the torso control, see bone_maps._rigify_fk)
        assert len(bm.bones) == sk.NUM_JOINTS - (name == "rigify_fk"), name
    assert bmaps.preset("mixamo").bones["left_elbow"] == "mixamorig:LeftForeArm"
    assert bmaps.preset("rigify").twist["left_shoulder"] == ["DEF-upper_arm.L.001"]
    assert bmaps.preset("vrm").bones["right_foot"] == "J_Bip_R_ToeBase"
    assert bmaps.preset("auto_rig_pro").bones["pelvis"] == "root.x"
    assert bmaps.preset("cc4").bones["left_elbow"] == "CC_Base_L_Forearm"
    assert bmaps.preset("daz_genesis8").bones["right_shoulder"] == "rShldrBend"
    with pytest.raises(ValueError, match="unknown bone map preset"):
        bmaps.preset("maya")


# ---------------------------------------------------------------------- (f) guessing
def _bones(pairs):
    return [(n, p, None, None) for n, p in pairs]


def _mixamo_bones(prefix="mixamorig:"):
    out = [("Hips", None), ("Spine", "Hips"), ("Spine1", "Spine"), ("Spine2", "Spine1"), ("Neck", "Spine2"),
           ("Head", "Neck"), ("HeadTop_End", "Head")]
    for S in ("Left", "Right"):
        out += [(f"{S}Shoulder", "Spine2"), (f"{S}Arm", f"{S}Shoulder"), (f"{S}ForeArm", f"{S}Arm"),
                (f"{S}Hand", f"{S}ForeArm"), (f"{S}HandIndex1", f"{S}Hand"), (f"{S}HandThumb1", f"{S}Hand"),
                (f"{S}UpLeg", "Hips"), (f"{S}Leg", f"{S}UpLeg"), (f"{S}Foot", f"{S}Leg"),
                (f"{S}ToeBase", f"{S}Foot"), (f"{S}Toe_End", f"{S}ToeBase")]
    return _bones([(prefix + n, None if p is None else prefix + p) for n, p in out])


def _ue5_bones():
    out = [("root", None), ("pelvis", "root"), ("spine_01", "pelvis")]
    out += [(f"spine_0{i}", f"spine_0{i - 1}") for i in range(2, 6)]
    out += [("neck_01", "spine_05"), ("neck_02", "neck_01"), ("head", "neck_02"),
            ("ik_foot_root", "root"), ("ik_hand_root", "root"), ("ik_hand_gun", "ik_hand_root")]
    for s in ("l", "r"):
        out += [(f"clavicle_{s}", "spine_05"), (f"upperarm_{s}", f"clavicle_{s}"),
                (f"upperarm_twist_01_{s}", f"upperarm_{s}"), (f"upperarm_twist_02_{s}", f"upperarm_{s}"),
                (f"upperarm_correctiveRoot_{s}", f"upperarm_{s}"), (f"lowerarm_{s}", f"upperarm_{s}"),
                (f"lowerarm_twist_01_{s}", f"lowerarm_{s}"), (f"lowerarm_twist_02_{s}", f"lowerarm_{s}"),
                (f"hand_{s}", f"lowerarm_{s}"), (f"index_metacarpal_{s}", f"hand_{s}"),
                (f"thigh_{s}", "pelvis"), (f"thigh_twist_01_{s}", f"thigh_{s}"), (f"thigh_twist_02_{s}", f"thigh_{s}"),
                (f"calf_{s}", f"thigh_{s}"), (f"calf_twist_01_{s}", f"calf_{s}"), (f"calf_twist_02_{s}", f"calf_{s}"),
                (f"foot_{s}", f"calf_{s}"), (f"ball_{s}", f"foot_{s}"), (f"ik_foot_{s}", "ik_foot_root"),
                (f"ik_hand_{s}", "ik_hand_gun")]
    return _bones(out)


def _vrm_bones():
    C = "J_Bip_C_"
    out = [("Root", None), (C + "Hips", "Root"), (C + "Spine", C + "Hips"), (C + "Chest", C + "Spine"),
           (C + "UpperChest", C + "Chest"), (C + "Neck", C + "UpperChest"), (C + "Head", C + "Neck"),
           ("J_Adj_L_FaceEye", C + "Head"), ("J_Sec_Hair1_01", C + "Head")]
    for s in ("L", "R"):
        b = f"J_Bip_{s}_"
        out += [(b + "Shoulder", C + "UpperChest"), (b + "UpperArm", b + "Shoulder"), (b + "LowerArm", b + "UpperArm"),
                (b + "Hand", b + "LowerArm"), (b + "Index1", b + "Hand"), (b + "Thumb1", b + "Hand"),
                (b + "UpperLeg", C + "Hips"), (b + "LowerLeg", b + "UpperLeg"), (b + "Foot", b + "LowerLeg"),
                (b + "ToeBase", b + "Foot")]
    return _bones(out)


def _rigify_bones():
    out = [("root", None), ("DEF-spine", "root")]
    out += [(f"DEF-spine.00{i}", "DEF-spine" if i == 1 else f"DEF-spine.00{i - 1}") for i in range(1, 7)]
    out += [("torso", "root"), ("hips", "torso"), ("chest", "torso"), ("ORG-spine", "root")]
    for s in ("L", "R"):
        out += [(f"DEF-pelvis.{s}", "DEF-spine"), (f"DEF-thigh.{s}", "DEF-spine"),
                (f"DEF-thigh.{s}.001", f"DEF-thigh.{s}"), (f"DEF-shin.{s}", f"DEF-thigh.{s}.001"),
                (f"DEF-shin.{s}.001", f"DEF-shin.{s}"), (f"DEF-foot.{s}", f"DEF-shin.{s}.001"),
                (f"DEF-toe.{s}", f"DEF-foot.{s}"), (f"DEF-shoulder.{s}", "DEF-spine.003"),
                (f"DEF-upper_arm.{s}", f"DEF-shoulder.{s}"), (f"DEF-upper_arm.{s}.001", f"DEF-upper_arm.{s}"),
                (f"DEF-forearm.{s}", f"DEF-upper_arm.{s}.001"), (f"DEF-forearm.{s}.001", f"DEF-forearm.{s}"),
                (f"DEF-hand.{s}", f"DEF-forearm.{s}.001"), (f"upper_arm_fk.{s}", "root"),
                (f"hand_ik.{s}", "root"), (f"MCH-forearm_ik.{s}", "root")]
    return _bones(out)


@pytest.mark.parametrize("style, bones, preset", [
    ("mixamo", _mixamo_bones(), "mixamo"),
    ("mixamo1", _mixamo_bones("mixamorig1:"), "mixamo"),
    ("mixamo_plain", _mixamo_bones(""), "mixamo_plain"),
    ("ue5", _ue5_bones(), "ue5"),
    ("vrm", _vrm_bones(), "vrm"),
    ("rigify", _rigify_bones(), "rigify"),
])
def test_guess_bone_map(style, bones, preset):
    names = [b[0] for b in bones]
    expect = bmaps.preset(preset)
    expect_bones = {j: b.split(":")[-1] for j, b in expect.bones.items()}
    # with presets
    bm, notes = bmaps.guess_bone_map(bones)
    assert bm.name == preset
    assert {j: b.split(":")[-1] for j, b in bm.bones.items()} == expect_bones
    assert all(b in names for b in bm.target_bones())
    assert [n.joint for n in notes] == list(JN) and all(n.confidence == 1.0 for n in notes)
    bmaps.validate_bone_map(bm, names)
    # from names and hierarchy alone (Rigify's DEF-spine.004.. carry no neck/head names)
    if style == "rigify":
        return
    bm2, notes2 = bmaps.guess_bone_map(bones, use_presets=False)
    assert bm2.bones == bm.bones, {j: (bm2.bones.get(j), bm.bones.get(j)) for j in JN
                                   if bm2.bones.get(j) != bm.bones.get(j)}
    assert all(n.bone is not None and n.confidence >= 0.6 for n in notes2), notes2
    if style == "ue5":
        assert sorted(bm2.twist["left_elbow"]) == ["lowerarm_twist_01_l", "lowerarm_twist_02_l"]
        assert bm2.twist["right_shoulder"] == ["upperarm_twist_01_r", "upperarm_twist_02_r"]
    bmaps.validate_bone_map(bm2, names)


def test_guess_maps_the_upper_arm_named_shldr():
    """Daz Genesis 1/2 and Poser figures name the upper arm ``lShldr`` (and Diffeomorphic renames
    Genesis 3/8's lShldrBend so when it merges the Bend/Twist bones); the guess did not know the
    word: the upper arms stayed unmapped (the collars turned to point at the elbows) and the
    report advised mapping the elbow to ``lShldr``."""
    out = [("hip", None), ("pelvis", "hip"), ("abdomen", "hip"), ("abdomen2", "abdomen"), ("chest", "abdomen2"),
           ("neck", "chest"), ("head", "neck")]
    for s in "lr":
        out += [(f"{s}Collar", "chest"), (f"{s}Shldr", f"{s}Collar"), (f"{s}ForeArm", f"{s}Shldr"),
                (f"{s}Hand", f"{s}ForeArm"), (f"{s}Thumb1", f"{s}Hand"), (f"{s}Index1", f"{s}Hand"),
                (f"{s}Thigh", "pelvis"), (f"{s}Shin", f"{s}Thigh"), (f"{s}Foot", f"{s}Shin"), (f"{s}Toe", f"{s}Foot")]
    bm, notes = bmaps.guess_bone_map(_bones(out))
    assert [bm.bones.get(j) for j in ("pelvis", "spine1", "spine2", "spine3", "neck", "head")] == \
        ["hip", "abdomen", "abdomen2", "chest", "neck", "head"]
    for side in ("left", "right"):
        s = side[0]
        assert [bm.bones.get(f"{side}_{j}") for j in ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle",
                                                      "foot")] == \
            [f"{s}{b}" for b in ("Collar", "Shldr", "ForeArm", "Hand", "Thigh", "Shin", "Foot", "Toe")]
    assert all(n.bone is not None and n.confidence >= 0.6 for n in notes), [n for n in notes if n.confidence < 0.6]
    bmaps.validate_bone_map(bm, [b[0] for b in out])


def _cc4_bones(twist_under="segment", twist=True):
    """A CC4 rig's body bones, heads / tails along +Z per segment: ``twist_under`` ``"segment"``
    (as CC exports it: Twist01 under the segment's bone at its head, Twist02 under Twist01
    half-way along, listed here tip first) or ``"clavicle"`` / ``"thigh_parent"`` (an older
    layout with the arm's twist bones beside the segment, under the clavicle); ``twist=False``: a
    rig exported without twist bones."""
    z = lambda a, b: (np.array([0.0, 0.0, a]), np.array([0.0, 0.0, b]))     # noqa: E731
    out = [("CC_Base_BoneRoot", None) + z(0, 0.1), ("CC_Base_Hip", "CC_Base_BoneRoot") + z(1.0, 1.1),
           ("CC_Base_Pelvis", "CC_Base_Hip") + z(1.0, 0.95), ("CC_Base_Waist", "CC_Base_Hip") + z(1.1, 1.2),
           ("CC_Base_Spine01", "CC_Base_Waist") + z(1.2, 1.3), ("CC_Base_Spine02", "CC_Base_Spine01") + z(1.3, 1.5),
           ("CC_Base_NeckTwist01", "CC_Base_Spine02") + z(1.5, 1.55),
           ("CC_Base_NeckTwist02", "CC_Base_NeckTwist01") + z(1.55, 1.6),
           ("CC_Base_Head", "CC_Base_NeckTwist02") + z(1.6, 1.8)]
    for S in ("L", "R"):
        b = f"CC_Base_{S}_"
        out += [(b + "Clavicle", "CC_Base_Spine02") + z(1.45, 1.5), (b + "Upperarm", b + "Clavicle") + z(1.5, 1.2),
                (b + "Forearm", b + "Upperarm") + z(1.2, 0.95), (b + "Hand", b + "Forearm") + z(0.95, 0.85),
                (b + "Thigh", "CC_Base_Pelvis") + z(0.95, 0.5), (b + "Calf", b + "Thigh") + z(0.5, 0.08),
                (b + "Foot", b + "Calf") + z(0.08, 0.03), (b + "ToeBase", b + "Foot") + z(0.03, 0.02)]
        if not twist:
            continue
        for seg, (h, t) in (("Upperarm", (1.5, 1.2)), ("Forearm", (1.2, 0.95)), ("Thigh", (0.95, 0.5)),
                            ("Calf", (0.5, 0.08))):
            under = b + seg
            if twist_under == "clavicle" and seg == "Upperarm":
                under = b + "Clavicle"
            mid = 0.5 * (h + t)
            out += [(b + seg + "Twist02", b + seg + "Twist01") + z(mid, t), (b + seg + "Twist01", under) + z(h, mid)]
    return out


def test_presets_keep_the_twist_bones_a_rig_has_below_their_segment():
    """The cc4 preset's Twist01/02 pairs on CC's own layout (base to tip whatever their order in
    the rig); beside the segment (an older layout) or absent they are left out, and the rest of the
    preset still holds; a user's own map is not fitted (its mistakes are errors)."""
    bm, _ = bmaps.guess_bone_map(_cc4_bones())
    assert bm.name == "cc4"
    assert bm.twist["left_elbow"] == ["CC_Base_L_ForearmTwist01", "CC_Base_L_ForearmTwist02"]
    assert set(bm.twist) == {f"{s}_{p}" for s in ("left", "right") for p in ("shoulder", "elbow", "hip", "knee")}
    fitted = bmaps.fit_twist(bmaps.preset("cc4"), _cc4_bones())
    assert fitted.twist == bm.twist and fitted.bones == bmaps.preset("cc4").bones

    beside = bmaps.fit_twist(bmaps.preset("cc4"), _cc4_bones(twist_under="clavicle"))
    assert "left_shoulder" not in beside.twist and "right_shoulder" not in beside.twist
    assert beside.twist["left_knee"] == ["CC_Base_L_CalfTwist01", "CC_Base_L_CalfTwist02"]
    guessed, _ = bmaps.guess_bone_map(_cc4_bones(twist_under="clavicle"))
    assert guessed.twist == beside.twist

    bare = _cc4_bones(twist=False)
    assert bmaps.fit_twist(bmaps.preset("cc4"), bare).twist == {}
    bmaps.validate_bone_map(bmaps.fit_twist(bmaps.preset("cc4"), bare), [b[0] for b in bare])
    with pytest.raises(ValueError, match="has no bone"):
        bmaps.validate_bone_map(bmaps.preset("cc4"), [b[0] for b in bare])


def test_guess_missing_parts_are_reported():
    bones = [b for b in _mixamo_bones("") if "Toe" not in b[0] and b[0] != "Spine2"]
    bones = [(n, "Spine1" if p == "Spine2" else p, h, t) for n, p, h, t in bones]
    bm, notes = bmaps.guess_bone_map(bones, use_presets=False)
    by = {n.joint: n for n in notes}
    assert by["left_foot"].bone is None and by["left_foot"].confidence == 0
    assert by["spine1"].bone == "Spine" and by["spine3"].bone == "Spine1" and by["spine2"].bone is None
    assert "left_foot" not in bm.bones


# ---------------------------------------------------------------------- (g) validation
def test_validation_errors_are_clear():
    body = sk.make_body(1.75)
    rig, bm, _ = mixamo_rig(body)
    good = bm.to_dict()
    with pytest.raises(ValueError, match=r"unknown source joint.*'left_elbw'"):
        bmaps.validate_bone_map(dict(good, bones=dict(good["bones"], left_elbw="x")))
    dup = dict(good["bones"], right_wrist="mixamorig:LeftHand")
    with pytest.raises(ValueError, match=r"used more than once: 'mixamorig:LeftHand' \(joints 'left_wrist' and "
                                         r"'right_wrist'\)"):
        bmaps.validate_bone_map(dict(good, bones=dup))
    with pytest.raises(ValueError, match=r"has no bone\(s\) 'mixamorig:Hip' \(pelvis\)"):
        bmaps.validate_bone_map(dict(good, bones=dict(good["bones"], pelvis="mixamorig:Hip")), rig.names)
    with pytest.raises(ValueError, match=r"pelvis.*must be mapped"):
        bmaps.validate_bone_map({j: b for j, b in good["bones"].items() if j != "pelvis"})
    with pytest.raises(ValueError, match="twist bones given for joint"):
        bmaps.validate_bone_map({"pelvis": "a", "twist": {"left_elbow": ["t"]}})
    with pytest.raises(ValueError, match="twist of 'left_elbow'"):
        bmaps.validate_bone_map({"pelvis": "a", "left_elbow": "b", "twist": {"left_elbow": ["a"]}})
    with pytest.raises(ValueError, match="empty or non-text"):
        bmaps.validate_bone_map({"pelvis": ""})
    # hierarchy that contradicts the body
    swapped = dict(good["bones"], left_elbow="mixamorig:LeftArm", left_shoulder="mixamorig:LeftForeArm")
    with pytest.raises(ValueError, match=r"'mixamorig:LeftForeArm' \(left_shoulder\) is under 'mixamorig:LeftArm'"):
        rt.retarget(np.broadcast_to(np.eye(3), (1, 22, 3, 3)), body.rest_positions()[None], body, rig, swapped)
    # a twist bone outside its segment
    with pytest.raises(ValueError, match="not a descendant"):
        rt.make_plan(body, rig, dict(good["bones"], twist={"left_elbow": ["mixamorig:HeadTop_End"]}))
    with pytest.raises(ValueError, match="duplicate bone names"):
        rt.TargetRig(["a", "a"], [-1, 0], np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="not a rotation"):
        rt.TargetRig(["a"], [-1], 2 * np.eye(3)[None], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="own ancestor"):
        rt.TargetRig(["a", "b"], [1, 0], np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"\(T, 22, 3, 3\)"):
        rt.retarget(np.zeros((2, 21, 3, 3)), np.zeros((2, 21, 3)), body, rig, bm)


def test_editor_rows_round_trip():
    """The panel's map editor rows: one per joint in joint order, unmapped joints empty; back to
    the same map (twist lists kept, also on an unmapped joint, for validation to report)."""
    ue5 = bmaps.preset("ue5")
    rows = bmaps.bone_map_rows(ue5)
    assert [r[0] for r in rows] == list(sk.JOINT_NAMES)
    assert dict((j, b) for j, b, _ in rows)["spine2"] == "spine_03"
    assert rows[sk.J["left_elbow"]][2] == ["lowerarm_twist_02_l", "lowerarm_twist_01_l"]
    back = bmaps.bone_map_from_rows(rows, "ue5")
    assert back.to_dict() == ue5.to_dict()
    partial = bmaps.BoneMap("p", {"pelvis": "hips", "left_knee": "knee.L"}, {})
    rows = bmaps.bone_map_rows(partial)
    assert sum(1 for _, b, _ in rows if b) == 2 and len(rows) == sk.NUM_JOINTS
    assert bmaps.bone_map_from_rows(rows, "p").to_dict() == partial.to_dict()
    orphan = bmaps.bone_map_from_rows([("pelvis", "hips", []), ("left_elbow", " ", ["twist.L"])])
    assert orphan.bones == {"pelvis": "hips"} and orphan.twist == {"left_elbow": ["twist.L"]}
    with pytest.raises(ValueError, match="twist bones given for joint\\(s\\) \\['left_elbow'\\]"):
        bmaps.validate_bone_map(orphan)


def test_guess_orders_twist_bones_base_to_tip_and_keeps_them_below_their_segment():
    """From names alone twist bones are listed base to tip by where their heads lie along the
    segment (UE5's lowerarm_twist_01 is next to the wrist), whatever order the rig lists them in;
    a twist-named bone not below the segment's bone (it could not share its twist) is left out."""
    bones = []
    for n, p, _, _ in _ue5_bones():
        bones.append((n, p, None, None))
    bones.append(("upperarm_twist_03_l", "clavicle_l", None, None))     # beside the arm, not below it
    at = {"upperarm_l": 0.0, "upperarm_twist_01_l": 0.05, "upperarm_twist_02_l": 0.15, "lowerarm_l": 0.3,
          "lowerarm_twist_01_l": 0.5, "lowerarm_twist_02_l": 0.4, "thigh_l": 0.0, "thigh_twist_01_l": 0.1,
          "thigh_twist_02_l": 0.25, "calf_l": 0.45, "calf_twist_01_l": 0.8, "calf_twist_02_l": 0.6}
    x = np.array([1.0, 0.0, 0.0])
    placed = [(n, p, (at[n] * x if n in at else None), (at[n] * x + 0.01 * x if n in at else None))
              for n, p, _, _ in bones]
    bm, _ = bmaps.guess_bone_map(placed, use_presets=False)
    ue5 = bmaps.preset("ue5")
    for j in ("left_shoulder", "left_elbow", "left_hip", "left_knee"):
        assert bm.twist[j] == ue5.twist[j], (j, bm.twist[j])
    # without positions: the rig's own order (here 01 before 02), still only bones below the arm
    bm2, _ = bmaps.guess_bone_map(bones, use_presets=False)
    assert bm2.twist["left_elbow"] == ["lowerarm_twist_01_l", "lowerarm_twist_02_l"]
    assert bm2.twist["left_shoulder"] == ["upperarm_twist_01_l", "upperarm_twist_02_l"]
    body = sk.make_body(1.75)
    names = [b[0] for b in bones]
    rig = rt.TargetRig(names, [b[1] for b in bones], np.broadcast_to(np.eye(3), (len(names), 3, 3)),
                       np.arange(3 * len(names), dtype=float).reshape(-1, 3))
    rt.make_plan(body, rig, bm2)                                         # a map the retarget accepts


def _arp_rig(body, twist="c_arm_twist_offset", seed=5):
    """An Auto-Rig Pro rig as its export writes it: ``(TargetRig, bones)``, bones as
    :func:`bone_maps.guess_bone_map` takes them (name, parent, head, tail; metres, A-pose, rolls).

    twist: the upper arm's twist bone (``c_arm_twist_offset``, or ``arm_twist`` as some exports
    name it): each limb segment split in two along its length, ``{twist}.l`` from the shoulder
    half-way and ``arm_stretch.l`` on to the elbow under it, ``thigh_twist.l`` > ``thigh_stretch.l``
    from the hip, ``forearm_stretch.l`` > ``forearm_twist.l`` > ``hand.l``, ``leg_stretch.l`` >
    ``leg_twist.l`` > ``foot.l``.  ``None``: exported without twist bones (each segment one
    *_stretch bone)."""
    rng = np.random.default_rng(seed)
    P, ydir = _joint_rig_geometry(body, _scales(1.05, 0.97, 1.03), 50.0)
    bones, B = [], []

    def add(name, parent, head, y, tail=None):
        head = np.asarray(head, float)
        bones.append((name, parent, head, head + 0.1 * rot.normalize(y) if tail is None else tail))
        B.append(_frame(y, rng))

    add("c_traj", None, np.zeros(3), [0, 1.0, 0])
    prev = "c_traj"
    for jn, b in (("pelvis", "root.x"), ("spine1", "spine_01.x"), ("spine2", "spine_02.x"),
                  ("spine3", "spine_03.x"), ("neck", "neck.x"), ("head", "head.x")):
        add(b, prev, P[J[jn]], ydir[J[jn]])
        prev = b
    for side, s in (("left", "l"), ("right", "r")):
        add(f"shoulder.{s}", "spine_03.x", P[J[f"{side}_collar"]], ydir[J[f"{side}_collar"]])
        chains = ((f"shoulder.{s}", ("shoulder", "elbow", "wrist"),
                   (f"{twist}.{s}", f"arm_stretch.{s}"), (f"forearm_stretch.{s}", f"forearm_twist.{s}"),
                   f"hand.{s}"),
                  ("root.x", ("hip", "knee", "ankle"), (f"thigh_twist.{s}", f"thigh_stretch.{s}"),
                   (f"leg_stretch.{s}", f"leg_twist.{s}"), f"foot.{s}"))
        for parent, (a, m, e), upper, lower, end in chains:
            pa, pm, pe = (P[J[f"{side}_{n}"]] for n in (a, m, e))
            for (hd, tl), names in (((pa, pm), upper), ((pm, pe), lower)):
                if twist is None:       # one *_stretch bone over the whole segment
                    stretch = next(n for n in names if "_stretch." in n)
                    add(stretch, parent, hd, tl - hd, tl)
                    parent = stretch
                    continue
                half = 0.5 * (hd + tl)
                add(names[0], parent, hd, tl - hd, half)
                add(names[1], names[0], half, tl - hd, tl)
                parent = names[1]
            add(end, parent, pe, ydir[J[f"{side}_{e}"]])
        add(f"toes_01.{s}", f"foot.{s}", P[J[f"{side}_foot"]], ydir[J[f"{side}_foot"]])
        add(f"index1.{s}", f"hand.{s}", P[J[f"{side}_wrist"]] + 0.08 * rot.normalize(ydir[J[f"{side}_wrist"]]),
            ydir[J[f"{side}_wrist"]])
    rig = rt.TargetRig([b[0] for b in bones], [b[1] for b in bones], np.array(B), np.array([b[2] for b in bones]))
    return rig, bones


@pytest.mark.parametrize("twist", ["c_arm_twist_offset", "arm_twist", None])
def test_auto_rig_pro_preset_fits_its_export_with_and_without_twist_bones(twist):
    """Auto-Rig Pro deforms with root.x, spine_0N.x, shoulder.l, the limbs' *_stretch bones,
    hand.l, foot.l, toes_01.l (arm.l, forearm.l, thigh.l and leg.l are mechanism bones of the
    control rig).  Exported with twist bones, the upper arm and thigh start with their twist bone
    (c_arm_twist_offset.l or arm_twist.l, thigh_twist.l) and the *_stretch bone hangs under it
    from half-way: fitted to such a rig, the preset makes that twist bone the segment's bone, so
    the arm pivots at the shoulder, not half-way along it, and the skin of both halves follows."""
    body, local, root, pos, wrot = _smooth_source(frames=40, seed=7)
    rig, bones = _arp_rig(body, twist=twist)
    names = [b[0] for b in bones]
    fitted = bmaps.validate_bone_map(bmaps.fit_twist(bmaps.preset("auto_rig_pro"), bones), names)
    assert fitted.bones["pelvis"] == "root.x" and fitted.bones["right_knee"] == "leg_stretch.r"
    if twist is None:
        assert fitted.twist == {} and fitted.bones == bmaps.preset("auto_rig_pro").bones
    else:
        assert fitted.bones["left_shoulder"] == f"{twist}.l" and fitted.bones["right_hip"] == "thigh_twist.r"
        assert fitted.twist["left_shoulder"] == ["arm_stretch.l"] and fitted.twist["right_hip"] == ["thigh_stretch.r"]
        assert fitted.twist["left_elbow"] == ["forearm_twist.l"] and fitted.twist["right_knee"] == ["leg_twist.r"]
        with pytest.raises(ValueError, match="has no bone"):      # the unfitted preset names bones it lacks
            bmaps.validate_bone_map(bmaps.preset("auto_rig_pro"), names)
    bm, notes = bmaps.guess_bone_map(bones)
    assert bm.name == "auto_rig_pro" and bm.bones == fitted.bones and bm.twist == fitted.twist
    assert all(n.confidence == 1.0 for n in notes)

    # every segment of the character points where the performer's does, from the joint it
    # starts at; both halves of a split segment turn together
    res = rt.retarget(wrot, pos, body, rig, fitted, "scaled")
    assert _seg_dirs(res, rig, fitted, pos, wrot, body).max() < 1e-7
    hw, i = res.world_heads(), rig.index
    for side, s in (("left", "l"), ("right", "r")):
        for a, b, c in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle")):
            d_src = rot.normalize(pos[:, J[f"{side}_{b}"]] - pos[:, J[f"{side}_{a}"]])
            d_tgt = rot.normalize(hw[:, i[fitted.bones[f"{side}_{b}"]]] - hw[:, i[fitted.bones[f"{side}_{a}"]]])
            assert np.abs(d_tgt - d_src).max() < 1e-7, (side, a)
            for tb in fitted.twist.get(f"{side}_{a}", ()):          # the lower half on the same line
                d_half = rot.normalize(hw[:, i[tb]] - hw[:, i[fitted.bones[f"{side}_{a}"]]])
                assert np.abs(d_half - d_src).max() < 1e-7, tb
    if twist is None:
        return
    # the map ARP exports were given before (the *_stretch bones, no twist bones) left the twist
    # bones above them at rest: each upper arm and thigh turned about its middle, the elbows and
    # knees centimetres to decimetres away from where the shoulder and hip joints put them
    old = rt.retarget(wrot, pos, body, rig, bmaps.BoneMap("old", bmaps.preset("auto_rig_pro").bones), "scaled")
    assert res.plan.notes == []
    # such a map (a saved one, say) is told what is wrong, once per split upper arm and thigh
    said = [n for n in old.plan.notes if "starts the same segment" in n]
    assert len(said) == 4 and any(n.startswith(f"'arm_stretch.l' (left_shoulder) hangs under '{twist}.l'")
                                  and n.endswith(f"map left_shoulder to '{twist}.l' with 'arm_stretch.l' as its "
                                                 f"twist bone") for n in said), said
    ho = old.world_heads()
    seg = {}
    for side, s in (("left", "l"), ("right", "r")):
        for a, b, top in (("shoulder", "elbow", f"{twist}.{s}"), ("hip", "knee", f"thigh_twist.{s}")):
            d_src = rot.normalize(pos[:, J[f"{side}_{b}"]] - pos[:, J[f"{side}_{a}"]])
            d_old = rot.normalize(ho[:, i[fitted.bones[f"{side}_{b}"]]] - ho[:, i[top]])
            seg[(side, a)] = float(np.degrees(np.arccos(np.clip(np.sum(d_old * d_src, -1), -1, 1))).max())
    assert min(seg.values()) > 5.0, seg

    # the split segment's twist ramps along it: the top half (the segment's bone now) keeps a
    # quarter, the lower half three quarters, as one twist bone half-way along
    plain = bmaps.BoneMap("no twist", dict(fitted.bones))
    r0 = rt.retarget(wrot, pos, body, rig, plain, "scaled")
    ey = np.array([0, 1.0, 0])
    for main, tw in ((f"{twist}.l", "arm_stretch.l"), ("thigh_twist.r", "thigh_stretch.r"),
                     ("forearm_stretch.r", "forearm_twist.r"), ("leg_stretch.l", "leg_twist.l")):
        tau = np.unwrap(rot.twist_angle(r0.basis_rot[:, i[main]], ey))
        assert np.ptp(tau) > 0.2, main               # the motion does twist these segments
        assert np.abs(res.orientations[:, i[main]]
                      - r0.orientations[:, i[main]] @ rot.axis_angle_rotation(ey, -0.75 * tau)).max() < 1e-9
        rel = np.swapaxes(res.orientations[:, i[main]], -1, -2) @ res.orientations[:, i[tw]]
        expect = rot.axis_angle_rotation(ey, 0.5 * tau) @ (rig.rest_rot[i[main]].T @ rig.rest_rot[i[tw]])
        assert np.abs(rel - expect).max() < 1e-9, tw
    # hands and feet keep their orientations whatever the twist bones do
    for b in ("hand.l", "foot.r", "head.x"):
        assert np.abs(res.world_orientations()[:, i[b]] - r0.world_orientations()[:, i[b]]).max() < 1e-9


def test_a_twist_bone_above_its_segment_starts_it_only_from_the_segment_base():
    """The fit makes a listed twist bone above the segment's bone the segment's bone only when it
    hangs between that bone and the bone of the joint above, its head not past the segment
    bone's: an ARP-named bone elsewhere (under the clavicle beside the arm, or above the
    clavicle's bone) is left out."""
    body = sk.make_body(1.75)
    _, bones = _arp_rig(body)
    beside = [(n, "shoulder.l" if n == "arm_stretch.l" else p, h, t) for n, p, h, t in bones]
    fit = bmaps.fit_twist(bmaps.preset("auto_rig_pro"), beside)
    assert fit.bones["left_shoulder"] == "arm_stretch.l" and "left_shoulder" not in fit.twist
    assert fit.bones["right_shoulder"] == "c_arm_twist_offset.r"
    # a twist bone whose head lies past the segment bone's (here: moved down to the elbow)
    past = [(n, p, h + (t - h) * 3 if n == "c_arm_twist_offset.l" else h, t) for n, p, h, t in bones]
    fit = bmaps.fit_twist(bmaps.preset("auto_rig_pro"), past)
    assert fit.bones["left_shoulder"] == "arm_stretch.l" and fit.bones["right_shoulder"] == "c_arm_twist_offset.r"


def _mpfb_rig(body, seed=6):
    """MakeHuman / MPFB's default skeleton (as its names and hierarchy go): ``(TargetRig, bones)``.

    No bone named hips or pelvis: ``root`` is the hips, with the spine (spine05 up to spine01,
    then neck01-03 and head) and each leg's ``pelvis.L`` above it; every limb segment is two bones
    (upperarm01.L > upperarm02.L, lowerarm01/02, upperleg01/02, lowerleg01/02), the hand is
    ``wrist.L``, a ``shoulder01.L`` sits between the clavicle and the upper arm."""
    rng = np.random.default_rng(seed)
    P, ydir = _joint_rig_geometry(body, _scales(0.97, 1.04, 0.98), 45.0)
    bones, B = [], []

    def add(name, parent, head, y):
        head = np.asarray(head, float)
        bones.append((name, parent, head, head + 0.1 * rot.normalize(y)))
        B.append(_frame(y, rng))

    add("root", None, P[0], P[J["spine1"]] - P[0])
    sp = [P[0] + (P[J["neck"]] - P[0]) * (i + 0.5) / 5 for i in range(5)]
    prev = "root"
    for i, h in enumerate(sp):
        add(f"spine0{5 - i}", prev, h, P[J["neck"]] - P[0])
        prev = f"spine0{5 - i}"
    for i in range(3):
        add(f"neck0{i + 1}", prev, P[J["neck"]] + (P[J["head"]] - P[J["neck"]]) * i / 3, P[J["head"]] - P[J["neck"]])
        prev = f"neck0{i + 1}"
    add("head", prev, P[J["head"]], [0, 0, 1.0])
    for side, s in (("left", "L"), ("right", "R")):
        c, a = P[J[f"{side}_collar"]], P[J[f"{side}_shoulder"]]
        add(f"clavicle.{s}", "spine01", c, a - c)
        add(f"shoulder01.{s}", f"clavicle.{s}", 0.5 * (c + a), a - c)
        for parent, stems, (ja, jm, je), end in (
                (f"shoulder01.{s}", ("upperarm", "lowerarm"), ("shoulder", "elbow", "wrist"), "wrist"),
                (f"pelvis.{s}", ("upperleg", "lowerleg"), ("hip", "knee", "ankle"), "foot")):
            if end == "foot":
                add(f"pelvis.{s}", "root", P[0], P[J[f"{side}_hip"]] - P[0])
            pts = [P[J[f"{side}_{n}"]] for n in (ja, jm, je)]
            for stem, (hd, tl) in zip(stems, ((pts[0], pts[1]), (pts[1], pts[2]))):
                add(f"{stem}01.{s}", parent, hd, tl - hd)
                add(f"{stem}02.{s}", f"{stem}01.{s}", 0.5 * (hd + tl), tl - hd)
                parent = f"{stem}02.{s}"
            add(f"{end}.{s}", parent, pts[2], ydir[J[f"{side}_{je}"]])
        add(f"toe1-1.{s}", f"foot.{s}", P[J[f"{side}_foot"]], ydir[J[f"{side}_foot"]])
    rig = rt.TargetRig([b[0] for b in bones], [b[1] for b in bones], np.array(B), np.array([b[2] for b in bones]))
    return rig, bones


def test_guess_maps_a_makehuman_skeleton_from_where_the_legs_and_spine_meet():
    """A rig with no bone named hips or pelvis gets, as its pelvis, the bone where the legs and the
    spine meet (MPFB's ``root``), not the root-most spine bone (spine05, which the legs do not
    hang from: mapped there, the character's legs stayed behind at rest while its body moved);
    each segment's second bone (upperarm02.L, ...) shares the segment's twist."""
    body, local, root, pos, wrot = _smooth_source(frames=40, seed=7)
    rig, bones = _mpfb_rig(body)
    bm, notes = bmaps.guess_bone_map(bones)
    by = {n.joint: n for n in notes}
    assert bm.bones["pelvis"] == "root" and "legs and the spine meet" in by["pelvis"].why
    assert [bm.bones[j] for j in ("spine1", "spine2", "spine3", "neck", "head")] == \
        ["spine05", "spine03", "spine01", "neck01", "head"]
    assert [bm.bones[f"left_{j}"] for j in ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle", "foot")] \
        == ["clavicle.L", "upperarm01.L", "lowerarm01.L", "wrist.L", "upperleg01.L", "lowerleg01.L", "foot.L",
            "toe1-1.L"]
    assert bm.twist == {f"{side}_{j}": [f"{stem}02.{side[0].upper()}"]
                        for side in ("left", "right") for j, stem in (("shoulder", "upperarm"), ("elbow", "lowerarm"),
                                                                       ("hip", "upperleg"), ("knee", "lowerleg"))}
    bmaps.validate_bone_map(bm, rig.names)
    res = rt.retarget(wrot, pos, body, rig, bm, "scaled")
    assert _seg_dirs(res, rig, bm, pos, wrot, body).max() < 1e-7
    # the feet go where the body's do, relative to the pelvis, scaled by the leg ratio
    hw, i, k = res.world_heads(), rig.index, res.plan.leg_ratio
    for side, s in (("left", "L"), ("right", "R")):
        rel_t = hw[:, i[f"foot.{s}"]] - hw[:, i["root"]]
        rel_s = pos[:, J[f"{side}_ankle"]] - pos[:, 0]
        assert np.abs(np.linalg.norm(rel_t, axis=-1) - k * np.linalg.norm(rel_s, axis=-1)).max() < 0.01
    # mapped to the root-most spine bone, as the guess did before, the legs stayed where they
    # stood at rest while the body walked 0.8 m away from them
    old = bmaps.BoneMap("old", dict(bm.bones, pelvis="spine05", spine1="spine04"), bm.twist)
    ro = rt.retarget(wrot, pos, body, rig, old, "scaled")
    assert np.ptp(ro.world_heads()[:, i["upperleg01.L"]], axis=0).max() < 1e-12
    drift = np.linalg.norm(ro.world_heads()[:, i["upperleg01.L"]] - ro.world_heads()[:, i["spine05"]], axis=-1)
    assert np.ptp(drift) > 0.5


@pytest.mark.parametrize("apose_deg, turned", [(0.0, False), (45.0, False), (45.0, True)])
def test_a_rigs_end_bones_read_back_as_the_bodys_orientations(apose_deg, turned):
    """rig_keypoints.end_orientations / retarget.body_world_from_bones read a rig's head, hand and
    foot bones back into the body's convention: a source motion retargeted onto a rig (T- or
    A-pose rest, random rolls, facing -Y or turned to +Y) reads back as that motion's world
    orientations (turned with the rig: F R Fᵀ F)."""
    from blender_manikin.core import rig_keypoints as rk
    body, local, root, pos, wrot = _smooth_source(frames=40, seed=5)
    rig, bmap, _ = mixamo_rig(body, apose_deg=apose_deg)
    F = np.eye(3)
    if turned:
        F = rot.axis_angle_rotation(np.array([0, 0, 1.0]), np.array(np.pi))
        rig = rt.TargetRig(rig.names, rig.parents, F @ rig.rest_rot, rig.heads @ F.T)
    res = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    Gw = rig.world_rot @ res.orientations         # (T, B, 3, 3) world orientations of the bones
    bones = {j: Gw[:, rig.index[bmap.bones[j]]] for j in rk.END_JOINTS}
    got = rk.end_orientations(rig, bmap, bones)
    assert set(got) == set(rk.END_JOINTS)
    for j in rk.END_JOINTS:
        want = F @ wrot[:, J[j]] @ F.T @ F
        ang = np.degrees(rot.geodesic_angle(got[j], want)).max()
        assert ang < 1e-4, (j, ang)                # degrees


def _rig_with_turned_hands(body, apose_deg, turn_deg, seed=7, forearm_twist=False):
    """A Mixamo-named rig (random rolls) whose hands rest turned about their bones by ``turn_deg``
    (left, right) from the body's palms-down (turned with the arm in an A-pose), with index,
    middle, ring, little finger and thumb bones placed on that turned palm.  Returns ``(rig, map,
    M)``: M ``{wrist joint: (3, 3)}`` the hand bone's world orientation in the body's rest pose
    (palms down, T-pose), what the body's wrist rotation poses."""
    rig, bmap, _ = mixamo_rig(body, seed=seed, extra=False, apose_deg=apose_deg)
    leaf = end_site_offsets(body)
    names, B, heads = list(rig.names), list(rig.rest_rot), list(rig.heads)
    parents = [rig.names[p] if p >= 0 else None for p in rig.parents]
    M = {}
    for (side, S, sgn), turn in zip((("left", "Left", 1.0), ("right", "Right", -1.0)), turn_deg):
        e = rot.normalize(leaf[J[f"{side}_wrist"]])
        Ra = rot.axis_angle_rotation(np.array([0, 1.0, 0]), np.array(sgn * np.radians(apose_deg)))
        Tw = rot.axis_angle_rotation(e, np.array(np.radians(turn)))
        k = rig.index[f"mixamorig:{S}Hand"]
        M[f"{side}_wrist"] = Ra.T @ rig.rest_rot[k]             # Y along e, the rig's random roll
        B[k] = Ra @ Tw @ M[f"{side}_wrist"]
        # knuckles across the palm-down hand, thumb side (-Y, the body faces -Y) to little finger
        for n, off in (("Index", (0.09, -0.03, 0.0)), ("Middle", (0.095, -0.01, 0.0)),
                       ("Ring", (0.09, 0.01, 0.0)), ("Pinky", (0.08, 0.03, 0.0)), ("Thumb", (0.03, -0.04, -0.01))):
            o = np.array([sgn * off[0], off[1], off[2]])
            for i in (1, 2):
                names.append(f"mixamorig:{S}Hand{n}{i}")
                parents.append(f"mixamorig:{S}Hand" if i == 1 else f"mixamorig:{S}Hand{n}1")
                B.append(Ra @ Tw @ _frame(o, rng=np.random.default_rng(i)))
                heads.append(rig.heads[k] + Ra @ Tw @ (o * (1.0 + 0.4 * (i - 1))))
        if forearm_twist:
            ke = rig.index[f"mixamorig:{S}ForeArm"]
            names.append(f"mixamorig:{S}ForeArmTwist")
            parents.append(f"mixamorig:{S}ForeArm")
            B.append(rig.rest_rot[ke])
            heads.append(0.5 * (rig.heads[ke] + rig.heads[k]))
            bmap.twist[f"{side}_elbow"] = [f"mixamorig:{S}ForeArmTwist"]
    return rt.TargetRig(names, parents, np.array(B), np.array(heads)), bmap, M


@pytest.mark.parametrize("apose_deg, turn", [(0.0, (-90.0, 90.0)), (40.0, (30.0, 30.0)), (40.0, (-25.0, 35.0))])
def test_a_rig_resting_with_its_palms_turned_gets_the_bodys_hand_turn(apose_deg, turn):
    """A rig resting palms-forward (T-pose) or with its hands turned 30° in an A-pose: its rest palm
    is read from its finger bones, so the retargeted hand has the body's hand orientation (before,
    the rest twist was taken as palms-down and the hand came out 90° / 30° off), the plan says so,
    and the rest of the rig is as without the turn."""
    body, local, root, pos, wrot = _smooth_source(frames=30, seed=2)
    rig, bmap, M = _rig_with_turned_hands(body, apose_deg, turn)
    res = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    Gw = res.world_orientations()
    for side, S, t in (("left", "Left", turn[0]), ("right", "Right", turn[1])):
        j = f"{side}_wrist"
        ang = np.degrees(rot.geodesic_angle(Gw[:, rig.index[f"mixamorig:{S}Hand"]], wrot[:, J[j]] @ M[j])).max()
        assert ang < 1.0, (j, ang)
        assert res.plan.palms[j].startswith(f"fingers 'mixamorig:{S}HandIndex1' to 'mixamorig:{S}HandPinky1'")
        assert f"{abs(t):.0f}° from palms-down" in " ".join(res.plan.notes)
    # the same rig resting palms-down: every other bone as before
    flat, _, _ = _rig_with_turned_hands(body, apose_deg, (0.0, 0.0))
    ref = rt.retarget(wrot, pos, body, flat, bmap, "scaled")
    assert ref.plan.notes == [] and "rests turned 0.0° from" in ref.plan.palms["left_wrist"]
    others = [k for k, n in enumerate(rig.names) if "Hand" not in n]
    np.testing.assert_allclose(res.world_orientations()[:, others], ref.world_orientations()[:, others], atol=1e-9)


def test_a_turned_rest_palm_is_carried_by_the_forearm_twist_bones():
    """With a forearm twist bone the rest palm's turn is shared along the forearm as any forearm
    twist is (the twist bone half-way takes 3/4 of it, the forearm 1/4), the hand has it whole."""
    body, local, root, pos, wrot = _smooth_source(frames=10, seed=2)
    rig, bmap, M = _rig_with_turned_hands(body, 0.0, (-90.0, 90.0), forearm_twist=True)
    flat, _, _ = _rig_with_turned_hands(body, 0.0, (0.0, 0.0), forearm_twist=True)
    a = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    b = rt.retarget(wrot, pos, body, flat, bmap, "scaled")
    assert "twist bones" in " ".join(a.plan.notes)
    Ga, Gb = a.world_orientations(), b.world_orientations()
    for S, t in (("Left", -90.0), ("Right", 90.0)):
        for name, share in ((f"{S}ForeArm", 0.25), (f"{S}ForeArmTwist", 0.75)):
            k = rig.index[f"mixamorig:{name}"]
            # the turned rig's bone, turned back by its share of the rest turn (-t), is the flat rig's
            y = Ga[:, k, :, 1]
            back = rot.axis_angle_rotation(y, np.full(len(y), np.radians(share * t))) @ Ga[:, k]
            assert np.degrees(rot.geodesic_angle(back, Gb[:, k])).max() < 0.5, name
        k = rig.index[f"mixamorig:{S}Hand"]
        j = "left_wrist" if S == "Left" else "right_wrist"
        assert np.degrees(rot.geodesic_angle(Ga[:, k], wrot[:, J[j]] @ M[j])).max() < 1.0


def test_a_rig_without_finger_bones_keeps_its_rest_palm_and_says_so():
    body, local, root, pos, wrot = _smooth_source(frames=5, seed=2)
    rig, bmap, _ = mixamo_rig(body)                      # one finger bone per hand: no knuckle line
    plan = rt.make_plan(body, rig, bmap)
    assert plan.palms["left_wrist"].startswith("assumed palms-down") and plan.notes == []


@pytest.mark.parametrize("apose_deg, turn", [(0.0, (-90.0, 90.0)), (40.0, (30.0, -30.0))])
def test_an_armatures_palm_up_hand_reads_back_palm_up_whatever_its_rest_palm(apose_deg, turn):
    """rig_keypoints.end_orientations on a rig resting palms-forward or with its hands turned 30°:
    a hand bone turned palm-up (180° about the arm, the arm held out sideways) and one lowered,
    palm-forward, read back as those body wrist rotations (before: off by the rest turn)."""
    from blender_manikin.core import rig_keypoints as rk
    body = sk.make_body()
    rig, bmap, M = _rig_with_turned_hands(body, apose_deg, turn)
    leaf = end_site_offsets(body)
    e = rot.normalize(leaf[J["left_wrist"]])
    want = {"left_wrist": rot.axis_angle_rotation(np.stack([e, e]), np.radians([180.0, 170.0])),
            "right_wrist": np.stack([rot.axis_angle_rotation(np.array([0, 1.0, 0]), np.radians(80.0)) @
                                     rot.axis_angle_rotation(np.array([1.0, 0, 0]), np.radians(90.0)), np.eye(3)])}
    got = rk.end_orientations(rig, rk.checked_map(bmap, rig.names), {j: R @ M[j] for j, R in want.items()})
    for j, R in want.items():
        ang = np.degrees(rot.geodesic_angle(got[j], R)).max()
        assert ang < 1.0, (j, ang)


def test_finger_knuckles_by_name_and_kept_by_a_restricted_rig():
    """finger_knuckles finds each finger's knuckle bone below the hand whatever the rig's naming
    (metacarpals skipped, the thumb and props ignored); finger_bones keeps them when the rig is
    restricted to the driven bones, so the restricted rig turns its hands as the full one does."""
    def knuckles(bones):
        names = ["hand"] + [n for n, _ in bones]
        tg = rt.TargetRig(names, [None] + [p for _, p in bones], np.broadcast_to(np.eye(3), (len(names), 3, 3)),
                          np.zeros((len(names), 3)))
        return {f: tg.names[b] for f, b in rt.finger_knuckles(tg, "hand").items()}

    assert knuckles([("index_metacarpal_l", "hand"), ("index_01_l", "index_metacarpal_l"),
                     ("pinky_metacarpal_l", "hand"), ("pinky_01_l", "pinky_metacarpal_l"),
                     ("thumb_01_l", "hand"), ("weapon_l", "hand")]) == {0: "index_01_l", 3: "pinky_01_l"}
    assert knuckles([("DEF-palm.01.L", "hand"), ("DEF-f_index.01.L", "DEF-palm.01.L"),
                     ("DEF-f_index.02.L", "DEF-f_index.01.L"), ("DEF-palm.04.L", "hand"),
                     ("DEF-f_pinky.01.L", "DEF-palm.04.L"), ("DEF-thumb.01.L", "DEF-palm.01.L")]) \
        == {0: "DEF-f_index.01.L", 3: "DEF-f_pinky.01.L"}
    assert knuckles([("index1_base.l", "hand"), ("index1.l", "index1_base.l"), ("c_ring1_base.l", "hand"),
                     ("ring1.l", "c_ring1_base.l")]) == {0: "index1.l", 2: "ring1.l"}
    assert knuckles([("CC_Base_L_Mid1", "hand"), ("CC_Base_L_Pinky1", "hand"), ("CC_Base_L_Thumb1", "hand")]) \
        == {1: "CC_Base_L_Mid1", 3: "CC_Base_L_Pinky1"}
    assert knuckles([("lCarpal1", "hand"), ("lIndex1", "lCarpal1"), ("lCarpal2", "hand"), ("lPinky1", "lCarpal2")]) \
        == {0: "lIndex1", 3: "lPinky1"}
    assert knuckles([("finger1-1.L", "hand"), ("finger2-1.L", "hand"), ("finger5-1.L", "hand")]) \
        == {0: "finger2-1.L", 3: "finger5-1.L"}
    body, local, root, pos, wrot = _smooth_source(frames=10, seed=2)
    rig, bmap, M = _rig_with_turned_hands(body, 0.0, (-90.0, 90.0))
    small = rig.restricted_to(bmap.target_bones() + rt.finger_bones(rig, bmap))
    res = rt.retarget(wrot, pos, body, small, bmap, "scaled")
    k = small.index["mixamorig:LeftHand"]
    want = wrot[:, J["left_wrist"]] @ M["left_wrist"]
    assert np.degrees(rot.geodesic_angle(res.world_orientations()[:, k], want)).max() < 1.0


def test_a_rest_palm_turned_a_few_degrees_is_taken_as_palms_down():
    """Knuckles arch and modellers leave hands a little rolled: a rest palm read within
    ``PALM_TURN_MIN_DEG`` of palms-down is not turned back (the retarget as for a flat palm), and
    the plan says it was taken so."""
    body, local, root, pos, wrot = _smooth_source(frames=10, seed=2)
    rig, bmap, M = _rig_with_turned_hands(body, 40.0, (3.0, -3.0))
    flat, _, _ = _rig_with_turned_hands(body, 40.0, (0.0, 0.0))
    a = rt.retarget(wrot, pos, body, rig, bmap, "scaled")
    b = rt.retarget(wrot, pos, body, flat, bmap, "scaled")
    assert a.plan.notes == []
    said = a.plan.palms["left_wrist"]
    assert "(taken as palms-down)" in said and "3.0° from palms-down" in said
    others = [k for k, n in enumerate(rig.names) if "Hand" not in n]
    np.testing.assert_allclose(a.world_orientations()[:, others], b.world_orientations()[:, others], atol=1e-9)
    # the hand keeps the rig's own 3° roll instead of being turned back
    hand = rig.index["mixamorig:LeftHand"]
    off = np.degrees(rot.geodesic_angle(a.world_orientations()[:, hand], b.world_orientations()[:, hand]))
    np.testing.assert_allclose(off, 3.0, atol=0.2)
