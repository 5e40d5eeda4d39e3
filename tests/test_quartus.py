"""The Quartus project: .qsf and .sdc well-formed and complete, pin table checks, manifest, resources."""

import json
import re
import shlex

import pytest

from kfpga.cli import main
from kfpga.core import registry
from kfpga.core.config import FilterConfig
from kfpga.flows.quartus import PinError, load_pins, port_bits, write_project
from kfpga.hw.cores import make_core
from kfpga.hw.resources import estimate
from kfpga.hw.tools import iverilog_parse, iverilog_path
from kfpga.hw.top import PORTS
from kfpga.model.reference import KalmanParams

#: The timing goal of the auto-chosen designs: the estimate 1.25 x the board's 50 MHz.
GOAL_MHZ = 62.5


def qsf_assignments(text):
    """(kind, name, value, target) for each assignment line of a .qsf."""
    out = []
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        words = shlex.split(line)
        if words[0] == "set_location_assignment":
            out.append(("location", None, words[1], words[words.index("-to") + 1]))
        elif words[0] in ("set_global_assignment", "set_instance_assignment"):
            name = words[words.index("-name") + 1]
            target = words[words.index("-to") + 1] if "-to" in words else None
            value = words[words.index("-name") + 2]
            out.append((words[0].split("_")[1], name, value, target))
        else:
            raise AssertionError(f"unexpected .qsf line: {line}")
    return out


def sdc_commands(text):
    """Commands of a .sdc with their arguments ([get_ports {...}] expanded to port names)."""
    cmds = []
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        ports = []
        for group in re.findall(r"\[get_ports \{([^}]*)\}\]", line):
            ports += group.split()
        cmds.append((line.split()[0], line, ports))
    return cmds


def expand(pattern_list, config):
    """Port bits named by SDC patterns (``name`` or ``name[*]``)."""
    names = set()
    for p in pattern_list:
        names.add(p[:-3] if p.endswith("[*]") else p)
    return names


@pytest.fixture(scope="module", params=["steady", "full"])
def project(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"q_{request.param}")
    config = FilterConfig()
    manifest = write_project(out, config, variant=request.param)
    return out, config, manifest


def test_qsf_device_family_top_sources(project):
    out, _, _ = project
    a = qsf_assignments((out / "kfpga_top.qsf").read_text())
    globals_ = {name: value for kind, name, value, _ in a if kind == "global"}
    assert globals_["FAMILY"] == "Cyclone II"
    assert globals_["DEVICE"] == "EP2C20Q240C8"
    assert globals_["TOP_LEVEL_ENTITY"] == "kfpga_top"
    assert (out / globals_["VERILOG_FILE"]).exists() and (out / globals_["SDC_FILE"]).exists()
    assert (out / "kfpga_top.qpf").read_text().count('PROJECT_REVISION = "kfpga_top"') == 1


def test_every_port_bit_has_exactly_one_pin_and_no_pin_twice(project):
    out, config, _ = project
    a = qsf_assignments((out / "kfpga_top.qsf").read_text())
    locations = [(target, pin) for kind, _, pin, target in a if kind == "location"]
    targets = [t for t, _ in locations]
    pins = [p for _, p in locations]
    expected = {p if b is None else f"{p}[{b}]" for p, b in port_bits(config)}
    assert sorted(targets) == sorted(expected)  # every bit once, nothing else
    assert len(pins) == len(set(pins))
    assert all(re.fullmatch(r"PIN_\d+", p) for p in pins)
    standards = {t: v for kind, name, v, t in a if kind == "instance" and name == "IO_STANDARD"}
    assert set(standards) == expected and set(standards.values()) == {"3.3-V LVTTL"}


def test_sdc_constrains_every_clock_and_port(project):
    out, config, _ = project
    cmds = sdc_commands((out / "kfpga_top.sdc").read_text())
    clocks = [line for c, line, _ in cmds if c == "create_clock"]
    assert len(clocks) == 1 and "-period 20.000" in clocks[0] and "{clk50}" in clocks[0]
    generated = [line for c, line, _ in cmds if c == "create_generated_clock"]
    assert len(generated) == 1 and "-divide_by 10" in generated[0] and "{adc_clk}" in generated[0]
    inputs = set().union(*(expand(p, config) for c, _, p in cmds if c == "set_input_delay"))
    false_from = set().union(*(expand(p, config) for c, _, p in cmds if c == "set_false_path"))
    outputs = set().union(*(expand(p, config) for c, _, p in cmds if c == "set_output_delay"))
    for name, (direction, _, _) in PORTS.items():
        if name == "clk50":
            continue
        if direction == "in":
            assert name in inputs | false_from, name
        elif name != "adc_clk":  # the generated clock's target
            assert name in outputs, name
    # -max and -min for every delayed port
    for kind in ("set_input_delay", "set_output_delay"):
        for flag in ("-max", "-min"):
            covered = set().union(*(expand(p, config) for c, line, p in cmds if c == kind and flag in line))
            assert covered == (inputs if kind == "set_input_delay" else outputs)


def test_sdc_multicycle_only_on_the_enabled_capture_with_its_reason(project):
    out, _, _ = project
    text = (out / "kfpga_top.sdc").read_text()
    cmds = sdc_commands(text)
    multi = [(line, ports) for c, line, ports in cmds if c == "set_multicycle_path"]
    assert {tuple(p) for _, p in multi} == {("adc_data[*]",)}
    # captured on the strobe that ends READ1, 9 system cycles after RD fell (RD moves one cycle
    # after its strobe)
    assert any("-setup" in line and line.rstrip().endswith(" 9") for line, _ in multi)
    assert any("-hold" in line and line.rstrip().endswith(" 8") for line, _ in multi)
    before = text[: text.index("set_multicycle_path")]
    assert "clock enable" in before.splitlines()[-2] + before.splitlines()[-1]


def test_sdc_numbers_come_from_the_datasheet_table(project):
    out, _, _ = project
    text = (out / "kfpga_top.sdc").read_text()
    # tACC 40 ns + the RD output budget (half of 20 ns) + 2 ns of board
    assert "set_input_delay -clock clk50 -max 52.000 [get_ports {adc_data[*]}]" in text
    assert "tD9 = 10 ns" in text and "tC1 = 200 ns" in text


def test_project_verilog_parses_as_verilog_2001(project):
    if iverilog_path() is None:
        pytest.skip("iverilog not installed (Debian: apt-get install iverilog)")
    out, _, _ = project
    rc, text = iverilog_parse(out / "kfpga_top.v", "kfpga_top")
    assert rc == 0, text


def test_manifest(project):
    out, config, manifest = project
    again = json.loads((out / "manifest.json").read_text())
    assert again == manifest
    assert manifest["device"] == "EP2C20Q240C8" and manifest["device_ordering_code"] == "EP2C20Q240C8N"
    assert manifest["formats"]["x1"]["format"] == str(config.formats["x1"])
    assert {p["name"] for p in manifest["ports"]} == set(PORTS)
    assert manifest["core"]["cycles_per_update"] == (4 if manifest["variant"] == "steady" else 25)
    assert manifest["generator"]["kfpga"]
    assert set(manifest["files"]) <= {p.name for p in out.iterdir()}
    assert "quartus_sh --flow compile kfpga_top" in (out / "README.txt").read_text()


def write_table(path, rows):
    path.write_text("port,bit,pin,io_standard,note\n" + "\n".join(rows) + "\n")
    return path


def default_rows():
    return [line for line in (load_pins.__globals__["_constraint_file"]("pins.csv").read_text().splitlines())
            if line and not line.startswith("#")][1:]


@pytest.mark.parametrize(("edit", "message"), [
    (lambda rows: rows[:-1], r"no pin for out_timeout"),
    (lambda rows: [*rows, "out_data,40,PIN_200,3.3-V LVTTL,"], r"line \d+: the design has no port bit out_data\[40\]"),
    (lambda rows: [rows[0], *rows[1:-1], "out_timeout,,PIN_34,3.3-V LVTTL,"], r"PIN_34 is already used by clk50"),
    (lambda rows: [*rows[:-1], "out_timeout,,P37,3.3-V LVTTL,"], r"pin must look like PIN_37, not 'P37'"),
    (lambda rows: [*rows, rows[-1].replace("PIN_168", "PIN_200")], r"out_timeout already has PIN_168"),
])
def test_pin_table_errors_name_the_line(tmp_path, edit, message):
    table = write_table(tmp_path / "pins.csv", edit(default_rows()))
    with pytest.raises(PinError, match=message):
        write_project(tmp_path / "out", FilterConfig(), variant="steady", pins=table)


def test_generate_command_with_bad_pins_is_one_line(tmp_path, capsys):
    table = write_table(tmp_path / "pins.csv", default_rows()[:-2])
    code = main(["generate", "--out", str(tmp_path / "o"), "--pins", str(table), "--no-lint"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "no pin for out_overflow, out_timeout" in err


def test_ratio_too_fast_for_the_adc_is_refused(tmp_path):
    with pytest.raises(PinError, match=r"--ratio 8 makes the ADC clock 6.25 MHz; the ADS8364 allows 5 MHz"):
        write_project(tmp_path, FilterConfig(), variant="steady", ratio=8)


@pytest.mark.slow
def test_resource_report_is_consistent(tmp_path, capsys):
    """Runs Yosys on both parallel cores; the time-varying one must need more of everything."""
    assert main(["resources", "--variant", "steady", "--architecture", "parallel", "--json", "--quiet"]) == 0
    steady = json.loads(capsys.readouterr().out)
    assert main(["resources", "--variant", "full", "--architecture", "parallel", "--json", "--quiet"]) == 0
    full = json.loads(capsys.readouterr().out)
    for r in (steady, full):
        assert {"variant", "luts", "ffs", "mul18", "mul9", "lut_levels", "logic_cells"} <= set(r)
        assert r["luts"] >= r["logic_cells"] - r["ffs"] > 0 and r["ffs"] > 0
        assert r["lut_levels"] <= r["lut_levels_no_carry"]
        assert r["longest_path_ends_at"], "the report names where the longest path ends"
        assert r["whole_design"]["logic_cells"] > r["logic_cells"]  # the ADC front end costs something
    for r in (steady, full):  # the timing goal: 1.25 x 50 MHz estimated on the -8 part, core and whole design
        assert r["fmax_mhz_estimate"] >= GOAL_MHZ and r["whole_design"]["fmax_mhz_estimate"] >= GOAL_MHZ, r["worst_path"]
        assert r["worst_path"]["start"] and r["worst_path"]["end"] and r["worst_path"]["steps"]
        assert all(p["delay_ns"] <= p["budget_ns"] for p in r["whole_design"]["timing"]["io_paths"])
    assert steady["mul18"] < full["mul18"]
    assert steady["logic_cells"] < full["logic_cells"] and steady["ffs"] < full["ffs"]
    # the multipliers the designs have: K1 e, K2 e; and those plus K1 pl11, K1 pl12, K2 pl11, K2 pl12
    assert (steady["mul18"], full["mul18"]) == (2, 6)


@pytest.mark.slow
def test_t_not_a_power_of_two_costs_one_multiplier(tmp_path):
    from kfpga.hw.generate import write_block

    path, _ = write_block(tmp_path, "core", FilterConfig(params=KalmanParams(T=0.3)), variant="steady")
    assert estimate(path, path.stem)["mul18"] == 3


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["steady", "full"])
def test_six_channels_meet_the_timing_goal(variant, capsys):
    assert main(["resources", "--variant", variant, "--channels", "6", "--json", "--quiet"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["fmax_mhz_estimate"] >= GOAL_MHZ and r["whole_design"]["fmax_mhz_estimate"] >= GOAL_MHZ
    assert r["all_goals_met"], {k: m for k, m in r["goals_met"].items() if not m}


@pytest.mark.slow
def test_ecp5_place_and_route_agrees_the_loop_is_short(capsys):
    """A real place-and-route on another family: the pipelined steady core runs well above 50 MHz."""
    assert main(["resources", "--variant", "steady", "--architecture", "parallel", "--ecp5", "--json", "--quiet"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["ecp5_fmax_mhz"] > 75 and r["whole_design"]["ecp5_fmax_mhz"] > 75


@pytest.mark.slow
@pytest.mark.parametrize("name", ["roll", "lsfront"])
def test_the_folded_cores_meet_their_goals(capsys, name):
    """The square-root roll predictor and the least-squares front end on the folded core:
    within one 50 MHz cycle on the -8 part (their goal: an update every half second or every
    second needs no more), the multiplier's blocks, the program and registers in block memory."""
    assert main(["resources", "--filter", name, "--json", "--quiet"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["all_goals_met"], {k: m for k, m in r["goals_met"].items() if not m}
    assert r["fmax_mhz_estimate"] >= 50 and r["whole_design"]["fmax_mhz_estimate"] >= 50
    # one 18x18 multiplier; block memory holds the register file (18-bit words) and a program word a step
    spec = registry.get(name)
    program = make_core(FilterConfig(filter=name), spec.default_variant, architecture="folded").program
    assert r["mul18"] == 1 and r["memory_bits"] > 18 * program.depth + len(program.words)
