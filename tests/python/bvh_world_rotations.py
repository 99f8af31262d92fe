#!/usr/bin/env python3
"""World rotations of BVH joints at fractional frames, computed independently of imubake with
scipy: a minimal BVH parser, each joint's rotation channels composed as intrinsic Euler angles in
channel order (scipy's upper-case orders are intrinsic: BVH `Zrotation Xrotation Yrotation` is
`from_euler("ZXY", [z, x, y])`), local rotations interpolated between frames with scipy's Slerp,
and world rotations composed down the hierarchy.

usage: bvh_world_rotations.py FILE.bvh JOINT[,JOINT...] FRAME[,FRAME...]
prints JSON {joint: [[w, x, y, z] per frame]}
"""
import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def parse(path):
    tokens = open(path).read().split()
    joints, stack, i = [], [], 0
    while tokens[i] != "MOTION":
        t = tokens[i]
        if t in ("ROOT", "JOINT"):
            joints.append({"name": tokens[i + 1], "parent": stack[-1] if stack else None, "channels": []})
            i += 2
        elif t == "End":
            joints.append({"name": None, "parent": stack[-1], "channels": []})
            i += 2
        elif t == "{":
            stack.append(len(joints) - 1)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "CHANNELS":
            n = int(tokens[i + 1])
            joints[-1]["channels"] = tokens[i + 2:i + 2 + n]
            i += 2 + n
        else:
            i += 1
    frames = int(tokens[i + 2])
    values = np.array([float(v) for v in tokens[i + 6:]]).reshape(frames, -1)
    return joints, values


def main():
    path, names, frames = sys.argv[1], sys.argv[2].split(","), [float(f) for f in sys.argv[3].split(",")]
    joints, values = parse(path)
    start, local = 0, []
    for j in joints:
        rot = [c for c in j["channels"] if c.endswith("rotation")]
        idx = [start + j["channels"].index(c) for c in rot]
        start += len(j["channels"])
        if rot:
            order = "".join(c[0] for c in rot)
            local.append(Rotation.from_euler(order, values[:, idx], degrees=True))
        else:
            local.append(Rotation.identity(len(values)))
    keys = np.arange(len(values))
    at = np.clip(np.array(frames), 0, len(values) - 1)
    local_at = [Slerp(keys, r)(at) for r in local]
    world = []
    for k, j in enumerate(joints):
        world.append(local_at[k] if j["parent"] is None else world[j["parent"]] * local_at[k])
    out = {}
    for name in names:
        k = next(i for i, j in enumerate(joints) if j["name"] == name)
        q = world[k].as_quat()  # x, y, z, w
        out[name] = [[float(v[3]), float(v[0]), float(v[1]), float(v[2])] for v in q]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
