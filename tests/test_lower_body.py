"""Lower-body takes (``core/keypoint_layouts.py`` ``lower_body_only``): a Vicon Plug-in Gait
lower-body TRC and COCO-17 keypoints of the legs only are solved, the legs as a full-body take of
the same motion gives them, the trunk, arms and head riding on the pelvis at rest, the stature
from the legs.  Before: refused ("joint(s) pelvis, spine1, ... cannot be placed: point(s)
left_shoulder, ... never seen")."""
import numpy as np
import pytest

from blender_manikin import cli
from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core.io_keypoints import keypoints_from_points
from blender_manikin.core.solve import SolveSettings, solve_recording

from fixtures_keypoints import hinge_motion
from test_marker_sets import anatomical_markers, write_marker_trc

LEGS = [f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle")]
UPPER_MARKERS = ("SHO", "ELB", "WRA", "WRB", "FHD", "BHD")
#: COCO-17's upper-body points (a crop to the legs never sees them)
UPPER_COCO = ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
              "left_elbow", "right_elbow", "left_wrist", "right_wrist")


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=150, seed=3)


def _pig_trc(path, motion, lower, mirror=False):
    """A Plug-in Gait TRC (lateral markers only) of ``motion``; ``lower``: the upper body's columns
    left empty, as Vicon writes a lower-body trial; ``mirror``: a left-handed file."""
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    pts = pts.copy()
    if lower:
        for k, n in enumerate(names):
            if n[1:] in UPPER_MARKERS:
                pts[:, k] = np.nan
    write_marker_trc(path, names, pts, mirror=mirror)
    text = path.read_text(encoding="utf-8")
    path.write_text("\n".join("\t".join("" if c.strip() == "nan" else c for c in line.split("\t"))
                              for line in text.split("\n")), encoding="utf-8")
    return path


def _leg_errors(P, pos):
    """Median distance (metres) per leg joint between a solve's joints and the skeleton's, both
    relative to the first frame's hips' midpoint (the solve moves the floor)."""
    n = min(len(P), len(pos))              # the solve's grid may end a frame short of the file
    P, pos = P[:n], pos[:n]
    hips = [sk.J["left_hip"], sk.J["right_hip"]]
    o_p, o_w = P[:1, hips].mean(1), pos[:1, hips].mean(1)
    return {j: float(np.median(np.linalg.norm((P[:, sk.J[j]] - o_p) - (pos[:, sk.J[j]] - o_w), axis=-1)))
            for j in LEGS}


def _check_upright_trunk(out):
    """The trunk, neck and head stand on the pelvis as at rest: no bend between them; the pelvis's
    up axis square to the hip line (the trunk follows the pelvis's heading and sideways tilt)."""
    res = out.result
    P, W = res.fk()
    for j in ("spine1", "spine2", "spine3", "neck", "head"):
        rel = np.swapaxes(W[:, sk.J["pelvis"]], -1, -2) @ W[:, sk.J[j]]
        ang = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)))
        assert ang.max() < 1.0, (j, ang.max())
    trunk = rot.normalize(P[:, sk.J["neck"]] - P[:, sk.J["pelvis"]])
    hip_line = rot.normalize(P[:, sk.J["left_hip"]] - P[:, sk.J["right_hip"]])
    assert np.abs(np.sum(trunk * hip_line, -1)).max() < 0.02
    # upright: the trunk's forward tilt is nil (the hips cannot show it)
    fwd = rot.normalize(np.cross(np.broadcast_to([0.0, 0.0, 1.0], hip_line.shape), hip_line))
    assert np.abs(np.sum(trunk * fwd, -1)).max() < 0.02
    # the arms hang below the shoulders, beside the body
    for side in ("left", "right"):
        assert (P[:, sk.J[f"{side}_wrist"], 2] < P[:, sk.J[f"{side}_shoulder"], 2] - 0.3).all()


def test_a_lower_body_plugin_gait_take_is_solved(tmp_path, motion):
    body, pos, world = motion
    full = solve_recording(str(_pig_trc(tmp_path / "full.trc", motion, False)), SolveSettings(fps=60.0))
    lower = solve_recording(str(_pig_trc(tmp_path / "lower.trc", motion, True)), SolveSettings(fps=60.0))
    e_full, e_low = _leg_errors(full.result.positions, pos), _leg_errors(lower.result.positions, pos)
    for j in LEGS:
        assert e_low[j] < e_full[j] + 0.005, (j, e_low[j], e_full[j])
        assert e_low[j] < 0.02, (j, e_low[j])
    _check_upright_trunk(lower)
    summary = lower.summary()
    assert "lower body only: the trunk, arms and head follow the pelvis at rest" in summary, summary
    assert "the stature estimated from the legs' length (hip to ankle taken as 49% of it" in summary
    assert abs(lower.body.stature - body.stature) < 0.03 * body.stature, (lower.body.stature, body.stature)
    # a stature given scales it, and is said so
    sized = solve_recording(str(tmp_path / "lower.trc"), SolveSettings(fps=60.0, height=1.9))
    assert abs(sized.body.stature - 1.9) < 1e-6 and "the stature given" in sized.summary()


def test_a_left_handed_lower_body_take_is_told_from_its_feet(tmp_path, motion):
    """No shoulders: the body's left comes from the hips, its facing from the toes ahead of the
    heels, so a mirrored (left-handed) file is put right and its legs land where they were.
    Before: "right-handed (assumed: no clear facing)", the legs solved mirrored."""
    from blender_manikin.core.io_keypoints import read_keypoints
    body, pos, world = motion
    path = _pig_trc(tmp_path / "mirrored.trc", motion, True, mirror=True)
    rec = read_keypoints(path)
    assert rec.metadata["handed"] == "left", rec.metadata["detected"]
    assert "left-handed (toes ahead of the heels)" in rec.metadata["detected"], rec.metadata["detected"]
    e = _leg_errors(solve_recording(rec, SolveSettings(fps=60.0)).result.positions, pos)
    assert max(e.values()) < 0.02, e


def test_lower_body_coco_keypoints_are_solved(motion):
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    t = np.arange(len(clean)) / 30.0
    full = solve_recording(keypoints_from_points(t, clean, "coco17", "full"), SolveSettings(fps=30.0))
    legs_only = clean.copy()
    legs_only[:, [kl.LAYOUTS["coco17"].index(p) for p in UPPER_COCO]] = np.nan
    assert kl.lower_body_only(legs_only, "coco17") and not kl.lower_body_only(clean, "coco17")
    lower = solve_recording(keypoints_from_points(t, legs_only, "coco17", "legs"), SolveSettings(fps=30.0))
    e_full, e_low = _leg_errors(full.result.positions, pos), _leg_errors(lower.result.positions, pos)
    for j in LEGS:
        assert e_low[j] < e_full[j] + 0.005, (j, e_low[j], e_full[j])
    _check_upright_trunk(lower)
    assert "lower body only" in lower.summary()
    assert abs(lower.body.stature - body.stature) < 0.03 * body.stature, (lower.body.stature, body.stature)
    # shoulders seen, arms never: not a lower-body take (the arms hang at rest:
    # test_arms_never_seen_hang_at_rest)
    arms = clean.copy()
    lay = kl.LAYOUTS["coco17"]
    arms[:, [lay.index(f"{s}_{j}") for s in ("left", "right") for j in ("elbow", "wrist")]] = np.nan
    assert not kl.lower_body_only(arms, "coco17")


def test_cli_solve_and_convert_a_lower_body_trc(tmp_path, motion, capsys):
    path = _pig_trc(tmp_path / "lower.trc", motion, True)
    assert cli.main(["solve", str(path), "--out", str(tmp_path / "s"), "--format", "json"]) == 0
    assert (tmp_path / "s" / "lower.json").stat().st_size > 0
    assert "lower body only" in capsys.readouterr().out
    pytest.importorskip("dask")
    assert cli.main(["convert", str(path), "--out", str(tmp_path / "c"), "--format", "json",
                     "--workers", "1", "--no-progress"]) == 0
    assert (tmp_path / "c" / "lower.json").stat().st_size > 0


def test_stray_upper_body_samples_keep_a_lower_body_take(motion):
    """A detector's false positives in a crop to the legs (a wrist on one frame, a nose on
    another) leave it a lower-body take: the strays are dropped and said, the legs solved as
    without them.  Before: the take went the full-body way and was refused ("joint(s) pelvis,
    spine1, ... cannot be placed: point(s) ... left_shoulder ... never seen")."""
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    t = np.arange(len(clean)) / 30.0
    lay = kl.LAYOUTS["coco17"]
    legs_only = clean.copy()
    legs_only[:, [lay.index(p) for p in UPPER_COCO]] = np.nan
    stray = legs_only.copy()
    stray[40, lay.index("left_wrist")] = clean[40, lay.index("left_wrist")] + [0.3, 0.1, -0.5]
    stray[90, lay.index("nose")] = clean[90, lay.index("nose")]
    assert kl.lower_body_only(stray, "coco17")
    assert kl.drop_stray_upper_body(stray, "coco17")[1] == 2
    ref = solve_recording(keypoints_from_points(t, legs_only, "coco17", "legs"), SolveSettings(fps=30.0))
    out = solve_recording(keypoints_from_points(t, stray, "coco17", "stray"), SolveSettings(fps=30.0))
    assert "2 stray upper-body sample(s) left out" in out.summary(), out.summary()
    assert np.allclose(out.result.positions, ref.result.positions, atol=1e-9)
    _check_upright_trunk(out)
    # body22 straight from the raw points (no solve): the stray wrist does not reach the arms
    b22 = kl.body22_from_keypoints(stray, "coco17")
    assert b22.lower_body and np.allclose(b22.positions, kl.body22_from_keypoints(legs_only, "coco17").positions,
                                          equal_nan=True)
    # upper-body points seen on more frames: not strays, the full-body way (refused, naming them)
    many = legs_only.copy()
    many[:20, lay.index("left_wrist")] = clean[:20, lay.index("left_wrist")]
    assert not kl.lower_body_only(many, "coco17")


@pytest.mark.parametrize("layout", ["mediapipe33", "body25"])
def test_feet_never_seen_lie_flat_facing_the_hips(motion, layout):
    """A crop above the toes (heels and toes never seen) in a layout that has them: the feet lie
    flat ahead of the ankles facing the way the hips face, as in a layout without them (COCO),
    their twist said missing.  Before: refused ("joint(s) left_foot, right_foot cannot be placed")."""
    body, pos, world = motion
    lay = kl.LAYOUTS[layout]
    clean = kl.keypoints_from_body22(pos, world, layout, body.stature)
    t = np.arange(len(clean)) / 30.0
    feet = [k for k, p in enumerate(lay.points) if any(w in p for w in ("heel", "toe", "foot_index"))]
    full = clean.copy()
    full[:, feet] = np.nan
    out = solve_recording(keypoints_from_points(t, full, layout, "nofeet"), SolveSettings(fps=30.0))
    assert {"left_foot", "right_foot"} <= set(kl.body22_from_keypoints(full, layout).no_twist)
    assert "right_foot" in next(x for x in out.summary().split("; ") if x.startswith("no twist")), out.summary()
    legs = full.copy()
    legs[:, [k for k, p in enumerate(lay.points) if p not in kl.LOWER_BODY_POINTS]] = np.nan
    lower = solve_recording(keypoints_from_points(t, legs, layout, "legs"), SolveSettings(fps=30.0))
    assert "lower body only" in lower.summary() and "left_foot" in lower.summary()
    e = _leg_errors(lower.result.positions, pos)
    assert max(e.values()) < 0.03, e
    b22 = kl.body22_from_keypoints(legs, layout)
    fwd = rot.normalize(b22.positions[:, sk.J["left_foot"]] - b22.positions[:, sk.J["left_ankle"]])
    hip_left = b22.positions[:, sk.J["left_hip"]] - b22.positions[:, sk.J["right_hip"]]
    facing = rot.normalize(np.cross(hip_left, np.broadcast_to([0.0, 0.0, 1.0], hip_left.shape)))
    assert np.all(np.sum(fwd * facing, -1) > 0.7) and np.abs(fwd[:, 2]).max() < 0.75


def _angle_deg(A, B):
    """``(T,)`` degrees between rotations ``A`` and ``B`` ``(T, 3, 3)``."""
    rel = np.swapaxes(A, -1, -2) @ B
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)))


def test_pelvis_markers_tilt_a_lower_body_take(tmp_path, motion):
    """Plug-in Gait's ASIS and PSIS show the pelvis's forward tilt, which two hip centres cannot: a
    lower-body take whose pelvis tilts by a known angle over time (from 6° back to 14° forwards
    about the hip line; the ASIS-PSIS line at its neutral 12° on the upright pelvis) is solved with
    the pelvis following it within 2° and the trunk leaning with it (upright on the pelvis).
    Before: the pelvis stood upright on the world's up (off by the whole tilt)."""
    body, pos, world = motion
    t = np.arange(len(pos)) / 60.0
    tilt = np.radians(4.0 + 10.0 * np.sin(2.0 * np.pi * 0.8 * t))
    hip_line = pos[:, sk.J["left_hip"]] - pos[:, sk.J["right_hip"]]
    tilted = world.copy()            # the pelvis turned about the hip line: the hips and legs stay
    tilted[:, sk.J["pelvis"]] = rot.axis_angle_rotation(hip_line, tilt) @ world[:, sk.J["pelvis"]]
    path = _pig_trc(tmp_path / "tilt.trc", (body, pos, tilted), True)
    out = solve_recording(str(path), SolveSettings(fps=60.0))
    assert "tilted forwards and back with the pelvis markers (ASIS, PSIS), 12° of anterior tilt taken as " \
           "upright" in out.summary(), out.summary()
    P, W = out.result.fk()
    n = min(len(P), len(pos))
    err = _angle_deg(W[:n, sk.J["pelvis"]], tilted[:n, sk.J["pelvis"]])
    assert err.max() < 2.0, err.max()
    # the trunk leans with the pelvis: the neck where the tilted pelvis carries the rest body's
    rest = out.body.rest_positions()
    want = np.einsum("tij,j->ti", tilted[:n, sk.J["pelvis"]], rest[sk.J["neck"]] - rest[sk.J["pelvis"]])
    got = P[:n, sk.J["neck"]] - P[:n, sk.J["pelvis"]]
    lean = np.degrees(np.arccos(np.clip(np.sum(rot.normalize(want) * rot.normalize(got), -1), -1.0, 1.0)))
    assert lean.max() < 2.0, lean.max()
    for j in ("spine1", "spine2", "spine3", "neck", "head"):        # still upright on the pelvis
        assert _angle_deg(W[:, sk.J["pelvis"]], W[:, sk.J[j]]).max() < 1.0, j
    assert max(_leg_errors(P, pos).values()) < 0.02


def test_keypoint_lower_body_takes_without_pelvis_markers_stay_upright(motion):
    """Keypoints (no pelvis markers): the lower-body pelvis stands upright as before."""
    body, pos, world = motion
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    legs_only = clean.copy()
    legs_only[:, [kl.LAYOUTS["coco17"].index(p) for p in UPPER_COCO]] = np.nan
    b22 = kl.body22_from_keypoints(legs_only, "coco17")
    assert b22.lower_body and not b22.pelvis_tilt and sk.J["pelvis"] not in b22.end_rot


def _solved_with_points_cut(motion, layout, sides, points):
    """``(full, cut)`` solves of ``motion``'s ``layout`` keypoints: all of them, and with ``points``
    (``"wrist"``, ...) of ``sides`` never seen (NaN the whole take; still a full-body take)."""
    body, pos, world = motion
    lay = kl.LAYOUTS[layout]
    clean = kl.keypoints_from_body22(pos, world, layout, body.stature)
    t = np.arange(len(clean)) / 30.0
    cut = clean.copy()
    gone = {f"{s}_{w}" for s in sides for w in points}
    cut[:, [k for k, p in enumerate(lay.points) if p in gone]] = np.nan
    assert not kl.lower_body_only(cut, layout)
    full = solve_recording(keypoints_from_points(t, clean, layout, "full"), SolveSettings(fps=30.0))
    return full, solve_recording(keypoints_from_points(t, cut, layout, "cut"), SolveSettings(fps=30.0))


def _rest_as_the_full_take(P, Pf, sides):
    """Every joint but the elbows and wrists of ``sides`` within 1 cm (median) of the full take's
    solve ``Pf``; ``P`` ``(T, 22, 3)`` metres."""
    seen = [j for j in sk.JOINT_NAMES if not any(j == f"{s}_{a}" for s in sides for a in ("elbow", "wrist"))]
    for j in seen:
        d = np.linalg.norm(P[:, sk.J[j]] - Pf[:, sk.J[j]], axis=-1)
        assert np.median(d) < 0.01, (j, np.median(d))


@pytest.mark.parametrize("layout, sides", [("coco17", ("left", "right")), ("mediapipe33", ("left",))])
def test_arms_never_seen_hang_at_rest(motion, layout, sides):
    """Video keypoints with the hands cut off all take (shoulders, trunk and head seen, an arm's
    elbow and wrist never): the arm hangs at rest from its shoulder (70° below the shoulder line,
    elbow straight), said so; the rest of the body as the full take solves it.
    Before: refused ("joint(s) left_elbow, ... cannot be placed")."""
    full, out = _solved_with_points_cut(motion, layout, sides, ("elbow", "wrist", "index", "pinky", "thumb"))
    summary = out.summary()
    assert f"arm(s) never seen: the {' and '.join(sides)} arm(s) hang at rest from the shoulder (70° below " \
           "horizontal, elbow straight)" in summary, summary
    assert "lower body only" not in summary
    P, W = out.result.fk()
    Pf = full.result.positions
    _rest_as_the_full_take(P, Pf, sides)
    for s in sides:
        sh, el, wr = (P[:, sk.J[f"{s}_{a}"]] for a in ("shoulder", "elbow", "wrist"))
        upper, fore = rot.normalize(el - sh), rot.normalize(wr - el)
        assert np.sum(upper * fore, -1).min() > 0.98                        # elbow straight
        line = rot.normalize(P[:, sk.J["left_shoulder"]] - P[:, sk.J["right_shoulder"]])
        drop = np.degrees(np.arccos(np.clip(np.abs(np.sum(upper * line, -1)), 0.0, 1.0)))
        assert np.abs(drop - kl.ARM_DROP_DEG).max() < 3.0, (drop.min(), drop.max())
        assert (wr[:, 2] < sh[:, 2] - 0.3).all()


@pytest.mark.parametrize("layout", ["opencap", "plugingait"])
def test_pelvis_from_marker_points_round_trip(motion, layout):
    """The mid-ASIS / mid-PSIS points :func:`keypoint_layouts.keypoints_from_body22` places on a
    tilted pelvis give that pelvis back in a lower-body take (:func:`keypoint_layouts.pelvis_from_markers`)."""
    body, pos, world = motion
    lay = kl.LAYOUTS[layout]
    hip_line = pos[:, sk.J["left_hip"]] - pos[:, sk.J["right_hip"]]
    tilted = world.copy()
    tilted[:, sk.J["pelvis"]] = rot.axis_angle_rotation(hip_line, np.linspace(-0.2, 0.3, len(pos))) \
        @ world[:, sk.J["pelvis"]]
    kp = kl.keypoints_from_body22(pos, tilted, layout, body.stature)
    kp[:, [k for k, p in enumerate(lay.points) if p not in kl.LOWER_BODY_POINTS]] = np.nan
    b = kl.body22_from_keypoints(kp, layout)
    assert b.lower_body and b.pelvis_tilt
    assert _angle_deg(b.end_rot[sk.J["pelvis"]], tilted[:, sk.J["pelvis"]]).max() < 1e-4


def test_psis_missing_at_the_start_keeps_the_trunk_upright(tmp_path, motion):
    """A lower-body Plug-in Gait take whose PSIS markers are not seen on its first 30 frames (the
    ASIS are): the mid-ASIS and mid-PSIS are held together over that start, so the pelvis keeps its
    first seen tilt and the trunk stands up on it.  Before: the mid-PSIS was held while the mid-ASIS
    walked on past it, turning the pelvis over (158° off) and the trunk upside down."""
    body, pos, world = motion
    names, pts = anatomical_markers(pos, world, body.stature, "plugingait", medial=False)
    pts = pts.copy()
    for k, n in enumerate(names):
        if n[1:] in UPPER_MARKERS:
            pts[:, k] = np.nan
        if n in ("LPSI", "RPSI"):
            pts[:30, k] = np.nan
    assert np.linalg.norm(pos[30, sk.J["pelvis"]] - pos[0, sk.J["pelvis"]]) > 0.3     # it walks meanwhile
    path = tmp_path / "late_psis.trc"
    write_marker_trc(path, names, pts)
    text = path.read_text(encoding="utf-8")
    path.write_text("\n".join("\t".join("" if c.strip() == "nan" else c for c in line.split("\t"))
                              for line in text.split("\n")), encoding="utf-8")
    out = solve_recording(str(path), SolveSettings(fps=60.0))
    assert "tilted forwards and back with the pelvis markers" in out.summary()
    P, W = out.result.fk()
    n = min(len(P), len(pos))
    trunk = P[:n, sk.J["neck"]] - P[:n, sk.J["pelvis"]]
    assert (trunk[:, 2] > 0.8 * np.linalg.norm(trunk, axis=-1)).all(), trunk[:5]
    assert _angle_deg(W[:n, sk.J["pelvis"]], world[:n, sk.J["pelvis"]])[30:].max() < 2.0


@pytest.mark.parametrize("layout, sides", [("coco17", ("left", "right")), ("mediapipe33", ("right",))])
def test_a_wrist_never_seen_continues_its_upper_arm(motion, layout, sides):
    """Hands cut off by the frame all take while the elbows are seen: the forearm continues the
    upper arm, straight, its length the proportions' beside the measured upper arm; said so, the
    rest of the body as the full take solves it.  Before: refused ("joint(s) left_wrist ... cannot
    be placed")."""
    full, out = _solved_with_points_cut(motion, layout, sides, ("wrist", "index", "pinky", "thumb"))
    summary = out.summary()
    assert f"wrist(s) never seen: the {' and '.join(sides)} forearm(s) continue the upper arm, straight" in summary, \
        summary.split("; ")
    P = out.result.positions
    Pf = full.result.positions
    _rest_as_the_full_take(P, Pf, sides)
    for s in sides:
        sh, el, wr = (P[:, sk.J[f"{s}_{a}"]] for a in ("shoulder", "elbow", "wrist"))
        upper, fore = el - sh, wr - el
        cos = np.sum(rot.normalize(upper) * rot.normalize(fore), -1)
        assert np.median(cos) > 0.97, np.median(cos)                # straight (within the joint limits)
        ratio = np.linalg.norm(fore, axis=-1) / np.linalg.norm(upper, axis=-1)
        assert np.median(ratio) == pytest.approx(sk.PROPORTIONS["forearm"] / sk.PROPORTIONS["upper_arm"], rel=0.1)
        # the elbow where the keypoints put it (the upper arm is seen)
        assert np.median(np.linalg.norm(el - Pf[:, sk.J[f"{s}_elbow"]], axis=-1)) < 0.05
