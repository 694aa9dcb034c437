"""The sidebar panel of the 3D view (N panel, tab "matex")."""

import bpy

from . import job


class MATEX_PT_panel(bpy.types.Panel):
    bl_label = "matex"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "matex"

    def draw(self, context):
        s = context.scene.matex
        layout = self.layout
        layout.prop(s, "weights")
        layout.prop(s, "prompt")
        layout.prop(s, "negative")
        row = layout.row(align=True)
        row.prop(s, "style_image")
        row.prop(s, "style_scale", text="Scale")
        col = layout.column(align=True)
        col.prop(s, "seed")
        col.prop(s, "views")
        col.prop(s, "steps")
        col.prop(s, "texture_size")
        layout.prop(s, "fast")
        layout.prop(s, "device")
        layout.prop(s, "storage")
        if job.active() is not None:
            wm = context.window_manager
            layout.label(text=wm.matex_status)
            layout.prop(wm, "matex_progress", text="Progress", slider=True)
            layout.operator("matex.cancel", icon="CANCEL")
            return
        layout.operator("matex.texture_selected", icon="TEXTURE")
        row = layout.row(align=True)
        row.operator("matex.enhance")
        row.prop(s, "strength")
        row = layout.row(align=True)
        row.operator("matex.transfer")
        row.prop(s, "transfer_source", text="")
        box = layout.box()
        box.prop(s, "threads")
        box.prop(s, "extra_args")


def register():
    bpy.utils.register_class(MATEX_PT_panel)


def unregister():
    bpy.utils.unregister_class(MATEX_PT_panel)
