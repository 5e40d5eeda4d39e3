"""Per-channel state storage shared by the cores: one register per channel, read by a mux tree,
or, for many channels, one word per channel in block memory (Cyclone II M4K)."""

from __future__ import annotations

import math

from amaranth import Array, Cat, Const, Elaboratable, Module, Mux, Signal, unsigned
from amaranth.lib.memory import Memory

from kfpga.core.ops import Fx

__all__ = ["state_array", "select", "at", "check_channels", "MAX_REGISTER_CHANNELS", "StateMemory", "m4k_blocks",
           "M4K_WIDTHS"]

#: Channel states kept in registers; more go to block memory (:class:`StateMemory`).
MAX_REGISTER_CHANNELS = 8

#: Cyclone II M4K block: depth -> widest word of one block (4,096 bits, 4,608 with the parity
#: bits, which a 9-, 18- or 36-bit word uses; Cyclone II Device Handbook vol. 1, "Cyclone II
#: Memory Blocks", table "M4K Block Configurations (Simple Dual-Port RAM)").
M4K_WIDTHS = {128: 36, 256: 18, 512: 9, 1024: 4, 2048: 2, 4096: 1}


def m4k_blocks(depth, width, *, two_reads=False):
    """M4K blocks of a ``depth`` x ``width`` simple dual-port RAM: blocks side by side, each as
    wide as the depth allows, and more rows of them past 4,096 words. ``two_reads``: a memory read
    on two ports (true dual-port mode, whose widest word is 18 bits at 256 deep: no 128 x 36)."""
    rows = math.ceil(depth / 4096)
    per_row = min(depth, 4096)
    widths = {d: w for d, w in M4K_WIDTHS.items() if not (two_reads and w > 18)}
    block_depth = next(d for d in sorted(widths) if d >= per_row)
    return rows * math.ceil(width / widths[block_depth])


class StateMemory(Elaboratable):
    """One word per channel holding every state register, in block memory.

    The core drives :attr:`read_addr` every cycle; the word of that channel is in the read
    register at the next clock edge (synchronous, not transparent: a read of the address being
    written gives the old word, as an M4K block does). :meth:`values` reads the state fields of
    the word, zero for a channel outside ``0..channels-1`` (like the register path);
    :meth:`write` writes them back (never for such a channel).

    Parameters
    ----------
    channels:
        Words (the memory's depth).
    formats:
        ``{state name: QFormat}``: the fields of a word, in order.
    reset:
        ``{state name: raw int}``: every word's power-up value.
    """

    def __init__(self, channels, formats, reset):
        self.channels = channels
        self.formats = dict(formats)
        self.width = sum(fmt.width for fmt in self.formats.values())
        word, offset = 0, 0
        for name, fmt in self.formats.items():
            word |= (reset[name] & ((1 << fmt.width) - 1)) << offset
            offset += fmt.width
        self.memory = Memory(shape=unsigned(self.width), depth=channels, init=[word] * channels)
        self._write = self.memory.write_port()
        self._read = self.memory.read_port()
        self.read_addr = Signal.like(self._read.addr, name="state_read_addr")
        self.m4k_blocks = m4k_blocks(channels, self.width)

    def values(self, m, channel):
        """``{state name: Fx}`` of the word read for ``channel`` (the address read a cycle before)."""
        in_range = Signal(name="state_in_range")
        m.d.comb += in_range.eq(channel < self.channels)
        out, offset = {}, 0
        for name, fmt in self.formats.items():
            raw = Signal(unsigned(fmt.width), name=f"{name}_read")
            m.d.comb += raw.eq(Mux(in_range, self._read.data[offset:offset + fmt.width], 0))
            out[name] = Fx(raw.as_signed(), fmt.frac_bits, None, fmt, name)
            offset += fmt.width
        return out

    def write(self, m, enable, channel, raws):
        """Write ``{state name: raw value}`` into ``channel``'s word when ``enable``."""
        m.d.comb += [self._write.addr.eq(channel), self._write.en.eq(enable & (channel < self.channels)),
                     self._write.data.eq(Cat(*(raws[name][:fmt.width] for name, fmt in self.formats.items())))]

    def elaborate(self, platform):
        m = Module()
        m.submodules.memory = self.memory
        m.d.comb += [self._read.addr.eq(self.read_addr), self._read.en.eq(1)]
        return m


def check_channels(channels, limit=MAX_REGISTER_CHANNELS, what="channels"):
    if not isinstance(channels, int) or isinstance(channels, bool):
        raise TypeError(f"{what} must be an integer, not {channels!r}")
    if not 1 <= channels <= limit:
        raise ValueError(f"{what} must be an integer 1..{limit}, not {channels!r}")


def state_array(channels, shape, init, name):
    """One register per channel, all with the same power-up value."""
    return Array(Signal(shape, init=init, name=f"{name}_{c}") for c in range(channels))


def select(states, index):
    """``states[index]`` as a balanced tree of ``Mux`` on the index bits (Verilog ``assign``).

    Not an ``Array`` read: that becomes an ``always @*`` case block, which an event-driven
    simulator (Icarus) leaves undefined until one of its inputs changes; with channel 0 first
    and the state still at its power-up value, that never happens. A mux tree is a continuous
    assignment, defined from time zero, and its depth grows with log2 of the channel count.
    An index outside the array reads zero. With one channel it is the register itself.
    """
    if isinstance(index, int):
        return states[index] if 0 <= index < len(states) else Const(0, states[0].shape())
    if len(states) == 1 and len(index) <= 1:
        return states[0]
    level = list(states)
    while len(level) & (len(level) - 1) or len(level) < 2:
        level.append(Const(0, states[0].shape()))
    bit = 0
    while len(level) > 1:
        level = [Mux(index[bit], level[k + 1], level[k]) for k in range(0, len(level), 2)]
        bit += 1
    if len(index) > bit:  # an index wider than the tree: its high bits set read zero too
        return Mux(index[bit:].any(), Const(0, states[0].shape()), level[0])
    return level[0]


def at(states, index):
    """The register of channel ``index``, as an assignment target."""
    return states[0] if len(states) == 1 else states[index]
