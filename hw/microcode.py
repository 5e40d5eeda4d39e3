"""The folded core's compiler: a filter's update as microcode for one narrow datapath.

A filter that updates a hundred times a second has hundreds of thousands of clock cycles for each
update, and needs few logic cells, not a datapath that updates in one clock. The folded core
(``hw/folded.py``) has one: a register file of 18-bit words in M4K block memory, one signed
18 x 18 embedded multiplier and one accumulator, run by microcode from a second M4K block. Every
operation of the update is a sequence of multiply-accumulate steps (DSP Builder's ALU folding
does the same; here the operations are the filter's own trace, so the core computes the model's
integers by construction, and :func:`execute` checks it).

**Numbers.** A value is held in *digits* of radix 2**17, one 18-bit word each: the lower digits
are ``0 .. 2**17 - 1`` (the word's top bit 0), the top digit is signed. Every digit is then a
signed 18-bit multiplier operand, and a product of two digits is one 18 x 18 product. A value of
``w`` bits takes ``1 + ceil((w - 18) / 17)`` digits (18 bits: 1, 35: 2, 52: 3); its digit count
comes from the interval of its integers (:class:`FoldOps`), which the formats bound.

**One step** (a :class:`Mac`)::

    acc = S(acc) + RF[a] * RF[b]        S: keep (acc), shift (acc >> 17, arithmetic) or clear (0)
    then, optionally: a flag := the new acc's sign (or its bit 16), or |= it; the sample's
    overflow flag |= it; RF[d] := the new acc's low digit (acc[16:0]) or top digit (acc[17:0]),
    or an output field's chunk := acc's low bits.

``a`` may be predicated: ``RF[flag ? a2 : a]``. Constants (1, -1, powers of two, rounding and
saturation bounds, every constant digit of the update) are words of the register file, so a copy
is a product by 1, a shift by ``r < 17`` bits a product by ``2**r`` and a shift by 17 bits the
accumulator's own shift. A sum is accumulated digit by digit from the lowest, the carry staying
in the accumulator; a product column by column. A requantisation ``floor((v + addend) / 2**s)``
multiplies each digit by ``2**(17 - r)`` (``s = 17 q + r``) and drops ``q + 1`` digits; the
addend of each rounding rule is one to three steps, predicated on the value's sign or on the bit
that becomes the LSB; saturation compares the result with the format's bounds and selects them
by a predicate. The restoring divider and square root are loops (a step may begin a loop of the
steps that follow it, or end one): each iteration doubles (or quadruples) the remainder and the
dividend bits below it as one number, subtracts the divisor, and keeps the difference where it
is not negative.

**Timing.** A step is in flight for four cycles (the register file is addressed in its first,
read into the multiplier in its second, whose product is registered then, accumulated in its
third, written in its fourth, and its flag captured from the accumulator then too): a step that
reads a word another writes, or is predicated on a flag another captures, comes at least four
cycles after it. The compiler schedules the steps in order and gives each the wait before the
next; a loop's waits hold for every iteration.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kfpga.core.fixed import Overflow, Rounding, shift_round
from kfpga.core.ops import Fx, Ops, quotient_bits

__all__ = ["DIGIT", "WORD", "KEEP", "SHIFT", "CLEAR", "LO", "HI", "OUT", "Mac", "FoldOps", "Program", "compile_update",
           "execute", "digits_for", "handshake_twin", "programmable_names", "Setting", "READ_LATENCY", "FLAG_LATENCY"]

#: Bits a lower digit carries, and the register file's word.
DIGIT, WORD = 17, 18
RADIX = 1 << DIGIT
#: Accumulator inputs.
KEEP, SHIFT, CLEAR = 0, 1, 2
#: Writes.
NONE, LO, HI, OUT = 0, 1, 2, 3
#: Flag captures.
SET, OR = 1, 2
#: Loop marks.
BEGIN, END = 1, 2
#: Cycles from a step's issue to one that reads the word it writes, and to one predicated on
#: the flag it captures.
READ_LATENCY, FLAG_LATENCY = 4, 4
#: Flags: two for the steps of one operation, and the sample's overflow flag.
FLAGS = 2
MAX_WAIT = 7
#: Reuse a temporary's register once it is dead (off: every value keeps its own, for debugging).
REUSE = True


def digits_for(lo, hi):
    """Digits of radix 2**17 (the top one signed 18 bits) that hold every integer in ``[lo, hi]``."""
    bits = max(_signed_bits(lo), _signed_bits(hi))
    return 1 if bits <= WORD else 1 + -(-(bits - WORD) // DIGIT)


def _signed_bits(v):
    return (v if v >= 0 else ~v).bit_length() + 1


def to_digits(value, n):
    """``value`` as ``n`` digits (lower ones unsigned, the top one signed)."""
    out = []
    for _ in range(n - 1):
        out.append(value & (RADIX - 1))
        value >>= DIGIT
    if not -(1 << DIGIT) <= value < 1 << DIGIT:
        raise ValueError(f"{value} does not fit the top digit")
    return [*out, value]


def from_digits(digits):
    return sum(d << (DIGIT * k) for k, d in enumerate(digits))


@dataclass(frozen=True)
class Mac:
    """One step (see the module docstring). Addresses are symbolic until the program is placed:
    ``("k", d)`` the constant word ``d``, ``("t", node, k)`` digit ``k`` of a value, ``("s", state,
    k)`` of a channel's state, ``("u", input, k)`` of a sample."""

    a: tuple
    b: tuple
    acc: int = KEEP
    a2: tuple | None = None
    pred: int | None = None
    wr: int = NONE
    d: object = None
    cap: int = NONE
    flag: int = 0
    bit16: bool = False
    ovf: bool = False
    loop: int = NONE
    count: int = 0


def k(value):
    """The constant word ``value`` (a signed 18-bit digit)."""
    if not -(1 << DIGIT) <= value < 1 << DIGIT:
        raise ValueError(f"constant word {value} is not an 18-bit digit")
    return ("k", value)


ZERO, ONE, NEG = k(0), k(1), k(-1)


def nop(**kw):
    return Mac(ZERO, ZERO, **kw)


# -- the trace ---------------------------------------------------------------------------------


@dataclass
class _Node:
    op: str
    args: tuple
    lo: int
    hi: int
    shift: int = 0
    fmt: object = None
    key: object = None  # input: ("s" | "u", name); const: raw
    overflow: bool = False  # a write that can overflow (its interval passes its format)
    name: str | None = None


@dataclass(frozen=True)
class _P:
    node: int
    lo: int
    hi: int


class FoldOps(Ops):
    """Records the update's operations with the interval of every value (as the compiled model's
    trace does, ``kfpga/core/compiled.py``): the digits each value takes, and which writes can
    overflow."""

    def __init__(self, formats, programmable=()):
        super().__init__(formats)
        self.nodes = []
        self.programmable = frozenset(programmable)

    def constants(self, constants):
        """The variant's constants; a :attr:`programmable` one is a word of the register file that
        the bus writes (any integer of its format, so no product by it is specialised)."""
        out = super().constants(constants)
        for name in self.programmable:
            fmt = self.fmt(constants[name].point)
            out[name] = Fx(self._new("input", (), fmt.min_raw, fmt.max_raw, key=("const", name)), fmt.frac_bits,
                           None, fmt, name)
        return out

    def _new(self, op, args=(), lo=0, hi=0, **kw):
        self.nodes.append(_Node(op, tuple(a.node for a in args), lo, hi, **kw))
        return _P(len(self.nodes) - 1, lo, hi)

    def _const_node(self, value):
        return self._new("const", (), value, value, key=value)

    def _input(self, raw, fmt, name):
        return self._new("input", (), fmt.min_raw, fmt.max_raw, key=raw)

    def _const(self, raw, fmt, value, name):
        return self._const_node(raw)

    def _zero(self):
        return self._const_node(0)

    def _is_const(self, p):
        return self.nodes[p.node].op == "const"

    def _shl(self, x, n):
        if self._is_const(x):
            return self._const_node(x.lo << n)
        return self._new("shl", (x,), x.lo << n, x.hi << n, shift=n)

    def _add(self, x, y):
        if self._is_const(x) and self._is_const(y):
            return self._const_node(x.lo + y.lo)
        return self._new("add", (x, y), x.lo + y.lo, x.hi + y.hi)

    def _sub(self, x, y):
        if self._is_const(x) and self._is_const(y):
            return self._const_node(x.lo - y.lo)
        return self._new("sub", (x, y), x.lo - y.hi, x.hi - y.lo)

    def _neg(self, x):
        if self._is_const(x):
            return self._const_node(-x.lo)
        return self._new("neg", (x,), -x.hi, -x.lo)

    def _mul(self, x, y):
        if self._is_const(x) and self._is_const(y):
            return self._const_node(x.lo * y.lo)
        corners = (x.lo * y.lo, x.lo * y.hi, x.hi * y.lo, x.hi * y.hi)
        return self._new("mul", (x, y), min(corners), max(corners))

    def _abs(self, x):
        lo, hi = (x.lo, x.hi) if x.lo >= 0 else (-x.hi, -x.lo) if x.hi <= 0 else (0, max(-x.lo, x.hi))
        return self._new("abs", (x,), lo, hi)

    def _lt(self, x, y):
        return self._new("lt", (x, y), 0, 1)

    def _mux(self, cond, x, y):
        return self._new("mux", (cond, x, y), min(x.lo, y.lo), max(x.hi, y.hi))

    def _rq(self, x, src_frac, fmt, name):
        shift = src_frac - fmt.frac_bits
        lo, hi = shift_round(x.lo, shift, fmt.rounding), shift_round(x.hi, shift, fmt.rounding)
        over = not (fmt.min_raw <= lo and hi <= fmt.max_raw)
        if over:
            lo, hi = (max(lo, fmt.min_raw), min(hi, fmt.max_raw)) if fmt.overflow is Overflow.SATURATE else (
                fmt.min_raw, fmt.max_raw)
        return self._new("rq", (x,), lo, hi, shift=shift, fmt=fmt, overflow=over, name=name), None

    def _div(self, num, den, shift, fmt, name):
        limit = (1 << quotient_bits(fmt)) - 1
        return self._new("div", (num, den), -limit, limit, shift=shift, fmt=fmt, overflow=True, name=name), None

    def _sqrt(self, raw, shift, fmt, name):
        return self._new("sqrt", (raw,), 0, fmt.max_raw, shift=shift, fmt=fmt, overflow=True, name=name), None

    def _any(self, flags):
        return None


# -- lowering: each operation as steps ------------------------------------------------------------


@dataclass
class _Val:
    """A value's digits: their addresses (digit ``k`` of a value of ``n`` digits)."""

    addrs: tuple
    lo: int = 0
    hi: int = 0

    @property
    def n(self):
        return len(self.addrs)

    def at(self, k):
        """Digit ``k``; past the top digit a value has none (its top digit carries the sign)."""
        return self.addrs[k] if 0 <= k < len(self.addrs) else None

    @property
    def top(self):
        return self.addrs[-1]


def _reach(terms):
    """The digits a sum of ``terms`` ``(val, c, shift)`` has contributions at."""
    return max((v.n + s // DIGIT for v, _, s in terms), default=1)


def _const_val(value):
    n = digits_for(value, value)
    return _Val(tuple(k(d) for d in to_digits(value, n)), value, value)


ZERO_VAL, ONE_VAL, NEG_ONE = _const_val(0), _const_val(1), _const_val(-1)


class _Lowering:
    """Turns the trace into steps; :attr:`code` the steps, :attr:`vals` each node's digits."""

    def __init__(self, nodes, state_names, sample_names, input_digits, tag="t"):
        self.nodes = nodes
        self.tag = tag  # the temporaries' address tag: each routine has its own
        self.counted = []  # the points whose overflows the routine counts
        self.code = []
        self.vals = {}
        self.temps = 0  # temporary digits made so far (each its own address: "t", id, k)
        self.state_names = state_names
        self.sample_names = sample_names
        self.input_digits = input_digits

    # helpers -------------------------------------------------------------------------------------
    def temp(self, n, lo=0, hi=0):
        tid = self.temps
        self.temps += 1
        return _Val(tuple((self.tag, tid, j) for j in range(n)), lo, hi)

    def emit(self, mac):
        self.code.append(mac)

    def linear(self, terms, n, out=None):
        """``sum(c * v << s)`` over ``terms`` ``(val, c, s)`` with ``c`` +1 or -1, into ``n`` digits
        (more, when a term has digits past them: none is left out; ``out``: in place, its digits)."""
        n = out.n if out is not None else max(n, _reach(terms))
        out = out or self.temp(n)
        for d in range(n):
            steps = []
            for v, c, s in terms:
                q, r = divmod(s, DIGIT)
                src = v.at(d - q)
                if src is not None:
                    steps.append((src, k(c * (1 << r))))
            self._digit(d, n, steps or [(ZERO, ZERO)], out)
        return out

    def _digit(self, d, n, steps, out):
        """The steps of output digit ``d`` of ``n``, the last writing it to ``out``."""
        for j, (a, b) in enumerate(steps):
            first = j == 0
            mode = (CLEAR if d == 0 else SHIFT) if first else KEEP
            last = j == len(steps) - 1
            self.emit(Mac(a, b, mode, wr=(HI if d == n - 1 else LO) if last else NONE,
                          d=out.addrs[d] if last else None))

    def capture_sign(self, v, flag, *, ovf=False):
        """``flag := v < 0`` from its top digit."""
        self.emit(Mac(v.top, ONE, CLEAR, cap=SET, flag=flag, ovf=ovf))

    def compare_negative(self, terms, n, flag, *, ovf=False, mode=SET):
        """``flag := sum(terms) < 0`` (terms as :meth:`linear`, over ``n`` digits or more)."""
        n = max(n, _reach(terms) + 1)
        for d in range(n):
            steps = []
            for v, c, s in terms:
                q, r = divmod(s, DIGIT)
                src = v.at(d - q)
                if src is not None:
                    steps.append((src, k(c * (1 << r))))
            steps = steps or [(ZERO, ZERO)]
            for j, (a, b) in enumerate(steps):
                last = d == n - 1 and j == len(steps) - 1
                self.emit(Mac(a, b, (CLEAR if d == 0 else SHIFT) if j == 0 else KEEP,
                              cap=mode if last else NONE, flag=flag, ovf=ovf and last))

    def select(self, flag, if_set, if_clear, n, out=None):
        """``if_set`` where ``flag``, else ``if_clear``, into ``n`` digits (both normalised through
        the accumulator, so that either may have fewer digits)."""
        n = out.n if out is not None else max(n, if_set.n, if_clear.n)
        out = out or self.temp(n)
        for d in range(n):
            a, a2 = if_clear.at(d) or ZERO, if_set.at(d) or ZERO
            if a == a2:
                self._digit(d, n, [(a, ONE)], out)
            else:
                self.emit(Mac(a, ONE, CLEAR if d == 0 else SHIFT, a2=a2, pred=flag, wr=HI if d == n - 1 else LO,
                              d=out.addrs[d]))
        return out

    # operations --------------------------------------------------------------------------------
    def lower(self, i):
        node = self.nodes[i]
        getattr(self, f"op_{node.op}")(i, node)

    def arg(self, node, j):
        return self.vals[node.args[j]]

    def n_of(self, node):
        return digits_for(node.lo, node.hi)

    def op_const(self, i, node):
        self.vals[i] = _const_val(node.key)

    def op_input(self, i, node):
        kind, name = node.key
        n = self.input_digits if kind == "sample" else digits_for(node.lo, node.hi)
        tag = {"sample": "u", "state": "s", "const": "c"}[kind]
        self.vals[i] = _Val(tuple((tag, name, j) for j in range(n)), node.lo, node.hi)

    def op_shl(self, i, node):
        self.vals[i] = self.linear([(self.arg(node, 0), 1, node.shift)], self.n_of(node))

    def op_add(self, i, node):
        self.vals[i] = self.linear([(self.arg(node, 0), 1, 0), (self.arg(node, 1), 1, 0)], self.n_of(node))

    def op_sub(self, i, node):
        self.vals[i] = self.linear([(self.arg(node, 0), 1, 0), (self.arg(node, 1), -1, 0)], self.n_of(node))

    def op_neg(self, i, node):
        self.vals[i] = self.linear([(self.arg(node, 0), -1, 0)], self.n_of(node))

    def op_mul(self, i, node):
        x, y = self.arg(node, 0), self.arg(node, 1)
        n = max(self.n_of(node), x.n + y.n - 1)
        out = self.temp(n)
        for d in range(n):
            steps = [(x.at(j), y.at(d - j)) for j in range(x.n) if y.at(d - j) is not None]
            self._digit(d, n, steps or [(ZERO, ZERO)], out)
        self.vals[i] = out

    def op_abs(self, i, node):
        x = self.arg(node, 0)
        self.capture_sign(x, 0)
        n = max(self.n_of(node), x.n)
        out = self.temp(n)
        for d in range(n):
            # the product's first operand is the sign: -1 where the value is negative
            self.emit(Mac(ONE, x.at(d) or ZERO, CLEAR if d == 0 else SHIFT, a2=NEG, pred=0,
                          wr=HI if d == n - 1 else LO, d=out.addrs[d]))
        self.vals[i] = out

    def op_lt(self, i, node):
        x, y = self.arg(node, 0), self.arg(node, 1)
        n = max(x.n, y.n) + 1
        self.compare_negative([(x, 1, 0), (y, -1, 0)], n, 0)
        out = self.temp(1)
        self.emit(Mac(ZERO, ONE, CLEAR, a2=ONE, pred=0, wr=HI, d=out.addrs[0]))
        self.vals[i] = out

    def op_mux(self, i, node):
        cond, x, y = (self.arg(node, j) for j in range(3))
        self.emit(Mac(cond.top, NEG, CLEAR, cap=SET, flag=0))  # -cond < 0: the condition holds
        self.vals[i] = self.select(0, x, y, self.n_of(node))

    def op_rq(self, i, node):
        v = self.arg(node, 0)
        fmt, s = node.fmt, node.shift
        exact_lo, exact_hi = (shift_round(self.nodes[node.args[0]].lo, s, fmt.rounding),
                              shift_round(self.nodes[node.args[0]].hi, s, fmt.rounding))
        nr = digits_for(min(exact_lo, 0), max(exact_hi, 0))
        if s <= 0:
            r = self.linear([(v, 1, -s)], nr) if s < 0 else v
        else:
            r = self.round_shift(v, s, fmt.rounding, nr)
        self.vals[i] = self.fit(r, nr, fmt, node.overflow)

    def round_shift(self, v, s, rounding, nr):
        """``floor((v + addend) / 2**s)`` into ``nr`` digits (the addend of ``rounding``)."""
        rounding = Rounding(rounding)
        q, r = divmod(s - 1, DIGIT)
        r += 1  # s = 17 q + r, r in 1..17: each digit times 2**(17 - r), q + 1 digits dropped
        c = 1 << (DIGIT - r)
        nr = max(nr, v.n - q - 1)  # every digit of v is read
        extra = {}  # digit -> steps of the addend (times c) added there
        if rounding is Rounding.NEAREST:
            extra[q] = [(ONE, k(1 << 16))]
        elif rounding is Rounding.ROUND:  # 2**(s-1), less 1 for a negative value
            self.capture_sign(v, 0)
            extra[q] = [(ONE, k(1 << 16))]
            extra.setdefault(0, []).append(("pred", ZERO, ONE, k(-c)))
        elif rounding is Rounding.FIX:  # 2**s - 1 for a negative value
            self.capture_sign(v, 0)
            extra.setdefault(0, []).append(("pred", ZERO, ONE, k(-c)))
            extra.setdefault(q + 1, []).append(("pred", ZERO, ONE, ONE))
        elif rounding is Rounding.CONVERGENT:  # 2**(s-1) - 1, plus the bit that becomes the LSB
            qb, rb = divmod(s, DIGIT)
            src = v.at(qb) if qb < v.n else v.top
            shift_bit = 1 << (16 - rb) if qb < v.n else 1 << 16  # past the top: the sign bit
            self.emit(Mac(src, k(shift_bit), CLEAR, cap=SET, flag=0, bit16=qb < v.n))
            extra[q] = [(ONE, k(1 << 16))]
            extra.setdefault(0, []).append(("pred", ONE, ZERO, k(-c)))  # -c unless the bit is 1
        out = self.temp(nr)
        total = q + 1 + nr
        # With no addend below digit q the digits under it carry nothing past the cut (their sum
        # and digit q's bits below it stay under 2**(17 (q + 1)) once scaled by c), so a floor
        # starts at digit q.
        first = min(extra, default=q)
        for d in range(min(first, q), total):
            steps = []
            src = v.at(d)
            if src is not None:
                steps.append((src, k(c)))
            steps += extra.get(d, [])
            steps = steps or [(ZERO, ZERO)]
            write = d > q
            for j, step in enumerate(steps):
                mode = (CLEAR if d == min(first, q) else SHIFT) if j == 0 else KEEP
                last = j == len(steps) - 1
                wr, dst = NONE, None
                if last and write:
                    wr, dst = (HI if d == total - 1 else LO), out.addrs[d - q - 1]
                if step[0] == "pred":
                    _, a, a2, b = step
                    self.emit(Mac(a, b, mode, a2=a2, pred=0, wr=wr, d=dst))
                else:
                    self.emit(Mac(step[0], step[1], mode, wr=wr, d=dst))
        return out

    def fit(self, r, nr, fmt, can_overflow):
        """``r`` (``nr`` digits) written into ``fmt``: saturated (or wrapped) and flagged where it
        can pass the format (the interval says so), else as it is."""
        nt = digits_for(fmt.min_raw, fmt.max_raw)
        if not can_overflow:
            if nr <= nt:
                return r if nr == nt else self.linear([(r, 1, 0)], nt)
            return self.truncate(r, nt)
        top, bottom = _const_val(fmt.max_raw), _const_val(fmt.min_raw)
        n = max(nr, nt) + 1
        if fmt.overflow is Overflow.WRAP:
            self.compare_negative([(top, 1, 0), (r, -1, 0)], n, 1, ovf=True)  # r > max: flagged
            self.compare_negative([(r, 1, 0), (bottom, -1, 0)], n, 1, ovf=True)  # r < min: flagged
            return self.wrap(r, nt, fmt.width)
        kept = self.truncate(r, nt) if nr > nt else r if nr == nt else self.linear([(r, 1, 0)], nt)
        if not self.past_power(r, fmt.width - 1, 1, high=True):
            self.compare_negative([(top, 1, 0), (r, -1, 0)], n, 1, ovf=True)  # r > max
        high = self.select(1, top, kept, nt)
        if not self.past_power(r, fmt.width - 1, 1, high=False):
            self.compare_negative([(r, 1, 0), (bottom, -1, 0)], n, 1, ovf=True)  # r < min
        return self.select(1, bottom, high, nt)

    def past_power(self, r, p, flag, *, high):
        """``flag := r >= 2**p`` (``high``) or ``r < -2**p``, flagged as an overflow, from the digits
        of ``r`` that hold bit ``p`` and above: with ``F = floor(r / 2**p)`` (read as a floor from
        digit ``q`` up, :meth:`round_shift`), ``r >= 2**p`` is ``-F < 0`` and ``r < -2**p`` is
        ``F + 1 < 0``. The full comparison reads every digit of ``r`` and of the bound, twice as many
        steps. False (nothing emitted) where ``r`` has no digit at ``q``."""
        if p < 1:
            return False
        q, rr = divmod(p - 1, DIGIT)
        c = 1 << (DIGIT - rr - 1)  # p = 17 q + rr + 1: each digit times 2**(17 - (rr + 1))
        if q >= r.n:
            return False
        sign = -1 if high else 1
        steps = [(r.at(q), k(sign * c), CLEAR)]
        if high:
            # -(v_q c) rounded up, not down, at the shift: then it is -floor(v_q c / 2**17) exactly
            steps.append((ONE, k(RADIX - 1), KEEP))
        for d in range(q + 1, r.n):
            steps.append((r.at(d), k(sign * c), SHIFT))
            if not high and d == q + 1:
                steps.append((ONE, ONE, KEEP))  # F + 1: the 1 at the weight of F's first digit
        if not high and r.n == q + 1:
            steps.append((ONE, ONE, SHIFT))  # F is digit q's scaled value shifted once
        for j, (a, b, mode) in enumerate(steps):
            last = j == len(steps) - 1
            self.emit(Mac(a, b, mode, cap=SET if last else NONE, flag=flag, ovf=last))
        return True

    def truncate(self, r, nt):
        """The low ``nt`` digits of ``r``, whose value fits them (its top digit signed again)."""
        self.capture_sign(r, 0)
        out = self.temp(nt)
        for d in range(nt - 1):
            self._digit(d, nt, [(r.at(d), ONE)], out)
        # the top digit: digit nt-1 less 2**17 where the value is negative (two steps of 2**16)
        mode = CLEAR if nt == 1 else SHIFT
        self.emit(Mac(r.at(nt - 1), ONE, mode))
        self.emit(Mac(ZERO, ONE, KEEP, a2=k(-(1 << 16)), pred=0))
        self.emit(Mac(ZERO, ONE, KEEP, a2=k(-(1 << 16)), pred=0, wr=HI, d=out.addrs[nt - 1]))
        return out

    def wrap(self, r, nt, width):
        """The low ``width`` bits of ``r`` as a signed value of ``nt`` digits."""
        out = self.temp(nt)
        for d in range(nt - 1):
            self._digit(d, nt, [(r.at(d) or ZERO, ONE)], out)
        w = width - DIGIT * (nt - 1)  # bits of the top digit, 1..18
        t = r.at(nt - 1) or ZERO
        if w == WORD:
            # t is a lower digit of r (a wider r: it overflows), and the top digit's 18th bit is
            # bit 0 of r's next digit: t less 2**17 where that bit is 1
            self.emit(Mac(r.at(nt) or ZERO, k(1 << 16), CLEAR, cap=SET, flag=0, bit16=True))
            self.emit(Mac(t, ONE, CLEAR))
            self.emit(Mac(ZERO, ONE, KEEP, a2=k(-(1 << 16)), pred=0))
            self.emit(Mac(ZERO, ONE, KEEP, a2=k(-(1 << 16)), pred=0, wr=HI, d=out.addrs[nt - 1]))
            return out
        low = self.temp(1)
        # l = ((t + 2**(w-1)) mod 2**w) << (17 - w), as a low digit
        self.emit(Mac(t, k(1 << (DIGIT - w)), CLEAR))
        self.emit(Mac(ONE, k(1 << 16), KEEP, wr=LO, d=low.addrs[0]))
        # then (l << w) >> 17 = (t + 2**(w-1)) mod 2**w, less 2**(w-1): the top digit
        self.emit(Mac(low.addrs[0], k(1 << (w - 1)), CLEAR))
        self.emit(Mac(low.addrs[0], k(1 << (w - 1)), KEEP))
        self.emit(Mac(ONE, k(-(1 << (w - 1))), SHIFT, wr=HI, d=out.addrs[nt - 1]))
        return out

    def op_div(self, i, node):
        """The restoring divider (:func:`kfpga.core.ops.divide`): ``|num| << shift`` over ``den``."""
        num, den = self.arg(node, 0), self.arg(node, 1)
        fmt, shift = node.fmt, node.shift
        qbits = quotient_bits(fmt)
        src_num, src_den = self.nodes[node.args[0]], self.nodes[node.args[1]]
        mag_hi = max(abs(src_num.lo), abs(src_num.hi))
        m = self.magnitude(num, digits_for(0, mag_hi))  # flag 0: num < 0, the quotient's sign ...
        negative = self.keep_flag(0)  # ... kept in a word while the loop takes the flag
        nl = -(-qbits // DIGIT)  # digits that hold the dividend's last qbits bits, left-justified
        rd_shift = shift + DIGIT * nl - qbits
        den_hi = max(src_den.hi, 1)
        nr = max(digits_for(0, 2 * den_hi + 1), den.n)  # the remainder, below twice the divisor once doubled
        nrd = max(digits_for(0, mag_hi << rd_shift), nl + nr, m.n + rd_shift // DIGIT)
        # rd: the remainder (above nl digits: the dividend's bits above its last qbits) and the
        # dividend's last bits below it, shifted into the remainder one a step
        rd = self.linear([(m, 1, rd_shift)], nrd)
        first = _Val(rd.addrs[nl:])
        # flag 1, bad: den <= 0, or the quotient does not fit (the first remainder is >= den)
        self.compare_negative([(den, 1, 0), (NEG_ONE, 1, 0)], den.n + 1, 1, ovf=True)
        self.compare_negative([(den, 1, 0), (first, -1, 0), (NEG_ONE, 1, 0)], max(den.n, first.n) + 1, 1, mode=OR,
                              ovf=True)
        # a bad division runs on 0 / 1, so that every value stays in its digits (its quotient is replaced)
        rd = self.select(1, ZERO_VAL, rd, nrd, rd)
        den = self.select(1, ONE_VAL, den, den.n)
        rem = _Val(rd.addrs[nl:nl + nr])
        quo = self.temp(digits_for(0, (1 << qbits) - 1))
        self.linear([(ZERO_VAL, 1, 0)], quo.n, quo)
        self.emit(nop(loop=BEGIN, count=qbits))
        self.linear([(rd, 1, 1)], nrd, rd)  # the remainder and the dividend below it, doubled
        trial = self.temp(nr)
        self.emit_difference(rem, den, nr, trial, flag=0)  # trial = rem - den; flag 0: negative
        self.select(0, rem, trial, nr, rem)  # the difference kept where it is not negative
        self.double_plus_bit(quo, 0)  # quotient = 2 quotient + (difference not negative)
        kept = self.select(1, _const_val((1 << qbits) - 1), quo, quo.n)
        self.emit(Mac(negative, NEG, CLEAR, cap=SET, flag=0))  # flag 0: the quotient's sign again
        self.vals[i] = self.signed(kept, digits_for(fmt.min_raw, fmt.max_raw))

    def keep_flag(self, flag):
        """A word that holds ``flag`` (1 or 0), for a flag needed again after its flag is reused."""
        word = self.temp(1)
        self.emit(Mac(ZERO, ONE, CLEAR, a2=ONE, pred=flag, wr=HI, d=word.addrs[0]))
        return word.addrs[0]

    def double_plus_bit(self, q, flag):
        """``q = 2 q + (not flag)``, in place; then the loop's end (a step of its own, which holds
        where the loop starts)."""
        for d in range(q.n):
            wr = HI if d == q.n - 1 else LO
            if d == 0:
                self.emit(Mac(q.addrs[0], k(2), CLEAR))
                self.emit(Mac(ONE, ONE, KEEP, a2=ZERO, pred=flag, wr=wr, d=q.addrs[0]))
            else:
                self.emit(Mac(q.addrs[d], k(2), SHIFT, wr=wr, d=q.addrs[d]))
        self.emit(nop(loop=END))

    def emit_difference(self, x, y, n, out, *, flag):
        """``out = x - y`` (``n`` digits), ``flag := out < 0``."""
        for d in range(n):
            steps = [(s, b) for s, b in ((x.at(d), ONE), (y.at(d), NEG)) if s is not None] or [(ZERO, ZERO)]
            for j, (a, b) in enumerate(steps):
                last = j == len(steps) - 1
                self.emit(Mac(a, b, (CLEAR if d == 0 else SHIFT) if j == 0 else KEEP,
                              wr=(HI if d == n - 1 else LO) if last else NONE, d=out.addrs[d] if last else None,
                              cap=SET if last and d == n - 1 else NONE, flag=flag))

    def magnitude(self, x, n):
        """``|x|`` into ``n`` digits; flag 0 := ``x < 0`` (kept for the sign of the result)."""
        self.capture_sign(x, 0)
        out = self.temp(max(n, x.n))
        n = out.n
        for d in range(n):
            self.emit(Mac(ONE, x.at(d) or ZERO, CLEAR if d == 0 else SHIFT, a2=NEG, pred=0,
                          wr=HI if d == n - 1 else LO, d=out.addrs[d]))
        return out

    def signed(self, x, n):
        """``x`` negated where flag 0 is set."""
        out = self.temp(max(n, x.n))
        n = out.n
        for d in range(n):
            self.emit(Mac(ONE, x.at(d) or ZERO, CLEAR if d == 0 else SHIFT, a2=NEG, pred=0,
                          wr=HI if d == n - 1 else LO, d=out.addrs[d]))
        return out

    def op_sqrt(self, i, node):
        """The restoring square root (:func:`kfpga.core.ops.square_root`) of ``raw`` shifted."""
        x = self.arg(node, 0)
        fmt, shift = node.fmt, node.shift
        src = self.nodes[node.args[0]]
        self.capture_sign(x, 0, ovf=True)  # a negative radicand: the root is 0, flagged
        pos_hi = max(src.hi, 0)
        rad_hi = pos_hi << shift if shift >= 0 else pos_hi >> -shift
        half = -(-max(rad_hi.bit_length(), 1) // 2)  # the root's bits
        nl = -(-2 * half // DIGIT)
        nq = digits_for(0, (1 << half) - 1)
        nr = digits_for(0, (1 << (half + 2)) + 1)
        nrd = nl + nr
        pos = self.select(0, ZERO_VAL, x, x.n)  # max(x, 0)
        negative = self.keep_flag(0)
        if shift < 0:  # a floor shift first
            pos = self.round_shift(pos, -shift, Rounding.FLOOR, digits_for(0, max(rad_hi, 1)))
        rd = self.linear([(pos, 1, max(shift, 0) + DIGIT * nl - 2 * half)], nrd)
        rem = _Val(rd.addrs[nl:nl + nr])
        root = self.temp(nq)
        self.linear([(ZERO_VAL, 1, 0)], nq, root)
        self.emit(nop(loop=BEGIN, count=half))
        self.linear([(rd, 1, 2)], nrd, rd)  # two more radicand bits into the remainder
        trial = self.temp(nr)
        for d in range(nr):  # trial = rem - 4 root - 1; flag 2: negative
            steps = [(rem.at(d), ONE)] if rem.at(d) is not None else []
            if root.at(d) is not None:
                steps.append((root.at(d), k(-4)))
            if d == 0:
                steps.append((ONE, NEG))
            steps = steps or [(ZERO, ZERO)]
            for j, (a, b) in enumerate(steps):
                last = j == len(steps) - 1
                self.emit(Mac(a, b, (CLEAR if d == 0 else SHIFT) if j == 0 else KEEP,
                              wr=(HI if d == nr - 1 else LO) if last else NONE, d=trial.addrs[d] if last else None,
                              cap=SET if last and d == nr - 1 else NONE, flag=0))
        self.select(0, rem, trial, nr, rem)
        self.double_plus_bit(root, 0)
        nt = digits_for(0, fmt.max_raw)
        limit = _const_val(fmt.max_raw)
        self.compare_negative([(limit, 1, 0), (root, -1, 0)], max(nq, limit.n) + 1, 1, ovf=True)  # root > limit
        # a root is never negative: its digits past nt are zeros once it is within the limit
        fitted = self.select(1, limit, root, nt)
        self.emit(Mac(negative, NEG, CLEAR, cap=SET, flag=0))  # flag 0: the radicand was negative
        self.vals[i] = self.select(0, ZERO_VAL, fitted, nt)


# -- the program -----------------------------------------------------------------------------------


@dataclass
class Program:
    """The microcode of one config and variant, placed.

    ``words``: each step as a dict of its fields (addresses resolved; ``d`` the output chunk of an
    ``OUT`` write), with its ``wait``; ``init``: the register file's power-up words (constants and
    every channel's reset state); ``init_steps``: the steps that write one channel's reset state
    (the first ``init_steps`` words); ``state_base``, ``state_bits``: state digit ``j`` of channel
    ``c`` is at ``state_base | c << state_bits | j``; ``sample_addrs``: ``[(input, digit, addr)]``;
    ``chunks``: ``[(output, offset, width)]`` of each output chunk in the payload's order;
    ``acc_bits``: the accumulator's width; ``depth``: the register file's.
    """

    words: list
    init: list
    init_steps: int
    state_base: int
    state_bits: int
    sample_addrs: list
    chunks: list
    acc_bits: int
    depth: int
    channels: int
    update_cycles: int  # from the first step to the last's write
    init_cycles: int
    outputs: tuple = ()
    input_digits: int = 1
    consts: dict = field(default_factory=dict)
    #: for tests: every symbolic address's register, each traced value's digits, the trace
    addresses: dict = field(default_factory=dict, repr=False)
    values: dict = field(default_factory=dict, repr=False)
    nodes: list = field(default_factory=list, repr=False)
    #: ``{routine: (first word, steps)}`` (``init``, ``update``, and ``predict``, ``commit`` when built)
    routines: dict = field(default_factory=dict)
    #: ``{routine: cycles}`` from its first step to its last's write
    cycles: dict = field(default_factory=dict)
    #: the :class:`Setting` s a bus writes (a programmable program), and the first shadow word's address
    settings: tuple = ()
    shadow_base: int = 0
    #: the points whose overflows the counters count (a programmable program), and the first one's address
    counters: tuple = ()
    counter_base: int = 0

    def start(self, routine):
        """The first word of ``routine``."""
        return self.routines[routine][0]

    def routine(self, name):
        """The words of the routine ``name``."""
        start, n = self.routines[name]
        return self.words[start:start + n]

    @property
    def shadow_words(self):
        """The register-file words a bus writes: every setting's digits."""
        return sum(st.digits for st in self.settings)

    @property
    def address_bits(self):
        return max(1, (self.depth - 1).bit_length())


def programmable_names(config, variant):
    """What a programmable core takes from its bus: ``(constants, states)``, the names of the
    constants quantised into a configurable point (a structural one, a shift or an exact ``1/h``,
    stays built in: it shapes the update) and of the states whose reset value is one."""
    from kfpga.core.spec import Constant

    consts = [n for n, c in config.constants(variant).items() if isinstance(c, Constant) and isinstance(c.point, str)]
    states = [n for n, point in config.spec.model.variants[variant].state_for(config.params) if isinstance(point, str)]
    return consts, states


def _trace(config, variant, *, predict=False, programmable=()):
    spec_variant = config.spec.model.variants[variant]
    ops = FoldOps(config.formats, programmable)
    k_ = ops.constants(config.constants(variant))
    states = spec_variant.state_for(config.params)
    x = {name: ops.input(("state", name), config.point_format(point), name) for name, point in states}
    u = {name: ops.input(("sample", name), config.input_format, name) for name in config.inputs}
    x_next, outs = spec_variant.predict(ops, k_, x) if predict else spec_variant.update(ops, k_, x, u)
    for label, value in [*outs.items(), *x_next.items()]:
        if not isinstance(value, Fx):
            raise TypeError(f"{label}: the update must give Fx values")
    return ops.nodes, states, x_next, outs, dict(ops.point_of)


def _live(nodes, roots):
    """Every node a root needs, and every write that can overflow (its flag is the sample's)."""
    live, todo = set(), [*roots, *(i for i, n in enumerate(nodes) if n.overflow)]
    while todo:
        i = todo.pop()
        if i not in live:
            live.add(i)
            todo.extend(nodes[i].args)
    return live


def _routine(config, variant, tag, *, predict=False, programmable=(), counting=False):
    """One sample's routine (the update, or with ``predict`` the update of a sample with no
    measurement): ``(lowering, output chunks, {state: digits})``; its temporaries are tagged ``tag``;
    with ``counting``, every write that can overflow also counts its overflows in a register-file
    word of its point (``("o", point)``)."""
    nodes, states, x_next, outs, point_of = _trace(config, variant, predict=predict, programmable=programmable)
    state_names = [name for name, _ in states]
    input_digits = digits_for(config.input_format.min_raw, config.input_format.max_raw)
    low = _Lowering(nodes, state_names, list(config.inputs), input_digits, tag)
    output_fields = [o.name for o in config.outputs]
    roots = [outs[name].raw.node for name in output_fields] + [x_next[name].raw.node for name in state_names]
    live = _live(nodes, roots)
    for i in range(len(nodes)):
        if i in live or nodes[i].op in ("const", "input"):
            start = len(low.code)
            low.lower(i)
            if counting and nodes[i].overflow:
                point = point_of.get(nodes[i].name, nodes[i].name)
                low.code[start:] = _count_overflows(low.code[start:], point)
                low.counted.append(point)
    # the outputs, chunk by chunk
    chunks = []
    for name in output_fields:
        fmt = config.output_format(name)
        v = low.vals[outs[name].raw.node]
        n = digits_for(fmt.min_raw, fmt.max_raw)
        v = low.truncate(v, n) if v.n > n else v
        for dgt in range(n):
            width = min(DIGIT, fmt.width - DIGIT * dgt) if dgt < n - 1 else fmt.width - DIGIT * dgt
            chunk = len(chunks)
            chunks.append((name, DIGIT * dgt, width))
            low.emit(Mac(v.at(dgt) or ZERO, ONE, CLEAR if dgt == 0 else SHIFT, wr=OUT, d=chunk))
    # the next state: values that are another state's present value (or a sample) first to a temporary
    final = {}
    for name, (_, point) in zip(state_names, states, strict=True):
        v = low.vals[x_next[name].raw.node]
        n = digits_for(config.point_format(point).min_raw, config.point_format(point).max_raw)
        if v.n > n:
            v = low.truncate(v, n)
        elif any(a[0] in ("s", "u") for a in v.addrs):
            v = low.linear([(v, 1, 0)], n)
        final[name] = (v, n)
    for name, (v, n) in final.items():
        low.linear([(v, 1, 0)], n, _Val(tuple(("s", name, j) for j in range(n))))
    return low, chunks, {name: final[name][1] for name in state_names}


def _count_overflows(code, point):
    """``code`` (one write's steps) with, after each capture of its overflow flag, two steps that
    add the flag to the counter word ``("o", point)`` (its low digit: it wraps at 2**17). A capture
    ORed into the flag by the next step counts once, after that step; the accumulator is free
    there (the next step clears it)."""
    out, depth = [], 0
    counter = ("o", point)
    for j, mac in enumerate(code):
        out.append(mac)
        depth += (mac.loop == BEGIN) - (mac.loop == END)
        if not (mac.ovf and mac.cap) or _ored_later(code, j):
            continue
        nxt = code[j + 1] if j + 1 < len(code) else None
        if depth or (nxt is not None and nxt.acc != CLEAR):
            raise AssertionError("an overflow capture inside a loop, or before a step that keeps the accumulator")
        out += [Mac(counter, ONE, CLEAR), Mac(ZERO, ONE, KEEP, a2=ONE, pred=mac.flag, wr=LO, d=counter)]
    return out


def _ored_later(code, j):
    """Whether a later step ORs another overflow condition into the flag step ``j`` captures
    (before any step captures that flag anew)."""
    flag = code[j].flag
    for mac in code[j + 1:]:
        if mac.cap and mac.flag == flag:
            return mac.cap == OR and mac.ovf
    return False


@dataclass(frozen=True)
class Setting:
    """A value a programmable core takes from its bus: the constant ``name`` (``kind`` ``"c"``) or
    the reset value of the state ``name`` (``"r"``), held in ``fmt`` as ``digits`` words of the
    register file; the bus writes them at ``shadow`` (the index of the first, among all the
    settings' digits), and a commit copies them to where the routines read them."""

    kind: str
    name: str
    label: str
    point: object
    fmt: object
    digits: int
    shadow: int
    raw: int


def compile_update(config, variant, *, channels=1, channel_bits=None, predict=False, programmable=False):
    """The :class:`Program` of ``config``'s ``variant`` for a core of ``channels`` channel states.

    ``predict``: with a routine for a sample with no measurement (the variant's ``predict``).
    ``programmable``: the constants and the reset state in register-file words that a bus writes
    (through shadow words, copied between updates by the commit routine), so that no product is
    specialised to a built-in constant; at power-up they hold the config's values."""
    spec_variant = config.spec.model.variants[variant]
    if predict and spec_variant.predict is None:
        raise ValueError(f"the {config.spec.name} filter's {variant} variant takes every sample as a measurement: "
                         "no update without one (missing samples do not apply)")
    consts, resets = programmable_names(config, variant) if programmable else ((), ())
    low, chunks, state_digits = _routine(config, variant, "t", programmable=consts, counting=programmable)
    routines = {"update": low.code}
    lows = [low]
    if predict:
        coast, coast_chunks, _ = _routine(config, variant, "tp", predict=True, programmable=consts,
                                          counting=programmable)
        if coast_chunks != chunks:
            raise AssertionError("the routines without a measurement give other output chunks")
        routines["predict"] = coast.code
        lows.append(coast)
    states = spec_variant.state_for(config.params)
    reset = config.reset_state(variant)
    init_code = []
    for name, point in states:
        fmt = config.point_format(point)
        n = digits_for(fmt.min_raw, fmt.max_raw)
        for dgt, value in enumerate(to_digits(reset[name], n)):
            init_code.append(Mac(("r", name, dgt) if name in resets else k(value), ONE, CLEAR, wr=HI,
                                 d=("s", name, dgt)))
    if not init_code:
        init_code.append(nop())
    settings = []
    if programmable:
        table, raw, j = config.constants(variant), config.constant_raw(variant), 0
        points = dict(states)
        for kind, name, point, value, label in (
                [("c", n, table[n].point, raw[n], table[n].label or n) for n in consts]
                + [("r", n, points[n], reset[n], f"{n}(0)") for n in resets]):
            fmt = config.point_format(point)
            n = digits_for(fmt.min_raw, fmt.max_raw)
            settings.append(Setting(kind, name, label, point, fmt, n, j, value))
            j += n
        # the commit: every shadow word copied to the word the routines read
        routines["commit"] = [Mac(("p", st.shadow + dgt), ONE, CLEAR, wr=HI, d=(st.kind, st.name, dgt))
                              for st in settings for dgt in range(st.digits)] or [nop()]
    counters = tuple(dict.fromkeys(p for lw in lows for p in lw.counted))
    if programmable:  # the counters to 0
        routines["clear"] = [Mac(ZERO, ZERO, CLEAR, wr=LO, d=("o", point)) for point in counters] or [nop()]
    return _place(config, init_code, routines, lows, state_digits, chunks, channels, channel_bits,
                  digits_for(config.input_format.min_raw, config.input_format.max_raw), settings, counters)


def _place(config, init_code, routines, lows, state_digits, chunks, channels, channel_bits, input_digits, settings,
           counters=()):
    """Addresses for every word, the schedule's waits, the register file's power-up words."""
    parts = [("init", init_code), *routines.items()]
    code = [mac for _, part in parts for mac in part]
    consts = sorted({addr[1] for mac in code for addr in (mac.a, mac.b, mac.a2) if addr and addr[0] == "k"})
    addr = {("k", v): j for j, v in enumerate(consts)}
    samples = [(name, dgt) for name in config.inputs for dgt in range(input_digits)]
    for j, (name, dgt) in enumerate(samples):
        addr[("u", name, dgt)] = len(consts) + j
    counter_base = len(consts) + len(samples)
    for j, point in enumerate(counters):  # the overflow counters, 0 at power-up
        addr[("o", point)] = counter_base + j
    image, shadow_base, temp_base = _place_settings(addr, settings, counter_base + len(counters))
    for tag, part in (("t", routines["update"]), ("tp", routines.get("predict", []))):
        addr.update(_allocate(part, temp_base, tag))  # the routines never run at once: the same registers
    top = max([*addr.values(), 0]) + 1
    offsets, j = {}, 0
    for name, n in state_digits.items():
        for dgt in range(n):
            offsets[(name, dgt)] = j
            j += 1
    state_bits = max(1, (max(j, 1) - 1).bit_length())
    cbits = channel_bits if channel_bits is not None else max(1, (channels - 1).bit_length())
    # one spare block past the channels, all zeros: what a channel number past the last reads
    region = (channels + (1 if channels < 1 << cbits else 0)) << state_bits
    state_base = 1 << max(top - 1, region - 1, 1).bit_length()
    for (name, dgt), off in offsets.items():
        addr[("s", name, dgt)] = state_base | off
    depth = state_base + region
    init = [0] * depth
    for v, a in zip(consts, range(len(consts)), strict=True):
        init[a] = v & ((1 << WORD) - 1)
    for a, v in image.items():
        init[a] = v & ((1 << WORD) - 1)
    words = [_resolve(mac, addr) for mac in code]
    starts, cycles = _finish(words, parts)
    acc_bits = _acc_bits(code)
    return Program(words, init, len(init_code), state_base, state_bits,
                   [(name, dgt, addr[("u", name, dgt)]) for name, dgt in samples], chunks, acc_bits, depth, channels,
                   cycles["update"], cycles["init"], tuple(o.name for o in config.outputs), input_digits,
                   {v: addr[("k", v)] for v in consts}, addr, {i: v.addrs for i, v in lows[0].vals.items()},
                   lows[0].nodes, starts, cycles, tuple(settings), shadow_base, counters, counter_base)


def _place_settings(addr, settings, nxt):
    """Addresses from ``nxt`` on for the settings' words: first those the routines read, then the
    shadow words the bus writes (both hold the config's values at power-up). Returns ``(power-up
    words {address: digit}, the first shadow word's address, the next free address)``."""
    image = {}
    for keys in ((lambda st, dgt: (st.kind, st.name, dgt)), (lambda st, dgt: ("p", st.shadow + dgt))):
        for st in settings:
            for dgt, value in enumerate(to_digits(st.raw, st.digits)):
                addr[keys(st, dgt)] = nxt
                image[nxt] = value
                nxt += 1
    shadow = addr[("p", 0)] if settings else nxt
    return image, shadow, nxt


def _finish(words, parts):
    """Mark each routine's last step, resolve the loops, schedule each routine on its own (the core
    waits for a routine's last write before another starts). Returns ``({routine: (first word,
    steps)}, {routine: cycles})``."""
    starts, pos = {}, 0
    for name, part in parts:
        starts[name] = (pos, len(part))
        pos += len(part)
        words[pos - 1]["end"] = 1  # the last step of each routine
    begin = None
    for pos, w in enumerate(words):  # a loop's end holds its first step's address, its begin the count
        if w["loop"] == BEGIN:
            begin, w["d"] = pos, w["count"] - 1
        elif w["loop"] == END:
            w["d"] = begin + 1
    cycles = {}
    for name, (start, n) in starts.items():
        part = words[start:start + n]
        for w, wait in zip(part, _schedule(part), strict=True):
            w["wait"] = wait
        cycles[name] = _cycles(part)
    return starts, cycles


def handshake_twin(program):
    """A short copy of ``program`` for the formal stream checks of its core.

    The folded core's handshake (write a sample's digits, take the word, run the routine, give
    the estimate; after reset the reset routine for every channel) does not depend on what its
    steps compute, only on how many digits a sample has and how long each routine runs. The twin
    keeps the sample's digits, the output chunks and the channels, and runs a reset routine of one
    step and an update of three (a sample's digit into an output chunk, the sample's flag, a
    state write), on a register file of a few words, so that a bounded check covers whole updates
    from reset."""
    import dataclasses

    consts = {0: 0, 1: 1}
    samples = [(name, dgt, 2 + j) for j, (name, dgt, _) in enumerate(program.sample_addrs)]
    state_bits = 1
    region = (program.channels + 1) << state_bits
    base = 1 << max(2 + len(samples) - 1, region - 1, 1).bit_length()

    def word(a, b, **kw):
        w = {"a": a, "b": b, "a2": a, "acc": CLEAR, "pred": 0, "wr": NONE, "d": 0, "cap": NONE, "flag": 0, "bit16": 0,
             "ovf": 0, "loop": NONE, "count": 0, "end": 0}
        w.update(kw)
        return w

    init = [word(0, 1, wr=HI, d=base, end=1)]
    update = [word(samples[0][2], 1, wr=OUT, d=0), word(samples[0][2], 1, cap=SET, ovf=1),
              word(0, 1, wr=HI, d=base, end=1)]
    for part in (init, update):
        for w, wait in zip(part, _schedule(part), strict=True):
            w["wait"] = wait
    words = init + update
    depth = base + region
    image = [0] * depth
    image[1] = 1
    return dataclasses.replace(program, words=words, init=image, init_steps=1, state_base=base, state_bits=state_bits,
                               sample_addrs=samples, update_cycles=_cycles(update), init_cycles=_cycles(init),
                               depth=depth, consts=consts, addresses={}, values={}, nodes=[],
                               routines={"init": (0, 1), "update": (1, 3)},
                               cycles={"init": _cycles(init), "update": _cycles(update)}, settings=(), shadow_base=0,
                               counters=(), counter_base=0)


def _resolve(mac, addr):
    def a(x):
        return addr[x] if x is not None else 0

    return {"a": a(mac.a), "b": a(mac.b), "a2": a(mac.a2) if mac.a2 is not None else a(mac.a), "acc": mac.acc,
            "pred": 0 if mac.pred is None else 1 + mac.pred, "wr": mac.wr,
            "d": (mac.d if mac.wr == OUT else a(mac.d)) if mac.wr != NONE else 0, "cap": mac.cap, "flag": mac.flag,
            "bit16": int(mac.bit16), "ovf": int(mac.ovf), "loop": mac.loop, "count": mac.count, "end": 0}


def _lifetimes(code, tag="t"):
    """``(first, last)``: the step that first uses each temporary digit, and the last; a digit used
    inside a loop lives through the whole loop (its registers are not reused there)."""
    first, last, spans, start = {}, {}, [], None
    for pos, mac in enumerate(code):
        if mac.loop == BEGIN:
            start = pos
        for x in (mac.a, mac.b, mac.a2, mac.d if mac.wr in (LO, HI) else None):
            if x is not None and x[0] == tag:
                first.setdefault(x, pos)
                last[x] = pos
        if mac.loop == END:
            spans.append((start, pos))
    for x in first:
        for lo, hi in spans:
            if first[x] <= hi and last[x] >= lo:
                first[x], last[x] = min(first[x], lo), max(last[x], hi)
    return first, last


def _allocate(code, base, tag="t"):
    """Registers for the temporary digits from ``base`` on, each reused once its last reader has
    read it (a freed register is written again no sooner than the next step, whose write comes
    after the last read in the pipeline; with :data:`REUSE` off each digit keeps its own)."""
    first, last = _lifetimes(code, tag)
    starts, ends = {}, {}
    for x, p in first.items():
        starts.setdefault(p, []).append(x)
    for x, p in last.items():
        ends.setdefault(p, []).append(x)
    free, nxt, out = [], base, {}
    for pos in range(len(code)):
        for x in sorted(starts.get(pos, [])):
            if free:
                out[x] = free.pop()
            else:
                out[x], nxt = nxt, nxt + 1
        if REUSE:
            free.extend(sorted(out[x] for x in ends.get(pos, [])))
    return out


def _reads(w):
    return [w["a"], w["b"], *([w["a2"]] if w["pred"] else [])]


def _schedule(words):
    """Each step's wait before the next: a word is read ``READ_LATENCY`` cycles after the step
    that writes it, a predicate ``FLAG_LATENCY`` after its flag. A loop's body is walked through
    every iteration and its waits kept for all of them (the largest each step needs)."""
    waits = [0] * len(words)
    for _ in range(8):  # an increased wait moves the steps after it: again until nothing changes
        changed = False
        written, flagged = {}, {}
        t, prev = 0, None  # the next free issue cycle, and (position, issue) of the last step
        pos, loop_start, left = 0, None, 0
        while pos < len(words):
            w = words[pos]
            earliest = max([t] + [written[a] + READ_LATENCY for a in _reads(w) if a in written]
                           + ([flagged[w["pred"] - 1] + FLAG_LATENCY] if w["pred"] and w["pred"] - 1 in flagged else []))
            if earliest > t:
                need = earliest - prev[1] - 1
                if need > waits[prev[0]]:
                    waits[prev[0]], changed = need, True
                t = earliest
            if w["wr"] in (LO, HI):
                written[w["d"]] = t
            if w["cap"]:
                flagged[w["flag"]] = t
            prev = (pos, t)
            t += 1 + waits[pos]
            pos, loop_start, left = _next(words, pos, loop_start, left)
        if not changed:
            break
    if max(waits, default=0) > MAX_WAIT:
        raise ValueError(f"a wait of {max(waits)} cycles does not fit the step's field")
    return waits


def _next(words, pos, loop_start, left):
    """The step after ``pos``, a loop's begin and end taken: ``(pos, loop start, iterations left)``."""
    w = words[pos]
    if w["loop"] == BEGIN:
        return pos + 1, pos + 1, w["count"]
    if w["loop"] == END and left > 1:
        return loop_start, loop_start, left - 1
    return pos + 1, loop_start, left


def _cycles(words):
    """Cycles from the first step's issue to the last step's write, loops unrolled."""
    t, last, pos, loop_start, left = 0, 0, 0, None, 0
    while pos < len(words):
        last = t
        t += 1 + words[pos]["wait"]
        pos, loop_start, left = _next(words, pos, loop_start, left)
    return last + READ_LATENCY


def _acc_bits(code):
    """The accumulator's width: the largest magnitude any step can leave in it, a digit at most
    2**17 (a constant word its own)."""
    def bound(x):
        return abs(x[1]) if x[0] == "k" else 1 << DIGIT

    acc = 0
    most = 0
    for mac in code:
        a = max(bound(mac.a), bound(mac.a2) if mac.a2 is not None else 0)
        p = a * bound(mac.b)
        base = 0 if mac.acc == CLEAR else acc if mac.acc == KEEP else (acc >> DIGIT) + 1
        acc = base + p
        most = max(most, acc)
    return max(WORD + 2, (most + 1).bit_length() + 1)


# -- the core's semantics, cycle by cycle -------------------------------------------------------------


def _run(p, regs, words, ch, out_bits):
    """One routine of ``words`` on channel ``ch``: the sample's overflow flag."""
    mask, sign = (1 << WORD) - 1, 1 << (WORD - 1)
    spare = ch >= p.channels

    def physical(a):
        return a | (p.channels if spare else ch) << p.state_bits if a >= p.state_base else a

    acc, ovf, flags = 0, 0, [0] * FLAGS
    writes, caps = [], []  # in issue order: (commit cycle, address, value), (visible cycle, flag, op, bit)
    t, pos, loop_start, left = 0, 0, None, 0
    while pos < len(words):
        w = words[pos]
        while writes and writes[0][0] < t:  # written at the end of the step's fifth cycle
            _, a, v = writes.pop(0)
            regs[a] = v
        while caps and caps[0][0] <= t:
            _, f, op, bit = caps.pop(0)
            flags[f] = bit if op == SET else flags[f] | bit
        a_addr = w["a2"] if w["pred"] and flags[w["pred"] - 1] else w["a"]
        base = 0 if w["acc"] == CLEAR else acc if w["acc"] == KEEP else acc >> DIGIT
        acc = base + regs[physical(a_addr)] * regs[physical(w["b"])]
        if (acc if acc >= 0 else ~acc).bit_length() + 1 > p.acc_bits:
            raise AssertionError(f"step {pos}: the accumulator passes its {p.acc_bits} bits")
        if w["cap"]:
            bit = (acc >> 16) & 1 if w["bit16"] else int(acc < 0)
            caps.append((t + FLAG_LATENCY, w["flag"], w["cap"], bit))
            ovf |= bit if w["ovf"] else 0
        if w["wr"] in (LO, HI):
            value = acc & (RADIX - 1) if w["wr"] == LO else ((acc & mask) ^ sign) - sign
            if w["wr"] == HI and value != acc:
                raise AssertionError(f"step {pos}: the top digit {acc} does not fit 18 bits")
            if not (spare and w["d"] >= p.state_base):  # a channel past the last updates nothing
                writes.append((t + READ_LATENCY - 1, physical(w["d"]), value))
        elif w["wr"] == OUT:
            out_bits[w["d"]] = acc
        t += 1 + w["wait"]
        pos, loop_start, left = _next(words, pos, loop_start, left)
    for _, a, v in writes:
        regs[a] = v
    return ovf


def execute(program, samples, channels, *, missing=None, settings=None, registers=None):
    """Run ``program`` as the core does: every step reads the register file and the flags as they
    are at its issue (a word written ``READ_LATENCY`` cycles before, a flag ``FLAG_LATENCY``), so
    that a schedule that broke the pipeline's rules gives other integers. ``samples``: one
    ``{input: code}`` per update; ``channels``: the channel number of each; ``missing``: true
    where a sample has no measurement (the predict routine runs); ``settings``: ``{sample index:
    {shadow word: digit}}``, written to the shadow words and committed before that sample (a
    programmable program); ``registers``: a list given the register file's words at the end (the
    overflow counters are at ``counter_base``). Returns ``([{output: raw}], [overflow])``."""
    p = program
    mask, sign = (1 << WORD) - 1, 1 << (WORD - 1)
    regs = [((v & mask) ^ sign) - sign for v in p.init]
    init, update = p.routine("init"), p.routine("update")
    for ch in range(p.channels):
        _run(p, regs, init, ch, {})
    outs, flags = [], []
    for n, (sample, ch) in enumerate(zip(samples, channels, strict=True)):
        if settings and n in settings:
            for j, digit in settings[n].items():
                regs[p.shadow_base + j] = digit
            _run(p, regs, p.routine("commit"), 0, {})
        for name, dgt, a in p.sample_addrs:
            regs[a] = to_digits(int(sample[name]), p.input_digits)[dgt]
        chunks = {}
        words = p.routine("predict") if missing is not None and missing[n] else update
        ovf = _run(p, regs, words, int(ch), chunks)
        values = {}
        for j, (name, offset, width) in enumerate(p.chunks):
            values[name] = values.get(name, 0) | (chunks[j] & ((1 << width) - 1)) << offset
        result = {}
        for name in p.outputs:
            width = sum(w for n, _, w in p.chunks if n == name)
            raw = values[name]
            result[name] = raw - (((raw >> (width - 1)) & 1) << width)
        outs.append(result)
        flags.append(bool(ovf))
    if registers is not None:
        registers[:] = regs
    return outs, flags
