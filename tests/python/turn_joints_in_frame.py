#!/usr/bin/env python3
"""A BVH with some segments turned about their own long axes in one frame — a subject holding a
pose other than the one a mapping declares (legs turned out at the hips, say). Independent of
imubake: numpy and scipy, with bvh_positions.py's parser and forward kinematics.

usage: turn_joints_in_frame.py IN.bvh OUT.bvh FRAME JOINT=DEG[,JOINT=DEG...]

Each named joint's world rotation in FRAME is turned by DEG about its segment's axis, up from its
first child to the joint (anticlockwise seen from the joint's end: for a hanging leg, from above),
its descendants carried along: its local rotation becomes R_parent⁻¹ · R_u(DEG) · R_parent · R_local,
written back as the joint's own Euler channels (intrinsic, in channel order). Every other value is
written as read.
"""
import sys

import numpy as np
from scipy.spatial.transform import Rotation

from bvh_positions import forward, local_rotations, parse


def main():
    src, dst, frame = sys.argv[1], sys.argv[2], int(sys.argv[3])
    turns = {k: float(v) for k, v in (p.split("=") for p in sys.argv[4].split(","))}
    joints, values, frame_time = parse(src)
    world, pos = forward(joints, values[frame:frame + 1])
    local = local_rotations(joints, values[frame:frame + 1])
    starts = np.cumsum([0] + [len(j["channels"]) for j in joints])
    missing = set(turns) - {j["name"] for j in joints}
    if missing:
        sys.exit(f"no joint named {sorted(missing)}")
    out = values.copy()
    for k, j in enumerate(joints):
        if j["name"] not in turns:
            continue
        parent = world[j["parent"]] if j["parent"] is not None else Rotation.identity(1)
        child = next(c for c, cj in enumerate(joints) if cj["parent"] == k)
        up = pos[k][0] - pos[child][0]
        turn = Rotation.from_rotvec(np.radians(turns[j["name"]]) * up / np.linalg.norm(up))
        new = parent.inv() * turn * parent * local[k]
        rot = [c for c in j["channels"] if c.endswith("rotation")]
        idx = [starts[k] + j["channels"].index(c) for c in rot]
        out[frame, idx] = new.as_euler("".join(c[0] for c in rot), degrees=True)[0]
    text = open(src).read()
    head = text[:text.index("MOTION")]
    with open(dst, "w") as f:
        f.write(head)
        f.write(f"MOTION\nFrames: {len(out)}\nFrame Time: {frame_time:.8f}\n")
        for row in out:
            f.write(" ".join(f"{v:.6f}" for v in row) + "\n")


if __name__ == "__main__":
    main()
