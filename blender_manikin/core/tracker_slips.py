"""Foot trackers that slip on the body mid-take: found on the planted feet and put right.

Never imports bpy.

A foot tracker's offset to its ankle (:mod:`.device_offsets`) is measured once, at the T-pose
(:mod:`.calibration`).  When its strap slips later, sliding up or down the shin or turning
round it, the offset is wrong from then on: the ankle the tracker implies stands that much
higher (a slide) or its foot points that much off (a turn) for the rest of the take.

In the ankle's own frame (:mod:`.skeleton`: +Z along the shin when the foot stands flat) both
are simple.  A tracker mounted at ``c`` with orientation ``M`` (``device = joint · (c, M)``)
that slides ``s`` metres up the shin is at ``c + s ẑ``: the old offset then puts the ankle at
``joint_pos + s · joint_rot ẑ``, its orientation right.  One that turns by ``θ`` round the
shin (an axis through the ankle) is at ``(Rz(θ) c, Rz(θ) M)``: the old offset puts the ankle
where it is, turned to ``joint_rot · Rz(θ)``.  So the correction from the slip on is
``pos - s · rot ẑ`` and ``rot · Rz(-θ)``, on the targets (:class:`.pose_result.TrackerTargets`).

Both are measured where the truth is known: on the foot's *plants* (the implied ankle still,
slower than :data:`PLANT_SPEED` for :data:`PLANT_MIN_S` or more, the foot flat within
:data:`FLAT_MAX_DEG` and the pelvis upright within :data:`UPRIGHT_MAX_DEG`), a flat foot's ankle stands
at one height and points one way relative to the pelvis (or, without a pelvis tracker, the
headset).  A slip is a *step* in those per plant: the plants before a moment agree with each
other, the plants after it agree with each other, and the two differ by at least
:data:`SLIP_SLIDE_M` in height or :data:`SLIP_TURN_DEG` in heading (each side's scatter under
:data:`SLIP_CONSISTENT` of the step).  Motion does not do that: a squat keeps the planted
ankle's height, a kick or a step lifts it between plants, a turn of the body turns the pelvis
with the feet.  The slip happened between the last plant before and the first after (the foot
in the air, where a strap is knocked); the correction eases in over that gap.

What a body does can look the same, so it is told apart where it can be and otherwise only
reported:

* both feet stepping alike within :data:`BOTH_FEET_S` (both planted ankles higher: a step onto
  a platform; both headings turned against the pelvis: a stance, or the pelvis tracker turning
  round the belt) is no strap of one foot; the turn is named as the pelvis tracker's
  (``device="pelvis"``, its turn round the waist), not corrected;
* a turn alone (no slide at the same moment) is what a held stance does too (a fighter's back
  foot turned out 40° for the rest of the take): it is named in the summary, not corrected.  A
  turn that comes with a slide at the same moment is the strap's, and is put right with it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .features import heading_yaw
from .rotations import axis_angle_rotation, wrap_angle

#: metres per second under which an implied ankle counts as still (planted)
PLANT_SPEED = 0.15
#: seconds either side of a frame its speed is measured over
PLANT_SPAN_S = 0.1
#: seconds an ankle must stay still for a plant
PLANT_MIN_S = 0.25
#: a longer plant counts as several of at most this many seconds (a foot that stands all along,
#: in squats, still gives a plant before a slip and one after)
PLANT_MAX_S = 1.0
#: plants needed on either side of a slip
MIN_PLANTS = 2
#: metres the planted ankle height must step by for a slide along the shin
SLIP_SLIDE_M = 0.03
#: degrees the planted foot's heading (relative to the pelvis) must step by for a turn round it
SLIP_TURN_DEG = 16.0
#: the plants on each side scatter (median absolute deviation) less than this share of the step
SLIP_CONSISTENT = 0.25
#: degrees a planted foot's up axis may lean from the vertical (a flat foot, not on its toes or side)
FLAT_MAX_DEG = 20.0
#: degrees the pelvis (or the headset) may lean for its feet's plants to count (not lying down)
UPRIGHT_MAX_DEG = 45.0
#: seconds within which both feet stepping alike is the body (a platform, a stance), not a strap
BOTH_FEET_S = 1.0
FOOT_DEVICES = ("left_foot", "right_foot")
_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class TrackerSlip:
    """One slip of a foot tracker (or of the pelvis tracker, both feet turning alike against it).

    device: ``"left_foot"`` / ``"right_foot"`` (or ``"pelvis"``: ``turn_deg`` its turn round the
    waist, found from the feet, never corrected); start, end: frames between which it happened
    (the last planted frame before it, the first after); slide: metres the tracker slid up the
    shin (negative: down); turn_deg: degrees it turned round the shin (about the ankle's +Z);
    either is 0 when it did not step; after: the offsets fit the take *after* it (they were
    measured there: the planted ankle stands at the rest height after it, not before), so the
    frames before it are the ones put right.  A turn is put right only with a slide (a turn
    alone may be a stance: :attr:`corrected` is then False, the slip only reported)."""
    device: str
    start: int
    end: int
    slide: float
    turn_deg: float
    after: bool = False

    @property
    def corrected(self) -> bool:
        return bool(self.slide)


def plants(pos, valid, fps):
    """``[(first, last)]`` frame ranges (inclusive) where the point ``pos`` ``(T, 3)`` m stays
    slower than :data:`PLANT_SPEED` (over :data:`PLANT_SPAN_S` either side) for
    :data:`PLANT_MIN_S` or more, valid throughout; cut into pieces of at most
    :data:`PLANT_MAX_S`."""
    T = pos.shape[0]
    k = max(1, int(round(PLANT_SPAN_S * fps)))
    if T < 2 * k + 1:
        return []
    speed = np.full(T, np.inf)          # over +-PLANT_SPAN_S: a tracker's jitter is no motion
    speed[k:-k] = np.linalg.norm(pos[2 * k:] - pos[:-2 * k], axis=-1) * fps / (2 * k)
    still = np.nan_to_num(speed, nan=np.inf) < PLANT_SPEED
    still &= np.asarray(valid, bool)
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    long = (ends - starts + 1) >= PLANT_MIN_S * fps
    out = []
    n = max(int(round(PLANT_MAX_S * fps)), 1)
    for a, b in zip(starts[long].tolist(), ends[long].tolist()):
        cuts = np.linspace(a, b + 1, max(int(np.ceil((b + 1 - a) / n)), 1) + 1).round().astype(int)
        out.extend((int(c0), int(c1) - 1) for c0, c1 in zip(cuts[:-1], cuts[1:]))
    return out


def _prefix_medians(values):
    """``(K,)``: ``np.median(values[:m + 1])`` for every ``m`` of ``values`` ``(K,)`` (finite), in
    O(K log K) comparisons (a sorted list kept as they come; the middle one, or the mean of the
    middle two as numpy takes it), not a median of every prefix anew (O(K²): a 60-minute walk
    has 3,000 plants a foot)."""
    import bisect
    kept, out = [], np.empty(len(values))
    for m, v in enumerate(values.tolist()):
        bisect.insort(kept, v)
        n = m + 1
        out[m] = kept[n // 2] if n % 2 else (kept[n // 2 - 1] + kept[n // 2]) / 2.0
    return out


def _best_step(values):
    """The split of ``values`` ``(K,)`` (one per plant, in time order) with the largest step
    between the medians of the plants before and after it, each side at least
    :data:`MIN_PLANTS` long and consistent (every plant within :data:`SLIP_CONSISTENT` of the
    step from its side's median).  Returns ``(m, step)``: plants ``m`` on are after it;
    ``(None, 0.0)`` when no split is consistent.  Linear in ``K`` but for a sort: each side's
    median from :func:`_prefix_medians`, its farthest plant from the running extremes."""
    values = np.asarray(values, dtype=np.float64)
    K = len(values)
    best, step = None, 0.0
    if K < 2 * MIN_PLANTS:
        return best, step
    if not np.all(np.isfinite(values)):     # a NaN is on one side of every split: its median NaN, no step
        return best, step
    med_a = _prefix_medians(values)                       # med_a[m - 1]: median of values[:m]
    med_b = _prefix_medians(values[::-1])[::-1]           # med_b[m]: median of values[m:]
    hi_a, lo_a = np.maximum.accumulate(values), np.minimum.accumulate(values)
    hi_b, lo_b = np.maximum.accumulate(values[::-1])[::-1], np.minimum.accumulate(values[::-1])[::-1]
    for m in range(MIN_PLANTS, K - MIN_PLANTS + 1):
        ma, mb = med_a[m - 1], med_b[m]
        d = float(mb - ma)
        # the farthest plant from a side's median is its largest or its smallest (|x - med| as
        # numpy rounds it grows with x either side of it, so the maximum is the same number)
        scatter = max(hi_a[m - 1] - ma, ma - lo_a[m - 1], hi_b[m] - mb, mb - lo_b[m])
        if scatter <= SLIP_CONSISTENT * abs(d) and abs(d) > abs(step):
            best, step = m, d
    return best, step


def find_tracker_slips(targets, fps=None, rest_ankle_z=None) -> list:
    """The foot trackers of ``targets`` (:class:`.pose_result.TrackerTargets`, offsets applied,
    floor at z = 0) that slipped mid-take (see the module docstring): a list of
    :class:`TrackerSlip`, at most one per foot (the largest step).

    Which side the offsets fit: the one whose plants stand nearer ``rest_ankle_z`` (metres, the
    body's ankle height standing flat; the calibration puts the planted ankle there) for a
    slide, nearer the pelvis's heading for a turn (the calibration points the foot with the
    body); without ``rest_ankle_z``, before it."""
    fps = float(fps or targets.fps)
    ref = "pelvis" if "pelvis" in targets.rot else "head"
    ref_heading = heading_yaw(targets.rot[ref]) if ref in targets.rot else None
    upright = targets.rot[ref][:, 2, 2] > np.cos(np.radians(UPRIGHT_MAX_DEG)) if ref in targets.rot else True
    out = []
    for d in FOOT_DEVICES:
        if d not in targets.pos:
            continue
        pos, rot = targets.pos[d], targets.rot[d]
        valid = targets.valid.get(d, np.ones(pos.shape[0], bool))
        if ref_heading is not None:
            valid = valid & targets.valid.get(ref, np.ones(pos.shape[0], bool)) & upright
        # a plant is a foot standing flat under a body standing up: a foot on its side or its
        # toes, or a body lying on the floor, holds its ankle at other heights and headings
        valid = valid & (rot[:, 2, 2] > np.cos(np.radians(FLAT_MAX_DEG)))
        segs = plants(pos, valid, fps)
        if len(segs) < 2 * MIN_PLANTS:
            continue
        height = np.array([np.median(pos[a:b + 1, 2]) for a, b in segs])
        m_h, slide = _best_step(height)
        m_t, turn = None, 0.0
        if ref_heading is not None:
            rel = wrap_angle(heading_yaw(rot) - ref_heading)
            heading = np.array([np.median(rel[a:b + 1]) for a, b in segs])
            m_t, turn = _best_step(heading)
        slide = slide if m_h is not None and abs(slide) >= SLIP_SLIDE_M else 0.0
        turn = turn if m_t is not None and abs(np.degrees(turn)) >= SLIP_TURN_DEG else 0.0
        if not slide and not turn:
            continue
        m = m_h if slide else m_t
        if slide and turn and m_t != m_h:      # two steps at two moments: the larger one
            if abs(np.degrees(turn)) / SLIP_TURN_DEG > abs(slide) / SLIP_SLIDE_M:
                m, slide = m_t, 0.0
            else:
                turn = 0.0
        if slide:
            start, end = _moment(pos[:, 2], segs[m - 1], segs[m], slide)
            late = rest_ankle_z is not None and \
                abs(np.median(height[m:]) - rest_ankle_z) < abs(np.median(height[:m]) - rest_ankle_z)
        else:
            start, end = _moment(rel, segs[m - 1], segs[m], turn, angle=True)
            late = abs(np.median(heading[m:])) < abs(np.median(heading[:m]))
        out.append(TrackerSlip(d, start, end, float(slide), float(np.degrees(turn)), bool(late)))
    return _one_foot_only(out, fps)


def _one_foot_only(slips, fps):
    """``slips`` less the steps both feet make alike (same sign, within a factor 2, within
    :data:`BOTH_FEET_S`): a platform or a stance, not a strap.  Slips left with neither a slide
    nor a turn are dropped."""
    if len(slips) != 2:
        return slips
    a, b = slips
    near = abs(a.start - b.start) <= BOTH_FEET_S * fps

    def alike(x, y):
        return bool(x and y and np.sign(x) == np.sign(y) and 0.5 <= x / y <= 2.0)
    slide = not (near and alike(a.slide, b.slide))
    turn = not (near and alike(a.turn_deg, b.turn_deg))
    kept = [replace(s, slide=s.slide if slide else 0.0, turn_deg=s.turn_deg if turn else 0.0) for s in slips]
    out = [s for s in kept if s.slide or s.turn_deg]
    if not turn:            # both feet turned alike against the pelvis: its tracker, or a stance
        out.append(TrackerSlip("pelvis", min(a.start, b.start), max(a.end, b.end), 0.0,
                               -0.5 * (a.turn_deg + b.turn_deg), a.after and b.after))
    return out


def _moment(value, before, after, step, angle=False):
    """The frames ``(start, end)`` a slip happened between: the last planted frame before it and
    the first after.  value: ``(T,)`` the per-frame height or heading; before, after: the plants
    on either side; step: the change (radians with ``angle``, the value wrapped).  Within a
    plant (a foot that stood through it) the frame the value crossed half the step, else the
    swing between the two plants."""
    a0, a1 = before
    b0, b1 = after
    ref = np.median(value[a0:a1 + 1])
    moved = np.abs(wrap_angle(value - ref) if angle else value - ref) > abs(step) / 2
    tail = np.cumprod(moved[a0:a1 + 1][::-1])[::-1].astype(bool)        # moved to the plant's end
    if tail.any():
        f = a0 + int(np.argmax(tail))
        return max(f - 1, a0), f
    head = np.cumprod(~moved[b0:b1 + 1]).astype(bool)                   # not yet moved from its start
    if head.any() and not head.all():
        f = b0 + int(head.sum())
        return f - 1, f
    return int(a1), int(b0)


def correct_tracker_slips(targets, slips):
    """``targets`` with each slip's offset change taken out from it on (the module docstring),
    eased in (smoothstep) over its ``start``-``end`` frames; or, for a slip whose offsets fit
    the take ``after`` it, put in before it.  A slip not :attr:`~TrackerSlip.corrected` (a turn
    alone) is left as it is.  Returns new targets."""
    if not slips:
        return targets
    pos = dict(targets.pos)
    rot = dict(targets.rot)
    T = targets.num_frames
    f = np.arange(T, dtype=np.float64)
    for s in slips:
        x = np.clip((f - s.start) / max(s.end - s.start, 1), 0.0, 1.0)
        w = x * x * (3 - 2 * x) - (1.0 if s.after else 0.0)
        R = rot[s.device]
        pos[s.device] = pos[s.device] - (s.slide * w)[:, None] * R[:, :, 2]
        if not s.corrected:
            continue
        if s.turn_deg:
            Rz = axis_angle_rotation(np.tile(_Z, (T, 1)), -np.radians(s.turn_deg) * w)
            rot[s.device] = R @ Rz
    return replace(targets, pos=pos, rot=rot)


def tracker_slip_notes(slips, fps, t0=0.0) -> list:
    """The summary's notes, one per slip: ``"left foot tracker offset changed at 3.40-3.90 s
    (its strap slipped 6.8 cm up the shin): put right from then on"`` (``"... up to then"``
    when the offsets fit the take after it); for a turn alone, ``"right foot: planted, it turned
    30° against the hips at ... (...): not corrected; check that foot after it"``."""
    notes = []
    for s in slips:
        foot, span = s.device.replace('_', ' '), f"{t0 + s.start / fps:.2f}-{t0 + s.end / fps:.2f} s"
        if s.device == "pelvis":
            notes.append(f"pelvis tracker: both planted feet turned {abs(s.turn_deg):.0f}° against it at {span} "
                         f"and stayed so (its belt turned round the waist, or the stance changed): not corrected; "
                         f"check the hips {'before' if s.after else 'after'} it")
            continue
        if not s.corrected:
            notes.append(f"{foot}: planted, it turned {abs(s.turn_deg):.0f}° against the hips at {span} and stayed "
                         f"so (its tracker's strap turned round the shin, or the stance changed): not corrected; "
                         f"check that foot {'before' if s.after else 'after'} it")
            continue
        when = f"{foot} tracker offset changed at {span}"
        what = [f"{100 * abs(s.slide):.1f} cm {'up' if s.slide > 0 else 'down'} the shin"]
        if s.turn_deg:
            what.append(f"{abs(s.turn_deg):.0f}° round it")
        notes.append(f"{when} (its strap slipped {' and '.join(what)}): put right "
                     f"{'up to' if s.after else 'from'} then{'' if s.after else ' on'}")
    return notes
