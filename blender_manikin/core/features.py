"""Network inputs and outputs: canonical frame, feature and target layouts.

Shared by training (numpy batches fed to torch) and inference (onnxruntime),
so both see exactly the same numbers.  Never imports bpy or torch.

Canonical frame of a window
---------------------------
A window of W frames is expressed in the frame of its centre frame ``c``:
origin at the head joint's floor projection ``o = (hx, hy, 0)``, rotated
about +Z so the head's heading (its local -Y axis projected on the floor)
points along -Y, and every length divided by the performer's stature ``s``::

    C = Rz(yaw_c)                      world-from-canonical rotation (3, 3)
    p_can = Cᵀ (p - o) / s             positions
    R_can = Cᵀ R                       world orientations

So a performer anywhere in the room, facing anywhere, of any height gives the
same features (tested).  Heights stay measured from the floor (z = 0).

Inputs ``x`` : ``(B, W, F_in)`` float32, per frame, for each input device
in ``INPUT_DEVICES`` order: canonical position (3), canonical orientation
6D (6), velocity (3, canonical, in statures per second / 10); then, for
body-conditioned models (SparsePoser's "static encoder" idea), the same
:data:`BODY_FEATURES` on every frame of the window: the performer's segment
lengths in statures, minus those of the reference body (:data:`BODY_REFERENCE`,
the body model's Drillis & Contini proportions when the networks were
trained), times :data:`BODY_SCALE`.  So one model adapts to long legs, short
arms or a low head joint instead of assuming the training actors'
proportions.

Outputs (MANIKIN) ``y`` : ``(B, W, F_out)`` float32 with the blocks of
:data:`OUTPUT_BLOCKS`: root (pelvis) world orientation 6D in the canonical
frame; torso local rotations 6D (spine1, spine2, spine3, neck, left_collar,
right_collar); ankle positions relative to the head (canonical, / s); ankle
world orientations 6D (canonical); swivel (cos, sin) for the four limbs;
foot-contact logits (left, right).

The network-only baseline (``kind="fk"``) predicts the root orientation and
all 21 other local rotations (6D) instead, posed by FK.
"""
from __future__ import annotations

import numpy as np

from . import rotations as rot
from .devices import DEVICE_JOINT, REQUIRED_DEVICES  # noqa: F401  (DEVICE_JOINT: used by training)
from .skeleton import J, MIRROR_JOINTS, MIRROR_M, NUM_JOINTS, mirror_name

INPUT_DEVICES = REQUIRED_DEVICES
PER_DEVICE = 12
VEL_SCALE = 0.1

TORSO_LOCAL = ("spine1", "spine2", "spine3", "neck", "left_collar", "right_collar")
TORSO_LOCAL_IDX = tuple(J[n] for n in TORSO_LOCAL)
ANKLES = (J["left_ankle"], J["right_ankle"])

OUTPUT_BLOCKS = {
    "manikin": (("root_rot", 6), ("torso_rot", 6 * len(TORSO_LOCAL)), ("ankle_pos", 6),
                ("ankle_rot", 12), ("swivel", 8), ("contact", 2)),
    "fk": (("root_rot", 6), ("local_rot", 6 * (NUM_JOINTS - 1)), ("contact", 2)),
}


#: body features (each a length in statures, see :func:`body_measures`)
BODY_FEATURES = ("thigh", "shank", "ankle_above_ball", "torso", "neck_head",
                 "hip_width", "shoulder_width", "upper_arm", "forearm")
#: multiplies (measure - reference) so that a ±12 % segment is about ±0.1-0.3
BODY_SCALE = 5.0

_LEFT, _RIGHT = ("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle")


def _chain_z(offsets, names):
    """Sum of the offsets' z along a joint chain ``(..., )``."""
    return sum(offsets[..., J[n], 2] for n in names)


def head_above_ankles(offsets):
    """``(...)`` metres: the head joint above the ankle joints of a body standing straight,
    from rest offsets ``(..., 22, 3)`` (left/right averaged)."""
    off = np.asarray(offsets, np.float64)
    head_z = _chain_z(off, ("spine1", "spine2", "spine3", "neck", "head"))
    ankle_z = 0.5 * (_chain_z(off, _LEFT) + _chain_z(off, _RIGHT))
    return head_z - ankle_z


def stature_from_offsets(offsets):
    """``(...)`` metres: the stature the network's features are normalised by (its length unit),
    from rest offsets ``(..., 22, 3)``: the head joint above the ankles / :data:`HEAD_ABOVE_ANKLES`
    (0.871), as the body model built bodies when the networks were trained.  It does not depend
    on a source skeleton's floor convention.  (The body model's own stature of a body,
    :func:`~.skeleton.stature_from_head_above_ankles`, is 0.871 / 0.831 = 1.048 times it since its
    head joint moved down to 0.870.)"""
    return head_above_ankles(offsets) / HEAD_ABOVE_ANKLES


def body_measures(offsets, stature):
    """Segment lengths of a body in statures, :data:`BODY_FEATURES` order.

    offsets ``(..., 22, 3)`` rest offsets in metres (parent frame = world at
    rest: T-pose, +Z up), stature ``(...)`` metres.  Returns ``(..., K)``
    float64: thigh, shank, ankle above the ball of the foot, pelvis to neck,
    neck to head, hip and shoulder joint-centre widths, upper arm, forearm
    (left/right averaged)."""
    off = np.asarray(offsets, np.float64)
    s = np.asarray(stature, np.float64)
    L = np.linalg.norm(off, axis=-1)
    both = lambda a, b: 0.5 * (a + b)  # noqa: E731
    hips = off[..., J["left_hip"], 0] - off[..., J["right_hip"], 0]
    shoulders = ((off[..., J["left_collar"], 0] + off[..., J["left_shoulder"], 0])
                 - (off[..., J["right_collar"], 0] + off[..., J["right_shoulder"], 0]))
    m = np.stack([
        both(L[..., J["left_knee"]], L[..., J["right_knee"]]),
        both(L[..., J["left_ankle"]], L[..., J["right_ankle"]]),
        both(-off[..., J["left_foot"], 2], -off[..., J["right_foot"], 2]),
        _chain_z(off, ("spine1", "spine2", "spine3", "neck")),
        off[..., J["head"], 2],
        hips, shoulders,
        both(L[..., J["left_elbow"]], L[..., J["right_elbow"]]),
        both(L[..., J["left_wrist"]], L[..., J["right_wrist"]]),
    ], -1)
    return m / s[..., None]


#: statures between the head joint and the ankles on the bodies the networks were trained with
#: (the body model's proportions of that time: head joint 0.910, ankles 0.039).  A constant of the
#: network contract (its length unit), not of the body model: ``make_body`` now puts the head
#: joint lower (:mod:`.skeleton`), and a network sees the body's head above its ankles / 0.871.
HEAD_ABOVE_ANKLES = 0.871
#: body measures (statures, :data:`BODY_FEATURES` order) the body features are taken relative to:
#: the body model's proportions when the networks were trained.  Recorded in each model's contract
#: (``body_normalisation.reference``) and checked against it when a model is loaded.
BODY_REFERENCE = np.array([0.245, 0.246, 0.027, 0.280, 0.070, 0.100, 0.209, 0.186, 0.146])


def body_features(offsets, stature):
    """Network body features ``(..., K)`` float32 (see module doc) from rest
    offsets ``(..., 22, 3)`` metres and stature ``(...)`` metres (:func:`stature_from_offsets`);
    zero for a body with the proportions of :data:`BODY_REFERENCE`."""
    return ((body_measures(offsets, stature) - BODY_REFERENCE) * BODY_SCALE).astype(np.float32)


def output_slices(kind="manikin"):
    """``{block name: slice}`` into the last axis of ``y``."""
    out, k = {}, 0
    for name, size in OUTPUT_BLOCKS[kind]:
        out[name] = slice(k, k + size)
        k += size
    return out


def output_dim(kind="manikin"):
    return sum(size for _, size in OUTPUT_BLOCKS[kind])


def input_dim(devices=INPUT_DEVICES, body=False):
    """Per-frame input size: 12 per device, plus the body features when ``body``."""
    return PER_DEVICE * len(devices) + (len(BODY_FEATURES) if body else 0)


def heading_yaw(R):
    """Yaw (radians about +Z) of orientations ``(..., 3, 3)``: the angle of
    the local -Y axis projected on the floor, 0 when it points along -Y."""
    f = -R[..., :, 1]
    return np.arctan2(f[..., 0], -f[..., 1])


def rot_z(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def canonical_frames(head_pos, head_rot, centre=None):
    """Canonical frame of each window.

    head_pos ``(B, W, 3)``, head_rot ``(B, W, 3, 3)`` (head *joint* targets).
    Returns ``(C (B, 3, 3), origin (B, 3))``; ``centre`` defaults to W // 2.
    """
    c = head_pos.shape[1] // 2 if centre is None else centre
    C = rot_z(heading_yaw(head_rot[:, c]))
    o = head_pos[:, c].copy()
    o[:, 2] = 0.0
    return C, o


def make_inputs(pos, rot_m, stature, fps, devices=INPUT_DEVICES, frames=None, body=None):
    """Network input ``(B, W, 12·D [+ K])`` float32.

    pos: dict device → ``(B, W, 3)`` joint target positions (metres, world);
    rot_m: dict device → ``(B, W, 3, 3)`` joint target orientations;
    stature: ``(B,)`` metres; fps: frames per second of the window.
    frames: optional precomputed ``(C, o)``.  body: optional ``(B, K)``
    :func:`body_features`, appended to every frame.  Returns ``(x, C, o)``.
    """
    C, o = canonical_frames(pos["head"], rot_m["head"]) if frames is None else frames
    s = np.asarray(stature, np.float64).reshape(-1, 1, 1)
    Ct = np.swapaxes(C, -1, -2)[:, None]
    feats = []
    for d in devices:
        p = np.einsum("bwij,bwj->bwi", Ct, pos[d] - o[:, None]) / s
        r6 = rot.matrix_to_6d(Ct @ rot_m[d])
        vel = np.zeros_like(p)
        vel[:, 1:] = (p[:, 1:] - p[:, :-1]) * (fps * VEL_SCALE)
        vel[:, 0] = vel[:, 1] if p.shape[1] > 1 else 0.0
        feats += [p, r6, vel]
    if body is not None:
        b = np.asarray(body, np.float64)
        b = np.broadcast_to(b.reshape(-1, 1, b.shape[-1]), (feats[0].shape[0], feats[0].shape[1], b.shape[-1]))
        feats.append(b)
    return np.concatenate(feats, -1).astype(np.float32), C, o


#: sign of each 6D component (first column, then second) under ``R -> M R M``, ``M = diag(-1, 1, 1)``:
#: the first column becomes ``-M c0``, the second ``M c1`` (linear, so it holds for raw network 6D too)
SIXD_MIRROR_SIGN = np.concatenate([-np.diag(MIRROR_M), np.diag(MIRROR_M)])
_X_MIRROR_SIGN = np.diag(MIRROR_M)


def mirror_inputs(x, devices=INPUT_DEVICES):
    """Network inputs ``(..., W, 12·D [+ K])`` of the left/right mirror image (x -> -x) of the
    same windows: what :func:`make_inputs` makes from mirrored trackers.

    A mirrored window's canonical frame is the mirror of the original's (its heading yaw is
    negated), so in canonical coordinates the mirror is exact: positions and velocities
    negate x, orientations become ``M R M``, and the left and right devices swap. The body
    features (left/right averages) stay. ``devices`` must hold each device's mirror image."""
    x = np.asarray(x)
    order = [devices.index(mirror_name(d)) for d in devices]
    sign = np.concatenate([_X_MIRROR_SIGN, SIXD_MIRROR_SIGN, _X_MIRROR_SIGN]).astype(x.dtype)
    D = len(devices) * PER_DEVICE
    per = x[..., :D].reshape(x.shape[:-1] + (len(devices), PER_DEVICE))[..., order, :] * sign
    return np.concatenate([per.reshape(x.shape[:-1] + (D,)), x[..., D:]], -1)


def mirror_outputs(y, kind="manikin"):
    """Network outputs ``(..., W, F_out)`` (raw: 6D, canonical positions, (cos, sin), logits) mapped
    through the left/right mirror: the outputs for the mirrored window, read back as the
    original's. Its own inverse. Swivel angles negate under the mirror (each limb's swivel frame
    ``(u, v = n × u)`` turns left-handed), so their sines change sign as the limbs swap."""
    y = np.asarray(y)
    sl = output_slices(kind)
    lead = y.shape[:-1]
    out = np.empty_like(y)

    def block(name, n, width):
        return y[..., sl[name]].reshape(lead + (n, width))

    def put(name, v):
        out[..., sl[name]] = v.reshape(lead + (sl[name].stop - sl[name].start,))

    s6 = SIXD_MIRROR_SIGN.astype(y.dtype)
    put("root_rot", block("root_rot", 1, 6) * s6)
    put("contact", block("contact", 2, 1)[..., ::-1, :])
    if kind == "manikin":
        torso = [TORSO_LOCAL.index(mirror_name(n)) for n in TORSO_LOCAL]
        put("torso_rot", block("torso_rot", len(TORSO_LOCAL), 6)[..., torso, :] * s6)
        put("ankle_pos", block("ankle_pos", 2, 3)[..., ::-1, :] * _X_MIRROR_SIGN.astype(y.dtype))
        put("ankle_rot", block("ankle_rot", 2, 6)[..., ::-1, :] * s6)
        put("swivel", block("swivel", 4, 2)[..., [1, 0, 3, 2], :] * np.array([1, -1], y.dtype))
    else:
        put("local_rot", block("local_rot", NUM_JOINTS - 1, 6)[..., MIRROR_JOINTS[1:] - 1, :] * s6)
    return out


def encode_targets(world_rot, local_rot, positions, swivel, contacts, C, o, stature, kind="manikin",
                   head_anchor=None):
    """Training targets ``(B, W, F_out)`` float32 from ground truth.

    world_rot/local_rot: ``(B, W, 22, 3, 3)``; positions ``(B, W, 22, 3)``;
    swivel ``(B, W, 4)`` radians; contacts ``(B, W, 2)`` in {0, 1}.
    head_anchor: ``(B, W, 3)`` what the ankle positions are relative to
    (default the head joint); pass the head *input* when it carries an
    offset, since :func:`decode_outputs` anchors them at the input.
    """
    Ct = np.swapaxes(C, -1, -2)[:, None]
    s = np.asarray(stature, np.float64).reshape(-1, 1, 1)
    blocks = [rot.matrix_to_6d(Ct @ world_rot[:, :, 0])]
    if kind == "manikin":
        B, W = swivel.shape[:2]
        blocks.append(rot.matrix_to_6d(local_rot[:, :, list(TORSO_LOCAL_IDX)]).reshape(B, W, -1))
        anchor = positions[:, :, J["head"]] if head_anchor is None else head_anchor
        rel = positions[:, :, list(ANKLES)] - anchor[:, :, None]
        blocks.append((np.einsum("bwij,bwkj->bwki", Ct, rel) / s[..., None]).reshape(B, W, 6))
        blocks.append(rot.matrix_to_6d(Ct[:, :, None] @ world_rot[:, :, list(ANKLES)]).reshape(B, W, 12))
        blocks.append(np.stack([np.cos(swivel), np.sin(swivel)], -1).reshape(B, W, 8))
    else:
        B, W = local_rot.shape[:2]
        blocks.append(rot.matrix_to_6d(local_rot[:, :, 1:]).reshape(B, W, -1))
    blocks.append(np.asarray(contacts, np.float64))
    return np.concatenate(blocks, -1).astype(np.float32)


def decode_outputs(y, C, o, stature, head_pos, kind="manikin"):
    """Network output ``(B, W, F_out)`` → world-space quantities (dict).

    head_pos ``(B, W, 3)`` anchors the ankle positions.  Keys (manikin):
    ``root_rot (B, W, 3, 3)`` world, ``torso_rot (B, W, 6, 3, 3)`` local,
    ``ankle_pos (B, W, 2, 3)`` world metres, ``ankle_rot (B, W, 2, 3, 3)``
    world, ``swivel_cs (B, W, 4, 2)`` unnormalised (cos, sin),
    ``contact (B, W, 2)`` probabilities.  (fk): ``root_rot``,
    ``local_rot (B, W, 21, 3, 3)``, ``contact``.
    """
    y = np.asarray(y, np.float64)
    sl = output_slices(kind)
    B, W = y.shape[:2]
    Cb = C[:, None]
    s = np.asarray(stature, np.float64).reshape(-1, 1, 1)
    out = {"root_rot": Cb @ rot.sixd_to_matrix(y[..., sl["root_rot"]]),
           "contact": 1.0 / (1.0 + np.exp(-y[..., sl["contact"]]))}
    if kind == "manikin":
        out["torso_rot"] = rot.sixd_to_matrix(y[..., sl["torso_rot"]].reshape(B, W, -1, 6))
        rel = y[..., sl["ankle_pos"]].reshape(B, W, 2, 3) * s[..., None]
        out["ankle_pos"] = head_pos[:, :, None] + np.einsum("bij,bwkj->bwki", C, rel)
        out["ankle_rot"] = Cb[:, :, None] @ rot.sixd_to_matrix(y[..., sl["ankle_rot"]].reshape(B, W, 2, 6))
        out["swivel_cs"] = y[..., sl["swivel"]].reshape(B, W, 4, 2)
    else:
        out["local_rot"] = rot.sixd_to_matrix(y[..., sl["local_rot"]].reshape(B, W, -1, 6))
    return out
