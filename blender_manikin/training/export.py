"""Export a training checkpoint to ONNX with its contract.

    python -m blender_manikin.training.export --checkpoint DIR/checkpoint.pt \\
        --out blender_manikin/models/manikin_s.onnx

The graph takes ``x`` ``(batch, W, 12·D)`` float32 and returns ``y``
``(batch, W, F_out)`` float32 (opset 17, dynamic batch axis, fixed window).
The model's contract is JSON in the ONNX ``metadata_props`` under
``manikin_contract`` (read by ``core.model_runner``): contract version,
kind, input/output names and shapes, fps, window, input devices, joint
names, torso joints, output blocks, normalisation constants, training data
(source, clips, frames, split, licence), parameter count, code version,
training steps/minutes and validation metrics.  The export is checked with
onnxruntime against torch (max abs difference <= 1e-4) before it is kept.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings

import numpy as np

from ..core import features
from ..core.skeleton import JOINT_NAMES, TORSO_JOINTS
from .weight_average import trained_weights

CONTRACT_KEY = "manikin_contract"
CONTRACT_VERSION = 1
INPUT_NAME = "x"
OUTPUT_NAME = "y"
OPSET = 17
MAX_BYTES = 10 * 1024 * 1024

CANONICAL_FRAME = (
    "Each window is expressed in the frame of its centre frame c = W // 2: origin at the head "
    "joint's floor projection (hx, hy, 0), rotated about +Z so the head's heading (its local -Y "
    "axis projected on the floor) points along -Y, every length divided by the performer's "
    "stature; p_can = C^T (p - o) / s, R_can = C^T R.  Blender axes (metres, +Z up, body faces -Y).  "
    "Per input device: canonical position (3), orientation 6D (first two matrix columns, 6), "
    "velocity (3): backward difference in statures per second times vel_scale (frame 0 copies "
    "frame 1).")


def build_contract(ckpt, num_parameters):
    from ..core.version import __version__
    from .model import ModelConfig
    cfg = ModelConfig.from_dict(ckpt["config"])
    data = dict(ckpt.get("data", {}))
    val = ckpt.get("val") or {}
    if "sources" not in data and data.get("source"):      # a checkpoint from before several sources
        data["sources"] = [dict(name=data["source"], path=data.get("source_path"), format="bvh", options={},
                                licence=data.get("licence"), clips=data.get("clips"), frames=data.get("frames"),
                                hours=round(float(data.get("frames") or 0) / float(data.get("fps") or 30.0) / 3600, 3))]
    return {
        "contract_version": CONTRACT_VERSION,
        "kind": cfg.kind,
        "input_name": INPUT_NAME,
        "output_name": OUTPUT_NAME,
        "input_shape": ["batch", cfg.window, cfg.input_dim],
        "output_shape": ["batch", cfg.window, cfg.output_dim],
        "dtype": "float32",
        "opset": OPSET,
        "fps": float(data.get("fps", 30.0)),
        "window": cfg.window,
        "centre_frame": cfg.window // 2,
        "causal": bool(cfg.causal),
        "input_devices": list(cfg.devices),
        "device_joints": {d: JOINT_NAMES[features.DEVICE_JOINT[d]] for d in cfg.devices},
        "per_device": [["position", 3], ["rotation_6d", 6], ["velocity", 3]],
        "body_features": list(features.BODY_FEATURES) if cfg.body else [],
        "body_normalisation": ({"scale": features.BODY_SCALE, "reference": features.BODY_REFERENCE.tolist(),
                                "stature": "head joint above the ankles / %.3f" % features.HEAD_ABOVE_ANKLES}
                               if cfg.body else {}),
        "joint_names": list(JOINT_NAMES),
        "torso_joints": [JOINT_NAMES[j] for j in TORSO_JOINTS],
        "torso_local": list(features.TORSO_LOCAL),
        "output_blocks": [[n, s] for n, s in features.OUTPUT_BLOCKS[cfg.kind]],
        "normalisation": {"vel_scale": features.VEL_SCALE, "length_unit": "stature",
                          "canonical_frame": CANONICAL_FRAME},
        "architecture": {k: v for k, v in cfg.to_dict().items() if k not in ("kind", "devices")},
        "num_parameters": int(num_parameters),
        "training_data": {k: data.get(k) for k in ("source", "sources", "clips", "frames", "split", "contact_rule",
                                                    "augmentation", "sampling", "validation")},
        "licence": data.get("licence", "see training data"),
        "code_version": __version__,
        "training": {"steps": int(ckpt.get("step", 0)), "minutes": round(float(ckpt.get("elapsed", 0.0)) / 60, 2),
                     "batch": ckpt.get("args", {}).get("batch"), "seed": ckpt.get("args", {}).get("seed"),
                     "init": (os.path.basename(ckpt["args"]["init"]) if ckpt.get("args", {}).get("init")
                              else None),
                     "weight_average": ({"decay": ckpt["ema"]["decay"], "updates": ckpt["ema"]["updates"]}
                                        if ckpt.get("ema") else None)},
        "validation": {k: v for k, v in val.items()} if val else {},
    }


def export(checkpoint, out, verify=True, quiet=False):
    """Write the ONNX file; returns ``(contract dict, max abs difference to torch)``."""
    import torch
    import onnx
    from .backbones import build_model
    from .model import ModelConfig, count_parameters

    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=False)
    cfg = ModelConfig.from_dict(ckpt["config"])
    model = build_model(cfg)
    model.load_state_dict(trained_weights(ckpt))
    model.eval()
    contract = build_contract(ckpt, count_parameters(model))
    out = os.fspath(out)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    tmp = out + ".tmp.onnx"
    write_graph(model, cfg, tmp)
    m = onnx.load(tmp)
    del m.metadata_props[:]
    p = m.metadata_props.add()
    p.key, p.value = CONTRACT_KEY, json.dumps(contract, sort_keys=True)
    m.producer_name = "blender_manikin.training.export"
    m.doc_string = f"MANIKIN pose network ({cfg.kind}); licence: {contract['licence']}"
    onnx.checker.check_model(m)
    onnx.save(m, tmp)
    size = os.path.getsize(tmp)
    if size > MAX_BYTES:
        os.remove(tmp)
        raise RuntimeError(f"exported model is {size / 1e6:.1f} MB (limit {MAX_BYTES / 1e6:.0f} MB)")
    diff = float("nan")
    if verify:
        diff = verify_onnx(tmp, model, cfg)
        if not diff <= 1e-4:
            os.remove(tmp)
            raise RuntimeError(f"onnxruntime output differs from torch by {diff:.2e} (> 1e-4)")
    os.replace(tmp, out)
    if not quiet:
        print(f"wrote {out} ({size / 1e6:.2f} MB, {contract['num_parameters']:,} parameters, kind "
              f"{cfg.kind}, window {cfg.window}, opset {OPSET}); onnxruntime vs torch max |diff| {diff:.2e}")
    return contract, diff


def write_graph(model, cfg, path):
    """``torch.onnx.export`` of ``model`` to ``path`` as every export makes it (opset
    :data:`OPSET`, dynamic batch axis, constant folding), without the contract."""
    import torch
    x = torch.randn(2, cfg.window, cfg.input_dim)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, (x,), path, input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
                          dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}},
                          opset_version=OPSET, dynamo=False, do_constant_folding=True)


def verify_onnx(path, model, cfg, seed=0):
    """Max |onnxruntime - torch| on random and realistic-scale inputs, batches 1 and 5."""
    import torch
    import onnxruntime as ort
    sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(seed)
    worst = 0.0
    for B in (1, 5):
        x = rng.normal(size=(B, cfg.window, cfg.input_dim)).astype(np.float32)
        with torch.no_grad():
            ref = model(torch.from_numpy(x)).numpy()
        got = sess.run([OUTPUT_NAME], {INPUT_NAME: x})[0]
        worst = max(worst, float(np.abs(got - ref).max()))
    return worst


def read_contract(path):
    import onnx
    m = onnx.load(path, load_external_data=False)
    for p in m.metadata_props:
        if p.key == CONTRACT_KEY:
            return json.loads(p.value)
    raise KeyError(f"{path}: no {CONTRACT_KEY} metadata")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m blender_manikin.training.export", description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--no-verify", action="store_true")
    a = ap.parse_args(argv)
    contract, diff = export(a.checkpoint, a.out, verify=not a.no_verify)
    return 0


if __name__ == "__main__":
    sys.exit(main())
