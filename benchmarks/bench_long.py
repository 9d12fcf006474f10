"""Seconds and memory of every stage of the Blender-free solve on long recordings (10, 30 and
60 minutes side by side), to see which stage grows faster than the take.

    python benchmarks/bench_long.py [--minutes 10,30,60] [--rate 90] [--fps 30] [--devices 6]
                                    [--formats bvh,json,npz] [--snap-every S] [--keep DIR]

For each length a native-CSV recording is synthesised (the bundled example's performer and
motion, ``examples/make_example_recording.py``, walking in place for the whole take; ``--devices
6`` adds pelvis and foot trackers so the foot detectors run, 3 is headset and controllers;
``--snap-every 3`` turns the tracking space 30° every 3 s, as a game's snap turning does), then
read and solved with :func:`blender_manikin.core.solve.solve_recording` and written in
``--formats``, in a fresh process of its own.  Each stage's function is wrapped: the table gives
its seconds and the peak resident memory it added over the memory at its start (MB; a thread
samples ``/proc/self/statm`` every 10 ms, so stages under ~20 ms show ~0).  The last column
(``growth/length``) gives the seconds' growth from the shortest to the longest take divided by the
growth in length: about 1 is linear, 2 or more is quadratic.  Measured, never asserted.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "examples"))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

#: (row name, module under blender_manikin.core, function): the stages wrapped, in solve order
STAGES = [
    ("read", "solve", "read_recording"),
    ("teleports: find", "solve", "find_rig_jumps"),
    ("teleports: remove", "solve", "remove_rig_jumps"),
    ("teleports: restore", "solve", "restore_rig_jumps"),
    ("resample", "solve", "resample_recording"),
    ("smoothing", "smoothing", "smooth_device_poses"),
    ("tracker sides", "solve", "fix_swapped_sides"),
    ("targets (offsets)", "solve", "make_targets"),
    ("offsets auto", "offsets_auto", "headset_evidence"),
    ("headset off", "solve", "headset_off"),
    ("calibrate", "solve", "calibrate"),
    ("tracker slips: find", "solve", "find_tracker_slips"),
    ("tracker slips: correct", "solve", "correct_tracker_slips"),
    ("lost hands", "solve", "relax_lost_hands"),
    ("network windows", "pipeline", "predict"),
    ("solver (assemble)", "pipeline", "assemble"),
    ("arm adaptation", "solve", "adapt_arms"),
]
#: output formats: row name
WRITE_ROWS = {"bvh": "write BVH", "json": "write JSON", "npz": "write NPZ"}


def make_streams(minutes, rate, devices, snap_every=0.0):
    """``[TrackerStream]`` of a ``minutes`` long take at ``rate`` Hz with ``devices`` (3 or 6):
    the example's motion (:func:`make_example_recording.motion`), made ten minutes at a time.
    ``snap_every`` > 0: a 30° snap turn of the tracking space (about the headset) every that
    many seconds, as a VR game's snap turning makes them."""
    import numpy as np
    import make_example_recording as mk
    from blender_manikin.core.device_offsets import get_preset, remove_offsets
    from blender_manikin.core.recording import TrackerStream
    from blender_manikin.core.rotations import matrix_to_quat
    from blender_manikin.core.skeleton import BodyMeasurements, J, forward_kinematics, make_body
    joints = dict(mk.JOINT)
    if devices == 6:
        joints.update(pelvis="pelvis", left_foot="left_ankle", right_foot="right_ankle")
    body = make_body(BodyMeasurements(stature=mk.STATURE))
    preset = get_preset("openxr_generic")["devices"]
    rng = np.random.default_rng(mk.SEED)
    dur = minutes * 60.0
    snaps = np.arange(snap_every, dur - 1.0, snap_every) + 0.5 / rate if snap_every > 0 else np.zeros(0)
    turns = np.cumsum(np.radians(30.0) * np.where(rng.random(len(snaps)) < 0.5, -1.0, 1.0))
    streams = []
    for k, (dev, joint) in enumerate(joints.items()):
        t = mk.jittered_times(rate, dur, rng, start=0.0037 * k)
        pos, rot = np.empty((len(t), 3)), np.empty((len(t), 3, 3))
        step = int(600 * rate)
        for a in range(0, len(t), step):
            local, root = mk.motion(t[a:a + step], body)
            p, r = forward_kinematics(local, root, body)
            dp, dr = remove_offsets(p[:, J[joint]], r[:, J[joint]], preset[dev])
            pos[a:a + step] = dp + rng.normal(0.0, 0.0002, dp.shape)
            rot[a:a + step] = dr
        if snaps.size:          # the space turned about the vertical through the standing head
            seg = np.searchsorted(snaps, t)
            yaw = np.concatenate([[0.0], turns])[seg]
            c, s = np.cos(yaw), np.sin(yaw)
            Rz = np.zeros((len(t), 3, 3))
            Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
            pivot = np.array([0.0, 0.0, 0.0])
            pos = np.einsum("nij,nj->ni", Rz, pos - pivot) + pivot
            rot = Rz @ rot
        streams.append(TrackerStream(dev, t, pos, matrix_to_quat(rot)))
    return streams


def make_recording(path, minutes, rate, devices, snap_every=0.0):
    """Write :func:`make_streams` to ``path`` (native CSV, Blender axes, no offsets line)."""
    from blender_manikin.core.io_csv import write_csv
    write_csv(path, make_streams(minutes, rate, devices, snap_every), axes="blender")


def child(args):
    """Solve ``args.csv`` with every stage wrapped; print the rows as JSON."""
    import importlib
    import numpy as np
    from bench_addon import StageMemory, rss_mb
    from blender_manikin.core import formats as fm
    from blender_manikin.core.solve import SolveSettings, solve_recording

    stack, rows = ["other"], {}

    def wrap(name, fn):
        def timed(*a, **kw):
            stack.append(name)
            base, t = rss_mb(), time.perf_counter()
            try:
                return fn(*a, **kw)
            finally:
                dt = time.perf_counter() - t
                stack.pop()
                r = rows.setdefault(name, {"seconds": 0.0, "base": base, "calls": 0})
                r["seconds"] += dt
                r["calls"] += 1
                r["base"] = min(r["base"], base)
        return timed

    for name, mod, attr in STAGES:
        m = importlib.import_module(f"blender_manikin.core.{mod}")
        setattr(m, attr, wrap(name, getattr(m, attr)))
    mem = StageMemory(lambda: stack[-1])
    t = time.perf_counter()
    out = solve_recording(args.csv, SolveSettings(fps=args.fps))
    total = time.perf_counter() - t
    res = out.result
    with tempfile.TemporaryDirectory() as d:
        for fmt in [f for f in args.formats.split(",") if f]:
            w = fm.WRITERS[fmt]
            wrap(WRITE_ROWS.get(fmt, fmt), lambda dst: w.write(dst, res, source="bench"))(
                os.path.join(d, "out" + w.extension))
    peak = mem.stop()
    for name, r in rows.items():
        r["peak_mb"] = max(0.0, peak.get(name, r["base"]) - r["base"])
    print(json.dumps({"rows": rows, "total": total, "frames": int(res.num_frames), "peak_rss": max(peak.values()),
                      "samples": int(sum(len(s.time) for s in out.recording.streams.values())),
                      "finite": bool(np.isfinite(res.local_rot).all())}))


def run_child(csv, fps, formats):
    cmd = [sys.executable, os.path.abspath(__file__), "--child", "--csv", csv, "--fps", str(fps),
           "--formats", formats]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads([ln for ln in out.splitlines() if ln.startswith("{")][-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", default="10,30,60")
    ap.add_argument("--rate", type=float, default=90.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--devices", type=int, choices=(3, 6), default=6)
    ap.add_argument("--formats", default="bvh,json,npz")
    ap.add_argument("--snap-every", type=float, default=0.0,
                    help="seconds between 30-degree snap turns of the tracking space (0: none)")
    ap.add_argument("--keep", help="folder to keep (and reuse) the synthesised recordings in")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--csv", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        return child(args)
    from blender_manikin.core import metrics
    folder = args.keep or tempfile.mkdtemp(prefix="manikin-long-")
    os.makedirs(folder, exist_ok=True)
    minutes = [float(m) for m in args.minutes.split(",")]
    results = {}
    for m in minutes:
        snaps = f"_snap{args.snap_every:g}s" if args.snap_every > 0 else ""
        csv = os.path.join(folder, f"long_{m:g}min_{args.rate:g}hz_{args.devices}dev{snaps}.csv")
        if not os.path.exists(csv):
            t = time.perf_counter()
            make_recording(csv, m, args.rate, args.devices, args.snap_every)
            print(f"made {csv} ({os.path.getsize(csv) / 1e6:.0f} MB) in {time.perf_counter() - t:.0f} s",
                  flush=True)
        results[m] = run_child(csv, args.fps, args.formats)
        r = results[m]
        print(f"{m:g} min: {r['samples']:,} samples -> {r['frames']:,} frames at {args.fps:g} fps, "
              f"solve {r['total']:.1f} s, peak resident {r['peak_rss']:.0f} MB", flush=True)
        if not args.keep:
            os.remove(csv)
    names = [n for n, _, _ in STAGES] + [WRITE_ROWS.get(f, f) for f in args.formats.split(",") if f]
    cols, fmts = [], {}
    for m in minutes:
        cols += [f"{m:g} min s", f"{m:g} min MB"]
        fmts.update({f"{m:g} min s": ".2f", f"{m:g} min MB": ".0f"})
    if len(minutes) > 1:
        cols.append("growth/length")
        fmts["growth/length"] = ".2f"
    table = []
    for n in names:
        vals = {}
        for m in minutes:
            r = results[m]["rows"].get(n)
            vals[f"{m:g} min s"] = r["seconds"] if r else float("nan")
            vals[f"{m:g} min MB"] = r["peak_mb"] if r else float("nan")
        if len(minutes) > 1:
            a, b = results[minutes[0]]["rows"].get(n), results[minutes[-1]]["rows"].get(n)
            ok = a and b and a["seconds"] > 0.02
            vals["growth/length"] = (b["seconds"] / a["seconds"]) / (minutes[-1] / minutes[0]) if ok else float("nan")
        table.append((n, vals))
    snaps = f", a snap turn every {args.snap_every:g} s" if args.snap_every > 0 else ""
    print(f"{args.devices} devices at {args.rate:g} Hz{snaps}, solved at {args.fps:g} fps; {os.cpu_count()} CPUs")
    print(metrics.format_table(table, cols, name_header="stage", formats=fmts))


if __name__ == "__main__":
    main()
