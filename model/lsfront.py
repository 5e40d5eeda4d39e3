"""The least-squares pseudo-acceleration front end of [Fukuda] (Furuno, JP3218441B2), in float.

A ship's speed log gives the velocity alone. The front end keeps its last ``Ns`` samples, fits a
line to them by least squares, and gives the Kalman filter of the ``va2`` model (state velocity
and acceleration, both observed) the line's value at the newest sample (the estimated velocity)
and its slope (the pseudo-acceleration) as its two observations. While fewer than ``Ns``
samples exist, the filter takes the raw velocity alone, as an m = 1 update. ``Ns`` follows the
magnitude of the filter's velocity innovation through a table of thresholds: a small innovation
(the ship steady) a long window, a large one (a manoeuvre) a short window (the patent's sample
point number determiner S).

**The fit with running sums** (O(1) per sample, as hardware would do it): over the window,
index ``k = 0 .. N-1`` from the oldest, ``S0 = sum v_k`` and ``S1 = sum k v_k``. When the window
slides by one, ``S0' = S0 - v_old + v_new`` and ``S1' = S1 - (S0 - v_old) + (N - 1) v_new``.
The slope is ``b = (N S1 - K1 S0) / D`` with ``K1 = N(N-1)/2``, ``K2 = (N-1)N(2N-1)/6``,
``D = N K2 - K1^2`` (a constant divisor per N: one product by ``1/D``), the value at the newest
sample ``(S0 - b K1) / N + b (N - 1)``. A window of each N in the table is kept at once, so
changing N needs no refit. The tests hold every fit equal to ``numpy.polyfit`` on its window.

The observations' noise, for the filter's R: with raw velocity noise ``r`` (variance), the line's
end value has variance ``r (1/N + ((N-1)/2)^2 / Sxx)`` and its slope ``r / (Sxx T^2)``,
``Sxx = N (N^2 - 1) / 12``. Successive fits share most of their samples, so their errors are
correlated in time, which the filter does not know: the patent's design, kept as it is.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from kfpga.core.codes import CODE_FORMAT, CODE_MAX
from kfpga.core.fixed import QFormat, Rounding, bits_for
from kfpga.core.formats import MAX_WORD
from kfpga.core.params import number
from kfpga.core.spec import Constant, Docs, FilterSpec, Hardware, Model, MutationBlock, Output, Point, Variant

#: The longest window the table may name.
MAX_WINDOW = 64

__all__ = ["LSFrontParams", "RunningFit", "line_fit", "lsfront", "kalman_va", "moving_average", "fit_variances",
           "MAX_WINDOW", "SPEC", "POINTS", "window_constants", "scaled_constant", "sum_formats", "fit_bounds",
           "code_model", "mode_gains", "thresholds", "push", "fit", "next_window", "lsfront_update", "switched"]


@dataclass(frozen=True, kw_only=True)
class LSFrontParams:
    """The front end and its filter (defaults: a speed log at 1 Hz, in m/s).

    Parameters
    ----------
    T:
        Sample period (s), > 0.
    q:
        Variance of the acceleration's change per step (the filter's process noise, on the
        acceleration), > 0.
    r:
        Variance of the raw velocity's noise ((m/s)^2), > 0.
    table:
        ``((threshold, Ns), ...)``: the window for a velocity innovation below each threshold,
        thresholds rising, the last one ``inf``; every Ns an integer >= 3 and at most
        :data:`MAX_WINDOW`.
    lsb:
        m/s per ADC code of the speed log, > 0 (the bit-accurate front end and its core work in
        codes; default 1 mm/s: +-32.8 m/s full scale).
    """

    T: float = 1.0
    q: float = 1e-5
    r: float = 0.01
    table: tuple = ((0.1, 30), (0.3, 12), (math.inf, 5))
    lsb: float = 0.001

    def __post_init__(self):
        for name in ("T", "q", "r", "lsb"):
            object.__setattr__(self, name, number(name, getattr(self, name), minimum=0.0, strict=True))
        try:
            rows = [(float(t), n) for t, n in self.table]
        except (TypeError, ValueError):
            raise TypeError(f"table must be pairs (threshold, Ns), not {self.table!r}") from None
        if not rows:
            raise ValueError("table must have at least one (threshold, Ns) row")
        for t, n in rows:
            if not isinstance(n, int) or isinstance(n, bool) or n < 3:
                raise ValueError(f"Ns must be an integer >= 3 (a line through fewer points has no noise to "
                                 f"suppress), not {n!r}")
            if n > MAX_WINDOW:
                raise ValueError(f"Ns must be at most {MAX_WINDOW} (the window's samples are state: each costs a "
                                 f"register per channel and a move per update), not {n!r}")
            if not t > 0:
                raise ValueError(f"a threshold must be > 0, not {t!r}")
        if any(b[0] <= a[0] for a, b in itertools.pairwise(rows)):
            raise ValueError(f"the thresholds must rise, not {[t for t, _ in rows]}")
        if rows[-1][0] != math.inf:
            raise ValueError("the last threshold must be inf: every innovation needs a window")
        object.__setattr__(self, "table", tuple(rows))

    @property
    def windows(self):
        return sorted({n for _, n in self.table})

    def window_for(self, innovation):
        """Ns for a velocity innovation of this magnitude."""
        return next(n for t, n in self.table if abs(innovation) < t)


def line_fit(s0, s1, n):
    """``(value at the newest sample, slope per sample)`` of the least-squares line from the
    running sums of a window of ``n`` samples."""
    k1 = n * (n - 1) / 2.0
    k2 = (n - 1) * n * (2 * n - 1) / 6.0
    slope = (n * s1 - k1 * s0) / (n * k2 - k1 * k1)
    return (s0 - slope * k1) / n + slope * (n - 1), slope


class RunningFit:
    """The running sums of one window length ``n``: :meth:`push` a sample, O(1)."""

    def __init__(self, n):
        self.n = n
        self.window = []
        self.s0 = 0.0
        self.s1 = 0.0

    def push(self, v):
        if len(self.window) < self.n:
            self.s1 += len(self.window) * v
            self.s0 += v
            self.window.append(v)
            return
        old = self.window.pop(0)
        self.s1 = self.s1 - (self.s0 - old) + (self.n - 1) * v
        self.s0 = self.s0 - old + v
        self.window.append(v)

    @property
    def full(self):
        return len(self.window) == self.n

    def fit(self):
        return line_fit(self.s0, self.s1, self.n)


def fit_variances(n, r, T):
    """``(variance of the line's end value, variance of its slope per second)`` for raw noise ``r``."""
    sxx = n * (n * n - 1) / 12.0
    end = (n - 1) / 2.0
    return r * (1.0 / n + end * end / sxx), r / (sxx * T * T)


def _kalman(params):
    f = np.array([[1.0, params.T], [0.0, 1.0]])
    gq = np.array([[0.0, 0.0], [0.0, params.q]])
    return f, gq


def _update(x, p, z, h, r):
    s = h @ p @ h.T + r
    k = p @ h.T @ np.linalg.inv(s)
    innov = z - h @ x
    return x + k @ innov, (np.eye(2) - k @ h) @ p, innov


def lsfront(v, params=None, *, x0=None, p0=None):
    """The LS-fed Kalman filter over the velocities ``v``: ``{"velocity", "acceleration", "Ns",
    "fit_velocity", "fit_acceleration"}`` per sample (``Ns`` 0 where the raw velocity went in
    alone; the fits NaN there)."""
    params = LSFrontParams() if params is None else params
    v = np.asarray(v, dtype=np.float64)
    f, gq = _kalman(params)
    x = np.array([v[0], 0.0]) if x0 is None else np.asarray(x0, dtype=np.float64)
    p = np.diag([params.r, 1.0]) if p0 is None else np.asarray(p0, dtype=np.float64)
    fits = {n: RunningFit(n) for n in params.windows}
    ns = params.table[0][1]
    out = {k: np.full(len(v), np.nan) for k in ("velocity", "acceleration", "fit_velocity", "fit_acceleration")}
    out["Ns"] = np.zeros(len(v), dtype=np.int64)
    for i, value in enumerate(v):
        for fit in fits.values():
            fit.push(value)
        if i:
            x, p = f @ x, f @ p @ f.T + gq
        fit = fits[ns]
        if fit.full:
            fv, slope = fit.fit()
            var_v, var_a = fit_variances(ns, params.r, params.T)
            x, p, innov = _update(x, p, np.array([fv, slope / params.T]), np.eye(2), np.diag([var_v, var_a]))
            out["Ns"][i], out["fit_velocity"][i], out["fit_acceleration"][i] = ns, fv, slope / params.T
        else:
            x, p, innov = _update(x, p, np.array([value]), np.array([[1.0, 0.0]]), np.array([[params.r]]))
        ns = params.window_for(innov[0])
        out["velocity"][i], out["acceleration"][i] = x
    return out


def kalman_va(v, params=None, *, a=None, r_a=None):
    """The Kalman filter of the same model on the raw velocity alone (``a`` None), or with a
    measured acceleration ``a`` of noise variance ``r_a`` as its second observation."""
    params = LSFrontParams() if params is None else params
    v = np.asarray(v, dtype=np.float64)
    f, gq = _kalman(params)
    x, p = np.array([v[0], 0.0]), np.diag([params.r, 1.0])
    out = {"velocity": np.empty(len(v)), "acceleration": np.empty(len(v))}
    for i, value in enumerate(v):
        if i:
            x, p = f @ x, f @ p @ f.T + gq
        if a is None:
            x, p, _ = _update(x, p, np.array([value]), np.array([[1.0, 0.0]]), np.array([[params.r]]))
        else:
            x, p, _ = _update(x, p, np.array([value, a[i]]), np.eye(2), np.diag([params.r, r_a]))
        out["velocity"][i], out["acceleration"][i] = x
    return out


def moving_average(v, window):
    """The mean of the last ``window`` samples (fewer at the start)."""
    v = np.asarray(v, dtype=np.float64)
    c = np.concatenate([[0.0], np.cumsum(v)])
    k = np.arange(len(v))
    lo = np.maximum(0, k - window + 1)
    return (c[k + 1] - c[lo]) / (k - lo + 1)


# -- the bit-accurate front end and its filter ----------------------------------------------------------------
#
# One update per speed-log sample, in ADC codes: the velocity in codes, the acceleration in codes
# per sample (times T), so that the transition is F = [[1, 1], [0, 1]] (its products are sums)
# whatever T is. The filter is the ``va2`` model in steady state: one gain set for each way the
# front end can feed it (m = 1, the raw velocity, while the window in use is not full; m = 2, the
# fit of each window Ns), from the discrete Riccati equation of that mode's H and R, and
# selected at run time. The time-varying filter of the float model (``lsfront``) would need a
# 2 x 2 inverse per sample and a covariance that jumps with Ns; the switched steady-state filter
# is its fixed-point form, and :func:`switched` is that form in float (the reference the integer
# model is compared with, and whose distance from ``lsfront`` the evaluation shows).
#
# An update, exactly as the model and the core compute it:
#
#   first = not primed                    (the first sample starts the filter at (v, 0), as lsfront)
#   every window n:  S0 = S0 - w_n + v    S1 = S1 - (S0_old - w_n) + (n - 1) v     (exact integers)
#   count = min(count + 1, max Ns)        m1 = ns > count   (the window in use is not full)
#   b  = [ (n S1 - K1 S0) * 2^s/D * 2^-s ]_b      the slope, one product by a constant per window
#   fv = [ S0 * 2^t/n * 2^-t + b (n - 1)/2 ]_fv   the line at the newest sample (the raw v if m1)
#   xl1 = [x1 + x2]_xl1 (v if first)      xl2 = x2 (0 if first)
#   e1 = [fv - xl1]_e1                    e2 = [b - xl2]_e2 (0 if m1)
#   x1 = [xl1 + K11 e1 + K12 e2]_x1       x2 = [xl2 + K21 e1 + K22 e2]_x2     (K of the mode)
#   ns = the table's window for |e1| (thresholds in codes)
#
# where w_n is the sample n before (the delay line w1..wN, zero after reset: a window not yet
# full holds zeros, which m1 keeps out of the filter), and the window of b, fv and K is the one
# in use (ns). Every value is selected before it is written into a point, so a window not in use
# never raises the overflow flag.

#: The format of the "primed" flag: 0 after reset, 1 once a sample came.
FLAG = QFormat(2, 0)
#: Significant bits of a constant factor (1/D, 1/n): an 18-bit operand, its binary point moved.
CONSTANT_BITS = 18


def _integer_format(magnitude):
    return QFormat(bits_for(magnitude, 0), 0)


def window_constants(n):
    """``(K1, D)`` of a window of ``n``: ``K1 = sum k = n(n-1)/2`` and ``D = n sum k^2 - K1^2``."""
    k1 = n * (n - 1) // 2
    k2 = (n - 1) * n * (2 * n - 1) // 6
    return k1, n * k2 - k1 * k1


def scaled_constant(value, label):
    """``(Constant, s)``: ``value = c * 2**-s`` with ``c`` in [1/2, 1) held in ``CONSTANT_BITS``
    bits; the product by ``value`` is one by ``c`` and a binary point moved by ``s`` (free)."""
    s = -math.frexp(value)[1]  # value = m 2**e with m in [1/2, 1): s = -e
    return Constant(value * 2.0 ** s, QFormat(1, CONSTANT_BITS - 1, Rounding.NEAREST), label), s


def sum_formats(n):
    """``(S0, S1)`` formats of a window of ``n``: exact for any codes (``|S0| <= n 2^15``,
    ``|S1| <= K1 2^15``)."""
    k1, _ = window_constants(n)
    return _integer_format(n * (CODE_MAX + 1)), _integer_format(k1 * (CODE_MAX + 1))


def count_format(params):
    return _integer_format(max(params.windows))


def fit_bounds(n):
    """``(largest |fv|, largest |b|)`` of the line through any ``n`` codes: the weights of the
    end value and of the slope, summed in magnitude, times the largest code."""
    k = np.arange(n)
    k1, d = window_constants(n)
    slope_w = (n * k - k1) / d
    end_w = 1.0 / n + slope_w * (n - 1) / 2.0
    big = float(CODE_MAX + 1)
    return float(np.abs(end_w).sum() * big), float(np.abs(slope_w).sum() * big)


def code_model(params, m, n=None):
    """The ``va2`` model in the codes' units for mode ``m`` (1: the raw velocity; 2: the fit of a
    window of ``n``): ``(F, G Q G^T, H, R)`` as arrays."""
    scale = params.lsb ** 2
    q = params.q * params.T ** 2 / scale  # the acceleration's change per step, in (codes/sample)^2
    f, gqg = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[0.0, 0.0], [0.0, q]])
    if m == 1:
        return f, gqg, np.array([[1.0, 0.0]]), np.array([[params.r / scale]])
    var_v, var_a = fit_variances(n, params.r, params.T)
    return f, gqg, np.eye(2), np.diag([var_v / scale, var_a * params.T ** 2 / scale])


def mode_gains(params):
    """``{0: K (2 x 2), n: K (2 x 2), ...}``: the steady-state gain of each mode (0: m = 1, its
    second column 0; n: the fit of a window of n), from the discrete Riccati equation."""
    from kfpga.model.riccati import dare

    out = {0: np.hstack([dare(*code_model(params, 1))[0], np.zeros((2, 1))])}
    for n in params.windows:
        out[n] = dare(*code_model(params, 2, n))[0]
    return out


def thresholds(params):
    """The table's thresholds in codes, and the window below each (the last threshold ``inf``)."""
    return [(t / params.lsb, n) for t, n in params.table]


def _by_window(ops, k, ns, values):
    """``values[n]`` of the window ``ns`` in use (a chain of comparisons with the window lengths)."""
    windows = k["windows"]
    out = values[windows[-1]]
    for n in reversed(windows[:-1]):
        out = ops.select(ops.gt(ns, k[f"n{n}"]), out, values[n])   # ns > n: a longer window
    return out


def push(ops, k, x, v):
    """Every window's running sums after the sample ``v`` (exact): ``{n: (S0, S1)}``."""
    sums = {}
    for n in k["windows"]:
        f0, f1 = k["sum_formats"][n]
        rest = ops.sub(x[f"s0_{n}"], x[f"w{n}"])                                             # S0 - v_old
        s0 = ops.rq(ops.add(rest, v), f0, f"s0_{n}")                                        # S0 + v - v_old
        s1 = ops.rq(ops.add(ops.sub(x[f"s1_{n}"], rest), ops.mul(k[f"m{n}"], v)), f1, f"s1_{n}")  # S1 - rest + (n-1) v
        sums[n] = (s0, s1)
    return sums


def fit(ops, k, sums, ns, m1, v):
    """``(fv, b)``: the line of the window in use at the newest sample, and its slope per sample;
    the raw sample and 0 while that window is not full (``m1``)."""
    slopes = {}
    for n, (s0, s1) in sums.items():
        num = ops.sub(ops.mul(k[f"n{n}"], s1), ops.mul(k[f"k1_{n}"], s0))                  # n S1 - K1 S0
        slopes[n] = ops.shift(ops.mul(num, k[f"invd{n}"]), -k[f"invd{n}_shift"])             # / D
    b = ops.rq(ops.select(m1, k["zero"], _by_window(ops, k, ns, slopes)), "b")
    ends = {n: ops.add(ops.shift(ops.mul(s0, k[f"invn{n}"]), -k[f"invn{n}_shift"]), ops.mul(b, k[f"h{n}"]))
            for n, (s0, _) in sums.items()}                                                   # S0 / n + b (n-1)/2
    fv = ops.rq(ops.select(m1, v, _by_window(ops, k, ns, ends)), "fv")
    return fv, b


def next_window(ops, k, e1):
    """Ns for the next sample: the table's window for ``|e1|``."""
    mag = ops.abs(e1)
    out = k[f"n{k['table'][-1]}"]
    for j in range(len(k["table"]) - 2, -1, -1):
        out = ops.select(ops.gt(k[f"t{j}"], mag), k[f"n{k['table'][j]}"], out)  # |e1| < threshold j
    return out


def lsfront_update(ops, k, x, u):
    """One sample of the front end and its steady-state filter: ``(next state, outputs)``."""
    v = u["v"]
    first = ops.gt(k["one"], x["primed"])
    sums = push(ops, k, x, v)
    count = ops.rq(ops.min(ops.add(x["count"], k["one"]), k["nmax"]), k["count_format"], "count")
    ns = x["ns"]
    m1 = ops.gt(ns, count)                                                                    # the window not full
    fv, b = fit(ops, k, sums, ns, m1, v)
    xl1 = ops.rq(ops.select(first, v, ops.add(x["x1"], x["x2"])), "xl1")                     # xl1 = x1 + x2
    xl2 = ops.select(first, k["zero"], x["x2"])                                              # xl2 = x2
    e1 = ops.rq(ops.sub(fv, xl1), "e1")                                                      # e1 = fv - xl1
    e2 = ops.rq(ops.select(m1, k["zero"], ops.sub(b, xl2)), "e2")                           # e2 = b - xl2
    gains = {}
    for i in (1, 2):
        for j in (1, 2):
            per_window = {n: k[f"K{i}{j}_{n}"] for n in k["windows"]}
            gains[i, j] = ops.select(m1, k[f"K{i}{j}_0"], _by_window(ops, k, ns, per_window))
    x1 = ops.rq(ops.add(xl1, ops.add(ops.mul(gains[1, 1], e1), ops.mul(gains[1, 2], e2))), "x1")   # x1 = xl1 + K e
    x2 = ops.rq(ops.add(xl2, ops.add(ops.mul(gains[2, 1], e1), ops.mul(gains[2, 2], e2))), "x2")   # x2 = xl2 + K e
    used = ops.rq(ops.select(m1, k["zero"], ns), k["count_format"], "ns_used")
    state = {"x1": x1, "x2": x2, "count": count, "primed": k["one"],
             "ns": ops.rq(next_window(ops, k, e1), k["count_format"], "ns")}
    for n, (s0, s1) in sums.items():
        state[f"s0_{n}"], state[f"s1_{n}"] = s0, s1
    state["w1"] = v
    for i in range(2, max(k["windows"]) + 1):
        state[f"w{i}"] = x[f"w{i - 1}"]
    return state, {"velocity": x1, "accel": x2, "ns": used}


def _state(params):
    out = [("x1", "x1"), ("x2", "x2"), ("count", count_format(params)), ("ns", count_format(params)),
           ("primed", FLAG)]
    for n in params.windows:
        f0, f1 = sum_formats(n)
        out += [(f"s0_{n}", f0), (f"s1_{n}", f1)]
    out += [(f"w{i}", CODE_FORMAT) for i in range(1, max(params.windows) + 1)]
    return tuple(out)


def _constants(params):
    nmax = max(params.windows)
    out = {"windows": tuple(params.windows), "table": tuple(n for _, n in params.table),
           "sum_formats": {n: sum_formats(n) for n in params.windows}, "count_format": count_format(params),
           "one": Constant(1.0, QFormat(2, 0), "1"), "zero": Constant(0.0, QFormat(2, 0), "0"),
           "nmax": Constant(float(nmax), count_format(params), "max Ns")}
    for n in params.windows:
        k1, d = window_constants(n)
        out[f"n{n}"] = Constant(float(n), count_format(params), f"N = {n}")
        out[f"m{n}"] = Constant(float(n - 1), count_format(params), f"N - 1 = {n - 1}")
        out[f"k1_{n}"] = Constant(float(k1), _integer_format(k1), f"K1 = {k1}")
        out[f"invd{n}"], out[f"invd{n}_shift"] = scaled_constant(1.0 / d, f"1/D = 1/{d}")
        out[f"invn{n}"], out[f"invn{n}_shift"] = scaled_constant(1.0 / n, f"1/{n}")
        out[f"h{n}"] = Constant((n - 1) / 2.0, QFormat(bits_for((n - 1) / 2.0, 1), 1), f"({n} - 1)/2")
    for j, (t, _) in enumerate(thresholds(params)[:-1]):
        out[f"t{j}"] = Constant(t, "threshold", f"threshold {j}")
    for mode, gain in mode_gains(params).items():
        for i in (1, 2):
            for j in (1, 2):
                out[f"K{i}{j}_{mode}"] = Constant(float(gain[i - 1][j - 1]), f"k{i}", f"K[{i - 1}][{j - 1}] of "
                                                  + ("m = 1" if mode == 0 else f"Ns = {mode}"))
    return out


def _initial(params):
    out = {name: 0.0 for name, _ in _state(params)}
    out["ns"] = float(params.table[0][1])
    return out


def switched(codes, params):
    """The switched steady-state filter in float, on the codes along the last axis (the model's
    equations in real arithmetic, written apart from the stage functions): ``{"velocity",
    "accel", "ns"}`` in codes, codes per sample and samples."""
    codes = np.asarray(codes, dtype=np.float64)
    gains = mode_gains(params)
    table = thresholds(params)
    out = {name: np.empty(codes.shape) for name in ("velocity", "accel", "ns")}
    for index in np.ndindex(codes.shape[:-1]):
        fits = {n: RunningFit(n) for n in params.windows}
        x, ns = None, params.table[0][1]
        for i, value in enumerate(codes[index]):
            for f in fits.values():
                f.push(value)
            if x is None:
                x = np.array([value, 0.0])                     # the first sample starts the filter
                xl = x.copy()
            else:
                xl = np.array([x[0] + x[1], x[1]])             # xl = F x
            if fits[ns].full:
                fv, slope = fits[ns].fit()
                gain, z, used = gains[ns], np.array([fv, slope]), ns
            else:
                gain, z, used = gains[0], np.array([value, xl[1]]), 0
            e = z - xl
            x = xl + gain @ e                                  # x = xl + K (z - xl)
            out["velocity"][(*index, i)], out["accel"][(*index, i)], out["ns"][(*index, i)] = x[0], x[1], used
            ns = next(n for t, n in table if abs(e[0]) < t)
    return out


POINTS = {p.name: p for p in (
    Point("x1", "velocity estimate (codes; output)"),
    Point("xl1", "predicted velocity xl1 = x1 + x2", same_as="x1"),
    Point("x2", "acceleration estimate (codes per sample; output)"),
    Point("fv", "the velocity observation: the line's value at the newest sample (the raw sample while m = 1)"),
    Point("b", "the slope observation: the line's slope per sample (0 while m = 1)"),
    Point("e1", "velocity innovation e1 = fv - xl1", role="operand"),
    Point("e2", "acceleration innovation e2 = b - x2", role="operand"),
    Point("k1", "gains of the velocity, one pair per mode (constants)", role="operand", constant=True),
    Point("k2", "gains of the acceleration, one pair per mode (constants)", role="operand", constant=True),
    Point("threshold", "the table's thresholds on |e1| (constants, codes)", constant=True),
)}


def _points_for(params):
    names = list(POINTS)
    return names if len(params.table) > 1 else [p for p in names if p != "threshold"]


def _stimulus(params):
    """Full-scale steps and sines of the speed log's codes, with its noise."""
    from kfpga.model.ranges import full_scale_stimulus

    return full_scale_stimulus(params.r / params.lsb ** 2, segment=1024)


def _ranges(params, stimulus=None):
    from kfpga.model.ranges import float_ranges

    ranges = float_ranges(SPEC, params, list(VARIANTS.values()), _stimulus(params) if stimulus is None else stimulus)
    # the fit of any codes, not only of the stimulus's: its bound over every window (a window
    # not yet full is a window of zeros and codes, so the bound covers it too)
    bounds = [fit_bounds(n) for n in params.windows]
    ranges["fv"] = max(ranges.get("fv", 0.0), float(CODE_MAX + 1), *(end for end, _ in bounds))
    ranges["b"] = max(ranges.get("b", 0.0), *(slope for _, slope in bounds))
    return ranges


def _default_formats(params, ranges, *, operand_bits, state_frac, max_word=MAX_WORD):
    from kfpga.core.formats import noise_frac_bits, register_formats

    formats = register_formats(SPEC, params, ranges, operand_bits=operand_bits, state_frac=state_frac, max_word=max_word)
    # an innovation's step small against the noise of the observation it carries (a quarter of
    # its standard deviation): the slope of the longest window is the quietest observation
    n = max(params.windows)
    _, var_a = fit_variances(n, params.r, params.T)
    need = noise_frac_bits(var_a * params.T ** 2 / params.lsb ** 2)
    e2 = formats["e2"]
    if need > e2.frac_bits:
        formats["e2"] = QFormat(e2.int_bits, need, e2.rounding, e2.overflow)
    return formats


def _validate(config):
    return None


def _random_params(rng):
    windows = sorted({int(n) for n in rng.integers(3, 17, int(rng.integers(1, 4)))}, reverse=True)
    limits = sorted(float(t) for t in rng.uniform(0.02, 0.5, len(windows) - 1))
    table = tuple(zip([*limits, math.inf], windows, strict=True))
    return LSFrontParams(T=float(rng.choice([1.0, 0.5, 2.0])), q=float(10 ** rng.uniform(-6, -3)),
                         r=float(10 ** rng.uniform(-3, -1)), table=table, lsb=float(rng.choice([0.001, 0.002, 0.0005])))


def _goals(config, variant, channels=1):
    """The folded core's: one multiplier of the widest product (a window's sums by its
    constants: up to 2 x 2 embedded multipliers), the program and the registers in block memory,
    4,000 logic cells for the adder, the shifter, the multiplier's operands and their multiplexers
    (the words are as wide as the widest exact value, a window's slope before it is rounded: 58
    bits by default); every path within one cycle of the 50 MHz system clock (a sample a second
    leaves no reason to pipeline it)."""
    return {"logic_cells": 4000, "mul18": 4, "lut_levels": 16, "worst_path_ns": 20.0}


def _scenario(name, n, seed, params):
    """A ship's speed log in codes: ``sine``, 5 m/s varying by 2 m/s over 600 samples; ``random-accel``,
    the model's own (white changes of the acceleration of variance q), from 5 m/s; both with the
    log's noise r. The truth is the speed (codes)."""
    from kfpga.model.scenarios import adc_codes

    rng = np.random.default_rng([seed, 3])
    k = np.arange(n)
    if name == "sine":
        truth = 5.0 + 2.0 * np.sin(2 * np.pi * k / 600.0)
    elif name == "random-accel":
        accel = np.cumsum(rng.normal(0.0, math.sqrt(params.q), n))
        accel -= np.convolve(accel, np.ones(200) / 200.0, mode="same")  # a drift-free acceleration
        truth = np.clip(5.0 + np.cumsum(accel) * params.T, -30.0, 30.0)
    else:
        raise ValueError(f"scenario must be one of sine, random-accel, not {name!r}")
    codes = adc_codes((truth + rng.normal(0.0, math.sqrt(params.r), n)) / params.lsb)
    return truth / params.lsb, codes


def reference(params, variant, y):
    return switched(y, params)


VARIANTS = {
    "steady": Variant("steady", "the line fit of the window in use (m = 2) or the raw velocity (m = 1) into the va2 "
                                "filter with that mode's steady-state gain", _state, _constants, _initial,
                      lsfront_update),
}


def _mutation():
    """``make mutate``: the folded core of the front end on 120 stress samples."""
    from kfpga.core.config import FilterConfig

    return [MutationBlock("folded core (lsfront)", FilterConfig(filter=SPEC.name), "steady", {"samples": 120})]


SPEC = FilterSpec(
    name="lsfront",
    params=LSFrontParams,
    docs=Docs(
        summary="the least-squares pseudo-acceleration front end into the va2 filter: a line through the last Ns speed-log "
                "samples gives the velocity and its slope, Ns from the innovation; steady-state gains per mode",
        source="[Fukuda]: Fukuda (Furuno), JP3218441B2, a ship's speed with a least-squares front end to a Kalman filter",
        aliases=("ls-frontend",),
    ),
    model=Model(
        points=POINTS,
        inputs=(("v", "the speed log's velocity (a 16-bit ADC code, lsb m/s per code)"),),
        outputs=(Output("velocity", "x1", "the velocity estimate (codes)"),
                 Output("accel", "x2", "the acceleration estimate (codes per sample)"),
                 Output("ns", QFormat(8, 0), "the window of this sample's fit, 0 for the raw velocity (m = 1)")),
        variants=VARIANTS,
        reference=reference,
        ranges=_ranges,
        default_output="velocity",
        points_for=_points_for,
        default_formats=_default_formats,
        validate=_validate,
        random_params=_random_params,
        scenario=_scenario,
        scenarios=("sine", "random-accel"),
        period=lambda params: (params.T, True),
    ),
    hardware=Hardware(
        goals=_goals,
        mutation=_mutation,
    ),
    evaluation="kfpga.model.evaluations.lsfront:EVALUATION",
)
