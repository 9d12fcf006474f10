"""The whole solve of a recording, without Blender: read → resample → offsets → calibrate →
solve (network, then torso, feet and limbs) → arm adaptation → quality notes.

    from blender_manikin.core.solve import SolveSettings, solve_recording
    outcome = solve_recording("take.csv", SolveSettings(fps=30.0))
    outcome.result          # PoseResult: (T, 22) local rotations, root, swivel, contacts, ...
    outcome.summary()       # the one-line summary the panel and the CLI show

The add-on's job (``blender/solve_job.py``) runs exactly this in its worker thread and adds
only what needs Blender: sampling scene objects into a recording before, writing the armature
and action after.  Every stage is also a function of its own, for tests and benchmarks.
Times are on the recording clock in seconds; ``SolveSettings.tpose_time`` is seconds after the
first tracker sample (what the timeline shows).  No bpy.
"""
from __future__ import annotations

import copy
import os
import threading
import time as _time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from . import skeleton as sk
from .pipeline import DEFAULT_OVERLAP, overlap_windows
from .tracker_sides import mixed_pelvis_role, swapped_feet, swapped_hands, swapped_note
from .headset_off import headset_off, headset_off_note
from .lost_hands import relax_lost_hands
from .plain import shown
from .seated import POSTURES, SEATED_HEAD_HEIGHT, seat_legs, stature_from_seated_head
from .pose_result import PoseResult, TrackerTargets
from .teleports import (TELEPORT_CHOICES, find_rig_jumps, remove_rig_jumps, restore_rig_jumps, rig_jumps_note,
                        unconfirmed_jumps_note)
from .tracker_slips import FOOT_DEVICES, correct_tracker_slips, find_tracker_slips, tracker_slip_notes


class SolveError(RuntimeError):
    """A problem the user can fix (bad settings, bad recording); the message says what."""


def error_message(exc) -> str:
    """A one-line, user-readable message for ``exc`` (no traceback)."""
    msg = str(exc).strip() or exc.__class__.__name__
    if isinstance(exc, (SolveError, ValueError, OSError, RuntimeError)) or \
            exc.__class__.__name__ in ("RecordingError", "ModelError"):
        return msg
    return f"{exc.__class__.__name__}: {msg}"


@dataclass
class SolveSettings:
    """How to solve a recording (the panel's and the command line's options, plain values).

    axes / units: override the file's metadata (None = file / format default).  fps: the solve
    frame rate.  calibration: ``"AUTO"`` (calibrate on the most T-pose-like moment when one is
    plausible, else stature from the standing head height), ``"TPOSE"`` (calibrate on the
    T-pose at ``tpose_time`` seconds after the first sample) or ``"MEASURE"`` (``height`` and
    optional ``arm_span``, metres); with TPOSE/AUTO a given ``height`` overrides the measured
    stature.  sole: the performer's shoe soles, metres (None: :data:`.skeleton.SOLE`, 3 cm; 0
    barefoot): the stature measured from the head's height is the barefoot one, and the body
    stands that much above the floor.  floor: where the recording's floor is, metres on its
    vertical axis (0, the default: at its zero), or ``"height"``: under a performer of
    ``height`` standing in the take (:func:`floor_height`); the solve moves it to z = 0.
    offsets: a device-offsets preset name, ``"none"``, ``"auto"`` (see :func:`resolve_offsets`)
    or an offsets dict (:mod:`.device_offsets`).  max_frames: crop.  start / end: the part of
    the take to solve, seconds from its first sample (None: from the start / to the end); a
    tracker take is still calibrated on the whole recording (its T-pose is usually at the start)
    and solved :data:`TRIM_MARGIN_S` beyond either end (from a multiple of :data:`TRIM_ALIGN_S`),
    so that the network sees the motion around the cut as in the whole take's solve.
    smoothing: ``"auto"`` (default: each device's, or keypoint's, track gets the Savitzky-Golay
    filter its own measured noise calls for, so clean tracks stay as they are) or one window in
    seconds for all (0: off); see :mod:`.smoothing`.
    layout: a layout file (path or dict) fixing the columns of a wide-layout CSV.  rate: samples
    per second of a wide-layout CSV, or of keypoints, timed by a frame counter only.

    Keypoint inputs (:mod:`.keypoint_solve`) also use: keypoint_layout (a
    :mod:`.keypoint_layouts` name; None: told from the file), up (the file's up axis, ``+y``
    ...; None: told from the body), ik
    (``"adaptive"`` or ``"naive"`` HybrIK), mapping (a keypoint CSV's column mapping file),
    fix_sides (undo a detector's left/right label swaps, :mod:`.keypoint_sides`; default on; for
    trackers, controllers held in the other hands or foot trackers on the other feet,
    :mod:`.tracker_sides`) and
    despike (remove a detector's misplaced samples, :mod:`.keypoint_spikes`; default on) and
    keypoint_floor (``"feet"``, the default: the floor is found under the feet and moved to
    z = 0, the body standing on its soles; ``"keep"``: the heights as given, the joints where the
    keypoints are, e.g. an armature's bones in the scene, :data:`.keypoint_solve.KEYPOINT_FLOORS`)
    and subject_params (a Vicon subject parameter file, ``.mp`` / ``.vsk``, for a Plug-in Gait
    TRC: the subject's joint widths and, unless ``height`` is given, stature; ``"none"``: not
    used; None: the one found beside the TRC, :mod:`.subject_params`) and person (in a file with
    several people, the one solved: a label or a 0-based index; ``"all"``, the default, solves a
    one-person file and refuses one with several: ``solve``, ``convert`` and the Blender solve
    split such a file into one solve per person, :func:`.io_keypoints.read_keypoint_people`) and
    person_axis (a 4-D array's people axis).
    Tracker inputs also use model (the pose network) and overlap (how many network windows see
    each frame: 2, the default, keeps 10,000 frames/s; 3 and 4 are a little more accurate at 1.5
    and 2 times the network time; :data:`.pipeline.OVERLAP_CHOICES`), and teleports (what to
    do with the teleports and snap turns of an app that moves the tracking space,
    :mod:`.teleports`: ``"keep"``, the default, solves the take as one motion and puts them back
    on the solved body; ``"remove"`` leaves them out, the character's path continuous;
    ``"ignore"`` solves the recording as it stands), and posture (``"standing"``, the default,
    or ``"seated"``: the legs sit on a chair, feet on the floor, the stature from the typed
    height, a standing T-pose, or the seated head height; :mod:`.seated`).
    """
    axes: str | None = None
    units: str | None = None
    fps: float | None = 30.0
    calibration: str = "AUTO"
    tpose_time: float | None = None
    height: float | None = None
    arm_span: float | None = None
    sole: float | None = None
    floor: object = 0.0               # metres, or "height" (under the performer of `height`)
    offsets: object = "auto"
    max_frames: int | None = None
    layout: object = None
    rate: float | None = None
    keypoint_layout: str | None = None
    up: str | None = None
    smoothing: object = "auto"        # "auto" or a window in seconds (0: off); trackers and keypoints
    ik: str = "adaptive"
    mapping: object = None
    fix_sides: bool = True            # undo left/right label swaps (keypoint_sides; tracker_sides)
    despike: bool = True              # keypoints: remove samples far off their point's path (keypoint_spikes)
    keypoint_floor: str = "feet"      # keypoints: "feet" (found under them, moved to z = 0) or "keep" (as given)
    model: str | None = None          # None / "auto": by the recording's trackers; a shipped name or .onnx
    overlap: int = DEFAULT_OVERLAP    # windows seeing each frame: 2, 3 or 4 (pipeline.OVERLAP_CHOICES)
    teleports: str = "keep"           # "keep", "remove" or "ignore" (teleports.TELEPORT_CHOICES)
    posture: str = "standing"         # "standing" or "seated" (seated.POSTURES): seated legs on a chair
    start: float | None = None        # seconds from the first sample: solve from here (None: the start)
    end: float | None = None          # seconds from the first sample: solve up to here (None: the end)
    calibration_take: str | None = None   # a recording whose T-pose calibrates this take (body, offsets)
    subject_params: str | None = None     # keypoints: a Vicon .mp / .vsk for a Plug-in Gait TRC, "none", or None: auto
    person: str | None = "all"        # keypoints: "all" or one person's label / 0-based index (io_keypoints)
    person_axis: int | None = None    # keypoints: a 4-D array's people axis, 0 or 1 (None: the file's, or told)


@dataclass
class SolveOutcome:
    """What a solve produced: ``recording`` (:class:`.recording.Recording`), ``report``
    (resampling gaps), ``targets`` (:class:`TrackerTargets`), ``body``, ``offsets`` (the device
    offsets used, refined by calibration), ``info`` (notes for the user: the calibration moment,
    arm adaptation, implausible stature), ``result`` (:class:`PoseResult`) and ``timings``
    (seconds per stage)."""
    recording: object = None
    report: object = None
    targets: TrackerTargets | None = None
    body: sk.Body | None = None
    offsets: object = None
    info: list = field(default_factory=list)
    result: PoseResult | None = None
    timings: dict = field(default_factory=dict)
    floor: float | None = None          # the floor's height in the recording (metres), moved to z = 0
    floor_why: str | None = None        # how the floor was found when the settings did not say
    jumps: list = field(default_factory=list)   # the app's teleports and snap turns (teleports.RigJump)
    headset_off: tuple = (0, 0)         # frames at the start / end where the headset lay off (headset_off.py)
    slips: list = field(default_factory=list)   # foot trackers that slipped mid-take (tracker_slips.TrackerSlip)

    def summary(self, extra_timings=None, timings=True) -> str:
        """One line: frames, fps, where the solve gave way, stature, calibration, gaps, and (with
        ``timings``) the seconds per stage."""
        parts = []
        detected = (getattr(self.recording, "metadata", None) or {}).get("detected")
        if detected:
            parts.append(detected)
        if self.result is not None:
            parts.append(f"{self.result.num_frames} frames at {self.result.fps:g} fps")
            parts.extend(getattr(self.result, "notes", None) or [])
            parts.extend(self.result.quality_notes())
        if self.body is not None:
            parts.append(f"stature {self.body.stature:.2f} m")
        for note in self.info:
            if note.startswith(("offsets ", "trimmed to", "calibrated", "calibration: ", "no T-pose found",
                                "arm span", "estimated stature", "stature ", "check whether the performer sits",
                                "check the arms: ",
                                "head stands", "floor at",
                                "left/right labels swapped back", "left and right controllers swapped back",
                                "left and right foot trackers swapped back", "pelvis and left foot trackers",
                                "the headset lay still",
                                "pelvis and right foot trackers",
                                "spikes removed", "lower body only", "arm(s) never seen", "wrist(s) never seen",
                                "no twist information", "keypoints: adaptive HybrIK", "keypoints: naive HybrIK",
                                "point(s) never seen", "retarget:", "smoothing", "no smoothing", "no mannequin")) \
                    or " tracker offset" in note or " teleport" in note or " snap turn" in note \
                    or note.endswith("the arm hangs relaxed there"):
                parts.append(note)
        if self.report is not None:
            gaps = getattr(self.report, "gaps", [])
            if gaps:
                parts.append(gaps_note(gaps, getattr(self.report, "t0", 0.0)))
            # what the reader and the resampler repaired or left out (each said once)
            parts.extend(dict.fromkeys(getattr(self.report, "warnings", None) or []))
        seconds = dict(self.timings, **(extra_timings or {})) if timings else {}
        if seconds:
            parts.append(", ".join(f"{k} {v:.2f}s" for k, v in seconds.items()))
        return "; ".join(parts)


def gaps_note(gaps, t0=0.0):
    """The summary's line on bridged gaps: ``"3 gap(s) bridged, the longest head 3.0 s from 2.0 s
    (no samples)"``, ``"... the longest point left wrist 0.2 s from 5.0 s (not seen)"``.  gaps:
    :class:`.resample.Gap` s (a tracker device or a keypoint name, seconds on
    the recording's clock); t0: the clock's time of the solve's first frame."""
    from .devices import LABELS
    g = max(gaps, key=lambda g: g.duration)
    what = LABELS[g.device].lower() if g.device in LABELS else f"point {g.device.replace('_', ' ')}"
    why = GAP_REASONS.get(g.reason, g.reason)
    dur = f"{g.duration:.1f}" if g.duration >= 0.95 else f"{g.duration:.2f}"
    return f"{len(gaps)} gap(s) bridged, the longest {what} {dur} s from {g.start - t0:.1f} s ({why})"


#: :class:`.resample.Gap` reasons in the summary's words
GAP_REASONS = {"missing": "no samples", "invalid": "marked not tracked", "nan": "not-a-number values",
               "frozen": "frozen pose", "origin": "at the tracking origin", "jump": "spikes",
               "start": "not tracked at the start", "end": "not tracked at the end",
               "lost": "not seen"}


# --------------------------------------------------------------------------
# the stages
def read_recording(path, settings: SolveSettings):
    """Read the recording file at ``path`` (Blender axes, metres)."""
    from .formats import load_recording
    if not path:
        raise SolveError("no recording file chosen")
    return load_recording(path, axes=settings.axes, units=settings.units, layout=settings.layout,
                          rate=settings.rate)


def resample_recording(recording, fps, floor=0.0):
    """``(times, pos, quat, valid, report)`` on a grid at ``fps`` (see :func:`.resample.resample`).
    floor: the floor setting (:func:`parse_floor`): the head-height check measures from a
    floor height and is skipped where the floor will be put under the performer."""
    from .resample import resample, seconds_from_time_units
    floor = parse_floor(floor)
    return resample(seconds_from_time_units(recording), fps, floor=None if floor == FLOOR_FROM_HEIGHT else floor)


#: a trimmed tracker take is solved this many seconds beyond either end of the part kept (the
#: network's half window), then cut ...
TRIM_MARGIN_S = 1.0
#: ... from a multiple of this many seconds of the take: the network's windows (every second one
#: mirrored) then fall where they fall in the whole take's solve, for the shipped models at every
#: overlap but the four-tracker and six-tracker networks' 3 (their window periods divide 4 s)
TRIM_ALIGN_S = 4.0


def trim_span(times, start=None, end=None):
    """``(first, stop)`` frame indices of the part ``[start, end]`` seconds (from ``times[0]``;
    None: from the first / to the last frame) of frames at ``times`` ``(T,)``, or None when the
    whole take is kept.  Raises :class:`SolveError` for a part outside the take or empty."""
    if start is None and end is None:
        return None
    T = len(times)
    length = float(times[-1] - times[0]) if T else 0.0
    for name, v in (("start", start), ("end", end)):
        if v is not None and not (np.isfinite(v) and v >= 0):
            raise SolveError(f"{name} {shown(v)}: expected seconds >= 0 from the recording's first sample")
    if start is not None and start > length:
        raise SolveError(f"start {start:g} s is past the recording's end ({length:.2f} s long)")
    if start is not None and end is not None and end <= start:
        raise SolveError(f"end {end:g} s is not after start {start:g} s")
    rel = np.asarray(times) - times[0]
    first = 0 if start is None else int(np.searchsorted(rel, float(start) - 1e-9, side="left"))
    stop = T if end is None else int(np.searchsorted(rel, float(end) + 1e-9, side="right"))
    if stop - first < 2:
        raise SolveError(f"the part {start or 0:g}-{end if end is not None else length:g} s holds fewer than 2 frames")
    return first, stop


def fix_swapped_sides(pos, quat, valid, fps):
    """Swap the controllers, the pelvis tracker and a foot tracker, then the foot trackers, back
    where the take says they were in the other hands, the roles mixed up, or on the other feet
    (:mod:`.tracker_sides`).

    pos, quat, valid: device → resampled ``(T, 3)`` metres / ``(T, 4)`` wxyz / ``(T,)`` bool on
    one grid of ``fps`` frames per second, changed in place.  Returns the summary's notes."""
    notes = []
    if all(d in pos for d in ("head", "left_hand", "right_hand")):
        both = valid["head"] & valid["left_hand"] & valid["right_hand"]
        swapped, share, wide = swapped_hands(quat["head"], pos["left_hand"], pos["right_hand"], both, fps)
        if swapped:                    # held in the other hands, or mislabelled: swapped back
            for d in (pos, quat, valid):
                d["left_hand"], d["right_hand"] = d["right_hand"], d["left_hand"]
            notes.append(swapped_note(share, wide, fps))
    feet = [d for d in ("left_foot", "right_foot") if d in pos]
    if "pelvis" in pos and feet:
        foot = mixed_pelvis_role(pos["pelvis"][:, 2], {d: pos[d][:, 2] for d in feet}, valid)
        if foot is not None:           # the waist tracker was given a foot's role
            drop = float(np.median(pos[foot][valid[foot], 2]) - np.median(pos["pelvis"][valid["pelvis"], 2]))
            for d in (pos, quat, valid):
                d["pelvis"], d[foot] = d[foot], d["pelvis"]
            notes.append(f"pelvis and {foot.replace('_', ' ')} trackers swapped back: the pelvis one was "
                         f"{drop:.2f} m below the foot one (keep them as labelled with --keep-sides / "
                         f"Fix Left/Right Swaps off)")
    if all(d in pos for d in ("head", "left_foot", "right_foot")):
        both = valid["head"] & valid["left_foot"] & valid["right_foot"]
        pelvis = None
        if "pelvis" in pos:
            both = both & valid["pelvis"]
            pelvis = quat["pelvis"]
        swapped, share, wide = swapped_feet(quat["head"], pos["left_foot"], pos["right_foot"], pelvis, both, fps)
        if swapped:                    # strapped to the other feet, or the roles mixed up
            for d in (pos, quat, valid):
                d["left_foot"], d["right_foot"] = d["right_foot"], d["left_foot"]
            notes.append(swapped_note(share, wide, fps, "foot trackers"))
    return notes


def resolve_offsets(offsets, recording):
    """``"auto"`` → the preset the recording implies, else ``offsets`` unchanged.

    auto: the file's ``# offsets: PRESET`` metadata when it names a preset, or the offsets the file
    records (a dict: a Beat Saber replay's own saber offsets, :mod:`.io_bsor`); else the default of
    the file's format (:mod:`.formats`: ``beat_saber`` for a ``.bsor`` replay, whose hand poses
    are saber poses; ``none`` otherwise: the device poses are taken as joint poses).
    """
    if not (isinstance(offsets, str) and offsets.lower() == "auto"):
        return offsets
    from . import device_offsets, formats
    meta = (getattr(recording, "metadata", None) or {}).get("offsets")
    if isinstance(meta, str) and meta.strip() in device_offsets.PRESET_NAMES:
        return meta.strip()
    if isinstance(meta, dict) and meta.get("devices"):
        return meta
    return formats.default_offsets(str(getattr(recording, "source", "")))


def _offsets_unstated(setting, resolved, recording):
    """True when the offsets are ``auto`` and neither the file nor its format says what they are
    (``none`` by default): :mod:`.offsets_auto` then looks at the take itself."""
    if not (isinstance(setting, str) and setting.lower() == "auto") or resolved != "none":
        return False
    meta = (getattr(recording, "metadata", None) or {}).get("offsets")
    return not (isinstance(meta, str) and meta.strip())


def offsets_note(setting, resolved, recording=None, guessed=None):
    """The summary's note on the device offsets: ``"offsets beat_saber_touch (auto: from the file)"``.

    setting: what the user chose (``"auto"``, a preset name, a file's offsets dict ...);
    resolved: what :func:`resolve_offsets` made of it, or what the take showed
    (:mod:`.offsets_auto`; ``guessed``: why).  ``None`` when nothing needs saying: a typed preset
    or offsets the user gave (they know what they chose), or ``auto`` giving ``none`` for a format
    whose poses are the joints' own."""
    if not (isinstance(setting, str) and setting.lower() == "auto"):
        return None
    meta = (getattr(recording, "metadata", None) or {}).get("offsets")
    if isinstance(resolved, dict) and resolved is meta:
        return f"offsets {resolved.get('name', 'custom')} (auto: {resolved.get('description') or 'from the file'})"
    if not isinstance(resolved, str):
        return None
    if guessed:
        hands = ("; openxr_hand_tracking if the hands are tracked without controllers (wrist joints)"
                 if resolved == "openxr_generic" else "")
        return (f"offsets {resolved} (auto: {guessed}; choose offsets none if the head samples are the head "
                f"joint's{hands})")
    if resolved == "none":
        return None
    why = "from the file" if isinstance(meta, str) and meta.strip() == resolved else "the format's default"
    return f"offsets {resolved} (auto: {why})"


def make_targets(times, pos, quat, valid, fps, offsets="none"):
    """Joint targets from resampled device poses after device ``offsets`` (a preset name,
    ``"none"``, or an offsets dict of :mod:`.device_offsets`).  Returns ``(targets, offsets)``."""
    from . import device_offsets
    try:
        off = device_offsets.validate_offsets(offsets if offsets not in ("", None) else "none")
    except ValueError as exc:
        raise SolveError(f"device offsets: {exc}") from exc
    return device_offsets.to_targets(times, pos, quat, valid, off, fps=fps), off


def standing_head_height(targets: TrackerTargets) -> float:
    """The head joint's standing height (metres, the recording's z): the
    :data:`.resample.STANDING_PERCENTILE` (90th) percentile of the head target's z over the take
    (the performer stands for a tenth of it at least; robust to jumps and noise)."""
    from .resample import STANDING_PERCENTILE
    return float(np.nanpercentile(np.asarray(targets.pos["head"])[:, 2], STANDING_PERCENTILE))


def head_height_for(stature, sole=None) -> float:
    """How high (metres above the floor) the head joint of a performer of ``stature`` metres
    stands on ``sole`` metres of shoe sole (None: :data:`.skeleton.SOLE`): the inverse of
    :func:`.calibration.stature_from_head_height`."""
    return float(sk.sole_or_default(sole)) + float(stature) * sk.PROPORTIONS["head_height"]


#: the floor settings that are not a number (see :func:`floor_height`)
FLOOR_FROM_HEIGHT = "height"


def parse_floor(value):
    """``SolveSettings.floor`` checked: a float (metres) or :data:`FLOOR_FROM_HEIGHT`.
    None or "" mean 0.  Raises :class:`SolveError` naming the value."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return 0.0
    if isinstance(value, str) and value.strip().lower() == FLOOR_FROM_HEIGHT:
        return FLOOR_FROM_HEIGHT
    try:
        floor = float(value)
    except (TypeError, ValueError):
        raise SolveError(f"floor {value!r}: expected a height in metres or {FLOOR_FROM_HEIGHT!r}") from None
    if not np.isfinite(floor):
        raise SolveError(f"floor {value!r}: expected a finite height in metres")
    return floor


def floor_height(settings: SolveSettings, targets: TrackerTargets) -> float:
    """Where the floor is in the recording (metres, the recording's z after axes and units).

    ``settings.floor``: a number, the floor's height as typed (0, the default: the recording's
    zero is the floor, as OpenXR's stage space and SteamVR's standing universe put it), or
    ``"height"``: under a performer of ``settings.height`` standing in the take, i.e. the
    standing head height (:func:`standing_head_height`) less the head height of that stature
    (:func:`head_height_for`), for recordings whose origin is at eye level, on a desk or
    anywhere else (a take whose origin is at eye level while the floor is left at 0:
    :func:`eye_level_floor`).  Raises :class:`SolveError` when ``"height"`` has no height."""
    floor = parse_floor(settings.floor)
    if floor != FLOOR_FROM_HEIGHT:
        return floor
    if not settings.height or settings.height <= 0:
        raise SolveError("the floor under the performer (--floor height; the panel's Floor: Under Performer) "
                         "needs their height: give --height METRES (the panel's Height)")
    return standing_head_height(targets) - head_height_for(settings.height, settings.sole)


def move_floor(targets: TrackerTargets, floor: float) -> TrackerTargets:
    """``targets`` with the floor at ``floor`` metres moved to z = 0 (every device lowered by
    ``floor``); the same object when ``floor`` is 0."""
    if not floor:
        return targets
    down = np.array([0.0, 0.0, float(floor)])
    return TrackerTargets(fps=targets.fps, pos={d: np.asarray(v) - down for d, v in targets.pos.items()},
                          rot=targets.rot, valid=targets.valid)


def floor_note(settings: SolveSettings, floor: float, why=None):
    """The note for the summary when the floor was moved (else None); ``why``: how it was found
    when the settings did not say (:func:`eye_level_floor`)."""
    if not floor:
        return None
    how = why or (f"under the {settings.height:.2f} m performer" if parse_floor(settings.floor) == FLOOR_FROM_HEIGHT
                  else "as set")
    return f"floor at {floor:+.3f} m ({how}) moved to 0"


#: a standing head (:data:`.resample.STANDING_PERCENTILE`) this close (metres) to the recording's
#: zero, the floor left at 0, is an origin at eye level (OpenXR LOCAL space, Unity's Device
#: tracking origin, a headset's starting pose), not a floor: :func:`eye_level_floor` finds it
EYE_LEVEL_MAX = 0.5
#: the stature an eye-level take is sized for when it has no T-pose and no typed height
EYE_LEVEL_STATURE = 1.75
#: metres the hands stay from the head (the median over their samples) in a take at a person's
#: scale (about 0.5 m; a hand at the face 0.15 m): closer, the positions are scaled down (metres
#: read as centimetres or millimetres), not an origin at eye level
HANDS_FROM_HEAD_MIN = 0.1


def hands_from_head(recording):
    """The median distance (metres) of the hands' valid samples from the head at their times, or
    None without hand samples (a take of the head alone)."""
    head = recording.streams["head"]
    hp = np.asarray(head.pos, np.float64)
    ok = np.asarray(head.valid, bool) & np.all(np.isfinite(hp), -1)
    if ok.sum() < 2:
        return None
    dist = []
    for d in ("left_hand", "right_hand"):
        s = recording.streams.get(d)
        if s is None:
            continue
        p = np.asarray(s.pos, np.float64)
        m = np.asarray(s.valid, bool) & np.all(np.isfinite(p), -1)
        at = np.stack([np.interp(s.time[m], head.time[ok], hp[ok, k]) for k in range(3)], -1)
        dist.append(np.linalg.norm(p[m] - at, axis=-1))
    dist = np.concatenate(dist) if dist else np.zeros(0)
    return float(np.median(dist)) if dist.size else None


def eye_level_origin(recording, settings: SolveSettings) -> bool:
    """Whether ``recording`` (Blender axes, metres) has its origin at eye level: the floor setting
    left at 0 and the standing head within :data:`EYE_LEVEL_MAX` of it, the hands at a person's
    distance from it (:data:`HANDS_FROM_HEAD_MIN`: positions scaled down, as a wrong unit makes
    them, are no eye level, and the head-height check then says what they look like)."""
    from .resample import STANDING_PERCENTILE
    if parse_floor(settings.floor) != 0.0 or "head" not in recording.streams:
        return False
    head = recording.streams["head"]
    z = np.asarray(head.pos, np.float64)[:, 2][np.asarray(head.valid, bool)]
    z = z[np.isfinite(z)]
    if not (z.size and abs(float(np.percentile(z, STANDING_PERCENTILE))) < EYE_LEVEL_MAX):
        return False
    reach = hands_from_head(recording)
    return reach is None or reach >= HANDS_FROM_HEAD_MIN


def eye_level_floor(settings: SolveSettings, targets: TrackerTargets):
    """``(floor, why)``: where the floor of an eye-level take (:func:`eye_level_origin`) is, metres
    in the recording's z, under a performer of the typed height, else of the stature the take's
    T-pose arm span gives (wrist to wrist :data:`.calibration.TPOSE_WRIST_DISTANCE` of it), else
    of :data:`EYE_LEVEL_STATURE` (with a calibration take: the stature it calibrates), standing
    (its standing head height) or, with the *Seated* posture, sitting (its median head height,
    :data:`.seated.SEATED_HEAD_HEIGHT` of the stature); ``why`` says which, for the summary."""
    from . import calibration as cal
    from .seated import SEATED_HEAD_HEIGHT
    head = standing_head_height(targets)
    if settings.height:
        stature, why = float(settings.height), f"under the typed {float(settings.height):.2f} m"
    elif settings.calibration_take:      # the body is the calibration take's: its floor is under that one
        mode = str(settings.teleports or "keep").strip().lower()
        stature = calibration_from_take(settings, mode)[0].stature
        why = (f"under the {stature:.2f} m performer of the calibration take "
               f"{os.path.basename(os.fspath(settings.calibration_take))}")
    else:
        guess = head - head_height_for(EYE_LEVEL_STATURE, settings.sole)
        cand = cal.find_tpose(move_floor(targets, guess))
        if cand.plausible:
            k = cand.frame
            span = float(np.linalg.norm(targets.pos["left_hand"][k] - targets.pos["right_hand"][k]))
            stature = span / cal.TPOSE_WRIST_DISTANCE
            why = (f"under a {stature:.2f} m performer, from the T-pose's arm span at "
                   f"{k / targets.fps:.2f} s")
        else:
            stature = EYE_LEVEL_STATURE
            why = f"under a {stature:.2f} m performer: no T-pose to measure, type the height"
    if str(settings.posture or "").lower() == "seated":
        from .seated import stood_and_sat
        z = np.asarray(targets.pos["head"], np.float64)[:, 2]
        stood, seated_head = stood_and_sat(z, head_height_for(stature, settings.sole) - SEATED_HEAD_HEIGHT * stature)
        if stood:           # the standing frames put the floor under the standing head
            floor = head - head_height_for(stature, settings.sole)
            why += ", seated and standing"
        else:
            floor = seated_head - SEATED_HEAD_HEIGHT * stature
            why += ", seated"
    else:
        floor = head - head_height_for(stature, settings.sole)
    return floor, f"the recording's origin is at eye level: {why}"


def body_from_head_height(targets: TrackerTargets, height=None, arm_span=None, sole=None) -> sk.Body:
    """A body when no calibration pose is available: stature = ``height`` (metres) if given,
    else from the standing head height (:func:`standing_head_height`; standing on ``sole``
    metres of shoe sole, None: :data:`.skeleton.SOLE`: (z - sole) / 0.870), clipped to 1.0-2.3 m."""
    if height is None:
        head_z = standing_head_height(targets)
        height = float(np.clip((head_z - sk.sole_or_default(sole)) / sk.PROPORTIONS["head_height"], 1.0, 2.3))
    try:
        return sk.make_body(sk.BodyMeasurements(stature=float(height), arm_span=arm_span or None, sole=sole))
    except ValueError as exc:
        raise SolveError(f"body measurements: {exc}") from exc


def calibrate(settings: SolveSettings, targets: TrackerTargets, times, offsets):
    """The performer's body for ``settings.calibration``.

    Returns ``(body, offsets, info)``: the offsets refined by a T/A-pose calibration (else
    unchanged) and ``info``, notes for the user (the calibration moment, its problems).  With
    pelvis / foot trackers the T/A-pose also measures their whole offsets (unless typed, which
    are kept) and, from the pelvis tracker, the legs (:mod:`.calibration`, "Six trackers"):
    one note per tracker (``"pelvis tracker offset 12.3 cm, 171° (from the T-pose)"``) and the
    legs in the calibration note.  Without a calibration pose, extra trackers whose offsets are
    not typed get a note: their raw poses are taken as the joints'."""
    from . import calibration as cal
    mode = (settings.calibration or "AUTO").upper()
    info = []
    extra = [d for d in ("pelvis", "left_foot", "right_foot") if d in targets.pos]
    untyped = [d for d in extra if d not in cal.typed_tracker_offsets(offsets)]
    no_pose_note = (f"{', '.join(d.replace('_', ' ') for d in untyped)} tracker offsets not measured (no "
                    f"T-pose): their poses are taken as the joints'; type their offsets or calibrate on a T-pose")
    if mode == "MEASURE":
        if not settings.height or settings.height <= 0:
            raise SolveError("calibration by measurements needs a height (metres)")
        if untyped:
            info.append(no_pose_note)
        return body_from_head_height(targets, settings.height, settings.arm_span, settings.sole), offsets, info
    t0 = float(times[0])
    meas = {"stature": float(settings.height)} if settings.height else None
    if settings.arm_span:                     # typed: kept, with or without a typed height
        meas = {**(meas or {}), "arm_span": float(settings.arm_span)}
    if settings.sole is not None:
        meas = {**(meas or {}), "sole": float(settings.sole)}
    if mode == "TPOSE":
        if settings.tpose_time is None:
            raise SolveError("T-pose calibration needs the time of the T-pose")
        dur = float(times[-1] - times[0])
        if not (-1e-6 <= float(settings.tpose_time) <= dur + 1e-6):
            raise SolveError(f"T-pose time {settings.tpose_time:.3f} s is outside the recording "
                             f"(0-{dur:.3f} s after the first sample)")
        t = t0 + float(settings.tpose_time)
    else:   # AUTO: the most T-pose-like moment, if it is plausible, else an A-pose's
        cand = cal.find_tpose(targets, t0=t0)
        if not cand.plausible:
            cand = cal.find_apose(targets, t0=t0)
        if str(settings.posture or "").lower() == "seated" and not settings.height:
            seated = _seated_stature(targets, times, cand, settings.sole)
            if seated is not None:          # no standing T-pose: the seated head sizes the body
                info.append(f"stature {seated:.2f} m from the seated head height (its "
                            f"{SEATED_HEAD_HEIGHT:.3f}; type the height to be sure)")
                meas = {**(meas or {}), "stature": seated}
                if not cand.plausible:
                    if untyped:
                        info.append(no_pose_note)
                    return body_from_head_height(targets, seated, settings.arm_span, settings.sole), offsets, info
        if not cand.plausible:
            info.append("no T-pose found: stature from the standing head height")
            if untyped:
                info.append(no_pose_note)
            return body_from_head_height(targets, settings.height, settings.arm_span, settings.sole), offsets, info
        t = cand.time
    try:
        res = cal.calibrate(targets, time=t, offsets=offsets, t0=t0, measurements=meas)
        body = cal.body_for(res.measurements)
    except ValueError as exc:
        raise SolveError(f"calibration at {t - t0:.2f} s: {exc}") from exc
    note = (f"calibrated on {'an' if res.pose == 'A' else 'a'} {res.pose}-pose at {t - t0:.2f} s: stature "
            f"{res.measurements.stature:.2f} m, arm span {res.measurements.arm_span or 0:.2f} m")
    legs = res.measured.get("legs") or {}
    if legs.get("used") and res.measurements.thigh is not None and res.measurements.shank is not None:
        src = "pelvis tracker" if legs["source"] == "pelvis tracker" else "typed pelvis offset"
        note += f", legs {res.measurements.thigh + res.measurements.shank:.2f} m (from the {src})"
    elif extra:
        note += ", legs proportional"
    info.append(note)
    for d, tr in res.tracker_offsets.items():
        label = d.replace("_", " ")
        text = f"{label} tracker offset {100 * tr['distance']:.1f} cm, {tr['angle_deg']:.0f}°"
        if tr["source"] == "typed":
            text += " (typed, kept"
            if "disagree_m" in tr:
                text += (f"; the T-pose suggests one {100 * tr['disagree_m']:.1f} cm, {tr['disagree_deg']:.0f}° "
                         f"different")
            text += ")"
        else:
            text += " (from the T-pose)" if res.pose == "T" else " (from the A-pose)"
        info.append(text)
    info += [f"calibration: {p}" for p in res.problems]
    return body, res.offsets, info


#: a T-pose whose head stands this much (metres) above the take's median head height was made
#: standing: with the *Seated* posture it still sizes the body
STANDING_TPOSE_RISE = 0.15


def _seated_stature(targets, times, cand, sole=None):
    """The stature (metres) a seated take's head implies (:func:`.seated.stature_from_seated_head`
    of its median height), or None when ``cand`` is a T-pose made standing (its head
    :data:`STANDING_TPOSE_RISE` above the median): that one sizes the body as usual.  A take
    that also stands (:func:`.seated.stood_and_sat`) has its seated head from the frames it sits."""
    from .seated import stood_and_sat
    z = targets.pos["head"][:, 2]
    ok = np.asarray(targets.valid.get("head", np.ones(len(z), bool)), bool) & np.isfinite(z)
    median = float(np.median(z[ok] if ok.any() else z))
    if cand.plausible:
        k = int(np.clip(np.searchsorted(times, cand.time), 0, len(z) - 1))
        if z[k] - median > STANDING_TPOSE_RISE:
            return None
    hi = float(np.percentile(z[ok] if ok.any() else z, 90))
    standing = (hi - sk.sole_or_default(sole)) / sk.PROPORTIONS["head_height"]
    stood, seated_head = stood_and_sat(z[ok] if ok.any() else z, hi - SEATED_HEAD_HEIGHT * standing)
    return stature_from_seated_head(seated_head if stood else median)


#: metres the standing head may stand above or below where a typed height puts it before the
#: summary says so (:func:`head_height_note`)
HEAD_HEIGHT_TOLERANCE = 0.15


def stature_note(settings: SolveSettings, outcome: SolveOutcome):
    """A note when the body's stature is implausible (:func:`.calibration.stature_warning`), else None."""
    from . import calibration as cal
    if settings.height:                          # a typed height always wins
        sized_by = "height setting"
    elif any(n.startswith("calibrated") for n in outcome.info):
        sized_by = "T-pose"
    else:
        sized_by = "head height"
    units = settings.units or (getattr(outcome.recording, "metadata", None) or {}).get("units", "m")
    return cal.stature_warning(outcome.body.stature, standing_head_height(outcome.targets), sized_by, units)


def head_height_note(settings: SolveSettings, outcome: SolveOutcome, tolerance=HEAD_HEIGHT_TOLERANCE):
    """With a typed height: a note when the standing head (:func:`standing_head_height`, floor
    moved) is more than ``tolerance`` metres from where that performer's head stands
    (:func:`head_height_for`), else None.  The body hangs from the head, so a floor that is
    not where the recording says folds the legs (head too low) or lifts the feet (too high)."""
    if not settings.height or outcome.body is None:
        return None
    head = standing_head_height(outcome.targets)
    expected = head_height_for(outcome.body.stature, outcome.body.sole)
    if abs(head - expected) <= tolerance:
        return None
    side = "lower" if head < expected else "higher"
    return (f"head stands {head:.2f} m above the floor, {abs(head - expected):.2f} m {side} than a "
            f"standing {outcome.body.stature:.2f} m performer's ({expected:.2f} m): check the floor "
            f"(Floor 'Under Performer', --floor height, puts it under the performer), the height, or whether the "
            f"performer sits")


def default_solver(targets, body, progress=None, model=None, overlap=None):
    """:func:`.pipeline.solve` (network, torso, feet, limbs) with ``model`` (default: the shipped
    model for the recording's trackers, :mod:`.model_choice`), each frame seen by ``overlap``
    network windows (default 2)."""
    from . import model_choice, pipeline
    try:
        path = model_choice.resolve_model(model)
    except ValueError as exc:
        raise SolveError(str(exc)) from exc
    return pipeline.solve(targets, body, runner=path, progress=progress, overlap=overlap)


#: an arm span from the reach more than this times the stature the standing head height gave: a
#: performer seated, solved standing (adults' arm spans are 0.95-1.06 of their stature; a 2.0 m
#: performer on a seat at knee height, solved standing: a 1.44 m body reaching 1.58 m, 1.10)
ARM_SPAN_SITS_RATIO = 1.08


def long_reach_note(outcome: SolveOutcome, span, stature):
    """The summary's note when the arms were lengthened to ``span`` metres, over
    :data:`ARM_SPAN_SITS_RATIO` times the ``stature`` (metres) the standing head height gave,
    with advice that fits the take's trackers.  Head and hands only: the head is lower than a
    standing one's, so the performer may sit.  With a pelvis tracker whose offset was not
    measured (no T-pose, not typed) that offset is the likelier cause (a generated 1.72 m
    six-tracker take without its T-pose: 1.89 m with the pelvis tracker, arms kept with head and
    hands only).  With pelvis and both foot trackers the legs are tracked, so sitting is not
    offered."""
    from . import calibration as cal
    have = outcome.targets.pos if outcome.targets is not None else {}
    legs_tracked = all(d in have for d in ("pelvis", "left_foot", "right_foot"))
    pelvis_unmeasured = "pelvis" in have and "pelvis" not in cal.typed_tracker_offsets(outcome.offsets)
    reach = (f"the hands reach {span:.2f} m apart, {span / stature:.2f} times the {stature:.2f} m the standing "
             f"head height gives (an arm span is about the stature)")
    if not pelvis_unmeasured and not legs_tracked:
        # arms this long for the body the head sized: the head is lower than a standing one's
        return (f"check whether the performer sits: {reach}; set the Posture to Seated (--posture seated), "
                "or type the height")
    advice = []
    if pelvis_unmeasured:
        advice.append("the pelvis tracker's offset was not measured (no T-pose), which can put the shoulders "
                      "out of the hands' reach: type its offset or calibrate on a T-pose (--calibration-take)")
    if not legs_tracked:
        advice.append("or the performer sits: set the Posture to Seated (--posture seated)")
    advice.append("or type the height and arm span")
    return f"check the arms: {reach}; " + ", ".join(advice)


def adapt_arms(settings: SolveSettings, outcome: SolveOutcome, result, solver, progress=None):
    """Lengthen arms built from proportions when the hands cannot reach their trackers.

    Only when no arm span was measured (no T/A-pose calibration) or given: the span comes from
    :func:`.calibration.arm_span_for_reach` and the recording is solved again with it: only the
    analytic stages when the solver's result offers ``with_body`` (the network's inputs barely
    change with the arm span), else the whole ``solver``.  Notes it in ``outcome.info`` and sets
    ``outcome.body``.  Returns the result to keep."""
    from . import calibration as cal
    if settings.arm_span or any(n.startswith("calibrated") for n in outcome.info):
        return result
    if result.reach_error is None or not (result.reach_error[:, :2] > 0.005).any():
        return result
    before = int((result.reach_error[:, :2] > 0.005).any(1).sum())
    if result.with_body is not None:     # the same network output, assembled with longer arms
        def resolve(b):
            return result.with_body(b, progress=progress)
    else:
        def resolve(b):
            return solver(outcome.targets, b, progress=progress)
    body, again, new_span = cal.adapt_arms_to_reach(result, resolve)
    if new_span is None:
        return result
    after = int((again.reach_error[:, :2] > 0.005).any(1).sum())
    outcome.info.append(f"arm span {new_span:.2f} m from the recording's reach (no T-pose; hands off their "
                        f"trackers on {before} frame(s) with proportional arms, {after} now)")
    stature = float(body.stature)
    if (not settings.height and str(settings.posture or "standing").lower() == "standing"
            and new_span > ARM_SPAN_SITS_RATIO * stature and stature >= cal.PLAUSIBLE_STATURE[0]):
        outcome.info.append(long_reach_note(outcome, new_span, stature))
    outcome.body = body
    return again


# --------------------------------------------------------------------------
#: progress fractions at the stage boundaries
STAGES = {"reading recording": 0.0, "resampling": 0.09, "calibrating": 0.16, "solving": 0.22, "done": 1.0}


def device_targets(out: SolveOutcome, settings: SolveSettings, teleports="keep"):
    """The middle stages of :func:`solve_recording` on ``out.recording``: times in seconds,
    teleports found (``teleports`` mode), resampled onto the ``settings.fps`` grid, smoothed,
    left/right swaps undone, device offsets, the floor moved to 0, a headset lying off pointed
    out.  Sets ``out.report``, ``out.targets`` and ``out.floor``.  Returns ``(times, pos, quat,
    valid, offsets, notes, smoothing_note, jumps)``: the resampled device poses (device → ``(T,
    3)`` m / ``(T, 4)`` wxyz / ``(T,)`` bool), the validated offsets, the summary's notes so far
    and the teleports (:class:`.teleports.RigJump`)."""
    from .resample import seconds_from_time_units
    out.recording = seconds_from_time_units(out.recording)      # before anything measures speeds
    jumps, continuous, unconfirmed = [], out.recording, []
    if teleports != "ignore":      # over the whole take, trim or not: the calibration and the floor
        jumps = find_rig_jumps(out.recording, unconfirmed)   # are measured on all of it, and a part is the whole's
        continuous = remove_rig_jumps(out.recording, jumps)
    eye_level = eye_level_origin(continuous, settings)       # no floor at 0: found below
    times, pos, quat, valid, out.report = resample_recording(
        continuous, settings.fps, FLOOR_FROM_HEIGHT if eye_level else settings.floor)
    if settings.max_frames is not None and settings.max_frames > 0 and len(times) > settings.max_frames:
        n = int(settings.max_frames)
        times = times[:n]
        pos = {d: v[:n] for d, v in pos.items()}
        quat = {d: v[:n] for d, v in quat.items()}
        valid = {d: v[:n] for d, v in valid.items()}
    from .smoothing import parse_smoothing, smooth_device_poses, smoothing_note
    smoothing = parse_smoothing(settings.smoothing)
    pos, quat, windows = smooth_device_poses(pos, quat, settings.fps, smoothing)
    smoothed = smoothing_note(smoothing, list(windows.values()) if windows else None, "device")
    sides = []
    if settings.fix_sides:
        sides = fix_swapped_sides(pos, quat, valid, settings.fps)
    resolved = resolve_offsets(settings.offsets, out.recording)
    out.targets, offsets = make_targets(times, pos, quat, valid, settings.fps, resolved)

    def floor_of(targets):               # (floor, how it was found when the settings did not say)
        return eye_level_floor(settings, targets) if eye_level else (floor_height(settings, targets), None)

    out.floor, out.floor_why = floor_of(out.targets)
    out.targets = move_floor(out.targets, out.floor)
    guessed = None
    if _offsets_unstated(settings.offsets, resolved, out.recording):      # a headset's poses after all?
        from .offsets_auto import HEADSET_PRESET, headset_evidence
        as_headset, headset_offsets = make_targets(times, pos, quat, valid, settings.fps, HEADSET_PRESET)
        headset_floor, headset_why = floor_of(as_headset)
        labels = (out.recording.metadata or {}).get("device_labels") or {}
        preset, guessed = headset_evidence(out.targets, move_floor(as_headset, headset_floor), float(times[0]),
                                           labels.get("head"))
        if preset is not None:
            resolved, offsets, out.floor, out.floor_why = preset, headset_offsets, headset_floor, headset_why
            out.targets = move_floor(as_headset, headset_floor)
    note = offsets_note(settings.offsets, resolved, out.recording, guessed)
    first, last = headset_off(out.targets.pos["head"], out.targets.rot["head"], settings.fps,
                              out.targets.valid.get("head"))
    out.headset_off = (first, last)
    T, fps = len(times), settings.fps
    if settings.start is not None and settings.start >= first / fps - 0.05:
        first = 0                        # trimmed away already
    if settings.end is not None and settings.end <= (T - last) / fps + 0.05:
        last = 0
    off_notes = headset_off_note(first, last, T, fps, out.targets.pos["head"], out.targets.rot["head"])
    notes = [n for n in (note, *sides, *off_notes, unconfirmed_jumps_note(unconfirmed, float(times[0]))) if n]
    return times, pos, quat, valid, offsets, notes, smoothed, jumps


#: calibrations measured on calibration takes, newest last: a batch solves many takes against the
#: same one, which is then read once (key: the file's path, size and time, the settings)
_CALIBRATION_TAKES = OrderedDict()
_CALIBRATION_TAKES_LOCK = threading.Lock()
CALIBRATION_TAKES_KEPT = 4


def calibration_from_take(settings: SolveSettings, teleports="keep", devices=()):
    """``(body, offsets, info)`` calibrated on the T- or A-pose of another recording,
    ``settings.calibration_take`` (a session's calibration take: the same performer, the same
    trackers strapped on the same way), read, resampled and calibrated as :func:`calibrate` does
    with ``settings`` (Auto or T-pose time; typed height and arm span still win).  The notes
    name the take, and the solved take's ``devices`` the calibration take lacks (their offsets
    are not measured).  Raises :class:`SolveError` when it holds no usable pose.

    The last :data:`CALIBRATION_TAKES_KEPT` calibrations are kept (each caller gets its own
    copy): the takes of a batch are calibrated on one read of the file, read again when it
    changes (size or modification time) or the settings do."""
    import dataclasses
    path = settings.calibration_take
    mode = (settings.calibration or "AUTO").upper()
    if mode == "MEASURE":
        raise SolveError("a calibration take needs Auto or T-pose calibration (measurements come from the "
                         "typed height)")
    cal_settings = dataclasses.replace(settings, start=None, end=None, max_frames=None, calibration_take=None)
    try:
        st = os.stat(path)
        key = (os.path.abspath(os.fspath(path)), st.st_size, st.st_mtime_ns, repr(cal_settings), teleports)
    except (OSError, TypeError):
        key = None                       # not a file (read_recording says what is wrong)
    with _CALIBRATION_TAKES_LOCK:
        hit = _CALIBRATION_TAKES.get(key) if key is not None else None
    if hit is None:
        hit = _calibrate_on_take(path, cal_settings, teleports)
        if key is not None:
            with _CALIBRATION_TAKES_LOCK:
                _CALIBRATION_TAKES[key] = hit
                while len(_CALIBRATION_TAKES) > CALIBRATION_TAKES_KEPT:
                    _CALIBRATION_TAKES.popitem(last=False)
    body, offsets, info, have = copy.deepcopy(hit)
    missing = [d for d in devices if d in ("pelvis", "left_foot", "right_foot") and d not in have]
    if missing:
        info.append(f"{', '.join(d.replace('_', ' ') for d in missing)} tracker offsets not measured (not in "
                    f"the calibration take {os.path.basename(os.fspath(path))}): their poses are taken as "
                    f"the joints'")
    return body, offsets, info


def _calibrate_on_take(path, cal_settings, teleports):
    """:func:`calibration_from_take`'s measurement: ``(body, offsets, info, devices the take has)``."""
    import re
    name = os.path.basename(os.fspath(path))
    from .recording import RecordingError
    cal = SolveOutcome()
    try:
        cal.recording = read_recording(path, cal_settings)
    except RecordingError as exc:
        raise SolveError(f"calibration take: {exc}") from exc
    times, _, _, _, offsets, _, _, _ = device_targets(cal, cal_settings, teleports)
    body, offsets, info = calibrate(cal_settings, cal.targets, times, offsets)
    if not any(n.startswith("calibrated on") for n in info):
        raise SolveError(f"calibration take {name}: no T- or A-pose found in it ({'; '.join(info) or 'no notes'})")
    out = []
    for n in info:
        n = re.sub(r"^(calibrated on an? [TA]-pose at [\d.]+ s)", lambda m: f"{m.group(1)} of {name}", n)
        n = n.replace("(from the T-pose)", f"(from the T-pose of {name})").replace(
            "(from the A-pose)", f"(from the A-pose of {name})")
        out.append(n)
    return body, offsets, out, tuple(cal.targets.pos)


def solve_recording(source, settings: SolveSettings | None = None, solver=None, progress=None) -> SolveOutcome:
    """Solve a recording: ``source`` is a file path or a :class:`.recording.Recording`
    (e.g. sampled from scene objects).  Keypoint inputs (a FreeMoCap folder, ``.npy`` / ``.npz``,
    a keypoint CSV: :func:`.io_keypoints.is_keypoint_input`) go to
    :func:`.keypoint_solve.solve_keypoints`.

    solver: ``(targets, body, progress) -> PoseResult`` (default :func:`default_solver`).
    progress: optional ``(fraction 0-1, stage text)`` callback; an exception raised from it
    (a cancel) stops the solve.  Returns the :class:`SolveOutcome`; raises :class:`SolveError`
    for what the user can fix."""
    settings = settings or SolveSettings()
    try:
        overlap_windows(settings.overlap)        # any solver gets it from the settings: check it once
    except ValueError as exc:
        raise SolveError(str(exc)) from None
    if solver is None:
        def solver(targets, body, progress=None):
            return default_solver(targets, body, progress=progress, model=settings.model,
                                  overlap=settings.overlap)
    report = progress or (lambda f, stage=None: None)
    if settings.fps is None or not settings.fps > 0:
        raise SolveError("no frame rate: set fps")
    parse_floor(settings.floor)                  # a bad floor setting fails before the file is read
    posture = str(settings.posture or "standing").strip().lower()
    if posture not in POSTURES:
        raise SolveError(f"posture {shown(settings.posture)}: expected one of {', '.join(POSTURES)}")
    mode = str(settings.teleports or "keep").strip().lower()
    if mode not in TELEPORT_CHOICES:
        raise SolveError(f"teleports {shown(settings.teleports)}: expected one of {', '.join(TELEPORT_CHOICES)}")
    from .io_keypoints import KeypointRecording, is_keypoint_input
    if isinstance(source, KeypointRecording) or (
            (isinstance(source, str) or hasattr(source, "__fspath__")) and is_keypoint_input(source)):
        from .keypoint_solve import solve_keypoints      # 3D keypoints: HybrIK, no network
        return solve_keypoints(source, settings, progress=progress)
    out = SolveOutcome()
    t = _time.perf_counter()
    if isinstance(source, (str, bytes)) or hasattr(source, "__fspath__"):
        report(STAGES["reading recording"], "reading recording")
        out.recording = read_recording(source, settings)
        out.timings["read"] = _time.perf_counter() - t
    else:
        out.recording = source
    report(STAGES["resampling"], "resampling")
    t = _time.perf_counter()
    times, pos, quat, valid, offsets, pre_notes, smoothed, jumps = device_targets(out, settings, mode)
    out.timings["resample"] = _time.perf_counter() - t
    report(STAGES["calibrating"], "calibrating")
    t = _time.perf_counter()
    if settings.calibration_take:       # calibrated on another take's T-pose (the session's)
        out.body, out.offsets, out.info = calibration_from_take(settings, mode, tuple(out.targets.pos))
    else:
        out.body, out.offsets, out.info = calibrate(settings, out.targets, times, offsets)
    for extra in pre_notes:
        out.info.append(extra)
    if out.offsets is not offsets:     # calibration refined the device rotations
        out.targets = move_floor(make_targets(times, pos, quat, valid, settings.fps, out.offsets)[0], out.floor)
    if any(d in out.targets.pos for d in FOOT_DEVICES):     # a foot tracker's strap slipped mid-take
        rest = float(out.body.rest_positions()[sk.J["left_ankle"], 2])
        out.slips = find_tracker_slips(out.targets, settings.fps, rest_ankle_z=rest)
        out.targets = correct_tracker_slips(out.targets, out.slips)
        out.info.extend(tracker_slip_notes(out.slips, settings.fps))
    out.targets, lost = relax_lost_hands(out.targets, out.body)     # long hand gaps: the arm hangs
    out.info.extend(lost)
    notes = (floor_note(settings, out.floor, out.floor_why),) if posture == "seated" else \
        (floor_note(settings, out.floor, out.floor_why), stature_note(settings, out), head_height_note(settings, out))
    for note in notes:
        if note:
            out.info.append(note)
    out.info.append(smoothed)
    span = trim_span(times, settings.start, settings.end)
    solve_times = times
    if span is not None:             # calibrated on the whole take; solved with a margin, then cut
        margin = int(round(TRIM_MARGIN_S * settings.fps))
        align = max(int(round(TRIM_ALIGN_S * settings.fps)), 1)
        lo, hi = max(0, (span[0] - margin) // align * align), min(len(times), span[1] + margin)
        off_first, off_last = out.headset_off        # the context stops where a headset lay off
        if off_first and span[0] >= off_first:
            lo = max(lo, off_first)
        if off_last and span[1] <= len(times) - off_last:
            hi = min(hi, len(times) - off_last)
        solved = slice(lo, hi)
        out.targets, solve_times = out.targets.frames(solved), times[solved]
        out.info.append(f"trimmed to {times[span[0]] - times[0]:.2f}-{times[span[1] - 1] - times[0]:.2f} s")
    if jumps:
        out.info.append(rig_jumps_note(jumps, mode, float(times[0])))
        out.jumps = list(jumps)
    out.timings["calibrate"] = _time.perf_counter() - t
    report(STAGES["solving"], "solving")
    t = _time.perf_counter()
    lo, hi = STAGES["solving"], STAGES["done"]

    def solve_progress(f):
        report(lo + (hi - lo) * 0.5 * float(f))

    result = solver(out.targets, out.body, progress=solve_progress)
    first = result
    result = adapt_arms(settings, out, result, solver,
                        progress=lambda f: report(lo + (hi - lo) * (0.5 + 0.5 * float(f)),
                                                  "solving again with arms for the reach"))
    result.with_body = None      # frees the network output (long takes)
    result.t0 = float(solve_times[0])
    if result.targets is None:
        result.targets = out.targets
    if span is not None:
        keep = slice(span[0] - solved.start, span[1] - solved.start)
        result = result.frames(keep)
        out.targets = out.targets.frames(keep)
    if posture == "seated":              # a leg whose foot has a tracker stays on it
        result = seat_legs(result, legs=[k for k, d in enumerate(("left_foot", "right_foot"))
                                         if d not in out.targets.pos])
    if jumps and mode == "keep":         # the solved body goes where the recording went
        result = restore_rig_jumps(result, jumps)
        out.targets = result.targets
    out.result = result
    out.timings["solve"] = _time.perf_counter() - t
    stage_times = dict(getattr(first, "timings", None) or {})      # network / solver split
    if result is not first:       # arm adaptation re-solved: its time counts to its stages
        for k, v in (getattr(result, "timings", None) or {}).items():
            stage_times[k] = stage_times.get(k, 0.0) + v
    for k, v in stage_times.items():
        out.timings[f"solve.{k}"] = v
    report(STAGES["done"], "done")
    return out
