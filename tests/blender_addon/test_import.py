"""File > Import > imubake take: exact scene rate, frame range, keys, and bone world matrices
checked against an independent BVH reader (bvh_reference.py, numpy only)."""

import json
import math
import os
import shutil
import tempfile
import unittest

import bpy
import numpy as np

import harness
from bvh_reference import Y_UP_TO_Z_UP as C
from bvh_reference import Bvh, angle_deg


def import_op(path, **kw):
    return bpy.ops.import_scene.imubake_take(filepath=path, **kw)


def capture_stdout(call):
    """What `call` writes to file descriptor 1 (Blender's C code included)."""
    import sys

    sys.stdout.flush()
    saved = os.dup(1)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 1)
        try:
            call()
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
        tmp.seek(0)
        return tmp.read().decode("utf-8", "replace")


def sidecar(name):
    with open(harness.take(name), encoding="utf-8") as f:
        return json.load(f)


class ImportAtExactRate(unittest.TestCase):
    def check_take(self, name, fmt):
        scene = harness.fresh_scene()
        # A longer scene than the take: the import must shorten it.
        scene.frame_end = 5000
        path = harness.take(name, fmt)
        self.assertEqual(import_op(path), {"FINISHED"})
        data = sidecar(name)
        frames = data["frames"]
        fps, base = harness.RATES[name]
        self.assertEqual(scene.render.fps, fps)
        self.assertAlmostEqual(scene.render.fps_base, base, places=6)
        # fps / fps_base is the sidecar's rational rate.
        rate = data["fps"]["num"] / data["fps"]["den"]
        self.assertAlmostEqual(scene.render.fps / scene.render.fps_base, rate, delta=rate * 1e-6)
        self.assertEqual((scene.frame_start, scene.frame_end), (1, frames))

        arms = harness.armatures()
        self.assertEqual(len(arms), 1)
        arm = arms[0]
        self.assertEqual(arm.name, name)
        self.assertEqual(arm.animation_data.action.name, name)
        curves = harness.fcurves(arm)
        # Every animated bone (the GLB leaves out bones no sensor drives) has rotation curves.
        self.assertGreater(len(curves), 16 * 3)
        for fc in curves:
            xs = [p.co[0] for p in fc.keyframe_points]
            self.assertEqual(len(xs), frames, fc.data_path)
            # One key on every frame 1..frames, exactly on the frame.
            self.assertEqual(xs, [float(i) for i in range(1, frames + 1)], fc.data_path)

        # Bone world matrices against the independent reader of the take's BVH: Blender frame
        # n + 1 is take frame n; a bone's world rotation is C·R_bvh·Cᵀ times its rest rotation
        # (rest rotations are identity in BVH), its head C·p_bvh.
        bvh = Bvh(harness.take(name, "bvh"))
        self.assertEqual(bvh.frames, frames)
        worst_rot, worst_pos, worst_bone = 0.0, 0.0, ("", 0)
        for f in (0, frames // 3, frames - 1):
            scene.frame_set(f + 1)
            ref = bvh.world(f)
            for pb in arm.pose.bones:
                rot, pos = ref[pb.name]
                want = C @ rot @ C.T @ harness.rest_rot(arm, pb.name)
                err = angle_deg(harness.world_rot(arm, pb), want)
                if err > worst_rot:
                    worst_bone = (pb.name, f)
                worst_rot = max(worst_rot, err)
                head = np.array(arm.matrix_world @ pb.head)
                worst_pos = max(worst_pos, float(np.linalg.norm(head - C @ pos)))
        # Blender's pose matrices are single precision: bones deep in the chain already differ by
        # up to 0.01° from the double-precision reference (walk_24's BVH: 0.0099°).
        self.assertLess(worst_rot, 0.02, "%s %s: worst bone rotation error %.4f° (%s at take frame %d)"
                        % (name, fmt, worst_rot, worst_bone[0], worst_bone[1]))
        self.assertLess(worst_pos, 1e-4, "%s %s: worst head error %.6f m" % (name, fmt, worst_pos))
        self.assert_no_flips(arm, frames)

    def assert_no_flips(self, arm, frames):
        """No bone turns by 90° or more between frames, and no Euler channel jumps by 180°+."""
        for fc in harness.fcurves(arm):
            if "rotation_euler" in fc.data_path:
                values = [p.co[1] for p in fc.keyframe_points]
                jump = max(abs(b - a) for a, b in zip(values, values[1:]))
                self.assertLess(math.degrees(jump), 180.0, fc.data_path)
        scene = bpy.context.scene
        prev = None
        for f in range(1, frames + 1, max(1, frames // 120)):
            scene.frame_set(f)
            now = {pb.name: harness.world_rot(arm, pb) for pb in arm.pose.bones}
            if prev is not None:
                for n in now:
                    self.assertLess(angle_deg(now[n], prev[n]), 90.0, "%s at frame %d" % (n, f))
            prev = now

    def test_bvh_at_24(self):
        self.check_take("walk_24", "imubake.json")

    def test_bvh_at_2997(self):
        self.check_take("walk_2997", "bvh")

    def test_bvh_at_60(self):
        self.check_take("walk_60", "imubake.json")

    def test_bvh_at_120(self):
        self.check_take("walk_120", "imubake.json")

    def test_glb_at_2997_lands_on_frames(self):
        # Blender's glTF importer alone would put key n at n * 1.002 at 29.97 fps.
        self.check_take("walk_2997", "glb")

    def test_glb_at_24(self):
        self.check_take("walk_24", "glb")

    def test_bind_frame_at_scene_frame_1(self):
        # `--bind-frame`: take frame 0 is the rig's rest pose, so scene frame 1 shows it (every
        # bone at rest) and the take plays from scene frame 2, each frame where the BVH puts it.
        self.check_take("walk_bind", "bvh")
        self.assertTrue(sidecar("walk_bind")["pipeline"]["bind_frame"])
        arm = harness.armatures()[0]
        bpy.context.scene.frame_set(1)
        for pb in arm.pose.bones:
            self.assertLess(pb.matrix_basis.to_quaternion().angle, 1e-5, pb.name)
        bpy.context.scene.frame_set(2)
        self.assertTrue(any(pb.matrix_basis.to_quaternion().angle > 1e-3 for pb in arm.pose.bones))

    def test_in_place_root_joint(self):
        # `--in-place`: a `root` bone at floor level carries the walk; the hips ride on it, and
        # every bone lands where the BVH puts it, from the BVH and from the GLB.
        for fmt in ("bvh", "glb"):
            self.check_take("walk_inplace", fmt)
            arm = harness.armatures()[0]
            self.assertEqual(arm.data.bones["Hips"].parent.name, "root")

    def test_glb_euler_mode(self):
        harness.fresh_scene()
        self.assertEqual(import_op(harness.take("walk_60", "glb"), rotation_mode="ZYX"), {"FINISHED"})
        arm = harness.armatures()[0]
        self.assertEqual({pb.rotation_mode for pb in arm.pose.bones}, {"ZYX"})
        self.assertFalse([fc for fc in harness.fcurves(arm) if "quaternion" in fc.data_path])


class Contacts(unittest.TestCase):
    def test_contacts_are_keyed_as_custom_properties(self):
        harness.fresh_scene()
        path = harness.take("walk_60", "imubake.json")
        data = json.load(open(path, encoding="utf-8"))
        self.assertEqual(data["pipeline"]["root"], "feet")
        self.assertEqual(import_op(path), {"FINISHED"})
        arm = harness.armatures()[0]
        frames = data["frames"]
        for side in ("left", "right"):
            expected = [0.0] * frames
            for start, end in data["contacts"][side]:
                for n in range(start, end + 1):
                    expected[n] = 1.0
            self.assertGreater(sum(expected), frames / 4, side)
            fc = next(fc for fc in harness.fcurves(arm) if fc.data_path == '["contact_%s"]' % side)
            self.assertEqual([p.co[0] for p in fc.keyframe_points], [float(n + 1) for n in range(frames)])
            self.assertEqual([p.co[1] for p in fc.keyframe_points], expected)
            # What an IK setup reads: the property's value at a scene frame.
            for n in (0, frames // 3, frames - 1):
                bpy.context.scene.frame_set(n + 1)
                self.assertEqual(arm["contact_%s" % side], expected[n], (side, n))


class BadSidecars(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp()
        for ext in ("bvh", "glb"):
            shutil.copy(harness.take("walk_24", ext), os.path.join(self.dir, "t.%s" % ext))
        self.good = sidecar("walk_24")
        self.good["outputs"] = [{"format": "bvh", "path": "t.bvh"}, {"format": "glb", "path": "t.glb"}]

    def write(self, data):
        path = os.path.join(self.dir, "t.imubake.json")
        with open(path, "w", encoding="utf-8") as f:
            f.write(data if isinstance(data, str) else json.dumps(data))
        return path

    def assert_refused(self, path, words):
        scene = harness.fresh_scene()
        scene.render.fps, scene.render.fps_base, scene.frame_end = 25, 1.0, 77
        counts = (len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures))
        with self.assertRaises(RuntimeError) as raised:
            import_op(path)
        message = str(raised.exception)
        for w in words:
            self.assertIn(w, message)
        self.assertEqual((len(bpy.data.objects), len(bpy.data.actions), len(bpy.data.armatures)), counts)
        self.assertEqual((scene.render.fps, scene.render.fps_base, scene.frame_end), (25, 1.0, 77))

    def test_good_copy_imports(self):
        harness.fresh_scene()
        self.assertEqual(import_op(self.write(self.good)), {"FINISHED"})

    def test_not_json(self):
        self.assert_refused(self.write('{"fps": {"num": 24,'), ["t.imubake.json", "not valid JSON"])

    def test_zero_denominator(self):
        bad = dict(self.good, fps={"num": 24, "den": 0})
        self.assert_refused(self.write(bad), ["fps.den", "positive integer"])

    def test_frames_not_a_number(self):
        bad = dict(self.good, frames="__import__('os').system('false')")
        self.assert_refused(self.write(bad), ["frames", "int"])

    def test_output_outside_folder(self):
        bad = dict(self.good, outputs=[{"format": "bvh", "path": "../../etc/passwd"}])
        self.assert_refused(self.write(bad), ["not inside the take's folder"])

    def test_missing_output_file(self):
        bad = dict(self.good, outputs=[{"format": "bvh", "path": "gone.bvh"}])
        self.assert_refused(self.write(bad), ["gone.bvh", "missing"])

    def test_bvh_without_sidecar(self):
        self.assert_refused(os.path.join(self.dir, "t.bvh"), ["no sidecar", "t.imubake.json"])

    def test_truncated_bvh_restores_scene(self):
        with open(os.path.join(self.dir, "t.bvh"), "r+", encoding="utf-8") as f:
            f.truncate(300)
        self.assert_refused(self.write(self.good), ["t.bvh"])

    def test_warnings_are_reported(self):
        take_import = harness.submodule("take_import")
        harness.fresh_scene()
        data = dict(self.good, warnings=["sensor N5_1 is not in the mapping; ignored"],
                    dropped_lines=[{"line": 3, "reason": "bad", "text": "x"}])
        path = self.write(data)
        imported = take_import.import_take(bpy.context, path)
        self.assertIn("sensor N5_1 is not in the mapping; ignored", imported.warnings)
        self.assertTrue(any("1 line(s)" in w for w in imported.warnings))
        # Through the operator: Blender prints a headless operator's reports on stdout (fd 1).
        harness.fresh_scene()
        printed = capture_stdout(lambda: self.assertEqual(import_op(path), {"FINISHED"}))
        self.assertIn("t: sensor N5_1 is not in the mapping; ignored", printed)


if __name__ == "__main__":
    unittest.main()


class Registration(unittest.TestCase):
    def test_menu_entry_panel_and_clean_disable(self):
        import addon_utils

        ui = harness.submodule("ui")
        self.assertTrue(hasattr(bpy.types, "IMPORT_SCENE_OT_imubake_take"))
        self.assertTrue(hasattr(bpy.types, "IMUBAKE_PT_watch"))
        self.assertIn(ui._menu_import, bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize())
        addon_utils.disable(harness.MODULE, default_set=True)
        try:
            self.assertFalse(hasattr(bpy.types, "IMPORT_SCENE_OT_imubake_take"))
            self.assertFalse(hasattr(bpy.types.Scene, "imubake_watch_folder"))
        finally:
            addon_utils.enable(harness.MODULE, default_set=True)
        self.assertTrue(hasattr(bpy.types, "IMPORT_SCENE_OT_imubake_take"))
