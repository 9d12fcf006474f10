"""Put a MANIKIN solve onto another armature (Blender glue of :mod:`..core.retarget`).

gather → create, as the solve does:

1. :func:`target_rig_from_object` reads the target's rest (``bone.matrix_local``, parents, the
   object's ``matrix_world``) and :func:`sample_source` the MANIKIN armature's motion: from its
   FK keys when it is a plain FK solve (no evaluation), else by evaluating the live rig frame by
   frame (``frame_set``: about a millisecond a frame);
2. the numpy core retargets (:func:`..core.retarget.retarget`, and with ``keep_ends`` the hands
   and feet are solved again on the target's own limb lengths);
3. :func:`key_retarget` writes a NEW action on the target: ``rotation_quaternion`` of every mapped
   (and twist) bone and the root bone's ``location``, bulk-keyed on both action APIs.  The
   target's previous action is kept (with a fake user) and never modified; the keyed bones'
   rotation mode is set to quaternions (recorded in the action's ``manikin_rotation_modes``
   custom property so it can be restored).  All or nothing: on an error the new action is removed
   and the previous one assigned back.

Frames are scene frames; positions metres; the MANIKIN armature is expected at the world origin
(its ``matrix_world`` is applied anyway).
"""
from __future__ import annotations

import numpy as np

import bpy

from ..core import bone_maps
from ..core import retarget as rt
from ..core import rotations as rot
from ..core import skeleton as sk
from . import armature as arm_mod
from . import keying

#: action custom property: the keyed bones' rotation modes before the retarget (JSON-like dict)
PROP_MODES = "manikin_rotation_modes"


def target_rig_from_object(obj) -> rt.TargetRig:
    """The :class:`~..core.retarget.TargetRig` of armature object ``obj`` at rest."""
    if obj is None or obj.type != 'ARMATURE':
        raise TypeError("the retarget target must be an armature object")
    bones = list(obj.data.bones)
    names = [b.name for b in bones]
    parents = [b.parent.name if b.parent is not None else None for b in bones]
    A = np.array([np.array(b.matrix_local, dtype=np.float64) for b in bones]).reshape(len(bones), 4, 4)
    return rt.TargetRig.from_matrices(names, parents, A, np.array(obj.matrix_world, dtype=np.float64))


def bone_list(obj):
    """``[(name, parent, head (3,), tail (3,))]`` of ``obj``'s bones in armature space (for
    :func:`..core.bone_maps.guess_bone_map`)."""
    return [(b.name, b.parent.name if b.parent else None, np.array(b.head_local), np.array(b.tail_local))
            for b in obj.data.bones]


def resolve_bone_map(choice, target_obj, path=None):
    """``(BoneMap, notes)`` for the panel's / command line's choice: ``"auto"`` (guessed from the
    target's bone names and hierarchy: notes list each joint's bone and why), a preset name of
    :data:`..core.bone_maps.PRESETS`, or ``"file"`` with ``path`` (a saved map, JSON)."""
    key = str(choice or "auto").lower()
    if key == "auto":
        bmap, notes = bone_maps.guess_bone_map(bone_list(target_obj))
        return bmap, notes
    if key == "file":
        if not path:
            raise ValueError("no bone map file chosen")
        return bone_maps.load_bone_map(path), []
    return bone_maps.preset(key), []


def _frames_of(action, obj):
    """Scene frames of the keys of ``action`` (its pelvis rotation curve, else any curve)."""
    fcs = keying.action_fcurves(action, obj)
    if not fcs:
        raise ValueError(f"action {action.name!r} has no keys")
    fc = next((f for f in fcs if f.data_path == 'pose.bones["pelvis"].rotation_quaternion'), fcs[0])
    co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
    fc.keyframe_points.foreach_get("co", co)
    return co[0::2].astype(np.float64)


def sample_source(obj, context=None, frames=None):
    """The motion of the MANIKIN armature ``obj``: ``(frames (T,), world_rot (T, 22, 3, 3),
    positions (T, 22, 3) metres, swivel (T, 4) radians, body)``, body-model convention (identity =
    rest T-pose).  frames: scene frames (default: the keys of its action)."""
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
    if not live_rig.is_live_rig(obj):           # plain FK keys: read them, no evaluation
        fps = float(context.scene.render.fps) / float(context.scene.render.fps_base)
        res, key_frames = live_rig.result_from_fk_action(obj, fps)
        if len(key_frames) == len(frames) and np.allclose(key_frames, frames):
            pos, wr = res.fk()
            return frames, wr, pos, res.swivel, body
    _, rest = arm_mod.rest_matrices(obj)
    W = np.array(obj.matrix_world, dtype=np.float64)
    Rw = rot.orthonormalize(W[:3, :3])
    scene = context.scene
    keep = scene.frame_current, scene.frame_subframe
    T = len(frames)
    wr = np.empty((T, sk.NUM_JOINTS, 3, 3))
    pos = np.empty((T, sk.NUM_JOINTS, 3))
    swivel = np.zeros((T, 4))
    from .writer import SWIVEL_PROPS
    pbs = [obj.pose.bones[n] for n in sk.JOINT_NAMES]
    try:
        for t, f in enumerate(frames):
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
            for j, pb in enumerate(pbs):
                M = np.array(pb.matrix, dtype=np.float64)
                wr[t, j] = Rw @ rot.orthonormalize(M[:3, :3]) @ rest[j].T
                pos[t, j] = (W @ np.append(M[:3, 3], 1.0))[:3]
            for li, limb in enumerate(sk.LIMB_NAMES):
                swivel[t, li] = float(obj.get(SWIVEL_PROPS[limb], 0.0))
    finally:
        scene.frame_set(keep[0], subframe=keep[1])
    return frames, wr, pos, swivel, body


def key_retarget(target_obj, res: rt.RetargetResult, target: rt.TargetRig, frames, name, interpolation='LINEAR'):
    """A NEW action ``name`` on ``target_obj`` with the keys of ``res``; returns it.  The previous
    action stays (fake user), the keyed bones' rotation modes are recorded (:data:`PROP_MODES`)."""
    keyed = [k for k in range(target.num_bones) if res.keyed[k]]
    prev = target_obj.animation_data.action if target_obj.animation_data else None
    action = keying.new_action(name)
    try:
        modes = {}
        for k in keyed:
            pb = target_obj.pose.bones[target.names[k]]
            modes[pb.name] = pb.rotation_mode
        action[PROP_MODES] = modes
        if prev is not None:
            prev.use_fake_user = True
        keying.assign_action(target_obj, action)
        ch = []
        for k in keyed:
            path = f'pose.bones["{target.names[k]}"].rotation_quaternion'
            for i in range(4):
                ch.append((path, i, target.names[k], res.quaternions[:, k, i]))
        if res.root_bone is not None:
            rb = res.root_bone
            for i in range(3):
                ch.append((f'pose.bones["{rb}"].location', i, rb, res.root_location[:, i]))
        keying.key_channels(action, target_obj, frames, ch, interpolation)
        for k in keyed:
            target_obj.pose.bones[target.names[k]].rotation_mode = 'QUATERNION'
    except BaseException:
        if prev is not None:
            keying.assign_action(target_obj, prev)
        elif target_obj.animation_data is not None:
            target_obj.animation_data.action = None
        bpy.data.actions.remove(action)
        raise
    return action


def retarget_onto(source_obj, target_obj, bone_map="auto", map_path=None, root_motion="scaled",
                  keep_ends=False, context=None):
    """Retarget the MANIKIN armature ``source_obj``'s motion onto ``target_obj``: a new action
    ``MANIKIN_retarget_<source action>`` on the target.  Returns ``(action, result, notes)``:
    notes, plain-language lines for the user (the guessed map's doubtful joints, hands / feet out
    of the target's reach)."""
    context = context or bpy.context
    if target_obj is None or target_obj == source_obj:
        raise ValueError("choose a target armature other than the solved one")
    target = target_rig_from_object(target_obj)
    bmap, guess = resolve_bone_map(bone_map, target_obj, map_path)
    frames, wr, pos, swivel, body = sample_source(source_obj, context)
    res = rt.retarget(wr, pos, body, target, bmap, root_motion)
    notes = [f"{g.joint}: {g.bone or 'no bone'} ({g.why})" for g in guess if g.confidence < 0.5]
    if keep_ends:
        res = rt.keep_ends_on_targets(res, wr, pos, swivel, ends="scaled" if root_motion != "as_is" else "source")
        err = res.reach_error
        if err is not None:
            for li, limb in enumerate(sk.LIMB_NAMES):
                bad = np.isfinite(err[:, li]) & (err[:, li] > 0.005)
                if bad.any():
                    notes.append(f"{limb.replace('_', ' ')}: out of the character's reach on {int(bad.sum())} "
                                 f"frame(s), by up to {100 * float(np.nanmax(err[bad, li])):.1f} cm")
    src_action = source_obj.animation_data.action
    action = key_retarget(target_obj, res, target, frames, f"MANIKIN_retarget_{src_action.name}")
    return action, res, notes
