"""Joint maps: axis/unit conversion, round trips through source layouts, floor, real data."""
import os
import warnings

import numpy as np
import pytest

from blender_manikin.core import skeleton
from blender_manikin.core.bvh import iter_bvh_sources, read_bvh, write_bvh
from blender_manikin.core.joint_maps import (BANDAI, CMU, MIXAMO, ORIENTED_JOINTS, REST_FOOT_PITCH, UNIT_CANDIDATES,
                                             axis_conversion, clip_to_body_motion, detect_joint_map,
                                             estimate_floor, rest_pose_report, take_id_from_name)

from fixtures_bvh import CMU_UNIT, bandai_clip, cmu_clip, mixamo_clip, synthetic_motion

J = skeleton.J
SHARED_ARCHIVE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                              "shared", "data", "bandai-namco-motion.tar.xz")


@pytest.fixture(scope="module")
def motion():
    return synthetic_motion(frames=90, seed=0)


def _through_file(clip, tmp_path, fname):
    path = tmp_path / fname
    write_bvh(path, clip)
    return read_bvh(path)


def _check_roundtrip(m, pos, rot, body):
    assert m.positions.shape == pos.shape and m.positions.dtype == np.float64
    assert np.abs(m.positions - pos).max() < 1e-6
    for n in ORIENTED_JOINTS:
        assert np.abs(m.rotations[n] - rot[:, J[n]]).max() < 1e-6, n
    assert m.foot_pitch == pytest.approx(REST_FOOT_PITCH, abs=1e-6)
    assert abs(m.floor_height) < 1e-6
    assert np.abs(m.body.offsets - body.offsets).max() < 1e-6
    assert np.abs(m.body.root_rest - body.root_rest).max() < 1e-6
    assert m.body.stature == pytest.approx(body.stature, abs=1e-6)


# --------------------------------------------------------------------------
def test_axis_conversion():
    M = axis_conversion("y", "z")
    assert np.allclose(M @ [1, 2, 3], [1, -3, 2])          # (x, y, z) -> (x, -z, y)
    assert np.isclose(np.linalg.det(M), 1.0)
    assert np.allclose(axis_conversion("z", "-y"), np.eye(3))   # already Blender
    assert np.allclose(axis_conversion("y", "-z") @ [1, 0, 0], [-1, 0, 0])
    with pytest.raises(ValueError):
        axis_conversion("y", "-y")


def test_detect_joint_map(motion):
    body, _, _, pos, rot = motion
    b = bandai_clip(body, pos[:2], rot[:2])
    c = cmu_clip(body, pos[:2], rot[:2])
    assert detect_joint_map(b.joint_names) is BANDAI
    assert detect_joint_map(c.joint_names) is CMU
    assert detect_joint_map(["cmu:" + n.upper() for n in c.joint_names]) is CMU
    with pytest.raises(ValueError, match="bandai: missing"):
        detect_joint_map(b.joint_names[:-3])
    assert len(BANDAI.table().splitlines()) == 22


MIXAMO_BVH = """HIERARCHY
ROOT mixamorig:Hips
{ OFFSET 0 100 0 CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
 JOINT mixamorig:Spine { OFFSET 0 10 0 CHANNELS 3 Zrotation Xrotation Yrotation
  JOINT mixamorig:Spine1 { OFFSET 0 12 0 CHANNELS 3 Zrotation Xrotation Yrotation
   JOINT mixamorig:Spine2 { OFFSET 0 13 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT mixamorig:Neck { OFFSET 0 15 0 CHANNELS 3 Zrotation Xrotation Yrotation
     JOINT mixamorig:Head { OFFSET 0 10 0 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 18 0 } } }
""" + "".join("""    JOINT mixamorig:{S}Shoulder {{ OFFSET {x6} 11 0 CHANNELS 3 Zrotation Xrotation Yrotation
     JOINT mixamorig:{S}Arm {{ OFFSET {x12} 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT mixamorig:{S}ForeArm {{ OFFSET {x28} 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
       JOINT mixamorig:{S}Hand {{ OFFSET {x25} 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
        End Site {{ OFFSET {x10} 0 0 }} }} }} }} }}
""".format(S=S, x6=6 * x, x12=12 * x, x28=28 * x, x25=25 * x, x10=10 * x)
              for S, x in (("Left", 1), ("Right", -1))) + """
   } } }
""" + "".join("""  JOINT mixamorig:{S}UpLeg {{ OFFSET {x9} -6 0 CHANNELS 3 Zrotation Xrotation Yrotation
   JOINT mixamorig:{S}Leg {{ OFFSET 0 -43 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT mixamorig:{S}Foot {{ OFFSET 0 -42 0 CHANNELS 3 Zrotation Xrotation Yrotation
     JOINT mixamorig:{S}ToeBase {{ OFFSET 0 -6 13 CHANNELS 3 Zrotation Xrotation Yrotation
      End Site {{ OFFSET 0 0 8 }} }} }} }} }}
""".format(S=S, x9=9 * x) for S, x in (("Left", 1), ("Right", -1))) + """}
MOTION
Frames: 2
Frame Time: 0.0166667
""" + ("0 96 0" + " 0" * 66 + "\n") * 2


def test_a_mixamo_rig_is_not_taken_for_the_cmu_map(motion):
    """A Mixamo BVH has every cgspeed CMU joint name, but its Spine1 is mid-back and its Neck sits
    on Spine2: mapped as cgspeed, spine1-3 were bunched into the lowest 17 cm of the back and
    spine3 -> neck was 34 cm, with no warning.  Detection checks the hierarchy, and the Mixamo map
    (spine1-3 spread over Hips-Neck) takes it."""
    import io
    clip = read_bvh(io.BytesIO(MIXAMO_BVH.encode()), "Walking_01.bvh")
    assert not CMU.missing(clip.joint_names)
    assert CMU.wrong_parents(clip.joint_names, clip.parents) == (
        "'mixamorig:Neck' is a child of 'mixamorig:Spine2', not of 'Spine1'",)
    assert detect_joint_map(clip.joint_names, clip.parents) is MIXAMO
    m = clip_to_body_motion(clip)
    assert m.joint_map == "mixamo" and m.unit_scale == 0.01
    spine = m.positions[0, [J[n] for n in ("pelvis", "spine1", "spine2", "spine3", "neck")]]
    steps = np.linalg.norm(np.diff(spine, axis=0), axis=1)
    assert np.allclose(steps, 0.125, atol=1e-6)                   # 50 cm Hips-Neck, in quarters
    body, _, _, pos, rot = motion
    c = cmu_clip(body, pos[:2], rot[:2])
    assert detect_joint_map(c.joint_names, c.parents) is CMU


@pytest.mark.parametrize("prefix", ["mixamorig:", ""])
def test_mixamo_layout_roundtrip(motion, tmp_path, prefix):
    """Body -> Mixamo-rig BVH (cm, Y-up, T-pose rest; with and without the namespace) -> map."""
    body, _, _, pos, rot = motion
    clip = _through_file(mixamo_clip(body, pos, rot, prefix=prefix), tmp_path, "Walking.bvh")
    assert max(rest_pose_report(clip).values()) < 1e-6
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = clip_to_body_motion(clip)
    assert m.joint_map == "mixamo" and m.unit_scale == 0.01 and m.fps == 30.0
    _check_roundtrip(m, pos, rot, body)


def test_bandai_layout_roundtrip(motion, tmp_path):
    """Body posed by FK -> Bandai-layout BVH (cm, Y-up, ZXY, non-T-pose frames) -> map."""
    body, _, _, pos, rot = motion
    clip = _through_file(bandai_clip(body, pos, rot), tmp_path, "dataset-1_walk_synthetic_001.bvh")
    assert all(len(c) == 6 for c in clip.channels)
    rep = rest_pose_report(clip)
    assert rep["spine"] > 60 and rep["left_leg"] > 60            # zero pose is not a T-pose
    m = clip_to_body_motion(clip, foot_pitch="auto")
    assert m.joint_map == "bandai" and m.unit_scale == 0.01 and m.fps == 30.0
    assert m.name == "dataset-1_walk_synthetic_001" and m.take_id == "dataset-1_walk_synthetic_001"
    _check_roundtrip(m, pos, rot, body)
    # the rest frame of every oriented joint is identity (first frame of a rest-pose clip)
    rest = np.broadcast_to(np.eye(3), (2, 22, 3, 3))
    p0, r0 = skeleton.forward_kinematics(rest, np.broadcast_to(body.root_rest, (2, 3)), body)
    m0 = clip_to_body_motion(bandai_clip(body, p0, r0), foot_pitch=None, floor=0.0)
    for n in ORIENTED_JOINTS:
        assert np.allclose(m0.rotations[n], np.eye(3), atol=1e-9), n


def test_cmu_layout_roundtrip(motion, tmp_path):
    """Body -> CMU-layout BVH (1/0.45 inch, Y-up, ZYX, 3 channels below Hips) -> map."""
    body, _, _, pos, rot = motion
    clip = _through_file(cmu_clip(body, pos, rot), tmp_path, "01_01.bvh")
    assert clip.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert all(c == ("Zrotation", "Yrotation", "Xrotation") for c in clip.channels[1:])
    assert max(rest_pose_report(clip).values()) < 1e-6           # T-pose zero pose
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = clip_to_body_motion(clip)                            # map and units auto-detected
    assert m.joint_map == "cmu" and m.fps == 120.0
    assert m.unit_scale == pytest.approx(CMU_UNIT)
    assert clip.global_transforms()[0][0, 0, 1] == pytest.approx(body.root_rest[2] / CMU_UNIT)  # ~17 units
    _check_roundtrip(m, pos, rot, body)


@pytest.mark.parametrize("unit", ["m", "mm", "inch", "cm"])
def test_unit_auto_detection(motion, unit):
    body, _, _, pos, rot = motion
    clip = bandai_clip(body, pos[:20], rot[:20], scale=UNIT_CANDIDATES[unit])
    m = clip_to_body_motion(clip, unit_scale="auto", floor=0.0)
    assert m.unit_scale == UNIT_CANDIDATES[unit]
    assert np.abs(m.positions - pos[:20]).max() < 1e-6


def test_floor_estimation(motion):
    body, _, _, pos, rot = motion
    # the source's ground is 7 cm below the performer's floor, and 3 frames
    # drop the whole body 40 cm (glitches) -- the floor estimate ignores them
    pos2, rot2 = pos.copy(), rot.copy()
    pos2[40:43] -= [0, 0, 0.4]
    clip = bandai_clip(body, pos2, rot2, raise_by=0.07)
    m = clip_to_body_motion(clip, foot_pitch="auto")
    assert m.floor_height == pytest.approx(0.07, abs=1e-6)
    ok = np.ones(len(pos), bool)
    ok[40:43] = False
    assert np.abs(m.positions[ok] - pos[ok]).max() < 1e-6
    # standing frames: ankles and balls sit at the body's rest heights
    rest = body.rest_positions()
    for n in ("left_ankle", "right_foot"):
        assert np.allclose(m.positions[:15, J[n], 2], rest[J[n], 2], atol=1e-6)
    # explicit floor and estimate_floor directly
    m2 = clip_to_body_motion(clip, foot_pitch="auto", floor=0.0)
    assert np.allclose(m2.positions[ok], pos[ok] + [0, 0, 0.07], atol=1e-6)
    z = np.zeros((100, 2, 3))
    z[:, 0, 2] = np.linspace(0.1, 1.0, 100)
    z[:, 1, 2] = 5.0
    assert estimate_floor(z, {0: 0.1, 1: 0.0}) == pytest.approx(np.percentile(np.linspace(0, 0.9, 100), 5))


def test_take_id():
    assert take_id_from_name("a/b/Dataset-1_Walk_normal_001.bvh.gz") == "dataset-1_walk_normal_001"
    assert take_id_from_name("01_01.BVH") == "01_01"


# --------------------------------------------------------------------------
@pytest.mark.skipif(not os.path.exists(SHARED_ARCHIVE), reason="Bandai Namco archive not available")
def test_real_bandai_file():
    # the first .bvh member in archive order (no full decompression needed)
    name, opener = next(iter_bvh_sources(SHARED_ARCHIVE, sort=False))
    with opener() as f:
        clip = read_bvh(f, name=name)
    assert clip.num_joints == 22 and all(len(c) == 6 for c in clip.channels)
    m = clip_to_body_motion(clip)
    assert m.joint_map == "bandai" and m.fps == 30.0 and m.unit_scale == 0.01
    P = m.positions
    head = np.median(P[:, J["head"], 2])
    assert 1.3 <= head <= 1.5
    feet = P[:, [J["left_foot"], J["right_foot"]], 2]
    assert abs(np.percentile(feet, 2)) < 0.04 and np.median(feet.min(axis=1)) < 0.06
    ankles = P[:, [J["left_ankle"], J["right_ankle"]], 2]
    assert 0.03 < np.percentile(ankles, 5) < 0.15
    # set-1 performers start facing +Z in the file, i.e. -Y after conversion
    fwd = m.rotations["pelvis"][0] @ [0, -1, 0]
    assert fwd[1] < -0.7
    # the left hip is on +X of the pelvis frame; wrists and head are proper rotations
    hip = m.rotations["pelvis"][0].T @ (P[0, J["left_hip"]] - P[0, J["pelvis"]])
    assert hip[0] > 0.04
    for n in ORIENTED_JOINTS:
        R = m.rotations[n]
        assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-9)
        assert np.allclose(np.linalg.det(R), 1.0)
    # bone lengths are constant in the source: the Body reproduces them
    L = np.linalg.norm(P[:, 1:] - P[:, skeleton.PARENTS[1:]], axis=-1)
    assert np.abs(L - m.body.bone_lengths()[1:]).max() < 1e-3


def _to_blender_axes(clip):
    """The same take written in Blender's own axes (Z up, the performer facing -Y), as Blender's BVH
    export writes an armature built in Blender: every OFFSET, End Site and world pose turned by
    ``(x, y, z) -> (x, -z, y)``."""
    from blender_manikin.core.bvh import BvhClip
    M = axis_conversion("y", "z")
    pos, rot = clip.global_transforms()
    loc = np.empty(rot.shape)
    tr = np.empty(pos.shape)
    for j in range(clip.num_joints):
        p, Rw = clip.parents[j], M @ rot[:, j] @ M.T
        if p < 0:
            loc[:, j], tr[:, j] = Rw, pos[:, j] @ M.T
        else:
            Rp = M @ rot[:, p] @ M.T
            loc[:, j] = np.swapaxes(Rp, -1, -2) @ Rw
            tr[:, j] = np.einsum("tji,tj->ti", Rp, (pos[:, j] - pos[:, p]) @ M.T)
    return BvhClip.from_local_transforms(clip.name, clip.joint_names, clip.parents, clip.offsets @ M.T,
                                         clip.channels, loc, tr, clip.frame_time, end_sites=clip.end_sites @ M.T)


def test_z_up_take_with_up_override_and_the_warning_without(motion):
    """A Z-up take mapped with ``up="z", forward="-y"`` is the Y-up take's body motion, without a
    warning (the rest-pose check measured the map's own +Y up and warned "the rest pose is not a
    T-pose ... 'spine': 90" on every such take); read as the map's Y-up, the warning says which
    file axis the spine runs along and what to give (it said only "not a T-pose")."""
    body, _, _, pos, rot = motion
    clip = cmu_clip(body, pos[:30], rot[:30])
    zup = _to_blender_axes(clip)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = clip_to_body_motion(zup, "cmu", up="z", forward="-y")
    _check_roundtrip(m, pos[:30], rot[:30], body)
    assert max(rest_pose_report(zup, "cmu", up="z", forward="-y").values()) < 1e-6
    with pytest.warns(UserWarning, match=r"its spine runs along the file's \+z axis, not the up axis in use "
                                         r"\(\+y\): if that is the file's up axis, give up 'z', forward '-y'"):
        clip_to_body_motion(zup, "cmu")


@pytest.mark.parametrize("prefix", ["Model_", "mixamorig_"])
def test_a_prefix_every_joint_shares_is_looked_past(motion, prefix, tmp_path):
    """A Mixamo rig whose every joint carries a prefix ending in ``_`` (``Model_Hips``, ``Model_Spine``,
    ... as in a public BVH; ``mixamorig_Hips`` where a tool replaced Mixamo's ``:``) is detected and
    mapped as Mixamo (it was "no joint map fits this skeleton (... mixamo: missing Hips, Spine, ...)")."""
    body, _, _, pos, rot = motion
    clip = _through_file(mixamo_clip(body, pos, rot, prefix=prefix), tmp_path, "take.bvh")
    assert clip.joint_names[0] == prefix + "Hips"
    assert detect_joint_map(clip.joint_names, clip.parents) is MIXAMO
    _check_roundtrip(clip_to_body_motion(clip), pos, rot, body)


@pytest.mark.parametrize("frame_time, fps", [(0.0333, 30.0), (0.0167, 60.0), (0.0417, 24.0), (0.0111, 90.0),
                                             (0.0083333, 120.0), (0.0333667, 1 / 0.0333667), (0.03, 1 / 0.03)])
def test_frame_time_written_with_few_digits(motion, tmp_path, frame_time, fps):
    """``Frame Time: 0.0333`` (a tool that writes four decimals) is 30 fps, the one whole rate whose
    frame time rounds to it (it was 30.03; 0.0167 gave 59.88); NTSC's 0.0333667 keeps 29.97 and
    ``0.03``, which 29-40 fps all round to, keeps 33.3."""
    body, _, _, pos, rot = motion
    clip = cmu_clip(body, pos[:4], rot[:4])
    clip.frame_time = frame_time
    m = clip_to_body_motion(_through_file(clip, tmp_path, "take.bvh"))
    assert m.fps == pytest.approx(fps, rel=1e-9)
