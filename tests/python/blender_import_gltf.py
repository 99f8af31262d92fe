#!/usr/bin/env python3
"""Imports a glTF/GLB file with real Blender (the `bpy` module) and reports what came in.

usage: blender_import_gltf.py FILE [FILE ...] QUERY_JSON
  QUERY_JSON: {"bones": [names], "times": [seconds]}: the pose bones whose world-space head
  positions to report, at the given animation times (glTF key times), in every file.

Each file is imported into a fresh empty scene. Prints one JSON line per file, in the order
given, as the last lines of stdout (after anything the importer prints):
  {"path", "blender", "armatures", "armature", "bones": [names], "skinned_meshes": [{"name", "parent",
   "armature"}], "empties", "actions": [names],
   "action", "frame_range": [start, end], "scene_fps": [fps, fps_base], "frames_per_second",
   "heads": [{"time", "frame", "bones": {name: [x, y, z]}}]}
Blender's importer converts glTF's Y-up to Z-up: glTF (x, y, z) is Blender (x, -z, y).

Time → frame: the importer writes keys at frame = t * render.fps * render.fps_base
(io_scene_gltf2/blender/imp/animation_node.py), frame 0 at t = 0. For NTSC rates that product is
not the scene rate Blender plays at (fps / fps_base: fps = 30, fps_base = 1.001 would map keys at
30.03 per second), so this script leaves the scene rate at its factory value and evaluates each
requested time at the (fractional) frame the importer put its key on, through frame_set's
subframe. Every reported pose is then exactly a glTF key, with no interpolation involved.
"""
import json
import math
import sys

import bpy


def import_one(path, query):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)
    scene = bpy.context.scene

    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    # Meshes deformed by an armature (the importer also adds an unlinked "Icosphere" bone shape
    # in a `glTF_not_exported` collection; it is not counted).
    skinned = [
        {"name": o.name, "parent": o.parent.name if o.parent else None,
         "armature": next((m.object.name for m in o.modifiers if m.type == "ARMATURE" and m.object), None)}
        for o in bpy.data.objects
        if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)
    ]
    out = {
        "path": path,
        "blender": bpy.app.version_string,
        "armatures": len(arms),
        "bones": [],
        "armature": arms[0].name if len(arms) == 1 else None,
        "skinned_meshes": skinned,
        "empties": sum(1 for o in bpy.data.objects if o.type == "EMPTY"),
        "actions": sorted(a.name for a in bpy.data.actions),
        "action": None,
        "frame_range": None,
        "scene_fps": [scene.render.fps, scene.render.fps_base],
        "heads": [],
    }
    if len(arms) != 1:
        return out
    arm = arms[0]
    out["bones"] = [b.name for b in arm.data.bones]
    anim = arm.animation_data
    if anim is not None and anim.action is not None:
        out["action"] = anim.action.name
        out["frame_range"] = list(anim.action.frame_range)

    # The importer's own factor (see the module docstring).
    per_second = scene.render.fps * scene.render.fps_base
    out["frames_per_second"] = per_second
    for t in query["times"]:
        frame = t * per_second
        whole = math.floor(frame)
        scene.frame_set(whole, subframe=frame - whole)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = arm.evaluated_get(depsgraph)
        heads = {}
        for name in query["bones"]:
            pb = evaluated.pose.bones[name]
            heads[name] = list(evaluated.matrix_world @ pb.head)
        out["heads"].append({"time": t, "frame": frame, "bones": heads})
    return out


def main():
    *paths, query = sys.argv[1:]
    query = json.loads(query)
    results = [import_one(path, query) for path in paths]
    for out in results:
        print(json.dumps(out))


main()
