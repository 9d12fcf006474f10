"""Left and right controllers swapped: the performer held each in the other hand, or the recorder
mislabelled them.

Never imports bpy.

Solved as labelled, such a take crosses the arms in front of the body for its whole length.  The
headset tells: people hold their hands apart with the left one on the left far more than the
other way round.  Over :data:`WIDE_M` apart sideways (the headset's left axis), the left hand
stood on the right on at most 4.3 % of those frames in any of 3,363 mocap clips (Bandai Namco and
HDM05, folded-arm walks and two-handed sword slashes included: hands crossed are held close) and
on 0.06 % of the real Beat Saber sessions' frames; a swapped take has it on nearly all of them.
:func:`swapped_hands` says a take is swapped when that share is :data:`SWAPPED_SHARE` or more
over at least :data:`MIN_WIDE_S` of such frames, and the solve then swaps the two streams back
(``fix_sides``, on by default; ``--keep-sides`` keeps them as labelled) and says so.
"""
from __future__ import annotations

import numpy as np

from .rotations import quat_to_matrix

#: hands at least this far apart sideways (metres, along the headset's left axis) are counted
WIDE_M = 0.30
#: the share of those frames with the left hand on the right that means the labels are swapped
SWAPPED_SHARE = 0.8
#: seconds of such frames needed before anything is decided
MIN_WIDE_S = 1.0


def swapped_hands(head_quat, left_pos, right_pos, valid=None, fps=30.0):
    """``(swapped, share, wide_frames)`` for device poses on one frame grid.

    head_quat: ``(T, 4)`` the headset's orientations (wxyz, Blender axes: its local +X is the
    wearer's left, :mod:`.device_offsets`); left_pos, right_pos: ``(T, 3)`` metres; valid: optional
    ``(T,)`` bool, frames where all three are tracked.  share: the fraction of the frames with the
    hands over :data:`WIDE_M` apart sideways where the left one is on the right (NaN without any)."""
    left_axis = quat_to_matrix(np.asarray(head_quat, np.float64))[:, :, 0]
    side = np.einsum("ni,ni->n", np.asarray(left_pos, np.float64) - np.asarray(right_pos, np.float64), left_axis)
    wide = np.abs(side) > WIDE_M
    if valid is not None:
        wide &= np.asarray(valid, bool)
    n = int(wide.sum())
    if n == 0:
        return False, float("nan"), 0
    share = float(np.mean(side[wide] < 0))
    return bool(share >= SWAPPED_SHARE and n >= MIN_WIDE_S * fps), share, n


def swapped_note(share, n, fps):
    return (f"left and right controllers swapped back: the left one was on the performer's right on "
            f"{100 * share:.0f} % of {n / fps:.1f} s with the hands apart (keep them as labelled with "
            f"--keep-sides / Fix Left/Right Swaps off)")
