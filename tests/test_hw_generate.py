"""Generated Verilog: Verilator -Wall clean (with explained waivers), Icarus -g2001, plain Verilog-2001."""

import re

import pytest

from kfpga.cli import main
from kfpga.core.config import FilterConfig
from kfpga.hw.generate import FORBIDDEN, LINT_WAIVERS, TOP_NAME, write_block, write_top
from kfpga.hw.tools import iverilog_parse, iverilog_path, verilator_lint
from kfpga.hw.top import PORTS

DESIGNS = [("steady", False), ("full", False), ("steady", True), ("full", True)]


@pytest.fixture(scope="module", params=DESIGNS, ids=lambda d: f"{d[0]}-{'6ch' if d[1] else '1ch'}")
def top_verilog(request, tmp_path_factory):
    variant, six = request.param
    out = tmp_path_factory.mktemp(f"gen_{variant}_{six}")
    path, top = write_top(out, FilterConfig(), variant=variant, six_channel=six, channel=None if six else 3)
    return path, top


def test_verilator_lint_clean_with_explained_waivers(top_verilog):
    path, _ = top_verilog
    waivers = path.parent / "verilator_lint.vlt"
    rc, out = verilator_lint(path, TOP_NAME, waivers)
    assert rc == 0, out
    text = waivers.read_text()
    for rule, reason in LINT_WAIVERS.items():
        assert f"lint_off -rule {rule}" in text and reason in text
    # nothing but the waived rules comes up without the waivers
    rc, out = verilator_lint(path, TOP_NAME)
    rules = set(re.findall(r"%Warning-([A-Z0-9]+):", out))
    assert rules <= set(LINT_WAIVERS), rules - set(LINT_WAIVERS)


def test_icarus_parses_as_verilog_2001(top_verilog):
    if iverilog_path() is None:
        pytest.skip("iverilog not installed (Debian: apt-get install iverilog)")
    path, _ = top_verilog
    rc, out = iverilog_parse(path, TOP_NAME)
    assert rc == 0, out


def test_plain_verilog_no_simulation_constructs(top_verilog):
    path, _ = top_verilog
    text = path.read_text()
    for construct in FORBIDDEN:
        assert construct not in text, construct
    assert not re.search(r"^module \\", text, re.MULTILINE), "escaped module names"
    assert re.search(rf"^module {TOP_NAME}\(", text, re.MULTILINE)


def test_ports_are_the_documented_pins(top_verilog):
    path, top = top_verilog
    text = path.read_text()
    header = re.search(rf"^module {TOP_NAME}\((.*?)\);", text, re.MULTILINE | re.DOTALL)[1]
    names = {p.strip() for p in header.split(",")}
    assert names == set(PORTS)
    width = top.config.output_format(top.out_field).width
    for name, (direction, bits, _) in PORTS.items():
        bits = width if name == "out_data" else bits
        decl = "input" if direction == "in" else "output"
        vector = rf"\[{bits - 1}:0\] " if bits > 1 else ""
        pattern = rf"^  {decl} {vector}{name};"
        assert re.search(pattern, text, re.MULTILINE), (name, pattern)


@pytest.mark.parametrize(("block", "kwargs"), [
    ("core", {"variant": "steady"}), ("core", {"variant": "full", "channels": 6}),
    ("divider", {"ratio": 10}), ("controller", {"six_channel": True}),
])
def test_blocks_lint_clean(tmp_path, block, kwargs):
    path, _ = write_block(tmp_path, block, FilterConfig() if block == "core" else None, **kwargs)
    rc, out = verilator_lint(path, path.stem, tmp_path / "verilator_lint.vlt")
    assert rc == 0, out


def test_generate_command(tmp_path, capsys):
    assert main(["generate", "--variant", "full", "--out", str(tmp_path), "--channels", "6"]) == 0
    out = capsys.readouterr().out
    assert "verilator --lint-only -Wall: clean" in out
    assert (tmp_path / f"{TOP_NAME}.v").exists()
