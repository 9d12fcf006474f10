"""Start a training run from trained weights (``train --init PATH``): fine-tuning.

    cfg, state = load_initial_weights("blender_manikin/models/manikin_s.onnx")
    model = build_model(cfg); model.load_state_dict(state)

``PATH`` is either

* a training checkpoint (``checkpoint.pt`` / ``best.pt``): its ``config`` and ``model``;
* an exported model (``.onnx``, :mod:`.export`): the configuration comes from its contract
  (``kind``, ``input_devices``, ``architecture``) and the weights are read back from the graph's
  initialisers.  ``torch.onnx.export`` keeps the names of most parameters; the weights of the
  linear layers become unnamed ``MatMul`` operands, transposed, in the order the model defines
  them, so those are matched in order and by shape.  The result is then checked the way an export
  is checked (:func:`.export.verify_onnx`: onnxruntime against torch, max abs difference
  <= 1e-4); a file that does not read back exactly raises :class:`ValueError` rather than
  starting a run from the wrong weights.

Only the weights are taken: the optimizer, step count and learning-rate plan start afresh (use
``--resume`` to continue a run instead).
"""
from __future__ import annotations

import os

import numpy as np

from .model import ModelConfig

#: largest |onnxruntime - torch| accepted for weights read back from an ONNX file
MAX_DIFF = 1e-4


def config_from_contract(contract) -> ModelConfig:
    """The :class:`.model.ModelConfig` an exported model's contract describes."""
    arch = dict(contract.get("architecture") or {})
    if not arch:
        raise ValueError("the contract has no 'architecture' (exported before it was recorded)")
    arch["kind"] = contract["kind"]
    arch["devices"] = tuple(contract["input_devices"])
    return ModelConfig.from_dict(arch)


def _state_from_onnx(path, model):
    """``state_dict`` of ``model`` filled from the ONNX file's initialisers (see module doc)."""
    import onnx
    import torch
    from onnx import numpy_helper
    graph = onnx.load(path).graph
    inits = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    state = model.state_dict()
    out, unnamed = {}, []
    for name, t in state.items():
        if name in inits and tuple(inits[name].shape) == tuple(t.shape):
            out[name] = torch.from_numpy(np.array(inits[name], dtype=np.float32).reshape(t.shape))
        else:
            unnamed.append(name)
    used = set(out)
    # MatMul operands that are initialisers, in graph order (each once)
    operands, seen = [], set()
    for node in graph.node:
        if node.op_type in ("MatMul", "Gemm"):
            for i in node.input:
                if i in inits and i not in used and i not in seen:
                    seen.add(i)
                    operands.append(i)
    if len(operands) != len(unnamed):
        raise ValueError(f"{path}: {len(unnamed)} parameters without a name in the graph "
                         f"({', '.join(unnamed[:4])}...) against {len(operands)} unnamed weights")
    for name, op in zip(unnamed, operands):
        t, w = state[name], np.array(inits[op], dtype=np.float32)
        if w.ndim == 2 and tuple(w.T.shape) == tuple(t.shape):
            w = w.T
        if tuple(w.shape) != tuple(t.shape):
            raise ValueError(f"{path}: weight {op} {w.shape} does not fit parameter {name} {tuple(t.shape)}")
        out[name] = torch.from_numpy(np.ascontiguousarray(w))
    return out


def load_initial_weights(path):
    """``(ModelConfig, state_dict)`` of a checkpoint or exported model (see module doc).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for one whose weights
    cannot be read back exactly."""
    import torch
    from .backbones import build_model
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"--init {path}: no such file")
    if path.lower().endswith(".onnx"):
        from .export import read_contract, verify_onnx
        try:
            cfg = config_from_contract(read_contract(path))
        except (KeyError, ValueError) as exc:
            raise ValueError(f"--init {path}: {exc}") from None
        model = build_model(cfg)
        model.load_state_dict(_state_from_onnx(path, model))
        model.eval()
        diff = verify_onnx(path, model, cfg)
        if not diff <= MAX_DIFF:
            raise ValueError(f"--init {path}: the weights read back differ from the file's outputs by "
                             f"{diff:.2e} (> {MAX_DIFF:g}); start from its training checkpoint instead")
        return cfg, model.state_dict()
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(ckpt, dict) or "model" not in ckpt or "config" not in ckpt:
        raise ValueError(f"--init {path}: not a training checkpoint (no 'model' and 'config')")
    return ModelConfig.from_dict(ckpt["config"]), ckpt["model"]
