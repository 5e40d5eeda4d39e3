# amaranth: UnusedElaboratable=no
"""The whole design (hw/top.py) at its pins, in the Amaranth simulator, with the ADS8364 model.

The co-simulation (tests/test_cosim.py) runs the generated Verilog for thousands of estimates;
these run in seconds and look at the top level itself: which HOLD pin starts each conversion,
that no other HOLD moves, that every read is the conversion just made, and that ``out_data``,
``out_channel`` and ``out_overflow`` are the model's on exactly the samples read.
"""

import numpy as np
import pytest
from amaranth.sim import Simulator

from kfpga.core.board import SYSTEM_PERIOD_NS, Board
from kfpga.core.config import FilterConfig
from kfpga.hw.top import FilterSystem
from kfpga.sim.ads8364 import ADS8364
from kfpga.sim.amaranth_streams import run_with_deadline
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.sources import Source, scenario_source

PIN_OF = {"clk": "adc_clk", "hold_a": "adc_hold_a_n", "hold_b": "adc_hold_b_n", "hold_c": "adc_hold_c_n",
          "reset": "adc_reset_n", "wr": "adc_wr_n", "cs": "adc_cs_n", "rd": "adc_rd_n", "addr": "adc_addr"}


def run_system(top, source, estimates, *, max_cycles=200_000):
    """Clock ``top`` through its ``clk50`` pin with the ADC model on its pins until ``estimates``
    estimates came out. Returns the estimates ``(channel, x1, sticky)``, the ADC model and the
    times (ns) each HOLD pin fell."""
    adc = ADS8364(source)
    out, falls = [], {"hold_a": [], "hold_b": [], "hold_c": []}
    half = SYSTEM_PERIOD_NS / 2 * 1e-9

    async def bench(ctx):
        ctx.set(top.rst_n, 0)
        last = {pin: ctx.get(getattr(top, port)) for pin, port in PIN_OF.items()}
        pending = adc.pins(0, last)  # the power-up levels, before the first edge
        for cycle in range(max_cycles):
            if cycle == 4:
                ctx.set(top.rst_n, 1)
            ctx.set(top.clk50, 1)
            await ctx.delay(half / 10)  # the registers have moved
            t = (cycle + 1) * SYSTEM_PERIOD_NS
            levels = {pin: ctx.get(getattr(top, port)) for pin, port in PIN_OF.items()}
            for pin in falls:
                if last[pin] and not levels[pin]:
                    falls[pin].append(t)
            last = levels
            pending += adc.pins(t, levels)
            for event in [e for e in pending if e[0] <= t]:
                _, name, value = event
                if name == "eoc":
                    ctx.set(top.adc_eoc_n, value)
                else:
                    ctx.set(top.adc_data, 0 if value is None else value & 0xFFFF)
            pending = [e for e in pending if e[0] > t]
            if ctx.get(top.out_valid):
                out.append((ctx.get(top.out_channel), ctx.get(top.out_data), ctx.get(top.out_overflow)))
                if len(out) == estimates:
                    return
            await ctx.delay(half - half / 10)
            ctx.set(top.clk50, 0)
            await ctx.delay(half)
        raise AssertionError(f"{len(out)} of {estimates} estimates in {max_cycles} cycles")

    sim = Simulator(top)
    sim.add_testbench(bench)
    run_with_deadline(sim, max_cycles + 10, period=SYSTEM_PERIOD_NS * 1e-9)
    return out, adc, falls


def check_against_model(config, variant, out, adc):
    """Every estimate is the model's on the codes the ADC drove, and every read was fresh: the
    conversion the HOLD just started, with the source's code of that instant."""
    board = Scoreboard(config, variant)
    for r in adc.reads[: len(out)]:
        board.add_input(r.channel, r.code)
    for channel, x1, sticky in out:
        board.add_output(channel=channel, x1=x1, sticky=sticky)
    report = board.assert_ok()
    assert report["compared"] == len(out)
    return report


@pytest.mark.parametrize("channel", [1, 2, 4, 5], ids=["A1", "B0", "C0", "C1"])
def test_single_channel_drives_its_own_hold_pin(channel, seed):
    config = FilterConfig()
    top = FilterSystem(config, variant="steady", channel=channel)
    source = scenario_source("sine", 64, seed)
    out, adc, falls = run_system(top, source, 8)
    pair = "abc"[channel // 2]
    assert len(falls[f"hold_{pair}"]) >= 8
    assert all(not falls[f"hold_{p}"] for p in "abc" if p != pair), falls  # the other HOLDs never move
    assert adc.conversions >= 8
    expected = source.expected(len(out))
    # each read is of the conversion just made and carries the source's code for this channel
    assert [r.channel for r in adc.reads[:8]] == [channel] * 8
    assert [r.conversion for r in adc.reads[:8]] == list(range(8))
    assert [r.code for r in adc.reads[:8]] == list(expected[channel, :8])
    assert all(c == channel for c, _, _ in out)
    check_against_model(config, "steady", out, adc)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_six_channels_pull_all_three_holds_at_once(variant, seed):
    config = FilterConfig()
    top = FilterSystem(config, variant=variant, six_channel=True)
    source = scenario_source("sine", 64, seed)
    out, adc, falls = run_system(top, source, 18)
    assert falls["hold_a"] == falls["hold_b"] == falls["hold_c"] and len(falls["hold_a"]) >= 3
    assert [c for c, _, _ in out] == [0, 1, 2, 3, 4, 5] * 3
    expected = source.expected(3)
    assert [r.code for r in adc.reads[:18]] == [int(expected[c, k]) for k in range(3) for c in range(6)]
    check_against_model(config, variant, out, adc)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_the_timer_starts_a_conversion_every_period(variant, seed):
    """A [board] sample rate slower than the free-running ADC: the HOLD pin falls once every
    clock / rate cycles (600 here, 83.3 kHz), never faster, and every estimate is the model's."""
    config = FilterConfig(board=Board(sample_rate_hz=50e6 / 600))
    top = FilterSystem(config, variant=variant, channel=0)
    assert top.frontend.conversion_cycles == 600
    source = scenario_source("sine", 64, seed)
    out, adc, falls = run_system(top, source, 6, max_cycles=6_000)
    # the first conversion right after reset, then one on each tick of the timer (which counts
    # from reset, so the first gap is shorter by the first conversion's start)
    gaps = np.diff(falls["hold_a"]) / SYSTEM_PERIOD_NS
    assert len(gaps) >= 5 and set(gaps[1:]) == {600} and 0 < gaps[0] <= 600, gaps
    check_against_model(config, variant, out, adc)


def test_saturation_reaches_the_overflow_pin(seed):
    """Full-scale square waves on the input saturate the innovation: out_overflow rises with the
    model's first flag and stays (sticky)."""
    codes = np.tile(np.repeat([32767, -32768], 3), 6)
    top = FilterSystem(FilterConfig(), variant="steady", channel=0)
    out, adc, _ = run_system(top, Source(np.tile(codes, (6, 1))), 24)
    report = check_against_model(FilterConfig(), "steady", out, adc)
    assert report["compared"] == 24
    flags = [s for _, _, s in out]
    assert flags[-1] == 1 and flags[0] == 0 and sorted(flags) == flags  # rises once, stays
