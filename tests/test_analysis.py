"""The precision reports of ``compare``: dead band and limit cycles, overflows per point."""

import math
from fractions import Fraction

import numpy as np
import pytest

from kfpga.core import registry
from kfpga.core.config import FilterConfig
from kfpga.flows.analysis import LIMIT_CYCLE_INPUTS, LIMIT_CYCLE_SAMPLES, LIMIT_CYCLE_WINDOW, compare, limit_cycles
from kfpga.model.reference import steady_state_gain

COARSE = {"x1": "Q18.2", "xl1": "Q18.2", "v": "Q17.2", "x2": "Q17.2", "e": "Q17.0"}


def hand_alpha_beta(y, k1, k2):
    """The paper's steady filter with quarter-code states and whole-code innovations, written
    out from its definition with exact rationals: xl1 = x1 + v; e = [y - xl1]_1;
    x1 = [xl1 + K1 e]_1/4; v = [v + K2 e]_1/4, [.]_q to the nearest multiple of q with ties up
    (K1, K2 already on the 2**-16 grid)."""
    def nearest(value, step):
        return math.floor(value / step + Fraction(1, 2)) * step

    q = Fraction(1, 4)
    x1 = v = Fraction(0)
    out = []
    for code in y:
        xl1 = x1 + v
        e = nearest(code - xl1, 1)
        x1, v = nearest(xl1 + k1 * e, q), nearest(v + k2 * e, q)
        out.append(x1)
    return np.array(out, dtype=np.float64)


def test_limit_cycle_of_coarse_formats_matches_the_hand_filter():
    config = FilterConfig.from_dict({"formats": COARSE})
    k = {name: Fraction(round(v * 65536), 65536) for name, v in zip(("k1", "k2"), np.ravel(steady_state_gain()[0]), strict=True)}
    lc = limit_cycles(config, "steady")
    w = slice(LIMIT_CYCLE_SAMPLES - LIMIT_CYCLE_WINDOW, None)
    worst_dead, worst_cycle = 0.0, 0.0
    for label, before, after, at in LIMIT_CYCLE_INPUTS:
        y = [before if n < at else after for n in range(LIMIT_CYCLE_SAMPLES)]
        # the float filter has settled on the level to far below a code by then
        diff = hand_alpha_beta(y, k["k1"], k["k2"])[w] - after
        assert lc["inputs"][label]["dead_band_lsb"] == pytest.approx(abs(float(np.median(diff))), abs=1e-6), label
        assert lc["inputs"][label]["limit_cycle_lsb"] == pytest.approx(float(np.ptp(diff)), abs=1e-6), label
        worst_dead, worst_cycle = max(worst_dead, abs(float(np.median(diff)))), max(worst_cycle, float(np.ptp(diff)))
    assert (lc["dead_band_lsb"], lc["limit_cycle_lsb"]) == (pytest.approx(worst_dead, abs=1e-6),
                                                            pytest.approx(worst_cycle, abs=1e-6))
    assert worst_cycle > 0  # whole-code innovations keep the estimate sawing about the level


def test_an_exact_filter_has_no_limit_cycle():
    # alpha = beta = 0.5: every product is a shift, and with enough fraction bits nothing rounds
    name, params = registry.preset("cv2-fixed-gain")
    config = FilterConfig(filter=name, params=params)
    lc = limit_cycles(config, "steady")
    assert lc["limit_cycle_lsb"] == 0.0 and lc["dead_band_lsb"] < 1e-6


def test_default_formats_keep_limit_cycles_below_one_code():
    for variant in ("steady", "full"):
        lc = limit_cycles(FilterConfig(), variant)
        assert 0 < lc["limit_cycle_lsb"] <= 1.0, (variant, lc)


def test_overflows_are_counted_per_point(seed):
    config = FilterConfig()
    y = np.where(np.arange(2000) % 8 < 4, 32767, -32768)  # a fast full-scale square wave overshoots e
    m = compare(config, "steady", y, limit_cycle=False).metrics
    assert m["overflow_points"]["e"] > 0 and m["overflow_points"]["e"] == m["overflow_sites"]["e"]
    assert m["overflows"] >= m["overflow_points"]["e"]
    assert set(m["overflow_points"]) <= set(config.formats)
    assert "limit_cycle_lsb" not in m
