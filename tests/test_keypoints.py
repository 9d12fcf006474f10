"""3D keypoints → animated 22-joint body (HybrIK twist-and-swing): layouts, readers, solve, CLI."""
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import hybrik
from blender_manikin.core import keypoint_solve as ks
from blender_manikin.core import smoothing as sm
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core.io_keypoints import is_keypoint_input, read_keypoints
from blender_manikin.core.recording import RecordingError
from blender_manikin.core.solve import SolveError, SolveSettings, solve_recording

from fixtures_keypoints import (POSE2SIM_HALPE26, hinge_motion, set_csv_cells, to_y_up, write_freemocap,
                                write_layout_csv, write_layout_npy, write_trc)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIMB_JOINTS = [sk.J[f"{s}_{j}"] for s in ("left", "right")
               for j in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")]


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=240, seed=0)


def _fit_error(outcome, clean_file, layout):
    """Mean distance (m) of the fitted limb joints to the clean keypoints' joints, both in the
    solver's frame (the clean file read the same way; the solve's floor shift removed)."""
    ref = kl.body22_from_keypoints(read_keypoints(clean_file, layout=layout).points, layout).positions
    fit = outcome.result.fk()[0]
    ref = ref.copy()
    ref[..., 2] += np.median(fit[..., 2] - ref[..., 2])
    return float(np.linalg.norm(fit[:, LIMB_JOINTS] - ref[:, LIMB_JOINTS], axis=-1).mean())


def _bone_drift(outcome):
    pos = outcome.result.fk()[0]
    L = np.linalg.norm(pos[:, 1:] - pos[:, sk.PARENTS[1:]], axis=-1)
    return float(np.abs(L - L[:1]).max())


# --------------------------------------------------------------------------
# layouts
@pytest.mark.parametrize("layout", list(kl.LAYOUTS))
def test_layout_joints_and_orientations_round_trip(layout, motion):
    body, pos, world = motion
    kp = kl.keypoints_from_body22(pos, world, layout, body.stature)
    assert kp.shape == (len(pos), len(kl.LAYOUTS[layout].points), 3)
    b = kl.body22_from_keypoints(kp, layout)
    have = range(22) if layout.startswith("smpl") else LIMB_JOINTS
    np.testing.assert_allclose(b.positions[:, have], pos[:, have], atol=1e-9)
    assert np.isfinite(b.positions).all()
    # the orientations a layout shows are the body's (twist included), except the flat-roll feet
    flat = {sk.J[f"{s}_ankle"] for s in ("left", "right")} if layout in ("mediapipe33", "plugingait") else set()
    for j, R in b.end_rot.items():
        if j not in flat:
            np.testing.assert_allclose(R, world[:, j], atol=1e-6 if layout != "h36m17" else 0.7)
    shows = {"mediapipe33": {"head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"},
             "coco17": {"head"}, "h36m17": {"head"}, "body25": {"head", "left_ankle", "right_ankle"},
             "halpe26": {"head", "left_ankle", "right_ankle"}, "smpl22": set(), "smpl24": set(),
             "opencap": {"left_ankle", "right_ankle"}, "plugingait": {"head", "left_ankle", "right_ankle"}}[layout]
    assert {sk.JOINT_NAMES[j] for j in b.end_rot} == shows
    assert "left_wrist" in b.no_twist or "left_wrist" in shows


def test_a_head_without_its_ears_is_placed_from_the_head_top(motion):
    """Halpe 26 has the ears and the head top: where the ears are missing (Pose2Sim's markers leave
    them out; a detector loses them), the head joint comes from the head top and the neck, as for
    Human3.6M, instead of going missing."""
    body, pos, world = motion
    kp = kl.keypoints_from_body22(pos, world, "halpe26", body.stature)
    lay = kl.LAYOUTS["halpe26"]
    kp[::2, [lay.index(p) for p in ("left_eye", "right_eye", "left_ear", "right_ear")]] = np.nan
    b = kl.body22_from_keypoints(kp, "halpe26")
    head = sk.J["head"]
    assert np.isfinite(b.positions).all() and np.isfinite(b.end_rot[head]).all()
    np.testing.assert_allclose(b.positions[1::2, head], pos[1::2, head], atol=1e-9)       # from the ears
    np.testing.assert_allclose(b.positions[::2, head], pos[::2, head], atol=1e-6)         # from the head top


def test_layout_names_and_aliases():
    assert kl.canonical_layout("COCO") == "coco17"
    assert kl.canonical_layout("MediaPipe-33") == "mediapipe33"
    assert kl.canonical_layout("openpose") == "body25"
    assert kl.canonical_layout("Halpe") == "halpe26" and kl.canonical_layout("AlphaPose") == "halpe26"
    with pytest.raises(ValueError, match="unknown keypoint layout 'coco18'.*coco17"):
        kl.canonical_layout("coco18")


# --------------------------------------------------------------------------
# readers
def test_freemocap_folder_detection_line(tmp_path, motion):
    folder, _ = write_freemocap(str(tmp_path / "session"), *motion)
    assert is_keypoint_input(folder) and is_keypoint_input(os.path.join(folder, "output_data"))
    rec = read_keypoints(folder)
    assert rec.layout == "mediapipe33" and rec.points.shape == (240, 33, 3)
    line = rec.metadata["detected"]
    assert line.startswith("keypoints: mediapipe33 (33 points, from the file); FreeMoCap folder;")
    assert "units mm (leg 0.7" in line
    assert "up +Y (shoulders above the ankles), right-handed (nose ahead of the ears)" in line
    assert "30 Hz (assumed: set the rate)" in line
    # metres, +Z up: the head is above the feet, the performer about 1.7 m tall
    lay = kl.LAYOUTS["mediapipe33"]
    h = rec.points[:, lay.index("nose"), 2] - rec.points[:, lay.index("left_ankle"), 2]
    assert 1.3 < np.median(h) < 1.8
    # +Y up turned as Blender's importers turn it, (x, y, z) -> (x, -z, y): the body made facing
    # -Y (Blender's front view) comes back facing -Y, its left at +X
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "mediapipe33", body.stature)
    np.testing.assert_allclose(rec.points[0] - rec.points[0, :1], clean[0] - clean[0, :1], atol=0.002)


def test_seventeen_points_told_apart_and_mirrored_files_found(tmp_path, motion):
    body, pos, world = motion
    for layout in ("coco17", "h36m17"):
        p = tmp_path / f"{layout}.npy"
        write_layout_npy(p, layout, body, pos, world, scale=100.0)       # centimetres
        rec = read_keypoints(p)
        assert rec.layout == layout and rec.metadata["units"] == "cm"
    # a left-handed file (Unity-like: X mirrored) is recognised by the face and put right
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    np.save(tmp_path / "mirrored.npy", to_y_up(clean) * np.array([-1.0, 1.0, 1.0]))
    np.save(tmp_path / "plain.npy", to_y_up(clean))
    a, b = read_keypoints(tmp_path / "mirrored.npy"), read_keypoints(tmp_path / "plain.npy")
    assert a.metadata["handed"] == "left" and b.metadata["handed"] == "right"
    la, lb = kl.body22_from_keypoints(a.points, "coco17"), kl.body22_from_keypoints(b.points, "coco17")
    # the same body, its left still on its left (same limb lengths, same facing relative to it)
    np.testing.assert_allclose(np.linalg.norm(la.positions[:, 7] - la.positions[:, 8], axis=-1),
                               np.linalg.norm(lb.positions[:, 7] - lb.positions[:, 8], axis=-1), atol=1e-9)
    np.testing.assert_allclose(la.end_rot[sk.J["head"]] @ np.eye(3), la.end_rot[sk.J["head"]], atol=1e-9)
    assert np.linalg.det(la.end_rot[sk.J["head"]]).min() > 0.99


def test_keypoint_csv_with_gaps_and_a_mapping_file(tmp_path, motion):
    body, pos, world = motion
    p = tmp_path / "coco.csv"
    write_layout_csv(p, "coco17", body, pos, world, drop=0.02, seed=3)
    assert is_keypoint_input(p)
    rec = read_keypoints(p)
    assert rec.layout == "coco17" and np.isnan(rec.points).any()
    assert "30 Hz (from the times)" in rec.metadata["detected"]
    names = {"nose": "Nose", "left_wrist": "LWrist", "right_wrist": "RWrist"}
    q = tmp_path / "renamed.csv"
    write_layout_csv(q, "coco17", body, pos, world, names=names)
    assert not is_keypoint_input(q)              # not a layout's own column names
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({"layout": "coco", "columns": names}))
    rec2 = read_keypoints(q, mapping=str(mapping))
    assert rec2.layout == "coco17" and np.isfinite(rec2.points).all()


@pytest.mark.parametrize("column, scale, offset, unit", [
    ("timestamp", 1.0, 0.0, ""),                 # seconds
    ("timestamp", 1.0, 1.7e9, ""),               # Unix seconds
    ("time", 1e3, 0.0, ", in ms"),
    ("timestamp", 1e3, 0.0, ", in ms"),
    ("timestamp", 1e9, 1.7e18, ", in ns"),       # Unix nanoseconds
])
def test_keypoint_csv_times_are_read_in_the_unit_their_steps_say(tmp_path, motion, column, scale, offset, unit):
    # a time in ms was read as seconds (0.03 Hz: 8 s became 8000 s, 240000 frames), a timestamp
    # in seconds as ms (30000 Hz: the take one frame long), one in ns ran out of memory
    body, pos, world = motion
    p = tmp_path / "times.csv"
    write_layout_csv(p, "coco17", body, pos, world)
    lines = p.read_text().splitlines()
    lines[0] = lines[0].replace("time,", f"{column},", 1)
    for k in range(1, len(lines)):
        t = float(lines[k].split(",", 1)[0])
        lines[k] = repr(offset + t * scale) + "," + lines[k].split(",", 1)[1]
    p.write_text("\n".join(lines) + "\n")
    rec = read_keypoints(p)
    assert f"30 Hz (from the times{unit})" in rec.metadata["detected"]
    assert rec.time[-1] - rec.time[0] == pytest.approx(239 / 30.0, rel=1e-6)
    fps = 1.0 / np.median(np.diff(rec.time))
    assert ks.resample_points(rec.time, rec.points, fps)[0].shape == (240,)


def test_freemocap_csv_exports_are_read_as_keypoints(tmp_path, motion):
    # FreeMoCap writes output_data/mediapipe_body_3d_xyz.csv (body_nose_x, ..., no time) and
    # <recording>_by_trajectory.csv (timestamp, empty without timestamps, and timestamp_by_camera
    # first; hand points after the body's): both were taken for tracker CSVs and refused with
    # "wrong header: expected the column names 'time,device,px,...'"
    body, pos, world = motion
    clean = write_layout_csv(tmp_path / "plain.csv", "mediapipe33", body, pos, world)
    lines = (tmp_path / "plain.csv").read_text().splitlines()
    head = lines[0].split(",")[1:]
    body_csv = tmp_path / "mediapipe_body_3d_xyz.csv"
    body_csv.write_text("\n".join([",".join(f"body_{c}" for c in head)]
                                  + [ln.split(",", 1)[1] for ln in lines[1:]]) + "\n")
    by_traj = tmp_path / "take_by_trajectory.csv"
    by_traj.write_text("\n".join([",".join(["timestamp", "timestamp_by_camera"] + [f"body_{c}" for c in head]
                                           + ["right_hand_wrist_x", "right_hand_wrist_y", "right_hand_wrist_z"])]
                                 + [',"{}",' + ln.split(",", 1)[1] + ",1,2,3" for ln in lines[1:]]) + "\n")
    for p in (body_csv, by_traj):
        assert is_keypoint_input(p)
        rec = read_keypoints(p)
        assert rec.layout == "mediapipe33" and "30 Hz (assumed: set the rate)" in rec.metadata["detected"]
        np.testing.assert_allclose(rec.points - rec.points[:1, :1], clean - clean[:1, :1], atol=2e-6)


def test_pose2sim_trc_markers_are_read_as_halpe26_and_solved(tmp_path, motion):
    """An OpenSim .trc as Pose2Sim writes it (Halpe 26 without the eyes and ears, in mm, +Y up,
    tab separated): the markers named as points (RBigToe, Hip, Head), the layout the one they cover
    most, the missing points NaN, the rate and units from the header; solved, the limbs land on
    the markers and the head is placed from the head top."""
    body, pos, world = motion
    path = tmp_path / "Balancing_for_IK.trc"
    pts = write_trc(path, body, pos, world)
    assert is_keypoint_input(path)
    rec = read_keypoints(path)
    assert rec.layout == "halpe26" and "30 Hz (from the times)" in rec.metadata["detected"]
    assert rec.metadata["units"] == "mm" and rec.metadata["up"] == "+Y"
    lay = kl.LAYOUTS["halpe26"]
    assert np.isnan(rec.points[:, lay.index("left_ear")]).all()
    got = rec.points[:, [lay.index(p) for p in ("left_wrist", "right_ankle", "head_top")]]
    want = pts[:, [POSE2SIM_HALPE26.index(m) for m in ("LWrist", "RAnkle", "Head")]]
    np.testing.assert_allclose(got - got[:1, :1], want - want[:1, :1], atol=2e-5)
    out = solve_recording(str(path), SolveSettings(fps=30.0))
    P = out.result.positions
    for j in ("left_wrist", "right_knee", "head"):
        err = np.linalg.norm((P[:, sk.J[j]] - P[:, :1]) - (pos[:, sk.J[j]] - pos[:, :1]), axis=-1)
        assert np.median(err) < 0.01, (j, np.median(err))
    # markers that do not name a limb's joints: an error naming what they lack, and where
    bad = tmp_path / "markers.trc"
    write_trc(bad, body, pos, world, markers=tuple(m for m in POSE2SIM_HALPE26 if m != "LKnee"))
    with pytest.raises(RecordingError, match=r"markers.trc, line 4: the TRC's markers .* lack left_knee"):
        read_keypoints(bad)
    lines = path.read_text().splitlines()
    lines[8] = lines[8].replace("\t", "\tabc\t", 1)
    (tmp_path / "cell.trc").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"cell.trc, line 9: 'abc' is not a number"):
        read_keypoints(tmp_path / "cell.trc")
    (tmp_path / "not.trc").write_text("Frame#\tTime\n")
    with pytest.raises(RecordingError, match="not a TRC file"):
        read_keypoints(tmp_path / "not.trc")


def test_a_tilted_floor_is_levelled_from_the_planted_feet(tmp_path):
    # keypoints in a camera's frame (OpenCV: +Y down, +Z ahead), the camera pitched 20° down and
    # rolled 5°: the up axis was snapped to -Y and the tilt kept, so the body leant 20° and,
    # walking away from the camera, climbed a slope: its feet 0.6 m above the floor by the end
    body, pos, world = hinge_motion(frames=1, seed=0)
    t = np.arange(600) / 30.0
    s = 0.8 * (np.floor(t / 2.0) + np.clip(t % 2.0 - 1.0, 0.0, 1.0))     # walks in bursts, feet still between
    path = np.stack([np.sin(0.15 * s), -np.cos(0.15 * s), 0 * s], -1) * np.gradient(s)[:, None]
    pos, world = pos + path.cumsum(0)[:, None], np.repeat(world, 600, axis=0)
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    pitch, roll = np.radians(20.0), np.radians(5.0)
    cam = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    cam = (rot.axis_angle_rotation(np.array([0.0, 0, 1]), roll)
           @ rot.axis_angle_rotation(np.array([1.0, 0, 0]), pitch) @ cam)
    np.save(tmp_path / "camera.npy", (clean - [0.0, -8.0, 1.6]) @ cam.T)
    np.save(tmp_path / "level.npy", to_y_up(clean))
    rec = read_keypoints(tmp_path / "camera.npy")
    assert re.search(r"floor levelled \(tilted 2\d\.\d° in the file, from the planted feet\)", rec.metadata["detected"])
    ankles = rec.points[:, [kl.LAYOUTS["coco17"].index(f"{s}_ankle") for s in ("left", "right")], 2].min(-1)
    assert np.ptp(np.percentile(ankles.reshape(10, -1), 5, axis=1)) < 0.02     # the same floor all along
    level = read_keypoints(tmp_path / "level.npy")
    assert "floor levelled" not in level.metadata["detected"]
    # a slope walked up in a level frame (the plants climb 17°, the trunks stay upright): left as it is
    uphill = clean + np.stack([0 * s, 0 * s, 0.3 * s], -1)[:, None]
    np.save(tmp_path / "uphill.npy", to_y_up(uphill))
    hill = read_keypoints(tmp_path / "uphill.npy")
    assert "floor levelled" not in hill.metadata["detected"]
    np.testing.assert_allclose(hill.points - hill.points[:1, :1], uphill - uphill[:1, :1], atol=1e-6)

    def lean(r):                                # degrees the trunk leans off the vertical
        up = r.points[:, 5:7].mean(1) - r.points[:, 11:13].mean(1)
        return np.degrees(np.arccos(np.median(up[:, 2] / np.linalg.norm(up, axis=-1))))
    assert abs(lean(rec) - lean(level)) < 1.5                            # upright (it leant 20°)


@pytest.mark.parametrize("content, problem", [
    (b"\x93NUMPY garbage", "not a readable .npy array"),
])
def test_bad_npy(tmp_path, content, problem):
    p = tmp_path / "bad.npy"
    p.write_bytes(content)
    with pytest.raises(RecordingError, match=rf"bad.npy: {problem}"):
        read_keypoints(p)


def test_bad_inputs_name_the_file_line_and_problem(tmp_path, motion):
    body, pos, world = motion
    np.save(tmp_path / "shape.npy", np.zeros((10, 5)))
    with pytest.raises(RecordingError, match=r"shape.npy: keypoints must be \(frames, points, 3\).*\(10, 5\)"):
        read_keypoints(tmp_path / "shape.npy")
    np.save(tmp_path / "count.npy", np.zeros((10, 19, 3)))
    with pytest.raises(RecordingError, match="count.npy: 19 points per frame match no keypoint layout"):
        read_keypoints(tmp_path / "count.npy")
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    np.save(tmp_path / "tiny.npy", to_y_up(clean) * 1e-5)
    with pytest.raises(RecordingError, match="tiny.npy: cannot tell the units.*set the units"):
        read_keypoints(tmp_path / "tiny.npy")
    p = tmp_path / "cells.csv"
    write_layout_csv(p, "coco17", body, pos, world)
    set_csv_cells(p, {(5, 4): "oops"})
    with pytest.raises(RecordingError, match=r"cells.csv, line 6: column 'left_eye_x': 'oops' is not a number"):
        read_keypoints(p)
    with pytest.raises(RecordingError, match="layout coco17 has 17 points, the file 33"):
        read_keypoints(write_freemocap(str(tmp_path / "fm"), *motion)[0], layout="coco17")


# --------------------------------------------------------------------------
# stages
def test_bridge_gaps_and_smoothing():
    t = np.arange(20) / 10.0
    x = np.stack([t, t ** 2, np.ones_like(t)], -1)[:, None, :].copy()
    y = x.copy()
    y[3:6] = np.nan
    y[0] = np.nan
    filled, gaps = ks.bridge_gaps(t, y, ["p"])
    assert [(g.reason, g.samples) for g in gaps] == [("start", 1), ("lost", 3)]
    np.testing.assert_allclose(filled[3:6, 0, 0], t[3:6])               # linear: exact on a line
    np.testing.assert_allclose(filled[0], filled[1])                     # held before the first
    # Savitzky-Golay (quadratic) keeps quadratics exactly, ends included; noise shrinks
    np.testing.assert_allclose(sm.smooth(x, 10.0, 0.5), x, atol=1e-12)
    rng = np.random.default_rng(0)
    n = rng.normal(size=(400, 3))
    assert sm.smooth(n, 30.0, 0.4).std() < 0.6 * n.std()
    np.testing.assert_array_equal(sm.smooth(n, 30.0, 0.0), n)


def test_track_noise_and_auto_smoothing_follow_each_points_own_noise():
    """smooth_auto: the noise measured on each track picks its filter; a noisy track gets a long
    window and ends closer to the truth than any one fixed window; a clean one is left sharp."""
    fps, T = 30.0, 300
    t = np.arange(T) / fps
    rng = np.random.default_rng(3)
    truth = np.stack([np.stack([0.3 * np.sin(2 * np.pi * f * t + k), 0.2 * np.cos(2 * np.pi * f * t),
                                0.1 * np.sin(np.pi * f * t)], -1)
                      for k, f in enumerate((0.3, 0.3, 2.0, 2.0))], 1)            # (T, 4, 3): slow, slow, fast, fast
    sigma = np.array([0.0, 0.02, 0.0, 0.02])
    x = truth + rng.normal(size=truth.shape) * sigma[None, :, None]
    est = sm.track_noise(x)
    assert est[0] < 0.002 and est[2] < 0.004                     # clean tracks: (nearly) no noise measured
    np.testing.assert_allclose(est[[1, 3]], 0.02, rtol=0.2)
    y, choice = sm.smooth_auto(x, fps)
    win = np.array([sm.AUTO_FILTERS[c][0] for c in choice])
    assert win[1] > win[3] > 0.0 and win[2] <= 0.2                # slow noisy: longest; clean fast: (nearly) none
    err = np.linalg.norm(y - truth, axis=-1).mean(0)
    assert err[0] < 0.001 and err[2] < 0.003                       # clean input stays (nearly) as it was
    for w in (0.2, 0.4, 0.8):                                       # better than one window for all
        fixed = np.linalg.norm(sm.smooth(x, fps, w) - truth, axis=-1).mean(0)
        assert err.sum() < fixed.sum()
    assert sm.savgol_trace(T, 1, 2) == T and sm.savgol_trace(T, 13, 2) < T / 3
    assert sm.parse_smoothing("auto") == "auto" and sm.parse_smoothing("0.3") == 0.3 and sm.parse_smoothing(None) == 0
    for bad in ("soft", -1.0, "nan"):
        with pytest.raises(SolveError, match="expected 'auto' or a window in seconds"):
            sm.parse_smoothing(bad)


def test_rigid_trunk_meets_the_hips_and_shoulders_of_a_bent_trunk():
    """A layout without spine points: the guessed spine joints shorten as the trunk bends; the
    trunk fit still puts the hips and shoulders where the keypoints are."""
    body = sk.make_body(1.75)
    T = 60
    local = np.broadcast_to(np.eye(3), (T, sk.NUM_JOINTS, 3, 3)).copy()
    bend = np.linspace(0.0, 1.2, T)                                 # up to ~70 degrees forward over 3 joints
    for j in ("spine1", "spine2", "spine3"):
        local[:, sk.J[j]] = rot.axis_angle_rotation(np.array([1.0, 0.0, 0.0]), -bend / 3)
    pos, world = sk.forward_kinematics(local, np.tile(body.root_rest, (T, 1)), body)
    P = kl.body22_from_keypoints(kl.keypoints_from_body22(pos, world, "coco17", body.stature), "coco17").positions
    chord = np.linalg.norm(P[:, sk.J["neck"]] - P[:, sk.J["pelvis"]], axis=-1)
    assert chord.max() - chord.min() > 0.03                          # the guessed spine is not rigid
    sized = ks.size_body(P, derived_spine=True)
    spine = [sk.J[n] for n in ("spine1", "spine2", "spine3", "neck")]
    assert abs(sized.bone_lengths()[spine].sum() - np.percentile(chord, ks.SPINE_PERCENTILE)) < 1e-9
    Pt, R0 = ks.rigid_trunk(P, sized)
    ik = hybrik.ik_from_positions(Pt, sized, end_rot={sk.J["pelvis"]: R0}, aim_chain=True, within_limits=True)
    hips = [sk.J["left_hip"], sk.J["right_hip"]]
    shoulders = [sk.J["left_shoulder"], sk.J["right_shoulder"]]
    assert np.linalg.norm(ik.positions[:, hips] - P[:, hips], axis=-1).max() < 1e-3
    assert np.linalg.norm(ik.positions[:, shoulders] - P[:, shoulders], axis=-1).max() < 0.01
    # the guessed spine joints, aimed at one by one, leave the shoulders further off
    plain = hybrik.ik_from_positions(P, ks.size_body(P), aim_chain=True, within_limits=True)
    ours = np.linalg.norm(ik.positions[:, shoulders] - P[:, shoulders], axis=-1).mean()
    theirs = np.linalg.norm(plain.positions[:, shoulders] - P[:, shoulders], axis=-1).mean()
    assert ours < 0.5 * theirs, (ours, theirs)


def test_sized_body_has_the_takes_bones_and_stands_on_the_floor(motion):
    body, pos, world = motion
    b = ks.size_body(pos)
    np.testing.assert_allclose(b.bone_lengths(), body.bone_lengths(), atol=1e-9)
    np.testing.assert_allclose(b.rest_positions(), body.rest_positions(), atol=1e-9)
    assert abs(b.stature - body.stature) < 1e-9
    lifted = pos + np.array([0.0, 0.0, 0.3])
    assert abs(ks.estimate_floor(lifted, b) - 0.3) < 0.02


# --------------------------------------------------------------------------
# whole solves
@pytest.mark.parametrize("sigma", [0.02 / np.sqrt(3), 0.02])
def test_freemocap_folder_with_noise_and_gaps_solves_within_targets(tmp_path, motion, sigma):
    """The issue's target: fitted joints within 1.5 cm of the clean keypoints at 2 cm noise
    (read both ways: 2 cm in 3D, σ = 1.15 cm per coordinate; and σ = 2 cm per coordinate),
    bones constant to 0.1 mm."""
    body, pos, world = motion
    folder, clean = write_freemocap(str(tmp_path / "fm"), body, pos, world, sigma=sigma, drop=0.03, seed=5)
    np.save(tmp_path / "clean.npy", to_y_up(clean, 1000.0))
    out = solve_recording(folder, SolveSettings(fps=30.0))
    assert out.result.num_frames == 240 and out.body is not None
    err = _fit_error(out, tmp_path / "clean.npy", "mediapipe33")
    assert err < 0.015, err
    assert _bone_drift(out) < 1e-4
    assert abs(out.body.stature - body.stature) < 0.03
    s = out.summary()
    assert s.startswith("keypoints: mediapipe33")
    assert re.search(r"\d+ gap\(s\) bridged, the longest point [a-z ]+ \d+\.\d\d? s from \d+\.\d s \(not seen\)", s), s
    assert "smoothing auto (per point, from its measured noise): windows " in s
    assert "no twist information: left_foot, right_foot (rest twist)" in s
    # hinges within limits, feet above the floor
    from blender_manikin.core import limb_solver as ls
    P, W = out.result.fk()
    for li, (_, b, m, e) in enumerate(sk.LIMBS):
        loc = out.result.local_rot[:, m]
        axis_angle = np.degrees(np.arccos(np.clip((np.trace(loc, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))
        assert axis_angle.max() <= np.degrees(ls.FLEX_MAX[li]) + 60.0       # flexion plus twist range
    assert P[:, [sk.J["left_ankle"], sk.J["right_ankle"]], 2].min() > 0.0


@pytest.mark.parametrize("sigma", [0.02, 0.04])
def test_adaptive_beats_naive_as_noise_grows(tmp_path, motion, sigma):
    body, pos, world = motion
    clean = write_layout_npy(tmp_path / "k.npy", "h36m17", body, pos, world, sigma=sigma, seed=2)
    np.save(tmp_path / "clean.npy", to_y_up(clean))
    err = {}
    for ik in ("adaptive", "naive"):
        out = solve_recording(tmp_path / "k.npy", SolveSettings(fps=30.0, ik=ik, smoothing=0.0))
        err[ik] = _fit_error(out, tmp_path / "clean.npy", "h36m17")
    assert err["adaptive"] < err["naive"], err


def test_the_summary_says_which_ik_solved(tmp_path, motion):
    """A researcher comparing naive and adaptive HybrIK (``--ik``, the panel's *IK*) reads in the
    summary (command line, panel, batch) which of the two solved the take, and where the floor was."""
    body, pos, world = motion
    write_layout_npy(tmp_path / "k.npy", "coco17", body, pos, world, sigma=0.01, seed=3)
    for ik in ("adaptive", "naive"):
        s = solve_recording(tmp_path / "k.npy", SolveSettings(fps=30.0, ik=ik)).summary()
        assert re.search(rf"; keypoints: {ik} HybrIK, floor at [+-]\d\.\d{{3}} m moved to 0; ", s), s


def test_unknown_ik_and_never_seen_points(tmp_path, motion):
    body, pos, world = motion
    write_layout_npy(tmp_path / "k.npy", "coco17", body, pos, world)
    with pytest.raises(SolveError, match="ik 'fancy': expected adaptive or naive"):
        solve_recording(tmp_path / "k.npy", SolveSettings(ik="fancy"))
    kp = to_y_up(kl.keypoints_from_body22(pos, world, "coco17", body.stature))
    kp[:, kl.LAYOUTS["coco17"].index("left_ear")] = np.nan
    np.save(tmp_path / "noear.npy", kp)
    # an ear never seen: the head on the trunk's up axis, untwisted (it could not be placed before)
    out = solve_recording(tmp_path / "noear.npy", SolveSettings())
    assert "point(s) never seen: left_ear" in out.info
    assert any(n.startswith("no twist information: head,") for n in out.info), out.info
    head = out.result.positions[:, sk.J["head"]] - out.result.positions[:, sk.J["neck"]]
    assert np.isfinite(head).all() and 0.05 < np.median(np.linalg.norm(head, axis=-1)) < 0.15
    kp[:, kl.LAYOUTS["coco17"].index("left_hip")] = np.nan
    np.save(tmp_path / "nohip.npy", kp)
    with pytest.raises(SolveError, match="joint\\(s\\) .*left_hip.* cannot be placed: point\\(s\\) left_ear, "
                                         "left_hip never seen"):
        solve_recording(tmp_path / "nohip.npy", SolveSettings())


def test_cli_solves_keypoints_without_blender(tmp_path, motion):
    """``python -m blender_manikin solve`` on a FreeMoCap folder and a COCO-17 .npy: json + bvh,
    no bpy needed (run in a fresh process with bpy hidden)."""
    body, pos, world = motion
    d = tmp_path / "in"
    d.mkdir()
    write_layout_npy(d / "coco.npy", "coco17", body, pos, world, sigma=0.01, drop=0.02, scale=1000.0)
    folder, _ = write_freemocap(str(tmp_path / "session1"), body, pos, world, sigma=0.01)
    out = tmp_path / "out"
    code = ("import sys; sys.modules['bpy'] = None\n"
            "from blender_manikin import cli\n"
            f"sys.exit(cli.main(['solve', {str(d)!r}, {folder!r}, '--out', {str(out)!r}, "
            "'--format', 'json,bvh', '--fps', '30', '--smoothing', '0.3', '--layout', 'coco17']))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=ROOT))
    assert r.returncode == 1, r.stderr          # --layout coco17 does not fit the 33-point folder
    assert "session1" in r.stderr and "layout coco17 has 17 points, the file 33" in r.stderr
    ok = [ln for ln in r.stdout.splitlines() if ln.startswith("OK ")]
    assert len(ok) == 1 and "coco.npy" in ok[0] and "keypoints: coco17 (17 points, as set)" in ok[0]
    doc = json.loads((out / "coco.json").read_text())
    assert len(doc["positions"]) == 240
    assert (out / "coco.bvh").read_text().startswith("HIERARCHY")
    code = code.replace(", '--layout', 'coco17'", "")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=ROOT))
    assert r.returncode == 0, r.stderr
    assert (out / "session1.json").exists() and (out / "session1.bvh").exists()


def test_dataset_conversion_takes_a_freemocap_folder_as_one_input(tmp_path, motion):
    from blender_manikin.core import convert
    root = tmp_path / "captures"
    folder, _ = write_freemocap(str(root / "day1" / "session_a"), *motion)
    os.makedirs(os.path.join(folder, "output_data", "raw_data"))
    np.save(os.path.join(folder, "output_data", "raw_data", "mediapipe_2d.npy"), np.zeros((3, 33, 2)))
    body, pos, world = motion
    write_layout_npy(root / "day1" / "clip.npy", "coco17", body, pos, world)
    found = convert.collect_inputs([str(root)])
    assert found == [os.path.abspath(root / "day1" / "clip.npy"), os.path.abspath(folder)]


def test_keypoints_trimmed_to_a_part_of_the_take(tmp_path, motion):
    """--start / --end cut keypoints too: the frames of that part, the times kept."""
    from blender_manikin.core import solve as cs
    body, pos, world = motion
    folder, _ = write_freemocap(str(tmp_path / "session"), body, pos, world, sigma=0.005)
    full = cs.solve_recording(folder, cs.SolveSettings(fps=30.0))
    part = cs.solve_recording(folder, cs.SolveSettings(fps=30.0, start=2.0, end=4.0))
    assert part.result.num_frames == 61 and part.result.t0 == pytest.approx(full.result.t0 + 2.0)
    assert "trimmed to 2.00-4.00 s" in part.info
    e = np.linalg.norm(part.result.positions - full.result.positions[60:121], axis=-1)
    assert np.median(e) < 0.02
    with pytest.raises(cs.SolveError, match="past the recording's end"):
        cs.solve_recording(folder, cs.SolveSettings(fps=30.0, start=60.0))


def test_layouts_are_found_from_point_names():
    """Object or column names as tools write them are matched to a layout's points."""
    assert kl.point_key("Body_Left_Wrist.001") == "left_wrist"
    assert kl.point_key("mediapipe_nose") == "nose" and kl.point_key("left hip_empty") == "left_hip"
    names = [f"{p}.002" for p in kl.LAYOUTS["coco17"].points] + ["Camera", "origin"]
    layout, found = kl.layout_from_names(names)
    assert layout == "coco17" and found["left_ankle"] == "left_ankle.002"
    mp = list(kl.LAYOUTS["mediapipe33"].points)                  # holds every COCO point too
    assert kl.layout_from_names(mp)[0] == "mediapipe33"
    assert kl.layout_from_names(mp[:-1] + ["Cube"]) is not None and \
        kl.layout_from_names(mp[:-1])[0] == "coco17"             # a mediapipe point short: COCO's 17
    assert kl.layout_from_names(["nose", "left_wrist"]) is None


def test_straight_limbs_of_noisy_keypoints_keep_their_swivel():
    """A straight arm or leg in noisy keypoints: its mid joint is off the shoulder-wrist (hip-ankle)
    axis by the noise alone, in a random direction, and that direction must not set the swivel.
    The bundled example (examples/make_example_keypoints.py: 8 mm noise) starts with a still
    T-pose: its shoulders turned up to 144° about the arm from frame to frame and its hips to
    the 45° limit (knee caps sideways) where the performance's were still."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples"))
    from make_example_recording import STATURE, motion as example_motion
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = solve_recording(os.path.join(root, "examples", "example_keypoints"), SolveSettings(fps=30.0))
    P, W = out.result.fk()
    body = sk.make_body(sk.BodyMeasurements(stature=STATURE))
    local, rp = example_motion(np.arange(P.shape[0]) / 30.0, body)
    true_pos, true_rot = sk.forward_kinematics(local, rp, body)
    tpose = slice(0, 30)                          # the first second: a still T-pose, limbs straight
    for name in ("left_shoulder", "right_shoulder", "left_hip", "right_hip"):
        j = sk.J[name]
        err = np.degrees(rot.geodesic_angle(W[tpose, j], true_rot[tpose, j]))
        step = np.degrees(rot.geodesic_angle(W[1:30, j], W[:29, j]))
        assert err.max() < 20.0 and step.max() < 15.0, (name, err.max(), step.max())
    assert np.linalg.norm(P - true_pos, axis=-1).mean() < 0.012          # the joints where they were


def test_keypoint_floor_keep_leaves_the_joints_at_the_heights_given(motion):
    """keypoint_floor="keep" (an armature's bones, whose floor is the scene's): the solved joints
    stay where the keypoints are, 0.4 m up on a platform, whatever the shoe soles; "feet" (the
    default) stands the body on z = 0 on its soles; anything else is named."""
    from blender_manikin.core.io_keypoints import keypoints_from_points
    body, pos, world = motion
    lifted = pos + np.array([0.0, 0.0, 0.4])
    rec = keypoints_from_points(np.arange(len(pos)) / 30.0, lifted, "smpl22", "platform")
    for sole in (0.0, 0.03):
        out = ks.solve_keypoints(rec, SolveSettings(fps=30.0, keypoint_floor="keep", sole=sole))
        err = np.linalg.norm(out.result.fk()[0] - lifted, axis=-1)
        assert err.mean() < 0.003 and np.median(err.max(-1)) < 0.01, (sole, err.mean(), err.max())
        assert any(re.match(r"floor at \+0\.[34]\d\d m under the feet, heights kept as given", n)
                   for n in out.info), out.info
    out = ks.solve_keypoints(rec, SolveSettings(fps=30.0, sole=0.03))
    dz = np.median(out.result.fk()[0][..., 2] - lifted[..., 2])
    assert -0.42 < dz < -0.35, dz          # moved to the floor found under the feet, on the soles
    with pytest.raises(SolveError, match="keypoint floor 'float': expected feet or keep"):
        ks.solve_keypoints(rec, SolveSettings(keypoint_floor="float"))
    from blender_manikin import cli
    p = cli.build_parser()
    assert cli.solve_settings(p.parse_args(["solve", "k.npy", "--out", "o", "--keypoint-floor", "keep"])) \
        .keypoint_floor == "keep"
    assert cli.solve_settings(p.parse_args(["solve", "k.npy", "--out", "o"])).keypoint_floor == "feet"
