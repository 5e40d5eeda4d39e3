"""A filter's update as a program for the sequential core (``hw/sequencer.py``).

A filter that needs an update every second (a ship's roll, a speed log) has no use for a
datapath that does it in one clock: what it needs is few logic cells. The sequential core runs
the update one operation at a time on one adder, one multiplier, one divider and one square
root, with every value in block memory. Its program is the update itself: the variant's stage
functions run once on :class:`ProgramOps`, which records each primitive operation of the
operations layer (``kfpga/core/ops.py``) with its operands, in the order the model computes them.
The core executes exactly those operations, each with the same rounding and overflow rule as
the model, so it computes the model's integers by construction (and the tests check it).

What is decided here, once per config:

* the values: every operation's exact width (Amaranth's rules, as :class:`~kfpga.core.ops.WidthOps`),
  and so the width of the core's words and of its multiplier, divider and square root;
* the registers: constants and reset states at fixed addresses, the samples of one update at
  fixed addresses, every intermediate in a register that is free again after its last use
  (linear-scan allocation of a straight-line program), and each channel's state in its own
  block (the address of state ``k`` of channel ``c`` is ``base | c << bits | k``);
* the end of the update: each output field copied to the output word, then each next state
  copied to its channel's block (a state whose next value is another state's present value
  goes through a register first).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kfpga.core.fixed import Overflow, Rounding
from kfpga.core.ops import Fx, Ops, const_width, quotient_bits

__all__ = ["Instruction", "Program", "ProgramOps", "build_program", "OPS", "ROUNDINGS"]

#: The operations of the core, in the order of their opcodes.
OPS = ("move", "add", "sub", "neg", "shl", "abs", "lt", "mux", "mul", "rq", "div", "sqrt", "out")
#: Rounding rules in the order of their codes in an instruction.
ROUNDINGS = tuple(Rounding)


@dataclass(frozen=True)
class Instruction:
    """One operation: ``dst = op(a, b, c)``.

    ``shift``: the constant left shift of ``shl``, the right shift of ``rq`` (``src_frac -
    frac``, negative: a left shift), the dividend's left shift of ``div``, the radicand's of
    ``sqrt`` (negative: a floor right shift). ``width``: the target format's width of ``rq`` and
    ``sqrt``, the quotient format's of ``div``. ``rounding`` and ``wrap``: ``rq``'s rules.
    ``out`` copies ``a`` into output field ``dst``.
    """

    op: str
    dst: int = 0
    a: int = 0
    b: int = 0
    c: int = 0
    shift: int = 0
    width: int = 0
    rounding: int = 0
    wrap: bool = False


@dataclass(frozen=True)
class _Node:
    op: str
    args: tuple
    width: int
    shift: int = 0
    fmt: object = None
    key: object = None  # input: ("state" | "sample", name); const: raw


@dataclass
class _V:
    """A traced value: its node and exact signed width."""

    node: int
    width: int


class ProgramOps(Ops):
    """Records the primitive operations of an update (see module docstring)."""

    def __init__(self, formats):
        super().__init__(formats)
        self.nodes = []

    def _new(self, op, args=(), width=1, **kw):
        self.nodes.append(_Node(op, tuple(a.node for a in args), width, **kw))
        return _V(len(self.nodes) - 1, width)

    def _input(self, raw, fmt, name):
        return self._new("input", width=fmt.width, key=raw)

    def _const(self, raw, fmt, value, name):
        return self._new("const", width=const_width(raw, fmt), key=raw)

    def _zero(self):
        return self._new("const", width=1, key=0)

    def _shl(self, x, n):
        return self._new("shl", (x,), x.width + n, shift=n)

    def _add(self, x, y):
        return self._new("add", (x, y), max(x.width, y.width) + 1)

    def _sub(self, x, y):
        return self._new("sub", (x, y), max(x.width, y.width) + 1)

    def _neg(self, x):
        return self._new("neg", (x,), x.width + 1)

    def _mul(self, x, y):
        return self._new("mul", (x, y), x.width + y.width)

    def _abs(self, x):
        return self._new("abs", (x,), x.width + 1)

    def _lt(self, x, y):
        return self._new("lt", (x, y), 2)

    def _mux(self, cond, x, y):
        return self._new("mux", (cond, x, y), max(x.width, y.width))

    def _rq(self, raw, src_frac, fmt, name):
        return self._new("rq", (raw,), fmt.width, shift=src_frac - fmt.frac_bits, fmt=fmt), None

    def _div(self, num, den, shift, fmt, name):
        return self._new("div", (num, den), fmt.width, shift=shift, fmt=fmt), None

    def _sqrt(self, raw, shift, fmt, name):
        return self._new("sqrt", (raw,), fmt.width, shift=shift, fmt=fmt), None

    def _any(self, flags):
        return None


@dataclass(frozen=True)
class Program:
    """The update of one config and variant, ready for the core.

    ``instructions``: the program; ``init``: the register file's power-up words (constants,
    every channel's reset state); ``state_addrs``: ``{state name: address for channel 0}``;
    ``sample_addrs``: ``{input name: address}``; ``outputs``: the output fields in order, with
    their widths; ``width``: the word width; ``mul_widths``, ``dividend_bits``, ``divisor_bits``,
    ``quotient_bits``, ``radicand_bits``: the units' widths; ``state_base``, ``state_bits``,
    ``depth``: the register file's layout (state ``k`` of channel ``c`` is at
    ``state_base | c << state_bits | k``).
    """

    instructions: tuple
    init: tuple
    state_addrs: dict
    sample_addrs: dict
    outputs: tuple
    width: int
    mul_widths: tuple
    dividend_bits: int
    divisor_bits: int
    quotient_bits: int
    radicand_bits: int
    state_base: int
    state_bits: int
    depth: int
    channel_bits: int

    @property
    def address_bits(self):
        return max(1, (self.depth - 1).bit_length())

    def count(self, op):
        return sum(i.op == op for i in self.instructions)


def _bits(n):
    return max(1, math.ceil(math.log2(n))) if n > 1 else 1


def build_program(config, variant, *, channels=1, channel_bits=None):
    """The :class:`Program` of ``config``'s ``variant`` for a core of ``channels`` channel states
    (``channel_bits``: the width of the channel number, default the fewest that number them)."""
    spec_variant = config.spec.variants[variant]
    ops = ProgramOps(config.formats)
    k = ops.constants(config.constants(variant))
    states = spec_variant.state_for(config.params)
    x = {name: ops.input(("state", name), config.point_format(point), name) for name, point in states}
    u = {name: ops.input(("sample", name), config.input_format, name) for name in config.inputs}
    x_next, outs = spec_variant.update(ops, k, x, u)
    nodes = ops.nodes
    results = [(name, outs[name]) for name in (o.name for o in config.outputs)]
    finals = [(name, x_next[name]) for name, _ in states]
    for label, value in results + finals:
        if not isinstance(value, Fx):
            raise TypeError(f"{label}: the update must give Fx values")
    live, order = _live(nodes, results, finals)

    # fixed addresses: constants, then samples; temporaries after them; states in their blocks
    addr, consts = {}, {}
    for i in sorted(live):
        n = nodes[i]
        if n.op == "const":
            consts.setdefault(n.key, len(consts))
            addr[i] = consts[n.key]
    sample_addrs = {name: len(consts) + j for j, name in enumerate(config.inputs)}
    state_names = [name for name, _ in states]
    temp_of, copy_regs, next_temp = _allocate(nodes, order, results, finals, len(consts) + len(sample_addrs))
    stride_bits = _bits(len(state_names))
    cbits = channel_bits if channel_bits is not None else _bits(channels)
    state_base = 1 << max(_bits(next_temp), stride_bits + cbits)
    state_addrs = {name: state_base + j for j, name in enumerate(state_names)}
    for i in live:
        n = nodes[i]
        if n.op == "input":
            kind, name = n.key
            addr[i] = state_addrs[name] if kind == "state" else sample_addrs[name]
    addr.update(temp_of)
    depth = state_base + (1 << (stride_bits + cbits))
    program, width, sizes = _instructions(nodes, order, addr, results, finals, copy_regs, state_addrs)

    init = [0] * depth
    for raw, a in consts.items():
        init[a] = raw & ((1 << width) - 1)
    reset = config.reset_state(variant)
    for c in range(min(channels, 1 << cbits)):
        for name, a in state_addrs.items():
            init[a | c << stride_bits] = reset[name] & ((1 << width) - 1)
    outputs = tuple((o.name, config.output_format(o.name).width) for o in config.outputs)
    return Program(tuple(program), tuple(init), state_addrs, sample_addrs, outputs, width,
                   (sizes["mul_a"], sizes["mul_b"]), sizes["dividend"], sizes["divisor"], sizes["quotient"],
                   sizes["radicand"], state_base, stride_bits, depth, cbits)


def _live(nodes, results, finals):
    """Every node an output, a next state or an overflow flag needs (a write that can overflow
    counts even if nothing reads it: its flag is part of the sample's overflow bit), and the
    operations among them in program order."""
    live = set()
    todo = [v.raw.node for _, v in results + finals] + [i for i, n in enumerate(nodes) if n.op in ("rq", "div", "sqrt")]
    while todo:
        i = todo.pop()
        if i not in live:
            live.add(i)
            todo.extend(nodes[i].args)
    return live, [i for i in range(len(nodes)) if i in live and nodes[i].op not in ("input", "const")]


def _allocate(nodes, order, results, finals, temp_base):
    """Temporary registers from ``temp_base`` on, reused once their value is read for the last
    time: ``(temp_of, copy_regs, next_temp)``. At the end of the update the outputs are read
    first (they may read a present state), then the states; a next state that is another
    state's present value is copied to a register (``copy_regs``) first."""
    uses = {}
    for pos, i in enumerate(order):
        for a in nodes[i].args:
            uses[a] = pos
    tail = len(order)
    copies = [v.raw.node for name, v in finals
              if nodes[v.raw.node].op == "input" and nodes[v.raw.node].key != ("state", name)]
    for node in [v.raw.node for _, v in results] + copies + [v.raw.node for _, v in finals]:
        uses[node] = tail + 1  # read at the end
    for pos, i in enumerate(order):
        uses.setdefault(i, pos + 1)  # read by nothing (a write kept for its flag): free after it
    free, next_temp, temp_of = [], temp_base, {}
    releases = {}
    for node, last in uses.items():
        releases.setdefault(last, []).append(node)
    for pos, i in enumerate(order):
        # operands read for the last time by this operation
        free += [temp_of[done] for done in releases.get(pos, []) if done in temp_of]
        if free:
            reg = free.pop()
        else:
            reg, next_temp = next_temp, next_temp + 1
        temp_of[i] = reg
    copy_regs = {}
    for node in copies:
        if free:
            copy_regs[node] = free.pop()
        else:
            copy_regs[node], next_temp = next_temp, next_temp + 1
    return temp_of, copy_regs, next_temp


def _instructions(nodes, order, addr, results, finals, copy_regs, state_addrs):
    """The instructions, the register width and the units' sizes (``mul_a``, ``mul_b``,
    ``dividend``, ``divisor``, ``quotient``, ``radicand``)."""
    program, width = [], 2
    sizes = dict.fromkeys(("mul_a", "mul_b", "dividend", "divisor", "quotient", "radicand"), 1)
    for i in order:
        n = nodes[i]
        args = [addr[a] for a in n.args]
        arg_widths = [nodes[a].width for a in n.args]
        width = max(width, n.width, *arg_widths)
        if n.op == "mul":
            wa, wb = arg_widths
            if wa < wb:  # the wider operand on the multiplier's first input
                args, (wa, wb) = args[::-1], (wb, wa)
            sizes["mul_a"], sizes["mul_b"] = max(sizes["mul_a"], wa), max(sizes["mul_b"], wb)
            program.append(Instruction("mul", addr[i], *args))
        elif n.op == "rq":
            fmt = n.fmt
            program.append(Instruction("rq", addr[i], args[0], shift=n.shift, width=fmt.width,
                                       rounding=ROUNDINGS.index(Rounding(fmt.rounding)),
                                       wrap=fmt.overflow is Overflow.WRAP))
            width = max(width, arg_widths[0] + 1, arg_widths[0] - n.shift + 1)
        elif n.op == "div":
            sizes["dividend"] = max(sizes["dividend"], arg_widths[0] + n.shift)
            sizes["divisor"] = max(sizes["divisor"], arg_widths[1])
            sizes["quotient"] = max(sizes["quotient"], quotient_bits(n.fmt))
            program.append(Instruction("div", addr[i], *args, shift=n.shift, width=n.fmt.width))
        elif n.op == "sqrt":
            sizes["radicand"] = max(sizes["radicand"], arg_widths[0] + max(n.shift, 0))
            program.append(Instruction("sqrt", addr[i], args[0], shift=n.shift, width=n.fmt.width))
        elif n.op == "shl":
            program.append(Instruction("shl", addr[i], args[0], shift=n.shift))
        else:
            program.append(Instruction(n.op, addr[i], *args))
    program += [Instruction("out", j, addr[v.raw.node]) for j, (_, v) in enumerate(results)]
    program += [Instruction("move", reg, addr[node]) for node, reg in copy_regs.items()]
    for name, v in finals:
        src = copy_regs.get(v.raw.node, addr[v.raw.node])
        if src != state_addrs[name]:
            program.append(Instruction("move", state_addrs[name], src))
    sizes["radicand"] += sizes["radicand"] % 2  # the restoring root takes two radicand bits a step
    return program, width + 1, sizes  # a sign bit to spare: every value is held sign-extended


_ALU = {"move": lambda a, b, c, n: a, "add": lambda a, b, c, n: a + b, "sub": lambda a, b, c, n: a - b,
        "neg": lambda a, b, c, n: -a, "shl": lambda a, b, c, n: a << n, "abs": lambda a, b, c, n: abs(a),
        "lt": lambda a, b, c, n: int(a < b), "mux": lambda a, b, c, n: b if a else c, "mul": lambda a, b, c, n: a * b}


def execute(program, samples, channels):
    """The core's semantics in Python: run ``program`` on ``samples`` (``[{input: code}]``) of
    ``channels`` (a channel number per sample), from the power-up register file. Returns
    ``([{output: raw}], [overflow])``, one per sample. Each operation is the model's own
    integer function (``kfpga/core/ops.py``, ``kfpga/core/fixed.py``) on the values it reads."""
    from kfpga.core.fixed import QFormat, requantize
    from kfpga.core.ops import divide, square_root

    mask, sign = (1 << program.width) - 1, 1 << (program.width - 1)
    regs = [(v & mask) - ((v & sign) << 1) for v in program.init]
    outs, flags = [], []
    for sample, channel in zip(samples, channels, strict=True):

        def at(a, channel=channel):
            return a | channel << program.state_bits if a >= program.state_base else a

        for name, a in program.sample_addrs.items():
            regs[a] = int(sample[name])
        word, flag = [0] * len(program.outputs), False
        for ins in program.instructions:
            a, b, c = regs[at(ins.a)], regs[at(ins.b)], regs[at(ins.c)]
            if ins.op == "out":
                word[ins.dst] = a
                continue
            if ins.op == "rq":
                fmt = QFormat(ins.width, 0, ROUNDINGS[ins.rounding], "wrap" if ins.wrap else "saturate")
                value, hit = requantize(a, ins.shift, fmt)
            elif ins.op == "div":
                value, hit = divide(a, b, ins.shift, ins.width - 1)
            elif ins.op == "sqrt":
                value, hit = square_root(a, ins.shift, (1 << (ins.width - 1)) - 1)
            else:
                hit = False
                value = _ALU[ins.op](a, b, c, ins.shift)
            flag |= bool(hit)
            regs[at(ins.dst)] = int(value)
        outs.append(dict(zip((name for name, _ in program.outputs), word, strict=True)))
        flags.append(flag)
    return outs, flags


def handshake_twin(program, width=8):
    """A short, narrow copy of ``program`` for the formal stream checks of its core.

    The sequential core's handshake (take a sample, run the program, give the estimate) does not
    depend on what the program computes: only on how long it runs, which is the length of each
    kind of operation. The twin keeps one operation of each kind the program has (a division
    and a square root with units 3 and 2 bits wide; one of the adder's, which all take the same
    cycles), one output copy and one state write, on
    ``width``-bit words, so that a bounded check covers whole updates from reset."""
    import dataclasses

    kept, seen = [], set()
    for ins in program.instructions:
        # the operations of the adder (move, add, ..., mux) all take READ, EXEC, WRITE: one stands for them
        kind = ins.op if ins.op in ("rq", "mul", "div", "sqrt") else "alu"
        if kind not in seen and ins.op not in ("out", "move"):
            seen.add(kind)
            kept.append(ins)
    kept.append(next(i for i in program.instructions if i.op == "out"))
    # the registers the kept operations read and write, renumbered from 0 (the register file then
    # as small as they need: its contents, three copies, are state the solver carries), then one
    # state per channel block
    plain = sorted({a for ins in kept for a in (ins.a, ins.b, ins.c, *([] if ins.op == "out" else [ins.dst]))
                    if a < program.state_base} | set(program.sample_addrs.values()))
    where = {a: j for j, a in enumerate(plain)}
    state_bits = 1
    region = 1 << (state_bits + program.channel_bits)
    base = 1 << max(_bits(len(plain)), state_bits + program.channel_bits)

    def moved(a):
        return base | (a - program.state_base) >> program.state_bits << state_bits if a >= program.state_base else where[a]

    kept = [dataclasses.replace(ins, dst=ins.dst if ins.op == "out" else moved(ins.dst), a=moved(ins.a), b=moved(ins.b),
                                c=moved(ins.c)) for ins in kept]
    kept.append(Instruction("move", base, kept[0].dst))
    mask = (1 << width) - 1
    init = [0] * (base + region)
    for a, j in where.items():
        init[j] = program.init[a] & mask
    for c in range(1 << program.channel_bits):
        init[base | c << state_bits] = program.init[program.state_base | c << program.state_bits] & mask
    first_state = next(iter(program.state_addrs))
    return dataclasses.replace(program, instructions=tuple(kept), init=tuple(init), state_addrs={first_state: base},
                               sample_addrs={n: where[a] for n, a in program.sample_addrs.items()}, width=width,
                               mul_widths=(4, 4), dividend_bits=6, divisor_bits=3, quotient_bits=3, radicand_bits=4,
                               state_base=base, state_bits=state_bits, depth=base + region)
