"""Operators of the heavy-mesh jobs (jobs.py): cancel them, and Compute Now in the background.

`ComputeInBackground` gives `hemishadow.compute` (live.py) an `invoke`: clicked in a window,
heavy objects compute in the worker, with progress in the header and the window manager,
and Esc cancels; scripts (`execute`) still compute synchronously.
"""

import bpy

from .. import jobs


class HEMISHADOW_OT_cancel_jobs(bpy.types.Operator):
    """Stop computing heavy objects in the background; they keep their previous result, marked stale"""

    bl_idname = "hemishadow.cancel_jobs"
    bl_label = "Cancel"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        return bool(jobs.pending())

    def execute(self, context):
        count = jobs.cancel()
        self.report({"INFO"}, f"hemishadow: cancelled the computation of {count} objects; previous results kept")
        return {"FINISHED"}


def _summary(pending):
    running = pending[0]
    more = f" (+{len(pending) - 1} more)" if len(pending) > 1 else ""
    return f"Hemishadow: computing {running.name}, {int(running.fraction * 100)} %{more}  (Esc to cancel)"


class ComputeInBackground:
    """Mixin for the Compute Now operator (its `target` property): `invoke` sends heavy
    objects to the worker and waits for them modally."""

    _objects = ()
    _timer = None
    _area = None
    _errors = None

    def invoke(self, context, event):
        from .live import target_objects

        objects = target_objects(context, self.target)
        if context.window is None or not any(jobs.heavy(o) for o in objects):
            return self.execute(context)
        self._errors = jobs.update_scene(context.scene, context.evaluated_depsgraph_get(), objects,
                                         interactive=True, force=True)
        self._objects = objects
        if not jobs.pending(objects):
            return self._done(context)
        self._area = context.area
        wm = context.window_manager
        self._timer = wm.event_timer_add(jobs.INTERVAL, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            jobs.cancel(self._objects)
            self._end(context)
            self.report({"WARNING"}, "hemishadow: cancelled; the previous results stay, marked stale")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        jobs.poll()
        pending = jobs.pending(self._objects)
        if pending:
            if self._area is not None:
                self._area.header_text_set(_summary(pending))
            return {"RUNNING_MODAL"}
        self._end(context)
        for obj in self._objects:
            if jobs.error(obj):
                self._errors.setdefault(obj.name, jobs.error(obj))
        return self._done(context)

    def cancel(self, context):
        # Blender cancels a running modal operator when it loads another file or quits.
        jobs.cancel(self._objects)
        self._end(context)

    def _end(self, context):
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        if self._area is not None:
            self._area.header_text_set(None)
            self._area = None

    def _done(self, context):
        from .. import lighting

        errors = self._errors or {}
        if errors and len(errors) == len(self._objects):
            self.report({"ERROR"}, "; ".join(errors.values()))
            return {"CANCELLED"}
        if errors:
            self.report({"WARNING"}, "; ".join(errors.values()))
        for message in lighting.report(context.scene):  # as execute: fallbacks, lamps not represented
            self.report({"WARNING"}, message)
        return {"FINISHED"}


classes = (HEMISHADOW_OT_cancel_jobs,)
