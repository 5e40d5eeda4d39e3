"""The folded core: any filter's update as microcode on one 18-bit datapath (``hw/microcode.py``).

At a low sample rate a filter has hundreds of thousands of clock cycles for each update and
needs few logic cells. :class:`FoldedCore` has one register file of 18-bit words in M4K block
memory (two copies: two read ports), one signed 18 x 18 embedded multiplier and one accumulator;
its microcode, in another M4K block, is the filter's own update compiled step by step, so it
computes the model's integers for every update the operations layer writes (divisions and square
roots included). A step goes through four pipeline stages::

    R  the step's word is in the program memory's read register: the operands are addressed
       (the first one by a flag when the step is predicated; a state's address with the channel)
    X  the operands read and multiplied, the product into the multiplier's output register
    A  acc = acc, acc >> 17 or 0, plus the product
    W  the sum's low or top digit written to the register file, or an output chunk loaded; a
       flag captured from the sum's sign or its bit 16

A step issues every cycle unless its word says to wait (the compiler's schedule keeps a word
read, and a flag used, at least four cycles after the step that writes it), and a step
may begin a loop of the steps after it or end one (a counter, a start address). Each stage is
at most one carry chain, one multiplier or one memory read between registers.
"""

from __future__ import annotations

from amaranth import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from kfpga.core.board import MAX_CHANNELS
from kfpga.hw.core import Core
from kfpga.hw.microcode import BEGIN, DIGIT, END, FLAGS, HI, LO, OR, OUT, READ_LATENCY, WORD, compile_update, handshake_twin
from kfpga.hw.storage import check_channels, m4k_blocks

__all__ = ["FoldedCore", "BUSES", "encode", "make_core", "rom_columns", "rom_words", "word_layout", "bus_members"]

#: The buses a programmable core can have (``hw/regmap.py`` for its registers).
BUSES = ("avalon", "axi4lite")


def bus_members(bus, address_bits):
    """The ports of ``bus`` (``None``: none), word addresses of ``address_bits`` bits: Avalon-MM
    ``avs_*`` (word addresses, read data the cycle after a read, ``avs_readdatavalid``) or
    AXI4-Lite ``s_axil_*`` (byte addresses)."""
    if bus is None:
        return {}
    if bus == "avalon":
        return {"avs_address": In(address_bits), "avs_write": In(1), "avs_writedata": In(32), "avs_read": In(1),
                "avs_readdata": Out(32), "avs_readdatavalid": Out(1), "avs_waitrequest": Out(1)}
    if bus == "axi4lite":
        a = address_bits + 2
        return {"s_axil_awaddr": In(a), "s_axil_awprot": In(3), "s_axil_awvalid": In(1), "s_axil_awready": Out(1),
                "s_axil_wdata": In(32), "s_axil_wstrb": In(4), "s_axil_wvalid": In(1), "s_axil_wready": Out(1),
                "s_axil_bresp": Out(2), "s_axil_bvalid": Out(1), "s_axil_bready": In(1),
                "s_axil_araddr": In(a), "s_axil_arprot": In(3), "s_axil_arvalid": In(1), "s_axil_arready": Out(1),
                "s_axil_rdata": Out(32), "s_axil_rresp": Out(2), "s_axil_rvalid": Out(1), "s_axil_rready": In(1)}
    raise ValueError(f"bus must be one of {', '.join(BUSES)}, not {bus!r}")


def word_layout(program):
    """The fields of a program word, LSB first: ``{name: bits}`` (addresses as wide as the register
    file needs; ``d`` also holds an output chunk's number and a loop's count)."""
    abits = program.address_bits
    counts = [w["count"] for w in program.words if w["loop"] == BEGIN] + [len(program.chunks), len(program.words)]
    dbits = max(abits, max(counts).bit_length())
    return {"a": abits, "a2": abits, "b": abits, "d": dbits, "acc": 2, "pred": 2, "wr": 2, "cap": 2, "flag": 1,
            "bit16": 1, "ovf": 1, "loop": 2, "wait": 3, "end": 1}


def rom_columns(program):
    """``(varying, constant)``: the bit columns of the encoded words that differ between words
    (the program memory holds only these) and ``{bit: value}`` of those that do not (constants in
    logic: a field no step uses, a wait or an address bit no word sets)."""
    words = encode(program)
    width = sum(word_layout(program).values())
    varying = [i for i in range(width) if len({(w >> i) & 1 for w in words}) > 1]
    constant = {i: (words[0] >> i) & 1 for i in range(width) if i not in varying}
    return varying, constant


def rom_words(program):
    """The program memory's contents: each word's varying columns (:func:`rom_columns`), packed."""
    varying, _ = rom_columns(program)
    return [sum(((w >> i) & 1) << j for j, i in enumerate(varying)) for w in encode(program)]


def encode(program):
    """The program memory's words (a loop's begin holds its count in ``d``, its end the address of
    its first step)."""
    layout = word_layout(program)
    out = []
    for w in program.words:
        values = dict(w)
        word, offset = 0, 0
        for name, bits in layout.items():
            if not 0 <= values[name] < 1 << bits:
                raise ValueError(f"program field {name} = {values[name]} does not fit {bits} bits")
            word |= values[name] << offset
            offset += bits
        out.append(word)
    return out


class FoldedCore(Core):
    """A filter's update as microcode on one multiplier and one accumulator (module docstring).

    A sample's digits are written to the register file one a cycle while ``i.valid`` is high in
    the idle state (and no estimate waits on ``o``), and the word is taken with the last
    (``i.ready``) in cycle ``c``; the update's steps run, and the estimate is on ``o`` in cycle
    ``c + latency``; the next word's digits can be written from then on. After reset
    the core first writes every channel's reset state (:attr:`startup_cycles`, during which it
    takes no sample). A channel number outside ``0..channels-1`` reads a zero state and updates
    nothing.

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
    missing:
        With ``i.payload.missing``: a sample with it set has no measurement, and the update only
        predicts (the variant's ``predict``, its codes not read).
    bus:
        ``"avalon"`` or ``"axi4lite"``: a register slave (``hw/regmap.py``) through which the
        constants and reset values are written at run time (taking effect between updates), the
        filter reset, and its counters read; ``None``: none, every constant built in.
    """

    max_channels = MAX_CHANNELS

    def __init__(self, config, variant, *, channels=1, program=None, missing=False, bus=None):
        from kfpga.hw.layouts import channel_bits

        check_channels(channels, self.max_channels)  # the base class's checks, before the compiler runs
        config.require_hardware(variant)
        if bus is not None and bus not in BUSES:
            raise ValueError(f"bus must be one of {', '.join(BUSES)}, not {bus!r}")
        self.missing, self.bus = missing, bus
        program = program or compile_update(config, variant, channels=channels, channel_bits=channel_bits(channels),
                                            predict=missing, programmable=bus is not None)
        self.program = program
        self.regs = None
        members = {}
        if bus is not None:
            from kfpga.hw.regmap import register_map

            self.regs = register_map(program, config, variant)
            self.bus_address_bits = max(5, max(r.index for r in self.regs).bit_length())
            members = bus_members(bus, self.bus_address_bits)
        super().__init__(config, variant, channels, missing=missing, members=members)

    def formal_twin(self):
        """The core on a short copy of its program (:func:`kfpga.hw.microcode.handshake_twin`): the
        same handshake, whole updates within a bounded check's reach."""
        from kfpga.hw.generate import figures_only

        figures_only(self)  # the twin is built instead of this core
        return FoldedCore(self.config, self.variant, channels=self.channels, program=handshake_twin(self.program),
                          missing=False, bus=None)

    #: Samples the core holds at once: it takes one only when no estimate waits (or one is taken in
    #: that cycle), so an update and an estimate never overlap (the formal stream checks count it).
    capacity = 1

    @property
    def load_cycles(self):
        """Cycles before the handshake that write the sample's digits but the last (the input word
        is read while its ``valid`` is high, and taken with its last digit)."""
        return len(self.program.sample_addrs) - 1

    @property
    def cycles_per_update(self):
        """Cycles from taking one sample to being able to take the next (``o`` always ready)."""
        return self.load_cycles + self.latency

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return 1 + self.program.update_cycles

    @property
    def startup_cycles(self):
        """Cycles after reset before the first sample is taken (every channel's reset state written)."""
        return 1 + self.channels * self.program.init_cycles  # a cycle to fetch the first word

    @property
    def m4k_blocks(self):
        """Block memories: two copies of the register file and the program (a ROM read on two ports,
        as wide as its varying columns)."""
        p = self.program
        return 2 * m4k_blocks(p.depth, WORD) + m4k_blocks(max(len(p.words), 2), max(len(rom_columns(p)[0]), 1),
                                                          two_reads=True)

    def elaborate(self, platform):
        b = _Build(self, Module())
        b.memories()
        b.fetch()
        b.read()
        b.multiply()
        b.accumulate()
        b.write()
        b.schedule()
        if self.bus is not None:
            b.registers()
        self.parts = b  # the signals of the last elaboration, for a bench that looks inside
        return b.m


class _Build:
    """The parts of a :class:`FoldedCore`, one method per stage; each keeps as attributes the
    signals the later ones use."""

    def __init__(self, core, m):
        self.core, self.m, self.p = core, m, core.program
        self.layout = word_layout(self.p)
        self.abits = self.p.address_bits
        p = self.p
        self.channel = Signal.like(core.i.payload.channel, name="channel")
        cbits = len(self.channel)
        # the block a channel's states are in: past the last channel, the spare block of zeros
        self.spare = core.channels < (1 << cbits)
        self.in_range = Signal(name="in_range")
        self.block = Signal(max(cbits, 1), name="block")
        m.d.comb += self.in_range.eq(self.channel < core.channels if self.spare else 1)
        m.d.comb += self.block.eq(Mux(self.in_range, self.channel, core.channels) if self.spare else self.channel)
        self.update_start = p.init_steps

    def is_state(self, addr):
        return addr[self.abits - 1] if self.p.state_base == 1 << (self.abits - 1) else Const(0, 1)

    def physical(self, addr):
        """A register address; state digit j of channel c is at base | c << bits | j."""
        return Mux(self.is_state(addr), addr | (self.block << self.p.state_bits), addr)

    def memories(self):
        m, p = self.m, self.p
        varying, constant = rom_columns(p)
        self.rom = Memory(shape=unsigned(max(len(varying), 1)), depth=max(len(p.words), 2), init=rom_words(p))
        m.submodules.program = self.rom

        def unpack(data):  # the whole word again: the memory's columns and the constant ones
            column = {i: j for j, i in enumerate(varying)}
            return Cat(*(data[column[i]] if i in column else Const(constant[i], 1)
                         for i in range(sum(self.layout.values()))))
        self.unpack = unpack
        self.fetch_port = self.rom.read_port()
        # the program memory's second port reads the word in R once more, for X: the word of the
        # step in X with no pipeline register of its own
        self.again_port = self.rom.read_port()
        files = [Memory(shape=unsigned(WORD), depth=p.depth, init=p.init) for _ in range(2)]
        for n, mem in enumerate(files):
            m.submodules[f"registers_{'ab'[n]}"] = mem
        self.reads = [mem.read_port() for mem in files]
        writes = [mem.write_port() for mem in files]
        self.wr_addr, self.wr_data = Signal(self.abits, name="wr_addr"), Signal(WORD, name="wr_data")
        self.wr_en = Signal(name="wr_en")
        for port in writes:
            m.d.comb += [port.addr.eq(self.wr_addr), port.data.eq(self.wr_data), port.en.eq(self.wr_en)]

    def fetch(self):
        """The program counter, the wait counter and the loop: which word is in the read register.

        A routine runs while ``running``: a step issues when no wait is left; the last one's write
        is three cycles later (``ending``, the wait counter counting it down), and the routine is
        ``finished`` in that cycle. After reset the reset routine runs at once, for channel 0."""
        m, p = self.m, self.p
        data = self.unpack(self.fetch_port.data)
        self.word, offset = {}, 0
        for name, bits in self.layout.items():
            self.word[name] = data[offset:offset + bits]
            offset += bits
        self.pc = Signal(range(max(len(p.words), 2)), name="pc")
        self.pc_next = Signal.like(self.pc, name="pc_next")
        self.waiting = Signal(3, name="waiting")
        count_max = max([w["count"] for w in p.words if w["loop"] == BEGIN] + [1])
        # datapath and operand registers have no reset (what they hold is read only where a valid
        # bit, reset, says so): the multiplier's own registers have none, and the rest costs less
        self.loop_left = Signal(range(max(count_max, 2)), name="loop_left", reset_less=True)  # iterations after this
        self.running = Signal(init=1, name="running")
        self.ending = Signal(name="ending")
        # the program memory's read register holds no word after reset: the first cycle fetches one
        primed = Signal(name="primed")
        m.d.sync += primed.eq(1)
        self.issue, self.last, self.finished = Signal(name="issue"), Signal(name="last"), Signal(name="finished")
        m.d.comb += [self.fetch_port.addr.eq(self.pc_next), self.fetch_port.en.eq(1),
                     self.issue.eq(self.running & primed & (self.waiting == 0) & ~self.ending),
                     self.finished.eq(self.ending & (self.waiting == 1))]
        self.back = back = (self.word["loop"] == END) & (self.loop_left != 0)
        m.d.comb += self.last.eq(self.issue & self.word["end"] & ~back)
        m.d.sync += self.pc.eq(self.pc_next)
        with m.If(self.issue):
            # the last step's write is READ_LATENCY - 1 cycles on
            m.d.sync += self.waiting.eq(Mux(self.last, READ_LATENCY - 1, self.word["wait"]))
            with m.If(self.word["loop"] == BEGIN):
                m.d.sync += self.loop_left.eq(self.word["d"])
            with m.Elif(back):
                m.d.sync += self.loop_left.eq(self.loop_left - 1)
            with m.If(self.last):
                m.d.sync += self.ending.eq(1)
        with m.Elif(self.waiting != 0):
            m.d.sync += self.waiting.eq(self.waiting - 1)

    def read(self):
        """R: the operands addressed (the first by its predicate's flag)."""
        m, w = self.m, self.word
        self.flags = [Signal(name=f"flag{j}", reset_less=True) for j in range(FLAGS)]
        chosen = Signal(name="predicate")
        m.d.comb += chosen.eq(Mux(w["pred"] == 0, 0, Mux(w["pred"] == 1, self.flags[0], self.flags[1])))
        a = Mux(chosen, w["a2"], w["a"])
        for port, addr in zip(self.reads, (a, w["b"]), strict=True):
            m.d.comb += [port.addr.eq(self.physical(addr)), port.en.eq(1)]
        # what the later stages need of the step: in X its word read again, then a register for A
        m.d.comb += [self.again_port.addr.eq(self.pc), self.again_port.en.eq(1)]
        again, offset, data = {}, 0, self.unpack(self.again_port.data)
        for name, bits in self.layout.items():
            again[name] = data[offset:offset + bits]
            offset += bits
        fields = {"acc": 2, "cap": 2, "flag": self.layout["flag"], "bit16": 1, "ovf": 1, "wr": 2, "d": self.layout["d"]}
        x = {"valid": Signal(name="x_valid"), **{name: again[name] for name in fields}}
        m.d.sync += x["valid"].eq(self.issue)
        a = {"valid": Signal(name="a_valid")}
        a.update({name: Signal(bits, name=f"a_{name}", reset_less=True) for name, bits in fields.items()})
        m.d.sync += [a[name].eq(x[name]) for name in a]
        self.stages = [x, a]

    def multiply(self):
        """X: the operands read and multiplied, the product registered (the multiplier's own register)."""
        m = self.m
        self.product = Signal(signed(2 * WORD), name="product", reset_less=True)
        m.d.sync += self.product.eq(self.reads[0].data.as_signed() * self.reads[1].data.as_signed())

    def accumulate(self):
        """A: acc = S(acc) + product (the mode's two bits: shift, clear)."""
        m, p, a = self.m, self.p, self.stages[1]
        self.acc = Signal(signed(p.acc_bits), name="acc", reset_less=True)
        shift = a["acc"][0]  # SHIFT = 1, CLEAR = 2
        keep = Signal(name="acc_keep", reset_less=True)  # one-hot with shift, registered: a LUT4 a bit
        m.d.sync += keep.eq(~self.stages[0]["acc"].any())  # the step in X's mode
        base = Signal(signed(p.acc_bits), name="acc_base")
        m.d.comb += base.eq(Mux(keep, self.acc, Mux(shift, self.acc >> DIGIT, 0)))
        with m.If(a["valid"]):
            m.d.sync += self.acc.eq(base + self.product)
        self.w = {name: Signal(len(a[name]), name=f"w_{name}", reset_less=name != "valid")
                  for name in ("valid", "wr", "d", "cap", "flag", "bit16", "ovf")}
        m.d.sync += [reg.eq(a[name]) for name, reg in self.w.items()]

    def write(self):
        """W: the sum's digit into the register file, or its low bits into an output chunk; a flag
        (or the sample's overflow flag) from its sign or its bit 16."""
        m, core, p, w = self.m, self.core, self.p, self.w
        acc = self.acc
        self.digit = Cat(acc[:DIGIT], Mux(w["wr"] == HI, acc[DIGIT], 0))
        self.step_write = Signal(name="step_write")
        addr = w["d"][:self.abits]
        m.d.comb += self.step_write.eq(w["valid"] & ((w["wr"] == LO) | (w["wr"] == HI))
                                       & ~(self.is_state(addr) & ~self.in_range))
        self.step_addr = self.physical(addr)
        # the output chunks: each a slice of the estimate's fields (a chunk's number in d's low bits)
        self.outs = {name: Signal(signed(core.config.output_format(name).width), name=f"out_{name}", reset_less=True)
                     for name in p.outputs}
        out = Signal(name="out_write")
        m.d.comb += out.eq(w["valid"] & (w["wr"] == OUT))
        low = w["d"][:max(1, (len(p.chunks) - 1).bit_length())]
        for j, (name, offset, width) in enumerate(p.chunks):
            with m.If(out & (low == j)):
                m.d.sync += self.outs[name][offset:offset + width].eq(acc[:width])
        self.fo = Signal(name="sample_overflow", reset_less=True)
        bit = Mux(w["bit16"], acc[16], acc[-1])
        with m.If(w["valid"] & (w["cap"] != 0)):
            for j, flag in enumerate(self.flags):
                with m.If(w["flag"] == j):
                    m.d.sync += flag.eq(bit | ((w["cap"] == OR) & flag))
            with m.If(w["ovf"]):
                m.d.sync += self.fo.eq(self.fo | bit)

    def schedule(self):
        """Idle (a sample's digits written, one a cycle, straight from the input word, which is
        taken with the last) or running a routine: the reset routine once for each channel after
        reset, then the update's for each sample (the predict routine's for a sample with no
        measurement); with a bus, the commit routine and the reset routine between two updates."""
        m, core, p = self.m, self.core, self.p
        bus = core.bus is not None
        self.write_port()
        self.outputs()
        self.initializing = initializing = Signal(init=1, name="initializing")
        self.commit_pending, self.reset_pending = Signal(name="commit_pending"), Signal(name="reset_pending")
        self.clear_pending = Signal(name="clear_pending")
        self.committing = Signal(name="committing")  # the commit routine, or the counters' clear, runs
        free = ~core.o.valid | core.o.ready  # no estimate waits, or it is taken now
        last_digit = self.load == len(p.sample_addrs) - 1
        idle = ~self.running
        # a commit or a reset waits for the end of the update that runs, and holds the next sample
        held = (self.commit_pending | self.reset_pending | self.clear_pending) if bus else Const(0, 1)
        # ready does not follow valid within a cycle: it is high once the other digits are written
        m.d.comb += core.i.ready.eq(idle & free & last_digit & ~held)
        self.start_commit, self.start_reset = Signal(name="start_commit"), Signal(name="start_reset")
        self.start_clear = Signal(name="start_clear")
        if bus:  # at an update's end: the commit first, then the counters' clear, then the reset
            m.d.comb += [self.start_commit.eq(idle & self.commit_pending),
                         self.start_clear.eq(idle & ~self.commit_pending & self.clear_pending),
                         self.start_reset.eq(idle & ~self.commit_pending & ~self.clear_pending & self.reset_pending
                                             & free)]
        self.take = take = Signal(name="take")
        coast = core.i.payload.missing if core.missing else Const(0, 1)
        # plain assignments (Verilog `assign`), not outputs of case statements: no simulator can leave
        # them undefined at time zero while their inputs have not changed yet
        restart = initializing & (self.channel != core.channels - 1)  # the next channel's reset routine
        idle_pc = self.pc
        if core.missing:
            idle_pc = Mux(take & coast, p.start("predict"), idle_pc)
        if bus:
            idle_pc = Mux(self.start_commit, p.start("commit"),
                          Mux(self.start_clear, p.start("clear"), Mux(self.start_reset, 0, idle_pc)))
        m.d.comb += [self.sample_write.eq(idle & core.i.valid & free & ~held),
                     take.eq(self.sample_write & last_digit),
                     self.pc_next.eq(Mux(self.issue, Mux(self.back, self.word["d"], self.pc + 1),
                                         Mux(self.finished, Mux(restart, 0, self.update_start), idle_pc)))]
        with m.If(self.sample_write):
            m.d.sync += self.load.eq(self.load + 1)
            with m.If(last_digit):  # the last digit: the word is taken, the update runs
                m.d.sync += [self.channel.eq(core.i.payload.channel), self.fo.eq(0), self.load.eq(0),
                             self.running.eq(1)]
        with m.Elif(idle):
            m.d.sync += self.load.eq(0)
        if bus:
            with m.If(self.start_commit | self.start_clear):
                m.d.sync += [self.running.eq(1), self.committing.eq(1)]
            with m.If(self.start_reset):
                m.d.sync += [self.running.eq(1), initializing.eq(1), self.channel.eq(0), self.reset_pending.eq(0)]
        with m.If(self.finished):  # the last step's write is in this cycle
            m.d.sync += self.ending.eq(0)
            with m.If(self.committing):  # the commit, or (none pending) the clear
                m.d.sync += [self.committing.eq(0), self.running.eq(0), self.commit_pending.eq(0)]
                with m.If(~self.commit_pending):
                    m.d.sync += self.clear_pending.eq(0)
            with m.Elif(~initializing):
                m.d.sync += [core.o.valid.eq(1), self.running.eq(0)]
            with m.Elif(~restart):  # every channel's reset state written
                m.d.sync += [self.channel.eq(0), initializing.eq(0), self.running.eq(0)]
            with m.Else():  # the next channel's
                m.d.sync += self.channel.eq(self.channel + 1)

    def write_port(self):
        """The register file's one write port: a sample's digit, a step's, or (with a bus) a
        setting's digit, in a cycle the other two leave free."""
        m, bus = self.m, self.core.bus is not None
        self.sample_write, self.sample_addr, self.sample_data = self.sample_port()
        # a setting's digit, straight from the bus (registers() drives them): the bus waits while
        # the port is taken
        self.bus_write = Signal(name="bus_write")
        self.bus_addr = Signal(self.abits, name="bus_addr")
        self.bus_data = Signal(WORD, name="bus_data")
        self.port_busy = Signal(name="port_busy")
        m.d.comb += self.port_busy.eq(self.sample_write | self.step_write)
        addr, data = self.step_addr, self.digit
        if bus:
            addr, data = Mux(self.step_write, addr, self.bus_addr), Mux(self.step_write, data, self.bus_data)
        m.d.comb += [self.wr_addr.eq(Mux(self.sample_write, self.sample_addr, addr)),
                     self.wr_data.eq(Mux(self.sample_write, self.sample_data, data)),
                     self.wr_en.eq(self.sample_write | self.step_write | (self.bus_write if bus else 0))]

    def registers(self):
        """The bus slave: the fixed registers, the settings' shadow words and the overflow counters
        (``hw/regmap.py``), behind Avalon-MM or AXI4-Lite. A setting's digit goes into the register
        file in a cycle nothing else writes it; a write waits (``waitrequest``, no ``awready``)
        while the port is taken or a commit is pending. A read answers the next cycle; a counter's
        (a word of the register file) the cycle after, once no routine runs."""
        from kfpga.hw.regmap import counters_base

        m, core, p = self.m, self.core, self.p
        abits = core.bus_address_bits
        # a write's address and a read's apart: no multiplexer between them on either path
        r = {"addr": Signal(abits, name="reg_raddr"), "waddr": Signal(abits, name="reg_waddr"),
             "wdata": Signal(32, name="reg_wdata"),
             "offer": Signal(name="reg_offer"), "roffer": Signal(name="reg_roffer"), "write": Signal(name="reg_write"),
             "read": Signal(name="reg_read"), "stall": Signal(name="reg_stall"), "rstall": Signal(name="reg_rstall"),
             "rdata": Signal(32, name="reg_rdata", reset_less=True), "done": Signal(name="reg_done")}
        self.reg_port = r
        base = counters_base(p)
        is_counter = (r["addr"] >= base) & (r["addr"] < base + len(p.counters))
        # a counter is read through the register file's first port: not while a routine runs, and one
        # read at a time
        # (its address registered first: the port's address path is the core's longest), one read at
        # a time, and not when a routine runs in the next cycle
        want, in_flight = Signal(name="counter_want"), Signal(name="counter_read")
        counter_addr = Signal(self.abits, name="counter_addr", reset_less=True)
        starting = self.take | self.start_commit | self.start_clear | self.start_reset
        m.d.comb += [r["rstall"].eq(r["roffer"] & ((is_counter & (self.running | starting)) | want | in_flight)),
                     r["read"].eq(r["roffer"] & ~r["rstall"])]
        self.settings_port(r)
        value = self.fixed_registers(r)
        with m.If(want):
            m.d.comb += self.reads[1].addr.eq(counter_addr)
        m.d.sync += [want.eq(r["read"] & is_counter), in_flight.eq(want), counter_addr.eq(r["addr"] + (p.counter_base - base)),
                     r["done"].eq((r["read"] & ~is_counter) | in_flight)]
        with m.If(r["read"] & ~is_counter):
            m.d.sync += r["rdata"].eq(value)
        with m.If(in_flight):  # a counter's word (its low digit: 17 bits)
            m.d.sync += r["rdata"].eq(self.reads[1].data[:DIGIT])
        (self.avalon if core.bus == "avalon" else self.axi4lite)()

    def settings_port(self, r):
        """A setting's digit from the bus to its shadow word."""
        from kfpga.hw.regmap import SETTINGS_BASE

        m, p = self.m, self.p
        n = p.shadow_words
        addr = r["waddr"]
        is_setting = (addr >= SETTINGS_BASE) & (addr < SETTINGS_BASE + n)
        # a setting's write waits while the register file's write port is taken or a commit is pending
        m.d.comb += [r["stall"].eq(r["offer"] & is_setting & (self.port_busy | self.commit_pending)),
                     r["write"].eq(r["offer"] & ~r["stall"])]
        # a lower digit keeps 17 bits (the word's top bit 0), the top digit of each setting 18
        tops = sum(1 << (SETTINGS_BASE + st.shadow + st.digits - 1) for st in p.settings)
        top_digit = Const(tops, SETTINGS_BASE + max(n, 1)).bit_select(addr, 1)
        m.d.comb += [self.bus_write.eq(r["offer"] & is_setting & ~r["stall"]),
                     self.bus_addr.eq(addr + (p.shadow_base - SETTINGS_BASE)),
                     self.bus_data.eq(Cat(r["wdata"][:DIGIT], r["wdata"][DIGIT] & top_digit))]

    def fixed_registers(self, r):
        """``CONTROL``'s actions, the counters in logic, and the value a read of a fixed register gives."""
        from kfpga.hw.regmap import (
            COMMITTED,
            CONTROL,
            CONTROL_BITS,
            COUNT_BITS,
            ID,
            INFO,
            OVERFLOWS,
            STATUS,
            UPDATES,
            VERSION,
            identity,
        )

        m, core, p = self.m, self.core, self.p
        updates, overflows, committed = (Signal(COUNT_BITS, name=f"reg_{x}") for x in ("updates", "overflows", "committed"))
        ovf_seen = Signal(name="reg_overflow")
        control = r["offer"] & (r["waddr"] == CONTROL)  # never held: only a setting's write waits
        wdata = r["wdata"]
        with m.If(control & wdata[CONTROL_BITS["CLEAR"]]):
            m.d.sync += [updates.eq(0), overflows.eq(0), committed.eq(0), ovf_seen.eq(0), self.clear_pending.eq(1)]
        with m.Else():
            with m.If(self.take):
                m.d.sync += updates.eq(updates + 1)
            with m.If(core.o.valid & core.o.ready & core.o.payload.overflow):
                m.d.sync += ovf_seen.eq(1)
                with m.If(~overflows.all()):  # it holds at its largest value
                    m.d.sync += overflows.eq(overflows + 1)
            with m.If(self.start_commit):
                m.d.sync += committed.eq(updates)
        with m.If(control & wdata[CONTROL_BITS["COMMIT"]]):
            m.d.sync += self.commit_pending.eq(1)
        with m.If(control & wdata[CONTROL_BITS["RESET"]]):
            m.d.sync += self.reset_pending.eq(1)
        info = VERSION | (core.channels - 1) << 8 | p.shadow_words << 16
        pending = Cat(self.commit_pending, self.reset_pending, self.clear_pending)
        status = Cat(self.commit_pending, self.reset_pending, ovf_seen, self.running, self.clear_pending)
        value = Const(0, 32)
        for j, reg in ((ID, Const(identity(core.config, core.variant), 32)), (INFO, Const(info, 32)),
                       (CONTROL, pending), (STATUS, status), (UPDATES, updates), (OVERFLOWS, overflows),
                       (COMMITTED, committed)):
            value = Mux(r["addr"] == j, reg, value)
        return value

    def avalon(self):
        """Avalon-MM: word addresses, ``waitrequest`` for an access that must wait, the read data
        with ``readdatavalid`` (the cycle after the read, a counter's one later)."""
        m, core, r = self.m, self.core, self.reg_port
        m.d.comb += [r["addr"].eq(core.avs_address), r["waddr"].eq(core.avs_address), r["wdata"].eq(core.avs_writedata),
                     r["offer"].eq(core.avs_write), r["roffer"].eq(core.avs_read),
                     core.avs_waitrequest.eq(r["stall"] | r["rstall"]), core.avs_readdata.eq(r["rdata"]),
                     core.avs_readdatavalid.eq(r["done"])]

    def axi4lite(self):
        """AXI4-Lite: byte addresses; a write takes its address and data together (``awready`` and
        ``wready`` in one cycle), answered with ``bvalid`` (OKAY); a read with ``rvalid`` once its
        data is in (OKAY), held until taken."""
        m, core, r = self.m, self.core, self.reg_port
        bvalid, rvalid, busy = Signal(name="axil_bvalid"), Signal(name="axil_rvalid"), Signal(name="axil_reading")
        offered = core.s_axil_awvalid & core.s_axil_wvalid & ~bvalid
        m.d.comb += [r["waddr"].eq(core.s_axil_awaddr[2:]), r["addr"].eq(core.s_axil_araddr[2:]),
                     r["wdata"].eq(core.s_axil_wdata), r["offer"].eq(offered),
                     r["roffer"].eq(core.s_axil_arvalid & ~rvalid & ~busy & ~offered),
                     core.s_axil_awready.eq(r["write"]), core.s_axil_wready.eq(r["write"]),
                     core.s_axil_arready.eq(r["read"]),
                     core.s_axil_bvalid.eq(bvalid), core.s_axil_bresp.eq(0),
                     core.s_axil_rvalid.eq(rvalid), core.s_axil_rresp.eq(0), core.s_axil_rdata.eq(r["rdata"])]
        with m.If(r["write"]):
            m.d.sync += bvalid.eq(1)
        with m.Elif(core.s_axil_bready):
            m.d.sync += bvalid.eq(0)
        with m.If(r["read"]):
            m.d.sync += busy.eq(1)
        with m.If(r["done"]):
            m.d.sync += [busy.eq(0), rvalid.eq(1)]
        with m.Elif(core.s_axil_rready):
            m.d.sync += rvalid.eq(0)

    def sample_port(self):
        """The register file's write port for a sample's digits: ``(enable, address, data)``, the
        digit ``load`` of the input word (the lower digits unsigned, the top one sign-extended)."""
        m, core, p = self.m, self.core, self.p
        self.load = Signal(range(max(len(p.sample_addrs), 2)), name="load")
        write, addr, data = Signal(name="sample_write"), Signal(self.abits, name="sample_addr"), Signal(WORD,
                                                                                                       name="sample_digit")
        digits = []
        for name, dgt, a in p.sample_addrs:
            value = getattr(core.i.payload, name)
            if dgt < p.input_digits - 1:
                digits.append((a, value.as_unsigned()[DIGIT * dgt:DIGIT * (dgt + 1)]))
            else:
                digits.append((a, value.as_signed() >> (DIGIT * dgt)))
        sel_addr, sel_data = digits[0][0], digits[0][1]
        for j, (a, value) in enumerate(digits[1:], start=1):  # a chain of multiplexers, not a case block
            sel_addr, sel_data = Mux(self.load == j, a, sel_addr), Mux(self.load == j, value, sel_data)
        m.d.comb += [addr.eq(sel_addr), data.eq(sel_data)]
        return write, addr, data

    def outputs(self):
        """The estimate's fields from the output chunks; the sample's flag and the sticky one."""
        m, core = self.m, self.core
        with m.If(core.o.valid & core.o.ready):
            m.d.sync += core.o.valid.eq(0)
        sticky = Signal(name="sticky")
        m.d.comb += [core.o.payload.channel.eq(self.channel), core.o.payload.overflow.eq(self.fo),
                     core.overflow.eq(sticky | (core.o.valid & self.fo))]
        m.d.comb += [getattr(core.o.payload, name).eq(reg) for name, reg in self.outs.items()]
        m.d.sync += sticky.eq(core.overflow)


def make_core(config, variant, *, channels=1, stages=None, missing=False, bus=None):
    """The folded core of any filter's ``variant`` (``channels`` channel states), with the missing
    bit and a register bus if asked; ``stages`` does not apply (it runs one step at a time)."""
    if stages is not None:
        raise ValueError("stages applies to a pipelined loop; the folded core runs one step at a time")
    return FoldedCore(config, variant, channels=channels, missing=missing, bus=bus)
