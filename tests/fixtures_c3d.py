"""A small C3D writer for tests (numpy + struct): marker motion written as Vicon / Qualisys files
are, in each processor's encoding (Intel, DEC, MIPS), as int16 × scale or float32, with analog
channels between the frames, ``LABELS2`` past a split, invalid samples and takes longer than
65535 frames (``TRIAL:ACTUAL_START_FIELD`` / ``ACTUAL_END_FIELD``).

DEC floats are written the way the C3D user guide and ``EmbodiedCognition/py-c3d`` state it:
the IEEE single of 4 × the value, its two 16-bit words swapped (each word little-endian).
"""
import struct

import numpy as np

PROC = {"intel": 84, "dec": 85, "mips": 86}


def float_bytes(values, proc):
    """``values`` as 4-byte floats of processor ``proc``."""
    v = np.asarray(values, np.float64).ravel()
    if proc == "mips":
        return v.astype(">f4").tobytes()
    if proc == "intel":
        return v.astype("<f4").tobytes()
    u = (v * 4.0).astype("<f4").view("<u4")
    return np.stack([(u >> 16) & 0xFFFF, u & 0xFFFF], -1).astype("<u2").tobytes()


def int_bytes(values, proc):
    """``values`` as 16-bit words of processor ``proc`` (0 to 65535 wrap to the signed range)."""
    v = np.asarray(values, np.int64)
    return np.where(v > 32767, v - 65536, v).astype(">i2" if proc == "mips" else "<i2").tobytes()


def _param(name, gid, typ, dims, payload, proc, locked=False):
    e = ">" if proc == "mips" else "<"
    nb = name.encode()
    body = struct.pack("bB", typ, len(dims)) + bytes(dims) + payload + b"\x00"
    return struct.pack("bb", -len(nb) if locked else len(nb), gid) + nb + struct.pack(e + "h", 2 + len(body)) + body


def _group(name, gid, proc):
    e = ">" if proc == "mips" else "<"
    nb = name.encode()
    return struct.pack("bb", len(nb), -gid) + nb + struct.pack(e + "h", 3) + b"\x00"


def _chars(strings):
    L = max([len(s) for s in strings] + [1])
    return L, b"".join(s.encode().ljust(L) for s in strings)


def write_c3d(path, names, pts, rate=60.0, proc="intel", floats=False, scale=0.1, units="mm",
              analog_channels=0, analog_per_frame=0, invalid=None, labels_split=255, first_frame=1,
              long_take=False, groups_after=False, data_start_param=None, long_frames=False):
    """Write ``pts`` ``(T, K, 3)`` (in ``units``, file axes) as a C3D.  invalid: ``(T, K)`` bool
    samples written with a residual of -1 (their coordinates junk).  labels_split: markers per
    ``LABELS`` parameter (255 in real files).  long_take: the header's last frame 65535 and the
    frames in ``TRIAL:ACTUAL_*_FIELD`` (long_frames: in ``POINT:LONG_FRAMES``, a float, as QTM writes
    it, with ``POINT:FRAMES`` capped at 65535 and no ``TRIAL`` fields).  groups_after: parameters
    listed before their groups.  data_start_param: a ``POINT:DATA_START`` value to write (None: the
    parameter left out; the header's word 9 always holds the true block)."""
    pts = np.asarray(pts, np.float64)
    T, K = pts.shape[:2]
    inv = np.zeros((T, K), bool) if invalid is None else np.asarray(invalid, bool)
    e = ">" if proc == "mips" else "<"
    fl = (lambda v: float_bytes([v], proc))
    n_analog = analog_channels * analog_per_frame
    P, A, TR = 1, 2, 3
    params = []
    labels = [names[i:i + labels_split] for i in range(0, K, labels_split)]
    for k, chunk in enumerate(labels):
        L, raw = _chars(chunk)
        params.append(_param("LABELS" if k == 0 else f"LABELS{k + 1}", P, -1, (L, len(chunk)), raw, proc,
                             locked=k == 0))
    params += [
        _param("USED", P, 2, (), int_bytes([K], proc), proc, locked=True),
        _param("SCALE", P, 4, (), fl(-1.0 if floats else scale), proc),
        _param("RATE", P, 4, (), fl(rate), proc),
        _param("UNITS", P, -1, (len(units),), units.encode(), proc),
        _param("FRAMES", P, 2, (), int_bytes([min(T, 65535)], proc), proc),
        _param("DESCRIPTIONS", P, -1, (4, min(K, 255)), b"mark" * min(K, 255), proc),
        _param("USED", A, 2, (), int_bytes([analog_channels], proc), proc),
        _param("RATE", A, 4, (), fl(rate * analog_per_frame), proc),
        _param("GEN_SCALE", A, 4, (), fl(1.0), proc),
    ]
    last = first_frame + T - 1
    if data_start_param is not None:
        params.append(_param("DATA_START", P, 2, (), int_bytes([data_start_param], proc), proc))
    if long_frames:
        params.append(_param("LONG_FRAMES", P, 4, (), fl(float(T)), proc))
    if long_take and not long_frames:
        w = lambda f: int_bytes(np.array([f % 65536, f // 65536], np.uint16).view(np.int16), proc)  # noqa: E731
        params += [_param("ACTUAL_START_FIELD", TR, 2, (2,), w(first_frame), proc),
                   _param("ACTUAL_END_FIELD", TR, 2, (2,), w(last), proc)]
    groups = [_group("POINT", P, proc), _group("ANALOG", A, proc), _group("TRIAL", TR, proc)]
    section = b"".join(params + groups if groups_after else groups + params)
    n_blocks = (4 + len(section) + 511) // 512
    param_blocks = (bytes([1, 0x50, n_blocks, PROC[proc]]) + section).ljust(512 * n_blocks, b"\x00")
    data_start = 2 + n_blocks
    word = (lambda v: struct.pack(e + "H", v))
    header = bytearray(512)
    header[0:2] = bytes([2, 0x50])
    header[2:12] = b"".join(word(v) for v in (K, n_analog, first_frame % 65536,
                                              65535 if long_take or long_frames else last % 65536, 10))
    header[12:16] = fl(-1.0 if floats else scale)
    header[16:20] = word(data_start) + word(analog_per_frame)
    header[20:24] = fl(rate)
    # frames: x, y, z, residual per marker, then the analog samples
    rng = np.random.default_rng(0)
    four = np.concatenate([pts, np.zeros((T, K, 1))], -1)
    four[inv] = [rng.uniform(-999, 999), 0.0, 0.0, -1.0]
    analog = rng.uniform(-500, 500, (T, n_analog))
    if floats:
        frames = np.concatenate([four.reshape(T, -1), analog], 1)
        raw = float_bytes(frames, proc)
    else:
        q = np.round(four / scale)
        q[..., 3] = four[..., 3]
        frames = np.concatenate([q.reshape(T, -1), np.round(analog)], 1)
        assert np.abs(frames).max(initial=0) < 32767, "the markers do not fit int16 at this scale"
        raw = int_bytes(frames, proc)
    with open(path, "wb") as f:
        f.write(bytes(header) + param_blocks + raw.ljust(-(-len(raw) // 512) * 512, b"\x00"))
    return path
