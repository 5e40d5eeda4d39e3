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

from amaranth import Cat, Module, Mux, Signal, signed

from kfpga.core.board import MAX_CHANNELS
from kfpga.core.codes import CODE_FORMAT
from kfpga.core.ops import Fx, divider_shift, quotient_bits
from kfpga.hw.arith import NO_OVERFLOW, any_flag, live_flags
from kfpga.hw.core import Core, write_estimate
from kfpga.hw.cvloop import ConstantGainLoop
from kfpga.hw.divider import Divider
from kfpga.hw.storage import at, select
from kfpga.model import cvloop
from kfpga.model import kalman2 as eq

__all__ = ["SteadyCore", "FullCore", "make_core"]


class SteadyCore(ConstantGainLoop):
    """The paper's steady-state (constant-gain) core: the constant-velocity loop
    (:class:`~kfpga.hw.cvloop.ConstantGainLoop`) with the gains ``K1`` and ``T*K2``; see there for
    the pipeline and the stream contract."""

    max_channels = MAX_CHANNELS  # past eight, the states in block memory (LoopPipeline)


class FullCore(Core):
    """Time-varying Kalman core: the decomposed equations with two restoring dividers.

    Schedule per update (one channel at a time), at most one carry chain or one multiplier
    between two registers so that it meets 50 MHz on the -8 part with margin::

        IDLE   accept a sample; load the channel's state
        TU1    time update: xl1 = x1 + v, pl11..pl22
        TU2    S = pl11 + R, the innovation e = y - xl1, the dividends |pl11|, |pl21| (shifted)
        GO     start both divisions K1 = pl11 / S, K2 = pl21 / S
        DIV    quotient_bits + 1 cycles (18 with the default formats)
        MUL    the six products K1 e, K2 e, K1 pl11, K1 pl12, K2 pl11, K2 pl12 (registered)
        WB     requantise, saturate, write the state back; the flags registered one by one
        X1     x2 = v / T (a free shift when T = 2**k) and the estimate out; when T is not a
               power of two, X1..X3 are the three steps of x2 (v rounded into vt, the product by
               1/T, the rounding into x2), and X3 puts the estimate out

    An update takes ``quotient_bits + 8`` cycles, 25 with the default formats, two more when
    T is not a power of two (:attr:`cycles_per_update`): the input is accepted in cycle ``c``,
    the estimate is on ``o`` in cycle ``c + cycles_per_update``, and the next input can be
    accepted in that same cycle. If ``o`` is still full, the last state waits.

    Parameters and members as :class:`SteadyCore` (without ``stages``).
    """

    def __init__(self, config, *, channels=1):
        super().__init__(config, "full", channels)
        f = config.formats
        self.quotient_bits = quotient_bits(f["gain"])
        self.div_shift = divider_shift(f["pl"].frac_bits, f["s"].frac_bits, f["gain"].frac_bits)
        self.dividend_bits = f["pl"].width + self.div_shift
        self._divider_args = {"dividend_bits": self.dividend_bits, "divisor_bits": f["s"].width,
                              "quotient_bits": self.quotient_bits}
        self.rate_steps = 0 if self.constants["t_shift"] is not None else 3

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to being able to accept the next (``o`` always ready)."""
        return 1 + 2 + 1 + (self.quotient_bits + 1) + 1 + 1 + 1 + (self.rate_steps - 1 if self.rate_steps else 0)

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.cycles_per_update

    def elaborate(self, platform):
        b = _FullBuild(self, Module())
        b.time_update()
        b.correction()
        b.rate()
        b.schedule()
        return b.m


class _FullBuild:
    """The parts of a :class:`FullCore`, one method per part of its schedule; each keeps as
    attributes the signals the later ones use."""

    names = ("x1", "v", "p11", "p12", "p21", "p22")

    def __init__(self, core, m):
        self.core, self.m = core, m
        self.f = f = core.config.formats
        self.regs = core._states(self.names)
        m.submodules.div1 = self.div1 = Divider(**core._divider_args)
        m.submodules.div2 = self.div2 = Divider(**core._divider_args)
        self.points = points = dict(core.config.spec.model.variants["full"].state_for(core.config.params))
        # working registers of the channel being updated
        self.channel = Signal.like(core.i.payload.channel)
        self.sample = Signal(signed(CODE_FORMAT.width))
        self.work = {n: Signal(signed(f[points[n]].width), name=f"{n}_w") for n in self.names}
        self.flags = Signal()  # OR of the overflow flags of this update so far

    def time_update(self):
        """TU1: the time update, from the working registers; TU2: S, the innovation, the dividends."""
        m, core, f = self.m, self.core, self.f
        self.tu1 = tu1 = core.arith(m, prefix="tu1_")
        self.k = k = tu1.constants(core.constants)
        self.x = x = {n: tu1.input(self.work[n], self.points[n], n) for n in self.names}
        xl1 = cvloop.predict(tu1, x["x1"], x["v"])                                        # xl1 = x1 + v
        pl = eq.covariance_predict(tu1, k, x["p11"], x["p12"], x["p21"], x["p22"])   # P' = Phi P Phi^T + Q'
        self.held1 = [tu1.hold(v, n) for v, n in zip((xl1, *pl), ("xl1", "pl11", "pl12", "pl21", "pl22"), strict=True)]
        self.xl1_r, self.pl11_r, self.pl12_r, self.pl21_r, self.pl22_r = (h for h, _ in self.held1)
        self.tu2 = tu2 = core.arith(m, prefix="tu2_")
        self.s = eq.innovation_variance(tu2, k, self.pl11_r)                           # S = pl11 + R
        e = cvloop.innovation(tu2, tu2.input(self.sample, CODE_FORMAT, "y"), self.xl1_r)  # e = y - xl1
        self.e_r, self.e_assign = tu2.hold(e, "e")
        self.num1 = Signal(core.dividend_bits, name="num1")
        self.num2 = Signal(core.dividend_bits, name="num2")
        self.den = Signal(f["s"].width, name="den")
        div1, div2 = self.div1, self.div2
        m.d.comb += [
            div1.i.payload.dividend.eq(self.num1), div1.i.payload.divisor.eq(self.den),
            div2.i.payload.dividend.eq(self.num2), div2.i.payload.divisor.eq(self.den),
            div1.o.ready.eq(1), div2.o.ready.eq(1),
        ]

    def dividend(self, pl_value):
        """|pl| << shift: the divider works on magnitudes."""
        magnitude = Mux(pl_value < 0, -pl_value, pl_value).as_unsigned()
        return magnitude.shift_left(self.core.div_shift)[:self.core.dividend_bits]

    def correction(self):
        """The gains (truncation toward zero, the sign back from the numerator); MUL: the
        products (registered); WB: the sums, from the registered products."""
        m, core, f = self.m, self.core, self.f
        self.k1 = k1 = Signal(signed(f["gain"].width))
        self.k2 = k2 = Signal(signed(f["gain"].width))
        mul = core.arith(m, prefix="mul_")
        g1, g2 = mul.input(k1, "gain", "K1"), mul.input(k2, "gain", "K2")
        k1e, k2e, pk = eq.full_products(mul, g1, g2, self.e_r, self.pl11_r, self.pl12_r)
        self.products = [mul.hold(v, n) for v, n in zip((k1e, k2e, *pk), ("k1e", "k2e", "k1p11", "k1p12", "k2p11", "k2p12"),
                                                        strict=True)]
        k1e_r, k2e_r, *pk_r = (p for p, _ in self.products)
        wb = core.arith(m, prefix="wb_")
        self.x1_n = cvloop.correct(wb, self.xl1_r, k1e_r, "x1")                          # x1 = xl1 + K1 e
        self.v_n = cvloop.correct(wb, self.x["v"], k2e_r, "v")                           # v = v + K2 e
        p_n = eq.covariance_correct(wb, (self.pl11_r, self.pl12_r, self.pl21_r, self.pl22_r), pk_r)  # P = P' - K C P'
        self.next_state = dict(zip(self.names, (self.x1_n, self.v_n, *p_n), strict=True))
        # the flags of WB are registered one by one and ORed in the next cycle: an OR tree
        # after the saturations would lengthen WB's path by two LUT levels
        self.wb_live = live_flags([flag for _, flag in wb.flags])
        self.wb_bits = Signal(len(self.wb_live), name="wb_flags") if self.wb_live else None
        self.wb_any = self.wb_bits.any() if self.wb_live else NO_OVERFLOW

    def rate(self):
        """x2 = v / T from the new v: free when T = 2**k, else three steps."""
        m, core, f = self.m, self.core, self.f
        self.v_done = Signal(signed(f["v"].width), name="v_done")
        self.x1_done = Signal(signed(f["x1"].width), name="x1_done")
        v_done_fx = Fx(self.v_done, f["v"].frac_bits, None, f["v"], "v")
        rate_ops = [core.arith(m, prefix=f"x{n}_") for n in range(1, 4)]
        if core.rate_steps:
            operand, self.op_assign = rate_ops[0].hold(cvloop.rate_operand(rate_ops[0], self.k, v_done_fx), "vt")
            product, self.pr_assign = rate_ops[1].hold(cvloop.rate_product(rate_ops[1], self.k, operand), "vt_inv_t")
            self.x2_n = cvloop.rate_write(rate_ops[2], self.k, product)
            self.rate_flags = [rate_ops[0].overflow(), NO_OVERFLOW, rate_ops[2].overflow()]
            self.out_flags = [self.flags, self.rate_flags[2]]
        else:
            self.x2_n = cvloop.rate(rate_ops[0], self.k, v_done_fx)
            self.rate_flags = [rate_ops[0].overflow()]
            self.out_flags = [self.flags, self.wb_any, self.rate_flags[0]]

    def emit(self, x2):
        m, core = self.m, self.core
        with m.If(~core.o.valid | core.o.ready):
            m.d.sync += core.o.valid.eq(1)
            write_estimate(m, core, self.channel, {"x1": Fx(self.x1_done, 0), "x2": x2, "yhat": self.xl1_r},
                           self.out_flags)
            m.next = "IDLE"

    def schedule(self):
        m, core = self.m, self.core
        with m.If(core.o.valid & core.o.ready):
            m.d.sync += core.o.valid.eq(0)
        core.flag_outputs(m, self.out_flags)
        with m.FSM(name="schedule") as fsm:
            self.update_states()
            self.write_states()
        # plain assignments (Verilog `assign`), not case-statement outputs: no simulator can
        # leave them undefined at time zero while the state has not changed yet
        m.d.comb += [
            core.i.ready.eq(fsm.ongoing("IDLE")),
            self.div1.i.valid.eq(fsm.ongoing("GO")),
            self.div2.i.valid.eq(fsm.ongoing("GO")),
        ]

    def update_states(self):
        m, core, flags = self.m, self.core, self.flags
        with m.State("IDLE"):
            with m.If(core.i.valid):
                m.d.sync += [self.channel.eq(core.i.payload.channel), self.sample.eq(core.i.payload.y)]
                m.d.sync += [self.work[n].eq(select(self.regs[n], core.i.payload.channel)) for n in self.names]
                m.next = "TU1"
        with m.State("TU1"):
            m.d.sync += [assign for _, assign in self.held1]
            m.d.sync += flags.eq(self.tu1.overflow())  # the constant 0 when no TU1 write can overflow
            m.next = "TU2"
        with m.State("TU2"):
            m.d.sync += [self.e_assign, flags.eq(any_flag([flags, self.tu2.overflow()])),
                         self.num1.eq(self.dividend(self.pl11_r.raw)), self.num2.eq(self.dividend(self.pl21_r.raw)),
                         self.den.eq(Mux(self.s.raw > 0, self.s.raw.as_unsigned(), 0))]  # S <= 0: a zero divisor
            m.next = "GO"
        with m.State("GO"):
            m.next = "DIV"
        with m.State("DIV"):
            with m.If(self.div1.o.valid):  # both dividers finish in the same cycle
                m.d.sync += [
                    self.k1.eq(_signed_quotient(self.div1.o.payload, self.pl11_r.raw)),
                    self.k2.eq(_signed_quotient(self.div2.o.payload, self.pl21_r.raw)),
                    flags.eq(flags | self.div1.o.payload.overflow | self.div2.o.payload.overflow),
                ]
                m.next = "MUL"
        with m.State("MUL"):
            m.d.sync += [assign for _, assign in self.products]
            m.next = "WB"

    def write_states(self):
        m, core = self.m, self.core
        with m.State("WB"):
            m.d.sync += [at(self.regs[n], self.channel).eq(self.next_state[n].raw) for n in self.names]
            m.d.sync += [self.v_done.eq(self.v_n.raw), self.x1_done.eq(self.x1_n.raw)]
            if self.wb_live:
                m.d.sync += self.wb_bits.eq(Cat(*self.wb_live))
            m.next = "X1"
        with m.State("X1"):
            if core.rate_steps:
                m.d.sync += [self.op_assign, self.flags.eq(any_flag([self.flags, self.wb_any, self.rate_flags[0]]))]
                m.next = "X2"
            else:
                self.emit(self.x2_n)
        if core.rate_steps:
            with m.State("X2"):
                m.d.sync += self.pr_assign
                m.next = "X3"
            with m.State("X3"):
                self.emit(self.x2_n)


def _signed_quotient(result, numerator):
    return Mux(numerator < 0, -result.quotient, result.quotient)


def make_core(config, variant, *, channels=1, stages=None):
    """The core of ``variant`` ("steady" or "full"), each with the stages that meet 50 MHz;
    ``stages``: L of the steady loop (default 4), which the time-varying core does not have."""
    if variant == "steady":
        return SteadyCore(config, channels=channels, stages=4 if stages is None else stages)
    if variant == "full":
        if stages is not None:
            raise ValueError("stages applies to the steady variant's loop; the time-varying core has a fixed schedule")
        return FullCore(config, channels=channels)
    raise ValueError(f"variant must be 'steady' or 'full', not {variant!r}")
