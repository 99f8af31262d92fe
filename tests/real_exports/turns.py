"""Each body part's world turn in a source BVH and in its retargeted output, by an independent
forward kinematics (scipy's rotations; not imubake's code).

    python turns.py SOURCE.bvh OUTPUT.bvh SOURCE_PARTS.json TARGET_PARTS.json STEP

STEP: source frames per output frame (the output's rate divides the source's). The parts files
are `imubake inspect --json`. Prints JSON {part: largest angle in degrees between the source
part's world rotation (since the rest pose) and the target part's, over the frames}; the spine
is compared at its top (the thorax), the neck at its top (a one-joint neck takes the source's top).
"""
import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation as R


def parse_bvh(path):
    text = open(path, encoding="utf-8", errors="replace").read().split()
    i = 0
    names, parents, channels = [], [], []
    stack = []
    while text[i] != "MOTION":
        tok = text[i]
        if tok in ("ROOT", "JOINT"):
            names.append(text[i + 1])
            parents.append(stack[-1] if stack else None)
            channels.append([])
            i += 2
        elif tok == "End":
            # Skip the End Site block.
            depth = 0
            while True:
                i += 1
                if text[i] == "{":
                    depth += 1
                elif text[i] == "}":
                    depth -= 1
                    if depth == 0:
                        break
            i += 1
        elif tok == "{":
            if names and (not stack or stack[-1] != len(names) - 1):
                stack.append(len(names) - 1)
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "CHANNELS":
            n = int(text[i + 1])
            channels[-1] = text[i + 2:i + 2 + n]
            i += 2 + n
        else:
            i += 1
    frames = int(text[i + 2])
    i += 6  # MOTION Frames: N Frame Time: T
    total = sum(len(c) for c in channels)
    values = np.array(text[i:i + frames * total], dtype=float).reshape(frames, total)
    return names, parents, channels, values


def world_rotations(bvh):
    names, parents, channels, values = bvh
    frames = values.shape[0]
    world = [None] * len(names)
    col = 0
    for j, chans in enumerate(channels):
        order = "".join(c[0] for c in chans if c.endswith("rotation"))
        idx = [col + k for k, c in enumerate(chans) if c.endswith("rotation")]
        col += len(chans)
        local = R.from_euler(order.upper(), values[:, idx], degrees=True) if order else R.identity(frames)
        world[j] = local if parents[j] is None else world[parents[j]] * local
    return dict(zip(names, world))


def main():
    src, out, sparts, tparts, step = sys.argv[1:6]
    step = int(step)
    sw = world_rotations(parse_bvh(src))
    tw = world_rotations(parse_bvh(out))
    sp = json.load(open(sparts))["parts"]
    tp = json.load(open(tparts))["parts"]
    result = {}
    for part, s in sp.items():
        t = tp.get(part, {"joints": []})["joints"]
        s = s["joints"]
        if not s or not t:
            continue
        sj, tj = s[-1], t[-1]
        a = sw[sj]
        b = tw[tj]
        n = min(len(b), (len(a) + step - 1) // step)
        a = a[np.arange(n) * step]
        b = b[np.arange(n)]
        err = (a * b.inv()).magnitude()
        result[part] = float(np.degrees(err.max()))
    print(json.dumps(result))


main()
