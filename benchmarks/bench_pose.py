"""Accuracy and speed of MANIKIN against its baselines, on the Bandai Namco held-out takes and on
the HDM05 validation set (another studio, other people and motions), side by side, in one run.

    python benchmarks/bench_pose.py [--datasets bandai,hdm05] [--model M.onnx]
        [--previous-model P.onnx] [--fk-model F.onnx] [--max-clips N] [--markdown]

Ground truth: every clip is mapped onto the 22-joint body and solved by HybrIK into the cache
the training uses (``training/dataset.py``; HDM05 through ``core/asf_amc.py``), and posed by FK
on the clip's own skeleton.  Inputs: its head and wrist joint poses.  Bandai: the validation
split (whole takes the network never saw).  HDM05: every clip (it is never trained on).

Each set is solved twice (``--body calibrated,gt``): with the body a T-pose calibration gives
(the solver's own proportions, ``skeleton.make_body``, sized to the performer's stature and
arm span, as for a real user: the error then includes the skeletons' differences), and with
the true skeleton.

Methods: (a) the shipped model, network + analytic limbs (``core.pipeline.solve``); (p) the
previously shipped model, same pipeline; (b) the network-only baseline: the same backbone trained
to predict all 22 rotations, posed by FK (AvatarPoser-style, ``core.baselines.network_only``);
(c) classic IK: body under the head, straight spine, two-bone arms with a fixed pole, straight
planted legs (``core.baselines.classic_ik``).

Columns (frame-weighted means over clips, ``core.metrics``): MPJPE, U-PE, L-PE, knee and ankle
position errors (cm), H-PE (hands, cm), Jitter (10^2 m/s^3; GT: the ground truth's own),
GP (ground penetration, cm), foot skating (cm/s: horizontal speed of a predicted ankle on the
frames the ground-truth foot is planted), frames/s (the whole method on all the set's frames
in one call, this machine's CPU; measured, never asserted).
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from blender_manikin.core import baselines, features, metrics, pipeline, rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.model_runner import ModelRunner, MODELS_DIR  # noqa: E402
from blender_manikin.core.pose_result import TrackerTargets  # noqa: E402

SHARED = os.path.join(os.path.dirname(ROOT), "shared", "data")
DATASETS = {
    "bandai": (os.path.join(SHARED, "bandai-namco-motion.tar.xz"), "val"),
    "hdm05": (os.path.join(SHARED, "validation", "hdm05-subset.tar.xz"), "all"),
}
DEFAULT_BVH = DATASETS["bandai"][0]
PREVIOUS = os.path.join(ROOT, "benchmarks", "models", "manikin_s_previous.onnx")
COLUMNS = ["MPJPE", "U-PE", "L-PE", "knee", "ankle", "H-PE", "Jitter", "Jitter-GT", "GP", "skate", "frames/s"]
UNITS = {"MPJPE": "cm", "U-PE": "cm", "L-PE": "cm", "knee": "cm", "ankle": "cm", "H-PE": "cm",
         "Jitter": "1e2 m/s^3", "Jitter-GT": "1e2 m/s^3", "GP": "cm", "skate": "cm/s", "frames/s": ""}
KNEES = [sk.J["left_knee"], sk.J["right_knee"]]
ANKLES = [sk.J["left_ankle"], sk.J["right_ankle"]]


def load_clip(path):
    """``(body, local (T,22,3,3), positions (T,22,3), world (T,22,3,3), fps)`` of a cache clip, posed
    by FK on its own skeleton."""
    body, local, pos, world, fps, _ = load_clip_with_contacts(path)
    return body, local, pos, world, fps


def load_clip_with_contacts(path):
    with np.load(path) as z:
        body = sk.Body.from_offsets(z["offsets"], z["root_rest"], stature=float(z["stature"]))
        local = rot.quat_to_matrix(z["local_quat"].astype(np.float64))
        root = z["root_pos"].astype(np.float64)
        fps = float(z["fps"])
        contacts = z["contacts"].astype(bool)
    pos, world = sk.forward_kinematics(local, root, body)
    return body, local, pos, world, fps, contacts


def targets_from_gt(pos, world, fps):
    dev = {"head": sk.J["head"], "left_hand": sk.J["left_wrist"], "right_hand": sk.J["right_wrist"]}
    return TrackerTargets(fps=fps, pos={d: pos[:, j].copy() for d, j in dev.items()},
                          rot={d: world[:, j].copy() for d, j in dev.items()})


def calibrated_body(gt_body):
    """The body a T-pose calibration builds for this performer: the solver's proportions at the
    performer's stature (the skeleton's head above its ankles / 0.871) and wrist-to-wrist span."""
    stature = float(features.stature_from_offsets(gt_body.offsets))
    rest = gt_body.rest_positions()
    span = float(np.linalg.norm(rest[sk.J["left_wrist"]] - rest[sk.J["right_wrist"]]))
    return sk.make_body(sk.BodyMeasurements(stature=stature, arm_span=span))


def clip_metrics(res, gt_local, gt_pos, fps, contacts):
    ev = metrics.evaluate(res.positions, res.local_rot, gt_pos, gt_local, fps)
    P = res.positions
    ev["knee"] = float(100 * np.linalg.norm(P[:, KNEES] - gt_pos[:, KNEES], axis=-1).mean())
    ev["ankle"] = float(100 * np.linalg.norm(P[:, ANKLES] - gt_pos[:, ANKLES], axis=-1).mean())
    speed = np.zeros((P.shape[0], 2))
    if P.shape[0] > 1:
        speed[1:] = np.linalg.norm(np.diff(P[:, ANKLES, :2], axis=0), axis=-1) * fps
    planted = contacts[:, :2]
    ev["skate"] = float(100 * speed[planted].mean()) if planted.any() else 0.0
    return ev


def dataset_files(name, max_clips=0):
    from blender_manikin.training import dataset   # the training cache (numpy only here)
    source, part = DATASETS[name]
    if not os.path.exists(source):
        return None, source
    files = dataset.build_cache(source, verbose=False)
    if part == "val":
        files = dataset.split_files(files)[1]
    return (files[:max_clips] if max_clips else files), source


def run_dataset(name, methods, args, body_mode):
    files, source = dataset_files(name, args.max_clips)
    if files is None:
        print(f"{name}: {source} not found, skipped", file=sys.stderr)
        return None
    sums = {m: {} for m in methods}
    frames, all_targets = 0, []
    for i, f in enumerate(files):
        gt_body, gt_local, gt_pos, gt_world, fps, contacts = load_clip_with_contacts(f)
        T = gt_pos.shape[0]
        if T < 4:
            continue
        body = calibrated_body(gt_body) if body_mode == "calibrated" else gt_body
        tg = targets_from_gt(gt_pos, gt_world, fps)
        frames += T
        all_targets.append((tg, body))
        for m, fn in methods.items():
            ev = clip_metrics(fn(tg, body), gt_local, gt_pos, fps, contacts)
            for k, v in ev.items():
                sums[m][k] = sums[m].get(k, 0.0) + v * T
        if not args.markdown:
            print(f"\r{name}: {i + 1}/{len(files)} clips, {frames} frames", end="", file=sys.stderr)
    if not args.markdown:
        print(file=sys.stderr)
    # speed: every clip back to back as one sequence, solved in one call
    big = TrackerTargets(fps=all_targets[0][0].fps,
                         pos={d: np.concatenate([t.pos[d] for t, _ in all_targets]) for d in all_targets[0][0].pos},
                         rot={d: np.concatenate([t.rot[d] for t, _ in all_targets]) for d in all_targets[0][0].rot})
    rows = []
    for m, fn in methods.items():
        fn(TrackerTargets(fps=big.fps, pos={d: v[:200] for d, v in big.pos.items()},
                          rot={d: v[:200] for d, v in big.rot.items()}), all_targets[0][1])     # warm-up
        t = time.perf_counter()
        fn(big, all_targets[0][1])
        row = {k: v / frames for k, v in sums[m].items()}
        row["frames/s"] = big.num_frames / max(time.perf_counter() - t, 1e-9)
        rows.append((m, row))
    return dict(name=name, body=body_mode, source=source, clips=len(files), frames=frames, rows=rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", default="bandai,hdm05", help="comma-separated: " + ",".join(DATASETS))
    ap.add_argument("--model", default=os.path.join(MODELS_DIR, "manikin_s.onnx"))
    ap.add_argument("--previous-model", default=PREVIOUS, help="the model shipped before (skipped if absent)")
    ap.add_argument("--fk-model", default=os.path.join(ROOT, "benchmarks", "models", "baseline_fk.onnx"),
                    help="the network-only baseline (kind fk; not shipped in the add-on)")
    ap.add_argument("--body", default="calibrated,gt",
                    help="bodies to solve with, comma-separated: calibrated (what a T-pose calibration "
                         "builds) and/or gt (the true skeleton)")
    ap.add_argument("--max-clips", type=int, default=0, help="limit the clips per dataset (0: all)")
    ap.add_argument("--markdown", action="store_true", help="print only the tables")
    args = ap.parse_args(argv)

    runner = ModelRunner(args.model)
    methods = {"(a) MANIKIN, shipped model": lambda tg, b: pipeline.solve(tg, b, runner)}
    if os.path.isfile(args.previous_model) and os.path.abspath(args.previous_model) != os.path.abspath(args.model):
        prev = ModelRunner(args.previous_model)
        methods["(p) MANIKIN, previous model"] = lambda tg, b: pipeline.solve(tg, b, prev)
    if os.path.isfile(args.fk_model):
        fk_runner = ModelRunner(args.fk_model)
        methods["(b) network only (FK, AvatarPoser-style)"] = lambda tg, b: baselines.network_only(tg, b, fk_runner)
    methods["(c) classic IK (Blender-style rig)"] = lambda tg, b: baselines.classic_ik(tg, b)

    results = []
    for name in [d.strip() for d in args.datasets.split(",") if d.strip()]:
        if name not in DATASETS:
            raise SystemExit(f"unknown dataset {name!r}: choose from {', '.join(DATASETS)}")
        for body_mode in [b.strip() for b in args.body.split(",") if b.strip()]:
            if body_mode not in ("calibrated", "gt"):
                raise SystemExit(f"unknown body {body_mode!r}: choose calibrated or gt")
            r = run_dataset(name, methods, args, body_mode)
            if r is not None:
                results.append(r)
    if not args.markdown:
        print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, numpy {np.__version__}")
    fmt = {"frames/s": ",.0f", "H-PE": ".4f", "GP": ".4f", "MPJPE": ".2f"}
    for r in results:
        what = "calibrated body (T-pose: stature and arm span)" if r["body"] == "calibrated" else "true skeleton"
        print(f"\n{r['name']}, {what}: {r['clips']} clips, {r['frames']} frames at 30 fps "
              f"({os.path.basename(r['source'])})")
        rows = [(m, {(f"{k} [{UNITS[k]}]" if UNITS.get(k) else k): v for k, v in row.items() if k in UNITS})
                for m, row in r["rows"]]
        cols = [f"{k} [{UNITS[k]}]" if UNITS[k] else k for k in COLUMNS]
        f2 = {(f"{k} [{UNITS[k]}]" if UNITS.get(k) else k): v for k, v in fmt.items()}
        print(metrics.format_table(rows, cols, formats=f2))
    return results


if __name__ == "__main__":
    main()
