"""The Amaranth backend of the operations layer: a filter's stage functions built as RTL.

:class:`AmaranthOps` runs the same stage functions as the model (``kfpga/core/ops.py``) and builds
their combinational logic in a module. The alignment and multiplier rules come from
:class:`~kfpga.core.ops.Ops`; this module supplies Amaranth's operators and :func:`requantise`, the
one place where bits are dropped. Amaranth widens ``+``, ``-`` and ``*`` to hold every result,
so nothing wraps before the explicit quantisation, which saturates (or wraps) and raises a
flag exactly as :func:`kfpga.core.fixed.requantise` does.
"""

from __future__ import annotations

from functools import reduce

from amaranth import Cat, Const, Mux, Signal, signed

from kfpga.core.fixed import Overflow, Rounding
from kfpga.core.ops import Ops, const_width

__all__ = ["AmaranthOps", "any_flag", "live_flags", "requantise"]

#: The flag of a write that cannot overflow: a constant, so that no register, OR gate or output
#: bit is built for it (a register that always holds 0 is logic no test can check).
NO_OVERFLOW = Const(0, 1)


def live_flags(flags):
    """The flags that can be 1: every one but the constant 0s."""
    return [f for f in flags if not (isinstance(f, Const) and f.value == 0)]


def any_flag(flags):
    """The OR of ``flags``, without the constant 0s (:data:`NO_OVERFLOW` when none is left)."""
    live = live_flags(flags)
    return reduce(lambda a, b: a | b, live) if live else NO_OVERFLOW


def _round_addend(value, shift, rounding):
    """:func:`kfpga.core.fixed.round_addend` in bits: an unsigned ``shift``-bit addend (``None``: 0).

    ``h = 2**(shift-1)`` is ``1`` then ``shift-1`` zeros; ``h - 1`` is ``0`` then ones; so ``round``'s
    ``h - sign`` is ``~sign`` then copies of ``sign``, ``convergent``'s ``h - 1 + b`` is ``b`` then
    copies of ``~b`` (``b`` the bit that becomes the LSB), and ``fix``'s addend is ``shift`` copies of
    the sign: no adder beyond the one every rounding rule needs.
    """
    rounding = Rounding(rounding)
    sign = value[-1]
    low = shift - 1
    if rounding is Rounding.FLOOR:
        return None
    if rounding is Rounding.NEAREST:
        return Const(1 << low, shift)
    if rounding is Rounding.ROUND:
        return Cat(sign.replicate(low), ~sign)
    if rounding is Rounding.CONVERGENT:
        b = value[shift] if shift < len(value) else sign
        return Cat((~b).replicate(low), b)
    return sign.replicate(shift)  # FIX


def requantise(m, value, src_frac, fmt, *, name, cannot_overflow=False):
    """Write ``value * 2**-src_frac`` into ``fmt``: returns ``(result, overflowed)`` signals.

    ``result`` is a ``signed(fmt.width)`` signal, driven combinationally in ``m``, and
    ``overflowed`` a 1-bit signal, or :data:`NO_OVERFLOW` when the write cannot overflow.
    Overflow is detected from the bits above the target width (all equal to the sign bit, or
    not), which is cheaper and shallower than a magnitude compare. ``cannot_overflow``: the
    value always fits (the model's interval analysis says so): no saturation, and the flag is
    :data:`NO_OVERFLOW`.
    """
    value = value.as_signed()
    shift = src_frac - fmt.frac_bits
    # shift_left/shift_right, not << and >>: with an int amount those build a variable shift,
    # as wide as the largest shift its amount's bits could give
    if shift > 0:
        addend = _round_addend(value, shift, fmt.rounding)
        if addend is not None:
            value = value + addend
        value = value.shift_right(shift)  # arithmetic: value is signed
    elif shift < 0:
        value = value.shift_left(-shift)
    rounded = Signal(signed(max(len(value), fmt.width)), name=f"{name}_rounded")
    m.d.comb += rounded.eq(value)
    result = Signal(signed(fmt.width), name=name)
    w = fmt.width
    if len(rounded) == w or cannot_overflow:
        m.d.comb += result.eq(rounded[:w])
        return result, NO_OVERFLOW
    overflowed = Signal(name=f"{name}_ovf")
    # the value fits iff bits [w-1:] are all equal (all copies of the sign bit)
    top = rounded[w - 1:]
    sign = rounded[-1]
    positive_overflow = ~sign & top.any()
    negative_overflow = sign & ~top.all()
    m.d.comb += overflowed.eq(positive_overflow | negative_overflow)
    if fmt.overflow is Overflow.SATURATE:
        max_raw = Const(fmt.max_raw, signed(w))
        min_raw = Const(fmt.min_raw, signed(w))
        m.d.comb += result.eq(Mux(positive_overflow, max_raw, Mux(negative_overflow, min_raw, rounded[:w])))
    else:
        m.d.comb += result.eq(Cat(rounded[:w]))  # wrap: keep the low bits
    return result, overflowed


class AmaranthOps(Ops):
    """Build a stage's combinational logic in ``m``; values are signed Amaranth values.

    Parameters
    ----------
    m:
        The module the logic goes into.
    formats:
        The config's ``{point: QFormat}``.
    prefix:
        Prepended to every signal name (to tell pipeline stages or channels apart).
    overflow_sites:
        The names of the writes that can overflow (the model's interval analysis, the kernel's
        ``sites``); the others get no saturation logic and no flag. ``None``: every write can.
    """

    def __init__(self, m, formats, *, prefix="", overflow_sites=None):
        super().__init__(formats)
        self.m = m
        self.prefix = prefix
        self.overflow_sites = overflow_sites

    def _input(self, raw, fmt, name):
        return raw.as_signed()

    def _const(self, raw, fmt, value, name):
        return Const(raw, signed(const_width(raw, fmt)))

    def _zero(self):
        return Const(0, signed(1))

    def _shl(self, raw, n):
        return raw.shift_left(n)  # a constant shift, n bits wider (``<<`` by an int is a variable shift)

    def _abs(self, x):
        return Mux(x < 0, -x, x)  # -x is one bit wider: the most negative value stays exact

    def _lt(self, x, y):
        return x < y  # both signed: a signed comparison

    def _mux(self, cond, x, y):
        return Mux(cond, x, y)

    def _rq(self, raw, src_frac, fmt, name):
        safe = self.overflow_sites is not None and name not in self.overflow_sites
        return requantise(self.m, raw, src_frac, fmt, name=f"{self.prefix}{name}", cannot_overflow=safe)

    def _div(self, num, den, shift, fmt, name):
        raise NotImplementedError(
            f"{name}: a division is sequential; the core instantiates hw/divider.Divider and feeds it "
            "with divider_operands()")

    def _sqrt(self, raw, shift, fmt, name):
        raise NotImplementedError(f"{name}: a square root is sequential; the core instantiates its square-root unit")

    def _any(self, flags):
        if not live_flags(flags):
            return NO_OVERFLOW
        flag = Signal(name=f"{self.prefix}overflow_any")
        self.m.d.comb += flag.eq(any_flag(flags))
        return flag

    def hold(self, value, name):
        """A register holding ``value`` (an :class:`~kfpga.core.ops.Fx`): ``(Fx of the register, its .eq)``.

        The core decides when the assignment happens (which FSM state, which enable).
        """
        reg = Signal(signed(len(value.raw)), name=f"{self.prefix}{name}")
        held = type(value)(reg, value.frac, value.const, value.fmt, name)
        return held, reg.eq(value.raw)
