"""A performer standing in a T-pose or an A-pose is solved standing straight.

Every real recording starts with a calibration pose, and the solve must show a body standing
on straight legs there, whatever the performer's size or proportions: knees flexed less than
10 degrees and ankles within 2 cm of the rest body's ankle height.  The recordings are made here
by FK of standing bodies of 1.50, 1.75 and 2.00 m (the solver's own proportions) and of a body
with the proportions of the Bandai Namco training skeleton (long shanks, narrow shoulders, a
short neck), with a little sway; calibration finds the pose and sizes the body, and the shipped
network solves it (the whole core pipeline, no Blender).
"""
import numpy as np
import pytest

from blender_manikin.core import calibration as cal
from blender_manikin.core import metrics, pipeline, rotations as rot, skeleton as sk
from blender_manikin.core.model_runner import load_model
from blender_manikin.core.pose_result import TrackerTargets

J = sk.J
DEVICE_JOINTS = {"head": J["head"], "left_hand": J["left_wrist"], "right_hand": J["right_wrist"]}


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
    root[2] += sk.PROPORTIONS["foot_height"] * H - lowest
    return sk.Body(off, root, body.measurements)


def standing_targets(body, pose="T", seconds=4.0, fps=30.0, seed=0):
    """Head and wrist joint targets of ``body`` standing still in a T- or A-pose, swaying 1 cm."""
    rng = np.random.default_rng(seed)
    T = int(seconds * fps)
    t = np.arange(T) / fps
    local = np.tile(np.eye(3), (T, sk.NUM_JOINTS, 1, 1))
    if pose == "A":
        down = np.radians(40.0)
        local[:, J["left_shoulder"]] = rot.axis_angle_rotation(np.array([0.0, 1.0, 0.0]), np.full(T, down))
        local[:, J["right_shoulder"]] = rot.axis_angle_rotation(np.array([0.0, 1.0, 0.0]), np.full(T, -down))
    sway = np.radians(0.4) * np.sin(2 * np.pi * 0.3 * t + rng.uniform(0, 6))
    local[:, 0] = rot.axis_angle_rotation(np.array([1.0, 0.0, 0.0]), sway)
    root = np.tile(body.root_rest, (T, 1))
    P, R = sk.forward_kinematics(local, root, body)
    return TrackerTargets(fps=fps, pos={d: P[:, j].copy() for d, j in DEVICE_JOINTS.items()},
                          rot={d: R[:, j].copy() for d, j in DEVICE_JOINTS.items()})


CASES = [(1.50, "T"), (1.75, "T"), (2.00, "T"), (1.50, "A"), (1.75, "A"), (2.00, "A"),
         ("bandai", "T"), ("bandai", "A")]


@pytest.mark.parametrize("who,pose", CASES, ids=[f"{w}-{p}" for w, p in CASES])
def test_standing_calibration_pose_is_solved_standing_straight(who, pose):
    performer = bandai_like_body() if who == "bandai" else sk.make_body(float(who))
    targets = standing_targets(performer, pose)
    if pose == "T":             # found automatically
        cand = cal.find_tpose(targets)
        assert cand.plausible, cand
        frame = cand.frame
    else:                       # an A-pose is calibrated at a given time (--calibration-time)
        frame = targets.num_frames // 2
    res = cal.calibrate(targets, frame=frame)
    assert res.pose == pose
    body = cal.body_for(res.measurements)
    solved = pipeline.solve(targets, body, load_model())
    knees = metrics.knee_flexion(solved.positions)
    rest_ankle = body.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2]
    ankle_err = np.abs(solved.positions[:, [J["left_ankle"], J["right_ankle"]], 2] - rest_ankle)
    # every frame after the first half second (the network's window is centred; edges padded)
    k = int(0.5 * targets.fps)
    assert knees[k:-k].max() < 10.0, f"knees flexed {knees[k:-k].max():.1f} deg (median {np.median(knees):.1f})"
    assert ankle_err[k:-k].max() < 0.02, f"ankles {100 * ankle_err[k:-k].max():.1f} cm off the rest height"
