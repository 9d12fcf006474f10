"""Keypoint files laid out as the tools that write them lay them out (synthetic values in each
writer's layout, read from its code): FreeMoCap's whole-skeleton arrays (pre-1.0
``DataArrays/mediaPipeSkel_3d_origin_aligned.npy``, v1's ``mediaPipeSkel_3d_body_hands_face.npy``),
4D-Humans' ``pred_keypoints_3d`` and VIBE's ``joints3d`` (OpenPose's 25 joints first), MotionBERT's
``X3D.npy`` (camera axes, the picture's own scale) and Sports2D's 2-D ``.trc``."""
import os

import numpy as np
import pytest

from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core.io_keypoints import is_keypoint_input, read_keypoint_people, read_keypoints
from blender_manikin.core.recording import RecordingError

from fixtures_keypoints import hinge_motion, to_y_up, write_trc


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=120, seed=3)


def camera_axes(points):
    """Blender axes (+Z up) → a camera's: x right, y down, z ahead (the camera looking along +Y)."""
    p = np.asarray(points, np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def _same_shape(got, want):
    np.testing.assert_allclose(got - got[:1, :1], want - want[:1, :1], atol=1e-6)


def test_freemocap_whole_skeleton_arrays_are_read_from_their_body_points(tmp_path, motion):
    # FreeMoCap's body + right hand + left hand + face arrays (543 points before 1.0, 553 in v1,
    # millimetres): "543 points per frame match no keypoint layout"; a pre-1.0 recording folder
    # (DataArrays/) was "not a keypoint file"
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "mediapipe33", body.stature)
    for k in (543, 553):
        whole = np.full((len(clean), k, 3), np.nan)
        whole[:, :33] = to_y_up(clean, 1000.0)
        whole[:, 33:] = 5000.0                  # hands and face: far off, so a wrong slice shows
        path = tmp_path / f"whole{k}.npy"
        np.save(path, whole)
        rec = read_keypoints(path)
        assert rec.layout == "mediapipe33" and rec.metadata["units"] == "mm"
        assert f"the first 33 of the file's {k}, FreeMoCap's whole MediaPipe skeleton" in rec.metadata["detected"]
        _same_shape(rec.points, clean)
    session = tmp_path / "sesh_2022-05-24_16_10_46"
    os.makedirs(session / "DataArrays")
    np.save(session / "DataArrays" / "mediaPipeSkel_3d_origin_aligned.npy", whole[..., [0, 2, 1]] * [1, 1, -1])
    assert is_keypoint_input(session)
    rec = read_keypoints(session)
    assert rec.layout == "mediapipe33" and "FreeMoCap folder" in rec.metadata["detected"]
    _same_shape(rec.points, clean)


@pytest.mark.parametrize("count, extra", [(44, 19), (49, 24)])
def test_smpl_regressors_openpose_joints_first_are_read_as_body25(tmp_path, motion, count, extra):
    # 4D-Humans' pred_keypoints_3d (44: OpenPose's 25 joints, then 19 extra) and VIBE's joints3d
    # (49: 25, then 24), root-relative in camera axes: "44 points per frame match no keypoint layout"
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "body25", body.stature)
    joints = np.concatenate([clean, np.full((len(clean), extra, 3), 3.0)], 1)
    path = tmp_path / f"joints{count}.npy"
    np.save(path, camera_axes(joints - clean[:, 8:9]))
    rec = read_keypoints(path)
    assert rec.layout == "body25" and rec.metadata["up"] == "-Y"
    assert f"the first 25 of the file's {count}" in rec.metadata["detected"]
    _same_shape(rec.points, clean - clean[:, 8:9])
    # the same, two people (PHALP tracks several): people × frames × points × 3
    np.save(tmp_path / "two.npy", np.stack([camera_axes(joints), camera_axes(joints) + [2.0, 0.0, 0.0]]))
    people = read_keypoint_people(tmp_path / "two.npy")
    assert [r.layout for _, r in people] == ["body25", "body25"]


def test_a_scale_that_makes_no_performer_is_said(tmp_path, motion):
    # MotionBERT's X3D.npy: Human3.6M's 17 joints in camera axes, scaled so the clip's 2-D extent
    # spans [-1, 1]: someone walking 3 m across the picture came out a 0.7 m performer "in metres",
    # without a word
    body, pos, world = motion
    h36 = camera_axes(kl.keypoints_from_body22(pos, world, "h36m17", body.stature))
    h36[..., 0] += np.linspace(0.0, 3.0, len(h36))[:, None]
    scale = 2.0 / max(np.ptp(h36[..., 0]), np.ptp(h36[..., 1]))
    np.save(tmp_path / "X3D.npy", h36 * scale)
    rec = read_keypoints(tmp_path / "X3D.npy")
    said = rec.metadata["detected"]
    assert rec.layout == "h36m17" and "units m (leg 0." in said
    assert "m tall; if not, the file's scale is not m" in said and "--height" in said
    np.save(tmp_path / "metres.npy", camera_axes(kl.keypoints_from_body22(pos, world, "h36m17", body.stature)))
    assert "tall" not in read_keypoints(tmp_path / "metres.npy").metadata["detected"]


def test_a_two_dimensional_trc_is_refused(tmp_path, motion):
    # Sports2D writes its .trc from one video: X, Y the picture's pixels / 1000 ("m"), Z 0 on every
    # marker; it was read as a flat body in metres, its facing assumed
    body, pos, world = motion
    path = tmp_path / "run_px_person00.trc"
    write_trc(path, body, pos, world, units="m")
    lines = path.read_text().splitlines()
    for i in range(6, len(lines)):
        cells = lines[i].split("\t")
        cells[4::3] = ["0.0"] * len(cells[4::3])
        lines[i] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"run_px_person00.trc: every point has the same Z \(0.0\): "
                                             r"the points lie in one plane, a 2-D pose"):
        read_keypoints(path)


def _long_rows(points, names, prefix=(), suffix=(), first=0):
    """A long table's rows ``frame, *prefix, name, x, y, z, *suffix`` of ``points`` (frames × K × 3),
    the frames numbered from ``first``."""
    return [",".join([str(first + f), *prefix, n, *(f"{v:.6f}" for v in points[f, k]), *suffix])
            for f in range(len(points)) for k, n in enumerate(names)]


def test_freemocap_long_tables_are_read_as_keypoints(tmp_path, motion):
    # FreeMoCap v1's <recording>_by_frame.csv and v2's files (a row per point per frame: frame,
    # keypoint, x, y, z, with model and trajectory columns) were taken for tracker CSVs: "wrong
    # header: expected the column names 'time,device,px,py,pz,qw,qx,qy,qz'"
    body, pos, world = motion
    mp = kl.keypoints_from_body22(pos, world, "mediapipe33", body.stature)
    coco = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    y_up = to_y_up(mp, 1000.0)
    v1 = ["frame,timestamp,timestamp_by_camera,model,keypoint,x,y,z,reprojection_error"]
    for f in range(len(mp)):               # FreeMoCap v1.8's DataSaver: body, centres of mass, hands, face
        v1 += _long_rows(y_up[f:f + 1], kl.LAYOUTS["mediapipe33"].points, ("", "{}", "mediapipe_body"), ("4.1",),
                         first=f)
        v1 += [f"{f},,{{}},mediapipe_com,full_body,1,2,3,",
               f"{f},,{{}},mediapipe_hand,right_wrist,9,9,9,1.0",     # a hand's point named as the body's
               f"{f},,{{}},mediapipe_face,0000,7,7,7,2.0"]
    (tmp_path / "recording_by_frame.csv").write_text("\n".join(v1) + "\n")
    coco_mm = to_y_up(coco, 1000.0)
    extra = ("left_big_toe", "left_small_toe", "left_heel", "right_big_toe", "right_small_toe", "right_heel",
             "head_center", "neck_center", "trunk_center", "hips_center")
    v2_points = np.concatenate([coco_mm, np.full((len(coco), len(extra), 3), 500.0)], 1)
    names = kl.LAYOUTS["coco17"].points + extra
    (tmp_path / "rtmpose_body_3d_xyz.csv").write_text(
        "\n".join(["frame,keypoint,x,y,z"] + _long_rows(v2_points, names)) + "\n")
    by_frame = ["frame,keypoint,x,y,z,model,trajectory,reprojection_error"]
    by_frame += _long_rows(v2_points, names, (), ("rtmpose.body", "3d_xyz", ""))
    by_frame += _long_rows(v2_points + 40.0 * np.sin(np.arange(len(coco)))[:, None, None], names, (),
                           ("rtmpose.body", "rigid_3d_xyz", ""))
    by_frame += _long_rows(np.full((len(coco), 2, 3), 9.0), ("hand_root", "thumb1"), (), ("rtmpose.left_hand",
                                                                                          "3d_xyz", ""))
    (tmp_path / "freemocap_data_by_frame.csv").write_text("\n".join(by_frame) + "\n")
    for file, layout, clean in (("recording_by_frame.csv", "mediapipe33", mp),
                                ("rtmpose_body_3d_xyz.csv", "coco17", coco),
                                ("freemocap_data_by_frame.csv", "coco17", coco)):
        path = tmp_path / file
        assert is_keypoint_input(path), file
        rec = read_keypoints(path)
        assert rec.layout == layout and rec.metadata["units"] == "mm" and rec.num_frames == len(clean), file
        _same_shape(rec.points, clean)
    # a cell that is not a number: the line named
    lines = (tmp_path / "rtmpose_body_3d_xyz.csv").read_text().splitlines()
    lines[30] = lines[30].rsplit(",", 1)[0] + ",abc"
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"bad.csv, line 31: column 'z': 'abc' is not a number"):
        read_keypoints(tmp_path / "bad.csv")
