"""The layout: hw/, model/ and sim/ at the top, installed as kfpga.hw, kfpga.model and kfpga.sim
(``kfpga/hw``, ``kfpga/model`` and ``kfpga/sim`` link to them, for import-linter), and no tool
that walks the repository sees one of their files twice."""

import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("hw", "model", "sim")
BIN = Path(sys.executable).parent


def _once(paths, what):
    """Every path names a different file (symbolic links resolved)."""
    real = Counter(os.path.realpath(ROOT / p) for p in paths)
    twice = sorted(p for p, n in real.items() if n > 1)
    assert not twice, f"{what} sees these files twice: {twice[:5]}"


@pytest.mark.parametrize("layer", LAYERS)
def test_a_layer_is_imported_under_one_name(layer):
    """``import hw`` from the repository's root (which pytest puts on sys.path) is refused with
    the package's name, so no module runs twice under two names."""
    ok = subprocess.run([sys.executable, "-c", f"import kfpga.{layer}"], cwd=ROOT, capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    bad = subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, '.'); import {layer}"], cwd=ROOT,
                         capture_output=True, text=True)
    assert bad.returncode != 0 and f"import kfpga.{layer}, not {layer}" in bad.stderr, bad.stderr


@pytest.mark.parametrize("layer", LAYERS)
def test_the_links_are_the_layers(layer):
    link = ROOT / "kfpga" / layer
    assert link.is_symlink() and link.resolve() == (ROOT / layer).resolve()


def test_ruff_walks_each_file_once():
    out = subprocess.run([BIN / "ruff", "check", "--show-files", "."], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    files = [line.strip() for line in out.splitlines() if line.strip().endswith(".py")]
    assert any(Path(f).resolve() == (ROOT / "hw" / "folded.py").resolve() for f in files)
    _once(files, "ruff")


def test_grep_walks_each_file_once():
    """``grep -r`` (not ``-R``) follows no link below the folder it is given."""
    out = subprocess.run(["grep", "-rl", "--include=*.py", "def make_core", "hw", "kfpga"], cwd=ROOT,
                         capture_output=True, text=True).stdout.split()
    assert "hw/folded.py" in out
    _once(out, "grep -r")


def test_pytest_collects_only_the_tests():
    """The layers' folders hold no pytest tests (sim/test_*.py are cocotb modules); pytest walks
    neither them nor their links, and collects each test file once."""
    run = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", "."],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    files = {line.split("::")[0] for line in run.stdout.splitlines() if "::" in line}
    assert "tests/test_golden.py" in files
    outside = sorted(f for f in files if not f.startswith("tests/"))
    assert not outside, f"pytest collects outside tests/: {outside[:5]}"
    _once(files, "pytest")


def test_coverage_measures_each_file_once(tmp_path):
    """With the project's own settings (pyproject.toml), every layer is measured, under its folder."""
    data = tmp_path / "cov"
    subprocess.run([sys.executable, "-m", "coverage", "run", f"--data-file={data}", "-m", "kfpga", "filters"], cwd=ROOT,
                   capture_output=True, check=True)
    subprocess.run([sys.executable, "-m", "coverage", "json", f"--data-file={data}", "-o", str(tmp_path / "c.json")],
                   cwd=ROOT, capture_output=True, check=True)
    files = list(json.loads((tmp_path / "c.json").read_text())["files"])
    assert "model/kalman2.py" in files and "kfpga/core/spec.py" in files, files
    assert not [f for f in files if f.startswith(tuple(f"kfpga/{layer}/" for layer in LAYERS))]
    _once(files, "coverage")
