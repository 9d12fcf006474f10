"""Teleports and snap turns (core/teleports.py): found, solved as one motion, put back.

The bundled example recording, with jumps of the tracking space put in by hand: every device
moved (a teleport) or turned about the headset's vertical (a snap turn) from a given time on.
"""
import os
import re

import numpy as np
import pytest

from blender_manikin.core import solve as cs
from blender_manikin.core.formats import load_recording
from blender_manikin.core.recording import Recording, TrackerStream
from blender_manikin.core.rotations import axis_angle_rotation, matrix_to_quat, quat_to_matrix
from blender_manikin.core.teleports import find_rig_jumps, remove_rig_jumps, unconfirmed_jumps_note

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")
Z = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def example():
    rec = load_recording(EXAMPLE)
    return rec, cs.solve_recording(rec, cs.SolveSettings(fps=30.0))


def head_at(rec, t):
    s = rec.streams["head"]
    return s.pos[np.searchsorted(s.time, t)]


def moved(rec, jumps, devices=None):
    """``rec`` with its space jumped: ``jumps`` = [(time, turn_deg, (dx, dy, dz))], each turn about
    the vertical through the head's place at that time, applied to every sample at or after it
    (only ``devices``' samples when given).  Returns the recording and the composite transforms
    ``[(time, R, t)]`` (x -> R x + t) in force from each time on."""
    streams = {d: (s.time, s.pos.copy(), quat_to_matrix(s.quat)) for d, s in rec.streams.items()}
    composite = []
    R_all, t_all = np.eye(3), np.zeros(3)
    for time, turn, shift in jumps:
        pivot = head_at(rec, time)
        pivot = R_all @ pivot + t_all
        R = axis_angle_rotation(Z, np.radians(turn))
        t = pivot - R @ pivot + np.asarray(shift, float)
        for d, (tt, p, Rm) in streams.items():
            if devices is not None and d not in devices:
                continue
            m = tt >= time
            p[m] = p[m] @ R.T + t
            Rm[m] = R @ Rm[m]
        R_all, t_all = R @ R_all, R @ t_all + t
        composite.append((time, R_all.copy(), t_all.copy()))
    out = Recording(streams={d: TrackerStream(d, tt, p, matrix_to_quat(Rm), rec.streams[d].valid)
                             for d, (tt, p, Rm) in streams.items()},
                    source="moved", metadata=dict(rec.metadata))
    return out, composite


def expected_positions(base, composite, starts):
    """The base solve's joint positions moved as the recording was, frame by frame: from each
    jump's first moved sample (``starts``) on."""
    P = base.result.positions.copy()
    times = base.result.t0 + np.arange(base.result.num_frames) / base.result.fps
    for (_, R, t), start in zip(composite, starts):
        m = times >= start
        P[m] = (base.result.positions[m] @ R.T) + t
    return P


def _found_where_made(rec, jumped, jumps):
    """The jumps :func:`find_rig_jumps` finds in ``jumped`` (``rec`` moved by ``jumps``, as
    :func:`moved` takes them): each at its time and turn, and taken out, the take is ``rec``'s
    motion again (within the head's motion in one sample)."""
    found = find_rig_jumps(jumped)
    for j, (time, turn, _) in zip(found, jumps):
        assert j.time == pytest.approx(time, abs=0.015) and j.turn_deg == pytest.approx(turn, abs=1.0)
    back = remove_rig_jumps(jumped, found)
    for d, s in back.streams.items():
        assert np.abs(s.pos - rec.streams[d].pos).max() < 0.02, d
    return found


@pytest.mark.parametrize("jumps,kinds", [
    ([(3.5, 0.0, (2.0, -1.0, 0.0))], ["teleport"]),
    ([(2.5, 45.0, (0, 0, 0)), (4.6, -30.0, (0, 0, 0))], ["snap turn", "snap turn"]),
    ([(3.0, 90.0, (-1.5, 0.5, 0.2))], ["teleport and turn"]),
])
def test_jumps_are_found_solved_as_one_motion_and_put_back(example, jumps, kinds):
    rec, base = example
    jumped, composite = moved(rec, jumps)
    found = _found_where_made(rec, jumped, jumps)
    assert [j.kind for j in found] == kinds

    keep = cs.solve_recording(jumped, cs.SolveSettings(fps=30.0))
    assert f"(first at {found[0].time:.2f} s) solved as one motion and put back" in keep.summary()
    err = np.linalg.norm(keep.result.positions - expected_positions(base, composite, [j.time for j in found]), axis=-1)
    assert np.median(err) < 0.005 and err.max() < 0.03, (np.median(err), err.max())
    # the hands still land on their trackers, which are where the recording has them
    for d, j in (("left_hand", "left_wrist"), ("right_hand", "right_wrist")):
        from blender_manikin.core.skeleton import J
        miss = np.linalg.norm(keep.result.positions[:, J[j]] - keep.result.targets.pos[d], axis=-1)
        assert np.median(miss) < 1e-4, d

    removed = cs.solve_recording(jumped, cs.SolveSettings(fps=30.0, teleports="remove"))
    assert "taken out (the path is continuous)" in removed.summary()
    err = np.linalg.norm(removed.result.positions - base.result.positions, axis=-1)
    assert np.median(err) < 0.005 and err.max() < 0.03

    # solved as recorded, the jump tears the pose apart around it
    ignored = cs.solve_recording(jumped, cs.SolveSettings(fps=30.0, teleports="ignore"))
    starts = [j.time for j in found]
    err = np.linalg.norm(ignored.result.positions - expected_positions(base, composite, starts), axis=-1)
    assert err.max() > 0.10 and "teleport" not in ignored.summary()


def test_what_is_not_a_jump_of_the_space(example):
    rec, _ = example
    assert find_rig_jumps(rec) == []
    # the head alone jumps (a tracking error of the headset): the hands did not move with it
    alone, _ = moved(rec, [(3.5, 0.0, (0.8, 0.0, 0.0))], devices=("head",))
    assert find_rig_jumps(alone) == []
    # one head sample off by 1 m that comes back (a glitch; the resampler drops it)
    s = rec.streams["head"]
    pos = s.pos.copy()
    pos[300] += [1.0, 0.0, 0.0]
    glitch = Recording(streams={**rec.streams, "head": TrackerStream("head", s.time, pos, s.quat, s.valid)})
    assert find_rig_jumps(glitch) == []
    # a whole-body spin up to 1,500 deg/s (a pirouette) turns as fast as a snap turn, but smoothly
    spin_streams = {}
    for d, st in rec.streams.items():
        t = st.time - 3.0
        angle = np.radians(np.where(t > 0, 1500.0 * np.minimum(t, 0.3) ** 2 / 0.6 + 1500.0 * np.maximum(t - 0.3, 0), 0))
        pivot = head_at(rec, 3.0) * [1, 1, 0]
        R = axis_angle_rotation(np.tile(Z, (len(t), 1)), angle)
        p = np.einsum("nij,nj->ni", R, st.pos - pivot) + pivot
        spin_streams[d] = TrackerStream(d, st.time, p, matrix_to_quat(R @ quat_to_matrix(st.quat)), st.valid)
    assert find_rig_jumps(Recording(streams=spin_streams)) == []


def test_a_bad_teleports_setting_is_refused():
    with pytest.raises(cs.SolveError, match="teleports 'sometimes': expected one of keep, remove, ignore"):
        cs.solve_recording(EXAMPLE, cs.SolveSettings(teleports="sometimes"))


def glided(rec, speed, start=1.5):
    """``rec`` with every device carried forward (-Y) at ``speed`` m/s from ``start`` s: a
    thumbstick's smooth locomotion, the performer standing in place."""
    streams = {}
    for d, s in rec.streams.items():
        p = s.pos.copy()
        p[:, 1] -= speed * np.clip(s.time - start, 0.0, None)
        streams[d] = TrackerStream(d, s.time, p, s.quat, s.valid)
    return Recording(streams=streams, source="glided", metadata=dict(rec.metadata))


def test_smooth_locomotion_is_walked(example):
    """A player carried along by a thumbstick (no teleport: the space moves smoothly) is solved as
    a body that walks with it: the feet stride and lift, where the same take in place barely
    steps; nothing is taken for a teleport."""
    from blender_manikin.core.skeleton import J
    rec, base = example
    strides = []
    for speed, out in ((0.0, base), (1.0, cs.solve_recording(glided(rec, 1.0), cs.SolveSettings(fps=30.0)))):
        assert "teleport" not in out.summary() and "snap turn" not in out.summary()
        P = out.result.positions[75:]                                    # from 2.5 s
        fwd = [np.ptp(P[:, J[a], 1] - P[:, J["pelvis"], 1]) for a in ("left_ankle", "right_ankle")]
        lift = [P[:, J[a], 2].max() - np.percentile(P[:, J[a], 2], 5) for a in ("left_ankle", "right_ankle")]
        strides.append((min(fwd), min(lift)))
    assert strides[0][0] < 0.15 and strides[1][0] > 0.4           # each foot swings 40 cm or more
    assert strides[1][1] > 0.08                                   # and lifts


@pytest.mark.parametrize("second", ["next head sample", 0.08])
def test_a_jump_right_after_another_is_measured_from_after_it(example, second):
    """A teleport, then a snap turn on the very next head sample (an app that sets the position
    and the facing in two updates), or a second teleport 0.08 s on: the head's motion before the
    second is measured after the first (across it, the first jump looked like 8 m/s of motion and
    the second was taken 9 cm and 4-5 degrees short, left in the take)."""
    rec, base = example
    head_t = rec.streams["head"].time
    if second == "next head sample":
        jumps = [(3.0, 0.0, (0.8, 0.0, 0.0)), (head_t[np.searchsorted(head_t, 3.0) + 1], 45.0, (0, 0, 0))]
    else:
        jumps = [(3.0, 0.0, (0.6, 0.0, 0.0)), (3.0 + second, 30.0, (0.0, 0.6, 0.0))]
    jumped, composite = moved(rec, jumps)
    found = _found_where_made(rec, jumped, jumps)
    assert len(found) == 2
    keep = cs.solve_recording(jumped, cs.SolveSettings(fps=30.0))
    err = np.linalg.norm(keep.result.positions - expected_positions(base, composite, [j.time for j in found]),
                         axis=-1)
    assert np.median(err) < 0.005 and np.percentile(err.max(1), 98) < 0.03


@pytest.mark.parametrize("turn,shift", [
    (0.0, (0.2, 0.0, 0.0)),         # a short teleport
    (0.0, (0.0, 0.0, -0.25)),       # the app's floor height reset (seated / standing)
    (5.0, (0.12, -0.10, 0.0)),      # a recentre or guardian reset: 16 cm and 5 degrees
])
def test_a_jump_of_the_space_under_30_cm_is_found(example, turn, shift):
    """The space moved 15-30 cm in one sample (13-23 m/s at 90 Hz, no head moves so): found and
    put back like a long teleport.  Solved as recorded, the joints were 5-33 cm off on 25-127
    frames (the 25 cm drop: 127 frames, over 4 s)."""
    rec, base = example
    jumped, composite = moved(rec, [(3.0, turn, shift)])
    found = find_rig_jumps(jumped)
    assert [j.kind for j in found] == ["teleport"] and found[0].time == pytest.approx(3.0, abs=0.015)
    assert np.abs(found[0].trans - composite[0][2]).max() < 0.02
    keep = cs.solve_recording(jumped, cs.SolveSettings(fps=30.0))
    assert "1 teleport (first at 3.01 s) solved as one motion and put back" in keep.summary()
    err = np.linalg.norm(keep.result.positions - expected_positions(base, composite, [found[0].time]), axis=-1)
    assert np.median(err) < 0.005 and np.percentile(err.max(1), 98) < 0.03


@pytest.mark.parametrize("shift", [
    (0.05, 0.0, 0.0),               # a recentre of 5 cm
    (0.0, -0.06, 0.05),             # 8 cm
    (0.08, 0.0, -0.075),            # 11 cm, the floor reset with it
])
def test_a_shift_of_the_space_under_15_cm_is_found(example, shift):
    """A recentre or floor reset of 5-11 cm (under TELEPORT_MIN_M, so not found before): the head's
    step less what its velocity just before and after carries it is the shift, and both hands'
    steps say the same; found, taken out and put back.  Solved as recorded, the feet drag and
    the joints stay off after it."""
    rec, base = example
    jumped, composite = moved(rec, [(3.0, 0.0, shift)])
    found = find_rig_jumps(jumped)
    assert [j.kind for j in found] == ["teleport"] and found[0].time == pytest.approx(3.0, abs=0.015)
    assert np.abs(found[0].trans - composite[0][2]).max() < 0.01
    back = remove_rig_jumps(jumped, found)
    for d, s in back.streams.items():
        assert np.abs(s.pos - rec.streams[d].pos).max() < 0.01, d
    keep = cs.solve_recording(jumped, cs.SolveSettings(fps=30.0))
    assert "1 teleport (first at 3.01 s)" in keep.summary()
    err = np.linalg.norm(keep.result.positions - expected_positions(base, composite, [found[0].time]), axis=-1)
    assert np.median(err) < 0.005 and np.percentile(err.max(1), 98) < 0.03


def test_what_is_not_a_small_shift_of_the_space(example):
    """Under 15 cm the hands decide: the head alone shifted 8 cm (the headset's tracking, not the
    space), or one head sample 8 cm off that comes back, or the hands alone, is no jump."""
    rec, _ = example
    for devices in (("head",), ("left_hand", "right_hand")):
        alone, _ = moved(rec, [(3.0, 0.0, (0.08, 0.0, 0.0))], devices=devices)
        assert find_rig_jumps(alone) == [], devices
    s = rec.streams["head"]
    pos = s.pos.copy()
    pos[300] += [0.0, 0.08, 0.0]
    glitch = Recording(streams={**rec.streams, "head": TrackerStream("head", s.time, pos, s.quat, s.valid)})
    assert find_rig_jumps(glitch) == []


class _Counted(np.ndarray):
    """An array that adds to :attr:`elements` the size of every ufunc it goes into (comparisons,
    arithmetic): how much of the take a detector reads, counted without timing it."""
    elements = 0

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        _Counted.elements += max(x.size for x in inputs if isinstance(x, _Counted))
        plain = [x.view(np.ndarray) if isinstance(x, _Counted) else x for x in inputs]
        if "out" in kwargs:
            kwargs["out"] = tuple(x.view(np.ndarray) if isinstance(x, _Counted) else x for x in kwargs["out"])
        return getattr(ufunc, method)(*plain, **kwargs)


def _looped(rec, seconds):
    """``rec`` repeated (time shifted) to ``seconds`` long."""
    streams = {}
    for d, s in rec.streams.items():
        dur = s.time[-1] - s.time[0] + 1.0 / 90
        reps = int(np.ceil(seconds / dur))
        t = np.concatenate([s.time - s.time[0] + k * dur for k in range(reps)])
        streams[d] = TrackerStream(d, t, np.tile(s.pos, (reps, 1)), np.tile(s.quat, (reps, 1)))
    return Recording(streams=streams, source="looped", metadata=dict(rec.metadata))


def _jump_work(rec, n, monkeypatch):
    """Elements of the take's time and segment arrays that finding, removing and restoring ``n``
    snap turns (spread over 50 s from 2 s) read; also checks they are all found."""
    from blender_manikin.core import teleports as tp
    jumped, _ = moved(rec, [(2.0 + k * 50.0 / n, 30.0 if k % 2 else -30.0, (0.0, 0.0, 0.0)) for k in range(n)])
    for s in jumped.streams.values():
        s.time = s.time.view(_Counted)
    segments = tp._segments
    monkeypatch.setattr(tp, "_segments", lambda times, jumps: segments(times, jumps).view(_Counted))
    _Counted.elements = 0
    jumps = find_rig_jumps(jumped)
    assert len(jumps) == n
    remove_rig_jumps(jumped, jumps)
    T = 60 * 30
    body = cs.sk.make_body(cs.sk.BodyMeasurements(stature=1.75))
    result = cs.PoseResult(fps=30.0, body=body, local_rot=np.tile(np.eye(3), (T, 22, 1, 1)),
                           root_pos=np.zeros((T, 3)), swivel=np.zeros((T, 4)),
                           t0=float(jumped.streams["head"].time[0]))
    tp.restore_rig_jumps(result, jumps)
    return _Counted.elements


def test_jumps_cost_no_pass_over_the_take_each(monkeypatch):
    """A long VR session with snap turning has thousands of jumps (a snap every 3 s is 1,200 an
    hour): finding, removing and restoring them must not read the whole take once per jump (that
    was O(T²): 45 + 28 + 10 s for 60 minutes at 90 Hz; benchmarks/bench_long.py).  Counted, not
    timed: 60 jumps in a minute read about as much of the take as 3 do."""
    rec = _looped(load_recording(EXAMPLE), 60.0)
    few, many = _jump_work(rec, 3, monkeypatch), _jump_work(rec, 60, monkeypatch)
    samples = sum(len(s) for s in rec.streams.values())
    assert many < 1.5 * few, (few, many, samples)


def headset_picked_up_from_a_table(rec, seconds=3.0):
    """``rec`` with ``seconds`` more at its start where only the headset is tracked: lying still
    0.75 m up, tipped 90° (face down on a table), the controllers not yet on (no samples); from
    the take's first sample on it is worn, so the head jumps about a metre in one sample."""
    from blender_manikin.core.rotations import axis_angle_to_quat
    rng = np.random.default_rng(5)
    streams = dict(rec.streams)
    s = rec.streams["head"]
    rate = 1.0 / np.median(np.diff(s.time))
    n = int(seconds * rate)
    t = s.time[0] - (n - np.arange(n)) / rate
    p = np.tile([0.6, -0.4, 0.75], (n, 1)) + rng.normal(0, 0.0002, (n, 3))
    q = np.tile(axis_angle_to_quat(np.array([np.pi / 2, 0.0, 0.0])), (n, 1))
    streams["head"] = TrackerStream("head", np.concatenate([t, s.time]), np.concatenate([p, s.pos]),
                                    np.concatenate([q, s.quat]))
    return Recording(streams=streams, source="headset picked up", metadata=dict(rec.metadata))


def without_hands_between(rec, t0, t1, devices=("left_hand", "right_hand")):
    """``rec`` with ``devices``' samples from ``t0`` to ``t1`` s left out (not tracked)."""
    streams = dict(rec.streams)
    for d in devices:
        s = rec.streams[d]
        m = (s.time < t0) | (s.time > t1)
        streams[d] = TrackerStream(d, s.time[m], s.pos[m], s.quat[m], s.valid[m])
    return Recording(streams=streams, source=rec.source, metadata=dict(rec.metadata))


def test_a_headset_picked_up_with_the_controllers_off_is_no_teleport(example):
    """A recording started with the headset on a table and the controllers off: the head's jump
    onto the performer has no hand to confirm it, so it is no teleport (taken for one, it moved the
    whole worn take down onto the table: stature 1.00 m, no T-pose found).  It is left as recorded
    and the headset pointed out; a trim at it gives the example's own solve."""
    rec, base = example
    table = headset_picked_up_from_a_table(rec)
    assert find_rig_jumps(table) == []
    whole = cs.solve_recording(table, cs.SolveSettings(fps=30.0))
    s = whole.summary()
    assert "put back" not in s and "calibrated on a T-pose at 3." in s and "stature 1.75 m" in s, s
    assert re.search(r"the head jumped 1\.\d\d m at (2\.99|3\.00) s with no controller tracked around it, so it "
                     r"is left as recorded, not taken for a teleport", s), s
    assert "the headset lay still (0.8 m up, tipped 90°) for the first 3.0 s (not yet worn?)" in s, s
    for start in (3.0, 3.2):
        trimmed = cs.solve_recording(table, cs.SolveSettings(fps=30.0, start=start))
        s = trimmed.summary()
        assert "put back" not in s and "stature 1.75 m" in s, s
        skip = int(round((start - 3.0) * 30))
        assert trimmed.result.num_frames == base.result.num_frames - skip
        err = np.linalg.norm(trimmed.result.positions - base.result.positions[skip:], axis=-1)
        assert np.median(err) < 0.002 and err.max() < 0.05, (start, np.median(err), err.max())


def test_a_jump_no_hand_can_confirm_is_no_teleport(example):
    """Both controllers untracked around the jump (no samples within half a second of it on
    either side): the head alone cannot tell the space moving from its own tracking."""
    rec, _ = example
    jumped, _ = moved(rec, [(3.5, 0.0, (2.0, -1.0, 0.0))])
    unconfirmed = []
    assert find_rig_jumps(without_hands_between(jumped, 2.9, 4.1), unconfirmed) == []
    assert [j.kind for j in unconfirmed] == ["teleport"] and unconfirmed[0].time == pytest.approx(3.5, abs=0.015)
    assert unconfirmed_jumps_note(unconfirmed).startswith("the head jumped 2.2")
    # a turn, the same
    turned, _ = moved(rec, [(3.5, 45.0, (0, 0, 0))])
    unconfirmed = []
    assert find_rig_jumps(without_hands_between(turned, 2.9, 4.1), unconfirmed) == []
    assert [j.kind for j in unconfirmed] == ["snap turn"]
    assert unconfirmed_jumps_note(unconfirmed).startswith("the head jumped 45° at 3.5")



def test_an_unconfirmed_jump_and_turn_is_said_as_far_as_the_head_moved(example):
    """A take 5 m from the origin, the head stepping 0.5 m and turning 90° with no hand tracked:
    the note says 0.50 m (before: 7.42 m, the space's shift, which holds the turn about the
    origin) and the turn."""
    rec, _ = example
    far, _ = moved(rec, [(-1e9, 0.0, (5.0, 0.0, 0.0))])           # every sample moved: no jump
    jumped, _ = moved(far, [(3.5, 90.0, (0.5, 0.0, 0.0))])
    unconfirmed = []
    assert find_rig_jumps(without_hands_between(jumped, 2.9, 4.1), unconfirmed) == []
    assert [j.kind for j in unconfirmed] == ["teleport and turn"]
    assert unconfirmed_jumps_note(unconfirmed).startswith("the head jumped 0.50 m (turning 90°) at 3.50 s")

def test_a_real_teleport_with_a_hand_tracked_is_still_found(example):
    """After a headset picked up from a table: the app's teleport at 3.5 s, the hands moving with
    it, is found (and only it), with both hands tracked around it or only the right one."""
    rec, _ = example
    jumped, _ = moved(rec, [(3.5, 0.0, (2.0, -1.0, 0.0))])
    for take in (jumped, without_hands_between(jumped, 3.0, 4.0, ("left_hand",))):
        table = headset_picked_up_from_a_table(take)
        found = find_rig_jumps(table)
        assert [j.kind for j in found] == ["teleport"] and found[0].time == pytest.approx(3.5, abs=0.015)
        assert found[0].trans == pytest.approx([2.0, -1.0, 0.0], abs=0.03)
    out = cs.solve_recording(table, cs.SolveSettings(fps=30.0, start=3.0))
    s = out.summary()
    # the times from the take's start, as the T-pose's: 3 s of table, then the teleport at 3.5 s
    assert re.search(r"1 teleport \(first at 6\.(49|50) s\) solved as one motion and put back", s), s
    assert "stature 1.75 m" in s, s
