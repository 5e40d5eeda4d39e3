"""Test signals in ADC codes: the truth and what a 16-bit ADC would deliver.

Every generator takes a seed; callers print it so a run can be replayed.
"""

from __future__ import annotations

import numpy as np

from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.errors import UsageError

__all__ = ["SCENARIOS", "sine", "random_accel", "model_walk", "adc_codes", "make", "for_config", "stress_codes",
           "threshold_codes", "process_noise", "rail_count", "check_rails", "ScenarioError", "MAX_RAIL_SHARE"]

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
    """A rate driven by white noise of variance ``q`` per sample (the filter's own model: the rate a
    random walk, ``x2 += w``), with a weak, critically damped pull toward zero.

    A pure random walk of the rate leaves the ADC range within a few thousand samples; the pull
    keeps the position's standard deviation near ``spread`` at any sample period T (its natural
    frequency ``w`` per unit time follows from the noise intensity ``q / T``). It is small next to
    the noise (about 1 % of its standard deviation), so the filter's model still holds.
    """
    rng = np.random.default_rng(seed)
    # stationary std of a critically damped oscillator driven by white noise of intensity
    # q / T per unit time: sqrt((q / T) / (4 w^3)) = spread
    w = (q / (4.0 * T * spread**2)) ** (1.0 / 3.0)
    x1 = np.zeros(batch)
    x2 = np.zeros(batch)
    truth = np.empty((*batch, n))
    acc = rng.normal(0.0, np.sqrt(q), (*batch, n))
    for k in range(n):
        truth[..., k] = x1
        x1 = x1 + T * x2
        x2 = x2 + acc[..., k] - T * (w * w * truth[..., k] + 2.0 * w * x2)
    y = adc_codes(truth + rng.normal(0.0, np.sqrt(noise_var), (*batch, n)))
    return truth, y


def model_walk(n, seed, *, q=2.0, noise_var=4.0, T=1.0, batch=()):
    """The constant-velocity model itself: ``x1 += T x2``, ``x2 += w``, ``w ~ N(0, q)``, from 0; the
    whole track scaled by one factor when it would pass 3/4 of the ADC's range (the process noise
    is then smaller than the model's by the square of that factor)."""
    rng = np.random.default_rng(seed)
    x2 = np.cumsum(rng.normal(0.0, np.sqrt(q), (*batch, n)), axis=-1)
    truth = np.concatenate([np.zeros((*batch, 1)), T * np.cumsum(x2, axis=-1)[..., :-1]], axis=-1)
    peak = float(np.max(np.abs(truth))) if n else 0.0
    if peak > 0.75 * CODE_MAX:
        truth *= 0.75 * CODE_MAX / peak
    y = adc_codes(truth + rng.normal(0.0, np.sqrt(noise_var), (*batch, n)))
    return truth, y


def process_noise(params):
    """The rate's noise per sample of a constant-velocity model: its ``Q``, or for a tracker given by
    its gains (alpha, beta) the noise for which they are the steady-state Kalman gains
    (``beta^2 / (1 - alpha) = q T^2 / R``, the tracking index)."""
    if hasattr(params, "Q"):
        return float(params.Q)
    return params.R * params.beta ** 2 / ((1.0 - min(params.alpha, 0.999)) * params.T ** 2)


SCENARIOS = {"sine": sine, "random-accel": random_accel, "model": model_walk}
#: Largest share of a scenario's samples allowed at the ADC's rails (clipped): beyond it the
#: scenario is refused, as it would test the rails, not the filter.
MAX_RAIL_SHARE = 0.02


class ScenarioError(UsageError):
    """A scenario that does not fit the ADC's range for this model (a one-line error)."""


def rail_count(codes):
    """Samples of ``codes`` (an array, or ``{input: array}``) at the ADC's rails."""
    arrays = codes.values() if isinstance(codes, dict) else [codes]
    return int(sum(np.count_nonzero((np.asarray(a) <= CODE_MIN) | (np.asarray(a) >= CODE_MAX)) for a in arrays))


def check_rails(name, codes):
    """The samples of scenario ``name`` at the ADC's rails; :class:`ScenarioError` beyond
    :data:`MAX_RAIL_SHARE` of them."""
    count = rail_count(codes)
    total = sum(np.size(a) for a in (codes.values() if isinstance(codes, dict) else [codes]))
    if total and count > MAX_RAIL_SHARE * total:
        raise ScenarioError(f"scenario {name} drives the ADC to its rails on {count} of {total} samples "
                            f"({100 * count / total:.1f} %, at most {100 * MAX_RAIL_SHARE:g} %): its track leaves the "
                            "16-bit range for this model; choose another scenario, or your own --input")
    return count


def for_config(name, n, seed, config):
    """``(truth, codes)`` of scenario ``name`` for a config: its filter's own scenarios when it has
    them (``FilterSpec.scenario``), else :func:`make` on one input."""
    if config.spec.model.scenario is not None:
        return config.spec.model.scenario(name, n, seed, config.params)
    return make(name, n, seed, config.params)


def make(name, n, seed, params, batch=()):
    """``(truth, y)`` of scenario ``name`` for a constant-velocity model ``params`` (T, R, and Q or
    the gains: :func:`process_noise`; the noise variance is R)."""
    if name == "sine":
        return sine(n, seed, noise_var=params.R, batch=batch)
    if name == "random-accel":
        return random_accel(n, seed, q=process_noise(params), noise_var=params.R, T=params.T, batch=batch)
    if name == "model":
        return model_walk(n, seed, q=process_noise(params), noise_var=params.R, T=params.T, batch=batch)
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
