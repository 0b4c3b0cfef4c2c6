"""UI: the "Farm" section under Actions (issue 14): submit the animation bake, the lightmaps or
the probes of the SAVED .blend to a Dask scheduler, the same jobs the Bake buttons run here.

Blender's Python has no dask: the job runs as `PYTHON -m hemishadow farm KIND FILE.blend
--scheduler ADDRESS [options]` in a Python that has it (the project's .venv; the setting or
$HEMISHADOW_FARM_PYTHON), followed by a timer; Cancel sends it Ctrl-C (queued units removed,
nothing written). Nothing is saved for the user: an unsaved or modified file is refused, as the
workers would bake what is on disk, not what is on screen.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading

import bpy
from bpy.props import EnumProperty, PointerProperty, StringProperty

from . import lightmap_settings, panorama_settings, probes

LOOPBACK = "tcp://127.0.0.1:8786"
KINDS = [("bake", "Animation Cache", "Bake the frame range of the objects Bake Animation would bake"),
         ("lightmaps", "Lightmaps", "Bake the Lightmaps panel's objects with its settings"),
         ("probes", "Probes", "Bake the active Light Probe Volume or Empty"),
         ("panorama", "Panorama", "Bake the Panorama panel's panorama with its settings")]


class HemishadowFarmSettings(bpy.types.PropertyGroup):
    address: StringProperty(name="Scheduler", default=LOOPBACK,
                            description="Address of the Dask scheduler (tls://... on a real farm, docs/farm.md)")
    python: StringProperty(name="Python", default="", subtype="FILE_PATH",
                           description="A Python with dask and hemishadow (the project's .venv/bin/python); "
                                       "empty: $HEMISHADOW_FARM_PYTHON")
    kind: EnumProperty(name="Job", items=KINDS, default="bake")


def job_arguments(context, kind):
    """The subcommand's options for the job the panel's Bake buttons would run here."""
    scene = context.scene
    if kind == "bake":
        from .operators.bake import bakeable_objects

        objects = bakeable_objects(context)
        if not objects:
            raise ValueError("no object has hemishadow enabled")
        return ["--start", str(scene.frame_start), "--end", str(scene.frame_end), "--scene", scene.name,
                "--objects", *[o.name for o in objects]]
    if kind == "lightmaps":
        settings = scene.hemishadow_lightmaps
        objects = lightmap_settings.objects(context, settings)
        if not objects:
            raise ValueError("no mesh object for the lightmaps: select them or choose a collection")
        size = (["--texel-density", str(settings.texel_density)] if settings.size_mode == "DENSITY"
                else ["--resolution", str(settings.resolution)])
        out = ["--out", settings.directory] if settings.directory else []
        layout = (["--atlas", settings.atlas_name, "--islands", settings.uv_name]
                  if settings.layout == "ATLAS" and len(objects) > 1 else ["--uv", settings.uv_name])
        return ["--objects", *[o.name for o in objects], *layout, *size, "--basis", settings.basis,
                "--bounces", str(settings.bounces), "--samples", str(settings.samples),
                *([] if settings.adaptive else ["--uniform"]), "--margin", str(settings.margin), "--scene", scene.name,
                *out]
    if kind == "panorama":
        where = panorama_settings.bake_arguments(scene)
        if where.get("at") is not None:
            place = ["--at", ",".join(f"{v:g}" for v in where["at"])]
        else:
            place = ["--camera", where["camera"]] if where.get("camera") else []
        out = ["--out", scene.hemishadow_panorama.filepath] if scene.hemishadow_panorama.filepath else []
        width, height = where["size"]
        return [*place, "--size", f"{width}x{height}", "--coefficients", str(where["coefficients"]),
                "--bounces", str(where["bounces"]), "--scene", scene.name, *out]
    volume = probes.active_volume(context)
    if volume is None:
        raise ValueError("make a Light Probe Volume or an Empty active")
    return ["--volume", volume.name, "--scene", scene.name]


def farm_command(context, settings=None):
    """The command line of the farm job; ValueError says why there is none."""
    settings = settings or context.scene.hemishadow_farm
    if not bpy.data.filepath:
        raise ValueError("save the .blend first: the workers bake the saved file")
    if bpy.data.is_dirty:
        raise ValueError("the .blend has unsaved changes: save it first (the workers bake the saved file)")
    python = bpy.path.abspath(settings.python) if settings.python else os.environ.get("HEMISHADOW_FARM_PYTHON", "")
    if not python:
        raise ValueError("set the farm's Python (a Python with dask and hemishadow) or $HEMISHADOW_FARM_PYTHON")
    return [python, "-m", "hemishadow", "farm", settings.kind, bpy.data.filepath,
            "--scheduler", settings.address or LOOPBACK, *job_arguments(context, settings.kind)]


class FarmRun:
    """A submitted job: its process and the last line it printed (a reader thread collects them)."""

    def __init__(self, command):
        self.command = command
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                        start_new_session=True)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line.rstrip())

    @property
    def status(self):
        code = self.process.poll()
        last = self.lines[-1] if self.lines else "submitted"
        if code is None:
            return f"running: {last}"
        return {0: "done", 130: "cancelled: nothing written"}.get(code, f"failed: {last}")

    def cancel(self):
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)   # the client removes queued units, writes nothing


_run: FarmRun | None = None


def current():
    return _run


def _redraw():
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
    if _run is not None and _run.process.poll() is None:
        return 1.0
    return None


class HEMISHADOW_OT_farm_submit(bpy.types.Operator):
    """Submit the job to the Dask scheduler (the saved .blend; nothing is saved for you)"""

    bl_idname = "hemishadow.farm_submit"
    bl_label = "Submit to Farm"

    def execute(self, context):
        global _run
        if _run is not None and _run.process.poll() is None:
            self.report({"ERROR"}, "a farm job is running: cancel it or wait")
            return {"CANCELLED"}
        try:
            command = farm_command(context)
            _run = FarmRun(command)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, f"hemishadow farm: {error}")
            return {"CANCELLED"}
        if not bpy.app.timers.is_registered(_redraw):
            bpy.app.timers.register(_redraw, first_interval=1.0)
        self.report({"INFO"}, "hemishadow farm: submitted " + " ".join(command[3:6]))
        return {"FINISHED"}


class HEMISHADOW_OT_farm_cancel(bpy.types.Operator):
    """Cancel the farm job: queued units are removed and nothing is written"""

    bl_idname = "hemishadow.farm_cancel"
    bl_label = "Cancel Farm Job"

    @classmethod
    def poll(cls, context):
        return _run is not None and _run.process.poll() is None

    def execute(self, context):
        _run.cancel()
        return {"FINISHED"}


class HEMISHADOW_PT_farm(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Hemishadow"
    bl_label = "Farm"
    bl_parent_id = "HEMISHADOW_PT_actions"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        settings = context.scene.hemishadow_farm
        layout.prop(settings, "address")
        layout.prop(settings, "python")
        layout.prop(settings, "kind")
        row = layout.row(align=True)
        row.operator("hemishadow.farm_submit", icon="NETWORK_DRIVE")
        row.operator("hemishadow.farm_cancel", text="", icon="CANCEL")
        if _run is not None:
            layout.label(text=_run.status[:120])
        elif bpy.data.is_dirty or not bpy.data.filepath:
            layout.label(text="Save the .blend first: the farm bakes the saved file", icon="INFO")


classes = (HemishadowFarmSettings, HEMISHADOW_OT_farm_submit, HEMISHADOW_OT_farm_cancel, HEMISHADOW_PT_farm)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.hemishadow_farm = PointerProperty(type=HemishadowFarmSettings)


def unregister():
    if _run is not None:
        _run.cancel()
    del bpy.types.Scene.hemishadow_farm
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
