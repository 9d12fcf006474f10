"""The body armature: names, rest heads, rolls and the R_local -> pose-bone mapping (real Blender)."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import armature as am  # noqa: E402
from blender_manikin.core import limb_solver as ls  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import fresh_scene  # noqa: E402


@pytest.fixture
def body():
    fresh_scene()
    return sk.make_body(sk.BodyMeasurements(stature=1.72, arm_span=1.75))


def test_bones_named_and_placed(body):
    obj = am.create_armature(body)
    assert obj.type == 'ARMATURE' and obj.name == "MANIKIN_body"
    assert sorted(b.name for b in obj.data.bones) == sorted(sk.JOINT_NAMES)
    rest = body.rest_positions()
    for j, name in enumerate(sk.JOINT_NAMES):
        b = obj.data.bones[name]
        np.testing.assert_allclose(np.array(b.head_local), rest[j], atol=1e-5)
        parent = None if sk.PARENTS[j] < 0 else sk.JOINT_NAMES[sk.PARENTS[j]]
        assert (b.parent.name if b.parent else None) == parent
        assert b.length > 0.01
        assert obj.pose.bones[name].rotation_mode == 'QUATERNION'
    # tails point at the child; leaves as documented
    def tail_dir(n):
        b = obj.data.bones[n]
        return rot.normalize(np.array(b.tail_local) - np.array(b.head_local))
    np.testing.assert_allclose(tail_dir("head"), [0, 0, 1], atol=1e-5)
    np.testing.assert_allclose(tail_dir("left_wrist"), [1, 0, 0], atol=1e-5)
    np.testing.assert_allclose(tail_dir("right_wrist"), [-1, 0, 0], atol=1e-5)
    np.testing.assert_allclose(tail_dir("left_foot"), [0, -1, 0], atol=1e-5)
    np.testing.assert_allclose(tail_dir("left_elbow"), [1, 0, 0], atol=1e-5)
    np.testing.assert_allclose(tail_dir("left_knee"), [0, 0, -1], atol=1e-5)
    assert obj.data.bones["left_elbow"].use_connect and not obj.data.bones["left_hip"].use_connect
    assert am.armature_matches_body(obj, body)
    assert not am.armature_matches_body(obj, body.scaled(1.1))


def test_new_object_never_reuses_user_data(body):
    user_arm = bpy.data.armatures.new("MANIKIN_body")
    user_obj = bpy.data.objects.new("MANIKIN_body", user_arm)
    bpy.context.scene.collection.objects.link(user_obj)
    a = am.create_armature(body)
    b = am.create_armature(body)
    assert len({user_obj.name, a.name, b.name}) == 3
    assert len({user_arm.name, a.data.name, b.data.name}) == 3
    assert len(user_arm.bones) == 0 and user_obj.data == user_arm


def test_rolls_hinges_on_local_x(body):
    """Elbows and knees flex about the bone's local +X; +angle = flexion."""
    obj = am.create_armature(body)
    heads, B = am.rest_matrices(obj)
    _, _, B_expected, _ = am.bone_layout(body)
    np.testing.assert_allclose(B, B_expected, atol=1e-5)
    for li, (_, base, mid, end) in enumerate(sk.LIMBS):
        # the hinge axis of the limb solver is the bone's X axis (armature space)
        np.testing.assert_allclose(B[mid][:, 0], ls.H0[li], atol=1e-5)
        theta = 0.7
        R = np.broadcast_to(np.eye(3), (1, sk.NUM_JOINTS, 3, 3)).copy()
        R[0, mid] = rot.axis_angle_rotation(ls.H0[li], theta)
        q = am.pose_bone_quaternions(R, B)[0, mid]
        np.testing.assert_allclose(q, [np.cos(theta / 2), np.sin(theta / 2), 0, 0], atol=1e-5)
        # positive local-X rotation really bends the limb: the end moves away from
        # the straight line, forwards (-Y) for elbows, backwards (+Y) for knees
        from blender_manikin.core.skeleton import forward_kinematics
        p, _ = forward_kinematics(R, body.root_rest[None], body)
        dy = p[0, end, 1] - p[0, mid, 1]
        assert (dy < -0.05) if li < 2 else (dy > 0.05)
    # torso and legs share local X = performer's left; arms: left down / right up
    for name in ("pelvis", "spine1", "spine3", "neck", "head", "left_hip", "right_knee", "left_ankle"):
        np.testing.assert_allclose(B[sk.J[name]][:, 0], [1, 0, 0], atol=1e-5)
    np.testing.assert_allclose(B[sk.J["left_shoulder"]][:, 0], [0, 0, -1], atol=1e-5)
    np.testing.assert_allclose(B[sk.J["right_shoulder"]][:, 0], [0, 0, 1], atol=1e-5)
    for name in ("spine2", "left_shoulder", "right_elbow"):
        np.testing.assert_allclose(B[sk.J[name]][:, 2], [0, -1, 0], atol=1e-5)   # Z forward
    # left/right rolls are Blender mirror images (x-mirror: X -> -M X, Y -> M Y, Z -> M Z)
    M = np.diag([-1.0, 1, 1])
    for name in ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle", "foot"):
        L, Rr = B[sk.J[f"left_{name}"]], B[sk.J[f"right_{name}"]]
        np.testing.assert_allclose(Rr, np.stack([-M @ L[:, 0], M @ L[:, 1], M @ L[:, 2]], -1), atol=1e-5)


def test_pose_quaternions_sign_continuous():
    T = 50
    ang = np.linspace(0, 4 * np.pi, T)
    R = np.broadcast_to(np.eye(3), (T, sk.NUM_JOINTS, 3, 3)).copy()
    R[:, 3] = rot.axis_angle_rotation(np.array([0, 0, 1.0]), ang)
    q = am.pose_bone_quaternions(R, np.broadcast_to(np.eye(3), (sk.NUM_JOINTS, 3, 3)))
    assert np.all(np.sum(q[1:] * q[:-1], -1) > 0)
    np.testing.assert_allclose(rot.quat_to_matrix(q[:, 3]), R[:, 3], atol=1e-9)
