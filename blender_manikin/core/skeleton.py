"""The 22-joint body model: topology, rest offsets from anthropometry, and FK.

World axes are Blender's: right-handed, metres, **+Z up, the body faces -Y**,
so the performer's left is +X.  The rest pose is a T-pose standing on the
floor ``z = 0`` with every joint frame aligned with the world axes (as in
SMPL): a local rotation of identity for every joint gives the rest pose, and

    R_world[j] = R_world[parent[j]] @ R_local[j]
    p_world[j] = p_world[parent[j]] + R_world[parent[j]] @ offset[j]

Limbs are straight in the rest pose: arms along +X (left) / -X (right),
legs along -Z, so every limb bone's rest direction is a coordinate axis.

Topology and joint order follow the SMPL body (first 22 joints); none of
SMPL's numbers are used.  Rest offsets come from the segment proportions of
Drillis & Contini (1966) as tabulated in D. A. Winter, *Biomechanics and
Motor Control of Human Movement*, 4th ed. (2009), Fig. 4.1, as fractions of
stature H:

=================  =======  ==========================================
quantity           value    note
=================  =======  ==========================================
shoulder height    0.818 H  glenohumeral joint centre height
hip joint height   0.530 H  greater trochanter / hip centre
knee height        0.285 H
ankle height       0.039 H
upper arm          0.186 H  shoulder-elbow
forearm            0.146 H  elbow-wrist
thigh              0.245 H  hip-knee
shank              0.246 H  knee-ankle
foot length        0.152 H  heel-toe; the ball (SMPL "foot") lies
                            0.48 of it ahead of the ankle
shoulder breadth   0.259 H  biacromial; joint centres lie ~0.025 H
                            inside each acromion -> 0.209 H between them
hip breadth        0.191 H  bitrochanteric; hip joint centres are
                            ~0.52 of it apart -> 0.100 H (Bell et al. 1990)
chin height        0.870 H  head joint: the head's pivot at the top of
                            the neck, as mocap skeletons place it
ear height         0.910 H  skull base, between the ears
=================  =======  ==========================================

Torso joints (spine1-3, neck, collars) are spaced evenly between the pelvis
(0.03 H above the hip centres) and the neck joint (0.830 H, the neck base).

The head and neck joints follow the motion-capture skeletons the network is
trained and validated on rather than the anatomical skull base (0.910 H) and
C7 (0.840 H) this model used before: a tracker on a mocap skeleton's head
joint sees the shoulders, collars and pelvis 0.05-0.07 statures below it,
where the skull-base head put them 0.09.  Solving the Bandai Namco held-out
takes and the HDM05 validation set with a calibrated body, head joint at
0.91 / 0.89 / 0.88 / 0.87 / 0.86 H gave MPJPE 5.05 / 4.14 / 3.79 / 3.72 /
3.91 cm (Bandai) and 11.76 / 10.95 / 10.70 / 10.56 / 10.56 cm (HDM05); with
the head at 0.87, the neck at 0.84 / 0.83 / 0.82 H gave 3.72 / 3.61 / 3.70
(Bandai) and 10.56 / 10.42 / 10.31 (HDM05).  Both are chosen where the
training data (Bandai) does best.  The eyes (an HMD) stay 0.936 H high, so
the head joint lies 0.066 H (11.5 cm at 1.75 m) below them
(:mod:`.device_offsets`).

Shoes: the proportions are barefoot; a made body stands on soles
(:attr:`BodyMeasurements.sole`, default :data:`SOLE` = 3 cm), which lift
every joint by as much, so the stature stays the barefoot one and the rest
ankles are ``0.039 H + sole`` above the floor.  Both studios' skeletons,
floored by their feet, stand their ankles that much higher than the
barefoot proportions put them: HDM05 2.9 cm, Bandai Namco 3.3 cm (the head
joint's height above the ankles gives the stature).  A T-pose calibration
measures the stature from the head's height above the floor: without soles
it came out 2.0 % (HDM05) and 2.5 % (Bandai) too tall, legs about 3 cm too
long and the feet settled 3 cm too low; with 3 cm soles, 0.1 % and 0.3 %.
Solved with bodies calibrated that way, soles 0 / 2 / 3 / 4 cm gave MPJPE
10.50 / 10.36 / 10.32 / 10.29 cm (HDM05) and 3.90 / 3.53 / 3.41 / 3.32 cm
(Bandai), knees 19.52 / 19.22 / 19.12 / 19.06 and 5.97 / 4.99 / 4.57 /
4.22 cm.  3 cm is where the measured stature matches the skeletons, not the
best score.
"""
from __future__ import annotations

from dataclasses import dataclass, field, asdict
from typing import Optional

import numpy as np

JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee",
    "spine2", "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot",
    "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)
PARENTS = np.array([-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19])
NUM_JOINTS = 22
J = {name: i for i, name in enumerate(JOINT_NAMES)}


#: the ranges the performer's lengths are taken in, metres: by the panel (Height, Arm Span: 0 from
#: the proportions, Shoe Soles) and the command line (--height, --arm-span, --sole)
LENGTH_RANGES = {"height": (0.5, 2.8), "arm_span": (0.0, 3.0), "sole": (0.0, 0.2)}


def mirror_name(name: str) -> str:
    """The left/right mirror image of a joint or device name ("left_knee" -> "right_knee")."""
    return name.replace("left_", "\0").replace("right_", "left_").replace("\0", "right_")


#: joint index of each joint's left/right mirror image (x -> -x)
MIRROR_JOINTS = np.array([J[mirror_name(n)] for n in JOINT_NAMES])
#: the mirror x -> -x, as it acts on a rotation: ``R -> MIRROR_M @ R @ MIRROR_M`` (every rest frame
#: of the body model is world aligned, so this is a joint's mirrored rotation)
MIRROR_M = np.diag([-1.0, 1.0, 1.0])

TORSO_JOINTS = (J["pelvis"], J["spine1"], J["spine2"], J["spine3"], J["neck"],
                J["left_collar"], J["right_collar"], J["head"])

#: The four limbs as (name, base, mid, end) joint indices.
LIMBS = (
    ("left_arm", J["left_shoulder"], J["left_elbow"], J["left_wrist"]),
    ("right_arm", J["right_shoulder"], J["right_elbow"], J["right_wrist"]),
    ("left_leg", J["left_hip"], J["left_knee"], J["left_ankle"]),
    ("right_leg", J["right_hip"], J["right_knee"], J["right_ankle"]),
)
LIMB_NAMES = tuple(limb[0] for limb in LIMBS)

#: Children lists, derived from PARENTS.
CHILDREN = tuple(tuple(int(c) for c in np.nonzero(PARENTS == j)[0]) for j in range(NUM_JOINTS))

# fractions of stature (see module docstring)
PROPORTIONS = dict(
    shoulder_height=0.818, hip_height=0.530, knee_height=0.285, ankle_height=0.039,
    upper_arm=0.186, forearm=0.146, thigh=0.245, shank=0.246,
    shoulder_width=0.209, hip_width=0.100, foot_forward=0.073, foot_height=0.012,
    neck_height=0.830, head_height=0.870, ear_height=0.910, eye_height=0.936, pelvis_above_hips=0.030,
    collar_out=0.040, collar_height=0.800,
)

#: metres a made body stands above the floor on its shoe soles (see the module docstring); a
#: barefoot performer: ``BodyMeasurements(sole=0)``
SOLE = 0.03


def sole_or_default(sole) -> float:
    """The soles' thickness in metres: ``sole``, or :data:`SOLE` when it is None."""
    return SOLE if sole is None else float(sole)


@dataclass
class BodyMeasurements:
    """Measurements of a performer, metres.  Only ``stature`` is required.

    ``arm_span`` is wrist-to-wrist in a T-pose (what hand trackers measure);
    when given and the arm segments are not, upper arm and forearm are scaled
    together so the span matches.  ``shoulder_width`` and ``hip_width`` are
    distances between the joint centres.  ``sole``: the shoe soles' thickness, how far the
    feet stand above the floor (``None``: :data:`SOLE`; 0 barefoot); the stature is the
    barefoot one.
    """
    stature: float = 1.75
    arm_span: Optional[float] = None
    upper_arm: Optional[float] = None
    forearm: Optional[float] = None
    thigh: Optional[float] = None
    shank: Optional[float] = None
    shoulder_width: Optional[float] = None
    hip_width: Optional[float] = None
    sole: Optional[float] = None

    @property
    def sole_height(self) -> float:
        """The soles' thickness in metres (:data:`SOLE` when not given)."""
        return sole_or_default(self.sole)

    def to_dict(self):
        return {k: v for k, v in asdict(self).items() if v is not None}


@dataclass
class Body:
    """A sized skeleton: ``offsets`` ``(22, 3)`` float64 metres in the parent
    frame (rest), and the pelvis rest position ``root_rest`` ``(3,)``.

    Build one with :func:`make_body` or :meth:`from_offsets`.
    """
    offsets: np.ndarray
    root_rest: np.ndarray
    measurements: BodyMeasurements = field(default_factory=BodyMeasurements)

    @classmethod
    def from_offsets(cls, offsets, root_rest, stature=None, sole=0.0):
        """A body with these rest ``offsets`` ``(22, 3)`` and pelvis rest position ``root_rest``
        ``(3,)`` (metres; the feet stand where they put them), on soles ``sole`` metres thick
        (the floor is that far below where the barefoot feet would stand).  stature: metres,
        default from the head joint's height, ``(z - sole) / 0.870``."""
        offsets = np.asarray(offsets, dtype=np.float64).reshape(NUM_JOINTS, 3)
        root_rest = np.asarray(root_rest, dtype=np.float64).reshape(3)
        body = cls(offsets, root_rest)
        rest = body.rest_positions()
        if stature is None:
            stature = float((rest[J["head"], 2] - sole) / PROPORTIONS["head_height"])
        body.measurements = BodyMeasurements(stature=float(stature), sole=float(sole))
        return body

    @property
    def stature(self) -> float:
        return float(self.measurements.stature)

    @property
    def sole(self) -> float:
        """Metres the rest feet stand above the floor on their soles (:meth:`from_offsets`
        bodies: 0 unless given)."""
        return self.measurements.sole_height

    def rest_positions(self):
        """``(22, 3)`` world positions of the rest T-pose (made bodies: the soles on z = 0, the
        joints :attr:`sole` higher than the barefoot proportions)."""
        p = np.zeros((NUM_JOINTS, 3))
        p[0] = self.root_rest
        for j in range(1, NUM_JOINTS):
            p[j] = p[PARENTS[j]] + self.offsets[j]
        return p

    def bone_lengths(self):
        """``(22,)`` length of the offset to each joint's parent (0 for the root)."""
        return np.linalg.norm(self.offsets, axis=-1)

    def limb_lengths(self):
        """``(4, 2)`` upper and lower segment lengths of each limb in LIMBS order."""
        L = self.bone_lengths()
        return np.array([[L[m], L[e]] for _, b, m, e in LIMBS])

    def scaled(self, factor):
        return Body.from_offsets(self.offsets * factor, self.root_rest * factor,
                                 stature=self.stature * factor, sole=self.sole * factor)


def stature_from_head_above_ankles(head_above_ankles):
    """Stature (metres, array-like) of a body whose head joint stands ``head_above_ankles``
    metres above its ankle joints when upright, by the proportions of :data:`PROPORTIONS`."""
    return np.asarray(head_above_ankles, np.float64) / (PROPORTIONS["head_height"] - PROPORTIONS["ankle_height"])


def make_body(measurements: BodyMeasurements | float | None = None) -> Body:
    """Build a :class:`Body` from measurements (or a stature in metres), its rest T-pose standing
    on its soles on the floor ``z = 0`` (:attr:`BodyMeasurements.sole`)."""
    if measurements is None:
        measurements = BodyMeasurements()
    elif not isinstance(measurements, BodyMeasurements):
        measurements = BodyMeasurements(stature=float(measurements))
    m = measurements
    H = float(m.stature)
    if not np.isfinite(H) or H <= 0.3 or H > 3.0:
        raise ValueError(f"stature {H!r} m is not a plausible human height (0.3-3 m)")
    P = {k: v * H for k, v in PROPORTIONS.items()}
    sw = m.shoulder_width if m.shoulder_width is not None else P["shoulder_width"]
    hw = m.hip_width if m.hip_width is not None else P["hip_width"]
    ua = m.upper_arm if m.upper_arm is not None else P["upper_arm"]
    fa = m.forearm if m.forearm is not None else P["forearm"]
    if m.arm_span is not None and m.upper_arm is None and m.forearm is None:
        arm = (float(m.arm_span) - sw) / 2.0
        if arm <= 0.05:
            raise ValueError(f"arm span {m.arm_span} m is smaller than the shoulder width {sw:.3f} m")
        s = arm / (ua + fa)
        ua, fa = ua * s, fa * s
    th = m.thigh if m.thigh is not None else P["thigh"]
    sh = m.shank if m.shank is not None else P["shank"]
    for name, v in (("shoulder_width", sw), ("hip_width", hw), ("upper_arm", ua), ("forearm", fa),
                    ("thigh", th), ("shank", sh)):
        if not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name} must be a positive length in metres, got {v!r}")
    sole = m.sole_height
    if not np.isfinite(sole) or not LENGTH_RANGES["sole"][0] <= sole <= LENGTH_RANGES["sole"][1]:
        raise ValueError(f"sole must be 0-0.2 m (the shoe soles' thickness; 0 barefoot), got {m.sole!r}")

    ankle_h = P["ankle_height"]
    hip_h = ankle_h + sh + th              # legs define where the hips are
    pelvis_h = hip_h + P["pelvis_above_hips"]
    neck_h = max(P["neck_height"], pelvis_h + 0.1 * H)
    shoulder_h = neck_h - (P["neck_height"] - P["shoulder_height"])
    collar_h = neck_h - (P["neck_height"] - P["collar_height"])
    head_h = neck_h + (P["head_height"] - P["neck_height"])
    spine = np.linspace(pelvis_h, neck_h, 5)   # pelvis, spine1, spine2, spine3, neck

    pos = np.zeros((NUM_JOINTS, 3))
    pos[J["pelvis"]] = [0, 0, pelvis_h]
    pos[J["spine1"]] = [0, 0, spine[1]]
    pos[J["spine2"]] = [0, 0, spine[2]]
    pos[J["spine3"]] = [0, 0, spine[3]]
    pos[J["neck"]] = [0, 0, neck_h]
    pos[J["head"]] = [0, 0, head_h]
    for side, sx in (("left", 1.0), ("right", -1.0)):
        pos[J[f"{side}_collar"]] = [sx * P["collar_out"], 0, collar_h]
        pos[J[f"{side}_shoulder"]] = [sx * sw / 2, 0, shoulder_h]
        pos[J[f"{side}_elbow"]] = [sx * (sw / 2 + ua), 0, shoulder_h]
        pos[J[f"{side}_wrist"]] = [sx * (sw / 2 + ua + fa), 0, shoulder_h]
        pos[J[f"{side}_hip"]] = [sx * hw / 2, 0, hip_h]
        pos[J[f"{side}_knee"]] = [sx * hw / 2, 0, hip_h - th]
        pos[J[f"{side}_ankle"]] = [sx * hw / 2, 0, ankle_h]
        pos[J[f"{side}_foot"]] = [sx * hw / 2, -P["foot_forward"], P["foot_height"]]
    pos[:, 2] += sole
    offsets = np.zeros_like(pos)
    offsets[1:] = pos[1:] - pos[PARENTS[1:]]
    body = Body(offsets, pos[0].copy(), BodyMeasurements(**{**m.to_dict(), "stature": H}))
    return body


def forward_kinematics(local_rot, root_pos, body: Body, offsets=None):
    """Batched FK.

    local_rot: ``(T, 22, 3, 3)`` local rotations (parent frame), rest = identity.
    root_pos: ``(T, 3)`` pelvis world position, metres.
    offsets: optional ``(22, 3)`` or ``(T, 22, 3)`` overriding ``body.offsets``.
    Returns ``(positions (T, 22, 3), world_rot (T, 22, 3, 3))`` float64.
    Loops over the 22 joints, vectorised over frames (joint-major contiguous
    buffers, so each step is one batched matmul).
    """
    local_rot = np.asarray(local_rot, dtype=np.float64)
    T = local_rot.shape[0]
    off = np.asarray(body.offsets if offsets is None else offsets, dtype=np.float64)
    per_frame = off.ndim == 3
    loc = np.ascontiguousarray(np.moveaxis(local_rot, 1, 0))             # (22, T, 3, 3)
    offj = np.ascontiguousarray(np.moveaxis(off, 1, 0))[..., None] if per_frame else off
    pos = np.empty((NUM_JOINTS, T, 3))
    rot = np.empty((NUM_JOINTS, T, 3, 3))
    pos[0] = np.asarray(root_pos, dtype=np.float64).reshape(T, 3)
    rot[0] = loc[0]
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        np.matmul(rot[p], loc[j], out=rot[j])
        if per_frame:
            pos[j] = pos[p] + np.matmul(rot[p], offj[j])[..., 0]
        else:
            pos[j] = pos[p] + np.matmul(rot[p], offj[j])
    return np.moveaxis(pos, 0, 1), np.moveaxis(rot, 0, 1)


def local_from_world(world_rot):
    """Inverse of the rotation part of FK: ``(T, 22, 3, 3)`` world → local."""
    world_rot = np.asarray(world_rot, dtype=np.float64)
    local = world_rot.copy()
    par = world_rot[:, PARENTS[1:]]
    local[:, 1:] = np.swapaxes(par, -1, -2) @ world_rot[:, 1:]
    return local
