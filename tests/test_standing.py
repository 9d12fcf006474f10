"""A performer standing in a T-pose or an A-pose is solved standing straight.

Every real recording starts with a calibration pose, and the solve must show a body standing
on straight legs there, whatever the performer's size or proportions: knees flexed less than
10 degrees and ankles within 2 cm of the rest body's ankle height.  The recordings are made by
FK (``benchmarks/standing.py``) of standing bodies of 1.50, 1.75 and 2.00 m (the solver's own
proportions) and of a body with the proportions of the Bandai Namco training skeleton, with a
little sway; calibration finds the pose and sizes the body, and the shipped network solves it
(the whole core pipeline, no Blender).
"""
import pytest

from benchmarks.standing import CASES, solve_standing
from blender_manikin.core.model_runner import load_model


@pytest.mark.parametrize("who,pose", CASES, ids=[f"{w}-{p}" for w, p in CASES])
def test_standing_calibration_pose_is_solved_standing_straight(who, pose):
    knees, ankle_err, res = solve_standing(who, pose, load_model())
    assert res.pose == pose
    k = 15          # every frame after the first half second (the network's windows are centred)
    assert knees[k:-k].max() < 10.0, f"knees flexed {knees[k:-k].max():.1f} deg"
    assert ankle_err[k:-k].max() < 0.02, f"ankles {100 * ankle_err[k:-k].max():.1f} cm off the rest height"


def test_a_performer_skeleton_stands_as_it_is_and_is_held_against_its_own_ankles():
    """Another studio's skeleton (here: a Body with the Bandai proportions, its ankles higher than
    the body model puts them) is stood as it is (``performer_body`` keeps a Body), calibrated
    and solved straight; the ankle error against the performer's own skeleton is then the
    difference between its ankles and the calibrated rest body's, which the benchmark reports
    beside the error against the rest body."""
    import numpy as np
    from benchmarks.standing import J, ankle_error_against, bandai_like_body, performer_body, solve_standing_full
    performer = bandai_like_body(1.80)
    assert performer_body(performer) is performer
    knees, ankle_err, res, solved, who = solve_standing_full(performer, "T", load_model())
    assert who is performer and res.pose == "T"
    k = 15
    assert knees[k:-k].max() < 10.0 and ankle_err[k:-k].max() < 0.02
    own = ankle_error_against(solved.positions, performer)[k:-k]
    rest = performer.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2]
    body_rest = solved.body.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2]
    assert np.allclose(own, np.abs(body_rest - rest), atol=0.005)
    assert (own > 0.02).all()       # the body model's ankle sits elsewhere than this skeleton's
