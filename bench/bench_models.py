"""The example models (``examples/models``) with their default formats and with formats ``propose``d
for them: both variants, the fixed-point RMSE against float's on five seeds the search did not see,
and a co-simulation of each design on Verilator and Icarus.

For each model: ``propose`` searches every variant at once on seeds 1..4 of the filter's default
scenario (``--samples`` samples each), and writes ``examples/models/<model>.proposed.toml``
(``--reuse`` takes the files already there instead); then, for the default and the proposed
formats and each variant, ``compare`` runs seeds 1001..1005 (20,000 samples) and the core that
``--architecture auto`` chooses at the model's ``[board]`` rate runs ``--cosim`` samples on each
simulator against the model. Prints the table; ``--json`` writes the figures to
``build/models/models.json``.

    python bench/bench_models.py [--reuse] [--samples N] [--cosim N] [--only NAME]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from kfpga.core.config import FilterConfig
from kfpga.flows.analysis import compare
from kfpga.flows.explore import candidates, choose
from kfpga.flows.propose import Signal, proposal_toml, propose
from kfpga.model import scenarios

MODELS = Path(__file__).resolve().parents[1] / "examples" / "models"
SEARCH_SEEDS = (1, 2, 3, 4)
UNSEEN_SEEDS = (1001, 1002, 1003, 1004, 1005)


def model_files(only=None):
    return [p for p in sorted(MODELS.glob("*.toml")) if not p.stem.endswith(".proposed") and (only is None or only in p.stem)]


def variants(config):
    return [name for name, v in config.spec.model.variants.items() if v.applies(config.params) is None]


def proposed(path, config, *, samples, reuse):
    """The proposal for ``config`` (searched now, or the file ``propose`` wrote before)."""
    out = path.with_name(path.stem + ".proposed.toml")
    if reuse and out.exists():
        return FilterConfig.from_toml(out), None
    scenario = config.spec.model.scenarios[0]
    runs = [scenarios.for_config(scenario, samples, s, config) for s in SEARCH_SEEDS]
    ys = [y for _, y in runs]
    codes = {k: np.stack([y[k] for y in ys]) for k in ys[0]} if isinstance(ys[0], dict) else np.stack(ys)
    signal = Signal(np.stack([t for t, _ in runs]), codes, [f"seed {s}" for s in SEARCH_SEEDS])
    t0 = time.perf_counter()
    result = propose(config, variants(config), [signal])
    seconds = time.perf_counter() - t0
    described = [f"scenario {scenario}, {samples} samples, seeds {SEARCH_SEEDS[0]}..{SEARCH_SEEDS[-1]}"]
    out.write_text(proposal_toml(result, config.ranges(), budget=0.01, objective="multipliers", seconds=seconds,
                                 signals=described))
    return FilterConfig.from_toml(out), seconds


def unseen(config, variant):
    """The fixed RMSE over float's, one ratio per unseen seed."""
    scenario = config.spec.model.scenarios[0]
    out = []
    for seed in UNSEEN_SEEDS:
        truth, y = scenarios.for_config(scenario, 20000, seed, config)
        out.append(compare(config, variant, y, truth, limit_cycle=False).metrics["rmse_fixed_over_float"])
    return out


def cosim(config, variant, samples):
    """The chosen design on each simulator: ``{simulator: mismatches}`` and the design's figures."""
    from kfpga.sim.runner import SIMULATORS, build, run

    rate = config.board.sample_rate_hz or 1000.0
    best = choose(candidates(config, variant, channels=1, clock_hz=config.board.clock_hz, need_hz=rate))
    options = {"architecture": best.architecture, **({} if best.stages is None else {"stages": best.stages})}
    out = {}
    for simulator in SIMULATORS:
        result = run(build(simulator, "core", config=config, variant=variant, channels=1, **options), "test_core",
                     testcase="core_bit_exact",
                     params={"variant": variant, "seed": 7, "samples": samples, "channels": 1, "p_idle": 0.2,
                             "p_ready": 0.7, "config_toml": config.to_toml(), **options}, tag=f"models-{variant}")
        out[simulator] = result["mismatches"] if result["ok"] else f"failed: {result.get('first_mismatches')}"
    return out, best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reuse", action="store_true", help="take the proposals already in examples/models")
    parser.add_argument("--samples", type=int, default=4000, help="samples of each seed propose searches (default 4000)")
    parser.add_argument("--cosim", type=int, default=200, help="samples of each co-simulation (default 200)")
    parser.add_argument("--only", metavar="NAME", help="the models whose file name has NAME")
    parser.add_argument("--json", action="store_true", help="also write build/models/models.json")
    args = parser.parse_args(argv)
    rows = []
    for path in model_files(args.only):
        config = FilterConfig.from_toml(path)
        search, seconds = proposed(path, config, samples=args.samples, reuse=args.reuse)
        for formats, cfg in (("default", config), ("proposed", search)):
            for variant in variants(config):
                ratios = unseen(cfg, variant)
                sims, best = cosim(cfg, variant, args.cosim)
                row = {"model": path.stem, "formats": formats, "variant": variant, "worst_change": max(abs(r - 1) for r in ratios),
                       "ratios": ratios, "cosim": sims, "design": best.label, "logic_cells": best.logic_cells,
                       "fmax_mhz": best.fmax_mhz, "search_s": seconds if formats == "proposed" else None}
                rows.append(row)
                print(f"{path.stem:<12} {formats:<8} {variant:<6} worst {100 * row['worst_change']:.3f} % of float "
                      f"over seeds {UNSEEN_SEEDS[0]}..{UNSEEN_SEEDS[-1]}; {best.label}, {best.logic_cells} cells, "
                      f"{best.fmax_mhz:g} MHz; mismatches {sims}", flush=True)
    if args.json:
        out = Path("build") / "models"
        out.mkdir(parents=True, exist_ok=True)
        (out / "models.json").write_text(json.dumps(rows, indent=1))
    bad = [r for r in rows if r["worst_change"] > 0.01 or any(v != 0 for v in r["cosim"].values())]
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
