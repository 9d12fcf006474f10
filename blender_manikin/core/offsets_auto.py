"""Headset or head joint?  What the *Auto* device offsets make of a recording that does not say.

A CSV that names no offsets (no ``# offsets:`` line; every wide-layout CSV) is read as joint
poses (``none``: mocap, keyed scene objects).  Loggers in Unity, Unreal or OpenXR apps write the
headset's view pose there, 11.5 cm above and 8 cm in front of the head joint: taken for the joint,
it sizes a 1.75 m performer 1.88 m tall and hides the T-pose (its hands then stand 13 cm below
where the shoulders would be).  Two kinds of evidence decide, in this order:

1. the take's T-pose (:func:`.calibration.find_tpose`), looked for with the head samples as the
   head joint and as a headset's view pose (``openxr_generic``): when only the headset reading
   gives a T-pose, or one that fits clearly better (:data:`TPOSE_MARGIN`), and the head stands
   ahead of the hands as a headset does (:data:`HEAD_AHEAD_MIN`), the samples are a headset's.
   A standing body's own joints fit the other way round by as much (the mocap T-poses of
   ``benchmarks/standing.py`` at 1.50-2.00 m: hands on the shoulders' height read as joints,
   17 cm off read as a headset), and a T-pose with the hands drooped 14-16 cm, no T-pose read as
   joints but one read as a headset, keeps its hands beside the head joint;
2. without a T-pose that decides, the name the file gives the head (``hmd``, ``headset``,
   ``Main Camera``, ``CenterEyeAnchor``, ...; a wide CSV's column prefix, a native CSV's device
   name, a scene object's name; :func:`is_headset_name`): a name for the hardware, not the body
   part.

Either way the solve says so in its summary and how to override it.  No bpy.
"""
from __future__ import annotations

import re

import numpy as np

from . import calibration as cal
from .devices import OBJECT_AFFIXES, name_key, snake_name

#: the preset a headset's recording gets: the head as an OpenXR view pose (every preset but
#: ``none`` agrees on the head), the hands as grip poses
HEADSET_PRESET = "openxr_generic"
#: how much lower (find_tpose's cost: span ratio + 3 x height error / stature + speed) the T-pose
#: must be read as a headset's than as the head joint's before the headset reading wins; 13 cm of
#: height error on a 1.75 m performer is 0.22
TPOSE_MARGIN = 0.1
#: metres the head sample must stand ahead of the hands in the T-pose (:func:`head_ahead_of_hands`)
#: for the T-pose to say "headset": a performer drooping the hands 14 cm below the shoulders
#: makes a T-pose only read as a headset, but keeps them beside the head joint
HEAD_AHEAD_MIN = 0.04
#: head names that name the hardware, as :func:`is_headset_name` compares them (lower case, no
#: separators, an engine's ``Anchor`` / ``Pose`` / ``Transform`` ending dropped)
HEADSET_NAMES = frozenset(("hmd", "headset", "camera", "maincamera", "xrcamera", "vrcamera", "centereye",
                           "centreeye", "eyecenter", "headmounteddisplay", "xrhead", "vrhead", "viewer"))


def is_headset_name(name) -> bool:
    """Whether a head device's ``name`` (a column prefix, a device or an object's name) names a
    headset: ``HMD``, ``CenterEyeAnchor``, ``Main Camera``, ``VR_Camera.001``, ``xr_head`` (not
    ``head``, ``Head``, ``MANIKIN_head``)."""
    keys = set()
    for n in (str(name), snake_name(name)):
        for k in (name_key(n), name_key(n, OBJECT_AFFIXES)):
            k = re.sub(r"[^a-z0-9]", "", k)
            keys.add(k)
            keys.update(k[:-len(end)] for end in ("anchor", "pose", "transform") if k.endswith(end))
    return bool(keys & HEADSET_NAMES)


def head_ahead_of_hands(targets, frame):
    """Metres the head sample stands ahead of the hands' midpoint at ``frame``, along the facing
    the hands give (horizontal, square to the left-right line; :class:`~.pose_result.TrackerTargets`,
    Z up).  In a T-pose the wrists lie in the plane of the head joint: about 0 read as joints,
    about 8 cm for a headset's view pose (in front of the eyes)."""
    head = np.asarray(targets.pos["head"][frame], np.float64)
    left, right = (np.asarray(targets.pos[d][frame], np.float64) for d in ("left_hand", "right_hand"))
    forward = np.cross(left - right, [0.0, 0.0, 1.0])
    n = np.linalg.norm(forward)
    if not n > 1e-6:
        return 0.0
    return float(np.dot(head - 0.5 * (left + right), forward / n))


def headset_evidence(as_joint, as_headset, t0=0.0, head_label=None):
    """``(preset, reason)``: :data:`HEADSET_PRESET` and a plain reason when the head samples are a
    headset's, else ``(None, None)``.

    as_joint, as_headset: the take's :class:`~.pose_result.TrackerTargets` (the floor at z = 0)
    made with the offsets ``none`` and :data:`HEADSET_PRESET`; t0: the time of their frame 0
    (seconds); head_label: the name the file gives the head device (a column prefix, a device
    name), if any."""
    if not all(d in as_joint.pos for d in ("head", "left_hand", "right_hand")) or as_joint.num_frames < 2:
        return None, None
    joint = cal.find_tpose(as_joint, t0=t0)
    headset = cal.find_tpose(as_headset, t0=t0)
    ahead = head_ahead_of_hands(as_joint, headset.frame)
    if headset.plausible and (not joint.plausible or headset.cost + TPOSE_MARGIN < joint.cost) \
            and ahead > HEAD_AHEAD_MIN:
        return HEADSET_PRESET, (f"the T-pose at {headset.time - t0:.2f} s fits a headset's view pose, not the "
                                f"head joint: its hands {100 * joint.height_error:.0f} cm off shoulder height "
                                f"read as the joint's, {100 * headset.height_error:.0f} cm as a headset's, "
                                f"the head {100 * ahead:.0f} cm ahead of them")
    if joint.plausible:
        return None, None
    if head_label and is_headset_name(head_label):
        return HEADSET_PRESET, f"the head samples are named {head_label!r}, a headset"
    return None, None
