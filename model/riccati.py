"""The discrete Riccati equation of a linear state-space model: its stabilising solution and gain.

Shared by the filters whose gains come from it (the general model, the least-squares front
end's modes). Models::

    x(k+1) = F x(k) + G w(k), cov(G w) = GQG        y(k) = H x(k) + v(k), cov(v) = R
"""

from __future__ import annotations

import math

import numpy as np

from kfpga.core.formats import PRECISION

__all__ = ["PBHError", "check_pbh", "dare", "loop_frac_bits"]


class PBHError(ValueError):
    """The steady-state gain does not exist: a mode is not detectable or not stabilisable."""


def check_pbh(f, gqg, h):
    """Raise :class:`PBHError` when a mode of F on or outside the unit circle is not seen by H or
    not driven by the process noise (the PBH tests): then no stabilising solution exists."""
    f, gqg, h = np.asarray(f, dtype=float), np.asarray(gqg, dtype=float), np.asarray(h, dtype=float)
    n = len(f)
    w, v = np.linalg.eigh(gqg)
    root = v @ np.diag(np.sqrt(np.clip(w, 0, None)))  # G Q^1/2 (up to an orthogonal factor)
    for lam in np.linalg.eigvals(f):
        if abs(lam) < 1 - 1e-9:
            continue
        a = lam * np.eye(n) - f
        if np.linalg.matrix_rank(np.vstack([a, h]), tol=1e-9) < n:
            raise PBHError(f"(F, H) is not detectable: F's mode of eigenvalue {lam:.4g} is not stable and H does not "
                           "see it, so the steady-state gain does not exist (observe that state, or use the full variant)")
        if np.linalg.matrix_rank(np.hstack([a, root]), tol=1e-9) < n:
            raise PBHError(f"(F, G Q^1/2) is not stabilisable: F's mode of eigenvalue {lam:.4g} is not stable and no "
                           "process noise reaches it, so the Riccati equation has no stabilising solution (add noise "
                           "to that state, or use the full variant)")


def dare(f, gqg, h, r):
    """The steady-state gain K (n x m) and predicted covariance of the discrete Riccati equation.

    Solves ``P = F P F^T - F P H^T (H P H^T + R)^-1 H P F^T + G Q G^T`` by the structure-preserving
    doubling algorithm (quadratic convergence even with poles near 1); ``K = P H^T (H P H^T + R)^-1``.
    Raises :class:`PBHError` when no stabilising solution exists.
    """
    check_pbh(f, gqg, h)
    f, gqg, h, r = (np.asarray(a, dtype=float) for a in (f, gqg, h, r))
    n = len(f)
    a = f.T.copy()
    g = h.T @ np.linalg.inv(r) @ h
    q = gqg.copy()
    eye = np.eye(n)
    for _ in range(200):
        w = np.linalg.inv(eye + g @ q)
        a_next = a @ w @ a
        g_next = g + a @ w @ g @ a.T
        q_next = q + a.T @ q @ w @ a
        done = np.max(np.abs(q_next - q)) <= 1e-15 * max(np.max(np.abs(q_next)), 1e-300)
        a, g, q = a_next, g_next, q_next
        if done:
            break
    else:  # pragma: no cover - converges in a few dozen steps once PBH holds
        raise ArithmeticError("Riccati doubling did not converge")
    p = (q + q.T) / 2
    k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
    return k, p


def _injected(a, v, steps=60):
    """``sum_k A^k v v^T A^kT``: the steady covariance of a unit injection ``v`` each update into the
    error loop ``A`` (doubling: 2**steps updates)."""
    s, m = np.outer(v, v), a.copy()
    for _ in range(steps):
        s_next = s + m @ s @ m.T
        if np.allclose(s_next, s, rtol=1e-12, atol=0):
            break
        s, m = s_next, m @ m
    return s


def loop_frac_bits(f, h, gain, floors):
    """Fraction bits of each state for the rounding the loop feeds back, or ``None`` per state
    when the loop ``A = (I - K H) F`` is not stable.

    A state's rounding, each update, is carried by the steady error loop ``A`` (slowly forgotten
    when the gains are small), so it adds the steady covariance of that injection to every
    state. Each state gets the fraction bits that keep its share of every state's added error
    within a quarter of the budget (:data:`~kfpga.core.formats.PRECISION`) of the float filter's
    error floor there (``floors``, one per state). The state is written after the correction, and
    its prediction (the same format) before it: both injections count.
    """
    f, h, gain = np.asarray(f, dtype=float), np.asarray(h, dtype=float), np.asarray(gain, dtype=float)
    n = f.shape[0]
    a = (np.eye(n) - gain @ h) @ f
    if np.max(np.abs(np.linalg.eigvals(a))) >= 1.0:
        return [None] * n
    share = math.sqrt((1.0 + PRECISION / 4) ** 2 - 1.0) / math.sqrt(n)
    out = []
    for i in range(n):
        v = np.zeros(n)
        v[i] = 1.0
        gain_sq = np.diag(_injected(a, v)) + np.diag(_injected(a, (np.eye(n) - gain @ h) @ v))
        lsbs = [share * floors[j] * math.sqrt(12.0 / gain_sq[j]) for j in range(n) if gain_sq[j] > 0 and floors[j] > 0]
        out.append(math.ceil(-math.log2(min(lsbs))) if lsbs else None)
    return out
