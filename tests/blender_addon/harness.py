"""Shared set-up for the add-on tests: the installed add-on, fresh scenes, the sample takes."""

import os

import bpy

MODULE = "bl_ext.user_default.imubake"
RATES = {"walk_24": (24, 1.0), "walk_2997": (30, 1.001), "walk_60": (60, 1.0), "walk_120": (120, 1.0),
         "walk_inplace": (30, 1.0), "walk_bind": (30, 1.0)}


def install(zip_path):
    """Installs and enables the extension zip into BLENDER_USER_RESOURCES (set by run.py)."""
    result = bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True
    )
    if "FINISHED" not in result or MODULE not in bpy.context.preferences.addons:
        raise RuntimeError("installing %s failed: %s" % (zip_path, result))


def addon():
    """The installed add-on's package (its submodules: sidecar, take_import, retarget, ...)."""
    import importlib

    return importlib.import_module(MODULE)


def submodule(name):
    import importlib

    return importlib.import_module(MODULE + "." + name)


def fresh_scene():
    """An empty scene; the add-on stays enabled (read_homefile keeps preferences)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    assert MODULE in bpy.context.preferences.addons
    return bpy.context.scene


def takes_dir():
    return os.environ["IMUBAKE_TAKES"]


def take(name, ext="imubake.json"):
    return os.path.join(takes_dir(), "%s.%s" % (name, ext))


def shared(rel):
    """A file under ../shared/data; the Rust driver only runs this suite when the data is there."""
    base = os.environ.get("IMUBAKE_SHARED_DATA") or os.path.join(
        os.path.dirname(__file__), "..", "..", "..", "shared", "data"
    )
    path = os.path.join(base, rel)
    if not os.path.exists(path):
        raise FileNotFoundError("shared data %s is missing" % path)
    return path


def fcurves(obj):
    """F-curves of the action `obj` plays, on Blender 4.2 (Action.fcurves) and 5.0 (channelbags)."""
    adt = obj.animation_data
    if adt is None or adt.action is None:
        return []
    action = adt.action
    if "fcurves" in bpy.types.Action.bl_rna.properties:
        return list(action.fcurves)
    out = []
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(adt.action_slot)
            if bag is not None:
                out.extend(bag.fcurves)
    return out


def version():
    return bpy.app.version


def enable(module):
    """Enables a bundled add-on (io_anim_bvh, rigify); it stays on across read_homefile."""
    import addon_utils

    addon_utils.enable(module, default_set=True)


def mixamo_character():
    """An empty scene with a Mixamo armature built from ../shared/data's Mixamo rig BVH, in its
    rest pose (T-pose), without animation, active and selected."""
    enable("io_anim_bvh")
    fresh_scene()
    path = shared("bvh/mixamo_rig_freebvh.bvh")
    result = bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=False, update_scene_duration=False)
    assert "FINISHED" in result
    arm = bpy.context.object
    arm.name = "Character"
    arm.animation_data_clear()
    for pb in arm.pose.bones:
        pb.matrix_basis.identity()
    bpy.context.view_layer.update()
    return arm


def rigify_metarig():
    """An empty scene with Rigify's human metarig (arms resting about 28° below horizontal)."""
    enable("rigify")
    fresh_scene()
    assert "FINISHED" in bpy.ops.object.armature_human_metarig_add()
    return bpy.context.object


def armatures():
    return [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]


def world_rot(obj, pb):
    """A pose bone's world rotation as a numpy 3x3."""
    import numpy as np

    return np.array((obj.matrix_world @ pb.matrix).to_3x3().normalized())


def rest_rot(obj, bone_name):
    import numpy as np

    return np.array((obj.matrix_world @ obj.data.bones[bone_name].matrix_local).to_3x3().normalized())
