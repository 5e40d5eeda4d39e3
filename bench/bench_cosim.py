"""Benchmark: co-simulation speed of the generated Verilog, Verilator against Icarus, one run.

For each core alone, at full rate (valid and ready held high) with every estimate checked
against the model, it reports samples/s of the clocked loop (stimulus packed before it,
results unpacked after it) and of the whole test, two ways: the cocotb bench (a Python await
per clock cycle) and kfpga_core_cosim with the stream source and sink in the simulator
(kfpga.sim.corerun). For the whole design it reports
estimates per wall second, every one checked against the model and every ADS8364 timing
figure checked on every conversion, two ways: the cocotb bench with the Python ADC model on
the pins (one Python call per pin edge), and kfpga_cosim with the Verilog ADC model in the
simulator (kfpga.sim.system); the ratio of the two is the speed-up. Compare ratios measured in
one run, not absolute figures across machines.

    python bench/bench_cosim.py [--samples N] [--system-samples N] [--json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

from kfpga.core.config import FilterConfig
from kfpga.hw.tools import simulator_available
from kfpga.sim import corerun, system
from kfpga.sim.runner import SIMULATORS, build, run
from kfpga.sim.sources import stress_codes

SEED = 20080525


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=50000,
                        help="samples through the steady core in the cocotb bench (default 50000; the full core a "
                             "tenth; the in-simulator source and sink four times as many, a tenth of that on Icarus)")
    parser.add_argument("--system-samples", type=int, default=20000,
                        help="estimates through the whole design with the Verilog ADC on Verilator (default 20000; "
                             "a tenth on Icarus; the Python ADC runs a tenth on Verilator, a twentieth on Icarus)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    print(f"seed {SEED}")
    sims = [s for s in SIMULATORS if simulator_available(s)[0]]
    rows = _core_rows(sims, args.samples) + _system_rows(sims, args.system_samples)
    speedups = {}
    for variant in ("steady", "full"):
        for sim in sims:
            old, new = (next(r for r in rows if r["simulator"] == sim and r["what"] ==
                             f"whole design, {variant}, 1 channel, {how}") for how in
                        ("Python ADC (cocotb)", "Verilog ADC (kfpga_cosim)"))
            speedups[f"whole design, {variant}, {sim}"] = new["test_samples_per_s"] / old["test_samples_per_s"]
    ratios = {}
    for what in dict.fromkeys(r["what"] for r in rows):
        by = {r["simulator"]: r for r in rows if r["what"] == what}
        if {"verilator", "icarus"} <= set(by):
            key = "loop_samples_per_s" if by["verilator"]["loop_samples_per_s"] else "test_samples_per_s"
            ratios[what] = by["verilator"][key] / by["icarus"][key]
    machine = f"{platform.machine()}, Python {platform.python_version()}"
    if args.json:
        print(json.dumps({"rows": rows, "verilator_over_icarus": ratios, "verilog_adc_over_python_adc": speedups,
                          "machine": machine}, indent=2))
        return 0
    print(f"co-simulation speed, every estimate checked, {machine}")
    print(f"{'what':<62} {'simulator':<10} {'samples':>8} {'loop samples/s':>15} {'test samples/s':>15}")
    for r in rows:
        loop = f"{r['loop_samples_per_s']:,.0f}" if r["loop_samples_per_s"] else "-"
        print(f"{r['what']:<62} {r['simulator']:<10} {r['samples']:>8} {loop:>15} {r['test_samples_per_s']:>15,.0f}")
    for what, ratio in ratios.items():
        print(f"Verilator / Icarus, {what}: {ratio:.1f}x")
    for what, ratio in speedups.items():
        print(f"Verilog ADC / Python ADC, {what}: {ratio:.1f}x")
    return 0


def _core_rows(sims, samples_arg):
    """Each core alone: the cocotb bench, then the source and sink in the simulator."""
    rows = []
    for variant, samples in (("steady", samples_arg), ("full", max(samples_arg // 10, 1000))):
        for sim in sims:
            r = run(build(sim, "core", variant=variant), "test_core", testcase="core_bit_exact",
                    params={"variant": variant, "seed": SEED, "samples": samples}, tag="bench")
            assert r["mismatches"] == 0
            rows.append({"what": f"{variant} core alone", "simulator": sim, "samples": samples,
                         "loop_samples_per_s": r["samples_per_s"], "test_samples_per_s": samples / r["wall_s"]})
    config = FilterConfig()
    for variant, samples in (("steady", samples_arg * 4), ("full", max(samples_arg * 4 // 10, 1000))):
        for sim in sims:
            n = samples if sim == "verilator" else samples // 10
            words = [{"channel": 0, "y": int(c)} for c in stress_codes(SEED, n)]
            t0 = time.perf_counter()
            r = corerun.run(corerun.build(sim, config=config, variant=variant), words=words, seed=SEED, tag="bench")
            assert r["mismatches"] == 0 and r["ok"]
            rows.append({"what": f"{variant} core alone, source and sink in the simulator", "simulator": sim,
                         "samples": n, "loop_samples_per_s": r["samples_per_s"],
                         "test_samples_per_s": n / (time.perf_counter() - t0)})
    return rows


def _system_rows(sims, system_samples):
    """The whole design: the Python ADC model (cocotb), then the Verilog one (kfpga_cosim)."""
    rows = []
    for variant in ("steady", "full"):
        for sim in sims:
            # the Python ADC model is the slower: fewer estimates
            n_py = max(system_samples // (10 if sim == "verilator" else 20), 100)
            r = run(build(sim, "top", variant=variant), "test_top", testcase="system_bit_exact",
                    params={"variant": variant, "seed": SEED, "samples": n_py}, tag="bench")
            assert r["mismatches"] == 0
            rows.append({"what": f"whole design, {variant}, 1 channel, Python ADC (cocotb)", "simulator": sim,
                         "samples": r["samples"], "loop_samples_per_s": None,
                         "test_samples_per_s": r["samples"] / r["wall_s"]})
            n = system_samples if sim == "verilator" else max(system_samples // 10, 100)
            r = system.run(system.build(sim, variant=variant), params={"seed": SEED}, samples=n, tag="bench")
            assert r["mismatches"] == 0 and r["ok"]
            rows.append({"what": f"whole design, {variant}, 1 channel, Verilog ADC (kfpga_cosim)", "simulator": sim,
                         "samples": r["samples"], "loop_samples_per_s": r["samples_per_s"],
                         "test_samples_per_s": r["samples"] / r["wall_total_s"]})
    return rows


if __name__ == "__main__":
    raise SystemExit(main())
