"""Read 3D keypoints (markerless or marker capture) into a :class:`KeypointRecording`.

Inputs:

* a FreeMoCap recording folder: ``output_data/mediapipe_body_3d_xyz.npy`` (frames × 33 × 3,
  millimetres, NaN where a point was lost), with ``mediapipe_{left,right}_hand_3d_xyz.npy``
  (frames × 21 × 3) when present (their knuckles then orient the hands); the folder itself,
  its ``output_data`` folder or the ``.npy`` file may be given; a pre-1.0 (2022) recording
  folder's ``DataArrays/mediaPipeSkel_3d_origin_aligned.npy`` too (:data:`FREEMOCAP_FILES`);
* ``.npy``: ``(T, K, 3)``, ``(T, K, 4)`` (the 4th value a confidence 0-1) or ``(T, 3K)``; an
  array whose first points are a layout's and the rest others (:data:`LEADING_POINTS`:
  FreeMoCap's whole MediaPipe skeleton, 543 or 553 points; 4D-Humans' ``pred_keypoints_3d``, 44,
  and VIBE's ``joints3d``, 49, OpenPose's 25 joints first) is read from those first points;
* ``.npz``: one such array under ``keypoints`` / ``joints3d`` / ``joints`` / ``positions`` /
  ``points`` / ``pose3d`` / ``kp3d`` (or the only 2-3-D array), with optional ``fps``,
  ``time`` (seconds), ``confidence`` ``(T, K)`` and ``layout``;
* CSV: a ``time`` / ``timestamp`` column (seconds, or ms, µs or ns when its steps say so: no
  keypoints are sampled slower than 2 Hz; or only ``frame`` with a rate) and
  ``<point>_x``, ``<point>_y``, ``<point>_z`` columns named after the layout's points (also with
  FreeMoCap's ``body_`` prefix, :func:`.keypoint_layouts.point_key`; empty cells for missing
  points), or other names through a mapping file
  (``{"layout": "coco17", "columns": {"nose": "Nose", ...}}``: layout point → column prefix);
  or a long table, a row per point per frame (``frame``, ``keypoint``, ``x``, ``y``, ``z``:
  FreeMoCap's ``*_by_frame.csv`` and v2's files, :func:`_load_long_csv`);
* ``.trc`` (OpenSim's marker trajectories, as Pose2Sim writes them): its
  markers named as a layout's points (``RHip``, ``LBigToe``, ``Hip`` for the hips' midpoint,
  ``Head`` for the head top: :func:`trc_point`), the layout the one whose points they cover most
  (Pose2Sim's 22 markers of Halpe 26 make ``halpe26`` without the eyes and ears), its other
  points missing; ``Time``, ``DataRate`` and ``Units`` from the file.  Anatomical markers
  (OpenCap's, Vicon Plug-in Gait's) become joint centres (:mod:`.marker_sets`); for Plug-in Gait a
  Vicon subject parameter file (``.mp`` / ``.vsk``, :mod:`.subject_params`) given, or found
  beside the TRC (:func:`.subject_params.find_subject_params`), gives the subject's joint widths
  and stature (``metadata["subject_height"]``, metres).  Markers of one ``Subject:`` prefix only
  (several subjects in one file are refused, naming them);
* JSON (:func:`_load_json_keypoints`): a folder of one file per frame (:func:`keypoint_json_files`:
  EasyMocap's ``keypoints3d/000000.json``, ``[{"id", "keypoints3d": [[x, y, z, c] * 25]}]``;
  OpenPose's ``--3d`` ``*_keypoints.json``, ``people[].pose_keypoints_3d`` flat x, y, z, c), or one
  file of a take (MMPose's results, ``{"meta_info", "instance_info": [{"frame_id", "instances":
  [{"keypoints", "keypoint_scores"}]}]}``, the layout from ``meta_info``'s ``dataset_name``; a
  list of MediaPipe landmark lists ``[[{"x", "y", "z", "visibility"} * 33], ...]``), each person
  by their id (else their place in the frame), the ``c`` / score / visibility the confidence;
* ``.c3d`` (Vicon, Qualisys, OptiTrack / Motive, Cortex marker capture, :mod:`.io_c3d`): its
  ``POINT:LABELS`` markers read as a TRC's (the same step, :func:`_markers_to_points`), units
  from ``POINT:UNITS``, times from ``POINT:RATE`` and the first frame.

Several people in one file (:func:`read_keypoint_people`): a 4-D ``.npy`` / ``.npz``,
``(P, T, K, 3|4)`` or ``(T, P, K, 3|4)`` (the people axis: the option, the ``.npz``'s
``person_axis`` / ``people_first``, else :func:`people_axis`'s rule: the shorter axis when at most
a quarter of the other; too close is refused), or a CSV with a person column
(:data:`PERSON_COLUMNS`, any case) and a time or frame column, each row one person at one time
(a column with a different value on every row numbers the rows: it is not a person column, and
the file is one person's; a person column with one value is one person, read by
:func:`read_keypoints` without choosing them).
Each person is trimmed to the frames from the first to the last where they are seen (half the
points or more), keeps the file's time stamps, and is then read as a one-person file; one seen
in fewer than :data:`MIN_PERSON_FRAMES` frames is left out with a note.

The layout (:mod:`.keypoint_layouts`) is given (``layout=``, ``--layout``), stored in the file,
or told from the point count (17 points: COCO-17 or Human3.6M-17, told apart by their first
points: COCO's nose sits near its ears, Human3.6M's pelvis far from its right ankle) or the
CSV's column names.  Units (m, cm, mm) come from the leg's length (a leg that makes a
performer shorter or taller than :data:`PLAUSIBLE_STATURE` is said: the file's scale may be its
own, as MotionBERT's ``X3D.npy``'s), the up axis from the
shoulders standing above the ankles (the hips where no frame has shoulders: a lower-body marker
set), and the handedness from the face or the feet pointing
forward of the body's left-right axis; a floor tilted in the file (a pitched camera's frame) is
levelled from the planted feet (:func:`_floor_tilt`).  What was decided is said in one line
(``metadata["detected"]``), e.g. ``keypoints: coco17 (17 points, told from the point count and
the nose near the ears); units mm (leg 0.86 m); up +Y, right-handed (nose ahead of the ears);
30 Hz (assumed: set the rate)``.

Returned points are ``(T, K, 3)`` float64, metres, Blender axes (+Z up, right-handed), NaN where
a point is missing or below the confidence threshold.  Points that all share one coordinate (a
2-D pose, as Sports2D's ``.trc`` with Z 0) are refused.  Errors are :class:`.recording.RecordingError`
naming the file and the problem (and the line, for CSV).
"""
from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import threading
import tokenize
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np
from numpy.lib import format as npformat

from . import keypoint_layouts as kl
from . import marker_sets
from . import subject_params as sp
from . import rotations as rot
from . import skeleton as sk
from .plain import shown
from .recording import (RecordingError, UNITS, batches, canonical_units, chunked, decode_head, json_key_line,
                        load_json_file, missing_file, read_check, read_text, row_chunks, time_unit_of_step)

#: points with a confidence below this are treated as missing
MIN_CONFIDENCE = 0.3
#: sample rate assumed for arrays with no time and no rate given (Hz)
DEFAULT_RATE = 30.0
FREEMOCAP_BODY = "mediapipe_body_3d_xyz.npy"
#: CSV columns naming the person a row belongs to (case-insensitive; the first of these found)
PERSON_COLUMNS = ("person", "person_id", "id", "track", "track_id", "subject")
#: a person seen (half the points or more) in fewer frames than this is left out
MIN_PERSON_FRAMES = 5
_NPZ_KEYS = ("keypoints", "joints3d", "joints", "positions", "points", "pose3d", "kp3d", "data")
#: FreeMoCap folders' body files, in the order looked for: v1's ``output_data`` and its pre-1.0
#: (2022) ``DataArrays`` whole skeleton (body, hands and face, of which the body's 33 are read)
FREEMOCAP_FILES = (os.path.join("output_data", FREEMOCAP_BODY), FREEMOCAP_BODY,
                   os.path.join("DataArrays", "mediaPipeSkel_3d_origin_aligned.npy"))
#: arrays whose first points are a layout's, in its order, their other points left out: point
#: count → (layout, whose array it is and what its points are)
LEADING_POINTS = {
    44: ("body25", "4D-Humans / HMR 2.0's pred_keypoints_3d: OpenPose's 25 joints, then 19 extra"),
    49: ("body25", "SPIN / VIBE's joints3d: OpenPose's 25 joints, then 24 extra"),
    137: ("body25", "OpenPose's / EasyMocap's total: 25 joints, then 2 x 21 hands and 70 face points"),
    67: ("body25", "EasyMocap's bodyhand: OpenPose's 25 joints, then the left and right hands' 2 x 21"),
    118: ("body25", "EasyMocap's bodyhandface: OpenPose's 25 joints, then 2 x 21 hands and 51 face points"),
    133: ("coco17", "COCO-WholeBody (MMPose, RTMPose / RTMW3D): COCO's 17 body points, then 6 feet, 68 face "
                    "and 2 x 21 hands"),
    543: ("mediapipe33", "FreeMoCap's whole MediaPipe skeleton: the body's 33, then the hands' 2 x 21 and the "
                         "face's 468"),
    553: ("mediapipe33", "FreeMoCap's whole MediaPipe skeleton: the body's 33, then the hands' 2 x 21 and the "
                         "face's 478"),
}
#: statures (metres) a leg told in metres may imply without a note that the file's scale may not be metric
PLAUSIBLE_STATURE = (1.2, 2.2)


@dataclass
class KeypointRecording:
    """3D keypoints of one performer.

    time: ``(T,)`` float64 seconds, increasing.  points: ``(T, K, 3)`` float64 metres, Blender
    axes (+Z up, right-handed), NaN = missing.  layout: :data:`.keypoint_layouts.LAYOUTS` name.
    metadata: ``units``, ``up``, ``handed``, ``rate`` and ``detected`` (the one-line report).
    orientations: ``{joint: (T, 3, 3)}`` world orientations the source gives besides its points
    (body convention, :class:`.keypoint_layouts.Body22`'s ``end_rot``: the head, wrists and
    ankles; e.g. an armature's bones, :func:`.rig_keypoints.end_orientations`), empty for files.
    """
    time: np.ndarray
    points: np.ndarray
    layout: str
    source: str = ""
    metadata: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    orientations: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.points.shape[0])


# --------------------------------------------------------------------------
# recognising keypoint inputs
def freemocap_body_file(path):
    """The ``mediapipe_body_3d_xyz.npy`` of a FreeMoCap folder at ``path`` (the recording
    folder, its ``output_data`` or the file itself), else a pre-1.0 recording folder's
    ``DataArrays/mediaPipeSkel_3d_origin_aligned.npy`` (:data:`FREEMOCAP_FILES`), else None."""
    p = os.fspath(path)
    if os.path.isfile(p):
        return p if os.path.basename(p) == FREEMOCAP_BODY else None
    for cand in (os.path.join(p, f) for f in FREEMOCAP_FILES):
        if os.path.isfile(cand):
            return cand
    return None


def is_keypoint_input(path) -> bool:
    """True for what :func:`read_keypoints` reads: a FreeMoCap folder, a folder of per-frame keypoint
    JSON, a ``.npy`` / ``.npz`` / ``.trc`` / ``.c3d``, a ``.json`` with a keypoint JSON's keys
    (:func:`keypoint_json_kind`) that the tracker JSON reader's sniff does not claim (as
    :func:`.formats.reader_for` prefers it: a tracker JSON with a ``meta_info`` key stays one), or a CSV whose
    columns are ``<point>_x/_y/_z`` of a keypoint layout (no tracker devices)."""
    p = os.fspath(path)
    if freemocap_body_file(p) or keypoint_json_files(p):
        return True
    ext = os.path.splitext(p)[1].lower()
    if ext in (".npy", ".npz", ".trc", ".c3d"):
        return os.path.isfile(p)
    if ext == ".json":          # a keypoint JSON's keys, and not a tracker JSON (its sniff first, as in reader_for)
        if not os.path.isfile(p) or _json_head_kind(p) is None:
            return False
        from .formats import READERS, SNIFF_BYTES
        try:
            with open(p, "rb") as f:
                return not READERS["json"].sniff(f.read(SNIFF_BYTES))
        except OSError:
            return False
    if ext == ".csv" and os.path.isfile(p):
        try:
            with open(p, "rb") as f:
                header = (decode_head(f.read(4096)).splitlines() or [""])[0]
        except OSError:
            return False
        cols = [c.strip().lower() for c in header.split(",")]
        return _layout_from_columns(cols) is not None or _long_header(cols)
    return False


def one_person_file(path) -> bool:
    """True when the keypoint file (or FreeMoCap folder) at ``path`` surely holds one person, told
    without reading its samples (a large file lists its people in a moment): a ``.npy`` whose
    array is not 4-D (its shape from the header, ``np.load(mmap_mode="r")``), a ``.trc`` / ``.c3d``, a CSV
    whose header row (the first row neither blank nor a ``#`` comment, in the first 64 KiB) has
    no person column (:data:`PERSON_COLUMNS`).  False when it may hold several (a 4-D array, a
    person column, a ``.npz``) or cannot be told (unreadable, missing): read it to know."""
    p = os.fspath(path)
    p = freemocap_body_file(p) or p
    ext = os.path.splitext(p)[1].lower()
    try:
        if ext == ".npy":
            return np.ndim(np.load(p, mmap_mode="r", allow_pickle=False)) != 4
        if ext in (".trc", ".c3d"):             # one subject a file (several are refused)
            return os.path.isfile(p)
        if ext == ".csv":
            with open(p, "rb") as f:
                chunk = f.read(65536)
                whole = not f.read(1)
            lines = decode_head(chunk).splitlines()
            if not whole:
                lines = lines[:-1]                  # the last line may be cut off by the chunk
            for row in csv.reader(lines):
                if row and any(c.strip() for c in row) and not row[0].lstrip().startswith("#"):
                    return not any(c.strip().lower() in PERSON_COLUMNS for c in row)
    except _ARRAY_ERRORS:
        pass
    return False


# --------------------------------------------------------------------------
def read_keypoints(path, layout=None, units=None, up=None, rate=None, mapping=None,
                   handed=None, subject_params=None, person=None, person_axis=None) -> KeypointRecording:
    """Read keypoints from ``path`` (see the module docstring).

    layout: a layout name (overrides the file).  units: ``m``/``cm``/``mm`` (default: told from
    the leg's length).  up: the file's up axis, ``+x``/``-x``/``+y``/``-y``/``+z``/``-z``
    (default: told from the body).  rate: samples per second when the file has no time (default
    :data:`DEFAULT_RATE`, said in the report).  mapping: a mapping file's path or dict for a CSV.
    handed: ``right``/``left`` (default: told from the face or feet).  subject_params: a TRC's
    Vicon subject parameter file (``.mp`` / ``.vsk``), ``"none"`` for none, or None / ``"auto"``
    (default): the one found beside a Plug-in Gait TRC / C3D (:func:`.subject_params.find_subject_params`).
    person: in a file with several people, the one to read (a label or a 0-based index,
    :func:`read_keypoint_people`); None or ``"all"`` reads a one-person file (a CSV whose person
    column holds one person too) and refuses a file with several, naming them.  person_axis: a
    4-D array's people axis (0 or 1; default: the file's ``person_axis`` / ``people_first``, else
    told from the shape, :func:`people_axis`).
    """
    raw = _load_input(path, rate, mapping, subject_params, person_axis, layout)
    if raw["people"] is None:
        pick = _person_key(person)
        if pick not in (None, "all", "0"):
            raise RecordingError(f"person {shown(person)}: the file holds one person (0)", path=raw["src"])
        return _one_person(raw, layout, units, up, handed, subject_params)
    if _person_key(person) in (None, "all") and len(raw["people"]) == 1:
        person = raw["people"][0][0]            # a person column naming one person: theirs
    if _person_key(person) in (None, "all"):
        labels = [lab for lab, _ in raw["people"]]
        raise RecordingError(f"{len(labels)} people in the file ({', '.join(labels)}): choose one "
                             "(--person LABEL or N, the Person field) or read them all with "
                             "read_keypoint_people", path=raw["src"])
    return read_keypoint_people(path, layout, units, up, rate, mapping, handed, subject_params,
                                person=person, person_axis=person_axis, _raw=raw)[0][1]


def read_keypoint_people(path, layout=None, units=None, up=None, rate=None, mapping=None, handed=None,
                         subject_params=None, person="all", person_axis=None, _raw=None) -> list:
    """``[(label, KeypointRecording), ...]``: each person of a keypoint file, in the file's order
    (a 4-D array's index ``"0"``, ``"1"``...; a CSV's person column values, numbers in
    numerical order, names in the order they first appear).  A one-person file gives
    ``[("0", recording)]``, the recording :func:`read_keypoints` gives.

    Each person's recording holds the frames from the first to the last where that person is
    seen (at least half the layout's points, above the confidence threshold), NaN between, with
    the file's time stamps kept (a person who enters at 4 s starts at 4 s), and is read as a
    one-person file (units, up axis and handedness told from that body).  A person seen in fewer
    than :data:`MIN_PERSON_FRAMES` frames is left out, said in the others' reports.
    person: ``"all"`` (default) or one person's label or 0-based index (a label first).
    Other options as :func:`read_keypoints`."""
    raw = _raw or _load_input(path, rate, mapping, subject_params, person_axis, layout)
    src = raw["src"]
    if raw["people"] is None:
        pick = _person_key(person)
        if pick not in (None, "all", "0"):
            raise RecordingError(f"person {shown(person)}: the file holds one person (0)", path=src)
        return [("0", _one_person(raw, layout, units, up, handed, subject_params))]
    people, notes = _people_seen(raw)
    labels = [p[0] for p in people]
    if not people:
        raise RecordingError(f"no person seen in {MIN_PERSON_FRAMES} frames or more "
                             f"({'; '.join(notes)})", path=src)
    pick = _person_key(person)
    if pick not in (None, "all"):
        all_labels = [lab for lab, _ in raw["people"]]
        if pick in all_labels:
            k = all_labels.index(pick)
        elif pick.lstrip("-").isdigit() and 0 <= int(pick) < len(all_labels):
            k = int(pick)
        else:
            raise RecordingError(f"person {shown(person)}: no such person (the file's people: "
                                 f"{', '.join(all_labels)}; a label or an index 0-{len(all_labels) - 1})",
                                 path=src)
        if all_labels[k] not in labels:
            why = next(n for n in notes if n.startswith(f"person {all_labels[k]} "))
            raise RecordingError(why, path=src)
        people = [people[labels.index(all_labels[k])]]
    out = []
    all_labels = [lab for lab, _ in raw["people"]]
    for lab, X, conf, first, sl in people:
        read_check()                          # each person takes a moment: a cancel between them
        said = f"person {lab} of {len(raw['people'])} ({', '.join(lab2 for lab2, _ in raw['people'])}), " \
               f"frames {first + sl.start}-{first + sl.stop - 1}"
        one = dict(raw, X=X[sl], conf=None if conf is None else conf[sl],
                   time=None if raw["time"] is None else raw["time"][sl],
                   frames=raw["frames"][sl], decided=list(raw["decided"]) + [said] + notes,
                   lines=None if raw.get("lines") is None else raw["lines"][all_labels.index(lab)][sl])
        rec = _one_person(one, layout, units, up, handed, subject_params)
        rec.metadata["person"] = lab
        rec.metadata["people"] = labels
        out.append((lab, rec))
    return out


def keypoint_person_labels(path, layout=None, rate=None, mapping=None, subject_params=None,
                           person_axis=None):
    """The labels of the people :func:`read_keypoint_people` would read from ``path`` (those
    seen in :data:`MIN_PERSON_FRAMES` frames or more, in the file's order), or None for a
    one-person file: the file is loaded but no person is read (no units, up axis or
    handedness told), so it is cheaper than reading them.  Options as :func:`read_keypoints`;
    raises as it does for a file it cannot read."""
    raw = _load_input(path, rate, mapping, subject_params, person_axis, layout)
    if raw["people"] is None:
        return None
    return [p[0] for p in _people_seen(raw)[0]]


def _people_seen(raw):
    """``([(label, X, conf, first frame, slice of the frames seen), ...], notes)``: the people of
    ``raw`` (:func:`_load_input`) seen in :data:`MIN_PERSON_FRAMES` frames or more, each with the
    slice from the first to the last frame they are seen; ``notes`` says who was left out."""
    people, notes = [], []
    for lab, (X, conf, first) in raw["people"]:
        seen = _seen_frames(X, conf)
        if seen.sum() < MIN_PERSON_FRAMES:
            notes.append(f"person {lab} left out (seen in {int(seen.sum())} frame(s), fewer than "
                         f"{MIN_PERSON_FRAMES})")
            continue
        idx = np.nonzero(seen)[0]
        people.append((lab, X, conf, first, slice(int(idx[0]), int(idx[-1]) + 1)))
    return people, notes


def _person_key(person):
    """``person`` as a label text (None for None / ``""``, ``"all"`` for all)."""
    if person is None:
        return None
    key = str(person).strip()
    if not key:
        return None
    return "all" if key.lower() == "all" else key


def _seen_frames(X, conf):
    """``(T,)`` bool: frames where at least half of the ``(T, K, 3|4)`` points are finite (and
    at or above :data:`MIN_CONFIDENCE` where a confidence is given); of an array whose first points are
    a layout's (:data:`LEADING_POINTS`), those points only (COCO-WholeBody's hands and face are often
    below the threshold while the body is seen)."""
    lead = LEADING_POINTS.get(X.shape[1])
    if lead is not None:
        n = len(kl.LAYOUTS[lead[0]].points)
        X, conf = X[:, :n], (None if conf is None else np.asarray(conf)[:, :n])
    ok = np.isfinite(X[..., :3]).all(-1)
    c = X[..., 3] if X.shape[-1] == 4 and conf is None else conf
    if c is not None:
        with np.errstate(invalid="ignore"):
            ok &= ~(np.asarray(c, np.float64) < MIN_CONFIDENCE)
    return ok.sum(1) * 2 >= X.shape[1]


#: the last file :func:`_load_input` read inside :func:`reusing_loads` (this process's, one file):
#: ``{"key": (path, size, modification time, options), "raw": its dict}``
_KEPT = {}
_KEPT_LOCK = threading.Lock()
_REUSE = threading.local()


@contextlib.contextmanager
def reusing_loads():
    """Inside this block, a file this process loaded last (inside such a block too), unchanged
    since (same size and modification time) and read with the same options, is not parsed again:
    the batch converter's per-person tasks (``core.convert``) read a group file once per worker,
    not once per person.  One file is kept at most: loading another drops it first
    (:func:`forget_loads` drops it at once).  Outside such a block, reads neither use nor fill it."""
    before = getattr(_REUSE, "on", False)
    _REUSE.on = True
    try:
        yield
    finally:
        _REUSE.on = before


def forget_loads():
    """Drop the file :func:`reusing_loads` keeps (its arrays are freed when nothing else holds them)."""
    with _KEPT_LOCK:
        _KEPT.clear()


def _load_key(path, rate, mapping, subject_params, person_axis, layout):
    """What a kept load must match: the file (absolute path, size, modification time in ns) and
    the options; None (never kept) for a folder, a mapping given as a dict or a missing file."""
    p = os.path.abspath(os.fspath(path))
    if not isinstance(mapping, (str, os.PathLike, type(None))):
        return None
    try:
        st = os.stat(p)
    except OSError:
        return None
    if not os.path.isfile(p):
        return None
    return (p, st.st_size, st.st_mtime_ns, rate, None if mapping is None else os.fspath(mapping),
            None if subject_params is None else str(subject_params), person_axis, layout)


def _load_input(path, rate, mapping, subject_params, person_axis, layout):
    """:func:`_read_input`, or inside :func:`reusing_loads` the file this process read last when it
    is the same (the dict is shared: its readers copy what they change)."""
    key = _load_key(path, rate, mapping, subject_params, person_axis, layout) \
        if getattr(_REUSE, "on", False) else None
    if key is None:
        return _read_input(path, rate, mapping, subject_params, person_axis, layout)
    with _KEPT_LOCK:
        if _KEPT.get("key") == key:
            return _KEPT["raw"]
        _KEPT.clear()                    # the file before is dropped before this one is read
    raw = _read_input(path, rate, mapping, subject_params, person_axis, layout)
    with _KEPT_LOCK:
        _KEPT.update(key=key, raw=raw)
    return raw


def _read_input(path, rate, mapping, subject_params, person_axis, layout):
    """The file read as it stands: a dict of ``X`` (its array), ``time``, ``conf``,
    ``file_layout``, ``hands``, ``src``, ``decided``, ``subject``, ``units``, ``rate`` and
    ``people`` (None for one person, else ``[(label, (X (T, K, 3|4), conf, first frame)), ...]``
    on the file's clock, with ``frames`` (T,) the sample numbers for a rate), ``lines``: the
    text file's line of each frame (``(T,)`` ints; with people ``(P, T)``, 0 where a person has
    no row), None for binary files (.npy, .npz, FreeMoCap, C3D), whose errors name the frame."""
    p = os.fspath(path)
    body_file = freemocap_body_file(p)
    raw = dict(decided=[], subject=None, time=None, conf=None, file_layout=None, hands=None,
               units=None, rate=rate, people=None, frames=None, lines=None)
    npz_axis = None
    json_files = None if body_file else keypoint_json_files(p)
    if body_file:
        raw.update(X=_load_npy(body_file), file_layout="mediapipe33", src=body_file)
        raw["decided"].append("FreeMoCap folder")
        raw["hands"] = {s: _optional_npy(os.path.join(os.path.dirname(body_file), f"mediapipe_{s}_hand_3d_xyz.npy"))
                        for s in ("left", "right")}
    elif json_files is not None or os.path.splitext(p)[1].lower() == ".json":
        raw["src"] = p
        if json_files is None and not os.path.exists(p):
            raise RecordingError(missing_file(p), path=p)
        X, people, frames, file_layout, said = _load_json_keypoints(p, *(json_files or (None, None)))
        raw.update(X=X, frames=frames, file_layout=file_layout)
        raw["decided"].append(said)
        if people is not None:
            raw["people"] = people
            raw["decided"].append(f"{len(people)} people (the file's person ids, else their place in each frame)")
            return raw
    else:
        raw["src"] = p
        if not os.path.exists(p):
            raise RecordingError(missing_file(p), path=p)
        ext = os.path.splitext(p)[1].lower()
        if ext == ".npy":
            raw["X"] = _load_npy(p)
        elif ext == ".npz":
            X, time, conf, file_layout, npz_rate, npz_axis = _load_npz(p)
            raw.update(X=X, time=time, conf=conf, file_layout=file_layout, rate=rate or npz_rate)
        elif ext == ".csv":
            X, time, file_layout, rate, groups, lines = _load_csv(p, mapping, rate)
            raw.update(X=X, time=time, file_layout=file_layout, rate=rate, lines=lines)
            if groups is not None:
                labels, X4, time, frames, lines = groups
                raw.update(people=[(lab, (X4[k], None, 0)) for k, lab in enumerate(labels)], time=time,
                           frames=frames, lines=lines)
                raw["decided"].append(f"{len(labels)} {'person' if len(labels) == 1 else 'people'} "
                                      "(the CSV's person column)")
                return raw
        elif ext in (".trc", ".c3d"):
            load = _load_trc if ext == ".trc" else _load_c3d
            X, time, file_layout, rate, trc_units, rules, subject, lines = load(p, rate, subject_params)
            raw.update(X=X, time=time, file_layout=file_layout, rate=rate, units=trc_units, subject=subject,
                       lines=lines)
            raw["decided"] += [rules] if rules else []
        else:
            raise RecordingError(f"not a keypoint file: expected a FreeMoCap folder, a folder of per-frame JSON "
                                 f"keypoints, .npy, .npz, .csv, .json, .trc or .c3d, got {ext or '(no extension)'!r}",
                                 path=p)
    if np.ndim(raw["X"]) == 4:
        K = raw["X"].shape[2]
        n_points = None
        if layout is not None:
            name = kl.canonical_layout(layout)
            n_points = [len(kl.LAYOUTS[name].points)] + [k for k, (lay, _) in LEADING_POINTS.items() if lay == name]
        axis, how = people_axis(raw["X"].shape, person_axis if person_axis is not None else npz_axis,
                                raw["src"], n_points)
        X4 = np.moveaxis(np.asarray(raw["X"]), axis, 0)
        conf = raw["conf"]
        C4 = None if conf is None or np.ndim(conf) != 3 else np.moveaxis(np.asarray(conf), axis, 0)
        if conf is not None and C4 is None:
            raise RecordingError(f"confidence shape {tuple(np.shape(conf))} does not match the keypoints' "
                                 f"{tuple(raw['X'].shape[:3])}", path=raw["src"])
        raw["decided"].append(f"{X4.shape[0]} people on axis {axis} of {tuple(raw['X'].shape)} ({how}), "
                              f"{K} points")
        raw.update(people=[(str(k), (X4[k], None if C4 is None else C4[k], 0)) for k in range(X4.shape[0])],
                   frames=np.arange(X4.shape[1], dtype=np.float64))
        if raw["time"] is not None and np.size(raw["time"]) != X4.shape[1]:
            raise RecordingError(f"{np.size(raw['time'])} times for {X4.shape[1]} frames", path=raw["src"])
        if raw["time"] is not None:
            raw["time"] = np.asarray(raw["time"], np.float64).reshape(-1)
    return raw


def people_axis(shape, person_axis=None, path="", point_counts=None):
    """``(axis, how)``: which of the first two axes of a 4-D keypoint array ``shape``
    ``(P, T, K, 3|4)`` or ``(T, P, K, 3|4)`` holds the people.

    person_axis: 0 or 1 as set (an option, or the ``.npz``'s ``person_axis``; its
    ``people_first`` true is 0).  Else the rule: the shorter of the two axes, when it is at most
    a quarter of the other's length (a take has far more frames than people); two axes closer
    than that are refused, naming the shape and the option to set.  The third axis must be a
    layout's point count (``point_counts``: the counts allowed, default every layout's) and the
    last 3 or 4."""
    src = path
    if len(shape) != 4 or shape[3] not in (3, 4):
        raise RecordingError(f"a 4-D keypoint array must be (people, frames, points, 3|4) or (frames, people, "
                             f"points, 3|4); found shape {tuple(shape)}", path=src)
    counts = point_counts or sorted({len(lay.points) for lay in kl.array_layouts().values()} | set(LEADING_POINTS))
    if shape[2] not in counts:
        raise RecordingError(f"shape {tuple(shape)}: its third axis ({shape[2]}) is no layout's point count "
                             f"({', '.join(map(str, counts))})", path=src)
    if person_axis is not None:
        key = str(person_axis).strip().lower()
        if key not in ("0", "1"):
            raise RecordingError(f"person axis {shown(person_axis)}: expected 0 (people, frames, ...) or "
                                 "1 (frames, people, ...)", path=src)
        return int(key), "as set"
    a, b = int(shape[0]), int(shape[1])
    if 4 * min(a, b) <= max(a, b):
        return (0 if a < b else 1), "the shorter axis: people"
    raise RecordingError(f"shape {tuple(shape)}: cannot tell the people axis from the frames axis "
                         f"({a} and {b} are too close); set it: --person-axis 0 for (people, frames, points, "
                         f"{shape[3]}) or 1 for (frames, people, points, {shape[3]}), or save person_axis "
                         "in the .npz", path=src)


def _one_person(raw, layout, units, up, handed, subject_params):
    """One person's :class:`KeypointRecording` from :func:`_load_input`'s ``raw`` (or one
    person's part of it)."""
    src, decided, subject = raw["src"], list(raw["decided"]), raw["subject"]
    units_said = "as set" if units else "the file's"          # the option, else the file's header (TRC)
    units = units or raw["units"]
    read_check()                          # between the load and the two steps after it: a cancel there
    X, conf = _shape_points(raw["X"], raw["conf"], src)
    T, K = X.shape[:2]
    if T < 2:
        raise RecordingError(f"{T} frame(s): at least 2 are needed", path=src)

    # layout: option, file, else the point count
    if layout is not None:
        try:
            name = kl.canonical_layout(layout)
        except ValueError as exc:
            raise RecordingError(str(exc), path=src) from None
        how = "as set"
    elif raw["file_layout"] is not None:
        name, how = kl.canonical_layout(raw["file_layout"]), "from the file"
    elif K in LEADING_POINTS:
        name, how = LEADING_POINTS[K][0], "told from the point count"
    else:
        name, how = _layout_from_count(X, src)
    lead = LEADING_POINTS.get(K)
    if lead is not None and lead[0] == name:        # a layout's points first, then others: those read
        n = len(kl.LAYOUTS[name].points)
        X, conf = X[:, :n], (None if conf is None else conf[:, :n])
        how += f"; the first {n} of the file's {K}, {lead[1]}"
        K = n
    if len(kl.LAYOUTS[name].points) != K:
        raise RecordingError(f"layout {name} has {len(kl.LAYOUTS[name].points)} points, the file {K}",
                             path=src)
    decided.insert(0, f"keypoints: {name} ({K} points, {how})")
    if _explicit(subject_params) and subject is None:
        decided.append(f"subject parameters {os.path.basename(os.fspath(subject_params))} not used (only for "
                       "a TRC's Plug-in Gait markers)")
    read_check()
    rec = _finish(X, conf, name, src, decided, raw["hands"], units, up, handed, raw["rate"], raw["time"],
                  frames=raw["frames"], units_said=units_said, lines=raw.get("lines"))
    if subject is not None and subject.height:
        rec.metadata["subject_height"] = subject.height
    return rec


def _explicit(subject_params):
    """Whether ``subject_params`` names a file (not None, ``""``, ``"auto"`` or ``"none"``)."""
    return bool(subject_params) and str(subject_params).strip().lower() not in ("auto", "none")


def keypoints_from_points(time, points, layout, source, units="m", up="+z", how="as given", said=None,
                          orientations=None):
    """A :class:`KeypointRecording` from points already in hand (e.g. empties sampled in a Blender
    scene): ``time`` ``(T,)`` seconds, ``points`` ``(T, K, 3)`` in ``units`` with ``up`` (default
    metres, +Z up), NaN where missing; ``layout`` a layout name whose points they are, in its
    order; ``how`` says where the layout came from in the one-line report (``said``, when given,
    is that report's first item instead: what was read, e.g. an armature's bones).  The handedness
    is still told from the body (a mirrored source is put right), as for files.  orientations:
    ``{joint: (T, 3, 3)}`` (see :class:`KeypointRecording`), given in metres, +Z up, right-handed
    (a source putting them otherwise is refused)."""
    X = np.array(points, dtype=np.float64, copy=True)
    name = kl.canonical_layout(layout)
    if X.ndim != 3 or X.shape[1:] != (len(kl.LAYOUTS[name].points), 3):
        raise RecordingError(f"points of shape {X.shape}: expected (frames, {len(kl.LAYOUTS[name].points)}, 3) "
                             f"for layout {name}", path=source)
    if X.shape[0] < 2:
        raise RecordingError(f"{X.shape[0]} frame(s): at least 2 are needed", path=source)
    decided = [said or f"keypoints: {name} ({X.shape[1]} points, {how})"]
    rec = _finish(X, None, name, source, decided, None, units, up, None, None, np.asarray(time, np.float64))
    if orientations:
        from .skeleton import J
        if str(up).lower() != "+z" or rec.metadata.get("handed") not in (None, "right"):
            raise RecordingError("orientations are taken in Blender's axes only (+Z up, right-handed)",
                                 path=source)
        bad = [j for j, R in orientations.items() if j not in J or np.shape(R) != (X.shape[0], 3, 3)]
        if bad:
            raise RecordingError(f"orientations of {', '.join(map(str, bad))}: expected a (T, 3, 3) rotation "
                                 f"per frame of a body joint", path=source)
        rec.orientations = {j: np.asarray(R, np.float64) for j, R in orientations.items()}
    return rec


def _finish(X, conf, name, src, decided, hands, units, up, handed, rate, time, frames=None, units_said="as set",
            lines=None):
    """The shared end of reading: confidence → missing, hand knuckles, units, up axis,
    handedness, times; returns the :class:`KeypointRecording`.  frames: ``(T,)`` sample numbers
    on the rate's clock when there are no times (a person's frames of a file with several;
    default ``0 .. T-1``).  units_said: where ``units`` came from, for the read's line (``"as
    set"``, ``"the file's"``).  lines: ``(T,)`` the text file's line of each frame (0: none),
    named in a frame's error; None for a binary file (the error names the frame alone)."""
    T = X.shape[0]
    # confidence → missing
    if conf is not None:
        low = np.isfinite(conf) & (conf < MIN_CONFIDENCE)
        X[low] = np.nan
        if low.any():
            decided.append(f"{100.0 * low.mean():.1f}% of points below confidence {MIN_CONFIDENCE:g}")
    X[~np.isfinite(X).all(-1)] = np.nan
    if not np.isfinite(X).any():
        raise RecordingError("no finite keypoint in the file", path=src)
    # one coordinate the same on every point of every frame: a picture's points, not 3-D ones
    span = np.nanmax(X, axis=(0, 1)) - np.nanmin(X, axis=(0, 1))
    if span.max() > 0 and span.min() <= 1e-9 * span.max():
        a = int(np.argmin(span))
        raise RecordingError(f"every point has the same {'XYZ'[a]} ({shown(float(np.nanmin(X[..., a])))}): the "
                             f"points lie in one plane, a 2-D pose (as Sports2D's .trc: the picture's pixels / 1000, "
                             f"Z 0); 3-D keypoints are needed", path=src)

    lay = kl.LAYOUTS[name]
    if hands is not None:
        _hand_knuckles(X, lay, hands)

    # units from the leg: hip to ankle, about 0.75-0.95 m for adults
    leg = _median_dist(X, lay, "left_hip", "left_ankle", "right_hip", "right_ankle")
    if units is not None:
        try:
            u = canonical_units(units)
        except ValueError as exc:
            raise RecordingError(f"units option: {exc}", path=src) from None
        decided.append(f"units {u} ({units_said})")
    else:
        u = None
        for cand in ("m", "cm", "mm"):
            if 0.3 <= leg * UNITS[cand] <= 1.6:
                u = cand
                break
        if u is None:
            raise RecordingError(f"cannot tell the units: the hip-to-ankle distance is {leg:.4g} "
                                 f"(expected about 0.85 m, 85 cm or 850 mm); set the units", path=src)
        # a leg that makes no adult's stature: the file's scale may be its own (MotionBERT's X3D.npy
        # is scaled to the video's picture: a body 2 units tall when standing, smaller when it moves);
        # the leg at its straightest (95th percentile: not a bent knee's or a seated pose's)
        straight = _median_dist(X, lay, "left_hip", "left_ankle", "right_hip", "right_ankle", q=95.0)
        stature = straight * UNITS[u] / (sk.PROPORTIONS["thigh"] + sk.PROPORTIONS["shank"])
        low, high = PLAUSIBLE_STATURE
        odd = "" if low <= stature <= high else (
            f": a performer about {stature:.2f} m tall; if not, the file's scale is not {u} (a lifter's "
            f"own scale, as MotionBERT's X3D.npy has): set the performer's height (--height)")
        decided.append(f"units {u} (leg {leg * UNITS[u]:.2f} m{odd})")
    X *= UNITS[u]

    # up axis and handedness
    M, up_name, up_how = _up_matrix(X, lay, up, src)
    X = X @ M.T
    mirrored, hand_how = _handedness(X, lay, handed, src)
    if mirrored:
        X[..., 0] *= -1.0
    decided.append(f"up {up_name}{up_how}, {'left' if mirrored else 'right'}-handed ({hand_how})")

    # time
    if time is None:
        r = float(rate) if rate else DEFAULT_RATE
        if not (np.isfinite(r) and r > 0):
            raise RecordingError(f"sample rate {shown(rate)} must be a positive number", path=src)
        time = (np.arange(T, dtype=np.float64) if frames is None else np.asarray(frames, np.float64)) / r
        decided.append(f"{r:g} Hz" + ("" if rate else " (assumed: set the rate)"))
    else:
        time = np.asarray(time, np.float64).reshape(-1)
        if time.shape[0] != T:
            raise RecordingError(f"{time.shape[0]} times for {T} frames", path=src)
        time, unit_note = _time_in_seconds(time)
        d = np.diff(time)
        if not np.all(np.isfinite(time)) or np.any(d <= 0):
            k = int(np.nonzero(~np.isfinite(time[1:]) | (d <= 0))[0][0]) + 1
            raise RecordingError(f"time {shown(float(time[k]))} s of frame {k} is not after the previous "
                                 f"frame's {shown(float(time[k - 1]))} s", path=src, line=_line_of(lines, k))
        decided.append(f"{1.0 / np.median(d):.3g} Hz (from the times{unit_note})")
    # a floor tilted in the file (camera coordinates, a capture volume set up off level)
    tilt = _floor_tilt(X, lay, time)
    if tilt is not None:
        R, deg = tilt
        X = X @ R.T
        decided.append(f"floor levelled (tilted {deg:.1f}° in the file, from the planted feet)")
    missing = float(np.mean(~np.isfinite(X[..., 0])))
    if missing > 0:
        decided.append(f"{100.0 * missing:.1f}% of points missing")
    meta = {"units": u, "up": up_name, "handed": "left" if mirrored else "right",
            "detected": "; ".join(decided)}
    return KeypointRecording(time=time, points=X, layout=name, source=src, metadata=meta)


# --------------------------------------------------------------------------
def _line_of(lines, k):
    """The text file's line of frame ``k`` (:func:`_finish`'s ``lines``), or None."""
    if lines is None or not 0 <= k < len(lines) or int(lines[k]) <= 0:
        return None
    return int(lines[k])


def _time_in_seconds(time):
    """``(seconds, note)``: times read in the unit their steps say
    (:func:`.recording.time_unit_of_step`); note says a unit other than seconds (", in ms")."""
    d = np.diff(time[np.isfinite(time)])
    scale, unit = time_unit_of_step(float(np.median(d)) if d.size else 0.0)
    return (time, "") if unit == "s" else (time * scale, f", in {unit}")


def _stand_in(path):
    """Why the file at ``path`` is a stand-in for the data (:func:`.recording.not_data`), or None."""
    from .recording import not_data
    try:
        with open(path, "rb") as f:
            head = f.read(512)
    except OSError:
        return None
    return "file is empty" if not head else not_data(head, text=False)


#: what numpy raises on a damaged .npy / .npz: a header that does not parse (tokenize's error for
#: an unclosed bracket), a damaged archive, an unknown compression
_ARRAY_ERRORS = (OSError, ValueError, EOFError, SyntaxError, tokenize.TokenError, zipfile.BadZipFile, zlib.error,
                 NotImplementedError)


def _npy_fits(f, size, path, member=""):
    """Refuse the ``.npy`` read from ``f`` (``size`` bytes, header included; ``member``: its name in
    an ``.npz``) when its header's shape needs more bytes than follow it: numpy allocates the
    whole array before it reads (a flipped digit in the shape asked for 56 TiB)."""
    start = f.tell()
    version = npformat.read_magic(f)
    read_header = npformat.read_array_header_1_0 if version == (1, 0) else npformat.read_array_header_2_0
    shape, _, dtype = read_header(f)
    need = int(np.prod([int(n) for n in shape], dtype=object)) * dtype.itemsize     # Python ints: no overflow
    left = size - (f.tell() - start)
    if need > left or min(shape, default=0) < 0:
        size_is = "a negative size" if min(shape, default=0) < 0 else f"{need} bytes"
        raise RecordingError(f"{member + ': ' if member else ''}the array header says shape {shown(shape)} of "
                             f"{dtype.str} ({size_is}), but {left} bytes follow the header: a damaged file",
                             path=path, offset=None if member else f.tell() - start)


def _np_load(path):
    """``np.load(path)`` (no pickles) after :func:`_npy_fits` of the file or of each array of an archive."""
    with open(path, "rb") as f:
        archive = f.read(4) in (b"PK\x03\x04", b"PK\x05\x06")        # as np.load tells them
    if archive:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                if info.filename.endswith(".npy"):
                    with zf.open(info) as f:
                        _npy_fits(f, info.file_size, path, member=info.filename[:-4])
    else:
        with open(path, "rb") as f:
            _npy_fits(f, os.fstat(f.fileno()).st_size, path)
    return np.load(path, allow_pickle=False)


def _load_npy(path):
    try:
        return _np_load(path)
    except RecordingError:
        raise
    except _ARRAY_ERRORS as exc:
        raise RecordingError(_stand_in(path) or f"not a readable .npy array ({exc})", path=path) from None


def _optional_npy(path):
    if not os.path.isfile(path):
        return None
    try:
        a = np.asarray(_np_load(path), np.float64)
    except (RecordingError, *_ARRAY_ERRORS):
        return None
    return a if a.ndim == 3 and a.shape[1:] == (21, 3) else None


def _load_npz(path):
    try:
        z = _np_load(path)
        keys = list(z.files)
        arrays = {k: z[k] for k in keys}
    except RecordingError:
        raise
    except _ARRAY_ERRORS as exc:
        raise RecordingError(_stand_in(path) or f"not a readable .npz archive ({exc})", path=path) from None
    key = next((k for k in _NPZ_KEYS if k in arrays), None)
    if key is None:
        cands = [k for k, a in arrays.items() if a.ndim in (2, 3, 4) and a.dtype.kind == "f"]
        if len(cands) != 1:
            raise RecordingError(f"no keypoint array: expected one of {', '.join(_NPZ_KEYS)} "
                                 f"(the archive holds {', '.join(keys) or 'nothing'})", path=path)
        key = cands[0]
    time = arrays.get("time", arrays.get("times"))
    conf = arrays.get("confidence", arrays.get("scores"))
    layout = str(arrays["layout"]) if "layout" in arrays else None
    fps = arrays.get("fps", arrays.get("rate"))
    axis = None                                 # a 4-D array's people axis, where the archive says it
    if "person_axis" in arrays:
        axis = arrays["person_axis"].reshape(-1)[0] if arrays["person_axis"].size == 1 else arrays["person_axis"]
    elif "people_first" in arrays and arrays["people_first"].size == 1:
        axis = 0 if bool(arrays["people_first"].reshape(-1)[0]) else 1
    return arrays[key], time, conf, layout, (float(fps) if fps is not None and np.size(fps) == 1 else None), axis


#: a coordinate this large, in any unit, is a corrupt float (its square overflows float64): missing
_CORRUPT = 1e100


def _shape_points(X, conf, path):
    X = np.asarray(X)
    if X.dtype.kind not in "fiu":
        raise RecordingError(f"keypoints must be numbers, found dtype {X.dtype}", path=path)
    with np.errstate(invalid="ignore"):         # a corrupt float (a signalling NaN) counts as missing
        X = X.astype(np.float64)
    X[~(np.abs(X) < _CORRUPT)] = np.nan         # and so do infinities and absurd magnitudes
    if X.ndim == 2 and X.shape[1] % 3 == 0 and X.shape[1] >= 3 * 17:
        X = X.reshape(X.shape[0], -1, 3)
    if X.ndim != 3 or X.shape[2] not in (3, 4):
        raise RecordingError(f"keypoints must be (frames, points, 3), (frames, points, 4) or "
                             f"(frames, 3 x points); found shape {tuple(X.shape)}", path=path)
    if X.shape[2] == 4:
        conf = X[..., 3] if conf is None else conf
        X = X[..., :3].copy()
    if conf is not None:
        conf = np.asarray(conf, np.float64)
        if conf.shape != X.shape[:2]:
            raise RecordingError(f"confidence shape {tuple(conf.shape)} does not match the keypoints' "
                                 f"{tuple(X.shape[:2])}", path=path)
    return X, conf


def _median_dist(X, lay, *pairs, q=50.0):
    """The median (``q``: another percentile) over frames and ``pairs`` of the distance between
    each pair of points (names of ``lay``), in the file's unit; NaN where none is seen."""
    d = []
    for a, b in zip(pairs[0::2], pairs[1::2]):
        d.append(np.linalg.norm(X[:, lay.index(a)] - X[:, lay.index(b)], axis=-1))
    d = np.concatenate(d)
    d = d[np.isfinite(d)]
    return float(np.percentile(d, q)) if d.size else float("nan")


def _layout_from_count(X, path):
    K = X.shape[1]
    names = kl.layouts_with(K)
    if not names:
        raise RecordingError(f"{K} points per frame match no keypoint layout "
                             f"({', '.join(f'{n}: {len(f.points)}' for n, f in kl.array_layouts().items())}); "
                             f"set the layout", path=path)
    if len(names) == 1:
        return names[0], "told from the point count"
    if set(names) == {"coco17", "h36m17"}:
        # point 0 to points 3 and 6: COCO nose → left ear, right shoulder (0.1, 0.25 m), Human3.6M
        # pelvis → right ankle, left ankle (0.9 m), against the extent of the body (scale-free)
        ext = np.linalg.norm(np.nanmax(X, axis=1) - np.nanmin(X, axis=1), axis=-1)
        ratios = []
        for k in (3, 6):
            q = np.linalg.norm(X[:, 0] - X[:, k], axis=-1) / ext
            q = q[np.isfinite(q)]
            if q.size:
                ratios.append(np.median(q))
        r = float(np.mean(ratios)) if ratios else float("nan")
        if np.isfinite(r) and r < 0.2:
            return "coco17", "told from the point count and the nose near the ears"
        if np.isfinite(r) and r > 0.3:
            return "h36m17", "told from the point count and the pelvis far from the ankle"
    raise RecordingError(f"{K} points per frame fit layouts {', '.join(names)}: set the layout "
                         f"(--layout {'|'.join(names)})", path=path)


def _point_prefixes(cols):
    """``{point name: column prefix}`` of the ``<prefix>_x/_y/_z`` columns in ``cols``, the prefix
    read as a point name by :func:`.keypoint_layouts.point_key` (FreeMoCap's ``body_nose_x``
    is ``nose``); the first column wins."""
    out = {}
    for c in cols:
        if c.endswith(("_x", "_y", "_z")):
            out.setdefault(kl.point_key(c[:-2]), c[:-2])
    return out


def _layout_from_columns(cols):
    """The layout whose points all have ``_x/_y/_z`` columns in ``cols`` (most points wins)."""
    have = _point_prefixes(cols)
    best = None
    for name, lay in kl.array_layouts().items():
        if all(p in have for p in lay.points) and (
                best is None or len(lay.points) > len(kl.LAYOUTS[best].points)):
            best = name
    return best


def _load_csv(path, mapping, rate):
    """``(X (T, K, 3), time (T,) or None, layout, rate, people, lines (T,))`` of a keypoint CSV;
    ``people``: :func:`_csv_people`'s split where a person column names several rows a time
    (then ``X`` and ``lines`` None: the split carries its own), else None; ``lines``: each data
    row's line in the file.  The rows are parsed a chunk at a time (:func:`.recording.batches`:
    a cancel is checked between chunks), so the file's text cells are never held all at once."""
    rows = ((i, r) for i, r in enumerate(csv.reader(_text_lines(read_text(path))), 1)
            if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#"))
    hline, header = next(rows, (None, None))
    if header is None:
        raise RecordingError("file is empty", path=path)
    cols = [c.strip().lower() for c in header]
    if mapping is None and _long_header(cols):
        return _load_long_csv(path, cols, rows, hline, rate)
    if mapping is not None:
        if not isinstance(mapping, dict):
            mapping = load_json_file(os.fspath(mapping))
        try:
            name = kl.canonical_layout(mapping.get("layout", ""))
        except ValueError as exc:
            raise RecordingError(f"mapping: {exc}", path=path) from None
        prefix = {p: str(mapping.get("columns", {}).get(p, p)).strip().lower() for p in kl.LAYOUTS[name].points}
    else:
        name = _layout_from_columns(cols)
        if name is None:
            raise RecordingError("no keypoint layout's columns found: expected <point>_x, <point>_y, <point>_z "
                                 f"for every point of one of {', '.join(kl.LAYOUTS)} (or a mapping file)",
                                 path=path, line=hline)
        have = _point_prefixes(cols)
        prefix = {p: have[p] for p in kl.LAYOUTS[name].points}
    idx = []
    for p in kl.LAYOUTS[name].points:
        for ax in "xyz":
            c = f"{prefix[p]}_{ax}"
            if c not in cols:
                raise RecordingError(f"column {c!r} (point {p} of {name}) is missing", path=path, line=hline)
            idx.append(cols.index(c))
    tcol = next((c for c in ("time", "t", "seconds", "timestamp", "frame") if c in cols), None)
    pcol = next((c for c in PERSON_COLUMNS if c in cols), None)
    Xs, tvs, lines, ids = [], [], [], []
    for part in batches(rows):
        x, t = _csv_numbers(part, cols, idx, tcol, path)
        Xs.append(x)
        tvs.append(t)
        lines.extend(ln for ln, _ in part)
        if pcol is not None:
            ids.extend(r[cols.index(pcol)].strip() for _, r in part)
    if not lines:
        raise RecordingError("no data rows after the header", path=path, line=hline)
    X, tv, lines = np.concatenate(Xs), np.concatenate(tvs), np.array(lines, np.int64)
    del Xs, tvs
    if pcol is not None and len(lines) > 1 and len(set(ids)) == len(lines):
        pcol = None                 # a value on every row: a row number (an "id" column), not a person
    time = None
    if tcol is not None and not np.isfinite(tv).any():
        tcol = None                             # a time column with no time in it: the rate decides
    if pcol is not None:
        read_check()
        return None, None, name, rate, _csv_people(path, ids, lines, pcol, tcol, tv, X), None
    if tcol in ("time", "t", "seconds", "timestamp"):
        time = tv                               # its unit from its steps (_time_in_seconds)
    elif tcol == "frame" and rate:
        time = (tv - tv[0]) / float(rate)
    return X.reshape(len(X), -1, 3), time, name, rate, None, lines


#: the columns of a long keypoint table, a row per point per frame (FreeMoCap's ``*_by_frame.csv``)
LONG_COLUMNS = ("frame", "keypoint", "x", "y", "z")


def _long_header(cols) -> bool:
    """True for the header ``cols`` (lower case) of a long keypoint table (:data:`LONG_COLUMNS`)."""
    return all(c in cols for c in LONG_COLUMNS) and _layout_from_columns(cols) is None


def _load_long_csv(path, cols, rows, hline, rate):
    """As :func:`_load_csv`, of a long table: a row per point per frame, with ``frame``,
    ``keypoint``, ``x``, ``y``, ``z`` columns (FreeMoCap v1's ``<recording>_by_frame.csv``, v2's
    ``freemocap_data_by_frame.csv`` and ``<tracker>_body_3d_xyz.csv``).  A ``model`` column: the
    rows of the body's model (its name's last word ``body``: ``mediapipe_body``, ``rtmpose.body``);
    a ``trajectory`` column: the ``3d_xyz`` rows.  The layout from the points' names
    (:func:`.keypoint_layouts.layout_from_names`), other points left out; the time from a ``time``
    / ``timestamp`` column where it is filled in (FreeMoCap leaves it empty without timestamps),
    else the frame numbers at ``rate``."""
    at = {c: i for i, c in reversed(list(enumerate(cols)))}
    recs = []
    for part in batches(rows):
        for ln, r in part:
            if len(r) != len(cols):
                raise RecordingError(f"expected {len(cols)} comma-separated fields (as in the header), found "
                                     f"{len(r)}", path=path, line=ln)
            recs.append((ln, r))
    if not recs:
        raise RecordingError("no data rows after the header", path=path, line=hline)
    if "model" in at:                           # the body's rows, not the hands', face's or centres of mass'
        models = list(dict.fromkeys(r[at["model"]].strip() for _, r in recs))
        body = [m for m in models if re.split(r"[._\s]", m.lower())[-1] == "body"]
        if not body:
            raise RecordingError(f"column 'model' names {', '.join(map(repr, models))}: none is a body's (a "
                                 "name ending in 'body', as mediapipe_body)", path=path, line=hline)
        recs = [(ln, r) for ln, r in recs if r[at["model"]].strip() == body[0]]
    if "trajectory" in at:
        kinds = list(dict.fromkeys(r[at["trajectory"]].strip() for _, r in recs))
        kind = "3d_xyz" if "3d_xyz" in kinds else kinds[0]
        recs = [(ln, r) for ln, r in recs if r[at["trajectory"]].strip() == kind]
    names = list(dict.fromkeys(r[at["keypoint"]].strip() for _, r in recs))
    found = kl.layout_from_names(names)
    if found is None:
        raise RecordingError(f"the 'keypoint' column's points ({', '.join(names[:8])}"
                             f"{', ...' if len(names) > 8 else ''}) are not every point of one of "
                             f"{', '.join(kl.array_layouts())}", path=path, line=hline)
    name, by_point = found
    index = {by_point[p]: k for k, p in enumerate(kl.LAYOUTS[name].points)}
    tcol = next((c for c in ("time", "timestamp") if c in at), None)

    def number(ln, r, c):
        cell = r[at[c]].strip()
        try:
            return float(cell) if cell else np.nan
        except ValueError:
            raise RecordingError(f"column {c!r}: {cell!r} is not a number", path=path, line=ln) from None
    frame = np.array([number(ln, r, "frame") for ln, r in recs])
    if not np.isfinite(frame).all():
        ln = recs[int(np.argmax(~np.isfinite(frame)))][0]
        raise RecordingError("column 'frame' is empty: every row needs its frame", path=path, line=ln)
    frames, first = np.unique(frame, return_index=True)
    X = np.full((len(frames), len(index), 3), np.nan)
    seen = np.zeros(X.shape[:2], bool)
    for (ln, r), f in zip(recs, np.searchsorted(frames, frame)):
        k = index.get(r[at["keypoint"]].strip())
        if k is None:
            continue
        if seen[f, k]:
            raise RecordingError(f"point {r[at['keypoint']].strip()} has two rows at frame "
                                 f"{shown(float(frames[f]))}", path=path, line=ln)
        seen[f, k] = True
        X[f, k] = [number(ln, r, c) for c in "xyz"]
    lines = np.array([recs[i][0] for i in first], np.int64)
    time = None
    if tcol is not None:
        tv = np.array([number(recs[i][0], recs[i][1], tcol) for i in first])
        time = tv if np.isfinite(tv).all() else None
    if time is None and rate:
        time = (frames - frames[0]) / float(rate)
    return X, time, name, rate, None, lines


def _text_lines(text):
    """The lines of ``text`` with their ends (``\n``, ``\r\n`` or ``\r``), one at a time, for
    ``csv.reader`` (as ``io.StringIO(text, newline="")`` gives them, without its copy of the text)."""
    return (m.group() for m in re.finditer(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+\Z", text))


def _csv_numbers(part, cols, idx, tcol, path):
    """``(X (n, len(idx)), time (n,))`` of ``part``, a chunk of a keypoint CSV's data rows
    ``[(line, cells), ...]``: the point columns ``idx`` and the time column ``tcol`` (NaN
    without one) as numbers, an empty cell or ``nan`` NaN.  Raises naming the line of a row with
    the wrong number of fields, or of a cell that is not a number."""
    for ln, r in part:
        if len(r) != len(cols):
            raise RecordingError(f"expected {len(cols)} comma-separated fields (as in the header), found {len(r)}",
                                 path=path, line=ln)
    take = list(idx) + ([cols.index(tcol)] if tcol is not None else [])
    try:            # the chunk at once, each cell as float() reads it; an empty cell (FreeMoCap's time) NaN
        values = np.array([[r[i] or "nan" for i in take] for _, r in part], np.float64).reshape(len(part), len(take))
    except ValueError:                          # a blank cell (NaN too), or the cell at fault and its line
        values = np.empty((len(part), len(take)))
        for k, (ln, r) in enumerate(part):
            for m, i in enumerate(take):
                cell = r[i].strip()
                try:
                    values[k, m] = float(cell) if cell else np.nan
                except ValueError:
                    raise RecordingError(f"column {cols[i]!r}: {r[i].strip() if m < len(idx) else r[i]!r} "
                                         "is not a number", path=path, line=ln) from None
    return values[:, :len(idx)], (values[:, len(idx)] if tcol is not None else np.full(len(part), np.nan))


def _csv_people(path, ids, lines, pcol, tcol, tv, X):
    """``(labels, X (P, G, K, 3), time (G,) or None, frames (G,), lines (P, G))`` of a keypoint CSV whose
    ``pcol`` column names each row's person (``ids``: each data row's, ``lines`` (N,) its line,
    ``tv`` its time, ``X`` (N, 3K) its points): the people laid on the file's times (or frame
    numbers, from 0 at the file's first), NaN where a person has no row.  Labels: numbers in
    numerical order, else names in the order they first appear."""
    for ln, v in zip(lines, ids):
        if not v:
            raise RecordingError(f"column {pcol!r} is empty: every row needs its person", path=path, line=int(ln))
    if tcol is None:
        raise RecordingError(f"a {pcol!r} column needs a time or frame column to put the people's rows "
                             "together", path=path, line=int(lines[0]))
    if not np.isfinite(tv).all():
        k = int(np.nonzero(~np.isfinite(tv))[0][0])
        raise RecordingError(f"column {tcol!r} is empty: with several people every row needs it",
                             path=path, line=int(lines[k]))
    labels = list(dict.fromkeys(ids))
    try:
        labels.sort(key=float)
    except ValueError:
        pass
    grid = np.unique(tv)
    P, G = len(labels), len(grid)
    X4 = np.full((P, G, X.shape[1] // 3, 3), np.nan)
    col = np.searchsorted(grid, tv)
    number = {lab: n for n, lab in enumerate(labels)}
    row = np.fromiter((number[v] for v in ids), np.int64, len(ids))
    # a person's second row at one time: the first such row in the file is named
    cell = row * G + col
    _, first = np.unique(cell, return_index=True)
    if len(first) < len(cell):
        repeat = np.ones(len(cell), bool)
        repeat[first] = False
        k = int(np.argmax(repeat))
        raise RecordingError(f"person {ids[k]} has two rows at {tcol} {shown(float(tv[k]))}", path=path,
                             line=int(lines[k]))
    X4[row, col] = X.reshape(len(X), -1, 3)
    at = np.zeros((P, G), np.int64)                     # each person's row's line at each time, 0: none
    at[row, col] = lines
    lines = at
    if tcol == "frame":
        return labels, X4, None, grid - grid[0], lines
    return labels, X4, grid, np.arange(G, dtype=np.float64), lines


# --------------------------------------------------------------------------
# JSON keypoints: EasyMocap, OpenPose 3-D, MMPose, MediaPipe landmark dumps
#: keys that mark a keypoint JSON document's frame (:func:`looks_like_keypoint_json`): EasyMocap's
#: ``keypoints3d``, OpenPose's ``pose_keypoints_3d`` (``body_keypoints_3d`` in its older docs)
_JSON_FRAME_KEYS = re.compile(r'"(keypoints3d|pose_keypoints_3d|body_keypoints_3d)"\s*:')
#: keys that mark a whole take's keypoint JSON: MMPose's ``--save-predictions`` results file
_JSON_TAKE_KEYS = re.compile(r'"(instance_info|meta_info)"\s*:')
#: MMPose's ``meta_info`` ``dataset_name`` → the layout of its ``keypoints`` (COCO-WholeBody's
#: 133 points start with COCO's 17: :data:`LEADING_POINTS`)
_MMPOSE_DATASETS = {"h36m": "h36m17", "coco": "coco17", "coco_wholebody": "coco17", "halpe": "halpe26",
                    "halpe26": "halpe26"}
#: the head of a file read to tell a keypoint JSON (bytes)
_JSON_HEAD = 65536


def _landmark_list(head):
    """``"frame"`` when the JSON text ``head`` starts with a MediaPipe landmark list (``[{"x", "y",
    "z", "visibility"}, ...]``), ``"take"`` when it starts with a list of those (frames), else None."""
    t = head.lstrip("\ufeff \t\r\n")
    m = re.match(r"(\[\s*)+\{([^{}]*)\}", t)
    if m is None:
        return None
    keys = set(re.findall(r'"([a-z_]+)"\s*:', m.group(2)))
    if not {"x", "y", "z", "visibility"} <= keys:
        return None
    return "take" if re.match(r"\[\s*\[", t) else "frame"


def keypoint_json_kind(head_text):
    """``"frame"`` when the JSON text ``head_text`` (a file's first bytes) is one frame of 3D keypoints
    (EasyMocap's ``keypoints3d/000000.json``, OpenPose's ``*_keypoints.json`` with
    ``pose_keypoints_3d``, a MediaPipe landmark list), ``"take"`` when it holds a take's frames
    (MMPose's results file, a list of MediaPipe landmark lists), else None."""
    t = head_text.lstrip("\ufeff \t\r\n")
    if t[:1] not in ("[", "{") or "blender_manikin" in t[:2000]:      # not this add-on's own JSON output
        return None
    if _JSON_TAKE_KEYS.search(t):
        return "take"
    if _JSON_FRAME_KEYS.search(t):
        return "frame"
    return _landmark_list(t)


def looks_like_keypoint_json(head_text) -> bool:
    """Whether the JSON text ``head_text`` is 3D keypoints (:func:`keypoint_json_kind`)."""
    return keypoint_json_kind(head_text) is not None


def _json_head_kind(path):
    try:
        with open(path, "rb") as f:
            return keypoint_json_kind(decode_head(f.read(_JSON_HEAD)))
    except OSError:
        return None


def keypoint_json_files(path):
    """``(files, frame numbers)`` of a folder of one keypoint JSON file per frame at ``path``
    (EasyMocap's ``keypoints3d`` folder, or its output folder holding one; OpenPose's
    ``--write_json`` folder): its ``.json`` files, the first of them a frame
    (:func:`keypoint_json_kind`), at least 2, in the order of the last number in their names
    (``000012.json``, ``clip_000000000012_keypoints.json``; the names' order where they have none
    or repeat one), the frame numbers those numbers (else 0, 1, ...).  None for anything else."""
    p = os.fspath(path)
    if not os.path.isdir(p):
        return None
    for d in (p, os.path.join(p, "keypoints3d")):
        if not os.path.isdir(d):
            continue
        names = sorted(n for n in os.listdir(d) if n.lower().endswith(".json") and not n.startswith(".")
                       and os.path.isfile(os.path.join(d, n)))
        if len(names) < 2 or _json_head_kind(os.path.join(d, names[0])) != "frame":
            continue
        nums = [re.findall(r"\d+", os.path.splitext(n)[0]) for n in names]
        if all(nums) and len({int(n[-1]) for n in nums}) == len(names):
            order = sorted(range(len(names)), key=lambda k: int(nums[k][-1]))
            frames = np.array([int(nums[k][-1]) for k in order], np.float64)
        else:
            order, frames = range(len(names)), np.arange(len(names), dtype=np.float64)
        return [os.path.join(d, names[k]) for k in order], frames
    return None


def frames_folder_of(path):
    """The folder whose per-frame JSON files (:func:`keypoint_json_files`) include ``path``, a
    file of one frame (EasyMocap's ``keypoints3d/000000.json``, OpenPose's ``*_keypoints.json``);
    None for anything else.  The panel reads that folder when one frame's file is picked in the
    file browser (the command line refuses the file, naming its folder)."""
    p = os.path.abspath(os.fspath(path))
    if not (os.path.isfile(p) and p.lower().endswith(".json") and _json_head_kind(p) == "frame"):
        return None
    folder = os.path.dirname(p)
    found = keypoint_json_files(folder)
    if found is None or os.path.dirname(found[0][0]) != folder:
        return None
    return folder if any(os.path.samefile(f, p) for f in found[0]) else None


def json_frames_folder(path):
    """The folder holding the per-frame files of :func:`keypoint_json_files` ``(path)``: ``path``
    itself, or its ``keypoints3d`` sub-folder when ``path`` is an output folder holding one (whose
    other recordings, a tracker take beside it, are inputs of their own); None for anything else."""
    found = keypoint_json_files(path)
    return None if found is None else os.path.dirname(found[0][0])


def _json_points(value, key_path, text, path, what):
    """``(K, 4)`` float64 (x, y, z, confidence; confidence NaN where not given) of a JSON value:
    ``[[x, y, z(, c)], ...]`` or a flat ``[x, y, z, c, ...]`` (OpenPose's, 4 a point); raises naming
    the file, the line and the problem."""
    def bad(problem):
        return RecordingError(f"{what}: {problem}", path=path, line=json_key_line(text, key_path))
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise bad("expected numbers ([x, y, z] or [x, y, z, confidence] a point)") from None
    if a.ndim == 3 and a.shape[0] == 1:          # MMPose: (1, K, 3) for one instance
        a = a[0]
    if a.ndim == 1:
        if a.size % 4:
            raise bad(f"{a.size} numbers: expected x, y, z, confidence for each point (4 a point)")
        a = a.reshape(-1, 4)
    if a.ndim == 2 and a.shape[1] == 2 and len(a) >= 17:
        raise bad(f"shape {tuple(a.shape)}: [x, y] a point, a 2-D pose (a picture's); 3-D keypoints are needed")
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise bad(f"shape {tuple(a.shape)}: expected [x, y, z] or [x, y, z, confidence] for each point")
    if a.shape[1] == 3:
        a = np.concatenate([a, np.full((len(a), 1), np.nan)], 1)
    return a


def _json_frame_people(doc, text, path, base=()):
    """``[(label or None, (K, 4)), ...]``: the people of one frame's JSON value ``doc`` at the key path
    ``base`` of ``text``: EasyMocap's ``[{"id", "keypoints3d"}, ...]``, OpenPose's ``{"people":
    [{"pose_keypoints_3d": [x, y, z, c, ...], "person_id"}, ...]}``, a MediaPipe landmark list
    ``[{"x", "y", "z", "visibility"}, ...]`` (one person, the visibility its confidence)."""
    out = []
    if isinstance(doc, dict) and isinstance(doc.get("people"), list):
        for n, person in enumerate(doc["people"]):
            key = next((k for k in ("pose_keypoints_3d", "body_keypoints_3d") if isinstance(person, dict)
                        and k in person), None)
            if key is None:
                raise RecordingError(f"people[{n}]: no pose_keypoints_3d (an OpenPose file written with --3d "
                                     "has them)", path=path, line=json_key_line(text, base + ("people", n)))
            if not person[key]:
                continue                            # OpenPose without --3d, or not reconstructed
            pid = person.get("person_id")
            pid = pid[0] if isinstance(pid, list) and len(pid) == 1 else pid
            label = str(pid) if isinstance(pid, int) and pid >= 0 else None
            out.append((label, _json_points(person[key], base + ("people", n, key), text, path,
                                            f"people[{n}].{key}")))
        return out
    if isinstance(doc, list) and doc and all(isinstance(d, dict) and {"x", "y", "z"} <= set(d) for d in doc):
        try:
            a = np.array([[d["x"], d["y"], d["z"], d.get("visibility", np.nan)] for d in doc], np.float64)
        except (TypeError, ValueError):
            raise RecordingError("a landmark's x, y, z or visibility is not a number", path=path,
                                 line=json_key_line(text, base)) from None
        return [(None, a)]
    if isinstance(doc, list):
        for n, person in enumerate(doc):
            if not (isinstance(person, dict) and "keypoints3d" in person):
                raise RecordingError(f"[{n}]: expected a person's {{\"id\", \"keypoints3d\"}} (EasyMocap) or a "
                                     "landmark's {\"x\", \"y\", \"z\", \"visibility\"} (MediaPipe)", path=path,
                                     line=json_key_line(text, base + (n,)))
            pid = person.get("id")
            out.append((None if pid is None else str(pid),
                        _json_points(person["keypoints3d"], base + (n, "keypoints3d"), text, path,
                                     f"[{n}].keypoints3d (person {shown(pid)})")))
        return out
    raise RecordingError("not a keypoint frame: expected EasyMocap's [{\"id\", \"keypoints3d\"}], OpenPose's "
                         "{\"people\": [{\"pose_keypoints_3d\"}]} or a MediaPipe landmark list", path=path,
                         line=json_key_line(text, base) if base else 1)


def _mmpose_frames(frames, text, path, base):
    """``[(frame_id or None, [(label, (K, 4)), ...]), ...]`` of MMPose's ``instance_info``: each
    frame's ``instances``, their ``keypoints`` ``[[x, y, z], ...]`` and ``keypoint_scores`` (the
    confidence), a person labelled by its ``track_id`` where it has one."""
    out = []
    for f, frame in enumerate(chunked(frames)):
        if not (isinstance(frame, dict) and isinstance(frame.get("instances"), list)):
            raise RecordingError(f"frame {f}: expected {{\"frame_id\", \"instances\": [...]}} (MMPose's "
                                 "instance_info)", path=path, line=json_key_line(text, base + (f,)))
        people = []
        for n, inst in enumerate(frame["instances"]):
            at = base + (f, "instances", n)
            if not (isinstance(inst, dict) and "keypoints" in inst):
                raise RecordingError(f"frame {f}, instance {n}: no keypoints", path=path, line=json_key_line(text, at))
            a = _json_points(inst["keypoints"], at + ("keypoints",), text, path, f"frame {f}, instance {n}: keypoints")
            if "keypoint_scores" in inst:
                s = np.array(inst["keypoint_scores"], np.float64).reshape(-1)
                if s.size != len(a):
                    raise RecordingError(f"frame {f}, instance {n}: {s.size} keypoint_scores for {len(a)} "
                                         "keypoints", path=path, line=json_key_line(text, at + ("keypoint_scores",)))
                a[:, 3] = s
            tid = inst.get("track_id")
            people.append((None if tid is None else str(tid), a))
        fid = frame.get("frame_id")
        out.append((fid if isinstance(fid, (int, float)) and not isinstance(fid, bool) else None, people))
    return out


def _load_json_keypoints(path, files=None, frames=None):
    """``(X, people, frames (T,), file_layout, said)`` of a keypoint JSON file (a take: MMPose's
    results, a list of MediaPipe landmark lists; or one frame) or of ``files``, a folder's
    per-frame JSON files (:func:`keypoint_json_files`) with their frame numbers ``frames``.
    ``X`` ``(T, K, 4)`` for one person (people None), else people ``[(label, ((T, K, 4), None, 0)),
    ...]`` (X None); x, y, z as written, the 4th value the confidence (NaN where not given);
    frames numbered from the first (0)."""
    file_layout, said = None, "JSON keypoints"
    if files is None:
        text = read_text(path)
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise RecordingError(f"not valid JSON ({exc.msg})", path=path, line=exc.lineno) from None
        take = None
        if isinstance(doc, dict) and "instance_info" in doc:
            meta = doc.get("meta_info") if isinstance(doc.get("meta_info"), dict) else {}
            file_layout = _MMPOSE_DATASETS.get(str(meta.get("dataset_name", "")).strip().lower())
            said = "MMPose results" + (f" ({meta['dataset_name']})" if meta.get("dataset_name") else "")
            if not isinstance(doc["instance_info"], list):
                raise RecordingError("instance_info: expected a list of frames", path=path,
                                     line=json_key_line(text, ("instance_info",)))
            take = _mmpose_frames(doc["instance_info"], text, path, ("instance_info",))
        elif isinstance(doc, list) and doc and all(isinstance(f, dict) and "instances" in f for f in doc):
            said, take = "MMPose results", _mmpose_frames(doc, text, path, ())
        elif isinstance(doc, list) and doc and all(isinstance(f, list) for f in doc):
            said = "MediaPipe landmark lists" if _landmark_list(text) else "a list of JSON frames"
            take = [(None, _json_frame_people(f, text, path, (n,)) if f else []) for n, f in enumerate(chunked(doc))]
        if take is None:
            _json_frame_people(doc, text, path)     # refuses what is not a frame
            raise RecordingError("1 frame: a file of one frame (EasyMocap's keypoints3d/000000.json, OpenPose's "
                                 f"*_keypoints.json); give its folder ({os.path.dirname(os.path.abspath(path))}), "
                                 "whose files are the frames", path=path)
        ids = [fid for fid, _ in take]
        if all(i is not None for i in ids) and np.all(np.diff(ids) > 0):
            frames = np.asarray(ids, np.float64)
        else:
            frames = np.arange(len(take), dtype=np.float64)
    else:
        take = []
        for f in chunked(files, 64):               # a cancel checked every 64 files
            text = read_text(f)
            try:
                doc = json.loads(text)
            except json.JSONDecodeError as exc:
                raise RecordingError(f"not valid JSON ({exc.msg})", path=f, line=exc.lineno) from None
            take.append((f, _json_frame_people(doc, text, f)))
        kind = "EasyMocap" if os.path.basename(os.path.dirname(files[0])) == "keypoints3d" else "per-frame"
        said = f"{len(files)} {kind} JSON files"
    # the people, by label (a person with none: their place in the frame)
    labels, K, first_at = [], None, None
    for fr, (src, people) in enumerate(take):
        for n, (lab, a) in enumerate(people):
            lab = str(n) if lab is None else lab
            if lab not in labels:
                labels.append(lab)
            if K is None:
                K, first_at = len(a), (src if files is not None else path, fr)
            elif len(a) != K:
                where = src if files is not None else path
                raise RecordingError(f"frame {fr}: person {lab} has {len(a)} points, frame {first_at[1]} "
                                     f"{K}" + (f" ({os.path.basename(first_at[0])})" if files is not None else ""),
                                     path=where)
    if not labels:
        raise RecordingError(f"no person with 3D keypoints in any of its {len(take)} frame(s)",
                             path=os.path.dirname(files[0]) if files is not None else path)
    try:
        labels.sort(key=float)
    except ValueError:
        pass
    X4 = np.full((len(labels), len(take), K, 4), np.nan)
    number = {lab: k for k, lab in enumerate(labels)}
    for fr, (_, people) in enumerate(take):
        for n, (lab, a) in enumerate(people):
            X4[number[str(n) if lab is None else lab], fr] = a
    frames = np.asarray(frames, np.float64) - float(frames[0])
    if len(labels) == 1:
        return X4[0], None, frames, file_layout, said
    return None, [(lab, (X4[k], None, 0)) for k, lab in enumerate(labels)], frames, file_layout, said


#: points a layout chosen from a TRC's markers must have (the limbs' joints)
TRC_NEEDED = tuple(f"{s}_{j}" for s in ("left", "right")
                   for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"))
#: marker names that are not a side's joint, as Pose2Sim and OpenPose-style tools write them
_TRC_NAMES = {"hip": "mid_hip", "midhip": "mid_hip", "head": "head_top", "headtop": "head_top"}


def trc_point(marker) -> str:
    """A TRC marker's name as a layout point's: CamelCase split, a leading ``R`` / ``L`` side
    spelt out (``RBigToe`` → ``right_big_toe``), then :func:`.keypoint_layouts.point_key`;
    ``Hip`` is the hips' midpoint and ``Head`` the head top (Halpe's points)."""
    import re
    name = re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", str(marker).strip())
    key = kl.point_key(name)
    key = re.sub(r"^r_", "right_", re.sub(r"^l_", "left_", key))
    return _TRC_NAMES.get(key.replace("_", ""), key)


def _load_trc(path, rate, subject_params=None):
    """``(X (T, K, 3), time (T,) s or None, layout, rate, units, rules, subject, lines (T,))`` of an
    OpenSim ``.trc`` file: its table read here, its markers made a layout's points by
    :func:`_markers_to_points`; ``lines``: each data row's line in the file.  subject_params: as
    :func:`read_keypoints` takes it."""
    lines = read_text(path).splitlines()

    def cells(line):
        return line.split("\t") if "\t" in line else line.split()
    if not lines or not lines[0].startswith("PathFileType"):
        raise RecordingError("not a TRC file: its first line does not start with 'PathFileType'", path=path,
                             line=1)
    if len(lines) < 5:
        raise RecordingError("the TRC header is cut short (5 lines expected before the data)", path=path)
    keys, vals = [c.strip() for c in cells(lines[1])], [c.strip() for c in cells(lines[2])]
    header = dict(zip(keys, vals))
    names = [c.strip() for c in cells(lines[3])[2:] if c.strip()]
    if not names:
        raise RecordingError("no marker names on the TRC's fourth line", path=path, line=4)
    units = {"m": "m", "cm": "cm", "mm": "mm"}.get(header.get("Units", "").strip().lower())
    try:
        file_rate = float(header.get("DataRate", "nan"))
    except ValueError:
        raise RecordingError(f"DataRate {shown(header.get('DataRate'))} is not a number", path=path, line=3) from None
    _marker_layout(names, path, "TRC", dict(line=4))      # names refused before the table is read
    width = 2 + 3 * len(names)
    rows, lines_no = [], []
    for i, line in enumerate(chunked(lines[5:]), start=6):
        if line.strip():              # missing trailing cells (markers lost) and empty ones are NaN
            c = [v.strip() or "nan" for v in cells(line)][:width]
            rows.append(c + ["nan"] * (width - len(c)))
            lines_no.append(i)
    if not rows:
        raise RecordingError("no data rows after the TRC header", path=path)
    try:
        data = np.concatenate([np.array(rows[part], dtype=np.float64).reshape(-1, width)    # a chunk at a time
                               for part in row_chunks(len(rows))])
    except ValueError:
        for row, i in zip(rows, lines_no):              # the first cell that is not a number, and its line
            for v in row:
                try:
                    float(v)
                except ValueError:
                    raise RecordingError(f"{shown(v)} is not a number", path=path, line=i) from None
        raise
    M = data[:, 2:].reshape(len(rows), len(names), 3)
    time, rate = _trc_time(data, rate, file_rate)
    return (*_markers_to_points(path, names, M, units, rate, time, subject_params, "TRC", dict(line=4)),
            np.array(lines_no, np.int64))


def _load_c3d(path, rate, subject_params=None):
    """As :func:`_load_trc`, of a C3D file (:func:`.io_c3d.read_c3d`): its frames' times from
    ``POINT:RATE`` (the take's first frame at ``(first - 1) / rate`` s), or ``rate`` when given;
    ``lines`` None (a binary file: errors name the frame)."""
    from . import io_c3d
    c = io_c3d.read_c3d(path)
    where = dict(offset=c.labels_offset)
    _marker_layout(c.names, path, "C3D", where)
    time = None if rate else c.time
    return (*_markers_to_points(path, c.names, c.points, c.units, rate or c.rate, time, subject_params, "C3D",
                                where), None)


def _is_body(names) -> bool:
    """Whether marker ``names`` (one subject's) make a body: a whole anatomical marker set, or
    points named for a layout's limbs (:data:`TRC_NEEDED`)."""
    marker_set, set_missing = marker_sets.detect_marker_set(names)
    if marker_set is not None and not set_missing:
        return True
    points = {trc_point(n) for n in names}
    return all(p in points for p in TRC_NEEDED)


def _one_subject(names, M, path, kind, where):
    """``(names, M, note)``: a file's markers narrowed to its one body where they carry several
    ``Subject:`` prefixes (a prop, a second labelled object: left out, ``note`` names them, else
    None); markers of two or more bodies are refused, naming them (one subject a file)."""
    groups = {}
    for k, n in enumerate(names):
        groups.setdefault(marker_sets.marker_subject(n), []).append(k)
    if len([g for g in groups if g]) < 2:
        return names, M, None
    bodies = [g for g in groups if _is_body([names[k] for k in groups[g]])]
    if len(bodies) > 1:
        said = ", ".join(sorted(g or "markers without a prefix" for g in bodies))
        raise RecordingError(f"the {kind}'s markers belong to {len(bodies)} subjects ({said}): one subject a "
                             "file is read; export each subject's markers on their own", path=path, **where)
    if not bodies:
        return names, M, None               # the layout step says what is missing
    keep = groups[bodies[0]]
    others = sorted(g or "markers without a prefix" for g in groups if g != bodies[0])
    note = f"markers of {bodies[0] or 'no prefix'} read; {', '.join(others)} left out (not a body)"
    return [names[k] for k in keep], M[:, keep], note


def _marker_layout(names, path, kind, where):
    """``(layout name, marker set or None)`` for a marker file's ``names`` (:func:`_markers_to_points`),
    or :class:`RecordingError` naming the file (``kind``: ``"TRC"`` / ``"C3D"``) and ``where``
    (``line=`` / ``offset=``): markers of several ``Subject:`` prefixes, too few joints."""
    points = [trc_point(n) for n in names]
    missing = [p for p in TRC_NEEDED if p not in points]
    # anatomical markers (OpenCap's r.ASIS_study ..., Plug-in Gait's LASI ...): their joint centres
    # (also where the file has video keypoints too, as OpenCap's have: the markers place the hips
    # better than a detector's hip points)
    marker_set, set_missing = marker_sets.detect_marker_set(names)
    if marker_set is not None and set_missing and missing:
        raise RecordingError(f"the {kind}'s markers look like {marker_set}'s but lack "
                             f"{', '.join(set_missing)} (found: {', '.join(names)})", path=path, **where)
    if missing and marker_set is None:
        raise RecordingError(f"the {kind}'s markers ({', '.join(names)}) lack {', '.join(missing)}: name them "
                             "as a layout's points (RHip, LKnee, ...) or use OpenCap's or Plug-in Gait's "
                             "anatomical markers (r.ASIS_study, LASI, ...)", path=path, **where)
    if marker_set is not None and set_missing:
        marker_set = None                       # video keypoints with an incomplete marker set: the keypoints
    # the layout whose points the markers cover most; of equals, the one with the fewest points
    video = list(kl.array_layouts())
    best = marker_set or max(video, key=lambda n: (sum(p in points for p in kl.LAYOUTS[n].points),
                                                   -len(kl.LAYOUTS[n].points)))
    return best, marker_set


def _markers_to_points(path, names, M, units, rate, time, subject_params, kind, where):
    """The shared step of marker files (TRC, C3D): ``(X (T, K, 3), time, layout, rate, units,
    rules, subject)`` from the file's marker ``names`` (K0, ``Subject:`` prefixes allowed, one
    subject) and ``M`` ``(T, K0, 3)`` in the file's ``units`` (``"m"`` / ``"cm"`` / ``"mm"``, or
    None: told from the ASIS markers' spacing for an anatomical set), NaN where lost; ``time``
    ``(T,)`` s or None, ``rate`` Hz or None.  Markers named as a layout's points
    (:func:`trc_point`) fill that layout; anatomical markers become joint centres
    (:func:`.marker_sets.joint_centres`; ``rules``: how, :func:`.marker_sets.rules_used`, and
    the subject parameter file used, or None; ``subject``: the
    :class:`.subject_params.SubjectParams` used, or None).  subject_params: as
    :func:`read_keypoints` takes it; ``kind`` and ``where`` (``line=`` / ``offset=``) name the
    file's format and the names' place in messages."""
    names, M, left_out = _one_subject(names, M, path, kind, where)
    best, marker_set = _marker_layout(names, path, kind, where)
    lay = kl.LAYOUTS[best]
    X = np.full((len(M), len(lay.points), 3), np.nan)
    if marker_set is not None:
        if units is None:                       # the ASIS markers' distance (about 0.25 m) tells the unit
            k = [marker_sets.marker_key(n) for n in names]
            ends = [k.index(f"{s}_asis" if marker_set == "opencap" else f"{s}asi") for s in "lr"]
            pw = float(np.nanmedian(np.linalg.norm(M[:, ends[0]] - M[:, ends[1]], axis=-1)))
            units = "m" if pw < 1.0 else "cm" if pw < 100.0 else "mm"
        subject, how = None, ""
        if _explicit(subject_params):
            subject, how = sp.read_subject_params(subject_params), "as set"
        elif marker_set == "plugingait" and str(subject_params or "auto").strip().lower() == "auto":
            found = sp.find_subject_params(path, names)
            if found:
                subject, how = sp.read_subject_params(found), f"found beside the {kind}"
        offsets = {} if subject is None else {
            (s, j): subject.offset(s, j) for s in ("left", "right") for j in marker_sets.HALF_WIDTH
            if subject.offset(s, j) is not None}
        _, centres = marker_sets.joint_centres(names, M, UNITS[units], marker_set, offsets=offsets)
        for k, p in enumerate(lay.points):
            X[:, k] = centres[p]
        rules = marker_sets.rules_used(names, marker_set, offsets)
        if subject is not None:
            rules += f"; {subject.summary()} ({how})"
        return X, time, best, rate, units, "; ".join(filter(None, (rules, left_out))), subject
    points = [trc_point(n) for n in names]
    for k, p in enumerate(lay.points):
        if p in points:
            X[:, k] = M[:, points.index(p)]
    return X, time, best, rate, units, left_out, None


def _trc_time(data, rate, file_rate):
    """``(time or None, rate)`` of a TRC's table: its Time column where every row has one, else
    the rate given, else the header's ``DataRate``."""
    time = data[:, 1] if np.isfinite(data[:, 1]).all() else None
    if time is None and not rate and np.isfinite(file_rate) and file_rate > 0:
        rate = file_rate
    return time, rate


def _hand_knuckles(X, lay, hands):
    """Use FreeMoCap's hand points for the hand orientation: index / pinky knuckles (hand points
    5 and 17) replace the pose's, where both are finite."""
    for side, h in hands.items():
        if h is None or h.shape[0] != X.shape[0]:
            continue
        for pose_pt, hand_pt in ((f"{side}_index", 5), (f"{side}_pinky", 17)):
            ok = np.isfinite(h[:, hand_pt]).all(-1)
            X[ok, lay.index(pose_pt)] = h[ok, hand_pt]


_AXIS = {"+x": (0, 1.0), "x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "y": (1, 1.0), "-y": (1, -1.0),
         "+z": (2, 1.0), "z": (2, 1.0), "-z": (2, -1.0)}


def _up_matrix(X, lay, up, path):
    """``(M, name, how)``: the proper rotation (a signed axis permutation) taking the file's up
    axis to +Z, X kept where it can be (so a +Y-up file turns as Blender's importers turn it)."""
    if up is not None:
        key = str(up).strip().lower()
        if key not in _AXIS:
            raise RecordingError(f"up axis {up!r}: expected one of +x, -x, +y, -y, +z, -z", path=path)
        a, s = _AXIS[key]
        how = " (as set)"
    else:
        an = 0.5 * (X[:, lay.index("left_ankle")] + X[:, lay.index("right_ankle")])
        # the shoulders, else the hips (a lower-body marker set, e.g. Plug-in Gait Lower Body)
        for upper in ("shoulder", "hip"):
            top = 0.5 * (X[:, lay.index(f"left_{upper}")] + X[:, lay.index(f"right_{upper}")])
            with np.errstate(invalid="ignore"):
                ok = np.all(np.isfinite(top - an), axis=-1)
            if ok.any():
                break
        else:
            raise RecordingError("cannot tell the up axis (no frame with shoulders or hips, and ankles); set it",
                                 path=path)
        v = np.median(rot.normalize(top[ok] - an[ok]), axis=0)
        a = int(np.argmax(np.abs(v)))
        if abs(v[a]) < 0.7 * np.linalg.norm(v):
            raise RecordingError(f"cannot tell the up axis: the body lies along no axis "
                                 f"({upper}s − ankles ≈ {np.round(v, 2).tolist()}); set it", path=path)
        s = float(np.sign(v[a]))
        how = f" ({upper}s above the ankles)"
    # as Blender's importers turn +Y up into +Z up ((x, y, z) -> (x, -z, y)): X stays where it
    # is (the first axis that is not up), Z is up, Y completes a right-handed frame
    z = np.zeros(3)
    z[a] = s
    x = np.zeros(3)
    x[0 if a != 0 else 1] = 1.0
    y = np.cross(z, x)
    return np.stack([x, y, z]), f"{'+' if s > 0 else '-'}{'xyz'[a].upper()}", how


#: points whose lowest one stands on the floor (those a layout has)
_FOOT_POINTS = ("ankle", "heel", "foot_index", "big_toe", "small_toe", "foot")
#: a lowest foot point slower than this (m/s, horizontally) is planted (as the solve's contacts)
_PLANTED_SPEED = 0.25
#: metres (a standard deviation) the planted feet must spread along a direction for it to tilt
#: the floor fully (a ridge: a direction spread this much counts half, one twice as wide 80 %)
_LEVEL_SPREAD = 0.15
#: degrees: a floor tilted less is left as it is; more than _LEVEL_MAX is not a floor
_LEVEL_MIN, _LEVEL_MAX = 2.0, 45.0


def _floor_tilt(X, lay, time):
    """``(R (3, 3), degrees)`` levelling the floor the planted feet stand on, or None.

    X ``(T, K, 3)`` metres, +Z up as far as the axes go (a camera's or a capture's frame turned
    by a signed axis permutation keeps its tilt).  Per frame the lowest foot point; where it is
    still (planted) it stands on the floor; a plane ``z = a x + b y + c`` is fitted to those
    places (ridge: a direction they span less than :data:`_LEVEL_SPREAD` metres hardly tilts it;
    refitted to the places within 5 cm of it, so a foot resting off the floor does not count)."""
    idx = [lay.index(f"{s}_{n}") for s in ("left", "right") for n in _FOOT_POINTS if f"{s}_{n}" in lay]
    F = X[:, idx]
    z = np.where(np.isfinite(F[..., 2]), F[..., 2], np.inf)
    k = np.argmin(z, axis=1)
    low = F[np.arange(len(F)), k]                                     # (T, 3), NaN where no foot
    t = np.asarray(time, np.float64)
    v = np.full(len(t), np.inf)
    if len(t) > 2:
        v[1:-1] = np.linalg.norm(low[2:, :2] - low[:-2, :2], axis=-1) / (t[2:] - t[:-2])
    ok = np.isfinite(low).all(-1) & (v < _PLANTED_SPEED)
    if ok.sum() < 30:
        return None
    P = low[ok]
    keep = np.ones(len(P), bool)
    for last in (False, False, False, True):
        Q = P[keep]
        m = Q.mean(0)
        A = Q[:, :2] - m[:2]
        ridge = len(Q) * _LEVEL_SPREAD ** 2 if last else 1e-9 * len(Q)
        a = np.linalg.solve(A.T @ A + ridge * np.eye(2), A.T @ (Q[:, 2] - m[2]))
        if not last:                            # a plant off the floor (a foot on a step) left out
            res = P[:, 2] - (m[2] + (P[:, :2] - m[:2]) @ a)
            keep = np.abs(res - np.median(res[keep])) < 0.05
            if keep.sum() < 10:
                return None
    n = rot.normalize(np.array([-a[0], -a[1], 1.0]))
    deg = float(np.degrees(np.arccos(np.clip(n[2], -1.0, 1.0))))
    if not (_LEVEL_MIN <= deg <= _LEVEL_MAX):
        return None
    # people stand square to the floor they stand on: a camera's tilt turns their trunks with the
    # floor, a slope or a staircase walked up in a level frame does not (the trunks stay upright
    # while the plants climb), and is left as it is
    up = _trunk_up(X, lay)
    if up is None or np.dot(up, n) <= up[2]:
        return None
    return rot.rotation_between(n, np.array([0.0, 0.0, 1.0])), deg


def _trunk_up(X, lay):
    """``(3,)`` unit: the mean direction from the hips' midpoint to the shoulders' over the frames
    that have all four, or None (a layout without them, no such frame)."""
    names = ("left_hip", "right_hip", "left_shoulder", "right_shoulder")
    if not all(n in lay for n in names):
        return None
    hip = X[:, [lay.index(n) for n in names[:2]]].mean(1)
    sho = X[:, [lay.index(n) for n in names[2:]]].mean(1)
    d = sho - hip
    d = d[np.isfinite(d).all(-1) & (np.linalg.norm(np.nan_to_num(d), axis=-1) > 1e-6)]
    if not len(d):
        return None
    return rot.normalize(rot.normalize(d).mean(0))


def _handedness(X, lay, handed, path):
    """``(mirrored, how)``: whether the body's left-right labels disagree with its facing
    (left x up should point forward) after the up axis is +Z."""
    if handed is not None:
        key = str(handed).strip().lower()
        if key not in ("right", "left"):
            raise RecordingError(f"handedness {handed!r}: expected right or left", path=path)
        return key == "left", "as set"
    up = np.array([0.0, 0.0, 1.0])
    # the body's left from the hips and, where seen, the shoulders (a lower-body take has none)
    shoulders = X[:, lay.index("left_shoulder")] - X[:, lay.index("right_shoulder")]
    left = X[:, lay.index("left_hip")] - X[:, lay.index("right_hip")] + \
        np.where(np.isfinite(shoulders), shoulders, 0.0)
    fwd = np.cross(left, up)
    cues = []
    if "nose" in lay and "left_ear" in lay:
        cues.append(("nose ahead of the ears", X[:, lay.index("nose")]
                     - 0.5 * (X[:, lay.index("left_ear")] + X[:, lay.index("right_ear")])))
    for side in ("left", "right"):
        for toe, back in ((f"{side}_foot_index", f"{side}_heel"), (f"{side}_big_toe", f"{side}_heel"),
                          (f"{side}_foot", f"{side}_ankle")):
            if toe in lay and back in lay:
                cues.append(("toes ahead of the heels", X[:, lay.index(toe)] - X[:, lay.index(back)]))
                break
    base = "thorax" if "thorax" in lay else "neck"          # the head's base: Human3.6M's, Halpe's
    if "nose" in lay and "head_top" in lay and base in lay:
        mid = 0.5 * (X[:, lay.index("head_top")] + X[:, lay.index(base)])
        cues.append(("nose ahead of the head", X[:, lay.index("nose")] - mid))
    if not cues:
        return False, "assumed"
    votes, said = [], []
    for name, v in cues:
        d = np.sum(rot.normalize(fwd) * rot.normalize(v), -1)
        d = d[np.isfinite(d)]
        if d.size:                      # a cue whose points are all missing (a TRC without ears) says nothing
            votes.append(float(np.median(d)))
            said.append(name)
    score = float(np.sum(votes))
    if not np.isfinite(score) or abs(score) < 0.1:
        return False, "assumed: no clear facing"
    return score < 0, said[0]
