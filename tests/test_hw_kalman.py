# amaranth: UnusedElaboratable=no
"""Kalman cores against the bit-accurate model, in the Amaranth simulator.

Every output integer (x1, x2, yhat, overflow flag) and the sticky flag must equal the model's
on random samples with full-scale steps, the most negative code and saturating inputs, under
random valid/ready backpressure on both sides, and exactly one output comes per input.
"""

import numpy as np
import pytest
from amaranth.sim import Simulator
from amaranth_streams import run_stream

from kfpga.config import KalmanConfig
from kfpga.fixed import QFormat
from kfpga.hw.kalman import FullKalman, SteadyKalman, make_core
from kfpga.model.kalman import FixedKalman
from kfpga.model.reference import KalmanParams
from kfpga.sim.sources import stress_codes

SEED = 31337


CONFIGS = {
    "default": KalmanConfig(),
    "T=0.5 shift": KalmanConfig(params=KalmanParams(T=0.5)),
    "T=0.3 product": KalmanConfig(params=KalmanParams(T=0.3, Q=1.0, R=9.0)),
    "narrow wrap floor": KalmanConfig(
        formats={"x1": QFormat(17, 5, "floor", "wrap"), "xl1": QFormat(17, 5, "floor", "saturate"),
                 "v": QFormat(15, 6, "floor", "saturate"), "e": QFormat(15, 3, "half_up", "saturate")},
        check_ranges=False),
}


def check_core(variant, config, y, channels, *, seed, p_idle, p_ready):
    rng = np.random.default_rng(seed)
    ch = rng.integers(0, channels, len(y)) if channels > 1 else np.zeros(len(y), dtype=np.int64)
    dut = make_core(config, variant, channels=channels)
    payloads = [{"channel": int(c), "sample": int(s)} for c, s in zip(ch, y, strict=True)]
    out = run_stream(dut, payloads, seed=seed, p_idle=p_idle, p_ready=p_ready, extra_cycles=50)
    model = FixedKalman(config, variant=variant)
    x1, x2, yhat, ovf = model.run_channels(y, ch)
    got = {k: np.array([getattr(o, k) for o in out]) for k in ("channel", "x1", "x2", "yhat", "overflow")}
    assert len(out) == len(y)
    np.testing.assert_array_equal(got["channel"], ch)
    first = np.flatnonzero((got["x1"] != x1) | (got["x2"] != x2) | (got["yhat"] != yhat) | (got["overflow"] != ovf))
    assert first.size == 0, (
        f"first mismatch at sample {first[0]}: rtl x1={got['x1'][first[0]]} x2={got['x2'][first[0]]} "
        f"yhat={got['yhat'][first[0]]} ovf={got['overflow'][first[0]]}; model x1={x1[first[0]]} x2={x2[first[0]]} "
        f"yhat={yhat[first[0]]} ovf={ovf[first[0]]}")
    return ovf


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_core_bit_exact_default_10000_samples(variant):
    """>= 10,000 random samples through each core with default formats, backpressure both sides."""
    seed = SEED
    print(f"seed {seed}")
    y = stress_codes(seed, 10000)
    ovf = check_core(variant, KalmanConfig(), y, 1, seed=seed, p_idle=0.2, p_ready=0.6)
    assert ovf.any(), "the stimulus must exercise saturation"


@pytest.mark.parametrize("name", [n for n in CONFIGS if n != "default"])
@pytest.mark.parametrize("variant", ["steady", "full"])
def test_core_bit_exact_other_formats_and_t(variant, name):
    seed = SEED + 1 + list(CONFIGS).index(name)
    print(f"seed {seed}")
    y = stress_codes(seed, 2500 if variant == "full" else 4000)
    check_core(variant, CONFIGS[name], y, 1, seed=seed, p_idle=0.3, p_ready=0.5)


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_core_six_channels(variant):
    seed = SEED + 11
    print(f"seed {seed}")
    y = stress_codes(seed, 3000)
    check_core(variant, KalmanConfig(), y, 6, seed=seed, p_idle=0.1, p_ready=0.7)


def test_sticky_overflow_flag():
    """The sticky flag rises with the first saturating sample and stays."""
    config = KalmanConfig()
    y = np.array([0] * 20 + [32767, -32768] * 20 + [0] * 20, dtype=np.int64)
    for variant in ("steady", "full"):
        dut = make_core(config, variant)
        sticky = []
        sim = Simulator(dut)
        sim.add_clock(1e-8)

        async def bench(ctx, dut=dut, sticky=sticky):
            ctx.set(dut.o.ready, 1)
            for s in y:
                ctx.set(dut.i.payload, {"channel": 0, "sample": int(s)})
                ctx.set(dut.i.valid, 1)
                await ctx.tick().until(dut.i.ready)
                ctx.set(dut.i.valid, 0)
                *_, valid = await ctx.tick().sample(dut.o.valid)
                while not valid:
                    *_, valid = await ctx.tick().sample(dut.o.valid)
                sticky.append(ctx.get(dut.overflow))

        sim.add_testbench(bench)
        sim.run()
        expected = FixedKalman(config, variant=variant).run(y).sticky
        np.testing.assert_array_equal(sticky, expected)
        assert expected[-1] and not expected[0]


@pytest.mark.parametrize(("cls", "cycles"), [(SteadyKalman, 1), (FullKalman, 22)])
def test_latency_and_cycles_per_update(cls, cycles):
    """Measured latency and throughput equal what the cores state (and README quotes)."""
    dut = cls(KalmanConfig())
    accepted, produced = [], []
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def bench(ctx):
        ctx.set(dut.o.ready, 1)
        ctx.set(dut.i.valid, 1)
        ctx.set(dut.i.payload, {"channel": 0, "sample": 100})
        for cycle in range(200):
            _, _, ready, valid = await ctx.tick().sample(dut.i.ready, dut.o.valid)
            if ready:
                accepted.append(cycle)
            if valid:
                produced.append(cycle)

    sim.add_testbench(bench)
    sim.run()
    latency = cls.LATENCY if cls is SteadyKalman else dut.latency
    per_update = cls.CYCLES_PER_UPDATE if cls is SteadyKalman else dut.cycles_per_update
    assert per_update == cycles
    assert produced[0] - accepted[0] == latency
    assert np.all(np.diff(accepted[:5]) == per_update)
    assert np.all(np.diff(produced[:5]) == per_update)


def test_core_rejects_bad_channel_count():
    with pytest.raises(ValueError, match="channels must be an integer 1..8, not 9"):
        SteadyKalman(KalmanConfig(), channels=9)
