"""Fixed-point versus float: the error figures of ``kfpga compare`` and ``kfpga sweep``."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from kfpga.core.config import FilterConfig, analysed_ranges, default_formats
from kfpga.core.fixedmodel import FixedModel
from kfpga.core.formats import MAX_WORD
from kfpga.model.plots import pyplot, save_figure

__all__ = ["sample_count", "rmse", "sqnr_db", "float_run", "Comparison", "compare", "limit_cycles", "sweep",
           "precision_warnings", "startup_samples",
           "plot_compare", "plot_sweep"]

#: The noise-free inputs of the limit-cycle check: (name, level before, level after, step at)
LIMIT_CYCLE_INPUTS = (("constant +10000", 10000, 10000, 0), ("constant -3001", -3001, -3001, 0),
                      ("step 0 -> 10000", 0, 10000, 1000))
LIMIT_CYCLE_SAMPLES = 8000
LIMIT_CYCLE_WINDOW = 2000  # the last samples, after settling


def rmse(estimate, truth):
    return float(np.sqrt(np.mean((np.asarray(estimate, dtype=np.float64) - truth) ** 2)))


#: The start-up ends when the float filter's error, as a rolling RMS, first comes within this
#: factor of its RMS over the second half of the run.
STARTUP_FACTOR = 1.5


def startup_samples(estimate, truth):
    """The samples the filter's start-up took: the first ``k`` where the RMS of ``estimate -
    truth`` over a window from ``k`` (a hundredth of the run, at least 10 samples) is within
    :data:`STARTUP_FACTOR` of its RMS over the second half; ``None`` when it never is in the
    first half (the run is too short to tell)."""
    err2 = (np.asarray(estimate, dtype=np.float64) - truth) ** 2
    n = err2.shape[-1]
    window = max(10, n // 100)
    if n < 4 * window:
        return None
    steady = float(np.mean(err2[n // 2:]))
    sums = np.concatenate([[0.0], np.cumsum(err2)])
    rolling = (sums[window:] - sums[:-window]) / window  # [k]: the mean over k .. k + window - 1
    inside = np.flatnonzero(rolling[:n // 2] <= STARTUP_FACTOR ** 2 * steady)
    return int(inside[0]) if inside.size else None


def sqnr_db(reference, test):
    """Signal-to-quantisation-noise ratio of ``test`` against ``reference``, in dB."""
    noise = float(np.sum((np.asarray(test) - reference) ** 2))
    signal = float(np.sum(np.asarray(reference) ** 2))
    if noise == 0.0:
        return float("inf")
    return 10.0 * np.log10(signal / noise)


def float_run(config, variant, y, missing=None):
    """The float reference of the config's filter on ``y``: ``{output: float array}`` in input units.

    With ``missing`` (true where a sample has no measurement) it is the filter's own equations in
    float64 (:func:`coast_float_run`): the reference functions take every sample as a measurement."""
    if missing is not None and np.any(missing):
        return coast_float_run(config, variant, y, missing)
    return config.spec.model.reference(config.params, variant, y)


def coast_float_run(config, variant, y, missing):
    """The variant's update (and, where ``missing``, its predict) in float64, sample by sample, on
    :class:`~kfpga.core.ops.FloatOps`: the model's equations with nothing rounded. ``ValueError``
    for a variant that takes every sample as a measurement."""
    from kfpga.core.ops import FloatOps

    v = config.spec.model.variants[variant]
    if v.predict is None:
        raise ValueError(f"the {config.spec.name} filter's {variant} variant takes every sample as a measurement: "
                         "missing samples do not apply")
    states = v.state_for(config.params)
    constants = v.constants(config.params)
    codes = y if isinstance(y, dict) else {config.inputs[0]: y}
    x = {name: float(value) for name, value in v.initial(config.params).items()}
    outs = {name: np.empty(len(missing)) for name in config.output_names}
    for t, lost in enumerate(np.asarray(missing, dtype=bool)):
        ops = FloatOps(config.formats)
        k = ops.constants(constants)
        xs = {name: ops.input(x[name], point, name) for name, point in states}
        if lost:
            nxt, o = v.predict(ops, k, xs)
        else:
            u = {name: ops.input(float(codes[name][t]), config.input_format, name) for name in config.inputs}
            nxt, o = v.update(ops, k, xs, u)
        x = {name: float(nxt[name].raw) for name in x}
        for name in outs:
            outs[name][t] = float(o[name].raw)
    return outs


@dataclass
class Comparison:
    """Result of one fixed-versus-float run; ``metrics`` is what ``--json`` prints."""

    metrics: dict
    y: np.ndarray | None  # the input that observes the main output (None if no input does)
    truth: np.ndarray | None
    float_out: np.ndarray
    fixed_out: np.ndarray
    lsb: float
    settle: int
    output: str = "x1"
    extra: dict = field(default_factory=dict)
    fixed_all: dict = field(default_factory=dict)  # every output, fixed and float (the plot's)
    float_all: dict = field(default_factory=dict)
    period: float | None = None  # the model's sample period in seconds, if it has one


def compare(config, variant, y, truth=None, *, settle=None, seed=None, scenario=None, limit_cycle=True):
    """Run the float and the bit-accurate filter on the same codes ``y`` and measure them.

    The RMSE figures are of the filter's main output (its ``default_output``, x1 for the
    paper's filter) against ``truth`` and skip the first ``settle`` samples, where both filters
    are still converging (default: the float filter's start-up, :func:`startup_samples`, at
    least 100 or a tenth of short runs, at most half the run); the other figures use every
    sample. ``fields`` gives the fixed - float difference of every output; ``overflow_points``
    the samples that overflowed at each quantisation point; ``limit_cycle_lsb`` and
    ``dead_band_lsb`` come from :func:`limit_cycles` (skipped with ``limit_cycle=False``).
    """
    codes = {k: np.asarray(v, dtype=np.int64) for k, v in y.items()} if isinstance(y, dict) else None
    y = codes if codes is not None else np.asarray(y, dtype=np.int64)
    n = sample_count(y)
    # the raw input that observes the main output, for the "raw" RMSE and the plot
    measured = config.spec.measured_input(config.params)
    raw = (codes.get(measured) if codes is not None else y) if measured is not None else None
    model = FixedModel(config, variant=variant)
    res = model.run(y)
    fixed = model.to_float(res)
    flt = float_run(config, variant, y)
    main = config.spec.model.default_output
    fx1, flx1 = fixed[main], flt[main]
    startup = startup_samples(flx1, truth) if truth is not None else None
    if settle is None:  # past the start-up, when it was measured and took more than the default
        settle = max(min(100, n // 10), min(startup or 0, n // 2))
    if not 0 <= settle < n:
        raise ValueError(f"settle must be in [0, {n}), not {settle}")
    lsb = model.output_format(main).lsb
    w = slice(settle, None)
    fields = {}
    for name in model.outputs:
        diff = np.abs(fixed[name] - flt[name])
        out_lsb = model.output_format(name).lsb
        fields[name] = {"format": str(model.output_format(name)), "max_abs_fixed_minus_float": float(np.max(diff)),
                        "rms_fixed_minus_float": float(np.sqrt(np.mean(diff[w] ** 2))),
                        "max_abs_fixed_minus_float_lsb": float(np.max(diff) / out_lsb),
                        "sqnr_db": sqnr_db(flt[name], fixed[name])}
    metrics = {
        "filter": config.filter,
        "variant": variant,
        "scenario": scenario,
        "samples": n,
        "seed": seed,
        "settle": settle,
        "startup_samples": startup,
        "field": main,
        "measured_input": measured,
        "rmse_raw": rmse(raw[w], truth[w]) if truth is not None and raw is not None else None,
        "rmse_float": rmse(flx1[w], truth[w]) if truth is not None else None,
        "rmse_fixed": rmse(fx1[w], truth[w]) if truth is not None else None,
        "rmse_fixed_over_float": None,
        "max_abs_fixed_minus_float_lsb": fields[main]["max_abs_fixed_minus_float_lsb"],
        "max_abs_fixed_minus_float": fields[main]["max_abs_fixed_minus_float"],
        "sqnr_db": fields[main]["sqnr_db"],
        "overflows": int(np.count_nonzero(res.overflow)),
        "overflow_sites": {name: int(np.count_nonzero(f)) for name, f in res.overflow_sites.items() if f.any()},
        "overflow_points": {name: int(np.count_nonzero(f)) for name, f in res.overflow_points.items()},
        "x1_format": str(model.output_format(main)),
        "fields": fields,
        "formats": {name: str(fmt) for name, fmt in config.formats.items()},
    }
    if truth is not None and metrics["rmse_float"] > 0:
        metrics["rmse_fixed_over_float"] = metrics["rmse_fixed"] / metrics["rmse_float"]
    if limit_cycle:
        lc = limit_cycles(config, variant)
        metrics.update(limit_cycle_lsb=lc["limit_cycle_lsb"], dead_band_lsb=lc["dead_band_lsb"], limit_cycle=lc)
    return Comparison(metrics, raw, truth, flx1, fx1, lsb, settle, main, fixed_all=dict(fixed),
                      float_all={name: flt[name] for name in fixed}, period=getattr(config.params, "T", None))


def limit_cycles(config, variant, *, samples=LIMIT_CYCLE_SAMPLES, window=LIMIT_CYCLE_WINDOW, floats=None):
    """Dead band and limit cycles of the fixed filter on noise-free inputs (:data:`LIMIT_CYCLE_INPUTS`).

    The input that observes the main output (or the first) gets the level, any other input 0.
    Over the last ``window`` samples, where the float filter has settled, the fixed main output
    minus the float one is measured in input LSBs (ADC codes): the **dead band** is the largest
    offset it keeps (its median, in magnitude), the **limit cycle** its peak-to-peak swing. A
    filter without either gives 0 and 0. ``fields`` gives each output's largest |fixed - float| in
    the window, in its own units (a rate stuck off zero shows there). ``floats``: a dict this
    function fills with the float runs the first time and reads after (they do not depend on the
    formats: a search passes one dict for all its candidates).
    """
    model = FixedModel(config, variant=variant)
    main = config.spec.model.default_output
    names = config.inputs
    driven = config.spec.measured_input(config.params) or names[0]
    k = np.arange(samples)
    w = slice(samples - window, None)
    levels = np.stack([np.where(k < at, before, after) for _, before, after, at in LIMIT_CYCLE_INPUTS]).astype(np.int64)
    codes = levels if len(names) == 1 else {n: levels if n == driven else np.zeros_like(levels) for n in names}
    fixed = model.to_float(model.run(codes))  # all inputs at once on the batched model
    per_input, dead, cycle = {}, 0.0, 0.0
    for i, (label, *_rest) in enumerate(LIMIT_CYCLE_INPUTS):
        y = levels[i] if len(names) == 1 else {n: c[i] for n, c in codes.items()}
        if floats is not None and (variant, label) in floats:
            flt = floats[(variant, label)]
        else:
            flt = float_run(config, variant, y)
            if floats is not None:
                floats[(variant, label)] = flt
        diff = fixed[main][i][w] - flt[main][w]
        entry = {"dead_band_lsb": float(abs(np.median(diff))), "limit_cycle_lsb": float(np.ptp(diff)),
                 "fields": {name: float(np.max(np.abs(fixed[name][i][w] - flt[name][w]))) for name in model.outputs}}
        per_input[label] = entry
        dead, cycle = max(dead, entry["dead_band_lsb"]), max(cycle, entry["limit_cycle_lsb"])
    return {"dead_band_lsb": dead, "limit_cycle_lsb": cycle, "inputs": per_input, "field": main,
            "samples": samples, "window": window}


def precision_warnings(config, budget=0.01):
    """Lines naming every output point whose rounding alone (uniform noise of rms step/sqrt(12))
    would add more than ``budget`` to the float filter's steady-state error of that output
    (``FilterSpec.error_std``), that is, whose rms rounding noise exceeds
    ``sqrt((1 + budget)**2 - 1)`` (14 % for 1 %) of that error."""
    spec = config.spec
    std = spec.model.error_std(config.params) if spec.model.error_std else None
    if not std:
        return []
    share = math.sqrt((1.0 + budget) ** 2 - 1.0)
    out = []
    for o in spec.outputs_for(config.params):
        fmt = config.formats.get(o.point) if isinstance(o.point, str) else None
        sigma = std.get(o.name)
        if fmt is None or not sigma or fmt.lsb / math.sqrt(12.0) <= share * sigma:
            continue
        out.append(f"formats.{o.point} = {fmt}: its rounding noise ({fmt.lsb:g}/sqrt(12) rms) is more than "
                   f"{100 * share:.3g} % of the float filter's own error of {o.name} ({sigma:.3g}), so it alone adds more "
                   f"than {100 * budget:g} % to that RMSE; give it more fraction bits")
    return out


def sweep_config(params, width, ranges):
    """Formats for a sweep point: operands ``width`` bits, registers ``width - 10`` fraction bits."""
    formats = default_formats(params, ranges=ranges, operand_bits=width, state_frac=max(width - 10, 0))
    return FilterConfig(params=params, formats=formats, check_ranges=False, max_word=max(width, MAX_WORD))


def sample_count(y):
    """The number of samples of ``y`` (an array, or ``{input: array}``)."""
    return len(next(iter(y.values()))) if isinstance(y, dict) else len(y)


def sweep(params, variant, y, truth, widths, *, settle=None, range_source="scenario", budget=0.01, progress=None):
    """Fixed-point error for each operand width: ``(rows, narrowest)``.

    ``range_source`` picks the float run the integer bits come from: the swept signal itself
    (``"scenario"``) or the full-scale stimulus (``"full-scale"``). Each row gives the formats
    every point actually got; it ``passes`` when the fixed RMSE is within ``budget`` of float's
    either way (a fixed filter far better than float is not the float filter either).
    ``narrowest`` is the narrowest width from which every wider one in ``widths`` passes.
    """
    ranges = analysed_ranges(params, y if range_source == "scenario" else None)
    rows = []
    iterator = progress(widths) if progress else widths
    for width in iterator:
        cfg = sweep_config(params, width, ranges)
        m = compare(cfg, variant, y, truth, settle=settle, limit_cycle=False).metrics
        ratio = m["rmse_fixed_over_float"]
        rows.append({
            "bits": width,
            "formats": m["formats"],
            "rmse_float": m["rmse_float"],
            "rmse_fixed": m["rmse_fixed"],
            "rmse_fixed_over_float": ratio,
            "passes": ratio is not None and abs(ratio - 1.0) <= budget and m["overflows"] == 0,
            "sqnr_db": m["sqnr_db"],
            "max_abs_fixed_minus_float": m["max_abs_fixed_minus_float"],
            "overflows": m["overflows"],
        })
    narrowest = None
    for r in sorted(rows, key=lambda r: -r["bits"]):
        if not r["passes"]:
            break
        narrowest = r["bits"]
    return rows, narrowest


def _rolling_rms(x, window):
    """The rms of ``x`` over a sliding ``window`` (centred; shorter at the ends)."""
    x = np.asarray(x, dtype=np.float64)
    if window <= 1 or len(x) <= window:
        return np.abs(x)
    c = np.concatenate([[0.0], np.cumsum(x * x)])
    k = np.arange(len(x))
    lo, hi = np.maximum(0, k - window // 2), np.minimum(len(x), k + window // 2 + 1)
    return np.sqrt((c[hi] - c[lo]) / (hi - lo))


def _envelope(x, bins):
    """``(centres, low, high)``: the smallest and largest of ``x`` in ``bins`` equal slices."""
    x = np.asarray(x, dtype=np.float64)
    edges = np.linspace(0, len(x), min(bins, len(x)) + 1).astype(int)
    lows = np.array([x[a:b].min() for a, b in itertools.pairwise(edges)])
    highs = np.array([x[a:b].max() for a, b in itertools.pairwise(edges)])
    return (edges[:-1] + edges[1:]) / 2, lows, highs


def _figures_text(m):
    lines = []
    if m.get("rmse_float") is not None:
        lines.append(f"RMSE of {m['field']} vs truth: float {m['rmse_float']:.4g}, fixed {m['rmse_fixed']:.4g} "
                     f"({100 * (m['rmse_fixed_over_float'] - 1):+.3f} %)")
    lines.append("SQNR fixed vs float: " + ", ".join(f"{name} {f['sqnr_db']:.1f} dB" for name, f in m["fields"].items()))
    lines.append(f"overflows: {m['overflows']} sample(s)")
    return "\n".join(lines)


def plot_compare(cmp_, path, title=""):
    """One figure of a comparison: the main output with truth and input (all samples and a zoom),
    its estimation error as a rolling RMS, every other output (float and fixed), and the fixed -
    float difference of the main output as an envelope and a histogram in LSB; the figures (RMSE,
    SQNR, overflows) written on it. The time axis is in seconds when the model has a period T."""
    plt = pyplot()
    n = len(cmp_.fixed_out)
    k = np.arange(n) * (cmp_.period or 1.0)
    unit = "time (s)" if cmp_.period else "sample"
    label = f"noisy input {cmp_.metrics.get('measured_input') or 'y'}"
    others = [name for name in cmp_.fixed_all if name != cmp_.output]
    rows = 4 + len(others)
    fig = plt.figure(figsize=(12, 3 * rows), constrained_layout=True)
    grid = fig.add_gridspec(rows, 4)
    ref = cmp_.truth if cmp_.truth is not None else cmp_.float_out
    centre = cmp_.settle + int(np.argmax(np.abs(ref[cmp_.settle:])))
    z0 = min(max(centre - 30, 0), max(n - 60, 0))
    z = slice(z0, min(z0 + 60, n))
    window = max(n // 200, 1)
    _overview(fig.add_subplot(grid[0, :]), cmp_, k, z, label, title)
    _zoom(fig.add_subplot(grid[1, :]), cmp_, k, z, label)
    _error(fig.add_subplot(grid[2, :]), cmp_, k, window)
    for row, name in enumerate(others, start=3):
        ax = fig.add_subplot(grid[row, :])
        ax.plot(k, cmp_.float_all[name], lw=0.8, color="tab:blue", label=f"float {name}")
        ax.plot(k, cmp_.fixed_all[name], lw=0.8, ls="--", color="tab:red", label=f"fixed {name}")
        ax.set_ylabel(name)
        ax.legend(loc="upper right", fontsize=8)
    _difference(fig.add_subplot(grid[rows - 1, :3]), fig.add_subplot(grid[rows - 1, 3]), cmp_, k, window, unit)
    for a in fig.axes[:-2]:
        a.set_xlabel(unit)
    save_figure(fig, path, dpi=100)


def _overview(ax, cmp_, k, z, label, title):
    """All samples: the input (``cmp_.y``, None when no input observes the plotted output
    itself), truth, the fixed output, the zoom's span and the figures."""
    if cmp_.y is not None:
        ax.plot(k, cmp_.y, lw=0.4, color="0.7", label=label)
    if cmp_.truth is not None:
        ax.plot(k, cmp_.truth, lw=1.0, color="k", label="truth")
    ax.plot(k, cmp_.fixed_out, lw=0.8, color="tab:red", label=f"fixed {cmp_.output}")
    ax.axvspan(k[z.start], k[z.stop - 1], color="tab:orange", alpha=0.2, label="zoom below")
    ax.set_ylabel(f"{cmp_.output} (input units)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title)
    ax.text(0.01, 0.97, _figures_text(cmp_.metrics), transform=ax.transAxes, va="top", fontsize=8,
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})


def _zoom(ax, cmp_, k, z, label):
    if cmp_.y is not None:
        ax.plot(k[z], cmp_.y[z], ".", ms=5, color="0.55", label=label)
    if cmp_.truth is not None:
        ax.plot(k[z], cmp_.truth[z], lw=1.4, color="k", label="truth")
    ax.plot(k[z], cmp_.float_out[z], lw=1.0, color="tab:blue", label=f"float {cmp_.output}")
    ax.plot(k[z], cmp_.fixed_out[z], lw=1.0, ls="--", color="tab:red", label=f"fixed {cmp_.output}")
    ax.set_ylabel(f"{cmp_.output} (zoom)")
    ax.legend(loc="upper right", fontsize=8)


def _error(ax, cmp_, k, window):
    """The estimation error against truth as a rolling RMS (input, float, fixed)."""
    if cmp_.truth is None:
        ax.text(0.5, 0.5, "no truth in the input", ha="center", transform=ax.transAxes)
        return
    n = len(cmp_.fixed_out)
    if cmp_.y is not None:
        ax.plot(k, _rolling_rms(cmp_.y - cmp_.truth, window), lw=0.8, color="0.6", label="input - truth")
    ax.plot(k, _rolling_rms(cmp_.float_out - cmp_.truth, window), lw=0.9, color="tab:blue", label="float - truth")
    ax.plot(k, _rolling_rms(cmp_.fixed_out - cmp_.truth, window), lw=0.9, ls="--", color="tab:red",
            label="fixed - truth")
    ax.axvline(k[min(cmp_.settle, n - 1)], color="0.4", ls=":", lw=0.8, label="end of settling")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel(f"error, rolling rms\n({window} samples)")


def _difference(ax, hist, cmp_, k, window, unit):
    """Fixed - float of the main output in LSB: an envelope and a rolling RMS, and a histogram."""
    diff = (cmp_.fixed_out - cmp_.float_out) / cmp_.lsb
    centres, lows, highs = _envelope(diff, 400)
    ax.fill_between(centres * (cmp_.period or 1.0), lows, highs, color="tab:purple", alpha=0.4, lw=0, label="range")
    ax.plot(k, _rolling_rms(diff, window), lw=0.8, color="tab:purple", label="rolling rms")
    ax.set_ylabel(f"fixed - float of {cmp_.output}\n(LSB = {cmp_.lsb:g})")
    ax.set_xlabel(unit)
    ax.legend(loc="upper right", fontsize=8)
    hist.hist(diff[cmp_.settle:], bins=60, color="tab:purple", alpha=0.7)
    hist.set_xlabel("fixed - float (LSB)")
    hist.set_ylabel("samples")


def plot_sweep(rows, narrowest, path, title="", budget=0.01):
    """RMSE and SQNR against operand width: the budget band, the narrowest passing width and the
    width of one embedded multiplier marked."""
    from kfpga.core.formats import MULTIPLIER_BITS

    plt = pyplot()
    bits = [r["bits"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True, constrained_layout=True)
    flt = np.array([r["rmse_float"] for r in rows])
    ax1.plot(bits, [r["rmse_fixed"] for r in rows], "o-", color="tab:red", label="fixed")
    ax1.plot(bits, flt, "-", color="tab:blue", label="float")
    ax1.fill_between(bits, (1 - budget) * flt, (1 + budget) * flt, color="tab:blue", alpha=0.15,
                     label=f"float ± {100 * budget:g} %")
    for ax in (ax1, ax2):
        if bits[0] <= MULTIPLIER_BITS <= bits[-1]:
            ax.axvline(MULTIPLIER_BITS, color="0.3", ls=":", lw=1.0,
                       label=f"{MULTIPLIER_BITS} bits: one embedded multiplier per product" if ax is ax1 else None)
        if narrowest is not None:
            ax.axvline(narrowest, color="tab:green", ls="--",
                       label=f"narrowest within {100 * budget:g} % from there up: {narrowest} bits" if ax is ax1 else None)
    ax1.set_ylabel("RMSE vs truth (codes)")
    ax1.legend(fontsize=8)
    ax1.set_title(title, fontsize=9)
    ax2.plot(bits, [r["sqnr_db"] for r in rows], "o-", color="tab:purple")
    ax2.set_ylabel("SQNR fixed vs float (dB)")
    ax2.set_xlabel("multiplier operand width (bits)")
    save_figure(fig, path, dpi=110)
