"""Device offsets (presets, JSON, apply/remove, targets) and T/A-pose calibration."""
import json
import os

import numpy as np
import pytest

from blender_manikin.core.calibration import (
    CalibrationError, calibrate, find_tpose, stature_from_eye_height,
)
from blender_manikin.core.device_offsets import (
    JOINT_OF_DEVICE, PRESET_NAMES, apply_offsets, get_preset, load_offsets, remove_offsets, save_offsets,
    to_targets, validate_offsets,
)
from blender_manikin.core.pose_result import TrackerTargets
from blender_manikin.core import skeleton as sk
from blender_manikin.core.formats import load_recording
from blender_manikin.core.recording import from_blender
from blender_manikin.core.resample import resample
from blender_manikin.core.rotations import (
    axis_angle_rotation, geodesic_angle, matrix_to_quat, quat_to_matrix,
)
from blender_manikin.core.skeleton import NUM_JOINTS, BodyMeasurements, J, forward_kinematics, make_body

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")
DEVS = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")


def deg(Ra, Rb):
    return np.degrees(geodesic_angle(Ra, Rb))


def rz(a_deg):
    return axis_angle_rotation(np.array([0, 0, 1.0]), np.deg2rad(a_deg))


def ry(a_deg):
    return axis_angle_rotation(np.array([0, 1.0, 0]), np.deg2rad(a_deg))


def rx(a_deg):
    return axis_angle_rotation(np.array([1.0, 0, 0]), np.deg2rad(a_deg))


# --------------------------------------------------------------------------
# synthetic performer
def body_frames(body, n, heading=0.0, arm_down=0.0, shift=(0.3, -0.2), moving=None):
    """Joint world poses of ``body`` held in a T-pose (arm_down=0) or A-pose for ``n`` frames."""
    local = np.broadcast_to(np.eye(3), (n, NUM_JOINTS, 3, 3)).copy()
    local[:, 0] = rz(heading)
    local[:, J["left_shoulder"]] = ry(arm_down)
    local[:, J["right_shoulder"]] = ry(-arm_down)
    if moving is not None:                                   # (n,) elbow flexion in degrees
        local[:, J["left_elbow"]] = axis_angle_rotation(np.array([0, 0, 1.0]), np.deg2rad(moving))
    root = np.repeat((body.root_rest + [shift[0], shift[1], 0.0])[None], n, 0)
    return forward_kinematics(local, root, body)


def device_targets(pos, rot, true_offsets, assumed_offsets, fps=60.0):
    """Record devices through ``true_offsets``, make targets with ``assumed_offsets``."""
    devpos, devquat = {}, {}
    for d in ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot"):
        j = J[JOINT_OF_DEVICE[d]]
        p, R = remove_offsets(pos[:, j], rot[:, j], true_offsets["devices"][d])
        devpos[d], devquat[d] = p, matrix_to_quat(R)
    n = pos.shape[0]
    times = np.arange(n) / fps
    valid = {d: np.ones(n, dtype=bool) for d in devpos}
    return to_targets(times, devpos, devquat, valid, assumed_offsets), devpos, devquat


def perturbed(preset, seed=1, max_deg=15.0):
    """A copy of ``preset`` whose device rotations are off by up to ``max_deg`` (mounting variation)."""
    rng = np.random.default_rng(seed)
    out = get_preset(preset)
    for d, e in out["devices"].items():
        axis = rng.normal(size=3)
        R = quat_to_matrix(np.array(e["rot"])) @ axis_angle_rotation(axis, np.deg2rad(rng.uniform(5, max_deg)))
        e["rot"] = list(matrix_to_quat(R))
    return out


# --------------------------------------------------------------------------
# device offsets
def test_presets_are_editable_copies_and_json_round_trip(tmp_path):
    assert {"none", "openxr_generic", "quest_touch", "index_knuckles", "vive_wand", "beat_saber"} <= set(PRESET_NAMES)
    a = get_preset("quest_touch")
    a["devices"]["head"]["pos"][0] = 99.0
    assert get_preset("quest_touch")["devices"]["head"]["pos"][0] == 0.0
    json.dumps(a)                                             # plain lists and floats
    for name in PRESET_NAMES:
        p = get_preset(name)
        assert set(p["devices"]) == set(DEVS) and p["description"]
        for e in p["devices"].values():
            assert len(e["pos"]) == 3 and len(e["rot"]) == 4
            assert np.linalg.norm(e["rot"]) == pytest.approx(1.0)
    path = tmp_path / "my_offsets.json"
    save_offsets(path, a)
    b = load_offsets(path)
    assert b["name"] == "quest_touch" and b["devices"]["head"]["pos"][0] == 99.0
    np.testing.assert_allclose(b["devices"]["left_hand"]["rot"], a["devices"]["left_hand"]["rot"])
    (tmp_path / "bad.json").write_text('{"devices": {"tail": {"pos": [0, 0, 0]}}}')
    with pytest.raises(ValueError, match="bad.json, line 1: unknown device 'tail'"):
        load_offsets(tmp_path / "bad.json")
    (tmp_path / "bad2.json").write_text('{"devices": {"head": {"pos": [0, 0]}}}')
    with pytest.raises(ValueError, match="bad2.json, line 1: head: 'pos' must be 3 finite numbers"):
        load_offsets(tmp_path / "bad2.json")
    (tmp_path / "bad3.json").write_text('{"devices": ')
    with pytest.raises(ValueError, match="bad3.json, line 1: not valid JSON"):
        load_offsets(tmp_path / "bad3.json")
    with pytest.raises(ValueError, match="unknown offsets preset"):
        get_preset("psvr9")


def test_head_offset_is_behind_and_below_the_eyes():
    e = get_preset("openxr_generic")["devices"]["head"]
    np.testing.assert_allclose(e["pos"], [0.0, 0.08, -0.115])
    np.testing.assert_allclose(e["rot"], [1, 0, 0, 0])
    # HMD turned 90 deg left: the head joint is then 8 cm to the HMD's right (+Y rotated to -X)
    p, R = apply_offsets(np.array([0, 0, 1.6]), rz(90.0), e)
    np.testing.assert_allclose(p, [-0.08, 0, 1.485], atol=1e-12)


@pytest.mark.parametrize("side", ["left", "right"])
def test_openxr_grip_semantics_in_a_tpose(side):
    """Holding a controller in a T-pose (palm down), the OpenXR grip pose follows the spec."""
    e = get_preset("openxr_generic")["devices"][f"{side}_hand"]
    wrist = np.array([0.75 if side == "left" else -0.75, 0.0, 1.43])
    p, R = remove_offsets(wrist, np.eye(3), e)
    _, q_xr = from_blender(None, matrix_to_quat(R), "openxr")   # grip orientation in OpenXR axes
    Rxr = quat_to_matrix(q_xr)
    down_xr = np.array([0, -1.0, 0])
    fwd_xr = np.array([0, 0, -1.0])
    # +X is normal to the palm: away from the palm (palm faces down) for the left hand, into it for the right
    assert Rxr[:, 0] @ down_xr == pytest.approx(1.0 if side == "left" else -1.0, abs=1e-9)
    # -Z runs through the fist from little finger to thumb: thumb points forward in a palm-down T-pose
    # (tilted towards the fingers by GRIP_TILT_DEG)
    assert (-Rxr[:, 2]) @ fwd_xr == pytest.approx(np.cos(np.deg2rad(15.0)), abs=1e-9)
    # grip centre (palm) is further out along the arm and below the wrist centre
    out = 1.0 if side == "left" else -1.0
    assert (p - wrist)[0] * out == pytest.approx(0.06, abs=1e-6)
    assert (p - wrist)[2] == pytest.approx(-0.02, abs=1e-6)


@pytest.mark.parametrize("side", ["left", "right"])
def test_openxr_hand_tracking_wrist_semantics_in_a_tpose(side):
    """A tracked hand in a T-pose (palm down): the XR_EXT_hand_tracking wrist joint pose is the
    wrist itself, -Z towards the fingers, +Y out of the back of the hand, +X to the thumb (left)
    or to the little finger (right)."""
    e = get_preset("openxr_hand_tracking")["devices"][f"{side}_hand"]
    wrist = np.array([0.75 if side == "left" else -0.75, 0.0, 1.43])
    p, R = remove_offsets(wrist, np.eye(3), e)
    np.testing.assert_allclose(p, wrist, atol=1e-9)
    _, q_xr = from_blender(None, matrix_to_quat(R), "openxr")
    Rxr = quat_to_matrix(q_xr)
    out_xr = np.array([-1.0 if side == "left" else 1.0, 0, 0])   # the wearer's left is OpenXR -X
    up_xr, fwd_xr = np.array([0, 1.0, 0]), np.array([0, 0, -1.0])
    np.testing.assert_allclose(-Rxr[:, 2], out_xr, atol=1e-9)       # fingers
    np.testing.assert_allclose(Rxr[:, 1], up_xr, atol=1e-9)         # back of the hand
    thumb = fwd_xr                                                   # palm down: thumbs forward
    np.testing.assert_allclose(Rxr[:, 0], thumb if side == "left" else -thumb, atol=1e-9)
    # the same in Unity axes (Meta's hand constants: distal +Z, dorsal +Y, left thumb side +X)
    _, q_u = from_blender(None, matrix_to_quat(R), "unity")
    Ru = quat_to_matrix(q_u)
    np.testing.assert_allclose(Ru[:, 2], [-1.0 if side == "left" else 1.0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(Ru[:, 1], [0, 1.0, 0], atol=1e-9)


def test_apply_remove_offsets_vectorised_and_quaternion_form():
    rng = np.random.default_rng(0)
    R = axis_angle_rotation(rng.normal(size=(50, 3)), rng.uniform(0, 3, 50))
    p = rng.normal(size=(50, 3))
    for name in ("quest_touch", "index_knuckles", "beat_saber"):
        e = get_preset(name)["devices"]["right_hand"]
        jp, jR = apply_offsets(p, R, e)
        dp, dR = remove_offsets(jp, jR, e)
        np.testing.assert_allclose(dp, p, atol=1e-12)
        np.testing.assert_allclose(dR, R, atol=1e-12)
        jp2, jq = apply_offsets(p, matrix_to_quat(R), e)
        np.testing.assert_allclose(jp2, jp, atol=1e-12)
        assert deg(quat_to_matrix(jq), jR).max() < 1e-4
        # convention: joint_rot = device_rot @ offset_rot, joint_pos = device_pos + device_rot @ offset_pos
        np.testing.assert_allclose(jR, R @ quat_to_matrix(np.array(e["rot"])), atol=1e-12)
        np.testing.assert_allclose(jp, p + R @ np.array(e["pos"]), atol=1e-12)


def test_to_targets():
    times = np.arange(10) / 30
    pos = {"head": np.tile([0, 0, 1.6], (10, 1)), "left_hand": np.zeros((10, 3))}
    quat = {d: np.tile([1.0, 0, 0, 0], (10, 1)) for d in pos}
    t = to_targets(times, pos, quat, {"head": np.arange(10) > 2}, "openxr_generic")
    assert isinstance(t, TrackerTargets) and t.fps == pytest.approx(30)
    assert t.devices == ("head", "left_hand") and t.num_frames == 10
    np.testing.assert_allclose(t.pos["head"][0], [0, 0.08, 1.485])
    assert t.rot["left_hand"].shape == (10, 3, 3)
    assert t.valid["head"].sum() == 7 and t.valid["left_hand"].all()
    assert validate_offsets(None)["devices"]["head"]["pos"] == [0.0, 0.0, 0.0]


# --------------------------------------------------------------------------
# calibration
@pytest.mark.parametrize("stature,span,heading", [(1.75, None, 0.0), (1.62, 1.70, 30.0), (1.91, 1.83, -120.0)])
def test_tpose_recovers_stature_span_and_rotation_offsets(stature, span, heading):
    body = make_body(BodyMeasurements(stature=stature, arm_span=span))
    true_span = np.linalg.norm(body.rest_positions()[J["left_wrist"]] - body.rest_positions()[J["right_wrist"]])
    pos, rot = body_frames(body, 60, heading=heading)
    true_off = perturbed("openxr_generic", seed=int(stature * 100))
    targets, devpos, devquat = device_targets(pos, rot, true_off, "openxr_generic")
    res = calibrate(targets, time=0.5, offsets="openxr_generic")
    assert res.plausible, res.problems
    assert res.pose == "T" and abs(res.arm_angle_deg) < 0.5
    assert res.measurements.stature == pytest.approx(stature, abs=0.01)
    assert res.measurements.arm_span == pytest.approx(true_span, abs=0.01)
    if span is not None:
        assert res.measurements.arm_span == pytest.approx(span, abs=0.01)
    assert res.heading_deg == pytest.approx(heading, abs=0.5)
    # the updated offsets map the devices onto the true joint orientations (within 1 degree)
    for d in DEVS:
        j = J[JOINT_OF_DEVICE[d]]
        _, jR = apply_offsets(devpos[d], quat_to_matrix(devquat[d]), res.offsets["devices"][d])
        assert deg(jR, rot[:, j]).max() < 1.0, d
        assert res.rotation_change_deg[d] > 4.0                     # the perturbation was seen
        if d in ("head", "left_hand", "right_hand"):          # their positions are the preset's;
            assert res.offsets["devices"][d]["pos"] == get_preset("openxr_generic")["devices"][d]["pos"]
        else:                                                 # the extra trackers' are measured
            assert np.linalg.norm(res.offsets["devices"][d]["pos"]) < 0.01, d
    # and the calibrated body rebuilt from the measurements has the performer's span
    rebuilt = make_body(res.measurements).rest_positions()
    assert np.linalg.norm(rebuilt[J["left_wrist"]] - rebuilt[J["right_wrist"]]) == pytest.approx(true_span, abs=0.01)


@pytest.mark.parametrize("stature,droop", [(1.55, 10.0), (1.75, 15.0), (1.95, 19.0)])
def test_a_tpose_with_the_arms_below_horizontal_measures_the_whole_span(stature, droop):
    """Performers rarely hold a T-pose level: with the arms up to 19° below horizontal (still a
    T-pose) the span is measured along the arms, from the shoulders, not as the wrists'
    distance, which is 1.6-7.1 cm short at 10-19° (the arms came out that much too short)."""
    body = make_body(stature)
    rest = body.rest_positions()
    true_span = np.linalg.norm(rest[J["left_wrist"]] - rest[J["right_wrist"]])
    pos, rot = body_frames(body, 60, heading=25.0, arm_down=droop)
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    res = calibrate(targets, time=0.5)
    assert res.plausible, res.problems
    assert res.pose == "T" and res.arm_angle_deg == pytest.approx(droop, abs=0.5)
    assert res.measured["wrist_distance"] < true_span - 0.015          # what the wrists alone say
    assert res.measurements.arm_span == pytest.approx(true_span, abs=0.003)


def test_apose_is_classified_and_tilts_the_wrists():
    body = make_body(BodyMeasurements(stature=1.80, arm_span=1.62))
    pos, rot = body_frames(body, 60, heading=15.0, arm_down=40.0)
    true_off = perturbed("quest_touch", seed=5)
    targets, devpos, devquat = device_targets(pos, rot, true_off, "quest_touch")
    res = calibrate(targets, time=0.5, offsets="quest_touch")
    assert res.plausible, res.problems
    assert res.pose == "A" and res.arm_angle_deg == pytest.approx(40.0, abs=0.5)
    assert res.measurements.stature == pytest.approx(1.80, abs=0.01)
    assert res.measurements.arm_span == pytest.approx(1.62, abs=0.01)
    for d in ("left_hand", "right_hand", "head"):
        j = J[JOINT_OF_DEVICE[d]]
        _, jR = apply_offsets(devpos[d], quat_to_matrix(devquat[d]), res.offsets["devices"][d])
        assert deg(jR, rot[:, j]).max() < 1.0, d
    # forcing "T" on an A-pose is reported
    assert any("not a T-pose" in p for p in calibrate(targets, time=0.5, offsets="quest_touch", pose="T").problems)


def test_implausible_poses_are_reported():
    body = make_body(1.75)
    # arms hanging down: not a T/A-pose
    pos, rot = body_frames(body, 60, arm_down=85.0)
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    res = calibrate(targets, time=0.5)
    assert not res.plausible
    assert any("below horizontal" in p for p in res.problems)
    assert any("apart" in p for p in res.problems)
    with pytest.raises(CalibrationError, match="not a usable"):
        calibrate(targets, time=0.5, strict=True)
    # a T-pose while the left elbow bends and straightens: moving and bent
    flex = 60.0 * (0.5 - 0.5 * np.cos(np.linspace(0, 2 * np.pi, 60)))
    pos, rot = body_frames(body, 60, moving=flex)
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    res = calibrate(targets, time=0.5)
    assert any("left_hand moved" in p and "hold still" in p for p in res.problems)
    # head turned away from the arms' line
    pos, rot = body_frames(body, 60)
    rot[:, J["head"]] = rz(40.0) @ rot[:, J["head"]]
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    assert any("look straight ahead" in p for p in calibrate(targets, time=0.5).problems)
    with pytest.raises(ValueError, match="outside the recording"):
        calibrate(targets, time=5.0)


def test_measurements_pass_through_and_override():
    body = make_body(1.75)
    pos, rot = body_frames(body, 30)
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    m = BodyMeasurements(stature=1.81, arm_span=1.9, upper_arm=0.3)
    res = calibrate(targets, time=0.25, measurements=m)
    assert res.measurements is m
    assert res.measured["stature"] == pytest.approx(1.75, abs=0.01)
    res = calibrate(targets, time=0.25, measurements={"stature": 1.80})
    assert res.measurements.stature == 1.80
    assert res.measurements.arm_span == pytest.approx(res.measured["arm_span"])


def test_find_tpose_picks_the_still_tpose_moment():
    body = make_body(1.70)
    n = 300                                                     # 5 s at 60 fps
    t = np.arange(n) / 60
    arm = np.where((t > 2.0) & (t < 3.0), 0.0, 70.0 + 10 * np.sin(3 * t))
    arm = np.convolve(np.pad(arm, 10, mode="edge"), np.ones(21) / 21, mode="valid")
    local = np.broadcast_to(np.eye(3), (n, NUM_JOINTS, 3, 3)).copy()
    local[:, J["left_shoulder"]] = axis_angle_rotation(np.array([0, 1.0, 0]), np.deg2rad(arm))
    local[:, J["right_shoulder"]] = axis_angle_rotation(np.array([0, 1.0, 0]), np.deg2rad(-arm))
    pos, rot = forward_kinematics(local, np.repeat(body.root_rest[None], n, 0), body)
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    cand = find_tpose(targets, t0=10.0)
    assert 12.1 <= cand.time <= 12.9 and cand.plausible
    assert cand.frame == int(round((cand.time - 10.0) * 60))
    res = calibrate(targets, time=cand.time, t0=10.0)
    assert res.plausible and res.measurements.stature == pytest.approx(1.70, abs=0.01)
    # default time: find_tpose is used
    assert calibrate(targets).frame == cand.frame


def test_arms_spread_while_lying_or_crouching_are_not_a_tpose():
    """Arms out at shoulder height are a T-pose only when the head stands as high as a standing
    performer's: lying on the back with the arms spread on the floor (HDM05's lie-down takes,
    which once calibrated a 7 cm body and failed the solve) or crouching with the arms out is
    not one; in a take with both, the standing T-pose is found."""
    body = make_body(1.75)
    n = 60
    pos, rot = body_frames(body, n)
    on_back = rx(-90.0)                                             # face up, the feet along -y
    pelvis = pos[0, 0]
    lying_pos = (pos - pelvis) @ on_back.T + [pelvis[0], pelvis[1], 0.12]
    lying_rot = on_back @ rot
    for p_, r_ in ((lying_pos, lying_rot), (pos - [0.0, 0.0, 0.6], rot)):
        targets, *_ = device_targets(p_, r_, get_preset("none"), "none")
        assert not find_tpose(targets).plausible
        with pytest.raises(CalibrationError, match="not a usable"):
            calibrate(targets, strict=True)
    both, *_ = device_targets(np.concatenate([lying_pos, pos]), np.concatenate([lying_rot, rot]),
                              get_preset("none"), "none")
    cand = find_tpose(both)
    assert cand.plausible and cand.frame >= n
    assert calibrate(both).measurements.stature == pytest.approx(1.75, abs=0.01)


def test_example_recording_calibrates_to_its_body():
    rec = load_recording(EXAMPLE)
    times, pos, quat, valid, report = resample(rec, 60)
    targets = to_targets(times, pos, quat, valid, "openxr_generic")
    cand = find_tpose(targets, t0=times[0])
    assert cand.plausible and cand.time < 1.0
    res = calibrate(targets, time=cand.time, offsets="openxr_generic", t0=times[0])
    assert res.plausible, res.problems
    assert res.measurements.stature == pytest.approx(1.75, abs=0.01)
    body = make_body(1.75).rest_positions()
    assert res.measurements.arm_span == pytest.approx(
        np.linalg.norm(body[J["left_wrist"]] - body[J["right_wrist"]]), abs=0.01)
    assert max(res.rotation_change_deg.values()) < 1.0       # the example was recorded with these offsets


def test_stature_from_eye_height():
    """Eyes at 0.936 of the barefoot stature, lifted by the shoe soles (3 cm unless given)."""
    assert sk.SOLE == 0.03
    assert stature_from_eye_height(1.668) == pytest.approx(1.75, abs=0.001)
    assert stature_from_eye_height(1.638, sole=0.0) == pytest.approx(1.75, abs=0.001)
    body = make_body(1.75)
    eyes = body.rest_positions()[J["head"], 2] + (sk.PROPORTIONS["eye_height"] - sk.PROPORTIONS["head_height"]) * 1.75
    assert stature_from_eye_height(eyes) == pytest.approx(1.75, abs=1e-9)


def test_apply_offsets_with_a_whole_offsets_set():
    R = rz(30.0)
    p = np.array([0.1, 0.2, 1.5])
    e = get_preset("index_knuckles")["devices"]["left_hand"]
    a = apply_offsets(p, R, e)
    b = apply_offsets(p, R, "index_knuckles", device="left_hand")
    c = apply_offsets(p, R, get_preset("index_knuckles"), device="left_hand")
    for x in (b, c):
        np.testing.assert_allclose(x[0], a[0], atol=1e-12)
        np.testing.assert_allclose(x[1], a[1], atol=1e-9)
    np.testing.assert_allclose(remove_offsets(*a, "index_knuckles", device="left_hand")[0], p, atol=1e-12)


BSOR_SAMPLE = os.path.join(ROOT, "..", "shared", "data", "vr", "beatsaber-replay-sample.bsor")


@pytest.mark.skipif(not os.path.isfile(BSOR_SAMPLE), reason="real BSOR sample (../shared) not available")
def test_beat_saber_preset_puts_wrists_within_reach_on_real_data():
    """With the saber-to-wrist offsets, the wrists of a real player stay within arm's reach."""
    rec = load_recording(BSOR_SAMPLE)
    times, pos, quat, valid, report = resample(rec, 60)

    def reach_ratio(preset):
        tg = to_targets(times, pos, quat, valid, preset)
        head = tg.pos["head"]
        H = np.median(head[:, 2]) / sk.PROPORTIONS["head_height"]
        yaw_fwd = tg.rot["head"][:, :, 1] * [1, 1, 0]                   # backward axis, horizontal
        left = np.cross(yaw_fwd / np.linalg.norm(yaw_fwd, axis=1, keepdims=True), [0, 0, 1.0])
        out = []
        for d, s in (("left_hand", 1.0), ("right_hand", -1.0)):
            below = (sk.PROPORTIONS["head_height"] - sk.PROPORTIONS["shoulder_height"]) * H
            shoulder = head + s * left * 0.1045 * H - np.array([0.0, 0.0, below])
            dist = np.linalg.norm(tg.pos[d] - shoulder, axis=1)
            out.append(np.percentile(dist, 99) / (0.332 * H))
        return max(out)

    assert reach_ratio("beat_saber") < 1.1
    assert reach_ratio("none") > reach_ratio("beat_saber") + 0.05


def test_stature_warning_names_the_likely_cause():
    from blender_manikin.core.calibration import stature_warning
    assert stature_warning(1.75, 1.59, "T-pose") is None
    assert stature_warning(1.40, 1.27, "head height") is None and stature_warning(2.10, 1.9, "T-pose") is None
    low = stature_warning(0.35, 0.32, "head height")
    assert low.startswith("estimated stature 0.35 m is outside 1.40-2.10 m") and "floor" in low
    assert "0.32 m above height 0" in low and "set the performer's height" in low and "--floor" in low
    assert "performer sits" in low                           # sized by the head: seated is a cause
    assert "sits" not in stature_warning(0.35, 0.32, "T-pose")           # a T-pose is stood
    # centimetres read as metres: the unit factor that makes it plausible is named
    cm = stature_warning(175.0, 159.0, "head height", units="m")
    assert "--units cm" in cm and "1.75 m" in cm
    mm = stature_warning(1750.0, 1590.0, "T-pose", units="m")
    assert "--units mm" in mm
    assert "--units" not in low
    typed = stature_warning(2.5, 1.6, "height setting")
    assert "check the height setting (2.50 m)" in typed and "floor" not in typed


@pytest.mark.parametrize("droop", [15.0, 25.0, 40.0, 55.0])
def test_auto_calibration_finds_a_low_t_pose_or_an_a_pose(droop):
    """*Auto* calibrates on a T-pose held up to 20° low and on an A-pose (20-65°), as the README
    says: find_tpose wants the hands at shoulder height (arms more than about 12° low miss it, and
    the take was sized by its head alone, the span proportional and the hands' rotations not
    refined); the solve then asks find_apose.  Arms hanging relaxed (75°) are neither."""
    from blender_manikin.core import solve as cs
    body = make_body(BodyMeasurements(stature=1.80, arm_span=1.66))      # arms 6 % longer than proportional
    pos, rot = body_frames(body, 60, heading=30.0, arm_down=droop)
    targets, *_ = device_targets(pos, rot, get_preset("none"), "none")
    b, _, info = cs.calibrate(cs.SolveSettings(fps=60.0), targets, np.arange(60) / 60.0, "none")
    assert info[0].startswith(f"calibrated on {'a T' if droop < 20 else 'an A'}-pose"), info
    assert b.stature == pytest.approx(1.80, abs=0.01)
    rest = b.rest_positions()
    assert np.linalg.norm(rest[J["left_wrist"]] - rest[J["right_wrist"]]) == pytest.approx(1.66 + 0.02, abs=0.01)
    from blender_manikin.core.calibration import find_apose
    assert find_apose(targets).plausible
    relaxed, *_ = device_targets(*body_frames(body, 60, arm_down=75.0), get_preset("none"), "none")
    assert not find_apose(relaxed).plausible
