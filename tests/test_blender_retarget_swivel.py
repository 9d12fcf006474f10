"""Live swivel on the retargeted character (real Blender): the character gets the keyed swivel
properties, editing a key turns its elbow / knee about the shoulder-wrist / hip-ankle axis while
the hand / foot stays on its target, the option off adds nothing, Bake gives plain FK keys, and
one undo removes it all."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import character_swivel as cs  # noqa: E402
from blender_manikin.blender import keying, live_rig, retarget_apply, writer  # noqa: E402
from blender_manikin.core import bone_maps  # noqa: E402
from blender_manikin.core import retarget as rt  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import mixamo_style_character, styled_character  # noqa: E402
from test_blender_swivel_rig import _FakeLayout, consistent_result  # noqa: E402
from blender_manikin.blender.writer import CONTACT_PROPS as _CONTACTS  # noqa: E402

#: the footstep curves a retarget carries onto the character (keyed, not rig parts)
CONTACT_PROPS = set(_CONTACTS.values())
CONTACT_PATHS = {f'["{n}"]' for n in CONTACT_PROPS}

T = 30
MM = 1e-3
EDIT = np.radians(40.0)
#: the character's (Mixamo) base, mid and end bone of each limb, LIMB_NAMES order
LIMB_BONES = [tuple(bone_maps.preset("mixamo").bones[sk.JOINT_NAMES[j]] for j in (b, m, e))
              for _, b, m, e in sk.LIMBS]


def _take():
    """A stand-in solved take (FK keys on the MANIKIN body, frames 1..T; its limbs and swivel
    consistent, as a solve's are) and an A-pose Mixamo-style character with rolled bones, long
    enough to reach the performer's hands and feet."""
    res = consistent_result(T=T, seed=1, stature=1.8)
    src = writer.write_result(res, writer.WriteOptions(frame_start=1)).armature
    char = mixamo_style_character(stature=1.95)
    return src, char


def _own_bones(obj):
    return [b.name for b in obj.data.bones if not b.name.startswith(cs.PREFIX)]


def _world_pose(obj, names):
    """World heads (B, 3) and orientations (B, 3, 3) of bones ``names`` as evaluated now (the
    object's scale, e.g. 0.01 of an FBX in centimetres, taken out of the orientations)."""
    W = np.array(obj.matrix_world)
    M = np.array([W @ np.array(obj.pose.bones[n].matrix) for n in names])
    R = M[:, :3, :3]
    return M[:, :3, 3], R / np.linalg.norm(R, axis=-2, keepdims=True)


def _reachable_frames(res, count=3):
    """Frames (0-based) where every limb reaches its target (so the hands / feet are on them)."""
    ok = np.nonzero(np.nanmax(res.reach_error, axis=1) < 1e-6)[0]
    assert len(ok) >= count
    return ok[np.linspace(0, len(ok) - 1, count).round().astype(int)]


def _shift_key(obj, limb, k, delta):
    """Graph-Editor style: move the swivel key of frame index ``k`` (and its handles) by ``delta``."""
    fc = live_rig.swivel_fcurve(obj, limb)
    kp = fc.keyframe_points[k]
    for attr in ("co", "handle_left", "handle_right"):
        getattr(kp, attr)[1] += delta
    fc.update()


def _expected_with_swivel(src, char, swivel):
    """The keep-ends retarget of ``src`` onto ``char`` solved in numpy with ``swivel`` (T, 4): world
    heads and orientations of every bone, and its bone names."""
    frames, wr, pos, _, body = retarget_apply.sample_source(src)
    target = retarget_apply.target_rig_from_object(char)
    bmap, _ = retarget_apply.resolve_bone_map("auto", char)
    res = rt.retarget(wr, pos, body, target, bmap, "as_is")
    res = rt.keep_ends_on_targets(res, wr, pos, swivel, ends="source")
    return res.world_heads(), res.world_orientations(), res.bone_names


def test_swivel_properties_carried_over_and_edited_live(addon):
    src, char = _take()
    action, res, notes = retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)
    assert cs.is_character_rig(char) and char.animation_data.action == action
    assert len(char.animation_data.drivers) == 8          # swivel + flexion per limb, no Python needed
    for fc in char.animation_data.drivers:
        assert fc.driver.is_simple_expression, fc.driver.expression
    # (a) the four swivel properties, keyed with the source's values on the source's frames
    src_keys = {}
    for limb in sk.LIMB_NAMES:
        assert writer.SWIVEL_PROPS[limb] in char.keys()
        f_src, v_src = live_rig.read_keys(live_rig.swivel_fcurve(src, limb))
        f, v = live_rig.read_keys(live_rig.swivel_fcurve(char, limb))
        np.testing.assert_allclose(f, f_src)
        np.testing.assert_allclose(v, v_src, atol=1e-6)
        assert np.ptp(v) > 0.05                                  # a real curve, not a constant
        src_keys[limb] = v_src
    # the hidden copy the "Reset Swivel" tool restores
    f, v = live_rig.read_keys(live_rig.swivel_fcurve(char, "left_arm", solved=True))
    np.testing.assert_allclose(v, src_keys["left_arm"], atol=1e-6)

    sc = bpy.context.scene
    names = _own_bones(char)
    idx = [res.bone_names.index(n) for n in names]
    heads0, rots0 = res.world_heads(), res.world_orientations()
    frames = _reachable_frames(res)
    # (b) before the edit: the live pose is the keep-ends retarget's, every bone
    for k in frames:
        sc.frame_set(1 + int(k))
        h, r = _world_pose(char, names)
        assert np.linalg.norm(h - heads0[k, idx], axis=-1).max() < MM
        assert np.abs(r - rots0[k, idx]).max() < 1e-3
        for li, (_, _, end) in enumerate(LIMB_BONES):
            assert np.linalg.norm(_world_pose(char, [end])[0][0] - res.end_targets[k, li]) < MM
    before = {}
    for k in frames:
        sc.frame_set(1 + int(k))
        before[k] = {li: _world_pose(char, list(bones))[0] for li, bones in enumerate(LIMB_BONES)}
    # a swivel key +40 degrees on every limb, on these frames only
    for li, limb in enumerate(sk.LIMB_NAMES):
        for k in frames:
            _shift_key(char, limb, int(k), EDIT)
    for k in frames:
        sc.frame_set(1 + int(k))
        for li, bones in enumerate(LIMB_BONES):
            (b0, m0, e0) = before[k][li]
            b1, m1, e1 = _world_pose(char, list(bones))[0]
            assert np.linalg.norm(e1 - res.end_targets[k, li]) < MM, (k, bones[2])     # hand / foot stays
            assert np.linalg.norm(b1 - b0) < MM                                         # shoulder / hip too
            n = rot.normalize(e0 - b0)

            def perp(p):
                v = p - b0
                return v - np.dot(v, n) * n
            p0, p1 = perp(m0), perp(m1)
            assert abs(np.linalg.norm(p1) - np.linalg.norm(p0)) < MM                    # on its circle
            assert np.linalg.norm(p0) > 0.01
            turn = np.degrees(np.arctan2(np.dot(np.cross(p0, p1), n), np.dot(p0, p1)))
            assert abs(turn - 40.0) < 2.0, (k, bones[1], turn)
    # and the whole character is the keep-ends retarget solved with the edited swivel (pronation,
    # hands and the other bones included); a frame in between keys keeps its own
    edited = np.stack([src_keys[limb] for limb in sk.LIMB_NAMES], -1)
    edited[frames] += EDIT
    heads1, rots1, bone_names = _expected_with_swivel(src, char, edited)
    idx1 = [bone_names.index(n) for n in names]
    for k in list(frames) + [int(frames[0]) + 1]:
        sc.frame_set(1 + int(k))
        h, r = _world_pose(char, names)
        assert np.linalg.norm(h - heads1[k, idx1], axis=-1).max() < MM, k
        assert np.abs(r - rots1[k, idx1]).max() < 1e-3, k
    assert np.linalg.norm(heads1[frames[0], idx1] - heads0[frames[0], idx], axis=-1).max() > 0.03


def test_option_off_adds_nothing_and_a_new_retarget_removes_the_rig(addon):
    src, char = _take()
    bones = sorted(b.name for b in char.data.bones)
    props = set(char.keys())
    n_objects = len(bpy.data.objects)

    def plain():
        assert sorted(b.name for b in char.data.bones) == bones
        assert all(len(pb.constraints) == 0 for pb in char.pose.bones)
        assert len(char.animation_data.drivers) == 0
        assert set(char.keys()) - CONTACT_PROPS == props and not cs.is_character_rig(char)   # footsteps only
        assert not any(c.name.startswith("MANIKIN") for c in char.data.collections)
        assert len(bpy.data.objects) == n_objects
        paths = {fc.data_path for fc in keying.action_fcurves(char.animation_data.action, char)}
        assert not any("swivel" in p or cs.PREFIX in p for p in paths)

    # keep-ends with the option off, and keep-ends off (the option's default follows it)
    action, res, _ = retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True, live_swivel=False)
    plain()
    k = int(_reachable_frames(res)[0])
    bpy.context.scene.frame_set(1 + k)
    hand = _world_pose(char, [LIMB_BONES[0][2]])[0][0]
    assert np.linalg.norm(hand - res.end_targets[k, 0]) < MM              # still kept on its target
    retarget_apply.retarget_onto(src, char, "auto", None, "scaled", False)
    plain()
    # with the rig, then again without: the rig goes, the character's own bones stay
    retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)
    assert cs.is_character_rig(char) and len(char.data.bones) > len(bones)
    assert any(len(pb.constraints) for pb in char.pose.bones)
    retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True, live_swivel=False)
    plain()


def test_a_linked_character_gets_plain_keys_on_its_targets(addon, tmp_path):
    """A character linked from a library (a library override, as a studio's asset is) cannot take
    the rig's bones: keep-ends with the live swivel gives it plain keys, its hands and feet on their
    targets, and says so, instead of failing."""
    src, char = _take()
    path = str(tmp_path / "characters.blend")
    coll = bpy.data.collections.new("Characters")
    coll.objects.link(char)
    bpy.data.libraries.write(path, {coll}, fake_user=True)
    data = char.data
    bpy.data.objects.remove(char)
    bpy.data.armatures.remove(data)
    bpy.data.collections.remove(coll)
    with bpy.data.libraries.load(path, link=True) as (_, dst):
        dst.collections = ["Characters"]
    scene = bpy.context.scene
    over = dst.collections[0].override_hierarchy_create(scene, bpy.context.view_layer)
    if over.name not in scene.collection.children:
        scene.collection.children.link(over)
    char = next(o for o in over.all_objects if o.type == 'ARMATURE')
    assert char.override_library is not None and not char.data.is_editable
    action, res, notes = retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True, live_swivel=True)
    assert char.animation_data.action == action and not cs.is_character_rig(char)
    assert any("no live swivel" in n for n in notes)
    k = int(_reachable_frames(res)[0])
    scene.frame_set(1 + k)
    hand = _world_pose(char, [LIMB_BONES[0][2]])[0][0]
    assert np.linalg.norm(hand - res.end_targets[k, 0]) < MM


#: rotation modes an animator gave the left arm's bones (the others stay quaternions)
EULER_ARM = dict(zip(LIMB_BONES[0], ('XYZ', 'ZXY', 'AXIS_ANGLE')))


@pytest.mark.parametrize("modes", [{}, EULER_ARM], ids=["quaternions", "euler_arm"])
def test_bake_gives_plain_fk_keys_of_the_live_pose(addon, modes):
    """The bake keys the live pose as plain FK, each bone in its own rotation mode (its modes are
    not switched, so the character's other actions keyed in them still play)."""
    src, char = _take()
    for name, mode in modes.items():
        char.pose.bones[name].rotation_mode = mode
    live, res, _ = retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)
    sc = bpy.context.scene
    bpy.context.view_layer.objects.active = char
    # an edit through the swivel tools: the slider on a frame, then Key Swivel
    k = int(_reachable_frames(res)[1])
    sc.frame_set(1 + k)
    char[writer.SWIVEL_PROPS["left_arm"]] = float(char[writer.SWIVEL_PROPS["left_arm"]]) + EDIT
    assert bpy.ops.manikin.key_swivel(limb='left_arm') == {'FINISHED'}
    names = _own_bones(char)
    frames = np.arange(1, T + 1)
    live_h, live_r = [], []
    for f in frames:
        sc.frame_set(int(f))
        h, r = _world_pose(char, names)
        live_h.append(h)
        live_r.append(r)
    live_h, live_r = np.array(live_h), np.array(live_r)
    elbow = names.index(LIMB_BONES[0][1])
    assert np.linalg.norm(live_h[k, elbow] - res.world_heads()[k, res.bone_names.index(LIMB_BONES[0][1])]) > 0.03

    assert bpy.ops.manikin.bake_character_swivel() == {'FINISHED'}
    baked = char.animation_data.action
    assert baked != live and live.name in bpy.data.actions and live.use_fake_user
    assert baked.get(cs.PROP_BAKED_FROM) == live.name
    # plain: the character's own bones and nothing else; keys only on its bones' channels
    assert _own_bones(char) == names and len(char.data.bones) == len(names)
    assert all(len(pb.constraints) == 0 for pb in char.pose.bones)
    assert len(char.animation_data.drivers) == 0 and not cs.is_character_rig(char)
    fcs = keying.action_fcurves(baked, char)
    for fc in fcs:
        assert (fc.data_path.startswith("pose.bones[") or fc.data_path in CONTACT_PATHS) \
            and cs.PREFIX not in fc.data_path, fc.data_path
    baked_paths = {fc.data_path: len(fc.keyframe_points) for fc in fcs}
    for bones in LIMB_BONES:
        for bone in bones:
            mode = modes.get(bone, 'QUATERNION')
            assert char.pose.bones[bone].rotation_mode == mode
            assert baked_paths[f'pose.bones["{bone}"].{keying.ROTATION_PATHS.get(mode, "rotation_euler")}'] == T
    # the baked keys reproduce the live pose, the edit included
    for f in frames:
        sc.frame_set(int(f))
        h, r = _world_pose(char, names)
        assert np.linalg.norm(h - live_h[f - 1], axis=-1).max() < MM, f
        assert np.abs(r - live_r[f - 1]).max() < 1e-3, f


def test_undo_removes_the_rig(addon):
    src, char = _take()
    name = char.name
    n_bones = len(char.data.bones)
    s = bpy.context.scene.manikin
    s.armature = src
    s.retarget_target = char
    s.retarget_map, s.retarget_root, s.retarget_keep_ends = 'AUTO', 'AS_IS', True
    assert s.retarget_live_swivel                         # on by default with keep-ends
    bpy.context.view_layer.objects.active = src
    bpy.ops.ed.undo_push(message="before the retarget")
    # as from the panel: the operator pushes its own undo step (undo=True)
    assert bpy.ops.manikin.retarget('EXEC_DEFAULT', True) == {'FINISHED'}
    char = bpy.data.objects[name]
    assert cs.is_character_rig(char) and len(char.data.bones) > n_bones
    assert bpy.ops.ed.undo() == {'FINISHED'}
    char = bpy.data.objects[name]
    assert len(char.data.bones) == n_bones
    assert not any(b.name.startswith(cs.PREFIX) for b in char.data.bones)
    assert all(len(pb.constraints) == 0 for pb in char.pose.bones)
    assert not cs.is_character_rig(char) and writer.SWIVEL_PROPS["left_arm"] not in char.keys()
    assert char.animation_data is None or char.animation_data.action is None
    assert bpy.ops.ed.redo() == {'FINISHED'}               # the retarget's own undo step
    assert cs.is_character_rig(bpy.data.objects[name])


def test_fbx_character_in_centimetres_facing_y(addon):
    """A character as an FBX in centimetres lands (object turned 90° about X, scale 0.01, facing
    +Y, against the performer's -Y): the rig turns with it, its lengths are centimetres; live pose
    = keep-ends pose, before and after a swivel edit."""
    src, _ = _take()
    char = mixamo_style_character("FBXChar", stature=1.95, fbx_cm=True)
    action, res, notes = retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)
    names = _own_bones(char)
    idx = [res.bone_names.index(n) for n in names]
    k = int(_reachable_frames(res)[1])
    sc = bpy.context.scene
    sc.frame_set(1 + k)
    h, r = _world_pose(char, names)
    assert np.linalg.norm(h - res.world_heads()[k, idx], axis=-1).max() < MM
    assert np.abs(r - res.world_orientations()[k, idx]).max() < 1e-3
    keys = np.stack([live_rig.read_keys(live_rig.swivel_fcurve(char, limb))[1] for limb in sk.LIMB_NAMES], -1)
    for limb in sk.LIMB_NAMES:
        _shift_key(char, limb, k, EDIT)
    keys[k] += EDIT
    heads1, rots1, bone_names = _expected_with_swivel(src, char, keys)
    idx1 = [bone_names.index(n) for n in names]
    sc.frame_set(1 + k)
    h, r = _world_pose(char, names)
    assert np.linalg.norm(h - heads1[k, idx1], axis=-1).max() < MM
    assert np.abs(r - rots1[k, idx1]).max() < 1e-3
    assert np.linalg.norm(heads1[k, idx1] - res.world_heads()[k, idx], axis=-1).max() > 0.03


def _check_edit_keeps_twist_shared(src, char, choice, path, bmap):
    """Retarget ``src`` onto ``char`` with the live swivel (bone map ``choice`` / ``path``, which
    resolves to ``bmap``), edit the left arm's and right leg's swivel keys, and check the limbs'
    bones and twist bones against the numpy retarget with the edited swivel, same map."""
    action, res, notes = retarget_apply.retarget_onto(src, char, choice, path, "as_is", True)
    assert not any("twist" in n for n in notes), notes
    k = int(_reachable_frames(res)[1])
    for limb in ("left_arm", "right_leg"):
        _shift_key(char, limb, k, EDIT)
    frames, wr, pos, swivel, body = retarget_apply.sample_source(src)
    sw = writer.unwrap_swivel(swivel)
    sw[k, [0, 3]] += EDIT
    target = retarget_apply.target_rig_from_object(char)
    exp = rt.keep_ends_on_targets(rt.retarget(wr, pos, body, target, bmap, "as_is"), wr, pos, sw, ends="source")
    names = []
    for joint, end in (("left_shoulder", "left_wrist"), ("left_elbow", None), ("right_hip", None),
                       ("right_knee", "right_ankle")):
        names += [bmap.bones[joint]] + list(bmap.twist.get(joint, [])) + ([bmap.bones[end]] if end else [])
    twisted = [n for j in ("left_shoulder", "left_elbow", "right_hip", "right_knee") for n in bmap.twist.get(j, [])]
    assert twisted, "no twist bones on the edited limbs: the check would prove nothing"
    idx = [exp.bone_names.index(n) for n in names]
    bpy.context.scene.frame_set(1 + k)
    h, r = _world_pose(char, names)
    assert np.linalg.norm(h - exp.world_heads()[k, idx], axis=-1).max() < MM
    assert np.abs(r - exp.world_orientations()[k, idx]).max() < 1e-3
    # the edit changed the twist the bones share (the test would pass without the shares otherwise)
    it = [exp.bone_names.index(n) for n in twisted]
    before = res.world_orientations()[k, it]
    assert np.degrees(rot.geodesic_angle(before, exp.world_orientations()[k, it])).max() > 5.0


def test_twist_bones_share_the_edited_twist(addon, tmp_path):
    """A character with twist bones (two along the upper arm, one along the forearm and thigh,
    as Unreal's mannequin has them): after a swivel edit they still share their segment's twist as
    the retarget does."""
    src, char = _take()
    twist = {"left_shoulder": ("mixamorig:LeftArm", "mixamorig:LeftForeArm", ["LeftArmTwist1", "LeftArmTwist2"]),
             "left_elbow": ("mixamorig:LeftForeArm", "mixamorig:LeftHand", ["LeftForeArmTwist"]),
             "right_hip": ("mixamorig:RightUpLeg", "mixamorig:RightLeg", ["RightThighTwist"])}
    bpy.context.view_layer.objects.active = char
    bpy.ops.object.mode_set(mode='EDIT')
    eb = char.data.edit_bones
    for seg, nxt, names in twist.values():
        d = eb[nxt].head - eb[seg].head
        for i, n in enumerate(names):
            t = eb.new(n)
            t.head = eb[seg].head + d * (i + 1) / (len(names) + 1)
            t.tail = t.head + d.normalized() * 0.05
            t.roll = eb[seg].roll
            t.parent = eb[seg]
    bpy.ops.object.mode_set(mode='OBJECT')
    base = bone_maps.preset("mixamo")
    bmap = bone_maps.BoneMap("mixamo_twist", dict(base.bones), {j: v[2] for j, v in twist.items()})
    bone_maps.save_bone_map(tmp_path / "map.json", bmap)
    _check_edit_keeps_twist_shared(src, char, "file", str(tmp_path / "map.json"), bmap)


@pytest.mark.parametrize("style", ["cc4", "daz_genesis8"])
def test_twist_chains_of_tool_rigs_share_the_edited_twist(addon, style):
    """CC's Twist01/02 pairs (a chain beside the limb: Twist01 under the segment bone, Twist02
    under Twist01) and Daz's Bend/Twist chains (the Twist bone between the Bend bone and the next
    segment's), with their presets: a swivel edit keeps the twist shared as the retarget shares it."""
    res = consistent_result(T=T, seed=1, stature=1.55)
    src = writer.write_result(res, writer.WriteOptions(frame_start=1)).armature
    char, _ = styled_character(style)
    bmap, _ = retarget_apply.resolve_bone_map(style, char)
    assert bmap.twist
    _check_edit_keeps_twist_shared(src, char, style, None, bmap)


def test_cli_live_swivel(tmp_path, monkeypatch):
    """``solve --retarget ... --keep-ends``: the saved character has the live swivel;
    ``--no-live-swivel`` (or no --keep-ends) gives plain keys."""
    from blender_manikin import cli
    from blender_manikin.blender import solve_job
    from blender_util import fresh_scene, stub_solver, synthetic_result, write_recording_csv
    p = cli.build_parser()
    base = ["solve", "take.csv", "--out", "out", "--retarget", "c.blend"]
    assert p.parse_args(base).live_swivel is None                 # follows --keep-ends
    assert p.parse_args(base + ["--keep-ends", "--no-live-swivel"]).live_swivel is False
    assert p.parse_args(base + ["--live-swivel"]).live_swivel is True
    fresh_scene()
    mixamo_style_character("Character", stature=1.7)
    lib = tmp_path / "characters.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(lib), copy=True)
    rec = write_recording_csv(tmp_path / "take.csv", synthetic_result(T=20, fps=30.0, seed=2))
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    for flags, live in (([], True), (["--no-live-swivel"], False)):
        out = tmp_path / f"out{int(live)}"
        assert cli.main(["solve", str(rec), "--out", str(out), "--format", "blend", "--fps", "30", "--height", "1.8",
                         "--retarget", f"{lib}:Character", "--keep-ends"] + flags) == 0
        bpy.ops.wm.open_mainfile(filepath=str(out / "take.blend"))
        char = bpy.data.objects["Character"]
        assert cs.is_character_rig(char) == live
        assert (writer.SWIVEL_PROPS["left_leg"] in char.keys()) == live


def test_swivel_panel_on_the_character(addon):
    from blender_manikin.panels import swivel_panel
    src, char = _take()
    retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)
    bpy.context.view_layer.objects.active = char
    assert swivel_panel.MANIKIN_PT_swivel.poll(bpy.context)
    log = []
    swivel_panel.MANIKIN_PT_swivel.draw(type("P", (), {"layout": _FakeLayout(log)})(), bpy.context)
    assert [a[1] for kind, a, k in log if kind == "prop"] == [f'["swivel_{limb}"]' for limb in sk.LIMB_NAMES]
    ops = {a for kind, a, k in log if kind == "operator"}
    assert {"manikin.key_swivel", "manikin.smooth_swivel", "manikin.reset_swivel",
            "manikin.bake_character_swivel"} <= ops and "manikin.bake_live_rig" not in ops
    for idname in ops:
        assert getattr(bpy.ops.manikin, idname.split(".")[1]).poll()
    bpy.context.view_layer.objects.active = src            # the body (FK solve): not a character rig
    assert not bpy.ops.manikin.bake_character_swivel.poll()


def _socketed_character(name="Socketed"):
    """A Mixamo-named character whose upper arms hang under unmapped socket bones that follow the
    collars through Copy Transforms, as a generated Rigify rig's arms hang under ORG-shoulder
    (copying the shoulder control): the retarget's own arithmetic keeps such a socket at rest
    under the chest, Blender turns it with the collar."""
    from blender_util import build_armature, humanoid_bones, humanoid_joints
    P = humanoid_joints(1.95, 40.0)
    names = bone_maps.preset("mixamo").bones
    bones = humanoid_bones(P, names)
    out = []
    for b in bones:
        for side, S in (("left", "Left"), ("right", "Right")):
            if b[0] == f"mixamorig:{S}Arm":
                col = next(x for x in bones if x[0] == f"mixamorig:{S}Shoulder")
                out.append((f"{S}ArmSocket", "mixamorig:Spine2", col[2], col[3]))
                b = (b[0], f"{S}ArmSocket", b[2], b[3])
        out.append(b)
    char = build_armature(name, out, seed=4)
    for S in ("Left", "Right"):
        c = char.pose.bones[f"{S}ArmSocket"].constraints.new('COPY_TRANSFORMS')
        c.target, c.subtarget = char, f"mixamorig:{S}Shoulder"
    return char


def test_live_swivel_hands_on_an_arm_under_a_constrained_socket(addon):
    """Keep-ends with the live swivel on a rig whose arms hang under bones following the collars
    through constraints (a generated Rigify rig's ORG-shoulder): the hand controls were keyed
    where the retarget's arithmetic put the shoulders (the sockets at rest), 12 cm off where
    Blender turns them on Rigify, so the live IK stretched the arms straight or bent them
    otherwise than the plain keys (Rigify on the bundled example: 108 and 129 frames straight
    where the performer's elbows bent over 20°).  The controls are moved with the evaluated
    shoulder: the live rig gives the plain keys' pose."""
    src, _ = _take()
    plain = _socketed_character("Plain")
    retarget_apply.retarget_onto(src, plain, "mixamo", None, "scaled", True, live_swivel=False)
    live = _socketed_character("Live")
    retarget_apply.retarget_onto(src, live, "mixamo", None, "scaled", True, live_swivel=True)
    sc = bpy.context.scene
    worst = 0.0
    arm = [n for b in LIMB_BONES[:2] for n in b]
    for k in (0, 9, 19, 29):
        sc.frame_set(1 + k)
        hp, _ = _world_pose(plain, arm)
        hl, _ = _world_pose(live, arm)
        worst = max(worst, float(np.abs(hp - hl).max()))
    assert worst < MM, worst


def test_the_animators_own_manikin_named_constraints_survive_the_rig(addon):
    """Only the rig's own constraints are its (``MANIKIN follow IK``, ...): an animator's
    constraint whose name merely starts with ``MANIKIN `` (``MANIKIN mine``) stays, unmuted, when
    a second retarget rebuilds the rig, when the rig is muted and when Bake removes it; and its
    bone is not taken for one the rig drives.  (A real Blender window showed a second retarget
    deleting it.)"""
    src, char = _take()
    hips = bone_maps.preset("mixamo").bones["pelvis"]
    fore = LIMB_BONES[0][1]
    for name in (fore, hips):
        c = char.pose.bones[name].constraints.new('LIMIT_SCALE')
        c.name = "MANIKIN mine"

    def mine():
        return [(n, [(c.name, c.mute) for c in char.pose.bones[n].constraints if c.name == "MANIKIN mine"])
                for n in (fore, hips)]

    kept = [(fore, [("MANIKIN mine", False)]), (hips, [("MANIKIN mine", False)])]
    retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)
    retarget_apply.retarget_onto(src, char, "auto", None, "as_is", True)      # the rig rebuilt
    assert cs.is_character_rig(char) and mine() == kept
    assert hips not in cs.rig_driven_bones(char)
    live_rig.set_rig_enabled(char, False)
    assert mine() == kept
    live_rig.set_rig_enabled(char, True)
    cs.bake_character_rig(char, remove_rig=True)
    assert not cs.is_character_rig(char) and mine() == kept
