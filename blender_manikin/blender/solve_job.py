"""The full-body solve as a job: source → targets → body → pose → scene.

Shared by the operator (modal, cancellable, progress in the UI) and the
command line (synchronous).  The stages are

1. :meth:`SolveJob.gather` (main thread): for scene sources, sample the mapped
   objects into a :class:`~blender_manikin.core.recording.Recording`;
2. :meth:`SolveJob.compute` (any thread, numpy/onnxruntime only, never
   touches Blender data): load the file, resample to the frame rate, apply
   device offsets, calibrate the body, run :func:`pipeline.solve`;
3. :meth:`SolveJob.write` (main thread): create the armature / action /
   empties in one all-or-nothing step (:func:`.writer.write_result`).

Nothing in the scene changes before stage 3, so cancelling (Esc in the UI,
:meth:`SolveJob.cancel`) or a failure in stages 1-2 leaves no data behind, and
an undo step after stage 3 restores the scene completely.

Times: the recording clock in seconds.  ``SolveConfig.tpose_time`` is seconds
after the first tracker sample (what the timeline shows: the solve's frame
``k`` is at ``k / fps`` after the first sample).
"""
from __future__ import annotations

import threading
import time as _time
from dataclasses import dataclass, field

import numpy as np

from ..core import skeleton as sk
from ..core.pose_result import TrackerTargets

UNDO_MESSAGE = "MANIKIN: Solve Full Body"

#: stage boundaries of the overall progress fraction
_P_LOAD, _P_RESAMPLE, _P_BODY, _P_SOLVE, _P_WRITE = 0.08, 0.15, 0.2, 0.92, 1.0


class SolveError(RuntimeError):
    """A problem the user can fix (bad settings, bad recording); the message says what."""


try:   # the pipeline's own cancellation exception when it exists
    from ..core.pipeline import SolveCancelled   # noqa: F401
except Exception:                                # pragma: no cover - pipeline not importable
    class SolveCancelled(Exception):
        """The user cancelled the solve."""


@dataclass
class SolveConfig:
    """Everything a solve needs, as plain values (from the panel or the command line).

    source: ``"FILE"`` (``filepath``) or ``"SCENE"`` (``scene_sources``:
    device → ``(object name, bone name or "")``, sampled over
    ``scene_frames`` = (first, last) scene frame).
    axes / units: override the file's metadata (None = file / format default).
    fps: solve frame rate (None = the scene's).
    calibration: ``"AUTO"`` (calibrate on the most T-pose-like moment when
    one is plausible, else stature from the standing head height), ``"TPOSE"``
    (calibrate on the T-pose at ``tpose_time`` seconds after the first
    sample) or ``"MEASURE"`` (``height`` and optional ``arm_span``, metres).
    With TPOSE/AUTO a given ``height`` overrides the measured stature.
    offsets: device offsets preset name (``"none"`` when the devices already
    give joint poses; ``"auto"``: see :func:`resolve_offsets`) or an offsets
    dict (:mod:`core.device_offsets`).  frame_start: scene frame of the first solved frame;
    max_frames: crop (None = whole recording).
    live_rig: convert the solved armature to the live swivel rig
    (:mod:`.live_rig`): elbows/knees follow the swivel properties and the
    hand/foot controls.  False keeps plain FK keys only.
    """
    source: str = "FILE"
    filepath: str = ""
    axes: str | None = None
    units: str | None = None
    fps: float | None = None
    calibration: str = "AUTO"
    tpose_time: float | None = None
    height: float | None = None
    arm_span: float | None = None
    offsets: str = "auto"
    frame_start: int = 1
    max_frames: int | None = None
    create_trackers: bool = False
    live_rig: bool = True
    set_scene_range: bool = False
    armature_name: str = "MANIKIN_body"
    reuse_armature: object = None
    scene_sources: dict = field(default_factory=dict)
    scene_frames: tuple | None = None


# --------------------------------------------------------------------------
# numpy stages (no bpy)
def _check_cancel(flag):
    if flag is not None and flag.is_set():
        raise SolveCancelled("cancelled")


def load_source(config: SolveConfig):
    """Read ``config.filepath`` into a Recording (Blender axes, metres)."""
    from ..core.recording import load_recording
    if not config.filepath:
        raise SolveError("no recording file chosen")
    return load_recording(config.filepath, axes=config.axes, units=config.units)


def resample_recording(recording, fps):
    """``(times, pos, quat, valid, report)`` on a grid at ``fps`` (see :func:`core.resample.resample`)."""
    from ..core.resample import resample
    return resample(recording, fps)


def resolve_offsets(offsets, recording):
    """``"auto"`` → the preset the recording implies, else ``offsets`` unchanged.

    auto: the file's ``# offsets: PRESET`` metadata when it names a preset;
    ``beat_saber`` for a ``.bsor`` replay (its hand poses are saber poses);
    otherwise ``none`` (the device poses are taken as joint poses).
    """
    if not (isinstance(offsets, str) and offsets.lower() == "auto"):
        return offsets
    from ..core import device_offsets
    meta = (getattr(recording, "metadata", None) or {}).get("offsets")
    if isinstance(meta, str) and meta.strip() in device_offsets.PRESET_NAMES:
        return meta.strip()
    if str(getattr(recording, "source", "")).lower().endswith(".bsor"):
        return "beat_saber"
    return "none"


def make_targets(times, pos, quat, valid, fps, offsets="none"):
    """Joint targets from resampled device poses after device ``offsets``.

    offsets: a preset name (:data:`core.device_offsets.PRESET_NAMES`;
    ``"none"``: the device poses are the joint poses) or an offsets dict
    (see :mod:`blender_manikin.core.device_offsets`).
    """
    from ..core import device_offsets
    try:
        off = device_offsets.validate_offsets(offsets if offsets not in ("", None) else "none")
    except ValueError as exc:
        raise SolveError(f"device offsets: {exc}") from exc
    return device_offsets.to_targets(times, pos, quat, valid, off, fps=fps), off


def body_from_head_height(targets: TrackerTargets, height=None, arm_span=None) -> sk.Body:
    """A body when no calibration pose is available.

    stature = ``height`` (metres) if given, else the 90th percentile of the
    head joint height / 0.910 (standing; :data:`skeleton.PROPORTIONS`),
    clipped to 1.0-2.3 m.
    """
    if height is None:
        head_z = np.asarray(targets.pos["head"])[:, 2]
        height = float(np.clip(np.nanpercentile(head_z, 90) / sk.PROPORTIONS["head_height"], 1.0, 2.3))
    try:
        return sk.make_body(sk.BodyMeasurements(stature=float(height), arm_span=arm_span or None))
    except ValueError as exc:
        raise SolveError(f"body measurements: {exc}") from exc


def calibrate(config: SolveConfig, targets: TrackerTargets, times, offsets):
    """The performer's body for ``config.calibration`` (see :class:`SolveConfig`).

    Returns ``(body, offsets, info)``: the offsets refined by a T/A-pose
    calibration (else unchanged), and ``info``, a list of human-readable
    notes (the calibration moment, implausibility warnings).
    """
    from ..core import calibration as cal
    mode = (config.calibration or "AUTO").upper()
    info = []
    if mode == "MEASURE":
        if not config.height or config.height <= 0:
            raise SolveError("calibration by measurements needs a height (metres)")
        return body_from_head_height(targets, config.height, config.arm_span), offsets, info
    t0 = float(times[0])
    meas = {"stature": float(config.height)} if config.height else None
    if config.arm_span and meas is not None:
        meas["arm_span"] = float(config.arm_span)
    if mode == "TPOSE":
        if config.tpose_time is None:
            raise SolveError("T-pose calibration needs the time of the T-pose")
        dur = float(times[-1] - times[0])
        if not (-1e-6 <= float(config.tpose_time) <= dur + 1e-6):
            raise SolveError(f"T-pose time {config.tpose_time:.3f} s is outside the recording "
                             f"(0-{dur:.3f} s after the first sample)")
        t = t0 + float(config.tpose_time)
    else:   # AUTO: the most T-pose-like moment, if it is plausible
        cand = cal.find_tpose(targets, t0=t0)
        if not cand.plausible:
            info.append("no T-pose found: stature from the standing head height")
            return body_from_head_height(targets, config.height, config.arm_span), offsets, info
        t = cand.time
    try:
        res = cal.calibrate(targets, time=t, offsets=offsets, t0=t0, measurements=meas)
        body = cal.body_for(res.measurements)
    except ValueError as exc:
        raise SolveError(f"calibration at {t - t0:.2f} s: {exc}") from exc
    info.append(f"calibrated on a {res.pose}-pose at {t - t0:.2f} s: stature "
                f"{res.measurements.stature:.2f} m, arm span {res.measurements.arm_span or 0:.2f} m")
    info += [f"calibration: {p}" for p in res.problems]
    return body, res.offsets, info


def run_solver(targets, body, progress=None):
    """:func:`blender_manikin.core.pipeline.solve` (separate so tests can replace it)."""
    from ..core import pipeline
    return pipeline.solve(targets, body, progress=progress)


# --------------------------------------------------------------------------
class SolveJob:
    """One solve; see the module docstring for the stages and threading rules.

    Attributes after a run: ``recording``, ``report`` (resampling
    :class:`GapReport` or None), ``targets``, ``body``, ``result``
    (:class:`PoseResult`), ``output`` (:class:`.writer.WriteOutput`),
    ``error`` (exception of a failed background run), ``timings`` (seconds
    per stage), ``progress`` (0-1) and ``stage`` (text).
    """

    def __init__(self, config: SolveConfig):
        self.config = config
        self.recording = None
        self.report = None
        self.targets = None
        self.body = None
        self.offsets = None
        self.info = []
        self.result = None
        self.output = None
        self.error = None
        self.progress = 0.0
        self.stage = "starting"
        self.timings = {}
        self._cancel = threading.Event()
        self._thread = None

    # -- progress / cancel
    def cancel(self):
        """Ask the job to stop; the background stage raises :class:`SolveCancelled` soon."""
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    def _set(self, fraction, stage=None):
        self.progress = float(fraction)
        if stage:
            self.stage = stage
        _check_cancel(self._cancel)

    # -- stage 1 (main thread)
    def gather(self, context):
        """Sample scene sources (main thread).  No-op for file sources."""
        cfg = self.config
        if cfg.source.upper() != "SCENE":
            return
        from .scene_trackers import sample_sources, SceneSourceError
        scene = context.scene
        start, end = cfg.scene_frames or (scene.frame_start, scene.frame_end)
        t = _time.perf_counter()
        self._set(0.0, "sampling scene objects")
        try:
            self.recording = sample_sources(
                scene, cfg.scene_sources, start, end,
                progress=lambda f: self._set(_P_LOAD * f))
        except SceneSourceError as exc:
            raise SolveError(str(exc)) from exc
        if cfg.fps is None:
            cfg.fps = self.recording.metadata["fps"]
        cfg.frame_start = int(start)
        self.timings["read"] = _time.perf_counter() - t

    # -- stage 2 (any thread)
    def compute(self):
        """Load, resample, offsets, calibration, solve.  Sets ``self.result``."""
        cfg = self.config
        if cfg.fps is None or not cfg.fps > 0:
            raise SolveError("no frame rate: set fps")
        t = _time.perf_counter()
        if self.recording is None:
            self._set(0.0, "reading recording")
            self.recording = load_source(cfg)
            self.timings["read"] = _time.perf_counter() - t
        self._set(_P_LOAD, "resampling")
        t = _time.perf_counter()
        times, pos, quat, valid, report = resample_recording(self.recording, cfg.fps)
        self.report = report
        if cfg.max_frames is not None and cfg.max_frames > 0 and len(times) > cfg.max_frames:
            n = int(cfg.max_frames)
            times = times[:n]
            pos = {d: v[:n] for d, v in pos.items()}
            quat = {d: v[:n] for d, v in quat.items()}
            valid = {d: v[:n] for d, v in valid.items()}
        self.targets, offsets = make_targets(times, pos, quat, valid, cfg.fps,
                                             resolve_offsets(cfg.offsets, self.recording))
        self.timings["resample"] = _time.perf_counter() - t
        self._set(_P_RESAMPLE, "calibrating")
        t = _time.perf_counter()
        self.body, self.offsets, self.info = calibrate(cfg, self.targets, times, offsets)
        self._check_stature()
        if self.offsets is not offsets:     # calibration refined the device rotations
            self.targets, _ = make_targets(times, pos, quat, valid, cfg.fps, self.offsets)
        self.timings["calibrate"] = _time.perf_counter() - t
        self._set(_P_BODY, "solving")
        t = _time.perf_counter()
        span = _P_SOLVE - _P_BODY
        result = run_solver(self.targets, self.body,
                            progress=lambda f: self._set(_P_BODY + span * float(f)))
        result = self._adapt_arms(result, progress_width=span)
        result.t0 = float(times[0])
        if result.targets is None:
            result.targets = self.targets
        self.result = result
        self.timings["solve"] = _time.perf_counter() - t
        for k, v in getattr(result, "timings", {}).items():     # network / solver split
            self.timings[f"solve.{k}"] = v
        self._set(_P_SOLVE, "writing")
        return result

    def _check_stature(self):
        """Warn (``self.info``, the summary) when the body's stature is implausible."""
        from ..core import calibration as cal
        cfg = self.config
        if cfg.height:                      # a typed height always wins
            sized_by = "height setting"
        elif any(n.startswith("calibrated") for n in self.info):
            sized_by = "T-pose"
        else:
            sized_by = "head height"
        head = np.asarray(self.targets.pos["head"])[:, 2]
        units = (getattr(self.recording, "metadata", None) or {}).get("units", "m") if cfg.units is None else cfg.units
        note = cal.stature_warning(self.body.stature, float(np.nanpercentile(head, 90)), sized_by, units)
        if note:
            self.info.append(note)

    def _adapt_arms(self, result, progress_width):
        """Lengthen arms built from proportions when the hands cannot reach their trackers.

        Only when no arm span was measured (no T/A-pose calibration) or given:
        the span comes from :func:`core.calibration.arm_span_for_reach` and the
        recording is solved again with it.  Notes it in ``self.info``.
        """
        from ..core import calibration as cal
        if self.config.arm_span or any(n.startswith("calibrated") for n in self.info):
            return result
        if result.reach_error is None or not (result.reach_error[:, :2] > 0.005).any():
            return result
        before = int((result.reach_error[:, :2] > 0.005).any(1).sum())
        self._set(_P_BODY + 0.5 * progress_width, "solving again with arms for the reach")
        def progress(f):
            self._set(_P_BODY + progress_width * (0.5 + 0.5 * float(f)))

        body, again, new_span = cal.adapt_arms_to_reach(
            result, lambda b: run_solver(self.targets, b, progress=progress))
        if new_span is None:
            return result
        after = int((again.reach_error[:, :2] > 0.005).any(1).sum())
        self.info.append(f"arm span {new_span:.2f} m from the recording's reach (no T-pose; hands off their "
                         f"trackers on {before} frame(s) with proportional arms, {after} now)")
        self.body = body
        return again

    # -- stage 3 (main thread)
    def write(self, context):
        """Create the armature, action and empties (all or nothing).  Sets ``self.output``."""
        from . import writer
        _check_cancel(self._cancel)
        cfg = self.config
        t = _time.perf_counter()
        opts = writer.WriteOptions(frame_start=cfg.frame_start, armature=cfg.reuse_armature,
                                   armature_name=cfg.armature_name,
                                   create_trackers=cfg.create_trackers,
                                   set_scene_range=cfg.set_scene_range)
        out = writer.write_result(self.result, opts, context=context)
        self.timings["keying"] = _time.perf_counter() - t
        t = _time.perf_counter()
        if cfg.live_rig:
            from . import live_rig
            try:
                out.live_action = live_rig.build_live_rig(out.armature, self.result, frames=out.frames,
                                                          context=context)
            except BaseException:
                writer.remove_output(out)
                raise
        elif out.armature is not None:
            from . import live_rig
            if live_rig.is_live_rig(out.armature):      # re-solved onto a live rig: plain FK wins
                live_rig.set_rig_enabled(out.armature, False)
        self.output = out
        if cfg.live_rig:
            self.timings["live rig"] = _time.perf_counter() - t
        self.progress = 1.0
        self.stage = "done"
        return self.output

    # -- synchronous
    def run(self, context):
        """All stages in this thread (command line, ``EXEC_DEFAULT``)."""
        self.gather(context)
        self.compute()
        return self.write(context)

    # -- background (modal operator)
    def start_background(self):
        """Run :meth:`compute` in a worker thread; poll :attr:`done`."""
        def work():
            try:
                self.compute()
            except BaseException as exc:       # reported by the main thread
                self.error = exc
        self._thread = threading.Thread(target=work, name="MANIKIN solve", daemon=True)
        self._thread.start()

    @property
    def done(self) -> bool:
        return self._thread is not None and not self._thread.is_alive()

    def join(self, timeout=None):
        if self._thread is not None:
            self._thread.join(timeout)

    def summary(self) -> str:
        """One line: frames, fps, stature, devices, gaps, where the solve gave way, timings."""
        parts = []
        if self.result is not None:
            parts.append(f"{self.result.num_frames} frames at {self.result.fps:g} fps")
            parts.extend(self.result.quality_notes())
        if self.body is not None:
            parts.append(f"stature {self.body.stature:.2f} m")
        for note in self.info:
            if note.startswith(("calibrated", "arm span", "estimated stature")):
                parts.append(note)
        if self.report is not None:
            gaps = getattr(self.report, "gaps", [])
            if gaps:
                parts.append(f"{len(gaps)} gap(s) bridged")
        if self.timings:
            parts.append(", ".join(f"{k} {v:.2f}s" for k, v in self.timings.items()))
        return "; ".join(parts)


def error_message(exc) -> str:
    """A one-line, user-readable message for ``exc`` (no traceback)."""
    msg = str(exc).strip() or exc.__class__.__name__
    if isinstance(exc, (SolveError, ValueError, OSError, RuntimeError)) or \
            exc.__class__.__name__ in ("RecordingError", "ModelError"):
        return msg
    return f"{exc.__class__.__name__}: {msg}"


def find_tpose_time(config: SolveConfig, context=None):
    """Propose the T-pose moment of the source of ``config``.

    Returns ``(seconds after the first tracker sample, candidate)`` where
    candidate is a :class:`core.calibration.TPoseCandidate` (``plausible``
    tells whether it looks like a still T-pose).
    """
    from ..core import calibration as cal
    job = SolveJob(config)
    if config.source.upper() == "SCENE":
        job.gather(context)
    else:
        job.recording = load_source(config)
    if config.fps is None:
        raise SolveError("no frame rate: set fps")
    times, pos, quat, valid, _ = resample_recording(job.recording, config.fps)
    targets, _ = make_targets(times, pos, quat, valid, config.fps,
                              resolve_offsets(config.offsets, job.recording))
    cand = cal.find_tpose(targets, t0=float(times[0]))
    return float(cand.time - times[0]), cand
