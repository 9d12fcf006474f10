"""glTF binary (``.glb``) export of an armature and its animation, for game engines and the web
(Godot, three.js, Babylon.js, Unity with glTFast), through Blender's own glTF exporter
(``bpy.ops.export_scene.gltf``, the bundled ``io_scene_gltf2`` add-on).

Every ``.glb`` the add-on writes (``cli.py solve --format glb``, the panel's **Export glTF** and
**Export Each Take** with the glTF format) goes through :func:`export_glb` with :data:`SETTINGS`:
like the FBX presets (:mod:`.fbx_presets`) one take, the scene's frame range sampled at every
frame with no key reduction, so constraints, drivers and the live swivel rig (which glTF cannot
hold) are baked into plain node tracks.  glTF has one axis system and one unit (+Y up, +Z the
asset's front, metres), so there is no preset: Blender's +Z up becomes +Y and the body's front
(Blender -Y) +Z, the exporter's own conversion; lengths in metres as the scene shows them.
Keywords a Blender version's exporter lacks are left out (:func:`exporter_kwargs`): the names below
are those of Blender 4.2 and 5.0 alike.
"""
from __future__ import annotations

#: ``bpy.ops.export_scene.gltf`` keywords of every export (each commented with why)
SETTINGS = {
    "export_format": 'GLB',                   # one binary file: JSON, buffers and any textures inside
    "use_selection": True,                    # the armature, its meshes and extras only (selected by export_glb)
    "export_yup": True,                       # glTF's +Y up (Blender's +Z); the body's front becomes +Z
    "export_apply": False,                    # modifiers kept: the mannequin stays skinned, not frozen
    "export_skins": True,                     # the child meshes skinned to the joints
    "export_def_bones": True,                 # deforming bones only: a rig's control and mechanism bones
                                              # (the live rig's MCH-*) have their effect baked into the keys
    "export_leaf_bone": False,                # no extra "_end" joints: not in the character
    "export_rest_position_armature": True,    # the skin's bind pose is the rest pose, as in Blender
    "export_animations": True,
    # one animation: the active action(s), merged (the character's older actions, kept by the
    # retarget with a fake user, stay out of the file, as in the FBX's one take)
    "export_animation_mode": 'ACTIVE_ACTIONS',
    # not every armature action of the file: with one armature exported, the exporter of 4.2 (its
    # default) adds all of them to that one merged animation, the other takes' keys over the take's
    # (Export Each Take in 4.2 wrote the first take's 30 frames into a 40-frame take's file)
    "export_anim_single_armature": False,
    "export_frame_range": True,               # the scene's frame range
    "export_frame_step": 1,                   # every scene frame
    "export_force_sampling": True,            # constraints, drivers and the live rig sampled to keys
    # no key reduction: the optimiser drops keys it finds redundant (as the FBX path, which
    # writes every frame: reduction lets planted feet slide)
    "export_optimize_animation_size": False,
    "export_anim_slide_to_zero": True,        # the take's first frame at 0 s: a clip an engine plays from 0
    "export_bake_animation": False,           # objects without an action (the mesh) get no tracks
    "export_extras": False,                   # custom properties (the swivel values) stay in Blender
    "export_cameras": False,
    "export_lights": False,
    "will_save_settings": False,              # no exporter settings stored in the user's scene
    # export_loglevel is left at -1: any other value fails in the exporter of 4.2 and 5.0
    # (KeyError 'loglevel': it sets that setting only for -1)
}


#: set once this process has run the glTF exporter (:func:`exit_crashes`)
_exported = False


def exit_crashes() -> bool:
    """Whether this process would crash on leaving Python: Blender 4.2's ``bpy`` module, once its
    glTF exporter has run, ends with a segmentation fault (exit status 139) after every output is
    written: its static ``SpaceType`` destructors free Python classes after the interpreter has
    finished (``bpy_class_free`` → ``PyGILState_Ensure`` with no interpreter).  The entry points
    (:func:`blender_manikin.cli.exit_process`, the tests' ``conftest.py``) then leave by
    ``os._exit`` with their own status.  Blender binaries, and the module of 4.3 and later (5.0.1
    and 5.2.3 tested), leave cleanly."""
    if not _exported:
        return False
    import bpy
    return not bpy.app.binary_path and tuple(bpy.app.version) < (4, 3, 0)


def accepted_keywords() -> set:
    """The keyword names of this Blender's ``bpy.ops.export_scene.gltf`` (the bundled add-on
    enabled for this session when it is off)."""
    from .fbx_presets import accepted_keywords as keywords
    return keywords("gltf", "io_scene_gltf2")


def exporter_kwargs(accepted=None) -> dict:
    """:data:`SETTINGS` that the exporter accepts (``accepted``: keyword names, default this
    Blender's :func:`accepted_keywords`); keywords of other Blender versions are left out."""
    have = set(accepted) if accepted is not None else accepted_keywords()
    return {k: v for k, v in SETTINGS.items() if k in have}


def exporter_fps_base(fps_base: float) -> float:
    """The ``render.fps_base`` to give the exporter for a scene's ``fps_base``.  Blender plays
    ``render.fps / fps_base`` frames a second, but the glTF exporter of 4.2 and 5.0 times its keys
    as ``frame / (render.fps * fps_base)`` (``keyframes.py``, the samplers): right only for
    ``fps_base`` 1.  A 29.97 fps solve (fps 30, fps_base 1.001) came out at 30.03 fps, its 210
    frames 6.960 s long instead of 6.974 s.  So the exporter is given ``1 / fps_base`` while it
    writes (the frames it samples do not depend on it), and the scene's is set back afterwards."""
    return 1.0 / fps_base if abs(fps_base - 1.0) > 1e-12 else fps_base


def export_glb(filepath, armature, extra_objects=(), context=None, name=None) -> dict:
    """Write ``armature`` (with its child meshes, and ``extra_objects`` such as tracker empties) to
    the glTF binary ``filepath`` (``.glb``): the joints its deforming bones, the meshes skinned to
    them, one animation named ``name`` (default: the armature's action's name) sampled at every
    frame of the scene's range, starting at 0 s; the scene's frame rate (``render.fps / fps_base``)
    gives the times (seconds; :func:`exporter_fps_base`).

    The selection, the active object, the current frame, the frame rate and the file's objects and
    actions are as before afterwards (edit or pose mode is left for object mode, as the exporter does).  Returns
    ``{"kwargs", "objects", "animation"}``.  ``RuntimeError`` when the exporter fails; ``ValueError``
    when ``armature`` is not one, or naming ``filepath`` when it is too long for Windows, nothing
    written."""
    import bpy
    from .fbx_presets import export_objects, selection_kept
    context = context or bpy.context
    meshes, extra = export_objects(filepath, armature, extra_objects, context)
    have = accepted_keywords()
    kwargs = exporter_kwargs(have)
    ad = armature.animation_data
    if name is None:
        name = ad.action.name if ad is not None and ad.action is not None else armature.name
    if "export_nla_strips_merged_animation_name" in have:      # the merged take's name
        kwargs["export_nla_strips_merged_animation_name"] = str(name)
    scene = context.scene
    frame = (scene.frame_current, scene.frame_subframe)
    base = scene.render.fps_base
    view_layer = context.view_layer
    objs = [armature] + meshes + extra
    with selection_kept(context):
        try:
            for o in view_layer.objects:
                o.select_set(o in objs)
            view_layer.objects.active = armature
            scene.render.fps_base = exporter_fps_base(base)
            global _exported
            _exported = True
            res = bpy.ops.export_scene.gltf(filepath=str(filepath), **kwargs)
            if 'FINISHED' not in res:
                raise RuntimeError(f"glTF export failed ({res})")
        finally:
            scene.render.fps_base = base
            scene.frame_set(frame[0], subframe=frame[1])
    return {"kwargs": kwargs, "objects": [o.name for o in objs], "animation": str(name)}
