"""The ADS8364 controller with its clock divider, wired to the behavioural ADC model (Amaranth sim)."""

import random

from amaranth import ClockDomain, Elaboratable, Module, Signal
from amaranth.sim import Simulator

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.hw.ads8364 import ADS8364Controller
from kfpga.hw.clockdiv import ClockDivider
from kfpga.sim.ads8364 import ADS8364

SYS_NS = SYSTEM_PERIOD_NS


class ControllerTop(Elaboratable):
    """Divider + controller with an explicit sync domain, so tests can pulse its reset."""

    def __init__(self, **kwargs):
        self.divider = ClockDivider(ratio=10)
        self.ctrl = ADS8364Controller(**kwargs)
        self.cd = ClockDomain("sync")
        self.enable = Signal(init=1)

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = self.cd
        m.submodules.divider = self.divider
        m.submodules.ctrl = self.ctrl
        m.d.comb += [self.ctrl.strobe.eq(self.divider.strobe), self.ctrl.enable.eq(self.enable)]
        return m


class Harness:
    """Runs ``top`` against ``ADS8364(source)``; ``script(ctx, h)`` drives the test.

    Every system cycle the harness reports pin changes to the model (which raises on a timing
    violation) and applies its EOC/data events. Each ADC CLK period it records
    ``(state, word)`` in :attr:`periods`; :attr:`outputs` collects the controller's output
    words, accepted with probability ``p_ready`` per cycle.
    """

    def __init__(self, top, source, *, p_ready=1.0, seed=0):
        self.top = top
        self.adc = ADS8364(source)
        self.p_ready = p_ready
        self.rng = random.Random(seed)
        self.cycle = 0
        self.periods = []
        self.outputs = []
        self.timeouts_seen = 0
        self._pending = []
        self._decoded = False
        self.stop = False

    def pins(self, ctx):
        c = self.top.ctrl
        w = c.word
        return {
            "clk": ctx.get(self.top.divider.clk_out),
            "hold_a": ctx.get(w.hold_a), "hold_b": ctx.get(w.hold_b), "hold_c": ctx.get(w.hold_c),
            "reset": ctx.get(w.reset),
            "cs": ctx.get(w.cs),
            "rd": ctx.get(w.rd),
            "wr": ctx.get(w.wr),
            "addr": ctx.get(c.addr),
        }

    async def monitor(self, ctx):
        c = self.top.ctrl
        ctx.set(c.o.ready, 1)
        self._pending += self.adc.pins(0, self.pins(ctx))  # power-up levels, at t = 0
        while not self.stop:
            ready = self.rng.random() < self.p_ready
            ctx.set(c.o.ready, ready)
            _, _, strobe, valid, payload = await ctx.tick().sample(self.top.divider.strobe, c.o.valid, c.o.payload)
            self.cycle += 1
            t = self.cycle * SYS_NS
            if valid and ready:
                self.outputs.append((payload.channel, payload.sample))
            self._pending += self.adc.pins(t, self.pins(ctx))
            due = [e for e in self._pending if e[0] <= t]
            self._pending = [e for e in self._pending if e[0] > t]
            for _, name, value in due:
                if name == "eoc":
                    ctx.set(c.eoc, value)
                else:
                    ctx.set(c.data, 0 if value is None else value & 0xFFFF)
            if self._decoded:  # the word and state of the period that started: the word is decoded
                self.periods.append((ctx.get(c.state), ctx.get(c.word.as_value())))  # one cycle after the strobe
            self._decoded = strobe

    def run(self, script, *, deadline_cycles=200000):
        sim = Simulator(self.top)
        sim.add_clock(SYS_NS * 1e-9, domain="sync")

        async def guarded(ctx):
            await script(ctx, self)
            self.stop = True

        async def watchdog(ctx):
            for _ in range(deadline_cycles):
                await ctx.tick()
                if self.stop:
                    return
            self.stop = True
            raise AssertionError(f"the test did not finish within {deadline_cycles} cycles")

        sim.add_testbench(self.monitor)
        sim.add_testbench(guarded)
        sim.add_testbench(watchdog, background=True)
        sim.run()


async def wait_outputs(ctx, h, count, limit=100000):
    """Let the simulation run until ``count`` outputs have been collected."""
    for _ in range(limit):
        if len(h.outputs) >= count:
            return
        await ctx.tick()
    raise AssertionError(f"only {len(h.outputs)} of {count} outputs after {limit} cycles")


async def wait_state(ctx, h, state, limit=100000):
    for _ in range(limit):
        if ctx.get(h.top.ctrl.state) == state:
            return
        await ctx.tick()
    raise AssertionError(f"state {state} not reached in {limit} cycles")
