"""Formal properties of the blocks: each a harness around one block, with ``Assert``, ``Assume``
and ``Cover`` statements, proven by SymbiYosys (``kfpga/verify/formal.py``, ``make formal``).

A harness drives every input of its block from a top-level port, so the solver chooses them
freely in every cycle; ``Assume`` narrows them to what the block may expect (the stream
contract on its inputs, an ADC clock strobe no more often than every other cycle). Monitors
(counters, copies of last cycle's values) are ordinary registers of the harness. Each property
keeps its own ``Assert`` statements and ``Cover`` statements that show it is not vacuous: a
harness built with ``only=name`` holds that property alone, so each is proven by itself.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import ClassVar

from amaranth import Elaboratable, Module, Mux, ResetSignal, Signal
from amaranth.hdl import Assert, Assume, Cover

from kfpga.hw.ads8364 import CONV0, N_STATES, READ0, ADS8364Controller
from kfpga.hw.clockdiv import ClockDivider
from kfpga.hw.divider import Divider

__all__ = ["Harness", "ClockDividerProps", "DividerProps", "ControllerProps", "StreamProps"]


class Harness(Elaboratable):
    """A block, its monitors and its properties; :meth:`properties` names what it can check.

    ``only``: the names of the properties to build (default: all). ``free_state``: the block's
    registers start in any state (the formal script removes their initial values), for
    properties that hold from every state.
    """

    #: property name -> one line saying what it states
    PROPERTIES: ClassVar[dict] = {}
    free_state = False

    def __init__(self, only=None):
        unknown = set(only or ()) - set(self.PROPERTIES)
        if unknown:
            raise ValueError(f"unknown properties {sorted(unknown)}; known: {', '.join(self.PROPERTIES)}")
        self.only = set(only) if only else set(self.PROPERTIES)
        self.ports = []

    def want(self, name):
        return name in self.only

    def port(self, shape, name, init=0):
        sig = Signal(shape, name=name, init=init)
        self.ports.append(sig)
        return sig

    @staticmethod
    def past(m, value, name, init=0):
        """``value`` one cycle ago (``init`` in the first cycle)."""
        reg = Signal.like(value, name=name, init=init) if hasattr(value, "shape") else Signal(name=name, init=init)
        m.d.sync += reg.eq(value)
        return reg

    @staticmethod
    def counter(m, name, bits, *, clear, count, init=0):
        """Counts cycles with ``count`` high since ``clear`` (saturating at its largest value)."""
        reg = Signal(bits, name=name, init=init)
        with m.If(clear):
            m.d.sync += reg.eq(0)
        with m.Elif(count & (reg != (1 << bits) - 1)):
            m.d.sync += reg.eq(reg + 1)
        return reg

    @staticmethod
    def reset():
        """The reset of the ``sync`` domain, a free input of the harness like the others. (The
        domain is the implicit one: its clock and reset become ports; a domain defined here would
        leave them undriven.)"""
        return ResetSignal("sync")


def assert_held(m, h, port, rst, what="o held until ready"):
    """The stream contract of an output ``port``: ``valid``, once high, stays high with the same
    payload until ``ready``. Returns ``held``: the word offered last cycle was not taken."""
    held = h.past(m, port.valid & ~port.ready & ~rst, "o_held")
    was = h.past(m, port.payload.as_value(), "o_payload_was")
    with m.If(held & ~rst):
        m.d.comb += Assert(port.valid & (port.payload.as_value() == was), what)
    return held


class ClockDividerProps(Harness):
    """The clock divider from any power-up state (it has no reset)."""

    PROPERTIES: ClassVar[dict] = {
        "strobe period": "strobe comes exactly every `ratio` system cycles",
        "ADC clock high and low": "clk_out is high ratio//2 cycles and low ratio - ratio//2, every period, and "
                                  "rises right after each strobe (logic on the strobe moves with the ADC clock edge)",
    }

    def __init__(self, ratio=10, only=None):
        super().__init__(only)
        # the strobe period holds from any state; the clock's first period after a state the
        # counter cannot reach (ratio 5: 5..7 of its 3 bits) is short, so that one is proven
        # from power-up, as the FPGA starts
        self.free_state = self.only == {"strobe period"}
        self.ratio = ratio
        self.dut = ClockDivider(ratio=ratio)

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = d = self.dut
        r = self.ratio
        bits = r.bit_length() + 1
        if self.want("strobe period"):
            seen = Signal(name="strobe_seen")
            with m.If(d.strobe):
                m.d.sync += seen.eq(1)
            gap = self.counter(m, "gap", bits, clear=d.strobe, count=1)
            m.d.comb += Assert(~seen | (gap <= r - 1), "no more than ratio cycles between strobes")
            with m.If(d.strobe & seen):
                m.d.comb += Assert(gap == r - 1, "a strobe every ratio cycles")
            m.d.comb += Cover(d.strobe & seen & (gap == r - 1))
        if self.want("ADC clock high and low"):
            before = self.past(m, d.clk_out, "clk_was")
            known = self.past(m, 1, "clk_was_known")  # ``before`` is a real level from the second cycle on
            edges = Signal(2, name="clk_edges")  # a run is only whole after the first edge
            changed = known & (d.clk_out != before)
            with m.If(changed & (edges != 3)):
                m.d.sync += edges.eq(edges + 1)
            run = self.counter(m, "run", bits, clear=changed, count=1)  # cycles since the level began, minus one
            high, low = r // 2, r - r // 2
            with m.If(changed & (edges != 0)):  # a whole run of the level ``before`` just ended
                m.d.comb += Assert(Mux(before, run + 1 == high, run + 1 == low),
                                   "clk_out high ratio//2 and low ratio - ratio//2 cycles")
            m.d.comb += Assert((edges == 0) | (run + 1 <= max(high, low)), "no longer level run")
            strobe_was = self.past(m, d.strobe, "strobe_was")
            m.d.comb += Assert(~known | (strobe_was == (d.clk_out & ~before)), "clk_out rises the cycle after a strobe")
            m.d.comb += [Cover(changed & before & (edges != 0)), Cover(changed & ~before & (edges != 0))]
        return m


class DividerProps(Harness):
    """The restoring divider, one request at a time, every dividend and divisor of its widths."""

    PROPERTIES: ClassVar[dict] = {
        "quotient": "no overflow: q*d <= n < (q+1)*d; overflow: q is all ones",
        "overflow": "overflow exactly when d = 0 or the quotient does not fit (n >= d << qbits)",
        "stream contract": "o.valid held with its payload until ready; one result per request, in order",
    }

    def __init__(self, dividend_bits, divisor_bits, quotient_bits, only=None, invariants=True):
        super().__init__(only)
        self.invariants = invariants  # state the restoring step's invariant (for k-induction)
        self.widths = (dividend_bits, divisor_bits, quotient_bits)
        self.dut = Divider(dividend_bits=dividend_bits, divisor_bits=divisor_bits, quotient_bits=quotient_bits)

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = d = self.dut
        nb, db, qb = self.widths
        valid, ready = self.port(1, "i_valid"), self.port(1, "o_ready")
        dividend, divisor = self.port(nb, "i_dividend"), self.port(db, "i_divisor")
        m.d.comb += [d.i.valid.eq(valid), d.i.payload.dividend.eq(dividend), d.i.payload.divisor.eq(divisor),
                     d.o.ready.eq(ready)]
        rst = self.reset()
        # the request being divided, and how many results are owed
        req_n, req_d = Signal(nb, name="req_dividend"), Signal(db, name="req_divisor")
        owed = Signal(2, name="owed")
        take, give = d.i.valid & d.i.ready, d.o.valid & d.o.ready
        with m.If(take):
            m.d.sync += [req_n.eq(dividend), req_d.eq(divisor)]
        m.d.sync += owed.eq(owed + take - give)
        new = d.o.valid & ~self.past(m, d.o.valid & ~d.o.ready, "result_held")
        q, ovf = d.o.payload.quotient, d.o.payload.overflow
        fits = (req_d != 0) & ((req_n >> qb) < req_d)
        # invariants of the restoring step, so that k-induction needs no long prefix: while busy,
        # the request equals (quotient d + remainder) 2^count + the bits not yet brought down
        lows = d.low >> (qb - d.count).as_unsigned()
        m.d.comb += Assert(d.count <= qb, "count within its range")
        if self.invariants:  # stated only for k-induction (a BMC job leaves the multiplier out)
            with m.If(d.busy & ~rst):
                m.d.comb += Assert(d.divisor == req_d, "the divisor is the request's")
                m.d.comb += Assert(d.overflowed == ~fits, "the overflow decision is the request's")
                with m.If(~d.overflowed):
                    m.d.comb += Assert(d.remainder < d.divisor, "remainder below the divisor")
                    m.d.comb += Assert(((d.quotient * d.divisor + d.remainder) << d.count) + lows == req_n,
                                       "the division so far accounts for the dividend")
                m.d.comb += Assert(owed == 1, "a busy divider owes one result")
                m.d.comb += Assert((d.count >= 1) & ~d.o.valid, "busy: bits left, no result shown")
            with m.If(~d.busy & ~rst):
                m.d.comb += Assert(owed == d.o.valid, "an idle divider owes what it shows")
        shown = d.o.valid & ~rst  # every cycle a result is shown, not only its first
        if self.want("quotient"):
            with m.If(shown & ~ovf):
                m.d.comb += Assert((q * req_d <= req_n) & (req_n < (q + 1) * req_d), "q = floor(n / d)")
            with m.If(shown & ovf):
                m.d.comb += Assert(q == (1 << qb) - 1, "overflow: the largest quotient")
            m.d.comb += Cover(new & ~ovf & (q != 0) & (req_d > 1))
        if self.want("overflow"):
            with m.If(shown):
                m.d.comb += Assert(ovf == ~fits, "overflow iff d = 0 or n >= d << qbits")
            m.d.comb += [Cover(new & ovf & (req_d != 0)), Cover(new & ovf & (req_d == 0))]
        if self.want("stream contract"):
            held = assert_held(m, self, d.o, rst)
            m.d.comb += Assert(owed <= 1, "one request at a time")
            with m.If(d.o.valid & ~rst):
                m.d.comb += Assert(owed == 1, "a result only for a request")
            m.d.comb += Cover(held & ~rst & d.o.ready)
        return m


class ControllerProps(Harness):
    """The ADS8364 controller, with the strobe free but never in two cycles in a row."""

    PROPERTIES: ClassVar[dict] = {
        "recovery": "from every state (the 10 illegal ones included) it is in CONV0 within `bound` CLK periods; "
                    "an illegal state restarts cleanly (RESET low first)",
        "address stable": "A2..A0 never change while RD is low, and are stable one system cycle before RD falls",
        "HOLD pulse": "HOLD is low for exactly one CLK period, and falls again only 20 periods (a conversion) "
                      "later or after a RESET pulse",
        "RD under CS": "RD is only low while CS is low",
        "one word per read": "one output word per read (RD pulse), held until taken: none is lost or overwritten; "
                             "1 or 6 words per conversion, none only after a timeout",
        "timeout": "the timeout flag rises if and only if EOC has not come `timeout_periods` CLK periods "
                   "after the conversion started",
    }

    def __init__(self, *, six_channel=False, channel=0, timeout_periods=40, only=None):
        super().__init__(only)
        self.dut = ADS8364Controller(channel=channel, six_channel=six_channel, timeout_periods=timeout_periods)
        self.six_channel = six_channel
        self.reads = 6 if six_channel else 1
        # CONV0 -> CONV19 waiting for EOC until the timeout, then the reads (the 3-bit read index
        # from any value: up to 8 READ0/READ1 pairs), back to CONV0
        self.bound = timeout_periods + 2 * 8 + 2
        self.free_state = only is not None and set(only) == {"recovery"}

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = c = self.dut
        rst = self.reset()
        strobe, enable, eoc = self.port(1, "strobe"), self.port(1, "enable"), self.port(1, "eoc", init=1)
        data, ready = self.port(16, "data"), self.port(1, "o_ready")
        m.d.comb += [c.strobe.eq(strobe), c.enable.eq(enable), c.eoc.eq(eoc), c.data.eq(data), c.o.ready.eq(ready)]
        strobe_was = self.past(m, strobe, "strobe_was")
        m.d.comb += Assume(~(strobe & strobe_was))  # the divider's strobe: at most every other cycle
        w = c.word
        hold = w.hold_a & w.hold_b & w.hold_c  # 0 while any HOLD is low
        rst_was = self.past(m, rst, "rst_was", init=1)
        quiet = ~rst & ~rst_was  # no reset now or last cycle
        t = SimpleNamespace(c=c, w=w, rst=rst, rst_was=rst_was, quiet=quiet, hold=hold, strobe=strobe, eoc=eoc,
                            ready=ready)
        for name, build in (("recovery", self._recovery), ("address stable", self._address_stable),
                            ("HOLD pulse", self._hold_pulse), ("RD under CS", self._rd_under_cs),
                            ("one word per read", self._one_word_per_read), ("timeout", self._timeout)):
            if self.want(name):
                build(m, t)
        return m

    def _recovery(self, m, t):
        """The property "recovery" (:attr:`PROPERTIES`)."""
        c, w, rst, strobe, ready = t.c, t.w, t.rst, t.strobe, t.ready
        m.d.comb += [Assume(ready), Assume(~rst)]
        since = self.counter(m, "since_conv0", 7, clear=c.state == CONV0, count=strobe)
        m.d.comb += Assert(since <= self.bound, "back in CONV0 within the bound")
        illegal = self.past(m, strobe & (c.state >= N_STATES), "was_illegal")
        illegal2 = self.past(m, illegal, "was_illegal2")
        with m.If(illegal):
            m.d.comb += Assert((c.state == CONV0) & (c.restart == 2) & (c.read_index == 0),
                               "an illegal state goes to CONV0, restart, read index 0")
        with m.If(illegal2):
            m.d.comb += Assert(~w.reset, "the clean start shows RESET low first")
        m.d.comb += [Cover(illegal2), Cover(since >= self.dut.timeout_periods)]

    def _address_stable(self, m, t):
        """The property "address stable" (:attr:`PROPERTIES`)."""
        c, w = t.c, t.w
        rd_was = self.past(m, w.rd, "rd_was", init=1)
        addr_was = self.past(m, c.addr, "addr_was")
        with m.If(~rd_was):  # RD was low: the address did not move, not even as RD rises
            m.d.comb += Assert(c.addr == addr_was, "A2..A0 stable while RD is low")
        with m.If(rd_was & ~w.rd):
            m.d.comb += Assert(c.addr == addr_was, "A2..A0 set a cycle before RD falls")
        m.d.comb += Cover(rd_was & ~w.rd & (c.addr == (5 if self.six_channel else self.dut.channel)))

    def _hold_pulse(self, m, t):
        """The property "HOLD pulse" (:attr:`PROPERTIES`)."""
        w, rst, quiet, hold, strobe = t.w, t.rst, t.quiet, t.hold, t.strobe
        hold_was = self.past(m, hold, "hold_was", init=1)
        fell, rose = hold_was & ~hold, ~hold_was & hold
        # strobes while HOLD is low, the one in the cycle it falls included (the word moves two
        # cycles after a strobe: with strobes every other cycle the next one comes with it)
        low_strobes = Signal(3, name="low_strobes")
        with m.If(fell):
            m.d.sync += low_strobes.eq(strobe)
        with m.Elif(strobe & ~hold & (low_strobes != 7)):
            m.d.sync += low_strobes.eq(low_strobes + 1)
        since_fall = self.counter(m, "since_fall", 6, clear=fell, count=strobe)
        falls = Signal(2, name="hold_falls")
        reset_pulse = Signal(name="reset_pulse_since_fall")  # RESET low (or a reset) since the last fall
        with m.If(fell):
            m.d.sync += reset_pulse.eq(0)
            with m.If(falls != 3):
                m.d.sync += falls.eq(falls + 1)
        with m.Elif(~w.reset | rst):
            m.d.sync += reset_pulse.eq(1)
        with m.If(rose & quiet & ~reset_pulse):
            m.d.comb += Assert(low_strobes == 1, "HOLD low for one CLK period")
        m.d.comb += Assert(hold | (low_strobes <= 1) | reset_pulse | rst, "never low for two periods")
        with m.If(fell & (falls != 0) & ~reset_pulse):
            m.d.comb += Assert(since_fall >= 20, "no HOLD while a conversion runs")
        m.d.comb += [Cover(rose & quiet & (low_strobes == 1)), Cover(fell & (falls != 0) & ~reset_pulse)]

    def _rd_under_cs(self, m, t):
        """The property "RD under CS" (:attr:`PROPERTIES`)."""
        w = t.w
        m.d.comb += Assert(w.rd | ~w.cs, "RD low only while CS is low")
        m.d.comb += Cover(~w.rd)

    def _one_word_per_read(self, m, t):
        """The property "one word per read" (:attr:`PROPERTIES`)."""
        c, w, rst, rst_was, hold = t.c, t.w, t.rst, t.rst_was, t.hold
        held = assert_held(m, self, c.o, rst, "no word overwritten")
        rd_was = self.past(m, w.rd, "rd_was", init=1)
        new = c.o.valid & ~held
        # words made minus reads ended: a word is valid a cycle before its RD pulse ends
        ahead = Signal(range(-2, 3), name="words_ahead")
        with m.If(rst):
            m.d.sync += ahead.eq(0)
        with m.Else():
            m.d.sync += ahead.eq(ahead + new - (~rd_was & w.rd & ~rst_was))
        m.d.comb += Assert(rst | (ahead == 0) | (ahead == 1), "one word per read")
        hold_was = self.past(m, hold, "hold_was", init=1)
        fell = hold_was & ~hold
        per_conv = self.counter(m, "words_per_conversion", 3, clear=fell | rst, count=new)
        clean = Signal(name="clean_since_fall")  # a HOLD fell with no reset or timeout since
        with m.If(rst):
            m.d.sync += clean.eq(0)
        with m.Elif(fell):
            m.d.sync += clean.eq(1)
        with m.Elif(~w.reset):
            m.d.sync += clean.eq(0)
        with m.If(fell & clean & ~rst):
            m.d.comb += Assert((per_conv == self.reads) | ((per_conv == 0) & c.timeout),
                               "all words of a conversion, or none after a timeout")
        m.d.comb += Assert(per_conv <= self.reads, "no more words than channels")
        m.d.comb += [Cover(fell & clean & (per_conv == self.reads)), Cover(held & ~rst & c.o.ready)]

    def _timeout(self, m, t):
        """The property "timeout" (:attr:`PROPERTIES`)."""
        c, w, rst, rst_was, strobe, eoc = t.c, t.w, t.rst, t.rst_was, t.strobe, t.eoc
        # the EOC edge as the controller sees it: the pin through its two synchroniser
        # flip-flops (which a reset does not clear), then one more
        s1, s2 = Signal(name="eoc_s1", init=1, reset_less=True), Signal(name="eoc_s2", init=1, reset_less=True)
        m.d.sync += [s1.eq(eoc), s2.eq(s1)]
        s3 = self.past(m, s2, "eoc_s3", init=1)
        started = strobe & (c.state == CONV0) & w.start  # the strobe that ends a conversion's HOLD period
        came = Signal(name="eoc_came")  # an EOC edge since that strobe
        with m.If(started | rst):
            m.d.sync += came.eq(0)
        with m.Elif(s3 & ~s2):
            m.d.sync += came.eq(1)
        periods = self.counter(m, "periods_since_start", 7, clear=started | rst, count=strobe)
        waiting = Signal(name="waiting")  # from the start until the controller reads or starts over
        with m.If(started):
            m.d.sync += waiting.eq(1)
        with m.Elif(rst | (c.state == READ0) | (c.state == CONV0)):
            m.d.sync += waiting.eq(0)
        # the deadline: the strobe ending the (timeout_periods - 1)th CLK period after the
        # HOLD period (39 for the default 40: the HOLD period is the first of the 40)
        deadline = strobe & waiting & (periods == self.dut.timeout_periods - 2)
        missed = self.past(m, deadline & ~came & ~rst, "deadline_missed")
        flag_was = self.past(m, c.timeout, "timeout_was")
        rises = c.timeout & ~flag_was & ~rst_was
        with m.If(rises):
            m.d.comb += Assert(missed, "the flag rises only at the deadline, without EOC")
        with m.If(missed & ~rst):
            m.d.comb += Assert(c.timeout, "no EOC by the deadline: the flag is up")
        m.d.comb += [Cover(rises), Cover(self.past(m, deadline & came, "deadline_met") & ~c.timeout)]


class StreamProps(Harness):
    """A filter core's stream ports: the input driven by a producer that keeps the contract."""

    PROPERTIES: ClassVar[dict] = {
        "output contract": "o.valid, once high, stays high with the same payload until o.ready",
        "input only when free": "i.ready only while the core can take a sample: no more in flight than it holds",
        "one output per input": "outputs never outnumber inputs, and all come out once o.ready has been high long "
                                "enough",
        "free when idle": "with nothing in flight and no output waiting, i.ready is high whatever o.ready is: a "
                          "receiver that raises ready only after it sees valid is never deadlocked",
    }

    def __init__(self, core, capacity, drain, only=None, startup=0):
        super().__init__(only)
        self.dut = core
        self.capacity = capacity  # samples the core can hold at once
        self.drain = drain  # cycles with o.ready high (and no input) after which nothing is left
        self.startup = startup  # cycles after reset before the core takes its first sample

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = c = self.dut
        rst = self.reset()
        valid, ready = self.port(1, "i_valid"), self.port(1, "o_ready")
        payload = self.port(len(c.i.payload.as_value()), "i_payload")
        m.d.comb += [c.i.valid.eq(valid), c.i.payload.as_value().eq(payload), c.o.ready.eq(ready)]
        # the producer keeps the contract: a word offered stays, unchanged, until taken
        offered = self.past(m, valid & ~c.i.ready & ~rst, "i_offered")
        was = self.past(m, payload, "i_payload_was")
        with m.If(offered & ~rst):
            m.d.comb += Assume(valid & (payload == was))
        take, give = c.i.valid & c.i.ready, c.o.valid & c.o.ready
        bits = max(self.capacity + 1, 2).bit_length() + 1
        inflight = Signal(bits, name="in_flight")
        with m.If(rst):
            m.d.sync += inflight.eq(0)
        with m.Else():
            m.d.sync += inflight.eq(inflight + take - give)
        if self.want("output contract"):
            held = assert_held(m, self, c.o, rst)
            m.d.comb += Cover(held & ~rst & ready)
        if self.want("input only when free"):
            m.d.comb += Assert(rst | (inflight <= self.capacity), "no more in flight than the core holds")
            m.d.comb += Cover(inflight == self.capacity)
        if self.want("one output per input"):
            with m.If(~rst & c.o.valid):
                m.d.comb += Assert(inflight != 0, "an output only for an input")
            calm = self.counter(m, "drained", 8, clear=rst | take | ~ready, count=1)
            with m.If(~rst & (calm >= self.drain)):
                m.d.comb += Assert(inflight == 0, "every input has come out")
            m.d.comb += Cover(~rst & give & (inflight == 1) & self.past(m, inflight == 1, "one_was"))
        if self.want("free when idle"):
            # cycles since reset, saturating past the core's start-up (its reset state written)
            up = self.counter(m, "since_reset", (self.startup + 2).bit_length() + 1, clear=rst, count=1)
            with m.If(~rst & (up > self.startup) & (inflight == 0) & ~c.o.valid):
                m.d.comb += Assert(c.i.ready, "free when nothing is in flight, whatever o.ready")
            m.d.comb += Cover(~rst & (up > self.startup) & (inflight == 0) & ~ready & c.i.ready)
        return m
