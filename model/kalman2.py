"""The paper's 2-state Kalman filter ([Zhong]): its equations, once, and its spec.

Both variants run in the datapath's units (``v = T*x2``, ``P' = D P D``, see
:meth:`~kfpga.model.reference.KalmanParams.scaled`), so T never multiplies inside the loop.
Every quantity written to a register is an exact sum or product written once into the format
of its quantisation point (:data:`POINTS`), with that format's rounding and overflow rule.
The stage functions below are that arithmetic; the bit-accurate model (``kfpga/core/fixedmodel.py``),
the RTL cores (``hw/kalman2.py``), the range analysis, the width checks and the exact-rational
spec all run these same functions.

Steady state (constant gains ``k1 = K1``, ``k2 = T*K2``, rounded into ``gain``)::

    xl1 = [x1 + v]_xl1          e = [y - xl1]_e
    x1  = [xl1 + k1*e]_x1       v = [v + k2*e]_v          yhat = xl1

Time-varying (the paper's equations with its two misprints corrected; ``Q' = T^2 Q`` in ``pl``,
``R`` in ``s``)::

    xl1  = [x1 + v]_xl1
    pl11 = [p11 + p12 + p21 + p22]_pl    pl12 = [p12 + p22]_pl
    pl21 = [p21 + p22]_pl                pl22 = [p22 + Q']_pl
    S    = [pl11 + R]_s
    K1   = div(pl11, S)                  K2   = div(pl21, S)
    e    = [y - xl1]_e
    x1   = [xl1 + K1*e]_x1               v    = [v + K2*e]_v
    p11  = [pl11 - K1*pl11]_p            p12  = [pl12 - K1*pl12]_p
    p21  = [pl21 - K2*pl11]_p            p22  = [pl22 - K2*pl12]_p

``div(n, d)`` is the restoring divider (:meth:`kfpga.core.ops.Ops.div`): ``|n|/d`` truncated to
``gain.frac_bits``, saturated to ``gain``'s largest value, given the sign of ``n``.

The output ``x2 = v / T`` is ``[v]_x2`` read with the binary point moved by k when ``T = 2**k``
(a shift), else ``[[v]_vt * (1/T)]_x2`` with ``1/T`` rounded into ``inv_t`` and ``v`` rounded
into the 18-bit operand ``vt`` first. Any saturation (or wrap) sets the sample's overflow flag.
"""

from __future__ import annotations

import numpy as np

from kfpga.core.board import WORST_PATH_GOAL_NS
from kfpga.core.errors import ConfigError
from kfpga.core.fixed import QFormat
from kfpga.core.formats import MAX_WORD, covariance_frac, register_formats
from kfpga.core.spec import Constant, Docs, FilterSpec, Hardware, Model, MutationBlock, Output, Variant
from kfpga.model import start
from kfpga.model.cvloop import (
    POINTS,
    correct,
    finish_formats,
    innovation,
    loop_formats,
    measured_start,
    predict,
    rate,
    rate_constants,
    steady_gain,
    steady_goals,
    stressed,
    t_exponent,
)
from kfpga.model.ranges import float_ranges, full_scale_stimulus
from kfpga.model.reference import KalmanParams, kalman_decomposed, steady_error_std, steady_state, steady_state_gain

__all__ = ["SPEC", "VARIANTS", "reference", "covariance_predict", "innovation_variance", "gains", "covariance_correct",
           "full_products", "steady_update", "full_update", "steady_predict", "full_predict"]



# -- the equations -------------------------------------------------------------------------------


def covariance_predict(ops, k, p11, p12, p21, p22):
    """P' = Phi P Phi^T + G Q G^T in datapath units (Phi = [[1, 1], [0, 1]])."""
    pl11 = ops.rq(ops.add(ops.add(ops.add(p11, p12), p21), p22), "pl", "pl11")   # pl11 = p11 + p12 + p21 + p22
    pl12 = ops.rq(ops.add(p12, p22), "pl", "pl12")                                # pl12 = p12 + p22
    pl21 = ops.rq(ops.add(p21, p22), "pl", "pl21")                                # pl21 = p21 + p22
    pl22 = ops.rq(ops.add(p22, k["q"]), "pl", "pl22")                             # pl22 = p22 + Q'
    return pl11, pl12, pl21, pl22


def innovation_variance(ops, k, pl11):
    """S = pl11 + R."""
    return ops.rq(ops.add(pl11, k["r"]), "s")


def gains(ops, pl11, pl21, s):
    """K1 = pl11 / S, K2 = pl21 / S (both by the restoring divider)."""
    return ops.div(pl11, s, "gain", "K1"), ops.div(pl21, s, "gain", "K2")


def covariance_correct(ops, pl, products):
    """P = P' - K C P': p11 = pl11 - K1 pl11, p12 = pl12 - K1 pl12, p21 = pl21 - K2 pl11,
    p22 = pl22 - K2 pl12 (``products`` = K1 pl11, K1 pl12, K2 pl11, K2 pl12)."""
    return tuple(ops.rq(ops.sub(a, b), "p", f"p{n}") for a, b, n in zip(pl, products, ("11", "12", "21", "22"),
                                                                           strict=True))


def full_products(ops, k1, k2, e, pl11, pl12):
    """The six products of the time-varying measurement update."""
    return ops.mul(k1, e), ops.mul(k2, e), (ops.mul(k1, pl11), ops.mul(k1, pl12), ops.mul(k2, pl11), ops.mul(k2, pl12))


def steady_update(ops, k, x, u):
    """One steady-state update: ``(next state, outputs)``."""
    xl1 = predict(ops, x["x1"], x["v"])                             # xl1 = x1 + v
    e = innovation(ops, u["y"], xl1)                                # e = y - xl1
    x1 = correct(ops, xl1, ops.mul(k["k1"], e), "x1")               # x1 = xl1 + K1 e
    v = correct(ops, x["v"], ops.mul(k["k2"], e), "v")              # v = v + T K2 e
    x1, v, count = measured_start(ops, k, x, u["y"], x1, v)         # init = "measurement"
    return {"x1": x1, "v": v, **count}, {"x1": x1, "x2": rate(ops, k, v), "yhat": xl1}


def full_update(ops, k, x, u):
    """One time-varying update: ``(next state, outputs)``."""
    xl1 = predict(ops, x["x1"], x["v"])                             # xl1 = x1 + v
    pl = covariance_predict(ops, k, x["p11"], x["p12"], x["p21"], x["p22"])
    s = innovation_variance(ops, k, pl[0])                          # S = pl11 + R
    k1, k2 = gains(ops, pl[0], pl[2], s)                            # K = [pl11, pl21] / S
    e = innovation(ops, u["y"], xl1)                                # e = y - xl1
    k1e, k2e, pk = full_products(ops, k1, k2, e, pl[0], pl[1])
    x1 = correct(ops, xl1, k1e, "x1")                               # x1 = xl1 + K1 e
    v = correct(ops, x["v"], k2e, "v")                              # v = v + K2 e
    x1, v, count = measured_start(ops, k, x, u["y"], x1, v)         # init = "measurement"
    p11, p12, p21, p22 = covariance_correct(ops, pl, pk)
    state = {"x1": x1, "v": v, "p11": p11, "p12": p12, "p21": p21, "p22": p22, **count}
    return state, {"x1": x1, "x2": rate(ops, k, v), "yhat": xl1}


def _held_start(k, x):
    """The start's count, unchanged by a sample with no measurement."""
    return {"start": x["start"]} if "start" in k else {}


def steady_predict(ops, k, x):
    """A sample with no measurement: ``x = Phi x`` (``x1 = [xl1]_x1``, v held)."""
    xl1 = predict(ops, x["x1"], x["v"])                             # xl1 = x1 + v
    x1 = ops.rq(xl1, "x1")
    return {"x1": x1, "v": x["v"], **_held_start(k, x)}, {"x1": x1, "x2": rate(ops, k, x["v"]), "yhat": xl1}


def full_predict(ops, k, x):
    """A sample with no measurement: ``x = Phi x``, ``P = [Phi P Phi^T + G Q G^T]_p``."""
    state, outs = steady_predict(ops, k, x)
    pl = covariance_predict(ops, k, x["p11"], x["p12"], x["p21"], x["p22"])
    state.update({f"p{n}": ops.rq(v, "p", f"p{n}") for v, n in zip(pl, ("11", "12", "21", "22"), strict=True)})
    return state, outs


# -- what the spec needs -----------------------------------------------------------------------


def _steady_constants(params):
    k1, k2 = steady_gain(params)
    return {"k1": Constant(k1, "gain", "K1"), "k2": Constant(k2, "gain", "T*K2"), **rate_constants(params),
            **start.start_constants(params)}


def _full_constants(params):
    scaled = params.scaled()
    return {"q": Constant(scaled.Q, "pl", "T^2*Q"), "r": Constant(params.R, "s", "R"), **rate_constants(params),
            **start.start_constants(params)}


def _initial(params):
    scaled = params.scaled()
    return {"x1": scaled.x0[0], "v": scaled.x0[1], **({"start": 0.0} if start.measured(params) else {})}


def _full_initial(params):
    scaled = params.scaled()
    (p11, p12), (p21, p22) = scaled.P0
    return {**_initial(params), "p11": p11, "p12": p12, "p21": p21, "p22": p22}


def _full_settled(params):
    """The covariance the time-varying gain settles to, in datapath units (P' = D P D), and the gains
    K1 and T*K2 the divider settles to (each update's quotient holds them as finely)."""
    if not params.Q > 0:
        return []
    k, pl = steady_state_gain(params.T, params.Q, params.R)
    d = np.diag([1.0, params.T])
    c = np.array([[1.0, 0.0]])
    p = (np.eye(2) - np.reshape(k, (2, 1)) @ c) @ pl
    out = []
    for name, m, point in (("P", d @ p @ d, "p"), ("Pl", d @ pl @ d, "pl")):
        out += [(f"{name}{i + 1}{j + 1}", float(m[i][j]), point) for i in range(2) for j in range(2)
                if abs(m[i][j]) > 1e-12 * np.max(np.abs(m))]
    out += [(label, float(value), "gain") for label, value in (("K1", k[0]), ("T*K2", params.T * k[1])) if value > 0]
    return out


def _steady_applies(params):
    if not params.Q > 0:
        return f"model.Q = {params.Q!r}: the steady-state variant needs Q > 0 (Q = 0 gives K_inf = 0)"
    return None


VARIANTS = {
    "steady": Variant("steady", "constant gain K_inf (a fixed-gain filter): one update per sample, no divider",
                      lambda params: (("x1", "x1"), ("v", "v"), *start.start_state(params)), _steady_constants,
                      _initial, steady_update, _steady_applies,  # the loop runs the start (hw/cvloop.py)
                      predict=steady_predict),
    "full": Variant("full", "time-varying gain: covariance and two restoring dividers per update",
                    lambda params: (("x1", "x1"), ("v", "v"), ("p11", "p"), ("p12", "p"), ("p21", "p"), ("p22", "p"),
                                    *start.start_state(params)),
                    _full_constants, _full_initial, full_update, hardware=start.hardware, settled=_full_settled,
                    predict=full_predict),
}


def _points_for(params):
    names = [n for n in POINTS if n not in ("inv_t", "vt")]
    if t_exponent(params.T) is None:
        names += ["inv_t", "vt"]
    return [n for n in POINTS if n in names]


def _ranges(params, stimulus=None):
    """Largest magnitude of each point over both variants (one config serves both)."""
    stimulus = full_scale_stimulus(params.R) if stimulus is None else stimulus
    variants = [v for name, v in VARIANTS.items() if name == "full" or params.Q > 0]
    return float_ranges(SPEC, params, variants, stimulus)


def _default_formats(params, ranges, *, operand_bits, state_frac, max_word=MAX_WORD):
    err = _error_std(params, measurement_only=True)
    # the registers' steps small against the float filter's error there (v = T x2), the part the
    # measurement noise alone causes: the floor of that error on any signal
    noise = ({"x1": min(err["x1"], err["yhat"]), "v": params.T * err["x2"], "vt": params.T * err["x2"], "x2": err["x2"]}
             if err else None)
    formats = register_formats(SPEC, params, ranges, operand_bits=operand_bits, state_frac=state_frac, noise=noise,
                               max_word=max_word)
    if err:  # the rounding the loop feeds back: small gains forget it slowly
        loop_formats(formats, steady_gain(params), (noise["x1"], noise["v"]))
    # the predicted covariance that feeds the division: its guard bits, and P and S as fine
    pl = formats["pl"]
    frac = covariance_frac(pl, max_word)
    formats["pl"] = QFormat(pl.int_bits, frac, pl.rounding, pl.overflow)
    for name in ("p", "s"):
        f = formats[name]
        if f.frac_bits < frac:
            formats[name] = QFormat(f.int_bits, frac, f.rounding, f.overflow)
    return finish_formats(params, formats, state_frac=state_frac)


def _validate(config):
    f, params = config.formats, config.params
    scaled = params.scaled()
    for label, value, name in (
        ("R", params.R, "s"),
        ("T^2*Q", scaled.Q, "pl"),
        ("P0", np.max(np.abs(scaled.P0)), "p"),
        ("x0[0]", abs(scaled.x0[0]), "x1"),
        ("T*x0[1]", abs(scaled.x0[1]), "v"),
    ):
        if not f[name].covers(value):
            raise ConfigError(f"model.{label} = {value:g} does not fit formats.{name} = {f[name]} (max {f[name].max_value:g})")
    if f["s"].lsb / 2 > params.R:
        raise ConfigError(
            f"model.R = {params.R:g} rounds to 0 in formats.s = {f['s']} (LSB {f['s'].lsb:g}): "
            "the divisor S = pl11 + R could be 0; give s more fraction bits"
        )


def reference(params, variant, y):
    """The float filter in input units: x1, x2, yhat."""
    out = steady_state(y, params) if variant == "steady" else kalman_decomposed(y, params)
    return {"x1": out["x1"], "x2": out["x2"], "yhat": out["yhat"]}


def _random_params(rng):
    t = float(rng.choice([1.0, 0.5, 2.0, 0.25, rng.uniform(0.1, 3.0)]))
    a = rng.normal(size=(2, 2))
    p0 = a @ a.T + rng.uniform(0.5, 8) * np.eye(2)
    return KalmanParams(T=t, Q=float(rng.uniform(0.05, 20.0)), R=float(rng.uniform(0.5, 40.0)),
                        P0=tuple(map(tuple, (p0 + p0.T) / 2)),
                        x0=(float(rng.normal(0, 100)), float(rng.normal(0, 5))))


def _goals(config, variant, channels=1):
    """The steady core: the constant-gain loop's (:func:`~kfpga.model.cvloop.steady_goals`). The
    time-varying core: 2,000 logic cells for one channel, about 300 more per further channel
    state (three cells per state bit of its six registers: 119 bits). Every path within the board's
    timing goal (62.5 MHz estimated)."""
    if variant == "steady":
        return steady_goals(config, channels)
    return {"logic_cells": 2000 + 300 * (channels - 1), "mul18": 12, "lut_levels": 16,
            "worst_path_ns": WORST_PATH_GOAL_NS}


def _error_std(params, *, measurement_only=False):
    """Steady-state error of x1, x2 and the prediction yhat (physical units); with
    ``measurement_only`` the part the measurement noise alone causes, a floor under the error
    on any signal (a signal off the model only adds to it)."""
    if not params.Q > 0:
        return None
    f = np.array([[1.0, params.T], [0.0, 1.0]])
    gqg = np.array([[0.0, 0.0], [0.0, 0.0 if measurement_only else params.Q]])
    k, _ = steady_state_gain(params.T, params.Q, params.R)
    (s1, s2), (sy,) = steady_error_std(f, gqg, [[1.0, 0.0]], [[params.R]], np.reshape(k, (2, 1)))
    return {"x1": s1, "x2": s2, "yhat": sy}


def _mutation():
    """``make mutate``: the steady core with its state narrower than its range (each of its four
    writes then saturates, some samples alone, in 1,200 stress samples), and the time-varying core
    with x1 a bit narrower than its range (its write then saturates alone on some stress samples,
    so the bench sees that flag reach the estimate by itself)."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixed import QFormat

    config = FilterConfig(filter=SPEC.name)
    narrow = FilterConfig(filter=SPEC.name, formats={"x1": QFormat(16, config.formats["x1"].frac_bits)},
                          check_ranges=False)
    return [MutationBlock("steady core", stressed(config, 13), "steady", {"samples": 1200}),
            MutationBlock("full core", narrow, "full", {"samples": 150})]


def _coverage():
    """A sample period that is not a power of two: x2 = v / T in more steps."""
    from kfpga.core.config import FilterConfig

    return {f"{SPEC.name}-T0.3": FilterConfig(filter=SPEC.name, params=KalmanParams(T=0.3, Q=1.0, R=9.0))}


SPEC = FilterSpec(
    name="kalman2",
    params=KalmanParams,
    docs=Docs(
        summary="the paper's 2-state Kalman filter (angle, rate), steady-state or time-varying gain",
        source="[Zhong]: Zhong et al., Design and implementation of Kalman filter based on FPGA",
    ),
    model=Model(
        points=POINTS,
        inputs=(("y", "the ADC code"),),
        outputs=(Output("x1", "x1", "filtered position"), Output("x2", "x2", "rate"),
                 Output("yhat", "xl1", "one-step prediction of y")),
        variants=VARIANTS,
        reference=reference,
        ranges=_ranges,
        default_output="x1",
        points_for=_points_for,
        default_formats=_default_formats,
        validate=_validate,
        random_params=_random_params,
        presets={"cv2": ("the paper's constant-velocity filter ([Zhong]): T = 1, Q = 2, R = 4, P0 = 10 I", KalmanParams)},
        error_std=_error_std,
        period=lambda params: (params.T, True),
    ),
    hardware=Hardware(
        goals=_goals,
        mutation=_mutation,
        coverage=_coverage,
    ),
    evaluation="kfpga.model.evaluations.kalman2:EVALUATION",
)
