"""``kfpga propose``: per-point word lengths searched against stated constraints, over many seeds
and every variant at once."""

from __future__ import annotations

import numpy as np

from kfpga.cli import loading, options, output
from kfpga.core import registry
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("propose", help="search per-point word lengths for a model under stated constraints",
                       description="Search the format of every quantisation point: integer bits from the analysed "
                                   "ranges, fraction bits trimmed (or first grown) point by point, so that on every "
                                   "seed (or file) the fixed RMSE of the main output stays within --budget of "
                                   "float's (the search keeps a quarter of it as the margin for other seeds), "
                                   "nothing overflows on full-scale stress, no limit cycle or dead band exceeds one "
                                   "input LSB and every constant is held within 1 %, for every variant at once. "
                                   "Formats the config pins are kept. --objective multipliers first keeps "
                                   "multiplier operands within 18 bits, then trims register bits; bits trims the "
                                   "widest points first. Prints a table; --out writes a commented config.",
                       epilog="example: kfpga propose --config my.toml --seeds 10 --out proposed.toml")
    options.add_signal_args(p, files=True)
    p.add_argument("--seeds", type=options.positive_int, default=10, metavar="N",
                   help="scenario seeds searched at once, from --seed on (default: 10)")
    p.add_argument("--budget", type=options.budget, default=0.01, metavar="PCT",
                   help="how far the fixed RMSE may be from float's, either way (default: 1%%)")
    p.add_argument("--objective", choices=("multipliers", "bits"), default="multipliers",
                   help="what to save first (default: multipliers)")
    p.add_argument("--out", metavar="TOML", help="write the proposal as a config file")
    options.add_json(p, "print the proposal as JSON")
    options.add_quiet(p)
    p.set_defaults(func=run, all_variants=True)


def _progress(quiet):
    """A callback that shows what is being tried; its ``tick`` counts the candidates."""
    bar = None if quiet else output.progress_bar(desc="propose", unit="candidate")

    def step(text):
        if bar is not None:
            bar.set_postfix_str(text[:60])

    step.tick = (lambda: bar.update(1)) if bar is not None else (lambda: None)
    step.close = (lambda: bar.close()) if bar is not None else (lambda: None)
    return step


def _stack(rows):
    """Rows of codes (arrays, or ``{input: array}``) as one batch."""
    if isinstance(rows[0], dict):
        return {k: np.stack([r[k] for r in rows]) for k in rows[0]}
    return np.stack(rows)


def _files(args, config):
    from kfpga.core.csvio import read_samples
    from kfpga.flows.propose import Signal

    signals = []
    for path in args.input:
        samples = read_samples(path, clip=args.clip, columns=config.inputs, bits=config.input_format.width)
        if samples.truth is None:
            raise UsageError(f"propose needs a truth to measure RMSE: {path} has no 'truth' column")
        n = min(args.samples or len(samples), len(samples))
        y = samples.y
        y = {k: v[:n] for k, v in y.items()} if isinstance(y, dict) else y[:n]
        signals.append(Signal(samples.truth[None, :n], _stack([y]), [path]))
    return signals, [f"{len(args.input)} file(s): {', '.join(args.input)}"]


def _scenario(args, config):
    from kfpga.flows.propose import Signal
    from kfpga.model import scenarios

    n = loading.check_samples(args.samples or 20000, runs=args.seeds)
    first = output.pick_seed(args.seed)
    seeds = list(range(first, first + args.seeds))
    runs = [scenarios.for_config(args.scenario, n, s, config) for s in seeds]
    for _, y in runs:
        scenarios.check_rails(args.scenario, y)
    output.info(f"seeds {seeds[0]}..{seeds[-1]} (replay with --seed {first} --seeds {args.seeds})")
    signal = Signal(np.stack([t for t, _ in runs]), _stack([y for _, y in runs]), [f"seed {s}" for s in seeds])
    return [signal], [f"scenario {args.scenario}, {n} samples, seeds {seeds[0]}..{seeds[-1]}"]


def _variants(args, config):
    """The variants asked for: ``--variant``, else every variant that applies to the model."""
    if args.variant is not None:
        config.require_variant(args.variant)
        return [args.variant]
    return [name for name, v in config.spec.model.variants.items() if v.applies(config.params) is None]


def run(args):
    from kfpga.core.config import analysed_ranges
    from kfpga.core.paths import check_output_file, write_text
    from kfpga.flows.propose import proposal_toml, propose

    loading.check_signal_args(args)
    inputs = ([args.config] if args.config else []) + (args.input or [])
    out = str(check_output_file(args.out, option="--out", inputs=inputs, extensions=(".toml",))) if args.out else None
    variant = args.variant
    args.variant = None
    config = loading.load_config(args)  # every variant is checked below
    args.variant = variant
    loading.require_word_lengths(config, "propose")
    variants = _variants(args, config)
    if args.settle is not None and args.settle < 0:
        raise UsageError(f"--settle must be >= 0, not {args.settle}")
    signals, described = _files(args, config) if args.input else _scenario(args, config)
    step = _progress(args.quiet)
    result = propose(config, variants, signals, budget=args.budget, objective=args.objective, settle=args.settle,
                     progress=step)
    step.close()
    ranges = analysed_ranges(config.params, filter=config.filter)
    if out:
        write_text(out, proposal_toml(result, ranges, budget=args.budget, objective=args.objective,
                                      seconds=result.seconds, signals=described))
    rows = [{"point": name, "default": str(config.formats[name]), "proposed": str(fmt),
             "analysed_max": ranges.get(name), "bound_by": result.bound.get(name)}
            for name, fmt in result.config.formats.items()]
    summary = {"filter": config.filter, "variants": list(variants), "signals": described,
               "seeds": [label for s in signals for label in s.labels] if not args.input else None,
               "budget": args.budget, "objective": args.objective, "points": rows,
               "multipliers": {"default": result.multipliers[0], "proposed": result.multipliers[1]},
               "register_bits": {"default": result.register_bits[0], "proposed": result.register_bits[1]},
               "check": result.metrics, "margin": result.metrics["margin"], "candidates": result.evaluations,
               "seconds": result.seconds, "notes": result.notes, "out": out}
    if args.json:
        output.emit_json(summary)
        return 0
    _print(config, args, variants, described, rows, result, out)
    return 0


def _print(config, args, variants, described, rows, result, out):
    print(f"kfpga propose: {config.filter} filter, {', '.join(variants)} variant(s), {'; '.join(described)}; "
          f"budget {100 * args.budget:g} %, objective {args.objective}")
    print(f"  {'point':<6} {'default':>8} {'proposed':>8}  bound by")
    for r in rows:
        print(f"  {r['point']:<6} {r['default']:>8} {r['proposed']:>8}  {r['bound_by']}")
    m = result.metrics
    print(f"  multiplier pieces {result.multipliers[0]} -> {result.multipliers[1]}, register bits "
          f"{result.register_bits[0]} -> {result.register_bits[1]}")
    print(f"  check: worst RMSE change {100 * m['worst_rmse_change']:.3f} % of float over every seed and variant, "
          f"margin {100 * m['margin']:.3f} % of the budget; limit cycle {m['limit_cycle_lsb']:.3g} LSB, dead band "
          f"{m['dead_band_lsb']:.3g} LSB, no overflow on full-scale stress")
    for note in result.notes:
        print(f"  note: {note}")
    print(f"  {result.evaluations} candidates in {result.seconds:.1f} s" + (f"; wrote {out}" if out else
                                                                            "; --out FILE writes it as a config"))


#: The examples ending ``kfpga propose --help``.
def EXAMPLES():
    return ("kfpga propose --config tracker.toml --out tracker-proposed.toml",
            f"kfpga propose --filter {registry.example()} --objective bits --json")
