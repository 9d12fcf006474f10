"""The solve operators: *Solve Full Body* and *Solve Several Files*.

Invoked from the UI they are modal: the numpy/onnxruntime work of each solve
runs in a worker thread while a window-manager timer updates ``wm.progress_*``
and the status bar; Esc cancels.  Nothing in the scene changes until a solve is
complete (see :mod:`blender_manikin.blender.solve_job`): cancelling or an
error leaves no data of that solve behind, and on success everything is created
in one step, followed by the operator's undo push (``bl_options`` ``UNDO``), so
Ctrl+Z removes the whole solve.  Several files are solved one after another
(:class:`~blender_manikin.blender.solve_job.SolveQueue`); Esc stops the file
being solved (nothing of it is written) and the rest, and the files solved
before stay, in the operator's undo step.  *Solve Full Body* on a keypoint file with several
people (Person ``all``) solves each person the same way, onto an armature of their own
(:func:`~blender_manikin.blender.solve_job.person_configs`), and so does *Solve Several Files* for
each such file among its files; the file is read by its job, in the worker thread (the queue
then puts one solve per person in its place), so a large group file never freezes the window.
Run with ``EXEC_DEFAULT`` (scripts,
background mode) both run synchronously.  Errors are shown with
``self.report({'ERROR'}, ...)``.
"""
from __future__ import annotations

import dataclasses
import os

import bpy
from bpy.types import Operator

from ..blender import solve_job as sj
from ..core import formats

#: how the panel's box starts after a solve that failed (it shows it with an error icon)
FAILED = "Solve failed: "

#: the solve queue of the modal operator in progress (one at a time) and what its window holds
#: (``leftovers``: timer, workspaces), for :func:`abort_active`
_ACTIVE = {"job": None, "leftovers": None}


def abort_active(context):
    """Stop the modal solve in progress when the add-on is unregistered under it (disabled in the
    Preferences, updated): Blender then frees the operator without calling its ``cancel()``, which
    would leave its timer ticking and the status bar saying "Esc to cancel" for good."""
    job, left = _ACTIVE["job"], _ACTIVE["leftovers"]
    _ACTIVE.update(job=None, leftovers=None)
    if job is not None:
        job.cancel()
    if left is None:
        return
    wm = context.window_manager
    try:
        wm.event_timer_remove(left["timer"])
    except (ReferenceError, RuntimeError, TypeError):
        pass
    wm.progress_end()
    for win in wm.windows:
        with context.temp_override(window=win):
            win.workspace.status_text_set(None)


def _people(op) -> bool:
    """*Solve Full Body* solving a keypoint file's people (its one configuration was split into
    one per person by the queue, :class:`~..blender.solve_job.SolveQueue`)."""
    q = getattr(op, "_queue", None)
    return q is not None and len(q) > 1


def _finish_report(op, context, job):
    s = context.scene.manikin
    out = job.output
    summary = job.summary()
    s.last_report = job.summary(timings=False)        # the panel's box: what the animator acts on
    if out is not None:
        s.armature = out.armature
    for note in job.info:
        if note.startswith(("calibration:", "estimated stature")):
            op.report({'WARNING'}, note)
    if job.result is not None:
        for note in job.result.quality_notes():
            op.report({'WARNING'}, f"MANIKIN: {note}")
    if job.report is not None:
        for g in getattr(job.report, "gaps", [])[:5]:
            op.report({'INFO'}, f"bridged {g}")
    op.report({'INFO'}, f"MANIKIN: {out.armature.name} / {out.action.name}: {summary}")


def _written_one(op, context, job, who=None):
    """One of several solves written (a file of *Solve Several Files*, a person of a group
    keypoint file): kept in ``op._written`` as plain values (the objects may be gone by the end:
    an undo while the next are solved frees them) and reported."""
    out = job.output
    context.scene.manikin.armature = out.armature          # the swivel panel's: the last
    name = f"{out.armature.name} / {out.action.name}"
    op._written.append((name, float(out.frames[0]), float(out.frames[-1])))
    op.report({'INFO'}, f"MANIKIN: {who + ': ' if who else ''}{name}: {job.summary(timings=False)}")


def _named(tag, exc) -> str:
    """The message of ``exc`` led by ``tag`` (a file's name, or ``group.npy person 1``) once: a
    reader's error already starts with its file (:class:`core.recording.RecordingError`:
    ``broken.csv, line 1: ...``), which the tag then replaces (``group.npy person 1, line 1:
    ...``) instead of leading it (``broken.csv: broken.csv, line 1: ...`` said it twice)."""
    message = sj.error_message(exc)
    path = getattr(exc, "path", None)
    name = os.path.basename(str(path)) if path else ""
    if name and message.startswith(name) and tag.startswith(name):
        return tag + message[len(name):]
    return f"{tag}: {message}"


def _finish_several(op, context, what, unit, who):
    """The end of several solves in one operator run (one undo step): the scene range over them
    all (when the settings ask for one), the panel's box saying ``N of M <what> solved: <armature /
    action>, ...; failed: <who(job)>: <why>; ...`` (``0 of M <what> solved; failed: ...`` when none
    was; after Esc: how many ``unit`` were not solved)
    and the operator's return value."""
    q, scene = op._queue, context.scene
    if op._written and op._base.set_scene_range:
        scene.frame_start = int(min(a for _, a, _ in op._written))
        scene.frame_end = max(int(max(b for _, _, b in op._written) + 0.999), scene.frame_start)
    solved = [name for name, _, _ in op._written]
    failed = [_named(who(j), e) for j, e in q.failed]
    report = f"{len(solved)} of {len(q)} {what} solved" + (": " + ", ".join(solved) if solved else "")
    if failed:
        report += f"; failed: {'; '.join(failed)}"
    if q.cancelled:
        left = len(q) - len(q.solved) - len(q.failed)
        report += f"; cancelled (Esc), {left} {unit} not solved"
    scene.manikin.last_report = report
    if not solved:
        op.report({'WARNING'} if q.cancelled else {'ERROR'}, f"MANIKIN: {report}")
        return {'CANCELLED'}
    op.report({'INFO'}, f"MANIKIN: {report}")
    return {'FINISHED'}


class _ModalSolves:
    """What both solve operators share: a :class:`~..blender.solve_job.SolveQueue` run either
    synchronously (:meth:`_run_now`) or modally (:meth:`_run_modal`: a worker thread per solve,
    a window-manager timer updating ``wm.progress_*`` and the status bar, Esc cancelling).
    Subclasses give ``_queue_done(context, job)``, ``_queue_failed(context, job, exc)`` and
    ``_queue_finish(context) -> set`` (the operator's return value)."""

    def _start(self, context, modal):
        """Make the solves' configurations (``_configs``) and run them, modally or not."""
        if _ACTIVE["job"] is not None:     # a file browser's execute is not checked by poll()
            self.report({'ERROR'}, "MANIKIN: a solve is already running (Esc cancels it)")
            return {'CANCELLED'}
        try:
            configs = self._configs(context)
        except Exception as exc:
            context.scene.manikin.last_report = f"{FAILED}{sj.error_message(exc)}"
            self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")
            return {'CANCELLED'}
        return self._run_modal(context, configs) if modal else self._run_now(context, configs)

    def _make_queue(self, context, configs):
        return sj.SolveQueue(configs, on_done=lambda job: self._queue_done(context, job),
                             on_failed=lambda job, exc: self._queue_failed(context, job, exc))

    def _run_now(self, context, configs):
        self._queue = self._make_queue(context, configs)
        self._queue.run(context)
        return self._queue_finish(context)

    def _run_modal(self, context, configs):
        wm = context.window_manager
        self._queue = self._make_queue(context, configs)
        self._timer = None
        self._scene = context.scene                 # written there, whichever scene is shown then
        if not self._queue.start(context):          # every source failed to gather: nothing to wait for
            return self._queue_finish(context)
        _ACTIVE["job"] = self._queue
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        _ACTIVE["leftovers"] = {"timer": self._timer}
        wm.modal_handler_add(self)
        self._status(context)
        return {'RUNNING_MODAL'}

    def _status(self, context, text=None):
        ws = getattr(context, "workspace", None)
        if ws is None:
            return
        q = getattr(self, "_queue", None)
        if text is None and q is not None:
            text = f"MANIKIN: {q.stage} {100 * q.progress:.0f}%  (Esc to cancel)"
        ws.status_text_set(text)

    def _cleanup(self, context):
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        # The 3D Views (their sidebar holds the panel) drawn again: an operator that ends
        # CANCELLED (a failed solve) redraws nothing, so the panel's "Solve failed: ..." box was
        # not drawn until something else redrew the sidebar (the status bar alone said it).
        for win in wm.windows:
            for area in win.screen.areas:
                if area.type == 'VIEW_3D':
                    area.tag_redraw()
        ws = getattr(context, "workspace", None)
        if ws is not None:
            ws.status_text_set(None)
        _ACTIVE.update(job=None, leftovers=None)

    def modal(self, context, event):
        q = self._queue
        if event.type == 'ESC' and event.value == 'PRESS':
            q.cancel()
            self._cleanup(context)
            return self._queue_finish(context)
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        try:
            other = None if context.scene == self._scene else self._scene.name
        except ReferenceError:                       # its scene was deleted: nowhere to write it
            q.cancel()
            self._cleanup(context)
            return self._queue_finish(context)
        if other is not None:                        # another scene is shown: wait for the user
            self._status(context, f"MANIKIN: {q.stage} {100 * q.progress:.0f}%: show scene {other!r} "
                                  "to write it (Esc to cancel)")
            return {'RUNNING_MODAL'}
        running = q.poll(context)
        context.window_manager.progress_update(int(100 * q.progress))
        if running:
            self._status(context)
            return {'RUNNING_MODAL'}
        self._cleanup(context)
        return self._queue_finish(context)

    def cancel(self, context):
        """Called by Blender when the modal operator is aborted (e.g. file load)."""
        if getattr(self, "_queue", None) is not None:
            self._queue.cancel()
        self._cleanup(context)


class MANIKIN_OT_solve_full_body(_ModalSolves, Operator):
    """Solve the full body from the trackers and key it on a new armature action"""
    bl_idname = "manikin.solve_full_body"
    bl_label = "Solve Full Body"
    bl_description = ("Solve full-body animation from the tracker recording or scene objects and "
                      "write it as a new action (Esc cancels)")
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if _ACTIVE["job"] is not None:
            cls.poll_message_set("a solve is already running")
            return False
        return context.scene is not None and hasattr(context.scene, "manikin")

    def _configs(self, context):
        from ..blender.properties import config_from_settings
        base = config_from_settings(context)
        self._base = base
        self._written = []
        return [base]        # a keypoint file with several people: split by the queue, read in its job

    def execute(self, context):
        return self._start(context, modal=False)

    def invoke(self, context, event):
        return self._start(context, modal=not bpy.app.background and context.window is not None)

    def _queue_done(self, context, job):
        if not _people(self):
            _finish_report(self, context, job)
            return
        _written_one(self, context, job, f"person {job.config.person}")

    def _queue_failed(self, context, job, exc):
        if isinstance(exc, sj.SolveCancelled):
            return                                   # said once, by _queue_finish
        if _people(self):                            # the others go on; said with them at the end
            self.report({'WARNING'}, f"MANIKIN: person {job.config.person}: {sj.error_message(exc)}")
            return
        context.scene.manikin.last_report = f"{FAILED}{sj.error_message(exc)}"
        self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")

    def _queue_finish(self, context):
        q = self._queue
        if _people(self):
            name = os.path.basename(self._base.filepath)
            return _finish_several(self, context, f"people of {name}", "person(s)",
                                   lambda j: f"person {j.config.person}")
        if q.solved:
            return {'FINISHED'}
        if q.cancelled or any(isinstance(e, sj.SolveCancelled) for _, e in q.failed):
            self.report({'WARNING'}, "MANIKIN: solve cancelled, nothing was written")
        return {'CANCELLED'}


class MANIKIN_OT_solve_files(_ModalSolves, Operator):
    """Solve several recordings (or keypoint files) with the panel's settings, each onto an
    armature and action of its own, named after the file"""
    bl_idname = "manikin.solve_files"
    bl_label = "Solve Several Files"
    bl_description = ("Choose several recordings or keypoint files: each is solved with the panel's settings "
                      "onto its own armature (MANIKIN_<file>) and action; one that fails does not stop the "
                      "others; Esc stops after the files already solved")
    bl_options = {'REGISTER', 'UNDO'}

    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement, options={'HIDDEN', 'SKIP_SAVE'})
    directory: bpy.props.StringProperty(subtype='DIR_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    filter_glob: bpy.props.StringProperty(default=";".join("*" + e for e in formats.input_extensions()),
                                          options={'HIDDEN'})
    #: set by invoke: the file browser's execute runs the files modally (progress, Esc) when there
    #: is a window; scripts calling the operator get it synchronous
    interactive: bpy.props.BoolProperty(default=False, options={'HIDDEN', 'SKIP_SAVE'})

    @classmethod
    def poll(cls, context):
        return MANIKIN_OT_solve_full_body.poll(context)

    def invoke(self, context, event):
        self.interactive = True
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def _configs(self, context):
        from ..blender.properties import config_from_settings
        paths = [os.path.join(self.directory, f.name) for f in self.files if f.name]
        if not paths:
            raise sj.SolveError("choose one or more files")
        base = config_from_settings(context)
        self._base = base
        # what each written take was, as plain values: the objects themselves may be gone by the
        # end (an undo while the next files are solved frees them)
        self._written = []
        source = "KEYPOINTS" if base.source.upper() == "KEYPOINTS" else "FILE"
        configs = []
        for path in paths:
            take = os.path.splitext(os.path.basename(path))[0]
            cfg = dataclasses.replace(
                base, source=source, filepath=path, keypoint_collection=None, keypoint_armature=None,
                reuse_armature=None,
                armature_name=f"MANIKIN_{take}", set_scene_range=False, create_trackers=False, marker_take=take)
            # a keypoint file with several people (Person all): read by its job when its turn comes
            # (in the worker thread when modal), then one solve each, as Solve Full Body does
            configs.append(cfg)
        return configs

    def execute(self, context):
        return self._start(context, modal=self.interactive and not bpy.app.background
                           and context.window is not None)

    def _queue_done(self, context, job):
        _written_one(self, context, job)

    def _queue_failed(self, context, job, exc):
        self.report({'WARNING'}, f"MANIKIN: {_named(_file_who(job), exc)}")

    def _queue_finish(self, context):
        return _finish_several(self, context, "takes" if any(c.take for c in self._queue.configs) else "files",
                               "file(s)", _file_who)


def _file_who(job):
    """A solve of *Solve Several Files* as its report names it: the file, and the person of a file
    with several (``group.npy person 1``)."""
    name = os.path.basename(job.config.filepath)
    return f"{name} person {job.config.person}" if job.config.take else name


CLASSES = (MANIKIN_OT_solve_full_body, MANIKIN_OT_solve_files)
