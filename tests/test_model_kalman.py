"""The bit-accurate model against an independent exact-rational implementation of its spec.

``spec_run`` follows the equations of ``model/kalman.py``'s docstring with Python Fractions:
every quantity is an exact rational, written once into its format by floor / half-up rounding
and saturate / wrap, and the divider is a bit-by-bit restoring division. It shares no
alignment, shift or closure code with the model, so agreement on random configs is evidence
that the fast kernels compute what the spec says.
"""

import math
from fractions import Fraction

import numpy as np
import pytest

from kfpga.analysis import float_run, rmse
from kfpga.config import ConfigError, KalmanConfig, default_formats
from kfpga.fixed import Overflow, QFormat, Rounding
from kfpga.model.kalman import FixedKalman, divide
from kfpga.model.reference import KalmanParams
from kfpga.scenarios import SINE_AMPLITUDE, SINE_PERIOD, sine

SEED = 5150


def quantise(value, fmt):
    """Exact rational -> (raw, overflowed) by the format's rules."""
    scaled = Fraction(value) * (1 << fmt.frac_bits)
    raw = math.floor(scaled + Fraction(1, 2)) if fmt.rounding is Rounding.HALF_UP else math.floor(scaled)
    if fmt.min_raw <= raw <= fmt.max_raw:
        return raw, False
    if fmt.overflow is Overflow.SATURATE:
        return (fmt.max_raw if raw > fmt.max_raw else fmt.min_raw), True
    return (raw - fmt.min_raw) % (1 << fmt.width) + fmt.min_raw, True


def restoring_divide(num, den, n_bits):
    """Quotient bits of num/den (num >= 0, den > 0, num < den * 2**n_bits) one per step."""
    rem, quo = 0, 0
    for i in range(num.bit_length() + n_bits, -1, -1):
        rem = (rem << 1) | ((num >> i) & 1)
        quo <<= 1
        if rem >= den:
            rem -= den
            quo |= 1
    return quo


def spec_divide(num, den, f_num, f_den, gain):
    """K = num/den truncated toward zero to gain.frac_bits, saturated to gain's largest value."""
    limit = gain.max_raw
    if den <= 0:
        return limit if num >= 0 else -limit, True
    q = Fraction(abs(num), 1 << f_num) / Fraction(den, 1 << f_den)
    exact = q * (1 << gain.frac_bits)
    if exact >= limit + 1:
        return (limit if num >= 0 else -limit), True
    num_int = exact.numerator * 1  # exact = a/b -> restoring division of a by b
    quo = restoring_divide(num_int, exact.denominator, gain.width)
    return (-quo if num < 0 else quo), False


def spec_run(config, variant, y):
    f = config.formats
    p = config.params.scaled()
    val = {name: (lambda raw, name=name: Fraction(raw, 1 << f[name].frac_bits)) for name in f}
    x1 = quantise(Fraction(p.x0[0]), f["x1"])[0]
    v = quantise(Fraction(p.x0[1]), f["v"])[0]
    if variant == "steady":
        k1f, k2f = config.steady_gain
        k1, k2 = quantise(Fraction(k1f), f["gain"])[0], quantise(Fraction(k2f), f["gain"])[0]
    else:
        pp = [quantise(Fraction(c), f["p"])[0] for c in (*p.P0[0], *p.P0[1])]
        q_c = val["pl"](quantise(Fraction(p.Q), f["pl"])[0])
        r_c = val["s"](quantise(Fraction(config.params.R), f["s"])[0])
    t_shift = config.t_shift
    inv_t = None if t_shift is not None else val["inv_t"](quantise(Fraction(1 / config.params.T), f["inv_t"])[0])
    out = []
    for yk in y:
        flags = []

        def q(value, name, flags=flags):
            raw, flag = quantise(value, f[name])
            flags.append(flag)
            return raw

        xl1 = q(val["x1"](x1) + val["v"](v), "xl1")
        if variant == "full":
            p11, p12, p21, p22 = (val["p"](r) for r in pp)
            pl11 = q(p11 + p12 + p21 + p22, "pl")
            pl12 = q(p12 + p22, "pl")
            pl21 = q(p21 + p22, "pl")
            pl22 = q(p22 + q_c, "pl")
            s = q(val["pl"](pl11) + r_c, "s")
            k1, fl1 = spec_divide(pl11, s, f["pl"].frac_bits, f["s"].frac_bits, f["gain"])
            k2, fl2 = spec_divide(pl21, s, f["pl"].frac_bits, f["s"].frac_bits, f["gain"])
            flags += [fl1, fl2]
        e = q(Fraction(int(yk)) - val["xl1"](xl1), "e")
        x1 = q(val["xl1"](xl1) + val["gain"](k1) * val["e"](e), "x1")
        v = q(val["v"](v) + val["gain"](k2) * val["e"](e), "v")
        if variant == "full":
            g1, g2 = val["gain"](k1), val["gain"](k2)
            a11, a12, a21, a22 = (val["pl"](r) for r in (pl11, pl12, pl21, pl22))
            pp = [q(a11 - g1 * a11, "p"), q(a12 - g1 * a12, "p"), q(a21 - g2 * a11, "p"), q(a22 - g2 * a12, "p")]
        x2_exact = val["v"](v) / (1 << t_shift) if t_shift is not None and t_shift >= 0 else None
        if t_shift is not None and t_shift < 0:
            x2_exact = val["v"](v) * (1 << -t_shift)
        if inv_t is not None:
            x2_exact = val["vt"](q(val["v"](v), "vt")) * inv_t
        x2 = q(x2_exact, "x2")
        out.append((x1, x2, xl1, any(flags)))
    return [np.array(col) for col in zip(*out, strict=True)]


def random_config(rng, variant):
    """Random model and formats near (and sometimes well below) the defaults; always valid."""
    while True:
        try:
            return _random_config(rng)
        except ConfigError:
            continue


def _random_config(rng):
    t = float(rng.choice([1.0, 0.5, 2.0, 0.25, rng.uniform(0.1, 3.0)]))
    a = rng.normal(size=(2, 2))
    params = KalmanParams(
        T=t,
        Q=float(rng.uniform(0.05, 20.0)),
        R=float(rng.uniform(0.5, 40.0)),
        P0=tuple(map(tuple, a @ a.T + rng.uniform(0.5, 8) * np.eye(2))),
        x0=(float(rng.normal(0, 100)), float(rng.normal(0, 5))),
    )
    formats = default_formats(params)
    for name, fmt in list(formats.items()):
        if name == "xl1" or (name == "inv_t" and 2 ** round(math.log2(params.T)) == params.T):
            continue
        i = max(1, fmt.int_bits + int(rng.integers(-3, 2)))
        fb = max(0, fmt.frac_bits + int(rng.integers(-3, 3)))
        if name in ("e", "gain", "pl", "inv_t", "vt"):
            fb = min(fb, 18 - i) if i < 18 else 0
            i = min(i, 18)
        formats[name] = QFormat(i, fb, str(rng.choice(["floor", "half_up"])), str(rng.choice(["saturate", "saturate", "wrap"])))
    formats["xl1"] = formats["x1"].with_rules(rounding=str(rng.choice(["floor", "half_up"])))
    # the divider needs gain.frac + s.frac >= pl.frac
    if formats["gain"].frac_bits + formats["s"].frac_bits < formats["pl"].frac_bits:
        formats["s"] = QFormat(formats["s"].int_bits, formats["pl"].frac_bits, formats["s"].rounding, formats["s"].overflow)
    return KalmanConfig(params=params, formats=formats, check_ranges=False)


def random_codes(rng, n):
    """Noise, a random walk, full-scale steps and the extreme codes."""
    walk = np.cumsum(rng.normal(0, 200, n))
    y = walk + rng.normal(0, 30, n)
    y[n // 3: n // 3 + 20] = 32767
    y[n // 2: n // 2 + 20] = -32768
    y[rng.integers(0, n, 10)] = -32768
    return np.clip(np.round(y), -32768, 32767).astype(np.int64)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_model_equals_exact_spec_on_random_configs(variant):
    print(f"seed {SEED}")
    rng = np.random.default_rng(SEED if variant == "steady" else SEED + 1)
    for trial in range(12):
        config = random_config(rng, variant)
        y = random_codes(rng, 400)
        model = FixedKalman(config, variant=variant)
        res = model.run(y)
        x1, x2, yhat, flags = spec_run(config, variant, y)
        ctx = f"trial {trial}: {config.params} {{k: str(v) for k, v in config.formats.items()}}"
        np.testing.assert_array_equal(res.x1, x1, err_msg=ctx)
        np.testing.assert_array_equal(res.x2, x2, err_msg=ctx)
        np.testing.assert_array_equal(res.yhat, yhat, err_msg=ctx)
        np.testing.assert_array_equal(res.overflow, flags, err_msg=ctx)
        # the batch path computes the same integers
        batch = model.run(np.stack([y, y[::-1]]))
        np.testing.assert_array_equal(batch.x1[0], res.x1)
        np.testing.assert_array_equal(batch.overflow[0], res.overflow)
        rev = model.run(y[::-1].copy())
        np.testing.assert_array_equal(batch.x2[1], rev.x2)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_default_config_equals_spec_and_exercises_saturation(variant):
    config = KalmanConfig()
    rng = np.random.default_rng(SEED + 7)
    # full-scale square wave: overshoot drives e past Q17.1 and must saturate (flagged)
    y = np.tile(np.repeat(np.array([32767, -32768]), 7), 30)
    y = np.concatenate([y, random_codes(rng, 200)])
    res = FixedKalman(config, variant=variant).run(y)
    x1, x2, yhat, flags = spec_run(config, variant, y)
    np.testing.assert_array_equal(res.x1, x1)
    np.testing.assert_array_equal(res.x2, x2)
    np.testing.assert_array_equal(res.yhat, yhat)
    np.testing.assert_array_equal(res.overflow, flags)
    assert res.overflow.any(), "a full-scale square wave must saturate the innovation"
    assert res.sticky[-1]
    first = int(np.argmax(res.overflow))
    assert not res.sticky[:first].any() and res.sticky[first:].all()


def test_state_continues_across_runs():
    rng = np.random.default_rng(SEED + 8)
    y = random_codes(rng, 600)
    for variant in ("steady", "full"):
        model = FixedKalman(variant=variant)
        whole = model.run(y)
        first = model.run(y[:250])
        second = model.run(y[250:], first.state)
        np.testing.assert_array_equal(np.concatenate([first.x1, second.x1]), whole.x1)
        np.testing.assert_array_equal(np.concatenate([first.sticky, second.sticky]), whole.sticky)


def test_run_channels_keeps_channels_apart():
    rng = np.random.default_rng(SEED + 9)
    y = random_codes(rng, 600)
    ch = rng.integers(0, 6, 600)
    model = FixedKalman(variant="full")
    x1, _, _, _ = model.run_channels(y, ch)
    for c in range(6):
        np.testing.assert_array_equal(x1[ch == c], model.run(y[ch == c]).x1)


def test_divide_matches_restoring_division_exhaustively():
    n_bits, shift = 6, 3
    for num in range(-64, 64):
        for den in range(-3, 40):
            q, flag = divide(num, den, shift, n_bits)
            qa, fa = divide(np.array([num]), np.array([den]), shift, n_bits)
            assert (int(qa[0]), bool(fa[0])) == (q, flag)
            limit = (1 << n_bits) - 1
            if den <= 0:
                assert (abs(q), flag) == (limit, True)
                continue
            mag = abs(num) << shift
            if mag >= den << n_bits:
                assert (abs(q), flag) == (limit, True)
            else:
                assert (abs(q), flag) == (restoring_divide(mag, den, n_bits), False)
                assert q == (-1 if num < 0 else 1) * (mag // den)


@pytest.mark.parametrize("variant", ["steady", "full"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fixed_rmse_within_one_percent_of_float(variant, seed):
    """Done-when of the model: default formats on the default scenario."""
    from kfpga.analysis import compare

    truth, y = sine(20000, seed)
    m = compare(KalmanConfig(), variant, y, truth).metrics
    print(f"seed {seed}: {m['rmse_fixed']:.5f} vs {m['rmse_float']:.5f}")
    assert m["overflows"] == 0
    assert m["rmse_fixed"] <= 1.01 * m["rmse_float"]
    assert m["rmse_float"] < m["rmse_raw"]


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_power_of_two_t_is_a_shift_and_other_t_a_product(variant):
    for t, shift in ((1.0, 0), (0.25, -2), (4.0, 2), (0.3, None)):
        cfg = KalmanConfig(params=KalmanParams(T=t))
        assert cfg.t_shift == shift
        model = FixedKalman(cfg, variant=variant)
        assert (model.datapath.inv_t is None) == (shift is not None)
        _, y = sine(20000, 4)
        # the sine's true rate in units per unit time (one sample lasts T)
        k = np.arange(len(y))
        rate = SINE_AMPLITUDE * 2 * np.pi / SINE_PERIOD * np.cos(2 * np.pi * k / SINE_PERIOD) / t
        _, x2_float, _ = float_run(cfg, variant, y)
        _, x2_fixed, _ = model.to_float(model.run(y))
        w = slice(100, None)
        # exactness is the spec test's job; here: the rate output, through the shift or the
        # product by 1/T, estimates the true rate as well as float does, up to the rounding of its
        # own output step q (uniform rounding noise adds q^2/12 to the error variance): for
        # T = 2**k the x2 LSB, else the 18-bit operand vt's LSB scaled by 1/T
        f = cfg.formats
        q = f["x2"].lsb if shift is not None else f["vt"].lsb / t
        bound = np.sqrt(rmse(x2_float[w], rate[w]) ** 2 + (q**2 + f["x2"].lsb ** 2) / 12)
        assert rmse(x2_fixed[w], rate[w]) <= 1.01 * bound, t


def test_run_rejects_bad_input():
    model = FixedKalman()
    with pytest.raises(TypeError, match="integer ADC codes"):
        model.run(np.array([1.5, 2.0]))
    with pytest.raises(ValueError, match="signed 16-bit ADC range"):
        model.run(np.array([40000]))
