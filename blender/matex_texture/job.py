"""One texturing job on the selected object: prepare (UV map, export), run matex through its
progress stream, then put the result on the object or leave it as it was.

The object is changed only when matex succeeded (the material) and by the UV map made when it
had none (Smart UV Project); that UV map is removed again when the run fails or is cancelled,
so a cancelled job leaves the object exactly as the artist had it."""

import os
import shlex
import shutil
import tempfile

import bpy

from . import export, material, server, stream

# The one job running (the add-on runs one matex at a time); the Cancel button reaches it here.
_active = None


def active():
    return _active


def _uv_select_state(mesh):
    state = {}
    for name, seq in (("verts", mesh.vertices), ("edges", mesh.edges), ("faces", mesh.polygons)):
        flags = [False] * len(seq)
        seq.foreach_get("select", flags)
        state[name] = flags
    return state


def _restore_select_state(mesh, state):
    for name, seq in (("verts", mesh.vertices), ("edges", mesh.edges), ("faces", mesh.polygons)):
        seq.foreach_set("select", state[name])


def smart_uv_project(context, obj):
    """A new UV map "UVMap" on the object's own mesh, unwrapped by Blender's Smart UV Project
    (the mesh's selection is put back as it was). Returns the map's name."""
    mesh = obj.data
    layer = mesh.uv_layers.new(name="UVMap")
    mesh.uv_layers.active = layer
    name = layer.name  # the layer's Python object does not survive the trip through edit mode
    selection = _uv_select_state(mesh)
    view_layer = context.view_layer
    previous = view_layer.objects.active
    view_layer.objects.active = obj
    try:
        with context.temp_override(active_object=obj, object=obj, selected_objects=[obj],
                                   selected_editable_objects=[obj], edit_object=obj):
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.select_all(action="SELECT")
            bpy.ops.uv.smart_project(island_margin=0.02)
            bpy.ops.object.mode_set(mode="OBJECT")
    except RuntimeError:
        if obj.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        mesh.uv_layers.remove(mesh.uv_layers[name])
        raise
    finally:
        view_layer.objects.active = previous
    _restore_select_state(mesh, selection)
    return name


def _common_args(s):
    """Options every verb takes, then the artist's extra options (shlex: quotes work)."""
    args = ["--up", "z", "--threads", str(s.threads)] if s.threads > 0 else ["--up", "z"]
    return args + shlex.split(s.extra_args)


def _network_args(s):
    args = ["--weights", bpy.path.abspath(s.weights), "--seed", str(s.seed), "--views", str(s.views),
            "--texture-size", str(s.texture_size), "--device", s.device]
    if s.fast:
        args.append("--fast")
    if s.steps > 0:
        args += ["--steps", str(s.steps)]
    if s.negative:
        args += ["--negative", s.negative]
    if s.style_image:
        args += ["--style-image", bpy.path.abspath(s.style_image), "--style-scale", "%g" % s.style_scale]
    return args


class Job:
    """mode: "texture", "enhance" or "transfer". Call start(), then poll() until it returns
    True; cancel() may come at any time."""

    def __init__(self, obj, mode, settings, matex, server_url="", server_token=""):
        """server_url: a `matex serve` that textures (enhance and transfer still run matex here)."""
        self.obj, self.mode, self.s, self.matex = obj, mode, settings, matex
        self.server = (server_url, server_token) if server_url and mode == "texture" else None
        # saved beside the .blend only once there is one; packed until then
        self.storage = settings.storage if bpy.data.filepath else "PACK"
        self.added_uv = None
        self.uv_name = None
        self.tmp = None
        self.run = None
        self.mesh_path = self.out = None
        self.slots = []
        self.fraction, self.status = 0.0, "matex: starting"
        self.error = None
        self.ok = False

    def start(self, context):
        """Prepares and starts matex; raises ValueError with a message for the artist."""
        global _active
        if _active is not None:
            raise ValueError("matex is already running (cancel it first)")
        if self.mode != "transfer" and not self.s.weights and self.server is None:
            raise ValueError("set the weight file (.mxw) in the matex panel")
        if self.mode == "texture" and not self.s.prompt.strip():
            raise ValueError("type a prompt in the matex panel")
        self.tmp = tempfile.mkdtemp(prefix="matex_blender_")
        try:
            argv = self._prepare(context)
            if self.server is not None:
                style = [bpy.path.abspath(self.s.style_image)] if self.s.style_image else []
                self.run = server.ServerRun(self.server[0], self.server[1], self.mesh_path,
                                            server.options(self.s, self.s.extra_args), style, self.out)
            else:
                self.run = stream.MatexRun(argv)
        except Exception:
            self._undo()
            raise
        _active = self

    def _prepare(self, context):
        obj, s = self.obj, self.s
        if obj.data.uv_layers.active is None:
            if self.mode == "enhance":
                raise ValueError("%s has no UV map: texture it first" % obj.name)
            self.added_uv = smart_uv_project(context, obj)
        self.uv_name = obj.data.uv_layers.active.name
        depsgraph = context.evaluated_depsgraph_get()
        mesh_path = self.mesh_path = os.path.join(self.tmp, "input.obj")
        out = self.out = os.path.join(self.tmp, "out")
        textures = self._texture_files(obj, "input") if self.mode == "enhance" else None
        self.slots = self._write(obj, depsgraph, mesh_path, self.uv_name, None, textures)
        if self.mode == "texture":
            return [self.matex, "texture", mesh_path, s.prompt, "-o", out] + _network_args(s) + _common_args(s)
        if self.mode == "enhance":
            return ([self.matex, "enhance", mesh_path, s.prompt, "--strength", "%g" % s.strength, "-o", out]
                    + _network_args(s) + _common_args(s))
        return [self.matex, "transfer", self._write_source(context, depsgraph), mesh_path, "-o", out,
                "--views", str(s.views), "--size", str(s.texture_size)] + _common_args(s)

    def _write(self, obj, depsgraph, path, uv_name, matrix, textures):
        obj_eval, mesh = export.evaluated_mesh(obj, depsgraph)
        try:
            return export.write_obj(path, mesh, uv_name, matrix, textures)
        finally:
            obj_eval.to_mesh_clear()

    def _texture_files(self, obj, prefix):
        """The object's current textures as PNGs in the job's folder: {slot: path}."""
        slots = sorted({p.material_index for p in obj.data.polygons})
        files = {}
        for slot, image in material.current_images(obj, slots).items():
            files[slot] = os.path.join(self.tmp, "%s_%d.png" % (prefix, slot))
            export.save_png(image, files[slot])
        return files

    def _write_source(self, context, depsgraph):
        """transfer: the source object, textured, moved into the destination's object space."""
        src = self.s.transfer_source
        if src is None or src.type != "MESH" or src == self.obj:
            raise ValueError("choose another mesh object to transfer from")
        if src.data.uv_layers.active is None:
            raise ValueError("%s has no UV map: nothing to transfer" % src.name)
        path = os.path.join(self.tmp, "source.obj")
        matrix = self.obj.matrix_world.inverted() @ src.matrix_world
        self._write(src, depsgraph, path, src.data.uv_layers.active.name, matrix, self._texture_files(src, "source"))
        return path

    def poll(self):
        """Reads matex's new events; when it has ended, applies or undoes. True when done."""
        for event in self.run.poll():
            if event.get("event") in ("step", "stage"):
                self.fraction = max(self.fraction, stream.progress_fraction(event))
                self.status = stream.describe(event)
        if not self.run.done():
            return False
        self._finish()
        return True

    def _finish(self):
        global _active
        result = self.run.result
        try:
            if result.get("ok"):
                slot_pngs = material.textures_by_slot(result["out"], self.slots)
                material.apply_textures(self.obj, self.uv_name, slot_pngs, self.storage)
                self.ok = True
                self.status = "matex: done, coverage %.3f in %.1f s" % (result.get("coverage", 0), result.get("seconds", 0))
            else:
                self.error = "cancelled" if self.run.cancelled else result.get("error", "matex failed")
        except (OSError, ValueError, RuntimeError) as e:
            self.error = str(e)
        finally:
            if not self.ok:
                self._undo()
            shutil.rmtree(self.tmp, ignore_errors=True)
            _active = None

    def _undo(self):
        """Back to the object as it was: the UV map this job made goes away."""
        if self.added_uv is not None:
            layer = self.obj.data.uv_layers.get(self.added_uv)
            if layer is not None:
                self.obj.data.uv_layers.remove(layer)
            self.added_uv = None
        if self.tmp:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def cancel(self):
        if self.run is not None:
            self.run.cancel()
