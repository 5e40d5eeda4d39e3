"""``kfpga generate``: the Verilog and a Quartus II 13.0 project for the EP2C20Q240C8N."""

from __future__ import annotations

from pathlib import Path

from kfpga.cli import common
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("generate", help="write the Verilog and a Quartus II 13.0 project for the EP2C20Q240C8N",
                       description="Write plain Verilog-2001 of the top level (clock divider, ADS8364 controller, "
                                   "filter core, output port) and a complete Quartus II 13.0sp1 project into DIR: "
                                   ".qpf, .qsf (device, sources, pins from the pin table), .sdc, manifest.json, "
                                   "README.txt, and the Verilator lint waivers.")
    common.add_design_args(p, "1: filter one ADC channel; 6: sample all six with one HOLD and filter each (default: 1)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--channel", type=common.adc_channel, metavar="CH",
                   help="the channel of --channels 1: 0..5 or A0, A1, B0, B1, C0, C1 (default: A0)")
    p.add_argument("--ratio", type=int, default=10, metavar="N", help="system clock / ADC clock (default: 10)")
    p.add_argument("--pins", metavar="CSV", help="pin table for your board (default: constraints/pins.csv)")
    p.add_argument("--out-field", metavar="FIELD", help=common.out_field_help())
    p.add_argument("--no-lint", action="store_true", help="skip the Verilator lint and Icarus parse checks")
    p.set_defaults(func=run)


def run(args):
    from kfpga.core.paths import check_output_dir
    from kfpga.flows.quartus import write_project
    from kfpga.hw.top import out_field

    check_output_dir(args.out, option="--out")
    common.check_channel(args)
    config = common.load_config(args, hardware=True)
    common.warn_precision(config)
    common.check_channel(args, config)
    if args.ratio < 2:
        raise UsageError(f"--ratio must be >= 2, not {args.ratio}")
    try:
        field = out_field(config, args.out_field)
    except ValueError as exc:
        raise UsageError(f"--out-field: {exc}") from None
    pre = common.prefilter(args)
    manifest = write_project(args.out, config, variant=args.variant, six_channel=args.channels == 6,
                             channel=args.channel, ratio=args.ratio, pins=args.pins, out_field=field, prefilter=pre)
    _print(args, config, field, manifest, pre)
    if not args.no_lint:
        _lint(args.out)
    return 0


def _print(args, config, field, manifest, pre):
    from kfpga.core.ads8364 import CHANNELS
    from kfpga.hw.generate import TOP_NAME

    print(f"wrote {args.out}/: {', '.join(manifest['files'])}")
    where = "six channels" if args.channels == 6 else ", ".join(
        f"{CHANNELS[c]}" + (f" ({n})" if len(args.adc) > 1 else "") for n, c in zip(config.inputs, args.adc, strict=True))
    print(f"  {config.filter} filter, {args.variant} core, ADC {where}, {field} "
          f"{manifest['out_data']['format']} on out_data, "
          f"latency {manifest['core']['latency_cycles']} cycles, {manifest['core']['cycles_per_update']} cycle(s) "
          f"per update; compile with: cd {args.out} && quartus_sh --flow compile {TOP_NAME}")
    if pre is not None:
        print(f"  {pre.filter} pre-filter before the core: {common.describe_params(pre.params)}, "
              f"{manifest['prefilter']['channels']} channel state(s), {pre.spec.prefilter.delay} samples late, "
              f"{manifest['prefilter']['latency_cycles']} cycles of latency")


def _lint(out):
    from kfpga.core.tools import iverilog_parse, iverilog_path, verilator_lint
    from kfpga.hw.generate import TOP_NAME

    path = Path(out) / f"{TOP_NAME}.v"
    rc, text = verilator_lint(path, TOP_NAME, path.parent / "verilator_lint.vlt")
    if rc:
        raise UsageError(f"verilator --lint-only -Wall reports problems in {path}:\n{text}")
    print("verilator --lint-only -Wall: clean (waivers and their reasons: verilator_lint.vlt)")
    if iverilog_path():
        rc, text = iverilog_parse(path, TOP_NAME)
        if rc:
            raise UsageError(f"iverilog -g2001 rejects {path}:\n{text}")
        print("iverilog -g2001: parses")
    else:
        print("iverilog not installed: Verilog-2001 parse check skipped")
