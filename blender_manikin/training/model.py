"""The pose network: a small Transformer encoder with a global and a local head.

Seq-to-seq (MANIKIN-LN style): every frame of the W-frame window gets an
output, and every frame is supervised.  The window is centred (the
canonical frame is the centre frame's), so by default attention is
non-causal; ``causal=True`` masks the future for a live variant.

    x (B, W, F_in) -> Linear -> + learned positional embedding (W, d)
      -> N pre-LN Transformer blocks (multi-head self-attention, GELU MLP)
      -> LayerNorm -> global head (MLP -> root orientation 6D)
                   -> local head  (MLP -> every other output block)
    y (B, W, F_out) in features.OUTPUT_BLOCKS[kind] order (root_rot first)

The two heads follow Dual Attention Poser's separation of the global root
orientation from the local body pose (its dual-path encoder and
cross-attention mixer are not used: the encoder is shared).  Attention is
written out with plain tensor ops (``scaled_dot_product_attention``) so the
ONNX export (opset 17) is a straightforward graph.
"""
from __future__ import annotations

from dataclasses import dataclass, asdict

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from ..core import features

_IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


@dataclass
class ModelConfig:
    kind: str = "manikin"
    devices: tuple = features.INPUT_DEVICES
    window: int = 40
    d_model: int = 160
    layers: int = 3
    heads: int = 4
    ff_mult: int = 4
    head_hidden: int = 256
    dropout: float = 0.05
    causal: bool = False
    body: bool = True          # inputs end with features.BODY_FEATURES (the performer's proportions)
    arch: str = "posenet"      # backbone (training/backbones.py): posenet | dap

    @property
    def input_dim(self):
        return features.input_dim(self.devices, body=self.body)

    @property
    def output_dim(self):
        return features.output_dim(self.kind)

    def to_dict(self):
        d = asdict(self)
        d["devices"] = list(self.devices)
        return d

    @classmethod
    def from_dict(cls, d):
        d = dict(d)
        d["devices"] = tuple(d.get("devices", features.INPUT_DEVICES))
        d.setdefault("body", False)     # checkpoints from before body conditioning
        return cls(**{k: v for k, v in d.items() if k in cls.__dataclass_fields__})


class Block(nn.Module):
    def __init__(self, d, heads, ff, dropout):
        super().__init__()
        self.heads = heads
        self.ln1 = nn.LayerNorm(d)
        self.qkv = nn.Linear(d, 3 * d)
        self.proj = nn.Linear(d, d)
        self.ln2 = nn.LayerNorm(d)
        self.ff1 = nn.Linear(d, ff)
        self.ff2 = nn.Linear(ff, d)
        self.drop = nn.Dropout(dropout)
        self.p = dropout

    def forward(self, h, mask=None):
        B, W, d = h.shape
        q, k, v = self.qkv(self.ln1(h)).view(B, W, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v, attn_mask=mask,
                                           dropout_p=self.p if self.training else 0.0)
        h = h + self.drop(self.proj(a.transpose(1, 2).reshape(B, W, d)))
        h = h + self.drop(self.ff2(F.gelu(self.ff1(self.ln2(h)))))
        return h


def _mlp(d, hidden, out):
    return nn.Sequential(nn.Linear(d, hidden), nn.GELU(), nn.Linear(hidden, out))


class PoseNet(nn.Module):
    def __init__(self, cfg: ModelConfig):
        super().__init__()
        if cfg.d_model % cfg.heads:
            raise ValueError(f"d_model {cfg.d_model} is not divisible by heads {cfg.heads}")
        self.cfg = cfg
        d = cfg.d_model
        self.inp = nn.Linear(cfg.input_dim, d)
        self.pos = nn.Parameter(torch.randn(1, cfg.window, d) * 0.02)
        self.blocks = nn.ModuleList(Block(d, cfg.heads, cfg.ff_mult * d, cfg.dropout) for _ in range(cfg.layers))
        self.ln = nn.LayerNorm(d)
        sizes = dict(features.OUTPUT_BLOCKS[cfg.kind])
        self.global_head = _mlp(d, cfg.head_hidden, sizes["root_rot"])
        self.local_head = _mlp(d, cfg.head_hidden, cfg.output_dim - sizes["root_rot"])
        if cfg.causal:
            self.register_buffer("mask", torch.ones(cfg.window, cfg.window, dtype=torch.bool).tril(),
                                 persistent=False)
        else:
            self.mask = None
        self._init_output_bias()

    def _init_output_bias(self):
        init_rest_pose(self.global_head[-1], self.local_head[-1], self.cfg.kind)

    def forward(self, x):
        h = self.inp(x) + self.pos[:, : x.shape[1]]
        for blk in self.blocks:
            h = blk(h, self.mask)
        h = self.ln(h)
        return torch.cat([self.global_head(h), self.local_head(h)], -1)


def init_rest_pose(global_last, local_last, kind, weight_scale=0.1):
    """Start a network at the rest pose: the last global layer outputs identity 6D, the last
    local layer's biases are identity 6D for rotation blocks, the ankles 0.87 statures below the
    head (skeleton proportions), swivel (cos, sin) = (1, 0) and contact logits 1; both layers'
    weights are multiplied by ``weight_scale``."""
    with torch.no_grad():
        global_last.weight.mul_(weight_scale)
        global_last.bias.copy_(torch.tensor(_IDENTITY_6D))
        local_last.weight.mul_(weight_scale)
        bias = np.zeros(local_last.bias.shape[0], np.float32)
        k = 0
        for name, size in features.OUTPUT_BLOCKS[kind][1:]:
            if name.endswith("_rot"):
                bias[k:k + size] = np.tile(_IDENTITY_6D, size // 6)
            elif name == "ankle_pos":
                bias[k:k + size] = [0.05, 0.0, -0.87, -0.05, 0.0, -0.87]
            elif name == "swivel":
                bias[k:k + size] = np.tile([1.0, 0.0], size // 2)
            elif name == "contact":
                bias[k:k + size] = 1.0
            k += size
        local_last.bias.copy_(torch.from_numpy(bias))


def count_parameters(model):
    return int(sum(p.numel() for p in model.parameters()))
