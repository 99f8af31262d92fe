"""Automatic bone matching (names.py, no bpy) on naming schemes written out by hand, names only
(no hierarchy: the flat lists a caller without an armature passes)."""

import unittest

import harness

MIXAMO = ["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2", "mixamorig:Neck",
          "mixamorig:Head", "mixamorig:LeftShoulder", "mixamorig:LeftArm", "mixamorig:LeftForeArm",
          "mixamorig:LeftHand", "mixamorig:LeftHandIndex1", "mixamorig:LeftUpLeg", "mixamorig:LeftLeg",
          "mixamorig:LeftFoot", "mixamorig:LeftToeBase"]
# Unreal's mannequin: `_l/_r` suffixes.
UE = ["root", "pelvis", "spine_01", "spine_02", "spine_03", "neck_01", "head", "clavicle_l", "upperarm_l",
      "lowerarm_l", "hand_l", "index_01_l", "thigh_l", "calf_l", "calf_twist_01_l", "foot_l", "ball_l",
      "upperarm_r", "ik_hand_root"]
# Unity/VRM humanoid names.
VRM = ["Hips", "Spine", "Chest", "UpperChest", "Neck", "Head", "LeftShoulder", "LeftUpperArm",
       "LeftLowerArm", "LeftHand", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes", "RightUpperArm"]
# `.L/.R` in mixed case, as in many hand-made rigs.
DOT_L = ["Pelvis", "Spine", "Neck", "Head", "Shoulder.L", "UpperArm.L", "Forearm.L", "Hand.L", "Thigh.L",
         "Shin.L", "Foot.L", "Toe.L", "Thigh.R"]


class AutomaticMap(unittest.TestCase):
    def setUp(self):
        self.names = harness.submodule("names")

    def test_schemes(self):
        m = self.names.auto_bone_map
        self.assertEqual(m(MIXAMO, UE), {
            "mixamorig:Hips": "pelvis", "mixamorig:Spine": "spine_01", "mixamorig:Spine1": "spine_02",
            "mixamorig:Spine2": "spine_03", "mixamorig:Neck": "neck_01", "mixamorig:Head": "head",
            "mixamorig:LeftShoulder": "clavicle_l", "mixamorig:LeftArm": "upperarm_l",
            "mixamorig:LeftForeArm": "lowerarm_l", "mixamorig:LeftHand": "hand_l",
            "mixamorig:LeftUpLeg": "thigh_l", "mixamorig:LeftLeg": "calf_l", "mixamorig:LeftFoot": "foot_l",
            "mixamorig:LeftToeBase": "ball_l"})
        self.assertEqual(m(MIXAMO, VRM), {
            "mixamorig:Hips": "Hips", "mixamorig:Spine": "Spine", "mixamorig:Spine1": "Chest",
            "mixamorig:Spine2": "UpperChest", "mixamorig:Neck": "Neck", "mixamorig:Head": "Head",
            "mixamorig:LeftShoulder": "LeftShoulder", "mixamorig:LeftArm": "LeftUpperArm",
            "mixamorig:LeftForeArm": "LeftLowerArm", "mixamorig:LeftHand": "LeftHand",
            "mixamorig:LeftUpLeg": "LeftUpperLeg", "mixamorig:LeftLeg": "LeftLowerLeg",
            "mixamorig:LeftFoot": "LeftFoot", "mixamorig:LeftToeBase": "LeftToes"})
        # A one-joint spine takes the source spine's top (chains pair by their place along them).
        self.assertEqual(m(MIXAMO, DOT_L), {
            "mixamorig:Hips": "Pelvis", "mixamorig:Spine2": "Spine", "mixamorig:Neck": "Neck",
            "mixamorig:Head": "Head", "mixamorig:LeftShoulder": "Shoulder.L", "mixamorig:LeftArm": "UpperArm.L",
            "mixamorig:LeftForeArm": "Forearm.L", "mixamorig:LeftHand": "Hand.L", "mixamorig:LeftUpLeg": "Thigh.L",
            "mixamorig:LeftLeg": "Shin.L", "mixamorig:LeftFoot": "Foot.L", "mixamorig:LeftToeBase": "Toe.L"})

    def test_no_false_matches(self):
        # Fingers, twist bones, IK helpers and end bones are not body parts.
        for name in ("index_01_l", "calf_twist_01_l", "ik_hand_root", "mixamorig:HeadTop_End",
                     "mixamorig:LeftHandIndex1", "DEF-upper_arm.L", "MCH-forearm_ik.L", "root"):
            self.assertIsNone(self.names.canonical(name), name)


if __name__ == "__main__":
    unittest.main()
