"""The general state-space filter (``model/kalman.py``): what is particular to it.

The contract suite holds its bit-accurate model equal to exact rationals and to the RTL on
random models. Here: the float reference against filterpy and its own decomposed form, the
steady-state gain against scipy, the presets (``cv2`` against the golden integers, ``ca3`` and
``va2`` against float), the general steady filter against the paper's at the same formats, CSV
input with two observations, and the refusals of bad models, each pinned by its message.
"""

import math
import re

import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter

from kfpga.core import registry
from kfpga.core.config import ConfigError, FilterConfig
from kfpga.core.csvio import read_samples
from kfpga.core.errors import InputError
from kfpga.core.fixed import QFormat
from kfpga.core.fixedmodel import FixedModel
from kfpga.core.ops import FloatOps
from kfpga.flows.analysis import compare
from kfpga.model.kalman import SPEC, StateSpaceParams, dare_gain, reference
from kfpga.model.scenarios import for_config


def exactly(text):
    return "^" + re.escape(text) + "$"


def random_model(rng, n, m):
    """A random observable, stabilisable model with n states and m observations."""
    f = np.eye(n) + np.triu(rng.uniform(-0.6, 0.9, (n, n)), 1)
    f[np.diag_indices(n)] = rng.uniform(0.6, 1.0, n)
    g = rng.normal(size=(n, n))
    q = np.diag(rng.uniform(0.1, 3.0, n))
    h = np.zeros((m, n))
    for j in range(m):
        h[j, j] = 1.0
    a = rng.normal(size=(n, n))
    r = np.diag(rng.uniform(0.5, 10.0, m))
    return StateSpaceParams(F=f.tolist(), G=g.tolist(), Q=q.tolist(), H=h.tolist(), R=r.tolist(),
                            P0=(a @ a.T + np.eye(n)).tolist(), x0=rng.normal(0, 5, n).tolist())


def observations(rng, params, steps=150):
    ys = rng.normal(0, 200, (steps, params.m)).cumsum(axis=0)
    return {name: ys[:, j] for j, name in enumerate(params.observations)}


SHAPES = [(n, m) for n in range(1, 5) for m in range(1, 3) if m <= n]


@pytest.mark.parametrize(("n", "m"), SHAPES)
def test_reference_equals_filterpy(n, m, seed):
    rng = np.random.default_rng(seed)
    params = random_model(rng, n, m)
    y = observations(rng, params)
    ours = reference(params, "full", y)
    f, gqg, h, r = params.arrays()
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.F, kf.Q, kf.H, kf.R = f, gqg, h, r
    kf.x, kf.P = np.array(params.x0, dtype=float), np.array(params.P0, dtype=float)
    ys = np.stack([y[name] for name in params.observations], axis=-1)
    for t in range(len(ys)):
        kf.predict()
        np.testing.assert_allclose([ours[f"yhat{j + 1}"][t] for j in range(m)], h @ kf.x, rtol=1e-9, atol=1e-7)
        kf.update(ys[t])
        np.testing.assert_allclose([ours[f"x{i + 1}"][t] for i in range(n)], kf.x, rtol=1e-9, atol=1e-7)


def decomposed(params, variant, y):
    """The variant's update (the stage functions the fixed model and RTL run) in float64."""
    v = SPEC.model.variants[variant]
    ops = FloatOps({})
    k = ops.constants(v.constants(params))
    state = {name: ops.input(value, point, name) for (name, point), value in
             zip(v.state_for(params), (v.initial(params)[name] for name, _ in v.state_for(params)), strict=True)}
    steps = len(next(iter(y.values())))
    out = {}
    for t in range(steps):
        u = {name: ops.input(y[name][t], "y", name) for name in params.observations}
        state, o = v.update(ops, k, state, u)
        for name, value in o.items():
            out.setdefault(name, []).append(float(value.raw))
    return {name: np.array(v) for name, v in out.items()}


@pytest.mark.parametrize(("n", "m"), SHAPES)
@pytest.mark.parametrize("variant", ["steady", "full"])
def test_decomposed_form_equals_matrix_form(n, m, variant, seed):
    rng = np.random.default_rng(seed)
    params = random_model(rng, n, m)
    y = observations(rng, params)
    matrix_form = reference(params, variant, y)
    stages = decomposed(params, variant, y)
    assert set(stages) == set(matrix_form)
    for name in matrix_form:
        np.testing.assert_allclose(stages[name], matrix_form[name], rtol=1e-9, atol=1e-6, err_msg=name)


@pytest.mark.parametrize(("n", "m"), SHAPES)
def test_steady_gain_equals_scipy_dare(n, m, seed):
    rng = np.random.default_rng(seed)
    params = random_model(rng, n, m)
    f, gqg, h, r = params.arrays()
    p = scipy.linalg.solve_discrete_are(f.T, h.T, gqg, r)
    k_scipy = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
    k, p_ours = dare_gain(params)
    np.testing.assert_allclose(k, k_scipy, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(p_ours, p, rtol=1e-8, atol=1e-9)


def test_cv2_preset_is_the_paper_filter_and_its_golden_integers():
    name, params = registry.preset("cv2")
    assert name == "kalman2"
    # the golden file's default config (tests/test_golden.py checks every case of it)
    from test_golden import GOLDEN, golden_config

    config = FilterConfig(filter=name, params=params)
    assert config.formats == golden_config("default").formats
    for variant in ("steady", "full"):
        res = FixedModel(config, variant=variant).run(GOLDEN[f"default/{variant}/stress/y"].astype(np.int64))
        for field in ("x1", "x2", "yhat"):
            np.testing.assert_array_equal(res.outputs[field], GOLDEN[f"default/{variant}/stress/{field}"])


def test_general_steady_filter_equals_the_paper_filter_at_the_same_formats(seed):
    """At T = 1 the paper's steady filter is x = F x + K (y - H F x) with F = [[1, 1], [0, 1]]:
    given the same formats (xl2 = x2 exactly, yhat = xl1) and its products K e exact, as the paper's
    are, both give the same integers."""
    paper = FilterConfig(filter="kalman2")
    f = paper.formats
    general = FilterConfig(filter="kalman", params=StateSpaceParams(), formats={
        "x1": f["x1"], "x2": f["v"], "xl1": f["xl1"], "xl2": f["v"], "yh1": f["xl1"], "e1": f["e"],
        "k1": f["gain"], "k2": f["gain"], "ke11": "exact", "ke21": "exact"})
    assert {name: fmt for name, fmt in general.casts.items() if name.startswith("ke")} == {"ke11": None, "ke21": None}
    rng = np.random.default_rng(seed)
    y = np.clip(np.round(np.cumsum(rng.normal(0, 300, 3000))), -32768, 32767).astype(np.int64)
    y[1000:1010] = 32767
    a = FixedModel(paper, variant="steady").run(y)
    b = FixedModel(general, variant="steady").run(y)
    np.testing.assert_array_equal(a.outputs["x1"], b.outputs["x1"])
    np.testing.assert_array_equal(a.outputs["yhat"], b.outputs["yhat1"])
    np.testing.assert_array_equal(a.state.values["v"], b.state.values["x2"])
    np.testing.assert_array_equal(a.overflow, b.overflow)


@pytest.mark.parametrize(("preset", "variant"), [("ca3", "steady"), ("ca3", "full"), ("va2", "steady"),
                                                 ("va2", "full")])
def test_presets_fixed_rmse_within_one_percent_of_float(preset, variant, seed):
    name, params = registry.preset(preset)
    config = FilterConfig(filter=name, params=params)
    truth, y = for_config("sine", 20000, seed, config)
    m = compare(config, variant, y, truth).metrics
    assert m["overflows"] == 0
    assert m["rmse_fixed_over_float"] <= 1.01, m["rmse_fixed_over_float"]


def test_two_observations_read_from_their_csv_columns(tmp_path):
    _, params = registry.preset("va2")
    config = FilterConfig(filter="kalman", params=params)
    assert config.inputs == ("velocity", "acceleration")
    path = tmp_path / "in.csv"
    path.write_text("acceleration,velocity,truth\n1,10,9.5\n-2,12,11.0\n3,-7,-6.5\n")
    samples = read_samples(path, columns=config.inputs)
    np.testing.assert_array_equal(samples.y["velocity"], [10, 12, -7])
    np.testing.assert_array_equal(samples.y["acceleration"], [1, -2, 3])
    res = FixedModel(config).run(samples.y)
    assert len(res.outputs["x1"]) == 3 and set(res.outputs) == {"x1", "x2", "yhat1", "yhat2"}
    path.write_text("velocity,truth\n1,2\n")
    with pytest.raises(InputError, match=exactly(f"{path}: line 1: no column named 'acceleration' (the header has: "
                                                 "velocity, truth)")):
        read_samples(path, columns=config.inputs)


BAD_MODELS = [
    ({"F": [[1.0, 1.0]]}, "model.F must be n x n with n = 1..4 states, not 1 x 2"),
    ({"F": [[1.0] * 5] * 5}, "model.F must be n x n with n = 1..4 states, not 5 x 5"),
    ({"H": [[1.0, 0.0, 0.0]]}, "model.H must be m x 2 (m = 1..2 observations of the 2 states), not 1 x 3"),
    ({"G": [[1.0], [0.0], [0.0]]}, "model.G must be 2 x p (p = 1..4 noise inputs), not 3 x 1"),
    ({"Q": [[1.0, 0.5], [0.4, 1.0]], "G": [[1.0, 0.0], [0.0, 1.0]]},
     "model.Q must be symmetric, not [[1.0, 0.5], [0.4, 1.0]]"),
    ({"Q": [[-1.0]]}, "model.Q must be positive semi-definite, not ((-1.0,),) (eigenvalues -1)"),
    ({"R": [[0.0]]}, "model.R must be positive definite, not [[0.0]] (eigenvalues 0)"),
    ({"P0": [[1.0, 2.0], [2.0, 1.0]]}, "model.P0 must be positive definite, not [[1.0, 2.0], [2.0, 1.0]] "
                                       "(eigenvalues -1, 3)"),
    ({"P0": [[1.0, 0.1], [0.0, 1.0]]}, "model.P0 must be symmetric, not [[1.0, 0.1], [0.0, 1.0]]"),
    ({"H": [[0.3, 0.0]]}, "model.H[0][0] = 0.3: H must select states (entries 0 or +-2**k)"),
    ({"x0": [1.0]}, "model.x0 must have 2 entries (one per state), not 1: [1.0]"),
    ({"H": [[0.0, 1.0]]}, "model.H: (F, H) is not detectable: F's mode of eigenvalue 1 is not stable and H does not "
                          "see it, so the steady-state gain does not exist (observe that state, or use the full "
                          "variant)"),
    ({"G": [[1.0], [0.0]]}, "model.G, model.Q: (F, G Q^1/2) is not stabilisable: F's mode of eigenvalue 1 is not stable and no "
                            "process noise reaches it, so the Riccati equation has no stabilising solution (add "
                            "noise to that state, or use the full variant)"),
    ({"observations": ["a", "a"], "H": [[1.0, 0.0], [0.0, 1.0]], "R": [[1.0, 0.0], [0.0, 1.0]]},
     "model.observations must be 2 different names (letters, digits, _), not ['a', 'a']"),
]


@pytest.mark.parametrize(("model", "message"), BAD_MODELS, ids=[m for m, _ in enumerate(BAD_MODELS)])
def test_bad_models_are_refused_with_a_message_naming_the_matrix(model, message):
    with pytest.raises(ConfigError, match=exactly(message)):
        # the steady variant needs the Riccati equation's solution; the others fail on creation
        FilterConfig.from_dict({"filter": {"name": "kalman"}, "model": model}, source="my.toml").require_variant("steady")


def test_innovation_fraction_bits_follow_the_observation_noise():
    """R = 0.01 (0.1 codes of noise): e gets the fraction bits that keep its step below a
    quarter of the noise's standard deviation, even past one 18-bit multiplier operand."""
    _, params = registry.preset("ca3")
    e = FilterConfig(filter="kalman", params=params).formats["e1"]
    assert e.lsb <= math.sqrt(0.01) / 4 and e.frac_bits == 6 and e.width > 18
    # the paper's noise (R = 4) keeps the 18-bit operand
    assert FilterConfig(filter="kalman").formats["e1"] == QFormat(17, 1, "half_up")
