"""A six-tracker recording (headset, controllers, pelvis and foot trackers strapped on at random
rotations, with jitter and a T-pose; tests/fixtures_six_trackers.py) solved through the panel's
operator and the command line with the six-tracker network: the summary names the model and
the measured tracker offsets, and the solved ankles land on the foot trackers."""
import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin import cli  # noqa: E402
from blender_manikin.core.io_csv import write_csv  # noqa: E402

from fixtures_six_trackers import body_with_legs, random_mounts, six_tracker_recording  # noqa: E402

SIX = "model head, hands, pelvis and feet (manikin_s_six.onnx)"


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("six") / "six_trackers.csv"
    body = body_with_legs(1.78, 1.03)
    write_csv(str(path), six_tracker_recording(body, random_mounts(5), duration=5.0, seed=5,
                                               heading=40.0, shift=(0.3, 0.2)), axes="openxr", units="m")
    return str(path)


def _solve_in_panel(recording, **props):
    s = bpy.context.scene.manikin
    s.source = 'FILE'
    s.filepath = recording
    s.live_rig = False
    s.create_trackers = True
    for k, v in props.items():
        setattr(s, k, v)
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    return s


def test_panel_solves_six_trackers_with_the_six_tracker_model(addon, recording):
    s = _solve_in_panel(recording)
    report = s.last_report
    assert SIX in report, report
    for label in ("pelvis", "left foot", "right foot"):
        assert f"{label} tracker offset" in report and "(from the T-pose)" in report, report
    assert {o.name for o in bpy.data.collections["MANIKIN trackers"].objects} == {
        "MANIKIN_head", "MANIKIN_left_hand", "MANIKIN_right_hand", "MANIKIN_pelvis", "MANIKIN_left_foot",
        "MANIKIN_right_foot"}
    arm = s.armature
    sc = bpy.context.scene
    misses = []
    for frame in range(sc.frame_start + 5, sc.frame_end, 17):
        sc.frame_set(frame)
        for bone, empty in (("left_ankle", "MANIKIN_left_foot"), ("right_ankle", "MANIKIN_right_foot"),
                            ("pelvis", "MANIKIN_pelvis")):
            joint = (arm.matrix_world @ arm.pose.bones[bone].head)
            misses.append((joint - bpy.data.objects[empty].matrix_world.to_translation()).length)
    # the pelvis and the ankles on their trackers' targets (the legs reach: measured from the T-pose)
    assert np.median(misses) < 1e-4 and max(misses) < 0.01, (np.median(misses), max(misses))


def test_panel_model_override(addon, recording):
    s = _solve_in_panel(recording, model='HEAD_HANDS')
    assert "model manikin_s (head, left hand, right hand, chosen)" in s.last_report, s.last_report
    s.model = 'FILE'
    s.model_file = ""
    with pytest.raises(RuntimeError, match="no file is chosen"):
        bpy.ops.manikin.solve_full_body()


def test_cli_solves_six_trackers(addon, recording, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["solve", recording, "--out", str(out), "--format", "json,bvh"]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("OK ") and SIX in line and "pelvis tracker offset" in line, line
    doc = json.loads((out / "six_trackers.json").read_text())
    assert set(doc["trackers"]) == {"head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot"}
    pos = np.asarray(doc["positions"])
    feet = np.asarray(doc["trackers"]["left_foot"], dtype=float)
    miss = np.linalg.norm(pos[:, 7] - feet, axis=-1)              # joint 7: left_ankle
    assert np.median(miss) < 1e-4, float(np.median(miss))
    assert cli.main(["solve", recording, "--out", str(out), "--format", "json", "--model", "pelvis"]) == 0
    assert "model manikin_s_pelvis (head, left hand, right hand, pelvis, chosen)" in capsys.readouterr().out
    assert cli.main(["solve", recording, "--out", str(out), "--format", "json", "--model", "huge"]) == 1
    assert "model 'huge': not a file, nor one of auto, head_hands, pelvis, six" in capsys.readouterr().err
