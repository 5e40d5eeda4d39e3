"""Your own model at its real sample period: default formats that hold every constant, the
time-varying filter for any F and small T, scenarios drawn from the model, and a board that runs at
the model's rate (the conversion timer, the architecture chosen to meet the clock, kfpga explore).
"""

import json

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.core.config import FilterConfig
from kfpga.core.errors import UsageError
from kfpga.flows.analysis import compare
from kfpga.model import scenarios
from kfpga.model.kalman import StateSpaceParams
from kfpga.model.reference import KalmanParams
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.simulators import need

pytestmark = pytest.mark.xdist_group("own-model")


def tracker(t=0.01, r=25.0):
    """A 3-state constant-acceleration tracker sampled every ``t`` seconds."""
    return StateSpaceParams(F=((1.0, t, t * t / 2), (0.0, 1.0, t), (0.0, 0.0, 1.0)), G=((0.0,), (0.0,), (1.0,)),
                            Q=((1.0,),), H=((1.0, 0.0, 0.0),), R=((r,),), T=t)


def two_axis(t=0.02):
    """A 4-state two-axis constant-velocity tracker, both positions observed."""
    return StateSpaceParams(F=((1.0, t, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, t), (0.0, 0.0, 0.0, 1.0)),
                            G=((0.0, 0.0), (1.0, 0.0), (0.0, 0.0), (0.0, 1.0)), Q=((1.0, 0.0), (0.0, 1.0)),
                            H=((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)), R=((4.0, 0.0), (0.0, 4.0)), T=t,
                            observations=("x", "y"))


MODELS = {
    "paper T=0.01": FilterConfig(filter="kalman2", params=KalmanParams(T=0.01)),
    "paper T=0.001": FilterConfig(filter="kalman2", params=KalmanParams(T=0.001)),
    "2-state T=0.01": FilterConfig(filter="kalman", params=StateSpaceParams(
        F=((1.0, 0.01), (0.0, 1.0)), G=((0.0,), (1.0,)), Q=((1.0,),), H=((1.0, 0.0),), R=((4.0,),), T=0.01)),
    "3-state T=0.01": FilterConfig(filter="kalman", params=tracker()),
    "3-state T=0.001": FilterConfig(filter="kalman", params=tracker(0.001, 4.0)),
    "4-state two axes T=0.02": FilterConfig(filter="kalman", params=two_axis()),
    "random walk": FilterConfig(filter="kalman", params=StateSpaceParams(F=((1.0,),), G=((1.0,),), Q=((0.01,),),
                                                                           H=((1.0,),), R=((100.0,),))),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", MODELS)
def test_default_formats_are_within_one_percent_for_every_variant(name, seed):
    config = MODELS[name]
    truth, y = scenarios.for_config(config.spec.model.scenarios[0], 6000, seed, config)
    for variant, v in config.spec.model.variants.items():
        if v.applies(config.params):
            continue
        config.require_variant(variant)
        m = compare(config, variant, y, truth, limit_cycle=False).metrics
        assert m["overflows"] == 0, (name, variant, m["overflow_points"])
        assert abs(m["rmse_fixed_over_float"] - 1) <= 0.01, (name, variant, m["rmse_fixed_over_float"])


def test_each_entry_of_f_is_its_own_constant_held_to_ten_significant_bits():
    config = MODELS["3-state T=0.01"]
    f = config.formats
    assert {"f12", "f13", "f23"} <= set(f) and "f" not in f
    for name, value in (("f12", 0.01), ("f13", 5e-5), ("f23", 0.01)):
        raw = round(value * 2 ** f[name].frac_bits)
        assert abs(raw) >= 2 ** 9 and abs(raw * f[name].lsb - value) <= 1e-3 * value, (name, f[name])
        assert abs(raw) < 2 ** 17  # its significant bits fit one multiplier operand


def test_model_sized_defaults_and_pinned_formats_kept_in_toml(capsys, tmp_path):
    params = StateSpaceParams(F=((1.0, 0.5, 0.125), (0.0, 1.0, 0.5), (0.0, 0.0, 1.0)), G=((0.0,), (0.0,), (1.0,)),
                              Q=((1.0,),), H=((1.0, 0.0, 0.0),), R=((4.0,),))
    assert params.P0 == ((10.0, 0.0, 0.0), (0.0, 10.0, 0.0), (0.0, 0.0, 10.0)) and params.x0 == (0.0, 0.0, 0.0)
    cfg = tmp_path / "k.toml"
    cfg.write_text('[formats.x1]\nformat = "Q18.10"\n[formats.xl1]\nformat = "Q18.10"\n')
    assert main(["formats", "--config", str(cfg), "--toml"]) == 0
    text = capsys.readouterr().out
    assert '\n[formats.x1]' in text and '\n# [formats.x2]' in text  # pinned kept, defaults commented
    again = tmp_path / "again.toml"
    again.write_text(text)
    assert FilterConfig.from_toml(again).formats["x1"].frac_bits == 10


def test_formats_exits_non_zero_when_its_table_would_be_refused(capsys, tmp_path):
    cfg = tmp_path / "k.toml"
    cfg.write_text('[formats.gain]\nformat = "Q2.5"\n')
    assert main(["formats", "--config", str(cfg)]) == 2
    out, err = capsys.readouterr()
    assert "gain" in out and "the constant K1 = 0.7051" in err


def test_scenarios_follow_the_model_and_stay_in_range(seed):
    config = MODELS["3-state T=0.01"]
    truth, y = scenarios.for_config("model", 20000, seed, config)
    assert np.max(np.abs(truth)) <= 0.75 * 32767 + 1 and scenarios.rail_count(y) == 0
    # the sine of a two-axis model moves both axes, a quarter period apart
    two = MODELS["4-state two axes T=0.02"]
    _, codes = scenarios.for_config("sine", 4000, seed, two)
    assert np.std(codes["x"]) > 4000 and np.std(codes["y"]) > 4000
    assert abs(np.corrcoef(codes["x"], codes["y"])[0, 1]) < 0.1
    # a scenario driving the ADC to its rails is refused
    with pytest.raises(UsageError, match=r"scenario s drives the ADC to its rails on \d+ of 100 samples"):
        scenarios.check_rails("s", np.full(100, 32767))


def test_the_time_varying_tracker_runs_on_the_folded_core():
    config = MODELS["3-state T=0.01"]
    assert config.spec.architectures("full", config.params) == ("folded",)
    assert "folded core runs" in config.spec.why_not("full", config.params, "parallel")


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
def test_the_time_varying_tracker_is_bit_exact(simulator, seed):
    """The 3-state tracker at T = 0.01 s, time-varying, on its generated Verilog, against the model."""
    need(simulator)
    config = MODELS["3-state T=0.01"]
    _, y = scenarios.for_config("model", 60, seed, config)
    result = run(build(simulator, "core", config=config, variant="full", channels=2, architecture="folded"),
                 "test_core", testcase="core_bit_exact",
                 params={"variant": "full", "seed": seed, "codes": [int(c) for c in y], "channels": 2, "p_idle": 0.2,
                         "p_ready": 0.7, "config_toml": config.to_toml(), "architecture": "folded"},
                 tag="own-model-tracker")
    assert result["ok"] and result["mismatches"] == 0 and result["samples"] == 60, result.get("first_mismatches")


# -- the board at the model's rate ------------------------------------------------------------------

TRACKER_100 = """[filter]
name = "kalman"
[model]
T = 0.01
F = [[1.0, 0.01], [0.0, 1.0]]
G = [[0.0], [1.0]]
Q = [[1.0]]
H = [[1.0, 0.0]]
R = [[4.0]]
[board]
sample_rate_hz = 100
"""


@pytest.fixture
def at_100_hz(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "t.toml"
    path.write_text(TRACKER_100)
    return path


def test_generate_chooses_a_design_that_meets_the_clock(at_100_hz, capsys, tmp_path):
    assert main(["generate", "--config", str(at_100_hz), "--out", "g", "--no-lint", "--quiet"]) == 0
    m = json.loads((tmp_path / "g" / "manifest.json").read_text())
    assert m["sample_rate_hz"] == 100 and m["conversion_cycles"] == 500000
    # at 100 updates a second the folded core has cycles to spare, and is the cheapest design
    assert m["timing"]["fmax_mhz_estimate"] >= 62.5 and m["timing"]["logic_cells"] <= 500
    assert m["core"]["architecture"] == "folded"
    assert "100 Hz" in (tmp_path / "g" / "README.txt").read_text()
    # a parallel design that misses the clock is refused, naming one that meets it ...
    capsys.readouterr()
    assert main(["generate", "--config", str(at_100_hz), "--out", "slow", "--architecture", "parallel", "--stages", "1",
                 "--no-lint", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "below the 50 MHz clock" in err[0] and "meets it (--architecture folded)" in err[0]
    assert not (tmp_path / "slow").exists()
    # ... unless forced, and the manifest records it
    assert main(["generate", "--config", str(at_100_hz), "--out", "forced", "--architecture", "parallel", "--stages",
                 "1", "--ignore-timing", "--no-lint", "--quiet"]) == 0
    forced = json.loads((tmp_path / "forced" / "manifest.json").read_text())
    assert forced["timing"]["ignored"] and not forced["timing"]["meets_clock"]


def test_explore_lists_the_candidates(at_100_hz, capsys):
    assert main(["explore", "--config", str(at_100_hz), "--json", "--quiet"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert len(found) >= 2 and {c["architecture"] for c in found} == {"parallel", "folded"}
    chosen = [c for c in found if c["chosen"]]
    assert len(chosen) == 1 and chosen[0]["meets"]
    assert chosen[0]["logic_cells"] == min(c["logic_cells"] for c in found if c["meets"])


@pytest.mark.cosim
def test_simulate_runs_at_the_model_rate(at_100_hz, capsys):
    need("verilator")
    assert main(["simulate", "--config", str(at_100_hz), "--samples", "100", "--seed", "1", "--json", "--quiet"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["mismatches"] == 0 and r["samples"] == 100 and r["sample_rate_hz"] == 100
    assert 0.98e6 <= r["sim_time_us"] <= 1.02e6  # 100 conversions at 100 Hz


def test_a_rate_the_adc_cannot_reach_and_a_period_that_disagrees_are_refused(tmp_path, capsys):
    fast = tmp_path / "fast.toml"
    fast.write_text("[model]\nT = 3.3333333e-6\n[board]\nsample_rate_hz = 300000\n")
    assert main(["generate", "--config", str(fast), "--out", str(tmp_path / "g"), "--no-lint"]) == 2
    assert "at most 217391 Hz" in capsys.readouterr().err
    other = tmp_path / "other.toml"
    other.write_text("[model]\nT = 0.01\n[board]\nsample_rate_hz = 50\n")
    assert main(["compare", "--config", str(other), "--samples", "500"]) == 2
    assert "T = 0.01 s is a rate of 100 Hz, but [board] sample_rate_hz = 50" in capsys.readouterr().err


def test_a_design_past_the_device_is_never_chosen_nor_written(at_100_hz, capsys, tmp_path, monkeypatch):
    """With the device's M4K blocks cut to 3 (the folded core of this tracker takes more), explore
    marks the folded core 'no (device: ...)', auto takes a parallel loop, and a forced folded core
    is refused in one line, even with --ignore-timing: nothing is written."""
    from kfpga.hw.resources import EP2C20

    monkeypatch.setitem(EP2C20, "m4k_blocks", 3)
    assert main(["explore", "--config", str(at_100_hz), "--json", "--quiet"]) == 0
    found = json.loads(capsys.readouterr().out)
    folded = next(c for c in found if c["architecture"] == "folded")
    assert folded["m4k_blocks"] > 3 and not folded["fits"] and not folded["meets"] and not folded["chosen"]
    assert next(c for c in found if c["chosen"])["architecture"] == "parallel"
    assert main(["explore", "--config", str(at_100_hz), "--quiet"]) == 0
    assert f"no (device: {folded['m4k_blocks']} of 3 M4K blocks)" in capsys.readouterr().out
    for extra in ([], ["--ignore-timing"]):
        assert main(["generate", "--config", str(at_100_hz), "--out", "big", "--architecture", "folded", "--no-lint",
                     "--quiet", *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"kfpga generate: error: the folded design does not fit the EP2C20: it takes "
                       f"{folded['m4k_blocks']} of 3 M4K blocks"]
        assert not (tmp_path / "big").exists()
