"""A start from the first measurements (``[model] init = "measurement"``), shared by the filters
that have one.

After reset a filter's state is ``x0``. Far from the signal, or with small gains (a small Q
against R, a short sample period), it takes the filter hundreds of samples to forget that
guess. With ``init = "measurement"`` the state comes from the first samples instead: each
position a sensor observes is set from the first sample, each rate from the first two::

    sample 0:  position = y0 / h                  (the rates keep x0's)
    sample 1:  position = y1 / h,  rate = (y1 / h - position) / F[position][rate]

and the update runs as usual from sample 2 on. The covariance of a time-varying filter runs
from ``P0`` throughout (give P0 the start's own variance, about R for a position and 2R/T**2
for a rate, for gains that trust the start from the first update).

The samples of the start are counted in a 2-bit state ``start``: 0 before the first sample,
1 before the second, -1 from then on (reset sets it to 0 with the other states). Two
comparisons and a multiplexer per state written by the start: no divider, no extra multiplier
in the program of the folded core, which runs it; the parallel cores, hand-pipelined for
one update form, refuse it.
"""

from __future__ import annotations

from kfpga.core.fixed import QFormat
from kfpga.core.spec import Constant

__all__ = ["INITS", "START", "check_init", "measured", "start_state", "start_constants", "phase", "start_samples",
           "hardware", "float_start", "measured_start_float"]

#: The values of ``[model] init``: from the state ``x0`` (the default), or from the first samples.
INITS = ("state", "measurement")
#: The format of the start's count: 0, 1, then -1.
START = QFormat(2, 0)


def check_init(value):
    """``init`` validated (``TypeError``/``ValueError`` naming the field)."""
    if not isinstance(value, str):
        raise TypeError(f"init must be a string ({' or '.join(map(repr, INITS))}), not {value!r}")
    if value not in INITS:
        raise ValueError(f"init must be {' or '.join(map(repr, INITS))}, not {value!r}")
    return value


def measured(params):
    """Whether these parameters start from the measurements."""
    return getattr(params, "init", "state") == "measurement"


def start_state(params):
    """The state the start adds: ``(("start", START),)``, or nothing."""
    return (("start", START),) if measured(params) else ()


def start_constants(params):
    """The constants of the count (none without the start)."""
    if not measured(params):
        return {}
    return {"start": True, "start_zero": Constant(0.0, START, "0"), "start_one": Constant(1.0, START, "1"),
            "start_done": Constant(-1.0, START, "-1")}


def phase(ops, k, count):
    """``(starting, second, next count)``: the conditions "this is sample 0 or 1" and "this is
    sample 1", and the count after this sample."""
    starting = ops.gt(count, k["start_done"])                                 # count >= 0
    second = ops.gt(count, k["start_zero"])                                   # count == 1
    nxt = ops.select(starting, ops.select(second, k["start_done"], k["start_one"]), k["start_done"])
    return starting, second, nxt


def start_samples(params):
    """The samples the start takes over (0 without it)."""
    return 2 if measured(params) else 0


def hardware(params):
    """Why the parallel core cannot run these parameters' start, or ``None``."""
    if measured(params):
        return ('model.init = "measurement": the start from the first samples runs on the folded core '
                "(--architecture folded); the parallel cores start from x0")
    return None


def float_start(count, ys, prev, new, positions, rates):
    """The float filter's state after sample ``count`` (0 or 1) of the start.

    ``ys``: the samples (one per observation); ``prev``, ``new``: the states before this sample
    and after the usual update (sequences of floats or arrays); ``positions``: ``{state j: (observation
    i, h)}``, the states a sensor observes (``y_i = h x_j``); ``rates``: ``{state r: (position j,
    f)}``, the states that move a position (``x_j += f x_r``). On sample 0 the positions are
    set and every other state keeps its value; on sample 1 the positions are set, the rates are
    the difference over ``f``, the other states take the usual update."""
    out = list(prev if count == 0 else new)
    for j, (i, h) in positions.items():
        out[j] = ys[i] / h
    if count == 1:
        for r, (j, f) in rates.items():
            out[r] = (ys[positions[j][0]] / positions[j][1] - prev[j]) / f
    return out


def measured_start_float(params, count, y, x1_prev, x2_prev, x1, x2):
    """:func:`float_start` of the 2-state loops (position x1 observed, rate x2 with ``x1 += T x2``):
    ``(x1, x2)`` after sample ``count``; unchanged without the start or after it."""
    if not measured(params) or count > 1:
        return x1, x2
    return tuple(float_start(count, (y,), (x1_prev, x2_prev), (x1, x2), {0: (0, 1.0)}, {1: (0, params.T)}))
