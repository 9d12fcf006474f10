"""Helpers for the Blender tests (tests/test_blender_*.py): a fresh scene and synthetic solves."""
import os
import re
import shutil
import subprocess
import sys

import numpy as np

from blender_manikin.core import limb_solver as ls
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core.pose_result import PoseResult, TrackerTargets


def fresh_scene():
    """Empty factory scene (no objects), 24 fps unless changed."""
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def smooth_local_rotations(T, seed=0, spread=0.6):
    """``(T, 22, 3, 3)`` smooth random local rotations; elbows/knees are hinges about ``ls.H0``."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, T)[:, None, None]
    freq = rng.uniform(0.5, 2.0, size=(1, sk.NUM_JOINTS, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(1, sk.NUM_JOINTS, 3))
    aa = spread * np.sin(2 * np.pi * freq * t + phase)
    local = rot.axis_angle_to_matrix(aa)
    for li, (_, b, m, e) in enumerate(sk.LIMBS):
        flex = 0.2 + 0.8 * (1 + np.sin(2 * np.pi * (li + 1) * t[:, 0, 0]))
        local[:, m] = rot.axis_angle_rotation(ls.H0[li], flex)
    # whole-body turn of more than pi over the clip: exercises quaternion sign continuity
    yaw = np.linspace(0.0, 1.5 * np.pi, T)
    local[:, 0] = rot.axis_angle_rotation(np.array([0.0, 0, 1]), yaw) @ local[:, 0]
    return local


def synthetic_result(T=40, fps=24.0, seed=0, stature=1.8, with_targets=True):
    """A :class:`PoseResult` with smooth motion, swivel angles crossing ±pi, and tracker targets."""
    body = sk.make_body(stature)
    local = smooth_local_rotations(T, seed)
    t = np.arange(T) / fps
    root = body.root_rest + np.stack([0.3 * np.sin(t), 0.5 * t, 0.05 * np.sin(3 * t)], -1)
    swivel = np.stack([np.angle(np.exp(1j * (3.0 + 2.0 * t))), np.sin(t), -0.3 * t, 0.1 * np.ones(T)], -1)
    res = PoseResult(fps=fps, body=body, local_rot=local, root_pos=root, swivel=swivel,
                     contacts=np.zeros((T, 2), bool), t0=12.5)
    if with_targets:
        pos, wr = res.fk()
        devs = {"head": "head", "left_hand": "left_wrist", "right_hand": "right_wrist"}
        res.targets = TrackerTargets(
            fps=fps, pos={d: pos[:, sk.J[j]].copy() for d, j in devs.items()},
            rot={d: wr[:, sk.J[j]].copy() for d, j in devs.items()},
            valid={d: np.ones(T, bool) for d in devs})
    return res


def evaluated_heads(obj, frames):
    """World positions ``(len(frames), 22, 3)`` of every bone head after ``scene.frame_set``."""
    import bpy
    scene = bpy.context.scene
    out = np.empty((len(frames), sk.NUM_JOINTS, 3))
    rots = np.empty((len(frames), sk.NUM_JOINTS, 3, 3))
    for k, f in enumerate(frames):
        scene.frame_set(int(f))
        mw = np.array(obj.matrix_world)
        for j, name in enumerate(sk.JOINT_NAMES):
            pb = obj.pose.bones[name]
            m = mw @ np.array(pb.matrix)
            out[k, j] = m[:3, 3]
            rots[k, j] = m[:3, :3]
    return out, rots


def write_recording_csv(path, res, axes="openxr", jitter=0.0, seed=0, rates=None):
    """Write ``res.targets`` (joint poses, offsets ``none``) as a native CSV recording.

    Each device is sampled at its own rate (``rates``: device -> Hz, default
    the result's fps) from the result's FK (linear interpolation of positions,
    nearest rotation), with optional timestamp jitter (seconds std).
    """
    from blender_manikin.core import rotations as rot
    from blender_manikin.core.io_csv import write_csv
    from blender_manikin.core.recording import TrackerStream
    rng = np.random.default_rng(seed)
    T = res.num_frames
    t_grid = res.t0 + np.arange(T) / res.fps
    streams = []
    for dev in res.targets.devices:
        rate = (rates or {}).get(dev, res.fps)
        n = int(np.floor((T - 1) / res.fps * rate)) + 1
        t = res.t0 + np.arange(n) / rate
        if jitter:
            t = t + rng.normal(scale=jitter, size=n)
            t[0] = t_grid[0]
            t = np.maximum.accumulate(t) + np.arange(n) * 1e-7
            t[-1] = t_grid[-1]
            t[:-1] = np.minimum(t[:-1], t_grid[-1] - 1e-4)
        p = np.stack([np.interp(t, t_grid, res.targets.pos[dev][:, i]) for i in range(3)], -1)
        k = np.clip(np.round((t - res.t0) * res.fps).astype(int), 0, T - 1)
        q = rot.matrix_to_quat(res.targets.rot[dev][k])
        streams.append(TrackerStream(dev, t, p, q))
    write_csv(path, streams, axes=axes, precision=9)
    return path


def stub_solver(targets, body, progress=None):
    """Stand-in for ``pipeline.solve`` (no network): straight T-pose carried by the head target,
    local rotations identity except a slow spine bend, swivel from time."""
    from blender_manikin.core import rotations as rot
    T = targets.num_frames
    if progress is not None:
        progress(0.5)
    local = np.broadcast_to(np.eye(3), (T, sk.NUM_JOINTS, 3, 3)).copy()
    local[:, sk.J["spine2"]] = rot.axis_angle_rotation(
        np.tile([1.0, 0.0, 0.0], (T, 1)), np.linspace(0, 0.5, T))
    rest = body.rest_positions()
    pos0, _ = sk.forward_kinematics(local, np.zeros((T, 3)), body)
    root = targets.pos["head"] - pos0[:, sk.J["head"]]
    res = PoseResult(fps=float(targets.fps), body=body, local_rot=local, root_pos=root,
                     swivel=np.tile(np.linspace(-1, 1, T)[:, None], (1, 4)),
                     contacts=np.zeros((T, 2), bool), targets=targets)
    if progress is not None:
        progress(1.0)
    assert rest.shape == (22, 3)
    return res


# A real Blender binary: CI's Debian 13 job has Debian's blender 4.3 and sets
# BLENDER_MANIKIN_REQUIRE_BLENDER_BINARY=1, so there a missing or too old binary fails the tests
# instead of skipping them.
REQUIRE_BLENDER_BINARY = os.environ.get("BLENDER_MANIKIN_REQUIRE_BLENDER_BINARY", "") not in ("", "0")
BLENDER_BINARY_MIN = (4, 2)
# What a Blender binary itself prints on stdout around a script's output.
BLENDER_BANNER = re.compile(r"^(Blender \d+\.\d+(\.\d+)?( .*)?|Blender quit|)$")


def blender_binary_env(**extra):
    """The environment for a ``blender`` subprocess: this one without what the bpy module set for
    itself (``import bpy`` points ``OCIO`` at its own colour config, which another Blender version
    cannot load)."""
    env = {k: v for k, v in os.environ.items() if k not in ("OCIO", "PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = binary_path()
    env.update(extra)
    return env


def binary_path():
    """``$PATH`` without the virtual environment running the tests: a Blender binary picks the
    site-packages of the first ``python3`` on PATH, and must see its own, not the test venv's
    bpy, numpy and onnxruntime."""
    entries = os.environ.get("PATH", "/usr/bin:/bin").split(os.pathsep)
    if sys.prefix != sys.base_prefix:
        venv = os.path.realpath(sys.prefix)
        entries = [e for e in entries if not os.path.realpath(e).startswith(venv + os.sep)]
    return os.pathsep.join(entries)


def blender_binary():
    """``(path, (major, minor))`` of a ``blender`` >= 4.2 on PATH; skips the test when there is none
    (fails instead where CI requires one)."""
    import pytest
    path = shutil.which("blender")
    why = "no blender binary on PATH"
    if path is not None:
        out = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=120).stdout
        m = re.search(r"Blender (\d+)\.(\d+)", out)
        version = (int(m.group(1)), int(m.group(2))) if m else (0, 0)
        if version >= BLENDER_BINARY_MIN:
            return path, version
        why = f"{path} is Blender {version[0]}.{version[1]}, older than 4.2"
    if REQUIRE_BLENDER_BINARY:
        pytest.fail(f"{why} (BLENDER_MANIKIN_REQUIRE_BLENDER_BINARY is set)")
    pytest.skip(why)


def mixamo_style_character(name="Character", stature=1.62, arm_down_deg=45.0, seed=3, fbx_cm=False,
                           arm_scale=1.0):
    """A Mixamo-named armature (for the retarget tests and tools/render_retarget_figure.py): the
    body model's joints at ``stature`` metres, arms ``arm_scale`` times as long and turned
    ``arm_down_deg`` down (an A-pose rest), every bone rolled by a random angle.  fbx_cm: as an
    FBX in centimetres lands in Blender (bones in a +Y-up frame, x100; the object turned 90°
    about X and scaled 0.01), the character facing +Y.  Returns the object."""
    import bpy
    from blender_manikin.core import bone_maps
    bmap = bone_maps.preset("mixamo")
    body = sk.make_body(stature)
    P = body.rest_positions()
    for side, sx in (("left", 1.0), ("right", -1.0)):           # the A-pose: arms turned down
        s = P[sk.J[f"{side}_shoulder"]].copy()
        R = rot.axis_angle_rotation(np.array([0.0, 1.0, 0.0]), np.radians(sx * arm_down_deg))
        for j in ("elbow", "wrist"):
            P[sk.J[f"{side}_{j}"]] = s + arm_scale * (R @ (P[sk.J[f"{side}_{j}"]] - s))
    if fbx_cm:     # face +Y (turned 180° about Z), then into the file's +Y-up centimetres
        P = P * np.array([-1.0, -1.0, 1.0])
        P = np.stack([P[:, 0], P[:, 2], -P[:, 1]], -1) * 100.0
    rng = np.random.default_rng(seed)
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')
    eb = arm.edit_bones
    made = {}
    for j in range(sk.NUM_JOINTS):                               # parents first (SMPL order)
        joint = sk.JOINT_NAMES[j]
        b = eb.new(bmap.bones[joint])
        b.head = P[j]
        kids = [c for c in sk.CHILDREN[j] if sk.JOINT_NAMES[c] in bmap.bones]
        if len(kids) == 1 or joint in ("pelvis", "spine3"):
            c = kids[0] if len(kids) == 1 else sk.J["spine1" if joint == "pelvis" else "neck"]
            b.tail = P[c]
        else:                                                    # end bones: along the parent's direction
            p = sk.PARENTS[j]
            d = (P[j] - P[p]) / np.linalg.norm(P[j] - P[p])
            b.tail = P[j] + 0.08 * d * (100.0 if fbx_cm else 1.0)
        b.roll = float(rng.uniform(-np.pi, np.pi))
        if j:
            b.parent = made[sk.PARENTS[j]]
        made[j] = b
    bpy.ops.object.mode_set(mode='OBJECT')
    if fbx_cm:
        obj.rotation_euler = (np.pi / 2, 0.0, 0.0)
        obj.scale = (0.01, 0.01, 0.01)
        bpy.context.view_layer.update()
    return obj
