"""The sequential core: any variant's update run one operation at a time (``kfpga/core/program.py``).

A slow filter (a ship's roll predicted every second, a speed log) needs few logic cells, not a
datapath that updates in one clock. :class:`SequentialCore` executes the update's program: one
operation at a time on one adder, one multiplier, one restoring divider (``hw/divider.py``) and
one restoring square root (``hw/sqrt.py``), with the constants, the samples, the intermediates
and every channel's state in one register file in block memory (Cyclone II M4K, three read
ports as three copies of it). The operations are the model's own integer functions, so the core
computes the model's integers for any update the operations layer can write, the square-root
covariance forms included.

Each operation takes three cycles, each with at most one carry chain, one multiplier or one
shifter between registers (so that it meets 50 MHz on the -8 part): READ (the instruction is in
the program memory's read register: its operands are addressed, its operation and its target
format's constants are registered), EXEC (the operands are read and the result computed), WRITE
(the result is written). A requantisation takes two more (its value and rounding addend are
registered in EXEC; then their sum shifted, a carry chain into a shifter; then the saturation), a
product one more (the multiplier's output is registered), a division and a square root their
unit's latency and four more (to shift its operand, to start it, to bound its result, to sign
it); an output copy has no WRITE.
"""

from __future__ import annotations

import operator
from functools import reduce

from amaranth import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib.memory import Memory

from kfpga.core.board import MAX_SENSORS
from kfpga.core.fixed import Rounding
from kfpga.core.ops import Fx
from kfpga.core.program import OPS, ROUNDINGS, build_program, handshake_twin
from kfpga.hw.core import Core, write_estimate
from kfpga.hw.divider import Divider
from kfpga.hw.sqrt import SquareRoot
from kfpga.hw.storage import m4k_blocks, select

__all__ = ["SequentialCore", "encode", "make_core"]

#: Fields of an instruction word, LSB first: (name, bits) with the address width filled in.
_FIELDS = ("op", "dst", "a", "b", "c", "shift", "width", "rounding", "wrap")


def _layout(program):
    abits = program.address_bits
    return {"op": 4, "dst": abits, "a": abits, "b": abits, "c": abits, "shift": 8, "width": 7, "rounding": 3, "wrap": 1}


def encode(program):
    """The program memory's words, one per instruction."""
    layout = _layout(program)
    words = []
    for ins in program.instructions:
        values = {"op": OPS.index(ins.op), "dst": ins.dst, "a": ins.a, "b": ins.b, "c": ins.c,
                  "shift": ins.shift & 0xFF, "width": ins.width, "rounding": ins.rounding, "wrap": int(ins.wrap)}
        word, offset = 0, 0
        for name in _FIELDS:
            bits = layout[name]
            if not 0 <= values[name] < 1 << bits:
                raise ValueError(f"instruction field {name} = {values[name]} does not fit {bits} bits")
            word |= values[name] << offset
            offset += bits
        words.append(word)
    return words


class SequentialCore(Core):
    """A filter's update as a program on one adder, multiplier, divider and square root.

    The input is accepted in cycle ``c``; the samples go to the register file, one per cycle;
    the program runs; the estimate is on ``o`` in cycle ``c + cycles_per_update`` if ``o`` is
    free, and the next input can be accepted in that same cycle. After reset the core first
    writes every channel's reset state into the register file (``channels`` times the number of
    states, cycles during which it takes no input). A channel number outside
    ``0..channels-1`` reads a zero state and updates nothing.

    Parameters
    ----------
    config:
        The shared :class:`~kfpga.core.config.FilterConfig`.
    variant:
        The variant whose update the core runs.
    channels:
        Independent channel states (1..256), each a block of the register file.

    Members
    -------
    i : In(stream.Signature(input_layout(config, channels)))
        Samples.
    o : Out(stream.Signature(output_layout(config, channels)))
        Estimates, one per sample.
    overflow : Out(1)
        Sticky: some write saturated (or wrapped) since reset.
    """

    max_channels = MAX_SENSORS  # every channel's state a block of the register file

    def __init__(self, config, variant, *, channels=1, program=None):
        super().__init__(config, variant, channels)
        self.program = program or build_program(config, variant, channels=channels,
                                                channel_bits=len(self.i.payload.channel))

    def formal_twin(self):
        """The core on a short, narrow copy of its program (:func:`kfpga.core.program.handshake_twin`):
        the same handshake, whole updates within a bounded check's reach."""
        from kfpga.hw.generate import figures_only

        figures_only(self)  # the twin is built instead of this core
        return SequentialCore(self.config, self.variant, channels=self.channels, program=handshake_twin(self.program))

    @property
    def startup_cycles(self):
        """Cycles after reset before the first sample is taken (the reset state written)."""
        return self.channels << self.program.state_bits

    def _op_cycles(self, ins):
        p = self.program
        # READ, EXEC, WRITE; rq: SHIFT and SATURATE between; a product: PRODUCT; a unit: PREP,
        # START, its latency (quotient or root bits + 1), BOUND and SIGN; out: no WRITE
        return {"out": 2, "rq": 5, "mul": 4, "div": p.quotient_bits + 8, "sqrt": p.radicand_bits // 2 + 8}.get(ins.op, 3)

    @property
    def cycles_per_update(self):
        """Cycles from accepting one sample to being able to accept the next (``o`` always ready)."""
        return 1 + len(self.program.sample_addrs) + sum(self._op_cycles(i) for i in self.program.instructions) + 1

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.cycles_per_update

    @property
    def m4k_blocks(self):
        """Block memories: three copies of the register file and the program."""
        p = self.program
        return 3 * m4k_blocks(p.depth, p.width) + m4k_blocks(len(p.instructions), sum(_layout(p).values()))

    def elaborate(self, platform):
        b = _Build(self, Module())
        b.memories()
        b.decode()
        b.constants()
        b.alu()
        b.requantiser()
        b.units()
        b.schedule()
        return b.m


class _Build:
    """The parts of a :class:`SequentialCore`, built one method at a time into ``m``; each
    method keeps as attributes the signals the later ones use."""

    def __init__(self, core, m):
        self.core, self.m, self.p = core, m, core.program
        self.w = self.p.width
        self.layout = _layout(self.p)
        self.abits = self.p.address_bits
        self.used = {i.op for i in self.p.instructions}
        self.rqs = [i for i in self.p.instructions if i.op == "rq"]
        self.has_div, self.has_sqrt = bool(self.p.count("div")), bool(self.p.count("sqrt"))
        self.has_units = self.has_div or self.has_sqrt

    def memories(self):
        """The program, and the register file three times (one per read port)."""
        m, p = self.m, self.p
        rom = Memory(shape=unsigned(sum(self.layout.values())), depth=max(len(p.instructions), 2), init=encode(p))
        m.submodules.program = rom
        self.fetch = rom.read_port()
        files = [Memory(shape=unsigned(self.w), depth=p.depth, init=p.init) for _ in range(3)]
        for n, mem in enumerate(files):
            m.submodules[f"registers_{'abc'[n]}"] = mem
        self.reads = [mem.read_port() for mem in files]
        writes = [mem.write_port() for mem in files]
        self.wr_addr, self.wr_data = Signal(self.abits, name="wr_addr"), Signal(self.w, name="wr_data")
        self.wr_en = Signal(name="wr_en")
        for port in writes:
            m.d.comb += [port.addr.eq(self.wr_addr), port.data.eq(self.wr_data), port.en.eq(self.wr_en)]

    def is_state(self, field):
        return field[self.abits - 1] if self.p.state_base == 1 << (self.abits - 1) else Const(0, 1)

    def physical(self, field):
        """A register address; state k of channel c is at base | c << bits | k."""
        channel = self.channel
        return Mux(self.is_state(field), field | (channel << self.p.state_bits), field) if len(channel) else field

    def decode(self):
        """The instruction in the program memory's read register, and its operands: addressed in
        the first cycle of an operation (READ), read from then on."""
        m, core = self.m, self.core
        self.ins, offset = {}, 0
        for name in _FIELDS:
            self.ins[name] = self.fetch.data[offset:offset + self.layout[name]]
            offset += self.layout[name]
        self.channel = channel = Signal.like(core.i.payload.channel, name="channel")
        self.in_range = Signal(name="in_range")
        m.d.comb += self.in_range.eq(channel < core.channels if core.channels < 2 ** len(channel) else 1)
        zero_state = [Signal(name=f"zero_{n}") for n in "abc"]  # an out-of-range channel reads zero
        for port, name, z in zip(self.reads, "abc", zero_state, strict=True):
            m.d.comb += [port.addr.eq(self.physical(self.ins[name])), port.en.eq(1)]
            m.d.sync += z.eq(self.is_state(self.ins[name]) & ~self.in_range)
        self.a, self.b, self.c = (Mux(z, 0, port.data).as_signed() for port, z in zip(self.reads, zero_state, strict=True))

    def constants(self):
        """What READ registers of the instruction: its operation, and the constants of its target
        format (a table of the program's (shift, width) pairs, not shifters of run-time widths).
        Only what the program uses is built: its operations, its rounding rules, wrap-around if it
        wraps, constants as wide as its shifts and target widths (the rest could never act)."""
        p = self.p
        self.op = {name: Signal(name=f"op_{name}") if name in self.used else Const(0, 1) for name in OPS}
        self.rounding = Signal.like(self.ins["rounding"], name="k_rounding")
        self.wrap = Signal(name="k_wrap") if any(i.wrap for i in self.rqs) else Const(0, 1)
        largest = max([abs(i.shift) for i in p.instructions] + [1])
        self.table = sorted({(i.shift, i.width) for i in p.instructions if i.op in ("rq", "div", "sqrt", "shl")})
        widest = max([width for _, width in self.table] + [1])
        self.k_amount, self.k_right = Signal(range(largest + 1), name="k_amount"), Signal(name="k_right")
        # 2**(s-1), 2**s - 1
        self.k_half, self.k_fix = Signal(largest + 1, name="k_half"), Signal(largest + 1, name="k_fix")
        self.k_below = Signal(largest + 1, name="k_below")  # 2**(s-1) - 1: half an LSB less one, so no adder picks it
        # 2**(width-1) - 1, 2**width - 1
        self.k_top, self.k_mask = Signal(widest, name="k_top"), Signal(widest + 1, name="k_mask")

    def read_instruction(self):
        m, ins = self.m, self.ins
        m.d.sync += [self.op[name].eq(ins["op"] == OPS.index(name)) for name in OPS if name in self.used]
        m.d.sync += self.rounding.eq(ins["rounding"])
        if isinstance(self.wrap, Signal):
            m.d.sync += self.wrap.eq(ins["wrap"])
        with m.Switch(Cat(ins["shift"], ins["width"])):
            for sh, width in self.table:
                with m.Case((sh & 0xFF) | width << 8):
                    m.d.sync += [self.k_amount.eq(abs(sh)), self.k_right.eq(sh > 0),
                                 self.k_half.eq(1 << (sh - 1) if sh > 0 else 0),
                                 self.k_fix.eq((1 << sh) - 1 if sh > 0 else 0),
                                 self.k_below.eq((1 << (sh - 1)) - 1 if sh > 0 else 0),
                                 self.k_top.eq((1 << max(width - 1, 0)) - 1), self.k_mask.eq((1 << width) - 1)]

    def alu(self):
        """The one-cycle operations and the multiplier's registered operands; each result goes
        to one register, written in the operation's last cycle."""
        a, b, c, op = self.a, self.b, self.c, self.op
        self.result, self.flag = Signal(signed(self.w), name="result"), Signal(name="result_flag")
        self.wa, self.wb = wa, wb = self.p.mul_widths
        self.mul_a, self.mul_b = Signal(signed(wa), name="mul_a"), Signal(signed(wb), name="mul_b")
        self.alu_value = Signal(signed(self.w), name="alu")
        terms = {"add": a + b, "sub": a - b, "neg": -a, "abs": Mux(a < 0, -a, a), "lt": a < b,
                 "mux": Mux(a != 0, b, c), "shl": a << self.k_amount, "move": a}
        self.m.d.comb += self.alu_value.eq(
            reduce(operator.or_, [Mux(op[n], t, 0) for n, t in terms.items() if n in self.used], Const(0, 1)))

    def requantiser(self):
        """rq: EXEC registers the value (in ``held``, free then) and its rounding addend; SHIFT
        adds them and shifts; SATURATE saturates or wraps around."""
        m, a, w = self.m, self.a, self.w
        self.negative = negative = a < 0
        self.held = Signal(w, name="held")  # a unit's result; an rq's value
        self.addend = Signal(signed(w + 2), name="rq_addend")
        self.addend_next = Signal(signed(w + 2), name="rq_addend_next")
        k_half, k_below = self.k_half, self.k_below
        # the addends of ROUND and CONVERGENT chosen between two registered constants, half an
        # LSB and one less, by a bit of a: a multiplexer, not a carry chain (k_half and k_below
        # are 0 when nothing is shifted off); FLOOR adds nothing
        addends = {Rounding.NEAREST: k_half,
                   Rounding.ROUND: Mux(negative, k_below, k_half),  # half - 1 for a negative value
                   # the bit that becomes the LSB breaks a tie: bit s of a (s = k_amount) through the
                   # mask 2 k_half = 2**s, an AND and an OR tree, not a barrel shifter
                   Rounding.CONVERGENT: Mux((a & (k_half << 1)).any(), k_half, k_below),
                   Rounding.FIX: Mux(negative, self.k_fix, 0)}
        # a chain of multiplexers (a Verilog assign), not a case statement: an always block whose
        # inputs happen never to change would stay undefined from time zero in Icarus
        choice = Const(0, 1)
        for rule in sorted({ROUNDINGS[i.rounding] for i in self.rqs} - {Rounding.FLOOR}, key=ROUNDINGS.index):
            choice = Mux(self.rounding == ROUNDINGS.index(rule), addends[rule], choice)
        m.d.comb += self.addend_next.eq(choice)
        self.summed = Signal(signed(w + 2), name="rq_sum")
        m.d.comb += self.summed.eq(self.held.as_signed() + self.addend)
        self.moved = moved = Signal(signed(w + 2), name="rq_moved")
        top = self.k_top.as_signed()
        self.high, self.low = moved > top, moved < -top - 1
        self.bounded = Mux(self.high, top, Mux(self.low, -top - 1, moved))
        if isinstance(self.wrap, Signal):
            kept = Signal(w + 2, name="rq_kept")  # the low width bits ...
            m.d.comb += kept.eq(moved.as_unsigned() & self.k_mask)
            wrapped = (kept - ((kept & (self.k_top + 1)) << 1)).as_signed()  # ... as a signed width-bit value
            self.bounded = Mux(self.wrap, wrapped, self.bounded)

    def units(self):
        """A division or a root: its operand prepared, the unit run, its result bounded."""
        m, p, op = self.m, self.p, self.op
        self.neg_r, self.bad_r = Signal(name="neg_r"), Signal(name="bad_r")
        self.magnitude = Signal(self.w, name="magnitude")  # a unit's operand before its shift
        self.unit_done, self.unit_value, self.unit_overflow = Const(1, 1), Const(0, 1), Const(0, 1)
        self.start = Signal(name="unit_start")
        cases = []
        if self.has_div:
            div = Divider(dividend_bits=p.dividend_bits, divisor_bits=p.divisor_bits, quotient_bits=p.quotient_bits)
            m.submodules.divider = div
            self.num, self.den = Signal(p.dividend_bits, name="div_num"), Signal(p.divisor_bits, name="div_den")
            m.d.comb += [div.i.valid.eq(self.start & op["div"]), div.o.ready.eq(1),
                         div.i.payload.dividend.eq(self.num), div.i.payload.divisor.eq(self.den)]
            cases.append((op["div"], div.o.valid, div.o.payload.quotient, div.o.payload.overflow))
        if self.has_sqrt:
            root = SquareRoot(radicand_bits=p.radicand_bits)
            m.submodules.square_root = root
            self.radicand = Signal(p.radicand_bits, name="radicand")
            m.d.comb += [root.i.valid.eq(self.start & op["sqrt"]), root.o.ready.eq(1),
                         root.i.payload.radicand.eq(self.radicand)]
            cases.append((op["sqrt"], root.o.valid, root.o.payload.root, Const(0, 1)))
        if self.has_units:
            done, value, over = Signal(name="unit_done"), Signal(self.w, name="unit_value"), Signal(name="unit_overflow")
            for is_op, valid, out, ovf in cases:
                with m.If(is_op):
                    m.d.comb += [done.eq(valid), value.eq(out), over.eq(ovf)]
            self.unit_done, self.unit_value, self.unit_overflow = done, value, over

    def write(self, addr, data):
        self.m.d.comb += [self.wr_addr.eq(addr), self.wr_data.eq(data), self.wr_en.eq(1)]

    def next_instruction(self):
        m = self.m
        m.d.comb += self.pc_next.eq(self.pc + 1)
        with m.If(self.pc == len(self.p.instructions) - 1):
            m.next = "EMIT"
        with m.Else():
            m.next = "READ"

    def schedule(self):
        """The program counter and the state machine that runs the program."""
        m, p, core = self.m, self.p, self.core
        self.pc = Signal(range(len(p.instructions) + 1), name="pc")
        self.pc_next = Signal.like(self.pc, name="pc_next")
        m.d.comb += [self.pc_next.eq(self.pc), self.fetch.addr.eq(self.pc_next), self.fetch.en.eq(1)]
        m.d.sync += self.pc.eq(self.pc_next)
        self.flags = Signal(name="flags")  # the overflow flags of this update, ORed
        self.outs = {name: Signal(signed(width), name=f"out_{name}") for name, width in p.outputs}
        with m.If(core.o.valid & core.o.ready):
            m.d.sync += core.o.valid.eq(0)
        core.flag_outputs(m, [self.flags])
        with m.FSM(name="schedule") as fsm:
            self.start_states()
            with m.State("READ"):  # the instruction is here: its operands are addressed, its constants taken
                self.read_instruction()
                m.next = "EXEC"
            with m.State("EXEC"):  # the operands are here
                self.execute()
            self.arithmetic_states()
            if self.has_units:
                self.unit_states()
            with m.State("WRITE"):
                with m.If(~(self.is_state(self.ins["dst"]) & ~self.in_range)):  # never an out-of-range channel's state
                    self.write(self.physical(self.ins["dst"]), self.result)
                m.d.sync += self.flags.eq(self.flags | self.flag)
                self.next_instruction()
            with m.State("EMIT"):
                with m.If(~core.o.valid | core.o.ready):
                    m.d.sync += core.o.valid.eq(1)
                    write_estimate(m, core, self.channel, {name: Fx(reg, 0) for name, reg in self.outs.items()},
                                   [self.flags])
                    m.next = "IDLE"
        # a plain assignment (Verilog `assign`), not a case-statement output
        m.d.comb += core.i.ready.eq(fsm.ongoing("IDLE"))

    def start_states(self):
        """INIT (every channel's reset state into the register file), IDLE (a sample taken) and
        LOAD (its values into the register file, one a cycle)."""
        m, p, core = self.m, self.p, self.core
        samples = {name: Signal(signed(16), name=f"sample_{name}") for name in p.sample_addrs}
        reset_values = [Const(core.reset_state[n] & ((1 << self.w) - 1), self.w) for n in p.state_addrs]
        init_last = (core.channels << p.state_bits) - 1
        init_count = Signal(range(init_last + 1), name="init_count")
        with m.State("INIT"):
            self.write(Const(p.state_base, self.abits) | init_count, select(reset_values, init_count[:p.state_bits]))
            m.d.sync += init_count.eq(init_count + 1)
            with m.If(init_count == init_last):
                m.next = "IDLE"
        with m.State("IDLE"):
            with m.If(core.i.valid):
                m.d.sync += [self.channel.eq(core.i.payload.channel), self.flags.eq(0)]
                m.d.sync += [reg.eq(getattr(core.i.payload, name)) for name, reg in samples.items()]
                m.next = "LOAD_0"
        for j, (name, addr) in enumerate(p.sample_addrs.items()):
            with m.State(f"LOAD_{j}"):
                self.write(addr, samples[name])
                if j == len(samples) - 1:
                    m.d.comb += self.pc_next.eq(0)
                    m.next = "READ"
                else:
                    m.next = f"LOAD_{j + 1}"

    def execute(self):
        """EXEC: the operands are read; a one-cycle result registered, or the operation's next
        state chosen."""
        m, a, b, op = self.m, self.a, self.b, self.op
        m.d.sync += [self.result.eq(self.alu_value), self.flag.eq(0), self.mul_a.eq(a[:self.wa]),
                     self.mul_b.eq(b[:self.wb]), self.held.eq(a), self.addend.eq(self.addend_next)]
        # a division's dividend is |a|, a root's radicand a (0 if negative): shifted in PREP
        if self.has_units:
            m.d.sync += [self.magnitude.eq(Mux(self.negative, Mux(op["div"], -a, 0), a)), self.neg_r.eq(self.negative),
                         self.bad_r.eq(Mux(op["div"], b <= 0, self.negative))]
        if self.has_div:
            m.d.sync += self.den.eq(Mux(b > 0, b.as_unsigned(), 0)[:self.p.divisor_bits])
        with m.If(op["out"]):
            with m.Switch(self.ins["dst"]):
                for j, reg in enumerate(self.outs.values()):
                    with m.Case(j):
                        m.d.sync += reg.eq(a)
            self.next_instruction()
        with m.Elif(op["rq"]):
            m.next = "SHIFT"
        with m.Elif(op["mul"]):
            m.next = "PRODUCT"
        if self.has_units:
            with m.Elif(op["div"] | op["sqrt"]):
                m.next = "PREP"
        with m.Else():
            m.next = "WRITE"

    def arithmetic_states(self):
        m = self.m
        with m.State("SHIFT"):
            m.d.sync += self.moved.eq(Mux(self.k_right, self.summed >> self.k_amount, self.summed << self.k_amount))
            m.next = "SATURATE"
        with m.State("SATURATE"):
            m.d.sync += [self.result.eq(self.bounded), self.flag.eq(self.high | self.low)]
            m.next = "WRITE"
        with m.State("PRODUCT"):  # from registered operands: the multiplier alone in the cycle
            m.d.sync += self.result.eq(self.mul_a * self.mul_b)
            m.next = "WRITE"

    def unit_states(self):
        """A division or a root: its operand shifted, the unit run, the result bounded and signed."""
        m, p, op = self.m, self.p, self.op
        with m.State("PREP"):  # the operand shifted: left, or (a root's negative shift) right, a floor shift
            if self.has_div:
                m.d.sync += self.num.eq((self.magnitude << self.k_amount)[:p.dividend_bits])
            if self.has_sqrt:
                m.d.sync += self.radicand.eq(Mux(self.k_right, self.magnitude << self.k_amount,
                                                 self.magnitude >> self.k_amount)[:p.radicand_bits])
            m.next = "START"
        with m.State("START"):
            m.d.comb += self.start.eq(1)
            m.next = "WAIT"
        with m.State("WAIT"):
            with m.If(self.unit_done):
                m.d.sync += [self.held.eq(self.unit_value), self.flag.eq(self.bad_r | self.unit_overflow)]
                m.next = "BOUND"
        with m.State("BOUND"):  # the quotient or root bounded by its format ...
            with m.If(self.flag | (self.held > self.k_top)):
                m.d.sync += [self.held.eq(self.k_top), self.flag.eq(1)]
            m.next = "SIGN"
        with m.State("SIGN"):  # ... then a quotient takes the dividend's sign; a negative radicand's root is 0
            neg = self.neg_r
            m.d.sync += self.result.eq(Mux(op["div"] & neg, -self.held, Mux(op["sqrt"] & neg, 0, self.held)))
            m.next = "WRITE"




def make_core(config, variant, *, channels=1, stages=None):
    """The sequential core of any filter's ``variant`` (``channels`` channel states); ``stages``
    does not apply (it runs one operation at a time)."""
    if stages is not None:
        raise ValueError("stages applies to a pipelined loop; the sequential core runs one operation at a time")
    return SequentialCore(config, variant, channels=channels)
