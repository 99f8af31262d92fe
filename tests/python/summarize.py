#!/usr/bin/env python3
"""An independent re-implementation of paper 002's data summarizer (7.4.2), used to check
`imubake inspect --json`. It parses each format with Python's csv/re modules and numpy, sharing no
code with imubake.

usage: summarize.py FORMAT PATH   (FORMAT: sou | imubake-csv | xsens-dot | xsens-mtw | xio-session)
prints JSON: {"node_count", "time_frame_s", "sensors": {id: {"samples", "mean_dt_ms",
"min_dt_ms", "max_dt_ms", "gaps": [[start_s, end_s], ...]}}, "dropped_lines": [line numbers]}
"""
import csv
import json
import math
import os
import re
import sys

import numpy as np

SOU_RE = re.compile(r"^[0-9]+,[a-zA-Z0-9]+(,[ \-0-9\.]+){6}$")
GAP_S = 0.25


def sou(path):
    series, dropped, seen = {}, [], set()
    with open(path, "rb") as f:
        for n, raw in enumerate(f.read().split(b"\n"), start=1):
            line = raw.rstrip(b"\r").decode("utf-8", "replace")
            if not line.strip():
                continue
            if not SOU_RE.match(line):
                dropped.append(n)
                continue
            fields = line.split(",")
            try:
                values = [float(v) for v in fields[2:]]
            except ValueError:
                dropped.append(n)
                continue
            if not all(math.isfinite(v) for v in values):
                dropped.append(n)
                continue
            t = int(fields[0]) / 1000.0
            if (fields[1], t) in seen:  # a repeated time: the first row is kept
                dropped.append(n)
                continue
            seen.add((fields[1], t))
            for node in ("_0", "_1"):
                series.setdefault(fields[1] + node, []).append(t)
    return series, dropped


def imubake_csv(path):
    series, dropped, seen = {}, [], set()
    with open(path, newline="") as f:
        rows = list(enumerate(f.read().splitlines(), start=1))
    rows = [(n, l) for n, l in rows if l.strip() and not l.lstrip().startswith("#")]
    header = [h.strip().lower() for h in rows[0][1].split(",")]
    tcol = next(h for h in header if h in ("time_s", "time_ms", "time_us"))
    scale = {"time_s": 1.0, "time_ms": 1e-3, "time_us": 1e-6}[tcol]
    for n, line in rows[1:]:
        fields = line.split(",")
        row = dict(zip(header, fields))
        try:
            values = [float(row[h]) for h in header if h != "sensor"]
        except (ValueError, KeyError):
            dropped.append(n)
            continue
        if len(fields) != len(header) or not row["sensor"].strip() or not all(map(math.isfinite, values)):
            dropped.append(n)
            continue
        quat = [row.get(h) for h in ("qw", "qx", "qy", "qz")]
        if None not in quat and all(float(v) == 0.0 for v in quat):
            dropped.append(n)
            continue
        key = (row["sensor"].strip(), float(row[tcol]))
        if key in seen:
            dropped.append(n)
            continue
        seen.add(key)
        series.setdefault(key[0], []).append(key[1] * scale)
    return series, dropped


def xsens_dot(folder):
    series = {}
    for name in sorted(os.listdir(folder)):
        if not name.endswith(".csv"):
            continue
        with open(os.path.join(folder, name), encoding="utf-8") as f:
            lines = f.read().splitlines()
        start = next(i for i, l in enumerate(lines) if l.startswith("PacketCounter,"))
        header = lines[start].split(",")
        col = header.index("SampleTimeFine")
        ticks = []
        for l in lines[start + 1:]:
            fields = l.split(",")
            if len(fields) >= len(header) and fields[col].isdigit():
                ticks.append(int(fields[col]))
        ticks = np.array(ticks, dtype=np.int64)
        steps = np.diff(ticks)
        steps[steps < -(2**31)] += 2**32
        unwrapped = np.concatenate([[ticks[0]], ticks[0] + np.cumsum(steps)])
        series[name.split("_")[0]] = list(unwrapped / 1e6)
    return series, []


def xsens_mtw(folder):
    series = {}
    files = [folder] if os.path.isfile(folder) else [os.path.join(folder, n) for n in sorted(os.listdir(folder)) if n.endswith(".txt")]
    for path in files:
        with open(path, newline="") as f:
            lines = f.read().splitlines()
        rate = float(next(l for l in lines if "Update Rate" in l).split(":")[1].strip().rstrip("Hz"))
        header_at = next(i for i, l in enumerate(lines) if l.startswith("PacketCounter"))
        counters = np.array([int(l.split("\t")[0]) for l in lines[header_at + 1:] if l.strip()], dtype=np.int64)
        steps = np.diff(counters)
        steps[steps < -(2**15)] += 2**16
        unwrapped = np.concatenate([[counters[0]], counters[0] + np.cumsum(steps)])
        sensor = os.path.splitext(os.path.basename(path))[0].split("_")[-1]
        series[sensor] = list(unwrapped / rate)
    return series, []


def xio_session(folder):
    """Per device: the quaternion stream; the take's clock spans every stream of every device."""
    series, bounds = {}, []
    for device in sorted(os.listdir(folder)):
        name = re.sub(r"\s+[0-9A-F]{8}\s+\([^)]*\)$", "", device)
        for stream in ("Quaternion.csv", "Inertial.csv", "Magnetometer.csv"):
            path = os.path.join(folder, device, stream)
            if not os.path.isfile(path):
                continue
            with open(path, newline="") as f:
                times = [int(r[0]) / 1e6 for r in list(csv.reader(f))[1:] if r]
            bounds += [min(times), max(times)]
            if stream == "Quaternion.csv":
                series[name] = times
    return series, [], bounds


def summarize(series, dropped, bounds=()):
    """bounds: extra times (other streams) that the take's clock also spans."""
    start = min([min(t) for t in series.values()] + list(bounds))
    end = max([max(t) for t in series.values()] + list(bounds))
    sensors = {}
    for node, times in series.items():
        t = np.array(times, dtype=np.float64)
        t = np.sort(t, kind="stable")
        t = t[np.concatenate([[True], np.diff(t) != 0])]  # repeated times keep the first
        dt = np.diff(t)
        sensors[node] = {
            "samples": int(len(t)),
            "mean_dt_ms": float(np.mean(dt) * 1e3) if len(dt) else None,
            "min_dt_ms": float(np.min(dt) * 1e3) if len(dt) else None,
            "max_dt_ms": float(np.max(dt) * 1e3) if len(dt) else None,
            "gaps": [[float(a - start), float(b - start)] for a, b, d in zip(t[:-1], t[1:], dt) if d > GAP_S],
        }
    return {"node_count": len(series), "time_frame_s": float(end - start), "sensors": sensors,
            "dropped_lines": dropped}


if __name__ == "__main__":
    fmt, path = sys.argv[1], sys.argv[2]
    reader = {"sou": sou, "imubake-csv": imubake_csv, "xsens-dot": xsens_dot,
              "xsens-mtw": xsens_mtw, "xio-session": xio_session}[fmt]
    print(json.dumps(summarize(*reader(path))))
