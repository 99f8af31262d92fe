#!/usr/bin/env python3
"""Joint positions of a BVH at every frame, computed independently of imubake with numpy and
scipy: a minimal BVH parser (offsets, End Sites, channels), each joint's rotation channels composed
as intrinsic Euler angles in channel order, positions down the hierarchy
(p_child = p_parent + R_parent · offset), a position channel replacing its OFFSET component (the root's channels are its world position).

usage: bvh_positions.py FILE.bvh JOINT[,JOINT...] [FOOT,FOOT... [FIRST:LAST]]
prints JSON {"joints": {joint: [[x, y, z] per frame]}, "lowest": [y per frame] (the lowest joint
or End Site), "rest_lowest": y, "rest_highest": y (the rest pose, root at its OFFSET),
"frame_time": s; with FOOT names "contacts": {foot: [bool per frame]} and "airborne": [bool per
frame], no point of any foot near its lowest height (see `contacts`), judged on frames FIRST to
LAST (inclusive; all by default) alone — the motion a simulation played, without a reference pose
before or after it, which would otherwise stand in the ±0.5 s window — and false outside them}
"""
import json
import sys

import numpy as np
from scipy.ndimage import minimum_filter1d
from scipy.spatial.transform import Rotation


def parse(path):
    tokens = open(path).read().split()
    joints, stack, i = [], [], 0
    while tokens[i] != "MOTION":
        t = tokens[i]
        if t in ("ROOT", "JOINT", "End"):
            name = tokens[i + 1] if t != "End" else None
            joints.append({"name": name, "parent": stack[-1] if stack else None, "channels": [], "offset": np.zeros(3)})
            i += 2
        elif t == "{":
            stack.append(len(joints) - 1)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "OFFSET":
            joints[-1]["offset"] = np.array([float(v) for v in tokens[i + 1:i + 4]])
            i += 4
        elif t == "CHANNELS":
            n = int(tokens[i + 1])
            joints[-1]["channels"] = tokens[i + 2:i + 2 + n]
            i += 2 + n
        else:
            i += 1
    frames = int(tokens[i + 2])
    frame_time = float(tokens[i + 5])
    values = np.array([float(v) for v in tokens[i + 6:]]).reshape(frames, -1)
    return joints, values, frame_time


def local_rotations(joints, values):
    """Each joint's local rotation per frame (a Rotation stack): its rotation channels composed as
    intrinsic Euler angles in channel order."""
    n = len(values)
    out, start = [], 0
    for j in joints:
        ch = j["channels"]
        rot = [c for c in ch if c.endswith("rotation")]
        if rot:
            idx = [start + ch.index(c) for c in rot]
            out.append(Rotation.from_euler("".join(c[0] for c in rot), values[:, idx], degrees=True))
        else:
            out.append(Rotation.identity(n))
        start += len(ch)
    return out


def translations(joints, values, channels=True):
    """Each joint's translation from its parent per frame ((n, 3)): its OFFSET, a position channel
    replacing its component (the root's channels are its world position); `channels=False` keeps
    the OFFSETs (the rest pose)."""
    n = len(values)
    out, start = [], 0
    for j in joints:
        ch = j["channels"]
        t = np.tile(j["offset"], (n, 1))
        for axis, name in enumerate(("Xposition", "Yposition", "Zposition")):
            if channels and name in ch:
                t[:, axis] = values[:, start + ch.index(name)]
        out.append(t)
        start += len(ch)
    return out


def compose(joints, local, translation):
    """World rotations and positions down the hierarchy: R = R_parent · R_local,
    p = p_parent + R_parent · translation."""
    world, pos = [], []
    for i, j in enumerate(joints):
        p = j["parent"]
        if p is None:
            world.append(local[i])
            pos.append(translation[i])
        else:
            world.append(world[p] * local[i])
            pos.append(pos[p] + world[p].apply(translation[i]))
    return world, pos


def forward(joints, values, channels=True):
    """World rotations (Rotation stacks) and positions ((n, 3)) of every joint and End Site."""
    return compose(joints, local_rotations(joints, values), translations(joints, values, channels))


def positions(joints, values, channels=True):
    """Positions per frame. A position channel replaces its OFFSET component (Blender's reading,
    and conventions.md's rule for the root); `channels=False` keeps the OFFSETs (the rest pose)."""
    return forward(joints, values, channels)[1]


def subtree(joints, k):
    """Indices of joint k and every joint and End Site below it."""
    out = [k]
    for i, j in enumerate(joints):
        if j["parent"] in out:
            out.append(i)
    return out


def contacts(joints, pos, k, height, frame_time):
    """Issue 49's rule for a foot in contact, per frame: one of its points (the foot joint, its
    toes, their End Sites) within 0.02 h of the lowest height that point reaches within ±0.5 s and
    moving horizontally slower than 0.12 h/s (central differences). Also whether one of them is
    that low at all, whatever its speed (a foot on the ground, even rolling or pushing off)."""
    half = max(1, int(round(0.5 / frame_time)))
    touching = np.zeros(len(pos[k]), dtype=bool)
    low_enough = np.zeros(len(pos[k]), dtype=bool)
    for i in subtree(joints, k):
        p = pos[i]
        low = minimum_filter1d(p[:, 1], size=2 * half + 1, mode="nearest")
        speed = np.linalg.norm(np.gradient(p[:, [0, 2]], frame_time, axis=0), axis=1)
        near = p[:, 1] <= low + 0.02 * height
        touching |= near & (speed < 0.12 * height)
        low_enough |= near
    return touching, low_enough


def main():
    path, names = sys.argv[1], sys.argv[2].split(",")
    feet = sys.argv[3].split(",") if len(sys.argv) > 3 else []
    joints, values, frame_time = parse(path)
    first, last = 0, len(values) - 1
    if len(sys.argv) > 4:
        first, last = (int(v) for v in sys.argv[4].split(":"))
    pos = positions(joints, values)
    rest = positions(joints, np.zeros((1, values.shape[1])), channels=False)
    out = {
        "joints": {},
        "lowest": np.min(np.stack([p[:, 1] for p in pos]), axis=0).tolist(),
        "rest_lowest": float(min(p[0, 1] for p in rest)),
        "rest_highest": float(max(p[0, 1] for p in rest)),
        "frame_time": frame_time,
    }
    for name in names:
        k = next(i for i, j in enumerate(joints) if j["name"] == name)
        out["joints"][name] = pos[k].tolist()
    height = out["rest_highest"] - out["rest_lowest"]
    out["contacts"] = {}
    played = [p[first:last + 1] for p in pos]
    grounded = np.zeros(len(values), dtype=bool)
    airborne = np.zeros(len(values), dtype=bool)
    for name in feet:
        k = next(i for i, j in enumerate(joints) if j["name"] == name)
        touching, low_enough = contacts(joints, played, k, height, frame_time)
        whole = np.zeros(len(values), dtype=bool)
        whole[first:last + 1] = touching
        out["contacts"][name] = whole.tolist()
        grounded[first:last + 1] |= low_enough
    airborne[first:last + 1] = ~grounded[first:last + 1]
    if feet:
        out["airborne"] = airborne.tolist()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
