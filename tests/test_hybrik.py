import numpy as np
import pytest

from blender_manikin.core import hybrik
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from pose_sampling import random_pose

ENDS = [sk.J[n] for n in ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")]


def _pose(seed, T=200, stature=1.75):
    rng = np.random.default_rng(seed)
    body = sk.make_body(stature)
    loc = random_pose(rng, T, spread=0.3)
    pos, wr = sk.forward_kinematics(loc, rng.normal(size=(T, 3)), body)
    return rng, body, loc, pos, wr


@pytest.mark.parametrize("adaptive", [True, False])
def test_exact_positions_reproduce_pose(adaptive):
    rng, body, loc, pos, wr = _pose(0)
    res = hybrik.ik_from_positions(pos, body, end_rot={j: wr[:, j] for j in ENDS}, adaptive=adaptive)
    assert np.abs(res.positions - pos).max() < 1e-6
    assert rot.geodesic_angle(res.world_rot[:, ENDS], wr[:, ENDS]).max() < 1e-4
    # limbs come out biomechanical: knees are pure hinges about +X
    for li in (2, 3):
        m = sk.LIMBS[li][2]
        ang = rot.matrix_to_axis_angle(res.local_rot[:, m])
        assert np.allclose(ang[:, 1:], 0, atol=1e-7) and np.all(ang[:, 0] >= -1e-9)


def test_positions_only_default_twist():
    rng, body, loc, pos, wr = _pose(1)
    res = hybrik.ik_from_positions(pos, body)
    assert np.abs(res.positions - pos).max() < 1e-6
    assert np.allclose(res.local_rot[:, sk.J["left_wrist"]], np.eye(3))   # no wrist info: identity


def test_twist_angles_are_applied():
    rng, body, loc, pos, wr = _pose(2, T=20)
    tw = np.zeros((20, 22))
    tw[:, sk.J["neck"]] = 0.5
    a = hybrik.ik_from_positions(pos, body)
    b = hybrik.ik_from_positions(pos, body, twists=tw)
    neck_axis = body.offsets[sk.J["head"]]
    rel = np.swapaxes(a.local_rot[:, sk.J["neck"]], -1, -2) @ b.local_rot[:, sk.J["neck"]]
    assert np.allclose(rot.twist_angle(rel, neck_axis), 0.5)
    assert np.abs(b.positions - pos).max() < 1e-6


def test_adaptive_beats_naive_under_noise():
    errs = {}
    for adaptive in (False, True):
        e = []
        for seed in range(3):
            rng, body, loc, pos, wr = _pose(10 + seed, T=300)
            noisy = pos + rng.uniform(-0.02, 0.02, pos.shape)
            res = hybrik.ik_from_positions(noisy, body, end_rot={j: wr[:, j] for j in ENDS}, adaptive=adaptive)
            e.append(np.linalg.norm(res.positions - noisy, axis=-1).mean())
        errs[adaptive] = np.mean(e)
    assert errs[True] < 0.8 * errs[False], errs


def test_bad_input_raises():
    body = sk.make_body(1.7)
    with pytest.raises(ValueError, match=r"\(T, 22, 3\)"):
        hybrik.ik_from_positions(np.zeros((5, 21, 3)), body)
    p = np.tile(body.rest_positions(), (3, 1, 1))
    p[1, 5, 2] = np.nan
    with pytest.raises(ValueError, match="frames \\[1\\]"):
        hybrik.ik_from_positions(p, body)


def test_rest_pose_gives_identity():
    body = sk.make_body(1.7)
    res = hybrik.ik_from_positions(np.tile(body.rest_positions(), (2, 1, 1)), body)
    assert np.allclose(res.local_rot, np.eye(3), atol=1e-7)


@pytest.mark.parametrize("adaptive", [True, False])
@pytest.mark.parametrize("seed", [1, 2, 5])
def test_aimed_chain_reproduces_exact_positions_and_keeps_axial_limits(adaptive, seed):
    """Keypoint IK (aim_chain, within_limits): exact positions still give the pose back, noisy
    ones never turn a shoulder or hip about its own axis past its range (seeds 2 and 5 have
    frames where the secant steps alone missed the limit by up to 70°)."""
    from blender_manikin.core import limb_solver as ls
    rng, body, loc, pos, wr = _pose(seed)
    ends = {j: wr[:, j] for j in ENDS}
    res = hybrik.ik_from_positions(pos, body, end_rot=ends, adaptive=adaptive, aim_chain=True)
    assert np.abs(res.positions - pos).max() < 1e-6
    noisy = pos + rng.normal(size=pos.shape) * 0.03
    res = hybrik.ik_from_positions(noisy, body, end_rot=ends, adaptive=adaptive, aim_chain=True,
                                   within_limits=True)
    base = [b for _, b, _, _ in sk.LIMBS]
    psi, elev = ls.axial_rotation(res.local_rot[:, base], list(range(4)))
    lo, hi = ls.axial_range(elev, list(range(4)))
    assert np.all((psi >= lo - 1e-3) & (psi <= hi + 1e-3))        # the secant steps stop within 0.06°
    # the elbows / knees sit on their positions' directions from the (reconstructed) base
    for _, b, m, e in sk.LIMBS:
        d_fit = rot.normalize(res.positions[:, m] - res.positions[:, b])
        d_in = rot.normalize(noisy[:, m] - (res.positions[:, b] if adaptive else noisy[:, b]))
        ok = np.sum(d_fit * d_in, -1) > np.cos(np.radians(0.01))
        assert ok.mean() > 0.5            # the rest moved their swivel to a limit
