# amaranth: UnusedElaboratable=no
"""The operations layer: every backend computes the same thing, and the shared rules hold.

A stage is written once; these tests run small stages through every backend (Python ints,
int64 arrays, the compiled scalar and vector loops, exact rationals, Amaranth in its simulator)
and hold the results equal, with the rounding and overflow tables of ``tests/test_fixed.py``.
"""

import re
from fractions import Fraction

import numpy as np
import pytest
from amaranth import Module, Signal, signed
from amaranth.sim import Simulator
from test_fixed import MODES, OVERFLOW_TABLE, ROUNDING_TABLE

from kfpga.core.compiled import compile_stage
from kfpga.core.fixed import QFormat
from kfpga.core.ops import FloatOps, FractionOps, IntOps, WidthOps
from kfpga.core.spec import Constant
from kfpga.hw.arith import AmaranthOps
from kfpga.sim.amaranth_streams import run_with_deadline

SRC = QFormat(20, 6)  # the input of the one-write stages


def one_write(fmt):
    """A stage that writes its input (held in ``SRC``) into ``fmt`` once."""

    def stage(ops, k, x, u):
        out = ops.rq(u["a"], fmt, "out")
        return {}, {"out": out}

    return stage


def run_backends(stage, raws, src=SRC, *, amaranth=True):
    """``[(raw, flag)]`` per backend for each input raw integer of ``stage``'s output."""
    results = {}
    for name in ("int", "numpy", "fraction"):
        out = []
        for raw in raws:
            ops = {"int": IntOps, "numpy": IntOps, "fraction": FractionOps}[name]({})
            value = np.array([raw], dtype=np.int64) if name == "numpy" else raw
            _, o = stage(ops, {}, {}, {"a": ops.input(value, src, "a")})
            got = ops.raw_of(o["out"]) if name == "fraction" else int(np.asarray(o["out"].raw).ravel()[0])
            out.append((got, bool(np.asarray(ops.overflow()).ravel()[0])))
        results[name] = out
    for vector in (False, True):
        kernel = compile_stage(stage, {}, constants={}, state=(), inputs=(("a", src),), outputs=("out",), vector=vector)
        n = len(raws)
        if vector:
            outs, flags = [np.zeros(n, dtype=np.int64)], [np.zeros(n, dtype=bool) for _ in kernel.sites]
            kernel.function([np.array(raws, dtype=np.int64)], *outs, *flags)
            any_flag = np.zeros(n, dtype=bool)
            for f in flags:
                any_flag |= f
            results["vector"] = list(zip(outs[0].tolist(), any_flag.tolist(), strict=True))
        else:
            outs, hits = [[0] * n], [[] for _ in kernel.sites]
            kernel.function(list(raws), *outs, *(h.append for h in hits))
            flagged = {i for h in hits for i in h}
            results["scalar"] = [(v, i in flagged) for i, v in enumerate(outs[0])]
    if amaranth:  # a sequential unit (a square root) has no combinational form
        results["amaranth"] = amaranth_run(stage, raws, src)
    return results


def amaranth_run(stage, raws, src):
    """The stage as combinational RTL in Amaranth's simulator."""
    m = Module()
    a = Signal(signed(src.width))
    ops = AmaranthOps(m, {})
    _, o = stage(ops, {}, {}, {"a": ops.input(a, src, "a")})
    flag = ops.overflow()
    out = []

    async def bench(ctx):
        for raw in raws:
            ctx.set(a, raw)
            await ctx.delay(1e-9)
            out.append((ctx.get(o["out"].raw), bool(ctx.get(flag))))

    sim = Simulator(m)
    sim.add_testbench(bench)
    run_with_deadline(sim, len(raws) + 10, period=1e-9)
    return out


@pytest.mark.parametrize(("raw", "shift", *MODES), ROUNDING_TABLE)
def test_rounding_table_on_every_backend(raw, shift, nearest, round, convergent, floor, fix):
    for rounding, expected in zip(MODES, (nearest, round, convergent, floor, fix), strict=True):
        src = QFormat(24, max(shift, 0) + 2)
        fmt = QFormat(24, src.frac_bits - shift, rounding)
        results = run_backends(one_write(fmt), [raw], src)
        for backend, got in results.items():
            assert got == [(expected, False)], (backend, rounding)


@pytest.mark.parametrize(("value", "sat", "wrap", "flag"), OVERFLOW_TABLE)
def test_overflow_table_on_every_backend(value, sat, wrap, flag):
    for overflow, expected in (("saturate", sat), ("wrap", wrap)):
        fmt = QFormat(4, 0, "floor", overflow)
        results = run_backends(one_write(fmt), [value], QFormat(12, 0))
        for backend, got in results.items():
            assert got == [(expected, flag)], (backend, overflow)


def mixed(ops, k, x, u):
    """Sums across binary points, products, a constant shift, a negation, a free binary point move."""
    a, b = u["a"], u["b"]
    s1 = ops.rq(ops.add(a, b), QFormat(14, 5, "half_up"), "s1")
    p = ops.rq(ops.mul(s1, b), QFormat(16, 3, "floor", "wrap"), "p")
    c = ops.rq(ops.sub(ops.mul(k["four"], p), ops.neg(a)), QFormat(18, 2, "half_up"), "c")
    d = ops.rq(ops.add(ops.shift(c, -3), ops.mul(k["third"], s1)), QFormat(12, 6, "half_up"), "d")
    return {}, {"s1": s1, "p": p, "c": c, "d": d}


CONSTS = {"four": Constant(4.0, QFormat(4, 0)), "third": Constant(1 / 3, QFormat(2, 10, "half_up"))}


def test_backends_agree_on_random_values(seed):
    rng = np.random.default_rng(seed)
    fa, fb = QFormat(10, 4), QFormat(8, 7)
    ra = rng.integers(fa.min_raw, fa.max_raw + 1, 400)
    rb = rng.integers(fb.min_raw, fb.max_raw + 1, 400)
    ra[:4], rb[:4] = [fa.min_raw, fa.max_raw, 0, -1], [fb.min_raw, fb.max_raw, fb.min_raw, 0]
    expected = {}
    # exact rationals: the spec
    for i in range(len(ra)):
        ops = FractionOps({})
        k = ops.constants(CONSTS)
        _, o = mixed(ops, k, {}, {"a": ops.input(int(ra[i]), fa, "a"), "b": ops.input(int(rb[i]), fb, "b")})
        for name, v in o.items():
            expected.setdefault(name, []).append(ops.raw_of(v))
    # numpy batch through IntOps
    ops = IntOps({})
    _, o = mixed(ops, ops.constants(CONSTS), {}, {"a": ops.input(ra, fa, "a"), "b": ops.input(rb, fb, "b")})
    for name, v in o.items():
        np.testing.assert_array_equal(v.raw, expected[name], err_msg=name)
    # the compiled loops
    for vector in (False, True):
        kernel = compile_stage(mixed, {}, constants=CONSTS, state=(), inputs=(("a", fa), ("b", fb)),
                               outputs=("s1", "p", "c", "d"), vector=vector)
        n = len(ra)
        if vector:
            outs = [np.zeros(n, dtype=np.int64) for _ in range(4)]
            kernel.function([ra, rb], *outs, *[np.zeros(n, dtype=bool) for _ in kernel.sites])
        else:
            outs = [[0] * n for _ in range(4)]
            kernel.function(list(zip(ra.tolist(), rb.tolist(), strict=True)), *outs, *([].append for _ in kernel.sites))
        for name, got in zip(("s1", "p", "c", "d"), outs, strict=True):
            np.testing.assert_array_equal(got, expected[name], err_msg=f"{name} vector={vector}")


def test_width_rules_are_amaranths():
    """WidthOps gives every intermediate the width Amaranth gives the same expression."""
    fa, fb = QFormat(10, 4), QFormat(8, 7)

    def expressions(ops, a, b):
        k = ops.constants(CONSTS)
        s1 = ops.rq(ops.add(a, b), QFormat(14, 5), "s1")
        return [ops.add(a, b), ops.sub(a, b), ops.neg(a), ops.mul(s1, b), ops.mul(k["four"], s1),
                ops.mul(k["third"], s1), ops.add(ops.mul(k["third"], s1), a)]

    widths = WidthOps({})
    w = expressions(widths, widths.input(None, fa, "a"), widths.input(None, fb, "b"))
    hw = AmaranthOps(Module(), {})
    h = expressions(hw, hw.input(Signal(signed(fa.width)), fa, "a"), hw.input(Signal(signed(fb.width)), fb, "b"))
    assert [x.raw.width for x in w] == [len(x.raw) for x in h]
    # 4 = 2**2 is a shift, no multiplier; 1/3 is a multiplier, counted each time it is built
    assert [m[0] for m in widths.report.multipliers] == ["s1*b", "third*s1", "third*s1"]


def test_division_on_every_backend(seed):
    rng = np.random.default_rng(seed)
    fn, fd, fq = QFormat(7, 11), QFormat(7, 11), QFormat(2, 16)

    def stage(ops, k, x, u):
        return {}, {"q": ops.div(u["n"], u["d"], fq, "q")}

    num = rng.integers(fn.min_raw, fn.max_raw + 1, 300)
    den = rng.integers(-50, fd.max_raw + 1, 300)
    den[:3], num[:3] = [0, -1, 1], [5, 5, fn.max_raw]  # zero and negative divisors, a quotient too big
    spec = []
    for n, d in zip(num.tolist(), den.tolist(), strict=True):
        ops = FractionOps({})
        _, o = stage(ops, {}, {}, {"n": ops.input(n, fn, "n"), "d": ops.input(d, fd, "d")})
        q = Fraction(n, 1 << 11) / Fraction(d, 1 << 11) if d > 0 else None
        spec.append((ops.raw_of(o["q"]), bool(ops.overflow())))
        if q is not None and abs(q) < 2 - 2**-16:
            assert ops.raw_of(o["q"]) == int(q * (1 << 16))  # truncation toward zero
    ops = IntOps({})
    _, o = stage(ops, {}, {}, {"n": ops.input(num, fn, "n"), "d": ops.input(den, fd, "d")})
    assert list(zip(o["q"].raw.tolist(), np.asarray(ops.overflow()).tolist(), strict=True)) == spec
    kernel = compile_stage(stage, {}, constants={}, state=(), inputs=(("n", fn), ("d", fd)), outputs=("q",), vector=False)
    outs, hits = [[0] * len(num)], [[] for _ in kernel.sites]
    kernel.function(list(zip(num.tolist(), den.tolist(), strict=True)), *outs, *(h.append for h in hits))
    flagged = {i for h in hits for i in h}
    assert [(q, i in flagged) for i, q in enumerate(outs[0])] == spec


@pytest.mark.parametrize(("src", "dst"), [(QFormat(20, 6), QFormat(12, 8)),    # radicand shifted left
                                          (QFormat(20, 22), QFormat(8, 6)),    # radicand shifted right (floor)
                                          (QFormat(9, 3), QFormat(4, 2))])     # roots that do not fit
def test_square_root_on_every_backend(seed, src, dst):
    """The restoring square root: the floor of the exact root, saturation and its flag, 0 and the
    flag for a negative radicand; the same integers on Python ints, int64 arrays, the compiled
    scalar and vector loops and exact rationals (whose root is found by bisection, no isqrt)."""
    rng = np.random.default_rng(seed)

    def stage(ops, k, x, u):
        return {}, {"out": ops.sqrt(u["a"], dst, "out")}

    raws = [0, 1, 2, 3, 4, -1, src.min_raw, src.max_raw, *rng.integers(src.min_raw, src.max_raw + 1, 200).tolist()]
    raws += [r * r for r in rng.integers(0, 1 << (src.width // 2 - 1), 20).tolist()]  # perfect squares
    results = run_backends(stage, raws, src, amaranth=False)
    for raw, (got, flag) in zip(raws, results["fraction"], strict=True):
        if raw < 0:
            assert (got, flag) == (0, True)
            continue
        exact = Fraction(raw, 1 << src.frac_bits)
        root = Fraction(got, 1 << dst.frac_bits)
        if flag:
            assert got == dst.max_raw and exact >= Fraction(dst.max_raw + 1, 1 << dst.frac_bits) ** 2
        else:
            assert root * root <= exact < (root + Fraction(1, 1 << dst.frac_bits)) ** 2
    for name, out in results.items():
        assert out == results["fraction"], name


def test_float_backend_is_the_real_valued_stage():
    ops = FloatOps({})
    k = ops.constants(CONSTS)
    _, o = mixed(ops, k, {}, {"a": ops.input(1.5, None, "a"), "b": ops.input(-0.25, None, "b")})
    s1 = 1.25
    assert o["s1"].raw == s1 and o["p"].raw == s1 * -0.25
    assert o["d"].raw == pytest.approx((4 * o["p"].raw + 1.5) / 8 + s1 / 3)
    assert ops.ranges["s1"] == s1 and ops.ranges["third"] == pytest.approx(1 / 3)


def test_a_constant_that_does_not_fit_is_refused():
    with pytest.raises(ValueError, match="^" + re.escape("the constant big = 9.0 does not fit Q4.0") + "$"):
        IntOps({}).const(9.0, QFormat(4, 0), "big")


def test_division_needs_a_whole_dividend():
    ops = WidthOps({})
    message = ("the division q = n / d needs Q2.3.frac_bits + d.frac_bits - n.frac_bits >= 0 (it is -4) "
               "so that the dividend is an exact integer")
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        ops.div(ops.input(None, QFormat(4, 8), "n"), ops.input(None, QFormat(4, 1), "d"), QFormat(2, 3), "q")
