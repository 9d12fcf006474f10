"""Differentiable geometry in torch, mirroring the numpy core.

Every function here is the torch twin of a numpy function in
``blender_manikin.core`` (same conventions, same formulas) and is tested to
agree with it to 1e-5 on random inputs (``tests/test_training.py``):

=============================  =========================================
torch (this module)            numpy
=============================  =========================================
:func:`sixd_to_matrix`         ``rotations.sixd_to_matrix``
:func:`matrix_to_6d`           ``rotations.matrix_to_6d``
:func:`quat_to_matrix`         ``rotations.quat_to_matrix``
:func:`rotation_between`       ``rotations.rotation_between``
:func:`swivel_frame`           ``limb_solver.swivel_frame``
:func:`mid_from_swivel`        ``limb_solver.mid_from_swivel`` (eq. 7)
:func:`torso_fk`               ``skeleton.forward_kinematics`` on the torso
:func:`full_fk`                ``skeleton.forward_kinematics``
=============================  =========================================

Everything is batched over arbitrary leading dimensions and finite for any
finite input (NaN-free gradients too: every normalisation is clamped).
"""
from __future__ import annotations

import numpy as np
import torch

from ..core import limb_solver as _ls
from ..core.features import TORSO_LOCAL_IDX
from ..core.skeleton import J, NUM_JOINTS, PARENTS

_EPS = 1e-12


def _unit(v, eps=_EPS):
    return v / torch.linalg.vector_norm(v, dim=-1, keepdim=True).clamp_min(eps)


def _dot(a, b):
    return (a * b).sum(-1)


def _const(a, like):
    return torch.as_tensor(np.asarray(a), dtype=like.dtype, device=like.device)


def matrix_to_6d(m):
    """``(..., 3, 3)`` -> ``(..., 6)``: first column, then second column."""
    return torch.cat([m[..., :, 0], m[..., :, 1]], -1)


def sixd_to_matrix(d6):
    """``(..., 6)`` -> ``(..., 3, 3)`` by Gram-Schmidt (Zhou et al. 2019)."""
    a = _unit(d6[..., :3])
    b2 = d6[..., 3:]
    b = _unit(b2 - _dot(a, b2)[..., None] * a)
    c = torch.cross(a, b, dim=-1)
    return torch.stack([a, b, c], -1)


def quat_to_matrix(q):
    """``(..., 4)`` wxyz (need not be unit) -> ``(..., 3, 3)``."""
    q = _unit(q)
    w, x, y, z = q.unbind(-1)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = [torch.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], -1),
            torch.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], -1),
            torch.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], -1)]
    return torch.stack(rows, -2)


def rotation_between(a, b):
    """Minimal rotations taking unit(``a``) to unit(``b``) (``(..., 3)`` -> ``(..., 3, 3)``).

    Antiparallel inputs get a half-turn about an axis perpendicular to ``a``
    (the same axis as the numpy version picks).
    """
    a, b = torch.broadcast_tensors(_unit(a), _unit(b))
    c = torch.cross(a, b, dim=-1)
    d = _dot(a, b)
    q = torch.cat([(1.0 + d)[..., None], c], -1)
    bad = (1.0 + d) < 1e-10
    ex = torch.zeros_like(a)
    ex[..., 0] = 1.0
    ey = torch.zeros_like(a)
    ey[..., 1] = 1.0
    helper = torch.where((a[..., :1].abs() < 0.9), ex, ey)
    perp = _unit(torch.cross(a, helper, dim=-1))
    q_bad = torch.cat([torch.zeros_like(d)[..., None], perp], -1)
    q = torch.where(bad[..., None], q_bad, q)
    return quat_to_matrix(q)


def _mv(R, v):
    """``R @ v`` for ``(..., 3, 3)`` and ``(..., 3)``."""
    return (R * v[..., None, :]).sum(-1)


def _mtv(R, v):
    """``Rᵀ @ v``."""
    return (R * v[..., :, None]).sum(-2)


def swivel_frame(base_pos, end_pos, parent_rot, limb_ids=None):
    """Torch :func:`limb_solver.swivel_frame`: ``(n, u, v, d)``.

    base_pos, end_pos ``(..., L, 3)``; parent_rot ``(..., L, 3, 3)``;
    ``limb_ids`` picks the L limbs (default all four, LIMBS order).
    """
    ids = np.arange(4) if limb_ids is None else np.asarray(limb_ids, int)
    n0 = _const(_ls.N0[ids], base_pos)
    u0 = _const(_ls.U0[ids], base_pos)
    diff = end_pos - base_pos
    d = torch.linalg.vector_norm(diff, dim=-1)
    n0b = n0.expand(diff.shape)
    n_fallback = _mv(parent_rot, n0b)
    n = torch.where((d > 1e-9)[..., None], diff / d.clamp_min(1e-12)[..., None], n_fallback)
    n_par = _mtv(parent_rot, n)
    swing = rotation_between(n0b, n_par)
    u_par = _mv(swing, u0.expand(n_par.shape))
    u = _mv(parent_rot, u_par)
    u = _unit(u - _dot(u, n)[..., None] * n)
    v = torch.cross(n, u, dim=-1)
    return n, u, v, d


def _safe_sqrt(x, eps=1e-6):
    """``sqrt(x)`` (x >= 0) whose derivative is capped at ``0.5 / sqrt(eps)``."""
    y = torch.sqrt(x.detach())
    if not x.requires_grad:
        return y
    g = 0.5 / torch.sqrt(x.detach().clamp_min(eps))
    return y + (x - x.detach()) * g


def mid_from_swivel(base_pos, end_pos, swivel, lengths, parent_rot, limb_ids=None):
    """Torch :func:`limb_solver.mid_from_swivel` (MANIKIN eq. 7).

    swivel: ``(..., L)`` angles in radians, or ``(..., L, 2)`` (cos, sin)
    pairs (normalised here, as MANIKIN does with the network's output).
    lengths: broadcastable to ``(..., L, 2)`` upper/lower segment lengths.
    The base-end distance is clamped to the reachable range first.
    """
    ids = np.arange(4) if limb_ids is None else np.asarray(limb_ids, int)
    n, u, v, d = swivel_frame(base_pos, end_pos, parent_rot, ids)
    lengths = lengths.expand(n.shape[:-1] + (2,))
    l1, l2 = lengths[..., 0], lengths[..., 1]
    flex_max = _const(_ls.FLEX_MAX[ids], d)
    d_min = torch.sqrt((l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * torch.cos(flex_max)).clamp_min(0.0)).clamp_min(1e-6)
    dc = torch.minimum(torch.maximum(d, d_min), l1 + l2)
    cos_a = ((l1 ** 2 + dc ** 2 - l2 ** 2) / (2 * l1 * dc)).clamp(-1.0, 1.0)
    # sin α from Heron's formula: exact zero for a straight limb even in float32
    # (1 - cos² loses ~1e-4 m there); the gradient of the square root is
    # capped within ~0.1° of straight, where the geometry's own derivative diverges
    heron = ((l1 + l2 + dc) * (l2 + dc - l1) * (l1 + l2 - dc) * (l1 + dc - l2)).clamp_min(0.0)
    sin_a = (_safe_sqrt(heron) / (2 * l1 * dc)).clamp(0.0, 1.0)
    if swivel.dim() == n.dim():            # (cos, sin) pairs
        cs = _unit(swivel, 1e-6)
        c, s = cs[..., 0], cs[..., 1]
    else:
        c, s = torch.cos(swivel), torch.sin(swivel)
    u_phi = c[..., None] * u + s[..., None] * v
    return base_pos + (l1 * cos_a)[..., None] * n + (l1 * sin_a)[..., None] * u_phi


# --------------------------------------------------------------------------
# forward kinematics
#: joints whose positions torso FK yields (pelvis, hips, spine, neck, collars,
#: head, shoulders), in this order
TORSO_FK_JOINTS = (J["pelvis"], J["left_hip"], J["right_hip"], J["spine1"], J["spine2"],
                   J["spine3"], J["neck"], J["left_collar"], J["right_collar"], J["head"],
                   J["left_shoulder"], J["right_shoulder"])
#: joints whose world rotations torso FK yields
TORSO_ROT_JOINTS = (J["pelvis"],) + tuple(TORSO_LOCAL_IDX)


def torso_fk(root_rot, torso_local, offsets):
    """Torso forward kinematics relative to the head joint.

    root_rot ``(..., 3, 3)`` pelvis world orientation; torso_local
    ``(..., 6, 3, 3)`` local rotations of ``features.TORSO_LOCAL`` (spine1,
    spine2, spine3, neck, left_collar, right_collar); offsets broadcastable
    to ``(..., 22, 3)`` rest offsets (per-sample bodies).  Returns
    ``(pos, rot)``: ``pos`` ``(..., 12, 3)`` positions of
    :data:`TORSO_FK_JOINTS` minus the head position (so the head is 0), and
    ``rot`` dict joint index -> ``(..., 3, 3)`` world rotation for
    :data:`TORSO_ROT_JOINTS`.  The head's own orientation does not move any
    of these joints, so it is not needed.
    """
    lead = root_rot.shape[:-2]
    offsets = offsets.expand(lead + (NUM_JOINTS, 3))
    local = {J["pelvis"]: root_rot}
    for k, j in enumerate(TORSO_LOCAL_IDX):
        local[j] = torso_local[..., k, :, :]
    rot, pos = {}, {}
    pos[0] = torch.zeros_like(offsets[..., 0, :])
    rot[0] = root_rot
    for j in (J["left_hip"], J["right_hip"], J["spine1"], J["spine2"], J["spine3"], J["neck"],
              J["left_collar"], J["right_collar"], J["head"], J["left_shoulder"], J["right_shoulder"]):
        p = int(PARENTS[j])
        pos[j] = pos[p] + _mv(rot[p], offsets[..., j, :])
        if j in local:
            rot[j] = rot[p] @ local[j]
    head = pos[J["head"]]
    out = torch.stack([pos[j] - head for j in TORSO_FK_JOINTS], -2)
    return out, {j: rot[j] for j in TORSO_ROT_JOINTS}


def full_fk(root_rot, local_rot, offsets):
    """Full FK with the pelvis at the origin.

    root_rot ``(..., 3, 3)``; local_rot ``(..., 21, 3, 3)`` for joints 1..21;
    offsets broadcastable to ``(..., 22, 3)``.  Returns ``(pos (..., 22, 3),
    world_rot (..., 22, 3, 3))``; add the pelvis position to place it.
    """
    lead = root_rot.shape[:-2]
    offsets = offsets.expand(lead + (NUM_JOINTS, 3))
    pos = [torch.zeros_like(offsets[..., 0, :])]
    rot = [root_rot]
    for j in range(1, NUM_JOINTS):
        p = int(PARENTS[j])
        pos.append(pos[p] + _mv(rot[p], offsets[..., j, :]))
        rot.append(rot[p] @ local_rot[..., j - 1, :, :])
    return torch.stack(pos, -2), torch.stack(rot, -3)
