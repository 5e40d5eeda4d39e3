"""``kfpga generate``: the Verilog and a Quartus II 13.0 project for the EP2C20Q240C8N."""

from __future__ import annotations

from pathlib import Path

from kfpga.cli import design, loading, options, output
from kfpga.core.errors import UsageError
from kfpga.hw.cores import make_core


def add_parser(sub):
    p = sub.add_parser("generate", help="write the Verilog and a Quartus II 13.0 project for the EP2C20Q240C8N",
                       description="Write plain Verilog-2001 of the top level (clock divider, ADS8364 controller, "
                                   "filter core, output port) and a complete Quartus II 13.0sp1 project into DIR: "
                                   ".qpf, .qsf (device, sources, pins from the pin table), .sdc, manifest.json, "
                                   "README.txt, and the Verilator lint waivers.")
    options.add_design_args(p, "1: filter one ADC channel; 6: sample all six with one HOLD and filter each (default: 1)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created; a folder it wrote before is replaced whole)")
    p.add_argument("--channel", type=options.adc_channel, metavar="CH",
                   help="the channel of --channels 1: 0..5 or A0, A1, B0, B1, C0, C1 (default: A0)")
    p.add_argument("--ratio", type=int, metavar="N", help="system clock / ADC clock (default: 10)")
    p.add_argument("--pins", metavar="CSV", help="pin table for your board (default: constraints/pins.csv)")
    p.add_argument("--out-field", metavar="FIELD", help=options.out_field_help())
    p.add_argument("--no-lint", action="store_true", help="skip the Verilator lint and Icarus parse checks")
    p.add_argument("--ignore-timing", action="store_true",
                   help="write a design whose estimated Fmax misses the clock anyway (a warning, recorded in the "
                        "manifest); without it such a design is refused")
    p.add_argument("--core-only", action="store_true",
                   help="the filter core alone, for your own design: PREFIX.v (every module named with the prefix), "
                        "a datasheet (README.txt, manifest.json), a Quartus .qip, a FuseSoC .core and a "
                        "self-checking testbench in tb/; --channels N is then its channel states (1..256)")
    p.add_argument("--prefix", metavar="NAME", help="with --core-only: the core's module name, and the prefix of its "
                                                    "submodules (default: kfpga_FILTER)")
    options.add_bus_args(p)
    options.add_quiet(p)
    p.set_defaults(func=run)


def run(args):
    if args.core_only:
        return _run_core_only(args)
    if args.prefix is not None:
        options.not_with("--prefix", "the board's design", "it names the core of --core-only")
    for option, value in (("--bus", args.bus), ("--missing", args.missing or None)):
        if value is not None:
            options.not_with(option, "the board's design", "the board's top has no bus pins and its ADC measures every "
                                                          "sample: use it with --core-only")
    args.ratio = 10 if args.ratio is None else args.ratio
    return _run_board(args)


def _run_core_only(args):
    """``--core-only``: the core alone (:mod:`kfpga.flows.coreip`)."""
    from kfpga.core.paths import atomic_dir, check_output_dir
    from kfpga.flows.coreip import write_core

    for option, value in (("--pins", args.pins), ("--ratio", args.ratio), ("--channel", args.channel),
                          ("--out-field", args.out_field), ("--prefilter", getattr(args, "prefilter", None))):
        if value is not None:
            options.not_with(option, "--core-only", "the core alone has no ADC, no pins and every output field")
    check_output_dir(args.out, option="--out", marker="manifest.json")
    config = loading.load_config(args, hardware=True)
    loading.warn_precision(config)
    prefix = design.core_prefix(args, config)
    design.check_architecture(args, config)
    design.check_bus_args(args, config)
    core_options = {**({"missing": True} if args.missing else {}), **({"bus": args.bus} if args.bus else {})}
    try:
        make_core(config, args.variant, channels=args.channels, **core_options,
                              **({} if args.architecture in (None, "auto") else {"architecture": args.architecture}))
    except ValueError as exc:
        raise UsageError(f"--channels {args.channels}: {exc}") from None
    architecture = design.architecture(args, config, args.channels)
    timing = _timing(args, config, architecture)
    cost = None
    if args.bus:
        from kfpga.flows.explore import bus_cost

        cost = bus_cost(config, args.variant, channels=args.channels, missing=args.missing, bus=args.bus)
    with atomic_dir(args.out) as folder:
        manifest = write_core(folder, config, variant=args.variant, prefix=prefix, channels=args.channels,
                              architecture=architecture, stages=args.stages, timing=timing, missing=args.missing,
                              bus=args.bus, bus_cost=cost)
    print(f"wrote {args.out}/: {', '.join(manifest['files'])}")
    print(f"  module {prefix}: {config.filter} filter, {args.variant} variant on the {manifest['architecture']} core, "
          f"{args.channels} channel state(s), latency {manifest['latency_cycles']} cycles, "
          f"{manifest['cycles_per_update']} cycle(s) per update; datasheet: {args.out}/README.txt; "
          f"testbench: {args.out}/tb/run_icarus.sh")
    if cost:
        goal = "within" if cost["within_goal"] else "over"
        print(f"  {args.bus} register bus: +{cost['logic_cells']} logic cells ({goal} the {cost['goal_logic_cells']} LE "
              f"goal), map {prefix}_regs.h/.md/.rdl; settings for new Q/R: kfpga regs")
    if not args.no_lint:
        _lint(args.out, prefix)
    return 0


def _run_board(args):
    from kfpga.core.paths import atomic_dir, check_output_dir
    from kfpga.flows.quartus import write_project
    from kfpga.hw.top import out_field

    check_output_dir(args.out, option="--out", marker="manifest.json")
    design.check_channel(args)
    config = loading.load_config(args, hardware=True)
    loading.warn_precision(config)
    design.check_channel(args, config)
    if args.ratio < 2:
        raise UsageError(f"--ratio must be >= 2, not {args.ratio}")
    try:
        field = out_field(config, args.out_field)
    except ValueError as exc:
        raise UsageError(f"--out-field: {exc}") from None
    pre = options.prefilter(args)
    sensors = design.sensors(args)
    design.check_sensors(args, pre)
    design.check_rate(args, config)
    _check_pins(config, field, args.pins, args.ratio, sensors)  # every refusal before the design search prints anything
    architecture = design.architecture(args, config, args.channels)
    timing = _timing(args, config, architecture)
    with atomic_dir(args.out) as folder:  # the folder appears whole, replacing the one written before
        manifest = write_project(folder, config, variant=args.variant, six_channel=args.channels == 6,
                                 channel=args.channel, ratio=args.ratio, pins=args.pins, out_field=field,
                                 prefilter=pre, architecture=architecture, stages=args.stages, timing=timing,
                                 sensors=sensors)
        _board_testbench(folder, config, args, pre, architecture, sensors, manifest)
    _print(args, config, field, manifest, pre)
    if not args.no_lint:
        _lint(args.out)
    return 0


def _board_testbench(folder, config, args, pre, architecture, sensors, manifest):
    """``tb/``: the self-checking testbench of the design just written (300 estimates of the
    filter's default scenario, seed 1), which the FuseSoC file's sim target runs; recorded in the
    manifest."""
    import json

    from kfpga.sim.testbench import write_testbench

    params = {"seed": 1, "scenario": config.spec.model.scenarios[0], "adc": list(args.adc) if args.adc else None,
              "channel": args.adc[0] if args.adc and args.channels != 6 else None}
    info = write_testbench(folder / "tb", config, variant=args.variant, six=args.channels == 6, channel=args.channel,
                           samples=300, params=params, prefilter=pre, architecture=architecture, stages=args.stages,
                           sensors=sensors)
    manifest["testbench"] = {"folder": "tb", "samples": info["samples"], "seed": 1, "scenario": info["scenario"]}
    manifest["files"] = sorted([*manifest["files"], *(f"tb/{name}" for name in info["files"])])
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")


def _check_pins(config, field, pins, ratio, sensors=1):
    """The pin table and the ADC clock, refused before the design search prints anything."""
    from kfpga.flows.quartus import PinError, board_rows, check_pins, io_timing

    rows, label = board_rows(config, field, pins, sensors)
    try:
        check_pins(rows, config, label, field, sensors)
    except PinError as exc:
        if sensors > 1 and pins is None:  # the built-in table ran out of spare pins
            raise PinError(f"{exc}; 'kfpga pins --channels {sensors} --write my_pins.csv' writes a table to complete "
                           "with your board's free pins (--pins my_pins.csv)") from None
        raise
    io_timing(ratio, sensors)  # refuses an ADC clock the ADS8364 cannot take


def _timing(args, config, architecture):
    """The chosen design's estimate against the clock: refused when it misses, unless
    ``--ignore-timing`` (then a warning, and the manifest records it); refused always when it does
    not fit the device."""
    from kfpga.flows.explore import choose
    from kfpga.hw.generate import figures_only

    missing, bus = getattr(args, "missing", False), getattr(args, "bus", None)
    every = args.candidates or design.explore(config, args.variant, args.channels, quiet=args.quiet, missing=missing,
                                              bus=bus)
    core_options = {**({"missing": True} if missing else {}), **({"bus": bus} if bus else {})}
    core = figures_only(make_core(config, args.variant, channels=args.channels, architecture=architecture,
                                              **({} if args.stages is None else {"stages": args.stages}), **core_options))
    chosen = next(c for c in every if c.architecture == architecture and c.stages == getattr(core, "stages", None))
    if not chosen.fits:
        raise UsageError(f"the {chosen.label} design does not fit the EP2C20: it takes {chosen.over_device}")
    clock = config.board.clock_hz / 1e6
    record = {"fmax_mhz_estimate": chosen.fmax_mhz, "clock_mhz": clock, "meets_clock": chosen.fmax_mhz >= clock,
              "worst_path": chosen.worst_path, "logic_cells": chosen.logic_cells}
    if chosen.fmax_mhz >= clock:
        return record
    better = choose(every)
    how = f"--architecture {better.architecture}" + (f" --stages {better.stages}" if better and better.stages else "") \
        if better else ""
    alternative = f"; {better.label} meets it ({how})" if better else ""
    message = (f"the {chosen.label} design is estimated at {chosen.fmax_mhz:g} MHz, below the {clock:g} MHz clock "
               f"(worst path {chosen.worst_path}){alternative}")
    if not args.ignore_timing:
        raise UsageError(message + "; --ignore-timing writes it anyway")
    output.info(f"warning: {message}; written anyway (--ignore-timing), the manifest records it")
    record["ignored"] = True
    return record


def _print(args, config, field, manifest, pre):
    from kfpga.hw.ads8364_timing import CHANNELS
    from kfpga.hw.generate import TOP_NAME

    print(f"wrote {args.out}/: {', '.join(manifest['files'])}")
    where = "six channels" if args.channels == 6 else ", ".join(
        f"{CHANNELS[c]}" + (f" ({n})" if len(args.adc) > 1 else "") for n, c in zip(config.inputs, args.adc, strict=True))
    if manifest.get("sensors"):
        where += f", {manifest['sensors']} sensors on a multiplexer (mux_sel)"
    core = manifest["core"]
    rate = manifest["sample_rate_hz"]
    print(f"  {config.filter} filter, {args.variant} variant on the {core['architecture']} core, ADC {where}"
          + (f" at {rate:g} Hz" if rate else " free running") + f", {field} "
          f"{manifest['out_data']['format']} on out_data, "
          f"latency {manifest['core']['latency_cycles']} cycles, {manifest['core']['cycles_per_update']} cycle(s) "
          f"per update; compile with: cd {args.out} && quartus_sh --flow compile {TOP_NAME}")
    if pre is not None:
        print(f"  {pre.filter} pre-filter before the core: {loading.describe_params(pre.params)}, "
              f"{manifest['prefilter']['channels']} channel state(s), {pre.spec.hardware.prefilter.delay} samples late, "
              f"{manifest['prefilter']['latency_cycles']} cycles of latency")


def _lint(out, top=None):
    from kfpga.hw.generate import TOP_NAME
    from kfpga.hw.tools import iverilog_parse, iverilog_path, verilator_lint

    top = top or TOP_NAME
    path = Path(out) / f"{top}.v"
    rc, text = verilator_lint(path, top, path.parent / "verilator_lint.vlt")
    if rc:
        raise UsageError(f"verilator --lint-only -Wall reports problems in {path}:\n{text}")
    print("verilator --lint-only -Wall: clean (waivers and their reasons: verilator_lint.vlt)")
    if iverilog_path():
        rc, text = iverilog_parse(path, top)
        if rc:
            raise UsageError(f"iverilog -g2001 rejects {path}:\n{text}")
        print("iverilog -g2001: parses")
    else:
        print("iverilog not installed: Verilog-2001 parse check skipped")


#: The examples ending ``kfpga generate --help``.
EXAMPLES = (
    "kfpga generate --config tracker.toml --out build/tracker       # the board's Quartus project",
    'kfpga generate --config tracker.toml --core-only --prefix my_kf --out build/my_kf',
)
