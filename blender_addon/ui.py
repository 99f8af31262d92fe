"""Operators, the File > Import entry and the sidebar panel (View3D > Sidebar > imubake)."""

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, PointerProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import live_view, names, retarget, watch
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


_LIVE_REFERENCE_ITEMS = (
    ("AUTO", "T-pose alignment", "Turn the character's arms and legs to the performer's T-pose first"),
    ("REST", "Rest pose", "The character's rest pose matches the performer's T-pose"),
    ("CURRENT", "Current pose", "The character's current pose matches the performer's T-pose"),
)


class IMUBAKE_OT_live_start(bpy.types.Operator):
    """Show the VMC stream (imubake live, or any VMC performer) on the character"""

    bl_idname = "imubake.live_start"
    bl_label = "Start live view"

    def execute(self, context):
        scene = context.scene
        target = scene.imubake_live_target
        if target is None or target.type != "ARMATURE":
            self.report({"ERROR"}, "choose the character (an armature) first")
            return {"CANCELLED"}
        host, _, port = scene.imubake_live_performer.rpartition(":")
        try:
            live_view.start(target, scene.imubake_live_port, scene.imubake_live_reference,
                            (host or "127.0.0.1", int(port)))
        except (OSError, ValueError, retarget.RetargetError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class IMUBAKE_OT_live_stop(bpy.types.Operator):
    """Stop the live view (a recording under way ends, its action kept)"""

    bl_idname = "imubake.live_stop"
    bl_label = "Stop live view"

    def execute(self, context):
        s = live_view.current()
        if s is not None and s.recording is not None:
            s.stop_recording()
        live_view.stop()
        return {"FINISHED"}


def _live_session(op):
    """The live view under way, or None after telling the user to start it."""
    s = live_view.current()
    if s is None:
        op.report({"ERROR"}, "start the live view first")
    return s


class IMUBAKE_OT_live_record(bpy.types.Operator):
    """Record what the live view shows into a new action (again: stop recording)"""

    bl_idname = "imubake.live_record"
    bl_label = "Record"

    def execute(self, context):
        s = _live_session(self)
        if s is None:
            return {"CANCELLED"}
        if s.recording is None:
            s.start_recording(context)
        else:
            action = s.stop_recording()
            self.report({"INFO"}, "recorded %s" % action.name)
        return {"FINISHED"}


class IMUBAKE_OT_live_recalibrate(bpy.types.Operator):
    """Ask imubake live to calibrate again (hold the mapping's pose)"""

    bl_idname = "imubake.live_recalibrate"
    bl_label = "Recalibrate"

    def execute(self, context):
        s = _live_session(self)
        if s is None:
            return {"CANCELLED"}
        try:
            s.recalibrate()
        except OSError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class IMUBAKE_PT_live(bpy.types.Panel):
    bl_label = "imubake live"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "imubake"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        s = live_view.current()
        col = layout.column()
        col.enabled = s is None
        col.prop(scene, "imubake_live_port", text="UDP port")
        col.prop(scene, "imubake_live_target", text="Character")
        col.prop(scene, "imubake_live_reference", text="Reference")
        col.prop(scene, "imubake_live_performer", text="Performer")
        if s is None:
            layout.operator(IMUBAKE_OT_live_start.bl_idname, icon="PLAY")
            return
        row = layout.row()
        row.operator(IMUBAKE_OT_live_stop.bl_idname, icon="PAUSE")
        row.operator(IMUBAKE_OT_live_record.bl_idname,
                     text="Stop recording" if s.recording else "Record", icon="REC")
        layout.operator(IMUBAKE_OT_live_recalibrate.bl_idname, icon="ARMATURE_DATA")
        last = "–" if s.last_t is None else "%.2f s" % s.last_t
        layout.label(text="%.0f packets/s · last frame %s · %d bad" % (
            s.packets_per_second(), last, s.receiver.bad))
        layout.label(text="bones matched %d, unmatched %d" % (
            len(s.view.matched), len(s.view.unmatched)))
        if s.recording is not None:
            layout.label(text="recording: %d keys" % s.keys)
        if s.error:
            layout.label(text=s.error, icon="ERROR")


def _menu_import(self, _context):
    self.layout.operator(IMUBAKE_OT_import_take.bl_idname,
                         text="imubake take (.imubake.json / .bvh / .glb)")


_CLASSES = (IMUBAKE_OT_import_take, IMUBAKE_OT_watch_start, IMUBAKE_OT_watch_stop, IMUBAKE_PT_watch,
            IMUBAKE_OT_live_start, IMUBAKE_OT_live_stop, IMUBAKE_OT_live_record, IMUBAKE_OT_live_recalibrate,
            IMUBAKE_PT_live)


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
    bpy.types.Scene.imubake_live_port = IntProperty(
        name="UDP port", default=39539, min=1, max=65535,
        description="Where VMC arrives (imubake live --vmc; the VMC Marionette's port)")
    bpy.types.Scene.imubake_live_target = PointerProperty(
        name="Character", type=bpy.types.Object, poll=_is_armature,
        description="The armature the live view poses")
    bpy.types.Scene.imubake_live_reference = EnumProperty(
        name="Reference pose", items=_LIVE_REFERENCE_ITEMS, default="AUTO")
    bpy.types.Scene.imubake_live_performer = StringProperty(
        name="Performer", default="127.0.0.1:39540",
        description="Where Recalibrate sends VMC's calibration request (imubake live --listen)")


def unregister():
    live_view.stop()
    for prop in ("imubake_live_performer", "imubake_live_reference", "imubake_live_target", "imubake_live_port"):
        delattr(bpy.types.Scene, prop)
    watch.stop()
    del bpy.types.Scene.imubake_watch_reference
    del bpy.types.Scene.imubake_watch_target
    del bpy.types.Scene.imubake_watch_folder
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
