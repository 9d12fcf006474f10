"""Pipeline building blocks that do not need the network."""
import numpy as np

from blender_manikin.core import pipeline as pl
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk


def test_resample_pose_targets_linear_and_slerp():
    T = 31
    t = np.arange(T) / 30.0
    pos = np.stack([t, 2 * t, 0 * t], -1)
    R = rot.axis_angle_to_matrix(np.stack([0 * t, 0 * t, t], -1))
    p, r, t_in, t_out = pl.resample_pose_targets(pos, R, 30.0, 90.0)
    assert np.isclose(t_out[-1], 1.0) and len(t_out) == 91
    assert np.allclose(p[:, 0], t_out) and np.allclose(p[:, 1], 2 * t_out)
    assert np.allclose(rot.matrix_to_axis_angle(r)[:, 2], t_out, atol=1e-9)


def test_lock_planted_feet_holds_position_during_contact():
    T = 60
    ankle = np.zeros((T, 2, 3))
    ankle[:, 0, 0] = np.linspace(0, 0.3, T)          # left foot slides 30 cm
    ankle[:, 1, 1] = np.linspace(0, 0.1, T)
    contact = np.zeros((T, 2))
    contact[20:40, 0] = 0.9
    out = pl.lock_planted_feet(ankle, contact, max_drift=1.0)
    assert np.ptp(out[20:40, 0, 0]) == 0.0               # no slide while planted
    ease = round(pl.CONTACT_BLEND_S * 30)
    assert np.allclose(out[:20 - ease, 0], ankle[:20 - ease, 0])    # untouched away from the contact
    assert np.allclose(out[:, 1], ankle[:, 1])            # other foot never planted
    step = np.abs(np.diff(out[:, 0, 0]))
    assert step.max() < 0.05                             # eased in and out, no pop


def test_lock_never_holds_a_shuffling_foot_far_from_the_prediction():
    """A foot the network calls planted while its predicted position walks 1 m in 10 s (a slow
    shuffle) is held in successive short plants that stay with the prediction."""
    T = 300
    ankle = np.zeros((T, 2, 3))
    ankle[:, :, 1] = np.linspace(0, -1.0, T)[:, None]
    ankle[:, :, 2] = 0.08
    contact = np.ones((T, 2))
    out = pl.lock_planted_feet(ankle, contact, axes=(0, 1))
    off = np.linalg.norm(out[..., :2] - ankle[..., :2], axis=-1)
    assert off.max() <= pl.LOCK_MAX_DRIFT + 1e-9
    steps = np.abs(np.diff(out[:, 0, 1]))
    assert (steps < 1e-12).mean() > 0.5                  # still held most of the time
    # a really planted foot with 1 cm of prediction noise is held at one spot
    rng = np.random.default_rng(0)
    still = np.zeros((T, 2, 3)) + rng.normal(scale=0.005, size=(T, 2, 3))
    held = pl.lock_planted_feet(still, contact)
    assert np.ptp(held[:, 0, 0]) == 0.0 and np.ptp(held[:, 1, 1]) == 0.0


def test_lock_planted_feet_horizontal_only_keeps_the_predicted_height():
    """The pipeline locks x, y (sliding) and leaves z to the network (the knee depends on it)."""
    T = 60
    ankle = np.zeros((T, 2, 3))
    ankle[:, 0, 0] = np.linspace(0, 0.3, T)
    ankle[:, 0, 2] = 0.08 + 0.01 * np.sin(np.linspace(0, 6, T))
    contact = np.zeros((T, 2))
    contact[20:40, 0] = 0.9
    out = pl.lock_planted_feet(ankle, contact, axes=pl.LOCK_AXES, max_drift=1.0)
    assert pl.LOCK_AXES == (0, 1)
    assert np.ptp(out[20:40, 0, 0]) == 0.0 and np.ptp(out[20:40, 0, 1]) == 0.0
    assert np.allclose(out[:, 0, 2], ankle[:, 0, 2])


def test_lock_eases_last_a_time_and_never_overlap_between_close_plants():
    """The ease into and out of a plant lasts CONTACT_BLEND_S seconds whatever the frame rate, and
    two plants a short swing apart share the swing: the foot moves one way, without a fold."""
    def ease_frames(fps):
        T = int(2 * fps)
        ankle = np.zeros((T, 2, 3))
        ankle[:, 0, 0] = np.linspace(0, 0.5, T)
        contact = np.zeros((T, 2))
        contact[T // 2:, 0] = 0.9
        out = pl.lock_planted_feet(ankle, contact, max_drift=1.0, fps=fps)
        return int((np.abs(out[:T // 2, 0, 0] - ankle[:T // 2, 0, 0]) > 1e-12).sum())
    assert ease_frames(30.0) == round(pl.CONTACT_BLEND_S * 30)
    assert ease_frames(60.0) == round(pl.CONTACT_BLEND_S * 60)
    # two plants 4 frames apart, the foot stepping 10 cm forward between them
    T = 60
    ankle = np.zeros((T, 2, 3))
    ankle[:, 0, 0] = np.clip((np.arange(T) - 28) / 4.0, 0, 1) * 0.1
    contact = np.zeros((T, 2))
    contact[10:28, 0] = contact[32:50, 0] = 0.9
    out = pl.lock_planted_feet(ankle, contact, max_drift=0.2, blend_s=0.2, fps=30.0)   # 6 frames
    x = out[:, 0, 0]
    assert np.ptp(x[10:28]) == 0.0 and np.ptp(x[32:50]) == 0.0
    assert np.isclose(x[20], 0.0) and np.isclose(x[40], 0.1)
    assert (np.diff(x) >= -1e-12).all()                  # forward only: the eases did not overlap


def _knee_flexion(d, thigh, shank):
    """Knee flexion (radians) of a two-bone leg whose hip and ankle are ``d`` apart."""
    d = np.minimum(d, thigh + shank)
    return np.pi - np.arccos(np.clip((thigh ** 2 + shank ** 2 - d ** 2) / (2 * thigh * shank), -1, 1))


def test_soften_leg_reach_keeps_a_knee_at_full_stretch_from_popping():
    """An ankle target that hovers around the leg's reach (5 mm noise) flickers the knee between
    straight and 10-15 degrees bent; the softened target keeps the knee's frame-to-frame change
    small, stays within reach, keeps the direction from the hip and moves a bent leg little."""
    rng = np.random.default_rng(3)
    T, thigh, shank = 90, 0.45, 0.43
    L = thigh + shank
    hips = np.zeros((T, 2, 3))
    hips[:, :, 2] = 0.95
    hips[:, 1, 0] = 0.2
    direction = rot.normalize(np.stack([np.full(T, 0.1), np.zeros(T), -np.ones(T)], -1))
    d = np.stack([L + rng.normal(scale=0.005, size=T),                   # left: at full stretch
                  0.8 + 0.02 * np.sin(np.linspace(0, 3, T))], 1)        # right: bent, smooth
    ankles = hips + d[..., None] * direction[:, None]
    sigma = pl.LEG_REACH_SMOOTH_S * 30.0
    soft = pl.soften_leg_reach(hips, ankles, np.array([L, L]), sigma)
    v = soft - hips
    ds = np.linalg.norm(v, axis=-1)
    assert ds.max() <= L + 1e-12
    assert np.allclose(rot.normalize(v), direction[:, None].repeat(2, 1))
    raw_pop = np.abs(np.diff(_knee_flexion(d[:, 0], thigh, shank))).max()
    soft_pop = np.abs(np.diff(_knee_flexion(ds[:, 0], thigh, shank))).max()
    assert np.degrees(raw_pop) > 8.0 and soft_pop < 0.5 * raw_pop
    assert np.abs(ds[:, 1] - d[:, 1]).max() < 1e-3                      # a smooth bent leg: as it was
    assert np.array_equal(pl.soften_leg_reach(hips, ankles, np.array([L, L]), 0.0), ankles)


def test_keep_feet_above_floor():
    body = sk.make_body(1.75)
    T = 5
    ankle = np.zeros((T, 2, 3))
    ankle[:, :, 2] = np.array([-0.1, 0.0, 0.02, 0.05, 0.3])[:, None]
    # toes pointing down 60 degrees
    R = np.broadcast_to(rot.axis_angle_to_matrix(np.array([-1.0, 0, 0])), (T, 2, 3, 3))
    out = pl.keep_feet_above_floor(ankle, R, body)
    ball = out + np.einsum("tkij,kj->tki", R, body.offsets[[sk.J["left_foot"], sk.J["right_foot"]]])
    assert ball[..., 2].min() >= -1e-12 and out[..., 2].min() > 0
    assert np.allclose(out[-1], ankle[-1])


def test_feet_keep_ball_and_heel_at_their_standing_height():
    """A flat foot the network put 2 cm into the floor comes up to its rest ankle height (less
    FOOT_SINK); turned toes up it stands on its heel, toes down on its ball, both at their rest
    height; a foot in the air is left; feet_below_floor measures what is left sunk."""
    body = sk.make_body(1.75)
    k = [sk.J["left_foot"], sk.J["right_foot"]]
    rest = body.rest_positions()
    ankle_rest, ball_rest = rest[[sk.J["left_ankle"], sk.J["right_ankle"]], 2], rest[k, 2]
    pitches = np.radians([0.0, -25.0, 25.0, 0.0])            # about x: - toes up (the feet face -y)
    T = len(pitches)
    R = np.broadcast_to(rot.axis_angle_to_matrix(pitches[:, None] * [1.0, 0, 0])[:, None], (T, 2, 3, 3))
    ankle = np.zeros((T, 2, 3))
    ankle[:, :, 2] = ankle_rest - 0.02
    ankle[-1, :, 2] = 0.4                                      # in the air
    sunk = pl.feet_below_floor(ankle, R, body)
    assert np.allclose(sunk[0], 0.02) and (sunk[1:3] > 0.02).all() and (sunk[-1] == 0).all()
    out = pl.keep_feet_above_floor(ankle, R, body)
    assert np.allclose(out[0, :, 2], ankle_rest - pl.FOOT_SINK)
    assert np.allclose(out[-1], ankle[-1]) and np.allclose(out[..., :2], ankle[..., :2])
    ball = out + np.einsum("tkij,kj->tki", R, body.offsets[k])
    heel_off = body.offsets[k] * [-pl.HEEL_BACK, -pl.HEEL_BACK, 1.0]
    heel = out + np.einsum("tkij,kj->tki", R, heel_off)
    assert np.allclose(heel[1, :, 2], ball_rest - pl.FOOT_SINK) and (ball[1, :, 2] > ball_rest + 0.04).all()
    assert np.allclose(ball[2, :, 2], ball_rest - pl.FOOT_SINK) and (heel[2, :, 2] > ball_rest + 0.01).all()
    assert (out[1:3, :, 2] > ankle_rest).all()                 # a tilted foot lifts its ankle
    assert pl.feet_below_floor(out, R, body).max() <= pl.FOOT_SINK + 1e-12


def test_reach_collars_brings_far_hand_within_reach():
    body = sk.make_body(1.75)
    T = 3
    local = np.broadcast_to(np.eye(3), (T, 22, 3, 3)).copy()
    root = np.tile(body.root_rest, (T, 1))
    pos, _ = sk.forward_kinematics(local, root, body)
    L = body.limb_lengths()[0].sum()
    sh = pos[:, sk.J["left_shoulder"]]
    wrists = np.stack([sh + [0.0, -(L + 0.02), 0.0], pos[:, sk.J["right_wrist"]]], 0)
    pos0, world0 = (np.array(a) for a in sk.forward_kinematics(local, root, body))
    new = pl._reach_collars(local.copy(), pos0, world0, wrists, body)
    assert np.allclose(pos0[:, sk.J["left_shoulder"]],
                       sk.forward_kinematics(new, root, body)[0][:, sk.J["left_shoulder"]])
    pos2, _ = sk.forward_kinematics(new, root, body)
    d = np.linalg.norm(wrists[0] - pos2[:, sk.J["left_shoulder"]], axis=-1)
    assert np.all(d <= L + 1e-9)
    assert np.allclose(new[:, sk.J["right_collar"]], np.eye(3))


def test_quality_notes_name_what_gave_way():
    from blender_manikin.core.pose_result import PoseResult
    body = sk.make_body(1.75)
    T = 10
    reach = np.zeros((T, 4))
    reach[3:5, 1] = [0.02, 0.034]                      # right hand 3.4 cm beyond the arm
    reach[6, 0] = 0.001                                # 1 mm: within tolerance
    lim = np.zeros((T, 4), bool)
    lim[2:9, 2] = True
    res = PoseResult(fps=30.0, body=body, local_rot=np.broadcast_to(np.eye(3), (T, 22, 3, 3)),
                     root_pos=np.zeros((T, 3)), swivel=np.zeros((T, 4)), reach_error=reach, at_limit=lim)
    notes = res.quality_notes()
    assert notes == ["right hand out of reach on 2 frame(s), by up to 3.4 cm (check the body size)",
                     "left leg swivel held at the hip's rotation limit on 7 frame(s)"]
    clean = PoseResult(fps=30.0, body=body, local_rot=res.local_rot, root_pos=res.root_pos,
                       swivel=res.swivel, reach_error=np.zeros((T, 4)), at_limit=np.zeros((T, 4), bool))
    assert clean.quality_notes() == []


def test_plant_pieces_match_the_plain_greedy_split():
    """Plants are split where the predicted ankle drifts further than the tolerance; the search in
    doubling windows (linear time on long plants) finds the same pieces as a scan of the rest."""
    def plain(path, a, b, tol):
        pieces, i = [], a
        while i < b:
            far = np.nonzero(np.linalg.norm(path[i:b] - path[i], axis=-1) > tol)[0]
            j = i + (int(far[0]) if far.size else b - i)
            pieces.append((i, j))
            i = j
        return pieces
    rng = np.random.default_rng(0)
    for n in (1, 5, 63, 64, 65, 500, 5000):
        path = np.cumsum(rng.normal(scale=0.004, size=(n, 2)), 0)
        for a, b in ((0, n), (n // 3, n)):
            assert pl._plant_pieces(path, a, b, 0.05) == plain(path, a, b, 0.05), (n, a, b)


def test_settle_planted_feet_puts_hovering_planted_feet_down():
    """A planted foot the network leaves 2 cm up comes down onto the floor (eased, no jump);
    a foot held higher than SETTLE_MAX, or not planted, is left where it is."""
    body = sk.make_body(1.75)
    T, fps = 90, 30.0
    rest = body.rest_positions()[[sk.J["left_ankle"], sk.J["right_ankle"]], 2]
    ankle = np.zeros((T, 2, 3))
    ankle[:, :, 2] = rest + np.array([0.02, pl.SETTLE_MAX + 0.03])      # left hovers, right is high
    R = np.broadcast_to(np.eye(3), (T, 2, 3, 3))
    contacts = np.zeros((T, 2), bool)
    contacts[20:70] = True
    out = pl.settle_planted_feet(ankle, R, contacts, body, fps)
    assert np.allclose(out[35:55, 0, 2], rest[0], atol=1e-3)           # on the floor mid-plant
    assert np.allclose(out[:5, 0, 2], ankle[:5, 0, 2])                  # untouched well before
    assert np.allclose(out[:, 1], ankle[:, 1])                          # too high: left alone
    assert np.abs(np.diff(out[:, 0, 2])).max() < 0.004                   # eased in and out
    assert (out[..., 2] >= rest - 1e-9).all()                            # never into the floor
    assert np.allclose(out[..., :2], ankle[..., :2])                     # height only
