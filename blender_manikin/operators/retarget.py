"""Retarget the solved motion onto the animator's character (``manikin.retarget``,
``manikin.save_bone_map``).  The math is :mod:`..core.retarget`; the glue
:mod:`..blender.retarget_apply`.  One Ctrl+Z undoes a retarget."""
from __future__ import annotations

from bpy.props import StringProperty
from bpy.types import Operator


def _source(context):
    """The MANIKIN armature to retarget: the active object when it is one, else the last solve's."""
    from ..blender.armature import PROP_BODY
    obj = getattr(context, "active_object", None)
    if obj is not None and obj.type == 'ARMATURE' and PROP_BODY in obj.keys():
        return obj
    s = context.scene.manikin
    return s.armature if s.armature is not None and s.armature.name in context.scene.objects else None


class MANIKIN_OT_retarget(Operator):
    """Put the solved motion onto the chosen character as a new action (its own actions are kept)"""
    bl_idname = "manikin.retarget"
    bl_label = "Retarget to Character"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "manikin", None)
        return s is not None and s.retarget_target is not None and _source(context) is not None

    def execute(self, context):
        import bpy
        from ..blender import retarget_apply
        s = context.scene.manikin
        src = _source(context)
        try:
            action, res, notes = retarget_apply.retarget_onto(
                src, s.retarget_target, s.retarget_map.lower(), bpy.path.abspath(s.retarget_map_file),
                s.retarget_root.lower(), s.retarget_keep_ends, context)
        except (ValueError, KeyError, TypeError) as exc:
            self.report({'ERROR'}, f"retarget: {exc}")
            return {'CANCELLED'}
        msg = f"MANIKIN: {src.name} -> {s.retarget_target.name} / {action.name}"
        self.report({'WARNING'} if notes else {'INFO'}, msg + ("; " + "; ".join(notes) if notes else ""))
        return {'FINISHED'}


class MANIKIN_OT_save_bone_map(Operator):
    """Save the bone map the retarget would use (preset or guess) as JSON, to edit and reuse"""
    bl_idname = "manikin.save_bone_map"
    bl_label = "Save Bone Map"
    filepath: StringProperty(subtype='FILE_PATH', default="bone_map.json")

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "manikin", None)
        return s is not None and s.retarget_target is not None

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        import bpy
        from ..blender import retarget_apply
        from ..core import bone_maps
        s = context.scene.manikin
        try:
            bmap, _ = retarget_apply.resolve_bone_map(s.retarget_map.lower(), s.retarget_target,
                                                      bpy.path.abspath(s.retarget_map_file))
            bone_maps.save_bone_map(bpy.path.abspath(self.filepath), bmap)
        except (ValueError, OSError) as exc:
            self.report({'ERROR'}, f"save bone map: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"bone map written to {self.filepath}")
        return {'FINISHED'}


CLASSES = (MANIKIN_OT_retarget, MANIKIN_OT_save_bone_map)
