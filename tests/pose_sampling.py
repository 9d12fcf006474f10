"""Random plausible poses for property tests (numpy only)."""
import numpy as np

from blender_manikin.core import limb_solver as ls
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk


def random_pose(rng, T, spread=0.35, flex_min=0.05):
    """Local rotations ``(T, 22, 3, 3)`` with hinge elbows/knees within limits.

    Torso and base joints get random rotations (``spread`` radians std per
    axis); mids get flexion in [flex_min, FLEX_MAX) and (arms) an elbow
    twist within the pronation range.
    """
    loc = rot.axis_angle_to_matrix(rng.normal(size=(T, sk.NUM_JOINTS, 3)) * spread)
    for li, (_, b, m, e) in enumerate(sk.LIMBS):
        th = rng.uniform(flex_min, ls.FLEX_MAX[li] - 1e-3, T)
        lo, hi = ls.TWIST_RANGE[li]
        tw = rng.uniform(lo, hi, T)
        loc[:, m] = rot.axis_angle_rotation(ls.H0[li], th) @ rot.axis_angle_rotation(ls.A0[li], tw)
        # keep wrist swing modest and twist-free so the elbow carries the twist
        sw = rng.normal(size=(T, 3)) * 0.4
        sw -= np.sum(sw * ls.A0[li], -1, keepdims=True) * ls.A0[li]
        loc[:, e] = rot.axis_angle_to_matrix(sw)
    return loc
