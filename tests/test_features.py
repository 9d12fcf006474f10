"""Network inputs are translation-, heading- and stature-invariant (issue: pose network, 2)."""
import numpy as np

from blender_manikin.core import features
from blender_manikin.core import skeleton as sk
from pose_sampling import random_pose


def _window(seed=0, B=3, W=40, stature=1.75):
    rng = np.random.default_rng(seed)
    body = sk.make_body(stature)
    loc = random_pose(rng, B * W, spread=0.25).reshape(B, W, 22, 3, 3)
    root = np.tile(body.root_rest, (B, W, 1)) + rng.normal(size=(B, 1, 3)) * [1, 1, 0]
    pos, wr = sk.forward_kinematics(loc.reshape(-1, 22, 3, 3), root.reshape(-1, 3), body)
    pos, wr = pos.reshape(B, W, 22, 3), wr.reshape(B, W, 22, 3, 3)
    P = {d: pos[:, :, features.DEVICE_JOINT[d]] for d in features.INPUT_DEVICES}
    R = {d: wr[:, :, features.DEVICE_JOINT[d]] for d in features.INPUT_DEVICES}
    return P, R, pos, wr, loc, body


def _transform(P, R, yaw, shift, scale):
    Rz = features.rot_z(np.array(yaw))
    P2 = {d: scale * (np.einsum("ij,bwj->bwi", Rz, p) + shift) for d, p in P.items()}
    R2 = {d: Rz @ r for d, r in R.items()}
    return P2, R2


def test_inputs_invariant_to_translation_heading_and_stature():
    P, R, *_ = _window()
    x, C, o = features.make_inputs(P, R, np.full(3, 1.75), 30.0)
    for yaw, shift, scale in ((0.7, [3.0, -2.0, 0.0], 1.0), (-2.5, [0.1, 0.4, 0.0], 1.2), (3.1, [-5, 5, 0], 0.85)):
        P2, R2 = _transform(P, R, yaw, np.array(shift), scale)
        x2, C2, o2 = features.make_inputs(P2, R2, np.full(3, 1.75 * scale), 30.0)
        assert np.allclose(x, x2, atol=1e-5)


def test_inputs_change_with_floor_height_and_pose():
    P, R, *_ = _window()
    x, _, _ = features.make_inputs(P, R, np.full(3, 1.75), 30.0)
    P2 = {d: p + [0, 0, 0.1] for d, p in P.items()}               # performer 10 cm higher: not invariant
    x2, _, _ = features.make_inputs(P2, R, np.full(3, 1.75), 30.0)
    assert not np.allclose(x, x2, atol=1e-3)


def test_canonical_frame_faces_minus_y_at_centre():
    P, R, *_ = _window(seed=3)
    C, o = features.canonical_frames(P["head"], R["head"])
    c = P["head"].shape[1] // 2
    can = np.swapaxes(C, -1, -2) @ R["head"][:, c]
    assert np.allclose(features.heading_yaw(can), 0.0, atol=1e-9)
    assert np.allclose(o[:, 2], 0.0) and np.allclose(o[:, :2], P["head"][:, c, :2])


def test_targets_round_trip_through_decode():
    P, R, pos, wr, loc, body = _window(seed=5)
    B, W = pos.shape[:2]
    sw = np.random.default_rng(1).uniform(-3, 3, (B, W, 4))
    contacts = np.zeros((B, W, 2))
    x, C, o = features.make_inputs(P, R, np.full(B, body.stature), 30.0)
    y = features.encode_targets(wr, loc, pos, sw, contacts, C, o, np.full(B, body.stature))
    assert y.shape == (B, W, features.output_dim("manikin")) and y.dtype == np.float32
    dec = features.decode_outputs(y, C, o, np.full(B, body.stature), P["head"])
    assert np.allclose(dec["root_rot"], wr[:, :, 0], atol=1e-5)
    assert np.allclose(dec["torso_rot"], loc[:, :, list(features.TORSO_LOCAL_IDX)], atol=1e-5)
    assert np.allclose(dec["ankle_pos"], pos[:, :, list(features.ANKLES)], atol=1e-5)
    assert np.allclose(dec["ankle_rot"], wr[:, :, list(features.ANKLES)], atol=1e-5)
    cs = dec["swivel_cs"]
    assert np.allclose(np.angle(np.exp(1j * (np.arctan2(cs[..., 1], cs[..., 0]) - sw))), 0, atol=1e-5)
    assert np.allclose(dec["contact"], 0.5)                   # logit 0


def _encoded(loc, root, offsets, contacts, body, B, W, kind):
    """(x, y) of a motion: make_inputs from its head and wrists, encode_targets from its joints."""
    from blender_manikin.core import limb_solver as ls
    pos, wr = sk.forward_kinematics(loc, root, body, offsets=offsets)
    limbs = np.array([lb[1:] for lb in sk.LIMBS])
    sw = ls.swivel_from_positions(pos[:, limbs[:, 0]], pos[:, limbs[:, 1]], pos[:, limbs[:, 2]],
                                  wr[:, sk.PARENTS[limbs[:, 0]]], base_rot=wr[:, limbs[:, 0]])
    pos, wr = pos.reshape(B, W, 22, 3), wr.reshape(B, W, 22, 3, 3)
    P = {d: pos[:, :, features.DEVICE_JOINT[d]] for d in features.INPUT_DEVICES}
    R = {d: wr[:, :, features.DEVICE_JOINT[d]] for d in features.INPUT_DEVICES}
    st = np.full(B, 1.75)
    x, C, o = features.make_inputs(P, R, st, 30.0, body=np.tile(features.body_features(offsets[0], 1.75), (B, 1)))
    y = features.encode_targets(wr, loc.reshape(B, W, 22, 3, 3), pos, sw.reshape(B, W, 4),
                                contacts.reshape(B, W, 2), C, o, st, kind=kind)
    return x, y


def test_mirrored_inputs_and_outputs_are_those_of_the_mirrored_motion():
    """mirror_inputs / mirror_outputs equal the inputs and targets made from the left/right mirror
    image of a motion (the training augmentation's mirror), for both output kinds; each is its own
    inverse.  Fails with a swivel sign, a collar or ankle swap, or a 6D sign wrong."""
    from blender_manikin.training.dataset import mirror_motion
    rng = np.random.default_rng(4)
    B, W = 3, 12
    body = sk.make_body(1.75)
    loc = random_pose(rng, B * W, spread=0.5)
    root = np.tile(body.root_rest, (B * W, 1)) + rng.normal(0, 0.3, (B * W, 3))
    offsets = np.broadcast_to(body.offsets, (B * W, 22, 3)).copy()
    contacts = rng.uniform(size=(B * W, 2))
    for kind in ("manikin", "fk"):
        x, y = _encoded(loc, root, offsets, contacts, body, B, W, kind)
        xm, ym = _encoded(*mirror_motion(loc, root, offsets, contacts), body, B, W, kind)
        assert np.abs(xm - x).max() > 0.1 and np.abs(ym - y).max() > 0.1      # the mirror is not trivial
        np.testing.assert_allclose(features.mirror_inputs(x), xm, atol=1e-5)
        np.testing.assert_allclose(features.mirror_outputs(y, kind), ym, atol=1e-5)
        np.testing.assert_array_equal(features.mirror_outputs(features.mirror_outputs(y, kind), kind), y)
        np.testing.assert_array_equal(features.mirror_inputs(features.mirror_inputs(x)), x)
        assert features.mirror_outputs(y[:0], kind).shape == (0,) + y.shape[1:]     # an empty batch
