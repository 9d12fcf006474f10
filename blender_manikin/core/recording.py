"""Tracker recordings: data classes, axis/unit conversion, and file loading.

Never imports bpy.

A :class:`Recording` holds one :class:`TrackerStream` per device (``head``,
``left_hand``, ``right_hand`` and optionally ``pelvis``, ``left_foot``,
``right_foot``; see :data:`~blender_manikin.core.pose_result.DEVICES`).  Every
stream has its own timestamps: devices are sampled at their own rates (72,
90, 120 Hz ...) with jitter, and :func:`~blender_manikin.core.resample.resample`
brings them onto a common frame grid.

Conventions of the data *after loading* (whatever the file used):

* time: seconds, float64, strictly increasing within a stream;
* positions: metres, Blender world axes (right-handed, +Z up, the performer
  faces -Y at rest, so the performer's right is -X);
* orientations: unit quaternions ``(w, x, y, z)`` of the *device* frame in
  Blender axes, acting on column vectors (see :mod:`.rotations`).  The device
  frame's own axes are converted like the world axes, so an HMD (OpenXR view
  space: -Z forward, +Y up) that looks straight ahead has identity
  orientation: local -Y forward, +Z up.

Axis conventions of source files (:data:`AXES`):

==========  ==============================================  =====================
name        convention                                      to Blender ``M``
==========  ==============================================  =====================
openxr      right-handed, +Y up, -Z forward, +X right        (x, y, z) → (-x, z, y)
            (also OpenVR/SteamVR, WebXR, OpenGL)
unity       left-handed, +Y up, +Z forward, +X right         (x, y, z) → (-x, -z, y)
blender     right-handed, +Z up, -Y forward, -X right        identity
unreal      left-handed, +Z up, +X forward, +Y right         (x, y, z) → (-y, -x, z)
            (Unreal Engine's world and component axes)
==========  ==============================================  =====================

All maps keep "forward" forward, "up" up and "right" right.  Positions convert
as ``p_b = M p``; rotation matrices as ``R_b = M R Mᵀ`` (a proper rotation even
for Unity's and Unreal's improper ``M``, det -1).  On quaternions this is
``(w, v) → (w, det(M) · M v)``, which keeps the sign of ``w`` (so sign
continuity and deliberate sign flips survive the conversion).
"""
from __future__ import annotations

import contextlib
import errno
import itertools
import os
import threading
from dataclasses import dataclass, field

import numpy as np

from .plain import shown
from .devices import ALIASES as DEVICE_ALIASES, DEVICES, canonical_device  # noqa: F401

#: axis conventions understood by the readers and writers
AXES = ("openxr", "unity", "blender", "unreal")
#: the conventions of :data:`AXES` whose axes are left-handed
LEFT_HANDED = ("unity", "unreal")

_AXES_ALIASES = {
    "openxr": "openxr", "openvr": "openxr", "steamvr": "openxr", "webxr": "openxr",
    "opengl": "openxr", "unity": "unity", "blender": "blender",
    "unreal": "unreal", "ue4": "unreal", "ue5": "unreal", "unreal_engine": "unreal",
}

_M = {
    "openxr": np.array([[-1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]]),
    "unity": np.array([[-1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]),
    "blender": np.eye(3),
    "unreal": np.array([[0.0, -1.0, 0], [-1.0, 0, 0], [0, 0, 1.0]]),
}

#: length units: metres per unit
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}

_UNITS_ALIASES = {
    "m": "m", "metre": "m", "metres": "m", "meter": "m", "meters": "m",
    "cm": "cm", "centimetre": "cm", "centimetres": "cm", "centimeter": "cm", "centimeters": "cm",
    "mm": "mm", "millimetre": "mm", "millimetres": "mm", "millimeter": "mm", "millimeters": "mm",
}

#: alternative device names accepted by the readers (lower case)


class RecordingError(ValueError):
    """A recording could not be read or used.

    The message names the file, the line (text formats) or byte offset
    (binary formats) where there is one, and the problem, e.g.
    ``"take1.csv, line 12: unknown device 'elbow_l' (expected one of head, ...)"``.
    The parts are also available as attributes.
    """

    def __init__(self, problem, path=None, line=None, offset=None):
        self.problem = str(problem)
        self.path = None if path is None else str(path)
        self.line = line
        self.offset = offset
        where = []
        if self.path:
            where.append(os.path.basename(self.path) or self.path)
        if line is not None:
            where.append(f"line {line}")
        if offset is not None:
            where.append(f"byte offset {offset}")
        msg = (", ".join(where) + ": " + self.problem) if where else self.problem
        super().__init__(msg)


def missing_file(path) -> str:
    """Why ``path`` is no file to read, in words for an error: ``"no such file"``, a folder, or a
    symbolic link that leads nowhere (its target gone, or links that loop)."""
    if os.path.islink(path):
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return "a symbolic link that loops (it leads back to itself through other links)"
            return f"a symbolic link to {os.readlink(path)!r}, which does not exist"
    if os.path.isdir(path):
        return "a folder, not a file"
    return "no such file"


#: rows (samples, frames, lines) a long reader parses between two :func:`read_check` calls:
#: a fraction of a second of work, so a read stops soon after it is asked to
CHECK_ROWS = 4096
_READS = threading.local()


@contextlib.contextmanager
def cancellable_reads(check):
    """Inside this block, the readers in this thread call ``check()`` (no arguments) between
    chunks of a long read (:func:`read_check`); it stops the read by raising (the add-on's
    solve job raises its ``SolveCancelled`` once Esc was pressed).  One check per thread (a
    worker's read is not stopped by another's Esc); the one before is restored on leaving."""
    before = getattr(_READS, "check", None)
    _READS.check = check
    try:
        yield
    finally:
        _READS.check = before


def read_check():
    """Called by a reader between chunks of its work: the check of the enclosing
    :func:`cancellable_reads` in this thread, which raises to stop the read; nothing outside one."""
    check = getattr(_READS, "check", None)
    if check is not None:
        check()


def row_chunks(n, size=None):
    """Slices ``0:size``, ``size:2*size``, ... of ``n`` rows (``size`` default :data:`CHECK_ROWS`),
    :func:`read_check` called before each: how a reader walks a long table in chunks."""
    size = max(int(CHECK_ROWS if size is None else size), 1)
    for start in range(0, int(n), size):
        read_check()
        yield slice(start, min(start + size, int(n)))


def batches(items, size=None):
    """Lists of ``size`` (default :data:`CHECK_ROWS`) successive items of the iterable ``items``
    (the last one shorter), :func:`read_check` called before each: how a reader walks a long
    iterator (a ``csv.reader``) a chunk at a time."""
    items = iter(items)
    while True:
        read_check()
        part = list(itertools.islice(items, max(int(CHECK_ROWS if size is None else size), 1)))
        if not part:
            return
        yield part


def chunked(items, size=None):
    """The items of the iterable ``items`` one by one, taken from it in :func:`batches`."""
    for part in batches(items, size):
        yield from part


def read_file_bytes(path) -> bytes:
    """The whole file, or :class:`RecordingError` naming it and why it cannot be read (also
    when it is a stand-in for the data: see :func:`not_data`)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise RecordingError(f"cannot read file ({exc.strerror or exc})", path=path) from None
    problem = not_data(data[:512], text=False)
    if problem:
        raise RecordingError(problem, path=path)
    return data


#: byte-order marks → codec, longest first (UTF-32 LE's BOM starts with UTF-16 LE's)
_BOMS = ((b"\xff\xfe\x00\x00", "utf-32-le"), (b"\x00\x00\xfe\xff", "utf-32-be"), (b"\xef\xbb\xbf", "utf-8"),
         (b"\xff\xfe", "utf-16-le"), (b"\xfe\xff", "utf-16-be"))


def not_data(head: bytes, text=True):
    """Why a file whose first bytes are ``head`` is a stand-in for data, not data, or None: a
    Git LFS pointer (the repository was cloned without ``git lfs pull``), an HTML page (a
    download link that answered with a login or error page), a gzip or ZIP archive (a
    compressed take; a ZIP only for a ``text`` format: an Excel workbook renamed ``.csv``)."""
    if head.startswith(b"version https://git-lfs.github.com/spec/"):
        return "a Git LFS pointer, not the data: fetch the file (git lfs pull)"
    if head.startswith(b"\x1f\x8b"):
        return "gzip-compressed: decompress it first (gunzip, 7-Zip)"
    if text and head.startswith(b"PK\x03\x04"):
        return "a ZIP archive (an Excel workbook?), not the data: extract it, or save the sheet as CSV"
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")[:64].lower()
    if text.startswith((b"<!doctype html", b"<html", b"<head", b"<body")):
        return "an HTML page (a failed download or a login page?), not the data"
    return None


def text_codec(head: bytes):
    """``(codec, bom_bytes)`` of a text file from its first bytes: UTF-8 unless a byte-order
    mark says UTF-16 / UTF-32 (Excel's "Unicode Text", Windows PowerShell's ``Out-File`` and
    ``>`` write UTF-16 LE with a BOM), or, without one, the NUL bytes of ASCII in UTF-16 do."""
    for bom, codec in _BOMS:
        if head.startswith(bom):
            return codec, len(bom)
    if len(head) >= 4 and b"\x00" in head:
        even, odd = head[0::2].count(0), head[1::2].count(0)
        if odd > 0.4 * len(head) / 2 and even == 0:
            return "utf-16-le", 0
        if even > 0.4 * len(head) / 2 and odd == 0:
            return "utf-16-be", 0
    return "utf-8", 0


def decode_text(data: bytes, path=None, errors="strict") -> str:
    """The text of a file's bytes (``data``): UTF-8, UTF-16 or UTF-32 (:func:`text_codec`),
    a BOM dropped.  Line ends are left as they are (``\\n``, ``\\r\\n`` or ``\\r``: ``splitlines``
    takes them all).  Raises :class:`RecordingError` naming ``path``, the line and the byte when
    ``errors="strict"`` and a byte does not decode, and for a stand-in (:func:`not_data`)."""
    problem = not_data(data[:512])
    if problem:
        raise RecordingError(problem, path=path)
    codec, skip = text_codec(data[:512])
    try:
        return data[skip:].decode(codec, errors)
    except UnicodeDecodeError as exc:
        at = skip + exc.start
        line = data[skip:at].decode(codec, "replace").count("\n") + 1
        excel = str(path or "").lower().endswith((".csv", ".tsv", ".txt"))
        hint = (": save it as UTF-8" + (" (Excel: CSV UTF-8)" if excel else "")) if codec == "utf-8" else ""
        raise RecordingError(f"not {codec.upper()} text (byte 0x{data[at]:02x}){hint}", path=path, line=line) from None


def decode_head(head: bytes) -> str:
    """The first bytes of a file as text, for recognising its format (undecodable bytes replaced)."""
    codec, skip = text_codec(head)
    return head[skip:].decode(codec, "replace")


def read_text(path, errors="strict") -> str:
    """The whole text file at ``path``: :func:`read_file_bytes` then :func:`decode_text`."""
    return decode_text(read_file_bytes(path), path=path, errors=errors)


def load_json_file(path):
    """The JSON document in the file at ``path`` (layout, offsets, bone map, mapping files): its
    text read by :func:`read_text` (a BOM, as Windows Notepad and PowerShell's
    ``Set-Content -Encoding UTF8`` write, or UTF-16, as PowerShell's ``Out-File`` writes, is
    read), parsed; :class:`RecordingError` (a ``ValueError``) names the file, the line and
    the problem."""
    import json
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(f"not valid JSON ({exc.msg})", path=path, line=exc.lineno) from None


def json_key_line(text, key_path):
    """The 1-based line of ``text`` (a JSON document that parses) where the key ``key_path``
    (a tuple of object keys, and array indices as ints counted from 0) is written, for an error
    about its value: the line of ``"key":`` of the deepest part of the path the text holds (a
    device's line when the key asked for inside it is missing); for an array index, the line
    its element starts on (``("parents", 2)``: the third pair's ``[``; the array's key's line
    when it has fewer elements); None when not even the first key is there.  A key written
    twice counts where it is written last (the value ``json.loads`` keeps)."""
    import json
    want = tuple(key_path)
    stack, found, line, i, n = [], {}, 1, 0, len(text)
    while i < n:
        c = text[i]
        if stack and stack[-1][0] == "[" and stack[-1][2] and c not in " \t\r\n,]":
            stack[-1][2] = False                         # an array's element starts here
            path = tuple(f[1] for f in stack)
            if path == want[:len(path)]:
                found[len(path)] = line
        if c == "\n":
            line += 1
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            k = j + 1
            while k < n and text[k] in " \t\r\n":
                k += 1
            if stack and stack[-1][0] == "{" and k < n and text[k] == ":":
                try:
                    stack[-1][1] = json.loads(text[i:j + 1])
                except ValueError:
                    stack[-1][1] = None
                path = tuple(f[1] for f in stack)
                if path == want[:len(path)]:
                    found[len(path)] = line
            line += text.count("\n", i, j)
            i = j
        elif c in "{[":
            stack.append([c, None, False] if c == "{" else [c, 0, True])   # [kind, key or index, element due]
        elif c in "}]":
            if stack:
                stack.pop()
        elif c == "," and stack and stack[-1][0] == "[":
            stack[-1][1] += 1
            stack[-1][2] = True
        i += 1
    return found[max(found)] if found else None


def canonical_axes(axes) -> str:
    """Canonical axes name (see :data:`AXES`) for ``axes`` (case-insensitive, aliases allowed)."""
    key = str(axes).strip().lower()
    if key not in _AXES_ALIASES:
        raise ValueError(f"unknown axes {shown(axes)}: expected one of {', '.join(AXES)}")
    return _AXES_ALIASES[key]


def canonical_units(units) -> str:
    """Canonical unit name (``m``, ``cm`` or ``mm``) for ``units``."""
    key = str(units).strip().lower()
    if key not in _UNITS_ALIASES:
        raise ValueError(f"unknown units {shown(units)}: expected one of {', '.join(UNITS)}")
    return _UNITS_ALIASES[key]


def axes_matrix(axes) -> np.ndarray:
    """``(3, 3)`` matrix ``M`` taking source-axes vectors to Blender axes (``p_b = M p``)."""
    return _M[canonical_axes(axes)].copy()


def _apply_axes(M, v, out=None):
    """``M v`` for ``(..., 3)`` vectors ``v``; ``M`` is a signed axis permutation (every axes
    convention is), so each output component is one input component times ±1: exact, and a
    NaN stays in its own component.  out: ``(..., 3)`` array to write into."""
    out = np.empty(np.shape(v), dtype=np.float64) if out is None else out
    for i in range(3):
        j = int(np.argmax(np.abs(M[i])))
        np.multiply(v[..., j], M[i, j], out=out[..., i])
    return out


def _convert_quat(quat, M):
    q = np.asarray(quat, dtype=np.float64)
    det = float(np.round(np.linalg.det(M)))
    out = np.empty(q.shape, dtype=np.float64)
    out[..., 0] = q[..., 0]
    _apply_axes(M * det, q[..., 1:], out=out[..., 1:])
    return out


def to_blender(pos, quat, axes):
    """Convert positions ``(..., 3)`` and wxyz quaternions ``(..., 4)`` from ``axes`` to Blender axes.

    Units are unchanged.  Either argument may be None.  Returns ``(pos, quat)``.
    """
    M = axes_matrix(axes)
    p = None if pos is None else _apply_axes(M, np.asarray(pos, dtype=np.float64))
    q = None if quat is None else _convert_quat(quat, M)
    return p, q


def from_blender(pos, quat, axes):
    """Inverse of :func:`to_blender`: Blender axes → ``axes``."""
    Mt = axes_matrix(axes).T
    p = None if pos is None else _apply_axes(Mt, np.asarray(pos, dtype=np.float64))
    q = None if quat is None else _convert_quat(quat, Mt)
    return p, q


#: seconds a single sample's time may leap ahead of both its neighbours (which go on from each
#: other) before it is taken for a corrupt timestamp and dropped (:func:`increasing_mask`)
TIME_SPIKE_S = 1.0


def time_unit_of_step(step, milliseconds=False):
    """``(factor to seconds, unit)`` of a time column whose median step is ``step`` (in its own
    unit): no tracker or keypoint stream is sampled slower than 2 Hz, so a step over 0.5 is not
    seconds but milliseconds (steps under 500), microseconds (under 5e5) or nanoseconds; with
    ``milliseconds`` (a column named so) at least milliseconds.  ``(1.0, "s")`` otherwise.
    The readers that know a file's time column (wide CSV and JSON, keypoints) decide with this."""
    if step <= 0.5 and not milliseconds:
        return 1.0, "s"
    return (1e-3, "ms") if step < 500 else (1e-6, "µs") if step < 5e5 else (1e-9, "ns")


def time_spikes(time) -> np.ndarray:
    """``(N,)`` bool: single samples whose time leaps more than :data:`TIME_SPIKE_S` ahead of the
    sample before them while the sample after them goes on from that one (a corrupt timestamp,
    not a pause: after a pause the time does not come back)."""
    t = np.asarray(time, dtype=np.float64)
    out = np.zeros(t.shape, dtype=bool)
    if t.size >= 3:
        prev, mid, nxt = t[:-2], t[1:-1], t[2:]
        with np.errstate(invalid="ignore"):
            out[1:-1] = (mid - prev > TIME_SPIKE_S) & (nxt < mid) & (nxt >= prev)
    return out


def increasing_mask(time) -> np.ndarray:
    """``(N,)`` bool: True for samples whose time is greater than every earlier sample's.

    Keeping these yields a strictly increasing series (the first of several
    samples sharing a time is kept; samples after a backwards jump are dropped
    until time passes the previous maximum).  NaN times are never kept, nor a single sample
    whose time leaps ahead of both its neighbours (:func:`time_spikes`): it would otherwise
    drop every sample after it, or stretch the take to its time.
    """
    t = np.asarray(time, dtype=np.float64)
    if t.size == 0:
        return np.zeros(0, dtype=bool)
    t = np.where(time_spikes(t), np.nan, t)
    tt = np.where(np.isfinite(t), t, -np.inf)
    prev_max = np.concatenate([[-np.inf], np.maximum.accumulate(tt)[:-1]])
    return np.isfinite(t) & (t > prev_max)


@dataclass
class TrackerStream:
    """The samples of one device.

    device: one of :data:`~blender_manikin.core.pose_result.DEVICES`.
    time: ``(N,)`` float64 seconds (recording clock), strictly increasing.
    pos: ``(N, 3)`` float64 metres, Blender world axes (may contain NaN = lost).
    quat: ``(N, 4)`` float64 unit wxyz quaternions, device orientation in
    Blender axes (may contain NaN = lost).
    valid: ``(N,)`` bool, False where the source flagged tracking as lost.
    """
    device: str
    time: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    valid: np.ndarray = None

    def __post_init__(self):
        dev = canonical_device(self.device)
        if dev is None:
            raise ValueError(f"unknown device {shown(self.device)}: expected one of {', '.join(DEVICES)}")
        self.device = dev
        self.time = np.asarray(self.time, dtype=np.float64).reshape(-1)
        n = self.time.shape[0]
        self.pos = np.asarray(self.pos, dtype=np.float64).reshape(n, 3)
        self.quat = np.asarray(self.quat, dtype=np.float64).reshape(n, 4)
        if self.valid is None:
            self.valid = np.ones(n, dtype=bool)
        self.valid = np.asarray(self.valid, dtype=bool).reshape(n)

    def __len__(self):
        return int(self.time.shape[0])

    @property
    def usable(self) -> np.ndarray:
        """``(N,)`` bool: valid and with finite position and non-degenerate finite quaternion."""
        qn = np.linalg.norm(self.quat, axis=-1)
        return (self.valid & np.all(np.isfinite(self.pos), -1) & np.all(np.isfinite(self.quat), -1)
                & (qn > 1e-6))

    @property
    def rate(self) -> float:
        """Nominal sample rate, Hz (1 / median sample interval); NaN with < 2 samples."""
        if len(self) < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.time)))

    def select(self, mask) -> "TrackerStream":
        """A new stream with only the samples where ``mask`` is True."""
        m = np.asarray(mask, dtype=bool)
        return TrackerStream(self.device, self.time[m], self.pos[m], self.quat[m], self.valid[m])

    def copy(self) -> "TrackerStream":
        return TrackerStream(self.device, self.time.copy(), self.pos.copy(), self.quat.copy(),
                             self.valid.copy())


@dataclass
class Recording:
    """A tracker recording in Blender axes and metres.

    streams: device name → :class:`TrackerStream`.
    source: where it came from (the file path for loaded recordings).
    metadata: free-form information from the file (``axes``/``units`` as read,
    ``source`` text, BSOR header fields ...).
    warnings: human-readable notes about repairs made while reading.
    """
    streams: dict
    source: str = ""
    metadata: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    @property
    def devices(self):
        """Devices present, in :data:`DEVICES` order."""
        return tuple(d for d in DEVICES if d in self.streams)

    def time_range(self):
        """``(first, last)`` sample time over all streams, seconds."""
        firsts = [s.time[0] for s in self.streams.values() if len(s)]
        lasts = [s.time[-1] for s in self.streams.values() if len(s)]
        if not firsts:
            return (float("nan"), float("nan"))
        return (float(min(firsts)), float(max(lasts)))

    @property
    def duration(self) -> float:
        a, b = self.time_range()
        return b - a

    def __getitem__(self, device):
        return self.streams[device]
