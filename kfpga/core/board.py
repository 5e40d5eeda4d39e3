"""The board the design runs on: its oscillator, defined once for the RTL, benches and constraints."""

__all__ = ["SYSTEM_MHZ", "SYSTEM_PERIOD_NS", "WORST_PATH_GOAL_NS"]

#: The 50 MHz oscillator of the paper's board (seeds/001, section 4.1): the one clock domain.
SYSTEM_MHZ = 50.0
#: Its period, 20 ns.
SYSTEM_PERIOD_NS = 1000.0 / SYSTEM_MHZ

#: The timing goal of every core and of the whole design: 75 MHz on the -8 part, a 1.5x margin
#: at the board's 50 MHz (the estimate of ``hw/timing.py``).
WORST_PATH_GOAL_NS = round(1000.0 / 75.0, 2)
