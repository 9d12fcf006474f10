"""Accuracy and speed of MANIKIN against its baselines, on held-out takes, in one run.

    python benchmarks/bench_pose.py [--bvh ../shared/data/bandai-namco-motion.tar.xz]
        [--model blender_manikin/models/manikin_s.onnx]
        [--fk-model benchmarks/models/baseline_fk.onnx] [--max-clips N]

For every validation clip of the training cache (whole takes the network
never saw, see ``training/dataset.py``) the ground truth is posed by FK on
the clip's own body, the head and wrist joint poses are given as tracker
targets, and each method solves the whole clip:

(a) MANIKIN: network + analytic limbs (``core.pipeline.solve``);
(b) network only: the same backbone trained to predict all 22 rotations,
    posed by FK (AvatarPoser approach, ``core.baselines.network_only``);
(c) classic IK: body under the head, straight spine, two-bone IK arms with
    a fixed pole, straight planted legs (``core.baselines.classic_ik``);
(d) MANIKIN without lower-body IK: legs from (b)'s rotations.

Metrics are frame-weighted means over the clips (``core.metrics``).
frames/s is the whole method (network + solver) in batch: all validation
clips back to back as one sequence solved in one call, on this machine's CPU
(onnxruntime with up to 2 threads here); it is measured, never asserted.
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

from blender_manikin.core import baselines, metrics, pipeline, rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.model_runner import ModelRunner, MODELS_DIR  # noqa: E402
from blender_manikin.core.pose_result import TrackerTargets  # noqa: E402

DEFAULT_BVH = os.path.join(os.path.dirname(ROOT), "shared", "data", "bandai-namco-motion.tar.xz")
COLUMNS = ["MPJPE", "MPJRE", "MPJVE", "H-PE", "U-PE", "L-PE", "Jitter", "GP", "frames/s", "params"]


def load_clip(path):
    with np.load(path) as z:
        body = sk.Body.from_offsets(z["offsets"], z["root_rest"], stature=float(z["stature"]))
        local = rot.quat_to_matrix(z["local_quat"].astype(np.float64))
        root = z["root_pos"].astype(np.float64)
        fps = float(z["fps"])
    pos, world = sk.forward_kinematics(local, root, body)
    return body, local, pos, world, fps


def targets_from_gt(pos, world, fps):
    dev = {"head": sk.J["head"], "left_hand": sk.J["left_wrist"], "right_hand": sk.J["right_wrist"]}
    return TrackerTargets(fps=fps, pos={d: pos[:, j].copy() for d, j in dev.items()},
                          rot={d: world[:, j].copy() for d, j in dev.items()})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bvh", default=DEFAULT_BVH, help="the training source (folder or archive)")
    ap.add_argument("--model", default=os.path.join(MODELS_DIR, "manikin_s.onnx"))
    ap.add_argument("--fk-model", default=os.path.join(ROOT, "benchmarks", "models", "baseline_fk.onnx"),
                    help="the network-only baseline (kind fk; not shipped in the add-on)")
    ap.add_argument("--max-clips", type=int, default=0, help="limit the validation clips (0: all)")
    ap.add_argument("--markdown", action="store_true", help="print only the table")
    args = ap.parse_args(argv)

    from blender_manikin.training import dataset   # training cache layout (numpy only here)
    files = dataset.build_cache(args.bvh, verbose=False)
    _, val_files, split = dataset.split_files(files)
    if args.max_clips:
        val_files = val_files[:args.max_clips]
    runner = ModelRunner(args.model)
    fk_runner = ModelRunner(args.fk_model) if os.path.isfile(args.fk_model) else None

    methods = {
        "(a) MANIKIN (network + analytic limbs)": lambda tg, b: pipeline.solve(tg, b, runner),
        "(c) classic IK (Blender-style rig)": lambda tg, b: baselines.classic_ik(tg, b),
    }
    params = {"(a) MANIKIN (network + analytic limbs)": runner.num_parameters,
              "(c) classic IK (Blender-style rig)": 0}
    if fk_runner is not None:
        methods["(b) network only (FK, AvatarPoser-style)"] = lambda tg, b: baselines.network_only(tg, b, fk_runner)
        methods["(d) MANIKIN without lower-body IK"] = lambda tg, b: pipeline.solve(
            tg, b, runner, lower_body="fk", fk_runner=fk_runner)
        params["(b) network only (FK, AvatarPoser-style)"] = fk_runner.num_parameters
        params["(d) MANIKIN without lower-body IK"] = runner.num_parameters + fk_runner.num_parameters
    order = sorted(methods)

    sums = {m: {} for m in order}
    frames = 0
    all_targets = []
    for i, f in enumerate(val_files):
        body, gt_local, gt_pos, gt_world, fps = load_clip(f)
        tg = targets_from_gt(gt_pos, gt_world, fps)
        T = gt_pos.shape[0]
        if T < 4:
            continue
        frames += T
        all_targets.append((tg, body))
        for m in order:
            res = methods[m](tg, body)
            ev = metrics.evaluate(res.positions, res.local_rot, gt_pos, gt_local, fps, body=body)
            for k, v in ev.items():
                sums[m][k] = sums[m].get(k, 0.0) + v * T
        if not args.markdown:
            print(f"\r{i + 1}/{len(val_files)} clips, {frames} frames", end="", file=sys.stderr)
    if not args.markdown:
        print(file=sys.stderr)
    # speed in batch: every validation clip back to back as one sequence, solved in one call
    big = TrackerTargets(fps=all_targets[0][0].fps,
                         pos={d: np.concatenate([t.pos[d] for t, _ in all_targets]) for d in all_targets[0][0].pos},
                         rot={d: np.concatenate([t.rot[d] for t, _ in all_targets]) for d in all_targets[0][0].rot})
    seconds = {}
    for m in order:
        methods[m](TrackerTargets(fps=big.fps, pos={d: v[:200] for d, v in big.pos.items()},
                                  rot={d: v[:200] for d, v in big.rot.items()}), all_targets[0][1])   # warm-up
        t = time.perf_counter()
        methods[m](big, all_targets[0][1])
        seconds[m] = time.perf_counter() - t
    rows = []
    for m in order:
        row = {k: v / frames for k, v in sums[m].items()}
        row["frames/s"] = big.num_frames / max(seconds[m], 1e-9)
        row["params"] = int(params[m])
        rows.append((m, row))
    if not args.markdown:
        print(f"validation: {len(val_files)} held-out clips ({frames} frames at 30 fps) of {args.bvh}; "
              f"split {split.get('rule', 'sha1(take_id) bucket')}")
        print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
              f"numpy {np.__version__}")
    fmt = {"frames/s": ",.0f", "params": ",d", "H-PE": ".4f", "GP": ".4f", "MPJRE": ".2f", "MPJPE": ".3f"}
    print(metrics.format_table(rows, COLUMNS, formats=fmt, units=True))
    if not args.markdown:
        print("units: positions cm, MPJRE deg, MPJVE cm/s, Jitter 10^2 m/s^3, GP cm")
    return rows


if __name__ == "__main__":
    main()
