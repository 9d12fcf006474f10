"""The full-body solve as a job: source → targets → body → pose → scene.

Shared by the operator (modal, cancellable, progress in the UI) and the
command line (synchronous).  The stages are

1. :meth:`SolveJob.gather` (main thread): for scene sources, sample the mapped
   objects into a :class:`~blender_manikin.core.recording.Recording`;
2. :meth:`SolveJob.compute` (any thread, numpy/onnxruntime only, never
   touches Blender data): :func:`blender_manikin.core.solve.solve_recording`
   (read, resample, device offsets, calibration, network and limbs);
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

import functools
import os
import threading
import time as _time
from dataclasses import dataclass, field


UNDO_MESSAGE = "MANIKIN: Solve Full Body"
#: custom property of a solve's actions: what was solved (the recording's path, or the scene
#: objects), next to the take's name in the action's own name (``MANIKIN_live_<take>``)
PROP_SOURCE = "manikin_source"

#: stage boundaries of the overall progress fraction
_P_LOAD, _P_SOLVE = 0.08, 0.92


from ..core.pipeline import SolveCancelled  # noqa: E402,F401  (raised through the job on cancel)
from ..core import solve as core_solve  # noqa: E402
from ..core.solve import SolveError, SolveSettings, error_message, resolve_offsets  # noqa: E402,F401


@dataclass
class SolveConfig(SolveSettings):
    """Everything a solve needs, as plain values (from the panel or the command line): the solve
    options of :class:`core.solve.SolveSettings` (axes, units, fps, calibration, tpose_time,
    height, arm_span, offsets, max_frames, layout; here ``fps`` None means the scene's), and
    what Blender adds.

    source: ``"FILE"`` (``filepath``: a recording, or keypoints recognised by their file),
    ``"KEYPOINTS"`` (``filepath``: 3D keypoints, :mod:`core.keypoint_solve`) or ``"SCENE"``
    (``scene_sources``: device → ``(object name, bone name or "")``, sampled over
    ``scene_frames`` = (first, last) scene frame).
    frame_start: scene frame of the first solved frame (scene sources: where the solve starts,
    :meth:`SolveJob.first_frame`).  create_trackers: also key tracker
    empties.  body_mesh: give the armature the mannequin mesh (:mod:`.body_mesh`).  live_rig:
    convert the solved armature to the live swivel rig (:mod:`.live_rig`):
    elbows/knees follow the swivel properties and the hand/foot controls; False keeps plain FK
    keys only.  mark_problems: timeline markers where the solve is worth a look
    (:mod:`core.review_marks`).  set_scene_range, armature_name, reuse_armature: how the result is
    written.  take: the take's name when it is not the file's (one person of a keypoint file with
    several: ``<file>_p<label>``, :func:`person_configs`).  keypoints: that person's
    :class:`core.io_keypoints.KeypointRecording`, already read (solved instead of the file).
    """
    fps: float | None = None
    source: str = "FILE"
    filepath: str = ""
    frame_start: int = 1
    create_trackers: bool = False
    body_mesh: bool = True
    live_rig: bool = True
    set_scene_range: bool = False
    mark_problems: bool = True
    armature_name: str = "MANIKIN_body"
    reuse_armature: object = None
    scene_sources: dict = field(default_factory=dict)
    scene_frames: tuple | None = None
    keypoint_collection: str | None = None
    keypoint_armature: str | None = None      # an animated armature's bones as keypoints
    keypoint_bone_map: str = "auto"           # its bone map: auto, a preset, file (keypoint_map_file)
    keypoint_map_file: str | None = None
    marker_take: str | None = None     # timeline markers named "MANIKIN <take>: ..." (several takes)
    take: str | None = None            # the take's name when not the file's (a person: <file>_p<label>)
    keypoints: object = None           # a KeypointRecording already read (a person of a group file)

    def take_name(self) -> str:
        """The take's name for the actions a solve makes (``MANIKIN_live_<take>``): the recording
        file's (or keypoint folder's) name without its extension, ``scene`` for scene objects;
        ``take`` when given."""
        if self.take:
            return self.take
        if self.source.upper() == "KEYPOINTS" and self.keypoint_armature:
            return self.keypoint_armature
        if self.source.upper() == "KEYPOINTS" and self.keypoint_collection:
            return self.keypoint_collection
        if self.source.upper() == "SCENE" or not self.filepath:
            return "scene"
        path = os.path.normpath(str(self.filepath))
        return os.path.splitext(os.path.basename(path))[0] or os.path.basename(path)

    def source_description(self) -> str:
        """What was solved: the recording's path, or the scene objects of each device."""
        if self.source.upper() == "KEYPOINTS" and self.keypoint_armature:
            return f"bones of armature {self.keypoint_armature} ({self.keypoint_bone_map} map)"
        if self.source.upper() == "KEYPOINTS" and self.keypoint_collection:
            return f"keypoint objects of collection {self.keypoint_collection}"
        if self.source.upper() == "SCENE":
            return "scene objects: " + ", ".join(f"{d} {o}{'/' + b if b else ''}"
                                                 for d, (o, b) in self.scene_sources.items())
        return str(self.filepath)

    def settings(self) -> SolveSettings:
        """The solve options of this configuration (:class:`core.solve.SolveSettings`)."""
        return SolveSettings(**{k: getattr(self, k) for k in SolveSettings.__dataclass_fields__})


# --------------------------------------------------------------------------
# numpy stages (no bpy)
def _check_cancel(flag):
    if flag is not None and flag.is_set():
        raise SolveCancelled("cancelled")


def load_source(config: SolveConfig):
    """Read ``config.filepath`` into a Recording (Blender axes, metres)."""
    return core_solve.read_recording(config.filepath, config.settings())


def run_solver(targets, body, progress=None, model=None, overlap=None):
    """:func:`blender_manikin.core.solve.default_solver` (separate so tests can replace it)."""
    return core_solve.default_solver(targets, body, progress=progress, model=model, overlap=overlap)


# --------------------------------------------------------------------------
class SolveJob:
    """One solve; see the module docstring for the stages and threading rules.

    Attributes after a run: ``recording``, ``report`` (resampling
    :class:`GapReport` or None), ``targets``, ``body``, ``result``
    (:class:`PoseResult`), ``output`` (:class:`.writer.WriteOutput`),
    ``error`` (exception of a failed background run), ``timings`` (seconds
    per stage), ``progress`` (0-1) and ``stage`` (text).

    split_people: the config's keypoint file may hold several people (:func:`may_hold_people`):
    :meth:`compute` first reads it and lists them (:func:`person_configs`), in whichever thread
    runs it (the worker's in the modal operator, so a large group file never freezes Blender's
    window).  With several people it solves none of them: ``people`` is then one
    :class:`SolveConfig` per person (each with its recording), for :class:`SolveQueue` to solve
    one after another; with one, that person is solved (``config`` becomes theirs).
    """

    def __init__(self, config: SolveConfig, split_people: bool = False):
        self.config = config
        self.split_people = bool(split_people)
        self.people = None
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
        self.outcome = None
        self.scene_fps = None        # scene sources: the fps they were sampled at (first_frame)
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
        """Sample scene sources (main thread): tracker objects, keypoint objects of a collection,
        or an animated armature's bones.  No-op for file sources."""
        cfg = self.config
        if cfg.source.upper() == "KEYPOINTS" and (cfg.keypoint_armature or cfg.keypoint_collection):
            return self._gather_keypoints(context)
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
        self.scene_fps = float(self.recording.metadata["fps"])
        self.timings["read"] = _time.perf_counter() - t

    def _gather_keypoints(self, context):
        """Keypoints sampled in the scene: the objects of a collection named after a layout's
        points, or an animated armature's mapped bones."""
        import bpy
        from ..core.recording import RecordingError
        from .scene_trackers import SceneSourceError, sample_armature_keypoints, sample_keypoint_empties
        cfg = self.config
        scene = context.scene
        start, end = cfg.scene_frames or (scene.frame_start, scene.frame_end)
        progress = lambda f: self._set(_P_LOAD * f)          # noqa: E731
        if cfg.keypoint_armature:
            obj = bpy.data.objects.get(cfg.keypoint_armature)
            if obj is None:
                raise SolveError(f"no object named {cfg.keypoint_armature!r}")
            what, sample = "the armature's bones", lambda: sample_armature_keypoints(
                scene, obj, start, end, cfg.keypoint_bone_map, cfg.keypoint_map_file, progress=progress)
        else:
            coll = bpy.data.collections.get(cfg.keypoint_collection)
            if coll is None:
                raise SolveError(f"no collection named {cfg.keypoint_collection!r}")
            what, sample = "keypoint objects", lambda: sample_keypoint_empties(
                scene, list(coll.all_objects), start, end, progress=progress, source=f"collection {coll.name!r}")
        t = _time.perf_counter()
        self._set(0.0, f"sampling {what}")
        try:
            self.recording = sample()
        except (SceneSourceError, RecordingError) as exc:
            raise SolveError(str(exc)) from exc
        if cfg.fps is None:
            cfg.fps = float(scene.render.fps) / float(scene.render.fps_base)
        cfg.frame_start = int(start)
        self.scene_fps = float(scene.render.fps) / float(scene.render.fps_base)
        self.timings["read"] = _time.perf_counter() - t

    # -- stage 2 (any thread)
    def compute(self):
        """:func:`core.solve.solve_recording` on the file or the gathered scene recording.
        Sets ``self.result`` (and ``recording``, ``report``, ``targets``, ``body``, ``offsets``,
        ``info``, ``timings``); with ``split_people`` and several people in the file, sets
        ``self.people`` instead, solves nothing and returns None.  :meth:`cancel` stops it
        also while a file is read: the readers check it between chunks
        (:func:`core.recording.cancellable_reads`)."""
        from ..core.recording import cancellable_reads
        with cancellable_reads(lambda: _check_cancel(self._cancel)):
            return self._compute()

    def _compute(self):
        if self.split_people:
            self.split_people = False
            self._set(0.0, "reading the file's people")
            people = person_configs(self.config)
            _check_cancel(self._cancel)
            if people is not None and len(people) > 1:
                self.people = people
                self.stage = f"{len(people)} people found"
                return None
            if people:                               # one person: solved here, the file read once
                self.config = people[0]
        cfg = self.config
        source = self.recording if self.recording is not None else cfg.filepath
        if self.recording is None and cfg.keypoints is not None:      # one person of a group file, read
            source = cfg.keypoints
        if source is None or source == "":
            raise SolveError("no recording file chosen")
        timings = dict(self.timings)
        lo = _P_LOAD if self.recording is not None else 0.0      # scene sources were gathered already

        def progress(fraction, stage=None):
            self._set(lo + (_P_SOLVE - lo) * float(fraction), stage)

        if cfg.source.upper() == "KEYPOINTS":        # 3D keypoints: HybrIK, whatever the file's name
            from ..core.keypoint_solve import solve_keypoints
            out = solve_keypoints(source, cfg.settings(), progress=progress)
        else:
            choice = {}
            if cfg.model and str(cfg.model).strip().lower() != "auto":     # the user's choice of network
                choice["model"] = cfg.model
            if cfg.overlap != SolveSettings.overlap:      # more windows per frame (checked by the solve)
                choice["overlap"] = cfg.overlap
            solver = functools.partial(run_solver, **choice) if choice else run_solver
            out = core_solve.solve_recording(source, cfg.settings(), solver=solver, progress=progress)
        self.outcome = out
        self.recording, self.report, self.targets = out.recording, out.report, out.targets
        self.body, self.offsets, self.info = out.body, out.offsets, out.info
        self.timings = dict(timings, **out.timings)
        self.result = out.result
        self._set(_P_SOLVE, "writing")
        return self.result

    # -- stage 3 (main thread)
    def first_frame(self):
        """The scene frame the result's first frame is keyed on: ``config.frame_start``; for
        scene sources, the frame of the result's first time (``result.t0``, seconds, sampled
        frame ``f`` at ``f / fps``), so the solve lines up with the objects when it starts later
        than the range (every source hidden, tracking lost, on the range's first frames)."""
        if self.scene_fps is None or self.result is None:
            return self.config.frame_start
        frame = float(self.result.t0) * self.scene_fps
        return int(round(frame)) if abs(frame - round(frame)) < 1e-4 else frame

    def write(self, context):
        """Create the armature, action and empties (all or nothing).  Sets ``self.output``."""
        from . import writer
        _check_cancel(self._cancel)
        cfg = self.config
        t = _time.perf_counter()
        self.stage = "keying"
        # With the live rig, its action is the only one keyed: the limbs' FK keys would be
        # overridden by its constraints, and a plain FK action is one Bake away (a 60-minute take
        # at 60 fps holds 216,000 keys per F-curve: a second action would double the memory).
        take = cfg.take_name()
        opts = writer.WriteOptions(frame_start=self.first_frame(), armature=cfg.reuse_armature,
                                   armature_name=cfg.armature_name, action_name=f"MANIKIN_solve_{take}",
                                   create_trackers=cfg.create_trackers, body_mesh=cfg.body_mesh,
                                   set_scene_range=cfg.set_scene_range, key_pose=not cfg.live_rig)
        from .units import result_in_scene_units
        result = result_in_scene_units(self.result, context.scene)     # metres → the scene's unit
        out = writer.write_result(result, opts, context=context)
        if self.outcome is not None:
            self.outcome.info.extend(out.notes)
        self.timings["keying"] = _time.perf_counter() - t
        t = _time.perf_counter()
        if cfg.live_rig:
            from . import live_rig
            self.stage = "live rig"
            try:
                out.live_action = live_rig.build_live_rig(out.armature, result, frames=out.frames,
                                                          context=context, action_name=f"MANIKIN_live_{take}")
                out.action = out.live_action
            except BaseException:
                writer.remove_output(out)
                raise
        elif out.armature is not None:
            from . import live_rig
            if live_rig.is_live_rig(out.armature):      # re-solved onto a live rig: plain FK wins
                live_rig.set_rig_enabled(out.armature, False)
        for act in {a for a in (out.action, out.live_action) if a is not None}:
            act[PROP_SOURCE] = cfg.source_description()      # which take it is, for the Action editor
        if cfg.mark_problems:
            from ..core.review_marks import review_marks
            marks = review_marks(self.result, self.report, getattr(self.outcome, "jumps", ()))
            writer.mark_timeline(context.scene, marks, out.frames, cfg.marker_take)
        self.output = out
        if cfg.live_rig:
            self.timings["live rig"] = _time.perf_counter() - t
        self.progress = 1.0
        self.stage = "done"
        return self.output

    # -- synchronous
    def run(self, context):
        """All stages in this thread (command line, ``EXEC_DEFAULT``).  None (nothing written)
        when the file was split into several people (``people``)."""
        self.gather(context)
        self.compute()
        if self.people is not None:
            return None
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

    def summary(self, timings=True) -> str:
        """One line: frames, fps, stature, devices, gaps, where the solve gave way, and (with
        ``timings``) the seconds per stage."""
        if self.outcome is None:
            return ""
        return self.outcome.summary({k: v for k, v in self.timings.items() if k not in self.outcome.timings},
                                    timings=timings)


class SolveQueue:
    """Solves one after another, as the solve operators run them: one (*Solve Full Body*) or
    one per file (*Solve Several Files*).

    configs: the :class:`SolveConfig` of each solve.  A keypoint file that may hold several
    people (:func:`may_hold_people`) is read by its job (in the worker thread when modal); when
    it holds several, the queue replaces that configuration by one per person (``configs`` and
    ``len`` grow; each person is a job of its own, failing or written on its own, and shares the
    file's part of ``progress``).  on_done(job) is called after a job was
    written, on_failed(job, exc) when one failed (its file unreadable, its solve or its writing
    raising); both on the main thread.  A failed job leaves nothing behind and the queue goes on
    with the next.

    Modal use (the operators' timer): :meth:`start`, then :meth:`poll` on every tick until it
    returns False; each job's compute runs in a worker thread (:meth:`SolveJob.start_background`)
    and is written in the tick after it finishes.  :meth:`cancel` (Esc) stops the running job,
    of which nothing is written, and the ones not started; those written before stay (one undo
    step with the operator's).  Synchronous use (scripts, background mode): :meth:`run`.

    ``solved`` / ``failed``: the jobs so far; ``progress`` 0-1 over the whole queue.
    """

    def __init__(self, configs, on_done=None, on_failed=None):
        self.configs = list(configs)
        self._weights = [1.0] * len(self.configs)     # each one's part of the progress (a person: a share)
        self.on_done = on_done or (lambda job: None)
        self.on_failed = on_failed or (lambda job, exc: None)
        self.index = -1
        self.job = None
        self.solved, self.failed = [], []
        self.cancelled = False

    def __len__(self):
        return len(self.configs)

    @property
    def progress(self) -> float:
        total = sum(self._weights)
        if not total:
            return 1.0
        i = max(self.index, 0)
        part = self.job.progress if self.job is not None else 1.0
        done = sum(self._weights[:i]) + (self._weights[i] if i < len(self._weights) else 0.0) * part
        r = done / total
        return 1.0 if r > 1.0 - 1e-9 else max(r, 0.0)     # all done is 1 (people's shares may sum just below)

    @property
    def stage(self) -> str:
        stage = self.job.stage if self.job is not None else "done"
        if len(self.configs) < 2:
            return stage
        cfg = self.configs[max(self.index, 0)]
        if cfg.keypoints is not None and len({c.filepath for c in self.configs}) == 1:    # a group file's people
            return f"person {max(self.index, 0) + 1} of {len(self.configs)} ({cfg.person}): {stage}"
        name = os.path.basename(cfg.filepath or "") or "take"
        return f"file {max(self.index, 0) + 1} of {len(self.configs)} ({name}): {stage}"

    def _job(self, index):
        cfg = self.configs[index]
        return SolveJob(cfg, split_people=may_hold_people(cfg))

    def _attempt(self, job, step, context):
        """``step(context)`` (the job's ``write`` or ``run``), then the job is done, failed, or
        split into its people."""
        try:
            step(context)
        except Exception as exc:
            self._fail(job, exc)
        else:
            if job.people is not None:
                self._split(job)
            else:
                self._done(job)

    def _split(self, job):
        """The job's file holds several people: its configuration is replaced by theirs, the
        first of them solved next."""
        i, n = self.index, len(job.people)
        self.configs[i:i + 1] = job.people
        self._weights[i:i + 1] = [self._weights[i] / n] * n
        self.index = i - 1

    def _done(self, job):
        self.solved.append(job)
        self.on_done(job)

    def _fail(self, job, exc):
        self.failed.append((job, exc))
        self.on_failed(job, exc)

    def _next(self, context) -> bool:
        """Start the next job that gathers; False when none is left."""
        self.job = None
        while not self.cancelled and self.index + 1 < len(self.configs):
            self.index += 1
            job = self._job(self.index)
            try:
                job.gather(context)
            except Exception as exc:
                self._fail(job, exc)
                continue
            job.start_background()
            self.job = job
            return True
        return False

    def start(self, context) -> bool:
        """Start the first job; False when there is nothing to wait for (every job failed)."""
        return self._next(context)

    def poll(self, context) -> bool:
        """Write a finished job and start the next; True while a job is running."""
        job = self.job
        if job is None:
            return False
        if not job.done:
            return True
        if job.error is not None:
            self._fail(job, job.error)
        elif job.people is not None:
            self._split(job)
        else:
            self._attempt(job, job.write, context)
        return self._next(context)

    def cancel(self, timeout=0.5):
        """Stop: the running job is dropped unwritten (its worker never touches Blender data,
        so it is safe to leave it finishing), none of the rest starts."""
        self.cancelled = True
        if self.job is not None:
            self.job.cancel()
            self.job.join(timeout)
        self.job = None

    def run(self, context):
        """Every job in this thread, one after another (scripts, background mode)."""
        self.index = -1
        while self.index + 1 < len(self.configs):
            self.index += 1
            job = self._job(self.index)
            self._attempt(job, job.run, context)
        self.job = None
        return self


def may_hold_people(config: SolveConfig) -> bool:
    """True when ``config`` solves a keypoint file (``source`` KEYPOINTS, a ``filepath``, not read
    yet) with Person ``"all"`` that may hold several people: to be read to list them
    (:func:`person_configs`).  False for a file that surely holds one
    (:func:`core.io_keypoints.one_person_file`: a 3-D ``.npy`` by its header, a ``.trc`` / ``.c3d``, a CSV
    without a person column; a moment, whatever the file's size) and for a chosen person: the
    solve reads those itself."""
    from ..core.io_keypoints import one_person_file
    cfg = config
    if (cfg.source.upper() != "KEYPOINTS" or not cfg.filepath or cfg.keypoint_armature
            or cfg.keypoint_collection or cfg.keypoints is not None):
        return False
    if str(cfg.person or "all").strip().lower() != "all":
        return False
    return not one_person_file(cfg.filepath)


def person_configs(config: SolveConfig):
    """The people of ``config``'s keypoint file, read once
    (:func:`core.io_keypoints.read_keypoint_people`): one configuration each, handed its
    recording (``keypoints``).  Several people: as the command line's outputs, take
    ``<file>_p<label>`` (:func:`core.file_names.person_stems`), a new armature ``MANIKIN_<take>``
    (never the reused one: each person is a body of their own), timeline markers of its own, no
    scene range (the operator sets one over them all).  One person: ``[config]`` with that
    recording.  None when the file cannot be opened (its solve tries again and says why); a file
    that opens but cannot be read raises the reader's :class:`core.recording.RecordingError` (or
    ``ValueError``), which names the problem: solving it whole would only say that it holds several
    people, hiding why they could not be read (e.g. the units not told from a person never seen
    standing).  Reads the whole file, on the caller's thread: :class:`SolveQueue` calls it from its job's
    :meth:`SolveJob.compute` (the worker thread of a modal run)."""
    import dataclasses
    from ..core.file_names import person_stems
    from ..core.io_keypoints import read_keypoint_people
    cfg = config
    s = cfg.settings()
    try:
        people = read_keypoint_people(cfg.filepath, layout=s.keypoint_layout, units=s.units, up=s.up, rate=s.rate,
                                      mapping=s.mapping, subject_params=s.subject_params,
                                      person=s.person or "all", person_axis=s.person_axis)
    except OSError:
        return None
    if len(people) == 1:          # one person (alone in the file, or the only one seen)
        return [dataclasses.replace(cfg, keypoints=people[0][1])]
    takes = person_stems(cfg.take_name(), [lab for lab, _ in people])
    return [dataclasses.replace(cfg, person=lab, keypoints=rec, take=take, armature_name=f"MANIKIN_{take}",
                                reuse_armature=None, set_scene_range=False, marker_take=take)
            for (lab, rec), take in zip(people, takes)]


def find_tpose_time(config: SolveConfig, context=None):
    """Propose the T-pose moment of the source of ``config``.

    Returns ``(seconds after the first tracker sample, candidate)`` where
    candidate is a :class:`core.calibration.TPoseCandidate` (``plausible``
    tells whether it looks like a still T-pose).  With a calibration take, the moment is the
    one in that take (which the calibration then uses).
    """
    import dataclasses
    from ..core import calibration as cal
    if config.calibration_take:
        config = dataclasses.replace(config, source="FILE", filepath=config.calibration_take, calibration_take=None)
    job = SolveJob(config)
    if config.source.upper() == "SCENE":
        job.gather(context)
    else:
        job.recording = load_source(config)
    if config.fps is None:
        raise SolveError("no frame rate: set fps")
    # the device targets as the solve makes them (offsets, also those the take shows, and the
    # floor, also one found under an eye-level origin: the T-pose test needs it)
    from ..core.solve import SolveOutcome, device_targets
    out = SolveOutcome()
    out.recording = job.recording
    times = device_targets(out, config, str(config.teleports or "keep").strip().lower())[0]
    cand = cal.find_tpose(out.targets, t0=float(times[0]))
    return float(cand.time - times[0]), cand
