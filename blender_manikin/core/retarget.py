"""Retarget a solved body-model motion onto another character's armature.  Never imports bpy.

Conventions
-----------
Source: the 22-joint body model (:mod:`.skeleton`): metres, Blender world axes (+Z up, body faces
-Y, performer's left +X), rest T-pose with every joint frame world-aligned, so a joint's world
rotation ``R[j]`` *is* its change from rest.  Inputs are world rotations ``(T, 22, 3, 3)`` and
positions ``(T, 22, 3)`` (``PoseResult.fk()``).

Target (:class:`TargetRig`): bones with rest matrices in armature space as Blender's
``bone.matrix_local`` gives them (rotation ``B_k``: columns = bone X, Y, Z, **Y along the bone**;
translation = head), armature units, plus the armature object's world transform
``p_world = t + s R_w p_arm`` (uniform scale ``s``, e.g. 0.01 for an FBX in centimetres; ``R_w``
e.g. a 90° turn about X for Y-up data).  The target must stand upright (+Z) in the world; it may
face any horizontal direction and rest in any pose (A-pose, T-pose) with any bone rolls.

Rest alignment (bone directions)
--------------------------------
Each mapped bone ``k`` (source joint ``j``) spans an anatomical segment: from its head to the head
of the bone mapped to the next mapped joint down ``j``'s chain (``c``: pelvis -> spine1 -> ... ->
neck -> head, collar -> shoulder -> elbow -> wrist, hip -> knee -> ankle -> foot); a bone with no
such child (hand, head, toe) uses its own Y axis.  ``d_k`` is that direction in the target's rest
(world), ``a_j`` the source's rest direction of ``j -> c`` (or the body's end-site direction).

* Facing: ``F`` is the turn about +Z taking the source's left (+X) to the target's left (from its
  rest hip, shoulder or collar heads; or ``facing_yaw``).  The source motion is expressed in the
  target's facing: ``R'[j] = F R[j] Fᵀ``, positions ``p' = F (p - c_s) + c_t`` (``c_s``, ``c_t``: the
  rest pelvis of each, on the floor).
* ``O_k = swing(d_k -> F a_j)``, the minimal rotation turning the target's rest segment onto the
  source's rest segment; ``G_k^T = O_k G_k^0`` is the target bone "posed into the source's rest
  pose" (``G_k^0``: its rest world orientation), so an A-pose character gets a T-pose when the
  performer stands in the T-pose, and its rolls are kept.
* Transfer: ``G_k(t) = R'[j](t) O_k G_k^0`` (world).  So **the target bone points where the source
  segment points** and turns about it as the source joint does.  Where source joints between ``j``
  and ``c`` have no bone the segment ``j -> c`` bends; ``G_k`` is then swung by the minimal rotation
  from ``R'[j] F a_j`` to the actual ``p'[c] - p'[j]`` (see :mod:`.bone_maps` on folding).  A bone with
  no usable segment (its chain child's head on its own head, e.g. Rigify's ``torso`` control) and no
  end role keeps ``O_k = I``.
* Hands: the swing leaves a hand's twist about its bone as the rig's rest has it, and the body's
  rest hand is palms-down (T-pose).  Where the hand bone has finger bones (two of the index,
  middle, ring and little finger's knuckle bones, by name, :func:`finger_knuckles`) the rig's rest
  palm is read from them (:func:`rest_palm_turn`: the knuckle line crossed with the hand's axis)
  and ``O_k`` also twists the hand about its axis by the angle from that palm to the body's, so a
  rig resting palms-forward or with its hands turned 30° in an A-pose gets the body's hand turn;
  the forearm's ``O_k`` takes the same twist when it has twist bones (they carry it along the
  forearm; without, the turn is at the wrist).  Without finger bones the rest palm is taken as the
  body's (``RetargetPlan.palms`` says which, and ``notes`` each hand turned).

Pose-bone basis
---------------
Blender composes a pose bone's armature-space matrix as ``M_k = M_p (A_p⁻¹ A_k) Basis_k`` (root:
``M_k = A_k Basis_k``), ``A`` the rest ``matrix_local``.  With orientations ``G`` (armature space,
``G = R_wᵀ G_world``) the rotation part gives ``G_k = G_p B_pᵀ B_k Q_k``, hence

    Q_k = B_kᵀ B_p G_pᵀ G_k        (root: Q_k = B_kᵀ G_k)

(``rotation_quaternion`` of the pose bone, w x y z, sign-continuous over time), and the
translation part gives the location channel of the root-motion bone (the one mapped to pelvis):
``loc = B_kᵀ B_p G_pᵀ (h_k - h_p) - B_kᵀ (h_k^0 - h_p^0)`` (root: ``B_kᵀ (h_k - h_k^0)``), armature
units in the bone's rest frame -- assuming Blender's defaults (inherit rotation and scale, local
location, bone not connected).  Unmapped bones keep ``Q = I`` (their rest pose relative to the
parent).  Twist bones: ``τ`` is the twist about the mapped bone's Y axis of its transferred orientation
relative to its parent's (the parent's *unreduced* orientation if the parent shares its own twist),
unwrapped over time; the mapped bone keeps ``s_k τ`` of it (``G_k = G_k^full Rot_Y((s_k - 1) τ)``)
and twist bone ``i`` gets ``G_k^full Rot_Y((s_i - 1) τ) B_kᵀ B_i``, the shares ``s`` by where the
bones sit along the segment (:func:`twist_shares`: from none of the twist at its base to nearly all
at its tip).  Children of the segment are unaffected (mapped bones take world orientations).

Root motion
-----------
The target's root-motion bone head follows ``h^0 + F Δ`` with ``Δ`` the source pelvis' displacement
from its rest position (world metres): ``"scaled"``: ``Δ`` times ``k`` = target leg length / source
leg length (hip-knee-ankle, world metres); ``"in_place"``: horizontal part removed, height change
scaled by ``k``; ``"as_is"``: unscaled.

Keeping hands and feet on the trackers
--------------------------------------
:func:`keep_ends_on_targets` re-solves the target's arms and legs with
:func:`.limb_solver.solve_limbs` on the target's own segment lengths (head-to-head distances of the
mapped base, mid and end bones) with the source's swivel angles, so the target's hand / foot bone
heads land on the source's wrist / ankle positions (mapped by ``F``, ``c_s``, ``c_t``; or the
scaled positions, see there).  Each limb's upper and lower segments must be mapped bones whose
segments are straight lines between the mapped heads (bones in between keep their rest pose
relative to their parent; twist bones along the segment are fine).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from . import rotations as rot
from .bone_maps import _tokens, as_bone_map, validate_bone_map
from .export_bvh import end_site_offsets
from .limb_solver import solve_limbs
from .skeleton import CHILDREN, JOINT_NAMES, LIMB_NAMES, LIMBS, NUM_JOINTS, PARENTS, Body, J

ROOT_MOTION = ("scaled", "in_place", "as_is")
_EY = np.array([0.0, 1.0, 0.0])


def _primary_children():
    out = np.full(NUM_JOINTS, -1)
    for j in range(NUM_JOINTS):
        if len(CHILDREN[j]) == 1:
            out[j] = CHILDREN[j][0]
    out[J["pelvis"]] = J["spine1"]
    out[J["spine3"]] = J["neck"]
    return out


#: the joint continuing each joint's chain (-1 at the ends: head, wrists, feet)
PRIMARY_CHILD = _primary_children()


def _orthonormal_check(R):
    """``(R, indices of the matrices that are not rotations)`` for ``(..., 3, 3)`` input."""
    R = np.asarray(R, np.float64)
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
    bad = (err > 1e-4) | (np.linalg.det(R) < 0.5)
    return R, np.nonzero(np.atleast_1d(bad))[0]


@dataclass
class TargetRig:
    """A target armature at rest.

    names: ``(B,)`` bone names.  parents: ``(B,)`` parent indices (-1 for roots) or parent names
    (None for roots).  rest_rot: ``(B, 3, 3)`` rest rotation of each bone in armature space
    (``bone.matrix_local`` 3x3: columns bone X, Y, Z; Y along the bone), orthonormal.
    heads: ``(B, 3)`` rest heads, armature units.  world_rot ``(3, 3)``, world_scale (uniform,
    > 0) and world_translation ``(3,)`` (metres): the armature object's ``matrix_world``.
    Use :meth:`from_matrices` to build one from 4x4 matrices.
    """
    names: tuple
    parents: np.ndarray
    rest_rot: np.ndarray
    heads: np.ndarray
    world_rot: np.ndarray = field(default_factory=lambda: np.eye(3))
    world_scale: float = 1.0
    world_translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        self.names = tuple(str(n) for n in self.names)
        B = len(self.names)
        if len(set(self.names)) != B:
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ValueError(f"target rig has duplicate bone names {dup}")
        self.index = {n: k for k, n in enumerate(self.names)}
        par = list(self.parents)
        if len(par) != B:
            raise ValueError(f"target rig: {len(par)} parents for {B} bones")
        if any(p is None or isinstance(p, str) for p in par):
            miss = [p for p in par if p is not None and p not in self.index]
            if miss:
                raise ValueError(f"target rig: unknown parent bone(s) {miss}")
            par = [-1 if p is None else self.index[p] for p in par]
        self.parents = np.asarray(par, dtype=int)
        if np.any((self.parents < -1) | (self.parents >= B)):
            raise ValueError("target rig: parent index out of range")
        self.rest_rot, bad = _orthonormal_check(np.asarray(self.rest_rot, np.float64).reshape(B, 3, 3))
        if len(bad):
            raise ValueError(f"target rig: rest rotation of bone(s) {[self.names[k] for k in bad]} is not a "
                             f"rotation (scaled or sheared matrix_local?)")
        self.rest_rot = rot.orthonormalize(self.rest_rot)
        self.heads = np.asarray(self.heads, np.float64).reshape(B, 3)
        self.world_rot, bad = _orthonormal_check(np.asarray(self.world_rot, np.float64).reshape(3, 3))
        if len(bad):
            raise ValueError("target rig: world_rot is not a rotation")
        self.world_scale = float(self.world_scale)
        if not np.isfinite(self.world_scale) or self.world_scale <= 0:
            raise ValueError(f"target rig: world_scale must be positive, got {self.world_scale}")
        self.world_translation = np.asarray(self.world_translation, np.float64).reshape(3)
        # parents-first order (and a cycle check)
        depth = np.full(B, -1)
        for k in range(B):
            chain, n = [], k
            while n >= 0 and depth[n] < 0:
                if n in chain:
                    raise ValueError(f"target rig: bone {self.names[n]!r} is its own ancestor")
                chain.append(n)
                n = self.parents[n]
            d = -1 if n < 0 else depth[n]
            for m in reversed(chain):
                d += 1
                depth[m] = d
        self.depth = depth
        self.order = np.argsort(depth, kind="stable")

    @classmethod
    def from_matrices(cls, names, parents, matrix_local, matrix_world=None):
        """From Blender-like data: ``matrix_local`` ``(B, 4, 4)`` (``bone.matrix_local``),
        ``matrix_world`` ``(4, 4)`` (the armature object's; uniform scale only)."""
        A = np.asarray(matrix_local, np.float64)
        W = np.eye(4) if matrix_world is None else np.asarray(matrix_world, np.float64)
        M = W[:3, :3]
        det = np.linalg.det(M)
        if det <= 0:
            raise ValueError("armature object matrix is mirrored or singular (negative / zero scale)")
        s = det ** (1.0 / 3.0)
        R = M / s
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-5:
            raise ValueError("armature object has a non-uniform scale or shear; apply its scale first")
        return cls(names, parents, A[:, :3, :3], A[:, :3, 3], R, s, W[:3, 3])

    @property
    def num_bones(self) -> int:
        return len(self.names)

    def restricted_to(self, names) -> "TargetRig":
        """This rig with only the bones ``names`` (those it has) and their ancestors.

        A retarget holds a row per bone and frame (orientations, heads, bases, quaternions); the
        bones a map neither names nor passes through -- fingers, face, props, helpers below the
        driven ones -- keep their rest pose under their parent whatever the retarget does, and a
        character with a face rig can have ten times as many of them as driven bones.  Bone
        order and indices are renumbered; names, rest poses and the world placement are kept."""
        keep = set()
        for n in names:
            k = self.index.get(n, -1)
            while k >= 0 and k not in keep:
                keep.add(k)
                k = int(self.parents[k])
        ids = sorted(keep)
        new = {k: i for i, k in enumerate(ids)}
        return TargetRig([self.names[k] for k in ids], [new[int(p)] if p >= 0 else -1 for p in self.parents[ids]],
                         self.rest_rot[ids], self.heads[ids], self.world_rot, self.world_scale,
                         self.world_translation)

    def to_world(self, p):
        """Armature-space points ``(..., 3)`` -> world metres."""
        return self.world_translation + self.world_scale * np.asarray(p, np.float64) @ self.world_rot.T

    def to_armature(self, p):
        """World points ``(..., 3)`` metres -> armature space."""
        return (np.asarray(p, np.float64) - self.world_translation) @ self.world_rot / self.world_scale

    def rest_world_heads(self):
        return self.to_world(self.heads)

    def rest_world_rot(self):
        return self.world_rot @ self.rest_rot


@dataclass
class RetargetPlan:
    """Constants of one (source body, target rig, bone map) retarget; see :func:`make_plan`."""
    body: Body
    target: TargetRig
    bone_map: object
    bone_of: np.ndarray          # (22,) target bone of each joint, -1 if none
    chain_child: np.ndarray      # (22,) next mapped joint down the chain, -1 if none
    folded: tuple                # joints whose segment spans unmapped source joints
    src_dir: np.ndarray          # (22, 3) source rest segment directions, in the target's facing
    align: np.ndarray            # (22, 3, 3) O_k G_k^0: target world orientation at the source rest
    F: np.ndarray                # (3, 3) facing turn about +Z
    c_s: np.ndarray
    c_t: np.ndarray
    leg_ratio: float
    root_bone: int
    root_rest_world: np.ndarray
    twist_main: dict             # main bone -> list of twist bones
    twist_of: dict               # twist bone -> (main bone, position, count)
    notes: list
    twist_share: dict = field(default_factory=dict)     # main and twist bones -> share of the twist
    # wrist joint -> how its rest palm was taken: "fingers" (with the knuckle bones and the turn, degrees,
    # put into ``align``) or "assumed palms-down" (no usable finger bones), see :func:`rest_palm_turn`
    palms: dict = field(default_factory=dict)


def twist_shares(along) -> np.ndarray:
    """How a limb segment's twist is shared between its bone and its twist bones.

    along: ``(n,)`` where each twist bone's head lies along the segment, base to tip: 0 at the
    segment bone's head, 1 at the next mapped joint's (clamped to [0, 1], kept in order).
    Returns ``(n + 1,)`` shares in [0, 1], the segment bone's first: each bone takes the twist of
    the middle of the stretch whose skin it carries (the segment bone from the base to the first
    twist bone, each twist bone from its head to the next one's, the last to the tip).  So the twist
    ramps from none at the segment's base, where the parent segment's skin meets it, to nearly
    all at its tip, where the next bone (hand, forearm, foot) carries it whole: one twist bone
    half-way along gets 3/4, the segment bone 1/4; CC's Twist01 at the head and Twist02 half-way
    get 1/4 and 3/4, the segment bone (no skin of its own) none.
    """
    a = np.maximum.accumulate(np.clip(np.asarray(along, np.float64).reshape(-1), 0.0, 1.0)) \
        if len(along) else np.zeros(0)
    p = np.concatenate([[0.0], a, [1.0]])
    return 0.5 * (p[:-1] + p[1:])


def _segments_starting_above(tg, bone_of, chain_child, twist_of, heads_w, G0):
    """Notes on mapped limb bones (upper arm, forearm, thigh, shin) that hang, part-way along
    their segment, under an unmapped bone that starts the same segment higher up (an Auto-Rig
    Pro export's arm_stretch.l under c_arm_twist_offset.l, mapped by hand): that bone keeps its
    rest pose, so the segment turns about the mapped bone's head, part-way along it.  Such an
    unmapped ancestor: its head behind the mapped head along the segment by more than a tenth
    of it, its own axis within 10° of the segment and the mapped head within a twentieth of
    the segment of that axis.  heads_w ``(B, 3)``, G0 ``(B, 3, 3)``: rest heads and orientations, world."""
    out = []
    mapped = set(int(b) for b in bone_of if b >= 0)
    for j in [j for _, base, mid, _ in LIMBS for j in (base, mid)]:
        k, c = int(bone_of[j]), int(chain_child[j])
        if k < 0 or c < 0:
            continue
        seg = heads_w[bone_of[c]] - heads_w[k]
        length = float(np.linalg.norm(seg))
        if length < 1e-6:
            continue
        d = seg / length
        u = int(tg.parents[k])
        while u >= 0 and u not in mapped and u not in twist_of:
            back = float((heads_w[k] - heads_w[u]) @ d)
            y = G0[u] @ _EY
            off = heads_w[k] - heads_w[u] - ((heads_w[k] - heads_w[u]) @ y) * y
            if back > 0.1 * length and float(y @ d) > np.cos(np.radians(10.0)) \
                    and float(np.linalg.norm(off)) < 0.05 * length:
                out.append(f"{tg.names[k]!r} ({JOINT_NAMES[j]}) hangs under {tg.names[u]!r}, which starts the "
                           f"same segment {100 * back:.0f} cm above it and is not mapped: it keeps its rest pose, "
                           f"so the segment turns about {tg.names[k]!r}'s head; map {JOINT_NAMES[j]} to "
                           f"{tg.names[u]!r} with {tg.names[k]!r} as its twist bone")
                break
            u = int(tg.parents[u])
    return out


def _is_ancestor(a, b, parents):
    """True when index ``a`` is a proper ancestor of ``b``."""
    n = parents[b]
    while n >= 0:
        if n == a:
            return True
        n = parents[n]
    return False


#: finger name tokens, radial (index) to ulnar (little finger) side
_FINGERS = (("index",), ("middle", "mid"), ("ring",), ("pinky", "little", "small"))
#: tokens of a finger's metacarpal bone (UE5's index_metacarpal_l, ARP's index1_base.l, Daz's lCarpal1)
_METACARPAL = {"metacarpal", "meta", "carpal", "base", "palm"}


def _finger_of(name):
    """0-3 (index, middle, ring, little finger) from a bone name's tokens, None for other bones
    (the thumb, props).  MakeHuman's ``finger2-1.L`` .. ``finger5-1.L`` count from the thumb."""
    toks = _tokens(name)
    if "thumb" in toks:
        return None
    for f, words in enumerate(_FINGERS):
        if any(w in toks for w in words):
            return f
    if "finger" in toks:
        i = toks.index("finger")
        if i + 1 < len(toks) and toks[i + 1] in ("2", "3", "4", "5"):
            return int(toks[i + 1]) - 2
    return None


def finger_knuckles(target: TargetRig, hand) -> dict:
    """``{finger: bone index}``, finger 0-3 = index, middle, ring, little: the knuckle bone of each
    finger found below the hand bone ``hand`` (an index or name), by name (Mixamo ``LeftHandIndex1``,
    UE ``index_01_l``, Rigify ``DEF-f_index.01.L``, CC ``CC_Base_L_Mid1``, VRM ``J_Bip_L_Ring1``,
    ARP ``index1.l``, Daz ``lPinky1``, MakeHuman ``finger5-1.L``): the finger's bone nearest the
    hand that is not its metacarpal (``index_metacarpal_l``, ``index1_base.l``), else its metacarpal."""
    k = target.index[hand] if isinstance(hand, str) else int(hand)
    children = {}
    for b, p in enumerate(target.parents):
        children.setdefault(int(p), []).append(b)
    best = {}
    todo = [(c, 1) for c in children.get(k, [])]
    while todo:
        b, depth = todo.pop(0)
        f = _finger_of(target.names[b])
        if f is not None:
            key = (bool(_METACARPAL & set(_tokens(target.names[b]))), depth)
            if f not in best or key < best[f][0]:
                best[f] = (key, b)
        todo += [(c, depth + 1) for c in children.get(b, [])]
    return {f: b for f, (_, b) in sorted(best.items())}


def finger_bones(target: TargetRig, bone_map) -> list:
    """Names of the knuckle bones (:func:`finger_knuckles`) of the hands ``bone_map`` maps on
    ``target``: what :func:`make_plan` reads the rest palms from, to keep when the rig is
    :meth:`TargetRig.restricted_to` the driven bones."""
    bm = as_bone_map(bone_map)
    out = []
    for side in ("left", "right"):
        hand = bm.bones.get(f"{side}_wrist")
        if isinstance(hand, str) and hand in target.index:
            out += [target.names[b] for b in finger_knuckles(target, hand).values()]
    return out


#: a rest palm turned less than this (degrees) from palms-down by its knuckles is taken as
#: palms-down: knuckles arch (the little finger's sits lower than the index's: 2.3° on Blender's
#: human metarig) and modellers leave hands a little rolled, so a smaller turn is not measured
#: well enough to twist the wrist by
PALM_TURN_MIN_DEG = 5.0


def rest_palm_turn(target: TargetRig, hand, side: str, align_hand, F):
    """The twist (radians, about the hand's aligned direction) that turns a rig's rest palm, as
    its fingers show it, onto the body's rest palm (returned as ``(angle, bones)``, below), or
    ``(None, reason)`` without two knuckle bones apart.

    hand: the hand bone (index or name); side: ``"left"`` or ``"right"``; align_hand ``(3, 3)``:
    the hand bone's world orientation posed into the body's rest (``RetargetPlan.align``, before
    this turn); F ``(3, 3)``: the facing turn.  The rest palm's normal (world, pointing out of the
    palm) is perpendicular to the knuckle line (the radial-most of index / middle / ring knuckle
    heads to the ulnar-most of little / ring / middle, :func:`finger_knuckles`) and to the hand
    bone's Y axis, on the side the side's hand frame gives it; the body's rest palm faces down
    (``F`` (0, 0, -1)) in its T-pose.
    Returns ``(angle, (radial bone, ulnar bone))`` or ``(None, reason)``."""
    k = target.index[hand] if isinstance(hand, str) else int(hand)
    kn = finger_knuckles(target, k)
    if len(kn) < 2:
        return None, "fewer than two finger bones (index, middle, ring, little finger)"
    fs = sorted(kn)
    radial, ulnar = kn[fs[0]], kn[fs[-1]]
    heads = target.rest_world_heads()
    G0 = target.rest_world_rot()
    across = heads[ulnar] - heads[radial]
    d = G0[k] @ _EY
    if float(np.linalg.norm(np.cross(across, d))) < max(0.2 * float(np.linalg.norm(across)), 1e-9):
        return None, f"knuckles {target.names[radial]!r}, {target.names[ulnar]!r} lie along the hand bone"
    # the hand's frame in the body's convention (X along the hand times the side's sign, Y thumb to
    # little finger, Z out of the back of the hand) as a keypoint layout's hand is read from its
    # knuckles (:func:`.keypoint_layouts.body22_from_keypoints`); the palm faces -Z
    n = -rot.frame_from_axes((1.0 if side == "left" else -1.0) * d, across, "xy")[:, 2]
    n = align_hand @ (G0[k].T @ n)                           # the palm with the hand in the body's rest
    a = align_hand @ _EY
    want = F @ np.array([0.0, 0.0, -1.0])
    n, want = n - (n @ a) * a, want - (want @ a) * a
    return float(np.arctan2(a @ np.cross(n, want), n @ want)), (radial, ulnar)


def _turn_rest_palms(tg, bone_of, twist_main, src_dir, align, F, notes):
    """Twist each mapped hand's ``align`` by :func:`rest_palm_turn` (and the forearm's, when the
    forearm has twist bones, so they carry the turn along the forearm); returns ``palms``."""
    palms = {}
    for side in ("left", "right"):
        j = J[f"{side}_wrist"]
        k = int(bone_of[j])
        if k < 0:
            continue
        ang, why = rest_palm_turn(tg, k, side, align[j], F)
        if ang is None:
            palms[JOINT_NAMES[j]] = f"assumed palms-down ({why})"
            continue
        deg = float(np.degrees(ang))
        palms[JOINT_NAMES[j]] = (f"fingers {tg.names[why[0]]!r} to {tg.names[why[1]]!r}: rests turned "
                                 f"{abs(deg):.1f}° from palms-down"
                                 + (" (taken as palms-down)" if abs(deg) < PALM_TURN_MIN_DEG else ""))
        if abs(deg) < PALM_TURN_MIN_DEG:
            continue
        align[j] = rot.axis_angle_rotation(src_dir[j], np.array(ang)) @ align[j]
        e = J[f"{side}_elbow"]
        ke = int(bone_of[e])
        carried = ke >= 0 and ke in twist_main
        if carried:
            align[e] = rot.axis_angle_rotation(src_dir[e], np.array(ang)) @ align[e]
        notes.append(f"{tg.names[k]!r} ({JOINT_NAMES[j]}) rests turned {abs(deg):.0f}° from palms-down, by its "
                     f"fingers ({tg.names[why[0]]!r} to {tg.names[why[1]]!r}): turned back at the "
                     + (f"wrist and along {tg.names[ke]!r}'s twist bones" if carried else "wrist"))
    return palms


def make_plan(body: Body, target: TargetRig, bone_map, facing_yaw: Optional[float] = None) -> RetargetPlan:
    """Validate the map against the rig and precompute the rest alignment (module docstring).

    facing_yaw: radians about +Z from the source's facing (-Y) to the target's; None detects it
    from the target's rest hips / shoulders / collars.
    """
    bm = validate_bone_map(as_bone_map(bone_map), target.names)
    tg = target
    bone_of = np.full(NUM_JOINTS, -1)
    for jn, b in bm.bones.items():
        bone_of[J[jn]] = tg.index[b]
    joint_of = {int(bone_of[j]): j for j in range(NUM_JOINTS) if bone_of[j] >= 0}
    # hierarchy consistency: a mapped bone's nearest mapped ancestor must follow a source ancestor
    for j in range(NUM_JOINTS):
        k = bone_of[j]
        if k < 0:
            continue
        a = tg.parents[k]
        while a >= 0 and a not in joint_of:
            a = tg.parents[a]
        if a >= 0:
            ja = joint_of[a]
            n = PARENTS[j]
            while n >= 0 and n != ja:
                n = PARENTS[n]
            if n < 0:
                raise ValueError(f"bone map {bm.name!r}: bone {tg.names[k]!r} ({JOINT_NAMES[j]}) is under "
                                 f"{tg.names[a]!r} ({JOINT_NAMES[ja]}) in the rig, but {JOINT_NAMES[ja]} is "
                                 f"not above {JOINT_NAMES[j]} in the body")
    twist_main, twist_of = {}, {}
    for jn, tb in bm.twist.items():
        main = tg.index[bm.bones[jn]]
        ids = [tg.index[b] for b in tb]
        for i, t in enumerate(ids):
            if not _is_ancestor(main, t, tg.parents):
                raise ValueError(f"bone map {bm.name!r}: twist bone {tg.names[t]!r} is not a descendant of "
                                 f"{tg.names[main]!r} ({jn})")
            twist_of[t] = (main, i, len(ids))
        twist_main[main] = ids

    P = body.rest_positions()
    leaf = end_site_offsets(body)
    heads_w = tg.rest_world_heads()
    G0 = tg.rest_world_rot()
    size = float(np.ptp(heads_w[bone_of[bone_of >= 0]], axis=0).max()) if (bone_of >= 0).sum() > 1 else 1.0
    size = max(size, 1e-6)

    notes = []
    if facing_yaw is None:
        yaw = 0.0
        for ln, rn in (("left_hip", "right_hip"), ("left_shoulder", "right_shoulder"),
                       ("left_collar", "right_collar")):
            kl, kr = bone_of[J[ln]], bone_of[J[rn]]
            if kl >= 0 and kr >= 0:
                left = heads_w[kl] - heads_w[kr]
                if np.hypot(left[0], left[1]) > 0.2 * np.linalg.norm(left) and np.linalg.norm(left) > 1e-3 * size:
                    yaw = float(np.arctan2(left[1], left[0]))
                    break
        else:
            notes.append("facing not detected (no left/right hips, shoulders or collars): assumed -Y")
    else:
        yaw = float(facing_yaw)
    F = rot.axis_angle_rotation(np.array([0.0, 0.0, 1.0]), np.array(yaw))

    chain_child = np.full(NUM_JOINTS, -1)
    folded = []
    src_dir = np.zeros((NUM_JOINTS, 3))
    align = np.broadcast_to(np.eye(3), (NUM_JOINTS, 3, 3)).copy()
    for j in range(NUM_JOINTS):
        k = bone_of[j]
        if k < 0:
            continue
        c = PRIMARY_CHILD[j]
        while c >= 0 and bone_of[c] < 0:
            c = PRIMARY_CHILD[c]
        chain_child[j] = c
        if c >= 0:
            a = P[c] - P[j]
            d = heads_w[bone_of[c]] - heads_w[k]
            if c != PRIMARY_CHILD[j]:
                folded.append(j)
        else:
            pc = PRIMARY_CHILD[j]
            a = P[pc] - P[j] if pc >= 0 else leaf[j]
            d = G0[k] @ _EY
        a = rot.normalize(F @ a)
        src_dir[j] = a
        if np.linalg.norm(d) < 1e-3 * size:
            if c >= 0:
                notes.append(f"{tg.names[k]!r} ({JOINT_NAMES[j]}): its segment has no length in the rig; "
                             f"rest orientation used as is")
                align[j] = G0[k]
                continue
            d = G0[k] @ _EY
        align[j] = rot.rotation_between(d, a) @ G0[k]

    notes += _segments_starting_above(tg, bone_of, chain_child, twist_of, heads_w, G0)
    palms = _turn_rest_palms(tg, bone_of, twist_main, src_dir, align, F, notes)

    # each segment's twist shared by where its bones sit between its head and the next joint's
    twist_share = {}
    for jn in bm.twist:
        main = tg.index[bm.bones[jn]]
        ids, c = twist_main[main], chain_child[J[jn]]
        seg = heads_w[bone_of[c]] - heads_w[main] if c >= 0 else np.zeros(3)
        if float(seg @ seg) > 1e-12:
            along = [float((heads_w[t] - heads_w[main]) @ seg / (seg @ seg)) for t in ids]
        else:                        # no next joint to measure by: evenly along the segment
            along = [(i + 1.0) / (len(ids) + 1) for i in range(len(ids))]
        shares = twist_shares(along)
        twist_share[main] = float(shares[0])
        twist_share.update({t: float(x) for t, x in zip(ids, shares[1:])})

    # leg length ratio for root motion
    ratios = []
    for side in ("left", "right"):
        ks = [bone_of[J[f"{side}_{n}"]] for n in ("hip", "knee", "ankle")]
        if min(ks) >= 0:
            lt = np.linalg.norm(heads_w[ks[1]] - heads_w[ks[0]]) + np.linalg.norm(heads_w[ks[2]] - heads_w[ks[1]])
            js = [J[f"{side}_{n}"] for n in ("hip", "knee", "ankle")]
            ls = np.linalg.norm(P[js[1]] - P[js[0]]) + np.linalg.norm(P[js[2]] - P[js[1]])
            ratios.append(lt / ls)
    root_bone = int(bone_of[J["pelvis"]])
    root_rest_world = heads_w[root_bone]
    if ratios:
        leg_ratio = float(np.mean(ratios))
    else:
        leg_ratio = float(root_rest_world[2] / body.root_rest[2]) if root_rest_world[2] > 0 else 1.0
        notes.append("legs not mapped: root motion scaled by the ratio of pelvis heights")
    c_s = np.array([body.root_rest[0], body.root_rest[1], 0.0])
    c_t = np.array([root_rest_world[0], root_rest_world[1], 0.0])
    return RetargetPlan(body, tg, bm, bone_of, chain_child, tuple(folded), src_dir, align, F, c_s, c_t,
                        leg_ratio, root_bone, root_rest_world, twist_main, twist_of, notes, twist_share, palms)


@dataclass
class RetargetResult:
    """Per-frame pose of the target rig.

    quaternions: ``(T, B, 4)`` pose-bone ``rotation_quaternion`` (w, x, y, z) of every target bone
    (identity for unmapped ones), sign-continuous over time.  basis_rot: the same as matrices.
    keyed: ``(B,)`` bool, bones the retarget drives (mapped and twist bones); key these.
    root_bone: name of the bone carrying root motion; root_location: ``(T, 3)`` its ``location``
    channel (armature units, the bone's rest frame).
    orientations ``(T, B, 3, 3)`` and heads ``(T, B, 3)``: posed bones in armature space (what
    Blender's ``pose_bone.matrix`` would hold).  reach_error: ``(T, 4)`` metres per limb in
    ``LIMB_NAMES`` order after :func:`keep_ends_on_targets` (NaN for limbs not re-solved), else None.
    """
    bone_names: tuple
    quaternions: np.ndarray
    basis_rot: np.ndarray
    keyed: np.ndarray
    root_bone: str
    root_location: np.ndarray
    orientations: np.ndarray
    heads: np.ndarray
    plan: RetargetPlan = field(repr=False)
    mapped_world: dict = field(repr=False)         # bone -> (T, 3, 3) world orientation before assembly
    root_head_world: np.ndarray = field(repr=False)
    reach_error: Optional[np.ndarray] = None
    end_targets: Optional[np.ndarray] = None      # (T, 4, 3) world targets of keep_ends (NaN if unused)

    def world_heads(self):
        """``(T, B, 3)`` bone heads in world metres."""
        return self.plan.target.to_world(self.heads)

    def world_orientations(self):
        """``(T, B, 3, 3)`` bone orientations in the world (columns bone X, Y, Z)."""
        return self.plan.target.world_rot @ self.orientations


def _check_source(world_rot, positions):
    world_rot = np.asarray(world_rot, np.float64)
    positions = np.asarray(positions, np.float64)
    if world_rot.ndim != 4 or world_rot.shape[1:] != (NUM_JOINTS, 3, 3):
        raise ValueError(f"world rotations must be (T, {NUM_JOINTS}, 3, 3), got {world_rot.shape}")
    if positions.shape != world_rot.shape[:2] + (3,):
        raise ValueError(f"positions must be (T, {NUM_JOINTS}, 3) matching the rotations, got {positions.shape}")
    if not (np.isfinite(world_rot).all() and np.isfinite(positions).all()):
        raise ValueError("source motion contains NaN/inf")
    return world_rot, positions


def _assemble(plan: RetargetPlan, mapped_world: dict, root_head_world) -> RetargetResult:
    tg = plan.target
    T = root_head_world.shape[0]
    Bn = tg.num_bones
    Bm, h0, par = tg.rest_rot, tg.heads, tg.parents
    G = np.empty((T, Bn, 3, 3))
    H = np.empty((T, Bn, 3))
    Q = np.empty((T, Bn, 3, 3))
    root_head = tg.to_armature(root_head_world)
    root_loc = np.zeros((T, 3))
    tw_info = {}
    for k in tg.order:
        p = par[k]
        frame = G[:, p] @ (Bm[p].T @ Bm[k]) if p >= 0 else np.broadcast_to(Bm[k], (T, 3, 3))
        if k in mapped_world:
            Gk = tg.world_rot.T @ mapped_world[k]
            if k in plan.twist_main:
                # the twist is measured against the parent's unreduced orientation, so a parent's
                # own twist sharing does not leak into this segment's twist
                n = len(plan.twist_main[k])
                # (a parent that is a twist bone of its segment -- Daz's lShldrTwist above
                # lForearmBend -- stands for that segment, unreduced)
                pm = plan.twist_of[p][0] if p in plan.twist_of else p
                frame_full = tw_info[pm][3] @ (Bm[pm].T @ Bm[k]) if pm in tw_info else frame
                q = rot.matrix_to_quat(np.swapaxes(frame_full, -1, -2) @ Gk)
                ang = np.unwrap(rot.swing_twist(q, _EY)[2])
                G_sw = Gk @ rot.axis_angle_rotation(_EY, -ang)
                tw_info[k] = (G_sw, ang, n, Gk)
                Gk = G_sw @ rot.axis_angle_rotation(_EY, ang * plan.twist_share[k])
        elif k in plan.twist_of:
            main = plan.twist_of[k][0]
            G_sw, ang, _, _ = tw_info[main]
            Gk = G_sw @ rot.axis_angle_rotation(_EY, ang * plan.twist_share[k]) @ (Bm[main].T @ Bm[k])
        else:
            Gk = frame
        G[:, k] = Gk
        Q[:, k] = np.swapaxes(frame, -1, -2) @ Gk
        if k == plan.root_bone:
            H[:, k] = root_head
            Hp = H[:, p] if p >= 0 else 0.0
            hp0 = h0[p] if p >= 0 else 0.0
            root_loc = np.einsum("tji,tj->ti", frame, H[:, k] - Hp) - (h0[k] - hp0) @ Bm[k]
        elif p >= 0:
            H[:, k] = H[:, p] + G[:, p] @ (Bm[p].T @ (h0[k] - h0[p]))
        else:
            H[:, k] = h0[k]
    # Q is a product of rotations (round-off away from orthonormal): its quaternion, normalised,
    # is the rotation (an SVD per bone and frame took most of a long take's retarget)
    quats = rot.quat_continuous(rot.normalize(rot.matrix_to_quat(Q)), axis=0)
    keyed = np.zeros(Bn, dtype=bool)
    keyed[list(mapped_world)] = True
    keyed[list(plan.twist_of)] = True
    return RetargetResult(tg.names, quats, Q, keyed, tg.names[plan.root_bone], root_loc, G, H, plan,
                          mapped_world, root_head_world)


def body_world_from_bones(plan: RetargetPlan, bone_world: dict) -> dict:
    """The rest alignment read backwards: a rig's own motion as body-model world orientations.

    bone_world: ``{joint name: (T, 3, 3)}`` world orientation (columns the bone's X, Y, Z axes,
    unit: any object scale taken out) of the bone ``plan`` maps to that joint.  Returns
    ``{joint name: (T, 3, 3)}``: the joint's world rotation in the body's convention (identity:
    its frame in the body's T-pose rest facing -Y, :mod:`.skeleton`), the one whose body, turned
    to the rig's facing and posed by it, has the bone in ``G``: with ``align`` = ``O_k G_k^0``
    (the bone posed into the body's rest, T-pose or not, module docstring) and ``F`` the rig's
    facing, ``G = R Fᵀ align`` at rest ``R = F``, hence ``R = G alignᵀ F``.  So the rig's rest
    (A-pose or T-pose, any rolls) gives the body's rest turned to its facing, and a hand turned
    palm-up about its bone is the body's wrist turned palm-up.  Joints the plan leaves without a
    bone are skipped."""
    out = {}
    for name, G in bone_world.items():
        j = J[name]
        if plan.bone_of[j] < 0:
            continue
        out[name] = np.asarray(G, np.float64) @ (plan.align[j].T @ plan.F)
    return out


def retarget(world_rot, positions, source_body: Body, target: TargetRig, bone_map, root_motion: str = "scaled",
             facing_yaw: Optional[float] = None, plan: Optional[RetargetPlan] = None) -> RetargetResult:
    """Retarget a source motion onto ``target`` (see the module docstring for the conventions).

    world_rot: ``(T, 22, 3, 3)`` source world rotations (identity = rest T-pose); positions:
    ``(T, 22, 3)`` source joint positions, metres, Blender world axes; source_body: the
    :class:`~.skeleton.Body` they were made with.  root_motion: ``"scaled"``, ``"in_place"`` or
    ``"as_is"``.  Returns a :class:`RetargetResult` (``quaternions`` ``(T, B, 4)`` for
    ``pose_bone.rotation_quaternion``, ``root_location`` ``(T, 3)`` for the pelvis bone's
    ``location``).  Vectorised over frames; loops over bones.
    """
    world_rot, positions = _check_source(world_rot, positions)
    if root_motion not in ROOT_MOTION:
        raise ValueError(f"root_motion must be one of {ROOT_MOTION}, got {root_motion!r}")
    plan = plan or make_plan(source_body, target, bone_map, facing_yaw)
    F = plan.F
    Rw = F @ world_rot @ F.T
    mapped = {}
    Pw = None
    if plan.folded:
        Pw = (positions - plan.c_s) @ F.T + plan.c_t
    for j in range(NUM_JOINTS):
        k = plan.bone_of[j]
        if k < 0:
            continue
        G = Rw[:, j] @ plan.align[j]
        if j in plan.folded:
            c = plan.chain_child[j]
            now = Rw[:, j] @ plan.src_dir[j]
            G = rot.rotation_between(now, Pw[:, c] - Pw[:, j]) @ G
        mapped[int(k)] = G
    delta = (positions[:, 0] - source_body.root_rest) @ F.T
    if root_motion == "scaled":
        delta = delta * plan.leg_ratio
    elif root_motion == "in_place":
        delta = np.stack([np.zeros(len(delta)), np.zeros(len(delta)), delta[:, 2] * plan.leg_ratio], -1)
    return _assemble(plan, mapped, plan.root_rest_world + delta)


def keep_ends_on_targets(res: RetargetResult, world_rot, positions, swivel, limbs=LIMB_NAMES,
                         ends: str = "source", end_positions=None) -> RetargetResult:
    """Re-solve the target's limbs so its hand / foot bone heads land on the source's wrists / ankles.

    res: a :func:`retarget` result; world_rot ``(T, 22, 3, 3)`` / positions ``(T, 22, 3)``: the same
    source motion; swivel: ``(T, 4)`` radians (``PoseResult.swivel``, ``LIMB_NAMES`` order), kept.
    limbs: which of ``LIMB_NAMES`` to re-solve (a limb whose base, mid or end joint has no bone is
    skipped).  ends: ``"source"`` puts the ends on the performer's wrist / ankle positions (mapped
    into the target's place and facing, not scaled: the character touches what the performer
    touched); ``"scaled"`` on the root bone's position plus the leg ratio times the source's
    pelvis-to-end offset (consistent with ``root_motion="scaled"``: a planted foot stays planted), for
    the feet from the character's own hips (:func:`_feet_rest_offsets`); a hand goes to the
    character's posed shoulder (its upper-arm bone's head) plus its arm ratio (upper arm + forearm,
    head to head, over the performer's) times the performer's shoulder-to-wrist offset, so it is in
    reach whatever the character's torso and legs are.
    end_positions: optional ``(T, L, 3)`` world targets for the ``limbs`` instead.

    Uses :func:`.limb_solver.solve_limbs` on the target's own upper / lower lengths with the
    source's collar / pelvis rotation as the swivel reference and the source wrist / ankle
    orientation for the forearm twist; hands and feet keep their transferred world orientation.
    Returns a new :class:`RetargetResult` with ``reach_error`` ``(T, 4)`` metres (NaN for limbs not
    re-solved): how far each end stayed from its target (out of reach, or closer than the elbow /
    knee folds).
    """
    world_rot, positions = _check_source(world_rot, positions)
    plan = res.plan
    F, bone_of = plan.F, plan.bone_of
    T = positions.shape[0]
    swivel = np.asarray(swivel, np.float64).reshape(T, 4)
    ids = []
    for name in limbs:
        li = LIMB_NAMES.index(name)
        _, b, m, e = LIMBS[li]
        if min(bone_of[b], bone_of[m], bone_of[e]) >= 0:
            ids.append(li)
    reach = np.full((T, 4), np.nan)
    targets_out = np.full((T, 4, 3), np.nan)
    if not ids:
        return res
    ids = np.array(ids)
    kb = bone_of[[LIMBS[i][1] for i in ids]]
    km = bone_of[[LIMBS[i][2] for i in ids]]
    ke = bone_of[[LIMBS[i][3] for i in ids]]
    jb = np.array([LIMBS[i][1] for i in ids])
    je = np.array([LIMBS[i][3] for i in ids])
    hw0 = plan.target.rest_world_heads()
    lengths = np.stack([np.linalg.norm(hw0[km] - hw0[kb], axis=-1), np.linalg.norm(hw0[ke] - hw0[km], axis=-1)], -1)

    def to_src(p):                                  # target world -> source frame
        return (p - plan.c_t) @ F + plan.c_s

    base_src = to_src(plan.target.to_world(res.heads[:, kb]))
    if end_positions is not None:
        tgt_w = np.asarray(end_positions, np.float64).reshape(T, len(ids), 3)
    elif ends == "source":
        tgt_w = (positions[:, je] - plan.c_s) @ F.T + plan.c_t
    elif ends == "scaled":
        off = (positions[:, je] - positions[:, :1]) @ F.T * plan.leg_ratio
        tgt_w = res.root_head_world[:, None] + off + _feet_rest_offsets(plan, ids)
        # a hand from the character's own shoulder, by its own arm's ratio: the leg ratio from the
        # hips put the hands of a rig whose arms or torso are proportioned otherwise than its legs
        # out of its arms' reach (elbows locked straight) or into them (elbows folded)
        arm = np.array([LIMB_NAMES[li].endswith("_arm") for li in ids])
        if arm.any():
            P = plan.body.rest_positions()
            jm = np.array([LIMBS[i][2] for i in ids])
            src_len = np.linalg.norm(P[jm] - P[jb], axis=-1) + np.linalg.norm(P[je] - P[jm], axis=-1)
            ratio = lengths.sum(-1) / src_len
            shoulder = plan.target.to_world(res.heads[:, kb])
            hand = shoulder + ratio[:, None] * ((positions[:, je] - positions[:, jb]) @ F.T)
            tgt_w[:, arm] = hand[:, arm]
    else:
        raise ValueError(f"ends must be 'source' or 'scaled', got {ends!r}")
    sol = solve_limbs(base_src, to_src(tgt_w), swivel[:, ids], lengths, world_rot[:, PARENTS[jb]],
                      end_rot=world_rot[:, je], limb_ids=ids)
    mapped = dict(res.mapped_world)
    for i, li in enumerate(ids):
        _, b, m, _ = LIMBS[li]
        mapped[int(bone_of[b])] = F @ sol.base_world[:, i] @ F.T @ plan.align[b]
        mapped[int(bone_of[m])] = F @ sol.mid_world[:, i] @ F.T @ plan.align[m]
    out = _assemble(plan, mapped, res.root_head_world)
    reach[:, ids] = sol.reach_error
    targets_out[:, ids] = tgt_w
    out.reach_error = reach
    out.end_targets = targets_out
    return out


def _feet_rest_offsets(plan: RetargetPlan, ids) -> np.ndarray:
    """``(L, 3)`` world offsets added to the scaled end targets of limbs ``ids``: for a leg, where
    the character's ankle sits from its root-motion bone's head at rest, less the leg ratio times
    where the performer's ankle sits from its pelvis (in the character's facing); zero for an arm.
    So a foot's target is the character's own rest ankle plus the leg ratio times the performer's
    ankle's displacement from its rest: the character stands on its own legs at rest, whatever
    bone its hips are (Blender's Human metarig's ``spine`` starts 6 cm *below* its thighs, the body
    model's pelvis 5 cm above its hips: measured from the pelvis, its feet's targets were 13 cm out
    of its legs' reach and its knees never bent).  Constant: a planted foot stays planted."""
    out = np.zeros((len(ids), 3))
    hw0 = plan.target.rest_world_heads()
    P = plan.body.rest_positions()
    for i, li in enumerate(ids):
        if LIMB_NAMES[li].endswith("_leg"):
            end = LIMBS[li][3]
            out[i] = (hw0[plan.bone_of[end]] - plan.root_rest_world) - plan.leg_ratio * (plan.F @ (P[end] - P[0]))
    return out


def retarget_pose_result(result, target: TargetRig, bone_map, root_motion: str = "scaled",
                         keep_ends: bool = False, ends: str = "source", facing_yaw=None) -> RetargetResult:
    """:func:`retarget` (and optionally :func:`keep_ends_on_targets`) of a ``PoseResult``."""
    pos, wrot = result.fk()
    res = retarget(wrot, pos, result.body, target, bone_map, root_motion, facing_yaw)
    if keep_ends:
        res = keep_ends_on_targets(res, wrot, pos, result.swivel, ends=ends)
    return res
