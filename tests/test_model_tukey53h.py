# amaranth: UnusedElaboratable=no
"""The 53H smoother's model ([Lu]): against the method's own definition, the offline end
handling, the comparator networks, angles and wide inputs, the evaluation and the CLI (its core
and the board's pre-filter: tests/test_hw_tukey53h.py)."""

import itertools
import json

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.core.ops import CostOps, IntOps
from kfpga.model import tukey53h as th

CONFIG = FilterConfig(filter="tukey53h")


def definition(x, threshold):
    """53H from the paper's four steps, written out with Python's statistics.median on every
    window (nothing shared with the model): the decisions for x[4..n-5], each as an int."""
    import statistics

    n = len(x)
    x1 = {i: statistics.median(x[i - 2:i + 3]) for i in range(2, n - 2)}
    x2 = {i: statistics.median([x1[i - 1], x1[i], x1[i + 1]]) for i in range(3, n - 3)}
    out = {}
    for i in range(4, n - 4):
        x3 = int(np.floor((x2[i - 1] + 2 * x2[i] + x2[i + 1]) / 4 + 0.5))  # rounded to the nearest code, ties up
        out[i] = x3 if abs(x[i] - x3) > threshold else int(x[i])
    return out


def glitchy(rng, n, *, density=0.03):
    x = np.round(3000 * np.sin(np.arange(n) / 15.0) + rng.normal(0, 20, n)).astype(np.int64)
    hits = rng.random(n) < density
    x[hits] = rng.choice([CODE_MIN, CODE_MAX, -20000, 20000], hits.sum())
    return x


def test_model_equals_the_definition_in_the_interior(seed):
    rng = np.random.default_rng(seed)
    for threshold in (0.5, 40.0, 500.0, 7000.0):
        x = glitchy(rng, 400)
        y = FixedModel(FilterConfig(filter="tukey53h", params=th.Tukey53HParams(threshold=threshold))).run(x).y
        want = definition([int(v) for v in x], threshold)
        got = {c: int(y[c + th.DELAY]) for c in want}  # the output for input c + 4 decides sample c
        assert got == want, f"threshold {threshold}"


def test_first_sample_fills_the_window_and_four_outputs_come_late():
    x = np.array([1000, 1001, 999, 30000, 1002, 1000, 998, 1001, 1003, 1000, 999, 1002], dtype=np.int64)
    y = FixedModel(CONFIG).run(x).y
    # the series extended to the left by copies of its first sample: the first four outputs are it
    assert y[:4].tolist() == [1000] * 4
    assert y[4:7].tolist() == [1000, 1001, 999]
    assert y[7] != 30000 and abs(int(y[7]) - 1000) < 5  # the glitch, replaced
    # the float reference says the same (it only keeps the Hanning value exact)
    assert th.reference(CONFIG.params, "online", x)["y"][7] == pytest.approx(float(y[7]), abs=0.5)


def test_channels_are_independent_and_a_batch_equals_one_by_one(seed):
    rng = np.random.default_rng(seed)
    a, b = glitchy(rng, 300), glitchy(rng, 300)
    model = FixedModel(CONFIG)
    batch = model.run(np.stack([a, b])).y
    assert np.array_equal(batch[0], model.run(a).y) and np.array_equal(batch[1], model.run(b).y)
    channel = rng.permutation(np.repeat([0, 1], 300))  # the two series interleaved at random
    codes = np.zeros(600, dtype=np.int64)
    codes[channel == 0], codes[channel == 1] = a, b
    outs, _, _ = model.run_channels(codes, channel)
    assert np.array_equal(outs["y"][channel == 0], model.run(a).y)
    assert np.array_equal(outs["y"][channel == 1], model.run(b).y)


def test_default_formats_cannot_overflow():
    """The interval analysis of the traced update finds no write that can overflow: a median is a
    sample, a Hanning value lies between samples (and rounds to the nearest code)."""
    assert FixedModel(CONFIG).kernel(False).sites == ()
    x = np.array([CODE_MAX, CODE_MIN] * 50 + [CODE_MAX] * 20, dtype=np.int64)
    assert not FixedModel(CONFIG).run(x).overflow.any()


def test_narrow_formats_saturate_and_flag():
    from kfpga.core.fixed import QFormat

    config = FilterConfig(filter="tukey53h", formats={"x": QFormat(12, 0)}, check_ranges=False)
    res = FixedModel(config).run(np.array([100, 5000, -5000, 100], dtype=np.int64))
    assert res.overflow[1] and res.overflow[2] and not res.overflow[0]


@pytest.mark.parametrize("values", [range(5), range(3)])
def test_median_networks_are_medians_for_every_order_and_tie(values):
    """Every input of {0..k-1}^k (ties included), through IntOps, against numpy's median."""
    k = len(values)
    network = th.median5 if k == 5 else th.median3
    ops = IntOps({})
    fmt = th.FLAG.__class__(8, 0)
    for combo in itertools.product(values, repeat=k):
        got = network(ops, *(ops.input(v, fmt) for v in combo)).raw
        assert got == int(np.median(combo)), combo


def test_comparator_counts():
    ops = CostOps({})
    th.median5(ops, *(ops.input(0, th.FLAG) for _ in range(5)))
    assert ops.counts["comparisons"] == 7 and ops.counts["multiplications"] == 0
    ops = CostOps({})
    th.median3(ops, *(ops.input(0, th.FLAG) for _ in range(3)))
    assert ops.counts["comparisons"] == 3


def test_offline_decides_every_point_and_handles_the_ends(seed):
    rng = np.random.default_rng(seed)
    # a slow signal, as navigation data is: reversing 8 points puts a corner into a steep one
    clean = np.round(3000 * np.sin(np.arange(200) / 150.0) + 500)
    x = (clean + rng.normal(0, 5, 200)).round().astype(np.int64)
    x[[0, 2, 197, 199]] = [30000, -30000, 30000, -30000]  # outliers among the first and last 4
    model = FixedModel(CONFIG)
    out = th.offline(x, run=lambda s: model.run(s).y)
    assert np.all(np.abs(out[[0, 2, 197, 199]] - clean[[0, 2, 197, 199]]) < 300)
    assert np.all(np.abs(FixedModel(CONFIG).run(x).y[8:] - clean[:-8]) < 300)  # online: the same inside
    # the interior is the online smoother's, 4 samples earlier
    assert np.array_equal(out[4:-4], model.run(x).y[8:])
    # the ends come from the reversed series: the first 8 and the last 8 reversed
    flipped = x.copy()
    flipped[:8], flipped[-8:] = x[:8][::-1], x[-8:][::-1]
    yr = model.run(flipped).y
    assert out[0] == yr[7 + th.DELAY] and out[3] == yr[4 + th.DELAY] and out[-1] == yr[len(x) - 8 + th.DELAY]
    # float and fixed agree but for the rounding of x3
    assert np.max(np.abs(th.offline(x, CONFIG.params) - out)) <= 0.5


@pytest.mark.parametrize("n", [0, 5, 15])
def test_offline_refuses_short_series(n):
    with pytest.raises(ValueError, match="at least 16 points"):
        th.offline(np.zeros(n, dtype=np.int64), CONFIG.params)


@pytest.mark.parametrize(("value", "error"), [(0, ValueError), (-3.0, ValueError), (70000.0, ValueError),
                                              (float("nan"), ValueError), ("5", TypeError), (True, TypeError)])
def test_bad_threshold(value, error):
    with pytest.raises(error, match="threshold"):
        th.Tukey53HParams(threshold=value)


def test_thresholds_from_physical_limits():
    assert th.velocity_threshold(0.5, 1.0, 0.001) == pytest.approx(500.0)
    assert th.attitude_threshold(3.0, 0.5, 0.01) == pytest.approx(150.0)
    with pytest.raises(ValueError, match="a_max"):
        th.velocity_threshold(0.0, 1.0, 0.001)


def test_baselines_against_their_definitions(seed):
    from scipy.signal import savgol_filter

    from kfpga.model.evaluations.tukey53h import cubic_smoothing, sliding_wls

    rng = np.random.default_rng(seed)
    x = rng.normal(0, 10, 60).cumsum()
    np.testing.assert_allclose(cubic_smoothing(x), savgol_filter(x, 5, 3, mode="interp"), atol=1e-9)
    out = sliding_wls(x, 4)
    for c in range(len(x)):
        lo, hi = max(0, c - 4), min(len(x), c + 5)
        t = np.arange(lo, hi) - c
        line = np.polyfit(t, x[lo:hi], 1, w=np.sqrt(1 - np.abs(t) / 5))
        assert out[c] == pytest.approx(line[1], abs=1e-9)


def test_evaluate_53h_cli(tmp_path, capsys, seed):
    plot = tmp_path / "nav.png"
    assert main(["evaluate", "tukey53h", "--seed", str(seed), "--json", "--plot", str(plot)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert plot.stat().st_size > 10000
    rows = {(r["signal"], r["method"]): r for r in result["rows"]}
    h53 = rows[("east velocity", "53H offline (improved ends), bit-accurate")]
    cubic = rows[("east velocity", "5-point cubic smoothing")]
    # runs of 2 that land next to each other make runs of 3 or 4, which no 53H removes: on some seeds
    # one or two of them stay (see the claims over 20 seeds)
    assert h53["outliers"] > 10 and h53["false_replacements"] <= 5 and h53["removed_pct"] > 80
    assert cubic["removed_pct"] < 50 and cubic["distorted"] > h53["distorted"]
    limits = {r["case"]: r for r in result["limits"]}
    assert limits["runs of 1"]["removed_pct"] == 100.0 and limits["runs of 3"]["removed_pct"] < 50
    assert result["comparators"]["median of 5"]["comparisons"] == 7 and len(result["claims"]) == 10
    first = result["first_outlier"]  # the improved (offline) form restores an outlier as the first sample
    assert abs(first["offline"] - first["measured"]) <= first["threshold"] < abs(first["outlier"] - first["measured"])


def test_filter_offline_cli(tmp_path, capsys):
    src = tmp_path / "in.csv"
    x = np.round(100 * np.sin(np.arange(40) / 5)).astype(int)
    x[[0, 20, 39]] += 3000
    src.write_text("y\n" + "\n".join(map(str, x)) + "\n")
    out = tmp_path / "out.csv"
    assert main(["filter", "--filter", "tukey53h", "--input", str(src), "--output", str(out), "--offline"]) == 0
    y = np.loadtxt(out, delimiter=",", skiprows=1)[:, 0]
    assert len(y) == 40 and np.all(np.abs(y[[0, 20, 39]]) < 300) and y[10] == x[10]
    short = tmp_path / "short.csv"
    short.write_text("y\n1\n2\n3\n")
    capsys.readouterr()
    assert main(["filter", "--filter", "tukey53h", "--input", str(short), "--output", str(out), "--offline"]) == 2
    assert "needs at least 16" in capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), [
    (["filter", "--input", "x.csv", "--output", "o.csv", "--offline"], "--offline applies to the tukey53h filter"),
    (["generate", "--out", "g", "--threshold", "5"], "--threshold applies with --prefilter tukey53h only"),
    (["generate", "--out", "g", "--prefilter", "tukey53h", "--threshold", "0"], "threshold must be > 0"),
    (["compare", "--prefilter", "tukey53h", "--filter", "kalman", "--preset", "va2"], "one-input filter"),
    (["compare", "--prefilter", "tukey53h", "--plot", "p.png"], "--plot does not apply with --prefilter"),
    (["sweep", "--filter", "tukey53h"], "sweep does not apply to the tukey53h filter"),
    (["propose", "--filter", "tukey53h"], "propose does not apply to the tukey53h filter"),
    (["simulate", "--prefilter", "tukey53h", "--adc-model", "python"], "--prefilter runs with --adc-model verilog"),
    (["simulate", "--glitches", "0"], "--glitches must be a positive integer"),
])
def test_cli_errors(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.csv").write_text("y\n" + "\n".join(["1"] * 20) + "\n")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "g").exists() and not (tmp_path / "o.csv").exists()


def test_compare_prefilter_cli(capsys, seed):
    assert main(["compare", "--prefilter", "tukey53h", "--seed", str(seed), "--samples", "4000", "--json"]) == 0
    m = json.loads(capsys.readouterr().out)
    assert m["glitches"] > 5 and m["replaced"] >= m["glitches"]
    assert m["with_prefilter"]["rmse_fixed"] < 3.0 < 100 < m["without_prefilter"]["rmse_fixed"]


ANGLE = FilterConfig(filter="tukey53h", params=th.Tukey53HParams(threshold=300.0, turn=36000.0))


def _heading(seed, n=400):
    """A heading in 0.01 deg codes turning through +-180 deg several times (both ways), with
    noise; codes in [-18000, 18000)."""
    rng = np.random.default_rng(seed)
    turn = np.cumsum(np.where(np.arange(n) % 200 < 100, 37.0, -41.0) + rng.normal(0, 5, n)) + 17000
    return ((np.round(turn) + 18000) % 36000 - 18000).astype(np.int64)


def test_a_heading_crossing_half_a_turn_passes_unchanged(seed):
    """179.90 deg to -179.90 deg: every output the sample 4 before (once the 53H folded it in
    half: 179.90 -> 89.83)."""
    h = _heading(seed)
    assert np.any(np.abs(np.diff(h)) > 18000)  # it crosses
    out = FixedModel(ANGLE).run(h).y
    np.testing.assert_array_equal(out[th.DELAY:], h[:-th.DELAY])
    np.testing.assert_array_equal(th.reference(ANGLE.params, "online", h)["y"][th.DELAY:], h[:-th.DELAY])
    folded = FixedModel(FilterConfig(filter="tukey53h", params=th.Tukey53HParams(threshold=300.0))).run(h).y
    assert np.any(folded[th.DELAY:] != h[:-th.DELAY])  # without the turn it does not


def test_outliers_next_to_the_crossing_are_found(seed):
    rng = np.random.default_rng(seed)
    h = _heading(seed)
    cross = np.flatnonzero(np.abs(np.diff(h)) > 18000)
    bad = h.copy()
    hits = np.unique(np.clip(np.r_[cross, cross + 1], 10, len(h) - 10))  # runs of 2 across each crossing
    bad[hits] = (bad[hits] + rng.choice([-1, 1], len(hits)) * 3000 + 18000) % 36000 - 18000
    out = FixedModel(ANGLE).run(bad).y[th.DELAY:]
    # each outlier replaced: within the threshold of the clean heading, across the wrap
    d = (out[hits] - h[hits] + 18000) % 36000 - 18000
    assert np.all(np.abs(d) <= ANGLE.params.threshold), d
    # the definition on the unwrapped heading, x3 rounded as the model rounds it, wrapped back
    defined = th._online_float(np.unwrap(bad.astype(float), period=36000), 300.0, lambda v: np.floor(v + 0.5))[0]
    np.testing.assert_array_equal(out, ((defined + 18000) % 36000 - 18000)[th.DELAY:])


@pytest.mark.parametrize(("kwargs", "message"), [({"turn": 36001}, "turn must be an even integer"),
                                                  ({"turn": 70000}, "turn must be an even integer 4..65536"),
                                                  ({"turn": 1000, "threshold": 300}, "below a quarter of the turn")])
def test_bad_turn(kwargs, message):
    with pytest.raises(ValueError, match=message):
        th.Tukey53HParams(**{"threshold": 10.0, **kwargs})


#: A latitude in 1e-7 deg (32 bits) and the paper's threshold V_max T / R at 15 m/s
LATITUDE = FilterConfig(filter="tukey53h", params=th.Tukey53HParams(
    threshold=round(th.position_threshold(15.0, 1.0, 1e-7)), input_bits=32))


def _latitude(seed, n=500):
    """A ship at 10 m/s going north-east from 59.9 deg N, every second, in 1e-7 deg, with GNSS
    noise of 2 m and a few outliers of 50 to 500 m."""
    rng = np.random.default_rng(seed)
    metres = 10.0 * np.cos(np.radians(45)) * np.arange(n) + rng.normal(0, 2.0, n)
    lat = np.round((59.9 + np.degrees(metres / 6371000.0)) / 1e-7).astype(np.int64)
    hits = rng.choice(np.arange(8, n - 8), 8, replace=False)
    lat[hits] += np.round(rng.choice([-1, 1], 8) * rng.uniform(50, 500, 8) / 6371000.0 * 180 / np.pi / 1e-7).astype(int)
    return lat, np.sort(hits)


def test_position_threshold_is_vmax_t_over_r():
    # 15 m/s over 1 s on the earth: 1.349e-4 deg, 1349 codes of 1e-7 deg
    assert th.position_threshold(15.0, 1.0, 1e-7) == pytest.approx(15.0 / 6371000.0 * 180 / np.pi / 1e-7)
    assert LATITUDE.formats["x"].width == 32 and LATITUDE.formats["y"].width == 32
    assert LATITUDE.input_format.width == 32


def test_latitude_outliers_removed_in_32_bits(seed):
    lat, hits = _latitude(seed)
    assert lat.max() > 2 ** 15 * 1000  # far beyond a 16-bit code
    out = FixedModel(LATITUDE).run(lat).y[th.DELAY:]
    fixed = lat[:-th.DELAY]
    assert np.all(out[hits] != fixed[hits])  # every outlier replaced
    changed = np.flatnonzero(out != fixed)
    assert set(changed) == set(hits)  # and nothing else


def test_wide_input_csv(tmp_path, capsys):
    lat, _ = _latitude(3, 40)
    src, out = tmp_path / "lat.csv", tmp_path / "out.csv"
    src.write_text("y\n" + "\n".join(str(v) for v in lat) + "\n")
    cfg = tmp_path / "lat.toml"
    cfg.write_text('[filter]\nname = "53h"\n\n[model]\nthreshold = 1349\ninput_bits = 32\n')
    assert main(["filter", "--config", str(cfg), "--input", str(src), "--output", str(out)]) == 0
    assert main(["filter", "--filter", "53h", "--input", str(src), "--output", str(out)]) == 2
    assert "outside the signed 16-bit range" in capsys.readouterr().err
