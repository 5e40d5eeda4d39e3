"""``kfpga propose``: per-point word lengths searched against stated constraints."""

from __future__ import annotations

import sys
from pathlib import Path

from kfpga.cli import common
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("propose", help="search per-point word lengths for a model under stated constraints",
                       description="Search the format of every quantisation point: integer bits from the analysed "
                                   "ranges, fraction bits trimmed (or first grown) point by point, so that the fixed "
                                   "RMSE of the main output stays within --budget of float's on the signal, nothing "
                                   "overflows on full-scale stress, no limit cycle or dead band exceeds one input LSB "
                                   "and every constant is held within 1 %. --objective multipliers first keeps "
                                   "multiplier operands within 18 bits, then trims register bits; bits trims the "
                                   "widest points first. Prints a table; --out writes a commented config.")
    common.add_signal_args(p)
    p.add_argument("--budget", type=common.budget, default=0.01, metavar="PCT",
                   help="how far the fixed RMSE may be from float's, either way (default: 1%%)")
    p.add_argument("--objective", choices=("multipliers", "bits"), default="multipliers",
                   help="what to save first (default: multipliers)")
    p.add_argument("--out", metavar="TOML", help="write the proposal as a config file")
    common.add_json(p, "print the proposal as JSON")
    common.add_quiet(p)
    p.set_defaults(func=run)


def _progress(quiet):
    """A callback that shows what is being tried; its ``tick`` counts the candidates."""
    bar = None
    if not quiet:
        from tqdm import tqdm

        bar = tqdm(desc="propose", unit="candidate", file=sys.stderr)

    def step(text):
        if bar is not None:
            bar.set_postfix_str(text[:60])

    step.tick = (lambda: bar.update(1)) if bar is not None else (lambda: None)
    step.close = (lambda: bar.close()) if bar is not None else (lambda: None)
    return step


def run(args):
    from kfpga.core.config import analysed_ranges
    from kfpga.core.paths import check_output_file
    from kfpga.flows.analysis import sample_count
    from kfpga.flows.propose import proposal_toml, propose

    common.check_signal_args(args)
    inputs = [args.config] if args.config else []
    inputs += [args.input] if args.input else []
    out = str(check_output_file(args.out, option="--out", inputs=inputs, extensions=(".toml",))) if args.out else None
    config = common.load_config(args)
    common.require_word_lengths(config, "propose")
    if config.pinned:
        raise UsageError(f"propose chooses every format itself, so the formats {args.config} pins would be ignored "
                         f"({', '.join(config.pinned)}): remove its [formats] tables")
    truth, y, label = common.samples_for(args, config, command="propose", need_truth=True)
    step = _progress(args.quiet)
    result = propose(config, args.variant, {label: (truth, y)}, budget=args.budget, objective=args.objective,
                     settle=args.settle, progress=step)
    step.close()
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
        common.emit_json(summary)
        return 0
    _print(config, args, label, sample_count(y), rows, result, out)
    return 0


def _print(config, args, label, count, rows, result, out):
    print(f"kfpga propose: {config.filter} filter, {args.variant} variant, {label}, {count} samples; "
          f"budget {100 * args.budget:g} %, objective {args.objective}")
    print(f"  {'point':<6} {'default':>8} {'proposed':>8}  bound by")
    for r in rows:
        print(f"  {r['point']:<6} {r['default']:>8} {r['proposed']:>8}  {r['bound_by']}")
    m = result.metrics
    ratio = m[label]
    print(f"  multiplier pieces {result.multipliers[0]} -> {result.multipliers[1]}, register bits "
          f"{result.register_bits[0]} -> {result.register_bits[1]}")
    print(f"  check: RMSE {100 * (ratio - 1):+.3f} % of float, limit cycle {m['limit_cycle_lsb']:.3g} LSB, dead band "
          f"{m['dead_band_lsb']:.3g} LSB, no overflow on full-scale stress")
    for note in result.notes:
        print(f"  note: {note}")
    print(f"  {result.evaluations} candidates in {result.seconds:.1f} s" + (f"; wrote {out}" if out else
                                                                            "; --out FILE writes it as a config"))
