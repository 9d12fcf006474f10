"""Left/right label swaps in markerless keypoints, found and undone.  No bpy.

Markerless capture (MediaPipe, OpenPose / body25, COCO detectors lifted to 3D, ...) often gives
a limb's points the other side's labels for a few frames: the "left knee" jumps onto the right
leg and back, seen from the side or when the legs pass each other.  Solved as they are, the
knees cross for those frames.  :func:`fix_side_swaps` finds such episodes per limb pair (the
legs: knee and below; the arms: elbow and below) and gives the points their sides back.

How, per limb pair, on the points as read (``(T, K, 3)`` metres, Z-up, NaN = missing):

1. **Continuity.**  Frame by frame, each side's chain is predicted from the frames before it
   (constant velocity over the last :data:`HISTORY`, on the labels as corrected so far).  A
   frame whose points sit closer to the *other* side's prediction, by :data:`SWAP_RATIO` of
   the distance and by at least :data:`SWAP_MARGIN` metres, is a swap relative to the frame
   before; the labels flip from there.  Limbs that truly cross (a cross step, a kick across
   the body) move continuously and are never flipped; a frame where the two chains are too
   close to tell keeps the state.
2. **Anatomy, once per take.**  The continuity pass fixes the labels only up to one global
   choice: whether the take starts swapped.  That choice is the one under which the left
   knee (elbow) is more often to the left of the right one, along the hips' (shoulders')
   left-right axis, over the frames where they are clearly apart (:data:`SIDE_APART`
   metres).  The knees and elbows, not the feet and hands: feet cross in a cross step, hands
   held behind the back or folded cross, the knees and elbows seldom do.
3. **Both ways.**  Steps 1-2 run forward and backward in time, and only the frames both call
   swapped are: where noise hides one end of an episode, one pass keeps the wrong labels after
   it (or before it, going back) while the other does not, so nothing is swapped there.
4. **Each run checked.**  A run of frames to swap is kept only where, over its frames whose
   knees (elbows) are clearly apart, the labels as read put the left one on the right more often
   than not (a run with no such frame is kept: both passes found it).  So noise can make the
   fix miss an episode, but seldom swap labels that were right.

Returns the corrected points and, per limb pair, the frames whose labels were swapped.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .runs import runs

#: the points of each limb pair, by name after ``left_`` / ``right_`` (those a layout has; the
#: first, the knee or elbow, votes on the sides in step 2)
LIMB_POINTS = {
    "legs": ("knee", "ankle", "heel", "foot_index", "big_toe", "small_toe", "foot"),
    "arms": ("elbow", "wrist", "pinky", "index", "thumb", "hand"),
}
#: the points whose left-right axis tells each limb pair's sides apart (step 2)
AXIS_POINTS = {"legs": "hip", "arms": "shoulder"}
#: a frame is a swap where the crossed assignment is this much closer than the kept one ...
SWAP_RATIO = 0.5
#: ... and closer by at least this many metres (per point, on average): noise never flips
SWAP_MARGIN = 0.04
#: usable frames the prediction of step 1 draws on: the last one, moved on by the velocity
#: from the first (a velocity over 3 steps: a third of one step's noise)
HISTORY = 4
#: metres apart along the left-right axis the knees (elbows) must be for a frame to vote in step 2
SIDE_APART = 0.05


@dataclass
class SideSwaps:
    """What :func:`fix_side_swaps` changed: ``frames`` limb pair name -> ``(T,)`` bool, the
    frames whose left and right labels were exchanged."""
    frames: dict = field(default_factory=dict)

    def count(self, limbs=None) -> int:
        return int(sum(int(m.sum()) for k, m in self.frames.items() if limbs is None or k in limbs))

    def note(self, fps):
        """A line for the solve summary, or None when nothing was swapped."""
        parts = [f"{k} on {int(m.sum())} frame(s) ({m.sum() / fps:.1f} s)"
                 for k, m in self.frames.items() if m.any()]
        return ("left/right labels swapped back: " + ", ".join(parts)) if parts else None


def limb_pairs(points, part):
    """``(left indices, right indices)`` of ``part``'s points in ``points`` (a layout's names)."""
    index = {n: i for i, n in enumerate(points)}
    left, right = [], []
    for name in LIMB_POINTS[part]:
        if f"left_{name}" in index and f"right_{name}" in index:
            left.append(index[f"left_{name}"])
            right.append(index[f"right_{name}"])
    return left, right


def _chain_distances(a, b):
    """Mean distance over the points both have, per frame: ``a``, ``b`` ``(n, k, 3)`` -> ``(n,)``
    metres, NaN where they share none."""
    d = np.linalg.norm(a - b, axis=-1)
    ok = np.isfinite(d)
    n = ok.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.where(ok, d, 0.0).sum(-1) / n, np.nan)


def _predict(history, t):
    """Each chain's points at frame ``t`` from ``history`` ``[(frame, left, right), ...]`` (the
    last usable frames, oldest first): the last one moved on by the velocity since the first."""
    f1, l1, r1 = history[-1]
    if len(history) == 1:
        return l1, r1
    f0, l0, r0 = history[0]
    k = (t - f1) / np.maximum(f1 - f0, 1)
    pl, pr = l1 + k * (l1 - l0), r1 + k * (r1 - r0)
    return np.where(np.isfinite(pl), pl, l1), np.where(np.isfinite(pr), pr, r1)


def _is_flip(keep, cross):
    """Whether the crossed assignment wins (:data:`SWAP_RATIO`, :data:`SWAP_MARGIN`); False
    where either cost is NaN."""
    with np.errstate(invalid="ignore"):
        return (cross < SWAP_RATIO * keep) & (keep - cross > 2 * SWAP_MARGIN)


def swap_states(L, R):
    """Step 1: ``(T,)`` bool, True where the labels are flipped relative to frame 0.

    L, R ``(T, k, 3)`` metres: the two chains' points as read (NaN = missing).  A frame whose
    :data:`HISTORY` frames before it are all usable and share its labelling (no flip among
    them) is decided from the labels as read, for all such frames at once; the loop does the
    arithmetic only around flips and missing frames."""
    T = L.shape[0]
    usable = np.isfinite(L).all(-1).any(-1) & np.isfinite(R).all(-1).any(-1)
    simple = np.zeros(T, bool)
    flip_read = np.zeros(T, bool)
    if T > HISTORY:
        run = np.ones(T - HISTORY, bool)
        for k in range(HISTORY + 1):
            run &= usable[k:T - HISTORY + k]
        simple[HISTORY:] = run
        t = np.nonzero(simple)[0]
        tt = t[:, None, None]
        hist = [(tt - HISTORY + k, L[t - HISTORY + k], R[t - HISTORY + k]) for k in range(HISTORY)]
        pl, pr = _predict(hist, tt)
        keep = _chain_distances(L[t], pl) + _chain_distances(R[t], pr)
        cross = _chain_distances(L[t], pr) + _chain_distances(R[t], pl)
        flip_read[t] = _is_flip(keep, cross)
    state = np.zeros(T, bool)
    cur, since, used = False, HISTORY, []        # since: usable frames from the last flip on
    for t in range(T):
        if usable[t]:
            if simple[t] and since >= HISTORY:
                flip = bool(flip_read[t])
            elif used:
                hist = [(f, *((R[f], L[f]) if state[f] else (L[f], R[f]))) for f in used[-HISTORY:]]
                pl, pr = _predict(hist, t)
                a, b = (R[t], L[t]) if cur else (L[t], R[t])           # as labelled so far
                keep = _chain_distances(a[None], pl[None]) + _chain_distances(b[None], pr[None])
                cross = _chain_distances(a[None], pr[None]) + _chain_distances(b[None], pl[None])
                flip = bool(_is_flip(keep, cross)[0])
            else:
                flip = False
            if flip:
                cur, since = not cur, 0
            since += 1
            used.append(t)
        state[t] = cur
    return state


def fix_side_swaps(points, names) -> tuple:
    """Undo left/right label swaps of the legs and arms (see the module docstring).

    points ``(T, K, 3)`` metres, Z-up (NaN = missing), the layout's point ``names`` (``K``).
    Returns ``(points, SideSwaps)``: a new array with the swapped frames' labels exchanged
    back (the input unchanged), and which frames those were, per limb pair."""
    X = np.array(points, np.float64, copy=True)
    out = SideSwaps()
    index = {n: i for i, n in enumerate(names)}
    for part in LIMB_POINTS:
        li, ri = limb_pairs(names, part)
        ax = AXIS_POINTS[part]
        if not li or f"left_{ax}" not in index or f"right_{ax}" not in index:
            continue
        L, R = X[:, li], X[:, ri]
        # step 2: the sides the anatomy prefers, over the frames where the chains are apart
        axis = X[:, index[f"left_{ax}"]] - X[:, index[f"right_{ax}"]]
        axis[:, 2] = 0.0
        axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-9)
        # the knees and elbows: hands clasped behind the back or feet in a cross step change
        # sides, the knees and elbows seldom do
        d = L[:, 0] - R[:, 0]                                           # (T, 3)
        with np.errstate(invalid="ignore"):
            side = np.einsum("ti,ti->t", d, axis)                       # > 0: left is left; NaN: unseen
        sure = np.isfinite(side) & (np.abs(side) > SIDE_APART)

        def oriented(state):
            as_read = int(np.sum(sure & ((side > 0) != state)))       # votes for the first frame's labels
            flipped = int(np.sum(sure & ((side > 0) == state)))
            return state if as_read >= flipped else ~state
        # step 3: forward and backward in time; a frame is swapped where both passes say so
        swapped = oriented(swap_states(L, R)) & oriented(swap_states(L[::-1], R[::-1])[::-1])
        # step 4: a run of swapped frames stays swapped only if, where its chains are clearly
        # apart, its labels as read mostly put the left chain on the right
        for a, b in runs(swapped):
            wrong, right = np.sum(sure[a:b] & (side[a:b] < 0)), np.sum(sure[a:b] & (side[a:b] > 0))
            if right > wrong:
                swapped[a:b] = False
        if swapped.any():
            Xs = X[swapped]
            Xs[:, li], Xs[:, ri] = Xs[:, ri].copy(), Xs[:, li].copy()
            X[swapped] = Xs
        out.frames[part] = swapped
    return X, out
