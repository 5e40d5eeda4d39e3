"""cocotb driver and monitor for Amaranth streams on generated Verilog.

Amaranth names a stream port ``p`` as ``p__payload``, ``p__valid`` and ``p__ready``; the payload
is the flat bit vector of an ``amaranth.lib.data`` layout. :func:`pack` and :func:`unpack` use
the layout itself, so the field positions are never written twice.
"""

from __future__ import annotations

import random
import time

from amaranth import Shape
from cocotb.triggers import RisingEdge

__all__ = ["pack", "unpack", "StreamSource", "StreamSink"]


def pack(layout, fields):
    """Integer bit pattern of ``fields`` (a dict of ints) in ``layout``."""
    word = 0
    for name, field in layout:
        width = Shape.cast(field.shape).width
        word |= (int(fields[name]) & ((1 << width) - 1)) << field.offset
    return word


def unpack(layout, word):
    """Dict of the fields of ``word`` in ``layout``; signed fields come back negative."""
    word = int(word)
    out = {}
    for name, field in layout:
        shape = Shape.cast(field.shape)
        value = (word >> field.offset) & ((1 << shape.width) - 1)
        if shape.signed and value >> (shape.width - 1):
            value -= 1 << shape.width
        out[name] = value
    return out


class _StreamPort:
    """The three signals Amaranth writes for stream port ``name``, with its payload layout."""

    def __init__(self, dut, name, clock, layout, rng):
        self.payload = getattr(dut, f"{name}__payload")
        self.valid = getattr(dut, f"{name}__valid")
        self.ready = getattr(dut, f"{name}__ready")
        self.clock = clock
        self.layout = layout
        self.rng = rng


class StreamSource(_StreamPort):
    """Drive ``dut.<name>__payload/__valid`` and honour ``__ready``.

    Parameters
    ----------
    p_idle:
        Probability of inserting an idle cycle before each word (random valid gaps).
    """

    def __init__(self, dut, name, clock, layout, *, rng=None, p_idle=0.0):
        super().__init__(dut, name, clock, layout, rng or random.Random(0))
        self.p_idle = p_idle
        self.sent = 0
        self.valid.value = 0

    async def send(self, words):
        """Send every dict in ``words``; returns when the last one has been accepted."""
        rising = RisingEdge(self.clock)
        for fields in words:
            while self.p_idle and self.rng.random() < self.p_idle:
                self.valid.value = 0
                await rising
            self.payload.value = pack(self.layout, fields)
            self.valid.value = 1
            while True:
                await rising
                if self.ready.value:
                    break
            self.sent += 1
        self.valid.value = 0


class StreamSink(_StreamPort):
    """Accept words from ``dut.<name>__payload/__valid``, driving ``__ready`` at random.

    Parameters
    ----------
    p_ready:
        Probability that ``ready`` is high in a cycle (1.0: always ready).
    """

    def __init__(self, dut, name, clock, layout, *, rng=None, p_ready=1.0):
        super().__init__(dut, name, clock, layout, rng or random.Random(1))
        self.p_ready = p_ready
        self.words = []
        self.ready.value = 1 if p_ready >= 1.0 else 0

    async def run(self, count):
        """Collect ``count`` words, then keep ``ready`` low.

        A word is taken at a rising edge where ``valid`` and ``ready`` are both high; values
        read right at ``RisingEdge`` are those before the edge, which is when the handshake
        happens.
        """
        rising = RisingEdge(self.clock)
        always = self.p_ready >= 1.0
        while len(self.words) < count:
            ready = always or self.rng.random() < self.p_ready
            self.ready.value = int(ready)
            await rising
            if ready and self.valid.value:
                self.words.append(unpack(self.layout, self.payload.value))
        self.ready.value = 0


async def pump(clock, source, sink, words):
    """Send ``words`` through ``source`` and collect as many from ``sink``, in one coroutine.

    Equivalent to running :meth:`StreamSource.send` and :meth:`StreamSink.run` side by side,
    with the same random idle / ready policies, but with one wake-up per clock cycle, signal
    writes only when a value changes, and payloads unpacked after the run: at full rate the
    Python side, not the simulator, sets the pace, and this roughly halves its cost. The time
    spent in the clocked loop is left in ``sink.loop_s``.
    """
    packed = [pack(source.layout, w) for w in words]
    n = len(packed)
    raw = []
    rising = RisingEdge(clock)
    i_payload, i_valid, i_ready = source.payload, source.valid, source.ready
    o_payload, o_valid, o_ready = sink.payload, sink.valid, sink.ready
    rng_in, rng_out = source.rng, sink.rng
    p_idle, p_ready = source.p_idle, sink.p_ready
    always_ready = p_ready >= 1.0
    if not p_idle and always_ready:
        await _pump_full_rate(rising, packed, raw, source, sink)
        return
    index, offered, valid_level, ready_level = 0, False, 0, None
    t0 = time.perf_counter()
    while len(raw) < n:
        if not offered and index < n and not (p_idle and rng_in.random() < p_idle):
            i_payload.value = packed[index]
            offered = True
        if int(offered) != valid_level:
            valid_level = int(offered)
            i_valid.value = valid_level
        ready = always_ready or rng_out.random() < p_ready
        if ready != ready_level:
            ready_level = ready
            o_ready.value = int(ready)
        await rising
        if offered and i_ready.value:
            index += 1
            offered = False
        if ready and o_valid.value:
            raw.append(int(o_payload.value))
    sink.loop_s = time.perf_counter() - t0
    i_valid.value = 0
    o_ready.value = 0
    source.sent += index
    sink.words.extend(unpack(sink.layout, w) for w in raw)


async def _pump_full_rate(rising, packed, raw, source, sink):
    """:func:`pump` with ``valid`` and ``ready`` held high: the same handshake checks (``ready``
    and ``valid`` are still read every cycle), none of the random-policy work."""
    i_payload, i_valid, i_ready = source.payload, source.valid, source.ready
    o_payload, o_valid, o_ready = sink.payload, sink.valid, sink.ready
    n = len(packed)
    index = 0
    i_payload.value = packed[0]
    i_valid.value = 1
    o_ready.value = 1
    append = raw.append
    t0 = time.perf_counter()
    while len(raw) < n:
        await rising
        if index < n and i_ready.value:
            index += 1
            if index < n:
                i_payload.value = packed[index]
            else:
                i_valid.value = 0
        if o_valid.value:
            append(int(o_payload.value))
    sink.loop_s = time.perf_counter() - t0
    o_ready.value = 0
    source.sent += index
    sink.words.extend(unpack(sink.layout, w) for w in raw)
