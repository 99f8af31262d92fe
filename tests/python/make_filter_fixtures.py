"""Write tests/fixtures/filters/*.json: inputs and SciPy/NumPy outputs for src/smooth/.

Usage (from the crate root):

    ~/.cache/imubake-test/venv/bin/python tests/python/make_filter_fixtures.py

The Rust test tests/motion/filters_scipy.rs reads only the JSON; Python is not needed at test time.
Deterministic: every random input comes from numpy.random.default_rng(SEED), and floats are
written with repr (round-trip exact). Written with SciPy 1.17.1 and NumPy 1.26.4.

Files:
  butter_sos.json   scipy.signal.butter(order, cutoff, fs=rate, output='sos') and sosfilt_zi
  sosfilt.json      scipy.signal.sosfilt / sosfiltfilt (defaults) on several series, including
                    series of length padlen + 1, padlen + 2 and (an error) padlen
  gaussian.json     scipy.ndimage.gaussian_filter1d(x, sigma, mode='reflect', truncate=...),
                    including series shorter than the kernel radius
  fft.json          the paper-002 frequency-domain filter written directly in NumPy (below), with
                    the DC bin included in or excluded from the maximum, and the cutoff variant
"""

import json
import os
import sys

import numpy as np
import scipy
import scipy.ndimage
import scipy.signal

SEED = 20260522
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "fixtures", "filters")


def floats(a):
    return [float(v) for v in np.asarray(a, dtype=np.float64).ravel()]


def make_signals(rng):
    """Named input series (lists of floats)."""
    s = {}
    s["random_walk_240"] = np.cumsum(rng.normal(scale=0.1, size=240))
    t = np.arange(257) / 100.0
    s["sine_noise_257"] = np.sin(2 * np.pi * 1.3 * t) + 0.2 * rng.normal(size=257)
    step = np.zeros(120)
    step[50:] = 1.0
    s["step_120"] = step
    # An angle track in degrees with a large mean (relative tolerance territory).
    t = np.arange(181) / 50.0
    s["angle_deg_181"] = (
        50.0 + 20.0 * np.sin(2 * np.pi * 0.7 * t) + 3.0 * np.sin(2 * np.pi * 9.0 * t)
        + 0.5 * rng.normal(size=181)
    )
    for n in (1, 2, 3, 5, 8):
        s["short_%d" % n] = rng.normal(size=n)
    return {k: floats(v) for k, v in s.items()}


def padlen(sos):
    ntaps = 2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum())
    return int(3 * ntaps)


def butter_cases():
    cases = []
    designs = [(1.0, 60.0), (5.0, 60.0), (20.0, 60.0), (6.0, 100.0), (25.0, 100.0),
               (30.0, 100.0), (45.0, 100.0), (2.0, 400.0), (150.0, 400.0), (0.5, 1000.0)]
    for order in range(1, 7):
        for cutoff, rate in designs:
            cases.append((order, cutoff, rate))
    for order in (7, 8, 9, 10):
        for cutoff, rate in ((5.0, 100.0), (40.0, 100.0)):
            cases.append((order, cutoff, rate))
    out = []
    for order, cutoff, rate in cases:
        sos = scipy.signal.butter(order, cutoff, fs=rate, output="sos")
        zi = scipy.signal.sosfilt_zi(sos)
        out.append({
            "order": order, "cutoff_hz": cutoff, "rate_hz": rate,
            "sos": [floats(r) for r in sos], "zi": [floats(r) for r in zi],
            "padlen": padlen(sos),
        })
    return out


def sosfilt_cases(signals, rng):
    long_cases = [
        ("random_walk_240", 1, 5.0, 100.0),
        ("random_walk_240", 4, 6.0, 100.0),
        ("random_walk_240", 6, 1.0, 400.0),
        ("random_walk_240", 8, 10.0, 100.0),
        ("sine_noise_257", 2, 3.0, 100.0),
        ("sine_noise_257", 3, 5.0, 100.0),
        ("sine_noise_257", 6, 10.0, 100.0),
        ("sine_noise_257", 2, 40.0, 100.0),
        ("step_120", 3, 5.0, 60.0),
        ("step_120", 5, 20.0, 60.0),
        ("angle_deg_181", 4, 2.0, 50.0),
        ("angle_deg_181", 3, 5.0, 50.0),
    ]
    out = []
    for name, order, cutoff, rate in long_cases:
        out.append(one_sosfilt_case(name, signals[name], order, cutoff, rate))
    # Short series around the padding length: padlen (too short), padlen + 1, padlen + 2.
    for order in range(1, 7):
        cutoff, rate = (5.0, 100.0) if order % 2 else (12.0, 60.0)
        sos = scipy.signal.butter(order, cutoff, fs=rate, output="sos")
        p = padlen(sos)
        for n in (p, p + 1, p + 2):
            name = "short_o%d_n%d" % (order, n)
            signals[name] = floats(np.cumsum(rng.normal(size=n)))
            out.append(one_sosfilt_case(name, signals[name], order, cutoff, rate))
    return out


def one_sosfilt_case(name, x, order, cutoff, rate):
    sos = scipy.signal.butter(order, cutoff, fs=rate, output="sos")
    x = np.asarray(x)
    case = {"signal": name, "order": order, "cutoff_hz": cutoff, "rate_hz": rate,
            "sosfilt": floats(scipy.signal.sosfilt(sos, x))}
    try:
        case["sosfiltfilt"] = floats(scipy.signal.sosfiltfilt(sos, x))
    except ValueError as e:
        assert "padlen" in str(e), e
        case["too_short"] = {"needed": padlen(sos) + 1, "got": len(x)}
    return case


def gaussian_cases(signals):
    plan = [
        ("random_walk_240", [0.5, 1.0, 2.5, 7.3], [4.0]),
        ("sine_noise_257", [2.0, 3.0], [4.0, 2.5]),
        ("step_120", [1.5, 30.0], [4.0]),
        ("angle_deg_181", [4.0], [4.0]),
        ("short_1", [1.0, 3.0], [4.0]),
        ("short_2", [0.7, 1.0, 3.0], [4.0]),
        ("short_3", [1.0, 3.0, 10.0], [4.0]),
        ("short_5", [1.0, 3.0, 10.0], [4.0, 1.0]),
        ("short_8", [1.0, 2.0, 3.0, 10.0], [4.0]),
    ]
    out = []
    for name, sigmas, truncates in plan:
        x = np.asarray(signals[name])
        for sigma in sigmas:
            for truncate in truncates:
                y = scipy.ndimage.gaussian_filter1d(x, sigma, mode="reflect", truncate=truncate)
                out.append({"signal": name, "sigma": sigma, "truncate": truncate,
                            "radius": int(truncate * sigma + 0.5), "output": floats(y)})
    return out


def fft_reference(x, rate, threshold, suppress, cutoff, dc_included):
    """The paper-002 filter in NumPy; returns (output, smallest relative margin to the limit)."""
    x = np.asarray(x)
    n = len(x)
    X = np.fft.rfft(x)
    mag = np.abs(X)
    Y = X.copy()
    margin = np.inf
    if threshold is not None:
        if dc_included:
            limit = threshold * mag.max()
            Y = np.where(mag >= limit, X, X * suppress)
            considered = mag
        elif n > 1:
            limit = threshold * mag[1:].max()
            Y = np.where(mag >= limit, X, X * suppress)
            Y[0] = X[0]
            considered = mag[1:]
        else:
            considered = np.array([])
        if considered.size and limit > 0:
            margin = float(np.min(np.abs(considered - limit)) / limit)
    if cutoff is not None:
        Y[np.fft.rfftfreq(n, 1.0 / rate) > cutoff] = 0
    return np.fft.irfft(Y, n=n), margin


def fft_cases(signals):
    variants = [
        # (threshold, suppress, cutoff_hz, dc_included)
        (0.5, 0.3, None, False),
        (0.5, 0.3, None, True),
        (0.2, 0.0, None, False),
        (None, 0.3, 12.5, False),
        (0.5, 0.3, 12.5, True),
        (0.3, 0.5, 4.0, False),
    ]
    plan = [
        ("random_walk_240", 100.0),
        ("sine_noise_257", 100.0),
        ("angle_deg_181", 50.0),
        ("step_120", 60.0),
        ("short_1", 100.0),
        ("short_2", 100.0),
        ("short_3", 100.0),
        ("short_8", 100.0),
    ]
    out = []
    for name, rate in plan:
        for threshold, suppress, cutoff, dc_included in variants:
            y, margin = fft_reference(signals[name], rate, threshold, suppress, cutoff,
                                      dc_included)
            # A bin within 1e-9 (relative) of the limit could fall either way between two
            # correct FFTs; such cases would test rounding, not the filter.
            if margin < 1e-9:
                print("skipping ill-conditioned case", name, threshold, dc_included,
                      file=sys.stderr)
                continue
            out.append({"signal": name, "rate_hz": rate, "threshold": threshold,
                        "suppress": suppress, "cutoff_hz": cutoff,
                        "dc": "included" if dc_included else "excluded",
                        "output": floats(y)})
    return out


def main():
    rng = np.random.default_rng(SEED)
    signals = make_signals(rng)
    os.makedirs(OUT, exist_ok=True)
    meta = {"scipy": scipy.__version__, "numpy": np.__version__, "seed": SEED,
            "script": "tests/python/make_filter_fixtures.py"}
    sos_cases = sosfilt_cases(signals, rng)
    files = {
        "butter_sos.json": {"meta": meta, "cases": butter_cases()},
        "sosfilt.json": {"meta": meta, "signals": signals, "cases": sos_cases},
        "gaussian.json": {"meta": meta, "signals": signals, "cases": gaussian_cases(signals)},
        "fft.json": {"meta": meta, "signals": signals, "cases": fft_cases(signals)},
    }
    total = 0
    for fname, content in files.items():
        path = os.path.join(OUT, fname)
        with open(path, "w") as f:
            json.dump(content, f, separators=(",", ":"))
            f.write("\n")
        size = os.path.getsize(path)
        total += size
        print("%s: %d cases, %d bytes" % (fname, len(content["cases"]), size))
    print("total %d bytes" % total)
    assert total < 500_000, "fixtures too large"


if __name__ == "__main__":
    main()
