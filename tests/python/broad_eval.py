#!/usr/bin/env python3
"""BROAD (Laidig et al. 2021) orientation accuracy of imubake's fusion against optical ground truth.

Usage: broad_eval.py IMUBAKE BROAD_DIR OUT.json [FILTER ...]

For each trial (*.hdf5) in BROAD_DIR: the IMU readings (gyro rad/s, acc m/s², mag µT at the
trial's `sampling_rate`) are written as imubake CSV, fused by `IMUBAKE fuse --fusion FILTER` for
each filter, and by PyPI's `vqf` (the authors' C++; online `VQF.updateBatch` and `offlineVQF`) with
the same sample time. The metric is BROAD's, implemented here independently of imubake: the error
quaternion q_est ⊗ q_opt⁻¹ (world frame), total angle 2·acos|w|, heading error 2·atan|z/w|,
inclination 2·acos√(w²+z²), RMS over samples with `movement` true and a valid reference (NaN
reference samples ignored), no heading offset removed. Published Madgwick/Mahony results
(`results_*_average_rmse.json`, parameters tuned over all 39 trials) are copied for each trial.
"""
import json
import pathlib
import subprocess
import sys
import tempfile

import h5py
import numpy as np
from vqf import VQF, offlineVQF


def qmul(a, b):
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ], axis=1)


def metrics(q_est, q_opt, movement):
    q_est = q_est / np.linalg.norm(q_est, axis=1)[:, None]
    q_opt = q_opt / np.linalg.norm(q_opt, axis=1)[:, None]
    inv = q_opt * np.array([1.0, -1.0, -1.0, -1.0])
    e = qmul(q_est, inv)
    e = e / np.linalg.norm(e, axis=1)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        total = 2 * np.arccos(np.clip(np.abs(e[:, 0]), 0, 1))
        heading = 2 * np.arctan(np.abs(e[:, 3] / e[:, 0]))
        incl = 2 * np.arccos(np.clip(np.sqrt(e[:, 0] ** 2 + e[:, 3] ** 2), 0, 1))

    def rmse(x):
        return float(np.degrees(np.sqrt(np.nanmean(x[movement] ** 2))))

    return {"total_rmse_deg": rmse(total), "heading_rmse_deg": rmse(heading),
            "inclination_rmse_deg": rmse(incl)}


def read_fused(path, n):
    q = np.loadtxt(path, delimiter=",", comments="#", skiprows=3, usecols=(2, 3, 4, 5))
    assert q.shape == (n, 4), (q.shape, n)
    return q


def main():
    imubake, broad, out = sys.argv[1], pathlib.Path(sys.argv[2]), sys.argv[3]
    filters = sys.argv[4:] or ["vqf", "madgwick", "mahony", "trust", "gyro"]
    published = {}
    for name in ("madgwick", "mahony"):
        f = broad / f"results_{name}_average_rmse.json"
        if f.exists():
            published[name] = json.loads(f.read_text())
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for h5 in sorted(broad.glob("*.hdf5")):
            trial = h5.stem
            with h5py.File(h5, "r") as f:
                rate = float(f.attrs["sampling_rate"])
                gyr = np.ascontiguousarray(f["imu_gyr"][:], dtype=float)
                acc = np.ascontiguousarray(f["imu_acc"][:], dtype=float)
                mag = np.ascontiguousarray(f["imu_mag"][:], dtype=float)
                movement = f["movement"][:].astype(bool)
                opt = f["opt_quat"][:]
            n = len(gyr)
            ts = 1.0 / rate
            csv = pathlib.Path(tmp) / f"{trial}.csv"
            t = np.arange(n) / rate
            table = np.column_stack([t, gyr, acc, mag])
            with open(csv, "w") as fh:
                fh.write("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n")
                for row in table:
                    fh.write("%.9f,imu,%s\n" % (row[0], ",".join(repr(float(v)) for v in row[1:])))
            res = {}
            online = VQF(ts).updateBatch(gyr, acc, mag)
            res["pypi vqf online"] = metrics(online["quat9D"], opt, movement)
            res["pypi vqf offline"] = metrics(offlineVQF(gyr, acc, mag, ts)["quat9D"], opt, movement)
            for spec in filters:
                fused = pathlib.Path(tmp) / f"{trial}.{spec.replace(':', '_')}.fused.csv"
                subprocess.run([imubake, "fuse", str(csv), "-o", str(fused), "--fusion", spec],
                               check=True, stdout=subprocess.DEVNULL)
                res[f"imubake {spec}"] = metrics(read_fused(fused, n), opt, movement)
            for name, data in published.items():
                if trial in data["trials"]:
                    res[f"published {name}"] = data["trials"][trial]["tagp_parameters"]
            results[trial] = res
            print(trial, {k: round(v["total_rmse_deg"], 3) for k, v in res.items()}, flush=True)
    pathlib.Path(out).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
