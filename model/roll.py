"""The ship-roll "combined interval" Kalman predictor of seeds/000 (SPEC §4), in float.

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
from dataclasses import dataclass
from importlib import resources

import numpy as np

from kfpga.params import matrix, number

__all__ = ["RollParams", "PAPER_P0", "transition", "predict", "table1", "synthetic_roll", "MIN_SAMPLES"]

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
    """

    T: float = 0.5
    q: float = 1.0
    R: float = 0.01
    s: float = 100.0
    P0: tuple = PAPER_P0

    def __post_init__(self):
        for name in ("T", "q", "R", "s"):
            object.__setattr__(self, name, number(name, getattr(self, name), minimum=0.0, strict=True))
        p0 = matrix("P0", self.P0, 3, 3, symmetric=True)
        if np.min(np.linalg.eigvalsh(np.array(p0))) < -1e-12:
            raise ValueError(f"P0 must be positive semi-definite, not {self.P0!r}")
        object.__setattr__(self, "P0", p0)


def transition(T):
    """The constant-acceleration transition over ``T`` (the paper's A with its bottom-right 1)."""
    return np.array([[1.0, T, T * T / 2.0], [0.0, 1.0, T], [0.0, 0.0, 1.0]])


def _start(z, step):
    """A filter's state from its first three samples ``z`` (``step`` apart): angle, rate, acceleration."""
    return np.array([z[2], (z[2] - z[1]) / step, (z[2] - 2.0 * z[1] + z[0]) / step ** 2])


def _cholesky(p, what):
    try:
        return np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        raise ValueError(f"{what} is not positive definite: the square-root form needs its Cholesky factor") from None


def _filter(z, params, *, improved, sqrt, fading):
    """One filter over its own samples ``z``: ``(predictions, covariances)``; prediction k (from
    sample k on, for sample k + 1) is NaN for the three samples that start it."""
    step = 2.0 * params.T
    a = transition(step)
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


def predict(z, params=None, *, improved=True, sqrt=True, fading=True):
    """The combined interval predictor over the roll series ``z`` (deg, every ``T``): an array
    ``p`` where ``p[n]`` is the prediction, made when sample n came, of sample n + 2 (1 s later
    at T = 0.5 s); NaN where a filter is still starting. ``improved=False`` is the paper's basic
    form (``sqrt`` and ``fading`` then do not apply). Raises ``ValueError`` for fewer than
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
        part, _ = _filter(z[parity::2], params, improved=improved, sqrt=sqrt and improved, fading=fading and improved)
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
