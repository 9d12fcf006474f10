"""Hands lost for long: the arm hangs relaxed at the side instead of following a straight bridge.

Never imports bpy.

Controllers lost behind the back, and tracked hands out of the headset cameras' view (hands at
the sides are, for most inside-out hand tracking), leave a hand without samples for seconds.
The resampler bridges every gap in a straight line between the last and the next sample, which
for a short gap is right and for a long one is not: a hand lost raised and found raised again
five seconds later stays raised in mid-air all that time.  People whose hands are not doing
anything let them hang, and that is what an animator expects to see.

So for a gap longer than :data:`RELAX_AFTER_S`, :func:`relax_lost_hands` eases the wrist target
from the bridge to a relaxed pose over :data:`EASE_S` after the hand is lost, holds it, and
eases back over :data:`EASE_S` before it is found (at either end of the take it stays relaxed
up to the first / from the last sample).  The relaxed pose hangs the arm from the shoulder,
:data:`ABDUCTION_DEG` out to the side and :data:`FORWARD_M` ahead of the shoulder, palm
towards the thigh; it is placed from the head's target, turned with the head's heading and
moved with its height (a crouching performer's hands go down with it), since the torso is not
solved yet.  The network and the limb solver then see that hand.  Gaps of up to
:data:`RELAX_AFTER_S` keep the straight bridge.  The frames stay marked as not tracked
(``valid`` False) and the summary says which hand hung where.
"""
from __future__ import annotations

import numpy as np

from .features import heading_yaw, rot_z
from .pose_result import TrackerTargets
from .rotations import axis_angle_rotation, matrix_to_quat, quat_slerp, quat_to_matrix
from .runs import runs
from .skeleton import J

#: gaps longer than this (seconds) hang the arm; shorter ones keep the resampler's bridge
RELAX_AFTER_S = 1.0
#: seconds to ease from the bridge to the relaxed arm and back
EASE_S = 0.5
#: the relaxed arm's angle out from the body's side (degrees)
ABDUCTION_DEG = 8.0
#: the relaxed wrist's distance ahead of the shoulder (metres)
FORWARD_M = 0.04
#: the wrist hangs this share of the arm's straight length below the shoulder's line (elbow a
#: little bent)
HANG = 0.97

_SIDES = (("left_hand", "left_shoulder", +1.0), ("right_hand", "right_shoulder", -1.0))


def relaxed_wrists(head_pos, head_rot, body):
    """Relaxed wrist poses for a head at ``head_pos`` ``(T, 3)`` with orientation ``head_rot``
    ``(T, 3, 3)`` (the head *joint*, Blender axes, metres): ``{device: (pos (T, 3), rot (T, 3,
    3))}`` for ``left_hand`` and ``right_hand``, the arms of ``body`` hanging at its sides."""
    rest = body.rest_positions()
    heading = rot_z(heading_yaw(head_rot))                      # (T, 3, 3)
    limbs = body.limb_lengths()
    out = {}
    for dev, shoulder, side in _SIDES:
        length = HANG * float(limbs[0 if side > 0 else 1].sum())
        a = np.radians(ABDUCTION_DEG)
        # body frame (rest: facing -Y, its left +X): the wrist below the shoulder, a little out
        # and forward
        local = rest[J[shoulder]] - rest[J["head"]] + np.array(
            [side * length * np.sin(a), -FORWARD_M, -length * np.cos(a)])
        pos = head_pos + heading @ local
        # the rest wrist points out along +X (left) / -X (right), palm down: turned down about
        # the body's forward axis, palm to the thigh
        hang = axis_angle_rotation(np.array([0.0, 1.0, 0.0]), side * np.pi / 2)
        out[dev] = (pos, heading @ hang)
    return out


def _weights(lost, fps, T):
    """``(T,)`` float in [0, 1]: how far each frame of a long gap is relaxed (smoothstep eases)."""
    w = np.zeros(T)
    n_min = RELAX_AFTER_S * fps
    ease = max(EASE_S * fps, 1.0)
    for a, b in runs(lost):
        if b - a <= n_min:
            continue
        k = np.arange(a, b, dtype=np.float64)
        up = np.ones(b - a) if a == 0 else np.clip((k - a + 1) / ease, 0, 1)
        down = np.ones(b - a) if b == T else np.clip((b - k) / ease, 0, 1)
        x = np.minimum(up, down)
        w[a:b] = x * x * (3 - 2 * x)
    return w


def relax_lost_hands(targets: TrackerTargets, body):
    """``(targets, notes)``: ``targets`` with each hand's long gaps relaxed (see the module
    docstring; a new :class:`TrackerTargets`, the input is not changed) and one note per hand that
    was relaxed, e.g. ``"left hand lost over 1 s on 2 stretches (5.2 s in all, from 3.1 s): the
    arm hangs relaxed there"``.  Without a head target, or without long gaps, ``targets`` is
    returned as it is."""
    if "head" not in targets.pos:
        return targets, []
    T = targets.num_frames
    fps = float(targets.fps)
    weights = {}
    for dev, _, _ in _SIDES:
        if dev not in targets.pos:
            continue
        valid = np.asarray(targets.valid.get(dev, np.ones(T, bool)), bool)
        if valid.shape != (T,) or not (~valid).any():
            continue
        w = _weights(~valid, fps, T)
        if w.any():
            weights[dev] = (w, ~valid)
    if not weights:
        return targets, []
    relaxed = relaxed_wrists(targets.pos["head"], targets.rot["head"], body)
    pos, rot = dict(targets.pos), dict(targets.rot)
    notes = []
    for dev, (w, lost) in weights.items():
        p_rel, r_rel = relaxed[dev]
        pos[dev] = targets.pos[dev] * (1 - w[:, None]) + p_rel * w[:, None]
        q = quat_slerp(matrix_to_quat(targets.rot[dev]), matrix_to_quat(r_rel), w)
        rot[dev] = np.where(w[:, None, None] > 0, quat_to_matrix(q), targets.rot[dev])
        long = [(a, b) for a, b in runs(lost) if b - a > RELAX_AFTER_S * fps]
        total = sum(b - a for a, b in long) / fps
        first = long[0][0] / fps
        n = len(long)
        notes.append(f"{dev.replace('_', ' ')} lost over {RELAX_AFTER_S:g} s on {n} stretch"
                     f"{'es' if n > 1 else ''} ({total:.1f} s in all, from {first:.1f} s): the arm hangs relaxed there")
    return TrackerTargets(fps=targets.fps, pos=pos, rot=rot, valid=dict(targets.valid)), notes
