"""Stream driver and monitor for Amaranth async testbenches, with random backpressure.

The Amaranth-simulator counterpart of ``sim/streams.py`` (cocotb): the same random policy
(an idle cycle before a word with probability ``p_idle``, ``ready`` high with probability
``p_ready``), the same one-output-per-input check, the same :class:`~kfpga.sim.scoreboard.Scoreboard`.
Every run has a cycle budget: a design that stops answering fails the test instead of hanging it.
"""

from __future__ import annotations

import random

import numpy as np
from amaranth.sim import Simulator

from kfpga.hw.cores import make_core
from kfpga.sim.scoreboard import Scoreboard

__all__ = ["drive", "collect", "run_stream", "run_core", "run_with_deadline", "measure_timing", "check_liveness",
           "StreamTimeout", "AFTER_VALID"]

#: The receiver's policy that raises ``ready`` only in the cycle after it has seen ``valid`` (a
#: receiver that waits for a word before it says it can take one): ``p_ready=AFTER_VALID``.
AFTER_VALID = "after valid"

CLOCK_PERIOD_S = 1e-8


class StreamTimeout(AssertionError):
    """The design did not produce the expected outputs within the cycle budget."""


def run_with_deadline(sim, cycles, what="the test", period=CLOCK_PERIOD_S):
    """``sim.run()``, failing with :class:`StreamTimeout` if the testbenches are still running
    after ``cycles`` clock periods (a hang becomes a failure)."""

    async def watchdog(ctx):
        try:
            await ctx.delay(cycles * period)  # one wake-up, not one per cycle
        except GeneratorExit:  # the simulation ended first: the testbenches finished in time
            return
        raise StreamTimeout(f"{what} did not finish within {cycles} cycles")

    sim.add_testbench(watchdog, background=True)
    sim.run()


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
    """Receive ``count`` payloads from ``port``, ready with probability ``p_ready`` each cycle
    (or, with :data:`AFTER_VALID`, only in the cycle after ``valid`` was seen high)."""
    out = [] if out is None else out
    seen = False
    while len(out) < count:
        ready = seen if p_ready == AFTER_VALID else rng.random() < p_ready
        ctx.set(port.ready, ready)
        _, _, valid, payload = await ctx.tick().sample(port.valid, port.payload)
        if valid and ready:
            out.append(payload)
        seen = bool(valid) and not ready
    ctx.set(port.ready, 0)
    return out


def run_stream(dut, payloads, *, seed, p_idle=0.0, p_ready=1.0, extra_cycles=0, max_cycles=None, vcd=None):
    """Push ``payloads`` through ``dut.i`` -> ``dut.o``; return the output payloads.

    Fails if fewer outputs than inputs come out within ``max_cycles`` (default: 200 per
    input plus 1000) and, after all expected outputs, if another appears within
    ``extra_cycles``.
    """
    rng_in, rng_out = random.Random(seed), random.Random(seed + 1)
    results, extra = [], []
    done = []
    sim = Simulator(dut)
    sim.add_clock(CLOCK_PERIOD_S)
    # the deadline: ten times what the core needs at the offered rates, so a hang fails
    per_update = getattr(dut, "cycles_per_update", 18) + 2
    rate = max((1 - p_idle) * (0.5 if p_ready == AFTER_VALID else p_ready), 0.05)
    budget = max_cycles if max_cycles is not None else int(10 * per_update * len(payloads) / rate) + 1000

    async def producer(ctx):
        await drive(ctx, dut.i, payloads, rng_in, p_idle)

    async def consumer(ctx):
        await collect(ctx, dut.o, len(payloads), rng_out, p_ready, results)
        ctx.set(dut.o.ready, 1)
        for _ in range(extra_cycles):
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            if valid:
                extra.append(payload)
        done.append(True)

    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    what = f"the stream of {len(payloads)} words (outputs so far: {{}})"
    try:
        if vcd:
            with sim.write_vcd(vcd):
                run_with_deadline(sim, budget + extra_cycles, what)
        else:
            run_with_deadline(sim, budget + extra_cycles, what)
    except StreamTimeout as exc:
        raise StreamTimeout(str(exc).format(len(results))) from None
    assert done
    assert not extra, f"{len(extra)} output(s) beyond one per input"
    return results


def run_core(config, variant, y, *, seed, channels=1, p_idle=0.0, p_ready=1.0, options=None, model_config=None,
             check=True):
    """Run codes ``y`` (random channels when ``channels > 1``) through the filter's core, and check
    every output field against the model with the :class:`Scoreboard`. ``y`` is an array, or
    ``{input: array}`` for a filter with several inputs; ``options`` go to the core.
    ``model_config``: the config of the model the core is checked against (default ``config``: a
    test that plants a fault in the core gives the right one here); ``check=False`` returns the
    report without failing on a mismatch.

    Returns the scoreboard's report, with ``got`` (each field's integers) and ``overflowed``.
    """
    rng = np.random.default_rng(seed)
    names = config.inputs
    columns = {k: np.asarray(v) for k, v in y.items()} if isinstance(y, dict) else {names[0]: np.asarray(y)}
    count = len(columns[names[0]])
    ch = rng.integers(0, channels, count) if channels > 1 else np.zeros(count, dtype=np.int64)
    dut = make_core(config, variant, channels=channels, **(options or {}))
    samples = [{name: int(columns[name][i]) for name in names} for i in range(count)]
    payloads = [{"channel": int(c), **s} for c, s in zip(ch, samples, strict=True)]
    out = run_stream(dut, payloads, seed=seed, p_idle=p_idle, p_ready=p_ready, extra_cycles=50)
    board = Scoreboard(model_config or config, variant)
    fields = ("channel", *config.output_names, "overflow")
    got = {f: np.array([int(getattr(o, f)) for o in out]) for f in fields}
    for c, s in zip(ch, samples, strict=True):
        board.add_input(c, s)
    for i in range(len(out)):
        board.add_output(**{f: got[f][i] for f in fields})
    report = board.assert_ok() if check else board.check()
    report["got"] = got
    report["overflowed"] = bool(got["overflow"].any())
    return report


def measure_timing(dut, config, updates=10):
    """``(latency, input intervals, output intervals)`` of a core fed one channel with ``valid``
    and ``ready`` held high: the cycles from the first input handshake to the first output, and
    the cycles between successive handshakes on each side."""
    accepted, produced = [], []
    sim = Simulator(dut)
    sim.add_clock(CLOCK_PERIOD_S)
    cycles = (updates + 2) * dut.cycles_per_update + dut.latency + 20

    async def bench(ctx):
        ctx.set(dut.o.ready, 1)
        ctx.set(dut.i.valid, 1)
        ctx.set(getattr(dut.i.payload, config.inputs[0]), 100)
        for cycle in range(cycles):
            _, _, ready, valid = await ctx.tick().sample(dut.i.ready, dut.o.valid)
            if ready:
                accepted.append(cycle)
            if valid:
                produced.append(cycle)

    sim.add_testbench(bench)
    run_with_deadline(sim, cycles + 100)
    return produced[0] - accepted[0], np.diff(accepted).tolist(), np.diff(produced).tolist()


def check_liveness(dut, payload, *, hold=20, settle=5):
    """The stream contract of ``dut`` with a slow receiver, in the Amaranth simulator; raises
    ``AssertionError`` naming the broken clause:

    1. with ``o.ready`` held low and nothing pending, ``i.ready`` is high once the unit's
       ``startup_cycles`` after reset have passed (it takes a word whatever its receiver does,
       as long as its output register is empty);
    2. a word taken while ``o.ready`` is low makes ``o.valid`` rise ``dut.latency`` cycles after
       the handshake, as with a ready receiver;
    3. ``o.valid`` and the payload then hold while ``o.ready`` stays low (``hold`` cycles);
    4. one cycle of ``o.ready`` takes the word, and ``o.valid`` falls.

    Returns ``{"latency": ..., "held_payload": ...}``.
    """
    sim = Simulator(dut)
    sim.add_clock(CLOCK_PERIOD_S)
    found = {}
    settle += getattr(dut, "startup_cycles", 0)
    budget = settle + dut.latency + hold + 40 + 4 * getattr(dut, "cycles_per_update", 1)

    async def bench(ctx):
        ctx.set(dut.o.ready, 0)
        ctx.set(dut.i.valid, 0)
        for _ in range(settle):
            await ctx.tick()
        assert ctx.get(dut.i.ready), "1: i.ready is low with o.ready low and nothing pending"
        ctx.set(dut.i.payload, payload)
        ctx.set(dut.i.valid, 1)
        cycle, taken = 0, None
        while True:
            _, _, ready, valid = await ctx.tick().sample(dut.i.ready, dut.o.valid)
            if taken is None and ready:
                taken = cycle
                ctx.set(dut.i.valid, 0)
            if valid:
                break
            cycle += 1
            assert cycle < budget, "2: o.valid never rose for a word taken while o.ready was low"
        found["latency"] = cycle - taken
        assert found["latency"] == dut.latency, (f"2: o.valid rose {found['latency']} cycles after the handshake "
                                                 f"with o.ready low; the declared latency is {dut.latency}")
        held = ctx.get(dut.o.payload)
        found["held_payload"] = held
        for k in range(hold):
            _, _, valid, now = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            assert valid, f"3: o.valid fell {k} cycles into a wait of the receiver, the word unread"
            assert now == held, f"3: the payload changed while o.valid waited for o.ready ({k} cycles in)"
        ctx.set(dut.o.ready, 1)
        _, _, valid = await ctx.tick().sample(dut.o.valid)
        assert valid, "4: o.valid fell before the receiver took the word"
        ctx.set(dut.o.ready, 0)
        _, _, valid = await ctx.tick().sample(dut.o.valid)
        assert not valid, "4: o.valid stayed high after the only word was taken"

    sim.add_testbench(bench)
    run_with_deadline(sim, budget + hold + 20, "the liveness check")
    return found
