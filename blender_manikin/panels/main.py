"""The MANIKIN tab of the 3D Viewport sidebar: "Solve full body"."""
from __future__ import annotations

from bpy.types import Panel, UIList

from ..blender.properties import DEVICE_LABELS
from ..core.pose_result import DEVICES


class _Base:
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "MANIKIN"

    @classmethod
    def poll(cls, context):
        return context.scene is not None and hasattr(context.scene, "manikin")


def split_layout(layout):
    """``layout`` (a panel's) with labels in a column of their own and no keyframe decorators."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


def smoothing_rows(col, s):
    """The Smoothing setting (trackers and keypoints alike), its window when one is set."""
    col.prop(s, "smoothing_mode")
    if s.smoothing_mode == 'WINDOW':
        col.prop(s, "smoothing")


class MANIKIN_PT_solve(_Base, Panel):
    bl_label = "Solve Full Body"
    bl_idname = "MANIKIN_PT_solve"

    def draw(self, context):
        layout = split_layout(self.layout)
        s = context.scene.manikin
        row = layout.row()
        row.use_property_split = False          # the whole width for the three sources
        row.prop(s, "source", expand=True)
        col = layout.column()
        if s.source == 'FILE':
            col.prop(s, "filepath")
            col.prop(s, "axes")
            col.prop(s, "units")
            col.prop(s, "layout_file")
        elif s.source == 'KEYPOINTS':
            col.prop(s, "keypoint_from")
            if s.keypoint_from == 'OBJECTS':
                col.prop(s, "keypoint_collection")
            elif s.keypoint_from == 'ARMATURE':
                col.prop(s, "keypoint_armature")
                col.prop(s, "keypoint_bone_map")
                if s.keypoint_bone_map == 'FILE':
                    col.prop(s, "keypoint_map_file")
            else:
                col.prop(s, "keypoint_path")
                col.prop(s, "keypoint_layout")
                col.prop(s, "keypoint_units")
                col.prop(s, "keypoint_up")
                if s.keypoint_path.lower().endswith((".trc", ".c3d")):   # Vicon's widths: marker files only
                    col.prop(s, "keypoint_subject_file")
                col.prop(s, "keypoint_person")
                toggled_row(col, s, "use_keypoint_rate", "keypoint_rate", "Rate")
            col.prop(s, "keypoint_floor")
            col.separator()
            smoothing_rows(col, s)
            fix_sides_row(col, s)
            col.prop(s, "despike")
            col.prop(s, "ik")
            toggled_row(col, s, "use_height", "height", "Height")
            col.prop(s, "sole")                 # the feet stand on it (Calibration is not shown here)
        else:
            col.operator("manikin.map_devices", icon='LINKED')
            for d in DEVICES:
                src = getattr(s, d)
                row = col.row(align=True)
                row.prop(src, "object", text=DEVICE_LABELS[d])
                if src.object is not None and src.object.type == 'ARMATURE':
                    col.prop_search(src, "bone", src.object.data, "bones", text="Bone")
        if s.source != 'KEYPOINTS':           # keypoints are solved by HybrIK, no network
            col.separator()
            col.prop(s, "posture")
            smoothing_rows(col, s)
            fix_sides_row(col, s)
            col.prop(s, "model")
            if s.model == 'FILE':
                col.prop(s, "model_file")
            col.prop(s, "overlap")
            col.prop(s, "teleports")
        row = layout.row()
        row.scale_y = 1.6
        row.operator("manikin.solve_full_body", icon='ARMATURE_DATA')
        if s.source == 'FILE' or (s.source == 'KEYPOINTS' and s.keypoint_from == 'FILE'):
            layout.operator("manikin.solve_files", icon='FILE_FOLDER')
        if s.last_report:
            box = layout.box().column(align=True)
            failed = s.last_report.startswith("Solve failed: ")
            # Solve Several Files: its items from "failed: " on, up to an Esc's "cancelled", are the
            # files that failed (one item each), flagged as errors, not bulleted as the ones solved
            failing = False
            # one paragraph per item of the summary ("a; b; c"), not one run-on block
            for part in report_items(s.last_report):
                failing = part.startswith("failed: ") or (failing and not part.startswith("cancelled (Esc)"))
                for i, line in enumerate(wrapped(part, context)):
                    icon = ('ERROR' if failed or failing or "check" in part else 'DOT') if i == 0 else 'BLANK1'
                    box.label(text=line, icon=icon)


def fix_sides_row(col, s):
    """Fix Left/Right Swaps under a "Fix" heading: the whole name, beside its checkbox, is cut in a
    250 px sidebar ("Fix Left/Right ...")."""
    col.column(heading="Fix").prop(s, "fix_sides", text="Side Swaps")


def report_items(text):
    """The summary's items: ``text`` split at the "; " outside parentheses."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == ";" and depth <= 0 and text[i + 1:i + 2] == " ":
            items.append(text[start:i].strip())
            start = i + 2
    items.append(text[start:].strip())
    return [item for item in items if item]


def toggled_row(layout, s, flag, value, heading, text=""):
    """A row headed ``heading``: the checkbox ``flag`` and, greyed out while it is off, ``value``
    (labelled ``text``)."""
    row = layout.row(heading=heading)
    row.prop(s, flag, text="")
    sub = row.row()
    sub.active = getattr(s, flag)
    sub.prop(s, value, text=text)


def wrapped(text, context, min_chars=12):
    """``text`` cut into lines that fit the sidebar's width (Blender labels do not wrap; one too
    long for its row is cut in the middle with "...").  The solve summary is a few sentences; a
    cut-off label would hide what the solve reports.  Lines are measured in the UI font
    (:mod:`blf`) where Blender draws one, else estimated from a character width.  ``min_chars``
    (characters of 6.2 px) is only a floor for a region too narrow to hold a line at all: at 24,
    lines of 149 px were drawn in the 135 px a 230 px sidebar leaves them, and cut."""
    region = getattr(context, "region", None)
    # Headless (background mode) Blender reports a UI scale of 0 and regions 1 pixel wide.
    scale = (context.preferences.system.ui_scale if context.preferences else 0.0) or 1.0
    width = region.width if region is not None and region.width > 100 else 300
    # less the icon, the panel's, box's and label's margins (measured in Blender 4.3: a line of
    # 197 px fits a 291 px sidebar, one of 204 px is cut)
    room = max(min_chars * 6.2 * scale, width - 96 * scale)
    measure = _text_measure(context, scale)
    lines = []
    for part in text.split("\n"):
        line = ""
        for word in part.split():
            longer = f"{line} {word}" if line else word
            if line and measure(longer) > room:
                lines.append(line)
                line = word
            else:
                line = longer
        lines.append(line)
    return lines


def _text_measure(context, scale):
    """``str -> pixels`` in the sidebar's label font, or an estimate (6.2 px a character at UI
    scale 1) where no font can be measured (background mode)."""
    try:
        import blf
        points = context.preferences.ui_styles[0].widget.points
        blf.size(0, points * scale)
        if blf.dimensions(0, "MANIKIN")[0] > 0:
            return lambda s: blf.dimensions(0, s)[0]
    except (ImportError, AttributeError, IndexError, TypeError, ValueError):
        pass
    return lambda s: len(s) * 6.2 * scale


class MANIKIN_PT_calibration(_Base, Panel):
    bl_label = "Calibration"
    bl_parent_id = "MANIKIN_PT_solve"
    bl_options = {'DEFAULT_CLOSED'}

    @classmethod
    def poll(cls, context):       # trackers only: keypoints are sized from the bones they show
        return _Base.poll(context) and context.scene.manikin.source != 'KEYPOINTS'

    def draw(self, context):
        layout = split_layout(self.layout)
        s = context.scene.manikin
        layout.prop(s, "calibration")
        if s.calibration != 'MEASURE':
            layout.prop(s, "calibration_take", text="Take")     # under Calibration; "Calibration ..." cut
        if s.calibration == 'TPOSE':
            row = layout.row(align=True)
            row.prop(s, "tpose_time")
            row.operator("manikin.find_tpose", text="", icon='VIEWZOOM')
        elif s.calibration == 'AUTO':
            layout.operator("manikin.find_tpose", icon='VIEWZOOM')
        if s.calibration == 'MEASURE' or s.floor_mode == 'PERFORMER':
            layout.prop(s, "height")
        else:
            toggled_row(layout, s, "use_height", "height", "Height")
        layout.prop(s, "arm_span")
        layout.prop(s, "sole")
        layout.prop(s, "floor_mode")
        if s.floor_mode == 'OFFSET':
            layout.prop(s, "floor_height")
        layout.separator()
        row = layout.row(align=True)
        row.prop(s, "offsets_preset")
        row.operator("manikin.load_offsets_preset", text="", icon='TEXT')
        layout.prop(s, "offsets_text", text="Edited")       # under Offsets; "Edited Offs..." cut


class MANIKIN_PT_output(_Base, Panel):
    bl_label = "Frames and Output"
    bl_parent_id = "MANIKIN_PT_solve"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = split_layout(self.layout)
        s = context.scene.manikin
        # scene objects (trackers or keypoints) are sampled from Start to End; files are read whole
        sampled = s.source == 'SCENE' or (s.source == 'KEYPOINTS' and s.keypoint_from in ('OBJECTS', 'ARMATURE'))
        # From Scene: the scene's own rate and range, greyed (the add-on's FPS / Start / End, unused
        # then, showed 60 fps and frames 1-250 beside a 24 fps scene of frames 1-168)
        scene = context.scene
        if s.source in ('FILE', 'KEYPOINTS'):
            # headed rows: "Scene Frame Rate" and "Scene Frame Range" were both cut to "Scene Frame ..."
            layout.column(heading="Frame Rate").prop(s, "use_scene_fps", text="From Scene")
            sub = layout.column()
            if s.use_scene_fps:
                sub.enabled = False
                sub.prop(scene.render, "fps", text="FPS")
                if scene.render.fps_base != 1.0:        # 23.976 fps: 24 / 1.001
                    sub.prop(scene.render, "fps_base", text="Base")
            else:
                sub.prop(s, "fps")
        layout.column(heading="Frame Range").prop(s, "use_scene_range", text="From Scene")
        col = layout.column(align=True)
        col.enabled = not s.use_scene_range
        frames = scene if s.use_scene_range else s
        col.prop(frames, "frame_start", text="Start")
        if not sampled:
            toggled_row(layout, s, "limit_frames", "frame_end", "Limit", "End")
            toggled_row(layout, s, "use_trim_start", "trim_start", "Trim Start", "From")
            toggled_row(layout, s, "use_trim_end", "trim_end", "Trim End", "To")
        else:
            col.prop(frames, "frame_end", text="End")
        layout.separator()
        col = layout.column(heading="Create")
        col.prop(s, "create_trackers")
        col.prop(s, "body_mesh")
        col.prop(s, "live_rig")
        col = layout.column(heading="Scene")        # "Set Scene Range" beside its checkbox: "Set Scene Ran..."
        col.prop(s, "set_scene_range", text="Set Range")
        col.prop(s, "mark_problems")
        layout.prop(s, "reuse_armature")
        layout.prop(s, "armature")


_JOINT_LABELS = {}


def _list_row_width(context, scale):
    """Pixels of a row of the bone map list: the sidebar less its tab strip, the panel's margins
    and the list's scroll bar (measured in Blender 4.3: 166 px rows in a 250 px sidebar)."""
    region = getattr(context, "region", None)
    width = region.width if region is not None and region.width > 100 else 300
    return max(1.0, width - 84 * scale)


def joint_column(context):
    """The bone map list's split factor: the joint column as wide as the longest joint label
    ("Right Shoulder") needs, measured in the UI font (:func:`_text_measure`), from 0.4 of the row
    to at most 0.45 (the bone column, with its icon and clear button, keeps the rest)."""
    from ..blender.bone_map_list import joint_label
    from ..core.skeleton import JOINT_NAMES
    scale = (context.preferences.system.ui_scale if context.preferences else 0.0) or 1.0
    if scale not in _JOINT_LABELS:
        measure = _text_measure(context, scale)
        _JOINT_LABELS[scale] = max(measure(joint_label(j)) for j in JOINT_NAMES)
    return min(0.45, max(0.4, (_JOINT_LABELS[scale] + 12 * scale) / _list_row_width(context, scale)))


def list_joint_label(joint, context, factor):
    """``joint``'s label in the bone map list: "Right Shoulder", or "R Shoulder" where the full one
    does not fit the joint column (``factor`` of the row) and would be cut to "Right Sho..."."""
    from ..blender.bone_map_list import joint_label
    scale = (context.preferences.system.ui_scale if context.preferences else 0.0) or 1.0
    label = joint_label(joint)
    room = factor * _list_row_width(context, scale) - 12 * scale
    if _text_measure(context, scale)(label) > room:
        label = label.replace("Left ", "L ").replace("Right ", "R ")
    return label


class MANIKIN_UL_bone_map(UIList):
    """The bone map editor's rows: a source joint and, searched among the character's bones, the
    bone that follows it (a red mark: the character has no such bone)."""
    bl_idname = "MANIKIN_UL_bone_map"

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index=0, flt_flag=0):
        target = data.retarget_target
        bones = target.data if target is not None and target.type == 'ARMATURE' else None
        factor = joint_column(context)
        split = layout.split(factor=factor)
        split.label(text=list_joint_label(item.name, context, factor))
        row = split.row(align=True)
        missing = bool(item.bone) and bones is not None and item.bone not in bones.bones
        row.alert = missing
        if bones is not None:
            row.prop_search(item, "bone", bones, "bones", text="", icon='ERROR' if missing else 'BONE_DATA')
        else:
            row.prop(item, "bone", text="", emboss=True)
        if item.twist:
            row.label(text="", icon='FORCE_VORTEX')


class MANIKIN_PT_retarget(_Base, Panel):
    bl_label = "Retarget to Character"
    bl_parent_id = "MANIKIN_PT_solve"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = split_layout(self.layout)
        s = context.scene.manikin
        layout.prop(s, "retarget_target")
        row = layout.row(align=True)
        row.prop(s, "retarget_map")
        row.operator("manikin.load_bone_map", text="", icon='FILE_REFRESH')
        row.operator("manikin.save_bone_map", text="", icon='FILE_TICK')
        if s.retarget_map == 'FILE':
            layout.prop(s, "retarget_map_file")
        if s.retarget_target is not None:
            col = layout.column()
            col.use_property_split = False
            col.template_list("MANIKIN_UL_bone_map", "", s, "retarget_bone_map", s, "retarget_bone_map_index",
                              rows=6)
            rows = s.retarget_bone_map
            if 0 <= s.retarget_bone_map_index < len(rows):
                item = rows[s.retarget_bone_map_index]
                if s.retarget_target.type == 'ARMATURE':       # the list's narrow column shows "mixamorig:..."
                    col.prop_search(item, "bone", s.retarget_target.data, "bones", text="Bone")
                col.prop(item, "twist", text="Twist")
            if s.retarget_bone_map_source:
                col.label(text=s.retarget_bone_map_source + (", edited" if s.retarget_bone_map_edited else ""),
                          icon='INFO')
        layout.prop(s, "retarget_root")
        col = layout.column()
        col.use_property_split = False          # long labels: the whole width
        col.prop(s, "retarget_keep_ends", text="Keep Hands/Feet on Targets")     # the name is cut at 250 px
        row = col.row()
        row.separator(factor=2.0)
        row.active = s.retarget_keep_ends
        row.prop(s, "retarget_live_swivel")
        layout.operator("manikin.retarget", icon='ARMATURE_DATA')


class MANIKIN_PT_export(_Base, Panel):
    """Export: the character (or, with none chosen, the solved armature) as FBX or glTF binary, and
    each retargeted take.  A sub-panel of its own: under "Retarget to Character" an animator with
    no character did not look for the export of the solved armature."""
    bl_label = "Export"
    bl_parent_id = "MANIKIN_PT_solve"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = split_layout(self.layout)
        s = context.scene.manikin
        layout.prop(s, "export_format")
        if s.export_format == 'GLB':
            layout.operator("manikin.export_gltf", icon='EXPORT')
        else:
            layout.prop(s, "export_fbx_preset")
            layout.operator("manikin.export_fbx", icon='EXPORT')
        # greyed out (its poll says why) without a character or retargeted takes
        layout.operator("manikin.export_fbx_takes", icon='EXPORT')


CLASSES = (MANIKIN_PT_solve, MANIKIN_PT_calibration, MANIKIN_PT_output, MANIKIN_UL_bone_map, MANIKIN_PT_retarget,
           MANIKIN_PT_export)
