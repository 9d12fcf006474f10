"""End-to-end speed and memory of the add-on on long recordings, 10, 30 and 60 minutes side by side.

    python benchmarks/bench_addon.py [--minutes 10,30,60] [--rate 90] [--fps 60] [--no-live-rig]
                                     [--read-hours 2] [--retarget]

For each length: synthesises a three-tracker recording at ``--rate`` Hz
(jittered timestamps, OpenXR axes, the bundled example's performer) as the
native CSV, then imports, solves and keys it at ``--fps`` with the code the
panel and the batch converter run (``blender.solve_job``), in the bpy
module, in a fresh process of its own; and solves the same file with the
Blender-free command line (``python -m blender_manikin solve --format
json,bvh,npz``) in another.  A thread samples the process's resident memory
every 10 ms, so each stage's row shows its seconds and the peak resident
memory (MB) reached while it ran.  With ``--retarget`` each solve is also retargeted (keep ends,
live swivel) onto the tests' Mixamo-style character and onto their CC4-style one with a 150-bone
face rig and 15 bones per hand, in rows of their own.

Then the reader alone: a ``--read-hours`` long, 90 Hz, six-device CSV (the
size of a long session with pelvis and feet trackers) is read in a fresh
process; the table gives MB/s and the peak memory.

Targets (issues): time linear in length; peak memory of a 60-minute take under 1.5 GB
in the command line and 2.5 GB in Blender; the reader at 50 MB/s or more in bounded
memory.  Timings are measured here, never asserted in tests.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "examples"))


def rss_mb():
    """Resident memory of this process now, MB (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError):
        return 0.0


class StageMemory:
    """Peak resident memory per stage: a thread samples :func:`rss_mb` every 10 ms and files
    it under ``stage()`` (a callable giving the current stage's name)."""

    def __init__(self, stage):
        self.stage, self.peak, self._stop = stage, {}, threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            name, mb = self.stage(), rss_mb()
            self.peak[name] = max(self.peak.get(name, 0.0), mb)
            time.sleep(0.01)

    def stop(self):
        self._stop.set()
        self._thread.join()
        return self.peak


# --------------------------------------------------------------------------
# child processes
def child_make(args):
    """Write the synthetic recording of ``args.minutes`` minutes to ``args.csv``."""
    import make_example_recording as mk
    from blender_manikin.core.io_csv import write_csv
    mk.RATES = {"head": args.rate, "left_hand": args.rate, "right_hand": args.rate}
    write_csv(args.csv, mk.synthesize(duration=args.minutes * 60.0), axes="openxr")


def child_make_six(args):
    """A ``args.hours`` long 90 Hz six-device CSV for the reader (smooth synthetic paths)."""
    import numpy as np
    from blender_manikin.core.devices import DEVICES
    n = int(args.hours * 3600 * 90)
    head = "# blender_manikin tracker recording\n# axes: openxr\n# units: m\ntime,device,px,py,pz,qw,qx,qy,qz,valid\n"
    with open(args.csv, "w", encoding="utf-8", newline="\n") as f:
        f.write(head)
        step = 90 * 600           # ten minutes at a time, each device's rows in turn (any order is valid)
        for a in range(0, n, step):
            t = np.arange(a, min(a + step, n)) / 90.0
            for k, d in enumerate(DEVICES):
                ph = t * (0.5 + 0.1 * k)
                q = np.stack([np.cos(0.2 * np.sin(ph)), 0.2 * np.sin(ph), np.zeros_like(t), 0.1 * np.cos(ph)], -1)
                q /= np.linalg.norm(q, axis=-1, keepdims=True)
                pos = np.stack([0.3 * np.sin(ph), 1.0 + 0.1 * np.cos(ph), 0.2 * np.sin(2 * ph)], -1)
                np.savetxt(f, np.concatenate([(t + 0.001 * k)[:, None], pos, q], 1),
                           fmt=f"%.6f,{d},%.6f,%.6f,%.6f,%.7f,%.7f,%.7f,%.7f,1")


def child_blender(args):
    """Solve ``args.csv`` in the bpy module as the panel does; print the stages as JSON."""
    import bpy
    from blender_manikin.blender import solve_job
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = int(args.fps), 1.0
    cfg = solve_job.SolveConfig(source="FILE", filepath=args.csv, fps=args.fps, offsets="openxr_generic",
                                calibration="AUTO", live_rig=not args.no_live_rig)
    job = solve_job.SolveJob(cfg)
    base = rss_mb()
    now = {"stage": None}
    mem = StageMemory(lambda: now["stage"] or job.stage)
    t = time.perf_counter()
    job.run(bpy.context)
    total = time.perf_counter() - t
    if args.retarget:
        # keep-ends and the live swivel rig, as the panel's Retarget to Character does with Keep
        # Ends on: onto the tests' Mixamo-style character (A-pose, rolled bones), then onto their
        # CC4-style one with a face rig and fingers (bones the retarget leaves alone)
        sys.path.insert(0, os.path.join(ROOT, "tests"))
        from blender_util import mixamo_style_character, styled_character
        from blender_manikin.blender import retarget_apply
        for stage, char, bone_map in (
                ("retarget", mixamo_style_character("Character", stature=1.8), "auto"),
                ("retarget cc4", with_face_and_fingers(styled_character("cc4")[0]), "cc4")):
            now["stage"] = stage
            t = time.perf_counter()
            retarget_apply.retarget_onto(job.output.armature, char, bone_map, None, "scaled", True)
            job.timings[stage] = time.perf_counter() - t
    peak = mem.stop()
    print(json.dumps({"timings": job.timings, "total": total, "frames": job.result.num_frames,
                      "peak": peak, "base": base, "summary": job.summary()}))


def with_face_and_fingers(char, face=150, fingers=15):
    """``char`` (a CC4-style armature object) with ``face`` leaf bones under its head and
    ``fingers`` under each hand, as a character with a face rig has them; returns it."""
    import bpy
    bpy.context.view_layer.objects.active = char
    bpy.ops.object.mode_set(mode='EDIT')
    eb = char.data.edit_bones
    for parent, n in (("CC_Base_Head", face), ("CC_Base_L_Hand", fingers), ("CC_Base_R_Hand", fingers)):
        p = eb[parent]
        for i in range(n):
            b = eb.new(f"{parent}_extra_{i:03d}")
            b.head, b.tail, b.parent = p.tail, p.tail + 0.2 * (p.tail - p.head), p
    bpy.ops.object.mode_set(mode='OBJECT')
    return char


def child_cli(args):
    """Solve ``args.csv`` with the Blender-free command line; print the peak memory as JSON."""
    from blender_manikin import cli
    stage = {"now": "solve"}
    mem = StageMemory(lambda: stage["now"])
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        cli.main(["solve", args.csv, "--out", out, "--fps", str(args.fps), "--offsets", "openxr_generic",
                  "--format", "json,bvh,npz"])
    print(json.dumps({"total": time.perf_counter() - t, "peak": max(mem.stop().values())}))


def child_read(args):
    """Read ``args.csv`` with the format registry's reader; print seconds, MB/s and peak memory."""
    from blender_manikin.core.formats import load_recording
    mem = StageMemory(lambda: "read")
    t = time.perf_counter()
    rec = load_recording(args.csv)
    dt = time.perf_counter() - t
    size = os.path.getsize(args.csv) / 1e6
    print(json.dumps({"seconds": dt, "mb": size, "mb_s": size / dt, "peak": mem.stop()["read"],
                      "samples": sum(len(s.time) for s in rec.streams.values())}))


def run_child(kind, **kw):
    cmd = [sys.executable, os.path.abspath(__file__), "--child", kind]
    for k, v in kw.items():
        if v is True:
            cmd.append(f"--{k.replace('_', '-')}")
        elif v not in (None, False):
            cmd += [f"--{k.replace('_', '-')}", str(v)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    return json.loads(lines[-1]) if lines else None


# --------------------------------------------------------------------------
STAGES = [("read", "read", "reading recording"), ("resample", "resample", "resampling"),
          ("calibrate", "calibrate", "calibrating"), ("network (onnxruntime)", "solve.network", None),
          ("solver (torso FK, feet, limbs)", "solve.solver", None), ("solve (network + solver)", None, "solving"),
          ("armature (+ FK keys: no live rig)", "keying", "keying"), ("live swivel rig", "live rig", "live rig")]
#: with --retarget, after the totals (not part of the solve)
RETARGET_STAGES = [("retarget onto Mixamo-style", "retarget", "retarget"),
                   ("retarget onto CC4 + face, fingers", "retarget cc4", "retarget cc4")]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", default="10,30,60", help="comma-separated recording lengths")
    ap.add_argument("--rate", type=float, default=90.0, help="tracker rate, Hz (all three devices)")
    ap.add_argument("--fps", type=float, default=60.0, help="scene / solve frame rate")
    ap.add_argument("--no-live-rig", action="store_true")
    ap.add_argument("--retarget", action="store_true",
                    help="also retarget each solve onto two characters (keep ends, live swivel)")
    ap.add_argument("--read-hours", type=float, default=2.0, help="length of the reader's six-device CSV (0: skip)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--csv", help=argparse.SUPPRESS)
    ap.add_argument("--hours", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        if args.child == "make":
            args.minutes = float(args.minutes)
        return {"make": child_make, "make_six": child_make_six, "blender": child_blender,
                "cli": child_cli, "read": child_read}[args.child](args)

    lengths = [float(m) for m in args.minutes.split(",") if m.strip()]
    tmp = tempfile.mkdtemp(prefix="manikin_bench_")
    runs = {}
    for m in lengths:
        csv = os.path.join(tmp, f"take_{m:g}min.csv")
        run_child("make", csv=csv, minutes=m, rate=args.rate)
        b = run_child("blender", csv=csv, minutes=m, rate=args.rate, fps=args.fps, no_live_rig=args.no_live_rig,
                      retarget=args.retarget)
        c = run_child("cli", csv=csv, minutes=m, fps=args.fps)
        runs[m] = (os.path.getsize(csv) / 1e6, b, c)
        os.remove(csv)
    cols = [f"{m:g} min" for m in lengths]
    w = max(len(s[0]) for s in STAGES) + 2
    cw = 20
    sizes = ", ".join(f"{m:g} min: {runs[m][0]:.0f} MB CSV, {runs[m][1]['frames']} frames" for m in lengths)
    print(f"three trackers at {args.rate:g} Hz, solved at {args.fps:g} fps ({sizes})\n")
    print(f"{'stage (seconds / peak MB)':<{w}}|" + "|".join(f"{c:>{cw}}" for c in cols))
    print(f"{'-' * w}|" + "|".join("-" * cw for _ in cols))
    for name, tkey, skey in STAGES:
        cells = []
        for m in lengths:
            b = runs[m][1]
            secs = b["timings"].get(tkey) if tkey else \
                sum(b["timings"].get(k, 0.0) for k in ("solve.network", "solve.solver"))
            peak = b["peak"].get(skey) if skey else None
            cells.append((f"{secs:8.2f} s" if secs is not None else "") + (f" / {peak:6,.0f}" if peak else ""))
        print(f"{name:<{w}}|" + "|".join(f"{c:>{cw}}" for c in cells))
    def solve_peak(b):
        return max(v for k, v in b["peak"].items() if k not in {r[2] for r in RETARGET_STAGES})
    print(f"{'total in Blender':<{w}}|" + "|".join(
        f"{runs[m][1]['total']:8.2f} s / {solve_peak(runs[m][1]):6,.0f}" for m in lengths))
    print(f"{'frames/s in Blender':<{w}}|" + "|".join(
        f"{runs[m][1]['frames'] / runs[m][1]['total']:>{cw},.0f}" for m in lengths))
    for name, tkey, skey in (RETARGET_STAGES if args.retarget else ()):
        print(f"{name:<{w}}|" + "|".join(
            f"{runs[m][1]['timings'][tkey]:8.2f} s / {runs[m][1]['peak'].get(skey, 0.0):6,.0f}" for m in lengths))
    print(f"{'command line, json+bvh+npz':<{w}}|" + "|".join(
        f"{runs[m][2]['total']:8.2f} s / {runs[m][2]['peak']:6,.0f}" for m in lengths))
    if len(lengths) > 1:
        a, z = lengths[0], lengths[-1]
        print(f"\ntime ratio {z:g} min / {a:g} min: {runs[z][1]['total'] / runs[a][1]['total']:.1f} in Blender, "
              f"{runs[z][2]['total'] / runs[a][2]['total']:.1f} on the command line "
              f"(length ratio {z / a:.1f})")
    if args.read_hours > 0:
        csv = os.path.join(tmp, "six_devices.csv")
        run_child("make_six", csv=csv, hours=args.read_hours)
        r = run_child("read", csv=csv)
        os.remove(csv)
        print(f"\nreader: {args.read_hours:g} h, 90 Hz, six devices: {r['mb']:.0f} MB CSV, {r['samples']:,} samples "
              f"read in {r['seconds']:.2f} s = {r['mb_s']:.0f} MB/s, peak {r['peak']:,.0f} MB")
    os.rmdir(tmp)


if __name__ == "__main__":
    main()
