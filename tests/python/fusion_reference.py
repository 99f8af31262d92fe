#!/usr/bin/env python3
"""Reference orientations for imubake's fusion cores, computed by independent implementations on
a real IMU log: PyPI `vqf` (the VQF authors' own C++, online, float64) and PyPI `ahrs` (Madgwick
and Mahony, MARG and IMU). Writes one JSON file with the readings and each filter's quaternions
(w, x, y, z); tests/motion/fusion_reference.rs compares imubake's cores with them sample by sample.

    python fusion_reference.py <vqf_imu_data.npz> <out.json> [samples]

The log is ../shared/data/imu/vqf_imu_data.npz (the VQF repository's example data, MIT): its
readings go into the output file, which lives in a temporary folder and is not checked in.
"""
import json
import sys

import numpy as np
import vqf
from ahrs.filters import Madgwick, Mahony

BETA = 0.12
KP, KI = 0.74, 0.0012


def main():
    npz, out = sys.argv[1], sys.argv[2]
    n = int(sys.argv[3]) if len(sys.argv) > 3 else 4000
    d = np.load(npz)
    rate = float(d["sampling_rate"])
    ts = 1.0 / rate
    gyr = np.ascontiguousarray(d["gyr"][:n], dtype=float)
    acc = np.ascontiguousarray(d["acc"][:n], dtype=float)
    mag = np.ascontiguousarray(d["mag"][:n], dtype=float)

    v = vqf.VQF(ts)
    batch = v.updateBatch(gyr, acc, mag)

    # ahrs: the first sample's attitude as the start (given to imubake too), then one update per
    # later sample.
    q0_enu = [0.9, 0.1, -0.2, 0.3]
    q0_enu = list(np.array(q0_enu) / np.linalg.norm(q0_enu))
    # NWU from ENU: q_nwu = Rz(-90°) ⊗ q_enu.
    c, s = np.cos(-np.pi / 4), np.sin(-np.pi / 4)
    r = np.array([c, 0.0, 0.0, s])

    def qmul(a, b):
        w1, x1, y1, z1 = a
        w2, x2, y2, z2 = b
        return np.array([
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ])

    q0_nwu = qmul(r, np.array(q0_enu))

    def run(filt, update, q0, with_mag):
        q = np.zeros((n, 4))
        q[0] = q0
        for t in range(1, n):
            if with_mag:
                q[t] = update(q[t - 1], gyr[t], acc[t], mag[t], dt=ts)
            else:
                q[t] = update(q[t - 1], gyr[t], acc[t], dt=ts)
        return q

    mw = Madgwick(frequency=rate, gain=BETA)
    madgwick_9d = run(mw, mw.updateMARG, q0_nwu, True)
    mw6 = Madgwick(frequency=rate, gain=BETA)
    madgwick_6d = run(mw6, mw6.updateIMU, q0_nwu, False)
    mh = Mahony(frequency=rate, k_P=KP, k_I=KI)
    mahony_9d = run(mh, mh.updateMARG, np.array(q0_enu), True)
    mh6 = Mahony(frequency=rate, k_P=KP, k_I=KI)
    mahony_6d = run(mh6, mh6.updateIMU, np.array(q0_enu), False)

    json.dump({
        "sample_time_s": ts,
        "beta": BETA, "kp": KP, "ki": KI,
        "q0_enu": q0_enu,
        "gyr": gyr.tolist(), "acc": acc.tolist(), "mag": mag.tolist(),
        "vqf_quat6d": batch["quat6D"].tolist(),
        "vqf_quat9d": batch["quat9D"].tolist(),
        "vqf_bias": batch["bias"].tolist(),
        "madgwick_9d_nwu": madgwick_9d.tolist(),
        "madgwick_6d_nwu": madgwick_6d.tolist(),
        "mahony_9d_enu": mahony_9d.tolist(),
        "mahony_6d_enu": mahony_6d.tolist(),
    }, open(out, "w"))


if __name__ == "__main__":
    main()
