"""Where a solve is worth a look: frames to mark on the animator's timeline.

Never imports bpy.

The solve summary counts what gave way ("left hand out of reach on 53 frame(s)"); on a ten-minute
take the animator also needs *where*.  :func:`review_marks` lists the first frame of each stretch:

* a hand or foot out of its limb's reach, or closer to the shoulder / hip than the elbow / knee
  folds (:meth:`.pose_result.PoseResult.misses`), and a swivel held at a joint limit, for
  :data:`MIN_FRAMES` frames or more;
* a device lost for :data:`MIN_GAP_S` or more (the resampler's bridged gaps);
* the app's teleports and snap turns (:mod:`.teleports`).

Marks of one kind closer than :data:`MERGE_S` to the previous one are left out (one mark per
episode), and at most :data:`MAX_MARKS` are made, the earliest first.  Frame numbers are indices
into the result's frames (frame 0 at ``result.t0`` on the recording's clock).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .devices import LABELS
from .runs import run_bounds
from .skeleton import LIMB_NAMES

#: a miss or a limit must last this many frames to be marked
MIN_FRAMES = 3
#: a gap must last this long (s) to be marked
MIN_GAP_S = 0.5
#: marks of one kind within this many seconds of the previous one are one episode
MERGE_S = 1.0
#: at most this many marks per solve
MAX_MARKS = 100

_ENDS = {"left_arm": ("left hand", "elbow"), "right_arm": ("right hand", "elbow"),
         "left_leg": ("left foot", "knee"), "right_leg": ("right foot", "knee")}


@dataclass(frozen=True)
class ReviewMark:
    """``frame``: index into the result's frames; ``label``: a few words ("left hand out of
    reach", "head lost 3.0 s", "teleport")."""
    frame: int
    label: str


def _runs(mask, min_len):
    """Start indices of the runs of True in ``mask`` (``(T,)`` bool) at least ``min_len`` long."""
    starts, stops = run_bounds(mask)
    return [int(a) for a, b in zip(starts, stops) if b - a >= min_len]


def review_marks(result, report=None, jumps=(), reach_tolerance=0.005) -> list:
    """The :class:`ReviewMark` s of a solve, sorted by frame.

    result: :class:`.pose_result.PoseResult`; report: the resampler's :class:`.resample.GapReport`
    (its gaps on the recording's clock), optional; jumps: :class:`.teleports.RigJump` s."""
    T, fps = result.num_frames, float(result.fps)
    marks = []
    if result.reach_error is not None:
        for i, limb in enumerate(LIMB_NAMES):
            far, close = result.misses(i, reach_tolerance)
            end, mid = _ENDS[limb]
            marks += [ReviewMark(f, f"{end} out of reach") for f in _runs(far, MIN_FRAMES)]
            marks += [ReviewMark(f, f"{end} inside the {mid}'s fold") for f in _runs(close, MIN_FRAMES)]
    if result.at_limit is not None:
        for i, limb in enumerate(LIMB_NAMES):
            marks += [ReviewMark(f, f"{limb.replace('_', ' ')} swivel at its limit")
                      for f in _runs(result.at_limit[:, i], MIN_FRAMES)]

    def frame_at(t):
        return int(np.clip(round((float(t) - result.t0) * fps), 0, max(T - 1, 0)))

    for g in getattr(report, "gaps", None) or []:
        if g.duration >= MIN_GAP_S and g.end > result.t0 and g.start < result.t0 + T / fps:
            what = LABELS.get(g.device, g.device.replace("_", " ")).lower()
            marks.append(ReviewMark(frame_at(g.start), f"{what} lost {g.duration:.1f} s"))
    for j in jumps or ():
        if result.t0 <= j.time < result.t0 + T / fps:
            marks.append(ReviewMark(frame_at(j.time), j.kind))
    marks.sort(key=lambda m: (m.frame, m.label))
    kept, last = [], {}
    for m in marks:
        if m.label in last and m.frame - last[m.label] < MERGE_S * fps:
            last[m.label] = m.frame            # the same episode goes on
            continue
        last[m.label] = m.frame
        kept.append(m)
    return kept[:MAX_MARKS]
