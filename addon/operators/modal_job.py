"""The modal half of a bake operator that runs a worker_job.WorkerJob: a timer steps the job,
progress shows in the window manager, the status bar and the area's header, Esc cancels at
once (nothing written), and the UI stays usable meanwhile. An operator mixes it in and says
what it bakes (`noun`), what the status line says (`status`) and what to do when the job
has written (`finished`)."""

from .. import worker_job


class ModalUi:
    """What a modal bake operator shows while it runs: a timer, the window manager's progress,
    the status bar and the area's header; `_end` takes them all down."""

    _timer = None
    _area = None

    def _status(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        if self._area is not None:
            self._area.header_text_set(text)

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        if self._area is not None:
            self._area.header_text_set(None)
            self._area = None


class ModalJob(ModalUi):
    _job = None
    noun = "bake"

    def start_modal(self, context, job):
        """Starts `job` and the modal loop; returns the operator's result."""
        self._job = job.start()
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        self._area = context.area
        wm.modal_handler_add(self)
        self._status(context, self.status(job))
        return {"RUNNING_MODAL"}

    def status(self, job):
        return f"Baking {self.noun}: {100 * job.fraction:.0f} % (Esc cancels)"

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()  # step() below returns CANCELLED at once; the worker stops at its next report
        elif event.type != "TIMER":
            return {"PASS_THROUGH"}  # the UI stays usable while the worker bakes
        state = job.step()
        if state == worker_job.RUNNING:
            context.window_manager.progress_update(int(1000 * job.fraction))
            self._status(context, self.status(job))
            return {"RUNNING_MODAL"}
        self._end(context)
        for message in job.warnings:
            self.report({"WARNING"}, message)
        if state == worker_job.CANCELLED:
            self.report({"WARNING"}, f"hemishadow: {self.noun} bake cancelled; nothing was written")
            return {"CANCELLED"}
        if state == worker_job.FAILED:
            self.report({"ERROR"}, f"hemishadow: {self.noun} bake failed, nothing written: {job.error}")
            return {"CANCELLED"}
        return self.finished(context, job.written)

    def cancel(self, context):  # Blender ends the operator (file closed, window gone)
        if self._job is not None:
            self._job.cancel()
        self._end(context)
