"""An animated character rig as 3D keypoints: a markerless capture's FBX (Rokoko Vision, Move.ai,
DeepMotion, Plask), an imported BVH, another rig's animation.  No bpy.

Each of the 22 body joints (:data:`.skeleton.JOINT_NAMES`) is the world position of the head of
the bone a bone map (:mod:`.bone_maps`, the retarget's maps and guess) gives it: a map names, for
each joint, the bone that turns at that joint, so the bone's head lies on it (Mixamo's
``LeftArm`` head on the shoulder, ``LeftToeBase`` on the ball of the foot, ``Head`` on the top
of the neck).  The 22 joints make a keypoint take in the ``smpl22`` layout
(:func:`.io_keypoints.keypoints_from_points`) that :mod:`.keypoint_solve` solves.

Joints the map leaves without a bone (a rig with fewer spine bones, without collars or toes):

* the limbs' joints and the head (:data:`REQUIRED`) must have a bone: without them there is
  nothing to solve (:func:`checked_map` names the missing ones);
* the pelvis, the neck, the collars and the balls of the feet are placed as
  :func:`.keypoint_layouts.body22_from_keypoints` places them for a layout of the twelve limb
  joints (the pelvis above the hips' midpoint, the neck above the shoulders', the collars where
  the rest body puts them, the feet flat ahead of the ankles, facing where the hips face);
* spine1-3 are spaced along the chain pelvis → spine1 → spine2 → spine3 → neck: each unmapped one
  linearly (by its place in the chain) between the nearest joints of the chain that have a
  bone or were placed (one spine bone, mapped to spine2 by the guess: spine1 half-way from the
  pelvis to it, spine3 half-way from it to the neck).

What was made up is said (:func:`derived_note`), for the solve's summary.

The head's, wrists' and ankles' orientations (:data:`END_JOINTS`, their twist: a hand turned
palm-up, a foot rolled, a head turned) are read from their bones too (:func:`end_orientations`):
each bone's world orientation is taken into the body's convention through the rig's rest pose,
as the retarget aligns a rig to the body (:func:`.retarget.make_plan`,
:func:`.retarget.body_world_from_bones`): the bone's rest direction (to the next mapped joint's
bone, the ankle's to the toe's; the hand's and head's own Y axis) is swung onto the body's rest
direction, so a T-pose, an A-pose or any rest with any bone rolls gives the body's rest twist.
A hand's rest twist is read from its finger bones where it has them (:func:`.retarget.rest_palm_turn`:
the knuckle line, index to little finger), so a rig resting palms-forward or with its hands
turned in an A-pose reads a palm-up hand as palm-up; without finger bones the rig is taken as
resting palms-down (palms to the thighs in an A-pose).
"""
from __future__ import annotations

import numpy as np

from . import bone_maps
from . import keypoint_layouts as kl
from . import retarget as rt
from . import skeleton as sk
from .skeleton import J, JOINT_NAMES, NUM_JOINTS

#: the joints whose orientation (twist) the keypoint solve takes (:class:`.keypoint_layouts.Body22`)
END_JOINTS = ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")

#: joints that must have a bone: the limbs' and the head
REQUIRED = tuple(f"{s}_{j}" for s in ("left", "right")
                 for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")) + ("head",)
#: the twelve limb joints as a layout: what :func:`.keypoint_layouts.body22_from_keypoints` derives
#: the trunk's joints from
_LIMBS = kl.KeypointLayout("limbs12", "the limb joints of a rig", REQUIRED[:-1])
#: the trunk's chain, pelvis to neck
_CHAIN = ("pelvis", "spine1", "spine2", "spine3", "neck")


def checked_map(bmap, bone_names, source="the armature"):
    """``bmap`` (a :class:`.bone_maps.BoneMap` or its dict) restricted to the bones the rig has
    (``bone_names``), its twist lists dropped (positions only).  Raises ``ValueError`` naming
    ``source``, the map and the :data:`REQUIRED` joints left without a bone (with the bone the map
    gave, where the rig lacks it)."""
    bm = bone_maps.as_bone_map(bmap)
    unknown = sorted(j for j in bm.bones if j not in J)
    if unknown:
        raise ValueError(f"{source}: bone map {bm.name!r} names unknown joint(s) {', '.join(unknown)}")
    have = set(bone_names)
    kept = {j: b for j, b in bm.bones.items() if isinstance(b, str) and b in have}
    missing = [j for j in REQUIRED if j not in kept]
    if missing:
        said = [f"{j} ({bm.bones[j]!r} not in the rig)" if bm.bones.get(j) else j for j in missing]
        raise ValueError(f"{source}: bone map {bm.name!r} leaves joint(s) {', '.join(said)} without a bone; "
                         f"the hips, knees, ankles, shoulders, elbows, wrists and head are needed "
                         f"(choose another map, or a map file that names them)")
    return bone_maps.BoneMap(bm.name, kept, {})


def joints_from_heads(heads):
    """The 22 joints from the bone heads of the mapped joints.

    heads: ``{joint: (T, 3)}`` world positions (metres, +Z up), at least the :data:`REQUIRED`
    joints.  Returns ``(P (T, 22, 3), derived)``: ``derived`` ``{joint: how}`` for the joints
    placed without a bone (see the module docstring), in :data:`.skeleton.JOINT_NAMES` order."""
    missing = [j for j in REQUIRED if j not in heads]
    if missing:
        raise ValueError(f"no bone head for joint(s) {', '.join(missing)}")
    T = np.asarray(heads[REQUIRED[0]]).shape[0]
    P = np.full((T, NUM_JOINTS, 3), np.nan)
    for j, h in heads.items():
        P[:, J[j]] = np.asarray(h, np.float64).reshape(T, 3)
    derived = {}
    unmapped = [j for j in JOINT_NAMES if j not in heads]
    if unmapped:
        guess = kl.body22_from_keypoints(P[:, [J[j] for j in _LIMBS.points]], _LIMBS).positions
        for j in ("pelvis", "neck", "left_collar", "right_collar", "left_foot", "right_foot"):
            if j not in heads:
                P[:, J[j]] = guess[:, J[j]]
                derived[j] = ("flat ahead of the ankle" if j.endswith("foot") else
                              "from the neck and shoulder (rest body)" if j.endswith("collar") else
                              "above the hips" if j == "pelvis" else "above the shoulders")
    have = [k for k, j in enumerate(_CHAIN) if j in heads or j in derived]        # pelvis and neck at least
    for k, j in enumerate(_CHAIN):
        if k in have:
            continue
        a = max(i for i in have if i < k)
        b = min(i for i in have if i > k)
        w = (k - a) / (b - a)
        P[:, J[j]] = (1.0 - w) * P[:, J[_CHAIN[a]]] + w * P[:, J[_CHAIN[b]]]
        derived[j] = f"along the chain {_CHAIN[a]} → {_CHAIN[b]}"
    return P, {j: derived[j] for j in JOINT_NAMES if j in derived}


def derived_note(derived) -> str:
    """One phrase for the summary: which joints had no bone and how they were placed, grouped
    (``"spine1, spine3 along the chain; left_collar, right_collar from the neck and shoulder
    (rest body)"``), or ``""``."""
    groups = {}
    for j, how in derived.items():
        key = "along the spine chain" if how.startswith("along the chain") else how
        groups.setdefault(key, []).append(j)
    return "; ".join(f"{', '.join(js)} {how}" for how, js in groups.items())


def end_orientations(target, bmap, bone_world):
    """The :data:`END_JOINTS`' world orientations, body convention, from their bones.

    target: the rig at rest (:class:`.retarget.TargetRig`); bmap: its bone map (as
    :func:`checked_map` gives it); bone_world: ``{joint: (T, 3, 3)}`` the mapped bones' world
    orientations (scale taken out), for the end joints.  Returns ``{joint: (T, 3, 3)}``
    (identity: the joint's frame in the body's T-pose rest facing -Y; :func:`.retarget.body_world_from_bones`).
    Raises ``ValueError`` (from :func:`.retarget.make_plan`) when the map does not fit the rig's
    hierarchy."""
    plan = rt.make_plan(sk.make_body(), target, bmap)
    return rt.body_world_from_bones(plan, {j: R for j, R in bone_world.items() if j in END_JOINTS})
