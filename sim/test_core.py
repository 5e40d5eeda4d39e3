"""cocotb: a filter core alone, on its generated Verilog, against the bit-accurate model."""

import time

import cocotb
import numpy as np
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, ReadOnly, RisingEdge, with_timeout

from kfpga.hw.cores import make_core
from kfpga.sim.bench import CoreTB, deadline, sim_params, write_results
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.sources import stress_codes
from kfpga.sim.streams import pump


async def levels(dut, signal, cycles):
    """The settled level of ``signal`` in each of the next ``cycles`` clock cycles."""
    out = []
    for _ in range(cycles):
        await RisingEdge(dut.clk)
        await ReadOnly()
        out.append(int(signal.value))
    await RisingEdge(dut.clk)
    return out


@cocotb.test(**deadline(40, default_samples=2000))
async def core_bit_exact(dut):
    """Every sample in, one estimate out, every integer equal to the model's.

    With ``p_idle = 0`` and ``p_ready = 1`` the core runs at its full rate.
    """
    p = sim_params()
    tb = CoreTB(dut, p)
    # ``codes``: the first input's samples (a filter's own signal), else the stress signal
    codes = np.array(p["codes"], dtype=np.int64) if "codes" in p else stress_codes(p["seed"], int(p.get("samples", 2000)))
    n = len(codes)
    rng = np.random.default_rng(p["seed"] + 2)
    count = p.get("channels", 1)
    if p.get("order") == "round-robin":  # channels in turn: what a C-slow core takes at full rate
        channels = np.arange(n) % count
    elif p.get("order") == "runs":  # random channels, each 1 to 3 times in a row (read-after-write)
        channels = np.repeat(rng.integers(0, count, n), rng.integers(1, 4, n))[:n]
    else:
        channels = rng.integers(0, count, n) if count > 1 else np.zeros(n, dtype=int)
    await tb.reset()
    sticky_at_start = await levels(dut, dut.overflow, 4)  # nothing has saturated yet
    start_ns = get_sim_time("ns")
    t0 = time.perf_counter()
    # one stress signal per input (a model with two observations gets two different ones)
    names = tb.config.inputs
    columns = {name: codes if j == 0 else stress_codes(p["seed"] + 7 * j, n) for j, name in enumerate(names)}
    words = [{"channel": int(c), **{name: int(columns[name][i]) for name in names}} for i, c in enumerate(channels)]
    # the deadline: ten times the cycles the core needs at the offered rates, so a hang fails
    per_update = make_core(tb.config, p["variant"], channels=count,
                                          architecture=p.get("architecture")).cycles_per_update
    rate = (1 - float(p.get("p_idle", 0.0))) * float(p.get("p_ready", 1.0))
    await with_timeout(pump(dut.clk, tb.source, tb.sink, words), int(10 * n * (per_update + 2) / rate + 1000) * 20,
                       "ns")
    wall = time.perf_counter() - t0
    cycles = (get_sim_time("ns") - start_ns) / 20
    await ClockCycles(dut.clk, 40)
    extra = int(dut.o__valid.value)  # a further estimate waiting would be one too many
    # the sticky flag: the OR of every estimate's flag since reset (the per-sample flags are the
    # model's, checked below)
    sticky_at_end = await levels(dut, dut.overflow, 4)
    for i, c in enumerate(channels):
        tb.scoreboard.add_input(c, {name: int(columns[name][i]) for name in names})
    for word in tb.sink.words:
        tb.scoreboard.add_output(**word)
    report = tb.scoreboard.check()
    # samples/s of the clocked loop itself: stimulus packing and result unpacking are outside it
    report.update({"samples": report["compared"], "wall_s": wall, "loop_s": tb.sink.loop_s,
                   "samples_per_s": n / tb.sink.loop_s, "cycles": cycles, "cycles_per_sample": cycles / n,
                   "extra_after_end": extra})
    report.update({"sticky_at_start": sticky_at_start, "sticky_at_end": sticky_at_end})
    write_results(p, report)
    assert report["ok"] and not extra, report
    assert sticky_at_start == [0] * 4 and sticky_at_end == [int(any(w["overflow"] for w in tb.sink.words))] * 4, report


@cocotb.test(**deadline(40, default_samples=2000))
async def core_idle_after_reset(dut):
    """The state holds however long the core waits: after each of four resets the first sample
    comes 0, 1, 2 or 3 idle cycles later, then samples at full rate, every estimate the model's
    (a state register that changes while the core idles reads another value after an odd wait)."""
    p = sim_params()
    tb = CoreTB(dut, p)
    tb.source.p_idle, tb.sink.p_ready = 0.0, 1.0
    n = max(8, min(40, int(p.get("samples", 2000)) // 4))
    names = tb.config.inputs
    per_update = make_core(tb.config, p["variant"], channels=tb.channels,
                                          architecture=p.get("architecture")).cycles_per_update
    compared = 0
    for gap in range(4):
        codes = {name: stress_codes(p["seed"] + 11 * gap + 7 * j, n) for j, name in enumerate(names)}
        words = [{"channel": 0, **{name: int(codes[name][i]) for name in names}} for i in range(n)]
        await tb.reset()
        if gap:
            await ClockCycles(dut.clk, gap)
        tb.sink.words, tb.scoreboard = [], Scoreboard(tb.config, tb.variant)
        await with_timeout(pump(dut.clk, tb.source, tb.sink, words), int(10 * n * (per_update + 2) + 1000) * 20, "ns")
        for word in words:
            tb.scoreboard.add_input(0, {name: word[name] for name in names})
        for word in tb.sink.words:
            tb.scoreboard.add_output(**word)
        report = tb.scoreboard.check()
        assert report["ok"], f"first sample {gap} cycles after reset: {report}"
        compared += report["compared"]
    write_results(p, {"ok": True, "samples": compared, "compared": compared, "mismatches": 0})
