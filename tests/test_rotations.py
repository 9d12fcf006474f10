import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from blender_manikin.core import rotations as rot

finite = st.floats(-3.0, 3.0, allow_nan=False)


def rand_R(rng, n):
    return rot.quat_to_matrix(rng.normal(size=(n, 4)))


def test_quat_matrix_round_trip():
    rng = np.random.default_rng(0)
    q = rot.normalize(rng.normal(size=(1000, 4)))
    q2 = rot.matrix_to_quat(rot.quat_to_matrix(q))
    assert np.allclose(np.abs(np.sum(q * q2, -1)), 1.0, atol=1e-12)
    assert np.all(q2[:, 0] >= 0)
    R = rot.quat_to_matrix(q)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_quat_convention_is_wxyz_right_handed():
    q = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])  # +90 deg about Z
    assert np.allclose(rot.quat_to_matrix(q) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(rot.quat_rotate(q, [1, 0, 0]), [0, 1, 0])


def test_quat_mul_matches_matrix_product():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2, 50, 4))
    assert np.allclose(rot.quat_to_matrix(rot.quat_mul(a, b)), rot.quat_to_matrix(a) @ rot.quat_to_matrix(b))


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, 3, elements=finite))
def test_axis_angle_round_trip(aa):
    R = rot.axis_angle_to_matrix(aa)
    R2 = rot.axis_angle_to_matrix(rot.matrix_to_axis_angle(R))
    assert np.allclose(R, R2, atol=1e-9)
    assert np.allclose(rot.quat_to_matrix(rot.axis_angle_to_quat(aa)), R, atol=1e-12)


def test_6d_round_trip_and_gram_schmidt():
    rng = np.random.default_rng(2)
    R = rand_R(rng, 500)
    assert np.allclose(rot.sixd_to_matrix(rot.matrix_to_6d(R)), R, atol=1e-12)
    noisy = rot.matrix_to_6d(R) + rng.normal(size=(500, 6)) * 0.01
    R2 = rot.sixd_to_matrix(noisy)
    assert np.allclose(R2 @ np.swapaxes(R2, -1, -2), np.eye(3), atol=1e-12)


def test_slerp_endpoints_midpoint_and_short_arc():
    q0 = np.array([1.0, 0, 0, 0])
    q1 = rot.axis_angle_to_quat(np.array([0, 0, 1.0]))
    assert np.allclose(rot.quat_slerp(q0, q1, 0.0), q0)
    assert np.allclose(rot.quat_slerp(q0, q1, 1.0), q1)
    mid = rot.quat_slerp(q0, q1, 0.5)
    assert np.allclose(rot.quat_to_axis_angle(mid), [0, 0, 0.5])
    # -q1 is the same rotation: slerp must still take the short arc
    mid2 = rot.quat_slerp(q0, -q1, 0.5)
    assert np.allclose(rot.quat_to_matrix(mid2), rot.quat_to_matrix(mid))


def test_quat_continuous_removes_sign_flips():
    t = np.linspace(0, 3, 100)
    q = rot.axis_angle_to_quat(np.stack([0 * t, t, 0 * t], -1))
    flipped = q.copy()
    flipped[::3] *= -1
    c = rot.quat_continuous(flipped)
    assert np.all(np.sum(c[1:] * c[:-1], -1) > 0)
    assert np.allclose(rot.quat_to_matrix(c), rot.quat_to_matrix(q))


def test_swing_twist_decomposition():
    rng = np.random.default_rng(3)
    q = rot.normalize(rng.normal(size=(500, 4)))
    axis = rot.normalize(rng.normal(size=(500, 3)))
    sw, tw, ang = rot.swing_twist(q, axis)
    assert np.allclose(rot.quat_to_matrix(rot.quat_mul(sw, tw)), rot.quat_to_matrix(q), atol=1e-10)
    # twist rotates about the axis, swing axis is perpendicular to it
    assert np.allclose(np.cross(tw[:, 1:], axis), 0, atol=1e-10)
    assert np.allclose(np.sum(sw[:, 1:] * axis, -1), 0, atol=1e-10)
    assert np.all((ang > -np.pi - 1e-12) & (ang <= np.pi + 1e-12))
    # a pure twist of known angle
    a = np.array([0.0, 0.0, 1.0])
    q = rot.axis_angle_to_quat(a * 0.7)
    assert np.isclose(rot.swing_twist(q, a)[2], 0.7)
    assert np.isclose(rot.twist_angle(rot.quat_to_matrix(q), -a), -0.7)


def test_rotation_between_including_antiparallel():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(200, 3))
    b = rng.normal(size=(200, 3))
    b[:5] = -a[:5]
    b[5:10] = a[5:10] * 3
    R = rot.rotation_between(a, b)
    assert np.all(np.isfinite(R))
    assert np.allclose(np.einsum("nij,nj->ni", R, rot.normalize(a)), rot.normalize(b), atol=1e-9)
    assert np.allclose(R[5:10], np.eye(3), atol=1e-9)


def test_geodesic_angle():
    R = rot.axis_angle_to_matrix(np.array([[0, 0.3, 0.0]]))
    assert np.isclose(rot.geodesic_angle(np.eye(3)[None], R)[0], 0.3)


def test_the_one_euler_implementation():
    """Intrinsic channel order (BVH), its inverse with gimbal lock, and fixed-axes orders
    (Blender rotation modes, Acclaim ASF axes)."""
    from blender_manikin.core import rotations as rot
    rng = np.random.default_rng(5)
    e = rng.uniform(-3, 3, (100, 3))
    e[:, 1] = rng.uniform(-1.5, 1.5, 100)
    ex = lambda a: rot.axis_angle_rotation(np.array([1.0, 0, 0]), a)  # noqa: E731
    ey = lambda a: rot.axis_angle_rotation(np.array([0, 1.0, 0]), a)  # noqa: E731
    ez = lambda a: rot.axis_angle_rotation(np.array([0, 0, 1.0]), a)  # noqa: E731
    assert np.allclose(rot.euler_to_matrix(e, "ZXY"), ez(e[:, 0]) @ ex(e[:, 1]) @ ey(e[:, 2]))
    for order in ("XYZ", "ZXY", "YXZ", "ZYX"):
        R = rot.euler_to_matrix(e, order)
        assert np.allclose(rot.euler_to_matrix(rot.matrix_to_euler(R, order), order), R, atol=1e-10)
    lock = rot.euler_to_matrix([[0.3, np.pi / 2, 0.2]], "ZXY")
    back = rot.matrix_to_euler(lock, "ZXY")
    assert back[0, 2] == 0.0 and np.allclose(rot.euler_to_matrix(back, "ZXY"), lock, atol=1e-9)
    # Blender's 'XYZ' mode applies X first: Rz @ Ry @ Rx, angles given as (x, y, z)
    assert np.allclose(rot.fixed_axes_euler_to_matrix(e, "XYZ"), ez(e[:, 2]) @ ey(e[:, 1]) @ ex(e[:, 0]))
    assert np.allclose(rot.fixed_axes_euler_to_matrix(e, "ZXY"), ey(e[:, 1]) @ ex(e[:, 0]) @ ez(e[:, 2]))
    with pytest.raises(ValueError, match="not representable"):
        rot.matrix_to_euler(rot.euler_to_matrix([[0.1, 0.2]], "XY"), "Z")


def test_vector_norm_matches_linalg_norm_and_feeds_normalize():
    rng = np.random.default_rng(3)
    for width in (3, 4):
        v = rng.normal(size=(50, width)) * 10.0 ** rng.uniform(-3, 3, size=(50, 1))
        v[0] = 0.0
        n = rot.vector_norm(v)
        np.testing.assert_array_equal(n, np.linalg.norm(v, axis=-1))
        np.testing.assert_array_equal(rot.normalize(v, norm=n), rot.normalize(v))
        w = v.copy()
        assert rot.normalize(w, norm=n, out=w) is w
        np.testing.assert_array_equal(w, rot.normalize(v))
        assert np.all(rot.normalize(v)[0] == 0.0)
        np.testing.assert_allclose(np.linalg.norm(rot.normalize(v)[1:], axis=-1), 1.0, atol=1e-12)


@pytest.mark.parametrize("order", ["xy", "yx", "xz", "zx", "yz", "zy"])
def test_frame_from_axes_keeps_the_first_axis_and_is_a_rotation(order):
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    R = rot.frame_from_axes(a, b, order)
    i, j = "xyz".index(order[0]), "xyz".index(order[1])
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R[..., i], a / np.linalg.norm(a, axis=-1, keepdims=True), atol=1e-12)
    # the second axis lies in the plane of a and b, on b's side
    assert np.all(np.sum(R[..., j] * b, -1) > 0)
    np.testing.assert_allclose(np.einsum("ti,ti->t", np.cross(a, b), R[..., j]), 0.0, atol=1e-9)
    with pytest.raises(ValueError, match="names one axis twice"):
        rot.frame_from_axes(a, b, "xx")


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_fixed_axes_euler_round_trip_and_continuity_through_gimbal_lock(order):
    """Blender's Euler modes: any rotation decomposes and composes back; a path turning through
    the middle axis's +-90 degrees (gimbal lock) is keyed without the 180-360 degree jumps of the
    plain decomposition, as Blender's compatible Euler keys it."""
    rng = np.random.default_rng(7)
    R = rot.quat_to_matrix(rot.normalize(rng.normal(size=(500, 4))))
    e = rot.matrix_to_fixed_axes_euler(R, order)
    np.testing.assert_allclose(rot.fixed_axes_euler_to_matrix(e, order), R, atol=1e-12)
    t = np.linspace(0.0, 1.0, 400)
    ang = np.zeros((400, 3))
    mid = "XYZ".index(order[1])
    ang[:, mid] = np.radians(-170 + 340 * t)                  # through +-90: both gimbal locks
    ang[:, (mid + 1) % 3] = np.radians(30 * np.sin(6 * t))
    ang[:, (mid + 2) % 3] = np.radians(20 * t)
    path = rot.fixed_axes_euler_to_matrix(ang, order)
    plain = rot.matrix_to_fixed_axes_euler(path, order)
    assert np.degrees(np.abs(np.diff(plain, axis=0)).max()) > 170             # the jumps this is for
    cont = rot.euler_continuous(plain, order)
    np.testing.assert_allclose(rot.fixed_axes_euler_to_matrix(cont, order), path, atol=1e-12)
    assert np.degrees(np.abs(np.diff(cont, axis=0)).max()) < 1.0               # 0.85 degrees a step
    # whole turns are taken off too, and several bones go at once (T, bones, 3)
    both = np.stack([plain + 2 * np.pi, plain], 1)
    np.testing.assert_allclose(rot.euler_continuous(both, order)[1:], np.stack([cont, cont], 1)[1:]
                               + np.array([2 * np.pi, 0.0])[None, :, None], atol=1e-9)


def test_axis_angle_continuous_keeps_the_rotation_and_its_axis():
    rng = np.random.default_rng(8)
    q = rot.normalize(rng.normal(size=(60, 2, 4)))
    aa = rot.quat_to_axis_angle_continuous(q)
    np.testing.assert_allclose(rot.axis_angle_to_matrix(aa[..., 1:] * aa[..., :1]), rot.quat_to_matrix(q), atol=1e-12)
    # through no rotation at all: the axis is carried over, the angle passes 0 smoothly
    ang = np.linspace(-0.3, 0.3, 7)
    axis = rot.normalize(np.array([1.0, 2.0, 2.0]))
    qs = rot.axis_angle_to_quat(axis * ang[:, None])
    out = rot.quat_to_axis_angle_continuous(qs)
    np.testing.assert_allclose(np.abs(out[:, 1:] @ axis), 1.0, atol=1e-12)     # along the one axis
    np.testing.assert_allclose(rot.axis_angle_to_matrix(out[:, 1:] * out[:, :1]),
                               rot.axis_angle_to_matrix(axis * ang[:, None]), atol=1e-12)
    assert np.all(np.isfinite(out)) and np.abs(out[3, 1:] - out[2, 1:]).max() < 1e-12     # no axis at 0
    # no rotation before any axis was seen: Blender's default axis, +Y
    lead = rot.quat_to_axis_angle_continuous(np.concatenate([[[1.0, 0, 0, 0]] * 2, qs[:2]]))
    np.testing.assert_allclose(lead[:2], [[0.0, 0, 1, 0]] * 2, atol=1e-12)


def test_wrap_angle():
    from blender_manikin.core.rotations import wrap_angle
    a = np.array([0.0, np.pi, -np.pi, 3 * np.pi / 2, -7.0, 10.0])
    w = wrap_angle(a)
    assert np.all((w >= -np.pi) & (w < np.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    assert w[1] == pytest.approx(-np.pi) and w[3] == pytest.approx(-np.pi / 2)
