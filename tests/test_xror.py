"""XROR reader (core/io_xror.py): synthetic files made here, the real sample against its BSOR."""
import os

import numpy as np
import pytest

bson = pytest.importorskip("bson")
fpzip = pytest.importorskip("fpzip")

from blender_manikin.core import formats  # noqa: E402
from blender_manikin.core.recording import RecordingError, to_blender  # noqa: E402
from fixtures_recordings import XROR_POSE_AXES as AXES, xror_bytes  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VR = os.path.join(os.path.dirname(ROOT), "shared", "data", "vr")


def _xror(n=120, devices=("HEAD", "HAND_LEFT", "HAND_RIGHT"), app="Some App", axes=None, width=None, seed=0,
          names=None, software=None):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 90.0
    pose = np.zeros((n, len(devices), 7))
    pose[..., :3] = rng.normal(size=(n, len(devices), 3)) * 0.1 + [0, 1.5, 0]
    q = rng.normal(size=(n, len(devices), 4))
    pose[..., 3:] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return xror_bytes(t, pose, devices, app=app, axes=axes, width=width, names=names, software=software), t, pose


def test_synthetic_xror_reads_in_blender_axes(tmp_path):
    data, t, pose = _xror()
    path = tmp_path / "take.xror"
    path.write_bytes(data)
    rec = formats.load_recording(path)
    assert set(rec.devices) == {"head", "left_hand", "right_hand"} and rec.metadata["format"] == "xror"
    assert "offsets" not in rec.metadata
    for j, dev in enumerate(("head", "left_hand", "right_hand")):
        s = rec.streams[dev]
        quat = np.concatenate([pose[:, j, 6:7], pose[:, j, 3:6]], -1)
        p_b, q_b = to_blender(pose[:, j, :3], quat, "unity")
        assert np.allclose(s.time, t, atol=1e-6) and np.allclose(s.pos, p_b, atol=1e-6)
        assert np.allclose(np.abs((s.quat * q_b).sum(-1)), 1.0, atol=1e-5)
    beat, _, _ = _xror(app="Beat Saber")
    (tmp_path / "bs.xror").write_bytes(beat)
    assert formats.load_recording(tmp_path / "bs.xror").metadata["offsets"] == "beat_saber"


def test_auto_offsets_of_an_xror_take_by_its_app(tmp_path):
    """--offsets auto: a Beat Saber session gets the saber preset; any other app's take is a
    headset and controllers, so the generic OpenXR preset (view pose for the head, grip poses for
    the hands), never "none", which would take the headset's pose for the head joint."""
    from blender_manikin.core import solve as cs
    for app, want in (("Beat Saber", "beat_saber"), ("Some Other Game", "openxr_generic"), ("", "openxr_generic")):
        data, _, _ = _xror(app=app)
        path = tmp_path / f"take_{want}_{len(app)}.xror"
        path.write_bytes(data)
        rec = formats.load_recording(path)
        assert cs.resolve_offsets("auto", rec) == want, app
        assert cs.resolve_offsets("none", rec) == "none"           # what the user sets is kept
    assert formats.default_offsets("x.xror") == "openxr_generic" and formats.default_offsets("x.csv") == "none"


_QUEST = {"runtime": "oculus", "api": "Oculus", "app_version": "1.29.1_123"}   # a Quest BSOR's, converted


@pytest.mark.parametrize("names,software,want", [
    (("VIVE Pro 2", "OpenVR Controller(Knuckles Left) - Left", "OpenVR Controller(Knuckles Right) - Right"), None,
     "beat_saber"),
    (("Oculus Quest2", "Oculus Touch Controller - Left", "Oculus Touch Controller - Right"), None, "beat_saber_touch"),
    (("Meta Quest 3", "Left Controller", "Right Controller"), None, "beat_saber_touch"),
    (("Oculus Quest2", "Oculus Touch Controller - Left", "Oculus Touch Controller - Right"), _QUEST,
     "beat_saber_oculus"),
    (("Meta Quest 3", "Left Controller", "Right Controller"), dict(_QUEST, app_version="1.37.0_9"),
     "beat_saber_xr_touch"),
])
def test_a_beat_saber_session_gets_the_preset_of_its_controllers_runtime_and_version(tmp_path, names, software,
                                                                                     want):
    data, _, _ = _xror(app="Beat Saber", names=names, software=software)
    (tmp_path / "bs.xror").write_bytes(data)
    assert formats.load_recording(tmp_path / "bs.xror").metadata["offsets"] == want


def test_devices_the_solve_does_not_use_are_left_out(tmp_path):
    """An elbow tracker and an eye-gaze direction (3 numbers a frame) between the head and hands:
    their numbers are skipped, the head and hands read as they are, each left-out device named."""
    n = 60
    rng = np.random.default_rng(3)
    t = np.arange(n) / 90.0
    pose = np.zeros((n, 3, 7))
    pose[..., :3] = rng.normal(size=(n, 3, 3)) * 0.1 + [0, 1.5, 0]
    q = rng.normal(size=(n, 3, 4))
    pose[..., 3:] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    elbow = rng.normal(size=(n, 7))
    gaze = rng.normal(size=(n, 3))
    rows = np.concatenate([t[:, None], pose[:, 0], elbow, gaze, pose[:, 1], pose[:, 2]], 1).astype(np.float32)
    devs = [("HEAD", AXES), ("ELBOW_LEFT", AXES), ("EYES", ["x", "y", "z"]), ("HAND_LEFT", AXES),
            ("HAND_RIGHT", AXES)]
    doc = {"$schema": "x", "info": {"hardware": {"devices": [{"name": j, "joint": j, "axes": a} for j, a in devs]},
                                    "software": {"app": {"name": "Some App"}}},
           "frames": fpzip.compress(np.ascontiguousarray(rows[None, None])), "events": []}
    path = tmp_path / "extra.xror"
    path.write_bytes(bson.encode(doc))
    rec = formats.load_recording(path)
    assert rec.devices == ("head", "left_hand", "right_hand")
    for j, dev in enumerate(("head", "left_hand", "right_hand")):
        quat = np.concatenate([pose[:, j, 6:7], pose[:, j, 3:6]], -1)
        p_b, _ = to_blender(pose[:, j, :3], quat, "unity")
        assert np.allclose(rec.streams[dev].pos, p_b, atol=1e-6), dev
    assert any("devices[1] (joint 'ELBOW_LEFT': not one the solve uses) left out" in w for w in rec.warnings)
    assert any("devices[2] (EYES" in w or "devices[2] (joint 'EYES'" in w for w in rec.warnings)


@pytest.mark.parametrize("hand_type,want", [("HAND", "openxr_hand_tracking"), ("HAND_TRACKING", "openxr_hand_tracking"),
                                             ("CONTROLLER", "openxr_generic")])
def test_hands_tracked_without_controllers_get_the_hand_tracking_offsets(tmp_path, hand_type, want):
    from blender_manikin.core import solve as cs
    n = 30
    t = np.arange(n) / 90.0
    pose = np.zeros((n, 3, 7))
    pose[..., 1] = 1.5
    pose[..., 6] = 1.0
    rows = np.concatenate([t[:, None], pose.reshape(n, -1)], 1).astype(np.float32)
    devs = [("HEAD", "HMD"), ("HAND_LEFT", hand_type), ("HAND_RIGHT", hand_type)]
    doc = {"$schema": "x", "info": {"hardware": {"devices": [{"name": j, "type": k, "joint": j, "axes": AXES}
                                                             for j, k in devs]},
                                    "software": {"app": {"name": "Some App"}}},
           "frames": fpzip.compress(np.ascontiguousarray(rows[None, None])), "events": []}
    path = tmp_path / "hands.xror"
    path.write_bytes(bson.encode(doc))
    assert cs.resolve_offsets("auto", formats.load_recording(path)) == want


def test_six_devices(tmp_path):
    data, _, _ = _xror(devices=("HEAD", "HAND_LEFT", "HAND_RIGHT", "WAIST", "FOOT_LEFT", "FOOT_RIGHT"))
    (tmp_path / "six.xror").write_bytes(data)
    assert formats.load_recording(tmp_path / "six.xror").devices == (
        "head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")


@pytest.mark.parametrize("make,message", [
    (lambda: _xror()[0][:-7], "declares"),
    (lambda: b"\x05\x00\x00\x00\x99", "not a valid BSON"),
    (lambda: _xror(axes=["x", "y", "z"])[0], "axes"),
    (lambda: _xror(devices=("ELBOW",))[0], r"no device the solve can read: devices\[0\] \(joint 'ELBOW'"),
    (lambda: _xror(width=15)[0], "frames have 15 numbers"),
    (lambda: bson.encode({"info": {}}), "missing field info.hardware"),
    (lambda: bson.encode({"info": {"hardware": {"devices": [{"joint": "HEAD", "axes": AXES}]}},
                          "frames": b"not fpzip"}), "fpzip could not decompress"),
])
def test_bad_files_raise_recording_errors_naming_the_file(tmp_path, make, message):
    path = tmp_path / "bad.xror"
    path.write_bytes(make())
    with pytest.raises(RecordingError, match=message) as info:
        formats.load_recording(path)
    assert "bad.xror" in str(info.value)


@pytest.mark.skipif(not os.path.exists(os.path.join(VR, "xror-beatsaber-sample.xror")),
                    reason="the real XROR sample lives in ../shared/data/vr")
def test_the_real_sample_matches_its_bsor():
    x = formats.load_recording(os.path.join(VR, "xror-beatsaber-sample.xror"))
    b = formats.load_recording(os.path.join(VR, "xror-beatsaber-sample.bsor"))
    assert x.metadata["app"] == "Beat Saber" and x.metadata["offsets"] == "beat_saber"
    for dev in ("head", "left_hand", "right_hand"):
        sx, sb = x.streams[dev], b.streams[dev]
        assert len(sx.time) == len(sb.time) > 27000
        assert np.abs(sx.time - sb.time).max() < 1e-6
        assert np.abs(sx.pos - sb.pos).max() < 1e-6
        assert np.abs(np.abs((sx.quat * sb.quat).sum(-1)) - 1.0).max() < 1e-6


@pytest.mark.parametrize("app,activity,scale", [
    ("Beat Saber", {"modifiers": "FS,GN"}, 1.2),                  # Faster Song: song time runs 1.2x
    ("Beat Saber", {"modifiers": "SS", "speed": 1.5}, 0.85 * 1.5),  # Slower Song, in practice at 1.5x
    ("Beat Saber", {}, 1.0),
    ("Some App", {"modifiers": "FS"}, 1.0),                       # another app's times are its own
])
def test_a_beat_saber_sessions_song_time_becomes_real_time(tmp_path, app, activity, scale):
    """XROR from a BSOR keeps its song times and the play's modifiers (info.software.activity):
    the frames are read on real time, as the .bsor would be."""
    data, t, _ = _xror(app=app, software={"activity": activity} if activity else None)
    (tmp_path / "s.xror").write_bytes(data)
    rec = formats.load_recording(tmp_path / "s.xror")
    assert rec.metadata["time_scale"] == pytest.approx(scale)
    kept = rec.streams["head"].time
    assert kept[-1] == pytest.approx(np.float32(t[-1]) / scale, rel=1e-6)
    assert any("song speed" in w for w in rec.warnings) == (scale != 1.0)


@pytest.mark.parametrize("height", [None, "1.80m", {"value": 1.8}])
def test_a_height_that_is_not_a_number_does_not_stop_the_motion(tmp_path, height):
    """``info.software.activity.height`` is the player's height setting, not motion: a null (an
    app that does not know it), a text or an object is left out with a warning, the take read."""
    data, t, _ = _xror(app="Beat Saber")
    doc = bson.decode(data)
    doc["info"]["software"]["activity"] = {"height": height}
    (tmp_path / "take.xror").write_bytes(bson.encode(doc))
    rec = formats.load_recording(tmp_path / "take.xror")
    assert "height" not in rec.metadata and len(rec.streams["head"].time) == len(t)
    assert any(w.startswith("info.software.activity.height ") and "is not a number: left out" in w
               for w in rec.warnings)
