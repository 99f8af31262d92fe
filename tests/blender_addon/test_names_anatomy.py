"""names.py's anatomy (no bpy): the hierarchy decides `Shoulder` and a sided `Hip`, rest positions
decide limbs without names, chains pair by their place along them, Rigify's metarig is declared
and a generated rig's FK controls are taken by name. Every BVH and built-in rig is also checked
against `imubake inspect --json` by tests/outputs/addon_anatomy.rs; these cases are written out by hand."""

import unittest

import harness


def chain(*names):
    """Names and parents of a simple chain (each joint the previous one's child)."""
    return list(names), [None] + list(range(len(names) - 1))


class Classify(unittest.TestCase):
    def setUp(self):
        self.names = harness.submodule("names")

    def test_words_and_sides(self):
        c = self.names.classify
        for name, want in (("mixamorig:LeftArm", ("left", "upper_arm")), ("RightLowerLeg", ("right", "shank")),
                           ("UpperLeg_L", ("left", "thigh")), ("upper_arm.L", ("left", "upper_arm")),
                           ("calf_r", ("right", "shank")), ("LHipJoint", ("left", "hip")),
                           ("lShldr", ("left", "upper_arm")), ("rButtock", ("right", "hip")),
                           ("Left-Knee", ("left", "shank")), ("l_up_arm", ("left", "upper_arm")),
                           ("LeftShoulder", ("left", "shoulder")), ("RightUpLeg_chr00", ("right", "thigh")),
                           ("T12", (None, "spine")), ("torso_7", (None, "spine")), ("neck_01", (None, "neck")),
                           ("Hip", (None, "pelvis")), ("root", (None, "root"))):
            self.assertEqual(c(name), want, name)
        for name in ("LeftHandIndex1", "LeftForeArmTwist", "LeftEye", "Spinal", "L0", "T13", "DEF-upper_arm.L",
                     "HeadTop_End", "RThumb"):
            self.assertIsNone(c(name), name)


class Resolve(unittest.TestCase):
    def setUp(self):
        self.names = harness.submodule("names")

    def parts(self, a):
        return {p: [a.names[j] for j in a.joints(p)] for p in self.names.PARTS if a.joints(p)}

    def test_shoulder_is_the_clavicle_above_an_upper_arm_else_the_upper_arm(self):
        # Mixamo: LeftShoulder -> LeftArm; MVN's BVH: LeftCollar -> LeftShoulder -> LeftElbow.
        names = ["Hips", "Spine", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"]
        a = self.names.resolve(names, [None, 0, 1, 2, 3, 4])
        self.assertEqual(self.parts(a)["left_clavicle"], ["LeftShoulder"])
        self.assertEqual(self.parts(a)["left_upper_arm"], ["LeftArm"])
        names = ["Hips", "Chest", "LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist"]
        a = self.names.resolve(names, [None, 0, 1, 2, 3, 4])
        self.assertEqual(self.parts(a)["left_clavicle"], ["LeftCollar"])
        self.assertEqual(self.parts(a)["left_upper_arm"], ["LeftShoulder"])
        self.assertEqual(self.parts(a)["left_forearm"], ["LeftElbow"])

    def test_a_sided_hip_is_a_hip_joint_above_a_thigh_else_the_thigh(self):
        names = ["Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "RHipJoint", "RightUpLeg", "RightLeg"]
        a = self.names.resolve(names, [None, 0, 1, 2, 0, 4, 5])
        p = self.parts(a)
        self.assertEqual((p["left_thigh"], p["right_thigh"], p["pelvis"]), (["LeftUpLeg"], ["RightUpLeg"], ["Hips"]))
        names = ["Hips", "LeftHip", "LeftKnee", "LeftAnkle", "RightHip", "RightKnee", "RightAnkle"]
        a = self.names.resolve(names, [None, 0, 1, 2, 0, 4, 5])
        p = self.parts(a)
        self.assertEqual((p["left_thigh"], p["left_shank"], p["left_foot"]), (["LeftHip"], ["LeftKnee"], ["LeftAnkle"]))
        # Where the thighs meet, and named `Hips`: named.
        self.assertEqual(a.found("pelvis"), "named")

    def test_chains_and_the_one_joint_between(self):
        names = ["root", "torso_1", "torso_2", "torso_3", "neck_1", "neck_2", "head", "l_shoulder", "l_up_arm",
                 "l_elbow_helper", "l_hand", "r_shoulder", "r_up_arm", "r_low_arm", "r_hand"]
        parents = [None, 0, 1, 2, 3, 4, 5, 3, 7, 8, 9, 3, 11, 12, 13]
        a = self.names.resolve(names, parents)
        p = self.parts(a)
        self.assertEqual(p["spine"], ["torso_1", "torso_2", "torso_3"])
        self.assertEqual(p["neck"], ["neck_1", "neck_2"])
        self.assertEqual(p["left_forearm"], ["l_elbow_helper"])
        self.assertEqual(a.found("left_forearm"), "shape")
        self.assertEqual(a.found("neck"), "named")
        self.assertEqual([s for s, _ in a.unity_bones()][:6], ["Hips", "Spine", "Chest", "UpperChest", "Neck", "Head"])

    def test_shape_alone(self):
        # A T-pose without names: legs end lowest, arms furthest out (+X is the body's left).
        names = ["j%d" % i for i in range(12)]
        parents = [None, 0, 1, 2, 1, 4, 0, 6, 7, 0, 9, 10]
        offsets = [(0, 1, 0), (0, 0.4, 0), (0.2, 0.1, 0), (0.3, 0, 0), (-0.2, 0.1, 0), (-0.3, 0, 0),
                   (0.1, -0.1, 0), (0, -0.4, 0), (0, -0.4, 0), (-0.1, -0.1, 0), (0, -0.4, 0), (0, -0.4, 0)]
        rest = []
        for j, p in enumerate(parents):
            o = offsets[j]
            rest.append(o if p is None else tuple(a + b for a, b in zip(rest[p], o)))
        ends = [None] * 12
        for j in (3, 5):
            ends[j] = (0.25 if j == 3 else -0.25, 0, 0)
        for j in (8, 11):
            ends[j] = (0, 0, 0.15)
        a = self.names.resolve(names, parents, rest, ends)
        p = self.parts(a)
        self.assertEqual(p["left_thigh"], ["j6"])
        self.assertEqual(p["left_shank"], ["j7"])
        self.assertEqual(p["right_foot"], ["j11"])
        self.assertEqual(p["left_upper_arm"], ["j2"])
        self.assertEqual(p["right_forearm"], ["j5"])
        self.assertEqual((p["pelvis"], p["spine"]), (["j0"], ["j1"]))
        self.assertEqual(a.found("left_thigh"), "shape")
        # Without rest positions the names say nothing.
        self.assertEqual(self.parts(self.names.resolve(names, parents)), {"pelvis": ["j0"]})

    def test_pairs_by_place_along_chains(self):
        n = self.names
        mk = lambda k: n.resolve(*chain("Hips", *["torso_%d" % (i + 1) for i in range(k)]))
        seven, three = mk(7), mk(3)
        self.assertEqual(n.pairs(seven, three), [(0, 0), (1, 1), (4, 2), (7, 3)])
        self.assertEqual(n.pairs(three, seven), [(0, 0), (1, 1), (1, 2), (2, 3), (2, 4), (2, 5), (3, 6), (3, 7)])


class Armatures(unittest.TestCase):
    """What the add-on's callers use: skeletons, Rigify, bone maps."""

    def setUp(self):
        self.names = harness.submodule("names")

    def test_metarig_spine_is_declared(self):
        n = self.names
        bones = ["spine", "spine.001", "spine.002", "spine.003", "spine.004", "spine.005", "spine.006", "face",
                 "shoulder.L", "upper_arm.L", "forearm.L", "hand.L", "pelvis.L", "thigh.L", "shin.L", "foot.L",
                 "toe.L", "heel.02.L"]
        parents = [None, "spine", "spine.001", "spine.002", "spine.003", "spine.004", "spine.005", "spine.006",
                   "spine.003", "shoulder.L", "upper_arm.L", "forearm.L", "spine", "spine", "thigh.L", "shin.L",
                   "foot.L", "shin.L"]
        parts = n.match_armature(n.Skeleton(bones, parents))
        self.assertEqual({k: parts[k] for k in ("Hips", "Spine", "Spine1", "Spine2", "Neck", "Head")},
                         {"Hips": "spine", "Spine": "spine.001", "Spine1": "spine.002", "Spine2": "spine.003",
                          "Neck": "spine.004", "Head": "spine.006"})
        self.assertEqual(parts["LeftShoulder"], "shoulder.L")
        self.assertEqual(parts["LeftToeBase"], "toe.L")
        # A Mixamo take onto it: the neck's one source joint drives the chain's first bone.
        mixamo = ["Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "LeftShoulder", "LeftArm"]
        m = n.auto_bone_map(n.Skeleton(mixamo, [None, 0, 1, 2, 3, 4, 3, 6]), n.Skeleton(bones, parents))
        self.assertEqual(m["Neck"], "spine.004")
        self.assertEqual(m["Head"], "spine.006")
        self.assertEqual(m["LeftShoulder"], "shoulder.L")

    def test_generated_rig_takes_fk_controls(self):
        n = self.names
        bones = ["root", "torso", "spine_fk", "spine_fk.001", "spine_fk.002", "spine_fk.003", "neck", "head",
                 "shoulder.L", "upper_arm_fk.L", "upper_arm_ik.L", "forearm_fk.L", "hand_fk.L", "hand_ik.L",
                 "thigh_fk.L", "thigh_parent.L", "shin_fk.L", "foot_fk.L", "toe_fk.L", "MCH-upper_arm_fk.L",
                 "DEF-upper_arm.L", "ORG-thigh.L"]
        parts = n.match_armature(bones)
        self.assertEqual(parts, {"Hips": "torso", "Spine": "spine_fk.001", "Spine1": "spine_fk.002",
                                 "Spine2": "spine_fk.003", "Neck": "neck", "Head": "head",
                                 "LeftShoulder": "shoulder.L", "LeftArm": "upper_arm_fk.L",
                                 "LeftForeArm": "forearm_fk.L", "LeftHand": "hand_fk.L", "LeftUpLeg": "thigh_fk.L",
                                 "LeftLeg": "shin_fk.L", "LeftFoot": "foot_fk.L", "LeftToeBase": "toe_fk.L"})

    def test_canonical_single_names(self):
        c = self.names.canonical
        for unity, want in (("Hips", "Hips"), ("Spine", "Spine"), ("Chest", "Spine1"), ("UpperChest", "Spine2"),
                            ("LeftShoulder", "LeftShoulder"), ("LeftUpperArm", "LeftArm"),
                            ("RightLowerLeg", "RightLeg"), ("LeftToes", "LeftToeBase"), ("Neck", "Neck")):
            self.assertEqual(c(unity), want, unity)


class InBlender(unittest.TestCase):
    """An armature as the add-on reads it (`retarget.skeleton`: hierarchy, rest heads turned from
    Blender's Z up to the rig world's Y up) resolves as `imubake inspect` resolves its BVH."""

    def test_mixamo_character_resolves_as_imubake_inspect(self):
        import json
        import os
        import subprocess

        arm = harness.mixamo_character()
        names, retarget = self.names_module(), harness.submodule("retarget")
        path = harness.shared("bvh/mixamo_rig_freebvh.bvh")
        out = subprocess.run([os.environ["IMUBAKE_BIN"], "inspect", path, "--json"], capture_output=True,
                             check=True)
        want = {p: v["joints"] for p, v in json.loads(out.stdout)["parts"].items()}
        got = names.anatomy(retarget.skeleton(arm)).to_json()["parts"]
        self.assertEqual({p: v["joints"] for p, v in got.items()}, want)
        # Every name stripped: the shape alone (left at +X, legs lowest) finds the same joints.
        original = [b.name for b in arm.data.bones]
        for i, b in enumerate(arm.data.bones):
            b.name = "j%d" % i
        stripped = names.anatomy(retarget.skeleton(arm)).to_json()["parts"]
        back = {"j%d" % i: n for i, n in enumerate(original)}
        for part in ("left_thigh", "left_shank", "left_foot", "right_thigh", "right_upper_arm", "left_forearm",
                     "pelvis", "spine"):
            self.assertEqual([back[j] for j in stripped[part]["joints"]], want[part], part)
            self.assertEqual(stripped[part]["found"], "shape", part)

    def names_module(self):
        return harness.submodule("names")


if __name__ == "__main__":
    unittest.main()
