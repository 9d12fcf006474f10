"""Writing a solve into the scene: bulk keys, both action APIs, swivel properties, trackers, undo."""
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying, writer  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import evaluated_heads, fresh_scene, synthetic_result  # noqa: E402

T = 36


@pytest.fixture
def scene():
    sc = fresh_scene()
    sc.render.fps = 24
    sc.render.fps_base = 1.0
    return sc


def test_keyed_pose_matches_fk_every_frame(scene):
    res = synthetic_result(T=T, fps=24.0)
    out = writer.write_result(res, writer.WriteOptions(frame_start=5))
    obj = out.armature
    np.testing.assert_allclose(out.frames, 5 + np.arange(T))
    # move the armature object: keys are in armature space, the check in world space
    heads, rots = evaluated_heads(obj, out.frames)
    pos, wrot = res.fk()
    assert np.max(np.abs(heads - pos)) < 1e-4            # 0.1 mm, every joint, every frame
    # bone orientation = joint world rotation @ bone rest rotation
    from blender_manikin.blender.armature import rest_matrices
    _, B = rest_matrices(obj)
    np.testing.assert_allclose(rots, wrot @ B[None], atol=1e-4)
    # same through pose_bone.head (matrix_world @ head)
    scene.frame_set(5 + T // 2)
    mw = np.array(obj.matrix_world)
    for j, name in enumerate(sk.JOINT_NAMES):
        h = mw @ np.append(np.array(obj.pose.bones[name].head), 1.0)
        assert np.max(np.abs(h[:3] - pos[T // 2, j])) < 1e-4


def test_key_counts_range_and_interpolation(scene):
    res = synthetic_result(T=T, fps=24.0)
    out = writer.write_result(res)
    act = out.action
    assert keying.is_slotted(act) == hasattr(act, "slots")
    fcs = keying.action_fcurves(act, out.armature)
    assert len(fcs) == 22 * 4 + 3 + 4 + 2
    for fc in fcs:
        assert len(fc.keyframe_points) == T
        assert tuple(fc.range()) == (1.0, float(T))
        contact = fc.data_path in ('["foot_contact_left"]', '["foot_contact_right"]')
        assert fc.keyframe_points[3].interpolation == ('CONSTANT' if contact else 'LINEAR')
    paths = {(fc.data_path, fc.array_index) for fc in fcs}
    assert ('pose.bones["pelvis"].location', 2) in paths
    assert ('pose.bones["left_elbow"].rotation_quaternion', 3) in paths
    groups = {fc.group.name for fc in fcs if fc.group is not None}
    assert {"pelvis", "left_wrist", writer.SWIVEL_GROUP} <= groups
    # quaternion keys are sign-continuous
    for j in range(22):
        q = np.array([[fc.keyframe_points[k].co[1] for k in range(T)]
                      for fc in fcs if fc.data_path.endswith(f'"{sk.JOINT_NAMES[j]}"].rotation_quaternion')])
        assert np.all(np.sum(q[:, 1:] * q[:, :-1], 0) > 0)


def test_frame_step_from_fps(scene):
    res = synthetic_result(T=12, fps=12.0)
    out = writer.write_result(res)             # scene 24 fps: two scene frames per solve frame
    np.testing.assert_allclose(out.frames, 1 + 2 * np.arange(12))
    heads, _ = evaluated_heads(out.armature, out.frames)
    assert np.max(np.abs(heads - res.positions)) < 1e-4


def test_swivel_properties_keyed(scene):
    res = synthetic_result(T=T, fps=24.0)
    obj = writer.write_result(res).armature
    for li, limb in enumerate(sk.LIMB_NAMES):
        name = f"swivel_{limb}"
        ui = obj.id_properties_ui(name).as_dict()
        assert ui["subtype"] == 'ANGLE'
        assert ui["soft_min"] == pytest.approx(-math.pi) and ui["soft_max"] == pytest.approx(math.pi)
        assert ui["min"] < -math.pi and ui["max"] > math.pi
        values = []
        for k in range(T):
            scene.frame_set(1 + k)
            values.append(obj[name])
        d = np.asarray(values) - res.swivel[:, li]
        # equal modulo 2 pi (keys are unwrapped so curves stay continuous)
        assert np.max(np.abs(np.angle(np.exp(1j * d)))) < 1e-5
        assert np.max(np.abs(np.diff(values))) < 1.0        # no 2 pi jumps in the curve
    fc = [f for f in keying.action_fcurves(obj.animation_data.action, obj)
          if f.data_path == '["swivel_left_arm"]']
    assert len(fc) == 1 and len(fc[0].keyframe_points) == T


def test_resolve_writes_new_action_and_keeps_first(scene):
    res = synthetic_result(T=T, fps=24.0)
    first = writer.write_result(res)
    act1 = first.action
    keys1 = [tuple(kp.co) for fc in keying.action_fcurves(act1, first.armature)
             for kp in fc.keyframe_points]
    res2 = synthetic_result(T=T + 4, fps=24.0, seed=3)
    second = writer.write_result(res2, writer.WriteOptions(armature=first.armature))
    assert second.armature == first.armature and not second.created_armature
    assert second.action != act1 and second.action.name.startswith("MANIKIN_solve")
    assert act1.name in bpy.data.actions and act1.use_fake_user
    assert first.armature.animation_data.action == second.action
    if keying.is_slotted(second.action):
        assert first.armature.animation_data.action_slot is not None
    keys1_after = [tuple(kp.co) for fc in keying.action_fcurves(act1, None) for kp in fc.keyframe_points]
    assert keys1 == keys1_after
    # a different body gets a new armature, the old one is untouched
    res3 = synthetic_result(T=T, fps=24.0, stature=1.6)
    third = writer.write_result(res3, writer.WriteOptions(armature=first.armature))
    assert third.created_armature and third.armature != first.armature
    assert first.armature.animation_data.action == second.action


def test_resolve_makes_a_new_armature_when_the_last_cannot_take_it(scene):
    """Reuse Armature: the last solve's armature parked in an excluded collection, or with an NLA
    strip being edited (tweak mode), gets no new action; the solve goes onto a new armature and
    the live rig is built on it, the old one untouched."""
    from blender_manikin.blender import live_rig
    res = synthetic_result(T=T, fps=24.0)
    first = writer.write_result(res)
    old, act1 = first.armature, first.action
    ad = old.animation_data
    track = ad.nla_tracks.new()
    strip = track.strips.new(act1.name, 1, act1)
    ad.action = None
    track.select = strip.select = True
    ad.use_tweak_mode = True
    second = writer.write_result(res, writer.WriteOptions(armature=old, key_pose=False))
    live_rig.build_live_rig(second.armature, res, frames=second.frames)
    assert second.created_armature and second.armature != old
    assert ad.use_tweak_mode and ad.action == act1 and not live_rig.is_live_rig(old)
    ad.use_tweak_mode = False
    parked = bpy.data.collections.new("old takes")
    scene.collection.children.link(parked)
    for c in list(old.users_collection):
        c.objects.unlink(old)
    parked.objects.link(old)
    bpy.context.view_layer.layer_collection.children["old takes"].exclude = True
    third = writer.write_result(res, writer.WriteOptions(armature=old, key_pose=False))
    live_rig.build_live_rig(third.armature, res, frames=third.frames)
    assert third.created_armature and third.armature not in (old, second.armature)
    assert not live_rig.is_live_rig(old)


def test_tracker_empties(scene):
    res = synthetic_result(T=T, fps=24.0)
    out = writer.write_result(res, writer.WriteOptions(create_trackers=True))
    assert out.tracker_collection.name == "MANIKIN trackers"
    assert set(out.trackers) == {"head", "left_hand", "right_hand"}
    for k in (0, T - 1):
        scene.frame_set(1 + k)
        for dev, empty in out.trackers.items():
            assert empty.users_collection[0] == out.tracker_collection
            np.testing.assert_allclose(np.array(empty.matrix_world)[:3, 3], res.targets.pos[dev][k], atol=1e-5)
            np.testing.assert_allclose(np.array(empty.matrix_world)[:3, :3], res.targets.rot[dev][k], atol=1e-5)
    # a second solve makes a second collection, not reusing the first
    out2 = writer.write_result(res, writer.WriteOptions(create_trackers=True))
    assert out2.tracker_collection != out.tracker_collection


def test_failure_leaves_nothing(scene, monkeypatch):
    n_obj, n_act, n_arm = len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures)
    res = synthetic_result(T=T, fps=24.0)

    def boom(*a, **k):
        raise RuntimeError("disk full")
    monkeypatch.setattr(writer, "_write_trackers", boom)
    with pytest.raises(RuntimeError):
        writer.write_result(res, writer.WriteOptions(create_trackers=True))
    assert (len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures)) == (n_obj, n_act, n_arm)
    monkeypatch.undo()
    out = writer.write_result(res, writer.WriteOptions(create_trackers=True))
    writer.remove_output(out)
    assert (len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures)) == (n_obj, n_act, n_arm)


class _LegacyFCurves:
    """The 4.2-4.3 ``action.fcurves`` collection, backed by a real channelbag (5.x has no legacy actions)."""

    def __init__(self, bag):
        self.bag = bag
        self.calls = []

    def find(self, data_path, index=0):
        return self.bag.fcurves.find(data_path, index=index)

    def new(self, data_path, index=0, action_group=""):
        self.calls.append((data_path, index, action_group))
        fc = self.bag.fcurves.new(data_path, index=index)
        if action_group:
            g = self.bag.groups.get(action_group) or self.bag.groups.new(action_group)
            fc.group = g
        return fc

    def __iter__(self):
        return iter(self.bag.fcurves)


class _LegacyAction:
    def __init__(self, fcurves):
        self.fcurves = fcurves


def test_legacy_action_path(scene):
    """The 4.x branch of ensure_fcurve/set_keys (action.fcurves.new with action_group)."""
    if "slots" not in bpy.types.Action.bl_rna.properties:
        pytest.skip("running on a legacy-only Blender: the real path is covered by the other tests")
    obj = bpy.data.objects.new("legacy_target", None)
    scene.collection.objects.link(obj)
    real = bpy.data.actions.new("legacy_backing")
    keying.assign_action(obj, real)
    bag = keying.ensure_channelbag(real, keying.ensure_slot(real, obj))
    fake = _LegacyAction(_LegacyFCurves(bag))
    assert not keying.is_slotted(fake)
    frames = np.arange(1, 11)
    fcs = keying.key_channels(fake, obj, frames, [("location", i, "Object Transforms", frames * (i + 1.0))
                                                  for i in range(3)])
    assert fake.fcurves.calls == [("location", i, "Object Transforms") for i in range(3)]
    assert keying.ensure_fcurve(fake, "location", 1, "Object Transforms") is not None
    assert len(fake.fcurves.calls) == 3                       # found, not created again
    assert all(len(fc.keyframe_points) == 10 for fc in fcs)
    assert keying.action_fcurves(fake) and len(list(keying.action_fcurves(fake))) == 3
    scene.frame_set(4)
    np.testing.assert_allclose(np.array(obj.location), [4, 8, 12], atol=1e-6)


def test_slotted_path_real(scene):
    if "slots" not in bpy.types.Action.bl_rna.properties:
        pytest.skip("no slotted actions in this Blender")
    obj = bpy.data.objects.new("slot_target", None)
    scene.collection.objects.link(obj)
    act = keying.new_action("MANIKIN_solve")
    keying.assign_action(obj, act)
    assert obj.animation_data.action_slot is not None
    assert obj.animation_data.action_slot.identifier == "OB" + obj.name
    fc = keying.ensure_fcurve(act, "location", 2, "Object Transforms", obj)
    keying.set_keys(fc, [1, 3], [0.0, 2.0])
    bag = act.layers[0].strips[0].channelbag(obj.animation_data.action_slot)
    assert bag.fcurves.find("location", index=2) == fc
    scene.frame_set(2)
    assert obj.location[2] == pytest.approx(1.0)
    with pytest.raises(ValueError):
        keying.ensure_fcurve(act, "location", 0)             # slotted needs the owner


def test_foot_contacts_are_keyed_as_steps(scene):
    """Each foot's contact is a keyed 0/1 custom property (footstep events for an engine)."""
    res = synthetic_result(T=T, fps=24.0)
    res.contacts = np.zeros((T, 2), bool)
    res.contacts[3:9, 0] = True
    res.contacts[6:, 1] = True
    out = writer.write_result(res)
    obj = out.armature
    sc = bpy.context.scene
    for k in range(T):
        sc.frame_set(1 + k)
        assert obj["foot_contact_left"] == pytest.approx(float(res.contacts[k, 0]))
        assert obj["foot_contact_right"] == pytest.approx(float(res.contacts[k, 1]))
    fc = next(f for f in keying.action_fcurves(out.action, obj) if f.data_path == '["foot_contact_left"]')
    assert fc.group.name == writer.CONTACT_GROUP and fc.keyframe_points[0].interpolation == 'CONSTANT'


def test_key_as_blender_value_other_than_property_keeps_auto_handles_fitted(scene):
    """key_as_blender given a value other than the property's (key_swivel's ``values``): the
    curve ends as update_keys leaves it, auto-clamped handles of the key and its neighbours
    fitted to the new value (Blender's keying fitted them to the property's value; the value was
    written over them, the neighbours' handles stale: the curve at frame 8 was 3.6995, not 3.92)."""
    def curve():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ob = bpy.data.objects.new("o", None)
        bpy.context.scene.collection.objects.link(ob)
        for f, v in ((1, 0.0), (11, 1.0), (21, 2.0), (31, 0.0)):
            ob["p"] = v
            ob.keyframe_insert('["p"]', frame=f)
        ob["p"] = 1.0
        fc = next(f for f in keying.action_fcurves(ob.animation_data.action, ob)
                  if f.data_path == '["p"]')
        return ob, fc

    def keys(fc):
        return np.array([[*k.handle_left, *k.co, *k.handle_right] for k in fc.keyframe_points])

    for frame in (11.0, 16.0):                    # an existing key, a new one
        ob, fc = curve()
        keying.update_keys(fc, [frame], [5.0])
        want, at = keys(fc), fc.evaluate(frame - 3)
        ob, fc = curve()
        if not keying.key_as_blender(ob, fc, frame, 5.0):
            keying.update_keys(fc, [frame], [5.0])
        np.testing.assert_allclose(keys(fc), want, atol=1e-5)
        assert abs(fc.evaluate(frame - 3) - at) < 1e-5
