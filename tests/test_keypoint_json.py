"""3D keypoints written as JSON by markerless tools, each in its writer's own layout (read from
their code): EasyMocap's ``keypoints3d/000000.json`` (``write_keypoints3d``: ``[{"id", "keypoints3d":
[[x, y, z, c] * 25]}]``, metres, world axes, ``'%2.3f'``), OpenPose's 3-D reconstruction
``*_keypoints.json`` (``people[].pose_keypoints_3d``: flat x, y, z, c with c 1 or 0, camera axes,
millimetres), MMPose's ``body3d_pose_lifter_demo.py --save-predictions`` results
(``{"meta_info", "instance_info": [{"frame_id", "instances": [{"keypoints", "keypoint_scores"}]}]}``,
Human3.6M-17 turned ``-k[..., [0, 2, 1]]`` and rebased to z 0) and MediaPipe world-landmark dumps
(``[[{"x", "y", "z", "visibility"} * 33], ...]``, metres, hip-centred, Y down)."""
import json
import os
import re

import numpy as np
import pytest

from blender_manikin import cli
from blender_manikin.core import formats
from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import skeleton as sk
from blender_manikin.core.io_keypoints import is_keypoint_input, read_keypoint_people, read_keypoints
from blender_manikin.core.recording import RecordingError
from blender_manikin.core.solve import SolveSettings, solve_recording

from fixtures_keypoints import hinge_motion


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=90, seed=7)


def camera_axes(points):
    """Blender axes (+Z up) → a camera's: x right, y down, z ahead (the camera looking along +Y)."""
    p = np.asarray(points, np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def _rel(p, k=0):
    return p - p[:, k:k + 1]


def _solve_close(path, pos, body, settings=None, tol=0.015):
    """The solve of ``path``: joints (relative to the pelvis) within ``tol`` of the motion's, its stature right."""
    out = solve_recording(str(path), settings or SolveSettings(fps=30.0))
    P = out.result.positions
    for j in ("left_wrist", "right_knee", "left_ankle", "head"):
        err = np.linalg.norm((P[:, sk.J[j]] - P[:, 0]) - (pos[:, sk.J[j]] - pos[:, 0]), axis=-1)
        assert np.median(err) < tol, (j, np.median(err))
    assert abs(out.body.stature - body.stature) < 0.05, out.body.stature
    # upright: the head above the pelvis above the ankles
    assert np.median(P[:, sk.J["head"], 2] - P[:, 0, 2]) > 0.4
    return out


def write_easymocap(folder, people, fmt="%2.3f"):
    """EasyMocap's ``write_keypoints3d``: one ``{frame:06d}.json`` a frame; ``people`` ``{id: (T, 25, 4)}``
    (NaN frames: the person not in that frame).  The text as ``write_common_results`` lays it out
    (``myarray2string``'s rows joined by ``\\r\\n``)."""
    os.makedirs(folder, exist_ok=True)
    T = len(next(iter(people.values())))
    for f in range(T):
        here = [(pid, a[f]) for pid, a in people.items() if np.isfinite(a[f]).all()]
        out = ["[\n"]
        for n, (pid, k) in enumerate(here):
            rows = ["["] + ["          [" + ", ".join(fmt % v for v in r) + "]" + (", " if i < len(k) - 1 else "")
                            for i, r in enumerate(k)] + ["        ]"]
            out.append("    {\n")
            out.append(f'        "id": {pid},\n')
            out.append('        "keypoints3d": ' + "\r\n".join(rows) + "\n")
            out.append("    }" + (",\n" if n < len(here) - 1 else "\n"))
        out.append("]\n")
        with open(os.path.join(folder, f"{f:06d}.json"), "w", newline="") as fh:
            fh.write("".join(out))


def write_openpose_3d(folder, points, lost=None, name="clip"):
    """OpenPose's ``--3d --write_json``: ``{name}_{frame:012d}_keypoints.json`` a frame, ``people[0]``'s
    ``pose_keypoints_3d`` flat x, y, z, c (c 0 and zeros where the reconstruction failed)."""
    os.makedirs(folder, exist_ok=True)
    for f, k in enumerate(points):
        flat = []
        for i, p in enumerate(k):
            ok = lost is None or not lost[f, i]
            flat += [float(v) for v in p] + [1.0] if ok else [0.0, 0.0, 0.0, 0.0]
        person = {"person_id": [-1], "pose_keypoints_2d": [0.0] * 75, "face_keypoints_2d": [],
                  "hand_left_keypoints_2d": [], "hand_right_keypoints_2d": [], "pose_keypoints_3d": flat,
                  "face_keypoints_3d": [], "hand_left_keypoints_3d": [], "hand_right_keypoints_3d": []}
        with open(os.path.join(folder, f"{name}_{f:012d}_keypoints.json"), "w") as fh:
            json.dump({"version": 1.3, "people": [person]}, fh)


def mmpose_lifted(h36m_blender):
    """MMPose's lifter output as its demo saves it: camera axes, root-relative, then ``-k[..., [0, 2, 1]]``
    and each frame's lowest point moved to z 0."""
    cam = camera_axes(_rel(h36m_blender))
    k = -cam[..., [0, 2, 1]]
    k[..., 2] -= k[..., 2].min(axis=-1, keepdims=True)
    return k


def write_mmpose(path, frames_people, dataset="h36m", names=None, scores=None):
    """MMPose's ``--save-predictions`` file: ``frames_people`` a list of frames, each a list of
    ``(K, 3)`` instances (``scores`` ``(K,)`` each one's ``keypoint_scores``, default 0.9); frame ids
    from 1 (the video demo counts before it processes)."""
    meta = {"dataset_name": dataset, "num_keypoints": len(frames_people[0][0]),
            "keypoint_id2name": {str(i): n for i, n in enumerate(names or [])}}
    info = [{"frame_id": f + 1, "instances": [{"keypoints": k.tolist(),
                                               "keypoint_scores": [0.9] * len(k) if scores is None else list(scores),
                                               "bbox": [[0.0, 0.0, 10.0, 10.0]], "bbox_score": 1.0}
                                              for k in people]}
            for f, people in enumerate(frames_people)]
    with open(path, "w") as fh:
        json.dump({"meta_info": meta, "instance_info": info}, fh, indent="\t")


# --------------------------------------------------------------------------
def test_easymocap_keypoints3d_folder_one_and_two_people(tmp_path, motion):
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "body25", body.stature)       # metres, +Z up (a floor chessboard)
    conf = np.full(clean.shape[:2] + (1,), 0.85)
    out = tmp_path / "output"
    write_easymocap(out / "keypoints3d", {0: np.concatenate([clean + [0.4, -0.2, 0.0], conf], -1)})
    for given in (out, out / "keypoints3d"):
        assert is_keypoint_input(given)
        assert cli.expand_inputs([str(given)]) == [str(given)]          # the folder is one input
    rec = read_keypoints(out)
    assert rec.layout == "body25" and rec.metadata["units"] == "m" and rec.metadata["up"] == "+Z"
    assert "90 EasyMocap JSON files" in rec.metadata["detected"]
    np.testing.assert_allclose(_rel(rec.points, 8), _rel(clean, 8), atol=1.5e-3)   # '%2.3f': 1 mm
    _solve_close(out, pos, body)

    # two people (EasyMocap's ids 0 and 2); the second enters at frame 30
    other = clean + [1.5, 0.5, 0.0]
    other[:30] = np.nan
    two = tmp_path / "two" / "keypoints3d"
    write_easymocap(two, {0: np.concatenate([clean, conf], -1), 2: np.concatenate([other, conf], -1)})
    people = read_keypoint_people(two)
    assert [lab for lab, _ in people] == ["0", "2"]
    assert people[1][1].num_frames == 60 and people[1][1].time[0] == pytest.approx(1.0)
    np.testing.assert_allclose(_rel(people[1][1].points, 8), _rel(other[30:], 8), atol=1.5e-3)
    with pytest.raises(RecordingError, match=r"2 people in the file \(0, 2\)"):
        read_keypoints(two)

    # --body bodyhand / bodyhandface (EasyMocap's config: body25, then the hands, then 51 face points)
    for count in (67, 118):
        extra = np.concatenate([np.full(clean.shape[:1] + (count - 25, 3), 9.0), conf[:, :1].repeat(count - 25, 1)], -1)
        write_easymocap(tmp_path / f"b{count}" / "keypoints3d", {0: np.concatenate([np.concatenate([clean, conf], -1),
                                                                                    extra], 1)})
        rec = read_keypoints(tmp_path / f"b{count}")
        assert rec.layout == "body25" and f"the first 25 of the file's {count}, EasyMocap's" in rec.metadata["detected"]
        np.testing.assert_allclose(_rel(rec.points, 8), _rel(clean, 8), atol=1.5e-3)


def test_openpose_3d_json_folder_in_camera_millimetres(tmp_path, motion):
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "body25", body.stature)
    lost = np.zeros(clean.shape[:2], bool)
    lost[10:14, kl.LAYOUTS["body25"].index("left_wrist")] = True          # not reconstructed: 0, 0, 0, c 0
    folder = tmp_path / "op3d"
    write_openpose_3d(folder, camera_axes(clean + [0.0, 3.0, 0.0]) * 1000.0, lost)
    assert is_keypoint_input(folder)
    rec = read_keypoints(folder)
    assert rec.layout == "body25" and rec.metadata["units"] == "mm" and rec.metadata["up"] == "-Y"
    wrist = kl.LAYOUTS["body25"].index("left_wrist")
    assert np.isnan(rec.points[10:14, wrist]).all() and np.isfinite(rec.points[14:, wrist]).all()
    _solve_close(folder, pos, body)


def test_mmpose_results_json_h36m_and_wholebody(tmp_path, motion):
    body, pos, world = motion
    h36m = kl.keypoints_from_body22(pos, world, "h36m17", body.stature)
    path = tmp_path / "results_clip.json"
    write_mmpose(path, [[k] for k in mmpose_lifted(h36m)])
    assert is_keypoint_input(path) and formats.is_recording_file(path)
    assert formats.reader_for(path).name == "keypoints_json"
    with pytest.raises(RecordingError, match="not a tracker recording: solve it as keypoints"):
        formats.load_recording(path)
    rec = read_keypoints(path)
    assert rec.layout == "h36m17" and "from the file" in rec.metadata["detected"]
    assert "MMPose results (h36m)" in rec.metadata["detected"] and rec.metadata["up"] == "+Z"
    # -k[..., [0, 2, 1]] of camera axes is Blender's turned half round the vertical: the performer faces +Y
    half = np.array([-1.0, -1.0, 1.0])
    np.testing.assert_allclose(_rel(rec.points), _rel(h36m * half), atol=1e-6)
    _solve_close(path, pos * half, body, tol=0.03)

    # COCO-WholeBody (133 points: COCO's 17 first), camera axes, two people a frame; the feet, face and
    # hands scored below the threshold (unseen), the body above it: the people are still seen
    coco = camera_axes(kl.keypoints_from_body22(pos, world, "coco17", body.stature))
    whole = np.concatenate([coco, np.full((len(coco), 116, 3), 50.0)], 1)
    wb = tmp_path / "wholebody.json"
    write_mmpose(wb, [[k, k + [1.5, 0.0, 0.5]] for k in whole], dataset="coco_wholebody",
                 scores=[0.9] * 17 + [0.1] * 116)
    people = read_keypoint_people(wb)
    assert [lab for lab, _ in people] == ["0", "1"]
    rec = people[0][1]
    assert rec.layout == "coco17" and "the first 17 of the file's 133" in rec.metadata["detected"]
    np.testing.assert_allclose(_rel(rec.points), _rel(kl.keypoints_from_body22(pos, world, "coco17", body.stature)),
                               atol=1e-6)


def test_mediapipe_world_landmark_lists(tmp_path, motion):
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "mediapipe33", body.stature)
    lay = kl.LAYOUTS["mediapipe33"]
    hips = (clean[:, lay.index("left_hip")] + clean[:, lay.index("right_hip")]) / 2
    cam = camera_axes(clean - hips[:, None])             # metres, hip-centred, Y down
    frames = [[{"x": float(x), "y": float(y), "z": float(z), "visibility": 0.99} for x, y, z in k] for k in cam]
    path = tmp_path / "pose_world_landmarks.json"
    path.write_text(json.dumps(frames))
    assert is_keypoint_input(path)
    rec = read_keypoints(path)
    assert rec.layout == "mediapipe33" and rec.metadata["units"] == "m" and rec.metadata["up"] == "-Y"
    _solve_close(path, pos, body)


def test_keypoint_json_errors_name_the_file_line_and_problem(tmp_path, motion):
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos[:6], world[:6], "body25", body.stature)
    conf = np.ones(clean.shape[:2] + (1,))
    # EasyMocap: a frame's rows of 2 numbers
    folder = tmp_path / "ez" / "keypoints3d"
    write_easymocap(folder, {0: np.concatenate([clean, conf], -1)})
    text = (folder / "000003.json").read_text()
    (folder / "000003.json").write_text(re.sub(r"\[([-\d.]+), ([-\d.]+), [-\d.]+, [-\d.]+\]", r"[\1, \2]", text))
    with pytest.raises(RecordingError, match=r"000003.json, line 4: \[0\].keypoints3d \(person 0\): shape \(25, 2\): "
                                             r"\[x, y\] a point, a 2-D pose"):
        read_keypoints(folder)
    text = (folder / "000003.json").read_text()
    (folder / "000003.json").write_text(re.sub(r"\[([-\d.]+), ([-\d.]+)\]", r"[\1, \2, 0.0, 0.0, 1.0]", text))
    with pytest.raises(RecordingError, match=r"000003.json, line 4: \[0\].keypoints3d \(person 0\): shape \(25, 5\): "
                                             r"expected \[x, y, z\] or \[x, y, z, confidence\] for each point"):
        read_keypoints(folder)
    # OpenPose: 99 numbers, not 4 a point
    op = tmp_path / "op"
    write_openpose_3d(op, clean * 1000.0)
    doc = json.loads((op / "clip_000000000002_keypoints.json").read_text())
    doc["people"][0]["pose_keypoints_3d"] = doc["people"][0]["pose_keypoints_3d"][:99]
    (op / "clip_000000000002_keypoints.json").write_text(json.dumps(doc, indent=1))
    with pytest.raises(RecordingError, match=r"clip_000000000002_keypoints.json, line \d+: people\[0\]."
                                             r"pose_keypoints_3d: 99 numbers: expected x, y, z, confidence"):
        read_keypoints(op)
    # MMPose: scores for fewer points than the keypoints
    mm = tmp_path / "mm.json"
    write_mmpose(mm, [[k[:17]] for k in clean])
    doc = json.loads(mm.read_text())
    doc["instance_info"][4]["instances"][0]["keypoint_scores"] = [0.9] * 16
    mm.write_text(json.dumps(doc, indent="\t"))
    line = [n for n, ln in enumerate(mm.read_text().splitlines(), 1) if '"keypoint_scores"' in ln][4]   # frame 4's
    with pytest.raises(RecordingError, match=rf"mm.json, line {line}: frame 4, instance 0: 16 keypoint_scores "
                                             "for 17 keypoints"):
        read_keypoints(mm)
    # one frame's file given alone
    with pytest.raises(RecordingError, match=r"000000.json: 1 frame: .* give its folder"):
        read_keypoints(folder / "000000.json")
    # a frame whose person has another point count
    write_openpose_3d(op, clean * 1000.0)
    doc = json.loads((op / "clip_000000000004_keypoints.json").read_text())
    doc["people"][0]["pose_keypoints_3d"] = doc["people"][0]["pose_keypoints_3d"][:72]
    (op / "clip_000000000004_keypoints.json").write_text(json.dumps(doc))
    with pytest.raises(RecordingError, match=r"clip_000000000004_keypoints.json: frame 4: person 0 has 18 "
                                             r"points, frame 0 25"):
        read_keypoints(op)
    # OpenPose without --3d: no 3-D keypoints in any frame
    two_d = tmp_path / "op2d"
    write_openpose_3d(two_d, clean * 1000.0)
    for f in os.listdir(two_d):
        doc = json.loads((two_d / f).read_text())
        doc["people"][0]["pose_keypoints_3d"] = []
        (two_d / f).write_text(json.dumps(doc))
    with pytest.raises(RecordingError, match=r"op2d: no person with 3D keypoints in any of its 6 frame"):
        read_keypoints(two_d)


def test_convert_and_solve_take_a_folder_of_frames_as_one_input(tmp_path, motion):
    from blender_manikin.core import convert
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "body25", body.stature)
    d = tmp_path / "in"
    write_easymocap(d / "em" / "keypoints3d", {0: np.concatenate([clean, np.ones(clean.shape[:2] + (1,))], -1)})
    h36m = kl.keypoints_from_body22(pos, world, "h36m17", body.stature)
    write_mmpose(d / "results_clip.json", [[k] for k in mmpose_lifted(h36m)])
    (d / "layout.json").write_text('{"layout": "coco17", "columns": {}}')       # not a recording
    assert convert.collect_inputs([str(d)]) == [str(d / "em"), str(d / "results_clip.json")]
    assert cli.expand_inputs([str(d)]) == [str(d / "results_clip.json")]       # sub-folders are not searched
    pytest.importorskip("distributed")     # convert's workers (requirements-train.txt; not in the bpy 4.2 venv)
    out = tmp_path / "out"
    code, recs = convert.run(convert.collect_inputs([str(d)]), str(out), ["json"], SolveSettings(fps=30.0),
                             workers=1, progress=False, log=lambda m: None)
    assert code == 0, [r["error"] for r in recs]
    assert sorted(n for n in os.listdir(out) if n.endswith(".json") and not n.startswith(".")) == [
        "em.json", "results_clip.json"]
    assert len(json.loads((out / "em.json").read_text())["positions"]) == 90


def test_a_tracker_json_with_a_meta_info_key_is_still_a_tracker_recording(tmp_path):
    """A tracker JSON whose first key is ``meta_info`` (as MMPose's results file has) has a head
    device and times: formats.reader_for gives it the tracker JSON reader, and the solve's choice
    (is_keypoint_input) agrees; it took it for keypoints ('not a keypoint frame') though it read before."""
    frames = [{"time": k / 90.0, "head": {"position": [0.1 * np.sin(k / 9.0), 1.6, 0.0], "rotation": [0, 0, 0, 1]},
               "leftHand": {"position": [-0.3, 1.0, 0.2], "rotation": [0, 0, 0, 1]},
               "rightHand": {"position": [0.3, 1.0, 0.2], "rotation": [0, 0, 0, 1]}} for k in range(300)]
    path = tmp_path / "take.json"
    path.write_text(json.dumps({"meta_info": {"app": "MyRecorder", "version": 2}, "frames": frames}))
    assert formats.reader_for(path).name == "json"
    assert not is_keypoint_input(path)
    assert len(formats.reader_for(path).read(path).streams) == 3


def test_a_tracker_take_beside_a_keypoints3d_folder_is_still_an_input(tmp_path, capsys):
    """An EasyMocap output folder (holding keypoints3d/) is one input; a tracker take in that
    folder is an input of its own, to convert's search and to solve's folder (both dropped it)."""
    from blender_manikin.core import convert
    (tmp_path / "keypoints3d").mkdir()
    for k in range(3):
        (tmp_path / "keypoints3d" / f"{k:06d}.json").write_text(
            json.dumps([{"id": 0, "keypoints3d": [[0.1 * j, 0.0, 1.0, 1.0] for j in range(25)]}]))
    take = tmp_path / "take.csv"
    take.write_text("time,device,x,y,z,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n")
    assert convert.collect_inputs([str(tmp_path)]) == [str(tmp_path), str(take)]
    assert convert.collect_inputs([str(tmp_path / "keypoints3d")]) == [str(tmp_path / "keypoints3d")]
    assert cli.expand_inputs([str(tmp_path)]) == [str(tmp_path), str(take)]
    assert cli.expand_inputs([str(tmp_path / "keypoints3d")]) == [str(tmp_path / "keypoints3d")]
    assert "not searched" not in capsys.readouterr().err      # keypoints3d/ is read, as the folder's input


def test_solve_of_an_easymocap_output_folder_names_only_sub_folders_with_takes(tmp_path, capsys):
    """`solve` on an EasyMocap output folder does not list its keypoints2d/, smpl/, ... (per-frame
    JSON that are no takes) as sub-folders not searched; a sub-folder with a take still is."""
    (tmp_path / "keypoints3d").mkdir()
    for sub in ("keypoints2d", "smpl"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "000000.json").write_text(json.dumps([{"id": 0, "Rh": [[0.0, 0.0, 0.0]]}]))
    for k in range(3):
        (tmp_path / "keypoints3d" / f"{k:06d}.json").write_text(
            json.dumps([{"id": 0, "keypoints3d": [[0.1 * j, 0.0, 1.0, 1.0] for j in range(25)]}]))
    assert cli.expand_inputs([str(tmp_path)]) == [str(tmp_path)]
    assert "not searched" not in capsys.readouterr().err
    (tmp_path / "tracked").mkdir()
    (tmp_path / "tracked" / "take.csv").write_text("time,device,x,y,z,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n")
    assert cli.expand_inputs([str(tmp_path)]) == [str(tmp_path)]
    err = capsys.readouterr().err
    assert "1 sub-folder(s) not searched (tracked)" in err, err
