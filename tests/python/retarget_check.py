#!/usr/bin/env python3
"""How closely a retargeted BVH follows its source, by the independent numpy BVH reader
(tests/blender_addon/bvh_reference.py): for each (source joint, target bone) pair, the angle
between the target bone's world rotation (its rest is the identity) and the source joint's world
rotation since the reference pose, D = S(t) · S(ref)ᵀ; and the hips' position against the source
root's scaled by the hip heights and stood on the target's floor, k · (p_s(t) − (0, floor_s, 0)) +
(0, floor, 0): both hip heights read in a standing frame (the reference frame, else the first),
each skeleton in its own pose there (the root's height above the lowest joint or end site), the
source's floor that frame's lowest point, the target's its rest pose's; where the target's pose
would go under its floor, the root rises by the difference.

    python retarget_check.py SOURCE.bvh TARGET.bvh PAIRS.json STEP REF

PAIRS.json: [[source joint, target bone], ...]; target frame m is source frame STEP · m; REF is
`rest` or a source frame number. Prints JSON {"worst_deg", "per_pair": {...}, "worst_root_m",
"frames"}.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "blender_addon"))
from bvh_reference import Bvh, angle_deg  # noqa: E402


def rest_heights(bvh):
    """Rest positions (every channel zero) and the lowest rest point, end sites included."""
    pos = []
    lowest = np.inf
    for j in bvh.joints:
        p = j["offset"] if j["parent"] is None else pos[j["parent"]] + j["offset"]
        pos.append(p)
        lowest = min(lowest, p[1])
    return pos, lowest


def standing(bvh, frame):
    """A standing frame's lowest point (joints and end sites) and the root's height above it."""
    w = bvh.world(frame)
    ys = [p[1] for _, p in w.values()]
    for j in bvh.joints:
        if j["name"] is None:
            r, p = w[bvh.joints[j["parent"]]["name"]]
            ys.append((p + r @ j["offset"])[1])
    low = min(ys)
    return low, w[bvh.names[0]][1][1] - low


def main():
    src, tgt = Bvh(sys.argv[1]), Bvh(sys.argv[2])
    pairs = json.load(open(sys.argv[3]))
    step, ref = int(sys.argv[4]), sys.argv[5]
    ref_world = None if ref == "rest" else src.world(int(ref))
    standing_frame = 0 if ref == "rest" else int(ref)
    assert standing_frame % step == 0, "the standing frame must be a target frame"
    floor_src, h_src = standing(src, standing_frame)
    # The target's hip height in the pose it takes in the standing frame (its rotations alone).
    _, h_tgt = standing(tgt, standing_frame // step)
    tgt_rest, tgt_low = rest_heights(tgt)
    k = h_tgt / h_src
    floor = tgt_low
    root_src, root_tgt = src.names[0], tgt.names[0]
    per_pair = {f"{s}->{t}": 0.0 for s, t in pairs}
    worst_root = 0.0
    frames = 0
    for m in range(tgt.frames):
        n = step * m
        if n >= src.frames:
            break
        frames += 1
        sw, tw = src.world(n), tgt.world(m)
        for s, t in pairs:
            d = sw[s][0] if ref_world is None else sw[s][0] @ ref_world[s][0].T
            key = f"{s}->{t}"
            per_pair[key] = max(per_pair[key], angle_deg(tw[t][0], d))
        expected = k * (sw[root_src][1] - np.array([0.0, floor_src, 0.0])) + np.array([0.0, floor, 0.0])
        # Never below the floor: the root rises by what of the target's pose would go under.
        _, hip_above_lowest = standing(tgt, m)
        expected[1] = max(expected[1], floor + hip_above_lowest)
        worst_root = max(worst_root, float(np.linalg.norm(tw[root_tgt][1] - expected)))
    json.dump({"worst_deg": max(per_pair.values()), "per_pair": per_pair,
               "worst_root_m": worst_root, "frames": frames, "k": k}, sys.stdout)


if __name__ == "__main__":
    main()
