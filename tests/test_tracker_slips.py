"""Foot trackers slipping on the body mid-take (core/tracker_slips.py): found, named, put right.

Six-tracker takes made by FK (tests/fixtures_slips.py: walking in place, squats, kicks) with a foot
tracker's strap slid up the shin or turned round it at a known time; the truth is the body's.
"""
import numpy as np
import pytest

from blender_manikin.core import solve as cs
from blender_manikin.core import tracker_slips as ts
from blender_manikin.core.rotations import geodesic_angle
from blender_manikin.core.skeleton import J
from blender_manikin.core.tracker_slips import correct_tracker_slips, find_tracker_slips, tracker_slip_notes
from fixtures_six_trackers import body_with_legs, random_mounts
from fixtures_slips import BODY_STEPS, KINDS, slip_recording, slip_take

BODY = body_with_legs(1.75)
REST = float(BODY.rest_positions()[J["left_ankle"], 2])
AT = 4.3


@pytest.mark.parametrize("kind", KINDS)
def test_takes_without_a_slip_have_none(kind):
    """Walking, squatting to 90° and kicking: the planted ankles keep their height and heading."""
    for seed in range(4):
        targets = slip_take(BODY, random_mounts(seed), kind, seed=seed)[0]
        assert find_tracker_slips(targets, rest_ankle_z=REST) == [], (kind, seed)


@pytest.mark.parametrize("kind", BODY_STEPS)
def test_what_the_body_does_is_no_slip(kind):
    """Both feet onto a 15 cm platform (both planted ankles higher) is no strap; a foot turned out
    40° and held (a stance) is named but not corrected, the targets left as they are."""
    targets = slip_take(BODY, random_mounts(3), kind, seed=3)[0]
    slips = find_tracker_slips(targets, rest_ankle_z=REST)
    assert all(not s.corrected for s in slips), slips
    fixed = correct_tracker_slips(targets, slips)
    for d in targets.pos:
        np.testing.assert_array_equal(fixed.pos[d], targets.pos[d])
    if kind == "platform":
        assert slips == []


def _ankle_errors(targets, P, R, device, frames):
    j = J[device.replace("foot", "ankle")]
    dist = np.linalg.norm(targets.pos[device][frames] - P[frames, j], axis=-1)
    ang = np.degrees(geodesic_angle(targets.rot[device][frames], R[frames, j]))
    return dist.mean(), ang.mean()


@pytest.mark.parametrize("kind,device,slide,turn", [
    ("walk", "left_foot", 0.07, 0.0),
    ("walk", "right_foot", 0.0, 30.0),
    ("squat", "left_foot", 0.05, 0.0),
    ("squat", "right_foot", 0.0, 20.0),
    ("kick", "left_foot", 0.10, 40.0),
])
@pytest.mark.parametrize("measured_after", [False, True])
def test_a_slipped_foot_tracker_is_found_and_put_right(kind, device, slide, turn, measured_after):
    """A strap slid 5-10 cm up the shin or turned 20-40° round it at 4.3 s: found on that foot,
    between frames around that moment, by how much, and the ankle target put right on the side
    the offsets do not fit (after the slip; before it when the T-pose that measured them came
    after)."""
    targets, P, R, t = slip_take(BODY, random_mounts(2), kind, slip=(device, AT, slide, turn), seed=2,
                                 measured_after=measured_after)
    slips = find_tracker_slips(targets, rest_ankle_z=REST)
    assert [s.device for s in slips] == [device]
    s = slips[0]
    assert t[s.start] <= AT + 0.02 and t[s.end] >= AT - 0.02 and t[s.end] - t[s.start] < 2.0
    assert s.slide == pytest.approx(slide, abs=0.01) and s.turn_deg == pytest.approx(turn, abs=3.0)
    assert s.after == measured_after
    wrong = t < AT - 1.0 if measured_after else t > AT + 1.0          # away from the easing
    dist, ang = _ankle_errors(targets, P, R, device, wrong)
    fixed = correct_tracker_slips(targets, slips)
    assert s.corrected == bool(slide)
    if not slide:                   # a turn alone may be a stance: named, not corrected
        for d in targets.pos:
            np.testing.assert_array_equal(fixed.pos[d], targets.pos[d])
            np.testing.assert_array_equal(fixed.rot[d], targets.rot[d])
        assert "not corrected" in tracker_slip_notes(slips, 60.0)[0]
        return
    dist2, ang2 = _ankle_errors(fixed, P, R, device, wrong)
    assert dist2 < 0.01 and ang2 < 2.0, (dist, ang, dist2, ang2)
    assert dist > 0.04 or ang > 15.0
    right = t > AT + 1.0 if measured_after else t < AT - 1.0          # the other side is left alone
    for d in targets.pos:
        np.testing.assert_allclose(fixed.pos[d][right], targets.pos[d][right], atol=1e-12)


def test_the_solve_names_the_slip_and_the_leg_follows_the_body():
    """End to end: the summary names the tracker, the time and the slip, and the solved left leg
    stays on the performer's after it (solved as recorded: the knee 11.6 cm and the ankle 6.9 cm
    off on average for the rest of the take, and nothing said)."""
    rec, P, _, t = slip_recording(BODY, random_mounts(1), "walk", slip=("left_foot", AT, 0.07, 0.0), seed=1)
    out = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert [s.device for s in out.slips] == ["left_foot"]
    assert any(n.startswith("left foot tracker offset changed at ") and "7.0 cm up the shin" in n
               for n in out.summary().split("; ")), out.summary()
    res = out.result
    idx = np.round((res.t0 + np.arange(res.num_frames) / res.fps) * 60).astype(int)
    late = t[idx] > AT + 1.0
    for name, tol in (("left_knee", 0.03), ("left_ankle", 0.01)):
        err = np.linalg.norm(res.positions[late, J[name]] - P[idx][late, J[name]], axis=-1)
        assert err.mean() < tol, (name, err.mean())


def test_a_body_lying_down_is_no_slip():
    """Lying on the floor (HDM05's lieDownFloor takes) holds a still foot on its side, its ankle
    higher than standing and turned against a pelvis that lies too: no strap slipped.  Plants
    count only with the foot flat and the pelvis upright (before: a 5 cm 'slide' put right, the
    foot pushed into the floor)."""
    from dataclasses import replace
    from blender_manikin.core.rotations import axis_angle_rotation
    targets, _, _, t = slip_take(BODY, random_mounts(4), "walk", seed=4)
    late = t > AT
    tip = axis_angle_rotation(np.array([1.0, 0.0, 0.0]), np.radians(80.0))
    pos, rot = dict(targets.pos), dict(targets.rot)
    pos["right_foot"] = pos["right_foot"] + late[:, None] * [0.0, 0.0, 0.05]
    for d in ("right_foot", "pelvis"):
        rot[d] = np.where(late[:, None, None], tip @ rot[d], rot[d])
    assert find_tracker_slips(replace(targets, pos=pos, rot=rot), rest_ankle_z=REST) == []


def test_a_pelvis_tracker_turning_round_the_belt_is_named():
    """The pelvis tracker's belt turned 25° round the waist at 4.3 s: both planted feet turn alike
    against it and stay so; named as the pelvis tracker's (or a stance), not corrected."""
    targets, _, _, t = slip_take(BODY, random_mounts(2), "walk", slip=("pelvis", AT, 0.0, 25.0), seed=2)
    slips = find_tracker_slips(targets, rest_ankle_z=REST)
    assert [s.device for s in slips] == ["pelvis"] and not slips[0].corrected
    assert slips[0].turn_deg == pytest.approx(25.0, abs=3.0)
    assert t[slips[0].start] <= AT + 0.02 and t[slips[0].end] >= AT - 0.02
    note = tracker_slip_notes(slips, 60.0)[0]
    assert note.startswith("pelvis tracker: both planted feet turned 2") and "not corrected" in note
    fixed = correct_tracker_slips(targets, slips)
    for d in targets.pos:
        np.testing.assert_array_equal(fixed.rot[d], targets.rot[d])


def _best_step_by_every_split(values):
    """The step search as it reads (:func:`tracker_slips._best_step`'s docstring): both sides'
    medians taken anew at every split."""
    best, step = None, 0.0
    for m in range(ts.MIN_PLANTS, len(values) - ts.MIN_PLANTS + 1):
        a, b = values[:m], values[m:]
        d = float(np.median(b) - np.median(a))
        scatter = max(np.abs(a - np.median(a)).max(), np.abs(b - np.median(b)).max())
        if scatter <= ts.SLIP_CONSISTENT * abs(d) and abs(d) > abs(step):
            best, step = m, d
    return best, step


def test_the_step_search_takes_no_median_per_split(monkeypatch):
    """An hour of walking plants each foot some 3,000 times: a median of both sides at every
    split was O(K²) (1.9 s of the 60-minute take's 2 s in the slip detector; benchmarks/
    bench_long.py).  The running medians give the same split and step, to the bit, on steps,
    ties and no step, with no np.median call per split."""
    rng = np.random.default_rng(3)
    cases = []
    for k in range(300):
        v = rng.normal(0.1, 0.002, int(rng.integers(0, 60)))
        if k % 2:
            v[int(rng.integers(0, len(v) + 1)):] += rng.choice([0.02, -0.03, 0.004])
        cases.append(np.round(v, 3) if k % 3 == 0 else v)
    expected = [_best_step_by_every_split(v) for v in cases]
    assert sum(m is not None for m, _ in expected) > 50
    calls = []
    median = np.median
    monkeypatch.setattr(np, "median", lambda *a, **kw: calls.append(1) or median(*a, **kw))
    assert [ts._best_step(v) for v in cases] == expected
    long = np.concatenate([rng.normal(0.1, 0.002, 1500), rng.normal(0.13, 0.002, 1500)])
    calls.clear()
    assert ts._best_step(long) == (1500, pytest.approx(0.03, abs=0.002))
    assert len(calls) < 10
