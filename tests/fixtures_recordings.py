"""Small synthetic tracker recordings for the recording/resample/calibration tests.

Everything is generated at test time (a few seconds of data); nothing here
reads /work/shared.  Ground truth is analytic so tests can compare resampled
values against it.
"""
from __future__ import annotations

import os
import struct

import numpy as np

from blender_manikin.core.io_csv import write_csv
from blender_manikin.core.recording import Recording, TrackerStream, from_blender
from blender_manikin.core.rotations import axis_angle_to_quat

#: per-device sample rates used by default (Hz)
RATES = {"head": 90.0, "left_hand": 72.0, "right_hand": 120.0}


def jittered_times(rate, duration, jitter=0.15, seed=0, start=0.0):
    """``(N,)`` strictly increasing timestamps at ``rate`` Hz with uniform jitter (fraction of a period)."""
    rng = np.random.default_rng(seed)
    n = int(np.floor(duration * rate)) + 1
    dt = 1.0 / rate
    t = start + np.arange(n) * dt + rng.uniform(-jitter, jitter, n) * dt
    t[0] = start
    return t


def truth(device, t):
    """Analytic pose of ``device`` at times ``t``: ``(pos (N,3) m, quat (N,4) wxyz)``, Blender axes."""
    t = np.asarray(t, dtype=np.float64)
    if device == "head":
        pos = np.stack([0.05 * np.sin(1.3 * t), 0.04 * np.sin(0.7 * t), 1.62 + 0.02 * np.sin(2.1 * t)], -1)
        aa = np.stack([0.1 * np.sin(1.7 * t), 0.05 * np.cos(0.6 * t), 0.4 * np.sin(0.9 * t)], -1)
    elif device in ("left_hand", "right_hand"):
        s = 1.0 if device == "left_hand" else -1.0
        ph = 0.0 if s > 0 else 1.0
        pos = np.stack([s * (0.35 + 0.15 * np.sin(1.1 * t + ph)), -0.3 + 0.1 * np.cos(0.8 * t),
                        1.2 + 0.2 * np.sin(1.5 * t + ph)], -1)
        aa = np.stack([0.6 * np.sin(1.2 * t + ph), 0.4 * np.cos(0.9 * t), s * 0.5 * np.sin(1.4 * t)], -1)
    elif device == "pelvis":
        pos = np.stack([0.02 * np.sin(0.5 * t), 0.0 * t, 0.95 + 0.01 * np.sin(3.0 * t)], -1)
        aa = np.stack([0.0 * t, 0.0 * t, 0.2 * np.sin(0.5 * t)], -1)
    else:
        s = 1.0 if device == "left_foot" else -1.0
        pos = np.stack([s * 0.1 + 0.0 * t, -0.05 + 0.0 * t, 0.08 + 0.03 * np.sin(2.0 * t) ** 2], -1)
        aa = np.stack([0.2 * np.sin(2.0 * t), 0.0 * t, 0.0 * t], -1)
    return pos, axis_angle_to_quat(aa)


def make_streams(duration=3.0, rates=None, jitter=0.15, seed=0, starts=None):
    """Device → :class:`TrackerStream` with jittered per-device timestamps and analytic poses."""
    rates = RATES if rates is None else rates
    starts = starts or {}
    streams = {}
    for k, (dev, rate) in enumerate(rates.items()):
        start = starts.get(dev, 0.0)
        t = jittered_times(rate, duration - start, jitter=jitter, seed=seed + k, start=start)
        p, q = truth(dev, t)
        streams[dev] = TrackerStream(dev, t, p, q)
    return streams


def _interval(s, ta, tb):
    return (s.time >= ta) & (s.time < tb)


def make_recording(duration=3.0, rates=None, jitter=0.15, seed=0, starts=None, gap=None, flip=None,
                   invalid=None, nan=None, frozen=None, source="synthetic") -> Recording:
    """A synthetic :class:`Recording` (Blender axes, metres) with optional defects.

    Each defect is ``(device, t_start, t_end)`` (seconds):
    gap: rows removed; flip: quaternions negated; invalid: valid=0 (poses
    replaced by zeros, as a runtime would); nan: positions and quaternions
    NaN; frozen: the pose of the first sample in the interval repeated.
    """
    streams = make_streams(duration, rates, jitter, seed, starts)
    if flip:
        d, a, b = flip
        s = streams[d]
        m = _interval(s, a, b)
        s.quat[m] *= -1.0
    if invalid:
        d, a, b = invalid
        s = streams[d]
        m = _interval(s, a, b)
        s.valid[m] = False
        s.pos[m] = 0.0
    if nan:
        d, a, b = nan
        s = streams[d]
        m = _interval(s, a, b)
        s.pos[m] = np.nan
        s.quat[m] = np.nan
    if frozen:
        d, a, b = frozen
        s = streams[d]
        idx = np.nonzero(_interval(s, a, b))[0]
        s.pos[idx] = s.pos[idx[0]]
        s.quat[idx] = s.quat[idx[0]]
    if gap:
        d, a, b = gap
        streams[d] = streams[d].select(~_interval(streams[d], a, b))
    return Recording(streams=streams, source=source, metadata={"source": source})


def write_recording_csv(directory, name="rec.csv", axes="openxr", units="m", metadata=None, **kwargs):
    """Write :func:`make_recording` (kwargs) to ``directory/name``; returns ``(path, recording)``."""
    rec = make_recording(**kwargs)
    path = os.path.join(os.fspath(directory), name)
    write_csv(path, rec, axes=axes, units=units, metadata=metadata)
    return path, rec


# --------------------------------------------------------------------------
# BSOR
def _bsor_string(s):
    b = s.encode("utf-8")
    return struct.pack("<i", len(b)) + b


def bsor_bytes(times, head, left, right, info=None, frame_fps=90, extra_tail=b"\x02\x00\x00\x00\x00"):
    """Bytes of a minimal BSOR replay.

    times: ``(N,)`` song times; head/left/right: ``(N, 7)`` Unity
    ``px, py, pz, qx, qy, qz, qw``.  info: header overrides.
    """
    fields = dict(version="0.7.1", gameVersion="1.29.1_test", timestamp="1700000000", playerID="0",
                  playerName="x", platform="steam", trackingSystem="OpenVR", hmd="Test HMD",
                  controller="Test Controller", hash="00", songName="Test Song", mapper="m",
                  difficulty="Easy", score=1234, mode="Standard", environment="Default", modifiers="",
                  jumpDistance=10.0, leftHanded=False, height=1.75, startTime=0.0, failTime=0.0, speed=0.0)
    fields.update(info or {})
    out = bytearray(struct.pack("<iBB", 0x442D3D69, 1, 0))
    for k in ("version", "gameVersion", "timestamp", "playerID", "playerName", "platform", "trackingSystem",
              "hmd", "controller", "hash", "songName", "mapper", "difficulty"):
        out += _bsor_string(str(fields[k]))
    out += struct.pack("<i", int(fields["score"]))
    for k in ("mode", "environment", "modifiers"):
        out += _bsor_string(str(fields[k]))
    out += struct.pack("<fBffff", fields["jumpDistance"], int(bool(fields["leftHanded"])), fields["height"],
                       fields["startTime"], fields["failTime"], fields["speed"])
    n = len(times)
    out += struct.pack("<Bi", 1, n)
    frames = np.zeros(n, dtype=np.dtype([("time", "<f4"), ("fps", "<i4"), ("pose", "<f4", (3, 7))]))
    frames["time"] = times
    frames["fps"] = frame_fps
    frames["pose"][:, 0] = head
    frames["pose"][:, 1] = left
    frames["pose"][:, 2] = right
    out += frames.tobytes()
    out += extra_tail
    return bytes(out)


def unity_pose(device, t):
    """Analytic pose in Unity axes as ``(N, 7)`` px, py, pz, qx, qy, qz, qw (from :func:`truth`)."""
    p, q = truth(device, t)
    pu, qu = from_blender(p, q, "unity")
    return np.concatenate([pu, qu[:, 1:], qu[:, :1]], -1)


def synthetic_bsor(n=180, rate=90.0, placeholder=True, repeated_zero_times=2, backwards=None, **info):
    """``(bytes, times_written)`` of a BSOR with a placeholder frame 0 and repeated time 0 frames.

    backwards: ``(frame_index, seconds)``: from that frame on, time jumps
    back by ``seconds`` (a rewind).
    """
    t = np.arange(n) / rate
    if repeated_zero_times:
        t[1:1 + repeated_zero_times + 1] = 0.0
        t[1 + repeated_zero_times + 1:] = (np.arange(n - 2 - repeated_zero_times) + 1) / rate
    if backwards:
        i, s = backwards
        t[i:] -= s
    t = t.astype(np.float32).astype(np.float64)
    head, left, right = (unity_pose(d, t) for d in ("head", "left_hand", "right_hand"))
    if placeholder:
        for a in (head, left, right):
            a[0] = [0, 0, 0, -1, -1, -1, -1]
    return bsor_bytes(t, head, left, right, info=info), t


XROR_POSE_AXES = ["x", "y", "z", "i", "j", "k", "1"]


def xror_bytes(t, pose, joints=("HEAD", "HAND_LEFT", "HAND_RIGHT"), app="Some App", axes=None, width=None,
               names=None, software=None):
    """An XROR document (BSON, fpzip-compressed float32 frames), as the xror repository writes it.

    t ``(n,)`` seconds; pose ``(n, D, 7)`` position x, y, z and quaternion x, y, z, w per device
    (Unity axes, metres); joints: the XROR joint name of each device.  axes / width: corrupt the
    device axes list or cut the frame width (for error tests).  Needs pymongo's bson and fpzip
    (requirements-xror.txt).  names: each device's hardware name (default: its joint name).
    software: more ``info.software`` fields (``runtime``, ``api``; an ``app_version`` key sets
    ``app.version``, default "1"), as the xror repository's BSOR conversion fills them."""
    import bson
    import fpzip
    n = len(t)
    rows = np.concatenate([np.asarray(t, np.float64)[:, None], np.asarray(pose).reshape(n, -1)], 1)
    rows = rows.astype(np.float32)
    if width is not None:
        rows = rows[:, :width]
    doc = {"$schema": "https://metaguard.github.io/xror/schema/v1.0.0/schema.json",
           "info": {"hardware": {"devices": [{"name": nm, "type": "x", "joint": j, "axes": axes or XROR_POSE_AXES}
                                             for j, nm in zip(joints, names or joints)]},
                    "software": {"app": {"name": app, "version": (software or {}).get("app_version", "1")},
                                 **{k: v for k, v in (software or {}).items() if k != "app_version"}}},
           "frames": fpzip.compress(np.ascontiguousarray(rows[None, None])), "events": []}
    return bson.encode(doc)


def write_wide_poses(path, times, pos, quat, names, axes="openxr"):
    """Write device poses as a wide CSV (``time`` in seconds, ``<prefix>_pos_{x,y,z}`` metres,
    ``<prefix>_rot_{w,x,y,z}``) in ``axes``.  times ``(T,)``; pos / quat: device → ``(T, 3)`` /
    ``(T, 4)`` wxyz, Blender axes; names: device → the column prefix.  Returns ``path``."""
    from blender_manikin.core.recording import from_blender
    cols, data = ["time"], [np.asarray(times, np.float64)]
    for d, prefix in names.items():
        p, q = from_blender(pos[d], quat[d], axes)
        for k, a in enumerate("xyz"):
            cols.append(f"{prefix}_pos_{a}")
            data.append(p[:, k])
        for k, a in enumerate("wxyz"):
            cols.append(f"{prefix}_rot_{a}")
            data.append(q[:, k])
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for row in np.stack(data, -1):
            f.write(",".join(f"{v:.6f}" for v in row) + "\n")
    return path
