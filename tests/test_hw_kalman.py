# amaranth: UnusedElaboratable=no
"""The general state-space filter's cores on the presets and on random models.

The contract suite runs the registry's default model (the paper's matrices); here the presets
of the source documents (three states, two observations) and random models with 1..4 states
go through the same checks: RTL equal to the model in the Amaranth simulator with
backpressure, the declared latency and cycles per update measured, the cycle budget of the
time-varying core, and cocotb on the generated Verilog on both simulators.
"""

import dataclasses

import numpy as np
import pytest

from kfpga.core import registry
from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.config import ConfigError, FilterConfig
from kfpga.hw.cores import make_core
from kfpga.hw.generate import figures_only
from kfpga.hw.kalman import FullCore, SteadyCore, default_stages
from kfpga.model.kalman import SPEC
from kfpga.sim.amaranth_streams import measure_timing, run_core
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.pipeline import stage_table_faults
from tests.helpers.simulators import need

PRESET_CASES = [("ca3", "steady"), ("ca3", "full"), ("va2", "steady")]


def preset_config(name):
    filter_name, params = registry.preset(name)
    return FilterConfig(filter=filter_name, params=params)


def codes(rng, n):
    y = np.cumsum(rng.normal(0, 250, n)) + rng.normal(0, 30, n)
    y[n // 4: n // 4 + 15] = CODE_MAX
    y[n // 2: n // 2 + 15] = CODE_MIN
    return np.clip(np.round(y), CODE_MIN, CODE_MAX).astype(np.int64)


def stimulus(config, rng, n):
    names = config.inputs
    return codes(rng, n) if len(names) == 1 else {name: codes(rng, n) for name in names}


@pytest.mark.parametrize(("preset", "variant"), PRESET_CASES)
@pytest.mark.parametrize("channels", [1, 3])
def test_preset_rtl_equals_model_with_backpressure(preset, variant, channels, seed):
    config = preset_config(preset)
    rng = np.random.default_rng(seed)
    n = 400 if variant == "full" else 1200
    report = run_core(config, variant, stimulus(config, rng, n), seed=seed, channels=channels, p_idle=0.3,
                      p_ready=0.5)
    assert report["compared"] == n and report["extra"] == 0


def test_random_models_rtl_equals_model(seed):
    """Random models with 1..4 states and 1..2 observations, both variants where they apply."""
    rng = np.random.default_rng(seed)
    done = 0
    for _ in range(8):
        params = SPEC.random_params(rng)
        for variant in SPEC.model.variants:
            try:
                config = FilterConfig(filter="kalman", params=params)
                config.require_variant(variant)
            except ConfigError:
                continue
            if config.spec.model.variants[variant].hardware(params):
                assert variant == "full" and params.m == 2  # the only model-only case
                continue
            n = 150 if variant == "full" else 400
            report = run_core(config, variant, stimulus(config, rng, n), seed=seed, channels=2, p_idle=0.2,
                              p_ready=0.7)
            assert report["compared"] == n and report["extra"] == 0, params
            done += 1
    assert done >= 8


@pytest.mark.parametrize(("preset", "variant"), PRESET_CASES)
def test_preset_latency_and_cycles_per_update_are_measured(preset, variant):
    config = preset_config(preset)
    dut = make_core(config, variant)
    latency, accepted, produced = measure_timing(dut, config)
    assert latency == dut.latency
    assert accepted[2:7] == [dut.cycles_per_update] * 5
    assert produced[:5] == [dut.cycles_per_update] * 5


def test_time_varying_core_takes_at_most_200_cycles_for_three_states():
    """Issue budget: <= 200 cycles per update at 50 MHz for n = 3 (ca3: 250 kupdates/s)."""
    dut = FullCore(preset_config("ca3"))
    assert dut.cycles_per_update <= 200


def test_two_observations_run_on_the_folded_core_only_for_the_time_varying_variant():
    config = preset_config("va2")
    with pytest.raises(ValueError, match=r"^the parallel time-varying core takes one observation, not 2: the "
                                         r"folded core runs this model$"):
        FullCore(config)
    assert config.spec.architectures("full", config.params) == ("folded",)


def test_steady_loop_stages():
    """Three-term rows of F (ca3) get a stage for their sum and one for its rounding by default; up to
    seven (eight with two observations) when the products by F get stages of their own."""
    ca3, cv2 = preset_config("ca3"), FilterConfig(filter="kalman")
    assert default_stages(ca3.params) == 5 and default_stages(cv2.params) == 4
    assert SteadyCore(ca3).cycles_per_update == 5
    for stages in range(1, 8):
        assert SteadyCore(ca3, stages=stages).cycles_per_update == stages
    with pytest.raises(ValueError, match="stages must be one of 1, 2, 3, 4, 5, 6, 7, not 8"):
        SteadyCore(ca3, stages=8)


def _tracker(observations):
    """A 3-state constant-acceleration tracker at T = 0.01 s: constants of F that are not powers of
    two, so the products by F take multipliers (the loop's ``cuts_multiplied`` tables)."""
    from kfpga.model.kalman import StateSpaceParams

    h = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))[:observations]
    r = ((25.0, 0.0), (0.0, 4.0)) if observations == 2 else ((25.0,),)
    params = StateSpaceParams(F=((1.0, 0.01, 5e-5), (0.0, 1.0, 0.01), (0.0, 0.0, 1.0)), G=((0.0,), (0.0,), (1.0,)),
                              Q=((1.0,),), H=h, R=r, T=0.01)
    return FilterConfig(filter="kalman", params=params)


#: One model for each of the loop's four stage tables: F's constants free or multiplied, one or
#: two observations.
STAGE_MODELS = {"ca3": lambda: preset_config("ca3"), "va2": lambda: preset_config("va2"),
                "tracker": lambda: _tracker(1), "tracker-2-obs": lambda: _tracker(2)}


@pytest.mark.parametrize("model", list(STAGE_MODELS))
def test_every_stage_count_is_bit_exact(model, seed):
    """The steady loop at every stage count it takes, for each of its stage tables: each cut
    between its steps moves registers, never a value (two channels, idle gaps, a slow receiver)."""
    config = STAGE_MODELS[model]()
    table = SteadyCore(config).cuts
    assert SteadyCore(config).cuts is {"ca3": SteadyCore.cuts, "va2": SteadyCore.cuts_two_observations,
                                       "tracker": SteadyCore.cuts_multiplied,
                                       "tracker-2-obs": SteadyCore.cuts_multiplied_two_observations}[model]
    rng = np.random.default_rng(seed)
    for stages in table:
        report = run_core(config, "steady", stimulus(config, rng, 150), seed=seed, channels=2, p_idle=0.2,
                          p_ready=0.6, options={"stages": stages})
        assert report["compared"] == 150 and report["extra"] == 0, stages


def test_states_in_block_memory_start_from_a_negative_x0(seed):
    """Nine channel states, past the eight kept in registers, live in block memory: every word's
    power-up value packs x0's fields side by side, a negative one included (its sign bits must
    stop at its own field), and every channel starts from x0."""
    import dataclasses

    base = preset_config("ca3")
    params = dataclasses.replace(base.params, x0=(-40.0, 3.5, -0.25))
    config = FilterConfig(filter="kalman", params=params)
    rng = np.random.default_rng(seed)
    report = run_core(config, "steady", stimulus(config, rng, 200), seed=seed, channels=9, p_idle=0.2, p_ready=0.7)
    assert report["compared"] == 200 and report["extra"] == 0


@pytest.mark.parametrize("model", list(STAGE_MODELS))
def test_every_stage_table_cuts_between_steps(model):
    """Each of the loop's four stage tables, on the steps the model's core has (a second
    observation splits the last step in two): no stage without a step."""
    core = SteadyCore(STAGE_MODELS[model]())
    assert stage_table_faults(core) == []
    assert max(core.cuts) == len(core.steps)


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("preset", "variant"), PRESET_CASES)
def test_preset_cosimulation_is_bit_exact(preset, variant, simulator, seed):
    need(simulator)
    config = preset_config(preset)
    samples = 400 if variant == "full" else 1500
    result = run(build(simulator, "core", config=config, variant=variant, channels=3), "test_core", testcase="core_bit_exact",
                 params={"variant": variant, "seed": seed, "samples": samples, "channels": 3, "p_idle": 0.2,
                         "p_ready": 0.7, "config_toml": config.to_toml()}, tag=f"preset-{preset}-{variant}")
    assert result["mismatches"] == 0 and result["ok"], result.get("first_mismatches")
    assert result["samples"] == samples


def _two_observation_config(adc):
    _, params = registry.preset("va2")
    return FilterConfig(filter="kalman", params=dataclasses.replace(params, adc=adc))


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize("adc", [None, (3, 1)], ids=["A0-A1", "B1-A1"])
def test_board_with_two_observations_is_bit_exact(simulator, adc, seed):
    """The whole design for va2: both observations' ADC channels sampled at one instant, one
    update per conversion with both samples (in either channel order), every estimate equal."""
    need(simulator)
    config = _two_observation_config(adc)
    channels = list(config.spec.adc_channels(config.params))
    result = run(build(simulator, "top", config=config, variant="steady"), "test_top", testcase="system_bit_exact",
                 params={"variant": "steady", "seed": seed, "samples": 250, "adc": channels,
                         "channel": channels[0], "config_toml": config.to_toml()}, tag="two-observations")
    assert result["mismatches"] == 0 and result["ok"], result.get("first_mismatches")
    assert result["samples"] >= 250
    assert result["rmse_hw"] <= 1.05 * result["rmse_float"] < result["rmse_raw"]


def test_board_refuses_what_does_not_apply_to_two_observations():
    from kfpga.hw.top import FilterSystem

    config = _two_observation_config((3, 1))
    with pytest.raises(ValueError, match=r"^six channels of their own need a one-input filter; this model reads 2 "
                                         r"ADC channels per update$"):
        FilterSystem(config, six_channel=True)
    with pytest.raises(ValueError, match=r"^the model's adc = \[3, 1\] names the ADC channel\(s\) of its input\(s\); "
                                         r"channel 2 contradicts it$"):
        FilterSystem(config, channel=2)
    assert figures_only(FilterSystem(config)).adc == (3, 1)
    with pytest.raises(ValueError, match=r"^adc must be 2 different ADC channels 0..5 \(A0..C1\), one per "
                                         r"observation, not \(1, 1\)$"):
        _two_observation_config((1, 1))
