"""Float64 reference Kalman filters for the paper's 2-state model ([Zhong]).

State ``x = [x1, x2]`` (position, rate), ``Phi = [[1, T], [0, 1]]``, ``G = [0, 1]^T``,
``C = [1, 0]``, process noise ``G Q G^T``, measurement noise ``R``, ``u = 0``.

Three forms, which agree to rounding error (tests pin this):

* :func:`kalman_matrix`: the five matrix equations of the paper (its eqs. 1-5).
* :func:`kalman_decomposed`: the scalar decomposition of the paper's section 4.3.1 with its two
  misprints corrected (``pl21`` and ``K2``, see docs/filters/kalman2.md), vectorised along a batch axis.
* :func:`steady_state`: the same filter with the constant gain ``K_inf`` of the discrete
  Riccati equation, i.e. an alpha-beta filter with ``alpha = K1``, ``beta = T*K2``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from kfpga.core.params import check_measured_start, matrix, number, vector
from kfpga.model.start import check_init, measured_start_float

__all__ = [
    "KalmanParams",
    "kalman_matrix",
    "kalman_decomposed",
    "steady_state_gain",
    "steady_state",
]


def _default_p0():
    return ((10.0, 0.0), (0.0, 10.0))


@dataclass(frozen=True, kw_only=True)
class KalmanParams:
    """Model parameters (defaults: the paper's T=1, Q=2, R=4, P0=10*I, x0=0), validated.

    Parameters
    ----------
    T:
        Sample period (> 0); with ``T = 1`` the rate ``x2`` is in units per sample.
    Q:
        Process noise variance on the rate (>= 0), entering as ``G Q G^T``.
    R:
        Measurement noise variance (> 0).
    P0:
        Initial error covariance, 2x2 symmetric positive definite.
    x0:
        Initial state estimate ``(x1, x2)``.
    init:
        ``"state"``: start from ``x0``; ``"measurement"``: x1 from the first sample, x2 from the
        first two (``model/start.py``).

    Raises ``TypeError`` for a value of the wrong type and ``ValueError`` for a wrong value,
    the message starting with the field's name.
    """

    T: float = 1.0
    Q: float = 2.0
    R: float = 4.0
    P0: tuple = field(default_factory=_default_p0)
    x0: tuple = (0.0, 0.0)
    init: str = "state"

    def __post_init__(self):
        s = object.__setattr__
        s(self, "init", check_init(self.init))
        s(self, "T", number("T", self.T, minimum=0.0, strict=True))
        s(self, "Q", number("Q", self.Q, minimum=0.0))
        s(self, "R", number("R", self.R, minimum=0.0, strict=True))
        s(self, "P0", matrix("P0", self.P0, 2, 2, symmetric=True, positive_definite=True))
        s(self, "x0", vector("x0", self.x0, 2))
        check_measured_start(self.x0, ((1.0, 0.0),))

    @property
    def phi(self):
        return np.array([[1.0, self.T], [0.0, 1.0]])

    @property
    def gqg(self):
        return np.array([[0.0, 0.0], [0.0, self.Q]])

    def scaled(self):
        """The same filter in the units of the datapath: ``v = T*x2`` and ``P' = D P D``.

        With ``D = diag(1, T)`` the model becomes ``Phi' = [[1, 1], [0, 1]]`` and
        ``Q' = T**2 * Q``: exactly the decomposition with ``T = 1``. The hardware and the
        bit-accurate model run in these units, so no product by T sits inside the loop.
        """
        t = self.T
        p0 = np.array(self.P0)
        d = np.diag([1.0, t])
        return replace(
            self,
            T=1.0,
            Q=self.Q * t * t,
            P0=tuple(map(tuple, d @ p0 @ d)),
            x0=(self.x0[0], self.x0[1] * t),
        )


def kalman_matrix(y, params=KalmanParams()):
    """Run the matrix-form Kalman filter on a 1-D sequence ``y``.

    Returns a dict of arrays: ``x`` (n, 2) filtered states, ``yhat`` (n,) one-step output
    predictions ``C x_{k|k-1}``, ``K`` (n, 2) gains, ``P`` (n, 2, 2) filtered covariances.
    """
    y = np.asarray(y, dtype=np.float64)
    phi, gqg = params.phi, params.gqg
    c = np.array([[1.0, 0.0]])
    x = np.array(params.x0, dtype=np.float64)
    p = np.array(params.P0, dtype=np.float64)
    n = len(y)
    xs, yh, ks, ps = np.empty((n, 2)), np.empty(n), np.empty((n, 2)), np.empty((n, 2, 2))
    eye = np.eye(2)
    for k, yk in enumerate(y):
        # (1) x_{k|k-1} = Phi x_{k-1}
        x_pred = phi @ x
        # (2) P_{k|k-1} = Phi P_{k-1} Phi^T + G Q G^T
        p_pred = phi @ p @ phi.T + gqg
        # (3) K_k = P_{k|k-1} C^T (C P_{k|k-1} C^T + R)^-1
        gain = p_pred @ c.T @ np.linalg.inv(c @ p_pred @ c.T + params.R)
        # (4) x_k = x_{k|k-1} + K_k (y_k - C x_{k|k-1})
        x_prev, x = x, x_pred + (gain @ (yk - c @ x_pred)).ravel()
        x = np.array(measured_start_float(params, k, yk, *x_prev, *x))  # init = "measurement"
        # (5) P_k = (I - K_k C) P_{k|k-1}
        p = (eye - gain @ c) @ p_pred
        xs[k], yh[k], ks[k], ps[k] = x, x_pred[0], gain.ravel(), p
    return {"x": xs, "yhat": yh, "K": ks, "P": ps}


def kalman_decomposed(y, params=KalmanParams()):
    """Run the decomposed (scalar) Kalman filter, vectorised along leading batch axes.

    ``y`` has shape ``(..., n)``; every channel starts from ``params.x0`` and ``params.P0``.
    Returns a dict with ``x1``, ``x2``, ``yhat`` of the same shape as ``y``, the gains ``K``
    (``(..., n, 2)``) and the filtered covariances ``P`` (``(..., n, 2, 2)``).
    """
    y = np.asarray(y, dtype=np.float64)
    n = y.shape[-1]
    batch = y.shape[:-1]
    t, q, r = params.T, params.Q, params.R
    x1 = np.full(batch, params.x0[0])
    x2 = np.full(batch, params.x0[1])
    p11, p12, p21, p22 = (np.full(batch, v) for v in (*params.P0[0], *params.P0[1]))
    rec = {name: np.empty(y.shape) for name in ("xl1", "x1", "x2")}
    gains, covs = np.empty((*y.shape, 2)), np.empty((*y.shape, 2, 2))
    for k in range(n):
        yk = y[..., k]
        # time update
        xl1 = x1 + t * x2                                     # xl1 = x1 + T x2
        xl2 = x2                                              # xl2 = x2
        pl11 = p11 + t * (p12 + p21) + t * t * p22            # pl11 = p11 + T(p12 + p21) + T^2 p22
        pl12 = p12 + t * p22                                  # pl12 = p12 + T p22
        pl21 = p21 + t * p22                                  # pl21 = p21 + T p22  (paper: p22 + T p22)
        pl22 = p22 + q                                        # pl22 = p22 + Q
        # gain
        s = pl11 + r                                          # S = pl11 + R
        k1 = pl11 / s                                         # K1 = pl11 / S
        k2 = pl21 / s                                         # K2 = pl21 / S  (paper: pl11 / (pl21 + 4))
        # measurement update
        e = yk - xl1                                          # innovation; yhat = xl1
        x1_prev, x1 = x1, xl1 + k1 * e                        # x1 = xl1 + K1 e
        x2 = xl2 + k2 * e                                     # x2 = xl2 + K2 e
        x1, x2 = measured_start_float(params, k, yk, x1_prev, xl2, x1, x2)  # init = "measurement"
        p11, p12 = pl11 - k1 * pl11, pl12 - k1 * pl12         # p1j = pl1j - K1 pl1j
        p21, p22 = pl21 - k2 * pl11, pl22 - k2 * pl12         # p2j = pl2j - K2 pl1j
        rec["xl1"][..., k], rec["x1"][..., k], rec["x2"][..., k] = xl1, x1, x2
        gains[..., k, 0], gains[..., k, 1] = k1, k2
        covs[..., k, 0, 0], covs[..., k, 0, 1], covs[..., k, 1, 0], covs[..., k, 1, 1] = p11, p12, p21, p22
    return {"x1": rec["x1"], "x2": rec["x2"], "yhat": rec["xl1"], "K": gains, "P": covs}


def steady_state_gain(T=1.0, Q=2.0, R=4.0):
    """Steady-state gain ``K_inf`` and predicted covariance of the discrete Riccati equation.

    Solves ``P = Phi P Phi^T - Phi P C^T (C P C^T + R)^-1 C P Phi^T + G Q G^T`` (the
    prediction covariance) with the structure-preserving doubling algorithm, which converges
    quadratically even when the filter's poles are near 1 (small Q/R), where plain iteration
    of the recursion needs thousands of steps. Returns ``(K, P_pred)``.
    """
    if not T > 0:
        raise ValueError(f"T must be > 0, not {T!r}")
    if not Q > 0:
        raise ValueError(f"Q must be > 0 for a steady-state gain (Q = 0 gives K_inf = 0), not {Q!r}")
    if not R > 0:
        raise ValueError(f"R must be > 0, not {R!r}")
    phi = np.array([[1.0, T], [0.0, 1.0]])
    c = np.array([[1.0, 0.0]])
    # Dual (control-form) data: A = Phi^T, G = C^T R^-1 C, H = G Q G^T.
    a = phi.T.copy()
    g = c.T @ c / R
    h = np.array([[0.0, 0.0], [0.0, Q]])
    eye = np.eye(2)
    for _ in range(200):
        w = np.linalg.inv(eye + g @ h)
        a_next = a @ w @ a
        g_next = g + a @ w @ g @ a.T
        h_next = h + a.T @ h @ w @ a
        done = np.max(np.abs(h_next - h)) <= 1e-15 * np.max(np.abs(h_next))
        a, g, h = a_next, g_next, h_next
        if done:
            break
    else:  # pragma: no cover - the doubling converges in a few dozen steps for valid inputs
        raise ArithmeticError("Riccati doubling did not converge")
    p_pred = (h + h.T) / 2
    k = (p_pred @ c.T / (c @ p_pred @ c.T + R)).ravel()
    return k, p_pred


def steady_state(y, params=KalmanParams(), gain=None):
    """Run the constant-gain (steady-state) filter along the last axis of ``y``.

    ``x1 = xl1 + K1 e``, ``x2 = x2 + K2 e`` with ``xl1 = x1 + T x2`` and ``e = y - xl1``.
    """
    if gain is None:
        gain, _ = steady_state_gain(params.T, params.Q, params.R)
    k1, k2 = gain
    y = np.asarray(y, dtype=np.float64)
    batch = y.shape[:-1]
    x1 = np.full(batch, params.x0[0])
    x2 = np.full(batch, params.x0[1])
    out = {name: np.empty(y.shape) for name in ("x1", "x2", "yhat", "e")}
    for k in range(y.shape[-1]):
        xl1 = x1 + params.T * x2
        e = y[..., k] - xl1
        x1, x2 = measured_start_float(params, k, y[..., k], x1, x2, xl1 + k1 * e, x2 + k2 * e)  # init = "measurement"
        out["x1"][..., k], out["x2"][..., k], out["yhat"][..., k], out["e"][..., k] = x1, x2, xl1, e
    return out


def steady_error_std(F, GQG, H, R, K):
    """Standard deviation of each state's and each prediction's error in steady state, for the
    gain ``K`` (any stabilising gain, the Kalman gain or a fixed one).

    The corrected error obeys ``e+ = (I - K H) F e + (I - K H) G w - K v``, so its covariance P
    solves the Lyapunov equation ``P = A P A^T + (I - K H) G Q G^T (I - K H)^T + K R K^T`` with
    ``A = (I - K H) F``; the prediction ``H F x`` has error covariance ``H (F P F^T + G Q G^T) H^T``.
    Returns ``(state std, prediction std)``.
    """
    from scipy.linalg import solve_discrete_lyapunov

    F, GQG, H, R, K = (np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in (F, GQG, H, R, K))
    n = F.shape[0]
    ikh = np.eye(n) - K @ H
    p = solve_discrete_lyapunov(ikh @ F, ikh @ GQG @ ikh.T + K @ R @ K.T)
    pred = H @ (F @ p @ F.T + GQG) @ H.T
    return np.sqrt(np.clip(np.diag(p), 0, None)), np.sqrt(np.clip(np.diag(pred), 0, None))

