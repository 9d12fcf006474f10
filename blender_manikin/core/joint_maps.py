"""Maps from source BVH skeletons onto the 22-joint body model.

Never imports bpy.  Input is a :class:`~blender_manikin.core.bvh.BvhClip`
(source units and axes); output is a :class:`MotionClip` in the body model's
conventions (see :mod:`blender_manikin.core.skeleton`): **metres, Blender
axes (+Z up, the body faces -Y, its left is +X), floor at z = 0**.

Axis and unit conversion
------------------------

A :class:`JointMap` names the source's up axis and the direction a performer
faces in the source's rest convention.  The rotation ``M`` (3x3, det +1)
takes source left/forward/up to Blender ``+X / -Y / +Z``; positions become
``p_blender = unit_scale * M @ p_source``.  For the built-in maps (source
+Y up, facing +Z, left +X) this is ``(x, y, z) -> (x, -z, y) * unit_scale``.

Checked on the Bandai Namco files: with the pelvis forward axis
``left x up`` (left = right hip -> left hip), walks, runs and dashes move
along that axis (+Z in the file), ``walk-back`` moves against it, and at the
first frame it is within 45 degrees of +Z in 80 % of the takes (a quarter
sample of all 3,076; ``walk-left``/``walk-right`` start already turned
towards +-X, about 11 % of the Set-2 takes face -Z).  So the files are
right-handed, +Y up, the ``_L`` joints are the performer's left (+X when
facing +Z), and the rest convention faces +Z; after conversion the
performer faces -Y as the body model does.  Units are centimetres (Hips
about 0.9 m up, Head about 1.35-1.40 m).

``unit_scale`` (metres per source unit) is the map's default or, with
``"auto"``, the candidate among m, cm, mm, inch, foot and the CMU unit
(1/0.45 inch = 0.056444 m, used by the cgspeed conversion whose Hips stand
about 17 units high) that makes the skeleton's leg (hip-knee-ankle) closest
to the body model's leg of a 1.70 m person (0.491 of stature).

Positions (table)
-----------------

Targets with no exact source joint are placed on the source skeleton:
``chain(a, b, c, d; f)`` is the point at fraction ``f`` of the arc length of
the polyline ``a-b-c-d`` (bone lengths from the clip, so it is a fixed blend
of two neighbouring joints); ``lerp(a, b; t) = (1 - t) a + t b``.
The body model spaces pelvis, spine1, spine2, spine3 and neck evenly, hence
the quarters.

==============  ===============================  =================================
body joint      Bandai Namco                     CMU (cgspeed BVH)
==============  ===============================  =================================
pelvis          Hips                             Hips
left_hip        UpperLeg_L                       LeftUpLeg
right_hip       UpperLeg_R                       RightUpLeg
spine1          chain(Hips,Spine,Chest,Neck;1/4) chain(Hips,Spine,Spine1; 1/4)
spine2          chain(...; 1/2)                  chain(...; 1/2)
spine3          chain(...; 3/4)                  chain(...; 3/4)
left_knee       LowerLeg_L                       LeftLeg
left_ankle      Foot_L                           LeftFoot
left_foot       Toes_L (ball of the foot)        LeftToeBase (ball of the foot)
neck            Neck                             Neck (= Spine1 point, neck base)
head            Head (top of the neck)           Head (top of the neck)
left_collar     Shoulder_L (clavicle root)       lerp(LeftShoulder, LeftArm; 0.4)
left_shoulder   UpperArm_L                       LeftArm
left_elbow      LowerArm_L                       LeftForeArm
left_wrist      Hand_L                           LeftHand
==============  ===============================  =================================

Right side likewise (``_R`` / ``Right...``).  Bandai's ``joint_Root`` (a
ground projection of the hips carrying the root motion of cyclic takes) is
not mapped; it moves everything through FK.  CMU's ``LeftShoulder`` joint
sits at the neck base, so the SMPL-like collar is put 0.4 of the way along
the clavicle (the body model puts its collar 0.04 H out of 0.105 H).

Mixamo (``mixamorig:`` names, a BVH written from its FBX rig, e.g. by Blender's
BVH export) has every cgspeed name, so it maps like CMU but for the spine:
spine1-3 at the quarters of ``chain(Hips, Spine, Spine1, Spine2, Neck)``, and
its ``Neck`` (on ``Spine2``, where cgspeed's is on ``Spine1``) is the neck base.
The hierarchy tells the two rigs apart (:func:`detect_joint_map`).  Names are matched exactly,
else case-insensitively without a namespace (``mixamorig:``) or a prefix ending in ``_`` that
every joint shares (``Model_Hips``, ``mixamorig_Hips``: :func:`_shared_prefix`).

LaFAN1 (Ubisoft La Forge, CC BY-NC-ND 4.0; ``lafan1``): Hips, Left/RightUpLeg, Leg, Foot,
Toe, Spine, Spine1, Spine2, Neck, Head, Left/RightShoulder, Arm, ForeArm, Hand; centimetres,
+Y up, 30 fps, ``Zrotation Yrotation Xrotation`` channels.  It has the cgspeed limb names but
``LeftToe`` (the ball of the foot) where cgspeed and Mixamo have ``LeftToeBase``, which tells
them apart.  Every OFFSET lies along the parent's local +X, so its zero pose is every chain
pointing +X, not a T-pose.  Positions as Mixamo's (spine1-3 at the quarters of
``chain(Hips, Spine, Spine1, Spine2, Neck)``) but for the collar, its ``LeftShoulder``
(clavicle root, 6 cm off the midline).  Orientations come from the joints' own axes, read off
the first frame of a LaFAN1 take quoted in a public README (a T-pose, performer facing +Z):
Hips and Head +X up, +Y forward, +Z left; LeftHand +X along the hand, +Z back of the hand
(+Y backward); RightHand +X along the hand, -Z back of the hand; feet +X towards the toe, -Z
to the performer's left.  One frame, so the hand and head axes are a convention seen once,
not a measured mean as for Bandai.

100STYLE (Mason et al. 2022, CC BY 4.0; ``100style``) is an Xsens MVN skeleton: Hips, Chest,
Chest2, Chest3, Chest4, Neck, Head, Left/RightCollar, Shoulder, Elbow, Wrist, Left/RightHip,
Knee, Ankle, Toe; centimetres, +Y up, faces +Z, 60 fps, ``Yrotation Xrotation Zrotation``;
zero pose a T-pose with world-aligned frames (so ``rest`` axes, as CMU).  spine1-3 are the
quarters of ``chain(Hips, Chest, ..., Chest4, Neck)``, the collar ``lerp(Collar, Shoulder;
0.4)`` (the Collar joint sits 3 cm off the midline), the foot its ``Toe`` (ball of the foot).

Xsens MVN's own BVH export has exactly 100STYLE's names and layout, so ``100style`` reads it
(MVN's segment names ``Pelvis``, ``L5``, ``L3``, ``T12``, ``T8`` are those of MVNX files and its
live stream, not of its BVH).

Perception Neuron (Axis Neuron / Axis Studio BVH; ``neuron``): Hips, Left/RightUpLeg, Leg, Foot
(no toe joint: the foot ends in an End Site, 8 cm below and 19.6 cm ahead of the ankle in the
default skeleton, used as ``left_foot``), Spine, Spine1..Spine3, Neck on Spine3, Head,
Left/RightShoulder, Arm, ForeArm, Hand and finger chains from ``LeftInHandIndex`` etc.;
``CHANNELS 6`` on every joint, cm, +Y up, faces +Z, zero pose a T-pose with world-aligned frames
(``rest`` axes).  On its default skeleton (hip joints 1.04 m up, so about 1.96 m tall) Spine3's
top is at 0.805 of stature, Neck at 0.862 and Head at 0.908 (ear height), so the neck base is
``lerp(Spine3, Neck; 0.4)`` and the head (top of the neck) ``lerp(Neck, Head; 0.2)``; spine1-3
are the quarters of ``chain(Hips, Spine, Spine1, Spine2, Spine3)``.

Rokoko Studio BVH (``rokoko``): Mixamo's names and hierarchy (Neck on Spine2, LeftToeBase) plus
Perception Neuron style finger roots (``LeftInHandIndex`` on ``LeftHand``), which tell it from
Mixamo (:attr:`JointMap.parents` joints must exist for detection).  Every OFFSET below the hips
lies along the parent's local +X (not a T-pose), so orientations come from local axes, read off
four frames of a real take and the finger OFFSETs: Hips and Head +X left, +Y up, +Z forward
(head forward . pelvis forward 0.91); hands +X along the hand, +Y the back of the hand (the
thumb root lies at +Z on the left hand, -Z on the right); feet +X towards LeftToeBase, -Z the
performer's left (0.77-1.0).  Its Neck joint is at 0.851 of stature and Head at 0.913 (legs:
about 1.77 m), so the neck base is ``lerp(Spine2, Neck; 0.8)`` and the head ``lerp(Neck,
Head; 0.3)``; spine1-3 as Mixamo's.  The ankle->ball line dips about 50 degrees when standing
(``foot_pitch`` measured per clip).

Any other rig: a joint-map file (JSON, :func:`load_joint_map`, README "Joint-map files").  Its
points may name a joint's End Site as ``"<joint>/End Site"`` (:data:`END_SITE`): the End Site
OFFSET's end, posed with that joint (``p[j] + R_world[j] @ end_site[j]``), for a rig whose foot
ends in an End Site with no toe joint (Perception Neuron's Axis Neuron BVH).

Orientations
------------

``MotionClip.rotations`` holds world rotations ``(T, 3, 3)`` for
``pelvis, head, left_wrist, right_wrist, left_ankle, right_ankle`` in the
body-model convention: **identity = that joint's frame in the T-pose rest**,
i.e. pelvis and head upright facing -Y; left wrist with the hand along +X,
palm down (back of the hand +Z, thumb -Y); right wrist along -X, palm down;
ankle with the foot standing flat, pointing -Y, lateral axis +X.  "Flat"
needs the source's own foot geometry: the ankle->ball line of a flat foot
dips by the *foot pitch* below the floor plane, so the identity ankle frame
maps ``foot_direction(pitch) = (0, -cos p, -sin p)`` to the ankle->ball
direction.  The pitch is a per-map constant (Bandai: 39.6 degrees, the
median over stance frames, identical in most takes because the files share
one skeleton), measured per clip (``"auto"``, CMU's default: median dip
while both the ankle and the ball are within 2 cm of their lowest), or the
body model's own 20.3 degrees (``skeleton.make_body``'s ankle->ball
offset).  A rotation maps body-local vectors (T-pose frame) to Blender world
vectors, like ``skeleton.forward_kinematics``'s world rotations.

Derivation.  Each oriented joint names two anatomical directions in the
source joint's *local* frame: a primary ``a`` (hand/bone direction, up for
pelvis and head, ankle-to-ball for the foot) and a secondary ``b`` (back of
the hand, face forward, body left, foot lateral), and the same directions
``A, B`` in the body's T-pose frame.  Gram-Schmidt gives orthonormal frames
``F_src = [a, b', a x b']`` and ``F_body = [A, B', A x B']``; then

    R_body(t) = M @ R_src(t) @ F_src @ F_body^T

(``M`` the axis conversion).  When the source joint points its ``a`` and
``b`` where the T-pose would, ``R_body = I``.  Source directions come from
the clip itself where the skeleton determines them, else from the rig's
axis convention:

* ``bone(j, k)``: the rest-pose (zero-channel) direction from joint ``j``
  to joint ``k``.  Exact in the local frame of ``j`` when ``k`` is a child
  of ``j`` (pelvis up = Hips->Spine, pelvis left = right hip -> left hip,
  ankle primary = ankle -> toes).
* ``rest``: the T-pose direction itself (``M^T A``).  Valid when the
  source's zero pose is a T-pose facing the map's forward axis with
  world-aligned joint frames, as in the CMU skeleton (its reference pose
  has arms along +-X with palms down: the thumb End Site points +Z, i.e.
  forward; legs splay 20 degrees outward, which does not affect the
  oriented joints' frames).
* ``local(v)``: a fixed axis of the rig's joint frame.

The Bandai zero pose is *not* a T-pose: every bone lies along its parent's
local +-X axis (the spine, the left leg and the left arm all point +X, the
right leg and arm -X), joint frames differ by arbitrary 90/180 degree turns
and the rotation channels carry them.  Its axis conventions were read off the
data (223 takes; means of world directions expressed in the joint frame):
Hips: +X up (Spine child), -Y left (leg children), +Z forward.  Head: +X up
along the neck, +Y face forward (mean 0.86 while walking), so +Z is left.
Hand_L: +X along the hand (mean forearm direction 0.91), -Y palm (faces the
thigh with the arm hanging, faces forward when waving: 0.8-0.98), +Z thumb
side (forward when hanging).  Hand_R: -X along the hand, +Y palm, -Z thumb.
Foot_L/Foot_R: +-X towards Toes, +Y to the performer's left (0.95).
The Bandai ``Head`` joint sits at the top of the neck about 0.8 of stature
high; with ``+X`` up the neutral head is pitched forward by the neck's lean.

Floor
-----

``floor="auto"`` estimates the floor from the ankle and ball-of-foot
joints: for every frame the lowest of ``z_j(t) - rest_z_j`` over those four
joints, where ``rest_z_j`` is the joint's height in the clip's own rest body
(ball of the foot at 0.012 of stature as in ``make_body``, ankle above it
along the flat foot), and the floor is the 5th percentile of that over the
clip (robust to jumps, a few bad frames and the swing foot).  On the Bandai
files this puts the floor 1.4-2.8 cm above the files' own ground (their
ball joints rest 4 cm up), so the balls rest at 1.8 cm and the ankles at
9.3 cm.  A number instead gives the floor height in
metres in the converted axes (``0.0`` keeps the source's own ground).

Body
----

``MotionClip.body`` is a :class:`~blender_manikin.core.skeleton.Body` with
the clip's own bone lengths (mean over frames of the mapped joint
distances) laid out in the standard rest directions: spine, neck and head
straight up, arms along +-X, legs along -Z, the foot flat along
``foot_direction(pitch)``; the hip offsets (in the pelvis frame), collar
offsets (in a chest frame built from spine3->neck and the collar line) and
shoulder directions are the clip's mean vectors, mirrored and averaged so the
body is left-right symmetric.  The pelvis height puts the rest balls of the
feet at 0.012 of stature with stature = head height / 0.870, the rules of
``skeleton.make_body`` and ``Body.from_offsets``.  For a body made by
``make_body`` and posed by FK this reproduces its offsets exactly.  (The
Bandai ``Head`` joint is at the top of the neck, as the body model's head
joint now is; measured with the body model's old skull-base head, 0.910 of
stature, the head-based stature of the Bandai skeleton came out 1.53 m, low
for legs that suggest about 1.63 m.)
"""
from __future__ import annotations

import json
import os
import re
import warnings
from dataclasses import dataclass, replace
from typing import Dict, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import skeleton
from .bvh import BvhClip
from .plain import shown
from .rotations import normalize

__all__ = [
    "Point", "joint", "lerp", "chain", "Axis", "local", "bone", "rest", "OrientationSpec",
    "JointMap", "BANDAI", "CMU", "MIXAMO", "LAFAN1", "STYLE100", "JOINT_MAPS", "load_joint_map",
    "ORIENTED_JOINTS", "MotionClip", "END_SITE", "point_names", "NEURON", "ROKOKO",
    "detect_joint_map", "get_joint_map", "axis_conversion", "detect_unit_scale",
    "estimate_floor", "clip_to_body_motion", "take_id_from_name", "rest_pose_report",
    "UNIT_CANDIDATES", "REST_FOOT_DIRECTION", "REST_FOOT_PITCH", "BANDAI_FOOT_PITCH",
    "foot_direction", "estimate_foot_pitch", "orientation_corrections",
]

JN = skeleton.JOINT_NAMES
NJ = skeleton.NUM_JOINTS
_J = skeleton.J

#: Joints whose orientation MotionClip carries (body-model names).
#: Suffix that names a joint's End Site as a source point in a map: ``"LeftFoot/End Site"`` is
#: the end of ``LeftFoot``'s End Site OFFSET, for a rig whose foot or head ends in an End Site
#: with no toe or head-top joint (Perception Neuron's Axis Neuron BVH, older Biovision rigs).
END_SITE = "/End Site"

ORIENTED_JOINTS = ("pelvis", "head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")

_P = skeleton.PROPORTIONS
#: Rest direction ankle -> ball of the foot in the body model (unit, Blender axes).
REST_FOOT_DIRECTION = normalize(np.array(
    [0.0, -_P["foot_forward"], _P["foot_height"] - _P["ankle_height"]]))
#: Its dip below the floor plane, degrees (20.3).
REST_FOOT_PITCH = float(np.degrees(np.arcsin(-REST_FOOT_DIRECTION[2])))
#: Ankle->ball dip of a flat-standing foot in the Bandai Namco files, degrees
#: (median over stance frames per take: median 39.6, 10th-90th percentile
#: 39.6-40.8, range 34-47 over 75 takes checked).
BANDAI_FOOT_PITCH = 39.6


def foot_direction(pitch_deg: float) -> np.ndarray:
    """Unit ankle->ball direction of a flat foot pointing -Y that dips ``pitch_deg``."""
    t = np.radians(float(pitch_deg))
    return np.array([0.0, -np.cos(t), -np.sin(t)])

#: Metres per unit for ``unit_scale="auto"``.
UNIT_CANDIDATES = {
    "m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "foot": 0.3048,
    "cmu": 0.0254 / 0.45,
}
_TYPICAL_LEG = (_P["thigh"] + _P["shank"]) * 1.70   # metres, hip-knee-ankle


# --------------------------------------------------------------------------
# specification objects
@dataclass(frozen=True)
class Point:
    """Where a body joint sits on the source skeleton (see module table)."""
    kind: str                       # "joint" | "lerp" | "chain"
    joints: Tuple[str, ...]
    t: float = 0.0

    def describe(self) -> str:
        if self.kind == "joint":
            return self.joints[0]
        if self.kind == "lerp":
            return f"lerp({self.joints[0]}, {self.joints[1]}; {self.t:g})"
        return f"chain({', '.join(self.joints)}; {self.t:g})"


def joint(name: str) -> Point:
    return Point("joint", (name,))


def lerp(a: str, b: str, t: float) -> Point:
    return Point("lerp", (a, b), float(t))


def chain(names: Sequence[str], fraction: float) -> Point:
    return Point("chain", tuple(names), float(fraction))


@dataclass(frozen=True)
class Axis:
    """An anatomical direction in a source joint's local frame."""
    kind: str                            # "local" | "bone" | "rest"
    vector: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    joints: Tuple[str, ...] = ()


def local(x, y, z) -> Axis:
    return Axis("local", (float(x), float(y), float(z)))


def bone(a: str, b: str) -> Axis:
    return Axis("bone", joints=(a, b))


def rest() -> Axis:
    return Axis("rest")


@dataclass(frozen=True)
class OrientationSpec:
    """Source joint and its primary/secondary anatomical axes (see module docstring)."""
    source: str
    primary: Axis
    secondary: Axis


# body-frame anatomical directions (T-pose, Blender axes) per oriented joint
_BODY_AXES = {
    "pelvis": ((0, 0, 1), (1, 0, 0)),                 # up, left
    "head": ((0, 0, 1), (0, -1, 0)),                  # up, face forward
    "left_wrist": ((1, 0, 0), (0, 0, 1)),             # along the hand, back of the hand
    "right_wrist": ((-1, 0, 0), (0, 0, 1)),
    "left_ankle": (None, (1, 0, 0)),       # ankle->ball (foot_direction), lateral (+X)
    "right_ankle": (None, (1, 0, 0)),
}

_AXES = {"x": 0, "y": 1, "z": 2}


def _axis_vec(s: str) -> np.ndarray:
    s = s.strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    v = np.zeros(3)
    v[_AXES[s.lstrip("+-")]] = sign
    return v


def axis_conversion(up: str = "y", forward: str = "z") -> np.ndarray:
    """Rotation ``M`` (3x3) from source axes to Blender axes.

    ``up`` and ``forward`` are the source's up axis and the direction its
    performer faces (``"y"``, ``"-z"``, ...).  ``M`` sends ``left = up x
    forward`` to +X, ``forward`` to -Y and ``up`` to +Z.  ``axis_conversion("y",
    "z")`` is ``(x, y, z) -> (x, -z, y)``.
    """
    u, f = _axis_vec(up), _axis_vec(forward)
    if abs(np.dot(u, f)) > 0.5:
        raise ValueError(f"up {up!r} and forward {forward!r} must be different axes")
    left = np.cross(u, f)
    src = np.stack([left, f, u], axis=1)                 # columns: source left, fwd, up
    dst = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]]).T
    return dst @ src.T


@dataclass(frozen=True)
class JointMap:
    """How a source skeleton maps onto the 22 body joints.

    ``positions``: one :class:`Point` per body joint name (the floor uses
    the ankles and feet, unit detection the hips, knees and ankles).
    ``orientations``: one :class:`OrientationSpec` per name in
    :data:`ORIENTED_JOINTS`.  ``unit_scale``: metres per source unit or
    ``"auto"``.  ``up`` / ``forward``: source axes (see
    :func:`axis_conversion`).  ``rest_is_tpose``: whether the zero-channel
    pose is a T-pose with world-aligned frames (required by ``rest()`` axes).
    ``foot_pitch``: degrees the ankle->ball line dips below the floor plane
    when the foot stands flat, ``"auto"`` (measure it on each clip) or
    ``None`` (the body model's 20.3 degrees).  ``parents``: ``(child, parent)`` source joints
    the rig must have so, which tells it from another rig with the same joint names (detection).
    """
    name: str
    positions: Mapping[str, Point]
    orientations: Mapping[str, OrientationSpec]
    unit_scale: Union[float, str] = "auto"
    up: str = "y"
    forward: str = "z"
    rest_is_tpose: bool = False
    foot_pitch: Union[float, str, None] = "auto"
    description: str = ""
    parents: Tuple[Tuple[str, str], ...] = ()

    def source_joints(self) -> Tuple[str, ...]:
        names = []
        for p in self.positions.values():
            names.extend(p.joints)
        for o in self.orientations.values():
            names.append(o.source)
            for ax in (o.primary, o.secondary):
                names.extend(ax.joints)
        return tuple(dict.fromkeys(names))

    def missing(self, joint_names: Sequence[str]) -> Tuple[str, ...]:
        res = _Resolver(joint_names)
        return tuple(n for n in self.source_joints() if res.find(n) is None)

    def wrong_parents(self, joint_names: Sequence[str], parents: Sequence[int]) -> Tuple[str, ...]:
        """How the hierarchy differs from :attr:`parents` (empty when it fits)."""
        res, out = _Resolver(joint_names), []
        for child, parent in self.parents:
            c, p = res.find(child), res.find(parent)
            if c is not None and p is not None and int(parents[c]) != p:
                actual = joint_names[int(parents[c])] if int(parents[c]) >= 0 else "nothing"
                out.append(f"{joint_names[c]!r} is a child of {actual!r}, not of {parent!r}")
        return tuple(out)

    def table(self) -> str:
        """The position map as text (one ``body: source`` line per joint)."""
        return "\n".join(f"{n:15s} {self.positions[n].describe()}" for n in JN)


def _body_positions(spine, name, collar_t=None) -> dict:
    """The 22 joints' positions of a rig whose trunk is ``Hips`` .. ``spine`` .. ``Neck``,
    ``Head`` (spine1-3 the quarters of the arc ``spine``, Hips to the neck base) and whose limb
    joints are ``name(side, part)`` (side ``"left"`` / ``"right"``; part ``hip``, ``knee``,
    ``ankle``, ``toe`` (the ball of the foot), ``collar``, ``shoulder``, ``elbow``, ``wrist``);
    ``collar_t``: the collar ``collar_t`` of the way from the collar joint to the shoulder (None:
    the collar joint itself)."""
    pos = {
        "pelvis": joint("Hips"),
        "spine1": chain(spine, 0.25), "spine2": chain(spine, 0.5), "spine3": chain(spine, 0.75),
        "neck": joint("Neck"), "head": joint("Head"),
    }
    for side in ("left", "right"):
        pos[f"{side}_hip"] = joint(name(side, "hip"))
        pos[f"{side}_knee"] = joint(name(side, "knee"))
        pos[f"{side}_ankle"] = joint(name(side, "ankle"))
        pos[f"{side}_foot"] = joint(name(side, "toe"))
        pos[f"{side}_collar"] = (joint(name(side, "collar")) if collar_t is None
                                 else lerp(name(side, "collar"), name(side, "shoulder"), collar_t))
        pos[f"{side}_shoulder"] = joint(name(side, "shoulder"))
        pos[f"{side}_elbow"] = joint(name(side, "elbow"))
        pos[f"{side}_wrist"] = joint(name(side, "wrist"))
    return pos


def _bandai() -> JointMap:
    parts = {"hip": "UpperLeg", "knee": "LowerLeg", "ankle": "Foot", "toe": "Toes", "collar": "Shoulder",
             "shoulder": "UpperArm", "elbow": "LowerArm", "wrist": "Hand"}
    pos = _body_positions(("Hips", "Spine", "Chest", "Neck"), lambda side, part: f"{parts[part]}_{side[0].upper()}")
    ori = {
        "pelvis": OrientationSpec("Hips", bone("Hips", "Spine"), bone("UpperLeg_R", "UpperLeg_L")),
        "head": OrientationSpec("Head", local(1, 0, 0), local(0, 1, 0)),
        "left_wrist": OrientationSpec("Hand_L", local(1, 0, 0), local(0, 1, 0)),
        "right_wrist": OrientationSpec("Hand_R", local(-1, 0, 0), local(0, -1, 0)),
        "left_ankle": OrientationSpec("Foot_L", bone("Foot_L", "Toes_L"), local(0, 1, 0)),
        "right_ankle": OrientationSpec("Foot_R", bone("Foot_R", "Toes_R"), local(0, 1, 0)),
    }
    return JointMap("bandai", pos, ori, unit_scale=0.01, up="y", forward="z", rest_is_tpose=False,
                    foot_pitch=BANDAI_FOOT_PITCH,
                    description="Bandai Namco Research Motiondataset 1/2 (cm, Y-up, faces +Z)")


#: the cgspeed BVH names' limb joints (``LeftUpLeg``, ``LeftArm``, ...), as :func:`_tpose_style` takes them
_CGSPEED_LIMBS = {"hip": "UpLeg", "knee": "Leg", "ankle": "Foot", "toe": "ToeBase", "collar": "Shoulder",
                  "shoulder": "Arm", "elbow": "ForeArm", "wrist": "Hand"}


def _tpose_style(name, spine, limbs, unit_scale, parents, description) -> JointMap:
    """A map for a rig whose zero pose is a T-pose with world-aligned frames, Y-up, facing +Z,
    and whose joints are ``Hips``, ``Neck``, ``Head`` and ``Left``/``Right`` + a limb name
    (``limbs``: part -> name: ``hip``, ``knee``, ``ankle``, ``toe`` (the ball of the foot),
    ``collar``, ``shoulder``, ``elbow``, ``wrist``); ``spine``: the joints from Hips to the neck
    base whose arc spine1-3 split in quarters; ``parents``: the hierarchy checks that tell it from
    other rigs with the same names."""
    pos = _body_positions(spine, lambda side, part: f"{side.capitalize()}{limbs[part]}", 0.4)
    ori = {"pelvis": OrientationSpec("Hips", rest(), rest()), "head": OrientationSpec("Head", rest(), rest())}
    for side, S in (("left", "Left"), ("right", "Right")):
        ori[f"{side}_wrist"] = OrientationSpec(f"{S}{limbs['wrist']}", rest(), rest())
    for side, S in (("left", "Left"), ("right", "Right")):
        ankle, toe = f"{S}{limbs['ankle']}", f"{S}{limbs['toe']}"
        ori[f"{side}_ankle"] = OrientationSpec(ankle, bone(ankle, toe), rest())
    return JointMap(name, pos, ori, unit_scale=unit_scale, up="y", forward="z", rest_is_tpose=True,
                    foot_pitch="auto", parents=parents, description=description)


def _neuron() -> JointMap:
    """Perception Neuron (Axis Neuron / Axis Studio BVH): the cgspeed limb names but no toe joint
    (the foot ends in an End Site at the ball of the foot, :data:`END_SITE`), Spine..Spine3 with
    ``Neck`` on ``Spine3`` (some versions add ``Neck1`` between Neck and Head), ``LeftInHandIndex``
    etc. finger roots, ``CHANNELS 6`` on every joint; cm, Y-up, faces +Z, the zero pose a T-pose
    with world-aligned frames (arms along +-X, legs along -Y)."""
    limbs = dict(_CGSPEED_LIMBS, toe="Foot" + END_SITE)
    jm = _tpose_style("neuron", ("Hips", "Spine", "Spine1", "Spine2", "Spine3"), limbs, "auto",
                      (("Neck", "Spine3"),),
                      "Perception Neuron / Axis Neuron BVH (cm, Y-up, faces +Z, T-pose rest, toes as End Sites)")
    # its Head joint sits at ear height (0.91 of stature), its Neck joint near the top of the neck
    pos = dict(jm.positions, neck=lerp("Spine3", "Neck", 0.4), head=lerp("Neck", "Head", 0.2))
    return replace(jm, positions=pos)


def _rokoko() -> JointMap:
    """Rokoko Studio BVH: Mixamo's names and hierarchy (``Neck`` on ``Spine2``) plus Perception
    Neuron style finger roots (``LeftInHandIndex`` on ``LeftHand``, which tells it from Mixamo);
    cm, Y-up, faces +Z.  Every OFFSET below the hips lies along the parent's local +X, so the zero
    pose is not a T-pose; the joints' axes (read off frames of a Rokoko take and the finger
    OFFSETs): Hips and Head +X left, +Y up, +Z forward; LeftHand/RightHand +X along the hand, +Y
    back of the hand (the thumb root lies towards +Z on the left hand, -Z on the right);
    LeftFoot/RightFoot +X towards the toe, -Z to the performer's left."""
    pos = _body_positions(("Hips", "Spine", "Spine1", "Spine2", "Neck"),
                          lambda side, part: f"{side.capitalize()}{_CGSPEED_LIMBS[part]}")
    # its Head joint sits at ear height (0.91 of stature), its Neck joint 0.85 of stature up
    pos.update(neck=lerp("Spine2", "Neck", 0.8), head=lerp("Neck", "Head", 0.3))
    ori = {
        "pelvis": OrientationSpec("Hips", bone("Hips", "Spine"), bone("RightUpLeg", "LeftUpLeg")),
        "head": OrientationSpec("Head", local(0, 1, 0), local(0, 0, 1)),
        "left_wrist": OrientationSpec("LeftHand", local(1, 0, 0), local(0, 1, 0)),
        "right_wrist": OrientationSpec("RightHand", local(1, 0, 0), local(0, 1, 0)),
        "left_ankle": OrientationSpec("LeftFoot", bone("LeftFoot", "LeftToeBase"), local(0, 0, -1)),
        "right_ankle": OrientationSpec("RightFoot", bone("RightFoot", "RightToeBase"), local(0, 0, -1)),
    }
    return JointMap("rokoko", pos, ori, unit_scale="auto", up="y", forward="z", rest_is_tpose=False,
                    foot_pitch="auto", parents=(("Neck", "Spine2"), ("LeftInHandIndex", "LeftHand")),
                    description="Rokoko Studio BVH (cm, Y-up, faces +Z, bones along local +X)")


def _cgspeed_style(name, spine, neck_parent, description) -> JointMap:
    """A map for the rigs with the cgspeed BVH names (``LeftUpLeg``, ``LeftArm``, ...; T-pose rest
    with world-aligned frames): CMU's and Mixamo's, which differ in their spine (``spine``: the
    joints from Hips to the neck base whose arc spine1-3 split in quarters) and in the joint the
    ``Neck`` sits on (``neck_parent``, what tells the two apart)."""
    return _tpose_style(name, spine, _CGSPEED_LIMBS, "auto", (("Neck", neck_parent),), description)


def _cmu() -> JointMap:
    return _cgspeed_style("cmu", ("Hips", "Spine", "Spine1"), "Spine1",
                          "CMU mocap, cgspeed BVH conversion (1/0.45 inch units, Y-up, faces +Z)")


def _mixamo() -> JointMap:
    """Mixamo's skeleton (``mixamorig:`` names), as a BVH written from its FBX rig (Blender's BVH
    export: zero channels are the rig's T-pose with world-aligned frames).  Its three spine joints
    are spaced over Hips-Neck like the body's (quarters of the arc); its ``Neck`` sits on
    ``Spine2`` (the cgspeed rig's on ``Spine1``), which tells the two apart, since Mixamo has
    every cgspeed name."""
    return _cgspeed_style("mixamo", ("Hips", "Spine", "Spine1", "Spine2", "Neck"), "Spine2",
                          "Mixamo rig as BVH (mixamorig: names, T-pose rest, Y-up, faces +Z, units detected)")


def _lafan1() -> JointMap:
    """Ubisoft La Forge LaFAN1 (cm, Y-up, 30 fps; see the module docstring).  Every OFFSET lies
    along the parent's local +X, so the zero pose is every chain pointing +X, not a T-pose;
    orientations come from the joints' own axes, read off the first frame of a LaFAN1 take
    (a T-pose): Hips/Head +X up, +Y forward, +Z left; LeftHand +X along the hand, +Z back of
    the hand; RightHand +X along the hand, -Z back of the hand; LeftFoot/RightFoot +X towards
    the toe, -Z to the performer's left."""
    parts = dict(_CGSPEED_LIMBS, toe="Toe")
    pos = _body_positions(("Hips", "Spine", "Spine1", "Spine2", "Neck"),
                          lambda side, part: f"{side.capitalize()}{parts[part]}")
    ori = {
        "pelvis": OrientationSpec("Hips", local(1, 0, 0), bone("RightUpLeg", "LeftUpLeg")),
        "head": OrientationSpec("Head", local(1, 0, 0), local(0, 1, 0)),
        "left_wrist": OrientationSpec("LeftHand", local(1, 0, 0), local(0, 0, 1)),
        "right_wrist": OrientationSpec("RightHand", local(1, 0, 0), local(0, 0, -1)),
        "left_ankle": OrientationSpec("LeftFoot", bone("LeftFoot", "LeftToe"), local(0, 0, -1)),
        "right_ankle": OrientationSpec("RightFoot", bone("RightFoot", "RightToe"), local(0, 0, -1)),
    }
    return JointMap("lafan1", pos, ori, unit_scale=0.01, up="y", forward="z", rest_is_tpose=False,
                    foot_pitch="auto", parents=(("LeftToe", "LeftFoot"), ("Neck", "Spine2")),
                    description="Ubisoft La Forge LaFAN1 (cm, Y-up, faces +Z, bones along local +X)")


def _style100() -> JointMap:
    """100STYLE (Mason et al. 2022), an Xsens MVN skeleton: Hips, Chest..Chest4, Neck, Head,
    Left/RightCollar, Shoulder, Elbow, Wrist, Left/RightHip, Knee, Ankle, Toe; cm, Y-up, faces +Z,
    the zero pose a T-pose with world-aligned frames (arms along +-X, the Toe joint the ball of
    the foot 7 cm below and 16 cm ahead of the ankle)."""
    limbs = {"hip": "Hip", "knee": "Knee", "ankle": "Ankle", "toe": "Toe", "collar": "Collar",
             "shoulder": "Shoulder", "elbow": "Elbow", "wrist": "Wrist"}
    return _tpose_style("100style", ("Hips", "Chest", "Chest2", "Chest3", "Chest4", "Neck"), limbs, 0.01,
                        (("Neck", "Chest4"),), "100STYLE / Xsens MVN BVH (cm, Y-up, faces +Z, T-pose rest)")


BANDAI = _bandai()
CMU = _cmu()
MIXAMO = _mixamo()
LAFAN1 = _lafan1()
STYLE100 = _style100()
NEURON = _neuron()
ROKOKO = _rokoko()
JOINT_MAPS: Dict[str, JointMap] = {"bandai": BANDAI, "cmu": CMU, "mixamo": MIXAMO, "lafan1": LAFAN1,
                                   "100style": STYLE100, "neuron": NEURON, "rokoko": ROKOKO}


# --------------------------------------------------------------------------
# name resolution and detection
def _norm_name(n: str) -> str:
    n = n.split(":")[-1].split("|")[-1]
    return n.strip().lower()


def _shared_prefix(names: Sequence[str]) -> str:
    """The prefix up to an ``_`` that every name starts with (``Model_`` of ``Model_Hips``,
    ``Model_Spine``, ...; ``mixamorig_`` where a tool turned Mixamo's ``mixamorig:`` into an
    underscore), or ``""``."""
    if len(names) < 2:
        return ""
    pre = os.path.commonprefix(list(names))
    return pre[: pre.rfind("_") + 1]


class _Resolver:
    """Find source joints by exact name, else case-insensitively without a namespace (``ns:``,
    ``a|b``) or without a prefix every joint name shares (:func:`_shared_prefix`)."""

    def __init__(self, names: Sequence[str]):
        self.exact = {n: i for i, n in enumerate(names)}
        self.loose = {}
        for i, n in enumerate(names):
            self.loose.setdefault(_norm_name(n), i)
        pre = _shared_prefix(names)
        for i, n in enumerate(names):
            if pre and len(n) > len(pre):
                self.loose.setdefault(_norm_name(n[len(pre):]), i)

    def find(self, name: str) -> Optional[int]:
        i = self.exact.get(name)
        return i if i is not None else self.loose.get(_norm_name(name))

    def __call__(self, name: str, clip_name: str = "") -> int:
        i = self.find(name)
        if i is None:
            raise KeyError(f"{clip_name}: source joint {name!r} not found")
        return i




def point_names(clip: BvhClip) -> Tuple[str, ...]:
    """The clip's joint names, then ``<joint>/End Site`` for each joint with an End Site
    (:meth:`BvhClip.end_site_joints` order): the names a map's points may use."""
    return tuple(clip.joint_names) + tuple(clip.joint_names[j] + END_SITE for j in clip.end_site_joints())


def detect_joint_map(joint_names: Sequence[str], parents: Optional[Sequence[int]] = None) -> JointMap:
    """The registered map whose source joints are all present (best coverage wins) and, when
    ``parents`` is given, whose :attr:`JointMap.parents` the hierarchy has (a Mixamo rig has the
    cgspeed names, but its ``Neck`` sits on ``Spine2``, two joints above the cgspeed neck base).
    The joints :attr:`JointMap.parents` names must be there too (Rokoko's ``LeftInHandIndex``
    tells it from Mixamo, whose names it has).

    ``joint_names``: a clip's joints, optionally followed by ``<joint>/End Site`` names
    (:func:`point_names`; ``parents`` then covers only the joints), which a rig whose foot ends in
    an End Site needs (Perception Neuron).  Raises ``ValueError`` listing what each map misses
    when none fits.
    """
    best, best_need, report = None, 0, []
    res = _Resolver(joint_names)
    for jm in JOINT_MAPS.values():
        need = jm.source_joints() + tuple(dict.fromkeys(n for pair in jm.parents for n in pair))
        need = tuple(dict.fromkeys(need))
        miss = tuple(n for n in need if res.find(n) is None)
        wrong = jm.wrong_parents(joint_names, parents) if parents is not None and not miss else ()
        report.append(f"{jm.name}: " + (f"another rig with its joint names ({'; '.join(wrong)})" if wrong
                                        else f"missing {', '.join(miss) if miss else 'nothing'}"))
        if not miss and not wrong and (best is None or len(need) > best_need):
            best, best_need = jm, len(need)
    if best is None:
        raise ValueError("no joint map fits this skeleton (" + "; ".join(report) + "); write a joint-map "
                         ".json for it (README 'Joint-map files'; a foot or head that ends in an End Site "
                         f"is named like 'LeftFoot{END_SITE}') and give it as the joint map")
    return best


def get_joint_map(joint_map: Union[None, str, JointMap], clip: Optional[BvhClip] = None) -> JointMap:
    if isinstance(joint_map, JointMap):
        return joint_map
    if joint_map is None or joint_map == "auto":
        if clip is None:
            raise ValueError("auto-detecting a joint map needs a clip")
        return detect_joint_map(point_names(clip), clip.parents)
    if str(joint_map).lower().endswith(".json"):
        return load_joint_map(joint_map)
    try:
        return JOINT_MAPS[str(joint_map).lower()]
    except KeyError:
        raise ValueError(f"unknown joint map {joint_map!r}; known: {', '.join(JOINT_MAPS)} "
                         "or a joint-map .json file") from None


# --------------------------------------------------------------------------
# joint-map files
_FILE_KEYS = {"name", "positions", "orientations", "units", "up", "forward", "rest_is_tpose",
              "foot_pitch", "parents", "description"}


def _file_point(v, where):
    """A :class:`Point` from a file's position entry: ``"Joint"``, ``{"lerp": [a, b], "t": t}``
    or ``{"chain": [a, b, ...], "at": f}``."""
    if isinstance(v, str) and v.strip():
        return joint(v.strip())
    if isinstance(v, dict):
        names = v.get("lerp", v.get("chain"))
        kind = "lerp" if "lerp" in v else "chain" if "chain" in v else None
        key = "t" if kind == "lerp" else "at"
        extra = sorted(set(v) - {kind, key})
        ok_names = (isinstance(names, list) and all(isinstance(n, str) and n.strip() for n in names)
                    and (len(names) == 2 if kind == "lerp" else len(names) >= 2))
        f = v.get(key)
        ok_f = isinstance(f, (int, float)) and not isinstance(f, bool) and 0.0 <= f <= 1.0
        if kind and ok_names and ok_f and not extra:
            return lerp(names[0], names[1], f) if kind == "lerp" else chain(names, f)
    raise ValueError(f"{where}: bad position {shown(v)} (expected a joint name, "
                     '{"lerp": ["A", "B"], "t": 0..1} or {"chain": ["A", "B", ...], "at": 0..1})')


def _file_axis(v, where):
    """An :class:`Axis` from ``"rest"``, a local axis (``"+x"``, ``"-z"``, ``[x, y, z]``) or
    ``{"bone": ["A", "B"]}``."""
    if v == "rest":
        return rest()
    if isinstance(v, str) and re.fullmatch(r"[+-]?[xyzXYZ]", v.strip()):
        return local(*_axis_vec(v))
    if (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                    for x in v) and any(x != 0 for x in v)):
        return local(*v)
    if (isinstance(v, dict) and set(v) == {"bone"} and isinstance(v["bone"], list) and len(v["bone"]) == 2
            and all(isinstance(n, str) and n.strip() for n in v["bone"])):
        return bone(*v["bone"])
    raise ValueError(f"{where}: bad axis {shown(v)} (expected \"rest\", a local axis such as \"+x\" "
                     'or [1, 0, 0], or {"bone": ["A", "B"]})')


def _default_orientation(name, pos, where):
    """Default for an oriented joint a file leaves out: the T-pose rest axes (``rest``) on the
    joint its position names; the ankles' primary axis is the bone ankle -> ball of the foot."""
    p = pos[name]
    if p.kind != "joint":
        raise ValueError(f"{where}: orientations.{name} is needed, since positions.{name} is "
                         f"{p.describe()}, not a single joint")
    if name.endswith("_ankle"):
        f = pos[name.replace("_ankle", "_foot")]
        if f.kind != "joint":
            raise ValueError(f"{where}: orientations.{name} is needed, since positions."
                             f"{name.replace('_ankle', '_foot')} is not a single joint")
        return OrientationSpec(p.joints[0], bone(p.joints[0], f.joints[0]), rest())
    return OrientationSpec(p.joints[0], rest(), rest())


def load_joint_map(path) -> JointMap:
    """Read a joint-map file (JSON, see README "Joint-map files") into a :class:`JointMap`.

    Required: ``positions`` with a source point for each of the 22 body joints
    (``skeleton.JOINT_NAMES``).  Optional: ``name`` (default: the file stem), ``units``
    (metres per source unit, a name in :data:`UNIT_CANDIDATES` or ``"auto"``; default
    ``"auto"``), ``up`` / ``forward`` (source axes, default ``"y"`` / ``"z"``),
    ``rest_is_tpose`` (default ``true``), ``foot_pitch`` (degrees, ``"auto"`` (default) or
    ``null``), ``orientations`` (per joint of :data:`ORIENTED_JOINTS`: ``{"joint": J,
    "primary": AXIS, "secondary": AXIS}``; a joint left out takes its position's joint with the
    T-pose rest axes, the ankles the bone ankle -> ball of the foot, which needs
    ``rest_is_tpose``), ``parents`` (``[[child, parent], ...]`` for detection) and
    ``description``.  Errors name the file, the line of the key at fault
    (:func:`.recording.json_key_line`) and the problem.
    """
    from .recording import json_key_line, read_text
    where = os.fspath(path)
    try:
        text = read_text(path)
    except OSError as exc:
        raise ValueError(f"{where}: cannot read the joint-map file ({exc.strerror or exc})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a JSON object with \"positions\"")

    def at(*key):
        """``where`` with the line of ``key`` (a key path) in the file, where it is written."""
        line = json_key_line(text, key)
        return where if line is None else f"{where}, line {line}"
    unknown = sorted(set(data) - _FILE_KEYS)
    if unknown:
        raise ValueError(f"{at(unknown[0])}: unknown field(s) {', '.join(unknown)} (expected "
                         f"{', '.join(sorted(_FILE_KEYS))})")
    positions = data.get("positions")
    if not isinstance(positions, dict):
        raise ValueError(f"{at('positions')}: \"positions\" must be an object naming a source joint for each body "
                         f"joint ({', '.join(JN)})")
    bad = sorted(set(positions) - set(JN))
    if bad:
        raise ValueError(f"{at('positions', bad[0])}: positions: unknown body joint(s) {', '.join(bad)} "
                         f"(body joints: {', '.join(JN)})")
    missing = [n for n in JN if n not in positions]
    if missing:
        raise ValueError(f"{at('positions')}: positions: missing body joint(s) {', '.join(missing)}")
    pos = {n: _file_point(positions[n], f"{at('positions', n)}: positions.{n}") for n in JN}

    units = data.get("units", "auto")
    if isinstance(units, bool) or not (
            (isinstance(units, (int, float)) and np.isfinite(units) and units > 0)
            or units == "auto" or units in UNIT_CANDIDATES):
        raise ValueError(f"{at('units')}: units must be metres per unit (a positive number), \"auto\" or one of "
                         f"{', '.join(UNIT_CANDIDATES)}; got {shown(units)}")
    if isinstance(units, str) and units != "auto":
        units = UNIT_CANDIDATES[units]
    up, fwd = data.get("up", "y"), data.get("forward", "z")
    for k, v in (("up", up), ("forward", fwd)):
        if not (isinstance(v, str) and re.fullmatch(r"[+-]?[xyzXYZ]", v.strip())):
            raise ValueError(f"{at(k)}: {k} must be an axis such as \"y\" or \"-z\"; got {shown(v)}")
    try:
        axis_conversion(up, fwd)
    except ValueError as exc:
        raise ValueError(f"{at('forward')}: {exc}") from None
    tpose = data.get("rest_is_tpose", True)
    if not isinstance(tpose, bool):
        raise ValueError(f"{at('rest_is_tpose')}: rest_is_tpose must be true or false; got {shown(tpose)}")
    fp = data.get("foot_pitch", "auto")
    if not (fp is None or fp == "auto" or (isinstance(fp, (int, float)) and not isinstance(fp, bool)
                                            and 0.0 <= fp <= 70.0)):
        raise ValueError(f"{at('foot_pitch')}: foot_pitch must be degrees (0-70), \"auto\" or null; got {shown(fp)}")

    oris_in = data.get("orientations", {})
    if not isinstance(oris_in, dict):
        raise ValueError(f"{at('orientations')}: \"orientations\" must be an object")
    bad = sorted(set(oris_in) - set(ORIENTED_JOINTS))
    if bad:
        raise ValueError(f"{at('orientations', bad[0])}: orientations: unknown joint(s) {', '.join(bad)} "
                         f"(oriented joints: {', '.join(ORIENTED_JOINTS)})")
    ori = {}
    for n in ORIENTED_JOINTS:
        if n not in oris_in:
            ori[n] = _default_orientation(n, pos, at("positions", n))
            if not tpose:
                raise ValueError(f"{at('rest_is_tpose')}: orientations.{n} is needed: the default (the T-pose "
                                 "rest axes) needs \"rest_is_tpose\": true")
            continue
        o = oris_in[n]
        w = f"{at('orientations', n)}: orientations.{n}"
        if not (isinstance(o, dict) and set(o) == {"joint", "primary", "secondary"}
                and isinstance(o["joint"], str) and o["joint"].strip()):
            raise ValueError(f'{w}: expected {{"joint": "Name", "primary": AXIS, "secondary": AXIS}}, '
                             f"got {shown(o)}")
        axes = [_file_axis(o[k], f"{at('orientations', n, k)}: orientations.{n}.{k}") for k in ("primary", "secondary")]
        if axes[0].kind == axes[1].kind == "local" and np.linalg.norm(np.cross(axes[0].vector, axes[1].vector)) \
                < 1e-6 * np.linalg.norm(axes[0].vector) * np.linalg.norm(axes[1].vector):
            raise ValueError(f"{at('orientations', n, 'secondary')}: orientations.{n}.secondary: "
                             f"{shown(o['secondary'])} is parallel to primary {shown(o['primary'])}: the two "
                             "axes of a joint's frame must differ")
        ori[n] = OrientationSpec(o["joint"].strip(), *axes)
        if not tpose and "rest" in (ori[n].primary.kind, ori[n].secondary.kind):
            raise ValueError(f'{w}: "rest" axes need "rest_is_tpose": true')

    parents = data.get("parents", [])
    bad = [(k,) for k, p in enumerate(parents if isinstance(parents, list) else [])
           if not (isinstance(p, list) and len(p) == 2 and all(isinstance(x, str) and x.strip() for x in p))]
    if not isinstance(parents, list) or bad:
        raise ValueError(f'{at("parents", *bad[0]) if bad else at("parents")}: parents must be a list of '
                         f'["child", "parent"] joint names; got {shown(parents)}')
    name = data.get("name", os.path.splitext(os.path.basename(where))[0])
    desc = data.get("description", f"joint-map file {os.path.basename(where)}")
    for k, v in (("name", name), ("description", desc)):
        if not (isinstance(v, str) and v.strip()):
            raise ValueError(f"{at(k)}: {k} must be a non-empty string; got {shown(v)}")
    return JointMap(name, pos, ori, unit_scale=units, up=up.strip(), forward=fwd.strip(), rest_is_tpose=tpose,
                    foot_pitch=fp, parents=tuple(tuple(p) for p in parents), description=desc)


# --------------------------------------------------------------------------
def take_id_from_name(name: str) -> str:
    """Stable take id for train/validation splits: the file stem, lower case.

    ``"Bandai/data/dataset-1_walk_normal_001.bvh.gz"`` -> ``"dataset-1_walk_normal_001"``.
    """
    base = os.path.basename(str(name).replace("\\", "/"))
    base = re.sub(r"(\.bvh)?(\.gz)?$", "", base, flags=re.IGNORECASE)
    return base.lower()


@dataclass
class MotionClip:
    """A source clip in body-model conventions.

    * ``positions``: ``(T, 22, 3)`` float64 metres, Blender axes, floor z = 0,
      joint order ``skeleton.JOINT_NAMES``.
    * ``rotations``: ``{name: (T, 3, 3)}`` world rotations for
      :data:`ORIENTED_JOINTS` (identity = T-pose rest frame of that joint).
    * ``body``: the clip's own :class:`skeleton.Body`.
    * ``fps``: frames per second (1 / Frame Time, rounded when within 1e-4
      of an integer or when a whole rate's frame time rounds to the Frame Time as written:
      ``0.0333`` is 30); ``name``: take name; ``take_id``: split key.
    * ``unit_scale`` (metres per source unit), ``floor_height`` (metres,
      converted axes, already subtracted), ``foot_pitch`` (degrees, see
      :func:`clip_to_body_motion`), ``joint_map`` (map name), ``source``
      (file name).
    """
    name: str
    take_id: str
    fps: float
    positions: np.ndarray
    rotations: Dict[str, np.ndarray]
    body: skeleton.Body
    joint_map: str = ""
    unit_scale: float = 1.0
    floor_height: float = 0.0
    foot_pitch: float = REST_FOOT_PITCH
    source: str = ""

    @property
    def num_frames(self) -> int:
        return int(self.positions.shape[0])

    def rotation_array(self, names: Sequence[str] = ORIENTED_JOINTS) -> np.ndarray:
        """``(T, len(names), 3, 3)`` stacked rotations."""
        return np.stack([self.rotations[n] for n in names], axis=1)


# --------------------------------------------------------------------------
# helpers
def _resolve_weights(jm: JointMap, res: _Resolver, rest_len_fn, clip_name: str) -> np.ndarray:
    """``(22, J)`` matrix W with body positions = W @ source positions."""
    W = np.zeros((NJ, len(res.exact)))
    for n in JN:
        p = jm.positions[n]
        idx = [res(j, clip_name) for j in p.joints]
        if p.kind == "joint":
            W[_J[n], idx[0]] = 1.0
        elif p.kind == "lerp":
            W[_J[n], idx[0]] += 1.0 - p.t
            W[_J[n], idx[1]] += p.t
        elif p.kind == "chain":
            seg = np.array([rest_len_fn(a, b) for a, b in zip(idx[:-1], idx[1:])])
            total = seg.sum()
            if total <= 0:
                raise ValueError(f"{clip_name}: chain {p.describe()} has zero length")
            target = p.t * total
            cum = np.concatenate([[0.0], np.cumsum(seg)])
            k = int(np.clip(np.searchsorted(cum, target, side="right") - 1, 0, len(seg) - 1))
            while seg[k] <= 0 and k < len(seg) - 1:
                k += 1
            u = (target - cum[k]) / seg[k] if seg[k] > 0 else 0.0
            u = float(np.clip(u, 0.0, 1.0))
            W[_J[n], idx[k]] += 1.0 - u
            W[_J[n], idx[k + 1]] += u
        else:  # pragma: no cover
            raise ValueError(f"unknown point kind {p.kind!r}")
    return W


def _frame(a, b):
    """Orthonormal frame(s) ``[a, b', a x b']`` as columns; ``(..., 3, 3)``."""
    a = normalize(a)
    b = np.asarray(b, dtype=np.float64)
    b = b - np.sum(a * b, -1, keepdims=True) * a
    nb = np.linalg.norm(b, axis=-1)
    if np.any(nb < 1e-6):
        raise ValueError("primary and secondary axes are parallel")
    b = b / nb[..., None]
    return np.stack([a, b, np.cross(a, b)], axis=-1)


def _source_axis(ax: Axis, body_vec, M, res: _Resolver, rest_pos, clip_name) -> np.ndarray:
    if ax.kind == "local":
        return np.asarray(ax.vector, dtype=np.float64)
    if ax.kind == "rest":
        return M.T @ np.asarray(body_vec, dtype=np.float64)
    if ax.kind == "bone":
        a, b = (res(j, clip_name) for j in ax.joints)
        v = rest_pos[b] - rest_pos[a]
        if np.linalg.norm(v) < 1e-9:
            raise ValueError(f"{clip_name}: bone {ax.joints} has zero rest length")
        return v
    raise ValueError(f"unknown axis kind {ax.kind!r}")  # pragma: no cover


def _rounded(report: Mapping[str, float]) -> Dict[str, int]:
    return {k: int(round(v)) for k, v in report.items()}


def orientation_corrections(clip: BvhClip, jm: JointMap, M: np.ndarray,
                            foot_pitch: float = REST_FOOT_PITCH) -> Dict[str, Tuple[int, np.ndarray]]:
    """``{body name: (source joint index, C)}`` with ``R_body = M @ R_src @ C``.

    ``foot_pitch`` (degrees) sets the ankles' body-frame primary direction
    :func:`foot_direction`.
    """
    res = _Resolver(point_names(clip))
    rest_pos = np.concatenate([clip.rest_positions(), clip.rest_end_sites()])
    out = {}
    for name in ORIENTED_JOINTS:
        spec = jm.orientations[name]
        A, B = _BODY_AXES[name]
        if A is None:
            A = tuple(foot_direction(foot_pitch))
        a = _source_axis(spec.primary, A, M, res, rest_pos, clip.name)
        b = _source_axis(spec.secondary, B, M, res, rest_pos, clip.name)
        try:
            C = _frame(a, b) @ _frame(np.asarray(A, float), np.asarray(B, float)).T
        except ValueError:
            hint = (" (a rig with the same joint names but another zero pose, e.g. a Rokoko BVH without "
                    "finger joints read as 'mixamo': give the joint map 'rokoko')" if jm.name == "mixamo" else "")
            raise ValueError(
                f"{clip.name}: joint map {jm.name!r}: orientations.{name}: its primary and secondary axes "
                f"are parallel in this skeleton's rest pose, so the map does not fit this rig{hint}; rest pose: "
                f"{_rounded(rest_pose_report(clip, jm))}") from None
        j = res(spec.source, clip.name)
        if j >= clip.num_joints:
            raise ValueError(f"{clip.name}: orientations.{name}: {spec.source!r} is an End Site, which has no "
                             "rotation; name its joint")
        out[name] = (j, C)
    return out


def rest_pose_report(clip: BvhClip, joint_map: Union[None, str, JointMap] = None,
                     up: Optional[str] = None, forward: Optional[str] = None) -> Dict[str, float]:
    """Angles (degrees) between the zero-channel pose's limbs and a T-pose.

    Keys ``left_arm``, ``right_arm`` (shoulder->wrist vs. +-left),
    ``left_leg``, ``right_leg`` (hip->ankle vs. down), ``spine`` (pelvis->neck
    vs. up), measured in the map's source axes, or ``up`` / ``forward`` where given (as
    :func:`clip_to_body_motion`'s overrides).  All near 0 (legs may splay
    ~20 degrees in CMU) means the rest pose is a T-pose.
    """
    jm = get_joint_map(joint_map, clip)
    M = axis_conversion(up or jm.up, forward or jm.forward)
    p = _rest_body_points(clip, jm) @ M.T          # Blender axes, source units

    def ang(v, d):
        v = normalize(v)
        return float(np.degrees(np.arccos(np.clip(np.dot(v, d), -1, 1))))

    return {
        "left_arm": ang(p[_J["left_wrist"]] - p[_J["left_shoulder"]], np.array([1.0, 0, 0])),
        "right_arm": ang(p[_J["right_wrist"]] - p[_J["right_shoulder"]], np.array([-1.0, 0, 0])),
        "left_leg": ang(p[_J["left_ankle"]] - p[_J["left_hip"]], np.array([0, 0, -1.0])),
        "right_leg": ang(p[_J["right_ankle"]] - p[_J["right_hip"]], np.array([0, 0, -1.0])),
        "spine": ang(p[_J["neck"]] - p[_J["pelvis"]], np.array([0, 0, 1.0])),
    }


def _rest_body_points(clip: BvhClip, jm: JointMap) -> np.ndarray:
    """``(22, 3)`` body joints on the clip's zero-channel pose (source axes and units)."""
    res = _Resolver(point_names(clip))
    rp = np.concatenate([clip.rest_positions(), clip.rest_end_sites()])
    W = _resolve_weights(jm, res, lambda a, b: float(np.linalg.norm(rp[b] - rp[a])), clip.name)
    return W @ rp


def _axes_hint(clip: BvhClip, jm: JointMap, M: np.ndarray, rep: Mapping[str, float]) -> str:
    """When the rest spine (pelvis -> neck) lies more than 45 degrees off the up axis in use, the
    source axis it runs along and the axes to give: a Z-up file (Blender's BVH export of a Z-up
    armature) read as the map's Y-up one maps the performer lying down."""
    if rep["spine"] <= 45.0:
        return ""
    p = _rest_body_points(clip, jm)

    def axis(v):                                   # the source axis nearest to v, e.g. "+z"
        k = int(np.argmax(np.abs(v)))
        return ("+" if v[k] > 0 else "-") + "xyz"[k]
    up, used = axis(p[_J["neck"]] - p[_J["pelvis"]]), axis(M[2])   # M's row 2: the source up in use
    hint = ", forward '-y' for Blender's axes" if up == "+z" else ""
    return (f"; its spine runs along the file's {up} axis, not the up axis in use ({used}): if that is the "
            f"file's up axis, give up '{up.lstrip('+')}'{hint} (a sources file's or joint-map file's "
            '"up" / "forward")')


def detect_unit_scale(leg_length_source_units: float) -> float:
    """Metres per unit among :data:`UNIT_CANDIDATES` for a hip-knee-ankle length."""
    L = float(leg_length_source_units)
    if not np.isfinite(L) or L <= 0:
        raise ValueError(f"cannot detect units from a leg length of {L!r}")
    names = list(UNIT_CANDIDATES)
    err = [abs(np.log(L * UNIT_CANDIDATES[n] / _TYPICAL_LEG)) for n in names]
    return UNIT_CANDIDATES[names[int(np.argmin(err))]]


def estimate_floor(positions: np.ndarray, rest_heights: Mapping[int, float], percentile: float = 5.0) -> float:
    """Floor height (same units as ``positions[..., 2]``) from foot joints.

    ``positions``: ``(T, J, 3)`` with +Z up.  ``rest_heights``: ``{joint index:
    height of that joint above the floor when standing}``.  Returns the
    ``percentile`` over frames of ``min_j (z_j(t) - rest_heights[j])``.
    """
    idx = list(rest_heights)
    z = positions[:, idx, 2] - np.array([rest_heights[i] for i in idx])
    low = np.min(z, axis=1)
    if low.size == 0:
        return 0.0
    return float(np.percentile(low, percentile))


def estimate_foot_pitch(positions: np.ndarray, tol: float = 0.02, percentile: float = 5.0) -> Optional[float]:
    """Dip (degrees) of the ankle->ball line while the foot stands flat.

    ``positions``: ``(T, 22, 3)`` metres, +Z up (floor not needed).  Stance
    frames of a foot are those where both its ankle and its ball are within
    ``tol`` metres of their own ``percentile`` heights; returns the median dip
    over the stance frames of both feet, or ``None`` when there are fewer
    than 3 or the result is outside 0-70 degrees.
    """
    vals = []
    for side in ("left", "right"):
        a = positions[:, _J[f"{side}_ankle"]]
        b = positions[:, _J[f"{side}_foot"]]
        L = np.linalg.norm(b - a, axis=-1)
        ok = L > 1e-6
        dip = np.degrees(np.arcsin(np.clip((a[:, 2] - b[:, 2]) / np.maximum(L, 1e-9), -1, 1)))
        st = ok & (a[:, 2] <= np.percentile(a[:, 2], percentile) + tol) \
            & (b[:, 2] <= np.percentile(b[:, 2], percentile) + tol)
        vals.append(dip[st])
    vals = np.concatenate(vals)
    if vals.size < 3:
        return None
    med = float(np.median(vals))
    return med if 0.0 <= med <= 70.0 else None


def _snap_fps(frame_time: float) -> float:
    """``1 / frame_time``, or a whole rate: the nearest when within 1e-4 of it, else the only one
    whose frame time rounds to ``frame_time`` as written (``0.0333`` is 30 fps, not 30.03;
    ``0.0167`` 60; ``0.0333667``, NTSC's 29.97, keeps its rate; ``0.03`` fits 29-40 and keeps 33.3)."""
    fps = 1.0 / frame_time
    r = round(fps)
    if r > 0 and abs(fps - r) < 1e-4 * fps:
        return float(r)
    text = repr(float(frame_time))               # the digits as written (shortest repr)
    if "." not in text or "e" in text:
        return fps
    half = 0.5 * 10.0 ** -len(text.split(".")[1])
    if half >= frame_time:
        return fps
    fits = range(int(np.ceil(1.0 / (frame_time + half))), int(np.floor(1.0 / (frame_time - half))) + 1)
    return float(fits[0]) if len(fits) == 1 and fits[0] > 0 else fps


def _mirror(v):
    return v * np.array([-1.0, 1.0, 1.0])


def _body_from_motion(pos: np.ndarray, R_pelvis: np.ndarray, foot_pitch: float = REST_FOOT_PITCH) -> skeleton.Body:
    """Body with the clip's mean bone lengths in the standard rest layout.

    ``pos``: ``(T, 22, 3)`` metres, Blender axes; ``R_pelvis``: ``(T, 3, 3)``
    pelvis orientation (body convention); ``foot_pitch``: degrees.
    """
    par = skeleton.PARENTS
    L = np.linalg.norm(pos[:, 1:] - pos[:, par[1:]], axis=-1).mean(axis=0)
    length = np.concatenate([[0.0], L])
    off = np.zeros((NJ, 3))
    up = np.array([0, 0, 1.0])
    for n in ("spine1", "spine2", "spine3", "neck", "head"):
        off[_J[n]] = up * length[_J[n]]

    # hips in the pelvis frame
    def mean_local(R, child, parent):
        v = np.einsum("tji,tj->ti", R, pos[:, child] - pos[:, parent])
        return v.mean(axis=0)

    hl = mean_local(R_pelvis, _J["left_hip"], _J["pelvis"])
    hr = mean_local(R_pelvis, _J["right_hip"], _J["pelvis"])
    h = 0.5 * (hl + _mirror(hr))
    off[_J["left_hip"]], off[_J["right_hip"]] = h, _mirror(h)

    # chest frame: up = spine3->neck, left = right collar -> left collar
    a = pos[:, _J["neck"]] - pos[:, _J["spine3"]]
    b = pos[:, _J["left_collar"]] - pos[:, _J["right_collar"]]
    upv = normalize(a)
    leftv = normalize(b - np.sum(b * upv, -1, keepdims=True) * upv)
    yv = np.cross(upv, leftv)                  # up x left = +Y (backward) in body frame
    Rc = np.stack([leftv, yv, upv], axis=-1)
    cl = mean_local(Rc, _J["left_collar"], _J["spine3"])
    cr = mean_local(Rc, _J["right_collar"], _J["spine3"])
    c = 0.5 * (cl + _mirror(cr))
    off[_J["left_collar"]], off[_J["right_collar"]] = c, _mirror(c)
    sl = normalize(mean_local(Rc, _J["left_shoulder"], _J["left_collar"]))
    sr = normalize(mean_local(Rc, _J["right_shoulder"], _J["right_collar"]))
    s = normalize(0.5 * (sl + _mirror(sr)))
    ls = 0.5 * (length[_J["left_shoulder"]] + length[_J["right_shoulder"]])
    off[_J["left_shoulder"]], off[_J["right_shoulder"]] = s * ls, _mirror(s * ls)

    def sym(n):
        return 0.5 * (length[_J["left_" + n]] + length[_J["right_" + n]])

    for n in ("elbow", "wrist"):
        off[_J["left_" + n]] = [sym(n), 0, 0]
        off[_J["right_" + n]] = [-sym(n), 0, 0]
    for n in ("knee", "ankle"):
        off[_J["left_" + n]] = [0, 0, -sym(n)]
        off[_J["right_" + n]] = [0, 0, -sym(n)]
    off[_J["left_foot"]] = off[_J["right_foot"]] = foot_direction(foot_pitch) * sym("foot")

    # pelvis height: the rest ball of the foot at foot_height * stature (as in
    # make_body), stature = head z / head_height (as in Body.from_offsets)
    rel = np.zeros((NJ, 3))
    for j in range(1, NJ):
        rel[j] = rel[par[j]] + off[j]
    c_ = _P["foot_height"] / _P["head_height"]
    head_rel, ball_rel = rel[_J["head"], 2], rel[_J["left_foot"], 2]
    z0 = (c_ * head_rel - ball_rel) / (1.0 - c_)
    return skeleton.Body.from_offsets(off, np.array([0.0, 0.0, z0]))


# --------------------------------------------------------------------------
def _check_source_joints(jm: JointMap, clip: BvhClip) -> None:
    """``ValueError`` naming the clip, the map (its description: a joint-map file's name) and each
    entry (``positions.left_wrist``, ``orientations.left_ankle``) whose source joint the clip's
    skeleton does not have (a misspelt name in a joint-map file), with the skeleton's joints."""
    names = point_names(clip)
    miss = set(jm.missing(names))
    if not miss:
        return
    entries = [(f"positions.{n}", p.joints) for n, p in jm.positions.items()]
    entries += [(f"orientations.{n}", (o.source,) + o.primary.joints + o.secondary.joints)
                for n, o in jm.orientations.items()]
    where = [f"{w}: {', '.join(repr(j) for j in dict.fromkeys(js) if j in miss)}"
             for w, js in entries if miss & set(js)]
    raise ValueError(f"{clip.name}: joint map {jm.name!r} ({jm.description or 'built in'}) names joint(s) this "
                     f"skeleton does not have: {'; '.join(where)} (its joints: {', '.join(names)})")


def clip_to_body_motion(clip: BvhClip, joint_map: Union[None, str, JointMap] = None, *,
                        unit_scale: Union[None, float, str] = None, floor: Union[str, float] = "auto",
                        up: Optional[str] = None, forward: Optional[str] = None,
                        foot_pitch: Union[None, float, str] = "map",
                        name: Optional[str] = None) -> MotionClip:
    """Map a BVH clip onto the 22-joint body (metres, Blender axes, floor z = 0).

    ``joint_map``: a :class:`JointMap`, a registered name (``"bandai"``, ``"cmu"``,
    ``"mixamo"``, ``"lafan1"``, ``"100style"``, ``"neuron"``, ``"rokoko"``), the path of a joint-map
    ``.json`` file (:func:`load_joint_map`) or ``None``/``"auto"`` to detect it from the joint names.
    ``unit_scale``: metres per source unit, ``"auto"``, or ``None`` for the
    map's default.  ``floor``: ``"auto"`` or the floor height in metres in
    converted axes.  ``up``/``forward`` override the map's source axes.
    ``foot_pitch``: dip (degrees) of the ankle->ball line of a flat foot,
    which defines the ankles' identity orientation and the body's rest foot;
    ``"map"`` uses the map's value, ``"auto"`` measures it on the clip
    (:func:`estimate_foot_pitch`, falling back to the body model's 20.3),
    ``None`` is the body model's 20.3.
    """
    jm = get_joint_map(joint_map, clip)
    _check_source_joints(jm, clip)
    M = axis_conversion(up or jm.up, forward or jm.forward)
    res = _Resolver(point_names(clip))
    T = clip.num_frames
    if T == 0:
        raise ValueError(f"{clip.name}: clip has no frames")
    pos_src, rot_src = clip.global_transforms()
    pos_src = np.concatenate([pos_src, clip.end_site_positions(pos_src, rot_src)], axis=1)   # + End Sites

    # chain weights from the clip's mean joint distances (constant for rigid bones)
    sample = pos_src[:: max(1, T // 64)]

    def seg_len(a, b):
        return float(np.linalg.norm(sample[:, b] - sample[:, a], axis=-1).mean())

    W = _resolve_weights(jm, res, seg_len, clip.name)

    scale = jm.unit_scale if unit_scale is None else unit_scale
    if isinstance(scale, str):
        if scale != "auto":
            scale = UNIT_CANDIDATES[scale]
        else:
            body_src = np.einsum("kj,tjc->tkc", W, sample)
            leg = 0.0
            for side in ("left", "right"):
                h, k, a = (_J[f"{side}_{n}"] for n in ("hip", "knee", "ankle"))
                leg += np.median(np.linalg.norm(body_src[:, k] - body_src[:, h], axis=-1)
                                 + np.linalg.norm(body_src[:, a] - body_src[:, k], axis=-1)) / 2
            scale = detect_unit_scale(leg)
    scale = float(scale)

    if any(ax.kind == "rest" for o in jm.orientations.values() for ax in (o.primary, o.secondary)):
        rep = rest_pose_report(clip, jm, up, forward)
        if not jm.rest_is_tpose or max(rep["left_arm"], rep["right_arm"], rep["spine"]) > 30.0:
            warnings.warn(f"{clip.name}: joint map {jm.name!r} takes orientations from the rest pose, "
                          f"but the rest pose is not a T-pose ({rep})" + _axes_hint(clip, jm, M, rep))

    # positions: W combines source joints, then axes and units
    P = np.einsum("kj,tjc->tkc", W, pos_src)
    P = np.einsum("ij,tkj->tki", M * scale, P)

    # foot pitch, orientations, body
    fp = jm.foot_pitch if isinstance(foot_pitch, str) and foot_pitch == "map" else foot_pitch
    if fp is None:
        fp = REST_FOOT_PITCH
    elif isinstance(fp, str):
        if fp != "auto":
            raise ValueError(f"foot_pitch must be 'map', 'auto', None or degrees, got {fp!r}")
        est = estimate_foot_pitch(P)
        fp = REST_FOOT_PITCH if est is None else est
    fp = float(fp)
    corr = orientation_corrections(clip, jm, M, fp)
    rotations = {n: M @ rot_src[:, j] @ C for n, (j, C) in corr.items()}

    body = _body_from_motion(P, rotations["pelvis"], fp)
    if isinstance(floor, str):
        if floor != "auto":
            raise ValueError(f"floor must be 'auto' or a height in metres, got {floor!r}")
        rest_p = body.rest_positions()
        heights = {_J[n]: rest_p[_J[n], 2] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")}
        floor_h = estimate_floor(P, heights)
    else:
        floor_h = float(floor)
    P[..., 2] -= floor_h

    nm = name or clip.name
    return MotionClip(
        name=nm, take_id=take_id_from_name(nm), fps=_snap_fps(clip.frame_time), positions=P,
        rotations=rotations, body=body, joint_map=jm.name, unit_scale=scale, floor_height=floor_h,
        foot_pitch=fp, source=clip.source,
    )
