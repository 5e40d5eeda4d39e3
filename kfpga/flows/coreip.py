"""The filter core alone, for your own design (``kfpga generate --core-only``, ``kfpga testbench
--core-only``).

The folder holds:

* ``PREFIX.v``: the core in Verilog-2001, module ``PREFIX`` and every submodule ``PREFIX__...``,
  so that several cores (other filters, other configs) coexist in one project;
* ``PREFIX.qip``: the Quartus file list (add it to a project: Project > Add/Remove Files);
* ``PREFIX.core``: a FuseSoC core file (CAPI2): the RTL fileset, and a ``sim`` target running the
  self-checking testbench on Icarus (default) or Verilator;
* ``tb/``: the testbench (``PREFIX_tb.v``, ``PREFIX_stimulus.hex``, ``PREFIX_expected.hex``, ``run_icarus.sh``,
  ``run_modelsim.do``): samples with random gaps on the input, a receiver ready with random
  gaps on the output, every estimate compared with the bit-accurate model's word, one line
  ``PASS: ...`` or ``FAIL: ...`` and an exit status;
* ``manifest.json`` and ``README.txt``: the datasheet (ports, payload fields and their formats,
  the handshake, latency, cycles per update, reset, overflow).

:func:`interface` describes the ports from the core itself, so the datasheet cannot drift from
the Verilog.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import re
from pathlib import Path

import numpy as np

from kfpga import __version__
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.cores import make_core
from kfpga.hw.generate import figures_only, finish_with_status, to_verilog, write_lint_waivers

__all__ = ["check_prefix", "interface", "write_core", "write_core_testbench", "core_icarus_command", "fusesoc_core",
           "VERILOG_KEYWORDS"]

#: Verilog-2001 reserved words: a prefix must not be one.
VERILOG_KEYWORDS = frozenset((
    "always", "and", "assign", "automatic", "begin", "buf", "bufif0", "bufif1", "case", "casex", "casez",
    "cell", "cmos", "config", "deassign", "default", "defparam", "design", "disable", "edge", "else", "end",
    "endcase", "endconfig", "endfunction", "endgenerate", "endmodule", "endprimitive", "endspecify", "endtable",
    "endtask", "event", "for", "force", "forever", "fork", "function", "generate", "genvar", "highz0", "highz1",
    "if", "ifnone", "incdir", "include", "initial", "inout", "input", "instance", "integer", "join", "large",
    "liblist", "library", "localparam", "macromodule", "medium", "module", "nand", "negedge", "nmos", "nor",
    "noshowcancelled", "not", "notif0", "notif1", "or", "output", "parameter", "pmos", "posedge", "primitive",
    "pull0", "pull1", "pulldown", "pullup", "pulsestyle_onevent", "pulsestyle_ondetect", "rcmos", "real",
    "realtime", "reg", "release", "repeat", "rnmos", "rpmos", "rtran", "rtranif0", "rtranif1", "scalared",
    "showcancelled", "signed", "small", "specify", "specparam", "strong0", "strong1", "supply0", "supply1",
    "table", "task", "time", "tran", "tranif0", "tranif1", "tri", "tri0", "tri1", "triand", "trior", "trireg",
    "unsigned", "use", "uwire", "vectored", "wait", "wand", "weak0", "weak1", "while", "wire", "wor", "xnor",
    "xor"
))

#: The receiver's ready in the testbench: high on READY_PER_1024 of 1024 cycles (an LFSR draws it).
READY_PER_1024 = 717
#: The share of the testbench's samples marked missing on a core with the missing bit.
MISSING_SHARE = 0.2


def check_prefix(prefix):
    """``prefix`` if it can name the core's modules (``ValueError`` naming the rule otherwise)."""
    if not isinstance(prefix, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,39}", prefix):
        raise ValueError(f"--prefix must be a Verilog name: a letter or _, then letters, digits or _, at most 40 "
                         f"characters, not {prefix!r}")
    if prefix in VERILOG_KEYWORDS:
        raise ValueError(f"--prefix {prefix} is a Verilog keyword; choose another name")
    if "__" in prefix:
        raise ValueError(f"--prefix {prefix}: no double underscore (the submodules are named PREFIX__NAME)")
    return prefix


def _fields(port):
    """``[(name, offset, width, signed)]`` of a stream port's payload, LSB first."""
    layout = port.signature.members["payload"].shape
    out = []
    for name, field in layout:
        shape = field.shape
        out.append((name, field.offset, field.width, bool(getattr(shape, "signed", False))))
    return out


def interface(config, core):
    """The core's ports: ``[{name, direction, width, description, fields?}]``, every payload field
    with its bit range and format (the one Verilog port ``i__payload`` packs them LSB first)."""
    fmt = {o.name: config.output_format(o.name) for o in config.outputs}
    notes = {"channel": "channel (state) number, 0..channels-1; an input beyond the last gives a zero state's "
                        "estimate and changes nothing",
             "overflow": "this estimate saturated somewhere in its update (the sample's own flag)",
             "missing": "1: this sample has no measurement (its codes are not read): the update only predicts"}

    def fields(port, output):
        rows = []
        for name, offset, width, signed in _fields(port):
            if name in fmt and output:
                what, form = f"estimate {name}", str(fmt[name])
            elif name in config.inputs:
                what, form = f"input {name}: a signed 16-bit ADC code", "Q16.0"
            else:
                what, form = notes.get(name, name), f"unsigned {width} bit(s)"
            rows.append({"name": name, "bits": f"[{offset + width - 1}:{offset}]", "offset": offset, "width": width,
                         "signed": signed, "format": form, "description": what})
        return rows

    i_width = sum(f[2] for f in _fields(core.i))
    o_width = sum(f[2] for f in _fields(core.o))
    return [
        {"name": "clk", "direction": "input", "width": 1, "description": "clock; everything on its rising edge"},
        {"name": "rst", "direction": "input", "width": 1,
         "description": "synchronous reset, active high: every channel's state to its reset value, the streams "
                        "empty, the overflow flag cleared"},
        {"name": "i__valid", "direction": "input", "width": 1, "description": "a sample is on i__payload"},
        {"name": "i__ready", "direction": "output", "width": 1,
         "description": "the core takes the sample on this edge if i__valid is high"},
        {"name": "i__payload", "direction": "input", "width": i_width, "description": "the sample",
         "fields": fields(core.i, False)},
        {"name": "o__valid", "direction": "output", "width": 1, "description": "an estimate is on o__payload"},
        {"name": "o__ready", "direction": "input", "width": 1,
         "description": "the receiver takes the estimate on this edge if o__valid is high"},
        {"name": "o__payload", "direction": "output", "width": o_width, "description": "the estimate",
         "fields": fields(core.o, True)},
        {"name": "overflow", "direction": "output", "width": 1,
         "description": "sticky: some estimate since reset saturated (or wrapped, in a wrap format)"},
        *_bus_ports(core),
    ]


#: What each bus port does (Avalon-MM slave ``avs_*``, AXI4-Lite slave ``s_axil_*``).
BUS_PORTS = {
    "avs_address": "word address (byte offset / 4) of the register (README: register map)",
    "avs_write": "write the register at avs_address", "avs_writedata": "the value written",
    "avs_read": "read the register at avs_address", "avs_readdata": "the value read, with avs_readdatavalid",
    "avs_readdatavalid": "avs_readdata holds the value read (the cycle after the read)",
    "avs_waitrequest": "hold the write: a setting waits for the register file's write port, or for a commit",
    "s_axil_awaddr": "write address (bytes)", "s_axil_awprot": "unused", "s_axil_awvalid": "write address valid",
    "s_axil_awready": "write address and data taken (together)", "s_axil_wdata": "the value written",
    "s_axil_wstrb": "unused: every write is a whole register", "s_axil_wvalid": "write data valid",
    "s_axil_wready": "write address and data taken (together)", "s_axil_bresp": "OKAY (0)",
    "s_axil_bvalid": "write response", "s_axil_bready": "write response taken",
    "s_axil_araddr": "read address (bytes)", "s_axil_arprot": "unused", "s_axil_arvalid": "read address valid",
    "s_axil_arready": "read address taken", "s_axil_rdata": "the value read", "s_axil_rresp": "OKAY (0)",
    "s_axil_rvalid": "read data valid (the cycle after the address is taken, held until taken)",
    "s_axil_rready": "read data taken",
}


def _bus_ports(core):
    """The register bus's ports of a programmable core (none without one)."""
    out = []
    for name, member in core.signature.members.items():
        if name in BUS_PORTS:
            out.append({"name": name, "direction": "input" if member.flow.name == "In" else "output",
                        "width": member.shape.width if hasattr(member.shape, "width") else int(member.shape),
                        "description": BUS_PORTS[name]})
    return out


def _bus_ties(core):
    """The testbench's connections of the bus ports: inputs held at 0, outputs open."""
    return "".join(f", .{p['name']}({p['width']}'d0)" if p["direction"] == "input" else f", .{p['name']}()"
                   for p in _bus_ports(core))


def _make(config, variant, channels, architecture, stages, missing=False, bus=None):
    options = {"architecture": architecture, **({} if stages is None else {"stages": stages}),
               **({"missing": True} if missing else {}), **({"bus": bus} if bus else {})}
    return make_core(config, variant, channels=channels, **options)


def write_core(out_dir, config, *, variant, prefix, channels=1, architecture=None, stages=None, samples=500, seed=1,
               scenario=None, timing=None, missing=False, bus=None, bus_cost=None):
    """Write the core-only folder (see the module's text) into ``out_dir``; returns the manifest.
    ``missing``, ``bus``: the folded core's no-measurement bit and register bus (then its map,
    ``PREFIX_regs.rdl``, ``.h``, ``.md``, too); ``bus_cost``: the bus's figures, for the datasheet."""
    check_prefix(prefix)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    core = _make(config, variant, channels, architecture, stages, missing, bus)
    text = to_verilog(core, prefix)
    modules = re.findall(r"^module (\S+?)\(", text, re.M)
    stray = [m for m in modules if m != prefix and not m.startswith(prefix + "__")]
    if stray:  # every module must carry the prefix, or two cores could clash
        raise AssertionError(f"modules without the prefix {prefix}: {', '.join(stray)}")
    (out_dir / f"{prefix}.v").write_text(text)
    write_lint_waivers(out_dir, f"*{prefix}.v")
    (out_dir / f"{prefix}.qip").write_text(
        f"# Quartus II file list of the {config.filter} core {prefix} (kfpga {__version__}):\n"
        f"# add this file to a project (Project > Add/Remove Files in Project)\n"
        f'set_global_assignment -name VERILOG_FILE [file join $::quartus(qip_path) "{prefix}.v"]\n')
    tb = write_core_testbench(out_dir / "tb", config, variant=variant, prefix=prefix, channels=channels,
                              architecture=architecture, stages=stages, samples=samples, seed=seed, scenario=scenario,
                              missing=missing, bus=bus)
    regmap = []
    if bus:
        from kfpga.hw.regmap import export

        regmap = [p.name for p in export(core.regs, out_dir, f"{prefix}_regs")]
    architecture = getattr(core, "architecture", architecture) or config.spec.architectures(variant, config.params)[0]
    manifest = {
        "generator": {"kfpga": __version__, "amaranth": importlib.metadata.version("amaranth")},
        "filter": config.filter, "variant": variant, "prefix": prefix, "modules": modules,
        "architecture": architecture, "stages": getattr(core, "stages", None), "channels": channels,
        "latency_cycles": core.latency, "cycles_per_update": core.cycles_per_update,
        "startup_cycles": getattr(core, "startup_cycles", 0),
        "model": _jsonable(dataclasses.asdict(config.params)),
        "formats": {name: str(f) for name, f in config.formats.items()},
        "ports": interface(config, core), "timing": timing,
        "testbench": {k: tb[k] for k in ("samples", "seed", "scenario", "missing")},
        "missing": bool(missing), "bus": bus, "bus_cost": bus_cost,
        "registers": [{"name": r.name, "offset": r.offset, "access": r.access, "description": r.description}
                      for r in (core.regs or [])] if bus else [],
        "files": sorted([f"{prefix}.v", f"{prefix}.qip", f"{prefix}.core", "manifest.json", "README.txt",
                         "verilator_lint.vlt", *regmap, *(f"tb/{f}" for f in tb["files"])]),
    }
    (out_dir / f"{prefix}.core").write_text(_fusesoc(prefix, config, manifest, tb))
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    (out_dir / "README.txt").write_text(datasheet(manifest))
    return manifest


def _jsonable(value):
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    return value


def datasheet(manifest):
    """The folder's README: the core's datasheet."""
    m = manifest
    rows = []
    for port in m["ports"]:
        rows.append(f"  {port['name']:<11} {port['direction']:<6} {port['width']:>4}  {port['description']}")
        for f in port.get("fields", []):
            rows.append(f"      {f['bits']:<9} {f['name']:<9} {f['format']:<14} {f['description']}")
    stages = f", {m['stages']} stages" if m["stages"] else ""
    p = m["prefix"]
    files = [(f"{p}.v", f"the core, Verilog-2001: module {p} and its submodules {p}__*"),
             (f"{p}.qip", "the Quartus file list: add it to your project"),
             (f"{p}.core", f"FuseSoC (CAPI2): fusesoc --cores-root . run --target sim kfpga:cores:{p}"),
             ("", "(Icarus; --tool verilator for Verilator)"),
             ("tb/", "the self-checking testbench: tb/run_icarus.sh, or in ModelSim"),
             ("", "(cd tb; vsim -c -do run_modelsim.do); PASS or FAIL and an exit status"),
             ("manifest.json", "this datasheet as data")]
    width = max(len(name) for name, _ in files) + 2
    listing = "\n".join(f"  {name:<{width}}{what}" for name, what in files)
    return f"""{p}: the {m['filter']} filter's {m['variant']} core ({m['architecture']}{stages}), {m['channels']}
channel state(s), written by kfpga {m['generator']['kfpga']} (kfpga generate --core-only).

Files
{listing}

Ports (one clock domain; payload fields packed LSB first into one vector)
{chr(10).join(rows)}

Handshake (the Amaranth lib.stream rules)
  A word moves on a rising edge where valid and ready are both high. A sender holds valid and
  its payload until the word moves; a receiver may hold ready low as long as it likes. The core's
  i__ready does not wait for i__valid, and does not depend on o__ready while its output register
  is empty: with o__ready low it still takes a sample, computes it, and holds the estimate (valid
  and payload unchanged) until the receiver takes it. One estimate per sample, in order.

Timing
  latency:          {m['latency_cycles']} cycles from the edge that takes a sample to the first edge with its
                    estimate's o__valid high (o__ready held high)
  cycles per update: {m['cycles_per_update']} (the core takes a sample at most every that many cycles)
  after reset:      {m['startup_cycles']} cycles before i__ready rises (the reset state written)
  reset:            rst high for one edge or more; power-up gives the same state

Overflow
  Every write that can exceed its format saturates (or wraps, where the format says wrap) and
  flags the estimate (o__payload's overflow field); the overflow port is the sticky OR since
  reset. The formats: {', '.join(f'{k} {v}' for k, v in m['formats'].items())}.

{_missing_text(m)}{_bus_text(m)}{_proven(m)}"""


def _proven(m):
    tb = m["testbench"]
    lost = f", {tb['missing']} of them missing" if m.get("missing") else ""
    return (f"Proven: the testbench in tb/ compares {tb['samples']} estimates (scenario {tb['scenario']},\n"
            f"seed {tb['seed']}{lost}) word for word with the bit-accurate model.\n")


def _missing_text(m):
    if not m.get("missing"):
        return ""
    return """Missing samples
  A sample with i__payload's missing bit set has no measurement: its codes are not read and the
  update only predicts (x = F x, P = F P F' + G Q G'); it still gives one estimate. A coasting
  filter's covariance grows with each missing sample: give the covariance formats room for the
  longest gap you expect (a saturation there is flagged like any other).

"""


def _bus_text(m):
    if not m.get("bus"):
        return ""
    kind = {"avalon": "Avalon-MM slave (avs_*, word addresses, readdatavalid the cycle after a read)",
            "axi4lite": "AXI4-Lite slave (s_axil_*, byte addresses)"}[m["bus"]]
    rows = "\n".join(f"  0x{r['offset']:03X}  {r['name']:<16} {r['access']:<3} {r['description']}" for r in m["registers"])
    cost = m.get("bus_cost")
    cost_text = (f"  Cost: {cost['logic_cells']} logic cells and {cost['m4k_blocks']} M4K block(s) over the same core "
                 f"without the bus (Yosys estimate, {cost['base_logic_cells']} -> {cost['logic_cells_with_bus']} LE).\n"
                 if cost else "")
    return f"""Register bus: {kind}
  The settings (the constants of the update and the reset values) are written digit by digit
  (kfpga regs computes them: radix 2**17, lower digits 17 bits, the top one signed 18) and take
  effect when CONTROL.COMMIT is written: the core copies them between two updates, never inside
  one, and COMMITTED holds the sample from which they apply. CONTROL.RESET restarts every channel
  from the committed reset values; CONTROL.CLEAR clears the counters. The map: {m['prefix']}_regs.rdl
  (SystemRDL), {m['prefix']}_regs.h (C), {m['prefix']}_regs.md.
{cost_text}
{rows}

"""


# -- the testbench of the core alone ----------------------------------------------------------------


def _stimulus(config, channels, samples, seed, scenario):
    """``(channel per sample, {input: codes})``: each channel its own run of the scenario, the
    channels in a seeded random order."""
    from kfpga.model import scenarios

    rng = np.random.default_rng(seed)
    order = rng.integers(0, channels, samples) if channels > 1 else np.zeros(samples, dtype=np.int64)
    counts = np.bincount(order, minlength=channels)
    per = {}
    for c in range(channels):
        _, y = scenarios.for_config(scenario, max(int(counts[c]), 2), seed + 1009 * c, config)
        per[c] = y if isinstance(y, dict) else {config.inputs[0]: y}
    taken = np.zeros(channels, dtype=int)
    codes = {name: np.zeros(samples, dtype=np.int64) for name in config.inputs}
    for k, c in enumerate(order):
        for name in config.inputs:
            codes[name][k] = per[c][name][taken[c]]
        taken[c] += 1
    return order, codes


def _pack(fields, values):
    word = 0
    for name, offset, width, _ in fields:
        word |= (int(values[name]) & ((1 << width) - 1)) << offset
    return word


def core_icarus_command(prefix):
    tb = f"{prefix}_tb"
    return (["iverilog", "-g2001", "-o", f"{tb}.vvp", "-s", tb, f"{tb}.v", f"../{prefix}.v"], ["vvp", "-n", f"{tb}.vvp"])


def write_core_testbench(out_dir, config, *, variant, prefix, channels=1, architecture=None, stages=None, samples=500,
                         seed=1, scenario=None, gaps=3, missing=False, bus=None):
    """The self-checking testbench of the core alone in ``out_dir`` (the core's Verilog, ``PREFIX.v``,
    one folder up); returns ``{samples, seed, scenario, files}``."""
    check_prefix(prefix)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    core = figures_only(_make(config, variant, channels, architecture, stages, missing, bus))  # its figures only
    scenario = scenario or config.spec.model.scenarios[0]
    order, codes = _stimulus(config, channels, samples, seed, scenario)
    # with the missing bit: a fifth of the samples marked (their codes not read)
    lost = np.random.default_rng(seed + 11).random(samples) < MISSING_SHARE if missing else np.zeros(samples, bool)
    outs, overflow, _ = FixedModel(config, variant=variant).run_channels(codes, order, missing=lost)
    i_fields, o_fields = _fields(core.i), _fields(core.o)
    iw, ow = sum(f[2] for f in i_fields), sum(f[2] for f in o_fields)
    rng = np.random.default_rng(seed + 7)
    gap = rng.integers(0, gaps + 1, samples) * (rng.random(samples) < 0.5)  # half back to back
    stim = [(int(g) << iw) | _pack(i_fields, {"channel": c, "missing": int(lost[k]),
                                              **{n: codes[n][k] for n in config.inputs}})
            for k, (c, g) in enumerate(zip(order, gap, strict=True))]
    expected = [_pack(o_fields, {"channel": c, "overflow": int(overflow[k]), **{n: outs[n][k] for n in outs}})
                for k, c in enumerate(order)]
    (out_dir / f"{prefix}_stimulus.hex").write_text("".join(f"{w:0{(iw + 8 + 3) // 4}x}\n" for w in stim))
    (out_dir / f"{prefix}_expected.hex").write_text("".join(f"{w:0{(ow + 3) // 4}x}\n" for w in expected))
    per = max(core.cycles_per_update, 1)
    max_cycles = int((per + gaps + 2) * samples * 1024 / READY_PER_1024) + core.latency + 200 + \
        getattr(core, "startup_cycles", 0)
    tb = f"{prefix}_tb"
    (out_dir / f"{tb}.v").write_text(_tb_verilog(prefix, iw, ow, samples, max_cycles, seed, o_fields, _bus_ties(core)))
    compile_cmd, run_cmd = core_icarus_command(prefix)
    script = out_dir / "run_icarus.sh"
    script.write_text("#!/bin/sh\n# Icarus Verilog: compile and run the core's self-checking testbench (exit 0 = PASS)\n"
                      f'cd "$(dirname "$0")" && {" ".join(compile_cmd)} && exec {" ".join(run_cmd)}\n')
    script.chmod(0o755)
    (out_dir / "run_modelsim.do").write_text(
        f"# ModelSim-Altera: vsim -c -do run_modelsim.do (from this folder; exit status 0 = PASS)\n"
        f"if {{[file exists work]}} {{ vdel -lib work -all }}\nvlib work\n"
        f"vlog -work work -timescale 1ns/1ps ../{prefix}.v {tb}.v\nvsim -c -onfinish stop work.{tb}\nrun -all\n"
        f"set failed [examine -radix unsigned /{tb}/failed]\n"
        f"if {{$failed != 0}} {{ quit -f -code 1 }} else {{ quit -f -code 0 }}\n")
    files = sorted(p.name for p in out_dir.iterdir() if p.is_file())
    return {"samples": samples, "seed": seed, "scenario": scenario, "files": files, "out_width": ow, "in_width": iw,
            "missing": int(lost.sum())}


#: The core's testbench, a ``str.format`` template (``{{`` and ``}}`` are Verilog's braces).
_TB_VERILOG = """// Self-checking testbench of the core {prefix} alone: samples from {prefix}_stimulus.hex with random
// gaps, a receiver whose ready an LFSR drops on about 30 % of the cycles, every estimate
// compared with {prefix}_expected.hex (the bit-accurate model). Plain Verilog-2001, written by kfpga.
// Ends with one PASS or FAIL line and an exit status.
`timescale 1ns / 1ps
`default_nettype none
module {tb};
    parameter integer SAMPLES = {samples};
    parameter integer MAX_CYCLES = {max_cycles};
    parameter [31:0] SEED = 32'd{seed_word};
    parameter integer READY_PER_1024 = {ready_per_1024};
    // 0: inside a larger testbench, which waits for done and reads failed (no $finish here)
    parameter integer STANDALONE = 1;

    reg clk = 1'b0;
    always #10 clk = ~clk;
    reg rst = 1'b1;
    reg i_valid = 1'b0;
    reg [{iw_top}:0] i_payload = {iw}'d0;
    wire i_ready, o_valid, overflow;
    reg o_ready = 1'b0;
    wire [{ow_top}:0] o_payload;

    {prefix} dut (
        .clk(clk), .rst(rst), .i__valid(i_valid), .i__ready(i_ready), .i__payload(i_payload),
        .o__valid(o_valid), .o__ready(o_ready), .o__payload(o_payload), .overflow(overflow){bus}
    );

    // {prefix}_stimulus.hex: {{idle cycles before the sample [7:0], the payload [{iw_top}:0]}}
    reg [{gap_top}:0] stimulus [0:SAMPLES - 1];
    reg [{ow_top}:0] expected [0:SAMPLES - 1];
    initial begin
        $readmemh("{prefix}_stimulus.hex", stimulus);
        $readmemh("{prefix}_expected.hex", expected);
    end

    integer sent = 0, got = 0, mismatches = 0, extra = 0, cycles = 0, idle = 0, after = 0;
    reg failed = 1'b0, done = 1'b0;
    reg [31:0] lfsr = SEED;
    wire [{ow_top}:0] want = expected[got < SAMPLES ? got : 0];

    task finish;
        begin
            failed = (mismatches != 0) || (got != SAMPLES) || (extra != 0);
            if (failed)
                $display("FAIL: {prefix}: %0d of %0d estimates, %0d mismatches, %0d extra%0s", got, SAMPLES, mismatches,
                         extra, got != SAMPLES ? ", the core stopped answering" : "");
            else
                $display("PASS: {prefix}: %0d estimates equal to the model, one per sample", got);
            done = 1'b1;
            if (STANDALONE != 0) begin
{finish}
            end
        end
    endtask

    initial idle = 0;
    always @(posedge clk) begin
        cycles = cycles + 1;
        if (cycles == 4) rst <= 1'b0;
        lfsr <= {{lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0]}};
        o_ready <= (got >= SAMPLES) || (lfsr[9:0] < READY_PER_1024);
        if (!rst) begin
            // the receiver: compare every estimate taken on this edge
            if (o_valid && o_ready) begin
                if (got >= SAMPLES)
                    extra = extra + 1;
                else begin
                    if (o_payload !== want) begin
                        mismatches = mismatches + 1;
                        if (mismatches <= 10)
                            $display("MISMATCH estimate %0d at %0t: got {show}, expected {show}", got, $time,
                                     {args});
                    end
                    got = got + 1;
                end
            end
            // the sender: the next sample after its idle cycles, held until taken
            if (i_valid && i_ready) begin
                sent = sent + 1;
                if (sent < SAMPLES && stimulus[sent][{gap_top}:{iw}] == 0)
                    i_payload <= stimulus[sent][{iw_top}:0];
                else begin
                    i_valid <= 1'b0;
                    idle = (sent < SAMPLES) ? stimulus[sent][{gap_top}:{iw}] - 1 : 0;
                end
            end else if (!i_valid && sent < SAMPLES) begin
                if (idle <= 0) begin
                    i_payload <= stimulus[sent][{iw_top}:0];
                    i_valid <= 1'b1;
                end else
                    idle = idle - 1;
            end
        end
        if (got >= SAMPLES) after = after + 1;
        if (!done && (after > 60 || cycles >= MAX_CYCLES)) finish;
    end
endmodule
`default_nettype wire
"""


def _tb_verilog(prefix, iw, ow, samples, max_cycles, seed, o_fields, bus=""):
    tb = f"{prefix}_tb"
    show = " ".join(f"{name} %0d" for name, *_ in o_fields)
    args = ", ".join(f"{'$signed(' if s else ''}{w}[{o + n - 1}:{o}]{')' if s else ''}"
                     for w in ("o_payload", "want") for _, o, n, s in o_fields)
    return _TB_VERILOG.format(prefix=prefix, tb=tb, samples=samples, max_cycles=max_cycles,
                              seed_word=(seed * 2654435761 + 1) & 0xFFFFFFFF | 1, ready_per_1024=READY_PER_1024,
                              iw_top=iw - 1, iw=iw, ow_top=ow - 1, gap_top=iw + 7,
                              finish=finish_with_status("                "), show=show, args=args, bus=bus)


def fusesoc_core(*, vlnv, comments, description, rtl, top, tb, tb_top, data, filesets="", targets=""):
    """A FuseSoC core file (CAPI2): the ``rtl`` fileset and its ``default`` target with ``top``, and a
    ``sim`` target running the testbench (``tb`` Verilog files, ``data`` files copied beside it,
    top ``tb_top``) on Icarus (default) or Verilator; ``filesets`` and ``targets`` add YAML of
    their own (the board's constraints and Quartus target)."""
    def listing(files, copy=False):
        return "\n".join(f"      - {f}: {{file_type: user, copyto: {Path(f).name}}}" if copy else f"      - {f}"
                         for f in files)

    header = "\n".join(f"# {line}" for line in comments)
    return f"""CAPI=2:
{header}
name: {vlnv}
description: "{description}"

filesets:
  rtl:
    files:
{listing(rtl)}
    file_type: verilogSource
{filesets}  tb:
    files:
{listing(tb)}
    file_type: verilogSource
  tbdata:
    files:
{listing(data, copy=True)}

targets:
  default:
    filesets: [rtl]
    toplevel: {top}
{targets}  sim:
    default_tool: icarus
    filesets: [rtl, tb, tbdata]
    toplevel: {tb_top}
    tools:
      icarus:
        iverilog_options: [-g2001]
      verilator:
        mode: binary
        verilator_options: [--timing, -CFLAGS, -fcoroutines, -Wno-fatal, -Wno-lint, -Wno-style]
"""


def _fusesoc(prefix, config, manifest, tb):
    vlnv = f"kfpga:cores:{prefix}"
    return fusesoc_core(
        vlnv=f"{vlnv}:1.0.0",
        comments=[f"FuseSoC core file of the {config.filter} core {prefix} (kfpga {__version__}).",
                  f"  fusesoc --cores-root . run --target sim {vlnv}               (Icarus)",
                  f"  fusesoc --cores-root . run --target sim --tool verilator {vlnv}"],
        description=f"{config.filter} filter, {manifest['variant']} core, {manifest['channels']} channel(s), "
                    f"latency {manifest['latency_cycles']} cycles",
        rtl=[f"{prefix}.v"], top=prefix, tb=[f"tb/{prefix}_tb.v"], tb_top=f"{prefix}_tb",
        data=[f"tb/{prefix}_stimulus.hex", f"tb/{prefix}_expected.hex"])
