# amaranth: UnusedElaboratable=no
"""The sequential core (hw/sequencer.py) and its program (kfpga/core/program.py): any registered
filter's update, on random configs (every rounding rule, wrap and saturate, narrow formats that
overflow), gives the model's integers, in the program's own semantics and in the RTL."""

import math

import numpy as np
import pytest
from amaranth.sim import Simulator
from contract.test_contract import random_config, stimulus

from kfpga.core import registry
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.core.program import build_program, execute
from kfpga.hw.sequencer import SequentialCore
from kfpga.hw.sqrt import SquareRoot
from kfpga.sim.amaranth_streams import run_stream, run_with_deadline
from kfpga.sim.scoreboard import Scoreboard

CASES = [pytest.param(spec.name, variant, id=f"{spec.name}-{variant}")
         for spec in registry.specs() for variant in spec.variants]
#: The sequential core runs any update, but a variant the spec keeps model-only has no core.
HW_CASES = [pytest.param(spec.name, variant, id=f"{spec.name}-{variant}")
            for spec in registry.specs() for variant in spec.variants
            if spec.variants[variant].hardware(spec.params()) is None]


def _words(config, y, channels):
    names = config.inputs
    return [{"channel": int(c), **{n: int((y[n] if isinstance(y, dict) else y)[i]) for n in names}}
            for i, c in enumerate(channels)]


@pytest.mark.parametrize(("name", "variant"), CASES)
def test_the_program_computes_the_models_integers(name, variant, seed):
    """The program run by its own semantics (:func:`kfpga.core.program.execute`), three channels in
    random order, against the model run channel by channel: every output, every flag."""
    rng = np.random.default_rng(seed)
    spec = registry.get(name)
    for _ in range(6):
        config = random_config(spec, variant, rng)
        y = stimulus(config, rng, 150)
        channels = rng.integers(0, 3, 150)
        outs, flags = execute(build_program(config, variant, channels=3), _words(config, y, channels), channels.tolist())
        model = FixedModel(config, variant=variant)
        for ch in range(3):
            idx = np.flatnonzero(channels == ch)
            result = model.run({k: v[idx] for k, v in y.items()} if isinstance(y, dict) else y[idx])
            for field in config.output_names:
                np.testing.assert_array_equal([outs[i][field] for i in idx], result.outputs[field], err_msg=field)
            np.testing.assert_array_equal([flags[i] for i in idx], result.overflow)


@pytest.mark.parametrize(("name", "variant"), HW_CASES)
def test_the_core_runs_any_update_bit_exact(name, variant, seed):
    """Each filter's update on the sequential core in Amaranth's simulator, random configs, two
    channels, random valid/ready: one estimate per sample, the model's integers."""
    rng = np.random.default_rng(seed)
    spec = registry.get(name)
    for trial in range(2):
        config = random_config(spec, variant, rng)
        n = 40 if name == "roll" else 80
        y = stimulus(config, rng, n)
        channels = rng.integers(0, 2, n)
        words = _words(config, y, channels)
        out = run_stream(SequentialCore(config, variant, channels=2), words, seed=seed + trial, p_idle=0.3,
                         p_ready=0.5, extra_cycles=40)
        board = Scoreboard(config, variant)
        for word in words:
            board.add_input(word["channel"], {k: v for k, v in word.items() if k != "channel"})
        for o in out:
            board.add_output(**{f: int(getattr(o, f)) for f in ("channel", *config.output_names, "overflow")})
        assert board.assert_ok()["compared"] == n


def test_roll_core_timing_is_its_programs():
    """The update's cycles: one to take the sample, one to store it, three per operation (read,
    execute, write), two more per requantisation, one more per product, a division's and a square
    root's latency and four more (shift, start, bound, sign), two per output copy, one to put the
    estimate out."""
    config = FilterConfig(filter="roll")
    core = SequentialCore(config, "sqrt", channels=1)
    p = core.program
    ops = {op: p.count(op) for op in ("mul", "div", "sqrt", "rq", "out")}
    simple = len(p.instructions) - sum(ops.values())
    expected = 1 + 1 + 3 * simple + 5 * ops["rq"] + 2 * ops["out"] + 4 * ops["mul"] \
        + ops["div"] * (7 + p.quotient_bits + 1) + ops["sqrt"] * (7 + p.radicand_bits // 2 + 1) + 1
    assert core.cycles_per_update == expected
    assert (ops["mul"], ops["div"], ops["sqrt"]) == (64, 16, 8)


@pytest.mark.parametrize("bits", [2, 8, 30, 54])
def test_square_root_unit(bits, seed):
    """``floor(sqrt(n))`` for the extremes and random radicands of every size, its latency the
    declared one."""
    rng = np.random.default_rng(seed)
    dut = SquareRoot(radicand_bits=bits)
    top = (1 << bits) - 1
    values = [v & top for v in [0, 1, 2, 3, 4, top, top - 1]]
    values += [int(rng.integers(0, 1 << int(rng.integers(1, bits + 1)))) & top for _ in range(60)]
    got, waits = [], []

    async def bench(ctx):
        ctx.set(dut.o.ready, 1)
        for v in values:
            ctx.set(dut.i.payload.radicand, v)
            ctx.set(dut.i.valid, 1)
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)
            cycles = 0
            while True:  # counted as the divider's test counts its latency
                cycles += 1
                *_, valid, root = await ctx.tick().sample(dut.o.valid, dut.o.payload.root)
                if valid:
                    break
            waits.append(cycles)
            got.append(root)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    run_with_deadline(sim, len(values) * (bits + 10) + 100)
    assert got == [math.isqrt(v) for v in values]
    assert set(waits) == {dut.latency}


def test_a_radicand_width_must_be_even():
    with pytest.raises(ValueError, match="^radicand_bits must be an even integer >= 2, not 7$"):
        SquareRoot(radicand_bits=7)


def test_the_handshake_twin_is_a_working_core(seed):
    """The formal checks' twin of the roll core (a short, narrow copy of its program) takes and
    gives one word per sample, at its declared latency; its handshake is the core's own code."""
    from kfpga.sim.amaranth_streams import measure_timing

    config = FilterConfig(filter="roll")
    twin = SequentialCore(config, "sqrt", channels=2).formal_twin()
    assert len(twin.program.instructions) < 10 and twin.program.width == 8
    words = [{"channel": i % 2, "z": int(v)} for i, v in enumerate(np.random.default_rng(seed).integers(-99, 99, 30))]
    assert len(run_stream(twin, words, seed=seed, p_idle=0.3, p_ready=0.5, extra_cycles=40)) == 30
    single = SequentialCore(config, "sqrt", channels=1).formal_twin()
    latency, accepted, produced = measure_timing(single, config)
    assert latency == single.latency
    assert accepted[2:5] == produced[:3] == [single.cycles_per_update] * 3
