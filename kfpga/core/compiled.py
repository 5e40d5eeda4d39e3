"""Trace an update stage once into straight-line Python, then run that as the model's loop.

The direct backend (:class:`kfpga.core.ops.IntOps`) pays for a function call, a dataclass and a
dispatch per operation, about 25 us per sample: too slow for a model meant to filter millions of
samples. :class:`TraceOps` runs the stage function once per config with symbolic values and
writes each operation as one line of Python source with every shift, rounding constant and
bound inlined. ``compile`` turns the source into a sample loop. The arithmetic is the same as
:class:`IntOps` (the tests hold the two equal on random configs); what is saved is the
interpretation.

Two forms are generated from one trace:

* ``scalar``: Python ints, one channel. Overflow is rare, so a saturation check is one chained
  comparison and the flag is recorded only on the (rare) overflow branch, as the sample index.
* ``vector``: numpy int64 arrays, one row per time step of a batch of channels; flags are
  boolean arrays.

Each value also carries the interval its raw integer can take. A write whose input interval
already fits its format needs no check, and cannot overflow; that is decided once, exactly,
at trace time. The intervals also bound every intermediate: when one can pass what int64 holds
(:data:`INT64_SAFE_BITS`), the vector form runs on numpy arrays of Python ints (``dtype=object``)
instead, exact at any width and several times slower; the scalar form is exact at any width as
it is.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from kfpga.core.fixed import Overflow, Rounding, shift_round
from kfpga.core.ops import Fx, Ops, divide, quotient_bits, square_root

__all__ = ["TraceOps", "FloatTraceOps", "Kernel", "compile_stage", "compile_float_ranges", "cast_bounds",
           "INT64_SAFE_BITS"]

#: Magnitude bits an int64 array holds with a bit to spare for a rounding addend: an intermediate
#: whose interval reaches past ``2**INT64_SAFE_BITS`` takes the vector form onto Python ints.
INT64_SAFE_BITS = 62


def _addend_source(v, shift, rounding):
    """:func:`~kfpga.core.fixed.round_addend` as Python source over the expression ``v`` (ints or
    int64 arrays alike: a comparison gives a bool, or a bool array, that counts as 0 or 1)."""
    half = 1 << (shift - 1)
    return {
        Rounding.FLOOR: "",
        Rounding.NEAREST: f" + {half}",
        Rounding.ROUND: f" + {half} - ({v} < 0)",
        Rounding.CONVERGENT: f" + {half - 1} + (({v} >> {shift}) & 1)",
        Rounding.FIX: f" + ({v} < 0) * {(1 << shift) - 1}",
    }[Rounding(rounding)]


@dataclass(frozen=True)
class _T:
    """A traced payload: a Python expression and the interval of the integer it holds."""

    expr: str
    lo: int
    hi: int


class TraceOps(Ops):
    """Records the operations of a stage as Python source lines (see module docstring)."""

    def __init__(self, formats, *, vector):
        super().__init__(formats)
        self.vector = vector
        self.lines = []
        self.sites = []  # names of the rq/div sites that can overflow, in order
        self._count = 0
        self.magnitude = 0  # the largest magnitude any intermediate's interval reaches
        self.cast_bounds = {}  # a cast point without a format -> the interval (lo, hi) of its exact value

    def _exact_cast(self, a, point):
        # the value's interval in real units, joined with the point's other uses (another variant's)
        lo, hi = Fraction(a.raw.lo, 1 << a.frac), Fraction(a.raw.hi, 1 << a.frac)
        if point in self.cast_bounds:
            lo, hi = min(lo, self.cast_bounds[point][0]), max(hi, self.cast_bounds[point][1])
        self.cast_bounds[point] = (lo, hi)
        return a

    def _reach(self, *bounds):
        self.magnitude = max(self.magnitude, *(abs(b) for b in bounds))

    def _var(self, expr, lo, hi):
        name = f"t{self._count}"
        self._count += 1
        self.lines.append(f"{name} = {expr}")
        self._reach(lo, hi)
        return _T(name, lo, hi)

    def _input(self, raw, fmt, name):
        return _T(raw, fmt.min_raw, fmt.max_raw)

    def _const(self, raw, fmt, value, name):
        return _T(repr(raw), raw, raw)

    def _zero(self):
        return _T("0", 0, 0)

    def _shl(self, x, n):
        return self._var(f"{x.expr} << {n}", x.lo << n, x.hi << n)

    def _add(self, x, y):
        return self._var(f"{x.expr} + {y.expr}", x.lo + y.lo, x.hi + y.hi)

    def _sub(self, x, y):
        return self._var(f"{x.expr} - {y.expr}", x.lo - y.hi, x.hi - y.lo)

    def _neg(self, x):
        return self._var(f"-{x.expr}", -x.hi, -x.lo)

    def _mul(self, x, y):
        corners = (x.lo * y.lo, x.lo * y.hi, x.hi * y.lo, x.hi * y.hi)
        return self._var(f"{x.expr} * {y.expr}", min(corners), max(corners))

    def _abs(self, x):
        lo, hi = (x.lo, x.hi) if x.lo >= 0 else (-x.hi, -x.lo) if x.hi <= 0 else (0, max(-x.lo, x.hi))
        return self._var(f"abs({x.expr})", lo, hi)  # abs() of an int64 array is np.abs

    def _lt(self, x, y):
        return self._var(f"{x.expr} < {y.expr}", 0, 1)

    def _mux(self, cond, x, y):
        expr = f"np.where({cond.expr}, {x.expr}, {y.expr})" if self.vector else f"{x.expr} if {cond.expr} else {y.expr}"
        return self._var(expr, min(x.lo, y.lo), max(x.hi, y.hi))

    def _site(self, name):
        self.sites.append(name)
        return len(self.sites) - 1

    def _rq(self, x, src_frac, fmt, name):
        shift = src_frac - fmt.frac_bits
        lo, hi = shift_round(x.lo, shift, fmt.rounding), shift_round(x.hi, shift, fmt.rounding)
        self._reach(x.lo - (1 << max(shift, 0)), x.hi + (1 << max(shift, 0)))  # with its rounding addend
        if shift > 0:
            add = _addend_source(x.expr, shift, fmt.rounding)
            value = self._var(f"({x.expr}{add}) >> {shift}" if add else f"{x.expr} >> {shift}", lo, hi)
        elif shift < 0:
            value = self._var(f"{x.expr} << {-shift}", lo, hi)
        else:
            value = x
        fmin, fmax = fmt.min_raw, fmt.max_raw
        if fmin <= lo and hi <= fmax:
            return value, "False"  # cannot overflow: the interval fits
        site = self._site(name)
        v = value.expr
        if value is x:  # keep the input untouched: it may be read again
            value = self._var(v, lo, hi)
            v = value.expr
        if self.vector:
            flag = f"f{site}"
            if fmt.overflow is Overflow.SATURATE:
                clipped = v
                if hi > fmax:
                    clipped = f"np.minimum({clipped}, {fmax})"
                if lo < fmin:
                    clipped = f"np.maximum({clipped}, {fmin})"
                self.lines.append(f"c{site} = {clipped}")
            else:
                self.lines.append(f"c{site} = (({v} - {fmin}) & {(1 << fmt.width) - 1}) + {fmin}")
            self.lines.append(f"{flag} = c{site} != {v}")
            self.lines.append(f"{v} = c{site}")
            self.lines.append(f"ov{site}[n] = {flag}")
            out = _T(v, max(lo, fmin), min(hi, fmax)) if fmt.overflow is Overflow.SATURATE else _T(v, fmin, fmax)
            return out, flag
        if fmt.overflow is Overflow.SATURATE:
            if hi > fmax:
                self.lines.append(f"if {v} > {fmax}: {v} = {fmax}; ov{site}(n)")
            if lo < fmin:
                self.lines.append(f"{'elif' if hi > fmax else 'if'} {v} < {fmin}: {v} = {fmin}; ov{site}(n)")
            return _T(v, max(lo, fmin), min(hi, fmax)), "site"
        self.lines.append(f"if not {fmin} <= {v} <= {fmax}: {v} = (({v} - {fmin}) & {(1 << fmt.width) - 1}) + {fmin}; "
                          f"ov{site}(n)")
        return _T(v, fmin, fmax), "site"

    def _div(self, num, den, shift, fmt, name):
        qbits = quotient_bits(fmt)
        limit = (1 << qbits) - 1
        site = self._site(name)
        # |num| << shift is compared with den << qbits
        self._reach(max(abs(num.lo), abs(num.hi)) << shift, max(abs(den.lo), abs(den.hi)) << qbits)
        q = self._var("0", -limit, limit)
        if self.vector:
            self.lines.append(f"{q.expr}, f{site} = divide({num.expr}, {den.expr}, {shift}, {qbits})")
            self.lines.append(f"ov{site}[n] = f{site}")
            return q, f"f{site}"
        m, d = f"m{site}", den.expr
        self.lines += [
            f"{m} = (-{num.expr} if {num.expr} < 0 else {num.expr}) << {shift}",
            f"if {d} <= 0 or {m} >= {d} << {qbits}: {q.expr} = {limit}; ov{site}(n)",
            f"else: {q.expr} = {m} // {d}",
            f"if {num.expr} < 0: {q.expr} = -{q.expr}",
        ]
        return q, "site"

    def _sqrt(self, raw, shift, fmt, name):
        limit = fmt.max_raw
        site = self._site(name)
        self._reach(max(abs(raw.lo), abs(raw.hi)) << max(shift, 0))  # the radicand
        r = self._var("0", 0, limit)
        if self.vector:
            self.lines.append(f"{r.expr}, f{site} = square_root({raw.expr}, {shift}, {limit})")
            self.lines.append(f"ov{site}[n] = f{site}")
            return r, f"f{site}"
        v = raw.expr
        radicand = f"{v} << {shift}" if shift >= 0 else f"{v} >> {-shift}"
        self.lines += [
            f"if {v} < 0: {r.expr} = 0; ov{site}(n)",
            f"else: {r.expr} = isqrt({radicand})",
            f"if {r.expr} > {limit}: {r.expr} = {limit}; ov{site}(n)",
        ]
        return r, "site"


_COPY = re.compile(r"^(t\d+) = (t\d+)$")


def _drop_copies(lines):
    """Remove ``tB = tA`` where ``tA`` is read nowhere else: ``tA``'s own line then defines ``tB``.

    A write that needs a check copies a bare sum first, in case the sum is read again; most are
    not, and a copy costs as much as an addition in the loop.
    """
    for i in range(len(lines) - 1, -1, -1):
        match = _COPY.match(lines[i])
        if not match:
            continue
        new, old = match.groups()
        word = re.compile(rf"\b{old}\b")
        uses = [j for j, line in enumerate(lines) if word.search(line)]
        if len(uses) == 2 and uses[1] == i and lines[uses[0]].startswith(f"{old} = "):
            lines[uses[0]] = f"{new} = " + lines[uses[0]][len(old) + 3:]
            del lines[i]


@dataclass
class Kernel:
    """A compiled stage loop and what it needs."""

    source: str
    function: object
    state: tuple  # state names, in argument order
    inputs: tuple  # input names
    outputs: tuple  # output names
    sites: tuple  # names of the writes that can overflow, in flag order
    site_points: dict  # each site's quantisation point
    wide: bool = False  # an intermediate can pass int64: the vector form runs on Python ints

    @property
    def dtype(self):
        """The element type of the vector form's arrays."""
        return object if self.wide else np.int64


def compile_stage(update, formats, *, constants, state, inputs, outputs, vector):
    """Trace ``update(ops, k, x, u) -> (x_next, outs)`` and compile it into a sample loop.

    ``constants``: ``{name: (value, point)}``; ``state``: ``((name, point), ...)``;
    ``inputs``: ``((name, format), ...)``; ``outputs``: names of the outputs to keep.

    The scalar function is ``f(ys, x..., outs..., ovs...) -> final state``: ``ys`` an iterable
    of input tuples (or ints, for one input), ``outs`` lists preallocated to ``len(ys)``,
    ``ovs`` the ``append`` methods of one list per overflow site (sample indices). The vector
    function takes ``ys`` as arrays shaped ``(steps, *batch)`` (one per input), ``outs`` and
    ``ovs`` as arrays of that shape.
    """
    ops = TraceOps(formats, vector=vector)
    k = ops.constants(constants)
    x = {name: ops.input(f"s_{name}", point, name) for name, point in state}
    u = {name: Fx(_T(f"u_{name}", fmt.min_raw, fmt.max_raw), fmt.frac_bits, None, fmt, name) for name, fmt in inputs}
    x_next, outs = update(ops, k, x, u)
    for name, point in state:
        got, fmt = x_next[name], ops.fmt(point)
        if got.frac != fmt.frac_bits or got.raw.lo < fmt.min_raw or got.raw.hi > fmt.max_raw:
            raise ValueError(f"the next value of state {name} is not in the format of {point} ({fmt})")
    state_names = tuple(name for name, _ in state)
    input_names = tuple(name for name, _ in inputs)
    sites = tuple(ops.sites)
    args = (["ys"] + [f"s_{n}" for n in state_names] + [f"o_{n}" for n in outputs]
            + [f"ov{i}" for i in range(len(sites))])
    tail = [f"o_{name}[n] = {outs[name].raw.expr}" for name in outputs]
    if state_names:
        tail.append(f"{', '.join('s_' + n for n in state_names)}, = {', '.join(x_next[n].raw.expr for n in state_names)},")
    lines = ops.lines + tail
    _drop_copies(lines)  # with the tail: a value the outputs or the next state read is read again
    body = [f"    {line}" for line in lines]
    if vector:
        head = ["for n in range(len(ys[0])):"] + [f"    u_{name} = ys[{i}][n]" for i, name in enumerate(input_names)]
    elif len(input_names) == 1:
        head = [f"for n, u_{input_names[0]} in enumerate(ys):"]
    else:
        head = [f"for n, ({', '.join('u_' + n for n in input_names)}) in enumerate(ys):"]
    lines = [f"def kernel({', '.join(args)}):", *[f"    {h}" for h in head], *[f"    {b}" for b in body],
             f"    return ({''.join('s_' + n + ', ' for n in state_names)})"]
    source = "\n".join(lines) + "\n"
    namespace = {"np": np, "divide": divide, "square_root": square_root, "isqrt": math.isqrt}
    exec(compile(source, f"<kfpga stage {update.__name__}>", "exec"), namespace)
    return Kernel(source, namespace["kernel"], state_names, input_names, tuple(outputs), sites,
                  {name: ops.point_of[name] for name in sites}, ops.magnitude.bit_length() > INT64_SAFE_BITS)


def cast_bounds(spec, params, formats, variant, input_format):
    """``{cast point: (lo, hi)}`` (``Fraction``): the interval of the exact value of every cast point that has
    no format in ``formats``, from the formats of the state and the inputs (what the default cast
    formats take their integer bits from: a cast then never overflows)."""
    v = spec.model.variants[variant]
    ops = TraceOps(formats, vector=False)
    k = ops.constants(v.constants(params))
    x = {name: ops.input(f"s_{name}", point, name) for name, point in v.state_for(params)}
    u = {name: Fx(_T(f"u_{name}", input_format.min_raw, input_format.max_raw), input_format.frac_bits, None, input_format,
                  name) for name, _ in spec.inputs_for(params)}
    v.update(ops, k, x, u)
    return ops.cast_bounds


class FloatTraceOps(TraceOps):
    """Records a stage as float64 Python source whose writes keep their largest magnitude.

    The float form of :class:`~kfpga.core.ops.FloatOps` (real constants, no rounding), compiled for
    the range analysis: one row of stimulus at a time, in Python floats, which is about 50
    times faster than stepping numpy arrays of a few rows through the direct backend.
    """

    def __init__(self):
        super().__init__({}, vector=False)
        self.value_payload = True
        self.constant_values = {}  # name -> largest magnitude of the constants written to it
        self.records = []  # site -> names it counts for

    def input(self, raw, point, name=None):
        return Fx(_T(raw, 0, 0), 0, None, None, name or str(point))

    def const(self, value, point, name=None):
        for key in {str(point), name or str(point)}:
            self.constant_values[key] = max(self.constant_values.get(key, 0.0), abs(float(value)))
        return Fx(_T(repr(float(value)), 0, 0), 0, None, None, name or str(point))

    def _scale(self, x, n):
        return self._var(f"{x.expr} * {2.0 ** n!r}", 0, 0)

    def _zero(self):
        return _T("0.0", 0, 0)

    def _record(self, x, point, name):
        site = len(self.records)
        self.records.append(sorted({str(point), name or str(point)}))
        self.lines += [f"a{site} = abs({x.expr})", f"if a{site} > m{site}: m{site} = a{site}"]

    def rq(self, a, point, name=None):
        self._record(a.raw, point, name)
        return Fx(a.raw, 0, None, None, name or str(point))

    def cast(self, a, point, name=None):
        return self.rq(a, point, name)  # every cast point's range, whether it has a format or not

    def div(self, num, den, point, name=None):
        q = self._var(f"{num.raw.expr} / {den.raw.expr}", 0, 0)
        return self.rq(Fx(q, 0), point, name)

    def sqrt(self, a, point, name=None):
        r = self._var(f"sqrt(max({a.raw.expr}, 0.0))", 0, 0)
        return self.rq(Fx(r, 0), point, name)


def compile_float_ranges(update, *, constants, state, inputs):
    """Compile ``update`` in float for range analysis.

    Returns ``run(ys, initial) -> {name: largest magnitude}``: ``ys`` an iterable of input
    values (one per step; tuples for several inputs), ``initial`` the state's start values.
    Constants count too.
    """
    ops = FloatTraceOps()
    k = ops.constants(constants)
    x = {name: ops.input(f"s_{name}", point, name) for name, point in state}
    u = {name: ops.input(f"u_{name}", name, name) for name in inputs}
    x_next, _ = update(ops, k, x, u)
    state_names = [name for name, _ in state]
    sites = range(len(ops.records))
    loop = (f"for u_{inputs[0]} in ys:" if len(inputs) == 1
            else f"for ({', '.join('u_' + n for n in inputs)}) in ys:")
    lines = [f"def kernel(ys, {', '.join('s_' + n for n in state_names)}):",
             *[f"    m{i} = 0.0" for i in sites], f"    {loop}", *[f"        {line}" for line in ops.lines],
             f"        {', '.join('s_' + n for n in state_names)}, = {', '.join(x_next[n].raw.expr for n in state_names)},",
             f"    return ({', '.join(f'm{i}' for i in sites)},)"]
    namespace = {"sqrt": math.sqrt}
    exec(compile("\n".join(lines) + "\n", f"<kfpga float stage {update.__name__}>", "exec"), namespace)
    kernel = namespace["kernel"]

    def run(ys, initial):
        out = dict(ops.constant_values)
        for m, names in zip(kernel(ys, *(float(initial[n]) for n in state_names)), ops.records, strict=True):
            for name in names:
                out[name] = max(out.get(name, 0.0), m)
        return out

    return run
