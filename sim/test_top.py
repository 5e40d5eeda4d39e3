"""cocotb: the whole design (divider + controller + core) with the ADC model, bit-exact."""

import time

import cocotb
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, FallingEdge, RisingEdge, Timer, with_timeout

from kfpga.sim.bench import SystemTB, deadline, sim_params, write_results
from kfpga.sim.system import conversions_for

PERIOD_US = 0.2  # ADC CLK


def hold_pin(dut, p):
    """The HOLD pin that starts this design's conversions."""
    pair = 0 if p.get("six") else p.get("channel", 0) // 2
    return (dut.adc_hold_a_n, dut.adc_hold_b_n, dut.adc_hold_c_n)[pair]


def outputs_after_reset(tb):
    return sum(1 for o in tb.outputs if o[0] > tb.resets[-1])


async def start(dut, p, samples):
    tb = SystemTB(dut, p, expected_conversions=conversions_for(p, samples))
    dut.rst_n.value = 0  # power-on reset before the ADC model starts watching the pins
    await ClockCycles(dut.clk50, 5)
    dut.rst_n.value = 1
    tb.start()
    return tb


async def run_to(tb, samples):
    # generous: 23 CLK periods per conversion with one read; a conversion read six times for
    # two inputs takes longer per update
    per_sample_us = (40 if len(tb.adc_channels) == 1 else 80) * PERIOD_US
    await with_timeout(tb.wait_outputs(samples), per_sample_us * samples + 200, "us")


def finish(tb, p, t0, **extra):
    report = tb.report(time.perf_counter() - t0)
    report.update(extra)
    write_results(p, report)
    return report


@cocotb.test(**deadline(20, default_samples=500))
async def system_bit_exact(dut):
    """The main regression: ``samples`` estimates, every one equal to the model's."""
    p = sim_params()
    n = int(p.get("samples", 500))
    tb = await start(dut, p, n)
    t0 = time.perf_counter()
    await run_to(tb, n)
    report = finish(tb, p, t0)
    per_conversion = 6 if p.get("six") else 1  # updates per conversion
    reads_per_conversion = 6 if p.get("six") or len(tb.adc_channels) > 1 else 1
    assert report["ok"] and report["mismatches"] == 0, report
    # one estimate per update: every update came out but the last few in flight
    assert report["outputs"] + report["pending_at_end"] == len(tb.updates()), report
    assert abs(tb.adc.conversions * per_conversion - len(tb.updates())) <= per_conversion, report
    assert abs(tb.adc.conversions * reads_per_conversion - len(tb.adc.reads)) <= reads_per_conversion, report
    assert report["timeout_flag"] == 0
    check_pins(dut, tb, p)


def check_pins(dut, tb, p):
    """The pins the model does not read, and the controller's own HOLD protocol: each HOLD that
    starts conversions goes low for exactly one CLK period per conversion (the idle level high),
    the others stay high; BYTE and ADD low and WR high throughout (sampled at every read)."""
    used = {0, 1, 2} if p.get("six") or len(tb.adc_channels) > 1 else {p.get("channel", 0) // 2}
    for pair, widths in enumerate(tb.adc.hold_low_ns):
        if pair in used:
            assert len(widths) >= tb.adc.conversions - 1, \
                f"HOLD{'ABC'[pair]}: {len(widths)} pulses, {tb.adc.conversions} conversions"
            assert all(abs(w - 1000 * PERIOD_US) < 1.0 for w in widths), f"HOLD{'ABC'[pair]} low for {sorted(set(widths))} ns"
        else:
            assert not widths, f"HOLD{'ABC'[pair]} pulsed, but this design converts with HOLD{'ABC'[min(used)]}"
    from kfpga.core.board import SYSTEM_PERIOD_NS

    widths = sorted({round(w, 3) for w in tb.valid_high_ns})
    assert widths == [round(SYSTEM_PERIOD_NS, 3)], f"out_valid high for {widths} ns, not one system cycle"
    assert tb.pin_levels and all(levels == (0, 0, 1) for levels in tb.pin_levels), \
        f"BYTE, ADD, WR not held at 0, 0, 1: {sorted(set(tb.pin_levels))}"


@cocotb.test(**deadline(20, default_samples=100))
async def reset_mid_conversion(dut):
    p = sim_params()
    tb = await start(dut, p, 60)
    await run_to(tb, 20)
    await FallingEdge(hold_pin(dut, p))
    await Timer(10 * PERIOD_US, "us")  # half-way through the conversion
    t0 = time.perf_counter()
    await tb.reset()
    await run_to(tb, len(tb.outputs) + 30)
    report = finish(tb, p, t0)
    assert report["ok"] and outputs_after_reset(tb) >= 30, report  # nothing lost after the reset


@cocotb.test(**deadline(20, default_samples=100))
async def reset_mid_update(dut):
    p = sim_params()
    tb = await start(dut, p, 60)
    await run_to(tb, 20)
    await RisingEdge(dut.adc_rd_n)  # a sample has just been read: the core is working on it
    # steady core: accepted one cycle later, out two cycles after that; full core: in DIV
    await ClockCycles(dut.clk50, 1 if p["variant"] == "steady" else 12)
    t0 = time.perf_counter()
    await tb.reset()
    await run_to(tb, len(tb.outputs) + 30)
    report = finish(tb, p, t0)
    assert report["ok"] and outputs_after_reset(tb) >= 30, report
    assert report["dropped_at_reset"] >= 1, report  # the sample being filtered was lost to the reset, by design


@cocotb.test(**deadline(20, default_samples=100))
async def missing_eoc_times_out_and_recovers(dut):
    p = sim_params()
    tb = await start(dut, p, 60)
    await run_to(tb, 10)
    tb.adc.drop_eoc(1)
    t_drop = get_sim_time("ns")
    t0 = time.perf_counter()
    await run_to(tb, len(tb.outputs) + 30)
    report = finish(tb, p, t0)
    assert report["ok"], report
    assert report["eocs_dropped"] == 1 and report["timeout_flag"] == 1, report
    after = [o for o in tb.outputs if o[0] > t_drop]
    assert len(after) >= 30  # nothing lost afterwards: every later read came out (ok above)


@cocotb.test(**deadline(20, default_samples=100))
async def glitch_sample(dut):
    p = dict(sim_params(), glitch=True)
    tb = await start(dut, p, 40)
    t0 = time.perf_counter()
    await run_to(tb, 40)
    report = finish(tb, p, t0, glitches=len(tb.source.glitches))
    assert tb.source.glitches and report["ok"], report


@cocotb.test(**deadline(20, default_samples=10))
async def reset_release_latency(dut):
    """rst_n released at each of the ten system cycles of an ADC clock period: the first action
    (RESET low to the ADC) comes 3 to 12 system cycles after the first clock edge that sees
    rst_n high: the reset synchroniser's two stages and the control word's register, then up to
    one strobe period more; each phase one cycle apart."""
    from cocotb.clock import Clock

    from kfpga.core.board import SYSTEM_PERIOD_NS

    p = sim_params()
    dut.rst_n.value = 0
    dut.adc_eoc_n.value = 1
    Clock(dut.clk50, SYSTEM_PERIOD_NS, unit="ns").start()
    ratio = int(p.get("ratio", 10))
    delays = []
    for phase in range(ratio):
        dut.rst_n.value = 0
        await ClockCycles(dut.clk50, 3 * ratio)
        await RisingEdge(dut.adc_clk)
        await ClockCycles(dut.clk50, phase)
        await Timer(1, "ns")  # between clock edges, as an asynchronous reset comes
        dut.rst_n.value = 1
        await RisingEdge(dut.clk50)  # the first edge that sees it high
        seen = get_sim_time("ns")
        await with_timeout(FallingEdge(dut.adc_reset_n), 20 * ratio * SYSTEM_PERIOD_NS, "ns")
        delays.append(round((get_sim_time("ns") - seen) / SYSTEM_PERIOD_NS, 3))
    write_results(p, {"delays_cycles": delays})
    assert sorted(delays) == [float(3 + k) for k in range(ratio)], delays
