"""The least-squares pseudo-acceleration front end of seeds/003 (Furuno, JP3218441B2), in float.

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

from kfpga.params import number

__all__ = ["LSFrontParams", "RunningFit", "line_fit", "lsfront", "kalman_va", "moving_average", "fit_variances"]


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
        thresholds rising, the last one ``inf``; every Ns an integer >= 3.
    """

    T: float = 1.0
    q: float = 1e-5
    r: float = 0.01
    table: tuple = ((0.1, 30), (0.3, 12), (math.inf, 5))

    def __post_init__(self):
        for name in ("T", "q", "r"):
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
    ns = params.window_for(math.inf) if len(params.table) == 1 else params.table[0][1]
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
