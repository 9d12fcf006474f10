"""Vicon subject parameter files (``core/subject_params.py``): ``.mp`` / ``.vsk`` read as metres,
malformed files named with their line, and their knee / ankle / elbow widths placing Plug-in
Gait's lateral-only joint centres (``core/marker_sets.py``), given or found beside the TRC."""
import os

import numpy as np
import pytest

from blender_manikin.core import marker_sets as ms
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core import subject_params as sp
from blender_manikin.core.io_keypoints import read_keypoints
from blender_manikin.core.recording import RecordingError
from test_marker_sets import anatomical_markers, joint_errors, write_marker_trc

#: the subject's widths (mm) and marker diameter: wider than :data:`marker_sets.HALF_WIDTH`'s
#: typical adult (knee 100, ankle 70 mm), so the typical guess is a centimetre or more off
KNEE_MM, ANKLE_MM, ELBOW_MM, MARKER_MM = 130.0, 90.0, 100.0, 14.0

MP = """{* Vicon Nexus subject parameters *}
$Bodymass = 82
$Height = 1812
$InterAsisDistance = 0
$LeftLegLength = 940
$RightLegLength=941
$LeftKneeWidth = 130
$RightKneeWidth = 130
$AnkleWidth = 90   {* both sides *}
$LeftElbowWidth = 100
$RightElbowWidth = 100
$LeftWristWidth = 0
$MarkerDiameter = 14
"""

VSK = """<?xml version="1.0" encoding="UTF-8"?>
<KinematicModel>
  <Parameters>
    <Parameter NAME="Bob_MarkerDiameter" VALUE="14" PRIOR="14"/>
    <Parameter NAME="Bob_LeftKneeWidth" VALUE="130" PRIOR="0"/>
    <Parameter NAME="Bob:RightKneeWidth" VALUE="130" PRIOR="0"/>
    <Parameter NAME="LeftAnkleWidth" VALUE="90"/>
    <Parameter NAME="RightAnkleWidth" VALUE="90"/>
    <Parameter NAME="Height" VALUE="1812"/>
  </Parameters>
</KinematicModel>
"""


def _write(path, text):
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    return str(path)


def test_mp_and_vsk_read_as_metres(tmp_path):
    """An ``.mp``'s ``$Name = Value`` lines (spaces optional, ``{* *}`` comments, an unsided
    ``AnkleWidth`` for both sides, 0 for not measured) and a ``.vsk``'s ``<Parameter>`` (subject
    prefixes) give the same widths, in metres; the offset from a lateral marker is half the width
    plus the marker's radius."""
    mp = sp.read_subject_params(_write(tmp_path / "Bob.mp", MP))
    vsk = sp.read_subject_params(_write(tmp_path / "Bob.vsk", VSK))
    for p in (mp, vsk):
        assert p.widths[("left", "knee")] == pytest.approx(0.130)
        assert p.widths[("right", "ankle")] == pytest.approx(0.090)
        assert p.marker_diameter == pytest.approx(0.014) and p.height == pytest.approx(1.812)
        assert p.offset("left", "knee") == pytest.approx(0.065 + 0.007)
    assert ("left", "wrist") not in mp.widths and mp.widths[("right", "elbow")] == pytest.approx(0.100)
    assert mp.raw["bodymass"] == "82"
    assert mp.summary() == ("subject Bob.mp: knee 130/130 mm, ankle 90/90 mm, elbow 100/100 mm (L/R), "
                            "marker 14 mm, height 1.812 m")


@pytest.mark.parametrize("text, message", [
    ("$Height = 1800\n$LeftKneeWidth 105\n", r"bad.mp, line 2: '\$LeftKneeWidth 105' is not a '\$Name = Value' line"),
    ("$LeftKneeWidth = 10S\n", r"bad.mp, line 1: LeftKneeWidth = '10S' is not a number"),
    ("\n$RightAnkleWidth = -70\n", r"bad.mp, line 2: RightAnkleWidth = '-70': expected a positive number"),
    ("$Height = 1.8\n", r"bad.mp, line 1: Height = 1.8 mm: expected a stature in millimetres"),
])
def test_a_malformed_mp_is_named(tmp_path, text, message):
    with pytest.raises(RecordingError, match=message):
        sp.read_subject_params(_write(tmp_path / "bad.mp", text))


def test_a_malformed_vsk_is_named(tmp_path):
    bad = VSK.replace('VALUE="90"/>\n    <Parameter NAME="RightAnkleWidth"', 'VALUE="ninety"/>\n    <Parameter '
                      'NAME="RightAnkleWidth"')
    with pytest.raises(RecordingError, match=r"bad.vsk, line 7: LeftAnkleWidth = 'ninety' is not a number"):
        sp.read_subject_params(_write(tmp_path / "bad.vsk", bad))
    with pytest.raises(RecordingError, match=r"cut.vsk, line \d+: not valid XML"):
        sp.read_subject_params(_write(tmp_path / "cut.vsk", VSK[:-20]))


def leg_motion(frames=60, fps=30.0):
    """``(body, positions, world)``: a body walking round a turn, its hips swinging forward and back
    and its knees bending (no thigh turned in or out: Plug-in Gait's lateral-only rule is exact for
    the knees and ankles), its arms as in the T-pose."""
    body = sk.make_body(1.80)
    t = np.arange(frames) / fps
    local = np.broadcast_to(np.eye(3), (frames, 22, 3, 3)).copy()
    local[:, sk.J["pelvis"]] = rot.axis_angle_rotation(np.array([0, 0, 1.0]), 0.8 * t)
    for side, ph in (("left", 0.0), ("right", np.pi)):
        local[:, sk.J[f"{side}_hip"]] = rot.axis_angle_rotation(np.array([1.0, 0, 0]), 0.4 * np.sin(4 * t + ph))
        local[:, sk.J[f"{side}_knee"]] = rot.axis_angle_rotation(np.array([1.0, 0, 0]),
                                                                 0.2 + 0.5 * (1 + np.sin(4 * t + ph)))
    root = np.stack([0.3 * t, 0.1 * t, np.full(frames, body.offsets[0][2])], -1)
    pos, world = sk.forward_kinematics(local, root, body)
    return body, pos, world


def _widen(names, pts, pos, knee=KNEE_MM, ankle=ANKLE_MM):
    """The lateral knee and ankle markers moved to the subject's widths (mm): ``width / 2 + marker
    radius`` from the joint centre, along where they were."""
    out = pts.copy()
    for S, side in (("L", "left"), ("R", "right")):
        for m, joint, w in (("KNE", "knee", knee), ("ANK", "ankle", ankle)):
            k, c = names.index(f"{S}{m}"), pos[:, sk.J[f"{side}_{joint}"]]
            d = rot.normalize(pts[:, k] - c)
            out[:, k] = c + (w + MARKER_MM) / 2000.0 * d
    return out


def test_lateral_only_offset_is_square_to_the_bone(tmp_path):
    """Lateral markers exactly ``HALF_WIDTH`` from the knee and ankle centres, no subject file: the
    centres read back within 0.5 mm.  Before: knees 3.9 mm, ankles 8.9 mm off, distal (the offset was taken square
    to the line from the hip to the marker, not to the bone)."""
    body, pos, world = leg_motion()
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    pts = _widen(names, pts, pos, knee=2000.0 * ms.HALF_WIDTH["knee"] - MARKER_MM,
                 ankle=2000.0 * ms.HALF_WIDTH["ankle"] - MARKER_MM)
    rec = read_keypoints(write_marker_trc(tmp_path / "walk.trc", names, pts))
    err = joint_errors(rec, pos, [f"{s}_{j}" for s in ("left", "right") for j in ("knee", "ankle")])
    assert max(err.values()) < 5e-4, err


def test_subject_widths_place_lateral_only_joints(tmp_path):
    """Lateral knee and ankle markers only, on a subject with 130 mm knees and 90 mm ankles: read
    with the subject's ``.mp`` the knee and ankle centres are within 2 mm of the skeleton's;
    without it (the typical half widths) a centimetre or more off.  Before: the ``.mp`` was not
    read (the centres stayed a centimetre off) and ``subject_params`` was not an argument."""
    body, pos, world = leg_motion()
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    pts = _widen(names, pts, pos)
    legs = [f"{s}_{j}" for s in ("left", "right") for j in ("knee", "ankle")]
    trc = write_marker_trc(tmp_path / "walk.trc", names, pts)
    mp = _write(tmp_path / "other_name.mp", MP)
    without = joint_errors(read_keypoints(trc, subject_params="none"), pos, legs)
    rec = read_keypoints(trc, subject_params=mp)
    err = joint_errors(rec, pos, legs)
    assert max(err.values()) < 0.002, err
    assert min(without.values()) > 0.009 and without["left_knee"] > 0.014, without
    assert ("knees, ankles, elbows the subject's half width from the lateral marker (no medial marker)"
            in rec.metadata["detected"]), rec.metadata["detected"]
    assert "subject other_name.mp: knee 130/130 mm, ankle 90/90 mm, elbow 100/100 mm (L/R), marker 14 mm, " \
           "height 1.812 m (as set)" in rec.metadata["detected"]
    assert rec.metadata["subject_height"] == pytest.approx(1.812)


def test_elbow_width_sets_the_distance():
    """The elbow keeps its medial direction rule; the subject's width only sets the distance: the
    centre lies about (width / 2 + radius) / HALF_WIDTH as far from the lateral marker (the sine
    scaling the distance is taken to the bone, which the distance turns a little), and exactly
    where the typical width puts it when that is the subject's."""
    body, pos, world = leg_motion(frames=4)
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    _, typical = ms.joint_centres(names, pts, 1.0)
    off = (ELBOW_MM + MARKER_MM) / 2000.0
    _, measured = ms.joint_centres(names, pts, 1.0, offsets={("left", "elbow"): off})
    lat = pts[:, names.index("LELB")]
    np.testing.assert_allclose(np.linalg.norm(measured["left_elbow"] - lat, axis=-1),
                               np.linalg.norm(typical["left_elbow"] - lat, axis=-1) * off / ms.HALF_WIDTH["elbow"],
                               rtol=0.02)
    np.testing.assert_allclose(measured["right_elbow"], typical["right_elbow"])
    _, same = ms.joint_centres(names, pts, 1.0, offsets={("left", "elbow"): ms.HALF_WIDTH["elbow"]})
    np.testing.assert_allclose(same["left_elbow"], typical["left_elbow"], atol=1e-12)


def test_subject_file_found_beside_the_trc(tmp_path):
    """Auto pickup: ``<Subject>.mp`` for markers named ``Subject:LKNE`` (another subject's file
    beside it is not taken), else the folder's only ``.mp``; none with two ``.mp`` and no prefix.
    Before: no file was looked for (the knee centres stayed the typical half width off)."""
    body, pos, world = leg_motion(frames=20)
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    pts = _widen(names, pts, pos)
    legs = ["left_knee", "right_knee"]
    sub = tmp_path / "session"
    os.makedirs(sub)
    _write(sub / "Bob.mp", MP)
    _write(sub / "Ann.mp", MP.replace("130", "95"))
    trc = write_marker_trc(sub / "walk.trc", [f"Bob:{n}" for n in names], pts)
    rec = read_keypoints(trc)
    assert "subject Bob.mp:" in rec.metadata["detected"] and "(found beside the TRC)" in rec.metadata["detected"]
    assert max(joint_errors(rec, pos, legs).values()) < 0.002
    plain = write_marker_trc(sub / "plain.trc", names, pts)             # two .mp, no prefix: which is not told
    rec = read_keypoints(plain)
    assert "subject " not in rec.metadata["detected"] and "subject_height" not in rec.metadata
    os.remove(sub / "Ann.mp")                                          # the folder's only .mp
    rec = read_keypoints(plain)
    assert "subject Bob.mp:" in rec.metadata["detected"]
    assert max(joint_errors(rec, pos, legs).values()) < 0.002
    vsk_dir = tmp_path / "vsk"
    os.makedirs(vsk_dir)
    _write(vsk_dir / "Bob.vsk", VSK)
    rec = read_keypoints(write_marker_trc(vsk_dir / "walk.trc", [f"Bob:{n}" for n in names], pts))
    assert "subject Bob.vsk:" in rec.metadata["detected"]
    assert max(joint_errors(rec, pos, legs).values()) < 0.002


def test_cli_option_reaches_the_solve(tmp_path):
    """``--subject-params FILE`` is a ``solve`` option and a SolveSettings field; the file's
    Height is the stature of the keypoint solve when no --height is given."""
    from blender_manikin import cli
    from blender_manikin.core.solve import SolveSettings, solve_recording
    mp = _write(tmp_path / "Bob.mp", MP)
    args = cli.build_parser().parse_args(["solve", "x.trc", "--out", str(tmp_path), "--subject-params", mp])
    assert cli.solve_settings(args).subject_params == mp
    body, pos, world = leg_motion(frames=30)
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    trc = write_marker_trc(tmp_path / "walk.trc", names, _widen(names, pts, pos), fps=30.0)
    out = solve_recording(str(trc), SolveSettings(fps=30.0, subject_params=mp))
    assert out.body.stature == pytest.approx(1.812, abs=1e-6)
    assert "stature 1.812 m from the subject parameter file" in out.info


def test_a_nexus_vsk_with_static_parameters_is_read(tmp_path):
    """Nexus writes a subject's measurements as ``<StaticParameter NAME= VALUE=>`` (as pyCGM2 reads
    them) and leaves ``VALUE`` out of one not measured: the widths are read from them, the one
    without a value is not measured (both were missed: no widths, or the file refused)."""
    text = """<?xml version="1.0" encoding="UTF-8"?>
<KinematicModel>
  <Parameters>
    <Parameter NAME="Bob_LeftFemurLength" PRIOR="0" SD="0"/>
  </Parameters>
  <StaticParameters>
    <StaticParameter NAME="MarkerDiameter" VALUE="14"/>
    <StaticParameter NAME="LeftKneeWidth" VALUE="130"/>
    <StaticParameter NAME="RightKneeWidth" VALUE="128"/>
    <StaticParameter NAME="LeftAnkleWidth" VALUE="90"/>
    <StaticParameter NAME="RightAnkleWidth"/>
    <StaticParameter NAME="Height" VALUE="1812"/>
  </StaticParameters>
</KinematicModel>
"""
    p = sp.read_subject_params(_write(tmp_path / "Bob.vsk", text))
    assert p.widths == {("left", "knee"): pytest.approx(0.130), ("right", "knee"): pytest.approx(0.128),
                        ("left", "ankle"): pytest.approx(0.090)}
    assert p.height == pytest.approx(1.812) and p.marker_diameter_given
    assert p.summary() == "subject Bob.vsk: knee 130/128 mm, ankle 90/- mm (L/R), marker 14 mm, height 1.812 m"


def test_a_labelling_skeletons_parameter_is_not_a_measurement(tmp_path):
    """A Nexus *PlugInGait FullBody Ai* ``.vsk`` (as in cadop/pyCGM's sample data) keeps the
    subject's measurements as ``<StaticParameter>`` and the labelling skeleton's fitted values as
    ``<Parameter>``, among them an unsided ``WristWidth`` of 32 mm (a marker offset, not the
    wrist).  A wrist width left unmeasured (no ``VALUE``) stays unmeasured: it was taken from the
    skeleton's ``WristWidth`` (32 mm on both sides), a ``<Parameter Height>`` as the stature."""
    text = """<?xml version="1.0" encoding="UTF-8" standalone="no"?>
<KinematicModel MODEL="PlugInGait FullBody Ai" VERSION="3.2">
\t<Parameters>
\t\t<StaticParameter NAME="Height" VALUE="1679" PRIOR="1700" HIDDEN="false" REQUIRED="true" QUANTITY="length"/>
\t\t<StaticParameter NAME="LeftKneeWidth" VALUE="144" PRIOR="120" HIDDEN="false" REQUIRED="true" QUANTITY="length"/>
\t\t<StaticParameter NAME="LeftWristWidth" PRIOR="40" HIDDEN="false" REQUIRED="true" QUANTITY="length"/>
\t\t<StaticParameter NAME="RightWristWidth" VALUE="65" PRIOR="40" HIDDEN="false" REQUIRED="true" QUANTITY="length"/>
\t\t<Parameter NAME="WristWidth" VALUE="31.906095504760742" PRIOR="31.085922241210937" SD="0" HIDDEN="false"/>
\t\t<Parameter NAME="KneeWidth" VALUE="88.5" PRIOR="90" SD="0" HIDDEN="false"/>
\t\t<Parameter NAME="LeftHandWidth" VALUE="-17.935661315917969" PRIOR="15.54" SD="0" HIDDEN="false"/>
\t</Parameters>
</KinematicModel>
"""
    p = sp.read_subject_params(_write(tmp_path / "Test.vsk", text))
    assert p.widths == {("left", "knee"): pytest.approx(0.144), ("right", "wrist"): pytest.approx(0.065)}
    assert p.height == pytest.approx(1.679)
    assert p.raw["parameter:wristwidth"] == "31.906095504760742"
    # a hand-written .vsk of <Parameter>s only is still read as measurements
    q = sp.read_subject_params(_write(tmp_path / "Hand.vsk", '<KinematicModel><Parameter NAME="KneeWidth" VALUE="100"/>'
                                                            '</KinematicModel>'))
    assert q.widths == {("left", "knee"): pytest.approx(0.1), ("right", "knee"): pytest.approx(0.1)}
