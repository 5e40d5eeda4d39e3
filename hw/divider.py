"""Restoring divider, one quotient bit per cycle, constant latency; bit-exact with ``model.divide``."""

from amaranth import Cat, Module, Mux, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["Divider"]


class Divider(wiring.Component):
    """``floor(dividend / divisor)`` to ``quotient_bits`` bits, saturating.

    The quotient is computed MSB first by restoring division. When the quotient does not fit
    (``dividend >= divisor << quotient_bits``) or the divisor is zero, the result is the
    largest quotient, ``2**quotient_bits - 1``, with ``overflow`` set. ``o.valid`` rises
    ``quotient_bits + 1`` cycles after the cycle of the input handshake (one cycle to load, one
    per quotient bit), overflow or not, so a schedule around it is fixed.

    Parameters
    ----------
    dividend_bits, divisor_bits:
        Unsigned operand widths.
    quotient_bits:
        Quotient width (``>= 1``).

    Members
    -------
    i : In(stream.Signature(StructLayout({"dividend": unsigned(dividend_bits), "divisor": unsigned(divisor_bits)})))
        Division requests.
    o : Out(stream.Signature(StructLayout({"quotient": unsigned(quotient_bits), "overflow": 1})))
        Results, in request order.
    """

    def __init__(self, *, dividend_bits, divisor_bits, quotient_bits):
        for name, value in (("dividend_bits", dividend_bits), ("divisor_bits", divisor_bits),
                            ("quotient_bits", quotient_bits)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, not {value!r}")
        self.dividend_bits = dividend_bits
        self.divisor_bits = divisor_bits
        self.quotient_bits = quotient_bits
        self.request_layout = data.StructLayout({
            "dividend": unsigned(dividend_bits),
            "divisor": unsigned(divisor_bits),
        })
        self.result_layout = data.StructLayout({"quotient": unsigned(quotient_bits), "overflow": 1})
        super().__init__({
            "i": In(stream.Signature(self.request_layout)),
            "o": Out(stream.Signature(self.result_layout)),
        })
        # the registers, visible to tests and to the formal properties (kfpga/verify/properties.py)
        n = quotient_bits
        self.divisor = Signal(divisor_bits, name="divisor")
        self.remainder = Signal(divisor_bits, name="remainder")  # always < divisor while dividing
        self.low = Signal(n, name="low")  # dividend bits still to be brought down, MSB first
        self.quotient = Signal(n, name="quotient")
        self.overflowed = Signal(name="overflowed")
        self.count = Signal(range(n + 1), name="count")
        self.busy = Signal(name="busy")

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.quotient_bits + 1

    def elaborate(self, platform):
        m = Module()
        n = self.quotient_bits
        divisor, remainder, low, quotient = self.divisor, self.remainder, self.low, self.quotient
        overflow, count, busy = self.overflowed, self.count, self.busy

        m.d.comb += self.i.ready.eq(~busy & (~self.o.valid | self.o.ready))
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)

        dividend = self.i.payload.dividend
        request_divisor = self.i.payload.divisor
        with m.If(self.i.valid & self.i.ready):
            # the quotient fits iff dividend >> n < divisor; then so does the first remainder
            m.d.sync += [
                divisor.eq(request_divisor),
                remainder.eq(dividend >> n),
                low.eq(dividend[:n]),
                quotient.eq(0),
                overflow.eq((request_divisor == 0) | ((dividend >> n) >= request_divisor)),
                count.eq(n),
                busy.eq(1),
            ]

        # one restoring step: bring down the next dividend bit, subtract if it fits
        trial = Cat(low[n - 1], remainder)
        fits = trial >= divisor
        with m.If(busy):
            m.d.sync += [
                remainder.eq(Mux(fits, trial - divisor, trial)),
                low.eq(low << 1),
                quotient.eq(Cat(fits, quotient[:n - 1])),
                count.eq(count - 1),
            ]
            with m.If(count == 1):
                m.d.sync += [
                    busy.eq(0),
                    self.o.valid.eq(1),
                    self.o.payload.quotient.eq(Mux(overflow, (1 << n) - 1, Cat(fits, quotient[:n - 1]))),
                    self.o.payload.overflow.eq(overflow),
                ]
        return m
