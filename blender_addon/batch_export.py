"""Batch export of imubake takes for game engines: FBX or glTF binary (.glb).

usage:
  python batch_export.py TAKES_DIR OUT_DIR --format fbx|glb [--engine unity|unreal|godot]
  blender -b -P batch_export.py -- TAKES_DIR OUT_DIR --format fbx|glb [--engine unity|unreal|godot]

`python` must be a Python with Blender's `bpy` module (the PyPI `bpy` package); with a Blender
executable, pass the arguments after `--`. Every take under TAKES_DIR (each `<stem>.imubake.json`
sidecar, searched recursively) is imported at its exact frame rate with the add-on's importer and
written to OUT_DIR/<relative folder>/<stem>.fbx or .glb, one key per frame, take frame n at
n / fps seconds, the animation named after the take. Files are written under a hidden temporary
name (`.<stem>.fbx.tmp`, `.<stem>.tmp.glb`) and renamed into place, so an output is either complete or absent.

Engine conventions (README, "Batch export for game engines", gives the same with sources):

  (none)  Blender's FBX exporter defaults: Y up, -Z forward, the Z-up to Y-up rotation and the
          metre-to-centimetre factor 100 on the armature node, FBX unit centimetres. Only the
          animation settings differ: one key per frame, no leaf bones.
  unity   Y up, -Z forward (FBX's own Y-up axis system; Unity then only mirrors X, so a take
          facing +Z faces Unity's forward +Z). FBX_SCALE_ALL: the file's unit is the metre and
          no node carries a scale, so with Unity's "Convert Units" 1 unit = 1 m. The axis
          rotation is baked into the skeleton so the armature node has an identity transform
          (no -90 deg X on the root, as Blender's default gives).
  unreal  Z up, Y forward: Blender's own axes, which are the axes Unreal's FBX importer converts
          to (Z up, -Y front, right-handed; Epic's Send to Unreal exports the same), so no
          rotation is added and the character faces +Y in Unreal like its mannequin.
          Centimetres (Unreal's unit, and its importer does not convert units by default): the
          skeleton and root translation are scaled by 100, the FBX unit is the centimetre and no
          node carries a scale. The armature object is named "Armature", which Unreal's FBX
          importer (4.24 and later) drops instead of making it an extra root bone.
  godot   glTF binary is Godot's recommended format (Y up and metres by the glTF spec, the take
          facing +Z). For FBX (Godot 4.3+ reads it with ufbx), the same settings as Unity: Y up,
          metres, identity armature node. No "-loop" suffix: mocap takes do not loop.

For glb, the engine changes nothing in the file: glTF fixes axes (Y up, +Z front) and units
(metres) by spec, and every engine's glTF importer converts from them. With `--engine godot`,
`<stem>.glb.import` goes beside each .glb, as `imubake convert --engine godot` writes it: Godot 3's
import settings baking the animation at the take's rate (the next whole rate above a fractional
one) with its lossy optimizer off, read by Godot on its first import (docs/src/godot.md).

Prints on stdout one line per take, `[3/12] walk_24: exported out/walk_24.fbx (285 frames at 24
fps) in 0.84 s` or `[4/12] bad: FAILED: <reason>`, then a summary, and nothing else: Blender's own
messages (its importers' and exporters' progress, a failed import's report and traceback, which
Blender cuts at a fixed length without ending the line) go to stderr, so they can never run into a
progress line. Exit status 0 when every take was exported, 1 when any failed (or none was found),
2 for usage errors.

This is a script, not part of the registered add-on: it imports the add-on's modules through the
package folder it sits in (the repository's `blender_addon/` or the installed extension's folder).
"""

import argparse
import importlib
import os
import sys
import time
from fractions import Fraction

FORMATS = ("fbx", "glb")
ENGINES = ("unity", "unreal", "godot")

# Options common to every FBX export: the armature only, its take baked with one key per frame
# (simplify factor 0 keeps every key, force_startend_keying the first and last), from the NLA
# strip named after the take (so the FBX animation stack is named after the take and starts at
# time 0), and no leaf bones (the "_end" bones Blender adds by default, which no engine needs).
FBX_COMMON = {
    "use_selection": False,
    "object_types": {"ARMATURE"},
    "add_leaf_bones": False,
    "primary_bone_axis": "Y",
    "secondary_bone_axis": "X",
    "armature_nodetype": "NULL",
    "use_armature_deform_only": False,
    "bake_anim": True,
    "bake_anim_use_all_bones": True,
    "bake_anim_use_nla_strips": True,
    "bake_anim_use_all_actions": False,
    "bake_anim_force_startend_keying": True,
    "bake_anim_step": 1.0,
    "bake_anim_simplify_factor": 0.0,
    "use_space_transform": True,
    "bake_space_transform": False,
}

# Per engine: exporter options, whether the axis rotation is baked into the skeleton (identity
# armature node), whether the take is rescaled to centimetres, and the armature object's name
# (None: the take's name).
FBX_ENGINES = {
    None: {
        "options": {"axis_forward": "-Z", "axis_up": "Y", "global_scale": 1.0,
                    "apply_unit_scale": True, "apply_scale_options": "FBX_SCALE_NONE"},
        "bake_axes": False, "centimetres": False, "armature_name": None,
    },
    "unity": {
        "options": {"axis_forward": "-Z", "axis_up": "Y", "global_scale": 1.0,
                    "apply_unit_scale": True, "apply_scale_options": "FBX_SCALE_ALL"},
        "bake_axes": True, "centimetres": False, "armature_name": None,
    },
    "unreal": {
        "options": {"axis_forward": "Y", "axis_up": "Z", "global_scale": 1.0,
                    "apply_unit_scale": True, "apply_scale_options": "FBX_SCALE_NONE"},
        "bake_axes": False, "centimetres": True, "armature_name": "Armature",
    },
    "godot": {
        "options": {"axis_forward": "-Z", "axis_up": "Y", "global_scale": 1.0,
                    "apply_unit_scale": True, "apply_scale_options": "FBX_SCALE_ALL"},
        "bake_axes": True, "centimetres": False, "armature_name": None,
    },
}

# glTF binary: Y up (the spec's), one sample per frame kept (no "optimize animation size", which
# drops keys), the animation starting at time 0, no leaf bones, nothing but the armature.
GLB_OPTIONS = {
    "export_format": "GLB",
    "use_selection": False,
    "export_yup": True,
    "export_animations": True,
    "export_animation_mode": "ACTIONS",
    "export_force_sampling": True,
    "export_frame_step": 1,
    "export_frame_range": False,
    "export_anim_slide_to_zero": True,
    "export_optimize_animation_size": False,
    "export_leaf_bone": False,
    "export_def_bones": False,
    "export_reset_pose_bones": True,
    "export_current_frame": False,
    "export_rest_position_armature": True,
    "export_cameras": False,
    "export_lights": False,
}


class UsageError(Exception):
    pass


class ExportError(Exception):
    """A take that cannot be exported; the message is the reason shown on its FAILED line."""


def parse_args(argv):
    """Arguments after `--` when present (Blender's convention), else after the script name."""
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    else:
        argv = argv[1:]
    parser = argparse.ArgumentParser(
        prog="batch_export.py",
        description="Export every imubake take under TAKES_DIR for a game engine.",
    )
    parser.add_argument("takes", metavar="TAKES_DIR", help="folder searched for <stem>.imubake.json")
    parser.add_argument("out", metavar="OUT_DIR", help="output folder (created if missing)")
    parser.add_argument("--format", required=True, type=str.lower, choices=FORMATS)
    parser.add_argument("--engine", type=str.lower, choices=ENGINES, default=None)
    # argparse reports usage errors on stderr and exits with status 2.
    return parser.parse_args(argv)


def addon_package():
    """The add-on package this script sits in, imported by its folder's name.

    The modules use relative imports, so they are imported as a package: the script's parent
    folder goes on sys.path and the package is `blender_addon` in the repository or `imubake` in
    an installed extension.
    """
    here = os.path.dirname(os.path.abspath(__file__))
    parent, name = os.path.split(here)
    if parent not in sys.path:
        sys.path.insert(0, parent)
    pkg = importlib.import_module(name)
    for sub in ("sidecar", "take_import", "compat"):
        importlib.import_module(name + "." + sub)
    return pkg


def rate_text(fps):
    """`24` or `30000/1001`, as imubake prints rates."""
    fps = Fraction(fps)
    return str(fps.numerator) if fps.denominator == 1 else "%d/%d" % (fps.numerator, fps.denominator)


def one_line(text):
    return " ".join(str(text).split())


class Progress:
    """This script's own lines, on the process's stdout and nothing else there.

    Blender writes to file descriptor 1 too, from C and from Python (importers' prints, operator
    reports, a failed import's traceback cut at a fixed length with no final newline), so a line
    printed after those could begin in the middle of one of theirs. `Progress.take_stdout()` keeps
    a duplicate of the original stdout for these lines and points descriptor 1 at stderr for the
    rest of the run: whatever Blender prints, now or buffered for later, shows on stderr.
    """

    def __init__(self):
        self.stream = sys.stdout

    def take_stdout(self):
        sys.stdout.flush()
        try:
            saved = os.dup(1)
            os.dup2(2, 1)
        except OSError:  # no separate descriptors here: lines go to stdout as they are
            return
        self.stream = os.fdopen(saved, "w", encoding="utf-8", errors="replace")

    def line(self, text):
        self.stream.write(text + "\n")
        self.stream.flush()


PROGRESS = Progress()


# ---------------------------------------------------------------------------------------------
# Export of one take (runs inside Blender)


def _action_to_strip(armature, name):
    """Moves the armature's action into an NLA strip named `name` (the FBX stack's name)."""
    adt = armature.animation_data
    action = adt.action
    start = int(round(action.frame_range[0]))
    track = adt.nla_tracks.new()
    track.name = name
    strip = track.strips.new(name, start, action)
    strip.name = name
    adt.action = None
    return strip


def _bake_axis_conversion(armature, forward, up):
    """Puts the exporter's axis rotation into the skeleton, so the armature node is identity.

    The FBX exporter multiplies root objects (here the armature) by C, the rotation from
    Blender's axes to the file's. The skeleton's rest is rotated by C and the object by C^-1:
    the pose in Blender's world is unchanged and the file's armature node is C C^-1 = identity.
    Pose channels are relative to each bone's rest, so the animation needs no change.
    """
    from bpy_extras.io_utils import axis_conversion

    conv = axis_conversion(to_forward=forward, to_up=up).to_4x4()
    armature.data.transform(conv)
    armature.matrix_world = armature.matrix_world @ conv.inverted()


def _scale_to_centimetres(pkg, scene, armature):
    """Makes 1 Blender unit 1 cm in this (temporary) scene: skeleton and translations x100.

    With the scene's unit scale at 0.01 the FBX exporter writes UnitScaleFactor 1 (centimetres)
    and scales no node, so the file's numbers are centimetres.
    """
    from mathutils import Matrix

    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.01
    armature.data.transform(Matrix.Scale(100.0, 4))
    armature.location = armature.location * 100.0
    for fc in pkg.compat.fcurves(armature):
        if not fc.data_path.endswith("location"):
            continue
        points = fc.keyframe_points
        n = len(points)
        for prop in ("co", "handle_left", "handle_right"):
            values = [0.0] * (2 * n)
            points.foreach_get(prop, values)
            values[1::2] = [v * 100.0 for v in values[1::2]]
            points.foreach_set(prop, values)
        fc.update()


def export_fbx(pkg, imported, path, engine):
    import bpy

    pkg.take_import.ensure_addon("io_scene_fbx", "EXPORT_SCENE_OT_fbx")
    profile = FBX_ENGINES[engine]
    scene = bpy.context.scene
    armature = imported.armature
    options = dict(FBX_COMMON, **profile["options"])
    if profile["bake_axes"]:
        _bake_axis_conversion(armature, options["axis_forward"], options["axis_up"])
    if profile["centimetres"]:
        _scale_to_centimetres(pkg, scene, armature)
    armature.name = profile["armature_name"] or imported.name
    _action_to_strip(armature, imported.name)
    # The scene's rate is the take's exact rate (set by import_take); the exporter keys frame f
    # at (f - strip start) / (fps / fps_base) seconds and writes the matching FBX time mode.
    result = bpy.ops.export_scene.fbx(filepath=path, **options)
    if "FINISHED" not in result:
        raise RuntimeError("Blender's FBX exporter returned %s" % sorted(result))


def export_glb(pkg, imported, path, engine):
    import bpy

    pkg.take_import.ensure_addon("io_scene_gltf2", "EXPORT_SCENE_OT_gltf")
    scene = bpy.context.scene
    render = scene.render
    saved = (render.fps, render.fps_base)
    # Blender's glTF exporter turns frames into seconds with fps * fps_base (Blender's rate is
    # fps / fps_base), which is only right when fps_base is 1. For the export, fps_base is set so
    # that fps * fps_base is the take's rate: 30000/1001 -> 30 * 0.999000999.
    render.fps_base = float(Fraction(imported.take.fps) / render.fps)
    try:
        result = bpy.ops.export_scene.gltf(filepath=path, **GLB_OPTIONS)
    finally:
        render.fps, render.fps_base = saved
    if "FINISHED" not in result:
        raise RuntimeError("Blender's glTF exporter returned %s" % sorted(result))


def godot_import_text(fps):
    """Godot 3's `<file>.import` for a take at `fps` (a Fraction), the text imubake's own
    `--engine godot` writes (src/write/godot.rs): the scene importer, materials kept in the scene,
    the animation baked at the next whole rate at or above the take's, the optimizer off."""
    bake = -(-fps.numerator // fps.denominator)
    return (
        '[remap]\n\nimporter="scene"\n\n[params]\n\n'
        "materials/storage=0\nanimation/import=true\nanimation/fps=%d\n"
        "animation/optimizer/enabled=false\n" % bake
    )


def write_atomic_text(path, text):
    """`path` written under a hidden name in its folder and renamed into place."""
    folder, base = os.path.split(path)
    tmp = os.path.join(folder, ".%s.tmp" % base)
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def export_take(pkg, sidecar_path, out_path, fmt, engine):
    """Imports one take into a fresh empty scene and exports it to `out_path` atomically."""
    import bpy

    # read_homefile keeps preferences and enabled add-ons (read_factory_settings would not).
    bpy.ops.wm.read_homefile(use_empty=True)
    imported = pkg.take_import.import_take(bpy.context, sidecar_path)
    own = {os.path.realpath(p) for p in imported.take.outputs.values()}
    if os.path.realpath(out_path) in own:
        raise ExportError(
            "%s is the take's own output; choose an output folder other than the takes folder"
            % out_path
        )
    folder, base = os.path.split(out_path)
    os.makedirs(folder, exist_ok=True)
    stem, ext = os.path.splitext(base)
    # Hidden, in the same folder (so the rename is atomic): `.<stem>.fbx.tmp`; `.<stem>.tmp.glb`
    # for glTF, whose exporter appends ".glb" to any other name.
    tmp = os.path.join(folder, ".%s%s.tmp" % (stem, ext) if fmt == "fbx" else ".%s.tmp%s" % (stem, ext))
    try:
        if fmt == "fbx":
            export_fbx(pkg, imported, tmp, engine)
        else:
            export_glb(pkg, imported, tmp, engine)
        if not os.path.isfile(tmp):
            raise RuntimeError("the exporter wrote no file")
        os.replace(tmp, out_path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    if fmt == "glb" and engine == "godot":
        write_atomic_text(out_path + ".import", godot_import_text(Fraction(imported.take.fps)))
    return imported


# ---------------------------------------------------------------------------------------------


def run(argv):
    args = parse_args(argv)
    takes_dir = os.path.abspath(args.takes)
    if not os.path.isdir(takes_dir):
        raise UsageError("takes folder %s does not exist (or is not a folder)" % args.takes)
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise UsageError("output %s exists and is not a folder" % args.out)
    # From here on stdout carries this script's lines only; Blender's go to stderr.
    say = PROGRESS.line
    PROGRESS.take_stdout()
    try:
        import bpy  # noqa: F401
    except ImportError:
        raise UsageError(
            "this Python has no bpy module: run with Blender (blender -b -P batch_export.py -- ...)"
            " or a Python with the bpy package"
        ) from None

    pkg = addon_package()
    sidecars = pkg.sidecar.find_sidecars(takes_dir)
    label = args.format + (" for " + args.engine if args.engine else "")
    if not sidecars:
        say("no imubake takes (*%s) under %s" % (pkg.sidecar.SUFFIX, args.takes))
        return 1
    if args.engine == "godot" and args.format == "fbx":
        say("note: glb is Godot's recommended format; FBX needs Godot 4.3+ (ufbx)")
    if args.engine and args.format == "glb":
        say("note: glb is the same for every engine (glTF is Y up, metres, +Z front by spec)")
    if args.engine == "godot" and args.format == "glb":
        say("note: <stem>.glb.import beside each: Godot 3 bakes at the take's rate, no optimizer")
    say("exporting %d take(s) from %s as %s" % (len(sidecars), args.takes, label))

    ext = "." + args.format
    failed = 0
    started = time.perf_counter()
    for i, path in enumerate(sidecars, 1):
        rel = os.path.relpath(os.path.dirname(path), takes_dir)
        base = os.path.basename(path)
        stem = base[: -len(pkg.sidecar.SUFFIX)]
        name = stem if rel == "." else os.path.join(rel, stem)
        out_path = os.path.normpath(os.path.join(args.out, rel, stem + ext))
        t0 = time.perf_counter()
        try:
            imported = export_take(pkg, path, os.path.abspath(out_path), args.format, args.engine)
        except Exception as e:  # one bad take never stops the batch
            failed += 1
            known = (pkg.take_import.TakeError, ExportError)
            reason = str(e) if isinstance(e, known) else "%s: %s" % (type(e).__name__, e)
            say("[%d/%d] %s: FAILED: %s" % (i, len(sidecars), name, one_line(reason)))
            continue
        say(
            "[%d/%d] %s: exported %s (%d frames at %s fps) in %.2f s"
            % (i, len(sidecars), name, out_path, imported.frames, rate_text(imported.take.fps),
               time.perf_counter() - t0)
        )
        for w in imported.warnings:
            say("    warning: %s" % one_line(w))
    done = len(sidecars) - failed
    say(
        "%d of %d take(s) exported as %s to %s, %d failed, in %.2f s"
        % (done, len(sidecars), label, args.out, failed, time.perf_counter() - started)
    )
    return 1 if failed else 0


def main(argv):
    try:
        return run(argv)
    except UsageError as e:
        print("batch_export.py: error: %s" % e, file=sys.stderr, flush=True)
        return 2


if __name__ == "__main__":
    code = main(sys.argv)
    sys.stdout.flush()
    sys.stderr.flush()
    # bpy as a module can hang on interpreter exit with handlers registered; leave at once.
    # Inside a Blender executable (-b -P) the script's exit status is the process's.
    os._exit(code)
