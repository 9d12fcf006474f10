"""Export the character (or the solved armature) with its animation as FBX for Blender, Unity or
Unreal (``manikin.export_fbx``; the settings are :mod:`..blender.fbx_presets`) or as glTF binary
(``manikin.export_gltf``; :mod:`..blender.gltf_export`), and each retargeted take as a file of its
own in either format (``manikin.export_fbx_takes``)."""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty, StringProperty
from bpy.types import Operator
from bpy_extras.io_utils import ExportHelper

from ..blender.properties import export_format_items, fbx_preset_items


def export_object(context):
    """What Export FBX / glTF writes: the retarget's character when one is chosen, else the solved
    MANIKIN armature (the active one, else the last solve's); None when there is neither."""
    from .retarget import _source
    s = getattr(context.scene, "manikin", None)
    if s is None:
        return None
    if s.retarget_target is not None and s.retarget_target.name in context.scene.objects:
        return s.retarget_target
    return _source(context)


def _preset_from_panel(op, context):
    """The panel's FBX preset (and format, for Export Each Take) for an export operator whose
    preset (format) was not given."""
    if not op.properties.is_property_set("preset"):
        op.preset = context.scene.manikin.export_fbx_preset
    if hasattr(op.properties, "file_format") and not op.properties.is_property_set("file_format"):
        op.file_format = context.scene.manikin.export_format


class MANIKIN_OT_export_fbx(Operator, ExportHelper):
    """Export the character (or, with none chosen, the solved armature) and its animation as FBX,
    with the axes, units and bones the chosen application expects"""
    bl_idname = "manikin.export_fbx"
    bl_label = "Export FBX"
    bl_options = {'REGISTER', 'UNDO'}
    filename_ext = ".fbx"
    filter_glob: StringProperty(default="*.fbx", options={'HIDDEN'})
    preset: EnumProperty(name="Preset", items=fbx_preset_items(), default='BLENDER',
                         description="Axes, units and bones of the file, for the application that reads it")

    @classmethod
    def poll(cls, context):
        return export_object(context) is not None

    def invoke(self, context, event):
        _preset_from_panel(self, context)
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender import fbx_presets
        obj = export_object(context)
        try:
            info = fbx_presets.export_fbx(self.filepath, obj, self.preset.lower(), context=context)
        except (ValueError, RuntimeError, OSError) as exc:
            self.report({'ERROR'}, f"export FBX: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"{obj.name} written to {self.filepath} ({info['preset']} preset, frames "
                              f"{context.scene.frame_start}-{context.scene.frame_end})")
        return {'FINISHED'}


class MANIKIN_OT_export_gltf(Operator, ExportHelper):
    """Export the character (or, with none chosen, the solved armature) and its animation as glTF
    binary (.glb): Y up, metres, deforming bones, the scene's frame range sampled at every frame"""
    bl_idname = "manikin.export_gltf"
    bl_label = "Export glTF"
    bl_options = {'REGISTER', 'UNDO'}
    filename_ext = ".glb"
    filter_glob: StringProperty(default="*.glb", options={'HIDDEN'})

    @classmethod
    def poll(cls, context):
        return export_object(context) is not None

    def execute(self, context):
        from ..blender import gltf_export
        obj = export_object(context)
        try:
            info = gltf_export.export_glb(self.filepath, obj, context=context)
        except (ValueError, RuntimeError, OSError) as exc:
            self.report({'ERROR'}, f"export glTF: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"{obj.name} written to {self.filepath} (animation {info['animation']!r}, frames "
                              f"{context.scene.frame_start}-{context.scene.frame_end})")
        return {'FINISHED'}


class MANIKIN_OT_export_fbx_takes(Operator):
    """Export each take retargeted onto the character as a file of its own (<character>_<take>.fbx
    or .glb), in the chosen format (and FBX preset)"""
    bl_idname = "manikin.export_fbx_takes"
    bl_label = "Export Each Take"
    bl_options = {'REGISTER'}
    directory: StringProperty(subtype='DIR_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    filter_folder: bpy.props.BoolProperty(default=True, options={'HIDDEN'})
    preset: EnumProperty(name="Preset", items=fbx_preset_items(), default='BLENDER',
                         description="Axes, units and bones of the files, for the application that reads them")
    file_format: EnumProperty(name="Format", items=export_format_items(), default='FBX',
                              description="FBX (with the preset) or glTF binary")
    overwrite: bpy.props.BoolProperty(
        name="Replace Files", default=False,
        description="Replace files of these names in the folder even when they are not this add-on's unchanged "
                    "exports (yours, or exports edited since); off: such a folder is refused, nothing written")

    @classmethod
    def poll(cls, context):
        """Greyed out, saying why, until there is a take to write: a character chosen (in this
        scene) with at least one retargeted take (:func:`..blender.fbx_presets.take_actions`)."""
        from ..blender.fbx_presets import take_actions
        s = getattr(context.scene, "manikin", None)
        if s is None:
            return False
        char = s.retarget_target
        if char is None or char.name not in context.scene.objects:
            cls.poll_message_set("choose the Character (Retarget to Character) first")
            return False
        if not take_actions(char):
            cls.poll_message_set(f"{char.name} has no retargeted takes: press Retarget to Character first")
            return False
        return True

    def invoke(self, context, event):
        _preset_from_panel(self, context)
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        from ..blender import fbx_presets
        char = context.scene.manikin.retarget_target
        try:
            paths = fbx_presets.export_fbx_takes(self.directory, char, self.preset.lower(), context=context,
                                                 overwrite=self.overwrite, file_format=self.file_format.lower())
        except (ValueError, RuntimeError, OSError) as exc:
            self.report({'ERROR'}, f"export takes: {exc}")
            return {'CANCELLED'}
        how = "glTF binary" if self.file_format == 'GLB' else f"FBX, {self.preset.lower()} preset"
        self.report({'INFO'}, f"{len(paths)} take(s) of {char.name} written to {self.directory} ({how})")
        return {'FINISHED'}


CLASSES = (MANIKIN_OT_export_fbx, MANIKIN_OT_export_gltf, MANIKIN_OT_export_fbx_takes)
