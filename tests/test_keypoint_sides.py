"""Left/right label swaps in markerless keypoints (core/keypoint_sides.py): found and undone,
and never invented on keypoints whose labels are right."""
import numpy as np
import pytest

from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core import keypoint_sides as ks
from blender_manikin.core.io_keypoints import KeypointRecording
from blender_manikin.core.solve import SolveSettings, solve_recording
from fixtures_keypoints import hinge_motion, noisy


def _keypoints(layout, frames=240, seed=0, sigma=0.01):
    body, pos, world = hinge_motion(frames=frames, seed=seed)
    lay = kl.LAYOUTS[layout]
    return lay, noisy(kl.keypoints_from_body22(pos, world, lay, body.stature), sigma, seed=seed)


def _swap(points, lay, part, frames):
    """``points`` with ``part``'s left and right labels exchanged on ``frames`` (bool mask)."""
    li, ri = ks.limb_pairs(lay.points, part)
    out = points.copy()
    sub = out[frames]
    sub[:, li], sub[:, ri] = sub[:, ri].copy(), sub[:, li].copy()
    out[frames] = sub
    return out


@pytest.mark.parametrize("layout", ["coco17", "mediapipe33", "body25", "h36m17", "smpl24"])
def test_swapped_episodes_are_undone_and_clean_labels_kept(layout):
    lay, X = _keypoints(layout)
    same, none = ks.fix_side_swaps(X, lay.points)
    assert none.count() == 0 and np.array_equal(same, X, equal_nan=True) and none.note(30.0) is None
    legs, arms = np.zeros(len(X), bool), np.zeros(len(X), bool)
    legs[[*range(40, 46), *range(150, 163)]] = True                 # 0.2 s and 0.4 s at 30 fps
    arms[100:104] = True
    bad = _swap(_swap(X, lay, "legs", legs), lay, "arms", arms)
    fixed, found = ks.fix_side_swaps(bad, lay.points)
    assert np.array_equal(found.frames["legs"], legs) and np.array_equal(found.frames["arms"], arms)
    np.testing.assert_array_equal(fixed, X)
    assert found.count() == 23 and found.count(("legs",)) == 19
    assert found.note(30.0) == "left/right labels swapped back: legs on 19 frame(s) (0.6 s), arms on 4 frame(s) (0.1 s)"
    assert np.array_equal(bad, _swap(_swap(X, lay, "legs", legs), lay, "arms", arms))      # input unchanged


def test_a_take_that_starts_swapped_and_missing_points_are_handled():
    """The anatomy decides which labelling is right: a take whose first second is swapped is
    fixed there, not after; frames with a chain's points missing keep the labels around them."""
    lay, X = _keypoints("coco17", frames=180)
    first = np.zeros(len(X), bool)
    first[:30] = True
    bad = _swap(X, lay, "legs", first)
    li, ri = ks.limb_pairs(lay.points, "legs")
    bad[60:64, li] = np.nan                                          # the left leg not seen for 4 frames
    fixed, found = ks.fix_side_swaps(bad, lay.points)
    assert np.array_equal(found.frames["legs"], first)
    ok = np.isfinite(bad).all(-1)
    np.testing.assert_array_equal(fixed[ok], X[ok])


def test_legs_that_really_cross_are_not_swapped():
    """A cross step: the left foot passes in front of the right one to the other side and
    back, moving continuously: nothing is swapped, though the left foot is on the right."""
    lay, X = _keypoints("mediapipe33", frames=120, sigma=0.0)
    li, ri = ks.limb_pairs(lay.points, "legs")
    hips = X[:, [lay.index("left_hip"), lay.index("right_hip")]]
    across = hips[:, 1] - hips[:, 0]                                 # left hip -> right hip
    across[:, 2] = 0.0
    w = np.sin(np.linspace(0.0, np.pi, len(X))) ** 2                 # out and back over 4 s
    moved = X.copy()
    moved[:, li] += (1.6 * w)[:, None, None] * across[:, None, :]
    assert (np.einsum("tki,ti->t", moved[:, li] - moved[:, ri], across) > 0.05).any()   # really crossed
    same, found = ks.fix_side_swaps(moved, lay.points)
    assert found.count() == 0 and np.array_equal(same, moved)


def test_the_solve_undoes_swaps_unless_told_not_to():
    lay, X = _keypoints("coco17")
    legs = np.zeros(len(X), bool)
    legs[90:100] = True
    rec = KeypointRecording(time=np.arange(len(X)) / 30.0, points=_swap(X, lay, "legs", legs),
                            layout="coco17", source="swapped.npy")
    out = solve_recording(rec, SolveSettings(fps=30.0))
    assert "left/right labels swapped back: legs on 10 frame(s) (0.3 s)" in out.summary()
    ref = solve_recording(KeypointRecording(time=rec.time, points=X, layout="coco17", source="clean.npy"),
                          SolveSettings(fps=30.0))
    knees = [4, 5]                                                   # left_knee, right_knee
    assert np.abs(out.result.positions[:, knees] - ref.result.positions[:, knees]).max() < 1e-6
    kept = solve_recording(rec, SolveSettings(fps=30.0, fix_sides=False))
    assert not any(n.startswith("left/right") for n in kept.info)
    assert np.abs(kept.result.positions[90:100, knees] - ref.result.positions[90:100, knees]).max() > 0.05
    from blender_manikin import cli
    p = cli.build_parser()
    assert cli.solve_settings(p.parse_args(["solve", "k.npy", "--out", "o"])).fix_sides is True
    assert cli.solve_settings(p.parse_args(["solve", "k.npy", "--out", "o", "--keep-sides"])).fix_sides is False
