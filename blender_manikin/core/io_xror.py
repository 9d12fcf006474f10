"""XROR (Extended Reality Open Recording, MetaGuard/xror, BSD-3): the format BOXRR-23 ships
its 4.7 million VR recordings in.

Schema this reader relies on (checked on ``../shared/data/vr/xror-beatsaber-sample.xror``):

* the file is one BSON document with ``$schema``, ``info``, ``frames`` and ``events``;
* ``info.hardware.devices``: a list, one entry per tracked device, with ``joint`` (``HEAD``,
  ``HAND_LEFT``, ``HAND_RIGHT``; also read: ``WAIST``/``HIPS``, ``FOOT_LEFT``, ``FOOT_RIGHT``),
  ``name``, ``type`` and ``axes``, the per-frame numbers of the device:
  ``["x", "y", "z", "i", "j", "k", "1"]`` = position then quaternion x, y, z, w;
* ``frames``: bytes, an fpzip-compressed float32 array of shape ``(1, 1, N, 1 + 7 D)``: per
  frame the time in seconds, then each device's ``axes`` numbers in ``info.hardware.devices``
  order.  A device whose joint is not one of those above (an elbow or chest tracker, eye gaze)
  or whose axes are not a pose is left out with a warning, its numbers skipped;
* Unity axes (left-handed, +Y up, +Z forward) and metres, by the format's convention;
* ``info.software.app.name`` names the application (``Beat Saber``: the hand poses are saber
  poses, so the preset of the game's default saber offsets for its version
  (``info.software.app.version``), runtime and controllers applies, as for ``.bsor``
  (:func:`.io_bsor.beat_saber_offsets`: ``beat_saber`` for Valve controllers on game 1.29.1 and
  before, ``beat_saber_touch``, ``beat_saber_xr`` ...); any other app: the
  format's default, ``openxr_generic``: the HEAD device is the headset's pose between the eyes,
  as XR runtimes report it, and the hands are taken as controller grip poses, or, when every
  hand device's ``type`` says ``HAND`` (tracked hands, no controller), as OpenXR hand-tracking
  wrist joints, ``openxr_hand_tracking``;
  :mod:`.formats`);
* as in BSOR, frame 0 is all zeros and the first frames may share time 0, and a Beat Saber
  session's frame times are song times: with a speed modifier in
  ``info.software.activity.modifiers`` (SS, FS, SF) or a practice speed (``activity.speed``)
  they are divided by the song's speed, as for ``.bsor`` (:func:`.io_bsor.song_speed`).

``events`` (note cuts and the like) are not read.  Needs the ``bson`` codec of ``pymongo`` and
the ``fpzip`` package (``pip install 'blender-manikin[xror]'``).
"""
from __future__ import annotations

import os
import time

import numpy as np

from .io_bsor import (
    beat_saber_offsets, game_version_warning, pose_frame_masks, pose_frames_to_streams, song_speed,
)
from .plain import shown
from .recording import Recording, RecordingError, canonical_axes, canonical_units, read_check, read_file_bytes

#: XROR joint names -> devices
JOINTS = {"HEAD": "head", "HAND_LEFT": "left_hand", "HAND_RIGHT": "right_hand", "WAIST": "pelvis",
          "HIPS": "pelvis", "PELVIS": "pelvis", "FOOT_LEFT": "left_foot", "FOOT_RIGHT": "right_foot"}
POSE_AXES = ["x", "y", "z", "i", "j", "k", "1"]
#: apps whose hand poses are not the controllers' (device offsets the reader asks for)
APP_OFFSETS = {"beat saber": "beat_saber"}
#: the decompressed frames may be at most this many times the file's size (fpzip compresses
#: float motion 2-4x; a larger claim is a corrupt or hostile file)
MAX_EXPANSION = 64


# np.save goes through a BytesIO: saving straight to a pipe uses ndarray.tofile, which needs a
# file position a pipe does not have in some interpreters ("obtaining file position failed",
# seen in an isolated Blender interpreter)
_DECOMPRESS = ("import io, sys, fpzip, numpy as np\n"
               "a = fpzip.decompress(sys.stdin.buffer.read())\n"
               "b = io.BytesIO()\n"
               "np.save(b, np.ascontiguousarray(a, dtype=np.float32), allow_pickle=False)\n"
               "sys.stdout.buffer.write(b.getvalue())\n")


def _tracked_hand(device) -> bool:
    """Whether an XROR device entry is a hand tracked without a controller: its ``type`` says
    ``HAND`` (not ``CONTROLLER``), e.g. ``"HAND"`` or ``"HAND_TRACKING"``."""
    kind = str(device.get("type", "")).upper()
    return "HAND" in kind and "CONTROLLER" not in kind


#: seconds between two cancel checks (:func:`.recording.read_check`) while the fpzip decoder runs
DECODER_POLL_S = 0.1


def decompress_isolated(blob: bytes, path, limit: int):
    """fpzip-decompress ``blob`` in a child Python process and return the float32 array.

    fpzip's decoder is C code that crashes the whole process (segmentation fault) on corrupt
    input (found by the fuzz tests: about one in five streams with a few flipped bytes), which
    would take Blender down with it.  So the decoding runs in a child process, with its memory
    capped near ``limit`` bytes where the platform allows; a crash or an oversized claim there
    becomes a :class:`RecordingError` here."""
    import io
    import subprocess
    import sys
    import tempfile
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))

    def cap():                           # POSIX: no more memory than the frames can need
        try:
            import resource
            soft = int(limit) + 1024 * 2**20
            resource.setrlimit(resource.RLIMIT_AS, (soft, soft))
        except (ImportError, ValueError, OSError):
            pass

    # the frames go to the decoder from a temporary file, so that waiting for it can be cut in short
    # waits with a cancel check between them (communicate's input is not sent on past a timeout)
    with tempfile.TemporaryFile() as source:
        source.write(blob)
        source.seek(0)
        try:
            p = subprocess.Popen([sys.executable, "-c", _DECOMPRESS], stdin=source, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, env=env, preexec_fn=cap if os.name == "posix" else None)
        except OSError as exc:
            raise RecordingError(f"frames: could not run the fpzip decoder ({exc})", path=path) from None
        deadline = time.monotonic() + 300
        try:
            while True:                  # a cancel (read_check) checked every DECODER_POLL_S while it decodes
                try:
                    out, err = p.communicate(timeout=DECODER_POLL_S)
                    break
                except subprocess.TimeoutExpired:
                    if time.monotonic() > deadline:
                        raise RecordingError("frames: could not run the fpzip decoder (it ran for more than "
                                             "300 s)", path=path) from None
                    read_check()
        finally:
            if p.returncode is None:     # stopped (a cancel, the time limit): the decoder ends with the read
                p.kill()
                p.communicate()
    if p.returncode != 0:
        if p.returncode < 0:
            why = f"the decoder crashed with signal {-p.returncode}"
        else:
            why = (err.decode("utf-8", "replace").strip().splitlines() or [f"exit status {p.returncode}"])[-1]
        raise RecordingError(f"frames: fpzip could not decompress them (corrupt data: {why})", path=path)
    try:
        return np.load(io.BytesIO(out), allow_pickle=False)
    except ValueError as exc:
        raise RecordingError(f"frames: the fpzip decoder returned no array ({exc})", path=path) from None


def _codecs(path):
    try:
        import bson
        import fpzip
    except ImportError:
        raise RecordingError("reading .xror needs the bson (pymongo) and fpzip packages: "
                             "pip install 'blender-manikin[xror]' (or pymongo fpzip)", path=path) from None
    return bson, fpzip


def read_xror(path, axes=None, units=None) -> Recording:
    """Read the device motion of an XROR file: a :class:`Recording` (Blender axes, metres) with a
    stream per device of ``info.hardware.devices`` and the app, hardware and user-free session
    fields in ``metadata``.  Raises :class:`RecordingError` naming the file and the problem."""
    path = os.fspath(path)
    data = read_file_bytes(path)
    if not data:
        raise RecordingError("file is empty", path=path, offset=0)
    return parse_xror(data, path=path, axes=axes, units=units)


def parse_xror(data: bytes, path="<bytes>", axes=None, units=None) -> Recording:
    """:func:`read_xror` on bytes already in memory."""
    bson, fpzip = _codecs(path)
    axes = canonical_axes(axes or "unity")
    units = canonical_units(units or "m")
    if len(data) < 5 or int.from_bytes(data[:4], "little") != len(data):
        raise RecordingError(f"not an XROR (BSON) document: it declares {int.from_bytes(data[:4], 'little')} "
                             f"bytes, the file has {len(data)}", path=path, offset=0)
    try:
        doc = bson.decode(data)
    except Exception as exc:                       # bson.errors.InvalidBSON and friends
        raise RecordingError(f"not a valid BSON document ({exc})", path=path, offset=0) from None

    def field(obj, *keys):
        cur = obj
        for k in keys:
            if not isinstance(cur, dict) or k not in cur:
                raise RecordingError(f"missing field {'.'.join(keys)}", path=path)
            cur = cur[k]
        return cur

    devices = field(doc, "info", "hardware", "devices")
    if not isinstance(devices, list) or not devices:
        raise RecordingError("info.hardware.devices lists no device", path=path)
    names, used, columns, skipped = [], [], [], []   # the devices read (name, entry, first column), left out
    width = 1
    for i, d in enumerate(devices):
        if not isinstance(d, dict):
            raise RecordingError(f"info.hardware.devices[{i}] is not an object", path=path)
        joint = str(d.get("joint", ""))
        axes_d = d.get("axes", [])
        if not isinstance(axes_d, (list, tuple)) or not axes_d:
            raise RecordingError(f"info.hardware.devices[{i}] ({joint}): axes {axes_d!r} is not a list of "
                                 "the device's numbers per frame", path=path)
        if joint.upper() not in JOINTS:
            skipped.append(f"devices[{i}] (joint {joint!r}: not one the solve uses)")
        elif list(axes_d) != POSE_AXES:
            skipped.append(f"devices[{i}] ({joint}: axes {list(axes_d)!r}, not {POSE_AXES}, position and "
                           "quaternion x y z w)")
        else:
            names.append(JOINTS[joint.upper()])
            used.append(d)
            columns.append(width)
        width += len(axes_d)
    if not names:
        raise RecordingError("info.hardware.devices has no device the solve can read: "
                             + "; ".join(skipped), path=path)
    if len(set(names)) != len(names):
        raise RecordingError(f"info.hardware.devices names a device twice: {names}", path=path)

    blob = field(doc, "frames")
    if not isinstance(blob, (bytes, bytearray)) or not blob:
        raise RecordingError("frames is not a compressed float array", path=path)
    arr = decompress_isolated(bytes(blob), path, limit=MAX_EXPANSION * max(len(data), 1))
    if arr.nbytes > MAX_EXPANSION * max(len(data), 1) or arr.ndim != 4:
        raise RecordingError(f"frames: an array of shape {arr.shape} is not plausible for this file", path=path)
    with np.errstate(invalid="ignore"):         # a corrupt float (a signalling NaN) is a lost sample
        frames = np.asarray(arr, dtype=np.float64).reshape(-1, arr.shape[-1])
    if frames.shape[1] != width:
        raise RecordingError(f"frames have {frames.shape[1]} numbers each; the {len(devices)} device(s) need "
                             f"{width} (time, then each device's axes)", path=path)
    if frames.shape[0] == 0:
        raise RecordingError("the recording has no frames", path=path)
    t = frames[:, 0]
    pose = np.stack([frames[:, c:c + 7] for c in columns], axis=1)
    warnings = [f"info.hardware.{s} left out" for s in skipped]
    ok, keep = pose_frame_masks(t, pose, warnings, devices=names, time_name="time")
    if not keep.any():
        raise RecordingError("no frame has a valid pose", path=path)
    info = doc.get("info", {}) if isinstance(doc.get("info"), dict) else {}
    software = info.get("software", {}) if isinstance(info.get("software"), dict) else {}
    app = software.get("app", {}) if isinstance(software.get("app"), dict) else {}
    activity = software.get("activity", {}) if isinstance(software.get("activity"), dict) else {}
    offsets = APP_OFFSETS.get(str(app.get("name", "")).strip().lower())
    speed = 1.0
    if offsets == "beat_saber":            # the frame times are song times
        speed = song_speed(activity.get("modifiers", ""), activity.get("speed", 0.0), warnings)
    streams = pose_frames_to_streams(t[keep] / speed, pose[keep], ok[keep], names, axes, units)
    meta = {"format": "xror", "schema": str(doc.get("$schema", "")), "axes": axes, "units": units,
            "app": str(app.get("name", "")), "app_version": str(app.get("version", "")),
            "api": str(software.get("api", "")), "runtime": str(software.get("runtime", "")),
            "hardware": [str(d.get("name", "")) for d in devices],
            "frames_in_file": int(frames.shape[0]), "frames_kept": int(keep.sum())}
    meta["time_scale"] = float(speed)
    if "height" in activity:               # the player's height setting: informative only
        try:
            meta["height"] = float(activity["height"])
        except (TypeError, ValueError):
            warnings.append(f"info.software.activity.height {shown(activity['height'])} is not a number: "
                            "left out")
    hand_devices = [d for d, n in zip(used, names) if n.endswith("_hand")]
    if offsets == "beat_saber":            # where the game holds the saber: version, runtime, controllers
        hands = [str(d.get("name", "")) for d in hand_devices]
        heads = [str(d.get("name", "")) for d, n in zip(used, names) if n == "head"]
        offsets = beat_saber_offsets(" ".join(hands), *heads, meta["runtime"], meta["api"],
                                     game_version=meta["app_version"], runtime=(meta["api"], meta["runtime"]))
        newer = game_version_warning(meta["app_version"])
        if newer:
            warnings.append(newer)
    elif hand_devices and all(_tracked_hand(d) for d in hand_devices):
        offsets = "openxr_hand_tracking"   # hands tracked without controllers: wrist joint poses
    if offsets:
        meta["offsets"] = offsets
    return Recording(streams=streams, source=path, metadata=meta, warnings=warnings)
