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
from scipy.spatial.transform import Slerp

from bvh_positions import local_rotations, parse


def world_rotations(joints, values, frames):
    """Each joint's world rotation (a Rotation stack) at the fractional `frames`: local rotations
    interpolated between frames (Slerp), composed down the hierarchy."""
    local = local_rotations(joints, values)
    keys = np.arange(len(values))
    at = np.clip(np.asarray(frames, dtype=float), 0, len(values) - 1)
    local_at = [Slerp(keys, r)(at) if len(values) > 1 else r[np.zeros(len(at), dtype=int)] for r in local]
    world = []
    for k, j in enumerate(joints):
        world.append(local_at[k] if j["parent"] is None else world[j["parent"]] * local_at[k])
    return world


def main():
    path, names, frames = sys.argv[1], sys.argv[2].split(","), [float(f) for f in sys.argv[3].split(",")]
    joints, values, _ = parse(path)
    world = world_rotations(joints, values, frames)
    out = {}
    for name in names:
        k = next(i for i, j in enumerate(joints) if j["name"] == name)
        q = world[k].as_quat()  # x, y, z, w
        out[name] = [[float(v[3]), float(v[0]), float(v[1]), float(v[2])] for v in q]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
