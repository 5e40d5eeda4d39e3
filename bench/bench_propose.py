"""Benchmark: the word-length search of ``kfpga propose`` with 1 seed and with 10, on one model.

The seeds of a scenario are the rows of one batch of the compiled model, so searching ten costs
little more than searching one; this prints both times and their ratio, from one run on one
machine (compare the ratio, not the seconds). The model: the paper's steady-state filter at
T = 1 and a 3-state constant-acceleration tracker at T = 0.01 s (both variants).

    python bench/bench_propose.py [--samples N] [--json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from kfpga.core.config import FilterConfig
from kfpga.flows.propose import Signal, propose
from kfpga.model import scenarios
from kfpga.model.kalman import StateSpaceParams

SEED = 20261204


def tracker():
    """The 3-state constant-acceleration tracker at T = 0.01 s."""
    t = 0.01
    return FilterConfig(filter="kalman", params=StateSpaceParams(
        F=((1.0, t, t * t / 2), (0.0, 1.0, t), (0.0, 0.0, 1.0)), G=((0.0,), (0.0,), (1.0,)), Q=((1.0,),),
        H=((1.0, 0.0, 0.0),), R=((25.0,),), T=t))


def search(config, variants, seeds, samples):
    runs = [scenarios.for_config("sine", samples, SEED + s, config) for s in range(seeds)]
    signal = Signal(np.stack([t for t, _ in runs]), np.stack([y for _, y in runs]), [f"seed {SEED + s}" for s in range(seeds)])
    t0 = time.perf_counter()
    result = propose(config, variants, [signal])
    return time.perf_counter() - t0, result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4000, help="samples per seed (default: 4000)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    print(f"seed {SEED}")
    rows = []
    for label, config, variants in (("paper's filter, steady, T = 1", FilterConfig(), ["steady"]),
                                    ("3-state tracker, T = 0.01 s, both variants", tracker(), ["steady", "full"])):
        for seeds in (1, 10):
            seconds, result = search(config, variants, seeds, args.samples)
            rows.append({"model": label, "seeds": seeds, "seconds": seconds, "candidates": result.evaluations,
                         "worst_rmse_change": result.metrics["worst_rmse_change"]})
    info = {"samples_per_seed": args.samples, "machine": f"{platform.machine()}, Python {platform.python_version()}"}
    if args.json:
        print(json.dumps({"rows": rows, **info}, indent=2))
        return 0
    print(f"kfpga propose, {args.samples} samples per seed, {info['machine']}")
    print(f"{'model':<46}{'seeds':>6}{'candidates':>12}{'seconds':>10}{'s/candidate':>13}{'ratio 10/1':>12}")
    for r in rows:
        one = next(o for o in rows if o["model"] == r["model"] and o["seeds"] == 1)
        per, per_one = r["seconds"] / r["candidates"], one["seconds"] / one["candidates"]
        ratio = f"{r['seconds'] / one['seconds']:.2f}x ({per / per_one:.2f}x)" if r["seeds"] == 10 else ""
        print(f"{r['model']:<46}{r['seeds']:>6}{r['candidates']:>12}{r['seconds']:>10.1f}{per:>13.2f}{ratio:>18}")
    print("ratio: the whole search (per candidate in brackets; the searches may try different candidates)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
