"""Resample tracker streams onto a common frame grid, bridging gaps.  Never imports bpy.

Each device of a :class:`~.recording.Recording` has its own timestamps.
:func:`resample` puts all devices on one grid (frame ``k`` at
``t0 + k / fps`` seconds of the recording clock): positions are interpolated
linearly, rotations by slerp after making the quaternion series
sign-continuous.  Everything is vectorised (``np.searchsorted``/``np.interp``);
there is no Python loop over samples or frames.

A sample is *usable* when its ``valid`` flag is set, its position and
quaternion are finite and the quaternion is not zero, and it is not a
*frozen* repeat: when a device repeats exactly the same pose for longer
than ``freeze_s`` while another device moves, the repeats after the first
are stale (tracking froze) and are not used.  Two more ways real devices
lose tracking are caught: a position that drops to the tracking origin
(``|p| < 1 mm`` while the device's median distance from it is over 30 cm;
reason ``'origin'``), and a *jump*: a sample that is more than ``jump_m``
away from both its usable neighbours while they are close to each other
(a spike when tracking returns; reason ``'jump'``).

A *gap* is an interval between two consecutive usable samples of a device
that either had unusable samples in it or is longer than ``gap_factor``
nominal sample intervals (missing rows).  Gaps are bridged by the same
interpolation (hold at the ends of the data) and reported in a
:class:`GapReport`: ``start``/``end`` are the times of the usable samples
around the gap, ``duration = end - start`` is the bridged time.  Frames
strictly inside a gap, or before a device's first / after its last usable
sample (held), get ``valid = False``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .plain import shown
from .devices import DEVICES, HAND_DEVICES, REQUIRED_DEVICES
from .recording import Recording, RecordingError, TrackerStream, increasing_mask, time_spikes
from .rotations import normalize, quat_continuous, quat_slerp
from .runs import run_bounds


#: head-joint/HMD height range (metres above the floor) accepted by the units check
HEAD_HEIGHT_RANGE = (0.5, 3.0)
#: the percentile of the head's height over a take that is its standing height: the performer
#: stands for a tenth of the take at least (the units check; :func:`.solve.standing_head_height`
#: sizes a body without a calibration pose by it).  Not the median: a take spent mostly on the
#: floor (HDM05's lie-down clips: 7 of 20 have the head's median 0.16-0.49 m up) is no units error
STANDING_PERCENTILE = 90


@dataclass
class Gap:
    """One bridged interval of one device.

    start/end: seconds (recording clock) of the usable samples around the gap
    (for ``reason='start'``: the grid start and the first usable sample; for
    ``'end'``: the last usable sample and the grid end).
    reason: ``'missing'`` (no rows), ``'invalid'`` (valid=0), ``'nan'``
    (non-finite values), ``'frozen'`` (repeated pose), ``'origin'`` (dropped to
    the tracking origin), ``'jump'`` (a spike away from its neighbours), ``'start'``/``'end'``
    (device not tracked at the start/end of the grid).
    samples: number of unusable samples inside the gap.
    """
    device: str
    start: float
    end: float
    reason: str
    samples: int = 0

    @property
    def duration(self) -> float:
        return float(self.end - self.start)

    def __str__(self):
        return (f"{self.device}: {self.reason} {self.start:.3f}-{self.end:.3f} s "
                f"({self.duration:.3f} s{', %d samples' % self.samples if self.samples else ''})")


@dataclass
class GapReport:
    """What :func:`resample` found and repaired.

    fps, t0, t_end (seconds), num_frames: the grid.  gaps: list of
    :class:`Gap`.  sign_flips: device → number of quaternion sign flips
    removed.  warnings: the recording's warnings plus resampling notes.
    """
    fps: float
    t0: float
    t_end: float
    num_frames: int
    devices: tuple = ()
    gaps: list = field(default_factory=list)
    sign_flips: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    def for_device(self, device):
        return [g for g in self.gaps if g.device == device]

    def total_gap_time(self, device) -> float:
        return float(sum(g.duration for g in self.for_device(device)))

    def summary(self) -> str:
        lines = [f"{self.num_frames} frames at {self.fps:g} fps, {self.t0:.3f}-{self.t_end:.3f} s, "
                 f"devices {', '.join(self.devices)}"]
        lines += [str(g) for g in self.gaps]
        lines += self.warnings
        return "\n".join(lines)

    def __str__(self):
        return self.summary()


def check_head_height(height, path=None, units=None, floor=0.0):
    """Raise :class:`RecordingError` when a standing head height (metres, the recording's z:
    :data:`STANDING_PERCENTILE`) is implausibly far above ``floor`` (the floor's height in the
    recording, metres).

    Suggests the unit that would make it plausible, or the floor setting.
    """
    lo, hi = HEAD_HEIGHT_RANGE
    h = float(height) - float(floor)
    if lo <= h <= hi:
        return
    loaded = f" (read as units={units})" if units else ""
    where = f"the floor at {float(floor):+.2f} m" if floor else "the floor"
    if h > hi:
        hint = None
        for name, factor in (("centimetres", 100.0), ("millimetres", 1000.0)):
            if lo <= h / factor <= hi:
                hint = (name, "cm" if factor == 100 else "mm")
                break
        if hint:
            msg = (f"head is {h:.0f} m above {where}{loaded}: positions look like {hint[0]}; "
                   f"set Units to {hint[0].capitalize()} (--units {hint[1]})")
        else:
            msg = (f"head is {h:.1f} m above {where}{loaded}: the units, the axes or the floor are "
                   f"wrong (positions should be metres; set the Floor, --floor, if it is not at 0)")
    else:
        hint = None
        for name, factor in (("were scaled down 100x", 100.0), ("were scaled down 1000x", 1000.0)):
            if lo <= h * factor <= hi:
                hint = name
                break
        if hint and units and units != "m":
            msg = (f"head is {h:.3f} m above {where}{loaded}: positions {hint}; they look like metres "
                   f"already: set Units to Metres (--units m)")
        else:
            msg = (f"head is only {h:.2f} m above {where}{loaded}: check the axes (height is the file's "
                   f"up axis) and the floor (an OpenXR LOCAL space puts the origin at the starting head "
                   f"pose, not on the floor): set the Floor (--floor) to its height (At Height), or to "
                   f"Under Performer (--floor height) to put it under a performer of the typed height")
    raise RecordingError(msg, path=path)


#: median sample steps (in the file's time unit) read as milliseconds, microseconds, nanoseconds:
#: 5-500 Hz trackers; steps of 0.2-2 (0.5-5 Hz in seconds) are left as seconds
TIME_UNIT_STEPS = (("milliseconds", 1e-3, (2.0, 200.0)), ("microseconds", 1e-6, (2e3, 2e5)),
                   ("nanoseconds", 1e-9, (2e6, 2e8)))


def seconds_from_time_units(recording: Recording) -> Recording:
    """``recording`` with its times in seconds: a recorder that wrote milliseconds (or micro-,
    nanoseconds: Unity's and Android's clocks) has its tracker samples 11 "seconds" apart, and
    solved as they stand a 7 s take becomes a 2-hour one.  When the devices' median sample step
    falls in one of :data:`TIME_UNIT_STEPS` the times are scaled to seconds, on a copy, with a
    warning naming the unit and the rate (the solve summary shows it); otherwise ``recording``
    is returned as it is."""
    steps = [float(np.median(np.diff(s.time))) for s in recording.streams.values() if len(s) > 2]
    steps = [x for x in steps if np.isfinite(x) and x > 0]
    if not steps:
        return recording
    step = float(np.median(steps))
    for name, factor, (lo, hi) in TIME_UNIT_STEPS:
        if lo <= step <= hi:
            streams = {d: TrackerStream(d, s.time * factor, s.pos, s.quat, s.valid)
                       for d, s in recording.streams.items()}
            note = (f"times read as {name}: samples every {step:g} of them ({1.0 / (step * factor):.0f} Hz; "
                    f"as seconds they would be {1.0 / step:.2g} Hz); write seconds to be sure")
            return Recording(streams=streams, source=recording.source, metadata=dict(recording.metadata),
                             warnings=list(recording.warnings) + [note])
    return recording


#: a required device whose last usable sample comes this many seconds or more before the head's
#: no longer ends the take (:func:`resample`)
END_HOLD_S = 0.25


def _frozen(t, pos, quat, others, freeze_s, move_tol):
    """Indices (into the usable-sample arrays) of stale repeats."""
    n = t.shape[0]
    if n < 3:
        return np.zeros(0, dtype=np.int64)
    same = (np.all(np.abs(pos[1:] - pos[:-1]) <= 1e-9, -1)
            & np.all(np.abs(quat[1:] - quat[:-1]) <= 1e-9, -1))
    if not same.any():
        return np.zeros(0, dtype=np.int64)
    starts, ends = run_bounds(same)             # same[i] True from starts to ends-1: samples starts..ends identical
    dur = t[ends] - t[starts]
    long_ = np.nonzero(dur > freeze_s)[0]
    out = []
    for k in long_:                              # loop over long runs only (few)
        a, b = t[starts[k]], t[ends[k]]
        moved = False
        for (to, po) in others:
            i0, i1 = np.searchsorted(to, [a, b], side="left")
            i1 = min(i1 + 1, to.shape[0])
            if i1 - i0 >= 2 and np.max(np.ptp(po[i0:i1], axis=0)) > move_tol:
                moved = True
                break
        if moved:
            out.append(np.arange(starts[k] + 1, ends[k] + 1))
    return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


def _jumps(pos, jump_m):
    """Indices of single-sample spikes: further than ``jump_m`` from both neighbours while the
    neighbours are within ``jump_m / 2`` of each other."""
    if pos.shape[0] < 3:
        return np.zeros(0, dtype=np.int64)
    prev = np.linalg.norm(pos[1:-1] - pos[:-2], axis=-1)
    nxt = np.linalg.norm(pos[1:-1] - pos[2:], axis=-1)
    across = np.linalg.norm(pos[2:] - pos[:-2], axis=-1)
    return np.nonzero((prev > jump_m) & (nxt > jump_m) & (across < 0.5 * jump_m))[0] + 1


#: a frame grid may hold this many times as many frames as the best-sampled device has usable
#: samples (and at least :data:`EMPTY_GRID_MIN_S` seconds) before :func:`resample` refuses it: a
#: take that is mostly time without samples has a corrupt timestamp, not a recording
EMPTY_GRID_RATIO = 100.0
EMPTY_GRID_MIN_S = 600.0


def _one_hand_absent(absent, required, devices):
    """True when what is ``absent`` of the ``required`` devices is one hand, the other hand and the
    head being in the recording's ``devices``: the solve then hangs that arm (a controller off or
    never seen) instead of refusing the take."""
    hands = [d for d in absent if d in HAND_DEVICES]
    return (len(absent) == 1 and len(hands) == 1 and "head" in devices
            and all(h in devices for h in HAND_DEVICES if h not in absent))


def _check_grid_length(prep, t0, t1, fps, path):
    """Raise :class:`RecordingError` when the grid from ``t0`` to ``t1`` seconds at ``fps`` would be
    mostly empty (see :data:`EMPTY_GRID_RATIO`), naming the longest step between usable samples."""
    frames = (t1 - t0) * fps
    samples = max(int(P["ok"].sum()) for P in prep.values())
    if frames <= max(EMPTY_GRID_RATIO * samples, EMPTY_GRID_MIN_S * fps):
        return
    step, where = -1.0, ""
    for d, P in prep.items():
        idx = np.nonzero(P["ok"])[0]
        t = P["t"][idx]
        if t.size > 1:
            k = int(np.argmax(np.diff(t)))
            if t[k + 1] - t[k] > step:
                step = float(t[k + 1] - t[k])
                where = (f"{d}'s time jumps from {t[k]:.3f} s to {t[k + 1]:.6g} s between its samples "
                         f"{int(idx[k]) + 1} and {int(idx[k + 1]) + 1}")
    raise RecordingError(f"the take would span {t1 - t0:.6g} s ({frames:.3g} frames at {fps:g} fps) for "
                         f"{samples} samples: {where}; a corrupt or wrong timestamp? (--start / --end, "
                         f"Trim in the panel, solve the part before or after it)", path=path)


def _unusable_why(valid, finite, nonzero):
    """What left a device without a usable sample, for the error: ``"all invalid or NaN: 12
    marked not tracked, 300 with a zero quaternion (no orientation: qw, qx, qy, qz all 0)"``."""
    parts = []
    for n, what in ((int((~valid).sum()), "marked not tracked"),
                    (int((valid & ~finite).sum()), "with not-a-number values"),
                    (int((valid & finite & ~nonzero).sum()),
                     "with a zero quaternion (no orientation: qw, qx, qy, qz all 0)")):
        if n:
            parts.append(f"{n} {what}")
    rest = int(valid.size) - int((~valid | ~finite | ~nonzero).sum())
    if rest:
        parts.append(f"{rest} at the tracking origin or spikes")
    return "all invalid or NaN: " + ", ".join(parts) if parts else "none in the file"


def resample(recording: Recording, fps, t_start=None, t_end=None, required=REQUIRED_DEVICES,
             gap_factor=3.0, freeze_s=0.1, move_tol=0.002, check_units=True, jump_m=0.25, floor=0.0):
    """Resample every device of ``recording`` onto one frame grid.

    recording: a :class:`Recording` (Blender axes, metres).
    fps: frames per second of the grid.
    t_start, t_end: grid limits in seconds of the recording clock; default:
    the first usable sample of any device, and the earliest last usable sample
    of the ``required`` devices, or the head's when a hand's last sample is
    more than :data:`END_HOLD_S` before it (the hand is held, and a solve lets
    its arm hang, :mod:`.lost_hands`: no head motion is dropped).
    required: devices that must be present (default head and both hands).
    gap_factor: a step between usable samples longer than this many nominal
    intervals (median step of the device) is a gap.
    freeze_s, move_tol: a pose repeated exactly for more than ``freeze_s``
    seconds while another device moves more than ``move_tol`` metres is frozen
    (not looked for when ``recording.metadata["exact"]``: keyed scene objects
    hold still exactly).
    jump_m: metres a sample may stand off both neighbours before it is a jump.
    check_units: raise when the standing head height (:data:`STANDING_PERCENTILE`) above
    ``floor`` (the floor's height in the recording, metres; None: not known yet, no check) is
    outside 0.5-3 m (see :func:`check_head_height`).

    Returns ``(times, pos, quat, valid, report)``: ``times`` ``(T,)`` seconds;
    ``pos`` device → ``(T, 3)`` metres; ``quat`` device → ``(T, 4)`` wxyz,
    sign-continuous; ``valid`` device → ``(T,)`` bool (False on bridged/held
    frames); ``report`` a :class:`GapReport`.
    """
    path = recording.source or None
    fps = float(fps)
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be positive, got {shown(fps)}")
    missing = [d for d in required if d not in recording.streams]
    meta = recording.metadata or {}
    # a hand with no rows hangs only where no rows were left out under other names (a misspelt
    # device) and the devices were not chosen by hand (scene objects: a slot left empty)
    rows_may_lack = not meta.get("ignored_devices") and "objects" not in meta
    if missing and not (rows_may_lack and _one_hand_absent(missing, required, recording.devices)):
        ignored = meta.get("ignored_devices") or []
        also = f"; rows of {', '.join(shown(n) for n in ignored)} were left out: not device names" if ignored else ""
        raise RecordingError(f"the recording has no {', '.join(missing)} samples "
                             f"(devices present: {', '.join(recording.devices) or 'none'}{also})", path=path)
    warnings = list(recording.warnings)
    absent = list(missing)              # a required hand with no usable sample: its arm hangs

    # --- usable samples per device
    prep = {}
    for d in recording.devices:
        s = recording.streams[d]
        inc = increasing_mask(s.time)
        if not inc.all():
            n_spikes = int(time_spikes(s.time).sum())
            warnings.append(f"{d}: {int((~inc).sum())} sample(s) with non-increasing time ignored"
                            + (f" ({n_spikes} with a time leaping ahead of the samples on either side: "
                               "a corrupt timestamp)" if n_spikes else ""))
            s = s.select(inc)
        finite = np.all(np.isfinite(s.pos), -1) & np.all(np.isfinite(s.quat), -1)
        nonzero = np.linalg.norm(np.where(np.isfinite(s.quat), s.quat, 0.0), axis=-1) > 1e-6
        reason = np.full(len(s), "", dtype=object)
        reason[~s.valid] = "invalid"
        reason[s.valid & ~(finite & nonzero)] = "nan"
        ok = s.valid & finite & nonzero
        if ok.any():
            dist = np.linalg.norm(np.where(finite[:, None], s.pos, 0.0), axis=-1)
            at_origin = ok & (dist < 1e-3) & (np.median(dist[ok]) > 0.3)
            reason[at_origin] = "origin"
            ok &= ~at_origin
            idx = np.nonzero(ok)[0]
            spikes = idx[_jumps(s.pos[idx], jump_m)]
            reason[spikes] = "jump"
            ok[spikes] = False
        if ok.sum() == 0:
            if d in required and not _one_hand_absent(absent + [d], required, recording.devices):
                raise RecordingError(f"{d} has no usable samples ({_unusable_why(s.valid, finite, nonzero)})",
                                     path=path)
            if d in required:
                absent.append(d)
            else:
                warnings.append(f"{d}: no usable samples; device dropped")
            continue
        prep[d] = dict(t=s.time, ok=ok, reason=reason, pos=s.pos, quat=s.quat)

    # --- frozen repeats (needs all devices' usable samples)
    for d, P in prep.items():
        idx = np.nonzero(P["ok"])[0]
        others = [(Q["t"][Q["ok"]], Q["pos"][Q["ok"]]) for e, Q in prep.items() if e != d]
        if (recording.metadata or {}).get("exact"):
            break                                # a keyed pose held still is not a lost tracker
        fr = _frozen(P["t"][idx], P["pos"][idx], P["quat"][idx], others, freeze_s, move_tol)
        if fr.size:
            P["ok"][idx[fr]] = False
            P["reason"][idx[fr]] = "frozen"

    # --- units sanity check
    if check_units and floor is not None and "head" in prep:
        P = prep["head"]
        check_head_height(np.percentile(P["pos"][P["ok"], 2], STANDING_PERCENTILE), path=path,
                          units=recording.metadata.get("units"), floor=floor)

    # --- grid
    firsts = {d: P["t"][P["ok"]][0] for d, P in prep.items()}
    lasts = {d: P["t"][P["ok"]][-1] for d, P in prep.items()}
    t0 = float(min(firsts.values())) if t_start is None else float(t_start)
    if t_end is None:
        present = [d for d in required if d in lasts]
        t1 = float(min(lasts[d] for d in present)) if present else float(max(lasts.values()))
        if "head" in required and "head" in lasts and lasts["head"] - t1 > END_HOLD_S:
            t1 = float(lasts["head"])            # a hand lost before the end: held, not the take cut
    else:
        t1 = float(t_end)
    if not (t1 >= t0):
        raise RecordingError(f"no time covered by all of {', '.join(required)}: grid would end at "
                             f"{t1:.3f} s before it starts at {t0:.3f} s", path=path)
    _check_grid_length(prep, t0, t1, fps, path)
    # 1e-3 frame of slack: timestamps written with 6 decimals must not lose the last frame
    T = int(np.floor((t1 - t0) * fps + 1e-3)) + 1
    times = t0 + np.arange(T) / fps
    report = GapReport(fps=fps, t0=t0, t_end=float(times[-1]), num_frames=T,
                       devices=tuple(d for d in DEVICES if d in prep), warnings=warnings)

    out_pos, out_quat, out_valid = {}, {}, {}
    for d in report.devices:
        P = prep[d]
        ok = P["ok"]
        idx = np.nonzero(ok)[0]
        tg = P["t"][idx]
        pg = P["pos"][idx]
        qg = normalize(P["quat"][idx])
        flips = int(np.sum(np.sum(qg[1:] * qg[:-1], -1) < 0)) if len(idx) > 1 else 0
        qg = quat_continuous(qg)
        report.sign_flips[d] = flips
        n = tg.shape[0]

        # gaps between consecutive usable samples
        traw = P["t"]
        nominal = float(np.median(np.diff(traw))) if traw.shape[0] > 1 else 1.0 / fps
        if n > 1:
            bad_between = np.diff(idx) - 1
            step = np.diff(tg)
            is_gap = (bad_between > 0) | (step > gap_factor * nominal)
            for k in np.nonzero(is_gap)[0]:          # loop over gaps only
                reasons = list(P["reason"][idx[k] + 1:idx[k + 1]])
                reason = max(set(reasons), key=reasons.count) if reasons else "missing"
                report.gaps.append(Gap(d, float(tg[k]), float(tg[k + 1]), reason, int(len(reasons))))
        else:
            is_gap = np.zeros(0, dtype=bool)
        if tg[0] - t0 > gap_factor * nominal:
            report.gaps.append(Gap(d, t0, float(tg[0]), "start", int(np.sum(P["t"][~ok] < tg[0]))))
        if report.t_end - tg[-1] > gap_factor * nominal:
            report.gaps.append(Gap(d, float(tg[-1]), report.t_end, "end", int(np.sum(P["t"][~ok] > tg[-1]))))

        # interpolate
        out_pos[d] = np.stack([np.interp(times, tg, pg[:, c]) for c in range(3)], -1)
        if n == 1:
            q = np.repeat(qg, T, axis=0)
            valid = np.isclose(times, tg[0])
        else:
            i = np.clip(np.searchsorted(tg, times, side="right") - 1, 0, n - 2)
            a = np.clip((times - tg[i]) / (tg[i + 1] - tg[i]), 0.0, 1.0)
            q = quat_slerp(qg[i], qg[i + 1], a)
            inside = (times > tg[i]) & (times < tg[i + 1])
            valid = (times >= tg[0]) & (times <= tg[-1]) & ~(is_gap[i] & inside)
        out_quat[d] = quat_continuous(q)
        out_valid[d] = valid

    for d in absent:                     # never tracked: held beside the head, marked lost
        side = 1.0 if d == "left_hand" else -1.0
        out_pos[d] = out_pos["head"] + np.array([0.2 * side, 0.0, -0.6])
        out_quat[d] = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
        out_valid[d] = np.zeros(T, dtype=bool)
        report.gaps.append(Gap(d, t0, report.t_end, "missing", 0))
        warnings.append(f"{d.replace('_', ' ')}: no usable sample in the take (a controller off or never "
                        f"seen): its arm hangs relaxed")
    report.devices = tuple(d for d in DEVICES if d in out_pos)
    report.gaps.sort(key=lambda g: (g.start, DEVICES.index(g.device)))
    return times, out_pos, out_quat, out_valid, report
