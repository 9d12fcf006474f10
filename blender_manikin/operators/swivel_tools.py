"""Swivel tools: make the live rig, key / smooth / reset swivel curves, bake to plain FK.

All operate on the active object, a MANIKIN armature (see
:mod:`blender_manikin.blender.live_rig`); key / smooth / reset also on a character given the
live swivel by a retarget, which "Bake Character to FK" bakes in place
(:mod:`blender_manikin.blender.character_swivel`).  Angles are radians in the data
(custom properties with subtype ANGLE; the UI shows degrees); frames are
scene frames.  Every operator has ``bl_options = {'REGISTER', 'UNDO'}``, so
one Ctrl+Z undoes it.

Register with :func:`register` / :func:`unregister` or the ``CLASSES`` tuple.
"""
from __future__ import annotations

from bpy.props import EnumProperty, FloatProperty, IntProperty, BoolProperty
from bpy.types import Operator

from ..blender.class_registry import register_classes, unregister_classes
from ..core import skeleton as sk

_LIMB_ITEMS = [('ALL', "All Limbs", "All four limbs")] + [
    (limb, limb.replace("_", " ").title(), f"Only the {limb.replace('_', ' ')}") for limb in sk.LIMB_NAMES]


def _limbs(choice):
    return sk.LIMB_NAMES if choice == 'ALL' else (choice,)


def _live_object(context):
    from ..blender import live_rig
    obj = getattr(context, "active_object", None)
    return obj if live_rig.is_live_rig(obj) else None


def _swivel_object(context):
    """The active object when its swivel curves can be edited: a live rig, or a character with
    the live swivel of a retarget (:mod:`..blender.character_swivel`)."""
    from ..blender import character_swivel
    obj = getattr(context, "active_object", None)
    return obj if _live_object(context) is not None or character_swivel.is_character_rig(obj) else None


def _frame_range(op, context):
    scene = context.scene
    if op.use_scene_range:
        if scene.use_preview_range:
            return scene.frame_preview_start, scene.frame_preview_end
        return scene.frame_start, scene.frame_end
    return op.frame_start, op.frame_end


class _LivePoll:
    @classmethod
    def poll(cls, context):
        if _live_object(context) is None:
            cls.poll_message_set("the active object is not a MANIKIN live rig (use Make Live Rig)")
            return False
        return True


class _SwivelPoll:
    @classmethod
    def poll(cls, context):
        if _swivel_object(context) is None:
            cls.poll_message_set("the active object is not a MANIKIN live rig or a character with live swivel")
            return False
        return True


class MANIKIN_OT_make_live_rig(Operator):
    """Convert the active solved MANIKIN armature to the live swivel rig (hand/foot controls,
    swivel-driven elbows and knees); its solve action is kept and a new action is keyed"""
    bl_idname = "manikin.make_live_rig"
    bl_label = "Make Live Rig"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        from ..blender import armature as arm_mod
        obj = getattr(context, "active_object", None)
        if obj is None or obj.type != 'ARMATURE' or arm_mod.PROP_BODY not in obj.keys():
            cls.poll_message_set("select a solved MANIKIN armature")
            return False
        if obj.animation_data is None or obj.animation_data.action is None:
            cls.poll_message_set("the armature has no solve action")
            return False
        if not (obj.is_editable and obj.data.is_editable):     # its rig bones are added in edit mode
            cls.poll_message_set("the armature is linked from a library (or a library override): "
                                 "its bones cannot be edited in this file")
            return False
        return True

    def execute(self, context):
        from ..blender import live_rig, writer
        obj = context.active_object
        try:
            result, frames = live_rig.result_from_fk_action(obj, writer.scene_fps(context.scene))
            action = live_rig.build_live_rig(obj, result, frames=frames, context=context)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"MANIKIN: live rig on {obj.name!r}, action {action.name!r} "
                    f"({len(frames)} frames)")
        return {'FINISHED'}


class MANIKIN_OT_key_swivel(_SwivelPoll, Operator):
    """Key the current swivel value(s) at the current frame (keeps a slider edit)"""
    bl_idname = "manikin.key_swivel"
    bl_label = "Key Swivel"
    bl_options = {'REGISTER', 'UNDO'}

    limb: EnumProperty(name="Limb", items=_LIMB_ITEMS, default='ALL')

    def execute(self, context):
        from ..blender import live_rig
        obj = _swivel_object(context)
        frame = context.scene.frame_current + context.scene.frame_subframe
        try:
            n = live_rig.key_swivel(obj, _limbs(self.limb), live_rig.action_frame(obj, frame), context=context)
        except ValueError as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"MANIKIN: keyed {n} swivel value(s) at frame {frame:g}")
        return {'FINISHED'}


class MANIKIN_OT_smooth_swivel(_SwivelPoll, Operator):
    """Smooth the swivel keys over a frame range (Gaussian or box filter of the unwrapped angles)"""
    bl_idname = "manikin.smooth_swivel"
    bl_label = "Smooth Swivel"
    bl_options = {'REGISTER', 'UNDO'}

    limb: EnumProperty(name="Limb", items=_LIMB_ITEMS, default='ALL')
    method: EnumProperty(name="Filter", items=[
        ('GAUSSIAN', "Gaussian", "Gaussian weights, window ±3 sigma"),
        ('BOX', "Box", "Moving average over ±width frames")], default='GAUSSIAN')
    sigma: FloatProperty(name="Width", description="Gaussian sigma / box half width, in frames",
                         default=2.0, min=0.0, soft_max=20.0)
    use_scene_range: BoolProperty(name="Scene Range", default=True,
                                  description="Use the scene's (preview) frame range")
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=250)

    def execute(self, context):
        from ..blender import live_rig
        obj = _swivel_object(context)
        f0, f1 = live_rig.action_frame_range(obj, *_frame_range(self, context))
        try:
            n = live_rig.smooth_swivel(obj, _limbs(self.limb), f0, f1, self.sigma, self.method)
        except ValueError as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"MANIKIN: smoothed {n} swivel keys in frames {f0}-{f1}")
        return {'FINISHED'}


class MANIKIN_OT_reset_swivel(_SwivelPoll, Operator):
    """Restore the solver's swivel (stored at solve time) on the swivel curves"""
    bl_idname = "manikin.reset_swivel"
    bl_label = "Reset Swivel to Solved"
    bl_options = {'REGISTER', 'UNDO'}

    limb: EnumProperty(name="Limb", items=_LIMB_ITEMS, default='ALL')
    scope: EnumProperty(name="Frames", items=[
        ('ALL', "All", "Every key"),
        ('RANGE', "Scene Range", "Keys in the scene's (preview) frame range"),
        ('CURRENT', "Current Frame", "Only the key at the current frame")], default='ALL')

    @classmethod
    def description(cls, context, properties):
        """The panel's Reset and Reset All share this operator: each tooltip says which frames."""
        frames = {'ALL': "on every frame", 'RANGE': "in the scene's (preview) frame range",
                  'CURRENT': "at the current frame only"}[properties.scope]
        return f"Restore the solver's swivel (stored at solve time) {frames}"

    def execute(self, context):
        from ..blender import live_rig
        obj = _swivel_object(context)
        scene = context.scene
        if self.scope == 'ALL':
            f0 = f1 = None
        elif self.scope == 'RANGE':
            f0, f1 = ((scene.frame_preview_start, scene.frame_preview_end) if scene.use_preview_range
                      else (scene.frame_start, scene.frame_end))
        else:
            f0 = f1 = scene.frame_current
        try:
            n = live_rig.reset_swivel(obj, _limbs(self.limb), *live_rig.action_frame_range(obj, f0, f1))
        except ValueError as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        if n == 0:
            self.report({'WARNING'}, "MANIKIN: no solved swivel stored on this armature")
            return {'CANCELLED'}
        scene.frame_set(scene.frame_current, subframe=scene.frame_subframe)
        self.report({'INFO'}, f"MANIKIN: reset the swivel of {n} limb(s)")
        return {'FINISHED'}


class MANIKIN_OT_bake_live_rig(_LivePoll, Operator):
    """Bake the live rig to plain FK keys on a new armature (deform bones only, no constraints,
    drivers or add-on logic) for FBX / BVH / game-engine export"""
    bl_idname = "manikin.bake_live_rig"
    bl_label = "Bake to FK"
    bl_options = {'REGISTER', 'UNDO'}

    use_scene_range: BoolProperty(name="Scene Range", default=True,
                                  description="Bake the scene's (preview) frame range")
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=250)

    def execute(self, context):
        from ..blender import live_rig
        obj = _live_object(context)
        f0, f1 = _frame_range(self, context)
        try:
            new = live_rig.bake_live_rig(obj, f0, f1, context=context)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"MANIKIN: baked frames {f0}-{f1} of {obj.name!r} into {new.name!r}")
        return {'FINISHED'}


class MANIKIN_OT_bake_character_swivel(Operator):
    """Bake the live swivel of the active character into plain FK keys (a new action, the live one
    kept) and remove its swivel rig, so the character exports as plain keys"""
    bl_idname = "manikin.bake_character_swivel"
    bl_label = "Bake Character to FK"
    bl_options = {'REGISTER', 'UNDO'}

    use_scene_range: BoolProperty(name="Scene Range", default=False,
                                  description="Bake the scene's (preview) frame range instead of the action's")
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=250)
    remove_rig: BoolProperty(name="Remove Swivel Rig", default=True,
                             description="Remove the controls and constraints the retarget added "
                                         "(off: mute them)")

    @classmethod
    def poll(cls, context):
        from ..blender import character_swivel
        if not character_swivel.is_character_rig(getattr(context, "active_object", None)):
            cls.poll_message_set("the active object is not a character with live swivel (Retarget to Character)")
            return False
        return True

    def execute(self, context):
        from ..blender import character_swivel
        obj = context.active_object
        f0 = f1 = None
        if self.use_scene_range:
            f0, f1 = _frame_range(self, context)
        try:
            action = character_swivel.bake_character_rig(obj, f0, f1, context=context, remove_rig=self.remove_rig)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {exc}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"MANIKIN: baked {obj.name!r} into {action.name!r}")
        return {'FINISHED'}


CLASSES = (MANIKIN_OT_make_live_rig, MANIKIN_OT_key_swivel, MANIKIN_OT_smooth_swivel,
           MANIKIN_OT_reset_swivel, MANIKIN_OT_bake_live_rig, MANIKIN_OT_bake_character_swivel)


def register():
    register_classes(CLASSES)


def unregister():
    unregister_classes(CLASSES)
