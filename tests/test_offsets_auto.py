"""Auto offsets on a CSV that does not say what its poses are (core/offsets_auto.py): a headset's
view pose is told from the head joint by the take's T-pose, else by the head's name; joint poses
(mocap) stay joint poses, whatever they are called."""
import os
import sys

import numpy as np
import pytest

from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk
from blender_manikin.core.device_offsets import remove_offsets
from blender_manikin.core.offsets_auto import HEADSET_PRESET
from blender_manikin.core.solve import SolveSettings, solve_recording

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks"))
from standing import bandai_like_body, standing_targets  # noqa: E402

from fixtures_recordings import write_wide_poses  # noqa: E402

DEVICES = ("head", "left_hand", "right_hand")


def write_wide(path, body, pose, labels, headset, droop=0.0):
    """A wide CSV (OpenXR axes, metres, seconds) of ``body`` standing 4 s in ``pose``, then 2 s
    with its arms reaching forward; each device's columns named by ``labels``; ``headset``: the
    poses a headset and grip poses give (:data:`HEADSET_PRESET` taken off the joints), else the
    joints' own.  droop: metres the hands hang lower during the hold (a tired T-pose)."""
    holds = [standing_targets(body, pose, seconds=4.0), standing_targets(body, "forward", seconds=2.0)]
    for d in ("left_hand", "right_hand"):               # droop: the hands this much lower in the hold
        holds[0].pos[d][:, 2] -= droop
    T = sum(h.num_frames for h in holds)
    pos, quat = {}, {}
    for d in DEVICES:
        p = np.concatenate([h.pos[d] for h in holds])
        R = np.concatenate([h.rot[d] for h in holds])
        if headset:
            p, R = remove_offsets(p, R, HEADSET_PRESET, d)
        pos[d], quat[d] = p, rot.matrix_to_quat(R)
    return write_wide_poses(path, np.arange(T) / holds[0].fps, pos, quat, labels)


JOINT_NAMES = {"head": "head", "left_hand": "left_hand", "right_hand": "right_hand"}
HEADSET_NAMES = {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}


def _solve(path):
    out = solve_recording(str(path), SolveSettings(fps=30.0))
    return out, out.summary()


@pytest.mark.parametrize("stature", [1.50, 1.75, 2.00])
def test_a_headset_take_with_a_t_pose_is_read_as_a_headset_whatever_its_names(tmp_path, stature):
    body = sk.make_body(stature)
    for labels in (HEADSET_NAMES, JOINT_NAMES):
        out, summary = _solve(write_wide(tmp_path / "take.csv", body, "T", labels, headset=True))
        assert f"offsets {HEADSET_PRESET} (auto: the T-pose at" in summary, summary
        assert "choose offsets none" in summary and "axes openxr" in summary
        assert abs(out.result.body.stature - stature) < 0.01, summary           # not 7 % too tall


@pytest.mark.parametrize("body", [sk.make_body(1.50), sk.make_body(2.00), bandai_like_body(1.70)],
                         ids=["1.50", "2.00", "bandai"])
def test_joint_poses_with_a_t_pose_stay_joint_poses_even_named_as_a_headset(tmp_path, body):
    for labels in (JOINT_NAMES, HEADSET_NAMES):
        path = write_wide(tmp_path / "take.csv", body, "T", labels, headset=False)
        out, summary = _solve(path)
        assert "auto:" not in summary and "calibrated on a T-pose" in summary, summary
        stated = solve_recording(str(path), SolveSettings(fps=30.0, offsets="none"))
        assert out.result.body.stature == stated.result.body.stature        # as if "none" was chosen
        np.testing.assert_array_equal(out.result.positions, stated.result.positions)


def test_without_a_t_pose_the_head_s_name_decides(tmp_path):
    body = sk.make_body(1.75)
    out, summary = _solve(write_wide(tmp_path / "hmd.csv", body, "A", HEADSET_NAMES, headset=True))
    assert f"offsets {HEADSET_PRESET} (auto: the head samples are named 'hmd', a headset" in summary, summary
    assert abs(out.result.body.stature - 1.75) < 0.03, summary
    out, summary = _solve(write_wide(tmp_path / "head.csv", body, "A", JOINT_NAMES, headset=False))
    assert "auto:" not in summary and abs(out.result.body.stature - 1.75) < 0.03, summary


def test_a_file_or_a_user_that_states_the_offsets_is_not_second_guessed(tmp_path):
    body = sk.make_body(1.75)
    path = write_wide(tmp_path / "take.csv", body, "T", JOINT_NAMES, headset=True)
    out = solve_recording(str(path), SolveSettings(fps=30.0, offsets="none"))
    assert "auto:" not in out.summary()
    assert out.result.body.stature > 1.8                  # what "none" makes of a headset, as asked


def test_a_native_csv_whose_head_rows_say_hmd(tmp_path):
    """The native format's device column may name the hardware (``hmd``): without a T-pose that
    is what the auto offsets go by; its other names (``head``) leave the poses as the joints'."""
    from blender_manikin.core.io_csv import write_csv
    from blender_manikin.core.recording import Recording, TrackerStream
    tg = standing_targets(sk.make_body(1.80), "A", seconds=3.0)
    t = np.arange(tg.num_frames) / tg.fps
    streams = {}
    for d in DEVICES:
        p, R = remove_offsets(tg.pos[d], tg.rot[d], HEADSET_PRESET, d)
        streams[d] = TrackerStream(d, t, p, rot.matrix_to_quat(R))
    path = tmp_path / "hmd.csv"
    write_csv(path, Recording(streams=streams, source="synthetic"))
    text = path.read_text()
    path.write_text(text.replace(",head,", ",hmd,"))
    out, summary = _solve(path)
    assert f"offsets {HEADSET_PRESET} (auto: the head samples are named 'hmd'" in summary, summary
    assert abs(out.result.body.stature - 1.80) < 0.03
    path.write_text(text)
    out, summary = _solve(path)
    assert "auto:" not in summary and out.result.body.stature > 1.9         # a headset taken as the joint


@pytest.mark.parametrize("droop", [0.10, 0.14, 0.16])
def test_a_drooped_mocap_t_pose_stays_joint_poses(tmp_path, droop):
    """Mocap hands 14-16 cm below the shoulders in the T-pose are no T-pose read as joints, and
    one read as a headset (its shoulders 11 cm lower), but the head joint stands level with the
    hands, not 8 cm ahead of them as a headset does: still joint poses."""
    path = write_wide(tmp_path / "take.csv", sk.make_body(1.75), "T", JOINT_NAMES, headset=False, droop=droop)
    out, summary = _solve(path)
    assert "auto:" not in summary, summary


@pytest.mark.parametrize("name,headset", [
    ("HMD", True), ("CenterEyeAnchor", True), ("Main Camera", True), ("VR_Camera.001", True), ("xr_head", True),
    ("XRHead", True), ("hmd_pose", True), ("headset", True),
    ("head", False), ("Head", False), ("MANIKIN_head", False), ("head_pose", False), ("LeftHand", False)])
def test_headset_names(name, headset):
    from blender_manikin.core.offsets_auto import is_headset_name
    assert is_headset_name(name) is headset


def test_a_meta_rig_export_without_a_t_pose(tmp_path):
    """An OVRCameraRig log (CenterEyeAnchor, LeftControllerAnchor, ...) with no T-pose: the
    headset's name decides."""
    names = {"head": "CenterEyeAnchor", "left_hand": "LeftControllerAnchor", "right_hand": "RightControllerAnchor"}
    out, summary = _solve(write_wide(tmp_path / "ovr.csv", sk.make_body(1.68), "A", names, headset=True))
    assert "head=CenterEyeAnchor_*" in summary
    assert "named 'CenterEyeAnchor', a headset" in summary, summary
    assert abs(out.result.body.stature - 1.68) < 0.03


def test_a_hand_tracked_take_s_summary_names_the_hand_tracking_preset(tmp_path):
    """Hands tracked without controllers (the OpenXR hand-tracking wrist joint) beside a headset:
    auto takes them for grip poses, the solved wrists 6 cm off the performer's, and the summary named
    only ``none`` as the other choice; it names ``openxr_hand_tracking`` too, which puts them on."""
    body = sk.make_body(1.75)
    holds = [standing_targets(body, "T", seconds=4.0), standing_targets(body, "forward", seconds=2.0)]
    T = sum(h.num_frames for h in holds)
    pos, quat, joints = {}, {}, {}
    for d in DEVICES:
        joints[d] = np.concatenate([h.pos[d] for h in holds])
        R = np.concatenate([h.rot[d] for h in holds])
        p, R = remove_offsets(joints[d], R, HEADSET_PRESET if d == "head" else "openxr_hand_tracking", d)
        pos[d], quat[d] = p, rot.matrix_to_quat(R)
    path = write_wide_poses(tmp_path / "hands.csv", np.arange(T) / holds[0].fps, pos, quat, HEADSET_NAMES)

    def wrist_error(out):
        res = out.result
        f = np.clip(np.round((res.t0 + np.arange(res.num_frames) / res.fps) * holds[0].fps).astype(int), 0, T - 1)
        return max(float(np.median(np.linalg.norm(res.positions[:, sk.J[j]] - joints[d][f], axis=-1)))
                   for d, j in (("left_hand", "left_wrist"), ("right_hand", "right_wrist")))
    out, summary = _solve(path)
    assert "openxr_hand_tracking if the hands are tracked without controllers" in summary, summary
    assert wrist_error(out) > 0.04
    out = solve_recording(str(path), SolveSettings(fps=30.0, offsets="openxr_hand_tracking"))
    assert wrist_error(out) < 0.01
