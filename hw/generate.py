"""Verilog-2001 from the Amaranth designs, with the lint waivers that go with it."""

from __future__ import annotations

import re
from pathlib import Path

from amaranth.back import verilog

from kfpga.hw.ads8364 import ADS8364Controller
from kfpga.hw.clockdiv import ClockDivider
from kfpga.hw.cores import make_core
from kfpga.hw.divider import Divider
from kfpga.hw.top import AdcFrontend, FilterSystem

__all__ = ["TOP_NAME", "LINT_WAIVERS", "figures_only", "finish_with_status", "to_verilog", "write_top", "write_block", "FORBIDDEN"]

TOP_NAME = "kfpga_top"

#: Verilator -Wall rules waived for the generated files, and why each is harmless.
LINT_WAIVERS = {
    "WIDTHEXPAND": "Amaranth types every operation exactly; Yosys's Verilog leaves the extension of a narrower "
                   "operand to the language (sign extension under $signed), which is value-preserving. The "
                   "co-simulation against the model proves the values.",
    "WIDTHTRUNC": "the narrowings are Amaranth's explicit slices (the low bits kept after saturation, a "
                  "remainder known to be below the divisor) and logical operators on multi-bit selects; none "
                  "drops a bit of a value that can be set",
    "UNUSEDSIGNAL": "unused bits of internal wires: upper bits of full-width products and sums, and payload "
                    "fields (x2, yhat) that the top level does not route to pins",
    "PROCASSINIT": "registers carry their power-up value in the declaration (reg r = init;) and are assigned "
                   "in always blocks: the FPGA power-up state, which Quartus honours",
    "CASEINCOMPLETE": "every case statement is preceded by a default assignment of the same variable, so no "
                      "latch is implied and an unlisted value keeps the default",
    "DECLFILENAME": "the submodules (kfpga_top__controller, ...) are written into the top's file on purpose: "
                    "one Verilog file per design for the Quartus project",
}

#: Constructs that must not appear in the synthesised Verilog (simulation-only or SystemVerilog).
FORBIDDEN = ("$display", "$finish", "$stop", "$random", "initial begin", "always_ff", "always_comb",
             "logic ", "`timescale", "#1", "assert property")


_ESCAPED_MODULE = re.compile(r"^module \\(\S+) ", re.MULTILINE)


def finish_with_status(indent="            "):
    """The Verilog that ends a self-checking testbench with its ``failed`` register as the exit
    status: ``$finish_and_return`` on Icarus, ``$stop`` (a non-zero exit) on Verilator when it
    failed, ``$finish`` elsewhere (ModelSim's script reads ``failed``)."""
    return "\n".join([
        "`ifdef __ICARUS__",
        f"{indent}$finish_and_return(failed ? 1 : 0);",
        "`elsif VERILATOR",
        f"{indent}if (failed) $stop;  // a $stop ends the run with a non-zero exit status",
        f"{indent}else $finish;",
        "`else",
        f"{indent}$finish;",
        "`endif",
    ])


def figures_only(elaboratable):
    """``elaboratable``, read for its figures only (latency, widths): not built, so Amaranth need
    not warn that it was never used (its ``MustUse`` flag), nor for the blocks it holds (a
    harness's ``dut``, a top level's frontend, core and pre-filter, and theirs)."""
    from amaranth.hdl import Elaboratable

    seen, todo = set(), [elaboratable]
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        obj._MustUse__silence = True
        todo += [v for v in vars(obj).values() if isinstance(v, Elaboratable)]
    return elaboratable


def to_verilog(elaboratable, name):
    """Verilog text of ``elaboratable`` as module ``name`` (no source locations: reproducible).

    Amaranth names submodules ``\\top.sub`` (escaped identifiers); they are renamed to plain
    identifiers (``top__sub``), the most conservative input for older synthesis tools.
    """
    return plain_module_names(verilog.convert(elaboratable, name=name, emit_src=False))


def plain_module_names(text):
    """Verilog ``text`` with Amaranth's escaped submodule names (``\\top.sub``) made plain (``top__sub``)."""
    for escaped in sorted(set(_ESCAPED_MODULE.findall(text)), key=len, reverse=True):
        plain = re.sub(r"[^A-Za-z0-9_]", "_", escaped.replace(".", "__"))
        text = text.replace(f"\\{escaped} ", f"{plain} ")
    return text


def write_lint_waivers(out_dir, file_glob):
    path = Path(out_dir) / "verilator_lint.vlt"
    lines = ["`verilator_config", "// Lint waivers (-Wall) for the generated Verilog: each rule and why it is harmless."]
    for rule, why in LINT_WAIVERS.items():
        lines += [f"// {rule}: {why}", f'lint_off -rule {rule} -file "{file_glob}"']
    path.write_text("\n".join(lines) + "\n")
    return path


def write_top(out_dir, config, *, variant=None, six_channel=False, channel=None, ratio=10, timeout_periods=40,
              out_field=None, prefilter=None, architecture=None, stages=None, sensors=1):
    """Write ``kfpga_top.v`` (and the lint waivers) into ``out_dir``; returns ``(verilog path, top)``.
    ``prefilter``: the config of a filter between the controller and the core, or ``None``;
    ``architecture``: the core's (default: the parallel one where it runs); ``sensors``: more than
    one on a multiplexer in front of the ADC (:class:`~kfpga.hw.top.FilterSystem`)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    top = FilterSystem(config, variant=variant, six_channel=six_channel, channel=channel, ratio=ratio,
                       timeout_periods=timeout_periods, out_field=out_field, prefilter=prefilter,
                       architecture=architecture, stages=stages, sensors=sensors)
    path = out_dir / f"{TOP_NAME}.v"
    path.write_text(to_verilog(top, TOP_NAME))
    write_lint_waivers(out_dir, f"*{TOP_NAME}.v")
    return path, top


def write_block(out_dir, block, config=None, **params):
    """Write one block on its own (for unit co-simulation): ``core``, ``divider`` (the clock
    divider), ``controller``, ``frontend`` (divider + controller with the board's ADC pin names)
    or ``restoring`` (the restoring divider of the time-varying core)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if block == "core":
        variant = params.pop("variant", None) or config.spec.default_variant
        dut = make_core(config, variant, **params)
    elif block == "divider":
        dut = ClockDivider(**params)
    elif block == "controller":
        dut = ADS8364Controller(**params)
    elif block == "frontend":
        dut = AdcFrontend(**params)
    elif block == "restoring":
        dut = Divider(**params)
    else:
        raise ValueError(f"block must be core, divider, controller, frontend or restoring, not {block!r}")
    name = f"kfpga_{block}"
    path = out_dir / f"{name}.v"
    path.write_text(to_verilog(dut, name))
    write_lint_waivers(out_dir, f"*{name}.v")
    return path, dut
