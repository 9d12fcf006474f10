"""A scene in centimetres (unit scale 0.01, as for Unreal Engine): the length settings show and take
physical lengths, scene objects are read as what they measure, and the solve is built at its true
size in the scene's unit (blender/units.py)."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import blender_manikin  # noqa: E402
from blender_manikin.blender import units, writer  # noqa: E402
from blender_manikin.blender.properties import config_from_settings  # noqa: E402
from blender_manikin.core.skeleton import J  # noqa: E402

from blender_util import fresh_scene  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def centimetre_scene(scene):
    scene.unit_settings.system = 'METRIC'
    scene.unit_settings.scale_length = 0.01
    scene.unit_settings.length_unit = 'CENTIMETERS'


def test_length_settings_are_physical_lengths(addon):
    sc = bpy.context.scene
    s = sc.manikin
    assert units.metres_per_unit(sc) == 1.0 and s.height == pytest.approx(1.75)
    centimetre_scene(sc)
    assert units.metres_per_unit(sc) == pytest.approx(0.01)
    # the defaults are still 1.75 m and 3 cm soles, shown as 175 and 3 scene units
    assert s.height == pytest.approx(175.0) and s.sole == pytest.approx(3.0)
    s.height, s.arm_span, s.floor_mode, s.floor_height = 182.0, 178.0, 'OFFSET', -160.0
    assert s.height_m == pytest.approx(1.82) and s.arm_span_m == pytest.approx(1.78)
    cfg = config_from_settings(bpy.context)
    assert cfg.arm_span == pytest.approx(1.78) and cfg.floor == pytest.approx(-1.6)
    assert cfg.sole == pytest.approx(0.03)
    s.calibration = 'MEASURE'
    assert config_from_settings(bpy.context).height == pytest.approx(1.82)
    s.height = 5000.0                                  # 50 m: held at the 2.8 m limit
    assert s.height_m == pytest.approx(2.8) and s.height == pytest.approx(280.0)
    sc.unit_settings.system = 'NONE'                   # no unit system: a unit is a metre
    assert units.metres_per_unit(sc) == 1.0 and s.height == pytest.approx(2.8)


def _solve_file(scene_setup):
    fresh_scene()
    blender_manikin.register()
    try:
        sc = bpy.context.scene
        scene_setup(sc)
        sc.render.fps, sc.render.fps_base = 30, 1.0
        s = sc.manikin
        s.source, s.filepath, s.create_trackers = 'FILE', EXAMPLE, True
        assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
        arm = s.armature
        heads, wrists_off = [], 0.0
        for f in (1, 40, 120):
            sc.frame_set(f)
            W = np.array(arm.matrix_world)
            heads.append([(W @ np.append(np.array(arm.pose.bones[n].head), 1.0))[:3]
                          for n in ("head", "left_ankle", "right_wrist")])
            target = np.array(bpy.data.objects["MANIKIN_right_hand"].matrix_world)[:3, 3]
            wrists_off = max(wrists_off, float(np.linalg.norm(heads[-1][2] - target)))
        # the mannequin, built in the scene's unit: its extent at the last of those frames
        from blender_manikin.blender.body_mesh import find_body_mesh
        mo = find_body_mesh(arm)
        me = mo.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
        co = np.array([tuple(v.co) for v in me.vertices])
        mo.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
        return (np.array(heads), wrists_off, s.last_report, bpy.data.objects["MANIKIN_right_hand"].empty_display_size,
                co.max(axis=0) - co.min(axis=0))
    finally:
        blender_manikin.unregister()


def test_a_solve_in_a_centimetre_scene_is_built_at_its_true_size():
    """The example (a 1.75 m performer) solved in a metre scene and in a centimetre scene: the
    same pose, 100 times the units; the wrists on their tracker empties either way."""
    metres, off_m, report_m, size_m, mannequin_m = _solve_file(lambda sc: None)
    cm, off_cm, report_cm, size_cm, mannequin_cm = _solve_file(centimetre_scene)
    assert "stature 1.75 m" in report_m and "stature 1.75 m" in report_cm
    np.testing.assert_allclose(cm, 100.0 * metres, atol=2e-3)        # 0.02 mm
    assert 145.0 < cm[0, 0, 2] < 165.0                                 # the head joint ~1.5 m up
    assert off_m < 1e-4 and off_cm < 1e-2                              # 0.1 mm either way
    assert size_cm == pytest.approx(100.0 * size_m)
    np.testing.assert_allclose(mannequin_cm, 100.0 * mannequin_m, atol=2e-2)      # 0.2 mm
    assert 1.0 < mannequin_m[2] < 1.9                                  # a person's size, in metres


def test_scene_objects_in_centimetres_are_read_as_what_they_measure(addon):
    """Tracker empties keyed in a centimetre scene (a 1.8 m body's head 150-odd units up): the
    solve measures a 1.8 m performer and lands on the empties."""
    from blender_util import synthetic_result
    sc = bpy.context.scene
    centimetre_scene(sc)
    sc.render.fps = 24
    res = synthetic_result(T=30, fps=24.0)
    src = writer.write_result(units.result_in_scene_units(res, sc), writer.WriteOptions(create_trackers=True))
    sc.frame_set(1)
    head_keys = np.array(src.trackers["head"].matrix_world)[:3, 3]
    assert head_keys[2] > 100.0                                        # keyed in centimetres
    s = sc.manikin
    s.source = 'SCENE'
    for dev, empty in src.trackers.items():
        getattr(s, dev).object = empty
    s.calibration, s.height = 'MEASURE', 180.0
    s.create_trackers, s.use_scene_range, s.reuse_armature = False, False, False
    s.frame_start, s.frame_end = 1, 30
    s.smoothing_mode, s.smoothing = 'WINDOW', 0.0
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "stature 1.80 m" in s.last_report
    out = s.armature
    sc.frame_set(12)
    head = np.array(out.matrix_world) @ np.append(np.array(out.pose.bones["head"].head), 1)
    np.testing.assert_allclose(head[:3], 100.0 * res.targets.pos["head"][11], atol=1e-2)
    rest_head = 100.0 * res.body.rest_positions()[J["head"], 2]           # the armature: 100 times
    assert out.data.bones["head"].head_local[2] == pytest.approx(rest_head, rel=0.01)


def test_a_retarget_in_a_centimetre_scene(addon):
    """A solve written in a centimetre scene retargets onto a character of that scene (a 1.95 m
    character, 195 units tall): hands and feet land on the performer's, in centimetres, and a
    shorter character's misses are reported in real centimetres."""
    from blender_manikin.blender import retarget_apply
    from blender_util import mixamo_style_character, synthetic_result
    sc = bpy.context.scene
    centimetre_scene(sc)
    sc.render.fps = 24
    res = synthetic_result(T=30, fps=24.0, seed=1, stature=1.8)
    src = writer.write_result(units.result_in_scene_units(res, sc), writer.WriteOptions(frame_start=1)).armature
    char = mixamo_style_character(stature=1.95)
    char.scale = (100.0, 100.0, 100.0)                 # 195 units: 1.95 m in this scene
    bpy.context.view_layer.update()
    retarget_apply.retarget_onto(src, char, "mixamo", None, "as_is", True)
    pos, _ = res.fk()
    worst = 0.0
    for k in (0, 11, 29):
        sc.frame_set(1 + k)
        for bone, j in (("mixamorig:LeftHand", "left_wrist"), ("mixamorig:RightFoot", "right_ankle")):
            W = np.array(char.matrix_world)
            h = (W @ np.append(np.array(char.pose.bones[bone].head), 1.0))[:3]
            worst = max(worst, float(np.linalg.norm(h - 100.0 * pos[k, J[j]])))
    assert worst < 1e-2, worst                          # 0.1 mm, in centimetres
    short = mixamo_style_character("Short", stature=1.5)
    short.scale = (100.0, 100.0, 100.0)
    bpy.context.view_layer.update()
    _, out, notes = retarget_apply.retarget_onto(src, short, "mixamo", None, "as_is", True)
    misses = [float(n.rsplit("by up to ", 1)[1].split(" cm")[0]) for n in notes if "out of the character's reach" in n]
    assert misses and all(0.5 < m < 60.0 for m in misses), notes


def _export_and_import(tmp_path, preset, scene_setup):
    """The body of a synthetic solve written in a scene set up by ``scene_setup``, exported with
    ``preset`` and imported into a fresh metre scene: world heads ``(3 frames, 22, 3)``."""
    from blender_manikin.blender import fbx_presets
    from blender_util import synthetic_result
    from test_blender_fbx_presets import _bone_heads, _import
    fresh_scene()
    blender_manikin.register()
    try:
        sc = bpy.context.scene
        scene_setup(sc)
        sc.render.fps = 24
        res = synthetic_result(T=10, fps=24.0, stature=1.8)
        arm = writer.write_result(units.result_in_scene_units(res, sc), writer.WriteOptions(frame_start=1)).armature
        sc.frame_start, sc.frame_end = 1, 10
        path = tmp_path / f"body_{preset}_{units.metres_per_unit(sc):g}.fbx"
        fbx_presets.export_fbx(path, arm, preset)
    finally:
        blender_manikin.unregister()
    back, _ = _import(path)
    from blender_manikin.core.skeleton import JOINT_NAMES
    return _bone_heads(back, list(JOINT_NAMES), [2, 5, 9]), res


@pytest.mark.parametrize("preset", ["blender", "unreal"])
def test_an_fbx_from_a_centimetre_scene_keeps_the_real_size(tmp_path, preset):
    """The solved body exported from a centimetre scene and from a metre scene, each imported
    into a fresh metre scene (the importer's defaults undo the file's units): the same motion at
    the same size, in metres."""
    in_m, res = _export_and_import(tmp_path, preset, lambda sc: None)
    in_cm, _ = _export_and_import(tmp_path, preset, centimetre_scene)
    np.testing.assert_allclose(in_cm, in_m, atol=1e-4)
    pos, _ = res.fk()                                    # and where the performer's joints were
    np.testing.assert_allclose(in_m[1], pos[4], atol=1e-3)


def test_lengths_saved_by_an_earlier_version_are_carried_over(addon, tmp_path):
    """A .blend saved before the lengths moved behind get/set holds them as ID properties named
    ``height`` etc. (metres): opening it carries them into the settings instead of losing them."""
    s = bpy.context.scene.manikin
    s["height"], s["sole"], s["arm_span"] = 1.82, 0.0, 1.79          # as the earlier version stored them
    assert s.height == pytest.approx(1.75)                           # not read as they are
    path = str(tmp_path / "old.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)                          # the load_post handler runs
    s = bpy.context.scene.manikin
    assert s.height_m == pytest.approx(1.82) and s.sole_m == 0.0 and s.arm_span_m == pytest.approx(1.79)
    assert not any(k in s.keys() for k in units.LENGTH_SETTINGS)
    assert config_from_settings(bpy.context).sole == 0.0
    s["height"] = 9.0                                                # out of range: clamped
    assert units.migrate_length_settings(bpy.data.scenes) == 1 and s.height_m == pytest.approx(2.8)
