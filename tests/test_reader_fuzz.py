"""Readers never crash: whatever the bytes, a reader returns a Recording or raises RecordingError
naming the file, and so does the resampling of what it returns (property-based: random bytes,
every truncation, flipped bytes).  Below, deterministic damage (fixed seeds) to a small valid file of
every reader's format, tracker recordings, keypoints, subject parameters, joint maps, BVH, ASF / AMC,
layout and offsets files, and the faults it found as minimal cases.  A bounded fuzz
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


# --------------------------------------------------------------------------------------------
# Deterministic damage to every reader's file (fixed seeds): truncations, byte flips, count and
# length fields set huge or negative, lines duplicated / swapped / deleted, a number replaced by
# nan / inf / 1e309 / "-" / an empty cell, a non-UTF-8 byte, a BOM, CRLF, an empty file, zeros.
# A reader either succeeds (finite, well-shaped data, NaN only where documented) or raises its
# format's error naming the file; anything else is a fault.
import random  # noqa: E402
import re  # noqa: E402
import struct  # noqa: E402
import warnings  # noqa: E402

NUMBER = re.compile(rb"(?<![\w.])-?\d+\.\d+(?:[eE][-+]?\d+)?")


def _lines_of(data):
    return data.split(b"\n")


def text_variants(data, seed=0, n=6):
    """(label, bytes) of damaged copies of the text file ``data``."""
    rng = random.Random(seed)
    yield "empty", b""
    yield "zeros", bytes(256)
    yield "bom", b"\xef\xbb\xbf" + data
    yield "crlf", data.replace(b"\n", b"\r\n")
    lines = _lines_of(data)
    for k in range(n):
        i = rng.randrange(len(lines))
        bad = list(lines)
        bad[i] = bad[i][: len(bad[i]) // 2] + b"\xff\xfe" + bad[i][len(bad[i]) // 2:]
        yield f"non-utf8 line {i + 1}", b"\n".join(bad)
    for k in range(n * 2):
        cut = rng.randrange(len(data))
        yield f"cut at {cut}", data[:cut]
    for k in range(n):
        i = rng.randrange(len(lines))
        yield f"line {i + 1} duplicated", b"\n".join(lines[:i + 1] + lines[i:])
        yield f"line {i + 1} deleted", b"\n".join(lines[:i] + lines[i + 1:])
        j = rng.randrange(len(lines))
        sw = list(lines)
        sw[i], sw[j] = sw[j], sw[i]
        yield f"lines {i + 1} and {j + 1} swapped", b"\n".join(sw)
    numbers = list(NUMBER.finditer(data))
    if numbers:
        for word in (b"nan", b"inf", b"-inf", b"1e309", b"-", b"", b"1e-320", b"0"):
            for k in range(n):
                m = numbers[rng.randrange(len(numbers))]
                yield f"number at byte {m.start()} -> {word!r}", data[:m.start()] + word + data[m.end():]
    for k in range(n * 2):
        bad = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            bad[rng.randrange(len(bad))] = rng.randrange(256)
        yield f"flips seed {seed}/{k}", bytes(bad)


def binary_variants(data, seed=0, n=6, fields=(), head=160, step=3):
    """(label, bytes) of damaged copies of the binary file ``data``; fields: ``(offset, struct
    format)`` of its count / length fields, each set huge, negative and zero."""
    rng = random.Random(seed)
    yield "empty", b""
    yield "zeros", bytes(len(data))
    for cut in range(0, min(head, len(data)), step):
        yield f"cut at {cut}", data[:cut]
    for k in range(n * 2):
        cut = rng.randrange(len(data))
        yield f"cut at {cut}", data[:cut]
    for off, fmt in fields:
        size = struct.calcsize(fmt)
        for value in ("huge", "negative", "zero", "max"):
            raw = {"huge": b"\xff\xff\xff\x7f", "negative": b"\xff\xff\xff\xff", "zero": b"\0\0\0\0",
                   "max": b"\xff\xff\xff\xff"}[value]
            if fmt.endswith(("h", "H")):
                raw = {"huge": b"\xff\x7f", "negative": b"\xff\xff", "zero": b"\0\0", "max": b"\xff\xff"}[value]
            if fmt.startswith(">"):
                raw = raw[::-1]
            yield f"{value} field at byte {off}", data[:off] + raw[:size] + data[off + size:]
    for where, span in (("head", (0, min(head, len(data)))), ("body", (min(head, len(data) - 1), len(data)))):
        for k in range(n * 2):
            bad = bytearray(data)
            for _ in range(rng.randint(1, 4)):
                bad[rng.randrange(*span)] = rng.randrange(256)
            yield f"{where} flips {k}", bytes(bad)


def _bsor_fields(data):
    """(offset, "<i") of a BSOR's string lengths and its frame count."""
    out, off = [], 6
    for _ in range(13):
        out.append((off, "<i"))
        off += 4 + struct.unpack_from("<i", data, off)[0]
    off += 4
    for _ in range(3):
        out.append((off, "<i"))
        off += 4 + struct.unpack_from("<i", data, off)[0]
    off += struct.calcsize("<fBffff") + 1
    out.append((off, "<i"))
    return out


def _keypoint_motion():
    from fixtures_keypoints import hinge_motion
    return hinge_motion(frames=12, seed=1)


_NPY = []


def _samples(tmp):
    """name -> (file name, bytes, binary?, fields) of a small valid file of each format."""
    import json
    from fixtures_keypoints import write_layout_csv, write_layout_npy, write_trc
    from fixtures_recordings import write_wide_poses
    out = {k.lstrip("_."): (f"fuzz{k if k.startswith('.') else '.csv'}", v, k in (".bsor", ".xror"), ())
           for k, v in VALID.items()}
    csv = open(EXAMPLE, "rb").read()[:6000]
    out["csv"] = ("fuzz.csv", csv[:csv.rindex(b"\n") + 1], False, ())
    bsor = out["bsor"][1]
    out["bsor"] = ("fuzz.bsor", bsor, True, _bsor_fields(bsor))
    if "xror" in out:
        x = out["xror"][1]
        out["xror"] = ("fuzz.xror", x, True, [(0, "<i")] + [(m.end() + 1, "<i") for m in re.finditer(b"frames", x)])
    # a wide CSV in seconds and metres
    t = np.arange(20) / 60.0
    pos = {d: np.tile([0.0, 0.0, 1.6 - 0.4 * (d != "head")], (20, 1)) for d in ("head", "left_hand", "right_hand")}
    quat = {d: np.tile([1.0, 0.0, 0.0, 0.0], (20, 1)) for d in pos}
    write_wide_poses(tmp / "wide.csv", t, pos, quat, {"head": "hmd", "left_hand": "left_controller",
                                                     "right_hand": "right_controller"})
    out["wide csv"] = ("fuzz.csv", (tmp / "wide.csv").read_bytes(), False, ())
    # Unity .anim
    from test_io_unity_anim import anim_text, motion as anim_motion
    at, objs = anim_motion(n=8)
    text = anim_text({p: {"time": at, "pos": ps, "quat": q} for p, (ps, q) in objs.items()})
    out["anim"] = ("fuzz.anim", text.encode(), False, ())
    # keypoints
    body, kpos, world = _keypoint_motion()
    write_layout_npy(tmp / "k.npy", "halpe26", body, kpos, world)
    npy = (tmp / "k.npy").read_bytes()
    out["keypoints npy"] = ("fuzz.npy", npy, True, [(8, "<H")])
    _NPY[:] = [npy]
    from fixtures_keypoints import write_freemocap
    write_freemocap(str(tmp / "fmc"), body, kpos, world, hands=False)
    fmc = (tmp / "fmc" / "output_data" / "mediapipe_body_3d_xyz.npy").read_bytes()
    out["freemocap"] = ("take/output_data/mediapipe_body_3d_xyz.npy", fmc, True, [(8, "<H")])
    np.savez(tmp / "k.npz", keypoints=np.load(tmp / "k.npy"))
    out["keypoints npz"] = ("fuzz.npz", (tmp / "k.npz").read_bytes(), True, [])
    write_layout_csv(tmp / "k.csv", "halpe26", body, kpos, world)
    out["keypoints csv"] = ("fuzz.csv", (tmp / "k.csv").read_bytes(), False, ())
    write_trc(tmp / "k.trc", body, kpos, world)
    out["trc"] = ("fuzz.trc", (tmp / "k.trc").read_bytes(), False, ())
    from fixtures_c3d import write_c3d
    from test_marker_sets import anatomical_markers
    names, pts = anatomical_markers(kpos, world, body.stature, "plugingait", medial=True)
    from fixtures_keypoints import to_y_up
    write_c3d(tmp / "k.c3d", names, to_y_up(pts, 1000.0), rate=60.0)
    c3d = (tmp / "k.c3d").read_bytes()
    pstart = (c3d[0] - 1) * 512
    out["c3d"] = ("fuzz.c3d", c3d, True, [(0, "<B"), (2, "<H"), (4, "<H"), (6, "<H"), (8, "<H"), (10, "<H"),
                                          (pstart + 2, "<B")])
    # subject parameters, joint map, BVH, ASF / AMC, layout, offsets
    from test_subject_params import MP, VSK
    out["mp"] = ("fuzz.mp", MP.encode(), False, ())
    out["vsk"] = ("fuzz.vsk", VSK.encode(), False, ())
    from test_joint_map_files import _lafan1_file_dict
    out["joint map"] = ("fuzz.json", json.dumps(_lafan1_file_dict(), indent=1).encode(), False, ())
    from fixtures_bvh import synthetic_motion, write_fixture, mixamo_clip
    b, _, _, bp, br = synthetic_motion(frames=6, seed=2)
    write_fixture(tmp / "m.bvh", mixamo_clip(b, bp, br))
    out["bvh"] = ("fuzz.bvh", (tmp / "m.bvh").read_bytes(), False, ())
    from test_asf_amc import TINY_AMC, TINY_ASF
    out["asf"] = ("fuzz.asf", TINY_ASF.encode(), False, ())
    out["amc"] = ("fuzz.amc", TINY_AMC.encode(), False, ())
    from blender_manikin.core.io_wide_csv import save_layout
    layout = formats.load_recording(tmp / "wide.csv").metadata["layout"]
    save_layout(tmp / "layout.json", layout)
    out["layout"] = ("fuzz.json", (tmp / "layout.json").read_bytes(), False, ())
    from blender_manikin.core.device_offsets import save_offsets
    save_offsets(tmp / "off.json", "openxr_generic")
    out["offsets"] = ("fuzz.json", (tmp / "off.json").read_bytes(), False, ())
    return out



def _npy_header_variants(data):
    """A .npy whose header's shape is huge, negative or not a shape."""
    size = 10 + struct.unpack_from("<H", data, 8)[0]

    def header(pattern, value):         # the header's text changed, padded to its length
        text = re.sub(pattern, value, data[10:size], count=1).rstrip(b" \n")
        return data[:10] + text.ljust(size - 11) + b"\n" + data[size:]
    for shape in (b"(99999999999, 26, 3)", b"(-5, 26, 3)", b"(0, 26, 3)", b"(12, 26)", b"()", b"(12, 0, 3)",
                  b"(2**62, 26, 3)", b"(12, -26, -3)"):
        yield f"shape {shape.decode()}", header(rb"\(\d+, \d+, \d+\)", shape)
    for descr in (b"'|O'", b"'<U8'", b"'<c16'", b"'>f8'", b"'<f2'", b"'<V0'"):
        yield f"descr {descr.decode()}", header(rb"'<f8'", descr)
    for k in range(2, 60, 3):                   # the header's text cut short, its brackets unclosed
        yield f"header text cut at {k}", data[:10] + data[10:10 + k]


def _npz_variants(npy):
    """An .npz (stored) whose array is each of :func:`_npy_header_variants`."""
    import io
    import zipfile
    for label, member in _npy_header_variants(npy):
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            zf.writestr("keypoints.npy", member)
        yield "member " + label, buf.getvalue()


def variants(name, data, binary, fields):
    """Every damaged variant of the sample ``name`` (:func:`_samples`)."""
    if not binary:
        yield from text_variants(data)
        return
    head = {"c3d": 1100, "bsor": 400}.get(name, 160)
    yield from binary_variants(data, fields=fields, head=head, step=7 if name == "c3d" else 3)
    if name in ("keypoints npy", "freemocap"):
        yield from _npy_header_variants(data)
    if name == "keypoints npz":
        yield from _npz_variants(_NPY[0])


def _read_any(name, path):
    """Read ``path`` as the format ``name``; returns what the reader gives."""
    from blender_manikin.core.asf_amc import read_amc, read_asf
    from blender_manikin.core.bvh import read_bvh
    from blender_manikin.core.io_keypoints import read_keypoints
    from blender_manikin.core.io_wide_csv import load_layout
    from blender_manikin.core.joint_maps import load_joint_map
    from blender_manikin.core.subject_params import read_subject_params
    if name in ("keypoints npy", "keypoints npz", "keypoints csv", "trc", "c3d"):
        return read_keypoints(path)
    if name == "freemocap":                         # the recording folder
        return read_keypoints(path[:path.index("take") + 4])
    if name in ("mp", "vsk"):
        return read_subject_params(path)
    if name == "joint map":
        return load_joint_map(path)
    if name == "bvh":
        return read_bvh(path)
    if name == "asf":
        return read_asf(path)
    if name == "amc":
        from test_asf_amc import TINY_ASF
        import io
        return read_amc(path, read_asf(io.BytesIO(TINY_ASF.encode()), "tiny.asf"))
    if name == "layout":
        return load_layout(path)
    if name == "offsets":
        return load_offsets(path)
    return formats.load_recording(path)


def _error_types(name):
    from blender_manikin.core.bvh import BvhError
    if name in ("bvh", "asf", "amc"):
        return (BvhError,)
    if name in ("joint map", "offsets"):
        return (ValueError,)
    return (RecordingError,)


def check_variant(tmp, name, fname, data):
    """Read ``data`` as ``name`` (its file named ``fname``): success with well-shaped data, or the
    format's error naming the file.  Returns None or the error."""
    folder = tmp / name.replace(" ", "_")          # alone: a subject file beside a .c3d is read with it
    folder.mkdir(exist_ok=True)
    path = folder / fname
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            got = _read_any(name, str(path))
        except _error_types(name) as exc:
            assert os.path.basename(fname) in str(exc), f"{name}: the error does not name the file: {exc}"
            return exc
    if isinstance(got, Recording):
        for s in got.streams.values():
            assert s.pos.shape == (len(s.time), 3) and s.quat.shape == (len(s.time), 4)
            assert not np.isinf(s.time).any()       # NaN: a row without a time, dropped by resample
    return None


@pytest.fixture(scope="module")
def samples(tmp_path_factory):
    return _samples(tmp_path_factory.mktemp("samples"))


SAMPLE_NAMES = ("csv", "semicolons.csv", "wide csv", "json", "jsonl", "bsor", "xror", "anim", "keypoints npy",
                "keypoints npz", "freemocap", "keypoints csv", "trc", "c3d", "mp", "vsk", "joint map", "bvh", "asf",
                "amc", "layout", "offsets")


@pytest.mark.parametrize("name", SAMPLE_NAMES)
def test_damaged_files_are_read_or_refused_by_name(tmp_path, samples, name):
    """Every deterministic damaged variant of each format's small valid file is read (well-shaped,
    no FP warning) or refused with the format's error naming the file."""
    if name not in samples:
        pytest.skip("xror needs pymongo's bson and fpzip (requirements-xror.txt)")
    fname, data, binary, fields = samples[name]
    assert check_variant(tmp_path, name, fname, data) is None, "the undamaged sample must read"
    faults = []
    for label, bad in variants(name, data, binary, fields):
        try:
            check_variant(tmp_path, name, fname, bad)
        except Exception as exc:        # noqa: BLE001 - collected, to list every fault at once
            faults.append(f"{label}: {type(exc).__name__}: {exc}")
    assert not faults, "\n".join(faults[:20])


# --- the faults the damaged variants found, as minimal cases -------------------------------------
def _npy_bytes(header_text, payload=b""):
    """A version 1.0 .npy with ``header_text`` (padded) and ``payload``."""
    text = header_text.encode("latin1")
    text = text + b" " * (-(10 + len(text) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text + payload


def test_npy_whose_shape_asks_for_terabytes_is_refused_before_allocating(tmp_path):
    """Before: MemoryError (numpy asked for 56.8 TiB) from a digit flipped in the header."""
    path = tmp_path / "big.npy"
    path.write_bytes(_npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (99999999999, 26, 3), }",
                                bytes(8 * 26 * 3 * 4)))
    from blender_manikin.core.io_keypoints import read_keypoints
    with pytest.raises(RecordingError, match=r"big\.npy, byte offset 128: the array header says shape "
                                             r"\(99999999999, 26, 3\) of <f8 \(62399999999376 bytes\), but 2496 "
                                             r"bytes follow the header"):
        read_keypoints(path)



def test_cut_npy_of_one_number_is_said_as_cut(tmp_path):
    """A 0-d array (shape ``()``) whose 8 bytes are cut to 5: said as the header's shape and the
    bytes that follow (before: 'not a readable .npy array (min() arg is an empty sequence)')."""
    path = tmp_path / "one.npy"
    path.write_bytes(_npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (), }", bytes(5)))
    from blender_manikin.core.io_keypoints import read_keypoints
    with pytest.raises(RecordingError, match=r"one\.npy, byte offset 128: the array header says shape \(\) of <f8 "
                                             r"\(8 bytes\), but 5 bytes follow the header"):
        read_keypoints(path)

def test_npy_header_with_an_unclosed_bracket_is_refused(tmp_path):
    """Before: tokenize.TokenError ('EOF in multi-line statement') escaped np.load."""
    path = tmp_path / "cut.npy"
    path.write_bytes(_npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (12,"))
    from blender_manikin.core.io_keypoints import read_keypoints
    with pytest.raises(RecordingError, match=r"cut\.npy: not a readable \.npy array"):
        read_keypoints(path)


def test_damaged_npz_archive_is_refused(tmp_path, samples):
    """Before: zipfile.BadZipFile (a cut archive, a flipped byte: bad CRC)."""
    from blender_manikin.core.io_keypoints import read_keypoints
    data = samples["keypoints npz"][1]
    path = tmp_path / "cut.npz"
    path.write_bytes(data[:len(data) // 2])
    with pytest.raises(RecordingError, match=r"cut\.npz: not a readable \.npz archive"):
        read_keypoints(path)
    flipped = bytearray(data)
    flipped[200] ^= 0xFF                            # inside the stored array: its CRC no longer matches
    path.write_bytes(bytes(flipped))
    with pytest.raises(RecordingError, match=r"cut\.npz: not a readable \.npz archive"):
        read_keypoints(path)


def _replace_cell(data, line, column, text):
    """``data`` (CSV bytes) with the cell ``column`` (0-based) of ``line`` (1-based) set to ``text``."""
    lines = data.split(b"\n")
    sep = b";" if b";" in lines[0] else b","
    cells = lines[line - 1].split(sep)
    cells[column] = text
    lines[line - 1] = sep.join(cells)
    return b"\n".join(lines)


@pytest.mark.parametrize("name", ["wide csv", "csv"])
@pytest.mark.parametrize("cell", [b"inf", b"-1e309"])
def test_an_infinite_pose_cell_is_a_lost_sample(tmp_path, samples, name, cell):
    """Before: 'invalid value encountered in divide' (normalising an infinite quaternion) as a
    RuntimeWarning; now the cell counts as lost, as NaN and empty cells do."""
    fname, data, _, _ = samples[name]
    header = data.split(b"\n")[0].decode()
    line = next(k for k, text in enumerate(data.split(b"\n"), 1) if k > 1 and text[:1].isdigit())
    column = 5 if name == "csv" else header.split(",").index("hmd_rot_x")
    path = tmp_path / fname
    path.write_bytes(_replace_cell(data, line, column, cell))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rec = formats.load_recording(path)
    for s in rec.streams.values():
        ok = s.valid & np.all(np.isfinite(s.pos), -1) & np.all(np.isfinite(s.quat), -1)
        assert not np.isinf(s.pos).any() and not np.isinf(s.quat).any()
        assert ok.sum() >= len(s) - 1


def test_a_time_past_float64_range_is_not_an_infinite_time(tmp_path, samples):
    """Before: a wide CSV's time cell '1e309' gave a stream whose time was inf."""
    fname, data, _, _ = samples["wide csv"]
    path = tmp_path / fname
    path.write_bytes(_replace_cell(data, 5, 0, b"1e309"))
    rec = formats.load_recording(path)
    assert not any(np.isinf(s.time).any() for s in rec.streams.values())
    times = resample(seconds_from_time_units(rec), 30.0)[0]
    assert np.all(np.isfinite(times))


def test_an_infinite_anim_key_value_is_named_with_its_line(tmp_path, samples):
    """Before: RuntimeWarning from normalising the key's quaternion (the key read as NaN)."""
    fname, data, _, _ = samples["anim"]
    text = data.decode()
    m = re.search(r"value: \{x: ([-\d.e]+)", text[text.index("m_RotationCurves"):])
    start = text.index("m_RotationCurves") + m.start(1)
    line = text.count("\n", 0, start) + 1 - 2      # the error names the key's first line ("- serializedVersion")
    path = tmp_path / fname
    path.write_text(text[:start] + "-inf" + text[start + len(m.group(1)):])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(RecordingError, match=rf"fuzz\.anim, line {line}: m_RotationCurves\[0\]: key value\.x "
                                                 r"-inf is not finite"):
            formats.load_recording(path)


def test_a_keypoint_past_any_scale_counts_as_missing(tmp_path, samples):
    """Before: 'overflow encountered in multiply' (squaring 1e300 for a bone length)."""
    from blender_manikin.core.io_keypoints import read_keypoints
    fname, data, _, _ = samples["keypoints csv"]
    path = tmp_path / fname
    path.write_bytes(_replace_cell(data, 3, 1, b"1e300"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rec = read_keypoints(path)
    assert np.isnan(rec.points[1, 0]).all() and np.isfinite(rec.points[0, 0]).all()


def test_a_signalling_nan_in_xror_frames_is_a_lost_sample(tmp_path):
    """Before: 'invalid value encountered in cast' (float32 -> float64 of a signalling NaN, which
    fpzip's decoder returns for some damaged streams) as a RuntimeWarning."""
    bson = pytest.importorskip("bson")
    fpzip = pytest.importorskip("fpzip")
    t = np.arange(30) / 90.0
    rows = np.concatenate([t[:, None], np.tile([0, 1.6, 0, 0, 0, 0, 1.0], (30, 3))], 1).astype(np.float32)
    rows.view(np.uint32)[7, 1 + 7 + 2] = 0x7F800001          # a signalling NaN: the left hand's z at frame 7
    devs = [{"joint": j, "axes": ["x", "y", "z", "i", "j", "k", "1"]} for j in ("HEAD", "HAND_LEFT", "HAND_RIGHT")]
    path = tmp_path / "snan.xror"
    path.write_bytes(bson.encode({"info": {"hardware": {"devices": devs}},
                                  "frames": fpzip.compress(np.ascontiguousarray(rows[None, None]))}))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rec = formats.load_recording(path)
    left = rec.streams["left_hand"]
    assert np.isclose(left.time, 7 / 90.0).sum() == 0 or not left.valid[7]
    assert len(rec.streams["head"]) == 30
