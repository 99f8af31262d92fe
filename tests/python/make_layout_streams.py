#!/usr/bin/env python3
"""Captures in the two shipped packet layouts (layouts/*.yaml), written from known values with
Python's `struct` and `binascii` (independently of imubake's decoder), with what a decoder must
make of them.

usage: make_layout_streams.py OUT_DIR

writes:
  matrix.txt   paper 004's data matrix: rows `sensor new type v1 … vn`, the values hexadecimal
               IEEE-754 float32 (big-endian bytes); sensors 1 and 2 send quaternions (type 2),
               sensor 3 Euler angles in degrees (type 1); 100 rows per sensor per second, no time
               (read with --rate 100); every 37th row of sensor 2 is a repeat with the new-data
               flag 0; three rows are damaged (a short hex token, an unknown type, a missing value)
  esp32.bin    the ESP32 struct: AA 55, u8 sensor, u32 t_us, float32 q[4], int16 gyro[3], int16
               accel[3], CRC-16/CCITT-FALSE (binascii.crc_hqx with 0xFFFF) over the bytes after
               the start, little-endian; 3 sensors at 100 Hz for 3 s, junk before the first frame,
               and three frames with a flipped byte
  esp32.csv    the same readings as imubake CSV (q, gyroscope in deg/s, accelerometer in g):
               what the binary capture must convert like
  expected.json  {"matrix": {"rows": [{"line", "sensor", "type", "values"}], "repeats": [lines],
               "bad_lines": [lines], "quaternions": {sensor: [[w, x, y, z] per kept row]}},
               "esp32": {"frames": [{"offset", "sensor", "t_us", "q", "gyro_dps", "accel_g"}],
               "bad_offsets": [offsets], "junk": n}}
"""
import binascii
import json
import math
import os
import struct
import sys

from scipy.spatial.transform import Rotation

RATE = 100
SECONDS = 3
GYRO_DPS = 2000 / 32768
ACCEL_G = 16 / 32768


def f32(v):
    """v rounded to float32, back as a Python float."""
    return struct.unpack("<f", struct.pack("<f", v))[0]


def unit_quaternion(t, sensor):
    """A smooth turn, different per sensor, normalised then rounded to float32."""
    yaw, pitch, roll = 40 * math.sin(0.7 * t + sensor), 15 * math.sin(1.3 * t), 10 * math.cos(0.9 * t + sensor)
    x, y, z, w = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_quat()
    return [f32(w), f32(x), f32(y), f32(z)]


def matrix(out_dir):
    rows, repeats, bad_lines, quaternions = [], [], [], {}
    lines = []
    for k in range(RATE * SECONDS):
        t = k / RATE
        for sensor in (1, 2, 3):
            if sensor == 3:
                kind = 1
                values = [f32(30 * math.sin(t)), f32(10 * math.sin(2 * t)), f32(-5 * math.cos(t))]
                # R = Rz(yaw) Ry(pitch) Rx(roll): scipy's intrinsic "ZYX".
                x, y, z, w = Rotation.from_euler("ZYX", values, degrees=True).as_quat()
                q = [w, x, y, z]
            else:
                kind = 2
                values = unit_quaternion(t, sensor)
                n = math.sqrt(sum(v * v for v in values))
                q = [v / n for v in values]
            hexes = " ".join(struct.pack(">f", v).hex().upper() for v in values)
            lines.append("%d 1 %d %s" % (sensor, kind, hexes))
            rows.append({"line": len(lines), "sensor": sensor, "type": kind, "values": values})
            quaternions.setdefault(str(sensor), []).append(q)
            if sensor == 2 and k % 37 == 5:
                lines.append("%d 0 %d %s" % (sensor, kind, hexes))
                repeats.append(len(lines))
        if k in (50, 120, 200):
            damaged = {
                50: "1 1 2 3F80000 00000000 00000000 00000000",
                120: "1 1 9 3F800000 00000000 00000000 00000000",
                200: "3 1 1 3F800000 00000000",
            }[k]
            lines.append(damaged)
            bad_lines.append(len(lines))
    with open(os.path.join(out_dir, "matrix.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    return {"rows": rows, "repeats": repeats, "bad_lines": bad_lines, "quaternions": quaternions}


def esp32(out_dir):
    data = bytearray(b"boot: ets Jun  8 2016\r\n")
    junk = len(data)
    frames, bad_offsets = [], []
    csv = ["time_s,sensor,qw,qx,qy,qz,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g"]
    for k in range(RATE * SECONDS):
        t_us = 10_000 * k
        for sensor in (1, 2, 3):
            q = unit_quaternion(t_us / 1e6, sensor)
            gyro = [int(3000 * math.sin(0.5 * k / RATE + i + sensor)) for i in range(3)]
            accel = [int(2048 * math.cos(0.3 * k / RATE + i)) for i in range(3)]
            accel[2] += 2048
            payload = struct.pack("<BI4f3h3h", sensor, t_us, *q, *gyro, *accel)
            crc = binascii.crc_hqx(payload, 0xFFFF)
            frame = bytearray(b"\xAA\x55" + payload + struct.pack("<H", crc))
            offset = len(data)
            if k in (30, 31, 150) and sensor == 2:
                frame[12] ^= 0x10  # inside q: the CRC no longer matches
                bad_offsets.append(offset)
            else:
                gyro_dps = [g * GYRO_DPS for g in gyro]
                accel_g = [a * ACCEL_G for a in accel]
                frames.append({"offset": offset, "sensor": sensor, "t_us": t_us, "q": q,
                               "gyro_dps": gyro_dps, "accel_g": accel_g})
                csv.append(",".join([repr(t_us / 1e6), str(sensor)] + [repr(v) for v in q + gyro_dps + accel_g]))
            data += frame
    with open(os.path.join(out_dir, "esp32.bin"), "wb") as f:
        f.write(bytes(data))
    with open(os.path.join(out_dir, "esp32.csv"), "w") as f:
        f.write("\n".join(csv) + "\n")
    return {"frames": frames, "bad_offsets": bad_offsets, "junk": junk}


def main(argv):
    if len(argv) != 2:
        sys.exit(__doc__)
    out_dir = argv[1]
    os.makedirs(out_dir, exist_ok=True)
    expected = {"matrix": matrix(out_dir), "esp32": esp32(out_dir)}
    with open(os.path.join(out_dir, "expected.json"), "w") as f:
        json.dump(expected, f)


if __name__ == "__main__":
    main(sys.argv)
