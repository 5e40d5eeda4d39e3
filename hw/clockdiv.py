"""Clock divider: a one-cycle enable strobe for the logic and a registered clock for the ADC pin."""

from amaranth import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

__all__ = ["ClockDivider"]


class ClockDivider(wiring.Component):
    """Divide the system clock by ``ratio`` (default 10: 50 MHz -> 5 MHz).

    No logic-generated clock clocks anything inside the FPGA: the internal logic runs on the
    system clock and advances on ``strobe`` (Intel and AMD both advise against ripple clocks).
    ``clk_out`` only leaves the chip, to the ADC's CLK pin, and comes straight from a flip-flop.

    ``clk_out`` is high for ``ratio // 2`` system cycles and low for the rest: exactly 50 % duty
    for even ratios; an odd ratio gives one more low cycle than high (e.g. 2 high, 3 low for 5).
    ``strobe`` is high in the last system cycle of each ``clk_out`` period, so logic that
    advances on it changes its registered outputs on the same system edge as ``clk_out`` rises.

    The divider ignores reset: it runs from power-up, so a reset of the logic never cuts a
    CLK period short at the ADC (whose CLK must stay >= 200 ns, high and low >= 60 ns).

    Parameters
    ----------
    ratio:
        System clock cycles per output period, ``>= 2``.

    Members
    -------
    strobe : Out(1)
        One-cycle clock enable, once every ``ratio`` cycles.
    clk_out : Out(1)
        Registered divided clock for an output pin.
    """

    strobe: Out(1)
    clk_out: Out(1, init=1)  # the counter starts at 0, in the high half

    def __init__(self, *, ratio=10):
        if not isinstance(ratio, int) or isinstance(ratio, bool) or ratio < 2:
            raise ValueError(f"ratio must be an integer >= 2, not {ratio!r}")
        self.ratio = ratio
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        count = Signal(range(self.ratio), reset_less=True)
        last = count == self.ratio - 1
        count_next = Signal.like(count)
        m.d.comb += [
            self.strobe.eq(last),
            count_next.eq(0),
        ]
        with m.If(~last):
            m.d.comb += count_next.eq(count + 1)
        clk_out = Signal(init=1, reset_less=True)
        m.d.sync += [
            count.eq(count_next),
            clk_out.eq(count_next < self.ratio // 2),
        ]
        m.d.comb += self.clk_out.eq(clk_out)
        return m
