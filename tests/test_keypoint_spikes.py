"""Spikes in markerless keypoints (core/keypoint_spikes.py): misplaced samples removed and
bridged, fast real motion and the take's ends left alone."""
import numpy as np
import pytest

from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import keypoint_spikes as ksp
from blender_manikin.core.io_keypoints import KeypointRecording
from blender_manikin.core.solve import SolveSettings, solve_recording
from fixtures_keypoints import hinge_motion, noisy


def _keypoints(layout="coco17", frames=240, sigma=0.01, seed=0):
    body, pos, world = hinge_motion(frames=frames, seed=seed)
    lay = kl.LAYOUTS[layout]
    return lay, noisy(kl.keypoints_from_body22(pos, world, lay, body.stature), sigma, seed=seed)


def test_local_median_is_centred_and_shrinks_at_the_ends():
    x = np.arange(10.0)[:, None, None] * np.array([1.0, 0.0, 0.0])      # a point moving 1 m a frame
    med = ksp.local_median(x)
    assert np.isnan(med[0]).all() and np.isnan(med[-1]).all()           # no frame on one side
    np.testing.assert_allclose(med[1:-1], x[1:-1])                      # steady motion: itself
    x[5, 0, 0] = np.nan                                                 # a gap: the rest still seen
    assert np.isfinite(ksp.local_median(x)[4]).all()


def test_spikes_are_removed_and_motion_kept():
    lay, X = _keypoints()
    clean, none = ksp.remove_spikes(X, 30.0)
    assert not none.any() and np.array_equal(clean, X)
    bad = X.copy()
    wrist, ankle = lay.index("left_wrist"), lay.index("right_ankle")
    bad[50, wrist] += [0.0, 0.6, 0.0]                                   # one frame off
    bad[120:123, ankle] += [0.4, 0.0, 0.2]                              # three frames off
    bad[0, wrist] += [1.0, 0.0, 0.0]                                    # the first frame: left alone
    out, spikes = ksp.remove_spikes(bad, 30.0)
    want = np.zeros(spikes.shape, bool)
    want[50, wrist] = want[120:123, ankle] = True
    assert np.array_equal(spikes, want)
    assert np.isnan(out[spikes]).all() and np.array_equal(out[~spikes], bad[~spikes])
    # a point that really moves fast is no spike: a foot kicked 0.6 m out and back in 0.3 s (18 cm a
    # frame; its peak 24 cm off the local median)
    kick = X.copy()
    t = np.arange(len(X))
    kick[:, ankle, 0] += 0.6 * np.exp(-0.5 * ((t - 100) / 2.0) ** 2)
    assert not ksp.remove_spikes(kick, 30.0)[1].any()


def test_the_threshold_grows_below_30_fps():
    assert ksp.spike_threshold(30.0) == ksp.spike_threshold(120.0) == ksp.SPIKE_MIN
    assert ksp.spike_threshold(15.0) == pytest.approx(4 * ksp.SPIKE_MIN)


def test_the_solve_removes_spikes_unless_told_not_to():
    lay, X = _keypoints()
    rng = np.random.default_rng(3)
    bad = X.copy()
    hit = rng.random(X.shape[:2]) < 0.01
    hit[[0, -1]] = False
    bad[hit] += 0.5 * np.array([0.0, 0.6, 0.8])
    rec = KeypointRecording(time=np.arange(len(X)) / 30.0, points=bad, layout="coco17", source="spiky.npy")
    ref = solve_recording(KeypointRecording(time=rec.time, points=X, layout="coco17", source="clean.npy"),
                          SolveSettings(fps=30.0))
    out = solve_recording(rec, SolveSettings(fps=30.0))
    assert f"spikes removed: {int(hit.sum())} sample(s)" in out.summary()
    kept = solve_recording(rec, SolveSettings(fps=30.0, despike=False))
    assert not any(n.startswith("spikes removed") for n in kept.info)
    err = [np.linalg.norm(r.result.positions - ref.result.positions, axis=-1).mean() for r in (out, kept)]
    assert err[0] < 0.01 < err[1]
    from blender_manikin import cli
    p = cli.build_parser()
    assert cli.solve_settings(p.parse_args(["solve", "k.npy", "--out", "o"])).despike is True
    assert cli.solve_settings(p.parse_args(["solve", "k.npy", "--out", "o", "--keep-spikes"])).despike is False
