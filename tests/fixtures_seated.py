"""A seated performance made by FK (tests/test_seated.py): a 1.75 m body on a chair at knee
height, looking around and reaching forward, recorded as OpenXR view and grip poses."""
from __future__ import annotations

import numpy as np

from blender_manikin.core.device_offsets import get_preset, remove_offsets
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.rotations import axis_angle_rotation, matrix_to_quat
from blender_manikin.core.skeleton import NUM_JOINTS, J, forward_kinematics

X, Y, Z = np.eye(3)


def _r(axis, deg):
    deg = np.asarray(deg, np.float64)
    return axis_angle_rotation(np.broadcast_to(axis, deg.shape + (3,)), np.radians(deg))


def seated_motion(body, t, heading=20.0, stand_first=False):
    """``(local (T, 22, 3, 3), root (T, 3))``: hips and knees at 90°, shins upright, feet flat on
    the floor; the head turning, the right hand reaching forward 3-5 s.  stand_first: a standing
    T-pose (the rest pose) for the first 1.5 s, then 1 s to sit down."""
    T = len(t)
    if stand_first:
        sit = np.clip((t - 1.5) / 1.0, 0.0, 1.0)
        sit = sit * sit * (3 - 2 * sit)
        local, root = seated_motion(body, t, heading)
        rest = np.tile(np.eye(3), (T, NUM_JOINTS, 1, 1))
        rest[:, J["pelvis"]] = local[:, J["pelvis"]]
        standing_root = np.tile(body.rest_positions()[J["pelvis"]], (T, 1))
        from blender_manikin.core.rotations import matrix_to_quat, quat_slerp, quat_to_matrix
        q = quat_slerp(matrix_to_quat(rest), matrix_to_quat(local), np.broadcast_to(sit[:, None], (T, NUM_JOINTS)))
        return quat_to_matrix(q), standing_root + sit[:, None] * (root - standing_root)
    local = np.tile(np.eye(3), (T, NUM_JOINTS, 1, 1))
    for side in ("left", "right"):
        local[:, J[f"{side}_hip"]] = _r(X, np.full(T, -90.0))
        local[:, J[f"{side}_knee"]] = _r(X, np.full(T, 90.0))
    local[:, J["pelvis"]] = _r(Z, np.full(T, heading))
    local[:, J["head"]] = _r(Z, 25.0 * np.sin(2 * np.pi * 0.2 * t)) @ _r(X, 8.0 * np.sin(2 * np.pi * 0.3 * t))
    local[:, J["left_shoulder"]] = _r(Y, np.full(T, 70.0))
    local[:, J["right_shoulder"]] = _r(Y, np.full(T, -70.0))
    reach = np.clip((t - 3.0) / 0.5, 0, 1) * np.clip((5.0 - t) / 0.5, 0, 1)
    local[:, J["right_shoulder"]] = _r(Z, 60.0 * reach) @ local[:, J["right_shoulder"]]
    local[:, J["left_elbow"]] = _r(Z, np.full(T, -40.0))
    local[:, J["right_elbow"]] = _r(Z, 40.0 * (1 - reach))
    rest = body.rest_positions()
    thigh = body.limb_lengths()[2, 0]
    # shins upright on the floor: the hips at knee height (thigh level), the feet where they stand
    root = np.tile(rest[J["pelvis"]], (T, 1))
    root[:, 2] -= rest[J["left_hip"], 2] - rest[J["left_knee"], 2]
    R = _r(Z, np.full(T, heading))
    root += (R @ np.array([0.0, thigh, 0.0]))          # the seat behind where the feet stood
    return local, root


def seated_recording(body, duration=8.0, fps=72.0, stand_first=False):
    """A :class:`Recording` of ``body`` seated (OpenXR view and grip poses, ``openxr_generic``)."""
    t = np.arange(int(duration * fps)) / fps
    local, root = seated_motion(body, t, stand_first=stand_first)
    pos, world = forward_kinematics(local, root, body)
    preset = get_preset("openxr_generic")["devices"]
    rng = np.random.default_rng(5)
    streams = {}
    for d, j in (("head", "head"), ("left_hand", "left_wrist"), ("right_hand", "right_wrist")):
        p, R = remove_offsets(pos[:, J[j]], world[:, J[j]], preset[d])
        p = p + rng.normal(0.0, 0.0005, p.shape)          # tracking noise: no sample repeats exactly
        streams[d] = TrackerStream(d, t, p, matrix_to_quat(R))
    return Recording(streams=streams, source="seated", metadata={"offsets": "openxr_generic"}), pos, world
