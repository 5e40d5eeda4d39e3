"""The ship-roll "combined interval" Kalman predictor of [Zhang], in float.

The roll angle is sampled every ``T`` = 0.5 s. Two 3-state constant-acceleration filters take
alternate samples (even and odd), so each sees one sample per ``2 T`` = 1 s, and each predicts
its next sample: 2 samples (1 s) ahead. Together they give a prediction for every sample.
A filter's step is ``A(T)^2 = A(2 T)`` (the model is exact over two sample periods), with the
paper's A corrected (its bottom-right entry is 1, not T), H = [1 0 0], Q = I per step,
R = 0.01 deg^2. Each filter starts from its first three samples: angle, rate and acceleration
by differences.

**Basic** (the paper's §1, predict then update): when a sample comes, the filter puts out
``A x`` (its state before the sample, moved one step on) and then takes the sample in. The
prediction a filter gives at a sample is so the one it made a step before: it lags by a step.

**Improved** (§2): update then predict: the sample first (gain, estimate, covariance from the
prediction), then the prediction ``A x`` that goes out, with fading memory
``P- = A (s P) A^T + Q`` (the paper's s = 100; 1 is no fading) and, with ``sqrt=True``, the
covariance carried as a square root: Potter's measurement update of the paper's equations
19-20 (``M = D^T H^T``, ``N = 1 / (M^T M + R)``, ``O = 1 / (1 + sqrt(N R))``, ``K = N D M``,
``D = D - O K M^T``) and a Cholesky factor of ``A (s D D^T) A^T + Q`` for the time update.

**P0.** The paper's P0 (all entries 10) is singular (rank 1): it has no Cholesky factor. A
filter here starts at its third sample with the state from its first three and ``P0``, and
moves both one step on before its first update: the square root is first taken of
``A P0 A^T + Q``, which is positive definite for any positive semi-definite P0 since Q = q I
with q > 0. So the paper's P0 is used as printed (the default, :data:`PAPER_P0`); ``10 I``
(the ``ca3`` preset's) changes the figures in the third decimal.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from importlib import resources

import numpy as np

from kfpga.core.fixed import QFormat
from kfpga.core.formats import MAX_WORD
from kfpga.core.params import matrix, number
from kfpga.core.spec import Constant, Docs, FilterSpec, Hardware, Model, Output, Point, Variant
from kfpga.model.start import check_init, measured

__all__ = ["RollParams", "PAPER_P0", "transition", "predict", "table1", "synthetic_roll", "MIN_SAMPLES", "SPEC",
           "sqrt_update", "plain_update", "pair_update", "PAIR", "PHASE", "FILTER_STATE", "unit_matrices", "reference",
           "predict_fixed", "predict_same_start", "covariance_ok", "word_sweep", "word_config"]

#: The paper's P0 (its equation 23): all entries 10, rank 1.
PAPER_P0 = ((10.0, 10.0, 10.0), (10.0, 10.0, 10.0), (10.0, 10.0, 10.0))
#: Each of the two filters needs 3 samples to start and one more to predict: 8 samples in all.
MIN_SAMPLES = 8


@dataclass(frozen=True, kw_only=True)
class RollParams:
    """Parameters of the interval predictor (defaults: the paper's).

    Parameters
    ----------
    T:
        Sample period (s), > 0; each of the two filters steps by 2 T.
    q:
        Process-noise variance per filter step (Q = q I), > 0.
    R:
        Measurement-noise variance (deg^2), > 0.
    s:
        Fading-memory factor of the improved form, > 0 (1: none; the paper's 100).
    P0:
        Covariance at each filter's start (default: the paper's all-10s matrix; symmetric and
        positive semi-definite).
    lsb:
        Degrees per ADC code of the roll sensor, > 0 (the bit-accurate filter and its core work
        in codes; default 0.01 deg, the resolution of the paper's table 1: +-327 deg full scale).
    init:
        ``"state"``: each filter of the bit-accurate predictor (and its core) starts from x = 0 and
        lets its first samples set the state; ``"measurement"``: from its first three samples
        (angle, rate and acceleration by differences), as the paper does (:func:`start_update`).
    """

    T: float = 0.5
    q: float = 1.0
    R: float = 0.01
    s: float = 100.0
    P0: tuple = PAPER_P0
    lsb: float = 0.01
    init: str = "state"

    def __post_init__(self):
        object.__setattr__(self, "init", check_init(self.init))
        for name in ("T", "q", "R", "s", "lsb"):
            object.__setattr__(self, name, number(name, getattr(self, name), minimum=0.0, strict=True))
        p0 = matrix("P0", self.P0, 3, 3, symmetric=True)
        if np.min(np.linalg.eigvalsh(np.array(p0))) < -1e-12:
            raise ValueError(f"P0 must be positive semi-definite, not {self.P0!r}")
        object.__setattr__(self, "P0", p0)


def transition(T, *, a33=1.0):
    """The constant-acceleration transition over ``T`` (the paper's A with its bottom-right 1);
    ``a33``: another bottom-right entry (eq. (22) prints T there)."""
    return np.array([[1.0, T, T * T / 2.0], [0.0, 1.0, T], [0.0, 0.0, a33]])


def _start(z, step):
    """A filter's state from its first three samples ``z`` (``step`` apart): angle, rate, acceleration."""
    return np.array([z[2], (z[2] - z[1]) / step, (z[2] - 2.0 * z[1] + z[0]) / step ** 2])


def _cholesky(p, what):
    try:
        return np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        raise ValueError(f"{what} is not positive definite: the square-root form needs its Cholesky factor") from None


def _filter(z, params, *, improved, sqrt, fading, printed=False):
    """One filter over its own samples ``z``: ``(predictions, covariances)``; prediction k (from
    sample k on, for sample k + 1) is NaN for the three samples that start it."""
    step = 2.0 * params.T
    # eq. (22) prints T, the sample period, in the bottom-right corner: the acceleration then
    # shrinks by T each step (with T the filter's own 1 s step the printed A would be the model's)
    a = transition(step, a33=params.T if printed else 1.0)
    h = np.array([1.0, 0.0, 0.0])
    q = params.q * np.eye(3)
    n = len(z)
    out = np.full(n, np.nan)
    covs = [None] * n
    if n < 3:
        return out, covs
    x = a @ _start(z[:3], step)  # the prediction for the 4th sample
    p = a @ np.array(params.P0) @ a.T + q
    s = params.s if fading else 1.0
    d = _cholesky(p, "the first prediction covariance A P0 A^T + Q") if sqrt else None
    if not improved:
        x, p = _start(z[:3], step), np.array(params.P0)
        out[2] = (a @ x)[0]
    else:
        out[2] = x[0]
    for k in range(3, n):
        if improved:
            if sqrt:
                m = d.T @ h
                nn = 1.0 / (m @ m + params.R)
                o = 1.0 / (1.0 + np.sqrt(nn * params.R))
                gain = nn * (d @ m)
                x = x + gain * (z[k] - x[0])
                d = d - o * np.outer(gain, m)
                p = d @ d.T
            else:
                gain = p @ h / (h @ p @ h + params.R)
                x = x + gain * (z[k] - x[0])
                p = (np.eye(3) - np.outer(gain, h)) @ p
            covs[k] = p
            x = a @ x
            p = a @ (s * p) @ a.T + q
            if sqrt:
                d = _cholesky(p, "the prediction covariance A (s P) A^T + Q")
            out[k] = x[0]
        else:
            # the basic order: the prediction made from the state before this sample goes out
            xp = a @ x
            pp = a @ p @ a.T + q
            out[k] = xp[0]
            gain = pp @ h / (h @ pp @ h + params.R)
            x = xp + gain * (z[k] - xp[0])
            p = (np.eye(3) - np.outer(gain, h)) @ pp
            covs[k] = p
    return out, covs


def predict(z, params=None, *, improved=True, sqrt=True, fading=True, printed_a=False):
    """The combined interval predictor over the roll series ``z`` (deg, every ``T``): an array
    ``p`` where ``p[n]`` is the prediction, made when sample n came, of sample n + 2 (1 s later
    at T = 0.5 s); NaN where a filter is still starting. ``improved=False`` is the paper's basic
    form (``sqrt`` and ``fading`` then do not apply). ``printed_a``: the transition as eq. (22)
    prints it, the sample period T in its bottom-right corner (float only; the core has the
    model's A). Raises ``ValueError`` for fewer than
    :data:`MIN_SAMPLES` samples."""
    params = RollParams() if params is None else params
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 1 or len(z) < MIN_SAMPLES:
        raise ValueError(f"the interval predictor needs a series of at least {MIN_SAMPLES} samples (each of its two "
                         f"filters starts from 3 and predicts from the 4th), not {len(z) if z.ndim == 1 else z.shape}")
    if not np.all(np.isfinite(z)):
        raise ValueError("the roll series must be finite numbers")
    if not improved and (sqrt is not True or fading is not True):
        raise ValueError("sqrt and fading are options of the improved form")
    out = np.full(len(z), np.nan)
    for parity in (0, 1):
        part, _ = _filter(z[parity::2], params, improved=improved, sqrt=sqrt and improved, fading=fading and improved,
                          printed=printed_a)
        out[parity::2] = part
    return out


def prediction_rmse(z, prediction, ahead=2):
    """RMSE of ``prediction[n]`` against ``z[n + ahead]`` where both exist."""
    z = np.asarray(z, dtype=np.float64)
    err = prediction[:-ahead] - z[ahead:]
    ok = np.isfinite(err)
    return float(np.sqrt(np.mean(err[ok] ** 2))), int(ok.sum())


def table1():
    """``(time s, roll deg)`` of the paper's table 1, shipped as ``kfpga/data/roll_table1.csv``."""
    text = resources.files("kfpga").joinpath("data/roll_table1.csv").read_text()
    rows = [r for r in csv.reader(line for line in text.splitlines() if not line.startswith("#")) if r]
    data = np.array([[float(a), float(b)] for a, b in rows[1:]])
    return data[:, 0], data[:, 1]


def synthetic_roll(n=480, seed=1, *, T=0.5, noise=0.02):
    """A roll series (deg) of ``n`` samples every ``T``, like the paper's table 1 (a swell of
    about 10 s, about 1 deg): three sinusoids of 8-12 s with random phases and slowly varying
    amplitude, plus white measurement noise of ``noise`` deg (the table's samples, given to
    0.01 deg, vary smoothly: far less than the AHRS's 0.1 deg accuracy, which the paper's R
    stands for). ``(time, roll, clean roll)``."""
    rng = np.random.default_rng([seed, 0])
    t = np.arange(1, n + 1) * T
    clean = np.zeros(n)
    for period, amp in ((10.0, 0.9), (8.3, 0.25), (12.5, 0.2)):
        envelope = 1.0 + 0.3 * np.sin(2 * np.pi * t / rng.uniform(60, 120) + rng.uniform(0, 2 * np.pi))
        clean += amp * envelope * np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi))
    return t, clean + rng.normal(0, noise, n), clean


# -- the bit-accurate predictor: the pair of filters, in ADC codes ---------------------------------------------
#
# The registered filter is the combined interval predictor: its state holds both filters (``a_``:
# the even samples', ``b_``: the odd samples') and the phase; each sample goes to the filter whose
# turn it is (its state selected, updated once, written back; the other filter's state kept), and
# the output is that filter's prediction of its next sample, 2 samples ahead. One filter's
# state is in codes and per filter step (tau = 2 T): x1 the angle, x2 the rate times tau,
# x3 the acceleration times tau^2, so the transition is A = [[1, 1, 1/2], [0, 1, 1], [0, 0, 1]]
# whatever T is (its products are shifts), and the noises are Q = q diag(1, tau^2, tau^4) / lsb^2,
# R / lsb^2. Each filter starts from x = 0 and the prediction covariance A P0 A^T + Q (the paper's
# P0 is used as printed, see above): its first samples set the state.
#
# ``sqrt`` (the hardware's): the covariance as its lower-triangular square root D (P- = D D^T),
# six registers. Potter's measurement update with H = [1 0 0] changes only D's first column:
#     S = d11^2 + R     K = d11 D[:, 0] / S     D[:, 0] = sqrt(R / S) D[:, 0]     x = x + K e
# (the paper's eqs. 19-20 with M = D^T H^T = (d11, 0, 0): its O K M^T is the column times
# 1 - sqrt(R/S)). The time update never forms P: the 3 x 6 matrix [sqrt(s) A D, sqrt(Q)] is
# brought to lower-triangular form [D-, 0] by Givens rotations, each ``r = sqrt(a^2 + b^2)``,
# ``c = a / r``, ``s = b / r`` on one restoring square root and two divisions; then
# D- D-^T = s A D D^T A^T + Q exactly in real arithmetic. Rows 1 and 2 take three rotations each
# (the zeros of sqrt(Q) need none); the last row's diagonal is the norm of what is left of it.
# A square root is the floor of the exact root (``Ops.sqrt``), a quotient truncated toward zero,
# every other write rounded by its point's rule.
#
# ``plain``: the same order and fading with P itself (six registers, symmetric):
#     S = p11 + R   K = P[:, 0] / S   P = P - K P[0, :]   x = x + K e
#     x- = A x      P- = s [A P A^T] + Q
# model only: it is the yardstick of the word-length sweep (``pd_sweep``).

#: The transition over one filter step in its own units (rows of (coefficient, column)).
_A = (((1.0, 0), (1.0, 1), (0.5, 2)), ((1.0, 1), (1.0, 2)), ((1.0, 2),))


def _units(params):
    """``(tau, S)``: the filter step and the scaling of (angle, rate, acceleration) into codes per step."""
    tau = 2.0 * params.T
    return tau, np.diag([1.0, tau, tau * tau]) / params.lsb


def unit_matrices(params):
    """``(A, Q, R, P-0)`` in the filter's own units: codes and filter steps."""
    _, scale = _units(params)
    a = transition(1.0)
    q = params.q * scale @ scale
    return a, q, params.R / params.lsb ** 2, a @ (scale @ np.array(params.P0) @ scale) @ a.T + q


def _scaled(ops, c, v):
    """``c * v`` for a transition coefficient 1 or 1/2: the value, or its binary point moved."""
    return v if c == 1.0 else ops.shift(v, -1)


def _row(ops, terms):
    out = None
    for c, v in terms:
        if v is not None:
            out = _scaled(ops, c, v) if out is None else ops.add(out, _scaled(ops, c, v))
    return out


def _predict_state(ops, xs):
    """x- = A x+ (the shifts of A, each sum rounded into its point)."""
    return [ops.rq(_row(ops, [(c, xs[j]) for c, j in row]), f"x{i + 1}") if len(row) > 1 else xs[i]
            for i, row in enumerate(_A)]


def _rotate(ops, m, p, c, tag):
    """One Givens rotation of columns p and c that zeroes m[p][c] (rows below p turn with it)."""
    a, b = m[p][p], m[p][c]
    r = ops.sqrt(ops.add(ops.mul(a, a), ops.mul(b, b)), "d", f"r{tag}")        # r = sqrt(a^2 + b^2)
    cos, sin = ops.div(a, r, "cs", f"c{tag}"), ops.div(b, r, "cs", f"s{tag}")   # c = a / r, s = b / r
    for q in range(p + 1, 3):
        u, v = m[q][p], m[q][c]
        turned_p = [ops.mul(cos, u) if u is not None else None, ops.mul(sin, v) if v is not None else None]
        turned_c = [ops.mul(cos, v) if v is not None else None, ops.neg(ops.mul(sin, u)) if u is not None else None]
        m[q][p] = ops.rq(_row(ops, [(1.0, t) for t in turned_p]), "d", f"u{tag}{q}")   # c u + s v
        m[q][c] = ops.rq(_row(ops, [(1.0, t) for t in turned_c]), "d", f"v{tag}{q}")   # c v - s u
    m[p][p], m[p][c] = r, None


def sqrt_update(ops, k, x, u):
    """One update of the square-root predictor: ``(next state, outputs)`` (see above)."""
    e = ops.rq(ops.sub(u["z"], x["x1"]), "e")                                        # e = z - x1
    d11 = x["d11"]
    sq = ops.mul(d11, d11)
    s = ops.rq(ops.add(sq, k["R"]), "s")                                             # S = d11^2 + R
    f = ops.div(k["sqrt_r"], ops.sqrt(s, "rs"), "f")                                 # f = sqrt(R / S)
    col = [d11, x["d21"], x["d31"]]
    kn = [ops.rq(sq, "kn", "kn1")] + [ops.rq(ops.mul(d11, col[i]), "kn", f"kn{i + 1}") for i in (1, 2)]
    gains = [ops.div(n, s, "k", f"K{i + 1}") for i, n in enumerate(kn)]             # K = d11 D[:, 0] / S
    xs = [ops.rq(ops.add(x[f"x{i + 1}"], ops.mul(g, e)), f"x{i + 1}", f"xu{i + 1}")  # x = x + K e
          for i, g in enumerate(gains)]
    col = [ops.rq(ops.mul(f, v), "d", f"dm{i + 1}") for i, v in enumerate(col)]     # D[:, 0] = f D[:, 0]
    xp = _predict_state(ops, xs)                                                      # x- = A x
    d = [[col[0], None, None], [col[1], x["d22"], None], [col[2], x["d32"], x["d33"]]]
    m = [[None] * 6 for _ in range(3)]
    for i, row in enumerate(_A):                                                      # [sqrt(s) A D, sqrt(Q)]
        for j in range(3):
            b = _row(ops, [(c, d[col_][j]) for c, col_ in row])
            if b is not None:
                m[i][j] = ops.rq(ops.mul(k["sqrt_s"], b), "d", f"m{i + 1}{j + 1}")
        m[i][3 + i] = k[f"g{i + 1}"]
    for p, cols in ((0, (1, 2, 3)), (1, (2, 3, 4))):
        for c in cols:
            _rotate(ops, m, p, c, f"{p + 1}{c + 1}")
    rest = [v for v in m[2][2:] if v is not None]
    norm = ops.sqrt(_row(ops, [(1.0, ops.mul(v, v)) for v in rest]), "d", "r33")    # d33 = |row 3 left|
    state = {"x1": xp[0], "x2": xp[1], "x3": xp[2], "d11": m[0][0], "d21": m[1][0], "d31": m[2][0],
             "d22": m[1][1], "d32": m[2][1], "d33": norm}
    return state, {"pred": xp[0], "rate": xp[1], "accel": xp[2]}


def plain_update(ops, k, x, u):
    """One update of the plain (covariance) predictor: ``(next state, outputs)``."""
    e = ops.rq(ops.sub(u["z"], x["x1"]), "e")                                        # e = z - x1

    def p(i, j):
        return x[f"p{min(i, j) + 1}{max(i, j) + 1}"]

    s = ops.rq(ops.add(p(0, 0), k["R"]), "ps")                                        # S = p11 + R
    gains = [ops.div(p(i, 0), s, "pk", f"K{i + 1}") for i in range(3)]               # K = P[:, 0] / S
    xs = [ops.rq(ops.add(x[f"x{i + 1}"], ops.mul(g, e)), f"x{i + 1}", f"xu{i + 1}")  # x = x + K e
          for i, g in enumerate(gains)]
    pu = {(i, j): ops.rq(ops.sub(p(i, j), ops.mul(gains[i], p(0, j))), "p", f"pu{i + 1}{j + 1}")
          for i in range(3) for j in range(i, 3)}                                     # P = P - K P[0, :]

    def pu_(i, j):
        return pu[(min(i, j), max(i, j))]

    xp = _predict_state(ops, xs)                                                      # x- = A x
    ap = [[_row(ops, [(c, pu_(col, j)) for c, col in row]) for j in range(3)] for row in _A]   # A P
    state = {"x1": xp[0], "x2": xp[1], "x3": xp[2]}
    for i in range(3):
        for j in range(i, 3):
            apa = ops.rq(_row(ops, [(c, ap[i][col]) for c, col in _A[j]]), "p", f"apa{i + 1}{j + 1}")  # A P A^T
            total = ops.mul(k["fade"], apa)
            if i == j:
                total = ops.add(total, k[f"q{i + 1}"])
            state[f"p{i + 1}{j + 1}"] = ops.rq(total, "p", f"p{i + 1}{j + 1}")       # P- = s A P A^T + Q
    return state, {"pred": xp[0], "rate": xp[1], "accel": xp[2]}


#: The format of the phase: 0 when the next sample is filter a's, 1 when it is filter b's.
PHASE = QFormat(2, 0)
#: The two filters of the pair: the even samples' and the odd samples'.
PAIR = ("a", "b")


#: The format of a filter's start count (init = "measurement"): 0, 1, 2, then -1.
START_COUNT = QFormat(3, 0)


def start_update(update):
    """One filter's ``update`` with the paper's start (``init = "measurement"``): its first two
    samples stored (``m1``, ``m2``; the outputs the sample itself and zero rates); at the third the
    state from the three by differences, angle ``z``, rate ``z - m2``, acceleration ``z - 2 m2 +
    m1`` (per filter step), moved one step on (``A x``: the prediction that goes out) with the
    covariance still the start's; the usual update from the fourth on. Without the start
    (no ``start`` in the constants) ``update`` itself."""

    def step(ops, k, x, u):
        nxt, outs = update(ops, k, x, u)
        if "start" not in k:
            return nxt, outs
        count = x["start"]
        running = ops.gt(k["count0"], count)                                          # count = -1
        second = ops.gt(count, k["count0"])                                           # count >= 1
        third = ops.gt(count, k["count1"])                                            # count = 2
        z = ops.rq(u["z"], "x1", "z_start")
        accel = ops.rq(ops.add(ops.sub(z, ops.shift(x["m2"], 1)), x["m1"]), "x3", "x3_start")  # z - 2 m2 + m1
        rate = ops.rq(ops.sub(z, x["m2"]), "x2", "x2_start")                          # z - m2
        started = _predict_state(ops, [z, rate, accel])                                # A x
        state = {n: ops.select(running, v, x[n]) for n, v in nxt.items()}             # the covariance: the start's
        for i, v in enumerate(started):
            name = f"x{i + 1}"
            state[name] = ops.select(running, nxt[name], ops.select(third, v, x[name]))
        state["m1"] = ops.select(running, x["m1"], ops.select(second, x["m1"], z))
        state["m2"] = ops.select(third, x["m2"], ops.select(second, z, x["m2"]))
        state["start"] = ops.select(running, k["count_done"], ops.select(third, k["count_done"],
                                                                         ops.select(second, k["count2"], k["count1"])))
        firsts = {"pred": z, "rate": k["count0"], "accel": k["count0"]}
        outs = {name: ops.select(running, v, ops.select(third, started[i], firsts[name]))
                for i, (name, v) in enumerate(outs.items())}
        return state, outs

    step.__name__ = update.__name__
    step.__doc__ = update.__doc__
    return step


def pair_update(update, names):
    """The interval predictor's update from one filter's ``update`` over its state ``names``
    (and the start's, when the constants have it): the filter whose turn it is takes the sample,
    the other keeps its state."""
    update = start_update(update)
    with_start = (*names, "start", "m1", "m2")

    def step(ops, k, x, u):
        names = with_start if "start" in k else step.names
        odd = ops.gt(x["phase"], k["zero"])                                           # filter b's turn
        mine = {n: ops.select(odd, x[f"b_{n}"], x[f"a_{n}"]) for n in names}
        nxt, outs = update(ops, k, mine, u)
        state = {"phase": ops.select(odd, k["zero"], k["one"])}
        for n in names:
            state[f"a_{n}"] = ops.select(odd, x[f"a_{n}"], nxt[n])
            state[f"b_{n}"] = ops.select(odd, nxt[n], x[f"b_{n}"])
        return state, outs

    step.names = tuple(names)
    step.__name__ = f"pair_{update.__name__}"
    step.__doc__ = f"The interval predictor's update: {update.__doc__}"
    return step


def _paired(state):
    """The pair's state from one filter's (with the start's, for ``init = "measurement"``)."""

    def of(params):
        one = (*state, *((("start", START_COUNT), ("m1", "x1"), ("m2", "x1")) if measured(params) else ()))
        return (*((f"{f}_{n}", p) for f in PAIR for n, p in one), ("phase", PHASE))

    return of


# -- the spec ----------------------------------------------------------------------------------------------

def _phase_constants(params):
    out = {"zero": Constant(0.0, PHASE, "0"), "one": Constant(1.0, PHASE, "1")}
    if measured(params):
        out.update({"start": True, **{f"count{v}": Constant(float(v), START_COUNT, str(v)) for v in (0, 1, 2)},
                    "count_done": Constant(-1.0, START_COUNT, "-1")})
    return out


def _sqrt_constants(params):
    _, q, r, _ = unit_matrices(params)
    out = {**_phase_constants(params), "R": Constant(r, "s", "R"), "sqrt_r": Constant(math.sqrt(r), "rs", "sqrt(R)"),
           "sqrt_s": Constant(math.sqrt(params.s), "sqs", "sqrt(s)")}
    out.update({f"g{i + 1}": Constant(math.sqrt(q[i, i]), "d", f"sqrt(Q)[{i}]") for i in range(3)})
    return out


def _plain_constants(params):
    _, q, r, _ = unit_matrices(params)
    out = {**_phase_constants(params), "R": Constant(r, "ps", "R"), "fade": Constant(params.s, "fade", "s")}
    out.update({f"q{i + 1}": Constant(q[i, i], "p", f"Q[{i}]") for i in range(3)})
    return out


_TRI = ((0, 0), (1, 0), (2, 0), (1, 1), (2, 1), (2, 2))


def _pair_initial(one, params):
    if measured(params):
        one = {**one, "start": 0.0, "m1": 0.0, "m2": 0.0}
    return {**{f"{f}_{n}": v for f in PAIR for n, v in one.items()}, "phase": 0.0}


def _sqrt_initial(params):
    d = np.linalg.cholesky(unit_matrices(params)[3])
    return _pair_initial({"x1": 0.0, "x2": 0.0, "x3": 0.0, **{f"d{i + 1}{j + 1}": float(d[i, j]) for i, j in _TRI}}, params)


def _plain_initial(params):
    p = unit_matrices(params)[3]
    return _pair_initial({"x1": 0.0, "x2": 0.0, "x3": 0.0, **{f"p{j + 1}{i + 1}": float(p[j, i]) for i, j in _TRI}}, params)


_X_STATE = (("x1", "x1"), ("x2", "x2"), ("x3", "x3"))
#: One filter's state in each form.
FILTER_STATE = {"sqrt": _X_STATE + tuple((f"d{i + 1}{j + 1}", "d") for i, j in _TRI),
                "plain": _X_STATE + tuple((f"p{j + 1}{i + 1}", "p") for i, j in _TRI)}
VARIANTS = {
    "sqrt": Variant("sqrt", "improved form, square-root covariance: Potter's update and a Givens time update",
                    _paired(FILTER_STATE["sqrt"]), _sqrt_constants, _sqrt_initial,
                    pair_update(sqrt_update, [n for n, _ in FILTER_STATE["sqrt"]])),
    "plain": Variant("plain", "improved form with the covariance itself (model only: the yardstick of the "
                              "square-root form's word lengths)",
                     _paired(FILTER_STATE["plain"]), _plain_constants, _plain_initial,
                     pair_update(plain_update, [n for n, _ in FILTER_STATE["plain"]]),
                     hardware=lambda params: "the plain covariance form is model-only: the core carries the square "
                                             "root (variant sqrt)"),
}

POINTS = {p.name: p for p in (
    Point("x1", "predicted roll angle, one filter step (2 samples) ahead (output)"),
    Point("x2", "predicted roll rate times the filter step (output)"),
    Point("x3", "predicted roll acceleration times the filter step squared (output)"),
    Point("e", "innovation e = z - x1", role="operand"),
    Point("d", "square-root covariance D and the matrix the time update triangularises", variants=("sqrt",)),
    Point("s", "innovation variance S = d11^2 + R: the divisor of the gains", variants=("sqrt",)),
    Point("rs", "sqrt(S)", variants=("sqrt",), frac="d"),
    Point("f", "sqrt(R / S): the factor of D's first column", role="operand", variants=("sqrt",)),
    Point("kn", "gain numerators d11 D[i][0]", variants=("sqrt",), frac="d"),
    Point("k", "gains K", role="operand", variants=("sqrt",)),
    Point("cs", "cosine and sine of a Givens rotation", role="operand", variants=("sqrt",)),
    Point("sqs", "sqrt(s), the fading factor's root (constant)", role="operand", variants=("sqrt",), constant=True),
    Point("p", "covariance P (plain form)", variants=("plain",)),
    Point("ps", "innovation variance S = p11 + R (plain form)", variants=("plain",)),
    Point("pk", "gains K (plain form)", role="operand", variants=("plain",)),
    Point("fade", "the fading factor s (constant, plain form)", role="operand", variants=("plain",), constant=True),
)}


def _points_for(params):
    return list(POINTS)


def reference(params, variant, z):
    """The interval predictor in float, in the filters' own units (codes, filter steps), each
    filter of the pair on its own samples (even, odd) from the start the bit-accurate one has
    (x = 0, P- = A P0 A^T + Q; or from the first three samples with ``init = "measurement"``):
    ``{"pred", "rate", "accel"}`` along the last axis of ``z``
    (codes), each sample's the prediction of the filter that took it. Both variants are the
    same filter in real arithmetic; this is the plain form, written independently of the stage
    functions."""
    a, q, r, p0 = unit_matrices(params)
    z = np.asarray(z, dtype=np.float64)
    out = {name: np.empty(z.shape) for name in ("pred", "rate", "accel")}
    for index in np.ndindex(z.shape[:-1]):
        for parity in (0, 1):
            _one_filter(a, q, r, p0, params.s, z[index][parity::2], out, index, parity, measured(params))
    return out


def _one_filter(a, q, r, p0, fade, z, out, index, parity, start=False):
    x, p = np.zeros(3), p0.copy()
    for n, zn in enumerate(z):
        if start and n < 3:  # init = "measurement": two samples stored, the state from three
            x = a @ _start(z[:3], 1.0) if n == 2 else np.array([zn, 0.0, 0.0])
            for name, value in zip(("pred", "rate", "accel"), x, strict=True):
                out[name][(*index, 2 * n + parity)] = value
            continue
        gain = p[:, 0] / (p[0, 0] + r)                  # K = P H^T / (H P H^T + R)
        x = x + gain * (zn - x[0])                      # x = x + K (z - H x)
        p = p - np.outer(gain, p[0, :])                 # P = (I - K H) P
        x, p = a @ x, a @ (fade * p) @ a.T + q          # x = A x, P = A (s P) A^T + Q
        for name, value in zip(("pred", "rate", "accel"), x, strict=True):
            out[name][(*index, 2 * n + parity)] = value


def _stimulus(params):
    """Full-scale steps and sines in codes (the covariance does not depend on them)."""
    from kfpga.model.ranges import full_scale_stimulus

    return full_scale_stimulus(unit_matrices(params)[2], segment=512)


def _ranges(params, stimulus=None):
    from kfpga.model.ranges import float_ranges

    return float_ranges(SPEC, params, list(VARIANTS.values()), _stimulus(params) if stimulus is None else stimulus)


def _default_formats(params, ranges, *, operand_bits, state_frac, max_word=MAX_WORD):
    from kfpga.core.formats import register_formats

    formats = register_formats(SPEC, params, ranges, operand_bits=operand_bits, state_frac=state_frac, max_word=max_word)
    # the innovation as fine as the angle: the gain of the angle is close to 1 (s = 100 keeps the
    # prediction covariance far above R), so e's rounding goes into every prediction undamped
    # (0.013 deg rms with whole codes, 0.0002 with x1's fraction bits); its product is on the
    # folded core's one multiplier, which the squares of D already make wider than 18 bits
    e, x1 = formats["e"], formats["x1"]
    formats["e"] = QFormat(e.int_bits, max(e.frac_bits, x1.frac_bits), e.rounding, e.overflow)
    # the plain form's covariance is a multiplier operand (K P, s A P A^T): within the word budget,
    # its range taking the integer bits and the rest fraction bits
    p = formats["p"]
    if p.width > max_word:
        formats["p"] = QFormat(p.int_bits, max(0, max_word - p.int_bits), p.rounding, p.overflow)
    return formats


def _validate(config):
    return None


def _random_params(rng):
    return RollParams(T=float(rng.choice([0.5, 0.25, 1.0])), q=float(rng.uniform(0.2, 3.0)),
                      R=float(rng.uniform(0.002, 0.05)), s=float(rng.choice([1.0, 4.0, 100.0, rng.uniform(1.0, 50.0)])),
                      lsb=float(rng.choice([0.01, 0.005, 0.02])))


def _goals(config, variant, channels=1):
    """The folded core's: one multiplier of the widest product (its squares of D take 2 x 2
    embedded multipliers), the program and the registers in block memory, 5,000 logic cells for
    the units and their multiplexers; every path within one cycle of the 50 MHz system clock (an
    update every half second leaves no reason to pipeline it further)."""
    return {"logic_cells": 5000, "mul18": 4, "lut_levels": 16, "worst_path_ns": 20.0}


def _scenario(name, n, seed, params):
    """The synthetic roll series in codes (its one scenario, ``roll``); the truth of the prediction
    at sample k is the clean roll at sample k + 2."""
    from kfpga.model.scenarios import adc_codes

    if name != "roll":
        raise ValueError(f"scenario must be roll, not {name!r}")
    _, noisy, clean = synthetic_roll(n + 2, seed, T=params.T)
    return clean[2:] / params.lsb, adc_codes(noisy[:n] / params.lsb)


SPEC = FilterSpec(
    name="roll",
    params=RollParams,
    docs=Docs(
        summary="ship-roll interval predictor: two constant-acceleration filters on alternate samples, improved form, "
                "square-root covariance; each sample's prediction of the sample 2 ahead (1 s)",
        source="[Zhang]: Zhang et al. 2021, the combined interval Kalman predictor of ship roll",
    ),
    model=Model(
        points=POINTS,
        inputs=(("z", "the roll angle (a 16-bit ADC code, lsb degrees per code)"),),
        outputs=(Output("pred", "x1", "the predicted roll angle of the sample 2 ahead (the next of the filter that took this one)"),
                 Output("rate", "x2", "the predicted roll rate times the filter step"),
                 Output("accel", "x3", "the predicted roll acceleration times the filter step squared")),
        variants=VARIANTS,
        reference=reference,
        ranges=_ranges,
        default_output="pred",
        points_for=_points_for,
        default_formats=_default_formats,
        validate=_validate,
        random_params=_random_params,
        scenario=_scenario,
        scenarios=("roll",),
        period=lambda params: (params.T, True),
    ),
    hardware=Hardware(
        goals=_goals,
    ),
    evaluation="kfpga.model.evaluations.roll:EVALUATION",
)


# -- the bit-accurate interval predictor and its word lengths -------------------------------------------------

#: The points of each form's covariance path: the registers, and the multiplier operands (gains,
#: rotations, the factor of D's column), the word-length sweep's two knobs.
COVARIANCE_POINTS = {"sqrt": (("d", "s", "rs", "kn"), ("k", "cs", "f")), "plain": (("p", "ps"), ("pk",))}


def _codes(z, params):
    from kfpga.model.scenarios import adc_codes

    return adc_codes(np.asarray(z, dtype=np.float64) / params.lsb)


def predict_same_start(z, params=None):
    """The improved predictor in float from the bit-accurate one's start (each filter from x = 0
    and A P0 A^T + Q, on the ADC codes of ``z``): its predictions in degrees, aligned as
    :func:`predict`'s (``p[n]`` predicts ``z[n + 2]``)."""
    params = RollParams() if params is None else params
    return reference(params, "sqrt", _codes(z, params))["pred"] * params.lsb


def covariance_ok(variant, values, prefix=""):
    """Whether the covariance of a filter's state (raw integers; ``prefix`` names the filter of
    the pair, ``"a_"`` or ``"b_"``) is positive definite: for the square-root form every diagonal
    entry of D above 0 (P = D D^T), for the plain form every eigenvalue of P above 0."""
    v = {k[len(prefix):]: int(np.asarray(x)) for k, x in values.items() if k.startswith(prefix)}
    if variant == "sqrt":
        return v["d11"] > 0 and v["d22"] > 0 and v["d33"] > 0
    p = np.array([[v["p11"], v["p12"], v["p13"]], [v["p12"], v["p22"], v["p23"]], [v["p13"], v["p23"], v["p33"]]],
                 dtype=np.float64)
    return bool(np.all(np.linalg.eigvalsh(p) > 0))


def predict_fixed(z, config, variant="sqrt", *, check=False):
    """The combined interval predictor in the bit-accurate model: ``(predictions in degrees,
    aligned as :func:`predict`'s, overflowed updates, updates whose covariance is not positive
    definite)``; the last is counted only with ``check`` (one model call per sample, the
    covariance of the filter that took it)."""
    from kfpga.core.fixedmodel import FixedModel

    params = config.params
    codes = _codes(z, params)
    model = FixedModel(config, variant=variant)
    lsb = config.formats["x1"].lsb * params.lsb
    if not check:
        result = model.run(codes)
        return result.outputs["pred"] * lsb, int(result.overflow.sum()), 0
    state, preds, overflowed, not_pd = None, [], 0, 0
    for n, code in enumerate(codes):
        result = model.run(np.array([code]), state=state)
        state = result.state
        preds.append(int(result.outputs["pred"][0]))
        overflowed += int(result.overflow[0])
        not_pd += not covariance_ok(variant, state.values, f"{PAIR[n % 2]}_")
    return np.array(preds) * lsb, overflowed, not_pd


def word_config(base, variant, register_frac, operand_bits):
    """``base`` with the covariance path of ``variant`` at ``register_frac`` fraction bits in its
    registers and ``operand_bits``-bit multiplier operands (each keeping its integer bits); or the
    reason the config refuses those formats (a constant they cannot hold)."""
    from kfpga.core.config import ConfigError, FilterConfig

    registers, operands = COVARIANCE_POINTS[variant]
    formats = dict(base.formats)
    for name in registers:
        formats[name] = QFormat(base.formats[name].int_bits, register_frac)
    for name in operands:
        formats[name] = QFormat(base.formats[name].int_bits, max(0, operand_bits - base.formats[name].int_bits))
    try:
        return FilterConfig(filter="roll", params=base.params, formats=formats, check_ranges=False)
    except ConfigError as exc:
        return str(exc)


def word_sweep(z, params=None, *, register_fracs=(0, 4, 8), operand_bits=(12, 14, 16, 18, 20, 22, 24, 26, 28)):
    """Both forms of the predictor over word lengths: for each form, register fraction bits and
    operand width, the updates whose covariance is not positive definite, the overflowed updates,
    the prediction RMSE (deg) and the largest difference from the float predictor (same start)."""
    from kfpga.core.config import FilterConfig

    params = RollParams() if params is None else params
    z = np.asarray(z, dtype=np.float64)
    base = FilterConfig(filter="roll", params=params)
    float_pred = predict_same_start(z, params)
    rows = []
    for variant in ("sqrt", "plain"):
        for frac in register_fracs:
            for bits in operand_bits:
                config = word_config(base, variant, frac, bits)
                row = {"form": variant, "register_frac": frac, "operand_bits": bits}
                if isinstance(config, str):
                    rows.append({**row, "why_not": config})
                    continue
                pred, overflowed, not_pd = predict_fixed(z, config, variant, check=True)
                ok = np.isfinite(pred[:-2]) & np.isfinite(float_pred[:-2])
                rmse, _ = prediction_rmse(z, pred)
                rows.append({**row, "covariance_width": config.formats[COVARIANCE_POINTS[variant][0][0]].width,
                             "updates": len(z), "not_positive_definite": not_pd, "overflowed": overflowed,
                             "rmse_deg": rmse, "max_from_float_deg": float(np.max(np.abs(pred - float_pred)[:-2][ok]))})
    return rows
