"""Resampling onto a common grid, gap bridging and reporting, units sanity check."""
import os
import re
import time

import numpy as np
import pytest

from blender_manikin.core.formats import load_recording
from blender_manikin.core.recording import Recording, RecordingError, TrackerStream
from blender_manikin.core.resample import check_head_height, resample
from blender_manikin.core.rotations import axis_angle_to_quat, geodesic_angle, quat_to_matrix

from fixtures_recordings import make_recording, make_streams, truth, write_recording_csv

EXAMPLE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples", "example_recording.csv")


def rot_err_deg(qa, qb):
    return np.degrees(geodesic_angle(quat_to_matrix(qa), quat_to_matrix(qb)))


def test_grid_and_accuracy_with_mixed_jittered_rates():
    rec = make_recording(duration=3.0)                     # head 90, left 72, right 120 Hz, jittered
    times, pos, quat, valid, report = resample(rec, 60)
    assert times[0] == pytest.approx(0.0)
    np.testing.assert_allclose(np.diff(times), 1 / 60, atol=1e-12)
    last = min(rec.streams[d].time[-1] for d in rec.devices)
    assert times[-1] <= last + 1e-9 and times[-1] > last - 1 / 60
    assert report.num_frames == len(times) and report.gaps == []
    for d in rec.devices:
        p, q = truth(d, times)
        assert np.abs(pos[d] - p).max() < 1e-4
        assert rot_err_deg(quat[d], q).max() < 0.05
        assert valid[d].all()
        assert pos[d].shape == (len(times), 3) and quat[d].shape == (len(times), 4)


def test_t_start_t_end_define_the_grid():
    rec = make_recording(duration=3.0)
    times, pos, *_ = resample(rec, 30, t_start=0.5, t_end=1.5)
    np.testing.assert_allclose(times, 0.5 + np.arange(31) / 30)


def test_slerp_midpoint_between_two_samples():
    s = lambda d: TrackerStream(d, [0.0, 1.0], [[0, 0, 1.6], [0.2, 0, 1.8]],
                                axis_angle_to_quat(np.array([[0, 0, 0], [0, 0, np.pi / 2]])))
    rec = Recording({d: s(d) for d in ("head", "left_hand", "right_hand")})
    times, pos, quat, valid, report = resample(rec, 2)
    np.testing.assert_allclose(times, [0, 0.5, 1.0])
    np.testing.assert_allclose(pos["head"][1], [0.1, 0, 1.7])
    expect = axis_angle_to_quat(np.array([0, 0, np.pi / 4]))
    assert rot_err_deg(quat["head"][1], expect) < 1e-9
    # slerp, not normalised lerp: a quarter of the way is 22.5 deg
    times, pos, quat, valid, report = resample(rec, 4)
    assert rot_err_deg(quat["head"][1], axis_angle_to_quat(np.array([0, 0, np.pi / 8]))) < 1e-9


def test_quaternion_sign_flips_are_handled():
    rec = make_recording(duration=2.0, flip=("left_hand", 0.5, 1.2))
    times, pos, quat, valid, report = resample(rec, 60)
    q = quat["left_hand"]
    assert np.all(np.sum(q[1:] * q[:-1], -1) > 0)                    # sign-continuous output
    assert rot_err_deg(q, truth("left_hand", times)[1]).max() < 0.05  # no spurious spin at the flips
    assert report.sign_flips["left_hand"] == 2
    assert report.gaps == []


def test_missing_rows_gap_reported_with_duration_and_bridged():
    rec = make_recording(duration=3.0, gap=("left_hand", 1.0, 1.5))
    lh = rec.streams["left_hand"]
    before = lh.time[lh.time < 1.0][-1]
    after = lh.time[lh.time >= 1.5][0]
    times, pos, quat, valid, report = resample(rec, 60)
    gaps = report.for_device("left_hand")
    assert len(gaps) == 1 and report.gaps == gaps
    g = gaps[0]
    assert g.reason == "missing" and g.samples == 0
    assert g.start == pytest.approx(before) and g.end == pytest.approx(after)
    assert g.duration == pytest.approx(after - before)
    assert 0.5 <= g.duration <= 0.5 + 2.5 / 72                       # the removed half second
    inside = (times > before) & (times < after)
    assert inside.sum() >= 29 and not valid["left_hand"][inside].any()
    assert valid["left_hand"][~inside].all()
    # bridged linearly between the samples around the gap
    k = np.nonzero(inside)[0][len(np.nonzero(inside)[0]) // 2]
    a = (times[k] - before) / (after - before)
    i0 = np.searchsorted(lh.time, before)
    np.testing.assert_allclose(pos["left_hand"][k], (1 - a) * lh.pos[i0] + a * lh.pos[i0 + 1], atol=1e-12)
    assert "left_hand: missing" in report.summary()


@pytest.mark.parametrize("kind,reason", [("invalid", "invalid"), ("nan", "nan"), ("frozen", "frozen")])
def test_tracking_loss_kinds_are_bridged_and_reported(kind, reason):
    rec = make_recording(duration=3.0, **{kind: ("right_hand", 1.0, 1.3)})
    rh = rec.streams["right_hand"]
    times, pos, quat, valid, report = resample(rec, 60)
    gaps = report.for_device("right_hand")
    assert [g.reason for g in gaps] == [reason]
    g = gaps[0]
    in_defect = (rh.time >= 1.0) & (rh.time < 1.3)
    n_bad = in_defect.sum() - (1 if kind == "frozen" else 0)         # frozen: first sample is real
    assert g.samples == n_bad
    assert g.duration == pytest.approx(0.3, abs=2.5 / 120)
    assert not valid["right_hand"][(times > g.start) & (times < g.end)].any()
    assert np.all(np.isfinite(pos["right_hand"])) and np.all(np.isfinite(quat["right_hand"]))
    # the other devices are untouched
    assert valid["head"].all() and valid["left_hand"].all()
    # outside the gap the values are still the truth
    ok = (times < g.start - 0.02) | (times > g.end + 0.02)
    assert np.abs(pos["right_hand"][ok] - truth("right_hand", times[ok])[0]).max() < 1e-4


def test_short_frozen_or_all_still_is_not_a_gap():
    # repeated pose for 50 ms only: below the 0.1 s threshold
    rec = make_recording(duration=2.0, frozen=("right_hand", 1.0, 1.05))
    assert resample(rec, 60)[4].gaps == []
    # every device perfectly still: nothing moves, so nothing is "frozen"
    streams = {}
    for d in ("head", "left_hand", "right_hand"):
        t = np.arange(100) / 90
        p, q = truth(d, np.zeros(100))
        streams[d] = TrackerStream(d, t, p, q)
    assert resample(Recording(streams), 60)[4].gaps == []


def test_exactly_held_keys_of_scene_objects_are_not_frozen():
    """Keyed scene objects (metadata ``exact``) hold still exactly: not a lost tracker."""
    rec = make_recording(duration=3.0, frozen=("right_hand", 1.0, 2.0))
    assert [g.reason for g in resample(rec, 60)[4].gaps] == ["frozen"]
    rec.metadata["exact"] = True
    times, pos, quat, valid, report = resample(rec, 60)
    assert report.gaps == [] and valid["right_hand"].all()


def test_a_hand_lost_before_the_end_does_not_cut_the_take():
    """The take ends with the head: a hand lost for its last second is held (and a solve lets that
    arm hang); one whose last sample is only a few milliseconds early still ends the grid."""
    rec = make_recording(duration=3.0, invalid=("left_hand", 2.0, 3.1))
    times, pos, quat, valid, report = resample(rec, 60)
    head_last = rec.streams["head"].time[-1]
    assert times[-1] == pytest.approx(head_last, abs=1 / 60)
    assert [g.reason for g in report.for_device("left_hand")] == ["end"]
    assert not valid["left_hand"][times > 2.05].any()
    rec = make_recording(duration=3.0)
    times = resample(rec, 60)[0]
    assert times[-1] <= min(rec.streams[d].time[-1] for d in rec.devices) + 1e-9


def test_hold_at_ends_for_a_late_optional_device():
    rates = {"head": 90.0, "left_hand": 72.0, "right_hand": 72.0, "pelvis": 60.0}
    rec = make_recording(duration=2.0, rates=rates, starts={"pelvis": 0.5})
    times, pos, quat, valid, report = resample(rec, 30)
    g = report.for_device("pelvis")
    assert [x.reason for x in g] == ["start"]
    assert g[0].start == pytest.approx(0.0) and g[0].end == pytest.approx(0.5)
    first = rec.streams["pelvis"].pos[0]
    early = times < 0.5
    np.testing.assert_allclose(pos["pelvis"][early], np.repeat(first[None], early.sum(), 0))
    assert not valid["pelvis"][early].any() and valid["pelvis"][~early].all()


def test_required_devices():
    rec = make_recording(duration=1.0, rates={"head": 90.0})
    with pytest.raises(RecordingError, match="has no left_hand, right_hand samples"):
        resample(rec, 30)
    rec = make_recording(duration=1.0, rates={"head": 90.0, "left_hand": 72.0})
    times, pos, quat, valid, report = resample(rec, 30)      # one hand never there: held, marked lost
    assert not valid["right_hand"].any() and "right hand: no usable sample" in report.warnings[-1]
    rec.metadata["objects"] = {"head": ("HMD", ""), "left_hand": ("Left", "")}      # scene slots: chosen
    with pytest.raises(RecordingError, match="has no right_hand samples"):
        resample(rec, 30)
    times, pos, *_ = resample(rec, 30, required=("head",))
    assert set(pos) == {"head", "left_hand"}
    rec = make_recording(duration=1.0, nan=("head", 0.0, 2.0))
    with pytest.raises(RecordingError, match=r"head has no usable samples \(all invalid or NaN: \d+ with "
                                             r"not-a-number values\)"):
        resample(rec, 30)
    # positions only, the quaternions written as zeros: the error says that is why
    rec = make_recording(duration=1.0)
    rec.streams["head"].quat[:] = 0.0
    rec.streams["head"].valid[:5] = False
    with pytest.raises(RecordingError, match=r"head has no usable samples \(all invalid or NaN: 5 marked not "
                                             r"tracked, \d+ with a zero quaternion \(no orientation"):
        resample(rec, 30)


def test_units_check_message_for_millimetres(tmp_path):
    path, rec = write_recording_csv(tmp_path, name="take_mm.csv", units="mm", duration=1.0)
    # strip the units line: the file now looks like metres but holds millimetres
    text = open(path).read().replace("# units: mm\n", "")
    open(path, "w").write(text)
    bad = load_recording(path)
    with pytest.raises(RecordingError) as ei:
        resample(bad, 30)
    msg = str(ei.value)
    assert msg.startswith("take_mm.csv: ")
    assert re.search(r"head is 16\d\d m above the floor \(read as units=m\)", msg)
    assert "positions look like millimetres; set Units to Millimetres (--units mm)" in msg
    good = load_recording(path, units="mm")
    times, pos, *_ = resample(good, 30)
    assert 1.55 < np.median(pos["head"][:, 2]) < 1.7
    times, *_ = resample(bad, 30, check_units=False)                 # opt-out


def test_a_take_spent_mostly_on_the_floor_passes_the_units_check():
    """The check takes the head's standing height (its 90th percentile), not its median: a
    performer lying on the floor for most of the take (the head 0.2 m up, as in HDM05's lie-down
    clips) and standing for the rest is no units error; a head never above 0.2 m still is."""
    rec = make_recording(duration=3.0)
    head = rec.streams["head"]
    low = head.time < 0.8 * head.time[-1]
    head.pos[low, 2] = 0.2
    assert np.median(head.pos[:, 2]) < 0.5
    times, pos, *_ = resample(rec, 30)
    assert pos["head"][:, 2].min() < 0.25
    head.pos[:, 2] = np.minimum(head.pos[:, 2], 0.2)
    with pytest.raises(RecordingError, match="head is only 0.20 m above the floor"):
        resample(rec, 30)


def test_units_check_other_cases():
    with pytest.raises(RecordingError,
                       match=r"positions look like centimetres; set Units to Centimetres \(--units cm\)"):
        check_head_height(165.0)
    with pytest.raises(RecordingError, match=r"they look like metres already: set Units to Metres \(--units m\)"):
        check_head_height(0.0165, units="cm")
    with pytest.raises(RecordingError, match="check the axes"):
        check_head_height(0.05)
    with pytest.raises(RecordingError, match="the units, the axes or the floor are wrong"):
        check_head_height(12.0)
    check_head_height(1.7)
    # measured from a floor that is not at 0: an eye-level origin with the floor set at -1.6 m
    check_head_height(0.05, floor=-1.6)
    with pytest.raises(RecordingError, match=r"head is only 0\.05 m above the floor at -1\.60 m"):
        check_head_height(-1.55, floor=-1.6)
    with pytest.raises(RecordingError, match=r"set the Floor \(--floor\) to its height \(At Height\), "
                                             r"or to Under Performer \(--floor height\)"):
        check_head_height(0.05)


def test_non_increasing_times_in_a_stream_are_ignored_with_warning():
    rec = make_recording(duration=1.0)
    s = rec.streams["head"]
    t = s.time.copy()
    t[40] = t[38]                                                    # a stale timestamp
    rec.streams["head"] = TrackerStream("head", t, s.pos, s.quat)
    times, pos, quat, valid, report = resample(rec, 30)
    assert any("non-increasing" in w for w in report.warnings)
    assert np.all(np.isfinite(pos["head"]))


def test_end_to_end_csv_unity_with_defects(tmp_path):
    path, rec = write_recording_csv(tmp_path, axes="unity", duration=3.0, gap=("head", 2.0, 2.4),
                                    flip=("right_hand", 0.3, 0.6), invalid=("left_hand", 0.5, 0.7))
    loaded = load_recording(path)
    times, pos, quat, valid, report = resample(loaded, 60)
    assert {(g.device, g.reason) for g in report.gaps} == {("head", "missing"), ("left_hand", "invalid")}
    for d in loaded.devices:
        ok = valid[d]
        assert np.abs(pos[d][ok] - truth(d, times[ok])[0]).max() < 1e-4
        assert rot_err_deg(quat[d][ok], truth(d, times[ok])[1]).max() < 0.05


def test_resample_is_fast_for_ten_minutes():
    rates = {"head": 90.0, "left_hand": 90.0, "right_hand": 90.0}
    streams = make_streams(duration=600.0, rates=rates, jitter=0.1)
    assert len(streams["head"]) >= 54_000
    rec = Recording(streams)
    resample(rec, 60)                                                # warm-up
    t0 = time.perf_counter()
    times, pos, quat, valid, report = resample(rec, 60)
    elapsed = time.perf_counter() - t0
    assert len(times) >= 35_900
    assert elapsed < 1.0, f"resampling took {elapsed:.2f} s"


def test_controller_dropping_to_the_origin_and_jumps_are_bridged_and_reported():
    """Real devices losing tracking: a controller reports (0, 0, 0), or one sample jumps away
    when tracking returns.  Both are bridged like any gap and named in the report."""
    from blender_manikin.core.resample import resample as rs
    n, rate = 200, 90.0
    t = np.arange(n) / rate
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    head = np.stack([0.02 * np.sin(t), np.zeros(n), np.full(n, 1.6)], -1)
    left = np.stack([0.3 + 0.1 * np.sin(2 * t), -0.3 * np.ones(n), 1.2 + 0.05 * np.cos(t)], -1)
    right = left * np.array([-1.0, 1.0, 1.0])
    truth_left = left.copy()
    left[60:70] = 0.0                                  # lost: the runtime reports the origin
    right[120] += [0.0, 0.0, 1.5]                      # one sample jumps 1.5 m when tracking returns
    rec = Recording({"head": TrackerStream("head", t, head, q), "left_hand": TrackerStream("left_hand", t, left, q),
                     "right_hand": TrackerStream("right_hand", t, right, q)}, source="lost.csv")
    times, pos, quat, valid, report = rs(rec, 90.0)
    reasons = {(g.device, g.reason) for g in report.gaps}
    assert ("left_hand", "origin") in reasons and ("right_hand", "jump") in reasons
    assert np.abs(pos["left_hand"][60:70] - truth_left[60:70]).max() < 0.01       # bridged, not at 0
    assert not valid["left_hand"][62] and valid["left_hand"][40]
    assert abs(pos["right_hand"][120, 2] - 1.2 - 0.05 * np.cos(t[120])) < 0.01


@pytest.mark.parametrize("unit,factor", [("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9)])
def test_times_written_in_other_units_are_read_as_seconds(unit, factor):
    """A recorder that wrote milliseconds (or Unity's / Android's micro- and nanoseconds, from an
    epoch) would turn a 3 s take into hours: the steps tell, the times are scaled, a warning says."""
    from blender_manikin.core.resample import seconds_from_time_units
    rec = make_recording(duration=3.0)
    scaled = Recording({d: TrackerStream(d, (s.time + 1.7e9) * factor, s.pos, s.quat, s.valid)
                        for d, s in rec.streams.items()})
    back = seconds_from_time_units(scaled)
    assert back.warnings[-1].startswith(f"times read as {unit}: samples every ")
    for d, s in rec.streams.items():
        np.testing.assert_allclose(back.streams[d].time - 1.7e9, s.time, atol=1e-5 if factor < 1e9 else 1e-4)
    times = resample(back, 60)[0]
    assert times[-1] - times[0] == pytest.approx(3.0, abs=0.05)
    # seconds, and a slow recording in seconds (1 Hz), are left as they are
    assert seconds_from_time_units(rec) is rec
    slow = Recording({d: TrackerStream(d, np.arange(10.0), s.pos[:10], s.quat[:10]) for d, s in rec.streams.items()})
    assert seconds_from_time_units(slow) is slow


def test_the_summary_names_the_longest_gap():
    """A headset lost for 3 s: the summary says which device, how long and from when (seconds
    from the take's start), not only how many gaps were bridged."""
    from blender_manikin.core.solve import SolveSettings, solve_recording
    rec = load_recording(EXAMPLE)
    h = rec.streams["head"]
    keep = (h.time < 2.0) | (h.time > 5.0)
    streams = dict(rec.streams, head=TrackerStream("head", h.time[keep], h.pos[keep], h.quat[keep]))
    out = solve_recording(Recording(streams=streams, source="head lost", metadata=dict(rec.metadata)),
                          SolveSettings(fps=30.0))
    assert "1 gap(s) bridged, the longest head 3.0 s from 2.0 s (no samples)" in out.summary()


def test_a_take_mostly_without_samples_is_refused_by_name(tmp_path):
    """A last sample stamped 1e12 s (a logger's closing row with a broken clock) on every device:
    the grid would be 3e13 frames.  A clear error naming the file, the device, the samples and
    the jump, before anything is allocated; a real pause is still a gap."""
    rec = make_recording(duration=3.0)
    for d, s in list(rec.streams.items()):
        rec.streams[d] = TrackerStream(d, np.r_[s.time, 1e12], np.vstack([s.pos, s.pos[-1]]),
                                       np.vstack([s.quat, s.quat[-1]]))
    rec.source = str(tmp_path / "broken_clock.csv")
    with pytest.raises(RecordingError) as err:
        resample(rec, 30.0)
    msg = str(err.value)
    assert "broken_clock.csv" in msg and "1e+12 s" in msg and "between its samples" in msg
    assert "--start / --end" in msg
    # ten minutes without samples between two takes of a session: a gap, not an error
    rec = make_recording(duration=3.0)
    for d, s in list(rec.streams.items()):
        rec.streams[d] = TrackerStream(d, np.r_[s.time, s.time + 600.0], np.vstack([s.pos, s.pos]),
                                       np.vstack([s.quat, s.quat]))
    times = resample(rec, 30.0)[0]
    assert times[-1] > 600.0
