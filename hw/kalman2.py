"""Cores of the paper's 2-state filter, built from the stage functions of ``model/kalman2.py``.

The arithmetic between the registers is the model's own: each core runs the stage functions on
:class:`~kfpga.hw.arith.AmaranthOps`, so the RTL and the bit-accurate model compute the same
integers by construction (and the tests check it). What is written here is the sequential
structure: the registers, the schedule, the dividers, the channel states.

Both cores take a stream of :func:`~kfpga.hw.layouts.input_layout` words (channel, signed 16-bit
``y``) and give one :func:`~kfpga.hw.layouts.output_layout` word (channel, x1, x2, yhat,
overflow) per input word, in order. Each channel (``channels`` of them, 1 to 8) has its own
state; a channel number outside ``0..channels-1`` reads a zero state and updates nothing. The
ADC controller only produces valid ones.
"""

from __future__ import annotations

from amaranth import Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from kfpga.ads8364 import CODE_FORMAT
from kfpga.hw.arith import AmaranthOps
from kfpga.hw.divider import Divider
from kfpga.hw.layouts import input_layout, output_layout
from kfpga.hw.storage import at, check_channels, select, state_array
from kfpga.model import kalman2 as eq
from kfpga.ops import divider_shift, quotient_bits

__all__ = ["SteadyKalman", "FullKalman", "make_core"]


def _signature(config, channels):
    return {
        "i": In(stream.Signature(input_layout(config.spec, channels))),
        "o": Out(stream.Signature(output_layout(config, channels))),
        "overflow": Out(1),
    }


def write_estimate(m, core, channel, outputs, overflowed):
    """Register the estimate word on ``core.o`` and raise the sticky flag on an overflow."""
    m.d.sync += [core.o.payload.channel.eq(channel), core.o.payload.overflow.eq(overflowed)]
    m.d.sync += [getattr(core.o.payload, name).eq(value.raw) for name, value in outputs.items()]
    with m.If(overflowed):
        m.d.sync += core.overflow.eq(1)


class _Core(wiring.Component):
    """What both cores share: config, channel count, the reset state, the stream signature."""

    def __init__(self, config, variant, channels):
        check_channels(channels)
        config.require_variant(variant)
        self.config = config
        self.variant = variant
        self.channels = channels
        self.constants = config.constants(variant)
        self.reset_state = config.reset_state(variant)
        super().__init__(_signature(config, channels))

    def _states(self, names):
        f = self.config.formats
        points = dict(self.config.spec.variants[self.variant].state)
        return {n: state_array(self.channels, signed(f[points[n]].width), self.reset_state[n], n) for n in names}


class SteadyKalman(_Core):
    """Steady-state (constant-gain) Kalman core: one sample per clock, fully pipelined.

    Stage 1 registers the input word; stage 2 computes the whole update (the loop
    x -> xl1 -> e -> K e -> x closes within one cycle to take a sample every clock) and
    registers the state and the output word. Both stages stall together when ``o`` is not
    ready, so nothing is dropped.

    Parameters
    ----------
    config:
        The shared :class:`~kfpga.config.FilterConfig` (the ``kalman2`` filter).
    channels:
        Independent channel states (1..8).

    Members
    -------
    i : In(stream.Signature(input_layout(spec, channels)))
        Samples.
    o : Out(stream.Signature(output_layout(config, channels)))
        Estimates, one per sample.
    overflow : Out(1)
        Sticky: some write saturated (or wrapped) since reset.
    """

    def __init__(self, config, *, channels=1):
        super().__init__(config, "steady", channels)

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return 2

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to being able to accept the next (``o`` always ready)."""
        return 1

    def elaborate(self, platform):
        m = Module()
        regs = self._states(("x1", "v"))

        # stage 1: input register
        a_valid = Signal()
        a = Signal.like(self.i.payload)
        advance = ~self.o.valid | self.o.ready
        m.d.comb += self.i.ready.eq(advance)
        with m.If(advance):
            m.d.sync += [a_valid.eq(self.i.valid), a.eq(self.i.payload)]

        # stage 2: the update, the model's own function
        ops = AmaranthOps(m, self.config.formats)
        k = ops.constants(self.constants)
        x = {n: ops.input(select(r, a.channel), n) for n, r in regs.items()}  # the state points are x1, v
        state, outputs = eq.steady_update(ops, k, x, {"y": ops.input(a.y, CODE_FORMAT, "y")})
        overflowed = ops.overflow()

        with m.If(advance):
            m.d.sync += self.o.valid.eq(a_valid)
            with m.If(a_valid):
                m.d.sync += [at(regs[n], a.channel).eq(state[n].raw) for n in regs]
                write_estimate(m, self, a.channel, outputs, overflowed)
        return m


class FullKalman(_Core):
    """Time-varying Kalman core: the decomposed equations with two restoring dividers.

    Schedule per update (one channel at a time)::

        IDLE   accept a sample; load the channel's state
        TU     time update xl1, pl11..pl22, S = pl11 + R and the innovation e; start both
               divisions K1 = pl11 / S, K2 = pl21 / S
        DIV    quotient_bits + 1 cycles (18 with the default formats)
        MUL    the six products K1 e, K2 e, K1 pl11, K1 pl12, K2 pl11, K2 pl12 (registered)
        WB     requantise, saturate, write the state back and the estimate out

    An update takes ``quotient_bits + 5`` cycles, 22 with the default formats
    (:attr:`cycles_per_update`): the input is accepted in cycle ``c``, the estimate is on ``o``
    in cycle ``c + 22``, and the next input can be accepted in that same cycle. If ``o`` is
    still full, WB waits.

    Parameters and members as :class:`SteadyKalman`.
    """

    def __init__(self, config, *, channels=1):
        super().__init__(config, "full", channels)
        f = config.formats
        self.quotient_bits = quotient_bits(f["gain"])
        self.div_shift = divider_shift(f["pl"].frac_bits, f["s"].frac_bits, f["gain"].frac_bits)
        self.dividend_bits = f["pl"].width + self.div_shift
        self._divider_args = {"dividend_bits": self.dividend_bits, "divisor_bits": f["s"].width,
                              "quotient_bits": self.quotient_bits}

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to being able to accept the next (``o`` always ready)."""
        return 1 + 1 + (self.quotient_bits + 1) + 1 + 1

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.cycles_per_update

    def elaborate(self, platform):
        m = Module()
        f = self.config.formats
        names = ("x1", "v", "p11", "p12", "p21", "p22")
        regs = self._states(names)
        m.submodules.div1 = div1 = Divider(**self._divider_args)
        m.submodules.div2 = div2 = Divider(**self._divider_args)

        # working registers of the channel being updated
        channel = Signal.like(self.i.payload.channel)
        sample = Signal(signed(CODE_FORMAT.width))
        points = dict(self.config.spec.variants["full"].state)
        work = {n: Signal(signed(f[points[n]].width), name=f"{n}_w") for n in names}
        flags = Signal()  # OR of the overflow flags of this update so far

        # -- time update and innovation (combinational from the working registers) -----------
        tu = AmaranthOps(m, f, prefix="tu_")
        k = tu.constants(self.constants)
        x = {n: tu.input(work[n], points[n], n) for n in names}
        xl1 = eq.predict(tu, x["x1"], x["v"])                                        # xl1 = x1 + v
        pl = eq.covariance_predict(tu, k, x["p11"], x["p12"], x["p21"], x["p22"])
        s = eq.innovation_variance(tu, k, pl[0])                                     # S = pl11 + R
        e = eq.innovation(tu, tu.input(sample, CODE_FORMAT, "y"), xl1)               # e = y - xl1
        held = [tu.hold(v, n) for v, n in zip((xl1, *pl, e), ("xl1", "pl11", "pl12", "pl21", "pl22", "e"), strict=True)]
        xl1_r, pl11_r, pl12_r, pl21_r, pl22_r, e_r = (h for h, _ in held)
        tu_flags = tu.overflow()

        # divider operands: |pl| << shift over S; S <= 0 becomes a zero divisor (saturates)
        def dividend(pl_value):
            magnitude = Mux(pl_value < 0, -pl_value, pl_value).as_unsigned()
            return magnitude.shift_left(self.div_shift)[:self.dividend_bits]

        divisor = Mux(s.raw > 0, s.raw.as_unsigned(), 0)
        m.d.comb += [
            div1.i.payload.dividend.eq(dividend(pl[0].raw)),
            div1.i.payload.divisor.eq(divisor),
            div2.i.payload.dividend.eq(dividend(pl[2].raw)),
            div2.i.payload.divisor.eq(divisor),
            div1.o.ready.eq(1),
            div2.o.ready.eq(1),
        ]

        # -- gains: truncation toward zero (the dividers work on magnitudes) ---------------------
        k1 = Signal(signed(f["gain"].width))
        k2 = Signal(signed(f["gain"].width))

        def signed_quotient(result, numerator):
            return Mux(numerator < 0, -result.quotient, result.quotient)

        # -- products (registered) and write-back (combinational from them) ----------------------
        mul = AmaranthOps(m, f, prefix="mul_")
        g1, g2 = mul.input(k1, "gain", "K1"), mul.input(k2, "gain", "K2")
        k1e, k2e, pk = eq.full_products(mul, g1, g2, e_r, pl11_r, pl12_r)
        products = [mul.hold(v, n) for v, n in zip((k1e, k2e, *pk), ("k1e", "k2e", "k1p11", "k1p12", "k2p11", "k2p12"),
                                                   strict=True)]
        k1e_r, k2e_r, *pk_r = (p for p, _ in products)
        wb_ops = AmaranthOps(m, f, prefix="wb_")
        x1_n = eq.correct(wb_ops, xl1_r, k1e_r, "x1")                                # x1 = xl1 + K1 e
        v_n = eq.correct(wb_ops, x["v"], k2e_r, "v")                                 # v = v + K2 e
        p_n = eq.covariance_correct(wb_ops, (pl11_r, pl12_r, pl21_r, pl22_r), pk_r)   # P = P' - K C P'
        x2_n = eq.rate(wb_ops, wb_ops.constants(self.constants), v_n)                # x2 = v / T
        wb_flags = Signal()
        m.d.comb += wb_flags.eq(flags | wb_ops.overflow())
        next_state = dict(zip(names, (x1_n, v_n, *p_n), strict=True))

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)

        with m.FSM(name="schedule") as fsm:
            with m.State("IDLE"):
                with m.If(self.i.valid):
                    m.d.sync += [channel.eq(self.i.payload.channel), sample.eq(self.i.payload.y)]
                    m.d.sync += [work[n].eq(select(regs[n], self.i.payload.channel)) for n in names]
                    m.next = "TU"
            with m.State("TU"):
                m.d.sync += [assign for _, assign in held]
                m.d.sync += flags.eq(tu_flags)
                m.next = "DIV"
            with m.State("DIV"):
                with m.If(div1.o.valid):  # both dividers finish in the same cycle
                    m.d.sync += [
                        k1.eq(signed_quotient(div1.o.payload, pl11_r.raw)),
                        k2.eq(signed_quotient(div2.o.payload, pl21_r.raw)),
                        flags.eq(flags | div1.o.payload.overflow | div2.o.payload.overflow),
                    ]
                    m.next = "MUL"
            with m.State("MUL"):
                m.d.sync += [assign for _, assign in products]
                m.next = "WB"
            with m.State("WB"):
                with m.If(~self.o.valid | self.o.ready):
                    m.d.sync += [at(regs[n], channel).eq(next_state[n].raw) for n in names]
                    m.d.sync += self.o.valid.eq(1)
                    write_estimate(m, self, channel, {"x1": x1_n, "x2": x2_n, "yhat": xl1_r}, wb_flags)
                    m.next = "IDLE"
        # plain assignments (Verilog `assign`), not case-statement outputs: no simulator can
        # leave them undefined at time zero while the state has not changed yet
        m.d.comb += [
            self.i.ready.eq(fsm.ongoing("IDLE")),
            div1.i.valid.eq(fsm.ongoing("TU")),
            div2.i.valid.eq(fsm.ongoing("TU")),
        ]
        return m


def make_core(config, variant, *, channels=1):
    """The core of ``variant`` ("steady" or "full")."""
    if variant == "steady":
        return SteadyKalman(config, channels=channels)
    if variant == "full":
        return FullKalman(config, channels=channels)
    raise ValueError(f"variant must be 'steady' or 'full', not {variant!r}")
