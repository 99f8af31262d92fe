"""Importing one imubake take into the scene, at its exact frame rate.

`import_take` reads the sidecar first (nothing is touched if it is malformed), imports the BVH with
Blender's BVH importer or the GLB/glTF with Blender's glTF importer, then corrects what those
importers get wrong for imubake takes:

- the scene rate is set exactly from the sidecar's rational fps (fps / fps_base == num / den) and
  the frame range is 1..frames (take frame n is scene frame n + 1), shortening the scene too;
- the glTF importer places a key at t seconds on frame t * fps * fps_base (not fps / fps_base) and
  starts at frame 0, so non-integer rates land off-frame: keys are moved to n + 1 exactly;
- foot contacts (takes converted with foot-rooted root motion) become the armature's custom
  properties `contact_left` and `contact_right`, keyed 0/1 on every frame (constant), for IK
  setups that pin feet;
- glTF rotations arrive as quaternions: they are turned into Euler curves made continuous with
  `Euler.make_compatible` (Blender's BVH importer already passes the previous Euler).

Any failure part-way removes what the import created and restores the scene's rate and range.
"""

import os

import bpy

from . import compat
from . import sidecar as sc


class TakeError(Exception):
    """A take that cannot be imported; the message is meant for the animator."""


class ImportedTake:
    """The result of `import_take`: the armature (named after the take) and its action."""

    def __init__(self, take, fmt, armature, action):
        self.take = take
        self.name = take.name
        self.format = fmt
        self.armature = armature
        self.action = action
        self.frames = take.frames
        self.fps, self.fps_base = take.scene_rate()
        self.warnings = list(take.warnings)


_FORMAT_OF_EXT = {".bvh": "bvh", ".glb": "glb", ".gltf": "gltf"}
# Data-blocks an importer may create; on failure the new ones are removed.
_DATA_KINDS = ("objects", "actions", "armatures", "meshes", "materials", "images", "textures",
               "collections", "cameras", "lights")


def import_take(context, path, *, fmt=None, rotation_mode="XYZ"):
    """Imports the take at `path` (a sidecar, or a .bvh/.glb/.gltf with its sidecar next to it).

    fmt            "bvh", "glb" or "gltf" to choose the output; by default the chosen file's own
                   format, else the first the sidecar lists of bvh, glb, gltf.
    rotation_mode  for glTF imports: an Euler order ("XYZ", ...) or "QUATERNION" to keep the
                   importer's quaternions. BVH imports keep the BVH's own channel order.
    Raises TakeError (bad sidecar, missing file, importer failure) with the scene unchanged.
    """
    try:
        take = sc.load(path)
        if fmt is None:
            fmt = _FORMAT_OF_EXT.get(os.path.splitext(path)[1].lower())
        fmt, anim_path = take.animation_file(fmt)
    except sc.SidecarError as e:
        raise TakeError(str(e)) from None

    scene = context.scene
    before = _snapshot(scene)
    try:
        if fmt == "bvh":
            armature = _import_bvh(context, take, anim_path)
        else:
            armature = _import_gltf(context, take, anim_path, rotation_mode)
        action = armature.animation_data.action if armature.animation_data else None
        if action is None:
            raise TakeError("%s: the importer made no animation" % anim_path)
        armature.name = take.name
        action.name = take.name
        key_contacts(armature, take)
        set_scene_rate(scene, take)
    except Exception as e:
        _restore(scene, before)
        if isinstance(e, TakeError):
            raise
        raise TakeError("%s: import failed: %s" % (anim_path, e)) from e
    return ImportedTake(take, fmt, armature, action)


def key_contacts(obj, take):
    """Keys `contact_left` / `contact_right` on `obj` (its action) from the take's contacts: 1 on
    the frames a foot is planted, else 0, on scene frames 1..frames (take frame n on n + 1)."""
    if take.contacts is None or obj.animation_data is None or obj.animation_data.action is None:
        return
    frames = [float(n + 1) for n in range(take.frames)]
    for side in ("left", "right"):
        values = [0.0] * take.frames
        for start, end in take.contacts[side]:
            for n in range(start, end + 1):
                values[n] = 1.0
        prop = "contact_" + side
        obj[prop] = values[0]
        fc = compat.new_fcurve(obj, '["%s"]' % prop, 0, "Contacts")
        compat.set_keys(fc, frames, values, interpolation="CONSTANT")


def set_scene_rate(scene, take):
    """Scene rate exactly the take's, frames 1..take.frames, current frame 1."""
    fps, base = take.scene_rate()
    scene.render.fps = fps
    scene.render.fps_base = base
    # Order matters: Blender clamps frame_end to at least frame_start.
    scene.frame_start = 1
    scene.frame_end = take.frames
    scene.frame_set(1)


def ensure_addon(module, operator_type):
    """Enables Blender's bundled add-on `module` unless its operator type is registered."""
    if not hasattr(bpy.types, operator_type):
        import addon_utils

        addon_utils.enable(module, default_set=True)
    if not hasattr(bpy.types, operator_type):
        raise TakeError("Blender's %s add-on cannot be enabled" % module)


def _new_armature(before, path):
    made = [o for o in bpy.data.objects if o.type == "ARMATURE" and o.as_pointer() not in before["objects"]]
    if len(made) != 1:
        raise TakeError("%s: expected one armature from the importer, found %d" % (path, len(made)))
    return made[0]


def _import_bvh(context, take, path):
    ensure_addon("io_anim_bvh", "IMPORT_ANIM_OT_bvh")
    before = {"objects": {o.as_pointer() for o in bpy.data.objects}}
    # Keys on frames 1.. one per BVH frame; the scene rate and range are set from the sidecar
    # afterwards (the importer's own update rounds the rate and never shortens the scene).
    result = bpy.ops.import_anim.bvh(
        filepath=path,
        target="ARMATURE",
        global_scale=0.01 if take.units == "cm" else 1.0,
        frame_start=1,
        use_fps_scale=False,
        update_scene_fps=False,
        update_scene_duration=False,
        rotate_mode="NATIVE",
        axis_forward="-Z",
        axis_up="Y",
    )
    if "FINISHED" not in result:
        raise TakeError("%s: Blender's BVH importer returned %s" % (path, sorted(result)))
    return _new_armature(before, path)


def _import_gltf(context, take, path, rotation_mode):
    ensure_addon("io_scene_gltf2", "IMPORT_SCENE_OT_gltf")
    scene = context.scene
    before = {"objects": {o.as_pointer() for o in bpy.data.objects}}
    result = bpy.ops.import_scene.gltf(filepath=path)
    if "FINISHED" not in result:
        raise TakeError("%s: Blender's glTF importer returned %s" % (path, sorted(result)))
    armature = _new_armature(before, path)
    # The importer put a key at t seconds on frame t * fps * fps_base of the scene at import time.
    imported_scale = scene.render.fps * scene.render.fps_base
    _move_keys_to_frames(armature, take, imported_scale, path)
    if rotation_mode != "QUATERNION":
        quaternions_to_euler(armature, rotation_mode)
    return armature


def _move_keys_to_frames(armature, take, imported_scale, path):
    rate = float(take.fps)
    for fc in compat.fcurves(armature):
        points = fc.keyframe_points
        n = len(points)
        co = [0.0] * (2 * n)
        points.foreach_get("co", co)
        frames = []
        for x in co[0::2]:
            exact = x / imported_scale * rate
            nearest = round(exact)
            # Our GLB samples exactly on frame times: anything else is not an imubake take.
            if abs(exact - nearest) > 1e-3:
                raise TakeError(
                    "%s: a key at %.6f s is not on a frame of %s fps" % (path, x / imported_scale, take.fps)
                )
            frames.append(nearest + 1.0)
        compat.set_keys(fc, frames, co[1::2], interpolation="LINEAR")


def quaternions_to_euler(armature, order):
    """Replaces every pose bone's quaternion curves by continuous Euler curves in `order`."""
    by_bone = {}
    for fc in compat.fcurves(armature):
        if fc.data_path.startswith('pose.bones["') and fc.data_path.endswith('"].rotation_quaternion'):
            bone = fc.data_path[len('pose.bones["'): -len('"].rotation_quaternion')]
            by_bone.setdefault(bone, {})[fc.array_index] = fc
    from mathutils import Quaternion

    for bone, curves in by_bone.items():
        if sorted(curves) != [0, 1, 2, 3]:
            continue
        keys = []
        for i in range(4):
            points = curves[i].keyframe_points
            co = [0.0] * (2 * len(points))
            points.foreach_get("co", co)
            keys.append(co)
        frames = keys[0][0::2]
        if any(k[0::2] != frames for k in keys[1:]):
            continue  # components keyed on different frames: leave the quaternions alone
        group = curves[0].group.name if curves[0].group else bone
        euler_values = ([], [], [])
        prev = None
        for j in range(len(frames)):
            q = Quaternion((keys[0][2 * j + 1], keys[1][2 * j + 1], keys[2][2 * j + 1], keys[3][2 * j + 1]))
            e = q.normalized().to_euler(order)
            if prev is not None:
                # The Euler triple nearest the previous frame's: no 360° wraps or gimbal flips.
                e.make_compatible(prev)
            prev = e
            for i in range(3):
                euler_values[i].append(e[i])
        for fc in curves.values():
            compat.remove_fcurve(armature, fc)
        data_path = 'pose.bones["%s"].rotation_euler' % bone
        for i in range(3):
            fc = compat.new_fcurve(armature, data_path, i, group)
            compat.set_keys(fc, frames, euler_values[i], interpolation="LINEAR")
    for pb in armature.pose.bones:
        pb.rotation_mode = order


def _snapshot(scene):
    r = scene.render
    return {
        "rate": (r.fps, r.fps_base, scene.frame_start, scene.frame_end, scene.frame_current),
        "data": {kind: {d.as_pointer() for d in getattr(bpy.data, kind)} for kind in _DATA_KINDS},
    }


def _restore(scene, before):
    """Removes every data-block made since `before` and puts the scene's rate and range back."""
    for kind in _DATA_KINDS:
        coll = getattr(bpy.data, kind)
        for d in [d for d in coll if d.as_pointer() not in before["data"][kind]]:
            try:
                coll.remove(d)
            except (ReferenceError, RuntimeError):
                pass
    fps, base, start, end, current = before["rate"]
    scene.render.fps, scene.render.fps_base = fps, base
    scene.frame_start, scene.frame_end = start, end
    scene.frame_current = current
