"""Co-simulation of the generated Verilog on Verilator and Icarus (cocotb, via cocotb_tools.runner).

Each test builds (once per content hash, under build/sim) and runs one cocotb bench from
``sim/``. A simulator that is not installed is skipped with the reason, except under CI
(``CI=true``), where both must run.
"""

import json
import os

import numpy as np
import pytest

from kfpga.sim import system
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.simulators import need

pytestmark = pytest.mark.cosim

#: Estimates per variant per simulator through the whole system (single channel), with the ADC
# model in the simulator (kfpga.sim.system); Icarus is about seventy times slower than Verilator.
# KFPGA_SYSTEM_SAMPLES sets both.
SYSTEM_SAMPLES = {"verilator": 100000, "icarus": 5000}
#: The same through the cocotb bench, whose Python ADC model reacts to every pin edge.
PYTHON_ADC_SAMPLES = {"verilator": 1000, "icarus": 300}
if os.environ.get("KFPGA_SYSTEM_SAMPLES"):
    SYSTEM_SAMPLES = dict.fromkeys(SYSTEM_SAMPLES, int(os.environ["KFPGA_SYSTEM_SAMPLES"]))


def check(result, samples=None):
    assert result["mismatches"] == 0, result.get("first_mismatches")
    assert result.get("ok", True), result
    if samples is not None:
        assert result["samples"] >= samples, result


@pytest.fixture(params=SIMULATORS)
def simulator(request):
    need(request.param)
    return request.param


# -- the cores alone (backpressure and channels: tests/contract) --------------------------


@pytest.mark.parametrize(("variant", "samples", "channels", "cycles"), [("steady", 5000, 4, 1), ("full", 3000, 1, 25)])
def test_core_full_rate(simulator, variant, samples, channels, cycles, seed):
    """Valid every cycle, ready every cycle: the core's own rate, every estimate exact.

    The steady core with its four loop stages takes a sample per clock from four channels in
    turn; the time-varying core, one update per 25 cycles.
    """
    result = run(build(simulator, "core", variant=variant, channels=channels), "test_core", testcase="core_bit_exact",
                 params={"variant": variant, "seed": seed, "samples": samples, "channels": channels,
                         "order": "round-robin"})
    print(f"{result['samples_per_s']:.0f} samples/s on {simulator}")
    check(result, samples)
    assert round(result["cycles_per_sample"], 2) == cycles


def _core_words(config, n, channels, seed, order):
    from kfpga.sim.sources import stress_codes

    rng = np.random.default_rng(seed + 2)
    chans = np.arange(n) % channels if order == "round-robin" else rng.integers(0, channels, n)
    names = config.inputs
    cols = {name: stress_codes(seed + 7 * j, n) for j, name in enumerate(names)}
    return [{"channel": int(c), **{name: int(cols[name][i]) for name in names}} for i, c in enumerate(chans)]


@pytest.mark.parametrize(("variant", "channels", "cycles", "samples"),
                         [("steady", 4, 1, {"verilator": 200000, "icarus": 20000}),
                          ("full", 1, 25, {"verilator": 20000, "icarus": 2000})], ids=["steady-4ch", "full"])
def test_core_in_simulator_full_rate(simulator, variant, channels, cycles, samples, seed):
    """The core with its stream source and sink in the simulator (kfpga.sim.corerun): the same
    checks as the cocotb bench, at the simulator's speed."""
    from kfpga.core.config import FilterConfig
    from kfpga.sim import corerun

    config = FilterConfig()
    built = corerun.build(simulator, config=config, variant=variant, channels=channels)
    n = samples[simulator]
    result = corerun.run(built, words=_core_words(config, n, channels, seed, "round-robin"), seed=seed)
    print(f"{result['samples_per_s']:.0f} samples/s on {simulator}")
    check(result, n)
    assert round(result["cycles_per_sample"], 2) == cycles
    assert result["sticky_at_start"] == 0 and result["sticky_at_end"] == [result["sticky_expected"]] * 4


@pytest.mark.parametrize(("variant", "channels"), [("steady", 4), ("full", 1)], ids=["steady-4ch", "full"])
def test_core_in_simulator_backpressure(simulator, variant, channels, seed):
    """Random idle cycles and backpressure; the channel states in random order."""
    from kfpga.core.config import FilterConfig
    from kfpga.sim import corerun

    config = FilterConfig()
    built = corerun.build(simulator, config=config, variant=variant, channels=channels)
    n = 20000 if simulator == "verilator" else 2000
    result = corerun.run(built, words=_core_words(config, n, channels, seed, "random"), seed=seed, p_idle=0.3,
                         p_ready=0.6)
    check(result, n)
    assert result["cycles_per_sample"] > 1.5  # the idle cycles and the backpressure happened


def test_core_in_simulator_sees_a_wrong_model(seed):
    """The in-simulator core path can fail: the model told another R differs."""
    need("verilator")
    from kfpga.core.config import FilterConfig
    from kfpga.sim import corerun

    built = corerun.build("verilator", config=FilterConfig(), variant="steady", channels=4)
    other = FilterConfig.from_dict({"model": {"R": 2.0}}, source="test")
    result = corerun.run(built, words=_core_words(FilterConfig(), 500, 4, seed, "round-robin"), seed=seed,
                         config=other)
    assert result["mismatches"] > 0 and not result["ok"]


# -- clock divider, controller -------------------------------------------------------------


@pytest.mark.parametrize("ratio", [10, 7])
def test_clock_divider(simulator, ratio, seed):
    result = run(build(simulator, "divider", ratio=ratio), "test_clockdiv", params={"seed": seed, "ratio": ratio})
    assert result["strobe_periods"] == [ratio]


def test_restoring_divider_alone(simulator, seed):
    """The time-varying core's divider at its widths: every quotient and flag against integer
    division, operands on the overflow boundary, divisor 0 and 1, backpressure."""
    from kfpga.verify.formal import divider_widths

    widths = divider_widths()
    n = 3000 if simulator == "verilator" else 1500
    result = run(build(simulator, "restoring", **widths), "test_restoring",
                 params={**widths, "seed": seed, "samples": n})
    assert result["mismatches"] == 0 and result["samples"] == n
    assert 0 < result["overflows"] < n


@pytest.mark.parametrize("six", [False, True], ids=["1ch", "6ch"])
def test_controller_pin_protocol(simulator, six, seed):
    result = run(build(simulator, "frontend", six=six, channel=3), "test_ads8364", testcase="pin_protocol",
                 params={"seed": seed, "samples": 60, "six": six, "channel": 3})
    assert result["mismatches"] == 0 and result["samples"] == 60


@pytest.mark.parametrize("six", [False, True], ids=["1ch", "6ch"])
def test_controller_missing_eoc_times_out(simulator, six, seed):
    result = run(build(simulator, "frontend", six=six, channel=3), "test_ads8364", testcase="missing_eoc_times_out",
                 params={"seed": seed, "samples": 60, "six": six, "channel": 3})
    assert result["mismatches"] == 0 and result["timeout_flag"] == 1 and result["eocs_dropped"] == 1


@pytest.mark.parametrize("six", [False, True], ids=["1ch", "6ch"])
def test_controller_stuck_eoc_is_no_conversion(simulator, six, seed):
    """EOC stuck low: no word without a falling edge, the timeout flag, and reads again after."""
    result = run(build(simulator, "frontend", six=six, channel=3), "test_ads8364", testcase="stuck_eoc_is_no_conversion",
                 params={"seed": seed, "samples": 60, "six": six, "channel": 3})
    assert result["mismatches"] == 0 and result["timeout_flag"] == 1 and result["words_while_stuck"] == 0
    assert result["samples"] >= 40


@pytest.mark.parametrize("six", [False, True], ids=["1ch", "6ch"])
def test_controller_ready_does_not_pace_the_conversions(simulator, six, seed):
    """ready low at random while the output is empty: the conversions keep their own rate."""
    result = run(build(simulator, "frontend", six=six, channel=3), "test_ads8364",
                 testcase="ready_does_not_pace_the_conversions", params={"seed": seed, "six": six, "channel": 3})
    assert result["mismatches"] == 0 and abs(result["conversions"] - result["expected_conversions"]) <= 1


# -- the whole design ----------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.parametrize("variant", ["steady", "full"])
def test_system_bit_exact(simulator, variant, seed):
    """100,000 estimates per variant on Verilator, 5,000 on Icarus, through divider + controller
    + core, with the Verilog ADS8364 model checking every timing figure."""
    samples = SYSTEM_SAMPLES[simulator]
    result = system.run(system.build(simulator, variant=variant, channel=1), params={"seed": seed, "channel": 1},
                        samples=samples)
    print(f"{result['samples']} estimates, {result['wall_s']:.1f} s on {simulator}")
    check(result, samples)
    assert result["outputs"] == samples and result["adc_errors"] == 0
    assert result["conversions"] >= samples and result["reads"] >= samples
    assert result["rmse_hw"] <= 1.01 * result["rmse_float"]


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_system_bit_exact_python_adc(simulator, variant, seed):
    """The same through the cocotb bench and the Python ADS8364 model: the two ADC models and the
    two ways of running agree on the same design."""
    samples = PYTHON_ADC_SAMPLES[simulator]
    result = run(build(simulator, "top", variant=variant, channel=1), "test_top", testcase="system_bit_exact",
                 params={"variant": variant, "seed": seed, "samples": samples, "channel": 1})
    check(result, samples)


def test_system_stress_codes_and_pins(simulator, seed):
    """Codes over every bit and both extremes (``stress_codes`` on all six channels) through the
    whole design, and the pins the ADC model does not read: each HOLD pulse one CLK period, the
    unused HOLDs high, BYTE and ADD low, WR high (``sim/test_top.py``, ``check_pins``)."""
    result = run(build(simulator, "top", variant="steady", channel=1), "test_top", testcase="system_bit_exact",
                 params={"variant": "steady", "seed": seed, "samples": 120, "channel": 1, "scenario": "stress"},
                 tag="stress")
    assert result["mismatches"] == 0 and result["ok"] and result["samples"] >= 120


def test_reset_release_latency(simulator):
    """rst_n released at every phase of the ADC clock: the first action 3..12 cycles after the
    first edge that sees it, one cycle apart (the synchroniser's stages, on the right edge)."""
    result = run(build(simulator, "top", variant="steady", channel=1), "test_top", testcase="reset_release_latency",
                 params={"variant": "steady", "seed": 1, "channel": 1}, tag="reset-latency")
    assert sorted(result["delays_cycles"]) == [float(3 + k) for k in range(10)]


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_system_six_channels(simulator, variant, seed):
    samples = 30000 if simulator == "verilator" else 3000
    result = system.run(system.build(simulator, variant=variant, six=True), params={"seed": seed}, samples=samples)
    check(result, samples)
    # each channel settles on its own: the figures skip every channel's start, not the stream's
    assert result["settle_per_channel"] == (100 if simulator == "verilator" else 50)
    assert result["rmse_hw"] <= 1.01 * result["rmse_float"] < result["rmse_raw"]
    assert abs(result["reads"] - 6 * result["conversions"]) <= 6  # six reads per conversion


def test_fast_regression_sees_a_wrong_model(seed):
    """The fast path can fail: the design built with R = 0.5, the model told R = 2, differ."""
    need("verilator")
    from kfpga.core.config import FilterConfig

    built = system.build("verilator", config=FilterConfig(), variant="steady", channel=1)
    other = FilterConfig.from_dict({"model": {"R": 2.0}}, source="test")
    result = system.run(built, params={"seed": seed, "channel": 1, "config_toml": other.to_toml()}, samples=500)
    assert result["mismatches"] > 0 and not result["ok"]


def test_fast_regression_stops_at_the_cycle_limit(seed, monkeypatch):
    """A design that stops answering ends the run with the reason, not a hang."""
    need("icarus")
    built = system.build("icarus", variant="steady", channel=1)
    monkeypatch.setattr(system, "cycle_budget", lambda built, records, samples: 2000)
    with pytest.raises(system.SystemRunFailed, match="cycle limit"):
        system.run(built, params={"seed": seed, "channel": 1}, samples=50)


@pytest.mark.parametrize("case", ["reset_mid_conversion", "reset_mid_update", "missing_eoc_times_out_and_recovers",
                                  "glitch_sample"])
@pytest.mark.parametrize("variant", ["steady", "full"])
def test_system_robustness(simulator, variant, case, seed):
    result = run(build(simulator, "top", variant=variant, channel=1), "test_top", testcase=case,
                 params={"variant": variant, "seed": seed, "channel": 1}, tag=case)
    check(result)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_simulate_command_json(variant, capsys, seed):
    """`kfpga simulate --json` on both variants: one JSON object, mismatches 0, exit code 0."""
    need("verilator")
    from kfpga.cli import main

    code = main(["simulate", "--variant", variant, "--samples", "300", "--seed", str(seed), "--json", "--quiet"])
    out = capsys.readouterr().out
    result = json.loads(out)
    assert code == 0
    assert {"samples", "mismatches", "simulator", "variant", "seed", "wall_s"} <= set(result)
    assert (result["mismatches"], result["samples"], result["variant"], result["seed"]) == (0, 300, variant, seed)


def test_simulate_waves(simulator, capsys, monkeypatch, tmp_path):
    """--waves leaves an FST waveform under build/waves, from either simulator."""
    from kfpga.cli import main

    monkeypatch.chdir(tmp_path)  # build/ of this test, not of the checkout
    code = main(["simulate", "--simulator", simulator, "--samples", "20", "--seed", "5", "--adc-model", "python",
                 "--waves", "--json",
                 "--quiet"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0 and result["mismatches"] == 0
    assert len(result["waves"]) == 1
    wave = tmp_path / result["waves"][0]
    assert wave.parent == tmp_path / "build" / "waves"
    from kfpga.hw.tools import verilator_fst

    if simulator == "icarus" or verilator_fst():
        assert wave.suffix == ".fst" and wave.stat().st_size > 1000  # FST is compressed binary
    else:  # no lz4 headers: Verilator writes VCD (and simulate says why)
        assert wave.suffix == ".vcd" and "adc_rd_n" in wave.read_text(errors="replace")[:200000]
