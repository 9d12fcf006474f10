"""A second solve onto the armature of the first (*Reuse Armature*): what the animator made on it
survives -- their own active action (kept in the file), actions in NLA strips or with a fake
user, NLA tracks and strip settings, drivers, constraints, custom properties, the pose-mode
selection -- and a failed or undone solve puts the armature's action and slot back."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying, live_rig, writer  # noqa: E402

from blender_util import synthetic_result, write_recording_csv  # noqa: E402
from conftest import ROOT  # noqa: E402
from test_blender_addon import addon  # noqa: E402,F401  (the add-on registered, the solver stubbed)


@pytest.fixture
def recording(tmp_path):
    res = synthetic_result(T=48, fps=24.0)
    return str(write_recording_csv(tmp_path / "take.csv", res, jitter=0.002))


def _solve_once(path):
    s = bpy.context.scene.manikin
    s.source, s.filepath, s.calibration, s.height = 'FILE', path, 'MEASURE', 1.8
    assert s.reuse_armature                                  # on by default
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    return s.armature


def _selectable(arm):
    """The bones whose ``select`` is the pose-mode selection (pose bones from Blender 5.0)."""
    return arm.pose.bones if hasattr(arm.pose.bones[0], "select") else arm.data.bones


def _animators_edits(arm):
    """What an animator does to the solved armature before solving again: their own action (a copy
    of the solve's, no fake user, a swivel key of theirs), NLA tracks, a driver, a constraint, a
    property, a pose-mode selection.  Returns the values to check afterwards."""
    solved = arm.animation_data.action
    mine = solved.copy()
    mine.name, mine.use_fake_user = "MyEdit", False
    keying.assign_action(arm, mine)
    fc = live_rig.swivel_fcurve(arm, "left_arm")
    keying.update_keys(fc, [10.0], [1.234])
    nla_only = bpy.data.actions.new("OnlyInTheNLA")
    nla_only.use_fake_user = False
    tr = arm.animation_data.nla_tracks.new()
    tr.name = "MyTrack"
    strip = tr.strips.new("older take", 1, solved)
    strip.scale, strip.repeat, strip.influence, strip.use_animated_influence = 1.5, 2.0, 0.4, True
    strip.influence = 0.4
    tr2 = arm.animation_data.nla_tracks.new()
    tr2.name = "Layer"
    tr2.strips.new("layer", 1, nla_only).blend_type = 'ADD'
    keep = bpy.data.actions.new("KeptByFakeUser")
    keep.use_fake_user = True
    arm["my_prop"] = 3.5
    con = arm.pose.bones["head"].constraints.new('LIMIT_ROTATION')
    con.name = "MyLimit"
    con = arm.pose.bones["head"].constraints.new('LIMIT_SCALE')
    con.name = "MANIKIN mine"                  # the animator's, named like the live rig's own
    drv = arm.driver_add('["my_prop"]')
    drv.driver.expression = "1.25"
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode='POSE')
    sel = _selectable(arm)
    for b in sel:
        b.select = False
    for name in ("spine2", "spine3"):
        sel[name].select = True
    arm.data.bones.active = arm.data.bones["spine2"]
    return dict(mine=mine.name, solved=solved.name, slot=getattr(arm.animation_data, "action_slot", None))


def _check_edits_kept(arm, names):
    acts = bpy.data.actions
    for name in (names["mine"], names["solved"], "OnlyInTheNLA", "KeptByFakeUser"):
        assert name in acts, name
    assert acts[names["mine"]].users >= 1, "the animator's action would be dropped on save"
    fc = next(f for f in keying.action_fcurves(acts[names["mine"]], arm) if f.data_path == '["swivel_left_arm"]')
    assert fc.evaluate(10.0) == pytest.approx(1.234)
    tracks = arm.animation_data.nla_tracks
    assert [t.name for t in tracks] == ["MyTrack", "Layer"]
    s = tracks["MyTrack"].strips[0]
    assert (s.action.name, s.scale, s.repeat, s.use_animated_influence) == (names["solved"], 1.5, 2.0, True)
    assert s.influence == pytest.approx(0.4)
    assert tracks["Layer"].strips[0].action.name == "OnlyInTheNLA"
    assert tracks["Layer"].strips[0].blend_type == 'ADD'
    assert "MyLimit" in arm.pose.bones["head"].constraints
    assert "MANIKIN mine" in arm.pose.bones["head"].constraints
    assert not arm.pose.bones["head"].constraints["MANIKIN mine"].mute
    assert any(d.data_path == '["my_prop"]' and d.driver.expression == "1.25" for d in arm.animation_data.drivers)
    assert "my_prop" in arm.keys()
    assert arm.mode == 'POSE'
    assert sorted(b.name for b in _selectable(arm) if b.select) == ["spine2", "spine3"]
    assert arm.data.bones.active.name == "spine2"


def test_a_second_solve_keeps_what_the_animator_made_on_the_armature(addon, recording, tmp_path):
    arm = _solve_once(recording)
    names = _animators_edits(arm)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    s = bpy.context.scene.manikin
    assert s.armature == arm                                      # reused
    new = arm.animation_data.action
    assert new.name not in (names["mine"], names["solved"])       # a new action, the edits untouched
    _check_edits_kept(arm, names)
    # saved and opened again: the animator's action, no longer assigned, is still there
    bpy.ops.object.mode_set(mode='OBJECT')
    path = str(tmp_path / "resolved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert names["mine"] in bpy.data.actions
    assert "OnlyInTheNLA" in bpy.data.actions and "KeptByFakeUser" in bpy.data.actions


def test_the_same_take_solved_again_at_another_scene_frame_rate_reuses_the_armature(addon):
    """Calibrated on frames resampled to the scene's rate, the example's body comes out 0.013 mm
    apart at 24 and 90 fps: the same performer, so the same armature."""
    s = bpy.context.scene.manikin
    s.source, s.filepath = 'FILE', os.path.join(ROOT, "examples", "example_recording.csv")
    assert s.calibration == 'AUTO'
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    arm = s.armature
    bpy.context.scene.render.fps = 90
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert s.armature == arm
    assert [o.name for o in bpy.data.objects if o.type == 'ARMATURE'] == [arm.name]


def test_a_solve_that_fails_on_the_reused_armature_gives_its_action_back(addon, recording, monkeypatch):
    arm = _solve_once(recording)
    names = _animators_edits(arm)
    n_actions = len(bpy.data.actions)

    def broken(obj, result):
        raise RuntimeError("keying failed")

    monkeypatch.setattr(live_rig, "live_channels", broken)
    with pytest.raises(RuntimeError, match="keying failed"):
        bpy.ops.manikin.solve_full_body()
    ad = arm.animation_data
    assert ad.action.name == names["mine"]
    assert getattr(ad, "action_slot", None) == names["slot"]
    assert not ad.action.use_fake_user                            # as it was
    assert len(bpy.data.actions) == n_actions
    _check_edits_kept(arm, names)


def test_a_failed_write_onto_a_reused_armature_gives_its_action_back(addon):
    """The FK write (no live rig) failing after the new action was assigned."""
    res = synthetic_result(T=20, fps=24.0)
    out = writer.write_result(res)
    mine = out.action.copy()
    mine.name, mine.use_fake_user = "MyEdit", False
    keying.assign_action(out.armature, mine)
    slot = getattr(out.armature.animation_data, "action_slot", None)
    if slot is not None:              # slotted (4.4+): a slot not named after the object (renamed)
        slot.name_display = "my pose"
        assert slot.identifier.endswith("my pose")
    n_actions = len(bpy.data.actions)
    bad = synthetic_result(T=20, fps=24.0)
    bad.targets.pos[next(iter(bad.targets.pos))] = np.zeros((3, 3))     # a tracker of the wrong length
    with pytest.raises(ValueError, match="frames"):
        writer.write_result(bad, writer.WriteOptions(armature=out.armature, create_trackers=True))
    ad = out.armature.animation_data
    assert ad.action == mine and not mine.use_fake_user
    assert getattr(ad, "action_slot", None) == slot       # its keys, not a new empty slot
    if slot is not None:
        assert len(mine.slots) == 1
    assert len(bpy.data.actions) == n_actions


def test_undo_of_a_second_solve_gives_the_armature_its_action_back(addon, recording):
    arm = _solve_once(recording)
    names = _animators_edits(arm)
    bpy.ops.object.mode_set(mode='OBJECT')
    arm_name = arm.name
    actions = sorted(a.name for a in bpy.data.actions)
    objects = sorted(o.name for o in bpy.data.objects)
    bpy.ops.ed.undo_push(message="before the second solve")
    assert bpy.ops.manikin.solve_full_body('EXEC_DEFAULT', True) == {'FINISHED'}
    assert len(bpy.data.actions) > len(actions)
    assert bpy.data.actions[names["mine"]].use_fake_user
    assert bpy.ops.ed.undo() == {'FINISHED'}
    arm = bpy.data.objects[arm_name]
    assert sorted(a.name for a in bpy.data.actions) == actions
    assert sorted(o.name for o in bpy.data.objects) == objects
    assert arm.animation_data.action.name == names["mine"]
    assert not arm.animation_data.action.use_fake_user


def test_a_retarget_that_fails_gives_the_character_its_action_and_slot_back(addon, monkeypatch):
    """The character's own action (no fake user, on 4.4+ a slot not named after it) is shown
    again, with its slot and no fake user, when the retarget's keying fails."""
    from blender_manikin.blender import retarget_apply
    from blender_util import mixamo_style_character
    src = writer.write_result(synthetic_result(T=20, fps=24.0)).armature
    char = mixamo_style_character(stature=1.8)
    mine = bpy.data.actions.new("CharWalk")
    mine.use_fake_user = False
    keying.assign_action(char, mine)
    bone = char.pose.bones[0].name
    fc = keying.ensure_fcurve(mine, f'pose.bones["{bone}"].location', 2, bone, char)
    keying.set_keys(fc, np.array([1.0, 20.0]), np.array([0.0, 0.1]))
    slot = getattr(char.animation_data, "action_slot", None)
    if slot is not None:
        slot.name_display = "walk"
    n_actions = len(bpy.data.actions)
    real = keying.key_channels

    def failing(action, owner, frames, channels, *a, **k):
        if owner == char and action != mine:
            raise RuntimeError("keying failed")
        return real(action, owner, frames, channels, *a, **k)

    monkeypatch.setattr(retarget_apply.keying, "key_channels", failing)
    with pytest.raises(RuntimeError, match="keying failed"):
        retarget_apply.retarget_onto(src, char, root_motion="as_is")
    ad = char.animation_data
    assert ad.action == mine and not mine.use_fake_user
    assert getattr(ad, "action_slot", None) == slot
    if slot is not None:
        assert len(mine.slots) == 1
    assert len(bpy.data.actions) == n_actions


def test_a_narrowed_swivel_slider_range_survives_a_re_solve(addon, recording):  # noqa: F811
    """The animator narrowed a swivel slider (Edit Property: soft range ±90°, 1 decimal) on the
    solved armature; solving again onto it kept resetting the range to ±180°."""
    arm = _solve_once(recording)
    name = writer.SWIVEL_PROPS["left_arm"]
    arm.id_properties_ui(name).update(soft_min=-1.5708, soft_max=1.5708, precision=1)
    assert _solve_once(recording) == arm
    ui = arm.id_properties_ui(name).as_dict()
    assert ui["soft_min"] == pytest.approx(-1.5708) and ui["soft_max"] == pytest.approx(1.5708)
    assert ui["precision"] == 1 and ui["subtype"] == 'ANGLE'
    other = arm.id_properties_ui(writer.SWIVEL_PROPS["right_arm"]).as_dict()
    assert other["soft_max"] == pytest.approx(np.pi)                  # the others as made
