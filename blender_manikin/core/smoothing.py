"""Zero-lag smoothing of sampled tracks: Savitzky-Golay filters, and the per-track choice among
them by Stein's unbiased risk estimate from each track's own measured noise.  No bpy.

One implementation for both kinds of input:

* 3D keypoints (:mod:`.keypoint_solve`): each point's position track;
* tracker recordings (:func:`.solve.solve_recording`): each device's position track and the two
  first axes of its orientation (:func:`smooth_device_poses`), after resampling onto the solve's
  frame grid and before the device offsets, so the hands still land exactly on their (smoothed)
  targets.

The setting (``SolveSettings.smoothing``, ``--smoothing``, the panel's Smoothing) is ``"auto"``
(the default: :func:`smooth_auto`; clean tracks are left as they are, noisy ones get the window
their noise calls for) or one quadratic window in seconds for every track (0: off).
"""
from __future__ import annotations

import numpy as np

from . import rotations as rot


def smooth_frames(x, sigma):
    """Gaussian smoothing along axis 0 (``sigma`` in frames, edges held), vectorised."""
    x = np.asarray(x, np.float64)
    if sigma <= 0 or x.shape[0] < 3:
        return x.copy()
    r = int(np.ceil(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    pad = np.concatenate([np.repeat(x[:1], r, 0), x, np.repeat(x[-1:], r, 0)], 0)
    out = np.zeros_like(x)
    for i, w in enumerate(k):
        out += w * pad[i:i + x.shape[0]]
    return out


# --------------------------------------------------------------------------
def savgol_weights(window: int, order: int = 2):
    """``(window, window)`` Savitzky-Golay weights: row ``i`` gives the least-squares polynomial
    (degree ``order``) through a window's samples evaluated at its sample ``i`` (the middle row
    is the usual smoothing kernel; the others serve the first and last half-windows)."""
    h = window // 2
    A = np.vander(np.arange(-h, h + 1, dtype=np.float64), order + 1, increasing=True)
    return A @ np.linalg.pinv(A)


def savgol_window(seconds, fps, T):
    """Frames (odd, at most ``T``) of a Savitzky-Golay window of ``seconds`` at ``fps``."""
    w = int(round(seconds * fps)) | 1
    return w if w <= T else (T if T % 2 else T - 1)


def smooth(x, fps, seconds, order=2):
    """Savitzky-Golay filter along axis 0 over ``seconds`` (an odd number of frames, at least
    ``order + 2``; else unchanged): zero lag, and polynomials of degree ``order`` pass through
    unchanged, ends included (the first and last half-windows take the polynomial fitted to the
    first and last whole window).  ``x``: ``(T, ...)``, any memory layout; returns a new array."""
    x = np.ascontiguousarray(x, np.float64)     # the ends are written through reshape views
    w = savgol_window(seconds, fps, x.shape[0])
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


#: the filters :func:`smooth_auto` chooses from: (window seconds, polynomial order); (0, 0) is none
AUTO_FILTERS = ((0.0, 0),) + tuple((w, 2) for w in (0.2, 0.3, 0.4, 0.5, 0.6, 0.8)) \
    + tuple((w, 4) for w in (0.6, 0.8, 1.0, 1.2, 1.6))
#: frames of the local cubic fit whose residual measures a track's noise
NOISE_WINDOW = 7


def savgol_trace(T, window, order=2):
    """Trace of the ``(T, T)`` matrix :func:`smooth` applies (its degrees of freedom)."""
    if window < order + 2 or window > T:
        return float(T)
    h = window // 2
    W = savgol_weights(window, order)
    return float((T - 2 * h) * W[h, h] + np.trace(W[:h, :h]) + sum(W[h + 1 + i, window - h + i] for i in range(h)))


def track_noise(x):
    """``(K,)`` noise standard deviation (the input's units) of each track of ``x`` ``(T, K, 3)``:
    from the residual of a local cubic fit over :data:`NOISE_WINDOW` frames, robustly (the
    median squared residual, so fast moves and filled gaps count little), assuming white noise
    of the same size on the three axes.  NaN for a track with missing samples (bridge them first)."""
    x = np.asarray(x, np.float64)
    w = NOISE_WINDOW
    if x.shape[0] < 3 * w:
        return np.full(x.shape[1], np.nan)
    h = w // 2
    r = (x - smooth(x, 1.0, w, order=3))[h:-h]          # fps 1: the window is in frames
    c = savgol_weights(w, 3)[h, h]
    # median of a chi-square(1) variable is 0.455 of its mean; a fitted residual keeps 1 - c of it
    out = np.full(x.shape[1], np.nan)
    ok = np.isfinite(r).all(axis=(0, 2))
    out[ok] = np.sqrt(np.median(r[:, ok] ** 2, axis=(0, 2)) / 0.4549 / (1.0 - c))
    return out


def smooth_auto(x, fps, filters=AUTO_FILTERS, noise_floor=0.0):
    """Each track of ``x`` ``(T, K, 3)`` smoothed by the filter of ``filters`` that Stein's
    unbiased risk estimate says brings it closest to the noise-free motion.

    For a linear smoother ``y = S x`` of a track with white noise σ (:func:`track_noise`) the
    expected squared error to the true motion is estimated, without knowing it, as
    ``|x - y|² - n σ² + 2 σ² tr(S)`` (n samples; Stein 1981): a longer window removes more
    noise but bends fast motion more, and the estimate weighs the two on the track's own data.
    So a wrist in a fast throw keeps a short window while a hip of the same take gets a long
    one, and clean input is left nearly as it is.  fps: the samples' rate (windows are in
    seconds).  noise_floor: ``float`` or ``(K,)``, the input's units: a track whose measured
    noise is at or below it is left exactly as it is (clean data, whose "noise" is only what a
    local cubic does not fit).  Returns ``(smoothed (T, K, 3), choice (K,) index into filters)``."""
    x = np.asarray(x, np.float64)
    T, K = x.shape[:2]
    sig2 = track_noise(x) ** 2
    best = np.zeros(K, np.int64)
    out = x.copy()
    ok = np.isfinite(sig2) & (sig2 > np.broadcast_to(np.asarray(noise_floor, np.float64), (K,)) ** 2)
    idx = np.nonzero(ok)[0]           # only these tracks are filtered (the rest: none, and no cost)
    if idx.size == 0:
        return out, best
    xs, s2 = x[:, idx], sig2[idx]
    ys, choice = xs.copy(), np.zeros(idx.size, np.int64)
    risk_best = np.full(idx.size, np.inf)
    for i, (seconds, order) in enumerate(filters):
        y = smooth(xs, fps, seconds, order) if seconds > 0 else xs
        tr = savgol_trace(T, savgol_window(seconds, fps, T), order) if seconds > 0 else float(T)
        risk = np.sum((xs - y) ** 2, axis=(0, 2)) + 3.0 * s2 * (2.0 * tr - T)
        better = risk < risk_best
        ys[:, better] = y[:, better]
        choice[better] = i
        risk_best[better] = risk[better]
    out[:, idx] = ys
    best[idx] = choice
    return out, best


def parse_smoothing(value):
    """``"auto"`` or a window in seconds (float >= 0) from a setting (``"auto"``, a number or a
    numeric string); :class:`.solve.SolveError` otherwise."""
    from .solve import SolveError        # solve imports this module lazily: no cycle
    if isinstance(value, str):
        v = value.strip().lower()
        if v == "auto":
            return "auto"
        try:
            value = float(v)
        except ValueError:
            raise SolveError(f"smoothing {value!r}: expected 'auto' or a window in seconds") from None
    if value is None:
        return 0.0
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise SolveError(f"smoothing {value!r}: expected 'auto' or a window in seconds >= 0")
    return value


def smoothing_note(smoothing, windows=None, what="point"):
    """The solve summary's line for a ``smoothing`` setting (:func:`parse_smoothing`'s value);
    with ``"auto"``, ``windows`` are the seconds :func:`smooth_auto` chose (0: none) for each
    ``what`` (``"point"``, ``"device"``)."""
    if smoothing == "auto":
        w = np.asarray(windows if windows is not None and len(windows) else [0.0], np.float64)
        if not np.any(w > 0):
            return f"smoothing auto (per {what}, from its measured noise): none needed, every {what} is clean"
        return (f"smoothing auto (per {what}, from its measured noise): windows {w.min():g}-{w.max():g} s, "
                f"median {np.median(w):g} s")
    return f"smoothing {smoothing:g} s" if smoothing else "no smoothing"


#: measured noise (σ per coordinate) at or below which ``"auto"`` leaves a device's track as it
#: is: 0.25 mm of position, and 0.0015 of an orientation axis (unit vector; about 0.09°).  Below
#: what animation shows, above what a clean source holds: keyed scene objects, ground-truth
#: trackers, a file written with 4 decimals (quantisation σ 0.03 mm)
DEVICE_NOISE_FLOOR_M = 0.00025
DEVICE_NOISE_FLOOR_AXIS = 0.0015


def smooth_targets(targets, smoothing):
    """:class:`.pose_result.TrackerTargets` with every device's position and orientation
    smoothed as :func:`smooth_device_poses` does (``targets.rot`` ``(T, 3, 3)`` world
    orientations; the frame rate is ``targets.fps``).  Returns ``(targets, windows)``."""
    from .pose_result import TrackerTargets
    devices = list(targets.pos)
    pos, rotm, windows = _smooth_poses({d: targets.pos[d] for d in devices},
                                       {d: targets.rot[d] for d in devices}, targets.fps, smoothing)
    return TrackerTargets(fps=targets.fps, pos=pos, rot=rotm, valid=dict(targets.valid)), windows


def smooth_device_poses(pos, quat, fps, smoothing):
    """Tracker poses on a frame grid, smoothed in time.

    pos: device -> ``(T, 3)`` metres; quat: device -> ``(T, 4)`` unit wxyz, sign-continuous (as
    :func:`.resample.resample` returns them).  fps: the grid's frames per second.  smoothing:
    ``"auto"`` (:func:`smooth_auto`: each device's position, and each of its first two
    orientation axes, gets the filter its own measured noise calls for; a track no noisier than
    :data:`DEVICE_NOISE_FLOOR_M` / :data:`DEVICE_NOISE_FLOOR_AXIS` is left as it is) or one Savitzky-Golay
    window in seconds for all (0: returned as given).  The orientation is rebuilt from its
    smoothed x and y axes (x kept, y made orthogonal; :func:`.rotations.frame_from_axes`).

    Returns ``(pos, quat, windows)``: new dicts of the same shapes, and for ``"auto"`` the
    window in seconds chosen per device (its longest over its three tracks; 0: none), else None.
    """
    if not parse_smoothing(smoothing) or not pos:
        return dict(pos), dict(quat), None
    out_pos, R, windows = _smooth_poses(pos, {d: rot.quat_to_matrix(quat[d]) for d in pos}, fps, smoothing)
    out_quat = {}
    for d in R:             # sign-continuous, with each device's sign convention from its first frame
        if windows is not None and windows[d] == 0:
            out_quat[d] = np.array(quat[d], np.float64)
            continue
        q = rot.quat_continuous(rot.matrix_to_quat(R[d]))
        out_quat[d] = -q if np.sum(q[0] * quat[d][0]) < 0 else q
    return out_pos, out_quat, windows


def _smooth_poses(pos, R, fps, smoothing):
    """:func:`smooth_device_poses` on ``(T, 3, 3)`` orientations ``R``: ``(pos, R, windows)``."""
    smoothing = parse_smoothing(smoothing)
    devices = list(pos)
    if not devices or not smoothing:
        return dict(pos), dict(R), None
    K = len(devices)
    X = np.stack([pos[d] for d in devices] + [R[d][..., 0] for d in devices] + [R[d][..., 1] for d in devices], 1)
    windows = None
    if smoothing == "auto":
        floor = np.repeat([DEVICE_NOISE_FLOOR_M, DEVICE_NOISE_FLOOR_AXIS], [K, 2 * K])
        X, choice = smooth_auto(X, fps, noise_floor=floor)
        w = np.array([AUTO_FILTERS[c][0] for c in choice]).reshape(3, K)
        windows = {d: float(w[:, k].max()) for k, d in enumerate(devices)}
    else:
        X = smooth(X, fps, smoothing)
    out_pos, out_rot = {}, {}
    for k, d in enumerate(devices):
        if windows is not None and windows[d] == 0:          # no filter on any track: exactly as given
            out_pos[d], out_rot[d] = np.array(pos[d], np.float64), np.array(R[d], np.float64)
            continue
        out_pos[d] = X[:, k].copy()
        out_rot[d] = rot.frame_from_axes(X[:, K + k], X[:, 2 * K + k], "xy")
    return out_pos, out_rot, windows
