"""Dual Attention Poser backbone (training/model_dap.py): shapes, rest-pose
start, causality, a short overfit with the project's losses, ONNX export.

Needs torch, onnx and onnxruntime; skipped without them.  Synthetic clips
(``dataset.synthetic_motion``) and tiny networks only: a few seconds on 2 cores.
"""
import dataclasses
import inspect
import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from blender_manikin.core import features, rotations as rot  # noqa: E402
from blender_manikin.training import dataset as ds, losses  # noqa: E402
from blender_manikin.training.model import ModelConfig, PoseNet, count_parameters  # noqa: E402
from blender_manikin.training.backbones import build_model  # noqa: E402
from blender_manikin.training.model_dap import DualAttentionPoser  # noqa: E402

TINY = dict(d_model=32, heads=2, layers=1, head_hidden=32, dropout=0.0)
SIX = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")


def _cfg(**kw):
    return ModelConfig(**{**TINY, "window": 16, **kw})


def _uses_body(cfg):
    return bool(getattr(cfg, "body", False))


def _sampler(files, cfg, seed=0, augment=None):
    kw = {}
    if "body" in inspect.signature(ds.WindowSampler).parameters:
        kw["body"] = _uses_body(cfg)
    return ds.WindowSampler(files, window=cfg.window, kind=cfg.kind, devices=cfg.devices, seed=seed,
                            augment=augment, **kw)


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    """Four synthetic clips (FK-posed sinusoids) through the cache record format."""
    rng = np.random.default_rng(0)
    d = tmp_path_factory.mktemp("dap_clips")
    files = []
    for i in range(4):
        rec = ds.motion_to_record(ds.synthetic_motion(rng, T=90, stature=1.6 + 0.1 * i, take_id=f"s{i}"),
                                  f"s{i}", "synthetic")
        files.append(str(d / f"s{i}.npz"))
        np.savez(files[-1], **rec)
    return ds.ClipSet.load(files)


# --------------------------------------------------------------------------
def test_shapes_and_size():
    for kind in ("manikin", "fk"):
        for devices in (features.INPUT_DEVICES, SIX):
            for causal in (False, True):
                cfg = _cfg(kind=kind, devices=devices, causal=causal)
                m = DualAttentionPoser(cfg).eval()
                x = torch.randn(3, cfg.window, cfg.input_dim)
                with torch.no_grad():
                    assert m(x).shape == (3, cfg.window, features.output_dim(kind))
                    assert m(x[:, :10]).shape == (3, 10, features.output_dim(kind))    # shorter than the window
    # extra per-window features after the device groups are taken whatever their number
    cfg = _cfg()
    if "body" in ModelConfig.__dataclass_fields__:
        for body in (False, True):
            c = dataclasses.replace(cfg, body=body)
            assert c.input_dim == features.PER_DEVICE * len(c.devices) + (len(features.BODY_FEATURES) if body else 0)
            assert DualAttentionPoser(c)(torch.randn(2, 16, c.input_dim)).shape == (2, 16, c.output_dim)
    # default size: within budget, comparable to PoseNet
    n = count_parameters(DualAttentionPoser(ModelConfig()))
    assert 500_000 < n < 1_500_000, n
    assert isinstance(build_model(cfg, "dap"), DualAttentionPoser) and isinstance(build_model(cfg), PoseNet)
    with pytest.raises(ValueError):
        DualAttentionPoser(_cfg(d_model=36, heads=4))          # path width 18 not divisible by 4 heads
    with pytest.raises(ValueError):
        build_model(cfg, "nope")


def test_starts_at_rest_pose(clips):
    cfg = _cfg()
    torch.manual_seed(0)
    m = DualAttentionPoser(cfg).eval()
    ref = PoseNet(cfg)
    # the same output biases as PoseNet (identity 6D, ankles below the head, swivel (1, 0), contacts)
    assert torch.equal(m.global_decoder.out.bias, ref.global_head[-1].bias)
    assert torch.equal(m.local_decoder.out.bias, ref.local_head[-1].bias)
    bias = torch.cat([m.global_decoder.out.bias, m.local_decoder.out.bias]).detach().numpy()
    x = _sampler(clips, cfg).sample(8)["x"]
    with torch.no_grad():
        y = m(torch.from_numpy(x)).numpy()
    assert np.abs(y - bias).mean() < 0.03 and np.abs(y - bias).max() < 0.15
    sl = features.output_slices(cfg.kind)
    for name in ("root_rot", "torso_rot", "ankle_rot"):
        R = rot.sixd_to_matrix(y[..., sl[name]].reshape(8, cfg.window, -1, 6).astype(np.float64))
        cos = (np.trace(R, axis1=-2, axis2=-1) - 1) / 2
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 10.0, name


@pytest.mark.parametrize("causal", [True, False])
def test_causal_masking_blocks_the_future(causal):
    cfg = _cfg(window=12, causal=causal, layers=2)
    torch.manual_seed(1)
    m = DualAttentionPoser(cfg).eval()
    with torch.no_grad():               # make the frame-mixing gate matrices large so any leak shows
        for dec in (m.global_decoder, m.local_decoder):
            for blk in dec.blocks:
                blk.M.normal_()
    x = torch.randn(2, 12, cfg.input_dim)
    x2 = x.clone()
    x2[:, 8:] += 1.0
    with torch.no_grad():
        y, y2 = m(x), m(x2)
    assert not torch.allclose(y[:, 8:], y2[:, 8:])
    if causal:
        assert torch.allclose(y[:, :8], y2[:, :8], atol=1e-6)
    else:                               # the test would see a leak
        assert not torch.allclose(y[:, :8], y2[:, :8], atol=1e-4)


def test_overfits_a_fixed_batch(clips):
    cfg = _cfg()
    torch.manual_seed(0)
    m = DualAttentionPoser(cfg)
    batch = losses.to_torch(_sampler(clips, cfg).sample(8))
    opt = torch.optim.Adam(m.parameters(), 3e-3)
    first = None
    for _ in range(25):
        total, terms, _ = losses.compute_loss(m(batch["x"]), batch, cfg.kind)
        opt.zero_grad()
        total.backward()
        opt.step()
        first = total.item() if first is None else first
    assert np.isfinite(total.item()) and total.item() < 0.6 * first, (first, total.item())


@pytest.mark.parametrize("kind,devices,causal", [("manikin", features.INPUT_DEVICES, False),
                                                 ("fk", SIX, True)])
def test_onnx_export_matches_torch(clips, tmp_path, kind, devices, causal):
    """Through training/export.py itself (cfg.arch selects DAP), then onnxruntime directly."""
    from blender_manikin.training import export
    from blender_manikin.core.model_runner import ModelRunner
    cfg = _cfg(kind=kind, devices=devices, causal=causal, dropout=0.05, arch="dap")
    torch.manual_seed(2)
    m = DualAttentionPoser(cfg)
    with torch.no_grad():               # move off the init (gates, biases) so the check means something
        for p in m.parameters():
            p.add_(torch.randn_like(p) * 0.02)
    ckpt = tmp_path / "checkpoint.pt"
    torch.save({"config": cfg.to_dict(), "model": m.state_dict(), "step": 0}, ckpt)
    out = tmp_path / "dap.onnx"
    contract, diff = export.export(str(ckpt), str(out), quiet=True)       # verify_onnx: batches 1 and 5
    assert diff <= 1e-4
    assert contract["input_shape"] == ["batch", cfg.window, cfg.input_dim] and contract["kind"] == kind
    assert contract["num_parameters"] == count_parameters(m) and contract["causal"] is causal
    assert os.path.getsize(out) < export.MAX_BYTES
    m.eval()
    sess = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    for B in (3, 17):                   # dynamic batch, realistic inputs
        x = _sampler(clips, cfg, seed=B).sample(B)["x"]
        with torch.no_grad():
            ref = m(torch.from_numpy(x)).numpy()
        got = sess.run([export.OUTPUT_NAME], {export.INPUT_NAME: x})[0]
        assert got.shape == ref.shape and np.abs(got - ref).max() < 1e-4
    runner = ModelRunner(str(out), threads=1)
    assert runner.contract.kind == kind and runner.num_parameters == count_parameters(m)
