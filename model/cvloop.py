"""The constant-velocity loop of the paper's 2-state filter and of the alpha-beta tracker.

Both filters run in the datapath's units (the position ``x1`` and the rate per sample
``v = T*x2``, so T never multiplies inside the loop) and share this loop::

    xl1 = [x1 + v]_xl1          e = [y - xl1]_e
    x1  = [xl1 + k1*e]_x1       v = [v + k2*e]_v          x2 = v / T

with constant gains (the steady-state Kalman filter is an alpha-beta filter with
``alpha = K1``, ``beta = T*K2``), or, in the paper's time-varying variant, the divider's
quotients. Here are the quantisation points, the stage functions and the format rules they
share; each filter's own file (``model/kalman2.py``, ``model/alphabeta.py``) adds its gains.

The output ``x2 = v / T`` is ``[v]_x2`` read with the binary point moved by k when ``T = 2**k``
(a shift), else ``[[v]_vt * (1/T)]_x2`` with ``1/T`` rounded into ``inv_t`` and ``v`` rounded
into the 18-bit operand ``vt`` first.
"""

from __future__ import annotations

import math

from kfpga.core.board import WORST_PATH_GOAL_NS
from kfpga.core.fixed import QFormat, Rounding
from kfpga.core.formats import noise_frac_bits
from kfpga.core.spec import Constant, Point
from kfpga.model import start
from kfpga.model.reference import steady_state_gain
from kfpga.model.riccati import loop_frac_bits

__all__ = ["POINTS", "LOOP_POINTS", "t_exponent", "steady_gain", "predict", "innovation", "correct", "rate_operand",
           "rate_product", "rate_write", "rate", "rate_constants", "finish_formats", "steady_goals", "stressed", "measured_start",
           "loop_formats"]

#: The points of the paper's filter; the loop's are :data:`LOOP_POINTS`.
POINTS = {
    p.name: p
    for p in (
        Point("x1", "filtered position x1 (state, output)"),
        Point("xl1", "predicted position xl1 = x1 + v (output yhat)", same_as="x1"),
        Point("v", "rate per sample v = T*x2 (state)"),
        Point("x2", "rate output x2 = v / T"),
        Point("e", "innovation e = y - xl1", role="operand"),
        Point("gain", "gains K1, T*K2 (constants, or the divider's quotients)", role="operand"),
        Point("p", "covariance p11, p12, p21, p22 (state)", variants=("full",), frac="pl"),
        Point("pl", "predicted covariance pl11..pl22", role="operand", variants=("full",)),
        Point("s", "innovation covariance S = pl11 + R (divisor)", variants=("full",), frac="pl"),
        Point("inv_t", "1/T, when T is not a power of two", role="operand", constant=True),
        Point("vt", "rate operand of x2 = v * (1/T), when T is not a power of two", role="operand"),
    )
}


#: The points of the constant-gain loop (no covariance).
LOOP_POINTS = ("x1", "xl1", "v", "x2", "e", "gain", "inv_t", "vt")


def t_exponent(T):
    """``k`` if ``T == 2**k`` exactly, else ``None``."""
    mantissa, exponent = math.frexp(T)
    return exponent - 1 if mantissa == 0.5 else None


def steady_gain(params):
    """Float ``(K1, T*K2)`` of the steady-state filter of the 2-state model ``params`` (T, Q, R), in
    datapath units."""
    (k1, k2), _ = steady_state_gain(params.T, params.Q, params.R)
    return k1, k2 * params.T


# -- the equations ------------------------------------------------------------------------------


def predict(ops, x1, v):
    """xl1 = x1 + v: the predicted position, also the one-step output prediction yhat."""
    return ops.rq(ops.add(x1, v), "xl1")


def innovation(ops, y, xl1):
    """e = y - xl1."""
    return ops.rq(ops.sub(y, xl1), "e")


def correct(ops, x, ke, point):
    """x = x + K e (a state corrected by a gain-times-innovation product)."""
    return ops.rq(ops.add(x, ke), point)


def measured_start(ops, k, x, y, x1, v):
    """``(x1, v, {"start": count})`` with the start from the measurements (``model/start.py``)
    when the constants ``k`` have it: x1 = y on samples 0 and 1, v = y - x1 (the previous x1,
    which is y0) on sample 1; else ``(x1, v, {})`` unchanged."""
    if "start" not in k:
        return x1, v, {}
    starting, second, count = start.phase(ops, k, x["start"])
    x1 = ops.select(starting, ops.rq(y, "x1", "x1_start"), x1)                        # x1 = y
    v = ops.select(second, ops.rq(ops.sub(y, x["x1"]), "v", "v_start"),            # v = y1 - y0
                   ops.select(starting, x["v"], v))
    return x1, v, {"start": count}


def rate_operand(ops, k, v):
    """The first step of x2 = v / T: v with its binary point moved by k when T = 2**k, else v
    rounded into the 18-bit multiplier operand vt."""
    if k["t_shift"] is not None:
        return ops.shift(v, -k["t_shift"])
    return ops.rq(v, "vt")


def rate_product(ops, k, vt):
    """The second step: nothing when T = 2**k, else the product vt * (1/T)."""
    return vt if k["t_shift"] is not None else ops.mul(vt, k["inv_t"])


def rate_write(ops, k, value):
    """The last step: the rate written into x2."""
    return ops.rq(value, "x2")


def rate(ops, k, v):
    """x2 = v / T: the binary point moved when T = 2**k, else [v]_vt * (1/T)."""
    return rate_write(ops, k, rate_product(ops, k, rate_operand(ops, k, v)))


def rate_constants(params):
    """The constants of x2 = v / T: the shift when T = 2**k, else 1/T rounded into ``inv_t``."""
    shift = t_exponent(params.T)
    out = {"t_shift": shift}
    if shift is None:
        out["inv_t"] = Constant(1.0 / params.T, "inv_t", "1/T")
    return out


def finish_formats(params, formats, *, state_frac):
    """The rules of the innovation and the rate output on top of the register rules, for the
    filters of this loop (this one and the alpha-beta tracker): ``params`` has T and R."""
    # the innovation's step small against the measurement noise (more than the multiplier's 18
    # bits then: a second multiplier piece per product), but no finer than the states
    e = formats["e"]
    want = min(max(e.frac_bits, noise_frac_bits(params.R)), max(e.frac_bits, state_frac))
    if want > e.frac_bits:
        formats["e"] = QFormat(e.int_bits, want, e.rounding, e.overflow)
    k = t_exponent(params.T)
    fv = formats["v"]
    if k is not None and fv.int_bits - k >= 1 and fv.frac_bits + k >= 0:
        # x2 = v / 2**k: the same bits, the binary point moved (a free shift)
        formats["x2"] = QFormat(fv.int_bits - k, fv.frac_bits + k, Rounding.NEAREST)
    return formats


def loop_formats(formats, gain, floors):
    """x1 (and xl1) and v fine enough for the rounding the loop feeds back
    (:func:`~kfpga.model.riccati.loop_frac_bits` with ``Phi = [[1, 1], [0, 1]]`` in the datapath's
    units): ``gain`` the loop's ``(k1, k2)``, ``floors`` the float filter's error of x1 and v."""
    needs = loop_frac_bits([[1.0, 1.0], [0.0, 1.0]], [[1.0, 0.0]], [[gain[0]], [gain[1]]], floors)
    for names, need in ((("x1", "xl1"), needs[0]), (("v",), needs[1])):
        fmt = formats[names[0]]
        if need is not None and need > fmt.frac_bits:
            for name in names:
                formats[name] = QFormat(formats[name].int_bits, need, formats[name].rounding, formats[name].overflow)
    return formats


def steady_goals(config, channels=1):
    """The constant-gain loop's goals: 400 logic cells for one channel, about 150 more per further
    channel state (three cells per state bit of x1 and v: 51 bits, for the registers, their read
    mux and write enable); two multipliers (none for a power-of-two gain), one more when T is not
    a power of two; every path within the timing goal. The start from the first measurements
    (``init = "measurement"``) adds its multiplexers and subtraction (150 cells) and a 2-bit count
    and a wider v per channel (20 more each)."""
    started = start.measured(config.params)
    return {"logic_cells": 400 + 150 * (channels - 1) + (150 + 20 * (channels - 1) if started else 0),
            "mul18": 2 + (0 if t_exponent(config.params.T) is not None else 1), "lut_levels": 16,
            "worst_path_ns": WORST_PATH_GOAL_NS}


def stressed(config, e_bits):
    """``config`` with the loop's state narrower than its range (x1 and xl1 Q15, v Q12, e Q``e_bits``):
    at the defaults no stress sample saturates xl1, x1 or v, whose saturation logic no bench could
    then reach; so narrowed, each of the four writes saturates, some samples with no other (its own
    flag alone on the estimate), in 1,200 stress samples (``make mutate``)."""
    from kfpga.core.config import FilterConfig

    narrow = {"x1": 15, "xl1": 15, "v": 12, "e": e_bits}
    return FilterConfig(filter=config.filter, params=config.params, check_ranges=False,
                        formats={**config.formats, **{p: QFormat(i, config.formats[p].frac_bits) for p, i in narrow.items()}})
