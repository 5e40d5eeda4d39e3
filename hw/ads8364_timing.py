"""ADS8364 timing facts used by the controller, its behavioural model and the timing constraints.

# Ref: Texas Instruments SBAS219C, "ADS8364: 250kSPS, 16-bit, 6-channel simultaneous sampling
#      ADC", sections "Timing and control", "Explanation of clock, reset, FD and EOC pins",
#      "Getting data" (Figure 7, Figure 9).
# Ref: [Zhong], section 4.2 (EOC low for half a clock cycle; HOLD >= 20 ns;
#      22-state controller; read only after the conversion, address stable before RD).

Every timing figure lives in :data:`TIMING`, with its source and whether the source text was
seen (``confirmed``) or the value is taken from a sibling part or chosen conservatively
(``assumed``). Change a figure here and the controller check (``sim/ads8364.py``) and the .sdc
follow.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Timing", "TIMING", "CHANNELS", "ADDRESS_CYCLE_MODE", "ADDRESS_FIFO_MODE", "CONVERSION_PERIODS", "hold_pair",
           "figure", "max_rate_hz", "check_rate"]

#: Channel names in address order: A2..A0 = 000..101 select them directly (SBAS219C, Getting data).
CHANNELS = ("A0", "A1", "B0", "B1", "C0", "C1")
ADDRESS_CYCLE_MODE = 0b110
ADDRESS_FIFO_MODE = 0b111


def hold_pair(channel):
    """0, 1 or 2: which of HOLDA/HOLDB/HOLDC converts ``channel`` (pairs A0/A1, B0/B1, C0/C1)."""
    return channel // 2


@dataclass(frozen=True)
class Timing:
    """One timing figure."""

    symbol: str
    description: str
    kind: str  # "min", "max" or "typ"
    value: float
    unit: str  # "ns" or "clk" (ADC CLK periods)
    source: str
    status: str  # "confirmed" or "assumed"


TIMING = {
    t.symbol: t
    for t in (
        Timing("tC1", "CLK period", "min", 200.0, "ns",
               "SBAS219C, Explanation of clock: minimum clock cycle 200 ns (5 MHz max)", "confirmed"),
        Timing("tW1", "CLK high or low time", "min", 60.0, "ns",
               "SBAS219C, Explanation of clock: CLK HIGH or LOW for at least 60 ns", "confirmed"),
        Timing("tCONV", "acquisition + conversion", "typ", 20.0, "clk",
               "SBAS219C, Timing and control: acquisition and conversion take 20 clock cycles", "confirmed"),
        Timing("tHOLDL", "HOLDx low width", "min", 20.0, "ns",
               "[Zhong] 4.2.1 and the ADS8364 datasheet: HOLDx low for at least 20 ns starts a conversion", "confirmed"),
        Timing("tHOLDH", "HOLDx high width between conversions", "min", 15.0, "ns",
               "sibling ADS7864 (SBAS141A, t2 = 15 ns); not seen for the ADS8364", "assumed"),
        Timing("tEOC", "EOC low width", "typ", 0.5, "clk",
               "[Zhong] 4.2.1 and the ADS8364 datasheet: EOC low for half a clock cycle", "confirmed"),
        Timing("tW4", "RESET low width", "min", 20.0, "ns",
               "SBAS219C, Explanation of reset, Figure 7", "confirmed"),
        Timing("tD2", "RESET high before the next HOLD falling edge", "min", 20.0, "ns",
               "SBAS219C, Explanation of reset, Figure 7", "confirmed"),
        Timing("tD9", "A2..A0 setup before RD falls", "min", 10.0, "ns",
               "SBAS219C, Getting data, Figure 9; the address must not change while RD is low", "confirmed"),
        Timing("tRDL", "RD low width", "min", 40.0, "ns",
               "not seen for the ADS8364; the controller holds RD low a whole CLK period (200 ns)", "assumed"),
        Timing("tACC", "RD falling to data valid", "max", 40.0, "ns",
               "not seen for the ADS8364; the controller samples the bus 200 ns after RD falls", "assumed"),
        Timing("tCSRD", "CS low before RD falls", "min", 0.0, "ns",
               "not seen for the ADS8364 (0 ns on sibling parts); the controller gives a CLK period", "assumed"),
    )
}

def figure(symbol, clk_period_ns=200.0):
    """A timing figure in nanoseconds (``clk`` figures scaled by ``clk_period_ns``)."""
    t = TIMING[symbol]
    return t.value * clk_period_ns if t.unit == "clk" else t.value


#: ADC clock periods of one free-running conversion and its reads: one channel 23 (20 to convert,
#: the EOC wait, two read states), all six 38 (six reads of two states); at 5 MHz a sample of one
#: channel every 230 system cycles (measured on the controller).
CONVERSION_PERIODS = {1: 23, 6: 38}


def max_rate_hz(board, channels, ratio=10, sensors=1):
    """The fastest the ADS8364 samples each of ``channels`` (1 or 6) at ``board``'s clock and the
    ADC clock ``ratio``, or each of ``sensors`` taking turns on one channel."""
    return board.clock_hz / (ratio * CONVERSION_PERIODS[6 if channels > 1 else 1] * sensors)


def check_rate(board, channels, ratio=10, sensors=1):
    """Refuse a ``board.sample_rate_hz`` the ADC cannot reach with ``channels`` (``ValueError``
    naming the limit)."""
    limit = max_rate_hz(board, channels, ratio, sensors)
    if board.sample_rate_hz is not None and board.actual_rate_hz(sensors) > limit * (1 + 1e-9):
        what = (f"{sensors} sensors taking turns on one channel" if sensors > 1 else
                "six channels" if channels > 1 else "one channel")
        raise ValueError(f"board.sample_rate_hz = {board.sample_rate_hz:g} is more than the ADS8364 converts "
                         f"{what} at a {board.clock_hz / ratio / 1e6:g} MHz ADC clock: at most {limit:.6g} Hz"
                         + (" each" if sensors > 1 else ""))
