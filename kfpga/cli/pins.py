"""``kfpga pins``: the pin table of a config, to edit for a board."""

from __future__ import annotations

from kfpga.cli import design, loading, options, output
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("pins", help="write the pin table for a config (to edit for your board)",
                       description="Print (or --write) the pin table kfpga generate would use for this config: one "
                                   "row per port bit, out_data as wide as the chosen output field. Bits the base "
                                   "table has no pin for get an empty pin, to be filled in with a free user I/O pin "
                                   "of your board; generate refuses the table until they have one.")
    options.add_filter_args(p)
    p.add_argument("--config", metavar="TOML", help="model parameters and formats")
    p.add_argument("--out-field", metavar="FIELD", help=options.out_field_help())
    p.add_argument("--pins", metavar="CSV", help="the table to start from (default: constraints/pins.csv)")
    p.add_argument("--write", metavar="CSV", help="write the table to this file instead of printing it")
    p.add_argument("--channels", type=options.channels_type, default=1, metavar="N",
                   help="as generate's: N other than 1 and 6 adds the multiplexer's select (mux_sel) and widens "
                        "out_channel (default: 1)")
    p.set_defaults(func=run)


def run(args):
    from kfpga.core.paths import check_output_file, write_text
    from kfpga.flows.quartus import pin_table
    from kfpga.hw.top import out_field

    if args.write:
        check_output_file(args.write, option="--write", inputs=(args.pins, args.config), extensions=(".csv",))
    config = loading.load_config(args, hardware=True)
    try:
        field = out_field(config, args.out_field)
    except ValueError as exc:
        raise UsageError(f"--out-field: {exc}") from None
    text = pin_table(config, out_field=field, base=args.pins, sensors=design.sensors(args))
    if not args.write:
        print(text, end="")
        return 0
    write_text(args.write, text)
    missing = sum(1 for line in text.splitlines() if line.endswith(",3.3-V LVTTL,choose a free user I/O pin"))
    output.info(f"wrote {args.write}" + (f"; {missing} port bit(s) still need a pin of your board" if missing else ""))
    return 0


#: The examples ending ``kfpga pins --help``.
EXAMPLES = (
    'kfpga pins',
    'kfpga pins --channels 16 --write my_pins.csv',
)
