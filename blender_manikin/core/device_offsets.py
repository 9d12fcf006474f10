"""Device-to-joint offsets: where the body joint is relative to a tracked device.

Never imports bpy.

Convention (all in Blender axes, metres)::

    joint_rot = device_rot @ offset_rot
    joint_pos = device_pos + device_rot @ offset_pos

``offset_pos`` is expressed in the device's local frame *after* axis
conversion to Blender conventions (see :mod:`.recording`): an HMD looking
straight ahead has local -Y forward, +Z up, -X to the wearer's right.
``offset_rot`` has the joint's axes as columns, expressed in that local
frame.  Joint orientations use the body model's convention
(:mod:`.skeleton`): identity = the T-pose rest orientation, body facing -Y;
wrists: hand pointing along +X (left) / -X (right), palm down; ankles:
foot flat pointing -Y; head and pelvis facing -Y, +Z up.

The joint a device drives is given by :data:`JOINT_OF_DEVICE`.

Offsets are plain, JSON-friendly dicts so the panel can show and edit
them::

    {"name": "quest_touch", "description": "...",
     "devices": {"head": {"pos": [x, y, z], "rot": [w, x, y, z]}, ...}}

(``rot`` is a unit quaternion; a device missing from ``devices`` has no
offset).  :func:`get_preset` returns a fresh copy; :func:`save_offsets` /
:func:`load_offsets` write/read JSON.

Presets and where their numbers come from
-----------------------------------------

All values are approximate physical measurements; :mod:`.calibration`
refines the rotations from a T-pose.

*Head* (all presets except ``none``): the HMD pose is the point between the
eyes looking forward; the head joint (the head's pivot at the top of the
neck, :mod:`.skeleton` places it at 0.870 of stature, the eyes are at
~0.936) is ``HEAD_BACK`` = 8 cm behind and ``HEAD_DOWN`` = 11.5 cm below
the eyes (0.066 H for H = 1.75 m), no rotation.

*Hands*, from the OpenXR grip pose (OpenXR 1.0 spec, "Standard pose
identifiers"): the grip position is the palm centroid; -Z runs through the
tube formed by the closed non-thumb fingers from the little finger to the
thumb; +X is normal to the palm, away from the palm for the left hand and
into the palm for the right; +Y completes a right-handed frame (it points
back towards the forearm).  Anatomical assumptions (hand-anthropometry
ballpark, adult): the wrist joint centre is ``GRIP_PROXIMAL`` = 6 cm proximal
(towards the forearm) and ``GRIP_DORSAL`` = 2 cm dorsal (towards the back
of the hand) of the palm centroid, and a held handle lies obliquely across
the palm (power grip, Napier 1956), its thumb end ``GRIP_TILT_DEG`` = 15°
towards the fingers from the line perpendicular to the forearm.

Native controller poses relate to the grip pose by the ``openxr_grip``
component of SteamVR's render models (the transform of the grip pose in the
device's raw OpenVR pose, ``grip = raw · T(origin) · R(rotate_xyz)``, as
collected by the xrizer project, ``src/input/profiles/*.rs``):

* ``none``: the device poses are the joint poses.
* ``openxr_generic``: OpenXR ``grip`` poses of any controller; raw → grip
  is the identity.
* ``quest_touch``: Meta/Oculus Touch raw (OpenVR) pose; grip origin
  (±0.007, -0.00183, 0.1019) m (+x for the left hand), rotated 20.6° about X.
* ``index_knuckles``: Valve Index raw (OpenVR) pose; grip origin
  (0, -0.015, 0.13) m, XYZ rotation (15.392°, ∓2.071°, ±0.303°) (upper
  signs for the left hand).
* ``vive_wand``: HTC Vive wand raw (OpenVR) pose; identity (SteamVR's grip
  pose for the wand is its raw pose).
* ``beat_saber``: BSOR saber poses, Valve controllers on SteamVR: the game
  puts the saber at ``raw · R_x(-16.3°) · T(0, 0.022, -0.01)`` (Unity axes,
  rotate then translate in local space), then ``index_knuckles``' raw → grip.
* ``beat_saber_touch``: BSOR saber poses, Touch controllers:
  ``raw · R_x(-4.3°) · T(0, -0.008, 0)`` (Unity), then ``quest_touch``'s
  raw → grip.
* ``openxr_hand_tracking``: hands tracked without controllers, recorded as
  the ``XR_HAND_JOINT_WRIST_EXT`` joint of OpenXR hand tracking
  (``XR_EXT_hand_tracking``; Quest hand tracking through OpenXR, Ultraleap):
  the joint sits at the wrist's pivot, so no translation; its -Z runs
  towards the fingers, +Y out of the back of the hand, and +X towards the
  thumb on the left hand and towards the little finger on the right (the
  same axes as Meta's Interaction SDK hand constants, in Unity axes: distal
  +Z, dorsal +Y, left thumb side +X, right thumb side -X; so a recording in
  Unity axes, ``--axes unity``, takes this preset too).  The head is the
  headset's view pose, as for controllers.

The Beat Saber numbers are the game's built-in controller adjustments
before version 1.29.4 (``OpenVRHelper.AdjustControllerTransform``, as
reproduced by the DefaultOffsetRestorer mod), applied to the runtime's raw
controller pose; the user's own in-game controller offsets are assumed zero.
Check on real data: on the shared real BSOR sample (Valve Index, game
1.29.1) the ``beat_saber`` wrists stay within arm's reach of the shoulders
(estimated from the head) far more consistently than the raw saber poses.
Pelvis and foot trackers have no preset offset (identity): a T-pose
calibration (:mod:`.calibration`) measures their whole offset, translation and
rotation, however they are strapped on; an entry that is not the identity is
taken as typed by the user and kept.
"""
from __future__ import annotations

import copy
import json
import os

import numpy as np

from .plain import shown
from .devices import DEVICE_JOINT_NAMES, DEVICES
from .pose_result import TrackerTargets
from .rotations import (
    euler_to_matrix,
    axis_angle_rotation, matrix_to_quat, normalize, quat_mul, quat_to_matrix, quat_conj,
)

#: body-model joint driven by each device (the vocabulary's map)
JOINT_OF_DEVICE = DEVICE_JOINT_NAMES

HEAD_BACK = 0.08
HEAD_DOWN = 0.115
GRIP_PROXIMAL = 0.06
GRIP_DORSAL = 0.02
GRIP_TILT_DEG = 15.0

# OpenXR/OpenVR local axes -> Blender local axes (see recording.py)
_M = np.array([[-1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])


def _rx(deg):
    return axis_angle_rotation(np.array([1.0, 0, 0]), np.deg2rad(deg))


def _euler_xyz(ax, ay, az):
    """Intrinsic X-Y-Z rotation (glam ``EulerRot::XYZ``): ``Rx @ Ry @ Rz``, degrees."""
    return euler_to_matrix(np.deg2rad([ax, ay, az]), "XYZ")


def _grip_to_wrist(side):
    """Wrist joint relative to the OpenXR grip pose, in OpenXR grip-local axes.

    Returns ``(R, p)``: ``R`` columns are the wrist joint's (Blender-convention)
    axes, ``p`` the wrist centre, both in grip-local coordinates.
    """
    a = np.deg2rad(GRIP_TILT_DEG)
    c, s = np.cos(a), np.sin(a)
    X, Y, Z = np.eye(3)
    radial = -c * Z + s * Y          # towards the thumb side of the hand
    fingers = -s * Z - c * Y         # wrist -> knuckles
    palm = X if side == "left" else -X   # direction the palm faces
    hand_x = fingers if side == "left" else -fingers
    R = np.stack([hand_x, -radial, -palm], axis=-1)
    p = -GRIP_PROXIMAL * fingers - GRIP_DORSAL * palm
    return R, p


def _hand_joint_to_wrist(side):
    """Wrist joint relative to the OpenXR hand-tracking wrist joint, in its local axes.

    Returns ``(R, p)`` as :func:`_grip_to_wrist`: ``R`` columns are the body model's wrist axes
    (hand along +X left / -X right, palm down at rest), ``p`` = 0 (both sit at the wrist pivot).
    """
    X, Y, Z = np.eye(3)
    fingers, dorsal = -Z, Y
    radial = X if side == "left" else -X
    hand_x = fingers if side == "left" else -fingers
    return np.stack([hand_x, -radial, dorsal], axis=-1), np.zeros(3)


def _head_from_hmd():
    # Blender-convention head axes in OpenXR view-local coords: X (wearer's left) = -X_o,
    # Y (back) = +Z_o, Z (up) = +Y_o  -> the matrix M itself.
    return _M.copy(), np.array([0.0, -HEAD_DOWN, HEAD_BACK])


def _compose(a, b):
    Ra, pa = a
    Rb, pb = b
    return Ra @ Rb, pa + Ra @ pb


def _inverse(a):
    R, p = a
    return R.T, -R.T @ p


def _unity_local_to_openxr(R_u, p_u):
    P = np.diag([1.0, 1.0, -1.0])
    return P @ R_u @ P, P @ p_u


def _beat_saber_adjust(pitch_deg, translate):
    """Saber pose in the raw pose's frame (OpenXR axes): Rotate(Euler(pitch,0,0)) then Translate."""
    R_u = _rx(pitch_deg)
    p_u = R_u @ np.asarray(translate, dtype=np.float64)
    return _unity_local_to_openxr(R_u, p_u)


_RAW_TO_GRIP = {
    "openxr_generic": {"left": (np.eye(3), np.zeros(3)), "right": (np.eye(3), np.zeros(3))},
    "vive_wand": {"left": (np.eye(3), np.zeros(3)), "right": (np.eye(3), np.zeros(3))},
    "quest_touch": {
        "left": (_rx(20.6), np.array([0.007, -0.00182941, 0.1019482])),
        "right": (_rx(20.6), np.array([-0.007, -0.00182941, 0.1019482])),
    },
    "index_knuckles": {
        "left": (_euler_xyz(15.392, -2.071, 0.303), np.array([0.0, -0.015, 0.13])),
        "right": (_euler_xyz(15.392, 2.071, -0.303), np.array([0.0, -0.015, 0.13])),
    },
}
_RAW_TO_GRIP["beat_saber"] = {
    side: _compose(_inverse(_beat_saber_adjust(-16.3, (0.0, 0.022, -0.01))), _RAW_TO_GRIP["index_knuckles"][side])
    for side in ("left", "right")
}
_RAW_TO_GRIP["beat_saber_touch"] = {
    side: _compose(_inverse(_beat_saber_adjust(-4.3, (0.0, -0.008, 0.0))), _RAW_TO_GRIP["quest_touch"][side])
    for side in ("left", "right")
}

_DESCRIPTIONS = {
    "none": "Device poses are the joint poses (no offset).",
    "openxr_generic": "OpenXR grip poses of any controller and an OpenXR view pose for the head.",
    "quest_touch": "Meta/Oculus Touch controllers, raw device pose as reported by SteamVR/OpenVR.",
    "index_knuckles": "Valve Index (Knuckles) controllers, raw device pose as reported by SteamVR/OpenVR.",
    "vive_wand": "HTC Vive wands, raw device pose as reported by SteamVR/OpenVR (equals their grip pose).",
    "beat_saber": "Beat Saber replay (BSOR) saber poses, Valve controllers on SteamVR, game <= 1.29.1 "
                  "default offsets.",
    "beat_saber_touch": "Beat Saber replay (BSOR) saber poses, Touch controllers, game <= 1.29.1 default "
                        "offsets.",
    "openxr_hand_tracking": "Hand tracking without controllers: OpenXR hand-tracking wrist joint poses "
                            "(XR_EXT_hand_tracking) and an OpenXR view pose for the head.",
}

PRESET_NAMES = ("none", "openxr_generic", "quest_touch", "index_knuckles", "vive_wand", "beat_saber",
                "beat_saber_touch", "openxr_hand_tracking")


def _entry(R_blender, p_blender):
    q = matrix_to_quat(R_blender)
    return {"pos": [round(float(v), 7) for v in p_blender], "rot": [round(float(v), 9) for v in q]}


def _identity_entry():
    return {"pos": [0.0, 0.0, 0.0], "rot": [1.0, 0.0, 0.0, 0.0]}


def _build_preset(name):
    devices = {}
    if name == "none":
        for d in DEVICES:
            devices[d] = _identity_entry()
    else:
        R, p = _head_from_hmd()
        devices["head"] = _entry(_M @ R, _M @ p)
        for side in ("left", "right"):
            if name == "openxr_hand_tracking":
                R, p = _hand_joint_to_wrist(side)
            else:
                R, p = _compose(_RAW_TO_GRIP[name][side], _grip_to_wrist(side))
            devices[f"{side}_hand"] = _entry(_M @ R, _M @ p)
        for d in ("pelvis", "left_foot", "right_foot"):
            devices[d] = _identity_entry()
    return {"name": name, "description": _DESCRIPTIONS[name], "devices": devices}


_PRESETS = {name: _build_preset(name) for name in PRESET_NAMES}


def get_preset(name="openxr_generic") -> dict:
    """A fresh, editable copy of a preset (plain dict of lists, see module docstring)."""
    key = str(name).strip().lower()
    if key not in _PRESETS:
        raise ValueError(f"unknown offsets preset {shown(name)}: expected one of {', '.join(PRESET_NAMES)}")
    return copy.deepcopy(_PRESETS[key])


def validate_offsets(offsets, where="offsets") -> dict:
    """Check and normalise an offsets dict; returns a new plain dict.

    Accepts the full form (``{"name", "description", "devices": {...}}``), a
    bare ``{device: {"pos", "rot"}}`` mapping, a preset name, or None
    (= ``none``).  Quaternions are normalised.  Raises ``ValueError`` naming
    the device and field.
    """
    if offsets is None:
        return get_preset("none")
    if isinstance(offsets, str):
        return get_preset(offsets)
    if not isinstance(offsets, dict):
        raise ValueError(f"{where}: expected a dict, got {type(offsets).__name__}")
    if "devices" in offsets:
        devs = offsets["devices"]
        name = str(offsets.get("name", "custom"))
        desc = str(offsets.get("description", ""))
    else:
        devs = offsets
        name, desc = "custom", ""
    if not isinstance(devs, dict):
        raise ValueError(f"{where}: 'devices' must be a dict of device -> {{pos, rot}}")
    out = {}
    for d, e in devs.items():
        if d not in DEVICES:
            raise ValueError(f"{where}: unknown device {shown(d)} (expected one of {', '.join(DEVICES)})")
        if not isinstance(e, dict):
            raise ValueError(f"{where}: {d}: expected {{'pos': [x, y, z], 'rot': [w, x, y, z]}}")
        try:
            pos = np.asarray(e.get("pos", [0.0, 0.0, 0.0]), dtype=np.float64)
            rot = np.asarray(e.get("rot", [1.0, 0.0, 0.0, 0.0]), dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: {d}: pos/rot must be lists of numbers") from None
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ValueError(f"{where}: {d}: 'pos' must be 3 finite numbers (metres), got {shown(e.get('pos'))}")
        if rot.shape != (4,) or not np.all(np.isfinite(rot)) or np.linalg.norm(rot) < 1e-6:
            raise ValueError(f"{where}: {d}: 'rot' must be a non-zero quaternion [w, x, y, z], "
                             f"got {shown(e.get('rot'))}")
        rot = rot / np.linalg.norm(rot)
        out[d] = {"pos": [float(v) for v in pos], "rot": [float(v) for v in rot]}
    return {"name": name, "description": desc, "devices": out}


def save_offsets(path, offsets) -> None:
    """Write offsets (any form :func:`validate_offsets` accepts) as JSON."""
    data = validate_offsets(offsets)
    data = {"format": "blender_manikin.device_offsets", "version": 1, **data}
    with open(os.fspath(path), "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=2)
        fh.write("\n")


def load_offsets(path) -> dict:
    """Read offsets saved by :func:`save_offsets`; ``ValueError`` names the file and problem."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{os.path.basename(path)}, line {exc.lineno}: not valid JSON ({exc.msg})") from None
    return validate_offsets(data, where=os.path.basename(path))


def offset_arrays(offsets, device):
    """``(pos (3,), rot (3, 3))`` of ``device`` in ``offsets`` (identity if absent)."""
    devs = validate_offsets(offsets)["devices"]
    e = devs.get(device, _identity_entry())
    return np.asarray(e["pos"], dtype=np.float64), quat_to_matrix(np.asarray(e["rot"], dtype=np.float64))


def _as_pair(offset, device=None):
    if device is not None and not (isinstance(offset, dict) and ("pos" in offset or "rot" in offset)):
        p, R = offset_arrays(offset, device)
        return p, matrix_to_quat(R)
    if isinstance(offset, dict):
        return (np.asarray(offset.get("pos", [0, 0, 0]), dtype=np.float64),
                normalize(np.asarray(offset.get("rot", [1, 0, 0, 0]), dtype=np.float64)))
    p, r = offset
    p = np.asarray(p, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    if r.shape == (3, 3):
        r = matrix_to_quat(r)
    return p, normalize(r)


def apply_offsets(pos, rot, offset, device=None):
    """Device poses → joint poses, vectorised.

    pos: ``(..., 3)`` device positions (m, Blender axes).  rot: ``(..., 3, 3)``
    matrices or ``(..., 4)`` wxyz quaternions (the output uses the same form).
    offset: one device's entry ``{"pos", "rot"}`` or a
    ``(pos (3,), rot (3,3)|(4,))`` pair; or, with ``device`` given, a whole
    offsets set (any form :func:`validate_offsets` accepts, e.g. a preset
    name) from which that device's entry is taken.
    Returns ``(joint_pos, joint_rot)``.
    """
    op, oq = _as_pair(offset, device)
    pos = np.asarray(pos, dtype=np.float64)
    rot = np.asarray(rot, dtype=np.float64)
    if rot.shape[-1] == 4:
        jq = quat_mul(rot, oq)
        R = quat_to_matrix(rot)
        return pos + np.einsum("...ij,j->...i", R, op), jq
    jR = rot @ quat_to_matrix(oq)
    return pos + np.einsum("...ij,j->...i", rot, op), jR


def remove_offsets(joint_pos, joint_rot, offset, device=None):
    """Inverse of :func:`apply_offsets`: joint poses → device poses (same forms and arguments)."""
    op, oq = _as_pair(offset, device)
    joint_pos = np.asarray(joint_pos, dtype=np.float64)
    joint_rot = np.asarray(joint_rot, dtype=np.float64)
    if joint_rot.shape[-1] == 4:
        dq = quat_mul(joint_rot, quat_conj(oq))
        R = quat_to_matrix(dq)
        return joint_pos - np.einsum("...ij,j->...i", R, op), dq
    dR = joint_rot @ quat_to_matrix(oq).T
    return joint_pos - np.einsum("...ij,j->...i", dR, op), dR


def to_targets(times, pos, quat, valid, offsets=None, fps=None) -> TrackerTargets:
    """Resampled device poses → :class:`TrackerTargets` of the joints they drive.

    times: ``(T,)`` seconds (the grid of :func:`.resample.resample`).
    pos: device → ``(T, 3)`` metres; quat: device → ``(T, 4)`` wxyz;
    valid: device → ``(T,)`` bool (missing = all True).  offsets: any form
    :func:`validate_offsets` accepts (default ``none``).  fps: grid rate,
    default ``1 / median(diff(times))``.
    """
    times = np.asarray(times, dtype=np.float64)
    if fps is None:
        fps = float(1.0 / np.median(np.diff(times))) if times.shape[0] > 1 else 0.0
    devs = validate_offsets(offsets)["devices"]
    tp, tr, tv = {}, {}, {}
    for d in DEVICES:
        if d not in pos:
            continue
        e = devs.get(d, _identity_entry())
        jp, jR = apply_offsets(pos[d], quat_to_matrix(quat[d]), e)
        tp[d] = jp
        tr[d] = jR
        v = valid.get(d) if valid is not None else None
        tv[d] = np.ones(times.shape[0], dtype=bool) if v is None else np.asarray(v, dtype=bool)
    return TrackerTargets(fps=float(fps), pos=tp, rot=tr, valid=tv)
