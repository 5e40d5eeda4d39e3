"""`kfpga testbench`: the self-checking Verilog-2001 testbench passes on Icarus, and fails,
with a non-zero exit status, when the expected file or the stimulus is wrong."""

import re
import subprocess

import pytest

from kfpga.cli import main
from kfpga.sim.testbench import TB_NAME, run_icarus
from tests.helpers.simulators import need

pytestmark = pytest.mark.cosim


def write(tmp_path, seed, *extra, samples=300):
    out = tmp_path / "tb"
    code = main(["testbench", "--out", str(out), "--samples", str(samples), "--seed", str(seed), *extra])
    assert code == 0
    return out


@pytest.mark.parametrize("extra", [["--variant", "steady", "--channel", "C1"], ["--variant", "full", "--channels", "6"]],
                         ids=["steady-C1", "full-6ch"])
def test_testbench_passes_on_icarus(tmp_path, seed, extra):
    need("icarus")
    out = write(tmp_path, seed, *extra)
    code, text = run_icarus(out, timeout_s=600)
    assert code == 0, text[-2000:]
    assert "PASS: 300 estimates equal to the model, 0 ADS8364 timing violations" in text
    assert "MISMATCH" not in text and "ADS8364 timing:" not in text


def test_testbench_fails_on_a_corrupted_expected_file(tmp_path, seed):
    need("icarus")
    out = write(tmp_path, seed)
    path = out / "expected.hex"
    lines = path.read_text().splitlines()
    k = 137
    lines[k] = f"{int(lines[k], 16) ^ 1:0{len(lines[k])}x}"  # one LSB of one estimate
    path.write_text("\n".join(lines) + "\n")
    code, text = run_icarus(out, timeout_s=600)
    assert code == 1, text[-2000:]
    assert re.search(r"MISMATCH estimate 137 ", text)
    assert "FAIL: 300 of 300 estimates checked, 1 mismatches" in text


def test_testbench_fails_on_other_codes(tmp_path, seed):
    """The expected file goes with its codes: other codes give other estimates."""
    need("icarus")
    out = write(tmp_path, seed)
    path = out / "codes.hex"
    words = path.read_text().splitlines()
    words[6 * 50] = f"{(int(words[6 * 50], 16) + 4000) & 0xFFFF:04x}"  # channel A0 of conversion 50
    path.write_text("\n".join(words) + "\n")
    code, text = run_icarus(out, timeout_s=600)
    assert code == 1 and "FAIL" in text


def test_testbench_script_and_plain_verilog(tmp_path, seed):
    need("icarus")
    out = write(tmp_path, seed, "--run-icarus", samples=100)
    tb = (out / f"{TB_NAME}.v").read_text()
    for construct in ("logic ", "always_ff", "always_comb", "$fatal", "assert property"):
        assert construct not in tb
    do = (out / "run_modelsim.do").read_text()
    assert "vlib work" in do and "vsim -c" in do and "run -all" in do and "quit -f -code 1" in do
    done = subprocess.run([str(out / "run_icarus.sh")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "PASS: 100 estimates" in done.stdout
    assert {"README.txt", "codes.hex", "expected.hex", "kfpga_top.v", "ads8364_model.v", "testbench.json"} <= {
        p.name for p in out.iterdir()}


def test_testbench_bad_arguments(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main(["testbench", "--out", str(tmp_path / "file")]) == 2
    assert "is a file; give a folder" in capsys.readouterr().err
    assert main(["testbench", "--out", str(tmp_path / "x"), "--channels", "6", "--channel", "A1"]) == 2
    assert "--channel does not apply with --channels 6" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["testbench", "--samples", "5"])
    assert exc.value.code == 2
