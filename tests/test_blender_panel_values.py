"""What the sidebar shows is what the solve and the exports use (found on screenshots of Blender
4.3's window, tools/panel_screenshot.sh): Frames and Output's greyed-out rate and range, with
From Scene ticked, are the scene's (they showed the add-on's unused 60 fps and frames 1-250 beside a
24 fps scene of frames 1-168); Export has a sub-panel of its own, and Export Each Take is greyed
out until the character has a retargeted take."""
from types import SimpleNamespace

import pytest

bpy = pytest.importorskip("bpy")

from blender_util import mixamo_style_character  # noqa: E402


class RecordingLayout:
    """A panel ``layout`` stand-in recording each drawn property as ``(owner, name, enabled)``:
    ``enabled`` False when it or a layout above it is greyed out and uneditable."""

    def __init__(self, log, parent=None):
        self.log, self.parent = log, parent
        self.use_property_split = self.use_property_decorate = False
        self.active = self.enabled = True
        self.alert, self.scale_y = False, 1.0

    def _on(self):
        return self.enabled and (self.parent is None or self.parent._on())

    def _child(self, *a, **k):
        return RecordingLayout(self.log, self)
    row = column = box = split = _child

    def prop(self, data, name, **k):
        assert name in data.bl_rna.properties, f"no property {name!r} on {data}"
        self.log.append((data, name, self._on()))

    def operator(self, idname, **k):
        self.log.append((None, idname, self._on()))

    def prop_search(self, *a, **k):
        pass

    def label(self, **k):
        pass

    def separator(self, **k):
        pass


def _drawn(panel_cls):
    log = []
    panel_cls.draw(SimpleNamespace(layout=RecordingLayout(log)), bpy.context)
    return log


@pytest.mark.parametrize("source", ['FILE', 'SCENE'])
def test_from_scene_shows_the_scenes_rate_and_range_greyed(addon, source):
    from blender_manikin.panels import main as panels
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 24, 1.001
    sc.frame_start, sc.frame_end = 1, 168
    s = sc.manikin
    s.source = source
    s.fps, s.frame_start, s.frame_end = 60.0, 1, 250
    s.use_scene_fps = s.use_scene_range = True
    log = _drawn(panels.MANIKIN_PT_output)
    want = [(sc, "frame_start", False)] + ([(sc, "frame_end", False)] if source == 'SCENE' else [])
    if source == 'FILE':
        want += [(sc.render, "fps", False), (sc.render, "fps_base", False)]
    for entry in want:
        assert entry in log, entry
    # none of the add-on's own, unused then
    assert not [(d, n) for d, n, _ in log if d == s and n in ("fps", "frame_start")]
    if source == 'SCENE':               # (a recording's End is Limit's, used with Limit ticked)
        assert not [d for d, n, _ in log if d == s and n == "frame_end"]
    # ticked off: the add-on's own, editable
    s.use_scene_fps = s.use_scene_range = False
    log = _drawn(panels.MANIKIN_PT_output)
    assert (s, "frame_start", True) in log and not [d for d, *_ in log if d in (sc, sc.render)]
    assert (s, "fps", True) in log if source == 'FILE' else (s, "fps", True) not in log


def test_export_has_its_own_sub_panel_and_each_take_waits_for_a_take(addon):
    from blender_manikin.operators.export import MANIKIN_OT_export_fbx_takes
    from blender_manikin.panels import main as panels
    s = bpy.context.scene.manikin
    assert panels.MANIKIN_PT_export in panels.CLASSES
    assert panels.MANIKIN_PT_export.bl_parent_id == "MANIKIN_PT_solve"
    names = [n for _, n, _ in _drawn(panels.MANIKIN_PT_retarget)]
    assert not {"export_format", "export_fbx_preset", "manikin.export_fbx"} & set(names)
    # no character: Export FBX writes the solved armature; Export Each Take is drawn, greyed out
    names = [n for _, n, _ in _drawn(panels.MANIKIN_PT_export)]
    assert names == ["export_format", "export_fbx_preset", "manikin.export_fbx", "manikin.export_fbx_takes"]
    assert not MANIKIN_OT_export_fbx_takes.poll(bpy.context)
    char = mixamo_style_character("Hero", stature=1.7)
    s.retarget_target = char
    assert not MANIKIN_OT_export_fbx_takes.poll(bpy.context)      # a character, no take retargeted yet
    act = bpy.data.actions.new("MANIKIN_retarget_walk")
    char.animation_data_create()
    char.animation_data.action = act
    char.keyframe_insert('location', frame=1)
    assert MANIKIN_OT_export_fbx_takes.poll(bpy.context)
    s.export_format = 'GLB'
    names = [n for _, n, _ in _drawn(panels.MANIKIN_PT_export)]
    assert names == ["export_format", "manikin.export_gltf", "manikin.export_fbx_takes"]
