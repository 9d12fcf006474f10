"""Baselines the benchmark compares MANIKIN with.  No bpy, no torch.

* :func:`classic_ik` — what a rig with Blender IK constraints gives: the
  body stands upright under the head (heading from the head, straight
  spine), arms are two-bone IK to the hand targets with a fixed pole
  (swivel 0, elbows out-back-down), legs straight down and planted on the
  floor under the hips.
* :func:`network_only` — the AvatarPoser approach: the same backbone trained
  to predict all 22 rotations (model kind ``"fk"``), posed by FK from the
  head target (hands are wherever FK puts them).
"""
from __future__ import annotations

import numpy as np

from . import features
from . import limb_solver as ls
from .pipeline import run_network
from .pose_result import PoseResult, TrackerTargets
from .skeleton import Body, J, NUM_JOINTS, forward_kinematics


def classic_ik(targets: TrackerTargets, body: Body) -> PoseResult:
    T = targets.num_frames
    head_pos, head_rot = targets.pos["head"], targets.rot["head"]
    yaw = features.rot_z(features.heading_yaw(head_rot))                  # (T, 3, 3)
    local = np.broadcast_to(np.eye(3), (T, NUM_JOINTS, 3, 3)).copy()
    local[:, 0] = yaw
    rest = body.rest_positions()
    head_rel = rest[J["head"]] - rest[J["pelvis"]]
    root_pos = head_pos - np.einsum("tij,j->ti", yaw, head_rel)
    # the head joint follows the tracker orientation through the neck
    local[:, J["head"]] = np.swapaxes(yaw, -1, -2) @ head_rot
    pos, world = forward_kinematics(local, root_pos, body)
    base = pos[:, ls.LIMB_BASE]
    par = world[:, ls.LIMB_PARENT]
    ankle_h = rest[[J["left_ankle"], J["right_ankle"]], 2]
    ankles = base[:, 2:].copy()
    ankles[..., 2] = ankle_h[None]
    ends = np.concatenate([np.stack([targets.pos["left_hand"], targets.pos["right_hand"]], 1), ankles], 1)
    end_rot = np.concatenate([np.stack([targets.rot["left_hand"], targets.rot["right_hand"]], 1),
                              np.stack([yaw, yaw], 1)], 1)
    sol = ls.solve_limbs(base, ends, np.zeros((T, 4)), body.limb_lengths(), par, end_rot=end_rot)
    local[:, ls.LIMB_BASE] = sol.base_local
    local[:, ls.LIMB_MID] = sol.mid_local
    local[:, ls.LIMB_END] = sol.end_local
    return PoseResult(fps=float(targets.fps), body=body, local_rot=local, root_pos=root_pos,
                      swivel=np.zeros((T, 4)), reach_error=sol.reach_error, targets=targets)


def network_only(targets: TrackerTargets, body: Body, fk_runner) -> PoseResult:
    if fk_runner.contract.kind != "fk":
        raise ValueError(f"{fk_runner.path}: network_only needs a kind 'fk' model")
    net = run_network(targets, body, fk_runner)
    T = targets.num_frames
    local = np.empty((T, NUM_JOINTS, 3, 3))
    local[:, 0] = net.root_rot
    local[:, 1:] = net.local_rot
    pos0, _ = forward_kinematics(local, np.zeros((T, 3)), body)
    root_pos = targets.pos["head"] - pos0[:, J["head"]]
    return PoseResult(fps=float(targets.fps), body=body, local_rot=local, root_pos=root_pos,
                      swivel=np.zeros((T, 4)), contacts=net.contact > 0.5, targets=targets)
