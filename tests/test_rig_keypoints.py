"""core/rig_keypoints.py (no bpy): a rig's bone heads as the 22 joints; joints without a bone."""
import numpy as np
import pytest

from blender_manikin.core import rig_keypoints as rk
from blender_manikin.core import skeleton as sk


def _rest(T=4):
    P = sk.make_body(1.7).rest_positions()
    return np.repeat(P[None], T, 0) + np.linspace(0, 0.3, T)[:, None, None] * np.array([1.0, 0.0, 0.0])


def test_a_full_map_is_taken_as_it_is():
    P = _rest()
    got, derived = rk.joints_from_heads({j: P[:, sk.J[j]] for j in sk.JOINT_NAMES})
    np.testing.assert_array_equal(got, P)
    assert derived == {}


def test_unmapped_spine_joints_are_spaced_along_the_chain():
    P = _rest()
    heads = {j: P[:, sk.J[j]] for j in sk.JOINT_NAMES if j not in ("spine1", "spine2", "spine3")}
    got, derived = rk.joints_from_heads(heads)
    for k, j in enumerate(("spine1", "spine2", "spine3"), start=1):
        np.testing.assert_allclose(got[:, sk.J[j]], P[:, 0] + k / 4 * (P[:, sk.J["neck"]] - P[:, 0]), atol=1e-12)
    assert rk.derived_note(derived) == "spine1, spine2, spine3 along the spine chain"


def test_a_map_without_the_limbs_is_refused_naming_them():
    bones = ["Hips", "LeftUpLeg", "RightUpLeg"]
    with pytest.raises(ValueError, match=r"rig 'X': bone map 'm' leaves joint\(s\) left_knee, left_ankle, .*"
                                         r"head \('Head' not in the rig\) without a bone"):
        rk.checked_map({"name": "m", "bones": {"pelvis": "Hips", "left_hip": "LeftUpLeg",
                                               "right_hip": "RightUpLeg", "head": "Head"}}, bones, "rig 'X'")
