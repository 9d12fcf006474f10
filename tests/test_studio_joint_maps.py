"""Joint-map presets for mocap systems' BVH exports (Perception Neuron, Rokoko, Xsens MVN), checked
on hierarchies rebuilt from real files (``fixtures_studio_bvh``): detection by joint names and
hierarchy, the rest-pose check, and where the 22 joints land."""
import warnings
from dataclasses import replace

import numpy as np
import pytest

from blender_manikin.core import joint_maps as jmod
from blender_manikin.core.bvh import read_bvh

import fixtures_studio_bvh as studio

J = jmod._J
M_YUP = jmod.axis_conversion("y", "z")


def _clip(tmp_path, name, joints, channels, frames=None):
    path = tmp_path / f"{name}.bvh"
    path.write_text(studio.bvh_text(joints, channels, frames))
    return read_bvh(path)


def _stature(m):
    return m.body.rest_positions()[J["head"], 2] / 0.870


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("joints, channels, expected", [
    (studio.NEURON, studio.NEURON_CHANNELS, "neuron"),
    (studio.ROKOKO, studio.ROKOKO_CHANNELS, "rokoko"),
    (studio.XSENS_MVN, studio.XSENS_MVN_CHANNELS, "100style"),
], ids=["neuron", "rokoko", "xsens_mvn"])
def test_each_systems_header_is_detected(tmp_path, joints, channels, expected):
    """Neuron (cgspeed names, no toe joint, Neck on Spine3), Rokoko (Mixamo's names plus
    LeftInHandIndex finger roots) and Xsens MVN (Chest..Chest4) each get their own preset."""
    clip = _clip(tmp_path, expected, joints, channels)
    assert jmod.detect_joint_map(jmod.point_names(clip), clip.parents).name == expected
    assert jmod.get_joint_map(None, clip).name == expected


def test_neuron_tpose_lands_on_the_body(tmp_path):
    """Axis Neuron header in its own zero pose (a T-pose): no warning, rest check 0, stature of its
    ~1.95 m default skeleton, feet on the floor, the foot point at the foot's End Site, hands at
    the wrists, identity orientations."""
    clip = _clip(tmp_path, "neuron_take", studio.NEURON, studio.NEURON_CHANNELS)
    assert max(jmod.rest_pose_report(clip, "neuron").values()) < 1e-6
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = jmod.clip_to_body_motion(clip)
    assert m.joint_map == "neuron" and m.unit_scale == 0.01
    assert 1.85 < _stature(m) < 2.05
    P = m.positions[0]
    assert 0.0 <= P[J["left_foot"], 2] < 0.04 and 0.0 <= P[J["right_foot"], 2] < 0.04
    assert 0.07 < P[J["left_ankle"], 2] < 0.13
    src, rot = clip.global_transforms()
    ends = clip.end_site_positions(src, rot)
    names = jmod.point_names(clip)
    foot_end = ends[0, names.index("LeftFoot/End Site") - clip.num_joints]
    lfoot = M_YUP @ foot_end * 0.01
    lhand = M_YUP @ src[0, clip.joint_names.index("LeftHand")] * 0.01
    off = m.positions[0, J["pelvis"]] - M_YUP @ src[0, 0] * 0.01          # the floor shift
    np.testing.assert_allclose(P[J["left_foot"]], lfoot + off, atol=1e-9)
    np.testing.assert_allclose(P[J["left_wrist"]], lhand + off, atol=1e-9)
    assert P[J["left_wrist"], 0] > 0.6 and P[J["right_wrist"], 0] < -0.6     # arms out along +-X
    assert P[J["head"], 2] > P[J["neck"], 2] > P[J["spine3"], 2] > P[J["pelvis"], 2]
    for R in m.rotations.values():
        np.testing.assert_allclose(R, np.broadcast_to(np.eye(3), R.shape), atol=1e-9)


def test_rokoko_take_lands_on_the_body(tmp_path):
    """Four frames of a real Rokoko take (bones along local +X, not a T-pose): no warning, a
    plausible stature, feet on the floor while standing, hands at the wrists, and the
    orientations agree with the file's own geometry (hand along its fingers, thumb side towards the
    thumb root, head facing where the pelvis faces, ankle lateral axis along the pelvis' left)."""
    clip = _clip(tmp_path, "jesse_dance", studio.ROKOKO, studio.ROKOKO_CHANNELS, studio.ROKOKO_FRAMES)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = jmod.clip_to_body_motion(clip)
    assert m.joint_map == "rokoko" and m.unit_scale == 0.01 and m.fps == 100.0
    assert 1.7 < _stature(m) < 1.95
    P = m.positions
    assert np.all(P[:2, [J["left_foot"], J["right_foot"]], 2] < 0.05)       # frames 1-2: standing
    assert np.all(_unit(P[:, J["head"]] - P[:, J["pelvis"]])[:, 2] > 0.95)
    src, _ = clip.global_transforms()
    ix = {n: i for i, n in enumerate(clip.joint_names)}
    w = np.einsum("ij,tkj->tki", M_YUP * 0.01, src)
    w += (P[:, J["pelvis"]] - w[:, ix["Hips"]])[:, None]
    np.testing.assert_allclose(P[:, J["left_wrist"]], w[:, ix["LeftHand"]], atol=1e-9)
    np.testing.assert_allclose(P[:, J["right_ankle"]], w[:, ix["RightFoot"]], atol=1e-9)
    np.testing.assert_allclose(P[:, J["left_foot"]], w[:, ix["LeftToeBase"]], atol=1e-9)
    R = m.rotations
    for side, S, along in (("left", "Left", 1.0), ("right", "Right", -1.0)):
        hand = _unit(w[:, ix[f"{S}HandMiddle1"]] - w[:, ix[f"{S}Hand"]])
        thumb = _unit(w[:, ix[f"{S}HandThumb1"]] - w[:, ix[f"{S}Hand"]])
        assert np.all(np.einsum("tij,j,ti->t", R[f"{side}_wrist"], [along, 0, 0], hand) > 0.99)
        assert np.all(np.einsum("tij,j,ti->t", R[f"{side}_wrist"], [0, -1, 0], thumb) > 0.7)
        lateral = np.einsum("tij,j->ti", R[f"{side}_ankle"], [1, 0, 0])
        assert np.all(np.einsum("ti,ti->t", lateral, np.einsum("tij,j->ti", R["pelvis"], [1, 0, 0])) > 0.7)
    face = np.einsum("tij,j->ti", R["head"], [0, -1, 0])
    assert np.all(np.einsum("ti,ti->t", face, np.einsum("tij,j->ti", R["pelvis"], [0, -1, 0])) > 0.85)


def test_rokoko_without_fingers_read_as_mixamo_names_the_file(tmp_path):
    """A Rokoko BVH without finger joints has exactly Mixamo's names and hierarchy, so it is read
    as 'mixamo', whose orientations need a T-pose rest: the error names the file and the preset to
    give (before: a bare 'primary and secondary axes are parallel'); with 'rokoko' it maps."""
    fingers = ("Index", "Middle", "Ring", "Pinky", "Thumb")
    joints = tuple(r for r in studio.ROKOKO if not any(f in r[0] for f in fingers))
    clip = _clip(tmp_path, "no_fingers", joints, studio.ROKOKO_CHANNELS)
    assert jmod.get_joint_map(None, clip).name == "mixamo"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                  # the rest-pose warning comes first
        with pytest.raises(ValueError, match=r"no_fingers: joint map 'mixamo': orientations\.left_ankle: .*"
                                             r"give the joint map 'rokoko'"):
            jmod.clip_to_body_motion(clip)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert jmod.clip_to_body_motion(clip, "rokoko").joint_map == "rokoko"


def test_parallel_axes_name_rokoko_only_for_the_mixamo_map(tmp_path):
    """The advice to give 'rokoko' is for a Rokoko take read as 'mixamo'; another map whose axes
    come out parallel on a rig (here a map whose ankle secondary is local +X, the Rokoko foot's
    bone direction) is refused without it."""
    clip = _clip(tmp_path, "rokoko_other_map", studio.ROKOKO, studio.ROKOKO_CHANNELS)
    ori = dict(jmod.ROKOKO.orientations, left_ankle=jmod.OrientationSpec(
        "LeftFoot", jmod.bone("LeftFoot", "LeftToeBase"), jmod.local(1, 0, 0)))    # +X is along that bone
    jm = replace(jmod.ROKOKO, name="studio_file", orientations=ori)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=r"rokoko_other_map: joint map 'studio_file': orientations\.left_ankle: "
                                             r"its primary and secondary axes are parallel") as e:
            jmod.clip_to_body_motion(clip, jm)
    assert "rokoko'" not in str(e.value)
