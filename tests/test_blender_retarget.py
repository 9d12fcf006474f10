"""Retargeting in Blender: a solved take onto a Mixamo-named character in an A-pose with rolled bones."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying, retarget_apply, writer  # noqa: E402
from blender_manikin.core import bone_maps  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import (build_armature, evaluated_heads, fresh_scene, humanoid_bones,  # noqa: E402
                          humanoid_joints, mixamo_style_character, synthetic_result)

T = 30


def _source(stature=1.8):
    res = synthetic_result(T=T, fps=24.0, seed=1, stature=stature)
    res.contacts = np.zeros((T, 2), bool)
    res.contacts[4:15, 0] = True                     # footstep curves to carry over
    res.contacts[10:, 1] = True
    out = writer.write_result(res, writer.WriteOptions(frame_start=1))
    return res, out.armature


def _bone_world(obj, name):
    pb = obj.pose.bones[name]
    W = np.array(obj.matrix_world)
    return (W @ np.append(np.array(pb.head), 1))[:3], (W @ np.append(np.array(pb.tail), 1))[:3]


def test_retarget_onto_an_a_pose_mixamo_rig(addon):
    res, src = _source()
    char = mixamo_style_character(stature=1.95)                     # long enough limbs to reach every target
    old = bpy.data.actions.new("character_idle")             # the user's own action: kept, untouched
    keying.assign_action(char, old)
    keying.key_channels(old, char, [1.0, 10.0], [('pose.bones["mixamorig:Hips"].location', 0, "Hips",
                                                   [0.0, 0.1])])
    s = bpy.context.scene.manikin
    s.armature = src
    s.retarget_target = char
    s.retarget_map, s.retarget_root, s.retarget_keep_ends = 'AUTO', 'AS_IS', True
    bpy.context.view_layer.objects.active = src
    assert bpy.ops.manikin.retarget() == {'FINISHED'}
    act = char.animation_data.action
    assert act != old and act.name.startswith("MANIKIN_retarget_") and old.name in bpy.data.actions
    assert old.use_fake_user and len(keying.action_fcurves(old, char)) == 1
    assert all(len(fc.keyframe_points) == T for fc in keying.action_fcurves(act, char))
    # the footstep curves come along, as steps
    contacts = {fc.data_path: fc for fc in keying.action_fcurves(act, char) if "foot_contact" in fc.data_path}
    assert set(contacts) == {'["foot_contact_left"]', '["foot_contact_right"]'}
    for k in (0, 7, 19):
        assert contacts['["foot_contact_left"]'].evaluate(1 + k) == pytest.approx(float(res.contacts[k, 0]))
    assert contacts['["foot_contact_right"]'].keyframe_points[0].interpolation == 'CONSTANT'

    pos, world = res.fk()
    sc = bpy.context.scene
    worst_end = 0.0
    for k in (0, 11, 29):
        sc.frame_set(1 + k)
        # hands and feet kept on the performer's (root motion as is): exactly there, though the
        # character's arms and legs are longer (its limbs re-solved with the swivel)
        for bone, j in (("mixamorig:LeftHand", "left_wrist"), ("mixamorig:RightFoot", "right_ankle")):
            h, _ = _bone_world(char, bone)
            worst_end = max(worst_end, float(np.linalg.norm(h - pos[k, sk.J[j]])))
    assert worst_end < 1e-4, worst_end
    assert char.pose.bones["mixamorig:LeftArm"].rotation_mode == 'QUATERNION'
    # a shorter character cannot reach everywhere: the report says where
    short = mixamo_style_character("Short", stature=1.5)
    _, out, notes = retarget_apply.retarget_onto(src, short, "mixamo", None, "as_is", True)
    assert any("out of the character's reach" in n for n in notes), notes


def test_a_character_resting_palms_forward_gets_the_performers_hands(addon):
    """A T-pose character resting palms-forward, its fingers on the turned palms: the retarget keeps
    the finger bones it reads the rest palms from, so each hand has the performer's hand turn
    (before: 90° off, the rest taken as palms-down), and the notes say the hands were turned."""
    res, src = _source()
    P = humanoid_joints(1.8, 0.0)
    names = bone_maps.preset("mixamo").bones
    bones = humanoid_bones(P, names)
    Tw = rot.axis_angle_rotation(np.array([1.0, 0.0, 0.0]), np.radians(-90.0))   # palm-down -> palm-forward
    for side, S, sx in (("left", "Left", 1.0), ("right", "Right", -1.0)):
        w = P[sk.J[f"{side}_wrist"]]
        for n, off in (("Index", (0.09, -0.03, 0.0)), ("Pinky", (0.08, 0.03, 0.0)), ("Thumb", (0.03, -0.04, -0.01))):
            h = w + Tw @ np.array([sx * off[0], off[1], off[2]])
            bones.append((f"mixamorig:{S}Hand{n}1", f"mixamorig:{S}Hand", h, h + np.array([sx * 0.03, 0.0, 0.0])))
    char = build_armature("PalmsForward", bones, seed=5)
    _, out, notes = retarget_apply.retarget_onto(src, char, "mixamo", None, "as_is", False)
    assert sum("rests turned 90° from palms-down" in n for n in notes) == 2, notes
    pos, world = res.fk()
    W = np.array(char.matrix_world)[:3, :3]
    for k in (0, 11, 29):
        bpy.context.scene.frame_set(1 + k)
        for side, S in (("left", "Left"), ("right", "Right")):
            b = f"mixamorig:{S}Hand"
            rest = W @ np.array(char.data.bones[b].matrix_local)[:3, :3]
            want = world[k, sk.J[f"{side}_wrist"]] @ Tw.T @ rest     # the hand in the body's rest, posed
            got = W @ np.array(char.pose.bones[b].matrix)[:3, :3]
            assert np.degrees(rot.geodesic_angle(got, want)) < 1.0, (k, side)


def test_retarget_directions_without_keep_ends_and_a_saved_map(addon, tmp_path):
    res, src = _source()
    char = mixamo_style_character(stature=1.7, arm_down_deg=30.0)
    bmap, _ = retarget_apply.resolve_bone_map("auto", char)
    assert bmap.bones["left_elbow"] == "mixamorig:LeftForeArm"
    path = tmp_path / "map.json"
    bone_maps.save_bone_map(path, bmap)
    action, out, notes = retarget_apply.retarget_onto(src, char, "file", str(path), "scaled", False)
    assert notes == []
    pos, _ = res.fk()
    sc = bpy.context.scene
    for k in (3, 20):
        sc.frame_set(1 + k)
        for bone, a, b in (("mixamorig:LeftForeArm", "left_elbow", "left_wrist"),
                           ("mixamorig:LeftUpLeg", "left_hip", "left_knee"),
                           ("mixamorig:Spine1", "spine2", "spine3")):
            h, t = _bone_world(char, bone)
            d_src = rot.normalize(pos[k, sk.J[b]] - pos[k, sk.J[a]])
            assert np.degrees(np.arccos(np.clip(np.dot(rot.normalize(t - h), d_src), -1, 1))) < 0.5, (bone, k)
    with pytest.raises(ValueError, match="choose a target armature other than the solved one"):
        retarget_apply.retarget_onto(src, src)


def test_a_character_in_nla_tweak_mode_is_refused_leaving_nothing(addon):
    """A character whose NLA strip is being edited (Tab in the NLA editor) cannot take a new
    action: the retarget says so and leaves nothing behind (no stray action kept by a fake user)."""
    _, src = _source()
    char = mixamo_style_character(stature=1.95)
    walk = bpy.data.actions.new("walk")
    keying.assign_action(char, walk)
    keying.key_channels(walk, char, [1.0, 10.0], [('pose.bones["mixamorig:Hips"].location', 0, "Hips", [0.0, 0.1])])
    ad = char.animation_data
    track = ad.nla_tracks.new()
    strip = track.strips.new("walk", 1, walk)
    ad.action = None
    track.select = strip.select = True
    ad.use_tweak_mode = True
    actions = set(bpy.data.actions.keys())
    s = bpy.context.scene.manikin
    s.armature, s.retarget_target, s.retarget_keep_ends = src, char, True
    bpy.context.view_layer.objects.active = src
    with pytest.raises(RuntimeError, match="tweak mode"):
        bpy.ops.manikin.retarget()
    assert set(bpy.data.actions.keys()) == actions
    assert ad.use_tweak_mode and ad.action == walk and len(char.data.bones) == len(char.pose.bones)
    assert not any(b.name.startswith("MANIKIN_") for b in char.data.bones)


def test_bones_keep_their_rotation_modes_and_the_characters_own_actions_still_play(addon):
    """A character animated in Euler (and axis-angle) rotations is keyed in those modes: its bones'
    modes are not switched to quaternions, so its own actions, reassigned, still play; the new keys
    put the hands and feet where quaternion keys would and do not spin between frames."""
    res, src = _source()
    reference = mixamo_style_character("Reference", stature=1.95)
    retarget_apply.retarget_onto(src, reference, "mixamo", None, "as_is", True, live_swivel=False)
    char = mixamo_style_character(stature=1.95)
    modes = {"mixamorig:LeftArm": 'XYZ', "mixamorig:LeftForeArm": 'ZXY', "mixamorig:RightUpLeg": 'YZX',
             "mixamorig:Spine": 'AXIS_ANGLE', "mixamorig:Hips": 'ZYX'}
    for name, mode in modes.items():
        char.pose.bones[name].rotation_mode = mode
    own = bpy.data.actions.new("character_wave")                     # the animator's Euler action
    keying.assign_action(char, own)
    wave = np.array([0.0, 0.4, -0.3])
    keying.key_channels(own, char, [1.0, 30.0], [('pose.bones["mixamorig:LeftArm"].rotation_euler', i,
                                                  "mixamorig:LeftArm", [0.0, v]) for i, v in enumerate(wave)])
    action, out, _ = retarget_apply.retarget_onto(src, char, "mixamo", None, "as_is", True, live_swivel=False)
    assert {n: char.pose.bones[n].rotation_mode for n in modes} == modes
    paths = {fc.data_path: fc for fc in keying.action_fcurves(action, char)}
    assert 'pose.bones["mixamorig:LeftArm"].rotation_euler' in paths
    assert 'pose.bones["mixamorig:Spine"].rotation_axis_angle' in paths
    assert 'pose.bones["mixamorig:LeftArm"].rotation_quaternion' not in paths
    from mathutils import Euler, Matrix
    for name, mode in modes.items():      # continuous keys: as Blender's compatible Euler, no spin
        path = f'pose.bones["{name}"].' + ("rotation_axis_angle" if mode == 'AXIS_ANGLE' else "rotation_euler")
        fcs = sorted((f for f in keying.action_fcurves(action, char) if f.data_path == path),
                     key=lambda f: f.array_index)
        v = np.array([[k.co[1] for k in fc.keyframe_points] for fc in fcs]).T
        if mode == 'AXIS_ANGLE':
            R = rot.axis_angle_to_matrix(v[:, 1:] * v[:, :1])
            step = rot.geodesic_angle(R[1:], R[:-1])
            assert np.all(np.abs(np.diff(v[:, 0])) <= step + 1e-5), name
            continue
        R = rot.fixed_axes_euler_to_matrix(v, mode)
        e = [Matrix(R[0].tolist()).to_euler(mode)]
        for t in range(1, T):
            e.append(Matrix(R[t].tolist()).to_euler(mode, Euler(e[-1], mode)))
        blender = np.abs(np.diff(np.array(e), axis=0)).sum()
        assert np.abs(np.diff(v, axis=0)).sum() <= blender + 1e-4, (name, blender)
    sc = bpy.context.scene
    for k in (0, 13, 29):
        sc.frame_set(1 + k)
        for bone in ("mixamorig:LeftHand", "mixamorig:RightFoot", "mixamorig:Head", "mixamorig:LeftForeArm"):
            assert np.linalg.norm(_bone_world(char, bone)[0] - _bone_world(reference, bone)[0]) < 1e-4, (k, bone)
    # the animator's own action, assigned again, plays: the arm where its Euler keys put it
    keying.assign_action(char, own)
    sc.frame_set(30)
    assert np.allclose(char.pose.bones["mixamorig:LeftArm"].rotation_euler, wave, atol=1e-6)
    M = np.array(char.pose.bones["mixamorig:LeftArm"].matrix_basis)[:3, :3]
    assert np.abs(M - rot.fixed_axes_euler_to_matrix(wave, "XYZ")).max() < 1e-5


def test_live_rig_source_is_sampled_by_evaluation(addon):
    """A live-rig solve (constraints, no FK keys on the limbs) is read by evaluating it: the same
    joints as the FK solve it came from."""
    from blender_manikin.blender import live_rig
    _, src = _source()
    frames, wr_fk, pos_fk, sw_fk, _ = retarget_apply.sample_source(src)
    # the rig from the FK keys (their swivel measured from the joints, as "Make Live" does)
    res, _ = live_rig.result_from_fk_action(src, 24.0)
    live_rig.build_live_rig(src, res, frames=frames)
    done = []
    frames2, wr, pos, sw, body = retarget_apply.sample_source(src, progress=done.append)
    assert done and done[0] == 0.0 and all(0.0 <= f < 1.0 for f in done)     # it says how far it is
    np.testing.assert_allclose(frames2, frames)
    np.testing.assert_allclose(pos, pos_fk, atol=1e-4)
    # orientations too, but the elbows': the rig puts the forearm's pronation into the elbow
    # (within its range) where these FK keys had it in the wrist; the hands agree either way
    not_elbows = [j for j in range(sk.NUM_JOINTS) if j not in (sk.J["left_elbow"], sk.J["right_elbow"])]
    assert np.degrees(rot.geodesic_angle(wr[:, not_elbows], wr_fk[:, not_elbows])).max() < 0.05
    np.testing.assert_allclose(np.angle(np.exp(1j * (sw - sw_fk))), 0.0, atol=1e-4)


def test_a_moved_solve_is_read_where_it_stands_with_or_without_the_live_rig(addon):
    """The solved armature moved and turned in the scene (the take placed on the set) is read in
    the world, as the live rig's evaluation reads it, from plain FK keys too."""
    from blender_manikin.blender import live_rig
    _, src = _source()
    src.location, src.rotation_euler = (2.0, -1.0, 0.3), (0.0, 0.0, 0.7)
    bpy.context.view_layer.update()
    frames, wr_fk, pos_fk, _, _ = retarget_apply.sample_source(src)
    heads, _ = evaluated_heads(src, frames[[0, 12, 29]])
    np.testing.assert_allclose(pos_fk[[0, 12, 29]], heads, atol=1e-4)
    res, _ = live_rig.result_from_fk_action(src, 24.0)
    live_rig.build_live_rig(src, res, frames=frames)
    _, wr, pos, _, _ = retarget_apply.sample_source(src)
    np.testing.assert_allclose(pos_fk, pos, atol=1e-4)
    hands = [sk.J["left_wrist"], sk.J["right_wrist"], sk.J["pelvis"], sk.J["head"]]
    assert np.degrees(rot.geodesic_angle(wr[:, hands], wr_fk[:, hands])).max() < 0.05


def test_cli_retargets_onto_a_character_from_a_blend_and_the_fbx_round_trip_holds(tmp_path, monkeypatch):
    """``solve --retarget FILE.blend:Character``: the .blend and the FBX carry the character with
    its new action; the FBX, imported again, puts the mapped bones where the .blend does."""
    from blender_manikin import cli
    from blender_manikin.blender import solve_job
    from blender_util import stub_solver, write_recording_csv
    fresh_scene()
    mixamo_style_character("Character", stature=1.7)
    mixamo_style_character("Other", stature=1.5)
    lib = tmp_path / "characters.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(lib), copy=True)
    rec = write_recording_csv(tmp_path / "take.csv", synthetic_result(T=40, fps=30.0, seed=2))
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    out = tmp_path / "out"
    assert cli.main(["solve", str(rec), "--out", str(out), "--format", "blend,fbx", "--fps", "30",
                     "--height", "1.8", "--retarget", f"{lib}:Character", "--bone-map", "mixamo"]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(out / "take.blend"))
    char = bpy.data.objects["Character"]
    assert "Other" not in bpy.data.objects
    assert char.animation_data.action.name.startswith("MANIKIN_retarget_")
    names = ["mixamorig:LeftHand", "mixamorig:RightFoot", "mixamorig:Head", "mixamorig:Hips"]
    sc = bpy.context.scene
    sc.frame_set(12)
    in_blend = np.array([_bone_world(char, n)[0] for n in names])
    fresh_scene()
    bpy.context.scene.render.fps = 30
    # FBX keeps scene frame f at time f / fps; the importer's default anim_offset would add a frame
    bpy.ops.import_scene.fbx(filepath=str(out / "take.fbx"), automatic_bone_orientation=False, anim_offset=0.0)
    arm = next(o for o in bpy.data.objects if o.type == 'ARMATURE')
    bpy.context.scene.frame_set(12)
    from_fbx = np.array([_bone_world(arm, n)[0] for n in names])
    np.testing.assert_allclose(from_fbx, in_blend, atol=1e-3)
    # a file with two armatures and no name, or a wrong name: a clear error
    fresh_scene()
    with pytest.raises(ValueError, match="name the armature, FILE.blend:OBJECT "
                                         "\\(armatures in the file: Character, Other\\)"):
        cli.append_character(str(lib))
    with pytest.raises(ValueError, match="no armature named 'Nobody'"):
        cli.append_character(f"{lib}:Nobody")


_RIGIFY_CHILD = r"""
import json, sys
import os

import numpy as np
import bpy, addon_utils
import blender_manikin
from blender_manikin.blender import keying, retarget_apply, writer
from blender_manikin.core import rotations as rot, skeleton as sk
from blender_util import fresh_scene, synthetic_result
fresh_scene()
blender_manikin.register()
if "rigify" not in {m.__name__ for m in addon_utils.modules()}:
    print(json.dumps({"skip": "this Blender build bundles no Rigify"}), flush=True)
    sys.exit(0)
addon_utils.enable("rigify", default_set=True, persistent=True)
res = synthetic_result(T=30, fps=24.0, seed=1, stature=1.8)
src = writer.write_result(res, writer.WriteOptions(frame_start=1)).armature
bpy.ops.object.armature_human_metarig_add()
meta = bpy.context.active_object
assert bpy.ops.pose.rigify_generate() == {'FINISHED'}
rig = next(o for o in bpy.data.objects if o.type == 'ARMATURE' and o not in (meta, src))
bmap, _ = retarget_apply.resolve_bone_map("auto", rig)
# the DEF bones mapped directly: they follow the rig's constraints, which the notes say
_, _, notes_def = retarget_apply.retarget_onto(src, rig, "rigify", None, "scaled", False)
action, out, notes = retarget_apply.retarget_onto(src, rig, "auto", None, "scaled", False)
paths = sorted({fc.data_path for fc in keying.action_fcurves(action, rig)})
pos, _ = res.fk()
worst = {}
W = np.array(rig.matrix_world)
for k in (5, 25):
    bpy.context.scene.frame_set(1 + k)
    for bone, a, b in (("DEF-forearm.L", "left_elbow", "left_wrist"),
                       ("DEF-upper_arm.R", "right_shoulder", "right_elbow")):
        pb = rig.pose.bones[bone]
        h = (W @ np.append(np.array(pb.head), 1))[:3]
        t = (W @ np.append(np.array(pb.tail), 1))[:3]
        d = rot.normalize(pos[k, sk.J[b]] - pos[k, sk.J[a]])
        ang = float(np.degrees(np.arccos(np.clip(np.dot(rot.normalize(t - h), d), -1, 1))))
        worst[bone] = max(worst.get(bone, 0.0), ang)
# the legs are solved onto the performer's feet scaled by the leg ratio: the foot travels k times
# as far as the performer's ankle (metres, between two frames)
feet = []
for k in (5, 25):
    bpy.context.scene.frame_set(1 + k)
    feet.append((W @ np.append(np.array(rig.pose.bones["DEF-foot.R"].head), 1))[:3])
foot_travel = float(np.linalg.norm(feet[1] - feet[0]))
ankle_travel = float(out.plan.leg_ratio * np.linalg.norm(pos[25, sk.J["right_ankle"]] - pos[5, sk.J["right_ankle"]]))
print(json.dumps({"map": bmap.name, "switch_keyed": 'pose.bones["upper_arm_parent.L"]["IK_FK"]' in paths,
                  "rig_switch": float(rig.pose.bones["upper_arm_parent.L"]["IK_FK"]), "worst": worst,
                  "foot_travel": foot_travel, "ankle_travel": ankle_travel,
                  "leg_reach_error": float(np.nansum(out.reach_error[[5, 25], 3])),
                  "notes": notes, "notes_def": notes_def}), flush=True)
"""


def test_retarget_onto_a_rig_generated_by_rigify():
    """Blender's own Rigify: human metarig, generated; the guess keys its FK controls (with the
    IK/FK switches keyed to FK in the new action), their bases taken under the rig's evaluated
    mechanism, the deforming arms point where the performer's do and the feet travel as the
    performer's, scaled by the leg ratio.

    In a process of its own: bpy 4.2.23 as a module crashes when the interpreter exits once
    Rigify has been enabled (a Blender bug, seen with nothing but ``addon_utils.enable``), so
    the child prints its results first and only a crash *after* that line is tolerated."""
    import json
    import os
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.path.join(root, "tests")]))
    r = subprocess.run([sys.executable, "-c", _RIGIFY_CHILD], capture_output=True, text=True, env=env,
                       timeout=600)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    assert lines, f"no result (exit {r.returncode}):\n{r.stderr[-3000:]}"
    out = json.loads(lines[-1])
    if "skip" in out:
        pytest.skip(out["skip"])
    assert r.returncode in (0, -11, 139), r.stderr[-3000:]
    assert out["map"] == "rigify_fk" and out["switch_keyed"]
    # keyed controls carry no constraints of their own; the DEF bones do, and the user is told
    assert not any("constraints" in n for n in out["notes"]), out["notes"]
    held = [n for n in out["notes_def"] if "follow constraints that set their rotation" in n]
    assert len(held) == 1 and held[0].count("DEF-") == 4 and "more" in held[0], out["notes_def"]
    assert out["rig_switch"] == 1.0                     # as the new action keys it
    for bone, ang in out["worst"].items():
        assert ang < 3.0, (bone, ang)
    assert out["ankle_travel"] > 0.05, out
    assert abs(out["foot_travel"] - out["ankle_travel"]) < 0.01 + out["leg_reach_error"], out


def test_retarget_onto_an_fbx_character_in_centimetres_facing_y(addon):
    """A character as an FBX in centimetres arrives (+Y up, object turned 90° about X, scale 0.01,
    facing +Y): the motion turns with it, its segments point where the performer's do turned by
    the facing, and the hips travel in its own metres."""
    res, src = _source()
    char = mixamo_style_character("FBXChar", stature=1.7, fbx_cm=True)
    action, out, notes = retarget_apply.retarget_onto(src, char, "auto", None, "as_is", False)
    pos, _ = res.fk()
    turn = np.diag([-1.0, -1.0, 1.0])             # the performer faces -Y, the character +Y
    sc = bpy.context.scene
    for k in (4, 26):
        sc.frame_set(1 + k)
        for bone, a, b in (("mixamorig:LeftForeArm", "left_elbow", "left_wrist"),
                           ("mixamorig:RightUpLeg", "right_hip", "right_knee"),
                           ("mixamorig:Spine1", "spine2", "spine3")):
            h, t = _bone_world(char, bone)
            d_src = turn @ rot.normalize(pos[k, sk.J[b]] - pos[k, sk.J[a]])
            assert np.degrees(np.arccos(np.clip(np.dot(rot.normalize(t - h), d_src), -1, 1))) < 0.5, (bone, k)
        # as is: the hips move as far as the performer's (metres in the world, not centimetres)
        hips, _ = _bone_world(char, "mixamorig:Hips")
        sc.frame_set(1)
        hips0, _ = _bone_world(char, "mixamorig:Hips")
        np.testing.assert_allclose(np.linalg.norm(hips - hips0), np.linalg.norm(pos[k, 0] - pos[0, 0]), atol=1e-4)


def test_several_selected_takes_are_each_retargeted(addon):
    """Two solved armatures selected: each take becomes an action of its own on the character
    (plain keys), the last assigned, the first kept; the character's own action untouched."""
    res_a, src_a = _source()
    res_b = synthetic_result(T=T, fps=24.0, seed=7, stature=1.7)
    src_b = writer.write_result(res_b, writer.WriteOptions(frame_start=1, armature_name="MANIKIN_take_b")).armature
    char = mixamo_style_character(stature=1.9)
    s = bpy.context.scene.manikin
    s.retarget_target, s.retarget_map, s.retarget_keep_ends = char, 'AUTO', False
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (src_a, src_b))
    bpy.context.view_layer.objects.active = src_a
    assert bpy.ops.manikin.retarget() == {'FINISHED'}
    made = sorted(a.name for a in bpy.data.actions if a.name.startswith("MANIKIN_retarget_"))
    assert len(made) == 2
    last = f"MANIKIN_retarget_{src_b.animation_data.action.name}"         # sorted by name: take_b last
    assert char.animation_data.action.name.startswith(last)
    assert all(bpy.data.actions[n].use_fake_user or bpy.data.actions[n] == char.animation_data.action for n in made)
    from blender_manikin.blender import character_swivel
    assert not character_swivel.has_rig_parts(char)                   # plain keys for several takes


def test_each_retargeted_take_is_exported_as_its_own_fbx(addon, tmp_path):
    """Two takes retargeted onto a character, exported one FBX each (<character>_<take>.fbx) with
    the take's frames; the character's action and the scene's range as they were."""
    from blender_manikin.blender import fbx_presets
    res_a, src_a = _source()
    res_b = synthetic_result(T=T + 10, fps=24.0, seed=7, stature=1.7)
    src_b = writer.write_result(res_b, writer.WriteOptions(frame_start=1, armature_name="MANIKIN_take_b")).armature
    char = mixamo_style_character(stature=1.9)
    for src in (src_a, src_b):
        retarget_apply.retarget_onto(src, char, "mixamo", None, "scaled", False)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 5, 7
    current = char.animation_data.action
    assert [a.name for a in fbx_presets.take_actions(char)] == sorted(
        a.name for a in bpy.data.actions if a.name.startswith("MANIKIN_retarget_"))
    paths = fbx_presets.export_fbx_takes(str(tmp_path / "takes"), char, "unity")
    assert len(paths) == 2 and all(os.path.exists(p) and os.path.basename(p).startswith(char.name + "_")
                                   for p in paths)
    assert char.animation_data.action == current and (sc.frame_start, sc.frame_end) == (5, 7)
    # exported again: its own unchanged files are replaced; a file of the user's of one's name is not
    assert fbx_presets.export_fbx_takes(str(tmp_path / "takes"), char, "unity") == paths
    with open(paths[0], "ab") as f:
        f.write(b"the animator's edit")
    before = open(paths[0], "rb").read()
    with pytest.raises(ValueError, match="already exists and is not this tool's") as refused:
        fbx_presets.export_fbx_takes(str(tmp_path / "takes"), char, "unity")
    # the panel's words, not the command line's (a real window said "pass --overwrite")
    assert "tick Replace Files" in str(refused.value) and "--overwrite" not in str(refused.value)
    assert open(paths[0], "rb").read() == before
    assert fbx_presets.export_fbx_takes(str(tmp_path / "takes"), char, "unity", overwrite=True) == paths
    from test_blender_fbx_presets import _import
    lengths = []
    for p in paths:
        _import(p)
        act = [a for a in bpy.data.actions if a.users][0]
        lengths.append(int(round(act.frame_range[1] - act.frame_range[0])) + 1)
    assert sorted(lengths) == [T, T + 10]
