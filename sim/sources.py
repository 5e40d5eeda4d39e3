"""Analog signal sources for the ADS8364 model: six channels, one value per sampling instant."""

from __future__ import annotations

import numpy as np

from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.csvio import read_header, read_samples
from kfpga.core.errors import InputError
from kfpga.model import scenarios
from kfpga.model.reference import KalmanParams
from kfpga.model.scenarios import stress_codes, threshold_codes

__all__ = ["Source", "scenario_source", "csv_source", "stress_codes", "threshold_codes"]


class Source:
    """Pre-computed codes ``(6, n)`` handed out one column per conversion.

    ``glitches`` maps a conversion index to ``(channel, code)``: that sample is replaced, e.g.
    by a full-scale spike, to model an ADC glitch. Past the end, the codes repeat from the
    start (long simulations of a short recording).
    """

    def __init__(self, codes, *, truth=None, glitches=None, name="source"):
        codes = np.asarray(codes, dtype=np.int64)
        if codes.ndim != 2 or codes.shape[0] != 6 or codes.shape[1] == 0:
            raise ValueError(f"codes must have shape (6, n) with n > 0, not {codes.shape}")
        if codes.min() < CODE_MIN or codes.max() > CODE_MAX:
            raise ValueError("codes must be signed 16-bit values")
        self.codes = codes
        self.truth = truth
        self.glitches = dict(glitches or {})
        self.name = name
        self.index = 0

    def next(self):
        k = self.index
        column = self.codes[:, k % self.codes.shape[1]].copy()
        if k in self.glitches:
            channel, code = self.glitches[k]
            column[channel] = code
        self.index += 1
        return column

    def expected(self, count):
        """The first ``count`` columns this source hands out (glitches included)."""
        cols = [self.codes[:, k % self.codes.shape[1]].copy() for k in range(count)]
        for k, (channel, code) in self.glitches.items():
            if k < count:
                cols[k][channel] = code
        return np.array(cols).T


def scenario_source(name, n, seed, params=None, *, glitches=None, config=None, adc=None, sensors=1):
    """Six channels of scenario ``name``: independent noise, channel c phase-shifted by c/6 turn.

    The phase shift keeps the channels distinguishable, so a channel mix-up cannot go unseen.
    A ``config`` whose filter has scenarios of its own (``FilterSpec.scenario``) gets six runs of
    them, seeded apart; with several inputs the first run's observations go on the ADC
    channels ``adc`` (one per input) and its truth with them. With ``sensors`` on a multiplexer
    in front of ADC channel ``adc[0]``, each sensor its own run (:func:`sensor_source`).
    """
    if sensors > 1:
        count = -(-n // sensors)
        codes, truths = _runs(name, count, seed, config, params, sensors)
        return sensor_source(codes, truths, adc[0] if adc else 0, name=f"{name} (seed {seed}), {sensors} sensors")
    if config is not None and config.spec.model.scenario is not None:
        return _spec_source(name, n, seed, config, adc, glitches)
    codes, truths = _runs(name, n, seed, config, params, 6)
    return Source(codes, truth=truths, glitches=glitches, name=f"{name} (seed {seed})")


def _runs(name, n, seed, config, params, count):
    """``(codes, truths)``, each ``(count, n)``: ``count`` runs of scenario ``name`` of one input,
    the filter's own scenarios seeded apart, or the generic ones as one run, each row shifted by
    337 samples (distinct waveforms from one seeded run)."""
    if config is not None and config.spec.model.scenario is not None:
        codes, truths = np.zeros((count, n), dtype=np.int64), np.zeros((count, n))
        for c in range(count):
            truth, y = config.spec.model.scenario(name, n, seed + 1009 * c, config.params)
            scenarios.check_rails(name, y)
            codes[c], truths[c] = (next(iter(y.values())) if isinstance(y, dict) else y), truth
        return codes, truths
    params = KalmanParams() if params is None else params
    truth, y = scenarios.make(name, n + count * 337, seed, params, batch=(count,))
    scenarios.check_rails(name, y)
    return (np.stack([y[c, c * 337: c * 337 + n] for c in range(count)]),
            np.stack([truth[c, c * 337: c * 337 + n] for c in range(count)]))


def sensor_source(codes, truths, channel, *, name):
    """The source of ``len(codes)`` sensors taking turns on ADC channel ``channel`` through a
    multiplexer, from reset: conversion ``j`` converts sensor ``j % N``'s sample ``j // N``.
    Its truth is ``(N, conversions)``, row ``s`` sensor s's truth at each conversion (read where
    the conversion is sensor s's)."""
    count, n = codes.shape
    order = np.arange(count * n)
    column = np.zeros((6, count * n), dtype=np.int64)
    column[channel] = codes[order % count, order // count]
    truth = None if truths is None else np.repeat(np.asarray(truths, dtype=np.float64), count, axis=1)
    return Source(column, truth=truth, name=name)


def _spec_source(name, n, seed, config, adc, glitches):
    codes, truths = np.zeros((6, n), dtype=np.int64), np.zeros((6, n))
    first = None
    for c in range(6):
        truth, y = config.spec.model.scenario(name, n, seed + 1009 * c, config.params)
        scenarios.check_rails(name, y)
        first = (truth, y) if first is None else first
        codes[c] = next(iter(y.values())) if isinstance(y, dict) else y
        truths[c] = truth
    truth, y = first
    if isinstance(y, dict):
        for channel, obs in zip(adc, config.inputs, strict=True):
            codes[channel], truths[channel] = y[obs], truth
    return Source(codes, truth=truths, glitches=glitches, name=f"{name} (seed {seed})")


def csv_source(path, *, clip=False, config=None, adc=None, sensors=1):
    """Replay a CSV: columns ``y0``..``y5`` if present, else the ``y`` column on all six. A
    ``config`` with several inputs reads their columns (the observation names) onto the ADC
    channels ``adc``, one per input. ``sensors`` on a multiplexer read columns ``y0`` ..
    ``y<N-1>``, one row a sample of each (:func:`sensor_source`). The truth, for the RMSE
    figures: a ``truth`` column with ``y`` or the inputs; ``truth0``.. with ``y0``.. ."""
    header = read_header(path)
    if sensors > 1:
        missing = [f"y{s}" for s in range(sensors) if f"y{s}" not in header]
        if missing:
            raise InputError(f"{path}: {sensors} sensors on a multiplexer replay columns y0..y{sensors - 1}, one per "
                             f"sensor; the header lacks {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}")
        codes = np.stack([read_samples(path, clip=clip, column=f"y{s}").y for s in range(sensors)])
        truths = _truths(path, header, [f"truth{s}" for s in range(sensors)])
        return sensor_source(codes, truths, adc[0] if adc else 0, name=f"csv {path}, {sensors} sensors")
    if config is not None and len(config.inputs) > 1:
        samples = read_samples(path, clip=clip, columns=config.inputs)
        codes = np.zeros((6, len(samples)), dtype=np.int64)
        truth = None if samples.truth is None else np.zeros((6, len(samples)))
        for channel, obs in zip(adc, config.inputs, strict=True):
            codes[channel] = samples.codes[obs]
            if truth is not None:
                truth[channel] = samples.truth
        return Source(codes, truth=truth, name=f"csv {path}")
    if all(f"y{c}" in header for c in range(6)):
        codes = np.stack([read_samples(path, clip=clip, column=f"y{c}").y for c in range(6)])
        truth = _truths(path, header, [f"truth{c}" for c in range(6)])
    else:
        samples = read_samples(path, clip=clip)
        codes = np.tile(samples.y, (6, 1))
        truth = None if samples.truth is None else np.tile(samples.truth, (6, 1))
    return Source(codes, truth=truth, name=f"csv {path}")


def _truths(path, header, names):
    """The truth columns ``names`` of a file (one per channel or sensor) as rows, or ``None``
    when the file lacks any of them."""
    from kfpga.core.csvio import read_series

    if not all(name in header for name in names):
        return None
    return np.stack([read_series(path, column=name) for name in names])
