"""A kfpga filter core inside your own Amaranth design, simulated with Amaranth's simulator.

The design: a sample source (a ramp with a little noise from a table) feeding the paper's
Kalman filter core through its input stream, and a register holding the latest position
estimate. The testbench checks every estimate against the bit-accurate model.

    python examples/amaranth_core.py
"""

import numpy as np
from amaranth import Array, Module, Signal, signed
from amaranth.lib import wiring
from amaranth.lib.wiring import Out
from amaranth.sim import Simulator

from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.ip import filter_core

CONFIG = FilterConfig()  # the paper's filter; FilterConfig.from_toml("my.toml") for your own
SAMPLES = np.round(np.arange(40) * 25.0 + np.random.default_rng(1).normal(0, 3, 40)).astype(int)


class Tracker(wiring.Component):
    """A sample source, the filter core, and the latest x1 estimate in a register."""

    x1: Out(signed(CONFIG.output_format("x1").width))
    count: Out(8)

    def __init__(self):
        super().__init__()
        self.core = filter_core(CONFIG, variant="steady")

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = core = self.core
        table = Array(int(v) for v in SAMPLES)
        index = Signal(range(len(SAMPLES) + 1))
        m.d.comb += [core.i.valid.eq(index < len(SAMPLES)), core.i.payload.y.eq(table[index]),
                     core.i.payload.channel.eq(0), core.o.ready.eq(1)]
        with m.If(core.i.valid & core.i.ready):
            m.d.sync += index.eq(index + 1)
        with m.If(core.o.valid):
            m.d.sync += [self.x1.eq(core.o.payload.x1), self.count.eq(self.count + 1)]
        return m


def simulate():
    """Run the design; returns the x1 estimates it produced, in order."""
    dut = Tracker()
    seen = []

    async def bench(ctx):
        for _ in range(400):
            await ctx.tick()
            if len(seen) < ctx.get(dut.count):
                seen.append(ctx.get(dut.x1))
            if len(seen) == len(SAMPLES):
                return

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    return seen


if __name__ == "__main__":
    got = simulate()
    want = FixedModel(CONFIG, variant="steady").run(SAMPLES).outputs["x1"].tolist()
    print(f"{len(got)} estimates of x1 from the core in an Amaranth design; equal to the model: {got == want}")
    raise SystemExit(0 if got == want else 1)
