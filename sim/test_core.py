"""cocotb: a filter core alone, on its generated Verilog, against the bit-accurate model."""

import time

import cocotb
import numpy as np
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, with_timeout

from kfpga.sim.bench import CoreTB, sim_params, write_results
from kfpga.sim.sources import stress_codes
from kfpga.sim.streams import pump


@cocotb.test()
async def core_bit_exact(dut):
    """Every sample in, one estimate out, every integer equal to the model's.

    With ``p_idle = 0`` and ``p_ready = 1`` the core runs at its full rate.
    """
    p = sim_params()
    tb = CoreTB(dut, p)
    n = int(p.get("samples", 2000))
    codes = stress_codes(p["seed"], n)
    rng = np.random.default_rng(p["seed"] + 2)
    count = p.get("channels", 1)
    if p.get("order") == "round-robin":  # channels in turn: what a C-slow core takes at full rate
        channels = np.arange(n) % count
    else:
        channels = rng.integers(0, count, n) if count > 1 else np.zeros(n, dtype=int)
    await tb.reset()
    start_ns = get_sim_time("ns")
    t0 = time.perf_counter()
    name = tb.config.inputs[0]
    words = [{"channel": int(c), name: int(v)} for c, v in zip(channels, codes, strict=True)]
    await with_timeout(pump(dut.clk, tb.source, tb.sink, words), 100 * n * 25 + 1000, "ns")
    wall = time.perf_counter() - t0
    cycles = (get_sim_time("ns") - start_ns) / 20
    await ClockCycles(dut.clk, 40)
    extra = int(dut.o__valid.value)  # a further estimate waiting would be one too many
    for c, v in zip(channels, codes, strict=True):
        tb.scoreboard.add_input(c, v)
    for word in tb.sink.words:
        tb.scoreboard.add_output(**word)
    report = tb.scoreboard.check()
    # samples/s of the clocked loop itself: stimulus packing and result unpacking are outside it
    report.update({"samples": report["compared"], "wall_s": wall, "loop_s": tb.sink.loop_s,
                   "samples_per_s": n / tb.sink.loop_s, "cycles": cycles, "cycles_per_sample": cycles / n,
                   "extra_after_end": extra})
    write_results(p, report)
    assert report["ok"] and not extra, report
