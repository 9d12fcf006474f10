"""Every file format the add-on reads and writes, registered in one place.

Readers turn a file into a :class:`~.recording.Recording` (Blender axes, metres); writers turn a
solved :class:`~.pose_result.PoseResult` into a file.  The command line's accepted inputs and
``--format`` choices, the panel's texts and the per-format device-offset defaults all come from
here, so adding a format is one registration (see ``docs/FORMATS.md``).  No bpy: the formats
Blender writes (``blend``, ``fbx``, ``glb``) are registered here by name with ``needs_blender`` and
written by the Blender side.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from .recording import Recording, RecordingError, decode_head, missing_file, not_data


@dataclass(frozen=True)
class ReaderFormat:
    """A recording format: ``extensions`` (lower case, with the dot), ``read(path, axes, units)``
    → :class:`Recording` (the CSV and JSON readers also take ``layout`` and ``rate``), an
    optional ``sniff(head_bytes) -> bool`` that recognises the format from the first bytes of a
    file whatever its name, and the device offsets ``auto`` means for
    it (``"none"``: its poses are the joints' poses).  kind: ``"trackers"`` (device poses: read
    into a :class:`Recording`) or ``"keypoints"`` (3D joint positions: ``read`` gives a
    :class:`.io_keypoints.KeypointRecording`; :func:`.solve.solve_recording` solves them by
    HybrIK, see :mod:`.keypoint_solve`)."""
    name: str
    description: str
    extensions: tuple
    read: Callable
    sniff: Optional[Callable] = None
    default_offsets: str = "none"
    kind: str = "trackers"


@dataclass(frozen=True)
class WriterFormat:
    """An output format: ``extension`` (with the dot) and ``write(path, result, source, options)``
    (``options``: the command line's namespace or ``None``), or ``needs_blender`` when Blender
    writes it (the scene, not the result, is saved)."""
    name: str
    description: str
    extension: str
    write: Optional[Callable] = None
    needs_blender: bool = False


READERS: dict = {}
WRITERS: dict = {}
SNIFF_BYTES = 4096


def register_reader(fmt: ReaderFormat) -> ReaderFormat:
    READERS[fmt.name] = fmt
    return fmt


def register_writer(fmt: WriterFormat) -> WriterFormat:
    WRITERS[fmt.name] = fmt
    return fmt


def input_extensions() -> tuple:
    """Every extension a reader claims, each once, e.g. ``(".csv", ".bsor")``."""
    return tuple(dict.fromkeys(e for f in READERS.values() for e in f.extensions))


#: extensions other files share (layout and offsets files, this add-on's JSON output, convert's
#: manifests): a file with one is a recording only when its reader's sniff says so
SHARED_EXTENSIONS = (".json", ".jsonl", ".ndjson")


def is_recording_file(path) -> bool:
    """Whether ``path`` is a recording to solve when a folder or a list is gathered: it has a
    reader's extension, and for :data:`SHARED_EXTENSIONS` its first bytes look like one."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in input_extensions():
        return False
    if ext not in SHARED_EXTENSIONS:
        return True
    try:
        with open(path, "rb") as f:
            head = f.read(SNIFF_BYTES)
    except OSError:
        return False
    return any(ext in fmt.extensions and fmt.sniff is not None and fmt.sniff(head) for fmt in READERS.values())


def describe_inputs() -> str:
    """``".csv (native CSV), .bsor (Beat Saber replay)"``: for help texts and the panel."""
    return ", ".join(f"{'/'.join(f.extensions)} ({f.description})" for f in READERS.values())


def reader_for(path) -> ReaderFormat:
    """The reader of ``path``: by extension, else by the file's first bytes.  Raises
    :class:`RecordingError` naming the file when no reader knows it."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    claim = [fmt for fmt in READERS.values() if ext in fmt.extensions]
    if len(claim) > 1:                  # an extension formats share (.json): the one whose sniff knows the file
        try:
            with open(path, "rb") as f:
                head = f.read(SNIFF_BYTES)
        except OSError:
            head = b""
        return next((fmt for fmt in claim if fmt.sniff is not None and fmt.sniff(head)), claim[0])
    if claim:
        return claim[0]
    try:
        with open(path, "rb") as f:
            head = f.read(SNIFF_BYTES)
    except OSError as exc:
        raise RecordingError(f"cannot read the file ({exc.strerror or exc})", path=path) from None
    for fmt in READERS.values():
        if fmt.sniff is not None and fmt.sniff(head):
            return fmt
    if not_data(head, text=False):
        raise RecordingError(not_data(head, text=False), path=path)
    raise RecordingError(f"unsupported file type {ext or '(none)'!r}: expected {describe_inputs()}", path=path)


def load_recording(path, axes=None, units=None, layout=None, rate=None) -> Recording:
    """Read a tracker recording with the reader of its format (:func:`reader_for`); ``axes`` /
    ``units`` override the file's metadata; ``layout`` (a layout file's path or dict) fixes the
    columns of a wide-layout CSV; ``rate`` (Hz) times a wide-layout CSV whose only time is a
    frame counter.  Returns a :class:`Recording` in Blender axes and metres; raises
    :class:`RecordingError` naming the file, line / byte offset and problem."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise RecordingError(missing_file(path), path=path)
    fmt = reader_for(path)
    if fmt.kind != "trackers":
        raise RecordingError(f"{fmt.description}, not a tracker recording: solve it as keypoints "
                             f"(the panel's Keypoints source, or the command line's solve)", path=path)
    if (layout is not None or rate) and fmt.name not in ("csv", "json"):
        what = "a layout file" if layout is not None else "a sample rate"
        raise RecordingError(f"{what} applies to wide-layout CSV and JSON files, not to {fmt.description}",
                             path=path)
    if layout is not None or rate:
        return fmt.read(path, axes=axes, units=units, layout=layout, rate=rate)
    return fmt.read(path, axes=axes, units=units)


def default_offsets(path) -> str:
    """The device offsets ``auto`` stands for with this file's format (``"none"`` if unknown)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    for fmt in READERS.values():
        if ext in fmt.extensions:
            return fmt.default_offsets
    return "none"


def writer_names() -> tuple:
    return tuple(WRITERS)


# --------------------------------------------------------------------------
# the built-in formats
def _csv_header(path):
    with open(path, "rb") as f:
        text = decode_head(f.read(SNIFF_BYTES))
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return (lines[0].lower() if lines else ""), text


def _read_csv(path, axes=None, units=None, rate=None, layout=None):
    """The native (long) CSV when the header has a ``device`` column, else a wide layout
    (``rate``: samples per second of a wide layout timed by a frame counter only; ``layout``: a
    layout file's path or dict, which makes it a wide layout)."""
    from .io_wide_csv import sniff_delimiter
    if layout is not None:
        from .io_wide_csv import read_wide_csv
        return read_wide_csv(path, axes=axes, units=units, layout=layout, rate=rate)
    header, text = _csv_header(path)
    if "device" not in [c.strip().strip('"') for c in header.split(sniff_delimiter(header))]:
        from .io_wide_csv import looks_wide, read_wide_csv
        if looks_wide(text):
            return read_wide_csv(path, axes=axes, units=units, rate=rate)
    from .io_csv import read_csv
    return read_csv(path, axes=axes, units=units)


def _read_bsor(path, axes=None, units=None):
    from .io_bsor import read_bsor
    return read_bsor(path, axes=axes, units=units)


def _sniff_bsor(head: bytes) -> bool:
    from .io_bsor import MAGIC
    return len(head) >= 4 and int.from_bytes(head[:4], "little") == MAGIC


def _sniff_csv(head: bytes) -> bool:
    text = decode_head(head)
    lines = [ln for ln in text.lower().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if bool(lines) and all(c in lines[0] for c in ("time", "device")):
        return True
    from .io_wide_csv import looks_wide
    return looks_wide(text)


def _read_xror(path, axes=None, units=None):
    from .io_xror import read_xror
    return read_xror(path, axes=axes, units=units)


register_reader(ReaderFormat("csv", "native or wide-layout CSV", (".csv",), _read_csv, _sniff_csv))
register_reader(ReaderFormat("bsor", "Beat Saber replay", (".bsor",), _read_bsor, _sniff_bsor,
                             default_offsets="beat_saber"))
# XROR: the file names its app; the reader sets the offsets metadata (beat_saber for Beat Saber).
# Any other app: its HEAD device is a headset pose, between the eyes, and its hands controller
# poses, so the generic OpenXR preset (view and grip poses), not "none": taking a headset's pose
# for the head joint puts that joint 11.5 cm too high and 8 cm too far forward (the bundled
# example, OpenXR view and grip poses, solved with --offsets none: no T-pose found, and a body
# sized from the head height 1.88 m tall for its 1.75 m performer)
register_reader(ReaderFormat("xror", "XROR / BOXRR-23", (".xror",), _read_xror,
                             default_offsets="openxr_generic"))


def _read_json(path, axes=None, units=None, layout=None, rate=None):
    from .io_json import read_json
    return read_json(path, axes=axes, units=units, layout=layout, rate=rate)


def _sniff_json(head: bytes) -> bool:
    from .io_json import looks_like_recording
    return looks_like_recording(decode_head(head))


# JSON / JSON Lines frames (WebXR, three.js, Unity's JsonUtility): flattened into a wide layout
register_reader(ReaderFormat("json", "JSON / JSON Lines frames", (".json", ".jsonl", ".ndjson"), _read_json,
                             _sniff_json))


def _read_keypoints(path, axes=None, units=None):
    from .io_keypoints import read_keypoints
    return read_keypoints(path, units=units)


# 3D keypoints; keypoint CSVs and FreeMoCap folders are recognised by io_keypoints.is_keypoint_input
register_reader(ReaderFormat("keypoints", "3D keypoints", (".npy", ".npz", ".trc", ".c3d"), _read_keypoints,
                             kind="keypoints"))


def _sniff_keypoint_json(head: bytes) -> bool:
    from .io_keypoints import looks_like_keypoint_json
    return looks_like_keypoint_json(decode_head(head))


# 3D keypoints as JSON (EasyMocap's keypoints3d/ frames, OpenPose's pose_keypoints_3d, MMPose's results,
# MediaPipe landmark lists): told from the JSON readers' shared .json by their first bytes; a folder of
# per-frame files is one input (io_keypoints.keypoint_json_files)
register_reader(ReaderFormat("keypoints_json", "3D keypoints JSON", (".json",), _read_keypoints,
                             _sniff_keypoint_json, kind="keypoints"))


def _read_unity_anim(path, axes=None, units=None):
    from .io_unity_anim import read_unity_anim
    return read_unity_anim(path, axes=axes, units=units)


def _sniff_unity_anim(head: bytes) -> bool:
    from .io_unity_anim import looks_like_anim
    return looks_like_anim(decode_head(head))


# Unity .anim clips (Unity Recorder, GameObjectRecorder): a Main Camera is a headset's view pose,
# a head bone the joint's, so, as for JSON, "none" and the take's T-pose or the head's name decide
# (core/offsets_auto.py: the reader gives the object's name as the head's label)
register_reader(ReaderFormat("unity_anim", "Unity animation clip", (".anim",), _read_unity_anim,
                             _sniff_unity_anim))


def _write_json(path, result, source="", options=None):
    from .export_json import write_json
    return write_json(path, result, source=source)


def _write_bvh(path, result, source="", options=None):
    from .export_bvh import write_bvh
    return write_bvh(path, result, units=getattr(options, "bvh_units", "cm") or "cm")


def _write_npz(path, result, source="", options=None):
    """Arrays for analysis pipelines: positions (T, 22, 3) metres, local rotations (T, 22, 3, 3),
    world orientations as wxyz quaternions (T, 22, 4), swivel (T, 4) radians, contacts (T, 2),
    fps, joint names, parents; Blender axes (+Z up, body faces -Y)."""
    from . import rotations as rot
    from .skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS
    T = result.num_frames
    positions = np.empty((T, NUM_JOINTS, 3), np.float32)
    quats = np.empty((T, NUM_JOINTS, 4), np.float32)
    for f, pos, world in result.fk_chunks():      # no (T, 22, 3, 3) float64 copy of a long take
        positions[f], quats[f] = pos, rot.matrix_to_quat(world)
    from .file_names import written_whole
    with written_whole(path, ".tmp.npz") as tmp:
        np.savez_compressed(tmp, positions=positions,
                            local_rot=result.local_rot.astype(np.float32),
                            rotations=quats,
                            swivel=result.swivel.astype(np.float32),
                            contacts=(result.contacts if result.contacts is not None
                                      else np.zeros((result.num_frames, 2), bool)),
                            fps=np.float64(result.fps), joints=np.array(JOINT_NAMES), parents=PARENTS,
                            source=np.array(str(source)))
    return path


register_writer(WriterFormat("blend", "Blender file with the armature and its action", ".blend", needs_blender=True))
register_writer(WriterFormat("fbx", "FBX of the armature, animation baked", ".fbx", needs_blender=True))
register_writer(WriterFormat("glb", "glTF binary of the armature, animation baked", ".glb", needs_blender=True))
register_writer(WriterFormat("bvh", "BVH motion (the 22-joint skeleton)", ".bvh", _write_bvh))
register_writer(WriterFormat("json", "JSON document (export_json.JSON_SCHEMA)", ".json", _write_json))
register_writer(WriterFormat("npz", "numpy arrays (positions, rotations, swivel, contacts)", ".npz", _write_npz))
