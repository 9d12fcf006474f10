"""Sampling animated scene objects / bones as tracker devices."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying, scene_trackers  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402

from blender_util import fresh_scene  # noqa: E402

N = 20


def _keyed_empty(name, mode, seed):
    rng = np.random.default_rng(seed)
    obj = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(obj)
    obj.rotation_mode = mode
    act = keying.new_action(name)
    keying.assign_action(obj, act)
    frames = np.arange(1, N + 1, 3)
    ch = [("location", i, "", rng.normal(size=len(frames))) for i in range(3)]
    if mode == 'QUATERNION':
        q = rot.quat_continuous(rot.normalize(rng.normal(size=(len(frames), 4))))
        ch += [("rotation_quaternion", i, "", q[:, i]) for i in range(4)]
    elif mode == 'AXIS_ANGLE':
        ch += [("rotation_axis_angle", i, "", rng.normal(size=len(frames))) for i in range(4)]
    else:
        ch += [("rotation_euler", i, "", rng.normal(size=len(frames))) for i in range(3)]
    keying.key_channels(act, obj, frames, ch, interpolation='BEZIER')
    obj.scale = (2.0, 0.5, 1.0)          # scale must not leak into the orientation
    return obj


@pytest.mark.parametrize("mode", ['QUATERNION', 'AXIS_ANGLE', 'XYZ', 'ZXY', 'YXZ'])
def test_fcurve_path_equals_frame_set(mode):
    fresh_scene()
    obj = _keyed_empty("src", mode, seed=len(mode))
    sc = bpy.context.scene
    sc.frame_set(7)
    fast = scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N)
    assert fast.metadata["method"]["head"] == "fcurves" and fast.metadata["exact"] is True
    assert sc.frame_current == 7
    slow = scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N, force_frame_set=True)
    assert slow.metadata["method"]["head"] == "frame_set"
    assert sc.frame_current == 7
    a, b = fast["head"], slow["head"]
    np.testing.assert_allclose(a.time, np.arange(1, N + 1) / 24.0)
    np.testing.assert_allclose(a.pos, b.pos, atol=1e-5)
    np.testing.assert_allclose(rot.quat_to_matrix(a.quat), rot.quat_to_matrix(b.quat), atol=1e-5)


def test_bone_and_constrained_sources():
    fresh_scene()
    sc = bpy.context.scene
    target = _keyed_empty("target", 'XYZ', seed=3)
    follower = bpy.data.objects.new("follower", None)
    sc.collection.objects.link(follower)
    c = follower.constraints.new('COPY_TRANSFORMS')
    c.target = target
    from blender_manikin.blender.armature import create_armature
    from blender_manikin.core import skeleton as sk
    arm = create_armature(sk.make_body(1.7))
    act = keying.new_action("arm")
    keying.assign_action(arm, act)
    keying.key_channels(act, arm, [1, N], [('pose.bones["left_elbow"].rotation_quaternion', 0, "", [1, 0.7]),
                                             ('pose.bones["left_elbow"].rotation_quaternion', 1, "", [0, 0.7])])
    rec = scene_trackers.sample_sources(sc, {"head": (follower, ""), "left_hand": (arm.name, "left_wrist")},
                                        1, N)
    assert rec.metadata["method"] == {"head": "frame_set", "left_hand": "frame_set"}
    # the names the devices come from, for the auto offsets (an object "HMD" is a headset)
    assert rec.metadata["device_labels"] == {"head": follower.name, "left_hand": "left_wrist"}
    ref = scene_trackers.sample_sources(sc, {"head": (target, "")}, 1, N)
    np.testing.assert_allclose(rec["head"].pos, ref["head"].pos, atol=1e-5)
    for k in (0, N - 1):
        sc.frame_set(1 + k)
        m = np.array(arm.matrix_world) @ np.array(arm.pose.bones["left_wrist"].matrix)
        np.testing.assert_allclose(rec["left_hand"].pos[k], m[:3, 3], atol=1e-6)
    with pytest.raises(scene_trackers.SceneSourceError, match="no bone"):
        scene_trackers.sample_sources(sc, {"head": (arm, "nope")}, 1, N)
    with pytest.raises(scene_trackers.SceneSourceError, match="no scene objects"):
        scene_trackers.sample_sources(sc, {}, 1, N)


def test_devices_are_mapped_by_the_objects_names(addon):
    """Map by Name: animated objects named after devices fill the empty slots; a slot the user
    set is kept; the scene's static camera is no headset."""
    sc = bpy.context.scene
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    made = {n: _keyed_empty(n, 'QUATERNION', seed=k)
            for k, n in enumerate(("HMD", "LeftController", "Right Controller.001", "Tracker_LeftFoot",
                                   "tracker_waist", "Cube"))}
    mine = _keyed_empty("my_right_foot_thing", 'XYZ', seed=9)
    s = sc.manikin
    s.right_foot.object = mine
    assert bpy.ops.manikin.map_devices() == {'FINISHED'}
    assert s.head.object == made["HMD"] and s.left_hand.object == made["LeftController"]
    assert s.right_hand.object == made["Right Controller.001"] and s.left_foot.object == made["Tracker_LeftFoot"]
    assert s.pelvis.object == made["tracker_waist"] and s.right_foot.object == mine
    from blender_manikin.core.devices import device_of_object_name
    assert device_of_object_name("MANIKIN_left_hand.002") == "left_hand" and device_of_object_name("Cube") is None
