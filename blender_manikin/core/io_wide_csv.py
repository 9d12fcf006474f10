"""Wide CSV layouts: one row per time step, one group of columns per device, as research datasets
and recorder tools write them (Unity / Unreal loggers, SteamVR and OpenXR dumps, BOXRR-style
exports).  The layout is detected from the header and the data, and said in one line
(``Recording.metadata["detected"]``), e.g.::

    wide layout: head=hmd_*, hands=left_controller_*/right_controller_*; quaternions x,y,z,w;
    time=timestamp in ms; units cm (head at 1.62 m); axes unity (left-handed), from the walking
    direction (41.3 s forward)

Detected:

* devices from column prefixes, with the aliases of :data:`.devices.ALIASES` (``hmd``, ``head``,
  ``headset``; ``left_controller``, ``controller_left``, ``LeftHand``, ``l_hand``, ...; ``waist``,
  ``pelvis``, ``hip``; ``left_foot``, ``foot_l``, ``tracker_left_foot``, ...);
* components: ``<dev>_pos_x``, ``<dev>_position_x``, ``<dev>.position.x``, ``<dev>_x`` for
  positions, ``<dev>_rot_{w,x,y,z}``, ``<dev>_quat_*``, ``<dev>.rotation.*`` for quaternions, in
  any column order (the letters name the components); pose matrices ``<dev>_m00`` ... ``<dev>_m23``
  (OpenVR's ``HmdMatrix34_t``, row-major); Unity's ``(x, y, z)`` tuples and Unreal's ``ToString()``
  (``X=.. Y=.. Z=..``, ``P=.. Y=.. R=..``) in one field;
* Euler angles: three columns ``<dev>_rot_{x,y,z}``, ``<dev>_euler_*``, ``<dev>_angles_*``,
  degrees when any exceeds 2π + 0.5, else radians; rotations about the fixed axes applied in
  :data:`EULER_ORDERS` order (Unity's Z, X, Y for a Unity file; an Unreal file's are its
  rotator's roll, pitch and yaw, :data:`ROTATOR`), unless a layout file's ``"euler"`` states the
  order and unit; ``<dev>_rot_{pitch,yaw,roll}`` columns are an Unreal rotator (Unreal's axes; a
  file whose head stands along Y, or given other axes, is refused);
* field separators (:func:`sniff_delimiter`: commas, semicolons or tabs) and decimal commas (a
  file not separated by commas with commas in its numbers);
* time: a ``time``/``t``/``seconds``/``timestamp`` column, in seconds, or in milliseconds, µs or
  ns when its steps say so (no tracker samples slower than 2 Hz), ``time_ms`` (milliseconds; a
  layout file's ``"unit"`` decides too), ``delta_time_ms``/``dt`` (per-row deltas), ISO 8601 date-times or times
  of day (:func:`iso_seconds`), or only a frame counter
  (``frame``, ``frame_index``, ...) with the rate given (``rate``); an unnamed first column
  (a pandas index) is ignored;
* units from an arm's length (:func:`.axes_detect.length_units`: the hands 55 apart from the head
  means centimetres), wherever the origin is;
* axes: Y-up or Z-up from the head's height, or where that is unclear from the hands below the
  head and the headset's own up axis (:func:`.axes_detect.up_axis`); between Blender
  (right-handed) and Unreal (left-handed, +X forward), the one that sees the left hand on the
  head's left, else the cues below; between Unity (left-handed, +Z forward) and
  OpenXR/OpenVR (right-handed, -Z forward), the convention the take faces forward in: the way
  the performer walks, else the head turning about the neck behind it, else the hands reaching
  ahead of the head (:func:`.axes_detect.choose_axes`; datasets' READMEs are not always right
  about their axes).

``axes`` / ``units`` given by the user override the detection.  Ambiguity (two column groups
for one device, a quaternion without all four components) is a :class:`RecordingError` that
names the candidates.
"""
from __future__ import annotations

import os
import re

import numpy as np

from .devices import DEVICES, canonical_device, snake_name
from .plain import shown
from .recording import (LEFT_HANDED, Recording, RecordingError, TrackerStream, UNITS, canonical_axes, canonical_units,
                        decode_text, json_key_line, load_json_file, read_check, read_file_bytes, read_text,
                        row_chunks, time_unit_of_step, to_blender)
from . import rotations as rot
from .rotations import normalize
from .axes_detect import choose_axes, heading_from_positions, heading_quats, length_units, up_axis, yaw_of
from .features import heading_yaw

_POS_WORDS = ("pos", "position", "p", "loc", "location", "")
_ROT_WORDS = ("rot", "rotation", "quat", "quaternion", "q", "orientation", "euler", "eul", "angles", "ang")
_FRAMES = ("frame", "frame_index", "frame_number", "frame_no", "frame_id", "frames")
_TIME_S = ("time", "t", "seconds", "time_s", "secs", "datetime", "date_time", "time_utc", "utc_time",
           "timestamp_utc", "time_of_day")
_TIME_MS = ("timestamp", "time_ms", "timestamp_ms", "ms")
#: of those, the names that say milliseconds (a ``timestamp`` may be in seconds, as Unix time is)
_NAMED_MS = ("time_ms", "timestamp_ms", "ms")
_DELTA_MS = ("delta_time_ms", "dt_ms", "delta_ms", "frame_time_ms")
_DELTA_S = ("delta_time", "dt", "delta_time_s")
#: time columns in nanoseconds / microseconds (OpenXR's ``XrTime``, Quest SDK dumps' ``timestampNs``)
_TIME_NS_US = {"time_ns": "time_ns", "timestamp_ns": "time_ns", "time_us": "time_us", "timestamp_us": "time_us"}
#: field separators, in the order a tie goes: commas; semicolons (spreadsheets and loggers on a
#: locale with decimal commas, Unity's float.ToString() on a German or French machine); tabs
DELIMITERS = (",", ";", "\t")
_DELIMITER_NAMES = {",": "commas", ";": "semicolons", "\t": "tabs"}


def sniff_delimiter(header_line):
    """The field separator of :data:`DELIMITERS` that splits the header line into the most
    fields (commas on a tie)."""
    return max(DELIMITERS, key=lambda d: len(header_line.split(d)))


#: a parenthesised tuple in one field, as Unity's Vector3 / Quaternion ToString() writes it:
#: "(0.10, 1.60, 0.20)", "(0.00000, 0.70711, 0.00000, 0.70711)" (x, y, z, w)
_TUPLE = re.compile(r"\(([^()]*)\)")


#: Unreal's ToString() of an FVector ("X=10.000 Y=-2.500 Z=160.000"), an FQuat ("X=... Y=... Z=...
#: W=...") or an FRotator ("P=-5.000000 Y=90.000000 R=0.000000": pitch, yaw, roll) in one field
_UNREAL_VALUE = r'[^\s,;\t"]+'
_UNREAL = re.compile(r"([XYZWPR])=(" + _UNREAL_VALUE + ")")
#: a whole field of them (from a field's start to its end)
_UNREAL_CELL = re.compile(r'(?<![^,;\t"])[XYZWPR]=' + _UNREAL_VALUE + r"(?: +[XYZWPR]=" + _UNREAL_VALUE
                          + r')*(?=[,;\t"]|$)')
_UNREAL_NAMES = {"XYZ": ("x", "y", "z"), "XYZW": ("x", "y", "z", "w"), "PYR": ("pitch", "yaw", "roll")}


def tuple_header(header, first_row, delim):
    """``header`` with each column whose cell in ``first_row`` (the first data line, text; or a
    list of lines, each column's first non-empty cell deciding) is a parenthesised tuple spread
    over one column per component (``head_position`` -> ``head_position_x``, ``_y``, ``_z``; four:
    ``_x`` .. ``_w``, Unity's quaternion order), or an Unreal ToString() (``X=.. Y=.. Z=..`` ->
    ``_x``, ``_y``, ``_z``; ``P=.. Y=.. R=..`` -> ``_pitch``, ``_yaw``, ``_roll``), or ``header``
    itself when the rows have none."""
    return _spread_header(header, first_row, delim)[0]


def _fields(line, delim):
    """A data line's fields, a parenthesised tuple's separators kept inside it."""
    return re.split(re.escape(delim) + r"(?![^()]*\))", line)


def _spread_header(header, rows, delim):
    """``(header, widths)``: :func:`tuple_header`'s header, and ``{column: components}`` of the
    spread columns (indices into ``header`` as given)."""
    rows = [rows] if isinstance(rows, str) else list(rows)
    cells = [None] * len(header)
    for row in rows:
        if "(" not in row and "=" not in row:
            continue
        fields = _fields(row, delim)
        if len(fields) != len(header):
            continue
        for i, cell in enumerate(fields):
            cell = cell.strip().strip('"')
            if cells[i] is None and cell:
                cells[i] = cell
        if all(c is not None for c in cells):
            break
    out, widths = [], {}
    for i, (name, cell) in enumerate(zip(header, cells)):
        cell = cell or ""
        m = _TUPLE.fullmatch(cell)
        if m:
            n = len(re.split(r"\s*[,;]\s*", m.group(1).strip()))
            names = [f"{name}_{a}" for a in ("xyz" if n == 3 else "xyzw" if n == 4 else range(n))]
        else:
            letters = "".join(m.group(1) for m in _UNREAL.finditer(cell)) if _UNREAL_CELL.fullmatch(cell) else ""
            names = [f"{name}_{a}" for a in _UNREAL_NAMES[letters]] if letters in _UNREAL_NAMES else [name]
        if len(names) > 1 or names[0] != name:
            widths[i] = len(names)
        out += names
    return out, widths


def _untuple(line, delim, widths=None, columns=None):
    """``line`` with each parenthesised tuple's or Unreal ToString()'s components as fields of
    their own; with ``widths`` (:func:`_spread_header`'s, of a header of ``columns`` columns), an
    empty field of a spread column (a lost sample) as that many empty fields."""
    if widths and (delim * 2 in line or line.startswith(delim) or line.endswith(delim) or '""' in line):
        fields = _fields(line, delim)
        if len(fields) == columns and any(not fields[i].strip().strip('"') for i in widths):
            line = delim.join(delim.join([""] * widths[i]) if i in widths and not f.strip().strip('"') else f
                              for i, f in enumerate(fields))
    if "(" in line:
        line = _TUPLE.sub(lambda m: delim.join(re.split(r"\s*[,;]\s*", m.group(1).strip())), line)
    if "=" in line:
        line = _UNREAL_CELL.sub(lambda m: delim.join(v.group(2) for v in _UNREAL.finditer(m.group(0))), line)
    return line


def iso_seconds(cells, path=None, lines=None):
    """Seconds ``(T,)`` float64 from ISO 8601 date-times (``2026-12-07T10:00:00.125``, a space for
    the ``T``, a ``Z`` or ``+01:00`` zone) or times of day (``10:00:00.125``; past midnight they
    run on), relative to the first; ``nan`` cells stay NaN.  None when the first finite cell is
    neither.  A later cell that is not one is a :class:`RecordingError` naming its line
    (``lines[k]``, the file line of cell ``k``).  None too when the first is a number."""
    import datetime as dt
    first = next((c for c in cells if c != "nan"), None)
    if first is None:
        return None
    try:
        float(first)
        return None                         # a number (Python reads "12" and "20261207" as ISO too)
    except ValueError:
        pass

    def parse(c):
        c = c.strip().strip('"')
        if c.endswith(("Z", "z")):
            c = c[:-1] + "+00:00"
        try:
            d = dt.datetime.fromisoformat(c)
            if d.tzinfo is None:
                d = d.replace(tzinfo=dt.timezone.utc)
            return d.timestamp(), True
        except ValueError:
            tod = dt.time.fromisoformat(c)
            return tod.hour * 3600 + tod.minute * 60 + tod.second + tod.microsecond * 1e-6, False
    try:
        _, dated = parse(first)
    except ValueError:
        return None
    out = np.full(len(cells), np.nan)
    for k, c in enumerate(cells):
        if c == "nan":
            continue
        try:
            out[k], d = parse(c)
        except ValueError:
            d = None
        if d is not dated:
            what = "an ISO 8601 date and time" if dated else "an ISO 8601 time of day"
            raise RecordingError(f"{shown(c)} is not {what}, as the first time is", path=path,
                                 line=None if lines is None else lines[k])
    if not dated:                                         # a take that runs past midnight
        ok = np.isfinite(out)
        out[ok] += 86400.0 * np.cumsum(np.concatenate([[0], np.diff(out[ok]) < -43200]))
    base = out[np.isfinite(out)][0]
    return out - base


def _raw_prefix(raw, prefix):
    """The part of the column name ``raw`` that the normalised ``prefix`` (:func:`.devices.snake_name`) came
    from: ``("CenterEyeAnchor.position.x", "center_eye_anchor")`` -> ``"CenterEyeAnchor"``."""
    want = sum(c.isalnum() for c in prefix)
    seen = 0
    for k, c in enumerate(raw):
        if c.isalnum():
            seen += 1
            if seen == want:
                return raw[: k + 1]
    return raw or prefix


def device_of(prefix):
    """The device a column prefix names, or None."""
    key = snake_name(prefix)
    return canonical_device(key) or canonical_device(key.replace("_", ""))


_COMPONENT = re.compile(r"^(?P<dev>.+?)_(?:(?P<word>[a-z]+)_)?(?P<axis>[xyzw]|pitch|yaw|roll)$")
#: a pose matrix's element: ``<dev>_m00`` ... ``<dev>_m23``, ``<dev>_m_0_3``, ``<dev>.m[0][3]`` (row,
#: column), as OpenVR's ``HmdMatrix34_t m[3][4]`` (row-major: rotation, then the position column)
_MATRIX = re.compile(r"^(?P<dev>.+?)_(?:(?P<word>[a-z]+)_)?m_?(?P<r>[0-3])_?(?P<c>[0-3])$")
#: an Unreal rotator's angles as the x, y, z of its ``FRotator::Euler()`` (roll, pitch, yaw)
_ROTATOR_AXES = {"pitch": "y", "yaw": "z", "roll": "x"}
_ROTATOR_WORDS = {a: w for w, a in _ROTATOR_AXES.items()}


#: an acronym run into the next word (``HMDLocation``, ``XRHead``): split there before
#: :func:`.devices.snake_name`, which splits only a lower-case letter from a capital
_ACRONYM = re.compile(r"(?<=[A-Z])(?=[A-Z][a-z])")


def parse_columns(header):
    """``({device: {"pos": {axis: col}, "rot": {axis: col}, "prefix": str}}, time_column, skipped)``.

    ``rot`` holds a quaternion's w, x, y, z columns, or x, y, z Euler-angle columns.  The time
    column is ``(index, kind)``; a frame counter (``frame``, ``frame_index``, ...) is the time
    only when there is no time column (kind ``"frames"``, read with a rate)."""
    groups, time_col, skipped, frame_col = {}, None, [], None
    for i, raw in enumerate(header):
        name = snake_name(_ACRONYM.sub("_", raw))
        if i == 0 and (name == "" or name.startswith("unnamed")):
            continue
        if name in _TIME_S + _TIME_MS + _DELTA_MS + _DELTA_S and time_col is None:
            time_col = (i, name)
            continue
        if name in _TIME_NS_US and time_col is None:
            time_col = (i, _TIME_NS_US[name])
            continue
        if name in _FRAMES:                   # a frame counter: the time when nothing better is there
            frame_col = frame_col or (i, "frames")
            continue
        m = _MATRIX.match(name)
        if m:
            prefix, word = m.group("dev"), m.group("word") or ""
            dev = device_of(prefix)
            if dev is None and word:
                prefix, dev = f"{prefix}_{word}", device_of(f"{prefix}_{word}")
            if dev is not None:
                g = groups.setdefault(dev, {"pos": {}, "rot": {}, "prefix": _raw_prefix(raw, prefix)})
                g.setdefault("mat", {})[(int(m.group("r")), int(m.group("c")))] = i
                continue
        m = _COMPONENT.match(name)
        if not m:
            skipped.append(raw)
            continue
        prefix, word, axis = m.group("dev"), m.group("word") or "", m.group("axis")
        rotator = axis in _ROTATOR_AXES
        axis = _ROTATOR_AXES.get(axis, axis)
        # "<dev>_q_x" style: the word may have been swallowed into the prefix
        dev = device_of(prefix)
        if dev is None and word and device_of(f"{prefix}_{word}"):     # "<dev with _>_x": no component word
            prefix, word = f"{prefix}_{word}", ""
            dev = device_of(prefix)
        if dev is None and "_" in prefix:
            head, _, tail = prefix.rpartition("_")
            if tail in _POS_WORDS + _ROT_WORDS:
                prefix, word, dev = head, tail, device_of(head)
        if dev is None:
            skipped.append(raw)
            continue
        kind = "rot" if word in _ROT_WORDS or axis == "w" or rotator else "pos" if word in _POS_WORDS else None
        if kind is None:
            skipped.append(raw)
            continue
        g = groups.setdefault(dev, {"pos": {}, "rot": {}, "prefix": _raw_prefix(raw, prefix)})
        if axis in g[kind]:
            raise RecordingError(f"two columns for {dev} {kind} {axis}: {header[g[kind][axis]]!r} and {raw!r}")
        g[kind][axis] = i
        if rotator:
            g["rotator"] = True
    for dev, g in groups.items():
        _matrix_columns(dev, g, header)
    return groups, time_col or frame_col, skipped


def _matrix_columns(dev, g, header):
    """A group of pose-matrix columns (``g["mat"]``: (row, column) -> column index) as the
    position columns (the 4th column's x, y, z) and ``g["mat"]``, the 9 rotation columns row by
    row; a 4x4 matrix's last row is not used."""
    if "mat" not in g:
        return
    need = [(r, c) for r in range(3) for c in range(4)]
    lacking = [f"m{r}{c}" for r, c in need if (r, c) not in g["mat"]]
    if lacking:
        raise RecordingError(f"{dev}: pose matrix without {', '.join(lacking)} (a 3x4 matrix needs rows 0-2, "
                             "columns 0-3: the rotation, then the position)")
    if g["pos"] or g["rot"]:
        other = header[next(iter({**g["pos"], **g["rot"]}.values()))]
        raise RecordingError(f"{dev}: a pose matrix and other pose columns ({other!r})")
    g["pos"] = {a: g["mat"][(r, 3)] for r, a in enumerate("xyz")}
    g["mat"] = [g["mat"][(r, c)] for r in range(3) for c in range(3)]


def looks_wide(head_text):
    """Whether a CSV header looks like a wide layout (a device's x, y, z position columns)."""
    lines = [ln for ln in head_text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        return False
    delim = sniff_delimiter(lines[0])
    header = [c.strip().strip('"') for c in lines[0].split(delim)]
    if len(lines) > 1:
        header = tuple_header(header, lines[1:200], delim)
    try:
        groups, _, _ = parse_columns(header)
    except RecordingError:
        return True
    return any(len(g["pos"]) == 3 for g in groups.values())


def _time(col, values, header=None, rate=None, path=None):
    i, name = col
    col_name = header[i] if header is not None else name
    v = values[:, i]
    finite = v[np.isfinite(v)]
    v0 = finite[0] if finite.size else np.nan        # a first row without a time (a JSON Lines header)
    if name == "frames":
        if not rate:
            raise RecordingError(f"the only time is the frame counter {col_name!r}: give the tracker rate "
                                 f"(--rate HZ, or \"rate\" in a layout file's \"time\")", path=path)
        return (v - v0) / float(rate), f"time={col_name} (frames) at {float(rate):g} Hz"
    if name in _DELTA_MS + _DELTA_S:
        v = np.cumsum(np.nan_to_num(v)) * (1e-3 if name in _DELTA_MS else 1.0)
        return v - v[0], f"time=cumulative {col_name}" + (" in ms" if name in _DELTA_MS else " in s")
    steps = np.diff(v[np.isfinite(v)])
    med = float(np.median(steps)) if steps.size else 0.0
    if name in ("time_us", "time_ns"):
        return (v - v0) * (1e-6 if name == "time_us" else 1e-9), f"time={col_name} in {name[5:]}"
    if name == "seconds_stated":                       # a layout file's "unit": "s"
        return v - v0, f"time={col_name} in s"
    scale, unit = time_unit_of_step(med, milliseconds=name in _NAMED_MS)      # no tracker under 2 Hz
    return (v - v0) * scale, f"time={col_name} in {unit}"


LAYOUT_VERSION = 1
#: the Euler-angle order each convention's tools write, as rotations about the fixed axes applied
#: first letter first (Unity's ``eulerAngles``: Z, then X, then Y); a layout file's "euler" wins
EULER_ORDERS = {"unity": "ZXY", "openxr": "XYZ", "blender": "XYZ", "unreal": "ROTATOR"}
#: an Unreal ``FRotator``: x, y, z are its roll, pitch and yaw (``FRotator::Euler()``), in degrees,
#: in Unreal's left-handed axes: yaw turns +X toward +Y, pitch lifts +X toward +Z, roll lowers +Y
#: toward -Z; as rotations about the fixed axes, X by -roll, then Y by -pitch, then Z by yaw
ROTATOR = "ROTATOR"
_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", ROTATOR)


def euler_matrix(angles, order):
    """``(T, 3, 3)`` rotation matrices of Euler angles ``(T, 3)`` (radians, the x, y, z columns)
    applied about the fixed axes in ``order`` (first letter first), or an Unreal rotator's
    (:data:`ROTATOR`: x, y, z = roll, pitch, yaw)."""
    if order == ROTATOR:
        return rot.fixed_axes_euler_to_matrix(np.asarray(angles, np.float64) * [-1.0, -1.0, 1.0], "XYZ")
    return rot.fixed_axes_euler_to_matrix(angles, order)


def load_layout(path):
    """A layout file (JSON, as :func:`save_layout` writes it) as a dict; errors name the file,
    the line of the first key at fault (:func:`.recording.json_key_line`) and every problem."""
    layout = load_json_file(path)
    problems, keys = [], []

    def bad(problem, *key):
        problems.append(problem)
        keys.append(key)
    if not isinstance(layout, dict) or layout.get("format") != "wide_csv":
        bad('expected an object with "format": "wide_csv"', "format")
    else:
        devs = layout.get("devices")
        if not isinstance(devs, dict) or not devs:
            bad('"devices" must map device names to their columns', "devices")
        else:
            for d, cols in devs.items():
                if canonical_device(d) is None:
                    bad(f"unknown device {d!r}", "devices", d)
                elif not isinstance(cols, dict) or not isinstance(cols.get("pos"), list) or len(cols["pos"]) != 3:
                    bad(f"{d}: \"pos\" must list the x, y, z columns", "devices", d, "pos")
                elif cols.get("matrix") is not None and (not isinstance(cols["matrix"], list)
                                                         or len(cols["matrix"]) != 9 or cols.get("rot")):
                    bad(f"{d}: \"matrix\" must list the 9 rotation columns row by row (and \"rot\" be null)",
                        "devices", d, "matrix")
                elif cols.get("rot") is not None and (not isinstance(cols["rot"], list) or len(cols["rot"]) != 4):
                    bad(f"{d}: \"rot\" must list the w, x, y, z columns (or be null)", "devices", d, "rot")
                elif cols.get("euler") is not None and (not isinstance(cols["euler"], list) or len(cols["euler"]) != 3
                                                        or cols.get("rot")):
                    bad(f"{d}: \"euler\" must list the x, y, z angle columns (and \"rot\" be null)", "devices", d,
                        "euler")
        tm = layout.get("time")
        if not isinstance(tm, dict) or not isinstance(tm.get("column"), str) or \
                tm.get("unit") not in ("s", "ms", "us", "ns", "delta_ms", "delta_s", "frames", "iso8601"):
            bad('"time" must be {"column": NAME, "unit": "s"|"ms"|"us"|"ns"|"delta_ms"|"delta_s"'
                '|"frames"|"iso8601"} (with "rate": HZ for frames)', "time")
        elif tm.get("rate") is not None and not (isinstance(tm["rate"], (int, float)) and tm["rate"] > 0):
            bad('"time": "rate" must be a positive number of samples per second', "time", "rate")
        eu = layout.get("euler")
        if eu is not None and (not isinstance(eu, dict) or str(eu.get("order", "")).upper() not in _ORDERS
                               or eu.get("unit") not in (None, "deg", "rad")):
            bad('"euler" must be {"order": "XYZ"|"ZXY"|... (applied first to last, about the fixed '
                'axes) or "rotator" (Unreal\'s roll, pitch, yaw), "unit": "deg"|"rad"}', "euler")
        for key, allowed in (("units", tuple(UNITS)), ("axes", ("unity", "openxr", "blender", "unreal")),
                             ("delimiter", DELIMITERS), ("decimal", (".", ","))):
            if layout.get(key) is not None and layout[key] not in allowed:
                bad(f'"{key}" must be one of {", ".join(allowed)} or null', key)
    if problems:
        line = json_key_line(read_text(path), keys[0]) if isinstance(layout, dict) else None
        raise RecordingError("layout file: " + "; ".join(problems), path=path, line=line)
    return layout


def save_layout(path, layout):
    """Write a layout dict (``Recording.metadata["layout"]``) as a JSON layout file."""
    import json
    from .file_names import written_whole
    with written_whole(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        json.dump(layout, f, indent=2)
        f.write("\n")
    return path


def _prefix_of(columns):
    """``["hmd_pos_x", "hmd_pos_y", "hmd_pos_z"]`` -> ``"hmd"``: the device part of column names."""
    common = os.path.commonprefix(list(columns)).rstrip("_. ")
    return re.sub(r"[_. ]?(pos|position|p|loc|location)$", "", common, flags=re.IGNORECASE)


def _layout_groups(layout, header, path, hline):
    """Column groups and the time column of ``header`` as a layout dict names them."""
    index = {name.strip(): i for i, name in enumerate(header)}

    def col(name):
        if name not in index:
            raise RecordingError(f"the layout names column {name!r}, which the header does not have",
                                 path=path, line=hline)
        return index[name]
    groups = {}
    for d, cols in layout["devices"].items():
        dev = canonical_device(d)
        rot = {a: col(c) for a, c in zip("wxyz", cols["rot"])} if cols.get("rot") else \
            {a: col(c) for a, c in zip("xyz", cols["euler"])} if cols.get("euler") else {}
        groups[dev] = {"pos": {a: col(c) for a, c in zip("xyz", cols["pos"])}, "rot": rot,
                       "prefix": _prefix_of(cols["pos"]) or d}
        if cols.get("matrix"):
            groups[dev]["mat"] = [col(c) for c in cols["matrix"]]
    unit = layout["time"]["unit"]
    name = {"s": "seconds_stated", "ms": "time_ms", "us": "time_us", "ns": "time_ns", "delta_ms": "delta_time_ms",
            "delta_s": "delta_time", "frames": "frames", "iso8601": "time"}[unit]
    return groups, (col(layout["time"]["column"]), name), []


def _matrix_quats(m):
    """``(T, 4)`` wxyz quaternions of rotation matrices given row by row, ``(T, 9)`` (NaN where a
    sample is lost: a NaN element, a mirror, or a singular matrix such as all zeros), made
    orthonormal first (logged matrices are rounded)."""
    m = np.asarray(m, np.float64).reshape(-1, 3, 3)
    ok = np.isfinite(m).all(axis=(1, 2))
    out = np.full((len(m), 4), np.nan)
    if ok.any():
        u, s, vt = np.linalg.svd(m[ok])
        R = u @ vt
        # not a rotation: a mirror, or singular (OpenVR's zeros for a pose it has not got): lost
        bad = (np.linalg.det(R) < 0) | ~(s[:, -1] > 1e-6 * s[:, 0])
        out[ok] = rot.matrix_to_quat(R)
        out[np.flatnonzero(ok)[bad]] = np.nan
    return out


def _rotation_kind(group):
    """How a device's orientation is given, in words (an error's)."""
    return "pose matrix" if group.get("mat") else "Euler" if len(group["rot"]) == 3 else "quaternion"


def read_wide_csv(path, axes=None, units=None, layout=None, rate=None) -> Recording:
    """Read a wide-layout CSV (see module doc) into a :class:`Recording` (Blender axes, metres).

    layout: a layout dict (:func:`load_layout`) or a layout file's path: the columns, time,
    units, axes and Euler-angle convention it states replace the detection (``axes`` /
    ``units`` still win).  rate: samples per second of a file whose only time is a frame
    counter (else the layout's ``"rate"``).  The layout that was used, detected or given, is
    ``metadata["layout"]`` (:func:`save_layout`)."""
    path = os.fspath(path)
    text = decode_text(read_file_bytes(path), path=path, errors="replace")
    lines = text.splitlines()
    rows = [(n, ln) for n, ln in enumerate(lines, 1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise RecordingError("file is empty", path=path)
    hline, header_text = rows[0]
    if isinstance(layout, (str, os.PathLike)):
        layout = load_layout(layout)
    delim = (layout or {}).get("delimiter") or sniff_delimiter(header_text)
    header = [c.strip().strip('"') for c in header_text.split(delim)]
    body = rows[1:]
    spread, widths = _spread_header(header, [ln for _, ln in body[:200]], delim)
    columns = len(header)
    tuples, header = spread != header, spread
    decimal = (layout or {}).get("decimal") or \
        ("," if delim != "," and any("," in ln for _, ln in body[:200]) else ".")

    def table():
        if len(body) < 2:
            raise RecordingError("fewer than two rows of samples", path=path)
        parts = []
        for part in row_chunks(len(body)):        # in chunks: a cancel is checked between them
            cells = [(ln.replace(",", ".") if decimal == "," else ln)
                     for ln in ((_untuple(ln, delim, widths, columns) if tuples else ln)
                                for _, ln in body[part])]                                  # 1,62 is 1.62
            cells = [ln.split(delim) for ln in cells]
            counts = np.fromiter((len(c) for c in cells), dtype=np.int64, count=len(cells))
            wrong = np.nonzero(counts != len(header))[0]
            if wrong.size:
                k = int(wrong[0])
                raise RecordingError(f"{counts[k]} fields, the header has {len(header)}", path=path,
                                     line=body[part.start + k][0])
            parts.append(np.char.strip(np.char.strip(np.array(cells, dtype=str)), '"'))
        return np.concatenate(parts), [n for n, _ in body]

    note = "" if delim == "," else (f"fields separated by {_DELIMITER_NAMES[delim]}"
                                    + (", decimal commas" if decimal == "," else ""))
    if tuples:
        what = "Unreal's X=.. Y=.. Z=.. / P=.. Y=.. R=.. strings" if any("=" in ln for _, ln in body[:200]) else \
            "vectors and quaternions as (x, y, z[, w]) tuples"
        note = "; ".join(n for n in (note, what) if n)
    extra = {"delimiter": delim, "decimal": decimal} if delim != "," or decimal != "." else {}
    return read_wide_table(path, header, hline, table, axes=axes, units=units, layout=layout, rate=rate,
                           note=note, layout_extra=extra)


def read_wide_table(path, header, hline, table, axes=None, units=None, layout=None, rate=None, note="",
                    layout_extra=None, what="wide layout") -> Recording:
    """A :class:`Recording` from a wide table: ``header`` (column names; ``hline`` its line, or
    None) and ``table()`` -> ``(cells, lines)``, the ``(N, len(header))`` text cells and each row's
    line (called once the columns are known to make a recording).  The columns, time, units and
    axes are detected as for a wide CSV (or taken from ``layout``); ``note`` goes before the time
    in the detection line, which starts with ``what``; ``layout_extra`` goes into the layout used
    (``metadata["layout"]``).  Errors name ``path`` and the line."""
    try:
        if layout is not None:
            groups, time_col, skipped = _layout_groups(layout, header, path, hline)
        else:
            groups, time_col, skipped = parse_columns(header)
    except RecordingError as exc:
        if exc.path:
            raise
        raise RecordingError(str(exc), path=path, line=hline) from None
    given = {"axes": "given" if axes else None, "units": "given" if units else None}
    if layout is not None:
        given = {k: given[k] or ("layout file" if layout.get(k) else None) for k in given}
        axes = axes or layout.get("axes")
        units = units or layout.get("units")
    if time_col is None:
        raise RecordingError("no time column (expected one of time, timestamp, delta_time_ms, ...)",
                             path=path, line=hline)
    for dev, g in groups.items():
        if len(g["pos"]) != 3:
            raise RecordingError(f"{dev}: position columns {sorted(g['pos'])} (need x, y, z)", path=path, line=hline)
        if g.get("rotator") and set(g["rot"]) != set("xyz"):      # named by their words, not as x, y, z
            order = [a for a in "yzxw" if a in g["rot"]]
            words = ", ".join(_ROTATOR_WORDS.get(a, a) for a in order)
            lacking = ", ".join(w for w, a in _ROTATOR_AXES.items() if a not in g["rot"]) or "the others"
            raise RecordingError(f"{dev}: rotator columns {words} without {lacking} "
                                 f"({', '.join(header[g['rot'][a]] for a in order)}; an Unreal rotator needs "
                                 "pitch, yaw and roll)", path=path, line=hline)
        if g["rot"] and len(g["rot"]) != 4 and set(g["rot"]) != set("xyz"):
            raise RecordingError(f"{dev}: rotation columns {sorted(g['rot'])}: a quaternion needs w, x, y, z, "
                                 "Euler angles x, y, z", path=path, line=hline)
    kinds = {"euler" if len(g["rot"]) == 3 else "quat" for g in groups.values() if g["rot"] or g.get("mat")}
    if len(kinds) > 1:
        raise RecordingError("some devices have quaternion or pose-matrix and others Euler-angle columns: "
                             + ", ".join(f"{d} {_rotation_kind(g)}" for d, g in groups.items()
                                         if g["rot"] or g.get("mat")),
                             path=path, line=hline)
    euler = kinds == {"euler"}
    missing = [d for d in ("head", "left_hand", "right_hand") if d not in groups]
    if missing:
        rays = [c for c in skipped if "targetray" in c.lower().replace("_", "")]
        hint = ("; a WebXR input source's targetRaySpace is its pointing ray, not the hand: log "
                "frame.getPose(source.gripSpace, ref) too" if rays and {"left_hand", "right_hand"} & set(missing)
                else "")
        raise RecordingError(f"no columns for {', '.join(missing)} (found devices: {', '.join(groups) or 'none'}; "
                             f"unrecognised columns: {', '.join(skipped[:8])}){hint}", path=path, line=hline)
    text_cells, row_lines = table()
    text_cells[text_cells == ""] = "nan"                 # an empty cell is a lost sample
    iso = iso_seconds(text_cells[:, time_col[0]], path, row_lines) \
        if time_col[1] != "frames" and (layout is None or layout["time"]["unit"] == "iso8601") else None
    if iso is not None:
        text_cells[:, time_col[0]] = "0"
    # the time's and the devices' columns; others (names, events, flags) may hold anything
    used = sorted({time_col[0]} | {i for g in groups.values()
                                   for i in (*g["pos"].values(), *g["rot"].values(), *g.get("mat", ()))})
    values = np.full(text_cells.shape, np.nan)
    try:
        for part in row_chunks(len(values)):             # vectorised, a chunk of rows at a time
            values[part, used] = text_cells[part][:, used].astype(np.float64)
    except ValueError:
        for k, row in enumerate(text_cells[:, used]):                 # only to name the bad cell's line
            for c in row:
                try:
                    float(c)
                except ValueError:
                    raise RecordingError(f"{shown(c)} is not a number", path=path, line=row_lines[k]) from None
        raise
    values[np.isinf(values)] = np.nan      # "inf", or a number past float64's range (1e309): not a measurement
    if rate is None and layout is not None:
        rate = layout["time"].get("rate")
    if iso is not None:
        t, time_note, time_unit = iso, f"time={header[time_col[0]]} as ISO 8601", "iso8601"
    else:
        t, time_note = _time(time_col, values, header, rate=rate, path=path)
        time_unit = time_note.rsplit(" in ", 1)[-1] if " in " in time_note else "s"
        if time_col[1] == "frames":
            time_unit = "frames"
        if time_note.startswith("time=cumulative"):
            time_unit = "delta_ms" if time_note.endswith("ms") else "delta_s"
    if note:
        time_note = f"{note}; {time_note}"
    pos = {d: values[:, [g["pos"][a] for a in "xyz"]] for d, g in groups.items()}
    if euler:
        eu = (layout or {}).get("euler") or {}
        angles = {d: values[:, [g["rot"][a] for a in "xyz"]] for d, g in groups.items() if g["rot"]}
        finite = np.concatenate([np.abs(a[np.isfinite(a)]) for a in angles.values()])
        big = float(finite.max()) if finite.size else 0.0
        eu_unit = eu.get("unit") or ("deg" if big > 2 * np.pi + 0.5 else "rad")
        angles = {d: np.radians(a) if eu_unit == "deg" else a for d, a in angles.items()}

        made = {}

        def quats_for(order):       # each order's quaternions once (detection, then the read)
            if order not in made:
                made[order] = {d: (rot.matrix_to_quat(euler_matrix(angles[d], order)) if g["rot"]
                                   else np.tile([1.0, 0, 0, 0], (len(t), 1))) for d, g in groups.items()}
            return made[order]
    else:
        quat = {d: (values[:, [g["rot"][a] for a in "wxyz"]] if g["rot"] else _matrix_quats(values[:, g["mat"]])
                    if g.get("mat") else np.tile([1.0, 0, 0, 0], (len(t), 1)))
                for d, g in groups.items()}
    # units from an arm's length (the hands' distance to the head), wherever the origin is
    if units is None:
        units = (length_units(pos) or ("m", 0.0))[0]
        units_how = None
    else:
        units = canonical_units(units)
        units_how = given["units"]
    scale = UNITS[units]
    metres = {d: p * scale for d, p in pos.items()}
    if euler:      # the order a convention's tools write (Unity: Z, X, Y), unless stated
        def order_for(ax):
            return str(eu.get("order") or EULER_ORDERS.get(ax, "XYZ")).upper()
    unrotated = [d for d, g in groups.items() if not g["rot"] and not g.get("mat")]
    rotators = [d for d, g in groups.items() if g.get("rotator")]
    if rotators:                       # pitch, yaw, roll columns: an Unreal rotator, in Unreal's axes only
        named = ", ".join(header[groups[rotators[0]]["rot"][a]] for a in "yzx")
        if axes is not None and canonical_axes(axes) != "unreal":
            raise RecordingError(f"{named}: pitch, yaw and roll columns are an Unreal rotator, read in Unreal's "
                                 f"axes, not in the axes {canonical_axes(axes)} ({given['axes']}): leave the axes to "
                                 "the file (or give unreal), or name them as Euler angles in a layout file "
                                 '("euler" columns x, y, z and the "euler" order)', path=path, line=hline)
        up, up_how = up_axis(metres, quats_for(ROTATOR)) if axes is None else (2, None)
        if up != 2:
            raise RecordingError(f"{named}: pitch, yaw and roll columns are read as an Unreal rotator, in Unreal's "
                                 f"axes (Z up), but the head stands along Y (Y up, from {up_how}): not an Unreal "
                                 'file; name them as Euler angles in a layout file ("euler" columns x, y, z and '
                                 'the "euler" order), or leave them out', path=path, line=hline)
    if axes is None and rotators:
        axes = "unreal"
        axes_note = f"axes unreal (left-handed), from the rotator columns of {', '.join(rotators)} (pitch, yaw, roll)"
    elif axes is None:
        read_check()                                      # the detection takes a second on a long take
        up, up_how = up_axis(metres, quats_for(order_for("openxr")) if euler else quat)
        cands = ("blender", "unreal") if up == 2 else ("unity", "openxr")
        # the head's orientation gives each reading's facing; without it, the positions do
        axes, why = choose_axes(t, metres, None if "head" in unrotated else
                                (lambda c: quats_for(order_for(c))) if euler else (lambda c: quat), cands)
        up_note = "" if up_how == "the head's height" else f", {'Z' if up == 2 else 'Y'} up from {up_how}"
        axes_note = f"axes {axes} ({'left-handed' if axes in LEFT_HANDED else 'right-handed'}){up_note}, {why}"
    else:
        axes = canonical_axes(axes)
        up = 2 if axes in ("blender", "unreal") else 1
        axes_note = f"axes {axes} ({given['axes']})"
    head_h = float(np.nanmedian(metres["head"][:, up]))
    units_note = f"units {units} ({units_how or f'head at {head_h:.2f} m'})"
    if euler:
        quat = quats_for(order_for(axes))
    streams = {}
    for d in DEVICES:
        if d not in groups:
            continue
        p, q = to_blender(pos[d] * scale, normalize(quat[d]), axes)
        streams[d] = [p, q]
    rot_note = ""
    if unrotated:      # no orientation columns: level, facing the head's (or the body's) heading
        if "head" in unrotated:
            yaw = yaw_of(heading_from_positions(t, {d: streams[d][0] for d in ("head", "left_hand", "right_hand")}))
            rot_note = (f"no orientation columns for {', '.join(unrotated)}: level, facing the hands' left-right line "
                        "and the walking direction")
        else:
            yaw = np.nan_to_num(heading_yaw(rot.quat_to_matrix(streams["head"][1])))   # a lost head: -Y
            rot_note = f"no orientation columns for {', '.join(unrotated)}: level, facing the head's heading"
        for d in unrotated:
            streams[d][1] = heading_quats(yaw)
    for d in list(streams):
        p, q = streams[d]
        ok = np.all(np.isfinite(p), -1) & np.all(np.isfinite(q), -1)
        streams[d] = TrackerStream(d, t.copy(), p, q, ok)
    if euler:
        stated = "stated" if eu.get("order") else ("Unity's" if axes == "unity" else "chosen")
        qnote = (f"Euler angles in {'degrees' if eu_unit == 'deg' else 'radians'}, fixed axes {order_for(axes)} "
                 f"({stated} order)")
        if order_for(axes) == ROTATOR:
            qnote = (f"Unreal rotators (roll, pitch, yaw) in {'degrees' if eu_unit == 'deg' else 'radians'}"
                     + (" (stated)" if eu.get("order") else ""))
    else:
        has_w_first = all(g["rot"]["w"] < g["rot"]["x"] for g in groups.values() if g["rot"])
        qnote = "quaternions w,x,y,z" if has_w_first else "quaternions x,y,z,w"
        if any(g.get("mat") for g in groups.values()):
            qnote = "3x4 pose matrices (row-major)" + ("" if all(g.get("mat") for g in groups.values() if g["rot"]
                                                               or g.get("mat")) else f"; {qnote}")
    if rot_note:
        qnote = rot_note if len(unrotated) == len(groups) else f"{qnote}; {rot_note}"
    hands = "/".join(f"{groups[d]['prefix']}_*" for d in ("left_hand", "right_hand"))
    extra = "".join(f", {d}={groups[d]['prefix']}_*" for d in ("pelvis", "left_foot", "right_foot") if d in groups)
    detected = (f"{what}: head={groups['head']['prefix']}_*, hands={hands}{extra}; {qnote}; {time_note}; "
                f"{units_note}; {axes_note}")
    used = {"format": "wide_csv", "version": LAYOUT_VERSION,
            "devices": {d: {"pos": [header[g["pos"][a]] for a in "xyz"],
                            "rot": [header[g["rot"][a]] for a in "wxyz"] if g["rot"] and not euler else None,
                            **({"matrix": [header[i] for i in g["mat"]]} if g.get("mat") else {}),
                            **({"euler": [header[g["rot"][a]] for a in "xyz"] if g["rot"] else None}
                               if euler else {})}
                        for d, g in groups.items()},
            "time": {"column": header[time_col[0]], "unit": {"µs": "us"}.get(time_unit, time_unit),
                     **({"rate": float(rate)} if time_col[1] == "frames" else {})},
            "units": units, "axes": axes}
    used.update(layout_extra or {})
    if euler:
        used["euler"] = {"order": order_for(axes), "unit": eu_unit}
    if layout is not None:
        detected = "layout file: " + detected.split(": ", 1)[1]
    meta = {"format": "wide_csv", "axes": axes, "units": units, "detected": detected,
            "ignored_columns": skipped, "layout": used,
            "device_labels": {d: g["prefix"] for d, g in groups.items()}}
    return Recording(streams=streams, source=path, metadata=meta, warnings=[])

