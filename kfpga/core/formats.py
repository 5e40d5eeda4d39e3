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
* Precision: every constant and reset value of the variants that apply is held within
  :data:`PRECISION` (1 %) by its default format. A register gets the fraction bits that takes;
  an operand first gives up its guard bit for them, then grows past the multiplier width (each
  product then takes more multiplier pieces), past the word budget too if it must. A format the
  user pins is checked instead, and refused naming the point and the bits it needs.
* The word budget (``max_word``, :data:`MAX_WORD` = 36 bits by default, two 18-bit multiplier
  pieces): what the noise rules above may grow an operand to. Where an exact sum or product of
  the update would be wider, each cast point in it (:meth:`~kfpga.core.ops.Ops.cast`: a product a
  filter lets be rounded before it enters a sum) gets a format (:func:`cast_formats`): its
  analysed range plus a guard bit, and :data:`CAST_GUARD` more fraction bits than the point its
  sum is written into, within the budget. Nothing is refused for width: a wider value stays
  exact, in the model and in the RTL.
* A point that holds only constants (an entry of F, 1/T) is an operand as above, with at least
  the fraction bits that leave its smallest constant :data:`CONSTANT_BITS` significant bits,
  whatever its size (0.01 and 5e-5 alike). A constant costs its significant bits only (its
  leading sign copies are not built), so a small constant with many fraction bits is still one
  narrow multiplier operand.

All defaults round ``nearest`` (ties toward +inf) and ``saturate``.
"""

from __future__ import annotations

import math
from fractions import Fraction

from kfpga.core.fixed import QFormat, Rounding, bits_for, to_raw

__all__ = ["MULTIPLIER_BITS", "MAX_WORD", "CAST_GUARD", "cast_formats",
           "STATE_FRAC_BITS", "GUARD_BITS", "PRECISION", "register_formats",
           "precision_frac_bits", "precision_needs", "noise_frac_bits", "noise_step_frac", "constant_frac_bits",
           "significant_bits", "constant_values", "COVARIANCE_GUARD", "covariance_frac"]

#: Cyclone II embedded multiplier operand width (Cyclone II Device Handbook, vol. 1, "Embedded
#: Multipliers": 18x18 or two 9x9 per block).
MULTIPLIER_BITS = 18
#: The default word budget (``[formats] max_word``): two 18-bit multiplier pieces. The widest an
#: operand grows for noise, and the widest exact sum or product before its cast points get formats
#: (the synthesis tools split a wider product into 18 x 18 pieces; the resource report counts each).
MAX_WORD = 2 * MULTIPLIER_BITS
#: Fraction bits a cast gets beyond the point its sum is written into: the roundings of up to
#: eight terms then add at most a quarter of that point's LSB (rms far less).
CAST_GUARD = 4
#: Default fraction bits of registers that are not multiplier operands.
STATE_FRAC_BITS = 8
GUARD_BITS = 1
#: The largest relative error a constant or reset value may get from its format.
PRECISION = 0.01
#: Fraction bits a predicted covariance that feeds the gain's division gets beyond what its
#: settled values need, when those already take it past the multiplier's width: the recursion
#: P -> Pl -> K -> P adds up its roundings (measured over T = 0.001 .. 8 on 2- and 3-state models;
#: within the multiplier's width the operand's own fraction bits suffice).
COVARIANCE_GUARD = 3


def covariance_frac(fmt, max_word=MAX_WORD):
    """The fraction bits of a predicted covariance operand ``fmt`` with :data:`COVARIANCE_GUARD`
    (within the word budget; never fewer than it has)."""
    if fmt.width <= MULTIPLIER_BITS:
        return fmt.frac_bits
    if fmt.width >= max_word:  # past the budget already, for the precision its values need: so is the guard
        return fmt.frac_bits + COVARIANCE_GUARD
    return min(fmt.frac_bits + COVARIANCE_GUARD, max_word - fmt.int_bits)


#: Significant bits every constant keeps at least by default: as many as the multiplier's operand
#: holds, so that a small constant is as precise as a large one (0.01 and 5e-5 alike). A constant
#: of F is the model itself: its error is a bias every update adds, which a slow filter's small
#: gains correct late (a relative error of 2**-11 in F's T cost 1.5 % of RMSE at T = 0.001 s).
CONSTANT_BITS = MULTIPLIER_BITS - 1


def precision_frac_bits(value, rounding=Rounding.NEAREST, precision=PRECISION):
    """The fewest fraction bits that hold ``value`` (nonzero) within ``precision``."""
    for frac in range(200):
        fmt = QFormat(max(bits_for(abs(value), frac), 1), frac, rounding)
        raw, _ = to_raw(value, fmt)
        if raw != 0 and abs(raw * fmt.lsb - value) <= precision * abs(value):
            return frac
    raise ValueError(f"no format holds {value!r}")


def noise_frac_bits(variance):
    """Fraction bits an innovation needs so that its step is at most a quarter of the standard
    deviation of the observation noise it carries (variance ``R``, in codes squared); else the
    rounding of the innovation, not the noise, sets the error (R = 0.01: steps of 0.025 codes).
    Variances of 16 and more need none."""
    return math.ceil(math.log2(4.0 / math.sqrt(variance))) if variance < 16.0 else 0


def constant_frac_bits(value, bits=MULTIPLIER_BITS):
    """The most fraction bits that keep the nonzero ``value`` within a signed ``bits``-bit integer
    (at least 0): its significant bits fill the multiplier's operand."""
    return max(0, bits - 2 - math.floor(math.log2(abs(value))))


def significant_bits(raw):
    """Bits of the signed integer ``raw`` without its redundant sign copies (the width a constant
    costs in the datapath)."""
    raw = int(raw)
    return (raw if raw >= 0 else ~raw).bit_length() + 1


def constant_values(spec, params):
    """``{point: [nonzero constant values]}`` of the variants that apply to ``params``."""
    from kfpga.core.spec import Constant

    out = {}
    for variant in spec.model.variants.values():
        if variant.applies(params):
            continue
        for c in variant.constants(params).values():
            if isinstance(c, Constant) and isinstance(c.point, str) and c.value != 0:
                out.setdefault(c.point, []).append(c.value)
    return out


def precision_needs(spec, params):
    """``{point: fraction bits}`` the nonzero constants and reset values of the variants that
    apply to ``params`` need (:func:`precision_frac_bits`)."""
    from kfpga.core.spec import Constant

    needs = {}
    for variant in spec.model.variants.values():
        if variant.applies(params):
            continue
        points = dict(variant.state_for(params))
        values = [(c.point, c.value) for c in variant.constants(params).values() if isinstance(c, Constant)]
        values += [(points[name], value) for name, value in variant.initial(params).items()]
        settled = [(point, value) for _, value, point in variant.settled(params)]
        for point, value in values + settled:
            if isinstance(point, str) and value != 0:
                needs[point] = max(needs.get(point, 0), precision_frac_bits(value))
        # the covariance a time-varying gain settles to sets the gain every update: held four
        # times finer than the constants (and see COVARIANCE_GUARD)
        for point, value in settled:
            if isinstance(point, str) and value != 0:
                needs[point] = max(needs[point], precision_frac_bits(value, precision=PRECISION / 4))
    return needs


def noise_step_frac(sigma, budget=PRECISION):
    """The fewest fraction bits whose rounding noise (rms step/sqrt(12)) adds at most ``budget``
    to an error of rms ``sigma`` it is uncorrelated with: step/sqrt(12) <= sqrt((1+b)^2 - 1) sigma."""
    limit = math.sqrt((1.0 + budget) ** 2 - 1.0) * sigma * math.sqrt(12.0)
    return max(0, math.ceil(-math.log2(limit))) if limit > 0 else 0


def _operand_format(point, reach, guard, precise, noisy, constants, operand_bits, max_word):
    """A multiplier operand's default format (the rules of the module docstring)."""
    if point.constant and constants:
        # the operand's fraction bits, more if its smallest constant would keep fewer than
        # CONSTANT_BITS significant bits (a small constant stays narrow: its sign copies are not built)
        top = max(abs(c) for c in constants)
        i = next(i for i in range(1, 64) if QFormat(i, max(operand_bits - i, 0)).covers(top))
        frac = max(operand_bits - i, min(constant_frac_bits(c, CONSTANT_BITS + 1) for c in constants), precise)
        return QFormat(i, frac, Rounding.NEAREST)
    need = next(i for i in range(1, 64) if QFormat(i, max(operand_bits - i, 0)).covers(reach))
    g = guard
    if need + g > operand_bits - 1 or operand_bits - need - g < precise:
        g = 0  # no room: keep the fraction bits, let saturation (flagged) cover the rest
    i = need + g
    frac = max(operand_bits - i, 0)
    if max(noisy, precise) > frac:
        # more multiplier pieces per product: for noise within the word budget, for precision
        # (the model itself: its constants, reset and settled values) past it if it must
        frac = max(min(noisy, max_word - i), precise, frac)
    return QFormat(i, frac, Rounding.NEAREST)


def register_formats(spec, params, ranges, *, operand_bits=MULTIPLIER_BITS, state_frac=STATE_FRAC_BITS,
                     noise=None, max_word=MAX_WORD):
    """``{point: QFormat}`` for the points of ``spec`` that ``params`` uses, by the rules above
    (the cast points left out: :func:`cast_formats` gives them theirs).

    ``noise``: ``{register point: rms error of the float filter there}``; such a register also
    gets the fraction bits whose rounding adds at most 1 % to that error (:func:`noise_step_frac`).
    """
    points = spec.model.points
    names = [name for name in spec.points_for(params) if not points[name].cast]
    formats = {}
    guard = {name: 0 if points[name].constant else GUARD_BITS for name in names}
    sharers = {name: [n for n in names if points[n].same_as == name] for name in names}
    # a point shared by others must cover all of their ranges
    reach = {name: max([ranges.get(name, 0.0)] + [ranges.get(n, 0.0) for n in sharers[name]]) for name in names}
    needs = precision_needs(spec, params)
    noisy = {}  # an operand may grow past the multiplier width for these (more pieces per product)
    for name, sigma in (noise or {}).items():
        if name in names and sigma and sigma > 0:
            # a quarter of the budget each: several roundings add up in one output
            noisy[name] = noise_step_frac(sigma, PRECISION / 4)
            needs[name] = max(needs.get(name, 0), noisy[name])
    # the fraction bits of each point and of the points that share its format
    precise = {name: max([needs.get(name, 0)] + [needs.get(n, 0) for n in sharers[name]]) for name in names}
    constants = constant_values(spec, params)
    for name in names:
        point = points[name]
        if point.operand and point.same_as is None:
            formats[name] = _operand_format(point, reach[name], guard[name], precise[name], noisy.get(name, 0),
                                            constants.get(name, ()), operand_bits, max_word)
    for name in names:
        point = points[name]
        if point.operand or point.same_as is not None:
            continue
        if isinstance(point.frac, str):
            frac = formats[point.frac].frac_bits if point.frac in formats else 0
        else:
            frac = state_frac if point.frac is None else point.frac
        frac = max(frac, precise[name])
        formats[name] = QFormat(bits_for(reach[name], frac) + guard[name], frac, Rounding.NEAREST)
    for name in names:
        if points[name].same_as is not None:
            formats[name] = formats[points[name].same_as]
    return {name: formats[name] for name in names}


def _cast_format(exact, bounds, max_word):
    """The default format of a cast point: ``exact`` its :class:`~kfpga.core.ops.ExactCast`, ``bounds``
    the interval of its exact value (the rules of the module docstring: it never overflows)."""
    target = exact.into_format.frac_bits if exact.into_format is not None else exact.frac
    frac = max(0, min(exact.frac, target + CAST_GUARD))

    def int_bits(frac):  # the bits the interval takes once rounded to ``frac`` (nearest: half an LSB more)
        reach = max(abs(bounds[0]), abs(bounds[1])) + Fraction(1, 1 << (frac + 1))
        return next(i for i in range(1, 4096) if QFormat(i, frac).max_raw >= reach * (1 << frac))

    i = int_bits(frac)
    if i + frac > max_word:
        frac = max(0, min(exact.frac, target), max_word - i)  # the guard gives way first, never the target's bits
        i = int_bits(frac)
    return QFormat(i, frac, Rounding.NEAREST)


def cast_formats(spec, params, formats, ranges, *, max_word=MAX_WORD, input_format, keep=()):
    """``{cast point: QFormat}`` for the cast points that an exact sum or product wider than
    ``max_word`` holds, in any variant that applies (``formats``: every other point's; ``keep``: the
    cast points the config pins, with a format or exact, which this leaves as they are). Its
    integer bits cover every value the formats before it can give (``ranges`` is not needed:
    a cast is a rounding inside a sum, and never saturates).

    A cast narrows the sum it enters, which may narrow the sums after it: the update is measured
    again with the casts so far until no wide intermediate holds an exact cast point.
    """
    from kfpga.core.compiled import cast_bounds
    from kfpga.core.ops import update_widths

    casts = {}
    variants = [name for name, v in spec.model.variants.items() if v.applies(params) is None]
    for _ in range(len(spec.model.points) + 1):
        wanted, bounds = {}, {}
        for variant in variants:
            current = {**formats, **casts}
            report = update_widths(spec, params, current, variant, input_format)
            for wide in report.past(max_word):
                for point in wide.casts - set(casts) - set(keep):
                    if report.exact_casts[point].into is not None:  # else nothing writes it: not built
                        wanted.setdefault(point, report.exact_casts[point])
            for point, (lo, hi) in cast_bounds(spec, params, current, variant, input_format).items():
                old = bounds.get(point, (lo, hi))
                bounds[point] = (min(lo, old[0]), max(hi, old[1]))
        if not wanted:
            break
        casts.update({point: _cast_format(exact, bounds[point], max_word) for point, exact in sorted(wanted.items())})
    return casts
