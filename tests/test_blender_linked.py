"""A solved armature linked into another file (a shot file linking the take from its own .blend),
as it is or as a library override: a solve with *Reuse Armature* pointed at it makes a new local
armature instead of failing in edit mode, *Make Live Rig* is greyed out, and the swivel tools
refuse to edit its linked action (the edit would be lost on save) with a message saying why."""
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying  # noqa: E402

from blender_util import fresh_scene, synthetic_result, write_recording_csv  # noqa: E402
from test_blender_addon import addon  # noqa: E402,F401  (the add-on registered, the solver stubbed)


@pytest.fixture
def recording(tmp_path):
    res = synthetic_result(T=48, fps=24.0)
    return str(write_recording_csv(tmp_path / "take.csv", res, jitter=0.002))


def _settings(path):
    s = bpy.context.scene.manikin
    s.source, s.filepath, s.calibration, s.height = 'FILE', path, 'MEASURE', 1.8
    return s


def _solve(path):
    s = _settings(path)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    return s.armature


def _linked_armature(recording, tmp_path, override):
    """Solve, save that file, start an empty one and link (or override) the solved armature."""
    name = _solve(recording).name
    lib = str(tmp_path / "take.blend")
    bpy.ops.wm.save_as_mainfile(filepath=lib)
    fresh_scene()
    with bpy.data.libraries.load(lib, link=True) as (_, dst):
        dst.objects = [name]
    arm = dst.objects[0]
    scene = bpy.context.scene
    scene.collection.objects.link(arm)
    if override:
        arm = arm.override_hierarchy_create(scene, bpy.context.view_layer, do_fully_editable=True)
    bpy.context.view_layer.objects.active = arm
    return arm


@pytest.mark.parametrize("override", [False, True], ids=["linked", "override"])
def test_a_solve_onto_a_linked_armature_makes_a_new_one(addon, recording, tmp_path, override):
    arm = _linked_armature(recording, tmp_path, override)
    action = arm.animation_data.action
    s = _settings(recording)                                     # the new file's panel
    s.armature = arm
    assert s.reuse_armature
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert s.armature != arm and s.armature.library is None and s.armature.override_library is None
    assert arm.animation_data.action == action                  # the linked one as it was


def test_the_swivel_tools_refuse_a_linked_action(addon, recording, tmp_path):
    arm = _linked_armature(recording, tmp_path, override=False)
    fc = next(f for f in keying.action_fcurves(arm.animation_data.action, arm)
              if f.data_path == '["swivel_left_arm"]')
    keys = [tuple(k.co) for k in fc.keyframe_points]
    bpy.context.scene.frame_set(10)
    for op in (bpy.ops.manikin.key_swivel, bpy.ops.manikin.smooth_swivel, bpy.ops.manikin.reset_swivel):
        with pytest.raises(RuntimeError, match="linked from .*take.blend.*would not be saved"):
            op()
    assert [tuple(k.co) for k in fc.keyframe_points] == keys
    assert not bpy.ops.manikin.make_live_rig.poll()              # its bones cannot be edited here
