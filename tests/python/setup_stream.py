"""A raw stream for `imubake setup`'s test: 16 simulated sensors at 100 Hz, one moving at a time.

Written with numpy and scipy's Rotation, apart from imubake's own simulator. Each sensor sits on a
bone of the mixamo rig in a random orientation (the pelvis's: its -y axis the body's forward, +z
up), with its own constant gyro bias (0.5 °/s SD per axis), its own magnetometer hard iron (10 µT
SD per axis) and white noise (gyro 0.1 °/s, specific force 0.02 m/s², field 0.1 µT, per axis). World ENU; gravity's specific force +z, the field
(0, 20, -40) µT. The timeline (seconds):

- 0 to 3: every sensor still;
- slot k (k = 0..15) from 3 + 1.5·k: sensor k of the shuffled order swings about a random axis,
  up to 200 °/s, for 0.8 s (51° out and back), and comes to rest where it started;
- 27 to 33: still (the gyro bias);
- 33 to 39: still (the pose);
- 39 to 45: the pelvis bows 30° forward and back between 41.5 and 43.5 (the heading);
- 45 to 47: still;
- 47 to 62: every sensor tumbles (150 °/s about an axis that wanders through the sensor's
  frame) for the magnetometers;
- 62 to 63: still.

    python setup_stream.py OUT.csv TRUTH.json [SEED]

TRUTH.json: each sensor's bone, bias (rad/s) and hard iron (µT), the order they move in and when, the pelvis
sensor and its forward axis, and the phases' times.
"""

import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation

RATE = 100.0
G = np.array([0.0, 0.0, 9.80665])
FIELD = np.array([0.0, 20.0, -40.0])
BONES = ["Hips", "Spine1", "Head", "LeftArm", "LeftForeArm", "LeftHand", "RightArm",
         "RightForeArm", "RightHand", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg",
         "RightLeg", "RightFoot", "Spine2"]
SLOT0, SLOT, MOVE = 3.0, 1.5, 0.8
BIAS_PHASE = (27.0, 33.0)
POSE_PHASE = (33.0, 39.0)
BOW_PHASE = (39.0, 45.0)
BOW = (41.5, 43.5, 30.0)
MAG_PHASE = (47.0, 62.0)
END = 63.0


def main():
    out, truth_path = sys.argv[1], sys.argv[2]
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    rng = np.random.default_rng(seed)
    ids = [f"imu{n:02d}" for n in rng.choice(90, size=16, replace=False) + 10]
    bones = dict(zip(ids, BONES))
    pelvis = ids[0]
    order = list(rng.permutation(ids))
    bias = {s: np.radians(rng.normal(0.0, 0.5, 3)) for s in ids}
    hard_iron = {s: rng.normal(0.0, 10.0, 3) for s in ids}
    # q_world_sensor at rest; the pelvis's sensor x, y, z = world -x, -y, +z (180° about z):
    # its -y is the body's forward (north).
    start = {s: Rotation.random(random_state=rng.integers(1 << 31)) for s in ids}
    start[pelvis] = Rotation.from_euler("z", 180, degrees=True)
    axes = {s: (lambda v: v / np.linalg.norm(v))(rng.normal(size=3)) for s in ids}

    n = int(round(END * RATE))
    times = np.arange(n) / RATE
    rows = []
    moves = []
    for s in ids:
        k = order.index(s)
        t0 = SLOT0 + SLOT * k
        moves.append({"sensor": s, "bone": bones[s], "start_s": t0, "end_s": t0 + MOVE})
        # The turn rate (sensor frame): 200 °/s · sin(2π (t − t0)/0.8) during the move, whose
        # integral over the move is 0 (out and back).
        rate = np.zeros((n, 3))
        inside = (times >= t0) & (times < t0 + MOVE)
        rate[inside] = np.outer(np.radians(200.0) * np.sin(2 * np.pi * (times[inside] - t0) / MOVE), axes[s])
        # The tumble: 150 °/s about an axis that wanders (three incommensurate rates).
        inside = (times >= MAG_PHASE[0]) & (times < MAG_PHASE[1])
        tau = times[inside] - MAG_PHASE[0]
        phase = rng.uniform(0, 2 * np.pi)
        wander = np.stack([np.sin(0.9 * tau + phase), np.cos(0.55 * tau + phase), np.sin(0.31 * tau) + 0.3], axis=1)
        rate[inside] = np.radians(150.0) * wander / np.linalg.norm(wander, axis=1, keepdims=True)
        # The bow (pelvis only): a turn about the world's −x (the body's left, so the trunk
        # tips forward), 30° · (1 − cos)/2 up and back.
        world_rate = np.zeros((n, 3))
        if s == pelvis:
            b0, b1, deg = BOW
            inside = (times >= b0) & (times < b1)
            phase = 2 * np.pi * (times[inside] - b0) / (b1 - b0)
            world_rate[inside] = np.outer(np.radians(deg) * np.pi / (b1 - b0) * np.sin(phase), [-1.0, 0.0, 0.0])
        # Orientation by exact steps of the piecewise-constant rates (sample i's rate holds to i+1).
        q = start[s]
        orientation = []
        for i in range(n):
            orientation.append(q)
            dt = 1.0 / RATE
            q = Rotation.from_rotvec(world_rate[i] * dt) * q * Rotation.from_rotvec(rate[i] * dt)
        orientation = Rotation.concatenate(orientation)
        # Every sensor is back where it started, to rounding (the pose and the bow rely on it).
        assert (orientation[int(BIAS_PHASE[0] * RATE)] * start[s].inv()).magnitude() < 1e-9
        # The gyro reads the body-frame rate: the sensor's own plus the world's turned in.
        gyro = rate + orientation.inv().apply(world_rate) + bias[s] + rng.normal(0, np.radians(0.1), (n, 3))
        acc = orientation.inv().apply(G) + rng.normal(0, 0.02, (n, 3))
        mag = orientation.inv().apply(FIELD) + hard_iron[s] + rng.normal(0, 0.1, (n, 3))
        for i in range(n):
            rows.append((times[i], s, gyro[i], acc[i], mag[i]))
    rows.sort(key=lambda r: (r[0], r[1]))
    with open(out, "w") as f:
        f.write("# imubake setup's test stream (tests/python/setup_stream.py); world ENU\n")
        f.write("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n")
        for t, s, g, a, m in rows:
            f.write(f"{t:.2f},{s}," + ",".join(f"{v:.6f}" for v in (*g, *a, *m)) + "\n")
    truth = {
        "sensors": {s: {"bone": bones[s], "bias_rad_s": bias[s].tolist(), "hard_iron": hard_iron[s].tolist()}
                    for s in ids},
        "moves": sorted(moves, key=lambda m: m["start_s"]),
        "pelvis": pelvis,
        "forward": "-y",
        "bias_phase_s": BIAS_PHASE,
        "pose_phase_s": POSE_PHASE,
        "bow_phase_s": BOW_PHASE,
        "mag_phase_s": MAG_PHASE,
        "end_s": END,
    }
    with open(truth_path, "w") as f:
        json.dump(truth, f, indent=1)


if __name__ == "__main__":
    main()
