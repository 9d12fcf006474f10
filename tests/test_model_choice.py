"""Networks per tracker set: the solve picks the shipped model for the recording's trackers, bridges
a short tracker loss, and solves a long one with the smaller model, cross-faded at the boundaries.

Generated six-tracker performances (tests/fixtures_six_trackers.py) with the extra trackers'
true offsets typed, so their targets are the joints'.
"""
import os

import numpy as np
import pytest

from blender_manikin.core import model_choice as mc, pipeline
from blender_manikin.core import solve as cs
from blender_manikin.core.devices import REQUIRED_DEVICES
from blender_manikin.core.device_offsets import get_preset
from blender_manikin.core.model_runner import ModelRunner
from blender_manikin.core.pose_result import TrackerTargets
from blender_manikin.core.skeleton import J

from fixtures_six_trackers import body_with_legs, random_mounts, six_tracker_targets, true_offsets

FPS = 60.0


def typed(mounts):
    off = get_preset("openxr_generic")
    off["name"] = "typed"
    off["devices"].update(true_offsets(mounts))
    return off


def targets_for(devices=None, invalid=None, duration=8.0, seed=4):
    body = body_with_legs(1.74, 1.0)
    mounts = random_mounts(seed)
    tg, _ = six_tracker_targets(body, mounts, duration=duration, fps=FPS, offsets=typed(mounts), invalid=invalid,
                                seed=seed)
    if devices is not None:
        tg = TrackerTargets(fps=tg.fps, pos={d: tg.pos[d] for d in devices}, rot={d: tg.rot[d] for d in devices},
                            valid={d: tg.valid[d] for d in devices})
    return tg, body


def test_short_losses_are_bridged_long_ones_are_not():
    tg, _ = targets_for(invalid=("left_foot", 2.0, 4.5))          # 2.5 s: bridged
    assert mc.tracked_frames(tg, "left_foot").all()
    tg, _ = targets_for(invalid=("left_foot", 2.0, 6.0))          # 4 s: lost
    t = np.arange(tg.num_frames) / FPS
    lost = (t >= 2.0) & (t < 6.0)
    assert np.array_equal(mc.tracked_frames(tg, "left_foot"), ~lost)
    assert mc.tracked_frames(tg, "right_foot").all()
    assert not mc.tracked_frames(tg, "no_such_device").any()


def test_a_lost_tracker_fades_out_before_the_loss_and_back_in_after():
    tg, _ = targets_for(invalid=("pelvis", 2.0, 6.0))
    w = mc.tracker_weights(tg)["pelvis"]
    t = np.arange(tg.num_frames) / FPS
    assert np.all(w[t < 2.0 - mc.MODEL_BLEND_S - 1e-9] == 1.0)
    assert np.all(w[(t >= 2.0) & (t < 6.0)] == 0.0)            # never a bridged pose of the lost tracker
    assert np.all(w[t >= 6.0 + mc.MODEL_BLEND_S - 1e-9] == 1.0)
    ramp = w[(t > 2.0 - mc.MODEL_BLEND_S) & (t < 2.0)]
    assert np.all(np.diff(ramp) < 0) and np.all((ramp > 0) & (ramp < 1))
    assert np.abs(np.diff(w)).max() <= 1.0 / (mc.MODEL_BLEND_S * FPS) + 1e-9     # linear, no jump


@pytest.mark.parametrize("devices,name", [
    (REQUIRED_DEVICES, "head_hands"),
    (REQUIRED_DEVICES + ("pelvis",), "pelvis"),
    (REQUIRED_DEVICES + ("pelvis", "left_foot", "right_foot"), "six"),
])
def test_the_model_matching_the_recordings_trackers_is_chosen(devices, name):
    tg, _ = targets_for(devices)
    plan = mc.plan_models(tg)
    assert plan.names == [name]
    assert tuple(plan.runners[0].contract.devices) == tuple(mc.SHIPPED_MODELS[name][1])
    assert np.all(plan.weights[0] == 1.0)
    assert plan.notes[0] == f"model {mc.MODEL_LABELS[name]} ({mc.SHIPPED_MODELS[name][0]})"


def test_feet_without_a_pelvis_tracker_use_the_three_tracker_model_and_say_so():
    tg, _ = targets_for(REQUIRED_DEVICES + ("left_foot", "right_foot"))
    plan = mc.plan_models(tg)
    assert plan.names == ["head_hands"]
    assert "no installed model takes the left foot, right foot tracker(s)" in plan.notes[0]


def test_a_long_foot_loss_is_solved_with_the_pelvis_model_and_blended():
    tg, body = targets_for(invalid=("left_foot", 2.0, 6.0))
    plan = mc.plan_models(tg)
    assert plan.names == ["pelvis", "six"]
    w_pelvis, w_six = plan.weights
    t = np.arange(tg.num_frames) / FPS
    assert np.allclose(w_pelvis + w_six, 1.0)
    assert np.all(w_six[(t >= 2.0) & (t < 6.0)] == 0.0) and np.all(w_six[t < 1.4] == 1.0)
    assert any(n.startswith("left foot tracker lost over 3 s: the head, hands and pelvis model on 2.0-6.0 s")
               for n in plan.notes), plan.notes

    res = pipeline.solve(tg, body)
    assert res.notes == plan.notes
    P = res.positions
    tracked = mc.tracker_weights(tg)["left_foot"] == 1.0
    # tracked: the ankle on its tracker; lost: the network's foot, not the bridged tracker pose
    miss = np.linalg.norm(P[:, J["left_ankle"]] - tg.pos["left_foot"], axis=-1)
    assert np.median(miss[tracked]) < 1e-4
    assert np.all(res.reach_error[~tracked, 2] == 0.0)
    # no jump where the tracker hands over: around each boundary the frame-to-frame steps of the
    # pelvis and the left leg are no larger than those of the take solved with the tracker never
    # lost (the arms' swivel is the network's either way: an elbow turning fast does so in both)
    tg_all, _ = targets_for()
    P_all = pipeline.solve(tg_all, body).positions
    leg = [J[n] for n in ("pelvis", "left_hip", "left_knee", "left_ankle", "left_foot")]
    step = np.linalg.norm(np.diff(P[:, leg], axis=0), axis=-1).max(axis=1)          # (T-1,) metres
    step_all = np.linalg.norm(np.diff(P_all[:, leg], axis=0), axis=-1).max(axis=1)
    for edge in (2.0, 6.0):
        near = np.abs(t[1:] - edge) < 2 * mc.MODEL_BLEND_S
        assert step[near].max() < step_all[near].max() + 0.005, (edge, step[near].max(), step_all[near].max())


def test_a_model_named_by_the_user_solves_the_whole_take():
    tg, body = targets_for()
    plan = mc.plan_models(tg, "head_hands")
    assert len(plan.runners) == 1 and tuple(plan.runners[0].contract.devices) == REQUIRED_DEVICES
    assert plan.notes[0].startswith("model manikin_s (head, left hand, right hand, chosen)")
    assert "pelvis, left foot, right foot tracker(s) drive the solve directly" in plan.notes[0]
    runner = ModelRunner(mc.shipped_model_path("six"))
    assert mc.plan_models(tg, runner).runners == [runner]
    with pytest.raises(ValueError, match=r"model 'nonsense': not a file, nor one of auto, head_hands, pelvis, six"):
        mc.resolve_model("nonsense")
    assert mc.resolve_model("auto") is None and mc.resolve_model("") is None
    assert mc.resolve_model("manikin_s_six") == mc.shipped_model_path("six")


def test_a_chosen_model_needing_trackers_the_recording_lacks_names_them_all():
    """*Pose Model: Six Trackers* (``--model six``) on a head-and-hands take: the error names every
    tracker the model takes that the take lacks and how to choose a model that fits, not the first
    one alone ("the pose model needs a 'pelvis' tracker")."""
    tg, _ = targets_for(devices=REQUIRED_DEVICES)
    with pytest.raises(mc.ModelError, match=r"model manikin_s_six takes the pelvis, left foot, right foot "
                       r"tracker\(s\), which the recording does not have \(it has head, left hand, right hand\): "
                       r"choose the model for its trackers \(Pose Model: Automatic, --model auto\)"):
        mc.plan_models(tg, "six")


def test_a_dual_attention_poser_model_is_named_as_one():
    """A researcher comparing backbones solves with a Dual Attention Poser model (``train --arch dap``,
    exported): the summary names the backbone from the model's contract, whatever the file is called."""
    dap = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "models",
                       "manikin_dap.onnx")
    tg, _ = targets_for(devices=REQUIRED_DEVICES)
    plan = mc.plan_models(tg, dap)
    assert plan.notes[0] == "model manikin_dap (Dual Attention Poser; head, left hand, right hand, chosen)"
    assert mc.plan_models(tg, "head_hands").notes[0] == "model manikin_s (head, left hand, right hand, chosen)"


def test_the_solve_summary_says_which_model_solved(tmp_path):
    from fixtures_six_trackers import six_tracker_recording
    from blender_manikin.core.io_csv import write_csv
    body = body_with_legs(1.70, 1.0)
    mounts = random_mounts(2)
    path = os.path.join(tmp_path, "six.csv")
    write_csv(path, six_tracker_recording(body, mounts, seed=2), axes="openxr", units="m")
    out = cs.solve_recording(path, cs.SolveSettings(fps=30.0))
    assert "model head, hands, pelvis and feet (manikin_s_six.onnx)" in out.summary()
    out = cs.solve_recording(path, cs.SolveSettings(fps=30.0, model="pelvis"))
    assert "model manikin_s_pelvis (head, left hand, right hand, pelvis, chosen)" in out.summary()
    with pytest.raises(cs.SolveError, match="model 'nope.onnx': not a file"):
        cs.solve_recording(path, cs.SolveSettings(fps=30.0, model="nope.onnx"))


def test_a_model_you_trained_stands_in_for_the_shipped_one_of_its_devices(monkeypatch):
    """``$BLENDER_MANIKIN_MODEL`` replaces the shipped model that takes the same trackers (here
    the six-tracker file under another name), not the three-tracker one."""
    import shutil
    import tempfile
    d = tempfile.mkdtemp()
    mine = os.path.join(d, "my_six.onnx")
    shutil.copy(mc.shipped_model_path("six"), mine)
    monkeypatch.setenv("BLENDER_MANIKIN_MODEL", mine)
    paths = {name: path for name, path, _ in mc.installed_models()}
    assert paths["six"] == mine and paths["head_hands"] == mc.shipped_model_path("head_hands")
    tg, _ = targets_for()
    plan = mc.plan_models(tg)
    assert plan.runners[0].path == os.path.abspath(mine) and "my_six.onnx" in plan.notes[0]
    shutil.rmtree(d)
