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
        m = Module()
        p = self.program
        w = p.width
        layout = _layout(p)
        abits = p.address_bits
        states = list(p.state_addrs)

        # -- memories: the program, and the register file three times (one per read port) ----------
        rom = Memory(shape=unsigned(sum(layout.values())), depth=max(len(p.instructions), 2), init=encode(p))
        m.submodules.program = rom
        fetch = rom.read_port()
        files = [Memory(shape=unsigned(w), depth=p.depth, init=p.init) for _ in range(3)]
        for n, mem in enumerate(files):
            m.submodules[f"registers_{'abc'[n]}"] = mem
        reads = [mem.read_port() for mem in files]
        writes = [mem.write_port() for mem in files]
        wr_addr, wr_data, wr_en = Signal(abits, name="wr_addr"), Signal(w, name="wr_data"), Signal(name="wr_en")
        for port in writes:
            m.d.comb += [port.addr.eq(wr_addr), port.data.eq(wr_data), port.en.eq(wr_en)]

        # -- the instruction in the program memory's read register ---------------------------------
        ins, offset = {}, 0
        for name in _FIELDS:
            ins[name] = fetch.data[offset:offset + layout[name]]
            offset += layout[name]
        channel = Signal.like(self.i.payload.channel, name="channel")
        in_range = Signal(name="in_range")
        m.d.comb += in_range.eq(channel < self.channels if self.channels < 2 ** len(channel) else 1)

        def is_state(field):
            return field[abits - 1] if p.state_base == 1 << (abits - 1) else Const(0, 1)

        def physical(field):
            """A register address; state k of channel c is at base | c << bits | k."""
            return Mux(is_state(field), field | (channel << p.state_bits), field) if len(channel) else field

        # operands: addressed in the first cycle of an operation (READ), read from then on
        zero_state = [Signal(name=f"zero_{n}") for n in "abc"]  # an out-of-range channel reads zero
        for port, name, z in zip(reads, "abc", zero_state, strict=True):
            m.d.comb += [port.addr.eq(physical(ins[name])), port.en.eq(1)]
            m.d.sync += z.eq(is_state(ins[name]) & ~in_range)
        a, b, c = (Mux(z, 0, port.data).as_signed() for port, z in zip(reads, zero_state, strict=True))

        # what READ registers of the instruction: its operation, and the constants of its target
        # format (a table of the program's (shift, width) pairs, not shifters of run-time widths)
        # only what the program uses is built: its operations, its rounding rules, wrap-around if
        # it wraps, constants as wide as its shifts and target widths (the rest could never act)
        used = {i.op for i in p.instructions}
        rqs = [i for i in p.instructions if i.op == "rq"]
        op = {name: Signal(name=f"op_{name}") if name in used else Const(0, 1) for name in OPS}
        rounding = Signal.like(ins["rounding"], name="k_rounding")
        wrap = Signal(name="k_wrap") if any(i.wrap for i in rqs) else Const(0, 1)
        largest = max([abs(i.shift) for i in p.instructions] + [1])
        table = sorted({(i.shift, i.width) for i in p.instructions if i.op in ("rq", "div", "sqrt", "shl")})
        widest = max([width for _, width in table] + [1])
        k_amount, k_right = Signal(range(largest + 1), name="k_amount"), Signal(name="k_right")
        k_half, k_fix = Signal(largest + 1, name="k_half"), Signal(largest + 1, name="k_fix")  # 2**(s-1), 2**s - 1
        k_below = Signal(largest + 1, name="k_below")  # 2**(s-1) - 1: half an LSB less one, so no adder picks it
        k_top, k_mask = Signal(widest, name="k_top"), Signal(widest + 1, name="k_mask")  # 2**(width-1) - 1, 2**width - 1

        def read_instruction():
            m.d.sync += [op[name].eq(ins["op"] == OPS.index(name)) for name in OPS if name in used]
            m.d.sync += rounding.eq(ins["rounding"])
            if isinstance(wrap, Signal):
                m.d.sync += wrap.eq(ins["wrap"])
            with m.Switch(Cat(ins["shift"], ins["width"])):
                for sh, width in table:
                    with m.Case((sh & 0xFF) | width << 8):
                        m.d.sync += [k_amount.eq(abs(sh)), k_right.eq(sh > 0),
                                     k_half.eq(1 << (sh - 1) if sh > 0 else 0), k_fix.eq((1 << sh) - 1 if sh > 0 else 0),
                                     k_below.eq((1 << (sh - 1)) - 1 if sh > 0 else 0),
                                     k_top.eq((1 << max(width - 1, 0)) - 1), k_mask.eq((1 << width) - 1)]

        # -- the units: each result goes to one register, written in the operation's last cycle --------
        result, flag = Signal(signed(w), name="result"), Signal(name="result_flag")
        wa, wb = p.mul_widths
        mul_a, mul_b = Signal(signed(wa), name="mul_a"), Signal(signed(wb), name="mul_b")
        alu = Signal(signed(w), name="alu")
        terms = {"add": a + b, "sub": a - b, "neg": -a, "abs": Mux(a < 0, -a, a), "lt": a < b,
                 "mux": Mux(a != 0, b, c), "shl": a << k_amount, "move": a}
        m.d.comb += alu.eq(reduce(operator.or_, [Mux(op[n], t, 0) for n, t in terms.items() if n in used], Const(0, 1)))
        # rq: EXEC registers the value (in ``held``, free then) and its rounding addend; SHIFT adds
        # them and shifts; SATURATE saturates or wraps around
        negative = a < 0
        neg_r, bad_r = Signal(name="neg_r"), Signal(name="bad_r")
        held = Signal(w, name="held")  # a unit's result; an rq's value
        addend, addend_next = Signal(signed(w + 2), name="rq_addend"), Signal(signed(w + 2), name="rq_addend_next")
        # the addends of ROUND and CONVERGENT chosen between two registered constants, half an
        # LSB and one less, by a bit of a: a multiplexer, not a carry chain (k_half and k_below
        # are 0 when nothing is shifted off); FLOOR adds nothing
        addends = {Rounding.NEAREST: k_half,
                   Rounding.ROUND: Mux(negative, k_below, k_half),  # half - 1 for a negative value
                   # the bit that becomes the LSB breaks a tie: bit s of a (s = k_amount) through the
                   # mask 2 k_half = 2**s, an AND and an OR tree, not a barrel shifter
                   Rounding.CONVERGENT: Mux((a & (k_half << 1)).any(), k_half, k_below),
                   Rounding.FIX: Mux(negative, k_fix, 0)}
        # a chain of multiplexers (a Verilog assign), not a case statement: an always block whose
        # inputs happen never to change would stay undefined from time zero in Icarus
        choice = Const(0, 1)
        for rule in sorted({ROUNDINGS[i.rounding] for i in rqs} - {Rounding.FLOOR}, key=ROUNDINGS.index):
            choice = Mux(rounding == ROUNDINGS.index(rule), addends[rule], choice)
        m.d.comb += addend_next.eq(choice)
        summed = Signal(signed(w + 2), name="rq_sum")
        m.d.comb += summed.eq(held.as_signed() + addend)
        moved = Signal(signed(w + 2), name="rq_moved")
        top = k_top.as_signed()
        high, low = moved > top, moved < -top - 1
        bounded = Mux(high, top, Mux(low, -top - 1, moved))
        if isinstance(wrap, Signal):
            kept = Signal(w + 2, name="rq_kept")  # the low width bits ...
            m.d.comb += kept.eq(moved.as_unsigned() & k_mask)
            wrapped = (kept - ((kept & (k_top + 1)) << 1)).as_signed()  # ... as a signed width-bit value
            bounded = Mux(wrap, wrapped, bounded)
        units = bool(p.count("div") or p.count("sqrt"))
        # a division or a root: its operand prepared, the unit run, its result bounded
        magnitude = Signal(w, name="magnitude")  # a unit's operand before its shift
        unit_done, unit_value, unit_overflow = Const(1, 1), Const(0, 1), Const(0, 1)
        start = Signal(name="unit_start")
        if p.count("div"):
            div = Divider(dividend_bits=p.dividend_bits, divisor_bits=p.divisor_bits, quotient_bits=p.quotient_bits)
            m.submodules.divider = div
            num, den = Signal(p.dividend_bits, name="div_num"), Signal(p.divisor_bits, name="div_den")
            m.d.comb += [div.i.valid.eq(start & op["div"]), div.o.ready.eq(1),
                         div.i.payload.dividend.eq(num), div.i.payload.divisor.eq(den)]
        if p.count("sqrt"):
            root = SquareRoot(radicand_bits=p.radicand_bits)
            m.submodules.square_root = root
            radicand = Signal(p.radicand_bits, name="radicand")
            m.d.comb += [root.i.valid.eq(start & op["sqrt"]), root.o.ready.eq(1), root.i.payload.radicand.eq(radicand)]
        if units:
            done = Signal(name="unit_done")
            value = Signal(w, name="unit_value")
            over = Signal(name="unit_overflow")
            cases = []
            if p.count("div"):
                cases.append((op["div"], div.o.valid, div.o.payload.quotient, div.o.payload.overflow))
            if p.count("sqrt"):
                cases.append((op["sqrt"], root.o.valid, root.o.payload.root, Const(0, 1)))
            for is_op, valid, out, ovf in cases:
                with m.If(is_op):
                    m.d.comb += [done.eq(valid), value.eq(out), over.eq(ovf)]
            unit_done, unit_value, unit_overflow = done, value, over

        # -- the schedule -------------------------------------------------------------------------------
        pc = Signal(range(len(p.instructions) + 1), name="pc")
        pc_next = Signal.like(pc, name="pc_next")
        m.d.comb += [pc_next.eq(pc), fetch.addr.eq(pc_next), fetch.en.eq(1)]
        m.d.sync += pc.eq(pc_next)
        flags = Signal(name="flags")  # the overflow flags of this update, ORed
        outs = {name: Signal(signed(width), name=f"out_{name}") for name, width in p.outputs}
        samples = {name: Signal(signed(16), name=f"sample_{name}") for name in p.sample_addrs}
        reset_values = [Const(self.reset_state[n] & ((1 << w) - 1), w) for n in states]
        init_last = (self.channels << p.state_bits) - 1
        init_count = Signal(range(init_last + 1), name="init_count")

        def write(addr, data):
            m.d.comb += [wr_addr.eq(addr), wr_data.eq(data), wr_en.eq(1)]

        def next_instruction():
            m.d.comb += pc_next.eq(pc + 1)
            with m.If(pc == len(p.instructions) - 1):
                m.next = "EMIT"
            with m.Else():
                m.next = "READ"

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        self.flag_outputs(m, [flags])
        with m.FSM(name="schedule") as fsm:
            with m.State("INIT"):  # every channel's reset state into the register file
                write(Const(p.state_base, abits) | init_count, select(reset_values, init_count[:p.state_bits]))
                m.d.sync += init_count.eq(init_count + 1)
                with m.If(init_count == init_last):
                    m.next = "IDLE"
            with m.State("IDLE"):
                with m.If(self.i.valid):
                    m.d.sync += [channel.eq(self.i.payload.channel), flags.eq(0)]
                    m.d.sync += [reg.eq(getattr(self.i.payload, name)) for name, reg in samples.items()]
                    m.next = "LOAD_0"
            for j, (name, addr) in enumerate(p.sample_addrs.items()):
                with m.State(f"LOAD_{j}"):
                    write(addr, samples[name])
                    if j == len(samples) - 1:
                        m.d.comb += pc_next.eq(0)
                        m.next = "READ"
                    else:
                        m.next = f"LOAD_{j + 1}"
            with m.State("READ"):  # the instruction is here: its operands are addressed, its constants taken
                read_instruction()
                m.next = "EXEC"
            with m.State("EXEC"):  # the operands are here
                m.d.sync += [result.eq(alu), flag.eq(0), mul_a.eq(a[:wa]), mul_b.eq(b[:wb]), held.eq(a),
                             addend.eq(addend_next)]
                # a division's dividend is |a|, a root's radicand a (0 if negative): shifted in PREP
                if units:
                    m.d.sync += [magnitude.eq(Mux(negative, Mux(op["div"], -a, 0), a)), neg_r.eq(negative),
                                 bad_r.eq(Mux(op["div"], b <= 0, negative))]
                if p.count("div"):
                    m.d.sync += den.eq(Mux(b > 0, b.as_unsigned(), 0)[:p.divisor_bits])
                with m.If(op["out"]):
                    with m.Switch(ins["dst"]):
                        for j, reg in enumerate(outs.values()):
                            with m.Case(j):
                                m.d.sync += reg.eq(a)
                    next_instruction()
                with m.Elif(op["rq"]):
                    m.next = "SHIFT"
                with m.Elif(op["mul"]):
                    m.next = "PRODUCT"
                if units:
                    with m.Elif(op["div"] | op["sqrt"]):
                        m.next = "PREP"
                with m.Else():
                    m.next = "WRITE"
            with m.State("SHIFT"):
                m.d.sync += moved.eq(Mux(k_right, summed >> k_amount, summed << k_amount))
                m.next = "SATURATE"
            with m.State("SATURATE"):
                m.d.sync += [result.eq(bounded), flag.eq(high | low)]
                m.next = "WRITE"
            with m.State("PRODUCT"):  # from registered operands: the multiplier alone in the cycle
                m.d.sync += result.eq(mul_a * mul_b)
                m.next = "WRITE"
            if units:  # a division or a root: its operand shifted, the unit run, the result bounded and signed
                with m.State("PREP"):  # the operand shifted: left, or (a root's negative shift) right, a floor shift
                    if p.count("div"):
                        m.d.sync += num.eq((magnitude << k_amount)[:p.dividend_bits])
                    if p.count("sqrt"):
                        m.d.sync += radicand.eq(Mux(k_right, magnitude << k_amount, magnitude >> k_amount)[:p.radicand_bits])
                    m.next = "START"
                with m.State("START"):
                    m.d.comb += start.eq(1)
                    m.next = "WAIT"
                with m.State("WAIT"):
                    with m.If(unit_done):
                        m.d.sync += [held.eq(unit_value), flag.eq(bad_r | unit_overflow)]
                        m.next = "BOUND"
                with m.State("BOUND"):  # the quotient or root bounded by its format ...
                    with m.If(flag | (held > k_top)):
                        m.d.sync += [held.eq(k_top), flag.eq(1)]
                    m.next = "SIGN"
                with m.State("SIGN"):  # ... then a quotient takes the dividend's sign; a negative radicand's root is 0
                    m.d.sync += result.eq(Mux(op["div"] & neg_r, -held, Mux(op["sqrt"] & neg_r, 0, held)))
                    m.next = "WRITE"
            with m.State("WRITE"):
                with m.If(~(is_state(ins["dst"]) & ~in_range)):  # never an out-of-range channel's state
                    write(physical(ins["dst"]), result)
                m.d.sync += flags.eq(flags | flag)
                next_instruction()
            with m.State("EMIT"):
                with m.If(~self.o.valid | self.o.ready):
                    m.d.sync += self.o.valid.eq(1)
                    write_estimate(m, self, channel, {name: Fx(reg, 0) for name, reg in outs.items()}, [flags])
                    m.next = "IDLE"
        # a plain assignment (Verilog `assign`), not a case-statement output
        m.d.comb += self.i.ready.eq(fsm.ongoing("IDLE"))
        return m




def make_core(config, variant, *, channels=1, stages=None):
    """The sequential core of any filter's ``variant`` (``channels`` channel states); ``stages``
    does not apply (it runs one operation at a time)."""
    if stages is not None:
        raise ValueError("stages applies to a pipelined loop; the sequential core runs one operation at a time")
    return SequentialCore(config, variant, channels=channels)
