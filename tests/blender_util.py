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


def modal_operator(cls, **props):
    """An instance standing in for a registered solve operator ``cls`` (Blender makes those), to
    drive its ``modal()`` in background mode: it has the operator's methods, ``props`` as
    attributes (``files``, ``directory``, ...) and collects ``report()`` calls in ``reports``.
    ``start_modal()`` does what ``_run_modal`` does less the window's timer and handler (there is
    no window in background mode) and returns the :class:`SolveQueue`."""
    from blender_manikin.operators import solve as solve_op

    class ModalOperator:
        def __init__(self):
            self._timer, self.reports = None, []
            for k, v in props.items():
                setattr(self, k, v)

        def report(self, kind, msg):
            self.reports.append((kind, msg))

        def start_modal(self):
            import bpy
            self._queue = self._make_queue(bpy.context, self._configs(bpy.context))
            self._scene = bpy.context.scene
            assert self._queue.start(bpy.context)
            solve_op._ACTIVE["job"] = self._queue
            return self._queue

    for name in ("_make_queue", "_status", "_cleanup", "modal", "cancel", "_configs", "_queue_done",
                 "_queue_failed", "_queue_finish"):
        setattr(ModalOperator, name, getattr(cls, name))
    return ModalOperator()


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


def humanoid_joints(stature=1.62, arm_down_deg=45.0, arm_scale=1.0, leg_scale=1.0, torso_scale=1.0,
                    thigh_shank=(1.0, 1.0)):
    """``(22, 3)`` rest joint positions of a test character, metres, +Z up, facing -Y: the body
    model at ``stature`` with the torso (pelvis to spine, neck, head, collars, shoulders and hips),
    the arms (elbows, wrists) and the legs (knees, ankles, balls of the feet) ``torso_scale``,
    ``arm_scale`` and ``leg_scale`` times as long, the arms turned ``arm_down_deg`` down about the
    shoulders (an A-pose rest) and the feet on the floor.

    Within each region every segment has the same ratio to the performer's, so a retarget's
    proportion scaling is predictable: a hand lands on ``pelvis + torso * (shoulder - pelvis) +
    arm * (wrist - shoulder)`` of a performer of the same stature, and so on -- unless
    ``thigh_shank`` scales the thighs and shanks further (legs of other proportions)."""
    body = sk.make_body(stature)
    scale = np.full(sk.NUM_JOINTS, float(torso_scale))
    for side in ("left", "right"):
        for j in ("elbow", "wrist"):
            scale[sk.J[f"{side}_{j}"]] = arm_scale
        for j, f in (("knee", thigh_shank[0]), ("ankle", thigh_shank[1]), ("foot", 1.0)):
            scale[sk.J[f"{side}_{j}"]] = leg_scale * f
    rest = body.rest_positions()
    P = np.zeros((sk.NUM_JOINTS, 3))
    P[0] = body.root_rest
    for j in range(1, sk.NUM_JOINTS):
        P[j] = P[sk.PARENTS[j]] + scale[j] * body.offsets[j]
    for side, sx in (("left", 1.0), ("right", -1.0)):           # the A-pose: arms turned down
        s = P[sk.J[f"{side}_shoulder"]].copy()
        R = rot.axis_angle_rotation(np.array([0.0, 1.0, 0.0]), np.radians(sx * arm_down_deg))
        for j in ("elbow", "wrist"):
            P[sk.J[f"{side}_{j}"]] = s + R @ (P[sk.J[f"{side}_{j}"]] - s)
    foot = sk.J["left_foot"]
    P[:, 2] += leg_scale * rest[foot, 2] - P[foot, 2]           # balls of the feet on the floor
    return P


def humanoid_bones(P, names, twist=None, root=None, end_length=0.08):
    """Bones ``[(name, parent, head (3,), tail (3,))]`` (parents first, metres, the frame of ``P``)
    of a character whose joints are ``P`` ``(22, 3)``.

    names: joint -> bone name, or a list of names: a chain of bones splitting the segment from the
    joint to the next joint of its chain evenly (e.g. UE5's ``spine_01``, ``spine_02`` for
    ``spine1``); the next chain's bone is parented to the last of them.  Joints not in ``names``
    have no bone.  Bones reach to the head of the next bone down their chain; end bones (head,
    hands, toes) go ``end_length`` metres on along their parent segment.  twist: joint ->
    ``[(name, fraction)]``, leaf bones under the joint's bone starting ``fraction`` of the way
    along its segment.  root: name of a bone at the origin, above the pelvis bone."""
    P = np.asarray(P, np.float64)
    out = []
    if root is not None:
        out.append((root, None, np.zeros(3), np.array([0.0, 0.1, 0.0])))
    last = {}
    for j in range(sk.NUM_JOINTS):                               # parents first (SMPL order)
        joint = sk.JOINT_NAMES[j]
        if joint not in names:
            continue
        chain = names[joint] if isinstance(names[joint], (list, tuple)) else [names[joint]]
        kids = [c for c in sk.CHILDREN[j] if sk.JOINT_NAMES[c] in names]
        if len(kids) == 1 or joint in ("pelvis", "spine3"):
            c = kids[0] if len(kids) == 1 else sk.J["spine1" if joint == "pelvis" else "neck"]
            end = P[c]
        else:                                                    # end bones: along the parent's direction
            p = sk.PARENTS[j]
            d = (P[j] - P[p]) / np.linalg.norm(P[j] - P[p])
            end = P[j] + end_length * d
        n = len(chain)
        parent = last.get(sk.PARENTS[j], root) if j else root
        for i, b in enumerate(chain):
            out.append((b, parent, P[j] + (end - P[j]) * i / n, P[j] + (end - P[j]) * (i + 1) / n))
            parent = b
        last[j] = chain[-1]
        for tb, f in (twist or {}).get(joint, ()):
            h = P[j] + f * (end - P[j])
            out.append((tb, chain[0], h, h + 0.25 * (end - P[j])))
    return out


def build_armature(name, bones, seed=3, facing="-Y", units=1.0, y_up=False, yaw_deg=0.0, location=(0.0, 0.0, 0.0)):
    """An armature object ``name`` with ``bones`` ``[(name, parent, head, tail)]`` (metres, +Z up,
    the character facing -Y, parents first), every bone rolled by a random angle (``seed``).

    As the character lands in Blender from elsewhere: facing="+Y" turns it half-way round;
    ``units`` (100 for centimetres) stores the bones that many times larger with the object scaled
    ``1 / units``; ``y_up`` stores them in a +Y-up frame with the object turned 90° about X (an
    FBX import); ``yaw_deg`` turns the object about Z and ``location`` moves it.  Returns it."""
    import bpy
    M = np.eye(3)
    if facing == "+Y":
        M = np.diag([-1.0, -1.0, 1.0])
    elif facing != "-Y":
        raise ValueError(f"facing must be '-Y' or '+Y', got {facing!r}")
    if y_up:
        M = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]) @ M

    def data(p):
        return (M @ np.asarray(p, np.float64)) * units
    rng = np.random.default_rng(seed)
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')
    eb = arm.edit_bones
    for bname, parent, head, tail in bones:
        b = eb.new(bname)
        b.head = data(head)
        b.tail = data(tail)
        b.roll = float(rng.uniform(-np.pi, np.pi))
        if parent is not None:
            b.parent = eb[parent]
    bpy.ops.object.mode_set(mode='OBJECT')
    obj.rotation_euler = (np.pi / 2 if y_up else 0.0, 0.0, np.radians(yaw_deg))
    obj.scale = (1.0 / units,) * 3
    obj.location = location
    bpy.context.view_layer.update()
    return obj


def rigify_character():
    """A rig generated by Blender's bundled Rigify from its human metarig (the metarig and Rigify's
    widget objects removed), in Object Mode: a real production rig (DEF-/ORG-/MCH- bones, controls)
    for the retarget benchmark and figure."""
    import addon_utils
    import bpy
    addon_utils.enable("rigify", default_set=True, persistent=True)
    bpy.ops.object.armature_human_metarig_add()
    meta = bpy.context.active_object
    bpy.ops.pose.rigify_generate()
    rig = bpy.context.active_object
    bpy.data.objects.remove(meta)
    for o in list(bpy.data.objects):
        if o.name.startswith("WGT-"):
            bpy.data.objects.remove(o)
    bpy.ops.object.mode_set(mode='OBJECT')
    return rig


def mixamo_style_character(name="Character", stature=1.62, arm_down_deg=45.0, seed=3, fbx_cm=False,
                           arm_scale=1.0):
    """A Mixamo-named armature (for the retarget tests and tools/render_retarget_figure.py): the
    body model's joints at ``stature`` metres, arms ``arm_scale`` times as long and turned
    ``arm_down_deg`` down (an A-pose rest), every bone rolled by a random angle.  fbx_cm: as an
    FBX in centimetres lands in Blender (bones in a +Y-up frame, x100; the object turned 90°
    about X and scaled 0.01), the character facing +Y.  Returns the object."""
    from blender_manikin.core import bone_maps
    P = humanoid_joints(stature, arm_down_deg, arm_scale)
    bones = humanoid_bones(P, bone_maps.preset("mixamo").bones)
    if fbx_cm:
        return build_armature(name, bones, seed, facing="+Y", units=100.0, y_up=True)
    return build_armature(name, bones, seed)


def _sided_names(center, limbs, fmt):
    """joint -> bone name: ``center`` as is, ``limbs`` (part -> stem) on both sides by ``fmt(stem, side)``."""
    out = dict(center)
    for side in ("left", "right"):
        for part, stem in limbs.items():
            out[f"{side}_{part}"] = fmt(stem, side)
    return out


def _ue_names(version):
    center = {"pelvis": "pelvis", "spine1": "spine_01", "spine2": "spine_02", "spine3": "spine_03",
              "neck": "neck_01", "head": "head"}
    if version == 5:                    # five spine bones and two neck bones
        center.update(spine1=["spine_01", "spine_02"], spine2=["spine_03", "spine_04"], spine3="spine_05",
                      neck=["neck_01", "neck_02"])
    limbs = {"collar": "clavicle", "shoulder": "upperarm", "elbow": "lowerarm", "wrist": "hand", "hip": "thigh",
             "knee": "calf", "ankle": "foot", "foot": "ball"}
    return _sided_names(center, limbs, lambda s, side: f"{s}_{side[0]}")


# Characters as each tool names and stands them (bone names written out here, not taken from the
# presets, so a wrong preset name fails).  stature (metres) and the torso / arm / leg scales give
# each other proportions than the performer's; the rest is how the character lands in Blender.
RIG_STYLES = {
    # Unreal Mannequin (UE4): an FBX exported Z-up in centimetres -- object scale 0.01, facing +Y
    "ue4": dict(names=_ue_names(4), root="root", stature=1.83, torso=0.95, arm=1.06, leg=1.0, arm_down=40.0,
                twist={"shoulder": [("upperarm_twist_01", 0.25)], "elbow": [("lowerarm_twist_01", 0.75)],
                       "hip": [("thigh_twist_01", 0.3)], "knee": [("calf_twist_01", 0.5)]},
                facing="+Y", units=100.0, y_up=False),
    # UE5 Manny: two twist bones per segment (the lower arm's and calf's _01 next to the wrist /
    # ankle), an FBX in centimetres and +Y up as Blender imports it (object 90° about X, 0.01)
    "ue5": dict(names=_ue_names(5), root="root", stature=1.78, torso=0.97, arm=1.0, leg=1.05, arm_down=45.0,
                twist={"shoulder": [("upperarm_twist_01", 0.25), ("upperarm_twist_02", 0.6)],
                       "elbow": [("lowerarm_twist_02", 0.35), ("lowerarm_twist_01", 0.75)],
                       "hip": [("thigh_twist_01", 0.25), ("thigh_twist_02", 0.6)],
                       "knee": [("calf_twist_02", 0.35), ("calf_twist_01", 0.7)]},
                facing="+Y", units=100.0, y_up=True),
    # VRoid / VRM 0.x as the VRM add-on imports it: metres, +Z up, facing -Y; placed off the origin
    "vrm": dict(names=_sided_names(
        {"pelvis": "J_Bip_C_Hips", "spine1": "J_Bip_C_Spine", "spine2": "J_Bip_C_Chest",
         "spine3": "J_Bip_C_UpperChest", "neck": "J_Bip_C_Neck", "head": "J_Bip_C_Head"},
        {"collar": "Shoulder", "shoulder": "UpperArm", "elbow": "LowerArm", "wrist": "Hand", "hip": "UpperLeg",
         "knee": "LowerLeg", "ankle": "Foot", "foot": "ToeBase"},
        lambda s, side: f"J_Bip_{side[0].upper()}_{s}"), root="Root", stature=1.45, torso=1.1, arm=0.95, leg=0.92,
        arm_down=35.0, twist={}, facing="-Y", units=1.0, y_up=False, location=(0.6, 1.2, 0.0)),
    # Auto-Rig Pro's deforming bones as its export writes them with twist bones: root.x is the
    # hips bone; each limb segment split in two along its length (``twist_in_chain``), the upper
    # arm into c_arm_twist_offset > arm_stretch, the thigh into thigh_twist > thigh_stretch, the
    # forearm into forearm_stretch > forearm_twist, the shin into leg_stretch > leg_twist; a
    # Blender rig, the object turned 30° about Z and moved
    "auto_rig_pro": dict(names=_sided_names(
        {"pelvis": "root.x", "spine1": "spine_01.x", "spine2": "spine_02.x", "spine3": "spine_03.x",
         "neck": "neck.x", "head": "head.x"},
        {"collar": "shoulder", "shoulder": ["c_arm_twist_offset", "arm_stretch"],
         "elbow": ["forearm_stretch", "forearm_twist"], "wrist": "hand", "hip": ["thigh_twist", "thigh_stretch"],
         "knee": ["leg_stretch", "leg_twist"], "ankle": "foot", "foot": "toes_01"},
        lambda s, side: [f"{x}.{side[0]}" for x in s] if isinstance(s, list) else f"{s}.{side[0]}"),
        root="c_traj", stature=1.70, torso=1.03, arm=1.08, leg=0.97, arm_down=50.0, twist={}, facing="-Y",
        units=1.0, y_up=False, yaw_deg=30.0, location=(1.5, -0.5, 0.0),
        twist_in_chain=("shoulder", "elbow", "hip", "knee")),
    # Character Creator 3/4 as an FBX in centimetres lands (+Y up, object 90° about X, 0.01): two
    # neck bones, CC_Base_Pelvis between the hips bone and the thighs (``hips_parent``), two twist
    # bones per limb segment as CC makes them (``twist_chain``: Twist01 under the segment's bone at
    # its head, Twist02 under Twist01 half-way along)
    "cc4": dict(names=_sided_names(
        {"pelvis": "CC_Base_Hip", "spine1": "CC_Base_Waist", "spine2": "CC_Base_Spine01",
         "spine3": "CC_Base_Spine02", "neck": ["CC_Base_NeckTwist01", "CC_Base_NeckTwist02"], "head": "CC_Base_Head"},
        {"collar": "Clavicle", "shoulder": "Upperarm", "elbow": "Forearm", "wrist": "Hand", "hip": "Thigh",
         "knee": "Calf", "ankle": "Foot", "foot": "ToeBase"},
        lambda s, side: f"CC_Base_{side[0].upper()}_{s}"), root="CC_Base_BoneRoot", stature=1.76, torso=1.02,
        arm=0.97, leg=1.03, arm_down=30.0, twist={}, facing="-Y", units=100.0, y_up=True,
        hips_parent="CC_Base_Pelvis",
        twist_chain={part: [(f"{stem}Twist01", 0.0), (f"{stem}Twist02", 0.5)] for part, stem in (
            ("shoulder", "Upperarm"), ("elbow", "Forearm"), ("hip", "Thigh"), ("knee", "Calf"))}),
    # Daz Genesis 8 as Diffeomorphic imports it (decimetres: object scale 0.1, +Z up, facing -Y):
    # four spine bones, Bend/Twist chains in the limbs (the Twist bone between the Bend bone and the
    # next segment's: the preset's twist bones, ``twist_in_chain``), pelvis between hip and the thighs
    "daz_genesis8": dict(names=_sided_names(
        {"pelvis": "hip", "spine1": "abdomenLower", "spine2": "abdomenUpper", "spine3": ["chestLower", "chestUpper"],
         "neck": ["neckLower", "neckUpper"], "head": "head"},
        {"collar": "Collar", "shoulder": ["ShldrBend", "ShldrTwist"], "elbow": ["ForearmBend", "ForearmTwist"],
         "wrist": "Hand", "hip": ["ThighBend", "ThighTwist"], "knee": "Shin", "ankle": "Foot", "foot": "Toe"},
        lambda s, side: [f"{side[0]}{x}" for x in s] if isinstance(s, list) else f"{side[0]}{s}"),
        root=None, stature=1.68, torso=0.98, arm=1.04, leg=1.0, arm_down=40.0, twist={}, facing="-Y",
        units=10.0, y_up=False, hips_parent="pelvis", twist_in_chain=("shoulder", "elbow", "hip")),
}


def _extra_bones(style, P, names):
    """Bones no preset maps: fingers, IK targets, props, helpers.  ``[(name, parent, head, tail)]``."""
    J = sk.J
    out = []

    def hand_frame(side):
        w = P[J[f"{side}_wrist"]]
        d = rot.normalize(w - P[J[f"{side}_elbow"]])
        return w, d

    def finger(name, parent, start, d, length=0.03):
        out.append((name, parent, start, start + length * d))

    for side in ("left", "right"):
        w, d = hand_frame(side)
        fwd = np.array([0.0, -1.0, 0.0])
        bone = names[f"{side}_wrist"]
        s, S = side[0], side[0].upper()
        if style.startswith("ue"):
            base = w + 0.09 * d
            if style == "ue5":
                finger(f"index_metacarpal_{s}", bone, w + 0.02 * d + 0.02 * fwd, d, 0.06)
                finger(f"index_01_{s}", f"index_metacarpal_{s}", base + 0.02 * fwd, d)
                out.append((f"upperarm_correctiveRoot_{s}", names[f"{side}_shoulder"], P[J[f"{side}_shoulder"]],
                            P[J[f"{side}_shoulder"]] + np.array([0.0, 0.0, 0.05])))
            else:
                finger(f"index_01_{s}", bone, base + 0.02 * fwd, d)
            finger(f"index_02_{s}", f"index_01_{s}", base + 0.02 * fwd + 0.03 * d, d)
            finger(f"thumb_01_{s}", bone, w + 0.03 * d + 0.04 * fwd, rot.normalize(d + fwd))
            finger(f"pinky_01_{s}", bone, base - 0.03 * fwd, d)
        elif style == "vrm":
            finger(f"J_Bip_{S}_Index1", bone, w + 0.08 * d + 0.02 * fwd, d)
            finger(f"J_Bip_{S}_Index2", f"J_Bip_{S}_Index1", w + 0.11 * d + 0.02 * fwd, d)
            finger(f"J_Bip_{S}_Thumb1", bone, w + 0.03 * d + 0.03 * fwd, rot.normalize(d + fwd))
            bust = P[J["spine3"]] + np.array([0.05 if s == "l" else -0.05, -0.08, 0.0])
            out.append((f"J_Sec_{S}_Bust1", names["spine3"], bust, bust + 0.06 * fwd))
        else:
            finger(f"thumb1.{s}", bone, w + 0.03 * d + 0.03 * fwd, rot.normalize(d + fwd))
            finger(f"index1_base.{s}", bone, w + 0.02 * d + 0.02 * fwd, d, 0.06)
            finger(f"index1.{s}", f"index1_base.{s}", w + 0.08 * d + 0.02 * fwd, d)
            finger(f"c_index2.{s}", f"index1.{s}", w + 0.11 * d + 0.02 * fwd, d)
    head = P[J["head"]]
    up = np.array([0.0, 0.0, 1.0])
    eye = head + np.array([0.03, -0.08, 0.06])
    if style.startswith("ue"):
        # IK bones under the root (UE keeps them on the hands and feet of the reference pose)
        out += [("ik_foot_root", "root", np.zeros(3), up * 0.1), ("ik_hand_root", "root", np.zeros(3), up * 0.1)]
        for side in ("left", "right"):
            a = P[J[f"{side}_ankle"]]
            out.append((f"ik_foot_{side[0]}", "ik_foot_root", a, a + np.array([0.0, -0.1, 0.0])))
        wr, wl = P[J["right_wrist"]], P[J["left_wrist"]]
        out += [("ik_hand_gun", "ik_hand_root", wr, wr + up * 0.1), ("ik_hand_r", "ik_hand_gun", wr, wr + up * 0.1),
                ("ik_hand_l", "ik_hand_gun", wl, wl + up * 0.1)]
        if style == "ue4":            # a prop carried in the right hand
            out.append(("weapon_r", names["right_wrist"], wr + np.array([0.0, -0.05, 0.0]),
                        wr + np.array([0.0, -0.35, 0.0])))
        else:
            out += [("interaction", "root", np.zeros(3), up * 0.1), ("center_of_mass", "root", P[0], P[0] + up * 0.1)]
    elif style == "vrm":
        hair = head + np.array([0.0, 0.06, 0.15])
        out += [("J_Adj_L_FaceEye", names["head"], eye, eye - 0.04 * up),
                ("J_Sec_Hair1_01", names["head"], hair, hair + np.array([0.0, 0.06, -0.1]))]
    else:
        out.append(("c_eye.l", names["head"], eye, eye - 0.04 * up))
    return out


def _first(v):
    return v if isinstance(v, str) else v[0]


_NEXT_JOINT = {"shoulder": "elbow", "elbow": "wrist", "hip": "knee", "knee": "ankle"}


def _tool_bones(st, P, bones):
    """A style's own extra bones: ``hips_parent`` (a bone between the hips bone and the thighs, as
    CC's CC_Base_Pelvis and Daz's pelvis are) and ``twist_chain`` (part -> ``[(stem, fraction)]``:
    twist bones along each side's segment, the first under the segment's bone, each next one
    under the one before, starting ``fraction`` of the way along and reaching to the next one's
    head or the segment's end)."""
    J = sk.J
    names = st["names"]
    out = list(bones)
    hp = st.get("hips_parent")
    if hp:
        pelvis, thighs = _first(names["pelvis"]), {_first(names[f"{s}_hip"]) for s in ("left", "right")}
        mid = 0.5 * (P[J["left_hip"]] + P[J["right_hip"]])
        tail = mid if np.linalg.norm(mid - P[0]) > 0.02 else P[0] + np.array([0.0, 0.0, -0.05])
        out = []
        for b in bones:
            out.append((b[0], hp if b[0] in thighs else b[1], b[2], b[3]))
            if b[0] == pelvis:
                out.append((hp, pelvis, P[0].copy(), tail))
    for part, chain in st.get("twist_chain", {}).items():
        for side in ("left", "right"):
            a, b = P[J[f"{side}_{part}"]], P[J[f"{side}_{_NEXT_JOINT[part]}"]]
            parent = _first(names[f"{side}_{part}"])
            ends = [f for _, f in chain[1:]] + [1.0]
            for (stem, f), g in zip(chain, ends):
                name = f"CC_Base_{side[0].upper()}_{stem}"
                out.append((name, parent, a + f * (b - a), a + g * (b - a)))
                parent = name
    return out


def style_twist(st):
    """The twist lists a style's preset should give: ``{joint: [bone, ...]}`` base to tip."""
    out = {f"{side}_{part}": [f"{b}_{side[0]}" for b, _ in v]
           for part, v in st["twist"].items() for side in ("left", "right")}
    for part, chain in st.get("twist_chain", {}).items():
        for side in ("left", "right"):
            out[f"{side}_{part}"] = [f"CC_Base_{side[0].upper()}_{stem}" for stem, _ in chain]
    for part in st.get("twist_in_chain", ()):
        for side in ("left", "right"):
            out[f"{side}_{part}"] = list(st["names"][f"{side}_{part}"][1:])
    return out


def styled_character(style, name=None, seed=7):
    """A character named and standing as ``style`` of :data:`RIG_STYLES` gives (A-pose rest,
    randomly rolled bones, its own proportions, the tool's units, up axis and facing), with
    fingers, IK bones and props no preset maps.  Returns ``(object, spec)``: spec is the style's
    dict plus ``joints`` ``(22, 3)`` (metres, +Z up, facing -Y, before the object's transform),
    ``F`` ``(3, 3)`` (the turn from the performer's facing, -Y, to the character's in the world)
    and ``bones`` (every bone name)."""
    st = dict(RIG_STYLES[style])
    P = humanoid_joints(st["stature"], st["arm_down"], st["arm"], st["leg"], st["torso"])
    twist = {f"{side}_{part}": [(f"{b}_{side[0]}", f) for b, f in v]
             for part, v in st["twist"].items() for side in ("left", "right")}
    bones = humanoid_bones(P, st["names"], twist, root=st["root"]) + _extra_bones(style, P, st["names"])
    bones = _tool_bones(st, P, bones)
    obj = build_armature(name or style, bones, seed, facing=st["facing"], units=st["units"], y_up=st["y_up"],
                         yaw_deg=st.get("yaw_deg", 0.0), location=st.get("location", (0.0, 0.0, 0.0)))
    yaw = np.radians(st.get("yaw_deg", 0.0)) + (np.pi if st["facing"] == "+Y" else 0.0)
    st.update(joints=P, F=rot.axis_angle_rotation(np.array([0.0, 0.0, 1.0]), np.array(yaw)),
              bones=[b[0] for b in bones])
    return obj, st


def planted_feet_result(T=60, fps=24.0, stature=1.8, seed=0, speed=0.5, stride=0.7, stance=0.44):
    """A :class:`PoseResult` of a walk forward (-Y) with planted feet and ``contacts`` marking them.

    The pelvis goes ``speed`` m/s forward, a little lowered, bobbing, swaying and turning (±0.15
    rad, as a walking pelvis does); each foot is planted, flat and pointing forward, on anchors a
    ``stride`` apart while the pelvis is within ``stance / 2`` of them (on the flagged frames the
    ankle, and so the ball of the foot, stays exactly still), and swings to the next anchor in
    between, lifted 7 cm.  The legs are solved onto those ankles (knees forward); spine, neck and
    arms move smoothly."""
    body = sk.make_body(stature)
    rest = body.rest_positions()
    s = np.arange(T) / fps
    y_p = -speed * s
    phase = 2 * np.pi * (-y_p) / stride
    root = np.stack([0.025 * np.sin(phase), y_p, body.root_rest[2] - 0.07 + 0.012 * np.cos(2 * phase)], -1)
    local = smooth_local_rotations(T, seed, spread=0.3)
    z = np.array([0.0, 0.0, 1.0])
    local[:, 0] = rot.axis_angle_rotation(z, 0.15 * np.sin(phase)) @ rot.axis_angle_rotation(
        np.array([0.0, 1.0, 0.0]), 0.05 * np.sin(phase))
    h = stance / 2
    ankles = np.zeros((T, 2, 3))
    contacts = np.zeros((T, 2), bool)
    for i, (side, a0) in enumerate((("left", 0.12), ("right", 0.12 - stride / 2))):
        j = sk.J[f"{side}_ankle"]
        r_all = a0 + h - y_p
        k = np.floor(r_all / stride)
        r = r_all - k * stride
        a_k = a0 - k * stride
        planted = r <= 2 * h
        u = np.clip((r - 2 * h) / (stride - 2 * h), 0.0, 1.0)
        ankles[:, i, 0] = rest[j, 0] + 0.02 * np.sign(rest[j, 0])
        ankles[:, i, 1] = np.where(planted, a_k, a_k - stride * (1 - np.cos(np.pi * u)) / 2)
        ankles[:, i, 2] = rest[j, 2] + np.where(planted, 0.0, 0.07 * np.sin(np.pi * u))
        contacts[:, i] = planted
    pos, wr = sk.forward_kinematics(local, root, body)
    legs = [2, 3]
    hips = pos[:, [sk.J["left_hip"], sk.J["right_hip"]]]
    sol = ls.solve_limbs(hips, ankles, np.zeros((T, 2)), body.limb_lengths()[legs], wr[:, [0, 0]],
                         end_rot=np.broadcast_to(np.eye(3), (T, 2, 3, 3)), limb_ids=legs)
    assert sol.reach_error.max() < 1e-9, sol.reach_error.max()
    for i, side in enumerate(("left", "right")):
        local[:, sk.J[f"{side}_hip"]] = sol.base_local[:, i]
        local[:, sk.J[f"{side}_knee"]] = sol.mid_local[:, i]
        local[:, sk.J[f"{side}_ankle"]] = sol.end_local[:, i]
    pos, wr = sk.forward_kinematics(local, root, body)
    assert np.abs(pos[:, [sk.J["left_ankle"], sk.J["right_ankle"]]] - ankles).max() < 1e-9
    swivel = ls.swivel_from_positions(pos[:, ls.LIMB_BASE], pos[:, ls.LIMB_MID], pos[:, ls.LIMB_END],
                                      wr[:, ls.LIMB_PARENT], base_rot=wr[:, ls.LIMB_BASE])
    return PoseResult(fps=fps, body=body, local_rot=local, root_pos=root, swivel=swivel, contacts=contacts, t0=0.0)


class PanelLayout:
    """A stand-in for a panel's ``layout`` (no UI in background mode; bpy imported by the caller):
    records what ``draw()`` draws, ``(kind, name)`` in ``log``, and checks every drawn property,
    operator and list exists."""

    def __init__(self, log):
        self.log = log
        self.use_property_split = self.use_property_decorate = False
        self.active, self.alert, self.scale_y = True, False, 1.0

    def _child(self, *a, **k):
        child = type(self)(self.log)
        self.log.append(("child", child))
        return child
    row = column = box = split = _child

    def prop(self, data, name, **k):
        assert name in data.bl_rna.properties, f"no property {name!r} on {data}"
        self.log.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **k):
        assert name in data.bl_rna.properties and search_name in search_data.bl_rna.properties
        self.log.append(("prop_search", name))
        self.log.append(("icon", k.get("icon")))

    def operator(self, idname, **k):
        import bpy
        mod, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), name), idname
        self.log.append(("operator", idname))

    def template_list(self, listtype, list_id, data, propname, active_data, active_propname, **k):
        import bpy
        assert listtype in dir(bpy.types), listtype
        assert propname in data.bl_rna.properties and active_propname in active_data.bl_rna.properties
        self.log.append(("template_list", propname))

    def label(self, **k):
        self.log.append(("label", k.get("text")))

    def separator(self, **k):
        pass


def drawn_props(panel_cls, context):
    """The names of the properties ``panel_cls.draw`` draws in ``context`` (:class:`PanelLayout`)."""
    from types import SimpleNamespace
    log = []
    panel_cls.draw(SimpleNamespace(layout=PanelLayout(log)), context)
    return {name for kind, name in log if kind == "prop"}


def live_auto_rig_pro_character(name="ARP", stature=1.7, seed=11):
    """A character built the way a live Auto-Rig Pro rig works, as far as a retarget sees it
    (ARP itself is a commercial add-on, not available to the tests): deforming bones (root.x,
    spine_01.x, spine_02.x -- two spine bones, ARP's default --, neck.x, head.x, shoulder.l,
    arm_stretch.l, forearm_stretch.l, hand.l, thigh_stretch.l, leg_stretch.l, foot.l, toes_01.l)
    that follow the FK controls (c_root_master.x, c_spine_01.x, ..., c_arm_fk.l, c_thigh_fk.l, ...,
    under c_traj) through Copy Transforms constraints; a limb's constraints weigh in by its IK/FK
    switch, the ``ik_fk_switch`` property of c_hand_ik.l / c_foot_ik.l (1: FK; 0, the rig's
    state here: the limb stays as its IK would hold it, at rest), through drivers.  Returns the
    object (+Z up, facing -Y, A-pose rest, rolled bones)."""
    import bpy
    P = humanoid_joints(stature, 40.0)
    deform = {"pelvis": "root.x", "spine1": "spine_01.x", "spine2": "spine_02.x", "neck": "neck.x", "head": "head.x"}
    ctrl = {"pelvis": "c_root_master.x", "spine1": "c_spine_01.x", "spine2": "c_spine_02.x", "neck": "c_neck.x",
            "head": "c_head.x"}
    for side in ("left", "right"):
        s = side[0]
        for part, d, c in (("collar", "shoulder", "c_shoulder"), ("shoulder", "arm_stretch", "c_arm_fk"),
                           ("elbow", "forearm_stretch", "c_forearm_fk"), ("wrist", "hand", "c_hand_fk"),
                           ("hip", "thigh_stretch", "c_thigh_fk"), ("knee", "leg_stretch", "c_leg_fk"),
                           ("ankle", "foot", "c_foot_fk"), ("foot", "toes_01", "c_toes_fk")):
            deform[f"{side}_{part}"] = f"{d}.{s}"
            ctrl[f"{side}_{part}"] = f"{c}.{s}"
    bones = [("c_traj", None, np.zeros(3), np.array([0.0, 0.3, 0.0]))]
    bones += humanoid_bones(P, ctrl, root="c_traj")
    bones += humanoid_bones(P, deform)
    for s in ("l", "r"):
        for b, j in ((f"c_hand_ik.{s}", f"{'left' if s == 'l' else 'right'}_wrist"),
                     (f"c_foot_ik.{s}", f"{'left' if s == 'l' else 'right'}_ankle")):
            h = P[sk.J[j]]
            bones.append((b, "c_traj", h, h + np.array([0.0, -0.1, 0.0])))
    obj = build_armature(name, bones, seed)
    switch_of = {}
    for side in ("left", "right"):
        s = side[0]
        for part in ("shoulder", "elbow", "wrist"):
            switch_of[deform[f"{side}_{part}"]] = f"c_hand_ik.{s}"
        for part in ("hip", "knee", "ankle", "foot"):
            switch_of[deform[f"{side}_{part}"]] = f"c_foot_ik.{s}"
    for s in ("l", "r"):
        for b in (f"c_hand_ik.{s}", f"c_foot_ik.{s}"):
            obj.pose.bones[b]["ik_fk_switch"] = 0.0
    for j, d in deform.items():
        c = obj.pose.bones[d].constraints.new('COPY_TRANSFORMS')
        c.target, c.subtarget = obj, ctrl[j]
        if d in switch_of:
            fc = c.driver_add("influence")
            var = fc.driver.variables.new()
            var.name, var.type = "fk", 'SINGLE_PROP'
            var.targets[0].id = obj
            var.targets[0].data_path = f'pose.bones["{switch_of[d]}"]["ik_fk_switch"]'
            fc.driver.expression = "fk"
    bpy.context.view_layer.update()
    return obj
