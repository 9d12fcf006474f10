"""A session's calibration take (SolveSettings.calibration_take, --calibration-take): the T-pose of
one recording calibrates another that has none (body, hand device rotations, the pelvis and foot
trackers' mounts)."""
import os

import numpy as np
import pytest

from blender_manikin.core import solve as cs
from blender_manikin.core.io_csv import write_csv
from blender_manikin.core.recording import Recording, TrackerStream

from fixtures_six_trackers import TPOSE_END, body_with_legs, random_mounts, six_tracker_recording

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def without_tpose(rec, cut=1.8):
    """``rec`` from ``cut`` seconds on: the T-pose (0-1.2 s) and the arms coming down left out."""
    streams = {}
    for d, s in rec.streams.items():
        k = s.time >= cut
        streams[d] = TrackerStream(d, s.time[k], s.pos[k], s.quat[k])
    return Recording(streams=streams, source="no T-pose", metadata=dict(rec.metadata))


def test_a_take_without_a_tpose_is_calibrated_on_the_sessions_calibration_take(tmp_path):
    body = body_with_legs(1.82, 1.05)                     # legs 5 % longer than proportional
    rec = six_tracker_recording(body, random_mounts(4), duration=8.0, seed=4)
    cal_path = str(tmp_path / "calibration.csv")
    write_csv(cal_path, rec, axes="openxr", units="m")
    take = without_tpose(rec)
    assert TPOSE_END < 1.8
    whole = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    alone = cs.solve_recording(take, cs.SolveSettings(fps=30.0))
    assert "tracker offsets not measured (no T-pose)" in alone.summary()
    with_cal = cs.solve_recording(take, cs.SolveSettings(fps=30.0, calibration_take=cal_path))
    s = with_cal.summary()
    assert "calibrated on a T-pose at 0.67 s of calibration.csv: stature 1.82 m" in s, s
    assert "pelvis tracker offset" in s and "(from the T-pose of calibration.csv)" in s
    assert "not measured" not in s
    assert with_cal.body.stature == pytest.approx(whole.body.stature, abs=1e-5)
    np.testing.assert_allclose(with_cal.body.offsets, whole.body.offsets, atol=1e-6)   # CSV decimals
    # the take's frames solved as the whole recording solves them (its network windows start later)
    T = with_cal.result.num_frames
    err = np.linalg.norm(with_cal.result.positions - whole.result.positions[-T:], axis=-1)
    err_alone = np.linalg.norm(alone.result.positions - whole.result.positions[-T:], axis=-1)
    assert np.median(err) < 0.01 and np.median(err_alone) > 3 * np.median(err), (np.median(err), np.median(err_alone))


def test_a_calibration_take_must_hold_a_pose(tmp_path):
    rec = six_tracker_recording(body_with_legs(1.7), random_mounts(1), duration=6.0, seed=1)
    no_pose = str(tmp_path / "no_pose.csv")
    write_csv(no_pose, without_tpose(rec), axes="openxr", units="m")
    with pytest.raises(cs.SolveError, match="calibration take no_pose.csv: no T- or A-pose found in it"):
        cs.solve_recording(rec, cs.SolveSettings(fps=30.0, calibration_take=no_pose))
    with pytest.raises(cs.SolveError, match="a calibration take needs Auto or T-pose calibration"):
        cs.solve_recording(rec, cs.SolveSettings(fps=30.0, calibration_take=no_pose, calibration="MEASURE",
                                                 height=1.7))
    with pytest.raises(cs.SolveError, match="nowhere.csv"):
        cs.solve_recording(rec, cs.SolveSettings(fps=30.0, calibration_take=str(tmp_path / "nowhere.csv")))


def test_trackers_the_calibration_take_lacks_are_said(tmp_path):
    """A calibration take made without the foot trackers: the take's foot trackers are not
    measured, and the summary says so."""
    rec = six_tracker_recording(body_with_legs(1.75), random_mounts(3), duration=6.0, seed=3)
    cal = Recording(streams={d: s for d, s in rec.streams.items() if d not in ("left_foot", "right_foot")},
                    source="no feet", metadata=dict(rec.metadata))
    path = str(tmp_path / "cal_no_feet.csv")
    write_csv(path, cal, axes="openxr", units="m")
    out = cs.solve_recording(without_tpose(rec), cs.SolveSettings(fps=30.0, calibration_take=path))
    assert "left foot, right foot tracker offsets not measured (not in the calibration take cal_no_feet.csv)" \
        in " ".join(out.info)


def test_a_batch_reads_its_calibration_take_once(tmp_path, monkeypatch):
    """The takes of a batch are calibrated on one read of the calibration take; each gets its own
    copy of the result; a changed file or other settings read it again."""
    rec = six_tracker_recording(body_with_legs(1.76), random_mounts(2), duration=6.0, seed=2)
    cal_path = tmp_path / "calibration.csv"
    write_csv(str(cal_path), rec, axes="openxr", units="m")
    reads = []
    real = cs.read_recording
    monkeypatch.setattr(cs, "read_recording", lambda path, s: reads.append(path) or real(path, s))
    settings = cs.SolveSettings(fps=30.0, calibration_take=str(cal_path))
    body, offsets, info = cs.calibration_from_take(settings, devices=("head", "left_hand", "right_hand"))
    body.offsets[:] = 0.0                                      # the caller's copy only
    body2, offsets2, info2 = cs.calibration_from_take(settings, devices=("head", "left_hand", "right_hand"))
    assert len(reads) == 1 and info2 == info and np.abs(body2.offsets).max() > 0.1
    # another take's trackers: the notes follow the take, not the first caller
    _, _, info3 = cs.calibration_from_take(cs.SolveSettings(fps=30.0, calibration_take=str(cal_path)),
                                           devices=("head", "left_hand", "right_hand", "left_foot"))
    assert len(reads) == 1 and info3 == info2      # the calibration take has foot trackers: measured
    cs.calibration_from_take(cs.SolveSettings(fps=30.0, calibration_take=str(cal_path), height=1.9))
    assert len(reads) == 2                                     # other settings: measured again
    os.utime(cal_path, ns=(1, 1))                              # the file changed
    cs.calibration_from_take(settings)
    assert len(reads) == 3


def _lowered(rec, dz):
    import copy
    out = copy.deepcopy(rec)
    for st in out.streams.values():
        st.pos[:, 2] += dz
    return out


def test_an_eye_level_take_stands_on_the_floor_of_its_calibration_takes_performer(tmp_path):
    """A session recorded with its origin at eye level (OpenXR LOCAL space: the floor 1.72 m down):
    the take without a T-pose is sized by the calibration take, and its floor goes under that
    performer, not under a 1.75 m default (a 1.90 m body hung from a floor 13 cm too high folds
    its knees), as a typed height puts it."""
    from examples.make_example_recording import synthesize
    rec = synthesize(stature=1.90)
    cal_path = str(tmp_path / "calibration.csv")
    write_csv(cal_path, _lowered(rec, -1.72), axes="openxr", units="m", metadata={"offsets": "openxr_generic"})
    take = _lowered(without_tpose(rec), -1.72)
    take.metadata["offsets"] = "openxr_generic"
    out = cs.solve_recording(take, cs.SolveSettings(fps=30.0, calibration_take=cal_path))
    typed = cs.solve_recording(take, cs.SolveSettings(fps=30.0, height=1.90))
    assert out.body.stature == pytest.approx(1.90, abs=0.005)
    assert out.floor == pytest.approx(-1.72, abs=0.01) and out.floor == pytest.approx(typed.floor, abs=0.005)
    assert "under the 1.90 m performer of the calibration take calibration.csv" in out.summary(), out.summary()
    from blender_manikin.core.metrics import knee_flexion
    assert np.median(np.linalg.norm(out.result.positions - typed.result.positions, axis=-1)) < 0.01
    assert np.median(knee_flexion(out.result.positions)) < np.median(knee_flexion(typed.result.positions)) + 5.0
