"""Retargeting onto the animator's character: a Mixamo armature (from ../shared/data's Mixamo rig
BVH), a Rigify human metarig, and a generated Rigify rig (FK controls). The source motion comes
from the take's BVH through the independent reader (bvh_reference.py): a target bone's world
rotation since the reference pose must equal C·R_bvh(f)·Cᵀ (BVH rest rotations are identity and
the take's rig rests in T-pose) within 2°."""

import json
import os
import tempfile
import unittest

import bpy
import numpy as np

import harness
from bvh_reference import Y_UP_TO_Z_UP as C
from bvh_reference import Bvh, angle_deg

TAKE = "walk_60"
SIDES = {"Left": ".L", "Right": ".R"}
# The expected maps, written out by hand (not computed by the add-on's name rules).
RIGIFY_META = {"Hips": "spine", "Spine": "spine.001", "Spine1": "spine.002", "Spine2": "spine.003",
               "Neck": "spine.004", "Head": "spine.006"}
RIGIFY_GENERATED = {"Hips": "torso", "Spine": "spine_fk.001", "Spine1": "spine_fk.002",
                    "Spine2": "spine_fk.003", "Neck": "neck", "Head": "head"}
for side, suffix in SIDES.items():
    for ours, theirs in (("Shoulder", "shoulder"), ("Arm", "upper_arm"), ("ForeArm", "forearm"),
                         ("Hand", "hand"), ("UpLeg", "thigh"), ("Leg", "shin"), ("Foot", "foot"),
                         ("ToeBase", "toe")):
        RIGIFY_META[side + ours] = theirs + suffix
        RIGIFY_GENERATED[side + ours] = theirs + ("" if ours == "Shoulder" else "_fk") + suffix
# Limb bones the automatic reference turns to the take's T-pose, with their direction in the
# take's rig (BVH offsets of the child joint), mapped to Blender's Z-up.
LIMB_DIRECTIONS = {"LeftArm": (1, 0, 0), "LeftForeArm": (1, 0, 0), "RightArm": (-1, 0, 0),
                   "RightForeArm": (-1, 0, 0), "LeftUpLeg": (0, -1, 0), "LeftLeg": (0, -1, 0)}


def import_take():
    return harness.submodule("take_import").import_take(bpy.context, harness.take(TAKE))


def follows(test, target, bone_map, reference, frames, bones_to_check=None, limit=2.0):
    """Worst angle between each mapped target bone's world rotation since the reference pose and
    the source bone's (from the BVH), over `frames` (take frames)."""
    bvh = Bvh(harness.take(TAKE, "bvh"))
    scene = bpy.context.scene
    tw = np.array(target.matrix_world.to_3x3())
    worst = 0.0
    for f in frames:
        scene.frame_set(f + 1)
        src = bvh.world(f)
        for s, t in (bones_to_check or bone_map).items():
            got = harness.world_rot(target, target.pose.bones[t]) @ (tw @ reference(t)).T
            want = C @ src[s][0] @ C.T
            err = angle_deg(got, want)
            worst = max(worst, err)
            test.assertLess(err, limit, "%s -> %s at frame %d: %.2f°" % (s, t, f, err))
    print("\n  %s: worst bone error %.3f° over %d bones" % (test.id(), worst, len(bones_to_check or bone_map)))
    return worst


class RetargetMixamo(unittest.TestCase):
    def test_operator_bakes_onto_selected_mixamo_armature(self):
        target = harness.mixamo_character()
        bpy.context.view_layer.objects.active = target
        frames = json.load(open(harness.take(TAKE), encoding="utf-8"))["frames"]
        rest = {b.name: np.array(b.matrix_local.to_3x3().normalized()) for b in target.data.bones}
        hips_rest = np.array(target.matrix_world @ target.data.bones["mixamorig:Hips"].head_local)
        result = bpy.ops.import_scene.imubake_take(filepath=harness.take(TAKE), reference="REST")
        self.assertEqual(result, {"FINISHED"})
        # The temporary imported armature is gone; the character plays a new action.
        self.assertEqual([a.name for a in harness.armatures()], ["Character"])
        self.assertNotIn(TAKE, [o.name for o in bpy.data.objects])
        self.assertEqual(target.animation_data.action.name, TAKE)
        self.assertEqual((bpy.context.scene.frame_start, bpy.context.scene.frame_end), (1, frames))
        bone_map = {n: "mixamorig:" + n for n in RIGIFY_META}
        for fc in harness.fcurves(target):
            self.assertEqual(len(fc.keyframe_points), frames)
        keyed = {fc.data_path.split('"')[1] for fc in harness.fcurves(target)}
        self.assertTrue(set(bone_map.values()) <= keyed)
        # The feet's contacts come along as the character's custom properties.
        self.assertTrue({"contact_left", "contact_right"} <= keyed)
        follows(self, target, bone_map, lambda t: rest[t], (0, frames // 2, frames - 1))

        # Root motion scaled by hip height: the character's hips (rest height above its lowest
        # bone point, in its own units) move as the take's hips (the take walks: --root auto is
        # feet) times the ratio; the take's hips are 0.98 m above its toes (offsets 0.0725 + 0.43
        # + 0.43 + 0.0475 below them).
        bones = target.data.bones
        lowest = min(min(b.head_local.z, b.tail_local.z) for b in bones)
        ratio = (bones["mixamorig:Hips"].head_local.z - lowest) / (0.0725 + 0.43 + 0.43 + 0.0475)
        bvh = Bvh(harness.take(TAKE, "bvh"))
        source_rest = np.array([0.0, 1.0, 0.0])
        for f in (frames // 2, frames - 1):
            bpy.context.scene.frame_set(f + 1)
            got = np.array(target.matrix_world @ target.pose.bones["mixamorig:Hips"].head) - hips_rest
            want = C @ (bvh.world(f)["Hips"][1] - source_rest) * ratio
            self.assertLess(np.linalg.norm(got - want), 1e-3 * ratio)

    def test_bone_map_json_limits_the_bake(self):
        target = harness.mixamo_character()
        imported = import_take()
        names = harness.submodule("names")
        retarget = harness.submodule("retarget")
        path = os.path.join(tempfile.mkdtemp(), "arms.json")
        with open(path, "w", encoding="utf-8") as f:
            # Values may be target bones or canonical part names resolved on the target.
            json.dump({"bones": {"LeftArm": "mixamorig:LeftArm", "LeftForeArm": "LeftForeArm"}}, f)
        bone_map = names.load_bone_map(path, [b.name for b in imported.armature.data.bones],
                                       [b.name for b in target.data.bones])
        self.assertEqual(bone_map, {"LeftArm": "mixamorig:LeftArm", "LeftForeArm": "mixamorig:LeftForeArm"})
        result = retarget.retarget(bpy.context, imported.armature, target, bone_map=bone_map, reference="REST")
        rotated = {fc.data_path.split('"')[1] for fc in harness.fcurves(target) if "rotation" in fc.data_path}
        # The mapped bones and the chain above them (held at the reference pose), nothing else.
        self.assertIn("mixamorig:LeftForeArm", rotated)
        self.assertNotIn("mixamorig:RightArm", rotated)
        self.assertNotIn("mixamorig:LeftUpLeg", rotated)
        follows(self, target, bone_map, lambda t: np.array(result.reference[t].to_3x3().normalized()),
                (10, 100))
        with open(path, "w", encoding="utf-8") as f:
            json.dump({"bones": {"NoSuchBone": "mixamorig:LeftArm"}}, f)
        with self.assertRaises(names.BoneMapError):
            names.load_bone_map(path, [b.name for b in imported.armature.data.bones],
                                [b.name for b in target.data.bones])


class RetargetRigify(unittest.TestCase):
    def check_reference_is_t_pose(self, target, reference, bone_names):
        for ours, (x, y, z) in LIMB_DIRECTIONS.items():
            want = C @ np.array([x, y, z], dtype=float)
            m = np.array(target.matrix_world.to_3x3()) @ np.array(reference[bone_names[ours]].to_3x3())
            got = m[:, 1] / np.linalg.norm(m[:, 1])  # a Blender bone points along its Y axis
            self.assertLess(np.degrees(np.arccos(np.clip(got @ want, -1, 1))), 2.0, ours)

    def test_metarig_with_automatic_t_pose(self):
        target = harness.rigify_metarig()
        # The metarig's arms rest well below horizontal, so REST would be wrong.
        upper = target.data.bones["upper_arm.L"]
        droop = np.degrees(np.arcsin(-(upper.tail_local - upper.head_local).normalized().z))
        self.assertGreater(droop, 20.0)
        imported = import_take()
        result = harness.submodule("retarget").retarget(bpy.context, imported.armature, target, reference="AUTO")
        self.assertEqual(result.bone_map, RIGIFY_META)
        self.check_reference_is_t_pose(target, result.reference, RIGIFY_META)
        frames = imported.frames
        follows(self, target, RIGIFY_META, lambda t: np.array(result.reference[t].to_3x3().normalized()),
                (0, frames // 3, frames - 1))

    def test_metarig_with_a_pose_the_animator_set(self):
        """Reference "CURRENT": the animator raised the arms by hand; that pose is the reference."""
        from mathutils import Matrix

        target = harness.rigify_metarig()
        for side, sign in (("L", 1), ("R", -1)):
            pb = target.pose.bones["upper_arm." + side]
            pb.rotation_mode = "XYZ"
            # Bone-local X of the metarig's upper arms points forward-ish: a turn about it lifts them.
            pb.matrix_basis = Matrix.Rotation(0.5 * sign, 4, "X") @ pb.matrix_basis
        bpy.context.view_layer.update()
        posed = {b.name: np.array(b.matrix.to_3x3().normalized()) for b in target.pose.bones}
        imported = import_take()
        result = harness.submodule("retarget").retarget(bpy.context, imported.armature, target,
                                                        reference="CURRENT")
        for name in ("upper_arm.L", "upper_arm.R", "forearm.L", "spine.003"):
            got = np.array(result.reference[name].to_3x3().normalized())
            self.assertLess(angle_deg(got, posed[name]), 1e-4, name)
        follows(self, target, RIGIFY_META, lambda t: posed[t], (0, imported.frames // 2))

    def test_generated_rig_bakes_fk_controls(self):
        target = harness.rigify_metarig()
        self.assertEqual(bpy.ops.pose.rigify_generate(), {"FINISHED"})
        rig = bpy.context.object
        self.assertNotEqual(rig, target)
        imported = import_take()
        end = 25  # a generated rig is evaluated by Blender level by level: keep the test short
        result = harness.submodule("retarget").retarget(bpy.context, imported.armature, rig,
                                                        reference="AUTO", frame_end=end)
        self.assertEqual(result.bone_map, RIGIFY_GENERATED)
        keyed = {fc.data_path.split('"')[1] for fc in harness.fcurves(rig)}
        self.assertFalse([b for b in keyed if b.startswith(("DEF-", "ORG-", "MCH-"))])
        self.assertTrue(set(RIGIFY_GENERATED.values()) <= keyed)
        # FK switches keyed to FK.
        switches = [fc for fc in harness.fcurves(rig) if fc.data_path.endswith('["IK_FK"]')]
        self.assertEqual(len(switches), 4)
        self.assertTrue(all(fc.keyframe_points[0].co[1] == 1.0 for fc in switches))
        harness.submodule("retarget").remove_armature(imported.armature)
        # The deforming bones, driven by constraints from the controls, follow the source.
        deform = {s: "DEF-" + t.replace("_fk", "") for s, t in RIGIFY_META.items()
                  if "DEF-" + t.replace("_fk", "") in rig.pose.bones}
        self.assertGreaterEqual(len(deform), 18)
        self.check_reference_is_t_pose(rig, result.reference, deform)
        follows(self, rig, deform, lambda t: np.array(result.reference[t].to_3x3().normalized()),
                (0, end // 2, end - 1))


if __name__ == "__main__":
    unittest.main()


class RetargetWithBoneMap(unittest.TestCase):
    def test_sou12_take_onto_mixamo_with_shipped_bone_map(self):
        """A take on paper 002's sou12 rig has no humanoid names: mappings/blender/sou12_bones.json
        maps it; the character's arms and legs follow, the hips carry the root motion."""
        global TAKE
        target = harness.mixamo_character()
        bpy.context.view_layer.objects.active = target
        repo = os.environ["IMUBAKE_REPO"]
        bone_map_path = os.path.join(repo, "mappings", "blender", "sou12_bones.json")
        result = bpy.ops.import_scene.imubake_take(filepath=harness.take("sou_wave"), reference="REST",
                                                   bone_map=bone_map_path)
        self.assertEqual(result, {"FINISHED"})
        self.assertEqual([a.name for a in harness.armatures()], ["Character"])
        sou = {"N0_0": "Hips", "N0_1": "Spine2", "N1_0": "RightArm", "N1_1": "RightForeArm",
               "N2_0": "LeftArm", "N2_1": "LeftForeArm", "N3_0": "RightUpLeg", "N3_1": "RightLeg",
               "N4_0": "LeftUpLeg", "N4_1": "LeftLeg", "N5_0": "Neck", "N5_1": "Head"}
        bone_map = {s: "mixamorig:" + t for s, t in sou.items()}
        rest = {b.name: np.array(b.matrix_local.to_3x3().normalized()) for b in target.data.bones}
        saved, TAKE = TAKE, "sou_wave"
        try:
            follows(self, target, bone_map, lambda t: rest[t], (0, 300, 599))
        finally:
            TAKE = saved
        keyed = {fc.data_path.split('"')[1] for fc in harness.fcurves(target) if fc.data_path.endswith("location")}
        self.assertEqual(keyed, {"mixamorig:Hips"})
