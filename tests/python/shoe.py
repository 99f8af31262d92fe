"""SHOE, the stance hypothesis optimal zero-velocity detector (Skog et al., IEEE TBME 2010),
written from the paper with numpy, independently of imubake, for its tests.

Usage: shoe.py <simulate --raw CSV> <sensor> <window_s> <A m/s^2> <Omega rad/s>
Prints one line per reading of <sensor>: time_s and T_k, where
    T_k = (1/W) sum_{i in window} ( |a_i - g a_mean/|a_mean||^2 / A^2 + |w_i|^2 / Omega^2 )
over the readings within window_s/2 of reading k (the threshold folded into A and Omega:
still is T_k <= 1).
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
    for k in range(len(t)):
        inside = np.abs(t - t[k]) <= half + 1e-12
        inside[k] = True
        a, w = acc[inside], gyro[inside]
        mean = a.mean(axis=0)
        up = G * mean / np.linalg.norm(mean)
        stat = (np.sum((a - up) ** 2, axis=1) / a_scale**2 + np.sum(w**2, axis=1) / w_scale**2).mean()
        print(f"{t[k]:.9f} {stat:.12e}")


if __name__ == "__main__":
    main()
