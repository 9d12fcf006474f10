"""FBX export presets for Blender, Unity and Unreal, and the one FBX export of the add-on (and
Export Each Take, in FBX or glTF binary: :func:`export_fbx_takes`).

Every FBX the add-on writes (``cli.py solve --format fbx``, the panel's **Export FBX**,
``manikin.export_fbx``) goes through :func:`export_fbx` with one of :data:`PRESETS`: plain dicts
of ``bpy.ops.export_scene.fbx`` keyword arguments, each choice commented with why.  Keywords a
Blender version's exporter does not have are left out (:func:`exporter_kwargs`), so the presets
work from Blender 4.2 to 5.x.

What the engines do with an FBX (the reason for the choices):

* **Unity** (``unity``) reads the file's axis system (``GlobalSettings`` UpAxis / FrontAxis /
  CoordAxis) and converts it to its own left-handed +Y-up, +Z-forward frame by negating X; it reads
  ``UnitScaleFactor`` ("1m (File)" in its importer when it is 100) and, with *Convert Units* (on by
  default), imports an object written at scale 1 at scale 1.  Blender's exporter applies its
  axis conversion to the root objects' transforms, so the armature arrives in Unity turned -90°
  about X (Unity 2020.1+ can bake that away with *Bake Axis Conversion*).  These are the settings
  of Blender's own Unity defaults (``io_scene_fbx.export_fbx_bin.defaults_unity3d``) with the
  scale written as units instead of on the objects.
* **Unreal** (``unreal``): UE's FBX importer converts every file to Z-up, -Y-front, right-handed
  (``FFbxImporter::ConvertScene``, then it flips Y) and only converts units when *Convert Scene
  Unit* is ticked (off by default): the numbers are read as centimetres.  So the preset writes
  Blender's own axes (Z up, -Y front: exactly UE's import system, nothing is converted and no
  rotation is put on the root), the file in centimetres (``UnitScaleFactor`` 1) and the skeleton
  at scale 1 with its bones in centimetres -- what Epic's *Send to Unreal* add-on does by scaling
  the rig (its "automatically scale bones").  Blender's exporter cannot put a unit factor into
  the bones, only onto the armature's node (an armature node at scale 100 becomes a root bone
  scaled 100 in UE), so :func:`export_fbx` exports a stand-in for the character: a copy of its
  armature with the bones scaled to centimetres and the object scaled by the inverse, its bones
  following the character's through Copy Location / Rotation / Scale constraints, baked by the
  exporter and removed afterwards (the character itself is not changed).
* **Blender** (``blender``, the default): what the add-on always wrote -- Blender's default axes
  (-Z forward, Y up) and units (centimetres, the unit scale on the root objects), for
  re-importing into Blender or any DCC.

All three write one take (the scene's frame range, every frame, every bone keyed), no leaf
bones, the armature as a plain node, Blender's bone axes, no NLA and no other actions.
"""
from __future__ import annotations

import contextlib

#: one take baked from the active action: the same in every preset
_ANIMATION = {
    "bake_anim": True,                        # constraints, drivers and the live rig baked to keys
    "bake_anim_use_all_bones": True,          # a key on every bone each frame: a track per bone
    "bake_anim_use_nla_strips": False,        # the active action only, not the NLA
    # one take: the character's previous actions, kept by the retarget with a fake user, would
    # otherwise go into the file as more takes (clips)
    "bake_anim_use_all_actions": False,
    "bake_anim_force_startend_keying": True,  # the first and last frame keyed on every channel
    "bake_anim_step": 1.0,                    # every scene frame
    # no key reduction: the simplifier drops keys and lets planted feet slide
    "bake_anim_simplify_factor": 0.0,
}

#: exporter keywords of each preset (see the module docstring for what each engine does)
PRESETS = {
    "blender": {
        # Blender's defaults for the axes and units (as the add-on always exported)
        "axis_forward": '-Z',
        "axis_up": 'Y',
        "apply_unit_scale": True,
        "apply_scale_options": 'FBX_SCALE_NONE',
        "global_scale": 1.0,
        "add_leaf_bones": False,              # no "_end" bones: they are not in the character
        "armature_nodetype": 'NULL',          # the armature object as a plain node
        "primary_bone_axis": 'Y',             # Blender's own bone axes: the rest as in Blender
        "secondary_bone_axis": 'X',
        "use_armature_deform_only": False,    # every bone, as the add-on always did
        **_ANIMATION,
    },
    "unity": {
        # Unity is +Y up; the character's front (Blender -Y) becomes +Z, Unity's forward (Unity
        # negates X to go left-handed, keeping Z)
        "axis_forward": '-Z',
        "axis_up": 'Y',
        # the scene's units into UnitScaleFactor (100 = metres) and nothing onto the objects:
        # Unity imports the armature at scale 1 instead of 100
        "apply_unit_scale": True,
        "apply_scale_options": 'FBX_SCALE_ALL',
        "global_scale": 1.0,
        # "Apply Transform" would bake the axis turn into the data, but the exporter marks it
        # experimental and broken with armatures and animation; Unity's own defaults leave it off
        "bake_space_transform": False,
        "add_leaf_bones": False,              # Unity would make a Transform of each "_end" bone
        "armature_nodetype": 'NULL',          # the armature is the root GameObject
        "primary_bone_axis": 'Y',             # Unity's Humanoid reads positions, not bone axes:
        "secondary_bone_axis": 'X',           # Blender's own axes keep the rest as it is
        # the skeleton that skins the mesh (a rig's control and mechanism bones are left out;
        # their effect is baked into the deforming bones' keys), as Blender's Unity defaults
        "use_armature_deform_only": True,
        "mesh_smooth_type": 'FACE',           # smoothing groups from the faces, as Blender's Unity defaults
        **_ANIMATION,
    },
    "unreal": {
        # Blender's own axes (Z up, -Y front) are UE's import axis system: UE converts nothing
        # and the character faces +Y in UE, as its mannequin does (Epic's Send to Unreal writes
        # these too)
        "axis_forward": 'Y',
        "axis_up": 'Z',
        # centimetres, UE's unit: UnitScaleFactor 1.0 so the file reads the same with or without
        # UE's "Convert Scene Unit"; the skeleton is exported as a stand-in in centimetres (see
        # RIG_IN_CENTIMETRES) so no scale lands on its root node
        "apply_unit_scale": True,
        "apply_scale_options": 'FBX_SCALE_NONE',
        "global_scale": 1.0,
        "bake_space_transform": False,        # experimental in the exporter, broken with armatures
        "add_leaf_bones": False,              # UE would add every "_end" bone to the skeleton
        "armature_nodetype": 'NULL',          # as Send to Unreal: the armature node is the root
        "primary_bone_axis": 'Y',             # Blender's own bone axes (Send to Unreal's choice)
        "secondary_bone_axis": 'X',
        "use_armature_deform_only": True,     # the deforming skeleton, rig mechanics baked in
        "mesh_smooth_type": 'FACE',           # UE warns of missing smoothing groups otherwise
        **_ANIMATION,
    },
}

#: presets exported through a stand-in whose bones are in centimetres (see the module docstring)
RIG_IN_CENTIMETRES = frozenset({"unreal"})

#: preset names, the default first
PRESET_NAMES = tuple(PRESETS)
DEFAULT = "blender"

#: one-line descriptions (the panel's and the command line's help)
DESCRIPTIONS = {
    "blender": "Blender's default axes and units (-Z forward, Y up, centimetres with the unit scale "
               "on the root), every bone",
    "unity": "Unity: Y up, -Z forward, metres in the file's unit and scale 1 on the objects, "
             "deforming bones only",
    "unreal": "Unreal Engine: Z up, -Y front (UE's import axes), centimetres with the skeleton at "
              "scale 1, deforming bones only",
}


def preset_kwargs(name: str) -> dict:
    """A copy of preset ``name``'s exporter keywords; ``ValueError`` for an unknown name."""
    key = str(name or DEFAULT).lower()
    if key not in PRESETS:
        raise ValueError(f"unknown FBX preset {name!r}; presets: {', '.join(PRESET_NAMES)}")
    return dict(PRESETS[key])


def accepted_keywords(operator: str = "fbx", addon: str = "io_scene_fbx") -> set:
    """The keyword names of this Blender's ``bpy.ops.export_scene.<operator>`` (enabling the
    bundled exporter add-on ``addon`` for this session when it is off); the glTF export asks for
    ``("gltf", "io_scene_gltf2")``."""
    import bpy
    try:
        rna = getattr(bpy.ops.export_scene, operator).get_rna_type()
    except (KeyError, AttributeError):
        import addon_utils
        addon_utils.enable(addon, default_set=False)
        rna = getattr(bpy.ops.export_scene, operator).get_rna_type()
    return {p.identifier for p in rna.properties if p.identifier != "rna_type"}


def exporter_kwargs(name: str, accepted=None) -> dict:
    """Preset ``name``'s keywords that the exporter accepts (``accepted``: keyword names, default
    this Blender's :func:`accepted_keywords`); keywords of other Blender versions are left out."""
    kw = preset_kwargs(name)
    have = set(accepted) if accepted is not None else accepted_keywords()
    return {k: v for k, v in kw.items() if k in have}


def units_to_centimetres(scene) -> float:
    """Centimetres per Blender unit of ``scene`` (100 for metres; the exporter's own rule)."""
    from .units import metres_per_unit
    return 100.0 * metres_per_unit(scene)


def export_fbx(filepath, armature, preset: str = DEFAULT, extra_objects=(), context=None) -> dict:
    """Write ``armature`` (with its child meshes, and ``extra_objects`` such as tracker empties)
    to the FBX ``filepath`` with preset ``preset`` (one of :data:`PRESET_NAMES`).

    The scene's frame range is baked, one take.  The selection, the active object and every
    object's name are as before afterwards (edit or pose mode is left for object mode, as the
    exporter itself does); for the ``unreal`` preset the stand-in skeleton (and copies of the
    meshes skinned to it) exist only during the export.  Tracker empties keep the unit scale on
    their nodes.  Returns
    ``{"preset", "kwargs", "objects", "stand_in"}`` (kwargs as passed to the exporter; objects:
    the names written).  ``RuntimeError`` when the exporter fails; ``ValueError`` naming
    ``filepath`` when it is too long for Windows (:func:`..core.file_names.check_path`), first.
    """
    import bpy
    context = context or bpy.context
    key = str(preset or DEFAULT).lower()
    kwargs = exporter_kwargs(key)
    meshes, extra = export_objects(filepath, armature, extra_objects, context)
    types = {'ARMATURE'} | ({'MESH'} if meshes else set()) | {o.type for o in extra}
    view_layer = context.view_layer
    factor = units_to_centimetres(context.scene)
    stand_in = key in RIG_IN_CENTIMETRES and abs(factor - 1.0) > 1e-9
    made, renamed = [], []
    with selection_kept(context):
        try:
            arm, mesh_objs = armature, meshes
            if stand_in:
                arm, mesh_objs = _centimetre_stand_in(armature, meshes, factor, context, made, renamed)
            objs = [arm] + mesh_objs + extra
            for o in view_layer.objects:
                o.select_set(o in objs)
            view_layer.objects.active = arm
            res = bpy.ops.export_scene.fbx(filepath=str(filepath), use_selection=True, object_types=types,
                                           **kwargs)
            if 'FINISHED' not in res:
                raise RuntimeError(f"FBX export failed ({res})")
            names = [o.name for o in objs]
        finally:
            for o in reversed(made):
                data = o.data if o.type == 'ARMATURE' else None
                bpy.data.objects.remove(o)
                if data is not None and data.users == 0:
                    bpy.data.armatures.remove(data)
            for obj, name in renamed:
                obj.name = name
            view_layer.update()
    return {"preset": key, "kwargs": kwargs, "objects": names, "stand_in": stand_in}


def export_objects(filepath, armature, extra_objects, context):
    """Checks shared by the FBX and glTF exports, before anything is written: ``armature`` is an
    armature (else ``ValueError``), ``filepath`` not too long for Windows
    (:func:`..core.file_names.check_path`, ``ValueError`` naming it); edit or pose mode left for
    object mode (edits flushed to the data, as the exporters do).  Returns ``(child meshes of
    armature, extra_objects less None)``."""
    import bpy
    if armature is None or armature.type != 'ARMATURE':
        raise ValueError("choose an armature to export")
    from ..core.file_names import check_path
    check_path(bpy.path.abspath(str(filepath)))     # too long for Windows: said, nothing written
    if context.mode != 'OBJECT' and bpy.ops.object.mode_set.poll():
        bpy.ops.object.mode_set(mode='OBJECT')
    return [o for o in armature.children if o.type == 'MESH'], [o for o in extra_objects if o is not None]


@contextlib.contextmanager
def selection_kept(context):
    """The view layer's selection and active object as they were when the block is left, however
    it is left (an export selects what it writes)."""
    view_layer = context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    try:
        yield
    finally:
        for o in view_layer.objects:
            if o is not None:
                o.select_set(o in selected)
        view_layer.objects.active = active


def _centimetre_stand_in(armature, meshes, factor, context, made, renamed):
    """A stand-in for ``armature`` in centimetres: a new object with a copy of its armature whose
    bones are ``factor`` times larger, following the original's world location and rotation
    (object constraints) at ``1 / factor`` of its scale (the same size in the world), each bone
    following the original's bone of the same name (Copy Location and Copy Rotation in world
    space, Copy Scale in local space); and copies of ``meshes`` skinned to it.  The stand-ins take
    the originals' names (the originals are renamed meanwhile: ``renamed`` lists ``(object,
    name)`` to restore); ``made`` collects the objects to remove.  Returns ``(stand-in armature,
    mesh copies)``."""
    import bpy
    from mathutils import Matrix
    coll = context.scene.collection
    data = armature.data.copy()
    if data.animation_data is not None:       # drivers of the original's data stay with it
        data.animation_data_clear()
    data.transform(Matrix.Scale(factor, 4))
    obj = bpy.data.objects.new(armature.name + ".stand_in", data)
    made.append(obj)
    coll.objects.link(obj)
    obj.scale = tuple(s / factor for s in armature.matrix_world.to_scale())
    for kind in ('COPY_LOCATION', 'COPY_ROTATION'):
        con = obj.constraints.new(kind)
        con.target = armature
    context.view_layer.update()               # the pose of the new object
    for pb in obj.pose.bones:
        for kind, space in (('COPY_LOCATION', 'WORLD'), ('COPY_ROTATION', 'WORLD'), ('COPY_SCALE', 'LOCAL')):
            con = pb.constraints.new(kind)
            con.target, con.subtarget = armature, pb.name
            con.owner_space = con.target_space = space
    copies = []
    scale = Matrix.Scale(factor, 4)
    for m in meshes:
        mc = m.copy()                         # shares the mesh data; vertex groups, modifiers copied
        made.append(mc)
        coll.objects.link(mc)
        mc.parent = obj
        # the stand-in's frame is the original's scaled by 1 / factor: this keeps the mesh in place
        mc.matrix_parent_inverse = scale @ m.matrix_parent_inverse
        for mod in mc.modifiers:
            if mod.type == 'ARMATURE' and mod.object == armature:
                mod.object = obj
        copies.append(mc)
    for orig, copy in [(armature, obj)] + list(zip(meshes, copies)):
        name = orig.name
        renamed.append((orig, name))
        orig.name = name[:40] + ".manikin_export"
        copy.name = name
    context.view_layer.update()
    return obj, copies


def take_actions(obj):
    """The takes of the character ``obj`` to export one by one: the ``MANIKIN_retarget_*``
    actions that key it, sorted by name."""
    import bpy
    from . import keying
    out = []
    for act in bpy.data.actions:
        if act.name.startswith("MANIKIN_retarget_") and keying.action_fcurves(
                act, obj if keying.is_slotted(act) else None):
            out.append(act)
    return sorted(out, key=lambda a: a.name)


def export_fbx_takes(directory, armature, preset: str = DEFAULT, context=None, actions=None,
                     overwrite: bool = False, file_format: str = "fbx") -> list:
    """One FBX per take (:func:`take_actions`, or ``actions``) of the character ``armature`` in ``directory`` (``//``
    relative to the .blend), or with ``file_format="glb"`` one glTF binary per take
    (:func:`.gltf_export.export_glb`, ``preset`` unused, the animation named after the take's action):
    ``<armature>_<take>.fbx`` / ``.glb`` (:func:`..core.file_names.file_stem`: letters of any script
    kept; takes whose names would be one file on Windows or macOS, ``Walk`` and ``walk``, ``Walk.001`` and
    ``Walk_001``, made unique with ``_2``...; on Windows cut, with a hash, so the path stays under 260
    characters), each with its action assigned and the scene's frame range set to the
    action's keys while it is written (:func:`export_fbx`, :func:`.gltf_export.export_glb`), the
    armature's NLA tracks not evaluated meanwhile: each file holds its take alone, a bone channel the take
    does not key at its rest value when the action shown, an NLA strip or another take animates it (it would
    otherwise carry that animation's last value) and as posed otherwise.
    The armature's action, its NLA evaluation, its pose and the frame range are as before afterwards.
    ``ValueError`` when an NLA strip of the armature is in tweak mode (its action cannot be changed), nothing
    written. Returns the paths written.  A file already there is replaced only when it is an unchanged export of an
    earlier run (:mod:`..core.output_guard`), else nothing is written and
    :class:`..core.output_guard.OutputInTheWay` (a ``ValueError``) names it, unless ``overwrite``."""
    import os
    import bpy
    from ..core import output_guard
    from ..core.file_names import file_stem, fit_stem, unique_stems
    from . import keying
    from . import character_swivel
    context = context or bpy.context
    scene = context.scene
    fmt = str(file_format or "fbx").lower()
    if fmt not in ("fbx", "glb"):
        raise ValueError(f"unknown export format {file_format!r}; formats: fbx, glb")
    if armature is None or armature.type != 'ARMATURE':
        raise ValueError("choose the character (an armature) whose takes to export")
    if character_swivel.has_rig_parts(armature):
        raise ValueError(f"{armature.name!r} carries the live swivel rig of one take, which would drive every "
                         f"take: retarget the takes with plain keys (several selected, or Keep Hands and Feet off)")
    actions = list(actions) if actions is not None else take_actions(armature)
    if not actions:
        raise ValueError(f"{armature.name!r} has no retargeted takes (MANIKIN_retarget_* actions) to export")
    takes = [act.name.replace('MANIKIN_retarget_', '').replace('MANIKIN_', '') for act in actions]
    stems = unique_stems(file_stem(f"{armature.name}_{t}") for t in takes)   # never one file on Windows, macOS
    folder = bpy.path.abspath(directory)
    # on Windows the whole path stays under 260 characters (a long take name cut, with a hash)
    stems = [fit_stem(s, f"{armature.name}_{t}", folder, len("." + fmt)) for s, t in zip(stems, takes)]
    paths = [os.path.join(folder, s + "." + fmt) for s in stems]
    ad = armature.animation_data
    if ad is not None and ad.use_tweak_mode:
        raise ValueError(f"{armature.name!r} has an NLA strip in tweak mode (Tab in the NLA editor), so its "
                         f"action cannot be changed to each take: leave tweak mode to export its takes")
    output_guard.check_free(paths, overwrite,          # no file of the user's replaced
                            remedy="tick Replace Files to replace what is there, or choose another folder")
    os.makedirs(directory, exist_ok=True)
    output_guard.claim(paths)
    before = ad.action if ad is not None else None
    use_nla = ad.use_nla if ad is not None else True
    frames = (scene.frame_start, scene.frame_end)
    # channels something else animates (the action shown, the NLA strips, the other takes): left
    # unkeyed by a take they would hold that animation's last value in its file
    others = [before] + [st.action for tr in (ad.nla_tracks if ad is not None else ()) for st in tr.strips]
    animated = _bone_channels(armature, [a for a in others + actions if a is not None])
    basis = [pb.matrix_basis.copy() for pb in armature.pose.bones]
    written = []
    try:
        for act, path in zip(actions, paths):
            keying.assign_action(armature, act).use_nla = False     # the take alone
            _rest_channels(armature, animated - _bone_channels(armature, [act]))
            a, b = act.frame_range
            scene.frame_start, scene.frame_end = int(round(a)), max(int(round(b)), int(round(a)))
            if fmt == "glb":
                from .gltf_export import export_glb
                export_glb(path, armature, context=context)
            else:
                export_fbx(path, armature, preset, context=context)
            written.append(path)
            output_guard.record([path])
    finally:
        if before is not None:
            keying.assign_action(armature, before)
        elif armature.animation_data is not None:
            armature.animation_data.action = None
        if armature.animation_data is not None:
            armature.animation_data.use_nla = use_nla
        for pb, m in zip(armature.pose.bones, basis):
            pb.matrix_basis = m
        scene.frame_start, scene.frame_end = frames
        scene.frame_set(scene.frame_current, subframe=scene.frame_subframe)
    return written


def _bone_channels(armature, actions):
    """``{(data_path, index)}`` of the pose-bone transform channels (location, rotation, scale)
    that ``actions`` key on ``armature`` (its slot on slotted actions)."""
    from . import keying
    out = set()
    for act in actions:
        for fc in keying.action_fcurves(act, armature if keying.is_slotted(act) else None):
            if fc.data_path.startswith("pose.bones[") and fc.data_path.rsplit(".", 1)[-1] in _REST_VALUE:
                out.add((fc.data_path, fc.array_index))
    return out


#: a pose channel's rest value, by property (rotation_quaternion / axis_angle: component 0)
_REST_VALUE = {"location": (0.0, 0.0, 0.0), "rotation_euler": (0.0, 0.0, 0.0), "scale": (1.0, 1.0, 1.0),
               "rotation_quaternion": (1.0, 0.0, 0.0, 0.0), "rotation_axis_angle": (0.0, 0.0, 1.0, 0.0)}


def _rest_channels(armature, channels):
    """Set the pose-bone channels ``{(data_path, index)}`` of ``armature`` to their rest values."""
    for path, index in channels:
        try:
            prop = armature.path_resolve(path)
        except ValueError:              # a bone the armature does not have
            continue
        prop[index] = _REST_VALUE[path.rsplit(".", 1)[-1]][index]
