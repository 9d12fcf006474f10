"""Left and right trackers swapped: controllers held in the other hands, foot trackers strapped
to the other feet, or a recorder that mislabelled them.

Never imports bpy.

*Controllers.*  Solved as labelled, such a take crosses the arms in front of the body for its
whole length.  The headset tells: people hold their hands apart with the left one on the left
far more than the other way round.  Over :data:`WIDE_M` apart sideways (the headset's left
axis), the left hand stood on the right on at most 4.3 % of those frames in any of 3,363 mocap
clips (Bandai Namco and HDM05, folded-arm walks and two-handed sword slashes included: hands
crossed are held close) and on 0.06 % of the real Beat Saber sessions' frames; a swapped take
has it on nearly all of them.  :func:`swapped_hands` says a take is swapped when that share is
:data:`SWAPPED_SHARE` or more over at least :data:`MIN_WIDE_S` of such frames.

*Foot trackers* (SteamVR assigns tracker roles by hand, and the left and right foot are easy to
mix up).  Solved as labelled, the legs cross for the whole take.  The headset's left axis does
not tell the feet apart: a head turned from the hips makes a walking stride look sideways.  The
pelvis does; its tracker is strapped on at a rotation nobody knows before the calibration, but
that rotation is fixed, so :func:`body_left_axis` takes the headset's horizontal left axis into
the pelvis tracker's frame, averages it over the take (what is left is the mean turn of the head
from the hips, a few degrees) and turns it back with the tracker, frame by frame: the hips' left
axis.  Along it, over :data:`WIDE_FEET_M` apart, the left ankle stood on the right on at most
53 % of those frames in any of the 3,363 clips with at least :data:`MIN_WIDE_FEET_S` of them
(the most: side-stepping and catwalk walks, whose feet cross); under 20 % in 2,100 of those
2,153 clips, so that a swap is caught in nearly all of them.  Without a pelvis tracker the
headset's axis is used with :data:`WIDE_FEET_HEAD_M` (at most 53 % there too; 638 of 667
clips caught).  :func:`swapped_feet` says the foot trackers are swapped at :data:`SWAPPED_SHARE`.
``benchmarks/bench_sides.py`` measures all three figures.

*Pelvis and foot roles* mixed up (the waist tracker given a foot's role): a pelvis tracker whose
median height over the take is :data:`ROLE_DROP_M` or more below a foot tracker's is that foot's,
and the two are swapped back (:func:`mixed_pelvis_role`).  Over the 3,363 clips the pelvis's median
height is at most 7.2 cm below the higher ankle's (HDM05's lie-down clips, legs raised; no false
swap), and with the pelvis and left foot exchanged 3,343 of them are caught (the rest lie down).

The solve then swaps the two streams back (``fix_sides``, on by default; ``--keep-sides`` keeps
them as labelled) before the calibration measures the trackers' offsets, and says so.
"""
from __future__ import annotations

import numpy as np

from .rotations import normalize, quat_to_matrix

#: hands at least this far apart sideways (metres, along the headset's left axis) are counted
WIDE_M = 0.30
#: the share of those frames with the left one on the right that means the labels are swapped
SWAPPED_SHARE = 0.8
#: seconds of such frames needed before anything is decided (controllers)
MIN_WIDE_S = 1.0
#: foot trackers at least this far apart sideways (metres, along the hips' left axis) are counted
WIDE_FEET_M = 0.10
#: ... along the headset's left axis, when there is no pelvis tracker (a stride seen from a
#: turned head looks sideways, so only feet far apart count)
WIDE_FEET_HEAD_M = 0.20
#: seconds of such frames needed before anything is decided (foot trackers)
MIN_WIDE_FEET_S = 2.0
#: metres a foot tracker's median height must stand above the pelvis tracker's before the two are
#: taken for each other's (the waist tracker given a foot's role)
ROLE_DROP_M = 0.3


def _sideways(axis, left_pos, right_pos):
    return np.einsum("ni,ni->n", np.asarray(left_pos, np.float64) - np.asarray(right_pos, np.float64), axis)


def _decide(side, wide_m, valid, min_frames):
    wide = np.abs(side) > wide_m
    if valid is not None:
        wide &= np.asarray(valid, bool)
    n = int(wide.sum())
    if n == 0:
        return False, float("nan"), 0
    share = float(np.mean(side[wide] < 0))
    return bool(share >= SWAPPED_SHARE and n >= min_frames), share, n


def _horizontal_unit(v):
    v = np.array(v, dtype=np.float64)
    v[..., 2] = 0.0
    return normalize(v)


def swapped_hands(head_quat, left_pos, right_pos, valid=None, fps=30.0):
    """``(swapped, share, wide_frames)`` for device poses on one frame grid.

    head_quat: ``(T, 4)`` the headset's orientations (wxyz, Blender axes: its local +X is the
    wearer's left, :mod:`.device_offsets`); left_pos, right_pos: ``(T, 3)`` metres; valid: optional
    ``(T,)`` bool, frames where all three are tracked.  share: the fraction of the frames with the
    hands over :data:`WIDE_M` apart sideways where the left one is on the right (NaN without any)."""
    left_axis = quat_to_matrix(np.asarray(head_quat, np.float64))[:, :, 0]
    return _decide(_sideways(left_axis, left_pos, right_pos), WIDE_M, valid, MIN_WIDE_S * fps)


def body_left_axis(head_quat, pelvis_quat, valid=None):
    """``(T, 3)`` unit horizontal vectors (Z-up world): the hips' left axis, from a pelvis tracker
    worn at any fixed rotation.

    head_quat, pelvis_quat: ``(T, 4)`` wxyz device orientations (the headset's local +X is the
    wearer's left); valid: optional ``(T,)`` bool, frames where both are tracked (the average is
    taken over those; all frames get an axis).  The headset's horizontal left axis, expressed in
    the tracker's frame and averaged, is the tracker-frame direction of the hips' left; turned by
    each frame's tracker rotation and made horizontal, it follows the hips, not the head."""
    head_left = _horizontal_unit(quat_to_matrix(np.asarray(head_quat, np.float64))[:, :, 0])
    Rp = quat_to_matrix(np.asarray(pelvis_quat, np.float64))
    local = np.einsum("nji,nj->ni", Rp, head_left)                  # Rpᵀ · head_left
    use = np.ones(len(local), bool) if valid is None else np.asarray(valid, bool)
    mean = local[use].mean(axis=0) if use.any() else local.mean(axis=0)
    mean = mean / max(float(np.linalg.norm(mean)), 1e-9)
    return _horizontal_unit(Rp @ mean)


def swapped_feet(head_quat, left_pos, right_pos, pelvis_quat=None, valid=None, fps=30.0):
    """``(swapped, share, wide_frames)`` for the foot trackers on one frame grid.

    head_quat: ``(T, 4)`` the headset's orientations (wxyz, local +X the wearer's left);
    left_pos, right_pos: ``(T, 3)`` the foot trackers' positions (metres, Z-up); pelvis_quat:
    optional ``(T, 4)`` a pelvis tracker's orientations (any mount), whose :func:`body_left_axis`
    then measures sideways (else the headset's, with :data:`WIDE_FEET_HEAD_M`); valid: optional
    ``(T,)`` bool, frames where every device used is tracked.  share: the fraction of the frames
    with the feet far enough apart sideways where the left one is on the right (NaN without any)."""
    if pelvis_quat is not None:
        axis, wide_m = body_left_axis(head_quat, pelvis_quat, valid), WIDE_FEET_M
    else:
        axis = _horizontal_unit(quat_to_matrix(np.asarray(head_quat, np.float64))[:, :, 0])
        wide_m = WIDE_FEET_HEAD_M
    return _decide(_sideways(axis, left_pos, right_pos), wide_m, valid, MIN_WIDE_FEET_S * fps)


def mixed_pelvis_role(pelvis_z, foot_z, valid=None):
    """The foot device whose stream is the pelvis tracker's (the roles mixed up), or None.

    pelvis_z: ``(T,)`` the pelvis tracker's heights (metres, Z-up); foot_z: device → ``(T,)`` the
    foot trackers' heights; valid: optional device → ``(T,)`` bool.  The foot whose median height
    stands the most above the pelvis's, when that is :data:`ROLE_DROP_M` or more."""
    def median(z, d):
        z = np.asarray(z, np.float64)
        ok = np.isfinite(z) if valid is None or d not in valid else np.asarray(valid[d], bool) & np.isfinite(z)
        return float(np.median(z[ok])) if ok.any() else float("nan")

    zp = median(pelvis_z, "pelvis")
    above = {d: median(z, d) - zp for d, z in foot_z.items()}
    above = {d: a for d, a in above.items() if np.isfinite(a)}
    if not above:
        return None
    d = max(above, key=above.get)
    return d if above[d] >= ROLE_DROP_M else None


def swapped_note(share, n, fps, what="controllers"):
    """The solve summary's line for a swap undone; ``what``: ``"controllers"`` or ``"foot trackers"``."""
    where = "hands" if what == "controllers" else "feet"
    return (f"left and right {what} swapped back: the left one was on the performer's right on "
            f"{100 * share:.0f} % of {n / fps:.1f} s with the {where} apart (keep them as labelled with "
            f"--keep-sides / Fix Left/Right Swaps off)")
