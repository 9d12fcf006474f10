"""A headset lying somewhere at the start or the end of a take (not yet, or no longer, worn).

Never imports bpy.

A recorder started before the performer puts the headset on (or stopped after it is taken off)
logs it where it lies: still, tipped well over, off the floor (a table, a shelf, a chair).  Solved
as recorded, the body folds to put its head there.  Nothing is cut from the take: the summary
says where it lay and which *Start* / *End* trims it (:func:`headset_off_note`).

A stretch counts when it touches the take's start or end, lasts :data:`MIN_OFF_S` or more, and on
every frame the head target moves less than :data:`STILL_M_S` and turns less than
:data:`STILL_DEG_S` (from one end of a :data:`SMOOTH_S` window about it to the other: tracking
noise does not add up), is tipped more than :data:`TILT_DEG`
from upright, and is :data:`MIN_HEIGHT_M` or more above the floor (a performer lying still on
the floor has the head lower).  On the 3,363 mocap clips (Bandai Namco, HDM05), whose heads are
worn throughout, no stretch is found (``benchmarks/bench_sides.py`` counts them).
"""
from __future__ import annotations

import numpy as np

from .rotations import geodesic_angle

#: seconds a stretch must last
MIN_OFF_S = 2.0
#: metres per second the head target may move and still count as lying still
STILL_M_S = 0.02
#: degrees per second it may turn
STILL_DEG_S = 3.0
#: degrees its up axis must be tipped from the vertical (a worn headset looking down: under 60)
TILT_DEG = 60.0
#: metres above the floor it must stand (a performer lying on the floor: the head lower)
MIN_HEIGHT_M = 0.4
#: seconds over which the speeds are measured (end to end: tracking noise does not add up)
SMOOTH_S = 0.5


def headset_off(pos, rot, fps, valid=None):
    """``(first_frames, last_frames)``: how many frames at the take's start and at its end the
    headset lay off the performer (0: none; untracked frames at the very start or end are
    counted in, as a trim would take them too).

    pos: ``(T, 3)`` the head target's positions (metres, Z-up, floor at 0); rot: ``(T, 3, 3)`` its
    world orientations (the head joint's: local +Z up); fps: frames per second; valid: optional
    ``(T,)`` bool, tracked frames (untracked ones end a stretch)."""
    pos = np.asarray(pos, np.float64)
    rot = np.asarray(rot, np.float64)
    T = len(pos)
    if T < 3:
        return 0, 0
    half = max(int(round(0.5 * SMOOTH_S * fps)), 1)
    k = np.arange(T)
    a, b = np.maximum(k - half, 0), np.minimum(k + half, T - 1)
    dt = (b - a) / fps                       # how far it went over the window, not the sum of
    speed = np.linalg.norm(pos[b] - pos[a], axis=-1) / dt        # its noisy steps
    turn = np.degrees(geodesic_angle(rot[a], rot[b])) / dt
    tilt = np.degrees(np.arccos(np.clip(rot[:, 2, 2], -1.0, 1.0)))
    off = (speed < STILL_M_S) & (turn < STILL_DEG_S) & (tilt > TILT_DEG) & (pos[:, 2] >= MIN_HEIGHT_M)
    need = int(np.ceil(MIN_OFF_S * fps))
    ok = np.ones(T, bool) if valid is None else np.asarray(valid, bool)
    out = []
    for o, v in ((off, ok), (off[::-1], ok[::-1])):
        i0 = int(np.argmax(v)) if v.any() else T      # untracked frames at the very end: skipped
        run = o[i0:] & v[i0:]
        n = int(np.argmin(run)) if not run.all() else len(run)
        # the frames within half a window of where it was picked up look moving: theirs too
        out.append(min(i0 + n + half, T) if n >= need else 0)
    return out[0], out[1]


def headset_off_note(first, last, T, fps, pos=None, rot=None):
    """The summary's lines for :func:`headset_off`'s stretches (none when both are 0)."""
    if first >= T and T:
        return [f"the headset lay still, tipped over, for the whole take ({T / fps:.1f} s): never worn?"]
    notes = []
    for n, at_start in ((first, True), (last, False)):
        if not n:
            continue
        where = ""
        if pos is not None and rot is not None:
            k = 0 if at_start else T - 1
            tilt = float(np.degrees(np.arccos(np.clip(rot[k][2, 2], -1.0, 1.0))))
            where = f" ({pos[k][2]:.1f} m up, tipped {tilt:.0f}°)"
        if at_start:
            notes.append(f"the headset lay still{where} for the first {n / fps:.1f} s (not yet worn?): "
                         f"Trim Start {n / fps:.1f} s (--start {n / fps:.1f}) leaves it out")
        else:
            end = (T - n) / fps
            notes.append(f"the headset lay still{where} for the last {n / fps:.1f} s (taken off?): "
                         f"Trim End {end:.1f} s (--end {end:.1f}) leaves it out")
    return notes
