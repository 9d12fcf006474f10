"""The lower-body diagnosis's geometry (the script itself needs ../shared's data)."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks"))

import diagnose_lower_body as dg  # noqa: E402
from blender_manikin.core import rotations as rot, skeleton as sk  # noqa: E402

J = sk.J


def _bent_pose(T=4):
    """``(positions (T, 22, 3) metres, world rotations (T, 22, 3, 3), body)``: a 1.75 m body with
    both knees bent 40 degrees (FK)."""
    body = sk.make_body(1.75)
    local = np.broadcast_to(np.eye(3), (T, 22, 3, 3)).copy()
    for s in ("left", "right"):
        local[:, J[f"{s}_hip"]] = rot.axis_angle_to_matrix(np.array([-0.35, 0.0, 0.0]))
        local[:, J[f"{s}_knee"]] = rot.axis_angle_to_matrix(np.array([0.7, 0.0, 0.0]))
    pos, world = sk.forward_kinematics(local, np.tile(body.root_rest, (T, 1)), body)
    return np.asarray(pos), np.asarray(world), body


def _turn_knees(pos, angle):
    """The knees turned by ``angle`` radians about each hip-to-ankle axis (the swivel)."""
    out = pos.copy()
    for s in ("left", "right"):
        h, a = pos[:, J[f"{s}_hip"]], pos[:, J[f"{s}_ankle"]]
        u = (a - h) / np.linalg.norm(a - h, axis=-1, keepdims=True)
        R = rot.axis_angle_to_matrix(u * angle)
        out[:, J[f"{s}_knee"]] = h + np.einsum("tij,tj->ti", R, pos[:, J[f"{s}_knee"]] - h)
    return out


def test_best_swivel_finds_the_true_knee_on_the_solved_circle():
    gt, world, body = _bent_pose()
    lengths = body.limb_lengths()
    knees = [J["left_knee"], J["right_knee"]]
    assert np.allclose(dg.knee_on_best_swivel(gt, world, lengths, gt), gt[:, knees], atol=1e-9)
    turned = _turn_knees(gt, np.radians(35.0))
    raw = np.linalg.norm(turned[:, knees] - gt[:, knees], axis=-1)
    best = np.linalg.norm(dg.knee_on_best_swivel(turned, world, lengths, gt) - gt[:, knees], axis=-1)
    assert raw.min() > 0.05 and best.max() < 1e-6        # a wrong swivel alone: all of it recovered
    bent = turned.copy()                                   # and the knee bent 20 degrees more, the
    R = rot.axis_angle_to_matrix(np.array([np.radians(20.0), 0.0, 0.0]))   # ankle with it: a wrong
    for s in ("left", "right"):                            # ankle the swivel cannot undo
        k, a = bent[:, J[f"{s}_knee"]], bent[:, J[f"{s}_ankle"]]
        bent[:, J[f"{s}_ankle"]] = k + (a - k) @ R.T
    left = np.linalg.norm(dg.knee_on_best_swivel(bent, world, lengths, gt) - gt[:, knees], axis=-1)
    assert (left > 0.005).all() and (left < np.linalg.norm(bent[:, knees] - gt[:, knees], axis=-1)).all()


def test_signed_errors_are_in_the_performers_heading_frame():
    gt = _bent_pose()[0]
    facing = -np.array([0.0, 1.0, 0.0])                    # the rest body faces -Y
    side = gt[0, J["right_hip"]] - gt[0, J["left_hip"]]
    pred = gt.copy()
    pred[:, J["pelvis"]] += 0.05 * facing + [0.0, 0.0, -0.02]
    pred[:, J["left_ankle"]] += 0.04 * side / np.linalg.norm(side)
    e = dg.signed_errors(pred, gt)
    k = list(dg.BIAS_JOINTS)
    assert np.allclose(e[:, k.index("pelvis")], [0.0, 0.05, -0.02])
    assert np.allclose(e[:, k.index("left_ankle")], [0.04, 0.0, 0.0])
    assert np.allclose(e[:, k.index("right_knee")], 0.0)


def test_expected_lean_on_a_circle_and_its_fit():
    fps, T = 30.0, 300
    t = np.arange(T) / fps
    r, w, H = 2.0, 1.5, 1.6                                # 3 m/s on a 2 m circle
    head = np.stack([r * np.cos(w * t), r * np.sin(w * t), np.full(T, H)], -1)
    lean = dg.expected_lean(head, fps)[30:-30]             # away from the smoothing's ends
    outward = head[30:-30, :2] / r
    # a / g times the head's height, less what the path's smoothing takes off a circle
    expect = (w * w * r) * H / dg.GRAVITY * np.exp(-0.5 * (w * dg.LEAN_SMOOTH_S) ** 2)
    assert np.allclose(np.sum(lean * outward, -1), expect, rtol=0.03)
    rng = np.random.default_rng(0)
    err = 0.3 * lean + rng.normal(scale=0.002, size=lean.shape)
    k, corr = dg.lean_fit(lean, err)
    assert abs(k - 0.3) < 0.01 and corr > 0.99
    assert dg.lean_fit(np.zeros((5, 2)), err[:5]) == (0.0, 0.0)
