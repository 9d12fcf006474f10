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
          names=None):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 90.0
    pose = np.zeros((n, len(devices), 7))
    pose[..., :3] = rng.normal(size=(n, len(devices), 3)) * 0.1 + [0, 1.5, 0]
    q = rng.normal(size=(n, len(devices), 4))
    pose[..., 3:] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return xror_bytes(t, pose, devices, app=app, axes=axes, width=width, names=names), t, pose


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


@pytest.mark.parametrize("names,want", [
    (("VIVE Pro 2", "OpenVR Controller(Knuckles Left) - Left", "OpenVR Controller(Knuckles Right) - Right"),
     "beat_saber"),
    (("Oculus Quest2", "Oculus Touch Controller - Left", "Oculus Touch Controller - Right"), "beat_saber_touch"),
    (("Meta Quest 3", "Left Controller", "Right Controller"), "beat_saber_touch"),
])
def test_a_beat_saber_session_on_touch_controllers_gets_the_touch_preset(tmp_path, names, want):
    data, _, _ = _xror(app="Beat Saber", names=names)
    (tmp_path / "bs.xror").write_bytes(data)
    assert formats.load_recording(tmp_path / "bs.xror").metadata["offsets"] == want


def test_six_devices(tmp_path):
    data, _, _ = _xror(devices=("HEAD", "HAND_LEFT", "HAND_RIGHT", "WAIST", "FOOT_LEFT", "FOOT_RIGHT"))
    (tmp_path / "six.xror").write_bytes(data)
    assert formats.load_recording(tmp_path / "six.xror").devices == (
        "head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")


@pytest.mark.parametrize("make,message", [
    (lambda: _xror()[0][:-7], "declares"),
    (lambda: b"\x05\x00\x00\x00\x99", "not a valid BSON"),
    (lambda: _xror(axes=["x", "y", "z"])[0], "axes"),
    (lambda: _xror(devices=("HEAD", "ELBOW"))[0], "joint 'ELBOW'"),
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
