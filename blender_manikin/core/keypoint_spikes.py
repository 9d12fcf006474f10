"""Spikes in markerless keypoints, found and removed.  No bpy.

A detector that loses a point for a frame or two often puts it somewhere else entirely (a
wrist on the other hand, an ankle on the floor tiles, a bad triangulation a metre off), and a
smoothing filter smears such a spike over its whole window.  :func:`remove_spikes` marks them
missing, so the gap bridging fills them from the frames around.

A sample is a spike where it stands further than :data:`SPIKE_MIN` metres (more at a frame rate
below 30 fps, :func:`spike_threshold`), and further than
:data:`SPIKE_K` times the point's own robust spread, from the median of its point over the
:data:`SPIKE_HALF_WINDOW` frames on either side (itself included: the median of seven samples
ignores up to three that are off, so runs of up to three frames are found too; near the ends
the window shrinks on both sides, and the first and last frames are left as they are).
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: frames on either side of a sample whose median it is held against
SPIKE_HALF_WINDOW = 3
#: metres from that median a sample must stand to be a spike, at :data:`SPIKE_RATE` frames a
#: second or more (at 30 fps the benchmark's mocap comes to 0.24 m, a kicking ankle); at a lower
#: rate real motion strays further from the median, as the square of the frame interval ...
SPIKE_MIN = 0.30
SPIKE_RATE = 30.0
#: ... and this many times the point's robust spread (1.4826 x its median distance from it)
SPIKE_K = 8.0


def _window_median(X, half):
    """``(T - 2 half, K, 3)``: the per-coordinate median of the ``2 half + 1`` frames centred on
    frames ``half .. T - 1 - half``, ignoring NaN (NaN where none is seen)."""
    windows = sliding_window_view(X, 2 * half + 1, axis=0)               # (T-2h, K, 3, 2h+1)
    out = np.full(windows.shape[:-1], np.nan)
    seen = np.isfinite(windows).any(-1)
    if seen.any():
        w = np.sort(windows[seen], axis=-1)                             # NaN sort last
        n = np.isfinite(w).sum(-1)
        rows = np.arange(w.shape[0])
        out[seen] = 0.5 * (w[rows, (n - 1) // 2] + w[rows, n // 2])
    return out


def local_median(points, half=SPIKE_HALF_WINDOW):
    """``(T, K, 3)``: each point's per-coordinate median over the frames centred on each frame,
    ``half`` on either side, ignoring NaN; near the ends the window shrinks on both sides
    alike (a one-sided window lags behind a moving point), and the first and last frames, with
    no frame on one side, get NaN."""
    X = np.asarray(points, np.float64)
    T = X.shape[0]
    out = np.full(X.shape, np.nan)
    for m in range(min(half, (T - 1) // 2), 0, -1):
        med = _window_median(X, m)                                      # frames m .. T-1-m
        if m == half:
            out[m:T - m] = med
        else:                                   # only the two frames that need this width
            out[m] = med[0]
            out[T - 1 - m] = med[-1]
    return out


def spike_threshold(rate):
    """Metres from the local median a sample must stand to be a spike at ``rate`` frames a
    second: :data:`SPIKE_MIN`, scaled by ``(SPIKE_RATE / rate)^2`` below :data:`SPIKE_RATE`."""
    return SPIKE_MIN * max(1.0, SPIKE_RATE / float(rate)) ** 2


def remove_spikes(points, rate=SPIKE_RATE):
    """``(points, spikes)``: ``points`` ``(T, K, 3)`` metres (NaN = missing), sampled at
    ``rate`` per second, with the spikes set to NaN (a new array), and ``spikes`` ``(T, K)``
    bool, where they were."""
    X = np.array(points, np.float64, copy=True)
    dev = np.linalg.norm(X - local_median(X), axis=-1)                  # (T, K), NaN where unseen
    spread = np.zeros(X.shape[1])
    for k in range(X.shape[1]):
        d = dev[:, k][np.isfinite(dev[:, k])]
        spread[k] = 1.4826 * float(np.median(d)) if d.size else 0.0
    with np.errstate(invalid="ignore"):
        spikes = (dev > spike_threshold(rate)) & (dev > SPIKE_K * spread[None])
    X[spikes] = np.nan
    return X, spikes
