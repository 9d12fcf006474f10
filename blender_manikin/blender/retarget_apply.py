"""Put a MANIKIN solve onto another armature (Blender glue of :mod:`..core.retarget`).

gather → create, as the solve does:

1. :func:`target_rig_from_object` reads the target's rest (``bone.matrix_local``, parents, the
   object's ``matrix_world``) and :func:`sample_source` the MANIKIN armature's motion: from its
   FK keys when it is a plain FK solve (no evaluation), else by evaluating the live rig frame by
   frame (``frame_set``: about a millisecond a frame);
2. the numpy core retargets (:func:`..core.retarget.retarget`, and with ``keep_ends`` the hands
   and feet are solved again on the target's own limb lengths);
3. :func:`key_retarget` writes a NEW action on the target: the rotation of every mapped (and
   twist) bone, in the bone's own rotation mode (quaternion, Euler or axis-angle keys,
   :func:`.keying.rotation_channels`: the character's other actions, keyed in those modes, still
   play), and the root bone's ``location``, bulk-keyed on both action APIs.  The target's
   previous action is kept (with a fake user) and never modified; the keyed bones and their
   modes are recorded in the action's ``manikin_rotation_modes`` custom property.  All or
   nothing: on an error the new action is removed and the previous one assigned back.

Frames are scene frames; positions in the scene's unit (the solve is written in it,
:mod:`.units`; the core's "metres" are whatever unit its inputs share); the MANIKIN armature is
expected at the world origin (its ``matrix_world`` is applied anyway).
"""
from __future__ import annotations

import numpy as np

import bpy
from mathutils import Matrix

from ..core import bone_maps
from ..core import retarget as rt
from ..core import rotations as rot
from ..core import skeleton as sk
from . import armature as arm_mod
from . import keying, writer

#: action custom property: the keyed bones' rotation modes before the retarget (JSON-like dict)
PROP_MODES = "manikin_rotation_modes"


def target_rig_from_object(obj) -> rt.TargetRig:
    """The :class:`~..core.retarget.TargetRig` of armature object ``obj`` at rest."""
    if obj is None or obj.type != 'ARMATURE':
        raise TypeError("the retarget target must be an armature object")
    bones = _own_bones(obj)
    names = [b.name for b in bones]
    parents = [b.parent.name if b.parent is not None else None for b in bones]
    A = np.array([np.array(b.matrix_local, dtype=np.float64) for b in bones]).reshape(len(bones), 4, 4)
    return rt.TargetRig.from_matrices(names, parents, A, np.array(obj.matrix_world, dtype=np.float64))


def _own_bones(obj):
    """The character's own bones: all but those a live swivel rig added
    (:mod:`.character_swivel`, removed and rebuilt by a new retarget)."""
    from .character_swivel import PREFIX
    return [b for b in obj.data.bones if not b.name.startswith(PREFIX)]


def bone_list(obj):
    """``[(name, parent, head (3,), tail (3,))]`` of ``obj``'s bones in armature space (for
    :func:`..core.bone_maps.guess_bone_map`)."""
    return [(b.name, b.parent.name if b.parent else None, np.array(b.head_local), np.array(b.tail_local))
            for b in _own_bones(obj)]


def resolve_bone_map(choice, target_obj, path=None):
    """``(BoneMap, notes)`` for the panel's / command line's choice: ``"auto"`` (guessed from the
    target's bone names and hierarchy: notes list each joint's bone and why), a preset name of
    :data:`..core.bone_maps.PRESETS` (fitted to the rig, :func:`..core.bone_maps.fit_preset`:
    its twist lists, and joints whose bone the rig lacks left out, each with a note), ``"file"``
    with ``path`` (a saved map, JSON), or a :class:`..core.bone_maps.BoneMap` (the panel's
    edited list), used as it is."""
    if isinstance(choice, bone_maps.BoneMap):
        return choice, []
    key = str(choice or "auto").lower()
    if key == "auto":
        bmap, notes = bone_maps.guess_bone_map(bone_list(target_obj))
        # a generated Rigify rig's DEF bones and a live Auto-Rig Pro rig's deforming bones follow
        # their controls through constraints: the FK controls are what to key
        if bmap.name == "rigify" and _is_generated_rigify(target_obj):
            return bone_maps.preset("rigify_fk"), notes
        if bmap.name == "auto_rig_pro" and _is_live_auto_rig_pro(target_obj):
            key = "auto_rig_pro_fk"
        else:
            return bmap, notes
    elif key == "file":
        if not path:
            raise ValueError("no bone map file chosen")
        return bone_maps.load_bone_map(path), []
    bones = bone_list(target_obj)
    try:
        bmap, missing = bone_maps.fit_preset(bone_maps.preset(key), bones)
    except ValueError:
        # not a rig of that kind: the preset as it is (the map editor shows which of its bones the
        # character lacks; the retarget refuses it, naming them)
        return bone_maps.fit_twist(bone_maps.preset(key), bones), []
    return bmap, [bone_maps.GuessNote(j, None, 0.0, f"the rig has no {b!r}: folded into its neighbours")
                  for j, b in missing]


def _is_generated_rigify(obj):
    """A rig generated by Rigify (its DEF bones follow its controls through constraints)."""
    bones = obj.data.bones
    return "upper_arm_fk.L" in bones and "DEF-upper_arm.L" in bones


def _is_live_auto_rig_pro(obj):
    """An Auto-Rig Pro rig with its controls (not an export of its deforming bones)."""
    bones = obj.data.bones
    return "c_arm_fk.l" in bones and "c_thigh_fk.l" in bones and "arm_stretch.l" in bones


#: IK/FK switch properties (pose bone custom properties; 1 is FK): Rigify's ``IK_FK`` (on the
#: limbs' parent controls), Auto-Rig Pro's ``ik_fk_switch`` (on c_hand_ik.l, c_foot_ik.l, ...)
IK_FK_PROPERTIES = ("IK_FK", "ik_fk_switch")


def _ik_fk_switches(obj, bmap):
    """``[(pose bone, property)]``: the IK/FK switches of a generated Rigify rig or a live
    Auto-Rig Pro rig that must be 1 (FK) for the FK controls ``bmap`` keys to move the limbs."""
    if not any(b.endswith(("_fk.L", "_fk.R", "_fk.l", "_fk.r")) for b in bmap.bones.values()):
        return []
    return [(pb.name, p) for pb in obj.pose.bones for p in IK_FK_PROPERTIES if p in pb.keys()]


def _frames_of(action, obj):
    """Scene frames of the keys of ``action`` (its pelvis rotation curve, else any curve)."""
    fcs = keying.action_fcurves(action, obj)
    if not fcs:
        raise ValueError(f"action {action.name!r} has no keys")
    fc = next((f for f in fcs if f.data_path == 'pose.bones["pelvis"].rotation_quaternion'), fcs[0])
    co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
    fc.keyframe_points.foreach_get("co", co)
    return co[0::2].astype(np.float64)


def sample_source(obj, context=None, frames=None, progress=None):
    """The motion of the MANIKIN armature ``obj``: ``(frames (T,), world_rot (T, 22, 3, 3),
    positions (T, 22, 3) metres, swivel (T, 4) radians, body)``, body-model convention (identity =
    rest T-pose).  frames: scene frames (default: the keys of its action).  progress: called with
    the fraction 0-1 sampled so far while a live rig is evaluated frame by frame."""
    from . import live_rig
    context = context or bpy.context
    if obj is None or arm_mod.PROP_BODY not in obj.keys():
        raise ValueError("choose a solved MANIKIN armature as the source")
    ad = obj.animation_data
    if ad is None or ad.action is None:
        raise ValueError(f"{obj.name!r} has no action to retarget")
    body = live_rig._body_from_object(obj)
    if frames is None:
        frames = _frames_of(ad.action, obj)
    frames = np.asarray(frames, dtype=np.float64)
    W = np.array(obj.matrix_world, dtype=np.float64)
    Rw = rot.orthonormalize(W[:3, :3])
    if not live_rig.is_live_rig(obj):           # plain FK keys: read them, no evaluation
        fps = float(context.scene.render.fps) / float(context.scene.render.fps_base)
        res, key_frames = live_rig.result_from_fk_action(obj, fps)
        if len(key_frames) == len(frames) and np.allclose(key_frames, frames):
            pos, wr = res.fk()                  # armature space: into the world, as evaluated below
            return frames, Rw @ wr, pos @ W[:3, :3].T + W[:3, 3], res.swivel, body
    # the live rig: Blender evaluates it frame by frame (constraints, drivers); the matrices are
    # read in bulk and converted all at once (not in Edit Mode, where it is not evaluated)
    live_rig.check_pose_evaluated(obj)
    _, rest = arm_mod.rest_matrices(obj)
    scene = context.scene
    keep = scene.frame_current, scene.frame_subframe
    T = len(frames)
    M = np.empty((T, sk.NUM_JOINTS, 4, 4), np.float32)        # as Blender stores them
    swivel = np.zeros((T, 4))
    from .writer import SWIVEL_PROPS
    order = [obj.pose.bones.find(n) for n in sk.JOINT_NAMES]
    props = [SWIVEL_PROPS[limb] for limb in sk.LIMB_NAMES]
    try:
        for t, f in enumerate(frames):
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
            M[t] = live_rig.evaluated_pose_matrices(obj.evaluated_get(context.evaluated_depsgraph_get()), order)
            swivel[t] = [float(obj.get(p, 0.0)) for p in props]
            if progress is not None and t % 500 == 0:
                progress(t / T)
    finally:
        scene.frame_set(keep[0], subframe=keep[1])
    wr = Rw @ rot.orthonormalize(M[..., :3, :3]) @ np.swapaxes(rest, -1, -2)
    pos = M[..., :3, 3] @ W[:3, :3].T + W[:3, 3]
    return frames, wr, pos, swivel, body


def _constrained_parents(obj, target: rt.TargetRig, keyed):
    """True when a keyed bone's parent chain (up to the nearest keyed ancestor) holds a bone with
    constraints: its parent then moves as the rig's mechanism says, not as its rest relation to
    the keyed ancestor says (e.g. Rigify's MCH and ORG bones), and the bases must be taken from
    the evaluated parents (:func:`_bases_from_evaluated_parents`)."""
    keyed = set(keyed)
    for k in keyed:
        p = target.parents[k]
        while p >= 0 and p not in keyed:
            if len(obj.pose.bones[target.names[p]].constraints):
                return True
            p = target.parents[p]
    return False


#: constraint types that set a bone's rotation themselves: keys on the bone do not show under them
_OVERRIDING = frozenset({'COPY_ROTATION', 'COPY_TRANSFORMS', 'CHILD_OF', 'DAMPED_TRACK', 'LOCKED_TRACK',
                         'TRACK_TO', 'STRETCH_TO', 'IK', 'SPLINE_IK', 'ARMATURE', 'TRANSFORM'})


def overriding_constraints(obj, names):
    """``[(bone, constraint name)]``: the bones ``names`` of ``obj`` with an active constraint
    (not muted, influence above 0) that sets their rotation itself (Copy Transforms / Rotation,
    Child Of, tracking, Stretch To, IK, Armature, Transformation): while it is on, the keys the
    retarget gives those bones do not show (e.g. the DEF bones of a generated Rigify rig, or the
    deforming bones of a rig whose controls drive them)."""
    out = []
    for n in names:
        pb = obj.pose.bones.get(n)
        for c in (pb.constraints if pb is not None else ()):
            if c.type in _OVERRIDING and not c.mute and c.influence > 0.0:
                out.append((n, c.name))
                break
    return out


def _bases_from_evaluated_parents(obj, res: rt.RetargetResult, target: rt.TargetRig, keyed, context):
    """``(quaternions (T, B, 4), root_location (T, 3))`` putting each keyed bone at its retargeted
    armature-space orientation (and the root bone at its head) under its parent *as the rig
    evaluates it*: ``Q_k = B_kᵀ B_p G_pᵀ G_k`` with ``G_p`` the evaluated parent (the pose-bone
    composition of :mod:`..core.retarget`).  Keyed bones are set depth by depth in the rig's
    hierarchy (the depsgraph updated in between) on each frame; tens of milliseconds a frame on
    a generated Rigify rig.  The bones' own pose values are restored afterwards."""
    # by depth in the whole hierarchy: a keyed bone's mechanism (e.g. Rigify's ORG-shoulder,
    # copying the shoulder control) sits above it, so the keyed bones it follows are set first
    keyed = [k for k in target.order if k in set(keyed)]
    depths = sorted({int(target.depth[k]) for k in keyed})
    levels = [[k for k in keyed if target.depth[k] == d] for d in depths]
    pbs = {k: obj.pose.bones[target.names[k]] for k in keyed}
    saved = {k: (pb.rotation_mode, tuple(pb.rotation_quaternion), tuple(pb.location)) for k, pb in pbs.items()}
    root = target.index.get(res.root_bone) if res.root_bone is not None else None
    B, h0 = target.rest_rot, target.heads
    T = res.quaternions.shape[0]
    Q = np.array(res.quaternions, copy=True)
    loc = np.array(res.root_location, copy=True)
    try:
        for pb in pbs.values():
            pb.rotation_mode = 'QUATERNION'
        for t in range(T):
            for lv in levels:
                context.view_layer.update()
                for k in lv:
                    pb = pbs[k]
                    G = res.orientations[t, k]
                    if pb.parent is None:
                        q_mat = B[k].T @ G
                        rel_h = res.heads[t, k] - h0[k]
                        rel_h0 = np.zeros(3)
                    else:
                        p = target.index[pb.parent.name]
                        Mp = np.array(pb.parent.matrix, dtype=np.float64)
                        Gp = rot.orthonormalize(Mp[:3, :3])
                        q_mat = B[k].T @ B[p] @ Gp.T @ G
                        rel_h = B[p] @ Gp.T @ (res.heads[t, k] - Mp[:3, 3])
                        rel_h0 = h0[k] - h0[p]
                    Q[t, k] = rot.matrix_to_quat(rot.orthonormalize(q_mat))
                    pb.rotation_quaternion = Q[t, k]
                    if k == root:
                        loc[t] = B[k].T @ (rel_h - rel_h0)
                        pb.location = loc[t]
        Q[:, keyed] = rot.quat_continuous(Q[:, keyed], axis=0)
    finally:
        for k, (mode, q, lc) in saved.items():
            pbs[k].rotation_mode = mode
            pbs[k].rotation_quaternion = q
            pbs[k].location = lc
        context.view_layer.update()
    return Q, loc


def key_retarget(target_obj, res: rt.RetargetResult, target: rt.TargetRig, frames, name, interpolation='LINEAR',
                 switches=()):
    """A NEW action ``name`` on ``target_obj`` with the keys of ``res``; returns it.  The previous
    action stays (fake user), the keyed bones' rotation modes are recorded (:data:`PROP_MODES`).
    switches: ``[(pose bone, property)]`` IK/FK switches keyed to 1 (FK) in the action (a Rigify or
    Auto-Rig Pro rig keyed on its FK controls, :func:`_ik_fk_switches`), so the rig itself is not
    changed."""
    keyed = [k for k in range(target.num_bones) if res.keyed[k]]
    before = keying.active_assignment(target_obj)
    prev = before[0]
    action = keying.new_action(name)
    try:
        modes = {}
        for k in keyed:
            pb = target_obj.pose.bones[target.names[k]]
            modes[pb.name] = pb.rotation_mode
        action[PROP_MODES] = modes
        keying.keep_active_action(target_obj)
        keying.assign_action(target_obj, action)
        _rest_bones_no_longer_keyed(target_obj, prev, set(modes))
        # the switches first: the bases below are taken with the rig in FK
        keying.key_channels(action, target_obj, frames,
                            [(f'pose.bones["{b}"]["{p}"]', 0, b, np.ones(len(frames))) for b, p in switches],
                            'CONSTANT')
        quats, root_loc = res.quaternions, res.root_location
        if _constrained_parents(target_obj, target, keyed):
            if switches:
                bpy.context.scene.frame_set(int(frames[0]))
            quats, root_loc = _bases_from_evaluated_parents(target_obj, res, target, keyed, bpy.context)
        # each bone keyed in its own rotation mode: the character's other actions still play on it
        names = [target.names[k] for k in keyed]
        ch = keying.rotation_channels(names, quats[:, keyed],
                                      [target_obj.pose.bones[n].rotation_mode for n in names])
        if res.root_bone is not None:
            rb = res.root_bone
            for i in range(3):
                ch.append((f'pose.bones["{rb}"].location', i, rb, root_loc[:, i]))
        keying.key_channels(action, target_obj, frames, ch, interpolation)
    except BaseException:
        keying.restore_assignment(target_obj, before)
        bpy.data.actions.remove(action)
        raise
    return action


def _rest_bones_no_longer_keyed(target_obj, prev, keyed_names):
    """Bones an earlier retarget keyed (``prev``, the action it made) that this one does not (a
    map with fewer bones, twist bones taken out) would keep that action's last evaluated pose once
    the new action is assigned (Blender leaves channels without F-curves where they were): put
    them back at rest, in their own rotation mode again, as the retarget's math assumes
    (unmapped bones at rest under their parent).  Bones of the animator's own are not touched."""
    earlier = prev.get(PROP_MODES) if prev is not None else None
    if not earlier:
        return
    for name, mode in dict(earlier).items():
        pb = target_obj.pose.bones.get(name)
        if pb is None or name in keyed_names:
            continue
        pb.matrix_basis = Matrix.Identity(4)
        pb.rotation_mode = mode


def copy_contacts(source_obj, source_action, target_obj, action, frames):
    """Key the solve's foot contacts (:data:`.writer.CONTACT_PROPS`, step curves) of
    ``source_action`` onto ``target_obj`` in ``action`` at ``frames``: the character carries the
    footstep events too.  Nothing when the source has none (a solve from before they were keyed)."""
    paths = {f'["{name}"]' for name in writer.CONTACT_PROPS.values()}
    curves = {fc.data_path: fc for fc in keying.action_fcurves(source_action, source_obj) if fc.data_path in paths}
    if not curves:
        return
    writer.ensure_contact_properties(target_obj)
    frames = np.asarray(frames, np.float64)
    channels = []
    for path, fc in sorted(curves.items()):
        n = len(fc.keyframe_points)
        if n == 0:
            continue
        co = np.empty(2 * n, np.float32)
        fc.keyframe_points.foreach_get("co", co)
        co = co.reshape(n, 2)
        # step curves: each frame takes the last key at or before it
        k = np.clip(np.searchsorted(co[:, 0], frames + 1e-4, side="right") - 1, 0, n - 1)
        channels.append((path, 0, writer.CONTACT_GROUP, co[k, 1], 'CONSTANT'))
    keying.key_channels(action, target_obj, frames, channels)


def retarget_onto(source_obj, target_obj, bone_map="auto", map_path=None, root_motion="scaled",
                  keep_ends=False, context=None, live_swivel=None, progress=None):
    """Retarget the MANIKIN armature ``source_obj``'s motion onto ``target_obj``: a new action
    ``MANIKIN_retarget_<source action>`` on the target.  Returns ``(action, result, notes)``:
    notes, plain-language lines for the user (the guessed map's doubtful joints, hands / feet out
    of the target's reach).

    live_swivel: also give the character the keyed swivel properties and the live swivel rig of
    :mod:`.character_swivel` (its elbows / knees follow the swivel, its hands / feet stay on their
    targets); None (default): when ``keep_ends`` is on.  A rig an earlier retarget left on the
    character is removed first either way (its actions are kept).  progress: called with the
    fraction 0-1 done (the source's evaluation is most of a long take's time)."""
    from . import character_swivel
    context = context or bpy.context
    if live_swivel is None:
        live_swivel = bool(keep_ends)
    if target_obj is None or target_obj == source_obj:
        raise ValueError("choose a target armature other than the solved one")
    if target_obj.animation_data is not None and target_obj.animation_data.use_tweak_mode:
        # its action cannot be changed while an NLA strip's action is being edited
        raise ValueError(f"{target_obj.name!r} is in NLA tweak mode (a strip's action is being edited): "
                         f"leave it (Tab in the NLA editor), then retarget")
    bmap, guess = resolve_bone_map(bone_map, target_obj, map_path)
    # only the bones the map drives and those above them: the retarget's arrays hold a row per
    # bone and frame, and fingers, face and props keep their rest pose under their parent anyway
    # (and the hands' knuckle bones, which show how the rig's rest palms face: rt.make_plan)
    full = target_rig_from_object(target_obj)
    target = full.restricted_to(bone_maps.as_bone_map(bmap).target_bones() + rt.finger_bones(full, bmap))
    # the live swivel adds bones: a linked character's armature (a library override's) cannot take
    # them, so it gets plain keys
    linked = live_swivel and not (getattr(target_obj.data, "is_editable", True) and target_obj.data.library is None)
    if linked:
        live_swivel = False
    frames, wr, pos, swivel, body = sample_source(
        source_obj, context, progress=None if progress is None else (lambda f: progress(0.6 * f)))
    if progress is not None:
        progress(0.6)
    res = rt.retarget(wr, pos, body, target, bmap, root_motion)
    notes = [f"{g.joint}: {g.bone or 'no bone'} ({g.why})" for g in guess if g.confidence < 0.5]
    notes += list(res.plan.notes)             # what the retarget assumed of the rig (facing, legs)
    if linked:
        notes.append(f"no live swivel: {target_obj.name!r}'s armature is linked from "
                     f"{target_obj.data.library.filepath if target_obj.data.library else 'a library'} and "
                     f"cannot take its bones; the limbs are keyed as plain keys")
    # With keep_ends every limb lands on its target; without, the legs still do when the root
    # motion is scaled or in place: transferred segment directions on a character with other
    # thigh : shank proportions would make planted feet slide (3-4 cm/s at +-12 %), so the legs
    # are solved onto the performer's feet scaled like the root motion (a planted foot stays
    # planted), with the performer's knee swivel.  "As is" root motion keeps the transfer.
    if keep_ends or root_motion != "as_is":
        limbs = sk.LIMB_NAMES if keep_ends else ("left_leg", "right_leg")
        res = rt.keep_ends_on_targets(res, wr, pos, swivel, limbs=limbs,
                                      ends="scaled" if root_motion != "as_is" else "source")
    err = res.reach_error
    if err is not None:
        from .units import metres_per_unit
        err = err * metres_per_unit(context.scene)          # scene units → metres
        for li, limb in enumerate(sk.LIMB_NAMES):
            bad = np.isfinite(err[:, li]) & (err[:, li] > 0.005)
            if bad.any():
                notes.append(f"{limb.replace('_', ' ')}: out of the character's reach on {int(bad.sum())} "
                             f"frame(s), by up to {100 * float(np.nanmax(err[bad, li])):.1f} cm")
    src_action = source_obj.animation_data.action
    if character_swivel.has_rig_parts(target_obj):
        character_swivel.remove_character_rig(target_obj, context)
    held = overriding_constraints(target_obj, [target.names[k] for k in np.nonzero(res.keyed)[0]])
    if held:
        shown = ", ".join(f"{b} ({c})" for b, c in held[:4]) + (f" and {len(held) - 4} more" if len(held) > 4 else "")
        notes.append(f"{len(held)} of the bones this map keys follow constraints that set their rotation: "
                     f"{shown}; their new keys do not show while those constraints are on: map the rig's "
                     f"controls instead, or mute the constraints")
    before = keying.active_assignment(target_obj)
    action = key_retarget(target_obj, res, target, frames, f"MANIKIN_retarget_{src_action.name}",
                          switches=_ik_fk_switches(target_obj, bmap))
    copy_contacts(source_obj, src_action, target_obj, action, frames)
    if live_swivel:
        try:
            notes += character_swivel.build_character_rig(target_obj, res, frames, wr, swivel, action, context)
        except BaseException:
            keying.restore_assignment(target_obj, before)
            bpy.data.actions.remove(action)
            raise
    if progress is not None:
        progress(1.0)
    return action, res, notes
