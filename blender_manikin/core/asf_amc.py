"""Acclaim ASF/AMC motion files (CMU mocap database, HDM05): reader and sources.

Never imports bpy.  The reader turns an ASF skeleton and an AMC motion into
the same :class:`~blender_manikin.core.bvh.BvhClip` that
:func:`~blender_manikin.core.bvh.read_bvh` returns, so
:func:`~blender_manikin.core.joint_maps.clip_to_body_motion` maps it onto the
22-joint body exactly like a BVH take (use :data:`ASF_MAP`, or
:func:`asf_clip_to_body_motion`, which also takes the units from the ASF).
Positions in the clip are in the ASF's own units and axes.

Acclaim conventions (Acclaim ASF definition v1.10; the CMU graphics lab's
AMC viewer; checked on HDM05 below)
---------------------------------------------------------------------------

* **Bones.**  Every bone has a unit ``direction`` and a ``length`` given in
  the *world rest frame* (the skeleton's zero pose), an ``axis`` (three
  angles about x, y, z and an order such as ``XYZ``) defining the bone's
  local frame ``C``, and ``dof`` (any of ``rx ry rz tx ty tz l``).  A
  child starts where its parent ends; the root's children start at the root.
* **Euler order.**  ``axis a_x a_y a_z XYZ`` means "rotate about X first,
  then Y, then Z, about fixed axes": ``C = Rz(a_z) @ Ry(a_y) @ Rx(a_x)``
  (matrices act on column vectors).  Rotation dofs are evaluated in the
  order listed (``dof rx ry rz`` gives ``M = Rz(rz) @ Ry(ry) @ Rx(rx)``);
  the same holds for the root's ``order`` (``RX RY RZ``) and ``axis``.
  Both are built with :func:`blender_manikin.core.bvh.euler_to_matrix`.
* **Forward kinematics.**  With ``W`` the world rotation of a bone relative
  to the rest pose (identity in the rest pose)::

      W_b     = W_parent @ C_b @ M_b @ C_b^-1
      start_b = end_parent  (the root position for the root's children)
      end_b   = start_b + W_b @ (length_b * direction_b)

  which is the spec's ``L = C^-1 M C B`` written for column vectors, and what
  the CMU viewer computes (its ``rot_parent_current = C_parent^-1 C_b``).
  The root: ``W_root = C_root @ M_root @ C_root^-1`` with ``C_root`` from
  ``orientation`` and ``axis``; its position is ``position`` (ASF) plus
  the AMC's ``TX TY TZ``.  CMU and HDM05 write zeros for both, so only the
  AMC values matter there.  Translation dofs ``tx ty tz`` of a bone move its
  start by ``W_parent @ C_b @ t`` and ``l`` lengthens the bone (both are
  rare; none in CMU or HDM05; ``l`` on a leaf bone does not move its End Site).
* **Units.**  ``:units length f`` means lengths are inches times ``f``
  (CMU and HDM05: ``f = 0.45``), so :attr:`AsfSkeleton.metres_per_unit` is
  ``0.0254 / f`` (0.056444 m per unit).  Angles (axis, limits, root
  orientation) use ``:units angle deg|rad``; the AMC values use the AMC's
  own ``:DEGREES`` / ``:RADIANS``, else the ASF's angle unit.

The clip (:func:`read_amc`)
---------------------------

One joint per ASF bone, placed at the bone's **start**, the root first and
then the bones depth first in ``:hierarchy`` order (parents before
children).  A joint's OFFSET is its parent bone's ``length * direction``
(zero for the root's children); a leaf bone's end (top of the head, finger
tips, toe tips) is its End Site.  Every joint frame is world-aligned in the
rest pose, as in the CMU cgspeed BVH conversion: the clip's world rotation
of joint ``b`` is ``W_b``, its local rotation ``C_b M_b C_b^-1``, written as
``Zrotation Yrotation Xrotation`` channels (the root adds
``Xposition Yposition Zposition`` first; bones without dofs have none).
So ``clip.global_transforms()`` gives the Acclaim world positions and
rotations; the Euler round trip is exact to ~1e-12.  The clip name is the
AMC file name without ``.amc``; the frame rate is not in the files (CMU and
HDM05 are 120 fps), hence ``fps``.

Problems raise :class:`AsfAmcError` (a :class:`~blender_manikin.core.bvh.BvhError`,
hence a ``ValueError``), e.g. ``HDM_bd_squat_001.amc line 57: bone 'lfemur'
expects 3 values (dof rx ry rz), got 2``.  Text is read as UTF-8, falling
back to Latin-1 (HDM05's AMC headers carry a German path in Latin-1); a byte-order mark is
dropped and UTF-16 read (:func:`~blender_manikin.core.bvh.read_bvh`'s bytes).

Reading sources
---------------

:func:`iter_asf_amc_sources` yields ``(name, source)`` pairs, sorted by name,
for every ``.amc`` (or ``.amc.gz``) in a directory (recursive) or a tar
archive (optionally gz/xz/bz2 compressed, read in one pass, members kept
zlib-compressed in memory), each paired with its performer's ASF: the ASF
whose file stem is the longest ``_``-separated prefix of the AMC stem
(HDM05 ``HDM_bd_squat1Reps_001_120.amc`` -> ``HDM_bd.asf``, CMU
``01_02.amc`` -> ``01.asf``), nearest in the folder tree when several
share a stem.  ``source()`` reads and returns the :class:`BvhClip` (the ASF
is parsed once per performer); ``source.open_asf()`` / ``source.open_amc()``
return binary file objects.

Joint map onto the 22-joint body (:data:`ASF_MAP`)
--------------------------------------------------

Built like :func:`blender_manikin.core.joint_maps._cmu` (the map of CMU's
cgspeed BVH conversion, whose joints sit at the same bone starts under other
names).  Joint ``x`` below is the start of ASF bone ``x``;
``chain``/``lerp`` as in :mod:`~blender_manikin.core.joint_maps`.

==============  =====================================  ====================================
body joint      ASF joint (start of bone)              cgspeed BVH equivalent
==============  =====================================  ====================================
pelvis          root                                   Hips
left_hip        lfemur (hip centre)                    LeftUpLeg
left_knee       ltibia                                 LeftLeg
left_ankle      lfoot                                  LeftFoot
left_foot       ltoes (ball of the foot)               LeftToeBase
spine1          chain(root, upperback, thorax,         chain(Hips, Spine, Spine1; 1/4)
                lowerneck; 1/4)
spine2          chain(...; 1/2)                        chain(...; 1/2)
spine3          chain(...; 3/4)                        chain(...; 3/4)
neck            lowerneck (neck base, end of thorax)   Neck
head            chain(lowerneck, upperneck, head;      Head (top of the neck)
                2/3): skull base, 1/3 up upperneck
left_collar     lerp(lclavicle, lhumerus; 0.4)         lerp(LeftShoulder, LeftArm; 0.4)
left_shoulder   lhumerus                               LeftArm
left_elbow      lradius                                LeftForeArm
left_wrist      lwrist                                 LeftHand
==============  =====================================  ====================================

Right side likewise (``r...``).  ``lowerback`` starts at the root, so the
spine chain runs root -> upperback -> thorax -> lowerneck along the
lowerback, upperback and thorax bones up to the neck base, where the
clavicles and the lower neck start (the cgspeed BVH puts its ``Spine1``,
``Neck`` and ``LeftShoulder`` at one point there).  ``lhipjoint``,
``lhand``, ``lfingers`` and ``lthumb`` are not mapped.

The head is the one joint not taken where the cgspeed analogy would put it
(the start of the ``head`` bone).  Measured on the five HDM05 rest poses as
fractions of the height of the ``head`` bone's end (the top of the head;
the legs confirm that scale: hip centres 0.51-0.52, knees 0.27-0.30, as in
the body model's 0.530 / 0.285): ``lowerneck`` starts at 0.82-0.85 (body
model neck: 0.830), ``upperneck`` at 0.88-0.90 and ``head`` at 0.94-0.95,
about eye level.  The head joint is the skull base, where the head sits on
the neck, 0.910 of the top of the head: it is put 2/3 of the way up the
lowerneck + upperneck polyline (:data:`HEAD_FRACTION`); with the ``head``
bone start the clips' statures came out 7-9 % higher.  (The body model
places its head joint, the top of the neck, at 0.870 of stature
(:mod:`~blender_manikin.core.skeleton`), so the clips' ``body.stature``,
head height / 0.870, is 4.6 % above the top of the head: 1.70-1.93 m.)

Orientations: pelvis (``root``), head (``head``, the head segment) and
wrists (``lwrist``, ``rwrist``, the hand segment) take the T-pose rest frame
(``rest()``); ankles (``lfoot``, ``rfoot``) take the ankle->ball bone and
the rest lateral axis; foot pitch ``"auto"``, as for cgspeed.

Axes.  +Y up, the rest pose faces **+Z**, the performer's left is **+X**
(``up="y"``, ``forward="z"``, the same conversion as the cgspeed map).
Checked on all 5 HDM05 skeletons: ``lfemur``/``ltibia`` point to +X
(0.342, -0.940, 0) and ``rfemur`` to -X, so the hips' right->left vector
(rfemur start -> lfemur start) is +X; the ``lfoot``/``rfoot`` bones (ankle
-> ball) point +Z and down (z component 0.78-0.97), ``ltoes``/``rtoes``
along +Z, and the thumbs point +Z (forward) with the arms along +-X: a
T-pose facing +Z, palms down, legs splayed 20 degrees.  ``left = up x
forward = Y x Z = +X`` agrees, so the rest pose is a right-handed T-pose
like the cgspeed one (``rest_pose_report`` passes).  The default units are
CMU's (``0.0254 / 0.45`` m); :func:`asf_joint_map` and
:func:`asf_clip_to_body_motion` take them from the ASF instead.

Checked on the HDM05 subset (all 287 clips, 5 performers;
``tests/test_asf_amc.py`` repeats the checks on a sample when the archive
is present):

* bone lengths (joint to joint) are constant over all frames to 1e-14
  units and equal the ASF lengths;
* every bone's ``C^-1 direction`` is its local -Y, so the x dof is a hinge
  perpendicular to the bone: the thigh-shank angle equals the ``tibia``
  dof to 1e-13 in every frame (with ``C^-1 M C`` it does not);
* the root's world rotation moves at most 2.4 degrees per frame even where
  its RY is within 0.1 degree of -90 and RX/RZ jump by 58 degrees between
  frames (in that dg clip the performer faces -X), which only the X-first
  Euler order gives;
* first frames: head above pelvis above knees above ankles in all 287, the
  lowest point a toe joint or toe tip;
* squats (52): while a knee bends 40-100 degrees it is 0.16-0.25 m (median
  per clip) ahead of the hip-ankle midpoint along the pelvis' facing, in
  every such frame.  (At the deepest frames of some bd/bk/dg squats the
  data itself degrades: knee dofs up to 202 degrees, feet flipped.)
* mapped with :data:`ASF_MAP`: ``body.stature`` bd 1.63-1.68, bk
  1.81-1.87, dg 1.67-1.77, mm 1.63-1.70, tr 1.73-1.81 m (top of the head
  in the rest pose: 1.59, 1.76, 1.66, 1.60, 1.66 m, with the legs splayed
  20 degrees); pelvis (ASF root) height in the first frame, median per
  performer: 0.96, 1.09, 0.96, 0.93, 1.02 m; no rest-pose warnings.
"""
from __future__ import annotations

import io
import os
import tarfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from . import joint_maps
from . import rotations as rot
from .bvh import BvhClip, BvhError, _decode, _read_bytes, euler_to_matrix  # degrees, BVH channel order
from .joint_maps import JointMap, OrientationSpec, bone, chain, joint, lerp, rest

__all__ = [
    "AsfAmcError", "AsfBone", "AsfSkeleton", "read_asf", "read_amc", "read_amc_values", "read_asf_amc",
    "AsfAmcSource", "iter_asf_amc_sources", "ASF_MAP", "asf_joint_map",
    "asf_clip_to_body_motion", "register_joint_map", "CMU_METRES_PER_UNIT", "HEAD_FRACTION",
]

#: Metres per ASF length unit for ``:units length 0.45`` (CMU, HDM05).
CMU_METRES_PER_UNIT = 0.0254 / 0.45
#: Where :data:`ASF_MAP` puts the body's head joint (where the head sits on the neck) along the
#: ASF neck lowerneck -> upperneck -> head (see the module docstring).
HEAD_FRACTION = 2.0 / 3.0

_ROT_DOFS = ("rx", "ry", "rz")
_TRANS_DOFS = ("tx", "ty", "tz")
_ALL_DOFS = _ROT_DOFS + _TRANS_DOFS + ("l",)
_ASF_KEYWORDS = (":version", ":name", ":units", ":documentation", ":root", ":bonedata",
                 ":hierarchy", ":skin")
_BONE_KEYS = ("id", "name", "direction", "length", "axis", "dof", "limits", "bodymass", "cofmass")


class AsfAmcError(BvhError):
    """A malformed ASF or AMC file.  ``str(err)`` is ``"<file> line <n>: <problem>"``."""


# --------------------------------------------------------------------------
# skeleton
@dataclass
class AsfBone:
    """One ASF bone (see the module docstring).

    ``direction``: unit ``(3,)`` in the world rest frame; ``length``: source
    units; ``axis``: ``(3,)`` degrees about x, y, z; ``axis_order``: e.g.
    ``"XYZ"`` (X applied first); ``dof``: lower-case tokens in file (and
    AMC value) order; ``limits``: one ``(lo, hi)`` per dof as written
    (angle limits in ASF angle units), may be empty; ``parent``: bone name
    (``"root"`` for the root's children); ``line``: line of its ``begin``.
    """
    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dof: Tuple[str, ...] = ()
    limits: Tuple[Tuple[float, float], ...] = ()
    id: Optional[int] = None
    parent: str = ""
    children: Tuple[str, ...] = ()
    line: int = 0

    @property
    def C(self) -> np.ndarray:
        """The bone's axis frame ``C`` (3x3, local -> world rest)."""
        return _ordered_euler(self.axis, self.axis_order)

    @property
    def vector(self) -> np.ndarray:
        """``length * direction`` (source units, world rest frame)."""
        return self.length * self.direction


@dataclass
class AsfSkeleton:
    """An ASF skeleton.

    * ``bones``: ``{name: AsfBone}`` depth first from the root in
      ``:hierarchy`` order (the root itself is not a bone).
    * ``root_order``: the root's AMC value order, lower case (``("tx",
      "ty", "tz", "rx", "ry", "rz")``); ``root_axis_order``;
      ``root_position`` (source units); ``root_orientation`` (degrees);
      ``root_children``.
    * ``mass_unit``, ``length_unit`` (the ``:units`` multipliers),
      ``angle_unit`` (``"deg"`` or ``"rad"``; every angle stored here is
      already in degrees).
    """
    name: str
    bones: Dict[str, AsfBone]
    root_order: Tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
    root_axis_order: str = "XYZ"
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    root_orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    root_children: Tuple[str, ...] = ()
    mass_unit: float = 1.0
    length_unit: float = 1.0
    angle_unit: str = "deg"
    version: str = ""
    documentation: str = ""
    source: str = ""

    @property
    def metres_per_unit(self) -> float:
        """Metres per ASF length unit: ``0.0254 / length_unit`` (lengths are inches x ``length``)."""
        return 0.0254 / self.length_unit

    @property
    def joint_names(self) -> Tuple[str, ...]:
        """``("root", bones...)``: the clip's joints (bone starts)."""
        return ("root",) + tuple(self.bones)

    @property
    def parents(self) -> np.ndarray:
        idx = {n: i for i, n in enumerate(self.joint_names)}
        return np.array([-1] + [idx[b.parent] for b in self.bones.values()], dtype=np.int64)

    @property
    def root_C(self) -> np.ndarray:
        return _ordered_euler(self.root_orientation, self.root_axis_order)

    def offsets(self) -> np.ndarray:
        """``(J, 3)`` rest offsets of the joints (parent bone's ``length * direction``)."""
        off = np.zeros((len(self.bones) + 1, 3))
        off[0] = self.root_position
        for j, b in enumerate(self.bones.values(), start=1):
            if b.parent != "root":
                off[j] = self.bones[b.parent].vector
        return off

    def rest_positions(self) -> np.ndarray:
        """``(J, 3)`` bone start positions in the rest pose (root at ``root_position``)."""
        par = self.parents
        off = self.offsets()
        p = np.zeros_like(off)
        for j in range(len(off)):
            p[j] = off[j] + (p[par[j]] if par[j] >= 0 else 0.0)
        return p

    def num_values(self, name: str) -> int:
        return len(self.root_order) if name == "root" else len(self.bones[name].dof)


def _ordered_euler(angles_deg, order: str) -> np.ndarray:
    """Rotation about fixed axes applied in ``order`` (first letter first): ``angles_deg`` are
    about x, y, z (that order); ``"XYZ"`` gives ``Rz @ Ry @ Rx``
    (:func:`.rotations.fixed_axes_euler_to_matrix`, in degrees)."""
    return rot.fixed_axes_euler_to_matrix(np.radians(np.asarray(angles_deg, dtype=np.float64)), order)


# --------------------------------------------------------------------------
# bytes and text
def _strip_suffix(name: str, suffixes) -> str:
    base = os.path.basename(str(name).replace("\\", "/"))
    low = base.lower()
    for suf in suffixes:
        if low.endswith(suf):
            return base[: -len(suf)]
    return base


_PUNCT = str.maketrans({",": " ", "(": " ", ")": " "})


def _number(tok: str, src: str, line: int, what: str) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise AsfAmcError(src, line, f"{what}: not a number: {tok!r}") from None
    return v


def _finite(tok, src, line, what):
    v = _number(tok, src, line, what)
    if not np.isfinite(v):
        raise AsfAmcError(src, line, f"{what}: not finite: {tok!r}")
    return v


# --------------------------------------------------------------------------
# ASF
def read_asf(path_or_fileobj, name: Optional[str] = None) -> AsfSkeleton:
    """Read an ASF skeleton from a path or a binary/text file object.

    ``name`` names the file in error messages (default: its file name).
    Problems raise :class:`AsfAmcError` naming the file and the line.
    """
    data, display = _read_bytes(path_or_fileobj)
    src = os.path.basename(name) if name else display
    text = _decode(data)
    lines = text.split("\n")

    section = None
    units = {"mass": 1.0, "length": 1.0, "angle": "deg"}
    version, skel_name, doc = "", "", []
    root = {"order": None, "axis": "XYZ", "position": np.zeros(3), "orientation": np.zeros(3)}
    raw_bones: List[dict] = []
    bone = None                     # dict of the bone being read
    limits_left = 0
    hierarchy: List[Tuple[int, List[str]]] = []
    in_hier = False
    seen = set()

    def order_token(tok, line, what):
        o = tok.upper()
        if len(o) != 3 or sorted(o) != ["X", "Y", "Z"]:
            raise AsfAmcError(src, line, f"{what}: rotation order must be a permutation of XYZ, got {tok!r}")
        return o

    for n, raw in enumerate(lines, start=1):
        content = raw.split("#", 1)[0].strip()
        if section == ":documentation" and not content.startswith(":"):
            doc.append(raw.rstrip("\r"))
            continue
        if not content:
            continue
        toks = content.translate(_PUNCT).split()
        if not toks:
            continue
        key = toks[0].lower()
        if key.startswith(":"):
            if key not in _ASF_KEYWORDS:
                raise AsfAmcError(src, n, f"unknown keyword {toks[0]!r}")
            if bone is not None:
                raise AsfAmcError(src, bone["line"], "bone block without 'end'")
            if in_hier:
                raise AsfAmcError(src, n, ":hierarchy block without 'end'")
            if key in seen and key != ":skin":
                raise AsfAmcError(src, n, f"{toks[0]} given twice")
            seen.add(key)
            section = key
            rest_toks = toks[1:]
            if key == ":version":
                version = " ".join(rest_toks)
            elif key == ":name":
                skel_name = " ".join(content.split()[1:])
            elif key == ":documentation" and rest_toks:
                doc.append(" ".join(rest_toks))
            elif rest_toks and key in (":units", ":root", ":bonedata", ":hierarchy"):
                raise AsfAmcError(src, n, f"unexpected {rest_toks[0]!r} after {toks[0]}")
            continue

        if section == ":units":
            if key not in ("mass", "length", "angle") or len(toks) != 2:
                raise AsfAmcError(src, n, f":units: expected 'mass|length|angle <value>', got {content!r}")
            if key == "angle":
                a = toks[1].lower()
                if a not in ("deg", "rad", "degree", "degrees", "radian", "radians"):
                    raise AsfAmcError(src, n, f":units angle must be 'deg' or 'rad', got {toks[1]!r}")
                units["angle"] = "deg" if a.startswith("deg") else "rad"
            else:
                v = _finite(toks[1], src, n, f":units {key}")
                if v <= 0:
                    raise AsfAmcError(src, n, f":units {key} must be positive, got {toks[1]!r}")
                units[key] = v
        elif section == ":root":
            if key == "order":
                order = tuple(t.lower() for t in toks[1:])
                for t in order:
                    if t not in _ROT_DOFS + _TRANS_DOFS:
                        raise AsfAmcError(src, n, f":root order: unknown token {t!r}")
                if len(set(order)) != len(order):
                    raise AsfAmcError(src, n, ":root order lists a token twice")
                root["order"] = order
            elif key == "axis":
                if len(toks) != 2:
                    raise AsfAmcError(src, n, f":root axis: expected one rotation order, got {content!r}")
                root["axis"] = order_token(toks[1], n, ":root axis")
            elif key in ("position", "orientation"):
                if len(toks) != 4:
                    raise AsfAmcError(src, n, f":root {key}: expected 3 numbers, got {len(toks) - 1}")
                root[key] = np.array([_finite(t, src, n, f":root {key}") for t in toks[1:]])
            else:
                raise AsfAmcError(src, n, f":root: unknown keyword {toks[0]!r}")
        elif section == ":bonedata":
            if key == "begin":
                if bone is not None:
                    raise AsfAmcError(src, n, f"'begin' inside the bone block of line {bone['line']}")
                bone = dict(line=n, axis=np.zeros(3), axis_order="XYZ", dof=(), limits=[], id=None)
                limits_left = 0
                continue
            if bone is None:
                raise AsfAmcError(src, n, f":bonedata: expected 'begin', got {toks[0]!r}")
            if key == "end":
                for req in ("name", "direction", "length"):
                    if req not in bone:
                        raise AsfAmcError(src, bone["line"], f"bone {bone.get('name', '?')!r} has no {req!r}")
                if bone["limits"] and len(bone["limits"]) != len(bone["dof"]):
                    raise AsfAmcError(src, n, f"bone {bone['name']!r}: {len(bone['dof'])} dofs "
                                              f"but {len(bone['limits'])} limits")
                raw_bones.append(bone)
                bone = None
                continue
            if limits_left and _is_number(toks[0]):
                if len(toks) != 2:
                    raise AsfAmcError(src, n, f"bone {bone.get('name', '?')!r}: a limit is '(min max)', "
                                              f"got {len(toks)} values")
                bone["limits"].append(tuple(_number(t, src, n, "limit") for t in toks))
                limits_left -= 1
                continue
            limits_left = 0
            if key not in _BONE_KEYS:
                raise AsfAmcError(src, n, f"unknown keyword {toks[0]!r} in a bone block")
            args = toks[1:]
            bname = bone.get("name", "?")
            if key == "id":
                bone["id"] = int(_finite(args[0], src, n, "id")) if args else None
            elif key == "name":
                if len(args) != 1:
                    raise AsfAmcError(src, n, "a bone name must be one word")
                if args[0] == "root":
                    raise AsfAmcError(src, n, "a bone may not be called 'root'")
                bone["name"] = args[0]
            elif key in ("direction", "axis"):
                want = 3 if key == "direction" else 4
                if len(args) != want:
                    raise AsfAmcError(src, n, f"bone {bname!r}: {key} needs "
                                              f"{'3 numbers' if want == 3 else '3 numbers and an order'}, "
                                              f"got {len(args)} values")
                vec = np.array([_finite(t, src, n, f"bone {bname!r} {key}") for t in args[:3]])
                if key == "direction":
                    bone["direction"] = vec
                else:
                    bone["axis"] = vec
                    bone["axis_order"] = order_token(args[3], n, f"bone {bname!r} axis")
            elif key == "length":
                if len(args) != 1:
                    raise AsfAmcError(src, n, f"bone {bname!r}: length needs one number")
                L = _finite(args[0], src, n, f"bone {bname!r} length")
                if L < 0:
                    raise AsfAmcError(src, n, f"bone {bname!r}: negative length {L}")
                bone["length"] = L
            elif key == "dof":
                dof = tuple(t.lower() for t in args)
                for t in dof:
                    if t not in _ALL_DOFS:
                        raise AsfAmcError(src, n, f"bone {bname!r}: unknown dof {t!r}")
                if len(set(dof)) != len(dof):
                    raise AsfAmcError(src, n, f"bone {bname!r}: a dof is listed twice")
                bone["dof"] = dof
            elif key == "limits":
                if not bone["dof"]:
                    raise AsfAmcError(src, n, f"bone {bname!r}: limits before dof")
                bone["limits"] = []
                limits_left = len(bone["dof"])
                if args:
                    if len(args) != 2:
                        raise AsfAmcError(src, n, f"bone {bname!r}: a limit is '(min max)', got {len(args)} values")
                    bone["limits"].append(tuple(_number(t, src, n, "limit") for t in args))
                    limits_left -= 1
            # bodymass, cofmass: ignored
        elif section == ":hierarchy":
            if key == "begin" and len(toks) == 1 and not in_hier:
                in_hier = True
                continue
            if key == "end" and len(toks) == 1 and in_hier:
                in_hier = False
                section = None
                continue
            if not in_hier:
                raise AsfAmcError(src, n, f":hierarchy: expected 'begin', got {toks[0]!r}")
            hierarchy.append((n, toks))
        elif section == ":skin":
            continue
        elif section in (":version", ":name"):
            raise AsfAmcError(src, n, f"unexpected {toks[0]!r} after {section}")
        else:
            raise AsfAmcError(src, n, f"expected a ':' keyword, got {toks[0]!r}")

    end_line = len(lines)
    if bone is not None:
        raise AsfAmcError(src, bone["line"], "bone block without 'end'")
    if in_hier:
        raise AsfAmcError(src, end_line, ":hierarchy block without 'end'")
    if ":root" not in seen:
        raise AsfAmcError(src, end_line, "no :root section")
    if ":hierarchy" not in seen and raw_bones:
        raise AsfAmcError(src, end_line, "no :hierarchy section")

    # bones by name, hierarchy
    by_name: Dict[str, dict] = {}
    for b in raw_bones:
        if b["name"] in by_name:
            raise AsfAmcError(src, b["line"], f"duplicate bone name {b['name']!r}")
        by_name[b["name"]] = b
    kids: Dict[str, List[str]] = {"root": []}
    parent_of: Dict[str, str] = {}
    for ln, toks in hierarchy:
        par = toks[0]
        if par != "root" and par not in by_name:
            raise AsfAmcError(src, ln, f":hierarchy: no bone named {par!r}")
        for c in toks[1:]:
            if c not in by_name:
                raise AsfAmcError(src, ln, f":hierarchy: no bone named {c!r}")
            if c in parent_of:
                raise AsfAmcError(src, ln, f":hierarchy: bone {c!r} has two parents "
                                           f"({parent_of[c]!r} and {par!r})")
            parent_of[c] = par
            kids.setdefault(par, []).append(c)
    order: List[str] = []
    stack = list(reversed(kids.get("root", [])))
    while stack:
        b = stack.pop()
        if b in order:          # a cycle through the root cannot happen, but be safe
            continue
        order.append(b)
        stack.extend(reversed(kids.get(b, [])))
    for b in raw_bones:
        if b["name"] not in parent_of:
            raise AsfAmcError(src, b["line"], f"bone {b['name']!r} is not in the :hierarchy")
        if b["name"] not in order:
            raise AsfAmcError(src, b["line"], f"bone {b['name']!r} is not connected to the root "
                                              "(the :hierarchy has a cycle)")

    to_deg = 1.0 if units["angle"] == "deg" else 180.0 / np.pi
    bones: Dict[str, AsfBone] = {}
    for nm in order:
        b = by_name[nm]
        d = b["direction"]
        nd = float(np.linalg.norm(d))
        if nd < 1e-12:
            if b["length"] > 0:
                raise AsfAmcError(src, b["line"], f"bone {nm!r}: zero direction with length {b['length']}")
            d = np.zeros(3)
        else:
            d = d / nd
        bones[nm] = AsfBone(
            name=nm, direction=d, length=float(b["length"]), axis=b["axis"] * to_deg,
            axis_order=b["axis_order"], dof=b["dof"], limits=tuple(b["limits"]), id=b["id"],
            parent=parent_of[nm], children=tuple(kids.get(nm, ())), line=b["line"])
    root_order = root["order"] if root["order"] is not None else ("tx", "ty", "tz", "rx", "ry", "rz")
    return AsfSkeleton(
        name=skel_name or _strip_suffix(src, (".asf.gz", ".asf")), bones=bones, root_order=root_order,
        root_axis_order=root["axis"], root_position=root["position"],
        root_orientation=root["orientation"] * to_deg, root_children=tuple(kids.get("root", ())),
        mass_unit=units["mass"], length_unit=units["length"], angle_unit=units["angle"],
        version=version, documentation="\n".join(doc).strip(), source=src)


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


# --------------------------------------------------------------------------
# AMC
_AMC_KEYWORDS = (":fully-specified", ":degrees", ":radians")


def read_amc(path_or_fileobj, skeleton: AsfSkeleton, name: Optional[str] = None,
             fps: float = 120.0) -> BvhClip:
    """Read an AMC motion for ``skeleton`` into a :class:`BvhClip`.

    ``name`` names the take (default: the file name; ``.amc`` is dropped
    for the clip name) and the file in error messages.  ``fps``: frames per
    second (not stored in AMC files).  See the module docstring for the
    clip's joints and conventions.
    """
    data, display = _read_bytes(path_or_fileobj)
    src = os.path.basename(name) if name else display
    take = _strip_suffix(name if name else display, (".amc.gz", ".amc", ".gz"))
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {fps!r}")
    text = _decode(data)
    values, first_frame, angle_unit = _parse_amc(text, skeleton, src)
    if angle_unit is None:
        angle_unit = skeleton.angle_unit
    clip = _build_clip(skeleton, values, take, 1.0 / float(fps), angle_unit, src)
    clip.source = src
    return clip


def read_amc_values(path_or_fileobj, skeleton: AsfSkeleton,
                    name: Optional[str] = None) -> Dict[str, np.ndarray]:
    """The AMC's raw values: ``{"root": (T, len(root_order)), bone: (T, len(dof))}``.

    Columns follow the ASF ``order`` / ``dof`` lists; rotation values are
    converted to degrees, translations stay in source units.  Only bones with
    dofs appear.  Errors as in :func:`read_amc`.
    """
    data, display = _read_bytes(path_or_fileobj)
    src = os.path.basename(name) if name else display
    values, _, angle_unit = _parse_amc(_decode(data), skeleton, src)
    if (angle_unit or skeleton.angle_unit) == "rad":
        out = {}
        for nm, v in values.items():
            dof = skeleton.root_order if nm == "root" else skeleton.bones[nm].dof
            rot = np.array([d in _ROT_DOFS for d in dof])
            out[nm] = np.where(rot, np.degrees(v), v)
        return out
    return {nm: v.copy() for nm, v in values.items()}


def read_asf_amc(asf, amc, name: Optional[str] = None, fps: float = 120.0,
                 asf_name: Optional[str] = None) -> BvhClip:
    """Read an ASF (path/file object, or an :class:`AsfSkeleton`) and an AMC into a clip."""
    skel = asf if isinstance(asf, AsfSkeleton) else read_asf(asf, asf_name)
    return read_amc(amc, skel, name=name, fps=fps)


def _parse_amc(text: str, skel: AsfSkeleton, src: str):
    """``({bone: (T, n) values}, first frame number, angle unit or None)``."""
    lines = text.split("\n")
    angle_unit = None
    body_start = len(lines)
    for n, raw in enumerate(lines):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        if s.startswith(":"):
            kw = s.split()[0].lower()
            if kw not in _AMC_KEYWORDS:
                raise AsfAmcError(src, n + 1, f"unknown keyword {s.split()[0]!r}")
            if kw == ":degrees":
                angle_unit = "deg"
            elif kw == ":radians":
                angle_unit = "rad"
            continue
        body_start = n
        break
    counts = {"root": len(skel.root_order)}
    counts.update({b.name: len(b.dof) for b in skel.bones.values() if b.dof})
    fast = _parse_amc_fast(lines, body_start, counts)
    if fast is not None:
        return fast[0], fast[1], angle_unit
    vals, first = _parse_amc_slow(lines, body_start, counts, skel, src)
    return vals, first, angle_unit


def _parse_amc_fast(lines, start, counts):
    """Vectorised parse when every frame lists the same bones in the same order.

    Returns ``None`` whenever anything is irregular (the slow path then
    either reads it or reports the exact line).
    """
    body = [ln for ln in lines[start:] if ln.strip()]
    if not body:
        return None
    # layout from the first frame
    if len(body[0].split()) != 1:
        return None
    layout = []
    for ln in body[1:]:
        toks = ln.split()
        if len(toks) == 1 and _is_int(toks[0]):
            break
        if toks[0] not in counts or len(toks) != 1 + counts[toks[0]] or toks[0] in (x for x, _ in layout):
            return None
        layout.append((toks[0], counts[toks[0]]))
    if {n for n, _ in layout} != set(counts):
        return None
    K = 1 + len(layout)
    if len(body) % K:
        return None
    T = len(body) // K
    # "|" marks the line ends, so a value that moved to another line is caught too
    P = 2 + sum(2 + c for _, c in layout)
    toks = (" | ".join(body) + " |").split()
    if len(toks) != T * P:
        return None
    arr = np.array(toks, dtype=object).reshape(T, P)
    fixed = [(1, "|")]
    cols = {}
    col = 2
    for nm, c in layout:
        fixed.append((col, nm))
        cols[nm] = (col + 1, col + 1 + c)
        fixed.append((col + 1 + c, "|"))
        col += 2 + c
    for c, want in fixed:
        if not np.all(arr[:, c] == want):
            return None
    fixed_cols = {c for c, _ in fixed}
    num_cols = np.array([c for c in range(1, P) if c not in fixed_cols], dtype=np.int64)
    try:
        frames = np.array(arr[:, 0].tolist(), dtype=np.int64)
        num = np.array(arr[:, num_cols].ravel().tolist(), dtype=np.float64).reshape(T, -1)
    except (ValueError, TypeError, OverflowError):
        return None
    if T and not np.all(np.diff(frames) == 1):
        return None
    if not np.all(np.isfinite(num)):
        return None
    pos = {c: i for i, c in enumerate(num_cols)}
    vals = {nm: num[:, pos[a]:pos[a] + (b - a)] for nm, (a, b) in cols.items()}
    return vals, int(frames[0])


def _is_int(tok: str) -> bool:
    try:
        int(tok)
        return True
    except ValueError:
        return False


def _parse_amc_slow(lines, start, counts, skel, src):
    frames: List[Dict[str, np.ndarray]] = []
    frame_lines: List[int] = []
    first = None
    cur = None
    for n in range(start, len(lines)):
        s = lines[n].strip()
        if not s or s.startswith("#"):
            continue
        ln = n + 1
        toks = s.split()
        if s.startswith(":"):
            raise AsfAmcError(src, ln, f"keyword {toks[0]!r} after the first frame")
        if len(toks) == 1 and _is_number(toks[0]):
            if not _is_int(toks[0]):
                raise AsfAmcError(src, ln, f"frame number must be an integer, got {toks[0]!r}")
            f = int(toks[0])
            if cur is not None:
                _check_frame(cur, frame_lines[-1], counts, src)
            if first is None:
                first = f
            elif f != first + len(frames):
                raise AsfAmcError(src, ln, f"frame number jumps from {first + len(frames) - 1} to {f}")
            cur = {}
            frames.append(cur)
            frame_lines.append(ln)
            continue
        if cur is None:
            raise AsfAmcError(src, ln, f"expected a frame number, got {toks[0]!r}")
        nm = toks[0]
        if nm not in counts:
            if nm in skel.bones:
                raise AsfAmcError(src, ln, f"bone {nm!r} has no dof in the skeleton but values here")
            raise AsfAmcError(src, ln, f"no bone named {nm!r} in the skeleton {skel.name!r}")
        if nm in cur:
            raise AsfAmcError(src, ln, f"bone {nm!r} given twice in frame {first + len(frames) - 1}")
        want = counts[nm]
        if len(toks) - 1 != want:
            dof = skel.root_order if nm == "root" else skel.bones[nm].dof
            raise AsfAmcError(src, ln, f"bone {nm!r} expects {want} values "
                                       f"({'order' if nm == 'root' else 'dof'} {' '.join(dof)}), "
                                       f"got {len(toks) - 1}")
        v = np.array([_number(t, src, ln, f"bone {nm!r} value {k + 1}") for k, t in enumerate(toks[1:])])
        if not np.all(np.isfinite(v)):
            raise AsfAmcError(src, ln, f"bone {nm!r}: non-finite value")
        cur[nm] = v
    if cur is not None:
        _check_frame(cur, frame_lines[-1], counts, src)
    T = len(frames)
    vals = {nm: (np.stack([f[nm] for f in frames]) if T else np.zeros((0, c))) for nm, c in counts.items()}
    return vals, (first if first is not None else 1)


def _check_frame(cur, line, counts, src):
    missing = [n for n in counts if n not in cur]
    if missing:
        raise AsfAmcError(src, line, f"frame lacks bone{'s' if len(missing) > 1 else ''} "
                                     f"{', '.join(repr(m) for m in missing)}")


# --------------------------------------------------------------------------
# FK -> BvhClip
_ROOT_CH = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
_POS_CH = ("Xposition", "Yposition", "Zposition")
_ROT_CH = ("Zrotation", "Yrotation", "Xrotation")


def _dof_rotation(dof, values_deg, T):
    """``M`` ``(T, 3, 3)`` from the rotation dofs in listed order (first applied first)."""
    rot = [(i, d[1].upper()) for i, d in enumerate(dof) if d in _ROT_DOFS]
    if not rot:
        return np.broadcast_to(np.eye(3), (T, 3, 3))
    idx = [i for i, _ in rot][::-1]
    axes = "".join(a for _, a in rot)[::-1]
    return euler_to_matrix(values_deg[:, idx], axes)


def _build_clip(skel: AsfSkeleton, values, take, frame_time, angle_unit, src) -> BvhClip:
    names = skel.joint_names
    J = len(names)
    T = next(iter(values.values())).shape[0] if values else 0
    deg = 1.0 if angle_unit == "deg" else 180.0 / np.pi
    parents = skel.parents
    offsets = skel.offsets()
    local = np.empty((T, J, 3, 3))
    trans = np.broadcast_to(offsets, (T, J, 3)).copy()
    moving = np.zeros(J, bool)

    # root
    rv = values["root"]
    order = skel.root_order
    Cr = skel.root_C
    rot_vals = np.where([d in _ROT_DOFS for d in order], rv * deg, rv)
    local[:, 0] = Cr @ _dof_rotation(order, rot_vals, T) @ Cr.T
    for k, d in enumerate(order):
        if d in _TRANS_DOFS:
            trans[:, 0, _TRANS_DOFS.index(d)] = skel.root_position[_TRANS_DOFS.index(d)] + rv[:, k]
    has_rot = [True]
    lengths = {b.name: np.full(T, b.length) for b in skel.bones.values()}
    for j, b in enumerate(skel.bones.values(), start=1):
        if b.dof:
            v = values[b.name]
            C = b.C     # computed once per bone
            isrot = np.array([d in _ROT_DOFS for d in b.dof])
            local[:, j] = C @ _dof_rotation(b.dof, np.where(isrot, v * deg, v), T) @ C.T
            t = np.zeros((T, 3))
            for k, d in enumerate(b.dof):
                if d in _TRANS_DOFS:
                    t[:, _TRANS_DOFS.index(d)] = v[:, k]
                    moving[j] = True
                elif d == "l":
                    lengths[b.name] = b.length + v[:, k]
            if moving[j]:
                trans[:, j] += t @ C.T
            has_rot.append(bool(isrot.any()))
        else:
            local[:, j] = np.eye(3)
            has_rot.append(False)
    # 'l' dofs move the children of the stretched bone
    for j, b in enumerate(skel.bones.values(), start=1):
        p = b.parent
        if p != "root" and "l" in skel.bones[p].dof:
            bp = skel.bones[p]
            trans[:, j] += (lengths[p] - bp.length)[:, None] * bp.direction
            moving[j] = True
    channels = [_ROOT_CH]
    for j in range(1, J):
        ch = (_POS_CH if moving[j] else ()) + (_ROT_CH if has_rot[j] else ())
        channels.append(ch)
    end_sites = np.full((J, 3), np.nan)
    for j, b in enumerate(skel.bones.values(), start=1):
        if not b.children:
            end_sites[j] = b.vector
    return BvhClip.from_local_transforms(take, names, parents, offsets, channels, local,
                                         translations=trans, frame_time=frame_time,
                                         end_sites=end_sites)


# --------------------------------------------------------------------------
# joint map
def _asf_map(unit_scale: float = CMU_METRES_PER_UNIT, name: str = "cmu_asf") -> JointMap:
    spine = ("root", "upperback", "thorax", "lowerneck")
    pos = {
        "pelvis": joint("root"),
        "spine1": chain(spine, 0.25), "spine2": chain(spine, 0.5), "spine3": chain(spine, 0.75),
        "neck": joint("lowerneck"), "head": chain(("lowerneck", "upperneck", "head"), HEAD_FRACTION),
    }
    for side, s in (("left", "l"), ("right", "r")):
        pos[f"{side}_hip"] = joint(f"{s}femur")
        pos[f"{side}_knee"] = joint(f"{s}tibia")
        pos[f"{side}_ankle"] = joint(f"{s}foot")
        pos[f"{side}_foot"] = joint(f"{s}toes")
        pos[f"{side}_collar"] = lerp(f"{s}clavicle", f"{s}humerus", 0.4)
        pos[f"{side}_shoulder"] = joint(f"{s}humerus")
        pos[f"{side}_elbow"] = joint(f"{s}radius")
        pos[f"{side}_wrist"] = joint(f"{s}wrist")
    ori = {
        "pelvis": OrientationSpec("root", rest(), rest()),
        "head": OrientationSpec("head", rest(), rest()),
        "left_wrist": OrientationSpec("lwrist", rest(), rest()),
        "right_wrist": OrientationSpec("rwrist", rest(), rest()),
        "left_ankle": OrientationSpec("lfoot", bone("lfoot", "ltoes"), rest()),
        "right_ankle": OrientationSpec("rfoot", bone("rfoot", "rtoes"), rest()),
    }
    return JointMap(name, pos, ori, unit_scale=float(unit_scale), up="y", forward="z",
                    rest_is_tpose=True, foot_pitch="auto",
                    description="Acclaim ASF/AMC with CMU bone names (CMU mocap, HDM05; "
                                "1/0.45 inch units, Y-up, faces +Z)")


#: Joint map for ASF/AMC clips with CMU bone names (CMU mocap, HDM05).
ASF_MAP = _asf_map()


def asf_joint_map(skeleton: Optional[AsfSkeleton] = None) -> JointMap:
    """:data:`ASF_MAP` with ``unit_scale`` from ``skeleton.metres_per_unit`` (when given)."""
    if skeleton is None:
        return ASF_MAP
    return replace(ASF_MAP, unit_scale=float(skeleton.metres_per_unit))


def asf_clip_to_body_motion(clip: BvhClip, skeleton: Optional[AsfSkeleton] = None, **kwargs):
    """``joint_maps.clip_to_body_motion(clip, asf_joint_map(skeleton), **kwargs)``."""
    return joint_maps.clip_to_body_motion(clip, asf_joint_map(skeleton), **kwargs)


def register_joint_map() -> JointMap:
    """Add :data:`ASF_MAP` to ``joint_maps.JOINT_MAPS`` (as ``"cmu_asf"``), opt-in.

    Afterwards ``clip_to_body_motion(clip)`` detects ASF clips by their bone
    names and ``get_joint_map("cmu_asf")`` finds the map.  Not done on
    import so that importing this module changes nothing elsewhere.
    """
    joint_maps.JOINT_MAPS[ASF_MAP.name] = ASF_MAP
    return ASF_MAP


# --------------------------------------------------------------------------
# sources
Opener = Callable[[], io.IOBase]
_AMC_SUFFIXES = (".amc.gz", ".amc")
_ASF_SUFFIXES = (".asf.gz", ".asf")
_ARCHIVE_SUFFIXES = (".tar", ".tar.gz", ".tgz", ".tar.xz", ".txz", ".tar.bz2", ".tbz2")


@dataclass
class AsfAmcSource:
    """One AMC take and its performer's ASF (see :func:`iter_asf_amc_sources`).

    Calling it returns the :class:`BvhClip`; ``open_asf()`` / ``open_amc()``
    return fresh binary file objects.  ``asf_name`` is ``None`` when no ASF
    was found; calling then raises :class:`AsfAmcError`.
    """
    name: str
    amc_name: str
    asf_name: Optional[str]
    open_amc: Opener
    open_asf: Optional[Opener]
    fps: float = 120.0
    _cache: Optional[dict] = field(default=None, repr=False, compare=False)

    def skeleton(self) -> AsfSkeleton:
        if self.open_asf is None:
            raise AsfAmcError(os.path.basename(self.amc_name), None,
                              "no ASF skeleton found for this AMC (expected e.g. "
                              f"{_asf_guess(self.amc_name)!r} next to it or in an asf/ folder)")
        cache = self._cache if self._cache is not None else {}
        sk = cache.get(self.asf_name)
        if sk is None:
            with self.open_asf() as f:
                sk = read_asf(f, self.asf_name)
            cache[self.asf_name] = sk
        return sk

    def read(self, fps: Optional[float] = None) -> BvhClip:
        skel = self.skeleton()
        with self.open_amc() as f:
            return read_amc(f, skel, name=self.amc_name, fps=self.fps if fps is None else fps)

    __call__ = read


def _asf_guess(amc_name: str) -> str:
    stem = _strip_suffix(amc_name, _AMC_SUFFIXES)
    return stem.split("_")[0] + ".asf" if "_" in stem else stem + ".asf"


def _lower_suffix(name: str, suffixes) -> bool:
    low = name.lower()
    return any(low.endswith(s) for s in suffixes)


def _pair(amcs: Sequence[str], asfs: Sequence[str]) -> Dict[str, Optional[str]]:
    """AMC path -> ASF path (longest stem prefix, nearest folder)."""
    by_stem: Dict[str, List[str]] = {}
    for a in asfs:
        by_stem.setdefault(_strip_suffix(a, _ASF_SUFFIXES).lower(), []).append(a)
    out = {}
    for m in amcs:
        parts = _strip_suffix(m, _AMC_SUFFIXES).lower().split("_")
        found = None
        for k in range(len(parts), 0, -1):
            cands = by_stem.get("_".join(parts[:k]))
            if cands:
                mdir = m.split("/")[:-1]

                def shared(a):
                    adir = a.split("/")[:-1]
                    n = 0
                    while n < min(len(adir), len(mdir)) and adir[n] == mdir[n]:
                        n += 1
                    return (n, -len(adir), a)

                found = max(cands, key=shared)
                break
        if found is None:
            # a single ASF in the AMC's folder or its asf/ sibling
            mdir = "/".join(m.split("/")[:-1])
            near = [a for a in asfs if "/".join(a.split("/")[:-1]) == mdir
                    or "/".join(a.split("/")[:-2]) == "/".join(m.split("/")[:-2])]
            if len(near) == 1:
                found = near[0]
        out[m] = found
    return out


def iter_asf_amc_sources(path, fps: float = 120.0) -> Iterator[Tuple[str, AsfAmcSource]]:
    """Yield ``(name, source)`` for every ``.amc`` / ``.amc.gz`` under ``path``.

    ``path`` is a directory (recursive; names relative to it,
    ``/``-separated), a tar archive (gz/xz/bz2 or plain; names are member
    paths without a leading ``./``), or a single ``.amc`` file (its ASF is
    looked for in its folder and in a sibling ``asf/`` folder).  Names are
    sorted.  ``source()`` returns the clip (see :class:`AsfAmcSource`; the
    ASF is parsed once per performer).  An AMC without an ASF is still
    yielded; reading it raises :class:`AsfAmcError`.
    """
    p = Path(path)
    cache: dict = {}
    if p.is_dir():
        files = {f.relative_to(p).as_posix(): f for f in p.rglob("*") if f.is_file()}
        amcs = sorted(n for n in files if _lower_suffix(n, _AMC_SUFFIXES))
        asfs = sorted(n for n in files if _lower_suffix(n, _ASF_SUFFIXES))
        pairs = _pair(amcs, asfs)
        for m in amcs:
            a = pairs[m]
            yield m, AsfAmcSource(m, m, a, _file_opener(files[m]),
                                  _file_opener(files[a]) if a else None, fps, cache)
        return
    if not p.exists():
        raise FileNotFoundError(f"no such file or directory: {p}")
    if _lower_suffix(p.name, _ARCHIVE_SUFFIXES):
        blobs: Dict[str, bytes] = {}
        with tarfile.open(p, mode="r|*") as tf:
            for member in tf:
                if not member.isfile():
                    continue
                nm = member.name
                while nm.startswith("./"):
                    nm = nm[2:]
                if not _lower_suffix(nm, _AMC_SUFFIXES + _ASF_SUFFIXES):
                    continue
                f = tf.extractfile(member)
                blobs[nm] = zlib.compress(f.read() if f is not None else b"", 1)
        amcs = sorted(n for n in blobs if _lower_suffix(n, _AMC_SUFFIXES))
        asfs = sorted(n for n in blobs if _lower_suffix(n, _ASF_SUFFIXES))
        pairs = _pair(amcs, asfs)
        for m in amcs:
            a = pairs[m]
            yield m, AsfAmcSource(m, m, a, _blob_opener(blobs[m]),
                                  _blob_opener(blobs[a]) if a else None, fps, cache)
        return
    if _lower_suffix(p.name, _AMC_SUFFIXES):
        cands: Dict[str, Path] = {}
        for d, rel in ((p.parent, "amc"), (p.parent.parent / "asf", "asf")):
            if d.is_dir():
                for f in sorted(d.iterdir()):
                    if f.is_file() and _lower_suffix(f.name, _ASF_SUFFIXES):
                        cands.setdefault(f"{rel}/{f.name}", f)
        a = _pair(["amc/" + p.name], list(cands))["amc/" + p.name]
        a_path = cands[a] if a is not None else None
        yield p.name, AsfAmcSource(p.name, p.name, a_path.name if a_path else None, _file_opener(p),
                                   _file_opener(a_path) if a_path else None, fps, cache)
        return
    raise ValueError(f"{p}: not a directory, .amc file or tar archive")


def _file_opener(p: Path) -> Opener:
    return lambda: open(p, "rb")


def _blob_opener(blob: bytes) -> Opener:
    return lambda: io.BytesIO(zlib.decompress(blob))
