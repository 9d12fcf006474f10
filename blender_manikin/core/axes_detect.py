"""A recording's length unit, up axis and forward convention, for files that do not say (wide
CSV layouts, JSON frames), and the heading of devices logged without orientations.  No bpy.

**Units** (:func:`length_units`): from the hands' distance to the head (an arm's length, 0.2-1
m), which does not depend on where the recording's origin is.  (The head's height did, and a
Unity log in world space, the player 12 m from the level's origin, read as centimetres.)

**Up** (:func:`up_axis`): the axis along which the head stands at a steady height of a standing
or seated person, when that is clear (a tracking-space origin on the floor under the performer);
otherwise, Y or Z by the hands hanging below the head along it and the headset's own up axis
along it (a world-space log whose origin is anywhere).

**Z up**: Blender (right-handed, -Y forward) or Unreal (left-handed, +X forward).  Read in the
wrong one a take is mirrored and turned 90°: the hands' left-right line runs along the head's
forward axis, so the convention that sees the left hand on the head's left decides
(:func:`hands_on_their_sides`), else the cues below.

**Forward**: Unity (left-handed, +Z forward) or OpenXR / OpenVR (right-handed, -Z forward).
Read in the wrong one of the two conventions, a take of a headset and two hands is its own
mirror image front to back with the head turned to face backwards: every frame as plausible a
body as the right reading (the left hand still on the performer's left), only the motion tells
them apart.  Three cues, each in the file's own coordinates (a dot product does not depend on
the axes change) and each taken first when it has enough evidence:

1. **walking** (:func:`walking_seconds`): people walk the way they face.  The seconds the head
   moves forward (faster than :data:`WALK_SPEED` horizontally, counted by the cosine of its
   direction to the head's forward axis) less those it moves backwards; decides past
   :data:`WALK_MIN_S`.  Read mirrored, the walk goes backwards;
2. **turning the head** (:func:`turn_pivot_behind`): a headset turns about the neck, behind it
   (a head joint of mocap turns about itself or the neck below).  The pivot is the point fixed
   to the head that moves least through the take's quick turns (high-passed positions and
   rotations, least squares, while the head stands); decides when it is :data:`PIVOT_MIN` or
   more behind or ahead.  Read mirrored, it is ahead;
3. **reaching** (:func:`reach_ahead`): hands reach up to 60 cm ahead of the head and hardly
   behind it; the 90th plus the 10th percentile of their distance ahead.  The only cue before
   this module, and the weakest: hands at the sides stand a few centimetres behind a headset,
   and a take of walking or waving reads mirrored by it.

Measured (``benchmarks/bench_axes.py``: every Bandai Namco take and the HDM05 subset written as
a headset and controllers, ``openxr_generic`` offsets, in both conventions): takes of 10 clips
one after the other were read the right way 99.7 % (Bandai) and 96.4 % (HDM05) of the time by
these cues, 24.1 % and 75.0 % by the reach alone; single clips of 1-10 s, 89.1 % and 66.2 %
against 51.7 % and 44.9 %.  The Beat Saber sample replay (Unity), which the reach alone reads as
OpenXR, is read as Unity by its head's turns (the pivot 3.8 cm behind the headset).

**Heading without orientations** (:func:`heading_from_positions`): a logger that writes positions
only gets level devices facing the way the body does, from the hands' left-right line and the
walking direction.

Positions are in the file's axes (metres, once the unit is known); quaternions ``(w, x, y, z)`` in
the file's axes.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .recording import LEFT_HANDED, increasing_mask, read_check
from .rotations import axis_angle_to_quat, normalize, quat_rotate, quat_to_matrix
from .smoothing import smooth_frames

#: each convention's up axis (index) and the head's local forward axis, in its own coordinates:
#: Unity or OpenXR (Y up), Blender (right-handed) or Unreal (left-handed, +X forward) (Z up)
CONVENTIONS = {"unity": (1, (0.0, 0.0, 1.0)), "openxr": (1, (0.0, 0.0, -1.0)), "blender": (2, (0.0, -1.0, 0.0)),
               "unreal": (2, (1.0, 0.0, 0.0))}
#: m/s of horizontal head speed above which the head is walking (a step is 1-1.5 m/s)
WALK_SPEED = 0.5
#: seconds walked forward less backward (or the reverse) that decide
WALK_MIN_S = 0.5
#: m/s below which the head counts as standing for the pivot
STAND_SPEED = 0.3
#: seconds of standing the pivot needs
STAND_MIN_S = 1.0
#: metres behind (or ahead of) the head's pose its turning pivot must be to decide
PIVOT_MIN = 0.02
#: seconds (Gaussian sigma) of the low-pass removed before the pivot fit, and of the smoothing
#: of the head's path before its speed is taken
HIGH_PASS_S = 0.15
#: radians (rms) of quick head turns below which the pivot fit shrinks to no pivot (ridge)
TURN_FLOOR = np.radians(0.5)


#: the head-to-hand distance (median, in the file's unit) below which a file is in metres, and
#: that times 100 below which it is in centimetres (else millimetres): an arm's reach is 0.2-1 m
ARM_MAX = 5.0
#: metres: the range the head's median height along an up axis must lie in (:func:`up_axis`)
HEAD_HEIGHT_RANGE = (0.5, 2.5)
#: metres the higher of two axes along which the head is steady must stand above the other
UP_MARGIN = 0.5
#: metres: the spread (interquartile range) of the head's height along the up axis above which
#: that axis is not taken from the head's height alone (walking along an axis spreads it by metres)
HEIGHT_SPREAD = 0.6


def length_units(pos):
    """``(units, arm)``: ``"m"``, ``"cm"`` or ``"mm"``, and the median distance from the head to
    the hands in the file's unit.  pos: device -> ``(T, 3)`` in the file's unit (lost samples
    NaN); None when no frame has the head and a hand."""
    dist = np.concatenate([np.linalg.norm(np.asarray(pos[h], np.float64) - pos["head"], axis=-1)
                           for h in ("left_hand", "right_hand") if h in pos])
    dist = dist[np.isfinite(dist)]
    if not dist.size:
        return None
    arm = float(np.median(dist))
    return ("m" if arm < ARM_MAX else "cm" if arm < 100 * ARM_MAX else "mm"), arm


def up_axis(pos, quat):
    """``(axis, how)``: 1 (Y up) or 2 (Z up), and in words how it was found.  pos: device ->
    ``(T, 3)`` metres; quat: device -> ``(T, 4)`` wxyz; both in the file's axes.

    Of Y and Z, the one along which the head stands at a steady height (its median in
    :data:`HEAD_HEIGHT_RANGE`, its interquartile spread at most :data:`HEIGHT_SPREAD`), or the
    higher by :data:`UP_MARGIN` when both do, as a tracking-space origin on the floor gives.
    Otherwise (an origin off the floor or far away), of Y and Z the one with the larger sum of:
    the hands' median depth below the head along it, in 30 cm (clipped to ±1), and the mean of the
    head's own up axis along it (a Y-up convention's device frame is Y-up, Blender's Z-up)."""
    head = np.asarray(pos["head"], np.float64)
    with warnings.catch_warnings():                   # all-NaN columns (lost devices) give NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(head, axis=0)
        hands = np.nanmean(np.stack([pos[h] for h in ("left_hand", "right_hand") if h in pos]), axis=0)
        below = np.nan_to_num(np.nanmedian(head - hands, axis=0))
        spread = np.nanpercentile(head, 75, axis=0) - np.nanpercentile(head, 25, axis=0)
    # the head stands at a steady height: an axis it walks along spreads over metres
    steady = [a for a in (1, 2) if HEAD_HEIGHT_RANGE[0] <= med[a] <= HEAD_HEIGHT_RANGE[1]
              and spread[a] <= HEIGHT_SPREAD]
    if len(steady) == 1 or (len(steady) == 2 and abs(med[1] - med[2]) >= UP_MARGIN):
        return max(steady, key=lambda a: med[a]), "the head's height"
    R = quat_to_matrix(normalize(np.where(np.isfinite(quat["head"]), quat["head"], [1.0, 0, 0, 0])))
    score = {a: float(np.clip(below[a] / 0.3, -1, 1) + np.mean(R[:, a, a])) for a in (1, 2)}
    axis = max(score, key=score.get)
    return axis, "the hands below the head and the headset's tilt (the origin is not under the performer)"


@dataclass
class FacingEvidence:
    """The three cues for one convention: positive says it is the right one.

    walk: seconds walked forward less backward; pivot: metres the head turns about a point
    behind its pose (negative: ahead); reach: metres, the hands' 90th plus 10th percentile
    distance ahead of the head."""
    walk: float
    pivot: float
    reach: float


def _rows(time, pos, quat):
    """``(T,)`` bool: the rows where the time and the head's position and rotation are finite and
    the time goes on (:func:`.recording.increasing_mask`: a repeated row is no step in time, and
    its zero time step would make the speeds infinite)."""
    ok = np.isfinite(pos["head"]).all(-1) & np.isfinite(quat["head"]).all(-1)
    return ok & increasing_mask(np.where(ok, time, np.nan))


def _forward(quat, axes):
    """``(T, 3)`` unit horizontal forward axis of the head, and the up index, in ``axes``."""
    up, local = CONVENTIONS[axes]
    fwd = quat_rotate(normalize(quat), np.array(local))
    fwd[:, up] = 0.0
    return normalize(fwd), up


def _rate(time):
    dt = np.diff(time)
    dt = dt[dt > 0]
    return 1.0 / float(np.median(dt)) if dt.size else 0.0


def walking_seconds(time, head_pos, fwd, up):
    """Seconds the head walks forward less backward: over the samples where its smoothed
    horizontal speed exceeds :data:`WALK_SPEED`, the sum of ``dt`` times the cosine of its
    direction to ``fwd``.  time ``(T,)`` s; head_pos ``(T, 3)`` metres; fwd ``(T, 3)`` unit,
    horizontal; up: the up axis index."""
    fps = _rate(time)
    if fps <= 0 or len(time) < 3:
        return 0.0
    path = smooth_frames(head_pos, HIGH_PASS_S * fps)
    v = np.gradient(path, time, axis=0)
    v[:, up] = 0.0
    speed = np.linalg.norm(v, axis=-1)
    dt = np.gradient(time)
    moving = (speed > WALK_SPEED) & (dt < 5.0 / fps)         # not across a gap in the samples
    if not moving.any():
        return 0.0
    return float(np.sum(np.sum(v[moving] * fwd[moving], -1) / speed[moving] * dt[moving]))


def turn_pivot_behind(time, head_pos, head_quat, local_forward, up):
    """Metres behind the head's pose (along its local forward axis) of the point fixed to the
    head that moves least through its quick turns while the performer stands: ``c`` minimising
    ``|hp(p) + hp(R) c|`` over the standing samples, ``hp`` the high-pass (the signal less its
    Gaussian low-pass of :data:`HIGH_PASS_S`), with a ridge of :data:`TURN_FLOOR` so that a head
    that hardly turns gives no pivot.  0 when the head stands for less than
    :data:`STAND_MIN_S`.  head_pos ``(T, 3)`` metres; head_quat ``(T, 4)`` wxyz; both in the
    file's axes."""
    fps = _rate(time)
    if fps <= 0 or len(time) < 3:
        return 0.0
    sigma = HIGH_PASS_S * fps
    path = smooth_frames(head_pos, sigma)
    v = np.gradient(path, time, axis=0)
    v[:, up] = 0.0
    standing = np.linalg.norm(v, axis=-1) < STAND_SPEED
    if standing.sum() < STAND_MIN_S * fps:
        return 0.0
    R = quat_to_matrix(normalize(head_quat))
    hp = (head_pos - path)[standing]
    hR = (R - smooth_frames(R.reshape(-1, 9), sigma).reshape(-1, 3, 3))[standing]
    A = hR.reshape(-1, 3)
    ridge = len(hR) * TURN_FLOOR ** 2
    c = np.linalg.solve(A.T @ A + ridge * np.eye(3), -A.T @ hp.reshape(-1))
    return float(-np.dot(c, local_forward))


def reach_ahead(pos, fwd, rows):
    """Metres: the 90th plus the 10th percentile of the hands' horizontal distance ahead of
    the head along ``fwd`` (every sample of ``rows``, both hands)."""
    head = pos["head"][rows]
    ahead = np.concatenate([np.sum((pos[h][rows] - head) * fwd, -1)
                            for h in ("left_hand", "right_hand") if h in pos])
    ahead = ahead[np.isfinite(ahead)]
    return float(np.percentile(ahead, 90) + np.percentile(ahead, 10)) if ahead.size else 0.0


#: of the Z-up conventions (Blender, Unreal), the one that sees the left hand on the head's left
#: by this much (the median cosine of the hands' left-right line to the head's left) where the
#: other does not: read in the wrong one, the take is mirrored and turned 90°, the hands' line
#: along the head's forward axis
SIDE_MIN = 0.5


def hands_on_their_sides(time, pos, quat, axes):
    """The median, over the frames with the hands 20 cm or more apart horizontally, of the cosine
    between the left-minus-right hand line and the head's left in ``axes`` (1: the hands' line
    points the head's left; 0: along its forward axis), or None with no such frames.  Arguments
    as :func:`facing_evidence`."""
    if "left_hand" not in pos or "right_hand" not in pos:
        return None
    time = np.asarray(time, np.float64)
    rows = _rows(time, pos, quat)
    fwd, up = _forward(quat["head"][rows], axes)
    up_vec = np.zeros(3)
    up_vec[up] = 1.0
    left = np.cross(up_vec, fwd) * (-1.0 if axes in LEFT_HANDED else 1.0)   # left-handed: mirrored
    line = np.asarray(pos["left_hand"], np.float64)[rows] - np.asarray(pos["right_hand"], np.float64)[rows]
    line[:, up] = 0.0
    apart = np.linalg.norm(line, axis=-1)
    ok = np.isfinite(apart) & (apart >= 0.2)
    if not ok.any():
        return None
    return float(np.median(np.sum(line[ok] * left[ok], -1) / apart[ok]))


def facing_evidence(time, pos, quat, axes) -> FacingEvidence:
    """The cues (:class:`FacingEvidence`) for reading a take in ``axes``.  time ``(T,)``
    seconds; pos: device -> ``(T, 3)`` metres; quat: device -> ``(T, 4)`` wxyz, both in the
    file's axes (lost samples NaN)."""
    time = np.asarray(time, np.float64)
    rows = _rows(time, pos, quat)
    t = time[rows]
    fwd, up = _forward(quat["head"][rows], axes)
    head = np.asarray(pos["head"], np.float64)[rows]
    local = np.array(CONVENTIONS[axes][1])
    return FacingEvidence(walk=walking_seconds(t, head, fwd, up),
                          pivot=turn_pivot_behind(t, head, quat["head"][rows], local, up),
                          reach=reach_ahead(pos, fwd, rows))


#: metres: the hands' sideways distance over which their left-right line gives the body's heading
#: fully (:func:`heading_from_positions`; closer together, the walking direction takes over)
HANDS_APART = 0.3
#: seconds (Gaussian sigma) the heading of a take without orientations is smoothed over (a
#: walk's arm swing, 0.9 Hz, left at a quarter)
HEADING_SMOOTH_S = 0.3


def heading_from_positions(time, pos, walking=True):
    """``(T, 3)`` unit horizontal forward direction of a body whose devices have no orientations,
    Blender axes (+Z up): from the hands' left-right line (the body faces ``up × (right - left)``),
    weighted by how far apart they are sideways (full at :data:`HANDS_APART`), and (``walking``)
    the line the head walks along, weighted by its speed from half :data:`WALK_SPEED` up (up to
    1.5: a walk outweighs the hands' swing), turned forward by the hands' line where that is
    clear (a step back is not a turn); frames with neither take the heading of their neighbours;
    smoothed (:data:`HEADING_SMOOTH_S`, which also evens out the arms' swing).  A take that
    neither walks nor reaches cannot tell its axes this way (:func:`choose_axes`), but read
    mirrored it only moves the hands a few centimetres front to back.  time ``(T,)`` seconds; pos:
    device -> ``(T, 3)`` metres, Blender axes, lost samples NaN."""
    time = np.asarray(time, np.float64)
    T = len(time)
    fps = _rate(time) or 30.0
    side = np.nan_to_num(np.asarray(pos["right_hand"], np.float64) - pos["left_hand"])
    side[:, 2] = 0.0
    lateral = np.cross([0.0, 0.0, 1.0], side)                    # |lateral| = the hands' spread
    spread = np.linalg.norm(lateral, axis=-1)
    lateral *= (np.clip(spread / HANDS_APART, 0.0, 1.0) / np.maximum(spread, 1e-9))[:, None]
    head = np.asarray(pos["head"], np.float64)
    ok = np.isfinite(head).all(-1)
    ok &= increasing_mask(np.where(ok, time, np.nan))            # a repeated row is no step in time
    v = np.zeros((T, 3))
    if ok.sum() >= 3:
        path = smooth_frames(head[ok], HIGH_PASS_S * fps)
        v[ok] = np.gradient(path, time[ok], axis=0)
    v[:, 2] = 0.0
    speed = np.linalg.norm(v, axis=-1)
    walk = v * (np.clip(speed / WALK_SPEED - 0.5, 0.0, 1.5) / np.maximum(speed, 1e-9))[:, None]
    # a walk gives the heading's line; the hands' left and right give its sign (a step back)
    back = (np.sum(walk * lateral, -1) < 0) & (np.linalg.norm(lateral, axis=-1) > 0.2)
    walk[back] *= -1.0
    f = lateral + walk if walking else lateral
    w = np.linalg.norm(f, axis=-1)
    known = w > 0.2
    if not known.any():
        out = np.zeros((T, 3))
        out[:, 1] = -1.0                                          # no evidence: Blender's forward
        return out
    ang = np.unwrap(np.arctan2(f[known, 1], f[known, 0]))
    ang = np.interp(np.arange(T), np.nonzero(known)[0], ang)
    ang = smooth_frames(ang[:, None], HEADING_SMOOTH_S * fps)[:, 0]
    return np.stack([np.cos(ang), np.sin(ang), np.zeros(T)], -1)


def heading_quats(yaw):
    """``(T, 4)`` wxyz: level device orientations (Blender device axes: -Y forward, +Z up) turned
    ``yaw`` ``(T,)`` radians about +Z (the angle of :func:`.features.heading_yaw`)."""
    return axis_angle_to_quat(np.asarray(yaw, np.float64)[:, None] * np.array([0.0, 0.0, 1.0]))


def yaw_of(forward):
    """``(T,)`` radians: the yaw (:func:`.features.heading_yaw`'s angle) of level ``forward``
    directions ``(T, 3)``, Blender axes."""
    return np.arctan2(forward[:, 0], -forward[:, 1])


def forward_of(yaw):
    """``(T, 3)``: the level forward direction of ``yaw`` ``(T,)`` radians (:func:`yaw_of`'s inverse)."""
    return np.stack([np.sin(yaw), -np.cos(yaw), np.zeros_like(yaw)], -1)


def _positions_only_evidence(time, pos, axes):
    """:class:`FacingEvidence` (no pivot) of a take without orientations read in ``axes``: the
    walking and reaching cues against the heading :func:`heading_from_positions` gives there."""
    from .recording import to_blender
    time = np.asarray(time, np.float64)
    rows = np.isfinite(pos["head"]).all(-1)
    rows &= increasing_mask(np.where(rows, time, np.nan))
    b = {d: to_blender(np.asarray(p, np.float64)[rows], None, axes)[0] for d, p in pos.items()}
    t = time[rows]
    fwd = heading_from_positions(t, b, walking=False)     # the hands' line alone: the walk is the evidence
    everything = np.ones(len(t), bool)
    return FacingEvidence(walk=walking_seconds(t, b["head"], fwd, 2), pivot=0.0,
                          reach=reach_ahead(b, fwd, everything))


def choose_axes(time, pos, quats_for, candidates):
    """``(axes, why)``: the convention among ``candidates`` the take faces forward in, and the
    cue that decided, in words.  quats_for: axes -> the devices' quaternions read in it (Euler
    angles give each convention its own), or None when the file has no orientations (the
    heading then comes from :func:`heading_from_positions`, and only walking and reaching
    decide); time, pos as :func:`facing_evidence`."""
    if len(candidates) == 1:
        return candidates[0], "the only convention with that up axis"
    if quats_for is not None and set(candidates) == {"blender", "unreal"}:
        side = {a: hands_on_their_sides(time, pos, quats_for(a), a) for a in candidates}
        best = max(candidates, key=lambda a: -2.0 if side[a] is None else side[a])
        other = next(a for a in candidates if a != best)
        if side[best] is not None and side[best] >= SIDE_MIN and (side[other] or 0.0) < SIDE_MIN:
            return best, "from the hands' left-right line (the left hand on the head's left)"
    ev = {}
    for a in candidates:              # each takes a good part of a second on a long take: a cancel between
        read_check()
        ev[a] = _positions_only_evidence(time, pos, a) if quats_for is None else \
            facing_evidence(time, pos, quats_for(a), a)
    walk = max(candidates, key=lambda a: ev[a].walk)
    if ev[walk].walk >= WALK_MIN_S:
        return walk, f"from the walking direction ({ev[walk].walk:.1f} s forward)"
    pivot = max(candidates, key=lambda a: ev[a].pivot)
    if ev[pivot].pivot >= PIVOT_MIN:
        return pivot, f"from the head's turns (about a point {100 * ev[pivot].pivot:.0f} cm behind it)"
    reach = max(candidates, key=lambda a: ev[a].reach)
    other = next(a for a in candidates if a != reach)
    return reach, (f"from the hands' reach ahead of the head, the weakest cue: if the body faces "
                   f"backwards, set the axes to {other} (Axes, --axes)")
