"""The mean gyro (°/s) of a raw log over a time window, with numpy, for checking a gyro bias.

    python mean_over_window.py xio <fusion.csv> <start_s> <end_s>
    python mean_over_window.py npz <vqf_imu_data.npz> <start_s> <end_s>

Prints JSON: {"mean_dps": [x, y, z], "samples": n} over samples with start ≤ t ≤ end.
"""

import json
import sys

import numpy as np


def main():
    kind, path, start, end = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
    if kind == "xio":
        d = np.genfromtxt(path, delimiter=",", skip_header=1)
        t, gyr_dps = d[:, 0] - d[0, 0], d[:, 1:4]
    else:
        d = np.load(path)
        fs = float(d["sampling_rate"])
        gyr_dps = np.degrees(d["gyr"].astype(np.float64))
        t = np.arange(len(gyr_dps)) / fs
    # The reader's t = 0 is the first sample; the window's ends are written to 1e-6 s.
    sel = (t >= start - 2e-6) & (t <= end + 2e-6)
    print(json.dumps({"mean_dps": gyr_dps[sel].mean(axis=0).tolist(), "samples": int(sel.sum())}))


if __name__ == "__main__":
    main()
