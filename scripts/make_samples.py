#!/usr/bin/env python3
"""Writes the bundled sample captures in samples/ (deterministic; standard library only).

samples/sou_wave.log: a paper-002 SOU log (Table 4 format) of 6 SOUs / 12 nodes, each SOU at about
26 Hz with jittered, asynchronous host timestamps, 20 s long: 3 s of T-pose, then the right arm
waves, the legs march and the head turns. Like a real log it starts with serial-port debug text and
has a few corrupted lines in the middle (a truncated row, line noise, two rows glued together).
Angles are yaw/pitch/roll in degrees, intrinsic Z-Y-X, NED, yaw 0-360 from north (Madgwick output).
"""
import math
import random
from pathlib import Path

random.seed(20260101)
OUT = Path(__file__).resolve().parent.parent / "samples"

HEADING = 90.0  # the subject faces east
DURATION_S = 20.0
START_MS = 5_234_871  # host uptime in ms at the first row


def node_angles(sou, t):
    """(yaw, pitch, roll) of nodes _0 and _1 of one SOU at time t (seconds)."""
    m = max(0.0, t - 3.0)  # motion starts after 3 s of T-pose
    ramp = min(1.0, m / 1.0)
    w = 2 * math.pi * 0.8 * m
    if sou == "N0":  # pelvis, chest: a little sway
        return (HEADING + 3 * ramp * math.sin(w / 2), 2 * ramp * math.sin(w), 0.0), (
            HEADING + 5 * ramp * math.sin(w / 2), 4 * ramp * math.sin(w), 0.0)
    if sou == "N1":  # right upper arm, forearm: waving
        up = 60 * ramp
        return (HEADING, 0.0, -up), (HEADING + 40 * ramp * math.sin(2 * w), 0.0, -up - 50 * ramp)
    if sou == "N2":  # left arm: relaxed swing
        return (HEADING, 10 * ramp * math.sin(w), 20 * ramp), (HEADING, 15 * ramp * math.sin(w), 25 * ramp)
    if sou in ("N3", "N4"):  # legs marching, in anti-phase
        phase = 0.0 if sou == "N3" else math.pi
        thigh = 35 * ramp * max(0.0, math.sin(w + phase))
        return (HEADING, thigh, 0.0), (HEADING, thigh - 40 * ramp * max(0.0, math.sin(w + phase)), 0.0)
    if sou == "N5":  # neck, head: looking around
        return (HEADING + 10 * ramp * math.sin(w / 3), -5 * ramp, 0.0), (
            HEADING + 30 * ramp * math.sin(w / 3), -10 * ramp, 0.0)
    raise ValueError(sou)


def fmt(a):
    yaw, pitch, roll = a
    noise = lambda: random.gauss(0.0, 0.15)
    yaw = (yaw + noise()) % 360.0
    return f"{yaw:.2f},{pitch + noise():.2f},{roll + noise():.2f}"


def sou_wave():
    rows = []
    for sou in ["N0", "N1", "N2", "N3", "N4", "N5"]:
        t_ms = START_MS + random.randint(0, 30)
        while t_ms - START_MS < DURATION_S * 1000:
            a0, a1 = node_angles(sou, (t_ms - START_MS) / 1000.0)
            rows.append((t_ms, sou, f"{t_ms},{sou},{fmt(a0)},{fmt(a1)}"))
            t_ms += random.choice([34, 36, 38, 38, 38, 40, 42])
    rows.sort(key=lambda r: (r[0], r[1]))
    lines = [
        "[    2.114] usb 1-1.2: new full-speed USB device number 3 using xhci_hcd",
        "[    2.301] cdc_acm 1-1.2:1.0: ttyACM0: USB ACM device",
        "Calibrating gyro... keep still",
        "N3,calib done",
    ]
    lines += [r[2] for r in rows]
    # Corruption in the middle, as the serial link produces it.
    mid = len(lines) // 2
    lines.insert(mid, lines[mid][: len(lines[mid]) // 2])  # truncated row
    lines.insert(mid + 100, "\x1b[0m@@#!~~ serial overrun")  # line noise
    glued = lines[mid + 200] + lines[mid + 201]
    lines[mid + 200 : mid + 202] = [glued]  # two rows glued together: both lost
    (OUT / "sou_wave.log").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    OUT.mkdir(exist_ok=True)
    sou_wave()
