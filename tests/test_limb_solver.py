"""Acceptance tests for the analytic limb solver (issue: foundation, section 3)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from blender_manikin.core import limb_solver as ls
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from pose_sampling import random_pose

B, M, E, P = ls.LIMB_BASE, ls.LIMB_MID, ls.LIMB_END, ls.LIMB_PARENT


def _solve_from_fk(loc, body, root=None):
    T = loc.shape[0]
    root = np.zeros((T, 3)) if root is None else root
    pos, wr = sk.forward_kinematics(loc, root, body)
    phi = ls.swivel_from_positions(pos[:, B], pos[:, M], pos[:, E], wr[:, P], base_rot=wr[:, B])
    sol = ls.solve_limbs(pos[:, B], pos[:, E], phi, body.limb_lengths(), wr[:, P], end_rot=wr[:, E])
    loc2 = loc.copy()
    loc2[:, B], loc2[:, M], loc2[:, E] = sol.base_local, sol.mid_local, sol.end_local
    pos2, wr2 = sk.forward_kinematics(loc2, root, body)
    return pos, wr, phi, sol, pos2, wr2


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), stature=st.floats(1.4, 2.1), spread=st.floats(0.05, 0.6))
def test_round_trip_positions_swivel_solve_fk(seed, stature, spread):
    rng = np.random.default_rng(seed)
    body = sk.make_body(sk.BodyMeasurements(stature=stature, upper_arm=stature * rng.uniform(0.16, 0.2)))
    loc = random_pose(rng, 64, spread=spread)
    pos, wr, phi, sol, pos2, wr2 = _solve_from_fk(loc, body, rng.normal(size=(64, 3)))
    assert np.abs(pos2[:, E] - pos[:, E]).max() < 1e-6          # wrists / ankles
    assert rot.geodesic_angle(wr2[:, E], wr[:, E]).max() < 1e-4
    assert np.abs(pos2[:, M] - pos[:, M]).max() < 1e-6          # elbows / knees
    assert np.abs(sol.reach_error).max() < 1e-9
    # the mid joint is a pure hinge (plus axial twist for elbows) within limits
    hinge_part = sol.mid_local @ np.swapaxes(rot.axis_angle_rotation(ls.A0, sol.elbow_twist), -1, -2)
    assert np.allclose(hinge_part, rot.axis_angle_rotation(ls.H0, sol.flexion), atol=1e-9)
    assert np.all((sol.flexion >= 0) & (sol.flexion <= ls.FLEX_MAX))
    assert np.all(sol.elbow_twist >= ls.TWIST_RANGE[:, 0] - 1e-12)
    assert np.all(sol.elbow_twist <= ls.TWIST_RANGE[:, 1] + 1e-12)
    assert np.all(sol.elbow_twist[:, 2:] == 0)               # knees: no twist at all
    # swivel round-trips: positions from the solved pose give the same angle back
    phi2 = ls.swivel_from_positions(pos2[:, B], pos2[:, M], pos2[:, E], wr2[:, P])
    assert np.abs(np.angle(np.exp(1j * (phi2 - phi)))).max() < 1e-6
    mid = ls.mid_from_swivel(pos[:, B], pos[:, E], phi, body.limb_lengths(), wr[:, P])
    assert np.abs(mid - pos[:, M]).max() < 1e-6


def test_zero_swivel_is_natural_pose():
    """phi = 0: elbows out-back-down, knees forward (body faces -Y, left is +X)."""
    body = sk.make_body(1.75)
    rest = body.rest_positions()
    T = 1
    R = np.broadcast_to(np.eye(3), (T, 4, 3, 3))
    # wrists hanging in front of the hips, ankles under the hips
    base = rest[B][None]
    end = base + np.array([[0.1, -0.25, -0.35], [-0.1, -0.25, -0.35], [0, -0.05, -0.7], [0, -0.05, -0.7]])[None]
    sol = ls.solve_limbs(base, end, np.zeros((T, 4)), body.limb_lengths(), R)
    n = rot.normalize(end - base)
    off = sol.mid_pos - base
    off = off - np.sum(off * n, -1, keepdims=True) * n        # elbow/knee offset from the axis
    left_elbow, right_elbow, left_knee, right_knee = off[0]
    assert left_elbow[0] > 0 and right_elbow[0] < 0             # out
    assert left_elbow[1] > 0 and right_elbow[1] > 0             # back
    assert left_knee[1] < 0 and right_knee[1] < 0               # knees forward
    assert abs(left_knee[0]) < 1e-9


def test_swivel_is_continuous_through_ordinary_motion():
    """Arms sweep hanging -> forward -> overhead -> side; the zero-swivel frame is smooth."""
    body = sk.make_body(1.75)
    T = 400
    s = np.linspace(0, 1, T)
    ang = np.pi * s
    dirs = np.stack([0.3 * np.sin(ang) + 0.1, -np.sin(ang) * 0.8, -np.cos(ang)], -1)
    base = np.broadcast_to(body.rest_positions()[B[0]], (T, 3))
    end = base + 0.5 * rot.normalize(dirs)
    n, u, v, d = ls.swivel_frame(base[:, None], end[:, None], np.broadcast_to(np.eye(3), (T, 1, 3, 3)), [0])
    assert np.linalg.norm(np.diff(u[:, 0], axis=0), axis=-1).max() < 0.05


def test_out_of_reach_extends_limb_towards_target_and_reports():
    body = sk.make_body(1.75)
    L = body.limb_lengths()
    base = np.zeros((3, 4, 3))
    direction = rot.normalize(np.array([1.0, -0.2, 0.1]))
    far = np.array([1.5, 0.2, 0.5])  # times the full length
    end = base + (far[:, None, None] * L.sum(1)[None, :, None]) * direction
    sol = ls.solve_limbs(base, end, np.zeros((3, 4)), L, np.broadcast_to(np.eye(3), (3, 4, 3, 3)))
    assert np.all(np.isfinite(sol.base_local)) and np.all(np.isfinite(sol.mid_pos))
    assert np.allclose(sol.reach_error[0], 0.5 * L.sum(1))            # too far by half a limb
    assert np.allclose(sol.flexion[0], 0.0, atol=1e-7)               # fully extended ...
    assert np.allclose(rot.normalize(sol.end_pos[0] - base[0]), direction)   # ... towards the target
    assert np.allclose(sol.flexion[1], ls.FLEX_MAX)                   # too close: most-flexed hinge
    assert np.all(sol.reach_error[1] > 0)
    assert np.allclose(sol.reach_error[2], 0.0)


def test_degenerate_inputs_stay_finite():
    body = sk.make_body(1.75)
    L = body.limb_lengths()
    T = 4
    base = np.zeros((T, 4, 3))
    end = np.zeros((T, 4, 3))                    # zero-length: target on the base
    end[1] = [[L[i].sum(), 0, 0] for i in range(4)]          # exactly straight
    end[2] = [[L[i].sum() - 1e-12, 0, 0] for i in range(4)]  # numerically straight
    end[3] = [[1e-13, 0, 0]] * 4
    R = np.broadcast_to(np.eye(3), (T, 4, 3, 3))
    sol = ls.solve_limbs(base, end, np.full((T, 4), 0.3), L, R, end_rot=R)
    for arr in (sol.base_local, sol.mid_local, sol.end_local, sol.mid_pos, sol.flexion):
        assert np.all(np.isfinite(arr))
    # a straight limb still has a well-defined hinge plane from the swivel
    phi = ls.swivel_from_positions(base[1:2], base[1:2] + end[1:2] * 0.5, end[1:2], R[1:2],
                                   base_rot=sol.base_world[1:2])
    assert np.allclose(phi, 0.3, atol=1e-6)


def test_nan_input_gives_clear_error():
    body = sk.make_body(1.75)
    end = np.zeros((2, 4, 3))
    end[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        ls.solve_limbs(np.zeros((2, 4, 3)), end, np.zeros((2, 4)), body.limb_lengths(),
                       np.broadcast_to(np.eye(3), (2, 4, 3, 3)))


def test_pronation_beyond_range_is_clamped_and_hand_stays_exact():
    body = sk.make_body(1.75)
    rng = np.random.default_rng(5)
    loc = random_pose(rng, 50)
    for li in (0, 1):
        _, b, m, e = sk.LIMBS[li]
        loc[:, m] = rot.axis_angle_rotation(ls.H0[li], np.full(50, 1.0)) @ \
            rot.axis_angle_rotation(ls.A0[li], np.full(50, 2.5))        # 143 deg of forearm twist
    pos, wr, phi, sol, pos2, wr2 = _solve_from_fk(loc, body)
    assert np.allclose(np.abs(sol.elbow_twist[:, :2]), np.radians(80))
    assert rot.geodesic_angle(wr2[:, E], wr[:, E]).max() < 1e-6
    assert ls.limit_report(sol)["pronation"][:, :2].all()


def test_vectorised_over_limb_subsets():
    body = sk.make_body(1.75)
    rng = np.random.default_rng(6)
    loc = random_pose(rng, 10)
    pos, wr = sk.forward_kinematics(loc, np.zeros((10, 3)), body)
    ids = [3, 0]
    phi = ls.swivel_from_positions(pos[:, B[ids]], pos[:, M[ids]], pos[:, E[ids]], wr[:, P[ids]], limb_ids=ids)
    sol = ls.solve_limbs(pos[:, B[ids]], pos[:, E[ids]], phi, body.limb_lengths()[ids], wr[:, P[ids]], limb_ids=ids)
    assert np.abs(sol.mid_pos - pos[:, M[ids]]).max() < 1e-9


def test_hip_axial_rotation_is_kept_within_range():
    """A knee swivel pointing the knee backwards is moved to the hip's limit; the foot stays put."""
    body = sk.make_body(1.75)
    rest = body.rest_positions()
    T = 60
    base = np.broadcast_to(rest[B], (T, 4, 3)).copy()
    end = base + np.array([[0.1, -0.25, -0.35], [-0.1, -0.25, -0.35], [0.0, -0.1, -0.75], [0.0, -0.1, -0.75]])
    R = np.broadcast_to(np.eye(3), (T, 4, 3, 3))
    phi = np.tile(np.linspace(-np.pi, np.pi, T)[:, None], (1, 4))
    sol, used = ls.solve_limbs_within_limits(base, end, phi, body.limb_lengths(), R, end_rot=R)
    bt, elev = ls.axial_rotation(sol.base_local)
    lo, hi = ls.axial_range(elev)
    assert np.all(bt >= lo - 1e-4) and np.all(bt <= hi + 1e-4)
    inside = (np.abs(phi[:, 2]) < 0.3)
    assert np.allclose(used[inside, 2], phi[inside, 2])              # natural knees untouched
    assert not np.allclose(used[:, 2], phi[:, 2])                    # backwards knees moved
    assert np.abs(sol.end_pos - end).max() < 1e-9 and sol.reach_error.max() < 1e-9
    knee_dir = sol.mid_pos[:, 2] - (base[:, 2] + end[:, 2]) / 2
    assert np.all(knee_dir[:, 1] < 0.02)                             # knees never point backwards


def _arm_pose(limb, bone_dir, forearm_dir, l1=0.3, l2=0.25):
    """Solve one limb (identity parent) with the elbow/knee bent 90° between the two directions."""
    base = np.zeros((1, 1, 3))
    mid = base + l1 * rot.normalize(np.asarray(bone_dir, float))
    end = mid + l2 * rot.normalize(np.asarray(forearm_dir, float))
    R = np.eye(3)[None, None]
    phi = ls.swivel_from_positions(base, mid, end, R, limb_ids=[limb])
    sol = ls.solve_limbs(base, end, phi, np.array([[l1, l2]]), R, limb_ids=[limb])
    assert np.abs(sol.mid_pos - mid).max() < 1e-9
    return ls.axial_rotation(sol.base_local, [limb])


@pytest.mark.parametrize("limb,medial", [(0, -1.0), (1, 1.0)])
def test_shoulder_axial_rotation_is_the_clinical_angle(limb, medial):
    """Arm at the side or abducted 90°, elbow at 90°: forearm forward is 0, towards the
    body (or down when abducted) is internal rotation, outwards (or up) external."""
    down, fwd, lat, up = (0, 0, -1), (0, -1, 0), (-medial, 0, 0), (0, 0, 1)
    cases = [(down, fwd, 0.0, 0.0), (down, (medial, 0, 0), 90.0, 0.0), (down, lat, -90.0, 0.0),
             (lat, fwd, 0.0, 90.0), (lat, down, 90.0, 90.0), (lat, up, -90.0, 90.0)]
    for bone, fore, want, want_elev in cases:
        psi, elev = _arm_pose(limb, bone, fore)
        assert np.degrees(psi[0, 0]) == pytest.approx(want, abs=1e-6), (bone, fore)
        assert np.degrees(elev[0, 0]) == pytest.approx(want_elev, abs=1e-6)


@pytest.mark.parametrize("limb,medial", [(2, -1.0), (3, 1.0)])
def test_hip_axial_rotation_is_the_clinical_angle(limb, medial):
    """Thigh down, knee at 90°: shin straight back is 0; internal hip rotation swings the
    shin outwards (the knee cap turns in)."""
    psi, _ = _arm_pose(limb, (0, 0, -1), (0, 1, 0))
    assert abs(psi[0, 0]) < 1e-9
    psi, _ = _arm_pose(limb, (0, 0, -1), (-medial, 1, 0))
    assert np.degrees(psi[0, 0]) == pytest.approx(45.0, abs=1e-6)


def test_shoulder_axial_rotation_is_kept_within_range():
    """Hand in front of the belly, the elbow swept round its whole circle: elbows that would
    need the humerus turned past the clinical range are moved to the limit, the hand never moves."""
    body = sk.make_body(1.75)
    rest = body.rest_positions()
    T = 91
    base = np.broadcast_to(rest[B], (T, 4, 3)).copy()
    L = body.limb_lengths()
    end = base.copy()
    end[:, 0] += [-0.12, -0.28, -0.30]           # left hand in front of the belly, elbow bent
    end[:, 1] += [0.12, -0.28, -0.30]
    end[:, 2:] += [0.0, -0.1, -0.75]
    R = np.broadcast_to(np.eye(3), (T, 4, 3, 3))
    phi = np.tile(np.linspace(-np.pi, np.pi, T)[:, None], (1, 4))
    raw = ls.solve_limbs(base, end, phi, L, R, end_rot=R)
    psi_raw, elev_raw = ls.axial_rotation(raw.base_local)
    lo_raw, hi_raw = ls.axial_range(elev_raw)
    outside = (psi_raw < lo_raw) | (psi_raw > hi_raw)
    assert outside[:, :2].any(0).all()                                # the sweep does leave the range
    sol, used = ls.solve_limbs_within_limits(base, end, phi, L, R, end_rot=R)
    psi, elev = ls.axial_rotation(sol.base_local)
    lo, hi = ls.axial_range(elev)
    assert np.all(psi >= lo - 1e-4) and np.all(psi <= hi + 1e-4)
    assert np.allclose(used[~outside], phi[~outside])                 # plausible elbows untouched
    assert not np.allclose(used[:, :2], phi[:, :2])
    assert np.abs(sol.end_pos - end).max() < 1e-9 and sol.reach_error.max() < 1e-9
    assert not ls.limit_report(sol)["base_twist"].any()
    assert ls.limit_report(raw)["base_twist"][:, :2].any()


def test_shoulder_axial_limit_widens_with_elevation():
    lo, hi = ls.axial_range(np.radians([[0.0] * 4, [90.0] * 4, [125.0] * 4]))
    margin = np.degrees(ls.SHOULDER_PASSIVE_MARGIN)
    assert np.degrees(hi[0, :2]) == pytest.approx([70 + margin] * 2)
    assert np.degrees(lo[0, :2]) == pytest.approx([-90 - margin] * 2)
    assert np.all(hi[1, :2] > hi[0, :2]) and np.all(lo[1, :2] < lo[0, :2])
    assert np.degrees(hi[2, :2]) == pytest.approx([180, 180]) and np.degrees(lo[2, :2]) == pytest.approx([-180, -180])
    assert np.degrees(hi[:, 2:]) == pytest.approx(45.0) and np.degrees(lo[:, 2:]) == pytest.approx(-45.0)


def test_hip_axial_limit_widens_past_the_flexion_range():
    lo, hi = ls.axial_range(np.radians([[100.0] * 4, [150.0] * 4, [170.0] * 4]))
    assert np.degrees(hi[0, 2:]) == pytest.approx(45.0) and np.degrees(lo[0, 2:]) == pytest.approx(-45.0)
    assert np.all(hi[1, 2:] > hi[0, 2:]) and np.all(lo[1, 2:] < lo[0, 2:])
    assert np.degrees(hi[2, 2:]) == pytest.approx(180.0) and np.degrees(lo[2, 2:]) == pytest.approx(-180.0)
