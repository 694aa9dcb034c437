"""matex's output folder onto the artist's object: one material per texture, the image on the
UV map the texture was made for, packed into the .blend or saved beside it."""

import os
import re
import shutil

import bpy

from .export import material_key

TEX_NODE = "matex texture"
UV_NODE = "matex uv"


def output_textures(out_dir):
    """{material name: PNG path} from the output's mesh.mtl (README: texture.png for one
    texture under the material "matex", else texture_<material>.png per material)."""
    textures, name = {}, None
    with open(os.path.join(out_dir, "mesh.mtl"), encoding="utf-8") as f:
        for line in f:
            words = line.split(None, 1)
            if len(words) == 2 and words[0] == "newmtl":
                name = words[1].strip()
            elif len(words) == 2 and words[0] == "map_Kd" and name is not None:
                textures[name] = os.path.join(out_dir, words[1].strip())
    if not textures:
        raise ValueError("%s: no texture in the output's mesh.mtl" % out_dir)
    return textures


def textures_by_slot(out_dir, slots):
    """{slot: PNG path} for the material slots the exported mesh used."""
    textures = output_textures(out_dir)
    if len(textures) == 1:
        png = next(iter(textures.values()))
        return {slot: png for slot in slots}
    missing = [s for s in slots if material_key(s) not in textures]
    if missing:
        raise ValueError("%s: no texture for material slot(s) %s" % (out_dir, missing))
    return {slot: textures[material_key(slot)] for slot in slots}


def current_images(obj, slots):
    """{slot: image} of the textures the object shows now (the matex node, else the first image
    texture node of each slot's material): what enhance improves and transfer moves."""
    images = {}
    for slot in slots:
        mat = obj.material_slots[slot].material if slot < len(obj.material_slots) else None
        nodes = mat.node_tree.nodes if mat and mat.use_nodes else []
        node = nodes.get(TEX_NODE) if nodes else None
        if node is None or node.image is None:
            node = next((n for n in nodes if n.type == "TEX_IMAGE" and n.image), None)
        if node is None:
            raise ValueError("%s: material slot %d has no image texture (texture it first)" % (obj.name, slot))
        images[slot] = node.image
    return images


def _node(nodes, kind, name):
    node = nodes.get(name)
    if node is None or node.bl_idname != kind:
        node = nodes.new(kind)
        node.name = name
    return node


def _link_nodes(mat, uv_name, image):
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    out = next((n for n in nodes if n.type == "OUTPUT_MATERIAL"), None) or nodes.new("ShaderNodeOutputMaterial")
    bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None) or nodes.new("ShaderNodeBsdfPrincipled")
    tex = _node(nodes, "ShaderNodeTexImage", TEX_NODE)
    uv = _node(nodes, "ShaderNodeUVMap", UV_NODE)
    uv.uv_map = uv_name
    uv.location = (bsdf.location.x - 600, bsdf.location.y)
    tex.location = (bsdf.location.x - 350, bsdf.location.y)
    old = tex.image
    tex.image = image
    links.new(uv.outputs["UV"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    if not bsdf.outputs["BSDF"].is_linked:
        links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    if old is not None and old != image and old.users == 0:
        bpy.data.images.remove(old)


def _clean(name):
    return re.sub(r"[^A-Za-z0-9_-]", "_", name) or "object"


def _saved_path(png, image_name, old_image):
    """Where a saved texture goes: textures/<image name>.png beside the .blend. A file there is
    replaced only when it is the one this material showed (written by an earlier run);
    otherwise a free name is taken, so no file the artist made is overwritten."""
    folder = os.path.join(os.path.dirname(bpy.data.filepath), "textures")
    os.makedirs(folder, exist_ok=True)
    base = os.path.join(folder, _clean(image_name))
    ours = bpy.path.abspath(old_image.filepath) if old_image is not None else None
    dest, n = base + ".png", 1
    while os.path.exists(dest) and os.path.abspath(dest) != (ours and os.path.abspath(ours)):
        dest, n = "%s_%d.png" % (base, n), n + 1
    shutil.copyfile(png, dest)
    return dest


def _load_image(png, name, storage, old_image):
    if storage == "SAVE":
        dest = _saved_path(png, name, old_image)
        image = bpy.data.images.load(dest, check_existing=False)
        image.filepath = bpy.path.relpath(dest)
        image.reload()
    else:
        image = bpy.data.images.load(png, check_existing=False)
        image.pack()
        image.filepath = "//%s.png" % _clean(name)  # the name it unpacks to; the temporary file goes away
    image.name = name
    return image


def apply_textures(obj, uv_name, slot_pngs, storage):
    """Creates or updates the material "matex <object>" (one texture) or "matex <object> <slot>"
    (one per material slot) with the image on uv_name and puts it in those slots. storage:
    "PACK" (into the .blend) or "SAVE" (textures/ beside the saved .blend). Returns the
    materials."""
    per_slot = len(set(slot_pngs.values())) > 1
    names = {slot: "matex %s %d" % (obj.name, slot) if per_slot else "matex %s" % obj.name for slot in slot_pngs}
    images = {}  # every image first: a file that fails to load leaves the materials as they were
    for slot, png in sorted(slot_pngs.items()):
        if png not in images:
            mat = bpy.data.materials.get(names[slot])
            tex = mat.node_tree.nodes.get(TEX_NODE) if mat and mat.node_tree else None
            images[png] = _load_image(png, names[slot], storage, tex.image if tex else None)
    if not obj.material_slots:
        obj.data.materials.append(None)
    made = []
    for slot, png in sorted(slot_pngs.items()):
        mat = bpy.data.materials.get(names[slot]) or bpy.data.materials.new(names[slot])
        mat.use_nodes = True
        _link_nodes(mat, uv_name, images[png])
        images[png].name = names[slot]  # the replaced image is gone now: take its name, not "<name>.001"
        obj.material_slots[slot].material = mat
        if mat not in made:
            made.append(mat)
    return made
