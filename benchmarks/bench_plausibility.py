"""Plausibility on real VR recordings, where there is no ground truth, model against model.

    python benchmarks/bench_plausibility.py [RECORDING ...] [--model M.onnx] [--previous-model P.onnx]

Default recordings: the Beat Saber replay in ``../shared/data/vr`` (a real player, VIVE Pro 2 and
Index controllers, 30 s; legs never observed) and the bundled ``examples/example_recording.csv``
(it starts with a T-pose).  Each is solved exactly as the add-on and the CLI solve it
(``core.solve.solve_recording``: read, resample to 30 fps, device offsets ``auto``,
calibration ``AUTO``) once per model, and the table prints, per recording and model:

* knee flexion (degrees; both knees pooled): median, 10th and 90th percentiles.  A player who
  mostly stands has a median near 0-20 degrees;
* pelvis off the feet: share of the frames with both feet planted on which the pelvis is more
  than 15 cm (horizontally) from the midpoint of the ankles, i.e. the body leans over feet that
  do not carry it;
* foot skating: mean horizontal ankle speed (cm/s) on the frames a foot is planted;
* hands off: share of frames on which a wrist misses its tracker by more than 1 cm, and the
  largest miss (cm); *inside elbow fold*: the share of frames on which a hand misses because its
  tracker is closer to the shoulder than the most-flexed elbow (160°) puts the wrist, even after
  the collar's swing (:meth:`.PoseResult.misses`; the rest of the misses are out of reach);
* the estimated stature (metres) and how the body was sized.

A second table solves standing T- and A-poses made by FK (``benchmarks/standing.py``: bodies of
1.50, 1.75 and 2.00 m, one with the Bandai skeleton's proportions, and the five HDM05 performers'
own skeletons when ``../shared`` has them: another studio, never trained on), and a 1.75 m
performer standing still with the arms hanging down or held forward (as holding controllers).
Each is calibrated as the add-on calibrates (the T-pose found automatically) and solved; the
table gives, after the first half second, the largest knee flexion, the largest ankle-height
error against the calibrated rest body the solve used, and against the performer's own
skeleton (where the body model puts the ankle elsewhere than the performer's skeleton does,
the two differ).

The previous model is the one shipped before the current one
(``benchmarks/models/manikin_s_previous.onnx``); it is skipped with a note when absent.
"""
from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from blender_manikin.core import metrics, skeleton as sk  # noqa: E402
from blender_manikin.core.model_runner import MODELS_DIR  # noqa: E402

J = sk.J
SHARED = os.path.join(os.path.dirname(ROOT), "shared")
DEFAULT_RECORDINGS = [os.path.join(SHARED, "data", "vr", "beatsaber-replay-sample.bsor"),
                      os.path.join(ROOT, "examples", "example_recording.csv")]
PREVIOUS = os.path.join(ROOT, "benchmarks", "models", "manikin_s_previous.onnx")
UNITS = {"knee p10": "deg", "knee median": "deg", "knee p90": "deg", "pelvis off feet": "%",
         "foot skate": "cm/s", "hands off": "%", "inside elbow fold": "%", "hand miss max": "cm",
         "stature": "m"}
COLUMNS = list(UNITS)


def plausibility(result, targets):
    """The table's numbers for one solved :class:`PoseResult` and its tracker targets."""
    P = result.positions
    fps = float(result.fps)
    knees = metrics.knee_flexion(P).reshape(-1)
    contacts = np.asarray(result.contacts, bool) if result.contacts is not None else np.zeros((P.shape[0], 2), bool)
    both = contacts.all(-1)
    mid = P[:, [J["left_ankle"], J["right_ankle"]], :2].mean(1)
    off = np.linalg.norm(P[:, J["pelvis"], :2] - mid, axis=-1) > 0.15
    ankles = P[:, [J["left_ankle"], J["right_ankle"]], :2]
    speed = np.zeros((P.shape[0], 2))
    if P.shape[0] > 1:
        speed[1:] = np.linalg.norm(np.diff(ankles, axis=0), axis=-1) * fps
    misses = []
    for dev, joint in (("left_hand", "left_wrist"), ("right_hand", "right_wrist")):
        misses.append(np.linalg.norm(P[:, J[joint]] - targets.pos[dev], axis=-1))
    miss = np.stack(misses, -1)
    close = np.stack([result.misses(limb, 0.01)[1] for limb in (0, 1)], -1)
    return {
        "knee p10": float(np.percentile(knees, 10)), "knee median": float(np.median(knees)),
        "knee p90": float(np.percentile(knees, 90)),
        "pelvis off feet": float(100.0 * off[both].mean()) if both.any() else 0.0,
        "foot skate": float(100.0 * speed[contacts].mean()) if contacts.any() else 0.0,
        "hands off": float(100.0 * (miss > 0.01).any(-1).mean()),
        "inside elbow fold": float(100.0 * close.any(-1).mean()), "hand miss max": float(100.0 * miss.max()),
        "stature": float(result.body.stature),
    }


def solve_file(path, model):
    """Solve ``path`` as the add-on does (:func:`core.solve.solve_recording`), with ``model``."""
    from blender_manikin.core import pipeline
    from blender_manikin.core.model_runner import ModelRunner
    from blender_manikin.core.solve import SolveSettings, solve_recording
    runner = ModelRunner(model)
    return solve_recording(path, SolveSettings(fps=30.0, offsets="auto", calibration="AUTO"),
                           solver=lambda tg, body, progress=None: pipeline.solve(tg, body, runner, progress=progress))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recordings", nargs="*",
                    help="recordings to solve (default: the Beat Saber replay and the example)")
    ap.add_argument("--model", default=os.path.join(MODELS_DIR, "manikin_s.onnx"))
    ap.add_argument("--previous-model", default=PREVIOUS)
    args = ap.parse_args(argv)
    recordings = args.recordings or [p for p in DEFAULT_RECORDINGS if os.path.isfile(p)]
    missing = [p for p in (args.recordings or DEFAULT_RECORDINGS) if not os.path.isfile(p)]
    for p in missing:
        print(f"skipped (not found): {p}", file=sys.stderr)
    models = [("shipped", args.model)]
    if os.path.isfile(args.previous_model):
        models.append(("previous", args.previous_model))
    else:
        print(f"no previous model at {args.previous_model}", file=sys.stderr)
    rows, notes = [], []
    for path in recordings:
        for label, model in models:
            job = solve_file(path, model)
            row = plausibility(job.result, job.targets)
            rows.append((f"{os.path.basename(path)} / {label}", row))
            if label == "shipped":
                frames = job.result.positions.shape[0]
                notes.append(f"{os.path.basename(path)}: {frames} frames; " + "; ".join(job.info))
    from blender_manikin.core.model_runner import ModelRunner
    from standing import CASES, HOLDS, ankle_error_against, hdm05_performers, solve_standing_full
    others = hdm05_performers()
    if not others:
        print("no HDM05 subset in ../shared: its performers' standing poses skipped", file=sys.stderr)
    cases = ([(f"{who if who == 'bandai' else f'{who:.2f} m'}", who, pose) for who, pose in CASES]
             + [("1.75 m", 1.75, h) for h in HOLDS]
             + [(f"HDM05 {actor}", body, pose) for actor, body in others.items() for pose in ("T", "A")])
    standing = []
    for label, model in models:
        runner = ModelRunner(model)
        for who_name, who, pose in cases:
            knees, ankle_err, _, solved, performer = solve_standing_full(who, pose, runner)
            own = ankle_error_against(solved.positions, performer)
            k = 15
            kind = f"{pose}-pose" if len(pose) == 1 else f"arms {pose}"
            standing.append((f"{who_name} {kind} / {label}",
                             {"knee max [deg]": float(knees[k:-k].max()),
                              "ankle error max [cm]": float(100 * ankle_err[k:-k].max()),
                              "ankle vs performer max [cm]": float(100 * own[k:-k].max())}))
    fmt = {f"{k} [{u}]": ".1f" for k, u in UNITS.items()}
    fmt["stature [m]"] = ".2f"
    rows = [(name, {f"{k} [{UNITS[k]}]": v for k, v in row.items()}) for name, row in rows]
    print(metrics.format_table(rows, list(fmt), name_header="recording / model", formats=fmt))
    for n in notes:
        print(n)
    print("\nStanding calibration poses made by FK (benchmarks/standing.py), after the first half second:")
    cols = ["knee max [deg]", "ankle error max [cm]", "ankle vs performer max [cm]"]
    print(metrics.format_table(standing, cols, name_header="performer / model", formats={c: ".1f" for c in cols}))
    return rows


if __name__ == "__main__":
    main()
