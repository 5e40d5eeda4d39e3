"""The sequential core: any variant's update run one operation at a time (``kfpga/program.py``).

A slow filter (a ship's roll predicted every second, a speed log) needs few logic cells, not a
datapath that updates in one clock. :class:`SequentialCore` executes the update's program: one
operation at a time on one adder, one multiplier, one restoring divider (``hw/divider.py``) and
one restoring square root (``hw/sqrt.py``), with the constants, the samples, the intermediates
and every channel's state in one register file in block memory (Cyclone II M4K, three read
ports as three copies of it). The operations are the model's own integer functions, so the core
computes the model's integers for any update the operations layer can write, the square-root
covariance forms included.

Each operation takes two cycles: its instruction is in the program memory's read register, and
its operands' addresses go to the register file; then its operands are read, the result is
computed and written. A product takes one cycle more (the multiplier's output is registered), a
division ``quotient_bits + 1`` more and a square root ``root_bits + 1`` more (the units' latencies).
"""

from __future__ import annotations

from amaranth import Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib.memory import Memory

from kfpga.fixed import Rounding
from kfpga.hw.core import Core, write_estimate
from kfpga.hw.divider import Divider
from kfpga.hw.sqrt import SquareRoot
from kfpga.hw.storage import m4k_blocks, select
from kfpga.ops import Fx
from kfpga.program import OPS, ROUNDINGS, build_program

__all__ = ["SequentialCore", "encode"]

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
        The shared :class:`~kfpga.config.FilterConfig`.
    variant:
        The variant whose update the core runs.
    channels:
        Independent channel states (1..8).

    Members
    -------
    i : In(stream.Signature(input_layout(config, channels)))
        Samples.
    o : Out(stream.Signature(output_layout(config, channels)))
        Estimates, one per sample.
    overflow : Out(1)
        Sticky: some write saturated (or wrapped) since reset.
    """

    def __init__(self, config, variant, *, channels=1):
        super().__init__(config, variant, channels)
        self.program = build_program(config, variant, channels=channels, channel_bits=len(self.i.payload.channel))

    def _op_cycles(self, ins):
        p = self.program
        return {"mul": 3, "div": 2 + p.quotient_bits + 1, "sqrt": 2 + p.radicand_bits // 2 + 1}.get(ins.op, 2)

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
        shift = ins["shift"].as_signed()
        op = {name: ins["op"] == OPS.index(name) for name in OPS}

        def amount(kind, value):
            """A shift amount sliced to the bits the program's largest such shift needs."""
            largest = max([abs(i.shift) for i in p.instructions if i.op == kind] + [1])
            return value.as_unsigned()[:largest.bit_length()]

        channel = Signal.like(self.i.payload.channel, name="channel")
        in_range = Signal(name="in_range")
        m.d.comb += in_range.eq(channel < self.channels if self.channels < 2 ** len(channel) else 1)

        def is_state(field):
            return field[abits - 1] if p.state_base == 1 << (abits - 1) else Const(0, 1)

        def physical(field):
            """A register address; state k of channel c is at base | c << bits | k."""
            return Mux(is_state(field), field | (channel << p.state_bits), field) if len(channel) else field

        # operands: addressed in the first cycle of an operation, read in the second and later
        zero_state = [Signal(name=f"zero_{n}") for n in "abc"]  # an out-of-range channel reads zero
        for port, name, z in zip(reads, "abc", zero_state, strict=True):
            m.d.comb += [port.addr.eq(physical(ins[name])), port.en.eq(1)]
            m.d.sync += z.eq(is_state(ins[name]) & ~in_range)
        a, b, c = (Mux(z, 0, port.data).as_signed() for port, z in zip(reads, zero_state, strict=True))

        # -- the units -----------------------------------------------------------------------------------
        alu = Signal(signed(w), name="alu")
        with m.Switch(ins["op"]):
            for name, value in (("move", a), ("add", a + b), ("sub", a - b), ("neg", -a), ("abs", Mux(a < 0, -a, a)),
                                ("lt", a < b), ("mux", Mux(a != 0, b, c)), ("shl", a << amount("shl", shift))):
                with m.Case(OPS.index(name)):
                    m.d.comb += alu.eq(value)
        rq_value, rq_flag = _requantize(m, a, shift, amount("rq", Mux(shift < 0, -shift, shift)), ins["width"],
                                        ins["rounding"], ins["wrap"], w)
        wa, wb = p.mul_widths
        product = Signal(signed(w), name="product")
        m.d.sync += product.eq(a[:wa].as_signed() * b[:wb].as_signed())
        limit = Signal(w, name="limit")  # 2**(width - 1) - 1: the largest quotient or root of the target
        m.d.comb += limit.eq((Const(1, w + 1) << (ins["width"] - 1)[:7]) - 1)
        div_value, div_flag, div_start = Signal(signed(w), name="div_value"), Signal(), Signal()
        div_done = Const(1, 1)
        if p.count("div"):
            div = Divider(dividend_bits=p.dividend_bits, divisor_bits=p.divisor_bits, quotient_bits=p.quotient_bits)
            m.submodules.divider = div
            magnitude = Mux(a < 0, -a, a).as_unsigned()
            m.d.comb += [div.i.valid.eq(div_start), div.o.ready.eq(1),
                         div.i.payload.dividend.eq((magnitude << amount("div", shift))[:p.dividend_bits]),
                         div.i.payload.divisor.eq(Mux(b > 0, b.as_unsigned(), 0)[:p.divisor_bits])]
            q = div.o.payload.quotient
            bad = div.o.payload.overflow | (b <= 0) | (q > limit)
            held = Mux(bad, limit, q)
            m.d.comb += [div_flag.eq(bad), div_value.eq(Mux(a < 0, -held, held))]
            div_done = div.o.valid
        sqrt_value, sqrt_flag, sqrt_start = Signal(signed(w), name="sqrt_value"), Signal(), Signal()
        sqrt_done = Const(1, 1)
        if p.count("sqrt"):
            unit = SquareRoot(radicand_bits=p.radicand_bits)
            m.submodules.square_root = unit
            by = amount("sqrt", Mux(shift < 0, -shift, shift))
            radicand = Mux(shift >= 0, a << by, a >> by)  # a floor shift: a is not negative here
            m.d.comb += [unit.i.valid.eq(sqrt_start), unit.o.ready.eq(1),
                         unit.i.payload.radicand.eq(Mux(a < 0, 0, radicand[:p.radicand_bits]))]
            r = unit.o.payload.root
            m.d.comb += [sqrt_flag.eq((a < 0) | (r > limit)), sqrt_value.eq(Mux(a < 0, 0, Mux(r > limit, limit, r)))]
            sqrt_done = unit.o.valid

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

        def result(data, flag=None):
            """Write an operation's result (never into the state of an out-of-range channel)."""
            with m.If(~(is_state(ins["dst"]) & ~in_range)):
                write(physical(ins["dst"]), data)
            if flag is not None:
                m.d.sync += flags.eq(flags | flag)
            m.d.comb += pc_next.eq(pc + 1)
            with m.If(pc == len(p.instructions) - 1):
                m.next = "EMIT"
            with m.Else():
                m.next = "READ"

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        self.flag_outputs(m, 1)
        with m.FSM(name="schedule") as fsm:
            with m.State("INIT"):  # every channel's reset state into the register file
                k = init_count[:p.state_bits]
                write(Const(p.state_base, abits) | (init_count << 0), select(reset_values, k))
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
            with m.State("READ"):  # the instruction is here; its operands are addressed
                m.next = "EXEC"
            with m.State("EXEC"):
                with m.If(op["mul"]):
                    m.next = "PRODUCT"
                with m.Elif(op["div"]):
                    m.d.comb += div_start.eq(1)
                    m.next = "DIVIDE"
                with m.Elif(op["sqrt"]):
                    m.d.comb += sqrt_start.eq(1)
                    m.next = "ROOT"
                with m.Elif(op["out"]):
                    with m.Switch(ins["dst"]):
                        for j, reg in enumerate(outs.values()):
                            with m.Case(j):
                                m.d.sync += reg.eq(a)
                    m.d.comb += pc_next.eq(pc + 1)
                    with m.If(pc == len(p.instructions) - 1):
                        m.next = "EMIT"
                    with m.Else():
                        m.next = "READ"
                with m.Elif(op["rq"]):
                    result(rq_value, rq_flag)
                with m.Else():
                    result(alu)
            with m.State("PRODUCT"):
                result(product)
            with m.State("DIVIDE"):
                with m.If(div_done):
                    result(div_value, div_flag)
            with m.State("ROOT"):
                with m.If(sqrt_done):
                    result(sqrt_value, sqrt_flag)
            with m.State("EMIT"):
                with m.If(~self.o.valid | self.o.ready):
                    m.d.sync += self.o.valid.eq(1)
                    write_estimate(m, self, channel, {name: Fx(reg, 0) for name, reg in outs.items()}, [flags])
                    m.next = "IDLE"
        # a plain assignment (Verilog `assign`), not a case-statement output
        m.d.comb += self.i.ready.eq(fsm.ongoing("IDLE"))
        return m


def _requantize(m, x, shift, amount, width, rounding, wrap, w):
    """The operations layer's ``rq`` with the format's rules as run-time inputs: ``x * 2**-shift``
    (``amount = |shift|``) rounded by ``rounding`` (an index of :data:`~kfpga.program.ROUNDINGS`),
    then saturated, or wrapped when ``wrap``, to ``width`` bits; ``(value, flag)`` as
    :func:`kfpga.fixed.requantize` gives them."""
    negative = x < 0
    right = shift > 0
    half = Signal(w + 1, name="rq_half")  # 2**(shift - 1), half an LSB of the result
    m.d.comb += half.eq(Mux(right, Const(1, w + 1) << (amount - 1)[:len(amount)], 0))
    lsb = (x >> amount)[0]  # the bit that becomes the LSB
    addend = Signal(signed(w + 2), name="rq_addend")
    with m.Switch(rounding):
        with m.Case(ROUNDINGS.index(Rounding.NEAREST)):
            m.d.comb += addend.eq(half)
        with m.Case(ROUNDINGS.index(Rounding.ROUND)):
            m.d.comb += addend.eq(Mux(right, half - negative, 0))
        with m.Case(ROUNDINGS.index(Rounding.CONVERGENT)):
            m.d.comb += addend.eq(Mux(right, half - 1 + lsb, 0))
        with m.Case(ROUNDINGS.index(Rounding.FIX)):
            m.d.comb += addend.eq(Mux(right & negative, (Const(1, w + 1) << amount) - 1, 0))
        with m.Default():  # floor
            m.d.comb += addend.eq(0)
    moved = Signal(signed(w + 2), name="rq_moved")
    m.d.comb += moved.eq(Mux(right, (x + addend) >> amount, x << Mux(right, 0, amount)))
    top = Signal(signed(w + 2), name="rq_max")  # 2**(width - 1) - 1
    m.d.comb += top.eq((Const(1, w + 2) << (width - 1)[:7]) - 1)
    bottom = -top - 1
    high, low = moved > top, moved < bottom
    kept = Signal(w + 2, name="rq_kept")  # the low width bits
    m.d.comb += kept.eq(moved.as_unsigned() & ((Const(1, w + 3) << width) - 1))
    wrapped = Signal(signed(w + 2), name="rq_wrapped")  # ... as a signed width-bit value
    m.d.comb += wrapped.eq(kept - ((kept & (top + 1).as_unsigned()) << 1))
    value = Signal(signed(w), name="rq_value")
    m.d.comb += value.eq(Mux(wrap, wrapped, Mux(high, top, Mux(low, bottom, moved))))
    return value, high | low
