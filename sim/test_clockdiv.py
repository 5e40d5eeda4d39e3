"""cocotb: the clock divider's strobe period and output duty cycle on the generated Verilog."""

import itertools

import cocotb
from cocotb.clock import Clock
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, Edge, ReadOnly, RisingEdge

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.sim.bench import deadline, sim_params, write_results


@cocotb.test(**deadline(0, default_samples=0, fixed_us=100))  # 40 ADC periods take 8 us
async def divider_ratio_and_duty(dut):
    p = sim_params()
    ratio = int(p.get("ratio", 10))
    Clock(dut.clk, SYSTEM_PERIOD_NS, unit="ns").start()
    dut.rst.value = 0
    await ClockCycles(dut.clk, 2 * ratio)
    samples = []  # (strobe, clk_out) of each system cycle, read once the cycle has settled
    for _ in range(20 * ratio):
        await RisingEdge(dut.clk)
        await ReadOnly()
        samples.append((int(dut.strobe.value), int(dut.clk_out.value)))
    strobes = [k for k, (s, _) in enumerate(samples) if s]
    # clk_out rises in the cycle after each strobe, and only then
    rises = [k - 1 for k in range(1, len(samples)) if samples[k][1] and not samples[k - 1][1]]
    await RisingEdge(dut.clk)
    edges = []
    for _ in range(20):
        await Edge(dut.clk_out)
        edges.append((get_sim_time("ns"), int(dut.clk_out.value)))
    highs = {round(b[0] - a[0]) for a, b in itertools.pairwise(edges) if a[1] == 1}
    lows = {round(b[0] - a[0]) for a, b in itertools.pairwise(edges) if a[1] == 0}
    periods = {b - a for a, b in itertools.pairwise(strobes)}
    report = {"ratio": ratio, "strobe_periods": sorted(periods), "high_ns": sorted(highs), "low_ns": sorted(lows),
              "rises_after_strobes": rises == [k for k in strobes if k < len(samples) - 1]}
    write_results(p, report)
    assert periods == {ratio}, report
    assert rises == [k for k in strobes if k < len(samples) - 1] and strobes, report
    assert highs == {20 * (ratio // 2)} and lows == {20 * (ratio - ratio // 2)}, report
