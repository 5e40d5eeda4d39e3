"""Samples with no measurement: the update predicts only (x = F x, P = F P F' + G Q G').

The model's compiled loops against the direct backend, a missing sample's code never read, the
folded core's microcode against the model, the float filter's coasting against filterpy's
predict-only steps (RMSE within 1 % over 10 seeds), and ``kfpga filter`` on empty cells.
"""

import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.linalg import solve_discrete_are

from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.microcode import compile_update, execute
from kfpga.model.scenarios import for_config

ROOT = Path(__file__).resolve().parents[1]
TRACKER = ROOT / "examples" / "models" / "tracker.toml"
#: The paper's filter with room in its covariance for gaps of several samples: the default formats
#: hold the covariance of a filter that measures every sample, and a coasting one grows past them
#: (a saturation there is flagged, and the time-varying gain then is not the float filter's).
GAPS = '[filter]\nname = "kalman2"\n[formats.p]\nformat = "Q9.11"\n[formats.pl]\nformat = "Q10.11"\n' \
       '[formats.s]\nformat = "Q10.11"\n'


def configs():
    return {"kalman2": FilterConfig(), "tracker": FilterConfig.from_toml(TRACKER)}


def lost(n, seed, share=0.2):
    return np.random.default_rng(seed).random(n) < share


@pytest.mark.parametrize("variant", ["steady", "full"])
@pytest.mark.parametrize("case", ["kalman2", "tracker"])
def test_the_compiled_model_coasts_as_the_direct_backend(case, variant, seed):
    config = configs()[case]
    y = np.random.default_rng(seed).normal(0, 400, 300).astype(np.int64)
    missing = lost(300, seed + 1)
    model = FixedModel(config, variant=variant)
    a, b = model.run(y, missing=missing), model.run_ops(y, missing=missing)
    for name in model.outputs:
        np.testing.assert_array_equal(a.outputs[name], b.outputs[name])
    np.testing.assert_array_equal(a.overflow, b.overflow)
    # a missing sample's code is never read; a measured one is
    other = np.where(missing, -y, y)
    c = model.run(other, missing=missing)
    for name in model.outputs:
        np.testing.assert_array_equal(a.outputs[name], c.outputs[name])
    assert any(not np.array_equal(a.outputs[n], model.run(y).outputs[n]) for n in model.outputs)


@pytest.mark.parametrize("variant", ["steady", "full"])
@pytest.mark.parametrize("case", ["kalman2", "tracker"])
def test_the_folded_microcode_coasts_as_the_model(case, variant, seed):
    config = configs()[case]
    y = np.random.default_rng(seed).normal(0, 400, 200).astype(np.int64)
    missing = lost(200, seed + 1)
    program = compile_update(config, variant, predict=True)
    outs, flags = execute(program, [{"y": int(c)} for c in y], [0] * len(y), missing=missing)
    want = FixedModel(config, variant=variant).run(y, missing=missing)
    for name in want.outputs:
        np.testing.assert_array_equal([o[name] for o in outs], want.outputs[name])
    assert flags == want.overflow.tolist()


def test_a_filter_that_cannot_coast_says_so():
    model = FixedModel(FilterConfig(filter="tukey53h"))
    with pytest.raises(ValueError, match="takes every sample as a measurement"):
        model.run(np.zeros(8, dtype=np.int64), missing=np.ones(8, dtype=bool))
    with pytest.raises(ValueError, match="takes every sample as a measurement"):
        compile_update(FilterConfig(filter="tukey53h"), "online", predict=True)


def _physical(config):
    """F, G Q G^T, H, R, P0, x0 of the model in its own units (the state the outputs show)."""
    p = config.params
    if config.spec.name == "kalman2":
        return (np.array([[1.0, p.T], [0.0, 1.0]]), np.array([[0.0, 0.0], [0.0, p.Q]]), np.array([[1.0, 0.0]]),
                np.array([[p.R]]), np.array(p.P0, dtype=float), np.array(p.x0, dtype=float))
    g = np.array(p.G)
    return (np.array(p.F), g @ np.array(p.Q) @ g.T, np.array(p.H), np.array(p.R), np.array(p.P0, dtype=float),
            np.array(p.x0, dtype=float))


def _filterpy(config, variant, y, missing):
    """filterpy's KalmanFilter: predict() every sample, update() where it is measured; the steady
    variant's covariance held at the Riccati equation's posterior (its gain then is K_inf)."""
    f, gqg, h, r, p0, x0 = _physical(config)
    n = len(f)
    kf = KalmanFilter(dim_x=n, dim_z=1)
    kf.F, kf.Q, kf.H, kf.R, kf.P, kf.x = f, gqg, h, r, p0.copy(), x0.reshape(n, 1)
    held = None
    if variant == "steady":
        prior = solve_discrete_are(f.T, h.T, gqg, r)
        gain = prior @ h.T @ np.linalg.inv(h @ prior @ h.T + r)
        held = (np.eye(n) - gain @ h) @ prior
        kf.P = held.copy()
    out = np.empty(len(y))
    for t, (z, gone) in enumerate(zip(y, missing, strict=True)):
        kf.predict()
        if not gone:
            kf.update(np.array([[float(z)]]))
        if held is not None:
            kf.P = held.copy()
        out[t] = kf.x[0, 0]
    return out


@pytest.mark.parametrize(("case", "variant"), [("kalman2", "steady"), ("gaps", "full"), ("tracker", "steady"),
                                               ("tracker", "full")])
def test_the_coasting_filter_is_within_one_percent_of_filterpy(case, variant):
    """The bit-accurate model's RMSE against the truth, a fifth of the samples missing, within 1 %
    of filterpy's (predict-only steps there), on each of 10 seeds of the model's own process."""
    config = FilterConfig.from_dict(tomllib.loads(GAPS)) if case == "gaps" else configs()[case]
    ratios = []
    for seed in range(10):
        truth, y = for_config("model", 4000, seed, config)
        missing = lost(len(y), 1000 + seed)
        model = FixedModel(config, variant=variant)
        res = model.run(y, missing=missing)
        ours = model.to_float(res)["x1"]
        theirs = _filterpy(config, variant, y, missing)
        settle = 200
        ratios.append(np.sqrt(np.mean((ours[settle:] - truth[settle:]) ** 2))
                      / np.sqrt(np.mean((theirs[settle:] - truth[settle:]) ** 2)))
    print(f"{case} {variant}: RMSE ratios {np.round(ratios, 4).tolist()}")
    assert max(abs(r - 1) for r in ratios) < 0.01, ratios


def test_kfpga_filter_takes_empty_cells_as_missing_samples(tmp_path):
    src = tmp_path / "lost.csv"
    src.write_text("y,truth\n10,0\n,1\n12,2\n13,3\n,4\n,5\n20,6\n")
    out = tmp_path / "est.csv"
    run = subprocess.run([sys.executable, "-m", "kfpga", "filter", "--config", str(TRACKER), "--input", str(src),
                          "--output", str(out)], capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr
    assert "3 with no measurement" in run.stderr
    lines = out.read_text().splitlines()
    assert lines[0].split(",")[-1] == "missing" and len(lines) == 8
    assert [line.split(",")[-1] for line in lines[1:]] == ["0", "1", "0", "0", "1", "1", "0"]
    config = FilterConfig.from_toml(TRACKER)
    model = FixedModel(config)
    codes = np.array([10, 0, 12, 13, 0, 0, 20])
    want = model.to_float(model.run(codes, missing=np.array([0, 1, 0, 0, 1, 1, 0], dtype=bool)))["x1"]
    np.testing.assert_array_equal([float(line.split(",")[0]) for line in lines[1:]], want)
    bad = subprocess.run([sys.executable, "-m", "kfpga", "filter", "--filter", "tukey53h", "--input", str(src),
                          "--output", str(out)], capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and "cannot coast" in bad.stderr and "Traceback" not in bad.stderr
