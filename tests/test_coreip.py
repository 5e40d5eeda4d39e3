# amaranth: UnusedElaboratable=no
"""The core in your own design: ``generate --core-only`` and ``testbench --core-only`` from the
command line, two filters' cores in one Verilog design on both simulators, the FuseSoC core file,
and the Amaranth example (``examples/amaranth_core.py``)."""

import json
import runpy
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from kfpga.cli import main
from kfpga.core.config import FilterConfig
from kfpga.flows.coreip import write_core
from kfpga.hw.tools import iverilog_path, verilator_env, verilator_root
from tests.helpers.simulators import need

ROOT = Path(__file__).parents[1]


def test_generate_core_only_writes_the_folder(tmp_path, capsys):
    out = tmp_path / "smooth"
    assert main(["generate", "--core-only", "--filter", "53h", "--prefix", "smooth", "--architecture", "parallel",
                 "--out", str(out), "--quiet"]) == 0
    names = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    manifest = json.loads((out / "manifest.json").read_text())
    assert names == manifest["files"]
    assert manifest["prefix"] == "smooth" and manifest["filter"] == "tukey53h" and manifest["modules"][0] == "smooth"
    assert '"smooth.v"' in (out / "smooth.qip").read_text()
    readme = (out / "README.txt").read_text()
    for port in ("clk", "rst", "i__valid", "i__ready", "i__payload", "o__valid", "o__ready", "o__payload", "overflow"):
        assert f"  {port} " in readme
    assert "latency:" in readme and "cycles per update:" in readme and "Handshake" in readme
    assert "module smooth" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--pins", "p.csv"], "--pins does not apply with --core-only"),
    (["--channel", "A1"], "--channel does not apply with --core-only"),
    (["--prefix", "module"], "--prefix module is a Verilog keyword"),
    (["--prefix", "9lives"], "--prefix must be a Verilog name"),
    (["--prefix", "a__b"], "no double underscore"),
    (["--channels", "9", "--variant", "full", "--architecture", "parallel"], "--channels 9: channels must be"),
], ids=["pins", "channel", "keyword", "digit", "double-underscore", "too-many-channels"])
def test_generate_core_only_refusals(tmp_path, capsys, argv, message):
    out = tmp_path / "core"
    assert main(["generate", "--core-only", *argv, "--out", str(out), "--quiet"]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_prefix_is_only_for_the_core(tmp_path, capsys):
    assert main(["generate", "--prefix", "k", "--out", str(tmp_path / "g")]) == 2
    assert "--prefix does not apply with the board's design" in capsys.readouterr().err


@pytest.mark.cosim
def test_testbench_core_only_runs_on_icarus(tmp_path, capsys, seed):
    need("icarus")
    out = tmp_path / "tb"
    code = main(["testbench", "--core-only", "--filter", "alphabeta", "--prefix", "ab", "--channels", "5",
                 "--architecture", "parallel", "--samples", "400", "--seed", str(seed), "--out", str(out),
                 "--run-icarus", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["icarus_exit"] == 0
    assert report["icarus_result"] == "PASS: ab: 400 estimates equal to the model, one per sample"


# -- two filters in one design --------------------------------------------------------------------------------

BOTH = """`timescale 1ns / 1ps
module both_tb;
    kf_tb #(.STANDALONE(0)) a ();
    smooth_tb #(.STANDALONE(0)) b ();
    always @(posedge a.clk) begin
        if (a.done && b.done) begin
            if (a.failed || b.failed) $display("FAIL: both: kf %0d, smooth %0d", a.failed, b.failed);
            else $display("PASS: both cores bit-exact in one design");
`ifdef __ICARUS__
            $finish_and_return((a.failed || b.failed) ? 1 : 0);
`else
            if (a.failed || b.failed) $stop;
            else $finish;
`endif
        end
    end
endmodule
"""


@pytest.fixture(scope="module")
def two_cores(tmp_path_factory):
    """kalman2 (prefix kf) and 53H (prefix smooth), their files in one folder with a testbench of both."""
    folder = tmp_path_factory.mktemp("both")
    for prefix, name in (("kf", "kalman2"), ("smooth", "tukey53h")):
        write_core(folder / prefix, FilterConfig(filter=name), variant=FilterConfig(filter=name).spec.default_variant,
                   prefix=prefix, channels=2, architecture="parallel", samples=300, seed=3)
        for path in [folder / prefix / f"{prefix}.v", *(folder / prefix / "tb").iterdir()]:
            if path.suffix in (".v", ".hex"):
                shutil.copy(path, folder)
    (folder / "both_tb.v").write_text(BOTH)
    return folder


SOURCES = ["kf.v", "smooth.v", "kf_tb.v", "smooth_tb.v", "both_tb.v"]


@pytest.mark.cosim
def test_two_filters_in_one_design_on_icarus(two_cores):
    need("icarus")
    exe = iverilog_path()
    subprocess.run([exe, "-g2001", "-o", "both.vvp", "-s", "both_tb", *SOURCES], cwd=two_cores, check=True,
                   capture_output=True, timeout=300)
    done = subprocess.run([str(Path(exe).with_name("vvp")), "-n", "both.vvp"], cwd=two_cores, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:]
    assert "PASS: kf: 300 estimates" in done.stdout and "PASS: smooth: 300 estimates" in done.stdout
    assert "PASS: both cores bit-exact in one design" in done.stdout


@pytest.mark.cosim
def test_two_filters_in_one_design_on_verilator(two_cores):
    need("verilator")
    root = verilator_root()
    cmd = [str(root / "bin" / "verilator"), "--binary", "--timing", "-CFLAGS", "-fcoroutines", "-Wno-fatal",
           "-Wno-lint", "-Wno-style", "--top-module", "both_tb", "-o", "both", *SOURCES]
    build = subprocess.run(cmd, cwd=two_cores, capture_output=True, text=True, env=verilator_env(), timeout=900)
    assert build.returncode == 0, (build.stdout + build.stderr)[-3000:]
    done = subprocess.run(["obj_dir/both"], cwd=two_cores, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:]
    assert "PASS: both cores bit-exact in one design" in done.stdout


# -- FuseSoC ---------------------------------------------------------------------------------------------------


@pytest.mark.cosim
def test_the_fusesoc_core_parses_and_its_icarus_target_passes(tmp_path):
    need("icarus")
    fusesoc = str(Path(sys.executable).with_name("fusesoc"))
    assert Path(fusesoc).exists(), "FuseSoC comes with the dev dependencies"
    write_core(tmp_path, FilterConfig(), variant="steady", prefix="kal", channels=2, architecture="parallel",
               samples=200, seed=2)
    env = {**verilator_env(), "PATH": f"{Path(iverilog_path()).parent}:{verilator_env()['PATH']}"}
    listed = subprocess.run([fusesoc, "--cores-root", ".", "core-info", "kfpga:cores:kal"], cwd=tmp_path,
                            capture_output=True, text=True, env=env, timeout=120)
    assert listed.returncode == 0 and "kfpga:cores:kal:1.0.0" in listed.stdout, listed.stderr[-1500:]
    ran = subprocess.run([fusesoc, "--cores-root", ".", "run", "--target", "sim", "kfpga:cores:kal"], cwd=tmp_path,
                         capture_output=True, text=True, env=env, timeout=600)
    assert ran.returncode == 0, (ran.stdout + ran.stderr)[-2000:]
    assert "PASS: kal: 200 estimates equal to the model" in ran.stdout


# -- Amaranth ----------------------------------------------------------------------------------------------------


def test_the_amaranth_example_runs():
    """``examples/amaranth_core.py``, as the manual shows it (docs/quartus-and-ip.md): the core inside an Amaranth design,
    every estimate the model's."""
    from kfpga.core.fixedmodel import FixedModel

    example = runpy.run_path(str(ROOT / "examples" / "amaranth_core.py"))
    got = example["simulate"]()
    want = FixedModel(example["CONFIG"], variant="steady").run(example["SAMPLES"]).outputs["x1"].tolist()
    assert got == want and len(got) == 40


def test_filter_core_refuses_what_it_cannot_build():
    from kfpga.hw.ip import filter_core

    core = filter_core(filter="alphabeta", channels=4)
    assert core.latency > 0 and "channel" in dict(core.i.payload.shape())
    with pytest.raises(ValueError, match="does not match"):
        filter_core(FilterConfig(), filter="alphabeta")


@pytest.mark.cosim
def test_the_board_fusesoc_file_synthesis_setup_and_simulation(tmp_path, capsys):
    """The board folder's kfpga_top.core: its Quartus target sets up a project with the device,
    the .sdc and the pins (Quartus itself is not run), and its sim target passes on Icarus."""
    need("icarus")
    out = tmp_path / "board"
    assert main(["generate", "--architecture", "parallel", "--out", str(out), "--quiet", "--no-lint"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert {"kfpga_top.core", "kfpga_top_pins.tcl", "tb/kfpga_tb.v"} <= set(manifest["files"])
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == manifest["files"]
    fusesoc = str(Path(sys.executable).with_name("fusesoc"))
    env = {**verilator_env(), "PATH": f"{Path(iverilog_path()).parent}:{verilator_env()['PATH']}"}
    setup = subprocess.run([fusesoc, "--cores-root", ".", "run", "--setup", "--target", "synth", "kfpga:board:kfpga_top"],
                           cwd=out, capture_output=True, text=True, env=env, timeout=300)
    assert setup.returncode == 0, setup.stderr[-1500:]
    tcl = "\n".join(p.read_text() for p in (out / "build").rglob("synth-quartus/*.tcl"))
    assert 'FAMILY "Cyclone II"' in tcl and "DEVICE EP2C20Q240C8" in tcl and "kfpga_top_pins.tcl" in tcl
    assert "kfpga_top.sdc" in tcl
    ran = subprocess.run([fusesoc, "--cores-root", ".", "run", "--target", "sim", "kfpga:board:kfpga_top"], cwd=out,
                         capture_output=True, text=True, env=env, timeout=900)
    assert ran.returncode == 0, (ran.stdout + ran.stderr)[-2000:]
    assert "PASS: 300 estimates equal to the model, 0 ADS8364 timing violations" in ran.stdout
