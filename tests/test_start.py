"""A start from the first measurements (``[model] init = "measurement"``, model/start.py): the
positions from the first sample, the rates from the first two, in the float filter, the model and
the folded core, bit-exact; the parallel cores refuse it; compare says how long the start-up
took."""

import dataclasses

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.flows.analysis import compare, startup_samples
from kfpga.model import scenarios
from kfpga.model.alphabeta import AlphaBetaParams
from kfpga.model.kalman import StateSpaceParams, start_plan
from kfpga.model.reference import KalmanParams
from kfpga.model.roll import RollParams
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.simulators import need

pytestmark = pytest.mark.xdist_group("start")

T = 0.01


def tracker(**kw):
    """The 3-state constant-acceleration tracker at T = 0.01 s."""
    return StateSpaceParams(F=((1.0, T, T * T / 2), (0.0, 1.0, T), (0.0, 0.0, 1.0)), G=((0.0,), (0.0,), (1.0,)),
                            Q=((1.0,),), H=((1.0, 0.0, 0.0),), R=((25.0,),), T=T, **kw)


#: (filter, params, position output, rate output), each starting from the measurements
STARTS = {
    "kalman2": ("kalman2", KalmanParams(T=T, Q=2.0, R=4.0, x0=(5.0, -7.0), init="measurement"), "x1", "x2"),
    "alphabeta": ("alphabeta", AlphaBetaParams(alpha=0.3, beta=0.05, T=T, R=4.0, x0=(5.0, -7.0), init="measurement"),
                  "x", "v"),
    "kalman": ("kalman", tracker(x0=(5.0, -7.0, 3.0), init="measurement"), "x1", "x2"),
}
CASES = [pytest.param(key, variant, id=f"{key}-{variant}") for key, (name, params, _, _) in STARTS.items()
         for variant in FilterConfig(filter=name, params=params).spec.model.variants]


@pytest.mark.parametrize(("key", "variant"), CASES)
def test_positions_from_the_first_sample_rates_from_the_first_two(key, variant):
    """y0 = 1000, y1 = 1003 at T = 0.01 s: the position is 1000, then 1003; the rate keeps x0's
    -7 on sample 0 and is (1003 - 1000) / 0.01 = 300 on sample 1; in the float filter and,
    exactly, in the bit-accurate model."""
    name, params, pos, rate = STARTS[key]
    y = np.array([1000, 1003, 1001, 1006, 1004, 1010], dtype=np.int64)
    config = FilterConfig(filter=name, params=params)
    flt = config.spec.model.reference(params, variant, y)
    model = FixedModel(config, variant=variant)
    fixed = model.to_float(model.run(y))
    # x0's rate as the model holds it: within an LSB of each rounding on its way to the output (the
    # state v = T x2 and the operand vt of v / T in the 2-state loops)
    held = model.output_format(rate).lsb + sum(config.formats[p].lsb / T for p in ("v", "vt") if p in config.formats)
    for out, tol in ((flt, 1e-9), (fixed, held)):
        assert out[pos][0] == 1000.0 and out[pos][1] == 1003.0
        assert abs(out[rate][0] + 7.0) <= tol and out[rate][1] == pytest.approx(300.0, rel=1e-12)
    assert fixed[rate][1] == 300.0
    # from x0 instead, the first estimate is a blend of x0 and y0
    plain = dataclasses.replace(params, init="state")
    assert config.spec.model.reference(plain, variant, y)[pos][0] < 1000.0


def test_the_acceleration_of_the_tracker_is_held_on_the_first_sample():
    flt = FilterConfig(filter="kalman", params=STARTS["kalman"][1]).spec.model.reference(
        STARTS["kalman"][1], "full", np.array([1000.0, 1003.0, 1001.0]))
    assert flt["x3"][0] == 3.0 and flt["x3"][1] != 3.0


def test_the_plan_names_each_position_and_its_rate():
    t = 0.5
    cv = StateSpaceParams(F=((1.0, t), (0.0, 1.0)), H=((1.0, 0.0),))
    assert start_plan(cv) == ({0: (0, 1.0)}, {1: (0, t)})
    # the acceleration moves the position through T**2/2 too, but it feeds the velocity: the rate is the velocity
    assert start_plan(tracker()) == ({0: (0, 1.0)}, {1: (0, T)})
    # two axes, each position with its own rate; an observation scaled by 2 reads y / 2
    two = StateSpaceParams(F=((1.0, t, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, t), (0.0, 0.0, 0.0, 1.0)),
                           G=((0.0, 0.0), (1.0, 0.0), (0.0, 0.0), (0.0, 1.0)), Q=((1.0, 0.0), (0.0, 1.0)),
                           H=((2.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)), R=((4.0, 0.0), (0.0, 4.0)))
    assert start_plan(two) == ({0: (0, 2.0), 2: (1, 1.0)}, {1: (0, t), 3: (2, t)})
    # a random walk has a position and no rate
    walk = StateSpaceParams(F=((1.0,),), G=((1.0,),), Q=((0.01,),), H=((1.0,),), R=((100.0,),))
    assert start_plan(walk) == ({0: (0, 1.0)}, {})
    with pytest.raises(ValueError, match="init = \"measurement\" needs an observation that selects one state alone"):
        StateSpaceParams(F=((1.0, t), (0.0, 1.0)), H=((1.0, 1.0),), init="measurement")


def test_an_observation_scaled_by_h_starts_its_position_at_y_over_h():
    params = StateSpaceParams(F=((1.0, T), (0.0, 1.0)), H=((2.0, 0.0),), R=((4.0,),), T=T, init="measurement")
    config = FilterConfig(filter="kalman", params=params)
    model = FixedModel(config, variant="steady")
    fixed = model.to_float(model.run(np.array([1000, 1004, 1002])))
    assert fixed["x1"][:2].tolist() == [500.0, 502.0] and fixed["x2"][1] == 200.0


@pytest.mark.parametrize("variant", ["sqrt", "plain"])
def test_the_roll_predictor_starts_from_three_samples_as_its_paper_does(variant):
    """Filter a takes 10, 22, 40 (samples 0, 2, 4): at its third the angle 40, the rate 40 - 22 = 18
    and the acceleration 40 - 2*22 + 10 = 6 (per filter step), moved a step on: 40 + 18 + 3 = 61,
    18 + 6 = 24, 6. Before that each sample goes out as its own prediction."""
    params = RollParams(init="measurement")
    config = FilterConfig(filter="roll", params=params)
    z = np.array([10, 14, 22, 30, 40, 46, 52], dtype=np.int64)
    model = FixedModel(config, variant=variant)
    fixed = model.to_float(model.run(z))
    for out in (fixed, config.spec.model.reference(params, variant, z)):
        assert [out["pred"][n] for n in range(4)] == [10.0, 14.0, 22.0, 30.0]
        assert (out["pred"][4], out["rate"][4], out["accel"][4]) == (61.0, 24.0, 6.0)
        # filter b: 14, 30, 46: 46 + 16 + 0
        assert (out["pred"][5], out["rate"][5], out["accel"][5]) == (62.0, 16.0, 0.0)


#: The parallel cores that run the start: the constant-gain loop's (hw/cvloop.py)
PARALLEL_STARTS = {("kalman2", "steady"), ("alphabeta", "steady")}


@pytest.mark.parametrize("key", STARTS)
def test_which_cores_run_it(key):
    """The constant-gain loop runs the start; the other parallel cores (hand-pipelined for one
    update form) refuse it, and the folded core runs every one."""
    name, params, _, _ = STARTS[key]
    config = FilterConfig(filter=name, params=params)
    for variant in config.spec.model.variants:
        if (key, variant) in PARALLEL_STARTS:
            assert config.spec.architectures(variant, params) == ("parallel", "folded")
            continue
        assert config.spec.architectures(variant, params) == ("folded",)
        why = config.spec.why_not(variant, params, "parallel")
        assert why.startswith('model.init = "measurement": the start from the first samples runs on the folded')


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("key", "variant", "architecture", "channels"),
                         [("kalman", "full", "folded", 2), ("kalman2", "steady", "folded", 2),
                          pytest.param("roll", "sqrt", "folded", 2, marks=pytest.mark.long),
                          ("kalman2", "steady", "parallel", 2),
                          ("alphabeta", "steady", "parallel", 3), ("alphabeta", "steady", "parallel", 10)])
def test_the_start_is_bit_exact_on_the_core(key, variant, architecture, channels, simulator, seed):
    """The core's generated Verilog against the model, several channels (each starts by itself;
    10: the states and counts in block memory), from a signal far from x0."""
    need(simulator)
    if key == "roll":
        name, params = "roll", RollParams(init="measurement")
    else:
        name, params, _, _ = STARTS[key]
    config = FilterConfig(filter=name, params=params)
    _, y = scenarios.for_config(config.spec.model.scenarios[0], 50, seed, config)
    y = np.clip(y + 9000, -32768, 32767)
    result = run(build(simulator, "core", config=config, variant=variant, channels=channels, architecture=architecture),
                 "test_core", testcase="core_bit_exact",
                 params={"variant": variant, "seed": seed, "codes": [int(c) for c in y], "channels": channels,
                         "p_idle": 0.2, "p_ready": 0.7, "config_toml": config.to_toml(), "architecture": architecture},
                 tag=f"start-{key}-{architecture}-{channels}")
    assert result["ok"] and result["mismatches"] == 0 and result["samples"] == 50, result.get("first_mismatches")


def test_compare_says_how_long_the_start_up_took(seed):
    """A tracker switched on at 12,000 codes: from x0 = 0 it takes over a hundred samples to get
    there (110 to 127 over 40 seeds); from the first two samples, fewer than half as many (0 to 55:
    the rate of two noisy samples is forgotten at the filter's own pace). The RMSE skips the
    start-up."""
    rng = np.random.default_rng(seed)
    n = 6000
    truth = 12000.0 + 40.0 * np.sin(np.arange(n) * T)
    y = np.round(truth + rng.normal(0.0, 2.0, n)).astype(np.int64)
    got = {}
    for init in ("state", "measurement"):
        config = FilterConfig(filter="kalman2", params=KalmanParams(T=T, Q=5.0, R=4.0, init=init))
        m = compare(config, "steady", y, truth, limit_cycle=False).metrics
        got[init] = m["startup_samples"]
        assert m["settle"] == max(100, got[init])
    assert got["state"] > 100 and got["measurement"] < 0.6 * got["state"], got


def test_startup_samples_of_a_decay():
    """An error that decays as exp(-k/50) on top of unit noise: the rolling RMS is within 1.5x of
    the noise's once the decay is below about its size."""
    rng = np.random.default_rng(7)
    k = np.arange(10_000)
    err = 1000.0 * np.exp(-k / 50.0) + rng.normal(0.0, 1.0, k.size)
    got = startup_samples(err, np.zeros(k.size))
    assert 300 < got < 400  # 1000 e^(-k/50) = 1 at k = 345
    assert startup_samples(err[:30], np.zeros(30)) is None  # too short to tell


def test_init_in_the_config_file(tmp_path, capsys):
    params = KalmanParams(T=T, init="measurement")
    text = FilterConfig(filter="kalman2", params=params).to_toml()
    assert 'init = "measurement"' in text
    path = tmp_path / "c.toml"
    path.write_text(text)
    assert FilterConfig.from_toml(path).params.init == "measurement"
    path.write_text(text.replace('init = "measurement"', 'init = "first"'))
    capsys.readouterr()
    assert main(["compare", "--config", str(path), "--samples", "200"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["kfpga compare: error: model.init must be 'state' or 'measurement', not 'first'"]
