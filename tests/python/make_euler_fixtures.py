#!/usr/bin/env python3
"""Generate tests/fixtures/euler/compat_<ORDER>.json: Euler expectations from Blender's mathutils.

Run (from the crate root) with the Python that has Blender's `bpy` module:

    ~/.cache/imubake-test/venv/bin/python tests/python/make_euler_fixtures.py

Deterministic (fixed seed); rerunning rewrites identical files. The Rust test
tests/outputs/euler_mathutils.rs reads the JSON only; it never runs Python.

Orders and angle layout
-----------------------
File names and the "order" field use imubake's names: an order is named by the order its
rotations are applied, as in BVH channel lists; "ZXY" means R = Rz(a0) * Rx(a1) * Ry(a2).
Blender names the same rotation mode by the reversed string ("YXZ") and stores angles per
axis (euler.x, euler.y, euler.z). Every angle triple in the fixtures is in imubake's
*application order*: angles[k] = blender_euler[AXIS[order[k]]], e.g. for "ZXY"
angles = (euler.z, euler.x, euler.y). Angles are radians.

Precision
---------
mathutils stores Quaternion and Euler components as float32 and computes in float32. So that
both sides start from the same numbers, every quaternion (and every Euler input) written to
the fixtures is rounded to float32 first and that exact float32 value is what mathutils gets.
Numbers are written as the shortest decimal that rounds back to the same float32; the Rust test
parses them and casts to f32 (then to f64) to recover the exact value. mathutils' outputs are
float32 too, so expectations carry float32 rounding (see the tolerances in the Rust test).

Contents of each file (all lists are JSON arrays)
-------------------------------------------------
- order, blender_order, gimbal_lock_epsilon (Blender's EULER_HYPOT_EPSILON), seed, blender.
- trajectories: smooth quaternion tracks, each {name, quats: [[w,x,y,z],...],
  principal: [...], chain: [...]}:
    * principal[n]: the principal solution (middle angle in [-pi/2, pi/2]) of quats[n]. mathutils'
      own Quaternion.to_euler(order) picks, of the two solutions, the one with the smaller sum of
      |angles|; when that one has |middle| > pi/2 the script converts it to the other one,
      (a + pi, pi - b, c + pi) wrapped to (-pi, pi], and checks with mathutils'
      Euler.to_quaternion() that it is the same rotation as mathutils' answer.
    * chain[0] = principal[0]; chain[n] = quats[n].to_euler(order, <chain[n-1] as a mathutils Euler>),
      i.e. Blender's discontinuity filter, fed with its own previous (float32) output.
  Kinds: smooth random motion (one with random quaternion sign flips, which must not matter),
  a long spin (> 360 degrees) about the first-applied axis, a fast tumble about a drifting axis
  (> 360 degrees), a track passing *exactly* through gimbal lock (middle angle +-90 degrees at a
  frame) and one coming near it (middle angle peaking at 89.9 and -89.99 degrees).
  No trajectory frame has cos(middle) within [0.5, 2] x gimbal_lock_epsilon (asserted): there
  float32 (Blender) and float64 (imubake) can legitimately take different branches; that band
  is covered by `threshold_band` instead.
- singles: random quaternions with mathutils' raw to_euler(order) ("to_euler", the smaller-sum
  choice) and the principal solution.
- compat_pairs: random quaternion q, random previous angles in [-12, 12] rad (float32) and
  q.to_euler(order, previous) ("expected").
- boundary_pairs: like compat_pairs, but exact ties: half turns about each axis with previous
  at 0 or +-0.1, and the identity with previous (+-pi/2, +-pi/2, +-pi/2).
- threshold_band: quaternions whose middle angle is 90 degrees minus delta (delta from 0 to 1e-3)
  around Blender's gimbal-lock threshold, with "cy" = |cos(middle)| computed in float64 from
  the exact float32 quaternion, and the principal solution.
- to_quaternion: random angles (float32, in [-7, 7] rad, beyond +-pi on purpose) and
  Euler(..., blender_order).to_quaternion() as [w, x, y, z] (sign as mathutils returns it).
"""

import json
import math
import os
import random
import struct
import sys

import bpy  # mathutils ships inside the bpy module
from mathutils import Euler, Quaternion

SEED = 20240611
ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
AXIS = {"X": 0, "Y": 1, "Z": 2}
EULER_HYPOT_EPSILON = 3.75e-5  # Blender, source/blender/blenlib/intern/math_rotation_c.cc
HERE = os.path.dirname(os.path.abspath(__file__))
OUT_DIR = os.path.normpath(os.path.join(HERE, "..", "fixtures", "euler"))


# ---------------------------------------------------------------------------------------------
# float32 helpers


def f32(v):
    """The float32 nearest to v, as a Python float (exact)."""
    return struct.unpack("<f", struct.pack("<f", v))[0]


def short32(v):
    """A Python float whose repr is the shortest decimal rounding to the float32 f32(v)."""
    v = f32(v)
    if v == 0.0:
        return 0.0
    for digits in range(1, 10):
        s = "%.*g" % (digits, v)
        if f32(float(s)) == v:
            return float(s)
    raise AssertionError(v)


# ---------------------------------------------------------------------------------------------
# float64 quaternion helpers (only used to *generate inputs*, never for expectations)


def qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def qnorm(q):
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def qexp(v):
    """Unit quaternion of the rotation vector v (axis * angle)."""
    angle = math.sqrt(sum(c * c for c in v))
    if angle < 1e-300:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), v[0] * s, v[1] * s, v[2] * s)


def axis_q(axis, angle):
    v = [0.0, 0.0, 0.0]
    v[axis] = angle
    return qexp(v)


def euler_q(order, angles):
    """Generator-side composition R = R_a0 * R_a1 * R_a2 (application order)."""
    q = (1.0, 0.0, 0.0, 0.0)
    for letter, angle in zip(order, angles):
        q = qmul(q, axis_q(AXIS[letter], angle))
    return q


def random_unit_quat(rng):
    return qnorm(tuple(rng.gauss(0.0, 1.0) for _ in range(4)))


def random_unit_vec(rng):
    v = [rng.gauss(0.0, 1.0) for _ in range(3)]
    n = math.sqrt(sum(c * c for c in v))
    return [c / n for c in v]


def quat32(q):
    """Round a float64 quaternion to the float32 values written to the fixture."""
    return [short32(c) for c in q]


def rotation_matrix(q):
    w, x, y, z = qnorm(q)
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def cos_middle(q, order):
    """cos(middle angle) = |first-applied axis column entries orthogonal to ...| in float64.

    For R = R_a0 R_a1 R_a2 the entry R[a0][a2] is +-sin(middle), so cos = sqrt(1 - R[a0][a2]^2),
    computed stably as the hypot of the other two entries of column a2.
    """
    m = rotation_matrix([f32(c) for c in q])  # the exact float32 values, not their decimals
    a0, a2 = AXIS[order[0]], AXIS[order[2]]
    rest = [m[r][a2] for r in range(3) if r != a0]
    return math.hypot(rest[0], rest[1])


# ---------------------------------------------------------------------------------------------
# mathutils side (the expectations)


def to_ours(euler, order):
    """mathutils Euler (per-axis x, y, z storage) -> application-order list of float32 values."""
    return [short32(euler[AXIS[letter]]) for letter in order]


def to_blender_xyz(angles, order):
    xyz = [0.0, 0.0, 0.0]
    for letter, angle in zip(order, angles):
        xyz[AXIS[letter]] = angle
    return xyz


def wrap(a):
    """Wrap to (-pi, pi]."""
    a = math.fmod(a + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def mu_quat(q32):
    return Quaternion(q32)


def mu_angle_between(angles_a, angles_b, order):
    """Rotation angle between two Euler triples, with mathutils' own Euler.to_quaternion()."""
    qa = Euler(to_blender_xyz(angles_a, order), order[::-1]).to_quaternion()
    qb = Euler(to_blender_xyz(angles_b, order), order[::-1]).to_quaternion()
    angle = qa.rotation_difference(qb).angle
    return min(angle, 2 * math.pi - angle)


def mathutils_principal(q32, order):
    """(raw mathutils to_euler, principal) in application order."""
    raw = to_ours(mu_quat(q32).to_euler(order[::-1]), order)
    if abs(raw[1]) <= math.pi / 2 + 1e-6:
        return raw, raw
    other = [short32(wrap(raw[0] + math.pi)), short32(wrap(math.pi - raw[1])),
             short32(wrap(raw[2] + math.pi))]
    # The converted triple is the same rotation as mathutils' own answer (not compared with q:
    # near gimbal lock mathutils' float32 answer itself is off by noise / cos(middle)).
    err = mu_angle_between(raw, other, order)
    assert err < 2e-5, (q32, raw, other, err)
    assert abs(other[1]) <= math.pi / 2 + 1e-6
    return raw, other


def trajectory_record(name, quats64, order):
    quats = [quat32(q) for q in quats64]
    blender = order[::-1]
    for q in quats:
        cy = cos_middle(q, order)
        assert not (0.5 * EULER_HYPOT_EPSILON <= cy <= 2.0 * EULER_HYPOT_EPSILON), (name, cy)
    principal = [mathutils_principal(q, order)[1] for q in quats]
    chain = [principal[0]]
    prev = Euler(to_blender_xyz(principal[0], order), blender)
    for q in quats[1:]:
        e = mu_quat(q).to_euler(blender, prev)
        chain.append(to_ours(e, order))
        prev = e
    return {"name": name, "quats": quats, "principal": principal, "chain": chain}


# ---------------------------------------------------------------------------------------------
# trajectories (float64 inputs)


def smooth_random(rng, frames, flip_signs):
    q = random_unit_quat(rng)
    base = [rng.uniform(-0.08, 0.08) for _ in range(3)]
    wob = [rng.uniform(-0.06, 0.06) for _ in range(3)]
    phase = rng.uniform(0.0, 2.0 * math.pi)
    out = []
    for n in range(frames):
        out.append(tuple(-c for c in q) if flip_signs and rng.random() < 0.25 else q)
        s = math.sin(2.0 * math.pi * n / 40.0 + phase)
        q = qnorm(qmul(q, qexp([b + s * w for b, w in zip(base, wob)])))
    return out


def spin_first_axis(rng, order, frames):
    """Pre-multiplying by a rotation about the first-applied axis winds angles[0] up."""
    a0 = AXIS[order[0]]
    q = euler_q(order, [rng.uniform(-1, 1), rng.uniform(-0.8, 0.8), rng.uniform(-1, 1)])
    wob = [rng.uniform(-0.02, 0.02) for _ in range(3)]
    out = []
    for n in range(frames):
        out.append(q)
        q = qnorm(qmul(axis_q(a0, 0.1), q))
        q = qnorm(qmul(q, qexp([w * math.cos(0.1 * n) for w in wob])))
    return out


def tumble(rng, frames):
    q = random_unit_quat(rng)
    axis = random_unit_vec(rng)
    drift = random_unit_vec(rng)
    out = []
    for n in range(frames):
        out.append(q)
        t = 0.03 * n
        v = [math.cos(t) * a + math.sin(t) * d for a, d in zip(axis, drift)]
        q = qnorm(qmul(q, qexp([0.15 * c for c in v])))
    return out


def through_lock(rng, order, frames):
    """Middle angle crosses +-90 degrees exactly at frame frames // 2."""
    sign = rng.choice([1.0, -1.0])
    a0, c0 = rng.uniform(-2, 2), rng.uniform(-2, 2)
    da, dc = rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05)
    mid = frames // 2
    out = []
    for n in range(frames):
        b = sign * (math.pi / 2 + 0.02 * (n - mid))
        out.append(euler_q(order, [a0 + da * n, b, c0 + dc * n]))
    return out


def near_lock(rng, order, frames):
    """Middle angle follows a sine peaking at 89.9 degrees (frame frames/4) and dipping to
    -89.99 degrees (frame 3 frames/4); frames should be a multiple of 4."""
    a0, c0 = rng.uniform(-2, 2), rng.uniform(-2, 2)
    da, dc = rng.uniform(-0.04, 0.04), rng.uniform(-0.04, 0.04)
    out = []
    for n in range(frames):
        s = math.sin(2.0 * math.pi * n / frames)
        b = s * (math.radians(89.9) if s > 0 else math.radians(89.99))
        out.append(euler_q(order, [a0 + da * n, b, c0 + dc * n]))
    return out


# ---------------------------------------------------------------------------------------------


def make_order(order, rng):
    blender = order[::-1]
    trajectories = [
        trajectory_record("smooth_random", smooth_random(rng, 70, False), order),
        trajectory_record("smooth_random_sign_flips", smooth_random(rng, 70, True), order),
        trajectory_record("long_spin_first_axis", spin_first_axis(rng, order, 100), order),
        trajectory_record("tumble", tumble(rng, 60), order),
        trajectory_record("through_gimbal_lock", through_lock(rng, order, 50), order),
        trajectory_record("near_gimbal_lock", near_lock(rng, order, 48), order),
    ]

    singles = []
    for _ in range(40):
        q = quat32(random_unit_quat(rng))
        raw, principal = mathutils_principal(q, order)
        singles.append({"quat": q, "to_euler": raw, "principal": principal})

    compat_pairs = []
    for _ in range(60):
        q = quat32(random_unit_quat(rng))
        previous = [short32(rng.uniform(-12.0, 12.0)) for _ in range(3)]
        e = mu_quat(q).to_euler(blender, Euler(to_blender_xyz(previous, order), blender))
        compat_pairs.append({"quat": q, "previous": previous, "expected": to_ours(e, order)})

    # Exact ties at the +-pi boundary and between the two solutions. Blender's compatible_eul
    # compares in float32 with pi_thresh = float(pi) > pi, so e.g. a half turn about an axis
    # with previous 0 comes out as -pi there (its "pi flip" fires); in float64 it is +pi. Both
    # are equally close to previous: the Rust test accepts either and reports the tie.
    boundary_pairs = []
    half_turns = [[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    previous_list = [[0.0, 0.0, 0.0], [0.1, -0.1, 0.1], [-0.1, 0.1, -0.1]]
    cases = [(q, prev) for q in half_turns for prev in previous_list]
    cases.append(([1.0, 0.0, 0.0, 0.0], [short32(math.pi / 2)] * 3))
    cases.append(([1.0, 0.0, 0.0, 0.0], [short32(-math.pi / 2)] * 3))
    for q, previous in cases:
        e = mu_quat(q).to_euler(blender, Euler(to_blender_xyz(previous, order), blender))
        boundary_pairs.append({"quat": q, "previous": previous, "expected": to_ours(e, order)})

    threshold_band = []
    for delta in [0.0, 1e-7, 1e-6, 1e-5, 3.0e-5, 3.6e-5, 3.75e-5, 3.9e-5, 4.5e-5, 1e-4, 1e-3]:
        for sign in (1.0, -1.0):
            angles = [rng.uniform(-3, 3), sign * (math.pi / 2 - delta), rng.uniform(-3, 3)]
            q = quat32(euler_q(order, angles))
            raw, principal = mathutils_principal(q, order)
            threshold_band.append({"quat": q, "cy": cos_middle(q, order), "principal": principal})

    to_quaternion = []
    for _ in range(40):
        angles = [short32(rng.uniform(-7.0, 7.0)) for _ in range(3)]
        qe = Euler(to_blender_xyz(angles, order), blender).to_quaternion()
        to_quaternion.append({"angles": angles, "quat": [short32(c) for c in qe]})

    return {
        "order": order,
        "blender_order": blender,
        "gimbal_lock_epsilon": EULER_HYPOT_EPSILON,
        "seed": SEED,
        "blender": bpy.app.version_string,
        "trajectories": trajectories,
        "singles": singles,
        "compat_pairs": compat_pairs,
        "boundary_pairs": boundary_pairs,
        "threshold_band": threshold_band,
        "to_quaternion": to_quaternion,
    }


def main():
    os.makedirs(OUT_DIR, exist_ok=True)
    total = 0
    for index, order in enumerate(ORDERS):
        rng = random.Random(SEED * 10 + index)
        data = make_order(order, rng)
        path = os.path.join(OUT_DIR, "compat_%s.json" % order)
        text = json.dumps(data, separators=(",", ":")) + "\n"
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        total += len(text)
        print("wrote %s (%d bytes)" % (os.path.relpath(path), len(text)))
    print("total %d bytes; mathutils from Blender %s" % (total, bpy.app.version_string))
    return 0


if __name__ == "__main__":
    sys.exit(main())
