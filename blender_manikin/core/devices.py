"""The device vocabulary, in one place: which trackers there are, what the UI calls them, which
joint each drives, which a solve needs, and the other names recordings use for them.

Everything that lists devices imports them from here (readers, resampling, calibration, the
network's inputs, the panel, the exporters).  No bpy.
"""
from __future__ import annotations

import re

from .skeleton import J

#: every device, in this order wherever devices are listed
DEVICES = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")
#: what every solve needs (and what the three-tracker network takes)
REQUIRED_DEVICES = ("head", "left_hand", "right_hand")
HAND_DEVICES = ("left_hand", "right_hand")
#: optional trackers (six-tracker setups: waist and both feet)
EXTRA_DEVICES = ("pelvis", "left_foot", "right_foot")

#: labels for the user interface
LABELS = {
    "head": "Head", "left_hand": "Left Hand", "right_hand": "Right Hand",
    "pelvis": "Pelvis", "left_foot": "Left Foot", "right_foot": "Right Foot",
}

#: the body joint whose pose each device's target is (after device offsets)
DEVICE_JOINT_NAMES = {"head": "head", "left_hand": "left_wrist", "right_hand": "right_wrist",
                      "pelvis": "pelvis", "left_foot": "left_ankle", "right_foot": "right_ankle"}
#: the same as joint indices of the 22-joint body
DEVICE_JOINT = {d: J[j] for d, j in DEVICE_JOINT_NAMES.items()}

#: other names recordings use (lower case, spaces and dashes as underscores)
ALIASES = {
    "hmd": "head", "headset": "head", "viewer": "head",
    "left": "left_hand", "lefthand": "left_hand", "left_controller": "left_hand",
    "right": "right_hand", "righthand": "right_hand", "right_controller": "right_hand",
    "waist": "pelvis", "hips": "pelvis", "hip": "pelvis",
    "leftfoot": "left_foot", "rightfoot": "right_foot",
    "controller_left": "left_hand", "hand_left": "left_hand", "l_hand": "left_hand", "hand_l": "left_hand",
    "l_controller": "left_hand", "leftcontroller": "left_hand", "left_hand_controller": "left_hand",
    "controller_right": "right_hand", "hand_right": "right_hand", "r_hand": "right_hand", "hand_r": "right_hand",
    "r_controller": "right_hand", "rightcontroller": "right_hand", "right_hand_controller": "right_hand",
    "foot_l": "left_foot", "foot_left": "left_foot", "l_foot": "left_foot", "tracker_left_foot": "left_foot",
    "left_foot_tracker": "left_foot", "foot_r": "right_foot", "foot_right": "right_foot", "r_foot": "right_foot",
    "tracker_right_foot": "right_foot", "right_foot_tracker": "right_foot", "tracker_waist": "pelvis",
    "waist_tracker": "pelvis", "tracker_hip": "pelvis", "camera": "head", "main_camera": "head",
    # engines' and SDKs' rig names: Meta's OVRCameraRig anchors (CenterEyeAnchor, LeftHandAnchor,
    # LeftControllerAnchor: the "_anchor" is dropped, see _SUFFIXES), Unreal's motion controllers,
    # XR cameras
    "center_eye": "head", "centereye": "head", "centre_eye": "head", "eye_center": "head",
    "vr_camera": "head", "vrcamera": "head", "xr_camera": "head", "xrcamera": "head",
    "xr_head": "head", "vr_head": "head", "xrhead": "head", "vrhead": "head",
    "motion_controller_l": "left_hand", "motioncontroller_l": "left_hand", "motion_controller_left": "left_hand",
    "motioncontrollerleft": "left_hand", "controller_l": "left_hand", "lcontroller": "left_hand",
    "lhand": "left_hand",
    "motion_controller_r": "right_hand", "motioncontroller_r": "right_hand",
    "motion_controller_right": "right_hand", "motioncontrollerright": "right_hand", "controller_r": "right_hand",
    "rcontroller": "right_hand", "rhand": "right_hand",
}

#: endings a device's name may carry and still name it (``head_pose``, ``LeftHandAnchor``,
#: ``left_grip``)
_SUFFIXES = ("_pose", "_anchor", "_transform", "_grip", "_space")


#: name parts that scene objects carry around a device's name (this add-on's own empties, tools)
OBJECT_AFFIXES = ("manikin_", "tracker_", "vr_", "xr_", "_tracker", "_empty")


def snake_name(name) -> str:
    """``LeftHand.Position.X`` -> ``left_hand_position_x``: camel case split, lower case, every run
    of other characters one ``_`` (how column names and rig names are compared)."""
    s = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", str(name).strip())
    return re.sub(r"[^a-z0-9]+", "_", s.lower()).strip("_")


def name_key(name, affixes=()) -> str:
    """An object's or column's ``name`` as a key: lower case, spaces and dashes as underscores,
    Blender's ``.001`` duplicate suffix dropped, then each prefix (``"body_"``) and suffix
    (``"_empty"``, written with its leading underscore) of ``affixes`` it has, in order."""
    key = str(name).strip().lower().replace(" ", "_").replace("-", "_")
    base, dot, num = key.rpartition(".")
    if dot and num.isdigit():
        key = base
    for a in affixes:
        if a.startswith("_") and key.endswith(a):
            key = key[:-len(a)]
        elif not a.startswith("_") and key.startswith(a):
            key = key[len(a):]
    return key


def device_of_object_name(name):
    """The device a scene object's ``name`` stands for (``"HMD"``, ``"LeftController"``,
    ``"MANIKIN_left_hand.001"``, ``"Tracker_LeftFoot"``), or ``None``: :func:`canonical_device`
    of its :func:`name_key`, else of that key without the affixes of :data:`OBJECT_AFFIXES`."""
    return canonical_device(name_key(name)) or canonical_device(name_key(name, OBJECT_AFFIXES))


def canonical_device(name):
    """The device named ``name`` (case-, space- and dash-insensitive, or an alias, also with up to
    three of the endings of :data:`_SUFFIXES`: ``left_hand_grip_pose``), or ``None``."""
    key = str(name).strip().lower().replace(" ", "_").replace("-", "_")
    keys = [key]
    for _ in range(3):                 # "left_hand_grip_pose_transform": three endings
        keys += [k[:-len(s)] for k in keys for s in _SUFFIXES if k.endswith(s) and len(k) > len(s)]
    for k in dict.fromkeys(keys):
        if k in DEVICES:
            return k
        if k in ALIASES:
            return ALIASES[k]
    return None
