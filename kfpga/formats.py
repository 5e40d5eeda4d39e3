"""Default formats from range analysis: the rules every filter's points follow.

* A register (``role="register"``) covers its analysed range plus one guard bit, with the
  config's state fraction bits (8 by default), or the fraction bits its point names.
* A multiplier operand (``role="operand"``) is as wide as the embedded multiplier takes (18
  bits on Cyclone II), its integer bits covering the analysed range plus a guard bit and the
  rest fraction bits. An operand whose integer bits plus guard would leave it no fraction bit
  gives up the guard bit instead; its saturation still raises the overflow flag.
* A point that holds only constants gets no guard bit; a point ``same_as`` another shares its
  format.

All defaults round ``nearest`` (ties toward +inf) and ``saturate``.
"""

from __future__ import annotations

from kfpga.fixed import QFormat, Rounding, bits_for

__all__ = ["MULTIPLIER_BITS", "MAX_OPERAND_BITS", "STATE_FRAC_BITS", "GUARD_BITS", "register_formats"]

#: Cyclone II embedded multiplier operand width (Cyclone II Device Handbook, vol. 1, "Embedded
#: Multipliers": 18x18 or two 9x9 per block).
MULTIPLIER_BITS = 18
#: Widest operand of a product: up to 2 x 2 embedded multipliers make one product (the synthesis
#: tools split it into 18 x 18 pieces and add them; the resource report counts every piece).
MAX_OPERAND_BITS = 2 * MULTIPLIER_BITS
#: Default fraction bits of registers that are not multiplier operands.
STATE_FRAC_BITS = 8
GUARD_BITS = 1


def register_formats(spec, params, ranges, *, operand_bits=MULTIPLIER_BITS, state_frac=STATE_FRAC_BITS):
    """``{point: QFormat}`` for the points of ``spec`` that ``params`` uses, by the rules above."""
    names = list(spec.points_for(params))
    points = spec.points
    formats = {}

    def guard(name):
        return 0 if points[name].constant else GUARD_BITS

    def reach(name):
        # a point shared by others must cover all of their ranges
        return max([ranges.get(name, 0.0)] + [ranges.get(n, 0.0) for n in names if points[n].same_as == name])

    for name in names:
        point = points[name]
        if point.operand and point.same_as is None:
            need = next(i for i in range(1, 64) if QFormat(i, max(operand_bits - i, 0)).covers(reach(name)))
            g = guard(name)
            if need + g > operand_bits - 1:
                g = 0  # no room: keep the fraction bit, let saturation (flagged) cover the rest
            i = need + g
            formats[name] = QFormat(i, max(operand_bits - i, 0), Rounding.NEAREST)
    for name in names:
        point = points[name]
        if point.operand or point.same_as is not None:
            continue
        if isinstance(point.frac, str):
            frac = formats[point.frac].frac_bits if point.frac in formats else 0
        else:
            frac = state_frac if point.frac is None else point.frac
        formats[name] = QFormat(bits_for(reach(name), frac) + guard(name), frac, Rounding.NEAREST)
    for name in names:
        if points[name].same_as is not None:
            formats[name] = formats[points[name].same_as]
    return {name: formats[name] for name in names}
