"""Controllers in the other hands, foot trackers on the other feet, a waist tracker given a foot's role
(core/tracker_sides.py): swapped back, and only then."""
import os
import re

import numpy as np

from blender_manikin.core import solve as cs
from blender_manikin.core.formats import load_recording
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.skeleton import J

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def swapped(rec, left="left_hand", right="right_hand"):
    """``rec`` with the streams of devices ``left`` and ``right`` exchanged."""
    s = dict(rec.streams)
    L, R = s[left], s[right]
    s[left] = TrackerStream(left, R.time, R.pos, R.quat, R.valid)
    s[right] = TrackerStream(right, L.time, L.pos, L.quat, L.valid)
    return Recording(streams=s, source="swapped", metadata=dict(rec.metadata))


def test_controllers_in_the_other_hands_are_swapped_back():
    rec = load_recording(EXAMPLE)
    base = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert "controllers swapped back" not in base.summary()
    out = cs.solve_recording(swapped(rec), cs.SolveSettings(fps=30.0))
    assert "left and right controllers swapped back: the left one was on the performer's right on 100 %" \
        in out.summary()
    err = np.linalg.norm(out.result.positions - base.result.positions, axis=-1)
    assert err.max() < 1e-6
    kept = cs.solve_recording(swapped(rec), cs.SolveSettings(fps=30.0, fix_sides=False))
    err = np.linalg.norm(kept.result.positions - base.result.positions, axis=-1)
    assert err[:, J["left_wrist"]].mean() > 0.3          # as labelled: the arms cross


def test_hands_held_close_and_crossed_are_not_swapped():
    """A two-handed grip crosses the hands close together: below WIDE_M apart, nothing is decided."""
    from blender_manikin.core.tracker_sides import swapped_hands
    T = 300
    q = np.tile([1.0, 0, 0, 0], (T, 1))                  # head facing -Y: its left is +X
    left = np.tile([-0.10, -0.3, 1.2], (T, 1))            # the left hand 20 cm to the right
    right = np.tile([0.10, -0.3, 1.2], (T, 1))
    assert swapped_hands(q, left, right)[0] is False
    left[:, 0], right[:, 0] = -0.25, 0.25                  # 50 cm, the left on the right: swapped
    assert swapped_hands(q, left, right) == (True, 1.0, T)
    assert swapped_hands(q[:20], left[:20], right[:20])[0] is False      # under a second: undecided
    assert swapped_hands(q, right, left)[0] is False


def swapped_feet_recording(rec):
    return swapped(rec, "left_foot", "right_foot")


def test_foot_trackers_on_the_other_feet_are_swapped_back():
    """Six trackers, the foot trackers' roles mixed up: swapped back before the calibration
    measures their offsets, so the solve is the one of the take as worn."""
    from fixtures_six_trackers import body_with_legs, random_mounts, six_tracker_recording
    rec = six_tracker_recording(body_with_legs(1.75), random_mounts(1), duration=8.0, seed=1)
    base = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert "swapped back" not in base.summary()
    out = cs.solve_recording(swapped_feet_recording(rec), cs.SolveSettings(fps=30.0))
    assert "left and right foot trackers swapped back: the left one was on the performer's right on 100 %" \
        in out.summary()
    assert "controllers swapped back" not in out.summary()
    err = np.linalg.norm(out.result.positions - base.result.positions, axis=-1)
    assert err.max() < 1e-6
    kept = cs.solve_recording(swapped_feet_recording(rec), cs.SolveSettings(fps=30.0, fix_sides=False))
    err = np.linalg.norm(kept.result.positions - base.result.positions, axis=-1)
    # as labelled, the calibration takes the other foot's place for a long offset, which swings
    # the ankle off as the foot turns (here, walking in place: up to 11 cm; knees 9 cm off)
    assert err[:, J["left_ankle"]].max() > 0.08 and err[:, J["left_knee"]].mean() > 0.05


def _yaw_quat(deg):
    from blender_manikin.core.rotations import axis_angle_to_quat
    deg = np.asarray(deg, np.float64)
    return axis_angle_to_quat(np.stack([np.zeros_like(deg), np.zeros_like(deg), np.deg2rad(deg)], -1))


def test_a_stride_seen_from_a_turned_head_is_not_a_swap():
    """Walking with the head turned 90° to the left: along the headset's left axis the stride is
    sideways, half the time with the left foot 'on the right'.  The hips' axis (from a pelvis
    tracker worn at any rotation) does not turn with the head; the feet stay apart on their own
    sides.  Swapped, they are caught."""
    from blender_manikin.core.rotations import axis_angle_to_quat, quat_mul
    from blender_manikin.core.tracker_sides import body_left_axis, swapped_feet
    fps, T = 30.0, 300
    t = np.arange(T) / fps
    stride = 0.35 * np.sin(2 * np.pi * 0.9 * t)            # ± 35 cm forward (-Y) and back
    left = np.stack([np.full(T, 0.09), -stride, np.full(T, 0.1)], -1)
    right = np.stack([np.full(T, -0.09), stride, np.full(T, 0.1)], -1)
    head = _yaw_quat(np.full(T, 90.0))                      # looking over the left shoulder
    mount = np.tile(axis_angle_to_quat(np.array([0.7, -1.9, 0.4])), (T, 1))   # strapped on anyhow
    hips = _yaw_quat(5.0 * np.sin(2 * np.pi * 0.9 * t))
    pelvis = quat_mul(hips, mount)
    axis = body_left_axis(head, pelvis)
    assert np.allclose(axis[:, 2], 0) and np.allclose(np.linalg.norm(axis, axis=1), 1)
    # the hips face -Y (left +X); the head's mean turn from them is 90° here, so the averaged axis
    # is the head's: the one case it cannot tell.  Looking ahead on average, it is the hips':
    head = _yaw_quat(40.0 * np.sin(2 * np.pi * 0.1 * t))
    axis = body_left_axis(head, pelvis)
    assert np.degrees(np.arccos(np.clip(axis[:, 0], -1, 1))).max() < 7.0
    assert swapped_feet(head, left, right, pelvis, fps=fps)[0] is False
    assert swapped_feet(head, right, left, pelvis, fps=fps)[:2] == (True, 1.0)
    turned = _yaw_quat(np.full(T, 90.0))
    found, share, _ = swapped_feet(turned, left, right, fps=fps)   # the headset's axis alone
    assert found is False and 0.3 < share < 0.7
    assert swapped_feet(head, right, left, pelvis, fps=fps, valid=np.arange(T) < 50)[0] is False   # < 2 s


def test_a_waist_tracker_given_a_foot_role_is_swapped_back():
    """The pelvis tracker's stream labelled as the left foot's and the other way round: swapped
    back before the calibration, so the solve is the one of the take as worn."""
    from fixtures_six_trackers import body_with_legs, random_mounts, six_tracker_recording
    rec = six_tracker_recording(body_with_legs(1.75), random_mounts(1), duration=8.0, seed=1)
    base = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    out = cs.solve_recording(swapped(rec, "pelvis", "left_foot"), cs.SolveSettings(fps=30.0))
    assert re.search(r"pelvis and left foot trackers swapped back: the pelvis one was 0\.\d\d m below", out.summary())
    err = np.linalg.norm(out.result.positions - base.result.positions, axis=-1)
    assert err.max() < 1e-6
    kept = cs.solve_recording(swapped(rec, "pelvis", "left_foot"), cs.SolveSettings(fps=30.0, fix_sides=False))
    # as labelled: offsets of 90 cm measured, the pelvis up to 25 cm off, a foot out of reach
    assert np.linalg.norm(kept.result.positions - base.result.positions, axis=-1)[:, J["pelvis"]].max() > 0.15
    assert "left foot out of reach" in kept.summary()


def test_legs_raised_while_lying_are_not_a_role_mixup():
    from blender_manikin.core.tracker_sides import mixed_pelvis_role
    T = 100
    lying = mixed_pelvis_role(np.full(T, 0.15), {"left_foot": np.full(T, 0.35), "right_foot": np.full(T, 0.1)})
    assert lying is None                                   # a foot 20 cm above the hips
    standing_swapped = {"left_foot": np.full(T, 0.1), "right_foot": np.full(T, 1.0)}
    assert mixed_pelvis_role(np.full(T, 0.12), standing_swapped) == "right_foot"
    valid = {"right_foot": np.zeros(T, bool)}              # never tracked: nothing to compare
    assert mixed_pelvis_role(np.full(T, 0.12), standing_swapped, valid) is None
