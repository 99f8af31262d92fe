"""imubake takes for Blender: import at the exact frame rate, retarget, watch a folder.

Modules: `sidecar` (reading the take's JSON, no bpy), `take_import` (BVH/GLB import and the scene
rate), `retarget` (baking onto the animator's armature), `watch` (the watch-folder poll), `ui`
(operators, menu entry, sidebar panel), `compat` (Blender 4.2 vs 5.0 animation API).
`batch_export.py` is a command-line script, not part of the registered add-on.
"""

from . import ui


def register():
    ui.register()


def unregister():
    ui.unregister()
