"""Body size and device rotation offsets from a T-pose (or A-pose) moment.

Never imports bpy.

In the style of SparsePoser's walk-in calibration (Ponton et al. 2023,
after Walk-In-Avatar, Ponton et al. 2022): the performer stands still in a
T-pose (or A-pose) for a moment; from the joint targets averaged over a short
window (default ±0.25 s) we measure

* stature ``H`` = head joint height / 0.910 (the body model puts the skull
  base at 0.910 H, :data:`.skeleton.PROPORTIONS`; from a raw HMD eye height
  use :func:`stature_from_eye_height`, eyes at ~0.936 H);
* arm span (wrist to wrist, what :class:`.skeleton.BodyMeasurements` calls
  ``arm_span``): the wrist distance in a T-pose; in an A-pose the shoulder
  breadth (0.209 H) plus both shoulder-to-wrist distances, the shoulders
  placed 0.818 H - 0.910 H below the head joint;
* the constant rotation between each device and its joint: in the pose the
  joint orientation is known - head, pelvis and ankles face the body heading
  (identity rotated by the heading yaw), a wrist's rest orientation (hand
  along the arm, palm down) swung to the measured arm direction (for a
  T-pose that is the heading itself; for an A-pose the arm tilted down) - so
  the device's offset rotation becomes ``device_rotᵀ @ expected_joint_rot``.

The heading is the horizontal line from the right to the left wrist (the
performer's left is +X at heading 0, facing -Y).  Checks report when the
moment is not plausibly a still T/A-pose (:attr:`CalibrationResult.problems`).

Targets in, offsets out: ``targets`` must have been made with ``offsets``
(:func:`.device_offsets.to_targets`); the result holds updated offsets with
the position offsets unchanged and the rotations corrected.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .device_offsets import validate_offsets
from .plain import shown
from .devices import HAND_DEVICES, REQUIRED_DEVICES
from .pose_result import TrackerTargets
from .rotations import geodesic_angle, matrix_to_quat, normalize, orthonormalize, quat_to_matrix, rotation_between
from .skeleton import J, PROPORTIONS, BodyMeasurements, make_body

#: eye (HMD) height as a fraction of stature (Drillis & Contini, Winter 2009 Fig. 4.1)
EYE_HEIGHT = 0.936
HEAD_HEIGHT = PROPORTIONS["head_height"]
SHOULDER_HEIGHT = PROPORTIONS["shoulder_height"]
SHOULDER_WIDTH = PROPORTIONS["shoulder_width"]
ARM_LENGTH = PROPORTIONS["upper_arm"] + PROPORTIONS["forearm"]     # shoulder to wrist, fraction of H
TPOSE_WRIST_DISTANCE = SHOULDER_WIDTH + 2 * ARM_LENGTH             # 0.873 H

_Z = np.array([0.0, 0.0, 1.0])


class CalibrationError(ValueError):
    """Raised by :func:`calibrate` with ``strict=True`` when the pose is implausible."""


def stature_from_head_height(z):
    """Stature (m) from the head joint (skull base) height above the floor (m)."""
    return float(z) / HEAD_HEIGHT


def stature_from_eye_height(z):
    """Stature (m) from the HMD (eye) height above the floor (m)."""
    return float(z) / EYE_HEIGHT


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
    small, one below the floor too big)."""
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
    causes.append(f"the floor (the head stands {float(head_height):.2f} m above height 0; the recording's "
                  "floor must be at 0)")
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
    rotation_change_deg: device → angle of the rotation correction.
    measured: raw numbers (head height, wrist distance, stature and arm span
    as measured, per-device motion).  problems: reasons the moment does not
    look like a still T/A-pose (empty = plausible).
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
    """Propose the most T-pose-like moment: hands far apart at shoulder height, still.

    targets: joint targets (head, left_hand, right_hand needed).  window:
    half-width in seconds over which the pose must hold.  t0: time of frame
    0 (seconds).  Vectorised over frames.
    """
    for d in REQUIRED_DEVICES:
        if d not in targets.pos:
            raise ValueError(f"find_tpose needs {d} targets")
    fps = float(targets.fps)
    n = targets.num_frames
    w = max(1, int(round(window * fps)))
    ok = np.ones(n, dtype=bool)
    for d in REQUIRED_DEVICES:
        v = targets.valid.get(d)
        if v is not None:
            ok &= np.asarray(v, dtype=bool)
    head = targets.pos["head"]
    wl = targets.pos["left_hand"]
    wr = targets.pos["right_hand"]
    H = np.maximum(head[:, 2] / HEAD_HEIGHT, 0.3)
    shoulder_z = head[:, 2] - (HEAD_HEIGHT - SHOULDER_HEIGHT) * H
    span_ratio = np.linalg.norm(wl - wr, axis=-1) / (TPOSE_WRIST_DISTANCE * H)
    height_err = 0.5 * (np.abs(wl[:, 2] - shoulder_z) + np.abs(wr[:, 2] - shoulder_z))
    speed = np.zeros(n)
    if n > 1:
        speed[1:] = (np.linalg.norm(np.diff(wl, axis=0), axis=-1)
                     + np.linalg.norm(np.diff(wr, axis=0), axis=-1)) * fps / 2
        speed[0] = speed[1]
    cost = np.abs(1.0 - span_ratio) + 3.0 * height_err / H + 0.5 * speed
    cost = np.where(ok & np.isfinite(cost), cost, 1e3)
    mc = _window_mean(cost, w)
    k = int(np.argmin(mc))
    sr = float(_window_mean(span_ratio, w)[k])
    he = float(_window_mean(height_err, w)[k])
    sp = float(_window_mean(speed, w)[k])
    plausible = bool(mc[k] < 1e2 and sr > 0.8 and he < 0.12 and sp < 0.3)
    return TPoseCandidate(time=float(t0 + k / fps), frame=k, cost=float(mc[k]), plausible=plausible,
                          span_ratio=sr, height_error=he, speed=sp)


def _heading_matrix(x_axis):
    x = normalize(np.array([x_axis[0], x_axis[1], 0.0]))
    y = np.cross(_Z, x)
    return np.stack([x, y, _Z], axis=-1)


def _yaw_deg(R):
    return float(np.degrees(np.arctan2(R[1, 0], R[0, 0])))


def _wrap_deg(a):
    return float((a + 180.0) % 360.0 - 180.0)


def calibrate(targets: TrackerTargets, time=None, offsets=None, window=0.25, pose="auto",
              measurements=None, t0=0.0, frame=None, strict=False) -> CalibrationResult:
    """Measure body size and device rotation offsets at a T/A-pose moment.

    targets: joint targets made with ``offsets`` (head, left_hand,
    right_hand required; pelvis/feet used when present).
    time: calibration moment in seconds (recording clock, frame ``k`` at
    ``t0 + k / fps``); or give ``frame``; default: :func:`find_tpose`.
    offsets: the offsets ``targets`` were made with (any form
    :func:`.device_offsets.validate_offsets` accepts; default none).
    window: half-width (s) of the averaging window.
    pose: ``'auto'`` (classify by arm elevation: < 20° T, 20-65° A), ``'T'``
    or ``'A'``.
    measurements: explicit body measurements: a :class:`BodyMeasurements` is
    passed through unchanged; a dict overrides only the given fields of the
    measured ones (e.g. ``{"stature": 1.80}``).
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

    # --- average each device over the window
    mean_pos, mean_rot, motion = {}, {}, {}
    for d in targets.devices:
        P = targets.pos[d][sl]
        R = targets.rot[d][sl]
        v = targets.valid.get(d)
        m = np.ones(P.shape[0], dtype=bool) if v is None else np.asarray(v, dtype=bool)[sl]
        m &= np.all(np.isfinite(P), -1) & np.all(np.isfinite(R), (-1, -2))
        if m.sum() == 0:
            problems.append(f"{d} is not tracked at {time:.2f} s")
            continue
        if m.mean() < 0.5:
            problems.append(f"{d} lost tracking for {100 * (1 - m.mean()):.0f}% of the calibration window")
        P, R = P[m], R[m]
        mean_pos[d] = P.mean(0)
        mean_rot[d] = orthonormalize(R.mean(0))
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
    H_meas = stature_from_head_height(head[2])
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

    # --- measurements
    wrist_distance = float(np.linalg.norm(wl - wr))
    if kind == "T":
        span = wrist_distance
    else:
        span = float(sw + np.linalg.norm(a_l) + np.linalg.norm(a_r))
    measured = dict(head_height=float(head[2]), stature=H_meas, arm_span=span, wrist_distance=wrist_distance,
                    arm_angles_deg={k: v[0] for k, v in angles.items()},
                    arm_swing_deg={k: v[1] for k, v in angles.items()},
                    head_turn_deg=head_turn, motion=motion)
    if isinstance(measurements, BodyMeasurements):
        meas = measurements
    else:
        fields_ = dict(stature=float(H_meas), arm_span=float(span))
        if isinstance(measurements, dict):
            fields_.update({k: v for k, v in measurements.items() if v is not None})
        meas = BodyMeasurements(**fields_)
    try:
        make_body(meas)
    except ValueError as exc:
        problems.append(f"measurements are not usable: {exc}")

    # --- rotation offsets
    expected = {"head": Rh, "pelvis": Rh, "left_foot": Rh, "right_foot": Rh,
                "left_hand": Rh @ rotation_between(np.array([1.0, 0, 0]), a_l),
                "right_hand": Rh @ rotation_between(np.array([-1.0, 0, 0]), a_r)}
    new = validate_offsets(offsets)
    changes = {}
    for d, R_t in mean_rot.items():
        e = new["devices"].get(d, {"pos": [0.0, 0.0, 0.0], "rot": [1.0, 0.0, 0.0, 0.0]})
        off_R = quat_to_matrix(np.asarray(e["rot"]))
        R_exp = expected[d]
        new_R = orthonormalize(off_R @ R_t.T @ R_exp)
        changes[d] = float(np.degrees(geodesic_angle(R_t, R_exp)))
        new["devices"][d] = {"pos": list(e["pos"]), "rot": [float(v) for v in matrix_to_quat(new_R)]}
    new["name"] = f"{new['name']} (calibrated)" if not new["name"].endswith("(calibrated)") else new["name"]

    result = CalibrationResult(measurements=meas, offsets=new, time=time, frame=frame, pose=kind,
                               arm_angle_deg=float(arm_angle), heading_deg=heading,
                               rotation_change_deg=changes, measured=measured, problems=problems)
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
