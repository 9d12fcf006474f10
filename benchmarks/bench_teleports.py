"""Jumps of the tracking space under 15 cm (``core/teleports.py``): found where they happen, never
where they did not, on fast synthetic motion and on the real VR recordings.

Synthetic takes (20 s, seeds 0-9, 1 mm noise) at 60, 90 and 120 Hz: *dance* (the head wandering
on a smooth path, the hands on their own smooth paths around it) and *boxing* (the hands at the
guard, punching 0.45 m out and back in 0.2 s, over a second each on average).  Per kind and rate:
the jumps found in the takes as made (each false) and, for shifts of 3, 5, 8 and 11 cm in random
directions at random times (5 per take), how many are found at their time.  Then the jumps found
in each real recording under ``../shared/data/vr`` (none is known), or in the recordings given.

    .venv/bin/python benchmarks/bench_teleports.py [--seeds N] [RECORDING ...]
"""
from __future__ import annotations

import argparse
import glob
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from blender_manikin.core import teleports as tp  # noqa: E402
from blender_manikin.core.formats import load_recording  # noqa: E402
from blender_manikin.core.recording import Recording, TrackerStream  # noqa: E402

SIZES = (0.03, 0.05, 0.08, 0.11)


def _smooth_path(t, knots_t, knots_p):
    """``(N, 3)``: a Catmull-Rom path through the knots at times ``t`` (velocity continuous,
    acceleration not: as hard on the detector as real motion)."""
    i = np.clip(np.searchsorted(knots_t, t) - 1, 1, len(knots_t) - 3)
    t0, t1 = knots_t[i], knots_t[i + 1]
    u = ((t - t0) / (t1 - t0))[:, None]
    p0, p1, p2, p3 = knots_p[i - 1], knots_p[i], knots_p[i + 1], knots_p[i + 2]
    h = (t1 - t0)[:, None]
    m1 = (p2 - p0) / (knots_t[i + 1] - knots_t[i - 1])[:, None] * h
    m2 = (p3 - p1) / (knots_t[i + 2] - knots_t[i])[:, None] * h
    u2, u3 = u * u, u * u * u
    return (2 * u3 - 3 * u2 + 1) * p1 + (u3 - 2 * u2 + u) * m1 + (-2 * u3 + 3 * u2) * p2 + (u3 - u2) * m2


def synthetic_take(kind, rate, seed, dur=20.0, noise=0.001):
    """``(t (N,), {device: (N, 3)})``: head and hands of a *dance* or *boxing* take, metres, Z-up."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(dur * rate)) / rate
    kt = np.arange(-0.5, dur + 0.6, 0.2 if kind == "dance" else 0.25)
    centre = np.cumsum(rng.normal(0, 0.11 if kind == "dance" else 0.07, (len(kt), 3)) * [1, 1, 0.3], 0)
    centre[:, 2] = 1.6 + np.clip(centre[:, 2] - centre[:, 2].mean(), -0.25, 0.25)
    head = _smooth_path(t, kt, centre)
    out = {"head": head}
    for k, side in enumerate(("left_hand", "right_hand")):
        if kind == "dance":
            ht = np.arange(-0.5, dur + 0.6, 0.2)
            rel = rng.normal(0, 0.22, (len(ht), 3)) + [(-0.3 if k == 0 else 0.3), 0, -0.4]
            out[side] = head + _smooth_path(t, ht, rel)
        else:
            guard = np.array([(-0.15 if k == 0 else 0.15), -0.25, -0.1])
            ext = np.zeros(len(t))
            for start in np.sort(rng.uniform(0.5, dur - 0.5, int(dur * 1.2))):
                u = (t - start) / 0.2
                m = (u > 0) & (u < 1)
                ext[m] = np.maximum(ext[m], np.sin(np.pi * u[m]) ** 2)
            out[side] = head + guard + ext[:, None] * np.array([0.0, -0.45, 0.05])
    return t, {d: p + rng.normal(0, noise, p.shape) for d, p in out.items()}


def as_recording(t, streams, at=None, shift=None):
    """The take as a :class:`Recording` (rotations identity), every device shifted by ``shift``
    from sample ``at`` on."""
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
    moved = {d: p + (np.arange(len(t)) >= at)[:, None] * shift if at is not None else p for d, p in streams.items()}
    return Recording(streams={d: TrackerStream(d, t.copy(), p, q.copy()) for d, p in moved.items()},
                     source="synthetic")


VR_DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "vr")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", nargs="*", metavar="RECORDING",
                    help=f"real recordings to look for jumps in (default: the .bsor and .xror files in {VR_DATA})")
    ap.add_argument("--seeds", type=int, default=10, help="synthetic takes per kind and rate (default 10)")
    args = ap.parse_args(argv)
    print(f"teleports.py: TELEPORT_MIN_M {tp.TELEPORT_MIN_M} m, SMALL_JUMP_MIN_M {tp.SMALL_JUMP_MIN_M} m")
    print(f"| take | false jumps ({args.seeds} x 20 s) | "
          + " | ".join(f"{100 * s:.0f} cm found" for s in SIZES) + " |")
    print("|---|---:|" + "---:|" * len(SIZES))
    for kind in ("dance", "boxing"):
        for rate in (60.0, 90.0, 120.0):
            false, found, trials = 0, dict.fromkeys(SIZES, 0), 0
            for seed in range(args.seeds):
                t, st = synthetic_take(kind, rate, seed)
                false += len(tp.find_rig_jumps(as_recording(t, st)))
                rng = np.random.default_rng(100 + seed)
                for size in SIZES:
                    for _ in range(5):
                        at = int(rng.integers(int(rate), len(t) - int(rate)))
                        v = rng.normal(size=3)
                        jumps = tp.find_rig_jumps(as_recording(t, st, at, v * size / np.linalg.norm(v)))
                        found[size] += any(abs(j.time - t[at]) < 1e-6 for j in jumps)
                trials += 5
            print(f"| {kind} {rate:.0f} Hz | {false} | " + " | ".join(f"{found[s]}/{trials}" for s in SIZES) + " |")
    recordings = args.recordings or sorted(f for f in glob.glob(os.path.join(VR_DATA, "*"))
                                           if f.endswith((".bsor", ".xror")))
    if not recordings:
        print(f"no real recordings: none under {VR_DATA}; give their paths as arguments")
    for f in recordings:
        print(f"{os.path.basename(f)}: {len(tp.find_rig_jumps(load_recording(f)))} jumps found")


if __name__ == "__main__":
    main()
