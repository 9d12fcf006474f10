"""Throughput of dataset-scale conversion (``blender-manikin convert``) with 1 and 2 Dask workers
on the same inputs, in one run.

    python benchmarks/bench_convert.py [--recordings 16] [--minutes 1.0] [--workers 1,2]

The inputs are made here: ``--recordings`` native-CSV recordings of ``--minutes`` each (three
trackers at 90 Hz, from ``examples/make_example_recording.py``'s motion, repeated).  Each worker
count converts them all to JSON into a fresh folder; the table gives wall-clock seconds,
recordings/s and solved frames/s (30 fps output).  Measured, never asserted.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from blender_manikin.core import convert, metrics  # noqa: E402
from blender_manikin.core.formats import load_recording  # noqa: E402
from blender_manikin.core.io_csv import write_csv  # noqa: E402
from blender_manikin.core.recording import TrackerStream  # noqa: E402
from blender_manikin.core.solve import SolveSettings  # noqa: E402

EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def make_inputs(folder, n, minutes):
    """``n`` CSV recordings of ``minutes`` each: the example's motion looped (time shifted)."""
    rec = load_recording(EXAMPLE)
    paths = []
    for i in range(n):
        streams = []
        for s in rec.streams.values():
            dur = s.time[-1] - s.time[0] + 1.0 / 90
            reps = int(np.ceil(minutes * 60 / dur))
            t = np.concatenate([s.time - s.time[0] + k * dur for k in range(reps)])
            streams.append(TrackerStream(s.device, t, np.tile(s.pos, (reps, 1)), np.tile(s.quat, (reps, 1))))
        path = os.path.join(folder, f"take{i:03d}.csv")
        write_csv(path, streams, axes="blender")
        paths.append(path)
    return paths


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=16)
    ap.add_argument("--minutes", type=float, default=1.0)
    ap.add_argument("--workers", default="1,2")
    args = ap.parse_args(argv)
    work = tempfile.mkdtemp(prefix="manikin-convert-")
    try:
        inputs = make_inputs(work, args.recordings, args.minutes)
        rows = []
        for w in [int(x) for x in args.workers.split(",")]:
            out = os.path.join(work, f"out{w}")
            t = time.perf_counter()
            code, records = convert.run(inputs, out, ["json"], SolveSettings(fps=30.0), workers=w, progress=False,
                                        log=lambda m: None)
            dt = time.perf_counter() - t
            frames = sum(r["frames"] for r in records)
            failed = sum(r["status"] != "ok" for r in records)
            rows.append((f"{w} worker(s)", {"recordings": len(records), "failed": failed, "seconds": dt,
                                            "recordings/s": len(records) / dt, "frames/s": frames / dt}))
        print(f"{args.recordings} recordings of {args.minutes:g} min (3 trackers, 90 Hz) -> JSON at 30 fps; "
              f"{os.cpu_count()} CPUs")
        print(metrics.format_table(rows, ["recordings", "failed", "seconds", "recordings/s", "frames/s"],
                                   name_header="LocalCluster",
                                   formats={"seconds": ".1f", "recordings/s": ".2f", "frames/s": ",.0f"}))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
