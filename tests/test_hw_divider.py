# amaranth: UnusedElaboratable=no
"""The restoring divider against Python integer division (Amaranth simulator)."""

import random

import pytest
from amaranth.sim import Simulator

from kfpga.core.config import FilterConfig
from kfpga.hw.divider import Divider
from kfpga.hw.kalman2 import FullCore
from kfpga.sim.amaranth_streams import run_with_deadline


def expected(dividend, divisor, n):
    if divisor == 0 or dividend >= divisor << n:
        return (1 << n) - 1, 1
    return dividend // divisor, 0


def run_divider(dut, requests, seed):
    """Feed ``requests`` with random gaps, drain with random stalls; return the results."""
    rng = random.Random(seed)
    results = []
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def producer(ctx):
        for dividend, divisor in requests:
            while rng.random() < 0.3:
                await ctx.tick()
            ctx.set(dut.i.payload, {"dividend": dividend, "divisor": divisor})
            ctx.set(dut.i.valid, 1)
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)

    async def consumer(ctx):
        while len(results) < len(requests):
            ready = rng.random() < 0.7
            ctx.set(dut.o.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            if valid and ready:
                results.append((payload.quotient, payload.overflow))

    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    # a hang fails: every request takes latency + 1 cycles, at the offered rates far fewer than this
    run_with_deadline(sim, 20 * (dut.latency + 2) * len(requests) + 1000)
    return results


@pytest.mark.parametrize(("dividend_bits", "divisor_bits", "quotient_bits"), [(6, 4, 3), (5, 5, 5), (7, 3, 1)])
def test_divider_exhaustive_small(dividend_bits, divisor_bits, quotient_bits, seed):
    dut = Divider(dividend_bits=dividend_bits, divisor_bits=divisor_bits, quotient_bits=quotient_bits)
    requests = [(a, b) for a in range(1 << dividend_bits) for b in range(1 << divisor_bits)]
    results = run_divider(dut, requests, seed)
    assert results == [expected(a, b, quotient_bits) for a, b in requests]


def test_divider_random_at_the_kalman_widths(seed):
    core = FullCore(FilterConfig())
    n = core.quotient_bits
    dividend_bits = core.dividend_bits
    divisor_bits = FilterConfig().formats["s"].width
    dut = Divider(dividend_bits=dividend_bits, divisor_bits=divisor_bits, quotient_bits=n)
    rng = random.Random(seed)
    requests = []
    for _ in range(1500):
        divisor = rng.choice([rng.randrange(1, 1 << divisor_bits), rng.randrange(1, 64), (1 << divisor_bits) - 1])
        kind = rng.random()
        if kind < 0.7:  # quotients that fit, the common case
            dividend = rng.randrange(0, divisor << n)
        elif kind < 0.8:  # the boundary
            dividend = (divisor << n) - rng.randrange(0, 2)
        else:
            dividend = rng.randrange(0, 1 << dividend_bits)
        requests.append((min(dividend, (1 << dividend_bits) - 1), divisor))
    requests += [(0, 0), (5, 0), ((1 << dividend_bits) - 1, 1)]
    results = run_divider(dut, requests, seed)
    assert results == [expected(a, b, n) for a, b in requests]


def test_divider_latency_is_constant():
    dut = Divider(dividend_bits=8, divisor_bits=4, quotient_bits=5)
    seen = {}
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def bench(ctx):
        ctx.set(dut.o.ready, 1)
        for label, (a, b) in {"normal": (77, 9), "overflow": (255, 1), "zero": (3, 0)}.items():
            ctx.set(dut.i.payload, {"dividend": a, "divisor": b})
            ctx.set(dut.i.valid, 1)
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)
            cycles = 0
            while True:
                cycles += 1
                *_, valid = await ctx.tick().sample(dut.o.valid)
                if valid:
                    break
            seen[label] = cycles

    sim.add_testbench(bench)
    run_with_deadline(sim, 10 * (dut.latency + 2) * 3 + 100)  # three divisions
    assert set(seen.values()) == {dut.latency}, seen


def test_divider_rejects_bad_widths():
    with pytest.raises(ValueError, match="^quotient_bits must be a positive integer, not 0$"):
        Divider(dividend_bits=8, divisor_bits=4, quotient_bits=0)
