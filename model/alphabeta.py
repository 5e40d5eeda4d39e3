"""The alpha-beta tracker of [Chen] (marine radar ARPA): its equations and its spec.

Per axis of a track, with the measurement ``z`` and the sample period ``T``::

    xp = x + T v                 (predict)
    x  = xp + alpha (z - xp)
    v  = v + (beta / T) (z - xp)

It runs in the datapath units of [Zhong]'s 2-state Kalman filter (``model/cvloop.py``): the state is
``x`` and the rate per sample ``T v``, so T never multiplies inside the loop and the update is
the steady-state Kalman update with the gains ``alpha`` and ``beta`` (the steady-state Kalman
filter *is* an alpha-beta filter with ``alpha = K1``, ``beta = T K2``; the tests hold the two
equal integer for integer). The same quantisation points, the same stage functions::

    xl1 = [x1 + v]_xl1          e = [z - xl1]_e
    x1  = [xl1 + alpha*e]_x1    v = [v + beta*e]_v          outputs x = x1, v = v / T

Choosing beta from alpha (:func:`benedict_bordner`, :func:`critically_damped`,
:func:`kalman_relation`):

* Benedict-Bordner, ``beta = alpha^2 / (2 - alpha)``: the relation of the steady-state Kalman
  filter of this model (white noise on the rate, ``G = [0, 1]``): every Q/R gives a pair on it;
* critically damped (both poles of the loop at ``theta``: the fading-memory filter),
  ``alpha = 1 - theta^2``, ``beta = (1 - theta)^2``;
* [Chen] uses alpha = 0.5 and states beta = 0.5 from its formula (7), which is
  not legible; neither relation above gives 0.5 at alpha = 0.5 (0.167 and 0.086). The preset
  ``ab-paper`` takes [Chen]'s stated values as printed; ``beta = alpha^2 / (1 - alpha)`` is a
  relation that gives them, a guess at (7) only.

Stability: ``0 < alpha < 2`` and ``0 < beta < 4 - 2 alpha`` (the poles of the loop inside the
unit circle).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kfpga.core.errors import ConfigError
from kfpga.core.formats import MAX_WORD, register_formats
from kfpga.core.params import number, vector
from kfpga.core.spec import Build, Constant, Docs, FilterSpec, Hardware, Mode, Model, MutationBlock, Output, Variant
from kfpga.model import cvloop as eq
from kfpga.model import start
from kfpga.model.ranges import float_ranges, full_scale_stimulus
from kfpga.model.reference import steady_error_std

__all__ = ["AlphaBetaParams", "SPEC", "POINTS", "VARIANTS", "update", "reference", "benedict_bordner",
           "critically_damped", "kalman_relation", "from_kalman", "stable", "MAX_TRACKS"]

#: Tracks one core can hold (two states each, one per axis; ``hw/alphabeta.py``).
MAX_TRACKS = 256


def benedict_bordner(alpha):
    """``beta = alpha^2 / (2 - alpha)`` (Benedict-Bordner; the steady-state Kalman relation here)."""
    return alpha * alpha / (2.0 - alpha)


def critically_damped(alpha):
    """``beta`` of the critically damped filter with this ``alpha``: ``alpha = 1 - theta^2``,
    ``beta = (1 - theta)^2`` (``0 < alpha <= 1``)."""
    if not 0 < alpha <= 1:
        raise ValueError(f"alpha must be in (0, 1] for a critically damped filter, not {alpha!r}")
    theta = math.sqrt(1.0 - alpha)
    return (1.0 - theta) ** 2


def kalman_relation(alpha):
    """``beta = alpha^2 / (1 - alpha)``: one relation that gives [Chen]'s beta = 0.5 at alpha = 0.5."""
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1) for beta = alpha^2 / (1 - alpha), not {alpha!r}")
    return alpha * alpha / (1.0 - alpha)


def stable(alpha, beta):
    """Whether the loop's poles lie inside the unit circle: ``0 < alpha < 2``, ``0 < beta < 4 - 2 alpha``."""
    return 0 < alpha < 2 and 0 < beta < 4 - 2 * alpha


@dataclass(frozen=True, kw_only=True)
class AlphaBetaParams:
    """Parameters of one axis of an alpha-beta tracker (defaults: [Chen]'s alpha = beta = 0.5, T = 1).

    Parameters
    ----------
    alpha:
        Position gain, in (0, 2).
    beta:
        Rate gain (``beta / T`` multiplies the innovation), in (0, 4 - 2 alpha).
    T:
        Sample period (> 0): the radar's scan period.
    R:
        Variance of the measurement noise, in codes squared (> 0). It does not enter the
        update: it sizes the word lengths (the innovation's and the registers' steps small
        against the error that noise leaves) and the ranges.
    x0:
        State after reset ``(x, v)`` (used with ``init = "state"``).
    init:
        ``"measurement"`` (the default): each track from its first two plots, position the
        second and velocity their difference (``model/start.py``), in the model, ``kfpga filter
        --tracks`` and every core; ``"state"``: from ``x0`` (a track then takes tens of scans
        to forget a guess far from the target).

    Raises ``TypeError`` for a value of the wrong type and ``ValueError`` for a wrong value,
    the message starting with the field's name.
    """

    alpha: float = 0.5
    beta: float = 0.5
    T: float = 1.0
    R: float = 4.0
    x0: tuple = (0.0, 0.0)
    init: str = "measurement"

    def __post_init__(self):
        s = object.__setattr__
        s(self, "init", start.check_init(self.init))
        s(self, "alpha", number("alpha", self.alpha))
        s(self, "beta", number("beta", self.beta))
        s(self, "T", number("T", self.T, minimum=0.0, strict=True))
        s(self, "R", number("R", self.R, minimum=0.0, strict=True))
        s(self, "x0", vector("x0", self.x0, 2))
        if not 0 < self.alpha < 2:
            raise ValueError(f"alpha must be in (0, 2) for a stable tracker, not {self.alpha!r}")
        if not 0 < self.beta < 4 - 2 * self.alpha:
            raise ValueError(f"beta must be in (0, 4 - 2*alpha) = (0, {4 - 2 * self.alpha:g}) for a stable tracker "
                             f"with alpha = {self.alpha:g}, not {self.beta!r}")

    @property
    def gain(self):
        """``(K1, K2)`` in input units: ``(alpha, beta / T)``."""
        return self.alpha, self.beta / self.T


def from_kalman(params):
    """The alpha-beta parameters equal to the steady-state filter of ``KalmanParams``: alpha = K1,
    beta = T K2, the same T, R and x0."""
    k1, k2 = eq.steady_gain(params)
    return AlphaBetaParams(alpha=k1, beta=k2, T=params.T, R=params.R, x0=params.x0, init=params.init)


POINTS = {name: point for name, point in eq.POINTS.items() if name in eq.LOOP_POINTS}


def update(ops, k, x, u):
    """One alpha-beta update: ``(next state, outputs)``."""
    xl1 = eq.predict(ops, x["x1"], x["v"])                            # xp = x + T v
    e = eq.innovation(ops, u["z"], xl1)                               # e = z - xp
    x1 = eq.correct(ops, xl1, ops.mul(k["k1"], e), "x1")              # x = xp + alpha e
    v = eq.correct(ops, x["v"], ops.mul(k["k2"], e), "v")             # T v = T v + beta e
    x1, v, count = eq.measured_start(ops, k, x, u["z"], x1, v)        # init = "measurement": the first two plots
    return {"x1": x1, "v": v, **count}, {"x": x1, "v": eq.rate(ops, k, v)}


def _constants(params):
    # named k1, k2 as the steady-state Kalman core's gains: the same steps build both cores
    return {"k1": Constant(params.alpha, "gain", "alpha"), "k2": Constant(params.beta, "gain", "beta"),
            **eq.rate_constants(params), **start.start_constants(params)}


def _initial(params):
    return {"x1": params.x0[0], "v": params.x0[1] * params.T, **({"start": 0.0} if start.measured(params) else {})}


VARIANTS = {
    "steady": Variant("steady", "constant gains alpha, beta: one update per sample, no multiplier for a power-of-two gain",
                      lambda params: (("x1", "x1"), ("v", "v"), *start.start_state(params)), _constants, _initial,
                      update),  # every core runs the start: the loop's (hw/cvloop.py) and the folded one
}


def reference(params, variant, z):
    """The float tracker in input units, along the last axis of ``z``: ``{"x", "v"}``."""
    z = np.asarray(z, dtype=np.float64)
    a, b = params.gain
    x = np.full(z.shape[:-1], params.x0[0])
    v = np.full(z.shape[:-1], params.x0[1])
    out = {"x": np.empty(z.shape), "v": np.empty(z.shape)}
    for n in range(z.shape[-1]):
        xp = x + params.T * v
        e = z[..., n] - xp
        x, v = start.measured_start_float(params, n, z[..., n], x, v, xp + a * e, v + b * e)  # init = "measurement"
        out["x"][..., n], out["v"][..., n] = x, v
    return out


def _error_std(params, *, measurement_only=True):
    """Steady-state error of x and v (input units) on a straight-line track: the measurement
    noise alone drives it (no process noise in the model)."""
    f = np.array([[1.0, params.T], [0.0, 1.0]])
    k = np.reshape(params.gain, (2, 1))
    (s1, s2), _ = steady_error_std(f, np.zeros((2, 2)), [[1.0, 0.0]], [[params.R]], k)
    return {"x": s1, "v": s2}


def _points_for(params):
    names = ["x1", "xl1", "v", "x2", "e", "gain"] + (["inv_t", "vt"] if eq.t_exponent(params.T) is None else [])
    return [n for n in POINTS if n in names]


def _ranges(params, stimulus=None):
    stimulus = full_scale_stimulus(params.R) if stimulus is None else stimulus
    return float_ranges(SPEC, params, list(VARIANTS.values()), stimulus)


def _default_formats(params, ranges, *, operand_bits, state_frac, max_word=MAX_WORD):
    err = _error_std(params)
    noise = {"x1": err["x"], "v": params.T * err["v"], "vt": params.T * err["v"], "x2": err["v"]}
    formats = register_formats(SPEC, params, ranges, operand_bits=operand_bits, state_frac=state_frac, noise=noise,
                               max_word=max_word)
    eq.loop_formats(formats, (params.alpha, params.beta), (noise["x1"], noise["v"]))  # the rounding the loop feeds back
    return eq.finish_formats(params, formats, state_frac=state_frac)


def _validate(config):
    f, params = config.formats, config.params
    for label, value, name in (("x0[0]", abs(params.x0[0]), "x1"), ("T*x0[1]", abs(params.x0[1] * params.T), "v")):
        if not f[name].covers(value):
            raise ConfigError(f"model.{label} = {value:g} does not fit formats.{name} = {f[name]} (max {f[name].max_value:g})")


def _random_params(rng):
    alpha = float(rng.uniform(0.05, 1.5))
    beta = float(rng.uniform(0.02, 0.9)) * (4 - 2 * alpha)
    return AlphaBetaParams(alpha=alpha, beta=beta, T=float(rng.choice([1.0, 0.5, 2.0, rng.uniform(0.1, 3.0)])),
                           R=float(rng.uniform(0.5, 40.0)), x0=(float(rng.normal(0, 100)), float(rng.normal(0, 5))))


def _goals(config, variant, channels=1):
    """The constant-gain loop's (two multipliers, none for a power-of-two gain, one more when T is
    not a power of two)."""
    return eq.steady_goals(config, channels)


def _track_columns(config, tracks):
    from kfpga.core.errors import UsageError

    if not 1 <= tracks <= MAX_TRACKS:
        raise UsageError(f"--tracks must be 1..{MAX_TRACKS} (the tracker's limit), not {tracks}")
    return ("track", "axis", *config.inputs)


def _replay_tracks(config, variant, samples, tracks, *, exact, source):
    """``kfpga filter --tracks N``: a multi-target replay through per-(track, axis) states, as the
    many-track core has them (state ``2 track + axis``)."""
    from kfpga.core.errors import InputError
    from kfpga.core.fixedmodel import FixedModel

    track, axis = samples["track"], samples["axis"]
    for name, values, top in (("track", track, tracks - 1), ("axis", axis, 1)):
        bad = np.flatnonzero((values < 0) | (values > top))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"{source}: line {k + 2}: {name} = {int(values[k])} is outside 0..{top}"
                             + (f" (--tracks {tracks})" if name == "track" else ""))
    state = 2 * track + axis
    z = {name: samples[name] for name in config.inputs}
    if not exact:
        columns = {o: np.zeros(len(state)) for o in config.output_names}
        for s in np.unique(state):
            idx = np.flatnonzero(state == s)
            out = reference(config.params, variant, *(z[n][idx].astype(float) for n in config.inputs))
            for o in config.output_names:
                columns[o][idx] = out[o]
    else:
        model = FixedModel(config, variant=variant)
        raw, overflow, _ = model.run_channels(z, state)
        columns = {o: model.output_format(o).to_float(raw[o]) for o in config.output_names}
        columns["overflow"] = overflow
    return {"track": track, "axis": axis, **columns}, f"{len(state)} plots of {len(np.unique(track))} track(s)"


TRACKS = Mode(
    option="--tracks",
    argument={"type": int, "metavar": "N",
              "help": "replay a multi-target recording of N tracks (1..256): columns track (0..N-1), axis (0 or 1) and "
                      "z, in the order the plots came; each track and axis has its own state, as in the many-track "
                      "core; the output has track, axis, x, v"},
    columns=_track_columns,
    run=_replay_tracks,
    example="--tracks 40 --input plots.csv --output tracks.csv",
)


def _mutation():
    """``make mutate``: the loop with its state narrower than its range (each write then saturates,
    some samples alone, in 1,200 stress samples)."""
    from kfpga.core.config import FilterConfig

    return [MutationBlock("alphabeta core", eq.stressed(FilterConfig(filter=SPEC.name), 14), "steady", {"samples": 1200})]


def _coverage():
    """The many-track core (2 x 3 states through one loop)."""
    from kfpga.core.config import FilterConfig

    return {"tracker3": Build(FilterConfig(filter=SPEC.name), "steady", architecture="parallel", options={"tracks": 3})}


SPEC = FilterSpec(
    name="alphabeta",
    params=AlphaBetaParams,
    docs=Docs(
        summary="alpha-beta tracker (marine radar ARPA), constant gains alpha, beta; one axis of a track per channel",
        source="[Chen]: Chen and Yang 2016, Research on the alpha-beta algorithm in a marine radar ARPA system",
        aliases=("alpha-beta",),
    ),
    model=Model(
        points=POINTS,
        inputs=(("z", "the measured position (a radar coordinate, 16-bit)"),),
        outputs=(Output("x", "x1", "filtered position"), Output("v", "x2", "velocity (per unit of T)")),
        variants=VARIANTS,
        reference=reference,
        ranges=_ranges,
        default_output="x",
        points_for=_points_for,
        default_formats=_default_formats,
        validate=_validate,
        random_params=_random_params,
        presets={
            "ab-paper": ("[Chen]'s tracker: alpha = beta = 0.5 as printed, T = 1", AlphaBetaParams),
            "ab-bb": ("Benedict-Bordner at [Chen]'s alpha = 0.5: beta = alpha^2/(2 - alpha) = 0.1667, T = 1",
                      lambda: AlphaBetaParams(alpha=0.5, beta=benedict_bordner(0.5))),
            "ab-critical": ("critically damped at [Chen]'s alpha = 0.5: beta = (1 - sqrt(1 - alpha))^2 = 0.0858, T = 1",
                            lambda: AlphaBetaParams(alpha=0.5, beta=critically_damped(0.5))),
        },
        error_std=_error_std,
        period=lambda params: (params.T, True),
        modes=(TRACKS,),
    ),
    hardware=Hardware(
        goals=_goals,
        mutation=_mutation,
        coverage=_coverage,
    ),
    evaluation="kfpga.model.evaluations.alphabeta:EVALUATION",
)
