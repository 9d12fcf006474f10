"""Unity ``.anim`` clips (the Unity Recorder's *Animation Clip* recorder, ``GameObjectRecorder``,
or a clip keyed by hand) as tracker recordings.

What the reader relies on (Unity's text serialization of an ``AnimationClip``, checked on
Recorder-style and hand-written clips in public repositories):

* YAML 1.1 (``%YAML 1.1``, ``--- !u!74 &7400000``, ``AnimationClip:``), two-space indentation,
  block sequences at their key's indentation (``m_PositionCurves:`` then ``- curve:``), flow
  mappings on one line (``value: {x: 0, y: 1.6, z: .5, w: 1}``), ``Infinity`` / ``-Infinity``
  for constant (stepped) tangents, keys with or without ``serializedVersion``.  A small parser of
  that subset is here: Blender ships no PyYAML.  Each ``m_Curve:`` key list in the exact form
  Unity writes (almost all of a clip) is read by one regular expression and its numbers converted
  at once (:func:`_fast_key_blocks`, 5-7x faster); any list in another form goes to the general
  parser, with the same results bit for bit;
* ``m_PositionCurves`` / ``m_RotationCurves`` (quaternion x, y, z, w) / ``m_EulerCurves``
  (degrees, the curve's ``m_RotationOrder``, Unity's default 4 = Z, X, Y) of vector keys, each
  with the ``path`` of the animated object below the recorded root
  (``XR Origin/Camera Offset/Main Camera``; ``''`` is the root itself); or the same as
  ``m_FloatCurves`` of one number each (``attribute: m_LocalPosition.x``, ``m_LocalRotation.w``,
  ``localEulerAnglesRaw.x``, ``classID: 4``).  ``m_EditorCurves`` (the editor's float copy of
  the same motion) are read only for what the other lists lack;
* the curves are local (relative to the parent object): a parent that is itself animated
  (``Camera Offset`` keyed with the rig's height) is composed in; a parent that is not keyed has
  no curve in the clip, so it is taken as identity: the root of the recorded hierarchy is the
  world (its constant offsets, e.g. an unkeyed ``Camera Offset`` height, are not in the file);
* Unity axes (left-handed, +Y up, +Z forward) and metres; times in seconds;
* ``m_CompressedRotationCurves`` (with ``m_Compressed: 1``) are Unity's packed keys, which this
  reader refuses: record with *Anim. Compression: Off*.

Devices come from each path's last name (``Main Camera``, ``CenterEyeAnchor``, ``HMD`` → head;
``LeftHand Controller``, ``Left Controller`` → left hand; ``Waist``/``Hip``/``Pelvis`` trackers,
``Left Foot`` ...; :func:`.devices.canonical_device`).  Each device is sampled at the key times of
its own curves and of its keyed parents' (every curve evaluated there as Unity does: cubic
Hermite from ``inSlope`` / ``outSlope``, a step where a tangent is infinite (constant), linear
where a key has no slopes, held before the first and after the last key; tangent weights are
not read).  A device whose curves start late or end early has samples only over its keys.
"""
from __future__ import annotations

import os
import re

import numpy as np

from . import recording as _recording
from . import rotations as rot
from .devices import DEVICES, canonical_device, device_of_object_name, snake_name
from .plain import shown
from .recording import (
    Recording, RecordingError, TrackerStream, canonical_axes, canonical_units, chunked, read_check,
    read_text, to_blender, UNITS,
)

#: Unity's ``RotationOrder`` (an Euler curve's ``m_RotationOrder``) → the fixed-axes order, first
#: rotation first, of :func:`.rotations.fixed_axes_euler_to_matrix` (4, ``OrderZXY``, is Unity's
#: ``eulerAngles``: :data:`.io_wide_csv.EULER_ORDERS` ``"unity"``)
ROTATION_ORDERS = {0: "XYZ", 1: "XZY", 2: "YZX", 3: "YXZ", 4: "ZXY", 5: "ZYX"}
#: float-curve attributes of a Transform → (channel, component)
FLOAT_ATTRIBUTES = {
    **{f"m_LocalPosition.{c}": ("pos", c) for c in "xyz"},
    **{f"m_LocalRotation.{c}": ("rot", c) for c in "xyzw"},
    **{f"{a}.{c}": ("euler", c) for a in ("localEulerAnglesRaw", "localEulerAngles", "localEulerAnglesBaked",
                                         "localEulerAnglesHint") for c in "xyz"},
}
_COMPONENTS = {"pos": "xyz", "rot": "xyzw", "euler": "xyz"}
_VECTOR_LISTS = (("m_PositionCurves", "pos"), ("m_RotationCurves", "rot"), ("m_EulerCurves", "euler"))


def looks_like_anim(head_text: str) -> bool:
    """Whether the first characters of a file are a Unity ``AnimationClip`` in text form."""
    return head_text.lstrip().startswith("%YAML") and "AnimationClip:" in head_text


# --------------------------------------------------------------------------
# the YAML subset Unity writes
class _Map(dict):
    """A YAML mapping; ``line``: the 1-based line it starts on."""
    line = 0


class _Seq(list):
    line = 0


#: a character that makes a flow mapping more than ``{x: 0, y: 1}`` (nested, quoted)
_NESTED = re.compile(r"[{}\[\]'\"]")
_KEY = re.compile(r"^([^\s'\"{\[#,][^:{}\[\],]*?|'[^']*'|\"[^\"]*\"):(?:\s+(.*))?$")


def _unquote(s, path, line):
    s = s.strip()
    if len(s) >= 2 and s[0] == s[-1] == "'":
        return s[1:-1].replace("''", "'")
    if len(s) >= 2 and s[0] == s[-1] == '"':
        import json
        try:
            return json.loads(s)
        except ValueError:
            raise RecordingError(f"bad double-quoted string {shown(s)}", path=path, line=line) from None
    if s[:1] in ("'", '"'):
        raise RecordingError(f"unterminated quoted string {shown(s)}", path=path, line=line)
    return s


def _flow(text, path, line):
    """A one-line flow value (``{x: 0, y: 1}``, ``[]``, ``[a, b]``) or a plain / quoted scalar."""
    if text[:1] not in "{['\"":
        return text
    inner = text[1:-1]
    if text[0] == "{" and text[-1] == "}" and not _NESTED.search(inner):   # a key's {x: .., y: ..}
        out = _Map()
        out.line = line
        for part in inner.split(","):
            k, colon, v = part.partition(":")
            if not colon:
                if part.strip():
                    raise RecordingError(f"a flow mapping entry {shown(part.strip())} without ':' in {shown(text)}",
                                         path=path, line=line)
                continue
            out[k.strip()] = v.strip()
        return out
    pos = 0

    def fail(why):
        raise RecordingError(f"{why} in {shown(text)}", path=path, line=line)

    def skip():
        nonlocal pos
        while pos < len(text) and text[pos] == " ":
            pos += 1

    def scalar(stops):
        nonlocal pos
        skip()
        if pos < len(text) and text[pos] in "'\"":
            q = text[pos]
            end = pos + 1
            while True:
                end = text.find(q, end)
                if end < 0:
                    fail("unterminated quoted string")
                if q == "'" and text[end + 1:end + 2] == "'":
                    end += 2
                    continue
                if q == '"' and text[end - 1] == "\\":
                    end += 1
                    continue
                break
            out = _unquote(text[pos:end + 1], path, line)
            pos = end + 1
            return out
        start = pos
        while pos < len(text) and text[pos] not in stops:
            pos += 1
        return text[start:pos].strip()

    def value(stops):
        nonlocal pos
        skip()
        if pos < len(text) and text[pos] == "{":
            pos += 1
            out = _Map()
            out.line = line
            skip()
            if pos < len(text) and text[pos] == "}":
                pos += 1
                return out
            while True:
                key = scalar(":,}")
                if pos >= len(text) or text[pos] != ":":
                    fail(f"a flow mapping entry {shown(key)} without ':'")
                pos += 1
                out[key] = value(",}")
                skip()
                if pos < len(text) and text[pos] == ",":
                    pos += 1
                    continue
                if pos < len(text) and text[pos] == "}":
                    pos += 1
                    return out
                fail("an unclosed '{'")
        if pos < len(text) and text[pos] == "[":
            pos += 1
            out = _Seq()
            out.line = line
            skip()
            if pos < len(text) and text[pos] == "]":
                pos += 1
                return out
            while True:
                out.append(value(",]"))
                skip()
                if pos < len(text) and text[pos] == ",":
                    pos += 1
                    continue
                if pos < len(text) and text[pos] == "]":
                    pos += 1
                    return out
                fail("an unclosed '['")
        return scalar(stops)

    v = value("")
    skip()
    if pos != len(text):
        fail(f"unexpected {shown(text[pos:])}")
    return v


#: a number as Unity writes it (``0``, ``-1.5``, ``.5``, ``1e-7``, ``-1.2345e+08``, ``Infinity``,
#: ``-Infinity``, ``NaN``): all that the fast key reader below accepts (``float`` reads each alike)
_NUM = r"(-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|-?Infinity|NaN)"
_EOL = r" *\r?\n"
#: the forms of a key's ``value`` / ``inSlope`` / ``outSlope``: one number (a float curve) or a
#: vector ``{x: .., y: .., z: ..}`` (``, w: ..`` for a quaternion), as Unity writes them
_KEY_FORMS = {"": _NUM, "xyz": r"\{x: %s, y: %s, z: %s\}" % ((_NUM,) * 3),
              "xyzw": r"\{x: %s, y: %s, z: %s, w: %s\}" % ((_NUM,) * 4)}
#: a key's lines after ``value:`` / ``inSlope:`` / ``outSlope:`` that Unity writes (some versions
#: not all of them), in this order: their values are not read
_KEY_TAIL = ("tangentMode", "weightedMode", "inWeight", "outWeight")
_KEY_PATTERNS = {}


def _key_pattern(indent, comps, version, tail):
    """One key at ``indent`` spaces whose values have the form ``comps`` (:data:`_KEY_FORMS`), at
    the start of a line: ``- serializedVersion: N`` (``version``; older Unity writes none), ``time:``,
    ``value:``, ``inSlope:``, ``outSlope:``, then the lines ``tail`` of :data:`_KEY_TAIL`, one per line
    in that order.  Groups: the time's, the value's, the inSlope's and the outSlope's numbers."""
    got = _KEY_PATTERNS.get((indent, comps, version, tail))
    if got is None:
        pad, form = " " * indent, _KEY_FORMS[comps]
        num = _NUM.replace("(-?", "(?:-?")                        # a number, capturing nothing
        weight = rf"(?:{num}|\{{x: {num}, y: {num}, z: {num}(?:, w: {num})?\}})"   # not read: any form
        sub = pad + "  "
        head = rf"serializedVersion: \d+{_EOL}{sub}" if version else ""
        rest = "".join(sub + name + ": " + (r"\d+" if name.endswith("Mode") else weight) + _EOL for name in tail)
        got = _KEY_PATTERNS[indent, comps, version, tail] = re.compile(
            rf"(?<=\n){pad}- {head}time: {_NUM}{_EOL}{sub}value: {form}{_EOL}{sub}inSlope: {form}{_EOL}"
            rf"{sub}outSlope: {form}{_EOL}{rest}")
    return got


#: a key's first lines, to tell its form: the indentation, whether ``serializedVersion`` is written,
#: the value's form (``{`` then the components' names) and the lines after ``outSlope`` (below)
_KEY_START = re.compile(r"( *)- (serializedVersion: \d+ *\r?\n *)?time: [^\n]*\n *value: (\{(?:x: [^,]*, y: [^,]*, "
                        r"z: [^,}]*(, w: )?)?)?[^\n]*\n *inSlope: [^\n]*\n *outSlope: [^\n]*\n")
_KEY_TAIL_LINE = re.compile(r" *(\w+): [^\n]*\n")


def _key_numbers(text, one, start, end, pad, lines_per_key, size):
    """The numbers of the keys ``one`` (:func:`_key_pattern`) from ``start`` to ``end`` of ``text``
    as a ``(K, 1 + 3 C)`` array (time, value, inSlope, outSlope), None where the keys do not cover
    every line.  Read about ``size`` characters (:data:`.recording.CHECK_ROWS` keys) at a time (cut
    where a key begins: a line ``pad + "- "``), :func:`.recording.read_check` before each, so a
    cancel stops a long clip."""
    parts, a = [], start
    while a < end:
        read_check()
        b = text.find("\n" + pad + "- ", min(a + max(size, 1), end) - 1, end) + 1 or end
        rows = one.findall(text, a, b)
        if len(rows) * lines_per_key != text.count("\n", a, b):
            return None
        parts.append(np.array(rows, dtype=np.float64).reshape(len(rows), -1))
        a = b
    return np.concatenate(parts) if parts else None


def _fast_key_blocks(text):
    """``[(head start, keys end, _KeyBlock)]`` of the ``m_Curve:`` key lists written exactly in
    Unity's form (:func:`_key_pattern`, every key alike), their numbers converted at once; a list in
    any other form (another field or order, a comment or blank line among its keys, deeper
    indentation, a number written otherwise) is left to the general parser.  The line after the keys
    must end the list (less indented, or a key at the list's indentation), so the general parser
    would end it there."""
    out = []
    find = text.find
    at = 0
    while True:
        at = find("m_Curve:", at)
        if at < 0:
            return out
        line_start = text.rfind("\n", 0, at) + 1
        indent = at - line_start
        end_head = find("\n", at)
        pad = " " * indent
        at += 8
        if (end_head < 0 or text[line_start:at] != pad + "m_Curve:" or text[at:end_head].strip(" \r")
                or not text.startswith(pad + "- ", end_head + 1)):
            continue
        start = end_head + 1
        first = _KEY_START.match(text, start)
        if not first or len(first.group(1)) != indent:
            continue
        comps = "" if not first.group(3) else ("xyzw" if first.group(4) else "xyz")
        tail, pos = [], first.end()
        for name in _KEY_TAIL:
            m = _KEY_TAIL_LINE.match(text, pos)
            if m and m.group(1) == name:
                tail.append(name)
                pos = m.end()
        lines_per_key = 4 + bool(first.group(2)) + len(tail)
        one = _key_pattern(indent, comps, bool(first.group(2)), tuple(tail))
        block = re.compile(rf"(?:{pad}[- ] [^\n]*\n)+").match(text, start)
        end = block.end()
        if end < len(text):                                    # the next line: less indented, or no "-"
            nxt = text[end:end + indent + 1]
            c = nxt.lstrip(" ")[:1]                            # "": indented deeper (or a blank line)
            if c in ("", "\t", "\r", "\n", "#") or (c == "-" and len(nxt) - len(nxt.lstrip(" ")) == indent):
                continue
        numbers = _key_numbers(text, one, start, end, pad, lines_per_key, (pos - start) * _recording.CHECK_ROWS)
        if numbers is None:
            continue             # a line no key of this form covers: matches start at line starts, so they tile
        if not np.isfinite(numbers[:, 0]).all():
            continue                                           # the general reader names the key
        out.append((line_start, end, _KeyBlock(text, start, end, 0, indent, comps, numbers)))
        at = end


class _KeyBlock:
    """An ``m_Curve`` key list read by the fast path of :func:`parse_unity_yaml`: ``time`` ``(K,)``
    seconds, ``value`` / ``in_slope`` / ``out_slope`` ``(K, C)`` float64 in the file's order, ``comps``
    the components (``""``: one number a key, C = 1; ``"xyz"``, ``"xyzw"``), ``line`` its first key's
    1-based line.  :meth:`general` is the same list as the general parser reads it."""

    def __init__(self, text, start, end, line, indent, comps, numbers):
        c = max(len(comps), 1)
        self.time = numbers[:, 0]
        self.value, self.in_slope, self.out_slope = (numbers[:, 1 + k * c:1 + (k + 1) * c] for k in range(3))
        self.comps, self.line, self.used = comps, line, False
        self._where = (text, start, end, indent)

    def general(self, path):
        """The keys as a :class:`_Seq` of :class:`_Map` (strings), read by the general parser."""
        text, start, end, indent = self._where
        lines = []
        for n, raw in enumerate(text[start:end].splitlines(), self.line):
            s = raw.rstrip()
            stripped = s.lstrip(" ")
            lines.append((n, len(s) - len(stripped), stripped))
        return _sequence(lines, 0, indent, path)[0]


class _KeysLine(str):
    """The text ``m_Curve:`` of a key list's head line whose keys the fast path read (``block``)."""
    block = None


def parse_unity_yaml(text, path="<text>", fast=True):
    """The documents of a Unity YAML file: ``[(tag, anchor, node), ...]`` (``"!u!74"``,
    ``"7400000"``, a :class:`_Map` of the document's one top-level key).  Only the subset Unity
    writes: block mappings and sequences by indentation, one-line flow collections, plain and
    quoted scalars (strings: numbers are converted by the reader).  With ``fast`` an ``m_Curve:``
    key list in Unity's exact form is a :class:`_KeyBlock` of its numbers (read with one regular
    expression and converted at once, several times faster), any other stays a :class:`_Seq` of
    the general parser.  Raises :class:`RecordingError` naming ``path``, the line and the problem
    (the general parser's: a file it refuses is read again without the fast path)."""
    blocks = _fast_key_blocks(text) if fast else []
    if not blocks:
        return _parse(text, path, [])
    try:
        docs = _parse(text, path, blocks)
    except RecordingError:
        docs = None                                       # the general parser's own error, below
    if docs is None or any(not b.used for _s, _e, b in blocks):   # (a head line not read as a key)
        return _parse(text, path, [])
    return docs


def _parse(text, path, blocks):
    """:func:`parse_unity_yaml` with the key lists ``blocks`` (:func:`_fast_key_blocks`) read."""
    docs = []
    lines = []                      # the current document's (line, indent, text)
    header = ("", "")

    def finish():
        if lines:
            node, i = _block(lines, 0, lines[0][1], path)
            if i < len(lines):
                ln = lines[i][0]
                raise RecordingError(f"unexpected indentation of {shown(lines[i][2])}", path=path, line=ln)
            docs.append((header[0], header[1], node))

    add = lines.append
    pos, n0 = 0, 1
    for seg_end, keys_end, block in blocks + [(len(text), len(text), None)]:
        piece = text[pos:seg_end].splitlines()         # ends in a line break: its lines as in one split
        for n, raw in enumerate(chunked(piece), n0):   # a cancel checked between chunks of lines
            s = raw.rstrip()
            if not s:
                continue
            stripped = s.lstrip(" ")                 # not empty: s ends in a character that is no space
            if stripped[0] == "#":
                continue
            ind = len(s) - len(stripped)
            if "\t" in s[:ind + 1]:
                raise RecordingError("a tab in the indentation (YAML indents with spaces)", path=path, line=n)
            c = s[0]
            if c == "%" and not lines:
                continue
            if c == "-" and s.startswith("---"):
                finish()
                lines = []
                add = lines.append
                parts = s.split()
                header = (parts[1] if len(parts) > 1 else "", parts[2].lstrip("&") if len(parts) > 2 else "")
                continue
            add((n, ind, stripped))
        if block is None:
            break
        n0 += len(piece)
        head = _KeysLine("m_Curve:")
        head.block = block
        block.line = n0 + 1
        add((n0, block._where[3], head))
        n0 += text.count("\n", seg_end, keys_end)      # the head line and the keys'
        pos = keys_end
    finish()
    return docs


def _block(lines, i, indent, path):
    if lines[i][2] == "-" or lines[i][2].startswith("- "):
        return _sequence(lines, i, indent, path)
    return _mapping(lines, i, indent, path)


def _value_after(lines, i, indent, path, rest, ln):
    """The value of a key on line ``ln`` (``lines[i - 1]``) whose text after the ``:`` is ``rest``:
    a scalar / flow value, else the block below it (deeper, or a sequence at the same indent)."""
    if rest:
        while rest[0] in "{[" and rest[-1] not in "}]" and _open(rest) and i < len(lines) and lines[i][1] > indent:
            rest += " " + lines[i][2]            # a flow collection over several lines
            i += 1
        return _flow(rest, path, ln), i
    if i < len(lines) and (lines[i][1] > indent or (lines[i][1] == indent and (lines[i][2] == "-"
                                                                                or lines[i][2].startswith("- ")))):
        return _block(lines, i, lines[i][1], path)
    return "", i


def _open(text):
    depth, q = 0, None
    for ch in text:
        if q:
            q = None if ch == q else q
        elif ch in "'\"":
            q = ch
        elif ch in "{[":
            depth += 1
        elif ch in "}]":
            depth -= 1
    return depth > 0


def _mapping(lines, i, indent, path):
    out = _Map()
    out.line = lines[i][0]
    n = len(lines)
    match = _KEY.match
    while i < n:
        ln, ind, text = lines[i]
        if ind < indent or (ind == indent and text[0] == "-" and text[1:2] in ("", " ")):
            break
        if ind > indent:
            raise RecordingError(f"unexpected indentation of {shown(text)}", path=path, line=ln)
        m = match(text)
        if not m:
            raise RecordingError(f"expected 'key: value', found {shown(text)}", path=path, line=ln)
        key, rest = m.group(1, 2)
        # a plain key (its first character no quote, by _KEY) is _unquote's strip
        key = _unquote(key, path, ln) if key[0] in "'\"" else key.strip()
        rest = rest.strip() if rest else ""
        if rest and rest[0] not in "{['\"":       # a plain scalar: _value_after's _flow returns it as it is
            out[key] = rest
            i += 1
            continue
        if rest and (rest[0] not in "{[" or rest[-1] in "}]"):     # one line: _value_after's _flow of it
            out[key] = _flow(rest, path, ln)
            i += 1
            continue
        if not rest and type(text) is _KeysLine:   # m_Curve: read by the fast path
            text.block.used = True
            out[key] = text.block
            i += 1
            continue
        out[key], i = _value_after(lines, i + 1, indent, path, rest, ln)
    return out, i


def _sequence(lines, i, indent, path):
    out = _Seq()
    out.line = lines[i][0]
    while i < len(lines):
        if len(out) % _recording.CHECK_ROWS == 0:
            read_check()                        # a long key list: a cancel checked every CHECK_ROWS items
        ln, ind, text = lines[i]
        if ind < indent or not (text == "-" or text.startswith("- ")):
            if ind > indent:
                raise RecordingError(f"unexpected indentation of {shown(text)}", path=path, line=ln)
            break
        if ind > indent:
            raise RecordingError(f"unexpected indentation of {shown(text)}", path=path, line=ln)
        item = text[1:].lstrip(" ")
        if not item:                             # "-" alone: the item is the block below
            if i + 1 < len(lines) and lines[i + 1][1] > indent:
                node, i = _block(lines, i + 1, lines[i + 1][1], path)
            else:
                node, i = "", i + 1
        elif item[0] not in "{['\"" and _KEY.match(item):   # "- key: value": a mapping starts here
            lines[i] = (ln, indent + len(text) - len(item), item)   # read once: the item's first key
            node, i = _mapping(lines, i, lines[i][1], path)
        else:
            node, i = _value_after(lines, i + 1, indent, path, item, ln)
        out.append(node)
    return out, i


# --------------------------------------------------------------------------
# curves
class _Curve:
    """One number's keys: ``time``, ``value``, ``in_slope``, ``out_slope`` ``(K,)`` float64
    (slopes NaN where the key has none: linear), sorted by time."""

    def __init__(self, time, value, in_slope, out_slope, line):
        order = np.argsort(time, kind="stable")
        self.time, self.value = time[order], value[order]
        self.in_slope, self.out_slope = in_slope[order], out_slope[order]
        self.line = line

    def __call__(self, t):
        """The curve at times ``t`` ``(N,)`` seconds, as Unity evaluates it (module docstring)."""
        t = np.asarray(t, np.float64)
        k = self.time
        if len(k) == 1:
            return np.full(t.shape, self.value[0])
        i = np.clip(np.searchsorted(k, t, side="right") - 1, 0, len(k) - 2)
        t0, t1 = k[i], k[i + 1]
        v0, v1 = self.value[i], self.value[i + 1]
        dt = t1 - t0
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.clip(np.where(dt > 0, (t - t0) / np.where(dt > 0, dt, 1.0), 1.0), 0.0, 1.0)
            m0, m1 = self.out_slope[i], self.in_slope[i + 1]
            linear = v0 + (v1 - v0) * s
            s2, s3 = s * s, s * s * s
            hermite = ((2 * s3 - 3 * s2 + 1) * v0 + (s3 - 2 * s2 + s) * m0 * dt
                       + (-2 * s3 + 3 * s2) * v1 + (s3 - s2) * m1 * dt)
        out = np.where(np.isnan(m0) | np.isnan(m1), linear, hermite)
        step = np.isinf(m0) | np.isinf(m1)
        out = np.where(step, np.where(s >= 1.0, v1, v0), out)
        out = np.where(t <= k[0], self.value[0], out)
        return np.where(t >= k[-1], self.value[-1], out)


def _number(text, what, path, line):
    try:
        return float(text)
    except (TypeError, ValueError):
        raise RecordingError(f"{what} {shown(text)} is not a number", path=path, line=line) from None


def _keys(curve_item, components, path, where):
    """``{component: _Curve}`` of a curve entry's ``m_Curve`` keys; ``components``: ``"xyz"`` /
    ``"xyzw"`` for vector keys, or ``None`` for a float curve (the result's key ``""``)."""
    curve = curve_item.get("curve")
    if not isinstance(curve, dict):
        raise RecordingError(f"{where}: no 'curve:' mapping", path=path, line=curve_item.line)
    keys = curve.get("m_Curve", _Seq())
    if isinstance(keys, _KeyBlock):
        if (components is None) == (keys.comps == "") and set(components or "") <= set(keys.comps) \
                and np.isfinite(keys.time).all() and np.isfinite(keys.value).all():
            cols = (keys.value, keys.in_slope, keys.out_slope)
            return {c: _Curve(keys.time, *(a[:, keys.comps.index(c) if c else 0] for a in cols), line=curve.line)
                    for c in components or ("",)}
        keys = keys.general(path)                        # not this list's form: read as the general parser does
    if keys == "":
        keys = _Seq()
    if not isinstance(keys, list):
        raise RecordingError(f"{where}: m_Curve is not a list of keys", path=path, line=curve.line)
    comps = components or ("",)
    cols = {c: ([], [], [], []) for c in comps}
    times = []
    fields = [(field, n, [(c, cols[c][n].append) for c in comps]) for field, n in
              (("value", 1), ("inSlope", 2), ("outSlope", 3))]
    nan, isfinite = np.nan, np.isfinite
    for key in keys:
        line = getattr(key, "line", curve.line)
        if not isinstance(key, dict):
            raise RecordingError(f"{where}: a key {shown(key)} that is not a mapping", path=path, line=line)
        if "time" not in key:
            raise RecordingError(f"{where}: a key without time", path=path, line=line)
        t = _number(key["time"], "time", path, line)
        if not isfinite(t):
            raise RecordingError(f"{where}: key time {shown(key['time'])} is not finite", path=path, line=line)
        times.append(t)
        for field, n, adds in fields:
            v = key.get(field)
            if v is None:
                if field == "value":
                    raise RecordingError(f"{where}: a key without value", path=path, line=line)
                for _, add in adds:
                    add(nan)
                continue
            is_map = isinstance(v, dict)
            for c, add in adds:
                if components is None:
                    x = v
                elif is_map and c in v:
                    x = v[c]
                else:
                    raise RecordingError(f"{where}: {field} {shown(v)} has no {c}", path=path, line=line)
                try:
                    x = float(x)
                except (TypeError, ValueError):
                    _number(x, f"{field}{'.' + c if c else ''}", path, line)     # raises, naming it
                    raise
                if n == 1 and not isfinite(x):          # slopes may be Infinity (a stepped key)
                    raise RecordingError(f"{where}: key value{'.' + c if c else ''} {shown(x)} is not finite",
                                         path=path, line=line)
                add(x)
    if not times:
        return {}
    t = np.asarray(times)
    return {c: _Curve(t, *(np.asarray(cols[c][n], np.float64) for n in (1, 2, 3)), line=curve.line) for c in comps}


def _collect(clip, path):
    """``{object path: {channel: {component: _Curve}}}`` (channels ``pos``, ``rot``, ``euler``;
    also ``order``: the Euler curves' rotation order), and the lists read."""
    found = {}
    orders = {}

    def put(obj, channel, comp_curves, order=None, only_missing=False):
        chans = found.setdefault(obj, {})
        if only_missing and (channel in chans or (channel in ("rot", "euler") and ({"rot", "euler"} & set(chans)))):
            return False
        if channel == "euler" and order is not None:
            orders[obj] = order
        chans.setdefault(channel, {}).update(comp_curves)
        return True

    for list_name, channel in _VECTOR_LISTS:
        items = clip.get(list_name) or _Seq()
        for n, item in enumerate(items):
            if not isinstance(item, dict):
                raise RecordingError(f"{list_name}[{n}] is not a curve", path=path, line=items.line)
            curves = _keys(item, _COMPONENTS[channel], path, f"{list_name}[{n}]")
            order = None
            if channel == "euler":
                order = ROTATION_ORDERS.get(int(_number((item.get("curve") or {}).get("m_RotationOrder", 4),
                                                        "m_RotationOrder", path, item.line)), "ZXY")
            if curves:
                put(str(item.get("path") or ""), channel, curves, order)
    for list_name in ("m_FloatCurves", "m_EditorCurves"):
        items = clip.get(list_name) or _Seq()
        pending = {}
        for n, item in enumerate(items):
            if not isinstance(item, dict):
                raise RecordingError(f"{list_name}[{n}] is not a curve", path=path, line=items.line)
            attr = str(item.get("attribute") or "")
            if attr not in FLOAT_ATTRIBUTES or str(item.get("classID", "4")) != "4":
                continue
            channel, comp = FLOAT_ATTRIBUTES[attr]
            curves = _keys(item, None, path, f"{list_name}[{n}] ({attr})")
            if curves:
                obj = str(item.get("path") or "")
                pending.setdefault((obj, channel), {})[comp] = curves[""]
                order = ROTATION_ORDERS.get(int(_number((item.get("curve") or {}).get("m_RotationOrder", 4),
                                                        "m_RotationOrder", path, item.line)), "ZXY")
                if channel == "euler":
                    orders.setdefault(obj, order)
        for (obj, channel), comps in pending.items():
            put(obj, channel, comps, only_missing=list_name == "m_EditorCurves")
    return found, orders


#: Unity class IDs of float curves that are not a Transform's, for the refusal's words
_CLASS_NAMES = {"1": "GameObject", "95": "Animator", "114": "script", "212": "SpriteRenderer",
                "224": "RectTransform", "23": "MeshRenderer", "137": "SkinnedMeshRenderer"}


def _what_it_animates(clip, paths):
    """The end of a refusal or warning: the objects whose Transform the clip animates (the root,
    path ``''``, named so), else the other properties its float curves animate (a humanoid clip's
    Animator muscle curves, a UI or script property) or that it has no curve."""
    if paths:
        return "the clip animates " + ", ".join(shown(p) if p else "the root object (path '')" for p in paths)
    other = []
    for list_name in ("m_FloatCurves", "m_PPtrCurves"):
        for item in clip.get(list_name) or ():
            if isinstance(item, dict):
                cls = str(item.get("classID", "")).strip()
                what = f"{_CLASS_NAMES.get(cls, 'class ' + cls)} {shown(str(item.get('attribute') or ''))}"
                other.append(what if not item.get("path") else f"{what} of {shown(str(item.get('path')))}")
    if not other:
        return "the clip has no curve"
    humanoid = any(w.startswith("Animator ") for w in other)
    listed = ", ".join(other[:4]) + (f" and {len(other) - 4} more" if len(other) > 4 else "")
    return (f"the clip animates no Transform, only {listed}"
            + (" (a humanoid clip's muscle curves: record the tracked objects' Transforms instead)"
               if humanoid else ""))


def _local_pose(chans, order, t):
    """``(pos (N, 3), quat (N, 4) wxyz)`` of an object's local curves at times ``t``, Unity axes;
    components without a curve are 0 (position, Euler) or identity."""
    n = len(t)
    pos = np.zeros((n, 3))
    for a, c in enumerate("xyz"):
        if c in chans.get("pos", {}):
            pos[:, a] = chans["pos"][c](t)
    if "rot" in chans:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        for a, c in zip((1, 2, 3, 0), "xyzw"):
            if c in chans["rot"]:
                q[:, a] = chans["rot"][c](t)
            elif c != "w":
                q[:, a] = 0.0
        quat = rot.normalize(q)
    elif "euler" in chans:
        deg = np.zeros((n, 3))
        for a, c in enumerate("xyz"):
            if c in chans["euler"]:
                deg[:, a] = chans["euler"][c](t)
        quat = rot.matrix_to_quat(rot.fixed_axes_euler_to_matrix(np.radians(deg), order))
    else:
        quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return pos, quat


def _key_times(chans):
    return np.unique(np.concatenate([cv.time for ch in ("pos", "rot", "euler") for cv in chans.get(ch, {}).values()]
                                    or [np.zeros(0)]))


def _device_of_path(obj):
    """The device an object path's last name stands for (also with a ``Tracker`` / ``VR`` word
    around it: ``Hip Tracker``, ``Pelvis Tracker``; :func:`.devices.device_of_object_name`), or None."""
    name = obj.rsplit("/", 1)[-1].strip()
    if not name:
        return None
    return (canonical_device(snake_name(name)) or canonical_device(name)
            or device_of_object_name(snake_name(name)))


def read_unity_anim(path, axes=None, units=None) -> Recording:
    """Read a Unity ``.anim`` clip's tracked objects (module docstring): a :class:`Recording` in
    Blender axes and metres, one stream per device found in the clip's object paths, with the
    paths and what was composed in ``metadata`` (``detected``, ``device_paths``,
    ``device_labels``).  ``axes`` / ``units`` override Unity's (left-handed Y up, metres).
    Raises :class:`RecordingError` naming the file, the line and the problem."""
    path = os.fspath(path)
    text = read_text(path)
    if not looks_like_anim(text[:4096]):
        raise RecordingError("not a Unity animation clip (no '%YAML' header and 'AnimationClip:')", path=path, line=1)
    axes = canonical_axes(axes or "unity")
    units = canonical_units(units or "m")
    docs = parse_unity_yaml(text, path)
    clip = next((node["AnimationClip"] for _tag, _anchor, node in docs
                 if isinstance(node, dict) and isinstance(node.get("AnimationClip"), dict)), None)
    if clip is None:
        raise RecordingError("no AnimationClip document in the file", path=path)
    compressed = clip.get("m_CompressedRotationCurves")
    if str(clip.get("m_Compressed", "0")).strip() not in ("0", "") or (isinstance(compressed, list) and compressed):
        line = getattr(compressed, "line", None) if compressed else None
        raise RecordingError("the clip's rotations are compressed (m_Compressed / m_CompressedRotationCurves), "
                             "which this reader does not unpack: record with compression off (the Recorder's "
                             "Animation Clip settings: Anim. Compression: Off)", path=path, line=line or clip.line)
    found, orders = _collect(clip, path)
    paths = sorted(p for p, ch in found.items() if any(ch.get(k) for k in ("pos", "rot", "euler")))
    devices, labels, warnings = {}, {}, []
    for p in paths:
        d = _device_of_path(p)
        if d is None:
            continue
        if d in devices:
            warnings.append(f"{d}: {shown(p)} also names it; {shown(devices[d])} used")
            continue
        devices[d] = p
        labels[d] = p.rsplit("/", 1)[-1]
    if "head" not in devices:
        raise RecordingError(f"no head curve: no animated object's name is a headset or head (Main Camera, "
                             f"CenterEyeAnchor, HMD, Head ...); {_what_it_animates(clip, paths)}", path=path)
    scale = UNITS[units]
    streams, composed = {}, {}
    for d in DEVICES:
        if d not in devices:
            continue
        p = devices[d]
        parts = p.split("/")
        chain = [q for q in ("/".join(parts[:k]) for k in range(0, len(parts))) if q in found] + [p]
        t = _key_times(found[p])
        if not len(t):
            continue
        wp, wq = np.zeros((len(t), 3)), np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
        for q in chain:                       # root first: world = parent's world * local
            lp, lq = _local_pose(found[q], orders.get(q, "ZXY"), t)
            wp = wp + rot.quat_rotate(wq, lp)
            wq = rot.normalize(rot.quat_mul(wq, lq))
        if len(chain) > 1:
            composed[d] = [q or "(root)" for q in chain[:-1]]
        bp, bq = to_blender(wp * scale, wq, axes)
        ok = np.all(np.isfinite(bp), -1) & np.all(np.isfinite(bq), -1)
        streams[d] = TrackerStream(d, t, bp, bq, ok)
    missing = [d for d in ("left_hand", "right_hand") if d not in streams]
    if missing:
        warnings.append(f"no curve for {', '.join(missing)}: {_what_it_animates(clip, paths)}")
    rate = clip.get("m_SampleRate")
    where = "; ".join(f"{d}={shown(devices[d])}" for d in DEVICES if d in devices)
    parents = ("; composed with the keyed parents " + ", ".join(f"{d}: {'/'.join(shown(x) for x in c)}"
                                                                for d, c in composed.items())) if composed else ""
    detected = (f"Unity .anim: {where}{parents}; unkeyed parents are not in the .anim (their constant offsets, e.g. "
                f"an unkeyed Camera Offset height, are left out): the recorded root is taken as the world; "
                f"axes {axes}, units {units}")
    meta = {"format": "unity_anim", "axes": axes, "units": units, "detected": detected,
            "name": str(clip.get("m_Name", "")), "device_paths": dict(devices), "device_labels": labels,
            "composed": composed}
    if rate not in (None, ""):
        try:
            meta["sample_rate"] = float(rate)
        except (TypeError, ValueError):
            pass
    return Recording(streams=streams, source=path, metadata=meta, warnings=warnings)
