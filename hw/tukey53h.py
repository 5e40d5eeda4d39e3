"""The streaming 53H core ([Lu]): one sample per clock, channels interleaved.

The stages are the model's own (``model/tukey53h.py``), one register stage each:

====  =====================================================================================
 1    read the channel's window and primed flag; fill them on its first sample; write the
      window shifted by the new sample
 2-6  the median-of-5 network (:data:`~kfpga.model.tukey53h.MEDIAN5`), one comparator layer per stage
 7    read, fill and write the channel's two medians of 5
 8-10 the median-of-3 network (:data:`~kfpga.model.tukey53h.MEDIAN3`)
 11   read, fill and write the channel's two medians of 3; ``before + 2 centre``
 12   ``x3 = (... + after) / 4``, rounded into point x3
 13   ``|x - x3|``
 14   the threshold test and the choice: the output register
====  =====================================================================================

Each stage keeps its own part of every channel's state (registers, one set per channel) and
reads and writes it while the sample passes, so a later sample of the same channel, one clock
behind, finds it written: **no sample ever waits for another**, whatever the order of channels,
and the core takes one sample per clock. All stages stall together when ``o`` is not ready.
The median networks need 7 + 3 comparators, the threshold test one more; no multiplier.
"""

from __future__ import annotations

from amaranth import Const, Module, Signal

from kfpga.core.ops import Fx
from kfpga.hw.arith import any_flag
from kfpga.hw.core import Core, register_stage, write_estimate
from kfpga.hw.storage import at, check_channels
from kfpga.model import tukey53h as eq

__all__ = ["OnlineCore", "make_core"]


class OnlineCore(Core):
    """The online 53H smoother for ``channels`` (1..8) interleaved channels; the stream contract
    of :class:`~kfpga.hw.core.Core` (one output per input, in order)."""

    def __init__(self, config, variant="online", *, channels=1):
        super().__init__(config, variant, channels)
        self._stages = self._plan()

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high: the
        input register and one register per stage."""
        return 1 + len(self._stages)

    @property
    def cycles_per_update(self):
        """One sample per clock, of any channel."""
        return 1

    #: BMC depth of the formal stream checks (``make formal``): the solver's time grows from 16 s at
    #: 30 cycles to more than 5 min at 33; 30 fill all 15 registers (the cover reaches it at 15)
    #: and drain a run of up to 12 samples.
    formal_depth = 30

    @property
    def capacity(self):
        """Samples the core holds at most: one in the input register and one per stage register."""
        return 1 + len(self._stages)

    def samples_per_clock(self, channels):
        return 1.0

    # -- the stages: (name, state lines it reads and writes, step) -------------------------------
    def _plan(self):
        stages = [("window", ("w1", "w2", "w3", "w4", "primed"), self._window)]
        stages += self._network("m5", eq.MEDIAN5, 2)
        stages.append(("a-line", ("a1", "a2"), self._a_line))
        stages += self._network("m3", eq.MEDIAN3, 1)
        stages.append(("b-line", ("b1", "b2"), self._b_line))
        stages.append(("hanning", (), lambda ops, k, v, s: {"x3": eq.hanning(ops, v["partial"], v["m3"]),
                                                              "centre": v["centre"]}))
        stages.append(("residual", (), lambda ops, k, v, s: {**v, "distance": eq.residual(ops, v["centre"], v["x3"])}))
        stages.append(("decide", (), lambda ops, k, v, s: {"y": eq.decide(ops, k, v["centre"], v["x3"], v["distance"])}))
        return stages

    @staticmethod
    def _network(tag, layers, result):
        reads = eq.network_reads(layers, result)

        def layer_step(n):
            def step(ops, k, v, s):
                values = eq.network_layer(ops, [v.get(p) for p in range(max(reads[0]) + 1)], layers[n])
                out = {p: values[p] for p in reads[n + 1]}
                out.update({key: v[key] for key in ("first", "centre", "shift") if key in v})
                return out
            return step

        return [(f"{tag}-{n + 1}", (), layer_step(n)) for n in range(len(layers))]

    def _window(self, ops, k, v, state):
        first, window, shift = eq.window_step(ops, k, state, v["y"])
        writes = {"w1": window[0], "w2": window[1], "w3": window[2], "w4": window[3],
                  "primed": ops.const(1, eq.FLAG, "1")}
        # an angle's frame shift travels with the sample to the lines of medians it moves
        return {**dict(enumerate(window)), "first": first, "centre": window[4],
                **({} if shift is None else {"shift": shift})}, writes

    def _a_line(self, ops, k, v, state):
        m5 = v[2]
        a1, a2 = eq.primed_line(ops, v["first"], m5, [state["a1"], state["a2"]], v.get("shift"))
        return ({0: m5, 1: a1, 2: a2, "first": v["first"], "centre": v["centre"],
                 **({"shift": v["shift"]} if "shift" in v else {})}, {"a1": m5, "a2": a1})

    def _b_line(self, ops, k, v, state):
        m3 = v[1]
        b1, b2 = eq.primed_line(ops, v["first"], m3, [state["b1"], state["b2"]], v.get("shift"))
        return ({"partial": eq.hanning_partial(ops, b2, b1), "m3": m3, "centre": v["centre"]},
                {"b1": m3, "b2": b1})

    def elaborate(self, platform):
        m = Module()
        advance = Signal()
        m.d.comb += [advance.eq(~self.o.valid | self.o.ready), self.i.ready.eq(advance)]

        s0_valid = Signal()
        s0 = Signal.like(self.i.payload, name="s0")
        with m.If(advance):
            m.d.sync += [s0_valid.eq(self.i.valid), s0.eq(self.i.payload)]

        valid, channel = s0_valid, s0.channel
        live = {"y": Fx(s0.y.as_signed(), 0, None, self.config.input_format, "y")}
        pending = []  # overflow flags not yet in a register bit
        in_range = channel < self.channels if 1 < self.channels < 2 ** len(channel) else Const(1, 1)
        for n, (_, lines, step) in enumerate(self._stages, start=1):
            ops = self.arith(m, prefix=f"s{n}_")
            k = ops.constants(self.constants)
            if lines:
                regs = self._states(list(lines))
                state = {line: self._state_value(regs, line, channel) for line in lines}
                live, writes = step(ops, k, live, state)
                with m.If(advance & valid & in_range):
                    m.d.sync += [at(regs[line], channel).eq(value.raw) for line, value in writes.items()]
            else:
                live = step(ops, k, live, None)
            flags = [flag for _, flag in ops.flags]
            if n == len(self._stages):
                pending += flags
                break
            valid, channel, flags, live = register_stage(m, advance, n, valid, channel, any_flag([*pending, *flags]), live)
            pending = [flags]
            in_range = channel < self.channels if 1 < self.channels < 2 ** len(channel) else Const(1, 1)
        self.flag_outputs(m, pending)
        with m.If(advance):
            m.d.sync += self.o.valid.eq(valid)
            with m.If(valid):
                write_estimate(m, self, channel, live, pending)
        return m


def make_core(config, variant="online", *, channels=1):
    """The registry's core factory (``kfpga.model.tukey53h.SPEC.core``); a bad channel count is
    refused before anything is built."""
    check_channels(channels, OnlineCore.max_channels)
    return OnlineCore(config, variant, channels=channels)
