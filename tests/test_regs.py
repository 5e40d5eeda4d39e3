"""``kfpga regs`` and the register map: the settings for new Q/R in the core's formats, computed
independently here (the Riccati equation by scipy, the rounding by hand), the refusals, and the
map's SystemRDL, C header (gcc -fsyntax-only) and Markdown from ``generate --core-only --bus``."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from kfpga.core.config import FilterConfig
from kfpga.hw.microcode import DIGIT
from kfpga.hw.regmap import SETTINGS_BASE

ROOT = Path(__file__).resolve().parents[1]
TRACKER = ROOT / "examples" / "models" / "tracker.toml"


def kfpga(*argv, cwd=None):
    return subprocess.run([sys.executable, "-m", "kfpga", *argv], capture_output=True, text=True, check=False, cwd=cwd)


def _nearest(value, frac):
    """``value`` in units of 2**-frac, rounded to nearest (ties away from zero never arise here)."""
    return int(np.floor(value * 2.0**frac + 0.5))


def _value(digits):
    """A setting's integer from its digits (lower ones 17 bits, the top one signed 18)."""
    top = digits[-1] - (1 << 18) if digits[-1] & (1 << 17) else digits[-1]
    return sum(d << (DIGIT * k) for k, d in enumerate(digits[:-1])) + (top << (DIGIT * (len(digits) - 1)))


def test_the_steady_gain_for_new_q_and_r_is_the_riccati_equations_in_the_cores_format():
    run = kfpga("regs", "--config", str(TRACKER), "--set", "Q=[[0.25]]", "--set", "R=[[36.0]]", "--format", "json")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    f = np.array([[1.0, 0.01, 5e-5], [0.0, 1.0, 0.01], [0.0, 0.0, 1.0]])
    g, h = np.array([[0.0], [0.0], [1.0]]), np.array([[1.0, 0.0, 0.0]])
    prior = solve_discrete_are(f.T, h.T, g @ g.T * 0.25, np.array([[36.0]]))
    gain = prior @ h.T / (h @ prior @ h.T + 36.0)
    config = FilterConfig.from_toml(TRACKER)
    by_name = {s["name"]: s for s in out["settings"]}
    for i in range(3):
        s = by_name[f"K{i}0"]
        frac = config.formats[f"k{i + 1}"].frac_bits
        assert s["raw"] == _nearest(gain[i, 0], frac), s
        assert _value(s["digits"]) == s["raw"]
    # F is unchanged and its entries keep their integers; x0 is 0
    assert by_name["F01"]["raw"] == _nearest(0.01, config.formats["f12"].frac_bits)
    assert all(by_name[f"x{i}"]["raw"] == 0 for i in (1, 2, 3))
    # the writes: every digit at SETTINGS_BASE + its index, the commit last
    writes = out["writes"]
    assert [w["index"] for w in writes[:-1]] == list(range(SETTINGS_BASE, SETTINGS_BASE + len(writes) - 1))
    assert writes[-1] == {"index": 2, "offset": 8, "value": 1, "register": "CONTROL"}


def test_the_other_formats_carry_the_same_writes(tmp_path):
    table = kfpga("regs", "--set", "Q=1.0", "--set", "R=6.0")
    tcl = kfpga("regs", "--set", "Q=1.0", "--set", "R=6.0", "--format", "tcl", "--base", "0x8000")
    c = kfpga("regs", "--set", "Q=1.0", "--set", "R=6.0", "--format", "c", "--out", str(tmp_path / "s.h"))
    js = json.loads(kfpga("regs", "--set", "Q=1.0", "--set", "R=6.0", "--format", "json").stdout)
    assert table.returncode == tcl.returncode == c.returncode == 0, (table.stderr, tcl.stderr, c.stderr)
    for w in js["writes"]:
        assert f"master_write_32 $m 0x{0x8000 + w['offset']:X} 0x{w['value']:08X}" in tcl.stdout
        assert f"0x{w['offset']:04X}  0x{w['value']:08X}  {w['register']}" in table.stdout
        assert f"{{0x{w['offset']:08X}u, 0x{w['value']:08X}u}}" in (tmp_path / "s.h").read_text()
    if shutil.which("gcc"):
        assert subprocess.run(["gcc", "-fsyntax-only", str(tmp_path / "s.h")], check=False).returncode == 0


@pytest.mark.parametrize(("argv", "message"), [
    (["--set", "R=100"], "do not fit the core's formats"),
    (["--set", "W=1"], "--set W: the kalman2 filter's parameters are"),
    (["--set", "Q=abc"], "the value is not TOML"),
    (["--set", "Q"], "give NAME=VALUE"),
    (["--config", str(TRACKER), "--set", "F=[[1.0, 0.01, 5e-5], [0.0, 1.0, 0.01], [0.0, 0.5, 1.0]]"],
     "another shape than the core's"),
    (["--config", str(TRACKER), "--variant", "full", "--set", "G=[[0.0], [0.5], [1.0]]"],
     "another shape than the core's"),
])
def test_a_value_the_core_cannot_take_is_one_clear_line(argv, message):
    run = kfpga("regs", *argv)
    assert run.returncode == 2 and message in run.stderr and "Traceback" not in run.stderr, run.stderr
    assert len(run.stderr.strip().splitlines()) == 1


def test_generate_writes_the_register_map_and_its_header_compiles(tmp_path):
    out = tmp_path / "core"
    run = kfpga("generate", "--config", str(TRACKER), "--core-only", "--bus", "avalon", "--missing", "--out", str(out),
                "--no-lint", "--prefix", "trk")
    assert run.returncode == 0, run.stderr
    for name in ("trk_regs.rdl", "trk_regs.h", "trk_regs.md"):
        assert (out / name).is_file(), name
    manifest = json.loads((out / "manifest.json").read_text())
    names = [r["name"] for r in manifest["registers"]]
    header, table = (out / "trk_regs.h").read_text(), (out / "trk_regs.md").read_text()
    for r in manifest["registers"]:
        assert f"0x{r['offset']:02X}" in table and r["name"] in table
        assert f"TRK_REGS__{r['name']}" in header
    assert names[:7] == ["ID", "INFO", "CONTROL", "STATUS", "UPDATES", "OVERFLOWS", "COMMITTED"]
    assert "Register bus: Avalon-MM" in (out / "README.txt").read_text()
    assert manifest["bus_cost"]["logic_cells"] > 0 and manifest["missing"] is True
    if not shutil.which("gcc"):
        pytest.fail("gcc is not installed: the header cannot be checked (apt-get install gcc)")
    check = subprocess.run(["gcc", "-fsyntax-only", "-std=c11", "-Wall", "-Werror", str(out / "trk_regs.h")],
                           capture_output=True, text=True, check=False)
    assert check.returncode == 0, check.stderr


def test_bus_and_missing_do_not_apply_to_the_boards_design_or_a_filter_that_cannot_coast(tmp_path):
    run = kfpga("generate", "--bus", "avalon", "--out", str(tmp_path / "x"))
    assert run.returncode == 2 and "use it with --core-only" in run.stderr
    run = kfpga("generate", "--filter", "tukey53h", "--core-only", "--missing", "--out", str(tmp_path / "y"))
    assert run.returncode == 2 and "takes every sample as a measurement" in run.stderr
    run = kfpga("generate", "--core-only", "--bus", "axi4lite", "--architecture", "parallel", "--out",
                str(tmp_path / "z"))
    assert run.returncode == 2 and "folded" in run.stderr
    assert not any((tmp_path / n).exists() for n in ("x", "y", "z"))
