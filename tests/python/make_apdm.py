#!/usr/bin/env python3
"""APDM Opal `.h5` recordings (file format 5, the layout OpenSim's APDM reader and public parsers
read) with known values, written by h5py, for tests/readers/apdm.rs.

    python make_apdm.py OUT_DIR

Writes OUT_DIR/opal.h5 with three sensors at 128 Hz over 2 s:
- `XI-000101`, `Label 0` = b"left_thigh" (NUL-padded to 16 bytes, as fixed-length strings are):
  readings and `/Processed/XI-000101/Orientation` (w first);
- `XI-000102`, `Label 0` a variable-length UTF-8 string "left_shank": readings only;
- `999`, no label: readings only (its id is the group name).
OUT_DIR/expected.json holds what a reader must find: per sensor id, times in seconds from the
first sample, the readings (m/s², rad/s, µT) and the orientation (w, x, y, z, unit norm).
Also writes OUT_DIR/bad_shape.h5 (a Gyroscope of N × 2) and OUT_DIR/short.h5 (a Magnetometer one
sample short).
"""
import json
import sys
from pathlib import Path

import h5py
import numpy as np
from scipy.spatial.transform import Rotation

RATE = 128
N = 2 * RATE
T0_US = 1_796_119_200_000_000  # 2026-12-01 10:00 UTC in µs


def readings(phase):
    t = np.arange(N) / RATE
    acc = np.stack([0.3 * np.sin(t + phase), -0.2 + 0 * t, 9.81 + 0.1 * np.cos(2 * t)], axis=1)
    gyro = np.stack([np.cos(t + phase), -0.5 * np.sin(3 * t), 0.2 + 0 * t], axis=1)
    mag = np.stack([20 + np.sin(t), -5 + 0 * t, -40 + np.cos(t)], axis=1)
    q = Rotation.from_euler("ZYX", np.stack([30 * np.sin(t), 10 * np.cos(t), 5 + 0 * t], axis=1),
                            degrees=True).as_quat()  # x y z w
    return t, acc, gyro, mag, q[:, [3, 0, 1, 2]]


def sensor(f, sid, label, phase, orientation):
    t, acc, gyro, mag, q = readings(phase)
    g = f.create_group(f"Sensors/{sid}")
    g["Time"] = (T0_US + np.round(t * 1e6)).astype(np.uint64)
    g["Accelerometer"] = acc
    g["Gyroscope"] = gyro
    g["Magnetometer"] = mag
    c = g.create_group("Configuration")
    c.attrs["Sample Rate"] = np.uint16(RATE)
    if isinstance(label, bytes):
        c.attrs["Label 0"] = np.array(label.ljust(16, b"\0"), dtype="S16")
    elif label is not None:
        c.attrs["Label 0"] = label
    if orientation:
        f[f"Processed/{sid}/Orientation"] = q
    out = {"t": (np.round(t * 1e6) / 1e6).tolist(), "acc": acc.tolist(), "gyro": gyro.tolist(),
           "mag": mag.tolist()}
    if orientation:
        out["q"] = q.tolist()
    return out


def main():
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    expected = {}
    with h5py.File(out / "opal.h5", "w") as f:
        f.attrs["FileFormatVersion"] = np.int32(5)
        expected["left_thigh"] = sensor(f, "XI-000101", b"left_thigh", 0.0, True)
        expected["left_shank"] = sensor(f, "XI-000102", "left_shank", 1.0, False)
        expected["999"] = sensor(f, "999", None, 2.0, False)
    json.dump(expected, open(out / "expected.json", "w"))
    with h5py.File(out / "bad_shape.h5", "w") as f:
        sensor(f, "XI-1", b"a", 0.0, False)
        del f["Sensors/XI-1/Gyroscope"]
        f["Sensors/XI-1/Gyroscope"] = np.zeros((N, 2))
    with h5py.File(out / "short.h5", "w") as f:
        sensor(f, "XI-1", b"a", 0.0, False)
        del f["Sensors/XI-1/Magnetometer"]
        f["Sensors/XI-1/Magnetometer"] = np.zeros((N - 1, 3))


if __name__ == "__main__":
    main()
