"""The VQF example log (../shared/data/imu/vqf_imu_data.npz: gyr rad/s, acc m/s², mag, and its
sampling_rate) as an imubake CSV with raw columns (one sensor, `imu`; time from 0 at the rate).

    python vqf_npz_to_csv.py <vqf_imu_data.npz> <out.csv>
"""

import sys

import numpy as np


def main():
    d = np.load(sys.argv[1])
    fs = float(d["sampling_rate"])
    gyr, acc, mag = d["gyr"], d["acc"], d["mag"]
    with open(sys.argv[2], "w") as f:
        f.write("# %s: gyro rad/s, acc m/s², mag as logged; %.3f Hz\n" % (sys.argv[1], fs))
        f.write("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n")
        for i in range(len(gyr)):
            vals = ",".join("%.9g" % v for v in (*gyr[i], *acc[i], *mag[i]))
            f.write("%.6f,imu,%s\n" % (i / fs, vals))


if __name__ == "__main__":
    main()
