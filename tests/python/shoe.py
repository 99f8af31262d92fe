"""SHOE, the stance hypothesis optimal zero-velocity detector (Skog et al., IEEE TBME 2010),
written from the paper with numpy, independently of imubake, for its tests.

Usage: shoe.py <simulate --raw CSV> <sensor> <window_s> <A m/s^2> <Omega rad/s> [POINTS]
Prints one line per reading of <sensor>: time_s and T_k, where
    T_k = (1/W) sum_{i in window} ( |a_i - g a_mean/|a_mean||^2 / A^2 + |w_i|^2 / Omega^2 )
over the readings within window_s/2 of reading k (the threshold folded into A and Omega:
still is T_k <= 1). With POINTS ("x,y,z;x,y,z;...", metres, sensor frame, from the sensor),
a third column: the least over the points r of the point's acceleration if it stood, m/s^2,
    a_k(r) = sqrt( (1/W) sum_{i in window} |c_i - g c_mean/|c_mean||^2 ),
    c_i = a_i + dw_i x r + w_i x (w_i x r),
dw_i the gyro's central difference (w_{i+1} - w_{i-1}) / (t_{i+1} - t_{i-1}), one-sided at the
ends: the specific force of a rigid body turning about a point that stands is gravity alone.
"""
import sys
import numpy as np

G = 9.80665


def main():
    path, sensor = sys.argv[1], sys.argv[2]
    window_s, a_scale, w_scale = (float(x) for x in sys.argv[3:6])
    rows = []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or line.startswith("time_s"):
                continue
            cells = line.strip().split(",")
            if len(cells) < 8 or cells[1] != sensor:
                continue
            rows.append([float(c) for c in [cells[0]] + cells[2:8]])
    data = np.array(rows)
    t, gyro, acc = data[:, 0], data[:, 1:4], data[:, 4:7]
    half = window_s / 2.0
    points = []
    if len(sys.argv) > 6:
        points = [np.array([float(v) for v in p.split(",")]) for p in sys.argv[6].split(";")]
    n = len(t)
    dw = np.zeros_like(gyro)
    for i in range(n):
        lo, hi = max(i - 1, 0), min(i + 1, n - 1)
        dw[i] = (gyro[hi] - gyro[lo]) / (t[hi] - t[lo])
    compensated = [acc + np.cross(dw, r) + np.cross(gyro, np.cross(gyro, r)) for r in points]
    for k in range(n):
        inside = np.abs(t - t[k]) <= half + 1e-12
        inside[k] = True
        a, w = acc[inside], gyro[inside]
        mean = a.mean(axis=0)
        up = G * mean / np.linalg.norm(mean)
        stat = (np.sum((a - up) ** 2, axis=1) / a_scale**2 + np.sum(w**2, axis=1) / w_scale**2).mean()
        line = f"{t[k]:.9f} {stat:.12e}"
        if points:
            least = np.inf
            for c in compensated:
                ck = c[inside]
                m = ck.mean(axis=0)
                least = min(least, np.sqrt((np.sum((ck - G * m / np.linalg.norm(m)) ** 2, axis=1)).mean()))
            line += f" {least:.12e}"
        print(line)


if __name__ == "__main__":
    main()
