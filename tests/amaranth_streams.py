"""Stream driver and monitor for Amaranth async testbenches, with random backpressure."""

import random

from amaranth.sim import Simulator


async def drive(ctx, port, payloads, rng, p_idle=0.0):
    """Send ``payloads`` on stream ``port``, idling for a cycle with probability ``p_idle``."""
    for payload in payloads:
        while p_idle and rng.random() < p_idle:
            await ctx.tick()
        ctx.set(port.payload, payload)
        ctx.set(port.valid, 1)
        await ctx.tick().until(port.ready)
        ctx.set(port.valid, 0)


async def collect(ctx, port, count, rng, p_ready=1.0, out=None):
    """Receive ``count`` payloads from ``port``, ready with probability ``p_ready`` each cycle."""
    out = [] if out is None else out
    while len(out) < count:
        ready = rng.random() < p_ready
        ctx.set(port.ready, ready)
        _, _, valid, payload = await ctx.tick().sample(port.valid, port.payload)
        if valid and ready:
            out.append(payload)
    ctx.set(port.ready, 0)
    return out


def run_stream(dut, payloads, *, seed, p_idle=0.0, p_ready=1.0, extra_cycles=0, vcd=None):
    """Push ``payloads`` through ``dut.i`` -> ``dut.o``; return the output payloads.

    Fails (by timing out in the simulator) if fewer outputs than inputs come out; after all
    expected outputs, runs ``extra_cycles`` more and checks that no further output appears.
    """
    rng_in, rng_out = random.Random(seed), random.Random(seed + 1)
    results, extra = [], []
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def producer(ctx):
        await drive(ctx, dut.i, payloads, rng_in, p_idle)

    async def consumer(ctx):
        await collect(ctx, dut.o, len(payloads), rng_out, p_ready, results)
        ctx.set(dut.o.ready, 1)
        for _ in range(extra_cycles):
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            if valid:
                extra.append(payload)

    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    if vcd:
        with sim.write_vcd(vcd):
            sim.run()
    else:
        sim.run()
    assert not extra, f"{len(extra)} output(s) beyond one per input"
    return results
