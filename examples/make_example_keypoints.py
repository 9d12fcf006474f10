"""Generate ``examples/example_keypoints/``: the example performance as a FreeMoCap recording.

The same synthetic performance as ``example_recording.csv`` (``make_example_recording.motion``:
T-pose, walking in place, a right-hand reach, a left-hand wave; the add-on's body model at
1.75 m), seen as a markerless capture would see it: MediaPipe's 33 body points
(:func:`blender_manikin.core.keypoint_layouts.keypoints_from_body22`) at 30 Hz, with 8 mm of
noise per coordinate and a few points lost (NaN, as MediaPipe drops a hand or foot), written
the way FreeMoCap writes them: ``output_data/mediapipe_body_3d_xyz.npy``, frames × 33 × 3,
millimetres, +Y up.  Run from anywhere::

    python examples/make_example_keypoints.py [output_folder]

and solve it with ``python -m blender_manikin solve examples/example_keypoints --out out``.
"""
from __future__ import annotations

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

from blender_manikin.core import keypoint_layouts as kl  # noqa: E402
from blender_manikin.core.skeleton import BodyMeasurements, forward_kinematics, make_body  # noqa: E402
from make_example_recording import DURATION, STATURE, motion  # noqa: E402

RATE = 30.0
NOISE = 0.008          # metres per coordinate
SEED = 7


def synthesize(rate=RATE, noise=NOISE, seed=SEED):
    """``(T, 33, 3)`` MediaPipe keypoints, metres, Blender axes (+Z up), NaN where lost."""
    body = make_body(BodyMeasurements(stature=STATURE))
    t = np.arange(int(DURATION * rate)) / rate
    local, root = motion(t, body)
    pos, rot = forward_kinematics(local, root, body)
    kp = kl.keypoints_from_body22(pos, rot, "mediapipe33", body.stature)
    rng = np.random.default_rng(seed)
    kp = kp + rng.normal(0.0, noise, kp.shape)
    lay = kl.LAYOUTS["mediapipe33"]
    for point, start in (("left_foot_index", 40), ("right_pinky", 95), ("left_wrist", 150)):
        kp[start:start + 6, lay.index(point)] = np.nan                  # a point lost for 0.2 s
    return kp


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    folder = argv[0] if argv else os.path.join(HERE, "example_keypoints")
    out = os.path.join(folder, "output_data")
    os.makedirs(out, exist_ok=True)
    kp = synthesize()
    y_up_mm = np.stack([kp[..., 0], kp[..., 2], -kp[..., 1]], -1) * 1000.0
    path = os.path.join(out, "mediapipe_body_3d_xyz.npy")
    np.save(path, y_up_mm.astype(np.float32))
    print(f"wrote {path} ({os.path.getsize(path) / 1024:.0f} KiB, {kp.shape[0]} frames)")


if __name__ == "__main__":
    main()
