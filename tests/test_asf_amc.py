"""Acclaim ASF/AMC reader: hand-computed FK, units, joint map, sources, errors, HDM05.

All fixtures are generated here; the HDM05 test reads ../shared when present
and is skipped otherwise.
"""
import io
import os
import tarfile
import warnings

import numpy as np
import pytest

from blender_manikin.core import asf_amc, joint_maps, skeleton
from blender_manikin.core.asf_amc import (ASF_MAP, AsfAmcError, iter_asf_amc_sources, read_amc,
                                          read_amc_values, read_asf, read_asf_amc)
from blender_manikin.core.bvh import BvhClip, BvhError, read_bvh, write_bvh
from blender_manikin.core.rotations import geodesic_angle, normalize

from conftest import SHARED

HDM05 = os.path.join(SHARED, "data", "validation", "hdm05-subset.tar.xz")
J = skeleton.J


# --------------------------------------------------------------------------
# a tiny skeleton with hand-computed answers
TINY_ASF = """\
# tiny test skeleton
:version 1.10
:name tiny
:units
  mass 1.0
  length 1.0
  angle deg
:documentation
  three bones, checked by hand
  second line of documentation
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name a
     direction 1 0 0
     length 2
     axis 0 0 90 XYZ
     dof rx
     limits (-180.0 180.0)
  end
  begin
     id 2
     name b
     direction 1 0 0
     length 1
     axis 0 0 0 XYZ
     dof rz
  end
  begin
     id 3
     name c
     direction 0 0 1
     length 0.5
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root a
    a b
    b c
  end
"""

TINY_AMC = """\
# made by hand
:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0 0 90
a 90
b 90
2
root 0 0 0 0 0 0
a 0
b 0
"""

# frame 1 (see the Acclaim rule W_b = W_parent C_b M_b C_b^-1):
#   W_root = Rz(90); W_a = Rz(90) Rz(90) Rx(90) Rz(-90) = Rz(90) Ry(90)
#   a: start (1,2,3), end = start + W_a (2,0,0) = (1,2,3) + Rz(90)(0,0,-2) = (1,2,1)
#   W_b = W_a Rz(90); b end = (1,2,1) + Rz(90) Ry(90) Rz(90) (1,0,0) = (1,2,1) + (-1,0,0)
#   c (no dof) end = (0,2,1) + W_b (0,0,0.5) = (0,2,1) + (0,0.5,0)
TINY_POS = np.array([
    [[1, 2, 3], [1, 2, 3], [1, 2, 1], [0, 2, 1]],
    [[0, 0, 0], [0, 0, 0], [2, 0, 0], [3, 0, 0]],
], dtype=float)
TINY_C_END = np.array([[0, 2.5, 1], [3, 0, 0.5]])


def _rx(d):
    a = np.radians(d)
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def _ry(d):
    a = np.radians(d)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def _rz(d):
    a = np.radians(d)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def _bytes(text, encoding="utf-8"):
    return io.BytesIO(text.encode(encoding))


@pytest.fixture(scope="module")
def tiny():
    sk = read_asf(_bytes(TINY_ASF), "tiny.asf")
    clip = read_amc(_bytes(TINY_AMC), sk, "tiny_01.amc", fps=60)
    return sk, clip


def test_tiny_skeleton_parsed(tiny):
    sk, _ = tiny
    assert sk.name == "tiny"
    assert sk.joint_names == ("root", "a", "b", "c")
    assert list(sk.parents) == [-1, 0, 1, 2]
    assert sk.bones["a"].dof == ("rx",) and sk.bones["a"].limits == ((-180.0, 180.0),)
    assert sk.bones["c"].dof == () and sk.bones["b"].children == ("c",)
    assert sk.root_order == ("tx", "ty", "tz", "rx", "ry", "rz")
    assert sk.length_unit == 1.0 and sk.angle_unit == "deg"
    assert sk.metres_per_unit == pytest.approx(0.0254)
    assert "checked by hand" in sk.documentation and "second line" in sk.documentation
    np.testing.assert_allclose(sk.bones["a"].C, _rz(90), atol=1e-12)
    np.testing.assert_allclose(sk.rest_positions(), [[0, 0, 0], [0, 0, 0], [2, 0, 0], [3, 0, 0]])


def test_tiny_positions_match_hand_computation(tiny):
    _, clip = tiny
    assert isinstance(clip, BvhClip)
    assert clip.name == "tiny_01" and clip.num_frames == 2 and clip.fps == pytest.approx(60)
    assert clip.joint_names == ("root", "a", "b", "c")
    pos, rot = clip.global_transforms()
    np.testing.assert_allclose(pos, TINY_POS, atol=1e-9)
    # world rotations: W_root = Rz(90), W_a = Rz(90) Ry(90), W_b = W_c = W_a Rz(90)
    np.testing.assert_allclose(rot[0, 0], _rz(90), atol=1e-9)
    np.testing.assert_allclose(rot[0, 1], _rz(90) @ _ry(90), atol=1e-9)
    np.testing.assert_allclose(rot[0, 2], _rz(90) @ _ry(90) @ _rz(90), atol=1e-9)
    np.testing.assert_allclose(rot[0, 3], rot[0, 2], atol=1e-9)
    np.testing.assert_allclose(rot[1], np.broadcast_to(np.eye(3), (4, 3, 3)), atol=1e-12)
    # the leaf bone's end is its End Site
    np.testing.assert_allclose(clip.end_sites[3], [0, 0, 0.5])
    assert np.all(np.isnan(clip.end_sites[:3]))
    end = pos[:, 3] + np.einsum("tij,j->ti", rot[:, 3], clip.end_sites[3])
    np.testing.assert_allclose(end, TINY_C_END, atol=1e-9)
    # the zero pose is the rest pose
    np.testing.assert_allclose(pos[1], clip.rest_positions(), atol=1e-12)


def test_channels_and_bvh_round_trip(tiny):
    _, clip = tiny
    assert clip.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert clip.channels[1] == clip.channels[2] == ("Zrotation", "Yrotation", "Xrotation")
    assert clip.channels[3] == ()
    buf = io.StringIO()
    write_bvh(buf, clip)
    back = read_bvh(io.BytesIO(buf.getvalue().encode()), "tiny.bvh")
    np.testing.assert_allclose(back.global_transforms()[0], TINY_POS, atol=1e-7)


def test_radians_units_and_amc_angle_default():
    asf_rad = (TINY_ASF.replace("angle deg", "angle rad")
               .replace("axis 0 0 90 XYZ", f"axis 0 0 {np.pi / 2!r} XYZ")
               .replace("(-180.0 180.0)", "(-3.2 3.2)"))
    sk = read_asf(_bytes(asf_rad), "tiny_rad.asf")
    np.testing.assert_allclose(sk.bones["a"].axis, [0, 0, 90])
    h = np.pi / 2
    amc_rad = TINY_AMC.replace(":DEGREES", ":RADIANS").replace("0 0 90", f"0 0 {h!r}") \
        .replace("a 90", f"a {h!r}").replace("b 90", f"b {h!r}")
    clip = read_amc(_bytes(amc_rad), sk, "r.amc")
    np.testing.assert_allclose(clip.global_transforms()[0], TINY_POS, atol=1e-9)
    # without :DEGREES/:RADIANS the ASF's angle unit applies
    clip2 = read_amc(_bytes(amc_rad.replace(":RADIANS\n", "")), sk, "r2.amc")
    np.testing.assert_allclose(clip2.global_transforms()[0], TINY_POS, atol=1e-9)
    # ... and an explicit :DEGREES overrides a radian ASF
    clip3 = read_amc(_bytes(TINY_AMC), sk, "d.amc")
    np.testing.assert_allclose(clip3.global_transforms()[0], TINY_POS, atol=1e-9)
    vals = read_amc_values(_bytes(amc_rad), sk, "r.amc")
    np.testing.assert_allclose(vals["a"][:, 0], [90, 0])
    np.testing.assert_allclose(vals["root"][0], [1, 2, 3, 0, 0, 90])


def test_units_length_sets_metres_per_unit():
    sk = read_asf(_bytes(TINY_ASF.replace("length 1.0", "length 0.45")), "cmu_units.asf")
    assert sk.metres_per_unit == pytest.approx(0.0254 / 0.45)
    assert asf_amc.asf_joint_map(sk).unit_scale == pytest.approx(0.0254 / 0.45)
    sk2 = read_asf(_bytes(TINY_ASF.replace("length 1.0", "length 2.54")), "cm.asf")
    assert sk2.metres_per_unit == pytest.approx(0.01)


def test_axis_order_and_dof_order():
    # axis "ZYX": Z first, i.e. C = Rx(ax) Ry(ay) Rz(az); dof "rz rx": rz applied first: M = Rx Rz
    asf = (TINY_ASF.replace("axis 0 0 90 XYZ", "axis 30 0 90 ZYX").replace("dof rx\n", "dof rz rx\n")
           .replace("limits (-180.0 180.0)", "limits (-180.0 180.0)\n            (-90 90)"))
    sk = read_asf(_bytes(asf), "order.asf")
    C = _rx(30) @ _rz(90)
    np.testing.assert_allclose(sk.bones["a"].C, C, atol=1e-12)
    amc = TINY_AMC.replace("a 90", "a 20 50").replace("a 0\n", "a 0 0\n")
    clip = read_amc(_bytes(amc), sk, "order.amc")
    _, rot = clip.global_transforms()
    W_a = _rz(90) @ C @ _rx(50) @ _rz(20) @ C.T
    np.testing.assert_allclose(rot[0, 1], W_a, atol=1e-9)
    pos = clip.global_transforms()[0]
    np.testing.assert_allclose(pos[0, 2], [1, 2, 3] + W_a @ [2, 0, 0], atol=1e-9)


def test_translation_and_length_dofs():
    asf = TINY_ASF.replace("     dof rz\n", "     dof tx ty l rz\n")
    sk = read_asf(_bytes(asf), "t.asf")
    amc = TINY_AMC.replace("b 90", "b 0.5 0.25 1 0").replace("b 0\n", "b 0 0 0 0\n")
    clip = read_amc(_bytes(amc), sk, "t.amc")
    pos, rot = clip.global_transforms()
    W_a = _rz(90) @ _ry(90)
    b_start = np.array([1, 2, 1]) + W_a @ np.array([0.5, 0.25, 0])      # C_b = I
    np.testing.assert_allclose(pos[0, 2], b_start, atol=1e-9)
    np.testing.assert_allclose(pos[0, 3], b_start + W_a @ np.array([2.0, 0, 0]), atol=1e-9)  # length 1 + l 1
    np.testing.assert_allclose(pos[1], [[0, 0, 0], [0, 0, 0], [2, 0, 0], [3, 0, 0]], atol=1e-12)
    assert clip.channels[2][:3] == ("Xposition", "Yposition", "Zposition")


def test_bone_order_may_vary_between_frames(tiny):
    _, clip = tiny
    shuffled = TINY_AMC.replace("2\nroot 0 0 0 0 0 0\na 0\nb 0\n", "2\nb 0\nroot 0 0 0 0 0 0\na 0\n")
    assert shuffled != TINY_AMC
    sk = read_asf(_bytes(TINY_ASF), "tiny.asf")
    clip2 = read_amc(_bytes(shuffled), sk, "shuffled.amc")
    np.testing.assert_allclose(clip2.motion, clip.motion, atol=1e-12)


def test_latin1_and_crlf_text():
    amc = "#!OML:ASF X:\\f\u00fcr Bonn\\skel.ASF\n" + TINY_AMC
    data = amc.replace("\n", "\r\n").encode("latin-1")
    sk = read_asf(io.BytesIO(TINY_ASF.replace("\n", "\r\n").encode("latin-1")), "tiny.asf")
    clip = read_amc(io.BytesIO(data), sk, "latin.amc")
    np.testing.assert_allclose(clip.global_transforms()[0], TINY_POS, atol=1e-9)


def test_byte_order_mark():
    """An ASF and an AMC saved with a UTF-8 byte-order mark (Windows tools) read as without one
    (they were "line 1: expected a ':' keyword, got '\\ufeff'" / "expected a frame number")."""
    sk = read_asf(_bytes(TINY_ASF, "utf-8-sig"), "tiny.asf")
    clip = read_amc(_bytes(TINY_AMC, "utf-8-sig"), sk, "bom.amc")
    np.testing.assert_allclose(clip.global_transforms()[0], TINY_POS, atol=1e-9)


def test_read_asf_amc_from_paths(tmp_path):
    (tmp_path / "tiny.asf").write_text(TINY_ASF)
    (tmp_path / "tiny_01.amc").write_text(TINY_AMC)
    clip = read_asf_amc(tmp_path / "tiny.asf", tmp_path / "tiny_01.amc", fps=30)
    assert clip.name == "tiny_01" and clip.source == "tiny_01.amc" and clip.fps == pytest.approx(30)
    np.testing.assert_allclose(clip.global_transforms()[0], TINY_POS, atol=1e-9)


# --------------------------------------------------------------------------
# malformed input: file, line, problem
def _asf_err(text, name="bad.asf"):
    with pytest.raises(AsfAmcError) as e:
        read_asf(_bytes(text), name)
    assert isinstance(e.value, ValueError) and isinstance(e.value, BvhError)
    return e.value


def _line_of(text, needle):
    return next(n for n, ln in enumerate(text.split("\n"), 1) if needle in ln)


@pytest.mark.parametrize("old,new,needle,problem", [
    (":documentation", ":bogus", ":bogus", "unknown keyword ':bogus'"),
    ("     length 1\n", "     length 1\n     colour red\n", "colour", "unknown keyword 'colour'"),
    ("     length 0.5", "     length half", "length half", "not a number: 'half'"),
    ("    b c\n", "    b c\n    c d\n", "c d", "no bone named 'd'"),
    ("direction 1 0 0\n     length 2", "direction 1 0\n     length 2", "direction 1 0", "direction needs 3 numbers"),
    ("dof rz", "dof rq", "dof rq", "unknown dof 'rq'"),
    ("axis 0 0 90 XYZ", "axis 0 0 90 XYQ", "XYQ", "permutation of XYZ"),
    ("  length 1.0\n", "  length -1\n", "length -1", "must be positive"),
])
def test_asf_errors_name_file_line_problem(old, new, needle, problem):
    text = TINY_ASF.replace(old, new, 1)
    assert text != TINY_ASF
    err = _asf_err(text)
    assert err.source == "bad.asf" and err.line == _line_of(text, needle)
    assert problem in err.problem
    assert str(err).startswith(f"bad.asf line {err.line}: ")


def test_asf_structural_errors():
    err = _asf_err(TINY_ASF.replace("     length 0.5\n", ""))
    assert "has no 'length'" in err.problem and err.line == _line_of(TINY_ASF, "name c") - 2
    err = _asf_err(TINY_ASF.replace("    b c\n", ""))
    assert "not in the :hierarchy" in err.problem
    err = _asf_err(TINY_ASF.replace("     name b", "     name a"))
    assert "duplicate bone name 'a'" in err.problem


def _amc_err(text, sk, name="bad.amc"):
    with pytest.raises(AsfAmcError) as e:
        read_amc(_bytes(text), sk, name)
    return e.value


@pytest.mark.parametrize("old,new,needle,problem", [
    ("a 90\n", "a 90 5\n", "a 90 5", "bone 'a' expects 1 values (dof rx), got 2"),
    ("root 0 0 0 0 0 0", "root 0 0 0 0 0", "root 0 0 0 0 0", "expects 6 values"),
    ("b 90", "b ninety", "b ninety", "not a number: 'ninety'"),
    ("\n2\n", "\n3\n", "3", "frame number jumps from 1 to 3"),
    ("b 90", "z 90", "z 90", "no bone named 'z'"),
    ("b 90", "c 90", "c 90", "bone 'c' has no dof"),
    (":DEGREES", ":FURLONGS", ":FURLONGS", "unknown keyword ':FURLONGS'"),
    ("a 0\nb 0\n", "a 0\na 0\nb 0\n", None, "bone 'a' given twice"),
    ("b 90", "b nan", "b nan", "non-finite"),
])
def test_amc_errors_name_file_line_problem(tiny, old, new, needle, problem):
    sk, _ = tiny
    text = TINY_AMC.replace(old, new, 1)
    assert text != TINY_AMC
    err = _amc_err(text, sk)
    assert err.source == "bad.amc" and problem in err.problem, str(err)
    lines = [ln.strip() for ln in text.split("\n")]
    if needle is not None:
        assert err.line == lines.index(needle) + 1
    else:                                                     # the second 'a 0'
        assert err.line == [n for n, ln in enumerate(lines, 1) if ln == "a 0"][1]
    assert str(err).startswith(f"bad.amc line {err.line}: ")


def test_amc_frame_missing_a_bone(tiny):
    sk, _ = tiny
    text = TINY_AMC.replace("a 0\n", "")
    err = _amc_err(text, sk)
    assert "frame lacks bone 'a'" in err.problem
    assert err.line == [ln.strip() for ln in text.split("\n")].index("2") + 1   # frame 2 starts there


def test_amc_values_before_first_frame(tiny):
    sk, _ = tiny
    err = _amc_err(TINY_AMC.replace(":DEGREES\n1\n", ":DEGREES\n"), sk)
    assert "expected a frame number" in err.problem and err.line == 4


def test_no_frames_gives_empty_clip(tiny):
    sk, _ = tiny
    clip = read_amc(_bytes(":FULLY-SPECIFIED\n:DEGREES\n"), sk, "empty.amc")
    assert clip.num_frames == 0 and clip.num_joints == 4


# --------------------------------------------------------------------------
# a full CMU-names skeleton (ASF written here) through the joint map
S20 = np.sin(np.radians(20.0))
C20 = np.cos(np.radians(20.0))


def _cmu_bones():
    """(name, parent, direction, length, axis, order, dof): a CMU/Vicon-like layout."""
    b = []
    for s, x in (("l", 1.0), ("r", -1.0)):
        b += [
            (f"{s}hipjoint", "root", (0.57 * x, -0.78, 0.25), 2.3, (0, 0, 0), ""),
            (f"{s}femur", f"{s}hipjoint", (S20 * x, -C20, 0), 7.3, (0, 0, 20 * x), "rx ry rz"),
            (f"{s}tibia", f"{s}femur", (S20 * x, -C20, 0), 7.1, (0, 0, 20 * x), "rx"),
            (f"{s}foot", f"{s}tibia", (0.14 * x, -0.38, 0.92), 2.4, (-90, 0, 20 * x), "rx rz"),
            (f"{s}toes", f"{s}foot", (0, 0, 1), 1.2, (-90, 0, 20 * x), "rx"),
        ]
    b += [
        ("lowerback", "root", (0, 1, 0), 2.2, (0, 0, 0), "rx ry rz"),
        ("upperback", "lowerback", (0, 1, 0), 2.2, (0, 0, 0), "rx ry rz"),
        ("thorax", "upperback", (0, 1, 0), 2.2, (0, 0, 0), "rx ry rz"),
        ("lowerneck", "thorax", (0, 1, 0), 1.75, (0, 0, 0), "rx ry rz"),
        ("upperneck", "lowerneck", (0, 1, 0), 1.75, (0, 0, 0), "rx ry rz"),
        ("head", "upperneck", (0, 1, 0), 1.8, (0, 0, 0), "rx ry rz"),
    ]
    for s, x in (("l", 1.0), ("r", -1.0)):
        b += [
            (f"{s}clavicle", "thorax", (0.97 * x, 0.24, 0), 3.7, (0, 0, 0), "ry rz"),
            (f"{s}humerus", f"{s}clavicle", (x, 0, 0), 4.8, (180, -30 * x, -90 * x), "rx ry rz"),
            (f"{s}radius", f"{s}humerus", (x, 0, 0), 3.0, (180, -30 * x, -90 * x), "rx"),
            (f"{s}wrist", f"{s}radius", (x, 0, 0), 1.5, (0, 90 * x, 90 * x), "ry"),
            (f"{s}hand", f"{s}wrist", (x, 0, 0), 1.3, (0, 90 * x, 90 * x), "rx rz"),
            (f"{s}fingers", f"{s}hand", (x, 0, 0), 1.0, (0, 90 * x, 90 * x), "rx"),
            (f"{s}thumb", f"{s}wrist", (0.7071 * x, 0, 0.7071), 1.5, (-90, 45 * x, 0), "rx rz"),
        ]
    return b


def _cmu_asf_text():
    out = [":version 1.10", ":name VICON", ":units", "  mass 1.0", "  length 0.45", "  angle deg",
           ":documentation", "  generated by the test", ":root", "   order TX TY TZ RX RY RZ",
           "   axis XYZ", "   position 0 0 0", "   orientation 0 0 0", ":bonedata"]
    kids = {}
    for i, (n, p, d, L, ax, dof) in enumerate(_cmu_bones(), start=1):
        out += ["  begin", f"     id {i}", f"     name {n}",
                "     direction " + " ".join(f"{v:.12g}" for v in d), f"     length {L}",
                "     axis " + " ".join(f"{v:g}" for v in ax) + " XYZ"]
        if dof:
            out.append(f"    dof {dof}")
            out.append("    limits " + "\n           ".join("(-180.0 180.0)" for _ in dof.split()))
        out.append("  end")
        kids.setdefault(p, []).append(n)
    out += [":hierarchy", "  begin"] + [f"    {p} {' '.join(c)}" for p, c in kids.items()] + ["  end"]
    return "\n".join(out) + "\n"


def _cmu_amc_text(frames):
    """``frames``: list of {bone: values}; unspecified bones are zero."""
    dofs = {n: len(d.split()) for n, _, _, _, _, d in _cmu_bones() if d}
    out = ["#!OML:ASF test", ":FULLY-SPECIFIED", ":DEGREES"]
    for i, fr in enumerate(frames, start=1):
        out.append(str(i))
        out.append("root " + " ".join(f"{v:.12g}" for v in fr.get("root", (0, 17.0, 0, 0, 0, 0))))
        for n, k in dofs.items():
            out.append(f"{n} " + " ".join(f"{v:g}" for v in fr.get(n, (0,) * k)))
    return "\n".join(out) + "\n"


STAND_Y = 7.3 * C20 + 7.1 * C20 + 2.4 * 0.38 + 0.78 * 2.3 + 0.2     # root height, toes just above 0


@pytest.fixture(scope="module")
def cmu_skel():
    return read_asf(_bytes(_cmu_asf_text()), "07.asf")


@pytest.fixture(scope="module")
def cmu_motion(cmu_skel):
    stand = {"root": (0, STAND_Y, 0, 0, 0, 0)}
    frames = [stand] * 30
    # squat-ish: hips flexed 50 deg (negative rx), knees 90 deg, ankles -40, pelvis down
    squat = {"root": (0, STAND_Y - 3.0, 0, 0, 0, 0), "lfemur": (-50, 0, 0), "rfemur": (-50, 0, 0),
             "ltibia": (90,), "rtibia": (90,), "lfoot": (-40, 0), "rfoot": (-40, 0)}
    frames += [squat] * 5
    frames += [{"root": (0, STAND_Y, 0, 0, 90, 0)}] * 5          # turned 90 deg about +Y
    clip = read_amc(_bytes(_cmu_amc_text(frames)), cmu_skel, "07_01.amc")
    with warnings.catch_warnings():
        warnings.simplefilter("error")            # the rest pose must pass as a T-pose
        mc = asf_amc.asf_clip_to_body_motion(clip, cmu_skel)
    return clip, mc


def test_map_covers_the_cmu_skeleton(cmu_skel):
    assert ASF_MAP.missing(cmu_skel.joint_names) == ()
    assert set(ASF_MAP.positions) == set(skeleton.JOINT_NAMES)
    assert ASF_MAP.positions["left_hip"].joints == ("lfemur",)
    assert ASF_MAP.positions["left_knee"].joints == ("ltibia",)
    assert ASF_MAP.positions["left_ankle"].joints == ("lfoot",)
    assert ASF_MAP.positions["left_foot"].joints == ("ltoes",)
    assert ASF_MAP.positions["left_shoulder"].joints == ("lhumerus",)
    assert ASF_MAP.positions["left_elbow"].joints == ("lradius",)
    assert ASF_MAP.positions["left_wrist"].joints == ("lwrist",)
    assert ASF_MAP.positions["neck"].joints == ("lowerneck",)
    # neither the cgspeed nor the Bandai map claims this skeleton
    assert joint_maps.CMU.missing(cmu_skel.joint_names) and joint_maps.BANDAI.missing(cmu_skel.joint_names)
    rep = joint_maps.rest_pose_report(read_amc(_bytes(_cmu_amc_text([{}])), cmu_skel, "z.amc"), ASF_MAP)
    assert max(rep["left_arm"], rep["right_arm"], rep["spine"]) < 15 and rep["left_leg"] < 25


def test_cmu_fixture_joint_positions(cmu_skel, cmu_motion):
    clip, mc = cmu_motion
    pos, _ = clip.global_transforms()
    i = {n: k for k, n in enumerate(clip.joint_names)}
    p = pos[0]
    # hip centre = femur start = root + lhipjoint vector; knee = hip + femur vector; ...
    hip = np.array([0, STAND_Y, 0]) + 2.3 * normalize(np.array([0.57, -0.78, 0.25]))
    np.testing.assert_allclose(p[i["lfemur"]], hip, atol=1e-6)
    np.testing.assert_allclose(p[i["ltibia"]], hip + 7.3 * np.array([S20, -C20, 0]), atol=1e-6)
    np.testing.assert_allclose(p[i["lclavicle"]], [0, STAND_Y + 6.6, 0], atol=1e-6)
    np.testing.assert_allclose(p[i["head"]], [0, STAND_Y + 6.6 + 3.5, 0], atol=1e-6)
    # squat frame: knee angle equals the tibia dof (hinge perpendicular to the bone)
    q = pos[30]
    th, sh = q[i["ltibia"]] - q[i["lfemur"]], q[i["lfoot"]] - q[i["ltibia"]]
    ang = np.degrees(np.arccos(np.dot(th, sh) / np.linalg.norm(th) / np.linalg.norm(sh)))
    assert ang == pytest.approx(90.0, abs=1e-6)
    # bone lengths constant over all frames
    par = clip.parents
    L = np.linalg.norm(pos[:, 1:] - pos[:, par[1:]], axis=-1)
    assert np.ptp(L, axis=0).max() < 1e-9


def test_cmu_fixture_body_motion(cmu_motion):
    clip, mc = cmu_motion
    assert mc.joint_map == "cmu_asf" and mc.unit_scale == pytest.approx(0.0254 / 0.45)
    assert mc.fps == 120 and mc.take_id == "07_01"
    P = mc.positions
    assert P.shape == (clip.num_frames, 22, 3)
    assert 1.55 < mc.body.stature < 1.95
    assert 0.85 < P[0, J["pelvis"], 2] < 1.1
    # standing: left is +X, feet on the floor, head on top, toes point -Y (the body faces -Y)
    assert P[0, J["left_hip"], 0] > P[0, J["right_hip"], 0] + 0.1
    assert P[0, J["left_shoulder"], 0] > 0.1 > -0.1 > P[0, J["right_shoulder"], 0]
    assert abs(min(P[0, J["left_foot"], 2], P[0, J["left_ankle"], 2])) < 0.05
    assert P[0, J["head"], 2] > P[0, J["neck"], 2] > P[0, J["spine3"], 2] > P[0, J["pelvis"], 2]
    assert P[0, J["left_foot"], 1] < P[0, J["left_ankle"], 1] - 0.05
    # pelvis orientation identity at the rest heading; turned 90 deg: faces +X in Blender
    np.testing.assert_allclose(mc.rotations["pelvis"][0], np.eye(3), atol=1e-9)
    np.testing.assert_allclose(mc.rotations["pelvis"][-1] @ [0, -1, 0], [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(mc.rotations["head"][0], np.eye(3), atol=1e-9)
    np.testing.assert_allclose(mc.rotations["left_wrist"][0], np.eye(3), atol=1e-9)
    # squat: knees in front of the hip-ankle line (forward = -Y), pelvis lower
    s = 31
    for side in ("left", "right"):
        k, h, a = (P[s, J[f"{side}_{n}"]] for n in ("knee", "hip", "ankle"))
        assert k[1] < 0.5 * (h[1] + a[1]) - 0.1
    assert P[s, J["pelvis"], 2] < P[0, J["pelvis"], 2] - 0.1


def test_register_joint_map(monkeypatch, cmu_motion):
    clip, _ = cmu_motion
    monkeypatch.setattr(joint_maps, "JOINT_MAPS", dict(joint_maps.JOINT_MAPS))
    with pytest.raises(ValueError):
        joint_maps.detect_joint_map(clip.joint_names)
    asf_amc.register_joint_map()
    assert joint_maps.detect_joint_map(clip.joint_names) is ASF_MAP
    assert joint_maps.get_joint_map("cmu_asf") is ASF_MAP


# --------------------------------------------------------------------------
# sources: folders and archives, ASF pairing
def _write_tree(root):
    (root / "asf").mkdir(parents=True)
    (root / "amc").mkdir()
    (root / "asf" / "HDM_xx.asf").write_text(TINY_ASF)
    (root / "asf" / "HDM_yy.asf").write_text(TINY_ASF.replace("length 2\n", "length 4\n"))
    (root / "amc" / "HDM_xx_squat_001_120.amc").write_text(TINY_AMC)
    (root / "amc" / "HDM_yy_squat_001_120.amc").write_text(TINY_AMC)
    (root / "cmu").mkdir()
    (root / "cmu" / "07.asf").write_text(TINY_ASF)
    (root / "cmu" / "07_01.amc").write_text(TINY_AMC)
    (root / "cmu" / "99_01.amc").write_text(TINY_AMC)        # no 99.asf, no single ASF next to it


def _check_sources(items):
    names = [n for n, _ in items]
    assert names == sorted(names)
    assert names == ["amc/HDM_xx_squat_001_120.amc", "amc/HDM_yy_squat_001_120.amc",
                     "cmu/07_01.amc", "cmu/99_01.amc"]
    src = dict(items)
    assert src["amc/HDM_xx_squat_001_120.amc"].asf_name == "asf/HDM_xx.asf"
    assert src["amc/HDM_yy_squat_001_120.amc"].asf_name == "asf/HDM_yy.asf"
    assert src["cmu/07_01.amc"].asf_name == "cmu/07.asf"
    clip = src["amc/HDM_xx_squat_001_120.amc"]()
    assert clip.name == "HDM_xx_squat_001_120"
    np.testing.assert_allclose(clip.global_transforms()[0], TINY_POS, atol=1e-9)
    yy = src["amc/HDM_yy_squat_001_120.amc"]()
    assert yy.global_transforms()[0][1, 2] == pytest.approx([4, 0, 0])     # its own skeleton
    xx = src["amc/HDM_xx_squat_001_120.amc"]
    assert xx.skeleton() is xx.skeleton()                   # parsed once
    with pytest.raises(AsfAmcError, match="no ASF skeleton"):
        src["cmu/99_01.amc"]()


def test_iter_sources_folder_and_archive(tmp_path):
    _write_tree(tmp_path / "data")
    _check_sources(list(iter_asf_amc_sources(tmp_path / "data")))
    arc = tmp_path / "data.tar.xz"
    with tarfile.open(arc, "w:xz") as tf:
        tf.add(tmp_path / "data", arcname=".")
    _check_sources(list(iter_asf_amc_sources(arc)))
    one = list(iter_asf_amc_sources(tmp_path / "data" / "amc" / "HDM_yy_squat_001_120.amc"))
    assert len(one) == 1 and one[0][1].asf_name == "HDM_yy.asf"
    with pytest.raises(FileNotFoundError):
        list(iter_asf_amc_sources(tmp_path / "nope"))


# --------------------------------------------------------------------------
# the real HDM05 subset (../shared), when present
@pytest.fixture(scope="module")
def hdm05():
    if not os.path.isfile(HDM05):
        pytest.skip("HDM05 subset (../shared/data/validation) not available")
    items = list(iter_asf_amc_sources(HDM05))
    by_actor = {}
    for name, src in items:
        actor = os.path.basename(name).split("_")[1]
        by_actor.setdefault(actor, []).append((name, src))
    return items, by_actor


def test_hdm05_pairs_every_take_with_its_actor(hdm05):
    items, by_actor = hdm05
    assert len(items) == 287 and sorted(by_actor) == ["bd", "bk", "dg", "mm", "tr"]
    for actor, lst in by_actor.items():
        assert all(src.asf_name.endswith(f"asf/HDM_{actor}.asf") for _, src in lst)


def _pick(lst, word):
    return next(src for name, src in lst if word in name)


def test_hdm05_clips_are_plausible_people(hdm05):
    _, by_actor = hdm05
    M = joint_maps.axis_conversion("y", "z")
    for actor, lst in sorted(by_actor.items()):
        sk = lst[0][1].skeleton()
        assert sk.length_unit == 0.45 and sk.angle_unit == "deg" and len(sk.bones) == 30
        assert ASF_MAP.missing(sk.joint_names) == ()
        # rest pose: left leg to +X, toes to +Z (faces +Z), left arm along +X
        assert sk.bones["lfemur"].direction[0] > 0.3 > -0.3 > sk.bones["rfemur"].direction[0]
        assert min(sk.bones["lfoot"].direction[2], sk.bones["rfoot"].direction[2]) > 0.7
        assert sk.bones["ltoes"].direction[2] > 0.99
        # rest heights as fractions of the top of the head: the mapped head (2/3 up the
        # neck) sits at the skull base (0.910 of it), the hips at 0.53
        rp = sk.rest_positions()
        i = {n: k for k, n in enumerate(sk.joint_names)}
        ground = min(rp[:, 1].min(), (rp[i["ltoes"]] + sk.bones["ltoes"].vector)[1])
        H = (rp[i["head"]] + sk.bones["head"].vector)[1] - ground
        neck = [rp[i[n]] for n in ("lowerneck", "upperneck", "head")]
        seg = [np.linalg.norm(neck[1] - neck[0]), np.linalg.norm(neck[2] - neck[1])]
        t = asf_amc.HEAD_FRACTION * sum(seg)
        if t <= seg[0]:
            head = neck[0] + (neck[1] - neck[0]) * t / seg[0]
        else:
            head = neck[1] + (neck[2] - neck[1]) * (t - seg[0]) / seg[1]
        assert 0.895 < (head[1] - ground) / H < 0.925, actor
        assert 0.50 < (rp[i["lfemur"], 1] - ground) / H < 0.54
        assert 0.81 < (rp[i["lowerneck"], 1] - ground) / H < 0.86
        assert sk.bones["lhumerus"].direction[0] > 0.99 and sk.bones["lthumb"].direction[2] > 0.5
        for word in ("squat", "jog"):
            src = _pick(lst, word)
            clip = src()
            pos, rot = clip.global_transforms()
            i = {n: k for k, n in enumerate(clip.joint_names)}
            par = clip.parents
            L = np.linalg.norm(pos[:, 1:] - pos[:, par[1:]], axis=-1)
            assert np.ptp(L, axis=0).max() < 1e-6, (actor, word)            # rigid bones
            rest_L = np.linalg.norm(clip.offsets[1:], axis=-1)
            np.testing.assert_allclose(L[0], rest_L, atol=1e-6)
            p = pos[0]
            y = {n: p[i[n], 1] for n in ("head", "root", "ltibia", "rtibia", "lfoot", "rfoot")}
            assert y["head"] > y["root"] > max(y["ltibia"], y["rtibia"]) > max(y["lfoot"], y["rfoot"])
            feet = [i[n] for n in ("lfoot", "rfoot", "ltoes", "rtoes")]
            assert p[feet, 1].min() - p[:, 1].min() < 1e-9                  # a foot joint is lowest
            # the knee angle is the tibia dof: Acclaim C M C^-1 (hinge perpendicular to the bone)
            vals = read_amc_values(src.open_amc(), sk, src.amc_name)
            th, sh = pos[:, i["ltibia"]] - pos[:, i["lfemur"]], pos[:, i["lfoot"]] - pos[:, i["ltibia"]]
            cos = np.sum(th * sh, -1) / np.linalg.norm(th, axis=-1) / np.linalg.norm(sh, axis=-1)
            np.testing.assert_allclose(cos, np.cos(np.radians(vals["ltibia"][:, 0])), atol=1e-9)
            # to the body model
            mc = asf_amc.asf_clip_to_body_motion(clip, sk)
            P = mc.positions
            # the body model's stature (head joint / 0.870) is 4.6 % above the head bone's end
            assert 1.65 < mc.body.stature < 2.0, (actor, mc.body.stature)
            top = (p[i["head"]] + rot[0, i["head"]] @ clip.end_sites[i["head"]] - p[feet].min(0))[1]
            assert 1.5 < top * sk.metres_per_unit < 1.85                      # head bone end ~ stature
            if word == "squat":
                assert 0.88 < P[0, J["pelvis"], 2] < 1.12, (actor, P[0, J["pelvis"], 2])
                assert 0.8 < P[0, J["head"], 2] / mc.body.stature < 0.95
                assert abs(min(P[0, [J["left_foot"], J["right_foot"]], 2].min(), 0.0)) < 0.05
                # knees forward: while the knees bend 40-100 deg, the knee is ahead of the
                # hip-ankle midpoint along the pelvis' forward (-Y in the body frame)
                fwd = np.einsum("tij,j->ti", mc.rotations["pelvis"], [0, -1.0, 0])
                for s, side in (("l", "left"), ("r", "right")):
                    flex = vals[f"{s}tibia"][:, 0]
                    sel = (flex > 40) & (flex < 100)
                    assert sel.sum() > 5
                    k, h, a = (P[sel, J[f"{side}_{n}"]] for n in ("knee", "hip", "ankle"))
                    ahead = np.sum((k - 0.5 * (h + a)) * fwd[sel], -1)
                    assert np.median(ahead) > 0.05 and np.mean(ahead > 0) > 0.9, (actor, side)
                    # the same in the source frame: thigh forward, shank backward
                    src_fwd = np.einsum("ij,tj->ti", M.T, fwd[sel])
                    thigh = pos[sel, i[f"{s}tibia"]] - pos[sel, i[f"{s}femur"]]
                    shank = pos[sel, i[f"{s}foot"]] - pos[sel, i[f"{s}tibia"]]
                    assert np.median(np.sum(thigh * src_fwd, -1)) > 0 > np.median(np.sum(shank * src_fwd, -1))


def test_hdm05_root_rotation_smooth_through_gimbal_lock(hdm05):
    """dg faces -X, so its root RY sits near -90 deg where RX/RZ swing by tens of
    degrees between frames; with the right Euler order (X first) the world
    rotation still moves smoothly."""
    _, by_actor = hdm05
    src = next(s for n, s in by_actor["dg"] if "squat1Reps_028" in n)
    sk = src.skeleton()
    vals = read_amc_values(src.open_amc(), sk, src.amc_name)["root"]
    assert np.abs(np.abs(vals[:, 4]) - 90).min() < 1.0 and np.abs(np.diff(vals[:, 3])).max() > 20
    _, rot = src().global_transforms()
    step = np.degrees(geodesic_angle(rot[1:, 0], rot[:-1, 0]))
    assert step.max() < 3.0
