"""``kfpga formats``: the quantisation formats of a config, or the config as a file to edit."""

from __future__ import annotations

from kfpga.cli import loading, options, output
from kfpga.core import registry
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("formats", help="show the quantisation formats (or write a config file to edit)",
                       description="Show every quantisation point with its format, the range it covers and the "
                                   "range the float analysis found; --toml prints a complete config file.")
    options.add_filter_args(p, variant=False)
    p.add_argument("--config", metavar="TOML", help="config to show (default: the built-in defaults)")
    p.add_argument("--toml", action="store_true",
                   help="print the config as TOML, the formats commented out (defaults that follow the parameters)")
    p.add_argument("--pin-formats", action="store_true",
                   help="with --toml: write the formats as settings, so they stay fixed when a parameter changes")
    options.add_json(p, "print the table as JSON")
    p.set_defaults(func=run)


def _built_bits(config, name, fmt):
    """The bits a point costs: a constant-only point's widest constant without its sign copies."""
    from kfpga.core.fixed import to_raw
    from kfpga.core.formats import constant_values, significant_bits

    values = constant_values(config.spec, config.params).get(name)
    if not config.spec.model.points[name].constant or not values:
        return fmt.width
    return max(significant_bits(to_raw(v, fmt)[0]) for v in values)


def formats_table(config):
    """Rows describing each quantisation point (``kfpga formats``); ``bits`` is what the point
    costs (a constant: its significant bits, which can be fewer than its format's)."""
    points = config.spec.model.points
    ranges = config.ranges()
    rows = []
    for name, fmt in config.formats.items():
        point = points[name]
        rows.append({
            "point": name,
            "format": str(fmt),
            "bits": _built_bits(config, name, fmt),
            "covers": f"±{fmt.max_value:.6g}",
            "analysed_max": ranges.get(name),
            "lsb": fmt.lsb,
            "rounding": fmt.rounding.value,
            "overflow": fmt.overflow.value,
            "variants": ",".join(point.variants or config.spec.model.variants),
            "multiplier_operand": point.operand,
            "cast": point.cast,
            "description": point.description,
        })
    return rows


def budget_lines(config):
    """What the word budget did: the cast points with formats and without, and what the datapath
    still builds wider than the budget (a product, a divider's dividend), per variant."""
    casts = config.casts
    given = [name for name, fmt in casts.items() if fmt is not None]
    if casts:
        lines = [f"word budget: formats.max_word = {config.max_word} bits; {len(given)} of the {len(casts)} cast points "
                 "round a product before its sum (marked [cast])" + (", the others keep it exact" if len(given) < len(casts)
                                                                    else "")]
    else:
        lines = [f"word budget: formats.max_word = {config.max_word} bits; the {config.filter} filter has no cast points: "
                 "its sums stay exact"]
    for variant, v in config.spec.model.variants.items():
        if v.applies(config.params) is not None:
            continue
        wide = config.over_budget(variant)
        if wide:
            shown = ", ".join(f"{_short(i.text)} ({i.width} bits, {i.kind})" for i in wide[:4])
            more = f" and {len(wide) - 4} more" if len(wide) > 4 else ""
            lines.append(f"built wider than the budget ({variant}): {shown}{more}")
    return lines


def _short(text, most=40):
    return text if len(text) <= most else text[:most - 3] + "..."


def run(args):
    if args.toml and args.json:
        raise UsageError("--toml and --json are two ways to print the same: choose one")
    if args.pin_formats and not args.toml:
        options.not_with("--pin-formats", "the table", "it says how --toml writes the formats")
    config = loading.load_config(args)
    loading.warn_precision(config)
    if args.toml:
        print(config.to_toml(formats=args.pin_formats), end="")
    elif args.json:
        output.emit_json(formats_table(config))
    else:
        _print(formats_table(config))
        for line in budget_lines(config):
            print(line)
    # the table is only worth writing if the other commands take it: every variant that applies
    for variant, v in config.spec.model.variants.items():
        if v.applies(config.params) is None:
            config.require_variant(variant)
    return 0


def _print(rows):
    width = max([6] + [len(r["point"]) for r in rows])
    print(f"{'point':<{width}} {'format':<7} {'bits':>4} {'covers':>12} {'analysed max':>13} {'rounding':<10} "
          f"{'overflow':<9} description")
    for r in rows:
        amax = f"{r['analysed_max']:.6g}" if r["analysed_max"] is not None else "-"
        op = " [multiplier operand]" if r["multiplier_operand"] else " [cast]" if r["cast"] else ""
        print(f"{r['point']:<{width}} {r['format']:<7} {r['bits']:>4} {r['covers']:>12} {amax:>13} {r['rounding']:<10} "
              f"{r['overflow']:<9} {r['description']}{op}")


#: The examples ending ``kfpga formats --help``.
def EXAMPLES():
    name = registry.example(skip=3)
    return ("kfpga formats --config tracker.toml", f"kfpga formats --filter {name} --toml > {name}.toml   # a config to edit")
