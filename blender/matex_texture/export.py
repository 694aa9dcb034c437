"""What the add-on hands matex: the object's evaluated mesh as an OBJ written here (so that the
vertex order, the triangles and every UV are exactly Blender's), and for enhance/transfer the
object's current textures as PNG files beside it."""

import os

import bpy


def material_key(slot_index):
    """The OBJ material name of a material slot. matex writes texture_<name>.png per material
    for a mesh with several materials that keep their own UVs; index names make that mapping
    exact whatever the artist called the materials."""
    return "m%d" % slot_index


def evaluated_mesh(obj, depsgraph):
    """The object's mesh with its modifiers applied, in object space; free with
    obj_eval.to_mesh_clear()."""
    obj_eval = obj.evaluated_get(depsgraph)
    mesh = obj_eval.to_mesh()
    mesh.calc_loop_triangles()
    return obj_eval, mesh


def write_obj(path, mesh, uv_name, matrix=None, textures=None):
    """Writes mesh's triangles with the UV map uv_name (one vt per loop) as an OBJ, faces grouped
    by material slot (usemtl m<slot>). matrix: applied to positions (transfer's source into the
    destination's object space). textures: {slot: png path} adds an .mtl with map_Kd lines
    (enhance and transfer read the textures from there). Returns the slots used."""
    uv_layer = mesh.uv_layers.get(uv_name) if uv_name else None
    if uv_layer is None:
        raise ValueError("the mesh has no UV map %r" % uv_name)
    by_slot = {}
    for tri in mesh.loop_triangles:
        by_slot.setdefault(tri.material_index, []).append(tri.loops)
    lines = []
    if textures:
        mtl = os.path.splitext(path)[0] + ".mtl"
        with open(mtl, "w", encoding="utf-8") as f:
            for slot, png in sorted(textures.items()):
                f.write("newmtl %s\nmap_Kd %s\n" % (material_key(slot), os.path.basename(png)))
        lines.append("mtllib %s" % os.path.basename(mtl))
    for v in mesh.vertices:
        co = matrix @ v.co if matrix is not None else v.co
        lines.append("v %.9g %.9g %.9g" % (co.x, co.y, co.z))
    for loop_uv in uv_layer.data:
        lines.append("vt %.9g %.9g" % (loop_uv.uv.x, loop_uv.uv.y))
    loops = mesh.loops
    for slot in sorted(by_slot):
        lines.append("usemtl %s" % material_key(slot))
        for tri in by_slot[slot]:
            lines.append("f " + " ".join("%d/%d" % (loops[l].vertex_index + 1, l + 1) for l in tri))
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")
    return sorted(by_slot)


def save_png(image, path):
    """image's pixels, unconverted, to an 8-bit PNG: through a new image of the same size, so a
    packed or generated image works too and no view transform is applied."""
    w, h = image.size
    if w == 0 or h == 0:
        raise ValueError("image %r has no pixels (missing file?)" % image.name)
    pixels = [0.0] * (w * h * 4)
    image.pixels.foreach_get(pixels)
    copy = bpy.data.images.new("matex_export", w, h, alpha=True)
    try:
        copy.pixels.foreach_set(pixels)
        copy.filepath_raw = path
        copy.file_format = "PNG"
        copy.save()
    finally:
        bpy.data.images.remove(copy)
