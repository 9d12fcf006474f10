"""The pose network backbones, selectable by name (``train --arch``, ``ModelConfig.arch``).

* ``posenet``: a Transformer encoder shared by a global (root orientation) and a local head
  (:class:`.model.PoseNet`);
* ``dap``: Dual Attention Poser, a global and a local Transformer path joined by a
  cross-attention mixer, with attention-gated MLP decoders (:class:`.model_dap.DualAttentionPoser`).

Both take ``(B, W, cfg.input_dim)`` float32 and return ``(B, W, cfg.output_dim)`` in
``features.OUTPUT_BLOCKS[cfg.kind]`` order, and export to the same ONNX contract.
"""
from __future__ import annotations

from .model import ModelConfig, PoseNet
from .model_dap import DualAttentionPoser

ARCHITECTURES = {"posenet": PoseNet, "dap": DualAttentionPoser}


def build_model(cfg: ModelConfig, arch=None):
    """The backbone named ``arch`` (default ``cfg.arch``)."""
    arch = arch or getattr(cfg, "arch", "posenet")
    try:
        return ARCHITECTURES[arch](cfg)
    except KeyError:
        raise ValueError(f"unknown architecture {arch!r} (choose from {sorted(ARCHITECTURES)})") from None
