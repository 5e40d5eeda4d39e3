"""More sensors than the ADC's six: ``--channels N`` (2..256, not 6) puts N sensors on a
multiplexer in front of one ADC channel; the top selects sensor k mod N for conversion k, the
core keeps one state per sensor, and out_channel names the sensor.

The expected outputs here come from the model run on each sensor's samples alone, not from the
co-simulation's scoreboard; the hardware runs are bit-exact on both simulators, for the
parallel and the folded core, and the multiplexer select is checked at every HOLD."""

import json
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.core.board import MAX_CHANNELS, Board
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.ads8364_timing import check_rate
from kfpga.hw.top import port_widths
from kfpga.sim import system
from kfpga.sim.ads8364 import Read
from kfpga.sim.sources import scenario_source, sensor_source
from tests.helpers.simulators import need

AB100 = """[filter]
name = "alphabeta"
[model]
T = 0.01
[board]
sample_rate_hz = 100
"""


@pytest.fixture
def ab100(tmp_path):
    path = tmp_path / "ab100.toml"
    path.write_text(AB100)
    return path


# -- the arithmetic of the board and the ports ---------------------------------------------------


def test_port_widths_follow_the_sensors():
    assert "mux_sel" not in port_widths(1) and port_widths(1)["out_channel"][1] == 3
    for n, sel, channel in [(2, 1, 3), (6, 3, 3), (8, 3, 3), (9, 4, 4), (64, 6, 6), (65, 7, 7), (256, 8, 8)]:
        widths = port_widths(n)
        assert (widths["mux_sel"][1], widths["out_channel"][1]) == (sel, channel), n
    assert MAX_CHANNELS == 256


def test_the_timer_converts_each_sensor_at_the_rate():
    """N sensors at rate r: one conversion every clock / (r N) cycles, each sensor at r."""
    board = Board(sample_rate_hz=100.0)
    assert board.conversion_cycles(1) == 500_000 and board.conversion_cycles(64) == 7812
    assert board.actual_rate_hz(64) == pytest.approx(50e6 / 7812 / 64)
    assert abs(board.actual_rate_hz(64) / 100 - 1) < 1e-4
    check_rate(Board(sample_rate_hz=840.0), 1, 10, 256)  # 215 kSPS on one channel: within
    with pytest.raises(ValueError, match=r"256 sensors taking turns on one channel .* at most \d+(\.\d+)? Hz each"):
        check_rate(Board(sample_rate_hz=2000.0), 1, 10, 256)


def test_the_sensor_source_takes_turns():
    codes = np.arange(3 * 5).reshape(3, 5) * 10  # sensor s, sample j: 10 (5 s + j)
    source = sensor_source(codes, None, 2, name="t")
    column = np.array([source.next()[2] for _ in range(15)])
    assert column.tolist() == [codes[k % 3, k // 3] for k in range(15)]


def test_every_sensor_is_filtered_on_its_own():
    """The expected words of the testbench, for sensors on a multiplexer, against the model run
    on each sensor's samples alone."""
    from kfpga.sim.testbench import expected_words

    config = FilterConfig.from_dict(tomllib.loads(AB100))
    n, count = 7, 40
    source = scenario_source(config.spec.model.scenarios[0], n * count, 5, config.params, config=config, adc=[0], sensors=n)
    codes = np.array([source.next() for _ in range(n * count)], dtype=np.int64)

    class Top:
        six_channel, adc, channel, out_field = False, (0,), 0, config.spec.model.default_output

    channels, values, _ = expected_words(config, "steady", Top, codes, n * count, sensors=n)
    assert channels.tolist() == [k % n for k in range(n * count)]
    model = FixedModel(config, variant="steady")
    for s in range(n):
        alone = model.run(codes[s::n, 0]).outputs[Top.out_field]
        assert values[s::n].tolist() == alone.tolist(), s


def test_a_wrong_select_is_counted():
    records = system.SystemRecords.__new__(system.SystemRecords)
    records.sensors, records.resets = 3, []

    records.adc = SimpleNamespace(reads=[Read(float(k), 0, 0, k, sel) for k, sel in enumerate([0, 1, 2, 0, 2, 2, 0])])
    assert records.mux_errors() == 1  # the fifth read (k = 4) was sensor 1's turn


# -- the commands -------------------------------------------------------------------------------


def test_generate_with_sixteen_sensors(tmp_path, capsys, ab100):
    out = tmp_path / "gen"
    assert main(["generate", "--config", str(ab100), "--channels", "16", "--out", str(out), "--no-lint",
                 "--quiet"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["channels"] == 16 and manifest["sensors"] == 16
    assert manifest["sample_rate_hz"] == pytest.approx(100, rel=1e-4)
    ports = {p["name"]: p for p in manifest["ports"]}
    assert ports["mux_sel"]["width"] == 4 and ports["out_channel"]["width"] == 4
    assert len(set(ports["mux_sel"]["pins"])) == 4 and all(ports["mux_sel"]["pins"])
    qsf = (out / "kfpga_top.qsf").read_text()
    for b in range(4):
        assert f"-to mux_sel[{b}]" in qsf and f"-to out_channel[{b}]" in qsf
    verilog = (out / "kfpga_top.v").read_text()
    assert "output [3:0] mux_sel" in verilog.replace("wire ", "")
    assert "mux_sel" in (out / "README.txt").read_text()


@pytest.mark.parametrize("argv, message", [
    (["--channels", "256"], "no pin for mux_sel[5], mux_sel[6], mux_sel[7]"),
    (["--channels", "257"], "must be an integer 1..256, not 257"),
    (["--channels", "16", "--prefilter", "53h"], "a pre-filter keeps a state per ADC channel"),
], ids=["pins-run-out", "too-many", "prefilter"])
def test_generate_refusals(tmp_path, capsys, ab100, argv, message):
    out = tmp_path / "gen"
    try:
        code = main(["generate", "--config", str(ab100), *argv, "--out", str(out), "--quiet"])
    except SystemExit as exc:  # argparse
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_rate_the_adc_cannot_reach_with_the_sensors(tmp_path, capsys):
    path = tmp_path / "fast.toml"
    path.write_text(AB100.replace("sample_rate_hz = 100", "sample_rate_hz = 2000").replace("T = 0.01", "T = 0.0005"))
    for command in (["generate", "--out", str(tmp_path / "gen")], ["simulate", "--samples", "10"],
                    ["testbench", "--out", str(tmp_path / "tb")]):
        assert main([*command, "--config", str(path), "--channels", "200"]) == 2, command
        assert "200 sensors taking turns on one channel" in capsys.readouterr().err
    assert not (tmp_path / "gen").exists() and not (tmp_path / "tb").exists()


def test_pins_writes_a_table_to_complete(tmp_path, capsys):
    path = tmp_path / "pins.csv"
    assert main(["pins", "--channels", "256", "--write", str(path)]) == 0
    rows = [line.split(",") for line in path.read_text().splitlines()]
    missing = [(r[0], r[1]) for r in rows if r[0] == "mux_sel" and not r[2]]
    assert missing == [("mux_sel", "5"), ("mux_sel", "6"), ("mux_sel", "7")]
    assert "3 port bit(s) still need a pin" in capsys.readouterr().err


def test_simulate_refuses_what_has_no_multiplexer(capsys, ab100):
    for extra, message in [(["--adc-model", "python"], "the cocotb bench has no multiplexer"),
                           (["--glitches", "3"], "the glitches are counted per ADC channel")]:
        assert main(["simulate", "--config", str(ab100), "--channels", "8", "--samples", "10", *extra]) == 2
        assert message in capsys.readouterr().err


# -- the hardware -------------------------------------------------------------------------------

DESIGNS = {
    "kalman2-16": ("kalman2", 16, "parallel", {"verilator": 640, "icarus": 160}),
    "alphabeta-64-at-100Hz": ("alphabeta", 64, "parallel", {"verilator": 640, "icarus": 128}),
    "kalman2-9-folded": ("kalman2", 9, "folded", {"verilator": 270, "icarus": 90}),
}


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", ["verilator", "icarus"])
@pytest.mark.parametrize("design", list(DESIGNS))
def test_sensors_bit_exact(simulator, design, seed):
    """Every sensor's estimates equal the model's, each sensor filtered from reset on its own
    samples, the select right at every HOLD and out_channel naming the sensor."""
    need(simulator)
    name, n, architecture, samples = DESIGNS[design]
    samples = samples[simulator]
    config = (FilterConfig.from_dict(tomllib.loads(AB100)) if design.endswith("Hz") else FilterConfig(filter=name))
    built = system.build(simulator, config=config, variant=config.spec.default_variant, channel=0,
                         architecture=architecture, sensors=n)
    result = system.run(built, params={"seed": seed, "channel": 0}, samples=samples, timeout_s=900)
    assert result["mismatches"] == 0 and result["mux_errors"] == 0, result
    assert result["outputs"] == samples and result["adc_errors"] == 0
    assert result["ok"]


@pytest.mark.cosim
def test_testbench_with_sensors_passes_and_fails(tmp_path, capsys, seed):
    """The plain-Verilog testbench checks the select too: PASS as written; FAIL when it expects
    another sensor count, and when one expected word is off."""
    from kfpga.sim.testbench import run_icarus

    need("icarus")
    out = tmp_path / "tb"
    assert main(["testbench", "--filter", "alphabeta", "--channels", "12", "--samples", "120", "--seed", str(seed),
                 "--out", str(out)]) == 0
    assert json.loads((out / "testbench.json").read_text())["sensors"] == 12
    code, text = run_icarus(out, timeout_s=600)
    assert code == 0 and "PASS: 120 estimates equal to the model" in text, text[-2000:]
    tb = out / "kfpga_tb.v"
    good = tb.read_text()
    tb.write_text(good.replace("parameter integer SENSORS = 12;", "parameter integer SENSORS = 11;"))
    code, text = run_icarus(out, timeout_s=600)
    assert code == 1 and "multiplexer selects wrong" in text and "MUX conversion" in text
    tb.write_text(good)
    path = out / "expected.hex"
    lines = path.read_text().splitlines()
    lines[50] = f"{int(lines[50], 16) ^ (1 << 5):0{len(lines[50])}x}"  # a data bit of sensor 2's fifth estimate
    path.write_text("\n".join(lines) + "\n")
    code, text = run_icarus(out, timeout_s=600)
    assert code == 1 and "FAIL: 120 of 120 estimates checked, 1 mismatches" in text
