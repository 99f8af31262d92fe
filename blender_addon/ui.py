"""Operators, the File > Import entry and the sidebar panel (View3D > Sidebar > imubake)."""

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, PointerProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import names, retarget, watch
from .take_import import TakeError, import_take

_REFERENCE_ITEMS = (
    ("AUTO", "T-pose alignment", "Turn the character's arms and legs to the take's T-pose first"),
    ("CURRENT", "Current pose", "The character's current pose matches the take's T-pose"),
    ("REST", "Rest pose", "The character's rest pose matches the take's T-pose"),
)


def _is_armature(_self, obj):
    return obj.type == "ARMATURE"


class IMUBAKE_OT_import_take(bpy.types.Operator, ImportHelper):
    """Import an imubake take at its exact frame rate; with an armature selected, retarget onto it"""

    bl_idname = "import_scene.imubake_take"
    bl_label = "Import imubake take"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".imubake.json"
    filter_glob: StringProperty(default="*.imubake.json;*.bvh;*.glb;*.gltf", options={"HIDDEN"})
    source_format: EnumProperty(
        name="Animation from",
        items=(("AUTO", "Chosen file / BVH", "The chosen .bvh/.glb, or the take's BVH"),
               ("BVH", "BVH", "The take's BVH"), ("GLB", "glTF", "The take's GLB or glTF")),
        default="AUTO",
    )
    rotation_mode: EnumProperty(
        name="glTF rotations",
        items=(("XYZ", "Euler XYZ", ""), ("ZYX", "Euler ZYX", ""), ("YXZ", "Euler YXZ", ""),
               ("QUATERNION", "Quaternion", "Keep the importer's quaternions")),
        default="XYZ",
    )
    retarget_onto_selected: BoolProperty(
        name="Retarget onto selected armature",
        description="Bake the take onto the active armature and remove the imported one",
        default=True,
    )
    reference: EnumProperty(name="Reference pose", items=_REFERENCE_ITEMS, default="AUTO")
    bone_map: StringProperty(
        name="Bone map",
        description="JSON bone map (source bone to target bone); empty: match names automatically",
        subtype="FILE_PATH",
        default="",
    )

    def execute(self, context):
        target = context.active_object if self.retarget_onto_selected else None
        if target is not None and target.type != "ARMATURE":
            target = None
        fmt = {"AUTO": None, "BVH": "bvh", "GLB": None}[self.source_format]
        if self.source_format == "GLB":
            fmt = "gltf" if self.filepath.lower().endswith(".gltf") else "glb"
        try:
            imported = import_take(context, self.filepath, fmt=fmt, rotation_mode=self.rotation_mode)
        except TakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for w in imported.warnings:
            self.report({"WARNING"}, "%s: %s" % (imported.name, w))
        if target is None:
            self.report({"INFO"}, "%s: %d frames at %s fps" % (imported.name, imported.frames, imported.take.fps))
            return {"FINISHED"}
        try:
            result = retarget.bake_imported(
                context, imported, target, reference=self.reference,
                bone_map_path=bpy.path.abspath(self.bone_map) if self.bone_map else None)
        except (retarget.RetargetError, names.BoneMapError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        context.view_layer.objects.active = target
        self.report({"INFO"}, "%s: %d frames baked onto %s (%d bones)"
                    % (result.action.name, imported.frames, target.name, len(result.bone_map)))
        return {"FINISHED"}


class IMUBAKE_OT_watch_start(bpy.types.Operator):
    """Import each new take imubake writes into the chosen folder"""

    bl_idname = "imubake.watch_start"
    bl_label = "Start watching"

    def execute(self, context):
        folder = bpy.path.abspath(context.scene.imubake_watch_folder)
        if not folder or not os.path.isdir(folder):
            self.report({"ERROR"}, "choose imubake's output folder first")
            return {"CANCELLED"}
        try:
            watch.start(folder)
        except TakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class IMUBAKE_OT_watch_stop(bpy.types.Operator):
    """Stop watching the folder"""

    bl_idname = "imubake.watch_stop"
    bl_label = "Stop watching"

    def execute(self, context):
        watch.stop()
        return {"FINISHED"}


class IMUBAKE_PT_watch(bpy.types.Panel):
    bl_label = "imubake watch folder"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "imubake"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        layout.prop(scene, "imubake_watch_folder", text="Folder")
        layout.prop(scene, "imubake_watch_target", text="Character")
        layout.prop(scene, "imubake_watch_reference", text="Reference")
        w = watch.current()
        if w is None:
            layout.operator(IMUBAKE_OT_watch_start.bl_idname, icon="PLAY")
        else:
            layout.operator(IMUBAKE_OT_watch_stop.bl_idname, icon="PAUSE")
            layout.label(text="Watching %s" % w.folder)
            for name, message in reversed(w.log[-5:]):
                layout.label(text="%s: %s" % (name, message))


def _menu_import(self, _context):
    self.layout.operator(IMUBAKE_OT_import_take.bl_idname,
                         text="imubake take (.imubake.json / .bvh / .glb)")


_CLASSES = (IMUBAKE_OT_import_take, IMUBAKE_OT_watch_start, IMUBAKE_OT_watch_stop, IMUBAKE_PT_watch)


def register():
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(_menu_import)
    bpy.types.Scene.imubake_watch_folder = StringProperty(
        name="imubake output folder", subtype="DIR_PATH", default="")
    bpy.types.Scene.imubake_watch_target = PointerProperty(
        name="Character", type=bpy.types.Object, poll=_is_armature,
        description="Armature to retarget new takes onto (none: import the take's own armature)")
    bpy.types.Scene.imubake_watch_reference = EnumProperty(
        name="Reference pose", items=_REFERENCE_ITEMS, default="AUTO")


def unregister():
    watch.stop()
    del bpy.types.Scene.imubake_watch_reference
    del bpy.types.Scene.imubake_watch_target
    del bpy.types.Scene.imubake_watch_folder
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
