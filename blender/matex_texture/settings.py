"""The panel's fields (per scene) and the add-on's preferences (the matex executable, a server)."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)


def _is_mesh(self, obj):
    return obj.type == "MESH"


class MatexSettings(bpy.types.PropertyGroup):
    weights: StringProperty(name="Weights", subtype="FILE_PATH",
                            description="matex weight file (.mxw, made by `matex convert`)")
    prompt: StringProperty(name="Prompt", description="What the object should look like")
    negative: StringProperty(name="Negative", description="What it should not look like (optional)")
    seed: IntProperty(name="Seed", default=0, min=0, description="The same seed gives the same texture")
    views: IntProperty(name="Views", default=6, min=2, max=64, description="View budget, front and back included")
    steps: IntProperty(name="Steps", default=0, min=0, max=200,
                       description="Denoising steps (0: matex's default, 10; 4 with Fast)")
    fast: BoolProperty(name="Fast", description="Few-step path (LCM + TAESD): needs a weight file made with "
                                                "convert --lcm-lora --taesd")
    style_image: StringProperty(name="Style image", subtype="FILE_PATH",
                                description="An image whose style the texture follows (IP-Adapter; optional): "
                                            "needs a weight file made with convert --image-encoder --ip-adapter")
    style_scale: FloatProperty(name="Style scale", default=0.6, min=0.0, max=2.0,
                               description="How strongly the style image steers the texture (0: not at all)")
    texture_size: IntProperty(name="Texture size", default=1024, min=16, max=8192, description="Texture side in texels")
    device: EnumProperty(name="Device", items=[("cpu", "CPU", "the CPU kernels"),
                                               ("cuda", "CUDA", "an NVIDIA GPU (a matex built by `make cuda`)")])
    storage: EnumProperty(name="Image", items=[("PACK", "Pack into .blend", "the texture is stored in the .blend"),
                                               ("SAVE", "Save beside .blend", "textures/<name>.png beside the "
                                                "saved .blend (packed while the .blend is unsaved)")])
    strength: FloatProperty(name="Strength", default=0.5, min=0.01, max=1.0,
                            description="Enhance: SDEdit strength (1 repaints)")
    transfer_source: PointerProperty(name="From", type=bpy.types.Object, poll=_is_mesh,
                                     description="Textured object whose texture moves onto the selected one "
                                                 "(same pose and units)")
    threads: IntProperty(name="Threads", default=0, min=0, description="CPU threads (0: all)")
    extra_args: StringProperty(name="Extra options",
                               description="More matex options, as on the command line (e.g. --candidates 20)")


class MatexPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    matex_path: StringProperty(name="matex executable", subtype="FILE_PATH",
                               description="Path of the matex program (empty: `matex` on PATH)")
    server_url: StringProperty(name="matex server", description="URL of a running `matex serve` "
                               "(http://127.0.0.1:8421): Texture runs there, the models loaded once (empty: "
                               "run matex here); its weights are the server's")
    server_token: StringProperty(name="Server token", subtype="PASSWORD",
                                 description="The server's token, when it has one (its --token-file)")

    def draw(self, context):
        self.layout.prop(self, "matex_path")
        self.layout.prop(self, "server_url")
        self.layout.prop(self, "server_token")


def preferences(context):
    return context.preferences.addons[__package__].preferences


classes = (MatexSettings, MatexPreferences)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.matex = PointerProperty(type=MatexSettings)
    bpy.types.WindowManager.matex_progress = FloatProperty(name="Progress", subtype="PERCENTAGE", min=0, max=100)
    bpy.types.WindowManager.matex_status = StringProperty(name="Status")


def unregister():
    del bpy.types.WindowManager.matex_status
    del bpy.types.WindowManager.matex_progress
    del bpy.types.Scene.matex
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
