"""Tracker smoothing (core/smoothing.py): clean tracks are left exactly as they are, noisy ones
come closer to the motion they measure, and the solve applies it and says so."""
import numpy as np
import pytest

from blender_manikin.core import rotations as rot
from blender_manikin.core import smoothing as sm
from blender_manikin.core.pose_result import TrackerTargets

FPS = 30.0


def _walk(T=300, fps=FPS):
    """Head and hands of a slow sway (positions metres, Z-up; wxyz quaternions turning about Z
    and X), as the resampler returns them."""
    t = np.arange(T) / fps
    pos, quat = {}, {}
    for k, d in enumerate(("head", "left_hand", "right_hand")):
        pos[d] = np.stack([0.25 * np.sin(1.3 * t + k), 0.4 * t, 1.0 + 0.1 * np.sin(2.1 * t + k)], -1)
        aa = np.stack([0.3 * np.sin(1.7 * t + k), 0 * t, 0.6 * np.sin(0.9 * t)], -1)
        quat[d] = rot.quat_continuous(rot.axis_angle_to_quat(aa))
    return pos, quat


def _noisy(pos, quat, pos_sigma, rot_sigma_deg, seed=0):
    rng = np.random.default_rng(seed)
    npos = {d: p + rng.normal(0.0, pos_sigma, p.shape) for d, p in pos.items()}
    nquat = {d: rot.quat_continuous(rot.quat_mul(rot.axis_angle_to_quat(
        rng.normal(0.0, np.deg2rad(rot_sigma_deg), (len(q), 3))), q)) for d, q in quat.items()}
    return npos, nquat


def _angle_deg(qa, qb):
    return np.degrees(rot.geodesic_angle(rot.quat_to_matrix(qa), rot.quat_to_matrix(qb)))


def test_auto_leaves_clean_tracks_exactly_as_they_are():
    pos, quat = _walk()
    # quantised as a file written with 4 decimals: still clean
    pos = {d: np.round(p, 4) for d, p in pos.items()}
    out_pos, out_quat, windows = sm.smooth_device_poses(pos, quat, FPS, "auto")
    assert windows == {"head": 0.0, "left_hand": 0.0, "right_hand": 0.0}
    for d in pos:
        assert np.array_equal(out_pos[d], pos[d]) and np.array_equal(out_quat[d], quat[d])
    # off: the same arrays' values, new dicts
    off_pos, off_quat, w = sm.smooth_device_poses(pos, quat, FPS, 0)
    assert w is None and off_pos is not pos and all(np.array_equal(off_pos[d], pos[d]) for d in pos)


def test_auto_brings_noisy_trackers_closer_to_their_motion():
    pos, quat = _walk()
    npos, nquat = _noisy(pos, quat, 0.003, 0.8)
    out_pos, out_quat, windows = sm.smooth_device_poses(npos, nquat, FPS, "auto")
    assert all(w > 0 for w in windows.values())
    for d in pos:
        before = np.linalg.norm(npos[d] - pos[d], axis=-1).mean()
        after = np.linalg.norm(out_pos[d] - pos[d], axis=-1).mean()
        assert after < 0.5 * before
        a0, a1 = _angle_deg(nquat[d], quat[d]).mean(), _angle_deg(out_quat[d], quat[d]).mean()
        assert a1 < 0.6 * a0
        # unit, sign-continuous, and the input's sign convention
        assert np.allclose(np.linalg.norm(out_quat[d], axis=-1), 1.0)
        assert (np.sum(out_quat[d][1:] * out_quat[d][:-1], -1) > 0).all()
        assert np.sum(out_quat[d][0] * nquat[d][0]) > 0
    # one fixed window smooths too, and the targets' version agrees with the devices' one
    fixed_pos, fixed_quat, w = sm.smooth_device_poses(npos, nquat, FPS, 0.4)
    assert w is None and np.linalg.norm(fixed_pos["head"] - pos["head"], axis=-1).mean() < 0.003
    tg = TrackerTargets(fps=FPS, pos=npos, rot={d: rot.quat_to_matrix(q) for d, q in nquat.items()})
    st, tw = sm.smooth_targets(tg, "auto")
    assert tw == windows
    for d in pos:
        assert np.allclose(st.pos[d], out_pos[d])
        assert np.allclose(st.rot[d], rot.quat_to_matrix(out_quat[d]), atol=1e-9)


def test_bad_smoothing_setting_is_an_error():
    from blender_manikin.core.solve import SolveError
    pos, quat = _walk(T=40)
    for bad in ("soft", -0.1, float("nan")):
        with pytest.raises(SolveError, match="expected 'auto' or a window in seconds"):
            sm.smooth_device_poses(pos, quat, FPS, bad)


def test_solve_smooths_a_noisy_recording_and_says_so(tmp_path):
    """The solve of a tracker recording smooths it by default and its summary says how; with
    smoothing 0 the hand targets are the raw samples."""
    from fixtures_recordings import make_recording, truth
    from blender_manikin.core.io_csv import write_csv
    from blender_manikin.core.solve import SolveSettings, solve_recording
    rec = make_recording(duration=6.0)
    rng = np.random.default_rng(5)
    for s in rec.streams.values():
        s.pos += rng.normal(0.0, 0.003, s.pos.shape)
    path = str(tmp_path / "noisy.csv")
    write_csv(path, rec, axes="openxr", units="m")
    settings = dict(fps=30.0, calibration="MEASURE", height=1.75)
    auto = solve_recording(path, SolveSettings(**settings))
    off = solve_recording(path, SolveSettings(**settings, smoothing=0))
    assert "smoothing auto (per device, from its measured noise): windows" in auto.summary()
    assert "no smoothing" in off.summary()
    times = auto.result.t0 + np.arange(auto.result.num_frames) / 30.0
    for d in ("left_hand", "right_hand"):
        clean = truth(d, times)[0]
        raw = np.linalg.norm(off.targets.pos[d] - clean, axis=-1).mean()
        smoothed = np.linalg.norm(auto.targets.pos[d] - clean, axis=-1).mean()
        assert smoothed < 0.6 * raw


def test_smooth_gives_the_same_on_any_memory_layout():
    """A track picked out of a larger array (not C-contiguous) is filtered, ends included, as its
    contiguous copy is."""
    rng = np.random.default_rng(1)
    x = rng.normal(size=(120, 6, 3))
    view = x[:, [1, 4]]
    assert not view.flags["C_CONTIGUOUS"]
    np.testing.assert_allclose(sm.smooth(view, FPS, 0.4), sm.smooth(np.ascontiguousarray(view), FPS, 0.4),
                               atol=1e-12)
    np.testing.assert_allclose(sm.smooth(x[::2], FPS, 0.4), sm.smooth(x[::2].copy(), FPS, 0.4), atol=1e-12)


def test_the_summary_says_when_no_device_needed_smoothing():
    from blender_manikin.core.smoothing import smoothing_note
    assert smoothing_note("auto", [0.0, 0.0, 0.0], "device") == \
        "smoothing auto (per device, from its measured noise): none needed, every device is clean"
    assert smoothing_note("auto", [0.0, 0.4, 0.2], "device") == \
        "smoothing auto (per device, from its measured noise): windows 0-0.4 s, median 0.2 s"
    assert smoothing_note(0.3) == "smoothing 0.3 s" and smoothing_note(0) == "no smoothing"
