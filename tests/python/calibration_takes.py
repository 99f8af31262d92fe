"""Calibration takes with known sensor errors, for imubake's sensor calibration tests.

    python calibration_takes.py random <seed> <sensors> <out.csv> <truth.json>
    python calibration_takes.py from-truth <simulate-truth.json> <out.csv>

`random` draws each sensor's errors (a random ellipsoid for the magnetometer, a lower-triangular
gyro matrix as paper 004's eq. 6, accelerometer offsets and gains, a gyro bias) and writes them to
truth.json; `from-truth` takes them from `imubake simulate --raw --sensor-errors` truth (its
`errors` and `gyro_bias_dps` per sensor, its field). Either way the take, at 100 Hz, is what a
person calibrating the sensors would record, one schedule for every sensor:

  5 s still; six positions (each axis up, then down), each reached by a 1.5 s turn and held 3 s;
  whole turns (1 or 2) about nine sensor-frame axes (x, y, z, the three diagonals, three more),
  3 s a turn, 2 s still after each; 40 s of tumbling (body rates of three incommensurate sines);
  3 s still.

Readings (sensor frame): gyro = M ω + b + noise (rad/s), accelerometer = diag(k) f + o + noise
(m/s², f = gravity's reaction, the sensor turning in place), magnetometer = S m + h + noise (µT,
the field F (0, cos δ, −sin δ) in ENU). Orientation is integrated with scipy's Rotation at 1 kHz.
Written independently of imubake (numpy/scipy only).
"""

import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation as R

RATE = 100.0
FINE = 10  # integration steps per sample
G = 9.80665
UP = np.array([0.0, 0.0, G])


def draw_errors(rng):
    m = np.eye(3)
    for r in range(3):
        m[r, r] += rng.uniform(-0.03, 0.03)
        for c in range(r):
            m[r, c] = rng.uniform(-1, 1) * np.radians(1.0)
    s = np.eye(3) + 0.0
    for r in range(3):
        for c in range(r, 3):
            d = rng.uniform(-0.05, 0.05)
            s[r, c] += d
            if c != r:
                s[c, r] += d
    h = rng.normal(size=3)
    h = h / np.linalg.norm(h) * rng.uniform(5, 40)
    return {
        "gyro_matrix": m.tolist(),
        "acc_gain": (1 + rng.uniform(-0.03, 0.03, 3)).tolist(),
        "acc_offset_m_s2": rng.uniform(-0.3, 0.3, 3).tolist(),
        "soft_iron": s.tolist(),
        "hard_iron_ut": h.tolist(),
    }


def schedule(rng, q0):
    """Body rates (sensor frame) at FINE * RATE Hz and the orientations they integrate to."""
    dt = 1.0 / (RATE * FINE)
    rates = []

    def hold(seconds):
        rates.extend([np.zeros(3)] * int(round(seconds / dt)))

    def turn(axis, angle, seconds):
        axis = np.asarray(axis, float) / np.linalg.norm(axis)
        n = int(round(seconds / dt))
        t = (np.arange(n) + 0.5) * dt
        # Raised-cosine speed: the angle's derivative, integrating to `angle`.
        speed = angle / seconds * (1 - np.cos(2 * np.pi * t / seconds))
        rates.extend(list(speed[:, None] * axis[None, :]))

    q = q0
    hold(5.0)
    # Six positions: the minimal turn bringing each axis up (ENU z), then down.
    for axis in range(3):
        for sign in (1.0, -1.0):
            a = np.zeros(3)
            a[axis] = sign
            up_in_sensor = q.inv().apply([0, 0, 1.0])
            cross = np.cross(up_in_sensor, a)  # rotate the sensor so that `a` meets up
            # body-frame rotation taking the sensor's `a` onto the current up direction
            v = np.cross(a, up_in_sensor)
            ang = np.arctan2(np.linalg.norm(v), np.dot(a, up_in_sensor))
            if np.linalg.norm(v) < 1e-9:
                v = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
                if ang < 1e-9:
                    hold(1.5)
                    hold(3.0)
                    continue
            turn(v, ang, 1.5)
            q = q * R.from_rotvec(v / np.linalg.norm(v) * ang)
            hold(3.0)
    axes = [
        [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, -1],
        [1, -1, 1], list(rng.normal(size=3)), list(rng.normal(size=3)),
    ]
    for i, a in enumerate(axes):
        k = 1 + i % 2
        turn(a, 2 * np.pi * k, 3.0 * k)
        hold(2.0)
    # Tumbling, ramped in and out.
    n = int(round(40.0 / dt))
    t = (np.arange(n) + 0.5) * dt
    ramp = np.minimum(1.0, np.minimum(t, 40.0 - t) / 2.0)
    phases = rng.uniform(0, 2 * np.pi, 3)
    freqs = np.array([0.23, 0.31, 0.17])
    w = 2.0 * np.sin(2 * np.pi * freqs[None, :] * t[:, None] + phases[None, :]) * ramp[:, None]
    rates.extend(list(w))
    hold(3.0)
    rates = np.array(rates)
    # Orientation at each fine step's end: q_{k+1} = q_k ⊗ exp(ω_k dt).
    steps = R.from_rotvec(rates * dt)
    quats = [q0]
    cur = q0
    for k in range(len(rates)):
        cur = cur * steps[k]
        quats.append(cur)
    return rates, quats


def readings(errors, bias_rad_s, field_enu, rng, q0):
    rates, quats = schedule(rng, q0)
    m = np.array(errors["gyro_matrix"])
    k = np.array(errors["acc_gain"])
    o = np.array(errors["acc_offset_m_s2"])
    s = np.array(errors["soft_iron"])
    h = np.array(errors["hard_iron_ut"])
    out = []
    for i in range(len(rates) // FINE):
        # The mean rate over the sample's period (as the simulator's gyro), the orientation at its end.
        w = rates[i * FINE:(i + 1) * FINE].mean(axis=0)
        q = quats[(i + 1) * FINE]
        f = q.inv().apply(UP)
        mag = q.inv().apply(field_enu)
        gyr = m @ w + bias_rad_s + rng.normal(0, np.radians(0.1), 3)
        acc = k * f + o + rng.normal(0, 0.02, 3)
        mg = s @ mag + h + rng.normal(0, 0.2, 3)
        out.append(((i + 1) / RATE, gyr, acc, mg))
    return out


def write(path, per_sensor):
    rows = []
    for name, samples in per_sensor.items():
        for t, g, a, m in samples:
            rows.append((t, name, g, a, m))
    rows.sort(key=lambda r: (r[0], r[1]))
    with open(path, "w") as f:
        f.write("# calibration take from calibration_takes.py\n")
        f.write("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n")
        for t, name, g, a, m in rows:
            vals = ",".join("%.9g" % v for v in (*g, *a, *m))
            f.write("%.4f,%s,%s\n" % (t, name, vals))


def main():
    mode = sys.argv[1]
    if mode == "random":
        seed, count, out_csv, out_truth = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
        rng = np.random.default_rng(seed)
        field = 48.0 * np.array([0.0, np.cos(np.radians(62)), -np.sin(np.radians(62))])
        truth = {"field_enu_ut": field.tolist(), "sensors": {}}
        per_sensor = {}
        for i in range(count):
            name = "s%d" % i
            errors = draw_errors(rng)
            bias = rng.uniform(-1, 1, 3) * np.radians(2.0)
            truth["sensors"][name] = dict(errors, gyro_bias_dps=np.degrees(bias).tolist())
            per_sensor[name] = readings(errors, bias, field, rng, R.random(random_state=rng.integers(1 << 31)))
        write(out_csv, per_sensor)
        with open(out_truth, "w") as f:
            json.dump(truth, f, indent=1)
    elif mode == "from-truth":
        truth_path, out_csv = sys.argv[2], sys.argv[3]
        truth = json.load(open(truth_path))
        field = np.array(truth["raw"]["field_enu_ut"])
        rng = np.random.default_rng(7)
        per_sensor = {}
        for s in truth["sensors"]:
            bias = np.radians(np.array(s["gyro_bias_dps"]))
            per_sensor[s["sensor"]] = readings(s["errors"], bias, field, rng, R.random(random_state=rng.integers(1 << 31)))
        write(out_csv, per_sensor)
    else:
        sys.exit("usage: see the docstring")


if __name__ == "__main__":
    main()
