"""Teleports and snap turns: VR apps that move the tracking space under the player.

Never imports bpy.

A VR app with locomotion logs world poses: when the player teleports, every device moves by the
same translation between two samples; on a snap turn (or a recentre) every device turns by the
same angle about the vertical axis.  No body moves so, but solved as they stand, such jumps tear
the pose apart around each (the bundled example moved 2.2 m at 3.5 s: the planted feet dragged
up to 2.2 m over 0.3 s, the knees 5-7 cm off for 2 s after, a hand 38 cm out of reach;
``tests/test_teleports.py``).

So before the solve :func:`find_rig_jumps` finds them and :func:`remove_rig_jumps` takes them out:
the motion after each jump is moved back by its inverse, so the take is one continuous motion.
After the solve :func:`restore_rig_jumps` puts them back on the solved body (its root, and the
tracker targets), so the character lands where the recording is, with the pose untouched; or
they stay out (the character's path continuous), as the user chooses.

A jump between two consecutive valid head samples ``a`` and ``b`` (times ``ta < tb``) is:

* a *teleport*: the head moves more than :data:`TELEPORT_MIN_M` and faster than
  :data:`TELEPORT_MIN_SPEED` (no head moves so in one sample at 30-120 Hz: a sprint is
  about 8 m/s, 0.07 m a sample at 120 Hz, 0.27 m at 30 Hz; a recentre, a guardian reset or a
  floor-height change moves the space 10-30 cm as well as metres);
* a *snap turn*: the head turns about the vertical more than :data:`TURN_MIN_DEG` and faster than
  :data:`TURN_MIN_RATE` (the fastest head turns reach about 800°/s; snap turns are 15-90° in
  one sample, so a 45° turn is found at 30 Hz and above, a 15° one at 80 Hz and above);

and it is kept when the head stays where it jumped (the next sample is nearer the new place
than the old: a tracking glitch of one sample comes back, and :mod:`.resample` removes it), and
the hands jumped with it: each tracked hand's first sample after the jump is nearer where the
jump would take its last sample before it than where it was (within :data:`HAND_TOLERANCE_M`
plus what a hand moves in that time), and at least one hand has a say: it has samples within
:data:`MAX_STEP_S` before and after the jump.  A head that jumps alone is a tracking error,
not the space moving; so is one that no hand can confirm: a headset picked up from a table (or
its tracking found again) while the controllers are still off jumps in one sample, and taken for
a teleport it would move the whole worn take onto the table (``tests/test_teleports.py``).  Such
a jump is left as recorded (a headset that lay still before it is pointed out by
:mod:`.headset_off`, with the trim that leaves it out).

A *smaller shift* (a recentre or a floor reset of :data:`SMALL_JUMP_MIN_M` to
:data:`TELEPORT_MIN_M`, slower than any head speed test can tell from motion) is found from what
the head's motion does not explain: its step less what its velocity just before and just after
carries it (:func:`_unexplained_steps`; exact for a constant acceleration, so real motion leaves
millimetres: at most 0.5 cm in the real Beat Saber replays), by more than a change of that
velocity within the step could leave (a hop's landing stops head and hands together: 4 cm in
one 30 fps step of HDM05's hops; the jump of the space leaves the velocity as it was), confirmed
by the hands: each
tracked hand's own unexplained step over the same moment agrees with the head's within
:data:`SMALL_JUMP_HAND_AGREE` of it, and at least one hand has a say.  It is taken as a
translation (a turn of under :data:`TURN_MIN_DEG` with it is not measured).  A hand in the middle
of a punch strays from that by centimetres, so such a shift can be missed then, never invented.

The jump's transform (``x -> R x + t``, R a turn about +Z; Blender axes, metres) is taken from
the head: its pose at ``tb`` against its pose at ``ta`` carried on by its velocity and turn rate
before the jump.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .features import rot_z
from .recording import Recording, TrackerStream
from .rotations import matrix_to_quat, quat_to_matrix, twist_angle, wrap_angle

_Z = np.array([0.0, 0.0, 1.0])

#: a teleport moves the head at least this far in one step (metres) ...
TELEPORT_MIN_M = 0.15
#: ... and faster than this (m/s), so that a step across a gap of lost tracking is not one
TELEPORT_MIN_SPEED = 8.0
#: a snap turn turns the head at least this much about the vertical (degrees) ...
TURN_MIN_DEG = 10.0
#: ... and faster than this (degrees/s)
TURN_MIN_RATE = 1200.0
#: consecutive head samples further apart than this (s) are not searched for jumps
MAX_STEP_S = 0.5
#: a hand's sample after a jump must be within this (metres) of where the jump takes it ...
HAND_TOLERANCE_M = 0.10
#: ... plus what a hand can move in the time between its two samples (m/s)
HAND_SPEED = 5.0
#: the samples on either side of a jump the head's velocity is taken from (s)
VELOCITY_SPAN_S = 0.1
#: a shift of the space under :data:`TELEPORT_MIN_M` is found down to this (metres): the head's
#: step less what its velocity just before and just after carries it (:func:`_unexplained_steps`)
SMALL_JUMP_MIN_M = 0.045
#: ... when each tracked hand's own unexplained step agrees with the head's within this fraction
#: of it (and better than no jump at all): hands moving fast stray from that by centimetres
SMALL_JUMP_HAND_AGREE = 0.5
#: what a solve does with them (:class:`.solve.SolveSettings` ``teleports``)
TELEPORT_CHOICES = ("keep", "remove", "ignore")


@dataclass(frozen=True)
class RigJump:
    """One jump of the tracking space.

    time: the first head sample after it (s, the recording clock); start: the last one before
    it.  rot: ``(3, 3)`` its turn about +Z; trans: ``(3,)`` metres; a point that stood still is
    at ``rot @ x + trans`` after it (Blender axes).  kind: ``"teleport"``, ``"snap turn"`` or
    ``"teleport and turn"``.  head_moved: metres the head moved in the jump, beyond its own motion
    (None where not measured): ``trans`` is the whole space's shift, which for a turn depends on
    how far the head is from the origin.
    """
    time: float
    start: float
    rot: np.ndarray
    trans: np.ndarray
    kind: str
    head_moved: float | None = None

    @property
    def turn_deg(self) -> float:
        return float(np.degrees(np.arctan2(self.rot[1, 0], self.rot[0, 0])))


def _yaw(R):
    """The turn about +Z of rotation(s) ``R`` (..., 3, 3): its twist about +Z, radians."""
    return twist_angle(R, _Z)


def _valid_samples(stream):
    ok = stream.valid & np.all(np.isfinite(stream.pos), -1) & np.all(np.isfinite(stream.quat), -1)
    return np.nonzero(ok)[0]


def _head_motion_before(t, p, R, k, first=0):
    """Head velocity (m/s) and turn rate about +Z (rad/s) over the samples before index ``k``,
    from index ``first`` on (the first sample after the jump before: a span across it would take
    that jump for motion)."""
    j = k - 1
    i = j
    while i > first and t[j] - t[i - 1] <= VELOCITY_SPAN_S:
        i -= 1
    if i == j:
        return np.zeros(3), 0.0
    dt = t[j] - t[i]
    v = (p[j] - p[i]) / dt
    w = wrap_angle(_yaw(R[j] @ R[i].T)) / dt
    return v, w


def _within(t, lo, hi, increasing):
    """Indices ``k`` (ascending) of ``t`` ``(N,)`` s with ``lo <= t[k] <= hi``.  ``increasing``:
    ``t`` never decreases, so the range is found by bisection (O(log N), not a pass over the
    take: a detector asking this once per jump stays linear in the take's length); the same
    comparisons decide the ends, so the answer is the same either way."""
    if not increasing:
        return np.nonzero((t >= lo) & (t <= hi))[0]
    return np.arange(np.searchsorted(t, lo, side="left"), np.searchsorted(t, hi, side="right"))


def _increasing(t) -> bool:
    """True when the times ``t`` ``(N,)`` never decrease (every reader's output; a stream built
    by hand may not be)."""
    return bool(np.all(np.diff(t) >= 0))


def _hand_samples(stream):
    """``(valid indices (M,), their times (M,) s, times never decrease)`` of a hand stream, for
    :func:`_hand_check` (computed once per take, not once per jump)."""
    idx = _valid_samples(stream)
    t = stream.time[idx]
    return idx, t, _increasing(t)


def _hand_check(stream, ta, tb, rot, trans, samples=None):
    """``True`` / ``False`` when a hand around ``(ta, tb)`` moved with / against the jump, ``None``
    when it has no valid samples close enough to tell.  samples: the stream's
    :func:`_hand_samples` (None: found here)."""
    idx, t, increasing = samples if samples is not None else _hand_samples(stream)
    if idx.size < 2:
        return None
    before = idx[_within(t, ta - MAX_STEP_S, ta + 1e-9, increasing)]
    after = idx[_within(t, tb - 1e-9, tb + MAX_STEP_S, increasing)]
    if before.size == 0 or after.size == 0:
        return None
    i, j = before[-1], after[0]
    h0, h1 = stream.pos[i], stream.pos[j]
    reach = HAND_TOLERANCE_M + HAND_SPEED * (stream.time[j] - stream.time[i])
    jumped = np.linalg.norm(rot @ h0 + trans - h1)
    stayed = np.linalg.norm(h1 - h0)
    return bool(jumped < reach and jumped < stayed)


def _unexplained_steps(t, p):
    """What motion does not explain of each step between consecutive samples.

    t: ``(N,)`` s, increasing; p: ``(N, 3)`` m.  Returns ``(steps (N - 1, 3), slack (N - 1,))``
    metres: for samples ``a``, ``b = a + 1``, ``p[b] - p[a] - (t[b] - t[a]) (v_before +
    v_after) / 2``, the velocities over :data:`VELOCITY_SPAN_S` before ``a`` and after ``b``
    (exact for a constant acceleration; a jump of the space between ``a`` and ``b`` leaves both
    velocities as they were, so it is all of it), and what a change of velocity within the step
    can leave unexplained, ``(t[b] - t[a]) |v_after - v_before| / 2`` (a hop's landing stops
    head and hands together within one 30 fps step: up to 4 cm).  NaN where a span runs off the
    take or across a gap of more than twice the span, or where the step itself is longer than
    :data:`MAX_STEP_S`."""
    n = len(t)
    out = np.full((max(n - 1, 0), 3), np.nan)
    slack = np.full(max(n - 1, 0), np.nan)
    if n < 4:
        return out, slack
    a = np.arange(n - 1)
    b = a + 1
    ia = np.searchsorted(t, t[a] - VELOCITY_SPAN_S, side="right") - 1
    ib = np.searchsorted(t, t[b] + VELOCITY_SPAN_S, side="left")
    ok = (ia >= 0) & (ib < n) & (t[b] - t[a] <= MAX_STEP_S)
    ia, ib = np.clip(ia, 0, n - 1), np.clip(ib, 0, n - 1)
    ok &= (t[a] - t[ia] <= 2 * VELOCITY_SPAN_S) & (t[ib] - t[b] <= 2 * VELOCITY_SPAN_S)
    a, b, ia, ib = a[ok], b[ok], ia[ok], ib[ok]
    v_before = (p[a] - p[ia]) / (t[a] - t[ia])[:, None]
    v_after = (p[ib] - p[b]) / (t[ib] - t[b])[:, None]
    out[a] = p[b] - p[a] - (t[b] - t[a])[:, None] * (v_before + v_after) / 2
    slack[a] = (t[b] - t[a]) * np.linalg.norm(v_after - v_before, axis=-1) / 2
    return out, slack


def _small_jumps(t, p, hands, big):
    """Shifts of the space under :data:`TELEPORT_MIN_M` (see :func:`find_rig_jumps`): head
    sample pairs ``(a, a + 1)`` (indices into ``t``, ``p``, the head's valid samples) whose
    unexplained step (:func:`_unexplained_steps`), less what a change of velocity within it can
    leave, is at least :data:`SMALL_JUMP_MIN_M`, the
    largest within :data:`VELOCITY_SPAN_S` either side, not within that of a jump in ``big``
    (times), and matched by every tracked hand's own (at least one hand must have a say: the
    head alone may be a tracking error).  Returns ``[(a, d (3,))]``."""
    d, slack = _unexplained_steps(t, p)
    size = np.nan_to_num(np.linalg.norm(d, axis=-1), nan=0.0)
    cand = np.nonzero(size - np.nan_to_num(slack, nan=np.inf) >= SMALL_JUMP_MIN_M)[0]
    if cand.size == 0:
        return []
    hand_steps = []
    for s in hands:
        idx = _valid_samples(s)
        if idx.size >= 4:
            hand_steps.append((s.time[idx], _unexplained_steps(s.time[idx], s.pos[idx])[0]))
    out = []
    big = np.sort(np.asarray(big, dtype=np.float64))
    steps = t[:-1]
    increasing = _increasing(steps)
    for a in cand:
        # the steps within VELOCITY_SPAN_S of this one: bisected a little wider, then the exact
        # test on those alone (one pass over the take per candidate would be quadratic)
        near = _within(steps, t[a] - VELOCITY_SPAN_S - 1e-6, t[a] + VELOCITY_SPAN_S + 1e-6, increasing)
        near = near[np.abs(steps[near] - t[a]) <= VELOCITY_SPAN_S]
        close = big[_within(big, t[a + 1] - 2 * VELOCITY_SPAN_S - 1e-6, t[a + 1] + 2 * VELOCITY_SPAN_S + 1e-6, True)]
        if size[a] < size[near].max() or (close.size and np.any(np.abs(close - t[a + 1]) <= 2 * VELOCITY_SPAN_S)):
            continue
        says = []
        for ht, hd in hand_steps:
            # the hand's steps over the jump: from its last sample by ta to its first from tb, one
            # step, or two with a sample between (on either side of the jump: the better one)
            k = np.arange(np.searchsorted(ht, t[a] + 1e-9, side="right") - 1,
                          np.searchsorted(ht, t[a + 1] - 1e-9, side="left"))
            k = k[(k >= 0) & (k < len(hd))]
            k = k[np.all(np.isfinite(hd[k]), -1)] if k.size else k
            if k.size == 0 or ht[k[0]] < t[a] - MAX_STEP_S:
                continue                                                 # no say
            miss = np.linalg.norm(hd[k] - d[a], axis=-1)
            best = int(np.argmin(miss))
            says.append(bool(miss[best] < SMALL_JUMP_HAND_AGREE * size[a]
                             and miss[best] < np.linalg.norm(hd[k[best]])))
        if says and all(says):
            out.append((int(a), d[a].copy()))
    return out


def find_rig_jumps(recording: Recording, unconfirmed=None) -> list:
    """The teleports and snap turns of ``recording`` (see the module docstring), in time order:
    a list of :class:`RigJump`.  Empty without a head stream, or without a hand stream (every
    jump needs a tracked hand moving with it).  ``unconfirmed``: a list that is given the
    :class:`RigJump` s of the head that no hand could confirm or refute (no hand samples on both
    sides), left as recorded (:func:`unconfirmed_jumps_note`)."""
    head = recording.streams.get("head")
    if head is None or len(head) < 3:
        return []
    idx = _valid_samples(head)
    if idx.size < 3:
        return []
    t = head.time[idx]
    p = head.pos[idx]
    R = quat_to_matrix(head.quat[idx])
    hands = [recording.streams[d] for d in ("left_hand", "right_hand") if d in recording.streams]
    hand_samples = [_hand_samples(s) for s in hands]
    jumps = []
    after = 0                      # the first head sample after the last jump found
    dt = np.diff(t)
    step = np.linalg.norm(p[1:] - p[:-1], axis=-1)
    turn = np.abs(wrap_angle(_yaw(R[1:] @ np.swapaxes(R[:-1], -1, -2))))
    candidate = (dt <= MAX_STEP_S) & (
        ((step > TELEPORT_MIN_M) & (step > TELEPORT_MIN_SPEED * dt))
        | ((turn > np.radians(TURN_MIN_DEG)) & (turn > np.radians(TURN_MIN_RATE) * dt)))
    for c in np.nonzero(candidate)[0]:
        a, b = c, c + 1
        v, w = _head_motion_before(t, p, R, b, after)
        h = t[b] - t[a]
        yaw = wrap_angle(_yaw(R[b] @ R[a].T) - w * h)
        rot = rot_z(yaw)
        trans = p[b] - rot @ (p[a] + v * h)
        moved = np.linalg.norm(p[b] - (p[a] + v * h))
        teleport = moved > TELEPORT_MIN_M
        turned = abs(np.degrees(yaw)) > TURN_MIN_DEG
        if not (teleport or turned):
            continue
        if b + 1 < len(t) and t[b + 1] - t[b] <= MAX_STEP_S:     # the head stays where it jumped
            back_p = np.linalg.norm(p[b + 1] - p[a]) < np.linalg.norm(p[b + 1] - p[b])
            back_r = abs(wrap_angle(_yaw(R[b + 1] @ R[a].T))) < abs(wrap_angle(_yaw(R[b + 1] @ R[b].T)))
            if (teleport and back_p) or (turned and not teleport and back_r):
                continue
        checks = [_hand_check(s, t[a], t[b], rot, trans, hs) for s, hs in zip(hands, hand_samples)]
        kind = "teleport and turn" if teleport and turned else ("teleport" if teleport else "snap turn")
        if False in checks or True not in checks:      # a hand moved against it, or none can tell
            if unconfirmed is not None and False not in checks:
                unconfirmed.append(RigJump(float(t[b]), float(t[a]), rot, trans, kind, float(moved)))
            continue
        jumps.append(RigJump(float(t[b]), float(t[a]), rot, trans, kind))
        after = b
    small = [RigJump(float(t[a + 1]), float(t[a]), np.eye(3), d, "teleport")
             for a, d in _small_jumps(t, p, hands, [j.time for j in jumps])]
    return sorted(jumps + small, key=lambda j: j.time)


def _segment_transforms(jumps):
    """Cumulative ``(R, t)`` of the space after each jump: ``[(I, 0), after jump 1, ...]``."""
    out = [(np.eye(3), np.zeros(3))]
    for j in jumps:
        R0, t0 = out[-1]
        out.append((j.rot @ R0, j.rot @ t0 + j.trans))
    return out


def _segments(times, jumps):
    """Index of the space each time is in: the number of jumps at or before it."""
    edges = np.array([j.time for j in jumps])
    return np.searchsorted(edges, np.asarray(times) + 1e-9, side="right")


def _by_segment(seg, n):
    """``[indices (ascending) where seg == k for k in range(n)]``: one sort for all the
    segments, not a pass over the take per jump (a take with a snap turn every few seconds
    has thousands)."""
    order = np.argsort(seg, kind="stable")
    bounds = np.searchsorted(seg[order], np.arange(n + 1), side="left")
    return [order[bounds[k]:bounds[k + 1]] for k in range(n)]


def remove_rig_jumps(recording: Recording, jumps) -> Recording:
    """A copy of ``recording`` with the motion after each jump moved back by it: one continuous
    motion in the space of the first sample.  A hand or foot sample between the head's two
    samples around a jump goes with whichever side it is nearer to."""
    if not jumps:
        return recording
    W = _segment_transforms(jumps)
    streams = {}
    for d, s in recording.streams.items():
        seg = _segments(s.time, jumps)
        pos = s.pos.copy()
        quat = s.quat.copy()
        if d != "head":            # samples between the head's two around a jump: the nearer side
            increasing = _increasing(s.time)
            for k, j in enumerate(jumps, start=1):
                Ra, ta = W[k - 1]
                Rb, tb = W[k]
                between = _within(s.time, j.start, j.time, increasing)      # then the strict test
                between = between[(s.time[between] > j.start + 1e-9) & (s.time[between] < j.time - 1e-9)]
                for i in between:
                    if i == 0 or not np.all(np.isfinite(s.pos[i - 1])):
                        continue
                    Rp, tp = W[seg[i - 1]]
                    ref = Rp.T @ (s.pos[i - 1] - tp)
                    if np.linalg.norm(Rb.T @ (s.pos[i] - tb) - ref) < np.linalg.norm(Ra.T @ (s.pos[i] - ta) - ref):
                        seg[i] = k
        for k, m in enumerate(_by_segment(seg, len(W))):
            if k == 0 or not m.size:
                continue
            Rk, tk = W[k]
            pos[m] = (pos[m] - tk) @ Rk           # Rk.T @ (x - tk), row-wise
            q = quat[m]
            ok = np.all(np.isfinite(q), -1)
            if ok.any():
                quat[m[ok]] = matrix_to_quat(Rk.T @ quat_to_matrix(q[ok]))
        streams[d] = TrackerStream(d, s.time.copy(), pos, quat, s.valid.copy())
    return Recording(streams=streams, source=recording.source, metadata=dict(recording.metadata),
                     warnings=list(recording.warnings))


def restore_rig_jumps(result, jumps):
    """Put ``jumps`` back on a :class:`.pose_result.PoseResult` solved without them: each frame
    after a jump moved by it (the root's position and orientation, and the tracker targets), the
    pose itself untouched.  Returns a new result; ``result`` is not changed."""
    import dataclasses
    from .pose_result import TrackerTargets
    from .skeleton import J
    if not jumps:
        return result
    W = _segment_transforms(jumps)
    T = result.num_frames
    frame_times = result.t0 + np.arange(T) / result.fps
    seg = _segments(frame_times, jumps)
    root_pos = result.root_pos.copy()
    local_rot = result.local_rot.copy()
    targets = result.targets
    if targets is not None:
        tpos = {d: v.copy() for d, v in targets.pos.items()}
        trot = {d: v.copy() for d, v in targets.rot.items()}
    for k, m in enumerate(_by_segment(seg, len(W))):
        if k == 0 or not m.size:
            continue
        Rk, tk = W[k]
        root_pos[m] = root_pos[m] @ Rk.T + tk
        local_rot[m, J["pelvis"]] = Rk @ local_rot[m, J["pelvis"]]
        if targets is not None:
            for d in tpos:
                tpos[d][m] = tpos[d][m] @ Rk.T + tk
                trot[d][m] = Rk @ trot[d][m]
    out = dataclasses.replace(result, root_pos=root_pos, local_rot=local_rot, _fk=None)
    if targets is not None:
        out.targets = TrackerTargets(fps=targets.fps, pos=tpos, rot=trot, valid=dict(targets.valid))
    return out


def unconfirmed_jumps_note(jumps, t0=0.0):
    """The summary's note on the head's jumps no tracked hand could confirm (:func:`find_rig_jumps`'s
    ``unconfirmed``), left as recorded: ``"the head jumped 0.92 m at 3.00 s with no controller
    tracked around it, so it is left as recorded, not taken for a teleport (a headset picked up,
    its tracking found again)"`` (the distance the head's own, :attr:`RigJump.head_moved`; a turn
    with it as ``"0.50 m (turning 90°)"``), the time in seconds from ``t0`` (the take's start on the
    recording clock); ``None`` without any."""
    if not jumps:
        return None
    j = jumps[0]
    turn = f"{abs(j.turn_deg):.0f}°"
    if "teleport" in j.kind:           # the head's own jump: trans also holds the turn about the origin
        size = f"{j.head_moved if j.head_moved is not None else np.linalg.norm(j.trans):.2f} m"
        size += f" (turning {turn})" if j.kind == "teleport and turn" else ""
    else:
        size = turn
    more = f" (and {len(jumps) - 1} more)" if len(jumps) > 1 else ""
    return (f"the head jumped {size} at {j.time - t0:.2f} s{more} with no controller tracked around it, so it is left "
            f"as recorded, not taken for a teleport (a headset picked up, its tracking found again)")


def rig_jumps_note(jumps, mode="keep", t0=0.0):
    """The summary's note: ``"2 teleports and 3 snap turns (first at 12.40 s) solved as one motion
    and put back"``, the time in seconds from ``t0`` (the take's start on the recording clock, as
    the summary's other times); ``None`` without jumps."""
    if not jumps:
        return None
    n_tel = sum(1 for j in jumps if "teleport" in j.kind)
    n_turn = sum(1 for j in jumps if "turn" in j.kind)
    parts = []
    if n_tel:
        parts.append(f"{n_tel} teleport{'s' if n_tel > 1 else ''}")
    if n_turn:
        parts.append(f"{n_turn} snap turn{'s' if n_turn > 1 else ''}")
    what = " and ".join(parts)
    how = "solved as one motion and put back" if mode == "keep" else "taken out (the path is continuous)"
    return f"{what} (first at {jumps[0].time - t0:.2f} s) {how}"
