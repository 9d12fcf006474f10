"""Reader for BeatLeader Beat Saber replays (``.bsor``).  Never imports bpy.

Only the header and the motion frames are read.  The schema relied on (all
little-endian; checked against a real replay, version 1, game 1.29.1)::

    offset 0   int32   magic 0x442d3d69
               uint8   format version (1; others are read with a warning)
               uint8   block id 0 (info)
    info block, strings are int32 byte length + UTF-8 bytes:
               str version, gameVersion, timestamp, playerID, playerName,
                   platform, trackingSystem, hmd, controller, hash, songName,
                   mapper, difficulty
               int32 score
               str mode, environment, modifiers   (modifiers: comma separated)
               float32 jumpDistance
               uint8 leftHanded (bool)
               float32 height (player height setting, metres)
               float32 startTime, failTime, speed (practice speed, 0 = normal)
    frames block:
               uint8   block id 1
               int32   frame count N
               N × 92 bytes: float32 time (song time, s), int32 fps,
                   then head, left hand, right hand, each 7 × float32
                   px, py, pz, qx, qy, qz, qw
    then blocks read only to reach the saber offsets (each a uint8 block id first):
               2 notes: int32 count, then per note int32 id, float32
                   event time, spawn time, int32 event type (0 good, 1 bad,
                   2 miss, 3 bomb), and for good and bad cuts 72 bytes of
                   cut info
               3 walls: int32 count × 16 bytes;  4 heights: × 8;
               5 pauses: × 12 (int64 duration, float32 time)
               6 saber offsets (newer recorders): float32 × 14: the left
                   saber's handle position (3) and rotation (4, x y z w) in
                   its controller's pose as the game read it, then the
                   right's (BeatLeader's ``ReplayRecorder.TryGetSaberOffsets``)
               7 custom data (not read)

Poses are in Unity axes (left-handed, +Y up, +Z forward), metres; the hand
poses are the game's *saber* poses, the head pose is the HMD (eye centre).
Where the game holds the saber depends on the game's version, the VR runtime
and the controller's maker (:mod:`.device_offsets`), so the reader names the
device offsets in ``metadata["offsets"]``: the replay's own saber offsets when
it records them (an offsets dict, :func:`.device_offsets.beat_saber_replay_offsets`:
they include the player's in-game controller settings), else the preset of the
game's defaults that its header's ``gameVersion``, ``controller`` (and ``hmd``,
``platform``, ``trackingSystem``) text implies (:func:`beat_saber_offsets`).

Left-handed mode (``info["leftHanded"]``) mirrors the map, not the player: the replay's left
hand is still the player's left controller, where it was in the room.  BeatLeader's own web
replayer shows such a replay against the unmirrored map by mirroring the player (the recorded
left hand drawn as the right saber, x negated), and ArcViewer by mirroring the map and drawing
the hands as recorded; both read the recorded hands as the physical ones, and so does this
reader (no swap, no warning; ``metadata["leftHanded"]`` keeps the flag).

Repairs (each reported in :attr:`Recording.warnings`):

* a device sample is invalid when its numbers are not finite, its
  quaternion is not (close to) unit length - e.g. frame 0, a placeholder with
  zero position and a quaternion of -1s - or it is exactly zero; frames with no
  valid device are dropped, other invalid samples are kept with
  ``valid=False``;
* song time must increase strictly: a frame is kept only when its time is
  greater than that of every earlier kept frame (the first of several frames
  sharing a time is kept; after a pause/rewind jump back, frames are dropped
  until the song passes the earlier time);
* with a song-speed modifier (SS 0.85, FS 1.2, SF 1.5) or a practice speed,
  song time runs faster/slower than real time; times are divided by the
  speed factor (assumption: the replay's frame time is song time).

The player ID and name are not copied into the metadata.
"""
from __future__ import annotations

import os
import struct

import numpy as np

from .recording import (
    Recording, RecordingError, TrackerStream, UNITS, canonical_axes, canonical_units,
    increasing_mask, read_file_bytes, time_spikes, to_blender,
)
from .device_offsets import (
    BEAT_SABER_LEGACY, BEAT_SABER_NODE_NAMES, BEAT_SABER_XR_PRESETS, beat_saber_replay_offsets,
)
from .rotations import normalize

MAGIC = 0x442D3D69
#: the devices of a BSOR frame, in the order their poses are stored
FRAME_DEVICES = ("head", "left_hand", "right_hand")
FRAME_BYTES = 92
_INFO_STRINGS_1 = ("version", "gameVersion", "timestamp", "playerID", "playerName", "platform",
                   "trackingSystem", "hmd", "controller", "hash", "songName", "mapper", "difficulty")
_INFO_STRINGS_2 = ("mode", "environment", "modifiers")
_PRIVATE = ("playerID", "playerName")
#: words in a replay's controller or headset names that mean Oculus/Meta Touch controllers (lower case)
TOUCH_WORDS = ("touch", "oculus", "quest", "rift", "meta")
#: words that mean Valve Index controllers, whatever the headset (a Quest streamed to SteamVR
#: with Index controllers is rare, an Index headset with Touch controllers rarer still)
VALVE_WORDS = ("knuckles", "index", "valve")
#: words that mean HTC Vive wands (lower case; "vive_controller" is SteamVR's name for a wand)
HTC_WORDS = ("vive_controller", "vive controller", "wand", "htc")
#: words in a replay's trackingSystem / platform that mean the Oculus runtime (lower case)
OCULUS_RUNTIME_WORDS = ("oculus", "ovr", "quest", "meta")
_SPEED_MODIFIERS = {"SS": 0.85, "FS": 1.2, "SF": 1.5}
_MAX_STRING = 1 << 20

FRAME_DTYPE = np.dtype([("time", "<f4"), ("fps", "<i4"), ("pose", "<f4", (3, 7))])


class _Reader:
    def __init__(self, data, path):
        self.b = data
        self.o = 0
        self.path = path

    def need(self, n, what):
        if self.o + n > len(self.b):
            raise RecordingError(f"file is truncated: {what} needs {n} bytes but only "
                                 f"{len(self.b) - self.o} remain", path=self.path, offset=self.o)

    def unpack(self, fmt, what):
        n = struct.calcsize(fmt)
        self.need(n, what)
        v = struct.unpack_from(fmt, self.b, self.o)
        self.o += n
        return v if len(v) > 1 else v[0]

    def string(self, what):
        start = self.o
        n = self.unpack("<i", f"length of {what}")
        if n < 0 or n > _MAX_STRING:
            raise RecordingError(f"invalid length {n} of string {what}: not a BSOR file or corrupted",
                                 path=self.path, offset=start)
        self.need(n, f"string {what}")
        raw = self.b[self.o:self.o + n]
        self.o += n
        return bytes(raw).decode("utf-8", errors="replace")


def _parse_header(r):
    magic = r.unpack("<i", "magic number")
    if (magic & 0xFFFFFFFF) != MAGIC:
        raise RecordingError(f"not a BSOR replay: magic number 0x{magic & 0xFFFFFFFF:08x}, expected "
                             f"0x{MAGIC:08x}", path=r.path, offset=0)
    version = r.unpack("<B", "format version")
    at = r.o
    block = r.unpack("<B", "info block id")
    if block != 0:
        raise RecordingError(f"expected the info block (id 0), found id {block}", path=r.path, offset=at)
    info = {}
    for k in _INFO_STRINGS_1:
        info[k] = r.string(k)
    info["score"] = r.unpack("<i", "score")
    for k in _INFO_STRINGS_2:
        info[k] = r.string(k)
    info["jumpDistance"] = float(r.unpack("<f", "jumpDistance"))
    info["leftHanded"] = bool(r.unpack("<B", "leftHanded"))
    info["height"] = float(r.unpack("<f", "height"))
    info["startTime"], info["failTime"], info["speed"] = (float(x) for x in r.unpack("<3f", "start/fail time, speed"))
    return version, info


def _last_of_equal_times(t, usable, first):
    """``first`` (``(N,)`` bool, frames kept as each time's first, :func:`.recording.increasing_mask`)
    moved to the last ``usable`` frame of the same time before the next kept one."""
    group = np.cumsum(first) - 1                      # the kept frame each frame follows (-1: none)
    heads = np.nonzero(first)[0]
    if heads.size == 0:
        return first
    same = usable & (group >= 0) & (t == t[heads[np.maximum(group, 0)]])
    idx = np.nonzero(same)[0]
    g = group[idx]
    last = idx[np.append(g[1:] != g[:-1], True)]      # each group's last frame of its head's time
    keep = np.zeros_like(first)
    keep[last] = True
    return keep


def pose_frame_masks(t, pose, warnings, devices=FRAME_DEVICES, time_name="song time"):
    """Which samples of pose frames are usable.

    t: ``(N,)`` seconds; pose: ``(N, D, 7)`` position x, y, z then quaternion x, y, z, w per
    device (Unity's order, as BSOR and XROR store them).  Returns ``(ok (N, D), keep (N,))``:
    ``ok`` marks finite, unit-quaternion, non-zero poses; ``keep`` the frames with any valid pose
    whose time increases (placeholders, pauses, rewinds and repeated times are dropped).  Of
    several frames that share a time the *last* is kept: the game logs frames with song time 0
    while it loads the song (frame times of 250-330 ms, its ``fps`` field 3-4), and the first of
    them holds a pose from up to half a second before the song began.  Keeping it put that
    stale pose one sample (11 ms) before the next, so the real replays began with an 8-11 cm
    jump of head and hands at 10 m/s that no body made (``/work/shared/data/vr``'s two BSOR
    files); the last frame of the run is the one the next time is counted from.  What was
    dropped is appended to ``warnings``."""
    quat = pose[..., 3:7]
    finite = np.all(np.isfinite(pose), -1)
    unit = np.abs(np.linalg.norm(quat, axis=-1) - 1.0) < 0.05
    zero = np.all(pose == 0.0, -1)
    ok = finite & unit & ~zero
    any_ok = ok.any(-1)
    earliest = any_ok & increasing_mask(np.where(any_ok, t, np.nan))
    keep = _last_of_equal_times(t, any_ok, earliest)
    n_placeholder = int((~any_ok).sum())
    if n_placeholder:
        first = np.nonzero(~any_ok)[0][:3]
        warnings.append(f"dropped {n_placeholder} frame(s) with no valid pose (placeholder/lost; "
                        f"frame index {', '.join(str(int(i)) for i in first)}{' ...' if n_placeholder > 3 else ''})")
    tt = np.where(any_ok, t, np.nan)
    spikes = any_ok & time_spikes(tt)
    if spikes.any():
        idx = np.nonzero(spikes)[0]
        warnings.append(f"dropped {idx.size} frame(s) whose {time_name} leapt ahead of the frames on "
                        f"either side (a corrupt timestamp; frame index "
                        f"{', '.join(str(int(i)) for i in idx[:3])}{' ...' if idx.size > 3 else ''})")
    dropped = any_ok & ~keep & ~spikes
    if dropped.any():
        idx = np.nonzero(dropped)[0]
        times = ", ".join(f"{t[i]:.3f}" for i in idx[:5])
        warnings.append(f"dropped {idx.size} frame(s) whose {time_name} did not increase "
                        f"(pause, rewind or repeated time; at t = {times}{' ...' if idx.size > 5 else ''} s)")
    lost = ok[keep] == False  # noqa: E712
    if lost.any():
        for j, dev in enumerate(devices):
            c = int(lost[:, j].sum())
            if c:
                warnings.append(f"{dev}: {c} sample(s) with an invalid pose marked invalid")
    return ok, keep


def parse_game_version(version):
    """``(major, minor, patch)`` of a Beat Saber version string (``"1.34.2_1234567"``), None when
    unreadable."""
    try:
        parts = tuple(int(x) for x in str(version).split("_")[0].split(".")[:3])
    except ValueError:
        return None
    return parts if len(parts) >= 2 else None


#: the last game version whose default saber offsets were checked on a real replay here
PRESET_GAME_VERSION = (1, 29, 1)
#: the first game version on OpenXR (``UnityXRHelper``): the controller pose the game reads is the
#: OpenXR grip pose, and the game holds the saber at other default offsets
OPENXR_GAME_VERSION = (1, 29, 4)


def _says(text, words):
    """Whether ``text`` (any value; None: empty) holds one of ``words`` (lower case)."""
    text = str(text or "").lower()
    return any(w in text for w in words)


def _maker(controller, headset):
    """``"valve"``, ``"oculus"`` or ``"htc"`` from the controller's name, else the headset's (and
    platform's) names, else ``"other"`` (a maker the game has no offsets for: Pico, Windows Mixed
    Reality ...)."""
    for names in ((controller,), headset):
        for maker, words in (("htc", HTC_WORDS), ("valve", VALVE_WORDS), ("oculus", TOUCH_WORDS)):
            if any(_says(n, words) for n in names):
                return maker
    return "other"


def _oculus_runtime(runtime):
    """Whether a game before 1.29.4 ran on the Oculus runtime (its ``OculusVRHelper``) rather than
    SteamVR: the first of the ``runtime`` names that names either decides (none: SteamVR)."""
    for text in runtime:
        if _says(text, ("openvr", "steam")):
            return False
        if _says(text, OCULUS_RUNTIME_WORDS):
            return True
    return False


def beat_saber_offsets(controller="", *headset, game_version=None, runtime=()) -> str:
    """The device-offset preset of a Beat Saber recording's defaults (:mod:`.device_offsets`).

    controller: the controller's name as the recorder wrote it (BSOR ``controller``, e.g.
    ``"OpenVR Controller(Knuckles Right) - Right"``; XROR's controller device names).
    headset: other names (``hmd``, ``platform``, ``trackingSystem``) that decide the maker when
    the controller's name does not.  game_version: the game's version string (None or
    unreadable: taken as 1.29.1 or earlier).  runtime: names of the VR runtime, most telling first
    (BSOR ``trackingSystem``, ``platform``): ``OpenVR``/``steam`` or ``Oculus``/``quest``.
    Returns, for game 1.29.4 and later, ``beat_saber_xr``, ``beat_saber_xr_touch`` or
    ``beat_saber_xr_vive`` (Valve, Oculus, HTC controllers), or ``openxr_generic`` for a maker
    the game has no offsets for (it holds the saber at the grip pose); before 1.29.4,
    ``beat_saber_oculus`` on the Oculus runtime, else (SteamVR) ``beat_saber``,
    ``beat_saber_touch`` or ``beat_saber_vive``, and ``beat_saber`` when the names say nothing
    (the game's offsets for other makers sit on a raw pose this reader has no grip for).
    """
    maker = _maker(controller, headset)
    version = parse_game_version(game_version)
    if version is not None and version >= OPENXR_GAME_VERSION:
        return BEAT_SABER_XR_PRESETS.get(maker, "openxr_generic")
    if maker == "oculus" and _oculus_runtime(runtime):
        return "beat_saber_oculus"
    return {"valve": "beat_saber", "oculus": "beat_saber_touch", "htc": "beat_saber_vive",
            "other": "beat_saber"}[maker]


def beat_saber_node(version, controller="", *headset, runtime=()) -> str:
    """Which controller pose (:data:`.device_offsets.BEAT_SABER_NODES`) a replay's saber offsets
    are measured from: the OpenXR grip pose from game 1.29.4 on, else the runtime's pose of the
    controller (arguments as :func:`beat_saber_offsets`)."""
    preset = beat_saber_offsets(controller, *headset, game_version=version, runtime=runtime)
    return BEAT_SABER_LEGACY[preset][1] if preset in BEAT_SABER_LEGACY else "openxr"


_CUT_BYTES = 72           # a good or bad cut's info in the notes block
_RECORD_BYTES = {3: 16, 4: 8, 5: 12}     # walls, heights, pauses


def read_saber_offsets(r, warnings):
    """The saber offsets of the blocks after the frames (``r`` just past them), or None.

    Returns ``{"left"|"right": (pos (3,), quat (4,) x, y, z, w)}`` (Unity axes, metres), None when
    the file has no saber-offsets block or one the recorder left empty (all zero, identity: it
    found no controller).  A tail that cannot be read, or offsets that are not a rigid pose within
    half a metre of the controller, add a warning and give None: the motion is read all the same.
    The recorder measures the saber's handle transform while the frames hold the saber's own
    transform; the two are taken to be one (not checked on a replay that records offsets)."""
    try:
        while r.o < len(r.b):
            at = r.o
            block = r.unpack("<B", "block id")
            if block == 2:
                n = r.unpack("<i", "note count")
                if n < 0:
                    raise RecordingError(f"negative note count {n}", path=r.path, offset=at + 1)
                for _ in range(n):
                    kind = r.unpack("<iffi", "note")[3]
                    if kind in (0, 1):
                        r.need(_CUT_BYTES, "note cut info")
                        r.o += _CUT_BYTES
            elif block in _RECORD_BYTES:
                n = r.unpack("<i", "record count")
                if n < 0:
                    raise RecordingError(f"negative record count {n}", path=r.path, offset=at + 1)
                r.need(n * _RECORD_BYTES[block], f"block {block}")
                r.o += n * _RECORD_BYTES[block]
            elif block == 6:
                v = np.array(r.unpack("<14f", "saber offsets"), dtype=np.float64)
                sides = {"left": (v[0:3], v[3:7]), "right": (v[7:10], v[10:14])}
                if all(not p.any() and np.allclose(q, [0, 0, 0, 1]) for p, q in sides.values()):
                    return None
                for side, (p, q) in sides.items():
                    if (not np.all(np.isfinite(v)) or abs(np.linalg.norm(q) - 1.0) > 0.01
                            or np.linalg.norm(p) > 0.5):
                        warnings.append(f"saber offsets at byte offset {at} are not a saber held in the hand "
                                        f"({side}: position {np.round(p, 3).tolist()} m, rotation "
                                        f"{np.round(q, 3).tolist()}): the game's default offsets are used")
                        return None
                return {side: (p, q / np.linalg.norm(q)) for side, (p, q) in sides.items()}
            else:
                return None          # custom data (7) or a block this reader does not know
    except RecordingError as exc:
        warnings.append(f"the blocks after the motion frames could not be read ({exc}); the game's default "
                        f"saber offsets are used")
    return None


def game_version_warning(version) -> str | None:
    """A warning when Beat Saber ``version`` is newer than the ones the presets were checked
    against on real replays (1.29.1 and earlier), else None (also for an unreadable one)."""
    parts = parse_game_version(version)
    if parts is None or parts <= PRESET_GAME_VERSION:
        return None
    return (f"Beat Saber {str(version).split('_')[0]}: the replay does not record the player's saber offsets, so "
            f"the game's defaults for {'.'.join(map(str, OPENXR_GAME_VERSION))} and later are used (not checked "
            f"on a real replay here); if the hands look turned, edit the offsets")


#: practice speeds taken as such (the game's practice menu offers 50-200 %); outside, a corrupt field
PRACTICE_SPEED_MIN, PRACTICE_SPEED_MAX = 0.25, 4.0


def song_speed(modifiers, practice=0.0, warnings=None) -> float:
    """How much faster than real time a Beat Saber song ran: the speed modifiers' factors (SS
    0.85, FS 1.2, SF 1.5; ``modifiers`` comma separated or a list) times the practice speed
    (``practice``, 0 or 1: none).  Frame times are song times, so real time is frame time / this.
    A factor other than 1 appends a warning to ``warnings`` when given."""
    if isinstance(modifiers, (list, tuple)):
        mods = [str(m) for m in modifiers]
    else:
        mods = str(modifiers or "").split(",")
    speed = 1.0
    for m in mods:
        speed *= _SPEED_MODIFIERS.get(m.strip().upper(), 1.0)
    try:
        practice = float(practice or 0.0)
    except (TypeError, ValueError):
        practice = 0.0
    if not np.isfinite(practice) or not (0.0 <= practice <= PRACTICE_SPEED_MAX) \
            or 0.0 < practice < PRACTICE_SPEED_MIN:
        if warnings is not None:      # a corrupt header field: a take of one frame, or of hours
            warnings.append(f"practice speed {practice:g} is not one the game plays at "
                            f"({PRACTICE_SPEED_MIN:g}-{PRACTICE_SPEED_MAX:g}): read as 1 (no practice speed)")
        practice = 0.0
    if practice > 0 and abs(practice - 1.0) > 1e-6:
        speed *= practice
    if abs(speed - 1.0) > 1e-9 and warnings is not None:
        warnings.append(f"song speed x{speed:g} (modifiers {','.join(m.strip() for m in mods if m.strip())!r}, "
                        f"practice speed {practice:g}): frame times divided by {speed:g} to get real time")
    return speed


def pose_frames_to_streams(t, pose, ok, devices, axes, units):
    """``{device: TrackerStream}`` (Blender axes, metres) from pose frames ``(N, D, 7)``
    (position, quaternion x, y, z, w) in ``axes`` and ``units``, times ``t`` ``(N,)`` seconds."""
    upos = pose[..., 0:3]
    uquat = np.concatenate([pose[..., 6:7], pose[..., 3:6]], -1)   # xyzw -> wxyz
    pos_b, quat_b = to_blender(upos * UNITS[units], normalize(uquat), axes)
    return {dev: TrackerStream(dev, t.copy(), pos_b[:, j], quat_b[:, j], ok[:, j]) for j, dev in enumerate(devices)}


def read_bsor(path, axes=None, units=None) -> Recording:
    """Read the head and hand motion of a BeatLeader replay.

    path: ``.bsor`` file.  axes/units: override the format's Unity axes and
    metres (only useful for odd files).  Returns a :class:`Recording` (Blender
    axes, metres) with devices ``head``, ``left_hand``, ``right_hand`` and
    header fields in ``metadata`` (``hmd``, ``controller``, ``trackingSystem``,
    ``height``, ``leftHanded``, ``gameVersion``, ``modifiers`` ...).
    Raises :class:`RecordingError` naming the byte offset for wrong magic,
    truncated or corrupted files.
    """
    path = os.fspath(path)
    data = read_file_bytes(path)
    if not data:
        raise RecordingError("file is empty", path=path, offset=0)
    return parse_bsor(data, path=path, axes=axes, units=units)


def parse_bsor(data: bytes, path="<bytes>", axes=None, units=None) -> Recording:
    """:func:`read_bsor` on bytes already in memory."""
    axes = canonical_axes(axes or "unity")
    units = canonical_units(units or "m")
    r = _Reader(memoryview(bytes(data)), path)
    version, info = _parse_header(r)
    warnings = []
    if version != 1:
        warnings.append(f"BSOR format version {version} (reader written for version 1)")

    at = r.o
    block = r.unpack("<B", "frames block id")
    if block != 1:
        raise RecordingError(f"expected the frames block (id 1), found id {block}", path=path, offset=at)
    at = r.o
    n = r.unpack("<i", "frame count")
    if n <= 0:
        raise RecordingError(f"frame count {n}: the replay has no motion frames", path=path, offset=at)
    avail = len(r.b) - r.o
    if n * FRAME_BYTES > avail:
        raise RecordingError(
            f"file is truncated: the frames block declares {n} frames ({n * FRAME_BYTES} bytes from byte "
            f"offset {r.o}) but only {avail} bytes remain ({avail // FRAME_BYTES} whole frames)",
            path=path, offset=r.o + (avail // FRAME_BYTES) * FRAME_BYTES)
    frames = np.frombuffer(r.b, dtype=FRAME_DTYPE, count=n, offset=r.o)
    with np.errstate(invalid="ignore"):         # a corrupt float (a signalling NaN) is checked below
        t = frames["time"].astype(np.float64)
        pose = frames["pose"].astype(np.float64)          # (N, 3 devices, 7)
    fps = frames["fps"].astype(np.int64)
    ok, keep = pose_frame_masks(t, pose, warnings)
    speed = song_speed(info.get("modifiers", ""), info.get("speed", 0.0), warnings)
    streams = pose_frames_to_streams(t[keep] / speed, pose[keep], ok[keep], FRAME_DEVICES, axes, units)

    meta = {k: v for k, v in info.items() if k not in _PRIVATE}
    meta.update(format="bsor", bsor_version=int(version), axes=axes, units=units,
                frames_in_file=int(n), frames_kept=int(keep.sum()), time_scale=float(speed),
                game_fps_median=float(np.median(fps[keep])) if keep.any() else float("nan"))
    r.o += n * FRAME_BYTES
    saber = read_saber_offsets(r, warnings)
    game = info.get("gameVersion", "")
    runtime = (info.get("trackingSystem"), info.get("platform"))
    if saber is not None:
        node = beat_saber_node(game, info.get("controller"), info.get("hmd"), info.get("platform"),
                               runtime=runtime)
        meta["saber_offsets"] = {side: {"pos": [float(v) for v in saber[side][0]],
                                        "rot_xyzw": [float(v) for v in saber[side][1]]} for side in saber}
        meta["offsets"] = beat_saber_replay_offsets(
            saber, node, f"the player's saber offsets the replay records (Beat Saber {str(game).split('_')[0]}, "
                         f"from {BEAT_SABER_NODE_NAMES[node]})")
    else:
        meta["offsets"] = beat_saber_offsets(info.get("controller"), info.get("hmd"), info.get("platform"),
                                             game_version=game, runtime=runtime)
        newer = game_version_warning(game)
        if newer:
            warnings.append(newer)
    return Recording(streams=streams, source=path, metadata=meta, warnings=warnings)
