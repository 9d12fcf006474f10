"""Frames worth a look (core/review_marks.py): misses, limits, lost devices and teleports, one
mark per episode."""
import numpy as np

from blender_manikin.core.resample import Gap, GapReport
from blender_manikin.core.review_marks import MAX_MARKS, review_marks
from blender_manikin.core.teleports import RigJump

from blender_util import synthetic_result


def test_marks_where_the_solve_gave_way():
    res = synthetic_result(T=120, fps=30.0, with_targets=False)      # t0 = 12.5 s
    res.reach_error = np.zeros((120, 4))
    res.reach_error[40:50, 1] = 0.05          # right hand: 10 frames off (no targets: counted far)
    res.reach_error[52:55, 1] = 0.05          # ... again 0.07 s later: the same episode
    res.reach_error[90:91, 2] = 0.05          # left foot: one frame only, not marked
    res.at_limit = np.zeros((120, 4), bool)
    res.at_limit[100:110, 0] = True
    report = GapReport(fps=30.0, t0=12.5, t_end=16.5, num_frames=120,
                       gaps=[Gap("head", 13.0, 14.0, "missing", 60), Gap("left_hand", 14.0, 14.2, "nan", 5)])
    jumps = [RigJump(time=15.0, start=14.99, rot=np.eye(3), trans=np.zeros(3), kind="teleport"),
             RigJump(time=30.0, start=29.99, rot=np.eye(3), trans=np.zeros(3), kind="snap turn")]  # after
    marks = [(m.frame, m.label) for m in review_marks(res, report, jumps)]
    assert marks == [(15, "head lost 1.0 s"), (40, "right hand out of reach"), (75, "teleport"),
                     (100, "left arm swivel at its limit")]


def test_marks_are_capped():
    res = synthetic_result(T=6000, fps=30.0, with_targets=False)
    res.reach_error = np.zeros((6000, 4))
    for a in range(0, 6000, 45):                 # an episode every 1.5 s
        res.reach_error[a:a + 5, 0] = 0.02
    marks = review_marks(res)
    assert len(marks) == MAX_MARKS and marks[1].frame == 45
