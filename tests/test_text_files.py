"""Text files as users' tools save them (core/recording.decode_text, one place for every text
reader): UTF-8 with a BOM, UTF-16 LE/BE with a BOM (Excel's "Unicode Text", Windows
PowerShell's ``Out-File``), CRLF and lone-CR line ends, no final newline; and stand-ins for the
data (a Git LFS pointer, an HTML error page, a gzip file) named like a recording."""
import gzip
import os

import numpy as np
import pytest

from blender_manikin.core import formats
from blender_manikin.core.io_keypoints import read_keypoints
from blender_manikin.core.recording import RecordingError
from fixtures_keypoints import hinge_motion, write_layout_csv, write_layout_npy, write_trc
from fixtures_recordings import make_recording, write_recording_csv, write_wide_poses

from test_io_unity_anim import anim_text, motion
from test_json_recording import unity_json

LFS = b"version https://git-lfs.github.com/spec/v1\noid sha256:4d7a2146\nsize 12345\n"
HTML = b"<!DOCTYPE html>\n<html><head><title>404 Not Found</title></head><body>Not Found</body></html>\n"

RECODE = {
    "utf8_bom": lambda b: b"\xef\xbb\xbf" + b,
    "utf16le": lambda b: b.decode("utf-8").encode("utf-16-le").join([b"\xff\xfe", b""]),
    "utf16be": lambda b: b.decode("utf-8").encode("utf-16-be").join([b"\xfe\xff", b""]),
    "utf16le_no_bom": lambda b: b.decode("utf-8").encode("utf-16-le"),
    "crlf": lambda b: b.replace(b"\n", b"\r\n"),
    "cr": lambda b: b.replace(b"\n", b"\r"),
    "no_final_newline": lambda b: b.rstrip(b"\n"),
}


def _wide(path):
    st = make_recording(duration=2.0).streams
    t = st["head"].time
    pos = {d: np.stack([np.interp(t, st[d].time, st[d].pos[:, k]) for k in range(3)], -1) for d in st}
    quat = {d: np.tile([1.0, 0, 0, 0], (len(t), 1)) for d in st}
    return write_wide_poses(path, t, pos, quat, {"head": "Head", "left_hand": "LeftHand", "right_hand": "RightHand"})


def _sources(tmp_path):
    body, P, W = hinge_motion(frames=40)
    write_layout_csv(tmp_path / "kp.csv", "coco17", body, P, W)
    write_trc(os.fspath(tmp_path / "kp.trc"), body, P, W)
    t, m = motion(30)
    (tmp_path / "take.anim").write_text(anim_text({p: {"time": t, "pos": x, "quat": q} for p, (x, q) in m.items()}))
    return {"take.anim": os.fspath(tmp_path / "take.anim"),
            "native.csv": write_recording_csv(tmp_path, "native.csv", duration=2.0)[0],
            "wide.csv": _wide(os.fspath(tmp_path / "wide.csv")),
            "take.json": os.fspath(unity_json(tmp_path / "take.json")),
            "kp.csv": os.fspath(tmp_path / "kp.csv"), "kp.trc": os.fspath(tmp_path / "kp.trc")}


def _read(path):
    """The arrays a reader gives: keypoints (T, K, 3), or each device's positions and times."""
    if os.path.basename(path).startswith("kp"):
        k = read_keypoints(path)
        return {"points": k.points}
    rec = formats.load_recording(path)
    return {f"{d}.{a}": getattr(s, a) for d, s in rec.streams.items() for a in ("time", "pos", "quat")}


@pytest.mark.parametrize("variant", sorted(RECODE))
def test_every_text_reader_reads_every_encoding_and_line_end(tmp_path, variant):
    for name, src in _sources(tmp_path).items():
        ref = _read(src)
        root, ext = os.path.splitext(name)
        dst = os.fspath(tmp_path / f"{root}_{variant}{ext}")
        with open(src, "rb") as f:
            data = RECODE[variant](f.read())
        with open(dst, "wb") as f:
            f.write(data)
        got = _read(dst)
        assert got.keys() == ref.keys(), (name, variant)
        for k in ref:
            np.testing.assert_array_equal(got[k], ref[k], err_msg=f"{name} {variant} {k}")


def test_excel_unicode_text_tab_separated_utf16(tmp_path):
    """Excel's "Unicode Text": tab-separated, UTF-16 LE with a BOM, CRLF."""
    src = _wide(os.fspath(tmp_path / "wide.csv"))
    with open(src, encoding="utf-8") as f:
        text = f.read().replace(",", "\t").replace("\n", "\r\n")
    dst = tmp_path / "Übung 1.csv"
    dst.write_bytes(text.encode("utf-16"))
    ref, got = formats.load_recording(src), formats.load_recording(dst)
    for d in ref.streams:
        np.testing.assert_array_equal(got.streams[d].pos, ref.streams[d].pos)


# a gzip file named as a binary format (.bsor, .npy, .npz) is that format's own error
@pytest.mark.parametrize("stand_in, problem, name", [
    (stand_in, problem, name)
    for stand_in, problem in ((LFS, "Git LFS pointer"), (HTML, "HTML page"), ("gzip", "gzip-compressed"))
    for name in ("take.csv", "take.json", "take.anim", "kp.trc", "take.bsor", "kp.npy", "kp.npz", "テイク_01.csv.gz")
    if not (stand_in == "gzip" and name.endswith((".npz", ".npy", ".bsor")))])
def test_stand_ins_for_the_data_are_named(tmp_path, stand_in, problem, name):
    if stand_in == "gzip":
        stand_in = gzip.compress(b"time,device,px,py,pz,qw,qx,qy,qz\n0,head,0,1.6,0,1,0,0,0\n")
    path = tmp_path / name
    path.write_bytes(stand_in)
    read = read_keypoints if name.startswith("kp") else formats.load_recording
    with pytest.raises(RecordingError, match=rf"^{name.replace('.', '[.]')}: .*{problem}"):
        read(path)


def test_keypoint_csv_in_utf16_is_recognised_as_keypoints(tmp_path):
    from blender_manikin.core.io_keypoints import is_keypoint_input
    body, P, W = hinge_motion(frames=20)
    write_layout_csv(tmp_path / "kp.csv", "coco17", body, P, W)
    (tmp_path / "kp16.csv").write_bytes((tmp_path / "kp.csv").read_text(encoding="utf-8").encode("utf-16"))
    assert is_keypoint_input(tmp_path / "kp16.csv")


def test_a_bad_byte_is_named_with_its_line(tmp_path):
    """Latin-1 where UTF-8 was expected (native CSV), and a broken UTF-16 file: file, line, byte."""
    path, _ = write_recording_csv(tmp_path, "take.csv", duration=1.0)
    lines = open(path, "rb").read().split(b"\n")
    lines[3] = lines[3] + b" \xb5m"          # '# ... µm' in cp1252
    open(path, "wb").write(b"\n".join(lines))
    with pytest.raises(RecordingError, match=r"take.csv, line 4: not UTF-8 text \(byte 0xb5\): save it as UTF-8"):
        formats.load_recording(path)
    from blender_manikin.core.recording import decode_text
    data = "a\nb\nc\n".encode("utf-16") + b"\x00\xd8"    # a lone high surrogate at the end, line 4
    with pytest.raises(RecordingError, match=r"x.csv, line 4: not UTF-16-LE text"):
        decode_text(data, path="x.csv")


def test_npy_keypoints_still_read(tmp_path):
    """The stand-in check runs only when numpy cannot read the file: a real .npz is a ZIP."""
    body, P, W = hinge_motion(frames=20)
    clean = write_layout_npy(tmp_path / "kp.npy", "coco17", body, P, W)
    a = np.load(tmp_path / "kp.npy")
    np.savez(tmp_path / "kp.npz", keypoints=a, layout="coco17")
    assert read_keypoints(tmp_path / "kp.npz").points.shape == clean.shape
