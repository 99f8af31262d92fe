"""Import one BVH file with Blender's own importer and report the pose bones' Euler values.

Usage: python blender_bvh_pose_euler.py OUT.json FILE.bvh MODES FRAMES BONES

MODES, FRAMES and BONES are comma-separated: importer `rotate_mode`s (NATIVE, XYZ, ...), Blender
scene frames (our frame n is Blender frame n + 1), pose bone names. Run with the test venv's
Python, where `bpy` is Blender (5.0.1) as a module. For each mode: factory settings (empty scene),
`bpy.ops.import_anim.bvh(rotate_mode=MODE, update_scene_fps=True)` with the importer's default
axes (-Z forward, Y up), then per bone its `rotation_mode` and rest matrix `bone.matrix_local`
(armature space, 3x3), and at each frame its `rotation_euler`, `matrix_basis` (3x3, relative to
rest in the bone's own axes) and `matrix` (3x3, armature space). blender_import_bvh.py
reports world matrices only; this script exists for the Euler values.
"""

import json
import sys

import bpy

# Importable only once bpy is loaded.
import addon_utils  # noqa: E402


def rows(m):
    return [list(r) for r in m.to_3x3()]


def import_one(path, mode, frames, bones):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types, "IMPORT_ANIM_OT_bvh"):
        addon_utils.enable("io_anim_bvh", default_set=True)
    result = bpy.ops.import_anim.bvh(filepath=path, rotate_mode=mode, update_scene_fps=True)
    if "FINISHED" not in result:
        raise RuntimeError("import of %s returned %s" % (path, result))
    scene = bpy.context.scene
    arm = next(o for o in scene.objects if o.type == "ARMATURE")
    report = {
        name: {
            "rotation_mode": arm.pose.bones[name].rotation_mode,
            "rest": rows(arm.data.bones[name].matrix_local),
            "frames": {},
        }
        for name in bones
    }
    for frame in frames:
        scene.frame_set(frame)
        for name in bones:
            pb = arm.pose.bones[name]
            report[name]["frames"][str(frame)] = {
                "euler": list(pb.rotation_euler),
                "basis": rows(pb.matrix_basis),
                "pose": rows(pb.matrix),
            }
    return {
        "rotate_mode": mode,
        "armature_matrix_world": [list(r) for r in arm.matrix_world],
        "bones": report,
    }


def main():
    out_path, path, modes, frames, bones = sys.argv[1:6]
    frames = [int(f) for f in frames.split(",") if f]
    bones = [b for b in bones.split(",") if b]
    imports = [import_one(path, m, frames, bones) for m in modes.split(",") if m]
    with open(out_path, "w") as f:
        json.dump({"blender": bpy.app.version_string, "imports": imports}, f)


if __name__ == "__main__":
    main()
