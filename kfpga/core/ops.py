"""The operations layer: a filter's arithmetic written once, run by several backends.

An update stage is a plain Python function over an ``ops`` object::

    def predict(ops, x1, v):
        return ops.rq(ops.add(x1, v), "xl1")          # xl1 = x1 + v

Values are :class:`Fx`: a backend payload and its binary point (``frac``: the payload stands
for ``raw * 2**-frac``). ``add``, ``sub``, ``neg``, ``mul``, ``shift``, ``abs``, ``select``, ``min``,
``max`` and ``sort2`` (a compare-exchange) are exact, ``gt`` gives a condition; ``rq``
writes a value into the format of a quantisation point (the one place where bits are dropped,
with the point's rounding and overflow rules, raising an overflow flag); ``cast`` is an ``rq``
into a *cast point* (a product's or a sum's own result format, as MATLAB's fimath
``SpecifyPrecision`` gives one) when the config gives that point a format, and the exact value
when it does not; ``div`` is the
restoring divider of the time-varying filters and ``sqrt`` the restoring square root of the
square-root covariance forms. The rules every backend shares live here, in
:class:`Ops`, once:

* a sum is aligned to the larger fraction count of its terms (the other term shifted left);
* a product has the sum of the fraction counts;
* a product by a constant 0, +-1 or +-2**k is no multiplier: a zero, the value, or a shift.

Backends (this module; the Amaranth one is ``hw/arith.py``, the compiled fast path
``kfpga/core/compiled.py``):

==================  ==========================================================================
:class:`IntOps`     the bit-accurate integers, on Python ints or numpy int64 arrays
:class:`FloatOps`   float64 values with real constants and no rounding; records every point's
                    largest magnitude (the range analysis)
:class:`WidthOps`   the exact width of every intermediate as the RTL builds it, multiplier
                    count and operand widths, the cast points that stay exact
:class:`FractionOps`  exact rationals rounded once per point: the spec the integer model is
                    tested against, sharing no shift or rounding code with it
==================  ==========================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from kfpga.core.fixed import Overflow, QFormat, Rounding, requantise, to_raw

__all__ = ["Fx", "Ops", "IntOps", "FloatOps", "WidthOps", "FractionOps", "CostOps", "update_cost", "Intermediate",
           "ExactCast", "WidthReport", "update_widths", "divider_shift",
           "const_width",
           "quantise_fraction", "quotient_bits", "divide", "root_shift", "square_root"]


@dataclass(frozen=True, slots=True)
class Fx:
    """A backend value ``raw`` standing for ``raw * 2**-frac``.

    ``const`` is the raw integer when the value is a constant known when the stage is built
    (every backend sees the same integer, so every backend makes the same multiplier choices);
    ``fmt`` is the format the value was written into (``None`` for exact intermediates).
    """

    raw: object
    frac: int
    const: int | None = None
    fmt: QFormat | None = None
    name: str | None = None


def divider_shift(num_frac, den_frac, quotient_frac):
    """Left shift of the dividend so that ``floor(|num| << shift / den)`` has ``quotient_frac`` bits."""
    return quotient_frac + den_frac - num_frac


def root_shift(frac, root_frac):
    """Left shift (negative: floor right shift) of a radicand with ``frac`` fraction bits so that
    its integer square root has ``root_frac`` fraction bits."""
    return 2 * root_frac - frac


def quotient_bits(fmt):
    """Magnitude bits of the divider's quotient written into ``fmt`` (its sign comes back after)."""
    return fmt.width - 1


def const_width(raw, fmt):
    """The width a constant is built with: its significant bits (no redundant sign copies), at
    most its format's. Every backend that counts widths uses this, so the widths it predicts are
    the RTL's; the integers do not depend on it."""
    raw = int(raw)
    return min(fmt.width, (raw if raw >= 0 else ~raw).bit_length() + 1)


def _power_of_two(c):
    """``k`` if ``|c| == 2**k``, else ``None``."""
    c = abs(c)
    return c.bit_length() - 1 if c and not c & (c - 1) else None


class Ops:
    """The arithmetic rules shared by every backend; a backend supplies the primitives.

    Parameters
    ----------
    formats:
        ``{point name: QFormat}`` of the config being built.
    """

    #: The payload is the real value itself (float, Fraction): moving the binary point
    #: rescales it, aligning a sum does not.
    value_payload = False

    def __init__(self, formats):
        self.formats = formats
        self.flags = []  # (name, flag payload) of every rq and div, in order
        self.point_of = {}  # name of every rq and div -> its point (the format's text for a bare format)

    # -- values -------------------------------------------------------------------------
    def fmt(self, point):
        """The format of ``point`` (or ``point`` itself when it is a :class:`QFormat`)."""
        if isinstance(point, QFormat):
            return point
        try:
            return self.formats[point]
        except KeyError:
            raise KeyError(f"no format for quantisation point {point!r}") from None

    def input(self, raw, point, name=None):
        """A value held in the format of ``point`` (a register, a port)."""
        fmt = self.fmt(point)
        return Fx(self._input(raw, fmt, name or _label(point)), fmt.frac_bits, None, fmt, name or _label(point))

    def const(self, value, point, name=None):
        """The real ``value`` quantised into the format of ``point`` (at build time)."""
        fmt = self.fmt(point)
        raw, overflowed = to_raw(value, fmt)
        if overflowed:
            raise ValueError(f"the constant {name or _label(point)} = {value!r} does not fit {fmt}")
        raw = int(raw)
        return Fx(self._const(raw, fmt, value, name or _label(point)), fmt.frac_bits, raw, fmt, name or _label(point))

    def constants(self, constants):
        """A variant's constants (``{name: Constant | structural}``) as values of this backend;
        structural entries pass through unchanged."""
        from kfpga.core.spec import Constant

        return {n: self.const(c.value, c.point, n) if isinstance(c, Constant) else c for n, c in constants.items()}

    # -- exact arithmetic ------------------------------------------------------------------
    def _aligned(self, a, b):
        """The payloads of ``a`` and ``b`` at a common binary point, and that point."""
        frac = max(a.frac, b.frac)
        return self._to_frac(a, frac), self._to_frac(b, frac), frac

    def _to_frac(self, a, frac):
        if a.frac == frac or self.value_payload:
            return a.raw
        return self._shl(a.raw, frac - a.frac)

    def add(self, a, b):
        """``a + b``, exact."""
        ra, rb, frac = self._aligned(a, b)
        return Fx(self._add(ra, rb), frac, _fold(a, b, frac, lambda x, y: x + y))

    def sub(self, a, b):
        """``a - b``, exact."""
        ra, rb, frac = self._aligned(a, b)
        return Fx(self._sub(ra, rb), frac, _fold(a, b, frac, lambda x, y: x - y))

    def neg(self, a):
        """``-a``, exact."""
        return Fx(self._neg(a.raw), a.frac, None if a.const is None else -a.const)

    def mul(self, a, b):
        """``a * b``, exact; a constant 0, +-1 or +-2**k factor costs no multiplier."""
        frac = a.frac + b.frac
        if self.value_payload:
            return Fx(self._mul(a.raw, b.raw), frac)
        if b.const is not None and a.const is None:
            a, b = b, a
        if a.const is not None and b.const is not None:
            return Fx(self._mul(a.raw, b.raw), frac, a.const * b.const)
        if a.const is not None:
            c = a.const
            if c == 0:
                return Fx(self._zero(), frac, 0)
            k = _power_of_two(c)
            if k is not None:
                raw = self._shl(b.raw, k) if k else b.raw
                return Fx(self._neg(raw) if c < 0 else raw, frac)
        return Fx(self._mul(a.raw, b.raw), frac)

    def shift(self, a, n):
        """``a * 2**n``: the binary point moves, no bit changes (free in hardware)."""
        raw = self._scale(a.raw, n) if self.value_payload else a.raw
        return Fx(raw, a.frac - n, a.const, None)

    # -- comparisons and selection ---------------------------------------------------------------
    def abs(self, a):
        """``|a|``, exact (one bit wider, as ``-a``)."""
        return Fx(self._abs(a.raw), a.frac, None if a.const is None else abs(a.const))

    def gt(self, a, b):
        """The condition ``a > b`` (a backend truth value: a bool, a bool array, a 1-bit signal)."""
        ra, rb, _ = self._aligned(a, b)
        return self._lt(rb, ra)

    def select(self, cond, a, b):
        """``a`` where ``cond`` holds, else ``b``, at their common binary point (a multiplexer)."""
        ra, rb, frac = self._aligned(a, b)
        return Fx(self._mux(cond, ra, rb), frac)

    def min(self, a, b):
        """The smaller of ``a`` and ``b`` (one comparator, one multiplexer)."""
        ra, rb, frac = self._aligned(a, b)
        return Fx(self._mux(self._lt(rb, ra), rb, ra), frac)

    def max(self, a, b):
        """The larger of ``a`` and ``b`` (one comparator, one multiplexer)."""
        ra, rb, frac = self._aligned(a, b)
        return Fx(self._mux(self._lt(ra, rb), rb, ra), frac)

    def sort2(self, a, b):
        """``(min, max)`` of ``a`` and ``b``: one compare-exchange of a sorting network (one
        comparator and a multiplexer per output)."""
        ra, rb, frac = self._aligned(a, b)
        swap = self._lt(rb, ra)
        return Fx(self._mux(swap, rb, ra), frac), Fx(self._mux(swap, ra, rb), frac)

    # -- quantisation ------------------------------------------------------------------------
    def cast(self, a, point, name=None):
        """``a`` written into the cast point ``point`` (as :meth:`rq`) when the config gives it a
        format, else ``a`` itself, exact: a product's or a sum's own result format, which a filter
        states where one may help (a product before it enters a sum) and the config sets where
        the exact width would pass the word budget (``kfpga/core/formats.py``)."""
        if isinstance(point, str) and point not in self.formats:
            return self._exact_cast(a, point)
        return self.rq(a, point, name)

    def _exact_cast(self, a, point):
        """A cast point without a format: the value itself (a backend may note it)."""
        return a

    def rq(self, a, point, name=None):
        """Write ``a`` into the format of ``point``: its rounding, its overflow rule, a flag."""
        fmt = self.fmt(point)
        name = name or _label(point)
        self.point_of[name] = point if isinstance(point, str) else str(point)
        raw, flag = self._rq(a.raw, a.frac, fmt, name)
        self.flags.append((name, flag))
        return Fx(raw, fmt.frac_bits, None, fmt, name)

    def div(self, num, den, point, name=None):
        """The restoring divider: ``|num| / den`` truncated to the fraction bits of ``point``,
        saturated to its largest value when it does not fit or ``den <= 0``, given the sign of
        ``num`` (truncation toward zero)."""
        fmt = self.fmt(point)
        name = name or _label(point)
        self.point_of[name] = point if isinstance(point, str) else str(point)
        shift = divider_shift(num.frac, den.frac, fmt.frac_bits)
        if shift < 0:
            raise ValueError(
                f"the division {name} = {num.name or 'num'} / {den.name or 'den'} needs "
                f"{point_name(point)}.frac_bits + {den.name or 'den'}.frac_bits - {num.name or 'num'}.frac_bits >= 0 "
                f"(it is {shift}) so that the dividend is an exact integer")
        raw, flag = self._div(num.raw, den.raw, shift, fmt, name)
        self.flags.append((name, flag))
        return Fx(raw, fmt.frac_bits, None, fmt, name)

    def sqrt(self, a, point, name=None):
        """The restoring square root: ``sqrt(a)`` truncated to the fraction bits of ``point`` (the
        floor of the exact root; like :meth:`div`, the point's rounding rule does not apply),
        saturated to its largest value when it does not fit; 0 and the flag for ``a < 0``."""
        fmt = self.fmt(point)
        name = name or _label(point)
        self.point_of[name] = point if isinstance(point, str) else str(point)
        raw, flag = self._sqrt(a.raw, root_shift(a.frac, fmt.frac_bits), fmt, name)
        self.flags.append((name, flag))
        return Fx(raw, fmt.frac_bits, None, fmt, name)

    def overflow(self):
        """OR of every flag raised so far."""
        return self._any([f for _, f in self.flags])

    # -- backend primitives ------------------------------------------------------------------
    def _input(self, raw, fmt, name):
        return raw

    def _const(self, raw, fmt, value, name):
        return raw

    def _zero(self):
        return 0

    def _scale(self, raw, n):
        """``raw * 2**n`` (value payloads only)."""
        raise NotImplementedError

    def _shl(self, raw, n):
        return raw << n

    def _add(self, x, y):
        return x + y

    def _sub(self, x, y):
        return x - y

    def _neg(self, x):
        return -x

    def _mul(self, x, y):
        return x * y

    def _abs(self, x):
        return abs(x)  # ints, Fractions, floats and numpy arrays alike

    def _lt(self, x, y):
        return x < y

    def _mux(self, cond, x, y):
        if isinstance(cond, np.ndarray) or isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            return np.where(cond, x, y)
        return x if cond else y

    def _rq(self, raw, src_frac, fmt, name):
        raise NotImplementedError

    def _div(self, num, den, shift, fmt, name):
        raise NotImplementedError

    def _sqrt(self, raw, shift, fmt, name):
        raise NotImplementedError

    def _any(self, flags):
        out = False
        for f in flags:
            out = out | f
        return out


def _label(point):
    return str(point) if isinstance(point, QFormat) else point


def point_name(point):
    return f"formats.{point}" if isinstance(point, str) else str(point)


def _fold(a, b, frac, op):
    if a.const is None or b.const is None:
        return None
    return op(a.const << (frac - a.frac), b.const << (frac - b.frac))


# -- bit-accurate integers ---------------------------------------------------------------------


def divide(num, den, shift, quotient_bits):
    """The restoring divider on integers: ``(quotient, overflowed)``; ints, int64 arrays, or arrays
    of Python ints (``dtype=object``, a batch past int64).

    ``floor(|num| * 2**shift / den)`` with the sign of ``num``; ``2**quotient_bits - 1`` (and the
    flag) when that does not fit in ``quotient_bits`` bits or ``den <= 0``.
    """
    limit = (1 << quotient_bits) - 1
    if isinstance(num, np.ndarray) or isinstance(den, np.ndarray):
        dtype = _dtype(num, den)
        num, den = np.broadcast_arrays(np.asarray(num, dtype=dtype), np.asarray(den, dtype=dtype))
        mag = np.abs(num) << shift
        bad = (den <= 0) | (mag >= (np.maximum(den, 1) << quotient_bits))
        quo = np.where(bad, limit, mag // np.maximum(den, 1))
        return np.where(num < 0, -quo, quo), bad
    mag = abs(num) << shift
    if den <= 0 or mag >= den << quotient_bits:
        quo, bad = limit, True
    else:
        quo, bad = mag // den, False
    return (-quo if num < 0 else quo), bad


def _dtype(*values):
    """``object`` when any of ``values`` is an array of Python ints (a batch past int64), else int64."""
    return object if any(isinstance(v, np.ndarray) and v.dtype == object for v in values) else np.int64


def square_root(raw, shift, limit):
    """The restoring square root on integers: ``(root, flag)``; ints, int64 arrays or arrays of
    Python ints.

    ``floor(sqrt(raw * 2**shift))`` (a negative ``shift`` drops bits first, by a floor shift:
    the floor of the root of a floor is the floor of the root); ``limit`` and the flag when the
    root is above ``limit``; 0 and the flag for a negative ``raw``.
    """
    if isinstance(raw, np.ndarray) and raw.dtype == object:  # Python ints: exact at any width
        rad = [max(int(v), 0) for v in raw.ravel()]
        rad = [v << shift if shift >= 0 else v >> -shift for v in rad]
        root = np.array([math.isqrt(v) for v in rad], dtype=object).reshape(raw.shape)
        bad = (raw < 0) | (root > limit)
        return np.where(raw < 0, 0, np.minimum(root, limit)), bad
    if isinstance(raw, np.ndarray):
        raw = np.asarray(raw, dtype=np.int64)
        rad = np.maximum(raw, 0)
        rad = rad << shift if shift >= 0 else rad >> -shift
        # float64's root of an integer below 2**62 is within one of the integer root: correct it
        root = np.floor(np.sqrt(rad.astype(np.float64))).astype(np.int64)
        root = np.where(root * root > rad, root - 1, root)
        root = np.where((root + 1) * (root + 1) <= rad, root + 1, root)
        bad = (raw < 0) | (root > limit)
        return np.where(raw < 0, 0, np.minimum(root, limit)), bad
    if raw < 0:
        return 0, True
    root = math.isqrt(raw << shift if shift >= 0 else raw >> -shift)
    return (limit, True) if root > limit else (root, False)


class IntOps(Ops):
    """The bit-accurate integers: payloads are Python ints (one channel) or int64 arrays (a batch).

    Every write goes through :func:`kfpga.core.fixed.requantise`; this backend is the plain,
    unoptimised statement of the integer model (``kfpga/core/compiled.py`` is its fast form, and
    the tests hold the two equal).
    """

    def _rq(self, raw, src_frac, fmt, name):
        return requantise(raw, src_frac, fmt)

    def _div(self, num, den, shift, fmt, name):
        return divide(num, den, shift, quotient_bits(fmt))

    def _sqrt(self, raw, shift, fmt, name):
        return square_root(raw, shift, fmt.max_raw)


# -- float: the real-valued filter and its ranges ----------------------------------------------


class FloatOps(Ops):
    """Float64 arithmetic with real (unquantised) constants; ``rq`` only records the magnitude.

    Payloads are floats or float arrays (a batch of stimuli). :attr:`ranges` maps each point
    (and each named value) to the largest magnitude written into it, constants included.
    """

    value_payload = True

    def __init__(self, formats):
        super().__init__(formats)
        self._seen = {}

    def record(self, name, value):
        self._seen.setdefault(name, []).append(value)

    def input(self, raw, point, name=None):
        return Fx(np.asarray(raw, dtype=np.float64), 0, None, None, name or _label(point))

    def const(self, value, point, name=None):
        fmt = self.formats.get(point) if isinstance(point, str) and self.formats else None
        fmt_raw = int(to_raw(value, fmt)[0]) if fmt is not None else None
        for key in {_label(point), name or _label(point)}:
            self.record(key, float(value))
        return Fx(float(value), 0, fmt_raw, fmt, name or _label(point))

    def rq(self, a, point, name=None):
        self.record(_label(point), a.raw)
        if name and name != _label(point):
            self.record(name, a.raw)
        return Fx(a.raw, 0, None, None, name or _label(point))

    def cast(self, a, point, name=None):
        return self.rq(a, point, name)  # no rounding in float: the range of the point is recorded

    def div(self, num, den, point, name=None):
        return self.rq(Fx(num.raw / den.raw, 0), point, name)

    def sqrt(self, a, point, name=None):
        return self.rq(Fx(np.sqrt(np.maximum(a.raw, 0.0)), 0), point, name)

    def _zero(self):
        return 0.0

    def _scale(self, raw, n):
        return raw * 2.0**n

    def overflow(self):
        return False

    @property
    def ranges(self):
        """``{name: largest magnitude}`` of everything recorded."""
        return {name: float(max(np.max(np.abs(v)) for v in values)) for name, values in self._seen.items()}


# -- widths, multipliers, bounds ---------------------------------------------------------------


@dataclass(frozen=True)
class Intermediate:
    """One exact intermediate as the RTL builds it."""

    text: str  # the expression, in point and constant names
    width: int  # signed width in bits (Amaranth's rules: a + b is one bit wider, a * b the sum)
    points: frozenset  # quantisation points whose formats set it
    kind: str  # "sum", "product", "shift", "dividend", "radicand", "comparison"
    into: str | None = None  # the point it is written to, when known
    casts: frozenset = frozenset()  # the cast points in it that keep their value exact (no format)


@dataclass
class _W:
    width: int
    text: str
    points: frozenset
    casts: frozenset = frozenset()  # exact cast points the value holds
    deps: frozenset = frozenset()  # the intermediates (indices) it is made of, its own included


@dataclass(frozen=True)
class ExactCast:
    """A cast point that keeps its value exact: the width and fraction bits it has there, and the
    point (with its format) whose write first consumes it."""

    width: int
    frac: int
    into: str | None = None
    into_format: QFormat | None = None


@dataclass
class WidthReport:
    """What :class:`WidthOps` found in a stage."""

    intermediates: list = field(default_factory=list)
    multipliers: list = field(default_factory=list)  # (text, width a, width b, points a, points b)
    writes: list = field(default_factory=list)  # (point, source width, format)
    exact_casts: dict = field(default_factory=dict)  # cast point -> ExactCast
    live: set = field(default_factory=set)  # the intermediates a write, an output or a next state reads

    @property
    def multiplier_count(self):
        return len(self.multipliers)

    def blocks(self, bits=18):
        """Embedded ``bits`` x ``bits`` multipliers the products take (a wider operand takes
        ``ceil(width / bits)`` pieces), one per product."""
        return sum(-(-wa // bits) * -(-wb // bits) for _, wa, wb, _, _ in self.multipliers)

    def widest_product_blocks(self, bits=18):
        """Embedded multipliers of one multiplier shared by every product (both operands as wide
        as the widest that it takes)."""
        if not self.multipliers:
            return 0
        wa = max(max(a, b) for _, a, b, _, _ in self.multipliers)
        wb = max(min(a, b) for _, a, b, _, _ in self.multipliers)
        return -(-wa // bits) * -(-wb // bits)

    def widest(self):
        return max(self.intermediates, key=lambda i: i.width, default=None)

    def past(self, bits):
        """The intermediates the datapath builds (a write, an output or a next state reads them)
        that are wider than ``bits``, widest first."""
        return sorted((i for n, i in enumerate(self.intermediates) if i.width > bits and n in self.live),
                      key=lambda i: -i.width)


class WidthOps(Ops):
    """Exact widths of every intermediate, the multipliers and their operand widths.

    Widths follow Amaranth's rules, which are the RTL's: ``a + b`` and ``a - b`` are one bit
    wider than the wider (aligned) term, ``-a`` one bit wider than ``a``, ``a * b`` as wide as
    both together, ``a << n`` ``n`` bits wider; a constant is as wide as its format. A cast point
    without a format keeps its value exact: the report notes its width, the sums that hold it and
    the write that consumes it (what the default cast formats are made from).
    """

    def __init__(self, formats):
        super().__init__(formats)
        self.report = WidthReport()

    def _node(self, width, text, points, kind, casts=frozenset(), args=()):
        self.report.intermediates.append(Intermediate(text, width, frozenset(points), kind, None, casts))
        deps = frozenset().union(*(a.deps for a in args)) | {len(self.report.intermediates) - 1}
        return _W(width, text, frozenset(points), casts, deps)

    def reads(self, value):
        """Mark what ``value`` (an :class:`Fx`) is made of as built: an output or a next state reads it."""
        self.report.live |= value.raw.deps

    def input(self, raw, point, name=None):
        value = super().input(raw, point, name)
        value.raw.points = value.raw.points | {_label(point)}
        return value

    def const(self, value, point, name=None):
        out = super().const(value, point, name)
        out.raw.points = out.raw.points | {_label(point)}
        return out

    def _exact_cast(self, a, point):
        self.report.exact_casts.setdefault(point, ExactCast(a.raw.width, a.frac))
        return Fx(_W(a.raw.width, a.raw.text, a.raw.points, a.raw.casts | {point}, a.raw.deps), a.frac, a.const, None,
                  a.name)

    def _consumed(self, raw, into, fmt):
        self.report.live |= raw.deps
        for point in raw.casts:
            cast = self.report.exact_casts[point]
            if cast.into is None:
                self.report.exact_casts[point] = ExactCast(cast.width, cast.frac, into, fmt)

    def _input(self, raw, fmt, name):
        return _W(fmt.width, name, frozenset([name]))

    def _const(self, raw, fmt, value, name):
        return _W(const_width(raw, fmt), name, frozenset([name]))

    def _zero(self):
        return _W(1, "0", frozenset())

    def _shl(self, raw, n):
        return _W(raw.width + n, raw.text, raw.points, raw.casts, raw.deps)

    def _add(self, x, y):
        return self._node(max(x.width, y.width) + 1, f"{x.text} + {y.text}", x.points | y.points, "sum", x.casts | y.casts,
                          (x, y))

    def _sub(self, x, y):
        return self._node(max(x.width, y.width) + 1, f"{x.text} - {_paren(y.text)}", x.points | y.points, "sum",
                          x.casts | y.casts, (x, y))

    def _neg(self, x):
        return self._node(x.width + 1, f"-{_paren(x.text)}", x.points, "sum", x.casts, (x,))

    def _mul(self, x, y):
        self.report.multipliers.append((f"{_paren(x.text)}*{_paren(y.text)}", x.width, y.width, x.points, y.points))
        return self._node(x.width + y.width, f"{_paren(x.text)}*{_paren(y.text)}", x.points | y.points, "product",
                          x.casts | y.casts, (x, y))

    def _abs(self, x):
        return self._node(x.width + 1, f"|{x.text}|", x.points, "sum", x.casts, (x,))

    def _lt(self, x, y):
        node = self._node(max(x.width, y.width) + 1, f"{x.text} < {y.text}", x.points | y.points, "comparison",
                          x.casts | y.casts, (x, y))
        return _W(1, f"{x.text} < {y.text}", x.points | y.points, frozenset(), node.deps)

    def _mux(self, cond, x, y):
        return _W(max(x.width, y.width), f"({cond.text} ? {x.text} : {y.text})", x.points | y.points, x.casts | y.casts,
                  cond.deps | x.deps | y.deps)

    def _rq(self, raw, src_frac, fmt, name):
        self.report.writes.append((name, raw.width, fmt))
        self._consumed(raw, name, fmt)
        if self.report.intermediates and self.report.intermediates[-1].text == raw.text:
            last = self.report.intermediates[-1]
            self.report.intermediates[-1] = Intermediate(last.text, last.width, last.points, last.kind, name, last.casts)
        return _W(fmt.width, name, frozenset([name])), False

    def _div(self, num, den, shift, fmt, name):
        qbits = quotient_bits(fmt)
        points = num.points | den.points | {name}
        # |num| << shift is compared with den << quotient_bits (kfpga.core.ops.divide)
        self._consumed(self._node(num.width + shift + 1, f"|{num.text}| << {shift}", points, "dividend", num.casts,
                                  (num,)), name, fmt)
        self._consumed(self._node(den.width + qbits, f"{den.text} << {qbits}", points, "comparison", den.casts, (den,)),
                       name, fmt)
        return _W(fmt.width, name, frozenset([name])), False

    def _sqrt(self, raw, shift, fmt, name):
        # the radicand, shifted; the restoring root compares it with the root so far
        self._consumed(self._node(raw.width + max(shift, 0),
                                  f"{raw.text} << {shift}" if shift >= 0 else f"{raw.text} >> {-shift}",
                                  raw.points | {name}, "radicand", raw.casts, (raw,)), name, fmt)
        return _W(fmt.width, name, frozenset([name])), False

    def overflow(self):
        return False


def _paren(text):
    return f"({text})" if any(c in text for c in " +-") else text


# -- cost: operations per update ----------------------------------------------------------------------


class CostOps(Ops):
    """Counts the operations of an update as the datapath builds them (:attr:`counts`):

    * ``additions``: every sum, difference and negation;
    * ``multiplications``: products that take a multiplier (a variable by a variable, or by a
      constant other than 0, +-1, +-2**k);
    * ``shifts``: products by 0, +-1 or +-2**k (wiring, no multiplier);
    * ``divisions``: the restoring divider;
    * ``square roots``: the restoring square root;
    * ``comparisons``: magnitude comparators (a compare-exchange of a sorting network is one,
      whose two outputs are multiplexers);
    * ``selections``: multiplexers between two values.

    Writes into a point (``rq``) are not counted: their rounding is part of the write.
    """

    def __init__(self, formats):
        super().__init__(formats)
        self.counts = {"additions": 0, "multiplications": 0, "shifts": 0, "divisions": 0, "square roots": 0,
                       "comparisons": 0, "selections": 0}

    def mul(self, a, b):
        c = a.const if b.const is None else b.const
        if a.const is not None and b.const is not None:
            pass  # folded when the stage is built: no hardware
        elif c is not None and (c == 0 or _power_of_two(c) is not None):
            self.counts["shifts"] += 1
        else:
            self.counts["multiplications"] += 1
        return super().mul(a, b)

    def _input(self, raw, fmt, name):
        return 0

    def _const(self, raw, fmt, value, name):
        return raw

    def _zero(self):
        return 0

    def _shl(self, raw, n):
        return 0

    def _add(self, x, y):
        self.counts["additions"] += 1
        return 0

    def _sub(self, x, y):
        self.counts["additions"] += 1
        return 0

    def _neg(self, x):
        self.counts["additions"] += 1
        return 0

    def _mul(self, x, y):
        return 0

    def _abs(self, x):
        self.counts["additions"] += 1  # a negation and a multiplexer on the sign
        self.counts["selections"] += 1
        return 0

    def _lt(self, x, y):
        self.counts["comparisons"] += 1
        return 0

    def _mux(self, cond, x, y):
        self.counts["selections"] += 1
        return 0

    def _rq(self, raw, src_frac, fmt, name):
        return 0, False  # a write, a cast among them: its rounding is part of the write

    def _div(self, num, den, shift, fmt, name):
        self.counts["divisions"] += 1
        return 0, False

    def _sqrt(self, raw, shift, fmt, name):
        self.counts["square roots"] += 1
        return 0, False


def update_cost(config, variant):
    """``{additions, multiplications, shifts, divisions}`` of one update of ``config``'s ``variant``,
    counted by running its update on :class:`CostOps`."""
    spec_variant = config.spec.model.variants[variant]
    ops = CostOps(config.formats)
    k = ops.constants(config.constants(variant))
    state = {name: ops.input(0, point, name) for name, point in spec_variant.state_for(config.params)}
    inputs = {name: ops.input(0, config.input_format, name) for name in config.inputs}
    spec_variant.update(ops, k, state, inputs)
    return dict(ops.counts)


def update_widths(spec, params, formats, variant, input_format):
    """What :class:`WidthOps` finds in the update of ``spec``'s ``variant`` with ``formats`` (the
    inputs in ``input_format``): a :class:`WidthReport`."""
    v = spec.model.variants[variant]
    ops = WidthOps(formats)
    k = ops.constants(v.constants(params))
    x = {name: ops.input(None, point, name) for name, point in v.state_for(params)}
    u = {name: ops.input(None, input_format, name) for name, _ in spec.inputs_for(params)}
    x_next, outs = v.update(ops, k, x, u)
    for value in [*x_next.values(), *outs.values()]:
        if isinstance(value, Fx):
            ops.reads(value)
    return ops.report


# -- exact rationals: the spec ----------------------------------------------------------------------


def quantise_fraction(value, fmt):
    """An exact rational written into ``fmt``: ``(raw, overflowed)`` by the format's rules."""
    scaled = Fraction(value) * (1 << fmt.frac_bits)
    # each rule from its definition, sharing nothing with round_addend
    if fmt.rounding is Rounding.NEAREST:
        raw = math.floor(scaled + Fraction(1, 2))
    elif fmt.rounding is Rounding.ROUND:
        raw = math.floor(abs(scaled) + Fraction(1, 2)) * (1 if scaled >= 0 else -1)
    elif fmt.rounding is Rounding.CONVERGENT:
        raw = round(scaled)  # Fraction.__round__: to nearest, ties to even
    elif fmt.rounding is Rounding.FIX:
        raw = math.trunc(scaled)
    else:
        raw = math.floor(scaled)
    if fmt.min_raw <= raw <= fmt.max_raw:
        return raw, False
    if fmt.overflow is Overflow.SATURATE:
        return (fmt.max_raw if raw > fmt.max_raw else fmt.min_raw), True
    return (raw - fmt.min_raw) % (1 << fmt.width) + fmt.min_raw, True


class FractionOps(Ops):
    """Exact rational values (``Fraction``), each written once into its point's format.

    The payload is the real value itself, so no alignment shift is ever formed; rounding is
    each rule applied to the exact ``value * 2**frac`` by its definition, and the division is the exact
    quotient truncated toward zero. This shares nothing with :class:`IntOps` but the equations,
    which makes it the spec the integer model is tested against.
    """

    value_payload = True

    def input(self, raw, point, name=None):
        fmt = self.fmt(point)
        return Fx(Fraction(int(raw), 1 << fmt.frac_bits), fmt.frac_bits, None, fmt, name or _label(point))

    def const(self, value, point, name=None):
        fmt = self.fmt(point)
        raw, overflowed = quantise_fraction(Fraction(value), fmt)
        if overflowed:
            raise ValueError(f"the constant {name or _label(point)} = {value!r} does not fit {fmt}")
        return Fx(Fraction(raw, 1 << fmt.frac_bits), fmt.frac_bits, raw, fmt, name or _label(point))

    def _zero(self):
        return Fraction(0)

    def _scale(self, raw, n):
        return raw * Fraction(2) ** n

    def _rq(self, value, src_frac, fmt, name):
        raw, flag = quantise_fraction(value, fmt)
        return Fraction(raw, 1 << fmt.frac_bits), flag

    def _div(self, num, den, shift, fmt, name):
        limit = fmt.max_raw
        if den <= 0:
            return Fraction(limit if num >= 0 else -limit, 1 << fmt.frac_bits), True
        exact = abs(num) / den * (1 << fmt.frac_bits)
        if exact >= limit + 1:
            return Fraction(limit if num >= 0 else -limit, 1 << fmt.frac_bits), True
        quo = math.floor(exact)
        return Fraction(-quo if num < 0 else quo, 1 << fmt.frac_bits), False

    def _sqrt(self, value, shift, fmt, name):
        if value < 0:
            return Fraction(0), True
        # the largest r with r^2 <= value * 4**frac, by bisection on exact rationals (no isqrt)
        target = value * (1 << (2 * fmt.frac_bits))
        lo, hi = 0, 1
        while hi * hi <= target:
            hi *= 2
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if mid * mid <= target else (lo, mid)
        if lo > fmt.max_raw:
            return Fraction(fmt.max_raw, 1 << fmt.frac_bits), True
        return Fraction(lo, 1 << fmt.frac_bits), False

    def raw_of(self, a):
        """The integer a value stands for in its format (``a`` must come from ``rq``/``div``)."""
        scaled = a.raw * (1 << a.frac)
        if scaled.denominator != 1:
            raise ValueError(f"{a.name} is not an integer in its format")
        return int(scaled)
