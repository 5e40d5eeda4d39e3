"""The least-squares front end of seeds/003, in float: the running sums against numpy's fit on
every window, the window table, the m = 1 start, and the evaluation."""

import json
import math

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.model import lsfront as ls


@pytest.mark.parametrize("n", [3, 5, 12, 30])
def test_running_fit_equals_polyfit_on_every_window(n, seed):
    rng = np.random.default_rng(seed)
    v = np.cumsum(rng.normal(0, 0.3, 200)) + rng.normal(0, 0.1, 200)
    fit = ls.RunningFit(n)
    for i, value in enumerate(v):
        fit.push(value)
        if i + 1 < n:
            assert not fit.full
            continue
        window = v[i + 1 - n:i + 1]
        slope, intercept = np.polyfit(np.arange(n), window, 1)
        end, got_slope = fit.fit()
        assert got_slope == pytest.approx(slope, abs=1e-9) and end == pytest.approx(intercept + slope * (n - 1), abs=1e-9)


def test_fit_variances_are_the_lines(seed):
    """The end value's and the slope's variance, against a Monte Carlo of the fit itself."""
    rng = np.random.default_rng(seed)
    n, r = 10, 0.04
    noise = rng.normal(0, math.sqrt(r), (20000, n))
    slopes, intercepts = np.polyfit(np.arange(n), noise.T, 1)
    var_end, var_slope = ls.fit_variances(n, r, 1.0)
    assert np.var(intercepts + slopes * (n - 1)) == pytest.approx(var_end, rel=0.05)
    assert np.var(slopes) == pytest.approx(var_slope, rel=0.05)


def test_raw_velocity_until_the_window_fills_and_the_table_picks_ns():
    params = ls.LSFrontParams(table=((0.1, 8), (math.inf, 4)))
    v = np.r_[np.full(40, 2.0), np.full(40, 3.0)]  # a step: a large innovation
    out = ls.lsfront(v, params)
    assert (out["Ns"][:7] == 0).all() and np.isnan(out["fit_velocity"][:7]).all()
    assert out["Ns"][7] == 8  # the first window full: both observations
    assert 4 in set(out["Ns"][40:50].tolist())  # the step's innovation shortens the window
    assert out["velocity"][-1] == pytest.approx(3.0, abs=1e-3)


@pytest.mark.parametrize(("kwargs", "match"), [({"table": ((0.1, 2), (math.inf, 5))}, "Ns must be an integer >= 3"),
                                               ({"table": ((0.3, 5), (0.1, 8), (math.inf, 3))}, "must rise"),
                                               ({"table": ((0.3, 5),)}, "last threshold must be inf"),
                                               ({"table": ()}, "at least one"), ({"r": 0}, "r must be > 0"),
                                               ({"table": ((0.1, 5.0), (math.inf, 3))}, "Ns must be an integer")])
def test_bad_parameters(kwargs, match):
    with pytest.raises((TypeError, ValueError), match=match):
        ls.LSFrontParams(**kwargs)


def test_evaluate_ls_frontend_cli(tmp_path, capsys, seed):
    plot = tmp_path / "ls.png"
    assert main(["evaluate", "ls-frontend", "--seed", str(seed), "--json", "--plot", str(plot)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert plot.stat().st_size > 10000
    rows = {r["filter"]: r for r in result["rows"]}
    fed, vonly = rows["LS-fed Kalman (the patent)"], rows["Kalman, velocity only"]
    mean = rows["moving average (10 samples)"]
    raw = rows["speed log (raw)"]
    assert fed["rmse_cruise"] < vonly["rmse_cruise"] < raw["rmse_cruise"]  # the patent's noise suppression
    assert abs(fed["lag_s"]) < mean["lag_s"]  # and a smaller lag than the moving average's
    assert sum(result["windows"].values()) == result["scenario"]["seconds"] and len(result["findings"]) == 4
