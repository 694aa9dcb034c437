"""The matex add-on in a real Blender, headless (tests/blender/run.sh sets the environment):
installed from its zip, it textures Suzanne with a UV map (and a subdivision modifier, so the
evaluated mesh is what goes out), Suzanne without one (Smart UV Project), and a two-material
cube (one texture per material); checks each material's image (size, the UV islands painted,
not empty) and that the object's mesh and UVs are what they were; renders a frame with Cycles
on the CPU and checks the object is textured in it (against the same frame untextured);
enhances and transfers; cancels a run in the middle and checks nothing changed; and checks a
bad weight path and a style image that is not an image end in matex's message in the operator's
report; and textures through a running `matex serve` set in the preferences."""

import json
import math
import os
import subprocess
import sys
import time

import bpy

MATEX = os.environ["MATEX"]
WEIGHTS = os.environ["MATEX_DEMO_WEIGHTS"]
TMP = os.environ["MATEX_BLENDER_TMP"]
SIZE = 256
failures = 0


def check(name, cond):
    global failures
    print(("ok   " if cond else "FAIL ") + name)
    failures += 0 if cond else 1


def snapshot(obj):
    """What the artist has: geometry, every UV map, the active one, modifiers, transform."""
    me = obj.data
    co = [0.0] * (3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    return {
        "co": co,
        "polys": [tuple(p.vertices) for p in me.polygons],
        "mat_index": [p.material_index for p in me.polygons],
        "uvs": {l.name: [tuple(d.uv) for d in l.data] for l in me.uv_layers},
        "active_uv": me.uv_layers.active.name if me.uv_layers.active else None,
        "mods": [m.name for m in obj.modifiers],
        "matrix": [tuple(r) for r in obj.matrix_world],
    }


def slot_materials(obj):
    return [s.material.name if s.material else None for s in obj.material_slots]


def pixels(image):
    px = [0.0] * (image.size[0] * image.size[1] * 4)
    image.pixels.foreach_get(px)
    return px


def island_mask(obj, uv_name, size, slot=None):
    """Texels (x, y) whose centre lies in a UV triangle of the object's own mesh (of one slot)."""
    me = obj.data
    me.calc_loop_triangles()
    uv = me.uv_layers[uv_name].data
    mask = set()
    for tri in me.loop_triangles:
        if slot is not None and tri.material_index != slot:
            continue
        p = [(uv[l].uv.x * size, uv[l].uv.y * size) for l in tri.loops]
        area = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1])
        if abs(area) < 1e-12:
            continue
        x0, x1 = max(0, int(min(q[0] for q in p))), min(size - 1, int(max(q[0] for q in p)))
        y0, y1 = max(0, int(min(q[1] for q in p))), min(size - 1, int(max(q[1] for q in p)))
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                cx, cy = x + 0.5, y + 0.5
                w = [((p[(i + 1) % 3][0] - cx) * (p[(i + 2) % 3][1] - cy)
                      - (p[(i + 2) % 3][0] - cx) * (p[(i + 1) % 3][1] - cy)) / area for i in range(3)]
                if min(w) >= 0:
                    mask.add((x, y))
    return mask


def check_image(label, obj, image, uv_name, slot=None):
    """Size; the UV islands painted (no texel left at the untouched value) and not flat."""
    check(label + ": image is %dx%d" % (SIZE, SIZE), tuple(image.size) == (SIZE, SIZE))
    if tuple(image.size) != (SIZE, SIZE):
        return
    px = pixels(image)
    mask = island_mask(obj, uv_name, SIZE, slot)
    check(label + ": the UV islands cover texels", len(mask) > 500)
    inside = [tuple(px[4 * (y * SIZE + x):4 * (y * SIZE + x) + 3]) for (x, y) in mask]
    if not inside:
        return
    painted = sum(1 for c in inside if max(c) - min(c) > 1e-3 or c[0] not in (0.0, 0.5))
    check(label + ": %.3f of the island texels painted" % (painted / len(inside)), painted >= 0.97 * len(inside))
    mean = [sum(c[i] for c in inside) / len(inside) for i in range(3)]
    var = sum((c[i] - mean[i]) ** 2 for c in inside for i in range(3)) / (3 * len(inside))
    check(label + ": texture not flat (std %.3f)" % math.sqrt(var), math.sqrt(var) > 0.02)


def tex_image(mat):
    node = mat.node_tree.nodes.get("matex texture") if mat and mat.use_nodes else None
    return node.image if node else None


def select_only(obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj


def add_monkey(name, location, uv=True):
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.name = name
    if not uv:
        while obj.data.uv_layers:
            obj.data.uv_layers.remove(obj.data.uv_layers[0])
    return obj


def run_operator(op, obj):
    select_only(obj)
    try:
        return op(), None
    except RuntimeError as e:  # an ERROR report of the operator
        return None, str(e)


def setup():
    bpy.ops.preferences.addon_install(filepath=os.environ["MATEX_ADDON_ZIP"])
    bpy.ops.preferences.addon_enable(module="matex_texture")
    check("add-on installed from the zip and enabled", "matex_texture" in bpy.context.preferences.addons)
    bpy.context.preferences.addons["matex_texture"].preferences.matex_path = MATEX
    for o in list(bpy.data.objects):
        if o.type == "MESH":
            bpy.data.objects.remove(o)
    s = bpy.context.scene.matex
    s.weights, s.prompt, s.steps, s.views, s.texture_size = WEIGHTS, "a red monkey", 2, 4, SIZE
    s.extra_args = "--image-size 64 --render-size 256 --candidates 8"
    return s


def test_stream_in_blender_python():
    """Every line of `--progress json` parses with Blender's own Python json module."""
    out = os.path.join(TMP, "stream")
    mesh = os.path.join(TMP, "stream.obj")
    with open(mesh, "w") as f:
        f.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    p = subprocess.run([MATEX, "texture", mesh, "a \"quoted\" prompt", "--weights", WEIGHTS, "-o", out, "--progress",
                        "json", "--image-size", "64", "--steps", "2", "--texture-size", "64", "--render-size", "64",
                        "--candidates", "8"], capture_output=True, text=True)
    lines = p.stdout.splitlines()
    events = [json.loads(l) for l in lines]
    check("stream: %d lines, each a JSON object" % len(lines), lines and all(isinstance(e, dict) for e in events))
    check("stream: step events", any(e["event"] == "step" for e in events))
    check("stream: result last, ok, exit 0", events[-1] == {**events[-1], "event": "result", "ok": True, "exit": 0})
    check("stream: output folder layout", all(os.path.isfile(os.path.join(out, f)) for f in
          ("texture.png", "texture.exr", "mesh.obj", "mesh.mtl", "mesh.glb", "report.json", ".matex-output")))


def test_texture_with_uvs(s):
    obj = add_monkey("Suzanne", (0, 0, 0))
    obj.modifiers.new("subdiv", "SUBSURF").levels = 1
    before = snapshot(obj)
    t0 = time.time()
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    check("texture (UVs, subdivision modifier) finished: %s (%.1f s)" % (err, time.time() - t0), res == {"FINISHED"})
    check("mesh, UVs, modifiers unchanged", snapshot(obj) == before)
    check("material 'matex Suzanne' in its slot", slot_materials(obj) == ["matex Suzanne"])
    image = tex_image(obj.material_slots[0].material) if obj.material_slots else None
    check("image packed", image is not None and image.packed_file is not None)
    if image:
        check_image("Suzanne", obj, image, "UVMap")
    uv_node = obj.material_slots[0].material.node_tree.nodes.get("matex uv") if obj.material_slots else None
    check("material reads the object's UV map", uv_node is not None and uv_node.uv_map == "UVMap")
    return obj


def test_texture_without_uvs(s):
    obj = add_monkey("Bare", (3, 0, 0), uv=False)
    before = snapshot(obj)
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    check("texture (no UV map) finished: %s" % err, res == {"FINISHED"})
    after = snapshot(obj)
    check("a new UV map 'UVMap', active", after["active_uv"] == "UVMap" and list(after["uvs"]) == ["UVMap"])
    new_uvs = after["uvs"].pop("UVMap")
    after["active_uv"] = None
    check("otherwise unchanged", after == before)
    check("Smart UV Project's UVs in [0, 1]", all(0 <= u <= 1 and 0 <= v <= 1 for u, v in new_uvs))
    image = tex_image(obj.material_slots[0].material) if obj.material_slots else None
    if image:
        check_image("Bare", obj, image, "UVMap")
    else:
        check("Bare has its image", False)


def test_multi_material(s):
    bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0, 3, 0))
    obj = bpy.context.active_object
    obj.name = "Cube"
    for name in ("wood", "metal"):
        obj.data.materials.append(bpy.data.materials.new(name))
    for i, p in enumerate(obj.data.polygons):
        p.material_index = 0 if i < 3 else 1
    before = snapshot(obj)
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    check("two-material cube finished: %s" % err, res == {"FINISHED"})
    check("mesh and UVs unchanged", snapshot(obj) == before)
    check("one material per slot", slot_materials(obj) == ["matex Cube 0", "matex Cube 1"])
    images = [tex_image(m.material) for m in obj.material_slots]
    check("two images", len(images) == 2 and all(images) and images[0] != images[1])
    for slot, image in enumerate(images):
        if image:
            check_image("Cube slot %d" % slot, obj, image, "UVMap", slot)


def render_chroma(obj, path):
    """Renders the frame (Cycles, CPU) to path; mean |R-G|+|G-B| over the object's pixels and
    how many there are. Lit by a white world, an untextured grey object has no chroma."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 4
    scene.cycles.use_denoising = False  # Debian builds Cycles without OpenImageDenoise
    scene.render.resolution_x = scene.render.resolution_y = 64
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.view_settings.view_transform = "Standard"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    px = pixels(img)
    bpy.data.images.remove(img)
    obj_px = [px[i:i + 4] for i in range(0, len(px), 4) if px[i + 3] > 0.5]
    chroma = sum(abs(p[0] - p[1]) + abs(p[1] - p[2]) for p in obj_px) / max(1, len(obj_px))
    return chroma, len(obj_px)


def test_render(obj):
    scene = bpy.context.scene
    for o in bpy.context.view_layer.objects:
        o.hide_render = o.type == "MESH" and o != obj
    cam = scene.camera
    cam.location = (0, -3, 0)
    cam.rotation_euler = (math.pi / 2, 0, 0)
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    textured, n = render_chroma(obj, os.path.join(TMP, "textured.png"))
    check("render: the object fills %d pixels" % n, n > 500)
    mat = obj.material_slots[0].material
    link = mat.node_tree.nodes["matex texture"].outputs["Color"].links[0]
    mat.node_tree.links.remove(link)
    plain, _ = render_chroma(obj, os.path.join(TMP, "plain.png"))
    check("render: textured chroma %.3f, untextured %.3f" % (textured, plain), textured > 0.05 and textured > 4 * plain)
    tex = mat.node_tree.nodes["matex texture"]
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])


def test_enhance_and_transfer(s, obj):
    old = pixels(tex_image(obj.material_slots[0].material))
    s.strength = 0.6
    res, err = run_operator(bpy.ops.matex.enhance, obj)
    check("enhance finished: %s" % err, res == {"FINISHED"})
    image = tex_image(obj.material_slots[0].material)
    check("enhance replaced the image", image is not None and pixels(image) != old)
    check("enhance: the material's one image, same name",
          [i.name for i in bpy.data.images if i.name.startswith("matex Suzanne")] == ["matex Suzanne"])
    copy = add_monkey("Copy", (0, 0, 0), uv=False)
    s.transfer_source = obj
    extra, s.extra_args = s.extra_args, "--candidates 8"  # transfer has no networks: no --image-size
    res, err = run_operator(bpy.ops.matex.transfer, copy)
    s.extra_args = extra
    check("transfer finished: %s" % err, res == {"FINISHED"})
    image = tex_image(copy.material_slots[0].material) if copy.material_slots else None
    if image:
        check_image("transfer", copy, image, "UVMap")
    else:
        check("transfer made an image", False)
    bpy.data.objects.remove(copy)


def test_cancel(s):
    from matex_texture import job

    obj = add_monkey("Cancelled", (-3, 0, 0), uv=False)
    before, mats, images = snapshot(obj), len(bpy.data.materials), len(bpy.data.images)
    steps, extra = s.steps, s.extra_args
    s.steps, s.extra_args = 50, "--image-size 128 --render-size 512 --candidates 12"
    select_only(obj)
    j = job.Job(obj, "texture", s, MATEX)
    j.start(bpy.context)
    tmp = j.tmp
    t0 = time.time()
    while not j.poll() and "step" not in j.status and time.time() - t0 < 60:
        time.sleep(0.02)
    check("a step reported before the cancel (%s)" % j.status, "step" in j.status)
    bpy.ops.matex.cancel()
    while not j.poll() and time.time() - t0 < 60:
        time.sleep(0.05)
    s.steps, s.extra_args = steps, extra
    check("cancelled: matex exit 130", j.run.result.get("exit") == 130 and j.error == "cancelled")
    after = snapshot(obj)
    check("cancelled: object as it was (the new UV map removed)%s" % "".join(
          " differs: %s" % k for k in before if before[k] != after[k]),
          after == before and not obj.material_slots)
    check("cancelled: no material, no image", len(bpy.data.materials) == mats and len(bpy.data.images) == images)
    check("cancelled: nothing left on disk", not os.path.exists(tmp))
    check("cancelled: no job running", job.active() is None)
    return obj


def test_bad_weights(s, obj):
    before, weights = snapshot(obj), s.weights
    s.weights = os.path.join(TMP, "none.mxw")
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    s.weights = weights
    check("bad weights: the operator fails", res is None and err is not None)
    check("bad weights: matex's message in the report (%s)" % (err or "").strip(),
          err is not None and "none.mxw: cannot open" in err)
    check("bad weights: object as it was", snapshot(obj) == before and not obj.material_slots)


def test_style_image(s, obj):
    """The style image field goes to matex as --style-image: a file that is not an image ends in
    matex's message naming it, before any work, and the object stays as it was; a real image
    textures the object."""
    before = snapshot(obj)
    notes = os.path.join(TMP, "notes.png")
    with open(notes, "w") as f:
        f.write("not a picture\n")
    s.style_image = notes
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    s.style_image = ""
    check("style image: the operator fails", res is None and err is not None)
    check("style image: matex's message naming it (%s)" % (err or "").strip(),
          err is not None and "notes.png: style image is not an image" in err)
    check("style image: object as it was", snapshot(obj) == before and not obj.material_slots)
    # a real image: the demo weights hold a tiny image encoder and IP-Adapter, so the run finishes
    image = bpy.data.images.new("matex_style_test", 8, 8)
    image.pixels.foreach_set([(i % 7) / 6.0 for i in range(8 * 8 * 4)])
    image.filepath_raw, image.file_format = os.path.join(TMP, "style.png"), "PNG"
    image.save()
    bpy.data.images.remove(image)
    s.style_image, s.style_scale = os.path.join(TMP, "style.png"), 0.8
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    s.style_image = ""
    check("style image: a real one, finished: %s" % err, res == {"FINISHED"})
    check("style image: the object textured", len(obj.material_slots) > 0)


def test_saved_beside_blend(s):
    """Storage "SAVE": the texture goes to textures/ beside the saved .blend, a relative path."""
    blend = os.path.join(TMP, "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    obj = add_monkey("Saved", (0, -3, 0))
    s.storage = "SAVE"
    res, err = run_operator(bpy.ops.matex.texture_selected, obj)
    s.storage = "PACK"
    check("saved: finished: %s" % err, res == {"FINISHED"})
    image = tex_image(obj.material_slots[0].material) if obj.material_slots else None
    path = os.path.join(TMP, "textures", "matex_Saved.png")
    check("saved: textures/matex_Saved.png beside the .blend", os.path.isfile(path))
    check("saved: the image reads it by a relative path, not packed",
          image is not None and image.filepath == "//textures/matex_Saved.png" and image.packed_file is None)
    if image:
        check_image("saved", obj, image, "UVMap")


def test_server(s):
    """With a server in the preferences, Texture runs there: the matex path is made invalid, so
    only the server can texture; a bad option ends in the server's message."""
    jobs = os.path.join(TMP, "serve-jobs")
    srv = subprocess.Popen([MATEX, "serve", "--weights", WEIGHTS, "--listen", "127.0.0.1:0", "--jobs", jobs],
                           stderr=subprocess.PIPE, text=True)
    line = srv.stderr.readline()
    url = line.split("listening on ")[1].split("/v1")[0] if "listening on " in line else ""
    check("server started: %s" % line.strip(), url.startswith("http://127.0.0.1:"))
    prefs = bpy.context.preferences.addons["matex_texture"].preferences
    prefs.server_url, prefs.matex_path = url, os.path.join(TMP, "no-such-matex")
    try:
        obj = add_monkey("Served", (6, 0, 0))
        before = snapshot(obj)
        res, err = run_operator(bpy.ops.matex.texture_selected, obj)
        check("texture through the server finished: %s" % err, res == {"FINISHED"})
        check("served: mesh and UVs unchanged", snapshot(obj) == before)
        image = tex_image(obj.material_slots[0].material) if obj.material_slots else None
        if image:
            check_image("served", obj, image, "UVMap")
        check("served: the server keeps no copy", [d for d in os.listdir(jobs) if not d.startswith(".")] == [])
        extra = s.extra_args
        s.extra_args = extra + " --colour red"
        res, err = run_operator(bpy.ops.matex.texture_selected, add_monkey("Refused", (9, 0, 0)))
        s.extra_args = extra
        check("served: a bad option ends in the server's message (%s)" % err, res is None and "unknown key" in (err or ""))
    finally:
        prefs.server_url, prefs.matex_path = "", MATEX
        srv.terminate()
        srv.wait(timeout=30)
    check("server stopped cleanly on SIGTERM", srv.returncode == 0)


def main():
    t0 = time.time()
    s = setup()
    test_stream_in_blender_python()
    suzanne = test_texture_with_uvs(s)
    test_texture_without_uvs(s)
    test_multi_material(s)
    test_render(suzanne)
    test_enhance_and_transfer(s, suzanne)
    bare = test_cancel(s)
    test_bad_weights(s, bare)
    test_style_image(s, bare)
    test_saved_beside_blend(s)
    test_server(s)
    print("test_addon: %d check(s) failed, %.1f s (Blender %s)" % (failures, time.time() - t0, bpy.app.version_string))
    sys.exit(1 if failures else 0)


main()
