# amaranth: UnusedElaboratable=no
"""The folded core (hw/folded.py) and its microcode (hw/microcode.py): any registered filter's
update, on random configs (every rounding rule, wrap and saturate, narrow formats that overflow,
narrow word budgets that give every cast point a format), gives the model's integers, in the
microcode's own cycle-by-cycle semantics and in the RTL."""

import dataclasses
import random

import numpy as np
import pytest
from contract.test_contract import long_tier, random_config, slow_update, stimulus

from kfpga.core import registry
from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.folded import FoldedCore, encode, word_layout
from kfpga.hw.microcode import DIGIT, compile_update, digits_for, execute, from_digits, to_digits
from kfpga.sim.amaranth_streams import measure_timing, run_stream
from kfpga.sim.scoreboard import Scoreboard

CASES = [pytest.param(spec.name, variant, id=f"{spec.name}-{variant}")
         for spec in registry.specs() for variant in spec.model.variants]
#: The folded core runs any update, but a variant the spec keeps model-only has no core.
HW_CASES = [pytest.param(spec.name, variant, id=f"{spec.name}-{variant}")
            for spec in registry.specs() for variant in spec.model.variants
            if spec.model.variants[variant].hardware(spec.params()) is None]


def _words(config, y, channels):
    names = config.inputs
    return [{"channel": int(c), **{n: int((y[n] if isinstance(y, dict) else y)[i]) for n in names}}
            for i, c in enumerate(channels)]


def _model_by_channel(config, variant, y, channels, count):
    model = FixedModel(config, variant=variant)
    out = {}
    for ch in range(count):
        idx = np.flatnonzero(channels == ch)
        out[ch] = (idx, model.run({k: v[idx] for k, v in y.items()} if isinstance(y, dict) else y[idx]))
    return out


@pytest.mark.parametrize(("value", "digits"), [(0, 1), (-1, 1), ((1 << 17) - 1, 1), (-(1 << 17), 1), (1 << 17, 2),
                                               (-(1 << 17) - 1, 2), ((1 << 34) - 1, 2), (-(1 << 34), 2), (1 << 34, 3),
                                               ((1 << 51) - 1, 3), (-(1 << 51), 3), (1 << 51, 4)])
def test_a_value_takes_the_digits_of_its_width(value, digits):
    """An 18-bit word holds 17 bits of a lower digit and the top digit's 18, signed."""
    assert digits_for(value, value) == digits
    held = to_digits(value, digits)
    assert from_digits(held) == value
    assert all(0 <= d < 1 << DIGIT for d in held[:-1]) and -(1 << DIGIT) <= held[-1] < 1 << DIGIT
    if digits > 1:  # one digit fewer does not hold it
        with pytest.raises(ValueError):
            to_digits(value, digits - 1)


@pytest.mark.parametrize(("name", "variant"), CASES)
def test_the_microcode_computes_the_models_integers(name, variant, seed):
    """The microcode run by its own semantics, cycle by cycle (:func:`kfpga.hw.microcode.execute`:
    a word read before its write lands, or a flag before it is captured, gives another value),
    three channels in random order, against the model run channel by channel: every output and
    flag."""
    rng = np.random.default_rng(seed)
    spec = registry.get(name)
    for _ in range(5):
        config = random_config(spec, variant, rng)
        y = stimulus(config, rng, 150)
        channels = rng.integers(0, 3, 150)
        outs, flags = execute(compile_update(config, variant, channels=3), _words(config, y, channels), channels.tolist())
        for idx, result in _model_by_channel(config, variant, y, channels, 3).values():
            for field in config.output_names:
                np.testing.assert_array_equal([outs[i][field] for i in idx], result.outputs[field], err_msg=field)
            np.testing.assert_array_equal([flags[i] for i in idx], result.overflow)


def test_a_schedule_that_breaks_the_pipeline_gives_other_integers(seed):
    """The executor keeps the pipeline's timing: with every wait dropped, steps read words before
    their writes land, and the estimates differ from the model's, or a digit no longer fits its
    word and the executor stops (so the test above can fail)."""
    config = FilterConfig(filter="kalman2")
    program = compile_update(config, "full")
    assert any(w["wait"] for w in program.words)
    hurried = dataclasses.replace(program, words=[{**w, "wait": 0} for w in program.words])
    y = stimulus(config, np.random.default_rng(seed), 40)
    words, channels = _words(config, y, np.zeros(40, int)), [0] * 40
    good, _ = execute(program, words, channels)
    expect = FixedModel(config, variant="full").run(y).outputs["x1"]
    assert [o["x1"] for o in good] == list(expect)
    try:
        bad, _ = execute(hurried, words, channels)
    except AssertionError as exc:
        assert "does not fit" in str(exc) or "passes its" in str(exc)
    else:
        assert [o["x1"] for o in bad] != list(expect)


@pytest.mark.parametrize(("name", "variant"), long_tier(HW_CASES, slow_update))
def test_the_core_runs_any_update_bit_exact(name, variant, seed):
    """Each filter's update on the folded core in Amaranth's simulator, random configs, two
    channels, random valid/ready: one estimate per sample, the model's integers."""
    rng = np.random.default_rng(seed)
    spec = registry.get(name)
    for trial in range(2):
        config = random_config(spec, variant, rng)
        core = FoldedCore(config, variant, channels=2)
        n = max(8, min(60, 60_000 // core.cycles_per_update))  # Amaranth's simulator: some 4,000 cycles a second
        y = stimulus(config, rng, n)
        channels = rng.integers(0, 2, n)
        words = _words(config, y, channels)
        out = run_stream(core, words, seed=seed + trial, p_idle=0.3, p_ready=0.5, extra_cycles=40)
        board = Scoreboard(config, variant)
        for word in words:
            board.add_input(word["channel"], {k: v for k, v in word.items() if k != "channel"})
        for o in out:
            board.add_output(**{f: int(getattr(o, f)) for f in ("channel", *config.output_names, "overflow")})
        assert board.assert_ok()["compared"] == n


def test_a_channel_past_the_last_reads_zeros_and_updates_nothing(seed):
    """Three channels on a two-bit channel field: channel 3 reads the spare block (all zeros, the
    model's state of zeros) and writes nothing, the others keep their own states."""
    config = FilterConfig(filter="kalman2")
    rng = np.random.default_rng(seed)
    y = stimulus(config, rng, 80)
    channels = rng.integers(0, 4, 80)
    out = run_stream(FoldedCore(config, "steady", channels=3), _words(config, y, channels), seed=seed, extra_cycles=20)
    got = np.array([int(o.x1) for o in out])
    expect = _model_by_channel(config, "steady", y, channels, 3)
    for idx, result in expect.values():
        np.testing.assert_array_equal(got[idx], result.outputs["x1"])
    model = FixedModel(config, variant="steady")
    zero = model.initial_state()
    zero = dataclasses.replace(zero, values=dict.fromkeys(zero.values, 0))
    stray = np.flatnonzero(channels == 3)
    assert stray.size
    for i in stray:
        assert got[i] == model.run(y[i:i + 1], zero).outputs["x1"][0]


def test_the_program_memory_holds_every_field(seed):
    """The encoded words give back each field of each step (the layout, LSB first)."""
    program = compile_update(FilterConfig(filter="roll"), "sqrt")
    layout = word_layout(program)
    for word, w in zip(encode(program), program.words, strict=True):
        offset = 0
        for name, bits in layout.items():
            assert (word >> offset) & ((1 << bits) - 1) == w[name], name
            offset += bits


def test_the_handshake_twin_is_a_working_core(seed):
    """The formal checks' twin of the roll core (a short copy of its program) takes and gives one
    word per sample, at its declared latency; its handshake is the core's own code."""
    config = FilterConfig(filter="roll")
    twin = FoldedCore(config, "sqrt", channels=2).formal_twin()
    assert len(twin.program.words) < 6 and twin.program.depth < 32
    words = [{"channel": i % 2, "z": int(v)} for i, v in enumerate(np.random.default_rng(seed).integers(-99, 99, 30))]
    assert len(run_stream(twin, words, seed=seed, p_idle=0.3, p_ready=0.5, extra_cycles=40)) == 30
    single = FoldedCore(config, "sqrt", channels=1).formal_twin()
    latency, accepted, produced = measure_timing(single, config)
    assert latency == single.latency
    assert accepted[2:5] == produced[:3] == [single.cycles_per_update] * 3


def test_a_sample_of_two_digits_is_written_before_its_word_is_taken(seed):
    """A 32-bit input (the 53H smoother's navigation data) takes two digits: the word is taken with
    the second, a cycle after the first was written, and the estimates are the model's."""
    from kfpga.model.tukey53h import Tukey53HParams

    config = FilterConfig(filter="tukey53h", params=Tukey53HParams(input_bits=32))
    dut = FoldedCore(config, "online")
    assert len(dut.program.sample_addrs) == 2 and dut.cycles_per_update == dut.latency + 1
    rng = np.random.default_rng(seed)
    y = rng.integers(-(1 << 31), 1 << 31, 60)
    out = run_stream(dut, [{"channel": 0, "y": int(v)} for v in y], seed=seed, p_idle=0.3, p_ready=0.6,
                     extra_cycles=20)
    expect = FixedModel(config, variant="online").run(y)
    for field in config.output_names:
        np.testing.assert_array_equal([int(getattr(o, field)) for o in out], expect.outputs[field], err_msg=field)


def _steps_run(code, regs):
    """The steps of ``code`` one after another (no pipeline): the accumulator, the flags and the
    register file as a dict of symbolic addresses (a constant word ``("k", v)`` holds ``v``)."""
    from kfpga.hw.microcode import CLEAR, HI, KEEP, LO, RADIX, SET

    acc, flags = 0, {}
    for mac in code:
        def read(addr):
            return addr[1] if addr[0] == "k" else regs[addr]
        a = mac.a2 if mac.pred is not None and flags.get(mac.pred - 1) else mac.a
        base = 0 if mac.acc == CLEAR else acc if mac.acc == KEEP else acc >> DIGIT
        acc = base + read(a) * read(mac.b)
        if mac.cap:
            bit = (acc >> 16) & 1 if mac.bit16 else int(acc < 0)
            flags[mac.flag] = bit if mac.cap == SET else flags.get(mac.flag, 0) | bit
        if mac.wr == LO:
            regs[mac.d] = acc & (RADIX - 1)
        elif mac.wr == HI:
            regs[mac.d] = acc
    return flags


def _lowered_value(value, n):
    from kfpga.hw.microcode import _Lowering, _Val

    low = _Lowering([], [], [], 1)
    v = _Val(tuple(("t", "v", j) for j in range(n)))
    return low, v, dict(zip(v.addrs, to_digits(value, n), strict=True))


EDGES = [(p, n) for n in (1, 2, 3, 4) for p in (1, 5, 16, 17, 18, 33, 34, 35, 51, 52) if p < 17 * n + 1]


@pytest.mark.parametrize(("p", "n"), EDGES)
def test_a_bound_check_from_the_top_digits_is_exact_at_its_edges(p, n, seed):
    """Saturation asks ``r >= 2**p`` and ``r < -2**p`` from the digits that hold bit ``p`` and
    above (``_Lowering.past_power``): at the bounds and one past them, and at random values of
    ``n`` digits, the flag is the comparison's, worked out here on Python integers."""
    rng = random.Random(seed)
    lo, hi = -(1 << (17 * n)), (1 << (17 * n)) - 1
    edges = [v for b in (1 << p, -(1 << p)) for v in (b - 2, b - 1, b, b + 1) if lo <= v <= hi]
    values = edges + [lo, hi, 0, -1] + [rng.randint(lo, hi) for _ in range(60)]
    for value in values:
        for high in (True, False):
            low, v, regs = _lowered_value(value, n)
            if not low.past_power(v, p, 1, high=high):
                assert p - 1 >= 17 * n  # only a value with no digit at bit p is left to the full check
                continue
            flags = _steps_run(low.code, regs)
            assert flags[1] == int(value >= 1 << p if high else value < -(1 << p)), (value, p, n, high)
            assert all(m.ovf for m in low.code if m.cap) and low.code[-1].cap


@pytest.mark.parametrize(("s", "n"), [(1, 1), (7, 2), (17, 2), (18, 2), (34, 3), (35, 3), (40, 4)])
def test_a_floor_from_digit_q_up_is_the_floor(s, n, seed):
    """A requantisation toward minus infinity reads no digit below the one that holds bit ``s``
    (``_Lowering.round_shift``): its result is ``value >> s`` at the edges of each digit and at
    random values."""
    from kfpga.core.fixed import Rounding

    rng = random.Random(seed)
    lo, hi = -(1 << (17 * n)), (1 << (17 * n)) - 1
    values = [lo, hi, 0, -1, 1 << s, (1 << s) - 1, -(1 << s), -(1 << s) - 1] + [rng.randint(lo, hi) for _ in range(60)]
    nr = digits_for(lo >> s, hi >> s)
    for value in values:
        low, v, regs = _lowered_value(value, n)
        out = low.round_shift(v, s, Rounding.FLOOR, nr)
        assert all(m.a[0] == "k" or m.a in v.addrs[(s - 1) // 17:] or m.a[1] != "v" for m in low.code)
        _steps_run(low.code, regs)
        assert from_digits([regs[a] for a in out.addrs]) == value >> s, (value, s, n)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_the_programmable_microcode_counts_each_points_overflows_as_the_model(variant, seed):
    """A programmable program's overflow counters (one register-file word a point) after a run of
    saturating samples, a fifth missing: each point's saturated writes, as the model's sites flag them."""
    import tomllib

    config = FilterConfig.from_dict(tomllib.loads('[filter]\nname = "kalman2"\n[formats.e]\nformat = "Q9.1"\n'),
                                    check_ranges=False)
    rng = np.random.default_rng(seed)
    y = np.clip(rng.normal(0, 9000, 300), -32768, 32767).astype(np.int64)
    missing = rng.random(300) < 0.2
    program = compile_update(config, variant, predict=True, programmable=True)
    regs = []
    outs, flags = execute(program, [{"y": int(c)} for c in y], [0] * len(y), missing=missing, registers=regs)
    model = FixedModel(config, variant=variant)
    res = model.run(y, missing=missing)
    for name in res.outputs:
        np.testing.assert_array_equal([o[name] for o in outs], res.outputs[name])
    assert flags == res.overflow.tolist()
    points = {**model.kernel(False).site_points, **model.kernel(False, predict=True).site_points}
    want = {}
    for site, hit in res.overflow_sites.items():
        want[points[site]] = want.get(points[site], 0) + int(np.count_nonzero(hit))
    got = {point: regs[program.counter_base + j] for j, point in enumerate(program.counters)}
    assert got == {point: want.get(point, 0) for point in got} and set(want) <= set(got)
    assert sum(got.values()) > 0
