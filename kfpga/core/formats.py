"""Default formats from range analysis: the rules every filter's points follow.

* A register (``role="register"``) covers its analysed range plus one guard bit, with the
  config's state fraction bits (8 by default), or the fraction bits its point names.
* A multiplier operand (``role="operand"``) is as wide as the embedded multiplier takes (18
  bits on Cyclone II), its integer bits covering the analysed range plus a guard bit and the
  rest fraction bits. An operand whose integer bits plus guard would leave it no fraction bit
  gives up the guard bit instead; its saturation still raises the overflow flag.
* A point that holds only constants gets no guard bit; a point ``same_as`` another shares its
  format.
* Noise: a point whose float error is known (the part of the filter's steady-state error there
  that the measurement noise alone causes, its floor on any signal) gets the fraction bits whose
  rounding adds at most a quarter of 1 % to that error (several roundings add up); an operand then
  grows past the multiplier width when it must (each product takes more multiplier pieces).
* Precision: every constant and reset value of the variants that apply must be held within
  :data:`PRECISION` (1 %). A register gets the fraction bits that takes; an operand, whose width
  is fixed, gives up its guard bit for them when its range allows. A value that still does not
  fit is refused when the config is checked, naming the point and the bits it needs.

All defaults round ``nearest`` (ties toward +inf) and ``saturate``.
"""

from __future__ import annotations

import math

from kfpga.core.fixed import QFormat, Rounding, bits_for, to_raw

__all__ = ["MULTIPLIER_BITS", "MAX_OPERAND_BITS", "STATE_FRAC_BITS", "GUARD_BITS", "PRECISION", "register_formats",
           "precision_frac_bits", "precision_needs", "noise_frac_bits", "noise_step_frac"]

#: Cyclone II embedded multiplier operand width (Cyclone II Device Handbook, vol. 1, "Embedded
#: Multipliers": 18x18 or two 9x9 per block).
MULTIPLIER_BITS = 18
#: Widest operand of a product: up to 2 x 2 embedded multipliers make one product (the synthesis
#: tools split it into 18 x 18 pieces and add them; the resource report counts every piece).
MAX_OPERAND_BITS = 2 * MULTIPLIER_BITS
#: Default fraction bits of registers that are not multiplier operands.
STATE_FRAC_BITS = 8
GUARD_BITS = 1
#: The largest relative error a constant or reset value may get from its format.
PRECISION = 0.01


def precision_frac_bits(value, rounding=Rounding.NEAREST):
    """The fewest fraction bits that hold ``value`` (nonzero) within :data:`PRECISION`."""
    for frac in range(200):
        fmt = QFormat(max(bits_for(abs(value), frac), 1), frac, rounding)
        raw, _ = to_raw(value, fmt)
        if raw != 0 and abs(raw * fmt.lsb - value) <= PRECISION * abs(value):
            return frac
    raise ValueError(f"no format holds {value!r}")


def noise_frac_bits(variance):
    """Fraction bits an innovation needs so that its step is at most a quarter of the standard
    deviation of the observation noise it carries (variance ``R``, in codes squared); else the
    rounding of the innovation, not the noise, sets the error (R = 0.01: steps of 0.025 codes).
    Variances of 16 and more need none."""
    return math.ceil(math.log2(4.0 / math.sqrt(variance))) if variance < 16.0 else 0


def precision_needs(spec, params):
    """``{point: fraction bits}`` the nonzero constants and reset values of the variants that
    apply to ``params`` need (:func:`precision_frac_bits`)."""
    from kfpga.core.spec import Constant

    needs = {}
    for variant in spec.variants.values():
        if variant.applies(params):
            continue
        points = dict(variant.state_for(params))
        values = [(c.point, c.value) for c in variant.constants(params).values() if isinstance(c, Constant)]
        values += [(points[name], value) for name, value in variant.initial(params).items()]
        values += [(point, value) for _, value, point in variant.settled(params)]
        for point, value in values:
            if isinstance(point, str) and value != 0:
                needs[point] = max(needs.get(point, 0), precision_frac_bits(value))
    return needs


def noise_step_frac(sigma, budget=PRECISION):
    """The fewest fraction bits whose rounding noise (rms step/sqrt(12)) adds at most ``budget``
    to an error of rms ``sigma`` it is uncorrelated with: step/sqrt(12) <= sqrt((1+b)^2 - 1) sigma."""
    limit = math.sqrt((1.0 + budget) ** 2 - 1.0) * sigma * math.sqrt(12.0)
    return max(0, math.ceil(-math.log2(limit))) if limit > 0 else 0


def register_formats(spec, params, ranges, *, operand_bits=MULTIPLIER_BITS, state_frac=STATE_FRAC_BITS,
                     noise=None):
    """``{point: QFormat}`` for the points of ``spec`` that ``params`` uses, by the rules above.

    ``noise``: ``{register point: rms error of the float filter there}``; such a register also
    gets the fraction bits whose rounding adds at most 1 % to that error (:func:`noise_step_frac`).
    """
    names = list(spec.points_for(params))
    points = spec.points
    formats = {}

    def guard(name):
        return 0 if points[name].constant else GUARD_BITS

    def reach(name):
        # a point shared by others must cover all of their ranges
        return max([ranges.get(name, 0.0)] + [ranges.get(n, 0.0) for n in names if points[n].same_as == name])

    needs = precision_needs(spec, params)
    noisy = {}  # an operand may grow past the multiplier width for these (more pieces per product)
    for name, sigma in (noise or {}).items():
        if name in names and sigma and sigma > 0:
            # a quarter of the budget each: several roundings add up in one output
            noisy[name] = noise_step_frac(sigma, PRECISION / 4)
            needs[name] = max(needs.get(name, 0), noisy[name])

    def precise(name):
        # the fraction bits of this point and of the points that share its format
        return max([needs.get(name, 0)] + [needs.get(n, 0) for n in names if points[n].same_as == name])

    for name in names:
        point = points[name]
        if point.operand and point.same_as is None:
            need = next(i for i in range(1, 64) if QFormat(i, max(operand_bits - i, 0)).covers(reach(name)))
            g = guard(name)
            if need + g > operand_bits - 1 or operand_bits - need - g < precise(name):
                g = 0  # no room: keep the fraction bits, let saturation (flagged) cover the rest
            i = need + g
            frac = max(operand_bits - i, 0)
            if noisy.get(name, 0) > frac:
                frac = min(noisy[name], MAX_OPERAND_BITS - i)
            formats[name] = QFormat(i, frac, Rounding.NEAREST)
    for name in names:
        point = points[name]
        if point.operand or point.same_as is not None:
            continue
        if isinstance(point.frac, str):
            frac = formats[point.frac].frac_bits if point.frac in formats else 0
        else:
            frac = state_frac if point.frac is None else point.frac
        frac = max(frac, precise(name))
        formats[name] = QFormat(bits_for(reach(name), frac) + guard(name), frac, Rounding.NEAREST)
    for name in names:
        if points[name].same_as is not None:
            formats[name] = formats[points[name].same_as]
    return {name: formats[name] for name in names}
