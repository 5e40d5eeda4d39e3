"""Any linear state-space model: an n-state Kalman filter from F, G, Q, H, R.

Model, with n = 1..4 states and m = 1..2 observations (each a 16-bit ADC code)::

    x_k = F x_{k-1} + G w_k,   w ~ N(0, Q)        y_k = H x_k + v_k,   v ~ N(0, R)

Steady state (``steady``): the gain K of the discrete Riccati equation (or one given)::

    xl = [F x]_xl          yh = [H xl]_yh        e = [y - yh]_e
    x  = [xl + K e]_x      outputs: x1..xn (filtered), yhat1..yhatm (= yh, one-step predictions)

Time-varying (``full``), m = 1 (P symmetric, n(n+1)/2 entries kept)::

    xl  = [F x]_xl                         Pl = [F P F^T + G Q G^T]_pl
    hp  = H Pl   (exact: a row of Pl when H selects one state)
    S   = [hp H^T + R]_s                   K_i = div(hp_i, S)        (the restoring divider)
    e   = [y - H xl]_e                     x = [xl + K e]_x
    P   = [Pl - K hp]_p                    (P_ij = Pl_ij - K_i hp_j, i <= j)

For m = 2 the time-varying variant is model-only (float and bit-accurate; no core): S is 2x2
and K = Pl H^T S^-1 with the inverse through the determinant: ``det = [s11 s22 - s12^2]_det``,
``K_i1 = div([hp1_i s22 - hp2_i s12]_kn, det)``, ``K_i2 = div([hp2_i s11 - hp1_i s12]_kn, det)``.

Every index runs over what the model has; a product by a matrix entry that is 0 or +-2**k
costs nothing (a shift; F = [[1, T], [0, 1]] with T = 2**k has only such entries). Any other
entry of F is a constant multiplier whose operand is the state rounded into an 18-bit operand
``xo<j>``. H must select states (entries 0 or +-2**k), as sensors do; the time-varying variant
needs F's entries to be 0 or +-2**k as well.

Every term of a sum that is a product (by a gain, or by an entry of F other than 0 and +-1) is a
cast point: rounded into a format of its own before it enters the sum where the config gives it
one (by default, where the exact sum would pass the word budget), else exact::

    ft<i><j>     F_ij x_j, a term of (F x)_i           ke<i><j>     K_ij e_j, a term of x_i
    fpt<i><j><c> F_ic P_cj, a term of (F P)_ij         plt<i><j><c> F_jc (F P)_ic, a term of Pl_ij
    kh<i><j><a>  K_ia (H Pl)_aj, a term of P_ij        dp1, dp2     S11 S22 and S12^2, of det S
    kp<i><b><t>  the two products of K's numerator b   (two observations)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kfpga.core.board import WORST_PATH_GOAL_NS
from kfpga.core.errors import ConfigError
from kfpga.core.fixed import QFormat
from kfpga.core.formats import (
    MAX_WORD,
    constant_frac_bits,
    covariance_frac,
    noise_frac_bits,
    precision_frac_bits,
    register_formats,
)
from kfpga.core.params import check_measured_start, matrix, number, vector
from kfpga.core.spec import Build, Constant, Docs, FilterSpec, Hardware, Model, Output, Point, Variant
from kfpga.model import start
from kfpga.model.ranges import float_ranges, full_scale_stimulus
from kfpga.model.riccati import PBHError, check_pbh, dare, loop_frac_bits

__all__ = ["StateSpaceParams", "SPEC", "PRESETS", "dare_gain", "reference", "steady_update", "full_update", "free",
           "PBHError", "predict_operands", "predict_terms", "predict_sums", "predict", "observe", "innovations",
           "gain_products", "correct", "covariance_fp", "covariance_sums", "covariance_predict", "observed_rows",
           "innovation_variance", "gains_one", "gains_two", "update_products", "update_corrections"]

MAX_STATES, MAX_OBS = 4, 2


def _square(name, value):
    try:
        rows = [list(r) for r in value]
    except TypeError:
        raise TypeError(f"{name} must be a matrix (a list of rows), not {value!r}") from None
    return len(rows), (len(rows[0]) if rows else 0)



def _start_vector(x0, n):
    """``x0`` (default zeros) as ``n`` numbers."""
    return (0.0,) * n if x0 is None else vector("x0", x0, n, each="state")


def _observation_names(observations, m):
    """The ``m`` observations' names (default y, or y1, y2), checked."""
    names = tuple(observations) or (("y",) if m == 1 else tuple(f"y{j + 1}" for j in range(m)))
    if len(names) != m or not all(isinstance(v, str) and v.isidentifier() for v in names) or len(set(names)) != m:
        raise ValueError(f"observations must be {m} different names (letters, digits, _), not {observations!r}")
    if {"channel", "overflow"} & set(names) or any(v.startswith(("x", "yhat")) and v[1:].isdigit() for v in names):
        raise ValueError(f"observations must not be named like an output or a stream field, not {names!r}")
    return names


def _adc_channels(adc, m):
    """The ADC channel of each of the ``m`` observations, checked."""
    try:
        channels = list(adc)
    except TypeError:
        raise TypeError(f"adc must be a list of {m} ADC channels (0..5), not {adc!r}") from None
    if (len(channels) != m or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 5 for c in channels)
            or len(set(channels)) != m):
        raise ValueError(f"adc must be {m} different ADC channels 0..5 (A0..C1), one per observation, not {adc!r}")
    return tuple(channels)


@dataclass(frozen=True, kw_only=True)
class StateSpaceParams:
    """A linear state-space model (defaults: the 2-state constant-velocity model of [Zhong]).

    Parameters
    ----------
    F:
        n x n state transition (n = 1..4).
    G:
        n x p process-noise input; the process noise is ``G Q G^T``.
    Q:
        p x p process-noise covariance, symmetric positive semi-definite.
    H:
        m x n observation matrix (m = 1..2); its entries must be 0 or +-2**k (it selects states).
    R:
        m x m observation-noise covariance, symmetric positive definite.
    P0:
        n x n initial covariance, symmetric positive definite (default: 10 I, n x n).
    x0:
        The n initial states (default: n zeros).
    T:
        The sampling period in seconds (> 0): the time scale of the scenarios; the matrices
        already contain it.
    observations:
        Names of the observations (CSV columns, stream fields); default ``y`` for one, ``y1``,
        ``y2`` for two.
    gain:
        n x m: a fixed gain instead of the Riccati equation's (an alpha-beta filter), for the
        steady-state variant.
    adc:
        The ADS8364 channel (0..5 = A0..C1) of each observation on the board; default: A0 for
        one observation (or ``--channel``), A0 and A1 for two.
    init:
        ``"state"``: start from ``x0``; ``"measurement"``: each state an observation selects
        alone from the first sample, the state that moves it (its rate) from the first two
        (:func:`start_plan`, ``model/start.py``).
    """

    F: tuple = ((1.0, 1.0), (0.0, 1.0))
    G: tuple = ((0.0,), (1.0,))
    Q: tuple = ((2.0,),)
    H: tuple = ((1.0, 0.0),)
    R: tuple = ((4.0,),)
    P0: tuple | None = None
    x0: tuple | None = None
    T: float = 1.0
    observations: tuple = ()
    gain: tuple | None = None
    adc: tuple | None = None
    init: str = "state"

    def __post_init__(self):
        s = object.__setattr__
        s(self, "init", start.check_init(self.init))
        n, cols = _square("F", self.F)
        if not 1 <= n <= MAX_STATES or cols != n:
            raise ValueError(f"F must be n x n with n = 1..{MAX_STATES} states, not {n} x {cols}")
        s(self, "F", matrix("F", self.F, n, n))
        m, hcols = _square("H", self.H)
        if not 1 <= m <= MAX_OBS or hcols != n:
            raise ValueError(f"H must be m x {n} (m = 1..{MAX_OBS} observations of the {n} states), not {m} x {hcols}")
        s(self, "H", matrix("H", self.H, m, n))
        bad = next(((i, j, h) for i, row in enumerate(self.H) for j, h in enumerate(row) if not free(h)), None)
        if bad is not None:
            raise ValueError(f"H[{bad[0]}][{bad[1]}] = {bad[2]!r}: H must select states (entries 0 or +-2**k)")
        rows, p = _square("G", self.G)
        if rows != n or not 1 <= p <= MAX_STATES:
            raise ValueError(f"G must be {n} x p (p = 1..{MAX_STATES} noise inputs), not {rows} x {p}")
        s(self, "G", matrix("G", self.G, n, p))
        s(self, "Q", matrix("Q", self.Q, p, p, symmetric=True))
        q_eig = np.linalg.eigvalsh(np.array(self.Q))
        if np.min(q_eig) < -1e-12 * max(1.0, np.max(np.abs(q_eig))):
            raise ValueError(f"Q must be positive semi-definite, not {self.Q!r} "
                             f"(eigenvalues {', '.join(f'{e:.4g}' for e in q_eig)})")
        s(self, "R", matrix("R", self.R, m, m, symmetric=True, positive_definite=True))
        if self.P0 is None:
            s(self, "P0", tuple(tuple(10.0 if i == j else 0.0 for j in range(n)) for i in range(n)))
        s(self, "P0", matrix("P0", self.P0, n, n, symmetric=True, positive_definite=True))
        s(self, "x0", _start_vector(self.x0, n))
        check_measured_start(self.x0, self.H)
        s(self, "T", number("T", self.T, minimum=0.0, strict=True))
        s(self, "observations", _observation_names(self.observations, m))
        if self.gain is not None:
            s(self, "gain", matrix("gain", self.gain, n, m))
        if self.adc is not None:
            s(self, "adc", _adc_channels(self.adc, m))
        if start.measured(self) and not start_plan(self)[0]:
            raise ValueError('init = "measurement" needs an observation that selects one state alone (a row of H '
                             "with one nonzero entry): no state of this model is measured by itself")

    def adc_channels(self, default=0):
        """The ADC channel of each observation (``default`` for one observation not given one)."""
        if self.adc is not None:
            return self.adc
        return (default,) if self.m == 1 else tuple(range(self.m))

    @property
    def n(self):
        return len(self.F)

    @property
    def m(self):
        return len(self.H)

    def arrays(self):
        """``(F, G Q G^T, H, R)`` as float arrays."""
        f, g, q = np.array(self.F), np.array(self.G), np.array(self.Q)
        return f, g @ q @ g.T, np.array(self.H), np.array(self.R)


def free(value):
    """Whether a constant factor costs no multiplier: 0 or +-2**k."""
    if value == 0:
        return True
    mantissa, _ = math.frexp(abs(value))
    return mantissa == 0.5


def exact_format(value):
    """A format holding 0 or +-2**k exactly, with as few fraction bits as it needs."""
    from kfpga.core.fixed import QFormat

    if value == 0:
        return QFormat(2, 0)
    k = math.frexp(abs(value))[1] - 1
    return QFormat(max(2, k + 2), max(0, -k))


def start_plan(params):
    """What the start from the measurements sets: ``({state j: (observation i, h)}, {state r:
    (position j, F[j][r])})``. A position is a state that a row of H selects alone (``y_i =
    h x_j``); its rate is the one other state that moves it in F directly (``F[j][r] != 0``, and
    ``x_r`` not itself feeding another such state: the acceleration of a constant-acceleration model
    moves the position through ``T**2/2`` as well, but it feeds the velocity, which is the rate).
    A position with no such state, or with several, keeps its rates at x0."""
    n = len(params.F)
    positions = {}
    for i, row in enumerate(params.H):
        picks = [j for j, h in enumerate(row) if h != 0]
        if len(picks) == 1 and picks[0] not in positions:
            positions[picks[0]] = (i, float(row[picks[0]]))
    rates = {}
    for j in positions:
        movers = [r for r in range(n) if r != j and r not in positions and params.F[j][r] != 0]
        direct = [r for r in movers if not any(params.F[c][r] != 0 for c in movers if c != r)]
        if len(direct) == 1 and direct[0] not in rates:
            rates[direct[0]] = (j, float(params.F[j][direct[0]]))
    return positions, rates


def _reciprocal(value):
    """``1 / value`` as a constant: exact when it is +-2**k, else with the multiplier's significant bits."""
    inv = 1.0 / value
    if free(inv):
        return exact_format(inv)
    return QFormat(max(2, math.floor(math.log2(abs(inv))) + 2), constant_frac_bits(inv))


def _start_constants(params):
    """The constants of the start: 1/h of each position, 1/F[j][r] of each rate."""
    if not start.measured(params):
        return {}
    positions, rates = start_plan(params)
    out = dict(start.start_constants(params))
    for j, (_, h) in positions.items():
        out[f"start_h{j}"] = Constant(1.0 / h, exact_format(1.0 / h), f"1/H[.][{j}]")
    for r, (j, f) in rates.items():
        out[f"start_f{r}"] = Constant(1.0 / f, _reciprocal(f), f"1/F[{j}][{r}]")
    out["start_plan"] = (positions, rates)
    return out


def measured_start(ops, k, x, u, xn):
    """The states after the start from the measurements (``model/start.py``, :func:`start_plan`)
    and ``{"start": count}``; ``xn`` unchanged and ``{}`` without it."""
    if "start" not in k:
        return xn, {}
    positions, rates = k["start_plan"]
    starting, second, count = start.phase(ops, k, x["start"])
    prev = [x[f"x{i + 1}"] for i in range(k["n"])]
    seen = {j: ops.mul(k[f"start_h{j}"], u[k["observations"][i]]) for j, (i, _) in positions.items()}  # y / h
    out = []
    for s, value in enumerate(xn):
        if s in positions:                                                        # x_j = y / h
            value = ops.select(starting, ops.rq(seen[s], f"x{s + 1}", f"x{s + 1}_start"), value)
        elif s in rates:                                                          # x_r = (y1/h - x_j) / F_jr
            j = rates[s][0]
            diff = ops.mul(ops.sub(seen[j], prev[j]), k[f"start_f{s}"])
            value = ops.select(second, ops.rq(diff, f"x{s + 1}", f"x{s + 1}_start"),
                               ops.select(starting, prev[s], value))
        else:                                                                     # held on sample 0
            value = ops.select(starting, ops.select(second, value, prev[s]), value)
        out.append(value)
    return out, {"start": count}


# -- the Riccati equation ----------------------------------------------------------------------


def dare_gain(params):
    """The steady-state gain K (n x m) and predicted covariance of the model's discrete Riccati
    equation (:func:`~kfpga.model.riccati.dare`); :class:`PBHError` when none stabilises."""
    return dare(*params.arrays())


def _check_pbh(params):
    f, gqg, h, _ = params.arrays()
    check_pbh(f, gqg, h)


def steady_gain(params):
    """The gain of the steady-state variant: ``params.gain`` when given, else the DARE's."""
    return np.array(params.gain) if params.gain is not None else dare_gain(params)[0]


# -- the float reference -----------------------------------------------------------------------


def reference(params, variant, y):
    """The float filter, matrix form: ``{x1..xn, yhat1..yhatm: array}`` for inputs ``y``.

    ``y`` is an array (one observation) or ``{observation: array}``.
    """
    f, gqg, h, r = params.arrays()
    names = params.observations
    ys = np.stack([np.asarray(y[nm] if isinstance(y, dict) else y, dtype=np.float64) for nm in names], axis=-1)
    steps = ys.shape[0]
    x = np.array(params.x0, dtype=np.float64)
    p = np.array(params.P0, dtype=np.float64)
    k_inf = steady_gain(params) if variant == "steady" else None
    xs, yh = np.empty((steps, params.n)), np.empty((steps, params.m))
    plan = start_plan(params) if start.measured(params) else None
    for t in range(steps):
        prev = x
        x = f @ x                                              # x = F x
        yh[t] = h @ x                                          # yhat = H x
        if variant == "steady":
            gain = k_inf
        else:
            p = f @ p @ f.T + gqg                              # P = F P F^T + G Q G^T
            gain = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)    # K = P H^T (H P H^T + R)^-1
            p = (np.eye(params.n) - gain @ h) @ p              # P = (I - K H) P
        x = x + gain @ (ys[t] - yh[t])                         # x = x + K (y - H x)
        if plan is not None and t < start.start_samples(params):  # init = "measurement"
            x = np.array(start.float_start(t, ys[t], prev, x, *plan))
        xs[t] = x
    out = {f"x{i + 1}": xs[:, i] for i in range(params.n)}
    out.update({f"yhat{j + 1}": yh[:, j] for j in range(params.m)})
    return out


# -- the equations, once ---------------------------------------------------------------------------


def _term(ops, k, name, x, operand, cache):
    """``c * x`` for the matrix entry ``k[name]`` (``None``: the entry is 0, no term)."""
    c = k.get(name)
    if c is None:
        return None
    if k["free"][name] or operand is None:
        return ops.mul(c, x)                                   # a shift, or a product of x as it is
    if operand not in cache:
        cache[operand] = ops.rq(x, operand)                    # the 18-bit operand of the product
    return ops.mul(c, cache[operand])


def _cast_term(ops, k, term, entry, point):
    """``term`` (the product of the constant ``k[entry]`` and a value) cast into ``point``; a term by
    +-1 is the value itself (no cast point), a missing term stays missing."""
    if term is None or entry in k["unit"]:
        return term
    return ops.cast(term, point)


def _sum(ops, k, terms):
    """The exact sum of the terms that exist (a constant 0 when none does)."""
    terms = [t for t in terms if t is not None]
    if not terms:
        return k["zero"]
    out = terms[0]
    for t in terms[1:]:
        out = ops.add(out, t)
    return out


def predict_operands(ops, k, x):
    """``{j: xo_j}``: each state that a constant of F other than 0 or +-2**k multiplies, rounded
    into the operand ``xo<j>`` of those products."""
    n = k["n"]
    return {j: ops.rq(x[j], f"xo{j + 1}") for j in range(n)
            if any(f"F{i}{j}" in k and not k["free"][f"F{i}{j}"] for i in range(n))}


def predict_terms(ops, k, x, xo):
    """The terms F_ij x_j of F x (a shift, or F_ij times the operand ``xo[j]``), each cast into
    ``ft<i><j>``; ``None`` where F_ij is 0."""
    n = k["n"]
    return [[_cast_term(ops, k, _term(ops, k, f"F{i}{j}", x[j], f"xo{j + 1}", {f"xo{j + 1}": xo[j]} if j in xo else {}),
                        f"F{i}{j}", f"ft{i + 1}{j + 1}")
             for j in range(n)] for i in range(n)]


def predict_sums(ops, k, x, terms=None):
    """F x, one exact sum per state (from the terms of :func:`predict_terms`, when given)."""
    if terms is None:
        terms = predict_terms(ops, k, x, predict_operands(ops, k, x))
    return [_sum(ops, k, row) for row in terms]


def predict(ops, k, x):
    """xl = [F x]_xl, one row per state."""
    return [ops.rq(v, f"xl{i + 1}") for i, v in enumerate(predict_sums(ops, k, x))]


def observe(ops, k, xl):
    """yh = H xl, one row per observation."""
    return [ops.rq(_sum(ops, k, [_term(ops, k, f"H{j}{i}", xl[i], None, {}) for i in range(k["n"])]), f"yh{j + 1}")
            for j in range(k["m"])]


def innovations(ops, k, u, yh):
    """e = y - yh."""
    return [ops.rq(ops.sub(u[name], yh[j]), f"e{j + 1}") for j, name in enumerate(k["observations"])]


def correct(ops, k, xl, products):
    """x = xl + K e (``products[i]``: the terms K_ij e_j of state i)."""
    return [ops.rq(_sum(ops, k, [xl[i], *products[i]]), f"x{i + 1}") for i in range(k["n"])]


def gain_products(ops, k, e):
    """K_ij e_j of the steady-state variant (K constant), each cast into ``ke<i><j>``."""
    return [[ops.cast(ops.mul(k[f"K{i}{j}"], e[j]), f"ke{i + 1}{j + 1}") for j in range(k["m"])] for i in range(k["n"])]


def _outputs(k, x, yh):
    out = {f"x{i + 1}": x[i] for i in range(k["n"])}
    out.update({f"yhat{j + 1}": yh[j] for j in range(k["m"])})
    return out


def steady_update(ops, k, x, u):
    """One steady-state update: ``(next state, outputs)``."""
    xs = [x[f"x{i + 1}"] for i in range(k["n"])]
    xl = predict(ops, k, xs)                                          # xl = F x
    yh = observe(ops, k, xl)                                          # yh = H xl
    e = innovations(ops, k, u, yh)                                    # e = y - yh
    xn = correct(ops, k, xl, gain_products(ops, k, e))                # x = xl + K e
    xn, count = measured_start(ops, k, x, u, xn)                      # init = "measurement"
    return {**{f"x{i + 1}": xn[i] for i in range(k["n"])}, **count}, _outputs(k, xn, yh)


def _pname(i, j):
    return f"{min(i, j) + 1}{max(i, j) + 1}"


def covariance_fp(ops, k, p):
    """F P, exact but for its terms F_ic P_cj, each cast into ``fpt<i><j><c>`` (``p(i, j)`` reads P)."""
    n = k["n"]
    return [[_sum(ops, k, [_cast_term(ops, k, _term(ops, k, f"F{i}{c}", p(c, j), None, {}), f"F{i}{c}",
                                      f"fpt{i + 1}{j + 1}{c + 1}") for c in range(n)]) for j in range(n)]
            for i in range(n)]


def covariance_sums(ops, k, fp):
    """(F P) F^T + G Q G^T, exact, the upper triangle; an entry (F P)_ic that a constant of F
    multiplies is first rounded into the operand ``fp<i><c>`` (a shift takes it exact)."""
    n = k["n"]
    out = {}
    for i in range(n):
        cache = {}
        for j in range(i, n):
            terms = [_cast_term(ops, k, _term(ops, k, f"F{j}{c}", fp[i][c], f"fp{i + 1}{c + 1}", cache), f"F{j}{c}",
                                f"plt{i + 1}{j + 1}{c + 1}") for c in range(n)]  # each cast into plt<i><j><c>
            out[(i, j)] = _sum(ops, k, [*terms, k.get(f"GQG{i}{j}")])
    return out


def covariance_predict(ops, k, p):
    """Pl = [F P F^T + G Q G^T]_pl, the upper triangle; ``p(i, j)`` reads P."""
    return {ij: ops.rq(v, f"pl{ij[0] + 1}{ij[1] + 1}") for ij, v in covariance_sums(ops, k, covariance_fp(ops, k, p)).items()}


def observed_rows(ops, k, pl):
    """hp = H Pl (rows of Pl when H selects states): ``hp[j][i]``, exact."""
    n = k["n"]
    return [[_sum(ops, k, [_term(ops, k, f"H{j}{c}", pl[(min(c, i), max(c, i))], None, {}) for c in range(n)])
             for i in range(n)] for j in range(k["m"])]


def innovation_variance(ops, k, hp):
    """S = [H Pl H^T + R]_s (one observation)."""
    return ops.rq(_sum(ops, k, [_term(ops, k, f"H0{i}", hp[0][i], None, {}) for i in range(k["n"])] + [k["R00"]]), "s")


def gains_one(ops, k, hp, s):
    """K_i = div(hp_i, S): K = Pl H^T / S for one observation."""
    return [[ops.div(hp[0][i], s, f"k{i + 1}", f"K{i}0")] for i in range(k["n"])]


def gains_two(ops, k, hp):
    """K = Pl H^T S^-1 for two observations, the inverse through the determinant."""
    n = k["n"]
    s = {(a, b): ops.rq(_sum(ops, k, [_term(ops, k, f"H{b}{i}", hp[a][i], None, {}) for i in range(n)]
                             + [k.get(f"R{a}{b}")]), f"s{a + 1}{b + 1}") for a in range(2) for b in range(a, 2)}
    det = ops.rq(ops.sub(ops.cast(ops.mul(s[(0, 0)], s[(1, 1)]), "dp1"), ops.cast(ops.mul(s[(0, 1)], s[(0, 1)]), "dp2")),
                 "det")  # det S
    gains = []
    for i in range(n):
        a, b = (ops.cast(ops.mul(hp[0][i], s[(1, 1)]), f"kp{i + 1}11"), ops.cast(ops.mul(hp[1][i], s[(0, 1)]), f"kp{i + 1}12"))
        n1 = ops.rq(ops.sub(a, b), "kn", f"kn{i}0")
        a, b = (ops.cast(ops.mul(hp[1][i], s[(0, 0)]), f"kp{i + 1}21"), ops.cast(ops.mul(hp[0][i], s[(0, 1)]), f"kp{i + 1}22"))
        n2 = ops.rq(ops.sub(a, b), "kn", f"kn{i}1")
        gains.append([ops.div(n1, det, f"k{i + 1}", f"K{i}0"), ops.div(n2, det, f"k{i + 1}", f"K{i}1")])
    return gains


def update_products(ops, k, gains, e, hp):
    """The products of the measurement update: ``("e", i, j)``: K_ij e_j; ``("p", i, j, a)``:
    K_ia hp_aj for the upper triangle of P."""
    n, m = k["n"], k["m"]
    out = {("e", i, j): ops.mul(gains[i][j], e[j]) for i in range(n) for j in range(m)}
    out.update({("p", i, j, a): ops.mul(gains[i][a], hp[a][j]) for i in range(n) for j in range(i, n) for a in range(m)})
    return out


def update_corrections(ops, k, xl, pl, products):
    """x = [xl + K e]_x and P = [Pl - K H Pl]_p from the products (each cast into ``ke<i><j>`` and
    ``kh<i><j><a>``): the next state."""
    n, m = k["n"], k["m"]
    xn = correct(ops, k, xl, [[ops.cast(products[("e", i, j)], f"ke{i + 1}{j + 1}") for j in range(m)] for i in range(n)])
    state = {f"x{i + 1}": xn[i] for i in range(n)}
    for i in range(n):
        for j in range(i, n):
            kh = _sum(ops, k, [ops.cast(products[("p", i, j, a)], f"kh{i + 1}{j + 1}{a + 1}") for a in range(m)])
            state[f"p{i + 1}{j + 1}"] = ops.rq(ops.sub(pl[(i, j)], kh), f"p{i + 1}{j + 1}")
    return state


def full_update(ops, k, x, u):
    """One time-varying update, m = 1 or 2: ``(next state, outputs)``."""
    n = k["n"]
    xl = predict(ops, k, [x[f"x{i + 1}"] for i in range(n)])           # xl = F x
    pl = covariance_predict(ops, k, lambda i, j: x[f"p{_pname(i, j)}"])  # Pl = F P F^T + G Q G^T
    hp = observed_rows(ops, k, pl)                                    # H Pl
    yh = observe(ops, k, xl)                                          # yh = H xl
    e = innovations(ops, k, u, yh)                                    # e = y - yh
    if k["m"] == 1:
        gains = gains_one(ops, k, hp, innovation_variance(ops, k, hp))  # K = Pl H^T / S
    else:
        gains = gains_two(ops, k, hp)                                 # K = Pl H^T S^-1
    state = update_corrections(ops, k, xl, pl, update_products(ops, k, gains, e, hp))  # x += K e; P -= K H Pl
    xn, count = measured_start(ops, k, x, u, [state[f"x{i + 1}"] for i in range(n)])  # init = "measurement"
    state.update({f"x{i + 1}": xn[i] for i in range(n)}, **count)
    return state, _outputs(k, xn, yh)


def _coast(ops, k, x):
    """``x = [F x]_x`` and its outputs (``yh = H xl``): a sample with no measurement."""
    n = k["n"]
    xl = predict(ops, k, [x[f"x{i + 1}"] for i in range(n)])           # xl = F x
    yh = observe(ops, k, xl)                                          # yh = H xl
    xn = [ops.rq(v, f"x{i + 1}") for i, v in enumerate(xl)]
    held = {"start": x["start"]} if "start" in k else {}              # the start waits for a measurement
    return {**{f"x{i + 1}": xn[i] for i in range(n)}, **held}, _outputs(k, xn, yh)


def steady_predict(ops, k, x):
    """A sample with no measurement, constant gain: ``x = F x``."""
    return _coast(ops, k, x)


def full_predict(ops, k, x):
    """A sample with no measurement: ``x = F x``, ``P = [F P F^T + G Q G^T]_p``."""
    state, outs = _coast(ops, k, x)
    pl = covariance_predict(ops, k, lambda i, j: x[f"p{_pname(i, j)}"])  # Pl = F P F^T + G Q G^T
    state.update({f"p{i + 1}{j + 1}": ops.rq(v, f"p{i + 1}{j + 1}") for (i, j), v in pl.items()})
    return state, outs


# -- what the spec needs ----------------------------------------------------------------------------


def _matrix_constants(params):
    """F and H entries: exact when 0 or +-2**k, else quantised into ``f`` (F only)."""
    out, flags = {}, {}
    for i, row in enumerate(params.F):
        for j, v in enumerate(row):
            if v != 0:
                out[f"F{i}{j}"] = Constant(v, exact_format(v) if free(v) else f"f{i + 1}{j + 1}", f"F[{i}][{j}]")
                flags[f"F{i}{j}"] = free(v)
    for j, row in enumerate(params.H):
        for i, v in enumerate(row):
            if v != 0:
                out[f"H{j}{i}"] = Constant(v, exact_format(v))
                flags[f"H{j}{i}"] = True
    return out, flags


def _structure(params):
    from kfpga.core.fixed import QFormat

    unit = frozenset(f"F{i}{j}" for i, row in enumerate(params.F) for j, v in enumerate(row) if abs(v) == 1)
    unit |= {f"H{j}{i}" for j, row in enumerate(params.H) for i, v in enumerate(row) if abs(v) == 1}
    return {"n": params.n, "m": params.m, "observations": params.observations, "zero": Constant(0.0, QFormat(2, 0)),
            "unit": unit}


def _steady_constants(params):
    consts, flags = _matrix_constants(params)
    gain = steady_gain(params)
    for i in range(params.n):
        for j in range(params.m):
            consts[f"K{i}{j}"] = Constant(float(gain[i][j]), f"k{i + 1}", f"K[{i}][{j}]")
    return {**consts, "free": flags, **_structure(params), **_start_constants(params)}


def _full_constants(params):
    consts, flags = _matrix_constants(params)
    _, gqg, _, r = params.arrays()
    n, m = params.n, params.m
    for i in range(n):
        for j in range(i, n):
            if gqg[i][j] != 0:
                consts[f"GQG{i}{j}"] = Constant(float(gqg[i][j]), f"pl{i + 1}{j + 1}", f"(G Q G^T)[{i}][{j}]")
    for a in range(m):
        for b in range(a, m):
            consts[f"R{a}{b}"] = Constant(float(r[a][b]), "s" if m == 1 else f"s{a + 1}{b + 1}", f"R[{a}][{b}]")
    return {**consts, "free": flags, **_structure(params), **_start_constants(params)}


def _initial(params):
    return {**{f"x{i + 1}": params.x0[i] for i in range(params.n)}, **({"start": 0.0} if start.measured(params) else {})}


def _full_initial(params):
    out = _initial(params)
    for i in range(params.n):
        for j in range(i, params.n):
            out[f"p{i + 1}{j + 1}"] = params.P0[i][j]
    return out


def _steady_applies(params):
    if params.gain is not None:
        return None
    try:
        _check_pbh(params)
    except PBHError as exc:  # name the matrices to change: H to observe a mode, G or Q to drive it
        where = "model.H" if str(exc).startswith("(F, H)") else "model.G, model.Q"
        return f"{where}: {exc}"
    return None


def _full_settled(params):
    """The covariance the time-varying gain settles to: P and Pl, upper triangles."""
    try:
        gain, pl = dare_gain(params)
    except (ValueError, PBHError):
        return []
    p = (np.eye(params.n) - gain @ np.array(params.H)) @ pl
    scale = float(np.max(np.abs(pl)))
    out = []
    for name, mat in (("p", p), ("pl", pl)):
        out += [(f"{name.upper()}{i + 1}{j + 1}", float(mat[i][j]), f"{name}{i + 1}{j + 1}")
                for i in range(params.n) for j in range(i, params.n) if abs(mat[i][j]) > 1e-12 * scale]
    return out


def _full_hardware(params):
    """Whether the parallel time-varying core runs these parameters: one observation, and F's
    entries 0 or +-2**k (its products by F are shifts); the folded core runs any."""
    if params.m != 1:
        return (f"the parallel time-varying core takes one observation, not {params.m}: the folded core runs "
                "this model")
    for i, row in enumerate(params.F):
        for j, v in enumerate(row):
            if not free(v):
                return (f"model.F[{i}][{j}] = {v!r}: the parallel time-varying core needs F's entries to be 0 or "
                        "+-2**k (its products by F are shifts); the folded core runs this model")
    return None


def _steady_state(params):
    return tuple((f"x{i + 1}", f"x{i + 1}") for i in range(params.n)) + start.start_state(params)


def _full_state(params):
    tri = [(i, j) for i in range(params.n) for j in range(i, params.n)]
    return _steady_state(params) + tuple((f"p{i + 1}{j + 1}", f"p{i + 1}{j + 1}") for i, j in tri)


VARIANTS = {
    "steady": Variant("steady", "constant gain K from the Riccati equation (or given): no divider",
                      _steady_state, _steady_constants, _initial, steady_update, _steady_applies, start.hardware,
                      predict=steady_predict),
    "full": Variant("full", "time-varying gain: P, S and a restoring divider per update (two observations: "
                            "model only)", _full_state, _full_constants, _full_initial, full_update, lambda params: None,
                    lambda params: start.hardware(params) or _full_hardware(params), _full_settled,
                    predict=full_predict),
}


def _points_for(params):
    n, m = params.n, params.m
    names = [f"x{i + 1}" for i in range(n)] + [f"xl{i + 1}" for i in range(n)]
    names += [f"yh{j + 1}" for j in range(m)] + [f"e{j + 1}" for j in range(m)] + [f"k{i + 1}" for i in range(n)]
    names += [f"f{i + 1}{j + 1}" for i in range(n) for j in range(n) if not free(params.F[i][j])]
    names += [f"xo{j + 1}" for j in range(n) if any(not free(params.F[i][j]) for i in range(n))]
    tri = [(i, j) for i in range(n) for j in range(i, n)]
    names += [f"p{i + 1}{j + 1}" for i, j in tri] + [f"pl{i + 1}{j + 1}" for i, j in tri]
    names += [f"fp{i + 1}{c + 1}" for i in range(n) for c in range(n) if _fp_rounded(params, i, c)]
    names += ["s"] if m == 1 else ["s11", "s12", "s22", "det", "kn"]
    names += _cast_points(params)
    return [p for p in POINTS if p in names]


def _cast_points(params):
    """The cast points of a model with these parameters: a product term of every sum."""
    n, m, f = params.n, params.m, params.F

    def scaled(i, j):  # a term by F_ij that is not the value itself
        return f[i][j] != 0 and abs(f[i][j]) != 1

    names = [f"ft{i + 1}{j + 1}" for i in range(n) for j in range(n) if scaled(i, j)]
    names += [f"ke{i + 1}{j + 1}" for i in range(n) for j in range(m)]
    names += [f"fpt{i + 1}{j + 1}{c + 1}" for i in range(n) for j in range(n) for c in range(n) if scaled(i, c)]
    names += [f"plt{i + 1}{j + 1}{c + 1}" for i in range(n) for j in range(i, n) for c in range(n) if scaled(j, c)]
    names += [f"kh{i + 1}{j + 1}{a + 1}" for i in range(n) for j in range(i, n) for a in range(m)]
    if m == 2:
        names += ["dp1", "dp2"] + [f"kp{i + 1}{b}{t}" for i in range(n) for b in (1, 2) for t in (1, 2)]
    return names


def _fp_rounded(params, i, c):
    """Whether (F P)_ic is rounded into an operand: a constant of F that is not 0 or +-2**k
    multiplies it in (F P) F^T (an entry F_jc, j >= i)."""
    return any(not free(params.F[j][c]) for j in range(i, params.n))


def _all_points():
    states, obs = range(1, MAX_STATES + 1), range(1, MAX_OBS + 1)
    pts = [Point(f"x{i}", f"state x{i} (output)") for i in states]
    pts += [Point(f"xl{i}", f"predicted state xl{i} = (F x){i}", same_as=f"x{i}") for i in states]
    pts += [Point(f"yh{j}", f"predicted observation yhat{j} = (H xl){j} (output)") for j in obs]
    pts += [Point(f"e{j}", f"innovation e{j} = y{j} - yhat{j}", role="operand") for j in obs]
    pts += [Point(f"k{i}", f"gains of state {i}: row {i} of K (constants, or the divider's quotients)", role="operand")
            for i in states]
    pts += [Point(f"f{i}{j}", f"F[{i - 1}][{j - 1}], when it is not 0 or +-2**k (a constant)", role="operand",
                  constant=True) for i in states for j in states]
    pts += [Point(f"xo{j}", f"state x{j} rounded into the operand of its products by F", role="operand") for j in states]
    pts += [Point(f"p{i}{j}", f"covariance P{i}{j} (state)", variants=("full",), frac=f"pl{i}{j}")
            for i in states for j in range(i, MAX_STATES + 1)]
    pts += [Point(f"fp{i}{j}", f"(F P){i}{j} rounded into the operand of its products by F (time-varying)",
                  role="operand", variants=("full",)) for i in states for j in states]
    pts += [Point(f"pl{i}{j}", f"predicted covariance Pl{i}{j}", role="operand", variants=("full",))
            for i in states for j in range(i, MAX_STATES + 1)]
    pts.append(Point("s", "innovation variance S = H Pl H^T + R (divisor)", variants=("full",), frac="pl11"))
    pts += [Point(name, f"innovation covariance {what} (two observations)", role="operand", variants=("full",))
            for name, what in (("s11", "S11"), ("s12", "S12"), ("s22", "S22"))]
    pts.append(Point("det", "det S = S11 S22 - S12^2 (the divisor, two observations)", variants=("full",), frac="s11"))
    pts.append(Point("kn", "numerators of K = Pl H^T adj(S) (two observations)", variants=("full",), frac="pl11"))
    return {p.name: p for p in pts + _all_cast_points()}


def _all_cast_points():
    states, obs = range(1, MAX_STATES + 1), range(1, MAX_OBS + 1)
    pts = [Point(f"ft{i}{j}", f"F[{i - 1}][{j - 1}] x{j}, a term of (F x){i}", role="cast") for i in states for j in states]
    pts += [Point(f"ke{i}{j}", f"K[{i - 1}][{j - 1}] e{j}, a term of x{i}", role="cast") for i in states for j in obs]
    pts += [Point(f"fpt{i}{j}{c}", f"F[{i - 1}][{c - 1}] P{min(c, j)}{max(c, j)}, a term of (F P){i}{j}", role="cast",
                  variants=("full",)) for i in states for j in states for c in states]
    pts += [Point(f"plt{i}{j}{c}", f"F[{j - 1}][{c - 1}] (F P){i}{c}, a term of Pl{i}{j}", role="cast", variants=("full",))
            for i in states for j in range(i, MAX_STATES + 1) for c in states]
    pts += [Point(f"kh{i}{j}{a}", f"K[{i - 1}][{a - 1}] (H Pl)[{a - 1}][{j - 1}], a term of P{i}{j}", role="cast",
                  variants=("full",)) for i in states for j in range(i, MAX_STATES + 1) for a in obs]
    pts += [Point("dp1", "S11 S22, a term of det S (two observations)", role="cast", variants=("full",)),
            Point("dp2", "S12^2, a term of det S (two observations)", role="cast", variants=("full",))]
    terms = {(1, 1): "(H Pl)[0][{i}] S22", (1, 2): "(H Pl)[1][{i}] S12", (2, 1): "(H Pl)[1][{i}] S11",
             (2, 2): "(H Pl)[0][{i}] S12"}
    pts += [Point(f"kp{i}{b}{t}", f"{terms[(b, t)].format(i=i - 1)}, a term of K's numerator {i}{b} (two observations)",
                  role="cast", variants=("full",)) for i in states for b in (1, 2) for t in (1, 2)]
    return pts


POINTS = _all_points()


def _inputs(params):
    return tuple((name, f"observation {j + 1}") for j, name in enumerate(params.observations))


def _outputs_for(params):
    out = [Output(f"x{i + 1}", f"x{i + 1}", f"filtered state {i + 1}") for i in range(params.n)]
    out += [Output(f"yhat{j + 1}", f"yh{j + 1}", f"one-step prediction of {params.observations[j]}")
            for j in range(params.m)]
    return tuple(out)


def _measured(params):
    """The observation of the default output x1 itself (its H row picks x1 alone), if any."""
    for j, row in enumerate(params.H):
        if row[0] == 1.0 and not any(row[1:]):
            return params.observations[j]
    return None


def _stimulus(params):
    """Full-scale stimulus for every observation: the same rows, each observation's phase moved."""
    base = full_scale_stimulus(float(np.max(np.diag(params.R))))
    return {name: np.roll(base, 997 * j, axis=1) for j, name in enumerate(params.observations)}


def _ranges(params, stimulus=None):
    stimulus = _stimulus(params) if stimulus is None else stimulus
    variants = [v for name, v in VARIANTS.items() if v.applies(params) is None]
    return float_ranges(SPEC, params, variants, stimulus)


def _default_formats(params, ranges, *, operand_bits, state_frac, max_word=MAX_WORD):
    err = _error_std(params, measurement_only=True)
    # the registers' steps small against the float filter's error of each state and prediction
    # (the part the measurement noise alone causes: its floor on any signal)
    noise = None
    if err:
        noise = {f"x{i + 1}": err[f"x{i + 1}"] for i in range(params.n)}
        noise.update({f"xo{i + 1}": err[f"x{i + 1}"] for i in range(params.n)})  # x_i as F's operand
        noise.update({f"yh{j + 1}": err[f"yhat{j + 1}"] for j in range(params.m)})
    formats = register_formats(SPEC, params, ranges, operand_bits=operand_bits, state_frac=state_frac, noise=noise,
                               max_word=max_word)
    # the innovation's step must be small against the observation noise it carries into every
    # state (at most a quarter of its standard deviation), else the rounding of e, not the
    # noise, sets the error (R = 0.01: 0.1 codes); beyond the multiplier width it takes a
    # second multiplier block per product, and more fraction bits than y - yhat has are useless
    for j in range(params.m):
        e = formats[f"e{j + 1}"]
        need = noise_frac_bits(params.R[j][j])
        want = min(max(e.frac_bits, need), max(e.frac_bits, state_frac))
        if want > e.frac_bits:
            formats[f"e{j + 1}"] = QFormat(e.int_bits, want, e.rounding, e.overflow)
    _f_formats(params, ranges, formats)
    _loop_formats(params, formats, err)
    _covariance_formats(params, formats, max_word)
    # a predicted observation that is one predicted state (H selects it) keeps that state's format:
    # then it is no extra logic
    for j, row in enumerate(params.H):
        picks = [i for i, h in enumerate(row) if h != 0]
        if len(picks) == 1 and row[picks[0]] == 1:
            formats[f"yh{j + 1}"] = formats[f"xl{picks[0] + 1}"]
    return formats


def _covariance_formats(params, formats, max_word):
    """The predicted covariance that feeds the division: its guard bits, and P as fine; S as
    fine as Pl; (F P)_ic, which feeds Pl_ij through F_jc, as fine as the finest of those, two
    bits finer."""
    for i in range(params.n):
        for j in range(i, params.n):
            name = f"pl{i + 1}{j + 1}"
            if name in formats:
                pl = formats[name]
                frac = covariance_frac(pl, max_word)
                formats[name] = QFormat(pl.int_bits, frac, pl.rounding, pl.overflow)
                p = formats[f"p{i + 1}{j + 1}"]
                if p.frac_bits < frac:
                    formats[f"p{i + 1}{j + 1}"] = QFormat(p.int_bits, frac, p.rounding, p.overflow)
    if params.m == 1 and "s" in formats and "pl11" in formats and formats["s"].frac_bits < formats["pl11"].frac_bits:
        s = formats["s"]
        formats["s"] = QFormat(s.int_bits, formats["pl11"].frac_bits, s.rounding, s.overflow)
    for i in range(params.n):
        for c in range(params.n):
            name = f"fp{i + 1}{c + 1}"
            if name in formats:
                fine = max(formats[f"pl{min(i, j) + 1}{max(i, j) + 1}"].frac_bits for j in range(i, params.n)) + 2
                fp = formats[name]
                if fine > fp.frac_bits:
                    formats[name] = QFormat(fp.int_bits, max(fp.frac_bits, min(fine, max_word - fp.int_bits)), fp.rounding,
                                            fp.overflow)


def _loop_formats(params, formats, err):
    """Fraction bits of the states for the rounding the loop feeds back
    (:func:`~kfpga.model.riccati.loop_frac_bits`); x_i and xl_i share a format."""
    if not err:
        return
    try:
        gain = steady_gain(params)
    except (ValueError, PBHError):
        return
    floors = [err[f"x{j + 1}"] for j in range(params.n)]
    for i, need in enumerate(loop_frac_bits(np.array(params.F), np.array(params.H), gain, floors)):
        fmt = formats[f"x{i + 1}"]
        if need is not None and need > fmt.frac_bits:
            formats[f"x{i + 1}"] = QFormat(fmt.int_bits, need, fmt.rounding, fmt.overflow)
            formats[f"xl{i + 1}"] = formats[f"x{i + 1}"]


def _f_formats(params, ranges, formats):
    """An entry F_ij that takes a multiplier: fraction bits so that its rounding, times the largest
    x_j, stays within a quarter of an LSB of xl_i (the error it would add to every prediction),
    and at most the multiplier's width of significant bits (a small entry then has few: its
    products are small); never fewer than the 1 % its value needs."""
    for i, row in enumerate(params.F):
        for j, value in enumerate(row):
            name = f"f{i + 1}{j + 1}"
            if name not in formats:
                continue
            reach = max(ranges.get(f"x{j + 1}", 0.0), 1.0)
            need = math.ceil(math.log2(4.0 * reach / formats[f"xl{i + 1}"].lsb))
            fmt = formats[name]
            frac = max(precision_frac_bits(value), min(need, constant_frac_bits(value)))
            formats[name] = QFormat(fmt.int_bits, frac, fmt.rounding, fmt.overflow)


def _validate(config):
    f, params = config.formats, config.params
    for i, v in enumerate(params.x0):
        if not f[f"x{i + 1}"].covers(abs(v)):
            raise ConfigError(f"model.x0[{i}] = {v:g} does not fit formats.x{i + 1} = {f[f'x{i + 1}']}")
    names = {name for name, _ in config.spec.model.variants["full"].state_for(params)}
    if config.spec.model.variants["full"].applies(params) is None:
        for i in range(params.n):
            for j in range(i, params.n):
                name = f"p{i + 1}{j + 1}"
                if name in names and not f[name].covers(abs(params.P0[i][j])):
                    raise ConfigError(f"model.P0[{i}][{j}] = {params.P0[i][j]:g} does not fit formats.{name} = {f[name]}")
        r_point = "s" if params.m == 1 else "s11"
        if f[r_point].lsb / 2 > min(params.R[j][j] for j in range(params.m)):
            raise ConfigError(f"model.R rounds to 0 in formats.{r_point} = {f[r_point]} (LSB {f[r_point].lsb:g}): the "
                              f"divisor could be 0; give {r_point} more fraction bits")


def _goals(config, variant, channels=1):
    """Logic cells per state and observation; every multiplier the model needs; the board's timing goal."""
    params = config.params
    n, m = params.n, params.m
    # every product of the update on its own embedded multipliers (steady), or all on one (full);
    # an operand wider than 18 bits (an innovation with many fraction bits) takes more pieces
    report = config.width_report(variant)
    if variant == "steady":
        return {"logic_cells": 250 * n + 150 * m + 150 * n * (channels - 1), "mul18": report.blocks(),
                "lut_levels": 16, "worst_path_ns": WORST_PATH_GOAL_NS}
    return {"logic_cells": 900 * n + 300 * n * (channels - 1), "mul18": report.widest_product_blocks(),
            "lut_levels": 16, "worst_path_ns": WORST_PATH_GOAL_NS}


def _random_params(rng):
    n = int(rng.integers(1, MAX_STATES + 1))
    m = int(rng.integers(1, min(n, MAX_OBS) + 1))
    t = float(rng.choice([1.0, 0.5, 0.25]))
    f = np.eye(n)
    for i in range(n - 1):
        f[i, i + 1] = t
        if i + 2 < n:
            f[i, i + 2] = t * t / 2 if free(t * t / 2) else 0.0
    g = np.zeros((n, 1))
    g[-1, 0] = 1.0
    h = np.zeros((m, n))
    for j in range(m):
        h[j, j] = 1.0
    a = rng.normal(size=(n, n))
    p0 = a @ a.T + rng.uniform(0.5, 8) * np.eye(n)
    r = np.diag(rng.uniform(0.5, 20.0, m))
    return StateSpaceParams(F=tuple(map(tuple, f)), G=tuple(map(tuple, g)), Q=((float(rng.uniform(0.05, 5.0)),),),
                            H=tuple(map(tuple, h)), R=tuple(map(tuple, r)), P0=tuple(map(tuple, (p0 + p0.T) / 2)),
                            x0=tuple(float(v) for v in rng.normal(0, 20, n)), T=t)


def _sine_truth(params, count):
    """Noise-free states for the ``sine`` scenario: an axis is a chain of states, each the
    derivative of the one before through F (``x_i(k+1) = x_i(k) + F_i,i+1 x_i+1(k) + ...``); the first
    state of every axis that an observation sees gets a sine (the axes a quarter period apart, so
    that every one moves), and the states down its chain the derivatives that link implies."""
    from kfpga.model import scenarios

    k = np.arange(count)
    w = 2 * np.pi / scenarios.SINE_PERIOD
    truth = np.zeros((params.n, count))
    observed = {}  # state -> the H entry that sees it
    for row in params.H:
        state = next(i for i, h in enumerate(row) if h != 0)
        observed.setdefault(state, row[state])
    waves, axes = {}, 0  # state -> (amplitude, phase)
    for i in range(params.n):
        if i > 0 and i - 1 in waves and params.F[i - 1][i] != 0:  # the derivative of the state before
            a, phase = waves[i - 1]
            waves[i] = (a * w / params.F[i - 1][i], phase + np.pi / 2)
        elif i in observed:  # the first state of an axis
            waves[i] = (scenarios.SINE_AMPLITUDE / abs(observed[i]), axes * np.pi / 2)
            axes += 1
    for i, (a, phase) in waves.items():
        truth[i] = a * np.sin(w * k + phase)
    return truth


def _model_truth(params, count, rng):
    """States drawn from the model itself, ``x(k+1) = F x(k) + G w``, ``w ~ N(0, Q)`` from 0, scaled
    (all of them by one factor) when the observations would pass 3/4 of the ADC's range."""
    from kfpga.core.codes import CODE_MAX

    f, g = np.array(params.F), np.array(params.G)
    lam, vec = np.linalg.eigh(np.array(params.Q))
    root = vec @ np.diag(np.sqrt(np.clip(lam, 0.0, None)))  # Q^1/2 (Q may be singular)
    w = rng.normal(0.0, 1.0, (count, len(lam))) @ root.T @ g.T
    truth = np.empty((params.n, count))
    x = np.zeros(params.n)
    for step in range(count):
        truth[:, step] = x
        x = f @ x + w[step]
    peak = float(np.max(np.abs(np.array(params.H) @ truth))) if count else 0.0
    limit = 0.75 * CODE_MAX
    return truth * (limit / peak) if peak > limit else truth


def _scenario(name, count, seed, params):
    """``sine``: each observation a sine (:func:`_sine_truth`); ``model`` (and ``random-accel``, its
    other name here): the model's own process (:func:`_model_truth`). Each observation is its row of
    H plus noise of variance R_jj. Returns the truth of x1 and the codes."""
    from kfpga.model import scenarios

    rng = np.random.default_rng(seed)
    if name == "sine":
        truth = _sine_truth(params, count)
    elif name in ("model", "random-accel"):
        truth = _model_truth(params, count, rng)
    else:
        raise ValueError(f"scenario must be one of {', '.join(scenarios.SCENARIOS)}, not {name!r}")
    h, r = np.array(params.H), np.array(params.R)
    codes = {}
    for j, obs in enumerate(params.observations):
        clean = h[j] @ truth
        codes[obs] = scenarios.adc_codes(clean + rng.normal(0.0, np.sqrt(r[j, j]), count))
    y = codes[params.observations[0]] if params.m == 1 else codes
    return truth[0], y


def _preset_ca3():
    t = 0.5
    return StateSpaceParams(F=((1.0, t, t * t / 2), (0.0, 1.0, t), (0.0, 0.0, 1.0)), G=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                            (0.0, 0.0, 1.0)), Q=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), H=((1.0, 0.0, 0.0),),
                            R=((0.01,),), P0=((10.0, 0.0, 0.0), (0.0, 10.0, 0.0), (0.0, 0.0, 10.0)), x0=(0.0, 0.0, 0.0),
                            T=t)


def _preset_va2():
    return StateSpaceParams(F=((1.0, 1.0), (0.0, 1.0)), G=((0.0,), (1.0,)), Q=((0.05,),), H=((1.0, 0.0), (0.0, 1.0)),
                            R=((4.0, 0.0), (0.0, 1.0)), P0=((10.0, 0.0), (0.0, 10.0)), x0=(0.0, 0.0), T=1.0,
                            observations=("velocity", "acceleration"))


def _preset_fixed_gain():
    alpha, beta = 0.5, 0.5
    return StateSpaceParams(F=((1.0, 1.0), (0.0, 1.0)), gain=((alpha,), (beta,)), T=1.0)


#: Named models: ``--preset NAME``. ``cv2`` is [Zhong]'s filter itself (the ``kalman2`` filter,
#: which keeps its own datapath: the rate scaled by T, both halves of P); the others are models of
#: this general filter.
PRESETS = {
    "ca3": ("constant acceleration, T = 0.5 s ([Zhang], the ship-roll predictor; A's bottom-right entry 1; "
            "P0 = 10 I, as [Zhang]'s all-10s matrix is singular)", _preset_ca3),
    "va2": ("velocity and acceleration, both observed ([Fukuda], fed by the least-squares front end)", _preset_va2),
    "cv2-fixed-gain": ("fixed gain alpha = beta = 0.5 on the constant-velocity model ([Chen]'s values)",
                       _preset_fixed_gain),
}


def _error_std(params, *, measurement_only=False):
    """Steady-state error of every state and every predicted observation, for the steady gain
    (``measurement_only``: the part the measurement noise alone causes, its floor on any signal)."""
    from kfpga.model.reference import steady_error_std

    try:
        gain = steady_gain(params)
    except (ValueError, PBHError):
        return None
    f, gqg, h, r = params.arrays()
    states, predictions = steady_error_std(f, 0 * gqg if measurement_only else gqg, h, r, gain)
    out = {f"x{i + 1}": float(v) for i, v in enumerate(states)}
    out.update({f"yhat{j + 1}": float(v) for j, v in enumerate(predictions)})
    return out


def _coverage():
    """The README's tracker (T = 0.01: F's constants multiplied, not shifted), and states in block
    memory whose power-up word packs a negative x0."""
    from dataclasses import replace

    from kfpga.core.config import FilterConfig

    tracker = StateSpaceParams(F=((1.0, 0.01, 5e-5), (0.0, 1.0, 0.01), (0.0, 0.0, 1.0)), G=((0.0,), (0.0,), (1.0,)),
                               Q=((1.0,),), H=((1.0, 0.0, 0.0),), R=((25.0,),), T=0.01)
    negative = FilterConfig(filter=SPEC.name, params=replace(_preset_ca3(), x0=(-40.0, 3.5, -0.25)))
    return {f"{SPEC.name}-tracker-T0.01": FilterConfig(filter=SPEC.name, params=tracker),
            f"{SPEC.name}-ca3-x0-steady-parallel-9": Build(negative, "steady", channels=9, architecture="parallel")}


SPEC = FilterSpec(
    name="kalman",
    params=StateSpaceParams,
    docs=Docs(
        summary="any linear state-space model: n = 1..4 states, m = 1..2 observations, from F, G, Q, H, R",
        source="your own linear state-space model: the general form of [Zhang], [Zhong], [Fukuda] and [Chen]",
    ),
    model=Model(
        points=POINTS,
        inputs=_inputs,
        outputs=_outputs_for,
        variants=VARIANTS,
        reference=reference,
        ranges=_ranges,
        default_output="x1",
        points_for=_points_for,
        default_formats=_default_formats,
        validate=_validate,
        random_params=_random_params,
        scenario=_scenario,
        scenarios=("model", "sine", "random-accel"),
        presets=PRESETS,
        measured=_measured,
        adc=lambda params: params.adc,
        error_std=_error_std,
        period=lambda params: (params.T, False),
    ),
    hardware=Hardware(
        goals=_goals,
        coverage=_coverage,
    ),
)
