"""Start a training run from trained weights (``train --init PATH``): fine-tuning.

    cfg, state = load_initial_weights("blender_manikin/models/manikin_s.onnx")
    model = build_model(cfg); model.load_state_dict(state)

``PATH`` is either

* a training checkpoint (``checkpoint.pt`` / ``best.pt``): its ``config`` and ``model``;
* an exported model (``.onnx``, :mod:`.export`): the configuration comes from its contract
  (``kind``, ``input_devices``, ``architecture``) and the weights are read back from the graph's
  initialisers.  ``torch.onnx.export`` keeps the names of most parameters, but the weights of
  the linear layers become unnamed, transposed ``MatMul`` operands (in graph order, which is not
  the order a model defines them in: the Dual Attention Poser's differ).  So the architecture is
  exported once more with distinct random weights, and each parameter is found in that reference
  by value, which names the initialiser to read from the file.  The result is then checked the
  way an export is checked (:func:`.export.verify_onnx`: onnxruntime against torch, max abs difference
  <= 1e-4); a file that does not read back exactly raises :class:`ValueError` rather than
  starting a run from the wrong weights.

Only the weights are taken: the optimizer, step count and learning-rate plan start afresh (use
``--resume`` to continue a run instead).
"""
from __future__ import annotations

import os

import numpy as np

from .model import ModelConfig
from .weight_average import trained_weights

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


def _state_from_onnx(path, model, cfg):
    """``state_dict`` of ``model`` filled from the ONNX file's initialisers (see module doc).

    Each parameter's initialiser is found by value in a reference export of the same
    architecture whose parameters are all distinct random numbers (so the exporter merges
    none of them): the reference names the initialiser (or transposed ``MatMul`` operand)
    that holds the parameter, and the file's initialiser of that name is read.  Buffers (not
    trained; the architecture fixes them) keep ``model``'s own values.  ``model``'s parameters
    are overwritten on the way (the caller loads the returned state)."""
    import tempfile
    import onnx
    import torch
    from onnx import numpy_helper
    from .export import write_graph

    with torch.no_grad():
        gen = torch.Generator().manual_seed(0)
        for q in model.parameters():
            q.copy_(torch.randn(q.shape, generator=gen))
    with tempfile.TemporaryDirectory() as tmp:
        ref_path = os.path.join(tmp, "reference.onnx")
        write_graph(model, cfg, ref_path)
        ref = {i.name: numpy_helper.to_array(i) for i in onnx.load(ref_path).graph.initializer}
    inits = {i.name: numpy_helper.to_array(i) for i in onnx.load(path).graph.initializer}
    by_bytes = {}
    for name, v in ref.items():
        by_bytes.setdefault((v.shape, v.astype(np.float32).tobytes()), []).append((name, False))
        if v.ndim == 2:
            by_bytes.setdefault((v.T.shape, np.ascontiguousarray(v.T).astype(np.float32).tobytes()),
                                []).append((name, True))
    out = {name: b.clone() for name, b in model.named_buffers()}
    for name, t in model.named_parameters():
        a = t.detach().numpy().astype(np.float32)
        hits = by_bytes.get((a.shape, a.tobytes()), [])
        if len(hits) != 1 or hits[0][0] not in inits:
            raise ValueError(f"{path}: parameter {name} {tuple(a.shape)} not found in the graph "
                             f"({len(hits)} candidates in the reference export)")
        ref_name, transposed = hits[0]
        w = np.array(inits[ref_name], dtype=np.float32)
        w = w.T if transposed else w
        if tuple(w.shape) != tuple(a.shape):
            raise ValueError(f"{path}: initialiser {ref_name} {w.shape} does not fit parameter {name} "
                             f"{tuple(a.shape)}")
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
        model.load_state_dict(_state_from_onnx(path, model, cfg))
        model.eval()
        diff = verify_onnx(path, model, cfg)
        if not diff <= MAX_DIFF:
            raise ValueError(f"--init {path}: the weights read back differ from the file's outputs by "
                             f"{diff:.2e} (> {MAX_DIFF:g}); start from its training checkpoint instead")
        return cfg, model.state_dict()
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(ckpt, dict) or "model" not in ckpt or "config" not in ckpt:
        raise ValueError(f"--init {path}: not a training checkpoint (no 'model' and 'config')")
    return ModelConfig.from_dict(ckpt["config"]), trained_weights(ckpt)


def widen_window(cfg, state, window):
    """``(cfg, state)`` of the same weights for a ``window``-frame window (``train --init PATH
    --window W``): a fine-tuning run that sees more context than the model was trained with.

    Only the transformer backbone (``arch`` "posenet") depends on the window, through its learned
    positional embedding ``pos`` ``(1, W, d)``.  The old embedding is placed so that the centre
    frames line up (old frame ``W_old // 2`` becomes frame ``window // 2``; the centre frame is
    where the canonical frame is taken), and the frames it did not cover repeat its first and
    last embedding.  A narrower window keeps the centred slice.  The Dual Attention Poser's
    frame-mixing matrices are sized by the window too and are not remapped: ``ValueError``.
    """
    import dataclasses
    import torch
    window = int(window)
    if window == cfg.window:
        return cfg, state
    if window < 2:
        raise ValueError(f"--window {window}: at least 2 frames")
    if cfg.arch != "posenet":
        raise ValueError(f"--window {window}: the {cfg.arch} backbone's weights depend on its window "
                         f"({cfg.window}); only posenet weights can be widened")
    pos = state["pos"]                                              # (1, W_old, d)
    old = pos.shape[1]
    shift = window // 2 - old // 2                                  # new index = old index + shift
    src = torch.clamp(torch.arange(window) - shift, 0, old - 1)
    out = dict(state)
    out["pos"] = pos[:, src].clone()
    return dataclasses.replace(cfg, window=window), out
