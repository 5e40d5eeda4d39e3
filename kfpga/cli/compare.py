"""``kfpga compare``: float against bit-accurate fixed point on one signal."""

from __future__ import annotations

import numpy as np

from kfpga.cli import loading, options, output
from kfpga.core.errors import UsageError

#: Full-scale ADC glitches ``compare --prefilter`` puts into a scenario's codes: this share of the samples.
GLITCH_DENSITY = 0.005


def add_parser(sub):
    p = sub.add_parser("compare", help="float vs bit-accurate fixed point on one signal: RMSE, SQNR, overflows",
                       description="Run the float and the bit-accurate fixed-point filter on the same ADC codes and "
                                   "report RMSE against truth of the raw input, the float and the fixed estimate, "
                                   "the largest fixed - float difference in LSBs of each output, the SQNR of fixed "
                                   "vs float and the number of samples that overflowed.")
    options.add_signal_args(p)
    options.add_json(p)
    p.add_argument("--plot", metavar="PNG", help="draw truth, input, both estimates and the fixed - float error")
    options.add_prefilter_args(p)
    p.set_defaults(func=run)


def run(args):
    from kfpga.flows.analysis import compare, plot_compare, sample_count

    loading.check_signal_args(args)
    args.plot = options.check_plot(args.plot)
    config = loading.load_config(args)
    pre = options.prefilter(args)
    if pre is not None:
        if len(config.inputs) != 1:
            raise UsageError(f"--prefilter: compare takes a one-input filter here; {config.filter} has "
                             f"{len(config.inputs)} inputs")
        if args.plot:
            raise UsageError("--plot does not apply with --prefilter (the table has the two runs)")
    truth, y, label = loading.samples_for(args, config, command="compare")
    loading.warn_precision(config)
    if pre is not None:
        return _with_prefilter(args, config, pre, truth, y, label)
    result = compare(config, args.variant, y, truth, settle=args.settle, seed=args.seed if not args.input else None,
                     scenario=None if args.input else args.scenario)
    m = result.metrics
    if args.plot:
        plot_compare(result, args.plot, title=f"kfpga compare: {args.variant} variant, {label}, {sample_count(y)} samples")
        m["plot"] = args.plot
    if args.json:
        output.emit_json(m)
        return 0
    _print(config, args, label, m)
    return 0


def _print(config, args, label, m):
    field = m["field"]
    print(f"kfpga compare: {config.filter} filter, {args.variant} variant, {label}, {m['samples']} samples"
          + (f", seed {m['seed']}" if m["seed"] is not None else ""))
    if m["rmse_float"] is not None:
        startup = m["startup_samples"]
        print("  start-up                   " + (f"{startup} samples (the float error's rolling RMS within 1.5x its "
                                                 "final RMS)" if startup is not None else
                                                 "not over in the first half of the run"))
        print(f"  RMSE of {field} vs truth (after {m['settle']} settling samples):")
        if m["rmse_raw"] is not None:
            print(f"    raw input    {m['rmse_raw']:10.4f} codes  ({m['measured_input']})")
        print(f"    float model  {m['rmse_float']:10.4f} codes")
        print(f"    fixed model  {m['rmse_fixed']:10.4f} codes  ({100 * (m['rmse_fixed_over_float'] - 1):+.3f} % vs float)")
    print("  fixed vs float             max |fixed - float|            SQNR")
    for name, fm in m["fields"].items():
        print(f"    {name:<8} {fm['format']:>8}   {fm['max_abs_fixed_minus_float_lsb']:8.1f} LSB "
              f"({fm['max_abs_fixed_minus_float']:.4g})   {fm['sqnr_db']:6.1f} dB")
    where = ", ".join(f"{k} {v}" for k, v in m["overflow_points"].items() if v)
    print(f"  overflows                  {m['overflows']} sample(s)" + (f" (at {where})" if where else ""))
    lc = m["limit_cycle"]
    print(f"  noise-free inputs          dead band {lc['dead_band_lsb']:.3g} LSB, limit cycle {lc['limit_cycle_lsb']:.3g} LSB "
          f"peak to peak ({field} - float over the last {lc['window']} of {lc['samples']} samples; input LSB = 1 code)")
    if args.plot:
        print(f"  plot: {args.plot}")


def _with_prefilter(args, config, pre, truth, y, label):
    """``compare --prefilter NAME``: the filter with and without the pre-filter on a glitchy signal."""
    from kfpga.core.codes import CODE_MAX, CODE_MIN
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.flows.analysis import compare, sample_count

    delay = pre.spec.hardware.prefilter.delay
    y = np.array(y, dtype=np.int64)
    glitches = 0
    if not args.input:  # a scenario: full-scale glitches at random samples, from the run's seed
        rng = np.random.default_rng([args.seed, 2])
        where = np.flatnonzero(rng.random(len(y)) < GLITCH_DENSITY)
        y[where] = rng.choice([CODE_MIN, CODE_MAX], len(where))
        glitches = len(where)
    smoothed = FixedModel(pre).run(y).outputs[pre.spec.model.default_output]
    late = None if truth is None else np.concatenate([np.repeat(truth[:1], delay), truth[:-delay]])
    runs = {}
    for key, codes, t in (("without", y, truth), ("with", smoothed, late)):
        m = compare(config, args.variant, codes, t, settle=args.settle, seed=None, scenario=None, limit_cycle=False).metrics
        runs[key] = {k: m.get(k) for k in ("rmse_raw", "rmse_float", "rmse_fixed", "overflows", "settle", "field")}
    replaced = int(np.sum(smoothed[delay:] != y[:-delay]))
    m = {"filter": config.filter, "variant": args.variant, "samples": sample_count(y), "seed": None if args.input else args.seed,
         "signal": label, "glitches": glitches if not args.input else None, "prefilter": pre.filter,
         "prefilter_params": {k: getattr(pre.params, k) for k in pre.params.__dataclass_fields__},
         "replaced": replaced, "without_prefilter": runs["without"], "with_prefilter": runs["with"]}
    if args.json:
        output.emit_json(m)
        return 0
    field = runs["with"]["field"]
    print(f"kfpga compare: {config.filter} filter, {args.variant} variant, {label}, {m['samples']} samples"
          + (f", seed {m['seed']}" if m["seed"] is not None else "")
          + (f", {glitches} full-scale glitches ({100 * GLITCH_DENSITY:g} % of the samples)" if not args.input else ""))
    print(f"  {pre.filter} pre-filter: {loading.describe_params(pre.params)}, {replaced} sample(s) replaced, each sample "
          f"{delay} late")
    if runs["with"]["rmse_float"] is None:
        print("  no truth for this signal: no RMSE (a CSV replay); the replaced count is above")
        return 0
    print(f"  RMSE of {field} vs truth (after {runs['with']['settle']} settling samples), codes:")
    print(f"    {'':<26}{'its input':>11}{'float':>11}{'fixed':>11}{'overflows':>11}")
    for key, text in (("without", "without the pre-filter"), ("with", f"with the {pre.filter} pre-filter")):
        r = runs[key]
        raw = "-" if r["rmse_raw"] is None else f"{r['rmse_raw']:.4f}"
        print(f"    {text:<26}{raw:>11}{r['rmse_float']:>11.4f}{r['rmse_fixed']:>11.4f}{r['overflows']:>11}")
    return 0


#: The examples ending ``kfpga compare --help``.
EXAMPLES = (
    "kfpga compare --seed 1 --plot build/compare.png        # the paper's filter, fixed against float",
    'kfpga compare --config tracker.toml --json               # your model at its own sample period',
)
