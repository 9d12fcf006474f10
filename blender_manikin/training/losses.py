"""Losses (MANIKIN eq. 15 and the network-only baseline) and validation metrics.

All quantities live in the window's canonical frame (see ``core.features``)
and in statures; position terms are multiplied back by the stature so they
are L1 distances in **metres**.  ``batch`` is a dict of tensors from
:class:`~.dataset.WindowSampler`: ``x``, ``y``, ``pos`` (ground-truth joint
positions), ``offsets`` (rest offsets / stature), ``stature``.

MANIKIN (``kind="manikin"``)::

    L = 0.05 L_ori       L1 on the root orientation 6D              (eq. 15, λ_ori)
      + 1    L_rot       L1 on the six torso local rotations 6D
      + 1    L_FK        L1 on torso-FK positions relative to the head  (eq. 1)
      + 1    L_foot      L1 on ankle positions (m) + ankle orientations 6D
      + 0.2  L_swivel    L1 on normalised (cos φ, sin φ)              (eq. 6)
      + 0.2  L_mid       L1 on elbow/knee positions from eq. 7        (eq. 8)
      + 0.1  L_contact   BCE on the foot-contact logits
      + 0.01 L_norm      (|(cos, sin)| - 1)^2, keeps the raw pair away from 0

L_mid places the mid joints with the differentiable swivel solver
(:func:`torch_geometry.mid_from_swivel`): bases (shoulders, hips) from the
predicted torso FK anchored at the *input* head, ends from the *input* wrists
(arms) and the predicted ankles (legs), parents (collars, pelvis) from the
predicted torso FK: exactly how inference assembles the body.  The paper
gives λ_ori = 0.05, λ_swivel = λ_m = 0.2 and 1 for the rest; contacts are
our addition (λ 0.1 so the BCE, ~0.3-0.7 early, does not swamp the metre-scale
position terms).

Network-only baseline (``kind="fk"``, AvatarPoser-style)::

    L = 0.05 L_ori + 1 L_rot (all 21 local rotations, 6D) + 1 L_FK (all 22
        joints relative to the head, m) + 0.1 L_contact

Metrics (:func:`metrics`) rebuild all 22 joints the way inference does
(head at the input head; MANIKIN: torso FK, wrists at the input wrists
clamped to the arm's reach, elbows/knees from the swivel, ankles and balls
from the predicted foot poses; fk: full FK) and report MPJPE, hand, upper
and lower body errors in cm, the root orientation error in degrees and the
contact accuracy.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from ..core import features
from ..core import limb_solver as _ls
from ..core.skeleton import J, LIMBS, NUM_JOINTS
from . import torch_geometry as tg

LAMBDA = dict(ori=0.05, rot=1.0, fk=1.0, foot=1.0, swivel=0.2, mid=0.2, contact=0.1, norm=0.01)

_HEAD = J["head"]
_FK_IDX = [k for k, j in enumerate(tg.TORSO_FK_JOINTS) if j != _HEAD]
_FK_JOINTS = [j for j in tg.TORSO_FK_JOINTS if j != _HEAD]
_BASES = [b for _, b, _, _ in LIMBS]
_MIDS = [m for _, _, m, _ in LIMBS]
_ENDS = [e for _, _, _, e in LIMBS]
_LIMB_PARENTS = [int(p) for p in _ls.LIMB_PARENT]
_UPPER = [j for j in range(NUM_JOINTS) if j not in (1, 2, 4, 5, 7, 8, 10, 11)]
_LOWER = [1, 2, 4, 5, 7, 8, 10, 11]


def to_torch(batch, device="cpu"):
    return {k: torch.as_tensor(v, device=device) for k, v in batch.items()}


def _blocks(y, kind):
    return {k: y[..., s] for k, s in features.output_slices(kind).items()}


def _dev_pos(x, devices, name):
    k = list(devices).index(name)
    return x[..., k * features.PER_DEVICE: k * features.PER_DEVICE + 3]


def _rot_angle(Ra, Rb):
    tr = (Ra * Rb).sum((-1, -2))
    return torch.acos(((tr - 1) / 2).clamp(-1 + 1e-7, 1 - 1e-7))


def assemble(y_pred, batch, kind="manikin", devices=features.INPUT_DEVICES):
    """Predicted quantities in the canonical frame (statures).  Returns a dict."""
    B, W = y_pred.shape[:2]
    p = _blocks(y_pred, kind)
    off = batch["offsets"][:, None]                                    # (B, 1, 22, 3)
    head_in = _dev_pos(batch["x"], devices, "head")                    # (B, W, 3)
    out = {"root_rot": tg.sixd_to_matrix(p["root_rot"]), "head_in": head_in}
    if kind == "manikin":
        torso = tg.sixd_to_matrix(p["torso_rot"].reshape(B, W, -1, 6))
        fk, wrot = tg.torso_fk(out["root_rot"], torso, off)
        out["torso_pos"] = fk                                          # rel. to head
        ankle_rel = p["ankle_pos"].reshape(B, W, 2, 3)
        out["ankle_rel"] = ankle_rel
        ankle_rot = tg.sixd_to_matrix(p["ankle_rot"].reshape(B, W, 2, 6))
        out["ankle_rot"] = ankle_rot
        cs = p["swivel"].reshape(B, W, 4, 2)
        out["swivel_cs"] = cs
        pos_of = {j: fk[..., k, :] + head_in for k, j in enumerate(tg.TORSO_FK_JOINTS)}
        base = torch.stack([pos_of[b] for b in _BASES], -2)
        wr = torch.stack([_dev_pos(batch["x"], devices, "left_hand"), _dev_pos(batch["x"], devices, "right_hand")], -2)
        ankles = head_in[..., None, :] + ankle_rel
        end = torch.cat([wr, ankles], -2)
        par = torch.stack([wrot[j] for j in _LIMB_PARENTS], -3)
        lengths = torch.stack([off[..., _MIDS, :].norm(dim=-1), off[..., _ENDS, :].norm(dim=-1)], -1)
        out["mid_pos"] = tg.mid_from_swivel(base, end, cs, lengths, par)
        # the positions the limb solver reaches (end clamped to the limb's range)
        d = (end - base).norm(dim=-1, keepdim=True).clamp_min(1e-9)
        l1, l2 = lengths[..., :1], lengths[..., 1:]
        fm = torch.as_tensor(_ls.FLEX_MAX, dtype=d.dtype)[:, None]
        dmin = torch.sqrt((l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * torch.cos(fm)).clamp_min(0)).clamp_min(1e-6)
        dc = torch.minimum(torch.maximum(d, dmin), l1 + l2)
        reached = base + (end - base) * dc / d
        allp = [None] * NUM_JOINTS
        for j, v in pos_of.items():
            allp[j] = v
        for li in range(4):
            allp[_MIDS[li]] = out["mid_pos"][..., li, :]
            allp[_ENDS[li]] = reached[..., li, :]
        for side, (a, f) in enumerate(((J["left_ankle"], J["left_foot"]), (J["right_ankle"], J["right_foot"]))):
            allp[f] = allp[a] + (ankle_rot[..., side, :, :] * off[..., f, None, :]).sum(-1)
        out["joints"] = torch.stack(allp, -2)
    else:
        local = tg.sixd_to_matrix(p["local_rot"].reshape(B, W, -1, 6))
        out["local_rot"] = local
        P, _ = tg.full_fk(out["root_rot"], local, off)
        rel = P - P[..., _HEAD:_HEAD + 1, :]
        out["rel"] = rel
        out["joints"] = rel + head_in[..., None, :]
    out["contact_logit"] = p["contact"]
    return out


def compute_loss(y_pred, batch, kind="manikin", devices=features.INPUT_DEVICES, lam=None):
    """``(total, terms dict of floats, assembled dict)``."""
    lam = dict(LAMBDA, **(lam or {}))
    B, W = y_pred.shape[:2]
    a = assemble(y_pred, batch, kind, devices)
    p = _blocks(y_pred, kind)
    t = _blocks(batch["y"], kind)
    s = batch["stature"].reshape(B, 1, 1, 1)
    pos = batch["pos"]
    rel_t = pos - pos[..., _HEAD:_HEAD + 1, :]
    terms = {"ori": (p["root_rot"] - t["root_rot"]).abs().mean()}
    if kind == "manikin":
        terms["rot"] = (p["torso_rot"] - t["torso_rot"]).abs().mean()
        terms["fk"] = ((a["torso_pos"][..., _FK_IDX, :] - rel_t[..., _FK_JOINTS, :]).abs() * s).mean()
        ank_t = t["ankle_pos"].reshape(B, W, 2, 3)
        terms["foot"] = ((a["ankle_rel"] - ank_t).abs() * s).mean() + (p["ankle_rot"] - t["ankle_rot"]).abs().mean()
        cs = a["swivel_cs"]
        n = cs.norm(dim=-1, keepdim=True)
        terms["swivel"] = (cs / n.clamp_min(1e-6) - t["swivel"].reshape(B, W, 4, 2)).abs().mean()
        terms["norm"] = ((n - 1.0) ** 2).mean()
        terms["mid"] = ((a["mid_pos"] - pos[..., _MIDS, :]).abs() * s).mean()
    else:
        terms["rot"] = (p["local_rot"] - t["local_rot"]).abs().mean()
        terms["fk"] = ((a["rel"] - rel_t).abs() * s).mean()
    terms["contact"] = F.binary_cross_entropy_with_logits(p["contact"], t["contact"])
    total = sum(lam[k] * v for k, v in terms.items())
    return total, {k: float(v.detach()) for k, v in terms.items()}, a


@torch.no_grad()
def metrics(y_pred, batch, kind="manikin", devices=features.INPUT_DEVICES, assembled=None):
    """Validation numbers (sums over windows*frames, to be divided by ``count``)."""
    a = assembled if assembled is not None else assemble(y_pred, batch, kind, devices)
    B, W = y_pred.shape[:2]
    s = batch["stature"].reshape(B, 1, 1)
    err = (a["joints"] - batch["pos"]).norm(dim=-1) * s * 100.0          # (B, W, 22) cm
    t = _blocks(batch["y"], kind)
    ang = torch.rad2deg(_rot_angle(a["root_rot"], tg.sixd_to_matrix(t["root_rot"])))
    acc = ((a["contact_logit"] > 0).float() == t["contact"]).float().mean(-1)
    n = B * W
    return dict(count=n, mpjpe_cm=float(err.mean(-1).sum()), hand_cm=float(err[..., [20, 21]].mean(-1).sum()),
                upper_cm=float(err[..., _UPPER].mean(-1).sum()), lower_cm=float(err[..., _LOWER].mean(-1).sum()),
                root_deg=float(ang.sum()), contact_acc=float(acc.sum()))


def reduce_metrics(parts):
    tot = {}
    for m in parts:
        for k, v in m.items():
            tot[k] = tot.get(k, 0.0) + v
    n = max(tot.pop("count", 1), 1)
    return {k: v / n for k, v in tot.items()}
