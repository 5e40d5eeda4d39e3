"""Kalman filter cores, bit-exact with ``model/kalman.py`` (same ``Datapath``, same integers).

Both cores take a stream of :data:`SampleLayout` words (channel, signed 16-bit sample) and give
one :func:`estimate_layout` word (channel, x1, x2, yhat, overflow) per input word, in order.
Each channel (``channels`` of them, 1 to 8) has its own state; a channel number outside
``0..channels-1`` reads a zero state and updates nothing (Amaranth ``Array`` semantics). The
ADC controller only produces valid ones. With ``channels=1`` the channel field is only carried
through.
"""

from __future__ import annotations

from amaranth import Array, Const, Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from kfpga.config import INPUT_FORMAT
from kfpga.hw.ads8364 import SampleLayout
from kfpga.hw.arith import align_sum, requantize
from kfpga.hw.divider import Divider
from kfpga.model.kalman import Datapath

__all__ = ["estimate_layout", "SteadyKalman", "FullKalman", "make_core"]


def estimate_layout(config):
    """Payload of the cores' output: channel, x1, x2, yhat (raw, in their formats), overflow."""
    f = config.formats
    return data.StructLayout({
        "channel": 3,
        "x1": signed(f["x1"].width),
        "x2": signed(f["x2"].width),
        "yhat": signed(f["xl1"].width),
        "overflow": 1,
    })


def _check_channels(channels):
    if not isinstance(channels, int) or not 1 <= channels <= 8:
        raise ValueError(f"channels must be an integer 1..8, not {channels!r}")


def _state_array(channels, shape, init, name):
    return Array(Signal(shape, init=init, name=f"{name}_{c}") for c in range(channels))


def _select(states, index):
    """``states[index]`` as a balanced tree of ``Mux`` on the index bits (Verilog ``assign``).

    Not an ``Array`` read: that becomes an ``always @*`` case block, which an event-driven
    simulator (Icarus) leaves undefined until one of its inputs changes; with channel 0 first
    and the state still at its power-up value, that never happens. A mux tree is a continuous
    assignment, defined from time zero, and its depth grows with log2 of the channel count
    (it sits in the steady-state core's one-cycle loop). An index outside the array reads zero.
    """
    level = list(states)
    while len(level) & (len(level) - 1):
        level.append(Const(0, states[0].shape()))
    bit = 0
    while len(level) > 1:
        level = [Mux(index[bit], level[k + 1], level[k]) for k in range(0, len(level), 2)]
        bit += 1
    return level[0]


def _x2_output(m, d, v):
    """x2 = v / T: a shift when T = 2**k (here only the binary point moves), else [v]_vt * (1/T)."""
    f = d.config.formats
    if d.inv_t is None:
        return requantize(m, v, d.x2_src_frac, f["x2"], name="x2")
    vt, f_vt = requantize(m, v, f["v"].frac_bits, f["vt"], name="vt")  # an 18-bit multiplier operand
    product = vt * Const(d.inv_t, signed(f["inv_t"].width))
    x2, f_x2 = requantize(m, product, d.x2_src_frac, f["x2"], name="x2")
    flag = Signal(name="x2_ovf_any")
    m.d.comb += flag.eq(f_vt | f_x2)
    return x2, flag


def _write_estimate(m, core, channel, x1, x2, yhat, overflowed):
    """Register the estimate word on ``core.o`` and raise the sticky flag on an overflow."""
    m.d.sync += [
        core.o.payload.channel.eq(channel),
        core.o.payload.x1.eq(x1),
        core.o.payload.x2.eq(x2),
        core.o.payload.yhat.eq(yhat),
        core.o.payload.overflow.eq(overflowed),
    ]
    with m.If(overflowed):
        m.d.sync += core.overflow.eq(1)


def _measurement_update(m, d, y, xl1, v, k1, k2, gain_shape):
    """e, then x1 = xl1 + K1 e and v = v + K2 e; returns ``(e, x1, v, flags)``."""
    f = d.config.formats
    e_full, e_frac = align_sum([y, xl1], [INPUT_FORMAT.frac_bits, f["xl1"].frac_bits], sub=True)
    e, f_e = requantize(m, e_full, e_frac, f["e"], name="e")
    k1e = Signal(signed(gain_shape + f["e"].width), name="k1e")
    k2e = Signal(signed(gain_shape + f["e"].width), name="k2e")
    m.d.comb += [k1e.eq(k1 * e), k2e.eq(k2 * e)]
    fp = f["gain"].frac_bits + f["e"].frac_bits
    x1_full, x1_frac = align_sum([xl1, k1e], [f["xl1"].frac_bits, fp])
    x1n, f_x1 = requantize(m, x1_full, x1_frac, f["x1"], name="x1_next")
    v_full, v_frac = align_sum([v, k2e], [f["v"].frac_bits, fp])
    vn, f_v = requantize(m, v_full, v_frac, f["v"], name="v_next")
    return e, x1n, vn, [f_e, f_x1, f_v]


class SteadyKalman(wiring.Component):
    """Steady-state (constant-gain) Kalman core: one sample per clock, fully pipelined.

    Stage 1 registers the input word; stage 2 computes the whole update (the loop
    x -> xl1 -> e -> K e -> x must close within one cycle to take a sample every clock) and
    registers the state and the output word. Latency: an input accepted in cycle ``c`` is on
    ``o`` (``o.valid`` high) in cycle ``c + 2``. Both stages stall together when ``o`` is not
    ready, so nothing is dropped.

    Parameters
    ----------
    config:
        The shared :class:`~kfpga.config.KalmanConfig`.
    channels:
        Independent channel states (1..8).

    Members
    -------
    i : In(stream.Signature(SampleLayout))
        Samples.
    o : Out(stream.Signature(estimate_layout(config)))
        Estimates, one per sample.
    overflow : Out(1)
        Sticky: some write saturated (or wrapped) since reset.
    """

    LATENCY = 2
    CYCLES_PER_UPDATE = 1

    def __init__(self, config, *, channels=1):
        _check_channels(channels)
        self.config = config
        self.channels = channels
        self.datapath = Datapath(config, "steady")
        super().__init__({
            "i": In(stream.Signature(SampleLayout)),
            "o": Out(stream.Signature(estimate_layout(config))),
            "overflow": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        d, f = self.datapath, self.config.formats
        x1s = _state_array(self.channels, signed(f["x1"].width), d.x0[0], "x1")
        vs = _state_array(self.channels, signed(f["v"].width), d.x0[1], "v")

        # stage 1: input register
        a_valid = Signal()
        a_sample = Signal(signed(16))
        a_channel = Signal(3)
        advance = ~self.o.valid | self.o.ready
        m.d.comb += self.i.ready.eq(advance)
        with m.If(advance):
            m.d.sync += [
                a_valid.eq(self.i.valid),
                a_sample.eq(self.i.payload.sample),
                a_channel.eq(self.i.payload.channel),
            ]

        # stage 2: the update
        index = a_channel if self.channels > 1 else 0
        x1, v = (_select(x1s, index), _select(vs, index)) if self.channels > 1 else (x1s[0], vs[0])
        xl1_full, xl1_frac = align_sum([x1, v], [f["x1"].frac_bits, f["v"].frac_bits])
        xl1, f_xl1 = requantize(m, xl1_full, xl1_frac, f["xl1"], name="xl1")        # xl1 = x1 + v
        gw = f["gain"].width
        k1, k2 = Const(d.k1, signed(gw)), Const(d.k2, signed(gw))
        _, x1n, vn, flags = _measurement_update(m, d, a_sample, xl1, v, k1, k2, gw)  # e, x1, v
        x2, f_x2 = _x2_output(m, d, vn)                                               # x2 = v / T
        overflowed = Signal()
        m.d.comb += overflowed.eq(f_xl1 | f_x2 | flags[0] | flags[1] | flags[2])

        with m.If(advance):
            m.d.sync += self.o.valid.eq(a_valid)
            with m.If(a_valid):
                m.d.sync += [x1s[index].eq(x1n), vs[index].eq(vn)]
                _write_estimate(m, self, a_channel, x1n, x2, xl1, overflowed)
        return m


class FullKalman(wiring.Component):
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
        _check_channels(channels)
        self.config = config
        self.channels = channels
        self.datapath = Datapath(config, "full")
        f = config.formats
        d = self.datapath
        self.dividend_bits = f["pl"].width + d.div_shift
        self._divider_args = {"dividend_bits": self.dividend_bits, "divisor_bits": f["s"].width,
                              "quotient_bits": d.quotient_bits}
        super().__init__({
            "i": In(stream.Signature(SampleLayout)),
            "o": Out(stream.Signature(estimate_layout(config))),
            "overflow": Out(1),
        })

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to being able to accept the next (o always ready)."""
        return 1 + 1 + (self.datapath.quotient_bits + 1) + 1 + 1

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.cycles_per_update

    def elaborate(self, platform):
        m = Module()
        d, f = self.datapath, self.config.formats
        ch = self.channels
        x1s = _state_array(ch, signed(f["x1"].width), d.x0[0], "x1")
        vs = _state_array(ch, signed(f["v"].width), d.x0[1], "v")
        ps = [_state_array(ch, signed(f["p"].width), d.p0[k], f"p{name}") for k, name in enumerate(("11", "12", "21", "22"))]

        m.submodules.div1 = div1 = Divider(**self._divider_args)
        m.submodules.div2 = div2 = Divider(**self._divider_args)

        # working registers of the channel being updated
        channel = Signal(3)
        sample = Signal(signed(16))
        x1 = Signal(signed(f["x1"].width))
        v = Signal(signed(f["v"].width))
        p11, p12, p21, p22 = (Signal(signed(f["p"].width), name=f"p{n}") for n in ("11", "12", "21", "22"))
        xl1 = Signal(signed(f["xl1"].width))
        pl11, pl12, pl21, pl22 = (Signal(signed(f["pl"].width), name=f"pl{n}_r") for n in ("11", "12", "21", "22"))
        e = Signal(signed(f["e"].width))
        k1 = Signal(signed(f["gain"].width))
        k2 = Signal(signed(f["gain"].width))
        flags = Signal()  # OR of the overflow flags of this update so far
        gw, plw, ew = f["gain"].width, f["pl"].width, f["e"].width
        k1e, k2e = Signal(signed(gw + ew)), Signal(signed(gw + ew))
        k1p11, k1p12, k2p11, k2p12 = (Signal(signed(gw + plw), name=n) for n in ("k1p11", "k1p12", "k2p11", "k2p12"))

        index = self.i.payload.channel if ch > 1 else 0
        windex = channel if ch > 1 else 0

        # -- time update (combinational from the working registers) -------------------------
        fp, fpl = f["p"].frac_bits, f["pl"].frac_bits
        xl1_full, xl1_frac = align_sum([x1, v], [f["x1"].frac_bits, f["v"].frac_bits])
        xl1_c, f1 = requantize(m, xl1_full, xl1_frac, f["xl1"], name="xl1")                  # xl1 = x1 + v
        pl11_c, f2 = requantize(m, p11 + p12 + p21 + p22, fp, f["pl"], name="pl11")           # pl11 = p11 + p12 + p21 + p22
        pl12_c, f3 = requantize(m, p12 + p22, fp, f["pl"], name="pl12")                        # pl12 = p12 + p22
        pl21_c, f4 = requantize(m, p21 + p22, fp, f["pl"], name="pl21")                        # pl21 = p21 + p22
        q_const = Const(d.q, signed(plw))
        pl22_full, pl22_frac = align_sum([p22, q_const], [fp, fpl])
        pl22_c, f5 = requantize(m, pl22_full, pl22_frac, f["pl"], name="pl22")                 # pl22 = p22 + Q'
        r_const = Const(d.r, signed(f["s"].width))
        s_full, s_frac = align_sum([pl11_c, r_const], [fpl, f["s"].frac_bits])
        s_c, f6 = requantize(m, s_full, s_frac, f["s"], name="s")                              # S = pl11 + R
        e_full, e_frac = align_sum([sample, xl1_c], [INPUT_FORMAT.frac_bits, f["xl1"].frac_bits], sub=True)
        e_c, f9 = requantize(m, e_full, e_frac, f["e"], name="e")                              # e = y - xl1

        # divider operands: |pl| << shift over S; S <= 0 becomes a zero divisor (saturates)
        def dividend(pl):
            magnitude = Mux(pl < 0, -pl, pl).as_unsigned()
            return (magnitude << d.div_shift)[:self.dividend_bits]

        divisor = Mux(s_c > 0, s_c.as_unsigned(), 0)
        m.d.comb += [
            div1.i.payload.dividend.eq(dividend(pl11_c)),
            div1.i.payload.divisor.eq(divisor),
            div2.i.payload.dividend.eq(dividend(pl21_c)),
            div2.i.payload.divisor.eq(divisor),
            div1.o.ready.eq(1),
            div2.o.ready.eq(1),
        ]

        # -- measurement update (combinational from the registered products) ------------------
        fg = f["gain"].frac_bits
        x1_full, x1_frac = align_sum([xl1, k1e], [f["xl1"].frac_bits, fg + f["e"].frac_bits])
        x1_n, f10 = requantize(m, x1_full, x1_frac, f["x1"], name="x1_next")                 # x1 = xl1 + K1 e
        v_full, v_frac = align_sum([v, k2e], [f["v"].frac_bits, fg + f["e"].frac_bits])
        v_n, f11 = requantize(m, v_full, v_frac, f["v"], name="v_next")                       # v = v + K2 e

        def p_update(pl, product, name):
            full, frac = align_sum([pl, product], [fpl, fg + fpl], sub=True)
            return requantize(m, full, frac, f["p"], name=name)

        p11_n, f12 = p_update(pl11, k1p11, "p11_next")                                         # p11 = pl11 - K1 pl11
        p12_n, f13 = p_update(pl12, k1p12, "p12_next")                                         # p12 = pl12 - K1 pl12
        p21_n, f14 = p_update(pl21, k2p11, "p21_next")                                         # p21 = pl21 - K2 pl11
        p22_n, f15 = p_update(pl22, k2p12, "p22_next")                                         # p22 = pl22 - K2 pl12
        x2_n, f16 = _x2_output(m, d, v_n)                                                      # x2 = v / T
        wb_flags = Signal()
        m.d.comb += wb_flags.eq(flags | f10 | f11 | f12 | f13 | f14 | f15 | f16)

        def signed_quotient(result, numerator):
            # truncation toward zero: the divider works on magnitudes, the sign comes back here
            return Mux(numerator < 0, -result.quotient, result.quotient)

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)

        with m.FSM(name="schedule") as fsm:
            with m.State("IDLE"):
                with m.If(self.i.valid):
                    m.d.sync += [
                        channel.eq(self.i.payload.channel),
                        sample.eq(self.i.payload.sample),
                        x1.eq(_select(x1s, index)),
                        v.eq(_select(vs, index)),
                        p11.eq(_select(ps[0], index)),
                        p12.eq(_select(ps[1], index)),
                        p21.eq(_select(ps[2], index)),
                        p22.eq(_select(ps[3], index)),
                    ]
                    m.next = "TU"
            with m.State("TU"):
                m.d.sync += [
                    xl1.eq(xl1_c), pl11.eq(pl11_c), pl12.eq(pl12_c), pl21.eq(pl21_c), pl22.eq(pl22_c), e.eq(e_c),
                    flags.eq(f1 | f2 | f3 | f4 | f5 | f6 | f9),
                ]
                m.next = "DIV"
            with m.State("DIV"):
                with m.If(div1.o.valid):  # both dividers finish in the same cycle
                    m.d.sync += [
                        k1.eq(signed_quotient(div1.o.payload, pl11)),
                        k2.eq(signed_quotient(div2.o.payload, pl21)),
                        flags.eq(flags | div1.o.payload.overflow | div2.o.payload.overflow),
                    ]
                    m.next = "MUL"
            with m.State("MUL"):
                m.d.sync += [
                    k1e.eq(k1 * e), k2e.eq(k2 * e),
                    k1p11.eq(k1 * pl11), k1p12.eq(k1 * pl12), k2p11.eq(k2 * pl11), k2p12.eq(k2 * pl12),
                ]
                m.next = "WB"
            with m.State("WB"):
                with m.If(~self.o.valid | self.o.ready):
                    m.d.sync += [
                        x1s[windex].eq(x1_n), vs[windex].eq(v_n),
                        ps[0][windex].eq(p11_n), ps[1][windex].eq(p12_n),
                        ps[2][windex].eq(p21_n), ps[3][windex].eq(p22_n),
                        self.o.valid.eq(1),
                    ]
                    _write_estimate(m, self, channel, x1_n, x2_n, xl1, wb_flags)
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

