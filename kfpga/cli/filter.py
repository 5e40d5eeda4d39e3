"""``kfpga filter``: a CSV of samples through the bit-accurate (or float) filter, and the modes
some filters add to it (their spec's ``modes``)."""

from __future__ import annotations

import numpy as np

from kfpga.cli import loading, options, output
from kfpga.core import registry
from kfpga.core.errors import InputError, UsageError


def add_parser(sub):
    p = sub.add_parser("filter", help="run a CSV of samples through the bit-accurate (or float) filter",
                       description="Read the input columns of a CSV file (signed 16-bit ADC codes, one row per sample: "
                                   "'y', or the model's observation names) and write every output of the filter and, "
                                   "for fixed point, the per-sample overflow flag, in input units, one row per input "
                                   "row. A row whose input cells are empty (a blank line in a one-column file) is a "
                                   "sample with no measurement: a filter that can predict only "
                                   f"({', '.join(registry.coasting())}) coasts over it (x = F x, P = F P F' + G Q G'), "
                                   "and the output marks it in a 'missing' column.")
    p.add_argument("--input", required=True, metavar="CSV", help="input file with the filter's input columns")
    p.add_argument("--output", required=True, metavar="CSV", help="output file")
    options.add_filter_args(p)
    p.add_argument("--float", action="store_true", help="use the float64 reference instead of the bit-accurate model")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    p.add_argument("--clip", action="store_true", help="saturate out-of-range inputs instead of failing")
    for spec in registry.specs():
        for mode in spec.model.modes:
            p.add_argument(mode.option, **{**mode.argument, "help": f"{spec.name} filter only: {mode.argument['help']}"})
    p.set_defaults(func=run)


def _mode(args, config):
    """The mode of the filter chosen by its option (``None``: plain filtering); a mode's option
    given for another filter is refused."""
    chosen = None
    for spec in registry.specs():
        for mode in spec.model.modes:
            value = getattr(args, mode.dest, None)
            if value is None or value is False:
                continue
            if spec.name != config.filter:
                raise UsageError(f"{mode.option} applies to the {spec.name} filter, not to {config.filter}")
            chosen = (mode, value)
    return chosen


def run(args):
    from kfpga.core.csvio import read_samples, write_columns
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.core.paths import check_output_file
    from kfpga.flows.analysis import float_run

    check_output_file(args.output, option="--output", inputs=(args.input, args.config), extensions=(".csv", ".txt"))
    config = loading.load_config(args)
    chosen = _mode(args, config)
    columns_in = chosen[0].columns(config, chosen[1]) if chosen else config.inputs
    coasts = not chosen and config.spec.model.variants[args.variant].predict is not None
    try:
        samples = read_samples(args.input, clip=args.clip, columns=columns_in, bits=config.input_format.width,
                               missing=coasts)
    except InputError as exc:
        if coasts or not ("no value in column" in str(exc) or "a blank line" in str(exc)):
            raise
        raise InputError(f"{exc} (the {config.filter} filter's {args.variant} variant takes every sample as a "
                         "measurement: it cannot coast over an empty one)") from None
    lost = samples.missing if coasts and samples.missing.any() else None
    kind = "float64" if args.float else "bit-accurate fixed-point"
    if chosen:
        mode, value = chosen
        table = samples.y if isinstance(samples.y, dict) else {columns_in[0]: samples.y}
        columns, what = mode.run(config, args.variant, table, value, exact=not args.float, source=args.input)
        form = f"{mode.option} {value}" if value is not True else mode.option
    else:
        if args.float:
            columns = dict(float_run(config, args.variant, samples.y, lost))
        else:
            model = FixedModel(config, variant=args.variant)
            res = model.run(samples.y, missing=lost)
            columns = {**model.to_float(res), "overflow": res.overflow}
        what, form = f"{len(samples)} samples", f"{args.variant} variant"
        if lost is not None:
            columns["missing"] = lost.astype(int)
            what += f" ({int(lost.sum())} with no measurement, predicted only)"
    write_columns(args.output, columns)
    note = [f"{what} filtered ({config.filter} filter, {form}, {kind}) -> {args.output}"]
    if samples.clipped:
        note.append(f"{samples.clipped} input value(s) saturated to the 16-bit range (--clip)")
    if "overflow" in columns:
        note.append(f"{int(np.count_nonzero(columns['overflow']))} sample(s) with overflow")
    output.info("; ".join(note))
    return 0


#: The examples ending ``kfpga filter --help``.
def EXAMPLES():
    lines = ["kfpga filter --config tracker.toml --input log.csv --output estimates.csv   # empty cells: lost samples"]
    lines += [f"kfpga filter --filter {spec.name} {mode.example}" for spec in registry.specs() for mode in spec.model.modes
              if mode.example]
    return lines
