# amaranth: UnusedElaboratable=no
"""Clock divider: strobe period, output duty cycle, alignment, and no glitch on reset."""

from itertools import pairwise

import pytest
from amaranth import ClockDomain, Elaboratable, Module
from amaranth.sim import Simulator

from kfpga.hw.clockdiv import ClockDivider
from kfpga.sim.amaranth_streams import run_with_deadline


class Top(Elaboratable):
    def __init__(self, ratio):
        self.div = ClockDivider(ratio=ratio)
        self.cd = ClockDomain("sync")

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = self.cd
        m.submodules.div = self.div
        return m


def trace(ratio, cycles, reset_at=()):
    top = Top(ratio)
    out = []
    sim = Simulator(top)
    sim.add_clock(2e-8, domain="sync")

    async def bench(ctx):
        out.append((ctx.get(top.div.strobe), ctx.get(top.div.clk_out)))
        for cycle in range(cycles):
            ctx.set(top.cd.rst, cycle in reset_at)
            await ctx.tick()
            out.append((ctx.get(top.div.strobe), ctx.get(top.div.clk_out)))

    sim.add_testbench(bench)
    run_with_deadline(sim, cycles + 10, period=2e-8)
    return out


def runs(levels):
    """Lengths of runs of equal values, as (value, length) pairs (first and last runs dropped)."""
    out, value, length = [], levels[0], 0
    for v in levels:
        if v == value:
            length += 1
        else:
            out.append((value, length))
            value, length = v, 1
    return out[1:]


@pytest.mark.parametrize("ratio", [2, 3, 4, 5, 7, 10, 11, 16])
def test_ratio_and_duty_cycle(ratio):
    t = trace(ratio, 20 * ratio)
    strobes = [i for i, (s, _) in enumerate(t) if s]
    assert all(b - a == ratio for a, b in pairwise(strobes))
    clk = [c for _, c in t]
    high = [n for v, n in runs(clk) if v == 1]
    low = [n for v, n in runs(clk) if v == 0]
    assert set(high) == {ratio // 2} and set(low) == {ratio - ratio // 2}
    # the cycle after a strobe is the first high cycle of clk_out
    for i in strobes:
        if i + 1 < len(t):
            assert clk[i + 1] == 1 and clk[i] == 0


def test_default_is_50_mhz_to_5_mhz_at_50_percent():
    t = trace(10, 200)
    clk = [c for _, c in t]
    assert {n for _, n in runs(clk)} == {5}


def test_reset_does_not_glitch_the_adc_clock():
    t = trace(10, 300, reset_at=range(57, 61))  # a reset in the middle of a low phase
    clk = [c for _, c in t]
    assert {n for _, n in runs(clk)} == {5}


def test_bad_ratio():
    with pytest.raises(ValueError, match="^ratio must be an integer >= 2, not 1$"):
        ClockDivider(ratio=1)
