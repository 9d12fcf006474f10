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
