"""Single-core throughput and round-trip accuracy of the analytic limb solver.

    python benchmarks/bench_solver.py [--frames 100000] [--repeat 3] [--chunks 0,4096] [--seed 0]

Generates ``--frames`` random plausible poses (hinge elbows/knees within
their flexion limits, forearm twist within ±70°, moderate torso, hip and
shoulder rotations, any heading), runs forward kinematics to get ground
truth, then times on one core:

* ``solve_limbs``: the batched analytic IK of the 4 limbs with end
  orientations, ``(T, 4)`` arrays;
* ``swivel_from_positions``: ground-truth swivel angles from joint positions;
* ``forward_kinematics``: the 22-joint FK;
* ``round trip``: swivel + solve + FK of the re-assembled pose.

Each stage runs once per entry of ``--chunks``: ``0`` is one call on all
frames, ``N`` calls it on N-frame slices (cache-sized batches are faster
than one huge batch).  Every row reports the best of ``--repeat`` runs
(the machine is shared).
The accuracy columns compare, after positions -> swivel -> solve -> FK, the
wrist/ankle world positions and orientations and the elbow/knee positions
with the ground truth (maximum over all frames and limbs).
"""
from __future__ import annotations

import os

# measure one core: must be set before numpy is imported
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
           "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core.limb_solver import (  # noqa: E402
    A0, H0, LIMB_BASE, LIMB_END, LIMB_MID, LIMB_PARENT, solve_limbs, swivel_from_positions)
from blender_manikin.core.metrics import format_table, rotation_angle  # noqa: E402
from blender_manikin.core.skeleton import J, NUM_JOINTS, forward_kinematics, make_body  # noqa: E402


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _random_rot(rng, n, max_deg):
    axis = rot.normalize(rng.normal(size=(n, 3)))
    angle = np.radians(max_deg) * rng.uniform(0.0, 1.0, size=(n, 1))
    return rot.axis_angle_to_matrix(axis * angle)


def _rot_about(axis, angle):
    axis = np.broadcast_to(np.asarray(axis, np.float64), angle.shape + (3,))
    return rot.axis_angle_to_matrix(axis * angle[..., None])


def random_poses(body, T, rng):
    """``(local_rot (T,22,3,3), root_pos (T,3))`` of random plausible poses."""
    local = np.empty((T, NUM_JOINTS, 3, 3))
    yaw = rng.uniform(-np.pi, np.pi, T)
    local[:, 0] = _rot_about([0, 0, 1.0], yaw) @ _random_rot(rng, T, 15)
    limits = {"spine1": 15, "spine2": 15, "spine3": 15, "neck": 20, "head": 30,
              "left_collar": 10, "right_collar": 10, "left_shoulder": 100, "right_shoulder": 100,
              "left_wrist": 45, "right_wrist": 45, "left_hip": 60, "right_hip": 60,
              "left_ankle": 30, "right_ankle": 30, "left_foot": 20, "right_foot": 20}
    for name, deg in limits.items():
        local[:, J[name]] = _random_rot(rng, T, deg)
    for k, (mid, hi) in enumerate(zip(LIMB_MID, (140.0, 140.0, 135.0, 135.0))):
        flex = np.radians(rng.uniform(5.0, hi, T))
        R = _rot_about(H0[k], flex)
        if k < 2:
            R = R @ _rot_about(A0[k], np.radians(rng.uniform(-70.0, 70.0, T)))
        local[:, mid] = R
    root = np.stack([rng.uniform(-1, 1, T), rng.uniform(-1, 1, T),
                     body.root_rest[2] + rng.uniform(-0.05, 0.05, T)], -1)
    return local, root


def best_time(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _slices(T, chunk):
    if chunk <= 0 or chunk >= T:
        return [slice(0, T)]
    return [slice(s, min(s + chunk, T)) for s in range(0, T, chunk)]


def chunked(fn, T, chunk):
    """Call ``fn(slice)`` over ``chunk``-frame slices (0: one call on all frames)."""
    return [fn(s) for s in _slices(T, chunk)]


def _cat(parts):
    """Concatenate a list of tuples of arrays along frames."""
    return tuple(np.concatenate(x) for x in zip(*parts))


class Problem:
    """Ground-truth poses and the limb-solver inputs derived from them."""

    def __init__(self, T, seed):
        rng = np.random.default_rng(seed)
        self.T = T
        self.body = make_body(1.75)
        self.lengths = self.body.limb_lengths()
        self.local, self.root = random_poses(self.body, T, rng)
        pos, world = forward_kinematics(self.local, self.root, self.body)
        self.base, self.mid, self.end = pos[:, LIMB_BASE], pos[:, LIMB_MID], pos[:, LIMB_END]
        self.par_rot, self.end_rot = world[:, LIMB_PARENT], world[:, LIMB_END]

    def swivel(self, s):
        return swivel_from_positions(self.base[s], self.mid[s], self.end[s], self.par_rot[s])

    def solve(self, s, phi):
        return solve_limbs(self.base[s], self.end[s], phi, self.lengths, self.par_rot[s],
                           end_rot=self.end_rot[s])

    def assemble(self, s, sol):
        """Local rotations of frames ``s`` with the limbs replaced by ``sol``."""
        loc = self.local[s].copy()
        loc[:, LIMB_BASE] = sol.base_local
        loc[:, LIMB_MID] = sol.mid_local
        loc[:, LIMB_END] = sol.end_local
        return loc

    def fk(self, s, loc):
        return forward_kinematics(loc, self.root[s], self.body)

    def round_trip(self, s):
        """positions -> swivel -> solve -> FK for frames ``s``."""
        sol = self.solve(s, self.swivel(s))
        return self.fk(s, self.assemble(s, sol))

    def accuracy(self, pos, world):
        """Max errors of the reconstructed limbs vs the ground truth."""
        e_pos = np.linalg.norm(pos[:, LIMB_END] - self.end, axis=-1)             # (T, 4) m
        e_rot = np.degrees(rotation_angle(world[:, LIMB_END], self.end_rot))     # (T, 4) deg
        e_mid = np.linalg.norm(pos[:, LIMB_MID] - self.mid, axis=-1)
        return {
            "wrist pos [m]": float(e_pos[:, :2].max()), "ankle pos [m]": float(e_pos[:, 2:].max()),
            "wrist rot [deg]": float(e_rot[:, :2].max()), "ankle rot [deg]": float(e_rot[:, 2:].max()),
            "elbow/knee pos [m]": float(e_mid.max()),
        }


def run(problem, chunk, repeat):
    """Table rows for one batch size."""
    P, T = problem, problem.T
    t_sw, (phi,) = best_time(lambda: _cat(chunked(lambda s: (P.swivel(s),), T, chunk)), repeat)
    t_solve, sols = best_time(lambda: chunked(lambda s: P.solve(s, phi[s]), T, chunk), repeat)
    solved = np.concatenate([P.assemble(s, sol) for s, sol in zip(_slices(T, chunk), sols)])
    t_fk, _ = best_time(lambda: _cat(chunked(lambda s: P.fk(s, solved[s]), T, chunk)), repeat)
    t_rt, (pos, world) = best_time(lambda: _cat(chunked(P.round_trip, T, chunk)), repeat)

    def speed(t, limbs=True):
        d = {"time [s]": t, "frames/s": T / t}
        if limbs:
            d["limb-solves/s"] = 4 * T / t
        return d

    tag = "one call" if chunk <= 0 or chunk >= T else f"{chunk}-frame chunks"
    return [
        (f"solve_limbs, 4 limbs + end_rot ({tag})", speed(t_solve)),
        (f"swivel_from_positions ({tag})", speed(t_sw)),
        (f"forward_kinematics, 22 joints ({tag})", speed(t_fk, limbs=False)),
        (f"round trip swivel+solve+FK ({tag})", {**speed(t_rt), **P.accuracy(pos, world)}),
    ]


COLUMNS = ["time [s]", "frames/s", "limb-solves/s", "wrist pos [m]", "ankle pos [m]",
           "wrist rot [deg]", "ankle rot [deg]", "elbow/knee pos [m]"]
FORMATS = {"time [s]": ".3f", "frames/s": ",.0f", "limb-solves/s": ",.0f", "wrist pos [m]": ".1e",
           "ankle pos [m]": ".1e", "wrist rot [deg]": ".1e", "ankle rot [deg]": ".1e",
           "elbow/knee pos [m]": ".1e"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3, help="runs per row; the best is reported")
    ap.add_argument("--chunks", default="0,4096",
                    help="comma-separated frames per call; 0 = all frames in one call (default 0,4096)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if args.frames < 1:
        ap.error("--frames must be >= 1")
    if args.repeat < 1:
        ap.error("--repeat must be >= 1")
    try:
        chunk_list = [int(c) for c in str(args.chunks).split(",") if c.strip()]
    except ValueError:
        ap.error("--chunks must be comma-separated integers")
    if not chunk_list or min(chunk_list) < 0:
        ap.error("--chunks must be non-negative integers")

    problem = Problem(int(args.frames), args.seed)
    rows = []
    for chunk in chunk_list:
        rows += run(problem, chunk, args.repeat)
    print(f"machine: {cpu_model()} ({os.cpu_count()} logical CPUs), Python {platform.python_version()}, "
          f"numpy {np.__version__}; 1 thread (OMP/OPENBLAS/MKL_NUM_THREADS=1)")
    print(f"{args.frames} random plausible poses (seed {args.seed}), body 1.75 m, "
          f"best of {args.repeat} runs per row; errors are maxima over all frames")
    print(format_table(rows, COLUMNS, name_header="stage", formats=FORMATS))
    return rows


if __name__ == "__main__":
    main()
