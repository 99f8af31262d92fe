#!/usr/bin/env python3
"""The floor of sharing a spine's bend evenly, computed independently of imubake (numpy, scipy):
a BVH's own motion with the joints between two sensed ones replaced by an even bend of the true
rotation between them (no sensor error, no calibration), and how far the head and the wrists then
are from the source's, relative to the hips.

usage: even_bend_floor.py FILE.bvh ANCESTOR:DESCENDANT[,ANCESTOR:DESCENDANT...] SENSED[,SENSED...]
  chains: unsensed joints strictly between each pair share its bend (by the segments' rest
  lengths, each taking the tangent's turn at its segment's middle: imubake's documented rule), or
  keep their rest rotation; SENSED joints keep their true world rotation.
prints JSON {"rest": h, "even": h}: the RMS over frames and over Head, LeftHand, RightHand of the
position error relative to the hips, in standing heights of the rest pose.
"""
import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation as R

from bvh_positions import compose, local_rotations, parse, translations


def main():
    path, pairs, sensed = sys.argv[1], sys.argv[2].split(","), sys.argv[3].split(",")
    joints, values, _ = parse(path)
    names = [j["name"] for j in joints]
    idx = {n: i for i, n in enumerate(names) if n}
    n = len(values)
    local = local_rotations(joints, values)
    offsets = translations(joints, values, channels=False)

    def fk(loc):
        return compose(joints, loc, offsets)

    world, pos = fk(local)

    def chain(a, d):
        out, k = [], joints[d]["parent"]
        while k != a:
            out.append(k)
            k = joints[k]["parent"]
        return out[::-1]

    rest_pos = [np.zeros(3)]
    for j in joints[1:]:
        rest_pos.append(rest_pos[j["parent"]] + j["offset"])
    ys = [p[1] for p in rest_pos]
    height = max(ys) - min(ys)

    def error(mode):
        loc = list(local)
        for pair in pairs:
            a, d = (idx[x] for x in pair.split(":"))
            between = chain(a, d)
            if mode == "rest":
                for u in between:
                    loc[u] = R.identity(n)
                continue
            lengths = [np.linalg.norm(joints[j]["offset"]) for j in between[1:] + [d]]
            total, before, previous = sum(lengths), 0.0, 0.0
            bend = (world[a].inv() * world[d]).as_rotvec()
            for i, u in enumerate(between):
                middle = (before + lengths[i] / 2) / total
                before += lengths[i]
                loc[u] = R.from_rotvec(bend * (middle - previous))
                previous = middle
        # Sensed joints keep their true world rotation.
        w = []
        for i, j in enumerate(joints):
            p = j["parent"]
            if names[i] in sensed and p is not None:
                loc[i] = w[p].inv() * world[i]
            w.append(loc[i] if p is None else w[p] * loc[i])
        _, moved = fk(loc)
        hips = idx["Hips"]
        e = [np.linalg.norm((pos[idx[k]] - pos[hips]) - (moved[idx[k]] - moved[hips]), axis=1)
             for k in ("Head", "LeftHand", "RightHand")]
        return float(np.sqrt(np.mean(np.concatenate(e) ** 2)) / height)

    print(json.dumps({"rest": error("rest"), "even": error("even")}))


if __name__ == "__main__":
    main()
