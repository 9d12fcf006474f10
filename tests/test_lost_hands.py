"""Hands lost for long (core/lost_hands.py): the arm hangs at the side, eased in and out."""
import os

import numpy as np
import pytest

from blender_manikin.core import solve as cs
from blender_manikin.core.features import heading_yaw
from blender_manikin.core.formats import load_recording
from blender_manikin.core.lost_hands import EASE_S, RELAX_AFTER_S, relax_lost_hands, relaxed_wrists
from blender_manikin.core.pose_result import TrackerTargets
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.rotations import axis_angle_rotation
from blender_manikin.core.skeleton import J, make_body

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")
FPS = 30.0


def standing_targets(body, T, heading_deg=30.0):
    """A still performer turned ``heading_deg`` about +Z, the left hand raised in front."""
    R = axis_angle_rotation(np.array([0.0, 0.0, 1.0]), np.radians(heading_deg))
    head = body.rest_positions()[J["head"]] @ R.T
    pos = {"head": np.tile(head, (T, 1)), "left_hand": np.tile(head + R @ [0.2, -0.4, 0.0], (T, 1)),
           "right_hand": np.tile(body.rest_positions()[J["right_wrist"]] @ R.T, (T, 1))}
    rot = {d: np.tile(R, (T, 1, 1)) for d in pos}
    return TrackerTargets(fps=FPS, pos=pos, rot=rot, valid={d: np.ones(T, bool) for d in pos})


def test_a_long_gap_hangs_the_arm_and_a_short_one_keeps_the_bridge():
    body = make_body(1.75)
    T = int(8 * FPS)
    tg = standing_targets(body, T)
    lost = np.zeros(T, bool)
    lost[30:120] = True                 # 1.0-4.0 s: long
    lost[180:200] = True                # 6.0-6.67 s: short
    tg.valid["left_hand"] = ~lost
    out, notes = relax_lost_hands(tg, body)
    assert notes == ["left hand lost over 1 s on 1 stretch (3.0 s in all, from 1.0 s): the arm hangs relaxed there"]
    assert tg.pos["left_hand"][75] == pytest.approx(tg.pos["left_hand"][0])          # the input is unchanged
    np.testing.assert_array_equal(out.valid["left_hand"], ~lost)                    # still not tracked
    want_p, want_r = relaxed_wrists(tg.pos["head"], tg.rot["head"], body)["left_hand"]
    ease = int(EASE_S * FPS)
    mid = slice(30 + ease, 120 - ease)
    np.testing.assert_allclose(out.pos["left_hand"][mid], want_p[mid], atol=1e-9)
    np.testing.assert_allclose(out.rot["left_hand"][mid], want_r[mid], atol=1e-9)
    # eased: the first lost frame barely moves, the pose before and after the gap is the recording's
    assert np.linalg.norm(out.pos["left_hand"][30] - tg.pos["left_hand"][30]) < 0.02
    np.testing.assert_allclose(out.pos["left_hand"][:30], tg.pos["left_hand"][:30])
    np.testing.assert_allclose(out.pos["left_hand"][120:], tg.pos["left_hand"][120:])
    step = np.linalg.norm(np.diff(out.pos["left_hand"], axis=0), axis=-1)            # no jump: at most
    span = np.linalg.norm(want_p[75] - tg.pos["left_hand"][75])                        # a smoothstep's
    assert step.max() <= 1.5 * span / (EASE_S * FPS - 1) + 1e-9                        # peak speed
    # the relaxed wrist hangs below the shoulder, at the body's left (its heading turned 30 deg)
    rest = body.rest_positions()
    R = tg.rot["head"][0]
    shoulder = tg.pos["head"][0] + R @ (rest[J["left_shoulder"]] - rest[J["head"]])
    arm = body.limb_lengths()[0].sum()
    d = out.pos["left_hand"][75] - shoulder
    assert -d[2] == pytest.approx(0.97 * arm * np.cos(np.radians(8.0)), abs=1e-6)
    assert (R.T @ d)[0] > 0.0 and abs((R.T @ d)[1]) < 0.05
    assert heading_yaw(tg.rot["head"][0]) == pytest.approx(np.radians(30.0))
    # the short gap keeps the straight bridge; the other hand is untouched
    np.testing.assert_allclose(out.pos["left_hand"][180:200], tg.pos["left_hand"][180:200])
    assert out.pos["right_hand"] is tg.pos["right_hand"]
    # a hand lost from the start hangs up to its first sample (eased only towards it)
    tg.valid["left_hand"] = np.arange(T) >= 60
    out, _ = relax_lost_hands(tg, body)
    np.testing.assert_allclose(out.pos["left_hand"][:60 - ease], want_p[:60 - ease], atol=1e-9)
    assert relax_lost_hands(standing_targets(body, T), body)[1] == []


def test_a_solve_hangs_the_arm_of_a_hand_lost_for_seconds():
    rec = load_recording(EXAMPLE)
    t0 = rec.time_range()[0]
    st = rec.streams["left_hand"]
    valid = st.valid & ~((st.time >= t0 + 2.0) & (st.time < t0 + 5.0))
    lost = Recording(streams={**rec.streams, "left_hand": TrackerStream("left_hand", st.time, st.pos, st.quat, valid)},
                     metadata=dict(rec.metadata))
    out = cs.solve_recording(lost, cs.SolveSettings(fps=FPS))
    assert "left hand lost over 1 s on 1 stretch (3.0 s in all, from 2.0 s): the arm hangs relaxed there" \
        in out.summary()
    P = out.result.positions
    f = int(3.5 * FPS)
    want = relaxed_wrists(out.targets.pos["head"][f:f + 1], out.targets.rot["head"][f:f + 1],
                          out.body)["left_hand"][0][0]
    assert np.linalg.norm(P[f, J["left_wrist"]] - want) < 0.03                  # on the relaxed target
    upper = P[f, J["left_elbow"]] - P[f, J["left_shoulder"]]
    fore = P[f, J["left_wrist"]] - P[f, J["left_elbow"]]
    flex = np.degrees(np.arccos(upper @ fore / np.linalg.norm(upper) / np.linalg.norm(fore)))
    assert flex < 30.0 and P[f, J["left_wrist"], 2] < P[f, J["left_shoulder"], 2] - 0.4
    # the recorded hand still lands on its tracker outside the gap
    g = int(1.0 * FPS)
    assert np.linalg.norm(P[g, J["left_wrist"]] - out.result.targets.pos["left_hand"][g]) < 1e-4
    assert RELAX_AFTER_S == 1.0


@pytest.mark.parametrize("how", ["no rows", "all invalid"])
def test_a_hand_never_tracked_hangs_for_the_whole_take(how):
    """A take whose left controller was off (no rows of it) or never tracked (every sample
    invalid): the solve goes on, that arm hangs relaxed all along, the right hand lands on its
    tracker, and the summary says so.  One hand is the most that may be missing: without the
    head, or without both hands, the take is refused by name."""
    from blender_manikin.core.recording import RecordingError
    from blender_manikin.core.resample import resample
    rec = load_recording(EXAMPLE)
    st = rec.streams["left_hand"]
    streams = dict(rec.streams)
    if how == "no rows":
        del streams["left_hand"]
    else:
        streams["left_hand"] = TrackerStream("left_hand", st.time, st.pos, st.quat, np.zeros(len(st.time), bool))
    one = Recording(streams=streams, source="one_hand.csv", metadata=dict(rec.metadata))
    times, pos, quat, valid, report = resample(one, FPS)
    assert not valid["left_hand"].any() and valid["right_hand"].mean() > 0.95
    assert np.isfinite(pos["left_hand"]).all() and "left_hand" in report.devices
    assert any("left hand: no usable sample in the take" in w for w in report.warnings)
    out = cs.solve_recording(one, cs.SolveSettings(fps=FPS))
    summary = out.summary()
    assert "left hand lost over 1 s on 1 stretch (7.0 s in all, from 0.0 s): the arm hangs relaxed there" in summary
    P = out.result.positions
    assert (P[:, J["left_wrist"], 2] < P[:, J["left_shoulder"], 2] - 0.4).all()        # hanging, every frame
    right = np.linalg.norm(P[:, J["right_wrist"]] - out.result.targets.pos["right_hand"], axis=-1)
    assert np.median(right) < 1e-4
    for gone in (("left_hand", "right_hand"), ("head",)):
        rest = Recording(streams={d: s for d, s in streams.items() if d not in gone}, source="few.csv",
                         metadata=dict(rec.metadata))
        with pytest.raises(RecordingError, match="few.csv: the recording has no"):
            resample(rest, FPS)
