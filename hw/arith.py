"""Amaranth forms of the model's integer operations (``kfpga.fixed``), for bit-exact RTL.

Each helper builds exactly the integer function of its model counterpart: ``requantize`` drops
fraction bits with the format's rounding (an arithmetic shift, after adding half an LSB for
``half_up``) and saturates (or wraps) into the format's width, raising a flag on overflow. The
sums feeding it are formed at full width (Amaranth widens ``+`` and ``*``), so nothing wraps
before the one explicit quantisation.
"""

from __future__ import annotations

from amaranth import Cat, Const, Mux, Signal, signed

from kfpga.fixed import Overflow, Rounding

__all__ = ["align_sum", "requantize"]


def align_sum(terms, fracs, sub=False):
    """Exact sum (or ``a - b`` with ``sub``) of signed values with different fraction bits.

    Returns ``(value, frac)``; each term is shifted left to the largest fraction count.
    """
    frac = max(fracs)
    shifted = [t.as_signed() << (frac - f) if frac != f else t.as_signed() for t, f in zip(terms, fracs, strict=True)]
    if sub:
        a, b = shifted
        return a - b, frac
    total = shifted[0]
    for t in shifted[1:]:
        total = total + t
    return total, frac


def requantize(m, value, src_frac, fmt, *, name):
    """Write ``value * 2**-src_frac`` into ``fmt``: returns ``(result, overflowed)`` signals.

    ``result`` is a ``signed(fmt.width)`` signal and ``overflowed`` a 1-bit signal, both driven
    combinationally in ``m``. Overflow is detected from the bits above the target width (all
    equal to the sign bit, or not), which is cheaper and shallower than a magnitude compare.
    """
    value = value.as_signed()
    shift = src_frac - fmt.frac_bits
    if shift > 0:
        if fmt.rounding is Rounding.HALF_UP:
            value = value + Const(1 << (shift - 1), signed(shift + 1))
        value = value >> shift  # arithmetic: value is signed
    elif shift < 0:
        value = value << -shift
    rounded = Signal(signed(max(len(value), fmt.width)), name=f"{name}_rounded")
    m.d.comb += rounded.eq(value)
    result = Signal(signed(fmt.width), name=name)
    overflowed = Signal(name=f"{name}_ovf")
    w = fmt.width
    if len(rounded) == w:
        m.d.comb += [result.eq(rounded), overflowed.eq(0)]
        return result, overflowed
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
