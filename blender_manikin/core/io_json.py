"""JSON and JSON Lines tracker recordings, as web and engine loggers write them (WebXR pages,
three.js, Unity's ``JsonUtility``, Python dumps): frames as objects, flattened into the columns
of a wide layout and read as a wide CSV is (:func:`.io_wide_csv.read_wide_table`: the devices,
components, time, units and axes are detected the same way, and the detection line says what
was found).  No bpy.

Accepted shapes:

* a list of frame objects, ``[{"time": 0.0, "head": {"position": {"x": 0, "y": 1.6, "z": 0},
  "rotation": {"x": 0, "y": 0, "z": 0, "w": 1}}, "leftHand": {...}, "rightHand": {...}}, ...]``;
* an object holding such a list: the longest list of objects in it (``{"fps": 72, "frames":
  [...]}``);
* JSON Lines (``.jsonl``, ``.ndjson``): one frame object per line.

Flattening (:func:`flatten`): nested keys joined with ``_`` (``head_position_x``); a list of 3
numbers is x, y, z; of 4 numbers x, y, z, w (WebXR's ``DOMPointReadOnly``, three.js, Unity and
Unreal write quaternions in that order); a position's ``w`` (WebXR positions carry ``w: 1``) is
dropped; a list of 16 numbers under a key naming a ``matrix`` is a column-major 4×4 rigid
transform (WebXR's ``XRRigidTransform.matrix``), read as its position and rotation; a list of
objects that each name their side (``"handedness": "left"``, ``"hand"``, ``"side"``) is keyed by
it (``left_hand_...``), as WebXR's input sources are: a source's ``gripSpace`` pose is its hand
(``targetRaySpace``, the pointing ray, is no device's; a ``"none"`` source, gaze, is left out);
an object of numbers keyed ``"0"``, ``"1"``, ... is the typed array ``JSON.stringify`` made it
from (a ``Float32Array`` matrix).  A frame without a source is a missing sample of it.  Time
keys in ns or us (``timestampNs``: OpenXR's ``XrTime``) are read in their unit.  Errors name the
file and the line of the frame (JSON Lines, or a list whose frames start on lines of their own).
"""
from __future__ import annotations

import functools
import json
import os
import re

import numpy as np

from .io_wide_csv import read_wide_table
from .plain import shown
from .recording import Recording, RecordingError, decode_text, read_check, read_file_bytes, row_chunks
from .rotations import matrix_to_quat

#: keys that say which side a list's object is on, and the sides they name
SIDE_KEYS = ("handedness", "hand", "side")
SIDES = {"left": "left_hand", "right": "right_hand", "l": "left_hand", "r": "right_hand"}
_POSITION_KEYS = ("position", "pos", "p", "location", "translation")
_ROTATION_KEYS = ("rotation", "rot", "orientation", "quaternion", "quat", "q")
JSONL_EXTENSIONS = (".jsonl", ".ndjson")


#: a head device's key near the start of a file (case-insensitive): what tells a recording from
#: the other JSON files beside it (layout, offsets and bone-map files, manifests, solved output)
_HEAD_KEY = re.compile(r'"(?:head|hmd|headset|viewer|camera|main[ _]?camera|center_?eye|centre_?eye|xr_?head|'
                       r'vr_?camera|xr_?camera)[a-z_ ]*"\s*:', re.IGNORECASE)


#: a time key with a number or a date-time string (a layout file's "time" holds an object)
_TIME_KEY = re.compile(r'"(?:time|t|timestamp|seconds|secs|time_?s|time_?ms|timestamp_?ms|ms|time(?:stamp)?_?(?:ns|us)|'
                       r'delta_?time(?:_?ms|_?s)?|dt(?:_?ms)?|frame(?:_?index|_?number)?|datetime|date_?time|time_?utc|utc_?time)"\s*:\s*[-+\d."]',
                       re.IGNORECASE)


def looks_like_recording(head_text) -> bool:
    """Whether the first few kilobytes of a JSON file look like a recording: a list or object
    with a head device's key and a time key holding a number or a string, and not a file of this
    add-on (its output's ``generator``, an offsets file's ``format``)."""
    t = head_text.lstrip("\ufeff \t\r\n")
    return (t[:1] in ("[", "{") and "blender_manikin" not in t[:2000] and bool(_HEAD_KEY.search(t))
            and bool(_TIME_KEY.search(t)))


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


@functools.lru_cache(maxsize=4096)
def _last_word(key):
    """``"gripPose"`` -> ``"pose"``, ``"head_position"`` -> ``"position"`` (keys repeat every frame)."""
    return re.split(r"[^a-z0-9]+", re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", key).lower())[-1]


@functools.lru_cache(maxsize=4096)
def _has_pose_parts(keys):
    """Whether an object with ``keys`` (a tuple) has both a position and a rotation key."""
    words = {_last_word(str(k)) for k in keys}
    return bool(words & set(_POSITION_KEYS)) and bool(words & set(_ROTATION_KEYS))


def flatten(obj, prefix="", out=None):
    """``{column: value}`` of one frame object (see the module doc); values are numbers or
    strings (an ISO 8601 time), other leaves (booleans, nulls, names) are left out."""
    out = {} if out is None else out
    if isinstance(obj, dict) and obj and all(k == str(n) for n, k in enumerate(obj)):
        obj = list(obj.values())            # a typed array as JSON.stringify writes it: {"0": .., "1": ..}
    if isinstance(obj, dict):
        parts = _has_pose_parts(tuple(obj))
        for k, v in obj.items():
            key = f"{prefix}_{k}" if prefix else str(k)
            if k in ("w", "W") and prefix and _last_word(prefix) in _POSITION_KEYS:
                continue                                   # a WebXR position's w (1)
            if parts and "matrix" in _last_word(str(k)):
                continue                                   # the same pose as its position and rotation
            flatten(v, key, out)
    elif isinstance(obj, list):
        if obj and all(_number(v) for v in obj):
            last = _last_word(prefix)
            if len(obj) == 16 and "matrix" in last:
                m = np.asarray(obj, np.float64).reshape(4, 4).T        # column-major
                base = prefix[: -len("matrix")].rstrip("_") if prefix.lower().endswith("matrix") else prefix
                base = base or "pose"
                if not (np.all(np.isfinite(m)) and np.abs(m).max() < 1e6
                        and abs(np.linalg.det(m[:3, :3]) - 1.0) < 0.1):
                    m = np.full((4, 4), np.nan)            # a lost or corrupt sample (not a rotation)
                for a, v in zip("xyz", m[:3, 3]):
                    out[f"{base}_position_{a}"] = float(v)
                with np.errstate(invalid="ignore"):
                    q = matrix_to_quat(m[:3, :3])
                for a, v in zip("wxyz", q):
                    out[f"{base}_rotation_{a}"] = float(v)
            elif len(obj) in (3, 4):
                for a, v in zip("xyzw", obj):
                    if not (a == "w" and last in _POSITION_KEYS):
                        out[f"{prefix}_{a}"] = v
        elif obj and all(isinstance(v, dict) for v in obj):
            for v in obj:
                side = next((str(v[k]).lower() for k in SIDE_KEYS if isinstance(v.get(k), str)), None)
                if side in SIDES:
                    flatten({k: x for k, x in v.items() if k not in SIDE_KEYS}, SIDES[side], out)
    elif _number(obj) or isinstance(obj, str):
        out[prefix] = obj
    return out


def _line_of(text, offset):
    return text.count("\n", 0, offset) + 1


class FrameLines:
    """The line each item of the JSON list that opens at ``text[start]`` (``"["``) starts on, found
    when first asked for (only an error needs them): each item is decoded in turn.  ``[k]`` is
    None when they cannot be told."""

    def __init__(self, text, start):
        self.text, self.start, self._lines = text, start, None

    def _find(self):
        text, dec = self.text, json.JSONDecoder()
        lines, i = [], self.start + 1
        line, counted = _line_of(text, i), i           # newlines counted up to ``counted``
        try:
            while True:
                while text[i] in " \t\r\n,":
                    i += 1
                if text[i] == "]":
                    return lines
                line += text.count("\n", counted, i)
                counted = i
                lines.append(line)
                _, i = dec.raw_decode(text, i)
        except (IndexError, ValueError):
            return []

    def __getitem__(self, k):
        if self._lines is None:
            self._lines = self._find()
        return self._lines[k] if 0 <= k < len(self._lines) else None


def frames_of(path, text):
    """``(frames, lines)``: the frame objects of a JSON or JSON Lines text and the line each
    starts on (``lines[k]``; a list, a :class:`FrameLines`, or None where it cannot be told).
    Raises :class:`RecordingError` naming the file and line."""
    if os.path.splitext(path)[1].lower() in JSONL_EXTENSIONS:
        frames, lines = [], []
        for n, ln in enumerate(text.splitlines(), 1):
            if not ln.strip():
                continue
            try:
                frames.append(json.loads(ln))
            except json.JSONDecodeError as exc:
                raise RecordingError(f"not valid JSON ({exc.msg})", path=path, line=n) from None
            lines.append(n)
        return frames, lines
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(f"not valid JSON ({exc.msg})", path=path, line=exc.lineno) from None
    except RecursionError:
        raise RecordingError("not valid JSON (nested too deeply)", path=path) from None
    if isinstance(doc, list):
        return doc, FrameLines(text, text.index("["))
    if isinstance(doc, dict):
        lists = {k: v for k, v in doc.items()
                 if isinstance(v, list) and len(v) >= 2 and all(isinstance(f, dict) for f in v)}
        if lists:
            key = max(lists, key=lambda k: len(lists[k]))
            m = re.search(r'"' + re.escape(json.dumps(key)[1:-1]) + r'"\s*:\s*\[', text)
            return lists[key], (FrameLines(text, m.end() - 1) if m else None)
    raise RecordingError("expected a list of frame objects, or an object holding one (e.g. \"frames\": [...])",
                         path=path, line=1)


def read_json(path, axes=None, units=None, layout=None, rate=None) -> Recording:
    """Read a JSON or JSON Lines recording (see the module doc) into a :class:`Recording`
    (Blender axes, metres).  axes, units, layout, rate: as :func:`.io_wide_csv.read_wide_csv`."""
    from .io_wide_csv import load_layout
    path = os.fspath(path)
    text = decode_text(read_file_bytes(path), path=path, errors="replace")
    if not text.strip():
        raise RecordingError("file is empty", path=path)
    read_check()                                  # a cancel before the parse (one call, a second or two)
    frames, lines = frames_of(path, text)
    if lines is None:
        lines = [None] * len(frames)
    flat, names = [], {}
    for part in row_chunks(len(frames)):          # in chunks: a cancel is checked between them
        for k in range(part.start, part.stop):
            f = frames[k]
            if not isinstance(f, dict):
                raise RecordingError(f"a frame is {type(f).__name__} {shown(f)}, not an object", path=path,
                                     line=lines[k])
            flat.append(flatten(f))
        names.update(dict.fromkeys(k for f in flat[part] for k in f))
    header = list(names)
    if isinstance(layout, (str, os.PathLike)):
        layout = load_layout(layout)

    def table():
        if len(flat) < 2:
            raise RecordingError("fewer than two frames", path=path)
        cells = np.concatenate([np.array([[str(f.get(k, "nan")) for k in header] for f in flat[part]], dtype=str)
                                for part in row_chunks(len(flat))])
        return cells, lines

    return read_wide_table(path, header, None, table, axes=axes, units=units,
                           layout=layout, rate=rate, what="JSON frames")
