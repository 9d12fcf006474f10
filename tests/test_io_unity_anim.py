"""Unity ``.anim`` clips (``core/io_unity_anim.py``): the Unity Recorder's vector curves and the
float-curve form, keyed parents composed (a Camera Offset height), Euler curves in Unity's Z, X, Y
order, Hermite / stepped curves between keys, controllers keyed over part of the clip, refused
compressed clips and errors naming the line; one solve end to end."""
import os
import re

import numpy as np
import pytest

from blender_manikin.core import formats
from blender_manikin.core.recording import RecordingError, from_blender

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")
HEAD, LEFT, RIGHT = ("XR Origin/Camera Offset/Main Camera", "XR Origin/Camera Offset/LeftHand Controller",
                     "XR Origin/Camera Offset/RightHand Controller")


def _num(x):
    return repr(float(x))


def _vec(v, comps):
    return "{" + ", ".join(f"{c}: {_num(x)}" for c, x in zip(comps, v)) + "}"


def _key(t, v, comps, slope=0.0, pad="      "):
    s = [slope] * len(comps) if comps else slope
    val = _vec(v, comps) if comps else _num(v)
    sl = _vec(s, comps) if comps else _num(s)
    return (f"{pad}- serializedVersion: 3\n{pad}  time: {_num(t)}\n{pad}  value: {val}\n"
            f"{pad}  inSlope: {sl}\n{pad}  outSlope: {sl}\n{pad}  tangentMode: 0\n{pad}  weightedMode: 0\n")


def anim_text(objects, style="vector", compressed=False):
    """A Unity .anim: objects = {path: {"time": (N,), "pos": (N, 3), "quat": (N, 4) x y z w,
    "euler": (N, 3) degrees}} (Unity axes), as vector curves or as float curves."""
    lists = {"m_RotationCurves": [], "m_EulerCurves": [], "m_PositionCurves": [], "m_FloatCurves": []}
    for path, o in objects.items():
        for field, list_name, comps, attr in (("pos", "m_PositionCurves", "xyz", "m_LocalPosition"),
                                              ("quat", "m_RotationCurves", "xyzw", "m_LocalRotation"),
                                              ("euler", "m_EulerCurves", "xyz", "localEulerAnglesRaw")):
            if o.get(field) is None:
                continue
            t, v = o["time"] if "time" in o else o[field + "_time"], np.asarray(o[field])
            if style == "vector":
                keys = "".join(_key(t[k], v[k], comps) for k in range(len(t)))
                lists[list_name].append(f"  - curve:\n      serializedVersion: 2\n      m_Curve:\n{keys}"
                                        f"      m_PreInfinity: 2\n      m_PostInfinity: 2\n"
                                        f"      m_RotationOrder: 4\n    path: {path}\n")
            else:
                for a, c in enumerate(comps):
                    keys = "".join(_key(t[k], v[k, a], "") for k in range(len(t)))
                    lists["m_FloatCurves"].append(
                        f"  - curve:\n      serializedVersion: 2\n      m_Curve:\n{keys}"
                        f"      m_PreInfinity: 2\n      m_PostInfinity: 2\n      m_RotationOrder: 4\n"
                        f"    attribute: {attr}.{c}\n    path: {path}\n    classID: 4\n    script: {{fileID: 0}}\n")
    body = ""
    for name in ("m_RotationCurves", "m_CompressedRotationCurves", "m_EulerCurves", "m_PositionCurves",
                 "m_ScaleCurves", "m_FloatCurves"):
        items = lists.get(name, [])
        if name == "m_CompressedRotationCurves" and compressed:
            body += ("  m_CompressedRotationCurves:\n  - path: Main Camera\n    data:\n      m_NumItems: 4\n"
                     "      m_Data: 0a0b0c0d\n      m_BitSize: 8\n")
            continue
        body += f"  {name}:\n" + "".join(items) if items else f"  {name}: []\n"
    return ("%YAML 1.1\n%TAG !u! tag:unity3d.com,2011:\n--- !u!74 &7400000\nAnimationClip:\n"
            "  m_ObjectHideFlags: 0\n  m_CorrespondingSourceObject: {fileID: 0}\n  m_Name: Take 001\n"
            f"  serializedVersion: 7\n  m_Legacy: 0\n  m_Compressed: {1 if compressed else 0}\n"
            "  m_UseHighQualityCurve: 1\n" + body + "  m_PPtrCurves: []\n  m_SampleRate: 60\n  m_WrapMode: 0\n"
            "  m_Bounds:\n    m_Center: {x: 0, y: 0, z: 0}\n    m_Extent: {x: 0, y: 0, z: 0}\n"
            "  m_AnimationClipSettings:\n    serializedVersion: 2\n    m_StartTime: 0\n    m_StopTime: 2\n"
            "  m_EditorCurves: []\n  m_EulerEditorCurves: []\n  m_HasGenericRootTransform: 0\n  m_Events: []\n")


def yaw_quat(deg):
    """x y z w quaternions of rotations about Unity's +Y by ``deg``."""
    a = np.radians(deg) / 2
    return np.stack([np.zeros_like(a), np.sin(a), np.zeros_like(a), np.cos(a)], -1)


def unity_to_blender_pos(p):
    p = np.asarray(p)
    return np.stack([-p[..., 0], -p[..., 2], p[..., 1]], -1)


def unity_to_blender_quat(q):
    """x y z w (Unity) → w x y z (Blender): (w, x, z, -y)."""
    q = np.asarray(q)
    return np.stack([q[..., 3], q[..., 0], q[..., 2], -q[..., 1]], -1)


def same_quat(a, b, tol=1e-5):
    return np.all(np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1)) < tol)


def motion(n=120, rate=60.0):
    """A known motion in Unity axes: time, {path: (pos, quat xyzw)}."""
    t = np.arange(n) / rate
    head = np.stack([0.1 * np.sin(t), 1.6 + 0.02 * np.cos(3 * t), 0.05 * t], -1)
    left = head + np.stack([-0.3 + 0.1 * np.sin(2 * t), -0.4 + 0 * t, 0.2 + 0 * t], -1)
    right = head + np.stack([0.3 + 0 * t, -0.4 + 0.05 * np.cos(t), 0.2 + 0 * t], -1)
    return t, {HEAD: (head, yaw_quat(30 * t)), LEFT: (left, yaw_quat(-20 * t + 10)),
               RIGHT: (right, yaw_quat(45 + 0 * t))}


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_vector_and_float_curves_read_back_in_blender_axes(tmp_path):
    t, m = motion()
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    for style in ("vector", "float"):
        rec = formats.load_recording(write(tmp_path, f"take_{style}.anim", anim_text(objs, style)))
        assert rec.devices == ("head", "left_hand", "right_hand")
        for d, p in (("head", HEAD), ("left_hand", LEFT), ("right_hand", RIGHT)):
            s = rec.streams[d]
            assert np.allclose(s.time, t, atol=1e-12) and s.valid.all()
            assert np.abs(s.pos - unity_to_blender_pos(m[p][0])).max() < 1e-5
            assert same_quat(s.quat, unity_to_blender_quat(m[p][1]))
        assert rec.metadata["device_labels"]["head"] == "Main Camera"
        assert "unkeyed parents are not in the .anim" in rec.metadata["detected"]
        assert rec.metadata["sample_rate"] == 60.0


def test_keyed_camera_offset_and_rotated_origin_are_composed(tmp_path):
    t, m = motion()
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    tk = np.array([0.0, 1.0])
    objs["XR Origin/Camera Offset"] = {"time": tk, "pos": np.array([[0.0, 1.1, 0.0], [0.0, 1.1, 0.0]])}
    objs["XR Origin"] = {"time": tk, "quat": yaw_quat(np.array([90.0, 90.0])), "pos": [[1.0, 0, 2.0]] * 2}
    rec = formats.load_recording(write(tmp_path, "offset.anim", anim_text(objs)))
    R = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])        # +90 deg about Unity's +Y
    for d, p in (("head", HEAD), ("left_hand", LEFT)):
        world = (m[p][0] + [0, 1.1, 0]) @ R.T + [1.0, 0, 2.0]
        s = rec.streams[d]
        assert np.allclose(s.time, t)                         # the parents' keys add no samples past the device's
        assert np.abs(s.pos - unity_to_blender_pos(world)).max() < 1e-5
        yaw = {"head": 30 * t, "left_hand": -20 * t + 10}[d] + 90
        assert same_quat(s.quat, unity_to_blender_quat(yaw_quat(yaw)))
    assert "Camera Offset" in rec.metadata["detected"] and "composed" in rec.metadata["detected"]


def _quat_xyzw(axis, deg):
    a = np.radians(deg) / 2
    q = np.zeros(np.shape(deg) + (4,))
    q[..., "xyz".index(axis)] = np.sin(a)
    q[..., 3] = np.cos(a)
    return q


def _mul_xyzw(a, b):
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], -1)


def test_euler_curves_are_unitys_zxy(tmp_path):
    t, m = motion(60)
    euler = np.stack([20 * np.sin(t), 40 * t - 10, -15 + 30 * t], -1)          # degrees about x, y, z
    # Unity's Quaternion.Euler(x, y, z): z first, then x, then y (about the fixed axes)
    q = _mul_xyzw(_quat_xyzw("y", euler[:, 1]), _mul_xyzw(_quat_xyzw("x", euler[:, 0]), _quat_xyzw("z", euler[:, 2])))
    objs = {p: {"time": t, "pos": pos, "quat": qq} for p, (pos, qq) in m.items()}
    objs[HEAD] = {"time": t, "pos": m[HEAD][0], "euler": euler}
    for style in ("vector", "float"):
        rec = formats.load_recording(write(tmp_path, f"euler_{style}.anim", anim_text(objs, style)))
        assert same_quat(rec.streams["head"].quat, unity_to_blender_quat(q))


def test_hermite_between_keys_and_constant_tangents_step(tmp_path):
    t, m = motion(3, rate=2.0)                                 # keys at 0, 0.5, 1
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    text = anim_text(objs)
    # the head's rotation keyed at 0.25 s too: its position is evaluated there
    objs[HEAD] = {"pos_time": t, "pos": m[HEAD][0], "quat_time": np.array([0.0, 0.25, 0.5, 1.0]),
                  "quat": yaw_quat(np.array([0.0, 10.0, 20.0, 30.0]))}
    text = anim_text(objs)
    rec = formats.load_recording(write(tmp_path, "hermite.anim", text))
    s = rec.streams["head"]
    assert np.allclose(s.time, [0, 0.25, 0.5, 1.0])
    h = 3 * 0.5 ** 2 - 2 * 0.5 ** 3                            # zero slopes: the smoothstep halfway
    expect = m[HEAD][0][0] + h * (m[HEAD][0][1] - m[HEAD][0][0])
    assert np.abs(s.pos[1] - unity_to_blender_pos(expect)).max() < 1e-9
    stepped = text.replace("inSlope: {x: 0.0, y: 0.0, z: 0.0}", "inSlope: {x: Infinity, y: Infinity, z: Infinity}")
    rec = formats.load_recording(write(tmp_path, "step.anim", stepped))
    assert np.abs(rec.streams["head"].pos[1] - unity_to_blender_pos(m[HEAD][0][0])).max() < 1e-12


def test_controllers_keyed_over_part_of_the_clip(tmp_path):
    t, m = motion()
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    part = (t >= 0.5) & (t <= 1.5)
    objs[LEFT] = {"time": t[part], "pos": m[LEFT][0][part], "quat": m[LEFT][1][part]}
    del objs[RIGHT]
    rec = formats.load_recording(write(tmp_path, "part.anim", anim_text(objs)))
    assert np.allclose(rec.streams["left_hand"].time, t[part]) and np.allclose(rec.streams["head"].time, t)
    assert "right_hand" not in rec.streams
    assert any("no curve for right_hand" in w for w in rec.warnings)


def test_refusals_and_errors_name_the_file_and_line(tmp_path):
    t, m = motion(4)
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    with pytest.raises(RecordingError, match=r"packed\.anim, line \d+: .*compress.*Anim\. Compression: Off"):
        formats.load_recording(write(tmp_path, "packed.anim", anim_text(objs, compressed=True)))
    lines = anim_text(objs).splitlines()
    n = next(i for i, ln in enumerate(lines) if "value: {x" in ln)
    broken = lines[:n] + [lines[n].replace("value:", "value")] + lines[n + 1:]
    with pytest.raises(RecordingError, match=rf"broken\.anim, line {n + 1}: expected 'key: value'"):
        formats.load_recording(write(tmp_path, "broken.anim", "\n".join(broken)))
    n = next(i for i, ln in enumerate(lines) if "time: " in ln)
    no_time = lines[:n] + lines[n + 1:]
    with pytest.raises(RecordingError, match=rf"notime\.anim, line {n}: m_RotationCurves\[0\]: a key without time"):
        formats.load_recording(write(tmp_path, "notime.anim", "\n".join(no_time)))
    objs.pop(HEAD)
    with pytest.raises(RecordingError, match=r"nohead\.anim: no head curve.*'XR Origin/Camera Offset/LeftHand "
                                             r"Controller', 'XR Origin/Camera Offset/RightHand Controller'"):
        formats.load_recording(write(tmp_path, "nohead.anim", anim_text(objs)))


def test_registered_by_extension_and_content(tmp_path):
    t, m = motion(4)
    text = anim_text({p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()})
    assert formats.reader_for("take.ANIM").name == "unity_anim"
    renamed = write(tmp_path, "take.txt", text)
    assert formats.reader_for(renamed).name == "unity_anim"
    assert formats.is_recording_file(write(tmp_path, "a.anim", text))
    assert formats.default_offsets("a.anim") == "none"         # auto: the take's T-pose or 'Main Camera' decide


def test_a_recorded_clip_solves_end_to_end(tmp_path):
    from blender_manikin.core.solve import SolveSettings, solve_recording
    src = formats.load_recording(EXAMPLE)
    names = {"head": HEAD, "left_hand": LEFT, "right_hand": RIGHT}
    objs = {}
    for d, p in names.items():
        s = src.streams[d]
        pos, q = from_blender(s.pos, s.quat, "unity")
        objs[p] = {"time": s.time, "pos": pos, "quat": q[:, [1, 2, 3, 0]]}
    path = write(tmp_path, "example.anim", anim_text(objs))
    rec = formats.load_recording(path)
    for d in names:
        assert np.abs(rec.streams[d].pos - src.streams[d].pos).max() < 1e-9
    out = solve_recording(str(path), SolveSettings(fps=30.0))
    ref = solve_recording(EXAMPLE, SolveSettings(fps=30.0))
    assert out.result.num_frames == ref.result.num_frames
    assert np.abs(out.result.positions - ref.result.positions).max() < 1e-3


def test_clips_of_no_tracked_object_are_refused_saying_what_they_animate(tmp_path):
    """Clips that are not recordings of tracked objects, as found in public Unity projects: one
    moving its own root object (``path:`` left empty, as Unity 6 writes it beside a script's
    curve, ``- serializedVersion: 2`` before ``curve:``), a humanoid clip (Animator muscle
    curves) and an empty clip.  Each is refused naming what it animates.  Before: "the clip
    animates ''" for the root and "the clip animates none" for the other two."""
    t, m = motion(4)
    root = anim_text({"": {"time": t, "pos": m[HEAD][0]}})
    root = root.replace("  m_FloatCurves: []\n", "  m_FloatCurves:\n  - serializedVersion: 2\n    curve:\n"
                        "      serializedVersion: 2\n      m_Curve:\n      - serializedVersion: 3\n        time: 0\n"
                        "        value: 2500\n        inSlope: 0\n        outSlope: 0\n      m_PreInfinity: 2\n"
                        "      m_PostInfinity: 2\n      m_RotationOrder: 4\n    attribute: K_Value\n"
                        "    path: MetalCube\n    classID: 114\n    script: {fileID: 11500000}\n    flags: 0\n")
    with pytest.raises(RecordingError, match=r"crush\.anim: no head curve.*; the clip animates the root object "
                                             r"\(path ''\)$"):
        formats.load_recording(write(tmp_path, "crush.anim", root))
    muscles = "".join(f"  - curve:\n      serializedVersion: 2\n      m_Curve:\n      - time: 0\n        value: 0\n"
                      f"      m_PreInfinity: 2\n    attribute: {a}\n    path: \n    classID: 95\n"
                      f"    script: {{fileID: 0}}\n" for a in ("RootT.x", "RootT.y", "RootT.z", "RootQ.x",
                                                                  "Left Arm Down-Up", "Neck Nod Down-Up"))
    humanoid = anim_text({}).replace("  m_FloatCurves: []\n", "  m_FloatCurves:\n" + muscles)
    with pytest.raises(RecordingError, match=r"walk\.anim: no head curve.*the clip animates no Transform, only "
                                             r"Animator 'RootT\.x', .* and 2 more \(a humanoid clip's muscle curves"):
        formats.load_recording(write(tmp_path, "walk.anim", humanoid))
    with pytest.raises(RecordingError, match=r"empty\.anim: no head curve.*; the clip has no curve$"):
        formats.load_recording(write(tmp_path, "empty.anim", anim_text({})))


def test_rig_names_pick_their_devices(tmp_path):
    """Meta's OVRCameraRig anchors, XR Interaction Toolkit 2.x controllers and body trackers
    named with a ``Tracker`` word ("Hip Tracker", "Pelvis Tracker", as the README's
    Waist / Hip / Pelvis trackers).  Before: "Hip Tracker" and "Pelvis Tracker" were no device
    (left out) while "Waist Tracker" and "Left Foot Tracker" were read."""
    t, m = motion()
    head, left, right = (m[p] for p in (HEAD, LEFT, RIGHT))
    for names in (("OVRCameraRig/TrackingSpace/CenterEyeAnchor", "OVRCameraRig/TrackingSpace/LeftHandAnchor",
                   "OVRCameraRig/TrackingSpace/RightHandAnchor", "OVRCameraRig/TrackingSpace/Hip Tracker"),
                  ("XR Origin (XR Rig)/Camera Offset/Main Camera", "XR Origin (XR Rig)/Camera Offset/Left Controller",
                   "XR Origin (XR Rig)/Camera Offset/Right Controller", "XR Origin (XR Rig)/Pelvis Tracker")):
        objs = {n: {"time": t, "pos": pos, "quat": q}
                for n, (pos, q) in zip(names, (head, left, right, (head[0] - [0, 0.7, 0], head[1])))}
        rec = formats.load_recording(write(tmp_path, "rig.anim", anim_text(objs)))
        assert rec.devices == ("head", "left_hand", "right_hand", "pelvis"), (names, rec.devices)
        assert rec.metadata["device_paths"] == dict(zip(rec.devices, names))
        assert np.abs(rec.streams["left_hand"].pos - unity_to_blender_pos(left[0])).max() < 1e-5


def _key_lists(docs):
    """Every curve's ``m_Curve`` node of a parsed clip, in the file's order."""
    clip = docs[0][2]["AnimationClip"]
    return [item["curve"]["m_Curve"] for name in ("m_RotationCurves", "m_EulerCurves", "m_PositionCurves",
                                                   "m_FloatCurves") for item in clip.get(name) or ()]


def _curve_arrays(text):
    """Each curve's arrays as read with the fast key path and by the general parser alone, and the
    number of key lists the fast path read."""
    from blender_manikin.core import io_unity_anim as u
    out = []
    for fast in (True, False):
        docs = u.parse_unity_yaml(text, "clip.anim", fast=fast)
        found, orders = u._collect(docs[0][2]["AnimationClip"], "clip.anim")
        out.append(({(o, ch, c, f): getattr(cv, f) for o, chans in found.items() for ch, comps in chans.items()
                     for c, cv in comps.items() for f in ("time", "value", "in_slope", "out_slope")}, orders,
                    sum(isinstance(k, u._KeyBlock) for k in _key_lists(docs)), _lines(docs)))
    return out


def _lines(docs):
    """The lines of the clip's curve lists, curves and key lists, with their paths."""
    clip = docs[0][2]["AnimationClip"]
    return [(name, clip[name].line if clip.get(name) else None) + tuple(
        (item.line, item["curve"].line, item["curve"]["m_Curve"].line, item.get("path"), item.get("attribute"))
        for item in clip.get(name) or ()) for name in ("m_RotationCurves", "m_EulerCurves", "m_PositionCurves",
                                                       "m_FloatCurves", "m_PPtrCurves", "m_Events")]


def _assert_same(fast, general):
    assert fast[0].keys() == general[0].keys() and fast[1] == general[1] and fast[3] == general[3]
    for k, a in fast[0].items():
        b = general[0][k]
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), k   # bit for bit


def test_fast_key_reader_is_the_general_parser_bit_for_bit(tmp_path, monkeypatch):
    """The fast path (one regular expression over each ``m_Curve:`` key list in Unity's form, its
    numbers converted at once) gives every curve's times, values and slopes bit for bit as the
    general parser, for vector and float curves with ``Infinity`` / ``-Infinity`` tangents, exponent
    numbers, ``inWeight`` / ``outWeight`` lines and Windows line ends; and the whole recording alike.
    Before: ``parse_unity_yaml`` had no fast path (its general parser took 5-7x as long)."""
    from blender_manikin.core import io_unity_anim as u
    t, m = motion(200, rate=90.0)
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    objs[HEAD]["pos"] = objs[HEAD]["pos"] * [1e-7, 1.0, -3e-9]                  # 1.1e-09, -1.4e-10 ...
    for style, sl, w in (("vector", "{x: 0.0, y: 0.0, z: 0.0}", "{x: 0.33333334, y: 0.33333334, z: 0.33333334}"),
                         ("float", "0.0", "0.33333334")):
        text = anim_text(objs, style)
        text = text.replace(f"inSlope: {sl}", f"inSlope: {sl.replace('0.0', 'Infinity')}", 7)
        text = text.replace(f"outSlope: {sl}", f"outSlope: {sl.replace('0.0', '-Infinity')}", 3)
        text = text.replace(f"outSlope: {sl}", f"outSlope: {sl.replace('0.0', '-2.5e-08')}", 4)
        assert re.search(r"value: [^\n]*\de-\d", text) and "Infinity" in text and "e-08" in text
        curves = text.count("m_Curve:")
        weighted = text.replace("weightedMode: 0\n", f"weightedMode: 0\n        inWeight: {w}\n"
                                                      f"        outWeight: {w}\n")
        for variant in (text, weighted, text.replace("\n", "\r\n")):
            fast, general = _curve_arrays(variant)
            assert fast[2] == curves and general[2] == 0                          # every list read fast
            _assert_same(fast, general)
        path = write(tmp_path, f"fast_{style}.anim", text)
        rec = formats.load_recording(path)
        general = u.parse_unity_yaml
        monkeypatch.setattr(u, "parse_unity_yaml", lambda text, path: general(text, path, fast=False))
        ref = formats.load_recording(path)
        monkeypatch.undo()
        assert rec.devices == ref.devices and rec.metadata["detected"] == ref.metadata["detected"]
        for d in rec.devices:
            for f in ("time", "pos", "quat", "valid"):
                assert getattr(rec.streams[d], f).tobytes() == getattr(ref.streams[d], f).tobytes(), (style, d, f)


def test_key_lists_in_another_form_are_left_to_the_general_parser(tmp_path):
    """A key list the fast path does not fully match is read by the general parser, counted by its
    node (a list of mappings, not a block of numbers), with the same results; the others stay fast.
    A list that is fast but not of its curve list's form (an x, y, z rotation) is read again by the
    general parser, which names the key's line; a file with an error gives the general parser's."""
    from blender_manikin.core import io_unity_anim as u
    t, m = motion(6)
    objs = {p: {"time": t, "pos": pos, "quat": q} for p, (pos, q) in m.items()}
    text = anim_text(objs)
    curves = text.count("m_Curve:")
    first = "      - serializedVersion: 3\n        time: 0.016666666666666666\n"     # the head's rotation, key 2
    assert text.count(first) == curves
    odd = {"comment": first + "        # a comment\n",
           "blank line": first + "\n",
           "blank line between keys": "\n" + first,
           "comment between keys": "      # a comment\n" + first,
           "order": first.replace("serializedVersion: 3\n        time:", "time:") + "        serializedVersion: 3\n",
           "extra field": first + "        m_Extra: 1\n",
           "number form": None, "underscore": None, "deeper": None, "tab": None}
    for why, new in odd.items():
        if why == "number form":
            odd_text = text.replace("value: {x: 0.0, y: 0.0", "value: {x: +0.0, y: 0.0", 1)
        elif why == "underscore":
            odd_text = text.replace("time: 0.016666666666666666", "time: 1_0", 1)
        elif why == "deeper":
            head, _, rest = text.partition("      m_Curve:\n")
            keys, sep, tail = rest.partition("      m_PreInfinity")
            odd_text = head + "      m_Curve:\n" + keys.replace("\n      ", "\n        ").replace(
                "      - ", "        - ", 1) + sep + tail
        elif why == "tab":
            odd_text = text.replace("inSlope: {x: 0.0, y: 0.0, z: 0.0}\n", "inSlope: {x: 0.0, y: 0.0, z: 0.0}\t\n", 1)
        else:
            odd_text = text.replace(first, new, 1)
        assert odd_text != text, why
        fast, general = _curve_arrays(odd_text)
        assert fast[2] == curves - 1 and general[2] == 0, why                  # that one list fell back
        _assert_same(fast, general)
    # a head's rotation written x, y, z: fast, then read again in full, naming the key as before
    no_w = re.sub(r", w: [^}]*\}", "}", text)
    docs = u.parse_unity_yaml(no_w, "clip.anim")
    assert all(isinstance(k, u._KeyBlock) for k in _key_lists(docs))
    lines = text.splitlines()
    n = next(i for i, ln in enumerate(lines) if "- serializedVersion: 3" in ln)      # the key's first line
    with pytest.raises(RecordingError, match=rf"now\.anim, line {n + 1}: m_RotationCurves\[0\]: value .* has no w"):
        formats.load_recording(write(tmp_path, "now.anim", no_w))
    # an infinite key time: the general parser's error and line
    with pytest.raises(RecordingError, match=rf"inf\.anim, line {n + 1}: m_RotationCurves\[0\]: key time "
                                             r"'Infinity' is not finite"):
        formats.load_recording(write(tmp_path, "inf.anim", text.replace("time: 0.0\n", "time: Infinity\n", 1)))
