"""The watch folder: takes written after watching started are imported by the poll (timers never
fire in a headless bpy), each into its own action, onto the chosen character when set."""

import json
import os
import shutil
import tempfile
import unittest

import bpy

import harness


def write_take(folder, source, stem):
    """Writes take `source` into `folder` as `stem` the way imubake does: outputs first, the
    sidecar last through a hidden temporary file renamed into place."""
    for ext in ("bvh", "glb"):
        shutil.copy(harness.take(source, ext), os.path.join(folder, "%s.%s" % (stem, ext)))
    with open(harness.take(source), encoding="utf-8") as f:
        data = json.load(f)
    data["outputs"] = [{"format": "bvh", "path": stem + ".bvh"}, {"format": "glb", "path": stem + ".glb"}]
    tmp = os.path.join(folder, ".%s.imubake.json.tmp" % stem)
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(data, f)
    os.replace(tmp, os.path.join(folder, stem + ".imubake.json"))
    return data["frames"]


class WatchFolder(unittest.TestCase):
    def setUp(self):
        self.watch = harness.submodule("watch")
        self.folder = tempfile.mkdtemp()

    def tearDown(self):
        bpy.ops.imubake.watch_stop()

    def start(self):
        bpy.context.scene.imubake_watch_folder = self.folder
        self.assertEqual(bpy.ops.imubake.watch_start(), {"FINISHED"})
        self.assertIsNotNone(self.watch.current())

    def test_poll_imports_new_takes_once(self):
        harness.fresh_scene()
        write_take(self.folder, "walk_24", "before")  # there before watching: not imported
        self.start()
        self.assertEqual(self.watch.poll(), [])
        frames_a = write_take(self.folder, "walk_60", "take_a")
        os.makedirs(os.path.join(self.folder, "session2"))
        frames_b = write_take(os.path.join(self.folder, "session2"), "walk_2997", "take_b")
        # A half-written take (no sidecar yet) is not touched.
        shutil.copy(harness.take("walk_24", "bvh"), os.path.join(self.folder, "take_c.bvh"))
        done = self.watch.poll()
        self.assertEqual([os.path.basename(p) for p, _ in done], ["take_a.imubake.json", "take_b.imubake.json"])
        self.assertEqual(sorted(a.name for a in harness.armatures()), ["take_a", "take_b"])
        for name, frames in (("take_a", frames_a), ("take_b", frames_b)):
            arm = bpy.data.objects[name]
            self.assertEqual(arm.animation_data.action.name, name)
            self.assertEqual({len(fc.keyframe_points) for fc in harness.fcurves(arm)}, {frames})
        # The scene shows the newest take at its rate.
        scene = bpy.context.scene
        self.assertEqual((scene.render.fps, round(scene.render.fps_base, 6), scene.frame_end), (30, 1.001, frames_b))
        self.assertEqual(self.watch.poll(), [])
        self.assertNotIn("before", [o.name for o in bpy.data.objects])

    def test_poll_retargets_onto_chosen_character(self):
        target = harness.mixamo_character()
        bpy.context.scene.imubake_watch_target = target
        bpy.context.scene.imubake_watch_reference = "REST"
        self.start()
        write_take(self.folder, "walk_60", "one")
        write_take(self.folder, "walk_24", "two")
        done = self.watch.poll()
        self.assertEqual([a for _, a in done], ["one", "two"])
        # Only the character is left; each take is its own action on it.
        self.assertEqual([a.name for a in harness.armatures()], ["Character"])
        self.assertIn("one", bpy.data.actions)
        self.assertIn("two", bpy.data.actions)
        self.assertEqual(target.animation_data.action.name, "two")

    def test_bad_take_is_reported_and_watch_goes_on(self):
        harness.fresh_scene()
        self.start()
        with open(os.path.join(self.folder, "broken.imubake.json"), "w", encoding="utf-8") as f:
            f.write("{not json")
        write_take(self.folder, "walk_60", "fine")
        done = dict((os.path.basename(p), r) for p, r in self.watch.poll())
        self.assertIn("not valid JSON", str(done["broken.imubake.json"]))
        self.assertEqual(done["fine.imubake.json"], "fine")
        # A reconverted take (its sidecar replaced) is imported again.
        self.assertEqual(self.watch.poll(), [])
        write_take(self.folder, "walk_24", "fine")
        os.utime(os.path.join(self.folder, "fine.imubake.json"), ns=(1, 1))
        self.assertEqual(len(self.watch.poll()), 1)


if __name__ == "__main__":
    unittest.main()
