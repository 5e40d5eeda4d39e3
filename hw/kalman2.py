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

from kfpga.core.ads8364 import CODE_FORMAT
from kfpga.core.board import MAX_SENSORS
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

    max_channels = MAX_SENSORS  # past eight, the states in block memory (LoopPipeline)


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
        m = Module()
        f = self.config.formats
        names = ("x1", "v", "p11", "p12", "p21", "p22")
        regs = self._states(names)
        m.submodules.div1 = div1 = Divider(**self._divider_args)
        m.submodules.div2 = div2 = Divider(**self._divider_args)
        points = dict(self.config.spec.variants["full"].state_for(self.config.params))

        # working registers of the channel being updated
        channel = Signal.like(self.i.payload.channel)
        sample = Signal(signed(CODE_FORMAT.width))
        work = {n: Signal(signed(f[points[n]].width), name=f"{n}_w") for n in names}
        flags = Signal()  # OR of the overflow flags of this update so far

        # -- TU1: the time update, from the working registers ----------------------------------
        tu1 = self.arith(m, prefix="tu1_")
        k = tu1.constants(self.constants)
        x = {n: tu1.input(work[n], points[n], n) for n in names}
        xl1 = cvloop.predict(tu1, x["x1"], x["v"])                                        # xl1 = x1 + v
        pl = eq.covariance_predict(tu1, k, x["p11"], x["p12"], x["p21"], x["p22"])   # P' = Phi P Phi^T + Q'
        held1 = [tu1.hold(v, n) for v, n in zip((xl1, *pl), ("xl1", "pl11", "pl12", "pl21", "pl22"), strict=True)]
        xl1_r, pl11_r, pl12_r, pl21_r, pl22_r = (h for h, _ in held1)

        # -- TU2: S, the innovation, the dividends ----------------------------------------------
        tu2 = self.arith(m, prefix="tu2_")
        s = eq.innovation_variance(tu2, k, pl11_r)                                    # S = pl11 + R
        e = cvloop.innovation(tu2, tu2.input(sample, CODE_FORMAT, "y"), xl1_r)            # e = y - xl1
        e_r, e_assign = tu2.hold(e, "e")

        def dividend(pl_value):  # |pl| << shift: the divider works on magnitudes
            magnitude = Mux(pl_value < 0, -pl_value, pl_value).as_unsigned()
            return magnitude.shift_left(self.div_shift)[:self.dividend_bits]

        num1, num2 = Signal(self.dividend_bits, name="num1"), Signal(self.dividend_bits, name="num2")
        den = Signal(f["s"].width, name="den")
        m.d.comb += [
            div1.i.payload.dividend.eq(num1), div1.i.payload.divisor.eq(den),
            div2.i.payload.dividend.eq(num2), div2.i.payload.divisor.eq(den),
            div1.o.ready.eq(1), div2.o.ready.eq(1),
        ]

        # -- gains: truncation toward zero, the sign back from the numerator ----------------------
        k1 = Signal(signed(f["gain"].width))
        k2 = Signal(signed(f["gain"].width))

        def signed_quotient(result, numerator):
            return Mux(numerator < 0, -result.quotient, result.quotient)

        # -- MUL: the products (registered); WB: the sums, from the registered products ----------
        mul = self.arith(m, prefix="mul_")
        g1, g2 = mul.input(k1, "gain", "K1"), mul.input(k2, "gain", "K2")
        k1e, k2e, pk = eq.full_products(mul, g1, g2, e_r, pl11_r, pl12_r)
        products = [mul.hold(v, n) for v, n in zip((k1e, k2e, *pk), ("k1e", "k2e", "k1p11", "k1p12", "k2p11", "k2p12"),
                                                   strict=True)]
        k1e_r, k2e_r, *pk_r = (p for p, _ in products)
        wb = self.arith(m, prefix="wb_")
        x1_n = cvloop.correct(wb, xl1_r, k1e_r, "x1")                                     # x1 = xl1 + K1 e
        v_n = cvloop.correct(wb, x["v"], k2e_r, "v")                                      # v = v + K2 e
        p_n = eq.covariance_correct(wb, (pl11_r, pl12_r, pl21_r, pl22_r), pk_r)       # P = P' - K C P'
        next_state = dict(zip(names, (x1_n, v_n, *p_n), strict=True))
        # the flags of WB are registered one by one and ORed in the next cycle: an OR tree
        # after the saturations would lengthen WB's path by two LUT levels
        wb_live = live_flags([flag for _, flag in wb.flags])
        wb_bits = Signal(len(wb_live), name="wb_flags") if wb_live else None
        wb_any = wb_bits.any() if wb_live else NO_OVERFLOW

        # -- x2 = v / T from the new v: free when T = 2**k, else three steps ---------------------
        v_done = Signal(signed(f["v"].width), name="v_done")
        x1_done = Signal(signed(f["x1"].width), name="x1_done")
        v_done_fx = Fx(v_done, f["v"].frac_bits, None, f["v"], "v")
        rate_ops = [self.arith(m, prefix=f"x{n}_") for n in range(1, 4)]
        if self.rate_steps:
            operand, op_assign = rate_ops[0].hold(cvloop.rate_operand(rate_ops[0], k, v_done_fx), "vt")
            product, pr_assign = rate_ops[1].hold(cvloop.rate_product(rate_ops[1], k, operand), "vt_inv_t")
            x2_n = cvloop.rate_write(rate_ops[2], k, product)
            rate_flags = [rate_ops[0].overflow(), NO_OVERFLOW, rate_ops[2].overflow()]
            out_flags = [flags, rate_flags[2]]
        else:
            x2_n = cvloop.rate(rate_ops[0], k, v_done_fx)
            rate_flags = [rate_ops[0].overflow()]
            out_flags = [flags, wb_any, rate_flags[0]]

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)

        self.flag_outputs(m, out_flags)

        def emit(x2):
            with m.If(~self.o.valid | self.o.ready):
                m.d.sync += self.o.valid.eq(1)
                write_estimate(m, self, channel, {"x1": Fx(x1_done, 0), "x2": x2, "yhat": xl1_r}, out_flags)
                m.next = "IDLE"

        with m.FSM(name="schedule") as fsm:
            with m.State("IDLE"):
                with m.If(self.i.valid):
                    m.d.sync += [channel.eq(self.i.payload.channel), sample.eq(self.i.payload.y)]
                    m.d.sync += [work[n].eq(select(regs[n], self.i.payload.channel)) for n in names]
                    m.next = "TU1"
            with m.State("TU1"):
                m.d.sync += [assign for _, assign in held1]
                m.d.sync += flags.eq(tu1.overflow())  # the constant 0 when no TU1 write can overflow
                m.next = "TU2"
            with m.State("TU2"):
                m.d.sync += [e_assign, flags.eq(any_flag([flags, tu2.overflow()])),
                             num1.eq(dividend(pl11_r.raw)), num2.eq(dividend(pl21_r.raw)),
                             den.eq(Mux(s.raw > 0, s.raw.as_unsigned(), 0))]  # S <= 0: a zero divisor (saturates)
                m.next = "GO"
            with m.State("GO"):
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
                m.d.sync += [at(regs[n], channel).eq(next_state[n].raw) for n in names]
                m.d.sync += [v_done.eq(v_n.raw), x1_done.eq(x1_n.raw)]
                if wb_live:
                    m.d.sync += wb_bits.eq(Cat(*wb_live))
                m.next = "X1"
            with m.State("X1"):
                if self.rate_steps:
                    m.d.sync += [op_assign, flags.eq(any_flag([flags, wb_any, rate_flags[0]]))]
                    m.next = "X2"
                else:
                    emit(x2_n)
            if self.rate_steps:
                with m.State("X2"):
                    m.d.sync += pr_assign
                    m.next = "X3"
                with m.State("X3"):
                    emit(x2_n)
        # plain assignments (Verilog `assign`), not case-statement outputs: no simulator can
        # leave them undefined at time zero while the state has not changed yet
        m.d.comb += [
            self.i.ready.eq(fsm.ongoing("IDLE")),
            div1.i.valid.eq(fsm.ongoing("GO")),
            div2.i.valid.eq(fsm.ongoing("GO")),
        ]
        return m


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
