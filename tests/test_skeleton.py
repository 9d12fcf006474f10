import numpy as np
import pytest

from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk


def test_topology_matches_smpl_body():
    assert sk.PARENTS.tolist() == [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]
    assert sk.JOINT_NAMES[0] == "pelvis" and sk.JOINT_NAMES[-1] == "right_wrist" and len(sk.JOINT_NAMES) == 22


@pytest.mark.parametrize("H", [1.5, 1.75, 2.0])
@pytest.mark.parametrize("sole", [None, 0.0, 0.05])
def test_body_proportions_scale_with_stature(H, sole):
    """Barefoot proportions of the stature, every joint lifted by the soles (3 cm unless given)."""
    body = sk.make_body(sk.BodyMeasurements(stature=H, sole=sole))
    s = 0.03 if sole is None else sole
    assert body.sole == s and body.stature == H
    rest = body.rest_positions()
    assert np.isclose(rest[sk.J["head"], 2], 0.870 * H + s)
    assert np.isclose(rest[sk.J["neck"], 2], 0.830 * H + s)
    assert np.isclose(rest[sk.J["left_ankle"], 2], 0.039 * H + s)
    assert np.isclose(rest[sk.J["left_shoulder"], 2], 0.818 * H + s)
    assert np.isclose(rest[sk.J["left_foot"], 2], 0.012 * H + s)  # the ball of the foot on its sole
    assert rest[:, 2].min() >= 0.0                         # nothing below the floor
    assert rest[sk.J["left_wrist"], 0] > 0 > rest[sk.J["right_wrist"], 0]   # left is +X
    assert rest[sk.J["left_foot"], 1] < rest[sk.J["left_ankle"], 1]          # faces -Y
    L = body.limb_lengths()
    assert np.allclose(L[0], [0.186 * H, 0.146 * H]) and np.allclose(L[2], [0.245 * H, 0.246 * H])


def test_measurements_override_proportions():
    m = sk.BodyMeasurements(stature=1.8, upper_arm=0.30, forearm=0.27, thigh=0.45, shank=0.42,
                            shoulder_width=0.38, hip_width=0.2)
    body = sk.make_body(m)
    rest = body.rest_positions()
    assert np.allclose(body.limb_lengths(), [[0.30, 0.27], [0.30, 0.27], [0.45, 0.42], [0.45, 0.42]])
    assert np.isclose(rest[sk.J["left_shoulder"], 0] - rest[sk.J["right_shoulder"], 0], 0.38)
    assert np.isclose(rest[sk.J["left_hip"], 0] - rest[sk.J["right_hip"], 0], 0.2)
    span = sk.make_body(sk.BodyMeasurements(stature=1.8, arm_span=1.5)).rest_positions()
    assert np.isclose(span[sk.J["left_wrist"], 0] - span[sk.J["right_wrist"], 0], 1.5)


def test_bad_measurements_raise():
    with pytest.raises(ValueError, match="stature"):
        sk.make_body(1700.0)
    with pytest.raises(ValueError, match="thigh"):
        sk.make_body(sk.BodyMeasurements(stature=1.7, thigh=-0.1))


def test_fk_rest_and_vectorised_against_loop():
    body = sk.make_body(1.7)
    T = 7
    pos, R = sk.forward_kinematics(np.broadcast_to(np.eye(3), (T, 22, 3, 3)), np.tile(body.root_rest, (T, 1)), body)
    assert np.allclose(pos, body.rest_positions())
    rng = np.random.default_rng(0)
    loc = rot.axis_angle_to_matrix(rng.normal(size=(T, 22, 3)))
    root = rng.normal(size=(T, 3))
    pos, R = sk.forward_kinematics(loc, root, body)
    for t in range(T):                     # reference: plain per-frame recursion
        Rw = [None] * 22
        pw = [None] * 22
        for j in range(22):
            p = sk.PARENTS[j]
            if p < 0:
                Rw[j], pw[j] = loc[t, j], root[t]
            else:
                Rw[j] = Rw[p] @ loc[t, j]
                pw[j] = pw[p] + Rw[p] @ body.offsets[j]
        assert np.allclose(pos[t], np.array(pw)) and np.allclose(R[t], np.array(Rw))
    assert np.allclose(sk.local_from_world(R), loc)
    # bone lengths are preserved by FK
    L = np.linalg.norm(pos[:, 1:] - pos[:, sk.PARENTS[1:]], axis=-1)
    assert np.allclose(L, body.bone_lengths()[1:])


@pytest.mark.parametrize("sole", [-0.01, 0.25, float("nan")])
def test_implausible_soles_are_refused(sole):
    with pytest.raises(ValueError, match="sole"):
        sk.make_body(sk.BodyMeasurements(stature=1.75, sole=sole))


def test_body_from_offsets_stands_where_its_root_says():
    """from_offsets keeps the feet where the root puts them; its stature discounts the soles."""
    made = sk.make_body(1.80)
    b = sk.Body.from_offsets(made.offsets, made.root_rest, sole=made.sole)
    assert b.sole == made.sole and b.stature == pytest.approx(1.80, abs=1e-9)
    np.testing.assert_allclose(b.rest_positions(), made.rest_positions())
    bare = sk.Body.from_offsets(made.offsets, made.root_rest - [0, 0, made.sole])
    assert bare.sole == 0.0 and bare.stature == pytest.approx(1.80, abs=1e-9)
