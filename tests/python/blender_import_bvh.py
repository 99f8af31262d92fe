"""Import BVH files with Blender's own importer and report what Blender made of them.

Usage: python blender_import_bvh.py [--frames N,N,...] OUT.json FILE.bvh [FILE.bvh ...]

Run with the test venv's Python, where `bpy` is Blender (5.0.1) as a module. For each file:
factory settings (empty scene), `bpy.ops.import_anim.bvh(update_scene_fps=True,
update_scene_duration=True)` with the importer's default axes (-Z forward, Y up: BVH Y-up is
turned into Blender Z-up), then it records the scene rate (fps, fps_base), the frame range, the
armature's bones, the keyframe count of every F-curve of the action, and at every keyed frame
each pose bone's head position and rotation matrix in world space. With `--frames`, poses are
reported only at those Blender frames (our frame n is Blender frame n + 1), which keeps long takes
cheap. The JSON goes to OUT.json (Blender prints its own messages on stdout).

Blender 5.0 removed `Action.fcurves`: F-curves live in the layered action's channelbag for the
object's slot (`action.layers[i].strips[j].channelbag(slot).fcurves`).
"""

import json
import sys

import bpy

# Importable only once bpy is loaded.
import addon_utils  # noqa: E402


def channelbag_fcurves(obj):
    adt = obj.animation_data
    action = adt.action
    slot = adt.action_slot
    fcurves = []
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot)
            if bag is not None:
                fcurves.extend(bag.fcurves)
    return fcurves


def import_one(path, pose_frames=None):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types, "IMPORT_ANIM_OT_bvh"):
        addon_utils.enable("io_anim_bvh", default_set=True)
    result = bpy.ops.import_anim.bvh(
        filepath=path, update_scene_fps=True, update_scene_duration=True
    )
    if "FINISHED" not in result:
        raise RuntimeError("import of %s returned %s" % (path, result))

    scene = bpy.context.scene
    armatures = [o for o in scene.objects if o.type == "ARMATURE"]
    if len(armatures) != 1:
        raise RuntimeError("expected one armature, found %d" % len(armatures))
    arm = armatures[0]

    fcurves = channelbag_fcurves(arm)
    curves = []
    for fc in fcurves:
        points = fc.keyframe_points
        curves.append(
            {
                "data_path": fc.data_path,
                "index": fc.array_index,
                "keys": len(points),
                "first": points[0].co[0] if len(points) else None,
                "last": points[-1].co[0] if len(points) else None,
            }
        )

    if pose_frames is None:
        pose_frames = sorted({int(round(p.co[0])) for fc in fcurves for p in fc.keyframe_points})
    frames = []
    for frame in pose_frames:
        scene.frame_set(frame)
        bones = {}
        for pb in arm.pose.bones:
            head = arm.matrix_world @ pb.head
            rot = (arm.matrix_world @ pb.matrix).to_3x3().normalized()
            bones[pb.name] = {
                "head": list(head),
                "matrix": [list(row) for row in rot],
            }
        frames.append({"frame": frame, "bones": bones})

    return {
        "path": path,
        "fps": scene.render.fps,
        "fps_base": scene.render.fps_base,
        "frame_start": scene.frame_start,
        "frame_end": scene.frame_end,
        "bones": [b.name for b in arm.data.bones],
        "armature_matrix_world": [list(row) for row in arm.matrix_world],
        "fcurves": curves,
        "frames": frames,
    }


def main():
    args = sys.argv[1:]
    pose_frames = None
    if args and args[0] == "--frames":
        pose_frames = [int(f) for f in args[1].split(",") if f]
        args = args[2:]
    out_path = args[0]
    results = [import_one(p, pose_frames) for p in args[1:]]
    with open(out_path, "w") as f:
        json.dump({"blender": bpy.app.version_string, "files": results}, f)


if __name__ == "__main__":
    main()
