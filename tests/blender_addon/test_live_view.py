"""The live view's posing (issue 19): VMC frames onto a Mixamo character in real Blender, checked by
where its bones then point: each turned from where it pointed at rest by the rotation sent, read in
Blender's axes (the rig's X, the character's left, is Blender's X; its up, Y, is Blender's Z; its
forward, Z, is Blender's −Y) — and a recording of N frames as N keys per channel."""

import math
import unittest

import bpy
import harness
from mathutils import Quaternion, Vector

S = math.sqrt(0.5)


def direction(arm, bone):
    pb = arm.pose.bones[bone]
    v = arm.matrix_world @ pb.tail - arm.matrix_world @ pb.head
    return v.normalized()


class Posing(unittest.TestCase):
    def setUp(self):
        self.arm = harness.mixamo_character()
        self.lv = harness.submodule("live_view")
        self.vmc = harness.submodule("vmc")
        self.view = self.lv.LiveView(self.arm, "REST")

    def frame(self, bones, t=0.0):
        f = self.vmc.Frame()
        f.t = t
        for name, q in bones.items():
            f.bones[name] = ((0.0, 1.0, 0.0) if name == "Hips" else (0.0, 0.1, 0.0), q)
        return f

    def rest(self, bone):
        return direction(self.arm, bone)

    def turned(self, rest, axis, deg):
        """`rest` turned by `deg` about `axis` (Blender's axes)."""
        return Quaternion(Vector(axis), math.radians(deg)) @ rest

    def assert_points(self, bone, expected, what):
        got = direction(self.arm, bone)
        angle = math.degrees(got.angle(Vector(expected)))
        self.assertLess(angle, 0.5, "%s: %s points %s" % (what, bone, tuple(round(c, 3) for c in got)))

    def test_rest_first(self):
        # The character in T-pose faces −Y: its left arm about along +X, its shins about down.
        self.assertGreater(self.rest("mixamorig:LeftArm").x, 0.98)
        self.assertLess(self.rest("mixamorig:LeftLeg").z, -0.98)

    def test_an_arm_turned_down_points_down(self):
        # −90° about the rig's forward axis (Z): the left arm from +X (the character's left) down.
        # In VMC's axes (X mirrored): (x, −y, −z, w) of (w, 0, 0, −sin 45°).
        arm, fore, right = (self.rest("mixamorig:" + b) for b in ("LeftArm", "LeftForeArm", "RightArm"))
        self.view.apply(self.frame({"Hips": (0, 0, 0, 1), "LeftUpperArm": (0, 0, S, S)}))
        bpy.context.view_layer.update()
        # −90° about the rig's +Z is +90° about Blender's +Y.
        self.assert_points("mixamorig:LeftArm", self.turned(arm, (0, 1, 0), 90), "arm down")
        self.assert_points("mixamorig:LeftForeArm", self.turned(fore, (0, 1, 0), 90), "the forearm follows")
        self.assert_points("mixamorig:RightArm", right, "the other arm stays")
        self.assertLess(direction(self.arm, "mixamorig:LeftArm").z, -0.98)

    def test_a_knee_bent_sends_the_shin_back(self):
        # +90° about the rig's left axis (X): the shin from down to backward (Blender +Y).
        shin, thigh = self.rest("mixamorig:LeftLeg"), self.rest("mixamorig:LeftUpLeg")
        self.view.apply(self.frame({"Hips": (0, 0, 0, 1), "LeftLowerLeg": (S, 0, 0, S)}))
        bpy.context.view_layer.update()
        self.assert_points("mixamorig:LeftLeg", self.turned(shin, (1, 0, 0), 90), "knee bent")
        self.assert_points("mixamorig:LeftUpLeg", thigh, "the thigh stays")
        self.assertGreater(direction(self.arm, "mixamorig:LeftLeg").y, 0.98, "behind")

    def test_the_hips_turn_the_body(self):
        # +90° about up (rig Y): facing +Z turns to facing +X; the left arm (+X) to rig −Z, which is
        # Blender's +Y (behind a character facing −Y).
        arm = self.rest("mixamorig:LeftArm")
        self.view.apply(self.frame({"Hips": (0, -S, 0, S)}))
        bpy.context.view_layer.update()
        self.assert_points("mixamorig:LeftArm", self.turned(arm, (0, 0, 1), 90), "hips turned")
        self.assertGreater(direction(self.arm, "mixamorig:LeftArm").y, 0.98, "behind")

    def test_the_hips_walk_scaled_to_the_character(self):
        hips = self.arm.pose.bones["mixamorig:Hips"]
        start = (self.arm.matrix_world @ hips.head).copy()
        f = self.frame({"Hips": (0, 0, 0, 1)})
        self.view.apply(f)  # the first frame: the hips 1 m up in VMC's axes
        f.bones["Hips"] = ((0.0, 1.0, 0.5), (0, 0, 0, 1))  # 0.5 m forward (VMC's and the rig's +Z)
        self.view.apply(f)
        bpy.context.view_layer.update()
        moved = self.arm.matrix_world @ hips.head - start
        # Forward is Blender's −Y; scaled by the character's hip height over the sender's 1 m.
        height = self.view.hips_height * self.arm.matrix_world.to_scale().z
        self.assertLess((moved - Vector((0, -0.5 * height, 0))).length, 1e-3 * height, moved)

    def test_unknown_bones_are_listed_not_applied(self):
        self.view.apply(self.frame({"Hips": (0, 0, 0, 1), "Tail": (0, 0, S, S)}))
        self.assertEqual(self.view.unmatched, ["Tail"])
        self.assertIn("LeftUpperArm", self.view.matched)

    def test_a_recording_keys_each_frame_shown(self):
        scene = bpy.context.scene
        arm = self.rest("mixamorig:LeftArm")
        for i in range(5):
            a = math.radians(10 * i) / 2
            self.view.apply(self.frame({"Hips": (0, 0, 0, 1), "LeftUpperArm": (0, 0, math.sin(a), math.cos(a))},
                                       t=i / 60))
            self.view.key(scene.frame_start + i)
        curves = [fc for fc in harness.fcurves(self.arm) if "LeftArm" in fc.data_path and "rotation" in fc.data_path]
        self.assertTrue(curves)
        for fc in curves:
            self.assertEqual([k.co.x for k in fc.keyframe_points],
                             [float(scene.frame_start + i) for i in range(5)])
        scene.frame_set(scene.frame_start + 4)
        bpy.context.view_layer.update()
        # The last key: 40° down about the forward axis.
        self.assert_points("mixamorig:LeftArm", self.turned(arm, (0, 1, 0), 40), "the recording's last frame")


if __name__ == "__main__":
    unittest.main()


class Panel(unittest.TestCase):
    """The Live panel's operators, the timer's tick called directly (timers do not fire in a
    background Blender): VMC packets from python-osc pose the character; Record keys one frame of
    the scene per frame received; bad packets change nothing and are counted; Recalibrate sends
    VMC's request to the performer."""

    def setUp(self):
        import socket

        from test_vmc import frame_bundle

        self.frame_bundle = frame_bundle
        self.arm = harness.mixamo_character()
        self.live = harness.submodule("live_view")
        scene = bpy.context.scene
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        probe.bind(("127.0.0.1", 0))
        scene.imubake_live_port = probe.getsockname()[1]
        probe.close()
        self.performer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.performer.bind(("127.0.0.1", 0))
        self.performer.settimeout(2.0)
        scene.imubake_live_performer = "127.0.0.1:%d" % self.performer.getsockname()[1]
        scene.imubake_live_target = self.arm
        scene.imubake_live_reference = "REST"
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.to = ("127.0.0.1", scene.imubake_live_port)

    def tearDown(self):
        bpy.ops.imubake.live_stop()
        self.tx.close()
        self.performer.close()

    def send_and_tick(self, data):
        self.tx.sendto(data, self.to)
        import time

        time.sleep(0.02)
        return self.live.current().tick()

    def test_start_show_record_recalibrate_stop(self):
        self.assertEqual(bpy.ops.imubake.live_start(), {"FINISHED"})
        session = self.live.current()
        rest = direction(self.arm, "mixamorig:LeftArm")
        scene = bpy.context.scene
        rate = scene.render.fps / scene.render.fps_base

        def arm_down(deg, t):
            a = math.radians(deg) / 2
            return self.frame_bundle(t, {"Hips": (0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
                                         "LeftUpperArm": (0.0, 0.1, 0.0, 0.0, 0.0, math.sin(a), math.cos(a))})

        self.assertIsNotNone(self.send_and_tick(arm_down(30, 0.0)))
        bpy.context.view_layer.update()
        turned = Quaternion(Vector((0, 1, 0)), math.radians(30)) @ rest
        self.assertLess(math.degrees(direction(self.arm, "mixamorig:LeftArm").angle(turned)), 0.5)
        # Bad packets: nothing changes, each is counted.
        self.send_and_tick(b"garbage")
        self.send_and_tick(self.frame_bundle(0.1, {"Hips": (0, 1, 0, float("nan"), 0, 0, 1)}))
        bpy.context.view_layer.update()
        self.assertLess(math.degrees(direction(self.arm, "mixamorig:LeftArm").angle(turned)), 0.5)
        self.assertEqual(session.receiver.bad, 2)
        self.assertIsNone(session.error)
        # Record six frames, at the scene's rate.
        self.assertEqual(bpy.ops.imubake.live_record(), {"FINISHED"})
        for i in range(6):
            self.send_and_tick(arm_down(10 * i, 1.0 + i / rate))
        action = session.recording[0]
        self.assertEqual(bpy.ops.imubake.live_record(), {"FINISHED"})
        self.assertIsNone(session.recording)
        self.assertTrue(action.name.startswith("imubake live"))
        self.assertEqual(self.arm.animation_data.action, action)
        curves = [fc for fc in harness.fcurves(self.arm) if "LeftArm\"]" in fc.data_path and "rotation" in fc.data_path]
        self.assertTrue(curves)
        for fc in curves:
            self.assertEqual([k.co.x for k in fc.keyframe_points],
                             [float(scene.frame_start + i) for i in range(6)])
        # Recalibrate: VMC's request reaches the performer, as python-osc reads it.
        from pythonosc.osc_message import OscMessage

        self.assertEqual(bpy.ops.imubake.live_recalibrate(), {"FINISHED"})
        data, _ = self.performer.recvfrom(1024)
        self.assertEqual(OscMessage(data).address, "/VMC/Ext/Set/Calib/Exec")
        self.assertIn("LeftUpperArm", session.view.matched)
        self.assertEqual(bpy.ops.imubake.live_stop(), {"FINISHED"})
        self.assertIsNone(self.live.current())


class Characters(unittest.TestCase):
    def test_a_generated_rigify_rig_follows_through_its_controls(self):
        """python-osc packets through the panel's session onto a generated Rigify rig: its
        deforming bones, driven by constraints from the FK controls the live view sets, turn since
        the rest pose as the sent bones have turned (composed here down Unity's hierarchy)."""
        import socket
        import time

        import numpy as np
        from bvh_reference import Y_UP_TO_Z_UP as C, angle_deg
        from test_vmc import frame_bundle

        meta = harness.rigify_metarig()
        self.assertEqual(bpy.ops.pose.rigify_generate(), {"FINISHED"})
        rig = bpy.context.object
        self.assertNotEqual(rig, meta)
        session = harness.submodule("live_view").Session(rig, port=0, reference="REST")
        self.assertIn("upper_arm_fk.L", session.view.bone_of.values())
        sent = {  # Unity's axes, (x, y, z, w)
            "Hips": (0.0, 0.0, 0.0, 1.0),
            "Spine": (0.1305262, 0.0, 0.0, 0.9914449),  # 15° about x
            "LeftUpperArm": (0.0, 0.2, S, 0.6782330),
            "LeftLowerArm": (0.0, -0.5, 0.0, 0.8660254),
            "RightUpperLeg": (-0.2588190, 0.0, 0.0, 0.9659258),
            "RightLowerLeg": (0.5, 0.0, 0.0, 0.8660254),
        }
        bones = {n: ((0.0, 1.0, 0.0) if n == "Hips" else (0.0, 0.1, 0.0)) + q for n, q in sent.items()}
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(frame_bundle(0.0, bones), ("127.0.0.1", session.receiver.port))
        time.sleep(0.05)
        self.assertIsNotNone(session.tick())
        session.close()
        bpy.context.view_layer.update()

        def rig_rotation(x, y, z, w):  # the documented mirror of X, as a numpy matrix
            return np.array(Quaternion((w, x, -y, -z)).normalized().to_matrix())

        parent = {"Hips": None, "Spine": "Hips", "LeftUpperArm": "Spine", "LeftLowerArm": "LeftUpperArm",
                  "RightUpperLeg": "Hips", "RightLowerLeg": "RightUpperLeg"}
        world = {}
        for n in parent:
            p = parent[n]
            world[n] = (world[p] if p else np.eye(3)) @ rig_rotation(*sent[n])
        tw = np.array(rig.matrix_world.to_3x3())
        worst = 0.0
        # The ORG upper arm carries the humerus' full rotation (Rigify's first DEF segment of the
        # upper arm does not take its twist, by design).
        for unity, deform in (("Spine", "DEF-spine.001"), ("LeftUpperArm", "ORG-upper_arm.L"),
                              ("LeftLowerArm", "DEF-forearm.L"), ("RightUpperLeg", "DEF-thigh.R"),
                              ("RightLowerLeg", "DEF-shin.R")):
            got = harness.world_rot(rig, rig.pose.bones[deform]) @ (tw @ np.array(
                rig.data.bones[deform].matrix_local.to_3x3().normalized())).T
            want = C @ world[unity] @ C.T
            err = angle_deg(got, want)
            worst = max(worst, err)
            self.assertLess(err, 0.5, "%s → %s: %.3f°" % (unity, deform, err))
        print("\n  generated Rigify rig: worst deforming bone %.3f°" % worst)

    def test_t_pose_alignment_straightens_a_metarigs_arms(self):
        # Rigify's metarig rests with its arms about 28° below horizontal: "AUTO" turns them to the
        # performer's T-pose first, so a frame at rest shows a T-pose and an arm sent down points
        # straight down.
        rig = harness.rigify_metarig()
        self.assertLess(direction(rig, "upper_arm.L").z, -0.3)
        view = harness.submodule("live_view").LiveView(rig, "AUTO")
        f = harness.submodule("vmc").Frame()
        f.bones["Hips"] = ((0.0, 1.0, 0.0), (0, 0, 0, 1))
        view.apply(f)
        bpy.context.view_layer.update()
        self.assertGreater(direction(rig, "upper_arm.L").x, 0.9999)
        self.assertLess(direction(rig, "thigh.R").z, -0.9999)
        f.bones["LeftUpperArm"] = ((0.0, 0.1, 0.0), (0, 0, S, S))
        view.apply(f)
        bpy.context.view_layer.update()
        self.assertLess(direction(rig, "upper_arm.L").z, -0.9999)


class EndToEnd(unittest.TestCase):
    """`imubake live` replaying the bundled walk into the live view: every frame shown puts every
    matched bone of the Mixamo character where the whole-take conversion (causal, 60 fps, read by
    an independent numpy BVH reader) says that bone has turned since the rest pose."""

    def test_imubake_live_into_the_character(self):
        import os
        import subprocess
        import tempfile
        import time

        import numpy as np
        from bvh_reference import Bvh, Y_UP_TO_Z_UP as C, angle_deg

        repo, exe = os.environ["IMUBAKE_REPO"], os.environ["IMUBAKE_BIN"]
        capture = os.path.join(repo, "samples", "walk.csv")
        mapping = os.path.join(repo, "mappings", "paper000_16imu_mixamo.json")
        out = tempfile.mkdtemp(prefix="imubake-live-")
        subprocess.run([exe, "convert", capture, "--mapping", mapping, "--causal", "--fps", "60",
                        "--format", "bvh", "--out", out], check=True, capture_output=True)
        bvh = Bvh(os.path.join(out, "walk.bvh"))
        arm = harness.mixamo_character()
        live = harness.submodule("live_view")
        names = harness.submodule("names")
        session = live.Session(arm, port=0, reference="REST")
        tw = np.array(arm.matrix_world.to_3x3())
        rest = {b.name: np.array(b.matrix_local.to_3x3().normalized()) for b in arm.data.bones}
        proc = subprocess.Popen([exe, "live", "--source", "file:%s@2" % capture, "--mapping", mapping,
                                 "--vmc", "127.0.0.1:%d" % session.receiver.port, "--listen", "off"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        worst, shown = 0.0, 0
        try:
            while True:
                frame = session.tick()
                if frame is not None:
                    bpy.context.view_layer.update()
                    n = int(round(frame.t * 60))
                    src = bvh.world(n)
                    for unity, bone in session.view.bone_of.items():
                        if unity not in frame.bones:
                            continue
                        got = harness.world_rot(arm, arm.pose.bones[bone]) @ (tw @ rest[bone]).T
                        want = C @ src[names.canonical(unity)][0] @ C.T
                        worst = max(worst, angle_deg(got, want))
                    shown += 1
                if proc.poll() is not None and frame is None:
                    break
                time.sleep(1 / 60)
        finally:
            session.close()
        self.assertEqual(proc.returncode, 0, proc.stderr.read().decode())
        print("\n  live into Blender: %d frames shown, worst bone %.4f°" % (shown, worst))
        self.assertGreater(shown, 100)
        self.assertLess(worst, 0.5)
        self.assertEqual(session.receiver.bad, 0)
