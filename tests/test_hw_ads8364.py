# amaranth: UnusedElaboratable=no
"""The ADS8364 controller, cycle by cycle, against the ADC's behavioural model (Amaranth sim).

Every run also passes the model's timing checks (CLK, HOLD, RESET, address setup, RD).
"""

import numpy as np
import pytest

from kfpga.hw.ads8364 import ADS8364Controller
from kfpga.sim.sources import Source, scenario_source
from tests.helpers.adc_harness import ControllerTop, Harness, wait_outputs, wait_state

# The documented 16-bit control word layout (hw/ads8364.py), written out independently here.
BITS = {"hold_a": 0, "hold_b": 1, "hold_c": 2, "addr": 3, "cs": 6, "rd": 7, "wr": 8, "byte": 9,
        "add": 10, "reset": 11, "start": 12, "wait_eoc": 13, "latch": 14, "last": 15}


def word(**fields):
    levels = {"hold_a": 1, "hold_b": 1, "hold_c": 1, "addr": 0, "cs": 1, "rd": 1, "wr": 1, "byte": 0, "add": 0,
              "reset": 1, "start": 0, "wait_eoc": 0, "latch": 0, "last": 0, **fields}
    return sum(v << BITS[k] for k, v in levels.items())


def expected_table(channel):
    """The 22 states of the paper's controller reading ``channel`` (single-channel mode)."""
    hold = {0: "hold_a", 1: "hold_a", 2: "hold_b", 3: "hold_b", 4: "hold_c", 5: "hold_c"}[channel]
    table = {0: word(addr=channel, start=1, **{hold: 0})}
    for s in range(1, 19):
        table[s] = word(addr=channel)
    table[19] = word(addr=channel, wait_eoc=1)
    table[20] = word(addr=channel, cs=0)
    table[21] = word(addr=channel, cs=0, rd=0, latch=1, last=1)
    return table


def codes_source(seed, n=400):
    return scenario_source("sine", n, seed)


@pytest.mark.parametrize("channel", [0, 3, 5])
def test_control_words_cycle_by_cycle(channel, seed):
    """After reset: RESET pulse, one idle period, then the 22 states with their words, repeatedly."""
    top = ControllerTop(channel=channel)
    h = Harness(top, codes_source(seed))

    async def script(ctx, h):
        await wait_outputs(ctx, h, 4)

    h.run(script)
    table = expected_table(channel)
    states = [s for s, _ in h.periods]
    words = [w for _, w in h.periods]
    assert states[:2] == [0, 0]
    assert words[0] == word(addr=channel, reset=0)  # ADC RESET pulse, one CLK period
    assert words[1] == word(addr=channel)  # RESET high for a period before HOLD (tD2)
    body = h.periods[2:]
    for state, w in body:
        assert w == table[state], f"state {state}: word {w:016b}, expected {table[state]:016b}"
    # the order: 0..19, then 19 while waiting for EOC, then 20, 21, back to 0
    conv = [s for s, _ in body]
    start = conv.index(0)
    cycle = conv[start: start + conv[start + 1:].index(0) + 1]
    assert cycle[:20] == list(range(20))
    assert set(cycle[20:-2]) <= {19} and cycle[-2:] == [20, 21]
    assert len(set(states)) == 22  # all 22 states visited
    # one output per conversion, the addressed channel, the code the ADC drove
    assert h.outputs == [(channel, r.code) for r in h.adc.reads[: len(h.outputs)]]
    assert all(ch == channel for ch, _ in h.outputs)
    assert h.adc.conversions >= len(h.outputs)


def test_six_channel_mode(seed):
    top = ControllerTop(six_channel=True)
    h = Harness(top, codes_source(seed))

    async def script(ctx, h):
        await wait_outputs(ctx, h, 18)

    h.run(script)
    conv0 = [w for s, w in h.periods if s == 0 and (w >> BITS["start"]) & 1]
    assert conv0 and all(w == word(hold_a=0, hold_b=0, hold_c=0, start=1) for w in conv0)
    reads = [(s, w) for s, w in h.periods if s in (20, 21)]
    addrs = [(w >> BITS["addr"]) & 7 for s, w in reads if s == 21]
    assert addrs[:12] == [0, 1, 2, 3, 4, 5] * 2
    lasts = [(w >> BITS["last"]) & 1 for s, w in reads if s == 21]
    assert lasts[:6] == [0, 0, 0, 0, 0, 1]
    # every word is the held sample of its channel: one HOLD samples all six at once
    source = codes_source(seed)
    expected = source.expected(3)
    got = h.outputs[:18]
    assert [c for c, _ in got] == [0, 1, 2, 3, 4, 5] * 3
    for k in range(3):
        assert [v for _, v in got[6 * k: 6 * k + 6]] == list(expected[:, k])


def test_eoc_timeout_raises_flag_and_recovers(seed):
    top = ControllerTop(channel=1)
    source = codes_source(seed)
    h = Harness(top, source)

    async def script(ctx, h):
        await wait_outputs(ctx, h, 2)
        h.adc.drop_eoc(1)
        assert not ctx.get(top.ctrl.timeout)
        await wait_outputs(ctx, h, 6)

    h.run(script)
    assert h.adc.eocs_dropped == 1
    # the conversion without EOC yields no word; every other conversion yields exactly one
    assert h.adc.conversions == len(h.outputs) + 1 or h.adc.conversions == len(h.outputs) + 2
    assert h.outputs == [(1, r.code) for r in h.adc.reads[: len(h.outputs)]]
    # a RESET pulse follows the timeout, then conversions go on
    resets = [i for i, (_, w) in enumerate(h.periods) if not (w >> BITS["reset"]) & 1]
    assert len(resets) == 2  # power-on and recovery
    # it waited in CONV19 from period 19 after HOLD up to the timeout at period 40: 21 periods
    runs, run = [], 0
    for s, _ in h.periods:
        run = run + 1 if s == 19 else 0
        runs.append(run)
    assert max(runs) == 21


def test_timeout_flag_is_sticky_and_period_is_forty_clks(seed):
    top = ControllerTop(channel=0)
    h = Harness(top, codes_source(seed))

    async def script(ctx, h):
        await wait_outputs(ctx, h, 1)
        h.adc.drop_eoc(1)
        await wait_state(ctx, h, 1)  # the conversion that will lose its EOC starts
        while not ctx.get(top.ctrl.timeout):
            await ctx.tick()
        await wait_outputs(ctx, h, 3)
        assert ctx.get(top.ctrl.timeout)

    h.run(script)
    # from the HOLD period of the failed conversion to the RESET period: 40 CLK periods
    states = [s for s, _ in h.periods]
    words = [w for _, w in h.periods]
    reset_at = [i for i, w in enumerate(words) if not (w >> BITS["reset"]) & 1][1]
    hold_at = max(i for i in range(reset_at) if states[i] == 0 and (words[i] >> BITS["start"]) & 1)
    assert reset_at - hold_at == 40


@pytest.mark.parametrize("state", range(22))
def test_reset_in_every_state_returns_to_idle(state, seed):
    top = ControllerTop(channel=2)
    h = Harness(top, codes_source(seed))
    checks = {}

    async def script(ctx, h):
        await wait_outputs(ctx, h, 1)
        await wait_state(ctx, h, state)
        for _ in range(3):  # somewhere inside the state's period
            await ctx.tick()
        ctx.set(top.cd.rst, 1)
        await ctx.tick()
        ctx.set(top.cd.rst, 0)
        checks["state"] = ctx.get(top.ctrl.state)
        checks["word"] = ctx.get(top.ctrl.word.as_value())
        checks["valid"] = ctx.get(top.ctrl.o.valid)
        before = len(h.outputs)
        await wait_outputs(ctx, h, before + 2)

    h.run(script)
    assert checks == {"state": 0, "word": word(addr=2), "valid": 0}
    assert h.outputs[-2:] == [(2, r.code) for r in h.adc.reads[-2:]]


@pytest.mark.parametrize("illegal", range(22, 32))
def test_illegal_state_recovers(illegal, seed):
    top = ControllerTop(channel=4)
    h = Harness(top, codes_source(seed))

    forced = {}

    async def script(ctx, h):
        await wait_outputs(ctx, h, 1)
        await wait_state(ctx, h, 7)
        for _ in range(3):  # somewhere inside the period, after its word was decoded
            await ctx.tick()
        ctx.set(top.ctrl.state, illegal)  # an upset flips the state register mid-period
        forced["period"] = len(h.periods)  # the next period starts at the next strobe
        await wait_outputs(ctx, h, 3)

    h.run(script)
    s_next, w_next = h.periods[forced["period"]]
    assert s_next == 0 and w_next == word(addr=4, reset=0)  # clean start: ADC RESET first
    assert h.periods[forced["period"] + 1] == (0, word(addr=4))


@pytest.mark.parametrize("illegal", [22, 27, 31])
def test_illegal_state_during_six_channel_reads_restarts_the_reads(illegal, seed):
    """An upset in the middle of a six-channel read phase: the recovery starts over at channel 0
    (the read index is reset), so every later conversion is read as A0..C1 in order."""
    top = ControllerTop(six_channel=True)
    h = Harness(top, codes_source(seed))
    forced = {}

    async def script(ctx, h):
        await wait_outputs(ctx, h, 9)  # a conversion read, then three reads into the next
        await wait_state(ctx, h, 20)  # READ0 of the fourth channel (index 3)
        for _ in range(3):
            await ctx.tick()
        forced["outputs"] = len(h.outputs)
        ctx.set(top.ctrl.state, illegal)
        await wait_outputs(ctx, h, forced["outputs"] + 12)

    h.run(script)
    assert forced["outputs"] == 9
    after = h.outputs[forced["outputs"]:]
    assert [c for c, _ in after[:12]] == [0, 1, 2, 3, 4, 5] * 2
    # each word is what the ADC drove for the address the controller set: a read index left
    # at 3 would put channel numbers on the wrong samples
    reads = [(r.channel, r.code) for r in h.adc.reads]
    assert after[:12] == reads[len(reads) - len(h.outputs) + forced["outputs"]:][:12]
    # the read addresses after the upset start at A0 again
    addrs = [(w >> BITS["addr"]) & 7 for s, w in h.periods if s == 21]
    assert addrs[-12:] == [0, 1, 2, 3, 4, 5] * 2


def test_backpressure_loses_nothing(seed):
    top = ControllerTop(six_channel=True)
    h = Harness(top, codes_source(seed), p_ready=0.05, seed=seed)

    async def script(ctx, h):
        await wait_outputs(ctx, h, 30)

    h.run(script)
    reads = [(r.channel, r.code) for r in h.adc.reads]
    assert h.outputs == reads[: len(h.outputs)]
    assert len(reads) - len(h.outputs) <= 1  # at most the read in flight


def test_enable_low_idles(seed):
    top = ControllerTop(channel=0)
    h = Harness(top, codes_source(seed))

    async def script(ctx, h):
        await wait_outputs(ctx, h, 1)
        ctx.set(top.enable, 0)
        await wait_state(ctx, h, 0)
        conversions = h.adc.conversions
        for _ in range(2000):
            await ctx.tick()
        assert h.adc.conversions == conversions
        assert ctx.get(top.ctrl.state) == 0
        ctx.set(top.enable, 1)
        await wait_outputs(ctx, h, 3)

    h.run(script)


def test_glitch_sample_passes_through_unchanged():
    source = Source(np.zeros((6, 50), dtype=np.int64), glitches={3: (5, -32768)})
    top = ControllerTop(channel=5)
    h = Harness(top, source)

    async def script(ctx, h):
        await wait_outputs(ctx, h, 6)

    h.run(script)
    assert [v for _, v in h.outputs[:6]] == [0, 0, 0, -32768, 0, 0]


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"channel": 6}, "channel must be 0..5"),
    ({"timeout_periods": 20}, "timeout_periods must be an integer > 22"),
])
def test_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ADS8364Controller(**kwargs)
