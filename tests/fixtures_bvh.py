"""Synthetic BVH fixtures for the BVH reader and joint-map tests.

Nothing here is committed data: the tests call these functions to write
BVH files into ``tmp_path``.

A synthetic motion is a 22-joint body (``skeleton.make_body``) posed with
smooth random local rotations through ``skeleton.forward_kinematics``
(metres, Blender axes).  It is then written as a source skeleton:

* **Bandai layout** (:func:`bandai_clip`): the Bandai Namco joint names and
  hierarchy (``joint_Root`` ground projection, Hips, Spine, Chest, ...),
  6 channels ``Xposition Yposition Zposition Zrotation Xrotation Yrotation``
  on every joint, centimetres, +Y up, facing +Z, and joint frames that are
  *not* the T-pose frames: each source joint frame is the body joint's frame
  turned by a fixed rotation ``O`` (body-local <- source-local) that points
  local +-X along the bone and follows the axis conventions found in the
  real files (see ``joint_maps``): Hips +X up / -Y left, Head +X up / +Y
  forward, Hand_L +X along the hand / +Y back of the hand, Hand_R -X / -Y,
  Foot +-X to the toes / +Y left.
* **CMU layout** (:func:`cmu_clip`): the cgspeed joint names, a T-pose zero
  pose with world-aligned frames, ``Xposition Yposition Zposition Zrotation
  Yrotation Xrotation`` on Hips and ``Zrotation Yrotation Xrotation``
  elsewhere, CMU units (1/0.45 inch), +Y up.

Both source skeletons have fewer torso joints than the body (Bandai has
Spine/Chest for spine1-3, CMU has Spine/Spine1 and a clavicle starting at the
neck), so the motion keeps the joints they cannot represent fixed
(``FIXED_FOR_SOURCES``); with that the joint maps' interpolations are exact
and a round trip must reproduce the body positions to rounding.

Source world rotation of a joint that follows body joint ``b``:
``R_src = M^T @ R_body[b] @ O`` with ``M`` the source-to-Blender axis
rotation; OFFSETs are the rest-pose differences expressed in the parent's
source frame and divided by the unit scale.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional, Sequence

import numpy as np

from blender_manikin.core import skeleton
from blender_manikin.core.bvh import BvhClip
from blender_manikin.core.joint_maps import REST_FOOT_DIRECTION, axis_conversion
from blender_manikin.core.rotations import axis_angle_to_matrix, rotation_between

J = skeleton.J
M_YUP = axis_conversion("y", "z")          # Blender = M_YUP @ source
CMU_UNIT = 0.0254 / 0.45                   # metres per cgspeed unit

#: Body joints whose local rotation stays identity so both layouts are exact.
FIXED_FOR_SOURCES = ("spine1", "spine2", "spine3", "left_collar", "right_collar")

BANDAI_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
CMU_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
CMU_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")

_ex, _ey, _ez = np.eye(3)


def _cols(*c):
    m = np.stack(c, axis=1).astype(np.float64)
    assert abs(np.linalg.det(m) - 1.0) < 1e-9
    return m


@dataclass
class SrcJoint:
    name: str
    parent: Optional[str]
    rot_from: Optional[str]          # body joint whose world rotation it carries (None: identity)
    O: np.ndarray                    # body-local <- source-local
    rest: np.ndarray                 # rest world position, Blender metres
    end: Optional[np.ndarray] = None  # End Site, rest world offset (Blender metres)


# --------------------------------------------------------------------------
def synthetic_motion(body: Optional[skeleton.Body] = None, frames: int = 90, fps: float = 30.0,
                     seed: int = 0, standing: int = 15, lift: float = 0.35,
                     amplitude: float = 0.6, fixed: Sequence[str] = FIXED_FOR_SOURCES):
    """Smooth random motion of the body model.

    The first ``standing`` frames stand in the rest pose on the floor
    (legs straight, pelvis only yawing, arms and head moving); later frames
    move every joint and are lifted by ``lift`` metres so the feet stay
    above their standing height.  Returns ``(body, local_rot (T,22,3,3),
    root_pos (T,3), positions (T,22,3), world_rot (T,22,3,3))``.
    """
    # barefoot by default: a mocap file's floor, estimated from its feet (joint_maps'
    # floor="auto"), puts the ball of the foot at the body model's barefoot height
    body = body or skeleton.make_body(skeleton.BodyMeasurements(stature=1.75, sole=0.0))
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    freq = rng.uniform(0.3, 1.2, size=(22, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(22, 3))
    amp = rng.uniform(-amplitude, amplitude, size=(22, 3))
    aa = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)
    stand = np.arange(frames) < standing
    legs = [J[n] for n in ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
                           "right_ankle", "left_foot", "right_foot")]
    aa[np.ix_(stand, legs)] = 0.0
    aa[stand, 0, :2] = 0.0                     # pelvis: yaw only while standing
    aa[:, [J[n] for n in fixed]] = 0.0
    local = axis_angle_to_matrix(aa)
    # a slow turn of the whole body (yaw about +Z)
    yaw = axis_angle_to_matrix(np.stack([np.zeros(frames), np.zeros(frames), 0.8 * t], -1))
    local[:, 0] = yaw @ local[:, 0]
    root = np.broadcast_to(body.root_rest, (frames, 3)).copy()
    root[:, 0] += 0.1 * np.sin(t)
    root[:, 1] -= 0.6 * t                      # walks towards -Y (the facing direction)
    root[~stand, 2] += lift
    pos, rot = skeleton.forward_kinematics(local, root, body)
    return body, local, root, pos, rot


# --------------------------------------------------------------------------
def _build(joints: Sequence[SrcJoint], pos, rot, scale: float, channels: Dict[str, Sequence[str]],
           world_positions: Dict[str, np.ndarray], name: str, frame_time: float) -> BvhClip:
    """Source clip whose FK reproduces the body (see module docstring)."""
    M = M_YUP
    T = pos.shape[0]
    names = [j.name for j in joints]
    idx = {n: i for i, n in enumerate(names)}
    parents = np.array([idx[j.parent] if j.parent else -1 for j in joints])
    Rrest, Rw = [], []
    for j in joints:
        if j.rot_from is None:
            Rrest.append(np.eye(3))
            Rw.append(np.broadcast_to(np.eye(3), (T, 3, 3)))
        else:
            Rrest.append(M.T @ j.O)
            Rw.append(M.T @ rot[:, J[j.rot_from]] @ j.O)
    offsets = np.zeros((len(joints), 3))
    ends = np.full((len(joints), 3), np.nan)
    local = np.empty((T, len(joints), 3, 3))
    for i, j in enumerate(joints):
        p = parents[i]
        if p >= 0:
            offsets[i] = Rrest[p].T @ (M.T @ (j.rest - joints[p].rest)) / scale
            local[:, i] = np.swapaxes(Rw[p], -1, -2) @ Rw[i]
        else:
            offsets[i] = M.T @ j.rest / scale
            local[:, i] = Rw[i]
        if j.end is not None:
            ends[i] = Rrest[i].T @ (M.T @ np.asarray(j.end, float)) / scale
    trans = np.broadcast_to(offsets, (T, len(joints), 3)).copy()
    for n, wp in world_positions.items():
        i = idx[n]
        p = parents[i]
        src = np.einsum("ij,tj->ti", M.T, wp) / scale
        if p < 0:
            trans[:, i] = src
        else:
            psrc = np.einsum("ij,tj->ti", M.T, world_positions[names[p]]) / scale
            trans[:, i] = np.einsum("tji,tj->ti", Rw[p], src - psrc)
    chans = [tuple(channels[n]) for n in names]
    return BvhClip.from_local_transforms(name, names, parents, offsets, chans, local, trans,
                                         frame_time=frame_time, end_sites=ends)


def bandai_joints(body: skeleton.Body):
    p = body.rest_positions()
    D = REST_FOOT_DIRECTION
    O_hips = _cols(_ez, -_ex, -_ey)            # X up, Y right (-Y left), Z forward (-Y body)
    O_spine = _cols(_ez, _ex, _ey)             # X up, another twist
    O_chest = _cols(_ez, -_ey, _ex)            # X up, Y forward, Z left (as the real Chest)
    O_head = O_chest
    O_arm_l = _cols(_ex, _ez, -_ey)            # X along the arm, Y back of the hand, Z thumb
    O_arm_r = _cols(_ex, -_ez, _ey)            # -X along the arm, -Y back of the hand
    O_leg_l = _cols(-_ez, _ex, -_ey)           # X down the leg, Y left
    O_leg_r = _cols(_ez, _ex, _ey)             # -X down the leg, Y left
    O_foot_l = _cols(D, _ex, np.cross(D, _ex))
    O_foot_r = _cols(-D, _ex, np.cross(-D, _ex))

    def clav(side, sx):
        d = p[J[f"{side}_shoulder"]] - p[J[f"{side}_collar"]]
        return rotation_between(sx * _ex, d) @ (O_arm_l if sx > 0 else O_arm_r)

    root_rest = p[0] * np.array([1.0, 1.0, 0.0])
    zero = np.zeros(3)
    js = [
        SrcJoint("joint_Root", None, None, np.eye(3), root_rest),
        SrcJoint("Hips", "joint_Root", "pelvis", O_hips, p[J["pelvis"]]),
        SrcJoint("Spine", "Hips", "spine1", O_spine, p[J["spine1"]]),
        SrcJoint("Chest", "Spine", "spine3", O_chest, p[J["spine3"]]),
        SrcJoint("Neck", "Chest", "neck", O_chest, p[J["neck"]]),
        SrcJoint("Head", "Neck", "head", O_head, p[J["head"]], end=zero),
    ]
    for side, s, sx, O in (("left", "L", 1.0, O_arm_l), ("right", "R", -1.0, O_arm_r)):
        js += [
            SrcJoint(f"Shoulder_{s}", "Chest", f"{side}_collar", clav(side, sx), p[J[f"{side}_collar"]]),
            SrcJoint(f"UpperArm_{s}", f"Shoulder_{s}", f"{side}_shoulder", O, p[J[f"{side}_shoulder"]]),
            SrcJoint(f"LowerArm_{s}", f"UpperArm_{s}", f"{side}_elbow", O, p[J[f"{side}_elbow"]]),
            SrcJoint(f"Hand_{s}", f"LowerArm_{s}", f"{side}_wrist", O, p[J[f"{side}_wrist"]], end=zero),
        ]
    for side, s, Ol, Of in (("left", "L", O_leg_l, O_foot_l), ("right", "R", O_leg_r, O_foot_r)):
        js += [
            SrcJoint(f"UpperLeg_{s}", "Hips", f"{side}_hip", Ol, p[J[f"{side}_hip"]]),
            SrcJoint(f"LowerLeg_{s}", f"UpperLeg_{s}", f"{side}_knee", Ol, p[J[f"{side}_knee"]]),
            SrcJoint(f"Foot_{s}", f"LowerLeg_{s}", f"{side}_ankle", Of, p[J[f"{side}_ankle"]]),
            SrcJoint(f"Toes_{s}", f"Foot_{s}", f"{side}_foot", Of, p[J[f"{side}_foot"]], end=zero),
        ]
    return js


def bandai_clip(body, pos, rot, name="synthetic_bandai", fps=30.0, scale=0.01, raise_by=0.0,
                channels=BANDAI_CHANNELS) -> BvhClip:
    """Bandai-layout clip of a posed body (``raise_by`` metres moves it up in the source)."""
    js = bandai_joints(body)
    up = np.array([0.0, 0.0, raise_by])
    for j in js:
        j.rest = j.rest + up
    pelvis = pos[:, J["pelvis"]] + up
    root = pelvis * np.array([1.0, 1.0, 0.0]) + up
    pos2 = pos + up
    # every joint's position channels hold its translation (= OFFSET below Hips)
    chans = {j.name: channels for j in js}
    clip = _build(js, pos2, rot, scale, chans, {"joint_Root": root, "Hips": pelvis}, name, 1.0 / fps)
    return clip


def cmu_joints(body: skeleton.Body):
    p = body.rest_positions()
    M = M_YUP
    f = 0.4
    js = [SrcJoint("Hips", None, "pelvis", M, p[J["pelvis"]])]
    for side, S, sx in (("left", "Left", 1.0), ("right", "Right", -1.0)):
        js += [
            SrcJoint(f"{S[0]}HipJoint", "Hips", "pelvis", M, p[J["pelvis"]]),
            SrcJoint(f"{S}UpLeg", f"{S[0]}HipJoint", f"{side}_hip", M, p[J[f"{side}_hip"]]),
            SrcJoint(f"{S}Leg", f"{S}UpLeg", f"{side}_knee", M, p[J[f"{side}_knee"]]),
            SrcJoint(f"{S}Foot", f"{S}Leg", f"{side}_ankle", M, p[J[f"{side}_ankle"]]),
            SrcJoint(f"{S}ToeBase", f"{S}Foot", f"{side}_foot", M, p[J[f"{side}_foot"]],
                     end=0.06 * REST_FOOT_DIRECTION * np.array([1, 1, 0])),
        ]
    neck1 = 0.5 * (p[J["neck"]] + p[J["head"]])
    js += [
        SrcJoint("LowerBack", "Hips", "pelvis", M, p[J["pelvis"]]),
        SrcJoint("Spine", "LowerBack", "spine2", M, p[J["spine2"]]),
        SrcJoint("Spine1", "Spine", "spine3", M, p[J["neck"]]),
        SrcJoint("Neck", "Spine1", "neck", M, p[J["neck"]]),
        SrcJoint("Neck1", "Neck", "neck", M, neck1),
        SrcJoint("Head", "Neck1", "head", M, p[J["head"]], end=np.array([0.0, 0.0, 0.1])),
    ]
    for side, S, T_, sx in (("left", "Left", "L", 1.0), ("right", "Right", "R", -1.0)):
        collar, shoulder, wrist = (p[J[f"{side}_{n}"]] for n in ("collar", "shoulder", "wrist"))
        clav_root = (collar - f * shoulder) / (1.0 - f)
        js += [
            SrcJoint(f"{S}Shoulder", "Spine1", f"{side}_collar", M, clav_root),
            SrcJoint(f"{S}Arm", f"{S}Shoulder", f"{side}_shoulder", M, shoulder),
            SrcJoint(f"{S}ForeArm", f"{S}Arm", f"{side}_elbow", M, p[J[f"{side}_elbow"]]),
            SrcJoint(f"{S}Hand", f"{S}ForeArm", f"{side}_wrist", M, wrist),
            SrcJoint(f"{S}FingerBase", f"{S}Hand", f"{side}_wrist", M, wrist),
            SrcJoint(f"{S}HandIndex1", f"{S}FingerBase", f"{side}_wrist", M, wrist + [sx * 0.045, 0, 0],
                     end=np.array([sx * 0.036, 0, 0])),
            SrcJoint(f"{T_}Thumb", f"{S}Hand", f"{side}_wrist", M, wrist,
                     end=np.array([sx * 0.037, -0.037, 0.0])),
        ]
    return js


def cmu_clip(body, pos, rot, name="synthetic_cmu", fps=120.0, scale=CMU_UNIT,
             root_channels=CMU_ROOT_CHANNELS, channels=CMU_CHANNELS) -> BvhClip:
    js = cmu_joints(body)
    chans = {j.name: channels for j in js}
    chans["Hips"] = root_channels
    return _build(js, pos, rot, scale, chans, {"Hips": pos[:, J["pelvis"]]}, name, 1.0 / fps)


def mixamo_joints(body: skeleton.Body, prefix: str = "mixamorig:"):
    """Mixamo's rig (``prefix`` + names): Hips, Spine, Spine1, Spine2 at the body's pelvis and
    spine1-3, Neck on Spine2, a T-pose zero pose with world-aligned frames (a BVH as Blender
    writes from Mixamo's FBX)."""
    p = body.rest_positions()
    M, f, n = M_YUP, 0.4, prefix
    js = [SrcJoint(n + "Hips", None, "pelvis", M, p[J["pelvis"]])]
    for side, S in (("left", "Left"), ("right", "Right")):
        js += [
            SrcJoint(f"{n}{S}UpLeg", n + "Hips", f"{side}_hip", M, p[J[f"{side}_hip"]]),
            SrcJoint(f"{n}{S}Leg", f"{n}{S}UpLeg", f"{side}_knee", M, p[J[f"{side}_knee"]]),
            SrcJoint(f"{n}{S}Foot", f"{n}{S}Leg", f"{side}_ankle", M, p[J[f"{side}_ankle"]]),
            SrcJoint(f"{n}{S}ToeBase", f"{n}{S}Foot", f"{side}_foot", M, p[J[f"{side}_foot"]],
                     end=0.06 * REST_FOOT_DIRECTION * np.array([1, 1, 0])),
        ]
    js += [
        SrcJoint(n + "Spine", n + "Hips", "spine1", M, p[J["spine1"]]),
        SrcJoint(n + "Spine1", n + "Spine", "spine2", M, p[J["spine2"]]),
        SrcJoint(n + "Spine2", n + "Spine1", "spine3", M, p[J["spine3"]]),
        SrcJoint(n + "Neck", n + "Spine2", "neck", M, p[J["neck"]]),
        SrcJoint(n + "Head", n + "Neck", "head", M, p[J["head"]], end=np.array([0.0, 0.0, 0.18])),
    ]
    for side, S in (("left", "Left"), ("right", "Right")):
        collar, shoulder, wrist = (p[J[f"{side}_{k}"]] for k in ("collar", "shoulder", "wrist"))
        js += [
            SrcJoint(f"{n}{S}Shoulder", n + "Spine2", f"{side}_collar", M, (collar - f * shoulder) / (1.0 - f)),
            SrcJoint(f"{n}{S}Arm", f"{n}{S}Shoulder", f"{side}_shoulder", M, shoulder),
            SrcJoint(f"{n}{S}ForeArm", f"{n}{S}Arm", f"{side}_elbow", M, p[J[f"{side}_elbow"]]),
            SrcJoint(f"{n}{S}Hand", f"{n}{S}ForeArm", f"{side}_wrist", M, wrist,
                     end=np.array([0.1 if side == "left" else -0.1, 0.0, 0.0])),
        ]
    return js


def mixamo_clip(body, pos, rot, name="synthetic_mixamo", fps=30.0, scale=0.01, prefix="mixamorig:") -> BvhClip:
    """Body motion as a Mixamo-rig BVH (centimetres by default, Y-up, faces +Z)."""
    js = mixamo_joints(body, prefix)
    chans = {j.name: CMU_CHANNELS for j in js}
    chans[prefix + "Hips"] = CMU_ROOT_CHANNELS
    return _build(js, pos, rot, scale, chans, {prefix + "Hips": pos[:, J["pelvis"]]}, name, 1.0 / fps)


def relayout(clip: BvhClip, channels: Dict[str, Sequence[str]], default=None) -> BvhClip:
    """The same motion with other CHANNELS per joint (missing names keep theirs / ``default``)."""
    trans, rot = clip.local_transforms()
    chans = [tuple(channels.get(n, default or clip.channels[i])) for i, n in enumerate(clip.joint_names)]
    return BvhClip.from_local_transforms(clip.name, clip.joint_names, clip.parents, clip.offsets, chans,
                                         rot, trans, frame_time=clip.frame_time, end_sites=clip.end_sites)


def write_fixture(path, clip: BvhClip):
    """Write ``clip`` to ``path`` (``.bvh`` or ``.bvh.gz``) and return the path."""
    from blender_manikin.core.bvh import write_bvh
    write_bvh(path, clip)
    return path


# --------------------------------------------------------------------------
# LaFAN1 and 100STYLE layouts (joint names, hierarchy and channel orders as the datasets' files)
LAFAN1_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
LAFAN1_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")


def lafan1_joints(body: skeleton.Body):
    """LaFAN1's rig: every OFFSET along the parent's local +X (so the zero pose is not a T-pose);
    Hips/Spine*/Neck/Head frames +X up, +Y forward, +Z left; left arm +X along the arm, +Y back,
    +Z up (the back of the hand); right arm +X along the arm, +Y back, -Z up; legs +X down,
    +Z to the right; feet +X towards the toe, +Z to the right (as read off a LaFAN1 take)."""
    p = body.rest_positions()
    D = REST_FOOT_DIRECTION
    O_trunk = _cols(_ez, -_ey, _ex)
    O_arm_l = _cols(_ex, _ey, _ez)
    O_arm_r = _cols(-_ex, _ey, -_ez)
    O_leg = _cols(-_ez, -_ey, -_ex)
    O_foot = _cols(D, np.cross(-_ex, D), -_ex)

    def clav(side, sx, O):
        d = p[J[f"{side}_shoulder"]] - p[J[f"{side}_collar"]]
        return rotation_between(sx * _ex, d) @ O

    zero = np.zeros(3)
    js = [SrcJoint("Hips", None, "pelvis", O_trunk, p[J["pelvis"]])]
    for side, S in (("left", "Left"), ("right", "Right")):
        js += [
            SrcJoint(f"{S}UpLeg", "Hips", f"{side}_hip", O_leg, p[J[f"{side}_hip"]]),
            SrcJoint(f"{S}Leg", f"{S}UpLeg", f"{side}_knee", O_leg, p[J[f"{side}_knee"]]),
            SrcJoint(f"{S}Foot", f"{S}Leg", f"{side}_ankle", O_foot, p[J[f"{side}_ankle"]]),
            SrcJoint(f"{S}Toe", f"{S}Foot", f"{side}_foot", O_foot, p[J[f"{side}_foot"]], end=zero),
        ]
    js += [
        SrcJoint("Spine", "Hips", "spine1", O_trunk, p[J["spine1"]]),
        SrcJoint("Spine1", "Spine", "spine2", O_trunk, p[J["spine2"]]),
        SrcJoint("Spine2", "Spine1", "spine3", O_trunk, p[J["spine3"]]),
        SrcJoint("Neck", "Spine2", "neck", O_trunk, p[J["neck"]]),
        SrcJoint("Head", "Neck", "head", O_trunk, p[J["head"]], end=zero),
    ]
    for side, S, sx, O in (("left", "Left", 1.0, O_arm_l), ("right", "Right", -1.0, O_arm_r)):
        js += [
            SrcJoint(f"{S}Shoulder", "Spine2", f"{side}_collar", clav(side, sx, O), p[J[f"{side}_collar"]]),
            SrcJoint(f"{S}Arm", f"{S}Shoulder", f"{side}_shoulder", O, p[J[f"{side}_shoulder"]]),
            SrcJoint(f"{S}ForeArm", f"{S}Arm", f"{side}_elbow", O, p[J[f"{side}_elbow"]]),
            SrcJoint(f"{S}Hand", f"{S}ForeArm", f"{side}_wrist", O, p[J[f"{side}_wrist"]], end=zero),
        ]
    return js


def lafan1_clip(body, pos, rot, name="synthetic_lafan1", fps=30.0, scale=0.01) -> BvhClip:
    """Body motion as a LaFAN1-layout BVH (cm, Y-up, ZYX channels, 30 fps)."""
    js = lafan1_joints(body)
    chans = {j.name: LAFAN1_CHANNELS for j in js}
    chans["Hips"] = LAFAN1_ROOT_CHANNELS
    return _build(js, pos, rot, scale, chans, {"Hips": pos[:, J["pelvis"]]}, name, 1.0 / fps)


STYLE100_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation")
STYLE100_CHANNELS = ("Yrotation", "Xrotation", "Zrotation")


def style100_joints(body: skeleton.Body):
    """100STYLE's (Xsens MVN) rig: Hips, Chest..Chest4, Neck, Head, collars on Chest4, T-pose zero
    pose with world-aligned frames; Chest..Chest3 at the body's spine1-3, Chest4 halfway from
    spine3 to the neck, the collar joint where lerp(Collar, Shoulder; 0.4) is the body's collar."""
    p = body.rest_positions()
    M, f = M_YUP, 0.4
    js = [SrcJoint("Hips", None, "pelvis", M, p[J["pelvis"]])]
    js += [
        SrcJoint("Chest", "Hips", "spine1", M, p[J["spine1"]]),
        SrcJoint("Chest2", "Chest", "spine2", M, p[J["spine2"]]),
        SrcJoint("Chest3", "Chest2", "spine3", M, p[J["spine3"]]),
        SrcJoint("Chest4", "Chest3", "spine3", M, 0.5 * (p[J["spine3"]] + p[J["neck"]])),
        SrcJoint("Neck", "Chest4", "neck", M, p[J["neck"]]),
        SrcJoint("Head", "Neck", "head", M, p[J["head"]], end=np.array([0.0, 0.0, 0.17])),
    ]
    for side, S, sx in (("right", "Right", -1.0), ("left", "Left", 1.0)):
        collar, shoulder = p[J[f"{side}_collar"]], p[J[f"{side}_shoulder"]]
        js += [
            SrcJoint(f"{S}Collar", "Chest4", f"{side}_collar", M, (collar - f * shoulder) / (1.0 - f)),
            SrcJoint(f"{S}Shoulder", f"{S}Collar", f"{side}_shoulder", M, shoulder),
            SrcJoint(f"{S}Elbow", f"{S}Shoulder", f"{side}_elbow", M, p[J[f"{side}_elbow"]]),
            SrcJoint(f"{S}Wrist", f"{S}Elbow", f"{side}_wrist", M, p[J[f"{side}_wrist"]],
                     end=np.array([sx * 0.18, 0.0, 0.0])),
        ]
    for side, S in (("right", "Right"), ("left", "Left")):
        js += [
            SrcJoint(f"{S}Hip", "Hips", f"{side}_hip", M, p[J[f"{side}_hip"]]),
            SrcJoint(f"{S}Knee", f"{S}Hip", f"{side}_knee", M, p[J[f"{side}_knee"]]),
            SrcJoint(f"{S}Ankle", f"{S}Knee", f"{side}_ankle", M, p[J[f"{side}_ankle"]]),
            SrcJoint(f"{S}Toe", f"{S}Ankle", f"{side}_foot", M, p[J[f"{side}_foot"]],
                     end=0.07 * REST_FOOT_DIRECTION * np.array([1, 1, 0])),
        ]
    return js


def style100_clip(body, pos, rot, name="synthetic_100style", fps=60.0, scale=0.01) -> BvhClip:
    """Body motion as a 100STYLE-layout BVH (cm, Y-up, YXZ channels, 60 fps)."""
    js = style100_joints(body)
    chans = {j.name: STYLE100_CHANNELS for j in js}
    chans["Hips"] = STYLE100_ROOT_CHANNELS
    return _build(js, pos, rot, scale, chans, {"Hips": pos[:, J["pelvis"]]}, name, 1.0 / fps)
