"""The ship-roll interval predictor of [Zhang]: in float, its forms against each other and
against an independent Kalman filter, the paper's data, the evaluation and its bad input; in
fixed point, against float and its word lengths (its core: tests/test_hw_roll.py)."""

import json

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.model import roll


def test_table1_is_the_papers():
    t, z = roll.table1()
    assert len(z) == 32 and t[0] == 0.5 and t[-1] == 16.0 and np.allclose(np.diff(t), 0.5)
    # spot values read off the paper's table 1, one per printed column
    assert (z[0], z[8], z[16], z[24], z[31]) == (-1.17, -0.05, -1.26, -0.65, 0.07)


def test_square_root_form_equals_the_plain_one_in_float(seed):
    """Potter's update (the paper's eqs. 19-20) and the Cholesky time update carry the same
    covariance as the plain Joseph-free form: the same predictions to rounding."""
    _, y, _ = roll.synthetic_roll(300, seed)
    for s in (1.0, 100.0):
        params = roll.RollParams(s=s)
        plain = roll.predict(y, params, sqrt=False)
        root = roll.predict(y, params, sqrt=True)
        np.testing.assert_allclose(root, plain, rtol=0, atol=1e-9, equal_nan=True)


def test_each_filter_is_a_kalman_filter_on_its_own_samples(seed):
    """The improved form without fading, on one parity, against filterpy-free textbook code:
    x- = A x, P- = A P A' + Q, with the state of each step written out here."""
    _, y, _ = roll.synthetic_roll(100, seed)
    pred = roll.predict(y, roll.RollParams(s=1.0), sqrt=False)
    z = y[0::2]
    a = roll.transition(1.0)
    x = a @ np.array([z[2], z[2] - z[1], z[2] - 2 * z[1] + z[0]])
    p = a @ np.array(roll.PAPER_P0) @ a.T + np.eye(3)
    for k in range(3, len(z)):
        s = p[0, 0] + 0.01
        kg = p[:, 0] / s
        x = x + kg * (z[k] - x[0])
        p = p - np.outer(kg, p[0, :])
        x, p = a @ x, a @ p @ a.T + np.eye(3)
        assert pred[2 * k] == pytest.approx(x[0], abs=1e-9)


def test_prediction_is_two_samples_ahead():
    """On a noise-free parabola the constant-acceleration model is exact: the improved form's
    prediction made at n equals the sample n + 2; the basic form's lags by a step."""
    t = np.arange(60) * 0.5
    z = 0.3 + 0.2 * t - 0.01 * t ** 2
    imp = roll.predict(z, roll.RollParams(R=1e-9, s=1.0))
    assert np.nanmax(np.abs(imp[30:-2] - z[32:])) < 1e-6
    basic = roll.predict(z, roll.RollParams(R=1e-9), improved=False)
    assert np.nanmax(np.abs(basic[30:] - z[30:])) < 1e-5  # the basic form "predicts" the sample it has


def test_the_papers_singular_p0_starts_every_form():
    """The square root is first taken of A P0 A' + Q (positive definite), so the paper's rank-1
    P0 starts the square-root form too, and it equals the plain form."""
    assert np.linalg.matrix_rank(np.array(roll.PAPER_P0)) == 1 and roll.RollParams().P0 == roll.PAPER_P0
    _, y, _ = roll.synthetic_roll(60, 1)
    params = roll.RollParams()
    assert np.isfinite(roll.predict(y, params, improved=False)[10])
    np.testing.assert_allclose(roll.predict(y, params, sqrt=True), roll.predict(y, params, sqrt=False), atol=1e-9,
                               equal_nan=True)


@pytest.mark.parametrize(("kwargs", "match"), [({"s": 0.0}, "s must be > 0"), ({"R": -1.0}, "R must be > 0"),
                                               ({"T": 0.0}, "T must be > 0"), ({"q": "1"}, "q must be a number"),
                                               ({"P0": ((1, 2, 0), (0, 1, 0), (0, 0, 1))}, "P0 must be symmetric"),
                                               ({"P0": ((-1, 0, 0), (0, 1, 0), (0, 0, 1))}, "positive semi-definite")])
def test_bad_parameters(kwargs, match):
    with pytest.raises((TypeError, ValueError), match=match):
        roll.RollParams(**kwargs)


def test_short_or_bad_series():
    with pytest.raises(ValueError, match="at least 8 samples"):
        roll.predict(np.zeros(7))
    with pytest.raises(ValueError, match="finite"):
        roll.predict(np.array([0.0] * 9 + [np.nan]))
    with pytest.raises(ValueError, match="options of the improved form"):
        roll.predict(np.zeros(10), improved=False, sqrt=False)


def test_evaluate_roll_cli(tmp_path, capsys, seed):
    plot = tmp_path / "roll.png"
    assert main(["evaluate", "roll", "--seed", str(seed), "--json", "--plot", str(plot)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert plot.stat().st_size > 10000
    rows = {(r["data"], r["form"]): r for r in result["rows"]}
    table = {form: r["rmse_deg"] for (data, form), r in rows.items() if data.startswith("table 1")}
    basic, improved = table["basic (predict, then update)"], table["improved: + square root (the paper's)"]
    assert improved < 0.2 < basic  # the paper's direction, and its requirement, on its own 32 samples
    assert len(result["sweep"]) == 20 and len(result["claims"]) == 9
    # fixed point and float on the same ADC codes, from the same start, over the same predictions
    for r in result["fixed"]:
        assert r["predictions"] == (26 if r["data"].startswith("table 1") else 474)
        assert r["max_from_float_deg"] < 0.001


def test_evaluate_roll_cli_errors(tmp_path, capsys):
    bad = tmp_path / "r.csv"
    bad.write_text("roll\n1\n2\nx\n")
    for argv, message in ((["--input", str(bad)], "line 4: roll = 'x' is not a number"),
                          (["--samples", "5"], "--samples must be at least 8"),
                          (["--fading", "-1"], "--fading/--q/--r/--p0: s must be > 0"),
                          (["--input", str(bad), "--seed", "1"], "--seed does not apply here"),
                          (["--input", str(bad), "--seeds", "3"], "--seeds does not apply here"),
                          (["--input", str(bad), "--noise", "0.1"], "--noise does not apply with --input"),
                          (["--p0", "x"], "--p0 must be a number (every entry) or diag:V, not 'x'"),
                          (["--q", "0"], "--fading/--q/--r/--p0: q must be > 0")):
        assert main(["evaluate", "roll", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
    short = tmp_path / "s.csv"
    short.write_text("# a comment\nroll\n1\n2\n3\n")
    assert main(["evaluate", "roll", "--input", str(short)]) == 2
    assert "3 samples; the interval predictor needs at least 8" in capsys.readouterr().err
    # without a header, the first line is a sample like the others (none is lost)
    short.write_text("1.5\n2\n3\n4\n")
    assert main(["evaluate", "roll", "--input", str(short)]) == 2
    assert "4 samples; the interval predictor needs at least 8" in capsys.readouterr().err


def test_read_series_header_is_optional(tmp_path):
    from kfpga.core.csvio import read_series

    path = tmp_path / "s.csv"
    path.write_text("# deg\nt,roll\n0,1.5\n0.5,-2\n")
    assert read_series(path).tolist() == [1.5, -2.0]
    path.write_text("0,1.5\n0.5,-2\n")
    assert read_series(path).tolist() == [1.5, -2.0]
    assert read_series(path, column="column 1").tolist() == [0.0, 0.5]


def _float_run(variant, z, params):
    """The variant's stage functions in float64 (FloatOps), one filter, from its reset state."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.ops import FloatOps

    config = FilterConfig(filter="roll", params=params)
    v = config.spec.model.variants[variant]
    x = dict(v.initial(params))
    out = []
    for code in z:
        ops = FloatOps(config.formats)
        k = ops.constants(v.constants(params))
        xs = {n: ops.input(x[n], p, n) for n, p in v.state_for(params)}
        nxt, o = v.update(ops, k, xs, {"z": ops.input(float(code), None, "z")})
        x = {n: float(nxt[n].raw) for n, _ in v.state_for(params)}
        out.append(float(o["pred"].raw))
    return np.array(out)


@pytest.mark.parametrize("variant", ["sqrt", "plain"])
def test_both_forms_are_the_kalman_filter_in_real_arithmetic(variant, seed):
    """The stage functions run in float (Potter's update and the Givens triangularisation, or the
    plain form) equal the plain matrix filter written independently (``roll.reference``)."""
    from kfpga.model.scenarios import adc_codes

    params = roll.RollParams(s=float(np.random.default_rng(seed).choice([1.0, 100.0])))
    _, y, _ = roll.synthetic_roll(120, seed)
    z = adc_codes(y[0::2] / params.lsb)
    np.testing.assert_allclose(_float_run(variant, z, params), roll.reference(params, variant, z)["pred"],
                               rtol=1e-9, atol=1e-6)


def test_fixed_point_predictor_is_close_to_float(seed):
    """At its default formats the square-root predictor in the core's integers stays within a
    thousandth of a degree of float (same start), with no overflow and its covariance positive
    definite after every update."""
    from kfpga.core.config import FilterConfig

    _, y, _ = roll.synthetic_roll(480, seed)
    pred, overflowed, not_pd = roll.predict_fixed(y, FilterConfig(filter="roll"), check=True)
    assert np.max(np.abs(pred - roll.predict_same_start(y))[:-2]) < 1e-3
    assert overflowed == 0 and not_pd == 0


def test_the_square_root_keeps_the_covariance_where_the_plain_form_loses_it():
    """With the 18-bit gains of one embedded multiplier the plain form's P stops being positive
    definite within its first updates; the square-root form keeps D nonsingular even with 12-bit
    operands and whole-code registers."""
    _, y, _ = roll.synthetic_roll(200, 3)
    rows = {(r["form"], r["operand_bits"]): r for r in roll.word_sweep(y, register_fracs=(0,), operand_bits=(12, 18))}
    assert rows[("sqrt", 12)]["not_positive_definite"] == 0 and rows[("sqrt", 18)]["not_positive_definite"] == 0
    assert rows[("plain", 18)]["not_positive_definite"] > 150


def test_positive_definiteness_checks():
    assert roll.covariance_ok("sqrt", {"d11": 3, "d22": 1, "d33": 2})
    assert not roll.covariance_ok("sqrt", {"d11": 3, "d22": 0, "d33": 2})
    identity = {"p11": 1, "p22": 1, "p33": 1, "p12": 0, "p13": 0, "p23": 0}
    assert roll.covariance_ok("plain", identity)
    assert not roll.covariance_ok("plain", {**identity, "p12": 2})  # eigenvalues 3, -1, 1
