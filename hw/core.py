"""What every filter core shares: its interface, its channel states, its output word, and the
pipelined update loop of the steady-state cores.

A core is an ``amaranth.lib.wiring.Component`` with an input stream of
:func:`~kfpga.hw.layouts.input_layout` words, an output stream of
:func:`~kfpga.hw.layouts.output_layout` words (one per input word, in order), a sticky
``overflow`` flag, and the properties ``latency`` and ``cycles_per_update``. The arithmetic
between its registers is its filter's stage functions on :class:`~kfpga.hw.arith.AmaranthOps`.
"""

from __future__ import annotations

from functools import cached_property, reduce
from types import MappingProxyType
from typing import ClassVar

from amaranth import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from kfpga.core.ops import Fx
from kfpga.hw.arith import NO_OVERFLOW, AmaranthOps, any_flag, live_flags
from kfpga.hw.layouts import channel_bits, input_layout, output_layout
from kfpga.hw.storage import MAX_REGISTER_CHANNELS, StateMemory, at, check_channels, select, state_array

__all__ = ["Core", "LoopPipeline", "write_estimate", "register_stage"]


def write_estimate(m, core, channel, outputs, flags):
    """Register the estimate word on ``core.o``, with the sample's overflow flags (1-bit values).

    The flags are registered one by one and ORed after the register (see
    :meth:`Core.flag_outputs`): an OR tree after the saturations would lengthen the last
    stage's path by its depth. Constant-0 flags get no register bit.
    """
    m.d.sync += core.o.payload.channel.eq(channel)
    live = live_flags(flags)
    if len(live) != core.flag_count:
        raise ValueError(f"{len(live)} overflow flags for the {core.flag_count} bits of flag_outputs()")
    if live:
        m.d.sync += core.o_flags.eq(Cat(*live))
    m.d.sync += [getattr(core.o.payload, name).eq(value.raw) for name, value in outputs.items()]


def register_stage(m, advance, tag, valid, channel, flags, live):
    """A pipeline register stage, loaded when ``advance``: every live value (an
    :class:`~kfpga.core.ops.Fx` keeps its binary point; a condition stays one bit), the valid bit, the
    channel and the flags so far (no register when they are the constant 0). Returns
    ``(valid, channel, flags, live)`` of the registers."""
    r_valid = Signal(name=f"r{tag}_valid")
    r_flags = Signal(name=f"r{tag}_flags") if live_flags([flags]) else NO_OVERFLOW
    r_channel = Signal.like(channel, name=f"r{tag}_channel")
    held = {}
    with m.If(advance):
        m.d.sync += [r_valid.eq(valid), r_channel.eq(channel)]
        if r_flags is not NO_OVERFLOW:
            m.d.sync += r_flags.eq(flags)
        for key, value in live.items():
            if isinstance(value, Fx):
                reg = Signal(signed(len(value.raw)), name=f"r{tag}_{key}")
                m.d.sync += reg.eq(value.raw)
                held[key] = Fx(reg, value.frac, value.const, value.fmt, str(key))
            else:
                reg = Signal(name=f"r{tag}_{key}")
                m.d.sync += reg.eq(value)
                held[key] = reg
    return r_valid, r_channel, r_flags, held


class Core(wiring.Component):
    """Config, variant, channel count, constants, reset state and the stream signature."""

    #: Channel states this core can hold (a core that keeps them in block memory holds more).
    max_channels = MAX_REGISTER_CHANNELS

    def __init__(self, config, variant, channels, *, index_bits=None, missing=False, members=None):
        check_channels(channels, self.max_channels)
        if index_bits is not None and index_bits < channel_bits(channels):
            raise ValueError(f"index_bits = {index_bits} cannot number {channels} channels")
        config.require_hardware(variant)
        self.config = config
        self.variant = variant
        self.channels = channels
        self.constants = config.constants(variant)
        self.reset_state = config.reset_state(variant)
        self.state_points = dict(config.spec.model.variants[variant].state_for(config.params))
        super().__init__({
            "i": In(stream.Signature(input_layout(config, channels, index_bits, missing=missing))),
            "o": Out(stream.Signature(output_layout(config, channels, index_bits))),
            "overflow": Out(1),
            **(members or {}),
        })

    @cached_property
    def overflow_sites(self):
        """The writes that can overflow: the model's interval analysis from the formats of the
        state and the samples (``kfpga/core/compiled.py``). Every value a write gets is the model's, so
        the others never saturate, and their logic is left out."""
        from kfpga.core.fixedmodel import FixedModel

        return frozenset(FixedModel(self.config, variant=self.variant).kernel(False).sites)

    def arith(self, m, prefix):
        """The operations layer's Amaranth backend for a stage of this core (:class:`AmaranthOps`)."""
        return AmaranthOps(m, self.config.formats, prefix=prefix, overflow_sites=self.overflow_sites)

    def flag_outputs(self, m, flags):
        """``o.payload.overflow`` and the sticky ``overflow`` from the registered bits of ``flags``
        (the values :func:`write_estimate` registers; the constant 0s get no bit). With none
        left, no write of this core can overflow, and both outputs are 0."""
        self.flag_count = len(live_flags(flags))
        if not self.flag_count:
            self.o_flags = None
            m.d.comb += [self.o.payload.overflow.eq(0), self.overflow.eq(0)]
            return
        self.o_flags = Signal(self.flag_count, name="o_flags")
        sticky = Signal(name="sticky")
        word = Signal(name="word_overflow")
        m.d.comb += [word.eq(self.o_flags.any()), self.o.payload.overflow.eq(word),
                     self.overflow.eq(sticky | (self.o.valid & word))]
        m.d.sync += sticky.eq(self.overflow)

    def _states(self, names=None):
        """One register per channel for each state name (default: all of the variant's)."""
        names = list(self.state_points) if names is None else names
        return {n: state_array(self.channels, signed(self.config.point_format(self.state_points[n]).width),
                               self.reset_state[n], n)
                for n in names}

    def _state_value(self, regs, name, channel):
        fmt = self.config.point_format(self.state_points[name])
        return Fx(select(regs[name], channel).as_signed(), fmt.frac_bits, None, fmt, name)


class LoopPipeline(Core):
    """A steady-state core: the update loop over L register stages, channels interleaved.

    A subclass names its update's steps (:attr:`steps`, each ``step(ops, k, live) -> live``
    over a dict of values), what each reads (:attr:`reads`), where a pipeline of L stages cuts
    (:attr:`cuts`), which values are written back (:attr:`writes`), and what follows the loop
    (:meth:`outputs`, :meth:`output_steps`, and :attr:`carry`: what the outputs read that no
    later step does). A sample enters an input register, reads its
    channel's state in the first stage and writes it back at the end of stage L. A sample may
    follow another of the same channel only once that one has written back (the input stalls
    until then; nothing is forwarded), so one channel takes a sample every L cycles and C >= L
    channels in turn one per clock (C-slow operation). All stages stall together when ``o`` is
    not ready, so nothing is dropped.

    With one channel a state value that a later stage reads is read again from the state
    register (it cannot change before this sample writes back) instead of being carried in
    pipeline registers; with several channels the read mux would cost more than it saves.

    Up to :data:`~kfpga.hw.storage.MAX_REGISTER_CHANNELS` channel states live in registers.
    A subclass that sets :attr:`max_channels` higher keeps more of them in block memory
    (:class:`~kfpga.hw.storage.StateMemory`, the Cyclone II M4K blocks): one word per channel,
    read synchronously. Its read address is the next sample's channel while the input register
    takes it, else the waiting sample's, so the word is in the read register when the sample is
    in the input register. The read is not transparent (an M4K read during a write to the same
    address gives the old word), so a sample also waits for the write-back of the clock before:
    the hazard is stalled, never forwarded, and one channel takes a sample every L + 1 cycles
    (any order of channels works; C > L channels in turn still run one per clock).
    """

    steps: ClassVar[tuple] = ()
    reads: ClassVar[tuple] = ()
    carry: ClassVar[tuple] = ()  # values :meth:`outputs` reads that no later step does
    cuts: ClassVar[dict] = MappingProxyType({})
    writes: ClassVar[dict] = MappingProxyType({})

    def __init__(self, config, variant, *, channels=1, stages, index_bits=None):
        if not isinstance(stages, int) or isinstance(stages, bool) or stages not in self.cuts:
            raise ValueError(f"stages must be one of {', '.join(map(str, self.cuts))}, not {stages!r}")
        super().__init__(config, variant, channels, index_bits=index_bits)
        self.stages = stages

    # what a subclass provides after the loop
    def outputs(self, live):
        """``{name: Fx}`` carried past the loop (the output fields and what their steps need)."""
        raise NotImplementedError

    def output_steps(self):
        """Steps after the loop, ``step(ops, k, out) -> out``, one register stage between two."""
        return []

    def final(self, out):
        """The output fields, ``{field: Fx}``, from what the last step gives."""
        return out

    @property
    def output_stages(self):
        return max(len(self.output_steps()) - 1, 0) if self.output_steps() else 0

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return 1 + self.stages + self.output_stages

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to accepting the next of the same channel (``o`` ready)."""
        return self.stages + (1 if self.channels > MAX_REGISTER_CHANNELS else 0)

    def samples_per_clock(self, channels):
        """Samples per clock with ``channels`` channels in turn: ``min(1, channels / cycles_per_update)``."""
        return min(1.0, channels / self.cycles_per_update)

    def elaborate(self, platform):
        m = Module()
        in_memory = self.channels > MAX_REGISTER_CHANNELS
        regs = {} if in_memory else self._states()
        advance = Signal()
        m.d.comb += advance.eq(~self.o.valid | self.o.ready)

        # the input register
        s0_valid = Signal()
        s0 = Signal.like(self.i.payload, name="s0")
        hazard = Signal()  # a sample of s0's channel has not written back yet
        take = Signal()  # s0 moves on (or is empty) and takes the next input
        m.d.comb += [take.eq(advance & (~s0_valid | ~hazard)), self.i.ready.eq(take)]
        with m.If(take):
            m.d.sync += [s0_valid.eq(self.i.valid), s0.eq(self.i.payload)]

        live = {name: Fx(getattr(s0, name).as_signed(), 0, None, self.config.input_format, name)
                for name in self.config.inputs}
        memory = None
        if in_memory:
            memory = StateMemory(self.channels, {n: self.config.point_format(p) for n, p in self.state_points.items()},
                                 self.reset_state)
            m.submodules.state = memory
            m.d.comb += memory.read_addr.eq(Mux(take, self.i.payload.channel, s0.channel))
            live.update(memory.values(m, s0.channel))
        else:
            live.update({name: self._state_value(regs, name, s0.channel) for name in regs})
        valid, channel, flags, live, in_flight, last_flags = self._loop(m, advance, regs, live, s0_valid & ~hazard,
                                                                        s0.channel)
        in_flight += self._write_back(m, advance, regs, memory, valid, channel, live)
        m.d.comb += hazard.eq(reduce(lambda a, b: a | b, [v & (c == s0.channel) for v, c in in_flight], Const(0, 1)))
        self._after_loop(m, advance, valid, channel, [flags, *last_flags], live)
        return m

    def _loop(self, m, advance, regs, live, valid, channel):
        """The loop's steps in their register stages; ``(valid, channel, flags, live, in_flight,
        last_flags)`` at the end of the last stage (``in_flight``: the (valid, channel) of the
        samples before their write-back; ``last_flags``: the last stage's, not yet registered)."""
        flags, in_flight, last_flags = NO_OVERFLOW, [], []
        groups, start = [], 0
        for cut in (*self.cuts[self.stages], len(self.steps)):
            groups.append(self.steps[start:cut])
            start = cut
        reread = set(regs) if self.channels == 1 else set()
        for n, group in enumerate(groups, start=1):
            ops = self.arith(m, prefix=f"s{n}_")
            k = ops.constants(self.constants)
            if n > 1:
                needed = set().union(*(self.reads[self.steps.index(s)] for s in group))
                live.update({name: self._state_value(regs, name, 0) for name in needed & reread})
            for step in group:
                live = step(ops, k, live)
            if n == len(groups):
                last_flags = [flag for _, flag in ops.flags]
                break
            flags = any_flag([flags, ops.overflow()])
            later = set().union(*self.reads[self.steps.index(group[-1]) + 1:], self.carry) - reread
            live = {name: value for name, value in live.items() if name in later}
            valid, channel, flags, live = register_stage(m, advance, n, valid, channel, flags, live)
            in_flight.append((valid, channel))
        return valid, channel, flags, live, in_flight, last_flags

    def _write_back(self, m, advance, regs, memory, valid, channel, live):
        """The write-back at the end of the last loop stage; the (valid, channel) it adds to
        the samples in flight."""
        if memory is not None:
            memory.write(m, advance & valid, channel, {name: live[key].raw for name, key in self.writes.items()})
            # the word written at the last clock edge is not yet in what the memory reads
            wrote_valid, wrote_channel = Signal(name="wrote_valid"), Signal.like(channel, name="wrote_channel")
            m.d.sync += [wrote_valid.eq(advance & valid), wrote_channel.eq(channel)]
            return [(wrote_valid, wrote_channel)]
        # a channel number past the last state updates nothing (one state: the register itself)
        in_range = channel < self.channels if 1 < self.channels < 2 ** len(channel) else Const(1, 1)
        with m.If(advance & valid & in_range):
            m.d.sync += [at(regs[name], channel).eq(live[key].raw) for name, key in self.writes.items()]
        return []

    def _after_loop(self, m, advance, valid, channel, pending, live):
        """The output steps, a register stage between two, and the output register (``pending``:
        the flags not yet ORed into one register bit)."""
        out = self.outputs(live)
        steps = self.output_steps()
        for n, step in enumerate(steps, start=1):
            ops = self.arith(m, prefix=f"o{n}_")
            out = step(ops, ops.constants(self.constants), out)
            pending += [flag for _, flag in ops.flags]
            if n < len(steps):
                valid, channel, flags, out = register_stage(m, advance, f"o{n}", valid, channel, any_flag(pending), out)
                pending = [flags]
        self.flag_outputs(m, pending)
        with m.If(advance):
            m.d.sync += self.o.valid.eq(valid)
            with m.If(valid):
                write_estimate(m, self, channel, self.final(out), pending)

