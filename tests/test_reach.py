"""The explicit-state equivalence check of data-independent mutants (kfpga/reach.py): its netlist
evaluation against the bit-accurate model, and its verdicts on mutants whose fate is known."""

import json

import numpy as np
import pytest
from amaranth import Module, Mux, Signal, signed
from amaranth.back import rtlil
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from kfpga import reach
from kfpga.config import FilterConfig
from kfpga.fixedmodel import FixedModel
from kfpga.formal import warm, yosys
from kfpga.hw.kalman2 import FullKalman


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
    core = FullKalman(config)
    program = reach.compile_pair(_pair(tmp_path, core), {"i__payload": list(range(1, 17))})
    go = program.inputs(i__valid=1, o__ready=1)
    model = FixedModel(config, variant="full")
    points = dict(config.spec.variants["full"].state_for(config.params))
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
    module = json.loads(pair_path.read_text())["modules"]["gold"]
    bits = module["netnames"][netname]["bits"]
    return next(name for name, cell in module["cells"].items()
                if cell["type"] == "$dff" and cell["connections"]["Q"] == bits)


@pytest.mark.parametrize(("mode", "bit", "verdict"), [
    ("const0", 3, "equivalent"),   # the count never reaches 8: bit 3 is always 0
    ("const1", 3, "different"),
    ("const0", 2, "different"),    # 4 and 5 lose their bit 2
    ("inv", 0, "different"),
])
def test_verdicts_on_the_counter(tmp_path, mode, bit, verdict):
    cell = _register_cell(_pair(tmp_path, Toy()), "count")
    path = _pair(tmp_path, Toy(), f"mutate -mode {mode} -module gate -cell {cell} -port D -portbit {bit}")
    result = reach.check(path, {"i__payload": list(range(8))})
    assert (result.equivalent, result.different) == (verdict == "equivalent", verdict == "different"), result.why
    if verdict == "equivalent":
        # (count, o.valid), the mutant's the same: (0, 0) and (1..5, either); the payload is data
        assert result.states == 1 + 5 * 2


def test_a_mutant_of_the_data_path_is_left_to_the_other_checks(tmp_path):
    cell = _register_cell(_pair(tmp_path, Toy()), "o__payload")
    path = _pair(tmp_path, Toy(), f"mutate -mode const0 -module gate -cell {cell} -port D -portbit 0")
    result = reach.check(path, {"i__payload": list(range(8))})
    assert not result.equivalent and not result.different
    assert "depends on the data" in result.why


def test_the_unmutated_design_is_equivalent_to_itself(tmp_path):
    result = reach.check(_pair(tmp_path, Toy()), {"i__payload": list(range(8))})
    assert result.equivalent, result.why
