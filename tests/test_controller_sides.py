"""Controllers held in the other hands (core/controller_sides.py): swapped back, and only then."""
import os

import numpy as np

from blender_manikin.core import solve as cs
from blender_manikin.core.formats import load_recording
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.skeleton import J

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def swapped(rec):
    s = dict(rec.streams)
    L, R = s["left_hand"], s["right_hand"]
    s["left_hand"] = TrackerStream("left_hand", R.time, R.pos, R.quat, R.valid)
    s["right_hand"] = TrackerStream("right_hand", L.time, L.pos, L.quat, L.valid)
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
    from blender_manikin.core.controller_sides import swapped_hands
    T = 300
    q = np.tile([1.0, 0, 0, 0], (T, 1))                  # head facing -Y: its left is +X
    left = np.tile([-0.10, -0.3, 1.2], (T, 1))            # the left hand 20 cm to the right
    right = np.tile([0.10, -0.3, 1.2], (T, 1))
    assert swapped_hands(q, left, right)[0] is False
    left[:, 0], right[:, 0] = -0.25, 0.25                  # 50 cm, the left on the right: swapped
    assert swapped_hands(q, left, right) == (True, 1.0, T)
    assert swapped_hands(q[:20], left[:20], right[:20])[0] is False      # under a second: undecided
    assert swapped_hands(q, right, left)[0] is False
