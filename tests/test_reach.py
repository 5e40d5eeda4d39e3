"""The explicit-state equivalence check of data-independent mutants (kfpga/verify/reach.py): its netlist
evaluation against the bit-accurate model, and its verdicts on mutants whose fate is known."""

import json

import numpy as np
import pytest
from amaranth import Module, Mux, Signal, signed
from amaranth.back import rtlil
from amaranth.lib import stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.kalman2 import FullCore
from kfpga.verify import reach
from kfpga.verify.formal import warm, yosys


@pytest.fixture(scope="module", autouse=True)
def _warm():
    warm()


def _pair(tmp_path, design, mutation=None):
    """gold.il and gate.il (gold with ``mutation``, a Yosys ``mutate`` command on module gate),
    flattened as the mutation flow does, and their netlist JSON."""
    (tmp_path / "design.il").write_text(rtlil.convert(design, name="top"))
    ok, log = yosys("read_rtlil design.il\nhierarchy -top top\nproc -norom\nflatten\nrename top gold\n"
                    "write_rtlil gold.il\nrename gold gate\n" + (f"{mutation}\n" if mutation else "")
                    + "write_rtlil gate.il\n", tmp_path)
    assert ok, log
    return reach.netlist_json("gold.il", "gate.il", tmp_path)


def test_the_evaluation_steps_the_covariance_as_the_model_does(tmp_path):
    """The time-varying core's covariance registers, stepped by the compiled netlist (sums,
    products, the restoring dividers, saturation), equal the bit-accurate model's after each of
    30 updates."""
    config = FilterConfig()
    core = FullCore(config)
    program = reach.compile_pair(_pair(tmp_path, core), {"i__payload": list(range(1, 17))})
    go = program.inputs(i__valid=1, o__ready=1)
    model = FixedModel(config, variant="full")
    points = dict(config.spec.model.variants["full"].state_for(config.params))
    state = program.init
    for k in range(1, 31):
        for _ in range(core.cycles_per_update):
            state = program.step(state, go)
        want = model.run(np.zeros(k, dtype=np.int64)).state
        for name in ("p11", "p12", "p21", "p22"):
            width = config.formats[points[name]].width
            raw = program.read(state, "gold", f"{name}_0")
            got = raw - (1 << width) if raw >> (width - 1) else raw
            assert got == int(getattr(want, name)), f"{name} after {k} updates"


class Toy(wiring.Component):
    """``o = y + count``, where ``count`` counts the samples taken up to 5 and stays there."""

    i: In(stream.Signature(signed(8)))
    o: Out(stream.Signature(signed(10)))

    def elaborate(self, platform):
        m = Module()
        count = Signal(4)
        m.d.comb += self.i.ready.eq(~self.o.valid | self.o.ready)
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += [self.o.valid.eq(1), self.o.payload.eq(self.i.payload + count),
                         count.eq(Mux(count == 5, 5, count + 1))]
        return m


def _register_cell(pair_path, netname):
    module = json.loads((pair_path.parent / "pair.json").read_text())["modules"]["gold"]
    bits = module["netnames"][netname]["bits"]
    return next(name for name, cell in module["cells"].items()
                if cell["type"] == "$dff" and cell["connections"]["Q"] == bits)


@pytest.mark.parametrize(("mode", "bit", "verdict"), [
    ("const0", 3, "equivalent"),   # the count never reaches 8: bit 3 is always 0
    ("const1", 3, "not proven"),   # the count differs, and the sum carries it to o.payload
    ("const0", 2, "not proven"),   # 4 and 5 lose their bit 2
    ("inv", 0, "not proven"),
])
def test_verdicts_on_the_counter(tmp_path, mode, bit, verdict):
    cell = _register_cell(_pair(tmp_path, Toy()), "count")
    path = _pair(tmp_path, Toy(), f"mutate -mode {mode} -module gate -cell {cell} -port D -portbit {bit}")
    result = reach.check(path, {"i__payload": list(range(8))})
    assert (result.equivalent, result.different) == (verdict == "equivalent", False), result.why
    if verdict == "not proven":
        assert "may reach output o__payload through the data path" in result.why
    if verdict == "equivalent":
        # (count, o.valid), the mutant's the same: (0, 0) and (1..5, either); the payload is data
        assert result.states == 1 + 5 * 2


def test_a_mutant_of_the_data_path_is_left_to_the_other_checks(tmp_path):
    cell = _register_cell(_pair(tmp_path, Toy()), "o__payload")
    path = _pair(tmp_path, Toy(), f"mutate -mode const0 -module gate -cell {cell} -port D -portbit 0")
    result = reach.check(path, {"i__payload": list(range(8))})
    assert not result.equivalent and not result.different
    assert "may reach output o__payload through the data path" in result.why


def test_the_unmutated_design_is_equivalent_to_itself(tmp_path):
    result = reach.check(_pair(tmp_path, Toy()), {"i__payload": list(range(8))})
    assert result.equivalent, result.why


class Scratch(wiring.Component):
    """A register file of four words: each sample is written to word 1, then word 1 is read back
    and ``o = word 1 + word 2`` (word 2 a constant); ``sel`` chooses word 3 instead of word 2, a
    multiplexer ``o`` does not use unless ``sel`` is set, which it never is."""

    i: In(stream.Signature(signed(8)))
    o: Out(stream.Signature(signed(10)))

    def elaborate(self, platform):
        m = Module()
        mem = Memory(shape=signed(8), depth=4, init=[0, 0, 5, 9])
        m.submodules.mem = mem
        wr, rd1, rd2 = mem.write_port(), mem.read_port(), mem.read_port()
        phase = Signal(2)
        sel = Signal()  # never set
        m.d.comb += [wr.addr.eq(1), wr.data.eq(self.i.payload), rd1.addr.eq(1), rd2.addr.eq(Mux(sel, 3, 2)),
                     self.i.ready.eq(phase == 0)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        with m.Switch(phase):
            with m.Case(0):
                with m.If(self.i.valid):
                    m.d.comb += wr.en.eq(1)
                    m.d.sync += phase.eq(1)
            with m.Case(1):  # the read address was set a cycle ago: the word is in the read register now
                m.d.sync += phase.eq(2)
            with m.Case(2):
                with m.If(~self.o.valid | self.o.ready):
                    m.d.sync += [self.o.valid.eq(1), self.o.payload.eq(rd1.data + rd2.data), phase.eq(0)]
        return m




@pytest.mark.parametrize(("word", "verdict"), [
    (0, "equivalent"),   # never read
    (1, "equivalent"),   # read only after each sample has been written to it
    (2, "not proven"),   # the constant: o carries it
    (3, "equivalent"),   # behind a multiplexer whose select is never set
])
def test_a_register_file_word_s_initial_contents(tmp_path, word, verdict):
    """A change of one bit of a memory's initial contents (what Yosys's mutate does to a $meminit
    cell) is followed word by word through the mapped memory: only a word that is read before it
    is written, into something an output shows, can be seen."""
    (tmp_path / "design.il").write_text(rtlil.convert(Scratch(), name="top"))
    ok, log = yosys("read_rtlil design.il\nhierarchy -top top\ntee -o meminit.txt select -list t:$meminit_v2\n", tmp_path)
    assert ok, log
    cell = (tmp_path / "meminit.txt").read_text().split()[-1].split("/")[-1]
    path = _pair(tmp_path, Scratch(), f"mutate -mode inv -module gate -cell {cell} -port DATA -portbit {8 * word + 1}")
    result = reach.check(path, {"i__payload": list(range(8))})
    assert (result.equivalent, result.different) == (verdict == "equivalent", False), result.why
    if verdict == "not proven":
        assert "o__payload" in result.why
