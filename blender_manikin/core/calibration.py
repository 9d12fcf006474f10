"""Body size and device rotation offsets from a T-pose (or A-pose) moment.

Never imports bpy.

In the style of SparsePoser's walk-in calibration (Ponton et al. 2023,
after Walk-In-Avatar, Ponton et al. 2022): the performer stands still in a
T-pose (or A-pose) for a moment; from the joint targets averaged over a short
window (default ±0.25 s) we measure

* stature ``H`` = (head joint height - sole) / 0.870 (the body model puts
  its head joint, the top of the neck, at 0.870 H, :data:`.skeleton.PROPORTIONS`,
  standing on shoe soles :data:`.skeleton.SOLE` = 3 cm thick unless the
  measurements give ``sole``); from a raw HMD eye height use
  :func:`stature_from_eye_height`, eyes at ~0.936 H;
* arm span (wrist to wrist, what :class:`.skeleton.BodyMeasurements` calls
  ``arm_span``): the shoulder breadth (0.209 H) plus both shoulder-to-wrist
  distances, the shoulders placed 0.870 H - 0.818 H below the head joint, in
  a T-pose as in an A-pose (a level T-pose's wrist distance; arms held a
  little low do not shorten it);
* the constant rotation between each device and its joint: in the pose the
  joint orientation is known - head, pelvis and ankles face the body heading
  (identity rotated by the heading yaw), a wrist's rest orientation (hand
  along the arm, palm down) swung to the measured arm direction (for a
  T-pose that is the heading itself; for an A-pose the arm tilted down) - so
  the device's offset rotation becomes ``device_rotᵀ @ expected_joint_rot``.

The heading is the horizontal line from the right to the left wrist (the
performer's left is +X at heading 0, facing -Y).  Checks report when the
moment is not plausibly a still T/A-pose (:attr:`CalibrationResult.problems`).

Six trackers (pelvis and feet, as in SparsePoser)
-------------------------------------------------

Extra trackers are strapped on at any rotation and some centimetres from
their joints, so their whole offset (translation *and* rotation) is measured
from the pose: the body model's rest T-pose (:meth:`.skeleton.Body.rest_positions`,
built from the measurements, soles on z = 0) is stood under the head joint
target, turned by the heading; that gives the expected pelvis and ankle
positions, and with the raw device pose (the targets with the current offsets
removed) ``offset_pos = R_deviceᵀ (p_joint - p_device)`` and
``offset_rot = R_deviceᵀ R_joint`` (:mod:`.device_offsets` convention).
Typed offsets win: an extra device whose entry in ``offsets`` is not the
identity (see :func:`typed_tracker_offsets`) keeps it, and the result only
reports how far the pose disagrees.  Head and controller offsets are handled
as before (rotations refined, positions kept).

What one still pose can and cannot tell (identifiability): a tracker's
position is all that is observed, so each joint position needs an
assumption, and whatever deviates from it ends up in the offset:

* *ankles*: the feet stand like the body model's: under the hips (ankle
  centres ``hip_width`` = 0.100 H apart), straight below the head joint
  front-to-back, at the model's ankle height 0.039 H + sole, flat and pointing along
  the heading.  Ankle height, stance width and toe-out are therefore not
  measured (a tracker 8 cm above the ankle looks exactly like an ankle 8 cm
  higher); feet set wider than the hips shift the foot offsets inward by the
  excess.  A foot that is higher or tilted at the calibration moment than
  when it is stood on later in the recording is reported (a lifted foot).
* *pelvis*: horizontally below the head joint (upright stance).  Its height
  and the legs' length trade off exactly (a tracker 5 cm above the pelvis
  joint is indistinguishable from legs 5 cm longer), so one of them must be
  given.  Here: with a typed pelvis offset the pelvis joint height follows
  from it; otherwise the tracker is assumed level with the pelvis joint
  (:data:`PELVIS_TRACKER_ABOVE_JOINT`, 0 m: a tracker at the back of the
  pelvis, e.g. on a belt over the sacrum), its horizontal offset is measured
  and the pelvis height is the tracker's height.  Either way the hip height
  is the pelvis joint height - 0.030 H (:data:`.skeleton.PROPORTIONS`
  ``pelvis_above_hips``), the leg (hip to ankle) that minus the ankle height,
  split into thigh and shank as the proportions do (0.245 : 0.246), and put
  into :class:`.skeleton.BodyMeasurements` so the legs are measured, not
  proportional.  A hip height far from the proportions (more than
  :data:`HIP_HEIGHT_NOTE` H) is reported: a tracker worn higher (at the waist)
  makes the legs that much too long unless its offset is typed; beyond
  :data:`HIP_HEIGHT_LIMIT` H the proportional legs are kept.  Without a
  pelvis tracker the legs stay proportional.

Targets in, offsets out: ``targets`` must have been made with ``offsets``
(:func:`.device_offsets.to_targets`); the result holds updated offsets: the
head's and hands' positions unchanged and their rotations corrected, the
extra trackers' measured (or typed, kept).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .device_offsets import JOINT_OF_DEVICE, validate_offsets
from .plain import shown
from .devices import EXTRA_DEVICES, HAND_DEVICES, REQUIRED_DEVICES
from .pose_result import TrackerTargets
from .rotations import geodesic_angle, matrix_to_quat, normalize, orthonormalize, quat_to_matrix, rotation_between
from .skeleton import J, PROPORTIONS, SOLE, BodyMeasurements, make_body, sole_or_default

#: eye (HMD) height as a fraction of stature (Drillis & Contini, Winter 2009 Fig. 4.1)
EYE_HEIGHT = PROPORTIONS["eye_height"]
HEAD_HEIGHT = PROPORTIONS["head_height"]
SHOULDER_HEIGHT = PROPORTIONS["shoulder_height"]
SHOULDER_WIDTH = PROPORTIONS["shoulder_width"]
ARM_LENGTH = PROPORTIONS["upper_arm"] + PROPORTIONS["forearm"]     # shoulder to wrist, fraction of H
TPOSE_WRIST_DISTANCE = SHOULDER_WIDTH + 2 * ARM_LENGTH             # 0.873 H
#: statures (m) the head height of a T-pose candidate may imply (:func:`find_tpose`): a head
#: lower than a 1.0 m performer's is someone crouching, kneeling or lying with the arms out
#: (HDM05's lie-down takes: arms spread on the floor, the head 9 cm up, once passed as a T-pose
#: of a 7 cm performer and failed the solve), or a floor that is not at 0
TPOSE_STATURE_RANGE = (1.0, 2.5)
#: wrist distance / the expected T-pose wrist distance (:data:`TPOSE_WRIST_DISTANCE` of the
#: stature the head height implies) a plausible T-pose keeps within (the body model's T-pose
#: reads 1.0, the Bandai-like and the five HDM05 skeletons' 0.85-0.93; crouching with the arms
#: out, the head 0.6 m lower, 1.65)
TPOSE_SPAN_RATIO = (0.8, 1.25)

_Z = np.array([0.0, 0.0, 1.0])

#: metres the pelvis tracker is assumed to sit above the pelvis joint in the calibration pose
#: (world vertical) when its offset is not typed; see the module docstring (identifiability)
PELVIS_TRACKER_ABOVE_JOINT = 0.0
#: hip height (fraction of stature) the proportions give: ankle height + shank + thigh
PROPORTIONAL_HIP_HEIGHT = PROPORTIONS["ankle_height"] + PROPORTIONS["shank"] + PROPORTIONS["thigh"]
#: a measured hip height further than this (fraction of stature) from the proportions is reported
#: (adult hip height / stature varies by about ±0.03, two standard deviations)
HIP_HEIGHT_NOTE = 0.04
#: ... and further than this is not used (the proportional legs are kept)
HIP_HEIGHT_LIMIT = 0.08
#: metres: a measured extra-tracker offset longer than this is reported (straps put trackers
#: 5-15 cm from the joints; further means the pose or the tracker is not what it should be)
MAX_TRACKER_OFFSET = 0.25
#: metres a foot tracker may stand higher at the calibration moment than it does when the foot is
#: stood on later in the recording (its 5th-percentile height), before the foot counts as lifted
FOOT_LIFT_TOLERANCE = 0.03
#: degrees a foot tracker may be tilted at the calibration moment relative to its tilt when stood on
FOOT_TILT_TOLERANCE = 15.0


class CalibrationError(ValueError):
    """Raised by :func:`calibrate` with ``strict=True`` when the pose is implausible."""


def stature_from_head_height(z, sole=SOLE):
    """Barefoot stature (m) from the head joint (top of the neck) height above the floor (m) of a
    performer standing on ``sole`` metres of shoe sole."""
    return (float(z) - float(sole)) / HEAD_HEIGHT


def stature_from_eye_height(z, sole=SOLE):
    """Barefoot stature (m) from the HMD (eye) height above the floor (m) of a performer standing
    on ``sole`` metres of shoe sole."""
    return (float(z) - float(sole)) / EYE_HEIGHT


def _sole_of(measurements):
    """The soles' thickness (m) ``measurements`` (a :class:`BodyMeasurements`, a dict or None)
    give, :data:`.skeleton.SOLE` when they do not."""
    if isinstance(measurements, BodyMeasurements):
        return measurements.sole_height
    return sole_or_default(measurements.get("sole") if isinstance(measurements, dict) else None)


#: statures (metres) outside which the solve summary warns (see :func:`stature_warning`)
PLAUSIBLE_STATURE = (1.40, 2.10)


def stature_warning(stature, head_height, sized_by, units="m", plausible=PLAUSIBLE_STATURE):
    """A note for the solve summary when ``stature`` (metres) is outside ``plausible``, naming
    the likely cause; ``None`` when it is plausible.

    head_height: the standing head height above the recording's floor (metres, as read).
    sized_by: ``"height setting"`` (typed by the user), ``"T-pose"`` or ``"head height"``.
    units: the units the positions were read in.  Likely causes: a typed height; positions in
    other units than read (a factor of 100 or 1000 would make the stature plausible); a floor
    that is not at height 0 (a tracking origin at eye level or on a desk makes the body too
    small, one below the floor too big; the solve's ``floor`` setting moves it); a body sized
    by the head height of a seated performer is too small."""
    lo, hi = plausible
    s = float(stature)
    if lo <= s <= hi:
        return None
    text = f"estimated stature {s:.2f} m is outside {lo:.2f}-{hi:.2f} m: "
    if sized_by == "height setting":
        return text + f"check the height setting ({s:.2f} m)"
    causes = []
    scale = {"m": 1.0, "cm": 0.01, "mm": 0.001}.get(units, 1.0)
    for name, factor in (("cm", 0.01), ("mm", 0.001), ("m", 1.0)):
        k = factor / scale
        if name != units and lo <= s * k <= hi:
            causes.append(f"the units (read as {units}; in {name} the stature would be {s * k:.2f} m: "
                          f"--units {name})")
    causes.append(f"the floor (the head stands {float(head_height):.2f} m above height 0; set the Floor, "
                  "--floor, to the floor's height, or to 'height' to put it under a performer of the typed height)")
    if s < lo and sized_by == "head height":
        causes.append("whether the performer sits (set the Posture, --posture, to seated)")
    causes.append("or set the performer's height")
    return text + "check " + ", ".join(causes)


@dataclass
class CalibrationResult:
    """What :func:`calibrate` measured.

    measurements: the :class:`BodyMeasurements` to build the body with
    (measured, or passed through).  offsets: updated device offsets (plain
    dict, see :mod:`.device_offsets`).  time/frame: the calibration moment.
    pose: ``'T'`` or ``'A'`` (as classified or requested).  arm_angle_deg:
    mean arm elevation below horizontal.  heading_deg: body yaw, 0 = facing
    -Y, positive = turned counter-clockwise seen from above.
    rotation_change_deg: device → angle of the rotation correction (0 for a
    typed extra-tracker offset, which is kept).
    tracker_offsets: extra device (pelvis, feet) → what became of its offset:
    ``source`` (``"T-pose"``: measured, or ``"typed"``: kept), ``distance``
    (m, length of the position offset) and ``angle_deg`` (of the rotation
    offset), ``pos`` (m, device frame) and ``rot`` (wxyz); for a typed one
    also ``disagree_m`` / ``disagree_deg``, how far the offset the pose
    implies is from it.
    measured: raw numbers (head height, wrist distance, stature and arm span
    as measured, per-device motion; ``legs``: ``source`` (``"pelvis
    tracker"``, ``"typed pelvis offset"`` or ``"proportions"``), and when
    measured ``pelvis_height``, ``hip_height``, ``leg_length`` (hip to ankle),
    ``thigh``, ``shank`` in metres and ``used`` (False when implausible)).
    problems: reasons the moment does not look like a still T/A-pose, or the
    trackers not like worn as assumed (empty = plausible).
    """
    measurements: BodyMeasurements
    offsets: dict
    time: float
    frame: int
    pose: str
    arm_angle_deg: float
    heading_deg: float
    rotation_change_deg: dict = field(default_factory=dict)
    measured: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    tracker_offsets: dict = field(default_factory=dict)

    @property
    def plausible(self) -> bool:
        return not self.problems


@dataclass
class TPoseCandidate:
    """The most T-pose-like moment found by :func:`find_tpose`.

    time (s, recording clock) and frame; cost (lower is better; ~0 for a
    perfect still T-pose); plausible: passes loose T-pose thresholds;
    span_ratio: wrist distance / expected T-pose wrist distance (0.873 H);
    height_error: mean |hand height - shoulder height| (m); speed: mean hand
    speed (m/s), all averaged over the window.
    """
    time: float
    frame: int
    cost: float
    plausible: bool
    span_ratio: float
    height_error: float
    speed: float


def _window_mean(x, w):
    """Centred moving average over ``2w+1`` samples along axis 0 (shrinks at the ends)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)], 0)
    i = np.arange(n)
    lo = np.clip(i - w, 0, n)
    hi = np.clip(i + w + 1, 0, n)
    cnt = (hi - lo).reshape((-1,) + (1,) * (x.ndim - 1))
    return (c[hi] - c[lo]) / cnt


def find_tpose(targets: TrackerTargets, window=0.25, t0=0.0) -> TPoseCandidate:
    """Propose the most T-pose-like moment: hands far apart at shoulder height, still, and the
    head as high as a standing performer's (:data:`TPOSE_STATURE_RANGE`; the floor at z = 0).

    targets: joint targets (head, left_hand, right_hand needed).  window:
    half-width in seconds over which the pose must hold.  t0: time of frame
    0 (seconds).  Vectorised over frames.
    """
    head, wl, wr, H, usable = _pose_frames(targets, "find_tpose")
    shoulder_z = head[:, 2] - (HEAD_HEIGHT - SHOULDER_HEIGHT) * H
    span_ratio = np.linalg.norm(wl - wr, axis=-1) / (TPOSE_WRIST_DISTANCE * H)
    height_err = 0.5 * (np.abs(wl[:, 2] - shoulder_z) + np.abs(wr[:, 2] - shoulder_z))
    return _still_pose(targets, span_ratio, height_err, H, usable, window, t0, max_height_error=0.12)


def _pose_frames(targets: TrackerTargets, who):
    """``(head, left hand, right hand (T, 3), H (T,), usable (T,) bool)`` for :func:`find_tpose` /
    :func:`find_apose`: the targets, the stature the head's height gives (at least 0.3 m) and the
    frames every device is tracked on with the head as high as a standing performer's
    (:data:`TPOSE_STATURE_RANGE`)."""
    for d in REQUIRED_DEVICES:
        if d not in targets.pos:
            raise ValueError(f"{who} needs {d} targets")
    ok = np.ones(targets.num_frames, dtype=bool)
    for d in REQUIRED_DEVICES:
        v = targets.valid.get(d)
        if v is not None:
            ok &= np.asarray(v, dtype=bool)
    head, wl, wr = (np.asarray(targets.pos[d], np.float64) for d in REQUIRED_DEVICES)
    H_head = (head[:, 2] - SOLE) / HEAD_HEIGHT
    standing = (H_head >= TPOSE_STATURE_RANGE[0]) & (H_head <= TPOSE_STATURE_RANGE[1])
    return head, wl, wr, np.maximum(H_head, 0.3), ok & standing


def _still_pose(targets, span_ratio, height_err, H, usable, window, t0, max_height_error) -> TPoseCandidate:
    """The candidate of the least cost (the span ratio off 1, the height error, the hands' speed)
    held over ``window`` seconds either side, among ``usable`` frames; plausible when the span
    ratio is in :data:`TPOSE_SPAN_RATIO`, the height error under ``max_height_error`` metres and the
    hands slower than 0.3 m/s.  A plausible moment where the recording's pelvis and foot trackers
    are tracked too is preferred (their offsets are measured there; where one is lost it is not),
    else the best of all ``usable`` frames."""
    extra = [d for d in EXTRA_DEVICES if d in targets.pos and targets.valid.get(d) is not None]
    if extra:
        tracked = np.logical_and.reduce([np.asarray(targets.valid[d], dtype=bool) for d in extra])
        if (usable & ~tracked).any() and (usable & tracked).any():
            cand = _still_pose_among(targets, span_ratio, height_err, H, usable & tracked, window, t0,
                                     max_height_error)
            if cand.plausible:
                return cand
    return _still_pose_among(targets, span_ratio, height_err, H, usable, window, t0, max_height_error)


def _still_pose_among(targets, span_ratio, height_err, H, usable, window, t0, max_height_error) -> TPoseCandidate:
    fps = float(targets.fps)
    n = targets.num_frames
    w = max(1, int(round(window * fps)))
    wl, wr = (np.asarray(targets.pos[d], np.float64) for d in ("left_hand", "right_hand"))
    speed = np.zeros(n)
    if n > 1:
        speed[1:] = (np.linalg.norm(np.diff(wl, axis=0), axis=-1)
                     + np.linalg.norm(np.diff(wr, axis=0), axis=-1)) * fps / 2
        speed[0] = speed[1]
    cost = np.abs(1.0 - span_ratio) + 3.0 * height_err / H + 0.5 * speed
    cost = np.where(usable & np.isfinite(cost), cost, 1e3)
    mc = _window_mean(cost, w)
    k = int(np.argmin(mc))
    sr = float(_window_mean(span_ratio, w)[k])
    he = float(_window_mean(height_err, w)[k])
    sp = float(_window_mean(speed, w)[k])
    lo, hi = TPOSE_SPAN_RATIO
    plausible = bool(mc[k] < 1e2 and lo < sr < hi and he < max_height_error and sp < 0.3)
    return TPoseCandidate(time=float(t0 + k / fps), frame=k, cost=float(mc[k]), plausible=plausible,
                          span_ratio=sr, height_error=he, speed=sp)


#: arm elevations (degrees below horizontal) :func:`find_apose` takes: a T-pose held low to an
#: A-pose (relaxed arms hang 70-90°)
APOSE_ELEVATION = (-20.0, 60.0)
#: degrees an arm may point forward or back of the hands' line in :func:`find_apose`
APOSE_SWING = 30.0


def find_apose(targets: TrackerTargets, window=0.25, t0=0.0) -> TPoseCandidate:
    """Propose the most still T- or A-pose-like moment by the arms, for poses :func:`find_tpose`
    does not take (it wants the hands at shoulder height: arms more than about 12° low miss it).

    Each arm is measured from where the head puts its shoulder (as :func:`calibrate` does): its
    reach (the span ratio is the shoulders' width plus both reaches over the expected wrist
    distance, :data:`TPOSE_WRIST_DISTANCE` of the stature), its elevation within
    :data:`APOSE_ELEVATION` and its swing within :data:`APOSE_SWING`; ``height_error`` is how far
    (m) the hands are outside those bounds.  The head must stand as a standing performer's, the
    hands still.  Same fields as :func:`find_tpose`."""
    head, wl, wr, H, usable = _pose_frames(targets, "find_apose")
    lat = (wl - wr) * [1.0, 1.0, 0.0]
    u = lat / np.maximum(np.linalg.norm(lat, axis=-1, keepdims=True), 1e-9)
    fwd = np.cross(_Z, u)
    centre = head + u * np.sum((0.5 * (wl + wr) - head) * u, -1, keepdims=True)
    centre[:, 2] = head[:, 2] - (HEAD_HEIGHT - SHOULDER_HEIGHT) * H
    half = 0.5 * SHOULDER_WIDTH * H[:, None]
    reach, err = [], []
    for wrist, s in ((wl, 1.0), (wr, -1.0)):
        a = wrist - (centre + s * u * half)
        out = s * np.sum(a * u, -1)
        ahead = np.abs(np.sum(a * fwd, -1))
        L = np.linalg.norm(a, axis=-1)
        elev = np.degrees(np.arctan2(-a[:, 2], np.maximum(out, 1e-9)))
        beyond = np.maximum(elev - APOSE_ELEVATION[1], 0.0) + np.maximum(APOSE_ELEVATION[0] - elev, 0.0)
        err.append(L * np.sin(np.radians(np.minimum(beyond, 90.0)))
                   + np.maximum(ahead - np.tan(np.radians(APOSE_SWING)) * np.maximum(out, 0.0), 0.0))
        reach.append(L)
    span_ratio = (SHOULDER_WIDTH * H + reach[0] + reach[1]) / (TPOSE_WRIST_DISTANCE * H)
    height_err = 0.5 * (err[0] + err[1])
    return _still_pose(targets, span_ratio, height_err, H, usable, window, t0, max_height_error=0.03)


def _heading_matrix(x_axis):
    x = normalize(np.array([x_axis[0], x_axis[1], 0.0]))
    y = np.cross(_Z, x)
    return np.stack([x, y, _Z], axis=-1)


def _yaw_deg(R):
    return float(np.degrees(np.arctan2(R[1, 0], R[0, 0])))


def _wrap_deg(a):
    return float((a + 180.0) % 360.0 - 180.0)


def _is_identity(entry, tol=1e-9):
    q = np.asarray(entry.get("rot", [1.0, 0.0, 0.0, 0.0]), dtype=np.float64)
    return bool(np.linalg.norm(entry.get("pos", [0.0, 0.0, 0.0])) <= tol and abs(abs(q[0]) - 1.0) <= tol)


def typed_tracker_offsets(offsets) -> tuple:
    """The extra devices (pelvis, feet) whose offsets in ``offsets`` were typed and are kept.

    offsets: any form :func:`.device_offsets.validate_offsets` accepts.  An entry counts as typed
    when it is present and not the identity (position 0 and rotation identity); the presets have
    identity entries for these devices, so with a preset (or none) every extra tracker is measured
    from the calibration pose.  (A tracker truly at its joint cannot be told apart from "not
    given": it is measured, which gives the same offset.)  Returns device names in
    :data:`.devices.EXTRA_DEVICES` order.
    """
    devs = validate_offsets(offsets)["devices"]
    return tuple(d for d in EXTRA_DEVICES if d in devs and not _is_identity(devs[d]))


def _legs_from_pelvis_height(pelvis_z, stature, sole=SOLE):
    """Leg measurements (metres) from the pelvis joint height ``pelvis_z`` above the floor (m) of a
    performer standing on ``sole`` metres of shoe sole.

    hip height = pelvis height - ``pelvis_above_hips`` H; leg (hip to ankle) = hip height - ankle
    height (0.039 H, the body model's, + the sole); thigh : shank as the proportions (0.245 : 0.246).
    Returns a dict of ``pelvis_height``, ``hip_height`` (above the floor), ``leg_length``,
    ``thigh``, ``shank``."""
    H = float(stature)
    hip = float(pelvis_z) - PROPORTIONS["pelvis_above_hips"] * H
    leg = hip - PROPORTIONS["ankle_height"] * H - float(sole)
    k = PROPORTIONS["thigh"] / (PROPORTIONS["thigh"] + PROPORTIONS["shank"])
    return dict(pelvis_height=float(pelvis_z), hip_height=hip, leg_length=leg, thigh=leg * k, shank=leg * (1 - k))


def _foot_stance(targets, device, z_cal, R_cal):
    """How much higher (m) and more tilted (degrees) ``device`` is at the calibration moment than
    when it is stood on later (its lowest 5 % of valid frames): ``(lift, tilt)``, or ``None`` with
    fewer than 10 valid frames.  z_cal: its target height at the moment; R_cal: its orientation.
    The tilt compares the direction that is up in the tracker at the moment with the vertical on
    the low frames, so it does not depend on the device's offset."""
    z = np.asarray(targets.pos[device][:, 2], dtype=np.float64)
    R = np.asarray(targets.rot[device], dtype=np.float64)
    v = targets.valid.get(device)
    ok = np.isfinite(z) & np.all(np.isfinite(R), (-1, -2))
    if v is not None:
        ok &= np.asarray(v, dtype=bool)
    if ok.sum() < 10:
        return None
    low = float(np.percentile(z[ok], 5))
    near = ok & (z <= low + 0.01)
    up = R_cal.T @ _Z                                   # the tracker's up at the calibration moment
    cos = np.clip(np.einsum("tij,j->ti", R[near], up)[:, 2], -1.0, 1.0)
    return float(z_cal - low), float(np.degrees(np.median(np.arccos(cos))))


_TRACKER_LABEL = {"pelvis": "pelvis", "left_foot": "left foot", "right_foot": "right foot"}


def calibrate(targets: TrackerTargets, time=None, offsets=None, window=0.25, pose="auto",
              measurements=None, t0=0.0, frame=None, strict=False) -> CalibrationResult:
    """Measure body size and device offsets at a T/A-pose moment.

    targets: joint targets made with ``offsets`` (head, left_hand,
    right_hand required; pelvis/feet used when present).
    time: calibration moment in seconds (recording clock, frame ``k`` at
    ``t0 + k / fps``); or give ``frame``; default: :func:`find_tpose`.
    offsets: the offsets ``targets`` were made with (any form
    :func:`.device_offsets.validate_offsets` accepts; default none).  Head
    and hands: their rotations are refined, positions kept.  Pelvis and
    feet: measured whole (position and rotation) from the pose, unless typed
    (a non-identity entry, :func:`typed_tracker_offsets`), which is kept.
    window: half-width (s) of the averaging window.
    pose: ``'auto'`` (classify by arm elevation: < 20° T, 20-65° A), ``'T'``
    or ``'A'``.
    measurements: explicit body measurements: a :class:`BodyMeasurements` is
    passed through unchanged; a dict overrides only the given fields of the
    measured ones (e.g. ``{"stature": 1.80}``, or ``thigh``/``shank``, which
    then also fix where the pelvis is and so the pelvis tracker's height offset).
    With a pelvis tracker the legs (``thigh``, ``shank``, metres) are measured
    from its height (module docstring: identifiability), else proportional.
    strict: raise :class:`CalibrationError` when problems were found.
    """
    for d in REQUIRED_DEVICES:
        if d not in targets.pos:
            raise ValueError(f"calibration needs {d} targets")
    fps = float(targets.fps)
    n = targets.num_frames
    if frame is None:
        if time is None:
            frame = find_tpose(targets, window=window, t0=t0).frame
        else:
            frame = int(round((float(time) - t0) * fps))
    frame = int(frame)
    if not 0 <= frame < n:
        raise ValueError(f"calibration time {t0 + frame / fps:.3f} s is outside the recording "
                         f"({t0:.3f}-{t0 + (n - 1) / fps:.3f} s)")
    time = float(t0 + frame / fps)
    w = max(0, int(round(window * fps)))
    sl = slice(max(0, frame - w), min(n, frame + w + 1))
    problems = []
    new = validate_offsets(offsets)
    typed = typed_tracker_offsets(new)

    # --- average each device over the window (and, for the extra trackers, the raw device poses:
    # the targets were made with the current offsets, joint = device ∘ offset)
    mean_pos, mean_rot, motion, dev_pos = {}, {}, {}, {}
    for d in targets.devices:
        P = targets.pos[d][sl]
        R = targets.rot[d][sl]
        v = targets.valid.get(d)
        m = np.ones(P.shape[0], dtype=bool) if v is None else np.asarray(v, dtype=bool)[sl]
        m &= np.all(np.isfinite(P), -1) & np.all(np.isfinite(R), (-1, -2))
        if m.sum() == 0:
            if d not in EXTRA_DEVICES:
                problems.append(f"{d} is not tracked at {time:.2f} s")
                continue
            text = f"the {_TRACKER_LABEL[d]} tracker is not tracked at {time:.2f} s: "
            if d in typed:
                text += "its typed offset is kept unchecked"
            else:
                text += (f"its offset cannot be measured (the tracker's own pose would be taken as the "
                         f"{JOINT_OF_DEVICE[d]}'s): calibrate where it is tracked or type its offset")
            if d == "pelvis":
                text += "; the legs stay proportional"
            problems.append(text)
            continue
        if m.mean() < 0.5:
            problems.append(f"{d} lost tracking for {100 * (1 - m.mean()):.0f}% of the calibration window")
        P, R = P[m], R[m]
        mean_pos[d] = P.mean(0)
        mean_rot[d] = orthonormalize(R.mean(0))
        if d in EXTRA_DEVICES:
            e = new["devices"].get(d, {"pos": [0.0, 0.0, 0.0], "rot": [1.0, 0.0, 0.0, 0.0]})
            R_dev = R @ quat_to_matrix(np.asarray(e["rot"])).T
            dev_pos[d] = (P - R_dev @ np.asarray(e["pos"], dtype=np.float64)).mean(0)
        moved = float(np.linalg.norm(P.max(0) - P.min(0)))
        turned = float(np.degrees(geodesic_angle(mean_rot[d][None], R).max()))
        motion[d] = (moved, turned)
        if moved > 0.05:
            problems.append(f"{d} moved {100 * moved:.0f} cm during the calibration window "
                            f"(±{window:g} s at {time:.2f} s): hold still")
        elif turned > 10.0:
            problems.append(f"{d} turned {turned:.0f}° during the calibration window: hold still")
    for d in REQUIRED_DEVICES:
        if d not in mean_pos:
            raise CalibrationError(f"cannot calibrate at {time:.2f} s: {d} is not tracked there")

    head = mean_pos["head"]
    wl, wr = mean_pos["left_hand"], mean_pos["right_hand"]
    sole = _sole_of(measurements)
    H_meas = stature_from_head_height(head[2], sole)
    H = H_meas
    if isinstance(measurements, BodyMeasurements):
        H = float(measurements.stature)
    elif isinstance(measurements, dict) and measurements.get("stature") is not None:
        H = float(measurements["stature"])
    if not 1.0 <= H_meas <= 2.3:
        problems.append(f"head joint is {head[2]:.2f} m above the floor, i.e. a stature of {H_meas:.2f} m: "
                        f"not a standing adult (check units and floor height)")

    # --- heading from the wrist line; compare with the head
    lateral = wl - wr
    lat_h = np.hypot(lateral[0], lateral[1])
    head_y = mean_rot["head"][:, 1]
    head_x = np.cross(head_y, _Z)
    head_heading = _heading_matrix(head_x) if np.hypot(head_x[0], head_x[1]) > 1e-6 else np.eye(3)
    if lat_h > 0.2:
        Rh = _heading_matrix(lateral)
    else:
        Rh = head_heading
        problems.append(f"hands are only {lat_h:.2f} m apart horizontally: stretch the arms out sideways")
    heading = _yaw_deg(Rh)
    head_turn = _wrap_deg(_yaw_deg(head_heading) - heading)
    if abs(head_turn) > 25.0:
        problems.append(f"the head faces {abs(head_turn):.0f}° away from the direction the arms' line "
                        f"implies: look straight ahead (or are the hands swapped?)")
    if lat_h > 0.2 and lat_h < 0.45 * H:
        problems.append(f"hands are only {lat_h:.2f} m apart (expected about {TPOSE_WRIST_DISTANCE * H:.2f} m "
                        f"in a T-pose): stretch the arms out sideways")
    if abs(wl[2] - wr[2]) > 0.15:
        problems.append(f"hands are at different heights ({wl[2]:.2f} m and {wr[2]:.2f} m)")

    # --- shoulders and arm directions in the heading frame
    centre = head + Rh[:, 0] * float(np.dot(0.5 * (wl + wr) - head, Rh[:, 0]))
    sz = head[2] - (HEAD_HEIGHT - SHOULDER_HEIGHT) * H
    sw = SHOULDER_WIDTH * H
    if isinstance(measurements, BodyMeasurements) and measurements.shoulder_width is not None:
        sw = float(measurements.shoulder_width)
    s_l = np.array([centre[0], centre[1], sz]) + Rh[:, 0] * sw / 2
    s_r = np.array([centre[0], centre[1], sz]) - Rh[:, 0] * sw / 2
    a_l = Rh.T @ (wl - s_l)
    a_r = Rh.T @ (wr - s_r)
    angles = {}
    for side, a, sgn in (("left", a_l, 1.0), ("right", a_r, -1.0)):
        horiz = np.hypot(a[0], a[1])
        elev = float(np.degrees(np.arctan2(-a[2], horiz)))          # below horizontal
        swing = float(np.degrees(np.arctan2(-a[1], sgn * a[0])))    # forward of the body line
        angles[side] = (elev, swing)
        L = float(np.linalg.norm(a))
        if L < 0.75 * ARM_LENGTH * H:
            problems.append(f"{side} hand is only {L:.2f} m from the shoulder (arm about "
                            f"{ARM_LENGTH * H:.2f} m): stretch the arm")
        if abs(swing) > 30.0:
            problems.append(f"{side} arm points {abs(swing):.0f}° {'forward' if swing > 0 else 'backward'} "
                            f"of the shoulder line: hold the arms out to the sides")
    arm_angle = 0.5 * (angles["left"][0] + angles["right"][0])

    pose_in = str(pose).strip().upper()
    if pose_in == "AUTO":
        if arm_angle < 20.0:
            kind = "T"
        elif arm_angle <= 65.0:
            kind = "A"
        else:
            kind = "A"
            problems.append(f"arms are {arm_angle:.0f}° below horizontal: not a T-pose or A-pose")
    elif pose_in in ("T", "A"):
        kind = pose_in
        if kind == "T" and abs(arm_angle) > 20.0:
            problems.append(f"arms are {arm_angle:.0f}° below horizontal: not a T-pose "
                            f"(hands should be at shoulder height, about {sz:.2f} m)")
        if kind == "A" and not 15.0 <= arm_angle <= 65.0:
            problems.append(f"arms are {arm_angle:.0f}° below horizontal: not an A-pose (15-65°)")
    else:
        raise ValueError(f"pose must be 'auto', 'T' or 'A', got {shown(pose)}")
    if arm_angle < -20.0:
        problems.append(f"hands are {-arm_angle:.0f}° above shoulder height")

    # --- measurements: the span is the shoulders' width plus each arm's reach from its shoulder,
    # in a T-pose as in an A-pose.  A level T-pose gives the wrists' distance (their line passes
    # through the shoulders); one with the arms a little below horizontal (a T-pose up to 20°)
    # gives the same span, where the wrists' distance alone came out short: 1.8 / 4.0 / 6.3 cm
    # for a 1.75 m performer at 10 / 15 / 19° (tests/test_calibration.py)
    wrist_distance = float(np.linalg.norm(wl - wr))
    span = float(sw + np.linalg.norm(a_l) + np.linalg.norm(a_r))
    # legs from the pelvis tracker (see the module docstring: its height and the legs' length trade
    # off; with a typed offset the target is the joint, else the tracker is taken level with it)
    legs = {"source": "proportions"}
    if "pelvis" in mean_pos:
        from_typed = "pelvis" in typed
        z_pelvis = float(mean_pos["pelvis"][2]) if from_typed else \
            float(dev_pos["pelvis"][2]) - PELVIS_TRACKER_ABOVE_JOINT
        legs = {"source": "typed pelvis offset" if from_typed else "pelvis tracker",
                **_legs_from_pelvis_height(z_pelvis, H, sole)}
        dev = (legs["hip_height"] - sole) / H - PROPORTIONAL_HIP_HEIGHT
        legs["used"] = bool(abs(dev) <= HIP_HEIGHT_LIMIT and legs["leg_length"] > 0.1 * H)
        if abs(dev) > HIP_HEIGHT_NOTE or not legs["used"]:
            expect = PROPORTIONAL_HIP_HEIGHT * H + sole
            if from_typed:
                text = (f"with the typed pelvis offset the hips are at {legs['hip_height']:.2f} m, the proportions "
                        f"put them at {expect:.2f} m: check the pelvis offset")
            else:
                text = (f"the pelvis tracker is {100 * abs(dev) * H:.0f} cm {'above' if dev > 0 else 'below'} where "
                        f"the proportions put the pelvis joint (hips at {legs['hip_height']:.2f} m, expected about "
                        f"{expect:.2f} m): if it is not worn level with the pelvis joint (at the back of the "
                        f"pelvis; a belt at the waist is higher), type its offset: worn higher or lower than "
                        f"the joint, it makes the legs longer or shorter by as much")
            problems.append(text + ("" if legs["used"] else "; the legs stay proportional"))

    measured = dict(head_height=float(head[2]), stature=H_meas, arm_span=span, wrist_distance=wrist_distance,
                    arm_angles_deg={k: v[0] for k, v in angles.items()},
                    arm_swing_deg={k: v[1] for k, v in angles.items()},
                    head_turn_deg=head_turn, motion=motion, legs=legs)
    if isinstance(measurements, BodyMeasurements):
        meas = measurements
    else:
        fields_ = dict(stature=float(H_meas), arm_span=float(span))
        if legs.get("used"):
            fields_.update(thigh=float(legs["thigh"]), shank=float(legs["shank"]))
        if isinstance(measurements, dict):
            fields_.update({k: v for k, v in measurements.items() if v is not None})
        meas = BodyMeasurements(**fields_)
    rest = None
    try:
        # the body's rest T-pose stood under the head joint, turned by the heading: where the
        # pelvis and ankles are in the calibration pose (soles on z = 0, rest head at x = y = 0)
        rest = np.array([head[0], head[1], 0.0]) + make_body(meas).rest_positions() @ Rh.T
    except ValueError as exc:
        problems.append(f"measurements are not usable: {exc}")

    # --- rotation offsets
    expected = {"head": Rh, "pelvis": Rh, "left_foot": Rh, "right_foot": Rh,
                "left_hand": Rh @ rotation_between(np.array([1.0, 0, 0]), a_l),
                "right_hand": Rh @ rotation_between(np.array([-1.0, 0, 0]), a_r)}
    changes, trackers = {}, {}
    for d, R_t in mean_rot.items():
        e = new["devices"].get(d, {"pos": [0.0, 0.0, 0.0], "rot": [1.0, 0.0, 0.0, 0.0]})
        off_R = quat_to_matrix(np.asarray(e["rot"]))
        R_exp = expected[d]
        new_R = orthonormalize(off_R @ R_t.T @ R_exp)       # = R_deviceᵀ R_exp, R_device = R_t off_Rᵀ
        new_p = np.asarray(e["pos"], dtype=np.float64)
        if d in EXTRA_DEVICES and rest is not None:
            R_dev = R_t @ off_R.T
            # rounded to 0.1 µm as the presets are (plain JSON numbers, far below what is measured)
            new_p = np.round(R_dev.T @ (rest[J[JOINT_OF_DEVICE[d]]] - dev_pos[d]), 7) + 0.0
        if d in typed:      # typed offsets win; report how far the pose disagrees
            changes[d] = 0.0
            kept_R = off_R
            kept_p = np.asarray(e["pos"], dtype=np.float64)
            trackers[d] = dict(source="typed", distance=float(np.linalg.norm(kept_p)),
                               angle_deg=float(np.degrees(geodesic_angle(np.eye(3), kept_R))),
                               pos=[float(v) for v in kept_p], rot=[float(v) for v in e["rot"]])
            if rest is not None:
                trackers[d].update(disagree_m=float(np.linalg.norm(new_p - kept_p)),
                                   disagree_deg=float(np.degrees(geodesic_angle(new_R, kept_R))))
            continue
        changes[d] = float(np.degrees(geodesic_angle(R_t, R_exp)))
        new["devices"][d] = {"pos": [float(v) for v in new_p], "rot": [float(v) for v in matrix_to_quat(new_R)]}
        if d in EXTRA_DEVICES and rest is not None:
            dist = float(np.linalg.norm(new_p))
            trackers[d] = dict(source="T-pose", distance=dist,
                               angle_deg=float(np.degrees(geodesic_angle(np.eye(3), new_R))),
                               pos=new["devices"][d]["pos"], rot=new["devices"][d]["rot"])
            if dist > MAX_TRACKER_OFFSET:
                where = ("stand upright with the head above the pelvis" if d == "pelvis" else
                         "stand with the feet under the hips, flat on the floor; is it on the "
                         f"{d.split('_')[0]} foot?")
                problems.append(f"the {_TRACKER_LABEL[d]} tracker comes out {100 * dist:.0f} cm from the "
                                f"{JOINT_OF_DEVICE[d].replace('_', ' ')} (straps keep it within about "
                                f"{100 * MAX_TRACKER_OFFSET:.0f} cm): {where}")
    # a foot lifted (or on its toes) at the calibration moment: its tracker stands higher or more tilted
    # there than when the foot is stood on later in the recording (only matters for a measured offset)
    feet = {}
    for d in ("left_foot", "right_foot"):
        if d not in mean_pos or d in typed:
            continue
        st = _foot_stance(targets, d, float(mean_pos[d][2]), mean_rot[d])
        if st is None:
            continue
        feet[d] = dict(lift=st[0], tilt_deg=st[1])
        side = d.split("_")[0]
        if st[0] > FOOT_LIFT_TOLERANCE:
            problems.append(f"the {side} foot is {100 * st[0]:.0f} cm higher at {time:.2f} s than when it is "
                            f"stood on later: put both feet flat on the floor for the calibration")
        elif st[1] > FOOT_TILT_TOLERANCE:
            problems.append(f"the {side} foot is tilted {st[1]:.0f}° at {time:.2f} s compared with when it is "
                            f"stood on later: put both feet flat on the floor for the calibration")
    measured["feet"] = feet
    new["name"] = f"{new['name']} (calibrated)" if not new["name"].endswith("(calibrated)") else new["name"]

    result = CalibrationResult(measurements=meas, offsets=new, time=time, frame=frame, pose=kind,
                               arm_angle_deg=float(arm_angle), heading_deg=heading,
                               rotation_change_deg=changes, measured=measured, problems=problems,
                               tracker_offsets=trackers)
    if strict and problems:
        raise CalibrationError(f"not a usable {kind}-pose at {time:.2f} s: " + "; ".join(problems))
    return result


#: metres added to each arm when a body is built from a measured span (see :func:`body_for`)
REACH_MARGIN = 0.01


def body_for(measurements: BodyMeasurements, reach_margin: float = REACH_MARGIN):
    """The :class:`~.skeleton.Body` to solve with, from calibrated measurements.

    A span measured in a T-pose is the wrist distance with *locked* elbows;
    building the arms exactly that long leaves no slack for the ~1 cm the
    predicted shoulders may be off, and the hands would miss fully
    extended targets.  Each arm gets ``reach_margin`` metres (default 1 cm,
    below the uncertainty of a controller-to-wrist offset), so such targets
    stay reachable with a barely bent elbow.  Without an arm span the
    proportions are used unchanged.
    """
    from dataclasses import replace
    m = measurements
    if m.arm_span is not None and m.upper_arm is None and m.forearm is None:
        m = replace(m, arm_span=float(m.arm_span) + 2.0 * float(reach_margin))
    return make_body(m)



#: the longest wrist-to-wrist span reach adaptation may give, as a multiple of the span the
#: proportions give for the stature (adult arm span / stature varies by about ±6 %)
MAX_REACH_SPAN_FACTOR = 1.08
#: the share of hand samples (%) the adapted arms must reach: arms are only lengthened
#: when more than 2 % of the samples are out of reach (a few odd frames are not the body)
REACH_QUANTILE = 98.0


def arm_span_for_reach(result, quantile=REACH_QUANTILE, margin=REACH_MARGIN,
                       max_factor=MAX_REACH_SPAN_FACTOR):
    """Wrist-to-wrist T-pose span (metres) whose arms reach the hand targets of ``result``.

    For recordings without a calibration pose (a game replay, say), where
    the arms come from the stature's proportions: the distance from each
    solved shoulder to its hand target, at the ``quantile`` over frames and both arms, plus
    ``margin``, is the arm length needed (SparsePoser-style body-size
    adaptation, from the motion instead of a T-pose).  Returns ``None`` when
    the proportional arms already reach; never more than ``max_factor``
    times the proportional span.  ``result``: a
    :class:`~.pose_result.PoseResult` with ``targets``.
    """
    body = result.body
    if result.targets is None or not set(HAND_DEVICES) <= set(result.targets.pos):
        return None
    pos = result.positions
    need = np.concatenate([np.linalg.norm(result.targets.pos[f"{s}_hand"] - pos[:, J[f"{s}_shoulder"]], axis=-1)
                           for s in ("left", "right")])
    need = float(np.percentile(need, quantile))
    arm = float(body.limb_lengths()[:2].sum(-1).mean())
    if need <= arm:
        return None
    rest = body.rest_positions()
    shoulder_width = float(np.linalg.norm(rest[J["left_shoulder"]] - rest[J["right_shoulder"]]))
    proportional = float(np.linalg.norm(rest[J["left_wrist"]] - rest[J["right_wrist"]]))
    return min(shoulder_width + 2.0 * (need + margin), max_factor * proportional)


def adapt_arms_to_reach(result, solve, iterations=3):
    """Lengthen the arms of ``result.body`` until the hands reach (see :func:`arm_span_for_reach`).

    ``solve(body) -> PoseResult`` re-solves the same targets with another
    body.  Re-solving matters: with longer arms the collars swing less, so
    the shoulders sit further from far targets and one estimate falls short;
    a few rounds converge (each only lengthens, up to the cap).  Returns
    ``(body, result, span)``; ``span`` is None when the arms were left alone.
    """
    span = None
    for _ in range(max(int(iterations), 1)):
        new = arm_span_for_reach(result)
        if new is None or (span is not None and new <= span + 1e-3):
            break
        span = new
        body = make_body(BodyMeasurements(stature=result.body.stature, arm_span=span))
        result = solve(body)
    return result.body, result, span
