"""Put a solved :class:`~blender_manikin.core.pose_result.PoseResult` into the scene.

Everything is written in one step at the end of a solve and is
all-or-nothing: if anything fails, every ID created so far is removed again
and the exception propagates (no half-written data).  Nothing that existed
before is modified except, optionally, the scene frame range and -- when an
existing MANIKIN armature of the same body is reused -- that armature's
assigned action (the previous action, the animator's own included, is given a fake user so it
stays in the file; undone, with its slot, when the write fails).

Timing: result frame ``k`` is keyed at scene frame
``frame_start + k * frame_step``; by default ``frame_step`` is
``scene_fps / result.fps`` so the animation plays back in real time.

Data written (armature object ``obj``, new action ``MANIKIN_solve[.NNN]``; with
``WriteOptions.key_pose`` False only the armature, its swivel properties and the
trackers: the live rig then keys its own action, see ``solve_job.SolveJob.write``):

* ``pose.bones["<joint>"].rotation_quaternion`` (w, x, y, z), every bone,
  see :mod:`.armature` for the mapping and the bone axes;
* ``pose.bones["pelvis"].location`` (scene units: the caller passes the result in them,
  :func:`.units.result_in_scene_units`; pelvis bone's rest frame);
* ``["swivel_left_arm"]`` ... ``["swivel_right_leg"]``: object custom
  properties, radians, unwrapped over time (so curves are continuous; the
  value modulo 2π is the solver's swivel angle), subtype ANGLE.
* ``["foot_contact_left"]``, ``["foot_contact_right"]``: object custom properties, 1 while
  the solve holds that foot planted, else 0, keyed as steps (constant interpolation): footstep
  events for a game engine or a sound editor.
* optional: the mannequin mesh (:mod:`.body_mesh`), a child of a new armature (or of a reused
  one that has none), skinned to its bones;
* optional tracker empties ``MANIKIN_<device>`` in a new collection
  ``MANIKIN trackers``, each with its own new action keying ``location``
  (scene units, world) and ``rotation_quaternion`` (the targeted joint's world
  orientation, body-model convention) of the device targets after offsets.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

import bpy

from ..core.plain import shown
from ..core import rotations as rot
from ..core import skeleton as sk
from . import armature as arm_mod
from . import keying
from .units import metres_per_unit

#: limb name -> custom property name on the armature object
SWIVEL_PROPS = {limb: f"swivel_{limb}" for limb in sk.LIMB_NAMES}
SWIVEL_GROUP = "Swivel"
#: foot (left, right) -> custom property keyed 1 while that foot is planted
CONTACT_PROPS = {"left": "foot_contact_left", "right": "foot_contact_right"}
CONTACT_GROUP = "Contacts"
#: hard limits of the swivel properties (radians); the soft (UI slider) range is [-pi, pi]
SWIVEL_HARD_LIMIT = 32.0 * math.pi
TRACKER_COLLECTION = "MANIKIN trackers"


@dataclass
class WriteOptions:
    """How :func:`write_result` writes.  Frames are scene frames."""
    frame_start: float = 1.0
    frame_step: float | None = None          # None: scene fps / result fps
    armature: object = None                  # reuse this MANIKIN armature if it fits the body
    armature_name: str = "MANIKIN_body"
    action_name: str = "MANIKIN_solve"
    create_trackers: bool = False
    body_mesh: bool = False                  # the mannequin mesh on the armature (.body_mesh)
    tracker_collection: str = TRACKER_COLLECTION
    set_scene_range: bool = False
    interpolation: str = 'LINEAR'
    key_pose: bool = True                    # False: armature only (the live rig keys its own action)


@dataclass
class WriteOutput:
    """What :func:`write_result` created."""
    armature: object
    action: object
    created_armature: bool
    frames: np.ndarray
    trackers: dict = field(default_factory=dict)          # device -> empty object
    tracker_actions: dict = field(default_factory=dict)   # device -> action
    tracker_collection: object = None
    live_action: object = None                            # set when the live swivel rig was built
    body_mesh: object = None                              # the mannequin, when this write made it
    notes: list = field(default_factory=list)             # for the solve's summary
    #: the reused armature's active action, slot and fake user before the write
    #: (:func:`.keying.active_assignment`), put back by :func:`remove_output`
    previous: tuple = (None, None, None)


def scene_fps(scene) -> float:
    """Effective frames per second of ``scene`` (``fps / fps_base``)."""
    return float(scene.render.fps) / float(scene.render.fps_base)


def ensure_swivel_properties(obj):
    """Create (if missing) the four swivel custom properties on ``obj`` with their UI data.

    Float, radians, subtype ANGLE, soft range [-π, π], hard range
    ±``SWIVEL_HARD_LIMIT``.  Existing properties are kept as they are, value and UI data (a slider
    range the user narrowed survives a re-solve onto the armature).
    """
    for limb, name in SWIVEL_PROPS.items():
        if name in obj.keys():
            continue
        obj[name] = 0.0
        desc = (f"MANIKIN swivel angle of the {limb.replace('_', ' ')} (radians): rotation of the "
                f"{'elbow' if 'arm' in limb else 'knee'} about the "
                f"{'shoulder-wrist' if 'arm' in limb else 'hip-ankle'} axis; 0 = "
                f"{'elbow out, back and down' if 'arm' in limb else 'knee forward'}")
        obj.id_properties_ui(name).update(subtype='ANGLE', min=-SWIVEL_HARD_LIMIT, max=SWIVEL_HARD_LIMIT,
                                          soft_min=-math.pi, soft_max=math.pi, default=0.0, precision=3,
                                          description=desc)


def ensure_contact_properties(obj):
    """Create (if missing) the two foot-contact custom properties on ``obj`` (0 or 1)."""
    for side, name in CONTACT_PROPS.items():
        if name not in obj.keys():
            obj[name] = 0
        try:
            obj.id_properties_ui(name).update(min=0, max=1, default=0,
                                              description=f"MANIKIN: 1 while the {side} foot is planted")
        except (AttributeError, TypeError):
            pass


def contact_channels(result):
    """Keying channels of the feet's contacts: ``(data_path, 0, group, values (T,), 'CONSTANT')``
    (none when the result has no contacts)."""
    contacts = getattr(result, "contacts", None)
    if contacts is None:
        return []
    c = np.asarray(contacts, dtype=np.float64).reshape(len(contacts), 2)
    return [(f'["{name}"]', 0, CONTACT_GROUP, c[:, k], 'CONSTANT')
            for k, name in enumerate(CONTACT_PROPS.values())]


def unwrap_swivel(swivel):
    """``(T, 4)`` swivel angles unwrapped over time, each limb shifted by a multiple of 2π
    so that its median lies in [-π, π] (continuous curves, values near the solver's)."""
    s = np.unwrap(np.asarray(swivel, dtype=np.float64).reshape(len(swivel), -1), axis=0)
    if s.shape[0]:
        s -= 2.0 * np.pi * np.round(np.median(s, axis=0) / (2.0 * np.pi))
    return s


def _pose_channels(obj, result):
    """The channels of the solve action, ``(data_path, index, group, values (T,))``, made one
    bone at a time as they are keyed (a long take's (T, 22, 4) float64 arrays would be held
    while Blender stores the keys)."""
    heads, rest_mats = arm_mod.rest_matrices(obj)
    for j, name in enumerate(sk.JOINT_NAMES):
        q = arm_mod.pose_bone_quaternions(result.local_rot[:, j:j + 1], rest_mats[j:j + 1])[:, 0]
        path = f'pose.bones["{name}"].rotation_quaternion'
        for i in range(4):
            yield (path, i, name, q[:, i])
    loc = arm_mod.root_locations(result.root_pos, heads[0], rest_mats[0])  # (T, 3)
    root = sk.JOINT_NAMES[0]
    for i in range(3):
        yield (f'pose.bones["{root}"].location', i, root, loc[:, i])
    swivel = unwrap_swivel(result.swivel)
    for li, limb in enumerate(sk.LIMB_NAMES):
        yield (f'["{SWIVEL_PROPS[limb]}"]', 0, SWIVEL_GROUP, swivel[:, li])
    yield from contact_channels(result)


def _remove_ids(ids):
    for idb in reversed(ids):
        try:
            if isinstance(idb, bpy.types.Object):
                bpy.data.objects.remove(idb)
            elif isinstance(idb, bpy.types.Armature):
                bpy.data.armatures.remove(idb)
            elif isinstance(idb, bpy.types.Action):
                bpy.data.actions.remove(idb)
            elif isinstance(idb, bpy.types.Collection):
                bpy.data.collections.remove(idb)
            elif isinstance(idb, bpy.types.Mesh):
                bpy.data.meshes.remove(idb)
            elif isinstance(idb, bpy.types.Material):
                bpy.data.materials.remove(idb)
        except ReferenceError:
            pass


def can_take_a_solve(obj, context) -> bool:
    """Whether the armature ``obj`` of an earlier solve can be given a new action and rig: in the
    view layer (not in an excluded collection: the live rig is built in edit mode), not in NLA
    tweak mode (its action cannot be changed while a strip's is being edited), and the object and
    its armature data editable in this file (not linked from a library, nor a library override,
    whose bones cannot be edited and whose changes would not be saved)."""
    if not (obj.is_editable and obj.data.is_editable):
        return False
    ad = obj.animation_data
    if ad is not None and ad.use_tweak_mode:
        return False
    context.view_layer.update()             # its bases as the collections now are
    return context.view_layer.objects.get(obj.name) is not None


def write_result(result, options: WriteOptions | None = None, context=None) -> WriteOutput:
    """Write ``result`` into the scene of ``context`` (default ``bpy.context``).

    Creates a new armature (or reuses ``options.armature`` when it is a
    MANIKIN armature of the same body that :func:`can_take_a_solve`), a NEW action assigned to it (not
    with ``options.key_pose`` False: the caller keys the armature, e.g. the
    live rig's own action), the swivel custom properties, and optionally
    tracker empties.  All or nothing.
    """
    options = options or WriteOptions()
    context = context or bpy.context
    scene = context.scene
    T = result.num_frames
    if T < 1:
        raise ValueError("the solve produced no frames")
    step = options.frame_step if options.frame_step else scene_fps(scene) / float(result.fps)
    frames = options.frame_start + np.arange(T, dtype=np.float64) * step
    created = []
    prev = None
    obj = options.armature
    try:
        try:
            reuse = obj is not None and arm_mod.armature_matches_body(obj, result.body) \
                and obj.name in scene.objects and can_take_a_solve(obj, context)
        except ReferenceError:                  # deleted while the solve ran
            reuse, obj = False, None
        if not reuse:
            obj = arm_mod.create_armature(result.body, options.armature_name, context=context)
            created += [obj.data, obj]
        else:
            # the action it shows now (maybe the animator's own, without a fake user) stays in the file
            prev = keying.keep_active_action(obj)
        ensure_swivel_properties(obj)
        ensure_contact_properties(obj)
        action = None
        if options.key_pose:
            action = keying.new_action(options.action_name)
            created.append(action)
            keying.assign_action(obj, action)
            keying.key_channels(action, obj, frames, _pose_channels(obj, result), options.interpolation)
        out = WriteOutput(obj, action, not reuse, frames)
        if prev is not None:
            out.previous = prev
        if options.body_mesh:
            from . import body_mesh
            if body_mesh.find_body_mesh(obj) is None:
                try:
                    out.body_mesh = body_mesh.add_body_mesh(obj, result.body, context, created)
                except ValueError as exc:            # an odd body: the solve is written without it
                    out.notes.append(f"no mannequin: {exc}")

        if options.create_trackers and result.targets is not None:
            _write_trackers(result.targets, frames, scene, options, out, created)

        if options.set_scene_range:
            scene.frame_start = int(math.floor(frames[0]))
            scene.frame_end = max(int(math.ceil(frames[-1])), scene.frame_start)
    except BaseException:
        if prev is not None:
            try:
                keying.restore_assignment(obj, prev)
            except Exception:
                pass
        _remove_ids(created)
        raise
    return out


def _write_trackers(targets, frames, scene, options, out, created):
    coll = bpy.data.collections.new(options.tracker_collection)
    created.append(coll)
    scene.collection.children.link(coll)
    out.tracker_collection = coll
    n = len(frames)
    for dev in targets.devices:
        pos = np.asarray(targets.pos[dev], dtype=np.float64)
        if pos.shape[0] != n:
            raise ValueError(f"tracker {shown(dev)} has {pos.shape[0]} frames, the solve {n}")
        empty = bpy.data.objects.new(f"MANIKIN_{dev}", None)
        created.append(empty)
        coll.objects.link(empty)
        empty.empty_display_type = 'ARROWS'
        empty.empty_display_size = 0.1 / metres_per_unit(scene)       # 10 cm in the scene's unit
        empty.rotation_mode = 'QUATERNION'
        ch = [("location", i, "Object Transforms", np.nan_to_num(pos[:, i])) for i in range(3)]
        R = targets.rot.get(dev) if targets.rot else None
        if R is not None:
            q = rot.quat_continuous(rot.matrix_to_quat(np.asarray(R, dtype=np.float64)), axis=0)
            q = np.where(np.isfinite(q), q, np.array([1.0, 0.0, 0.0, 0.0]))
            ch += [("rotation_quaternion", i, "Object Transforms", q[:, i]) for i in range(4)]
        action = keying.new_action(f"MANIKIN_tracker_{dev}")
        action.use_fake_user = False
        created.append(action)
        keying.assign_action(empty, action)
        keying.key_channels(action, empty, frames, ch, options.interpolation)
        out.trackers[dev] = empty
        out.tracker_actions[dev] = action


#: the prefix of the timeline markers a solve makes (:func:`mark_timeline`)
MARKER_PREFIX = "MANIKIN: "


def mark_timeline(scene, marks, frames, take=None):
    """Timeline markers ``MANIKIN: <label>`` (with ``take``: ``MANIKIN <take>: <label>``, for
    takes solved side by side) at the scene frames of ``marks``
    (:class:`..core.review_marks.ReviewMark`, indices into ``frames``, the scene frame of each
    result frame).  The scene's markers of the same prefix within the frames' range (an earlier
    solve of the same stretch) are replaced; every other marker is left as it is.  Returns the
    new markers."""
    prefix = MARKER_PREFIX if not take else f"MANIKIN {take}: "
    lo, hi = int(math.floor(frames[0])), int(math.ceil(frames[-1]))
    for m in list(scene.timeline_markers):
        if m.name.startswith(prefix) and lo <= m.frame <= hi:
            scene.timeline_markers.remove(m)
    return [scene.timeline_markers.new(f"{prefix}{mk.label}", frame=int(round(frames[mk.frame])))
            for mk in marks]


def remove_output(out: WriteOutput):
    """Delete everything :func:`write_result` created (armature only if it created it); a reused
    armature gets its action, slot and that action's fake user back."""
    ids = []
    if out.created_armature:
        ids += [out.armature.data, out.armature]
    elif out.armature is not None:
        try:
            keying.restore_assignment(out.armature, out.previous)
        except ReferenceError:
            pass
    ids += [a for a in (out.action, out.live_action) if a is not None]
    if out.body_mesh is not None:
        ids += [out.body_mesh.data, out.body_mesh]
    if out.tracker_collection is not None:
        ids.append(out.tracker_collection)
    ids += list(out.trackers.values()) + list(out.tracker_actions.values())
    _remove_ids(ids)
