#!/usr/bin/env python3
"""Xsens MVN takes (MVNX 4, as MVN 2019 exports them) made from the bundled 16-sensor walk, and
their imubake-CSV twin, for tests/readers/xsens_mvnx.rs.

    python make_mvnx.py samples/walk.csv OUT_DIR

Writes, in OUT_DIR:
- `walk.mvnx`: configuration FullBody, 17 sensors named after their segments (MVN's order:
  Pelvis, T8, Head, the right then left arm, the right then left leg) at 60 Hz. Each walk sensor is
  resampled (scipy Slerp) onto t = 0.02 s + n / 60 and written as `sensorOrientation` in MVN's
  global frame, x north, y west, z up: q_nwu_sensor = q_nwu_enu ⊗ q_enu_sensor. The walk has no
  head sensor: Head repeats T8's orientation. Three calibration frames (identity, tpose,
  tpose-isb) come first, and every normal frame has all 14 elements in MVN's order (the PyPI
  `mvnx` parser reads them by position). The 23 segments move on their own (for
  `--mvnx-segments`): a skeleton laid out in the identity frame (`SEGMENT_REST`, metres, x
  forward, y left, z up), each segment turning from its parent by a few sines (`local_rotation`),
  the pelvis walking forward and turning; `orientation` (w first) and `position` by forward
  kinematics: q_j = q_parent ⊗ r_j, p_j = p_parent + q_parent · (rest_j − rest_parent).
  `footContacts` (LeftFoot_Heel, LeftFoot_Toe, RightFoot_Heel, RightFoot_Toe): the left foot's
  heel and toe are down when (n // 45) is even, the right foot's when it is odd.
- `walk_upper.mvnx`: the same frames, configuration UpperBody: the first 11 sensors only.
- `walk_twin.csv`: the same orientations in ENU with the walk's sensor names, at t = n / 60: an
  imubake CSV that must convert (with the same mapping, names aside) to the same animation.
"""
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

RATE = 60
T0 = 0.02
SEGMENTS = [
    "Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head",
    "RightShoulder", "RightUpperArm", "RightForeArm", "RightHand",
    "LeftShoulder", "LeftUpperArm", "LeftForeArm", "LeftHand",
    "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToe",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToe",
]
PARENT = {
    "Pelvis": None, "L5": "Pelvis", "L3": "L5", "T12": "L3", "T8": "T12", "Neck": "T8", "Head": "Neck",
    "RightShoulder": "T8", "RightUpperArm": "RightShoulder", "RightForeArm": "RightUpperArm",
    "RightHand": "RightForeArm", "LeftShoulder": "T8", "LeftUpperArm": "LeftShoulder",
    "LeftForeArm": "LeftUpperArm", "LeftHand": "LeftForeArm", "RightUpperLeg": "Pelvis",
    "RightLowerLeg": "RightUpperLeg", "RightFoot": "RightLowerLeg", "RightToe": "RightFoot",
    "LeftUpperLeg": "Pelvis", "LeftLowerLeg": "LeftUpperLeg", "LeftFoot": "LeftLowerLeg",
    "LeftToe": "LeftFoot",
}
SEGMENT_REST = {
    "Pelvis": (0, 0, 0.95), "L5": (0, 0, 1.05), "L3": (0, 0, 1.15), "T12": (0, 0, 1.25),
    "T8": (0, 0, 1.35), "Neck": (0, 0, 1.55), "Head": (0, 0, 1.65),
    "RightShoulder": (0, -0.03, 1.5), "RightUpperArm": (0, -0.18, 1.5),
    "RightForeArm": (0, -0.48, 1.5), "RightHand": (0, -0.73, 1.5),
    "LeftShoulder": (0, 0.03, 1.5), "LeftUpperArm": (0, 0.18, 1.5),
    "LeftForeArm": (0, 0.48, 1.5), "LeftHand": (0, 0.73, 1.5),
    "RightUpperLeg": (0, -0.1, 0.9), "RightLowerLeg": (0, -0.1, 0.5),
    "RightFoot": (0, -0.1, 0.08), "RightToe": (0.15, -0.1, 0.0),
    "LeftUpperLeg": (0, 0.1, 0.9), "LeftLowerLeg": (0, 0.1, 0.5),
    "LeftFoot": (0, 0.1, 0.08), "LeftToe": (0.15, 0.1, 0.0),
}


def local_rotation(j, t):
    """Segment j's turn from its parent at time t (the pelvis: from the global frame)."""
    if j == 0:
        return Rotation.from_rotvec([0, 0, 0.3 * np.sin(0.5 * t)])
    return Rotation.from_rotvec([0.1 * np.sin(1.3 * t + j), 0.35 * np.sin(2 * t + 0.7 * j), 0.05 * np.cos(t + j)])


def segment_frame(t):
    """Every segment's orientation (w x y z) and position at time t, by forward kinematics."""
    rots, pos = {}, {}
    for j, name in enumerate(SEGMENTS):
        parent = PARENT[name]
        r = local_rotation(j, t)
        rest = np.array(SEGMENT_REST[name], dtype=float)
        if parent is None:
            rots[name] = r
            pos[name] = rest + np.array([0.5 * t, 0.0, 0.02 * np.sin(4 * t)])
        else:
            rots[name] = rots[parent] * r
            pos[name] = pos[parent] + rots[parent].apply(rest - np.array(SEGMENT_REST[parent]))
    quats = [v for name in SEGMENTS for v in wxyz(rots[name])]
    positions = [v for name in SEGMENTS for v in pos[name]]
    return quats, positions


# MVN sensor label -> the walk's sensor (Head: the walk has none; it repeats the sternum's).
SENSORS = [
    ("Pelvis", "pelvis"), ("T8", "sternum"), ("Head", "sternum"),
    ("RightShoulder", "right_shoulder_blade"), ("RightUpperArm", "right_upper_arm"),
    ("RightForeArm", "right_forearm"), ("RightHand", "right_hand"),
    ("LeftShoulder", "left_shoulder_blade"), ("LeftUpperArm", "left_upper_arm"),
    ("LeftForeArm", "left_forearm"), ("LeftHand", "left_hand"),
    ("RightUpperLeg", "right_thigh"), ("RightLowerLeg", "right_shank"), ("RightFoot", "right_foot"),
    ("LeftUpperLeg", "left_thigh"), ("LeftLowerLeg", "left_shank"), ("LeftFoot", "left_foot"),
]
UPPER_BODY = 11
# ENU -> NWU: north (ENU y) is NWU x, west (ENU -x) is NWU y, up stays z.
NWU_FROM_ENU = Rotation.from_matrix([[0, 1, 0], [-1, 0, 0], [0, 0, 1]])


def read_walk(path):
    tracks = {}
    for line in open(path):
        if line.startswith("#") or line.startswith("time_s"):
            continue
        t, sensor, w, x, y, z = line.strip().split(",")
        tracks.setdefault(sensor, []).append((float(t), float(x), float(y), float(z), float(w)))
    out = {}
    for sensor, rows in tracks.items():
        rows = np.array(rows)
        out[sensor] = Slerp(rows[:, 0], Rotation.from_quat(rows[:, 1:]))
    return out


def wxyz(rot):
    x, y, z, w = rot.as_quat()
    return [w, x, y, z]


def fmt(values, digits=9):
    return " ".join(f"{v:.{digits}f}" for v in values)


def mvnx(frames, labels, contacts, configuration):
    n_seg, n_sen = len(SEGMENTS), len(labels)
    seg_quats = fmt([1, 0, 0, 0] * n_seg, 6)
    seg_zeros = fmt([0] * 3 * n_seg, 6)
    seg_rest = fmt([v for name in SEGMENTS for v in SEGMENT_REST[name]], 6)
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<mvnx xmlns="http://www.xsens.com/mvn/mvnx" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" version="4">',
        '<mvn version="2019.0.0" build="fixture"/>',
        "<comment>made by tests/python/make_mvnx.py from samples/walk.csv</comment>",
        f'<subject label="walk" torsoColor="#ea6852" frameRate="{RATE}" segmentCount="{n_seg}" '
        f'recDate="Tue Dec 01 10:00:00.000 2026" originalFilename="walk.mvn" configuration="{configuration}" '
        'userScenario="singleLevel">',
        "<comment></comment>",
        "<segments>",
    ]
    for i, s in enumerate(SEGMENTS):
        out.append(f'<segment label="{s}" id="{i + 1}"><points><point label="p{s}"><pos_b>0 0 0</pos_b></point></points></segment>')
    out.append("</segments>")
    out.append("<sensors>")
    out += [f'<sensor label="{label}"/>' for label in labels]
    out.append("</sensors>")
    out.append('<joints><joint label="jL5S1"><connector1>Pelvis/jL5S1</connector1><connector2>L5/jL5S1</connector2></joint></joints>')
    out.append('<ergonomicJointAngles><ergonomicJointAngle label="Pelvis_T8" index="0" parentSegment="Pelvis" childSegment="T8"/></ergonomicJointAngles>')
    out.append("<footContactDefinition>")
    for i, c in enumerate(["LeftFoot_Heel", "LeftFoot_Toe", "RightFoot_Heel", "RightFoot_Toe"]):
        out.append(f'<contactDefinition label="{c}" index="{i}"/>')
    out.append("</footContactDefinition>")
    out.append(f'<frames segmentCount="{n_seg}" sensorCount="{n_sen}" jointCount="1">')
    for kind in ["identity", "tpose", "tpose-isb"]:
        out.append(f'<frame time="0" tc="00:00:00:00" ms="0" type="{kind}"><orientation>{seg_quats}</orientation>'
                   f"<position>{seg_rest}</position></frame>")
    ms0 = 1796119200000
    for n, quats in enumerate(frames):
        ms = ms0 + round(n * 1000 / RATE)
        left = (n // 45) % 2 == 0
        foot = [int(left), int(left), int(not left), int(not left)]
        quats_n, positions_n = segment_frame(n / RATE)
        out.append(
            f'<frame time="{ms - ms0}" index="{n}" tc="10:00:00:{n % RATE:02d}" ms="{ms}" type="normal">'
            f"<orientation>{fmt(quats_n)}</orientation><position>{fmt(positions_n)}</position>"
            f"<velocity>{seg_zeros}</velocity><acceleration>{seg_zeros}</acceleration>"
            f"<angularVelocity>{seg_zeros}</angularVelocity><angularAcceleration>{seg_zeros}</angularAcceleration>"
            f"<footContacts>{' '.join(map(str, foot))}</footContacts>"
            f"<sensorFreeAcceleration>{fmt([0] * 3 * n_sen, 6)}</sensorFreeAcceleration>"
            f"<sensorMagneticField>{fmt([0.5, 0, -0.8] * n_sen, 6)}</sensorMagneticField>"
            f"<sensorOrientation>{fmt([v for q in quats[:n_sen] for v in q])}</sensorOrientation>"
            f"<jointAngle>0 0 0</jointAngle><jointAngleXZY>0 0 0</jointAngleXZY>"
            f"<jointAngleErgo>0 0 0</jointAngleErgo><centerOfMass>0 0 0.95</centerOfMass></frame>"
        )
        contacts.append(foot)
    out.append("</frames>")
    out.append("</subject>")
    out.append('<securityCode code="00000000"/>')
    out.append("</mvnx>")
    return "\n".join(out) + "\n"


def main():
    walk, out_dir = Path(sys.argv[1]), Path(sys.argv[2])
    out_dir.mkdir(parents=True, exist_ok=True)
    tracks = read_walk(walk)
    end = min(s.times[-1] for s in tracks.values())
    start = max(s.times[0] for s in tracks.values())
    assert start <= T0, start
    count = int(np.floor((end - T0) * RATE)) + 1
    times = T0 + np.arange(count) / RATE
    enu = {name: tracks[name](times) for name in tracks}
    frames = []
    for n in range(count):
        frames.append([wxyz(NWU_FROM_ENU * enu[walk_name][n]) for _, walk_name in SENSORS])
    labels = [label for label, _ in SENSORS]
    (out_dir / "walk.mvnx").write_text(mvnx(frames, labels, [], "FullBody"))
    (out_dir / "walk_upper.mvnx").write_text(mvnx(frames, labels[:UPPER_BODY], [], "UpperBody"))
    with open(out_dir / "walk_twin.csv", "w") as f:
        f.write("# world: enu\ntime_s,sensor,qw,qx,qy,qz\n")
        for n in range(count):
            for name in sorted(enu):
                f.write(f"{n / RATE:.9f},{name},{fmt(wxyz(enu[name][n])).replace(' ', ',')}\n")
    print(count)


if __name__ == "__main__":
    main()
