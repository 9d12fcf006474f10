"""Analytic limb solver: swivel angles and exact two-bone IK with hinge limits.

MANIKIN (Jiang et al., ECCV 2024), equations 2-14, batched over frames and
vectorised over limbs.  A limb is (base, mid, end) = (shoulder, elbow, wrist)
or (hip, knee, ankle); see :data:`skeleton.LIMBS`.  Arrays carry a leading
``(T, L)`` shape: T frames, L limbs (``limb_ids`` picks which of the four).

Swivel angle
------------
``n`` is the unit base→end axis.  The zero-swivel direction ``u`` is a
body-fixed reference carried along with the limb by the *minimal swing* from
a neutral axis ``n0`` to ``n`` (both in the frame of the limb's parent joint:
collar for arms, pelvis for legs)::

    u = R_par @ swing(n0 → R_parᵀ n) @ u0,      v = n × u
    φ = atan2(v·(p_mid − p_base), u·(p_mid − p_base))          (eq. 5)
    p_mid = p_base + l1 cos α n + l1 sin α (cos φ u + sin φ v)  (eqs. 3, 4, 7)

``n0`` points lateral-forward-down for arms and down (11° forward) for legs,
so the only direction where ``u`` is undefined (``n = -n0``: wrist behind the
head on the other side, ankle above the hip behind the body) is outside the
human range of motion and φ is continuous through ordinary motion.  ``u0`` is
the natural mid-joint direction, so **φ = 0 means "elbow out, back and down"
and "knee forward"**; positive φ turns the mid joint right-handedly about
``n`` (for the left arm, from out-back-down towards up-back).  In the
parent's rest frame (Blender axes, body facing -Y):

=========  =====================  ==========================
limb       n0                     u0
=========  =====================  ==========================
left arm   (1, -1, -1)/√3         (1, 2, -1)/√6
right arm  (-1, -1, -1)/√3        (-1, 2, -1)/√6
legs       (0, -0.2, -1)/|.|      (0, -1, -0.2)/|.|
=========  =====================  ==========================

Rotations
---------
Rest limbs are straight along ``a0`` (arms ±X, legs -Z).  The mid joint is a
1-DoF hinge about ``h0`` in its local frame (elbows -Z / +Z for left / right,
knees +X) with flexion θ = π - interior angle (eq. 9).  The bend plane's
normal in the world is ``h = u_φ × n`` with ``u_φ = cos φ u + sin φ v``, which
stays defined for a straight limb, so the base rotation (swing and twist,
eqs. 10-12, built here in closed form as a change of frame) is::

    R_base_world = [a, h, a×h] [a0, h0, a0×h0]ᵀ,   a = (p_mid − p_base)/l1
    R_mid_local  = Rot(h0, θ) Rot(a0, τ)          (τ: elbow twist, arms only)
    R_end_local  = (R_base_world Rot(h0, θ) Rot(a0, τ))ᵀ R_end_world

τ is the twist of the wrist orientation about the forearm axis (eq. 13, the
pronation part), clamped to the forearm's range; the wrist keeps the swing
(eq. 14) and any excess twist, so the hand orientation is always exact.

Limits (degrees)
----------------
Elbow flexion 0-160, knee 0-145: the passive ranges (AAOS, Greene & Heckman 1994: elbow
0-150 active, about 10° more passive, where the forearm meets the upper arm; knee 0-135
active, ~145 passive).  The elbow's passive 160° matters where a player holds a controller at
the shoulder: on the shared Beat Saber replays a 150° elbow left a hand off its controller on
43.8 % and 13.7 % of the frames, 160° on 6.3 % and 3.5 % (``benchmarks/bench_plausibility.py``);
the mocap benchmarks never reach past 150° and do not move.  Forearm pronation 80 / supination 80
from the T-pose neutral (palm down, elbow crease forward; AAOS).  Shoulder
internal/external rotation 70/90 (+20 passive, widening above 60° of arm
elevation) and hip 45/45 (AAOS) are measured clinically, from the limb
hanging down with the forearm forward / knee cap forward, carried by the
minimal swing to the bone's direction (:func:`axial_rotation`,
:func:`axial_range`); :func:`solve_limbs_within_limits` enforces them by
moving the swivel, so the hand or foot never moves.  Hinge limits are enforced by clamping the
base-end distance to ``[d_min, l1 + l2]``: a target out of reach gets a
fully extended limb pointing at it and its distance in ``reach_error``; a
target too close gets the most-flexed elbow/knee.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rotations as rot
from .skeleton import LIMBS, PARENTS

_S3 = np.sqrt(3.0)
_S6 = np.sqrt(6.0)

#: rest direction of the upper segment (= lower segment), per limb, unit
A0 = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 0, -1.0], [0, 0, -1.0]])
#: hinge axis in the mid joint's local frame; +θ bends the limb
H0 = np.array([[0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0], [1.0, 0, 0]])
#: neutral base→end axis (parent frame) and its zero-swivel mid direction
N0 = rot.normalize(np.array([[1.0, -1, -1], [-1.0, -1, -1], [0, -0.2, -1], [0, -0.2, -1]]))
U0 = rot.normalize(np.array([[1.0, 2, -1], [-1.0, 2, -1], [0, -1, -0.2], [0, -1, -0.2]]))
#: maximum flexion of the hinge (elbow 160°, knee 145°: passive ranges), radians
FLEX_MAX = np.radians([160.0, 160.0, 145.0, 145.0])
#: twist about the forearm: (min, max) radians, arms only (legs 0)
#: pronation is +about +X for the left arm and -about -X for the right.
TWIST_RANGE = np.radians([[-80.0, 80.0], [-80.0, 80.0], [0.0, 0.0], [0.0, 0.0]])
#: sign that turns a twist about a0 into "pronation positive"
PRONATION_SIGN = np.array([1.0, -1.0, 0.0, 0.0])
#: axial rotation limits of the base (internal, external), radians: shoulders, hips (AAOS,
#: Greene & Heckman 1994); see :func:`axial_range` for how the shoulders' depend on elevation
BASE_TWIST_RANGE = np.radians([[70.0, 90.0], [70.0, 90.0], [45.0, 45.0], [45.0, 45.0]])
#: added to both shoulder limits (passive range beyond the active clinical one), radians
SHOULDER_PASSIVE_MARGIN = np.radians(20.0)
#: arm elevation (radians) where the shoulder's axial limit starts to widen, and where it is gone
SHOULDER_FADE_ELEVATION = np.radians([60.0, 120.0])
#: thigh elevation (radians) where the hip's axial limit starts to widen, and where it is gone:
#: past the hip's flexion range (a thigh raised towards the chest, legs up while lying down) the
#: measure nears its singularity (undefined straight up) and turns quickly with small motions
HIP_FADE_ELEVATION = np.radians([130.0, 165.0])
#: neutral pose for measuring axial rotation, parent frame: bone hanging down, hinge flexing
#: the forearm forward (arms) / the shin backward (legs)
AXIAL_NEUTRAL_BONE = np.array([[0, 0, -1.0]] * 4)
AXIAL_NEUTRAL_FLEX = np.array([[0, -1.0, 0], [0, -1.0, 0], [0, 1.0, 0], [0, 1.0, 0]])
#: sign taking a rotation about the bone (right-handed) to "internal rotation positive"
INTERNAL_SIGN = np.array([1.0, -1.0, 1.0, -1.0])

LIMB_BASE = np.array([b for _, b, _, _ in LIMBS])
LIMB_MID = np.array([m for _, _, m, _ in LIMBS])
LIMB_END = np.array([e for _, _, _, e in LIMBS])
LIMB_PARENT = PARENTS[LIMB_BASE]


def _ids(limb_ids):
    return np.arange(4) if limb_ids is None else np.asarray(limb_ids, dtype=int)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def swivel_frame(base_pos, end_pos, parent_rot, limb_ids=None):
    """Unit axis and zero-swivel basis of each limb.

    base_pos, end_pos: ``(..., L, 3)`` metres; parent_rot: ``(..., L, 3, 3)``
    world rotation of the limb's parent joint.  Returns ``(n, u, v, d)`` with
    ``n, u, v`` ``(..., L, 3)`` orthonormal (``v = n × u``) and the base-end
    distance ``d`` ``(..., L)``.  When base and end coincide ``n`` falls
    back to the neutral axis ``R_par n0``.
    """
    ids = _ids(limb_ids)
    base_pos = np.asarray(base_pos, np.float64)
    end_pos = np.asarray(end_pos, np.float64)
    parent_rot = np.asarray(parent_rot, np.float64)
    diff = end_pos - base_pos
    d = np.linalg.norm(diff, axis=-1)
    n0 = N0[ids]
    n_fallback = np.einsum("...ij,...j->...i", parent_rot, np.broadcast_to(n0, diff.shape))
    n = np.where((d > 1e-9)[..., None], diff / np.maximum(d, 1e-12)[..., None], n_fallback)
    n_par = np.einsum("...ji,...j->...i", parent_rot, n)
    swing = rot.rotation_between(np.broadcast_to(n0, n_par.shape), n_par)
    u_par = np.einsum("...ij,...j->...i", swing, np.broadcast_to(U0[ids], n_par.shape))
    u = np.einsum("...ij,...j->...i", parent_rot, u_par)
    u = rot.normalize(u - _dot(u, n)[..., None] * n)
    v = np.cross(n, u)
    return n, u, v, d


#: :func:`swivel_from_positions` ``straight`` for keypoints: a limb whose mid joint is within
#: about 8 % of the upper bone of the base-end axis (bent less than about 9°) takes the reference
#: swivel.  Keypoints' noise (mm to cm) puts a straight limb's mid joint off the axis in a random
#: direction, and that direction alone set the swivel: on the bundled example's T-pose the
#: shoulders turned up to 144° about the arm from frame to frame and the hips to the 45° limit
#: (the knee caps sideways); with it the shoulders stay within 8° and the hips within 13°, the
#: joints' positions unchanged (tests/test_keypoints.py)
STRAIGHT_NOISY = 0.08


def swivel_from_positions(base_pos, mid_pos, end_pos, parent_rot, limb_ids=None, base_rot=None,
                          straight=None):
    """Swivel angles φ ``(..., L)`` radians in (-π, π] from joint positions (eq. 5).

    For a straight limb φ does not move any joint and is ill-defined from
    positions; a reference hinge axis resolves it, with a weight that fades
    in only as the limb straightens (bent limbs are unaffected to ~1e-3 rad
    (angle change below 1e-9 / sin(flexion) rad).  The reference is
    the hinge of ``base_rot`` (``(..., L, 3, 3)`` world rotation of the base
    joint, e.g. from mocap) when given, else the hinge of the zero-twist
    swing of the base out of the rest pose, so a straight T-pose limb gets
    the rest-pose swivel and identity rotations.

    straight: for noisy positions (keypoints), where a straight limb's mid joint is off the
    base-end axis by the noise and its direction off the axis is noise: the mid joint's offset
    from the axis, in upper-bone lengths, below which the reference takes over (its weight
    ``straight * exp(-(offset / straight)²)``, negligible from twice that offset on;
    :data:`STRAIGHT_NOISY`).  None: exact positions (the 1e-9 weight above).
    """
    ids = _ids(limb_ids)
    n, u, v, d = swivel_frame(base_pos, end_pos, parent_rot, ids)
    w = np.asarray(mid_pos, np.float64) - np.asarray(base_pos, np.float64)
    l1 = np.linalg.norm(w, axis=-1)
    perp = w - _dot(w, n)[..., None] * n
    if base_rot is not None:
        h = np.einsum("...ij,...j->...i", np.asarray(base_rot, np.float64),
                      np.broadcast_to(H0[ids], n.shape))
    else:
        parent_rot = np.asarray(parent_rot, np.float64)
        n_par = np.einsum("...ji,...j->...i", parent_rot, n)
        swing = rot.rotation_between(np.broadcast_to(A0[ids], n_par.shape), n_par)
        h = np.einsum("...ij,...j->...i", parent_rot @ swing, np.broadcast_to(H0[ids], n.shape))
    # the mid joint bends towards u_phi = n x h (see module docstring)
    ref = rot.normalize(np.cross(n, h))
    weight = 1e-9
    if straight:
        off = np.linalg.norm(perp, axis=-1) / np.maximum(l1, 1e-12)
        weight = np.maximum(straight * np.exp(-(off / straight) ** 2), 1e-9)[..., None]
    perp = perp + weight * l1[..., None] * ref
    return np.arctan2(_dot(perp, v), _dot(perp, u))


def mid_from_swivel(base_pos, end_pos, swivel, lengths, parent_rot, limb_ids=None):
    """Mid-joint positions ``(..., L, 3)`` on the swivel circle (eq. 7).

    lengths: ``(..., L, 2)`` or ``(L, 2)`` upper and lower segment lengths.
    The base-end distance is clamped to the reachable range first (see
    :func:`solve_limbs`).
    """
    ids = _ids(limb_ids)
    n, u, v, d = swivel_frame(base_pos, end_pos, parent_rot, ids)
    l1, l2 = _lengths(lengths, n.shape[:-1])
    dc = _clamp_reach(d, l1, l2, FLEX_MAX[ids])
    cos_a = np.clip((l1 ** 2 + dc ** 2 - l2 ** 2) / (2 * l1 * dc), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a ** 2)
    swivel = np.asarray(swivel, np.float64)
    u_phi = np.cos(swivel)[..., None] * u + np.sin(swivel)[..., None] * v
    return np.asarray(base_pos) + (l1 * cos_a)[..., None] * n + (l1 * sin_a)[..., None] * u_phi


def _lengths(lengths, shape):
    lengths = np.asarray(lengths, np.float64)
    lengths = np.broadcast_to(lengths, shape + (2,))
    return lengths[..., 0], lengths[..., 1]


def _clamp_reach(d, l1, l2, flex_max):
    d_min = np.sqrt(np.maximum(l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * np.cos(flex_max), 0.0))
    d_min = np.maximum(d_min, 1e-6)
    return np.clip(d, d_min, l1 + l2)


def _check_finite(**arrays):
    for name, a in arrays.items():
        if a is None:
            continue
        a = np.asarray(a)
        if not np.isfinite(a).all():
            frames = np.unique(np.nonzero(~np.isfinite(a))[0])
            raise ValueError(f"limb solver input '{name}' contains NaN/inf at frame(s) "
                             f"{frames[:10].tolist()}; bridge tracking gaps before solving")


@dataclass
class LimbSolution:
    """Result of :func:`solve_limbs`; every array has leading shape ``(T, L)``.

    base_local, mid_local, end_local: ``(T, L, 3, 3)`` local rotations of the
    base, mid and end joints (parent frame).  base_world, mid_world:
    world rotations.  mid_pos, end_pos: ``(T, L, 3)`` reached positions
    (metres).  flexion: hinge angle θ (radians, ``[0, FLEX_MAX]``).
    elbow_twist: τ (radians, 0 for legs).  reach_error: distance from the
    requested to the reached end position (metres; 0 when reachable).
    """
    base_local: np.ndarray
    mid_local: np.ndarray
    end_local: np.ndarray | None
    base_world: np.ndarray
    mid_world: np.ndarray
    mid_pos: np.ndarray
    end_pos: np.ndarray
    flexion: np.ndarray
    elbow_twist: np.ndarray
    reach_error: np.ndarray
    swivel: np.ndarray


def solve_limbs(base_pos, end_pos, swivel, lengths, parent_rot, end_rot=None, limb_ids=None,
                clamp_twist=True):
    """Exact analytic IK of two-bone limbs (eqs. 7, 9-14).

    base_pos: ``(T, L, 3)`` base joint world positions (from torso FK), metres.
    end_pos: ``(T, L, 3)`` end-effector targets (wrist / ankle joint), metres.
    swivel: ``(T, L)`` radians.
    lengths: ``(L, 2)`` or ``(T, L, 2)`` upper/lower lengths, metres.
    parent_rot: ``(T, L, 3, 3)`` world rotation of the base's parent joint.
    end_rot: optional ``(T, L, 3, 3)`` world orientation wanted for the end
    joint; without it the elbow twist is 0 and ``end_local`` is None.
    Returns a :class:`LimbSolution`.  Finite for any finite input.
    """
    ids = _ids(limb_ids)
    base_pos = np.asarray(base_pos, np.float64)
    end_pos = np.asarray(end_pos, np.float64)
    parent_rot = np.asarray(parent_rot, np.float64)
    swivel = np.asarray(swivel, np.float64)
    _check_finite(base_pos=base_pos, end_pos=end_pos, swivel=swivel, parent_rot=parent_rot,
                  end_rot=end_rot)
    n, u, v, d = swivel_frame(base_pos, end_pos, parent_rot, ids)
    l1, l2 = _lengths(lengths, d.shape)
    flex_max = FLEX_MAX[ids]
    dc = _clamp_reach(d, l1, l2, flex_max)
    end_reached = base_pos + dc[..., None] * n
    reach_error = np.abs(d - dc)

    cos_a = np.clip((l1 ** 2 + dc ** 2 - l2 ** 2) / (2 * l1 * dc), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a ** 2)
    u_phi = np.cos(swivel)[..., None] * u + np.sin(swivel)[..., None] * v
    a = cos_a[..., None] * n + sin_a[..., None] * u_phi          # unit upper-segment direction
    mid_pos = base_pos + l1[..., None] * a
    cos_g = np.clip((l1 ** 2 + l2 ** 2 - dc ** 2) / (2 * l1 * l2), -1.0, 1.0)
    flexion = np.clip(np.pi - np.arccos(cos_g), 0.0, flex_max)   # eq. 9

    h = np.cross(u_phi, n)                                        # hinge axis, world
    a0 = np.broadcast_to(A0[ids], a.shape)
    h0 = np.broadcast_to(H0[ids], a.shape)
    world_frame = np.stack([a, h, np.cross(a, h)], axis=-1)
    rest_frame = np.stack([a0, h0, np.cross(a0, h0)], axis=-1)
    base_world = world_frame @ np.swapaxes(rest_frame, -1, -2)
    base_local = np.swapaxes(parent_rot, -1, -2) @ base_world
    hinge = rot.axis_angle_rotation(h0, flexion)
    bent_world = base_world @ hinge

    twist = np.zeros(d.shape)
    end_local = None
    if end_rot is not None:
        end_rot = np.asarray(end_rot, np.float64)
        rel = np.swapaxes(bent_world, -1, -2) @ end_rot
        twist_full = rot.twist_angle(rel, a0)
        is_arm = (ids < 2)
        twist = np.where(is_arm, twist_full, 0.0)
        if clamp_twist:
            lo, hi = TWIST_RANGE[ids, 0], TWIST_RANGE[ids, 1]
            twist = np.where(is_arm, np.clip(twist, lo, hi), 0.0)
        tw = rot.axis_angle_rotation(a0, twist)
        mid_local = hinge @ tw
        end_local = np.swapaxes(tw, -1, -2) @ rel
    else:
        mid_local = hinge
    mid_world = base_world @ mid_local
    return LimbSolution(base_local=base_local, mid_local=mid_local, end_local=end_local,
                        base_world=base_world, mid_world=mid_world, mid_pos=mid_pos,
                        end_pos=end_reached, flexion=flexion, elbow_twist=twist,
                        reach_error=reach_error, swivel=swivel)


def axial_rotation(base_local, limb_ids=None):
    """Clinical axial rotation of the shoulder / hip and the limb's elevation.

    The rotation is measured as in the clinic, from a neutral pose with the
    limb hanging straight down (``AXIAL_NEUTRAL_BONE``) and the hinge flexing
    towards ``AXIAL_NEUTRAL_FLEX`` (elbow: forearm forward; knee: shin
    backward, knee cap forward).  For any other bone direction ``b`` the
    neutral flexing direction is carried along by the minimal swing from the
    hanging direction to ``b`` (the swing-twist parametrisation of Baerlocher
    & Boulic 2001, ball-and-socket joints), so abducting the arm sideways
    keeps "forearm forward" as neutral, which is where the AAOS ranges are
    measured (arm at 90° abduction).  The rotation is the signed angle about
    ``b`` from that neutral to the actual flexing direction ``f = h × b``
    (``h`` the mid joint's hinge axis), internal rotation positive.

    base_local: ``(..., L, 3, 3)`` local rotation of the base (parent frame).
    Returns ``(rotation, elevation)``, both ``(..., L)`` radians; elevation
    is the angle between the bone and the hanging direction (0 hanging,
    π/2 horizontal, π straight up, where the measure is undefined).
    """
    ids = _ids(limb_ids)
    base_local = np.asarray(base_local, np.float64)
    shape = base_local.shape[:-1]
    b = np.einsum("...ij,...j->...i", base_local, np.broadcast_to(A0[ids], shape))
    h = np.einsum("...ij,...j->...i", base_local, np.broadcast_to(H0[ids], shape))
    f = np.cross(h, b)
    down = np.broadcast_to(AXIAL_NEUTRAL_BONE[ids], shape)
    ref = np.einsum("...ij,...j->...i", rot.rotation_between(down, b),
                    np.broadcast_to(AXIAL_NEUTRAL_FLEX[ids], shape))
    psi = np.arctan2(_dot(np.cross(ref, f), b), _dot(ref, f))
    elevation = np.arccos(np.clip(_dot(b, down), -1.0, 1.0))
    return INTERNAL_SIGN[ids] * psi, elevation


def axial_range(elevation, limb_ids=None):
    """Allowed axial rotation ``(lo, hi)`` radians (``(..., L)``, internal positive).

    Hips: AAOS internal / external rotation 45° / 45°, widening likewise past the hip's
    flexion range (:data:`HIP_FADE_ELEVATION`).
    Shoulders: AAOS internal 70° / external 90° (measured at 90° abduction)
    widened by :data:`SHOULDER_PASSIVE_MARGIN` (passive range and soft-tissue
    give that active clinical ranges leave out; real motion capture goes
    past the active range in 2-3 % of arm frames).  Above
    :data:`SHOULDER_FADE_ELEVATION` [0] of elevation the range widens
    smoothly to no limit at [1]: as the arm approaches vertical its axial
    rotation loses its clinical reference (Codman's paradox) and the
    measure's neutral direction turns quickly with small arm motions.
    ``python benchmarks/bench_limits.py`` reports how much ground-truth
    mocap breaks these ranges and what enforcing them costs (under 0.5 % of
    frames, elbows and knees moved by at most 4 mm).
    """
    ids = _ids(limb_ids)
    elevation = np.asarray(elevation, np.float64)
    internal = np.broadcast_to(BASE_TWIST_RANGE[ids, 0], elevation.shape)
    external = np.broadcast_to(BASE_TWIST_RANGE[ids, 1], elevation.shape)
    is_arm = ids < 2
    e0 = np.where(is_arm, SHOULDER_FADE_ELEVATION[0], HIP_FADE_ELEVATION[0])
    e1 = np.where(is_arm, SHOULDER_FADE_ELEVATION[1], HIP_FADE_ELEVATION[1])
    x = np.clip((elevation - e0) / (e1 - e0), 0.0, 1.0)
    fade = x * x * (3.0 - 2.0 * x)                                 # smoothstep 0 → 1
    margin = np.where(is_arm, SHOULDER_PASSIVE_MARGIN, 0.0)
    hi = internal + margin + fade * (np.pi - internal - margin)
    lo = -(external + margin + fade * (np.pi - external - margin))
    return lo, hi


def solve_limbs_within_limits(base_pos, end_pos, swivel, lengths, parent_rot, end_rot=None,
                              limb_ids=None, iterations=6):
    """:func:`solve_limbs`, with the swivel moved where it would break an axial limit.

    A swivel that would rotate the upper arm or thigh about its own axis
    beyond :func:`axial_range` (e.g. a knee pointing backwards, an elbow
    flipped up beside a hanging arm) is moved to the nearest angle at the
    limit by a few secant/Newton steps on the affected frames only; the
    hand / foot stays exactly on its target (the swivel circle keeps it
    there).  Returns ``(solution, swivel_used)``.
    """
    ids = _ids(limb_ids)
    swivel = np.array(swivel, np.float64, copy=True)
    sol = solve_limbs(base_pos, end_pos, swivel, lengths, parent_rot, end_rot=end_rot, limb_ids=ids)
    changed = False
    base_pos = np.asarray(base_pos, np.float64)
    end_pos = np.asarray(end_pos, np.float64)
    parent_rot = np.asarray(parent_rot, np.float64)
    lengths = np.broadcast_to(np.asarray(lengths, np.float64), swivel.shape + (2,))
    for k, li in enumerate(ids):
        psi, elev = axial_rotation(sol.base_local[:, k:k + 1], [li])
        lo, hi = axial_range(elev, [li])
        bad = np.nonzero(((psi < lo) | (psi > hi))[:, 0])[0]
        if bad.size == 0:
            continue
        changed = True
        args = (base_pos[bad, k:k + 1], end_pos[bad, k:k + 1])
        rest = dict(lengths=lengths[bad, k:k + 1], parent_rot=parent_rot[bad, k:k + 1],
                    end_rot=None if end_rot is None else np.asarray(end_rot)[bad, k:k + 1], limb_ids=[li])

        def excess_at(phi, sel=slice(None)):
            """Signed angle beyond the nearest limit (0 inside), and the rotation, of the frames
            ``bad[sel]`` at swivels ``phi``."""
            s_ = solve_limbs(args[0][sel], args[1][sel], phi[:, None],
                             **{n: (v[sel] if isinstance(v, np.ndarray) else v) for n, v in rest.items()})
            r, e = axial_rotation(s_.base_local, [li])
            lo_, hi_ = axial_range(e, [li])
            return (r - np.clip(r, lo_, hi_))[:, 0], r[:, 0]

        phi0 = swivel[bad, k]
        phi = phi0.copy()
        for _ in range(iterations):
            err, r = excess_at(phi)
            if np.all(np.abs(err) < 1e-6):
                break
            eps = 1e-4
            _, r2 = excess_at(phi + eps)
            slope = np.angle(np.exp(1j * (r2 - r))) / eps
            slope = np.where(np.abs(slope) < 0.1, np.sign(slope + 1e-12) * 0.1, slope)
            step = np.clip(np.where(np.abs(err) < 1e-6, 0.0, err / slope), -0.5, 0.5)
            phi = phi - step
        err, _ = excess_at(phi)
        ok = np.abs(err) < 1e-3
        if not ok.all():
            # near the measure's singularity the steps can miss: search the swivel circle instead
            sel = np.nonzero(~ok)[0]

            def excess_grid(f):
                """Excess ``(n, m)`` of the frames ``bad[sel]`` at swivels ``f`` ``(n, m)``."""
                return excess_at(f.ravel(), np.repeat(sel, f.shape[1]))[0].reshape(f.shape)
            phi[sel] = _nearest_swivel_within(excess_grid, phi0[sel])
        swivel[bad, k] = np.angle(np.exp(1j * phi))
    if changed:
        sol = solve_limbs(base_pos, end_pos, swivel, lengths, parent_rot, end_rot=end_rot, limb_ids=ids)
    return sol, swivel


def _nearest_swivel_within(excess, phi0, samples=72, splits=8, levels=3):
    """``(n,)`` swivels (radians) nearest ``phi0`` ``(n,)`` whose excess (angle beyond a limit,
    0 inside) is zero: the circle sampled every 360/``samples`` degrees, then the edge between
    the nearest sample inside and its outside neighbour towards ``phi0`` cut ``levels`` times
    into ``splits`` (to 5° / 512, 0.01°).
    Where no sample is inside, the sample with the least excess.  ``excess(phi)`` maps swivels
    ``(n, m)`` to their excess ``(n, m)``, one batched solve."""
    steps = np.arange(1, samples // 2 + 1) * (2 * np.pi / samples)
    # samples ordered by angular distance from phi0: 0, +d, -d, +2d, -2d, ...
    order = np.concatenate([[0.0], np.stack([steps, -steps], 1).ravel()])
    cand = phi0[:, None] + order[None]                                        # (n, S)
    ex = np.abs(excess(cand))
    inside = ex < 1e-9
    first = np.where(inside.any(1), inside.argmax(1), ex.argmin(1))
    out = cand[np.arange(phi0.size), first]
    # refine towards phi0 between the inside sample and the one a step nearer phi0 (outside)
    step = np.where(order[first] > 0, -1.0, 1.0) * (2 * np.pi / samples)
    edge = inside.any(1) & (first > 0)
    a, b = out.copy(), out + step                                             # a inside, b outside
    frac = np.arange(1, splits + 1) / splits
    for _ in range(levels):
        pts = a[:, None] + (b - a)[:, None] * frac[None]                       # (n, splits)
        inn = np.abs(excess(pts)) < 1e-9
        j = np.where(inn.all(1), splits - 1, (~inn).argmax(1))                  # first outside
        rows = np.arange(a.size)
        a, b = np.where(j > 0, pts[rows, np.maximum(j - 1, 0)], a), pts[rows, j]
    return np.where(edge, a, out)


def limit_report(solution: LimbSolution, limb_ids=None):
    """Per-frame booleans ``(T, L)`` of which biomechanical limits are touched.

    Keys: ``reach`` (target out of reach or too close), ``pronation``
    (forearm twist clamped), ``base_twist`` (shoulder/hip axial rotation
    outside :func:`axial_range`).
    """
    ids = _ids(limb_ids)
    bt, elev = axial_rotation(solution.base_local, ids)
    lo, hi = axial_range(elev, ids)
    tol = 1e-9
    tw = solution.elbow_twist
    return {
        "reach": solution.reach_error > 1e-6,
        "pronation": (ids < 2) & ((tw <= TWIST_RANGE[ids, 0] + tol) | (tw >= TWIST_RANGE[ids, 1] - tol)),
        "base_twist": (bt < lo - 1e-4) | (bt > hi + 1e-4),         # 0.006° solver tolerance
    }
