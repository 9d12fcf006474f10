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
  interleave in any order); a row repeating the time of the device's row before
  is ignored, with a warning.
* ``device``: ``head``, ``left_hand``, ``right_hand``, and optionally
  ``pelvis``, ``left_foot``, ``right_foot`` (case-insensitive; aliases such as
  ``hmd`` are accepted, see :data:`.recording.DEVICE_ALIASES`).  Rows of other names (extra
  trackers: chest, elbows, knees) are left out, each name counted in a warning with its first
  line, and listed in ``metadata["ignored_devices"]``; a solve missing a device it needs then
  names them too.
* ``px, py, pz``: position in ``units`` (default metres); ``qw, qx, qy, qz``:
  orientation quaternion (normalised on reading).  ``nan`` or an empty cell
  marks lost tracking.
* ``valid`` (optional): 1/0 (or true/false); 0 marks a sample whose pose the
  tracking system flagged as not tracked.
* Column order is free; extra columns are ignored; the header names are
  case-insensitive.
* Lines starting with ``#`` are comments.  ``# key: value`` comment lines are
  metadata: ``axes`` (``openxr`` default, ``unity``, ``blender``, ``unreal``; see
  :mod:`.recording`), ``units`` (``m``, ``cm``, ``mm``), ``source`` (free
  text); other keys are kept in :attr:`Recording.metadata`.

Problems (empty file, wrong header, missing column,
non-numeric field, wrong field count, non-increasing time within a device)
raise :class:`~.recording.RecordingError` naming the file, line and problem.
"""
from __future__ import annotations

import csv
import io
import os
import re

import numpy as np

from .plain import shown
from .pose_result import DEVICES
from .recording import (
    Recording, RecordingError, TrackerStream, UNITS, canonical_axes, canonical_device,
    canonical_units, decode_text, from_blender, not_data, read_check, text_codec, to_blender,
)
from .rotations import normalize, vector_norm

REQUIRED_COLUMNS = ("time", "device", "px", "py", "pz", "qw", "qx", "qy", "qz")
_NUMERIC = ("time", "px", "py", "pz", "qw", "qx", "qy", "qz")
_META_RE = re.compile(r"^#\s*([A-Za-z_][\w\-]*)\s*:\s*(.*?)\s*$")
_TRUE = {"1", "true", "yes", "1.0"}
_FALSE = {"0", "false", "no", "0.0"}


#: bytes read and parsed at a time: bounds the reader's working memory on big files
#: (the recording itself takes about 70 bytes per sample)
BLOCK_BYTES = 8 << 20


def _split(line):
    if '"' in line:
        return [f.strip() for f in next(csv.reader([line]))]
    return [f.strip() for f in line.split(",")]


def _to_float(values, name, lines, path):
    """Vectorised str → float64 with a line-accurate error on failure.  An empty cell of a pose
    column is a lost sample (NaN), as pandas' ``to_csv`` and spreadsheets write one; the time
    must be a number."""
    if name != "time":
        values = [v if v else "nan" for v in values]
    try:
        return np.array(values, dtype=np.float64)
    except ValueError:
        for s, ln in zip(values, lines):
            try:
                float(s)
            except ValueError:
                problem = f"{s!r} is not a number" if s else "the cell is empty"
                raise RecordingError(f"column '{name}': {problem}", path=path, line=int(ln)) from None
        raise


def _text_blocks(path, block_bytes):
    """Successive blocks of whole lines of the file at ``path``, as text.

    UTF-8 (a BOM is dropped), or UTF-16 / UTF-32 with a BOM (read whole: :func:`.recording.decode_text`);
    a byte that is not UTF-8 raises :class:`RecordingError` with its line (counting ``\n``), as
    does a stand-in for the data (a Git LFS pointer, an HTML page, a gzip file: :func:`.recording.not_data`)."""
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"cannot read file ({exc.strerror or exc})", path=path) from None
    with fh:
        line, rest, first = 1, b"", True     # line: of the block's start, for decoding errors
        while True:
            try:
                chunk = fh.read(block_bytes)
            except OSError as exc:
                raise RecordingError(f"cannot read file ({exc.strerror or exc})", path=path) from None
            buf = rest + chunk
            cut = len(buf) if not chunk else buf.rfind(b"\n") + 1
            if cut == 0 and chunk:         # no line end yet: read on
                rest = buf
                continue
            if first and text_codec(buf[:512])[0] != "utf-8" or first and not_data(buf[:512]):
                yield decode_text(buf + fh.read(), path=path)      # UTF-16/32: whole; a stand-in: raises
                return
            block, rest = buf[:cut], buf[cut:]
            if block:
                try:
                    text = block.decode("utf-8-sig" if first else "utf-8")
                except UnicodeDecodeError as exc:
                    raise RecordingError(f"not UTF-8 text (byte 0x{block[exc.start]:02x}): save it as UTF-8 "
                                         f"(Excel: CSV UTF-8)", path=path,
                                         line=line + block[:exc.start].count(b"\n")) from None
                yield text
                line += block.count(b"\n")
                first = False
            if not chunk:
                return


class _Block:
    """Parsed data rows of one block: ``t (n,)`` seconds, ``pq (n, 7)`` px..qz in file units and
    axes, ``valid (n,)`` bool, ``names`` device names as written, ``lines (n,)`` line numbers."""
    __slots__ = ("t", "pq", "valid", "names", "lines")


def _parse_exact(rows, lines, header, path):
    """Parse data lines one field at a time (quoted fields, odd cells): the reference path whose
    errors name the exact line and cell.  rows: stripped data lines; lines: their numbers."""
    fields = [_split(r) for r in rows]
    ncol = len(header)
    counts = np.fromiter((len(r) for r in fields), dtype=np.int64, count=len(fields))
    bad = np.nonzero(counts != ncol)[0]
    if bad.size:
        k = int(bad[0])
        raise RecordingError(f"expected {ncol} comma-separated fields (as in the header), found {counts[k]}",
                             path=path, line=int(lines[k]))
    cols = list(zip(*fields))
    b = _Block()
    num = [_to_float(cols[header.index(n)], n, lines, path) for n in _NUMERIC]
    b.t, b.pq = num[0], np.stack(num[1:], -1)
    if "valid" in header:
        raw = cols[header.index("valid")]
        vs = np.char.lower(np.asarray(raw, dtype=str))
        is_true, is_false = np.isin(vs, list(_TRUE)), np.isin(vs, list(_FALSE))
        badv = np.nonzero(~(is_true | is_false))[0]
        if badv.size:
            k = int(badv[0])
            raise RecordingError(f"column 'valid': {shown(raw[k])} is not 0 or 1", path=path, line=int(lines[k]))
        b.valid = is_true
    else:
        b.valid = np.ones(len(rows), dtype=bool)
    b.names = list(cols[header.index("device")])
    b.lines = np.asarray(lines, dtype=np.int64)
    return b


#: longest device name the fast path reads (a longer one goes through the exact path)
_NAME_CHARS = 24


def _parse_fast(rows, lines, header, text=None):
    """The same as :func:`_parse_exact` through numpy's C CSV parser; None where that path
    cannot be sure (quotes, a cell it does not parse, a field count off), so the caller falls
    back to the exact path for the block.  text: the block's whole text when ``rows`` are all
    its lines (lets the checks run on it in one pass); rows may then be None (not split yet)."""
    ncol = len(header)
    if ('"' in text) if text is not None else any('"' in r for r in rows):
        return None
    cols = [header.index(n) for n in _NUMERIC] + ([header.index("valid")] if "valid" in header else [])
    # Field counts: numpy rejects a row that lacks a column it reads; the comma total then
    # catches rows with too many fields, unless unread columns follow the last one it reads.
    commas = text.count(",") if text is not None else sum(r.count(",") for r in rows)
    if commas != (ncol - 1) * len(lines):
        return None
    if max(cols) < ncol - 1:
        rows = text.splitlines() if rows is None else rows
        if any(r.count(",") != ncol - 1 for r in rows):
            return None
    dcol = header.index("device")
    use = sorted(cols + [dcol])
    dtype = np.dtype([(f"c{c}", f"S{_NAME_CHARS}" if c == dcol else np.float64) for c in use])
    try:           # one pass of numpy's C parser over the block (a text stream reads fastest)
        rec = np.loadtxt(io.StringIO(text) if rows is None else rows, delimiter=",", usecols=use,
                         dtype=dtype, ndmin=1, comments=None)
    except (ValueError, UnicodeEncodeError):
        return None
    if len(rec) != len(lines):          # numpy skipped a blank (whitespace) line: line numbers would slip
        return None
    names = np.ascontiguousarray(rec[f"c{dcol}"])
    if names.size and np.any(names.view(np.uint8).reshape(len(names), _NAME_CHARS)[:, -1]):
        return None                     # a name may have been cut short
    b = _Block()
    b.t = rec[f"c{cols[0]}"].copy()
    b.pq = np.stack([rec[f"c{c}"] for c in cols[1:8]], -1)
    if "valid" in header:
        v = rec[f"c{cols[8]}"]
        if not np.all((v == 0) | (v == 1)):
            return None
        b.valid = v == 1
    else:
        b.valid = np.ones(len(lines), dtype=bool)
    b.names = names
    b.lines = lines
    return b


def _device_codes(block, unknown, labels):
    """``(n,)`` int8 index into :data:`DEVICES` of each row's device name, -1 for a name that is
    not a device (an extra tracker: chest, elbows, knees; or a typo), counted in ``unknown``
    (name → ``[rows, first line]``); ``labels`` gets the first name each device is written with
    (device → name, e.g. ``"head": "HMD"``; rows under another of its names are the same device's).
    One vectorised comparison per distinct name."""
    names = np.asarray(block.names)
    codes = np.empty(len(names), dtype=np.int8)
    todo = np.ones(len(names), dtype=bool)
    while todo.any():
        k = int(np.argmax(todo))
        name = names[k].decode("utf-8", "replace") if isinstance(names[k], bytes) else str(names[k])
        d = canonical_device(name)
        same = names == names[k]
        if d is None:
            seen = unknown.setdefault(name.strip(), [0, int(block.lines[k])])
            seen[0] += int(same.sum())
            codes[same] = -1
        else:
            codes[same] = DEVICES.index(d)
            labels.setdefault(d, name.strip())
        todo &= ~same
    return codes


def read_csv(path, axes=None, units=None, block_bytes=None) -> Recording:
    """Read a native CSV recording (see module docstring).

    path: file path.  axes: ``openxr``/``unity``/``blender``/``unreal`` overriding the
    file's ``# axes:`` metadata (default ``openxr``).  units: ``m``/``cm``/``mm``
    overriding ``# units:`` (default ``m``).  block_bytes: how much of the file is
    parsed at a time (default :data:`BLOCK_BYTES`; the result does not depend on it); a
    cancel (:func:`.recording.cancellable_reads`) is checked before each.
    The common rows (no quotes, nothing odd) go through numpy's C parser; a block with
    anything else is parsed field by field, so errors name the exact line either way.

    Returns a :class:`Recording` in Blender axes and metres with
    ``metadata['axes']``/``['units']`` set to what was applied.
    """
    path = os.fspath(path)
    metadata, meta_line = {}, {}
    header = header_line = None
    blocks = []
    unknown = {}                             # rows of names that are not devices
    labels = {}                              # device -> the name the file writes it with
    any_text = False
    first = 1                                # line number of the block's first line
    for text in _text_blocks(path, max(int(block_bytes or BLOCK_BYTES), 1)):
        read_check()                         # a cancel (Esc in Blender) stops the read between blocks
        if header is not None and text[:1] not in ("\n", "#") and "#" not in text and "\r" not in text \
                and "\n\n" not in text:
            # the usual block: data lines only (no comment, blank line or CR), parsed unsplit
            n = text.count("\n") + (not text.endswith("\n"))
            block = _parse_fast(None, np.arange(first, first + n, dtype=np.int64), header, text=text)
            if block is not None:
                block.names = _device_codes(block, unknown, labels)
                blocks.append(block)
                first += n
                continue
        block_lines = text.splitlines()
        j = 0
        if header is None:                  # comments, metadata and the header, line by line
            while j < len(block_lines) and header is None:
                s = block_lines[j].strip()
                if s and not s.startswith("#"):
                    header = [f.lower() for f in _split(s)]
                    header_line = first + j
                    _check_header(header, header_line, path)
                elif s:
                    _metadata_line(s, first + j, metadata, meta_line)
                any_text = any_text or bool(s)
                j += 1
        rest = block_lines[j:]
        if not rest:
            first += len(block_lines)
            continue
        rows = [s for s in rest if s and s[0] != "#"]
        block = None
        if len(rows) == len(rest):          # data lines only
            block = _parse_fast(rows, np.arange(first + j, first + j + len(rest), dtype=np.int64), header,
                                text="\n".join(rest))
        if block is None:                   # comments, blank or padded lines, odd cells: line by line
            rest = [ln.strip() for ln in rest]
            for i, s in enumerate(rest):
                if s.startswith("#"):
                    _metadata_line(s, first + j + i, metadata, meta_line)
            rows = [s for s in rest if s and s[0] != "#"]
            lines = np.asarray([first + j + i for i, s in enumerate(rest) if s and s[0] != "#"], dtype=np.int64)
            if rows:
                block = _parse_fast(rows, lines, header) or _parse_exact(rows, lines, header, path)
        if block is not None:
            block.names = _device_codes(block, unknown, labels)     # int8 codes from here on (names are 24 bytes a row)
            blocks.append(block)
            any_text = True
        first += len(block_lines)

    if not any_text:
        raise RecordingError("file is empty", path=path)
    if header is None:
        raise RecordingError("no column header and no data (only comments)", path=path)
    if not blocks:
        raise RecordingError("no data rows after the header", path=path, line=header_line)

    # --- axes and units: option wins over metadata
    warnings = []
    axes_stated = axes is not None or "axes" in metadata
    axes_used = _resolve("axes", axes, metadata, meta_line, canonical_axes, "openxr", path, warnings)
    units_used = _resolve("units", units, metadata, meta_line, canonical_units, "m", path, warnings)

    lines = np.concatenate([b.lines for b in blocks])
    t = np.concatenate([b.t for b in blocks])
    nonfinite = np.nonzero(~np.isfinite(t))[0]
    if nonfinite.size:
        k = int(nonfinite[0])
        raise RecordingError(f"time {shown(t[k])} is not a finite number", path=path, line=int(lines[k]))

    dev = np.concatenate([b.names for b in blocks])
    valid = np.concatenate([b.valid for b in blocks])
    pq = np.concatenate([b.pq for b in blocks])
    del blocks

    # in place on the one (n, 7) array: scale, quaternion lengths, normalisation; then each
    # device's rows are copied out and turned to Blender axes (peak: about twice the result)
    pq[np.isinf(pq)] = np.nan          # "inf", or past float64's range (1e309): a lost sample, as NaN
    scale = UNITS[units_used]
    if scale != 1.0:
        pq[:, :3] *= scale
    quat = pq[:, 3:]
    qn = vector_norm(quat)
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
    normalize(quat, norm=qn, out=quat)
    del qn, finite_q, zero_q, off_unit

    streams = {}
    for code, d in enumerate(DEVICES):
        idx = np.nonzero(dev == code)[0]
        if idx.size == 0:
            continue
        td = t[idx]
        repeat = np.nonzero(np.diff(td) == 0)[0] + 1
        if repeat.size:             # a logger that writes a frame twice: the first of each kept
            warnings.append(f"{d}: {repeat.size} row(s) repeating the time of the row before ignored "
                            f"(first at line {int(lines[idx[repeat[0]]])})")
            idx = np.delete(idx, repeat)
            td = t[idx]
        nonincr = np.nonzero(np.diff(td) <= 0)[0]
        if nonincr.size:
            k = int(nonincr[0])
            raise RecordingError(
                f"time {td[k + 1]:.6f} s of {d} is not after its previous sample at line "
                f"{int(lines[idx[k]])} ({td[k]:.6f} s): time must increase within each device",
                path=path, line=int(lines[idx[k + 1]]))
        rows = pq[idx]
        pos_d, quat_d = to_blender(rows[:, :3], rows[:, 3:], axes_used)
        del rows
        streams[d] = TrackerStream(d, td, pos_d, quat_d, valid[idx])

    for name, (rows, line) in unknown.items():
        warnings.append(f"device {shown(name)}: {rows} row(s) from line {line} ignored (not one of "
                        f"{', '.join(DEVICES)})")
    if unknown:
        metadata["ignored_devices"] = list(unknown)
    metadata["device_labels"] = labels
    metadata["axes"] = axes_used
    metadata["units"] = units_used
    if not axes_stated:
        back = _walked_backwards(streams)
        if back >= WALK_BACK_WARN_S:
            warnings.append(f"no '# axes:' line, so read as openxr; that way the performer walks backwards "
                            f"{back:.1f} s more than forwards: a Unity recording? (add '# axes: unity' or "
                            f"pass --axes unity if the body walks backwards)")
    return Recording(streams=streams, source=path, metadata=metadata, warnings=warnings)


#: seconds of net backward walking, read with the default axes, above which a native CSV that
#: states no axes is warned about (:func:`_walked_backwards`; people walk the way they face)
WALK_BACK_WARN_S = 2.0


def _walked_backwards(streams):
    """Seconds the head walks backwards less forwards (:func:`.axes_detect.walking_seconds`),
    Blender axes, or 0 without a head with enough samples."""
    from .axes_detect import forward_of, walking_seconds
    from .features import heading_yaw
    from .rotations import quat_to_matrix
    head = streams.get("head")
    if head is None or len(head.time) < 3:
        return 0.0
    ok = head.valid & np.isfinite(head.pos).all(-1) & np.isfinite(head.quat).all(-1)
    if ok.sum() < 3:
        return 0.0
    fwd = forward_of(heading_yaw(quat_to_matrix(head.quat[ok])))
    return -walking_seconds(head.time[ok], head.pos[ok], fwd, 2)


def _metadata_line(s, line, metadata, meta_line):
    """Keep a ``# key: value`` comment line's pair in ``metadata`` (other comments are ignored)."""
    m = _META_RE.match(s)
    if m:
        key = m.group(1).lower()
        metadata[key] = m.group(2)
        meta_line[key] = line


def _check_header(header, header_line, path):
    """Raise :class:`RecordingError` when the header lacks or repeats a required column."""
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
            found = ",".join(header)
            sep = next((name for ch, name in ((";", "semicolons"), ("\t", "tabs"), ("|", "bars"))
                        if len(header) == 1 and found.count(ch) >= len(REQUIRED_COLUMNS) - 1), None)
            hint = f": the fields are separated by {sep}, this format by commas" if sep else ""
            raise RecordingError(f"wrong header: expected the column names {expected!r} "
                                 f"(any order), found {found!r}{hint}", path=path, line=header_line)
        raise RecordingError(f"header is missing column(s) {', '.join(missing)} (expected {expected!r})",
                             path=path, line=header_line)
    dup = sorted({c for c in header if header.count(c) > 1 and c in REQUIRED_COLUMNS + ("valid",)})
    if dup:
        raise RecordingError(f"header repeats column(s) {', '.join(dup)}", path=path, line=header_line)


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
    (``openxr`` default, ``unity``, ``blender``, ``unreal``).  units: ``m``/``cm``/``mm``.
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
