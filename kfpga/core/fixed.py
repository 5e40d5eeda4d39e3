"""The fixed-point format type and the integer quantisation rules shared by model and RTL.

A value in format ``Q(i, f)`` is a signed two's-complement integer ``raw`` of ``i + f`` bits
(``i`` integer bits including the sign, ``f`` fraction bits) that stands for ``raw * 2**-f``.

Every quantisation point of the datapath is a :class:`QFormat`: the format plus the rounding
rule used when fraction bits are dropped and the overflow rule used when the result does not
fit. :func:`requantise` applies both to exact integers; ``hw/arith.py`` builds the same
operation in Amaranth and ``kfpga/core/compiled.py`` writes it into the model's compiled loops, so
the model and the RTL produce identical integers.

The functions accept Python ``int`` (arbitrary precision), numpy ``int64`` arrays, or numpy arrays
of Python ints (``dtype=object``: a batch whose intermediates pass int64). They are
written with shifts and compares instead of ``np.round`` (ties to even) or fxpmath (2000x
slower in a sample loop) so that the rounding is exactly the hardware's: every rule adds a
constant below one LSB (:func:`round_addend`, which for some rules depends on the sign or on the
bit that becomes the LSB) and then shifts right arithmetically.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

__all__ = ["Rounding", "Overflow", "QFormat", "round_addend", "shift_round", "requantise", "to_raw", "bits_for"]

class Rounding(StrEnum):
    """How fraction bits are dropped, named as MATLAB's fixed-point tools name them.

    ``half_up`` is accepted as another name of ``nearest``.
    """

    #: To nearest, ties toward plus infinity: add half an LSB, then shift right.
    NEAREST = "nearest"
    #: To nearest, ties away from zero.
    ROUND = "round"
    #: To nearest, ties to even (the LSB of the result 0).
    CONVERGENT = "convergent"
    #: Toward minus infinity: an arithmetic right shift.
    FLOOR = "floor"
    #: Toward zero.
    FIX = "fix"
    #: The earlier name of ``nearest``.
    HALF_UP = "nearest"

    @classmethod
    def _missing_(cls, value):
        return cls.NEAREST if value == "half_up" else None


class Overflow(StrEnum):
    """What happens when a value does not fit the format."""

    #: Clamp to the most positive / most negative value (the overflow flag is raised).
    SATURATE = "saturate"
    #: Keep the low bits, as two's-complement hardware does (the overflow flag is raised).
    WRAP = "wrap"


_QSTR = re.compile(r"^\s*[sS]?[qQ]\s*(-?\d+)\s*\.\s*(-?\d+)\s*$")


@dataclass(frozen=True)
class QFormat:
    """A signed fixed-point format with its rounding and overflow rules.

    Parameters
    ----------
    int_bits:
        Integer bits, the sign bit included (``>= 1``).
    frac_bits:
        Fraction bits (``>= 0``).
    rounding:
        Rule applied when a value with more fraction bits is written into this format.
    overflow:
        Rule applied when the rounded value is outside the representable range.
    """

    int_bits: int
    frac_bits: int
    rounding: Rounding = Rounding.FLOOR
    overflow: Overflow = Overflow.SATURATE

    def __post_init__(self):
        if not isinstance(self.int_bits, int) or isinstance(self.int_bits, bool) or self.int_bits < 1:
            raise ValueError(f"int_bits must be an integer >= 1 (the sign bit counts), not {self.int_bits!r}")
        if not isinstance(self.frac_bits, int) or isinstance(self.frac_bits, bool) or self.frac_bits < 0:
            raise ValueError(f"frac_bits must be an integer >= 0, not {self.frac_bits!r}")
        try:
            object.__setattr__(self, "rounding", Rounding(self.rounding))
        except ValueError:
            choices = ", ".join(r.value for r in Rounding)
            raise ValueError(f"rounding must be one of {choices} (half_up: nearest), not {self.rounding!r}") from None
        try:
            object.__setattr__(self, "overflow", Overflow(self.overflow))
        except ValueError:
            choices = ", ".join(o.value for o in Overflow)
            raise ValueError(f"overflow must be one of {choices}, not {self.overflow!r}") from None

    @classmethod
    def parse(cls, text, *, rounding=Rounding.FLOOR, overflow=Overflow.SATURATE):
        """Build a format from ``"Q<int>.<frac>"`` (e.g. ``"Q18.8"``)."""
        match = _QSTR.match(str(text))
        if not match:
            raise ValueError(f"format must look like 'Q18.8' (integer bits incl. sign . fraction bits), not {text!r}")
        return cls(int(match[1]), int(match[2]), rounding, overflow)

    @property
    def width(self):
        """Total bits."""
        return self.int_bits + self.frac_bits

    @property
    def min_raw(self):
        return -(1 << (self.width - 1))

    @property
    def max_raw(self):
        return (1 << (self.width - 1)) - 1

    @property
    def lsb(self):
        """Weight of one LSB."""
        return 2.0 ** -self.frac_bits

    @property
    def min_value(self):
        return self.min_raw * self.lsb

    @property
    def max_value(self):
        return self.max_raw * self.lsb

    def covers(self, magnitude):
        """Whether every value in ``[-magnitude, magnitude]`` is representable."""
        return magnitude <= self.max_value

    def with_rules(self, *, rounding=None, overflow=None):
        return QFormat(self.int_bits, self.frac_bits, rounding or self.rounding, overflow or self.overflow)

    def to_float(self, raw):
        """Real value of raw integer(s)."""
        return np.asarray(raw, dtype=np.float64) * self.lsb

    def __str__(self):
        return f"Q{self.int_bits}.{self.frac_bits}"


def bits_for(magnitude, frac_bits):
    """Fewest integer bits (sign included) with which ``Q(i, frac_bits)`` covers ``±magnitude``."""
    i = 1
    while QFormat(i, frac_bits).max_value < magnitude:
        i += 1
    return i


def round_addend(raw, shift, rounding):
    """What ``rounding`` adds to ``raw`` before an arithmetic right shift by ``shift > 0``.

    With ``h = 2**(shift-1)`` (half an LSB of the result): ``floor`` 0; ``nearest`` h; ``round``
    h, less one for a negative ``raw`` (a negative tie then stays below the next integer);
    ``convergent`` h - 1, plus one when the bit that becomes the LSB is 1 (a tie then goes to
    the even neighbour); ``fix`` ``2**shift - 1`` for a negative ``raw`` (floor of a negative value
    plus almost one LSB is its truncation toward zero). The RTL builds the same addends from
    the sign bit and bit ``shift`` (``hw/arith.py``).
    """
    rounding = Rounding(rounding)
    half = 1 << (shift - 1)
    if rounding is Rounding.FLOOR:
        return 0
    if rounding is Rounding.NEAREST:
        return half
    negative = raw < 0
    if rounding is Rounding.ROUND:
        return half - negative
    if rounding is Rounding.CONVERGENT:
        return half - 1 + ((raw >> shift) & 1)
    return negative * ((1 << shift) - 1)  # FIX


def shift_round(raw, shift, rounding):
    """Drop ``shift`` fraction bits of ``raw`` (int or int64 array) with ``rounding``.

    A negative ``shift`` appends zero fraction bits, which is exact.
    """
    if shift <= 0:
        return raw << -shift
    return (raw + round_addend(raw, shift, rounding)) >> shift


def requantise(raw, src_frac, fmt):
    """Write the exact value ``raw * 2**-src_frac`` into ``fmt``.

    Returns ``(raw_out, overflowed)``; for arrays, ``overflowed`` is a boolean array.
    """
    value = shift_round(raw, src_frac - fmt.frac_bits, fmt.rounding)
    lo, hi = fmt.min_raw, fmt.max_raw
    if isinstance(value, np.ndarray):
        flag = (value > hi) | (value < lo)
        if fmt.overflow is Overflow.SATURATE:
            return np.clip(value, lo, hi), flag
        return ((value - lo) & ((1 << fmt.width) - 1)) + lo, flag
    if lo <= value <= hi:
        return value, False
    if fmt.overflow is Overflow.SATURATE:
        return (hi if value > hi else lo), True
    return ((value - lo) & ((1 << fmt.width) - 1)) + lo, True


def to_raw(value, fmt):
    """Quantise real value(s) into ``fmt`` (rounding and overflow rules of ``fmt``).

    Works exactly for any finite float: the float is first expressed as an integer number of
    ``2**-(fmt.frac_bits + 60)`` units (floats carry 53 significant bits, so nothing is lost
    for values within the format's range) and then requantised.
    """
    guard = 60
    if np.ndim(value) == 0:
        v = float(value)
        if not np.isfinite(v):
            raise ValueError(f"cannot quantise {value!r} into {fmt}")
        exact = int(np.floor(v * 2.0 ** (fmt.frac_bits + guard)))
        # floor() of an already-integral scaled float is exact; any sub-unit part is far below
        # the rounding position, so floor here never changes the result of the final rounding
        return requantise(exact, fmt.frac_bits + guard, fmt)
    out = [to_raw(v, fmt) for v in np.ravel(value)]
    raws = np.array([r for r, _ in out], dtype=np.int64).reshape(np.shape(value))
    flags = np.array([f for _, f in out], dtype=bool).reshape(np.shape(value))
    return raws, flags
