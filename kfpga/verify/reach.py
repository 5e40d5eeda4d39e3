"""Equivalence of a mutant whose change lies in the data-independent part of a block, by
explicit-state reachability (``kfpga/verify/mutate.py``).

A time-varying Kalman core carries two kinds of state. Its estimate depends on the samples;
its covariance, its gains and its schedule do not: from the fixed reset they follow one
trajectory, whatever the samples, which settles after a few dozen updates. A mutant that
changes a covariance bit the trajectory never sets cannot be seen at the outputs, and no bench
can kill it; but neither k-induction nor a bounded check can show it: induction starts from
states the trajectory never visits, and a bounded check would have to run through hundreds of
cycles of divisions and products.

This check decides such mutants. On the pair of the original block (gold) and the mutant
(gate), it marks every net that depends on a data input (the samples) and calls the rest
*data-independent*: its registers step from the reset state by the control inputs alone
(valid, ready, channel, reset), whatever the samples are. When the mutation touches only
data-independent logic, the two designs' data paths are the same logic on the same samples, and
a data-path value can differ only if something it reads does. So the check enumerates every
reachable state of the data-independent registers of both designs, under every combination of
the control inputs, and carries with each a *may differ* bit for every data-path cell and
register: set where a cell reads a data-independent value that differs between gold and gate,
or a data-path value that may differ; not passed on by a multiplexer whose select is the same
in both and chooses another input (an operand an instruction does not use, a memory word not
addressed). If the search ends (no new state) and no difference ever reaches an output, the
mutant is equivalent: no input sequence can tell them apart. If one may reach an output, or the
search exceeds its state budget, it is not proven here.

Memories are mapped to one register per word first. A change of a memory's initial contents is
then a data-path register (a RAM word) that starts with its may-differ bit set, and stays
unseen if it is written before it is read, or a data-independent register (a ROM word) whose
instruction fields reach the data path only where the instruction uses them.

The netlist is Yosys's JSON of the miter, evaluated word by word with the semantics of Yosys's
internal cells; each step is compiled into one Python function (written here, not a simulator
library: no Python simulator reads a Yosys netlist and lets a search set and save its state).
"""

from __future__ import annotations

import json
import re
from collections import deque
from dataclasses import dataclass

__all__ = ["Verdict", "Program", "check", "compile_pair", "netlist_json"]

#: Control input bits the search enumerates at most (2**N combinations per state).
MAX_CONTROL_BITS = 10

_BITWISE = {"$and", "$or", "$xor", "$xnor", "$not", "$pos", "$mux"}
_SUPPORTED = _BITWISE | {"$add", "$sub", "$mul", "$neg", "$logic_not", "$logic_and", "$logic_or", "$reduce_and",
                         "$reduce_or", "$reduce_bool", "$reduce_xor", "$reduce_xnor", "$eq", "$ne", "$eqx", "$nex",
                         "$lt", "$le", "$gt", "$ge", "$shl", "$sshl", "$shr", "$sshr", "$shift", "$shiftx", "$pmux",
                         "$dff", "$scopeinfo"}


@dataclass(frozen=True)
class Verdict:
    """The outcome: ``equivalent`` (True), ``different`` (a reachable difference), or neither
    (``why`` says why the check does not apply or did not finish)."""

    equivalent: bool
    different: bool
    why: str
    states: int = 0


#: The cells that feed a memory's initial contents, and the wires between (a Yosys selection).
_INIT_GATES = "t:$meminit_v2 %ci2:+$meminit_v2[DATA] %ci1"


def netlist_json(gold_il, gate_il, folder):
    """Write the flat RTLIL modules ``gold`` and ``gate`` as one Yosys JSON file; its path.

    Memories become registers, one per word, and multiplexers (Yosys's ``memory_map``): a ROM's
    words are then data-independent registers that keep their initial contents, and a RAM's
    words data-path registers. The cells the mapping creates are named by a counter that the
    mutant's extra cells move on, so they are renamed by their order of creation, the same in
    both designs.
    """
    from kfpga.verify.formal import yosys

    for side, il in (("gold", gold_il), ("gate", gate_il)):
        # a mutation of a memory's initial contents may leave a gate on a constant (inv, cnot):
        # folded first, since a memory takes only constant contents
        ok, log = yosys(f"read_rtlil {il}\nopt_expr {_INIT_GATES}\nopt_clean\nmemory_collect\nmemory_map\n"
                        f"write_rtlil {side}_mapped.il\n", folder)
        if not ok:
            raise RuntimeError(f"the memories of {il} could not be mapped: {log.strip()[-300:]}")
    ok, log = yosys("read_rtlil gold_mapped.il\nread_rtlil gate_mapped.il\nwrite_json pair.json\n", folder)
    if not ok:
        raise RuntimeError(f"the designs could not be read: {log.strip()[-300:]}")
    path = folder / "pair.json"
    design = json.loads(path.read_text())
    gold, gate = design["modules"]["gold"]["cells"], design["modules"]["gate"]["cells"]
    # every generated name, by its name without the counter (a name both designs have may be two
    # different cells, one counter apart)
    groups = {}
    for side, cells in (("gold", gold), ("gate", gate)):
        for name in cells:
            if m := _COUNTED.match(name):
                stem = m.group(1) + "$" + (m.group(3) or "")
                groups.setdefault(stem, {"gold": [], "gate": []})[side].append((int(m.group(2)), name))
    renamed = {"gold": {}, "gate": {}}
    for stem, sides in groups.items():
        if len(sides["gold"]) == len(sides["gate"]):  # created in the same order in both
            for side, named in sides.items():
                renamed[side].update({name: f"{stem}#{k}" for k, (_, name) in enumerate(sorted(named))})
    for side in ("gold", "gate"):
        module = design["modules"][side]
        module["cells"] = {renamed[side].get(name, name): cell for name, cell in module["cells"].items()}
    matched = folder / "pair_matched.json"  # (pair.json keeps Yosys's names)
    matched.write_text(json.dumps(design))
    return matched


#: A generated name: before its counter, the counter, and a suffix (``$procmux$12_CMP0``).
_COUNTED = re.compile(r"^(.*)\$(\d+)(_[A-Z0-9_]+)?$")


def _int(value):
    if isinstance(value, int):
        return value
    return int(value, 2) if value and set(value) <= {"0", "1"} else 0


class _Netlist:
    """Gold and gate as one netlist: the cells ``(side, name)``, the net bits ``(side, id)``; the
    two designs share their input ports, bit ``("in", port, i)``."""

    def __init__(self, modules, data_inputs):
        gold, gate = modules["gold"], modules["gate"]
        if {n: p["direction"] for n, p in gold["ports"].items()} != {n: p["direction"] for n, p in gate["ports"].items()}:
            raise _NotApplicable("the two designs have different ports")
        self.ports = {n: len(p["bits"]) for n, p in gold["ports"].items()}
        self.inputs = [n for n, p in gold["ports"].items() if p["direction"] == "input"]
        self.outputs = [n for n, p in gold["ports"].items() if p["direction"] == "output"]
        self.cells, self.init, self.out_bits, self.netnames = {}, {}, {}, {}
        for side, module in (("gold", gold), ("gate", gate)):
            self._add(side, module)
        self.driver = {}  # net bit -> (cell, port, index)
        for key, cell in self.cells.items():
            for port, bits in cell["connections"].items():
                if cell["port_directions"][port] == "output":
                    for i, b in enumerate(bits):
                        self.driver[b] = (key, port, i)
        self.tainted = self._taint(data_inputs)

    def _add(self, side, module):
        """One design's cells, outputs, net names and initial values, its bits named by ``side``."""
        rename = {b: ("in", name, i) for name, port in module["ports"].items() if port["direction"] == "input"
                  for i, b in enumerate(port["bits"]) if isinstance(b, int)}
        self.out_bits[side] = {name: [self._bit(side, b, rename) for b in port["bits"]]
                               for name, port in module["ports"].items() if port["direction"] == "output"}
        for name, cell in module["cells"].items():
            if cell["type"] == "$scopeinfo":
                continue
            conn = {p: [self._bit(side, b, rename) for b in bits] for p, bits in cell["connections"].items()}
            self.cells[(side, name)] = {**cell, "connections": conn}
        self.netnames[side] = {name: [self._bit(side, b, rename) for b in net["bits"]]
                               for name, net in module["netnames"].items()}
        for net in module["netnames"].values():
            init = net.get("attributes", {}).get("init")
            if isinstance(init, str):
                for i, b in enumerate(net["bits"]):
                    if isinstance(b, int) and i < len(init):
                        self.init[self._bit(side, b, rename)] = init[len(init) - 1 - i]

    @staticmethod
    def _bit(side, b, rename):
        if not isinstance(b, int):
            return b  # a constant: "0", "1", "x", "z"
        return rename.get(b, (side, b))

    def params(self, cell):
        return {k: _int(v) for k, v in cell["parameters"].items()}

    def _taint(self, data_inputs):
        tainted = {("in", port, i) for port, bits in data_inputs.items() for i in bits}
        changed = True
        while changed:
            changed = False
            for cell in self.cells.values():
                out = self._tainted_outputs(cell, tainted)
                if not out <= tainted:
                    tainted |= out
                    changed = True
        return tainted

    def _tainted_outputs(self, cell, tainted):
        conn, kind = cell["connections"], cell["type"]

        def hit(bits):
            return any(b in tainted for b in bits)

        if kind == "$dff":
            return {q for d, q in zip(conn["D"], conn["Q"], strict=True) if d in tainted}
        if kind in ("$and", "$or", "$xor", "$xnor", "$not", "$pos"):
            p = self.params(cell)
            y = conn["Y"]
            out = set()
            for i, b in enumerate(y):
                for port in ("A", "B"):
                    if port in conn:
                        bits, signed = conn[port], p.get(f"{port}_SIGNED", 0)
                        if (i < len(bits) and bits[i] in tainted) or (i >= len(bits) and signed and bits[-1] in tainted):
                            out.add(b)
            return out
        if kind == "$mux":
            if hit(conn["S"]):
                return set(conn["Y"])
            return {y for a, b, y in zip(conn["A"], conn["B"], conn["Y"], strict=True) if a in tainted or b in tainted}
        if kind == "$pmux":
            if hit(conn["S"]):
                return set(conn["Y"])
            width = len(conn["Y"])
            return {y for i, y in enumerate(conn["Y"])
                    if conn["A"][i] in tainted or any(conn["B"][k * width + i] in tainted for k in range(len(conn["S"])))}
        inputs = [b for p, bits in conn.items() if cell["port_directions"][p] == "input" for b in bits]
        outputs = [b for p, bits in conn.items() if cell["port_directions"][p] == "output" for b in bits]
        return set(outputs) if hit(inputs) else set()


def _bits_expr(bits, source):
    """A Python expression for the word on ``bits`` (LSB first); ``source(bit)`` gives
    ``(variable, bit index)``, or ``None`` with a constant."""
    parts, i = [], 0
    while i < len(bits):
        b = bits[i]
        if not isinstance(b, tuple):
            if b == "1":
                parts.append(f"{1 << i}")
            i += 1
            continue
        src = source(b)
        if src is None:
            i += 1
            continue
        var, at = src
        j = i + 1
        while j < len(bits) and isinstance(bits[j], tuple) and source(bits[j]) == (var, at + j - i):
            j += 1
        mask = (1 << (j - i)) - 1
        word = f"(({var} >> {at}) & {mask})" if at else f"({var} & {mask})"
        parts.append(f"({word} << {i})" if i else word)
        i = j
    return " | ".join(parts) if parts else "0"


#: Cells whose expression needs no width: templates on the operand expressions a, b, s.
_PLAIN = {"$logic_not": "int(({a}) == 0)", "$logic_and": "int(({a}) != 0 and ({b}) != 0)",
          "$logic_or": "int(({a}) != 0 or ({b}) != 0)", "$reduce_or": "int(({a}) != 0)",
          "$reduce_bool": "int(({a}) != 0)", "$reduce_xor": "(bin({a}).count('1') & 1)",
          "$reduce_xnor": "(1 - (bin({a}).count('1') & 1))", "$mux": "(({b}) if ({s}) else ({a}))"}
_BINARY = {"$add": "+", "$sub": "-", "$mul": "*", "$and": "&", "$or": "|", "$xor": "^", "$xnor": "^"}
_COMPARE = {"$eq": "==", "$eqx": "==", "$ne": "!=", "$nex": "!=", "$lt": "<", "$le": "<=", "$gt": ">", "$ge": ">="}


def _ext(x, w, signed):
    return f"_sx({x}, {w})" if signed and w else x


def _cell_expr(kind, p, a, b, s, widths):
    """The Python expression of one cell's output word (Yosys internal-cell semantics)."""
    wa, wb, wy = widths
    mask_y = (1 << wy) - 1
    both = p.get("A_SIGNED", 0) and p.get("B_SIGNED", 0)
    if kind in _PLAIN:
        return _PLAIN[kind].format(a=a, b=b, s=s)
    if kind in _BINARY:
        body = f"({_ext(a, wa, both)}) {_BINARY[kind]} ({_ext(b, wb, both)})"
        return f"(~({body})) & {mask_y}" if kind == "$xnor" else f"({body}) & {mask_y}"
    if kind in ("$neg", "$not", "$pos"):
        x = _ext(a, wa, p.get("A_SIGNED", 0))
        return {"$neg": f"(-({x})) & {mask_y}", "$not": f"(~({x})) & {mask_y}", "$pos": f"({x}) & {mask_y}"}[kind]
    if kind == "$reduce_and":
        return f"int(({a}) == {(1 << wa) - 1})"
    if kind in _COMPARE:
        return f"int(({_ext(a, wa, both)}) {_COMPARE[kind]} ({_ext(b, wb, both)}))"
    return _shift_expr(kind, p, a, b, widths)


def _shift_expr(kind, p, a, b, widths):
    """The Python expression of a shift cell's output word."""
    wa, wb, wy = widths
    mask_y = (1 << wy) - 1
    if kind in ("$shl", "$sshl"):
        return f"(({_ext(a, wa, p.get('A_SIGNED', 0))}) << ({b})) & {mask_y}"
    mask_w = (1 << max(wa, wy)) - 1
    a_ext = _ext(a, wa, p.get("A_SIGNED", 0))
    if kind == "$shr" or (kind == "$sshr" and not p.get("A_SIGNED", 0)):
        return f"((({a_ext}) & {mask_w}) >> ({b})) & {mask_y}"
    if kind == "$sshr":
        return f"(({a_ext}) >> ({b})) & {mask_y}"
    if kind in ("$shift", "$shiftx"):
        # bits shifted in from outside A are x for $shiftx: both designs read them as 0
        base = f"(({a_ext}) & {mask_w})" if kind == "$shift" else f"({a})"
        if p.get("B_SIGNED", 0):
            return f"(_shift({base}, _sx({b}, {wb})) & {mask_y})"
        return f"(({base}) >> ({b})) & {mask_y}"
    raise ValueError(kind)


def _sx(v, w):
    return v - (1 << w) if (v >> (w - 1)) & 1 else v


def _shift(v, n):
    return v >> n if n >= 0 else v << -n


def _outputs(cell):
    return [b for p, bits in cell["connections"].items() if cell["port_directions"][p] == "output" for b in bits]


class _NotApplicable(Exception):
    pass


@dataclass(frozen=True)
class Program:
    """The data-independent logic of gold and gate, compiled: ``step(state, inputs)`` is the next
    state word (every data-independent register bit of both designs), or ``None`` when gold and
    gate give the data path or an output different values; ``inputs`` packs the control input
    bits (:attr:`control`, LSB first)."""

    step: object
    init: int
    control: tuple  # ((port, bit), ...)
    layout: tuple  # ((cell key, offset, width, mask), ...)
    followed: int  # cells of the data path whose "may differ" bit the search carries
    net: object
    readers: tuple = ()
    differ: list = None  # after a step gave None: ("differs" or "may differ", output port)

    def differences(self):
        """What the last step that gave ``None`` found: ``(kind, output port)``."""
        return self.differ[-1] if self.differ else None

    def inputs(self, **values):
        """The inputs word of ``port=value`` (ports left out are 0)."""
        return sum(((values.get(port, 0) >> i) & 1) << k for k, (port, i) in enumerate(self.control))

    def read(self, state, side, netname):
        """The value of the register wire ``netname`` of ``side`` ("gold" or "gate") in ``state``."""
        bits = self.net.netnames[side][netname]
        where = {}
        for key, off, _, _ in self.layout:
            for i, q in enumerate(self.net.cells[key]["connections"]["Q"]):
                where[q] = off + i
        return sum(((state >> where[b]) & 1) << i for i, b in enumerate(bits))


def _powers_up_cleared(name):
    """Whether register ``name``, which has no power-up value in the netlist, powers up 0: a
    memory's read register (``memory_map`` names it ``...$rdreg[k]``; Amaranth gives a read port
    none), which on the target, as every register of an Altera device's core and every M4K output
    register, powers up cleared (AN 252, table 1). Gold's and gate's are then the same 0."""
    return "$rdreg[" in name


def _compile(net, control):
    """The :class:`Program` of the data-independent registers of both designs."""
    tainted = net.tainted
    # every cell with an output bit that does not depend on the data; a bitwise cell may have
    # both kinds of bit, and its data bits (read here as 0) never reach a data-independent one
    di = {key: cell for key, cell in net.cells.items() if any(b not in tainted for b in _outputs(cell))}
    for key, cell in di.items():
        if cell["type"] not in _SUPPORTED:
            raise _NotApplicable(f"a {cell['type']} cell ({key[1]}) in the data-independent logic")
    variables = {key: f"v{i}" for i, key in enumerate(di)}
    layout, init, offset = _register_layout(net, di)
    control_var = {("in", port, i): ("_i", k) for k, (port, i) in enumerate(control)}

    def source(bit):
        if bit in tainted:
            return None  # a data bit a bitwise cell carries to a data bit: never read here
        if bit in control_var:
            return control_var[bit]
        if bit[0] == "in":
            raise _NotApplicable(f"input {bit[1]}[{bit[2]}] is read but is neither data nor a control input")
        if bit not in net.driver:
            return None  # an undriven bit (x): both designs alike read it as 0
        key, _, index = net.driver[bit]
        return variables[key], index

    lines = ["def step(_s, _i):"]
    lines += [f"    {variables[key]} = (_s >> {off}) & {(1 << width) - 1}" for key, off, width, _ in layout]
    for key in _combinational_order(net, di):
        lines += _cell_lines(net, di[key], variables[key], source)
    prop = _Propagation(net, source, offset).result()
    lines[1:1] = prop["read"]
    lines += prop["lines"]
    nxt = []
    for key, off, _, mask in layout:
        d = _bits_expr(di[key]["connections"]["D"], source)
        nxt.append(f"((({d}) & {mask}) << {off})" if off else f"(({d}) & {mask})")
    nxt += [f"(({d}) << {at})" for d, at in prop["next"]]
    lines.append("    return " + (" | ".join(nxt) if nxt else "0"))
    differ = []
    scope = {"_sx": _sx, "_shift": _shift, "_differ": differ}
    exec(compile("\n".join(lines), "<reach step>", "exec"), scope)  # the step, generated from the netlist above
    return Program(scope["step"], init | prop["init"], tuple(control), tuple(layout), prop["followed"], net,
                   (), differ)


def _register_layout(net, di):
    """The data-independent registers in the state word: ``(layout, init, width)``, ``layout``
    a list of (register, offset in the state word, width, mask of its kept bits)."""
    layout, init, offset = [], 0, 0
    for key, cell in di.items():
        if cell["type"] != "$dff":
            continue
        mask = value = 0
        for i, q in enumerate(cell["connections"]["Q"]):
            if q not in net.tainted:
                mask |= 1 << i
                value |= _power_up(net, key, i, q) << i
        width = len(cell["connections"]["Q"])
        layout.append((key, offset, width, mask))
        init |= value << offset
        offset += width
    return layout, init, offset


def _power_up(net, key, i, q):
    """The power-up value of bit ``i`` (net ``q``) of register ``key``."""
    bit = net.init.get(q)
    twin = net.cells.get(("gold", key[1])) if key[0] == "gate" else None
    if bit is None and twin is not None and twin["type"] == "$dff":
        # a mutation of the register's output port leaves it on a new net, without the init
        # attribute; a mutation rewires, it never changes a power-up value, so the register
        # starts as its gold twin does
        bit = net.init.get(twin["connections"]["Q"][i])
    if bit is None and _powers_up_cleared(key[1]):
        bit = "0"
    if bit not in ("0", "1"):
        raise _NotApplicable(f"register {key[1]} has no reset value for bit {i}")
    return int(bit)


def _combinational_order(net, di):
    """The combinational cells of ``di``, each after what it reads."""
    order, done, visiting = [], set(), set()

    def visit(key):
        if key in done:
            return
        if key in visiting:
            raise _NotApplicable(f"a combinational loop through {key[1]}")
        visiting.add(key)
        cell = di[key]
        if cell["type"] != "$dff":
            for b in (b for port, bits in cell["connections"].items() if cell["port_directions"][port] == "input"
                      for b in bits):
                if isinstance(b, tuple) and b[0] != "in" and b not in net.tainted and b in net.driver:
                    visit(net.driver[b][0])
        visiting.discard(key)
        done.add(key)
        order.append(key)

    for key in di:
        visit(key)
    return [key for key in order if di[key]["type"] != "$dff"]


def _cell_lines(net, cell, variable, source):
    """The step's lines that compute one combinational cell's output word."""
    conn, p = cell["connections"], net.params(cell)
    a = _bits_expr(conn["A"], source) if "A" in conn else "0"
    b = _bits_expr(conn["B"], source) if "B" in conn else "0"
    s = _bits_expr(conn["S"], source) if "S" in conn else "0"
    if cell["type"] == "$pmux":  # one-hot select: the lowest set bit chooses (both designs alike)
        width = len(conn["Y"])
        expr = a
        for k in reversed(range(len(conn["S"]))):
            bk = _bits_expr(conn["B"][k * width:(k + 1) * width], source)
            expr = f"(({bk}) if ((_sel >> {k}) & 1) else ({expr}))"
        return [f"    _sel = {s}", f"    {variable} = {expr}"]
    widths = (len(conn.get("A", [])), len(conn.get("B", [])), len(conn["Y"]))
    return [f"    {variable} = {_cell_expr(cell['type'], p, a, b, s, widths)}"]


class _Propagation:
    """The step's lines that carry a *may differ* bit through the data path, the cells with an
    output bit that depends on the data.

    Gold's and gate's data paths are the same cells on the same samples, so a data-path value can
    differ only if something it reads does: a data-independent value that differs between the two
    (computed exactly by the search), or a data-path value that may differ. A multiplexer whose
    select is data-independent and the same in both passes on only the chosen input's bit, so a
    value that differs but is not chosen (an operand an instruction does not use, a memory word
    not addressed) goes no further; any other cell's output may differ when one of its inputs
    may. A data-path register keeps the bit in the search state, starting at 1 when its power-up
    values differ (a memory word's initial contents). A step that lets a possible difference
    reach an output gives ``None``: the mutant is then not proven equivalent here.
    """

    def __init__(self, net, source, base):
        self.net, self.source, self.tainted = net, source, net.tainted
        self.pairs = {}
        for (side, name), cell in net.cells.items():
            if side == "gold" and any(b in self.tainted for b in _outputs(cell)):
                twin = net.cells.get(("gate", name))
                if twin is None or twin["type"] != cell["type"]:
                    raise _NotApplicable(f"cell {name} has no twin in the mutant")
                self.pairs[name] = (cell, twin)
        self.var = {name: f"_d{i}" for i, name in enumerate(self.pairs)}
        self.regs = [name for name, (cell, _) in self.pairs.items() if cell["type"] == "$dff"]
        self.where = {name: base + j for j, name in enumerate(self.regs)}

    def diff(self, gbits, tbits):
        """The expression of 'some bit of gold's gbits may differ from gate's tbits'."""
        terms, gold_di, gate_di = set(), [], []
        net, tainted = self.net, self.tainted
        for g, t in zip(gbits, tbits, strict=True):
            if (g in tainted) != (t in tainted):
                return "1"
            if g not in tainted:
                gold_di.append(g)
                gate_di.append(t)
            elif g != t:  # (a shared sample input bit is the same in both)
                dg, dt = net.driver.get(g), net.driver.get(t)
                if dg is None or dt is None or dg[0][1] != dt[0][1] or dg[1:] != dt[1:]:
                    return "1"
                terms.add(self.var[dg[0][1]])
        if gold_di:
            terms.add(f"int(({_bits_expr(gold_di, self.source)}) != ({_bits_expr(gate_di, self.source)}))")
        return " | ".join(sorted(terms)) if terms else "0"

    @staticmethod
    def inputs(cell, twin):
        return [(bits, twin["connections"][port]) for port, bits in cell["connections"].items()
                if cell["port_directions"][port] == "input"]

    def order(self):
        """The data path's combinational cells, each after what it reads (depth first, without
        recursion: a data path can be thousands of cells deep)."""
        order, done = [], set()
        for name in self.pairs:
            stack = [(name, False)]
            while stack:
                key, expanded = stack.pop()
                if key in done:
                    continue
                if expanded:
                    done.add(key)
                    order.append(key)
                    continue
                stack.append((key, True))
                if self.pairs[key][0]["type"] != "$dff":
                    stack += [(d, False) for d in self._drivers(key) if d not in done]
        return [name for name in order if self.pairs[name][0]["type"] != "$dff"]

    def _drivers(self, key):
        """The combinational data-path cells that drive ``key``'s inputs."""
        for bits, _ in self.inputs(*self.pairs[key]):
            for b in bits:
                if b in self.tainted and isinstance(b, tuple) and b[0] != "in":
                    driver = self.net.driver[b][0][1]
                    if self.pairs[driver][0]["type"] != "$dff":
                        yield driver

    def cell_lines(self, name):
        cell, twin = self.pairs[name]
        cg, ct = cell["connections"], twin["connections"]
        select_known = "S" in cg and not any(b in self.tainted for b in (*cg["S"], *ct["S"]))
        lines = []
        if cell["type"] == "$mux" and select_known:
            sg, st = _bits_expr(cg["S"], self.source), _bits_expr(ct["S"], self.source)
            expr = (f"(({self.diff(cg['B'], ct['B'])}) if ({sg}) else ({self.diff(cg['A'], ct['A'])})) "
                    f"if ({sg}) == ({st}) else 1")
        elif cell["type"] == "$pmux" and select_known:
            width = len(cg["Y"])
            sg, st = _bits_expr(cg["S"], self.source), _bits_expr(ct["S"], self.source)
            # every input a set select bit chooses (one, if the select is one-hot as it should be)
            chosen = [(cg["B"][k * width:(k + 1) * width], ct["B"][k * width:(k + 1) * width]) for k in range(len(cg["S"]))]
            terms = [f"(((_sg >> {k}) & 1) and ({self.diff(g, t)}))" for k, (g, t) in enumerate(chosen)]
            terms.append(f"((_sg == 0) and ({self.diff(cg['A'], ct['A'])}))")
            lines.append(f"    _sg, _st = {sg}, {st}")
            expr = f"int({' or '.join(terms)}) if _sg == _st else 1"
        else:
            expr = " | ".join(f"({self.diff(g, t)})" for g, t in self.inputs(cell, twin)) or "0"
        return [*lines, f"    {self.var[name]} = {expr}"]

    def output_checks(self):
        """The lines that end the step with ``None`` when an output differs or may differ."""
        lines, net = [], self.net
        for port in net.outputs:
            gbits, tbits = net.out_bits["gold"][port], net.out_bits["gate"][port]
            known = [(g, t) for g, t in zip(gbits, tbits, strict=True) if g not in self.tainted and t not in self.tainted]
            if known:  # a data-independent output bit: exactly compared
                g_expr = _bits_expr([g for g, _ in known], self.source)
                t_expr = _bits_expr([t for _, t in known], self.source)
                lines += [f"    if ({g_expr}) != ({t_expr}):", f"        _differ.append(('differs', {port!r}))",
                          "        return None"]
            rest = [(g, t) for g, t in zip(gbits, tbits, strict=True) if (g, t) not in known]
            if rest:
                lines += [f"    if {self.diff([g for g, _ in rest], [t for _, t in rest])}:",
                          f"        _differ.append(('may differ', {port!r}))", "        return None"]
        return lines

    def result(self):
        """``{"read", "lines", "next", "init", "followed"}``: the lines that read the registers'
        bits from the state, those that compute and check, the next bits with their places, the
        initial bits, the number of cells followed."""
        net = self.net
        read = [f"    {self.var[name]} = (_s >> {self.where[name]}) & 1" for name in self.regs]
        lines = [line for name in self.order() for line in self.cell_lines(name)] + self.output_checks()
        init = 0
        for name in self.regs:
            cell, twin = self.pairs[name]
            qg, qt = cell["connections"]["Q"], twin["connections"]["Q"]
            if any(g in self.tainted and net.init.get(g) != net.init.get(t, net.init.get(g))
                   for g, t in zip(qg, qt, strict=True)):
                init |= 1 << self.where[name]
        nxt = [(self.diff(self.pairs[name][0]["connections"]["D"], self.pairs[name][1]["connections"]["D"]),
                self.where[name]) for name in self.regs]
        return {"read": read, "lines": lines, "next": nxt, "init": init, "followed": len(self.pairs)}


def compile_pair(pair_path, data_inputs):
    """The :class:`Program` of gold and gate at ``pair_path`` (raises ``ValueError`` where the
    check does not apply)."""
    net = _Netlist(json.loads(pair_path.read_text())["modules"], data_inputs)
    clocks = {b for c in net.cells.values() if c["type"] == "$dff" for b in c["connections"]["CLK"]}
    control = [(port, i) for port in net.inputs for i in range(net.ports[port])
               if ("in", port, i) not in net.tainted and ("in", port, i) not in clocks]
    try:
        return _compile(net, control)
    except _NotApplicable as exc:
        raise ValueError(str(exc)) from None


def check(pair_path, data_inputs, *, max_states=300_000):
    """Decide gold against gate (``pair_path``: :func:`netlist_json`) by an explicit-state search
    of their data-independent logic.

    ``data_inputs``: ``{port: [bit, ...]}``, the input bits that carry data (the samples); every
    other input bit but the clock is a control input, enumerated at every step.
    """
    try:
        net = _Netlist(json.loads(pair_path.read_text())["modules"], data_inputs)
        mutation = [key for key in net.cells if key[0] == "gate" and ("gold", key[1]) not in net.cells]
        if any(b in net.tainted for key in mutation for b in _outputs(net.cells[key])):
            return Verdict(False, False, "the mutation is in logic that depends on the data")
        clocks = {b for c in net.cells.values() if c["type"] == "$dff" for b in c["connections"]["CLK"]}
        if len(clocks) > 1:
            raise _NotApplicable("more than one clock")
        control = [(port, i) for port in net.inputs for i in range(net.ports[port])
                   if ("in", port, i) not in net.tainted and ("in", port, i) not in clocks]
        if len(control) > MAX_CONTROL_BITS:
            return Verdict(False, False, f"{len(control)} control input bits (more than {MAX_CONTROL_BITS})")
        program = _compile(net, control)
    except _NotApplicable as exc:
        return Verdict(False, False, f"not applicable: {exc}")
    step, init, combos = program.step, program.init, range(1 << len(control))
    seen = {init}
    queue = deque([init])
    while queue:
        state = queue.popleft()
        for inputs in combos:
            nxt = step(state, inputs)
            if nxt is None:
                kind, port = program.differences()
                if kind == "differs":
                    return Verdict(False, True, f"gold and gate give output {port} different values at a reachable "
                                                f"state ({len(seen)} states searched)", len(seen))
                return Verdict(False, False, f"a difference may reach output {port} through the data path "
                                             f"({len(seen)} states searched)", len(seen))
            if nxt not in seen:
                if len(seen) >= max_states:
                    return Verdict(False, False, f"more than {max_states} reachable states", len(seen))
                seen.add(nxt)
                queue.append(nxt)
    return Verdict(True, False, f"all {len(seen)} reachable states of the data-independent logic "
                                f"({len(program.layout)} registers, {len(control)} control input bits): no difference "
                                f"reaches an output ({program.followed} cells of the data path followed)", len(seen))
