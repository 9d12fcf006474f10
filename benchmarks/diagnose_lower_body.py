"""Where the lower-body error comes from: a diagnosis of the shipped pipeline on clips with ground
truth (the HDM05 validation set, the Bandai held-out takes), to decide what to change next.

    python benchmarks/diagnose_lower_body.py [--datasets hdm05,bandai] [--body calibrated|gt|tpose]
        [--model M.onnx] [--max-clips N] [--markdown]

Prints, per dataset:

1. per motion class: the median ankle height on the frames the ground-truth foot is planted,
   solved and true (cm above the floor; the solved body's own standing ankle height beside
   them), and the signed mean error of the pelvis, knees and ankles in the true hips' heading
   frame (side: + to the performer's right; forward: + ahead; up: + higher; cm);
2. the knee error taken apart: the hip and ankle errors the leg inherits, the knee error, and
   the knee error with the best swivel the solved hip and ankle allow (:func:`knee_on_best_swivel`,
   the limb solver's own swivel circle:
   what a perfect swivel angle would leave; the rest is the hip and the ankle);
3. lean: the solved feet against the feet a body leaning into its head's horizontal acceleration
   would have (:func:`lean_fit`; a body accelerating at ``a`` leans ``atan(a / g)`` over its
   feet, so the feet sit ``a / g`` times the head's height behind the head).  ``k`` is the
   share of that lean the solve misses (0: none missed; 1: no lean at all), ``r`` the
   correlation; the feet's error with that share added back is a bound, not a fix the pipeline
   applies.

Nothing here is asserted or tuned: it reads the same clips as ``bench_pose.py``, through the same
calibration (``--body``) and pipeline.  Positions are metres, Z-up, the floor at z = 0.
"""
from __future__ import annotations

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402

from blender_manikin.core import limb_solver as ls, skeleton as sk  # noqa: E402
from blender_manikin.core.metrics import format_table  # noqa: E402

J = sk.J
SIDES = ("left", "right")
BIAS_JOINTS = ("pelvis", "left_knee", "right_knee", "left_ankle", "right_ankle")
#: metres per second squared
GRAVITY = 9.81
#: seconds (Gaussian sigma) the head path is smoothed over before its acceleration is taken
LEAN_SMOOTH_S = 0.25


def heading_frame(gt_pos):
    """``(T, 3, 3)``: per frame the rows side (the true hips' left-to-right direction, level),
    forward (level, the way the hips face) and up (+Z).  gt_pos ``(T, 22, 3)`` metres, Z-up."""
    side = gt_pos[:, J["right_hip"]] - gt_pos[:, J["left_hip"]]
    side = side * np.array([1.0, 1.0, 0.0])
    side /= np.maximum(np.linalg.norm(side, axis=-1, keepdims=True), 1e-9)
    up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), side.shape)
    forward = np.cross(up, side)
    return np.stack([side, forward, up], 1)


def signed_errors(pred_pos, gt_pos, joints=BIAS_JOINTS):
    """``(T, len(joints), 3)`` metres: solved minus true position of each of ``joints``, in the
    true hips' heading frame (side, forward, up; :func:`heading_frame`)."""
    idx = [J[j] for j in joints]
    d = pred_pos[:, idx] - gt_pos[:, idx]
    return np.einsum("tij,tkj->tki", heading_frame(gt_pos), d)


def knee_on_best_swivel(pred_pos, pred_world, lengths, gt_pos):
    """``(T, 2, 3)`` metres: each knee where the limb solver puts it (:func:`.limb_solver.mid_from_swivel`)
    for the solved hip and ankle, the body's leg ``lengths`` (``(4, 2)``, :meth:`.Body.limb_lengths`)
    and the swivel angle of the true knee about that hip-ankle axis: the nearest the knee gets with
    a perfect swivel (the solved knee's distance to it is the swivel's share of the knee error).
    pred_pos, gt_pos ``(T, 22, 3)``; pred_world ``(T, 22, 3, 3)`` the solved world rotations."""
    legs = [2, 3]                                              # LIMBS order: the left and right leg
    base, end = pred_pos[:, ls.LIMB_BASE[legs]], pred_pos[:, ls.LIMB_END[legs]]
    parent = pred_world[:, ls.LIMB_PARENT[legs]]
    phi = ls.swivel_from_positions(base, gt_pos[:, ls.LIMB_MID[legs]], end, parent, limb_ids=legs)
    return ls.mid_from_swivel(base, end, phi, np.asarray(lengths)[legs], parent, limb_ids=legs)


def expected_lean(head_pos, fps):
    """``(T, 2)`` metres: where a body leaning into its head's horizontal acceleration has its
    feet, relative to an upright body's: ``-a / g`` times the head's height (the body pivots over
    its feet, so the head leads them by that much).  head_pos ``(T, 3)``, Z-up; the path is
    smoothed (Gaussian, :data:`LEAN_SMOOTH_S`) before it is differentiated twice."""
    from blender_manikin.core.smoothing import smooth_frames
    smooth = smooth_frames(np.asarray(head_pos, np.float64), LEAN_SMOOTH_S * fps)
    acc = np.gradient(np.gradient(smooth, axis=0), axis=0) * fps * fps
    return -acc[:, :2] * (head_pos[:, 2] / GRAVITY)[:, None]


def lean_fit(lean, feet_error):
    """``(k, r)``: the least-squares share ``k`` of the expected lean (``(N, 2)``, metres) that
    the solved feet miss (``feet_error`` ``(N, 2)``, true minus solved, metres), and the
    correlation ``r`` of the two over both axes."""
    x, y = np.asarray(lean).reshape(-1), np.asarray(feet_error).reshape(-1)
    xx = float(np.dot(x, x))
    if xx <= 0 or x.size < 2:
        return 0.0, 0.0
    return float(np.dot(x, y) / xx), float(np.corrcoef(x, y)[0, 1])


def diagnose_clip(res, gt_pos, fps, contacts, targets):
    """The sums this script reports, for one solved clip: a dict of arrays to pool over clips."""
    P = res.positions
    ank = [J["left_ankle"], J["right_ankle"]]
    planted = np.asarray(contacts[:, :2], bool)
    best = knee_on_best_swivel(P, res.world_rot, res.body.limb_lengths(), gt_pos)
    knees = [J["left_knee"], J["right_knee"]]
    hips = [J["left_hip"], J["right_hip"]]
    feet_p = P[:, ank, :2].mean(1)
    feet_g = gt_pos[:, ank, :2].mean(1)
    return {
        "ankle_z_pred": P[:, ank, 2][planted], "ankle_z_gt": gt_pos[:, ank, 2][planted],
        "bias": signed_errors(P, gt_pos).reshape(len(P), -1),
        "hip": np.linalg.norm(P[:, hips] - gt_pos[:, hips], axis=-1).reshape(-1),
        "knee": np.linalg.norm(P[:, knees] - gt_pos[:, knees], axis=-1).reshape(-1),
        "knee_best_swivel": np.linalg.norm(best - gt_pos[:, knees], axis=-1).reshape(-1),
        "ankle": np.linalg.norm(P[:, ank] - gt_pos[:, ank], axis=-1).reshape(-1),
        "lean": expected_lean(targets.pos["head"], fps), "feet_error": feet_g - feet_p,
    }


def _median_cm(x):
    """The median of ``x`` (metres) in centimetres; NaN (printed n/a) for no values."""
    return 100 * float(np.median(x)) if np.size(x) else float("nan")


def run(name, args, runner):
    import bench_pose as bp
    from blender_manikin.core import pipeline
    files, source = bp.dataset_files(name, args.max_clips)
    if files is None:
        print(f"{name}: {source} not found, skipped", file=sys.stderr)
        return
    pooled, tpose_cache, rest_ankle = {}, {}, []
    for i, f in enumerate(files):
        gt_body, gt_local, gt_pos, gt_world, fps, contacts = bp.load_clip_with_contacts(f)
        if gt_pos.shape[0] < 4:
            continue
        targets = bp.targets_from_gt(gt_pos, gt_world, fps)
        if args.body == "calibrated":
            body = bp.calibrated_body(gt_body)
        elif args.body == "tpose":
            key = gt_body.offsets.tobytes() + gt_body.root_rest.tobytes()
            if key not in tpose_cache:
                tpose_cache[key] = bp.tpose_calibration(gt_body)
            body, offsets = tpose_cache[key]
            targets = bp.with_offsets(targets, offsets)
        else:
            body = gt_body
        rest_ankle.append(body.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2].mean())
        res = pipeline.solve(targets, body, runner)
        d = diagnose_clip(res, gt_pos, fps, contacts, targets)
        for key in (bp.motion_class(f), "all"):
            for k, v in d.items():
                pooled.setdefault(key, {}).setdefault(k, []).append(v)
        if not args.markdown:
            print(f"\r{name}: {i + 1}/{len(files)} clips", end="", file=sys.stderr)
    if not args.markdown:
        print(file=sys.stderr)
    cat = {c: {k: np.concatenate(v) for k, v in d.items()} for c, d in pooled.items()}
    classes = sorted((c for c in cat if c != "all"), key=lambda c: -float(cat[c]["knee"].mean()))
    print(f"\n{name}, {args.body} body ({os.path.basename(source)}); the solved body's standing ankle "
          f"{100 * float(np.mean(rest_ankle)):.1f} cm above the floor on average")
    cols = ["frames", "planted ankle z solved [cm]", "planted ankle z true [cm]"]
    for j in BIAS_JOINTS:
        cols.append(f"{j} side/fwd/up [cm]")
    rows = []
    for c in classes + ["all"]:
        d = cat[c]
        row = {"frames": len(d["bias"]), "planted ankle z solved [cm]": _median_cm(d["ankle_z_pred"]),
               "planted ankle z true [cm]": _median_cm(d["ankle_z_gt"])}
        b = 100 * d["bias"].reshape(len(d["bias"]), len(BIAS_JOINTS), 3).mean(0)
        for k, j in enumerate(BIAS_JOINTS):
            row[f"{j} side/fwd/up [cm]"] = "{:+.1f} / {:+.1f} / {:+.1f}".format(*b[k])
        rows.append((c, row))
    print(format_table(rows, cols, name_header="class", formats={"planted ankle z solved [cm]": ".1f",
                                            "planted ankle z true [cm]": ".1f"}))
    print(f"\nknee error taken apart, {name}:")
    cols = ["hip [cm]", "ankle [cm]", "knee [cm]", "knee, best swivel [cm]", "lean k", "lean r",
            "feet [cm]", "feet, k of the lean added [cm]"]
    rows = []
    for c in classes + ["all"]:
        d = cat[c]
        k, r = lean_fit(d["lean"], d["feet_error"])
        rows.append((c, {"hip [cm]": 100 * d["hip"].mean(), "ankle [cm]": 100 * d["ankle"].mean(),
                         "knee [cm]": 100 * d["knee"].mean(),
                         "knee, best swivel [cm]": 100 * d["knee_best_swivel"].mean(),
                         "lean k": k, "lean r": r,
                         "feet [cm]": 100 * np.linalg.norm(d["feet_error"], axis=-1).mean(),
                         "feet, k of the lean added [cm]":
                             100 * np.linalg.norm(d["feet_error"] - k * d["lean"], axis=-1).mean()}))
    print(format_table(rows, cols, name_header="class", formats={c: ".2f" for c in cols}))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", default="hdm05", help="comma-separated: hdm05, bandai (default hdm05)")
    ap.add_argument("--body", default="calibrated", choices=("calibrated", "gt", "tpose"),
                    help="the body each clip is solved with, as bench_pose.py's --body")
    ap.add_argument("--model", default=None, help="the pose network (default: the shipped one)")
    ap.add_argument("--max-clips", type=int, default=0, help="clips per dataset (0: all)")
    ap.add_argument("--markdown", action="store_true", help="no progress lines")
    args = ap.parse_args(argv)
    from blender_manikin.core.model_runner import ModelRunner
    runner = ModelRunner(args.model)
    for name in [d.strip() for d in args.datasets.split(",") if d.strip()]:
        run(name, args, runner)


if __name__ == "__main__":
    main()
