"""3D keypoint layouts (MediaPipe-33, COCO-17, Human3.6M-17, SMPL-22/24, OpenPose BODY_25, Halpe 26, and
the joint centres :mod:`.marker_sets` makes of OpenCap's and Plug-in Gait's markers) and how each
becomes the 22 joints of :mod:`.skeleton`.

A keypoint array is ``(T, K, 3)`` float64, metres, Blender axes (+Z up, right-handed; see
:mod:`.io_keypoints` for the conversion from files), NaN where a point is missing.  Each layout
names its K points in file order.  :func:`body22_from_keypoints` places the 22 body joints:

* joints a layout has (hips, knees, ankles, shoulders, elbows, wrists; SMPL has all 22) are
  taken as they are;
* the pelvis sits :data:`~.skeleton.PROPORTIONS` ``pelvis_above_hips`` above the hips' midpoint
  along the trunk, the neck base ``neck_height - shoulder_height`` above the shoulders'
  midpoint (or is the layout's neck / thorax), spine1-3 are spaced between them (through the
  Human3.6M spine point where there is one), the collars sit where the rest body puts them
  relative to the neck and shoulders, and the head joint (the top of the neck) lies 0.04
  statures below the midpoint of the ears (along the head's up axis, the face giving the
  head's frame), or 0.24 of the way from the neck to the head top; with no face points (none
  in the layout, or none ever seen in the file) it stands on the trunk's up axis, untwisted;
* the toes / ball of the foot (the ``foot`` joints) come from the layout's toe points, else
  (none in the layout, or never seen in the take) flat ahead of the ankle, facing the way the
  hips face;
* a lower-body take (:func:`lower_body_only`: the legs seen, no upper-body point seen but on a
  few stray frames, which are dropped):
  the pelvis stands on the world's up made square to the hip line (a marker layout's pelvis
  points, the mid-ASIS and mid-PSIS, where seen: tilted forwards and back with them,
  :func:`pelvis_from_markers`, also given as the pelvis's orientation), and the spine, neck, head,
  collars and arms (:data:`UPPER_BODY_JOINTS`) are the rest body's about it (arms lowered
  :data:`ARM_DROP_DEG` from the T-pose), sized by the stature the legs give
  (:func:`stature_from_legs`); ``Body22.lower_body`` says so;
* an arm whose elbow and wrist are never seen, in a take that shows the shoulders (hands cut off
  all take): it hangs from its shoulder as a lower-body take's arms, in the chest's frame (the
  shoulder line and the trunk's up); ``Body22.resting_arms`` names the sides;
* a wrist never seen while its elbow is: the forearm continues the upper arm, straight, its
  length the proportions' beside the upper arm measured in the take; ``Body22.straight_forearms``.

Twist (rotation about a bone) cannot be seen from one point per joint.  Where a layout has the
points for it, :func:`body22_from_keypoints` also returns world orientations: the head from the
face (ears and nose, or the head top and nose), the hands from the pinky / index points, the
feet from the heel and toes.  ``no_twist`` names the joints left with the rest twist; the solve's
summary lists them.  Orientations follow the body model's convention: the rest pose has every
joint frame equal to the world axes (the body faces -Y, its left is +X).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rotations as rot
from .skeleton import J, NUM_JOINTS, PROPORTIONS

_MP33 = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel", "right_heel",
    "left_foot_index", "right_foot_index",
)
_COCO17 = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip", "left_knee",
    "right_knee", "left_ankle", "right_ankle",
)
#: Human3.6M's 17 joints in the order VideoPose3D, MotionBERT and most 3D lifters write them
_H36M17 = (
    "pelvis", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
    "spine", "thorax", "nose", "head_top", "left_shoulder", "left_elbow", "left_wrist",
    "right_shoulder", "right_elbow", "right_wrist",
)
_SMPL22 = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)
#: Halpe 26 (AlphaPose, RTMPose / MMPose's Halpe models; Pose2Sim's default): COCO's 17, then the
#: head top, neck, hips' midpoint and the feet's big toes, small toes and heels
_HALPE26 = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip", "left_knee",
    "right_knee", "left_ankle", "right_ankle", "head_top", "neck", "mid_hip", "left_big_toe",
    "right_big_toe", "left_small_toe", "right_small_toe", "left_heel", "right_heel",
)
_BODY25 = (
    "nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow",
    "left_wrist", "mid_hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee",
    "left_ankle", "right_eye", "left_eye", "right_ear", "left_ear", "left_big_toe", "left_small_toe",
    "left_heel", "right_big_toe", "right_small_toe", "right_heel",
)

_LIMBS = tuple(f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"))
#: the pelvis markers' midpoints a marker layout carries besides its joint centres: the mid-ASIS
#: and the mid-PSIS (Plug-in Gait's SACR where it has no PSIS markers), which show the pelvis's
#: forward tilt the hips cannot (:func:`pelvis_from_markers`)
PELVIS_MARKER_POINTS = ("mid_asis", "mid_psis")
#: joint centres made from anatomical markers (:mod:`.marker_sets`): OpenCap's (no head markers)
_OPENCAP = _LIMBS + ("left_heel", "right_heel", "left_big_toe", "right_big_toe", "left_small_toe",
                     "right_small_toe") + PELVIS_MARKER_POINTS
#: and Vicon Plug-in Gait's (the head band's markers as the ears and nose; one toe marker)
_PLUGINGAIT = _LIMBS + ("left_heel", "right_heel", "left_foot_index", "right_foot_index", "left_ear", "right_ear",
                        "nose") + PELVIS_MARKER_POINTS

#: the points of a lower-body take (Plug-in Gait's lower-body marker set, a crop to the legs):
#: every other point of a layout is the upper body's (:func:`lower_body_only`)
LOWER_BODY_POINTS = frozenset(
    [f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle", "heel", "foot_index", "big_toe",
                                                     "small_toe")] + ["pelvis", "mid_hip", *PELVIS_MARKER_POINTS])
#: degrees below horizontal the arms of a lower-body take hang (a relaxed A-pose, elbows straight,
#: palms down as in the rest T-pose)
ARM_DROP_DEG = 70.0
#: degrees the line from the mid-PSIS to the mid-ASIS points below horizontal (anterior tilt) on the
#: rest body's neutral, untilted pelvis: a typical standing adult's (about 10-15° are reported; a
#: subject's own differs by several degrees, and that much shows as a lean of the trunk)
PELVIS_NEUTRAL_TILT_DEG = 12.0
#: the joints a lower-body take's pelvis carries as the rest body puts them
UPPER_BODY_JOINTS = ("spine1", "spine2", "spine3", "neck", "left_collar", "right_collar", "head",
                     "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist")

#: the head joint (top of the neck) lies this far from the neck base to the head top
_HEAD_ALONG_NECK = (PROPORTIONS["head_height"] - PROPORTIONS["neck_height"]) / (1.0 - PROPORTIONS["neck_height"])
#: statures the ears (the skull base) stand above the head joint, along the head's up axis
_EARS_ABOVE_HEAD = PROPORTIONS["ear_height"] - PROPORTIONS["head_height"]


@dataclass(frozen=True)
class KeypointLayout:
    """A named keypoint layout: ``points`` in file order and a one-line ``description``."""
    name: str
    description: str
    points: tuple

    def index(self, point: str) -> int:
        return self.points.index(point)

    def __contains__(self, point) -> bool:
        return point in self.points

    @property
    def has_spine(self) -> bool:
        """The layout has the spine joints as points (SMPL); others leave them to be guessed."""
        return "spine1" in self.points


LAYOUTS = {f.name: f for f in (
    KeypointLayout("mediapipe33", "MediaPipe / BlazePose 33 (FreeMoCap)", _MP33),
    KeypointLayout("coco17", "COCO 17", _COCO17),
    KeypointLayout("h36m17", "Human3.6M 17 (VideoPose3D, MotionBERT)", _H36M17),
    KeypointLayout("smpl22", "SMPL 22 body joints", _SMPL22),
    KeypointLayout("smpl24", "SMPL 24 (22 + hands; SMPL fits)", _SMPL22 + ("left_hand", "right_hand")),
    KeypointLayout("body25", "OpenPose BODY_25", _BODY25),
    KeypointLayout("halpe26", "Halpe 26 (AlphaPose, RTMPose; Pose2Sim)", _HALPE26),
    KeypointLayout("opencap", "joint centres from OpenCap's anatomical markers", _OPENCAP),
    KeypointLayout("plugingait", "joint centres from Vicon Plug-in Gait markers", _PLUGINGAIT),
)}

#: layouts of joint centres made from anatomical markers (:mod:`.marker_sets`), chosen by the
#: markers' names only: never by a point count or a detector's point names
MARKER_LAYOUTS = ("opencap", "plugingait")

_ALIASES = {"mediapipe": "mediapipe33", "blazepose": "mediapipe33", "freemocap": "mediapipe33",
            "coco": "coco17", "h36m": "h36m17", "human36m": "h36m17", "smpl": "smpl24",
            "openpose": "body25", "halpe": "halpe26", "alphapose": "halpe26", "pig": "plugingait",
            "vicon": "plugingait"}


def canonical_layout(name) -> str:
    """The layout name for ``name`` (case-insensitive; ``coco``, ``mediapipe``, ``h36m``,
    ``smpl``, ``openpose`` are aliases).  Raises ``ValueError`` listing the layouts."""
    key = str(name).strip().lower().replace("-", "").replace("_", "").replace(".", "")
    key = _ALIASES.get(key, key)
    if key not in LAYOUTS:
        raise ValueError(f"unknown keypoint layout {name!r}: expected one of {', '.join(LAYOUTS)}")
    return key


#: name parts that tools add around a point's name (FreeMoCap's and others' empties, CSV columns)
_NAME_AFFIXES = ("mediapipe_", "body_", "pose_", "mp_", "_body", "_empty", "_marker")


def point_key(name) -> str:
    """``name`` (an object's, a column's) as a point name: :func:`.devices.name_key` with the
    affixes of :data:`_NAME_AFFIXES` (``"Body_Left_Wrist.001"`` → ``"left_wrist"``)."""
    from .devices import name_key
    return name_key(name, _NAME_AFFIXES)


def layout_from_names(names):
    """``(layout, {point: name})`` for the layout all of whose points are among ``names``
    (matched by :func:`point_key`; the layout with the most points wins), or ``None``."""
    by_key = {}
    for n in names:
        by_key.setdefault(point_key(n), n)
    best = None
    for lay_name, lay in array_layouts().items():
        if all(p in by_key for p in lay.points) and (
                best is None or len(lay.points) > len(LAYOUTS[best].points)):
            best = lay_name
    if best is None:
        return None
    return best, {p: by_key[p] for p in LAYOUTS[best].points}


def array_layouts() -> dict:
    """``{name: layout}`` of the layouts a keypoint array or table holds as points (every layout
    but the marker sets, whose joint centres and pelvis midpoints are computed from markers)."""
    return {n: f for n, f in LAYOUTS.items() if n not in MARKER_LAYOUTS}


def layouts_with(count: int) -> list:
    """Names of the layouts with ``count`` points (what an unnamed ``(T, count, 3)`` array may be)."""
    return [n for n, f in array_layouts().items() if len(f.points) == count]


@dataclass
class Body22:
    """The body joints a keypoint layout gives.

    positions: ``(T, 22, 3)`` float64 metres, Blender axes, NaN where the keypoints were.
    end_rot: joint index → ``(T, 3, 3)`` world orientation (body-model convention; NaN on
    frames where its points were missing) for the joints whose twist the layout shows.
    no_twist: names of the joints whose twist the layout cannot show (rest twist used).
    lower_body: no upper-body point was ever seen (:func:`lower_body_only`): the trunk, collars,
    head and arms (:data:`UPPER_BODY_JOINTS`) are the rest body's on the pelvis, sized from the legs.
    pelvis_tilt: a lower-body take whose pelvis (and the trunk on it) tilts forwards and back with
    the pelvis markers (:func:`pelvis_from_markers`); False: upright on the world's up.
    resting_arms: the sides (``"left"``, ``"right"``) whose arm (elbow and wrist) was never seen
    in a take that shows the shoulders: it hangs at rest from the shoulder (:data:`ARM_DROP_DEG`).
    straight_forearms: the sides whose wrist was never seen while their elbow was: the forearm
    continues the upper arm, straight (:func:`body22_from_keypoints`).
    """
    positions: np.ndarray
    end_rot: dict
    no_twist: tuple
    lower_body: bool = False
    pelvis_tilt: bool = False
    resting_arms: tuple = ()
    straight_forearms: tuple = ()


#: an upper-body point seen on at most this share of the frames the legs are seen on is a
#: detector's stray sample (a false wrist or nose in a crop to the legs), not an upper body
STRAY_UPPER_SHARE = 0.05


def _upper_body_indices(lay):
    return [k for k, p in enumerate(lay.points) if p not in LOWER_BODY_POINTS]


def lower_body_only(points, layout) -> bool:
    """True when ``points`` ``(T, K, 3)`` (``layout``'s, NaN = missing) show both hips, knees and
    ankles but no upper-body point (shoulders, elbows, wrists, neck, face, hands: any point not in
    :data:`LOWER_BODY_POINTS`) on more than :data:`STRAY_UPPER_SHARE` of the frames the legs are
    seen on: a lower-body take (a few stray upper-body samples, a detector's false positives, do
    not make it a full-body one; :func:`drop_stray_upper_body` removes them)."""
    lay = LAYOUTS[canonical_layout(layout)] if not isinstance(layout, KeypointLayout) else layout
    seen = np.isfinite(np.asarray(points, np.float64)).all(-1)              # (T, K)
    legs = [f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle")]
    if not all(p in lay for p in legs):
        return False
    upper = _upper_body_indices(lay)
    leg_frames = seen[:, [lay.index(p) for p in legs]].any(-1).sum()
    if not upper or not all(seen[:, lay.index(p)].any() for p in legs):
        return False
    return bool((seen[:, upper].sum(0) <= STRAY_UPPER_SHARE * leg_frames).all())


def drop_stray_upper_body(points, layout):
    """``(points, dropped)``: ``points`` ``(T, K, 3)`` with the upper-body samples of a lower-body
    take (:func:`lower_body_only`) set to NaN, and how many samples (point-frames) that was; the
    points as given and 0 otherwise."""
    lay = LAYOUTS[canonical_layout(layout)] if not isinstance(layout, KeypointLayout) else layout
    X = np.asarray(points, np.float64)
    if not lower_body_only(X, lay):
        return X, 0
    upper = _upper_body_indices(lay)
    dropped = int(np.isfinite(X[:, upper]).all(-1).sum())
    if not dropped:
        return X, 0
    X = X.copy()
    X[:, upper] = np.nan
    return X, dropped


def stature_from_legs(P):
    """Stature (metres) of a body whose legs are ``P`` ``(T, 22, 3)``'s: the median hip-to-knee
    plus knee-to-ankle length, left and right averaged, over the rest body's leg length
    (:data:`~.skeleton.PROPORTIONS` ``thigh + shank`` of the stature).  NaN when never seen."""
    legs = []
    for side in ("left", "right"):
        hip, knee, ankle = (P[:, J[f"{side}_{j}"]] for j in ("hip", "knee", "ankle"))
        legs.append(np.linalg.norm(knee - hip, axis=-1) + np.linalg.norm(ankle - knee, axis=-1))
    legs = np.concatenate(legs)
    if not np.isfinite(legs).any():
        return np.nan
    return float(np.nanmedian(legs)) / (PROPORTIONS["thigh"] + PROPORTIONS["shank"])


def pelvis_from_markers(hip_left, mid_asis, mid_psis):
    """``(T, 3, 3)`` world orientation of the pelvis joint (body convention: +X its left, +Y its
    back, +Z up) from the pelvis markers: +X along ``hip_left`` (the right hip to the left one),
    the anterior direction (mid-PSIS to mid-ASIS, made square to it) as -Y, then turned back about
    +X by :data:`PELVIS_NEUTRAL_TILT_DEG`, so a pelvis whose ASIS stand that much below its PSIS
    is the rest body's upright one and each degree more anterior tilt leans it (and the trunk on
    it) a degree forwards.  All ``(T, 3)`` metres, Blender axes; NaN where a point is missing."""
    R = rot.frame_from_axes(hip_left, -(np.asarray(mid_asis, np.float64) - mid_psis), "xy")
    return R @ rot.axis_angle_rotation([1.0, 0.0, 0.0], -np.radians(PELVIS_NEUTRAL_TILT_DEG))


def _hanging_arms(H):
    """``{(side, joint): (3,)}``: the elbows' and wrists' offsets (metres) from their shoulder in
    the rest frame of a body of stature ``H`` metres (:func:`.skeleton.make_body`), the arms
    lowered :data:`ARM_DROP_DEG` from the T-pose about the shoulders' forward axis, elbows straight."""
    from .skeleton import make_body
    rest = make_body(H).rest_positions()
    a = np.radians(ARM_DROP_DEG)
    out = {}
    for side in ("left", "right"):
        sh = rest[J[f"{side}_shoulder"]]
        for j in ("elbow", "wrist"):
            along = rest[J[f"{side}_{j}"], 0] - sh[0]            # along ±X in the T-pose
            out[(side, j)] = np.array([along * np.cos(a), 0.0, -abs(along) * np.sin(a)])
    return out


def _upper_body_at_rest(pelvis, hip_left, up, H):
    """``{joint: (T, 3)}`` of :data:`UPPER_BODY_JOINTS` placed as a rest body of stature ``H``
    metres (:func:`.skeleton.make_body`) puts them about its pelvis, turned into the pelvis's frame
    (+X along ``hip_left``, the right hip to the left one; +Z ``up`` made square to it; the body faces
    -Y), the arms lowered :data:`ARM_DROP_DEG` from the T-pose about the shoulders' forward axis.
    pelvis, hip_left, up ``(T, 3)`` metres / directions, Blender axes."""
    from .skeleton import make_body
    rest = make_body(H).rest_positions()
    rel = rest - rest[J["pelvis"]]
    for (side, j), off in _hanging_arms(H).items():
        rel[J[f"{side}_{j}"]] = rel[J[f"{side}_shoulder"]] + off
    R = rot.frame_from_axes(hip_left, up, "xz")                       # (T, 3, 3), columns the axes
    return {n: pelvis + np.einsum("tij,j->ti", R, rel[J[n]]) for n in UPPER_BODY_JOINTS}


def _flat_roll(fwd):
    """``(T, 3, 3)`` frame of a foot pointing along ``fwd`` (its -Y) with no roll: +X horizontal."""
    up = np.broadcast_to([0.0, 0.0, 1.0], np.shape(fwd))
    y = -np.asarray(fwd, np.float64)
    return rot.frame_from_axes(y, np.cross(y, up), "yx")


def _trunk_up(P):
    """``(T, 3)`` unit vector from the hips' midpoint to the shoulders' midpoint."""
    mid_hip = 0.5 * (P[:, J["left_hip"]] + P[:, J["right_hip"]])
    mid_sh = 0.5 * (P[:, J["left_shoulder"]] + P[:, J["right_shoulder"]])
    return rot.normalize(mid_sh - mid_hip), mid_hip, mid_sh


def _square_to(up, line):
    """``(T, 3)`` unit: ``up`` less its component along ``line`` (``up`` itself where the two are
    parallel or ``line`` is zero)."""
    d = rot.normalize(line)
    sq = up - np.sum(up * d, -1, keepdims=True) * d
    n = np.linalg.norm(sq, axis=-1, keepdims=True)
    return np.where(n > 1e-6, sq / np.maximum(n, 1e-12), up)


def body22_from_keypoints(points, layout) -> Body22:
    """The 22 body joints (and the orientations the layout shows) from keypoints.

    points: ``(T, K, 3)`` float64 metres, Blender axes (+Z up), NaN = missing; K = the layout's
    point count.  layout: a :class:`KeypointLayout` or its name.  Missing points stay NaN in
    the joints made from them (the solve bridges gaps before this).
    """
    lay = LAYOUTS[canonical_layout(layout)] if not isinstance(layout, KeypointLayout) else layout
    X = np.asarray(points, np.float64)
    if X.ndim != 3 or X.shape[1:] != (len(lay.points), 3):
        raise ValueError(f"{lay.name} keypoints must be (T, {len(lay.points)}, 3), got {X.shape}")
    T = X.shape[0]

    def pt(name):
        return X[:, lay.index(name)]

    P = np.full((T, NUM_JOINTS, 3), np.nan)
    end_rot = {}
    pelvis_tilt = False
    if lay.name in ("smpl22", "smpl24"):
        P[:] = X[:, :NUM_JOINTS]
        return Body22(P, end_rot, ("left_wrist", "right_wrist", "head", "left_foot", "right_foot"))

    for side in ("left", "right"):
        for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"):
            P[:, J[f"{side}_{j}"]] = pt(f"{side}_{j}")
    up, mid_hip, mid_sh = _trunk_up(P)
    lower = lower_body_only(X, lay)
    if lower:
        X, _ = drop_stray_upper_body(X, lay)              # a detector's stray wrist or nose
        for side in ("left", "right"):
            for j in ("shoulder", "elbow", "wrist"):
                P[:, J[f"{side}_{j}"]] = np.nan
        _, mid_hip, mid_sh = _trunk_up(P)
        # no shoulders: the trunk stands on the world's up (made square to the hip line below,
        # so the pelvis keeps the hips' heading and sideways tilt), the body sized from the legs
        H = stature_from_legs(P)
        up = np.broadcast_to([0.0, 0.0, 1.0], up.shape)
        # pelvis markers (a marker layout's mid-ASIS and mid-PSIS): the pelvis's forward tilt too,
        # on the frames they are seen
        if all(p in lay for p in PELVIS_MARKER_POINTS):
            Rpel = pelvis_from_markers(P[:, J["left_hip"]] - P[:, J["right_hip"]], pt("mid_asis"), pt("mid_psis"))
            ok = np.isfinite(Rpel).all((-1, -2))
            if ok.any():
                up = np.where(ok[:, None], Rpel[..., 2], up)
                pelvis_tilt = True
            if ok.all():
                end_rot[J["pelvis"]] = Rpel
    else:
        # a stature estimate per take, only for the small fixed offsets below (pelvis above the
        # hips, neck above the shoulders): the median shoulder-to-hip distance / its rest fraction
        span = np.linalg.norm(mid_sh - mid_hip, axis=-1)
        trunk = np.nanmedian(span) if np.isfinite(span).any() else np.nan      # a hip or shoulder never seen
        H = trunk / (PROPORTIONS["shoulder_height"] - PROPORTIONS["hip_height"]) if np.isfinite(trunk) else 1.7
    # the pelvis above the hips' midpoint and the neck above the shoulders' along the trunk's up
    # made square to the hip line / the shoulder line: the derived joint stays equidistant from
    # the two measured ones, so the hips and shoulders fit a rigid body however the trunk bends
    up_hips = _square_to(up, P[:, J["left_hip"]] - P[:, J["right_hip"]])
    up_sh = _square_to(up, P[:, J["left_shoulder"]] - P[:, J["right_shoulder"]])
    # H36M's pelvis and OpenPose's mid-hip are the hips' midpoint, OpenPose's neck the shoulders':
    # a third measurement of the same point, averaged with the two it lies between (each
    # point's noise then counts a third); ours sit a little above them
    for name in ("pelvis", "mid_hip"):
        if name in lay:
            mid_hip = (pt(name) + 2.0 * mid_hip) / 3.0
    pelvis = mid_hip + PROPORTIONS["pelvis_above_hips"] * H * up_hips
    neck_above = (PROPORTIONS["neck_height"] - PROPORTIONS["shoulder_height"]) * H
    if "neck" in lay:
        mid_sh = (pt("neck") + 2.0 * mid_sh) / 3.0
    neck = pt("thorax") if "thorax" in lay else mid_sh + neck_above * up_sh
    P[:, J["pelvis"]] = pelvis
    P[:, J["neck"]] = neck
    if "spine" in lay:
        sp = pt("spine")
        P[:, J["spine1"]], P[:, J["spine2"]], P[:, J["spine3"]] = 0.5 * (pelvis + sp), sp, 0.5 * (sp + neck)
    else:
        for k, name in enumerate(("spine1", "spine2", "spine3"), start=1):
            P[:, J[name]] = pelvis + (neck - pelvis) * (k / 4.0)
    # collars: where the rest body puts them relative to the neck and the shoulders
    a = PROPORTIONS["collar_out"] / (0.5 * PROPORTIONS["shoulder_width"])
    b = (PROPORTIONS["collar_height"] - PROPORTIONS["neck_height"]
         - a * (PROPORTIONS["shoulder_height"] - PROPORTIONS["neck_height"])) * H
    # (from the neck above the shoulders, also where the layout measures a neck that moves
    # against the shoulders as they shrug: a collar then keeps its length)
    above_sh = mid_sh + neck_above * up_sh
    for side in ("left", "right"):
        P[:, J[f"{side}_collar"]] = above_sh + a * (P[:, J[f"{side}_shoulder"]] - above_sh) + b * up_sh
    # an arm never seen (elbow and wrist: hands cut off or hidden all take) with the shoulders
    # seen: it hangs at rest from its shoulder in the chest's frame, as a lower-body take's arms
    resting_arms = []
    if not lower:
        chest = None
        for side in ("left", "right"):
            if np.isfinite(P[:, [J[f"{side}_elbow"], J[f"{side}_wrist"]]]).all(-1).any():
                continue
            if chest is None:
                chest = rot.frame_from_axes(P[:, J["left_shoulder"]] - P[:, J["right_shoulder"]], up_sh, "xz")
                hanging = _hanging_arms(H)
            for j in ("elbow", "wrist"):
                P[:, J[f"{side}_{j}"]] = P[:, J[f"{side}_shoulder"]] + chest @ hanging[(side, j)]
            resting_arms.append(side)
    # a wrist never seen with its elbow seen (hands cut off by the frame all take, a marker set
    # without wrist markers): the forearm continues the upper arm, straight, as long as the
    # proportions make it beside the upper arm measured in the take
    straight_forearms = []
    if not lower:
        for side in ("left", "right"):
            if side in resting_arms or np.isfinite(P[:, J[f"{side}_wrist"]]).all(-1).any():
                continue
            upper = P[:, J[f"{side}_elbow"]] - P[:, J[f"{side}_shoulder"]]
            n = np.linalg.norm(upper, axis=-1)
            if not np.isfinite(n).any():
                continue
            fore = float(np.nanmedian(n)) * PROPORTIONS["forearm"] / PROPORTIONS["upper_arm"]
            with np.errstate(invalid="ignore", divide="ignore"):
                P[:, J[f"{side}_wrist"]] = P[:, J[f"{side}_elbow"]] + upper / n[:, None] * fore
            straight_forearms.append(side)

    no_twist = []
    # head: below the skull base between the ears, oriented by the face; from the head top where
    # the ears are missing (a layout with both: Halpe 26, whose ears Pose2Sim's markers leave out)
    if "head_top" in lay:
        top = pt("head_top")
        P[:, J["head"]] = neck + _HEAD_ALONG_NECK * (top - neck)
        end_rot[J["head"]] = rot.frame_from_axes(top - P[:, J["head"]], -(pt("nose") - P[:, J["head"]]), "zy")
    if "left_ear" in lay:
        ears = 0.5 * (pt("left_ear") + pt("right_ear"))
        left = pt("left_ear") - pt("right_ear")
        fwd = pt("nose") - ears
        R = rot.frame_from_axes(left, -fwd, "xy")                       # +X the head's left, +Y its back
        head = ears - _EARS_ABOVE_HEAD * H * R[..., 2]
        if "head_top" in lay:
            seen = np.isfinite(head).all(-1) & np.isfinite(R).all((-1, -2))
            head = np.where(seen[:, None], head, P[:, J["head"]])
            R = np.where(seen[:, None, None], R, end_rot[J["head"]])
        end_rot[J["head"]], P[:, J["head"]] = R, head
    if lower:
        # a lower-body take: the trunk, collars, head and arms ride on the pelvis at rest
        for name, v in _upper_body_at_rest(pelvis, P[:, J["left_hip"]] - P[:, J["right_hip"]], up_hips, H).items():
            P[:, J[name]] = v
        end_rot.pop(J["head"], None)
        no_twist.append("head")
    # no face points, or a file whose face points are never there (OpenCap's video keypoints are
    # BODY_25 without the face): the head on the trunk's up axis, untwisted
    if not np.isfinite(P[:, J["head"]]).all(-1).any():
        P[:, J["head"]] = neck + (PROPORTIONS["head_height"] - PROPORTIONS["neck_height"]) * H * up
        end_rot.pop(J["head"], None)
        no_twist.append("head")
    # hands: the palm's plane from the index and pinky knuckles (T-pose: palms down, thumbs forward)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        if f"{side}_index" in lay and f"{side}_pinky" in lay and side not in resting_arms + straight_forearms:
            w = pt(f"{side}_wrist")
            idx, pky = pt(f"{side}_index"), pt(f"{side}_pinky")
            end_rot[J[f"{side}_wrist"]] = rot.frame_from_axes(sign * (0.5 * (idx + pky) - w), -(idx - pky), "xy")
        else:
            no_twist.append(f"{side}_wrist")
    # feet: heel -> toes gives the foot's direction, big -> small toe its roll; toes or heels
    # never seen in the take (a crop above them, a marker set without them): as a layout without
    # them, flat ahead of the ankle facing the way the hips face
    hip_left = P[:, J["left_hip"]] - P[:, J["right_hip"]]

    def ever(R):
        return R is not None and bool(np.isfinite(R).all((-1, -2)).any())

    for side, sign in (("left", 1.0), ("right", -1.0)):
        ankle = P[:, J[f"{side}_ankle"]]
        R, twist = None, False
        if f"{side}_heel" in lay and f"{side}_big_toe" in lay:
            heel, big, small = pt(f"{side}_heel"), pt(f"{side}_big_toe"), pt(f"{side}_small_toe")
            R, twist = rot.frame_from_axes(-(0.5 * (big + small) - heel), sign * (small - big), "yx"), True
            if not ever(R):                                   # small toe never seen: the big toe's line
                R, twist = _flat_roll(big - heel), False
        elif f"{side}_heel" in lay and f"{side}_foot_index" in lay:
            R = _flat_roll(pt(f"{side}_foot_index") - pt(f"{side}_heel"))
        if ever(R):
            end_rot[J[f"{side}_ankle"]] = R
        else:
            R = _flat_roll(np.cross(hip_left, np.broadcast_to([0.0, 0.0, 1.0], hip_left.shape)))
        if not twist or not ever(R):
            no_twist.append(f"{side}_foot")
        P[:, J[f"{side}_foot"]] = ankle + R @ _rest_foot(H)
    return Body22(P, end_rot, tuple(no_twist), lower, pelvis_tilt, tuple(resting_arms), tuple(straight_forearms))


def _rest_foot(H):
    """``(3,)`` rest offset ankle → ball of the foot for a stature ``H`` (metres)."""
    return np.array([0.0, -PROPORTIONS["foot_forward"],
                     PROPORTIONS["foot_height"] - PROPORTIONS["ankle_height"]]) * H


def keypoints_from_body22(positions, world_rot, layout, body_stature=1.7):
    """Keypoints of ``layout`` placed on a posed 22-joint body (for fixtures and benchmarks).

    positions ``(T, 22, 3)`` metres, world_rot ``(T, 22, 3, 3)`` (body-model convention).
    Face, hand and foot points sit at fixed offsets in the head, wrist and ankle frames, sized by
    ``body_stature`` metres, chosen so that :func:`body22_from_keypoints` gives back the joints
    (exactly for the joints a layout has, and the head / wrist / ankle orientations it shows).
    Human3.6M's pelvis and OpenPose's mid-hip and neck are where those tools put them: between
    the hips, between the shoulders.
    Returns ``(T, K, 3)``.
    """
    lay = LAYOUTS[canonical_layout(layout)] if not isinstance(layout, KeypointLayout) else layout
    P = np.asarray(positions, np.float64)
    R = np.asarray(world_rot, np.float64)
    H = float(body_stature)
    T = P.shape[0]

    def at(joint, offset):
        j = J[joint]
        return P[:, j] + R[:, j] @ (np.asarray(offset, np.float64) * H)

    mid_hip = 0.5 * (P[:, J["left_hip"]] + P[:, J["right_hip"]])
    e = _EARS_ABOVE_HEAD                      # the face stands this far above the head joint
    pts = {}
    for side, sx in (("left", 1.0), ("right", -1.0)):
        for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"):
            pts[f"{side}_{j}"] = P[:, J[f"{side}_{j}"]]
        pts[f"{side}_ear"] = at("head", [sx * 0.045, 0.0, e])
        pts[f"{side}_eye"] = at("head", [sx * 0.018, -0.05, e + 0.02])
        pts[f"{side}_eye_inner"] = at("head", [sx * 0.010, -0.05, e + 0.02])
        pts[f"{side}_eye_outer"] = at("head", [sx * 0.026, -0.048, e + 0.02])
        pts[f"mouth_{side}"] = at("head", [sx * 0.014, -0.052, e - 0.03])
        pts[f"{side}_index"] = at(f"{side}_wrist", [sx * 0.055, -0.012, 0.0])
        pts[f"{side}_pinky"] = at(f"{side}_wrist", [sx * 0.055, 0.012, 0.0])
        pts[f"{side}_thumb"] = at(f"{side}_wrist", [sx * 0.03, -0.025, -0.005])
        pts[f"{side}_heel"] = at(f"{side}_ankle", [0.0, 0.03, -0.027])
        pts[f"{side}_foot_index"] = at(f"{side}_ankle", [0.0, -0.115, -0.027])
        pts[f"{side}_big_toe"] = at(f"{side}_ankle", [-sx * 0.015, -0.11, -0.027])
        pts[f"{side}_small_toe"] = at(f"{side}_ankle", [sx * 0.015, -0.10, -0.027])
        pts[f"{side}_hand"] = at(f"{side}_wrist", [sx * 0.05, 0.0, 0.0])
    pts["nose"] = at("head", [0.0, -0.06, e])
    # the pelvis markers' midpoints: the mid-ASIS 0.09 statures ahead of the mid-PSIS, the line
    # between them tilted PELVIS_NEUTRAL_TILT_DEG forwards in the pelvis's frame (its neutral)
    tilt = np.radians(PELVIS_NEUTRAL_TILT_DEG)
    psis = np.array([0.0, 0.045, 0.02])
    pts["mid_psis"] = at("pelvis", psis)
    pts["mid_asis"] = at("pelvis", psis + 0.09 * np.array([0.0, -np.cos(tilt), -np.sin(tilt)]))
    pts["head_top"] = P[:, J["neck"]] + (P[:, J["head"]] - P[:, J["neck"]]) / _HEAD_ALONG_NECK
    pts["thorax"] = P[:, J["neck"]]
    pts["spine"] = P[:, J["spine2"]]
    mid_sh = 0.5 * (P[:, J["left_shoulder"]] + P[:, J["right_shoulder"]])
    pts["pelvis"] = mid_hip                   # Human3.6M's pelvis and OpenPose's mid-hip: between the hips
    pts["mid_hip"] = mid_hip
    pts["neck"] = mid_sh                      # OpenPose's neck: between the shoulders
    for name in ("spine1", "spine2", "spine3", "left_collar", "right_collar", "head", "left_foot", "right_foot"):
        pts[name] = P[:, J[name]]
    if lay.name in ("smpl22", "smpl24"):
        pts["pelvis"], pts["neck"] = P[:, J["pelvis"]], P[:, J["neck"]]
    return np.stack([pts[p] for p in lay.points], axis=1).reshape(T, len(lay.points), 3)
