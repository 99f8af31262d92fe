#!/usr/bin/env python3
"""WitMotion recordings (the binary serial protocol) encoding known values, for tests/readers/witmotion.rs.

    python make_witmotion.py OUT_DIR

Writes OUT_DIR/session/{left_thigh,left_shank}.bin (100 Hz, 200 samples, each sample the packets
0x50 time, 0x51 acceleration, 0x52 angular velocity, 0x53 angle, 0x54 magnetic field, 0x59
quaternion), OUT_DIR/notime/imu.bin (no time packets, no quaternion: angles only) and
OUT_DIR/expected.json: per recording and sample the values a reader must decode — computed here
from the int16 words written, with the protocol's scales (16 g, 2000 °/s, 180°, 1/32768), g =
9.80665 m/s², and the attitude for angle-only samples by scipy (intrinsic Z-Y-X: yaw, pitch, roll).
In left_shank.bin the checksum of sample 50's 0x52 packet is broken: that sample has no angular
velocity; its byte offset is in expected.json.
"""
import json
import math
import struct
import sys
from pathlib import Path

from scipy.spatial.transform import Rotation

G = 9.80665
RATE = 100
N = 200


def packet(kind, payload):
    body = bytes([0x55, kind]) + payload
    return body + bytes([sum(body) & 0xFF])


def words(kind, values):
    return packet(kind, struct.pack("<4h", *values))


def enc(value, full_scale):
    return max(-32768, min(32767, round(value / full_scale * 32768)))


def sample_values(k, phase):
    t = k / RATE
    roll, pitch, yaw = 20 * math.sin(t + phase), 10 * math.cos(2 * t), 90 + 30 * math.sin(0.5 * t)
    acc = [0.1 * math.sin(t), -0.2, 0.98 + 0.01 * math.cos(t)]
    gyro = [50 * math.cos(t), -20 * math.sin(3 * t), 5.0]
    mag = [120 + k % 7, -40, 300]
    q = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_quat()  # x y z w
    return (roll, pitch, yaw), acc, gyro, mag, [q[3], q[0], q[1], q[2]]


def recording(phase, timed=True, quaternion=True, break_gyro_at=None):
    out, expected, bad_offset = bytearray(), [], None
    for k in range(N):
        angles, acc, gyro, mag, q = sample_values(k, phase)
        a = [enc(v, 16) for v in acc]
        g = [enc(v, 2000) for v in gyro]
        e = [enc(v, 180) for v in angles]
        w = [enc(v, 1) for v in q]
        sample = {}
        if timed:
            ms = k * 10
            out += packet(0x50, bytes([26, 12, 1, 10, 0, ms // 1000]) + struct.pack("<H", ms % 1000))
            sample["t"] = k / RATE
        out += words(0x51, a + [2500])
        sample["accel_m_s2"] = [v / 32768 * 16 * G for v in a]
        gyro_packet = bytearray(words(0x52, g + [0]))
        if k == break_gyro_at:
            gyro_packet[10] ^= 0xFF
            bad_offset = len(out)
        else:
            sample["gyro_rad_s"] = [math.radians(v / 32768 * 2000) for v in g]
        out += gyro_packet
        out += words(0x53, e + [0x1234])
        out += words(0x54, mag + [2500])
        if quaternion:
            out += words(0x59, w)
            sample["q"] = [v / 32768 for v in w]
        else:
            roll, pitch, yaw = (v / 32768 * 180 for v in e)
            x, y, z, qw = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_quat()
            sample["q"] = [qw, x, y, z]
        sample["mag"] = mag
        expected.append(sample)
    return bytes(out), expected, bad_offset


def main():
    out = Path(sys.argv[1])
    (out / "session").mkdir(parents=True, exist_ok=True)
    (out / "notime").mkdir(parents=True, exist_ok=True)
    thigh, thigh_expected, _ = recording(0.0)
    shank, shank_expected, bad = recording(1.0, break_gyro_at=50)
    imu, imu_expected, _ = recording(2.0, timed=False, quaternion=False)
    (out / "session" / "left_thigh.bin").write_bytes(thigh)
    (out / "session" / "left_shank.bin").write_bytes(shank)
    (out / "notime" / "imu.bin").write_bytes(imu)
    json.dump({"left_thigh": thigh_expected, "left_shank": shank_expected, "imu": imu_expected,
               "bad_offset": bad}, open(out / "expected.json", "w"))


if __name__ == "__main__":
    main()
