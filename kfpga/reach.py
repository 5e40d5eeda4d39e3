"""Equivalence of a mutant whose change lies in the data-independent part of a block, by
explicit-state reachability (``kfpga/mutate.py``).

A time-varying Kalman core carries two kinds of state. Its estimate depends on the samples;
its covariance, its gains and its schedule do not: from the fixed reset they follow one
trajectory, whatever the samples, which settles after a few dozen updates. A mutant that
changes a covariance bit the trajectory never sets cannot be seen at the outputs, and no bench
can kill it; but neither k-induction nor a bounded check can show it: induction starts from
states the trajectory never visits, and a bounded check would have to run through hundreds of
cycles of divisions and products.

This check decides such mutants exactly. On the miter of the original block (gold) and the
mutant (gate), it marks every net that depends on a data input (the samples) and calls the rest
*data-independent*: its registers step from the reset state by the control inputs alone
(valid, ready, channel, reset), whatever the samples are. When the mutation touches only
data-independent logic, the two designs' data paths are the same logic, and they can differ only
if one of them reads a data-independent value that differs between gold and gate. So the check
enumerates every reachable state of the data-independent registers of both designs, under every
combination of the control inputs, and compares at each step every data-independent value that
the data path or an output reads, gold against gate. If the search ends (no new state) with no
difference, the mutant is equivalent: no input sequence can tell them apart. If a difference
appears, or the search exceeds its state budget, it is not proven here.

The netlist is Yosys's JSON of the miter, evaluated word by word with the semantics of Yosys's
internal cells; each step is compiled into one Python function (written here, not a simulator
library: no Python simulator reads a Yosys netlist and lets a search set and save its state).
"""

from __future__ import annotations

import json
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


def netlist_json(gold_il, gate_il, folder):
    """Write the flat RTLIL modules ``gold`` and ``gate`` as one Yosys JSON file; its path."""
    from kfpga.formal import yosys

    ok, log = yosys(f"read_rtlil {gold_il}\nread_rtlil {gate_il}\nwrite_json pair.json\n", folder)
    if not ok:
        raise RuntimeError(f"the designs could not be read: {log.strip()[-300:]}")
    return folder / "pair.json"


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
            rename = {}
            for name, port in module["ports"].items():
                for i, b in enumerate(port["bits"]):
                    if port["direction"] == "input" and isinstance(b, int):
                        rename[b] = ("in", name, i)
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
        self.driver = {}  # net bit -> (cell, port, index)
        for key, cell in self.cells.items():
            for port, bits in cell["connections"].items():
                if cell["port_directions"][port] == "output":
                    for i, b in enumerate(bits):
                        self.driver[b] = (key, port, i)
        self.tainted = self._taint(data_inputs)

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


def _cell_expr(kind, p, a, b, s, widths):
    """The Python expression of one cell's output word (Yosys internal-cell semantics)."""
    wa, wb, wy = widths
    mask_y = (1 << wy) - 1
    both = p.get("A_SIGNED", 0) and p.get("B_SIGNED", 0)

    def ext(x, w, signed):
        return f"_sx({x}, {w})" if signed and w else x

    if kind in ("$add", "$sub", "$mul", "$and", "$or", "$xor", "$xnor"):
        op = {"$add": "+", "$sub": "-", "$mul": "*", "$and": "&", "$or": "|", "$xor": "^", "$xnor": "^"}[kind]
        body = f"({ext(a, wa, both)}) {op} ({ext(b, wb, both)})"
        return f"(~({body})) & {mask_y}" if kind == "$xnor" else f"({body}) & {mask_y}"
    if kind in ("$neg", "$not", "$pos"):
        x = ext(a, wa, p.get("A_SIGNED", 0))
        return {"$neg": f"(-({x})) & {mask_y}", "$not": f"(~({x})) & {mask_y}", "$pos": f"({x}) & {mask_y}"}[kind]
    if kind == "$logic_not":
        return f"int(({a}) == 0)"
    if kind == "$logic_and":
        return f"int(({a}) != 0 and ({b}) != 0)"
    if kind == "$logic_or":
        return f"int(({a}) != 0 or ({b}) != 0)"
    if kind == "$reduce_and":
        return f"int(({a}) == {(1 << wa) - 1})"
    if kind in ("$reduce_or", "$reduce_bool"):
        return f"int(({a}) != 0)"
    if kind in ("$reduce_xor", "$reduce_xnor"):
        par = f"(bin({a}).count('1') & 1)"
        return par if kind == "$reduce_xor" else f"(1 - {par})"
    if kind in ("$eq", "$eqx", "$ne", "$nex", "$lt", "$le", "$gt", "$ge"):
        op = {"$eq": "==", "$eqx": "==", "$ne": "!=", "$nex": "!=", "$lt": "<", "$le": "<=", "$gt": ">", "$ge": ">="}[kind]
        return f"int(({ext(a, wa, both)}) {op} ({ext(b, wb, both)}))"
    if kind in ("$shl", "$sshl"):
        return f"(({ext(a, wa, p.get('A_SIGNED', 0))}) << ({b})) & {mask_y}"
    width = max(wa, wy)
    mask_w = (1 << width) - 1
    a_ext = ext(a, wa, p.get("A_SIGNED", 0))
    if kind == "$shr":
        return f"((({a_ext}) & {mask_w}) >> ({b})) & {mask_y}"
    if kind == "$sshr":
        if p.get("A_SIGNED", 0):
            return f"(({a_ext}) >> ({b})) & {mask_y}"
        return f"((({a_ext}) & {mask_w}) >> ({b})) & {mask_y}"
    if kind in ("$shift", "$shiftx"):
        # bits shifted in from outside A are x for $shiftx: both designs read them as 0
        base = f"(({a_ext}) & {mask_w})" if kind == "$shift" else f"({a})"
        if p.get("B_SIGNED", 0):
            return f"(_shift({base}, _sx({b}, {wb})) & {mask_y})"
        return f"(({base}) >> ({b})) & {mask_y}"
    if kind == "$mux":
        return f"(({b}) if ({s}) else ({a}))"
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
    compared: int
    net: object
    readers: tuple = ()  # what reads each compared bit: "cell name" or "output port"
    differ: list = None  # after a step gave None: the XOR of gold's and gate's compared bits

    def differences(self):
        """What read different values at the last step that gave ``None``."""
        if not self.differ:
            return []
        x = self.differ[-1]
        return sorted({self.readers[i] for i in range(len(self.readers)) if (x >> i) & 1})

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
    layout, init, offset = [], 0, 0  # (register, offset in the state word, width, mask of its kept bits)
    for key, cell in di.items():
        if cell["type"] != "$dff":
            continue
        mask = value = 0
        for i, q in enumerate(cell["connections"]["Q"]):
            if q not in tainted:
                bit = net.init.get(q)
                if bit not in ("0", "1"):
                    raise _NotApplicable(f"register {key[1]} has no reset value for bit {i}")
                mask |= 1 << i
                value |= int(bit) << i
        width = len(cell["connections"]["Q"])
        layout.append((key, offset, width, mask))
        init |= value << offset
        offset += width
    control_var = {("in", port, i): ("_i", k) for k, (port, i) in enumerate(control)}

    def source(bit):
        if bit in tainted:
            return None  # a data bit a bitwise cell carries to a data bit: never read here
        if bit in control_var:
            return control_var[bit]
        if bit[0] == "in":
            raise _NotApplicable(f"input {bit[1]}[{bit[2]}] is read but is neither data nor a control input")
        key, _, index = net.driver[bit]
        return variables[key], index

    order, done, visiting = [], set(), set()  # the combinational cells, each after what it reads

    def visit(key):
        if key in done:
            return
        if key in visiting:
            raise _NotApplicable(f"a combinational loop through {key[1]}")
        visiting.add(key)
        cell = di[key]
        if cell["type"] != "$dff":
            for port, bits in cell["connections"].items():
                if cell["port_directions"][port] == "input":
                    for b in bits:
                        if isinstance(b, tuple) and b[0] != "in" and b not in tainted:
                            visit(net.driver[b][0])
        visiting.discard(key)
        done.add(key)
        order.append(key)

    for key in di:
        visit(key)
    lines = ["def step(_s, _i):"]
    lines += [f"    {variables[key]} = (_s >> {off}) & {(1 << width) - 1}" for key, off, width, _ in layout]
    for key in order:
        cell = di[key]
        if cell["type"] == "$dff":
            continue
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
            lines += [f"    _sel = {s}", f"    {variables[key]} = {expr}"]
        else:
            widths = (len(conn.get("A", [])), len(conn.get("B", [])), len(conn["Y"]))
            lines.append(f"    {variables[key]} = {_cell_expr(cell['type'], p, a, b, s, widths)}")
    gold_bits, gate_bits, readers = _interface(net)
    if gold_bits:
        lines.append(f"    _g, _t = {_bits_expr(gold_bits, source)}, {_bits_expr(gate_bits, source)}")
        lines.append("    if _g != _t:")
        lines.append("        _differ.append(_g ^ _t)")
        lines.append("        return None")
    nxt = []
    for key, off, _, mask in layout:
        d = _bits_expr(di[key]["connections"]["D"], source)
        nxt.append(f"((({d}) & {mask}) << {off})" if off else f"(({d}) & {mask})")
    lines.append("    return " + (" | ".join(nxt) if nxt else "0"))
    differ = []
    scope = {"_sx": _sx, "_shift": _shift, "_differ": differ}
    exec(compile("\n".join(lines), "<reach step>", "exec"), scope)  # the step, generated from the netlist above
    return Program(scope["step"], init, tuple(control), tuple(layout), len(gold_bits), net, tuple(readers), differ)


def _interface(net):
    """``(gold bits, gate bits)``: every data-independent bit that the data path (a cell with an
    output bit that depends on the data) or an output reads in gold, and the same bit in gate."""
    tainted = net.tainted
    gold_bits, gate_bits, readers = [], [], []

    def pair(g, t, where):
        if (g in tainted) != (t in tainted):
            raise _NotApplicable(f"{where} depends on the data in one design only")
        if g not in tainted:
            gold_bits.append(g)
            gate_bits.append(t)
            readers.append(where)

    for (side, name), cell in net.cells.items():
        if side != "gold":
            continue
        twin = net.cells.get(("gate", name))
        if twin is None or twin["type"] != cell["type"]:
            raise _NotApplicable(f"cell {name} has no twin in the mutant")
        outs = _outputs(cell)
        if any((a in tainted) != (b in tainted) for a, b in zip(outs, _outputs(twin), strict=True)):
            raise _NotApplicable(f"an output of {name} depends on the data in one design only")
        if cell["type"] == "$dff" or not any(b in tainted for b in outs):
            continue  # state, or data-independent logic: searched, not read by the data path
        for port, bits in cell["connections"].items():
            if cell["port_directions"][port] == "input":
                for g, t in zip(bits, twin["connections"][port], strict=True):
                    pair(g, t, f"an input of {name}")
    for port in net.outputs:
        for g, t in zip(net.out_bits["gold"][port], net.out_bits["gate"][port], strict=True):
            pair(g, t, f"output {port}")
    return gold_bits, gate_bits, readers


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
                return Verdict(False, True, f"gold and gate give {', '.join(program.differences()[:3])} different "
                                            f"values at a reachable state ({len(seen)} states searched)", len(seen))
            if nxt not in seen:
                if len(seen) >= max_states:
                    return Verdict(False, False, f"more than {max_states} reachable states", len(seen))
                seen.add(nxt)
                queue.append(nxt)
    return Verdict(True, False, f"all {len(seen)} reachable states of the data-independent logic "
                                f"({len(program.layout)} registers, {len(control)} control input bits) give the data "
                                f"path and the outputs the same {program.compared} bits", len(seen))
