"""Retarget the solved motion onto the animator's character (``manikin.retarget``), and the
bone map editor's operators (``manikin.load_bone_map``, ``manikin.save_bone_map``).  The math is
:mod:`..core.retarget`; the glue :mod:`..blender.retarget_apply` and
:mod:`..blender.bone_map_list`.  One Ctrl+Z undoes a retarget or a Load Map."""
from __future__ import annotations

import os

from bpy.props import BoolProperty, StringProperty
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
    """Put the solved motion onto the chosen character as a new action (its own actions are kept);
    with several solved armatures selected, each take as an action of its own"""
    bl_idname = "manikin.retarget"
    bl_label = "Retarget to Character"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "manikin", None)
        if s is None:
            return False
        if s.retarget_target is None:
            cls.poll_message_set("choose the Character (its armature) first")
            return False
        if _source(context) is None:
            cls.poll_message_set("solve first, or select a solved MANIKIN armature")
            return False
        return True

    def execute(self, context):
        import bpy
        from ..blender import retarget_apply
        s = context.scene.manikin
        sources = _selected_sources(context) or [_source(context)]
        # several takes: one action each on the character, plain keys (a live swivel rig is the
        # character's, one at a time, and would drive only the last)
        live = s.retarget_keep_ends and s.retarget_live_swivel and len(sources) == 1
        made = []
        wm = context.window_manager
        wm.progress_begin(0, 100)               # the mouse cursor counts while a long take is read
        try:
            for i, src in enumerate(sources):
                def progress(f, i=i):
                    wm.progress_update(int(100 * (i + f) / len(sources)))
                try:
                    if s.retarget_map == 'EDITED':
                        action, res, notes = _retarget_with_edited_list(src, s, context, live, progress)
                    else:
                        action, res, notes = retarget_apply.retarget_onto(
                            src, s.retarget_target, s.retarget_map.lower(), bpy.path.abspath(s.retarget_map_file),
                            s.retarget_root.lower(), s.retarget_keep_ends, context, live_swivel=live,
                            progress=progress)
                except (ValueError, KeyError, TypeError, OSError) as exc:
                    self.report({'ERROR'}, f"retarget of {src.name}: {exc}")
                    return {'CANCELLED'}
                made.append(action.name)
                msg = f"MANIKIN: {src.name} -> {s.retarget_target.name} / {action.name}"
                self.report({'WARNING'} if notes else {'INFO'}, msg + ("; " + "; ".join(notes) if notes else ""))
        finally:
            wm.progress_end()
        if len(made) > 1:
            self.report({'INFO'}, f"MANIKIN: {len(made)} takes retargeted onto {s.retarget_target.name}: "
                                  f"{', '.join(made)} (the last assigned; the others kept with a fake user)")
        return {'FINISHED'}


def _retarget_with_edited_list(src, s, context, live_swivel, progress=None):
    """The retarget with the bone map list as edited, checked against the character first (a bone
    it lacks is an error naming the joint and the bone)."""
    from ..blender import bone_map_list, retarget_apply
    bmap = bone_map_list.checked_bone_map(s, s.retarget_target)
    return retarget_apply.retarget_onto(src, s.retarget_target, bmap, None, s.retarget_root.lower(),
                                        s.retarget_keep_ends, context, live_swivel=live_swivel, progress=progress)


def _selected_sources(context):
    """The selected MANIKIN armatures when there are several (each take retargeted in turn,
    sorted by name), else ``[]``."""
    from ..blender.armature import PROP_BODY
    sel = [o for o in (getattr(context, "selected_objects", None) or [])
           if o.type == 'ARMATURE' and PROP_BODY in o.keys()]
    return sorted(sel, key=lambda o: o.name) if len(sel) > 1 else []


class MANIKIN_OT_load_bone_map(Operator):
    """Fill the bone map list from the chosen map (Guess, a preset or a saved file) for the
    chosen character; the list's edits are replaced"""
    bl_idname = "manikin.load_bone_map"
    bl_label = "Load Map"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "manikin", None)
        if s is None or s.retarget_target is None:
            return False
        if s.retarget_map == 'EDITED':
            if hasattr(cls, "poll_message_set"):
                cls.poll_message_set("Choose Guess, a preset or From File to load the list from")
            return False
        return True

    def execute(self, context):
        from ..blender import bone_map_list
        s = context.scene.manikin
        try:
            bmap, notes = bone_map_list.load_choice(s, s.retarget_target)
        except (ValueError, OSError, KeyError, TypeError) as exc:
            self.report({'ERROR'}, f"load bone map: {exc}")
            return {'CANCELLED'}
        doubtful = [f"{g.joint}: {g.bone or 'no bone'} ({g.why})" for g in notes if g.confidence < 0.5]
        msg = f"bone map {bmap.name!r}: {len(bmap.bones)} of {len(s.retarget_bone_map)} joints mapped"
        self.report({'WARNING'} if doubtful else {'INFO'}, msg + ("; check " + "; ".join(doubtful) if doubtful else ""))
        return {'FINISHED'}


class MANIKIN_OT_save_bone_map(Operator):
    """Save the bone map list as it is (or, while it is empty, the chosen map) as JSON, to reuse
    with From File or on the command line (--bone-map FILE.json)"""
    bl_idname = "manikin.save_bone_map"
    bl_label = "Save Map"
    bl_options = {'REGISTER'}                  # writes a file; the scene is not changed
    filepath: StringProperty(subtype='FILE_PATH', default="",
                             description="Where to write the map (default: the user's bone map folder)")
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})
    #: the file browser marks a name that exists in red before it is replaced (as Export FBX's does)
    check_existing: BoolProperty(name="Check Existing", default=True, options={'HIDDEN'},
                                 description="Warn before replacing a file of this name")

    @classmethod
    def poll(cls, context):
        s = getattr(context.scene, "manikin", None)
        return s is not None and (len(s.retarget_bone_map) > 0 or s.retarget_target is not None)

    def _default_path(self, context, create):
        from ..blender import bone_map_list
        name = _file_name(context.scene.manikin.retarget_bone_map_name or "bone_map")
        return os.path.join(bone_map_list.user_folder(create=create), name + ".json")

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = self._default_path(context, create=True)
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        import bpy
        from ..blender import bone_map_list, retarget_apply
        from ..core import bone_maps
        from ..core.file_names import check_path
        s = context.scene.manikin
        try:
            path = bpy.path.abspath(self.filepath) if self.filepath else self._default_path(context, create=True)
            check_path(path)                   # too long for Windows: said, nothing written
            if len(s.retarget_bone_map):
                bmap = bone_map_list.to_bone_map(s)
            else:
                bmap, _ = retarget_apply.resolve_bone_map(s.retarget_map.lower(), s.retarget_target,
                                                          bpy.path.abspath(s.retarget_map_file))
            bone_maps.save_bone_map(path, bmap)
        except (ValueError, OSError) as exc:
            self.report({'ERROR'}, f"save bone map: {exc}")
            return {'CANCELLED'}
        self.filepath = path
        self.report({'INFO'}, f"bone map written to {path}")
        return {'FINISHED'}


def _file_name(name: str) -> str:
    """``name`` as a file name (letters, digits, ``-``, ``_``, ``.``), one Windows accepts
    (:func:`..core.file_names.windows_safe`: ``CON`` -> ``CON_``)."""
    import re
    from ..core.file_names import windows_safe
    return windows_safe(re.sub(r"[^\w.-]+", "_", str(name)).strip("._"), "bone_map")


CLASSES = (MANIKIN_OT_retarget, MANIKIN_OT_load_bone_map, MANIKIN_OT_save_bone_map)
