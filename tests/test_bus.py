"""The programmable core: settings written on its bus mid-stream, samples with no measurement.

The cocotb bench (``sim/test_bus.py``) drives the Avalon-MM slave with cocotbext-avalon and the
AXI4-Lite one with cocotbext-axi, on the paper's filter and the README's tracker, both variants,
on Verilator and Icarus (half the combinations in ``make test``, the rest in the long tier:
:func:`_square`): two new Q/R phases written while the stream runs, a fifth of the
samples missing, every estimate the model's that switches config at the sample the core
reports (``COMMITTED``). The register values come from ``kfpga regs``'s flow
(:func:`kfpga.flows.regs.settings_for`), the model's switch from the configs themselves.
"""

import dataclasses
import tomllib
from pathlib import Path

import pytest

from kfpga.core.config import FilterConfig
from kfpga.flows.regs import bus_writes, new_config, program_for, settings_for
from kfpga.hw.regmap import identity, register_map
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.simulators import need

pytestmark = pytest.mark.cosim

ROOT = Path(__file__).resolve().parents[1]
TRACKER = ROOT / "examples" / "models" / "tracker.toml"

#: The filters of the check, and two new (Q, R) each: within the formats their default configs
#: get, as a core built for them takes.
#: The paper's filter with an innovation format too narrow for the stress signal: its saturations
#: (and those they cause downstream) fill the overflow counters.
NARROW = '[filter]\nname = "kalman2"\n[formats.e]\nformat = "Q9.1"\n'

CASES = {
    "kalman2": (lambda: FilterConfig(), [{"Q": 1.0, "R": 6.0}, {"Q": 3.0, "R": 3.0}]),
    "narrow": (lambda: FilterConfig.from_dict(tomllib.loads(NARROW), check_ranges=False),
               [{"Q": 1.0, "R": 6.0}, {"Q": 3.0, "R": 3.0}]),
    "tracker": (lambda: FilterConfig.from_toml(TRACKER),
                [{"Q": ((0.25,),), "R": ((36.0,),)}, {"Q": ((0.5,),), "R": ((16.0,),)}]),
}


def counters(config, variant, program):
    """``[[word index, point], ...]`` of the core's overflow counters."""
    return [[r.index, r.setting] for r in register_map(program, config, variant) if r.name.startswith("OVF_")]


def phases(config, variant, program, changes):
    out = []
    for change in changes:
        params = dataclasses.replace(config.params, **change)
        new = new_config(config, variant, params)
        writes = bus_writes(settings_for(config, variant, params, program=program), program, config, variant)
        out.append({"config_toml": new.to_toml(), "writes": [[index, value] for index, value, _ in writes],
                    "check_ranges": config.check_ranges})
    return out


def _square(cases):
    """``cases`` (tuples ending in the simulator) with half of them in the long tier (``make
    test-long``): ``make test`` keeps a Latin square, each case on both simulators and each bus on
    both across the variants; the long tier runs the other half, so CI runs every combination."""
    kept = {("steady", "avalon", "verilator"), ("steady", "axi4lite", "icarus"), ("full", "axi4lite", "verilator"),
            ("full", "avalon", "icarus"), ("steady", "icarus"), ("full", "verilator")}
    return [pytest.param(*c, id="-".join(c), marks=[] if c[1:] in kept else [pytest.mark.long]) for c in cases]


@pytest.mark.parametrize(("case", "variant", "bus", "simulator"),
                         _square([(c, v, b, s) for c in CASES for v in ("steady", "full") for b in ("avalon", "axi4lite")
                                  for s in SIMULATORS]))
def test_settings_written_mid_stream_are_bit_exact(case, variant, bus, simulator, seed):
    need(simulator)
    make, changes = CASES[case]
    config = make()
    program = program_for(config, variant, missing=True)
    samples = 300 if simulator == "verilator" else 150
    params = {"variant": variant, "seed": seed, "samples": samples, "bus": bus, "missing": 0.2,
              "config_toml": config.to_toml(), "phases": phases(config, variant, program, changes),
              "id": identity(config, variant), "p_idle": 0.2, "p_ready": 0.8,
              "counters": counters(config, variant, program), "check_ranges": case != "narrow"}
    built = build(simulator, "core", config=config, variant=variant, missing=True, bus=bus)
    result = run(built, "test_bus", testcase="settings_mid_stream", params=params)
    assert result["ok"] and result["mismatches"] == 0, result
    assert len(result["switches"]) == 2 and result["missing"] > 0, result


@pytest.mark.parametrize(("case", "variant", "simulator"),
                         _square([(c, v, s) for c in CASES for v in ("steady", "full") for s in SIMULATORS]))
def test_missing_samples_without_a_bus_are_bit_exact(case, variant, simulator, seed):
    """The folded core with the missing bit and no bus: a fifth of the samples missing, at random
    backpressure, every estimate the model's (which predicts only there)."""
    need(simulator)
    config = CASES[case][0]()
    samples = 400 if simulator == "verilator" else 150
    params = {"variant": variant, "seed": seed, "samples": samples, "missing": 0.2, "config_toml": config.to_toml(),
              "p_idle": 0.3, "p_ready": 0.7, "check_ranges": config.check_ranges}
    result = run(build(simulator, "core", config=config, variant=variant, missing=True), "test_bus",
                 testcase="settings_mid_stream", params=params)
    assert result["ok"] and result["mismatches"] == 0 and result["missing"] > 0, result


@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("case", "variant", "bus"), [("narrow", "full", "avalon"), ("tracker", "steady", "axi4lite")])
def test_a_soft_reset_starts_from_the_new_reset_values(case, variant, bus, simulator, seed):
    """New x0 and P0 committed, then CONTROL.RESET and CLEAR between two halves of a stream."""
    need(simulator)
    config = CASES[case][0]()
    program = program_for(config, variant, missing=True)
    change = ({"x0": (100.0, -2.0), "P0": ((20.0, 0.0), (0.0, 5.0))} if case == "narrow"
              else {"x0": (50.0, 1.0, 0.0), "R": ((36.0,),)})
    params = {"variant": variant, "seed": seed, "samples": 160 if simulator == "verilator" else 80, "bus": bus,
              "missing": 0.2, "config_toml": config.to_toml(), "phases": phases(config, variant, program, [change]),
              "p_idle": 0.2, "p_ready": 0.8, "counters": counters(config, variant, program),
              "check_ranges": case != "narrow"}
    result = run(build(simulator, "core", config=config, variant=variant, missing=True, bus=bus), "test_bus",
                 testcase="reset_and_clear", params=params)
    assert result["ok"], result
