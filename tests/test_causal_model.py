"""A causal model (``train --causal``, the live variant) is solved as it is trained: each frame
from a window that ends at it, so what comes after a frame never changes it.

A tiny untrained (randomly perturbed) Transformer exported through training/export.py: the
check is about which frames the solver feeds it, not its accuracy.  Needs torch, onnx and
onnxruntime; skipped without them.  A few seconds on 2 cores.
"""
import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from blender_manikin.core import device_offsets, features, model_choice, pipeline  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.io_csv import read_csv  # noqa: E402
from blender_manikin.core.model_runner import ModelRunner  # noqa: E402
from blender_manikin.core.pose_result import TrackerTargets  # noqa: E402
from blender_manikin.core.resample import resample  # noqa: E402
from blender_manikin.training import export  # noqa: E402
from blender_manikin.training.model import ModelConfig, PoseNet  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def _tiny_model(tmp_path, causal):
    cfg = ModelConfig(window=16, d_model=32, heads=2, layers=1, head_hidden=32, dropout=0.0, causal=causal)
    torch.manual_seed(3)
    m = PoseNet(cfg)
    with torch.no_grad():               # off the rest-pose start, so every input frame counts
        for p in m.parameters():
            p.add_(torch.randn_like(p) * 0.05)
    ckpt = tmp_path / f"causal_{causal}.pt"
    torch.save({"config": cfg.to_dict(), "model": m.state_dict(), "step": 0}, ckpt)
    out = tmp_path / f"causal_{causal}.onnx"
    export.export(str(ckpt), str(out), quiet=True)
    return ModelRunner(str(out), threads=1)


@pytest.fixture(scope="module")
def targets():
    rec = read_csv(EXAMPLE)
    times, pos, quat, valid, _ = resample(rec, 30.0)      # the model's rate: no resampling in between
    return device_offsets.to_targets(times, pos, quat, valid, device_offsets.get_preset("openxr_generic"), fps=30.0)


def _fields(out):
    return {k: getattr(out, k) for k in ("root_rot", "contact", "torso_rot", "ankle_pos", "ankle_rot", "swivel")}


def test_a_causal_model_solves_a_frame_alike_whatever_comes_after_it(tmp_path, targets):
    runner = _tiny_model(tmp_path, causal=True)
    assert runner.contract.causal
    assert "causal: each frame from a window ending at it" in model_choice._whole_take_note(runner, targets)
    body = sk.make_body(1.75)
    cut = 100
    changed = TrackerTargets(fps=targets.fps, pos={d: v.copy() for d, v in targets.pos.items()},
                             rot={d: v.copy() for d, v in targets.rot.items()})
    for d in changed.pos:               # the tail moved 30 cm and turned 90 degrees
        changed.pos[d][cut:] += [0.3, -0.2, 0.0]
        changed.rot[d][cut:] = features.rot_z(np.pi / 2) @ changed.rot[d][cut:]
    whole = _fields(pipeline.run_network(targets, body, runner))
    for other in (targets.frames(slice(0, cut)), changed):
        got = _fields(pipeline.run_network(other, body, runner))
        for k, v in whole.items():
            np.testing.assert_allclose(got[k][:cut], v[:cut], atol=1e-6, err_msg=k)
    # the same weights run centred (not causal) do see the tail: the check above means something
    centred = _tiny_model(tmp_path, causal=False)
    a = _fields(pipeline.run_network(targets, body, centred))
    b = _fields(pipeline.run_network(changed, body, centred))
    assert np.abs(a["root_rot"][:cut] - b["root_rot"][:cut]).max() > 1e-3


def test_a_causal_model_trained_mirrored_does_not_flicker_on_a_held_pose(tmp_path, targets):
    """A model trained on mirrored windows runs mirror "alternate" by default; with one window
    per frame that left every other frame to the mirror image alone, so a held pose flickered
    between two poses at the model's rate.  Each frame is averaged with its mirror instead."""
    runner = _tiny_model(tmp_path, causal=True)
    runner.contract.raw["training_data"] = {"augmentation": {"mirror": 0.5}}    # as train.py records it
    assert runner.contract.trained_mirrored
    n = 40
    held = TrackerTargets(fps=targets.fps, pos={d: np.repeat(v[:1], n, 0) for d, v in targets.pos.items()},
                          rot={d: np.repeat(v[:1], n, 0) for d, v in targets.rot.items()})
    body = sk.make_body(1.75)
    out = _fields(pipeline.run_network(held, body, runner))
    both = _fields(pipeline.run_network(held, body, runner, mirror="both"))
    for k, v in out.items():
        np.testing.assert_allclose(v, np.repeat(v[:1], n, 0), atol=1e-6, err_msg=f"{k} changes on a held pose")
        np.testing.assert_allclose(v, both[k], atol=1e-6, err_msg=k)
