"""Sampling animated scene objects / bones as tracker devices."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying, scene_trackers  # noqa: E402
from mathutils import Matrix  # noqa: E402
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


def _parented(name, seed):
    """A keyed empty under a moving parent (sampled by stepping the scene)."""
    sc = bpy.context.scene
    root = bpy.data.objects.new(name + "_root", None)
    sc.collection.objects.link(root)
    act = keying.new_action(root.name)
    keying.assign_action(root, act)
    keying.key_channels(act, root, [1, N], [("location", 0, "", [0.0, 3.0]), ("rotation_euler", 2, "", [0.0, 1.0])])
    obj = _keyed_empty(name, 'XYZ', seed=seed)
    obj.parent = root
    return obj


def test_a_source_the_view_layer_does_not_evaluate_is_said_not_read_frozen():
    """An object stepped through the scene is read from the evaluated scene; one disabled in the
    viewports, or in a collection excluded from the view layer, is not evaluated there and keeps a
    stale matrix (it was read as a tracker frozen for the whole take): an error names it."""
    fresh_scene()
    sc = bpy.context.scene
    hidden = _parented("hidden", seed=5)
    ref = scene_trackers.sample_sources(sc, {"left_hand": (hidden, "")}, 1, N)
    assert ref.metadata["method"]["left_hand"] == "frame_set"
    assert np.ptp(ref["left_hand"].pos, axis=0).max() > 1.0
    hidden.hide_viewport = True
    with pytest.raises(scene_trackers.SceneSourceError, match="left_hand: object 'hidden' cannot be read"):
        scene_trackers.sample_sources(sc, {"left_hand": (hidden, "")}, 1, N)
    hidden.hide_viewport = False
    coll = bpy.data.collections.new("trackers")
    sc.collection.children.link(coll)
    coll.objects.link(hidden)
    sc.collection.objects.unlink(hidden)
    bpy.context.view_layer.layer_collection.children["trackers"].exclude = True
    with pytest.raises(scene_trackers.SceneSourceError, match="disabled in the viewports"):
        scene_trackers.sample_sources(sc, {"left_hand": (hidden, "")}, 1, N)
    # a plain keyed object is read from its F-curves, hidden or not
    plain = _keyed_empty("plain", 'XYZ', seed=6)
    plain.hide_viewport = True
    assert scene_trackers.sample_sources(sc, {"head": (plain, "")}, 1, N)["head"].valid.all()


def test_keyed_visibility_off_is_tracking_lost():
    """Visibility keyed off (an importer's or a plugin's "tracking lost") makes those samples lost,
    for a plain keyed object and for one stepped through the scene (whose world matrix the view
    layer leaves stale there); the samples around them are Blender's own."""
    fresh_scene()
    sc = bpy.context.scene
    objs = {"head": _keyed_empty("plain", 'XYZ', seed=7), "left_hand": _parented("child", seed=8)}
    lost = (np.arange(1, N + 1) >= 8) & (np.arange(1, N + 1) <= 12)
    truth = {d: np.empty((N, 3)) for d in objs}
    for k in range(N):
        sc.frame_set(1 + k)
        for d, o in objs.items():
            truth[d][k] = np.array(o.matrix_world)[:3, 3]
    for o in objs.values():
        fc = keying.ensure_fcurve(o.animation_data.action, "hide_viewport", 0, "", o)
        keying.set_keys(fc, np.arange(1, N + 1), lost.astype(float), 'CONSTANT')
    rec = scene_trackers.sample_sources(sc, {d: (o, "") for d, o in objs.items()}, 1, N)
    assert rec.metadata["method"] == {"head": "fcurves", "left_hand": "frame_set"}
    for d in objs:
        np.testing.assert_array_equal(rec[d].valid, ~lost)
        np.testing.assert_allclose(rec[d].pos[~lost], truth[d][~lost], atol=1e-5)


def test_a_camera_is_read_as_a_headset_looking_where_it_looks():
    """A camera looks along its -Z with +Y up; mapped to a device it is read in a device's axes
    (-Y forward, +Z up), so a camera keyed where a headset empty is gives the same samples (read
    as they stood, a camera as the head turned the solved body round and swapped its hands)."""
    fresh_scene()
    sc = bpy.context.scene
    hmd = _keyed_empty("HMD", 'QUATERNION', seed=4)
    hmd.scale = (1.0, 1.0, 1.0)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    cam.parent = hmd                                             # its -Z along the headset's -Y
    basis = np.eye(4)
    basis[:3, :3] = [[-1, 0, 0], [0, 0, 1], [0, 1, 0]]
    cam.matrix_basis = Matrix(basis.tolist())
    sc.frame_set(3)
    M = np.array(cam.matrix_world)[:3, :3]
    H = np.array(hmd.matrix_world)[:3, :3]
    np.testing.assert_allclose(-M[:, 2], -H[:, 1], atol=1e-6)    # the camera looks where the headset does
    np.testing.assert_allclose(M[:, 1], H[:, 2], atol=1e-6)      # with the same up
    a = scene_trackers.sample_sources(sc, {"head": (hmd, "")}, 1, N)["head"]
    b = scene_trackers.sample_sources(sc, {"head": (cam, "")}, 1, N)["head"]
    np.testing.assert_allclose(b.pos, a.pos, atol=1e-6)
    np.testing.assert_allclose(rot.quat_to_matrix(b.quat), rot.quat_to_matrix(a.quat), atol=1e-5)


def test_time_stretching_reads_parented_and_keyed_sources_alike():
    """With Time Stretching (frame_map_old / frame_map_new) a scene frame shows the animation of
    another frame; a source stepped through the scene is read at the animation's frames, as the
    F-curves of a keyed one are (and as the solve's keys are shown): a parented object read at
    the scene frames was stretched twice, 1.3 m off its own keys in the solve."""
    fresh_scene()
    sc = bpy.context.scene
    sc.render.frame_map_old, sc.render.frame_map_new = 100, 200
    obj = _keyed_empty("src", 'XYZ', seed=9)
    fast = scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N)
    slow = scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N, force_frame_set=True)
    assert fast.metadata["method"]["head"] == "fcurves" and slow.metadata["method"]["head"] == "frame_set"
    np.testing.assert_allclose(slow["head"].pos, fast["head"].pos, atol=1e-5)
    np.testing.assert_allclose(rot.quat_to_matrix(slow["head"].quat), rot.quat_to_matrix(fast["head"].quat), atol=1e-5)
    assert sc.frame_current == 1


def test_a_solve_that_starts_after_the_range_lines_up_with_the_objects(addon):
    """Every tracker lost (keyed hidden) on the range's first 5 frames: the solve starts at
    frame 6, where tracking starts, and each solved frame shows the pose of its own frame (it
    was keyed from the range's first frame, 5 frames early: 11 cm off mid-take)."""
    from blender_manikin.blender import writer
    from blender_util import synthetic_result
    sc = bpy.context.scene
    sc.render.fps = 24
    res = synthetic_result(T=40, fps=24.0)
    src = writer.write_result(res, writer.WriteOptions(create_trackers=True))
    for e in src.trackers.values():
        keying.key_channels(e.animation_data.action, e, [1, 6], [("hide_viewport", 0, "", [1.0, 0.0])],
                            interpolation='CONSTANT')
    s = sc.manikin
    s.source = 'SCENE'
    for dev, e in src.trackers.items():
        getattr(s, dev).object = e
    s.calibration, s.height = 'MEASURE', 1.8
    s.create_trackers, s.use_scene_range, s.reuse_armature = False, False, False
    s.frame_start, s.frame_end = 1, 40
    s.smoothing_mode, s.smoothing = 'WINDOW', 0.0
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}, s.last_report
    out = s.armature
    for f in (6, 12, 30, 40):
        sc.frame_set(f)
        head = np.array(out.matrix_world) @ np.append(np.array(out.pose.bones["head"].head), 1)
        np.testing.assert_allclose(head[:3], res.targets.pos["head"][f - 1], atol=2e-3)


def test_keyed_delta_transforms_are_read_as_blender_shows_them():
    """An object whose delta location / rotation is keyed (zero on the current frame) moves by
    it: its F-curves alone are not where Blender shows it (5 m off), so it is read by stepping
    the scene."""
    fresh_scene()
    sc = bpy.context.scene
    obj = _keyed_empty("src", 'XYZ', seed=11)
    act = obj.animation_data.action
    keying.key_channels(act, obj, [1, N], [("delta_location", 0, "", [0.0, 5.0]),
                                           ("delta_rotation_euler", 2, "", [0.0, 1.0])], interpolation='LINEAR')
    sc.frame_set(1)
    rec = scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N)
    for k in (0, N // 2, N - 1):
        sc.frame_set(1 + k)
        m = np.array(obj.matrix_world)
        np.testing.assert_allclose(rec["head"].pos[k], m[:3, 3], atol=1e-5)
        np.testing.assert_allclose(rot.quat_to_matrix(rec["head"].quat[k]), rot.orthonormalize(m[:3, :3]), atol=1e-5)


def test_an_action_without_a_slot_is_read_as_blender_shows_it():
    """Blender 4.4+: an action assigned with no slot (an action made for another object picked
    in the Object's Animation panel) does not move the object; it is read standing where it is,
    not from the action's F-curves (3 m off)."""
    fresh_scene()
    sc = bpy.context.scene
    obj = _keyed_empty("src", 'XYZ', seed=12)
    ad = obj.animation_data
    if not keying.is_slotted(ad.action):
        pytest.skip("no action slots before Blender 4.4")
    ad.action_slot = None
    obj.location, obj.rotation_euler = (0.1, 0.2, 0.3), (0.0, 0.0, 0.5)
    sc.frame_set(1)
    rec = scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N)
    m = np.array(obj.matrix_world)
    np.testing.assert_allclose(rec["head"].pos, np.broadcast_to(m[:3, 3], (N, 3)), atol=1e-6)


def test_one_object_mapped_to_two_devices_is_refused():
    """The same empty picked for both hands (a slip in the N-panel) is said, naming the devices
    and the object: it was solved, both hands reaching for one point ("out of reach")."""
    fresh_scene()
    sc = bpy.context.scene
    obj = _keyed_empty("LeftController", 'XYZ', seed=13)
    head = _keyed_empty("HMD", 'XYZ', seed=14)
    with pytest.raises(scene_trackers.SceneSourceError,
                       match="left_hand and right_hand: both are mapped to object 'LeftController'"):
        scene_trackers.sample_sources(sc, {"head": (head, ""), "left_hand": (obj, ""), "right_hand": (obj, "")},
                                      1, N)


@pytest.mark.parametrize("how", ["own scale", "parent's scale", "keyed scale"])
def test_a_mirrored_source_is_refused(how):
    """A reflection is no rotation: the F-curve reading gave the object's own rotation and the
    scene stepping the nearest rotation, one axis flipped (they disagreed by up to 180°).  A
    source mirrored on any frame is refused, naming the frame."""
    fresh_scene()
    sc = bpy.context.scene
    obj = _keyed_empty("HMD", 'XYZ', seed=15)
    if how == "own scale":
        obj.scale = (1.0, 1.0, -1.0)
        at = 1
    elif how == "parent's scale":
        parent = bpy.data.objects.new("Rig", None)
        sc.collection.objects.link(parent)
        parent.scale = (-1.0, 1.0, 1.0)
        obj.parent = parent
        at = 1
    else:
        keying.key_channels(obj.animation_data.action, obj, [1, 9, 10],
                            [("scale", 0, "", [1.0, 1.0, -1.0])], interpolation='CONSTANT')
        at = 10
    with pytest.raises(scene_trackers.SceneSourceError,
                       match=f"head: object 'HMD' is mirrored .* at frame {at}: a tracker's orientation is a rotation"):
        scene_trackers.sample_sources(sc, {"head": (obj, "")}, 1, N)
