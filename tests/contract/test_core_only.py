# amaranth: UnusedElaboratable=no
"""The core in your own design, for every registered filter on every architecture: the folder of
``generate --core-only`` (``kfpga/flows/coreip.py``) has every module named with the prefix, a
datasheet whose ports are the Verilog's, and a self-checking testbench that passes on Icarus and
fails on a wrong expected word."""

import json
import re
import subprocess
from pathlib import Path

import pytest
from test_contract import HW_CASES, samples_for

from kfpga.core.config import FilterConfig
from kfpga.flows.coreip import write_core
from tests.helpers.simulators import need


def run_core_tb(folder, timeout_s=900):
    from kfpga.hw.tools import iverilog_path

    path = f"{Path(iverilog_path()).parent}:/usr/bin:/bin"
    done = subprocess.run(["sh", "run_icarus.sh"], cwd=folder / "tb", capture_output=True, text=True,
                          env={"PATH": path}, timeout=timeout_s)
    return done.returncode, done.stdout + done.stderr


@pytest.mark.cosim
@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_core_only_folder_passes_its_testbench(name, variant, architecture, tmp_path, seed):
    need("icarus")
    config = FilterConfig(filter=name)
    prefix = f"p{seed % 1000}_{name}"
    n = min(samples_for(config, variant, 300, 3, architecture), 300)
    manifest = write_core(tmp_path, config, variant=variant, prefix=prefix, channels=3, architecture=architecture,
                          samples=n, seed=seed)
    text = (tmp_path / f"{prefix}.v").read_text()
    modules = re.findall(r"^module (\S+?)\(", text, re.M)
    assert modules and all(m == prefix or m.startswith(prefix + "__") for m in modules)
    top = text[text.index(f"module {prefix}("):]
    top = top[: top.index("endmodule")]
    ports = re.findall(r"^\s*(input|output)\s+(?:\[(\d+):0\]\s+)?(\w+);", top, re.M)
    declared = {p["name"]: (p["direction"], p["width"]) for p in manifest["ports"]}
    assert {name: (d, int(w) + 1 if w else 1) for d, w, name in ports} == declared
    assert json.loads((tmp_path / "manifest.json").read_text())["latency_cycles"] == manifest["latency_cycles"]
    code, out = run_core_tb(tmp_path)
    assert code == 0 and f"PASS: {prefix}: {n} estimates equal to the model" in out, out[-2000:]
    path = tmp_path / "tb" / f"{prefix}_expected.hex"
    lines = path.read_text().splitlines()
    lines[n // 2] = f"{int(lines[n // 2], 16) ^ 2:0{len(lines[n // 2])}x}"  # one bit of one estimate
    path.write_text("\n".join(lines) + "\n")
    code, out = run_core_tb(tmp_path)
    assert code == 1 and f"FAIL: {prefix}: {n} of {n} estimates, 1 mismatches" in out, out[-2000:]
