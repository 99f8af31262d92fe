"""An independent BVH reader (numpy only, no Blender, no imubake): joints' world rotation matrices
and positions at a frame, in the BVH's own Y-up frame.

Channels compose as intrinsic rotations in the order listed (`Zrotation Yrotation Xrotation` is
R = Rz·Ry·Rx); position channels replace the root OFFSET; a joint's world transform is its
parent's times (offset, local rotation).
"""

import numpy as np


def _axis(axis, deg):
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "Y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


class Bvh:
    def __init__(self, path):
        tokens = open(path).read().split()
        self.joints = []  # dicts: name, parent index, offset, channels
        stack, i = [], 0
        while tokens[i] != "MOTION":
            t = tokens[i]
            if t in ("ROOT", "JOINT"):
                self.joints.append({"name": tokens[i + 1], "parent": stack[-1] if stack else None,
                                    "offset": None, "channels": []})
                i += 2
            elif t == "End":
                self.joints.append({"name": None, "parent": stack[-1], "offset": None, "channels": []})
                i += 2
            elif t == "{":
                stack.append(len(self.joints) - 1)
                i += 1
            elif t == "}":
                stack.pop()
                i += 1
            elif t == "OFFSET":
                self.joints[-1]["offset"] = np.array([float(x) for x in tokens[i + 1:i + 4]])
                i += 4
            elif t == "CHANNELS":
                n = int(tokens[i + 1])
                self.joints[-1]["channels"] = tokens[i + 2:i + 2 + n]
                i += 2 + n
            else:
                i += 1
        self.frames = int(tokens[i + 2])
        self.frame_time = float(tokens[i + 5])
        width = sum(len(j["channels"]) for j in self.joints)
        values = np.array([float(x) for x in tokens[i + 6:i + 6 + width * self.frames]])
        self.motion = values.reshape(self.frames, width)
        self.names = [j["name"] for j in self.joints]

    def world(self, frame):
        """{joint name: (3x3 world rotation, world position)} at a 0-based frame."""
        row = self.motion[frame]
        col = 0
        out, rots, poss = {}, [], []
        for j in self.joints:
            rot = np.eye(3)
            pos = j["offset"].copy()
            for ch in j["channels"]:
                v = row[col]
                col += 1
                if ch.endswith("rotation"):
                    rot = rot @ _axis(ch[0], v)
                else:
                    pos["XYZ".index(ch[0])] = v
            if j["parent"] is None:
                wr, wp = rot, pos
            else:
                pr, pp = rots[j["parent"]], poss[j["parent"]]
                # Position channels replace the OFFSET (`--in-place` hips), as Blender reads them.
                wr, wp = pr @ rot, pp + pr @ pos
            rots.append(wr)
            poss.append(wp)
            if j["name"] is not None:
                out[j["name"]] = (wr, wp)
        return out


# Blender's BVH and glTF importers turn the Y-up rig world into Blender's Z-up one:
# a point (x, y, z) becomes (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])


def angle_deg(a, b):
    """The angle of the rotation taking rotation matrix b to a, in degrees."""
    r = a @ b.T
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))))
