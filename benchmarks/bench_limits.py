"""How often real motion breaks the solver's axial limits, and what enforcing them costs.

    python benchmarks/bench_limits.py [--bvh ../shared/data/bandai-namco-motion.tar.xz] [--every 12]

For every ``--every``-th clip of the training cache (ground truth from
mocap, see ``training/dataset.py``) the swivel of each limb is read off the
ground-truth elbow/knee, the limbs are solved with
``limb_solver.solve_limbs_within_limits`` and the table reports, per limb:
the share of frames whose shoulder/hip axial rotation is outside the bare
AAOS active range and outside ``limb_solver.axial_range`` (what is
enforced), the share of frames the enforcement moved, and
the mean and largest elbow/knee displacement it caused (cm).  Needs ../shared.
"""
from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from blender_manikin.core import limb_solver as ls, metrics, skeleton as sk  # noqa: E402
from bench_pose import load_clip  # noqa: E402  (benchmarks/ is the script's folder)

DEFAULT_BVH = os.path.join(os.path.dirname(ROOT), "shared", "data", "bandai-namco-motion.tar.xz")


def _outside_active(base_local):
    """``(T, 4)`` frames outside the bare AAOS active ranges (no passive margin, no
    widening with arm elevation)."""
    psi, _ = ls.axial_rotation(base_local)
    return (psi > ls.BASE_TWIST_RANGE[:, 0]) | (psi < -ls.BASE_TWIST_RANGE[:, 1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bvh", default=DEFAULT_BVH)
    ap.add_argument("--every", type=int, default=12, help="use every N-th clip")
    args = ap.parse_args(argv)
    from blender_manikin.training import dataset
    files = dataset.build_cache(args.bvh, verbose=False)[::max(args.every, 1)]
    B, M, E, P = ls.LIMB_BASE, ls.LIMB_MID, ls.LIMB_END, ls.LIMB_PARENT
    frames, outside, moved, disp, worst, active = 0, *(np.zeros(4) for _ in range(5))
    for f in files:
        body, _, pos, wr, _ = load_clip(f)
        phi = ls.swivel_from_positions(pos[:, B], pos[:, M], pos[:, E], wr[:, P])
        args_ = (pos[:, B], pos[:, E], phi, body.limb_lengths(), wr[:, P])
        free = ls.solve_limbs(*args_, end_rot=wr[:, E])
        sol, _ = ls.solve_limbs_within_limits(*args_, end_rot=wr[:, E])
        d = np.linalg.norm(sol.mid_pos - free.mid_pos, axis=-1)
        frames += d.shape[0]
        outside += ls.limit_report(free)["base_twist"].sum(0)
        active += _outside_active(free.base_local).sum(0)
        moved += (d > 1e-4).sum(0)
        disp += d.sum(0)
        worst = np.maximum(worst, d.max(0))
    rows = [(name, {"outside AAOS active [%]": 100 * active[i] / frames, "outside [%]": 100 * outside[i] / frames,
                    "moved [%]": 100 * moved[i] / frames, "mean shift [cm]": 100 * disp[i] / frames,
                    "max shift [cm]": 100 * worst[i]})
            for i, (name, *_) in enumerate(sk.LIMBS)]
    print(f"{len(files)} clips, {frames} ground-truth frames of {args.bvh}")
    cols = ["outside AAOS active [%]", "outside [%]", "moved [%]", "mean shift [cm]", "max shift [cm]"]
    fmt = {c: ".4f" if c == "mean shift [cm]" else ".2f" for c in cols}
    print(metrics.format_table(rows, name_header="limb", columns=cols, formats=fmt))


if __name__ == "__main__":
    main()
