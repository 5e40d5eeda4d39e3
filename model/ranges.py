"""Range analysis: the largest magnitude every datapath quantity reaches in float runs.

The default formats are chosen from these ranges (plus a guard bit), and a user's formats are
checked against them. The stimulus is the whole input range of the 16-bit ADC, driven the way
real signals use it: full-scale steps in both directions from a settled state, a full-scale
sine with noise, and the default demo scenario. All runs use the datapath's units (``v = T*x2``
and ``P' = D P D``, see :meth:`KalmanParams.scaled`). The noise generator has a fixed seed
(:data:`RANGE_SEED`) so that the default formats never change from one run to the next.
"""

from __future__ import annotations

import functools

import numpy as np

from kfpga.model.reference import KalmanParams, kalman_decomposed, steady_state, steady_state_gain

__all__ = ["ADC_MIN", "ADC_MAX", "RANGE_SEED", "range_stimulus", "analyse_ranges"]

#: Signed 16-bit ADC code range (ADS8364, two's complement).
ADC_MIN, ADC_MAX = -32768, 32767
RANGE_SEED = 20080525
#: Samples per stimulus segment; long enough for the default filter to settle many times over.
SEGMENT = 4096


def range_stimulus(params, segment=SEGMENT):
    """Stimulus rows, shape ``(4, 2*segment)``: step up, step down, full-scale sine, demo sine."""
    rng = np.random.default_rng(RANGE_SEED)
    n = 2 * segment
    t = np.arange(n)
    sigma = np.sqrt(params.R)
    step_up = np.where(t < segment, ADC_MIN, ADC_MAX).astype(np.float64)
    step_down = -step_up - 1.0
    amplitude = ADC_MAX - 6.0 * sigma
    sine = np.clip(np.round(amplitude * np.sin(2 * np.pi * t / 2000.0) + rng.normal(0, sigma, n)), ADC_MIN, ADC_MAX)
    demo = np.clip(np.round(8192.0 * np.sin(2 * np.pi * t / 2000.0) + rng.normal(0, sigma, n)), ADC_MIN, ADC_MAX)
    return np.stack([step_up, step_down, sine, demo])


def _max_abs(*arrays):
    return float(max(np.max(np.abs(a)) for a in arrays))


def analyse_ranges(params: KalmanParams, variant: str, stimulus=None):
    """Largest magnitude of each named quantity for ``variant`` ("steady" or "full").

    ``stimulus`` (rows of ADC codes) replaces the full-scale stimulus of :func:`range_stimulus`.
    Keys of the result: ``x1``, ``xl1``, ``v``, ``x2``, ``e``, ``gain`` and, for the full
    variant, ``p``, ``pl``, ``s``.
    """
    if stimulus is None:
        return dict(_full_scale_ranges(params, variant))
    return _analyse(params, variant, np.atleast_2d(np.asarray(stimulus, dtype=np.float64)))


@functools.lru_cache(maxsize=32)
def _full_scale_ranges(params, variant):
    return _analyse(params, variant, range_stimulus(params))


def _analyse(params, variant, y):
    scaled = params.scaled()
    if variant == "steady":
        (k1, k2), _ = steady_state_gain(params.T, params.Q, params.R)
        gain = (k1, k2 * params.T)
        run = steady_state(y, scaled, gain=gain)
        ranges = {
            "x1": _max_abs(run["x1"], [scaled.x0[0]]),
            "xl1": _max_abs(run["yhat"]),
            "v": _max_abs(run["x2"], [scaled.x0[1]]),
            "e": _max_abs(run["e"]),
            "gain": _max_abs(gain),
        }
    elif variant == "full":
        tr = kalman_decomposed(y, scaled, trace=True)["trace"]
        p0 = np.array(scaled.P0)
        ranges = {
            "x1": _max_abs(tr["x1"], [scaled.x0[0]]),
            "xl1": _max_abs(tr["xl1"]),
            "v": _max_abs(tr["x2"], [scaled.x0[1]]),
            "e": _max_abs(tr["e"]),
            "gain": _max_abs(tr["K1"], tr["K2"]),
            "p": _max_abs(tr["p11"], tr["p12"], tr["p21"], tr["p22"], p0),
            "pl": _max_abs(tr["pl11"], tr["pl12"], tr["pl21"], tr["pl22"]),
            "s": _max_abs(tr["S"]),
        }
    else:
        raise ValueError(f"variant must be 'steady' or 'full', not {variant!r}")
    ranges["x2"] = ranges["v"] / params.T
    return ranges
