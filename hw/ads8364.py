"""ADS8364 controller: the paper's 22-state machine with a 16-bit control word.

States (one ADC CLK period each, advancing on the clock divider's strobe)::

    CONV0          HOLD low: the conversion starts (or idle / ADC reset sequence, see below)
    CONV1..CONV18  converting (HOLD high again: HOLD low width is one CLK period)
    CONV19         converting; stays here until EOC has been seen (or the EOC timeout fires)
    READ0          CS low, A2..A0 = channel: the address settles a whole period before RD falls
    READ1          RD low; the data bus is captured at the end of the period

The machine reads only after the conversion is complete, with the address stable before RD
falls ([Zhong] 4.2.2). In six-channel mode CONV0 pulls all three HOLDs low, so all six
channels are sampled at the same instant, and READ0/READ1 repeat for addresses 0..5.

What a real board needs, beyond the paper:

* EOC passes a 2-flip-flop synchroniser; its falling edge is latched, so a half-period pulse is
  never missed between strobes.
* EOC timeout: if EOC has not come ``timeout_periods`` CLK periods after HOLD fell (default 40,
  two conversion times), the ``timeout`` flag is set and the controller restarts cleanly.
* Clean (re)start: after reset, a timeout, or an illegal state, CONV0 first shows RESET low for
  one period, then one idle period (RESET high >= 20 ns before the next HOLD, tD2), then
  converts. Reset in any state returns to CONV0, idle. The 5-bit state register has 10 illegal
  encodings; they all go to CONV0 with the restart sequence, so none can hang.
* Backpressure: READ0 waits until the output register is free, so a sample is never
  overwritten. A slow consumer stretches the sampling period instead of losing samples.
* The control word is decoded from the state one system cycle after the strobe, so each of
  the two has a cycle to itself (see ``kfpga resources``: it meets 50 MHz with margin); every
  pin moves one system cycle after the strobe. The data bus is captured on the strobe that
  ends READ1, nine system cycles after RD fell.
* The address pins follow the control word one more system cycle late, so A2..A0 never change
  in the same instant RD rises (they are stable while RD is low, tD9).
"""


from amaranth import Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from kfpga.hw.ads8364_timing import hold_pair

__all__ = ["ControlWord", "SampleLayout", "ADS8364Controller", "control_table",
           "N_STATES", "CONV0", "CONV19", "READ0", "READ1"]

N_STATES = 22
CONV0, CONV19, READ0, READ1 = 0, 19, 20, 21


class ControlWord(data.Struct):
    """The controller's 16-bit output word (bit 0 first).

    Pin fields carry pin levels; HOLDx, CS, RD, WR and RESET are active low on the ADS8364.

    ======  ========  =========================================================
    bits    field     meaning
    ======  ========  =========================================================
    0       hold_a    HOLDA pin (0: convert A0/A1)
    1       hold_b    HOLDB pin (0: convert B0/B1)
    2       hold_c    HOLDC pin (0: convert C0/C1)
    3-5     addr      A0, A1, A2 (000..101 select A0..C1 directly)
    6       cs        CS pin
    7       rd        RD pin
    8       wr        WR pin (always 1: the controller never writes the ADC)
    9       byte      BYTE pin (0: one 16-bit word per read)
    10      add       ADD pin (0: no header word; ignored in direct address mode)
    11      reset     RESET pin
    12      start     internal: a conversion starts in this period
    13      wait_eoc  internal: this state waits for EOC
    14      latch     internal: capture the data bus at the end of this period
    15      last      internal: last read of this conversion
    ======  ========  =========================================================
    """

    hold_a: 1
    hold_b: 1
    hold_c: 1
    addr: 3
    cs: 1
    rd: 1
    wr: 1
    byte: 1
    add: 1
    reset: 1
    start: 1
    wait_eoc: 1
    latch: 1
    last: 1


#: One ADC sample and the channel it came from (0..5 = A0..C1).
SampleLayout = data.StructLayout({"channel": 3, "sample": signed(16)})

_IDLE = {"hold_a": 1, "hold_b": 1, "hold_c": 1, "addr": 0, "cs": 1, "rd": 1, "wr": 1, "byte": 0,
         "add": 0, "reset": 1, "start": 0, "wait_eoc": 0, "latch": 0, "last": 0}


def idle_word(addr=0):
    """All pins inactive."""
    return {**_IDLE, "addr": addr}


def control_table(channel=0, six_channel=False):
    """The control word of each of the 22 states, as field dicts (the first read's address).

    CONV0 is shown converting; the controller replaces it by the idle or RESET word while
    idle or restarting. In six-channel mode READ0/READ1 repeat with addresses 0..5 and ``last``
    is set on the sixth read only.
    """
    addr = 0 if six_channel else channel
    table = [idle_word(addr) for _ in range(N_STATES)]
    holds = ("hold_a", "hold_b", "hold_c")
    table[CONV0] = {**table[CONV0], "start": 1,
                    **(dict.fromkeys(holds, 0) if six_channel else {holds[hold_pair(channel)]: 0})}
    table[CONV19] = {**table[CONV19], "wait_eoc": 1}
    table[READ0] = {**table[READ0], "cs": 0}
    table[READ1] = {**table[READ1], "cs": 0, "rd": 0, "latch": 1, "last": 0 if six_channel else 1}
    return table


class ADS8364Controller(wiring.Component):
    """Drive an ADS8364 and deliver its samples as a stream.

    Parameters
    ----------
    channel:
        The channel read in single-channel mode, 0..5 (A0, A1, B0, B1, C0, C1).
    six_channel:
        Convert all six channels with one HOLD and read all six.
    timeout_periods:
        CLK periods after HOLD falls without EOC before the timeout fires (default 40).

    Members
    -------
    strobe : In(1)
        One-cycle enable at the ADC clock rate (from :class:`ClockDivider`).
    enable : In(1)
        Convert while high; idle in CONV0 while low.
    eoc : In(1)
        The EOC pin (active low, asynchronous).
    data : In(16)
        D15..D0.
    word : Out(ControlWord)
        The registered control word: pin levels and internal strobes.
    addr : Out(3)
        The A2..A0 pins (``word.addr`` one system cycle later).
    o : Out(stream.Signature(SampleLayout))
        One word per channel per conversion.
    timeout : Out(1)
        Sticky: an EOC timeout has happened since reset.
    """

    def __init__(self, *, channel=0, six_channel=False, timeout_periods=40):
        if not isinstance(channel, int) or not 0 <= channel <= 5:
            raise ValueError(f"channel must be 0..5 (A0..C1), not {channel!r}")
        if not isinstance(timeout_periods, int) or timeout_periods <= N_STATES:
            raise ValueError(f"timeout_periods must be an integer > {N_STATES} (a conversion takes 20), not {timeout_periods!r}")
        self.channel = channel
        self.six_channel = bool(six_channel)
        self.timeout_periods = timeout_periods
        self.table = control_table(channel, self.six_channel)
        idle = idle_word(self.table[CONV0]["addr"])
        super().__init__({
            "strobe": In(1),
            "enable": In(1),
            "eoc": In(1, init=1),
            "data": In(16),
            "word": Out(ControlWord, init=idle),
            "addr": Out(3, init=idle["addr"]),
            "o": Out(stream.Signature(SampleLayout)),
            "timeout": Out(1),
        })
        # visible to tests, waveforms and the formal properties (kfpga/verify/properties.py)
        self.state = Signal(range(32), name="state")
        self.restart = Signal(range(3), init=2, name="restart")  # 2: RESET low next in CONV0, 1: one idle period, 0: run
        self.read_index = Signal(range(6), name="read_index")
        self.eoc_seen = Signal(name="eoc_seen")

    def elaborate(self, platform):
        m = Module()
        periods = Signal(range(self.timeout_periods + 1))
        word = self.word

        # EOC: 2-FF synchroniser, then latch the falling edge (a half-period pulse between strobes)
        eoc_sync = Signal(init=1)
        eoc_prev = Signal(init=1)
        m.submodules.eoc_sync = FFSynchronizer(self.eoc, eoc_sync, init=1, stages=2)
        m.d.sync += eoc_prev.eq(eoc_sync)
        with m.If(eoc_prev & ~eoc_sync):
            m.d.sync += self.eoc_seen.eq(1)

        # A2..A0 follow the word one cycle late, even across a reset (reset_less): they never
        # change in the same instant RD rises, not even when a reset ends a read
        addr_pins = Signal(3, init=self.table[CONV0]["addr"], reset_less=True)
        m.d.sync += addr_pins.eq(word.addr)
        m.d.comb += self.addr.eq(addr_pins)
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)

        self._next_state(m, periods)
        self._decode_word(m)
        return m

    def _next_state(self, m, periods):
        """On each strobe, the next state and the read index, and the EOC timeout's count."""
        state, restart, read_index, eoc_seen = self.state, self.restart, self.read_index, self.eoc_seen
        word = self.word
        next_state = Signal.like(state)
        next_index = Signal.like(read_index)
        # the limit compare is registered: periods moves only on a strobe, the compare is read
        # on the next one
        at_limit = Signal()
        m.d.sync += at_limit.eq(periods >= self.timeout_periods - 1)
        # the count stops at the limit: an upset that puts it beyond (its register has room up to
        # the next power of two) cannot make it wrap round and delay the timeout
        counted = Signal.like(periods)  # one adder and compare for both states that count
        m.d.comb += counted.eq(Mux(periods >= self.timeout_periods, periods, periods + 1))
        m.d.comb += [next_state.eq(state), next_index.eq(read_index)]

        with m.If(self.strobe):
            with m.Switch(state):
                with m.Case(CONV0):
                    with m.If(word.start):
                        m.d.comb += next_state.eq(1)
                        m.d.sync += [periods.eq(1), eoc_seen.eq(0)]
                with m.Case(*range(1, CONV19)):
                    m.d.comb += next_state.eq(state + 1)
                    m.d.sync += periods.eq(counted)
                with m.Case(CONV19):
                    m.d.sync += periods.eq(counted)
                    with m.If(eoc_seen):
                        m.d.comb += next_state.eq(READ0)
                    with m.Elif(at_limit):  # the EOC timeout: flag it, start over cleanly
                        m.d.comb += next_state.eq(CONV0)
                        m.d.sync += [self.timeout.eq(1), restart.eq(2)]
                with m.Case(READ0):
                    with m.If(~self.o.valid | self.o.ready):
                        m.d.comb += next_state.eq(READ1)
                with m.Case(READ1):
                    m.d.sync += [
                        self.o.valid.eq(1),
                        self.o.payload.channel.eq(read_index if self.six_channel else self.channel),
                        self.o.payload.sample.eq(self.data),
                    ]
                    if self.six_channel:
                        with m.If(read_index != 5):
                            m.d.comb += [next_state.eq(READ0), next_index.eq(read_index + 1)]
                        with m.Else():
                            m.d.comb += [next_state.eq(CONV0), next_index.eq(0)]
                    else:
                        m.d.comb += next_state.eq(CONV0)
                with m.Default():  # one of the 10 illegal encodings: start over cleanly
                    m.d.comb += [next_state.eq(CONV0), next_index.eq(0)]
                    m.d.sync += restart.eq(2)
            m.d.sync += [state.eq(next_state), read_index.eq(next_index)]

    def _decode_word(self, m):
        """The pins' word of the period that began."""
        state, restart, read_index, word = self.state, self.restart, self.read_index, self.word
        # the word of the period that began, decoded from the state one system cycle after the
        # strobe (and registered: no glitches). Deciding the next state and decoding its word in
        # the strobe's own cycle would put both between two registers, 14 LUT levels; this way
        # each has a cycle. Every pin moves one system cycle after the strobe, together. A CONV0
        # period shows the restart phase (2: RESET low, 1: one idle period, 0: convert), which
        # then counts down.
        decode = Signal()
        m.d.sync += decode.eq(self.strobe)
        with m.If(decode):
            next_word = Signal(ControlWord)
            with m.Switch(state):
                for s, fields in enumerate(self.table):
                    with m.Case(s):
                        m.d.comb += next_word.eq(ControlWord.const(fields))
                with m.Default():
                    m.d.comb += next_word.eq(ControlWord.const(idle_word()))
            if self.six_channel:
                m.d.comb += [next_word.addr.eq(read_index), next_word.last.eq(next_word.latch & (read_index == 5))]
            with m.If(state == CONV0):
                with m.If(restart == 2):
                    m.d.comb += next_word.eq(ControlWord.const({**idle_word(self.table[CONV0]["addr"]), "reset": 0}))
                with m.Elif((restart == 1) | ~self.enable):
                    m.d.comb += next_word.eq(ControlWord.const(idle_word(self.table[CONV0]["addr"])))
                m.d.sync += restart.eq(Mux(restart == 0, 0, restart - 1))
            m.d.sync += word.eq(next_word)
