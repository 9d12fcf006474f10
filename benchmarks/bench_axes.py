"""Unity or OpenXR, Blender or Unreal: how often a wide CSV's axes are read the right way
(``core/axes_detect.py``).

Every clip of the Bandai Namco set (all 3,076 takes) and of the HDM05 subset becomes a
recording of a headset and two controllers (the ground truth's head joint and wrists, moved to
the headset and grip poses by the ``openxr_generic`` offsets) and, as a mocap export would be,
of the head joint and wrists themselves.  Each is written in Unity's and in OpenXR's axes (Y
up), and in Blender's and Unreal's (Z up), and read back by the detection: single clips
(1-10 s), and takes of 10 clips one after the other (each clip moved and turned to start where
the one before ended, as one longer recording).  Prints, per row, how many readings the hands'
reach alone (the rule before this module) and the detection got right (Z up: the hands'
left-right line first; then walking, head turns, reach), and which cue decided; then the real
VR recordings of ``../shared/data/vr`` (Beat Saber, Unity axes).  A second table
writes the same headsets and controllers without orientations (a logger of positions only):
the axes read, and the heading :func:`.axes_detect.heading_from_positions` gives against the
hips' facing, beside the single direction unrotated devices faced before.

    .venv/bin/python benchmarks/bench_axes.py [--max-clips N]

Needs ``../shared/data`` (the dataset cache is built on first use, a few minutes).  Nothing is
timed: this is a count of right and wrong readings.
"""
from __future__ import annotations

import argparse
import glob
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

from bench_pose import DATASETS, SHARED, load_clip  # noqa: E402
from blender_manikin.core import axes_detect as ad  # noqa: E402
from blender_manikin.core import device_offsets as do  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core.devices import DEVICE_JOINT  # noqa: E402
from blender_manikin.core.features import heading_yaw  # noqa: E402
from blender_manikin.core.recording import from_blender  # noqa: E402
from blender_manikin.core.skeleton import J  # noqa: E402

DEVICES = ("head", "left_hand", "right_hand")
CONVENTIONS = ("unity", "openxr")
#: the Z-up pair, told apart by the hands' left-right line (Blender right-handed, Unreal left-handed)
CONVENTIONS_Z = ("blender", "unreal")
TAKE_CLIPS = 10


def clip_devices(path, headset, facing=False):
    """``(time, pos, rotm)``: the clip's devices in Blender axes (metres; ``(T, 3)``,
    ``(T, 3, 3)``), the headset and grips (``openxr_generic``) or the joints themselves; with
    ``facing``, also the hips' level facing direction ``(T, 3)`` (the truth for a heading)."""
    _, _, pos, world, fps = load_clip(path)
    if facing:
        side = pos[:, J["right_hip"]] - pos[:, J["left_hip"]]
        f = np.cross([0.0, 0.0, 1.0], side)
        f[:, 2] = 0.0
        f /= np.maximum(np.linalg.norm(f, axis=-1, keepdims=True), 1e-9)
    offsets = do.get_preset("openxr_generic")["devices"]
    P, R = {}, {}
    for d in DEVICES:
        j = DEVICE_JOINT[d]
        if headset:
            P[d], R[d] = do.remove_offsets(pos[:, j], world[:, j], offsets[d], device=d)
        else:
            P[d], R[d] = pos[:, j].copy(), world[:, j].copy()
    if facing:
        return np.arange(len(pos)) / fps, P, R, f
    return np.arange(len(pos)) / fps, P, R


def stitch(clips):
    """One take of ``clips`` (each ``(time, pos, rotm)``) one after the other: each clip turned
    about the vertical and moved so that its head starts where, and facing as, the last one's
    ended; time runs on at the clips' rate."""
    t_all, P_all, R_all = [], {d: [] for d in DEVICES}, {d: [] for d in DEVICES}
    t0 = 0.0
    for k, (t, P, R) in enumerate(clips):
        if k:
            yaw = heading_yaw(R_all["head"][-1][-1]) - heading_yaw(R["head"][0])
            Rz = rot.axis_angle_rotation(np.array([0.0, 0.0, 1.0]), yaw)
            start, end = P["head"][0], P_all["head"][-1][-1]
            P = {d: (p - start) @ Rz.T + end for d, p in P.items()}
            R = {d: Rz @ r for d, r in R.items()}
        dt = t[1] - t[0] if len(t) > 1 else 1 / 30
        t_all.append(t - t[0] + t0)
        t0 = t_all[-1][-1] + dt
        for d in DEVICES:
            P_all[d].append(P[d])
            R_all[d].append(R[d])
    return (np.concatenate(t_all), {d: np.concatenate(v) for d, v in P_all.items()},
            {d: np.concatenate(v) for d, v in R_all.items()})


def stitch_facing(clips):
    """:func:`stitch` of ``(t, P, R, facing)`` clips, the facing turned with each clip."""
    t, P, R = stitch([c[:3] for c in clips])
    facing, prev = [], None
    for c in clips:
        yaw = 0.0
        if prev is not None:
            yaw = heading_yaw(prev) - heading_yaw(c[2]["head"][0])
        Rz = rot.axis_angle_rotation(np.array([0.0, 0.0, 1.0]), yaw)
        facing.append(c[3] @ Rz.T)
        prev = (Rz @ c[2]["head"][-1])
    return t, P, R, np.concatenate(facing)


def read_both_ways(t, P, R, truth, conventions=CONVENTIONS):
    """``(reach_right, chosen_right, cue)`` for the take written in ``truth`` axes, one of
    ``conventions`` (a pair with the same up axis)."""
    pos, quat = {}, {}
    for d in DEVICES:
        pos[d], quat[d] = from_blender(P[d], rot.matrix_to_quat(R[d]), truth)
    ev = {a: ad.facing_evidence(t, pos, quat, a) for a in conventions}
    reach = max(conventions, key=lambda a: ev[a].reach)
    chosen, why = ad.choose_axes(t, pos, lambda a: quat, conventions)
    cue = ("hands" if "left-right line" in why else "walking" if "walking" in why
           else "turns" if "turns" in why else "reach")
    return reach == truth, chosen == truth, cue


def tally(takes, conventions=CONVENTIONS):
    """Counts over ``takes`` (each ``(t, P, R)``) read in both of ``conventions``."""
    n = reach = chosen = 0
    cues = {"hands": 0, "walking": 0, "turns": 0, "reach": 0}
    for t, P, R in takes:
        for truth in conventions:
            r, c, cue = read_both_ways(t, P, R, truth, conventions)
            n += 1
            reach += r
            chosen += c
            cues[cue] += 1
    return n, reach, chosen, cues


def positions_only(takes):
    """``(readings, right, heading errors, fixed errors)`` for ``takes`` (each ``(t, P, R,
    facing)``) written without orientations in both conventions: the axes
    :func:`.axes_detect.choose_axes` picks; the degrees between
    :func:`.axes_detect.heading_from_positions` (read the right way) and the hips' facing, every
    frame; and those of the unrotated devices read before (facing one way all along)."""
    n = right = 0
    errors, fixed = [], []
    for t, P, R, facing in takes:
        fixed.append(np.degrees(np.arccos(np.clip(-facing[:, 1], -1.0, 1.0))))   # identity: facing -Y
        for truth in CONVENTIONS:
            pos = {d: from_blender(P[d], None, truth)[0] for d in DEVICES}
            chosen, _ = ad.choose_axes(t, pos, None, CONVENTIONS)
            n += 1
            right += chosen == truth
        f = ad.heading_from_positions(t, P)
        errors.append(np.degrees(np.arccos(np.clip(np.sum(f * facing, -1), -1.0, 1.0))))
    return n, right, np.concatenate(errors), np.concatenate(fixed)


def vr_rows(conventions=CONVENTIONS):
    from blender_manikin.core.formats import load_recording
    rows = []
    for path in sorted(glob.glob(os.path.join(SHARED, "vr", "*.bsor"))):
        rec = load_recording(path)
        T = min(len(rec.streams[d].time) for d in DEVICES)
        t = rec.streams["head"].time[:T]
        P = {d: rec.streams[d].pos[:T] for d in DEVICES}
        R = {d: rot.quat_to_matrix(rec.streams[d].quat[:T]) for d in DEVICES}
        rows.append((os.path.basename(path), tally([(t, P, R)], conventions)))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-clips", type=int, default=0, help="per dataset (0: all)")
    args = ap.parse_args(argv)
    from blender_manikin.training import dataset

    def row(name, head, per, counts):
        n, reach, chosen, cues = counts
        print(f"| {name} | {head} | {per} | {n} | {100 * reach / n:.1f} % | {100 * chosen / n:.1f} % | "
              f"{cues['hands']} / {cues['walking']} / {cues['turns']} / {cues['reach']} |")

    for conventions, title in ((CONVENTIONS, "Y up: Unity or OpenXR"),
                               (CONVENTIONS_Z, "Z up: Blender or Unreal (first the hands' left-right line)")):
        print(f"\n{title}")
        print("| recordings | head | clips per take | readings | reach alone right | chosen right "
              "| decided by hands / walking / turns / reach |")
        print("|---|---|---:|---:|---:|---:|---|")
        for name, (source, _) in DATASETS.items():
            if not os.path.exists(source):
                print(f"{name}: {source} not found, skipped")
                continue
            files = dataset.build_cache(source, verbose=False)
            files = files[:args.max_clips] if args.max_clips else files
            order = np.random.default_rng(0).permutation(len(files))
            for headset in (True, False):
                clips = [clip_devices(files[i], headset) for i in order]
                clips = [c for c in clips if len(c[0]) >= 4]
                head = "headset" if headset else "head joint"
                row(name, head, 1, tally(clips, conventions))
                groups = [stitch(clips[k:k + TAKE_CLIPS])
                          for k in range(0, len(clips) - TAKE_CLIPS + 1, TAKE_CLIPS)]
                row(name, head, TAKE_CLIPS, tally(groups, conventions))
        for name, counts in vr_rows(conventions):
            row(name, "headset", "whole replay", counts)
    print("\npositions only (no orientation columns): the axes from walking and reaching against the heading "
          "from the hands' left-right line and the walking direction; that heading against the hips' facing")
    print("| recordings | clips per take | readings | axes right | heading error median / 90th pct [deg] "
          "| facing one way (before) [deg] |")
    print("|---|---:|---:|---:|---|---|")
    for name, (source, _) in DATASETS.items():
        if not os.path.exists(source):
            continue
        files = dataset.build_cache(source, verbose=False)
        files = files[:args.max_clips] if args.max_clips else files
        order = np.random.default_rng(0).permutation(len(files))
        clips = [clip_devices(files[i], True, facing=True) for i in order]
        clips = [c for c in clips if len(c[0]) >= 4]
        for per, takes in ((1, clips), (TAKE_CLIPS, [stitch_facing(clips[k:k + TAKE_CLIPS])
                                                     for k in range(0, len(clips) - TAKE_CLIPS + 1, TAKE_CLIPS)])):
            n, right, err, fixed = positions_only(takes)
            print(f"| {name} | {per} | {n} | {100 * right / n:.1f} % | "
                  f"{np.median(err):.1f} / {np.percentile(err, 90):.1f} | "
                  f"{np.median(fixed):.1f} / {np.percentile(fixed, 90):.1f} |")


if __name__ == "__main__":
    main()
