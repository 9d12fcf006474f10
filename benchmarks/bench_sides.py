"""Left/right swap detection on mocap: how far from a false swap every clip stays, and how many
swapped clips are caught.

For every clip of the Bandai Namco set (all 3,076 takes) and the HDM05 subset, the ground truth's
head joint stands in for the headset, its wrists for the controllers, its ankles for the foot
trackers and its pelvis, turned by a random fixed strap rotation per clip, for a pelvis tracker
(``core/tracker_sides.py``).  Each detector runs on the clip as labelled (a swap found there is
a false swap) and with the two sides exchanged (a swap found there is caught).  Prints one row
per detector: clips with enough frames to decide, the largest share of wrong-side frames in any
clip as labelled (the margin below :data:`SWAPPED_SHARE`), false swaps, swapped clips caught; and
for the pelvis/foot roles (:func:`mixed_pelvis_role`): the smallest height of the pelvis above the
higher ankle (medians over a clip), false swaps, and clips caught with the pelvis and left foot
exchanged; the clips in which a headset lying off is found (``core/headset_off.py``; none
should be: every head is worn); and foot tracker slips (``core/tracker_slips.py``): found in the
clips as recorded (none slipped: each found is false) and caught where the left foot tracker's
strap slides 7 cm up the shin half way through the clip; and the teleports, snap turns and
smaller shifts of the tracking space found in the head and hands (none happened: each is false).

    .venv/bin/python benchmarks/bench_sides.py [--max-clips N]

Needs ``../shared/data`` (the dataset cache is built on first use, a few minutes).
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

from bench_pose import DATASETS, load_clip  # noqa: E402
from blender_manikin.core import tracker_sides as ts  # noqa: E402
from blender_manikin.core.headset_off import headset_off  # noqa: E402
from blender_manikin.core.rotations import axis_angle_to_matrix, matrix_to_quat  # noqa: E402
from blender_manikin.core.pose_result import TrackerTargets  # noqa: E402
from blender_manikin.core.recording import Recording, TrackerStream  # noqa: E402
from blender_manikin.core.teleports import find_rig_jumps  # noqa: E402
from blender_manikin.core.skeleton import J  # noqa: E402
from blender_manikin.core.tracker_slips import find_tracker_slips  # noqa: E402

FEET = {"left_foot": "left_ankle", "right_foot": "right_ankle"}


def detectors(pos, world, fps, rng):
    """name → ``(as labelled, exchanged)``: each a ``(swapped, share, wide_frames)``."""
    head = matrix_to_quat(world[:, J["head"]])
    mount = axis_angle_to_matrix(rng.normal(size=3) * 2.0)         # any strap rotation
    pelvis = matrix_to_quat(world[:, J["pelvis"]] @ mount)
    lw, rw, la, ra = (pos[:, J[j]] for j in ("left_wrist", "right_wrist", "left_ankle", "right_ankle"))
    return {
        "controllers (headset axis)": (ts.swapped_hands(head, lw, rw, fps=fps),
                                       ts.swapped_hands(head, rw, lw, fps=fps)),
        "foot trackers (hips' axis from a pelvis tracker)": (
            ts.swapped_feet(head, la, ra, pelvis, fps=fps), ts.swapped_feet(head, ra, la, pelvis, fps=fps)),
        "foot trackers (headset axis, no pelvis tracker)": (
            ts.swapped_feet(head, la, ra, fps=fps), ts.swapped_feet(head, ra, la, fps=fps)),
    }


def slips(body, pos, world, fps, slide=0.07):
    """``(found as recorded, caught)``: foot tracker slips found in the clip (pelvis and feet
    trackers on their joints), and whether a ``slide`` (m) of the left foot's strap up the shin
    from half way is found on that foot."""
    devs = {"pelvis": "pelvis", "left_foot": "left_ankle", "right_foot": "right_ankle"}
    tg = TrackerTargets(fps=fps, pos={d: pos[:, J[j]] for d, j in devs.items()},
                        rot={d: world[:, J[j]] for d, j in devs.items()})
    rest = float(body.rest_positions()[J["left_ankle"], 2])
    found = find_tracker_slips(tg, fps, rest_ankle_z=rest)
    late = (np.arange(len(pos)) >= len(pos) // 2)[:, None]
    moved = dict(tg.pos, left_foot=tg.pos["left_foot"] + late * slide * tg.rot["left_foot"][:, :, 2])
    caught = find_tracker_slips(TrackerTargets(fps=fps, pos=moved, rot=tg.rot), fps, rest_ankle_z=rest)
    return len(found), any(s.device == "left_foot" and s.slide > slide / 2 for s in caught)


def rig_jumps(pos, world, fps):
    """Teleports and snap turns (``core/teleports.py``) found in the clip's head and hands (none
    happened: each is false)."""
    t = np.arange(len(pos)) / fps
    streams = {d: TrackerStream(d, t, pos[:, J[j]], matrix_to_quat(world[:, J[j]]))
               for d, j in (("head", "head"), ("left_hand", "left_wrist"), ("right_hand", "right_wrist"))}
    return len(find_rig_jumps(Recording(streams=streams, source="mocap")))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-clips", type=int, default=0, help="per dataset (0: all)")
    args = ap.parse_args(argv)
    from blender_manikin.training import dataset
    rows, clips, worst, roles = {}, 0, {}, {}
    rng = np.random.default_rng(0)
    for name, (source, _) in DATASETS.items():
        if not os.path.exists(source):
            print(f"{name}: {source} not found, skipped")
            continue
        files = dataset.build_cache(source, verbose=False)
        for f in files[:args.max_clips] if args.max_clips else files:
            body, _, pos, world, fps = load_clip(f)
            clips += 1
            found, caught = slips(body, pos, world, fps)
            sl = roles.setdefault("slips", dict(found=0, clips=0, caught=0))
            sl["found"] += found
            sl["clips"] += bool(found)
            sl["caught"] += caught
            sl["jumps"] = sl.get("jumps", 0) + rig_jumps(pos, world, fps)
            zp, za = pos[:, J["pelvis"], 2], {d: pos[:, J[j], 2] for d, j in FEET.items()}
            r = roles.setdefault("n", dict(false=0, caught=0, margin=np.inf))
            r["false"] += ts.mixed_pelvis_role(zp, za) is not None
            r["caught"] += ts.mixed_pelvis_role(za["left_foot"], {"left_foot": zp, "right_foot": za["right_foot"]}) \
                == "left_foot"
            r["margin"] = min(r["margin"], float(np.median(zp) - max(np.median(z) for z in za.values())))
            r["headset_off"] = r.get("headset_off", 0) + any(headset_off(pos[:, J["head"]], world[:, J["head"]], fps))
            for det, (kept, swapped) in detectors(pos, world, fps, rng).items():
                r = rows.setdefault(det, dict(decidable=0, false=0, caught=0, max_share=0.0))
                decided = kept[2] >= (ts.MIN_WIDE_S if det.startswith("controllers") else ts.MIN_WIDE_FEET_S) * fps
                if decided:
                    r["decidable"] += 1
                    if kept[1] > r["max_share"]:
                        r["max_share"], worst[det] = kept[1], os.path.basename(str(f))
                r["false"] += bool(kept[0])
                r["caught"] += bool(swapped[0])
    print(f"{clips} mocap clips (Bandai Namco, HDM05); swapped at a share of {ts.SWAPPED_SHARE:.0%}")
    print("| detector | clips decidable | max wrong-side share as labelled | false swaps | swapped clips caught |")
    print("|---|---:|---:|---:|---:|")
    for det, r in rows.items():
        print(f"| {det} | {r['decidable']} | {100 * r['max_share']:.1f} % | {r['false']} | {r['caught']} |")
    r = roles.get("n")
    if r:
        print(f"\npelvis / foot roles (swapped at a foot {ts.ROLE_DROP_M:.2f} m above the pelvis, medians): "
              f"the pelvis at least {100 * r['margin']:+.1f} cm above the higher ankle in every clip; "
              f"false swaps {r['false']}; the pelvis and left foot exchanged, caught in {r['caught']} of {clips}")
        print(f"headset lying off at a clip's start or end (core/headset_off.py; every head is worn): "
              f"found in {r['headset_off']} of {clips}")
    sl = roles.get("slips")
    if sl:
        print(f"foot tracker slips (core/tracker_slips.py, pelvis and feet trackers): {sl['found']} found in "
              f"{sl['clips']} of {clips} clips as recorded (each false); a 7 cm slide of the left foot's strap "
              f"from half way caught in {sl['caught']} of {clips}")
        print(f"jumps of the tracking space (core/teleports.py; none happened): {sl['jumps']} found in {clips} clips")
    for det, f in worst.items():
        print(f"largest share, {det}: {f}")


if __name__ == "__main__":
    main()
