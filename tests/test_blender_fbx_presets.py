"""FBX presets for Blender, Unity and Unreal: a retargeted character exported with each, imported
again by Blender's own FBX importer; the mapped bones (and a skinned mesh) land where they were,
and each preset's axes, units, bones and takes are what the engine expects."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import fbx_presets, keying, retarget_apply, writer  # noqa: E402
from blender_manikin.core import bone_maps  # noqa: E402

from blender_util import fresh_scene, mixamo_style_character, synthetic_result  # noqa: E402

T = 30
FRAMES = (1, 9, 17, 30)
MAPPED = sorted(bone_maps.preset("mixamo").bones.values())
CONTROL = "ctrl_hand_ik.L"            # a non-deforming control bone of the character


def _character_with_motion(mesh=True):
    """A Mixamo-style character (with a control bone, a skinned mesh, and an action of its own
    kept with a fake user) carrying a retargeted solve; the scene's range is the take's."""
    res = synthetic_result(T=T, fps=24.0, seed=1, stature=1.8)
    src = writer.write_result(res, writer.WriteOptions(frame_start=1)).armature
    char = mixamo_style_character("Hero", stature=1.75)
    bpy.context.view_layer.objects.active = char
    bpy.ops.object.mode_set(mode='EDIT')
    b = char.data.edit_bones.new(CONTROL)
    b.head, b.tail, b.use_deform = (0.5, 0.3, 0.0), (0.5, 0.3, 0.1), False
    bpy.ops.object.mode_set(mode='OBJECT')
    idle = bpy.data.actions.new("hero_idle")
    keying.assign_action(char, idle)
    keying.key_channels(idle, char, [1.0, 5.0], [('pose.bones["mixamorig:Hips"].location', 0, "Hips", [0.0, 0.1])])
    retarget_apply.retarget_onto(src, char, "mixamo", None, "scaled", False)
    assert idle.use_fake_user and char.animation_data.action != idle
    if mesh:
        _skinned_mesh(char)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, T
    return char


def _skinned_mesh(char):
    """Two triangles: one weighted to the hips, one to the left forearm."""
    W = np.array(char.matrix_world)
    hips = np.array(char.data.bones["mixamorig:Hips"].head_local)
    fore = char.data.bones["mixamorig:LeftForeArm"]
    mid = (np.array(fore.head_local) + np.array(fore.tail_local)) / 2
    verts = [hips + d for d in np.array([(0.1, 0, 0), (-0.1, 0, 0), (0, 0.05, 0.1)])]
    verts += [mid + d for d in np.array([(0.02, 0, 0), (-0.02, 0, 0), (0, 0.03, 0.02)])]
    me = bpy.data.meshes.new("HeroBody")
    me.from_pydata([tuple((W @ np.append(v, 1))[:3]) for v in verts], [], [(0, 1, 2), (3, 4, 5)])
    ob = bpy.data.objects.new("HeroBody", me)
    bpy.context.scene.collection.objects.link(ob)
    for name, idx in (("mixamorig:Hips", [0, 1, 2]), ("mixamorig:LeftForeArm", [3, 4, 5])):
        ob.vertex_groups.new(name=name).add(idx, 1.0, 'REPLACE')
    ob.modifiers.new("Armature", 'ARMATURE').object = char
    ob.parent = char
    ob.matrix_parent_inverse = char.matrix_world.inverted()
    return ob


def _bone_heads(arm, names, frames):
    """World heads ``(len(frames), len(names), 3)`` of ``arm``'s pose bones, metres."""
    sc = bpy.context.scene
    out = np.empty((len(frames), len(names), 3))
    for k, f in enumerate(frames):
        sc.frame_set(f)
        W = np.array(arm.matrix_world)
        for j, n in enumerate(names):
            out[k, j] = (W @ np.append(np.array(arm.pose.bones[n].head), 1.0))[:3]
    return out


def _mesh_verts(ob, frames):
    sc = bpy.context.scene
    out = []
    for f in frames:
        sc.frame_set(f)
        ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
        W = np.array(ev.matrix_world)
        co = np.array([W @ np.append(np.array(v.co), 1.0) for v in ev.data.vertices])[:, :3]
        out.append(co)
    return np.array(out)


def _import(path, raw=False):
    """Import ``path`` into an empty scene; ``raw``: without undoing the file's axes or units (what
    an application reading the numbers as they are sees).  Returns ``(armature, meshes)``."""
    fresh_scene()
    bpy.context.scene.render.fps = 24
    kw = {}
    if raw:
        unit = _global_settings(path)["UnitScaleFactor"]
        kw = dict(use_manual_orientation=True, axis_forward='Y', axis_up='Z', global_scale=100.0 / unit)
    # FBX keeps scene frame f at time f / fps; the importer's default anim_offset would add a frame
    assert bpy.ops.import_scene.fbx(filepath=str(path), anim_offset=0.0, **kw) == {'FINISHED'}
    arms = [o for o in bpy.data.objects if o.type == 'ARMATURE']
    assert len(arms) == 1
    return arms[0], [o for o in bpy.data.objects if o.type == 'MESH']


def _global_settings(path):
    """The file's GlobalSettings as Blender's FBX importer reads them."""
    from io_scene_fbx import parse_fbx
    from io_scene_fbx.import_fbx import elem_find_first, elem_props_get_integer, elem_props_get_number
    root, _ = parse_fbx.parse(str(path))
    props = elem_find_first(elem_find_first(root, b'GlobalSettings'), b'Properties70')
    out = {k: elem_props_get_integer(props, k.encode(), None)
           for k in ("UpAxis", "UpAxisSign", "FrontAxis", "FrontAxisSign", "CoordAxis", "CoordAxisSign")}
    out["UnitScaleFactor"] = elem_props_get_number(props, b"UnitScaleFactor", None)
    return out


#: per preset: the file's axes (FBX axis index 0/1/2 = X/Y/Z, sign), its unit in centimetres, the
#: raw frame's up / front / left directions of the character and the root node's raw rotation
#: (degrees about X) and scale
EXPECTED = {
    "blender": dict(up=(1, 1), front=(2, 1), coord=(0, 1), unit=1.0, raw_up=[0, 1, 0], raw_front=[0, 0, 1],
                    raw_left=[1, 0, 0], root_rot_x=-90.0, root_scale=100.0, deform_only=False),
    "unity": dict(up=(1, 1), front=(2, 1), coord=(0, 1), unit=100.0, raw_up=[0, 1, 0], raw_front=[0, 0, 1],
                  raw_left=[1, 0, 0], root_rot_x=-90.0, root_scale=1.0, deform_only=True),
    "unreal": dict(up=(2, 1), front=(1, -1), coord=(0, 1), unit=1.0, raw_up=[0, 0, 1], raw_front=[0, -1, 0],
                   raw_left=[1, 0, 0], root_rot_x=0.0, root_scale=1.0, deform_only=True),
}


@pytest.mark.parametrize("preset", fbx_presets.PRESET_NAMES)
def test_preset_round_trip_and_engine_facts(addon, tmp_path, preset):
    char = _character_with_motion()
    body = bpy.data.objects["HeroBody"]
    before = _bone_heads(char, MAPPED, FRAMES)
    verts = _mesh_verts(body, FRAMES)
    names = sorted(o.name for o in bpy.data.objects)
    head0 = np.array(char.data.bones["mixamorig:Head"].head_local)
    hips0 = np.array(char.data.bones["mixamorig:Hips"].head_local)
    n_arm, n_act = len(bpy.data.armatures), len(bpy.data.actions)
    bpy.context.view_layer.objects.active = body
    for o in bpy.data.objects:
        o.select_set(o.name == "HeroBody")
    path = tmp_path / f"hero_{preset}.fbx"
    info = fbx_presets.export_fbx(path, char, preset)
    assert info["stand_in"] == (preset == "unreal")
    # the scene as it was: names, selection, active object; no stand-in left behind
    assert sorted(o.name for o in bpy.data.objects) == names and char.name == "Hero"
    assert len(bpy.data.armatures) == n_arm and len(bpy.data.actions) == n_act
    assert [o.name for o in bpy.data.objects if o.select_get()] == ["HeroBody"]
    assert bpy.context.view_layer.objects.active == body
    exp = EXPECTED[preset]
    gs = _global_settings(path)
    assert (gs["UpAxis"], gs["UpAxisSign"]) == exp["up"]
    assert (gs["FrontAxis"], gs["FrontAxisSign"]) == exp["front"]
    assert (gs["CoordAxis"], gs["CoordAxisSign"]) == exp["coord"]
    assert gs["UnitScaleFactor"] == pytest.approx(exp["unit"])

    # imported with the importer's defaults (it undoes the file's axes and units): the mapped
    # bones and the skinned mesh where they were, within 1 mm, on every frame checked
    arm, meshes = _import(path)
    assert arm.name == "Hero"
    # the armature object as Blender's importer makes it: upright, at the file's unit (Unreal's
    # bones are centimetres, the object 0.01)
    _, rq, sc = arm.matrix_world.decompose()
    assert rq.angle < 1e-5
    np.testing.assert_allclose(np.array(sc), 0.01 if preset == "unreal" else 1.0, rtol=1e-5)
    bones = set(arm.data.bones.keys())
    assert not any(b.endswith("_end") for b in bones)                 # no leaf bones
    assert (CONTROL in bones) == (not exp["deform_only"])              # engines: deforming bones only
    assert set(MAPPED) <= bones
    assert [a.name for a in bpy.data.actions if a.users] and len(bpy.data.actions) == 1   # one take
    fcs = keying.action_fcurves(bpy.data.actions[0])
    assert fcs and all(len(fc.keyframe_points) == T for fc in fcs)    # every frame, no reduction
    np.testing.assert_allclose(_bone_heads(arm, MAPPED, FRAMES), before, atol=1e-3)
    assert [m.name for m in meshes] == ["HeroBody"]
    np.testing.assert_allclose(_mesh_verts(meshes[0], FRAMES), verts, atol=1e-3)
    # units: Blender and Unity put the armature's bones in metres, Unreal in centimetres (the
    # object at 0.01 here, as Blender imports a centimetre file)
    per_unit = 100.0 if preset == "unreal" else 1.0
    assert np.linalg.norm(arm.data.bones["mixamorig:Head"].head_local) == pytest.approx(
        per_unit * np.linalg.norm(head0), rel=1e-4)

    # the numbers as written (what an engine reads before its own conversion): the root's turn
    # and scale, the character's up, front and left, and the length unit
    arm, _ = _import(path, raw=True)
    loc, rq, sc = arm.matrix_world.decompose()
    np.testing.assert_allclose(np.array(sc), exp["root_scale"], rtol=1e-5)
    axis, ang = rq.to_axis_angle()
    if exp["root_rot_x"] == 0.0:
        assert abs(ang) < 1e-5
    else:
        np.testing.assert_allclose(np.degrees(ang) * np.sign(axis.x), exp["root_rot_x"], atol=1e-3)
        np.testing.assert_allclose(np.abs(np.array(axis)), [1, 0, 0], atol=1e-5)
    W = np.array(arm.matrix_world)

    def rest(n):
        return (W @ np.append(np.array(arm.data.bones[n].head_local), 1.0))[:3]
    per_m = 100.0 / exp["unit"]                     # raw numbers per metre
    up = rest("mixamorig:Head") - rest("mixamorig:Hips")
    left = rest("mixamorig:LeftUpLeg") - rest("mixamorig:RightUpLeg")
    toes = rest("mixamorig:LeftToeBase") - rest("mixamorig:LeftFoot")    # the foot points to the front
    assert np.linalg.norm(up) / per_m == pytest.approx(np.linalg.norm(head0 - hips0), rel=1e-4)
    np.testing.assert_allclose(up / np.linalg.norm(up), exp["raw_up"], atol=1e-4)
    np.testing.assert_allclose(left / np.linalg.norm(left), exp["raw_left"], atol=1e-4)
    front = toes - np.dot(toes, exp["raw_up"]) * np.array(exp["raw_up"], float)
    np.testing.assert_allclose(front / np.linalg.norm(front), exp["raw_front"], atol=1e-4)


def test_presets_are_what_the_exporter_takes(addon):
    """Every keyword of every preset is one this Blender's exporter accepts (a typo would be
    dropped silently otherwise); keywords another version lacks are left out."""
    have = fbx_presets.accepted_keywords()
    for name in fbx_presets.PRESET_NAMES:
        assert set(fbx_presets.PRESETS[name]) <= have, set(fbx_presets.PRESETS[name]) - have
        assert fbx_presets.exporter_kwargs(name) == fbx_presets.PRESETS[name]
    older = have - {"bake_anim_simplify_factor", "colors_type"}
    kw = fbx_presets.exporter_kwargs("unity", older)
    assert "bake_anim_simplify_factor" not in kw and kw["apply_scale_options"] == 'FBX_SCALE_ALL'
    with pytest.raises(ValueError, match="unknown FBX preset 'maya'"):
        fbx_presets.preset_kwargs("maya")
    # what the add-on always exported stays the default
    assert fbx_presets.DEFAULT == "blender" and fbx_presets.PRESETS["blender"]["axis_forward"] == '-Z'


def test_export_operator_writes_the_character_with_the_preset(addon, tmp_path):
    char = _character_with_motion(mesh=False)
    s = bpy.context.scene.manikin
    s.retarget_target = char
    s.export_fbx_preset = 'UNITY'
    path = tmp_path / "hero.fbx"
    assert bpy.ops.manikin.export_fbx(filepath=str(path), preset='UNREAL') == {'FINISHED'}
    assert _global_settings(path)["UnitScaleFactor"] == pytest.approx(1.0)
    arm, _ = _import(path)
    assert arm.name == "Hero" and CONTROL not in arm.data.bones
    # without a character chosen, the solved armature is exported
    fresh_scene()
    res = synthetic_result(T=10, fps=24.0, seed=2)
    src = writer.write_result(res, writer.WriteOptions(frame_start=1)).armature
    s = bpy.context.scene.manikin
    s.armature = src
    path2 = tmp_path / "body.fbx"
    assert bpy.ops.manikin.export_fbx(filepath=str(path2), preset='UNITY') == {'FINISHED'}
    assert _global_settings(path2)["UnitScaleFactor"] == pytest.approx(100.0)
    arm, _ = _import(path2)
    assert "left_elbow" in arm.data.bones


def test_cli_fbx_preset(tmp_path, monkeypatch):
    """``solve --fbx-preset unreal``: the live rig (constraints, drivers) exported through the
    centimetre stand-in lands where the .blend has it; a wrong preset is a usage error."""
    from blender_manikin import cli
    from blender_manikin.blender import solve_job
    from blender_manikin.core import skeleton as sk
    from blender_util import stub_solver, write_recording_csv
    fresh_scene()
    rec = write_recording_csv(tmp_path / "take.csv", synthetic_result(T=30, fps=30.0, seed=2))
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    out = tmp_path / "out"
    assert cli.main(["solve", str(rec), "--out", str(out), "--format", "blend,fbx", "--fps", "30",
                     "--height", "1.8", "--fbx-preset", "unreal"]) == 0
    gs = _global_settings(out / "take.fbx")
    assert (gs["UpAxis"], gs["FrontAxis"], gs["FrontAxisSign"], gs["UnitScaleFactor"]) == (2, 1, -1, 1.0)
    bpy.ops.wm.open_mainfile(filepath=str(out / "take.blend"))
    body = next(o for o in bpy.data.objects if o.type == 'ARMATURE')
    names = list(sk.JOINT_NAMES)
    in_blend = _bone_heads(body, names, (3, 17))
    mannequin = [o for o in bpy.data.objects if o.type == 'MESH']
    assert [o.parent for o in mannequin] == [body]          # the solve's mannequin, on by default
    mannequin_blend = _mesh_verts(mannequin[0], (3, 17))
    fresh_scene()
    bpy.context.scene.render.fps = 30
    assert bpy.ops.import_scene.fbx(filepath=str(out / "take.fbx"), anim_offset=0.0) == {'FINISHED'}
    arm = next(o for o in bpy.data.objects if o.type == 'ARMATURE')
    np.testing.assert_allclose(_bone_heads(arm, names, (3, 17)), in_blend, atol=1e-3)
    # the mannequin comes along, skinned: in the engine it moves as in the .blend
    meshes = [o for o in bpy.data.objects if o.type == 'MESH']
    assert len(meshes) == 1
    np.testing.assert_allclose(_mesh_verts(meshes[0], (3, 17)), mannequin_blend, atol=1e-3)
    assert cli.main(["solve", str(rec), "--out", str(out), "--fbx-preset", "maya"]) == 2
    # --no-mannequin: the armature alone
    bare = tmp_path / "bare"
    assert cli.main(["solve", str(rec), "--out", str(bare), "--format", "fbx", "--fps", "30", "--height", "1.8",
                     "--no-mannequin"]) == 0
    _, meshes = _import(bare / "take.fbx")
    assert meshes == []


def _two_bone_character():
    """An armature ``char``: bone ``A`` (origin to +Z 1 m) and its child ``B`` (+Z 1 m to 2 m),
    quaternion rotations; two takes ``MANIKIN_retarget_t1`` / ``_t2`` keying only ``A`` (0.3 /
    -0.3 rad about X, frames 1-10) and an action ``idle`` keying only ``B`` (90° about X)."""
    import math
    sc = bpy.context.scene
    arm = bpy.data.armatures.new("char")
    ob = bpy.data.objects.new("char", arm)
    sc.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    bpy.ops.object.mode_set(mode='EDIT')
    a = arm.edit_bones.new("A")
    a.head, a.tail = (0, 0, 0), (0, 0, 1)
    b = arm.edit_bones.new("B")
    b.head, b.tail, b.parent = (0, 0, 1), (0, 0, 2), a
    bpy.ops.object.mode_set(mode='OBJECT')
    for pb in ob.pose.bones:
        pb.rotation_mode = 'QUATERNION'

    def take(name, bone, angle):
        act = keying.new_action(name)
        keying.assign_action(ob, act)
        q = [math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0]
        keying.key_channels(act, ob, [1, 10], [(f'pose.bones["{bone}"].rotation_quaternion', i, bone, [q[i]] * 2)
                                               for i in range(4)])
        return act
    takes = [take("MANIKIN_retarget_t1", "A", 0.3), take("MANIKIN_retarget_t2", "A", -0.3)]
    return ob, takes, take("idle", "B", math.pi / 2)


def test_each_take_exported_alone_not_blended_with_the_nla(tmp_path):
    """A character with an NLA track (its idle keys bone B, which the takes do not key): Export Each
    Take writes each take alone, B straight on A as in the take (before, the idle's 90° bend was
    baked into every take's file); the NLA evaluation is on again afterwards.  With a strip in
    tweak mode the export is refused with a message, nothing written, tweak mode kept."""
    fresh_scene()
    bpy.context.scene.render.fps = 24
    ob, takes, idle = _two_bone_character()
    ad = ob.animation_data
    ad.action = None
    track = ad.nla_tracks.new()
    track.strips.new("idle", 1, idle)
    keying.assign_action(ob, takes[0])
    sc = bpy.context.scene
    sc.frame_set(5)                      # the scene shown, the idle blended in, before the export
    bent = np.array(ob.matrix_world @ ob.pose.bones["B"].tail)
    assert np.allclose(bent, [0.0, -np.sin(0.3) - np.cos(0.3), np.cos(0.3) - np.sin(0.3)], atol=1e-5)
    paths = fbx_presets.export_fbx_takes(str(tmp_path / "takes"), ob, "blender")
    sc.frame_set(5)                      # the NLA evaluated again afterwards
    assert np.allclose(np.array(ob.matrix_world @ ob.pose.bones["B"].tail), bent, atol=1e-5)
    assert ad.use_nla and ad.action == takes[0] and len(paths) == 2
    for path, angle in zip(paths, (0.3, -0.3)):
        imp, _ = _import(path)
        bpy.context.scene.frame_set(5)
        tail = np.array(imp.matrix_world @ imp.pose.bones["B"].tail)
        # the take's truth: B straight on A, A turned `angle` about X: tail 2 m along A
        assert np.allclose(tail, [0.0, -2 * np.sin(angle), 2 * np.cos(angle)], atol=1e-4), (path, tail)
    fresh_scene()
    ob, takes, idle = _two_bone_character()
    ad = ob.animation_data
    ad.action = None
    track = ad.nla_tracks.new()
    track.strips.new("idle", 1, idle)
    ad.nla_tracks.active = track
    ad.use_tweak_mode = True
    with pytest.raises(ValueError, match="tweak mode"):
        fbx_presets.export_fbx_takes(str(tmp_path / "tweak"), ob, "blender")
    assert ad.use_tweak_mode and ad.action == idle and not (tmp_path / "tweak").exists()
    ad.use_tweak_mode = False


def test_an_export_path_too_long_for_windows_is_refused_naming_it(addon, tmp_path, monkeypatch):
    """On Windows (its limits switched on here), Export FBX and Save Map to a path over 259
    characters say so, naming the path, and write nothing (Blender's or the system's own failure
    said neither); a path that fits is written as before."""
    from blender_manikin.core import file_names
    monkeypatch.setattr(file_names, "ON_WINDOWS", True)
    char = _character_with_motion(mesh=False)
    s = bpy.context.scene.manikin
    s.retarget_target = char
    deep = tmp_path / ("d" * 100) / ("e" * 100)
    deep.mkdir(parents=True)
    path = deep / ("hero" * 10 + ".fbx")
    assert len(str(path)) > 259
    with pytest.raises(ValueError, match="too long for Windows"):
        fbx_presets.export_fbx(str(path), char, "unity")
    with pytest.raises(RuntimeError, match="export FBX: .*heroherohero.fbx: the path is too long for Windows"):
        bpy.ops.manikin.export_fbx(filepath=str(path), preset='UNITY')
    with pytest.raises(RuntimeError, match="save bone map: .*mapmapmap.json: the path is too long for Windows"):
        bpy.ops.manikin.save_bone_map(filepath=str(deep / ("map" * 20 + ".json")))
    assert list(deep.iterdir()) == []
    assert bpy.ops.manikin.export_fbx(filepath=str(tmp_path / "hero.fbx"), preset='UNITY') == {'FINISHED'}
