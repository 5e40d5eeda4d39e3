"""The ``kfpga`` command line."""

from __future__ import annotations

import argparse
import json
import math
import secrets
import sys
from pathlib import Path

import numpy as np

from kfpga import __version__

EXIT_USAGE = 2


class UsageError(ValueError):
    """A bad argument or input; reported in one line, exit code 2."""


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, not {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, not {text!r}")
    return value


def _seed(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, not {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, not {text!r}")
    return value


def _bit_range(text):
    try:
        lo, hi = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must look like 10:24, not {text!r}") from None
    if not 4 <= lo <= hi <= 32:
        raise argparse.ArgumentTypeError(f"needs 4 <= first <= last <= 32, not {text!r}")
    return list(range(lo, hi + 1))


def _load_config(path):
    from kfpga.config import KalmanConfig

    return KalmanConfig() if path is None else KalmanConfig.from_toml(path)


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


def _ensure_parent(path):
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)


def _info(text):
    print(text, file=sys.stderr)


def _samples_for(args, params):
    """``(truth, y, label)`` from ``--input`` or the chosen scenario (printing the seed)."""
    from kfpga import scenarios
    from kfpga.csvio import read_samples

    if args.input:
        samples = read_samples(args.input, clip=args.clip)
        if samples.clipped:
            _info(f"{args.input}: {samples.clipped} value(s) outside the 16-bit range saturated (--clip)")
        y, truth = samples.y, samples.truth
        if args.samples:
            y = y[: args.samples]
            truth = truth[: args.samples] if truth is not None else None
        if truth is None:
            _info(f"{args.input}: no 'truth' column, so RMSE against truth is not reported")
        return truth, y, f"input {args.input}"
    args.seed = _pick_seed(args.seed)
    _info(f"seed {args.seed} (replay with --seed {args.seed})")
    truth, y = scenarios.make(args.scenario, args.samples or 20000, args.seed, params)
    return truth, y, f"scenario {args.scenario}"


# -- compare ---------------------------------------------------------------------------------


def _add_signal_args(p):
    p.add_argument("--variant", choices=("steady", "full"), default="steady",
                   help="steady: constant gain K_inf (alpha-beta); full: time-varying gain with divider (default: steady)")
    p.add_argument("--scenario", choices=("sine", "random-accel"), default="sine",
                   help="test signal when --input is not given: the paper's sine plus white noise of variance R, "
                        "or a random-acceleration track (default: sine)")
    p.add_argument("--input", metavar="CSV", help="use the 'y' column of CSV (and 'truth' if present) instead of a scenario")
    p.add_argument("--clip", action="store_true", help="saturate input values outside the 16-bit range instead of failing")
    p.add_argument("--samples", type=_positive_int, metavar="N", help="number of samples (default: 20000, or the whole --input)")
    p.add_argument("--seed", type=_seed, metavar="S", help="noise seed (default: random, printed)")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats (default: built-in, see 'kfpga formats')")
    p.add_argument("--settle", type=int, metavar="N", help="samples skipped by the RMSE figures (default: 100)")


def _run_compare(args):
    from kfpga.analysis import compare, plot_compare

    config = _load_config(args.config)
    config.require_variant(args.variant)
    truth, y, label = _samples_for(args, config.params)
    if args.settle is not None and not 0 <= args.settle < len(y):
        raise UsageError(f"--settle must be between 0 and {len(y) - 1}, not {args.settle}")
    result = compare(config, args.variant, y, truth, settle=args.settle, seed=args.seed if not args.input else None,
                     scenario=None if args.input else args.scenario)
    m = result.metrics
    if args.plot:
        _ensure_parent(args.plot)
        plot_compare(result, args.plot, title=f"kfpga compare: {args.variant} variant, {label}, {len(y)} samples")
        m["plot"] = args.plot
    if args.json:
        _emit_json(m)
        return 0
    fmt = config.formats["x1"]
    print(f"kfpga compare: {args.variant} variant, {label}, {m['samples']} samples"
          + (f", seed {m['seed']}" if m["seed"] is not None else ""))
    if m["rmse_raw"] is not None:
        print(f"  RMSE vs truth (after {m['settle']} settling samples):")
        print(f"    raw input    {m['rmse_raw']:10.4f} codes")
        print(f"    float model  {m['rmse_float']:10.4f} codes")
        print(f"    fixed model  {m['rmse_fixed']:10.4f} codes  ({100 * (m['rmse_fixed_over_float'] - 1):+.3f} % vs float)")
    print(f"  max |fixed - float| of x1  {m['max_abs_fixed_minus_float_lsb']:.1f} LSB "
          f"({m['max_abs_fixed_minus_float']:.4g} codes; x1 is {fmt}, LSB {fmt.lsb:g})")
    print(f"  SQNR fixed vs float        {m['sqnr_db']:.1f} dB")
    print(f"  overflows                  {m['overflows']} sample(s)")
    if args.plot:
        print(f"  plot: {args.plot}")
    return 0


# -- sweep -----------------------------------------------------------------------------------


def _run_sweep(args):
    from tqdm import tqdm

    from kfpga.analysis import plot_sweep, sweep

    config = _load_config(args.config)
    config.require_variant(args.variant)
    truth, y, label = _samples_for(args, config.params)
    if truth is None:
        raise UsageError("sweep needs a truth to measure RMSE: use a scenario or an --input with a 'truth' column")
    rows, narrowest = sweep(
        config.params, args.variant, y, truth, args.bits, settle=args.settle, range_source=args.ranges,
        progress=lambda it: tqdm(it, desc="sweep", unit="width", file=sys.stderr, disable=args.quiet),
    )
    plot = args.plot or f"build/sweep_{args.variant}.png"
    _ensure_parent(plot)
    plot_sweep(rows, narrowest, plot, title=f"kfpga sweep: {args.variant} variant, {label}, {len(y)} samples")
    if args.json:
        _emit_json({"variant": args.variant, "samples": len(y), "seed": args.seed, "ranges": args.ranges,
                    "narrowest_within_1pct": narrowest, "rows": rows, "plot": plot})
        return 0
    print(f"kfpga sweep: {args.variant} variant, {label}, {len(y)} samples; integer bits from the {args.ranges} range")
    print(f"{'bits':>4}  {'x1':>7}  {'e':>7}  {'RMSE fixed':>10}  {'vs float':>9}  {'SQNR dB':>8}  {'overflows':>9}")
    for r in rows:
        mark = " *" if r["bits"] == narrowest else ""
        print(f"{r['bits']:>4}  {r['x1_format']:>7}  {r['e_format']:>7}  {r['rmse_fixed']:10.4f}  "
              f"{100 * (r['rmse_fixed_over_float'] - 1):+8.3f}%  {r['sqnr_db']:8.1f}  {r['overflows']:>9}{mark}")
    print(f"float RMSE {rows[0]['rmse_float']:.4f}; "
          + (f"* narrowest width within 1 % of float from there up: {narrowest} bits" if narrowest
             else "no width in the range is within 1 % of float"))
    print(f"plot: {plot}")
    return 0


# -- filter ----------------------------------------------------------------------------------


def _run_filter(args):
    from kfpga.analysis import float_run
    from kfpga.csvio import read_samples, write_columns
    from kfpga.model.kalman import FixedKalman

    config = _load_config(args.config)
    config.require_variant(args.variant)
    samples = read_samples(args.input, clip=args.clip)
    if args.float:
        x1, x2, yhat = float_run(config, args.variant, samples.y)
        columns = {"x1": x1, "x2": x2, "yhat": yhat}
    else:
        model = FixedKalman(config, variant=args.variant)
        res = model.run(samples.y)
        x1, x2, yhat = model.to_float(res)
        columns = {"x1": x1, "x2": x2, "yhat": yhat, "overflow": res.overflow}
    write_columns(args.output, columns)
    kind = "float64" if args.float else "bit-accurate fixed-point"
    note = [f"{len(samples.y)} samples filtered ({args.variant} variant, {kind}) -> {args.output}"]
    if samples.clipped:
        note.append(f"{samples.clipped} input value(s) saturated to the 16-bit range (--clip)")
    if not args.float:
        note.append(f"{int(np.count_nonzero(columns['overflow']))} sample(s) with overflow")
    _info("; ".join(note))
    return 0


# -- formats ---------------------------------------------------------------------------------


def formats_table(config):
    """Rows describing each quantisation point (README and ``kfpga formats``)."""
    from kfpga.config import POINTS

    ranges = config.ranges()
    rows = []
    for name, fmt in config.formats.items():
        point = POINTS[name]
        if name == "inv_t" and config.t_shift is not None:
            continue
        rows.append({
            "point": name,
            "format": str(fmt),
            "bits": fmt.width,
            "covers": f"±{fmt.max_value:.6g}",
            "analysed_max": ranges.get(name),
            "lsb": fmt.lsb,
            "rounding": fmt.rounding.value,
            "overflow": fmt.overflow.value,
            "variants": ",".join(point.variants),
            "multiplier_operand": point.operand,
            "description": point.description,
        })
    return rows


def _run_formats(args):
    config = _load_config(args.config)
    if args.toml:
        print(config.to_toml(), end="")
        return 0
    rows = formats_table(config)
    if args.json:
        _emit_json(rows)
        return 0
    print(f"{'point':<6} {'format':<7} {'bits':>4} {'covers':>12} {'analysed max':>13} {'rounding':<8} {'overflow':<9} description")
    for r in rows:
        amax = f"{r['analysed_max']:.6g}" if r["analysed_max"] is not None else "-"
        op = " [multiplier operand]" if r["multiplier_operand"] else ""
        print(f"{r['point']:<6} {r['format']:<7} {r['bits']:>4} {r['covers']:>12} {amax:>13} {r['rounding']:<8} "
              f"{r['overflow']:<9} {r['description']}{op}")
    return 0


# -- generate --------------------------------------------------------------------------------


def _adc_channel(text):
    from kfpga.ads8364 import CHANNELS

    if text.upper() in CHANNELS:
        return CHANNELS.index(text.upper())
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 5:
        raise argparse.ArgumentTypeError(f"must be 0..5 or one of {', '.join(CHANNELS)}, not {text!r}")
    return value


def _run_generate(args):
    from kfpga.hw.generate import TOP_NAME, write_top
    from kfpga.tools import iverilog_parse, iverilog_path, verilator_lint

    config = _load_config(args.config)
    config.require_variant(args.variant)
    if args.ratio < 2:
        raise UsageError(f"--ratio must be >= 2, not {args.ratio}")
    path, _ = write_top(args.out, config, variant=args.variant, six_channel=args.channels == 6,
                        channel=args.channel, ratio=args.ratio)
    print(f"wrote {path} ({args.variant} core, {args.channels} channel(s), x1 {config.formats['x1']} on out_data)")
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


# -- main ------------------------------------------------------------------------------------


def build_parser():
    parser = argparse.ArgumentParser(
        prog="kfpga",
        description="Kalman filter for the Cyclone II: bit-accurate fixed-point model, Verilog and Quartus "
                    "project generation, co-simulation.",
        epilog="Run 'kfpga COMMAND --help' for the options of a command.",
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
    p.set_defaults(func=_run_compare)

    p = sub.add_parser("sweep", help="fixed-point error against word length, as a table and a PNG",
                       description="Rerun the comparison with every multiplier operand N bits wide (and N-10 fraction "
                                   "bits in the state registers) for each N in --bits, and mark the narrowest width "
                                   "from which the fixed RMSE stays within 1 %% of float.")
    _add_signal_args(p)
    p.add_argument("--bits", type=_bit_range, default=list(range(10, 25)), metavar="A:B",
                   help="operand widths to try, inclusive (default: 10:24)")
    p.add_argument("--ranges", choices=("scenario", "full-scale"), default="scenario",
                   help="where integer bits come from: the swept signal's own float run, or the full 16-bit "
                        "input range (default: scenario)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p.add_argument("--plot", metavar="PNG", help="where to draw the sweep (default: build/sweep_VARIANT.png)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run_sweep)

    p = sub.add_parser("filter", help="run a CSV of samples through the bit-accurate (or float) filter",
                       description="Read the 'y' column of a CSV file (signed 16-bit ADC codes, one row per sample) "
                                   "and write x1, x2, yhat (and the per-sample overflow flag for fixed point) in "
                                   "input units, one row per input row.")
    p.add_argument("--input", required=True, metavar="CSV", help="input file with a column named y")
    p.add_argument("--output", required=True, metavar="CSV", help="output file")
    p.add_argument("--variant", choices=("steady", "full"), default="steady", help="filter variant (default: steady)")
    p.add_argument("--float", action="store_true", help="use the float64 reference instead of the bit-accurate model")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    p.add_argument("--clip", action="store_true", help="saturate out-of-range inputs instead of failing")
    p.set_defaults(func=_run_filter)

    p = sub.add_parser("formats", help="show the quantisation formats (or write a config file to edit)",
                       description="Show every quantisation point with its format, the range it covers and the "
                                   "range the float analysis found; --toml prints a complete config file.")
    p.add_argument("--config", metavar="TOML", help="config to show (default: the built-in defaults)")
    p.add_argument("--toml", action="store_true", help="print the config as TOML")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.set_defaults(func=_run_formats)

    p = sub.add_parser("generate", help="write the Verilog of the whole design (and the Quartus project)",
                       description="Write plain Verilog-2001 of the top level (clock divider, ADS8364 controller, "
                                   "Kalman core, output port) into DIR, with the Verilator lint waivers.")
    p.add_argument("--variant", choices=("steady", "full"), default="steady", help="Kalman core (default: steady)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    p.add_argument("--channels", type=int, choices=(1, 6), default=1,
                   help="1: filter one ADC channel; 6: sample all six with one HOLD and filter each (default: 1)")
    p.add_argument("--channel", type=_adc_channel, default=0, metavar="CH",
                   help="the channel of --channels 1: 0..5 or A0, A1, B0, B1, C0, C1 (default: A0)")
    p.add_argument("--ratio", type=int, default=10, metavar="N", help="system clock / ADC clock (default: 10)")
    p.add_argument("--no-lint", action="store_true", help="skip the Verilator lint and Icarus parse checks")
    p.set_defaults(func=_run_generate)
    return parser


def main(argv=None):
    from kfpga.config import ConfigError
    from kfpga.csvio import InputError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ConfigError, InputError, UsageError) as exc:
        print(f"kfpga {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"kfpga {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
