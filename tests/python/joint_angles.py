#!/usr/bin/env python3
"""Joint angles of a BVH at every frame, computed independently of imubake with numpy and scipy
(a reference for `imubake angles`).

usage: joint_angles.py FILE.bvh OUT.csv [N]
writes CSV `frame,time_s,<columns>`, one row per BVH frame (time_s = frame * Frame Time), degrees.
With N the reference pose is frame N's instead of the rest pose: every "rest" below is frame N
(positions P are frame N's), and R_world(j, t) is replaced by R_world(j, t) R_world(j, N)^T, the
turn since frame N (so a skeleton whose joints' axes differ gives the same angles).

Definitions:
- BVH: rotation channels compose as intrinsic Euler angles in channel order; a position channel
  replaces its OFFSET component; R_world(j) = R_world(parent) R_local(j),
  p(child) = p(parent) + R_world(parent) offset(child). Rest pose = all channels zero (R = I).
- Joint names are compared after stripping any prefix up to the last ':'. Landmarks (S = Left or
  Right, first present wins): upper_arm SArm|SUpArm|SShoulder, forearm SForeArm|SLowArm|SElbow,
  hand SHand|SWrist, hand_end SHandMiddle1|SFingerBase|SHand_End (else the hand), walked down first
  children while it sits on the hand at rest, ending at an End Site; thigh SUpLeg|SThigh|SHip, shank SLeg|SKnee|SShin, foot SFoot|SAnkle, toe
  SToeBase|SToe (else the foot), walked the same way; pelvis = lowest common ancestor
  of the thighs, thorax = lowest common ancestor of the upper arms, neck = Neck|Head.
- Body frame B at rest: up = +Y, right = unit(P[right thigh] - P[left thigh] without its up
  part), fwd = up x right, B = [fwd, up, right] (ISB: X anterior, Y superior, Z right).
- Rest segment frames (columns X, Y, Z): pelvis, thorax, foot = B; a limb from Pp to Pd (thigh,
  shank, upper arm, forearm, hand -> hand_end): Y = unit(Pp - Pd), X = unit(r - (r.Y)Y),
  Z = X x Y, r = fwd (thigh, shank, upper arm) or the palm (forearm, hand): fwd when the rest arm
  hangs (unit(P[forearm] - P[upper_arm]) . -up >= cos 30 deg), else -up. F(t) = R_world(joint, t) F_rest.
- `{side}_{joint}` = angle between segment vectors (A, B) = atan2(|A x B|, A.B): shoulder (D, U),
  elbow (U, Fv), wrist (Fv, H), hip (D, T), knee (T, K), ankle (K, Ft), with D = pelvis - neck,
  U = forearm - upper_arm, Fv = hand - forearm, H = hand_end - hand, T = shank - thigh,
  K = foot - shank, Ft = toe - foot at rest, each turned by its segment joint's world rotation
  (D by the thorax for the shoulder, by the pelvis for the hip), as paper 000 builds its vectors.
- R = F_prox^T F_dist: shoulder (thorax, upper arm), elbow (upper arm, forearm), wrist (forearm,
  hand), hip (pelvis, thigh), knee (thigh, shank), ankle (shank, foot). Shoulder:
  R = Rx(b) Rz(a) Ry(c) (intrinsic 'XZY'); others R = Rz(a) Rx(b) Ry(c) (intrinsic 'ZXY').
  flexion = a (knee: -a); abduction = b left, -b right; rotation = -c left, c right.
"""
import sys
import warnings

import numpy as np
from scipy.spatial.transform import Rotation

from bvh_positions import forward, parse  # the suite's own minimal BVH reader (numpy, no imubake)

SIDES = ("Left", "Right")
JOINTS = ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class Skeleton:
    def __init__(self, joints):
        self.joints = joints
        self.short = [None if j["name"] is None else j["name"].split(":")[-1] for j in joints]

    def find(self, *names):
        for name in names:
            for k, s in enumerate(self.short):
                if s == name:
                    return k
        return None

    def children(self, k):
        return [i for i, j in enumerate(self.joints) if j["parent"] == k]

    def ancestors(self, k):
        chain = []
        while k is not None:
            chain.append(k)
            k = self.joints[k]["parent"]
        return chain

    def lca(self, a, b):
        if a is None or b is None:
            return None
        anc = set(self.ancestors(b))
        return next((k for k in self.ancestors(a) if k in anc), None)


def end_point(sk, joint, names, rest):
    """A point landmark: the first named joint below `joint` (else `joint` itself), walked down
    first children while it sits on `joint` at rest, ending at an End Site. Returns a function
    pos_list -> (n, 3) array, or None."""
    if joint is None:
        return None
    eps = 1e-9 * (1.0 + np.linalg.norm(rest[joint]))
    k = sk.find(*names)
    if k is None or joint not in sk.ancestors(k)[1:]:
        k = joint
    while True:
        if k != joint and np.linalg.norm(rest[k] - rest[joint]) > eps:
            return lambda pos, k=k: pos[k]
        kids = sk.children(k)
        named = [c for c in kids if sk.joints[c]["name"] is not None]
        if named:
            k = named[0]
            continue
        ends = [c for c in kids if sk.joints[c]["name"] is None]
        if ends and np.linalg.norm(rest[ends[0]] - rest[joint]) > eps:
            return lambda pos, e=ends[0]: pos[e]
        return None


def landmarks(sk, rest):
    lm = {}
    for S in SIDES:
        d = {}
        d["upper_arm"] = sk.find(S + "Arm", S + "UpArm", S + "Shoulder")
        d["forearm"] = sk.find(S + "ForeArm", S + "LowArm", S + "Elbow")
        d["hand"] = sk.find(S + "Hand", S + "Wrist")
        d["hand_end"] = end_point(sk, d["hand"], (S + "HandMiddle1", S + "FingerBase", S + "Hand_End"), rest)
        d["thigh"] = sk.find(S + "UpLeg", S + "Thigh", S + "Hip")
        d["shank"] = sk.find(S + "Leg", S + "Knee", S + "Shin")
        d["foot"] = sk.find(S + "Foot", S + "Ankle")
        d["toe"] = end_point(sk, d["foot"], (S + "ToeBase", S + "Toe"), rest)
        lm[S] = d
    lm["pelvis"] = sk.lca(lm["Left"]["thigh"], lm["Right"]["thigh"])
    lm["thorax"] = sk.lca(lm["Left"]["upper_arm"], lm["Right"]["upper_arm"])
    neck = sk.find("Neck", "Head")
    lm["neck"] = None if neck is None else (lambda pos, k=neck: pos[k])
    return lm


def limb_frame(p_prox, p_dist, r):
    y = unit(p_prox - p_dist)
    x = unit(r - np.dot(r, y) * y)
    z = np.cross(x, y)
    return np.column_stack([x, y, z])


def gamma(a, b):
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def euler(R, seq):
    """Intrinsic Euler angles (degrees) of a stack of rotation matrices, NaN where R is not finite."""
    out = np.full((len(R), 3), np.nan)
    ok = np.all(np.isfinite(R), axis=(1, 2))
    if np.any(ok):
        out[ok] = Rotation.from_matrix(R[ok]).as_euler(seq, degrees=True)
    return out


def compute(path, ref=None):
    joints, values, frame_time = parse(path)
    sk = Skeleton(joints)
    world, pos = forward(joints, values)
    if ref is None:
        _, rest = forward(joints, np.zeros((1, values.shape[1])), channels=False)
        rest = [p[0] for p in rest]
    else:
        rest = [p[ref] for p in pos]
        world = [w * w[ref].inv() for w in world]
    wmat = {}

    def W(k):
        if k not in wmat:
            wmat[k] = world[k].as_matrix()
        return wmat[k]

    lm = landmarks(sk, rest)
    L, Rt = lm["Left"], lm["Right"]
    columns, data = [], []
    if L["thigh"] is None or Rt["thigh"] is None:
        return frame_time, len(values), columns, data  # no body frame: nothing can be defined

    up = np.array([0.0, 1.0, 0.0])
    right = rest[Rt["thigh"]] - rest[L["thigh"]]
    right = unit(right - np.dot(right, up) * up)
    fwd = np.cross(up, right)
    B = np.column_stack([fwd, up, right])

    def V(joint, v_rest):
        """A segment vector: its rest vector turned by its joint's world rotation (n, 3)."""
        return world[joint].apply(v_rest)

    def seg(joint, F_rest):
        return W(joint) @ F_rest  # (n, 3, 3)

    for jname in JOINTS:
        for S in SIDES:
            d = lm[S]
            side = S.lower()
            try:
                if jname in ("shoulder", "elbow", "wrist"):
                    ua, fa, ha = d["upper_arm"], d["forearm"], d["hand"]
                    if ua is None or fa is None:
                        raise LookupError
                    dirn = unit(rest[fa] - rest[ua])
                    palm = fwd if np.dot(dirn, -up) >= np.cos(np.radians(30.0)) else -up
                    if jname == "shoulder":
                        if lm["thorax"] is None or lm["pelvis"] is None or lm["neck"] is None:
                            raise LookupError
                        A = V(lm["thorax"], rest[lm["pelvis"]] - lm["neck"](rest))
                        Bv = V(ua, rest[fa] - rest[ua])
                        Fp = seg(lm["thorax"], B)
                        Fd = seg(ua, limb_frame(rest[ua], rest[fa], fwd))
                    elif jname == "elbow":
                        if ha is None:
                            raise LookupError
                        A = V(ua, rest[fa] - rest[ua])
                        Bv = V(fa, rest[ha] - rest[fa])
                        Fp = seg(ua, limb_frame(rest[ua], rest[fa], fwd))
                        Fd = seg(fa, limb_frame(rest[fa], rest[ha], palm))
                    else:
                        if ha is None or d["hand_end"] is None:
                            raise LookupError
                        A = V(fa, rest[ha] - rest[fa])
                        Bv = V(ha, d["hand_end"](rest) - rest[ha])
                        Fp = seg(fa, limb_frame(rest[fa], rest[ha], palm))
                        Fd = seg(ha, limb_frame(rest[ha], d["hand_end"](rest), palm))
                else:
                    th, sh, ft = d["thigh"], d["shank"], d["foot"]
                    if jname == "hip":
                        if sh is None or lm["pelvis"] is None or lm["neck"] is None:
                            raise LookupError
                        A = V(lm["pelvis"], rest[lm["pelvis"]] - lm["neck"](rest))
                        Bv = V(th, rest[sh] - rest[th])
                        Fp = seg(lm["pelvis"], B)
                        Fd = seg(th, limb_frame(rest[th], rest[sh], fwd))
                    elif jname == "knee":
                        if sh is None or ft is None:
                            raise LookupError
                        A = V(th, rest[sh] - rest[th])
                        Bv = V(sh, rest[ft] - rest[sh])
                        Fp = seg(th, limb_frame(rest[th], rest[sh], fwd))
                        Fd = seg(sh, limb_frame(rest[sh], rest[ft], fwd))
                    else:
                        if sh is None or ft is None or d["toe"] is None:
                            raise LookupError
                        A = V(sh, rest[ft] - rest[sh])
                        Bv = V(ft, d["toe"](rest) - rest[ft])
                        Fp = seg(sh, limb_frame(rest[sh], rest[ft], fwd))
                        Fd = seg(ft, B)
            except LookupError:
                continue
            g = gamma(A, Bv)
            R = np.einsum("nji,njk->nik", Fp, Fd)
            if jname == "shoulder":
                e = euler(R, "XZY")
                b, a, c = e[:, 0], e[:, 1], e[:, 2]
            else:
                e = euler(R, "ZXY")
                a, b, c = e[:, 0], e[:, 1], e[:, 2]
            flex = -a if jname == "knee" else a
            abd = b if S == "Left" else -b
            rot = -c if S == "Left" else c
            base = f"{side}_{jname}"
            columns += [base, base + "_flexion", base + "_abduction", base + "_rotation"]
            data += [g, flex, abd, rot]
    return frame_time, len(values), columns, data


def main():
    path, out = sys.argv[1], sys.argv[2]
    ref = int(sys.argv[3]) if len(sys.argv) > 3 else None
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore")
        frame_time, n, columns, data = compute(path, ref)
    table = np.column_stack(data) if data else np.zeros((n, 0))
    with open(out, "w") as f:
        f.write(",".join(["frame", "time_s"] + columns) + "\n")
        for t in range(n):
            row = [str(t), repr(float(t * frame_time))] + [repr(float(v)) for v in table[t]]
            f.write(",".join(row) + "\n")


if __name__ == "__main__":
    main()
