"""Word lengths that are right for the model: constants held within 1 %, precision-aware defaults.

The grid: T in {0.001, 0.01, 0.1, 1, 8}, Q in {0.01, 2, 100}, R in {0.01, 4, 1000} on the paper's
model (cv2) and the constant-acceleration model (ca3), both variants: the default formats give a
fixed RMSE of x1 and of x2 within 1 % of float's, with no overflow, and none is refused. The
defaults add the bits every constant needs, past the word budget where they must (a time-varying
covariance that spans a wide range at T = 0.001), and the model is exact at any width.
"""

import itertools

import numpy as np
import pytest

from kfpga.core.config import ConfigError, FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.flows.analysis import compare, float_run, rmse
from kfpga.model.kalman import StateSpaceParams
from kfpga.model.reference import KalmanParams
from kfpga.model.scenarios import SINE_AMPLITUDE, SINE_PERIOD, for_config

GRID = list(itertools.product((0.001, 0.01, 0.1, 1.0, 8.0), (0.01, 2.0, 100.0), (0.01, 4.0, 1000.0)))


def ca3(t, q, r):
    return StateSpaceParams(F=((1.0, t, t * t / 2), (0.0, 1.0, t), (0.0, 0.0, 1.0)), G=np.eye(3).tolist(),
                            Q=(np.eye(3) * q).tolist(), H=((1.0, 0.0, 0.0),), R=((r,),), P0=(np.eye(3) * 10).tolist(),
                            x0=(0.0, 0.0, 0.0), T=t)


def config_for(model, t, q, r):
    if model == "cv2":
        return FilterConfig(filter="kalman2", params=KalmanParams(T=t, Q=q, R=r))
    return FilterConfig(filter="kalman", params=ca3(t, q, r))


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["steady", "full"])
@pytest.mark.parametrize("model", ["cv2", "ca3"])
def test_defaults_are_within_one_percent_and_none_is_refused(model, variant, seed):
    passed = []
    for t, q, r in GRID:
        where = f"{model} {variant} T={t} Q={q} R={r}"
        config = config_for(model, t, q, r)
        config.require_variant(variant)
        truth, y = for_config("sine", 5000, seed, config)
        m = compare(config, variant, y, truth, limit_cycle=False).metrics
        assert m["overflows"] == 0, (where, m["overflow_points"])
        assert abs(m["rmse_fixed_over_float"] - 1) <= 0.01, (where, m["rmse_fixed_over_float"])
        # x2, the rate: its truth is the sine's derivative per unit time (the scenario's own x2)
        rate = SINE_AMPLITUDE * 2 * np.pi / (SINE_PERIOD * t) * np.cos(2 * np.pi * np.arange(len(truth)) / SINE_PERIOD)
        bits = FixedModel(config, variant=variant)
        fixed, flt = bits.to_float(bits.run(y))["x2"][100:], float_run(config, variant, y)["x2"][100:]
        ratio = rmse(fixed, rate[100:]) / rmse(flt, rate[100:])
        assert abs(ratio - 1) <= 0.01, (where, "x2", ratio)
        passed.append(where)
    assert len(passed) == len(GRID)


def test_the_millisecond_case_gets_the_bits_it_needs(seed):
    """T = 0.001: T^2 Q = 2e-06 needs 25 fraction bits in pl, which the default gives it (pl grows past
    the multiplier's 18 bits); both variants run within 1 % of float."""
    config = FilterConfig.from_dict({"model": {"T": 0.001}})
    assert config.formats["pl"].frac_bits >= 25 and str(config.formats["gain"]) == "Q1.17"
    truth, y = for_config("sine", 5000, seed, config)
    for variant in ("steady", "full"):
        config.require_variant(variant)
        m = compare(config, variant, y, truth, limit_cycle=False).metrics
        assert m["overflows"] == 0 and abs(m["rmse_fixed_over_float"] - 1) <= 0.01, (variant, m["rmse_fixed_over_float"])


def test_a_pinned_format_that_loses_a_constant_is_refused():
    config = FilterConfig.from_dict({"formats": {"gain": "Q2.5"}})
    # K1 = 0.70512 on a 1/32 grid: 23/32 = 0.71875, 1.9 % off; on a 1/64 grid 45/64, 0.3 % off
    with pytest.raises(ConfigError, match=r"^the constant K1 = 0\.7051 is held as 0\.7188 in formats\.gain = Q2\.5, "
                                          r"1\.9 % off: gain needs at least 6 fraction bits"):
        config.require_variant("steady")


def test_a_reset_value_is_held_or_refused():
    # by default x1 gets the bits 0.001 needs: 15 (33/2**15 is 0.7 % off, 16/2**14 2.3 %) ...
    assert FilterConfig.from_dict({"model": {"x0": [0.001, 0.0]}}).formats["x1"].frac_bits == 15
    # ... a pinned format that cannot hold it is refused
    config = FilterConfig.from_dict({"model": {"x0": [0.001, 0.0]}, "formats": {"x1": "Q18.8", "xl1": "Q18.8"}})
    with pytest.raises(ConfigError, match=r"^the reset value of x1 = 0\.001 rounds to 0 in formats\.x1 = Q18\.8 "
                                          r"\(LSB 0\.00391\): x1 needs at least 15 fraction bits"):
        config.require_variant("steady")


def test_small_measurement_noise_gives_the_innovation_fraction_bits():
    # R = 0.01: sigma 0.1 code, so e keeps steps of at most 0.025 codes: 6 fraction bits
    assert FilterConfig.from_dict({"model": {"R": 0.01}}).formats["e"].frac_bits == 6
    assert FilterConfig().formats["e"].frac_bits == 1  # R = 4: the paper's Q17.1


def test_outputs_coarse_against_the_filter_noise_are_warned(capsys):
    from kfpga.cli import main
    from kfpga.flows.analysis import precision_warnings

    assert precision_warnings(FilterConfig()) == []
    # x2's float error is 1.92 (steady state, T = 1, Q = 2, R = 4): whole steps add 1/sqrt(12) = 0.289
    # rms, more than sqrt(1.01**2 - 1) * 1.92 = 0.272; half steps (0.144) do not
    coarse = FilterConfig.from_dict({"formats": {"x2": "Q17.0"}})
    (line,) = precision_warnings(coarse)
    assert line.startswith("formats.x2 = Q17.0: its rounding noise (1/sqrt(12) rms) is more than 14.2 % of the float "
                           "filter's own error of x2 (1.92)")
    assert precision_warnings(FilterConfig.from_dict({"formats": {"x2": "Q17.1"}})) == []
    assert main(["formats", "--preset", "ca3"]) == 0
    assert "warning" not in capsys.readouterr().err
