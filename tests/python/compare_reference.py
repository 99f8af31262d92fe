#!/usr/bin/env python3
"""RMSE and Pearson's r of two joint-angle tables at a given lag, computed independently of imubake
with numpy and scipy (scipy.stats.pearsonr), to check `imubake compare`.

usage: compare_reference.py A.csv B.csv LAG_S [--remove-offset]
Tables: CSV with a `time_s` column and angle columns (degrees; `nan` for none). For each angle in
both, each row of A at time t pairs with B at t + LAG_S by linear interpolation (np.interp; both
series unwrapped with period 360), rows outside B's span or with NaN left out. d = b - a wrapped into
(-180, 180]; offset = mean d; RMSE = sqrt(mean (d - offset)^2) with --remove-offset, else
sqrt(mean d^2); r = pearsonr(a, b).
prints JSON {angle: {"n", "rmse_deg", "r", "offset_deg"}}
"""
import csv
import json
import sys

import numpy as np
from scipy.stats import pearsonr


def load(path):
    rows = list(csv.reader(open(path)))
    header = rows[0]
    data = np.array([[float(x) if x not in ("", "nan") else np.nan for x in r] for r in rows[1:]])
    return {h: data[:, i] for i, h in enumerate(header)}


def main():
    a, b = load(sys.argv[1]), load(sys.argv[2])
    lag = float(sys.argv[3])
    remove = "--remove-offset" in sys.argv[4:]
    out = {}
    for name in a:
        if name in ("frame", "time_s") or name not in b:
            continue
        ta, va = a["time_s"], a[name].copy()
        finite = ~np.isnan(va)
        va[finite] = np.unwrap(va[finite], period=360.0)
        tb, vb = b["time_s"], b[name]
        keep_b = ~np.isnan(vb)
        tb, vb = tb[keep_b], np.unwrap(vb[keep_b], period=360.0)
        t = ta + lag
        inside = (t >= tb[0]) & (t <= tb[-1]) & ~np.isnan(va)
        x = va[inside]
        y = np.interp(t[inside], tb, vb)
        d = (y - x + 180.0) % 360.0 - 180.0
        offset = float(np.mean(d))
        rmse = float(np.sqrt(np.mean((d - (offset if remove else 0.0)) ** 2)))
        r = None if np.ptp(x) == 0 or np.ptp(y) == 0 else float(pearsonr(x, y).statistic)
        out[name] = {"n": int(inside.sum()), "rmse_deg": rmse, "r": r, "offset_deg": offset}
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
