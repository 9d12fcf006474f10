"""Six-tracker takes with squats and kicks, and foot trackers slipping on the body at a known time.

Generated at test time, nothing read from ../shared.  Built on :mod:`fixtures_six_trackers`
(T-pose to 1.2 s, then the take): ``"walk"`` walks in place (its motion as it is),
``"squat"`` squats 0-90° at the knees every 2 s, feet planted flat, ``"kick"`` walks in place
and kicks forward with the right leg (hip 80°, knee straight) every 1.6 s; what a body does that
looks like a slip: ``"platform"`` walks onto a 15 cm platform at 4.3 s (both planted ankles
higher), ``"stance"`` turns the right foot out 40° at 4.3 s and holds it.

A slip (:func:`slip_mounts`) changes a foot tracker's mount from time ``at`` on: slid ``slide``
metres up the shin (the ankle's +Z) and turned ``turn`` degrees round it.
"""
from __future__ import annotations

import numpy as np

from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.device_offsets import JOINT_OF_DEVICE, get_preset, remove_offsets, to_targets
from blender_manikin.core.rotations import axis_angle_rotation, axis_angle_to_matrix, matrix_to_quat
from blender_manikin.core.skeleton import J, forward_kinematics
from fixtures_six_trackers import DEVICES6, TPOSE_END, X, Z, _smooth, motion, true_offsets

KINDS = ("walk", "squat", "kick")
#: takes whose feet step like a slip but are the body's (:func:`take_motion`)
BODY_STEPS = ("platform", "stance")


def take_motion(t, body, kind="walk", heading=0.0):
    """Local rotations ``(N, 22, 3, 3)`` and root ``(N, 3)`` of a ``kind`` take."""
    local, root = motion(t, body, heading=heading)
    local = local.copy()
    root = root.copy()
    if kind == "platform":          # steps onto a 15 cm platform at 4.3 s and walks on there
        root[:, 2] += 0.15 * _smooth(4.2, 4.5, t)
        return local, root
    if kind == "stance":            # from 4.3 s the right foot turned out 40 degrees, held
        turn = axis_angle_rotation(Z, np.radians(-40.0) * _smooth(4.2, 4.5, t))
        local[:, J["right_hip"]] = turn @ local[:, J["right_hip"]]
        return local, root
    on = _smooth(TPOSE_END, TPOSE_END + 0.8, t)
    if kind == "squat":
        a = on * 45.0 * (1 - np.cos(2 * np.pi * 0.5 * (t - TPOSE_END)))     # 0-90 degrees
        for side in ("left", "right"):
            local[:, J[f"{side}_hip"]] = axis_angle_rotation(X, np.radians(-a))
            local[:, J[f"{side}_knee"]] = axis_angle_rotation(X, np.radians(2 * a))
            local[:, J[f"{side}_ankle"]] = axis_angle_rotation(X, np.radians(-a))
    elif kind == "kick":
        ph = ((t - TPOSE_END - 0.4) % 1.6) / 0.5
        k = on * np.where(ph < 1.0, np.sin(np.pi * np.clip(ph, 0, 1)) ** 2, 0.0)
        hip = axis_angle_rotation(X, np.radians(-80.0 * k))
        local[:, J["right_hip"]] = hip
        local[:, J["right_knee"]] = axis_angle_rotation(X, np.radians(20.0 * k))
        local[:, J["left_hip"]] = np.where(k[:, None, None] > 0, np.eye(3), local[:, J["left_hip"]])
        local[:, J["left_knee"]] = np.where(k[:, None, None] > 0, np.eye(3), local[:, J["left_knee"]])
        local[:, J["left_ankle"]] = np.where(k[:, None, None] > 0, np.eye(3), local[:, J["left_ankle"]])
    if kind != "walk":             # the lower ankle stands at its rest height, the feet stay put
        pos, _ = forward_kinematics(local, root, body)
        rest = body.rest_positions()
        ankles = [J["left_ankle"], J["right_ankle"]]
        low = np.minimum(pos[:, ankles[0], 2], pos[:, ankles[1], 2])
        root[:, 2] -= low - rest[ankles[0], 2]
        if kind == "squat":
            mid = pos[:, ankles].mean(1)[:, :2]
            root[:, :2] -= mid - mid[:1]
        else:                       # the standing (left) foot stays where it stands
            root[:, :2] -= pos[:, ankles[0], :2] - pos[:1, ankles[0], :2]
    return local, root


def slip_mounts(mounts, device, slide=0.0, turn=0.0):
    """``mounts`` with ``device``'s slid ``slide`` m up its ankle's +Z and turned ``turn``
    degrees round it (``device = joint · (c, M)``: ``c + s ẑ``, then ``Rz(θ)`` on both)."""
    c, M = mounts[device]
    Rz = axis_angle_rotation(Z, np.radians(turn))
    out = dict(mounts)
    out[device] = (Rz @ (c + slide * Z), Rz @ M)
    return out


def slip_devices(body, mounts, kind="walk", duration=8.0, fps=60.0, slip=None, seed=0,
                 noise_m=0.0015, noise_deg=0.5):
    """``(times, device_pos, device_quat, truth_pos (N, 22, 3), truth_rot (N, 22, 3, 3))`` on a
    ``fps`` grid: head and hands through the ``openxr_generic`` offsets, the extra trackers on
    ``mounts``.  slip: ``(device, at_s, slide_m, turn_deg)``: from ``at_s`` on that tracker sits on
    its slipped mount (:func:`slip_mounts`)."""
    t = np.arange(int(round(duration * fps))) / fps
    local, root = take_motion(t, body, kind)
    pos, rot = forward_kinematics(local, root, body)
    rng = np.random.default_rng(seed)
    preset = get_preset("openxr_generic")
    dev_pos, dev_quat = {}, {}
    after = slip_mounts(mounts, slip[0], slip[2], slip[3]) if slip else mounts
    for d in DEVICES6:
        j = J[JOINT_OF_DEVICE[d]]
        if d in mounts:
            c0, M0 = mounts[d]
            c1, M1 = after[d]
            late = (t >= slip[1])[:, None] if slip else np.zeros((len(t), 1), bool)
            c = np.where(late, c1, c0)
            M = np.where(late[:, :, None], M1, M0)
            p = pos[:, j] + np.einsum("nij,nj->ni", rot[:, j], c)
            R = rot[:, j] @ M
        else:
            p, R = remove_offsets(pos[:, j], rot[:, j], preset["devices"][d])
        p = p + rng.normal(0.0, noise_m, p.shape)
        R = R @ axis_angle_to_matrix(rng.normal(0.0, np.deg2rad(noise_deg) / np.sqrt(3), (len(t), 3)))
        dev_pos[d], dev_quat[d] = p, matrix_to_quat(R)
    return t, dev_pos, dev_quat, pos, rot


def slip_take(body, mounts, kind="walk", duration=8.0, fps=60.0, slip=None, seed=0, measured_after=False, **kw):
    """``(targets, truth_pos (N, 22, 3), truth_rot (N, 22, 3, 3), times)``: :func:`slip_devices`'
    targets made with the offsets a calibration measures: the mounts before the slip, or with
    ``measured_after`` the slipped one (calibrated on a T-pose after it)."""
    t, dev_pos, dev_quat, pos, rot = slip_devices(body, mounts, kind, duration, fps, slip, seed, **kw)
    after = slip_mounts(mounts, slip[0], slip[2], slip[3]) if slip else mounts
    offsets = get_preset("openxr_generic")
    offsets["devices"].update(true_offsets(after if measured_after else mounts))
    valid = {d: np.ones(len(t), bool) for d in DEVICES6}
    return to_targets(t, dev_pos, dev_quat, valid, offsets, fps=fps), pos, rot, t


def slip_recording(body, mounts, kind="walk", duration=8.0, fps=60.0, slip=None, seed=0, **kw):
    """``(Recording, truth_pos, truth_rot, times)``: :func:`slip_devices` as a recording of raw
    device poses (the solve calibrates the extra trackers on the T-pose at the start)."""
    t, dev_pos, dev_quat, pos, rot = slip_devices(body, mounts, kind, duration, fps, slip, seed, **kw)
    rec = Recording(streams={d: TrackerStream(d, t.copy(), dev_pos[d], dev_quat[d]) for d in DEVICES6},
                    source="synthetic six-tracker take", metadata={"offsets": "openxr_generic"})
    return rec, pos, rot, t
