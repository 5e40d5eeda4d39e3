"""The board the design runs on: its oscillator, defined once for the RTL, benches and constraints,
and the rate a config asks of it (``[board]``). What the ADS8364 can convert at that rate is the
hardware's (``hw/ads8364_timing.py``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["SYSTEM_MHZ", "SYSTEM_PERIOD_NS", "WORST_PATH_GOAL_NS", "Board", "MAX_CHANNELS",
           "sensor_bits"]

#: The 50 MHz oscillator of the paper's board ([Zhong], section 4.1): the one clock domain.
SYSTEM_MHZ = 50.0
#: Its period, 20 ns.
SYSTEM_PERIOD_NS = 1000.0 / SYSTEM_MHZ

#: The timing goal of every core and of the whole design: 62.5 MHz on the -8 part, the 1.25 x
#: margin over the board's 50 MHz that ``--architecture auto`` asks of the estimate
#: (``hw/timing.py``; ``kfpga/flows/explore.py``).
WORST_PATH_GOAL_NS = round(1000.0 / (1.25 * SYSTEM_MHZ), 2)

#: The most sensors an analog multiplexer in front of one ADC channel feeds, one channel state of the
#: core each (``--channels``); a filter's core may hold more (the alpha-beta tracker's tracks).
MAX_CHANNELS = 256


def sensor_bits(sensors):
    """Bits of the multiplexer's select and of a sensor's number: enough for ``sensors``."""
    return max(1, (sensors - 1).bit_length())


@dataclass(frozen=True, kw_only=True)
class Board:
    """The rate a design runs at (a config's ``[board]`` table).

    Parameters
    ----------
    sample_rate_hz:
        Samples a second of every channel (every sensor, with a multiplexer in front of the ADC):
        the top starts a conversion every ``clock_hz / (sample_rate_hz * sensors)`` system cycles
        (the nearest whole number). ``None``: the ADC converts as fast as it can (one channel
        every 230 cycles at 50 MHz).
    clock_hz:
        The system clock (default: the board's 50 MHz oscillator).
    """

    sample_rate_hz: float | None = None
    clock_hz: float = SYSTEM_MHZ * 1e6

    def __post_init__(self):
        for name in ("sample_rate_hz", "clock_hz"):
            value = getattr(self, name)
            if value is None and name == "sample_rate_hz":
                continue
            if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"board.{name} must be a positive number of Hz, not {value!r}")
            object.__setattr__(self, name, float(value))

    def conversion_cycles(self, sensors=1):
        """System cycles between conversions (``None``: free running); ``sensors`` take turns on
        one ADC channel, each at the sample rate."""
        if self.sample_rate_hz is None:
            return None
        return max(1, round(self.clock_hz / (self.sample_rate_hz * sensors)))

    def actual_rate_hz(self, sensors=1):
        """The rate of each channel (each sensor) the whole number of conversion cycles gives."""
        cycles = self.conversion_cycles(sensors)
        return None if cycles is None else self.clock_hz / (cycles * sensors)
