"""Cores of the general state-space filter (``model/kalman.py``), from its own stage functions.

* :class:`SteadyCore`: x = F x + K (y - H F x) over four or five register stages, channels
  interleaved (:class:`~kfpga.hw.core.LoopPipeline`): predict; observe and innovate; the
  products K e; correct. Any n = 1..4, m = 1..2; with m = 2 both samples of an update come in one word.
* :class:`FullCore`: the time-varying filter for one observation on one shared multiplier and one
  shared restoring divider, a hand-written schedule (below). Two observations are model-only.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import ClassVar

from amaranth import Cat, Const, Module, Mux, Signal, signed

from kfpga.core.board import MAX_CHANNELS
from kfpga.core.codes import CODE_FORMAT
from kfpga.core.ops import Fx, divider_shift, quotient_bits
from kfpga.hw.arith import live_flags
from kfpga.hw.core import Core, LoopPipeline, write_estimate
from kfpga.hw.divider import Divider
from kfpga.hw.storage import at, select
from kfpga.model import kalman as eq

__all__ = ["SteadyCore", "FullCore", "make_core", "default_stages"]


def _states(k, live):
    return [live[f"x{i + 1}"] for i in range(k["n"])]


def _predict_operands(ops, k, live):
    for j, v in eq.predict_operands(ops, k, _states(k, live)).items():          # xo_j = [x_j]_xo
        live[f"xo{j + 1}"] = v
    return live


def _predict_terms(ops, k, live):
    xo = {j: live[f"xo{j + 1}"] for j in range(k["n"]) if f"xo{j + 1}" in live}
    for i, row in enumerate(eq.predict_terms(ops, k, _states(k, live), xo)):   # F_ij x_j, exact
        for j, v in enumerate(row):
            if v is not None:
                live[f"ft{i}{j}"] = v
    return live


def _predict_sums(ops, k, live):
    terms = [[live.get(f"ft{i}{j}") for j in range(k["n"])] for i in range(k["n"])]
    for i, v in enumerate(eq.predict_sums(ops, k, None, terms)):               # F x, exact
        live[f"xs{i + 1}"] = v
    return live


def _predict_round(ops, k, live):
    for i in range(k["n"]):                                                     # xl = [F x]_xl
        live[f"xl{i + 1}"] = ops.rq(live[f"xs{i + 1}"], f"xl{i + 1}")
    return live


def _observe(ops, k, live):
    xl = [live[f"xl{i + 1}"] for i in range(k["n"])]
    yh = eq.observe(ops, k, xl)                                                 # yh = H xl
    e = eq.innovations(ops, k, {name: live[name] for name in k["observations"]}, yh)  # e = y - yh
    live.update({f"yh{j + 1}": yh[j] for j in range(k["m"])})
    live.update({f"e{j + 1}": e[j] for j in range(k["m"])})
    return live


def _products(ops, k, live):
    e = [live[f"e{j + 1}"] for j in range(k["m"])]
    for i, row in enumerate(eq.gain_products(ops, k, e)):                       # K e
        for j, v in enumerate(row):
            live[f"ke{i}{j}"] = v
    return live


def _correct(ops, k, live):
    xl = [live[f"xl{i + 1}"] for i in range(k["n"])]
    products = [[live[f"ke{i}{j}"] for j in range(k["m"])] for i in range(k["n"])]
    for i, v in enumerate(eq.correct(ops, k, xl, products)):                   # x = xl + K e
        live[f"x{i + 1}_next"] = v
    return live


# With two observations x = xl + K e sums three terms, and the sum is split over two steps:
# xl + K_i1 e_1, exact, then that plus K_i2 e_2, rounded. The model's exact sum adds its terms
# in the same order, so the integers are the same by construction.
def _correct_first(ops, k, live):
    for i in range(k["n"]):                                                     # xl + K_i1 e_1, exact
        live[f"xk{i + 1}"] = ops.add(live[f"xl{i + 1}"], live[f"ke{i}0"])
    return live


def _correct_second(ops, k, live):
    partial = [live[f"xk{i + 1}"] for i in range(k["n"])]
    products = [[live[f"ke{i}1"]] for i in range(k["n"])]
    for i, v in enumerate(eq.correct(ops, k, partial, products)):              # x = [xl + K_i1 e_1 + K_i2 e_2]_x
        live[f"x{i + 1}_next"] = v
    return live


_ALL = range(1, 5)
_OBS = range(1, 3)


def default_stages(params):
    """The register stages of the steady loop when none are asked for: 4; one more when a row of F
    sums three or more states (its exact sum and its rounding then get a stage each), and one more
    with two observations (x = xl + K e then sums three terms, over two stages)."""
    wide_f = any(sum(1 for v in row if v != 0) >= 3 for row in params.F)
    return 4 + wide_f + (params.m == 2)


class SteadyCore(LoopPipeline):
    """The steady-state filter of any model: x = xl + K e, xl = F x, e = y - H xl.

    Seven steps (``stages`` 1..7 register stages, :attr:`cuts`): the states a constant of F
    multiplies rounded into its operands; the products F_ij x_j; the exact sums F x; their
    rounding xl = [F x]; yh = H xl and e = y - yh; the products K e; x = xl + K e. With five
    stages the first three steps share one, with fewer the steps are grouped further; six and
    seven give the products by F (then their operands) stages of their own, for constants of F
    that are not powers of two. With two observations the last step is split in two (``stages``
    1..8): xl + K_i1 e_1, exact, then x = [that + K_i2 e_2]. One
    channel takes a sample every L cycles, C >= L channels in turn one per clock. The default
    L is :func:`default_stages`. Parameters and members as
    :class:`~kfpga.hw.cvloop.ConstantGainLoop`; the input word has one field per observation.
    """

    max_channels = MAX_CHANNELS  # past eight, the states in block memory (LoopPipeline)

    steps = (_predict_operands, _predict_terms, _predict_sums, _predict_round, _observe, _products, _correct)
    reads = ({f"x{i}" for i in _ALL}, {f"x{i}" for i in _ALL} | {f"xo{i}" for i in _ALL},
             {f"ft{i}{j}" for i in range(4) for j in range(4)}, {f"xs{i}" for i in _ALL},
             {f"xl{i}" for i in _ALL} | {"y", "y1", "y2"},
             {f"e{j}" for j in _OBS}, {f"xl{i}" for i in _ALL} | {f"ke{i}{j}" for i in range(4) for j in range(2)})
    # F's entries 0 or +-2**k: the steps of products by F are empty, and up to five stages cut as
    # the loop always has
    cuts: ClassVar[dict] = MappingProxyType({1: (), 2: (5,), 3: (4, 6), 4: (4, 5, 6), 5: (3, 4, 5, 6),
                                             6: (2, 3, 4, 5, 6), 7: (1, 2, 3, 4, 5, 6)})
    cuts_two_observations: ClassVar[dict] = MappingProxyType(
        {1: (), 2: (5,), 3: (4, 6), 4: (4, 5, 6), 5: (4, 5, 6, 7), 6: (3, 4, 5, 6, 7), 7: (2, 3, 4, 5, 6, 7),
         8: (1, 2, 3, 4, 5, 6, 7)})
    # constants of F that take multipliers: the operands are rounded in a stage of their own first
    # (the rounding's carry chain, the multiplier and the sum in one stage would be the longest
    # path); measured with kfpga explore on 2- and 3-state trackers at T = 0.01 s
    cuts_multiplied: ClassVar[dict] = MappingProxyType({1: (), 2: (4,), 3: (2, 5), 4: (1, 4, 5), 5: (1, 2, 4, 5),
                                                        6: (1, 2, 3, 4, 5), 7: (1, 2, 3, 4, 5, 6)})
    cuts_multiplied_two_observations: ClassVar[dict] = MappingProxyType(
        {1: (), 2: (4,), 3: (2, 5), 4: (1, 4, 5), 5: (1, 2, 4, 5), 6: (1, 2, 4, 5, 6), 7: (1, 2, 3, 4, 5, 6),
         8: (1, 2, 3, 4, 5, 6, 7)})
    carry = ("yh1", "yh2")

    def __init__(self, config, *, channels=1, stages=None):
        n = config.params.n
        self.writes = {f"x{i + 1}": f"x{i + 1}_next" for i in range(n)}
        # the observations' names are the model's own: the step after the prediction reads them
        names = set(config.inputs)
        self.reads = (*self.reads[:4], self.reads[4] | names, *self.reads[5:])
        if config.params.m == 2:
            self.steps = (*self.steps[:6], _correct_first, _correct_second)
            self.reads = (*self.reads[:6], {f"xl{i}" for i in _ALL} | {f"ke{i}0" for i in range(4)},
                          {f"xk{i}" for i in _ALL} | {f"ke{i}1" for i in range(4)})
            self.cuts = self.cuts_two_observations
        if any(not eq.free(v) for row in config.params.F for v in row):
            self.cuts = self.cuts_multiplied if config.params.m == 1 else self.cuts_multiplied_two_observations
        stages = default_stages(config.params) if stages is None else stages
        super().__init__(config, "steady", channels=channels, stages=stages)

    def outputs(self, live):
        k = self.constants
        out = {f"x{i + 1}": live[f"x{i + 1}_next"] for i in range(k["n"])}
        out.update({f"yhat{j + 1}": live[f"yh{j + 1}"] for j in range(k["m"])})
        return out


class FullCore(Core):
    """The time-varying filter for one observation on one multiplier and one divider.

    Schedule per update (one channel at a time), at most one carry chain or one multiplier
    between two registers::

        IDLE   accept a sample; load the channel's state
        T1     F x and F P, exact sums (products by F are shifts)
        T2     xl = [F x]_xl; (F P) F^T + G Q G^T, exact
        T3     Pl = [...]_pl; yh = [H xl]_yh; e = [y - yh]_e
        T4     S = [H Pl H^T + R]_s; the dividends |H Pl|_i, shifted
        DIV    n divisions K_i = (H Pl)_i / S, one after the other on one divider
               (quotient_bits + 2 cycles each)
        MUL    the n + n(n+1)/2 products K_i e and K_i (H Pl)_j, one per cycle on one multiplier
               whose operands are registered (one more cycle)
        WB     x = [xl + K e]_x, P = [Pl - K H Pl]_p, written back; flags registered
        OUT    the estimate out

    :attr:`cycles_per_update` is ``5 + n (quotient_bits + 2) + n + n(n+1)/2 + 3``. Parameters and
    members as :class:`SteadyCore` (no ``stages``).
    """

    def __init__(self, config, *, channels=1):
        config.require_hardware("full", "parallel")
        super().__init__(config, "full", channels)
        f, n = config.formats, config.params.n
        self.n = n
        self.h_index = [j for j, v in enumerate(config.params.H[0]) if v != 0]
        self.qbits = [quotient_bits(f[f"k{i + 1}"]) for i in range(n)]
        self.products = [("e", i, 0) for i in range(n)] + [("p", i, j, 0) for i in range(n) for j in range(i, n)]

    @property
    def divide_cycles(self):
        return max(self.qbits) + 2  # a start cycle, then quotient_bits + 1 cycles of the divider

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to being able to accept the next (``o`` always ready)."""
        return 1 + 4 + self.n * self.divide_cycles + len(self.products) + 1 + 1 + 1

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.cycles_per_update

    def elaborate(self, platform):
        b = _FullBuild(self, Module())
        b.predict()
        b.divide()
        b.multiply()
        b.write_back()
        b.schedule()
        return b.m


class _FullBuild:
    """The parts of a :class:`FullCore`, one method per step of its schedule; each keeps as
    attributes the signals the later ones use."""

    def __init__(self, core, m):
        self.core, self.m = core, m
        self.f, self.n = core.config.formats, core.n
        self.regs = core._states()
        self.names = list(self.regs)
        self.channel = Signal.like(core.i.payload.channel)
        self.obs = core.config.inputs[0]
        self.sample = Signal(signed(CODE_FORMAT.width))
        self.work = {nm: Signal(signed(self.f[core.state_points[nm]].width), name=f"{nm}_w") for nm in self.names}
        # the overflow flags of each step, registered as they are (ORed only when the word is written)
        self.step_flags = []

    def keep_flags(self, ops, tag):
        live = live_flags([flag for _, flag in ops.flags])
        if not live:
            return []  # no write of the step can overflow: no register
        reg = Signal(len(live), name=f"{tag}_flags")
        self.step_flags.append(reg)
        return [reg.eq(Cat(*live))]

    def fx(self, signal, point):
        return Fx(signal.as_signed(), self.f[point].frac_bits, None, self.f[point], point)

    def p_read(self, i, j):
        name = f"p{min(i, j) + 1}{max(i, j) + 1}"
        return self.fx(self.work[name], name)

    def predict(self):
        """T1: exact F x and F P; T2: xl, and (F P) F^T + G Q G^T exact; T3: Pl, yh, e."""
        m, core, n = self.m, self.core, self.n
        x = [self.fx(self.work[f"x{i + 1}"], f"x{i + 1}") for i in range(n)]
        self.t1 = t1 = core.arith(m, prefix="t1_")
        self.k = k = t1.constants(core.constants)
        self.xl_sum = [t1.hold(v, f"xlsum{i}") for i, v in enumerate(eq.predict_sums(t1, k, x))]
        self.fp = [[t1.hold(v, f"fp{i}{j}") for j, v in enumerate(row)]
                   for i, row in enumerate(eq.covariance_fp(t1, k, self.p_read))]
        self.t2 = t2 = core.arith(m, prefix="t2_")
        self.xl = [t2.hold(t2.rq(v, f"xl{i + 1}"), f"xl{i}") for i, (v, _) in enumerate(self.xl_sum)]
        self.pl_sum = {ij: t2.hold(v, f"plsum{ij[0]}{ij[1]}")
                       for ij, v in eq.covariance_sums(t2, k, [[h for h, _ in row] for row in self.fp]).items()}
        self.t3 = t3 = core.arith(m, prefix="t3_")
        self.pl = {ij: t3.hold(t3.rq(v, f"pl{ij[0] + 1}{ij[1] + 1}"), f"pl{ij[0]}{ij[1]}")
                   for ij, (v, _) in self.pl_sum.items()}
        self.xl_r = [h for h, _ in self.xl]
        yh = eq.observe(t3, k, self.xl_r)
        e = eq.innovations(t3, k, {self.obs: t3.input(self.sample, CODE_FORMAT, self.obs)}, yh)
        self.yh_r, self.yh_assign = t3.hold(yh[0], "yh")
        self.e_r, self.e_assign = t3.hold(e[0], "e")

    def divide(self):
        """T4: S and the dividends; DIV: one gain after another on one divider."""
        m, core, f, n = self.m, self.core, self.f, self.n
        self.t4 = t4 = core.arith(m, prefix="t4_")
        self.pl_r = {ij: h for ij, (h, _) in self.pl.items()}
        self.hp = hp = eq.observed_rows(t4, self.k, self.pl_r)
        self.s = s = eq.innovation_variance(t4, self.k, hp)
        self.shifts = [divider_shift(hp[0][i].frac, s.frac, f[f"k{i + 1}"].frac_bits) for i in range(n)]
        widths = [len(hp[0][i].raw) + self.shifts[i] for i in range(n)]
        self.div = div = Divider(dividend_bits=max(widths), divisor_bits=f["s"].width, quotient_bits=max(core.qbits))
        m.submodules.div = div
        self.nums = [Signal(max(widths), name=f"num{i}") for i in range(n)]
        self.den = Signal(f["s"].width, name="den")
        self.index = index = Signal(range(max(n, len(core.products)) + 1), name="index")
        self.gains = [Signal(signed(f[f"k{i + 1}"].width), name=f"K{i}") for i in range(n)]
        q = div.o.payload.quotient
        limit = Signal(max(core.qbits) + 1, name="limit")
        # operands chosen by mux trees, not case blocks (see storage.select)
        m.d.comb += limit.eq(select([Const((1 << b) - 1, len(limit)) for b in core.qbits], index))
        sel_num = Signal(max(widths))
        m.d.comb += [sel_num.eq(select(self.nums, index)), div.i.payload.dividend.eq(sel_num),
                     div.i.payload.divisor.eq(self.den), div.o.ready.eq(1)]
        self.hp_sign = Signal(n)
        self.saturate = (div.o.payload.overflow | (q > limit))
        self.quotient = Mux(self.saturate, limit, q)

    def multiply(self):
        """MUL: one product per cycle on one multiplier."""
        m, core, f, n, hp = self.m, self.core, self.f, self.n, self.hp
        operands_a = [Fx(g, f[f"k{i + 1}"].frac_bits) for i, g in enumerate(self.gains)]
        self.hp_r = [Signal(signed(len(hp[0][j].raw)), name=f"hp{j}") for j in range(n)]
        hp_fx = [Fx(self.hp_r[j], hp[0][j].frac) for j in range(n)]
        pairs = [(operands_a[p[1]], self.e_r if p[0] == "e" else hp_fx[p[2]]) for p in core.products]
        width_a = max(len(a.raw) for a, _ in pairs)
        width_b = max(len(b.raw) for _, b in pairs)
        # the operands are registered: the mux in front of the multiplier gets a cycle of its own
        self.sel_a, self.sel_b = Signal(signed(width_a)), Signal(signed(width_b))
        m.d.comb += [self.sel_a.eq(select([a.raw.as_signed() for a, _ in pairs], self.index)),
                     self.sel_b.eq(select([b.raw.as_signed() for _, b in pairs], self.index))]
        self.op_a, self.op_b = Signal(signed(width_a), name="op_a"), Signal(signed(width_b), name="op_b")
        self.product = Signal(signed(width_a + width_b), name="product")
        m.d.comb += self.product.eq(self.op_a * self.op_b)
        self.prod_regs = [Signal(signed(len(a.raw) + len(b.raw)), name=f"prod{idx}") for idx, (a, b) in enumerate(pairs)]
        self.products = {p: Fx(self.prod_regs[idx], pairs[idx][0].frac + pairs[idx][1].frac)
                         for idx, p in enumerate(core.products)}

    def write_back(self):
        """WB: the corrections from the registered products; the flags of every step."""
        m, core = self.m, self.core
        wb = core.arith(m, prefix="wb_")
        self.state = eq.update_corrections(wb, self.k, self.xl_r, self.pl_r, self.products)
        self.wb_live = live_flags([flag for _, flag in wb.flags])
        self.wb_bits = Signal(max(len(self.wb_live), 1), name="wb_flags")
        self.done = {nm: Signal(signed(self.f[core.state_points[nm]].width), name=f"{nm}_done")
                     for nm in (f"x{i + 1}" for i in range(self.n))}
        self.div_flags = Signal(name="div_flags")
        self.kept = {tag: self.keep_flags(ops, tag)
                     for tag, ops in (("t1", self.t1), ("t2", self.t2), ("t3", self.t3), ("t4", self.t4))}
        self.out_flags = ([r.any() for r in self.step_flags] + [self.div_flags] +
                          ([self.wb_bits.any()] if self.wb_live else []))
        core.flag_outputs(m, self.out_flags)

    def schedule(self):
        m, core = self.m, self.core
        with m.If(core.o.valid & core.o.ready):
            m.d.sync += core.o.valid.eq(0)
        with m.FSM(name="schedule") as fsm:
            self.predict_states()
            self.divide_states()
            self.finish_states()
        # plain assignments (Verilog `assign`), not case-statement outputs: no simulator can
        # leave them undefined at time zero while the state has not changed yet
        m.d.comb += [core.i.ready.eq(fsm.ongoing("IDLE")), self.div.i.valid.eq(fsm.ongoing("GO"))]

    def predict_states(self):
        m, core, kept = self.m, self.core, self.kept
        with m.State("IDLE"):
            with m.If(core.i.valid):
                m.d.sync += [self.channel.eq(core.i.payload.channel), self.sample.eq(getattr(core.i.payload, self.obs))]
                m.d.sync += [self.work[nm].eq(select(self.regs[nm], core.i.payload.channel)) for nm in self.names]
                m.next = "T1"
        with m.State("T1"):
            m.d.sync += [a for _, a in self.xl_sum] + [a for row in self.fp for _, a in row]
            m.d.sync += kept["t1"]
            m.next = "T2"
        with m.State("T2"):
            m.d.sync += [a for _, a in self.xl] + [a for _, a in self.pl_sum.values()]
            m.d.sync += kept["t2"]
            m.next = "T3"
        with m.State("T3"):
            m.d.sync += [a for _, a in self.pl.values()] + [self.yh_assign, self.e_assign]
            m.d.sync += kept["t3"]
            m.next = "T4"

    def divide_states(self):
        m, n, hp, index = self.m, self.n, self.hp, self.index

        def magnitude(v, shift):
            return Mux(v < 0, -v, v).as_unsigned().shift_left(shift)

        with m.State("T4"):
            m.d.sync += [self.nums[i].eq(magnitude(hp[0][i].raw, self.shifts[i])) for i in range(n)]
            m.d.sync += [self.hp_r[j].eq(hp[0][j].raw) for j in range(n)]
            m.d.sync += [self.hp_sign.eq(Cat(*(hp[0][i].raw < 0 for i in range(n)))), index.eq(0)]
            m.d.sync += [self.den.eq(Mux(self.s.raw > 0, self.s.raw.as_unsigned(), 0)), *self.kept["t4"],
                         self.div_flags.eq(0)]
            m.next = "GO"  # S <= 0 becomes a zero divisor (the quotient saturates)
        with m.State("GO"):
            m.next = "DIV"
        with m.State("DIV"):
            with m.If(self.div.o.valid):
                with m.Switch(index):
                    for i in range(n):
                        with m.Case(i):
                            m.d.sync += self.gains[i].eq(Mux(self.hp_sign[i], -self.quotient, self.quotient))
                m.d.sync += [self.div_flags.eq(self.div_flags | self.saturate), index.eq(index + 1)]
                with m.If(index == n - 1):
                    m.d.sync += index.eq(0)
                    m.next = "MUL"
                with m.Else():
                    m.next = "GO"

    def finish_states(self):
        m, core, index = self.m, self.core, self.index
        with m.State("MUL"):  # cycle c loads the operands of product c and stores product c - 1
            m.d.sync += [self.op_a.eq(self.sel_a), self.op_b.eq(self.sel_b), index.eq(index + 1)]
            with m.Switch(index):
                for idx, reg in enumerate(self.prod_regs, start=1):
                    with m.Case(idx):
                        m.d.sync += reg.eq(self.product)
            with m.If(index == len(core.products)):
                m.next = "WB"
        with m.State("WB"):
            m.d.sync += [at(self.regs[nm], self.channel).eq(self.state[nm].raw) for nm in self.names]
            m.d.sync += [self.done[nm].eq(self.state[nm].raw) for nm in self.done]
            if self.wb_live:
                m.d.sync += self.wb_bits.eq(Cat(*self.wb_live))
            m.next = "OUT"
        with m.State("OUT"):
            with m.If(~core.o.valid | core.o.ready):
                m.d.sync += core.o.valid.eq(1)
                outputs = {nm: Fx(self.done[nm], 0) for nm in self.done}
                outputs["yhat1"] = self.yh_r
                write_estimate(m, core, self.channel, outputs, self.out_flags)
                m.next = "IDLE"


def make_core(config, variant, *, channels=1, stages=None):
    """The core of ``variant`` ("steady" or "full"); ``stages``: L of the steady loop (default
    :func:`default_stages`), which the time-varying core does not have."""
    if variant == "steady":
        return SteadyCore(config, channels=channels, stages=stages)
    if variant == "full":
        if stages is not None:
            raise ValueError("stages applies to the steady variant's loop; the time-varying core has a fixed schedule")
        return FullCore(config, channels=channels)
    raise ValueError(f"variant must be 'steady' or 'full', not {variant!r}")
