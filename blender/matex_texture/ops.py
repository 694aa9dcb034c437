"""The operators: Texture selected, Enhance, Transfer, Cancel. From the UI (invoke) a job runs
under a modal timer, so Blender keeps drawing while matex works; from a script or in background
mode (execute) the same job runs to its end before the call returns."""

import time

import bpy

from . import job, settings, stream

POLL_SECONDS = 0.1


def _show(context, j):
    wm = context.window_manager
    wm.matex_progress = 100.0 * j.fraction
    wm.matex_status = j.status
    wm.progress_update(int(100 * j.fraction))
    if context.workspace is not None:
        context.workspace.status_text_set(j.status)
    for window in wm.windows:  # the sidebars only: redrawing the viewports each poll would be costly
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                for region in area.regions:
                    if region.type == "UI":
                        region.tag_redraw()


def _end(context, op, j):
    wm = context.window_manager
    wm.progress_end()
    if context.workspace is not None:
        context.workspace.status_text_set(None)
    wm.matex_status = j.status if j.ok else ""
    if j.ok:
        op.report({"INFO"}, j.status)
        return {"FINISHED"}
    op.report({"WARNING"} if j.error == "cancelled" else {"ERROR"}, "matex: %s" % j.error)
    return {"CANCELLED"}


class _MatexRunOperator:
    """Shared by the three verbs (mode)."""

    bl_options = {"REGISTER"}
    mode = "texture"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH" and context.mode == "OBJECT" and job.active() is None

    def _start(self, context):
        prefs = settings.preferences(context)
        url = prefs.server_url.strip()
        matex = stream.find_matex(prefs.matex_path)
        if matex is None and not (url and self.mode == "texture"):
            self.report({"ERROR"}, "matex not found: put it on PATH or set its path in the add-on's preferences")
            return None
        j = job.Job(context.active_object, self.mode, context.scene.matex, matex, url, prefs.server_token)
        try:
            j.start(context)
        except (ValueError, OSError, RuntimeError) as e:
            self.report({"ERROR"}, "matex: %s" % e)
            return None
        context.window_manager.progress_begin(0, 100)
        return j

    def execute(self, context):
        j = self._start(context)
        if j is None:
            return {"CANCELLED"}
        while not j.poll():
            _show(context, j)
            time.sleep(POLL_SECONDS)
        return _end(context, self, j)

    def invoke(self, context, event):
        self._job = self._start(context)
        if self._job is None:
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not self._job.poll():
            _show(context, self._job)
            return {"RUNNING_MODAL"}
        context.window_manager.event_timer_remove(self._timer)
        return _end(context, self, self._job)

    def cancel(self, context):
        """Blender ends the modal operator itself (a file is loaded, the window closes): stop
        matex and put the object back before its data may go away."""
        context.window_manager.event_timer_remove(self._timer)
        self._job.cancel()
        self._job.run.wait(timeout=60)
        self._job.poll()
        context.window_manager.progress_end()


class MATEX_OT_texture(_MatexRunOperator, bpy.types.Operator):
    """Texture the selected object from the prompt (matex texture)"""

    bl_idname = "matex.texture_selected"
    bl_label = "Texture selected"
    mode = "texture"


class MATEX_OT_enhance(_MatexRunOperator, bpy.types.Operator):
    """Enhance the selected object's texture under the prompt (matex enhance, SDEdit)"""

    bl_idname = "matex.enhance"
    bl_label = "Enhance"
    mode = "enhance"


class MATEX_OT_transfer(_MatexRunOperator, bpy.types.Operator):
    """Move the texture of the chosen object onto the selected one (matex transfer)"""

    bl_idname = "matex.transfer"
    bl_label = "Transfer"
    mode = "transfer"


class MATEX_OT_cancel(bpy.types.Operator):
    """Stop the running matex; the object stays as it was"""

    bl_idname = "matex.cancel"
    bl_label = "Cancel"

    @classmethod
    def poll(cls, context):
        return job.active() is not None

    def execute(self, context):
        job.active().cancel()
        return {"FINISHED"}


classes = (MATEX_OT_texture, MATEX_OT_enhance, MATEX_OT_transfer, MATEX_OT_cancel)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
