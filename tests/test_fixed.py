"""The format type and the quantisation rules: pinned by tables, cross-checked with fxpmath and APyTypes."""

import re

import numpy as np
import pytest
from fxpmath import Fxp

from kfpga.core.fixed import Overflow, QFormat, Rounding, bits_for, requantise, shift_round, to_raw

# -- the format type ---------------------------------------------------------------------


def test_format_geometry():
    f = QFormat(4, 3)
    assert (f.width, f.min_raw, f.max_raw) == (7, -64, 63)
    assert (f.min_value, f.max_value, f.lsb) == (-8.0, 7.875, 0.125)
    assert str(f) == "Q4.3"
    assert QFormat.parse("Q18.8") == QFormat(18, 8)
    assert QFormat.parse(" q2.16 ", rounding="half_up").rounding is Rounding.HALF_UP


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"int_bits": 0, "frac_bits": 3}, "int_bits must be an integer >= 1"),
        ({"int_bits": 2, "frac_bits": -1}, "frac_bits must be an integer >= 0"),
        ({"int_bits": 2.5, "frac_bits": 1}, "int_bits must be an integer"),
        ({"int_bits": 2, "frac_bits": 1, "rounding": "up"},
         "rounding must be one of nearest, round, convergent, floor, fix (half_up: nearest), not 'up'"),
        ({"int_bits": 2, "frac_bits": 1, "overflow": "clamp"}, "overflow must be one of saturate, wrap, not 'clamp'"),
    ],
)
def test_format_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match="^" + re.escape(message)):
        QFormat(**kwargs)


def test_parse_rejects_garbage():
    message = "format must look like 'Q18.8' (integer bits incl. sign . fraction bits), not '18.8'"
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        QFormat.parse("18.8")


def test_bits_for():
    assert bits_for(0.5, 1) == 1  # Q1.1 holds 0.5
    assert bits_for(1.0, 1) == 2
    assert bits_for(65535, 1) == 17  # Q17.1 max = 65535.5
    assert bits_for(65535.75, 1) == 18
    assert bits_for(32767, 0) == 16


# -- rounding and overflow tables ----------------------------------------------------------

# (raw, shift, nearest, round, convergent, floor, fix), each worked out by hand from the value
# raw / 2**shift: ties of both signs, ties to an odd and an even neighbour, exact negative
# multiples, the most negative and most positive ties
MODES = ("nearest", "round", "convergent", "floor", "fix")
ROUNDING_TABLE = [
    (5, 1, 3, 3, 2, 2, 2),              # 2.5
    (-5, 1, -2, -3, -2, -3, -2),        # -2.5
    (3, 1, 2, 2, 2, 1, 1),              # 1.5: the even neighbour is 2
    (-3, 1, -1, -2, -2, -2, -1),        # -1.5
    (10, 2, 3, 3, 2, 2, 2),             # 2.5 with two bits dropped
    (14, 2, 4, 4, 4, 3, 3),             # 3.5
    (-14, 2, -3, -4, -4, -4, -3),       # -3.5
    (6, 1, 3, 3, 3, 3, 3),              # exact
    (-6, 1, -3, -3, -3, -3, -3),        # exact negative multiple
    (-8, 2, -2, -2, -2, -2, -2),        # exact negative multiple
    (-7, 2, -2, -2, -2, -2, -1),        # -1.75
    (-6, 2, -1, -2, -2, -2, -1),        # -1.5
    (-5, 2, -1, -1, -1, -2, -1),        # -1.25
    (-13, 2, -3, -3, -3, -4, -3),       # -3.25
    (7, 2, 2, 2, 2, 1, 1),              # 1.75
    (12, 3, 2, 2, 2, 1, 1),             # 1.5 with three bits dropped
    (-9, 3, -1, -1, -1, -2, -1),        # -1.125
    (1, 1, 1, 1, 0, 0, 0),              # 0.5
    (-1, 1, 0, -1, 0, -1, 0),           # -0.5
    (-1, 3, 0, 0, 0, -1, 0),            # -0.125
    (0, 4, 0, 0, 0, 0, 0),
    (-32768, 4, -2048, -2048, -2048, -2048, -2048),
    (-32760, 4, -2047, -2048, -2048, -2048, -2047),  # -2047.5
    (32760, 4, 2048, 2048, 2048, 2047, 2047),        # 2047.5
    (3, 0, 3, 3, 3, 3, 3),              # no shift
    (3, -2, 12, 12, 12, 12, 12),        # a negative shift appends zeros
]


@pytest.mark.parametrize(("raw", "shift", *MODES), ROUNDING_TABLE)
def test_rounding_table(raw, shift, nearest, round, convergent, floor, fix):
    for mode, expected in zip(MODES, (nearest, round, convergent, floor, fix), strict=True):
        assert shift_round(raw, shift, Rounding(mode)) == expected, mode
        arr = np.array([raw, raw], dtype=np.int64)
        assert shift_round(arr, shift, Rounding(mode)).tolist() == [expected, expected], mode


def test_half_up_is_another_name_of_nearest():
    assert Rounding("half_up") is Rounding.NEAREST is Rounding.HALF_UP
    assert QFormat(4, 2, "half_up") == QFormat(4, 2, "nearest")
    assert [r.value for r in Rounding] == list(MODES)


Q4_0 = QFormat(4, 0)  # -8..7

# (raw value in Q4.0 units, saturate result, wrap result, overflowed)
OVERFLOW_TABLE = [
    (7, 7, 7, False),
    (-8, -8, -8, False),  # most negative value fits
    (8, 7, -8, True),
    (-9, -8, 7, True),
    (16, 7, 0, True),
    (-16, -8, 0, True),
    (23, 7, 7, True),
    (-100, -8, -4, True),
]


@pytest.mark.parametrize(("value", "sat", "wrap", "flag"), OVERFLOW_TABLE)
def test_overflow_table(value, sat, wrap, flag):
    for overflow, expected in ((Overflow.SATURATE, sat), (Overflow.WRAP, wrap)):
        fmt = Q4_0.with_rules(overflow=overflow)
        assert requantise(value, 0, fmt) == (expected, flag)
        out, f = requantise(np.array([value]), 0, fmt)
        assert (out[0], bool(f[0])) == (expected, flag)


def test_most_negative_value_rounds_and_saturates():
    # -8.5 in Q4.1 (raw -17) into Q4.0: floor gives -9 -> saturates to -8; half up gives -8 exactly
    fmt = QFormat(4, 0)
    assert requantise(-17, 1, fmt.with_rules(rounding=Rounding.FLOOR)) == (-8, True)
    assert requantise(-17, 1, fmt.with_rules(rounding=Rounding.HALF_UP)) == (-8, False)
    # 7.5 (raw 15 in Q4.1): floor 7 fits, half up 8 overflows
    assert requantise(15, 1, fmt.with_rules(rounding=Rounding.FLOOR)) == (7, False)
    assert requantise(15, 1, fmt.with_rules(rounding=Rounding.HALF_UP)) == (7, True)


def test_to_raw_rounds_constants():
    fmt = QFormat(2, 4, Rounding.HALF_UP)
    assert to_raw(0.5, fmt) == (8, False)
    assert to_raw(0.03125, fmt) == (1, False)  # tie -> up
    assert to_raw(-0.03125, fmt) == (0, False)  # tie -> toward +inf
    assert to_raw(5.0, fmt) == (31, True)
    with pytest.raises(ValueError, match="^cannot quantise nan into Q2.4$"):
        to_raw(float("nan"), fmt)


# -- cross-check against fxpmath on random values -------------------------------------------

# fxpmath's rules for ours: 'floor', 'fix' (toward zero) and 'around' (numpy's, ties to even);
# nearest is floor after adding half an LSB of the target; round (ties away) fxpmath lacks
FXPMATH = {"floor": ("floor", False), "fix": ("fix", False), "convergent": ("around", False),
           "nearest": ("floor", True)}
APYTYPES = {"floor": "TO_NEG", "nearest": "TIES_POS", "round": "TIES_AWAY", "convergent": "TIES_EVEN",
            "fix": "TO_ZERO"}


def random_requantisations(rng, rounding, overflow, count=5000, cases=20):
    """``(raw, src_frac, fmt)``: exact binary fractions well beyond the format's range, both signs,
    many ties."""
    for _ in range(cases):
        src_frac = int(rng.integers(0, 12))
        fmt = QFormat(int(rng.integers(1, 10)), int(rng.integers(0, 8)), rounding, overflow)
        span = 1 << (fmt.width + src_frac - fmt.frac_bits + 2)
        yield rng.integers(-span, span, count), src_frac, fmt


@pytest.mark.parametrize("overflow", ["saturate", "wrap"])
@pytest.mark.parametrize("rounding", sorted(FXPMATH))
def test_requantise_matches_fxpmath(rounding, overflow, seed):
    rng = np.random.default_rng(seed)
    mode, add_half = FXPMATH[rounding]
    for raw, src_frac, fmt in random_requantisations(rng, rounding, overflow):
        values = raw.astype(np.float64) * 2.0 ** -src_frac
        ours, flags = requantise(raw.astype(np.int64), src_frac, fmt)
        shifted = values + (fmt.lsb / 2 if add_half and src_frac > fmt.frac_bits else 0.0)
        ref = Fxp(shifted, signed=True, n_word=fmt.width, n_frac=fmt.frac_bits, rounding=mode, overflow=overflow)
        np.testing.assert_array_equal(ours, ref.val.astype(np.int64), err_msg=f"{fmt} from frac {src_frac}")
        # the flag is raised exactly when the rounded value left the range
        rounded = shift_round(raw.astype(object), src_frac - fmt.frac_bits, fmt.rounding)
        expected_flags = np.array([not fmt.min_raw <= int(r) <= fmt.max_raw for r in rounded])
        np.testing.assert_array_equal(flags, expected_flags)
        # the int path agrees with the array path
        for r, o, fl in zip(raw[:300].tolist(), ours[:300].tolist(), flags[:300].tolist(), strict=True):
            assert requantise(r, src_frac, fmt) == (o, fl)


@pytest.mark.parametrize("overflow", ["saturate", "wrap"])
@pytest.mark.parametrize("rounding", MODES)
def test_requantise_matches_apytypes(rounding, overflow, seed):
    apy = pytest.importorskip("apytypes")
    rng = np.random.default_rng(seed)
    quantization = getattr(apy.QuantizationMode, APYTYPES[rounding])
    wrap = {"saturate": apy.OverflowMode.SAT, "wrap": apy.OverflowMode.WRAP}[overflow]
    for raw, src_frac, fmt in random_requantisations(rng, rounding, overflow, count=2000):
        width = int(np.max(np.abs(raw))).bit_length() + 2
        src = apy.APyFixedArray.from_float(raw.astype(np.float64) * 2.0 ** -src_frac, int_bits=width - src_frac,
                                           frac_bits=src_frac)
        bits = np.asarray(src.cast(int_bits=fmt.int_bits, frac_bits=fmt.frac_bits, quantization=quantization,
                                   overflow=wrap).to_bits()).astype(np.int64)
        ref = bits - ((bits >> (fmt.width - 1)) << fmt.width)  # two's complement back to signed
        ours, _ = requantise(raw.astype(np.int64), src_frac, fmt)
        np.testing.assert_array_equal(ours, ref, err_msg=f"{rounding} {fmt} from frac {src_frac}")


def test_to_raw_matches_fxpmath_on_floats(seed):
    rng = np.random.default_rng(seed)
    values = rng.uniform(-300, 300, 3000)
    fmt = QFormat(8, 6, Rounding.FLOOR, Overflow.SATURATE)
    ours, _ = to_raw(values, fmt)
    ref = Fxp(values, signed=True, n_word=fmt.width, n_frac=fmt.frac_bits, rounding="floor", overflow="saturate")
    np.testing.assert_array_equal(ours, ref.val.astype(np.int64))
