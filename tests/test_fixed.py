"""The format type and the quantisation rules: pinned by tables, cross-checked with fxpmath."""

import re

import numpy as np
import pytest
from fxpmath import Fxp

from kfpga.fixed import Overflow, QFormat, Rounding, bits_for, requantize, shift_round, to_raw

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
        ({"int_bits": 2, "frac_bits": 1, "rounding": "nearest"}, "rounding must be one of floor, half_up, not 'nearest'"),
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

# (raw, shift, floor, half_up): ties, negative ties, exact negative multiples, odd values
ROUNDING_TABLE = [
    (5, 1, 2, 3),     # 2.5 -> floor 2, half up 3
    (-5, 1, -3, -2),  # -2.5 -> floor -3, half up -2 (ties toward +inf)
    (6, 1, 3, 3),     # exact
    (-6, 1, -3, -3),  # exact negative multiple
    (-8, 2, -2, -2),  # exact negative multiple
    (-7, 2, -2, -2),  # -1.75 -> floor -2, half up -2
    (-6, 2, -2, -1),  # -1.5 tie -> half up -1
    (-5, 2, -2, -1),  # -1.25 -> half up -1
    (7, 2, 1, 2),     # 1.75
    (1, 1, 0, 1),     # 0.5 tie
    (-1, 1, -1, 0),   # -0.5 tie -> half up 0
    (-1, 3, -1, 0),   # -0.125
    (0, 4, 0, 0),
    (-32768, 4, -2048, -2048),
    (3, 0, 3, 3),     # no shift
    (3, -2, 12, 12),  # negative shift appends zeros
]


@pytest.mark.parametrize(("raw", "shift", "floor", "half_up"), ROUNDING_TABLE)
def test_rounding_table(raw, shift, floor, half_up):
    assert shift_round(raw, shift, Rounding.FLOOR) == floor
    assert shift_round(raw, shift, Rounding.HALF_UP) == half_up
    arr = np.array([raw], dtype=np.int64)
    assert shift_round(arr, shift, Rounding.FLOOR)[0] == floor
    assert shift_round(arr, shift, Rounding.HALF_UP)[0] == half_up


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
        assert requantize(value, 0, fmt) == (expected, flag)
        out, f = requantize(np.array([value]), 0, fmt)
        assert (out[0], bool(f[0])) == (expected, flag)


def test_most_negative_value_rounds_and_saturates():
    # -8.5 in Q4.1 (raw -17) into Q4.0: floor gives -9 -> saturates to -8; half up gives -8 exactly
    fmt = QFormat(4, 0)
    assert requantize(-17, 1, fmt.with_rules(rounding=Rounding.FLOOR)) == (-8, True)
    assert requantize(-17, 1, fmt.with_rules(rounding=Rounding.HALF_UP)) == (-8, False)
    # 7.5 (raw 15 in Q4.1): floor 7 fits, half up 8 overflows
    assert requantize(15, 1, fmt.with_rules(rounding=Rounding.FLOOR)) == (7, False)
    assert requantize(15, 1, fmt.with_rules(rounding=Rounding.HALF_UP)) == (7, True)


def test_to_raw_rounds_constants():
    fmt = QFormat(2, 4, Rounding.HALF_UP)
    assert to_raw(0.5, fmt) == (8, False)
    assert to_raw(0.03125, fmt) == (1, False)  # tie -> up
    assert to_raw(-0.03125, fmt) == (0, False)  # tie -> toward +inf
    assert to_raw(5.0, fmt) == (31, True)
    with pytest.raises(ValueError, match="^cannot quantise nan into Q2.4$"):
        to_raw(float("nan"), fmt)


# -- cross-check against fxpmath on random values -------------------------------------------

@pytest.mark.parametrize("overflow", ["saturate", "wrap"])
@pytest.mark.parametrize("rounding", ["floor", "half_up"])
def test_requantize_matches_fxpmath(rounding, overflow, seed):
    rng = np.random.default_rng(seed)
    count = 5000
    for _ in range(20):
        src_frac = int(rng.integers(0, 12))
        fmt = QFormat(int(rng.integers(1, 10)), int(rng.integers(0, 8)), rounding, overflow)
        # exact binary fractions well beyond the format's range, both signs, many ties
        raw = rng.integers(-(1 << (fmt.width + src_frac - fmt.frac_bits + 2)),
                           1 << (fmt.width + src_frac - fmt.frac_bits + 2), count)
        values = raw.astype(np.float64) * 2.0 ** -src_frac
        ours, flags = requantize(raw.astype(np.int64), src_frac, fmt)
        # fxpmath floors; half up is floor after adding half an LSB of the target format
        shifted = values + (fmt.lsb / 2 if rounding == "half_up" and src_frac > fmt.frac_bits else 0.0)
        ref = Fxp(shifted, signed=True, n_word=fmt.width, n_frac=fmt.frac_bits, rounding="floor", overflow=overflow)
        np.testing.assert_array_equal(ours, ref.val.astype(np.int64), err_msg=f"{fmt} from frac {src_frac}")
        # the flag is raised exactly when the rounded value left the range
        rounded = shift_round(raw.astype(object), src_frac - fmt.frac_bits, fmt.rounding)
        expected_flags = np.array([not fmt.min_raw <= int(r) <= fmt.max_raw for r in rounded])
        np.testing.assert_array_equal(flags, expected_flags)
        # the int path agrees with the array path
        for r, o, fl in zip(raw[:300].tolist(), ours[:300].tolist(), flags[:300].tolist(), strict=True):
            assert requantize(r, src_frac, fmt) == (o, fl)


def test_to_raw_matches_fxpmath_on_floats(seed):
    rng = np.random.default_rng(seed)
    values = rng.uniform(-300, 300, 3000)
    fmt = QFormat(8, 6, Rounding.FLOOR, Overflow.SATURATE)
    ours, _ = to_raw(values, fmt)
    ref = Fxp(values, signed=True, n_word=fmt.width, n_frac=fmt.frac_bits, rounding="floor", overflow="saturate")
    np.testing.assert_array_equal(ours, ref.val.astype(np.int64))
