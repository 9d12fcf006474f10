"""JSON output of a solved animation, its JSON Schema and a dependency-free validator.

numpy only, never imports bpy.

Document (one per input, ``DIR/STEM.json``)
-------------------------------------------
==============  ===========================================================
key             value
==============  ===========================================================
``version``     format version, integer (:data:`FORMAT_VERSION`)
``source``      string: what was solved (the input file name, or "scene")
``generator``   string: "blender_manikin X.Y.Z" (optional)
``fps``         frames per second, number > 0
``t0``          seconds: the recording-clock time of frame 0, i.e. of the
                first tracker sample.  Frame ``k`` is at ``t0 + k / fps``,
                i.e. ``k / fps`` after the first tracker sample.
``num_frames``  number of frames ``T`` (optional; equals ``len(positions)``)
``units``       ``"m"``; ``axes``: ``"blender"`` (right-handed, +Z up, the
                body faces -Y, the performer's left is +X)
``joints``      the 22 joint names, SMPL order (:data:`skeleton.JOINT_NAMES`)
``parents``     22 parent indices, -1 for the root (pelvis)
``positions``   ``T x 22 x 3`` world joint positions, metres
``rotations``   ``T x 22 x 4`` world joint orientations, unit quaternions
                ``w, x, y, z``; identity = the rest T-pose (every joint frame
                aligned with the world axes); sign-continuous over time
``swivel``      ``{"left_arm", "right_arm", "left_leg", "right_leg"}``: ``T``
                swivel angles each, radians in (-pi, pi]
``trackers``    ``{device: T x 3}``: the device targets after device offsets,
                metres, Blender world axes; ``null`` where not finite.
                Devices from ``head, left_hand, right_hand, pelvis,
                left_foot, right_foot``
``contacts``    optional ``{"left_foot", "right_foot"}``: ``T`` booleans
==============  ===========================================================

Numbers are rounded to ``decimals`` (default 6: micrometres, microradians).
"""
from __future__ import annotations

import json
import math

import numpy as np

from . import rotations as rot
from . import skeleton as sk
from .file_names import written_whole
from .plain import shown
from .pose_result import DEVICES

FORMAT_VERSION = 1
SWIVEL_KEYS = tuple(sk.LIMB_NAMES)      # left_arm, right_arm, left_leg, right_leg


def _vec(n, nullable=False):
    item = {"type": ["number", "null"]} if nullable else {"type": "number"}
    return {"type": "array", "minItems": n, "maxItems": n, "items": item}


def _frames_of(schema):
    return {"type": "array", "items": schema}


#: JSON Schema (draft 2020-12) of the document written by :func:`write_json`.
JSON_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://github.com/blender-manikin/blender_manikin/schema/animation-v1.json",
    "title": "blender_manikin solved full-body animation",
    "type": "object",
    "required": ["version", "source", "fps", "t0", "joints", "parents", "positions",
                 "rotations", "swivel", "trackers"],
    "additionalProperties": False,
    "properties": {
        "version": {"type": "integer", "const": FORMAT_VERSION},
        "source": {"type": "string"},
        "generator": {"type": "string"},
        "fps": {"type": "number", "exclusiveMinimum": 0},
        "t0": {"type": "number"},
        "num_frames": {"type": "integer", "minimum": 0},
        "units": {"const": "m"},
        "axes": {"const": "blender"},
        "joints": {"const": list(sk.JOINT_NAMES)},
        "parents": {"const": [int(p) for p in sk.PARENTS]},
        "positions": _frames_of(_frames_of(_vec(3)) | {"minItems": sk.NUM_JOINTS,
                                                        "maxItems": sk.NUM_JOINTS}),
        "rotations": _frames_of(_frames_of(_vec(4)) | {"minItems": sk.NUM_JOINTS,
                                                        "maxItems": sk.NUM_JOINTS}),
        "swivel": {
            "type": "object",
            "required": list(SWIVEL_KEYS),
            "additionalProperties": False,
            "properties": {k: _frames_of({"type": "number", "minimum": -math.pi - 1e-6,
                                          "maximum": math.pi + 1e-6}) for k in SWIVEL_KEYS},
        },
        "trackers": {
            "type": "object",
            "propertyNames": {"enum": list(DEVICES)},
            "additionalProperties": _frames_of(_vec(3, nullable=True)),
        },
        "contacts": {
            "type": "object",
            "required": ["left_foot", "right_foot"],
            "additionalProperties": False,
            "properties": {k: _frames_of({"type": "boolean"}) for k in ("left_foot", "right_foot")},
        },
    },
}


# --------------------------------------------------------------------------
# writing
def _rounded(a, decimals):
    a = np.asarray(a, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError("non-finite values in the solved animation")
    return np.round(a, decimals).tolist()


def _rounded_nullable(a, decimals):
    a = np.round(np.asarray(a, dtype=np.float64), decimals)
    ok = np.isfinite(a)
    if ok.all():
        return a.tolist()
    return [[float(v) if f else None for v, f in zip(row, frow)] for row, frow in zip(a, ok)]


def _wrap(a):
    w = np.angle(np.exp(1j * np.asarray(a, dtype=np.float64)))
    return np.where(w <= -np.pi, w + 2 * np.pi, w)


def _pose_chunks(result):
    """``(positions (n,22,3), rotations (n,22,4), swivel (n,4))`` for successive frame chunks
    (:meth:`PoseResult.fk_chunks`): world positions, world quaternions sign-continuous over the
    whole take, swivel wrapped.  The same numbers as one pass over the take (the sign carries
    over from chunk to chunk)."""
    sw_all = np.asarray(result.swivel, dtype=np.float64).reshape(result.num_frames, len(SWIVEL_KEYS))
    last = None
    for f, pos, wrot in result.fk_chunks():
        q = rot.matrix_to_quat(wrot)
        if last is not None:          # continue the sign from the previous chunk's last frame
            q = rot.quat_continuous(np.concatenate([last[None], q], 0), axis=0)[1:]
        else:
            q = rot.quat_continuous(q, axis=0)
        last = q[-1]
        yield pos, q, _wrap(sw_all[f])


def _pose_arrays(result):
    """``(positions (T,22,3), rotations (T,22,4) sign-continuous, swivel (T,4) wrapped)``."""
    parts = list(_pose_chunks(result))
    if not parts:
        return np.zeros((0, sk.NUM_JOINTS, 3)), np.zeros((0, sk.NUM_JOINTS, 4)), np.zeros((0, len(SWIVEL_KEYS)))
    return tuple(np.concatenate(x, 0) for x in zip(*parts))


def _header(result, source, decimals, generator):
    """Every field except positions / rotations / swivel, in document order (those as None)."""
    T = result.num_frames
    if generator is None:
        from .version import __version__
        generator = f"blender_manikin {__version__}"
    doc = {
        "version": FORMAT_VERSION,
        "source": str(source),
        "generator": generator,
        "fps": float(result.fps),
        "t0": float(result.t0),
        "num_frames": T,
        "units": "m",
        "axes": "blender",
        "joints": list(sk.JOINT_NAMES),
        "parents": [int(p) for p in sk.PARENTS],
        "positions": None,
        "rotations": None,
        "swivel": None,
        "trackers": {},
    }
    targets = getattr(result, "targets", None)
    if targets is not None:
        for dev in DEVICES:
            if dev in targets.pos:
                p = np.asarray(targets.pos[dev], dtype=np.float64).reshape(-1, 3)
                if p.shape[0] != T:
                    raise ValueError(f"tracker {shown(dev)} has {p.shape[0]} frames, the solve {T}")
                doc["trackers"][dev] = _rounded_nullable(p, decimals)
    if getattr(result, "contacts", None) is not None:
        c = np.asarray(result.contacts, dtype=bool).reshape(T, 2)
        doc["contacts"] = {"left_foot": c[:, 0].tolist(), "right_foot": c[:, 1].tolist()}
    return doc


def result_to_dict(result, source: str = "", decimals: int = 6, generator: str | None = None) -> dict:
    """The JSON document (a dict of lists) for a :class:`PoseResult`."""
    doc = _header(result, source, decimals, generator)
    pos, q, sw = _pose_arrays(result)
    doc["positions"] = _rounded(pos, decimals)
    doc["rotations"] = _rounded(q, decimals)
    doc["swivel"] = {k: _rounded(sw[:, i], decimals) for i, k in enumerate(SWIVEL_KEYS)}
    return doc


def _fast_rows(a, decimals):
    """JSON text of the rows of a finite float array ``(n, ...)``, comma-separated, without the
    enclosing brackets; numbers with ``decimals`` fixed decimals."""
    a = np.asarray(a, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError("non-finite values in the solved animation")
    a = np.round(a, decimals) + 0.0          # + 0.0 turns -0.0 into 0.0
    num = f"%.{int(decimals)}f"

    def tpl(shape):
        if len(shape) == 0:
            return num
        return "[" + ",".join([tpl(shape[1:])] * shape[0]) + "]"
    row = tpl(a.shape[1:])
    return ",".join(row % tuple(r) for r in a.reshape(a.shape[0], -1).tolist())


def _fast_array(a, decimals):
    """JSON text of a finite float array (any shape), numbers with ``decimals`` fixed decimals."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 0:
        if not np.isfinite(a):
            raise ValueError("non-finite values in the solved animation")
        return f"%.{int(decimals)}f" % float(np.round(a, decimals) + 0.0)
    return "[" + _fast_rows(a, decimals) + "]"


def write_json(path, result, source: str = "", decimals: int = 6, indent=None, generator=None):
    """Write the JSON document of ``result`` to ``path`` (UTF-8); returns ``path``.

    The per-frame pose arrays are formatted straight from numpy with
    ``decimals`` fixed decimals (about 10x faster than ``json.dump`` of nested
    lists), :data:`.pose_result.CHUNK_FRAMES` frames at a time straight into the file, so a
    long take needs no more memory than a short one; ``indent`` applies to the
    other fields.  Written under a temporary name, then renamed.
    """
    doc = _header(result, source, decimals, generator)
    T = result.num_frames
    sw = _wrap(np.asarray(result.swivel, dtype=np.float64).reshape(T, len(SWIVEL_KEYS)))
    small = {"swivel": "{" + ",".join(f"{json.dumps(k)}:{_fast_array(sw[:, i], decimals)}"
                                      for i, k in enumerate(SWIVEL_KEYS)) + "}"}
    targets = getattr(result, "targets", None)
    if targets is not None and all(np.all(np.isfinite(targets.pos[d])) for d in doc["trackers"]):
        small["trackers"] = "{" + ",".join(f"{json.dumps(d)}:{_fast_array(targets.pos[d], decimals)}"
                                           for d in doc["trackers"]) + "}"
    sep = ",\n" if indent else ","
    with written_whole(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        f.write("{")
        for i, (k, v) in enumerate(doc.items()):
            if i:
                f.write(sep)
            f.write(f"{json.dumps(k)}:")
            if k in ("positions", "rotations"):
                f.write("[")
                for c, (pos, q, _) in enumerate(_pose_chunks(result)):
                    f.write(("," if c else "") + _fast_rows(pos if k == "positions" else q, decimals))
                f.write("]")
            else:
                f.write(small[k] if k in small else json.dumps(v, indent=indent, allow_nan=False))
        f.write("}\n")
    return path


def read_json(path) -> dict:
    with open(path, encoding="utf-8") as f:
        return json.load(f)


# --------------------------------------------------------------------------
# validation (the subset of JSON Schema that JSON_SCHEMA uses)
_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
    "integer": lambda v: (isinstance(v, int) and not isinstance(v, bool))
    or (isinstance(v, float) and v.is_integer()),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v),
}


def validate(instance, schema=None, path="$", max_errors=20) -> list:
    """Validate ``instance`` against ``schema`` (default :data:`JSON_SCHEMA`).

    Supports ``type``, ``const``, ``enum``, ``required``, ``properties``,
    ``additionalProperties``, ``propertyNames``, ``items``, ``minItems``,
    ``maxItems``, ``minimum``, ``maximum``, ``exclusiveMinimum``.
    Returns a list of error strings (empty when valid), at most ``max_errors``.
    """
    errors = []
    _validate(instance, JSON_SCHEMA if schema is None else schema, path, errors, max_errors)
    return errors


def _validate(v, s, path, errors, max_errors):
    if len(errors) >= max_errors:
        return
    if s is True or s == {}:
        return
    if s is False:
        errors.append(f"{path}: not allowed")
        return
    t = s.get("type")
    if t is not None:
        types = t if isinstance(t, list) else [t]
        if not any(_TYPES[x](v) for x in types):
            errors.append(f"{path}: expected {t}, got {type(v).__name__}")
            return
    if "const" in s and v != s["const"]:
        errors.append(f"{path}: must equal {shown(s['const'])}")
    if "enum" in s and v not in s["enum"]:
        errors.append(f"{path}: {shown(v)} not one of {shown(s['enum'])}")
    if _TYPES["number"](v):
        if "minimum" in s and v < s["minimum"]:
            errors.append(f"{path}: {v} < minimum {s['minimum']}")
        if "maximum" in s and v > s["maximum"]:
            errors.append(f"{path}: {v} > maximum {s['maximum']}")
        if "exclusiveMinimum" in s and v <= s["exclusiveMinimum"]:
            errors.append(f"{path}: {v} <= exclusiveMinimum {s['exclusiveMinimum']}")
    if isinstance(v, dict):
        for k in s.get("required", ()):
            if k not in v:
                errors.append(f"{path}: missing required {shown(k)}")
        props = s.get("properties", {})
        addl = s.get("additionalProperties", True)
        pn = s.get("propertyNames")
        for k, item in v.items():
            if pn is not None:
                _validate(k, pn, f"{path}.<key {shown(k)}>", errors, max_errors)
            if k in props:
                _validate(item, props[k], f"{path}.{k}", errors, max_errors)
            elif addl is False:
                errors.append(f"{path}: unexpected key {shown(k)}")
            elif isinstance(addl, dict):
                _validate(item, addl, f"{path}.{k}", errors, max_errors)
            if len(errors) >= max_errors:
                return
    if isinstance(v, list):
        if "minItems" in s and len(v) < s["minItems"]:
            errors.append(f"{path}: {len(v)} items < minItems {s['minItems']}")
        if "maxItems" in s and len(v) > s["maxItems"]:
            errors.append(f"{path}: {len(v)} items > maxItems {s['maxItems']}")
        item_s = s.get("items")
        if item_s is not None:
            for i, item in enumerate(v):
                _validate(item, item_s, f"{path}[{i}]", errors, max_errors)
                if len(errors) >= max_errors:
                    return


def validate_document(doc, max_errors=20) -> list:
    """:func:`validate` against :data:`JSON_SCHEMA` plus cross-field checks:
    every per-frame array has the same number of frames (and ``num_frames``
    when present) and rotations are unit quaternions (±1e-4)."""
    errors = validate(doc, JSON_SCHEMA, max_errors=max_errors)
    if errors or not isinstance(doc, dict):
        return errors
    T = len(doc["positions"])
    counts = {"rotations": len(doc["rotations"])}
    counts.update({f"swivel.{k}": len(v) for k, v in doc["swivel"].items()})
    counts.update({f"trackers.{k}": len(v) for k, v in doc["trackers"].items()})
    if "contacts" in doc:
        counts.update({f"contacts.{k}": len(v) for k, v in doc["contacts"].items()})
    if "num_frames" in doc:
        counts["num_frames"] = doc["num_frames"]
    for k, n in counts.items():
        if n != T:
            errors.append(f"$.{k}: {n} frames, positions has {T}")
    if T:
        q = np.asarray(doc["rotations"], dtype=np.float64)
        bad = np.abs(np.linalg.norm(q, axis=-1) - 1.0) > 1e-4
        if bad.any():
            t, j = np.argwhere(bad)[0]
            errors.append(f"$.rotations[{t}][{j}]: not a unit quaternion")
    return errors[:max_errors]
