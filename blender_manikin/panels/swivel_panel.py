"""The "Swivel & Posing" section of the MANIKIN sidebar tab (3D Viewport > Sidebar > MANIKIN).

Shows, for the active MANIKIN armature (or a character given the live swivel by a retarget,
:mod:`blender_manikin.blender.character_swivel`), each limb's swivel angle as a slider
(the keyed custom property ``["swivel_<limb>"]``, radians in the data,
displayed in the scene's rotation unit, degrees by default) with the
solver's value next to it, and the swivel tools of
:mod:`blender_manikin.operators.swivel_tools`.  It does not depend on
``Scene.manikin`` and can be registered on its own (:func:`register`).
"""
from __future__ import annotations

import math

from bpy.types import Panel

from ..blender.class_registry import register_classes, unregister_classes
from ..core import skeleton as sk

_LABELS = {"left_arm": "Left Elbow", "right_arm": "Right Elbow",
           "left_leg": "Left Knee", "right_leg": "Right Knee"}


class MANIKIN_PT_swivel(Panel):
    bl_label = "Swivel & Posing"
    bl_idname = "MANIKIN_PT_swivel"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "MANIKIN"
    bl_order = 10

    @classmethod
    def poll(cls, context):
        from ..blender import armature as arm_mod
        from ..blender import character_swivel
        obj = getattr(context, "active_object", None)
        return obj is not None and obj.type == 'ARMATURE' and (
            arm_mod.PROP_BODY in obj.keys() or character_swivel.is_character_rig(obj))

    def draw(self, context):
        from ..blender import character_swivel, live_rig, writer
        from .main import wrapped
        layout = self.layout
        obj = context.active_object
        character = character_swivel.is_character_rig(obj)
        live = live_rig.is_live_rig(obj) or character
        if not live:
            col = layout.column()
            for i, line in enumerate(wrapped("Plain FK solve: make it live to edit elbows and knees by their "
                                             "swivel.", context)):
                col.label(text=line, icon='INFO' if i == 0 else 'BLANK1')
            col.operator("manikin.make_live_rig", icon='CON_KINEMATIC')
        col = layout.column(align=True)
        if any(live_rig.SOLVED_PROPS[limb] in obj.keys() for limb in sk.LIMB_NAMES):
            head = col.row()
            head.label(text="Swivel")
            sub = head.row()
            sub.alignment = 'RIGHT'
            sub.label(text="Solved")
        for limb in sk.LIMB_NAMES:
            prop = writer.SWIVEL_PROPS[limb]
            if prop not in obj.keys():
                continue
            row = col.row(align=True)
            row.enabled = live
            row.prop(obj, f'["{prop}"]', text=_LABELS[limb], slider=True)
            solved = live_rig.SOLVED_PROPS[limb]
            if solved in obj.keys():
                sub = row.row(align=True)
                sub.alignment = 'RIGHT'
                sub.label(text=f"{round(math.degrees(float(obj[solved]))):d}°")     # an int: no "-0°"
        if not live:
            return
        row = layout.row(align=True)
        row.operator("manikin.key_swivel", icon='KEY_HLT').limb = 'ALL'
        row.operator("manikin.reset_swivel", text="Reset", icon='LOOP_BACK').scope = 'CURRENT'
        row = layout.row(align=True)
        row.operator("manikin.smooth_swivel", text="Smooth", icon='SMOOTHCURVE')   # "Smooth Sw..." at 250 px
        row.operator("manikin.reset_swivel", text="Reset All", icon='FILE_REFRESH').scope = 'ALL'
        if character:
            layout.operator("manikin.bake_character_swivel", icon='ACTION')
            hint = "Pose mode: grab MANIKIN_ctrl_hand.L/.R and MANIKIN_ctrl_foot.L/.R."
        else:
            layout.operator("manikin.bake_live_rig", icon='ACTION')
            hint = "Pose mode: grab ctrl_hand.L/.R and ctrl_foot.L/.R; torso and head are FK."
        box = layout.box().column(align=True)
        for i, line in enumerate(wrapped(hint, context)):       # cut to the sidebar's width
            box.label(text=line, icon='BONE_DATA' if i == 0 else 'BLANK1')


CLASSES = (MANIKIN_PT_swivel,)


def register():
    register_classes(CLASSES)


def unregister():
    unregister_classes(CLASSES)
