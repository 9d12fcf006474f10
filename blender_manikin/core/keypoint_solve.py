"""3D keypoints → an animated 22-joint body, by HybrIK twist-and-swing IK.  No bpy.

    from blender_manikin.core.solve import SolveSettings, solve_recording
    outcome = solve_recording("take/output_data", SolveSettings(fps=30.0, smoothing=0.2))
    outcome.result          # PoseResult, as a tracker solve gives (same writers, same armature)

Stages (each a function, for tests and benchmarks):

1. read (:func:`.io_keypoints.read_keypoints`): metres, Blender axes, NaN = missing;
2. :func:`bridge_gaps`: every point's missing stretches filled by linear interpolation in
   time (held at the ends), reported as :class:`.resample.Gap` s;
3. :func:`smooth`: a Savitzky-Golay filter (quadratic, zero lag) over ``smoothing`` seconds;
4. resampling to the solve's frame rate (linear in time);
5. :func:`.keypoint_layouts.body22_from_keypoints`: the 22 joints and the orientations the
   layout shows;
6. :func:`size_body`: bone lengths from the median over the take, left and right averaged, on
   the rest directions of :func:`.skeleton.make_body`, so bones never stretch;
7. :func:`estimate_floor`: the floor height from the lowest foot points; the take is moved so
   the floor is ``z = 0``;
8. IK (:func:`.hybrik.ik_from_positions`, adaptive by default: each bone aims at its keypoint
   from where the chain actually is): limbs through the analytic limb solver, so elbows and
   knees are hinges within their limits and the swivel angles become the usual keyed
   properties; feet contacts (:func:`foot_contacts`) hold planted ankles still and the feet are
   kept above the floor, then the limbs are solved again onto those ankle targets.
"""
from __future__ import annotations

import time as _time
import numpy as np

from . import hybrik
from . import keypoint_layouts as kl
from . import pipeline
from . import skeleton as sk
from .pose_result import PoseResult
from .resample import Gap, GapReport
from .solve import SolveError, SolveOutcome, SolveSettings

#: left / right joint pairs whose bone lengths are averaged
_PAIRS = [(sk.J[f"left_{n}"], sk.J[f"right_{n}"]) for n in
          ("hip", "knee", "ankle", "foot", "collar", "shoulder", "elbow", "wrist")]
#: an ankle slower than this (m/s) and lower than its rest height plus CONTACT_HEIGHT is planted
CONTACT_SPEED = 0.25
CONTACT_HEIGHT = 0.05


# --------------------------------------------------------------------------
def bridge_gaps(time, points, names=None):
    """Fill each point's missing stretches (NaN) by linear interpolation in time; before its
    first and after its last sample it is held.

    time ``(T,)`` seconds; points ``(T, K, 3)``.  Returns ``(filled (T, K, 3), gaps)``: gaps a
    list of :class:`.resample.Gap` (device = the point's name, reason ``lost`` / ``start`` /
    ``end``).  A point never seen stays NaN (the caller decides).
    """
    X = np.array(points, np.float64, copy=True)
    t = np.asarray(time, np.float64)
    gaps = []
    for k in range(X.shape[1]):
        ok = np.isfinite(X[:, k]).all(-1)
        if ok.all() or not ok.any():
            continue
        for a in range(3):
            X[~ok, k, a] = np.interp(t[~ok], t[ok], X[ok, k, a])
        name = names[k] if names is not None else str(k)
        miss = np.nonzero(~ok)[0]
        starts = np.concatenate([[0], np.nonzero(np.diff(miss) > 1)[0] + 1])
        ends = np.concatenate([starts[1:], [len(miss)]])
        for s, e in zip(starts, ends):
            a, b = miss[s], miss[e - 1]
            reason = "start" if a == 0 else ("end" if b == len(t) - 1 else "lost")
            gaps.append(Gap(name, float(t[max(a - 1, 0)]), float(t[min(b + 1, len(t) - 1)]), reason, int(b - a + 1)))
    return X, gaps


def savgol_weights(window: int, order: int = 2):
    """``(window, window)`` Savitzky-Golay weights: row ``i`` gives the least-squares polynomial
    (degree ``order``) through a window's samples evaluated at its sample ``i`` (the middle row
    is the usual smoothing kernel; the others serve the first and last half-windows)."""
    h = window // 2
    A = np.vander(np.arange(-h, h + 1, dtype=np.float64), order + 1, increasing=True)
    return A @ np.linalg.pinv(A)


def smooth(x, fps, seconds, order=2):
    """Savitzky-Golay filter along axis 0 over ``seconds`` (an odd number of frames, at least
    ``order + 2``; else unchanged): zero lag, and polynomials of degree ``order`` pass through
    unchanged, ends included (the first and last half-windows take the polynomial fitted to the
    first and last whole window).  ``x``: ``(T, ...)``; returns a new array."""
    x = np.asarray(x, np.float64)
    w = int(round(seconds * fps)) | 1
    if w > x.shape[0]:
        w = x.shape[0] if x.shape[0] % 2 else x.shape[0] - 1
    if seconds <= 0 or w < order + 2:
        return x.copy()
    h = w // 2
    W = savgol_weights(w, order)
    T = x.shape[0]
    out = np.zeros_like(x)
    for i in range(w):
        out[h:T - h] += W[h, i] * x[i:T - w + 1 + i]
    flat = x.reshape(T, -1)
    out.reshape(T, -1)[:h] = W[:h] @ flat[:w]
    out.reshape(T, -1)[T - h:] = W[h + 1:] @ flat[T - w:]
    return out


def resample_points(time, X, fps, t0=None):
    """``(times (N,), X (N, ...))``: ``X`` ``(T, ...)`` linearly interpolated onto a grid at ``fps``
    from ``t0`` (default the first time) to the last time."""
    t = np.asarray(time, np.float64)
    t0 = float(t[0]) if t0 is None else float(t0)
    n = int(np.floor((t[-1] - t0) * fps + 1e-6)) + 1
    grid = t0 + np.arange(n) / float(fps)
    flat = np.asarray(X, np.float64).reshape(len(t), -1)
    out = np.empty((n, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(grid, t, flat[:, c])
    return grid, out.reshape((n,) + np.shape(X)[1:])


def size_body(P, height=None) -> sk.Body:
    """A :class:`.skeleton.Body` with the bone lengths of ``P`` ``(T, 22, 3)`` metres.

    Each bone's length is its median over the frames, left and right averaged; directions and
    the rest pose are those of :func:`.skeleton.make_body` (limbs straight along the axes, feet
    on the floor), so the limb solver's hinge axes hold.  height: scales the body to that
    stature (metres; the head joint 0.871 statures above the ankles)."""
    L = np.linalg.norm(P[:, 1:] - P[:, sk.PARENTS[1:]], axis=-1)
    L = np.concatenate([[0.0], np.nanmedian(L, axis=0)])
    for a, b in _PAIRS:
        L[a] = L[b] = 0.5 * (L[a] + L[b])
    if not np.all(np.isfinite(L[1:])) or np.any(L[1:] <= 1e-4):
        raise SolveError("cannot size the body: some bones have no length in the keypoints")
    tmpl = sk.make_body(1.75)
    dirs = tmpl.offsets / np.maximum(tmpl.bone_lengths()[:, None], 1e-12)
    off = dirs * L[:, None]
    rel = np.zeros((sk.NUM_JOINTS, 3))
    for j in range(1, sk.NUM_JOINTS):
        rel[j] = rel[sk.PARENTS[j]] + off[j]
    ankle = min(rel[sk.J["left_ankle"], 2], rel[sk.J["right_ankle"], 2])
    head_above_ankle = rel[sk.J["head"], 2] - ankle
    H = head_above_ankle / (sk.PROPORTIONS["head_height"] - sk.PROPORTIONS["ankle_height"])
    if height:
        s = float(height) / H
        off, rel, ankle, H = off * s, rel * s, ankle * s, float(height)
    root = np.array([0.0, 0.0, -ankle + sk.PROPORTIONS["ankle_height"] * H])
    body = sk.Body.from_offsets(off, root, stature=H)
    return body


def estimate_floor(P, body: sk.Body):
    """The floor's height (metres): where the feet's lowest points are when the feet are down.

    Per frame, the lowest of each ankle less its rest height and each ball of the foot less
    its rest height; the floor is the 10th percentile over the take (robust to noise and to
    frames where a point dipped)."""
    rest = body.rest_positions()
    low = []
    for j in ("left_ankle", "right_ankle", "left_foot", "right_foot"):
        low.append(P[:, sk.J[j], 2] - rest[sk.J[j], 2])
    low = np.min(np.stack(low, -1), -1)
    return float(np.nanpercentile(low, 10))


def foot_contacts(ankle_pos, body: sk.Body, fps):
    """``(T, 2)`` float 0/1: planted where an ankle moves slower than :data:`CONTACT_SPEED`
    (m/s, horizontally, over three frames) and stays within :data:`CONTACT_HEIGHT` of its rest
    height.  ankle_pos ``(T, 2, 3)`` metres with the floor at ``z = 0``."""
    a = np.asarray(ankle_pos, np.float64)
    v = np.zeros(a.shape[:2])
    if a.shape[0] > 2:
        v[1:-1] = np.linalg.norm(a[2:, :, :2] - a[:-2, :, :2], axis=-1) * fps / 2.0
        v[0], v[-1] = v[1], v[-2]
    rest_h = body.rest_positions()[[sk.J["left_ankle"], sk.J["right_ankle"]], 2]
    return ((v < CONTACT_SPEED) & (a[..., 2] < rest_h + CONTACT_HEIGHT)).astype(np.float64)


def _finite_orientations(b22: kl.Body22):
    """Drop orientations whose points were never seen (after bridging they stay NaN)."""
    no_twist = list(b22.no_twist)
    for j in list(b22.end_rot):
        if not np.isfinite(b22.end_rot[j]).all():
            del b22.end_rot[j]
            no_twist.append(sk.JOINT_NAMES[j] if j != sk.J["head"] else "head")
    b22.no_twist = tuple(dict.fromkeys(no_twist))
    return b22


def fit_keypoints(P, end_rot, body: sk.Body, fps, adaptive=True, lock_feet=True):
    """IK of the 22 joints ``P`` ``(T, 22, 3)`` (floor at ``z = 0``) onto ``body``: a
    :class:`PoseResult` with contacts and the ankles kept above the floor."""
    ik = hybrik.ik_from_positions(P, body, end_rot=end_rot, adaptive=adaptive)
    ank = [sk.J["left_ankle"], sk.J["right_ankle"]]
    contacts = foot_contacts(ik.positions[:, ank], body, fps)
    targets = ik.positions[:, ank]
    if lock_feet:
        targets = pipeline.lock_planted_feet(targets, contacts, threshold=0.5)
    targets = pipeline.keep_feet_above_floor(targets, ik.world_rot[:, ank], body)
    moved = np.abs(targets - ik.positions[:, ank]).max() > 1e-9
    if moved:
        Q = P.copy()
        delta = targets - P[:, ank]
        Q[:, ank] = targets
        Q[:, [sk.J["left_foot"], sk.J["right_foot"]]] += delta
        er = dict(end_rot)
        for k, j in enumerate(ank):       # keep the feet's orientation from the first pass
            er.setdefault(j, ik.world_rot[:, j])
        ik = hybrik.ik_from_positions(Q, body, end_rot=er, adaptive=adaptive)
    return PoseResult(fps=float(fps), body=body, local_rot=ik.local_rot, root_pos=ik.root_pos,
                      swivel=ik.swivel, contacts=contacts > 0.5, reach_error=ik.reach_error)


def solve_keypoints(source, settings: SolveSettings | None = None, progress=None) -> SolveOutcome:
    """Solve keypoints (a path :func:`.io_keypoints.read_keypoints` reads, or a
    :class:`.io_keypoints.KeypointRecording`) into a :class:`SolveOutcome` whose ``result`` is
    a :class:`PoseResult` like a tracker solve's; ``info`` names the joints with no twist
    information, the floor and the smoothing.

    settings (:class:`.solve.SolveSettings`): fps (None: the file's rate), keypoint_layout,
    units, up, rate, mapping (see :func:`.io_keypoints.read_keypoints`), smoothing (seconds),
    ik (``adaptive`` / ``naive``), height (scales the measured body to this stature, metres),
    max_frames.  Tracker options (axes, offsets, calibration) do not apply.
    progress: ``(fraction, stage)`` callback; an exception raised from it stops the solve."""
    from .io_keypoints import KeypointRecording, read_keypoints
    s = settings or SolveSettings()
    if str(s.ik).lower() not in ("adaptive", "naive"):
        raise SolveError(f"ik {s.ik!r}: expected adaptive or naive")
    adaptive = str(s.ik).lower() == "adaptive"
    report = progress or (lambda f, stage=None: None)
    out = SolveOutcome()
    t = _time.perf_counter()
    if isinstance(source, KeypointRecording):
        rec = source
    else:
        report(0.0, "reading keypoints")
        rec = read_keypoints(source, layout=s.keypoint_layout, units=s.units, up=s.up, rate=s.rate,
                             mapping=s.mapping)
    out.recording = rec
    out.timings["read"] = _time.perf_counter() - t
    t = _time.perf_counter()
    report(0.1, "bridging gaps")
    lay = kl.LAYOUTS[rec.layout]
    X, gaps = bridge_gaps(rec.time, rec.points, lay.points)
    never = [lay.points[k] for k in range(X.shape[1]) if not np.isfinite(X[:, k]).any()]
    fps = float(s.fps) if s.fps else 1.0 / float(np.median(np.diff(rec.time)))
    rate = 1.0 / float(np.median(np.diff(rec.time)))
    X = smooth(X, rate, float(s.smoothing)) if s.smoothing else X
    times, X = resample_points(rec.time, X, fps)
    if s.max_frames and len(times) > s.max_frames:
        times, X = times[:s.max_frames], X[:s.max_frames]
    out.report = GapReport(fps=fps, t0=float(times[0]), t_end=float(times[-1]), num_frames=len(times),
                           devices=lay.points, gaps=gaps)
    b22 = _finite_orientations(kl.body22_from_keypoints(X, lay))
    P = b22.positions
    bad = [sk.JOINT_NAMES[j] for j in range(sk.NUM_JOINTS) if not np.isfinite(P[:, j]).all()]
    if bad:
        raise SolveError(f"{rec.source}: joint(s) {', '.join(bad)} cannot be placed: point(s) "
                         f"{', '.join(never) or '?'} never seen")
    out.timings["prepare"] = _time.perf_counter() - t
    report(0.3, "sizing")
    t = _time.perf_counter()
    body = size_body(P, s.height)
    floor = estimate_floor(P, body)
    P = P - np.array([0.0, 0.0, floor])
    out.body = body
    out.timings["size"] = _time.perf_counter() - t
    report(0.4, "solving")
    t = _time.perf_counter()
    result = fit_keypoints(P, b22.end_rot, body, fps, adaptive=adaptive)
    result.t0 = float(times[0])
    out.result = result
    out.timings["solve"] = _time.perf_counter() - t
    out.info.append(f"keypoints: {'adaptive' if adaptive else 'naive'} HybrIK, floor at {floor:+.3f} m "
                    f"moved to 0, smoothing {s.smoothing:g} s")
    if b22.no_twist:
        out.info.append(f"no twist information: {', '.join(b22.no_twist)} (rest twist)")
    if never:
        out.info.append(f"point(s) never seen: {', '.join(never)}")
    report(1.0, "done")
    return out
