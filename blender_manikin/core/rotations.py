"""Rotation utilities, batched over any leading shape. Never imports bpy.

Conventions (used everywhere in blender_manikin):

* Rotation matrices ``(..., 3, 3)`` act on column vectors: ``v_world = R @ v_local``.
  Composition ``R_parent @ R_local`` applies ``R_local`` first.
* Quaternions are ``(..., 4)`` in ``(w, x, y, z)`` order, unit length, Hamilton
  product; ``q`` and ``-q`` are the same rotation.
* Axis-angle is ``(..., 3)``: unit axis times angle in radians (right-hand rule).
* 6D (Zhou et al. 2019) is ``(..., 6)``: the first two *columns* of the matrix,
  ``[R[:,0], R[:,1]]`` concatenated; decoded by Gram-Schmidt.
* Swing-twist about a unit axis ``a``: ``R = R_swing @ R_twist`` where
  ``R_twist`` rotates about ``a`` and ``R_swing`` has its axis perpendicular to
  ``a``.  The twist angle is the same for ``R_twist @ R_swing`` ordering.

All functions compute in float64 and accept float32 input.
"""
from __future__ import annotations

import numpy as np

_EPS = 1e-12


def _f64(x):
    return np.asarray(x, dtype=np.float64)


def vector_norm(v):
    """``(...,)`` float64 Euclidean length of ``(..., 3)`` or ``(..., 4)`` vectors, in the same
    sum order as ``np.linalg.norm`` without its temporaries (what :func:`normalize` divides by)."""
    v = _f64(v)
    n = np.empty(v.shape[:-1])
    np.multiply(v[..., 0], v[..., 0], out=n)
    for k in range(1, v.shape[-1]):
        n += v[..., k] * v[..., k]
    return np.sqrt(n, out=n)


def normalize(v, axis=-1, eps=_EPS, norm=None, out=None):
    """Unit vectors along ``axis``; zero vectors stay zero (no NaN).  norm: the lengths from
    :func:`vector_norm` when the caller has them already; out: array to write into (``v``
    itself to normalise in place); both for the last axis of ``(..., 3|4)`` vectors only."""
    v = _f64(v)
    if v.ndim and axis in (-1, v.ndim - 1) and v.shape[-1] in (3, 4):
        n = vector_norm(v) if norm is None else norm
        return np.divide(v, np.maximum(n, eps)[..., None], out=out)
    n = np.linalg.norm(v, axis=axis, keepdims=True)
    return v / np.maximum(n, eps)


# --------------------------------------------------------------------------
# quaternion basics
def quat_mul(a, b):
    """Hamilton product ``a * b`` of ``(..., 4)`` wxyz quaternions."""
    a = _f64(a)
    b = _f64(b)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_conj(q):
    q = _f64(q).copy()
    q[..., 1:] *= -1.0
    return q


def quat_normalize(q):
    return normalize(q)


def quat_rotate(q, v):
    """Rotate vectors ``(..., 3)`` by quaternions ``(..., 4)``."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), _f64(v))


def quat_to_matrix(q):
    """``(..., 4)`` wxyz → ``(..., 3, 3)``.  Input need not be normalised."""
    q = normalize(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (yy + zz)
    m[..., 0, 1] = 2 * (xy - wz)
    m[..., 0, 2] = 2 * (xz + wy)
    m[..., 1, 0] = 2 * (xy + wz)
    m[..., 1, 1] = 1 - 2 * (xx + zz)
    m[..., 1, 2] = 2 * (yz - wx)
    m[..., 2, 0] = 2 * (xz - wy)
    m[..., 2, 1] = 2 * (yz + wx)
    m[..., 2, 2] = 1 - 2 * (xx + yy)
    return m


def matrix_to_quat(m):
    """``(..., 3, 3)`` → ``(..., 4)`` wxyz with ``w >= 0`` (Shepperd's method)."""
    m = _f64(m)
    shape = m.shape[:-2]
    f = m.reshape(-1, 9)
    N = f.shape[0]
    d0, d1, d2 = f[:, 0], f[:, 4], f[:, 8]
    tr = d0 + d1 + d2
    # argmax of (tr, m00, m11, m22), first maximum on ties
    k = np.zeros(N, dtype=np.int8)
    best = tr.copy()
    for c, dc in ((1, d0), (2, d1), (3, d2)):
        better = dc > best
        k[better] = c
        np.maximum(best, dc, out=best)
    q = np.empty((N, 4))
    if N:
        if not k.any():              # the common case: every row is case 0
            groups = ((0, slice(None)),)
        else:
            groups = tuple((c, np.flatnonzero(k == c)) for c in range(4))
        for c, i in groups:
            g = f[i]
            if g.shape[0] == 0:
                continue
            m00, m01, m02, m10, m11, m12, m20, m21, m22 = g.T
            if c == 0:
                s = np.sqrt(np.maximum(1.0 + (m00 + m11 + m22), 0.0)) * 2.0
                q[i, 0] = 0.25 * s
                q[i, 1] = (m21 - m12) / s
                q[i, 2] = (m02 - m20) / s
                q[i, 3] = (m10 - m01) / s
            elif c == 1:
                s = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 0.0)) * 2.0
                q[i, 0] = (m21 - m12) / s
                q[i, 1] = 0.25 * s
                q[i, 2] = (m01 + m10) / s
                q[i, 3] = (m02 + m20) / s
            elif c == 2:
                s = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 0.0)) * 2.0
                q[i, 0] = (m02 - m20) / s
                q[i, 1] = (m01 + m10) / s
                q[i, 2] = 0.25 * s
                q[i, 3] = (m12 + m21) / s
            else:
                s = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 0.0)) * 2.0
                q[i, 0] = (m10 - m01) / s
                q[i, 1] = (m02 + m20) / s
                q[i, 2] = (m12 + m21) / s
                q[i, 3] = 0.25 * s
    q = normalize(q)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(shape + (4,))


# --------------------------------------------------------------------------
# axis-angle
def axis_angle_to_matrix(aa):
    """``(..., 3)`` rotation vectors (axis * radians) → ``(..., 3, 3)`` (Rodrigues)."""
    aa = _f64(aa)
    theta = np.linalg.norm(aa, axis=-1, keepdims=True)
    k = aa / np.maximum(theta, _EPS)
    theta = theta[..., 0]
    s = np.sin(theta)
    c = 1 - np.cos(theta)
    x, y, z = k[..., 0], k[..., 1], k[..., 2]
    xx, yy, zz = x * x, y * y, z * z
    cxy, cxz, cyz = c * (x * y), c * (x * z), c * (y * z)
    sx, sy, sz = s * x, s * y, s * z
    R = np.empty(aa.shape[:-1] + (3, 3))
    # (K K)_ii = -(k_j^2 + k_l^2), (K K)_ij = k_i k_j
    R[..., 0, 0] = 1 + c * -(yy + zz)
    R[..., 0, 1] = -sz + cxy
    R[..., 0, 2] = sy + cxz
    R[..., 1, 0] = sz + cxy
    R[..., 1, 1] = 1 + c * -(xx + zz)
    R[..., 1, 2] = -sx + cyz
    R[..., 2, 0] = -sy + cxz
    R[..., 2, 1] = sx + cyz
    R[..., 2, 2] = 1 + c * -(xx + yy)
    return R


def matrix_to_axis_angle(m):
    """``(..., 3, 3)`` → ``(..., 3)`` rotation vectors, angle in [0, pi]."""
    return quat_to_axis_angle(matrix_to_quat(m))


def quat_to_axis_angle(q):
    q = normalize(q)
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    return v / np.maximum(s, _EPS) * angle


def axis_angle_to_quat(aa):
    aa = _f64(aa)
    theta = np.linalg.norm(aa, axis=-1, keepdims=True)
    k = aa / np.maximum(theta, _EPS)
    return np.concatenate([np.cos(theta / 2), k * np.sin(theta / 2)], axis=-1)


def axis_angle_rotation(axis, angle):
    """Rotation matrices about ``axis`` (``(..., 3)``, normalised here) by ``angle`` (``(...)`` radians)."""
    axis = normalize(axis)
    angle = _f64(angle)
    return axis_angle_to_matrix(axis * angle[..., None])


def skew(v):
    """``(..., 3)`` → cross-product matrices ``(..., 3, 3)``."""
    v = _f64(v)
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1] = -w
    K[..., 0, 2] = y
    K[..., 1, 0] = w
    K[..., 1, 2] = -x
    K[..., 2, 0] = -y
    K[..., 2, 1] = x
    return K


# --------------------------------------------------------------------------
# 6D
def matrix_to_6d(m):
    """``(..., 3, 3)`` → ``(..., 6)``: first column then second column."""
    m = _f64(m)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def frame_from_axes(a, b, order="xy"):
    """``(..., 3, 3)`` right-handed rotation whose columns are the frame's axes, from two of them.

    ``order`` names the axes ``a`` and ``b`` (``(..., 3)``) stand for: ``"xy"``, ``"yz"``,
    ``"zx"``, ``"yx"``, ... ``a`` is kept exactly (normalised), ``b`` is made orthogonal to it
    (Gram-Schmidt) and the third axis completes a right-handed frame."""
    i, j = "xyz".index(order[0]), "xyz".index(order[1])
    if i == j:
        raise ValueError(f"order {order!r} names one axis twice")
    e = [None, None, None]
    e[i] = normalize(a)
    b = _f64(b)
    e[j] = normalize(b - np.sum(e[i] * b, -1, keepdims=True) * e[i])
    e[3 - i - j] = np.cross(e[i], e[j]) if (j - i) % 3 == 1 else np.cross(e[j], e[i])
    return np.stack(e, axis=-1)


def sixd_to_matrix(d6):
    """``(..., 6)`` → ``(..., 3, 3)`` by Gram-Schmidt on the two columns."""
    d6 = _f64(d6)
    return frame_from_axes(d6[..., :3], d6[..., 3:], "xy")


# --------------------------------------------------------------------------
# interpolation and series
def quat_slerp(q0, q1, t):
    """Spherical interpolation between ``q0`` and ``q1`` (``(..., 4)``) at ``t`` (``(...)`` in [0,1]).

    Takes the short arc (flips ``q1`` when ``q0 . q1 < 0``).
    """
    q0 = normalize(q0)
    q1 = normalize(q1)
    t = _f64(t)[..., None]
    d = np.sum(q0 * q1, -1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-6
    w0 = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(small, 1.0, s))
    w1 = np.where(small, t, np.sin(t * theta) / np.where(small, 1.0, s))
    return normalize(w0 * q0 + w1 * q1)


def quat_continuous(q, axis=0):
    """Flip signs along ``axis`` so consecutive quaternions have positive dot product.

    ``q``: ``(T, ..., 4)`` (``axis=0`` is time).  Returns a copy.  Vectorised:
    the sign of sample ``t`` is the running product of the signs of the
    consecutive dot products.
    """
    q = np.moveaxis(_f64(q), axis, 0).copy()
    if q.shape[0] < 2:
        return np.moveaxis(q, 0, axis)
    d = np.sum(q[1:] * q[:-1], -1)
    flip = np.where(d < 0, -1.0, 1.0)
    sign = np.concatenate([np.ones((1,) + flip.shape[1:]), np.cumprod(flip, axis=0)], 0)
    q = q * sign[..., None]
    return np.moveaxis(q, 0, axis)


# --------------------------------------------------------------------------
# swing-twist
def swing_twist(q, axis):
    """Decompose wxyz quaternions ``q`` (``(..., 4)``) about unit ``axis`` (``(..., 3)``).

    Returns ``(q_swing, q_twist, twist_angle)`` with ``q = q_swing * q_twist``;
    ``twist_angle`` in (-pi, pi] radians, right-handed about ``axis``.  When the
    rotation is a half-turn about an axis perpendicular to ``axis`` the twist
    is undefined and returned as identity.
    """
    q, tw, angle = _twist(q, axis)
    sw = quat_mul(q, quat_conj(tw))
    return sw, tw, angle


def _dot3(a, b):
    """``sum(a * b, -1)`` for ``(..., 3)`` arrays, same summation order."""
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def _twist(q, axis):
    """``(normalised q, twist quaternion, twist angle)`` of :func:`swing_twist`."""
    q = normalize(q)
    axis = normalize(axis)
    proj = _dot3(q[..., 1:], axis)[..., None]
    shape = np.broadcast_shapes(q.shape, axis.shape[:-1] + (4,))
    tw = np.empty(shape)
    tw[..., :1] = q[..., :1]
    tw[..., 1:] = proj * axis
    n = np.linalg.norm(tw, axis=-1, keepdims=True)
    tw /= np.maximum(n, _EPS)
    small = n[..., 0] < 1e-9
    if small.any():
        tw[small] = (1.0, 0.0, 0.0, 0.0)
    angle = 2.0 * np.arctan2(_dot3(tw[..., 1:], axis), tw[..., 0])
    angle = np.where(angle > np.pi, angle - 2 * np.pi, angle)
    angle = np.where(angle <= -np.pi, angle + 2 * np.pi, angle)
    return q, tw, angle


def wrap_angle(a):
    """Angles ``a`` (radians, any shape) wrapped into ``[-pi, pi)``."""
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def twist_angle(R, axis):
    """Twist angle (radians, (-pi, pi]) of rotation matrices ``R`` about ``axis``."""
    return _twist(matrix_to_quat(R), axis)[2]


def rotation_between(a, b):
    """Minimal rotation matrices taking unit(``a``) to unit(``b``), ``(..., 3)`` → ``(..., 3, 3)``.

    For antiparallel inputs a half-turn about an arbitrary axis perpendicular
    to ``a`` is returned (finite, never NaN).
    """
    a = normalize(a)
    b = normalize(b)
    a, b = np.broadcast_arrays(a, b)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    # quaternion (1 + a.b, a x b) normalised is the half-way rotation
    q = np.empty(a.shape[:-1] + (4,))
    q[..., 0] = 1.0 + ((a0 * b0 + a1 * b1) + a2 * b2)
    q[..., 1] = a1 * b2 - a2 * b1
    q[..., 2] = a2 * b0 - a0 * b2
    q[..., 3] = a0 * b1 - a1 * b0
    bad = q[..., 0] < 1e-10
    if np.any(bad):
        ab = a[bad]
        helper = np.where(np.abs(ab[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
        perp = normalize(np.cross(ab, helper))
        q[bad] = np.concatenate([np.zeros((perp.shape[0], 1)), perp], -1)
    return quat_to_matrix(q)


def geodesic_angle(Ra, Rb):
    """Angle (radians) of ``Ra^T Rb`` for ``(..., 3, 3)`` inputs."""
    Ra = _f64(Ra)
    Rb = _f64(Rb)
    tr = np.einsum("...ji,...ji->...", Ra, Rb)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def orthonormalize(R):
    """Nearest rotation matrices (via SVD) to ``(..., 3, 3)`` inputs."""
    U, _, Vt = np.linalg.svd(_f64(R))
    det = np.linalg.det(U @ Vt)
    D = np.ones(U.shape[:-1])
    D[..., -1] = det
    return (U * D[..., None, :]) @ Vt


# --------------------------------------------------------------------------
# Euler angles: the one implementation every module uses (BVH channels, BVH export, Blender
# objects' rotation modes, Acclaim axes, device-offset presets).
_EULER_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _elementary(axis, angle):
    """Rotation matrices ``(..., 3, 3)`` about one coordinate axis (``"X"``, ``"Y"``, ``"Z"``),
    angles in radians."""
    a = _f64(angle)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i = _EULER_AXIS[axis]
    j, k = (i + 1) % 3, (i + 2) % 3
    R[..., i, i] = 1.0
    R[..., j, j] = c
    R[..., k, k] = c
    R[..., j, k] = -s
    R[..., k, j] = s
    return R


def euler_to_matrix(angles, axes):
    """Rotations composed in ``axes`` order, as BVH channels are: ``axes = "ZXY"`` gives
    ``R = Rz(a0) @ Rx(a1) @ Ry(a2)`` (each later rotation about the already rotated axes).

    angles: ``(..., n)`` radians for ``n = len(axes)`` letters from ``XYZ``; ``n = 0`` gives
    identity.  Returns ``(..., 3, 3)``."""
    ang = _f64(angles)
    axes = axes.upper()
    if ang.shape[-1] != len(axes):
        raise ValueError(f"{len(axes)} axes but {ang.shape[-1]} angles")
    R = np.broadcast_to(np.eye(3), ang.shape[:-1] + (3, 3)).copy()
    for n, ax in enumerate(axes):
        R = R @ _elementary(ax, ang[..., n]) if n else _elementary(ax, ang[..., n])
    return R


def _tait_bryan(R, axes):
    """Angles (radians) ``(..., 3)`` with ``R = Ri(a) Rj(b) Rk(c)``, axes distinct."""
    i, j, k = (_EULER_AXIS[a] for a in axes)
    # parity of the permutation (i, j, k): +1 for XYZ, YZX, ZXY
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    sb = np.clip(s * R[..., i, k], -1.0, 1.0)
    b = np.arcsin(sb)
    cb = np.sqrt(np.maximum(1.0 - sb * sb, 0.0))
    a = np.arctan2(-s * R[..., j, k], R[..., k, k])
    c = np.arctan2(-s * R[..., i, j], R[..., i, i])
    # gimbal lock: b = +-90 deg, only a + c (or a - c) is defined; put it in a
    lock = cb < 1e-7
    if np.any(lock):
        # with c = 0: R = Ri(a) Rj(b); column j of R is Ri(a) e_j
        a_l = np.arctan2(s * R[..., k, j], R[..., j, j])
        a = np.where(lock, a_l, a)
        c = np.where(lock, 0.0, c)
    return np.stack([a, b, c], axis=-1)


def matrix_to_euler(R, axes, tol=1e-6):
    """Inverse of :func:`euler_to_matrix`: radians ``(..., n)`` for ``n = len(axes)``.

    Three distinct axes decompose any rotation; the middle angle is in ``[-pi/2, pi/2]`` and at
    gimbal lock the last angle is 0.  One or two axes can only represent rotations about those
    axes; ``ValueError`` is raised when ``R`` is further than ``tol`` from representable."""
    R = _f64(R)
    axes = axes.upper()
    n = len(axes)
    if n == 0:
        ang = np.zeros(R.shape[:-2] + (0,))
    else:
        if len(set(axes)) != n or any(a not in _EULER_AXIS for a in axes):
            raise ValueError(f"rotation axes must be distinct letters from XYZ, got {axes!r}")
        full = axes + "".join(a for a in "XYZ" if a not in axes)
        ang = _tait_bryan(R, full)[..., :n]
    if n < 3:
        back = euler_to_matrix(ang, axes)
        err = np.abs(back - R).max() if R.size else 0.0
        if err > tol:
            raise ValueError(f"rotation is not representable with channels {axes!r} (residual {err:.2e})")
    return ang


def fixed_axes_euler_to_matrix(angles_xyz, order):
    """Rotations about the fixed world axes applied in ``order``, first letter first, as
    Blender's rotation modes and Acclaim ASF axes are: ``order = "XYZ"`` gives
    ``R = Rz(z) @ Ry(y) @ Rx(x)``.

    angles_xyz: ``(..., 3)`` radians about x, y and z (in that order, whatever ``order``);
    order: a permutation of ``XYZ``.  Returns ``(..., 3, 3)``."""
    a = _f64(angles_xyz)
    rev = order.upper()[::-1]
    return euler_to_matrix(a[..., [_EULER_AXIS[c] for c in rev]], rev)



def matrix_to_fixed_axes_euler(R, order):
    """Inverse of :func:`fixed_axes_euler_to_matrix`: ``(..., 3)`` radians about x, y and z (in
    that order) of rotations ``R`` ``(..., 3, 3)`` for a Blender rotation mode ``order`` (``"XYZ"``:
    ``R = Rz(z) @ Ry(y) @ Rx(x)``); the middle axis's angle in ``[-pi/2, pi/2]``."""
    rev = order.upper()[::-1]
    ang = matrix_to_euler(R, rev)
    out = np.empty_like(ang)
    for n, c in enumerate(rev):
        out[..., _EULER_AXIS[c]] = ang[..., n]
    return out


def euler_continuous(angles_xyz, order):
    """Fixed-axes Euler angles (:func:`fixed_axes_euler_to_matrix`) ``(T, ..., 3)`` radians made
    continuous along axis 0, as Blender's compatible Euler does: each frame takes, of the two
    decompositions of its rotation (the angles ``(a, b, c)`` in ``order`` and ``(a + pi, pi - b,
    c + pi)``) each turned by whole turns nearest the frame before, the one nearer it.  The same
    rotations; keys of them interpolate without a spin."""
    e = _f64(angles_xyz).copy()
    if e.shape[0] < 2:
        return e
    mid = _EULER_AXIS[order.upper()[1]]
    alt = e + np.pi
    alt[..., mid] = np.pi - e[..., mid]
    two_pi = 2.0 * np.pi
    for t in range(1, e.shape[0]):
        prev = e[t - 1]
        a = e[t] + two_pi * np.round((prev - e[t]) / two_pi)
        b = alt[t] + two_pi * np.round((prev - alt[t]) / two_pi)
        nearer = np.abs(b - prev).sum(-1) < np.abs(a - prev).sum(-1)
        e[t] = np.where(nearer[..., None], b, a)
    return e


def quat_to_axis_angle_continuous(q):
    """``(T, ..., 4)`` wxyz quaternions → ``(T, ..., 4)`` (angle, x, y, z), Blender's axis-angle
    rotation mode, continuous along axis 0: the quaternions' signs made continuous first (the angle
    may pass 180 degrees rather than flip its axis), and where the rotation is nearly none (no
    axis to read) the axis of the frame before (the first frames': +Y, Blender's default)."""
    q = quat_continuous(normalize(q), axis=0)
    v = q[..., 1:]
    s = vector_norm(v)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    seen = s > 1e-9
    axis = v / np.maximum(s, 1e-12)[..., None]
    # carry the last axis over axis-less frames: each frame's latest seen frame (-1: none yet, +Y)
    T = seen.shape[0]
    frame = np.arange(T).reshape((T,) + (1,) * (seen.ndim - 1))
    last = np.maximum.accumulate(np.where(seen, frame, -1), axis=0)
    carried = np.take_along_axis(axis, np.maximum(last, 0)[..., None], axis=0)
    axis = np.where((last >= 0)[..., None], carried, np.array([0.0, 1.0, 0.0]))
    return np.concatenate([angle[..., None], axis], -1)
