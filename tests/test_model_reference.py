"""Float reference: decomposed == matrix form == filterpy; steady-state gain vs scipy's DARE."""

import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter

from kfpga.model.reference import (
    KalmanParams,
    kalman_decomposed,
    kalman_matrix,
    steady_state,
    steady_state_gain,
)


def random_params(rng):
    a = rng.normal(size=(2, 2))
    p0 = a @ a.T + rng.uniform(0.1, 5.0) * np.eye(2)
    return KalmanParams(
        T=float(rng.choice([rng.uniform(0.01, 4.0), 0.5, 1.0, 2.0])),
        Q=float(rng.uniform(0.0, 10.0)),
        R=float(rng.uniform(0.05, 50.0)),
        P0=tuple(map(tuple, (p0 + p0.T) / 2)),
        x0=tuple(rng.normal(0, 10, 2)),
    )


def random_signal(rng, n):
    return np.cumsum(np.cumsum(rng.normal(0, 0.5, n))) + rng.normal(0, 3, n)


def filterpy_run(y, params):
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F = params.phi
    kf.H = np.array([[1.0, 0.0]])
    kf.Q = params.gqg
    kf.R = np.array([[params.R]])
    kf.P = np.array(params.P0)
    kf.x = np.array(params.x0).reshape(2, 1)
    xs, gains = [], []
    for yk in y:
        kf.predict()
        kf.update(yk)
        xs.append(kf.x.ravel().copy())
        gains.append(kf.K.ravel().copy())
    return np.array(xs), np.array(gains)


def test_decomposed_equals_matrix_form_on_random_models(seed):
    rng = np.random.default_rng(seed)
    for _ in range(25):
        params = random_params(rng)
        y = random_signal(rng, 300)
        m = kalman_matrix(y, params)
        d = kalman_decomposed(y, params)
        scale = np.max(np.abs(m["x"])) + 1.0
        np.testing.assert_allclose(d["x1"], m["x"][:, 0], rtol=1e-12, atol=1e-12 * scale)
        np.testing.assert_allclose(d["x2"], m["x"][:, 1], rtol=1e-12, atol=1e-12 * scale)
        np.testing.assert_allclose(d["yhat"], m["yhat"], rtol=1e-12, atol=1e-12 * scale)
        np.testing.assert_allclose(d["K"], m["K"], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(d["P"], m["P"], rtol=1e-10, atol=1e-12 * np.max(np.abs(m["P"])))


def test_both_forms_equal_filterpy(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        params = random_params(rng)
        y = random_signal(rng, 200)
        xs, gains = filterpy_run(y, params)
        m = kalman_matrix(y, params)
        d = kalman_decomposed(y, params)
        scale = np.max(np.abs(xs)) + 1.0
        np.testing.assert_allclose(m["x"], xs, rtol=1e-10, atol=1e-10 * scale)
        np.testing.assert_allclose(m["K"], gains, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(d["x1"], xs[:, 0], rtol=1e-10, atol=1e-10 * scale)
        np.testing.assert_allclose(d["x2"], xs[:, 1], rtol=1e-10, atol=1e-10 * scale)


def test_paper_misprints_are_corrected():
    """The paper's printed pl21 = p22 + T p22 and K2 = pl11/(pl21 + 4) give a different filter."""
    params = KalmanParams(P0=((10.0, 3.0), (3.0, 10.0)))
    y = np.linspace(0, 50, 20)
    m = kalman_matrix(y, params)
    # printed version, first step only
    p11, p12, p21, p22 = 10.0, 3.0, 3.0, 10.0
    pl11 = p11 + p12 + p21 + p22
    pl21_printed = p22 + p22
    k2_printed = pl11 / (pl21_printed + 4.0)
    assert not np.isclose(k2_printed, m["K"][0, 1])
    # corrected version matches the matrix form
    pl21 = p21 + p22
    assert np.isclose(pl21 / (pl11 + 4.0), m["K"][0, 1], rtol=1e-14)


def test_batch_axis_runs_independent_channels(seed):
    rng = np.random.default_rng(seed)
    y = rng.normal(0, 5, (3, 4, 100))
    d = kalman_decomposed(y, KalmanParams())
    single = kalman_decomposed(y[2, 1], KalmanParams())
    np.testing.assert_array_equal(d["x1"][2, 1], single["x1"])


def test_steady_state_gain_paper_values():
    k, _ = steady_state_gain(1.0, 2.0, 4.0)
    np.testing.assert_allclose(k, [0.7051, 0.3840], atol=5e-5)


def test_steady_state_gain_matches_scipy_dare(seed):
    rng = np.random.default_rng(seed)
    for _ in range(30):
        t = float(rng.uniform(0.01, 5.0))
        q = float(10 ** rng.uniform(-6, 3))
        r = float(10 ** rng.uniform(-3, 3))
        k, p = steady_state_gain(t, q, r)
        phi = np.array([[1.0, t], [0.0, 1.0]])
        c = np.array([[1.0, 0.0]])
        ps = scipy.linalg.solve_discrete_are(phi.T, c.T, np.diag([0.0, q]), np.array([[r]]))
        ks = (ps @ c.T / (c @ ps @ c.T + r)).ravel()
        np.testing.assert_allclose(p, ps, rtol=1e-8, atol=1e-12 * np.max(np.abs(ps)))
        np.testing.assert_allclose(k, ks, rtol=1e-8)


def test_time_varying_gain_converges_to_steady_state():
    params = KalmanParams()
    m = kalman_matrix(np.zeros(200), params)
    k, _ = steady_state_gain(params.T, params.Q, params.R)
    np.testing.assert_allclose(m["K"][-1], k, rtol=1e-12)


def test_steady_state_filter_is_alpha_beta(seed):
    rng = np.random.default_rng(seed)
    y = random_signal(rng, 500)
    params = KalmanParams(T=0.5)
    (k1, k2), _ = steady_state_gain(params.T, params.Q, params.R)
    out = steady_state(y, params)
    # alpha-beta: xp = x + T v; x = xp + alpha r; v = v + (beta / T) r, alpha = K1, beta = T K2
    alpha, beta = k1, params.T * k2
    x, v = 0.0, 0.0
    for n, z in enumerate(y):
        xp = x + params.T * v
        x, v = xp + alpha * (z - xp), v + beta / params.T * (z - xp)
        assert out["x1"][n] == pytest.approx(x, rel=1e-12, abs=1e-9)


def test_scaled_units_are_the_same_filter(seed):
    """Datapath units v = T*x2, P' = D P D give x2 = v / T exactly (up to rounding)."""
    rng = np.random.default_rng(seed)
    for _ in range(10):
        params = random_params(rng)
        y = random_signal(rng, 200)
        a = kalman_decomposed(y, params)
        b = kalman_decomposed(y, params.scaled())
        scale = np.max(np.abs(a["x1"])) + 1.0
        np.testing.assert_allclose(b["x1"], a["x1"], rtol=1e-10, atol=1e-10 * scale)
        np.testing.assert_allclose(b["x2"] / params.T, a["x2"], rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"T": 0.0}, "T must be > 0"),
    ({"Q": 0.0}, "Q must be > 0"),
    ({"R": -1.0}, "R must be > 0"),
])
def test_steady_state_gain_rejects_bad_parameters(kwargs, message):
    args = {"T": 1.0, "Q": 2.0, "R": 4.0, **kwargs}
    with pytest.raises(ValueError, match=message):
        steady_state_gain(**args)
