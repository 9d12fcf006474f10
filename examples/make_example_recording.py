"""Generate ``examples/example_recording.csv``: a short synthetic VR recording.

The motion is made by moving the add-on's own body model
(:func:`blender_manikin.core.skeleton.make_body`, 1.75 m, and
:func:`~blender_manikin.core.skeleton.forward_kinematics`) with smooth joint
rotations, and the devices are recorded through the inverse of the
``openxr_generic`` device offsets, so the recording is consistent with a
real body: an OpenXR view pose for the HMD and OpenXR grip poses for the
controllers.

Timeline (seconds):

* 0.0-1.0  T-pose, standing still (the calibration moment);
* 1.0-1.6  arms come down to the sides, walking in place starts (the stance
           leg bends so the head bobs ~2 cm with the foot planted, slight
           sway) and goes on to the end;
* 2.3-4.1  the right hand reaches forward and up, then comes back;
* 4.3-6.9  the left hand waves above the shoulder;
* the head looks around slowly throughout the motion part.

Devices: head at 90 Hz, hands at 72 Hz, with timestamp jitter (σ 0.6 ms) and
0.2 mm position noise; OpenXR axes, metres.  Run from anywhere::

    python examples/make_example_recording.py [output.csv]
"""
from __future__ import annotations

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from blender_manikin.core.device_offsets import get_preset, remove_offsets  # noqa: E402
from blender_manikin.core.recording import Recording, TrackerStream  # noqa: E402
from blender_manikin.core.io_csv import write_csv  # noqa: E402
from blender_manikin.core.rotations import axis_angle_to_quat, quat_mul, quat_slerp, quat_to_matrix, matrix_to_quat  # noqa: E402
from blender_manikin.core.skeleton import NUM_JOINTS, BodyMeasurements, J, forward_kinematics, make_body  # noqa: E402

STATURE = 1.75
DURATION = 7.0
RATES = {"head": 90.0, "left_hand": 72.0, "right_hand": 72.0}
JOINT = {"head": "head", "left_hand": "left_wrist", "right_hand": "right_wrist"}
SEED = 7

X, Y, Z = np.eye(3)


def smoothstep(a, b, t):
    x = np.clip((np.asarray(t, dtype=np.float64) - a) / (b - a), 0.0, 1.0)
    return x * x * (3 - 2 * x)


def bump(a, b, ramp, t):
    """0 before a, smooth ramp up over ``ramp`` s, 1, ramp down to 0 at b."""
    return smoothstep(a, a + ramp, t) * (1.0 - smoothstep(b - ramp, b, t))


def q_aa(axis, deg):
    """Quaternion(s) for rotations of ``deg`` (array) degrees about a fixed ``axis``."""
    deg = np.asarray(deg, dtype=np.float64)
    return axis_angle_to_quat(np.asarray(axis, dtype=np.float64) * np.deg2rad(deg)[..., None])


def qmul(*qs):
    out = qs[0]
    for q in qs[1:]:
        out = quat_mul(out, q)
    return out


def motion(t, body):
    """Local joint rotations ``(N, 22, 3, 3)`` and pelvis positions ``(N, 3)`` at times ``t`` (s)."""
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    q = np.zeros((n, NUM_JOINTS, 4))
    q[..., 0] = 1.0
    move = smoothstep(1.0, 1.6, t)            # 0 in the T-pose, 1 once moving
    walk = smoothstep(1.0, 1.8, t)
    reach = bump(2.3, 4.1, 0.6, t)
    wave = bump(4.3, 6.9, 0.5, t)

    # walking in place: 0.9 strides/s per leg, alternating
    ph = 2 * np.pi * 0.9 * (t - 1.0)
    lift_l = walk * np.maximum(0.0, np.sin(ph))
    lift_r = walk * np.maximum(0.0, -np.sin(ph))
    # the stance leg bends a little (hip -a, knee +2a, ankle -a keeps the foot flat) so the
    # pelvis bobs with the foot planted; the pelvis height is solved below
    flex_l = 14.0 * lift_r ** 2
    flex_r = 14.0 * lift_l ** 2
    for side, lift, flex in (("left", lift_l, flex_l), ("right", lift_r, flex_r)):
        q[:, J[f"{side}_hip"]] = q_aa(X, -35.0 * lift - flex)
        q[:, J[f"{side}_knee"]] = q_aa(X, 60.0 * lift + 2 * flex)
        q[:, J[f"{side}_ankle"]] = q_aa(X, -15.0 * lift - flex)

    # pelvis: sway over the stance leg, small yaw, forward lean when reaching
    q[:, J["pelvis"]] = qmul(q_aa(Z, 4.0 * walk * np.sin(ph)), q_aa(Y, 2.0 * walk * np.sin(ph)))
    q[:, J["spine1"]] = q_aa(X, -4.0 * reach)
    q[:, J["spine2"]] = qmul(q_aa(X, -3.0 * reach), q_aa(Y, -2.0 * walk * np.sin(ph)))
    q[:, J["spine3"]] = q_aa(Z, 6.0 * reach)
    # head: slow look-around, looks at the right hand while reaching, nods a little
    yaw = move * (20.0 * np.sin(2 * np.pi * 0.15 * (t - 1.0))) * (1 - reach) - 25.0 * reach
    pitch = move * 4.0 * np.sin(2 * np.pi * 0.4 * t) + 8.0 * reach
    q[:, J["neck"]] = q_aa(Z, 0.4 * yaw)
    q[:, J["head"]] = qmul(q_aa(Z, 0.6 * yaw), q_aa(X, pitch))

    # arms: T-pose -> relaxed at the sides (70 deg down), natural swing while walking
    relaxed_l = qmul(q_aa(Y, 70.0 * move), q_aa(Z, 8.0 * walk * np.sin(ph + np.pi)))
    relaxed_r = qmul(q_aa(Y, -70.0 * move), q_aa(Z, -8.0 * walk * np.sin(ph)))
    # right reach: arm forward and 25 deg up, elbow straightening, palm turning inward
    reach_r = qmul(q_aa(Z, np.full(n, 90.0)), q_aa(Y, np.full(n, 25.0)))
    q[:, J["right_shoulder"]] = quat_slerp(relaxed_r, reach_r, reach)
    q[:, J["right_elbow"]] = q_aa(Z, 15.0 * move * (1 - reach) + 5.0 * reach)
    q[:, J["right_wrist"]] = qmul(q_aa(X, -60.0 * reach), q_aa(Y, -10.0 * move))
    # left wave: upper arm 35 deg above horizontal, forearm up, swinging +-25 deg at 1.8 Hz
    wave_sh = q_aa(Y, np.full(n, -35.0))
    q[:, J["left_shoulder"]] = quat_slerp(relaxed_l, wave_sh, wave)
    swing = 25.0 * np.sin(2 * np.pi * 1.8 * (t - 4.3))
    q[:, J["left_elbow"]] = qmul(q_aa(Z, -15.0 * move * (1 - wave)), q_aa(Y, wave * (-95.0 + swing)))
    q[:, J["left_wrist"]] = qmul(q_aa(X, 70.0 * wave), q_aa(Y, 10.0 * move * (1 - wave)))

    local = quat_to_matrix(q)
    root = np.repeat(body.root_rest[None], n, axis=0)
    root[:, 0] += 0.015 * walk * np.sin(ph)                        # lateral sway over the stance leg
    root[:, 1] -= 0.02 * reach                                      # lean into the reach
    # pelvis height: the lower ankle stays at its standing height (stance foot planted)
    pos, _ = forward_kinematics(local, root, body)
    ankle_rest = body.rest_positions()[J["left_ankle"], 2]
    root[:, 2] -= np.minimum(pos[:, J["left_ankle"], 2], pos[:, J["right_ankle"], 2]) - ankle_rest
    return local, root


def jittered_times(rate, duration, rng, start):
    n = int(np.floor(duration * rate))
    t = start + np.arange(n) / rate + rng.normal(0.0, 0.0006, n)
    t = np.maximum.accumulate(t)
    t[1:] = np.maximum(t[1:], t[:-1] + 0.25 / rate)          # strictly increasing
    return t


def synthesize(duration=DURATION, stature=STATURE, seed=SEED, offsets="openxr_generic"):
    """Device streams (Blender axes, metres) of the synthetic performance."""
    body = make_body(BodyMeasurements(stature=stature))
    rng = np.random.default_rng(seed)
    preset = get_preset(offsets)["devices"]
    streams = {}
    for k, (dev, rate) in enumerate(RATES.items()):
        t = jittered_times(rate, duration, rng, start=0.0037 * k)
        local, root = motion(t, body)
        pos, rot = forward_kinematics(local, root, body)
        j = J[JOINT[dev]]
        dpos, drot = remove_offsets(pos[:, j], rot[:, j], preset[dev])
        dpos = dpos + rng.normal(0.0, 0.0002, dpos.shape)
        quat = matrix_to_quat(drot)
        streams[dev] = TrackerStream(dev, t, dpos, quat)
    return Recording(streams=streams, source="synthetic",
                     metadata={"source": f"synthetic performance by examples/make_example_recording.py "
                                         f"(body model {stature:.2f} m, {offsets} device offsets, seed {seed})"})


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    out = argv[0] if argv else os.path.join(HERE, "example_recording.csv")
    rec = synthesize()
    write_csv(out, rec, axes="openxr", units="m",
              metadata={"description": "T-pose 0-1 s, then walking in place, right-hand reach 2.3-4.1 s, "
                                       "left-hand wave 4.3-6.9 s",
                        "devices": "head 90 Hz, hands 72 Hz (OpenXR view and grip poses)",
                        "offsets": "openxr_generic"})
    print(f"wrote {out} ({os.path.getsize(out) / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
