"""Batch export for game engines: the INSTALLED extension's batch_export.py, run as users run it
(a subprocess with this Python, which has bpy), then its files read back.

Checked for FBX (no engine, unity, unreal, godot) and glb:
- exit status, one progress line per take, one output per take, no temporary file left (on a
  copy of the four walk takes; every take of the shared takes folder, whatever its rig, is also
  exported once for Unreal);
- the raw FBX (read with Blender's FBX parser, not imported): declared axes and unit per engine
  as README documents them, the armature node's name and transform, one animation stack named
  after the take, one key per frame on every curve at exactly n / fps seconds, the FBX time mode;
- re-imported with Blender's FBX importer: the scene rate, keys per F-curve, the key span, the
  Unreal export's centimetres (hips height);
- the pose: bones' world-space head positions at two frames, direct import (take_import) against
  the FBX read in its own axes, mapped back to Blender's by the documented conversion; also for a
  copy of a take whose root travels (the samples' root is fixed), for every engine and glb;
- glb: parsed directly (animation name, sample times n / fps), and the pose through the add-on's
  own glTF import (which also refuses keys that are off the take's frames);
- a folder with a corrupt sidecar and a broken BVH: exit status 1, FAILED lines, the good takes
  still exported (one in a sub-folder, kept relative); usage errors exit with status 2;
- stdout holds the script's lines only (Blender's own messages go to stderr).

The script's lines are found wherever they are in the output (searched for, not anchored at line
starts), so nothing here depends on what Blender prints, in which order, or how long it is: its
BVH importer's report of a broken file is cut at a fixed length without a final newline, so with
a longer install path a line printed after it once began mid-line.
"""

import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import unittest
from fractions import Fraction

import bpy
import numpy as np

import harness
from bvh_reference import Bvh

TAKES = ("walk_120", "walk_24", "walk_2997", "walk_60")  # the order find_sidecars gives
POSE_TAKES = ("walk_24", "walk_2997")  # an integer rate and an NTSC one
BONES = ("Hips", "Head", "LeftHand", "RightFoot", "LeftToeBase")
FBX_KTIME = 46186158000  # FBX 7.x time unit: ticks per second
ENGINES = (None, "unity", "unreal", "godot")

# What README documents, per engine: the rotation from Blender's world (Z up, the take facing -Y)
# to the file's axes, the file's unit in metres (UnitScaleFactor is centimetres per unit), the
# armature node's name (None: the take's) and whether that node is the identity.
C_YUP = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Blender (x, y, z) -> (x, z, -y)
CONVENTIONS = {
    None: {"axes": C_YUP, "unit_m": 0.01, "armature": None, "identity_node": False},
    "unity": {"axes": C_YUP, "unit_m": 1.0, "armature": None, "identity_node": True},
    "unreal": {"axes": np.eye(3), "unit_m": 0.01, "armature": "Armature", "identity_node": True},
    "godot": {"axes": C_YUP, "unit_m": 1.0, "armature": None, "identity_node": True},
}

LINE = re.compile(
    r"\[(\d+)/(\d+)\] (\S+): exported (.+?) \((\d+) frames at (\d+(?:/\d+)?) fps\) in \d+\.\d\d s"
)
# Every line the script prints: the header, notes, one per take (and its warnings), the summary.
SCRIPT_LINE = re.compile(
    r"exporting \d+ take\(s\) from .+ as .+|note: .+|\[\d+/\d+\] \S+: (?:exported|FAILED:) .+"
    r"|    warning: .+|\d+ of \d+ take\(s\) exported as .+, \d+ failed, in \d+\.\d\d s"
    r"|no imubake takes .+"
)


def summary(done, total, failed):
    """The summary line, wherever it is (not only at a line start)."""
    return r"(?<!\d)%d of %d take\(s\) exported .* %d failed" % (done, total, failed)


def script():
    """batch_export.py of the installed extension (not the repository's copy)."""
    path = os.path.join(os.path.dirname(harness.addon().__file__), "batch_export.py")
    if not os.path.isfile(path):
        raise FileNotFoundError("the installed extension has no batch_export.py: %s" % path)
    return path


def run_batch(*args):
    # The environment passes through: BLENDER_USER_RESOURCES keeps Blender off the home folder.
    return subprocess.run(
        [sys.executable, script(), *args],
        capture_output=True, text=True, env=dict(os.environ), timeout=900,
    )


def take_info(name):
    take = harness.submodule("sidecar").load(harness.take(name))
    return take.fps, take.frames


def rate_text(fps):
    return str(fps.numerator) if fps.denominator == 1 else "%d/%d" % (fps.numerator, fps.denominator)


def ensure_addon(module):
    import addon_utils

    addon_utils.enable(module, default_set=True)


# --- raw FBX ----------------------------------------------------------------------------------


def fbx_parse(path):
    ensure_addon("io_scene_fbx")
    from io_scene_fbx import parse_fbx

    root, version = parse_fbx.parse(path)
    return root, version


def children(elem, ident):
    return [e for e in elem.elems if e.id == ident]


def props70(elem):
    out = {}
    for e in children(elem, b"Properties70"):
        for p in e.elems:
            out[p.props[0].decode()] = list(p.props[4:])
    return out


def axis_and_sign(v):
    """(axis index, sign) of an axis-aligned vector, as FBX's GlobalSettings write axes."""
    i = int(np.argmax(abs(v)))
    return i, int(np.sign(v[i]))


def fbx_name(elem):
    return elem.props[1].split(b"\x00")[0].decode()


# --- glb --------------------------------------------------------------------------------------


def read_glb(path):
    data = open(path, "rb").read()
    magic, _version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and length == len(data), path
    offset, doc, binary = 12, None, None
    while offset < length:
        size, kind = struct.unpack_from("<II", data, offset)
        chunk = data[offset + 8: offset + 8 + size]
        offset += 8 + size
        if kind == 0x4E4F534A:
            doc = json.loads(chunk)
        elif kind == 0x004E4942:
            binary = chunk
    return doc, binary


def glb_floats(doc, binary, index):
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
    assert acc["componentType"] == 5126  # float32
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(binary, dtype="<f4", count=acc["count"] * width, offset=start).reshape(
        acc["count"], width)


# --- poses in Blender -------------------------------------------------------------------------


def the_armature():
    arms = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
    assert len(arms) == 1, [o.name for o in bpy.context.scene.objects]
    return arms[0]


def world_heads(armature, scene_frame):
    scene = bpy.context.scene
    whole = int(np.floor(scene_frame))
    scene.frame_set(whole, subframe=float(scene_frame - whole))
    mw = armature.matrix_world
    return {b: np.array(mw @ armature.pose.bones[b].head) for b in BONES}


def make_moving_take(folder, source="walk_24", name="moving_24"):
    """A copy of a sample take whose root travels (the samples' root is fixed): the BVH's root
    position channels get a drift and a sway, so root translation is exercised too."""
    with open(harness.take(source, "bvh")) as f:
        lines = f.read().split("\n")
    start = lines.index("MOTION") + 3
    for n in range(start, len(lines)):
        values = lines[n].split()
        if not values:
            continue
        k = n - start
        x, y, z = (float(v) for v in values[:3])
        moved = (x + 0.2 * np.sin(k / 15.0), y + 0.03 * np.cos(k / 7.0), z + 0.012 * k)
        values[:3] = ["%.6f" % v for v in moved]
        lines[n] = " ".join(values)
    with open(os.path.join(folder, name + ".bvh"), "w") as f:
        f.write("\n".join(lines))
    with open(harness.take(source)) as f:
        data = json.load(f)
    data["outputs"] = [{"format": "bvh", "path": name + ".bvh"}]
    path = os.path.join(folder, name + ".imubake.json")
    with open(path, "w") as f:
        json.dump(data, f)
    return path


def pose_frames(frames):
    """Two take frames (0-based): one inside, and the last (where timing errors are largest)."""
    return (frames // 3, frames - 1)


class BatchExportTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="imubake-batch-")
        cls.info = {name: take_info(name) for name in TAKES}
        # The four walk takes, copied: the shared takes folder may hold others (see
        # test_every_sample_take_exports), these runs check exactly these.
        cls.takes = os.path.join(cls.tmp, "takes")
        os.makedirs(cls.takes)
        for name in TAKES:
            for ext in ("bvh", "glb", "imubake.json"):
                shutil.copy(harness.take(name, ext), os.path.join(cls.takes, "%s.%s" % (name, ext)))
        cls.runs = {}
        for engine in ENGINES:
            out = os.path.join(cls.tmp, "fbx-%s" % (engine or "none"))
            args = [cls.takes, out, "--format", "fbx"] + (["--engine", engine] if engine else [])
            cls.runs[("fbx", engine)] = (out, run_batch(*args))
        out = os.path.join(cls.tmp, "glb")
        cls.runs[("glb", None)] = (out, run_batch(cls.takes, out, "--format", "glb"))
        out = os.path.join(cls.tmp, "glb-godot")
        cls.runs[("glb", "godot")] = (
            out, run_batch(cls.takes, out, "--format", "glb", "--engine", "godot"))
        # The direct import's world-space heads: the reference for every export.
        ti = harness.submodule("take_import")
        cls.reference = {}
        for name in POSE_TAKES:
            harness.fresh_scene()
            imported = ti.import_take(bpy.context, harness.take(name))
            for n in pose_frames(imported.frames):
                cls.reference[(name, n)] = world_heads(imported.armature, n + 1)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def assert_only_script_lines(self, run):
        """stdout is the script's lines and nothing else (Blender's messages go to stderr)."""
        lines = run.stdout.splitlines()
        self.assertTrue(lines, run.stderr)
        for line in lines:
            self.assertRegex(line, "^(?:%s)$" % SCRIPT_LINE.pattern, run.stdout)

    def output(self, fmt, engine, name):
        return os.path.join(self.runs[(fmt, engine)][0], "%s.%s" % (name, fmt))

    # --- the runs -----------------------------------------------------------------------------

    def test_runs_exit_zero_with_a_line_and_a_file_per_take(self):
        for (fmt, engine), (out, run) in self.runs.items():
            with self.subTest(format=fmt, engine=engine):
                self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
                lines = LINE.findall(run.stdout)
                self.assertEqual([(int(i), int(n), name) for i, n, name, *_ in lines],
                                 [(i, len(TAKES), name) for i, name in enumerate(TAKES, 1)],
                                 run.stdout)
                for _i, _n, name, path, frames, rate, in lines:
                    fps, count = self.info[name]
                    self.assertEqual(os.path.abspath(path), os.path.abspath(self.output(fmt, engine, name)))
                    self.assertEqual((int(frames), rate), (count, rate_text(fps)))
                self.assertNotIn("FAILED", run.stdout)
                self.assertRegex(run.stdout, summary(4, 4, 0))
                self.assert_only_script_lines(run)
                # Exactly one file per take (and Godot's import settings beside a glb for it); no
                # hidden temporary file left behind.
                suffixes = (fmt, fmt + ".import") if (fmt, engine) == ("glb", "godot") else (fmt,)
                self.assertEqual(sorted(os.listdir(out)),
                                 sorted("%s.%s" % (n, s) for n in TAKES for s in suffixes))

    def test_every_sample_take_exports(self):
        # Whatever the shared takes folder holds (other rigs too), exported for Unreal.
        sidecar = harness.submodule("sidecar")
        paths = sidecar.find_sidecars(harness.takes_dir())
        names = [os.path.basename(p)[: -len(sidecar.SUFFIX)] for p in paths]
        out = os.path.join(self.tmp, "all-unreal")
        run = run_batch(harness.takes_dir(), out, "--format", "fbx", "--engine", "unreal")
        self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
        self.assertEqual([name for _i, _n, name, *_ in LINE.findall(run.stdout)], names, run.stdout)
        self.assertEqual(sorted(os.listdir(out)), sorted(n + ".fbx" for n in names))
        for path, name in zip(paths, names):
            with self.subTest(take=name):
                take = sidecar.load(path)
                root, _version = fbx_parse(os.path.join(out, name + ".fbx"))
                objects = children(root, b"Objects")[0]
                self.assertEqual([fbx_name(s) for s in children(objects, b"AnimationStack")], [name])
                for curve in children(objects, b"AnimationCurve"):
                    self.assertEqual(len(children(curve, b"KeyTime")[0].props[0]), take.frames)

    # --- FBX, raw -------------------------------------------------------------------------------

    def test_fbx_files_follow_the_documented_conventions(self):
        for engine in ENGINES:
            conv = CONVENTIONS[engine]
            for name in TAKES:
                with self.subTest(engine=engine, take=name):
                    fps, frames = self.info[name]
                    root, version = fbx_parse(self.output("fbx", engine, name))
                    self.assertEqual(version, 7400)
                    settings = props70(children(root, b"GlobalSettings")[0])
                    # Declared axes: the file's up and front axes are Blender's +Z and -Y (the
                    # take's up and facing direction) carried through the documented rotation.
                    up = conv["axes"] @ np.array([0, 0, 1.0])
                    front = conv["axes"] @ np.array([0, -1.0, 0])
                    up_axis = (settings["UpAxis"][0], settings["UpAxisSign"][0])
                    self.assertEqual(up_axis, axis_and_sign(up))
                    # FBX's front axis is the direction a model seen from the front faces
                    # (FBX's Y-up default: +Z; Blender's own axes: -Y).
                    front_axis = (settings["FrontAxis"][0], settings["FrontAxisSign"][0])
                    self.assertEqual(front_axis, axis_and_sign(front))
                    # FBX unit: UnitScaleFactor centimetres per file unit.
                    self.assertAlmostEqual(settings["UnitScaleFactor"][0], conv["unit_m"] * 100.0, places=9)
                    # Frame rate: NTSC rates use FBX's NTSC time mode (9), others their own mode.
                    self.assertAlmostEqual(settings["CustomFrameRate"][0] / float(fps), 1.0, delta=1e-9)
                    ntsc = 9 if fps == Fraction(30000, 1001) else None
                    expected_mode = {24: 11, 60: 3, 120: 1}.get(fps, ntsc)
                    self.assertEqual(settings["TimeMode"][0], expected_mode)

                    objects = children(root, b"Objects")[0]
                    models = {fbx_name(m): (m.props[2].decode(), props70(m))
                              for m in children(objects, b"Model")}
                    nulls = [n for n, (kind, _) in models.items() if kind == "Null"]
                    self.assertEqual(nulls, [conv["armature"] or name])
                    node = models[nulls[0]][1]
                    if conv["identity_node"]:
                        np.testing.assert_allclose(node.get("Lcl Translation", [0, 0, 0]), 0, atol=1e-9)
                        np.testing.assert_allclose(node.get("Lcl Rotation", [0, 0, 0]), 0, atol=1e-4)
                        np.testing.assert_allclose(node.get("Lcl Scaling", [1, 1, 1]), 1, atol=1e-6)
                        # The hips' rest position in file units: the BVH's hips at its first frame
                        # (Blender's BVH importer rests the root there; metres, BVH axes =
                        # Blender (x, -z, y)) carried by the documented conversion.
                        bvh_hips = Bvh(harness.take(name, "bvh")).world(0)["Hips"][1]
                        blender_hips = np.array([bvh_hips[0], -bvh_hips[2], bvh_hips[1]])
                        expected = conv["axes"] @ blender_hips / conv["unit_m"]
                        np.testing.assert_allclose(models["Hips"][1]["Lcl Translation"], expected, atol=1e-4)
                    else:
                        # Blender's default: the axis rotation and the x100 on the armature node.
                        np.testing.assert_allclose(node["Lcl Rotation"], [-90, 0, 0], atol=1e-4)
                        np.testing.assert_allclose(node["Lcl Scaling"], [100, 100, 100], atol=1e-6)
                    self.assertNotIn("Hips_end", models)  # no leaf bones

                    stacks = [fbx_name(s) for s in children(objects, b"AnimationStack")]
                    self.assertEqual(stacks, [name])
                    expected_times = np.arange(frames) / float(fps)
                    curves = children(objects, b"AnimationCurve")
                    self.assertGreater(len(curves), 3 * 22)
                    for curve in curves:
                        times = np.asarray(children(curve, b"KeyTime")[0].props[0], dtype=np.int64)
                        self.assertEqual(len(times), frames)
                        # Take frame n at n / fps seconds (to a microsecond: fps_base is a float32).
                        np.testing.assert_allclose(times / FBX_KTIME, expected_times, atol=1e-6, rtol=0)

    # --- FBX re-imported in Blender -------------------------------------------------------------

    def import_fbx(self, path, **options):
        harness.fresh_scene()
        ensure_addon("io_scene_fbx")
        result = bpy.ops.import_scene.fbx(filepath=path, use_anim=True, **options)
        self.assertIn("FINISHED", result)
        return the_armature()

    def test_fbx_reimport_has_the_takes_rate_and_frames(self):
        for engine in ENGINES:
            for name in TAKES:
                with self.subTest(engine=engine, take=name):
                    fps, frames = self.info[name]
                    armature = self.import_fbx(self.output("fbx", engine, name))
                    scene = bpy.context.scene
                    # Blender's FBX importer sets the scene rate from the file's time mode:
                    # 29.97 (mode 9, 30/1.001) becomes fps 30, fps_base 1.001, as import_take sets.
                    self.assertEqual((scene.render.fps, round(scene.render.fps_base, 6)), harness.RATES[name])
                    rate = scene.render.fps / scene.render.fps_base
                    self.assertAlmostEqual(rate / float(fps), 1.0, delta=1e-4)
                    self.assertIn(name, armature.animation_data.action.name)
                    curves = harness.fcurves(armature)
                    self.assertGreaterEqual(len(curves), 3 * 22)
                    # Blender's importer places a key at t seconds on frame 1 + t * scene.render.fps
                    # (fps alone, not fps / fps_base): integer rates land on 1..frames, but 29.97's
                    # keys land on 1 + n * 1.001. The file is right (key n at n / 29.97 s, checked
                    # above); the importer stretches NTSC takes by 0.1 %.
                    expected = 1.0 + np.arange(frames) * scene.render.fps / float(fps)
                    for fc in curves:
                        co = np.zeros(2 * len(fc.keyframe_points))
                        fc.keyframe_points.foreach_get("co", co)
                        keys = co[0::2]
                        self.assertEqual(len(keys), frames, fc.data_path)
                        np.testing.assert_allclose(keys, expected, atol=1e-3)
                        if fps.denominator == 1:
                            self.assertAlmostEqual(keys[-1] - keys[0], frames - 1, delta=1e-3)

    def test_unreal_export_is_in_centimetres(self):
        for name in POSE_TAKES:
            with self.subTest(take=name):
                # The hips' height at the first frame (where Blender's importer rests the root).
                bvh_hips = Bvh(harness.take(name, "bvh")).world(0)["Hips"][1][1]
                armature = self.import_fbx(self.output("fbx", "unreal", name))
                self.assertEqual(armature.name, "Armature")
                # The file says centimetres (UnitScaleFactor 1), so Blender's importer scales the
                # armature by 0.01 to metres: its bones hold the file's numbers, in cm.
                hips = armature.data.bones["Hips"]
                self.assertAlmostEqual(hips.head_local.z, bvh_hips * 100.0, delta=1e-3)
                np.testing.assert_allclose(armature.matrix_world.to_scale(), 0.01, rtol=1e-6)
                self.assertAlmostEqual((armature.matrix_world @ hips.head_local).z, bvh_hips, delta=1e-5)
                # The Unity export, in metres, for contrast: hips 1.0 in its bones, no scale.
                armature = self.import_fbx(self.output("fbx", "unity", name))
                np.testing.assert_allclose(armature.matrix_world.to_scale(), 1.0, rtol=1e-6)
                self.assertAlmostEqual((armature.matrix_world @ armature.data.bones["Hips"].head_local).z,
                                       bvh_hips, delta=1e-5)

    def assert_fbx_pose(self, path, engine, fps, frames, reference):
        """World-space heads of the FBX at two frames against `reference` {(n): {bone: head}}."""
        conv = CONVENTIONS[engine]
        # Read in the file's own axes (no axis conversion); the importer still turns the file's
        # unit into metres (UnitScaleFactor). Then the documented rotation is undone.
        armature = self.import_fbx(path, use_manual_orientation=True, axis_forward="Y", axis_up="Z")
        scene = bpy.context.scene
        for n in pose_frames(frames):
            frame = 1.0 + n * scene.render.fps / float(fps)  # the importer's placement, see above
            heads = world_heads(armature, frame)
            for bone in BONES:
                got = conv["axes"].T @ heads[bone]
                np.testing.assert_allclose(got, reference[n][bone], atol=2e-4,
                                           err_msg="%s at take frame %d" % (bone, n))

    def test_fbx_pose_matches_the_direct_import(self):
        for engine in ENGINES:
            for name in POSE_TAKES:
                with self.subTest(engine=engine, take=name):
                    fps, frames = self.info[name]
                    reference = {n: self.reference[(name, n)] for n in pose_frames(frames)}
                    self.assert_fbx_pose(self.output("fbx", engine, name), engine, fps, frames, reference)

    def test_root_motion_survives_every_convention(self):
        takes = os.path.join(self.tmp, "moving")
        os.makedirs(takes)
        sidecar = make_moving_take(takes)
        ti = harness.submodule("take_import")
        harness.fresh_scene()
        imported = ti.import_take(bpy.context, sidecar)
        fps, frames = imported.take.fps, imported.frames
        reference = {n: world_heads(imported.armature, n + 1) for n in pose_frames(frames)}
        # The root really travels: centimetres and axes now apply to the translation keys too.
        travel = reference[frames - 1]["Hips"] - reference[frames // 3]["Hips"]
        self.assertGreater(np.linalg.norm(travel), 1.0)
        for engine in ENGINES:
            with self.subTest(engine=engine):
                out = os.path.join(self.tmp, "moving-%s" % (engine or "none"))
                run = run_batch(takes, out, "--format", "fbx", *(["--engine", engine] if engine else []))
                self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
                self.assert_fbx_pose(os.path.join(out, "moving_24.fbx"), engine, fps, frames, reference)
        with self.subTest(format="glb"):
            out = os.path.join(self.tmp, "moving-glb")
            run = run_batch(takes, out, "--format", "glb")
            self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
            imported = self.import_glb_as_take(os.path.join(out, "moving_24.glb"), sidecar)
            for n in pose_frames(frames):
                heads = world_heads(imported.armature, n + 1)
                for bone in BONES:
                    np.testing.assert_allclose(heads[bone], reference[n][bone], atol=2e-4,
                                               err_msg="%s at take frame %d" % (bone, n))

    # --- glb --------------------------------------------------------------------------------------

    def test_glb_has_one_animation_per_take_sampled_on_its_frames(self):
        for name in TAKES:
            with self.subTest(take=name):
                fps, frames = self.info[name]
                doc, binary = read_glb(self.output("glb", None, name))
                self.assertEqual(doc["asset"]["version"], "2.0")
                self.assertEqual([a["name"] for a in doc["animations"]], [name])
                names = {n.get("name") for n in doc["nodes"]}
                self.assertTrue(set(Bvh(harness.take(name, "bvh")).names) - {None} <= names)
                self.assertFalse({n for n in names if n and n.endswith("_end")})  # no leaf bones
                inputs = {s["input"] for s in doc["animations"][0]["samplers"]}
                for index in inputs:
                    times = glb_floats(doc, binary, index)[:, 0]
                    self.assertEqual(len(times), frames)
                    # n / fps seconds, not n / (fps * fps_base) as Blender's exporter alone writes.
                    np.testing.assert_allclose(times, np.arange(frames) / float(fps), atol=2e-6, rtol=0)

    def test_glb_for_godot_has_godots_import_settings_beside_it(self):
        """Godot 3 bakes at the take's rate (the next whole one above 29.97: 30), optimizer off;
        Godot itself imports such a file in tests/outputs/godot_import.rs."""
        out, run = self.runs[("glb", "godot")]
        self.assertEqual(run.returncode, 0, run.stdout)
        for name in TAKES:
            with self.subTest(take=name):
                fps, _ = self.info[name]
                text = open(os.path.join(out, name + ".glb.import")).read()
                bake = -(-fps.numerator // fps.denominator)
                self.assertEqual(bake, {"walk_2997": 30}.get(name, fps))
                self.assertIn("\nanimation/fps=%d\n" % bake, text)
                self.assertIn("\nanimation/optimizer/enabled=false\n", text)
                self.assertTrue(text.startswith('[remap]\n\nimporter="scene"\n'), text)
                self.assertFalse(os.path.exists(self.output("glb", None, name) + ".import"))

    def import_glb_as_take(self, glb, sidecar):
        """The exported glb with a copy of the take's sidecar pointing at it, imported by the
        add-on (which moves the glTF importer's keys onto frames and refuses any key off them)."""
        name = os.path.basename(glb)[: -len(".glb")]
        folder = tempfile.mkdtemp(dir=self.tmp)
        shutil.copy(glb, os.path.join(folder, name + ".glb"))
        with open(sidecar) as f:
            data = json.load(f)
        data["outputs"] = [{"format": "glb", "path": name + ".glb"}]
        with open(os.path.join(folder, name + ".imubake.json"), "w") as f:
            json.dump(data, f)
        harness.fresh_scene()
        ti = harness.submodule("take_import")
        return ti.import_take(bpy.context, os.path.join(folder, name + ".imubake.json"))

    def test_glb_pose_matches_the_direct_import(self):
        for name in POSE_TAKES:
            with self.subTest(take=name):
                fps, frames = self.info[name]
                imported = self.import_glb_as_take(self.output("glb", None, name), harness.take(name))
                self.assertEqual(imported.action.name, name)
                for n in pose_frames(frames):
                    heads = world_heads(imported.armature, n + 1)
                    for bone in BONES:
                        np.testing.assert_allclose(heads[bone], self.reference[(name, n)][bone], atol=2e-4,
                                                   err_msg="%s at take frame %d" % (bone, n))

    # --- failures -----------------------------------------------------------------------------

    def test_a_bad_take_fails_alone(self):
        takes = os.path.join(self.tmp, "mixed")
        sub = os.path.join(takes, "session1")
        os.makedirs(sub)
        for ext in ("bvh", "glb", "imubake.json"):
            shutil.copy(harness.take("walk_24", ext), os.path.join(takes, "walk_24." + ext))
            shutil.copy(harness.take("walk_60", ext), os.path.join(sub, "walk_60." + ext))
        with open(os.path.join(takes, "bad.imubake.json"), "w") as f:
            f.write('{"fps": {"num": 24, "den": 1}, "frames": ')  # cut short: not JSON
        # A valid sidecar whose BVH is garbage: the importer fails, not the sidecar check.
        with open(harness.take("walk_24")) as f:
            data = json.load(f)
        data["outputs"] = [{"format": "bvh", "path": "broken.bvh"}]
        with open(os.path.join(takes, "broken.imubake.json"), "w") as f:
            json.dump(data, f)
        with open(os.path.join(takes, "broken.bvh"), "w") as f:
            f.write("HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 1\n")
        out = os.path.join(self.tmp, "mixed-out")
        run = run_batch(takes, out, "--format", "fbx", "--engine", "unity")
        self.assertEqual(run.returncode, 1, run.stdout + run.stderr)
        # Sorted: bad, broken, walk_24, then session1/walk_60.
        self.assertRegex(run.stdout, r"\[1/4\] bad: FAILED: .*bad\.imubake\.json is not valid JSON")
        self.assertRegex(run.stdout, r"\[2/4\] broken: FAILED: .*broken\.bvh")
        self.assertEqual([(i, name) for i, _n, name, *_ in LINE.findall(run.stdout)],
                         [("3", "walk_24"), ("4", os.path.join("session1", "walk_60"))])
        self.assertRegex(run.stdout, summary(2, 4, 2))
        # Blender's report of the broken BVH (a traceback it cuts short, without a newline) is
        # not on stdout: each of the script's lines is a line of its own there.
        self.assert_only_script_lines(run)
        self.assertEqual(sorted(os.listdir(out)), ["session1", "walk_24.fbx"])
        self.assertEqual(os.listdir(os.path.join(out, "session1")), ["walk_60.fbx"])

    def test_never_overwrites_the_takes_own_outputs(self):
        takes = os.path.join(self.tmp, "in-place")
        os.makedirs(takes)
        for ext in ("bvh", "glb", "imubake.json"):
            shutil.copy(harness.take("walk_24", ext), os.path.join(takes, "walk_24." + ext))
        before = open(os.path.join(takes, "walk_24.glb"), "rb").read()
        run = run_batch(takes, takes, "--format", "glb")
        self.assertEqual(run.returncode, 1, run.stdout + run.stderr)
        self.assertRegex(run.stdout, r"\[1/1\] walk_24: FAILED: .*walk_24\.glb is the take's own output")
        self.assertEqual(open(os.path.join(takes, "walk_24.glb"), "rb").read(), before)
        self.assertEqual(sorted(os.listdir(takes)), ["walk_24.bvh", "walk_24.glb", "walk_24.imubake.json"])

    def test_usage_errors_exit_2(self):
        missing = os.path.join(self.tmp, "no-such-folder")
        out = os.path.join(self.tmp, "usage-out")
        for args in (
            [missing, out, "--format", "fbx"],
            [harness.takes_dir(), out, "--format", "obj"],
            [harness.takes_dir(), out, "--format", "fbx", "--engine", "cryengine"],
            [harness.takes_dir(), out],
        ):
            with self.subTest(args=args[2:]):
                run = run_batch(*args)
                self.assertEqual(run.returncode, 2, run.stdout + run.stderr)
                self.assertIn("error", run.stderr)
        self.assertFalse(os.path.exists(out))


if __name__ == "__main__":
    unittest.main()
