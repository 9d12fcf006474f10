"""glTF binary (.glb) export: the example's solve written by ``solve --format glb`` and a retargeted
character written by the panel's Export glTF / Export Each Take, read back with numpy (the GLB's
JSON and binary chunks, the nodes' TRS tracks multiplied down the hierarchy): the skin's joints,
one animation over the take's frames, and the joints' world positions where the solve / the
character put them (within 1 mm).  The user's scene is as it was after an export."""
import json
import os
import struct

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import fresh_scene, mixamo_style_character, synthetic_result  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")

#: componentType -> numpy dtype; accessor type -> components
_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def read_glb(path):
    """``(gltf JSON dict, binary chunk bytes)`` of the GLB ``path``: the 12-byte header ("glTF",
    version 2, length), the JSON chunk, then the BIN chunk."""
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    jlen, jtype = struct.unpack_from("<I4s", data, 12)
    assert jtype == b"JSON"
    gltf = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack_from("<I4s", data, 20 + jlen)
    assert btype == b"BIN\x00"
    return gltf, data[28 + jlen:28 + jlen + blen]


def accessor(gltf, binary, index):
    """Accessor ``index`` as a float array ``(count, components)`` (a byte stride honoured)."""
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(_DTYPES[acc["componentType"]])
    n = _WIDTH[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", n * dtype.itemsize)
    rows = [np.frombuffer(binary, dtype, n, start + i * stride) for i in range(acc["count"])]
    return np.array(rows, np.float64).reshape(acc["count"], n)


def _quat_matrix(q):
    """3x3 rotation of the glTF quaternion ``(x, y, z, w)``."""
    x, y, z, w = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def world_positions(gltf, binary, animation, times):
    """``{node name: (len(times), 3)}``: every node's world origin at each time (seconds), from the
    nodes' rest TRS and ``animation``'s tracks (linear, as the samplers say), in Blender's axes
    (glTF's +Y up back to +Z up: Blender ``(x, -z, y)``), metres."""
    nodes = gltf["nodes"]
    tracks = {}
    for ch in animation["channels"]:
        smp = animation["samplers"][ch["sampler"]]
        assert smp.get("interpolation", "LINEAR") == "LINEAR"
        tracks[(ch["target"]["node"], ch["target"]["path"])] = (accessor(gltf, binary, smp["input"])[:, 0],
                                                               accessor(gltf, binary, smp["output"]))
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", ())}

    def value(i, path, default, t):
        if (i, path) not in tracks:
            return np.asarray(nodes[i].get(path, default), float)
        tt, vv = tracks[(i, path)]
        k = int(np.clip(np.searchsorted(tt, t) - 1, 0, len(tt) - 2))
        a = float(np.clip((t - tt[k]) / (tt[k + 1] - tt[k]), 0.0, 1.0))
        return (1 - a) * vv[k] + a * vv[k + 1]

    out = {n.get("name", str(i)): np.empty((len(times), 3)) for i, n in enumerate(nodes)}
    for f, t in enumerate(times):
        world = {}

        def matrix(i):
            if i not in world:
                m = np.eye(4)
                m[:3, :3] = _quat_matrix(value(i, "rotation", (0, 0, 0, 1), t)) * value(i, "scale", (1, 1, 1), t)
                m[:3, 3] = value(i, "translation", (0, 0, 0), t)
                world[i] = (matrix(parent[i]) @ m) if i in parent else m
            return world[i]
        for i, n in enumerate(nodes):
            x, y, z = matrix(i)[:3, 3]
            out[n.get("name", str(i))][f] = (x, -z, y)
    return out


@pytest.mark.parametrize("fps", ["30", "29.97"])
def test_solve_format_glb_holds_the_solved_motion(tmp_path, fps):
    """``solve --format glb,npz`` on the example: one skin of the 22 joints (the deforming bones;
    the live rig's MCH and control bones baked in) used by the mannequin; one animation of 3
    tracks per joint, 210 keys from 0 to 209/fps s (at 29.97 fps too: the exporter's own timing
    gave 30.03 fps); the joints' world positions at frames 1, 60, 150, 210 those of the solve (the
    .npz) within 1 mm.  Before: ``unknown format(s) glb``."""
    from blender_manikin import cli
    fresh_scene()
    out = tmp_path / "out"
    assert cli.main(["solve", EXAMPLE, "--out", str(out), "--format", "glb,npz", "--fps", fps]) == 0
    assert sorted(os.listdir(out)) == [".blender_manikin_outputs", "example_recording.glb",
                                       "example_recording.npz"]         # no temporary folder left
    gltf, binary = read_glb(out / "example_recording.glb")
    solved = np.load(out / "example_recording.npz")
    rate, pos = float(solved["fps"]), solved["positions"]
    T = len(pos)
    assert (T, rate) == (210, float(fps))
    names = [n.get("name") for n in gltf["nodes"]]
    (skin,) = gltf["skins"]
    assert sorted(names[j] for j in skin["joints"]) == sorted(sk.JOINT_NAMES)
    skinned = [n for n in gltf["nodes"] if "skin" in n]
    assert [n["name"] for n in skinned] == ["MANIKIN_body_mannequin"]   # the mannequin comes along
    (anim,) = gltf["animations"]
    assert len(anim["samplers"]) == 3 * sk.NUM_JOINTS
    assert {(names[c["target"]["node"]], c["target"]["path"]) for c in anim["channels"]} == {
        (j, p) for j in sk.JOINT_NAMES for p in ("translation", "rotation", "scale")}
    for smp in anim["samplers"]:                        # every frame keyed, no key reduction
        acc = gltf["accessors"][smp["input"]]
        assert acc["count"] == T
        assert acc["min"][0] == pytest.approx(0.0) and acc["max"][0] == pytest.approx((T - 1) / rate, rel=1e-6)
    frames = np.array([1, 60, 150, 210])
    got = world_positions(gltf, binary, anim, (frames - 1) / rate)
    for j, name in enumerate(sk.JOINT_NAMES):
        np.testing.assert_allclose(got[name], pos[frames - 1, j], atol=1e-3, err_msg=name)


def _heads(arm, names, frames):
    """World heads ``(len(frames), len(names), 3)`` of ``arm``'s pose bones, metres."""
    sc = bpy.context.scene
    out = np.empty((len(frames), len(names), 3))
    for k, f in enumerate(frames):
        sc.frame_set(int(f))
        W = np.array(arm.matrix_world)
        for j, n in enumerate(names):
            out[k, j] = (W @ np.append(np.array(arm.pose.bones[n].head), 1.0))[:3]
    return out


def _retargeted_character(takes=1):
    """A Mixamo-style character as an FBX in centimetres lands (object scaled 0.01, turned 90°),
    with a non-deforming control bone and ``takes`` retargeted synthetic solves (24 fps)."""
    from blender_manikin.blender import retarget_apply, writer
    char = mixamo_style_character("Hero", stature=1.75, fbx_cm=True)
    bpy.context.view_layer.objects.active = char
    bpy.ops.object.mode_set(mode='EDIT')
    b = char.data.edit_bones.new("ctrl_hand_ik.L")
    b.head, b.tail, b.use_deform = (50.0, 30.0, 0.0), (50.0, 40.0, 0.0), False
    bpy.ops.object.mode_set(mode='OBJECT')
    for k in range(takes):
        res = synthetic_result(T=30 + 10 * k, fps=24.0, seed=1 + k, stature=1.8)
        src = writer.write_result(res, writer.WriteOptions(frame_start=1, armature_name=f"MANIKIN_take{k}")).armature
        retarget_apply.retarget_onto(src, char, "mixamo", None, "scaled", False)
    return char


def test_export_gltf_writes_the_character_and_leaves_the_scene_as_it_was(addon, tmp_path):
    """The panel's Export glTF with the retargeted character: its deforming bones are the joints,
    its animation the active action's, and the mapped bones land where Blender has them (within
    1 mm, through the object's 0.01 scale and turn); afterwards no object or action more, the
    selection, the active object and the current frame as they were.  The panel's Export
    sub-panel offers it when the format is glTF Binary."""
    from blender_manikin.core import bone_maps
    from blender_manikin.panels import main as panels
    from test_blender_bone_map_editor import PanelLayout
    from types import SimpleNamespace
    sc = bpy.context.scene
    sc.render.fps = 24
    char = _retargeted_character()
    s = sc.manikin
    s.retarget_target = char
    sc.frame_start, sc.frame_end = 1, 30
    sc.render.fps_base = 1.001          # played at 23.976 fps
    rate = 24 / 1.001
    sc.frame_set(7)
    other = next(o for o in bpy.data.objects if o.name.startswith("MANIKIN_take0"))
    for o in bpy.data.objects:
        o.select_set(o is other)
    bpy.context.view_layer.objects.active = other
    before = (sorted(bpy.data.objects.keys()), sorted(bpy.data.actions.keys()), sorted(bpy.data.armatures.keys()),
              sorted(bpy.data.meshes.keys()), list(sc.keys()))
    s.export_format = 'GLB'
    log = []
    panels.MANIKIN_PT_export.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("operator", "manikin.export_gltf") in log and ("operator", "manikin.export_fbx") not in log
    assert ("prop", "export_fbx_preset") not in log and ("operator", "manikin.export_fbx_takes") in log
    path = tmp_path / "hero.glb"
    assert bpy.ops.manikin.export_gltf(filepath=str(path)) == {'FINISHED'}
    after = (sorted(bpy.data.objects.keys()), sorted(bpy.data.actions.keys()), sorted(bpy.data.armatures.keys()),
             sorted(bpy.data.meshes.keys()), list(sc.keys()))
    assert after == before
    assert [o for o in bpy.data.objects if o.select_get()] == [other]
    assert bpy.context.view_layer.objects.active == other and sc.frame_current == 7
    assert (sc.render.fps, sc.render.fps_base) == (24, pytest.approx(1.001))
    gltf, binary = read_glb(path)
    names = [n.get("name") for n in gltf["nodes"]]
    (anim,) = gltf["animations"]
    assert anim["name"] == char.animation_data.action.name
    joints = {names[c["target"]["node"]] for c in anim["channels"]}
    assert joints == {b.name for b in char.data.bones if b.use_deform}          # no control bone
    mapped = sorted(bone_maps.preset("mixamo").bones.values())
    frames = np.array([1, 12, 30])
    acc = gltf["accessors"][anim["samplers"][0]["input"]]
    assert acc["count"] == 30 and acc["max"][0] == pytest.approx(29 / rate, rel=1e-6)
    got = world_positions(gltf, binary, anim, (frames - 1) / rate)
    want = _heads(char, mapped, frames)
    for j, name in enumerate(mapped):
        np.testing.assert_allclose(got[name], want[:, j], atol=1e-3, err_msg=name)


def test_export_each_take_as_glb(addon, tmp_path):
    """Export Each Take in glTF Binary: one <character>_<take>.glb per take, each one animation
    named after its take, over the take's own frames; the character's action and the scene's
    range as they were."""
    bpy.context.scene.render.fps = 24
    char = _retargeted_character(takes=2)
    s = bpy.context.scene.manikin
    s.retarget_target = char
    s.export_format = 'GLB'
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 5, 7
    current = char.animation_data.action
    takes = sorted(a.name for a in bpy.data.actions if a.name.startswith("MANIKIN_retarget_"))
    assert len(takes) == 2
    folder = tmp_path / "takes"
    assert bpy.ops.manikin.export_fbx_takes(directory=str(folder), file_format='GLB') == {'FINISHED'}
    files = sorted(f for f in os.listdir(folder) if not f.startswith("."))     # less the outputs record
    assert len(files) == 2 and all(f.startswith("Hero_") and f.endswith(".glb") for f in files)
    assert char.animation_data.action == current and (sc.frame_start, sc.frame_end) == (5, 7)
    from blender_manikin.blender import keying
    from blender_manikin.core import bone_maps
    mapped = sorted(bone_maps.preset("mixamo").bones.values())
    for name, f in zip(takes, files):
        gltf, binary = read_glb(folder / f)
        (anim,) = gltf["animations"]
        assert anim["name"] == name
        first, last = bpy.data.actions[name].frame_range
        acc = gltf["accessors"][anim["samplers"][0]["input"]]
        assert acc["count"] == round(last - first) + 1
        assert acc["max"][0] == pytest.approx((last - first) / 24.0)
        # the take's own motion (not another take's keys merged over it)
        frames = np.array([first, round((first + last) / 2), last])
        got = world_positions(gltf, binary, anim, (frames - first) / 24.0)
        keying.assign_action(char, bpy.data.actions[name])
        want = _heads(char, mapped, frames)
        for j, bone in enumerate(mapped):
            np.testing.assert_allclose(got[bone], want[:, j], atol=1e-3, err_msg=f"{name} {bone}")


def test_a_glb_batch_exits_with_its_own_status(tmp_path):
    """Blender 4.2's bpy module crashed on its way out after its glTF exporter ran: a batch that
    wrote every .glb exited 139 (a job scheduler saw a failure).  The command line leaves with
    its own status (cli.exit_process); a bad input still gives 1."""
    import subprocess
    import sys
    root, example = ROOT, EXAMPLE
    env = dict(os.environ, PYTHONPATH=root)
    ok = subprocess.run([sys.executable, "-m", "blender_manikin", "solve", example, "--out", str(tmp_path / "o"),
                         "--format", "glb"], cwd=root, env=env, capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0, (ok.returncode, ok.stderr[-2000:])
    assert (tmp_path / "o" / "example_recording.glb").stat().st_size > 0
    bad = tmp_path / "bad.csv"
    bad.write_text("time,device,px,py,pz,qw,qx,qy,qz\n0.0,head,1,2\n")
    failed = subprocess.run([sys.executable, "-m", "blender_manikin", "solve", example, str(bad), "--out",
                             str(tmp_path / "o2"), "--format", "glb"], cwd=root, env=env, capture_output=True,
                            text=True, timeout=300)
    assert failed.returncode == 1, (failed.returncode, failed.stderr[-2000:])
