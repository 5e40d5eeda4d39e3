# amaranth: UnusedElaboratable=no
"""The timing estimate on small designs whose longest path is known by hand.

Each design has registers at both ends of one kind of path; the expected delay is the sum of
the delay model's figures (hw/timing.py) along it, written out here.
"""

import pytest
from amaranth import Elaboratable, Module, Signal, signed
from amaranth.back import verilog

from kfpga.hw.resources import estimate
from kfpga.hw.timing import DELAYS, DERATE_C8, delay


def d(symbol):
    return delay(symbol)


class Registered(Elaboratable):
    """Registers in, a combinational function, a register out."""

    def __init__(self, widths, out_width, function, signed_inputs=False):
        shape = signed if signed_inputs else (lambda w: w)
        self.ins = [Signal(shape(w), name=f"in{k}") for k, w in enumerate(widths)]
        self.out = Signal(out_width, name="out")
        self.function = function

    def elaborate(self, platform):
        m = Module()
        regs = [Signal.like(i, name=f"r{k}") for k, i in enumerate(self.ins)]
        m.d.sync += [r.eq(i) for r, i in zip(regs, self.ins, strict=True)]
        m.d.sync += self.out.eq(self.function(*regs))
        return m


def worst(design, tmp_path):
    path = tmp_path / "design.v"
    path.write_text(verilog.convert(design, name="design", ports=[*design.ins, design.out], emit_src=False))
    return estimate(path, "design")["timing"]


@pytest.mark.parametrize("n", [8, 16, 24, 33])
def test_ripple_adder(tmp_path, n):
    """An n-bit sum: the top bit waits for the carry from the bottom one, across LAB boundaries."""
    t = worst(Registered([n, n], n, lambda a, b: (a + b)[:n]), tmp_path)
    labs = sum(1 for j in range(1, n) if j % 16 == 0)
    expected = (d("t_co") + d("t_lut") + (n - 1) * d("t_carry") + labs * d("t_carry_lab") + d("t_carry_sum")
                + d("t_route") + d("t_su"))
    assert t["worst_path_ns"] == pytest.approx(expected, abs=1e-3)
    assert [s["cell"] for s in t["worst_path"]["steps"]] == ["register", "carry chain", "setup"]


def test_register_multiplier_register(tmp_path):
    t = worst(Registered([18, 18], 36, lambda a, b: a * b, signed_inputs=True), tmp_path)
    expected = d("t_co") + 2 * d("t_route_mul") + d("t_mul18") + d("t_su")
    assert t["worst_path_ns"] == pytest.approx(expected, abs=1e-3)
    assert [s["cell"] for s in t["worst_path"]["steps"]] == ["register", "multiplier", "setup"]


def test_a_chain_of_luts(tmp_path):
    """The XOR of 64 bits: three levels of LUT4s (64 -> 16 -> 4 -> 1)."""
    t = worst(Registered([64], 1, lambda a: a.xor()), tmp_path)
    expected = d("t_co") + 3 * (d("t_lut") + d("t_route")) + d("t_su")
    assert t["worst_path_ns"] == pytest.approx(expected, abs=1e-3)
    assert [s["cell"] for s in t["worst_path"]["steps"]] == ["register", "LUT", "LUT", "LUT", "setup"]


def test_the_table_states_its_sources():
    assert DERATE_C8 > 1
    for figure in DELAYS.values():
        assert figure.value > 0 and figure.source and figure.status in ("source", "assumed")
