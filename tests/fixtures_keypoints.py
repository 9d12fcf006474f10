"""Keypoint inputs made from a moving body (numpy only): FreeMoCap folders, layout arrays, CSV.

The motion is the body model's (``fixtures_bvh.synthetic_motion``: smooth random rotations of
every joint, a slow turn and a walk), with elbows and knees replaced by hinges within their
limits, so a perfect solver could reproduce it.  Files are written the way markerless tools
write them: +Y up, millimetres (FreeMoCap) or metres.
"""
import os

import numpy as np

from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import limb_solver as ls
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from fixtures_bvh import synthetic_motion


def hinge_motion(frames=240, fps=30.0, seed=0, stature=1.72):
    """``(body, positions (T, 22, 3), world_rot (T, 22, 3, 3))``: standing motion on the floor
    (metres, Blender axes) with hinge elbows and knees flexing between 0.2 rad and most of
    their range."""
    body, local, root, _, _ = synthetic_motion(sk.make_body(stature), frames=frames, fps=fps, seed=seed,
                                               amplitude=0.35, lift=0.0, standing=frames)
    t = np.arange(frames) / fps
    rng = np.random.default_rng(seed + 100)
    for li, (_, b, m, e) in enumerate(sk.LIMBS):
        th = 0.2 + 0.25 * (1.0 + np.sin(2 * np.pi * rng.uniform(0.3, 1.0) * t + rng.uniform(0, 6))) \
            * (ls.FLEX_MAX[li] - 0.3)
        local[:, m] = rot.axis_angle_rotation(ls.H0[li], th)
    pos, world = sk.forward_kinematics(local, root, body)
    return body, pos, world


def to_y_up(points, scale=1.0):
    """Blender axes (+Z up) → a +Y-up right-handed file frame, times ``scale`` (1000: mm)."""
    p = np.asarray(points, np.float64)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], -1) * scale


def noisy(points, sigma, seed=0, drop=0.0):
    """``points`` plus Gaussian noise (``sigma`` metres per coordinate) with a fraction ``drop``
    of points lost (NaN): single points and runs of 5 frames."""
    rng = np.random.default_rng(seed)
    x = np.asarray(points, np.float64) + rng.normal(size=np.shape(points)) * sigma
    if drop:
        T, K = x.shape[:2]
        lost = rng.random((T, K)) < drop / 2
        for _ in range(int(drop * T * K / 10) + 1):
            k, f = rng.integers(K), rng.integers(0, T - 5)
            lost[f:f + 5, k] = True
        x[lost] = np.nan
    return x


def write_freemocap(folder, body, pos, world, sigma=0.0, seed=0, drop=0.0, hands=True):
    """A FreeMoCap recording folder: ``output_data/mediapipe_body_3d_xyz.npy`` (T × 33 × 3, mm,
    +Y up, NaN = lost) and the two hands' 21 points.  Returns ``(folder, clean keypoints in
    Blender axes, metres)``."""
    clean = kl.keypoints_from_body22(pos, world, "mediapipe33", body.stature)
    out = os.path.join(folder, "output_data")
    os.makedirs(out, exist_ok=True)
    np.save(os.path.join(out, "mediapipe_body_3d_xyz.npy"), to_y_up(noisy(clean, sigma, seed, drop), 1000.0))
    if hands:
        for side in ("left", "right"):
            h = np.full((pos.shape[0], 21, 3), np.nan)
            lay = kl.LAYOUTS["mediapipe33"]
            h[:, 0] = clean[:, lay.index(f"{side}_wrist")]
            h[:, 5] = clean[:, lay.index(f"{side}_index")]
            h[:, 17] = clean[:, lay.index(f"{side}_pinky")]
            np.save(os.path.join(out, f"mediapipe_{side}_hand_3d_xyz.npy"), to_y_up(noisy(h, sigma, seed + 1), 1000.0))
    return folder, clean


def write_layout_npy(path, layout, body, pos, world, sigma=0.0, seed=0, drop=0.0, scale=1.0):
    """``(T, K, 3)`` keypoints of ``layout`` in a +Y-up file (``scale`` 1: metres); returns the
    clean keypoints (Blender axes, metres)."""
    clean = kl.keypoints_from_body22(pos, world, layout, body.stature)
    np.save(path, to_y_up(noisy(clean, sigma, seed, drop), scale))
    return clean


def write_layout_csv(path, layout, body, pos, world, fps=30.0, sigma=0.0, seed=0, drop=0.0, names=None):
    """A keypoint CSV: ``time`` and ``<point>_x/_y/_z`` (metres, +Y up, empty cells where lost);
    ``names``: point → column prefix (for mapping files).  Returns the clean keypoints."""
    clean = kl.keypoints_from_body22(pos, world, layout, body.stature)
    x = to_y_up(noisy(clean, sigma, seed, drop))
    pts = kl.LAYOUTS[layout].points
    cols = ["time"] + [f"{(names or {}).get(p, p)}_{a}" for p in pts for a in "xyz"]
    with open(path, "w", encoding="utf-8") as f:
        f.write(",".join(cols) + "\n")
        for t in range(x.shape[0]):
            cells = [f"{t / fps:.6f}"] + ["" if not np.isfinite(v) else f"{v:.6f}" for v in x[t].ravel()]
            f.write(",".join(cells) + "\n")
    return clean


def set_csv_cells(path, cells):
    """Rewrite the CSV ``path`` with ``cells`` ``{(line index, column index): text}`` put in
    (line index 0: the header), as a damaged or hand-edited file has them."""
    lines = path.read_text().splitlines()
    for (k, c), text in cells.items():
        row = lines[k].split(",")
        row[c] = text
        lines[k] = ",".join(row)
    path.write_text("\n".join(lines) + "\n")


#: Pose2Sim's markers for Halpe 26 (its skeleton tree: the eyes and ears left out), as its TRC files name them
POSE2SIM_HALPE26 = ("Hip", "RHip", "RKnee", "RAnkle", "RBigToe", "RSmallToe", "RHeel", "LHip", "LKnee", "LAnkle",
                    "LBigToe", "LSmallToe", "LHeel", "Neck", "Head", "Nose", "RShoulder", "RElbow", "RWrist",
                    "LShoulder", "LElbow", "LWrist")


def write_trc(path, body, pos, world, fps=30.0, markers=POSE2SIM_HALPE26, units="mm"):
    """An OpenSim ``.trc`` of the Halpe 26 points of the motion ``pos`` / ``world`` named ``markers``
    (each a Pose2Sim name: ``RBigToe`` is Halpe's right big toe), +Y up, in ``units``, as Pose2Sim
    writes it (tab separated; ``Frame#``, ``Time``; a blank line after the header).  Returns the
    ``(T, len(markers), 3)`` points written, metres, Blender axes."""
    from blender_manikin.core.io_keypoints import trc_point
    lay = kl.LAYOUTS["halpe26"]
    kp = kl.keypoints_from_body22(pos, world, "halpe26", body.stature)
    pts = kp[:, [lay.index(trc_point(m)) for m in markers]]
    scale = {"m": 1.0, "mm": 1000.0}[units]
    Y = to_y_up(pts, scale)
    T = len(pts)
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{os.path.basename(path)}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{fps:.2f}\t{fps:.2f}\t{T}\t{len(markers)}\t{units}\t{fps:.2f}\t1\t{T}",
             "Frame#\tTime\t" + "\t\t\t".join(markers) + "\t\t",
             "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(markers))),
             ""]
    for t in range(T):
        lines.append(f"{t + 1}\t{t / fps:.6f}\t" + "\t".join(f"{v:.5f}" for v in Y[t].ravel()))
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")
    return pts
