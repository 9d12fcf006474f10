"""C3D marker files (``core/io_c3d.py``): the same Plug-in Gait / OpenCap marker motion written as
a TRC (``test_marker_sets.write_marker_trc``) and as C3Ds (``fixtures_c3d.write_c3d``: Intel, DEC
and MIPS processors, int16 × scale and float storage, analog channels between frames, LABELS2,
invalid samples) reads as the same joint centres and solves the same; DEC floats checked against
known VAX F bit patterns and py-c3d's conversion; bad files named with the byte offset."""
import os
import re

import numpy as np
import pytest

from blender_manikin.core.io_keypoints import is_keypoint_input, one_person_file, read_keypoints
from blender_manikin.core.recording import RecordingError
from fixtures_c3d import float_bytes, write_c3d
from fixtures_keypoints import hinge_motion, to_y_up
from test_marker_sets import anatomical_markers, write_marker_trc
from test_subject_params import MP


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=90, seed=3)


def _pig(motion, prefix=""):
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=True)
    return [prefix + n for n in names], pts


@pytest.mark.parametrize("proc", ["intel", "dec", "mips"])
@pytest.mark.parametrize("floats", [False, True])
def test_c3d_reads_as_the_trc_of_the_same_motion(tmp_path, motion, proc, floats):
    """Each processor and storage, with 2 analog channels × 4 samples a frame, labels split into
    LABELS / LABELS2 and two invalid samples (residual -1: NaN, as empty TRC cells): the same
    layout, times and joint centres as the TRC (int16 at 0.1 mm: within 0.1 mm).  Before: not a
    keypoint file."""
    names, pts = _pig(motion)
    T, K = pts.shape[:2]
    invalid = np.zeros((T, K), bool)
    invalid[10, names.index("LKNE")] = invalid[40, names.index("RWRA")] = True
    lost = pts.copy()
    lost[invalid] = np.nan
    trc = read_keypoints(write_marker_trc(tmp_path / "walk.trc", names, lost, fps=60.0))
    path = write_c3d(tmp_path / "walk.c3d", names, to_y_up(pts, 1000.0), rate=60.0, proc=proc, floats=floats,
                     analog_channels=2, analog_per_frame=4, invalid=invalid, labels_split=10)
    assert is_keypoint_input(path) and one_person_file(path)
    rec = read_keypoints(path)
    assert rec.layout == trc.layout == "plugingait"
    np.testing.assert_allclose(rec.time, trc.time, atol=1e-6)         # the TRC: 6 decimals
    assert np.array_equal(np.isnan(rec.points), np.isnan(trc.points))
    np.testing.assert_allclose(rec.points, trc.points, atol=1e-6 if floats else 1e-4, equal_nan=True)
    assert rec.metadata["detected"] == trc.metadata["detected"]


def test_c3d_solve_equals_the_trc_solve(tmp_path, motion):
    """End to end: an OpenCap marker C3D (float, DEC) solves as the TRC of the same values does
    (within 0.01 mm; the TRC keeps 6 decimals of mm)."""
    from blender_manikin.core.solve import SolveSettings, solve_recording
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "opencap")
    mm = to_y_up(pts, 1000.0).astype(np.float32).astype(np.float64)     # the values a float C3D holds
    pts = np.stack([mm[..., 0], -mm[..., 2], mm[..., 1]], -1) / 1000.0     # the same, as the TRC's
    trc = solve_recording(str(write_marker_trc(tmp_path / "walk.trc", names, pts, fps=30.0)),
                          SolveSettings(fps=30.0))
    c3d = solve_recording(str(write_c3d(tmp_path / "walk.c3d", names, mm, rate=30.0, proc="dec", floats=True,
                                        analog_channels=1, analog_per_frame=10)),
                          SolveSettings(fps=30.0))
    assert c3d.result.positions.shape == trc.result.positions.shape
    np.testing.assert_allclose(c3d.result.positions, trc.result.positions, atol=1e-5)   # 0.01 mm


def test_subject_prefix_finds_the_mp_beside_the_c3d(tmp_path, motion):
    """``Bob:LASI`` ... : Bob.mp beside the C3D gives the widths, as beside a TRC."""
    names, pts = _pig(motion, "Bob:")
    (tmp_path / "Bob.mp").write_text(MP, encoding="utf-8")
    rec = read_keypoints(write_c3d(tmp_path / "walk.c3d", names, to_y_up(pts, 1000.0)))
    assert "subject Bob.mp:" in rec.metadata["detected"] and "(found beside the C3D)" in rec.metadata["detected"]
    assert rec.metadata["subject_height"] == pytest.approx(1.812)


@pytest.mark.parametrize("ext", [".c3d", ".trc"])
def test_two_subjects_in_one_file_are_named(tmp_path, motion, ext):
    """Markers of two subjects (``Ann:`` and ``Bob:``) are refused, naming both: neither is
    solved from the other's markers (before: the TRC was read without a word, one subject's markers
    taken by name and the other's passed over)."""
    names, pts = _pig(motion, "Bob:")
    names = names + [n.replace("Bob:", "Ann:") for n in names]
    pts = np.concatenate([pts, pts + 1.0], axis=1)
    path = (write_c3d(tmp_path / "two.c3d", names, to_y_up(pts, 1000.0)) if ext == ".c3d"
            else write_marker_trc(tmp_path / "two.trc", names, pts))
    with pytest.raises(RecordingError, match=rf"two{ext}, (line 4|byte offset \d+): the (C3D|TRC)'s markers "
                                             r"belong to 2 subjects \(Ann, Bob\)"):
        read_keypoints(path)


@pytest.mark.parametrize("ext", [".c3d", ".trc"])
def test_a_prop_labelled_as_a_subject_is_left_out(tmp_path, motion, ext):
    """A Vicon session labels a prop as a subject of its own (``Sword:Tip``, ``Sword:Hilt``)
    beside the performer: the performer's markers are read, as without the prop, and the
    summary names what was left out (two subjects of markers were refused, one body is not)."""
    names, pts = _pig(motion, "Bob:")
    alone = read_keypoints(write_c3d(tmp_path / "alone.c3d", names, to_y_up(pts, 1000.0)) if ext == ".c3d"
                           else write_marker_trc(tmp_path / "alone.trc", names, pts))
    sword = pts[:, :2] + np.array([0.3, 0.0, 0.1])
    names2, pts2 = names + ["Sword:Tip", "Sword:Hilt"], np.concatenate([pts, sword], axis=1)
    path = (write_c3d(tmp_path / "prop.c3d", names2, to_y_up(pts2, 1000.0)) if ext == ".c3d"
            else write_marker_trc(tmp_path / "prop.trc", names2, pts2))
    rec = read_keypoints(path)
    np.testing.assert_array_equal(rec.points, alone.points)
    assert "markers of Bob read; Sword left out (not a body)" in rec.metadata["detected"]


def _py_c3d_dec_to_ieee(raw):
    """py-c3d's ``DEC_to_IEEE_BYTES`` (EmbodiedCognition/py-c3d, c3d/utils.py), restated: bytes
    2, 3, 0, 1 of each value, the exponent's high byte decremented (exponent - 2), as IEEE."""
    b = np.frombuffer(raw, np.uint8)
    out = np.empty(len(b), np.uint8)
    out[0::4], out[1::4], out[2::4] = b[2::4], b[3::4], b[0::4]
    out[3::4] = b[1::4] + (np.bitwise_and(b[1::4], 0x7F) == 0) - 1
    return np.frombuffer(out.tobytes(), np.float32)


def test_dec_floats_match_vax_f_and_py_c3d():
    """VAX F: 1.0 is the word 0x4080 then 0x0000 (bytes 80 40 00 00), -1.0 80 C0 00 00, 0.5
    00 40 00 00, 0 all zero; random values agree with py-c3d's conversion bit for bit, and the
    test writer's DEC bytes read back."""
    from blender_manikin.core.io_c3d import dec_to_float
    known = bytes.fromhex("80400000" "80c00000" "00400000" "00000000" "a0410000")
    np.testing.assert_array_equal(dec_to_float(known), [1.0, -1.0, 0.5, 0.0, 5.0])
    rng = np.random.default_rng(0)
    u = rng.integers(0, 2**32, 2000, dtype=np.uint64).astype(np.uint32)
    exp = (u >> 7) & 0xFF                        # the exponent bits of the first word (little-endian)
    u = u[(exp > 2) & (exp < 255)]
    raw = u.astype("<u4").tobytes()
    np.testing.assert_array_equal(dec_to_float(raw).astype(np.float32), _py_c3d_dec_to_ieee(raw))
    v = rng.uniform(-3000, 3000, 100).astype(np.float32)
    np.testing.assert_array_equal(dec_to_float(float_bytes(v, "dec")), v)


def test_a_take_longer_than_65535_frames(tmp_path):
    """The header's frame words overflow: TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD give the
    frames (70000 from frame 5: its time 4 / rate); groups listed after their parameters; 300
    markers in LABELS and LABELS2."""
    from blender_manikin.core.io_c3d import read_c3d
    rng = np.random.default_rng(2)
    pts = rng.uniform(-100, 100, (70000, 3, 3))
    c = read_c3d(write_c3d(tmp_path / "long.c3d", ["A", "B", "C"], pts, rate=100.0, long_take=True, first_frame=5,
                           groups_after=True))
    assert c.points.shape == (70000, 3, 3) and c.first_frame == 5 and c.time[0] == pytest.approx(0.04)
    np.testing.assert_allclose(c.points, pts, atol=0.051)
    names = [f"M{k}" for k in range(300)]
    c = read_c3d(write_c3d(tmp_path / "many.c3d", names, rng.uniform(-100, 100, (3, 300, 3)), proc="mips"))
    assert c.names == names and c.units == "mm"



def test_the_header_frames_win_over_a_stale_trial_end_field(tmp_path):
    """A 4-frame take whose header holds its frames (1-4) and whose TRIAL:ACTUAL_END_FIELD says 10
    (left stale): 4 frames, as py-c3d reads it (before: 10, the zeros padding the data's last
    512-byte block read as six frames of every marker at the origin)."""
    import struct

    from blender_manikin.core.io_c3d import read_c3d
    pts = np.arange(24, dtype=float).reshape(4, 2, 3)
    path = write_c3d(tmp_path / "stale.c3d", ["A", "B"], pts, long_take=True)
    data = bytearray(path.read_bytes())
    data[8:10] = struct.pack("<H", 4)                   # the header's last frame: 4
    at = bytes(data).index(b"ACTUAL_END_FIELD") + len("ACTUAL_END_FIELD") + 5
    assert struct.unpack_from("<hh", data, at) == (4, 0)
    data[at:at + 4] = struct.pack("<hh", 10, 0)
    path.write_bytes(bytes(data))
    c = read_c3d(path)
    assert c.points.shape == (4, 2, 3) and c.first_frame == 1
    np.testing.assert_allclose(c.points, pts, atol=0.051)

def _bad(tmp_path, name, change):
    path = write_c3d(tmp_path / name, ["A", "B"], np.ones((4, 2, 3)))
    data = bytearray(open(path, "rb").read())
    data = change(data)
    with open(path, "wb") as f:
        f.write(bytes(data))
    return path


def _rename_point(d):
    i = bytes(d).index(b"POINT", 512)
    d[i:i + 5] = b"PLACE"
    return d


@pytest.mark.parametrize("name, change, message", [
    ("csv.c3d", lambda d: bytearray(b"time,x\n0,1\n" * 60), "byte offset 1: not a C3D file: byte 2 is 0x69, not 0x50"),
    ("cut.c3d", lambda d: d[:1024 + 20], r"byte offset 1044: truncated: 4 frames of 16 bytes from byte 1024 need "
                                          r"1088 bytes, the file has 1044 \(frame 2 is cut short\)"),
    ("params.c3d", lambda d: d[:514] + bytes([9]) + d[515:],
     r"byte offset 514: the parameter section \(9 blocks of 512 bytes from byte 512\) runs past"),
    ("nopoint.c3d", _rename_point, "byte offset 512: no POINT group among the parameters"),
])
def test_bad_c3d_files_are_named(tmp_path, name, change, message):
    with pytest.raises(RecordingError, match=re.escape(name) + ", " + message):
        read_keypoints(_bad(tmp_path, name, change))


def test_zero_markers_are_named(tmp_path):
    path = write_c3d(tmp_path / "empty.c3d", [], np.ones((4, 0, 3)))
    with pytest.raises(RecordingError, match=r"empty.c3d, byte offset \d+: zero markers \(POINT:USED is 0\)"):
        read_keypoints(path)



def _with_float_params(tmp_path, name, values, **kw):
    """A C3D whose parameters ``values`` (``{(NAME, group id): float}``, group 1 POINT, 2 ANALOG) are
    written as floats holding these values (type 4 parameters may hold NaN, inf, a fraction, any size)."""
    import struct

    import fixtures_c3d

    plain = fixtures_c3d._param

    def param(pname, gid, typ, dims, payload, proc, locked=False):
        if (pname, gid) in values:
            typ, dims, payload = 4, (), struct.pack("<f", values[(pname, gid)])
        return plain(pname, gid, typ, dims, payload, proc, locked)

    fixtures_c3d._param = param
    try:
        return write_c3d(tmp_path / name, ["A", "B"], np.ones((4, 2, 3)), **kw)
    finally:
        fixtures_c3d._param = plain


@pytest.mark.parametrize("values, kw, message", [
    ({("RATE", 2): float("nan")}, {"analog_channels": 2, "analog_per_frame": 2},
     r"the analog rate \(ANALOG:RATE\) is nan, not a rate in Hz"),
    ({("USED", 2): -1.0}, {"analog_channels": 1, "analog_per_frame": 2},
     r"the analog channel count \(ANALOG:USED\) is -1.0, not a whole number of 0 or more"),
    ({("USED", 1): float("nan")}, {}, r"the marker count \(POINT:USED\) is nan, not a whole number of 1 or more"),
    ({("LONG_FRAMES", 1): float("inf")}, {"long_frames": True},
     r"the frame count \(POINT:LONG_FRAMES\) is inf, not a whole number"),
    # NaN read every sample as missing without a word; 0 put every marker at the origin
    ({("SCALE", 1): float("nan")}, {}, r"the scale nan \(POINT:SCALE\) is not a nonzero number"),
    ({("SCALE", 1): 0.0}, {}, r"the scale 0.0 \(POINT:SCALE\) is not a nonzero number"),
])
def test_float_counts_that_are_no_counts_are_named(tmp_path, values, kw, message):
    """A count or rate of a float parameter that is NaN, infinite or negative is refused naming the
    parameter and its byte offset (it escaped as 'cannot convert float NaN to integer', an
    OverflowError, or a reshape error from a negative analog channel count)."""
    path = _with_float_params(tmp_path, "counts.c3d", values, **kw)
    with pytest.raises(RecordingError, match=r"counts.c3d, byte offset \d+: " + message):
        read_keypoints(path)


@pytest.mark.skipif(not hasattr(os, "fork") or not os.path.exists("/proc/self"), reason="RLIMIT_AS: Linux")
def test_a_huge_marker_count_is_refused_before_naming_every_marker(tmp_path):
    """POINT:USED 3e9 (a float parameter) in a 2 KB file: the file is too short for it, said as
    truncated; the reader made the 3e9 markers' names first (MemoryError, or the process killed
    for memory).  Read in a child process whose address space is capped at 2 GB."""
    import subprocess
    import sys
    path = _with_float_params(tmp_path, "huge.c3d", {("USED", 1): 3e9})
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))\n"
            "from blender_manikin.core.io_c3d import read_c3d\n"
            "from blender_manikin.core.recording import RecordingError\n"
            "try:\n    read_c3d(%r)\nexcept RecordingError as exc:\n    print('REFUSED', exc)\n" % str(path))
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root,
                         env={**os.environ, "PYTHONPATH": root, "OPENBLAS_NUM_THREADS": "1"})
    assert run.returncode == 0 and "REFUSED" in run.stdout and "truncated: 4 frames" in run.stdout, \
        run.stdout + run.stderr

def test_c3d_is_a_keypoint_input_everywhere(tmp_path, motion):
    """The CLI's and convert's folder discovery and the Blender file filter (``formats``' input
    extensions) take ``.c3d``."""
    from blender_manikin.cli import expand_inputs
    from blender_manikin.core import formats
    from blender_manikin.core.convert import collect_inputs
    assert ".c3d" in formats.input_extensions()
    names, pts = _pig(motion)
    path = write_c3d(tmp_path / "walk.c3d", names, to_y_up(pts, 1000.0))
    assert is_keypoint_input(path) and not is_keypoint_input(os.path.join(tmp_path, "none.c3d"))
    assert expand_inputs([str(tmp_path)]) == [str(path)]
    assert collect_inputs([str(tmp_path)]) == [os.path.abspath(path)]


@pytest.mark.parametrize("stale", [2, 9])
def test_the_headers_data_block_wins_over_a_stale_point_data_start(tmp_path, stale):
    """POINT:DATA_START disagreeing with the header's word 9 (a parameter left stale by an editing
    tool): the data are read where the header says, as py-c3d and ezc3d read them.  Before: block 2
    (inside the parameter section) read as frames, values 2.8 m off; block 9 refused as outside the
    file."""
    from blender_manikin.core.io_c3d import read_c3d
    pts = np.random.default_rng(2).uniform(-100, 100, (6, 3, 3))
    c = read_c3d(write_c3d(tmp_path / "stale.c3d", ["A", "B", "C"], pts, data_start_param=stale))
    np.testing.assert_allclose(c.points, pts, atol=0.051)


def test_a_long_take_counted_in_point_long_frames(tmp_path):
    """A take longer than 65535 frames whose count is in POINT:LONG_FRAMES (a float, as QTM writes
    it; POINT:FRAMES capped at 65535, the header's last frame 65535, no TRIAL fields): all 70000
    frames.  Before: 65535, the last 4465 dropped without a word."""
    from blender_manikin.core.io_c3d import read_c3d
    pts = np.random.default_rng(3).uniform(-100, 100, (70000, 2, 3))
    c = read_c3d(write_c3d(tmp_path / "qtm.c3d", ["A", "B"], pts, rate=100.0, long_frames=True))
    assert c.points.shape == (70000, 2, 3)
    np.testing.assert_allclose(c.points[-1], pts[-1], atol=0.051)
