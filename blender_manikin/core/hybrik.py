"""HybrIK twist-and-swing IK for the 22-joint body, with biomechanical limbs.

Li et al., "HybrIK: A Hybrid Analytical-Neural Inverse Kinematics Solution
for 3D Human Pose and Shape Estimation", CVPR 2021, eqs. 6-10 and
Algorithms 1-2.  Turns joint positions ``(T, 22, 3)`` (metres, Blender axes)
into local rotations ``(T, 22, 3, 3)`` of a :class:`~.skeleton.Body`.

Joints are visited parents-first.  For joint ``j`` with parent world
rotation ``R_p`` (already reconstructed):

* one child ``c``: ``R_local = swing(o_c → R_pᵀ t) @ Rot(o_c, τ_j)`` where
  ``o_c`` is the rest offset, ``t`` the target bone vector and ``τ_j`` the
  optional twist angle (default 0) (HybrIK eqs. 6-10);
* several children (pelvis, spine3): the rotation best aligning all rest
  offsets with the target vectors (weighted Kabsch / SVD, as HybrIK does for
  its multi-child joints);
* no child (head, wrists, feet): the given world orientation, else identity;
* limbs (shoulder-elbow-wrist, hip-knee-ankle) go through
  :func:`.limb_solver.solve_limbs`, so elbows and knees come out as hinges
  within limits, with the swivel measured from the target mid joint.

**Naive** IK takes target vectors between *input* positions
(``t = p_c - p_j``), so errors in the input accumulate down the chain.
**Adaptive** IK (HybrIK Algorithm 2) takes ``t = p_c - p̂_j`` from the
*reconstructed* position ``p̂_j`` of the joint, so each bone points at its
target from where the chain actually is and errors do not accumulate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rotations as rot
from . import limb_solver as ls
from .skeleton import (Body, CHILDREN, J, LIMBS, NUM_JOINTS, PARENTS,
                       forward_kinematics)

_LIMB_OF_BASE = {b: i for i, (_, b, _, _) in enumerate(LIMBS)}
_LIMB_MIDS = {m for _, _, m, _ in LIMBS}


@dataclass
class IKResult:
    """local_rot ``(T, 22, 3, 3)``; root_pos ``(T, 3)`` metres; swivel ``(T, 4)``
    radians (LIMB_NAMES order); reach_error ``(T, 4)`` metres;
    positions / world_rot: FK of the result."""
    local_rot: np.ndarray
    root_pos: np.ndarray
    swivel: np.ndarray
    reach_error: np.ndarray
    positions: np.ndarray
    world_rot: np.ndarray


def kabsch(rest_vecs, target_vecs, weights=None, directions=True):
    """Rotations ``R`` ``(T, 3, 3)`` minimising ``Σ w |R r_i - t_i|²``.

    rest_vecs: ``(K, 3)`` or ``(T, K, 3)``; target_vecs: ``(T, K, 3)``.
    directions: normalise the vectors first, so only directions count (False: lengths weigh
    too, as for centred point sets).
    """
    t = np.asarray(target_vecs, np.float64)
    r = np.broadcast_to(rest_vecs, t.shape)
    if directions:
        t, r = rot.normalize(t), rot.normalize(r)
    w = np.ones(t.shape[-2]) if weights is None else np.asarray(weights, np.float64)
    H = np.einsum("tki,tkj,k->tij", t, r, w)           # sum w t r^T
    U, _, Vt = np.linalg.svd(H)
    d = np.linalg.det(U @ Vt)
    D = np.ones(U.shape[:-1])
    D[:, -1] = d
    return (U * D[:, None, :]) @ Vt


def ik_from_positions(positions, body: Body, end_rot=None, twists=None, adaptive=True,
                      base_rot=None, swivel=None, aim_chain=False, within_limits=False, straight=None):
    """Local rotations reproducing ``positions`` with the bone lengths of ``body``.

    positions: ``(T, 22, 3)`` target joint positions, metres, Blender axes.
    end_rot: optional dict ``joint index -> (T, 3, 3)`` world orientations for
    leaf / end joints (head, wrists, ankles, pelvis); a pelvis orientation
    replaces the Kabsch fit of the root.
    twists: optional ``(T, 22)`` twist angles (radians) of single-child joints.
    base_rot: optional dict ``limb base joint -> (T, 3, 3)`` source world
    rotations used only to define the swivel of straight limbs.
    swivel: optional ``(T, 4)`` swivel angles overriding the ones measured
    from the mid joints.
    adaptive: HybrIK Algorithm 2 (True) or naive (False).
    aim_chain: limbs as HybrIK's chain (for noisy positions, e.g. keypoints): the upper bone aims
    at the mid joint's position, the lower bone from there at the end's, and the limb solver puts
    the end where that chain ends (elbow / knee on their positions' directions, the hand / foot
    within the positions' bone-length noise of its own); False (mocap, training targets): the
    end lands exactly on its position and the mid joint on its swivel circle.
    within_limits: the swivel of a limb that would turn the shoulder / hip about its own axis
    beyond its range is moved to the limit (:func:`.limb_solver.solve_limbs_within_limits`).
    straight: noisy positions' nearly straight limbs take the reference swivel
    (:func:`.limb_solver.swivel_from_positions`, :data:`.limb_solver.STRAIGHT_NOISY` for
    keypoints); None: the swivel follows the mid joint however little the limb bends.
    """
    P = np.asarray(positions, np.float64)
    if P.ndim != 3 or P.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f"positions must be (T, 22, 3), got {P.shape}")
    if not np.isfinite(P).all():
        bad = np.unique(np.nonzero(~np.isfinite(P))[0])
        raise ValueError(f"positions contain NaN/inf at frames {bad[:10].tolist()}")
    T = P.shape[0]
    end_rot = {} if end_rot is None else end_rot
    base_rot = {} if base_rot is None else base_rot
    off = body.offsets
    local = np.broadcast_to(np.eye(3), (T, NUM_JOINTS, 3, 3)).copy()
    world = np.empty((T, NUM_JOINTS, 3, 3))
    recon = np.empty((T, NUM_JOINTS, 3))
    swiv = np.zeros((T, 4))
    reach = np.zeros((T, 4))
    done = np.zeros(NUM_JOINTS, bool)

    def src(j):
        return recon[:, j] if adaptive else P[:, j]

    # root
    root = J["pelvis"]
    recon[:, root] = P[:, root]
    if root in end_rot:
        world[:, root] = end_rot[root]
    else:
        ch = CHILDREN[root]
        world[:, root] = kabsch(off[list(ch)], P[:, list(ch)] - P[:, root:root + 1])
    local[:, root] = world[:, root]
    done[root] = True

    for j in range(1, NUM_JOINTS):
        if done[j]:
            continue
        p = PARENTS[j]
        Rp = world[:, p]
        recon[:, j] = recon[:, p] + np.einsum("tij,j->ti", Rp, off[j])
        if j in _LIMB_OF_BASE:
            li = _LIMB_OF_BASE[j]
            _, b, m, e = LIMBS[li]
            base_p = src(b)
            l1, l2 = np.linalg.norm(off[m]), np.linalg.norm(off[e])
            mid_t, end_t = P[:, m], P[:, e]
            if aim_chain:       # the chain's own mid and end: each bone along its positions' direction
                mid_t = base_p + l1 * rot.normalize(P[:, m] - base_p)
                end_t = mid_t + l2 * rot.normalize(P[:, e] - (mid_t if adaptive else P[:, m]))
            phi = ls.swivel_from_positions(base_p[:, None], mid_t[:, None], end_t[:, None],
                                           Rp[:, None], [li],
                                           base_rot=None if b not in base_rot else base_rot[b][:, None],
                                           straight=straight)[:, 0]
            if swivel is not None:
                phi = np.asarray(swivel, np.float64)[:, li]
            er = end_rot.get(e)
            args = (recon[:, b][:, None] if adaptive else base_p[:, None], end_t[:, None], phi[:, None],
                    np.array([[l1, l2]]), Rp[:, None])
            if within_limits:
                sol, used = ls.solve_limbs_within_limits(*args, end_rot=None if er is None else er[:, None],
                                                         limb_ids=[li])
                phi = used[:, 0]
            else:
                sol = ls.solve_limbs(*args, end_rot=None if er is None else er[:, None],
                                     limb_ids=[li], clamp_twist=True)
            swiv[:, li] = phi
            reach[:, li] = sol.reach_error[:, 0]
            local[:, b] = sol.base_local[:, 0]
            world[:, b] = sol.base_world[:, 0]
            local[:, m] = sol.mid_local[:, 0]
            world[:, m] = sol.mid_world[:, 0]
            recon[:, m] = recon[:, b] + np.einsum("tij,j->ti", world[:, b], off[m])
            done[b] = done[m] = True
            if er is not None:
                local[:, e] = sol.end_local[:, 0]
                world[:, e] = world[:, m] @ local[:, e]
                recon[:, e] = recon[:, m] + np.einsum("tij,j->ti", world[:, m], off[e])
                done[e] = True
            continue
        if j in _LIMB_MIDS:
            continue  # handled with its base
        ch = CHILDREN[j]
        if len(ch) == 0 or j in end_rot:
            if j in end_rot:
                local[:, j] = np.swapaxes(Rp, -1, -2) @ end_rot[j]
        elif len(ch) == 1:
            c = ch[0]
            t = P[:, c] - src(j)
            t_par = np.einsum("tji,tj->ti", Rp, t)
            R = rot.rotation_between(np.broadcast_to(off[c], t_par.shape), t_par)
            if twists is not None:
                R = R @ rot.axis_angle_rotation(np.broadcast_to(off[c], t_par.shape),
                                                np.asarray(twists, np.float64)[:, j])
            local[:, j] = R
        else:
            t = P[:, list(ch)] - src(j)[:, None]
            t_par = np.einsum("tji,tkj->tki", Rp, t)
            local[:, j] = kabsch(off[list(ch)], t_par)
        world[:, j] = Rp @ local[:, j]
        done[j] = True

    pos, wrot = forward_kinematics(local, P[:, root], body)
    return IKResult(local_rot=local, root_pos=P[:, root].copy(), swivel=swiv, reach_error=reach,
                    positions=pos, world_rot=wrot)
