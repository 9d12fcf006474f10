"""Read the marker trajectories of a C3D file (Vicon, Qualisys, OptiTrack / Motive, Cortex exports).

Pure numpy + :mod:`struct`, no bpy.  What is read (the C3D user guide's layout, as
``EmbodiedCognition/py-c3d`` reads it):

* the 512-byte header: byte 0 the parameter section's first 512-byte block (1-based), byte 1
  the key ``0x50``; 16-bit words for the point count, the analog samples per frame, the first
  and last frame, the scale (a float; negative: the data are floats), the data's first block,
  the analog samples per frame and the frame rate (a float);
* the parameter section: 4 bytes (byte 2 its block count, byte 3 the processor: 84 Intel,
  little-endian IEEE; 85 DEC, little-endian 16-bit words holding VAX F floats; 86 MIPS,
  big-endian IEEE), then groups and parameters (a name's length negative when locked; a negative
  id a group, a positive one a parameter of that group; a 16-bit offset to the next entry;
  a parameter's type -1 char, 1 byte, 2 int16, 4 float and its dimensions, first fastest);
  ``POINT:USED``, ``SCALE``, ``RATE``, ``UNITS``, ``DATA_START`` (only where the header's word 9
  is 0: the header's wins), ``FRAMES`` / ``LONG_FRAMES`` (the larger), ``LABELS`` (then
  ``LABELS2``, ``LABELS3`` ... past 255 markers), ``ANALOG:USED`` / ``RATE`` and
  ``TRIAL:ACTUAL_START_FIELD`` / ``ACTUAL_END_FIELD`` (two 16-bit words each, low first: takes
  longer than 65535 frames, read only when the header's last frame is 65535 or before its first);
* the data: per frame each marker's x, y, z and a residual word (int16 × ``POINT:SCALE``, or
  float32 when the scale is negative); a negative residual marks the sample invalid (NaN here);
  the analog samples stored after each frame's markers are skipped.

Errors are :class:`.recording.RecordingError` naming the file, the byte offset and the problem.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from .plain import shown
from .recording import RecordingError, read_file_bytes, row_chunks

BLOCK = 512
#: parameter section byte 3: the processor that wrote the file
PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}
#: POINT:UNITS as the keypoint reader's unit names
_UNITS = {"mm": "mm", "millimeters": "mm", "millimetres": "mm", "cm": "cm", "m": "m", "meters": "m",
          "metres": "m"}


@dataclass
class C3DMarkers:
    """A C3D's markers.  names: ``POINT:LABELS`` (``LABELS2`` ... after it), K of them, as
    written (``Subject:LASI`` keeps its prefix); points: ``(T, K, 3)`` float64 in the file's units
    and axes, NaN where a sample is invalid; units: ``"mm"`` / ``"cm"`` / ``"m"`` from
    ``POINT:UNITS``, None when it says none of these; rate: frames per second; first_frame: the
    take's first frame number (1-based); processor: ``"Intel"`` / ``"DEC"`` / ``"MIPS"``;
    labels_offset: the byte offset of the ``POINT:LABELS`` parameter (for messages)."""
    names: list
    points: np.ndarray
    units: str | None
    rate: float
    first_frame: int
    processor: str
    labels_offset: int | None

    @property
    def time(self):
        """``(T,)`` seconds on the take's clock: frame ``first_frame`` at ``(first_frame - 1) / rate``."""
        return (self.first_frame - 1 + np.arange(len(self.points), dtype=np.float64)) / self.rate


def dec_to_float(raw) -> np.ndarray:
    """VAX F floats (DEC processor files) as float64: ``raw`` bytes, 4 a value, each two
    little-endian 16-bit words, the first holding the sign, 8 exponent bits (excess 128) and the
    fraction's top 7 bits, the second the fraction's low 16.  Value ``0.1f × 2^(e - 128)``
    (hidden leading bit), 0 where the exponent is 0: the word-swapped bits read as an IEEE float
    divided by 4, computed here exactly (also for exponents IEEE would call infinite)."""
    w = np.frombuffer(bytes(raw), dtype="<u2").reshape(-1, 2).astype(np.uint32)
    u = (w[:, 0] << 16) | w[:, 1]
    exp = ((u >> 23) & 0xFF).astype(np.int64)
    frac = (u & 0x7FFFFF).astype(np.float64)
    val = np.ldexp(0.5 + frac / float(1 << 24), exp - 128)
    val[exp == 0] = 0.0
    return np.where(u >> 31, -val, val)


class _Decoder:
    """Numbers in one processor's encoding."""

    def __init__(self, processor):
        self.name = PROCESSORS[processor]
        self.end = ">" if self.name == "MIPS" else "<"

    def ints(self, raw, signed=True):
        return np.frombuffer(bytes(raw), dtype=f"{self.end}{'i2' if signed else 'u2'}").astype(np.int64)

    def floats(self, raw):
        if self.name == "DEC":
            return dec_to_float(raw)
        return np.frombuffer(bytes(raw), dtype=f"{self.end}f4").astype(np.float64)


@dataclass
class _Param:
    type: int
    dims: tuple
    raw: bytes
    offset: int


def _params(data, start, dec, path):
    """``{(GROUP, NAME): _Param}`` of the parameter section beginning at byte ``start``."""
    n_blocks = data[start + 2]
    end = start + BLOCK * n_blocks
    if n_blocks == 0:
        raise RecordingError("the parameter section says it has 0 blocks", path=path, offset=start + 2)
    if end > len(data):
        raise RecordingError(f"the parameter section ({n_blocks} blocks of 512 bytes from byte {start}) runs "
                             f"past the end of the file ({len(data)} bytes)", path=path, offset=start + 2)
    groups, found = {}, []
    pos = start + 4
    while pos + 2 <= end:
        n, gid = struct.unpack_from("bb", data, pos)
        if n == 0 or gid == 0:
            break
        name_end = pos + 2 + abs(n)
        if name_end + 2 > end:
            raise RecordingError("a parameter entry runs past the parameter section", path=path, offset=pos)
        name = data[pos + 2:name_end].decode("latin-1").strip().upper()
        nxt = int(dec.ints(data[name_end:name_end + 2])[0])
        stop = end if nxt == 0 else name_end + nxt
        if nxt < 0 or stop > end or (nxt and nxt < 2):
            raise RecordingError(f"entry {shown(name)}'s offset to the next entry ({nxt}) points outside the "
                                 "parameter section", path=path, offset=name_end)
        if gid < 0:
            groups[-gid] = name
        else:
            p = name_end + 2
            if p + 2 > stop:
                raise RecordingError(f"parameter {shown(name)} is cut short", path=path, offset=pos)
            typ, nd = struct.unpack_from("bB", data, p)
            if typ not in (-1, 1, 2, 4):
                raise RecordingError(f"parameter {shown(name)} has type {typ} (expected -1 char, 1 byte, "
                                     "2 int16 or 4 float)", path=path, offset=p)
            dims = tuple(data[p + 2:p + 2 + nd])
            size = abs(typ) * int(np.prod(dims, dtype=np.int64))
            body = p + 2 + nd
            if body + size > stop:
                raise RecordingError(f"parameter {shown(name)}'s {size} bytes of values run past its entry",
                                     path=path, offset=body)
            found.append((gid, name, _Param(typ, dims, data[body:body + size], pos)))
        if nxt == 0:
            break
        pos = stop
    return {(groups.get(gid, str(gid)), name): p for gid, name, p in found}


def _strings(p):
    """A char parameter's strings (its first dimension the length, the rest their count)."""
    if p.type != -1:
        return []
    if not p.dims:
        return [p.raw.decode("latin-1").strip()]
    L = p.dims[0]
    return [p.raw[i:i + L].decode("utf-8", "replace").strip() for i in range(0, len(p.raw), L)] if L else []


def _numbers(p, dec):
    """A numeric parameter's values, flat (first dimension fastest), float64."""
    if p.type == 4:
        return dec.floats(p.raw)
    if p.type == 2:
        return dec.ints(p.raw).astype(np.float64)
    if p.type == 1:
        return np.frombuffer(p.raw, np.uint8).astype(np.float64)
    return np.zeros(0)


def read_c3d(path) -> C3DMarkers:
    """The markers of the C3D file at ``path`` (:class:`C3DMarkers`)."""
    data = read_file_bytes(path)
    if len(data) < BLOCK:
        raise RecordingError(f"not a C3D file: {len(data)} bytes, shorter than its 512-byte header", path=path)
    if data[1] != 0x50:
        raise RecordingError(f"not a C3D file: byte 2 is 0x{data[1]:02X}, not 0x50", path=path, offset=1)
    start = (data[0] - 1) * BLOCK
    if data[0] == 0 or start + 4 > len(data):
        raise RecordingError(f"the parameter section's block ({data[0]}) is outside the file ({len(data)} "
                             "bytes)", path=path, offset=0)
    proc = data[start + 3]
    if proc not in PROCESSORS:
        raise RecordingError(f"processor type {proc} (expected 84 Intel, 85 DEC or 86 MIPS)", path=path,
                             offset=start + 3)
    dec = _Decoder(proc)
    words = dec.ints(data[2:12], signed=False)      # point count, analog per frame, first, last, gap
    h_points, h_analog, h_first, h_last = (int(v) for v in words[:4])
    h_scale, h_rate = float(dec.floats(data[12:16])[0]), float(dec.floats(data[20:24])[0])
    h_start = int(dec.ints(data[16:18], signed=False)[0])
    params = _params(data, start, dec, path)
    if not any(g == "POINT" for g, _ in params):
        raise RecordingError("no POINT group among the parameters", path=path, offset=start)

    def num(group, name, default=None):
        p = params.get((group, name))
        v = None if p is None else _numbers(p, dec)
        return default if v is None or not v.size else v

    def first(group, name, default, signed=False):
        v = num(group, name)
        if v is None:
            return default
        x = float(v[0])
        return x + 65536 if not signed and params[(group, name)].type == 2 and x < 0 else x

    def where(group, name, header_offset):
        """The byte offset of a parameter for a message, the header's word where it is absent."""
        return params[(group, name)].offset if (group, name) in params else header_offset

    def count(value, what, offset, lowest=0):
        """A count read from a parameter (a float parameter may hold NaN, inf or a fraction) as an int."""
        if not (np.isfinite(value) and value == int(value) and value >= lowest):
            raise RecordingError(f"{what} is {shown(value)}, not a whole number of {lowest} or more", path=path,
                                 offset=offset)
        return int(value)

    used = first("POINT", "USED", h_points)
    if used == 0:
        raise RecordingError("zero markers (POINT:USED is 0)", path=path, offset=where("POINT", "USED", 2))
    used = count(used, "the marker count (POINT:USED)", where("POINT", "USED", 2), lowest=1)
    scale = first("POINT", "SCALE", h_scale, signed=True)
    if not np.isfinite(scale) or scale == 0:     # NaN read every sample as missing, 0 every marker at the origin
        raise RecordingError(f"the scale {shown(scale)} (POINT:SCALE) is not a nonzero number (negative: float "
                             f"data)", path=path, offset=where("POINT", "SCALE", 12))
    rate = first("POINT", "RATE", h_rate, signed=True)
    if not np.isfinite(rate) or rate <= 0:
        raise RecordingError(f"frame rate {shown(rate)} (POINT:RATE) is not a positive number", path=path,
                             offset=params[("POINT", "RATE")].offset if ("POINT", "RATE") in params else 20)
    # the header's word 9 places the data, as py-c3d and ezc3d read it (a POINT:DATA_START left stale
    # by an editing tool read frames from the wrong block); the parameter only where the word is 0
    data_start = h_start or count(first("POINT", "DATA_START", 0), "the data's first block (POINT:DATA_START)",
                                  where("POINT", "DATA_START", 16))
    s_field, e_field = num("TRIAL", "ACTUAL_START_FIELD"), num("TRIAL", "ACTUAL_END_FIELD")
    if h_first <= h_last and h_last != 65535:
        # the header's frames where they hold the take (as py-c3d): the TRIAL fields only past
        # 65535 (a stale ACTUAL_END_FIELD read the zeros padding the last block as frames)
        first_frame, n = h_first, h_last - h_first + 1
    elif s_field is not None and e_field is not None and s_field.size >= 2 and e_field.size >= 2:
        lo_hi = [count(float(v[0]) % 65536 + 65536 * (float(v[1]) % 65536), f"the {k} frame (TRIAL:ACTUAL_{k.upper()}"
                       "_FIELD)", where("TRIAL", f"ACTUAL_{k.upper()}_FIELD", 6))
                 for v, k in ((s_field, "start"), (e_field, "end"))]
        first_frame, n = lo_hi[0], lo_hi[1] - lo_hi[0] + 1
    else:
        # POINT:FRAMES (int16 capped at 65535, or a float) or POINT:LONG_FRAMES (a float, QTM):
        # the larger, as py-c3d
        first_frame, n = h_first, max(count(first("POINT", k, 0), f"the frame count (POINT:{k})",
                                            where("POINT", k, 6)) for k in ("FRAMES", "LONG_FRAMES"))
    if n <= 0:
        raise RecordingError(f"no frames (first {first_frame}, frame count {n})", path=path, offset=6)
    labels = []
    for key in ["LABELS"] + [f"LABELS{k}" for k in range(2, 100)]:
        if ("POINT", key) not in params:
            break
        labels += _strings(params[("POINT", key)])
    units = _UNITS.get((_strings(params[("POINT", "UNITS")]) or [""])[0].lower()) \
        if ("POINT", "UNITS") in params else None
    # the data: per frame 4 words a marker, then the analog samples
    is_float = scale < 0
    word = 4 if is_float else 2
    channels = first("ANALOG", "USED", None)
    a_rate = first("ANALOG", "RATE", None, signed=True)
    if channels is not None and a_rate is not None:
        channels = count(channels, "the analog channel count (ANALOG:USED)", where("ANALOG", "USED", 4))
        per_frame = a_rate / rate
        if not (np.isfinite(per_frame) and per_frame >= 0):
            raise RecordingError(f"the analog rate (ANALOG:RATE) is {shown(a_rate)}, not a rate in Hz",
                                 path=path, offset=where("ANALOG", "RATE", 4))
        n_analog = channels * int(round(per_frame))
    else:
        n_analog = h_analog
    frame_bytes = (4 * used + n_analog) * word
    at = (data_start - 1) * BLOCK
    if data_start < 1 or at > len(data):
        said = "the header's word 9" if h_start else "POINT:DATA_START"
        raise RecordingError(f"the data's first block ({data_start}, {said}) is outside the file ({len(data)} "
                             "bytes)", path=path, offset=16)
    need = at + n * frame_bytes
    if need > len(data):
        raise RecordingError(f"truncated: {n} frames of {frame_bytes} bytes from byte {at} need {need} bytes, "
                             f"the file has {len(data)} (frame {(len(data) - at) // frame_bytes + 1} is cut "
                             "short)", path=path, offset=len(data))
    names = [(labels[k] if k < len(labels) else "") or f"*{k}" for k in range(used)]
    block = np.frombuffer(data, np.uint8, n * frame_bytes, at).reshape(n, frame_bytes)
    pts = np.empty((n, used, 3))
    for part in row_chunks(n):                   # a chunk of frames at a time: a cancel is checked between
        raw = block[part, :4 * used * word].tobytes()
        vals = (dec.floats(raw) if is_float else dec.ints(raw).astype(np.float64)).reshape(-1, used, 4)
        chunk = vals[..., :3] * (1.0 if is_float else abs(scale))
        chunk[~(vals[..., 3] >= 0) | ~np.isfinite(chunk).all(-1)] = np.nan
        pts[part] = chunk
    return C3DMarkers(names, pts, units, float(rate), int(first_frame), dec.name,
                      params[("POINT", "LABELS")].offset if ("POINT", "LABELS") in params else None)
