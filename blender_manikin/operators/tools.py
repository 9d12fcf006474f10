"""Small helper operators of the MANIKIN panel: find the T-pose, load an offsets preset."""

import json

import bpy
from bpy.props import StringProperty
from bpy.types import Operator

from ..blender import solve_job as sj


class MANIKIN_OT_find_tpose(Operator):
    """Find the most T-pose-like moment of the source and use it for calibration"""
    bl_idname = "manikin.find_tpose"
    bl_label = "Find T-Pose"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return context.scene is not None and hasattr(context.scene, "manikin")

    def execute(self, context):
        from ..blender.properties import config_from_settings
        s = context.scene.manikin
        try:
            seconds, cand = sj.find_tpose_time(config_from_settings(context), context)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")
            return {'CANCELLED'}
        s.tpose_time = seconds
        s.calibration = 'TPOSE'
        if cand.plausible:
            self.report({'INFO'}, f"MANIKIN: T-pose at {seconds:.2f} s")
        else:
            self.report({'WARNING'}, f"MANIKIN: best candidate at {seconds:.2f} s does not look like a "
                        f"still T-pose (hand span {100 * cand.span_ratio:.0f}% of expected, "
                        f"hand speed {cand.speed:.2f} m/s)")
        return {'FINISHED'}


class MANIKIN_OT_load_offsets_preset(Operator):
    """Copy the chosen device offsets preset into a text block that you can edit; the solve uses it"""
    bl_idname = "manikin.load_offsets_preset"
    bl_label = "Edit Offsets"
    bl_options = {'REGISTER', 'UNDO'}

    preset: StringProperty(name="Preset", default="",
                           description="Preset name (empty: the panel's choice)")

    @classmethod
    def poll(cls, context):
        return context.scene is not None and hasattr(context.scene, "manikin")

    def execute(self, context):
        from ..core import device_offsets
        s = context.scene.manikin
        name = self.preset or s.offsets_preset
        if name == "auto":
            self.report({'ERROR'}, "MANIKIN: choose a preset to edit (Auto picks one per recording)")
            return {'CANCELLED'}
        try:
            data = device_offsets.get_preset(name)
        except ValueError as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        text = bpy.data.texts.new(f"MANIKIN_offsets_{name}.json")
        text.write(json.dumps(data, indent=2) + "\n")
        s.offsets_text = text
        self.report({'INFO'}, f"MANIKIN: offsets in text {text.name!r} (edit it in the Text Editor; "
                    f"clear the Edited Offsets field to use the preset again)")
        return {'FINISHED'}


CLASSES = (MANIKIN_OT_find_tpose, MANIKIN_OT_load_offsets_preset)
