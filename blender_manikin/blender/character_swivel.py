"""Live swivel on the animator's character: after a retarget, edit an elbow or knee by its swivel.

:func:`build_character_rig` (called by :func:`.retarget_apply.retarget_onto` with
``live_swivel``) gives the retargeted character the four keyed swivel custom properties of the
solved body rig (``["swivel_left_arm"]`` ..., radians, the keys of the source's swivel: the one
:func:`..core.retarget.keep_ends_on_targets` used) and, for each limb whose shoulder / elbow /
wrist (hip / knee / ankle) are mapped, the mechanism of :mod:`.live_rig` built on the character's
own limb lengths, so changing a swivel value or key turns the elbow / knee about the
shoulder-wrist (hip-ankle) axis while the hand / foot stays where it is.  Everything is
constraints and simple-expression drivers stored in the .blend (no add-on needed to play it).

Added to the character (nothing of the user's is renamed or removed; names start with
:data:`PREFIX`; ``.L`` / ``.R`` = the performer's left / right; arms shown, legs use ``foot``,
``leg``, ``thigh``, ``shin``), none deforming, in the bone collections ``MANIKIN controls``
(the controls) and ``MANIKIN mechanism`` (hidden):

======================================  ===========================================================
``MANIKIN_ctrl_hand.L``                 hand control: no parent, rest = the character's hand bone
                                        (1.6x longer); keyed at the retargeted hand position
                                        (the keep-ends target) and orientation
``MANIKIN_MCH-arm_space.L``             swivel frame: child of the upper arm's parent bone at the
                                        shoulder, rest Y = ``F n0``, Z = ``F u0`` (the limb
                                        solver's neutral axis and zero-swivel direction turned
                                        into the character's facing ``F``), keyed so that it
                                        turns as the performer's collar / pelvis turns
``MANIKIN_MCH-arm_swivel.L``            child of the above: Euler Y = the swivel (driver), Damped
                                        Track to the control (:func:`.live_rig.setup_swivel_reference`)
``MANIKIN_MCH-arm_pole.L``              its child: the IK pole
``MANIKIN_MCH-upper_arm.L``,            straight two-bone IK chain on the character's head-to-head
``MANIKIN_MCH-forearm.L``               lengths, rest along ``F a0``, hinge axis ``F h0`` = local X
                                        (:func:`.live_rig.setup_ik_chain`: IK with pole, flexion
                                        driver, hinge limits)
``MANIKIN_MCH-forearm_twist.L``         arms: the forearm pronation (Transformation constraint:
``MANIKIN_MCH-hand_twist.L``            twist of the hand control in the IK forearm's frame,
                                        clamped to the forearm's range)
``MANIKIN_MCH-upper_arm_follow.L``,     children of the chain whose rest is the character's bone
``MANIKIN_MCH-forearm_follow.L``        "posed into the performer's rest" (``O_k G_k^0`` of
                                        :mod:`..core.retarget`): they carry the character's upper
                                        arm / forearm orientation
``MANIKIN_MCH-..._twist_space.L``       only where the map has twist bones: the segment's frame
                                        under its parent, to measure the twist they share
======================================  ===========================================================

Constraints added to the character's own bones (named ``MANIKIN ...``, appended to their stacks):
upper arm and forearm *Copy Transforms* (world) of their follow bones, the hand *Copy Rotation*
(world) of the control; with twist bones, the segment bone and each twist bone keep the share of
its twist :func:`..core.retarget.twist_shares` gives them by where they sit along it
(Transformation constraints, as :mod:`..core.retarget` shares it; twist bones must lie along the
segment, children of it or of the previous twist bone).

Why the live pose is the keep-ends pose: the chain is the body rig's turned by ``F``, with the
character's lengths, so it reproduces :func:`..core.limb_solver.solve_limbs` exactly (see
:mod:`.live_rig`); the follow bones then apply the constant ``(F M0)ᵀ O_k G_k^0`` that
:func:`..core.retarget.keep_ends_on_targets` applies to the solver's rotations
(``M0 = [h0, a0, h0×a0]``).  Without keep-ends (``live_swivel`` forced on) the limbs are solved
the same way onto the retargeted hand / foot positions with the source's swivel.

:func:`bake_character_rig` bakes the evaluated limbs into plain FK keys (a NEW action, the live
one kept) and removes (or mutes) the rig, for export; :func:`remove_character_rig` removes it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import bpy

from ..core import limb_solver as ls
from ..core import rotations as rot
from ..core import skeleton as sk
from . import keying
from . import live_rig
from . import writer

#: every bone the character rig adds starts with this
PREFIX = "MANIKIN_"
#: object custom property marking a character with the live swivel rig (value: format version)
PROP_RIG = "manikin_character_rig"
#: the action's custom property naming the live action a baked action came from
PROP_BAKED_FROM = "manikin_baked_from"


@dataclass(frozen=True)
class CharacterLimb:
    """Bones of one limb's rig on a character.  ``rig`` is a :class:`.live_rig.LimbRig` whose
    base / mid / end are the character's mapped bones and ctrl / ref / pole / upper / lower
    the added ones (what :func:`.live_rig.setup_ik_chain` and
    :func:`.live_rig.setup_swivel_reference` take)."""
    rig: live_rig.LimbRig
    parent: str            # the character's parent bone of its upper arm / thigh
    space: str             # keyed swivel frame (parent of rig.ref)
    follow_base: str
    follow_mid: str
    mid_twist: str | None  # arms: pronation
    end_twist: str | None
    twist_space_base: str | None
    twist_space_mid: str | None

    def added(self):
        r = self.rig
        return tuple(n for n in (r.ctrl, self.space, r.ref, r.pole, r.upper, r.lower, self.mid_twist,
                                 self.end_twist, self.follow_base, self.follow_mid, self.twist_space_base,
                                 self.twist_space_mid) if n)


def _names(li, base, mid, end, parent, twist_base, twist_mid):
    limb = sk.LIMB_NAMES[li]
    s = "L" if limb.startswith("left") else "R"
    arm = limb.endswith("arm")
    kind = "arm" if arm else "leg"
    up, lo = ("upper_arm", "forearm") if arm else ("thigh", "shin")
    m = f"{PREFIX}MCH-"
    rig = live_rig.LimbRig(limb=limb, index=li, is_arm=arm, base=base, mid=mid, end=end, parent=parent,
                           ctrl=f"{PREFIX}ctrl_{'hand' if arm else 'foot'}.{s}", ref=f"{m}{kind}_swivel.{s}",
                           pole=f"{m}{kind}_pole.{s}", upper=f"{m}{up}.{s}", lower=f"{m}{lo}.{s}")
    return CharacterLimb(rig=rig, parent=parent, space=f"{m}{kind}_space.{s}", follow_base=f"{m}{up}_follow.{s}",
                         follow_mid=f"{m}{lo}_follow.{s}", mid_twist=f"{m}{lo}_twist.{s}" if arm else None,
                         end_twist=f"{m}hand_twist.{s}" if arm else None,
                         twist_space_base=f"{m}{up}_twist_space.{s}" if twist_base else None,
                         twist_space_mid=f"{m}{lo}_twist_space.{s}" if twist_mid else None)


def is_character_rig(obj) -> bool:
    """True when ``obj`` is an armature with the live swivel rig of :func:`build_character_rig`."""
    return (obj is not None and getattr(obj, "type", None) == 'ARMATURE' and PROP_RIG in obj.keys())


def has_rig_parts(obj):
    """True when ``obj`` carries the rig's mark or any of its bones (e.g. after a failed build)."""
    return is_character_rig(obj) or any(b.name.startswith(PREFIX) for b in obj.data.bones)


def _frame(x, y):
    """Rotation with columns ``[x', y, x' × y]``: Y along ``y``, X = ``x`` made orthogonal to it."""
    y = rot.normalize(np.asarray(y, np.float64))
    x = rot.normalize(np.asarray(x, np.float64) - np.dot(x, y) * y)
    return np.stack([x, y, np.cross(x, y)], -1)


def _rest_frames(li, F):
    """``(M0, B_ref)`` of limb ``li`` in the source's facing turned by ``F`` (world axes): the IK
    chain's rest frame (X = hinge ``h0``, Y = limb ``a0``) and the swivel frame (Y = ``n0``,
    Z = ``u0`` made orthogonal to it, X = Y × Z)."""
    M0 = _frame(ls.H0[li], ls.A0[li])
    n0 = ls.N0[li]
    u0 = live_rig._u0_perp(li)
    Bref = np.stack([np.cross(n0, u0), n0, u0], -1)
    return F @ M0, F @ Bref


# --------------------------------------------------------------------------
# building
def _limbs_of(plan, notes):
    tg = plan.target
    out = []
    for li, (limb, b, m, e) in enumerate(sk.LIMBS):
        kb, km, ke = (int(plan.bone_of[j]) for j in (b, m, e))
        if min(kb, km, ke) < 0:
            notes.append(f"{limb.replace('_', ' ')}: not all of its bones are mapped; no live swivel")
            continue
        p = int(tg.parents[kb])
        if p < 0:
            notes.append(f"{limb.replace('_', ' ')}: {tg.names[kb]!r} has no parent bone; no live swivel")
            continue
        out.append((li, kb, km, ke, p))
    return out


def _twist_plan(plan, main, notes):
    """``[(twist bone index, relative share)]`` of the twist bones of segment bone ``main``:
    the share of the segment's twist a bone adds to its parent's (in all, each bone has the share
    :func:`..core.retarget.twist_shares` gave it, ``plan.twist_share``)."""
    tg = plan.target
    ids = plan.twist_main.get(main, [])
    absolute = {b: plan.twist_share[b] for b in [main] + list(ids)}
    out = []
    for t in ids:
        p = int(tg.parents[t])
        ym = tg.rest_rot[main][:, 1]
        yt = tg.rest_rot[t][:, 1]
        if p not in absolute or np.dot(ym, yt) < 0.999:
            notes.append(f"twist bone {tg.names[t]!r} is not along {tg.names[main]!r} under it or under "
                         f"the previous twist bone: it keeps its retargeted keys")
            continue
        out.append((t, absolute[t] - absolute[p]))
    return out


def _set_bone(eb, name, head, R, length, parent=None, connect=False):
    """Edit bone ``name`` (created or re-placed): head, rest rotation ``R`` (3x3, columns X Y Z,
    armature space), length; not deforming."""
    from mathutils import Matrix
    b = live_rig.free_edit_bone(eb, name)
    b.head = (0.0, 0.0, 0.0)
    b.tail = (0.0, float(max(length, 1e-4)), 0.0)
    b.roll = 0.0
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = head
    b.matrix = Matrix(M.tolist())
    if parent is not None:
        b.parent = eb[parent]
        b.use_connect = connect
    return b


def _create_bones(obj, limbs, plan, context):
    tg = plan.target
    W = tg.world_rot
    F = plan.F
    with live_rig._edit_mode(obj, context) as eb:
        for cl, (li, kb, km, ke, p) in limbs:
            r = cl.rig
            _, b, m, e = sk.LIMBS[li]
            hb, hm, he = tg.heads[kb], tg.heads[km], tg.heads[ke]
            l1, l2 = float(np.linalg.norm(hm - hb)), float(np.linalg.norm(he - hm))
            M0w, Brefw = _rest_frames(li, F)
            R_mch = W.T @ M0w
            R_ref = W.T @ Brefw
            # the control: the hand / foot bone's rest, longer
            end = eb[r.end]
            c = eb.get(r.ctrl) or eb.new(r.ctrl)
            c.use_deform, c.use_connect, c.parent = False, False, None
            c.head = end.head.copy()
            c.tail = end.head + (end.tail - end.head) * live_rig.CTRL_LENGTH
            c.roll = end.roll
            _set_bone(eb, cl.space, hb, R_ref, 0.5 * l1, cl.parent)
            _set_bone(eb, r.ref, hb, R_ref, 0.5 * l1, cl.space)
            _set_bone(eb, r.pole, hb + (l1 + l2) * R_ref[:, 2], R_ref, 0.1 * l1, r.ref)
            _set_bone(eb, r.upper, hb, R_mch, l1, cl.parent)
            elbow = hb + l1 * R_mch[:, 1]
            _set_bone(eb, r.lower, elbow, R_mch, l2, r.upper, connect=True)
            lower_parent = r.lower
            if cl.mid_twist:
                _set_bone(eb, cl.mid_twist, elbow, R_mch, 0.5 * l2, r.lower)
                lower_parent = cl.mid_twist
                # hand twist reference: posed = F R_end M0 (the solver's twist frame of the wrist)
                Be = tg.rest_rot[ke]
                _set_bone(eb, cl.end_twist, he, Be @ plan.align[e].T @ M0w, 0.5 * l2, r.ctrl)
            _set_bone(eb, cl.follow_base, hb, W.T @ plan.align[b], l1, r.upper)
            _set_bone(eb, cl.follow_mid, elbow, W.T @ plan.align[m], l2, lower_parent)
            if cl.twist_space_base:
                _set_bone(eb, cl.twist_space_base, hb, tg.rest_rot[kb], 0.5 * l1, cl.parent)
            if cl.twist_space_mid:
                pm = int(tg.parents[km])
                # under the upper segment's full (unshared) frame when the mid bone hangs from it
                # or from one of its twist bones (Daz's lShldrTwist above lForearmBend)
                if (pm == kb or pm in plan.twist_main.get(kb, ())) and cl.twist_space_base:
                    R = W.T @ plan.align[b] @ tg.rest_rot[kb].T @ tg.rest_rot[km]
                    _set_bone(eb, cl.twist_space_mid, hm, R, 0.5 * l2, cl.follow_base)
                else:
                    _set_bone(eb, cl.twist_space_mid, hm, tg.rest_rot[km], 0.5 * l2, tg.names[pm])
    _bone_collections(obj, [cl for cl, _ in limbs])


def _bone_collections(obj, limbs):
    arm = obj.data
    if "collections" not in arm.bl_rna.properties:
        return
    colls = arm.collections
    ctrl = colls.get(live_rig.COLL_CTRL) or colls.new(live_rig.COLL_CTRL)
    mch = colls.get(live_rig.COLL_MCH) or colls.new(live_rig.COLL_MCH)
    mch.is_visible = False
    for cl in limbs:
        for name in cl.added():
            bone = arm.bones[name]
            for c in list(bone.collections):          # new bones join the active collection
                c.unassign(bone)
            (ctrl if name == cl.rig.ctrl else mch).assign(bone)
        b = arm.bones[cl.rig.ctrl]
        if hasattr(b, "color"):
            b.color.palette = 'THEME09' if cl.rig.limb.startswith("left") else 'THEME04'


def _setup_constraints(obj, limbs, plan, notes):
    tg = plan.target
    pbs = obj.pose.bones
    for cl, (li, kb, km, ke, p) in limbs:
        r = cl.rig
        for name in cl.added():
            pbs[name].rotation_mode = 'QUATERNION'
            pbs[name].rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
            pbs[name].location = (0.0, 0.0, 0.0)
        live_rig.setup_swivel_reference(obj, r)
        live_rig.setup_ik_chain(obj, r)
        if cl.mid_twist:
            lim = ls.TWIST_RANGE[li]
            live_rig.twist_constraint(obj, pbs[cl.mid_twist], "pronation", cl.end_twist, r.lower, lim, lim)
        for bone, follow, space, main in ((r.base, cl.follow_base, cl.twist_space_base, kb),
                                          (r.mid, cl.follow_mid, cl.twist_space_mid, km)):
            c = live_rig._constraint(pbs[bone], 'COPY_TRANSFORMS', "follow IK")
            c.target, c.subtarget = obj, follow
            c.owner_space = c.target_space = 'WORLD'
            if space is None:
                continue
            k = 1.0 - plan.twist_share[main]          # turned back by what it does not keep
            live_rig.twist_constraint(obj, pbs[bone], "twist share", follow, space, (-np.pi, np.pi),
                                      (k * np.pi, -k * np.pi), 'AFTER')
            for t, share in _twist_plan(plan, main, []):
                live_rig.twist_constraint(obj, pbs[tg.names[t]], "twist share", follow, space, (-np.pi, np.pi),
                                          (-share * np.pi, share * np.pi), 'REPLACE')
        c = live_rig._constraint(pbs[r.end], 'COPY_ROTATION', "hand rotation" if r.is_arm else "foot rotation")
        c.target, c.subtarget = obj, r.ctrl
        c.owner_space = c.target_space = 'WORLD'
        c.mix_mode = 'REPLACE'
        c.use_x = c.use_y = c.use_z = True


def _parent_orientations(obj, res, parents, frames, context):
    """``({bone index: (T, 3, 3)}, {bone index: (T, 3)})``: armature-space orientation of each of
    ``parents`` on every frame -- the retarget's own where the bone and the bones up to the
    nearest keyed one carry no constraints, else as Blender evaluates the rig (the retarget's
    action assigned) -- and, for those evaluated, how far (armature units) Blender puts the bone's
    head from where the retarget's arithmetic does (zero where it agrees; a generated Rigify rig's
    ORG-shoulder follows the shoulder control, which the arithmetic keeps at rest: 12 cm)."""
    tg = res.plan.target
    out, shift, evaluate = {}, {}, []
    for p in set(parents):
        k, constrained = p, False
        while k >= 0:
            if len(obj.pose.bones[tg.names[k]].constraints):
                constrained = True
                break
            if res.keyed[k]:          # a keyed bone ends where the retarget put it
                break
            k = int(tg.parents[k])
        if constrained:
            evaluate.append(p)
        else:
            out[p] = res.orientations[:, p]
    if evaluate:
        scene = context.scene
        keep = scene.frame_current, scene.frame_subframe
        G = np.empty((len(frames), len(evaluate), 3, 3))
        H = np.empty((len(frames), len(evaluate), 3))
        try:
            for t, f in enumerate(frames):
                scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
                for i, p in enumerate(evaluate):
                    M = np.array(obj.pose.bones[tg.names[p]].matrix)
                    G[t, i] = rot.orthonormalize(M[:3, :3])
                    H[t, i] = M[:3, 3]
        finally:
            scene.frame_set(keep[0], subframe=keep[1])
        for i, p in enumerate(evaluate):
            out[p] = G[:, i]
            shift[p] = H[:, i] - res.heads[:, p]
    return out, shift


def character_channels(obj, res, limbs, world_rot, swivel, context, frames):
    """The channels :func:`build_character_rig` keys, ``(data_path, index, group, values)``:
    each control's location (bone rest frame, armature units) and rotation, each swivel frame's
    rotation (relative to its parent bone), the swivel and solved-swivel properties."""
    plan = res.plan
    tg = plan.target
    W, F = tg.world_rot, plan.F
    bones = obj.data.bones
    G_par, moved = _parent_orientations(obj, res, [p for _, (_, _, _, _, p) in limbs], frames, context)
    sw = writer.unwrap_swivel(swivel)
    ch = []
    for cl, (li, kb, km, ke, p) in limbs:
        r = cl.rig
        # control: the hand / foot bone's orientation, at the end target
        A = np.array(bones[r.ctrl].matrix_local, dtype=np.float64)
        B = rot.orthonormalize(A[:3, :3])
        if res.end_targets is not None and np.isfinite(res.end_targets[:, li]).all():
            target = tg.to_armature(res.end_targets[:, li])
        else:
            target = res.heads[:, ke]
        if p in moved:
            # the limb's base where Blender puts it (its parent following the rig's mechanism, not
            # as the retarget's arithmetic has it): the plain keys' hand / foot is moved with it
            Gp = G_par[p]
            hb = tg.heads[kb] - tg.heads[p]
            base = res.heads[:, p] + moved[p] + np.einsum("tij,j->ti", Gp, tg.rest_rot[p].T @ hb)
            target = target + base - res.heads[:, kb]
        loc = (target - A[:3, 3]) @ B
        q = rot.quat_continuous(rot.matrix_to_quat(rot.orthonormalize(B.T @ res.orientations[:, ke])), axis=0)
        for i in range(3):
            ch.append((f'pose.bones["{r.ctrl}"].location', i, live_rig.CTRL_GROUP, loc[:, i]))
        for i in range(4):
            ch.append((f'pose.bones["{r.ctrl}"].rotation_quaternion', i, live_rig.CTRL_GROUP, q[:, i]))
        # swivel frame: the performer's collar / pelvis turn (F R_par Fᵀ) on the rest frame F B_ref
        _, b, _, _ = sk.LIMBS[li]
        _, Brefw = _rest_frames(li, F)
        want = W.T @ F @ world_rot[:, sk.PARENTS[b]] @ F.T @ Brefw
        Bs = rot.orthonormalize(np.array(bones[cl.space].matrix_local, dtype=np.float64)[:3, :3])
        Bp = rot.orthonormalize(np.array(bones[cl.parent].matrix_local, dtype=np.float64)[:3, :3])
        Q = Bs.T @ Bp @ np.swapaxes(G_par[p], -1, -2) @ want
        q = rot.quat_continuous(rot.matrix_to_quat(rot.orthonormalize(Q)), axis=0)
        for i in range(4):
            ch.append((f'pose.bones["{cl.space}"].rotation_quaternion', i, cl.space, q[:, i]))
        ch.append((f'["{writer.SWIVEL_PROPS[r.limb]}"]', 0, writer.SWIVEL_GROUP, sw[:, li]))
        ch.append((f'["{live_rig.SOLVED_PROPS[r.limb]}"]', 0, live_rig.SOLVED_GROUP, sw[:, li]))
    return ch


def build_character_rig(obj, res, frames, world_rot, swivel, action=None, context=None,
                        interpolation: str = 'LINEAR'):
    """Give the retargeted character ``obj`` keyed swivel properties and the live swivel rig.

    res: the :class:`..core.retarget.RetargetResult` keyed on ``obj`` (its plan names the bones);
    frames: ``(T,)`` scene frames of its keys; world_rot: ``(T, 22, 3, 3)`` the source's world
    rotations (body-model convention); swivel: ``(T, 4)`` radians, the swivel the limbs were
    solved with (``LIMB_NAMES`` order).  action: where to key (default: ``obj``'s current action,
    the retarget's new one).  Adds the bones and constraints of the module docstring (an earlier
    rig of this module is removed first) and keys the controls, swivel frames and the
    ``["swivel_<limb>"]`` / ``["swivel_solved_<limb>"]`` properties.  Returns notes for the user
    (limbs left out, twist bones kept on their keys, ...).
    """
    context = context or bpy.context
    if obj is None or obj.type != 'ARMATURE':
        raise TypeError("the live swivel rig needs an armature object")
    plan = res.plan
    frames = np.asarray(frames, dtype=np.float64)
    world_rot = np.asarray(world_rot, np.float64)
    swivel = np.asarray(swivel, np.float64).reshape(len(frames), 4)
    if action is None:
        action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        raise ValueError(f"{obj.name!r} has no action to key the live swivel into")
    if has_rig_parts(obj):
        remove_character_rig(obj, context)
    notes = []
    limbs = []
    for li, kb, km, ke, p in _limbs_of(plan, notes):
        tb = kb in plan.twist_main
        tm = km in plan.twist_main
        limbs.append((_names(li, plan.target.names[kb], plan.target.names[km], plan.target.names[ke],
                             plan.target.names[p], tb, tm), (li, kb, km, ke, p)))
        for main in ((kb,) if tb else ()) + ((km,) if tm else ()):
            _twist_plan(plan, main, notes)
    if not limbs:
        notes.append("no limb has its three bones mapped: no live swivel on the character")
        return notes
    if obj.pose.ik_solver != 'LEGACY':
        notes.append("the character uses the iTaSC IK solver: the live swivel is exact with the "
                     "Standard one (Armature > Inverse Kinematics)")
    try:
        _create_bones(obj, limbs, plan, context)
        writer.ensure_swivel_properties(obj)
        live_rig._ensure_solved_properties(obj)
        _setup_constraints(obj, limbs, plan, notes)
        ch = character_channels(obj, res, limbs, world_rot, swivel, context, frames)
        fcs = keying.key_channels(action, obj, frames, ch, interpolation)
        for fc in fcs:
            if fc.data_path.startswith('["swivel_solved_'):
                fc.lock = True
                fc.hide = True
        obj[PROP_RIG] = 1
    except BaseException:
        remove_character_rig(obj, context)
        raise
    obj.update_tag()
    context.view_layer.update()
    return notes


# --------------------------------------------------------------------------
# removing and baking
def _remove_fcurves(action, obj, pred):
    """Remove the F-curves of ``action`` (``obj``'s slot) whose data path satisfies ``pred``."""
    fcs = [fc for fc in keying.action_fcurves(action, obj) if pred(fc.data_path)]
    if not fcs:
        return 0
    if keying.is_slotted(action):
        slot = keying.find_slot(action, obj)
        for layer in action.layers:
            for strip in layer.strips:
                bag = strip.channelbag(slot) if slot is not None else None
                if bag is None:
                    continue
                for fc in list(bag.fcurves):
                    if pred(fc.data_path):
                        bag.fcurves.remove(fc)
    else:
        for fc in fcs:
            action.fcurves.remove(fc)
    return len(fcs)


def _rig_path(path):
    """True for the data paths of the rig: its bones' channels and the swivel properties."""
    return (f'pose.bones["{PREFIX}' in path or path.startswith('["swivel_')
            or path.startswith(f'["{PROP_RIG}'))


def remove_character_rig(obj, context=None):
    """Remove what :func:`build_character_rig` added to ``obj``: its bones, the ``MANIKIN ...``
    constraints, the drivers of its bones, its (empty) bone collections and the swivel
    properties.  Actions are left as they are.  Returns the number of bones removed."""
    context = context or bpy.context
    ad = obj.animation_data
    if ad is not None:
        for fc in list(ad.drivers):
            if f'pose.bones["{PREFIX}' in fc.data_path:
                ad.drivers.remove(fc)
    for pb in obj.pose.bones:
        for c in list(pb.constraints):
            if live_rig.is_rig_constraint(c):
                pb.constraints.remove(c)
    n = sum(1 for b in obj.data.bones if b.name.startswith(PREFIX))
    if n:
        with live_rig._edit_mode(obj, context) as eb:
            for b in [b for b in eb if b.name.startswith(PREFIX)]:
                eb.remove(b)
    arm = obj.data
    if "collections" in arm.bl_rna.properties:
        for name in (live_rig.COLL_CTRL, live_rig.COLL_MCH):
            c = arm.collections.get(name)
            if c is not None and not len(c.bones):
                arm.collections.remove(c)
    for key in [PROP_RIG] + list(writer.SWIVEL_PROPS.values()) + list(live_rig.SOLVED_PROPS.values()):
        if key in obj.keys():
            del obj[key]
    obj.update_tag()
    return n


def rig_driven_bones(obj):
    """The character's own bones the rig drives (those with ``MANIKIN ...`` constraints), parents first."""
    return [b.name for b in obj.data.bones
            if not b.name.startswith(PREFIX)
            and any(live_rig.is_rig_constraint(c) for c in obj.pose.bones[b.name].constraints)]


def bake_character_rig(obj, frame_start=None, frame_end=None, context=None, remove_rig: bool = True,
                       interpolation: str = 'LINEAR'):
    """Bake the live swivel rig of character ``obj`` into plain FK keys; returns the new action.

    Every integer scene frame in ``[frame_start, frame_end]`` (default: the live action's frame
    range) is evaluated and the bones the rig drives (:func:`rig_driven_bones`: upper arms,
    forearms, hands, thighs, shins, feet and their twist bones) get rotation keys on each, in each
    bone's own rotation mode (the character's other actions keep playing; ``location`` too where
    the pose moved a bone off its rest offset).  The new action
    (``<live action>_baked``) is a copy of the live one with those curves replaced and the rig's
    own curves (controls, swivel frames, swivel properties) left out; it is assigned, the live
    action is kept (fake user).  remove_rig: remove the rig (:func:`remove_character_rig`), so
    the character is plain again for export; False mutes its constraints instead.
    """
    context = context or bpy.context
    if not is_character_rig(obj):
        raise ValueError(f"{obj.name!r} has no live swivel rig to bake")
    ad = obj.animation_data
    live = ad.action if ad is not None else None
    if live is None:
        raise ValueError(f"{obj.name!r} has no action to bake")
    if frame_start is None or frame_end is None:
        f0, f1 = live.frame_range
        frame_start = int(np.floor(f0)) if frame_start is None else frame_start
        frame_end = int(np.ceil(f1)) if frame_end is None else frame_end
    frame_start, frame_end = live_rig.check_frame_range(frame_start, frame_end)
    names = rig_driven_bones(obj)
    if not names:
        raise ValueError(f"{obj.name!r}: no bone follows the rig")
    bones = obj.data.bones
    parents = [bones[n].parent.name if bones[n].parent is not None else None for n in names]
    frames = np.arange(frame_start, frame_end + 1)
    # each bone keyed in its own rotation mode: the character's other actions still play on it
    ch = live_rig.fk_key_channels(obj, names, parents, frames, context,
                                  modes={n: obj.pose.bones[n].rotation_mode for n in names})

    action = live.copy()
    action.name = f"{live.name}_baked"
    action.use_fake_user = True
    action[PROP_BAKED_FROM] = live.name
    live.use_fake_user = True
    try:
        keying.assign_action(obj, action)
        _remove_fcurves(action, obj, _rig_path)
        keying.key_channels(action, obj, frames.astype(np.float64), ch, interpolation)
    except BaseException:
        keying.assign_action(obj, live)
        bpy.data.actions.remove(action)
        raise
    if remove_rig:
        remove_character_rig(obj, context)
    else:
        live_rig.set_rig_enabled(obj, False)
    return action
