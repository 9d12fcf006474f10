"""A headset lying on a table before it is put on (core/headset_off.py): the summary says so and
which trim leaves it out; nothing is cut by itself."""
import os

import numpy as np

from blender_manikin.core import solve as cs
from blender_manikin.core.formats import load_recording
from blender_manikin.core.headset_off import headset_off
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.rotations import axis_angle_to_quat

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def with_headset_on_a_table(rec, seconds=3.0, at_end=False):
    """``rec`` with ``seconds`` more at its start (or end): the headset lying 0.75 m up, tipped
    90° (face down on a table), the controllers held still at the performer's sides; 0.2 mm of
    tracking noise."""
    rng = np.random.default_rng(3)
    streams = {}
    for d, s in rec.streams.items():
        rate = 1.0 / np.median(np.diff(s.time))
        n = int(seconds * rate)
        if at_end:
            t = s.time[-1] + (1 + np.arange(n)) / rate
        else:
            t = s.time[0] - (n - np.arange(n)) / rate
        if d == "head":
            p = np.tile([0.6, -0.4, 0.75], (n, 1))
            q = np.tile(axis_angle_to_quat(np.array([np.pi / 2, 0.0, 0.0])), (n, 1))
        else:
            k = -1 if at_end else 0
            p, q = np.tile(s.pos[k], (n, 1)), np.tile(s.quat[k], (n, 1))
        p = p + rng.normal(0, 0.0002, p.shape)
        order = (lambda a, b: (b, a)) if at_end else (lambda a, b: (a, b))
        streams[d] = TrackerStream(d, np.concatenate(order(t, s.time)), np.concatenate(order(p, s.pos)),
                                   np.concatenate(order(q, s.quat)))
    return Recording(streams=streams, source="headset on a table", metadata=dict(rec.metadata))


def test_a_headset_on_a_table_is_pointed_out_with_its_trim():
    rec = load_recording(EXAMPLE)
    base = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert "headset lay still" not in base.summary()
    out = cs.solve_recording(with_headset_on_a_table(rec), cs.SolveSettings(fps=30.0))
    s = out.summary()
    assert "the headset lay still (0.8 m up, tipped 90°) for the first 3.0 s (not yet worn?): " \
           "Trim Start 3.0 s (--start 3.0) leaves it out" in s, s
    assert out.result.num_frames == base.result.num_frames + 90        # nothing cut by itself
    trimmed = cs.solve_recording(with_headset_on_a_table(rec), cs.SolveSettings(fps=30.0, start=3.0))
    assert "headset lay still" not in trimmed.summary()
    # the trimmed solve is the example's (the same T-pose, calibration and frames): the network's
    # context stops where the headset lay (with the table in its first windows: up to 38 cm off)
    assert trimmed.result.num_frames == base.result.num_frames
    err = np.linalg.norm(trimmed.result.positions - base.result.positions, axis=-1)
    assert np.median(err) < 0.002 and err.max() < 0.05
    end = cs.solve_recording(with_headset_on_a_table(rec, 2.5, at_end=True), cs.SolveSettings(fps=30.0))
    assert "for the last 2.5 s (taken off?): Trim End 7.0 s (--end 7.0) leaves it out" in end.summary()


def test_what_is_not_a_headset_lying_off():
    fps, T = 30.0, 150
    pos = np.tile([0.0, 0.0, 0.75], (T, 1))
    tipped = np.tile(np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]), (T, 1, 1))   # 90° about X
    assert headset_off(pos, tipped, fps) == (T, T)                  # the whole take lay there
    from blender_manikin.core.headset_off import headset_off_note
    assert headset_off_note(T, T, T, fps) == ["the headset lay still, tipped over, for the whole take (5.0 s): "
                                              "never worn?"]
    upright = np.tile(np.eye(3), (T, 1, 1))
    assert headset_off(pos, upright, fps) == (0, 0)                 # worn, standing still
    low = pos.copy()
    low[:, 2] = 0.15
    assert headset_off(low, tipped, fps) == (0, 0)                  # a performer lying on the floor
    assert headset_off(pos[:45], tipped[:45], fps) == (0, 0)        # 1.5 s: too short
    moving = pos + np.linspace(0, 1.0, T)[:, None] * np.array([1.0, 0, 0])
    assert headset_off(moving, tipped, fps) == (0, 0)               # carried
