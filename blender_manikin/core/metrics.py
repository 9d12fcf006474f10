"""Evaluation metrics for predicted vs ground-truth motion, and the table printer
every benchmark uses.  Pure numpy, vectorised; never imports bpy.

Inputs are sequences in the body-model conventions of :mod:`.skeleton`:
positions ``(T, 22, 3)`` metres (Blender axes, +Z up, floor ``z = 0``) and
local rotations ``(T, 22, 3, 3)`` (parent frame; joint 0's is the global
pelvis orientation).  ``fps`` is the frame rate of both sequences.

Definitions follow the AvatarPoser / AvatarJLM / MANIKIN evaluation code
(MANIKIN ECCV 2024, Sec. 4.1), which all report means over every frame of a
sequence.  ``e[t, j] = |p_pred[t, j] - p_gt[t, j]|`` is the per-joint
Euclidean position error.

===========  ===========  ========================================================  =================
key          unit         definition                                                joints
===========  ===========  ========================================================  =================
MPJRE        deg          mean over t, j of the geodesic angle of                   all 22 (incl. the
                          ``R_pred_local[t,j]^T R_gt_local[t,j]``                   pelvis/global one)
MPJPE        cm           mean over t, j of ``e[t, j]``                             all 22
MPJVE        cm/s         mean over t, j of ``|Δp_pred - Δp_gt| * fps``,            all 22
                          ``Δp[t] = p[t+1] - p[t]`` (T-1 velocities)
H-PE         cm           mean of ``e`` over t and the hand joints                  left_wrist, right_wrist
U-PE         cm           mean of ``e`` over t and the upper-body joints            pelvis, spine1-3, neck,
                                                                                    collars, head,
                                                                                    shoulders, elbows,
                                                                                    wrists (14)
L-PE         cm           mean of ``e`` over t and the lower-body joints            hips, knees, ankles,
                                                                                    feet (8)
Jitter       10^2 m/s^3   mean over t, j of ``|Δ³p_pred| * fps³`` / 100,            all 22
                          ``Δ³p[t] = p[t+3] - 3p[t+2] + 3p[t+1] - p[t]``
                          (jerk of the *prediction*; T-3 samples)
Jitter-GT    10^2 m/s^3   the same for the ground truth (reference level)           all 22
GP           cm           ground penetration: mean over t of                        all 22
                          ``max(0, floor - min_j z[t, j])``, floor = 0
Bone-max     cm           max over t, b of ``|L_pred[t, b] - L_ref[b]|``            the 21 bones
Bone-mean    cm           mean over t, b of ``|L_pred[t, b] - L_ref[b]|``           (joint → parent)
===========  ===========  ========================================================  =================

Notes on conventions:

* The pelvis is counted in the upper body (AvatarJLM ``test.py`` and MANIKIN
  ``main_test.py``: upper ``[0, 3, 6, 9, 12..21]``, lower ``[1, 2, 4, 5, 7,
  8, 10, 11]``); AGRoL instead puts the pelvis in the lower set.  U-PE and
  L-PE therefore partition the 22 joints and ``(14 U + 8 L) / 22 = MPJPE``.
* MPJRE here is the geodesic angle, averaged over all 22 *local* rotations
  (AvatarPoser's count).  AvatarJLM's code instead averages the absolute
  difference of axis-angle *components* over the 21 non-root joints, which is
  not a rotation distance; the numbers are not directly comparable.
* The angle is computed as ``atan2(|vee(R - Rᵀ)| / 2, (tr R - 1) / 2)`` on
  the relative rotation, which is accurate at 0 (identical inputs give
  exactly 0) and near π, unlike ``arccos`` whose floor is ~1e-6 deg.
* ``L_ref`` is ``body.bone_lengths()`` when a :class:`~.skeleton.Body` is
  given, else the per-bone mean over frames of the ground-truth lengths.
* Metrics that need more frames than given (MPJVE: 2, Jitter: 4) are NaN.
* NaNs in the inputs propagate; shapes are validated (``ValueError``).
"""
from __future__ import annotations

import math
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from .plain import shown
from .skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, J

HAND_JOINTS = (J["left_wrist"], J["right_wrist"])
UPPER_JOINTS = (J["pelvis"], J["spine1"], J["spine2"], J["spine3"], J["neck"],
                J["left_collar"], J["right_collar"], J["head"],
                J["left_shoulder"], J["right_shoulder"], J["left_elbow"], J["right_elbow"],
                J["left_wrist"], J["right_wrist"])
LOWER_JOINTS = (J["left_hip"], J["right_hip"], J["left_knee"], J["right_knee"],
                J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"])
#: joints whose local rotation enters MPJRE (all 22, pelvis/global included)
ROTATION_JOINTS = tuple(range(NUM_JOINTS))
#: bones as (child, parent) joint pairs, child = 1..21
BONES = tuple((j, int(PARENTS[j])) for j in range(1, NUM_JOINTS))

#: metric key -> unit, in the order :func:`evaluate` returns them
UNITS = {
    "MPJRE": "deg", "MPJPE": "cm", "MPJVE": "cm/s", "H-PE": "cm", "U-PE": "cm", "L-PE": "cm",
    "Jitter": "1e2 m/s^3", "Jitter-GT": "1e2 m/s^3", "GP": "cm", "Bone-max": "cm", "Bone-mean": "cm",
}
#: the column order of the MANIKIN tables (plus MPJRE in front)
PAPER_COLUMNS = ("MPJRE", "MPJPE", "H-PE", "GP", "U-PE", "L-PE", "MPJVE", "Jitter")

_M_TO_CM = 100.0


# --------------------------------------------------------------------------
# validation
def _check_shape(x, name, tail, joints):
    x = np.asarray(x, dtype=np.float64)
    jn = "J" if joints is None else str(joints)
    want = "(T, " + jn + ", " + ", ".join(map(str, tail)) + ")"
    if (x.ndim != 2 + len(tail) or x.shape[2:] != tail or x.shape[0] < 1
            or (joints is not None and x.shape[1] != joints)):
        raise ValueError(f"{name} must have shape {want} with T >= 1 frames, got {x.shape}")
    return x


def _positions(x, name, joints=None):
    return _check_shape(x, name, (3,), joints)


def _rotations(x, name, joints=None):
    return _check_shape(x, name, (3, 3), joints)


def _same(a, b, na, nb):
    if a.shape != b.shape:
        raise ValueError(f"{na} {a.shape} and {nb} {b.shape} must have the same shape")


def _fps(fps):
    try:
        f = float(fps)
    except (TypeError, ValueError):
        raise ValueError(f"fps must be a positive number, got {shown(fps)}") from None
    if not math.isfinite(f) or f <= 0:
        raise ValueError(f"fps must be a positive number, got {shown(fps)}")
    return f


def _joint_set(joints, n):
    if joints is None:
        return slice(None)
    idx = np.asarray(joints, dtype=int).reshape(-1)
    if idx.size == 0 or idx.min() < -n or idx.max() >= n:
        raise ValueError(f"joint indices {list(idx)} out of range for {n} joints")
    return idx


# --------------------------------------------------------------------------
# building blocks
def joint_errors(pred_pos, gt_pos):
    """Per-joint Euclidean position errors ``(T, J)`` in metres."""
    p = _positions(pred_pos, "pred_pos")
    g = _positions(gt_pos, "gt_pos")
    _same(p, g, "pred_pos", "gt_pos")
    return np.linalg.norm(p - g, axis=-1)


def rotation_angle(Ra, Rb):
    """Geodesic angle (radians, ``[0, π]``) of ``Raᵀ Rb`` for ``(..., 3, 3)`` inputs.

    Same quantity as :func:`.rotations.geodesic_angle`, computed with
    ``atan2`` so it is exact at 0 and accurate for tiny angles.
    """
    Ra = np.asarray(Ra, dtype=np.float64)
    Rb = np.asarray(Rb, dtype=np.float64)
    R = np.swapaxes(Ra, -1, -2) @ Rb
    c = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0
    sx = R[..., 2, 1] - R[..., 1, 2]
    sy = R[..., 0, 2] - R[..., 2, 0]
    sz = R[..., 1, 0] - R[..., 0, 1]
    s = np.sqrt(sx * sx + sy * sy + sz * sz)
    # (2 sin θ, 2 cos θ) for a proper rotation
    return np.arctan2(s, c)


def mpjpe(pred_pos, gt_pos, joints=None):
    """Mean per-joint position error, cm, over frames and ``joints`` (default all)."""
    e = joint_errors(pred_pos, gt_pos)
    return float(np.mean(e[:, _joint_set(joints, e.shape[1])]) * _M_TO_CM)


def hand_pe(pred_pos, gt_pos):
    """H-PE, cm: MPJPE over the two wrists."""
    _positions(pred_pos, "pred_pos", NUM_JOINTS)
    return mpjpe(pred_pos, gt_pos, HAND_JOINTS)


def upper_pe(pred_pos, gt_pos):
    """U-PE, cm: MPJPE over :data:`UPPER_JOINTS` (pelvis included)."""
    _positions(pred_pos, "pred_pos", NUM_JOINTS)
    return mpjpe(pred_pos, gt_pos, UPPER_JOINTS)


def lower_pe(pred_pos, gt_pos):
    """L-PE, cm: MPJPE over :data:`LOWER_JOINTS`."""
    _positions(pred_pos, "pred_pos", NUM_JOINTS)
    return mpjpe(pred_pos, gt_pos, LOWER_JOINTS)


def mpjre(pred_local_rot, gt_local_rot, joints=None):
    """Mean per-joint rotation error, degrees: geodesic angle of the local
    rotations averaged over frames and ``joints`` (default: all, as AvatarPoser)."""
    p = _rotations(pred_local_rot, "pred_local_rot")
    g = _rotations(gt_local_rot, "gt_local_rot")
    _same(p, g, "pred_local_rot", "gt_local_rot")
    sel = _joint_set(joints, p.shape[1])
    return float(np.degrees(np.mean(rotation_angle(p[:, sel], g[:, sel]))))


def mpjve(pred_pos, gt_pos, fps):
    """Mean per-joint velocity error, cm/s (first differences × fps); NaN if T < 2."""
    p = _positions(pred_pos, "pred_pos")
    g = _positions(gt_pos, "gt_pos")
    _same(p, g, "pred_pos", "gt_pos")
    f = _fps(fps)
    if p.shape[0] < 2:
        return float("nan")
    dv = np.diff(p - g, axis=0)      # Δp_pred - Δp_gt
    return float(np.mean(np.linalg.norm(dv, axis=-1)) * f * _M_TO_CM)


def jitter(pos, fps):
    """Mean jerk magnitude of a sequence, in 10² m/s³ (third difference × fps³ / 100).

    ``pos``: ``(T, J, 3)`` metres.  NaN if T < 4.
    """
    p = _positions(pos, "pos")
    f = _fps(fps)
    if p.shape[0] < 4:
        return float("nan")
    d3 = p[3:] - 3.0 * p[2:-1] + 3.0 * p[1:-2] - p[:-3]
    return float(np.mean(np.linalg.norm(d3, axis=-1)) * f ** 3 / 100.0)


def knee_flexion(pos):
    """``(T, 2)`` flexion of the left and right knee, degrees (0 = straight leg): the angle
    between the thigh (hip → knee) and the shank (knee → ankle) of positions ``(T, 22, 3)``."""
    p = _positions(pos, "pos", NUM_JOINTS)
    out = []
    for side in ("left", "right"):
        u = p[:, J[f"{side}_knee"]] - p[:, J[f"{side}_hip"]]
        v = p[:, J[f"{side}_ankle"]] - p[:, J[f"{side}_knee"]]
        c = (u * v).sum(-1) / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1), 1e-12)
        out.append(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
    return np.stack(out, -1)


def ground_penetration(pos, floor=0.0):
    """GP, cm: mean over frames of how far the lowest joint is below ``floor`` (z, metres)."""
    p = _positions(pos, "pos")
    depth = np.maximum(float(floor) - p[..., 2].min(axis=1), 0.0)
    return float(np.mean(depth) * _M_TO_CM)


def bone_lengths(pos):
    """``(T, 21)`` length of each bone (joint 1..21 to its parent), metres."""
    p = _positions(pos, "pos", NUM_JOINTS)
    return np.linalg.norm(p[:, 1:] - p[:, PARENTS[1:]], axis=-1)


def bone_length_drift(pos, ref_lengths):
    """``(max, mean)`` absolute deviation (cm) of each frame's bone lengths
    from ``ref_lengths`` (``(21,)`` for joints 1..21, or ``(22,)`` with the
    root's 0 first, as :meth:`.skeleton.Body.bone_lengths` returns)."""
    L = bone_lengths(pos)
    ref = np.asarray(ref_lengths, dtype=np.float64).reshape(-1)
    if ref.shape == (NUM_JOINTS,):
        ref = ref[1:]
    if ref.shape != (NUM_JOINTS - 1,):
        raise ValueError(f"ref_lengths must have {NUM_JOINTS - 1} or {NUM_JOINTS} entries, got {ref.shape}")
    dev = np.abs(L - ref) * _M_TO_CM
    return float(dev.max()), float(dev.mean())


# --------------------------------------------------------------------------
def evaluate(pred_pos, pred_local_rot, gt_pos, gt_local_rot, fps, body=None, floor=0.0):
    """All metrics of one sequence, as ``{key: float}`` in :data:`UNITS` order.

    pred_pos, gt_pos: ``(T, 22, 3)`` metres.  pred_local_rot, gt_local_rot:
    ``(T, 22, 3, 3)`` local rotations, or both ``None`` (MPJRE is then NaN).
    fps: frame rate.  body: optional :class:`~.skeleton.Body` whose bone
    lengths are the reference for the bone drift (else the ground truth's
    mean lengths).  See the module docstring for every definition.
    """
    p = _positions(pred_pos, "pred_pos", NUM_JOINTS)
    g = _positions(gt_pos, "gt_pos", NUM_JOINTS)
    _same(p, g, "pred_pos", "gt_pos")
    f = _fps(fps)
    if (pred_local_rot is None) != (gt_local_rot is None):
        raise ValueError("give both pred_local_rot and gt_local_rot, or neither")
    if pred_local_rot is not None:
        pr = _rotations(pred_local_rot, "pred_local_rot", NUM_JOINTS)
        gr = _rotations(gt_local_rot, "gt_local_rot", NUM_JOINTS)
        _same(pr, gr, "pred_local_rot", "gt_local_rot")
        if pr.shape[0] != p.shape[0]:
            raise ValueError(f"rotations have {pr.shape[0]} frames but positions have {p.shape[0]}")
        rot_err = mpjre(pr, gr)
    else:
        rot_err = float("nan")

    e = np.linalg.norm(p - g, axis=-1) * _M_TO_CM            # (T, 22) cm
    ref = body.bone_lengths() if body is not None else bone_lengths(g).mean(axis=0)
    bmax, bmean = bone_length_drift(p, ref)
    return {
        "MPJRE": rot_err,
        "MPJPE": float(e.mean()),
        "MPJVE": mpjve(p, g, f),
        "H-PE": float(e[:, HAND_JOINTS].mean()),
        "U-PE": float(e[:, UPPER_JOINTS].mean()),
        "L-PE": float(e[:, LOWER_JOINTS].mean()),
        "Jitter": jitter(p, f),
        "Jitter-GT": jitter(g, f),
        "GP": ground_penetration(p, floor),
        "Bone-max": bmax,
        "Bone-mean": bmean,
    }


# --------------------------------------------------------------------------
def _fmt_value(v, fmt):
    if v is None:
        return "-"
    if callable(fmt):
        return str(fmt(v))
    if isinstance(v, str):
        return v
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v)) if fmt is None else format(int(v), fmt)
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(x):
        return "n/a"
    return format(x, fmt or ".2f")


def format_table(rows: Sequence[tuple[str, Mapping]], columns: Iterable | None = None, *,
                 name_header: str = "method", formats: Mapping[str, str | Callable] | None = None,
                 units: bool = False) -> str:
    """Aligned plain-text table that is also a valid Markdown (GFM) table.

    rows: ``[(row_name, {column: value})]``.  columns: the keys to show, in
    order (default: every key, in order of first appearance).  Values: floats
    are printed with ``formats[column]`` (a format spec or a callable; default
    ``".2f"``), ints as ints, strings as they are; a missing value or ``None``
    prints ``-`` and NaN ``n/a``.  ``units=True`` appends :data:`UNITS` to
    known headers, e.g. ``MPJPE [cm]``.  Numbers are right-aligned, the name
    column left-aligned; ``|`` inside a cell is escaped as ``\\|``.
    """
    rows = list(rows)
    if columns is None:
        columns = []
        for _, d in rows:
            for k in d:
                if k not in columns:
                    columns.append(k)
    columns = list(columns)
    formats = dict(formats or {})
    headers = [name_header] + [f"{c} [{UNITS[c]}]" if units and c in UNITS else str(c) for c in columns]
    body = [[str(name)] + [_fmt_value(d.get(c), formats.get(c)) for c in columns] for name, d in rows]
    headers = [h.replace("|", "\\|") for h in headers]               # keep Markdown cells intact
    body = [[c.replace("|", "\\|") for c in r] for r in body]
    widths = [max(3, len(h), *(len(r[i]) for r in body)) for i, h in enumerate(headers)]

    def line(cells):
        return "| " + " | ".join(c.ljust(w) if i == 0 else c.rjust(w)
                                 for i, (c, w) in enumerate(zip(cells, widths))) + " |"

    sep = "|" + "|".join(("-" * (w + 1) + ":") if i else ("-" * (w + 2))
                         for i, w in enumerate(widths)) + "|"
    return "\n".join([line(headers), sep] + [line(r) for r in body])


__all__ = [
    "HAND_JOINTS", "UPPER_JOINTS", "LOWER_JOINTS", "ROTATION_JOINTS", "BONES", "UNITS", "PAPER_COLUMNS",
    "JOINT_NAMES", "joint_errors", "rotation_angle", "mpjpe", "hand_pe", "upper_pe", "lower_pe", "mpjre",
    "mpjve", "jitter", "ground_penetration", "bone_lengths", "bone_length_drift", "evaluate",
    "format_table",
]
