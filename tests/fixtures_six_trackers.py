"""Six-tracker performances (headset, two controllers, pelvis and foot trackers) from the body model.

Generated at test time, nothing read from ../shared.  A body (:func:`make_body`, legs optionally
not proportional) stands in a T-pose, then lowers the arms and walks in place (after
``examples/make_example_recording.py``), turned by ``heading`` degrees and moved by ``shift``.
The headset and controllers are recorded through the ``openxr_generic`` offsets; the pelvis
and foot trackers are strapped on at random rotations (upside down, turned about the foot) and
5-15 cm from their joints (:func:`random_mounts`), which the calibration has to measure.

Mount convention: a tracker at ``c`` (metres) with orientation ``M`` in its joint's frame, i.e.
``device_pos = joint_pos + joint_rot @ c`` and ``device_rot = joint_rot @ M``; its true offset
(:mod:`blender_manikin.core.device_offsets`: ``joint_rot = device_rot @ offset_rot``,
``joint_pos = device_pos + device_rot @ offset_pos``) is ``offset_rot = Mᵀ``,
``offset_pos = -Mᵀ c``.
"""
from __future__ import annotations

import numpy as np

from blender_manikin.core.device_offsets import JOINT_OF_DEVICE, get_preset, remove_offsets, to_targets
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.rotations import (
    axis_angle_rotation, axis_angle_to_matrix, axis_angle_to_quat, matrix_to_quat, quat_mul, quat_slerp,
    quat_to_matrix,
)
from blender_manikin.core.skeleton import NUM_JOINTS, PROPORTIONS, BodyMeasurements, J, forward_kinematics, make_body

DEVICES6 = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")
EXTRA = ("pelvis", "left_foot", "right_foot")
RATES = {"head": 90.0, "left_hand": 72.0, "right_hand": 72.0, "pelvis": 120.0, "left_foot": 120.0,
         "right_foot": 120.0}
TPOSE_END = 1.2          # seconds of still T-pose at the start
X, Y, Z = np.eye(3)


def body_with_legs(stature, leg_factor=1.0):
    """A body of ``stature`` (m) whose thigh and shank are ``leg_factor`` times the proportional."""
    return make_body(BodyMeasurements(stature=stature, thigh=PROPORTIONS["thigh"] * stature * leg_factor,
                                      shank=PROPORTIONS["shank"] * stature * leg_factor))


def _smooth(a, b, t):
    x = np.clip((np.asarray(t, dtype=np.float64) - a) / (b - a), 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _q(axis, deg):
    deg = np.asarray(deg, dtype=np.float64)
    return axis_angle_to_quat(np.asarray(axis, dtype=np.float64) * np.deg2rad(deg)[..., None])


def _mul(*qs):
    out = qs[0]
    for q in qs[1:]:
        out = quat_mul(out, q)
    return out


def motion(t, body, heading=0.0, shift=(0.0, 0.0), lift_left_foot=False, stance=0.0):
    """Local rotations ``(N, 22, 3, 3)`` and pelvis positions ``(N, 3)`` (m) at times ``t`` (s).

    0 - TPOSE_END s: still T-pose (the rest pose, both feet flat under the hips; with
    ``lift_left_foot`` the left foot is held up behind, knee bent, until 1.6 s; with ``stance``
    metres each ankle stands that much further out than under the hip, feet flat, until 1.6 s);
    then the arms come
    down and the performer walks in place (stance ankle at its rest height, pelvis sway and yaw),
    looking around.  The whole body is turned by ``heading`` degrees about +Z and moved by
    ``shift`` (x, y metres)."""
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    q = np.zeros((n, NUM_JOINTS, 4))
    q[..., 0] = 1.0
    t1 = TPOSE_END
    move = _smooth(t1, t1 + 0.6, t)
    walk = _smooth(t1, t1 + 0.8, t)
    ph = 2 * np.pi * 0.9 * (t - t1)
    lift_l = walk * np.maximum(0.0, np.sin(ph))
    lift_r = walk * np.maximum(0.0, -np.sin(ph))
    flex_l, flex_r = 14.0 * lift_r ** 2, 14.0 * lift_l ** 2
    for side, lift, flex in (("left", lift_l, flex_l), ("right", lift_r, flex_r)):
        q[:, J[f"{side}_hip"]] = _q(X, -35.0 * lift - flex)
        q[:, J[f"{side}_knee"]] = _q(X, 60.0 * lift + 2 * flex)
        q[:, J[f"{side}_ankle"]] = _q(X, -15.0 * lift - flex)
    if lift_left_foot:                       # the left foot held up behind during the T-pose
        up = 1.0 - _smooth(1.4, 1.6, t)
        q[:, J["left_hip"]] = _mul(q[:, J["left_hip"]], _q(X, -10.0 * up))
        q[:, J["left_knee"]] = _mul(q[:, J["left_knee"]], _q(X, 55.0 * up))
        q[:, J["left_ankle"]] = _mul(q[:, J["left_ankle"]], _q(X, -20.0 * up))
    if stance:                               # legs spread sideways, feet kept flat
        phi = np.degrees(np.arcsin(stance / body.limb_lengths()[2].sum())) * (1.0 - _smooth(1.4, 1.6, t))
        for side, sgn in (("left", -1.0), ("right", 1.0)):
            q[:, J[f"{side}_hip"]] = _mul(_q(Y, sgn * phi), q[:, J[f"{side}_hip"]])
            q[:, J[f"{side}_ankle"]] = _mul(q[:, J[f"{side}_ankle"]], _q(Y, -sgn * phi))
    q[:, J["pelvis"]] = _mul(_q(Z, heading + 5.0 * walk * np.sin(ph)), _q(Y, 3.0 * walk * np.sin(ph)))
    q[:, J["spine2"]] = _q(Y, -2.0 * walk * np.sin(ph))
    yaw = move * 20.0 * np.sin(2 * np.pi * 0.15 * (t - t1))
    q[:, J["neck"]] = _q(Z, 0.4 * yaw)
    q[:, J["head"]] = _mul(_q(Z, 0.6 * yaw), _q(X, move * 4.0 * np.sin(2 * np.pi * 0.4 * t)))
    q[:, J["left_shoulder"]] = _mul(_q(Y, 70.0 * move), _q(Z, 8.0 * walk * np.sin(ph + np.pi)))
    q[:, J["right_shoulder"]] = _mul(_q(Y, -70.0 * move), _q(Z, -8.0 * walk * np.sin(ph)))
    q[:, J["left_elbow"]] = _q(Z, -15.0 * move)
    q[:, J["right_elbow"]] = _q(Z, 15.0 * move)
    # a reach forward with the right hand 3-4.5 s
    reach = _smooth(3.0, 3.5, t) * (1 - _smooth(4.0, 4.5, t))
    q[:, J["right_shoulder"]] = quat_slerp(q[:, J["right_shoulder"]],
                                           np.broadcast_to(_mul(_q(Z, 80.0), _q(Y, 20.0)), (n, 4)), reach)
    local = quat_to_matrix(q)
    R = axis_angle_rotation(Z, np.deg2rad(heading))
    root = np.repeat(body.root_rest[None], n, axis=0)
    root[:, 0] += 0.015 * walk * np.sin(ph)
    root[:, :2] = root[:, :2] @ R[:2, :2].T + np.asarray(shift, dtype=np.float64)
    pos, _ = forward_kinematics(local, root, body)
    # the stance (lower) ankle stays at its rest height: pelvis height from the legs
    ankle_rest = body.rest_positions()[J["left_ankle"], 2]
    low = np.minimum(pos[:, J["left_ankle"], 2], pos[:, J["right_ankle"], 2])
    if lift_left_foot:
        low = np.where(t < 1.6, pos[:, J["right_ankle"], 2], low)
    root[:, 2] -= low - ankle_rest
    return local, root


def random_mounts(seed, pelvis_height=0.0):
    """True mounts of the extra trackers, device → ``(c (3,), M (3, 3))`` in the joint's frame.

    pelvis: 5-15 cm from the joint in a random *horizontal* direction of the pelvis frame, plus
    ``pelvis_height`` metres straight up (0: level with the joint, the calibration's stated
    assumption), upside down and turned at random about the vertical.  feet: 5-15 cm in a random
    direction (up to 6 cm to the side, 12 cm behind to 10 cm ahead, 0-8 cm above the ankle),
    turned 90° about the foot's long axis (left) or upside down (right), then a random
    rotation of up to 40° about a random axis."""
    rng = np.random.default_rng(seed)
    out = {}
    ang = rng.uniform(0, 2 * np.pi)
    c = rng.uniform(0.05, 0.15) * np.array([np.cos(ang), np.sin(ang), 0.0]) + [0, 0, pelvis_height]
    M = axis_angle_rotation(Y, np.pi) @ axis_angle_rotation(Z, rng.uniform(-np.pi, np.pi))
    out["pelvis"] = (c, M)
    for d, base in (("left_foot", axis_angle_rotation(Y, np.pi / 2)), ("right_foot", axis_angle_rotation(X, np.pi))):
        while True:
            c = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.12, 0.10), rng.uniform(0.0, 0.08)])
            if 0.05 <= np.linalg.norm(c) <= 0.15:
                break
        axis = rng.normal(size=3)
        out[d] = (c, base @ axis_angle_rotation(axis / np.linalg.norm(axis), np.deg2rad(rng.uniform(0, 40))))
    return out


def true_offsets(mounts):
    """The device-offset entries ``{device: {"pos", "rot"}}`` of ``mounts`` (see module docstring)."""
    return {d: {"pos": [float(v) for v in -M.T @ c], "rot": [float(v) for v in matrix_to_quat(M.T)]}
            for d, (c, M) in mounts.items()}


def device_poses(t, body, mounts, heading=0.0, shift=(0.0, 0.0), lift_left_foot=False, stance=0.0,
                 noise_m=0.0015, noise_deg=0.5, seed=0, devices=DEVICES6, preset="openxr_generic"):
    """Device poses at times ``t`` (s): ``{device: (pos (N, 3) m, quat (N, 4) wxyz)}`` in Blender axes.

    Head and hands through the ``preset`` offsets, extra trackers through ``mounts``;
    Gaussian noise of ``noise_m`` metres per axis on positions and a random rotation of about
    ``noise_deg`` degrees on orientations, per sample."""
    rng = np.random.default_rng(seed)
    local, root = motion(t, body, heading, shift, lift_left_foot, stance)
    pos, rot = forward_kinematics(local, root, body)
    preset = get_preset(preset)["devices"]
    out = {}
    for d in devices:
        j = J[JOINT_OF_DEVICE[d]]
        if d in mounts:
            c, M = mounts[d]
            p = pos[:, j] + rot[:, j] @ c
            R = rot[:, j] @ M
        else:
            p, R = remove_offsets(pos[:, j], rot[:, j], preset[d])
        n = p.shape[0]
        p = p + rng.normal(0.0, noise_m, (n, 3))
        R = R @ axis_angle_to_matrix(rng.normal(0.0, np.deg2rad(noise_deg) / np.sqrt(3), (n, 3)))
        out[d] = (p, matrix_to_quat(R))
    return out


def six_tracker_targets(body, mounts, duration=6.0, fps=60.0, offsets="openxr_generic", invalid=None, **kw):
    """:class:`TrackerTargets` on a ``fps`` grid made with ``offsets`` (the presets have no offsets
    for the extra trackers: their raw poses are the targets).  invalid: ``(device, t0, t1)``
    marks the device untracked in that interval.  Returns ``(targets, times)``."""
    times = np.arange(int(round(duration * fps))) / fps
    poses = device_poses(times, body, mounts, **kw)
    pos = {d: p for d, (p, _) in poses.items()}
    quat = {d: q for d, (_, q) in poses.items()}
    valid = {d: np.ones(len(times), dtype=bool) for d in poses}
    if invalid:
        d, a, b = invalid
        valid[d] &= ~((times >= a) & (times < b))
    return to_targets(times, pos, quat, valid, offsets, fps=fps), times


def six_tracker_recording(body, mounts, duration=6.0, seed=0, **kw) -> Recording:
    """A :class:`Recording` with each device at its own rate (:data:`RATES`, jittered timestamps)."""
    rng = np.random.default_rng(seed + 1000)
    streams = {}
    for k, (d, rate) in enumerate(RATES.items()):
        n = int(np.floor(duration * rate))
        t = 0.002 * k + np.arange(n) / rate + rng.uniform(-0.1, 0.1, n) / rate
        p, q = device_poses(t, body, mounts, seed=seed + k, devices=(d,), **kw)[d]
        streams[d] = TrackerStream(d, t, p, q)
    return Recording(streams=streams, source="synthetic six-tracker performance",
                     metadata={"source": "tests/fixtures_six_trackers.py", "offsets": "openxr_generic"})


def joint_truth(t, body, heading=0.0, shift=(0.0, 0.0), lift_left_foot=False, stance=0.0):
    """World joint positions ``(N, 22, 3)`` and rotations ``(N, 22, 3, 3)`` at times ``t``."""
    local, root = motion(t, body, heading, shift, lift_left_foot, stance)
    return forward_kinematics(local, root, body)
