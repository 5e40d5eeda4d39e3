"""The least-squares front end of [Fukuda]: the running sums against numpy's fit on every
window, the window table, the m = 1 start, the evaluation, and the bit-accurate front end
against its float form (its core: tests/test_hw_lsfront.py)."""

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
    assert main(["evaluate", "lsfront", "--seed", str(seed), "--json", "--plot", str(plot)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert plot.stat().st_size > 10000
    rows = {r["filter"]: r for r in result["rows"]}
    fed, vonly = rows["LS-fed Kalman (the patent, x0)"], rows["Kalman, velocity only (x2)"]
    equal = rows["Kalman, velocity only, equal suppression"]
    mean = rows["moving average (10 samples)"]
    raw = rows["speed log (raw)"]
    assert max(fed["rmse_cruise"], vonly["rmse_cruise"]) < raw["rmse_cruise"]
    assert abs(fed["lag_s"]) < mean["lag_s"]  # a smaller lag than the moving average's (every seed of 20)
    # the baseline at equal noise suppression: its q found by bisection matches x0's RMSE at constant speed
    assert equal["rmse_cruise"] == pytest.approx(fed["rmse_cruise"], rel=1e-3)
    assert sum(result["windows"].values()) == result["scenario"]["seconds"] and len(result["claims"]) == 6


def _fixed(params=None, **formats):
    from kfpga.core.config import FilterConfig

    return FilterConfig(filter="lsfront", params=params or ls.LSFrontParams(), formats=formats)


def _speed_log(rng, n, params):
    """A ship's speed (m/s) in codes, with manoeuvres and the log's noise."""
    accel = np.repeat(rng.normal(0, 0.03, n // 50 + 1), 50)[:n]
    v = 5.0 + np.cumsum(accel) * params.T + rng.normal(0, np.sqrt(params.r), n)
    return np.clip(np.round(v / params.lsb), -32768, 32767).astype(np.int64)


def test_running_sums_are_the_windows_exact_sums(seed):
    """The state's S0 and S1 of every window after each sample: the sums over the last n codes
    (zeros before the first), computed here directly."""
    from kfpga.core.fixedmodel import FixedModel

    rng = np.random.default_rng(seed)
    config = _fixed()
    codes = rng.integers(-32768, 32768, 80)
    codes[40:50] = 32767  # the extremes, where a narrow sum would wrap
    codes[60:70] = -32768
    model, state = FixedModel(config), None
    padded = np.r_[np.zeros(64, dtype=np.int64), codes]
    for i, code in enumerate(codes):
        state = model.run(np.array([code]), state=state).state
        for n in config.params.windows:
            window = padded[64 + i + 1 - n:64 + i + 1].astype(object)
            assert int(state.values[f"s0_{n}"]) == sum(window)
            assert int(state.values[f"s1_{n}"]) == sum(k * v for k, v in enumerate(window))


def test_fit_is_polyfit_within_its_roundings(seed):
    """The observations of a full window in the model's integers (the stage function ``fit`` on
    :class:`~kfpga.core.ops.IntOps`): numpy's least-squares line at the newest sample and its slope,
    within the rounding of the points b and fv and of the constants 2^s/D and 2^t/n."""
    from kfpga.core.ops import IntOps

    rng = np.random.default_rng(seed)
    params = ls.LSFrontParams()
    config = _fixed(params)
    codes = _speed_log(rng, 200, params)
    codes[100:130] = rng.integers(-32768, 32768, 30)  # any codes, the extremes of the fit
    for n in params.windows:
        for end in range(n, len(codes), 7):
            window = [int(c) for c in codes[end - n:end]]
            ops = IntOps(config.formats)
            k = ops.constants(config.constants("steady"))
            f0, f1 = ls.sum_formats(max(params.windows))
            # the window in use holds its sums; the others (not read) anything
            sums = {m: (ops.input(sum(window), f0), ops.input(sum(i * v for i, v in enumerate(window)), f1))
                    if m == n else (ops.input(0, f0), ops.input(0, f1)) for m in params.windows}
            ns = ops.input(n, ls.count_format(params))
            fv, b = ls.fit(ops, k, sums, ns, False, ops.input(window[-1], "fv"))
            slope, intercept = np.polyfit(np.arange(n), np.array(window, dtype=float), 1)
            lsb_b, lsb_fv = config.formats["b"].lsb, config.formats["fv"].lsb
            assert not any(flag for _, flag in ops.flags)
            assert abs(b.raw * lsb_b - slope) <= lsb_b / 2 + abs(slope) * 2.0 ** -17 + 1e-9
            end_value = intercept + (n - 1) * slope
            assert abs(fv.raw * lsb_fv - end_value) <= (lsb_fv / 2 + (n - 1) / 2 * (lsb_b / 2 + abs(slope) * 2.0 ** -17)
                                                        + abs(sum(window)) / n * 2.0 ** -17 + 1e-9)


def test_mode_gains_are_scipys_riccati_solution():
    """Each mode's steady-state gain against scipy's solver of the same discrete Riccati equation."""
    from scipy.linalg import solve_discrete_are

    params = ls.LSFrontParams()
    gains = ls.mode_gains(params)
    for mode, gain in gains.items():
        f, gqg, h, r = ls.code_model(params, 1 if mode == 0 else 2, mode or None)
        p = solve_discrete_are(f.T, h.T, gqg, r)
        k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
        np.testing.assert_allclose(gain[:, :k.shape[1]], k, rtol=1e-7, atol=1e-12)
    assert not gains[0][:, 1].any()  # m = 1: the slope column unused


def test_switched_filter_settles_onto_the_time_varying_one(seed):
    """With one window, once the time-varying filter's gain has settled, the switched steady-state
    filter (the fixed-point form's float reference) gives its estimates: the two are the same
    filter past the start (the codes' rounding of the speed aside)."""
    rng = np.random.default_rng(seed)
    params = ls.LSFrontParams(table=((math.inf, 10),))
    codes = _speed_log(rng, 3000, params)
    ref = ls.switched(codes, params)
    tv = ls.lsfront(codes * params.lsb, params)
    assert (ref["ns"][9:] == 10).all() and (ref["ns"][:9] == 0).all()
    assert np.max(np.abs(ref["velocity"][2000:] * params.lsb - tv["velocity"][2000:])) < 2e-4


def test_bit_accurate_front_end_follows_its_float_form(seed):
    """The model's integers against the switched filter in float: the same window nearly
    everywhere, no overflow on a ship's speeds, and far within the speed log's noise except
    after the two choose different windows (an innovation at a threshold): the filters then
    differ by what the windows differ (up to about 120 codes on 13 seeds), which fades out within
    60 samples (2 codes at most after that, on the same seeds)."""
    from kfpga.core.fixedmodel import FixedModel

    rng = np.random.default_rng(seed)
    config = _fixed()
    params = config.params
    codes = _speed_log(rng, 4000, params)
    run = FixedModel(config).run(codes)
    ref = ls.switched(codes, params)
    velocity = run.outputs["velocity"] * config.formats["x1"].lsb
    assert not run.overflow.any()
    same = run.outputs["ns"] == ref["ns"]
    assert np.mean(same) > 0.99
    apart = np.abs(velocity - ref["velocity"])  # codes (mm/s), against a noise of 100
    last_choice_apart = np.maximum.accumulate(np.where(same, -(10 ** 9), np.arange(len(same))))
    settled = np.arange(len(same)) - last_choice_apart > 60
    assert settled.mean() > 0.5 and np.max(apart[settled]) < 5.0
    assert np.median(apart) < 1.0


def test_window_longer_than_the_limit_is_refused():
    with pytest.raises(ValueError, match=f"Ns must be at most {ls.MAX_WINDOW}"):
        ls.LSFrontParams(table=((math.inf, ls.MAX_WINDOW + 1),))
