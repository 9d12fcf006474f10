"""Dual Attention Poser (DAP): a second backbone for the pose network.

Di, Dai, Zhang & Chen, "Dual Attention Poser: Dual Path Body Tracking Based
on Attention" (CVPRW 2023; /work/shared/papers/dual-attention-poser.md).
Same contract as :class:`~.model.PoseNet`: ``forward(x (B, W, F_in)) ->
y (B, W, F_out)`` with the blocks of ``features.OUTPUT_BLOCKS[cfg.kind]``
(root_rot first), built from a :class:`~.model.ModelConfig`, starting at the
rest pose, exported to ONNX opset 17 by the same exporter.

Shapes (default config: W = 40, d = d_model = 160, p = d / 2 = 80,
L = layers = 3, h = heads = 4, ff = ff_mult * p, g = head_hidden = 256)::

  x (B, W, F_in)        every frame: 12 per input device (position, 6D, velocity)
                        then any extra per-window features (e.g. body proportions);
                        the whole frame vector goes to both paths (paper eq. 4)
  ├─ global path (§3.2, eq. 5): Linear(F_in, p) + learned pos. emb. (W, p)
  │     -> L pre-LN Transformer blocks, temporal self-attention  -> Z2 (B, W, p)
  └─ local path  (§3.2, eq. 6): own Linear(F_in, p) + own pos. emb.
        -> L pre-LN Transformer blocks (own weights)              -> Z1 (B, W, p)
  cross-attention mixer (§3.3, eqs. 7-11), one layer, h heads:
        FH1 = fp1(Z1 + softmax(Q2(Z2) K1(Z1)^T / sqrt(p/h)) V1(Z1))   (B, W, p)
        FH2 = fp2(Z2 + softmax(Q1(Z1) K2(Z2)^T / sqrt(p/h)) V2(Z2))   (B, W, p)
        fp: pointwise residual MLP u + MLP(LN(u)), hidden ff
  concatenation (§3.5, eq. 18): C = FH1 ⊕ FH2, input of both decoders  (B, W, d)
  attention-gated-MLP decoders (§3.4, eqs. 12-17, Fig. 3), one per path,
        2 blocks each, with the skip connection between them:
        H_a = GELU(LN(H_in) U)                  U: d -> g         (B, W, g)
        (H_a1, H_a2) = split(H_a)                                  2 x (B, W, g/2)
                      (U is stored as its two halves U1, U2: no split copy in ONNX)
        H_b = H_a1 ⊙ (M LN(H_a2) + b)           M (W, W) across frames (near 0 at
                                                init), b (W, 1) token biases (= 1)
        H_in' = H_in + H_b V                    V: g/2 -> d
        -> LN -> Linear:  local decoder -> every output block but root_rot
                          global decoder -> root_rot 6D
  y = [global 6D, local blocks] (B, W, F_out)

With ``cfg.causal`` every operation across frames looks only at the past:
the encoders' self-attention, the mixer's cross-attention (lower-triangular
boolean masks) and the decoders' gating matrix M (masked to its lower
triangle), so a frame's output never depends on later frames.

Size at the default config: 0.90 M parameters (PoseNet 1.04 M), ~0.95 M
multiply-adds per frame (PoseNet ~1.07 M); in onnxruntime (batch 256 x 40
frames, one thread) its CPU time is within ~10 % of PoseNet's: more, smaller
operations (two paths, eight attention layers) offset the fewer FLOPs.

Mapping to the paper and what is simplified
-------------------------------------------
* Dual paths.  The paper's two paths are a *global* path (root
  orientation) and a *local* path (the rest of the body), each its own
  Transformer encoder over the frames of the window, both fed the same
  sparse input X (eqs. 4-6, Fig. 2).  That is what is built here; the paths
  are not a temporal-vs-spatial (per-device token) split, which the paper
  does not describe.  Extra per-window features appended to each frame
  (body proportions) simply enter both paths' input projections.
* Width.  Each path is ``d_model / 2`` wide so the concatenation (eq. 18)
  is ``d_model`` wide and the model keeps PoseNet's size and speed (the
  paper gives no sizes; two full-width paths would double the cost and
  exceed the 1.5 M parameter / inference-speed budget).  ``layers`` is the
  depth of *each* encoder.
* Scale.  Eqs. 5, 6, 8, 9 divide by a "scale factor d"; the usual
  1/sqrt(head dim) of multi-head attention is used.
* Mixer.  Eqs. 8-11 are implemented as printed: path 1's update attends with
  the *other* path's queries over its *own* keys and values (the correlation
  between the paths re-weights each path's features); the content of the
  two paths is then joined by the concatenation (§3.5).  The functions f
  are linear projections of LayerNorm-ed inputs, fp a residual pointwise MLP
  (the paper says only "pointwise MLP layer").  Attention masks, LayerNorms
  and dropout follow standard pre-LN Transformer practice.
* Decoder.  The gate f_{w,b} of eqs. 14-16 is gMLP's spatial gating unit
  (its ref. [18], "token-specific biases"): a learned (W, W) matrix across
  frames, initialised near zero with biases one (so the gate is ~1 at the
  start, as the paper requires), applied to one half of the channels and
  multiplying the other (eq. 16).  gMLP's LayerNorms (before U and on the
  gated half) are kept; each block is residual, which gives the paper's
  skip connection from the first block to the second.  A final LayerNorm
  and Linear map each decoder to its output blocks (the paper decodes 22
  SMPL rotations; here the MANIKIN or fk blocks).
* Input features.  The paper's per-device input also has an axis-angle
  orientation and the angular velocity R_{t-1}^-1 R_t (eqs. 2-4, 54
  numbers for 3 devices); the project's features (position, 6D, velocity)
  are used unchanged since they are the network contract.
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from ..core import features
from .model import Block, ModelConfig, init_rest_pose

__all__ = ["DualAttentionPoser"]


class _Path(nn.Module):
    """One encoder path (§3.2): input projection, learned positional
    embedding, ``layers`` pre-LN Transformer blocks over the frames."""

    def __init__(self, cfg, p):
        super().__init__()
        self.inp = nn.Linear(cfg.input_dim, p)
        self.pos = nn.Parameter(torch.randn(1, cfg.window, p) * 0.02)
        self.blocks = nn.ModuleList(Block(p, cfg.heads, cfg.ff_mult * p, cfg.dropout) for _ in range(cfg.layers))

    def forward(self, x, mask):
        h = self.inp(x) + self.pos[:, : x.shape[1]]
        for blk in self.blocks:
            h = blk(h, mask)
        return h


class _Fusion(nn.Module):
    """Fusion_i of eq. 7 (eqs. 8-11): ``fp(Z_self + softmax(Q(Z_other)
    K(Z_self)^T / sqrt(dk)) V(Z_self))`` with ``fp(u) = u + MLP(LN(u))``."""

    def __init__(self, p, heads, ff, dropout):
        super().__init__()
        self.heads, self.p = heads, dropout
        self.ln_q = nn.LayerNorm(p)
        self.ln_kv = nn.LayerNorm(p)
        self.q = nn.Linear(p, p)
        self.kv = nn.Linear(p, 2 * p)
        self.proj = nn.Linear(p, p)
        self.ln_f = nn.LayerNorm(p)
        self.ff1 = nn.Linear(p, ff)
        self.ff2 = nn.Linear(ff, p)
        self.drop = nn.Dropout(dropout)

    def forward(self, z_self, z_other, mask=None):
        B, W, p = z_self.shape
        hd = p // self.heads
        q = self.q(self.ln_q(z_other)).view(B, W, self.heads, hd).transpose(1, 2)
        k, v = self.kv(self.ln_kv(z_self)).view(B, W, 2, self.heads, hd).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v, attn_mask=mask,
                                           dropout_p=self.p if self.training else 0.0)
        u = z_self + self.drop(self.proj(a.transpose(1, 2).reshape(B, W, p)))
        return u + self.drop(self.ff2(F.gelu(self.ff1(self.ln_f(u)))))


class _GatedBlock(nn.Module):
    """One attention-gated-MLP block (eqs. 12-17, gMLP's spatial gating
    unit): ``h + V(H_a1 ⊙ (M LN(H_a2) + b))``, ``H_a = GELU(U LN(h))``,
    M a (W, W) matrix across frames (lower-triangular when causal)."""

    def __init__(self, d, hidden, window, causal, dropout):
        super().__init__()
        if hidden % 2:
            raise ValueError(f"head_hidden {hidden} must be even (split into gate and bypass halves)")
        self.ln = nn.LayerNorm(d)
        self.U1 = nn.Linear(d, hidden // 2)        # U of eq. 12, as its two halves (eq. 16's split)
        self.U2 = nn.Linear(d, hidden // 2)
        self.ln_gate = nn.LayerNorm(hidden // 2)
        self.M = nn.Parameter(torch.empty(window, window).uniform_(-1e-3, 1e-3))   # near zero (§3.4)
        self.b = nn.Parameter(torch.ones(window, 1))                                # ones (§3.4)
        self.V = nn.Linear(hidden // 2, d)
        self.drop = nn.Dropout(dropout)
        if causal:
            self.register_buffer("tri", torch.ones(window, window).tril(), persistent=False)
        else:
            self.tri = None

    def forward(self, h):
        T = h.shape[1]
        hn = self.ln(h)
        a1, a2 = F.gelu(self.U1(hn)), F.gelu(self.U2(hn))                     # eq. 12, split of eq. 16
        M = self.M[:T, :T]
        if self.tri is not None:
            M = M * self.tri[:T, :T]
        gate = torch.matmul(M, self.ln_gate(a2)) + self.b[:T]               # eq. 14: (W,W) @ (B,W,g/2)
        return h + self.drop(self.V(a1 * gate))                            # eqs. 15-17, residual


class _Decoder(nn.Module):
    """Attention-gated-MLP decoder (§3.4): 2 gated blocks (residual: the skip
    from block 1 to block 2), LayerNorm, Linear to the output blocks."""

    def __init__(self, cfg, d, out, blocks=2):
        super().__init__()
        self.blocks = nn.ModuleList(_GatedBlock(d, cfg.head_hidden, cfg.window, cfg.causal, cfg.dropout)
                                    for _ in range(blocks))
        self.ln = nn.LayerNorm(d)
        self.out = nn.Linear(d, out)

    def forward(self, h):
        for blk in self.blocks:
            h = blk(h)
        return self.out(self.ln(h))


class DualAttentionPoser(nn.Module):
    """Dual Attention Poser backbone; see the module docstring.

    ``DualAttentionPoser(cfg)``, ``forward(x (B, W, cfg.input_dim)) ->
    (B, W, cfg.output_dim)`` in ``features.OUTPUT_BLOCKS[cfg.kind]`` order.
    ``W <= cfg.window`` (the window the model was built for)."""

    arch = "dap"

    def __init__(self, cfg: ModelConfig):
        super().__init__()
        if cfg.d_model % 2 or (cfg.d_model // 2) % cfg.heads:
            raise ValueError(f"d_model {cfg.d_model} must be even and d_model/2 divisible by heads {cfg.heads}")
        self.cfg = cfg
        d, p = cfg.d_model, cfg.d_model // 2
        self.global_path = _Path(cfg, p)
        self.local_path = _Path(cfg, p)
        self.fuse_local = _Fusion(p, cfg.heads, cfg.ff_mult * p, cfg.dropout)
        self.fuse_global = _Fusion(p, cfg.heads, cfg.ff_mult * p, cfg.dropout)
        sizes = dict(features.OUTPUT_BLOCKS[cfg.kind])
        self.global_decoder = _Decoder(cfg, d, sizes["root_rot"])
        self.local_decoder = _Decoder(cfg, d, cfg.output_dim - sizes["root_rot"])
        if cfg.causal:
            self.register_buffer("mask", torch.ones(cfg.window, cfg.window, dtype=torch.bool).tril(),
                                 persistent=False)
        else:
            self.mask = None
        # the decoders' last Linear reads LayerNorm-ed (unit-scale) features, not a
        # GELU hidden layer as PoseNet's heads do: a smaller weight scale puts the first
        # outputs as close to the rest pose as PoseNet's (mean |y - bias| ~0.01)
        init_rest_pose(self.global_decoder.out, self.local_decoder.out, cfg.kind, weight_scale=0.03)

    def forward(self, x):
        T = x.shape[1]
        mask = None if self.mask is None else self.mask[:T, :T]
        z1 = self.local_path(x, mask)                   # Z_1 (local)
        z2 = self.global_path(x, mask)                  # Z_2 (global)
        fh1 = self.fuse_local(z1, z2, mask)             # eq. 10
        fh2 = self.fuse_global(z2, z1, mask)            # eq. 11
        c = torch.cat([fh1, fh2], -1)                   # eq. 18, input of both decoders
        return torch.cat([self.global_decoder(c), self.local_decoder(c)], -1)
