"""Animated scene objects (empties, meshes, bones) as tracker devices.

The world transform of each source is sampled on every scene frame of a
range and returned as a :class:`~blender_manikin.core.recording.Recording`
(Blender axes; scene units taken into metres, :mod:`.units`), so a scene source goes through the same
resampling / offsets / calibration / solve path as a file.

Sampling, per source:

* **plain keyed object** (no parent, no constraints, no drivers, no NLA, zero and unkeyed
  delta transforms, an action with a slot for it, its action's F-curves drive ``location`` /
  ``rotation_*``): the F-curves are evaluated directly (no scene
  re-evaluation), vectorised into numpy; unkeyed channels use the current
  property value;
* **anything else** (constraints, parents, drivers, bones): the scene is
  stepped with ``scene.frame_set`` and the evaluated world matrix is read
  (``obj.matrix_world`` or ``obj.matrix_world @ pose_bone.matrix``).  All
  such sources share one frame loop.  The current frame is restored afterwards.

A sample is lost (``valid`` False) where the object's keyed visibility hides it (``hide_viewport``
keyed on: an importer's or a plugin's "tracking lost"), and, stepping the scene, where the view
layer does not evaluate it (disabled in viewports, its collection disabled or excluded: its world
matrix there is a stale one); a source with no sample left is an error that says so.

Time of scene frame ``f`` is ``f / fps`` seconds (``fps = render.fps /
fps_base``).  Both ways read the animation at its own frame ``f``: with *Time Stretching*
(``render.frame_map_old`` / ``frame_map_new``) the scene is stepped to the scene frame that shows
it, as the F-curves are read and as the solve's keys are shown.  Orientations are the source's
world rotation (scale removed, as a unit quaternion w, x, y, z): the *device* orientation in
Blender axes, so device offsets apply as for a recording.  A camera object looks along its local
-Z with +Y up; it is read in a device's axes (-Y forward, +Z up: a headset looking where the
camera looks, :data:`CAMERA_TO_DEVICE`).
"""
from __future__ import annotations

import os

import numpy as np

from ..core import rotations as rot
from ..core.recording import Recording, TrackerStream
from . import keying
from .units import metres_per_unit


#: a camera's axes (-Z forward, +Y up, +X right) → a device's (-Y forward, +Z up, -X right,
#: :mod:`..core.device_offsets`): the device's rotation is the camera's times this
CAMERA_TO_DEVICE = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


class SceneSourceError(ValueError):
    """A scene object / bone mapped to a device cannot be sampled."""


def _is_plain_keyed(obj):
    if obj.parent is not None or len(obj.constraints):
        return False
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return False
    if len(ad.drivers) or len(ad.nla_tracks):
        return False
    slotted = keying.is_slotted(ad.action)
    if slotted and getattr(ad, "action_slot", None) is None:     # Blender animates nothing then
        return False
    if any(fc.data_path.startswith("delta_") or fc.data_path == "scale"
           for fc in keying.action_fcurves(ad.action, obj if slotted else None)):
        return False                     # keyed delta transforms move it too; a keyed scale may mirror it
    if any(v < 0 for v in obj.scale) or any(v < 0 for v in obj.delta_scale):
        return False                     # mirrored: read as drawn, and refused (sample_sources)
    if getattr(ad, "action_influence", 1.0) != 1.0 or getattr(ad, "action_blend_type", "REPLACE") != "REPLACE":
        return False
    if any(abs(v) > 0 for v in obj.delta_location) or any(abs(v) > 0 for v in obj.delta_rotation_euler):
        return False
    dq = obj.delta_rotation_quaternion
    if abs(dq[0] - 1.0) > 0 or any(abs(v) > 0 for v in dq[1:]):
        return False
    return True


_ROT_PATHS = {"QUATERNION": ("rotation_quaternion", 4), "AXIS_ANGLE": ("rotation_axis_angle", 4)}


def _visibility_fcurve(obj):
    """The F-curve keying ``obj``'s ``hide_viewport`` in its action (None when not keyed)."""
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return None
    for fc in keying.action_fcurves(ad.action, obj if keying.is_slotted(ad.action) else None):
        if fc.data_path == "hide_viewport" and not fc.mute:
            return fc
    return None


def _eval_plain(obj, frames):
    """World ``(pos (N,3), rotm (N,3,3))`` of a plain keyed object from its F-curves, and
    ``valid (N,)``: False where its keyed visibility hides it."""
    action = obj.animation_data.action
    fcs = {}
    for fc in keying.action_fcurves(action, obj if keying.is_slotted(action) else None):
        if not fc.mute:
            fcs[(fc.data_path, fc.array_index)] = fc

    def channel(path, n, current):
        out = np.empty((len(frames), n))
        for i in range(n):
            fc = fcs.get((path, i))
            if fc is None:
                out[:, i] = current[i]
            else:
                ev = fc.evaluate
                out[:, i] = [ev(f) for f in frames]
        return out

    pos = channel("location", 3, tuple(obj.location))
    mode = obj.rotation_mode
    if mode == "QUATERNION":
        q = channel("rotation_quaternion", 4, tuple(obj.rotation_quaternion))
        R = rot.quat_to_matrix(q)
    elif mode == "AXIS_ANGLE":
        aa = channel("rotation_axis_angle", 4, tuple(obj.rotation_axis_angle))
        R = rot.axis_angle_rotation(aa[:, 1:], aa[:, 0])
    else:
        e = channel("rotation_euler", 3, tuple(obj.rotation_euler))
        R = rot.fixed_axes_euler_to_matrix(e, mode)
    vis = _visibility_fcurve(obj)
    valid = np.ones(len(frames), dtype=bool) if vis is None else np.array([vis.evaluate(f) < 0.5 for f in frames])
    return pos, R, valid


def _matrix_parts(m):
    m = np.asarray(m, dtype=np.float64)
    return m[:3, 3].copy(), m[:3, :3].copy()


def _sample(scene, resolved, frames, depsgraph=None, progress=None, force_frame_set=False):
    """World ``pos`` ``{key: (N, 3)}`` (scene units) and ``rotm`` ``{key: (N, 3, 3)}`` of each
    ``resolved`` ``{key: (object, bone or "")}`` on scene ``frames`` ``(N,)``, and the ``method``
    per key (``"fcurves"``: a plain keyed object's F-curves evaluated; ``"frame_set"``: the scene
    stepped, the evaluated world matrix read; one loop for all), and ``valid`` ``{key: (N,)}``
    (False where the source is hidden by its keyed visibility or, stepping the scene, not
    evaluated: see the module's docstring).  The current frame is restored."""
    import bpy
    N = frames.shape[0]
    pos = {d: np.empty((N, 3)) for d in resolved}
    rotm = {d: np.empty((N, 3, 3)) for d in resolved}
    valid = {d: np.ones(N, dtype=bool) for d in resolved}
    method = {}
    loop = []
    for dev, (obj, bone) in resolved.items():
        if not bone and not force_frame_set and _is_plain_keyed(obj):
            pos[dev], rotm[dev], valid[dev] = _eval_plain(obj, frames)
            method[dev] = "fcurves"
        else:
            loop.append(dev)
            method[dev] = "frame_set"
    if loop:
        keyed_vis = {dev: _visibility_fcurve(resolved[dev][0]) is not None for dev in loop}
        old = (scene.frame_current, scene.frame_subframe)
        stretch = float(scene.render.frame_map_new) / float(scene.render.frame_map_old)
        try:
            for k, f in enumerate(frames):
                x = float(f) * stretch           # the scene frame showing the animation's frame f
                whole = int(np.floor(x + 1e-9))
                scene.frame_set(whole, subframe=max(0.0, x - whole))
                dg = depsgraph or bpy.context.evaluated_depsgraph_get()
                for dev in loop:
                    obj, bone = resolved[dev]
                    ev = obj.evaluated_get(dg)
                    # not evaluated (or hidden by its keys): the matrix is a stale one
                    valid[dev][k] = ev.is_evaluated and not (keyed_vis[dev] and obj.hide_viewport)
                    m = np.array(ev.matrix_world, dtype=np.float64)
                    if bone:
                        m = m @ np.array(ev.pose.bones[bone].matrix, dtype=np.float64)
                    pos[dev][k], rotm[dev][k] = _matrix_parts(m)
                if progress is not None and (k % 64 == 0 or k == N - 1):
                    progress((k + 1) / N)
        finally:
            scene.frame_set(old[0], subframe=old[1])
    elif progress is not None:
        progress(1.0)
    for dev, (obj, bone) in resolved.items():
        if not valid[dev].any():
            raise SceneSourceError(
                f"{dev}: object {obj.name!r} cannot be read on any frame of {int(frames[0])}..{int(frames[-1])}: "
                f"it is disabled in the viewports (or its collection is, or is excluded from the view layer), "
                f"or its keyed visibility hides it; enable it")
    return pos, rotm, method, valid


def sample_sources(scene, sources, frame_start, frame_end, depsgraph=None, progress=None,
                   force_frame_set=False):
    """Sample the mapped sources over scene frames ``frame_start..frame_end`` (inclusive).

    sources: ``{device: (object, bone_name)}`` with ``bone_name`` ``""`` / None
    for the object itself (``object`` may be an object or its name); one object (or bone) mapped
    to two devices is an error.
    progress: optional ``callable(fraction)``, may raise to cancel (the
    current frame is restored).  Returns a :class:`Recording` whose
    ``source`` is ``"scene"``; ``metadata`` records frames, fps and the
    method used per device.
    """
    import bpy

    frame_start, frame_end = int(frame_start), int(frame_end)
    if frame_end < frame_start:
        raise SceneSourceError(f"frame range {frame_start}..{frame_end} is empty")
    fps = float(scene.render.fps) / float(scene.render.fps_base)
    frames = np.arange(frame_start, frame_end + 1, dtype=np.float64)
    resolved = {}
    for dev, (obj, bone) in sources.items():
        if isinstance(obj, str):
            name = obj
            obj = bpy.data.objects.get(name)
            if obj is None:
                raise SceneSourceError(f"{dev}: no object named {name!r}")
        if obj is None:
            continue
        bone = bone or ""
        if bone:
            if obj.type != 'ARMATURE' or obj.pose is None or bone not in obj.pose.bones:
                raise SceneSourceError(f"{dev}: object {obj.name!r} has no bone {bone!r}")
        for other, (o, b) in resolved.items():
            if o == obj and b == bone:          # two devices are never in one place
                what = f"bone {bone!r} of object {obj.name!r}" if bone else f"object {obj.name!r}"
                raise SceneSourceError(f"{other} and {dev}: both are mapped to {what}; map each device "
                                       f"to its own object")
        resolved[dev] = (obj, bone)
    if not resolved:
        raise SceneSourceError("no scene objects are mapped to devices")

    pos, rotm, method, valid = _sample(scene, resolved, frames, depsgraph, progress, force_frame_set)
    for dev, (obj, bone) in resolved.items():
        mirrored = np.nonzero(valid[dev] & (np.linalg.det(rotm[dev]) < 0))[0]
        if mirrored.size:                # a reflection is no rotation: no device is drawn so
            raise SceneSourceError(
                f"{dev}: {'bone ' + repr(bone) + ' of ' if bone else ''}object {obj.name!r} is mirrored (a negative "
                f"scale, its own or a parent's) at frame {int(frames[mirrored[0]])}: a tracker's orientation is a "
                f"rotation; unmirror it (or apply the scale, Ctrl+A)")
    times = frames / fps
    metres = metres_per_unit(scene)          # scene units → the core's metres
    streams = {}
    for dev, (obj, bone) in resolved.items():
        pos[dev] *= metres
        R = rot.orthonormalize(rotm[dev])
        if not bone and obj.type == 'CAMERA':
            R = R @ CAMERA_TO_DEVICE
        q = rot.quat_continuous(rot.matrix_to_quat(R), axis=0)
        streams[dev] = TrackerStream(dev, times.copy(), pos[dev], q, valid[dev])
    meta = {"frames": (frame_start, frame_end), "fps": fps, "method": method,
            "objects": {d: (o.name, b) for d, (o, b) in resolved.items()},
            "device_labels": {d: b or o.name for d, (o, b) in resolved.items()},     # "HMD": a headset
            "axes": "blender", "units": "m", "exact": True}     # held keys repeat exactly: not lost
    return Recording(streams=streams, source="scene", metadata=meta)


def sample_keypoint_empties(scene, objects, frame_start, frame_end, progress=None, source="scene objects"):
    """3D keypoints from scene objects named after a layout's points (FreeMoCap's empties, a
    markerless add-on's, ``left_wrist`` / ``Body_Left_Wrist.001`` / ...: :func:`..core.keypoint_layouts.
    layout_from_names`), sampled on scene frames ``frame_start..frame_end`` as world positions,
    scene units taken into metres.  Returns a :class:`..core.io_keypoints.KeypointRecording`;
    raises :class:`SceneSourceError` when no layout's points are all there."""
    from ..core import keypoint_layouts as kl
    from ..core.io_keypoints import keypoints_from_points
    objects = [o for o in objects if o is not None]
    found = kl.layout_from_names([o.name for o in objects])
    if found is None:
        have = {kl.point_key(o.name) for o in objects}
        best = min(kl.LAYOUTS.values(), key=lambda lay: sum(p not in have for p in lay.points))
        missing = [p for p in best.points if p not in have]
        raise SceneSourceError(f"{source}: {len(objects)} object(s), but no keypoint layout has all its points "
                               f"among their names (closest, {best.name}, lacks {', '.join(missing[:6])}"
                               f"{' ...' if len(missing) > 6 else ''})")
    layout, names = found
    by_name = {o.name: o for o in objects}
    frame_start, frame_end = int(frame_start), int(frame_end)
    if frame_end <= frame_start:
        raise SceneSourceError(f"frame range {frame_start}..{frame_end} holds fewer than 2 frames")
    frames = np.arange(frame_start, frame_end + 1, dtype=np.float64)
    resolved = {p: (by_name[n], "") for p, n in names.items()}
    pos, _, _, valid = _sample(scene, resolved, frames, progress=progress)
    for p in pos:
        pos[p][~valid[p]] = np.nan                  # lost there
    points = np.stack([pos[p] for p in kl.LAYOUTS[layout].points], axis=1) * metres_per_unit(scene)
    fps = float(scene.render.fps) / float(scene.render.fps_base)
    return keypoints_from_points(frames / fps, points, layout, source,
                                 how=f"from the names of {len(names)} scene objects")


def armature_bone_map(obj, choice="auto", path=None):
    """``(BoneMap, label)``: the bone map of an animated armature read as keypoints.

    choice: ``"auto"`` (guessed from the bone names and hierarchy, the retarget's guess,
    :func:`..core.bone_maps.guess_bone_map`: its presets first), a preset of
    :data:`..core.bone_maps.PRESETS` (fitted to the rig, :func:`..core.bone_maps.fit_preset`) or
    ``"file"`` with ``path`` (a saved map, JSON).  The deforming bones are read as they are
    evaluated (a generated Rigify or a live Auto-Rig Pro rig's DEF bones follow their controls
    through constraints: their heads are where the body is, unlike the retarget, which keys the
    controls).  label: the map's name for the summary (``"mixamo map"``)."""
    from ..core import bone_maps
    from .retarget_apply import bone_list
    key = str(choice or "auto").lower()
    if key == "auto":
        bmap, _ = bone_maps.guess_bone_map(bone_list(obj))
        label = "bone map guessed from the names" if bmap.name == "guessed" else f"{bmap.name} map, guessed"
    elif key == "file":
        if not path:
            raise SceneSourceError(f"armature {obj.name!r}: the bone map is From File, but no file is chosen")
        try:
            bmap = bone_maps.load_bone_map(path)
        except (OSError, ValueError) as exc:
            raise SceneSourceError(f"bone map file {path!r}: {exc}") from None
        label = f"map {bmap.name!r} from {os.path.basename(path)}"
    else:
        try:
            bmap = bone_maps.preset(key)
        except ValueError as exc:
            raise SceneSourceError(str(exc)) from None
        try:
            bmap, _ = bone_maps.fit_preset(bmap, bone_list(obj))
        except ValueError:
            pass                        # not a rig of that kind: the required joints' check names what lacks
        label = f"{key} map"
    return bmap, label


def sample_armature_keypoints(scene, obj, frame_start, frame_end, choice="auto", path=None, progress=None):
    """3D keypoints from an animated armature (a markerless capture's FBX, an imported BVH,
    another rig's animation): each of the 22 body joints is the world position of the head of
    the bone the map (:func:`armature_bone_map`) gives it, and the head's, wrists' and ankles'
    orientations from their bones (:func:`..core.rig_keypoints.end_orientations`), sampled on scene frames
    ``frame_start..frame_end`` with the scene evaluated (action, NLA, constraints, drivers),
    scene units taken into metres; joints without a bone are placed as
    :mod:`..core.rig_keypoints` says.  Returns a :class:`..core.io_keypoints.KeypointRecording`
    in the ``smpl22`` layout whose report names the armature and the map.  Nothing of the
    armature changes (its action, pose, selection); the current frame is restored.

    Raises :class:`SceneSourceError`: no armature, an armature that is the solve's own output, a
    map leaving the limbs or the head without a bone (naming them), bones that do not move on
    the range (no animation there)."""
    from ..core import rig_keypoints
    from ..core.io_keypoints import keypoints_from_points
    from .armature import PROP_BODY
    from .retarget_apply import target_rig_from_object
    if obj is None:
        raise SceneSourceError("choose the armature whose animation gives the keypoints")
    if obj.type != 'ARMATURE':
        raise SceneSourceError(f"object {obj.name!r} is not an armature")
    if PROP_BODY in obj.keys():
        raise SceneSourceError(f"armature {obj.name!r} is a MANIKIN solve's output: choose the animated "
                               f"character it should follow")
    frame_start, frame_end = int(frame_start), int(frame_end)
    if frame_end <= frame_start:
        raise SceneSourceError(f"frame range {frame_start}..{frame_end} holds fewer than 2 frames")
    bmap, label = armature_bone_map(obj, choice, path)
    try:
        bmap = rig_keypoints.checked_map(bmap, obj.pose.bones.keys(), f"armature {obj.name!r}")
    except ValueError as exc:
        raise SceneSourceError(str(exc)) from None
    frames = np.arange(frame_start, frame_end + 1, dtype=np.float64)
    resolved = {j: (obj, b) for j, b in bmap.bones.items()}
    pos, rotm, _, valid = _sample(scene, resolved, frames, progress=progress)
    metres = metres_per_unit(scene)
    heads = {j: pos[j] * metres for j in pos}
    moved = max(float(np.ptp(h, axis=0).max()) for h in heads.values())
    if moved < 1e-6:
        raise SceneSourceError(f"armature {obj.name!r}: its bones do not move on frames {frame_start}..{frame_end}: "
                               f"it has no animation there (no action, NLA strip, driver or constraint moves "
                               f"them); choose the frames of its animation or another armature")
    for j in heads:
        heads[j][~valid[j]] = np.nan                # not evaluated there
    P, derived = rig_keypoints.joints_from_heads(heads)
    fps = float(scene.render.fps) / float(scene.render.fps_base)
    without = f"; without a bone: {rig_keypoints.derived_note(derived)}" if derived else ""
    try:
        turned = rig_keypoints.end_orientations(
            target_rig_from_object(obj), bmap,
            {j: rot.orthonormalize(rotm[j]) for j in rig_keypoints.END_JOINTS if j in rotm})
    except ValueError as exc:           # a map the rig's hierarchy does not follow: positions only
        turned, without = {}, f"{without}; rest twist of the head, wrists and ankles ({exc})"
    said = f"keypoints: {P.shape[1]} joints from armature {obj.name!r} ({label}{without})"
    return keypoints_from_points(frames / fps, P, "smpl22", f"armature {obj.name!r}", said=said,
                                 orientations=turned)
