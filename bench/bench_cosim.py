"""Benchmark: co-simulation speed of the generated Verilog, Verilator against Icarus, one run.

For each core alone, at full rate (valid and ready held high) with every estimate checked
against the model, it reports samples/s of the clocked cocotb loop (stimulus packed before
it, results unpacked after it) and of the whole test. For the whole design (ADS8364 model on
the pins) it reports estimates per wall second. Compare the ratios, not the absolute figures.

    python bench/bench_cosim.py [--samples N] [--system-samples N] [--json]
"""

from __future__ import annotations

import argparse
import json
import platform

from kfpga.sim.runner import SIMULATORS, build, run
from kfpga.tools import simulator_available

SEED = 20080525


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=50000, help="samples through the steady core (default 50000)")
    parser.add_argument("--system-samples", type=int, default=2000, help="estimates through the whole design")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    print(f"seed {SEED}")
    sims = [s for s in SIMULATORS if simulator_available(s)[0]]
    rows = []
    for variant, samples in (("steady", args.samples), ("full", max(args.samples // 10, 1000))):
        for sim in sims:
            r = run(build(sim, "core", variant=variant), "test_core",
                    params={"variant": variant, "seed": SEED, "samples": samples}, tag="bench")
            assert r["mismatches"] == 0
            rows.append({"what": f"{variant} core alone", "simulator": sim, "samples": samples,
                         "loop_samples_per_s": r["samples_per_s"], "test_samples_per_s": samples / r["wall_s"]})
    for variant in ("steady", "full"):
        for sim in sims:
            r = run(build(sim, "top", variant=variant), "test_top", testcase="system_bit_exact",
                    params={"variant": variant, "seed": SEED, "samples": args.system_samples}, tag="bench")
            assert r["mismatches"] == 0
            rows.append({"what": f"whole design, {variant}, 1 channel", "simulator": sim, "samples": r["samples"],
                         "loop_samples_per_s": None, "test_samples_per_s": r["samples"] / r["wall_s"]})
    ratios = {}
    for what in dict.fromkeys(r["what"] for r in rows):
        by = {r["simulator"]: r for r in rows if r["what"] == what}
        if {"verilator", "icarus"} <= set(by):
            key = "loop_samples_per_s" if by["verilator"]["loop_samples_per_s"] else "test_samples_per_s"
            ratios[what] = by["verilator"][key] / by["icarus"][key]
    machine = f"{platform.machine()}, Python {platform.python_version()}"
    if args.json:
        print(json.dumps({"rows": rows, "verilator_over_icarus": ratios, "machine": machine}, indent=2))
        return 0
    print(f"co-simulation speed, every estimate checked, {machine}")
    print(f"{'what':<34} {'simulator':<10} {'samples':>8} {'loop samples/s':>15} {'test samples/s':>15}")
    for r in rows:
        loop = f"{r['loop_samples_per_s']:,.0f}" if r["loop_samples_per_s"] else "-"
        print(f"{r['what']:<34} {r['simulator']:<10} {r['samples']:>8} {loop:>15} {r['test_samples_per_s']:>15,.0f}")
    for what, ratio in ratios.items():
        print(f"Verilator / Icarus, {what}: {ratio:.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
