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
`rest`, a source frame number N (`frame:N`) or `match:N`. With `match:N` the target bone's rest
is first aimed as the source joint is in frame N, D = S(t) · S(N)ᵀ · M: M turns the unit
directions from the bone to its nearest paired descendants in the target's rest (else to its
children and End Site, their mean) onto the same of the source in frame N — the best rotation by
SVD (Kabsch) when they span a plane, else the shortest turn of their mean; a bone with none keeps its nearest
paired ancestor's M. Also, whatever REF, "worst_aim_deg" ("per_aim" by bone): over target bones
with exactly one nearest paired descendant whose source joint is its own source joint's child,
the largest angle at any frame between the target's direction to it and the source's to its
joint (0 when the bone is aimed as its source joint is).
Prints JSON {"worst_deg", "per_pair": {...}, "worst_root_m", "worst_aim_deg", "per_aim",
"frames", "k"}.
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


def positions(bvh, frame):
    """Every joint's and End Site's world position at a frame, by index."""
    w = bvh.world(frame)
    out = []
    for j in bvh.joints:
        if j["name"] is None:
            r, p = w[bvh.joints[j["parent"]]["name"]]
            out.append(p + r @ j["offset"])
        else:
            out.append(w[j["name"]][1])
    return out


def unit(v):
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else None


def shortest(t, u):
    """The shortest rotation matrix taking unit t to unit u."""
    axis = np.cross(t, u)
    s, c = np.linalg.norm(axis), float(np.dot(t, u))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        a = unit(np.cross(t, [1.0, 0, 0]))
        a = a if a is not None else unit(np.cross(t, [0, 1.0, 0]))
        return 2 * np.outer(a, a) - np.eye(3)
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def best_rotation(dirs):
    """Kabsch over (t, u) unit pairs when they span a plane, else the shortest turn of their
    mean directions (the first's, should they cancel)."""
    h = sum(np.outer(u, t) for t, u in dirs)
    u_, sv, vt = np.linalg.svd(h)
    if sv[1] <= 1e-3 * sv[0]:
        t = unit(sum(t for t, _ in dirs))
        u = unit(sum(u for _, u in dirs))
        return shortest(t if t is not None else dirs[0][0], u if u is not None else dirs[0][1])
    d = np.sign(np.linalg.det(u_ @ vt))
    return u_ @ np.diag([1.0, 1.0, d]) @ vt


def nearest_paired(bvh, paired):
    """Each joint's nearest paired descendants (joint indices), through unpaired joints."""
    kids = {i: [] for i in range(len(bvh.joints))}
    for i, j in enumerate(bvh.joints):
        if j["parent"] is not None and j["name"] is not None:
            kids[j["parent"]].append(i)

    def below(i):
        out = []
        for c in kids[i]:
            out += [c] if bvh.names[c] in paired else below(c)
        return out
    return {i: below(i) for i in range(len(bvh.joints)) if bvh.names[i] is not None}


def matched(src, tgt, pairs, n):
    """M of each target bone for `match:N` (by target bone name)."""
    sp, tp = positions(src, n), rest_heights(tgt)[0]
    s_of = {t: s for s, t in pairs}
    s_index = {name: i for i, name in enumerate(src.names) if name is not None}
    t_index = {name: i for i, name in enumerate(tgt.names) if name is not None}
    near = nearest_paired(tgt, set(s_of))
    aims = {}
    for s, t in pairs:
        si, ti = s_index[s], t_index[t]
        dirs = []
        for d in near[ti]:
            a, b = unit(tp[d] - tp[ti]), unit(sp[s_index[s_of[tgt.names[d]]]] - sp[si])
            if a is not None and b is not None:
                dirs.append((a, b))
        if not dirs:
            def mean(points, at):
                vs = [unit(p - at) for p in points]
                return unit(sum(v for v in vs if v is not None)) if vs else None
            tk = [tp[c] for c, j in enumerate(tgt.joints) if j["parent"] == ti]
            sk = [sp[c] for c, j in enumerate(src.joints) if j["parent"] == si]
            a, b = mean(tk, tp[ti]), mean(sk, sp[si])
            if a is not None and b is not None:
                dirs.append((a, b))
        if dirs:
            aims[t] = best_rotation(dirs)
    out = {}
    for i, j in enumerate(tgt.joints):
        if j["name"] is None:
            continue
        inherited = np.eye(3) if j["parent"] is None else out[tgt.names[j["parent"]]]
        out[j["name"]] = aims.get(j["name"], inherited)
    return out


def main():
    src, tgt = Bvh(sys.argv[1]), Bvh(sys.argv[2])
    pairs = json.load(open(sys.argv[3]))
    step, ref = int(sys.argv[4]), sys.argv[5]
    ref_frame = None if ref == "rest" else int(ref.split(":")[-1])
    ref_world = None if ref_frame is None else src.world(ref_frame)
    aim = matched(src, tgt, pairs, ref_frame) if ref.startswith("match:") else {}
    standing_frame = ref_frame or 0
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
    per_aim = {}
    s_of = {t: s for s, t in pairs}
    s_index = {name: i for i, name in enumerate(src.names) if name is not None}
    # Bones with one paired descendant whose source joint is the child of theirs (a source path
    # through unpaired joints bends with them, which one target bone cannot).
    one_aim = {i: b[0] for i, b in nearest_paired(tgt, set(s_of)).items()
               if tgt.names[i] in s_of and len(b) == 1
               and src.joints[s_index[s_of[tgt.names[b[0]]]]]["parent"]
               == s_index[s_of[tgt.names[i]]]}
    frames = 0
    for m in range(tgt.frames):
        n = step * m
        if n >= src.frames:
            break
        frames += 1
        sw, tw = src.world(n), tgt.world(m)
        for s, t in pairs:
            d = sw[s][0] if ref_world is None else sw[s][0] @ ref_world[s][0].T
            d = d @ aim.get(t, np.eye(3))
            key = f"{s}->{t}"
            per_pair[key] = max(per_pair[key], angle_deg(tw[t][0], d))
        expected = k * (sw[root_src][1] - np.array([0.0, floor_src, 0.0])) + np.array([0.0, floor, 0.0])
        # Never below the floor: the root rises by what of the target's pose would go under.
        _, hip_above_lowest = standing(tgt, m)
        expected[1] = max(expected[1], floor + hip_above_lowest)
        worst_root = max(worst_root, float(np.linalg.norm(tw[root_tgt][1] - expected)))
        sp, tp = positions(src, n), positions(tgt, m)
        for ti, below in one_aim.items():
            si, sd = s_index[s_of[tgt.names[ti]]], s_index[s_of[tgt.names[below]]]
            a, b = unit(tp[below] - tp[ti]), unit(sp[sd] - sp[si])
            if a is not None and b is not None:
                cos = float(np.clip(np.dot(a, b), -1.0, 1.0))
                key = tgt.names[ti]
                per_aim[key] = max(per_aim.get(key, 0.0), float(np.degrees(np.arccos(cos))))
    json.dump({"worst_deg": max(per_pair.values()), "per_pair": per_pair,
               "worst_root_m": worst_root, "worst_aim_deg": max(per_aim.values(), default=0.0),
               "per_aim": per_aim, "frames": frames, "k": k},
              sys.stdout)


if __name__ == "__main__":
    main()
