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
* ``vive_wand``: HTC Vive wand raw (OpenVR) pose; grip origin (0, -0.015,
  0.097) m, rotated 5.037° about X (SteamVR's ``vr_controller_vive_1_5``
  render model; xrizer takes the wand's grip for its raw pose, but Beat
  Games' own measurement of the wand's OpenVR pose in its OpenXR grip pose,
  below, agrees with the render model to 0.8 mm and 0.04°).
* Beat Saber replays (BSOR, and XROR converted from them): the hand poses
  are the game's saber poses.  Where the game holds the saber depends on
  its version, the VR runtime and the controller's maker:

  - ``beat_saber``, ``beat_saber_touch``, ``beat_saber_vive``: game 1.29.1
    and before on SteamVR with Valve Index, Oculus/Meta Touch or HTC Vive
    controllers.  The game puts the saber at ``raw · R_x(a) · T(t)`` (Unity
    axes, rotate then translate in local space;
    ``OpenVRHelper.AdjustControllerTransform``): Valve a = -16.3°, t = (0,
    0.022, -0.01); other makers a = -4.3°, t = (0, -0.008, 0); then the
    controller's raw → grip (``index_knuckles``, ``quest_touch``,
    ``vive_wand``).
  - ``beat_saber_oculus``: game 1.29.1 and before on the Oculus runtime
    (Oculus PC app, Quest): ``OculusVRHelper`` puts the saber at
    ``node · R_x(-40°) · T(0, 0, 0.055)`` on the runtime's own controller
    pose, which sits at R_x(60°), (0, -0.01964, 0.04598) m in the OpenXR
    grip pose (Unity axes, right hand; the game's
    ``kOculusTouchOriginOffsetToLegacy``).
  - ``beat_saber_xr``, ``beat_saber_xr_touch``, ``beat_saber_xr_vive``:
    game 1.29.4 and later (OpenXR, ``UnityXRHelper``): the controller's pose
    is its OpenXR grip pose, and the game's default saber pose in it is, per
    maker (Unity axes, right hand; the left mirrored): Valve (0, 0, 0.12) m,
    R_x(-0.14°); Oculus (0.01, -0.045, 0.1) m, R_x(20°); HTC (0, 0.008,
    0.095) m, R_x(-0.04°); other makers (Pico, Windows Mixed Reality) none:
    the saber is the grip pose, ``openxr_generic``.

  A replay that records the player's own saber offsets (the BSOR
  saber-offsets block, :mod:`.io_bsor`) is solved with those instead
  (:func:`beat_saber_replay_offsets`): they include the player's in-game
  controller settings, which the presets take as zero.
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

The Beat Saber numbers are the game's (``OpenVRHelper``, ``OculusVRHelper``,
``UnityXRHelper``; as the DefaultOffsetRestorer mod reproduces them and as
published reconstructions of the game's code state them).  Checks: Beat
Games' measurement of the Index's OpenVR pose in its OpenXR grip pose
(``kValveIndexOriginOffsetToLegacy``) agrees with ``index_knuckles`` to 0.3
mm and 0.55° (``tests/test_beat_saber_offsets.py``), and on the shared real
BSOR sample (Valve Index, game 1.29.1) the ``beat_saber`` wrists stay within
arm's reach of the shoulders (estimated from the head) far more consistently
than the raw saber poses.
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


# preset -> side -> (R, p): the OpenXR grip pose in the pose the recording holds (a controller's raw
# pose, a Beat Saber saber ...), OpenXR axes, metres
_RAW_TO_GRIP = {
    "openxr_generic": {"left": (np.eye(3), np.zeros(3)), "right": (np.eye(3), np.zeros(3))},
    "vive_wand": {"left": (_rx(5.037), np.array([0.0, -0.015, 0.097])),
                  "right": (_rx(5.037), np.array([0.0, -0.015, 0.097]))},
    "quest_touch": {
        "left": (_rx(20.6), np.array([0.007, -0.00182941, 0.1019482])),
        "right": (_rx(20.6), np.array([-0.007, -0.00182941, 0.1019482])),
    },
    "index_knuckles": {
        "left": (_euler_xyz(15.392, -2.071, 0.303), np.array([0.0, -0.015, 0.13])),
        "right": (_euler_xyz(15.392, 2.071, -0.303), np.array([0.0, -0.015, 0.13])),
    },
}


def _unity_pose(quat_xyzw, pos, side="right"):
    """``(R, p)`` in OpenXR axes of a local pose given in Unity axes (quaternion x, y, z, w,
    metres); ``side="left"`` mirrors a right hand's pose for the left hand (x → -x, as the game
    mirrors its per-controller poses)."""
    x, y, z, w = (float(v) for v in quat_xyzw)
    R = quat_to_matrix(np.array([w, x, y, z]))
    p = np.asarray(pos, dtype=np.float64)
    if side == "left":
        Mx = np.diag([-1.0, 1.0, 1.0])
        R, p = Mx @ R @ Mx, Mx @ p
    return _unity_local_to_openxr(R, p)


#: the Oculus runtime's own controller pose (Beat Saber 1.29.1 and before on it) in the OpenXR grip
#: pose: Unity axes, right hand, quaternion x, y, z, w (the game's kOculusTouchOriginOffsetToLegacy)
OVR_NODE_IN_GRIP = ((0.5, 0.0, 0.0, 0.866025388), (0.0, -0.01964, 0.04598))
#: the grip pose in the controller pose the game reads (``GetNodePose``), per runtime and controller
BEAT_SABER_NODES = {
    "openxr": _RAW_TO_GRIP["openxr_generic"],
    "openvr_index": _RAW_TO_GRIP["index_knuckles"],
    "openvr_touch": _RAW_TO_GRIP["quest_touch"],
    "openvr_vive": _RAW_TO_GRIP["vive_wand"],
    "ovr": {side: _inverse(_unity_pose(*OVR_NODE_IN_GRIP, side=side)) for side in ("left", "right")},
}
#: Beat Saber 1.29.4 and later: the default saber pose in the OpenXR grip pose per controller maker
#: (Unity axes, right hand: quaternion x, y, z, w, position; ``UnityXRHelper``'s *OffsetDefaultPose)
BEAT_SABER_XR_DEFAULT = {
    "valve": ((-0.0012371338, 0.0, 0.0, 0.9999992), (0.0, 0.0, 0.12)),
    "oculus": ((0.17364818, 0.0, 0.0, 0.9848077), (0.01, -0.045, 0.1)),
    "htc": ((-0.00032738686, 0.0, 0.0, 0.99999994), (0.0, 0.008, 0.095)),
}
#: Beat Saber 1.29.1 and earlier: per preset, the game's adjustment of the controller pose it read
#: (pitch in degrees, translation in metres: Rotate then Translate, Unity axes) and which pose that
#: was (:data:`BEAT_SABER_NODES`)
BEAT_SABER_LEGACY = {"beat_saber": ((-16.3, (0.0, 0.022, -0.01)), "openvr_index"),
                     "beat_saber_touch": ((-4.3, (0.0, -0.008, 0.0)), "openvr_touch"),
                     "beat_saber_vive": ((-4.3, (0.0, -0.008, 0.0)), "openvr_vive"),
                     "beat_saber_oculus": ((-40.0, (0.0, 0.0, 0.055)), "ovr")}
#: Beat Saber 1.29.4 and later: the preset of each controller maker's default saber pose
BEAT_SABER_XR_PRESETS = {"valve": "beat_saber_xr", "oculus": "beat_saber_xr_touch", "htc": "beat_saber_xr_vive"}
#: what each controller pose of :data:`BEAT_SABER_NODES` is, for the solve summary
BEAT_SABER_NODE_NAMES = {"openxr": "the OpenXR grip pose", "openvr_index": "the Index controller's OpenVR pose",
                         "openvr_touch": "the Touch controller's OpenVR pose",
                         "openvr_vive": "the Vive wand's OpenVR pose", "ovr": "the Oculus runtime's pose"}
_RAW_TO_GRIP.update({name: {side: _compose(_inverse(_beat_saber_adjust(*adjust)), BEAT_SABER_NODES[node][side])
                            for side in ("left", "right")}
                     for name, (adjust, node) in BEAT_SABER_LEGACY.items()})
_RAW_TO_GRIP.update({name: {side: _inverse(_unity_pose(*BEAT_SABER_XR_DEFAULT[maker], side=side))
                            for side in ("left", "right")}
                     for maker, name in BEAT_SABER_XR_PRESETS.items()})

_BS = "Beat Saber replay saber poses"
_DESCRIPTIONS = {
    "none": "Device poses are the joint poses (no offset).",
    "openxr_generic": "OpenXR grip poses of any controller and an OpenXR view pose for the head.",
    "quest_touch": "Meta/Oculus Touch controllers, raw device pose as reported by SteamVR/OpenVR.",
    "index_knuckles": "Valve Index (Knuckles) controllers, raw device pose as reported by SteamVR/OpenVR.",
    "vive_wand": "HTC Vive wands, raw device pose as reported by SteamVR/OpenVR.",
    "beat_saber": f"{_BS}, game 1.29.1 or earlier on SteamVR, Valve Index controllers (the game's default offsets).",
    "beat_saber_touch": f"{_BS}, game 1.29.1 or earlier on SteamVR, Oculus/Meta Touch controllers.",
    "beat_saber_vive": f"{_BS}, game 1.29.1 or earlier on SteamVR, HTC Vive wands.",
    "beat_saber_oculus": f"{_BS}, game 1.29.1 or earlier on the Oculus runtime (Oculus PC app, Quest).",
    "beat_saber_xr": f"{_BS}, game 1.29.4 or later (OpenXR), Valve Index controllers.",
    "beat_saber_xr_touch": f"{_BS}, game 1.29.4 or later (OpenXR), Oculus/Meta Touch controllers.",
    "beat_saber_xr_vive": f"{_BS}, game 1.29.4 or later (OpenXR), HTC Vive wands.",
    "openxr_hand_tracking": "Hand tracking without controllers: OpenXR hand-tracking wrist joint poses "
                            "(XR_EXT_hand_tracking) and an OpenXR view pose for the head.",
}

PRESET_NAMES = ("none", "openxr_generic", "quest_touch", "index_knuckles", "vive_wand", "beat_saber",
                "beat_saber_touch", "beat_saber_vive", "beat_saber_oculus", "beat_saber_xr", "beat_saber_xr_touch",
                "beat_saber_xr_vive", "openxr_hand_tracking")


def _entry(R_blender, p_blender):
    q = matrix_to_quat(R_blender)
    return {"pos": [round(float(v), 7) for v in p_blender], "rot": [round(float(v), 9) for v in q]}


def _identity_entry():
    return {"pos": [0.0, 0.0, 0.0], "rot": [1.0, 0.0, 0.0, 0.0]}


def _build_preset(name):
    if name == "none":
        return {"name": name, "description": _DESCRIPTIONS[name],
                "devices": {d: _identity_entry() for d in DEVICES}}
    if name == "openxr_hand_tracking":
        return _offsets_from_grip(name, _DESCRIPTIONS[name], None)
    return _offsets_from_grip(name, _DESCRIPTIONS[name], _RAW_TO_GRIP[name])


def _offsets_from_grip(name, description, grip_in_device):
    """An offsets dict (headset view pose for the head, trackers identity) whose hands are
    controllers with the OpenXR grip pose at ``grip_in_device[side] = (R, p)`` (OpenXR axes), or,
    with ``grip_in_device`` None, OpenXR hand-tracking wrist joints."""
    R, p = _head_from_hmd()
    devices = {"head": _entry(_M @ R, _M @ p)}
    for side in ("left", "right"):
        if grip_in_device is None:
            R, p = _hand_joint_to_wrist(side)
        else:
            R, p = _compose(grip_in_device[side], _grip_to_wrist(side))
        devices[f"{side}_hand"] = _entry(_M @ R, _M @ p)
    for d in ("pelvis", "left_foot", "right_foot"):
        devices[d] = _identity_entry()
    return {"name": name, "description": description, "devices": devices}


def beat_saber_replay_offsets(saber_offsets, node="openxr", description=""):
    """Offsets of a Beat Saber replay from the saber offsets it records (BSOR's saber-offsets block).

    saber_offsets: ``{"left"|"right": (pos (3,), quat (4,))}``: each saber's handle in its
    controller's node pose as the recorder read them, Unity axes, metres, quaternion x, y, z, w.
    node: what the game's controller pose was (:data:`BEAT_SABER_NODES`): ``"openxr"`` (game
    1.29.4 and later: the OpenXR grip pose), ``"openvr_index"``, ``"openvr_touch"``,
    ``"openvr_vive"`` (earlier games on SteamVR: that controller's raw OpenVR pose) or ``"ovr"``
    (earlier games on the Oculus runtime).  Returns an offsets dict named ``beat_saber_replay``."""
    if node not in BEAT_SABER_NODES:
        raise ValueError(f"unknown controller pose {shown(node)}: expected one of {', '.join(BEAT_SABER_NODES)}")
    grip_in_saber = {}
    for side in ("left", "right"):
        pos, quat = saber_offsets[side]
        saber_in_node = _unity_pose(quat, pos)
        grip_in_saber[side] = _compose(_inverse(saber_in_node), BEAT_SABER_NODES[node][side])
    description = description or "Beat Saber replay saber poses, with the saber offsets the replay records."
    return _offsets_from_grip("beat_saber_replay", description, grip_in_saber)


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
    def fail(problem, *key):
        raise ValueError(f"{where}: {problem}")
    return _checked_offsets(offsets, fail)


def _first_not_number(v):
    """``(k,)``, the index of the first element of the list ``v`` that is not a finite number
    (the rest of a key path, for an error's line); ``()`` when every one is, or ``v`` is no list."""
    if isinstance(v, (list, tuple)):
        for k, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not np.isfinite(x):
                return (k,)
    return ()


def _checked_offsets(offsets, fail):
    """:func:`validate_offsets`'s work; ``fail(problem, *key_path)`` raises for a problem with
    the value at ``key_path`` (the keys in the JSON document, e.g. ``("devices", "head", "pos")``)."""
    if offsets is None:
        return get_preset("none")
    if isinstance(offsets, str):
        return get_preset(offsets)
    if not isinstance(offsets, dict):
        fail(f"expected a dict, got {type(offsets).__name__}")
    if "devices" in offsets:
        devs = offsets["devices"]
        name = str(offsets.get("name", "custom"))
        desc = str(offsets.get("description", ""))
        top = ("devices",)
    else:
        devs = offsets
        name, desc = "custom", ""
        top = ()
    if not isinstance(devs, dict):
        fail("'devices' must be a dict of device -> {pos, rot}", *top)
    out = {}
    for d, e in devs.items():
        if d not in DEVICES:
            fail(f"unknown device {shown(d)} (expected one of {', '.join(DEVICES)})", *top, d)
        if not isinstance(e, dict):
            fail(f"{d}: expected {{'pos': [x, y, z], 'rot': [w, x, y, z]}}", *top, d)
        try:
            pos = np.asarray(e.get("pos", [0.0, 0.0, 0.0]), dtype=np.float64)
        except (TypeError, ValueError):
            fail(f"{d}: pos/rot must be lists of numbers", *top, d, "pos", *_first_not_number(e.get("pos")))
        try:
            rot = np.asarray(e.get("rot", [1.0, 0.0, 0.0, 0.0]), dtype=np.float64)
        except (TypeError, ValueError):
            fail(f"{d}: pos/rot must be lists of numbers", *top, d, "rot", *_first_not_number(e.get("rot")))
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            fail(f"{d}: 'pos' must be 3 finite numbers (metres), got {shown(e.get('pos'))}", *top, d, "pos",
                 *_first_not_number(e.get("pos")))
        if rot.shape != (4,) or not np.all(np.isfinite(rot)) or np.linalg.norm(rot) < 1e-6:
            fail(f"{d}: 'rot' must be a non-zero quaternion [w, x, y, z], got {shown(e.get('rot'))}",
                 *top, d, "rot", *_first_not_number(e.get("rot")))
        rot = rot / np.linalg.norm(rot)
        out[d] = {"pos": [float(v) for v in pos], "rot": [float(v) for v in rot]}
    return {"name": name, "description": desc, "devices": out}


def save_offsets(path, offsets) -> None:
    """Write offsets (any form :func:`validate_offsets` accepts) as JSON."""
    data = validate_offsets(offsets)
    data = {"format": "blender_manikin.device_offsets", "version": 1, **data}
    with open(os.fspath(path), "w", encoding="utf-8", newline="\n") as fh:
        json.dump(data, fh, indent=2)
        fh.write("\n")


def load_offsets(path) -> dict:
    """Read offsets saved by :func:`save_offsets`; the ``ValueError``
    (:class:`.recording.RecordingError`) names the file, the line of the key at fault
    (:func:`.recording.json_key_line`) and the problem."""
    from .recording import RecordingError, json_key_line, load_json_file, read_text
    path = os.fspath(path)
    data = load_json_file(path)

    def fail(problem, *key):
        raise RecordingError(problem, path=path, line=json_key_line(read_text(path), key) if key else None)
    return _checked_offsets(data, fail)


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
