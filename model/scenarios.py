"""Test signals in ADC codes: the truth and what a 16-bit ADC would deliver.

Every generator takes a seed; callers print it so a run can be replayed.
"""

from __future__ import annotations

import numpy as np

from kfpga.core.ads8364 import CODE_MAX, CODE_MIN

__all__ = ["SCENARIOS", "sine", "random_accel", "adc_codes", "make", "for_config", "stress_codes", "threshold_codes"]

#: Demo sine: a quarter of full scale, 2000 samples per period.
SINE_AMPLITUDE = 8192.0
SINE_PERIOD = 2000.0


def adc_codes(analog):
    """Quantise like the ADC: round half up to an integer code, saturate to 16 bits."""
    return np.clip(np.floor(np.asarray(analog) + 0.5), CODE_MIN, CODE_MAX).astype(np.int64)


def sine(n, seed, *, noise_var=4.0, amplitude=SINE_AMPLITUDE, period=SINE_PERIOD, batch=()):
    """The paper's test: a sine plus white Gaussian noise of variance ``noise_var`` (= R)."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    truth = amplitude * np.sin(2 * np.pi * k / period)
    truth = np.broadcast_to(truth, (*batch, n))
    y = adc_codes(truth + rng.normal(0.0, np.sqrt(noise_var), (*batch, n)))
    return np.array(truth), y


def random_accel(n, seed, *, q=2.0, noise_var=4.0, T=1.0, spread=8000.0, batch=()):
    """A rate driven by white acceleration noise of variance ``q`` (the filter's own model).

    A pure random walk of the rate leaves the ADC range within a few thousand samples, so a
    weak, critically damped pull toward zero keeps the position near ``±spread``; it is small
    next to the noise (about 1 % of its standard deviation), so the filter's model still holds.
    """
    rng = np.random.default_rng(seed)
    # stationary std of a critically damped oscillator driven by white noise: sqrt(q / (4 w^3))
    w = (q / (4.0 * spread**2)) ** (1.0 / 3.0)
    x1 = np.zeros(batch)
    x2 = np.zeros(batch)
    truth = np.empty((*batch, n))
    acc = rng.normal(0.0, np.sqrt(q), (*batch, n))
    for k in range(n):
        truth[..., k] = x1
        x1 = x1 + T * x2
        x2 = x2 + acc[..., k] - T * (w * w * truth[..., k] + 2.0 * w * x2)
    truth = np.clip(truth, CODE_MIN, CODE_MAX)
    y = adc_codes(truth + rng.normal(0.0, np.sqrt(noise_var), (*batch, n)))
    return truth, y


SCENARIOS = {"sine": sine, "random-accel": random_accel}


def for_config(name, n, seed, config):
    """``(truth, codes)`` of scenario ``name`` for a config: its filter's own scenarios when it has
    them (``FilterSpec.scenario``), else :func:`make` on one input."""
    if config.spec.scenario is not None:
        return config.spec.scenario(name, n, seed, config.params)
    return make(name, n, seed, config.params)


def make(name, n, seed, params, batch=()):
    """``(truth, y)`` of scenario ``name`` for the model ``params`` (noise variance = R)."""
    if name == "sine":
        return sine(n, seed, noise_var=params.R, batch=batch)
    if name == "random-accel":
        return random_accel(n, seed, q=params.Q, noise_var=params.R, T=params.T, batch=batch)
    raise ValueError(f"scenario must be one of {', '.join(SCENARIOS)}, not {name!r}")


def threshold_codes(seed, n, threshold, *, hold=12):
    """Codes at an outlier test's boundary: levels held for ``hold`` samples (12: the medians
    and the Hanning value of their middle are the level itself; 24 for two channels taking
    turns), each with one spike ``level + d`` in the middle, ``|d|`` = ``threshold`` - 2 ..
    ``threshold`` + 2 (an integer threshold: rounded down) of either sign: a comparison or an
    absolute value a few codes off decides some of them the other way."""
    rng = np.random.default_rng(seed)
    t = int(threshold)
    levels = rng.integers(CODE_MIN + t + 3, CODE_MAX - t - 2, n // hold + 1)
    y = np.repeat(levels, hold)[:n]
    offsets = rng.choice([t - 2, t - 1, t, t + 1, t + 2], len(levels)) * rng.choice([-1, 1], len(levels))
    spikes = np.arange(hold // 2, n, hold)
    y[spikes] += offsets[: len(spikes)]
    return y.astype(np.int64)


def stress_codes(seed, n):
    """Codes that exercise a filter's corners: random walk + noise, full-scale steps both ways,
    a full-scale square wave (its overshoot saturates the innovation), extreme codes at random."""
    rng = np.random.default_rng(seed)
    y = np.cumsum(rng.normal(0, 300, n)) + rng.normal(0, 40, n)
    y = np.clip(np.round(y), CODE_MIN, CODE_MAX)
    k = n // 8
    y[k:k + 30] = CODE_MAX
    y[k + 30:k + 60] = CODE_MIN
    square = np.tile(np.repeat([CODE_MAX, CODE_MIN], 5), 20)
    y[2 * k:2 * k + len(square)] = square[: max(0, min(len(square), n - 2 * k))]
    y[rng.integers(0, n, max(n // 50, 1))] = CODE_MIN
    y[rng.integers(0, n, max(n // 50, 1))] = CODE_MAX
    return y.astype(np.int64)
