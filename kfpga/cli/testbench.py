"""``kfpga testbench``: a self-checking Verilog testbench for ModelSim-Altera or Icarus."""

from __future__ import annotations

import os
from pathlib import Path

from kfpga.cli import design, loading, options, output
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("testbench", help="write a self-checking Verilog testbench (ModelSim-Altera, Icarus)",
                       description="Write a plain Verilog-2001 testbench of the generated design into a folder: the "
                                   "design, a behavioural ADS8364 that replays the ADC codes and checks the datasheet "
                                   "timing, the codes and the model's expected outputs as $readmemh files, a "
                                   "ModelSim .do script and an Icarus script. The testbench compares every estimate "
                                   "with the bit-accurate model and ends with PASS or FAIL and an exit status. "
                                   "Exit code 0: written (and, with --run-icarus, passed); 1: the Icarus run failed; "
                                   "2: bad arguments.")
    options.add_design_args(p, "filter one channel or all six (default: 1)")
    p.add_argument("--channel", type=options.adc_channel, metavar="CH", help="channel of --channels 1 (default: A0)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the folder to write (created; a folder it wrote before is replaced whole)")
    options.add_adc_source_args(p)
    p.add_argument("--run-icarus", action="store_true", help="also compile and run it with Icarus Verilog")
    p.add_argument("--core-only", action="store_true",
                   help="the testbench of the core alone (the folder of 'generate --core-only', its tb/ with "
                        "--samples estimates of --scenario and --seed, random gaps on both streams); --channels N "
                        "is then its channel states")
    p.add_argument("--prefix", metavar="NAME", help="with --core-only: the core's module name (default: kfpga_FILTER)")
    options.add_json(p)
    p.set_defaults(func=run)


def run(args):
    if args.core_only:
        return _run_core_only(args)
    if args.prefix is not None:
        options.not_with("--prefix", "the board's testbench", "it names the core of --core-only")
    return _run_board(args)


def _run_core_only(args):
    """``--core-only``: the core's folder with its testbench (:func:`kfpga.flows.coreip.write_core`)."""
    import subprocess

    from kfpga.core.paths import atomic_dir, check_output_dir
    from kfpga.flows.coreip import write_core
    from kfpga.hw.tools import iverilog_path, simulator_available

    for option, value in (("--channel", args.channel), ("--input", args.input), ("--glitches", getattr(args, "glitches", None)),
                          ("--prefilter", getattr(args, "prefilter", None))):
        if value is not None:
            options.not_with(option, "--core-only", "the core's testbench drives its own stream from a scenario")
    check_output_dir(args.out, option="--out", marker="manifest.json")
    if args.run_icarus:
        ok, why = simulator_available("icarus")
        if not ok:
            raise UsageError(f"--run-icarus: {why}")
    config = loading.load_config(args, hardware=True)
    prefix = design.core_prefix(args, config)
    design.check_architecture(args, config)
    samples = loading.check_samples(2000 if args.samples is None else args.samples, kind="simulation")
    seed = output.pick_seed(args.seed)
    output.info(f"seed {seed} (replay with --seed {seed})")
    architecture = design.architecture(args, config, args.channels)
    with atomic_dir(args.out) as folder:
        try:
            manifest = write_core(folder, config, variant=args.variant, prefix=prefix, channels=args.channels,
                                  architecture=architecture, stages=args.stages, samples=samples, seed=seed,
                                  scenario=args.scenario)
        except ValueError as exc:
            raise UsageError(f"--channels {args.channels}: {exc}") from None
    result = {"prefix": prefix, "filter": config.filter, "variant": args.variant, "architecture": manifest["architecture"],
              "channels": args.channels, "samples": samples, "seed": seed, "out": str(Path(args.out))}
    if args.run_icarus:
        output.info("running it on Icarus ...")
        tb = Path(args.out) / "tb"
        path = f"{Path(iverilog_path()).parent}{os.pathsep}{os.environ.get('PATH', '')}"  # vvp beside iverilog
        done = subprocess.run(["sh", "run_icarus.sh"], cwd=tb, capture_output=True, text=True,
                              env={**os.environ, "PATH": path})
        result.update(_icarus(done.returncode, done.stdout + done.stderr))
    head = (f"kfpga testbench: {config.filter} filter, core {prefix} alone ({manifest['architecture']}, "
            f"{args.channels} channel state(s)), {samples} estimates, in {args.out}/")
    return _report(args, result, head, [f"  Icarus:           {args.out}/tb/run_icarus.sh",
                                        f"  ModelSim-Altera:  cd {args.out}/tb && vsim -c -do run_modelsim.do",
                                        f"  FuseSoC:          cd {args.out} && fusesoc --cores-root . run --target sim "
                                        f"kfpga:cores:{prefix}"])


def _icarus(code, text):
    """The Icarus run's exit status and its PASS or FAIL line (or the end of its output)."""
    lines = [ln for ln in text.splitlines() if ln.startswith(("PASS", "FAIL"))]
    return {"icarus_exit": code, "icarus_result": lines[-1] if lines else text.strip()[-300:]}


def _report(args, result, head, lines):
    """Print (or ``--json``) what was written and the Icarus run; the exit status."""
    if args.json:
        output.emit_json(result)
    else:
        print(head)
        for line in lines:
            print(line)
        if args.run_icarus:
            print(f"  Icarus run: {result['icarus_result']} (exit {result['icarus_exit']})")
    return 0 if not args.run_icarus or result["icarus_exit"] == 0 else 1


def _run_board(args):
    from kfpga.core.paths import atomic_dir, check_output_dir
    from kfpga.hw.tools import simulator_available
    from kfpga.sim.testbench import run_icarus, write_testbench

    check_output_dir(args.out, option="--out", marker="testbench.json")
    design.check_channel(args)
    config = loading.load_config(args, hardware=True)
    design.check_channel(args, config)
    out = Path(args.out)
    if args.run_icarus:
        ok, why = simulator_available("icarus")
        if not ok:
            raise UsageError(f"--run-icarus: {why}")
    pre = options.prefilter(args)
    design.check_sensors(args, pre)
    design.check_rate(args, config)
    design.check_architecture(args, config)
    params = design.adc_source_params(args, config)
    architecture = design.architecture(args, config, args.channels)
    output.info(f"writing the testbench of {args.samples} estimates into {out} ...")
    with atomic_dir(out) as folder:  # the folder appears whole, replacing the one written before
        info = write_testbench(folder, config, variant=args.variant, six=args.channels == 6, channel=args.channel,
                               samples=args.samples, params=params, prefilter=pre, architecture=architecture,
                               stages=args.stages, sensors=design.sensors(args))
    result = {**info, "out": str(out)}
    if args.run_icarus:
        output.info("running it on Icarus ...")
        result.update(_icarus(*run_icarus(out)))
    head = (f"kfpga testbench: {info['filter']} filter, {info['variant']} core, {info['channels']}, "
            f"{info['samples']} estimates, in {out}/")
    return _report(args, result, head, [f"  files: {', '.join(info['files'])}",
                                        f"  ModelSim-Altera:  cd {out} && vsim -c -do run_modelsim.do",
                                        f"  Icarus:           {out}/run_icarus.sh"])


#: The examples ending ``kfpga testbench --help``.
EXAMPLES = (
    'kfpga testbench --config tracker.toml --out build/tb --run-icarus',
    'kfpga testbench --config tracker.toml --core-only --out build/core_tb',
)
