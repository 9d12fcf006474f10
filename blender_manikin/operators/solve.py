"""MANIKIN_OT_solve_full_body: the "Solve full body" button.

Invoked from the UI it is modal: the numpy/onnxruntime work runs in a worker
thread while a window-manager timer updates ``wm.progress_*`` and the status
bar; Esc cancels.  Nothing in the scene changes until the solve is complete
(see :mod:`blender_manikin.blender.solve_job`): cancelling or an error leaves
no data behind, and on success everything is created in one step, followed
by the operator's undo push (``bl_options`` ``UNDO``), so Ctrl+Z removes the
whole solve.  Run with ``EXEC_DEFAULT`` (scripts, background mode) it runs
synchronously.  Errors are shown with ``self.report({'ERROR'}, ...)``.
"""
from __future__ import annotations

import bpy
from bpy.types import Operator

from ..blender import solve_job as sj

#: the job of the modal solve in progress (one at a time)
_ACTIVE = {"job": None}


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


class MANIKIN_OT_solve_full_body(Operator):
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

    # -- synchronous
    def execute(self, context):
        try:
            job = sj.SolveJob(self._config(context))
            job.run(context)
        except sj.SolveCancelled:
            self.report({'WARNING'}, "MANIKIN: solve cancelled")
            return {'CANCELLED'}
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")
            return {'CANCELLED'}
        _finish_report(self, context, job)
        return {'FINISHED'}

    def _config(self, context):
        from ..blender.properties import config_from_settings
        return config_from_settings(context)

    # -- modal
    def invoke(self, context, event):
        wm = context.window_manager
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            self._job = sj.SolveJob(self._config(context))
            self._job.gather(context)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")
            return {'CANCELLED'}
        _ACTIVE["job"] = self._job
        self._job.start_background()
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        self._status(context)
        return {'RUNNING_MODAL'}

    def _status(self, context, text=None):
        ws = getattr(context, "workspace", None)
        if ws is None:
            return
        if text is None and self._job is not None:
            text = (f"MANIKIN: {self._job.stage} {100 * self._job.progress:.0f}%  "
                    f"(Esc to cancel)")
        ws.status_text_set(text)

    def _cleanup(self, context):
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        ws = getattr(context, "workspace", None)
        if ws is not None:
            ws.status_text_set(None)
        _ACTIVE["job"] = None

    def modal(self, context, event):
        job = self._job
        if event.type == 'ESC' and event.value == 'PRESS':
            job.cancel()
            job.join(timeout=0.5)     # the worker never touches Blender data: safe to leave
            self._cleanup(context)
            self.report({'WARNING'}, "MANIKIN: solve cancelled, nothing was written")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        context.window_manager.progress_update(int(100 * job.progress))
        self._status(context)
        if not job.done:
            return {'RUNNING_MODAL'}
        self._cleanup(context)
        if job.error is not None:
            if isinstance(job.error, sj.SolveCancelled):
                self.report({'WARNING'}, "MANIKIN: solve cancelled, nothing was written")
            else:
                self.report({'ERROR'}, f"MANIKIN: {sj.error_message(job.error)}")
            return {'CANCELLED'}
        try:
            job.write(context)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")
            return {'CANCELLED'}
        _finish_report(self, context, job)
        return {'FINISHED'}

    def cancel(self, context):
        """Called by Blender when the modal operator is aborted (e.g. file load)."""
        if getattr(self, "_job", None) is not None:
            self._job.cancel()
        self._cleanup(context)


class MANIKIN_OT_solve_files(Operator):
    """Solve several recordings (or keypoint files) with the panel's settings, each onto an
    armature and action of its own, named after the file"""
    bl_idname = "manikin.solve_files"
    bl_label = "Solve Several Files"
    bl_description = ("Choose several recordings or keypoint files: each is solved with the panel's settings "
                      "onto its own armature (MANIKIN_<file>) and action; one that fails does not stop the others")
    bl_options = {'REGISTER', 'UNDO'}

    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement, options={'HIDDEN', 'SKIP_SAVE'})
    directory: bpy.props.StringProperty(subtype='DIR_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    filter_glob: bpy.props.StringProperty(default="*.csv;*.bsor;*.xror;*.npy;*.npz", options={'HIDDEN'})

    @classmethod
    def poll(cls, context):
        return MANIKIN_OT_solve_full_body.poll(context)

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        import dataclasses
        import os
        from ..blender.properties import config_from_settings
        paths = [os.path.join(self.directory, f.name) for f in self.files if f.name]
        if not paths:
            self.report({'ERROR'}, "MANIKIN: choose one or more files")
            return {'CANCELLED'}
        try:
            base = config_from_settings(context)
        except Exception as exc:
            self.report({'ERROR'}, f"MANIKIN: {sj.error_message(exc)}")
            return {'CANCELLED'}
        source = "KEYPOINTS" if base.source.upper() == "KEYPOINTS" else "FILE"
        scene, wm = context.scene, context.window_manager
        solved, failed, span = [], [], []
        wm.progress_begin(0, len(paths))
        try:
            for k, path in enumerate(paths):
                take = os.path.splitext(os.path.basename(path))[0]
                cfg = dataclasses.replace(base, source=source, filepath=path, keypoint_collection=None,
                                          reuse_armature=None, armature_name=f"MANIKIN_{take}",
                                          set_scene_range=False, create_trackers=False, marker_take=take)
                try:
                    job = sj.SolveJob(cfg)
                    job.run(context)
                except Exception as exc:             # one bad file does not stop the others
                    failed.append(f"{os.path.basename(path)}: {sj.error_message(exc)}")
                    self.report({'WARNING'}, f"MANIKIN: {os.path.basename(path)}: {sj.error_message(exc)}")
                else:
                    out = job.output
                    context.scene.manikin.armature = out.armature     # the swivel panel's: the last
                    solved.append(f"{out.armature.name} / {out.action.name}")
                    span.append((out.frames[0], out.frames[-1]))
                    self.report({'INFO'}, f"MANIKIN: {out.armature.name} / {out.action.name}: "
                                          f"{job.summary(timings=False)}")
                wm.progress_update(k + 1)
        finally:
            wm.progress_end()
        if span and base.set_scene_range:
            scene.frame_start = int(min(a for a, _ in span))
            scene.frame_end = max(int(max(b for _, b in span) + 0.999), scene.frame_start)
        s = scene.manikin
        s.last_report = (f"{len(solved)} of {len(paths)} files solved: " + ", ".join(solved)
                         + (f"; failed: {'; '.join(failed)}" if failed else ""))
        if not solved:
            self.report({'ERROR'}, f"MANIKIN: {s.last_report}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"MANIKIN: {s.last_report}")
        return {'FINISHED'}


CLASSES = (MANIKIN_OT_solve_full_body, MANIKIN_OT_solve_files)
