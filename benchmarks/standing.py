"""Recordings of a performer standing still in a T-pose or an A-pose, made by FK: the standing
calibration check of ``tests/test_standing.py`` and ``benchmarks/bench_plausibility.py``.

Bodies: the solver's own proportions at any stature (``skeleton.make_body``) and one with the
Bandai Namco training skeleton's proportions (long shanks, narrow shoulders, a short neck); the
benchmark also stands the HDM05 subset's five performers on their own skeletons
(:func:`hdm05_performers`, when ``../shared`` is there).
"""
import os

import numpy as np

from blender_manikin.core import calibration as cal
from blender_manikin.core import metrics, pipeline, rotations as rot, skeleton as sk
from blender_manikin.core.devices import DEVICE_JOINT
from blender_manikin.core.pose_result import TrackerTargets

J = sk.J
DEVICE_JOINTS = {"head": J["head"], "left_hand": J["left_wrist"], "right_hand": J["right_wrist"]}
CASES = [(1.50, "T"), (1.75, "T"), (2.00, "T"), (1.50, "A"), (1.75, "A"), (2.00, "A"),
         ("bandai", "T"), ("bandai", "A")]


def bandai_like_body(stature=1.70):
    """A body with the Bandai Namco skeleton's proportions (measured on its cache: thigh 0.262,
    shank 0.275, shoulder joints 0.138, hips 0.087, upper arm 0.163, forearm 0.150 statures;
    ankle 0.050 above the ball; neck to head 0.043)."""
    H = stature
    body = sk.make_body(sk.BodyMeasurements(stature=H, thigh=0.262 * H, shank=0.275 * H,
                                            shoulder_width=0.138 * H, hip_width=0.087 * H,
                                            upper_arm=0.163 * H, forearm=0.150 * H))
    off = body.offsets.copy()
    off[J["head"], 2] = 0.043 * H
    for side in ("left", "right"):
        off[J[f"{side}_foot"], 2] = -0.050 * H
    rest = sk.Body(off, body.root_rest, body.measurements).rest_positions()
    lowest = rest[[J["left_foot"], J["right_foot"]], 2].min()
    root = body.root_rest.copy()
    root[2] += sk.PROPORTIONS["foot_height"] * H + body.sole - lowest
    return sk.Body(off, root, body.measurements)


#: standing still with the arms held otherwise (not calibration poses: the legs must stay
#: straight all the same): arms hanging 85 degrees down; arms forward, elbows bent 60 degrees
#: (holding controllers or sabers in front of the chest)
HOLDS = ("down", "forward")


def standing_targets(body, pose="T", seconds=4.0, fps=30.0, seed=0, devices=None):
    """Joint targets of ``body`` standing still, swaying 1 cm, in a T-pose, an A-pose (arms 40
    degrees down) or one of :data:`HOLDS`: of the head and wrists, or of ``devices`` (each the
    pose of its joint, :data:`.devices.DEVICE_JOINT`: pelvis tracker = pelvis joint, foot
    trackers = ankles)."""
    rng = np.random.default_rng(seed)
    T = int(seconds * fps)
    t = np.arange(T) / fps
    local = np.tile(np.eye(3), (T, sk.NUM_JOINTS, 1, 1))
    y, z = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    if pose in ("A", "down"):
        down = np.radians(40.0 if pose == "A" else 85.0)
        local[:, J["left_shoulder"]] = rot.axis_angle_rotation(y, np.full(T, down))
        local[:, J["right_shoulder"]] = rot.axis_angle_rotation(y, np.full(T, -down))
    elif pose == "forward":
        local[:, J["left_shoulder"]] = rot.axis_angle_rotation(z, np.full(T, -np.pi / 2))
        local[:, J["right_shoulder"]] = rot.axis_angle_rotation(z, np.full(T, np.pi / 2))
        local[:, J["left_elbow"]] = rot.axis_angle_rotation(-z, np.full(T, np.radians(60)))
        local[:, J["right_elbow"]] = rot.axis_angle_rotation(z, np.full(T, np.radians(60)))
    sway = np.radians(0.4) * np.sin(2 * np.pi * 0.3 * t + rng.uniform(0, 6))
    local[:, 0] = rot.axis_angle_rotation(np.array([1.0, 0.0, 0.0]), sway)
    root = np.tile(body.root_rest, (T, 1))
    P, R = sk.forward_kinematics(local, root, body)
    joints = DEVICE_JOINTS if devices is None else {d: DEVICE_JOINT[d] for d in devices}
    return TrackerTargets(fps=fps, pos={d: P[:, j].copy() for d, j in joints.items()},
                          rot={d: R[:, j].copy() for d, j in joints.items()})


def performer_body(who):
    """The performer of a :data:`CASES` entry: ``"bandai"`` (:func:`bandai_like_body`), a stature
    in metres (:func:`skeleton.make_body`), or a :class:`skeleton.Body` as it is (another
    studio's skeleton, :func:`hdm05_performers`)."""
    if isinstance(who, sk.Body):
        return who
    return bandai_like_body() if who == "bandai" else sk.make_body(float(who))


def solve_standing(who, pose, runner):
    """Calibrate (a T-pose found automatically, an A-pose at a given time) and solve; a hold of
    :data:`HOLDS` is solved with the performer's stature, as typed.  Returns ``(knee flexion
    (T, 2) degrees, ankle height error (T, 2) metres, calibration or None)``; the ankle error is
    against the rest body the solve used (:func:`solve_standing_full` also gives the solve)."""
    knees, ankle_err, res, _, _ = solve_standing_full(who, pose, runner)
    return knees, ankle_err, res


def solve_standing_full(who, pose, runner):
    """:func:`solve_standing`, returning ``(knees, ankle_err, calibration or None, solved
    PoseResult, performer Body)``, so the solve can also be held against the performer's own
    skeleton (its rest ankles: :func:`ankle_error_against`)."""
    performer = performer_body(who)
    targets = standing_targets(performer, pose)
    res = None
    if pose in HOLDS:
        body = sk.make_body(performer.stature)
    else:
        if pose == "T":
            cand = cal.find_tpose(targets)
            if not cand.plausible:
                raise ValueError(f"no plausible T-pose found: {cand}")
            frame = cand.frame
        else:
            frame = targets.num_frames // 2
        res = cal.calibrate(targets, frame=frame)
        body = cal.body_for(res.measurements)
    solved = pipeline.solve(targets, body, runner)
    knees = metrics.knee_flexion(solved.positions)
    return knees, ankle_error_against(solved.positions, body), res, solved, performer


def ankle_error_against(positions, body):
    """``(T, 2)`` metres: how far the solved ankle joints (``positions`` ``(T, 22, 3)``, Z-up)
    are above or below ``body``'s ankles at rest, as absolute values."""
    rest_ankle = body.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2]
    return np.abs(positions[:, [J["left_ankle"], J["right_ankle"]], 2] - rest_ankle)


def hdm05_performers():
    """``{actor: Body}``: the HDM05 subset's performers (``bd``, ``bk``, ``dg``, ``mm``, ``tr``),
    each with the skeleton of its first clip in the benchmark's cache (another studio's
    skeletons, mapped onto the 22 joints; their rest pose is a T-pose).  ``{}`` when
    ``../shared/data/validation`` is absent.  Never trained on."""
    from bench_pose import dataset_files, load_clip
    files, _ = dataset_files("hdm05")
    out = {}
    for f in files or []:
        name = os.path.basename(f)
        actor = name.split("_HDM_")[1].split("_")[0] if "_HDM_" in name else None
        if actor and actor not in out:
            out[actor] = load_clip(f)[0]
    return dict(sorted(out.items()))
