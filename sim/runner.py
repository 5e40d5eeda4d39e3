"""Build generated Verilog for Verilator or Icarus and run the cocotb benches on it.

Used by the pytest launcher (``tests/test_cosim.py``) and by ``kfpga simulate``. Builds are
cached under ``build/sim/<simulator>/<design>-<hash of the Verilog>``; a file lock keeps
parallel test workers from building the same design at once.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import threading
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from kfpga.core.config import FilterConfig
from kfpga.hw.generate import TOP_NAME, write_block, write_top
from kfpga.hw.tools import simulator_available, verilator_env, verilator_fst

__all__ = ["SIMULATORS", "Built", "build", "run", "SimulationFailed", "file_lock"]

SIMULATORS = ("verilator", "icarus")
DEFAULT_ROOT = Path("build") / "sim"


class SimulationFailed(AssertionError):
    """A cocotb test failed; the message carries the failures and the log's tail."""


@dataclass
class Built:
    simulator: str
    design: str
    toplevel: str
    build_dir: Path
    verilog: Path
    runner: object


def _design_verilog(out_dir, design, config, opts):
    """Write the Verilog of ``design`` into ``out_dir``; returns ``(path, toplevel)``."""
    if design == "top":
        path, _ = write_top(out_dir, config, variant=opts["variant"], six_channel=opts.get("six", False),
                            channel=opts.get("channel"), architecture=opts.get("architecture"), stages=opts.get("stages"))
        return path, TOP_NAME
    if design == "core":
        path, _ = write_block(out_dir, "core", config, variant=opts["variant"], channels=opts.get("channels", 1),
                              architecture=opts.get("architecture"),
                              **({"stages": opts["stages"]} if opts.get("stages") is not None else {}),
                              **{k: opts[k] for k in ("missing", "bus") if opts.get(k)})
    elif design == "divider":
        path, _ = write_block(out_dir, "divider", ratio=opts.get("ratio", 10))
    elif design == "frontend":
        path, _ = write_block(out_dir, "frontend", six_channel=opts.get("six", False), channel=opts.get("channel", 0))
    elif design == "restoring":
        path, _ = write_block(out_dir, "restoring", dividend_bits=opts["dividend_bits"],
                              divisor_bits=opts["divisor_bits"], quotient_bits=opts["quotient_bits"])
    else:
        raise ValueError(f"design must be top, core, divider, frontend or restoring, not {design!r}")
    return path, path.stem


@contextlib.contextmanager
def file_lock(path):
    """An exclusive lock on ``path`` for the block: parallel test workers build a design once."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def build(simulator, design, *, config=None, root=DEFAULT_ROOT, waves=False, quiet=True, verilog_text=None, **opts):
    """Generate ``design``'s Verilog and compile it for ``simulator`` (cached by content).

    ``verilog_text`` replaces the generated Verilog (same top level and ports), e.g. a mutant
    of it (``kfpga/verify/mutate.py``)."""
    from cocotb_tools.runner import VerilatorControlFile, get_runner

    ok, why = simulator_available(simulator)
    if not ok:
        raise FileNotFoundError(why)
    config = FilterConfig() if config is None else config
    root = Path(root).resolve()
    staging = root / "src" / f"{design}-{os.getpid()}"
    verilog, toplevel = _design_verilog(staging, design, config, opts)
    if verilog_text is not None:
        verilog.write_text(verilog_text)
    files = sorted(staging.glob("*.v"))
    digest = hashlib.sha1(b"".join(f.read_bytes() for f in files) + simulator.encode() + bytes([waves])).hexdigest()[:10]
    build_dir = root / simulator / f"{design}-{digest}"
    if simulator == "verilator":
        os.environ.update(verilator_env())
    with file_lock(root / simulator / f".{design}-{digest}.lock"):
        src = build_dir / "src"
        stamp = build_dir / ".built"
        if not stamp.exists():
            # a cached build keeps its sources untouched: newer copies would make the runner
            # compile again over the binary another worker is running
            src.mkdir(parents=True, exist_ok=True)
            for f in staging.iterdir():
                shutil.copy2(f, src / f.name)
        shutil.rmtree(staging, ignore_errors=True)
        verilog = src / verilog.name
        runner = get_runner(simulator)
        sources = [src / f.name for f in files]
        build_args = []
        if simulator == "verilator":
            sources.append(VerilatorControlFile(src / "verilator_lint.vlt"))
            build_args = ["-O3", "--x-assign", "fast", "--x-initial", "fast", "-Wno-fatal"]
            if waves and verilator_fst():  # FST, as Icarus writes: compressed, a tenth of the VCD's size
                build_args.append("--trace-fst")
        log = build_dir / "build.log"
        if not stamp.exists():
            runner.build(sources=sources, hdl_toplevel=toplevel, build_dir=build_dir, timescale=("1ns", "1ps"),
                         build_args=build_args, waves=waves, always=True, log_file=log if quiet else None)
            stamp.write_text("ok")
        else:
            # the runner needs its build state even when the binary is cached
            runner.build(sources=sources, hdl_toplevel=toplevel, build_dir=build_dir, timescale=("1ns", "1ps"),
                         build_args=build_args, waves=waves, always=False, log_file=log if quiet else None)
    return Built(simulator, design, toplevel, build_dir, verilog, runner)


def _results_xml(path):
    tree = ET.parse(path)
    failures = []
    total = 0
    for case in tree.iter("testcase"):
        total += 1
        for tag in ("failure", "error"):
            for node in case.iter(tag):
                failures.append(f"{case.get('name')}: {node.get('message') or ''}".strip())
    return total, failures


def run(built, test_module, *, params, testcase=None, waves=False, quiet=True, tag=None, on_progress=None):
    """Run cocotb tests of ``kfpga.sim.<test_module>`` on ``built``; returns the bench's results.

    ``params`` reach the bench as JSON (``KFPGA_SIM``); the result dict it writes comes back
    with ``tests`` (how many ran). Raises :class:`SimulationFailed` when a test fails.
    ``on_progress(n)`` is called from a watcher thread as the bench reports estimates out.
    """
    tag = tag or (testcase if isinstance(testcase, str) else test_module)
    test_dir = built.build_dir / "runs" / f"{tag}-{os.getpid()}"
    test_dir.mkdir(parents=True, exist_ok=True)
    results = test_dir / "results.json"
    results.unlink(missing_ok=True)
    params = dict(params, results=str(results))
    log = test_dir / "sim.log"
    xml = test_dir / "results.xml"
    env = {"KFPGA_SIM": json.dumps(params), "COCOTB_RESULTS_FILE": str(xml)}
    if built.simulator == "verilator":
        env.update({k: v for k, v in verilator_env().items() if k in ("VERILATOR_ROOT", "PATH")})
    started = time.time()
    pytest_var = os.environ.pop("PYTEST_CURRENT_TEST", None)  # the runner would sys.exit on failure
    stop = threading.Event()
    if on_progress:
        threading.Thread(target=_watch_progress, args=(Path(str(results) + ".progress"), on_progress, stop),
                         daemon=True).start()
    try:
        built.runner.test(test_module=f"kfpga.sim.{test_module}", hdl_toplevel=built.toplevel, hdl_toplevel_lang="verilog",
                          build_dir=built.build_dir, test_dir=test_dir, testcase=testcase, extra_env=env,
                          results_xml=str(xml), waves=waves, log_file=log if quiet else None)
    except SystemExit as exc:
        raise SimulationFailed(f"{built.simulator} exited with {exc.code}\n{_tail(log)}") from None
    except RuntimeError as exc:  # the runner's own words for a simulator that exited non-zero
        raise SimulationFailed(f"{built.simulator}/{built.design}: {exc}\n{_tail(log)}") from None
    finally:
        stop.set()
        if pytest_var is not None:
            os.environ["PYTEST_CURRENT_TEST"] = pytest_var
    total, failures = _results_xml(xml) if xml.exists() else (0, ["no results file"])
    if failures or total == 0:
        raise SimulationFailed(f"{built.simulator}/{built.design}: {'; '.join(failures) or 'no test ran'}\n{_tail(log)}")
    out = json.loads(results.read_text()) if results.exists() else {}
    out.update({"tests": total, "simulator": built.simulator, "log": str(log), "build_dir": str(built.build_dir)})
    if waves:
        # Verilator dumps into the run folder, Icarus next to its build: keep what this run wrote
        found = list(test_dir.rglob("*")) + list(built.build_dir.glob("*"))
        out["waves"] = sorted(str(p) for p in found if p.suffix in (".vcd", ".fst") and p.stat().st_mtime >= started)
    return out


def _watch_progress(path, callback, stop):
    last = -1
    while not stop.wait(0.5):
        try:
            n = int(path.read_text() or 0)
        except (OSError, ValueError):
            continue
        if n != last:
            callback(n)
            last = n


def _tail(path, lines=40):
    try:
        text = Path(path).read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join(text[-lines:])
