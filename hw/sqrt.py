"""Restoring square root, one root bit per cycle, constant latency; bit-exact with ``ops.square_root``."""

from amaranth import Cat, Const, Module, Mux, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["SquareRoot"]


class SquareRoot(wiring.Component):
    """``floor(sqrt(radicand))`` of an unsigned radicand, MSB first (the digit-by-digit method).

    Each step brings down the next two radicand bits into the remainder and tries the root so
    far with a 1 appended: with root ``r`` the trial subtrahend is ``4 r + 1`` (``(2r + 1)^2 -
    (2r)^2``); if the remainder holds it, it is subtracted and the new root bit is 1. The
    remainder stays at most ``2 r``, so ``root_bits + 2`` bits hold it. ``o.valid`` rises
    ``root_bits + 1`` cycles after the cycle of the input handshake (one to load, one per root
    bit), so a schedule around it is fixed.

    Parameters
    ----------
    radicand_bits:
        Width of the unsigned radicand, even (``>= 2``); the root has half as many bits.

    Members
    -------
    i : In(stream.Signature(StructLayout({"radicand": unsigned(radicand_bits)})))
        Radicands.
    o : Out(stream.Signature(StructLayout({"root": unsigned(radicand_bits // 2)})))
        Roots, in request order.
    """

    def __init__(self, *, radicand_bits):
        if not isinstance(radicand_bits, int) or radicand_bits < 2 or radicand_bits % 2:
            raise ValueError(f"radicand_bits must be an even integer >= 2, not {radicand_bits!r}")
        self.radicand_bits = radicand_bits
        self.root_bits = radicand_bits // 2
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({"radicand": unsigned(radicand_bits)}))),
            "o": Out(stream.Signature(data.StructLayout({"root": unsigned(self.root_bits)}))),
        })

    @property
    def latency(self):
        """Cycles from the input handshake cycle to the first cycle with ``o.valid`` high."""
        return self.root_bits + 1

    def elaborate(self, platform):
        m = Module()
        n = self.root_bits
        low = Signal(2 * n, name="low")  # radicand bits still to be brought down, MSB first
        remainder = Signal(n + 2, name="remainder")
        root = Signal(n, name="root")
        count = Signal(range(n + 1), name="count")
        busy = Signal(name="busy")

        m.d.comb += self.i.ready.eq(~busy & (~self.o.valid | self.o.ready))
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += [low.eq(self.i.payload.radicand), remainder.eq(0), root.eq(0), count.eq(n), busy.eq(1)]

        trial = Cat(low[-2:], remainder)[:n + 2]        # 4 remainder + the next two bits
        subtrahend = Cat(Const(1, 1), Const(0, 1), root)[:n + 2]  # 4 root + 1
        fits = trial >= subtrahend
        new_root = Cat(fits, root[:n - 1])
        with m.If(busy):
            m.d.sync += [
                remainder.eq(Mux(fits, trial - subtrahend, trial)),
                low.eq(low << 2),
                root.eq(new_root),
                count.eq(count - 1),
            ]
            with m.If(count == 1):
                m.d.sync += [busy.eq(0), self.o.valid.eq(1), self.o.payload.root.eq(new_root)]
        return m
