"""Readers never crash: whatever the bytes, a reader returns a Recording or raises RecordingError
naming the file, and so does the resampling of what it returns (property-based: random bytes,
every truncation, flipped bytes).  A bounded fuzz
runs in the normal suite; ``pytest -m fuzz_long tests`` runs a longer one (deselected by default,
pyproject.toml), and BLENDER_MANIKIN_FUZZ_EXAMPLES sets the examples of the bounded one."""
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from blender_manikin.core import formats
from blender_manikin.core.device_offsets import load_offsets
from blender_manikin.core.recording import Recording, RecordingError
from blender_manikin.core.resample import resample, seconds_from_time_units

from fixtures_recordings import synthetic_bsor

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")
N = int(os.environ.get("BLENDER_MANIKIN_FUZZ_EXAMPLES", "60"))


def _valid_files():
    out = {".csv": open(EXAMPLE, "rb").read()[:6000], ".bsor": synthetic_bsor(n=40)[0]}
    # a wide layout as a logger on a decimal-comma locale writes it: semicolons, ISO 8601 times
    cols = ["time"] + [f"{d}_{k}_{a}" for d in ("hmd", "left_controller", "right_controller")
                       for k, axes in (("pos", "xyz"), ("rot", "wxyz")) for a in axes]
    lines = [";".join(cols)]
    for k in range(30):
        pose = [0.01 * k, 1.6, 0.0, 1.0, 0.0, 0.0, 0.0, -0.2, 1.2, -0.3, 1.0, 0.0, 0.0, 0.0,
                0.2, 1.2, -0.3 - 0.01 * k, 1.0, 0.0, 0.0, 0.0]
        lines.append(";".join([f"2026-12-07T10:00:{k / 72:09.6f}"] + [f"{v:.4f}".replace(".", ",") for v in pose]))
    out["_semicolons.csv"] = ("\n".join(lines) + "\n").encode()
    # JSON frames as Unity's JsonUtility writes them, and as JSON Lines
    import json
    frames = [{"time": k / 72, **{d: {"position": {"x": x, "y": 1.6 - 0.4 * (d != "head"), "z": -0.01 * k},
                                       "rotation": {"x": 0.0, "y": 0.1, "z": 0.0, "w": 1.0}}
                                   for d, x in (("head", 0.0), ("leftHand", -0.2), ("rightHand", 0.2))}}
              for k in range(30)]
    out[".json"] = json.dumps({"fps": 72, "frames": frames}, indent=1).encode()
    out[".jsonl"] = ("\n".join(json.dumps(f) for f in frames) + "\n").encode()
    try:
        import bson
        import fpzip
        t = np.arange(30) / 90.0
        rows = np.concatenate([t[:, None], np.tile([0, 1.6, 0, 0, 0, 0, 1.0], (30, 3))], 1).astype(np.float32)
        devs = [{"joint": j, "axes": ["x", "y", "z", "i", "j", "k", "1"]} for j in ("HEAD", "HAND_LEFT", "HAND_RIGHT")]
        out[".xror"] = bson.encode({"info": {"hardware": {"devices": devs}},
                                    "frames": fpzip.compress(np.ascontiguousarray(rows[None, None]))})
    except ImportError:
        pass
    return out


VALID = _valid_files()


def _read(tmp_path, ext, data):
    path = tmp_path / f"fuzz{ext}"
    path.write_bytes(data)
    try:
        rec = formats.load_recording(path)
    except RecordingError as exc:
        assert f"fuzz{ext}" in str(exc), str(exc)
        return None
    assert isinstance(rec, Recording)
    for s in rec.streams.values():
        assert s.pos.shape == (len(s.time), 3) and s.quat.shape == (len(s.time), 4)
    # what a reader accepts, the solve's resampling takes or refuses by name: corrupt times must
    # not turn into a frame grid of petabytes
    try:
        times, pos, _, _, _ = resample(seconds_from_time_units(rec), 30.0)
    except RecordingError as exc:
        assert f"fuzz{ext}" in str(exc), str(exc)
        return rec
    assert times.shape[0] >= 1 and all(p.shape == (times.shape[0], 3) for p in pos.values())
    return rec


FUZZ = settings(max_examples=N, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.mark.parametrize("ext", sorted(VALID))
@FUZZ
@given(data=st.binary(max_size=2048))
def test_random_bytes(tmp_path, ext, data):
    _read(tmp_path, ext, data)


@pytest.mark.parametrize("ext", sorted(VALID))
@FUZZ
@given(cut=st.floats(0, 1))
def test_truncations(tmp_path, ext, cut):
    data = VALID[ext]
    _read(tmp_path, ext, data[: int(cut * len(data))])


@pytest.mark.parametrize("ext", sorted(VALID))
@FUZZ
@given(flips=st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), min_size=1, max_size=8))
def test_flipped_bytes(tmp_path, ext, flips):
    data = bytearray(VALID[ext])
    for where, value in flips:
        data[min(int(where * len(data)), len(data) - 1)] = value
    _read(tmp_path, ext, bytes(data))


@pytest.mark.parametrize("ext", sorted(VALID))
def test_every_truncation_of_the_head(tmp_path, ext):
    data = VALID[ext]
    for n in range(0, min(len(data), 400)):
        _read(tmp_path, ext, data[:n])


@FUZZ
@given(text=st.text(max_size=400))
def test_offsets_json_never_crashes(tmp_path, text):
    path = tmp_path / "offsets.json"
    path.write_text(text, encoding="utf-8")
    try:
        load_offsets(str(path))
    except ValueError as exc:
        assert "offsets.json" in str(exc) or str(exc)


@pytest.mark.fuzz_long
@pytest.mark.parametrize("ext", sorted(VALID))
@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flips=st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), min_size=1, max_size=32),
       cut=st.floats(0.2, 1))
def test_long_fuzz_flips_and_cuts(tmp_path, ext, flips, cut):
    data = bytearray(VALID[ext])
    for where, value in flips:
        data[min(int(where * len(data)), len(data) - 1)] = value
    _read(tmp_path, ext, bytes(data[: max(1, int(cut * len(data)))]))
