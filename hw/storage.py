"""Per-channel state storage shared by the cores: one register per channel, read by a mux tree."""

from __future__ import annotations

from amaranth import Array, Const, Mux, Signal

__all__ = ["state_array", "select", "at", "check_channels", "MAX_REGISTER_CHANNELS"]

#: Channel states kept in registers (beyond this a core would use block memory).
MAX_REGISTER_CHANNELS = 8


def check_channels(channels, limit=MAX_REGISTER_CHANNELS):
    if not isinstance(channels, int) or isinstance(channels, bool):
        raise TypeError(f"channels must be an integer, not {channels!r}")
    if not 1 <= channels <= limit:
        raise ValueError(f"channels must be an integer 1..{limit}, not {channels!r}")


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
    if len(states) == 1:
        return states[0]
    level = list(states)
    while len(level) & (len(level) - 1):
        level.append(Const(0, states[0].shape()))
    bit = 0
    while len(level) > 1:
        level = [Mux(index[bit], level[k + 1], level[k]) for k in range(0, len(level), 2)]
        bit += 1
    return level[0]


def at(states, index):
    """The register of channel ``index``, as an assignment target."""
    return states[0] if len(states) == 1 else states[index]
