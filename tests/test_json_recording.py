"""JSON and JSON Lines recordings (``core/io_json.py``): Unity ``JsonUtility`` objects, WebXR
frames (viewer and input-source matrices), JSON Lines; read as the same take written as a wide
CSV; errors name the line; a folder's other JSON files are not taken for recordings."""
import json
import os

import numpy as np
import pytest

from blender_manikin.core import convert, formats
from blender_manikin.core import rotations as rot
from blender_manikin.core.recording import RecordingError, from_blender

from test_axes_detect import walking_take

DEVICES = ("head", "left_hand", "right_hand")


def _take():
    t, pos, quat = walking_take(4.0)
    return t, pos, quat


def unity_json(path, per_line=False):
    """The take as Unity's JsonUtility writes a list of frames (Unity axes, {x, y, z, w} objects)."""
    t, pos, quat = _take()
    names = {"head": "head", "left_hand": "leftHand", "right_hand": "rightHand"}
    frames = []
    for k in range(len(t)):
        f = {"time": round(float(t[k]), 6)}
        for d, n in names.items():
            p, q = from_blender(pos[d][k], quat[d][k], "unity")
            f[n] = {"position": dict(zip("xyz", map(float, p))),
                    "rotation": dict(zip("xyzw", map(float, q[[1, 2, 3, 0]]))), "isTracked": True}
        frames.append(f)
    with open(path, "w") as fh:
        if per_line:
            fh.write("\n".join(json.dumps(f) for f in frames) + "\n")
        else:
            json.dump({"app": "MyGame", "fps": 72, "frames": frames}, fh, indent=1)
    return path


def webxr_json(path):
    """The take as a WebXR page logs it: ``timestamp`` ms, the viewer's transform (position with
    w = 1, orientation, matrix) and the input sources' grip matrices (column-major), OpenXR axes."""
    t, pos, quat = _take()
    frames = []
    for k in range(len(t)):
        def transform(d, with_parts):
            p, q = from_blender(pos[d][k], quat[d][k], "openxr")
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = rot.quat_to_matrix(q), p
            out = {"matrix": [float(v) for v in m.T.reshape(-1)]}
            if with_parts:
                out["position"] = {**dict(zip("xyz", map(float, p))), "w": 1.0}
                out["orientation"] = dict(zip("xyzw", map(float, q[[1, 2, 3, 0]])))
            return out
        frames.append({"timestamp": 1000.0 * float(t[k]) + 12345.678,
                       "viewer": {"transform": transform("head", True), "emulatedPosition": False},
                       "inputSources": [{"handedness": h, "targetRayMode": "tracked-pointer",
                                         "gripPose": {"transform": transform(f"{h}_hand", False)}}
                                        for h in ("right", "left")]})
    with open(path, "w") as fh:
        json.dump(frames, fh)
    return path


def _check_same_take(rec):
    t, pos, quat = _take()
    for d in DEVICES:
        s = rec.streams[d]
        np.testing.assert_allclose(s.time, t - t[0], atol=2e-6)
        np.testing.assert_allclose(s.pos, pos[d], atol=1e-5)
        err = np.degrees(rot.geodesic_angle(rot.quat_to_matrix(s.quat), rot.quat_to_matrix(quat[d])))
        assert err.max() < 0.01


def test_unity_json_utility_frames(tmp_path):
    rec = formats.load_recording(unity_json(tmp_path / "take.json"))
    line = rec.metadata["detected"]
    assert line.startswith("JSON frames: head=head_*, hands=leftHand_*/rightHand_*; quaternions x,y,z,w; "
                           "time=time in s; units m (head at 1.61 m); axes unity (left-handed"), line
    assert "from the walking direction" in line
    _check_same_take(rec)


def test_webxr_frames_with_matrices_and_input_sources(tmp_path):
    rec = formats.load_recording(webxr_json(tmp_path / "webxr.json"))
    line = rec.metadata["detected"]
    assert "head=viewer_transform_*" in line and "time=timestamp in ms" in line and "axes openxr" in line, line
    _check_same_take(rec)


def test_json_lines(tmp_path):
    path = unity_json(tmp_path / "take.jsonl", per_line=True)
    _check_same_take(formats.load_recording(path))
    lines = open(path).read().splitlines()
    lines[40] = lines[40][:-5]
    open(path, "w").write("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"take.jsonl, line 41: not valid JSON"):
        formats.load_recording(path)


def test_errors_name_the_file_and_line(tmp_path):
    path = unity_json(tmp_path / "take.json")
    text = open(path).read()
    open(tmp_path / "cut.json", "w").write(text[: len(text) // 2])
    with pytest.raises(RecordingError, match=r"cut.json, line \d+: not valid JSON"):
        formats.load_recording(tmp_path / "cut.json")
    open(tmp_path / "mixed.json", "w").write('[{"time": 0, "head": {"position": [0, 1.6, 0]}},\n 5,\n {"time": 1}]')
    with pytest.raises(RecordingError, match=r"mixed.json, line 2: a frame is int 5, not an object"):
        formats.load_recording(tmp_path / "mixed.json")
    open(tmp_path / "scalar.json", "w").write('{"head": 1}')
    with pytest.raises(RecordingError, match=r"scalar.json, line 1: expected a list of frame objects"):
        formats.load_recording(tmp_path / "scalar.json")
    doc = json.load(open(path))
    doc["frames"][7]["head"]["position"]["y"] = "tall"
    json.dump(doc, open(tmp_path / "bad.json", "w"), indent=1)
    starts = [n for n, ln in enumerate(open(tmp_path / "bad.json"), 1) if ln.rstrip() in ("  {", "  {},")]
    with pytest.raises(RecordingError, match=rf"bad.json, line {starts[7]}: 'tall' is not a number"):
        formats.load_recording(tmp_path / "bad.json")       # the line the 8th frame starts on


def test_a_layout_file_fixes_a_json_take(tmp_path):
    from blender_manikin.core.io_wide_csv import save_layout
    path = unity_json(tmp_path / "take.json")
    rec = formats.load_recording(path)
    layout = dict(rec.metadata["layout"], axes="unity")
    save_layout(tmp_path / "layout.json", layout)
    again = formats.load_recording(path, layout=str(tmp_path / "layout.json"))
    assert again.metadata["detected"].startswith("layout file: ")
    _check_same_take(again)


def test_a_folder_gives_only_its_recordings(tmp_path):
    """Layout, offsets and bone-map files, a manifest and this add-on's own JSON output lie beside
    the recordings; only the recordings are inputs."""
    from blender_manikin import cli
    from blender_manikin.core.io_wide_csv import save_layout
    take = unity_json(tmp_path / "take.json")
    lines = unity_json(tmp_path / "lines.jsonl", per_line=True)
    save_layout(tmp_path / "layout.json", formats.load_recording(take).metadata["layout"])
    from blender_manikin.core.device_offsets import get_preset, save_offsets
    save_offsets(tmp_path / "offsets.json", get_preset("quest_touch"))
    open(tmp_path / "manifest.jsonl", "w").write(json.dumps({"path": "take.json", "status": "ok"}) + "\n")
    assert cli.main(["solve", str(take), "--out", str(tmp_path / "out"), "--format", "json"]) == 0
    out = tmp_path / "out" / "take.json"
    os.replace(out, tmp_path / "take_solved.json")
    want = sorted([str(take), str(lines)])
    assert sorted(convert.collect_inputs([str(tmp_path)])) == want
    assert sorted(cli.expand_inputs([str(tmp_path)])) == want
    assert convert.collect_inputs([str(tmp_path / "manifest.jsonl")]) == [str(take)]


def test_a_matrix_that_is_not_a_rigid_transform_is_a_lost_sample():
    from blender_manikin.core.io_json import flatten
    for bad in ([float("nan")] * 16, [1e308] * 16, [0.0] * 16):
        flat = flatten({"viewer": {"transform": {"matrix": bad}}})
        assert len(flat) == 7 and all(np.isnan(v) for v in flat.values())
    eye = flatten({"viewer": {"transform": {"matrix": list(np.eye(4).reshape(-1))}}})
    assert eye["viewer_transform_rotation_w"] == 1.0 and eye["viewer_transform_position_y"] == 0.0


def test_a_first_row_without_a_time_does_not_lose_every_time(tmp_path):
    """A JSON Lines log that opens with a session line (``{"app": ..., "fps": 72}``), or a wide CSV
    whose first row's time cell is empty: the times count from the first row that has one.
    Counting from the missing one made every time NaN ("head has no usable samples")."""
    path = unity_json(tmp_path / "take.jsonl", per_line=True)
    text = open(path).read()
    open(path, "w").write(json.dumps({"app": "MyGame", "fps": 72, "device": "Quest 3"}) + "\n" + text)
    rec = formats.load_recording(path)
    t, pos, _ = _take()
    for d in DEVICES:
        s = rec.streams[d]
        assert s.usable.sum() == len(t)
        np.testing.assert_allclose(s.time[s.usable], t - t[0], atol=2e-6)
        np.testing.assert_allclose(s.pos[s.usable], pos[d], atol=1e-5)
    from fixtures_recordings import write_wide_poses
    _, _, quat = _take()
    names = {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}
    csv = write_wide_poses(tmp_path / "take.csv", t + 5.0, pos, quat, names, "unity")
    lines = open(csv).read().splitlines()
    lines[1] = "," + lines[1].split(",", 1)[1]
    open(csv, "w").write("\n".join(lines) + "\n")
    rec = formats.load_recording(csv)
    assert np.isnan(rec.streams["head"].time[0])
    np.testing.assert_allclose(rec.streams["head"].time[1:], t[1:] - t[1], atol=2e-6)
    from blender_manikin.core.resample import resample
    times = resample(rec, 30.0, floor=None, check_units=False)[0]
    assert times[-1] - times[0] == pytest.approx(t[-1] - t[1], abs=0.04)


def raw_webxr_json(path, typed_arrays=False, lost=()):
    """The take as a page logs raw WebXR: ``frame.getViewerPose(ref)`` and, per input source,
    ``frame.getPose(source.gripSpace, ref)`` and ``frame.getPose(source.targetRaySpace, ref)``
    under the spec's own names (``gripSpace``, ``targetRaySpace``), a gaze source with
    ``handedness: "none"``, the left controller lost on the frames ``lost``; with
    ``typed_arrays`` the matrices are ``Float32Array``s as ``JSON.stringify`` writes them
    (``{"0": .., "15": ..}``)."""
    t, pos, quat = _take()
    ray = np.eye(4)                                   # the pointing ray: tilted and ahead of the grip
    ray[:3, :3] = rot.quat_to_matrix(rot.axis_angle_to_quat(np.radians(-30.0) * np.array([1.0, 0.0, 0.0])))
    ray[:3, 3] = [0.0, 0.05, -0.08]

    def matrix(d, k, off=np.eye(4)):
        p, q = from_blender(pos[d][k], quat[d][k], "openxr")
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = rot.quat_to_matrix(q), p
        flat = [float(v) for v in (m @ off).T.reshape(-1)]
        return {"matrix": {str(i): v for i, v in enumerate(flat)} if typed_arrays else flat}
    frames = []
    for k in range(len(t)):
        sources = [{"handedness": "none", "targetRayMode": "gaze", "targetRaySpace": {"transform": matrix("head", k)}}]
        for h in ("left", "right"):
            if h == "left" and k in lost:
                continue
            sources.append({"handedness": h, "targetRayMode": "tracked-pointer",
                            "targetRaySpace": {"transform": matrix(f"{h}_hand", k, ray)},
                            "gripSpace": {"transform": matrix(f"{h}_hand", k)}})
        frames.append({"timestamp": 1000.0 * float(t[k]) + 81234.5,
                       "viewerPose": {"transform": matrix("head", k), "emulatedPosition": False},
                       "inputSources": sources})
    with open(path, "w") as fh:
        json.dump(frames, fh)
    return path


@pytest.mark.parametrize("typed_arrays", [False, True])
def test_raw_webxr_grip_space_and_typed_arrays(tmp_path, typed_arrays):
    """The spec's names: the hands are the ``gripSpace`` poses (not the ``targetRaySpace`` rays,
    not the gaze source); a ``Float32Array`` matrix stringified as an object of indices is the
    same matrix.  Before: "no columns for left_hand, right_hand" (``gripSpace`` was not a hand's
    name) and, with typed arrays, "no columns for head, left_hand, right_hand"."""
    rec = formats.load_recording(raw_webxr_json(tmp_path / "webxr.json", typed_arrays))
    line = rec.metadata["detected"]
    assert "hands=left_hand_gripSpace_transform_*/right_hand_gripSpace_transform_*" in line, line
    assert "time=timestamp in ms" in line and "axes openxr" in line, line
    _check_same_take(rec)


def test_raw_webxr_a_lost_controller_is_missing_on_its_frames(tmp_path):
    lost = set(range(40, 60)) | set(range(5))
    rec = formats.load_recording(raw_webxr_json(tmp_path / "webxr.json", lost=lost))
    t, pos, quat = _take()
    s = rec.streams["left_hand"]
    assert np.flatnonzero(~s.usable).tolist() == sorted(lost)
    np.testing.assert_allclose(s.pos[s.usable], pos["left_hand"][s.usable], atol=1e-5)
    np.testing.assert_allclose(s.time, t - t[0], atol=2e-6)
    assert rec.streams["right_hand"].usable.all() and rec.streams["head"].usable.all()


def test_nanosecond_timestamps(tmp_path):
    """A Quest / OpenXR dump's ``timestampNs`` (``XrTime``, ns): read in ns, and the file is taken
    for a recording in a folder.  Before: "no time column"."""
    from blender_manikin.core.io_json import looks_like_recording
    t, pos, quat = _take()
    frames = []
    for k in range(len(t)):
        f = {"timestampNs": int(round(1e9 * t[k])) + 1234567890123456}
        for d, n in (("head", "centerEyePose"), ("left_hand", "leftControllerPose"),
                     ("right_hand", "rightControllerPose")):
            p, q = from_blender(pos[d][k], quat[d][k], "openxr")
            f[n] = {"position": dict(zip("xyz", map(float, p))),
                    "orientation": dict(zip("xyzw", map(float, q[[1, 2, 3, 0]])))}
        frames.append(f)
    path = tmp_path / "quest.json"
    path.write_text(json.dumps(frames))
    assert looks_like_recording(path.read_text()[:4096])
    rec = formats.load_recording(path)
    assert "time=timestampNs in ns" in rec.metadata["detected"], rec.metadata["detected"]
    _check_same_take(rec)


def test_raw_webxr_with_only_pointing_rays_says_to_log_the_grip(tmp_path):
    """A page that logged only ``targetRaySpace`` (the pointing ray, ahead of and tilted from the
    hand) has no hands: refused, and the message says which pose to log instead."""
    path = raw_webxr_json(tmp_path / "webxr.json")
    frames = json.loads(path.read_text())
    for f in frames:
        for src in f["inputSources"]:
            src.pop("gripSpace", None)
    path.write_text(json.dumps(frames))
    with pytest.raises(RecordingError, match=r"no columns for left_hand, right_hand .*targetRaySpace is its "
                                             r"pointing ray, not the hand: log frame.getPose\(source.gripSpace"):
        formats.load_recording(path)
