"""BVH reader/writer: channel layouts, rotation orders, compressed sources, errors."""
import gzip
import io
import os
import tarfile

import numpy as np
import pytest

from blender_manikin.core import bvh
from blender_manikin.core.bvh import (BvhClip, BvhError, euler_to_matrix, iter_bvh_sources,
                                      matrix_to_euler, read_bvh, write_bvh)
from blender_manikin.core.rotations import quat_to_matrix

from fixtures_bvh import bandai_clip, relayout, synthetic_motion

ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


@pytest.fixture(scope="module")
def motion():
    return synthetic_motion(frames=60, seed=3)


@pytest.fixture(scope="module")
def bandai(motion):
    body, _, _, pos, rot = motion
    return bandai_clip(body, pos, rot)


def _roundtrip(clip, tmp_path, fname):
    path = tmp_path / fname
    write_bvh(path, clip)
    return read_bvh(path)


# --------------------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_euler_roundtrip_every_order(order):
    rng = np.random.default_rng(1)
    R = quat_to_matrix(rng.normal(size=(500, 4)))
    e = matrix_to_euler(R, order)
    assert np.abs(euler_to_matrix(e, order) - R).max() < 1e-12
    # gimbal lock: middle angle +-90 degrees
    g = rng.uniform(-180, 180, size=(50, 3))
    g[:, 1] = np.where(rng.random(50) < 0.5, 90.0, -90.0)
    Rg = euler_to_matrix(g, order)
    assert np.abs(euler_to_matrix(matrix_to_euler(Rg, order), order) - Rg).max() < 1e-12


def test_euler_matches_channel_composition():
    # "Zrotation Xrotation Yrotation" (a, b, c) = Rz(a) Rx(b) Ry(c)
    a, b, c = 30.0, -50.0, 70.0
    Rz = euler_to_matrix([a], "Z")
    Rx = euler_to_matrix([b], "X")
    Ry = euler_to_matrix([c], "Y")
    assert np.allclose(euler_to_matrix([a, b, c], "ZXY"), Rz @ Rx @ Ry)
    # right-handed: +90 about Z takes +X to +Y
    assert np.allclose(euler_to_matrix([90.0], "Z") @ [1, 0, 0], [0, 1, 0])
    with pytest.raises(ValueError):
        matrix_to_euler(euler_to_matrix([10.0, 20.0], "XY"), "Z")


def test_layouts_and_orders_give_same_positions(bandai, tmp_path):
    ref_pos, ref_rot = bandai.global_transforms()
    names = bandai.joint_names
    layouts = {
        "bandai_zxy_6ch": {},
        "root6_rest3_xyz": {n: (("Zposition", "Xposition", "Yposition", "Yrotation", "Xrotation", "Zrotation")
                                if n in ("joint_Root", "Hips") else ("Xrotation", "Yrotation", "Zrotation"))
                            for n in names},
        "rotation_first_yzx": {n: ("Yrotation", "Zrotation", "Xrotation", "Xposition", "Yposition", "Zposition")
                               for n in names},
        "mixed_orders": {n: ((bvh.POSITION_CHANNELS if n in ("joint_Root", "Hips") else ())
                             + tuple(f"{a}rotation" for a in ORDERS[i % 6])) for i, n in enumerate(names)},
    }
    for label, chans in layouts.items():
        clip = relayout(bandai, chans) if chans else bandai
        back = _roundtrip(clip, tmp_path, f"{label}.bvh")
        assert back.channels == clip.channels
        pos, rot = back.global_transforms()
        assert np.abs(pos - ref_pos).max() < 1e-6, label      # cm
        assert np.abs(rot - ref_rot).max() < 1e-8, label


def test_channel_subsets_and_position_replacement(tmp_path):
    # root moves only in Y and yaws about Y; the child has one X rotation and a
    # Zposition channel that replaces only the z of its OFFSET
    T = 5
    yaw = np.linspace(0, 90, T)
    ty = np.linspace(10, 20, T)
    bend = np.linspace(0, 45, T)
    tz = np.linspace(0, 4, T)
    motion = np.stack([ty, yaw, bend, tz], axis=1)
    clip = BvhClip("subset", ("root", "child"), [-1, 0], [[1, 2, 3], [5, 6, 7]],
                   (("Yposition", "Yrotation"), ("Xrotation", "Zposition")), 0.04, motion,
                   end_sites=[[np.nan] * 3, [0, 0, 3]])
    back = _roundtrip(clip, tmp_path, "subset.bvh")
    assert back.channels == (("Yposition", "Yrotation"), ("Xrotation", "Zposition"))
    assert np.allclose(back.end_sites[1], [0, 0, 3]) and np.all(np.isnan(back.end_sites[0]))
    pos, rot = back.global_transforms()
    assert np.allclose(pos[:, 0], np.stack([np.ones(T), ty, 3 * np.ones(T)], 1))
    Ry = euler_to_matrix(yaw[:, None], "Y")
    child_local = np.stack([np.full(T, 5.0), np.full(T, 6.0), tz], 1)
    assert np.allclose(pos[:, 1], pos[:, 0] + np.einsum("tij,tj->ti", Ry, child_local))
    assert np.allclose(rot[:, 1], Ry @ euler_to_matrix(bend[:, None], "X"))
    assert back.fps == pytest.approx(25.0)


def test_header_details(tmp_path):
    text = (
        "HIERARCHY\r\nROOT Hips {\r\n OFFSET 0 0 0\r\n CHANNELS 6 Xposition Yposition Zposition"
        " Zrotation Xrotation Yrotation\r\n JOINT Left Leg\r\n {\r\n  OFFSET 1 -2 0\r\n"
        "  CHANNELS 3 zrotation xrotation yrotation\r\n  End Site\r\n  {\r\n   OFFSET 0 -3 0\r\n  }\r\n"
        " }\r\n}\r\nMOTION\r\nFrames: 2\r\nFrame Time: 0.0333333\r\n"
        "0 90 0 0 0 0 0 0 0\r\n\r\n1 90 0 90 0 0 0 0 0\r\n"
    )
    clip = read_bvh(io.BytesIO(text.encode()), name="dir/crlf.bvh")
    assert clip.name == "crlf" and clip.source == "crlf.bvh"
    assert clip.joint_names == ("Hips", "Left Leg")
    assert clip.channels[1] == ("Zrotation", "Xrotation", "Yrotation")
    assert clip.num_frames == 2 and clip.fps == pytest.approx(30.0, abs=1e-3)
    pos, _ = clip.global_transforms()
    assert np.allclose(pos[0, 1], [1, 88, 0])
    assert np.allclose(pos[1, 1], [3, 91, 0])      # root (1,90,0) + Rz(90) (1,-2,0) = (2,1,0)
    assert np.allclose(clip.rest_positions(), [[0, 0, 0], [1, -2, 0]])


def test_zero_frames_and_text_stream():
    text = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\n" \
           "MOTION\nFrames: 0\nFrame Time: 0.01\n"
    clip = read_bvh(io.StringIO(text))
    assert clip.motion.shape == (0, 3)
    pos, rot = clip.global_transforms()
    assert pos.shape == (0, 1, 3) and rot.shape == (0, 1, 3, 3)


# --------------------------------------------------------------------------
def test_gzip_and_archives(bandai, tmp_path):
    small = BvhClip(bandai.name, bandai.joint_names, bandai.parents, bandai.offsets, bandai.channels,
                    bandai.frame_time, bandai.motion[:10], end_sites=bandai.end_sites)
    ref = small.global_transforms()[0]
    src = tmp_path / "src"
    (src / "sub").mkdir(parents=True)
    write_bvh(src / "b_walk.bvh", small)
    write_bvh(src / "sub" / "a_run.bvh.gz", small)
    (src / "sub" / "a_run.json").write_text("{}")
    with gzip.open(src / "sub" / "a_run.bvh.gz", "rb") as f:
        assert f.read(9) == b"HIERARCHY"

    def check(name, opener):
        with opener() as f:
            clip = read_bvh(f, name=name)
        assert np.allclose(clip.global_transforms()[0], ref, atol=1e-6)
        return clip

    # directory (recursive, sorted), single files
    items = list(iter_bvh_sources(src))
    assert [n for n, _ in items] == ["b_walk.bvh", "sub/a_run.bvh.gz"]
    for n, op in items:
        check(n, op)
    assert read_bvh(src / "sub" / "a_run.bvh.gz").name == "a_run"
    assert [n for n, _ in iter_bvh_sources(src / "b_walk.bvh")] == ["b_walk.bvh"]

    # archives: members come sorted by name, json skipped, nothing unpacked
    for ext, mode in ((".tar.xz", "w:xz"), (".tar.gz", "w:gz"), (".tar", "w")):
        arc = tmp_path / f"set{ext}"
        with tarfile.open(arc, mode) as tf:
            tf.add(src / "b_walk.bvh", arcname="./data/b_walk.bvh")
            tf.add(src / "sub" / "a_run.json", arcname="./data/a_run.json")
            tf.add(src / "sub" / "a_run.bvh.gz", arcname="./data/a_run.bvh.gz")
        before = set(os.listdir(tmp_path))
        items = list(iter_bvh_sources(arc))
        assert [n for n, _ in items] == ["data/a_run.bvh.gz", "data/b_walk.bvh"]
        clips = [check(n, op) for n, op in items]
        assert [c.name for c in clips] == ["a_run", "b_walk"]
        # openers can be called again, in any order
        check(*items[1]), check(*items[0])
        streamed = [n for n, _ in iter_bvh_sources(arc, sort=False)]
        assert sorted(streamed) == ["data/a_run.bvh.gz", "data/b_walk.bvh"]
        assert set(os.listdir(tmp_path)) == before

    with pytest.raises(FileNotFoundError):
        list(iter_bvh_sources(tmp_path / "nope"))


# --------------------------------------------------------------------------
GOOD = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 90 0 0 0 0 0 0 0
0 91 0 0 0 0 0 0 0
0 92 0 0 0 0 0 0 0
"""


def _err(text, name="walk.bvh"):
    with pytest.raises(BvhError) as e:
        read_bvh(io.BytesIO(text.encode()), name=name)
    return str(e.value)


def test_good_fixture_parses():
    clip = read_bvh(io.BytesIO(GOOD.encode()), name="walk.bvh")
    assert clip.motion.shape == (3, 9)
    assert np.allclose(clip.end_sites[1], [0, 5, 0])


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16"])
def test_byte_order_mark_and_utf16(encoding):
    """A BVH saved with a byte-order mark (Windows tools: Notepad, .NET's Encoding.UTF8) or as
    UTF-16 (PowerShell's Out-File) reads like plain UTF-8 (it was "line 1: expected 'HIERARCHY',
    got '\\ufeffHIERARCHY'"); CRLF line ends too."""
    data = GOOD.replace("JOINT Spine", "JOINT Rücken").replace("\n", "\r\n").encode(encoding)
    clip = read_bvh(io.BytesIO(data), name="walk.bvh")
    assert clip.joint_names == ("Hips", "Rücken") and clip.motion.shape == (3, 9)
    assert np.allclose(clip.motion[:, 1], [90, 91, 92])


def test_names_in_another_8_bit_encoding_stay_distinct():
    """A header that is not UTF-8 (Shift-JIS joint names, as MikuMikuDance tools write) is read
    as Latin-1, as the ASF/AMC reader does: 左足 and 左手 stay two joints (their bytes became the
    same U+FFFD run: "line 11: duplicate joint name '����'")."""
    text = GOOD.replace("ROOT Hips", "ROOT センター").replace("JOINT Spine", "JOINT 左足").replace(
        "End Site\n    {\n      OFFSET 0 5 0\n    }\n  }\n", "}\n  JOINT 左手\n  {\n    OFFSET 0 5 0\n"
        "    CHANNELS 3 Zrotation Xrotation Yrotation\n  }\n").replace(" 0 0 0 0 0 0 0\n", " 0 0 0 0 0 0 0 0 0 0\n")
    clip = read_bvh(io.BytesIO(text.encode("shift_jis")), name="mmd.bvh")
    assert [n.encode("latin-1").decode("shift_jis") for n in clip.joint_names] == ["センター", "左足", "左手"]
    assert clip.motion.shape == (3, 12)


def test_error_wrong_value_count():
    lines = GOOD.split("\n")
    lines[19] = "0 91 0 0 0 0 0"        # file line 20
    assert _err("\n".join(lines)) == "walk.bvh line 20: expected 9 values per frame, got 7"


def test_error_every_frame_short():
    lines = GOOD.split("\n")
    for i in (18, 19, 20):
        lines[i] = "0 90 0 0 0 0 0 0"
    assert _err("\n".join(lines)) == "walk.bvh line 19: expected 9 values per frame, got 8"


def test_error_not_a_number():
    lines = GOOD.split("\n")
    lines[20] = "0 92 0 0 x 0 0 0 0"
    assert _err("\n".join(lines)) == "walk.bvh line 21: value 5 is not a number: 'x'"


def test_error_frame_count():
    msg = _err(GOOD.replace("Frames: 3", "Frames: 4"))
    assert msg == "walk.bvh line 21: header declares 4 frames, MOTION block has 3"


def test_error_header_problems():
    assert _err(GOOD.replace("Zrotation Xrotation Yrotation\n    End", "Zrotation Xrotation Wrotation\n    End")) \
        .startswith("walk.bvh line 9: joint 'Spine': unknown channel 'Wrotation'")
    assert _err(GOOD.replace("OFFSET 0 10 0", "OFFSET 0 ten 0")) == \
        "walk.bvh line 8: expected a number for OFFSET of 'Spine', got 'ten'"
    assert _err(GOOD.replace("MOTION\n", "")) == "walk.bvh line 16: expected 'ROOT', got 'Frames:'"
    assert _err(GOOD.split("MOTION")[0]) == "walk.bvh line 15: no MOTION section after the HIERARCHY"
    assert _err(GOOD.replace("Frame Time: 0.0333333", "Frame Time: 0")) == \
        "walk.bvh line 18: bad value for 'Frame Time': '0' (Frame Time must be positive)"
    assert _err(GOOD.replace("  }\n}\nMOTION", "  }\nMOTION")).startswith("walk.bvh line ")
    assert _err(GOOD.replace("HIERARCHY", "HIERARCHIE")) == "walk.bvh line 1: expected 'HIERARCHY', got 'HIERARCHIE'"
    assert _err(GOOD.replace("CHANNELS 3 Zrotation Xrotation Yrotation",
                             "CHANNELS 3 Zrotation Zrotation Yrotation")) == \
        "walk.bvh line 9: joint 'Spine': channel Zrotation listed twice"
