"""The panel's bone map editor: the list filled from a preset / guess / file for a Mixamo-style
character, edited, used by the retarget, saved to JSON and loaded back; bad bone names are clear
errors; the sub-panel and its list draw."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import bone_map_list, keying, writer  # noqa: E402
from blender_manikin.core import bone_maps  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import PanelLayout, mixamo_style_character, synthetic_result  # noqa: E402

T = 24
ALT = "alt_forearm.L"          # a second left forearm on the character, not in any preset


def _scene(alt=True):
    """A solved take (the source) and a Mixamo-style character (with ``ALT``), chosen in the
    panel's settings; returns ``(result, source, character, settings)``."""
    res = synthetic_result(T=T, fps=24.0, seed=4, stature=1.8)
    src = writer.write_result(res, writer.WriteOptions(frame_start=1)).armature
    char = mixamo_style_character("Hero", stature=1.7, arm_down_deg=30.0)
    if alt:
        bpy.context.view_layer.objects.active = char
        bpy.ops.object.mode_set(mode='EDIT')
        eb = char.data.edit_bones
        fore = eb["mixamorig:LeftForeArm"]
        b = eb.new(ALT)
        b.head, b.tail, b.roll, b.parent = fore.head.copy(), fore.tail.copy(), 0.3, eb["mixamorig:LeftArm"]
        bpy.ops.object.mode_set(mode='OBJECT')
    s = bpy.context.scene.manikin
    s.armature = src
    bpy.context.view_layer.objects.active = src
    return res, src, char, s


def _rows(s):
    return [(it.name, it.bone, it.twist) for it in s.retarget_bone_map]


def _row(s, joint):
    return next(it for it in s.retarget_bone_map if it.name == joint)


def test_load_preset_edit_a_row_and_retarget_with_the_edited_list(addon):
    res, src, char, s = _scene()
    assert len(s.retarget_bone_map) == 0
    s.retarget_target = char                      # filled by itself when empty: the guess (Mixamo names)
    assert [it.name for it in s.retarget_bone_map] == list(sk.JOINT_NAMES)
    assert _row(s, "left_elbow").bone == "mixamorig:LeftForeArm" and s.retarget_map == 'AUTO'
    assert not s.retarget_bone_map_edited
    s.retarget_map = 'MIXAMO_PLAIN'               # unedited rows follow the choice (no such bones here)
    assert _row(s, "pelvis").bone == "Hips"
    s.retarget_map = 'MIXAMO'
    assert bpy.ops.manikin.load_bone_map() == {'FINISHED'}
    assert _row(s, "pelvis").bone == "mixamorig:Hips" and s.retarget_bone_map_source == "Mixamo for Hero"
    assert dict((j, b) for j, b, _ in bone_map_list.rows(s)) == bone_maps.preset("mixamo").bones

    # the user's edit: the left elbow drives the other forearm; the choice becomes the edited list
    fore = char.pose.bones["mixamorig:LeftForeArm"]
    fore.rotation_mode = 'XYZ'
    _row(s, "left_elbow").bone = ALT
    assert s.retarget_map == 'EDITED' and s.retarget_bone_map_edited
    assert not bpy.ops.manikin.load_bone_map.poll()          # nothing to load from: the list is the map
    s.retarget_target = char                                  # edits are kept (never refilled by themselves)
    assert _row(s, "left_elbow").bone == ALT
    assert bpy.ops.manikin.retarget() == {'FINISHED'}
    act = char.animation_data.action
    paths = {fc.data_path for fc in keying.action_fcurves(act, char)}
    assert f'pose.bones["{ALT}"].rotation_quaternion' in paths
    assert not any("mixamorig:LeftForeArm" in p for p in paths)
    assert fore.rotation_mode == 'XYZ'                        # the replaced bone is untouched
    pos, _ = res.fk()
    sc = bpy.context.scene
    W = np.array(char.matrix_world)
    for k in (2, 13, 23):
        sc.frame_set(1 + k)
        assert np.allclose(np.array(fore.matrix_basis), np.eye(4))
        pb = char.pose.bones[ALT]
        h = (W @ np.append(np.array(pb.head), 1))[:3]
        t = (W @ np.append(np.array(pb.tail), 1))[:3]
        d = rot.normalize(pos[k, sk.J["left_wrist"]] - pos[k, sk.J["left_elbow"]])
        assert np.degrees(np.arccos(np.clip(np.dot(rot.normalize(t - h), d), -1, 1))) < 0.5, k


def test_unmapped_joints_and_twist_bones_are_kept(addon):
    """An emptied row is an unmapped joint (its rotation goes to its neighbours); a row's twist
    bones become the segment's twist bones."""
    _, src, char, s = _scene(alt=False)
    s.retarget_target = char
    _row(s, "spine3").bone = ""
    _row(s, "left_shoulder").twist = "mixamorig:LeftShoulder_unused, "
    bm = bone_map_list.to_bone_map(s)
    assert "spine3" not in bm.bones and bm.twist == {"left_shoulder": ["mixamorig:LeftShoulder_unused"]}
    _row(s, "left_shoulder").twist = ""
    assert bpy.ops.manikin.retarget() == {'FINISHED'}
    paths = {fc.data_path for fc in keying.action_fcurves(char.animation_data.action, char)}
    assert not any("mixamorig:Spine2" in p for p in paths) and any("mixamorig:Spine1" in p for p in paths)


def test_save_to_json_and_load_back_gives_the_same_list(addon, tmp_path, monkeypatch):
    _, src, char, s = _scene()
    s.retarget_map = 'MIXAMO'
    s.retarget_target = char
    _row(s, "left_elbow").bone = ALT
    _row(s, "left_elbow").twist = "twist_a.L, twist_b.L"
    _row(s, "spine3").bone = ""
    before = _rows(s)
    path = tmp_path / "hero_map.json"
    assert bpy.ops.manikin.save_bone_map(filepath=str(path)) == {'FINISHED'}
    doc = json.loads(path.read_text())
    assert doc["bones"]["left_elbow"] == ALT and "spine3" not in doc["bones"]
    assert doc["twist"] == {"left_elbow": ["twist_a.L", "twist_b.L"]} and doc["name"] == "mixamo"
    # the list replaced, then the file loaded back into it: the same rows
    s.retarget_map = 'AUTO'
    assert bpy.ops.manikin.load_bone_map() == {'FINISHED'}
    assert _rows(s) != before
    s.retarget_map = 'FILE'
    s.retarget_map_file = str(path)               # unedited rows follow the chosen file by themselves
    assert _rows(s) == before and not s.retarget_bone_map_edited
    _row(s, "head").bone = "mixamorig:Neck"       # edited: a new file name does not replace them ...
    s.retarget_map, s.retarget_map_file = 'FILE', str(path)
    assert _row(s, "head").bone == "mixamorig:Neck"
    assert bpy.ops.manikin.load_bone_map() == {'FINISHED'}     # ... Load Map does
    assert _rows(s) == before and s.retarget_bone_map_name == "mixamo"
    # no file chosen: the user's bone map folder
    monkeypatch.setattr(bone_map_list, "user_folder", lambda create=False: str(tmp_path / "user"))
    (tmp_path / "user").mkdir()
    assert bpy.ops.manikin.save_bone_map() == {'FINISHED'}
    assert bone_maps.load_bone_map(tmp_path / "user" / "mixamo.json").to_dict() == \
        bone_maps.load_bone_map(path).to_dict()



def test_save_map_has_the_file_browsers_warning_before_replacing_a_file(addon):
    """Save Map's file browser marks a chosen name that exists in red before it is replaced, as
    Blender's exporters' do: Blender shows that only for an operator with a ``check_existing``
    property that is on (a real window showed Save Map replacing a user's JSON without it)."""
    props = bpy.ops.manikin.save_bone_map.get_rna_type().properties
    assert "check_existing" in props.keys() and props["check_existing"].default is True

def test_a_bad_bone_name_is_an_error_naming_the_joint_and_the_bone(addon):
    _, src, char, s = _scene(alt=False)
    s.retarget_target = char
    before = char.animation_data.action if char.animation_data else None
    n_actions = len(bpy.data.actions)
    _row(s, "left_elbow").bone = "mixamorig:LeftForearm_typo"
    with pytest.raises(RuntimeError, match=r"no bone\(s\) 'mixamorig:LeftForearm_typo' \(left_elbow\)"):
        bpy.ops.manikin.retarget()
    assert len(bpy.data.actions) == n_actions
    assert (char.animation_data.action if char.animation_data else None) == before
    _row(s, "left_elbow").bone = "mixamorig:LeftForeArm"
    _row(s, "pelvis").bone = ""
    with pytest.raises(ValueError, match=r"\['pelvis'\] must be mapped"):
        bone_map_list.checked_bone_map(s, char)
    _row(s, "pelvis").bone = "mixamorig:Hips"
    _row(s, "head").bone = "mixamorig:Neck"
    with pytest.raises(ValueError, match="'mixamorig:Neck' \\(joints 'neck' and 'head'\\)"):
        bone_map_list.checked_bone_map(s, char)
    s.retarget_bone_map.clear()
    with pytest.raises(RuntimeError, match="the bone map list is empty: press Load Map"):
        bpy.ops.manikin.retarget()


def test_retarget_panel_and_bone_map_list_draw(addon):
    from blender_manikin.panels import main as panels
    _, src, char, s = _scene(alt=False)
    log = []
    panels.MANIKIN_PT_retarget.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("template_list", "retarget_bone_map") not in log           # no character: no list
    s.retarget_target = char
    s.retarget_map = 'FILE'
    log = []
    panels.MANIKIN_PT_retarget.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    for entry in (("template_list", "retarget_bone_map"), ("operator", "manikin.load_bone_map"),
                  ("operator", "manikin.save_bone_map"), ("operator", "manikin.retarget"),
                  ("prop", "retarget_map_file"), ("prop", "twist")):
        assert entry in log, entry
    assert ("operator", "manikin.export_fbx") not in log        # in the Export sub-panel
    # a row: the joint's label and a search among the character's bones; a missing bone is marked
    item = _row(s, "left_elbow")
    for bone, icon in (("mixamorig:LeftForeArm", 'BONE_DATA'), ("nope", 'ERROR')):
        item.bone = bone
        log = []
        panels.MANIKIN_UL_bone_map.draw_item(None, bpy.context, PanelLayout(log), s, item, 0, s,
                                             "retarget_bone_map_index", 0)
        assert ("label", "Left Elbow") in log and ("prop_search", "bone") in log and ("icon", icon) in log
        rows = [c for kind, c in log if kind == "child"]
        assert any(c.alert for c in rows) == (icon == 'ERROR')
