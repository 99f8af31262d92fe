#!/usr/bin/env python3
"""The qmt full-body example (a MATLAB .mat with one struct per segment: `acc` m/s², `gyr` rad/s,
`quat`, at the times `t`) as imubake CSV with raw readings: time_s,sensor,gx,gy,gz,ax,ay,az.
The file has no magnetometer, so it is a 6D body; its `quat` is left out (imubake fuses the raw
readings itself).

Usage: qmt_to_csv.py IN.mat OUT.csv
"""
import sys

import numpy as np
import scipy.io as sio


def main():
    mat = sio.loadmat(sys.argv[1], squeeze_me=True, struct_as_record=False)
    t = np.asarray(mat["t"], dtype=float)
    segments = sorted(k for k, v in mat.items() if hasattr(v, "_fieldnames"))
    with open(sys.argv[2], "w") as out:
        out.write("# qmt full-body example: raw readings of %d segments (no magnetometer)\n" % len(segments))
        out.write("time_s,sensor,gx,gy,gz,ax,ay,az\n")
        for i, ti in enumerate(t):
            for name in segments:
                s = mat[name]
                g, a = s.gyr[i], s.acc[i]
                if np.all(np.isfinite(g)) and np.all(np.isfinite(a)):
                    out.write("%.4f,%s,%s,%s\n" % (ti, name, ",".join("%.7g" % v for v in g),
                                                   ",".join("%.7g" % v for v in a)))


if __name__ == "__main__":
    main()
