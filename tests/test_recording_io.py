"""Tracker recordings in: native CSV reader/writer, axis conversion, BSOR reader."""
import os

import numpy as np

from blender_manikin.core.formats import load_recording  # noqa: E402
import pytest

from blender_manikin.core.io_bsor import parse_bsor, read_bsor
from blender_manikin.core.io_csv import read_csv, write_csv
from blender_manikin.core.recording import (
    AXES, RecordingError, TrackerStream, axes_matrix, from_blender, to_blender,
)
from blender_manikin.core.resample import resample
from blender_manikin.core.rotations import axis_angle_to_quat, geodesic_angle, quat_to_matrix

from fixtures_recordings import bsor_bytes, make_recording, synthetic_bsor, truth, unity_pose, write_recording_csv

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BSOR_SAMPLE = os.path.join(ROOT, "..", "shared", "data", "vr", "beatsaber-replay-sample.bsor")
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def rot_err_deg(qa, qb):
    return np.degrees(geodesic_angle(quat_to_matrix(qa), quat_to_matrix(qb)))


# --------------------------------------------------------------------------
# axis conventions
def test_openxr_axes_keep_forward_right_up():
    M = axes_matrix("openxr")
    assert np.linalg.det(M) == pytest.approx(1.0)
    # right (+X), up (+Y), forward (-Z) -> Blender right (-X), up (+Z), forward (-Y)
    p, _ = to_blender(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]]), None, "openxr")
    np.testing.assert_allclose(p, [[-1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-12)
    # identity (HMD looking forward) stays identity; a 90 deg left turn stays a left turn
    _, q = to_blender(None, axis_angle_to_quat(np.array([[0, 0, 0], [0, np.pi / 2, 0]])), "openxr")
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R[0], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R[1] @ [0, -1, 0], [1, 0, 0], atol=1e-12)   # forward -> performer's left


def test_unity_axes_improper_matrix_gives_proper_rotations():
    M = axes_matrix("unity")
    assert np.linalg.det(M) == pytest.approx(-1.0)
    p, _ = to_blender(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), None, "unity")
    np.testing.assert_allclose(p, [[-1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-12)
    # Unity: +90 deg about +Y turns forward (+Z) to the right (+X)
    _, q = to_blender(None, axis_angle_to_quat(np.array([0, np.pi / 2, 0])), "unity")
    R = quat_to_matrix(q)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ [0, -1, 0], [-1, 0, 0], atol=1e-12)        # forward -> right
    # M R M^T equals the quaternion rule
    Ru = quat_to_matrix(axis_angle_to_quat(np.array([0.3, -0.7, 0.2])))
    _, q = to_blender(None, axis_angle_to_quat(np.array([0.3, -0.7, 0.2])), "unity")
    np.testing.assert_allclose(quat_to_matrix(q), M @ Ru @ M.T, atol=1e-12)


@pytest.mark.parametrize("axes", AXES)
def test_conversion_round_trip_keeps_quaternion_sign(axes):
    rng = np.random.default_rng(3)
    p = rng.normal(size=(20, 3))
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    pb, qb = to_blender(p, q, axes)
    p2, q2 = from_blender(pb, qb, axes)
    np.testing.assert_allclose(p2, p, atol=1e-12)
    np.testing.assert_allclose(q2, q, atol=1e-12)
    np.testing.assert_allclose(qb[:, 0], q[:, 0])            # w (and so sign) preserved


# --------------------------------------------------------------------------
# CSV round trips
@pytest.mark.parametrize("axes", AXES)
@pytest.mark.parametrize("units", ["m", "mm"])
def test_csv_round_trip_each_axes(tmp_path, axes, units):
    path, rec = write_recording_csv(tmp_path, axes=axes, units=units, duration=1.5,
                                    invalid=("left_hand", 0.5, 0.6), nan=("head", 0.8, 0.85),
                                    flip=("right_hand", 0.2, 0.4))
    text = open(path, encoding="utf-8").read()
    assert f"# axes: {axes}" in text and f"# units: {units}" in text
    back = load_recording(path)
    assert back.metadata["axes"] == axes and back.metadata["units"] == units
    assert back.metadata["source"] == "synthetic"
    assert back.devices == ("head", "left_hand", "right_hand")
    for d, s in rec.streams.items():
        b = back.streams[d]
        np.testing.assert_allclose(b.time, s.time, atol=1e-6)
        np.testing.assert_array_equal(b.valid, s.valid)
        np.testing.assert_allclose(b.pos, s.pos, atol=2e-6, equal_nan=True)
        # quaternions: same values and same sign (the flip survives the file)
        np.testing.assert_allclose(b.quat, s.quat, atol=1e-6, equal_nan=True)


def test_csv_file_in_openxr_holds_openxr_numbers(tmp_path):
    """The writer really writes OpenXR axes: head height is the 2nd column, in metres."""
    path, rec = write_recording_csv(tmp_path, axes="openxr", duration=0.5)
    rows = [ln.split(",") for ln in open(path) if ln.startswith(("0", "1", "2")) and ",head," in ln]
    py = np.array([float(r[3]) for r in rows])
    np.testing.assert_allclose(py, rec.streams["head"].pos[:, 2], atol=1e-6)


def test_csv_free_column_order_extra_columns_comments_and_aliases(tmp_path):
    path = tmp_path / "free.csv"
    path.write_text(
        "\ufeff# a comment line\n"
        "# source: hand-written test\n"
        "# axes: blender\n"
        "\n"
        "QW,qx,qy,qz,Device,time,px,py,pz,battery\n"
        "1,0,0,0,HMD,0.0,0,0,1.6,99\n"
        "1,0,0,0,left_hand,0.01,0.3,0,1.2,80\n"
        "# tracking glitch below\n"
        "1,0,0,0,head,0.011,0,0,1.61,99\n"
        "2,0,0,0,right_hand,0.02,-0.3,0,1.2,70\n", encoding="utf-8")
    rec = read_csv(path)
    assert rec.metadata["source"] == "hand-written test"
    assert rec.metadata["axes"] == "blender"
    np.testing.assert_allclose(rec.streams["head"].pos[:, 2], [1.6, 1.61])
    np.testing.assert_allclose(rec.streams["right_hand"].quat, [[1, 0, 0, 0]])   # normalised
    assert any("not unit length" in w for w in rec.warnings)


def test_csv_units_metadata_and_option_precedence(tmp_path):
    path, rec = write_recording_csv(tmp_path, units="cm", duration=0.5)
    a = load_recording(path)
    np.testing.assert_allclose(a.streams["head"].pos, rec.streams["head"].pos, atol=1e-6)
    b = load_recording(path, units="m")          # option wins (positions 100x too big now)
    np.testing.assert_allclose(b.streams["head"].pos, rec.streams["head"].pos * 100, atol=1e-4)
    assert any("overrides" in w for w in b.warnings)
    c = load_recording(path, axes="unity")       # axes option wins too
    assert c.metadata["axes"] == "unity"


BAD_FILES = [
    ("", "file is empty", None),
    ("# only comments\n", "no column header", None),
    ("0.0,head,0,0,0,1,0,0,0\n", "wrong header", 1),
    ("time;device;px;py;pz;qw;qx;qy;qz\n0;head;0;1.6;0;1;0;0;0\n",
     "separated by semicolons, this format by commas", 1),
    ("time,device,px,py,pz,qw,qx,qy\n0,head,0,0,0,1,0,0\n", "missing column(s) qz", 1),
    ("time,device,px,py,pz,qw,qx,qy,qz\n", "no data rows", 1),
    ("# note\ntime,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n0.01,head,0,abc,0,1,0,0,0\n",
     "column 'py': 'abc' is not a number", 4),
    ("time,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n0.01,head,0,1.6,0,1,0,0\n",
     "expected 9 comma-separated fields", 3),
    ("time,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n0.02,left_hand,0,1,0,1,0,0,0\n"
     "0.01,head,0,1.6,0,1,0,0,0\n0.005,head,0,1.6,0,1,0,0,0\n",
     "time 0.005000 s of head is not after its previous sample at line 4", 5),
    ("time,device,px,py,pz,qw,qx,qy,qz,valid\n0,head,0,1.6,0,1,0,0,0,maybe\n", "'maybe' is not 0 or 1", 2),
    ("# axes: y-up\ntime,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n", "unknown axes 'y-up'", 1),
    ("# units: inches\ntime,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n", "unknown units", 1),
    ("time,device,px,py,pz,qw,qx,qy,qz\nnan,head,0,1.6,0,1,0,0,0\n", "not a finite number", 2),
]


def test_csv_rows_repeating_a_time_are_ignored_with_a_warning(tmp_path):
    """A logger that writes a frame twice (the same time for one device): the first row is kept,
    the repeat ignored and counted; a time going back is still an error (above)."""
    path = tmp_path / "twice.csv"
    path.write_text("time,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n0,left_hand,0,1,0,1,0,0,0\n"
                    "0.01,head,0,1.6,0,1,0,0,0\n0.01,head,0,1.7,0,1,0,0,0\n0.02,head,0,1.6,0,1,0,0,0\n",
                    encoding="utf-8")
    rec = load_recording(path)
    np.testing.assert_allclose(rec.streams["head"].time, [0.0, 0.01, 0.02])
    np.testing.assert_allclose(rec.streams["head"].pos[1], [0.0, 0.0, 1.6], atol=1e-9)   # the first row
    assert any(w.startswith("head: 1 row(s) repeating the time of the row before ignored (first at line 5)")
               for w in rec.warnings), rec.warnings


@pytest.mark.parametrize("block_bytes", [None, 7])
@pytest.mark.parametrize("content,problem,line", BAD_FILES)
def test_csv_errors_name_file_line_and_problem(tmp_path, monkeypatch, content, problem, line, block_bytes):
    from blender_manikin.core import io_csv
    if block_bytes:     # the file read a few bytes at a time: lines still counted right
        monkeypatch.setattr(io_csv, "BLOCK_BYTES", block_bytes)
    path = tmp_path / "bad_take.csv"
    path.write_text(content, encoding="utf-8")
    with pytest.raises(RecordingError) as ei:
        load_recording(path)
    msg = str(ei.value)
    assert msg.startswith("bad_take.csv")
    assert problem in msg
    if line is not None:
        assert f"line {line}:" in msg
        assert ei.value.line == line
    assert isinstance(ei.value, ValueError)


def test_csv_not_utf8(tmp_path):
    path = tmp_path / "latin.csv"
    path.write_bytes(b"time,device,px,py,pz,qw,qx,qy,qz\n# caf\xe9\n")
    with pytest.raises(RecordingError, match=r"latin.csv, line 2: not UTF-8"):
        load_recording(path)


def test_load_recording_dispatch_errors(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        load_recording(tmp_path / "missing.csv")
    p = tmp_path / "take.fbx"
    p.write_text("x")
    with pytest.raises(RecordingError, match="unsupported file type '.fbx'"):
        load_recording(p)


def test_tracker_stream_validates_device():
    with pytest.raises(ValueError, match="unknown device"):
        TrackerStream("tail", [0.0], [[0, 0, 0]], [[1, 0, 0, 0]])
    s = TrackerStream("HMD", [0.0, 0.1], np.zeros((2, 3)), [[1, 0, 0, 0]] * 2)
    assert s.device == "head" and s.valid.all() and s.rate == pytest.approx(10.0)


def test_write_csv_accepts_dict_of_streams_and_orders_rows(tmp_path):
    rec = make_recording(duration=0.3)
    path = tmp_path / "d.csv"
    write_csv(path, rec.streams, axes="unity", metadata={"source": "dict"})
    back = read_csv(path)
    assert back.metadata["source"] == "dict"
    times = [float(ln.split(",")[0]) for ln in open(path) if ln[0].isdigit()]
    assert times == sorted(times)
    assert sum(len(s) for s in back.streams.values()) == sum(len(s) for s in rec.streams.values())


# --------------------------------------------------------------------------
# BSOR
def test_bsor_synthetic_placeholder_and_repeated_times(tmp_path):
    data, t = synthetic_bsor(n=180, repeated_zero_times=2)
    path = tmp_path / "synth.bsor"
    path.write_bytes(data)
    rec = load_recording(path)
    assert rec.devices == ("head", "left_hand", "right_hand")
    s = rec.streams["head"]
    assert len(s) == 180 - 1 - 2                   # placeholder + 2 repeated t=0 frames dropped
    assert np.all(np.diff(s.time) > 0) and s.time[0] == 0.0
    assert any("no valid pose" in w for w in rec.warnings)
    assert any("did not increase" in w for w in rec.warnings)
    # Unity -> Blender conversion recovers the analytic truth (float32 precision)
    for d in rec.devices:
        p, q = truth(d, rec.streams[d].time)
        np.testing.assert_allclose(rec.streams[d].pos, p, atol=1e-5)
        assert rot_err_deg(rec.streams[d].quat, q).max() < 0.01
    md = rec.metadata
    assert md["hmd"] == "Test HMD" and md["controller"] == "Test Controller"
    assert md["trackingSystem"] == "OpenVR" and md["height"] == pytest.approx(1.75)
    assert md["leftHanded"] is False and md["frames_in_file"] == 180
    assert "playerName" not in md and "playerID" not in md


def test_bsor_loading_frames_at_time_zero_keep_the_latest_pose():
    """The game logs several frames with song time 0 while it loads (each 250-330 ms long, as in
    the real replays under shared/data/vr): their poses are from before the song, the last one
    from just before the next frame.  The take starts with that one, not with a pose half a
    second stale one sample before the next (an 11 cm jump of every device at 10 m/s)."""
    rate = 90.0
    t = np.arange(180) / rate
    t[1:4] = 0.0
    t[4:] = (np.arange(176) + 1) / rate
    t = t.astype(np.float32).astype(np.float64)
    pose_time = t.copy()
    pose_time[1:4] = [-0.6, -0.3, 0.0]           # when each loading frame's pose was taken
    head, left, right = (unity_pose(d, pose_time * 8.0) for d in ("head", "left_hand", "right_hand"))
    for a in (head, left, right):
        a[0] = [0, 0, 0, -1, -1, -1, -1]
    rec = parse_bsor(bsor_bytes(t, head, left, right), path="loading.bsor")
    for d in rec.devices:
        s = rec.streams[d]
        assert len(s) == 180 - 1 - 2 and s.time[0] == 0.0
        p, _ = truth(d, s.time[:3] * 8.0)
        np.testing.assert_allclose(s.pos[:3], p, atol=1e-5)
        step = np.linalg.norm(np.diff(s.pos[:3], axis=0), axis=-1)
        assert step[0] < 1.5 * step[1] + 1e-3, (d, step)      # no jump into the take
    assert any("did not increase" in w for w in rec.warnings)


def test_bsor_time_jump_back_keeps_strictly_increasing():
    data, t = synthetic_bsor(n=300, backwards=(200, 0.5))      # rewind by 0.5 s at frame 200
    rec = parse_bsor(data, path="rewind.bsor")
    s = rec.streams["left_hand"]
    assert np.all(np.diff(s.time) > 0)
    kept_after = np.sum(t[200:] > t[199])
    assert len(s) == 1 + 196 + kept_after              # frame 1, frames 4..199, and after the jump
    assert any("did not increase" in w and "pause, rewind" in w for w in rec.warnings)


def test_bsor_left_handed_replay_keeps_the_hands_as_recorded():
    """Left-handed mode mirrors the map, not the player: the recorded left hand is the left
    controller (as BeatLeader's replayers read it), so nothing is swapped or mirrored."""
    plain, _ = synthetic_bsor(n=120)
    lefty, _ = synthetic_bsor(n=120, leftHanded=True)
    a, b = parse_bsor(plain, path="plain.bsor"), parse_bsor(lefty, path="lefty.bsor")
    assert b.metadata["leftHanded"] is True and a.metadata["leftHanded"] is False
    for d in a.devices:
        np.testing.assert_array_equal(b.streams[d].pos, a.streams[d].pos)
        np.testing.assert_array_equal(b.streams[d].quat, a.streams[d].quat)
    assert b.warnings == a.warnings


def test_bsor_speed_modifier_rescales_time():
    data, _ = synthetic_bsor(n=100, modifiers="FS,DA")
    rec = parse_bsor(data)
    assert rec.metadata["time_scale"] == pytest.approx(1.2)
    assert rec.streams["head"].time[-1] == pytest.approx((100 - 4) / 90.0 / 1.2, rel=1e-5)
    assert any("song speed" in w for w in rec.warnings)


@pytest.mark.parametrize("speed", [1e30, -2.0, 0.01, float("nan")])
def test_bsor_corrupt_practice_speed_is_not_applied(speed):
    """A practice speed the game cannot play at (a corrupt header field) would shrink the take to
    a frame or stretch it to hours: it is read as none, with a warning naming it."""
    data, t = synthetic_bsor(n=180, speed=speed)
    rec = parse_bsor(data, path="corrupt_speed.bsor")
    s = rec.streams["head"]
    assert s.time[-1] - s.time[0] == pytest.approx(t[-1] - t[1], abs=1e-4)
    assert rec.metadata["time_scale"] == 1.0
    assert any(w.startswith(f"practice speed {speed:g} is not one the game plays at") for w in rec.warnings)
    ok, _ = synthetic_bsor(n=180, speed=1.5)                      # a real practice speed still counts
    assert parse_bsor(ok, path="practice.bsor").metadata["time_scale"] == pytest.approx(1.5)


def test_bsor_invalid_device_sample_kept_but_flagged():
    data, t = synthetic_bsor(n=50)
    raw = bytearray(data)
    # zero the left-hand pose of frame 10 (frames start 4 + 1 + 4 bytes after the header)
    data_good, _ = synthetic_bsor(n=50)
    frames_at = len(data_good) - 5 - 50 * 92
    off = frames_at + 10 * 92 + 8 + 7 * 4
    raw[off:off + 28] = bytes(28)
    rec = parse_bsor(bytes(raw))
    lh = rec.streams["left_hand"]
    assert len(lh) == len(rec.streams["head"])
    assert (~lh.valid).sum() == 1 and rec.streams["head"].valid.all()
    assert any("left_hand: 1 sample" in w for w in rec.warnings)


def test_bsor_wrong_magic_and_truncation_name_byte_offsets(tmp_path):
    data, _ = synthetic_bsor(n=40)
    bad = tmp_path / "garbled.bsor"
    bad.write_bytes(b"PK\x03\x04" + data[4:])
    with pytest.raises(RecordingError) as ei:
        load_recording(bad)
    assert "garbled.bsor, byte offset 0: not a BSOR replay" in str(ei.value)

    frames_at = len(data) - 5 - 40 * 92
    cut = tmp_path / "truncated.bsor"
    cut.write_bytes(data[:frames_at + 10 * 92 + 50])          # cut inside frame 10
    with pytest.raises(RecordingError) as ei:
        load_recording(cut)
    msg = str(ei.value)
    assert msg.startswith("truncated.bsor, byte offset")
    assert "truncated" in msg and "declares 40 frames" in msg
    assert ei.value.offset == frames_at + 10 * 92

    head_cut = tmp_path / "header_cut.bsor"
    head_cut.write_bytes(data[:30])
    with pytest.raises(RecordingError, match=r"header_cut.bsor, byte offset \d+: file is truncated"):
        read_bsor(head_cut)

    garbage_len = bytearray(data)
    garbage_len[6:10] = (10 ** 9).to_bytes(4, "little")    # length of the first info string
    with pytest.raises(RecordingError, match=r"byte offset 6: invalid length 1000000000 of string version"):
        parse_bsor(bytes(garbage_len), path="len.bsor")

    with pytest.raises(RecordingError, match="file is empty"):
        (tmp_path / "empty.bsor").write_bytes(b"")
        load_recording(tmp_path / "empty.bsor")


@pytest.mark.skipif(not os.path.isfile(BSOR_SAMPLE), reason="real BSOR sample (../shared) not available")
def test_bsor_real_sample():
    rec = load_recording(BSOR_SAMPLE)
    md = rec.metadata
    assert md["frames_in_file"] == 2682
    assert md["hmd"] == "VIVE Pro 2" and md["trackingSystem"] == "OpenVR"
    assert "Knuckles" in md["controller"] and md["leftHanded"] is False
    assert md["offsets"] == "beat_saber"                               # Valve Index controllers
    assert 1.0 < md["height"] < 2.5
    head = rec.streams["head"]
    assert 2670 <= len(head) <= 2682
    assert 85.0 < head.rate < 95.0
    assert np.all(np.diff(head.time) > 0)
    assert 28.0 < head.time[-1] - head.time[0] < 31.0
    assert 1.4 < np.median(head.pos[:, 2]) < 2.0                 # standing player's eye height
    # the player faces -Y (Blender forward): the HMD's forward axis is mostly -Y
    fwd = quat_to_matrix(head.quat) @ np.array([0.0, -1.0, 0.0])
    assert np.median(fwd[:, 1]) < -0.8
    # left hand on the performer's left (+X) of the right hand, on median
    assert np.median(rec.streams["left_hand"].pos[:, 0] - rec.streams["right_hand"].pos[:, 0]) > 0.1
    times, pos, quat, valid, report = resample(rec, 60)
    assert abs(times[-1] - times[0] - (head.time[-1] - head.time[0])) < 0.05
    assert all(v.mean() > 0.99 for v in valid.values())


# --------------------------------------------------------------------------
# bundled example
def test_bundled_example_recording():
    assert os.path.getsize(EXAMPLE) < 1_000_000
    rec = load_recording(EXAMPLE)
    assert rec.metadata["axes"] == "openxr" and "synthetic" in rec.metadata["source"]
    assert rec.devices == ("head", "left_hand", "right_hand")
    assert 6.0 <= rec.duration <= 8.0
    assert rec.streams["head"].rate == pytest.approx(90.0, rel=0.02)
    assert rec.streams["left_hand"].rate == pytest.approx(72.0, rel=0.02)
    dt = np.diff(rec.streams["head"].time)
    assert dt.std() > 1e-4                                         # jittered
    assert 1.55 < np.median(rec.streams["head"].pos[:, 2]) < 1.7   # 1.75 m performer's eyes


def test_example_recording_matches_its_generator(tmp_path):
    """examples/example_recording.csv is what examples/make_example_recording.py writes."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_example_recording",
                                                  os.path.join(ROOT, "examples", "make_example_recording.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "regenerated.csv"
    mod.main([str(out)])
    a, b = load_recording(EXAMPLE), load_recording(out)
    assert a.devices == b.devices
    for d in a.devices:
        np.testing.assert_allclose(a.streams[d].time, b.streams[d].time, atol=2e-6)
        np.testing.assert_allclose(a.streams[d].pos, b.streams[d].pos, atol=2e-6)
        np.testing.assert_allclose(a.streams[d].quat, b.streams[d].quat, atol=2e-6)


def test_native_csv_takes_the_same_device_aliases(tmp_path):
    from blender_manikin.core.formats import load_recording as load
    p = tmp_path / "aliases.csv"
    rows = ["time,device,px,py,pz,qw,qx,qy,qz"]
    for k in range(5):
        for dev in ("HMD", "controller_left", "hand_r", "tracker_left_foot"):
            rows.append(f"{k / 90:.6f},{dev},0,1.6,0,1,0,0,0")
    p.write_text("\n".join(rows) + "\n")
    assert load(p).devices == ("head", "left_hand", "right_hand", "left_foot")


def _csv_with_everything(tmp_path, rows=2000):
    """A native CSV whose data rows hold comments, blank and padded lines, quoted fields, long
    device aliases, extra columns and a metadata line half way."""
    rng = np.random.default_rng(3)
    out = ["\ufeff# blender_manikin tracker recording", "# axes: openxr",
           "time,device,px,py,pz,qw,qx,qy,qz,valid,note"]
    names = ["head", "Left Controller", '"right_hand"', "  hmd  "]        # hmd: the head too
    for i in range(rows):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        out.append(f"{0.004 * i:.6f},{names[i % 4]},{rng.normal():.6f},{1 + rng.random():.6f},"
                   f"{rng.normal():.6f},{q[0]:.7f},{q[1]:.7f},{q[2]:.7f},{q[3]:.7f},{int(i % 17 != 0)},x{i}")
        if i == 700:
            out.append("# units: m")
        if i == 900:
            out.append("")
        if i == 1100:
            out.append("   ")
    lines = "\n".join(out).split("\n")
    lines[1500] = "  " + lines[1500] + "  "         # a padded row
    path = tmp_path / "mixed.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_csv_read_in_blocks_equals_read_whole(tmp_path, monkeypatch):
    """Big files are read a block at a time (bounded memory): the result does not depend on
    the block size, whatever the rows hold (the fast path and the field-by-field one agree)."""
    from blender_manikin.core import io_csv
    path = _csv_with_everything(tmp_path)
    whole = read_csv(path, block_bytes=1 << 30)
    assert set(whole.streams) == {"head", "left_hand", "right_hand"}
    assert whole.metadata["units"] == "m"
    for bb in (1, 97, 4096, 50_000):
        part = read_csv(path, block_bytes=bb)
        assert part.metadata == whole.metadata and part.warnings == whole.warnings
        for d, s in whole.streams.items():
            for k in ("time", "pos", "quat", "valid"):
                np.testing.assert_array_equal(getattr(part.streams[d], k), getattr(s, k), err_msg=f"{bb} {d} {k}")
    # and the field-by-field path alone gives the same numbers
    monkeypatch.setattr(io_csv, "_parse_fast", lambda *a, **k: None)
    slow = read_csv(path, block_bytes=4096)
    for d, s in whole.streams.items():
        for k in ("time", "pos", "quat", "valid"):
            np.testing.assert_array_equal(getattr(slow.streams[d], k), getattr(s, k))


def test_csv_rows_of_other_trackers_are_left_out_and_named(tmp_path):
    """Extra trackers (a chest, elbows) or a misspelt device: their rows are left out with a
    warning naming each and its first line; a needed device missing names them too."""
    from blender_manikin.core.resample import resample
    text = ("time,device,px,py,pz,qw,qx,qy,qz\n"
            "0,head,0,1.6,0,1,0,0,0\n0,chest,0,1.3,0,1,0,0,0\n0,left_hand,0.3,1.0,0,1,0,0,0\n"
            "0,right_hand,-0.3,1.0,0,1,0,0,0\n0.02,chest,0,1.3,0,1,0,0,0\n0.02,left_elbow,0.2,1.1,0,1,0,0,0\n")
    for bb in (None, 40):
        p = tmp_path / "extra.csv"
        p.write_text(text)
        rec = read_csv(p, block_bytes=bb)
        assert rec.devices == ("head", "left_hand", "right_hand")
        assert "device 'chest': 2 row(s) from line 3 ignored (not one of head, left_hand" in rec.warnings[0]
        assert rec.warnings[1].startswith("device 'left_elbow': 1 row(s) from line 7 ignored")
        assert rec.metadata["ignored_devices"] == ["chest", "left_elbow"]
    p.write_text(text.replace("left_hand", "lefthnd"))
    with pytest.raises(RecordingError, match=r"no left_hand samples \(devices present: head, right_hand; rows of "
                                             r"'chest', 'lefthnd', 'left_elbow' were left out: not device names\)"):
        resample(read_csv(p), 30.0)


def test_csv_error_deep_in_a_big_file_names_its_line(tmp_path):
    path = _csv_with_everything(tmp_path)
    lines = path.read_text(encoding="utf-8").split("\n")
    def oops(row):
        row[3] = "oops"

    def unknown(row):
        row[1] = "elbow"

    for change, problem in ((oops, "column 'py': 'oops' is not a number"),
                            (list.pop, "expected 11 comma-separated fields")):
        row = lines[1800].split(",")
        change(row)
        p = tmp_path / "broken.csv"
        p.write_text("\n".join(lines[:1800] + [",".join(row)] + lines[1801:]), encoding="utf-8")
        for bb in (None, 333):
            with pytest.raises(RecordingError, match=rf"broken.csv, line 1801: {problem}"):
                read_csv(p, block_bytes=bb)


def test_increasing_mask_drops_a_corrupt_time_but_keeps_pauses_and_rewinds_as_before():
    from blender_manikin.core.recording import increasing_mask
    spike = [0.0, 0.01, 0.02, 5000.0, 0.03, 0.04]              # one timestamp gone wrong
    assert increasing_mask(spike).tolist() == [True, True, True, False, True, True]
    pause = [0.0, 0.01, 0.02, 9.0, 9.01, 9.02]                  # the time goes on after a pause
    assert increasing_mask(pause).all()
    rewind = [0.0, 0.01, 0.02, 0.03, 0.01, 0.02, 0.04]          # a rewind: dropped until time passes 0.03
    assert increasing_mask(rewind).tolist() == [True, True, True, True, False, False, True]
    assert increasing_mask([0.0, np.nan, 0.02]).tolist() == [True, False, True]


def test_bsor_frame_with_a_corrupt_time_is_dropped_alone(tmp_path):
    """One frame's song time gone wrong (1e9 s) costs that frame, not the rest of the take, nor
    a take stretched to 30 years."""
    _, t = synthetic_bsor(n=180, repeated_zero_times=0, placeholder=False)
    bad = t.copy()
    bad[90] = 1e9
    head, left, right = (unity_pose(d, t) for d in ("head", "left_hand", "right_hand"))
    path = tmp_path / "glitch.bsor"
    path.write_bytes(bsor_bytes(bad, head, left, right))
    rec = load_recording(path)
    assert len(rec.streams["head"]) == 179
    assert rec.streams["head"].time.max() < 2.0
    assert any("leapt ahead" in w and "frame index 90" in w for w in rec.warnings), rec.warnings
    assert not any("did not increase" in w for w in rec.warnings)
    times = resample(rec, 30.0)[0]
    assert times[-1] == pytest.approx(t[-1], abs=1 / 30)


def test_csv_empty_cells_are_lost_samples(tmp_path):
    """pandas' ``to_csv`` (and a spreadsheet) writes a lost sample's NaN as an empty cell: the
    sample is lost, as ``nan`` is, in the fast and the exact parser alike; an empty time is still
    an error naming its line."""
    path, _ = write_recording_csv(tmp_path, duration=0.5)
    lines = open(path).read().splitlines()
    hi = next(i for i, ln in enumerate(lines) if ln.startswith("time,"))
    rows = [k for k in range(hi + 1, len(lines)) if ",left_hand," in lines[k]][5:8]
    for k in rows:
        f = lines[k].split(",")
        f[2:9] = [""] * 7
        lines[k] = ",".join(f)
    for name, text in (("empty.csv", "\n".join(lines) + "\n"), ("empty_crlf.csv", "\r\n".join(lines) + "\r\n")):
        p = tmp_path / name
        p.write_text(text, newline="")
        rec = read_csv(p)
        s = rec.streams["left_hand"]
        assert (~s.usable).sum() == 3 and np.isnan(s.pos[~s.usable]).all()
        assert s.usable.sum() == len(s) - 3
    f = lines[rows[0]].split(",")
    f[0] = ""
    lines[rows[0]] = ",".join(f)
    (tmp_path / "no_time.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=rf"no_time.csv, line {rows[0] + 1}: column 'time': the cell is empty"):
        read_csv(tmp_path / "no_time.csv")
