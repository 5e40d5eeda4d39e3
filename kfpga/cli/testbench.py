"""``kfpga testbench``: a self-checking Verilog testbench for ModelSim-Altera or Icarus."""

from __future__ import annotations

from pathlib import Path

from kfpga.cli import common
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
    common.add_design_args(p, "filter one channel or all six (default: 1)")
    p.add_argument("--channel", type=common.adc_channel, metavar="CH", help="channel of --channels 1 (default: A0)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the folder to write (created; a folder it wrote before is replaced whole)")
    common.add_adc_source_args(p)
    p.add_argument("--run-icarus", action="store_true", help="also compile and run it with Icarus Verilog")
    common.add_json(p)
    p.set_defaults(func=run)


def run(args):
    from kfpga.core.paths import atomic_dir, check_output_dir
    from kfpga.core.tools import simulator_available
    from kfpga.sim.testbench import run_icarus, write_testbench

    check_output_dir(args.out, option="--out", marker="testbench.json")
    common.check_channel(args)
    config = common.load_config(args, hardware=True)
    common.check_channel(args, config)
    out = Path(args.out)
    if args.run_icarus:
        ok, why = simulator_available("icarus")
        if not ok:
            raise UsageError(f"--run-icarus: {why}")
    pre = common.prefilter(args)
    common.check_sensors(args, pre)
    common.check_rate(args, config)
    common.check_architecture(args, config)
    params = common.adc_source_params(args, config)
    architecture = common.architecture(args, config, args.channels)
    common.info(f"writing the testbench of {args.samples} estimates into {out} ...")
    with atomic_dir(out) as folder:  # the folder appears whole, replacing the one written before
        info = write_testbench(folder, config, variant=args.variant, six=args.channels == 6, channel=args.channel,
                               samples=args.samples, params=params, prefilter=pre, architecture=architecture,
                               stages=args.stages, sensors=common.sensors(args))
    result = {**info, "out": str(out)}
    if args.run_icarus:
        common.info("running it on Icarus ...")
        code, text = run_icarus(out)
        lines = [ln for ln in text.splitlines() if ln.startswith(("PASS", "FAIL"))]
        result.update({"icarus_exit": code, "icarus_result": lines[-1] if lines else text.strip()[-300:]})
    if args.json:
        common.emit_json(result)
    else:
        print(f"kfpga testbench: {info['filter']} filter, {info['variant']} core, {info['channels']}, "
              f"{info['samples']} estimates, in {out}/")
        print(f"  files: {', '.join(info['files'])}")
        print(f"  ModelSim-Altera:  cd {out} && vsim -c -do run_modelsim.do")
        print(f"  Icarus:           {out}/run_icarus.sh")
        if args.run_icarus:
            print(f"  Icarus run: {result['icarus_result']} (exit {result['icarus_exit']})")
    return 0 if not args.run_icarus or result["icarus_exit"] == 0 else 1
