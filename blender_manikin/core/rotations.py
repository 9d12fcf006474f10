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


def normalize(v, axis=-1, eps=_EPS):
    """Unit vectors along ``axis``; zero vectors stay zero (no NaN)."""
    v = _f64(v)
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
    w, x, y, z = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack([
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ], axis=-1)
    return m.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat(m):
    """``(..., 3, 3)`` → ``(..., 4)`` wxyz with ``w >= 0`` (Shepperd's method)."""
    m = _f64(m)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((m.shape[0], 4))
    # case w largest
    s = np.sqrt(np.maximum(1.0 + tr, 0.0)) * 2.0
    i = k == 0
    q[i, 0] = 0.25 * s[i]
    q[i, 1] = (m[i, 2, 1] - m[i, 1, 2]) / s[i]
    q[i, 2] = (m[i, 0, 2] - m[i, 2, 0]) / s[i]
    q[i, 3] = (m[i, 1, 0] - m[i, 0, 1]) / s[i]
    i = k == 1
    s = np.sqrt(np.maximum(1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2], 0.0)) * 2.0
    q[i, 0] = (m[i, 2, 1] - m[i, 1, 2]) / s[i]
    q[i, 1] = 0.25 * s[i]
    q[i, 2] = (m[i, 0, 1] + m[i, 1, 0]) / s[i]
    q[i, 3] = (m[i, 0, 2] + m[i, 2, 0]) / s[i]
    i = k == 2
    s = np.sqrt(np.maximum(1.0 + m[:, 1, 1] - m[:, 0, 0] - m[:, 2, 2], 0.0)) * 2.0
    q[i, 0] = (m[i, 0, 2] - m[i, 2, 0]) / s[i]
    q[i, 1] = (m[i, 0, 1] + m[i, 1, 0]) / s[i]
    q[i, 2] = 0.25 * s[i]
    q[i, 3] = (m[i, 1, 2] + m[i, 2, 1]) / s[i]
    i = k == 3
    s = np.sqrt(np.maximum(1.0 + m[:, 2, 2] - m[:, 0, 0] - m[:, 1, 1], 0.0)) * 2.0
    q[i, 0] = (m[i, 1, 0] - m[i, 0, 1]) / s[i]
    q[i, 1] = (m[i, 0, 2] + m[i, 2, 0]) / s[i]
    q[i, 2] = (m[i, 1, 2] + m[i, 2, 1]) / s[i]
    q[i, 3] = 0.25 * s[i]
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
    theta = theta[..., None]
    K = skew(k)
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + np.sin(theta) * K + (1 - np.cos(theta)) * (K @ K)


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
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([
        np.stack([z, -w, y], -1),
        np.stack([w, z, -x], -1),
        np.stack([-y, x, z], -1),
    ], -2)


# --------------------------------------------------------------------------
# 6D
def matrix_to_6d(m):
    """``(..., 3, 3)`` → ``(..., 6)``: first column then second column."""
    m = _f64(m)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_to_matrix(d6):
    """``(..., 6)`` → ``(..., 3, 3)`` by Gram-Schmidt on the two columns."""
    d6 = _f64(d6)
    a = normalize(d6[..., :3])
    b = d6[..., 3:] - np.sum(a * d6[..., 3:], -1, keepdims=True) * a
    b = normalize(b)
    c = np.cross(a, b)
    return np.stack([a, b, c], axis=-1)


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
    q = normalize(q)
    axis = normalize(axis)
    proj = np.sum(q[..., 1:] * axis, -1, keepdims=True)
    tw = np.concatenate([q[..., :1], proj * axis], -1)
    n = np.linalg.norm(tw, axis=-1, keepdims=True)
    ident = np.zeros_like(tw)
    ident[..., 0] = 1.0
    tw = np.where(n < 1e-9, ident, tw / np.maximum(n, _EPS))
    angle = 2.0 * np.arctan2(np.sum(tw[..., 1:] * axis, -1), tw[..., 0])
    angle = np.where(angle > np.pi, angle - 2 * np.pi, angle)
    angle = np.where(angle <= -np.pi, angle + 2 * np.pi, angle)
    sw = quat_mul(q, quat_conj(tw))
    return sw, tw, angle


def twist_angle(R, axis):
    """Twist angle (radians, (-pi, pi]) of rotation matrices ``R`` about ``axis``."""
    return swing_twist(matrix_to_quat(R), axis)[2]


def rotation_between(a, b):
    """Minimal rotation matrices taking unit(``a``) to unit(``b``), ``(..., 3)`` → ``(..., 3, 3)``.

    For antiparallel inputs a half-turn about an arbitrary axis perpendicular
    to ``a`` is returned (finite, never NaN).
    """
    a = normalize(a)
    b = normalize(b)
    a, b = np.broadcast_arrays(a, b)
    c = np.cross(a, b)
    d = np.sum(a * b, -1)
    # quaternion (1 + d, c) normalised is the half-way rotation
    q = np.concatenate([(1.0 + d)[..., None], c], -1)
    bad = (1.0 + d) < 1e-10
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
