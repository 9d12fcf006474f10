"""BVH (Biovision hierarchy) motion files: reader, minimal writer, and sources.

Never imports bpy.  Everything here is in the *source file's own* units and
axes; converting to the body model (metres, Blender axes) is the job of
:mod:`blender_manikin.core.joint_maps`.

Conventions
-----------

* **Units** are whatever the file uses (Bandai Namco: centimetres, CMU
  cgspeed: 1/0.45 inch); angles in the file are degrees.
* **Axes** are the file's (usually +Y up).  Nothing is converted here.
* **Joints** are stored in file order, which lists every parent before its
  children; ``parents[j]`` is the index of the parent or ``-1`` for a root.
  ``End Site`` blocks are not joints: their OFFSET is kept in
  ``BvhClip.end_sites`` (``(J, 3)``, NaN where a joint has none).
* **Channels.**  Each joint keeps its own ``CHANNELS`` list (any count
  0-6, any order).  The frame row of ``motion`` ``(T, C)`` holds the joints'
  channels in file order; ``channel_starts[j]`` is where joint ``j``'s begin.
* **Rotation channels** compose in the order listed, as in every BVH
  reader: ``CHANNELS ... Zrotation Xrotation Yrotation`` with values
  ``(a, b, c)`` degrees means ``R_local = Rz(a) @ Rx(b) @ Ry(c)`` (matrices
  act on column vectors, ``v_parent = t_local + R_local @ v_local``).  A
  joint with fewer than three rotation channels uses only those axes; one
  with none has ``R_local = I``.
* **Position channels replace the OFFSET** component by component when
  present (this is how Blender's importer reads them, and what the Bandai
  Namco files need: their joints below Hips repeat the OFFSET in the
  position channels, their Hips channels hold the hip position).  A joint
  with only ``Yposition`` takes x and z from its OFFSET.
* **Global transforms** (:meth:`BvhClip.global_transforms`)::

      R_world[j] = R_world[parent] @ R_local[j]
      p_world[j] = p_world[parent] + R_world[parent] @ t_local[j]

  with ``t_local`` = OFFSET with position channels substituted.  Shapes are
  positions ``(T, J, 3)`` and rotations ``(T, J, 3, 3)``, float64; the code
  loops over joints and is vectorised over frames.
* The **rest pose** (:meth:`BvhClip.rest_positions`) is the zero-channel
  pose built from OFFSETs alone: every joint's world rotation is identity.
  It is only a T-pose when the file was authored that way (CMU is, Bandai
  Namco is not).

Reading sources
---------------

:func:`iter_bvh_sources` yields ``(name, opener)`` pairs, sorted by name, for a
directory (recursive), a single ``.bvh`` / ``.bvh.gz`` file, or the
``.bvh`` / ``.bvh.gz`` members of a ``.tar``, ``.tar.gz`` / ``.tgz``,
``.tar.xz`` / ``.txz`` or ``.tar.bz2`` archive, read without unpacking to
disk.  ``opener()`` returns a fresh binary file object that
:func:`read_bvh` accepts.  Compressed tar streams cannot be read out of order
cheaply, so an archive is read in one pass; with ``sort=True`` (default) each
member is kept zlib-compressed in memory (about 30 % of its size) until it is
yielded in name order, with ``sort=False`` members come in archive order and
nothing is buffered.

Text is UTF-8 (a byte-order mark, as Windows tools write, is dropped) or UTF-16 / UTF-32
with a BOM (:func:`.recording.text_codec`), converted to UTF-8 before parsing; a header that
is not UTF-8 is read as Latin-1 (joint names in another 8-bit encoding stay distinct).

Parsing speed comes from reading the MOTION block with ``np.loadtxt`` (C
parser); the header is parsed line by line in Python.  Problems raise
:class:`BvhError` naming the file, the line and the problem, e.g.
``walk.bvh line 57: expected 72 values per frame, got 70``.
"""
from __future__ import annotations

import gzip
import io
import os
import re
import tarfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Optional, Tuple

import numpy as np

from . import rotations as rot
from .recording import text_codec

__all__ = [
    "BvhError", "BvhClip", "read_bvh", "write_bvh", "iter_bvh_sources",
    "euler_to_matrix", "matrix_to_euler", "POSITION_CHANNELS", "ROTATION_CHANNELS",
]

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
_CHANNEL_CANON = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}
_AXIS = {"X": 0, "Y": 1, "Z": 2}

_BVH_SUFFIXES = (".bvh", ".bvh.gz")
_ARCHIVE_SUFFIXES = (".tar", ".tar.gz", ".tgz", ".tar.xz", ".txz", ".tar.bz2", ".tbz2")


class BvhError(ValueError):
    """A malformed BVH file.  ``str(err)`` is ``"<file> line <n>: <problem>"``."""

    def __init__(self, source: str, line: Optional[int], problem: str):
        self.source = source
        self.line = line
        self.problem = problem
        where = f"{source} line {line}" if line is not None else f"{source}"
        super().__init__(f"{where}: {problem}")


# --------------------------------------------------------------------------
# Euler angles (BVH channel order)
def euler_to_matrix(angles_deg, axes: str):
    """Compose rotations in BVH channel order: ``R = R_axes[0](a0) @ R_axes[1](a1) @ ...``.

    ``angles_deg``: ``(..., n)`` degrees, ``axes``: ``n`` letters from ``XYZ`` (e.g. ``"ZXY"``).
    Returns ``(..., 3, 3)``.  (:func:`.rotations.euler_to_matrix`, in degrees.)
    """
    return rot.euler_to_matrix(np.radians(np.asarray(angles_deg, dtype=np.float64)), axes)


def matrix_to_euler(R, axes: str, tol: float = 1e-6):
    """Inverse of :func:`euler_to_matrix`: degrees ``(..., n)`` for ``n = len(axes)``
    (:func:`.rotations.matrix_to_euler`; at gimbal lock the last angle is 0)."""
    return np.degrees(rot.matrix_to_euler(R, axes, tol))


# --------------------------------------------------------------------------
@dataclass
class BvhClip:
    """One BVH file: hierarchy, channels and the raw MOTION block.

    Attributes (see the module docstring for conventions):

    * ``name``: take name (file name without ``.bvh`` / ``.bvh.gz``).
    * ``joint_names``: ``J`` names; ``parents``: ``(J,)`` int, ``-1`` for roots.
    * ``offsets``: ``(J, 3)`` float64 OFFSETs, source units, parent frame.
    * ``channels``: per joint a tuple of canonical channel names
      (``"Xposition"``, ..., ``"Zrotation"``) in file order.
    * ``end_sites``: ``(J, 3)`` End Site OFFSETs in the joint's frame, NaN if none.
    * ``frame_time``: seconds per frame as written; ``fps = 1 / frame_time``
      unrounded (``0.0333333`` gives 30.00003; ``MotionClip.fps`` rounds).
    * ``motion``: ``(T, C)`` float64 channel values (degrees, source units).
    * ``source``: where it was read from (for messages).
    """
    name: str
    joint_names: Tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: Tuple[Tuple[str, ...], ...]
    frame_time: float
    motion: np.ndarray
    end_sites: Optional[np.ndarray] = None
    source: str = ""
    channel_starts: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.joint_names = tuple(self.joint_names)
        self.parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        J = len(self.joint_names)
        self.offsets = np.asarray(self.offsets, dtype=np.float64).reshape(J, 3)
        self.channels = tuple(tuple(_CHANNEL_CANON[c.lower()] for c in ch) for ch in self.channels)
        if len(self.channels) != J or self.parents.shape[0] != J:
            raise ValueError("joint_names, parents, offsets and channels must have one entry per joint")
        for j, p in enumerate(self.parents):
            if p >= j:
                raise ValueError(f"joint {self.joint_names[j]!r}: parents must precede children")
        if self.end_sites is None:
            self.end_sites = np.full((J, 3), np.nan)
        self.end_sites = np.asarray(self.end_sites, dtype=np.float64).reshape(J, 3)
        counts = np.array([len(c) for c in self.channels], dtype=np.int64)
        self.channel_starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        C = int(counts.sum())
        self.motion = np.asarray(self.motion, dtype=np.float64).reshape(-1, C)
        self.frame_time = float(self.frame_time)
        self._index = {n: i for i, n in enumerate(self.joint_names)}

    # ------------------------------------------------------------------
    @property
    def num_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_channels(self) -> int:
        return int(self.motion.shape[1])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def joint_index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"{self.name}: no joint named {name!r}") from None

    def children(self, j: int) -> Tuple[int, ...]:
        return tuple(int(c) for c in np.nonzero(self.parents == j)[0])

    def channel_values(self, j: int) -> np.ndarray:
        """``(T, n)`` values of joint ``j``'s channels, in its CHANNELS order."""
        s = self.channel_starts[j]
        return self.motion[:, s:s + len(self.channels[j])]

    # ------------------------------------------------------------------
    def local_transforms(self):
        """Per-joint local translations ``(T, J, 3)`` and rotations ``(T, J, 3, 3)``."""
        T, J = self.num_frames, self.num_joints
        trans = np.broadcast_to(self.offsets, (T, J, 3)).copy()
        rots = np.empty((T, J, 3, 3))
        for j in range(J):
            trans_j, rots[:, j] = self._joint_local(j)
            if trans_j is not None:
                trans[:, j] = trans_j
        return trans, rots

    def _joint_local(self, j):
        vals = self.channel_values(j)
        chans = self.channels[j]
        T = vals.shape[0]
        trans = None
        rot_axes, rot_cols = "", []
        for n, c in enumerate(chans):
            if c.endswith("position"):
                if trans is None:
                    trans = np.broadcast_to(self.offsets[j], (T, 3)).copy()
                trans[:, _AXIS[c[0]]] = vals[:, n]
            else:
                rot_axes += c[0]
                rot_cols.append(n)
        if rot_axes:
            R = euler_to_matrix(vals[:, rot_cols], rot_axes)
        else:
            R = np.broadcast_to(np.eye(3), (T, 3, 3))
        return trans, R

    def global_transforms(self):
        """World positions ``(T, J, 3)`` and rotations ``(T, J, 3, 3)`` (source units/axes)."""
        T, J = self.num_frames, self.num_joints
        pos = np.empty((T, J, 3))
        rot = np.empty((T, J, 3, 3))
        for j in range(J):
            t, R = self._joint_local(j)
            if t is None:
                t = self.offsets[j]
            p = self.parents[j]
            if p < 0:
                pos[:, j] = t
                rot[:, j] = R
            else:
                Rp = rot[:, p]
                if t.ndim == 1:
                    pos[:, j] = pos[:, p] + Rp @ t
                else:
                    pos[:, j] = pos[:, p] + np.einsum("tij,tj->ti", Rp, t)
                rot[:, j] = Rp @ R
        return pos, rot

    def rest_positions(self):
        """``(J, 3)`` joint positions of the zero-channel pose from OFFSETs alone."""
        p = np.zeros((self.num_joints, 3))
        for j in range(self.num_joints):
            par = self.parents[j]
            p[j] = self.offsets[j] + (p[par] if par >= 0 else 0.0)
        return p

    def end_site_joints(self) -> np.ndarray:
        """``(E,)`` indices of the joints that have an End Site, ascending."""
        return np.nonzero(np.all(np.isfinite(self.end_sites), axis=1))[0]

    def end_site_positions(self, positions=None, rotations=None):
        """World positions of the End Sites, ``(T, E, 3)`` in :meth:`end_site_joints` order
        (source units and axes): ``p_world[j] + R_world[j] @ end_sites[j]``.

        ``positions`` ``(T, J, 3)`` / ``rotations`` ``(T, J, 3, 3)``: :meth:`global_transforms`'s
        output (computed when not given); the zero pose's are :meth:`rest_end_sites`.
        """
        if positions is None or rotations is None:
            positions, rotations = self.global_transforms()
        e = self.end_site_joints()
        return positions[:, e] + np.einsum("teij,ej->tei", rotations[:, e], self.end_sites[e])

    def rest_end_sites(self):
        """``(E, 3)`` End Site positions of the zero-channel pose (every world rotation identity)."""
        e = self.end_site_joints()
        return self.rest_positions()[e] + self.end_sites[e]

    # ------------------------------------------------------------------
    @classmethod
    def from_local_transforms(cls, name, joint_names, parents, offsets, channels, local_rot,
                              translations=None, frame_time=1 / 30, end_sites=None):
        """Build a clip from per-joint local rotations ``(T, J, 3, 3)``.

        ``translations``: ``(T, J, 3)`` local translations, used for the
        position channels (joints without position channels must match
        their OFFSET; this is not checked).  Rotations are converted to each
        joint's rotation channel order with :func:`matrix_to_euler`.
        """
        local_rot = np.asarray(local_rot, dtype=np.float64)
        T, J = local_rot.shape[:2]
        channels = tuple(tuple(_CHANNEL_CANON[c.lower()] for c in ch) for ch in channels)
        if translations is None:
            translations = np.broadcast_to(np.asarray(offsets, np.float64), (T, J, 3))
        cols = []
        for j in range(J):
            chans = channels[j]
            rot_axes = "".join(c[0] for c in chans if c.endswith("rotation"))
            eul = matrix_to_euler(local_rot[:, j], rot_axes) if rot_axes else np.zeros((T, 0))
            r = 0
            for c in chans:
                if c.endswith("position"):
                    cols.append(translations[:, j, _AXIS[c[0]]])
                else:
                    cols.append(eul[:, r])
                    r += 1
        motion = np.stack(cols, axis=1) if cols else np.zeros((T, 0))
        return cls(name, tuple(joint_names), parents, offsets, channels, frame_time, motion,
                   end_sites=end_sites)


# --------------------------------------------------------------------------
# reading
def _strip_bvh_suffix(name: str) -> str:
    base = os.path.basename(str(name).replace("\\", "/"))
    low = base.lower()
    for suf in (".bvh.gz", ".bvh", ".gz"):
        if low.endswith(suf):
            return base[: -len(suf)]
    return base


def _read_bytes(path_or_fileobj):
    """Return ``(data, display_name)``; gunzips when the data starts with the gzip magic."""
    if isinstance(path_or_fileobj, (str, os.PathLike)):
        display = os.path.basename(os.fspath(path_or_fileobj))
        with open(path_or_fileobj, "rb") as f:
            data = f.read()
    else:
        display = os.path.basename(str(getattr(path_or_fileobj, "name", "<stream>")))
        data = path_or_fileobj.read()
        if isinstance(data, str):
            data = data.encode("utf-8")
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    codec, skip = text_codec(data[:512])        # a BOM (Windows tools), or UTF-16/32 text
    if skip or codec != "utf-8":
        data = data[skip:].decode(codec, errors="replace").encode("utf-8")
    return data, display


def _decode(data: bytes) -> str:
    """Header text: UTF-8, else Latin-1, so names in another 8-bit encoding (Windows-1252,
    Shift-JIS) stay as distinct as their bytes (U+FFFD replacements made ``左足`` and ``左手`` in
    Shift-JIS the same name)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


_MOTION_RE = re.compile(rb"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE | re.IGNORECASE)


def read_bvh(path_or_fileobj, name: Optional[str] = None) -> BvhClip:
    """Read a BVH file (plain or gzip) from a path or a binary/text file object.

    ``name`` (optional) names the take and is used in error messages; it
    defaults to the file name.  Returns a :class:`BvhClip`; problems raise
    :class:`BvhError`.
    """
    data, display = _read_bytes(path_or_fileobj)
    src = os.path.basename(name) if name else display
    take = _strip_bvh_suffix(name if name else display)
    m = _MOTION_RE.search(data)
    if m is None:
        text = _decode(data)
        _parse_hierarchy(text, src)          # reports where the hierarchy goes wrong
        nlines = text.count("\n") + (0 if text.endswith("\n") else 1)
        raise BvhError(src, nlines, "no MOTION section after the HIERARCHY")
    header = _decode(data[: m.start()])
    motion_line = header.count("\n") + 1
    joints = _parse_hierarchy(header, src)

    # ---- Frames: / Frame Time: ------------------------------------------
    rest = data[m.end():]
    nl = rest.find(b"\n")
    pos = nl + 1 if nl >= 0 else len(rest)
    line_no = motion_line + 1          # line number of rest[pos:]
    frames = frame_time = None
    while frames is None or frame_time is None:
        if pos >= len(rest):
            raise BvhError(src, line_no, "MOTION section ends before 'Frames:' and 'Frame Time:'")
        nl = rest.find(b"\n", pos)
        end_ = nl if nl >= 0 else len(rest)
        text = rest[pos:end_].decode("utf-8", errors="replace").strip()
        this_line = line_no
        pos = end_ + 1
        line_no += 1
        if not text:
            continue
        key, sep, val = text.partition(":")
        k = key.strip().lower().replace(" ", "")
        if not sep or k not in ("frames", "frametime"):
            raise BvhError(src, this_line, f"expected 'Frames:' or 'Frame Time:', got {text[:40]!r}")
        try:
            if k == "frames":
                frames = int(val.strip())
                ok = frames >= 0
            else:
                frame_time = float(val.strip())
                ok = np.isfinite(frame_time) and frame_time > 0
        except ValueError:
            ok = False
        if not ok:
            raise BvhError(src, this_line, f"bad value for {key.strip()!r}: {val.strip()!r}"
                           + (" (Frame Time must be positive)" if k == "frametime" else ""))
    first_data_line = line_no
    body = rest[pos:] if pos < len(rest) else b""

    names = tuple(j["name"] for j in joints)
    channels = tuple(j["channels"] for j in joints)
    C = sum(len(c) for c in channels)
    motion = _parse_motion(body, C, frames, src, first_data_line)
    clip = BvhClip(
        name=take, joint_names=names,
        parents=np.array([j["parent"] for j in joints], dtype=np.int64),
        offsets=np.array([j["offset"] for j in joints], dtype=np.float64).reshape(-1, 3),
        channels=channels, frame_time=frame_time, motion=motion,
        end_sites=np.array([j["end"] if j["end"] is not None else (np.nan,) * 3 for j in joints],
                           dtype=np.float64).reshape(-1, 3),
        source=src,
    )
    return clip


def _tokenize(header: str):
    """Yield ``(line_no, token)``; braces are always separate tokens."""
    for n, line in enumerate(header.split("\n"), start=1):
        for tok in line.replace("{", " { ").replace("}", " } ").split():
            yield n, tok


def _parse_hierarchy(header: str, src: str):
    toks = list(_tokenize(header))
    nlines = header.count("\n") + 1
    i = 0

    def peek():
        return toks[i] if i < len(toks) else (nlines, None)

    def take(expected=None):
        nonlocal i
        if i >= len(toks):
            raise BvhError(src, nlines, f"unexpected end of HIERARCHY (expected {expected or 'more'})")
        ln, t = toks[i]
        if expected is not None and t.upper() != expected.upper():
            raise BvhError(src, ln, f"expected {expected!r}, got {t!r}")
        i += 1
        return ln, t

    def number(what):
        ln, t = take()
        try:
            v = float(t)
        except ValueError:
            raise BvhError(src, ln, f"expected a number for {what}, got {t!r}") from None
        if not np.isfinite(v):
            raise BvhError(src, ln, f"{what} is not finite")
        return v

    if not toks:
        raise BvhError(src, 1, "empty file")
    take("HIERARCHY")
    joints = []

    def parse_joint(parent, kw_line):
        nonlocal i
        # name: tokens until '{' on the same line
        name_toks = []
        while i < len(toks) and toks[i][0] == kw_line and toks[i][1] != "{":
            name_toks.append(toks[i][1])
            i += 1
        if not name_toks:
            raise BvhError(src, kw_line, "joint without a name")
        name = " ".join(name_toks)
        if any(j["name"] == name for j in joints):
            raise BvhError(src, kw_line, f"duplicate joint name {name!r}")
        take("{")
        me = len(joints)
        joints.append(dict(name=name, parent=parent, offset=None, channels=(), end=None, line=kw_line))
        while True:
            ln, t = peek()
            if t is None:
                raise BvhError(src, ln, f"joint {name!r}: missing '}}'")
            u = t.upper()
            if t == "}":
                i += 1
                break
            if u == "OFFSET":
                i += 1
                joints[me]["offset"] = tuple(number(f"OFFSET of {name!r}") for _ in range(3))
            elif u == "CHANNELS":
                i += 1
                ln_c, t_c = take()
                try:
                    n = int(t_c)
                    if n < 0:
                        raise ValueError
                except ValueError:
                    raise BvhError(src, ln_c, f"joint {name!r}: bad channel count {t_c!r}") from None
                chans = []
                for _ in range(n):
                    ln_x, c = take()
                    canon = _CHANNEL_CANON.get(c.lower())
                    if canon is None:
                        raise BvhError(src, ln_x, f"joint {name!r}: unknown channel {c!r} "
                                                  f"(CHANNELS {n} declared on line {ln_c})")
                    if canon in chans:
                        raise BvhError(src, ln_x, f"joint {name!r}: channel {canon} listed twice")
                    chans.append(canon)
                joints[me]["channels"] = tuple(chans)
            elif u in ("JOINT", "ROOT"):
                i += 1
                parse_joint(me, ln)
            elif u == "END":
                i += 1
                ln_s, s = take()
                if s.upper() != "SITE":
                    raise BvhError(src, ln_s, f"expected 'End Site', got 'End {s}'")
                take("{")
                take("OFFSET")
                end = tuple(number(f"End Site OFFSET of {name!r}") for _ in range(3))
                take("}")
                joints[me]["end"] = end
            else:
                raise BvhError(src, ln, f"joint {name!r}: unexpected {t!r}")
        if joints[me]["offset"] is None:
            raise BvhError(src, kw_line, f"joint {name!r} has no OFFSET")

    while i < len(toks):
        ln, t = take()
        if t.upper() != "ROOT":
            raise BvhError(src, ln, f"expected 'ROOT', got {t!r}")
        parse_joint(-1, ln)
    if not joints:
        raise BvhError(src, nlines, "HIERARCHY has no ROOT joint")
    return joints


def _parse_motion(body: bytes, C: int, frames: int, src: str, first_line: int):
    if not body.strip():
        values = np.zeros((0, C))
    else:
        try:
            values = np.loadtxt(io.BytesIO(body), dtype=np.float64, ndmin=2, comments=None)
        except ValueError:
            _locate_motion_error(body, C, src, first_line)
            raise  # pragma: no cover - _locate_motion_error always raises
        if values.shape[1] != C:
            _locate_motion_error(body, C, src, first_line)
    if values.shape[0] != frames:
        # find the line of the last frame for the message
        last = first_line + _line_of_row(body, values.shape[0] - 1) if values.shape[0] else first_line
        raise BvhError(src, last, f"header declares {frames} frames, MOTION block has {values.shape[0]}")
    if not np.all(np.isfinite(values)):
        row = int(np.nonzero(~np.all(np.isfinite(values), axis=1))[0][0])
        raise BvhError(src, first_line + _line_of_row(body, row), "non-finite channel value")
    return values


def _line_of_row(body: bytes, row: int) -> int:
    """0-based line offset (within ``body``) of the ``row``-th non-blank line."""
    r = -1
    for n, line in enumerate(body.split(b"\n")):
        if line.strip():
            r += 1
            if r == row:
                return n
    return n


def _locate_motion_error(body: bytes, C: int, src: str, first_line: int):
    """Slow path: find the first bad frame line and raise a precise BvhError."""
    for n, line in enumerate(body.split(b"\n")):
        toks = line.split()
        if not toks:
            continue
        if len(toks) != C:
            raise BvhError(src, first_line + n, f"expected {C} values per frame, got {len(toks)}")
        for k, t in enumerate(toks):
            try:
                float(t)
            except ValueError:
                raise BvhError(src, first_line + n,
                               f"value {k + 1} is not a number: {t.decode('utf-8', 'replace')!r}") from None
    raise BvhError(src, first_line, "could not parse the MOTION block")


# --------------------------------------------------------------------------
# writing
def _fmt(v) -> str:
    s = f"{v:.10g}"
    return "0" if s == "-0" else s


def write_bvh(path, clip: BvhClip, precision: int = 10):
    """Write ``clip`` as BVH text (gzip when ``path`` ends in ``.gz``).

    ``path`` may also be a writable text file object.  Channels, offsets and
    End Sites are written as stored; values with ``precision`` significant
    digits.
    """
    lines = ["HIERARCHY"]
    J = clip.num_joints

    def emit(j, depth):
        ind = "  " * depth
        kw = "ROOT" if clip.parents[j] < 0 else "JOINT"
        lines.append(f"{ind}{kw} {clip.joint_names[j]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET " + " ".join(_fmt(v) for v in clip.offsets[j]))
        ch = clip.channels[j]
        lines.append(f"{ind}  CHANNELS {len(ch)}" + "".join(" " + c for c in ch))
        for c in clip.children(j):
            emit(c, depth + 1)
        if np.all(np.isfinite(clip.end_sites[j])):
            lines.append(f"{ind}  End Site")
            lines.append(f"{ind}  {{")
            lines.append(f"{ind}    OFFSET " + " ".join(_fmt(v) for v in clip.end_sites[j]))
            lines.append(f"{ind}  }}")
        lines.append(f"{ind}}}")

    for j in range(J):
        if clip.parents[j] < 0:
            emit(j, 0)
    lines.append("MOTION")
    lines.append(f"Frames: {clip.num_frames}")
    lines.append(f"Frame Time: {clip.frame_time:.10g}")
    buf = io.StringIO()
    buf.write("\n".join(lines) + "\n")
    if clip.num_frames and clip.num_channels:
        np.savetxt(buf, clip.motion, fmt=f"%.{precision}g", delimiter=" ")
    elif clip.num_frames:
        buf.write("\n" * clip.num_frames)
    text = buf.getvalue()
    if hasattr(path, "write"):
        path.write(text)
        return
    path = os.fspath(path)
    if path.lower().endswith(".gz"):
        with gzip.open(path, "wt", encoding="utf-8", newline="\n") as f:
            f.write(text)
    else:
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)


# --------------------------------------------------------------------------
# sources: directories, files, archives
Opener = Callable[[], io.IOBase]


def _is_bvh_name(name: str) -> bool:
    low = name.lower()
    return any(low.endswith(s) for s in _BVH_SUFFIXES)


def _is_archive(path: str) -> bool:
    low = path.lower()
    return any(low.endswith(s) for s in _ARCHIVE_SUFFIXES)


def _file_opener(p: Path) -> Opener:
    return lambda: open(p, "rb")


def _bytes_opener(data: bytes, compressed: bool) -> Opener:
    if compressed:
        return lambda: io.BytesIO(zlib.decompress(data))
    return lambda: io.BytesIO(data)


def iter_bvh_sources(path, sort: bool = True) -> Iterator[Tuple[str, Opener]]:
    """Yield ``(name, opener)`` for every ``.bvh`` / ``.bvh.gz`` under ``path``.

    ``path`` is a directory (searched recursively; names are paths relative
    to it, ``/``-separated), a single BVH file (name = file name), or a tar
    archive (optionally gz/xz/bz2 compressed; names are member paths without
    a leading ``./``).  ``opener()`` returns a new binary file object each
    call; pass it to ``read_bvh(opener(), name)``.  Archives are read in one
    streaming pass without unpacking to disk; see the module docstring for
    what ``sort`` costs there.  Names are sorted (plain string order) unless
    ``sort=False`` for an archive.
    """
    p = Path(path)
    if p.is_dir():
        found = []
        for f in p.rglob("*"):
            if f.is_file() and _is_bvh_name(f.name):
                found.append((f.relative_to(p).as_posix(), f))
        for rel, f in sorted(found):
            yield rel, _file_opener(f)
        return
    if not p.exists():
        raise FileNotFoundError(f"no such file or directory: {p}")
    if _is_archive(p.name):
        yield from _iter_archive(p, sort)
        return
    if _is_bvh_name(p.name):
        yield p.name, _file_opener(p)
        return
    raise ValueError(f"{p}: not a directory, .bvh/.bvh.gz file or tar archive")


def _iter_archive(p: Path, sort: bool):
    buffered = []
    with tarfile.open(p, mode="r|*") as tf:
        for member in tf:
            if not member.isfile() or not _is_bvh_name(member.name):
                continue
            name = member.name
            while name.startswith("./"):
                name = name[2:]
            f = tf.extractfile(member)
            data = f.read() if f is not None else b""
            if sort:
                buffered.append((name, zlib.compress(data, 1)))
            else:
                yield name, _bytes_opener(data, False)
    if sort:
        buffered.sort(key=lambda x: x[0])
        for name, blob in buffered:
            yield name, _bytes_opener(blob, True)
