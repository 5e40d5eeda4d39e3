"""Range analysis: the largest magnitude every quantisation point reaches in float runs.

The default formats are chosen from these ranges (plus a guard bit), and a user's formats are
checked against them. :func:`float_ranges` runs a filter's own stage functions in float
(:class:`~kfpga.core.compiled.FloatTraceOps`, the compiled form of :class:`~kfpga.core.ops.FloatOps`),
recording every value written into each point, so the ranges come from exactly the arithmetic
the hardware does, without its rounding. The stimulus covers the whole
input range of the 16-bit ADC, driven the way real signals use it: full-scale steps in both
directions from a settled state, a full-scale sine with noise, and the demo sine. The noise
generator has a fixed seed (:data:`RANGE_SEED`) so that the default formats never change from
one run to the next.
"""

from __future__ import annotations

import numpy as np

from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.compiled import compile_float_ranges

__all__ = ["RANGE_SEED", "SEGMENT", "full_scale_stimulus", "float_ranges"]

RANGE_SEED = 20080525
#: Samples per stimulus segment; long enough for the default filter to settle many times over.
SEGMENT = 4096


def full_scale_stimulus(noise_var, segment=SEGMENT):
    """Stimulus rows, shape ``(4, 2*segment)``: step up, step down, full-scale sine, demo sine.

    The sines carry white noise of variance ``noise_var`` (the filter's R).
    """
    rng = np.random.default_rng(RANGE_SEED)
    n = 2 * segment
    t = np.arange(n)
    sigma = np.sqrt(noise_var)
    step_up = np.where(t < segment, CODE_MIN, CODE_MAX).astype(np.float64)
    step_down = -step_up - 1.0
    amplitude = CODE_MAX - 6.0 * sigma
    sine = np.clip(np.round(amplitude * np.sin(2 * np.pi * t / 2000.0) + rng.normal(0, sigma, n)), CODE_MIN, CODE_MAX)
    demo = np.clip(np.round(8192.0 * np.sin(2 * np.pi * t / 2000.0) + rng.normal(0, sigma, n)), CODE_MIN, CODE_MAX)
    return np.stack([step_up, step_down, sine, demo])


def float_ranges(spec, params, variants, stimulus):
    """``{point: largest magnitude}`` over ``variants`` of ``spec`` run in float on ``stimulus``.

    ``stimulus`` is ``{input name: array (rows, steps)}``, or one array when the filter has one
    input. The reset state counts as a value of its point; so do the constants.
    """
    names = [name for name, _ in spec.inputs_for(params)]
    if not isinstance(stimulus, dict):
        stimulus = {names[0]: np.atleast_2d(np.asarray(stimulus, dtype=np.float64))}
    rows = [np.asarray(stimulus[n], dtype=np.float64) for n in names]
    ranges = {}

    def merge(found):
        for name, value in found.items():
            ranges[name] = max(value, ranges.get(name, 0.0))

    for variant in variants:
        run = compile_float_ranges(variant.update, constants=variant.constants(params), state=variant.state_for(params),
                                   inputs=names)
        initial = variant.initial(params)
        points = dict(variant.state_for(params))
        for name, value in initial.items():
            merge({points[name]: abs(value)})
        for r in range(rows[0].shape[0]):
            ys = rows[0][r].tolist() if len(rows) == 1 else list(zip(*(a[r].tolist() for a in rows), strict=True))
            merge(run(ys, initial))
    return ranges
