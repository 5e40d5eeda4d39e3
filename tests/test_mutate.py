"""The mutation run's input contract (kfpga/verify/mutate.py): a one-channel core's channel field is
held at 0 in the equivalence checks, and nothing else is."""

import re
from types import SimpleNamespace

import pytest
from amaranth import Elaboratable, Module, Signal
from amaranth.back import rtlil

from kfpga.core.config import FilterConfig
from kfpga.hw.cores import make_core
from kfpga.verify import mutate
from kfpga.verify.formal import warm, yosys


@pytest.fixture(scope="module", autouse=True)
def _warm():
    warm()


@pytest.mark.parametrize("channels", [1, 2])
def test_the_tied_bits_are_the_channel_field_of_a_one_channel_core(channels):
    """With one channel the tied bits are the payload bits that carry no sample (the channel
    field); with two channels, where the field carries both numbers, none is tied."""
    cfg = FilterConfig()
    core = make_core(cfg, "steady", channels=channels)
    tied = mutate.channel_bits_tied(core)
    if channels == 2:
        assert tied is None
        return
    width = core.i.payload.shape().size
    samples = set(mutate.sample_bits(core)["i__payload"])
    assert set(tied) == {"i__payload"}
    assert tied["i__payload"], "a one-channel core has a channel field"
    assert samples.isdisjoint(tied["i__payload"])
    assert samples | set(tied["i__payload"]) == set(range(width)), "every payload bit is a sample bit or tied"


class _Xor(Elaboratable):
    """o = the XOR of the input bits in ``taps``: two of them differ only where a tap differs."""

    def __init__(self, taps):
        self.taps = taps
        self.inp = Signal(4, name="inp")
        self.o = Signal(name="o")

    def elaborate(self, platform):
        m = Module()
        acc = 0
        for k in self.taps:
            acc = acc ^ self.inp[k]
        m.d.sync += self.o.eq(acc)
        return m


def _equivalent(tmp_path, tied_bits):
    """The mutation run's equiv_induct check of gold (inp[1] ^ inp[2]) against gate (the same
    ^ inp[0]), with the bits ``tied_bits`` of ``inp`` held at 0 in both, as the run holds a
    one-channel core's channel field."""
    for name, taps in (("gold", [1, 2]), ("gate", [0, 1, 2])):
        design = _Xor(taps)
        (tmp_path / "design.il").write_text(rtlil.convert(design, name=name, ports=[design.inp, design.o]))
        ok, log = yosys(f"read_rtlil design.il\nproc\nwrite_rtlil {name}.il\n", tmp_path)
        assert ok, log
    block = SimpleNamespace(tied={"inp": tied_bits} if tied_bits is not None else None)
    return mutate._matched_equivalence(block, tmp_path) is not None


@pytest.mark.parametrize(("tied_bits", "expected"), [(None, False), ([3], False), ([0], True), ([0, 3], True)])
def test_a_change_that_only_a_tied_bit_shows_is_equivalent_and_no_other(tmp_path, tied_bits, expected):
    """The extra tap on bit 0 is invisible exactly when bit 0 is held at 0; holding another bit
    proves nothing."""
    assert _equivalent(tmp_path, tied_bits) is expected


def _register_cell(il_text, wire):
    """The name of the ``$dff`` cell whose Q is ``wire`` in Amaranth's RTLIL."""
    match = re.search(rf"^\s*cell \$dff (\S+)\n(?:\s*(?:parameter|connect) .*\n)*?\s*connect \\Q \\{wire}\n", il_text, re.M)
    assert match is not None, f"no register {wire}"
    return match.group(1)


@pytest.mark.long
def test_a_change_only_a_channel_number_shows_is_equivalent_in_a_one_channel_core(tmp_path):
    """The steady core's input register, bit 15 inverted when its bit 0 is set: bit 0 is the
    channel field, always 0 in a one-channel core, so equiv_induct proves it equivalent with the
    field held at 0 (the mutation run's survivor #11 before the names-kept try); the same
    change controlled by bit 1, a sample bit, is no such change."""
    block = next(b for b in mutate.blocks() if b.name == "steady core")
    assert block.tied == {"i__payload": [0]}
    (tmp_path / "design.il").write_text(rtlil.convert(block.make(), name=block.toplevel))
    cell = _register_cell((tmp_path / "design.il").read_text(), "s0")
    assert mutate._extract(block, "", tmp_path, "gold")
    proven = {}
    for ctrl in (0, 1):
        line = f"mutate -mode cnot1 -module {block.target} -cell {cell} -port Q -portbit 15 -ctrlbit {ctrl}"
        assert mutate._extract(block, line, tmp_path, "gate")
        proven[ctrl] = mutate._matched_equivalence(block, tmp_path)
    assert proven[0] == "; constants folded, channel field at 0: a one-channel core's input contract"
    assert proven[1] is None
