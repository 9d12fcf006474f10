"""BVH writer for solved animations (numpy only, never imports bpy).

The body model lives in Blender world axes (metres, +Z up, body faces -Y).
BVH files are conventionally Y-up, so every vector is mapped with

    v_bvh = C v_blender,   C = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]

i.e. ``(x, y, z) -> (x, z, -y)``: +Y up, the body faces +Z, the performer's
left stays +X.  This is the inverse of Blender's BVH importer defaults
(``axis_forward='-Z', axis_up='Y'``), so importing the file into Blender
restores the original Z-up coordinates.  Because every joint frame of the
body model is world-aligned at rest, a local rotation converts by the same
change of basis, ``R_bvh = C R Cᵀ``, and the hierarchy's OFFSETs are the rest
offsets ``C offset``.

Channels: the root has ``Xposition Yposition Zposition Zrotation Xrotation
Yrotation``, every other joint ``Zrotation Xrotation Yrotation``; rotations
in degrees with ``R = Rz(z) Rx(x) Ry(y)`` (the order the channels are
listed in), each angle unwrapped over time so curves have no 360° jumps.
Lengths in centimetres (``units="cm"``, the common BVH unit) or metres
(``units="m"``).  The leaf joints (head, wrists, feet) get an ``End Site``
from :func:`end_site_offsets`.  The ROOT's OFFSET is zero and its position
channels are the absolute pelvis position (BVH readers disagree on whether
OFFSET is added to them; with a zero OFFSET both readings agree).
"""
from __future__ import annotations

import io

import numpy as np

from . import rotations as rot
from . import skeleton as sk
from .file_names import written_whole
from .plain import shown

#: change of basis Blender (Z-up, -Y forward) → BVH (Y-up, +Z forward)
C_BLENDER_TO_BVH = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
UNIT_SCALE = {"m": 1.0, "cm": 100.0}


def end_site_offsets(body: sk.Body):
    """``(22, 3)`` tip offsets (metres, Blender axes, rest) of the leaf joints, zero elsewhere.

    head: 0.09 stature up (+Z, top of the skull); wrists: 0.10 stature along
    the forearm (±X, hand length); feet: 0.04 stature forward (-Y, toe tips
    ahead of the ball).  Used for BVH ``End Site`` and the armature's leaf bones.
    """
    H = body.stature
    out = np.zeros((sk.NUM_JOINTS, 3))
    out[sk.J["head"]] = [0.0, 0.0, 0.09 * H]
    for side in ("left", "right"):
        w = sk.J[f"{side}_wrist"]
        d = np.asarray(body.offsets[w], dtype=np.float64)
        n = np.linalg.norm(d)
        d = d / n if n > 1e-9 else np.array([1.0 if side == "left" else -1.0, 0.0, 0.0])
        out[w] = d * 0.10 * H
        out[sk.J[f"{side}_foot"]] = [0.0, -0.04 * H, 0.0]
    return out


def _fmt(v, decimals):
    return " ".join(f"{x:.{decimals}f}" for x in v)


def bvh_string(local_rot, root_pos, body: sk.Body, fps: float, units: str = "cm", decimals: int = 6,
               out=None, chunk_frames=None):
    """The BVH file text for an animation (``out`` None), or written to the text file ``out``.

    local_rot: ``(T, 22, 3, 3)`` body-model local rotations; root_pos:
    ``(T, 3)`` pelvis world positions (metres, Blender axes); ``fps`` frames
    per second; ``units`` ``"cm"`` or ``"m"``.  The motion is converted and formatted
    ``chunk_frames`` (default :data:`.pose_result.CHUNK_FRAMES`) frames at a time, so writing a long take
    to ``out`` needs no more memory than a short one; the text does not depend on it.
    """
    if units not in UNIT_SCALE:
        raise ValueError(f"units must be one of {sorted(UNIT_SCALE)}, got {shown(units)}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {shown(fps)}")
    s = UNIT_SCALE[units]
    C = C_BLENDER_TO_BVH
    local_rot = np.asarray(local_rot, dtype=np.float64)
    root_pos = np.asarray(root_pos, dtype=np.float64).reshape(-1, 3)
    T = local_rot.shape[0]
    if local_rot.shape != (T, sk.NUM_JOINTS, 3, 3) or root_pos.shape[0] != T:
        raise ValueError(f"expected local_rot (T, 22, 3, 3) and root_pos (T, 3), got "
                         f"{local_rot.shape} and {root_pos.shape}")
    offsets = body.offsets @ C.T * s
    tips = end_site_offsets(body) @ C.T * s

    lines = ["HIERARCHY"]

    def emit(j, depth):
        ind = "\t" * depth
        name = sk.JOINT_NAMES[j]
        if j == 0:
            lines.append(f"ROOT {name}")
            lines.append("{")
            lines.append(f"\tOFFSET {_fmt(np.zeros(3), decimals)}")
            lines.append("\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{ind}JOINT {name}")
            lines.append(f"{ind}{{")
            lines.append(f"{ind}\tOFFSET {_fmt(offsets[j], decimals)}")
            lines.append(f"{ind}\tCHANNELS 3 Zrotation Xrotation Yrotation")
        children = sk.CHILDREN[j]
        if children:
            for c in children:
                emit(c, depth + 1)
        else:
            lines.append(f"{ind}\tEnd Site")
            lines.append(f"{ind}\t{{")
            lines.append(f"{ind}\t\tOFFSET {_fmt(tips[j], decimals)}")
            lines.append(f"{ind}\t}}")
        lines.append(f"{ind}}}")

    emit(0, 0)
    lines.append("MOTION")
    lines.append(f"Frames: {T}")
    lines.append(f"Frame Time: {1.0 / fps:.8f}")
    # channel data, joints in hierarchy (depth-first) order
    order = []

    def walk(j):
        order.append(j)
        for c in sk.CHILDREN[j]:
            walk(c)
    walk(0)
    buf = io.StringIO() if out is None else None
    f = buf if out is None else out
    f.write("\n".join(lines) + "\n")
    unwrap = _Unwrap()
    from . import pose_result
    step = max(int(chunk_frames or pose_result.CHUNK_FRAMES), 1)
    for a in range(0, T, step):
        fr = slice(a, min(a + step, T))
        Rb = np.einsum("ab,tjbc,dc->tjad", C, local_rot[fr][:, order], C)       # C R Cᵀ
        eul = np.degrees(unwrap(rot.matrix_to_euler(Rb, "ZXY")))                # (n, 22, 3)
        # ROOT OFFSET is 0 and the position channels are absolute, which reads the
        # same whether an importer adds OFFSET to them or not
        root = root_pos[fr] @ C.T * s
        np.savetxt(f, np.concatenate([root, eul.reshape(len(eul), -1)], axis=1), fmt=f"%.{decimals}f",
                   delimiter=" ")
    return buf.getvalue() if buf is not None else None


class _Unwrap:
    """``numpy.unwrap`` along axis 0 (radians), fed the take in successive chunks: the same
    numbers as one call over the whole take (the running correction carries over)."""

    def __init__(self):
        self.last = self.carry = None

    def __call__(self, p):
        p = np.asarray(p, dtype=np.float64)
        if len(p) == 0:
            return p.copy()
        if self.last is None:
            head, rest, carry = p[:1], p, np.zeros_like(p[0])
        else:
            head, rest, carry = None, np.concatenate([self.last[None], p], 0), self.carry
        dd = np.diff(rest, axis=0)
        ddmod = np.mod(dd + np.pi, 2 * np.pi) - np.pi
        np.copyto(ddmod, np.pi, where=(ddmod == -np.pi) & (dd > 0))
        correct = ddmod - dd
        np.copyto(correct, 0, where=np.abs(dd) < np.pi)
        cum = np.cumsum(np.concatenate([carry[None], correct], 0), axis=0)[1:]
        self.last, self.carry = p[-1].copy(), (cum[-1] if len(cum) else carry)
        body = rest[1:] + cum
        return body if head is None else np.concatenate([head, body], 0)


def write_bvh(path, result, units: str = "cm", decimals: int = 6):
    """Write a :class:`~blender_manikin.core.pose_result.PoseResult` as BVH to ``path`` (under a
    temporary name, then renamed); returns ``path``."""
    with written_whole(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        bvh_string(result.local_rot, result.root_pos, result.body, result.fps, units, decimals, out=f)
    return path
