"""Bone maps: which bone of the animator's character follows which body-model joint.

Never imports bpy.  A bone map is data (JSON-friendly)::

    {"name": "mixamo",
     "bones": {"pelvis": "mixamorig:Hips", "spine1": "mixamorig:Spine", ...},
     "twist": {"left_elbow": ["lowerarm_twist_01_l"], ...}}

* ``bones``: source joint (one of :data:`skeleton.JOINT_NAMES`) -> target bone name.  Not every
  joint needs a bone, but ``pelvis`` must have one (it carries the root motion).  A flat dict
  ``{joint: bone, ..., "name": ..., "twist": {...}}`` is accepted as well.
* ``twist``: source joint -> target twist bones of that segment, listed **from the segment's base
  to its tip**.  The retarget (:mod:`.retarget`) shares the segment's twist about its own axis
  between the mapped bone and its twist bones by where they sit along it
  (:func:`.retarget.twist_shares`: from none at the segment's base to nearly all at its tip, so
  the skin twists evenly along the limb).

Source joints without a target bone
-----------------------------------
The retarget transfers *world* orientations, so a source joint with no bone (e.g. ``spine3`` on a
rig with only two spine bones, ``left_collar`` on a rig without clavicles) is folded in as
follows: its *swing* goes to the nearest mapped ancestor, whose bone is turned to point at the next
mapped joint down the chain (the segment ``spine2 -> neck`` of the source is what the target's
chest bone spans), and everything else (its twist and the remainder of its rotation) goes to the
nearest mapped child, whose world orientation is the source's, so its local rotation is the
product of the unmapped joints' local rotations and its own.  Target bones with no source joint
(extra bones between mapped ones, e.g. ``spine_02``/``spine_04`` of the UE5 mannequin, Rigify's
second neck bone ``DEF-spine.005``) keep their rest pose relative to their parent (identity
pose-bone rotation).

Presets
-------
:data:`PRESETS` (see :func:`preset`): ``rigify`` (generated rig's ``DEF-`` bones; note the DEF bones
of a generated rig are driven by constraints, so keying them needs those constraints muted --
``rigify_fk`` maps the FK controls instead), ``rigify_fk``, ``rigify_metarig``, ``mixamo``
(``mixamorig:`` prefix), ``mixamo_plain`` (no prefix), ``ue4``, ``ue5`` (Unreal mannequins; UE5's
five spine bones get spine1/2/3 on ``spine_01/03/05``), ``vrm`` (VRoid / VRM 0.x ``J_Bip_*``),
``auto_rig_pro_fk`` (a live ARP rig's FK controls: ``c_root_master.x``, ``c_arm_fk.l``, ...),
``auto_rig_pro`` (ARP's deforming bones, as exported: ``root.x``, ``arm_stretch.l``, ..., and
the twist bones each limb segment is split with: ``c_arm_twist_offset.l`` or ``arm_twist.l``,
``forearm_twist.l``, ``thigh_twist.l``, ``leg_twist.l``),
``cc4`` (Reallusion Character Creator 3/4, ``CC_Base_*``, with each limb segment's Twist01/02
pair), ``daz_genesis8`` (Daz Genesis 8 and 3: ``hip``, ``abdomenLower``, ``lShldrBend``, ..., with
the Bend/Twist chains' Twist bones).  Twist bones, ``rigify``'s and the Unreal mannequins' too,
are fitted to the rig they are used on (:func:`fit_twist`): those it lacks, or has elsewhere than
below their segment's bone, are left out, and one the rig has between the segment's bone and
the joint above it starts the segment (ARP's upper arm and thigh): it becomes the segment's bone.
A preset chosen by name is fitted with :func:`fit_preset`, which also leaves out the joints whose
bone the rig lacks (ARP's optional third spine bone).

:func:`guess_bone_map` guesses a map for an unknown rig from bone names and hierarchy.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Optional

import numpy as np

from .skeleton import JOINT_NAMES, J

SIDES = ("left", "right")


@dataclass
class BoneMap:
    """A bone map (see module docstring).  ``bones``: joint -> bone; ``twist``: joint -> [bones]."""
    name: str = "custom"
    bones: dict = field(default_factory=dict)
    twist: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"name": self.name, "bones": dict(self.bones),
                "twist": {k: list(v) for k, v in self.twist.items()}}

    @classmethod
    def from_dict(cls, d: Mapping) -> "BoneMap":
        """From ``{"name", "bones", "twist"}`` or a flat ``{joint: bone, "name":.., "twist":..}``."""
        if isinstance(d, BoneMap):
            return BoneMap(d.name, dict(d.bones), {k: list(v) for k, v in d.twist.items()})
        if not isinstance(d, Mapping):
            raise ValueError(f"a bone map must be a dict, got {type(d).__name__}")
        d = dict(d)
        name = d.pop("name", "custom")
        twist = d.pop("twist", {}) or {}
        bones = d.pop("bones", None)
        if bones is None:
            bones = d                      # flat form: everything left is joint -> bone
        elif d:
            raise ValueError(f"bone map has unknown keys {sorted(d)} (expected name, bones, twist)")
        if not isinstance(bones, Mapping) or not isinstance(twist, Mapping):
            raise ValueError("bone map 'bones' and 'twist' must be dicts")
        tw = {}
        for k, v in twist.items():
            if isinstance(v, str):
                v = [v]
            tw[str(k)] = [str(b) for b in v]
        return cls(str(name), {str(k): v for k, v in bones.items()}, tw)

    def target_bones(self) -> list:
        """Every target bone the map names (mapped first, then twist bones)."""
        out = list(self.bones.values())
        for j in self.twist:
            out += list(self.twist[j])
        return out

    def restricted_to(self, bone_names: Iterable[str]) -> "BoneMap":
        """A copy without the bones missing from ``bone_names`` (twist bones likewise)."""
        have = set(bone_names)
        tw = {j: [b for b in v if b in have] for j, v in self.twist.items()}
        return BoneMap(self.name, {j: b for j, b in self.bones.items() if b in have},
                       {j: v for j, v in tw.items() if v})


def bone_map_rows(bmap) -> list:
    """The rows of the panel's map editor: one ``(joint, bone, twist)`` per source joint, in
    :data:`skeleton.JOINT_NAMES` order; ``bone`` is ``""`` for an unmapped joint, ``twist`` the
    list of its twist bones (base to tip, may be empty)."""
    bm = as_bone_map(bmap)
    return [(j, bm.bones.get(j, "") or "", list(bm.twist.get(j, ()))) for j in JOINT_NAMES]


def bone_map_from_rows(rows: Iterable, name: str = "edited") -> BoneMap:
    """The :class:`BoneMap` of editor rows ``(joint, bone, twist)`` (the inverse of
    :func:`bone_map_rows`): rows with an empty bone are unmapped joints; twist lists are kept even
    then, so that :func:`validate_bone_map` can say they have no bone.  Not validated."""
    bones, twist = {}, {}
    for joint, bone, tw in rows:
        bone = (bone or "").strip()
        if bone:
            bones[joint] = bone
        tw = [b for b in (tw or ()) if b]
        if tw:
            twist[joint] = tw
    return BoneMap(name or "edited", bones, twist)


def as_bone_map(bmap) -> BoneMap:
    return bmap if isinstance(bmap, BoneMap) else BoneMap.from_dict(bmap)


def validate_bone_map(bmap, target_bone_names: Optional[Iterable[str]] = None,
                      require=("pelvis",)) -> BoneMap:
    """Check a bone map and return it as a :class:`BoneMap`.

    Raises ``ValueError`` naming the problem: an unknown source joint, a bone name that is not a
    non-empty string, a target bone used twice (two joints, or a joint and a twist list), twist
    bones of a joint that has no bone, a required joint (``pelvis``) without a bone, and -- when
    ``target_bone_names`` is given -- bones the target rig does not have.
    """
    bm = as_bone_map(bmap)
    unknown = [j for j in list(bm.bones) + list(bm.twist) if j not in J]
    if unknown:
        raise ValueError(f"bone map {bm.name!r}: unknown source joint(s) {sorted(set(unknown))}; "
                         f"valid joints are {', '.join(JOINT_NAMES)}")
    bad = [j for j, b in bm.bones.items() if not isinstance(b, str) or not b]
    bad += [j for j, v in bm.twist.items() for b in v if not isinstance(b, str) or not b]
    if bad:
        raise ValueError(f"bone map {bm.name!r}: joint(s) {sorted(set(bad))} have an empty or "
                         f"non-text bone name")
    missing_req = [j for j in require if j not in bm.bones]
    if missing_req:
        raise ValueError(f"bone map {bm.name!r}: joint(s) {missing_req} must be mapped to a bone "
                         f"(the pelvis bone carries the root motion)")
    orphan = [j for j in bm.twist if j not in bm.bones]
    if orphan:
        raise ValueError(f"bone map {bm.name!r}: twist bones given for joint(s) {orphan} that have "
                         f"no bone of their own")
    seen = {}
    dups = []
    for j, b in bm.bones.items():
        if b in seen:
            dups.append(f"{b!r} (joints {seen[b]!r} and {j!r})")
        seen.setdefault(b, j)
    for j, v in bm.twist.items():
        for b in v:
            if b in seen:
                dups.append(f"{b!r} (joint {seen[b]!r} and twist of {j!r})")
            seen.setdefault(b, f"twist of {j}")
    if dups:
        raise ValueError(f"bone map {bm.name!r}: target bone(s) used more than once: {'; '.join(dups)}")
    if target_bone_names is not None:
        have = set(target_bone_names)
        miss = [f"{b!r} ({j})" for j, b in bm.bones.items() if b not in have]
        miss += [f"{b!r} (twist of {j})" for j, v in bm.twist.items() for b in v if b not in have]
        if miss:
            raise ValueError(f"bone map {bm.name!r}: the target rig has no bone(s) {', '.join(miss)}")
    return bm


def save_bone_map(path, bmap) -> None:
    """Write ``bmap`` as JSON (UTF-8, sorted in joint order) to ``path``."""
    bm = validate_bone_map(bmap)
    d = bm.to_dict()
    d["bones"] = {j: d["bones"][j] for j in JOINT_NAMES if j in d["bones"]}
    d["twist"] = {j: d["twist"][j] for j in JOINT_NAMES if j in d["twist"]}
    Path(path).write_text(json.dumps(d, indent=2, ensure_ascii=False) + "\n", encoding="utf-8", newline="\n")


def load_bone_map(path) -> BoneMap:
    """Read a bone map written by :func:`save_bone_map` (or any dict of the accepted forms)."""
    from .recording import load_json_file
    return validate_bone_map(load_json_file(path))


# --------------------------------------------------------------------------
# presets
def _sided(center: dict, sided: dict, fmt, twist: Optional[dict] = None, name="custom") -> BoneMap:
    """``sided``: part -> bone stem; ``fmt(stem, side)`` makes the bone name for side 'left'/'right'."""
    bones = dict(center)
    for side in SIDES:
        for part, stem in sided.items():
            bones[f"{side}_{part}"] = fmt(stem, side)
    tw = {}
    for side in SIDES:
        for part, stems in (twist or {}).items():
            tw[f"{side}_{part}"] = [fmt(s, side) for s in stems]
    return BoneMap(name, bones, tw)


_LIMB_PARTS = ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle", "foot")


def _rigify(prefix: str, name: str, twist: bool) -> BoneMap:
    p = prefix
    center = {"pelvis": f"{p}spine", "spine1": f"{p}spine.001", "spine2": f"{p}spine.002",
              "spine3": f"{p}spine.003", "neck": f"{p}spine.004", "head": f"{p}spine.006"}
    stems = dict(zip(_LIMB_PARTS, ("shoulder", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe")))
    tw = {"shoulder": ["upper_arm.001"], "elbow": ["forearm.001"], "hip": ["thigh.001"],
          "knee": ["shin.001"]} if twist else None

    def fmt(stem, side):
        s = "L" if side == "left" else "R"
        if stem.endswith(".001"):
            return f"{p}{stem[:-4]}.{s}.001"
        return f"{p}{stem}.{s}"
    return _sided(center, stems, fmt, tw, name)


def _rigify_fk() -> BoneMap:
    # A generated rig's FK spine pivots at the torso control: spine_fk.001 and spine_fk hang down
    # from it towards the hips (the thighs' parents), spine_fk.002 and .003 go up to the neck.  So
    # the pelvis drives the torso control, the chest the upper pair; spine1 is folded into them.
    center = {"pelvis": "torso", "spine2": "spine_fk.002", "spine3": "spine_fk.003", "neck": "neck", "head": "head"}
    stems = dict(zip(_LIMB_PARTS, ("shoulder", "upper_arm_fk", "forearm_fk", "hand_fk", "thigh_fk", "shin_fk",
                                   "foot_fk", "toe_fk")))
    return _sided(center, stems, lambda s, side: f"{s}.{'L' if side == 'left' else 'R'}", None, "rigify_fk")


def _mixamo(prefix: str, name: str) -> BoneMap:
    p = prefix
    center = {"pelvis": f"{p}Hips", "spine1": f"{p}Spine", "spine2": f"{p}Spine1", "spine3": f"{p}Spine2",
              "neck": f"{p}Neck", "head": f"{p}Head"}
    stems = dict(zip(_LIMB_PARTS, ("Shoulder", "Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot", "ToeBase")))
    return _sided(center, stems, lambda s, side: f"{p}{'Left' if side == 'left' else 'Right'}{s}", None, name)


def _ue(version: int) -> BoneMap:
    if version == 4:
        center = {"pelvis": "pelvis", "spine1": "spine_01", "spine2": "spine_02", "spine3": "spine_03",
                  "neck": "neck_01", "head": "head"}
        tw = {"shoulder": ["upperarm_twist_01"], "elbow": ["lowerarm_twist_01"],
              "hip": ["thigh_twist_01"], "knee": ["calf_twist_01"]}
    else:
        center = {"pelvis": "pelvis", "spine1": "spine_01", "spine2": "spine_03", "spine3": "spine_05",
                  "neck": "neck_01", "head": "head"}
        tw = {"shoulder": ["upperarm_twist_01", "upperarm_twist_02"],
              "elbow": ["lowerarm_twist_02", "lowerarm_twist_01"],
              "hip": ["thigh_twist_01", "thigh_twist_02"], "knee": ["calf_twist_02", "calf_twist_01"]}
    stems = dict(zip(_LIMB_PARTS, ("clavicle", "upperarm", "lowerarm", "hand", "thigh", "calf", "foot", "ball")))
    return _sided(center, stems, lambda s, side: f"{s}_{'l' if side == 'left' else 'r'}", tw, f"ue{version}")


def _vrm() -> BoneMap:
    center = {"pelvis": "J_Bip_C_Hips", "spine1": "J_Bip_C_Spine", "spine2": "J_Bip_C_Chest",
              "spine3": "J_Bip_C_UpperChest", "neck": "J_Bip_C_Neck", "head": "J_Bip_C_Head"}
    stems = dict(zip(_LIMB_PARTS, ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot",
                                   "ToeBase")))
    return _sided(center, stems, lambda s, side: f"J_Bip_{'L' if side == 'left' else 'R'}_{s}", None, "vrm")


def _arp() -> BoneMap:
    # Auto-Rig Pro's deforming bones as its export writes them: root.x is the hips; a limb's
    # deforming bones are the *_stretch ones (arm.l, forearm.l, thigh.l, leg.l are non-deforming
    # mechanism bones of the control rig, and absent from an exported one).  Exported with twist
    # bones, each limb segment is split in two along its length: the upper arm into
    # c_arm_twist_offset.l (arm_twist.l in some exports) from the shoulder half-way and
    # arm_stretch.l on to the elbow under it, the thigh into thigh_twist.l > thigh_stretch.l; the
    # forearm into forearm_stretch.l > forearm_twist.l (the hand under it), the shin into
    # leg_stretch.l > leg_twist.l (the foot under it); a second twist bone per segment is named
    # *_twist_2.  The twist bones above their segment's *_stretch bone start the segment:
    # fit_twist makes them its bone on a rig that has them, the *_stretch bone a twist bone.
    center = {"pelvis": "root.x", "spine1": "spine_01.x", "spine2": "spine_02.x", "spine3": "spine_03.x",
              "neck": "neck.x", "head": "head.x"}
    stems = dict(zip(_LIMB_PARTS, ("shoulder", "arm_stretch", "forearm_stretch", "hand", "thigh_stretch",
                                   "leg_stretch", "foot", "toes_01")))
    tw = {"shoulder": ["c_arm_twist_offset", "arm_twist", "arm_twist_2"],
          "elbow": ["forearm_twist", "forearm_twist_2"],
          "hip": ["thigh_twist", "thigh_twist_2"], "knee": ["leg_twist", "leg_twist_2"]}
    return _sided(center, stems, lambda s, side: f"{s}.{'l' if side == 'left' else 'r'}", tw, "auto_rig_pro")


def _arp_fk() -> BoneMap:
    # A live Auto-Rig Pro rig's FK controls (its deforming bones follow them through the rig's
    # mechanism): c_root_master.x moves the hips with everything above and below them; the
    # limbs follow their FK controls while the IK/FK switch (the ik_fk_switch property of
    # c_hand_ik.l and c_foot_ik.l) is 1, which the retarget keys.  spine_03 is optional in ARP
    # (two spine bones by default): a rig without it has spine3 folded into its neighbours.
    center = {"pelvis": "c_root_master.x", "spine1": "c_spine_01.x", "spine2": "c_spine_02.x",
              "spine3": "c_spine_03.x", "neck": "c_neck.x", "head": "c_head.x"}
    stems = dict(zip(_LIMB_PARTS, ("c_shoulder", "c_arm_fk", "c_forearm_fk", "c_hand_fk", "c_thigh_fk", "c_leg_fk",
                                   "c_foot_fk", "c_toes_fk")))
    return _sided(center, stems, lambda s, side: f"{s}.{'l' if side == 'left' else 'r'}", None, "auto_rig_pro_fk")


def _cc4() -> BoneMap:
    # Reallusion Character Creator 3/4 (``CC_Base_``): CC_Base_Hip carries the root motion; its
    # child CC_Base_Pelvis (the thighs' parent) is left unmapped, as is NeckTwist02.  Each limb
    # segment's skin hangs on two twist bones: Twist01 under the segment bone at its head,
    # Twist02 under Twist01 half-way along; they share the segment's twist.
    center = {"pelvis": "CC_Base_Hip", "spine1": "CC_Base_Waist", "spine2": "CC_Base_Spine01",
              "spine3": "CC_Base_Spine02", "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head"}
    stems = dict(zip(_LIMB_PARTS, ("Clavicle", "Upperarm", "Forearm", "Hand", "Thigh", "Calf", "Foot", "ToeBase")))
    twist = {part: [f"{stem}Twist01", f"{stem}Twist02"]
             for part, stem in (("shoulder", "Upperarm"), ("elbow", "Forearm"), ("hip", "Thigh"), ("knee", "Calf"))}
    return _sided(center, stems, lambda s, side: f"CC_Base_{'L' if side == 'left' else 'R'}_{s}", twist, "cc4")


def _daz_genesis8() -> BoneMap:
    # Daz Genesis 8 (and 3): hip carries the root motion; pelvis (the thighs' parent), chestUpper
    # (the collars' parent) and neckUpper are left unmapped.  The limbs are Bend/Twist chains: the
    # Twist bone sits between the Bend bone and the next segment's (lShldrBend > lShldrTwist >
    # lForearmBend), and shares the segment's twist with the Bend bone (the shins have none).
    center = {"pelvis": "hip", "spine1": "abdomenLower", "spine2": "abdomenUpper", "spine3": "chestLower",
              "neck": "neckLower", "head": "head"}
    stems = dict(zip(_LIMB_PARTS, ("Collar", "ShldrBend", "ForearmBend", "Hand", "ThighBend", "Shin", "Foot", "Toe")))
    twist = {"shoulder": ["ShldrTwist"], "elbow": ["ForearmTwist"], "hip": ["ThighTwist"]}
    return _sided(center, stems, lambda s, side: f"{'l' if side == 'left' else 'r'}{s}", twist, "daz_genesis8")


_PRESET_FACTORIES = {
    "rigify": lambda: _rigify("DEF-", "rigify", True),
    "rigify_fk": _rigify_fk,
    "rigify_metarig": lambda: _rigify("", "rigify_metarig", False),
    "mixamo": lambda: _mixamo("mixamorig:", "mixamo"),
    "mixamo_plain": lambda: _mixamo("", "mixamo_plain"),
    "ue4": lambda: _ue(4),
    "ue5": lambda: _ue(5),
    "vrm": _vrm,
    "auto_rig_pro": _arp,
    "auto_rig_pro_fk": _arp_fk,
    "cc4": _cc4,
    "daz_genesis8": _daz_genesis8,
}
#: names of the built-in presets
PRESETS = tuple(_PRESET_FACTORIES)


def preset(name: str) -> BoneMap:
    """A fresh copy of the built-in preset ``name`` (one of :data:`PRESETS`)."""
    try:
        return _PRESET_FACTORIES[name]()
    except KeyError:
        raise ValueError(f"unknown bone map preset {name!r}; presets: {', '.join(PRESETS)}") from None


# --------------------------------------------------------------------------
# guessing
@dataclass
class GuessNote:
    """One line of :func:`guess_bone_map`'s report: ``bone`` is None when nothing was found;
    ``confidence`` in [0, 1]."""
    joint: str
    bone: Optional[str]
    confidence: float
    why: str


def _strip_ns(name: str) -> str:
    return name.rsplit(":", 1)[-1].lower()


def _ancestors(parent: Mapping, name: str) -> list:
    """Bone ``name``'s ancestors, nearest first (``parent``: bone -> parent bone or None)."""
    out = []
    while parent.get(name) is not None and len(out) < 10000:
        name = parent[name]
        out.append(name)
    return out


def _along(ends: Mapping, main: str, name: str) -> float:
    """How far bone ``name``'s head lies along bone ``main`` (``ends``: bone -> (head, tail),
    armature space; 0 without positions)."""
    h, t = ends.get(main, (None, None))
    hn = ends.get(name, (None, None))[0]
    if h is None or t is None or hn is None:
        return 0.0
    h, t, hn = (np.asarray(v, np.float64) for v in (h, t, hn))
    return float(np.dot(hn - h, t - h))


def _length2(ends: Mapping, name: str) -> float:
    """Bone ``name``'s squared length (armature units; 0 without positions)."""
    h, t = ends.get(name, (None, None))
    if h is None or t is None:
        return 0.0
    d = np.asarray(t, np.float64) - np.asarray(h, np.float64)
    return float(d @ d)


def _rig_tables(bones):
    """``(parent, ends)`` of ``bones`` ``[(name, parent, head, tail)]`` (heads / tails may be
    missing or None)."""
    bones = [tuple(b) for b in bones]
    parent = {b[0]: (b[1] if len(b) > 1 else None) for b in bones}
    ends = {b[0]: (b[2], b[3]) for b in bones if len(b) >= 4}
    return parent, ends


def fit_twist(bmap, bones) -> BoneMap:
    """``bmap`` with each twist list fitted to a rig: only the twist bones the rig has below the
    segment's own bone (what the retarget requires), base to tip by where their heads lie along
    it.  For a preset on a rig of its tool (a rig exported without twist bones, or with them
    elsewhere, keeps the rest of the preset); a user's own map is validated as it is.

    A listed twist bone the rig has *above* the segment's bone instead -- between it and the
    bone of the joint above, with its head at or before the segment bone's -- starts the
    segment: it becomes the segment's bone and the segment's bone one of its twist bones (the
    topmost such bone, when there are several).  Auto-Rig Pro's export splits the upper arm and
    the thigh so (``c_arm_twist_offset.l`` from the shoulder half-way, ``arm_stretch.l`` on to
    the elbow under it); mapped to the lower bone, the segment would pivot half-way along it.

    bones: ``[(name, parent or None, head (3,), tail (3,))]`` in armature space, as
    :func:`guess_bone_map` takes them."""
    bm = as_bone_map(bmap)
    parent, ends = _rig_tables(bones)
    mapped = set(bm.bones.values())
    out = dict(bm.bones)
    twist = {}
    for j, v in bm.twist.items():
        main = bm.bones.get(j)
        if main is None or main not in parent:
            continue
        listed = [b for b in v if b in parent]
        above = []                                  # listed bones above main, nearest first
        for a in _ancestors(parent, main):
            if a in mapped:
                break
            if a in listed and _along(ends, main, a) <= 0.01 * _length2(ends, main):
                above.append(a)
        if above:
            listed = [b for b in listed if b != above[-1]] + [main]
            main = out[j] = above[-1]
        keep = [b for b in listed if main in _ancestors(parent, b)]
        keep.sort(key=lambda b: _along(ends, main, b))
        if keep:
            twist[j] = keep
    return BoneMap(bm.name, out, twist)


def fit_preset(bmap, bones, max_missing: float = 1 / 3):
    """``(BoneMap, missing)``: a preset fitted to a rig of its tool: its twist lists fitted
    (:func:`fit_twist`) and the joints whose bone the rig lacks left unmapped (folded into their
    neighbours: a rig built with fewer spine bones, without toes, ...).  ``missing``: ``[(joint,
    bone)]`` left out.  Raises ``ValueError`` naming the missing bones when the rig lacks the
    pelvis bone or more than ``max_missing`` of the preset's bones (not a rig of that tool).

    bones: as :func:`guess_bone_map` takes them."""
    bm = fit_twist(bmap, bones)
    have = {b[0] for b in bones}
    missing = [(j, b) for j, b in bm.bones.items() if b not in have]
    if missing and ("pelvis" in dict(missing) or len(missing) > max_missing * len(bm.bones)):
        raise ValueError(f"bone map {bm.name!r}: the target rig has no bone(s) "
                         f"{', '.join(f'{b!r} ({j})' for j, b in missing)}: is it a rig of that kind?")
    gone = dict(missing)
    return BoneMap(bm.name, {j: b for j, b in bm.bones.items() if j not in gone},
                   {j: v for j, v in bm.twist.items() if j not in gone}), missing


def _match_preset(bones):
    """Best preset whose bones (namespace-stripped, case-insensitive) the rig has, or None.

    bones: as :func:`guess_bone_map` takes them.  Returns ``(BoneMap with the rig's actual names,
    preset name, fraction found)``; its twist lists are fitted to the rig (:func:`fit_twist`).
    """
    bones = [tuple(b) for b in bones]
    names = [b[0] for b in bones]
    lookup = {}
    for n in names:
        lookup.setdefault(_strip_ns(n), n)
    best, best_key = None, None
    for pname in PRESETS:
        pm = preset(pname)
        found = {j: lookup[_strip_ns(b)] for j, b in pm.bones.items() if _strip_ns(b) in lookup}
        frac = len(found) / len(pm.bones)
        tw = {j: [lookup[_strip_ns(b)] for b in v if _strip_ns(b) in lookup]
              for j, v in pm.twist.items() if j in found}
        fitted = fit_twist(BoneMap(pname, found, tw), bones)
        exact = sum(b in names for b in pm.bones.values())
        # ties (ue4 / ue5 share most names, mixamo / mixamo_plain differ by a prefix): more twist
        # bones found, then more names matched exactly
        key = (frac, sum(len(v) for v in fitted.twist.values()), exact)
        if best_key is None or key > best_key:
            best_key = key
            best = (fitted, pname, frac)
    return best


_CAMEL = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+")


def _tokens(name: str):
    """Lower-case tokens of a bone name: namespace dropped, split at separators and camelCase."""
    name = name.rsplit(":", 1)[-1]
    out = []
    for part in re.split(r"[\s_.\-|/]+", name):
        out += [t.lower() for t in _CAMEL.findall(part)]
    return out


def _side(tokens):
    """'left', 'right' or None from name tokens."""
    s = set(tokens)
    left = bool(s & {"l", "left", "lft"})
    right = bool(s & {"r", "right", "rgt"})
    if left == right:
        return None
    return "left" if left else "right"


#: tokens that mark helper / control / non-body bones (never guessed as a joint)
_SKIP = {"ik", "pole", "target", "mch", "org", "wgt", "vis", "tweak", "helper", "corrective", "end", "nub",
         "tip", "eye", "jaw", "finger", "thumb", "index", "middle", "ring", "pinky", "little", "breast",
         "hair", "skirt", "cloth", "bust", "prop", "weapon", "camera", "ctrl", "fk"}


def _role(tokens):
    """Role of a bone from its tokens: (role, is_twist) with role in
    hips/spine/neck/head/collar/upperarm/forearm/hand/thigh/shin/foot/toe or None."""
    s = set(tokens)
    twist = bool(s & {"twist", "roll"})
    joined = "".join(t for t in tokens if t not in {"l", "r", "left", "right", "def", "j", "bip", "c"}
                     and not t.isdigit())
    side = _side(tokens)
    if s & _SKIP:
        return None, twist
    if "toe" in joined or "ball" in joined:
        return "toe", twist
    if "foot" in joined or "ankle" in joined:
        return "foot", twist
    if "hand" in joined or "wrist" in joined:
        return "hand", twist
    if "forearm" in joined or "lowerarm" in joined or "elbow" in joined:
        return "forearm", twist
    if "upperarm" in joined or "arm" in joined or "humerus" in joined or "shldr" in joined:
        return "upperarm", twist
    if "clavicle" in joined or "collar" in joined or ("shoulder" in joined and side):
        return "collar", twist
    if "upleg" in joined or "upperleg" in joined or "thigh" in joined or "femur" in joined \
            or ("hip" in joined and side):
        return "thigh", twist
    if "calf" in joined or "shin" in joined or "lowerleg" in joined or "knee" in joined or "leg" in joined:
        return "shin", twist
    if side:
        return None, twist
    if "hips" in joined or "pelvis" in joined or joined == "hip":
        return "hips", twist
    if "neck" in joined:
        return "neck", twist
    if "head" in joined:
        return "head", twist
    if "spine" in joined or "chest" in joined or "torso" in joined or "abdomen" in joined:
        return "spine", twist
    return None, twist


#: the limb part whose bone ends each limb segment (the next one down the chain)
_NEXT_ROLE = {"upperarm": "forearm", "forearm": "hand", "thigh": "shin", "shin": "foot"}
_ROLE_JOINT = {"collar": "collar", "upperarm": "shoulder", "forearm": "elbow", "hand": "wrist",
               "thigh": "hip", "shin": "knee", "foot": "ankle", "toe": "foot"}


def guess_bone_map(bones, min_preset_fraction: float = 0.85, use_presets: bool = True):
    """Guess a bone map for a rig.

    bones: sequence of ``(name, parent_name or None, head (3,), tail (3,))`` in armature space
    (heads/tails are only used to order candidates; may be None).  A built-in preset is tried
    first (names compared case-insensitively without a ``namespace:`` prefix, so
    ``mixamorig1:Hips`` matches ``mixamo``); it is used when at least ``min_preset_fraction`` of its
    joints are found.  Otherwise bones are classified from name tokens (hips/pelvis, spine/chest,
    neck, head, shoulder/clavicle/collar, upperarm/arm/shldr, forearm/lowerarm, hand, thigh/upleg/
    upperleg, shin/calf/leg/lowerleg, foot, toe/ball; side from ``.L/.R``, ``_l/_r``,
    ``Left/Right``, ``L_/R_``) and the hierarchy: each limb part must descend from the previous
    part of its chain, the spine bones are the chain from the hips to the neck (spine1/2/3 spread
    over however many there are), and ties go to the bone nearest the root, then to names without
    a number.  Without a bone named hips or pelvis, the pelvis is the bone where the legs and
    the spine meet (MakeHuman / MPFB's ``root``), else the root-most spine bone.  Bones named
    twist/roll below a segment's bone become its twist bones, base to tip by where their heads
    lie along it, and so do the further bones of a segment split in several bones named alike
    (MPFB's ``upperarm02.L`` under ``upperarm01.L``, above the forearm's bone).
    ``use_presets=False`` skips the presets (names and hierarchy only).

    Returns ``(BoneMap, notes)``: ``notes`` is a list of :class:`GuessNote`, one per source joint,
    for the user to confirm.
    """
    bones = [tuple(b) for b in bones]
    names = [b[0] for b in bones]
    parent, ends = _rig_tables(bones)
    hit = _match_preset(bones) if use_presets else None
    if hit is not None and hit[2] >= min_preset_fraction:
        bm, pname, frac = hit
        notes = [GuessNote(j, bm.bones.get(j), 1.0 if j in bm.bones else 0.0,
                           f"preset {pname!r}" if j in bm.bones else f"preset {pname!r} bone not in the rig")
                 for j in JOINT_NAMES]
        return bm, notes

    def depth(n):
        d = 0
        while parent.get(n) is not None and d < 10000:
            n = parent[n]
            d += 1
        return d

    def ancestors(n):
        return _ancestors(parent, n)

    info = {}
    for n in names:
        toks = _tokens(n)
        role, tw = _role(toks)
        if role is not None:
            info[n] = (role, _side(toks), tw, any(t.isdigit() for t in toks))

    def cands(role, side, twist=False):
        c = [n for n, (r, s, t, _) in info.items() if r == role and s == side and t == twist]
        return sorted(c, key=lambda n: (depth(n), info[n][3], names.index(n)))

    bmap, notes, twist = {}, {}, {}

    def pick(joint, role, side, under=None):
        c = cands(role, side)
        if under is not None:
            inside = [n for n in c if under in ancestors(n)]
            c = inside or c
        if not c:
            notes[joint] = GuessNote(joint, None, 0.0, f"no bone named like a {role}"
                                     + (f" on the {side}" if side else ""))
            return None
        b = c[0]
        conf = 0.9 if len(c) == 1 else 0.6
        why = f"name looks like {side + ' ' if side else ''}{role}"
        if len(c) > 1:
            why += f"; chosen nearest the root of {len(c)} candidates ({', '.join(c[:4])})"
        if under is not None and under not in ancestors(b):
            conf = min(conf, 0.4)
            why += f"; not under {under!r} in the hierarchy"
        bmap[joint] = b
        notes[joint] = GuessNote(joint, b, conf, why)
        return b

    hips = pick("pelvis", "hips", None)
    spines = [n for n in cands("spine", None) if hips is None or hips in ancestors(n)]
    if hips is None and spines:
        # where the legs and the spine meet (MakeHuman / MPFB's default skeleton: the hips bone is
        # "root", above spine05 and the thighs' pelvis.L / pelvis.R); else the root-most spine bone
        legs = [cands("thigh", side) for side in SIDES]
        meet = None
        if all(legs):
            common = [a for a in [spines[0]] + ancestors(spines[0]) if all(a in ancestors(c[0]) for c in legs)]
            meet = common[0] if common else None
        if meet is not None and meet != spines[0]:
            hips = meet
            spines = [n for n in spines if hips in ancestors(n)]
            notes["pelvis"] = GuessNote("pelvis", hips, 0.6, "no hips/pelvis bone: where the legs and the spine meet")
        else:
            hips = spines.pop(0)
            notes["pelvis"] = GuessNote("pelvis", hips, 0.5, "no hips/pelvis bone: the root-most spine bone")
        bmap["pelvis"] = hips
    neck = pick("neck", "neck", None, hips)
    if neck is not None:
        spines = [s for s in spines if s in ancestors(neck)]
    spines.sort(key=depth)
    n = len(spines)
    slots = {0: [], 1: ["spine2"], 2: ["spine1", "spine3"]}.get(n, ["spine1", "spine2", "spine3"])
    idx = {0: [], 1: [0], 2: [0, 1]}.get(n, [0, int(round((n - 1) / 2)), n - 1])
    for j in ("spine1", "spine2", "spine3"):
        if j in slots:
            b = spines[idx[slots.index(j)]]
            bmap[j] = b
            notes[j] = GuessNote(j, b, 0.8 if n == 3 else 0.6,
                                 f"spine bone {idx[slots.index(j)] + 1} of {n} between hips and neck")
        else:
            notes[j] = GuessNote(j, None, 0.0, f"only {n} spine bone(s): folded into its neighbours")
    pick("head", "head", None, neck or hips)
    for side in SIDES:
        prev = None
        for role in ("collar", "upperarm", "forearm", "hand"):
            b = pick(f"{side}_{_ROLE_JOINT[role]}", role, side, prev)
            prev = b or prev
        prev = hips
        for role in ("thigh", "shin", "foot", "toe"):
            b = pick(f"{side}_{_ROLE_JOINT[role]}", role, side, prev)
            prev = b or prev
        for role in ("upperarm", "forearm", "thigh", "shin"):
            j = f"{side}_{_ROLE_JOINT[role]}"
            if j in bmap:
                # only bones below the segment's bone can share its twist (the retarget
                # requires it), listed base to tip by where they sit along it
                # (and bones named like the segment below its bone and above the next one's, the
                # rest of a segment split in several bones: MPFB's upperarm01 > upperarm02)
                nxt = bmap.get(f"{side}_{_ROLE_JOINT[_NEXT_ROLE[role]]}")
                split = [t for t in cands(role, side) if t not in bmap.values() and bmap[j] in ancestors(t)
                         and (nxt is None or t in ancestors(nxt))]
                tb = [t for t in cands(role, side, twist=True) if t not in bmap.values()
                      and bmap[j] in ancestors(t)] + split
                tb.sort(key=lambda t: _along(ends, bmap[j], t))
                if tb:
                    twist[j] = tb
    ordered = [notes[j] for j in JOINT_NAMES]
    bm = BoneMap("guessed", {j: bmap[j] for j in JOINT_NAMES if j in bmap}, twist)
    return bm, ordered

