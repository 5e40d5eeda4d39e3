"""Benchmark: resources, estimated Fmax and track rate of the alpha-beta many-track core.

For each track count, the core's generated Verilog goes through the project's Yosys flow
(``kfpga/hw/resources.py``: logic cells, multipliers, memory bits, the carry-aware timing
estimate of the -8 part); the M4K blocks are counted for the state memory's depth and width
(Cyclone II M4K configurations; Yosys maps memories for Cyclone IV's M9K, so its own block
count does not apply). One measurement per clock across tracks: a 2-D track update (two
axes) every two clocks, at the estimated Fmax and at the board's 50 MHz.

    python bench/bench_tracker.py [--tracks 1,3,8,64,256] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from kfpga.core.config import FilterConfig
from kfpga.hw.alphabeta import TrackerCore
from kfpga.hw.generate import to_verilog
from kfpga.hw.resources import EP2C20, estimate

BOARD_MHZ = 50.0


def measure(config, tracks, work):
    dut = TrackerCore(config, tracks=tracks)
    path = Path(work) / f"tracker_{tracks}.v"
    path.write_text(to_verilog(dut, "kfpga_tracker"))
    r = estimate(path, "kfpga_tracker")
    fmax = r["fmax_mhz_estimate"]
    return {"tracks": tracks, "states": 2 * tracks, "storage": "M4K" if dut.m4k_blocks else "registers",
            "logic_cells": r["logic_cells"], "mul18": r["mul18"],
            "memory_bits": 2 * tracks * dut.core_word_bits if dut.m4k_blocks else 0,
            "m4k_blocks": dut.m4k_blocks, "fmax_mhz_estimate": fmax, "worst_path_ns": r["worst_path_ns"],
            "track_updates_per_s_at_fmax": fmax * 1e6 / 2, "track_updates_per_s_at_50mhz": BOARD_MHZ * 1e6 / 2}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", default="1,3,8,64,256", help="track counts, comma-separated (default 1,3,8,64,256)")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = parser.parse_args(argv)
    try:
        counts = [int(t) for t in args.tracks.split(",")]
    except ValueError:
        parser.exit(2, f"{parser.prog}: error: --tracks must be integers separated by commas, not {args.tracks!r}\n")
    config = FilterConfig(filter="alpha-beta")
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for t in counts:
            print(f"synthesising {t} track(s)...", file=sys.stderr, flush=True)
            rows.append(measure(config, t, work))
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"alpha-beta tracker, default formats (x {config.formats['x1']}, v {config.formats['v']}); EP2C20: "
          f"{EP2C20['logic_elements']} LEs, {EP2C20['m4k_blocks']} M4K")
    print("| tracks | states in | logic cells | 18x18 multipliers | M4K blocks | memory bits | Fmax estimate (MHz) | "
          "2-D track updates/s at 50 MHz |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['tracks']} | {r['storage']} | {r['logic_cells']} | {r['mul18']} | {r['m4k_blocks']} | "
              f"{r['memory_bits']} | {r['fmax_mhz_estimate']:.1f} | {r['track_updates_per_s_at_50mhz'] / 1e6:.0f} M |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
