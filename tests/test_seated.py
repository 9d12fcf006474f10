"""Seated performers (core/seated.py): the legs sit on a chair, the feet on the floor."""
import numpy as np
import pytest

from blender_manikin.core import solve as cs
from blender_manikin.core.seated import SEATED_HEAD_HEIGHT, seated_leg_targets
from blender_manikin.core.skeleton import J, make_body

from fixtures_seated import seated_recording


def _flex(P, a, b, c):
    u, v = P[:, J[b]] - P[:, J[a]], P[:, J[c]] - P[:, J[b]]
    return np.degrees(np.arccos(np.sum(u * v, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)))


@pytest.fixture(scope="module")
def take():
    body = make_body(1.75)
    rec, pos, world = seated_recording(body)
    return body, rec, pos


def _truth_at(result, pos, rate=72.0):
    t = result.t0 + np.arange(result.num_frames) / result.fps
    return pos[np.clip(np.round(t * rate).astype(int), 0, len(pos) - 1)]


@pytest.mark.parametrize("height", [None, 1.75])
def test_a_seated_take_solved_seated(take, height):
    body, rec, pos = take
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, posture="seated", height=height,
                                                   calibration="MEASURE" if height else "AUTO"))
    if height is None:         # sized by the seated head: a seat at knee height, within 1 %
        assert out.body.stature == pytest.approx(1.75, rel=0.01)
        assert any(n.startswith("stature 1.74 m from the seated head height") for n in out.info)
    P = out.result.positions
    G = _truth_at(out.result, pos)
    err = np.linalg.norm(P - G, axis=-1)
    legs = [J[n] for n in ("left_knee", "right_knee", "left_ankle", "right_ankle")]
    assert err.mean() < 0.04 and err[:, legs].mean() < 0.08, (err.mean(), err[:, legs].mean())
    for side in ("left", "right"):
        knee = _flex(P, f"{side}_hip", f"{side}_knee", f"{side}_ankle")
        assert 75 < np.median(knee) < 105
        ankle_z = P[:, J[f"{side}_ankle"], 2]
        assert np.abs(ankle_z - body.rest_positions()[J[f"{side}_ankle"], 2]).max() < 0.005   # on the floor
    assert out.result.contacts.all()
    for d, j in (("left_hand", "left_wrist"), ("right_hand", "right_wrist")):
        assert np.median(np.linalg.norm(P[:, J[j]] - out.result.targets.pos[d], axis=-1)) < 1e-4
    assert "estimated stature" not in out.summary()


def test_the_same_take_solved_standing_is_a_short_standing_body(take):
    """What the setting is for: solved standing, the seated take becomes a 1.26 m standing body
    with its legs far off, and the summary points at the posture."""
    body, rec, pos = take
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert out.body.stature < 1.40 and "set the Posture, --posture, to seated" in out.summary()
    err = np.linalg.norm(out.result.positions - _truth_at(out.result, pos), axis=-1)
    assert err[:, [J["left_knee"], J["right_knee"]]].mean() > 0.25


def test_a_standing_t_pose_before_sitting_sizes_the_body():
    body = make_body(1.62)
    rec, pos, _ = seated_recording(body, stand_first=True)
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, posture="seated"))
    assert any(n.startswith("calibrated on a T-pose at 1.") for n in out.info), out.info
    assert not any("seated head height" in n for n in out.info)
    assert out.body.stature == pytest.approx(1.62, abs=0.02)
    late = out.result.positions[int(4 * 30):]
    assert np.abs(late[:, J["left_ankle"], 2] - body.rest_positions()[J["left_ankle"], 2]).max() < 0.005


def test_seated_leg_targets_follow_the_seat_height():
    body = make_body(1.75)
    rest = body.rest_positions()
    thigh, shank = body.limb_lengths()[2]
    pelvis = np.tile(np.eye(3), (3, 1, 1))
    knee_h = rest[J["left_ankle"], 2] + shank
    hips = np.stack([np.stack([rest[J["left_hip"]], rest[J["right_hip"]]])] * 3)
    for k, z in enumerate((knee_h, knee_h - 0.10, knee_h + thigh + 0.2)):      # knee height, lower, standing
        hips[k, :, 2] = z
    knees, ankles, rot = seated_leg_targets(hips, pelvis, body)
    np.testing.assert_allclose(np.linalg.norm(knees - hips, axis=-1), thigh, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(ankles - knees, axis=-1), shank, atol=1e-9)
    np.testing.assert_allclose(ankles[:2, :, 2], rest[J["left_ankle"], 2], atol=1e-9)        # on the floor
    assert knees[0, 0, 1] < hips[0, 0, 1] - 0.9 * thigh            # thigh level, forward (-Y)
    assert knees[1, 0, 2] > hips[1, 0, 2]                            # a low seat: knees above the hips
    np.testing.assert_allclose(knees[2, :, :2], hips[2, :, :2], atol=1e-9)     # too high to sit: hanging,
    np.testing.assert_allclose(ankles[2, :, 2], hips[2, :, 2] - thigh - shank, atol=1e-9)    # 0.2 m up
    np.testing.assert_allclose(rot, np.tile(np.eye(3), (3, 2, 1, 1)), atol=1e-9)   # flat, ahead
    assert SEATED_HEAD_HEIGHT == pytest.approx(0.257 + 0.05 + 0.870 - 0.530)


def test_a_bad_posture_is_refused():
    with pytest.raises(cs.SolveError, match="posture 'kneeling': expected one of standing, seated"):
        cs.solve_recording(*_example_and(posture="kneeling"))


def _example_and(**kw):
    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return os.path.join(root, "examples", "example_recording.csv"), cs.SolveSettings(fps=30.0, **kw)


def test_a_tracked_foot_stays_on_its_tracker_when_seated():
    from fixtures_six_trackers import random_mounts, six_tracker_recording
    body = make_body(1.70)
    rec = six_tracker_recording(body, random_mounts(4))
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, posture="seated"))
    P = out.result.positions
    for d, j in (("left_foot", "left_ankle"), ("right_foot", "right_ankle")):
        miss = np.linalg.norm(P[:, J[j]] - out.result.targets.pos[d], axis=-1)
        assert np.median(miss) < 1e-3, (d, np.median(miss))


def test_a_seated_take_at_eye_level_finds_its_floor(take):
    """A seated take whose origin is at eye level (the seated head about 0 m up, the floor left
    at 0): with the height typed, the floor goes under the seated head by the seated proportions,
    and the take solves as the one on the floor does."""
    import copy
    body, rec, pos = take
    low = copy.deepcopy(rec)
    for st in low.streams.values():
        st.pos[:, 2] -= 1.13                       # the seated head joint was about 1.13 m up
    settings = cs.SolveSettings(fps=30.0, posture="seated", height=1.75, calibration="MEASURE")
    ref = cs.solve_recording(rec, settings)
    out = cs.solve_recording(low, settings)
    assert "the recording's origin is at eye level: under the typed 1.75 m, seated" in out.summary()
    assert out.floor == pytest.approx(-1.13, abs=0.015)
    assert np.abs(out.result.positions - ref.result.positions).max() < 0.02


def test_a_take_that_stands_longer_than_it_sits_finds_its_seated_head():
    """Standing most of the take (its median head a standing one), then sitting: the seated head
    is the one of the frames it sits, so the eye-level floor lands under the performer (it was
    put 0.42 m too high, under the standing head taken for a seated one) and the stature from the
    seated head is not 1.37 times the performer's."""
    import copy
    body = make_body(1.75)
    rec, pos, _ = seated_recording(body, duration=3.3, stand_first=True)     # stands 1.5 s, sits from 2.5 s
    low = copy.deepcopy(rec)
    for st in low.streams.values():
        st.pos[:, 2] -= 1.45
    out = cs.solve_recording(low, cs.SolveSettings(fps=30.0, posture="seated", height=1.75, calibration="MEASURE"))
    assert out.floor == pytest.approx(-1.45, abs=0.02), out.floor
    late = out.result.positions[-8:]
    np.testing.assert_allclose(late[:, J["pelvis"], 2], pos[-1, J["pelvis"], 2], atol=0.03)
    from blender_manikin.core.seated import stood_and_sat
    head = pos[:, J["head"], 2]
    drop = head.max() - SEATED_HEAD_HEIGHT * 1.75
    stood, seated_head = stood_and_sat(head, drop)
    assert stood and seated_head == pytest.approx(SEATED_HEAD_HEIGHT * 1.75, abs=0.02)
    sitting = head[pos[:, J["pelvis"], 2] < pos[0, J["pelvis"], 2] - 0.3]
    assert stood_and_sat(sitting, drop) == (False, pytest.approx(np.median(sitting)))   # seated all along


def test_seated_feet_stay_planted_while_the_hips_sway(take):
    """Seated at a desk, the head turning and a hand reaching: the solved hips sway with the torso,
    and the seated feet under them slid with them (5-9 cm back and forth, 24-29 cm of travel over
    8 s) though marked planted; they are held where they stand."""
    body, rec, pos = take
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, posture="seated", height=1.75, calibration="MEASURE"))
    P = out.result.positions
    assert out.result.contacts.all()
    for a in ("left_ankle", "right_ankle"):
        xy = P[:, J[a], :2]
        assert np.linalg.norm(np.diff(xy, axis=0), axis=-1).sum() < 0.01, a


def test_seated_feet_go_round_with_a_turning_chair():
    """hold_seated_feet: held while the pelvis keeps its heading, carried round while the chair
    turns (90 degrees in a second), held again after, no jump."""
    from blender_manikin.core.features import rot_z
    from blender_manikin.core.seated import hold_seated_feet
    fps, T = 30.0, 120
    yaw = np.radians(np.clip((np.arange(T) - 45) / fps, 0.0, 1.0) * 90.0)          # turns from 1.5 to 2.5 s
    pelvis = rot_z(yaw)
    sway = 0.04 * np.sin(np.arange(T) / 5.0)
    ankles = np.stack([np.stack([0.1 * np.cos(yaw) + sway, 0.1 * np.sin(yaw) - 0.4, np.full(T, 0.08)], -1)] * 2, 1)
    held = hold_seated_feet(ankles, pelvis, fps)
    still_before, still_after = slice(0, 40), slice(85, T)
    for part in (still_before, still_after):
        assert np.ptp(held[part, 0, :2], axis=0).max() < 1e-9                        # planted
    assert np.linalg.norm(held[80, 0, :2] - held[40, 0, :2]) > 0.1                   # went round
    assert np.abs(held[..., 2] - ankles[..., 2]).max() == 0.0                        # on the floor as set
    assert np.linalg.norm(np.diff(held[:, 0], axis=0), axis=-1).max() < 0.03         # eased, no jump


def test_a_tall_seated_performer_solved_standing_is_told_to_set_seated():
    """A 2.0 m performer on a seat at knee height, solved standing: the standing head height gives a
    1.44 m body, a stature in the plausible range (so no stature note), but the hands reach 1.58 m
    apart, 1.1 times it: the summary says to check whether the performer sits.  Solved seated, or
    with a standing T-pose's body, nothing is said."""
    body = make_body(2.0)
    rec, pos, _ = seated_recording(body)
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert 1.40 <= out.body.stature < 1.5
    assert "check whether the performer sits: the hands reach" in out.summary(), out.summary()
    assert "set the Posture to Seated (--posture seated)" in out.summary()
    seated = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, posture="seated"))
    assert "check whether the performer sits" not in seated.summary()
    typed = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, height=2.0))
    assert "check whether the performer sits" not in typed.summary()


def test_a_six_tracker_take_without_a_t_pose_is_not_told_the_performer_may_sit():
    """Pelvis and foot trackers, no T-pose (the take cut after it): the pelvis tracker's offset is
    not measured and the arms are lengthened to reach the hands (1.89 m for a 1.72 m performer).
    The legs are tracked, so the summary does not say the performer may sit; it names the
    unmeasured pelvis offset."""
    from blender_manikin.core.recording import Recording, TrackerStream
    from fixtures_six_trackers import body_with_legs, random_mounts, six_tracker_recording
    base = six_tracker_recording(body_with_legs(1.72, 1.0), random_mounts(5), duration=8.0, seed=5,
                                 heading=20.0, shift=(0.3, -0.2))
    streams = {k: TrackerStream(k, st.time[st.time >= 2.0], st.pos[st.time >= 2.0], st.quat[st.time >= 2.0])
               for k, st in base.streams.items()}
    out = cs.solve_recording(Recording(streams=streams, source=base.source, metadata=dict(base.metadata)),
                             cs.SolveSettings(fps=30.0))
    said = out.summary()
    assert "check the arms: the hands reach" in said, said
    assert "performer sits" not in said, said
    assert "the pelvis tracker's offset was not measured (no T-pose)" in said, said
