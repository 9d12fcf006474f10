"""A mannequin mesh for a body: the solved performer seen as a body, not as bones.

An artist's wooden mannequin: one closed, rounded piece per bone (pelvis, three trunk pieces,
chest, neck, head; collar, upper arm, forearm and hand; thigh, shank, foot and toes), each moving
rigidly with its bone, the pieces overlapping at the joints so a bent elbow or knee shows no gap.
The build is one neutral adult's (radii as shares of stature, after anthropometric tables: hip
breadth 0.19, chest 0.19, thigh 0.12, head 0.09 x 0.11 x 0.14 of stature), not the performer's
shape: it is there to judge contacts, reach and volume (a hand through the chest, a foot in the
floor, a head in a wall) and to give an exported FBX a visible body.

The feet are built on the solver's floor convention (:func:`.pipeline.ankle_height_on_floor`):
in the rest pose their heel (:data:`.pipeline.HEEL_BACK` behind the ankle) and ball (the foot
joint) rest on the floor under the body's soles, and the bottom of the shoe blocks lies on it; the
top of the head is at the stature (plus the soles).

Axes and units: the body's own (:mod:`.skeleton`: Z up, the body faces -Y, the performer's left
is +X; metres, or whatever unit the :class:`~.skeleton.Body` is in: every size is a share of its
stature), the rest T-pose of ``body.rest_positions()``.  No bpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .export_bvh import end_site_offsets
from .pipeline import HEEL_BACK
from .skeleton import Body, J, JOINT_NAMES, NUM_JOINTS, PROPORTIONS

#: rings around each piece (its cross-section's vertices)
AROUND = 16
#: rings on each rounded end, pole excluded
CAP_RINGS = 4


@dataclass
class MannequinMesh:
    """The mannequin of a body in its rest pose.

    verts ``(V, 3)`` float64 (the body's unit, Z up, rest T-pose); faces ``(F, 4)`` int32 vertex
    indices, counter-clockwise seen from outside (a triangle repeats its last index); bone ``(V,)``
    int32: the joint (:data:`.skeleton.JOINT_NAMES` index) whose bone carries each vertex, with
    weight 1; piece ``(V,)`` int32: which closed piece each vertex belongs to (:attr:`names`)."""
    verts: np.ndarray
    faces: np.ndarray
    bone: np.ndarray
    piece: np.ndarray
    names: tuple

    @property
    def bone_names(self) -> tuple:
        """The names of the bones that carry vertices (the vertex groups an armature needs)."""
        return tuple(JOINT_NAMES[j] for j in np.unique(self.bone))


def _frame(axis, across):
    """Unit ``(e, u, v)``: ``e`` along ``axis``; ``u`` is ``across`` made perpendicular to it
    (the width direction of the cross-section); ``v = e x u``."""
    e = np.asarray(axis, np.float64)
    e = e / np.linalg.norm(e)
    u = np.asarray(across, np.float64) - np.dot(across, e) * e
    u = u / np.linalg.norm(u)
    return e, u, np.cross(e, u)


def rounded_piece(a, b, ra, rb, across=(1.0, 0.0, 0.0), flat=1.0, cap=1.0, around=AROUND,
                  cap_rings=CAP_RINGS):
    """One closed piece from ``a`` to ``b`` ``(3,)``: a cone of radius ``ra`` at ``a`` and ``rb``
    at ``b`` with a rounded end on either side, stretching beyond ``a`` and ``b`` by ``cap`` times
    their radius.  The cross-section is ``flat`` times as deep (along ``v`` of :func:`_frame`) as
    it is wide (along ``across``, made perpendicular to the axis).  Returns ``(verts (V, 3),
    faces (F, 4))``, faces counter-clockwise from outside (triangles at the poles repeat a
    vertex)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    L = float(np.linalg.norm(b - a))
    e, u, v = _frame(b - a if L > 1e-9 else (0.0, 0.0, 1.0), across)
    phi = np.linspace(0.0, 0.5 * np.pi, cap_rings + 1)[1:]           # from the pole to the equator
    # rings along the axis: (axial position from a, radius)
    rings = [(-cap * ra * np.cos(p), ra * np.sin(p)) for p in phi]
    rings += [(L + cap * rb * np.cos(p), rb * np.sin(p)) for p in phi[::-1]]
    th = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    circle = np.cos(th)[:, None] * u + flat * np.sin(th)[:, None] * v              # (around, 3)
    verts = [a - cap * ra * e]
    verts += [a + s * e + r * circle for s, r in rings]
    verts.append(a + (L + cap * rb) * e)
    verts = np.vstack([np.atleast_2d(x) for x in verts])
    n_r, last = len(rings), len(verts) - 1

    def ring(k, i):
        return 1 + k * around + (i % around)

    faces = [(0, ring(0, i + 1), ring(0, i), ring(0, i)) for i in range(around)]
    for k in range(n_r - 1):
        faces += [(ring(k, i), ring(k, i + 1), ring(k + 1, i + 1), ring(k + 1, i)) for i in range(around)]
    faces += [(last, ring(n_r - 1, i), ring(n_r - 1, i + 1), ring(n_r - 1, i + 1)) for i in range(around)]
    return verts, np.asarray(faces, np.int32)


def _unit(v, fallback):
    """``v`` ``(3,)`` made unit length, or ``fallback`` where it has none (a zero-length bone)."""
    v = np.asarray(v, np.float64)
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.asarray(fallback, np.float64)


def _pieces(body: Body):
    """``[(name, bone joint index, kwargs of rounded_piece)]`` for ``body``'s rest pose."""
    P = body.rest_positions()
    H = float(body.stature)
    leaf = end_site_offsets(body)                                     # the leaf bones' tips
    X, Y = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])
    out = []

    def add(name, joint, a, b, ra, rb, across=X, flat=1.0, cap=1.0):
        out.append((name, J[joint], dict(a=a, b=b, ra=ra * H, rb=rb * H, across=across, flat=flat, cap=cap)))

    hips = 0.5 * (P[J["left_hip"]] + P[J["right_hip"]])
    # the trunk: flattened front to back, its ends flat enough to stack without bulging
    add("pelvis", "pelvis", hips - 0.02 * H * up, P[J["spine1"]], 0.095, 0.088, flat=0.72, cap=0.5)
    add("abdomen", "spine1", P[J["spine1"]], P[J["spine2"]], 0.085, 0.085, flat=0.70, cap=0.5)
    add("waist", "spine2", P[J["spine2"]], P[J["spine3"]], 0.085, 0.095, flat=0.70, cap=0.5)
    chest_top = P[J["neck"]] - 0.025 * H * up
    add("chest", "spine3", P[J["spine3"]], chest_top, 0.097, 0.085, flat=0.68, cap=0.5)
    add("neck", "neck", P[J["neck"]] - 0.01 * H * up, P[J["head"]] + 0.02 * H * up, 0.032, 0.030)
    # the head: an ellipsoid from the chin to the top of the skull at the stature
    top = P[J["head"]][2] + (1.0 - PROPORTIONS["head_height"]) * H
    centre = np.array([P[J["head"]][0], P[J["head"]][1] - 0.008 * H, top - 0.068 * H])
    add("head", "head", centre - 1e-6 * up, centre, 0.047, 0.047, across=X, flat=1.2,     # axis: up
        cap=0.068 / 0.047)
    for side, sx in (("left", 1.0), ("right", -1.0)):
        s = f"{side}_"
        sh, el, wr = P[J[s + "shoulder"]], P[J[s + "elbow"]], P[J[s + "wrist"]]
        add(s + "collar", s + "collar", P[J[s + "collar"]], sh, 0.030, 0.042, across=Y)
        add(s + "upper_arm", s + "shoulder", sh, el, 0.040, 0.031, across=Y)
        add(s + "forearm", s + "elbow", el, wr, 0.030, 0.022, across=Y)
        d = _unit(wr - el, [sx, 0.0, 0.0])
        # the hand: palm width across the forearm's Y (palms down in the T-pose), thin
        add(s + "hand", s + "wrist", wr + 0.02 * H * d, wr + 0.085 * H * d, 0.026, 0.024, across=Y,
            flat=0.45, cap=0.9)
        hip, kn, an = P[J[s + "hip"]], P[J[s + "knee"]], P[J[s + "ankle"]]
        add(s + "thigh", s + "hip", hip, kn, 0.060, 0.040)
        add(s + "shank", s + "knee", kn, an, 0.040, 0.026)
        # the foot on the floor: its sole through the heel and the ball at their rest height
        ball = P[J[s + "foot"]]
        off = ball - an
        heel = an + off * np.array([-HEEL_BACK, -HEEL_BACK, 0.0])
        heel[2] = ball[2]
        floor = ball[2] - PROPORTIONS["foot_height"] * H - body.sole
        half = 0.5 * (an[2] - floor) * 0.85 / H                     # the block's half height
        z = floor + half * H
        w = 0.029
        fwd = _unit((ball - heel) * np.array([1.0, 1.0, 0.0]), [0.0, -1.0, 0.0])
        r_end = half                                                # rounded ends: half the height
        add(s + "foot", s + "ankle", np.r_[heel[:2] + fwd[:2] * r_end * H, z],
            np.r_[ball[:2], z], w, w * 0.95, across=X, flat=half / w, cap=r_end / w)
        toe_half = 0.5 * (ball[2] - floor + 0.004 * H) / H
        tip = ball + fwd * np.linalg.norm(leaf[J[s + "foot"]])       # the toe tip of the foot bone
        add(s + "toes", s + "foot", np.r_[ball[:2], floor + toe_half * H],
            np.r_[tip[:2] - fwd[:2] * 0.01 * H, floor + toe_half * H], w * 0.95, w * 0.8, across=X,
            flat=toe_half / w, cap=0.01 / w)
    return out


def mannequin_mesh(body: Body, around: int = AROUND, cap_rings: int = CAP_RINGS) -> MannequinMesh:
    """The :class:`MannequinMesh` of ``body`` in its rest pose (see the module docstring)."""
    verts, faces, bone, piece, names = [], [], [], [], []
    n = 0
    for k, (name, joint, kw) in enumerate(_pieces(body)):
        v, f = rounded_piece(around=around, cap_rings=cap_rings, **kw)
        verts.append(v)
        faces.append(f + n)
        bone.append(np.full(len(v), joint, np.int32))
        piece.append(np.full(len(v), k, np.int32))
        names.append(name)
        n += len(v)
    m = MannequinMesh(np.vstack(verts), np.vstack(faces).astype(np.int32), np.concatenate(bone),
                      np.concatenate(piece), tuple(names))
    if not np.isfinite(m.verts).all() or m.bone.max() >= NUM_JOINTS:
        raise ValueError("the body's rest pose gives no finite mannequin (a zero-length bone?)")
    return m


def posed_vertices(mesh: MannequinMesh, world_rot, positions, body: Body):
    """The mannequin's vertices posed: ``(T, V, 3)``, each vertex moved rigidly with its bone.

    world_rot ``(T, 22, 3, 3)`` world joint rotations (body-model convention: identity = the
    rest T-pose), positions ``(T, 22, 3)`` joint positions, both as a
    :class:`~.pose_result.PoseResult` gives them (``fk()``), in ``body``'s unit.  What
    Blender's Armature modifier does with the mesh's one-bone vertex groups."""
    rest = body.rest_positions()
    j = mesh.bone
    local = mesh.verts - rest[j]                                                  # (V, 3)
    R = np.asarray(world_rot, np.float64)[:, j]                                   # (T, V, 3, 3)
    return np.einsum("tvij,vj->tvi", R, local) + np.asarray(positions, np.float64)[:, j]
