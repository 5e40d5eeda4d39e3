"""``kfpga sweep``: fixed-point error against word length."""

from __future__ import annotations

import sys
from pathlib import Path

from kfpga.cli import loading, options, output
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("sweep", help="fixed-point error against word length, as a table and a PNG",
                       description="Rerun the comparison with every multiplier operand N bits wide (and N-10 fraction "
                                   "bits in the state registers) for each N in --bits; print the formats each point "
                                   "got, and mark the narrowest width from which every wider one keeps the fixed RMSE "
                                   "within --budget of float (a fixed RMSE further below float than the budget fails "
                                   "too: it is not the float filter's). The plot marks the 18-bit multiplier width "
                                   "and goes to build/sweep_VARIANT.png in the current folder unless --plot says "
                                   "otherwise.")
    options.add_signal_args(p)
    p.add_argument("--bits", type=options.bit_range, default=list(range(10, 25)), metavar="A:B",
                   help="operand widths to try, inclusive (default: 10:24)")
    p.add_argument("--budget", type=options.budget, default=0.01, metavar="PCT",
                   help="how far the fixed RMSE may be from float's, either way (default: 1%%)")
    p.add_argument("--ranges", choices=("scenario", "full-scale"), default="scenario",
                   help="where integer bits come from: the swept signal's own float run, or the full 16-bit "
                        "input range (default: scenario)")
    options.add_json(p, "print the rows as JSON")
    p.add_argument("--plot", metavar="PNG", help="where to draw the sweep (default: build/sweep_VARIANT.png)")
    options.add_quiet(p)
    p.set_defaults(func=run)


def run(args):
    from tqdm import tqdm

    from kfpga.flows.analysis import plot_sweep, sample_count, sweep

    loading.check_signal_args(args)
    args.plot = options.check_plot(args.plot)
    config = loading.load_config(args)
    loading.require_word_lengths(config, "sweep")
    if config.pinned:
        raise UsageError(f"sweep sets every format itself, so the formats {args.config} pins would be ignored "
                         f"({', '.join(config.pinned)}): remove its [formats] tables, or use compare")
    truth, y, label = loading.samples_for(args, config, command="sweep", need_truth=True)
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
    if args.json:
        output.emit_json({"filter": config.filter, "variant": args.variant, "samples": sample_count(y), "seed": args.seed,
                          "ranges": args.ranges, "budget": args.budget, "narrowest_within_budget": narrowest,
                          "rows": rows, "plot": plot})
        return 0
    _print(title, rows, narrowest, args.budget, plot)
    return 0


def _print(title, rows, narrowest, budget, plot):
    pct = f"{100 * budget:g} %"
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


#: The examples ending ``kfpga sweep --help``.
EXAMPLES = (
    "kfpga sweep --bits 8:20 --plot build/sweep.png          # RMSE against the state's fraction bits",
    'kfpga sweep --config tracker.toml --budget 1 --json',
)
