"""``kfpga explore``: every design the tool can build for a config, and the one it chooses."""

from __future__ import annotations

from kfpga.cli import design, loading, options, output
from kfpga.core import registry


def add_parser(sub):
    p = sub.add_parser("explore", help="every core design for a config: resources, estimated Fmax, throughput; the "
                                       "chosen one marked",
                       description="Synthesise every design of the filter's variant (its parallel core at each "
                                   "pipeline depth, and the folded core) with Yosys and list their logic cells, "
                                   "multipliers, M4K bits, estimated Fmax on the -8 part, cycles per update and the "
                                   "updates a second they sustain, against what the board needs (the [board] "
                                   "sample rate on every channel, or the free-running ADC's). The chosen design, "
                                   "the one --architecture auto builds, is the cheapest (logic cells, then "
                                   "multipliers, then M4K bits) whose estimate is at least 1.25 x the clock and "
                                   "whose throughput covers the need. Estimates are cached (~/.cache/kfpga).",
                       epilog="example: kfpga explore --config my.toml --plot build/explore.png; "
                              "kfpga explore --config my.toml --bus avalon (the folded core with its register bus, "
                              "and what the bus costs)")
    options.add_filter_args(p)
    p.add_argument("--channels", type=int, default=1, metavar="N",
                   help="channel states in the core (default: 1; the board has 1 or 6)")
    p.add_argument("--config", metavar="TOML", help="model parameters, formats and [board] rate")
    options.add_bus_args(p)
    options.add_json(p, "print the candidates as a JSON list (with --bus: and the bus's cost)")
    p.add_argument("--plot", metavar="PNG", help="draw logic cells against throughput, the need and the chosen one marked")
    options.add_quiet(p)
    p.set_defaults(func=run)


def run(args):
    from kfpga.core.errors import UsageError
    from kfpga.flows.explore import FMAX_MARGIN, choose

    if not 1 <= args.channels <= 512:
        raise UsageError(f"--channels must be 1..512, not {args.channels}")
    plot = options.check_plot(args.plot)
    config = loading.load_config(args, hardware=True)
    design.check_bus_args(args, config)
    found = design.explore(config, args.variant, args.channels, quiet=args.quiet, missing=args.missing, bus=args.bus)
    cost = None
    if args.bus:
        from kfpga.flows.explore import bus_cost

        cost = bus_cost(config, args.variant, channels=args.channels, missing=args.missing, bus=args.bus)
    best = choose(found)
    need = design.need_hz(config, args.channels)
    if plot:
        _plot(found, need, plot, f"kfpga explore: {config.filter} {args.variant}, {args.channels} channel(s)")
    if args.json:
        output.emit_json({"candidates": [c.as_dict() for c in found], "bus": cost} if cost else
                         [c.as_dict() for c in found])
        return 0
    clock = config.board.clock_hz / 1e6
    rate = config.board.sample_rate_hz
    need_text = (f"need {need:.6g} updates/s ({rate:g} Hz x {args.channels})" if rate else
                 "no [board] sample rate: the ADC converts as fast as the core takes samples")
    print(f"kfpga explore: {config.filter} filter, {args.variant} variant, {args.channels} channel(s); {need_text}; "
          f"{clock:g} MHz, estimated Fmax >= {FMAX_MARGIN * clock:g} MHz")
    print(f"  {'design':<24}{'logic cells':>12}{'mul18':>7}{'M4K bits':>10}{'Fmax MHz':>10}{'cycles':>8}"
          f"{'updates/s':>12}  meets")
    for c in found:
        misses = [what for what, ok in (("margin", c.meets_clock or not c.within_clock), ("clock", c.within_clock),
                                         ("rate", c.meets_rate), (f"device: {c.over_device}", c.fits)) if not ok]
        mark = "  <- chosen" if c.chosen else ""
        print(f"  {c.label:<24}{c.logic_cells:>12}{c.mul18:>7}{c.memory_bits:>10}{c.fmax_mhz:>10.1f}"
              f"{c.cycles_per_update:>8}{c.updates_per_s:>12.4g}  {'yes' if not misses else 'no (' + ', '.join(misses) + ')'}"
              f"{mark}")
    if cost:
        goal = "within" if cost["within_goal"] else "over"
        print(f"  the {args.bus} register bus: +{cost['logic_cells']} logic cells, +{cost['m4k_blocks']} M4K "
              f"({cost['base_logic_cells']} -> {cost['logic_cells_with_bus']} LE; {goal} the goal of "
              f"{cost['goal_logic_cells']}), {cost['fmax_mhz_estimate']:.1f} MHz estimated; only the folded core has it")
    if best is None and not any(c.fits for c in found):
        print("  no design fits the EP2C20: generate refuses them")
    elif best is None:
        print("  no design meets the clock and the rate: generate refuses them unless --ignore-timing")
    elif not best.meets:
        print(f"  no design has the {FMAX_MARGIN:g} x margin: the chosen one meets the clock itself")
    if plot:
        print(f"  plot: {plot}")
    return 0


def _plot(found, need, path, title):
    from kfpga.model.plots import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    for c in found:
        color = "tab:green" if c.meets else "tab:red"
        ax.scatter(c.updates_per_s, c.logic_cells, s=80 if c.chosen else 40, color=color,
                   edgecolors="black" if c.chosen else "none", zorder=3)
        ax.annotate(f"{c.label}\n{c.fmax_mhz:.0f} MHz", (c.updates_per_s, c.logic_cells), fontsize=8,
                    xytext=(5, 5), textcoords="offset points")
    if need > 0:
        ax.axvline(need, color="gray", linestyle="--", label=f"need {need:.3g} updates/s")
    ax.set_xscale("log")
    ax.set_xlabel("updates per second (all channels)")
    ax.set_ylabel("logic cells (estimate)")
    ax.set_title(title + " (green: meets clock and rate)")
    ax.legend(loc="best")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


#: The examples ending ``kfpga explore --help``.
def EXAMPLES():
    return ("kfpga explore --config tracker.toml --plot build/explore.png",
            f"kfpga explore --filter {registry.example()} --channels 6 --json")
