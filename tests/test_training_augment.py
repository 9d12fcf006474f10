"""Training augmentation that makes the network generalise: randomised bodies (retargeted by FK),
left/right mirroring, calibration poses, and the body features the network is conditioned on.

numpy only (no torch): the sampler runs on synthetic clips made here.
"""
import numpy as np
import pytest

from blender_manikin.core import features, rotations as rot, skeleton as sk
from blender_manikin.training import dataset as ds

J = sk.J


def _standing_clipset(T=30, bodies=(1.75,)):
    """Clips of a body standing still in the rest T-pose with feet flat on the floor."""
    quat, root, contacts, offsets, statures = [], [], [], [], []
    for s in bodies:
        body = sk.make_body(s)
        quat.append(np.tile([1.0, 0, 0, 0], (T, sk.NUM_JOINTS, 1)))
        root.append(np.tile(body.root_rest, (T, 1)))
        contacts.append(np.ones((T, 2), np.uint8))
        offsets.append(body.offsets)
        statures.append(s)
    n = len(bodies)
    cs = ds.ClipSet(np.concatenate(quat).astype(np.float32), np.concatenate(root), np.concatenate(contacts),
                    np.arange(n) * T, np.full(n, T), np.stack(offsets), np.array(statures),
                    [f"stand{i}" for i in range(n)])
    cs.lowest = cs.lowest_foot_heights()
    return cs


def _moving_clipset(n=3, T=120, seed=0):
    rng = np.random.default_rng(seed)
    recs = []
    for i in range(n):
        mc = ds.synthetic_motion(rng, T=T, take_id=f"t{i}")
        recs.append(ds.motion_to_record(mc, f"c{i}", "synthetic"))
    lens = np.array([r["local_quat"].shape[0] for r in recs])
    cs = ds.ClipSet(np.concatenate([r["local_quat"] for r in recs]), np.concatenate([r["root_pos"] for r in recs]),
                    np.concatenate([r["contacts"] for r in recs]), np.concatenate([[0], np.cumsum(lens)[:-1]]),
                    lens, np.stack([r["offsets"].astype(np.float64) for r in recs]),
                    np.array([float(r["stature"]) for r in recs]), [str(r["name"]) for r in recs])
    cs.lowest = cs.lowest_foot_heights()
    return cs


def test_body_features_are_the_same_for_every_stature_and_track_proportions():
    default = (ds.SOLVER_MEASURES - features.BODY_REFERENCE) * features.BODY_SCALE
    for s in (1.5, 1.75, 2.0):
        b = sk.make_body(s)
        s_net = features.stature_from_offsets(b.offsets)
        head_above = sk.PROPORTIONS["head_height"] - sk.PROPORTIONS["ankle_height"]
        assert s_net == pytest.approx(s * head_above / features.HEAD_ABOVE_ANKLES, abs=1e-9)
        assert np.abs(features.body_features(b.offsets, s_net) - default).max() < 1e-6
    long_legs = sk.make_body(sk.BodyMeasurements(stature=1.75, thigh=0.245 * 1.75 * 1.1))
    s_net = features.stature_from_offsets(long_legs.offsets)
    f = features.body_features(long_legs.offsets, s_net) - default
    k = features.BODY_FEATURES.index("thigh")
    assert f[k] == pytest.approx(features.BODY_SCALE * 0.1 * 0.245 * 1.75 / s_net, rel=1e-5)
    assert np.abs(np.delete(f, [k, features.BODY_FEATURES.index("torso")])).max() < 1e-6


def test_body_reference_is_the_body_model_the_networks_were_trained_with(monkeypatch):
    """The contract's reference and length unit are the body model's proportions of the training
    time (head joint at 0.910, neck at 0.840): such a body has zero features and its network
    stature is its stature."""
    monkeypatch.setitem(sk.PROPORTIONS, "head_height", 0.910)
    monkeypatch.setitem(sk.PROPORTIONS, "neck_height", 0.840)
    for s in (1.5, 1.75, 2.0):
        b = sk.make_body(s)
        assert features.stature_from_offsets(b.offsets) == pytest.approx(s, abs=1e-9)
        assert np.abs(features.body_features(b.offsets, s)).max() < 1e-6


def test_random_bodies_stand_on_the_floor_with_the_stature_asked_for():
    """A standing clip retargeted onto random bodies: feet flat at the solver's clearance,
    every frame, and the stature within the range; segment groups really vary."""
    cs = _standing_clipset()
    aug = ds.Augment(speed=(1, 1), floor=0.0, mirror=0.0, pos_noise=0.0, rot_noise_deg=0.0, hand_offset_deg=0.0,
                     head_offset=0.0, edge_prob=0.0, calibration=0.0)
    smp = ds.WindowSampler(cs, window=10, augment=aug, seed=3)
    b = smp.sample(64)
    s = b["stature"].astype(np.float64)
    assert 1.45 <= s.min() and s.max() <= 2.05 and s.max() - s.min() > 0.3
    P = b["pos"].astype(np.float64)                                      # canonical, statures
    low = P[:, :, [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]], 2].min(-1)
    assert np.abs(low - (ds.FOOT_CLEARANCE + sk.SOLE / s[:, None])).max() < 1e-5
    # ... which is where the body the solver builds stands its balls of the feet, on its soles
    made = sk.make_body(1.75)
    s_made = features.stature_from_offsets(made.offsets)
    ball = made.rest_positions()[J["left_foot"], 2] / s_made
    assert ds.FOOT_CLEARANCE + sk.SOLE / s_made == pytest.approx(ball, abs=1e-9)
    # the network's stature is the skeleton's (head 0.871 statures above the ankles)
    head_above = P[:, :, J["head"], 2] - P[:, :, [J["left_ankle"], J["right_ankle"]], 2].mean(-1)
    assert np.abs(head_above - features.HEAD_ABOVE_ANKLES).max() < 1e-5
    bf = b["x"][:, 0, features.input_dim():]
    assert bf.shape == (64, len(features.BODY_FEATURES))
    assert (bf.max(0) - bf.min(0) > 0.04).all(), "every body feature must vary"
    assert np.allclose(b["x"][:, :1, -bf.shape[1]:], b["x"][:, :, -bf.shape[1]:])   # constant over the window


def test_random_bodies_span_the_reference_proportions():
    """Bodies are drawn between the source skeleton's proportions and the solver's default body,
    so the bodies the solver builds at run time are inside the training range."""
    cs = _standing_clipset()
    cs.offsets = cs.offsets * 1.0
    cs.offsets[:, [J["left_knee"], J["right_knee"]]] *= 1.15       # a source with long thighs
    cs.offsets[:, [J["left_collar"], J["right_collar"], J["left_shoulder"], J["right_shoulder"]], 0] *= 0.7
    cs.lowest = cs.lowest_foot_heights()
    smp = ds.WindowSampler(cs, window=4, seed=0)
    bf = smp.sample(400)["x"][:, 0, features.input_dim():]
    lo, hi = np.percentile(bf, 2, axis=0), np.percentile(bf, 98, axis=0)
    default = (ds.SOLVER_MEASURES - features.BODY_REFERENCE) * features.BODY_SCALE
    assert (lo < default).all() and (hi > default).all(), (lo, default, hi)


def test_mirror_is_a_reflection_with_sides_swapped():
    rng = np.random.default_rng(2)
    mc = ds.synthetic_motion(rng, T=20)
    body = mc.body
    rec = ds.motion_to_record(mc, "m", "synthetic")
    local = rot.quat_to_matrix(rec["local_quat"].astype(np.float64))
    root = rec["root_pos"].astype(np.float64)
    P, _ = sk.forward_kinematics(local, root, body)
    lm, rm, om, cm = ds.mirror_motion(local, root, body.offsets, rec["contacts"])
    Pm, _ = sk.forward_kinematics(lm, rm, None, offsets=np.broadcast_to(om, (20,) + om.shape))
    expect = P[:, sk.MIRROR_JOINTS] * np.array([-1.0, 1.0, 1.0])
    assert np.abs(Pm - expect).max() < 1e-9
    assert np.allclose(np.linalg.det(lm), 1.0)
    assert (cm == rec["contacts"][:, ::-1]).all()


def test_calibration_holds_stand_straight_on_both_feet():
    cs = _moving_clipset()
    aug = ds.Augment(speed=(1, 1), stature=None, segment=0.0, floor=0.0, mirror=0.0, pos_noise=0.0,
                     rot_noise_deg=0.0, hand_offset_deg=0.0, head_offset=0.0, edge_prob=0.0, calibration=1.0)
    smp = ds.WindowSampler(cs, window=40, augment=aug, seed=5)
    rng = np.random.default_rng(0)
    cid, t = smp._times(32, rng)
    b = smp.sample(32, np.random.default_rng(0))
    P = b["pos"].astype(np.float64)
    y = b["y"]
    contact = y[..., features.output_slices()["contact"]]
    # frames where both feet are planted and the legs are straight (the holds)
    knee = []
    for side in ("left", "right"):
        hip, kn, an = P[..., J[f"{side}_hip"], :], P[..., J[f"{side}_knee"], :], P[..., J[f"{side}_ankle"], :]
        u, v = kn - hip, an - kn
        cosang = (u * v).sum(-1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)
        knee.append(np.degrees(np.arccos(np.clip(cosang, -1, 1))))
    knee = np.maximum(*knee)
    held = (contact.min(-1) > 0.5) & (knee < 5.0)
    assert held.any(axis=1).mean() > 0.8, "most windows must contain a held calibration pose"
    low = P[..., [J["left_foot"], J["right_foot"]], 2]
    on_soles = ds.FOOT_CLEARANCE + sk.SOLE / b["stature"].astype(np.float64)[:, None, None]
    assert np.abs((low - on_soles)[held]).max() < 0.01               # both balls on the floor
    # arms: T-pose (near horizontal) or A-pose (30-50 degrees down)
    arm = P[..., J["left_elbow"], :] - P[..., J["left_shoulder"], :]
    elev = np.degrees(np.arcsin(arm[..., 2] / np.linalg.norm(arm, axis=-1)))[held]
    assert ((elev > -22) & (elev < 16) | (elev < -25) & (elev > -60)).mean() > 0.9


def test_calibration_pose_shapes_and_ranges():
    q = ds.calibration_pose(np.random.default_rng(0), 200)
    assert q.shape == (200, sk.NUM_JOINTS, 4) and np.allclose(np.linalg.norm(q, axis=-1), 1.0)
    R = rot.quat_to_matrix(q)
    P, _ = sk.forward_kinematics(R, np.zeros((200, 3)), sk.make_body(1.75))
    knee = np.degrees(rot.geodesic_angle(R[:, J["left_knee"]], np.eye(3)))
    assert knee.max() <= 4.0 + 1e-6


def test_arm_mix_swaps_only_the_arms_between_windows():
    cs = _moving_clipset(n=4)
    off = dict(speed=(1, 1), stature=None, segment=0.0, floor=0.0, mirror=0.0, pos_noise=0.0, rot_noise_deg=0.0,
               hand_offset_deg=0.0, head_offset=0.0, edge_prob=0.0, calibration=0.0, dropout=0.0)
    plain = ds.WindowSampler(cs, window=12, augment=ds.Augment(arm_mix=0.0, **off), seed=0)
    mixed = ds.WindowSampler(cs, window=12, augment=ds.Augment(arm_mix=1.0, **off), seed=0)
    a, b = plain.sample(16, np.random.default_rng(4)), mixed.sample(16, np.random.default_rng(4))
    legs = [J[n] for n in ("pelvis", "left_hip", "left_knee", "left_ankle", "right_knee", "right_ankle", "head")]
    assert np.abs(a["pos"][:, :, legs] - b["pos"][:, :, legs]).max() < 1e-5       # legs, torso, head kept
    wrists = [J["left_wrist"], J["right_wrist"]]
    moved = np.linalg.norm(a["pos"][:, :, wrists] - b["pos"][:, :, wrists], axis=-1).max(axis=(1, 2))
    assert (moved > 0.02).mean() > 0.8                                           # arms from elsewhere


def test_tracking_gaps_are_bridged_or_frozen():
    rng = np.random.default_rng(1)
    B, W = 200, 30
    t = np.linspace(0, 1, W)
    pos = np.broadcast_to(np.stack([t, t ** 2, np.zeros(W)], -1), (B, W, 3)).copy()
    R = rot.axis_angle_to_matrix(np.broadcast_to((t[:, None] * np.array([0, 0, 1.0])), (B, W, 3)).copy())
    p2, R2 = ds.tracking_gaps(rng, pos, R, 0.5, 30.0)
    changed = np.abs(p2 - pos).max(axis=(1, 2)) > 1e-9
    assert 0.35 < changed.mean() < 0.65
    for b in np.nonzero(changed)[0]:
        d = np.nonzero(np.abs(p2[b] - pos[b]).max(-1) > 1e-9)[0]
        g0, g1 = d.min(), d.max() + 1
        assert 3 <= g1 - g0 + 1 and g1 - g0 <= 16 and g0 >= 1 and g1 <= W - 1
        seg = p2[b, g0 - 1:g1 + 1]
        frozen = np.allclose(seg[:-1], seg[0])
        linear = np.allclose(np.diff(seg, 2, axis=0), 0.0, atol=1e-12)
        assert frozen or linear


def test_lying_lays_whole_bodies_on_the_floor_and_only_when_asked():
    """Augment.lying: the body lies on the floor (trunk low and near horizontal, no joint under
    the floor, not propped up by its limbs), its limbs keep their motion, contacts are measured
    again; with lying=0 the batches are exactly those of before (no extra random draws)."""
    cs = _standing_clipset(bodies=(1.6, 1.75, 1.9))
    off = dict(speed=(1, 1), stature=None, segment=0.0, floor=0.0, mirror=0.0, pos_noise=0.0, rot_noise_deg=0.0,
               hand_offset_deg=0.0, head_offset=0.0, edge_prob=0.0, calibration=0.0, dropout=0.0, arm_mix=0.0)
    plain = ds.WindowSampler(cs, window=20, augment=ds.Augment(lying=0.0, **off), seed=0)
    lying = ds.WindowSampler(cs, window=20, augment=ds.Augment(lying=1.0, **off), seed=0)
    a, b = plain.sample(48, np.random.default_rng(7)), lying.sample(48, np.random.default_rng(7))
    P, Q = a["pos"].astype(np.float64), b["pos"].astype(np.float64)       # canonical, statures, z up
    assert np.percentile(P[..., J["head"], 2], 5) > 0.75                   # standing: head high
    laid = np.median(Q[..., J["pelvis"], 2], axis=1) < 0.3
    assert laid.mean() > 0.25, laid.mean()                                # a window may stay upright, not most
    Q, P = Q[laid], P[laid]
    assert Q[..., J["head"], 2].max() < 0.35                                # flat on the floor, not propped up
    assert Q[..., 2].min() >= ds.LYING_CLEARANCE - 1e-4
    trunk_low = Q[:, :, ds.LYING_TRUNK, 2].min(-1)
    assert trunk_low.min() >= ds.LYING_TRUNK_CLEARANCE - 1e-4
    assert trunk_low.max() <= ds.LYING_TRUNK_CLEARANCE + ds.LYING_MAX_PROP + 1e-4
    axis = Q[..., J["neck"], :] - Q[..., J["pelvis"], :]
    tilt = np.degrees(np.arccos(np.clip(axis[..., 2] / np.linalg.norm(axis, axis=-1), -1, 1)))
    assert np.percentile(tilt, 5) > 60 and np.percentile(tilt, 95) < 110     # lying, not standing
    # the limbs keep their motion relative to the pelvis (a rigid turn of the whole body)
    def rel(X, j):
        return np.linalg.norm(X[..., j, :] - X[..., J["pelvis"], :], axis=-1)
    for j in (J["left_wrist"], J["right_ankle"], J["head"]):
        assert np.allclose(rel(P, j), rel(Q, j), atol=1e-4)
    # contacts come from the new motion (the targets' contact block) and are 0/1
    sl = features.output_slices()["contact"]
    assert set(np.unique(b["y"][..., sl])) <= {0.0, 1.0}
    # lying=0 draws nothing: the same batch as a sampler without the field
    moving = _moving_clipset(n=3)
    a = ds.WindowSampler(moving, window=20, augment=ds.Augment(lying=0.0), seed=0).sample(16, np.random.default_rng(7))
    again = ds.WindowSampler(moving, window=20, augment=ds.Augment(), seed=0).sample(16, np.random.default_rng(7))
    assert np.array_equal(again["x"], a["x"]) and np.array_equal(again["y"], a["y"])


def _rest_windows(statures, W):
    """``(local (B, W, 22, 3, 3), root (B, W, 3), offsets (B, 22, 3), stature (B,))``: default
    bodies of ``statures`` standing in the rest pose for ``W`` frames."""
    bodies = [sk.make_body(s) for s in statures]
    local = np.broadcast_to(np.eye(3), (len(bodies), W, sk.NUM_JOINTS, 3, 3)).copy()
    root = np.stack([np.tile(b.root_rest, (W, 1)) for b in bodies])
    return local, root, np.stack([b.offsets for b in bodies]), np.array(statures, float)


def _reposed_rest_windows(field, seed):
    """Rest-pose windows of three bodies (1.6, 1.75, 1.9 m, 40 frames) through one augmentation
    (``Augment.<field> = 1``, its ``WindowSampler._<field>`` method, ``rng`` seeded ``seed``):
    ``(clipset, rng, (local, root, offsets, stature), (new local, new root), P before, P after)``
    with P ``(3, 40, 22, 3)``."""
    cs = _standing_clipset(bodies=(1.6, 1.75, 1.9), T=60)
    smp = ds.WindowSampler(cs, window=40, augment=ds.Augment(**{field: 1.0}), seed=0)
    rng = np.random.default_rng(seed)
    local, root, offsets, stature = _rest_windows((1.6, 1.75, 1.9), 40)
    loc2, root2 = getattr(smp, "_" + field)(rng, local, root, offsets, stature)
    P0, P1 = ds._window_fk(local, root, offsets)[0], ds._window_fk(loc2, root2, offsets)[0]
    return cs, rng, (local, root, offsets, stature), (loc2, root2), P0, P1


def test_crouch_sinks_the_pelvis_onto_planted_feet():
    """Augment.crouch: the pelvis sinks (and the trunk leans forward), the legs fold as hinges
    onto the feet where they were; nothing changes with crouch=0."""
    cs, rng, (local, root, offsets, stature), (loc2, root2), P0, P1 = _reposed_rest_windows("crouch", 2)
    drop = (P0[..., 0, 2] - P1[..., 0, 2]) / stature[:, None]
    assert drop.max() > 0.07 and drop.max() <= ds.CROUCH_DEPTH[1] + 1e-9 and drop.min() >= -1e-9
    ankles = [J["left_ankle"], J["right_ankle"]]
    assert np.abs(P1[:, :, ankles] - P0[:, :, ankles]).max() < 1e-6          # feet stay planted
    deep = drop > 0.05
    knee = np.degrees(rot.geodesic_angle(loc2[:, :, J["left_knee"]], np.eye(3)))
    assert (knee[deep] > 20).all()                                           # the legs fold ...
    from blender_manikin.core import limb_solver as ls
    R = loc2[:, :, J["left_knee"]]
    b = R @ ls.A0[2]
    assert np.abs(b @ ls.H0[2]).max() < 1e-9                                  # ... as hinges
    lean = P1[..., J["neck"], 1] - P1[..., 0, 1]                              # neck ahead (-Y) of the pelvis
    assert (lean[deep] < -0.01).all()
    plain = ds.WindowSampler(cs, window=40, augment=ds.Augment(crouch=0.0), seed=0)
    assert plain._crouch(rng, local, root, offsets, stature)[0] is local


def test_stoop_bends_the_trunk_over_straight_legs_onto_planted_feet():
    """Augment.stoop: the trunk pitches forward at the hips and through the spine, the head goes
    low and ahead, the legs stay nearly straight (unlike a crouch) as hinges on the feet where they
    were, the pelvis moves back; nothing changes with stoop=0."""
    cs, rng, (local, root, offsets, stature), (loc2, root2), P0, P1 = _reposed_rest_windows("stoop", 3)
    ankles = [J["left_ankle"], J["right_ankle"]]
    assert np.abs(P1[:, :, ankles] - P0[:, :, ankles]).max() < 1e-6          # feet stay planted
    trunk = P1[..., J["neck"], :] - P1[..., 0, :]
    bend = np.degrees(np.arctan2(-trunk[..., 1], trunk[..., 2]))             # forward (-Y) from upright
    held = bend > 20
    assert held.sum() > 10 and bend.max() <= ds.Augment().stoop_bend[1] + 1.0 and bend.min() > -1.0
    head_drop = (P0[..., J["head"], 2] - P1[..., J["head"], 2]) / stature[:, None]
    assert (head_drop[bend > 60] > 0.1).all()                                # the head goes low ...
    assert (P1[..., J["head"], 1] - P1[..., 0, 1])[held].max() < -0.05     # ... and ahead of the pelvis
    assert ((P1[..., 0, 1] - P0[..., 0, 1])[held] > 0.0).all()              # the pelvis moves back
    # the pelvis only sinks as far as straight legs need: far less than a crouch
    assert ((P0[..., 0, 2] - P1[..., 0, 2]) / stature[:, None]).max() < 0.1
    knee = np.degrees(rot.geodesic_angle(loc2[:, :, J["left_knee"]], np.eye(3)))
    assert knee.max() < 35.0                                                 # the legs stay nearly straight
    still = (loc2[:, :, 0] == local[:, :, 0]).all((-1, -2))                  # frames outside the hold
    assert still.any() and np.abs(P1[still] - P0[still]).max() < 1e-6      # untouched outside the hold
    from blender_manikin.core import limb_solver as ls
    b = loc2[:, :, J["left_knee"]] @ ls.A0[2]
    assert np.abs(b @ ls.H0[2]).max() < 1e-9                                  # hinge knees
    plain = ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=0.0), seed=0)
    assert plain._stoop(rng, local, root, offsets, stature)[0] is local
    # sampled batches stay finite with everything on
    both = ds.WindowSampler(cs, window=20, augment=ds.Augment(stoop=0.5, crouch=0.5, lying=0.3), seed=0)
    batch = both.sample(16, np.random.default_rng(1))
    assert all(np.isfinite(v).all() for v in batch.values() if isinstance(v, np.ndarray))


def test_stoop_knees_bend_a_stoop_into_a_semi_squat():
    """Augment.stoop_knees: a stoop's knees may bend as far as a semi-squat (as people mostly
    lift things off the floor), the pelvis sinking with them, the legs still hinges on the
    planted feet; the default keeps them nearly straight; a share outside 0-0.6 is refused."""
    cs = _standing_clipset(bodies=(1.6, 1.75, 1.9), T=60)
    ankles = [J["left_ankle"], J["right_ankle"]]
    from blender_manikin.core import limb_solver as ls
    knees, sinks = {}, {}
    for share in (0.03, 0.45):
        smp = ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=1.0, stoop_knees=share), seed=0)
        k, d = [], []
        for seed in range(8):
            local, root, offsets, stature = _rest_windows((1.6, 1.75, 1.9), 40)
            loc2, root2 = smp._stoop(np.random.default_rng(seed), local, root, offsets, stature)
            P0, P1 = ds._window_fk(local, root, offsets)[0], ds._window_fk(loc2, root2, offsets)[0]
            assert np.abs(P1[:, :, ankles] - P0[:, :, ankles]).max() < 1e-6      # feet stay planted
            b = loc2[:, :, J["left_knee"]] @ ls.A0[2]
            assert np.abs(b @ ls.H0[2]).max() < 1e-9                              # hinge knees
            k.append(np.degrees(rot.geodesic_angle(loc2[:, :, J["left_knee"]], np.eye(3))).max(1))
            d.append(((P0[..., 0, 2] - P1[..., 0, 2]) / stature[:, None]).max(1))
        knees[share], sinks[share] = np.concatenate(k), np.concatenate(d)
    assert knees[0.03].max() < 35.0                                       # nearly straight by default
    assert knees[0.45].max() > 90.0 and np.median(knees[0.45]) > 50.0       # a semi-squat
    assert knees[0.45].max() < 130.0
    assert np.median(sinks[0.45]) > 2 * np.median(sinks[0.03])            # the pelvis sinks with them
    for bad in (-0.01, 0.61):
        with pytest.raises(ValueError, match="stoop_knees"):
            ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=1.0, stoop_knees=bad), seed=0)


def test_stoop_bend_folds_past_horizontal_and_stoop_look_lifts_the_head():
    """Augment.stoop_bend sets how far the trunk bends (past 90°: a full forward fold, the head
    below the hips); Augment.stoop_look has the neck and head take part of the bend back (the
    face turns up towards what the hands reach for) without moving the arms."""
    cs = _standing_clipset(bodies=(1.6, 1.75, 1.9), T=60)
    ankles = [J["left_ankle"], J["right_ankle"]]

    def stooped(**kw):
        smp = ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=1.0, stoop_bend=(110.0, 125.0), **kw), seed=0)
        local, root, offsets, stature = _rest_windows((1.6, 1.75, 1.9), 40)
        loc2, root2 = smp._stoop(np.random.default_rng(4), local, root, offsets, stature)
        P0 = ds._window_fk(local, root, offsets)[0]
        P1, R1 = ds._window_fk(loc2, root2, offsets)
        assert np.abs(P1[:, :, ankles] - P0[:, :, ankles]).max() < 1e-6          # feet stay planted
        return P1, R1

    P, R = stooped()
    trunk = P[..., J["neck"], :] - P[..., 0, :]
    bend = np.degrees(np.arctan2(-trunk[..., 1], trunk[..., 2]))            # forward (-Y) from upright
    full = bend > 100
    assert full.sum() >= 5 and bend.max() < 126.0
    assert (P[..., J["head"], 2] < P[..., 0, 2])[full].all()                 # the head below the pelvis
    face = -R[..., J["head"], :, 1]                                          # the head's forward axis
    down = np.degrees(np.arctan2(-face[..., 2], -face[..., 1]))              # below the horizontal, forward
    P2, R2 = stooped(stoop_look=1.0)
    face2 = -R2[..., J["head"], :, 1]
    down2 = np.degrees(np.arctan2(-face2[..., 2], -face2[..., 1]))
    assert (down[full] > 100).all()                                          # turned with the trunk ...
    assert np.median(down2[full]) < np.median(down[full]) - 20               # ... or looking up from it
    spine3 = J["spine3"]
    for side in ("left", "right"):                                           # the arms hang from the trunk alike
        w = J[f"{side}_wrist"]
        rel = np.einsum("...ji,...j->...i", R[..., spine3, :, :], P[..., w, :] - P[..., spine3, :])
        rel2 = np.einsum("...ji,...j->...i", R2[..., spine3, :, :], P2[..., w, :] - P2[..., spine3, :])
        assert np.abs(rel - rel2).max() < 1e-6
    for bad in ((-5.0, 90.0), (60.0, 40.0), (25.0, 170.0)):
        with pytest.raises(ValueError, match="stoop_bend"):
            ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=1.0, stoop_bend=bad), seed=0)
    with pytest.raises(ValueError, match="stoop_look"):
        ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=1.0, stoop_look=1.5), seed=0)


def test_stoop_leaves_the_pelvis_alone_for_a_leg_kicked_up():
    """A stooping window whose leg is raised above the hip (a high kick): lowering the pelvis
    would take that foot further away, so only the hanging leg sets how low the pelvis goes (an
    earlier version stepped on every leg and could throw the body metres below the floor)."""
    cs = _standing_clipset(bodies=(1.6, 1.75, 1.9), T=60)
    smp = ds.WindowSampler(cs, window=40, augment=ds.Augment(stoop=1.0), seed=0)
    local, root, offsets, stature = _rest_windows((1.6, 1.75, 1.9), 40)
    kick = rot.axis_angle_to_matrix(np.array([-np.radians(120.0), 0.0, 0.0]))    # thigh swung forward and up
    local[:, :, J["left_hip"]] = kick
    for seed in range(6):
        loc2, root2 = smp._stoop(np.random.default_rng(seed), local, root, offsets, stature)
        P0, P1 = ds._window_fk(local, root, offsets)[0], ds._window_fk(loc2, root2, offsets)[0]
        assert P0[..., J["left_ankle"], 2].min() > P0[..., J["left_hip"], 2].max()      # the foot is up
        assert np.isfinite(P1).all()
        sink = (P0[..., 0, 2] - P1[..., 0, 2]) / stature[:, None]
        assert sink.max() < 0.1                                              # no deeper than for straight legs
        right = J["right_ankle"]
        assert np.abs(P1[..., right, :] - P0[..., right, :]).max() < 1e-6    # the standing foot stays planted


def test_motion_groups_of_take_names():
    assert ds.motion_class("Bandai-Namco-Research-Motiondataset-1/data/dataset-1_kick_active_001.bvh") == "kick"
    assert ds.motion_class("Bandai-Namco-Research-Motiondataset-2_data_dataset-2_walk-turn-left_x_003-6e.npz") \
        == "walk-turn-left"
    assert ds.motion_class("amc/HDM_bd_kickLFront1Reps_001_120.amc") == "kickLFront"
    assert ds.motion_class("01_02.amc") is None
    assert ds.motion_group("dataset-2_run_active_017.bvh") == "run"
    assert ds.motion_group("subjects/01/01_02.amc") == "01"          # CMU: a subject's session
    assert ds.motion_group("dance.bvh") == "dance"                   # a group of one take
    assert ds.motion_group("07.bvh") == "07"


def _named_clipset(names, T=30):
    cs = _standing_clipset(T=T, bodies=(1.75,) * len(names))
    cs.names = list(names)
    return cs


def test_balance_draws_rare_classes_more_and_zero_keeps_every_frame_alike():
    names = [f"dataset-2_walk_x_{i:03d}.bvh" for i in range(3)] + ["dataset-1_kick_x_001.bvh"]
    cs = _named_clipset(names)                       # walk: 90 frames in 3 takes, kick: 30 in 1
    plain = ds.WindowSampler(cs, window=8)
    assert np.array_equal(plain.p, cs.lengths / cs.lengths.sum()) and plain.balance == 0.0
    for b, kick in ((0.5, 30 ** 0.5 / (30 ** 0.5 + 90 ** 0.5)), (1.0, 0.5)):
        s = ds.WindowSampler(cs, window=8, balance=b)
        assert s.group_shares() == pytest.approx({"walk": 1 - kick, "kick": kick})
        assert list(s.group_shares()) == ["walk", "kick"]           # largest first
        assert s.p[0] == s.p[1] == s.p[2]                           # within a class, by length
        cid, _ = s._times(6000, np.random.default_rng(1))           # the draws follow it
        assert abs(np.mean(cid == 3) - kick) < 0.03
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="balance"):
            ds.WindowSampler(cs, window=8, balance=bad)
    unnamed = _named_clipset(names)
    unnamed.names = []
    with pytest.raises(ValueError, match="take names"):
        ds.WindowSampler(unnamed, window=8, balance=0.5)
