# amaranth: UnusedElaboratable=no
"""The formal flow itself (kfpga/verify/formal.py): the quick proofs pass, and a planted bug fails.

``make formal`` runs every property (CI runs it after ``make test``); here the quick ones run,
so that a broken flow (a property proven vacuously, a solver not found) fails the test suite.
"""

import dataclasses

import pytest

from kfpga.hw.clockdiv import ClockDivider
from kfpga.verify import formal
from kfpga.verify.properties import ClockDividerProps, ControllerProps, DividerProps

pytestmark = pytest.mark.xdist_group("formal")


@pytest.fixture(scope="module")
def warmed():
    formal.warm()


def job(block, prop):
    return next(j for j in formal.jobs() if j.block == block and j.prop == prop)


@pytest.mark.parametrize(("block", "prop"), [
    ("clock divider /10", "strobe period"),
    ("clock divider /5", "ADC clock high and low"),
    ("divider 6/4->3", "quotient"),
    ("divider 6/4->3", "overflow"),
    ("controller C0", "RD under CS"),
])
def test_quick_properties_are_proven(warmed, tmp_path, block, prop):
    row = formal.run_job(job(block, prop), tmp_path)
    assert row["ok"] and row["result"] == "proven", row


def test_a_planted_bug_fails_its_proof(warmed, tmp_path):
    """A divider by 9 checked against the properties of a divider by 10: a counterexample."""

    def wrong(only):
        harness = ClockDividerProps(10, only=only)
        harness.dut._MustUse__silence = True  # replaced, never built
        harness.dut = ClockDivider(ratio=9)
        return harness

    bad = dataclasses.replace(job("clock divider /10", "strobe period"), make=wrong)
    row = formal.run_job(bad, tmp_path)
    assert not row["ok"] and row["result"] == "FAILED (counterexample)", row


def test_a_vacuous_property_fails(warmed, tmp_path):
    """With no request ever made, the divider's stream contract would hold vacuously: its cover
    (a result held, then taken) is not reached, and the job fails."""
    base = job("divider 6/4->3", "stream contract")
    row = formal.run_job(dataclasses.replace(base, make=_never_valid), tmp_path)
    assert not row["ok"] and "cover" in row["result"], row


def _never_valid(only):
    from amaranth.hdl import Assume

    harness = DividerProps(6, 4, 3, only=only)
    elaborate = harness.elaborate

    def assume_no_requests(platform):
        m = elaborate(platform)
        m.d.comb += Assume(~harness.ports[0])  # i_valid never high: nothing is ever divided
        return m

    harness.elaborate = assume_no_requests
    return harness


def test_unknown_property_names_are_refused():
    with pytest.raises(ValueError, match=r"^unknown properties \['speed'\]; known: recovery, "):
        ControllerProps(only=["speed"])


def test_the_command_refuses_bad_options(capsys):
    with pytest.raises(SystemExit) as exc:
        formal.main(["--only", "no such block"])
    assert exc.value.code == 2
    assert "no job matches --only 'no such block'" in capsys.readouterr().err


class _Buffer:
    """A one-word stream buffer, right (``i.ready = ~o.valid | o.ready``) or with the slip the
    source mutants found in a core (``~o.valid & o.ready``: it waits for ``o.ready`` even when empty)."""

    def __new__(cls, slip):
        from amaranth import Module
        from amaranth.lib import data, stream, wiring
        from amaranth.lib.wiring import In, Out

        word = data.StructLayout({"x": 8})

        class Buffer(wiring.Component):
            i: In(stream.Signature(word))
            o: Out(stream.Signature(word))

            def elaborate(self, platform):
                m = Module()
                free = (~self.o.valid & self.o.ready) if slip else (~self.o.valid | self.o.ready)
                m.d.comb += self.i.ready.eq(free)
                with m.If(self.o.valid & self.o.ready):
                    m.d.sync += self.o.valid.eq(0)
                with m.If(self.i.valid & self.i.ready):
                    m.d.sync += [self.o.valid.eq(1), self.o.payload.eq(self.i.payload)]
                return m

        return Buffer()


@pytest.mark.parametrize("slip", [False, True])
def test_free_when_idle_catches_a_core_that_waits_for_ready(warmed, tmp_path, slip):
    """The stream property "free when idle" (every core gets it in make formal) holds for a
    buffer that keeps the contract and fails for one that waits for o.ready when empty, the
    deadlock of a receiver that raises ready only after it sees valid."""
    from kfpga.verify.properties import StreamProps

    base = job("kalman2 steady core", "free when idle")
    planted = dataclasses.replace(base, make=lambda only: StreamProps(_Buffer(slip), 1, 3, only=only), depth=8,
                                  cover_depth=8)
    row = formal.run_job(planted, tmp_path)
    if slip:
        assert not row["ok"] and row["result"] == "FAILED (counterexample)", row
    else:
        assert row["ok"], row
