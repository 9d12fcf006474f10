"""Where a live rig cannot be read, the tools say so instead of keying a wrong pose.

* Left in Edit Mode, Blender does not evaluate its pose (every frame reads as the rest pose), so
  *Bake to FK* and *Retarget to Character* refuse it and leave nothing behind (before: a bake up to
  0.97 m off the rig, a retargeted hand 0.66 m off); in Pose Mode both work as in Object Mode.
* *Make Live Rig* (F3 search, a script) on an armature that is live already read its live action as
  FK keys, which it has not for the arms and legs (before: the rebuilt rig 0.51 m off); refused."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import live_rig, writer  # noqa: E402

from blender_util import evaluated_heads, mixamo_style_character, synthetic_result  # noqa: E402


def _live_rig():
    res = synthetic_result(T=24, fps=24.0, seed=2)
    out = writer.write_result(res, writer.WriteOptions(frame_start=1))
    live_rig.build_live_rig(out.armature, res, frames=out.frames)
    arm = out.armature
    bpy.context.view_layer.objects.active = arm
    return arm


def _in_mode(arm, mode):
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode=mode)


def test_bake_to_fk_refuses_an_armature_in_edit_mode(addon):
    arm = _live_rig()
    objects = set(bpy.data.objects)
    _in_mode(arm, 'EDIT')
    with pytest.raises(RuntimeError, match="is in Edit Mode.*Object or Pose Mode"):
        bpy.ops.manikin.bake_live_rig(use_scene_range=False, frame_start=1, frame_end=24)
    assert set(bpy.data.objects) == objects and arm.mode == 'EDIT'
    _in_mode(arm, 'POSE')
    assert bpy.ops.manikin.bake_live_rig(use_scene_range=False, frame_start=1, frame_end=24) == {'FINISHED'}
    baked = next(o for o in bpy.data.objects if o not in objects and o.type == 'ARMATURE')
    bpy.ops.object.mode_set(mode='OBJECT')
    frames = [3, 12, 20]
    np.testing.assert_allclose(evaluated_heads(baked, frames)[0], evaluated_heads(arm, frames)[0], atol=1e-5)


def test_retarget_refuses_a_source_in_edit_mode(addon):
    arm = _live_rig()
    char = mixamo_style_character(stature=1.95)
    s = bpy.context.scene.manikin
    s.armature, s.retarget_target = arm, char
    actions = set(bpy.data.actions)
    _in_mode(arm, 'EDIT')
    with pytest.raises(RuntimeError, match="is in Edit Mode"):
        bpy.ops.manikin.retarget()
    assert set(bpy.data.actions) == actions
    assert char.animation_data is None or char.animation_data.action is None
    _in_mode(arm, 'POSE')
    assert bpy.ops.manikin.retarget() == {'FINISHED'}


def test_make_live_rig_refuses_an_armature_that_is_live_already(addon):
    arm = _live_rig()
    action = arm.animation_data.action
    frames = [3, 12, 20]
    before = evaluated_heads(arm, frames)[0]
    n_actions = len(bpy.data.actions)
    assert bpy.ops.manikin.make_live_rig.poll()                  # a solved armature with an action
    with pytest.raises(RuntimeError, match="is a live rig's.*live already"):
        bpy.ops.manikin.make_live_rig()
    assert arm.animation_data.action == action and len(bpy.data.actions) == n_actions
    np.testing.assert_allclose(evaluated_heads(arm, frames)[0], before, atol=1e-6)
