"""Benchmark: samples/s of the bit-accurate steady-state filter against other ways to write it.

Every contender runs the same steady-state filter (default formats) on the same ADC codes and
must produce the same integers as ``kfpga`` (checked before timing): our model single-channel
(Python ints) and batched (numpy, 4096 channels), the filter written on APyTypes and on
fxpmath, and filterpy's float KalmanFilter with the steady gain. Figures are from one run on one
machine; compare the ratios, not the absolute numbers.

    python bench/bench_model.py [--samples N] [--json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import apytypes as apy
import numpy as np
from filterpy.kalman import KalmanFilter
from fxpmath import Fxp

from kfpga.core.codes import CODE_FORMAT as INPUT_FORMAT
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.model.kalman2 import steady_gain
from kfpga.model.scenarios import sine

SEED = 20080525


def timed(fn, repeats=3):
    """Best wall time of ``repeats`` calls and the last result."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def apytypes_filter(cfg, model, y):
    """The steady-state filter on APyTypes scalars, cast at every register write."""
    f = cfg.formats
    k, x0 = cfg.constant_raw("steady"), model.reset
    q = {"floor": apy.QuantizationMode.TO_NEG, "nearest": apy.QuantizationMode.TIES_POS,
         "round": apy.QuantizationMode.TIES_AWAY, "convergent": apy.QuantizationMode.TIES_EVEN,
         "fix": apy.QuantizationMode.TO_ZERO}
    o = {"saturate": apy.OverflowMode.SAT, "wrap": apy.OverflowMode.WRAP}

    def fx(raw, fmt):
        return apy.APyFixed(raw & ((1 << fmt.width) - 1), int_bits=fmt.int_bits, frac_bits=fmt.frac_bits)

    def cast(value, fmt):
        return value.cast(int_bits=fmt.int_bits, frac_bits=fmt.frac_bits,
                          quantization=q[fmt.rounding.value], overflow=o[fmt.overflow.value])

    k1, k2 = fx(k["k1"], f["gain"]), fx(k["k2"], f["gain"])
    x1, v = fx(x0["x1"], f["x1"]), fx(x0["v"], f["v"])
    ys = [fx(int(c), INPUT_FORMAT) for c in y]
    out = []
    for yk in ys:
        xl1 = cast(x1 + v, f["xl1"])
        e = cast(yk - xl1, f["e"])
        x1 = cast(xl1 + k1 * e, f["x1"])
        v = cast(v + k2 * e, f["v"])
        out.append(x1)
    # back to raw two's-complement integers
    w = f["x1"].width
    return np.array([int(a.to_bits()) - ((int(a.to_bits()) >> (w - 1)) << w) for a in out], dtype=np.int64)


def fxpmath_filter(cfg, model, y):
    """The steady-state filter with fxpmath doing every quantisation.

    Sums and products are formed in float64, where they are exact for these formats (at most
    51 significant bits); fxpmath then rounds them (floor after adding half an LSB = half up)
    and saturates.
    """
    f = cfg.formats
    k, x0 = cfg.constant_raw("steady"), model.reset

    def quant(value, fmt):
        if fmt.rounding.value not in ("floor", "nearest"):
            raise ValueError(f"this port takes floor or nearest rounding, not {fmt.rounding.value}")
        half = fmt.lsb / 2 if fmt.rounding.value == "nearest" else 0.0
        return Fxp(value + half, signed=True, n_word=fmt.width, n_frac=fmt.frac_bits,
                   rounding="floor", overflow=fmt.overflow.value)

    k1, k2 = k["k1"] * f["gain"].lsb, k["k2"] * f["gain"].lsb
    x1, v = x0["x1"] * f["x1"].lsb, x0["v"] * f["v"].lsb
    out = []
    for yk in y.tolist():
        xl1 = quant(x1 + v, f["xl1"])
        e = quant(float(yk) - xl1.get_val(), f["e"])
        x1q = quant(xl1.get_val() + k1 * e.get_val(), f["x1"])
        v = quant(v + k2 * e.get_val(), f["v"]).get_val()
        x1 = x1q.get_val()
        out.append(int(x1q.val))
    return np.array(out, dtype=np.int64)


def filterpy_filter(cfg, y):
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F = cfg.params.phi
    kf.H = np.array([[1.0, 0.0]])
    k1, k2 = steady_gain(cfg.params)
    gain = np.array([[k1], [k2 / cfg.params.T]])
    out = np.empty(len(y))
    for n, yk in enumerate(y):
        kf.predict()
        kf.x = kf.x + gain * (yk - kf.x[0, 0])  # constant-gain update
        out[n] = kf.x[0, 0]
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=20000, help="samples per single-channel run (default 20000)")
    parser.add_argument("--batch", type=int, default=4096, help="channels in the batched run (default 4096)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    print(f"seed {SEED}")
    cfg = FilterConfig()
    model = FixedModel(cfg, variant="steady")
    _, y = sine(args.samples, SEED)
    ref = model.run(y).x1

    # same integers first: a benchmark of different filters would mean nothing
    n_check = 2000
    assert np.array_equal(apytypes_filter(cfg, model, y[:n_check]), ref[:n_check]), "APyTypes differs"
    n_fxp = 300
    assert np.array_equal(fxpmath_filter(cfg, model, y[:n_fxp]), ref[:n_fxp]), "fxpmath differs"

    results = {}
    t, _ = timed(lambda: model.run(y))
    results["kfpga single channel"] = len(y) / t
    _, yb = sine(1000, SEED, batch=(args.batch,))
    t, _ = timed(lambda: model.run(yb), repeats=2)
    results[f"kfpga batched ({args.batch} channels)"] = yb.size / t
    full = FixedModel(cfg, variant="full")
    t, _ = timed(lambda: full.run(y))
    results["kfpga single channel, time-varying"] = len(y) / t
    t, _ = timed(lambda: full.run(yb), repeats=2)
    results[f"kfpga batched ({args.batch} channels), time-varying"] = yb.size / t
    n_ops = min(len(y), 3000)
    t, _ = timed(lambda: model.run_ops(y[:n_ops]), repeats=1)
    results["kfpga single channel, direct IntOps (not compiled)"] = n_ops / t
    n_apy = min(len(y), 5000)
    t, _ = timed(lambda: apytypes_filter(cfg, model, y[:n_apy]), repeats=2)
    results["APyTypes loop"] = n_apy / t
    t, _ = timed(lambda: fxpmath_filter(cfg, model, y[:n_fxp]), repeats=1)
    results["fxpmath loop"] = n_fxp / t
    n_fp = min(len(y), 5000)
    t, _ = timed(lambda: filterpy_filter(cfg, y[:n_fp]), repeats=2)
    results["filterpy (float64)"] = n_fp / t

    single = results["kfpga single channel"]
    batched = results[f"kfpga batched ({args.batch} channels)"]
    ratios = {
        "single / APyTypes": single / results["APyTypes loop"],
        "single / direct IntOps": single / results["kfpga single channel, direct IntOps (not compiled)"],
        "single / fxpmath": single / results["fxpmath loop"],
        "batched / fxpmath": batched / results["fxpmath loop"],
        "single / filterpy": single / results["filterpy (float64)"],
    }
    info = {"machine": f"{platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}"}
    if args.json:
        print(json.dumps({"samples_per_s": results, "ratios": ratios, **info}, indent=2))
        return 0
    print(f"steady-state filter, default formats, {info['machine']}")
    print(f"{'implementation':<52} {'samples/s':>14}")
    for name, rate in results.items():
        print(f"{name:<52} {rate:>14,.0f}")
    print()
    for name, ratio in ratios.items():
        print(f"{name:<30} {ratio:>10,.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
