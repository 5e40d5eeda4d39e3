# amaranth: UnusedElaboratable=no
"""The paper's filter's cores against the bit-accurate model, in the Amaranth simulator.

Every output integer (x1, x2, yhat, overflow flag) and the sticky flag must equal the model's
on random samples with full-scale steps, the most negative code and saturating inputs, under
random valid/ready backpressure on both sides, and exactly one output comes per input. The
contract suite (``tests/contract``) runs the same checks on every registered filter with its
default config; here they cover more of this filter's formats and T values.
"""

import re

import numpy as np
import pytest
from amaranth.sim import Simulator
from test_golden import GOLDEN, golden_config

from kfpga.core.config import FilterConfig
from kfpga.core.fixed import QFormat
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.kalman2 import SteadyCore, make_core
from kfpga.model.reference import KalmanParams
from kfpga.sim.amaranth_streams import measure_timing, run_core, run_with_deadline
from kfpga.sim.sources import stress_codes

CONFIGS = {
    "default": FilterConfig(),
    "T=0.5 shift": FilterConfig(params=KalmanParams(T=0.5)),
    "T=0.3 product": FilterConfig(params=KalmanParams(T=0.3, Q=1.0, R=9.0)),
    "narrow wrap floor": FilterConfig(
        formats={"x1": QFormat(17, 5, "floor", "wrap"), "xl1": QFormat(17, 5, "floor", "saturate"),
                 "v": QFormat(15, 6, "floor", "saturate"), "e": QFormat(15, 3, "half_up", "saturate")},
        check_ranges=False),
}


def test_core_bit_exact_default_10000_samples(variant, seed):
    """>= 10,000 random samples through each core with default formats, backpressure both sides."""
    y = stress_codes(seed, 10000)
    report = run_core(FilterConfig(), variant, y, seed=seed, p_idle=0.2, p_ready=0.6)
    assert report["overflowed"], "the stimulus must exercise saturation"


@pytest.mark.parametrize("name", [n for n in CONFIGS if n != "default"])
def test_core_bit_exact_other_formats_and_t(variant, name, seed):
    y = stress_codes(seed, 2500 if variant == "full" else 4000)
    run_core(CONFIGS[name], variant, y, seed=seed, p_idle=0.3, p_ready=0.5)


def test_core_six_channels(variant, seed):
    run_core(FilterConfig(), variant, stress_codes(seed, 3000), seed=seed, channels=6, p_idle=0.1, p_ready=0.7)


@pytest.mark.parametrize("case", ["default/steady/stress", "default/full/stress", "wrap/steady/stress",
                                  "T0.3/full/stress"])
def test_core_equals_the_golden_integers(case):
    """The RTL's integers are the ones recorded before the operations layer (tests/golden)."""
    cname, variant, _ = case.split("/")
    y = GOLDEN[f"{case}/y"].astype(np.int64)
    report = run_core(golden_config(cname), variant, y, seed=1, p_idle=0.2, p_ready=0.7)
    for field in ("x1", "x2", "yhat", "overflow"):
        np.testing.assert_array_equal(report["got"][field], GOLDEN[f"{case}/{field}"], err_msg=f"{case}: {field}")


def test_sticky_overflow_flag(variant):
    """The sticky flag rises with the first saturating sample and stays."""
    config = FilterConfig()
    y = np.array([0] * 20 + [32767, -32768] * 20 + [0] * 20, dtype=np.int64)
    dut = make_core(config, variant)
    sticky = []
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def bench(ctx):
        ctx.set(dut.o.ready, 1)
        for s in y:
            ctx.set(dut.i.payload, {"channel": 0, "y": int(s)})
            ctx.set(dut.i.valid, 1)
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)
            *_, valid = await ctx.tick().sample(dut.o.valid)
            while not valid:
                *_, valid = await ctx.tick().sample(dut.o.valid)
            sticky.append(ctx.get(dut.overflow))

    sim.add_testbench(bench)
    run_with_deadline(sim, 60 * len(y))
    expected = FixedModel(config, variant=variant).run(y).sticky
    np.testing.assert_array_equal(sticky, expected)
    assert expected[-1] and not expected[0]


# One point made narrow, so that it saturates on samples where no other point does: there the
# estimate's flag comes from that point alone, and a core that dropped its flag would differ from
# the model. (variant, params, point, int_bits of the narrowed point)
FLAG_ALONE = {
    "xl1": ("steady", KalmanParams(), "xl1", 16),
    "x2 shift T=0.5": ("steady", KalmanParams(T=0.5), "x2", 16),
    "x2 product T=0.3": ("steady", KalmanParams(T=0.3), "x2", 16),
    "vt T=0.3": ("steady", KalmanParams(T=0.3), "vt", 14),
    # the time-varying core's rate steps (T not a power of two) after its write-back
    "vt T=0.3 full": ("full", KalmanParams(T=0.3), "vt", 14),
    # P0 with p21 + p22 > S: the first K2 = pl21 / S is 1.2, beyond gain's Q1.f, so the
    # divider saturates; nothing else does on that sample
    "divider": ("full", KalmanParams(R=0.5, P0=[[1.0, -2.0], [-2.0, 5.0]]), "gain", 1),
}


@pytest.mark.parametrize("case", list(FLAG_ALONE))
def test_each_overflow_flag_reaches_the_estimate_on_its_own(case, seed):
    variant, params, point, int_bits = FLAG_ALONE[case]
    base = FilterConfig(params=params, check_ranges=False)
    fmt = base.formats[point]
    config = FilterConfig(params=params, formats={**base.formats, point: QFormat(int_bits, fmt.frac_bits, fmt.rounding)},
                          check_ranges=False)
    y = stress_codes(1, 1200)  # fixed codes: the samples below are found in them, seed or not
    points = FixedModel(config, variant=variant).run(y).overflow_points
    others = np.logical_or.reduce([f for name, f in points.items() if name != point])
    alone = points[point] & ~others
    assert alone.any(), f"no sample saturates {point} alone"
    report = run_core(config, variant, y, seed=seed, p_idle=0.2, p_ready=0.6)  # every flag against the model
    assert report["got"]["overflow"][alone].all()


@pytest.mark.parametrize("name", ["T=0.5 shift", "T=0.3 product"])
def test_latency_with_the_rate_steps(variant, name):
    """T not a power of two: x2 = v (1/T) takes more steps (latency), no more cycles per update."""
    config = CONFIGS[name]
    dut = make_core(config, variant)
    latency, _, produced = measure_timing(dut, config)
    assert latency == dut.latency and produced[:5] == [dut.cycles_per_update] * 5
    shift = name == "T=0.5 shift"
    if variant == "steady":
        assert (dut.cycles_per_update, dut.latency) == ((4, 5) if shift else (4, 8))
    else:
        assert dut.cycles_per_update == (25 if shift else 27)


def test_core_rejects_bad_channel_count():
    with pytest.raises(ValueError, match="^" + re.escape("channels must be an integer 1..256, not 257") + "$"):
        SteadyCore(FilterConfig(), channels=257)
    with pytest.raises(TypeError, match="^" + re.escape("channels must be an integer, not '6'") + "$"):
        SteadyCore(FilterConfig(), channels="6")


@pytest.fixture(params=["steady", "full"])
def variant(request):
    return request.param
