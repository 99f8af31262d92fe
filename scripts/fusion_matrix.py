#!/usr/bin/env python3
"""Issue 51's accuracy matrix: the offline fusion on the takes animators record (short, dynamic,
a brief still pose first) against PyPI `vqf`'s offline mode on the same readings.

Each cell simulates a raw capture (`imubake simulate --raw`: 16 body-worn sensors, gyro noise
0.3 °/s, each sensor's constant gyro bias normal on every axis with the cell's standard
deviation, accelerometer 0.05 m/s², magnetometer 0.3 µT) and, with the same seed, the
orientations it was simulated from (the truth). The readings are fused by `imubake fuse --fusion offline` (the default for files), by
`imubake fuse --fusion vqf` (online VQF) and by PyPI `vqf`'s `offlineVQF` (the authors' C++,
on the mean sample interval: it takes uniform samples). Scores per sensor, over the motion (after
the still pose and the blend into the first frame), mean over the 16 sensors, degrees:

- `abs`: RMS of the angle between the fused orientation and the truth (ENU);
- `since`: RMS of the error's change since the still pose — the error quaternion
  `e(t) = q_fused(t) ⊗ q_true(t)⁻¹` against its mean over the pose — what a bone calibrated in
  that pose sees (a constant error is absorbed by calibration, one that changes is not). It does
  not depend on the fused world's heading.

And through the body — what animation sees: each fusion's orientations (and the truth's, for the
floor every fusion shares: the pipeline's own error) are converted by `imubake convert` onto the
source skeleton (`--rig` the source BVH, calibrated over the still pose, no smoothing), and each
mapped bone's world rotation since the calibration pose is compared with the source joint's
world rotation since its zero pose (the pose held), computed independently with scipy
(tests/python/bvh_world_rotations.py): `body`, the mean over the bones of each bone's RMS angle.
The default fusion is converted from the raw readings (the path users take); the others from
their orientations.

The offline fusion's own expected error (`expected_error_deg` per sensor, from `fuse --json`) is
averaged per cell and ranked against the cells' measured errors (Spearman, scipy).

usage: fusion_matrix.py [--cells full|quick|ranking|heldout|norest] [--seeds 1,2,3] [--out FILE.json]
                        [--bin IMUBAKE] [--data SHARED_DATA] [--heldout FILE.bvh=MAPPING,...]
`quick` is two cells and `ranking` twelve short ones (CI); `full` is issue 51's matrix (lengths,
rests, biases, rates, jitter; 216 cells) and takes about 45 minutes on two cores with three
seeds. `heldout` runs each `--heldout` take whole (after its first frame) in four cells: a
check on takes the fusion was not tuned on. `norest` runs each source without a pose (the motion
from the first sample) at 100 Hz for each bias, scored per sensor only (`since` is then since
the first sample): nothing to calibrate the body on. The JSON has each cell (`offline`, `vqf`,
`pypi_offline`, `truth`: [abs, since, body] degrees; `expected_deg`; each seed's sensors) and a
`summary`.
"""
import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import spearmanr
from vqf import offlineVQF

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests", "python"))
from bvh_positions import local_rotations, parse  # noqa: E402
from bvh_world_rotations import world_rotations  # noqa: E402

MAPPING = "tests/fixtures/mappings/cmu_16imu.json"
PYMO_MAPPING = "tests/fixtures/mappings/pymo_16imu.json"


def read_csv(path, columns):
    """{sensor: (times (n,), values (n, columns))} from an imubake CSV (comments skipped)."""
    rows = {}
    with open(path) as f:
        for line in f:
            if line.startswith("#") or line.startswith("time_s"):
                continue
            parts = line.strip().split(",")
            rows.setdefault(parts[1], []).append([float(parts[0])] + [float(v) for v in parts[2:2 + columns]])
    return {s: (np.array(v)[:, 0], np.array(v)[:, 1:]) for s, v in rows.items()}


def rotations(wxyz):
    return Rotation.from_quat(np.column_stack([wxyz[:, 1:], wxyz[:, :1]]))


def scores(fused, truth, times, rest_end, motion_start):
    """[abs, since] RMS degrees of one sensor (Rotation stacks on the same samples)."""
    error = fused * truth.inv()
    rest = times <= rest_end
    motion = times >= motion_start
    absolute = np.degrees(error[motion].magnitude())
    reference = error[rest].mean() if rest.any() else error[0]
    since = np.degrees((error[motion] * reference.inv()).magnitude())
    rms = lambda x: float(np.sqrt(np.mean(x ** 2)))
    return [rms(absolute), rms(since)]


def run(cmd):
    subprocess.run(cmd, check=True, capture_output=True)


_sources = {}


def source(path):
    if path not in _sources:
        _sources[path] = parse(path)[:2]
    return _sources[path]


def write_orientations(path, rows):
    """An imubake orientation CSV (ENU) from [(time_s, sensor, wxyz)] sorted by time."""
    with open(path, "w") as f:
        f.write("# world: enu\ntime_s,sensor,qw,qx,qy,qz\n")
        for t, sensor, q in rows:
            f.write(f"{t:.6f},{sensor}," + ",".join(f"{v:.9f}" for v in q) + "\n")


def body_error(out_bvh, bvh, info, bones, rest_s, fps):
    """Mean over the mapped bones of the RMS angle between the bone's world rotation since the
    calibration pose (the output's mean over [0, rest_s]) and the source joint's world rotation
    since its zero pose, over the motion, degrees."""
    joints, values = source(bvh)
    out_joints, out_values, _ = parse(out_bvh)
    out_local = local_rotations(out_joints, out_values)
    out_world = []
    for k, j in enumerate(out_joints):
        out_world.append(out_local[k] if j["parent"] is None else out_world[j["parent"]] * out_local[k])
    times = np.arange(len(out_values)) / fps
    frames = info["first_frame"] + (times - info["motion_start_s"]) / info["source_frame_time_s"]
    compared = (times >= info["motion_start_s"]) & (frames <= info["last_frame"])
    calibration = times <= rest_s
    src_world = world_rotations(joints, values, frames[compared])
    index = {j["name"]: k for k, j in enumerate(joints)}
    out_index = {j["name"]: k for k, j in enumerate(out_joints)}
    errors = []
    for bone, joint in bones:
        w = out_world[out_index[bone]]
        since = w[compared] * w[calibration].mean().inv()
        angle = np.degrees((since * src_world[index[joint]].inv()).magnitude())
        errors.append(float(np.sqrt(np.mean(angle ** 2))))
    return float(np.mean(errors))


FPS = 60


def cell(binary, repo, bvh, mapping, frames, rest_s, bias_dps, rate_hz, jitter_ms, seed, work):
    common = [bvh, "--mapping", os.path.join(repo, mapping), "--rig", bvh, "--frames", frames,
              "--hold-s", str(rest_s), "--rate", str(rate_hz), "--jitter-ms", str(jitter_ms),
              "--seed", str(seed)]
    if rest_s == 0:
        # No pose: the motion from the first sample (no blend from the zero pose either).
        common += ["--blend-s", "0"]
    raw, ori, info_path = (os.path.join(work, n) for n in ("raw.csv", "truth.csv", "truth.json"))
    run([binary, "simulate", *common, "--raw", "--gyro-bias-sd-dps", str(bias_dps), "--output", raw,
         "--truth", info_path])
    run([binary, "simulate", *common, "--output", ori])
    info = json.load(open(info_path))
    motion_start = info["motion_start_s"]
    # The calibration pose is the still pose the take opens with.
    cell_mapping = json.load(open(os.path.join(repo, mapping)))
    cell_mapping["calibration"] = {"pose": "rest", "start_s": 0.0, "duration_s": rest_s}
    mapping_path = os.path.join(work, "mapping.json")
    json.dump(cell_mapping, open(mapping_path, "w"))
    bones = [(s["bone"], s["source_joint"]) for s in info["sensors"]]
    true_bias = {s["sensor"]: s["gyro_bias_dps"] for s in info["sensors"]}

    def convert(capture, name):
        out = os.path.join(work, "out_" + name)
        run([binary, "convert", capture, "--mapping", mapping_path, "--rig", bvh, "--out", out,
             "--fps", str(FPS), "--format", "bvh", "--smooth", "none", "--root", "fixed"])
        stem = os.path.splitext(os.path.basename(capture))[0]
        return body_error(os.path.join(out, stem + ".bvh"), bvh, info, bones, rest_s, FPS)

    truth = read_csv(ori, 4)
    readings = read_csv(raw, 9)
    fused = {}
    stats = {}
    for fusion in ("offline", "vqf"):
        out = os.path.join(work, fusion + ".csv")
        done = subprocess.run([binary, "fuse", raw, "--output", out, "--fusion", fusion, "--json"],
                              check=True, capture_output=True)
        stats[fusion] = json.loads(done.stdout)["sensors"]
        fused[fusion] = read_csv(out, 4)
    result = {name: [] for name in ("offline", "vqf", "pypi_offline")}
    sensors = {}
    pypi_rows = []
    for sensor, (times, values) in readings.items():
        t_truth, q_truth = truth[sensor]
        true = rotations(q_truth)
        for name in ("offline", "vqf"):
            t, q = fused[name][sensor]
            # `fuse` starts the take at its first sample (the simulation's sensors start up to a
            # jitter later): the same samples, shifted by under a millisecond.
            assert len(t) == len(t_truth) and np.allclose(t - t[0], t_truth - t_truth[0], atol=1e-6), sensor
            result[name].append(scores(rotations(q), true, t_truth, rest_s, motion_start))
        sensors[sensor] = {"offline": result["offline"][-1], **stats["offline"][sensor],
                           "true_gyro_bias_dps": true_bias[sensor]}
        gyr, acc, mag = (np.ascontiguousarray(values[:, i:i + 3]) for i in (0, 3, 6))
        ts = float(np.mean(np.diff(times)))
        q = offlineVQF(gyr, acc, mag, ts)["quat9D"]
        result["pypi_offline"].append(scores(rotations(q), true, times, rest_s, motion_start))
        pypi_rows += [(t, sensor, v) for t, v in zip(times, q)]
    pypi = os.path.join(work, "pypi_offline.csv")
    write_orientations(pypi, sorted(pypi_rows, key=lambda r: r[0]))
    per_sensor = {name: np.mean(np.array(v), axis=0).tolist() for name, v in result.items()}
    if rest_s == 0:
        # Without a pose there is nothing to calibrate on: per sensor only.
        body = {k: float("nan") for k in ("offline", "vqf", "pypi_offline", "truth")}
    else:
        body = {"offline": convert(raw, "offline"),
                "vqf": convert(os.path.join(work, "vqf.csv"), "vqf"),
                "pypi_offline": convert(pypi, "pypi_offline"),
                "truth": convert(ori, "truth")}
    return {**{k: v + [body[k]] for k, v in per_sensor.items()}, "truth": [0.0, 0.0, body["truth"]],
            "sensors": sensors}


def frame_count(bvh):
    with open(bvh) as f:
        for line in f:
            if line.strip().startswith("Frames:"):
                return int(line.split()[1])
    raise ValueError(f"{bvh}: no Frames line")


def matrix(kind, heldout=()):
    """Cells: (label, bvh, mapping, frames at 120 fps, rest s, bias SD °/s, rate Hz, jitter ms)."""
    sources = [("CMU 01_01 5 s", "cmu_01_01.bvh", MAPPING, 600),
               ("CMU 01_01 10 s", "cmu_01_01.bvh", MAPPING, 1200),
               ("CMU 01_01 20 s", "cmu_01_01.bvh", MAPPING, 2400),
               ("pymo walk 5 s", "pymo_walk.bvh", PYMO_MAPPING, 600)]
    if kind == "quick":
        return [("CMU 01_01 10 s", "cmu_01_01.bvh", MAPPING, "1:1200", 1.5, 0.5, 100, 1.0),
                ("pymo walk 5 s", "pymo_walk.bvh", PYMO_MAPPING, "0:599", 0.5, 2.0, 60, 0.0)]
    if kind == "norest":
        # Takes that never rest: each source at 100 Hz, evenly sampled, each bias SD.
        cells = []
        for (label, bvh, mapping, n), bias in itertools.product(sources, (0.0, 0.5, 2.0)):
            first = 1 if bvh.startswith("cmu") else 0
            cells.append((label, bvh, mapping, f"{first}:{first + n - 1}", 0.0, bias, 100, 0.0))
        return cells
    if kind == "heldout":
        cells = []
        for bvh, mapping in heldout:
            label = os.path.basename(bvh)
            for rest, bias, rate, jitter in ((0.5, 2.0, 60, 0.0), (1.5, 0.5, 100, 1.0),
                                             (3.0, 0.5, 200, 0.0), (1.5, 2.0, 100, 0.0)):
                cells.append((label, bvh, mapping, f"1:{frame_count(bvh) - 1}", rest, bias, rate, jitter))
        return cells
    if kind == "ranking":
        # Short takes of each source, with and without jitter, a brief pose at a low rate and a
        # long one at a high rate, one bias each.
        cells = []
        for (label, bvh, mapping, n), jitter, (rest, rate, bias) in itertools.product(
                [sources[0], sources[1], sources[3]], (0.0, 1.0), ((0.5, 60, 2.0), (3.0, 200, 0.5))):
            first = 1 if bvh.startswith("cmu") else 0
            cells.append((label, bvh, mapping, f"{first}:{first + n - 1}", rest, bias, rate, jitter))
        return cells
    cells = []
    for (label, bvh, mapping, n), rest, bias, rate, jitter in itertools.product(
            sources, (0.5, 1.5, 3.0), (0.0, 0.5, 2.0), (60, 100, 200), (0.0, 1.0)):
        length = n / 120.0
        if rest > length - 2.0:
            continue
        first = 1 if bvh.startswith("cmu") else 0
        cells.append((label, bvh, mapping, f"{first}:{first + n - 1}", rest, bias, rate, jitter))
    return cells


def main():
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser()
    parser.add_argument("--cells", choices=("full", "quick", "ranking", "heldout", "norest"), default="full")
    parser.add_argument("--heldout", default="", help="FILE.bvh=MAPPING.json,...")
    parser.add_argument("--out")
    parser.add_argument("--bin", default=os.path.join(here, "target/release/imubake"))
    parser.add_argument("--data", default=os.path.join(here, "../shared/data"))
    parser.add_argument("--seeds", default="1,2,3")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    results = []
    heldout = [tuple(os.path.abspath(p) for p in item.split("=")) for item in args.heldout.split(",") if item]
    for label, bvh, mapping, frames, rest, bias, rate, jitter in matrix(args.cells, heldout):
        per_seed = []
        for seed in seeds:
            with tempfile.TemporaryDirectory() as work:
                per_seed.append(cell(args.bin, here, os.path.join(args.data, "bvh", bvh), mapping,
                                     frames, rest, bias, rate, jitter, seed, work))
        mean = {k: np.mean([s[k] for s in per_seed], axis=0).tolist() for k in per_seed[0] if k != "sensors"}
        expected = float(np.mean([v["expected_error_deg"] for s in per_seed for v in s["sensors"].values()]))
        row = {"take": label, "rest_s": rest, "bias_sd_dps": bias, "rate_hz": rate,
               "jitter_ms": jitter, "seeds": seeds, **mean, "expected_deg": expected,
               "sensors": [s["sensors"] for s in per_seed]}
        results.append(row)
        print(f"{label:15s} rest {rest:3.1f} s bias {bias:3.1f} °/s {rate:3d} Hz jitter {jitter:3.1f} ms  "
              + "  ".join(f"{k} {v[0]:.2f}/{v[1]:.2f}/{v[2]:.2f}" for k, v in mean.items())
              + f"  expected {expected:.2f}", flush=True)
    summary = summarize(results)
    print(json.dumps(summary, indent=1))
    if args.out:
        with open(args.out, "w") as f:
            # Strict JSON: a score that does not exist (no pose, no body) is null, not NaN.
            json.dump(without_nan({"cells": results, "summary": summary}), f, indent=1, allow_nan=False)


def without_nan(value):
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {k: without_nan(v) for k, v in value.items()}
    if isinstance(value, list):
        return [without_nan(v) for v in value]
    return value


def summarize(rows):
    """Means over the cells, the cells where the default is behind PyPI offline (by more than
    0.05°) or above imubake's vqf through the body, and the expected error's rank correlation."""
    col = lambda name, k: np.array([r[name][k] for r in rows])
    names = ("offline", "vqf", "pypi_offline", "truth")
    body, pypi, vqf = col("offline", 2), col("pypi_offline", 2), col("vqf", 2)
    expected = np.array([r["expected_deg"] for r in rows])
    if np.isnan(body).all():
        # No pose (`norest`): per sensor only.
        return {"cells": len(rows),
                "mean": {n: {k: float(np.mean(col(n, i))) for i, k in enumerate(("abs", "since"))}
                         for n in names},
                "behind_pypi_offline_abs": int(np.sum(col("offline", 0) > col("pypi_offline", 0) + 0.05)),
                "mean_expected_deg": float(np.mean(expected))}
    out = {"cells": len(rows),
           "mean": {n: {k: float(np.mean(col(n, i))) for i, k in enumerate(("abs", "since", "body"))}
                    for n in names},
           "behind_pypi_offline_body": int(np.sum(body > pypi + 0.05)),
           "worst_body_excess_over_pypi_offline": float(np.max(body - pypi)),
           "above_own_vqf_body": int(np.sum(body > vqf)),
           "behind_pypi_offline_since": int(np.sum(col("offline", 1) > col("pypi_offline", 1) + 0.05)),
           "mean_expected_deg": float(np.mean(expected))}
    if len(rows) > 2:
        out["spearman_expected_vs_body"] = float(spearmanr(expected, body).correlation)
        out["spearman_expected_vs_since"] = float(spearmanr(expected, col("offline", 1)).correlation)
    return out


if __name__ == "__main__":
    sys.exit(main())
