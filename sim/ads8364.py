"""Behavioural model of the TI ADS8364 with timing checks.

# Ref: Texas Instruments SBAS219C (ADS8364), Timing and control; Explanation of clock, reset
#      and EOC; Getting data (Figures 7, 9). Timing figures: hw/ads8364_timing.py (TIMING).

The model is simulator-agnostic: a wrapper (``sim/bench.py`` for cocotb, ``tests/helpers/adc_harness.py``
for the Amaranth unit tests) reports the pin levels with :meth:`ADS8364.pins` whenever they may
have changed, with the time in ns, and applies the output events the model returns
(``(time_ns, "eoc" | "data", value)``; ``data`` ``None`` means not driven).

Behaviour modelled:

* A falling HOLDA/HOLDB/HOLDC samples its channel pair from the analog source; edges in the
  same instant form one simultaneous conversion. The conversion counts 20 CLK rising edges
  after HOLD fell ("the HOLD signals start conversion on the next clock cycle"), then stores
  the codes in the output registers and pulls EOC low for half a CLK cycle (until the next
  falling CLK edge).
* CS and RD low drive the output register of channel A2..A0 (000..101) on D15..D0, valid
  ``tACC`` after the later of the two falling edges; rising RD releases the bus ``tDH`` later.
* RESET low clears the registers and aborts a conversion.

Timing checks (a violation raises :class:`TimingViolation` at once, which fails the test):
CLK period and high/low times, HOLD low and high widths, a HOLD during a conversion, RESET low
width and RESET high before the next HOLD, address setup before RD falls and stability while
RD is low, RD low width, and WR (the controller must never write).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from kfpga.hw.ads8364_timing import TIMING, figure

__all__ = ["TimingViolation", "ADS8364", "Read"]


class Read(NamedTuple):
    """One read of the parallel port: when, which channel, the code, the conversion it came from,
    and the design's multiplexer select at that conversion's HOLD (0 without a multiplexer)."""

    time_ns: float
    channel: int
    code: int
    conversion: int
    sel: int = 0

#: Data hold after RD rises (ns): not given in the pages seen; sibling parts hold >= 5 ns.
DATA_HOLD_NS = 5.0


class TimingViolation(AssertionError):
    """The controller broke an ADS8364 timing or protocol rule."""


class ADS8364:
    """One ADS8364 on a board: six channels, fed by ``source``.

    Parameters
    ----------
    source:
        Object with ``next() -> sequence of 6 ints``: the six analog inputs at one sampling
        instant, as signed 16-bit codes (see ``sim/sources.py``).
    """

    def __init__(self, source):
        self.source = source
        self.registers = [0] * 6
        self._origin = [-1] * 6  # conversion index of each register's code
        self._held = [0] * 6
        self._pairs = set()  # pairs of the conversion in progress
        self._clocks = 0  # CLK rising edges counted by the conversion in progress
        self._start = None  # time HOLD fell for the conversion in progress
        self._sample = None
        self._drop = 0
        self.eoc = 1
        # last edge times (ns)
        self._clk = 0
        self._clk_rise = self._clk_fall = None
        self._hold = [1, 1, 1]
        self._hold_fall = [None] * 3
        self._hold_rise = [-math.inf] * 3
        self._reset = 1
        self._reset_fall = None
        self._reset_rise = -math.inf
        self._cs = 1
        self._rd = 1
        self._rd_fall = None
        self._rd_rise = -math.inf
        self._addr = 0
        self._addr_change = -math.inf
        self._clk_period = figure("tC1")
        self._levels = None  # the pin levels of the last report
        # statistics for tests
        self.conversions = 0
        self.eoc_pulses = 0
        self.eocs_dropped = 0
        self._stuck = False
        self.hold_low_ns = ([], [], [])  # each HOLD pulse's low time, per pair
        self.reads = []  # Read tuples, in order
        self.clk_edges = 0

    # -- test controls ----------------------------------------------------------------------
    def drop_eoc(self, count=1):
        """Complete the next ``count`` conversions without an EOC pulse (a broken board)."""
        self._drop += count

    def stick_eoc(self, stuck=True):
        """EOC stuck low from the next conversion's end on (a fault on its line: a reset does not
        clear it), until ``stick_eoc(False)``; then it rises at the next CLK fall."""
        self._stuck = stuck

    @property
    def converting(self):
        return bool(self._pairs)

    # -- checks -----------------------------------------------------------------------------
    @staticmethod
    def _fail(t, message):
        raise TimingViolation(f"ADS8364 at {t:.1f} ns: {message}")

    def _min(self, t, symbol, measured):
        limit = figure(symbol, self._clk_period)
        if measured < limit - 1e-6:
            spec = TIMING[symbol]
            self._fail(t, f"{spec.description} is {measured:.1f} ns, below the minimum {limit:g} ns ({symbol})")

    # -- pin events ---------------------------------------------------------------------------
    def adopt_levels(self, levels):
        """Take the pin levels found when the model is attached to a running design.

        ``levels`` as for :meth:`pins`. They are not edges: no width or setup is measured from
        them, only from the next edges.
        """
        self._levels = dict(levels)
        self._clk, self._reset = int(levels["clk"]), int(levels["reset"])
        self._hold = [int(levels[f"hold_{p}"]) for p in "abc"]
        self._cs, self._rd, self._addr = int(levels["cs"]), int(levels["rd"]), int(levels["addr"])
        if not levels["wr"]:
            self._fail(0.0, "WR is low: the controller must not write to the ADC")
        if not (self._cs or self._rd):
            self._fail(0.0, "attached in the middle of a read")

    #: The pins a controller drives, in the order :meth:`pins` applies changes of one instant.
    PINS = ("clk", "hold_a", "hold_b", "hold_c", "reset", "wr", "cs", "addr", "rd")

    def edge(self, t, pin, value):
        """Pin ``pin`` (one of :data:`PINS`) took ``value`` at time ``t`` (ns); returns the events."""
        if pin == "clk":
            return self.clk_edge(t, value)
        if pin.startswith("hold_"):
            return self.hold_edge(t, "abc".index(pin[-1]), value)
        return getattr(self, {"reset": "reset_edge", "wr": "wr_edge", "cs": "cs_edge", "addr": "addr_change",
                              "rd": "rd_edge"}[pin])(t, value)

    def pins(self, t, levels):
        """Report the levels of all pins at time ``t`` (ns); every change since the last report is
        an edge, through :meth:`edge`.

        ``levels``: ``{pin: level}`` for every pin of :data:`PINS`. Changes in one report happen
        in one instant and are applied in the order the checks need: a rising RD ends its read
        before an address change is looked at, CS before the address, RD falling last (it starts
        a read with the address as it is now). The first report, with no :meth:`adopt_levels`
        before it, counts every level as an edge. Returns the model's output events.
        """
        old, self._levels = self._levels, dict(levels)
        events = []
        if old is not None and levels["rd"] == 1 and old["rd"] == 0:
            events += self.edge(t, "rd", 1)
        for pin in self.PINS:
            if old is None or levels[pin] != old[pin]:
                events += self.edge(t, pin, levels[pin])
        return events

    def clk_edge(self, t, level):
        self.clk_edges += 1
        events = []
        if level and not self._clk:
            if self._clk_rise is not None:
                self._min(t, "tC1", t - self._clk_rise)
                self._clk_period = t - self._clk_rise
            if self._clk_fall is not None:
                self._min_width(t, "CLK low time", t - self._clk_fall)
            self._clk_rise = t
            if self._pairs and t > self._start:
                self._clocks += 1
                if self._clocks == int(TIMING["tCONV"].value):
                    events += self._complete(t)
        elif not level and self._clk:
            if self._clk_rise is not None:
                self._min_width(t, "CLK high time", t - self._clk_rise)
            self._clk_fall = t
            if self.eoc == 0 and not self._stuck:
                self.eoc = 1  # EOC low for half a CLK cycle
                events.append((t, "eoc", 1))
        self._clk = level
        return events

    def _min_width(self, t, what, measured):
        limit = figure("tW1")
        if measured < limit - 1e-6:
            self._fail(t, f"{what} is {measured:.1f} ns, below the minimum {limit:g} ns (tW1)")

    def _complete(self, t):
        for pair in self._pairs:
            for ch in (2 * pair, 2 * pair + 1):
                self.registers[ch] = self._held[ch]
                self._origin[ch] = self.conversions - 1
        self._pairs = set()
        self._start = None
        if self._drop:
            self._drop -= 1
            self.eocs_dropped += 1
            return []
        if self.eoc == 0:  # stuck low: no new edge
            return []
        self.eoc = 0
        self.eoc_pulses += 1
        return [(t, "eoc", 0)]

    def hold_edge(self, t, pair, level):
        if level == self._hold[pair]:
            return []
        self._hold[pair] = level
        if level:
            if self._hold_fall[pair] is not None:
                self._min(t, "tHOLDL", t - self._hold_fall[pair])
                self.hold_low_ns[pair].append(t - self._hold_fall[pair])
            self._hold_rise[pair] = t
            return []
        self._min(t, "tHOLDH", t - self._hold_rise[pair])
        self._min(t, "tD2", t - self._reset_rise)
        if not self._reset:
            self._fail(t, "HOLD fell while RESET is low")
        self._hold_fall[pair] = t
        if self._pairs and t != self._start:
            self._fail(t, f"HOLD{'ABC'[pair]} fell during a conversion (started at {self._start:.1f} ns)")
        if not self._pairs:
            self._start = t
            self._clocks = 0
            self._sample = [int(v) for v in self.source.next()]
            self.conversions += 1
        if pair in self._pairs:
            return []
        self._pairs.add(pair)
        for ch in (2 * pair, 2 * pair + 1):
            self._held[ch] = self._sample[ch]
        return []

    def reset_edge(self, t, level):
        if level == self._reset:
            return []
        self._reset = level
        if level:
            if self._reset_fall is not None:
                self._min(t, "tW4", t - self._reset_fall)
            self._reset_rise = t
            return []
        self._reset_fall = t
        self.registers = [0] * 6
        self._origin = [-1] * 6
        self._pairs = set()
        self._start = None
        events = []
        if self.eoc == 0 and not self._stuck:
            self.eoc = 1
            events.append((t, "eoc", 1))
        return events

    def addr_change(self, t, value):
        if value == self._addr:
            return []
        if not self._rd and not self._cs:
            self._fail(t, f"A2..A0 changed from {self._addr} to {value} while RD is low")
        if t == self._rd_rise:
            self._fail(t, f"A2..A0 changed from {self._addr} to {value} in the same instant RD rose")
        self._addr = value
        self._addr_change = t
        return []

    def cs_edge(self, t, level):
        if level == self._cs:
            return []
        self._cs = level
        return self._read_port(t)

    def rd_edge(self, t, level):
        if level == self._rd:
            return []
        self._rd = level
        if level:
            if self._rd_fall is not None:
                self._min(t, "tRDL", t - self._rd_fall)
            self._rd_rise = t
        else:
            self._rd_fall = t
        return self._read_port(t)

    def wr_edge(self, t, level):
        if not level:
            self._fail(t, "WR went low: the controller must not write to the ADC")
        return []

    def _read_port(self, t):
        if self._cs or self._rd:
            return [(t + DATA_HOLD_NS, "data", None)]
        # both low: a read of the addressed channel
        self._min(t, "tD9", t - self._addr_change)
        if self._addr > 5:
            self._fail(t, f"address {self._addr:03b} (cycle/FIFO mode) is not used by this controller")
        code = self.registers[self._addr]
        self.reads.append(Read(t, self._addr, code, self._origin[self._addr]))
        return [(t, "data", None), (t + figure("tACC"), "data", code)]
