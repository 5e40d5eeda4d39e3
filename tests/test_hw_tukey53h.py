# amaranth: UnusedElaboratable=no
"""The 53H smoother's core (hw/tukey53h.py) against the bit-accurate model: any channel order, one
sample per clock, the threshold, angles and wide inputs on both simulators, and the board's
pre-filter with ADC glitches."""

import json

import numpy as np
import pytest
from test_model_tukey53h import ANGLE, CONFIG, LATITUDE, _heading, _latitude, glitchy

from kfpga.cli import main
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.cores import make_core
from kfpga.model import tukey53h as th
from kfpga.sim.amaranth_streams import measure_timing, run_core
from tests.helpers.simulators import core_is_bit_exact_on, need


@pytest.mark.parametrize("channels", [1, 2, 6, 8])
def test_core_bit_exact_any_channel_order_with_backpressure(channels, seed):
    rng = np.random.default_rng(seed)
    report = run_core(CONFIG, "online", glitchy(rng, 1200), seed=seed, channels=channels, p_idle=0.2, p_ready=0.6)
    assert report["compared"] == 1200 and report["mismatches"] == 0


def test_core_takes_one_sample_per_clock_of_the_same_channel():
    dut = make_core(CONFIG, "online", channels=6)
    latency, accepted, produced = measure_timing(dut, CONFIG)
    assert dut.cycles_per_update == 1 and set(accepted) == {1} and set(produced) == {1}
    assert latency == dut.latency == 15


def test_core_refuses_channel_counts():
    with pytest.raises(ValueError, match="channels must be an integer 1..8"):
        make_core(CONFIG, "online", channels=0)
    with pytest.raises(ValueError, match="channels must be an integer 1..8"):
        make_core(CONFIG, "online", channels=9)


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", ["verilator", "icarus"])
@pytest.mark.parametrize("six", [False, True])
def test_prefilter_removes_adc_glitches_bit_exact(simulator, six, seed):
    """The whole design with the pre-filter, full-scale glitches injected in the ADC model's codes:
    every estimate equals the model chain (53H, then the Kalman filter); no glitch gets past the
    pre-filter, no estimate strays; without it, they do."""
    from kfpga.sim import system

    need(simulator)
    pre = FilterConfig(filter="tukey53h")
    samples = 1800 if simulator == "verilator" else 600
    params = {"seed": seed, "glitch": True, "glitches": 6}
    built = system.build(simulator, config=FilterConfig(), six=six, prefilter=pre)
    r = system.run(built, params=params, samples=samples, tag=f"prefilter-{six}")
    assert r["ok"] and r["mismatches"] == 0 and r["samples"] == samples, r.get("first_mismatches")
    assert r["glitches_in_reads"] >= 1 and r["glitches_after_prefilter"] == 0
    assert r["estimates_off_by_more_than_bound"] == 0
    if not six:
        bare = system.run(system.build(simulator, config=FilterConfig()), params=params, samples=samples, tag="bare")
        assert bare["mismatches"] == 0 and bare["estimates_off_by_more_than_bound"] > 0


def test_prefilter_that_could_overflow_is_refused():
    from kfpga.core.fixed import QFormat
    from kfpga.hw.top import FilterSystem

    narrow = FilterConfig(filter="tukey53h", formats={"x": QFormat(12, 0)}, check_ranges=False)
    with pytest.raises(ValueError, match="can overflow"):
        FilterSystem(FilterConfig(), prefilter=narrow)
    with pytest.raises(ValueError, match="pre-filter must be one of tukey53h"):
        FilterSystem(FilterConfig(), prefilter=FilterConfig(filter="alphabeta"))


def test_scoreboard_models_the_chain():
    from kfpga.sim.scoreboard import Scoreboard

    rng = np.random.default_rng(5)
    x = glitchy(rng, 200)
    board = Scoreboard(FilterConfig(), "steady", prefilter=CONFIG)
    got = board.expected([(0, int(v)) for v in x])["x1"]
    want = FixedModel(FilterConfig()).run(FixedModel(CONFIG).run(x).y).x1
    assert np.array_equal(got, want)


@pytest.mark.parametrize("channels", [1, 2])
def test_core_decides_at_the_threshold(channels, seed):
    """Spikes of |d| = threshold - 2 .. threshold + 2, either sign, on held levels (where the
    smoothed value is the level): replaced exactly where |d| > threshold, by the core as by the
    model (an absolute value or a comparison a few codes off decides some the other way)."""
    from kfpga.sim.sources import threshold_codes

    t = CONFIG.params.threshold
    y = threshold_codes(seed, 600, t)
    spikes = np.arange(6, 600, 12)
    d = y[spikes] - y[spikes - 1]
    out = FixedModel(CONFIG).run(y).outputs["y"]
    np.testing.assert_array_equal(out[spikes + th.DELAY] != y[spikes], np.abs(d) > t)  # [Lu]'s test
    assert (d < -t).any() and (d > t).any() and (np.abs(d) <= t).any()
    run_core(CONFIG, "online", y, seed=seed, channels=channels, p_idle=0.2, p_ready=0.6)  # every output the model's


@pytest.mark.parametrize("channels", [1, 3])
def test_angle_core_bit_exact(channels, seed):
    rng = np.random.default_rng(seed)
    h = np.concatenate([_heading(seed, 300), glitchy(rng, 300)])
    report = run_core(ANGLE, "online", h, seed=seed, channels=channels, p_idle=0.2, p_ready=0.6)
    assert report["compared"] == 600 and report["mismatches"] == 0


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", ["verilator", "icarus"])
def test_angle_core_bit_exact_in_cocotb(simulator, seed):
    """The generated Verilog with a turn (an angle), two channels, on both simulators: every integer the model's."""
    h = _heading(seed, 400)
    core_is_bit_exact_on(simulator, ANGLE, "online", h, seed, "53h-angle", channels=2)


def test_wide_inputs_are_refused_on_the_board(tmp_path, capsys):
    cfg = tmp_path / "lat.toml"
    cfg.write_text('[filter]\nname = "53h"\n\n[model]\nthreshold = 1349\ninput_bits = 32\n')
    assert main(["generate", "--config", str(cfg), "--out", str(tmp_path / "board"), "--quiet"]) == 2
    assert "input_bits = 32: the board's ADS8364 gives 16-bit codes" in capsys.readouterr().err
    assert not (tmp_path / "board").exists()
    assert main(["generate", "--config", str(cfg), "--core-only", "--out", str(tmp_path / "core"), "--quiet"]) == 0
    manifest = json.loads((tmp_path / "core" / "manifest.json").read_text())
    assert "32" in json.dumps(manifest)


@pytest.mark.parametrize("channels", [1, 2])
def test_wide_core_bit_exact(channels, seed):
    lat, _ = _latitude(seed, 400)
    report = run_core(LATITUDE, "online", lat, seed=seed, channels=channels, p_idle=0.2, p_ready=0.6)
    assert report["compared"] == 400 and report["mismatches"] == 0


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", ["verilator", "icarus"])
def test_wide_core_bit_exact_in_cocotb(simulator, seed):
    """The generated Verilog with 32-bit inputs, a latitude in 1e-7 deg, on both simulators."""
    lat, _ = _latitude(seed, 400)
    core_is_bit_exact_on(simulator, LATITUDE, "online", lat, seed, "53h-wide", channels=2)
