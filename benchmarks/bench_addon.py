"""End-to-end speed of the add-on on a long recording: read, resample, network, solver, keying.

    python benchmarks/bench_addon.py [--minutes 10] [--rate 90] [--fps 60] [--model PATH]

Synthesises a ``--minutes`` long three-tracker recording at ``--rate`` Hz
(jittered timestamps, OpenXR axes, the bundled example's performer), writes
it as the native CSV, then imports, solves and keys it at ``--fps`` with the
same code the panel and the batch converter run (``blender.solve_job``),
in the bpy module, and prints one table row per stage.  Target (issue):
a 10-minute 90 Hz recording at 60 fps in <= 20 s on a 2-core machine.
Timings are measured here, never asserted in tests.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "examples"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=90.0, help="tracker rate, Hz (all three devices)")
    ap.add_argument("--fps", type=float, default=60.0, help="scene / solve frame rate")
    ap.add_argument("--no-live-rig", action="store_true")
    args = ap.parse_args(argv)

    import bpy
    import make_example_recording as mk
    from blender_manikin.core.io_csv import write_csv
    from blender_manikin.blender import solve_job

    mk.RATES = {"head": args.rate, "left_hand": args.rate, "right_hand": args.rate}
    t = time.perf_counter()
    rec = mk.synthesize(duration=args.minutes * 60.0)
    tmp = tempfile.mkdtemp(prefix="manikin_bench_")
    path = os.path.join(tmp, "long.csv")
    write_csv(path, rec, axes="openxr")
    n = {d: len(s.time) for d, s in rec.streams.items()}
    print(f"recording: {args.minutes:g} min, {', '.join(f'{d} {k}' for d, k in n.items())} samples, "
          f"{os.path.getsize(path) / 1e6:.1f} MB CSV (made in {time.perf_counter() - t:.1f} s)")

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = int(args.fps), 1.0
    cfg = solve_job.SolveConfig(source="FILE", filepath=path, fps=args.fps, offsets="openxr_generic",
                                calibration="AUTO", live_rig=not args.no_live_rig)
    job = solve_job.SolveJob(cfg)
    t = time.perf_counter()
    job.run(bpy.context)
    total = time.perf_counter() - t
    T = job.result.num_frames
    rows = [("read", "read"), ("resample", "resample"), ("calibrate", "calibrate"),
            ("network (onnxruntime)", "solve.network"), ("solver (torso FK, feet, limbs)", "solve.solver"),
            ("keying (armature + bulk F-curves)", "keying"), ("live swivel rig", "live rig")]
    w = max(len(r[0]) for r in rows) + 2
    print(f"{'stage':<{w}}| seconds")
    print(f"{'-' * w}|--------")
    for name, key in rows:
        if key in job.timings:
            print(f"{name:<{w}}| {job.timings[key]:7.2f}")
    print(f"{'total':<{w}}| {total:7.2f}   ({T} frames at {args.fps:g} fps, {T / total:,.0f} frames/s)")


if __name__ == "__main__":
    main()
