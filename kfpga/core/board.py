"""The board the design runs on: its oscillator, defined once for the RTL, benches and constraints."""

__all__ = ["SYSTEM_MHZ", "SYSTEM_PERIOD_NS"]

#: The 50 MHz oscillator of the paper's board (seeds/001, section 4.1): the one clock domain.
SYSTEM_MHZ = 50.0
#: Its period, 20 ns.
SYSTEM_PERIOD_NS = 1000.0 / SYSTEM_MHZ
