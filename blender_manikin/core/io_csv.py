"""The native tracker-recording CSV format: reader and writer.  Never imports bpy.

Format (UTF-8, optional BOM)::

    # blender_manikin tracker recording
    # source: Quest 3 via OpenXR, take 4
    # axes: openxr
    # units: m
    time,device,px,py,pz,qw,qx,qy,qz,valid
    0.000000,head,0.012000,1.623000,-0.051000,0.9990000,0.0100000,-0.0400000,0.0000000,1
    0.003100,left_hand,...

* One row per device sample.  ``time`` is seconds; each device has its own
  timestamps (rates may differ and jitter) and its time must strictly
  increase from row to row of that device (rows of different devices may
  interleave in any order).
* ``device``: ``head``, ``left_hand``, ``right_hand``, and optionally
  ``pelvis``, ``left_foot``, ``right_foot`` (case-insensitive; aliases such as
  ``hmd`` are accepted, see :data:`.recording.DEVICE_ALIASES`).
* ``px, py, pz``: position in ``units`` (default metres); ``qw, qx, qy, qz``:
  orientation quaternion (normalised on reading).  ``nan`` marks lost
  tracking.
* ``valid`` (optional): 1/0 (or true/false); 0 marks a sample whose pose the
  tracking system flagged as not tracked.
* Column order is free; extra columns are ignored; the header names are
  case-insensitive.
* Lines starting with ``#`` are comments.  ``# key: value`` comment lines are
  metadata: ``axes`` (``openxr`` default, ``unity``, ``blender``; see
  :mod:`.recording`), ``units`` (``m``, ``cm``, ``mm``), ``source`` (free
  text); other keys are kept in :attr:`Recording.metadata`.

Problems (empty file, wrong header, missing column, unknown device,
non-numeric field, wrong field count, non-increasing time within a device)
raise :class:`~.recording.RecordingError` naming the file, line and problem.
"""
from __future__ import annotations

import csv
import os
import re

import numpy as np

from .plain import shown
from .pose_result import DEVICES
from .recording import (
    Recording, RecordingError, TrackerStream, UNITS, canonical_axes, canonical_device,
    canonical_units, from_blender, read_file_bytes, to_blender,
)
from .rotations import normalize

REQUIRED_COLUMNS = ("time", "device", "px", "py", "pz", "qw", "qx", "qy", "qz")
_NUMERIC = ("time", "px", "py", "pz", "qw", "qx", "qy", "qz")
_META_RE = re.compile(r"^#\s*([A-Za-z_][\w\-]*)\s*:\s*(.*?)\s*$")
_TRUE = {"1", "true", "yes", "1.0"}
_FALSE = {"0", "false", "no", "0.0"}


def _split(line):
    if '"' in line:
        return [f.strip() for f in next(csv.reader([line]))]
    return [f.strip() for f in line.split(",")]


def _to_float(values, name, lines, path):
    """Vectorised str → float64 with a line-accurate error on failure."""
    try:
        return np.array(values, dtype=np.float64)
    except ValueError:
        for s, ln in zip(values, lines):
            try:
                float(s)
            except ValueError:
                text = str(s) if s else "(empty)"
                raise RecordingError(f"column '{name}': {text!r} is not a number", path=path,
                                     line=int(ln)) from None
        raise


def read_csv(path, axes=None, units=None) -> Recording:
    """Read a native CSV recording (see module docstring).

    path: file path.  axes: ``openxr``/``unity``/``blender`` overriding the
    file's ``# axes:`` metadata (default ``openxr``).  units: ``m``/``cm``/``mm``
    overriding ``# units:`` (default ``m``).

    Returns a :class:`Recording` in Blender axes and metres with
    ``metadata['axes']``/``['units']`` set to what was applied.
    """
    path = os.fspath(path)
    raw = read_file_bytes(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise RecordingError(f"not UTF-8 text (byte 0x{raw[exc.start]:02x})", path=path, line=line) from None
    if not text.strip():
        raise RecordingError("file is empty", path=path)

    metadata = {}
    meta_line = {}
    header = None
    header_line = None
    data_lines = []
    line_numbers = []
    for i, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = _META_RE.match(s)
            if m:
                key = m.group(1).lower()
                metadata[key] = m.group(2)
                meta_line[key] = i
            continue
        if header is None:
            header = [f.lower() for f in _split(s)]
            header_line = i
            continue
        data_lines.append(s)
        line_numbers.append(i)

    if header is None:
        raise RecordingError("no column header and no data (only comments)", path=path)
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        looks_like_data = False
        try:
            float(header[0])
            looks_like_data = True
        except ValueError:
            pass
        expected = ",".join(REQUIRED_COLUMNS)
        if looks_like_data or len(missing) == len(REQUIRED_COLUMNS):
            raise RecordingError(f"wrong header: expected the column names {expected!r} "
                                 f"(any order), found {','.join(header)!r}", path=path, line=header_line)
        raise RecordingError(f"header is missing column(s) {', '.join(missing)} (expected {expected!r})",
                             path=path, line=header_line)
    dup = sorted({c for c in header if header.count(c) > 1 and c in REQUIRED_COLUMNS + ("valid",)})
    if dup:
        raise RecordingError(f"header repeats column(s) {', '.join(dup)}", path=path, line=header_line)
    if not data_lines:
        raise RecordingError("no data rows after the header", path=path, line=header_line)

    # --- axes and units: option wins over metadata
    warnings = []
    axes_used = _resolve("axes", axes, metadata, meta_line, canonical_axes, "openxr", path, warnings)
    units_used = _resolve("units", units, metadata, meta_line, canonical_units, "m", path, warnings)

    # --- split rows
    rows = [_split(s) for s in data_lines]
    lines = np.asarray(line_numbers)
    ncol = len(header)
    counts = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    bad = np.nonzero(counts != ncol)[0]
    if bad.size:
        k = int(bad[0])
        raise RecordingError(f"expected {ncol} comma-separated fields (as in the header), found {counts[k]}",
                             path=path, line=int(lines[k]))
    cols = list(zip(*rows))
    col = {name: cols[header.index(name)] for name in REQUIRED_COLUMNS + (("valid",) if "valid" in header else ())}

    values = {name: _to_float(col[name], name, lines, path) for name in _NUMERIC}
    t = values["time"]
    nonfinite = np.nonzero(~np.isfinite(t))[0]
    if nonfinite.size:
        k = int(nonfinite[0])
        raise RecordingError(f"time {shown(col['time'][k])} is not a finite number", path=path, line=int(lines[k]))

    # devices: map unique names
    names, inverse = np.unique(np.asarray(col["device"], dtype=object).astype(str), return_inverse=True)
    dev_of_name = []
    for j, name in enumerate(names):
        d = canonical_device(name)
        if d is None:
            k = int(np.nonzero(inverse == j)[0][0])
            raise RecordingError(f"unknown device {shown(name)} (expected one of {', '.join(DEVICES)})",
                                 path=path, line=int(lines[k]))
        dev_of_name.append(d)
    dev = np.asarray(dev_of_name, dtype=object)[inverse]

    if "valid" in col:
        vs = np.char.lower(np.asarray(col["valid"], dtype=str))
        is_true = np.isin(vs, list(_TRUE))
        is_false = np.isin(vs, list(_FALSE))
        badv = np.nonzero(~(is_true | is_false))[0]
        if badv.size:
            k = int(badv[0])
            raise RecordingError(f"column 'valid': {shown(col['valid'][k])} is not 0 or 1", path=path,
                                 line=int(lines[k]))
        valid = is_true
    else:
        valid = np.ones(len(rows), dtype=bool)

    scale = UNITS[units_used]
    pos = np.stack([values["px"], values["py"], values["pz"]], -1) * scale
    quat = np.stack([values["qw"], values["qx"], values["qy"], values["qz"]], -1)
    qn = np.linalg.norm(quat, axis=-1)
    finite_q = np.isfinite(qn)
    zero_q = finite_q & (qn < 1e-6)
    off_unit = finite_q & ~zero_q & (np.abs(qn - 1.0) > 0.01)
    if np.any(off_unit):
        k = int(np.nonzero(off_unit)[0][0])
        warnings.append(f"{int(off_unit.sum())} quaternion(s) were not unit length and were normalised "
                        f"(first at line {int(lines[k])}, length {qn[k]:.3f})")
    if np.any(zero_q):
        k = int(np.nonzero(zero_q)[0][0])
        warnings.append(f"{int(zero_q.sum())} sample(s) have a zero quaternion and are marked invalid "
                        f"(first at line {int(lines[k])})")
        valid = valid & ~zero_q
    quat = normalize(quat)
    pos, quat = to_blender(pos, quat, axes_used)

    streams = {}
    for d in DEVICES:
        idx = np.nonzero(dev == d)[0]
        if idx.size == 0:
            continue
        td = t[idx]
        nonincr = np.nonzero(np.diff(td) <= 0)[0]
        if nonincr.size:
            k = int(nonincr[0])
            raise RecordingError(
                f"time {td[k + 1]:.6f} s of {d} is not after its previous sample at line "
                f"{int(lines[idx[k]])} ({td[k]:.6f} s): time must increase within each device",
                path=path, line=int(lines[idx[k + 1]]))
        streams[d] = TrackerStream(d, td, pos[idx], quat[idx], valid[idx])

    metadata["axes"] = axes_used
    metadata["units"] = units_used
    return Recording(streams=streams, source=path, metadata=metadata, warnings=warnings)


def _resolve(key, option, metadata, meta_line, canon, default, path, warnings):
    if option is not None:
        try:
            value = canon(option)
        except ValueError as exc:
            raise RecordingError(f"{key} option: {exc}", path=path) from None
        if key in metadata:
            try:
                file_value = canon(metadata[key])
            except ValueError:
                file_value = metadata[key]
            if file_value != value:
                warnings.append(f"{key}={value} (option) overrides the file's '# {key}: {metadata[key]}' "
                                f"(line {meta_line[key]})")
        return value
    if key in metadata:
        try:
            return canon(metadata[key])
        except ValueError as exc:
            raise RecordingError(f"metadata: {exc}", path=path, line=meta_line[key]) from None
    return default


def _streams_of(obj):
    if isinstance(obj, Recording):
        return list(obj.streams.values())
    if isinstance(obj, TrackerStream):
        return [obj]
    if isinstance(obj, dict):
        return list(obj.values())
    return list(obj)


def write_csv(path, recording_or_streams, axes="openxr", units="m", metadata=None,
              precision=6) -> None:
    """Write streams (Blender axes, metres) as a native CSV file.

    recording_or_streams: a :class:`Recording`, a dict device → stream, or an
    iterable of :class:`TrackerStream`.  axes: convention of the written file
    (``openxr`` default, ``unity``, ``blender``).  units: ``m``/``cm``/``mm``.
    metadata: extra ``# key: value`` lines (values are written with ``str``;
    a Recording's own scalar metadata is written too, ``axes``/``units``
    always reflect what was written).  precision: decimals for time and
    positions (quaternions get one more).

    Rows are ordered by time (ties by device order) and always carry a
    ``valid`` column.
    """
    axes = canonical_axes(axes)
    units = canonical_units(units)
    streams = sorted(_streams_of(recording_or_streams), key=lambda s: DEVICES.index(s.device))
    meta = {}
    if isinstance(recording_or_streams, Recording):
        for k, v in recording_or_streams.metadata.items():
            if isinstance(v, (str, int, float, bool, np.integer, np.floating)):
                meta[str(k)] = v
    if metadata:
        meta.update({str(k): v for k, v in metadata.items()})
    meta.pop("axes", None)
    meta.pop("units", None)

    times, devs, pos, quat, valid = [], [], [], [], []
    for s in streams:
        n = len(s)
        times.append(s.time)
        devs.append(np.full(n, DEVICES.index(s.device)))
        p, q = from_blender(s.pos, s.quat, axes)
        pos.append(p / UNITS[units])
        quat.append(q)
        valid.append(s.valid)
    if streams:
        t = np.concatenate(times)
        di = np.concatenate(devs)
        order = np.lexsort((di, t))
        t, di = t[order], di[order]
        P = np.concatenate(pos)[order]
        Q = np.concatenate(quat)[order]
        V = np.concatenate(valid)[order].astype(int)
    else:
        t = di = V = np.zeros(0)
        P = np.zeros((0, 3))
        Q = np.zeros((0, 4))

    p, qp = int(precision), int(precision) + 1
    fmt = (f"%.{p}f,%s,%.{p}f,%.{p}f,%.{p}f,%.{qp}f,%.{qp}f,%.{qp}f,%.{qp}f,%d")
    names = np.asarray(DEVICES, dtype=object)[di.astype(int)] if len(t) else []
    out = ["# blender_manikin tracker recording"]
    for k, v in meta.items():
        key = re.sub(r"[^\w\-]", "_", k) or "key"
        out.append(f"# {key}: {' '.join(str(v).split())}")
    out.append(f"# axes: {axes}")
    out.append(f"# units: {units}")
    out.append("time,device,px,py,pz,qw,qx,qy,qz,valid")
    out.extend(fmt % (t[i], names[i], P[i, 0], P[i, 1], P[i, 2], Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], V[i])
               for i in range(len(t)))
    with open(os.fspath(path), "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(out) + "\n")
