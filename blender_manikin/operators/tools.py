"""Small helper operators of the MANIKIN panel: find the T-pose, load an offsets preset, map
scene objects to devices by their names."""

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
        where = " of the calibration take" if s.calibration_take and s.source != 'KEYPOINTS' else ""
        if cand.plausible:
            self.report({'INFO'}, f"MANIKIN: T-pose at {seconds:.2f} s{where}")
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


def _animated(obj):
    ad = obj.animation_data
    return bool((ad is not None and (ad.action is not None or len(ad.drivers) or len(ad.nla_tracks)))
                or obj.parent is not None or len(obj.constraints))


class MANIKIN_OT_map_devices(Operator):
    """Map the scene's animated objects to the devices they are named after (HMD, LeftController,
    Tracker_LeftFoot, MANIKIN_head, ...); devices already mapped are kept"""
    bl_idname = "manikin.map_devices"
    bl_label = "Map by Name"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        from ..core.devices import DEVICES, LABELS, device_of_object_name
        s = context.scene.manikin
        found = {}
        for obj in sorted(context.scene.objects, key=lambda o: o.name):
            if obj.type in ('CAMERA', 'LIGHT') or not _animated(obj):
                continue
            d = device_of_object_name(obj.name)
            if d is not None:
                found.setdefault(d, []).append(obj)
        mapped, kept, doubts = [], [], []
        for d in DEVICES:
            slot = getattr(s, d)
            if slot.object is not None:
                kept.append(LABELS[d])
                continue
            if d in found:
                slot.object, slot.bone = found[d][0], ""
                mapped.append(f"{LABELS[d]} {found[d][0].name}")
                if len(found[d]) > 1:
                    doubts.append(f"{LABELS[d]}: also {', '.join(o.name for o in found[d][1:])}")
        if not mapped:
            self.report({'WARNING'}, "MANIKIN: no animated object is named after an unmapped device "
                                     "(e.g. HMD, LeftController, Tracker_LeftFoot)")
            return {'CANCELLED'}
        msg = "MANIKIN: mapped " + ", ".join(mapped)
        if kept:
            msg += f"; kept {', '.join(kept)}"
        if doubts:
            msg += f"; more than one object for {'; '.join(doubts)}"
        self.report({'INFO'}, msg)
        return {'FINISHED'}


CLASSES = (MANIKIN_OT_find_tpose, MANIKIN_OT_load_offsets_preset, MANIKIN_OT_map_devices)
