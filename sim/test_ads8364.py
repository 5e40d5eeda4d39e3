"""cocotb: the ADS8364 controller's pin protocol (with its clock divider) against the ADC model.

The model checks every datasheet timing figure on every edge; the test checks that each
conversion yields its words, in order, with the codes the ADC drove.
"""

import cocotb
from cocotb.triggers import Timer, with_timeout

from kfpga.sim.bench import FrontendTB, deadline, make_source, sim_params, write_results


@cocotb.test(**deadline(20, default_samples=60))
async def pin_protocol(dut):
    p = sim_params()
    n = int(p.get("samples", 60))
    per_conversion = 6 if p.get("six") else 1
    tb = FrontendTB(dut, p, make_source(p, n))
    await tb.reset()
    tb.pins.start()
    await with_timeout(tb.sink.run(n), 10_000 * n, "ns")
    reads = [(r.channel, r.code) for r in tb.adc.reads]
    got = [(w["channel"], w["sample"]) for w in tb.sink.words]
    report = {"samples": len(got), "conversions": tb.adc.conversions, "reads": len(reads),
              "mismatches": sum(a != b for a, b in zip(got, reads, strict=False))}
    write_results(p, report)
    assert got == reads[: len(got)], report
    expected_channels = list(range(6)) if per_conversion == 6 else [p.get("channel", 0)]
    assert [c for c, _ in got] == (expected_channels * n)[:n]
    # every conversion read completely: at most the conversion in progress is unread
    assert tb.adc.conversions - len(reads) // per_conversion <= 1, report


@cocotb.test(**deadline(20, default_samples=60))
async def missing_eoc_times_out(dut):
    """An EOC that never comes: the timeout flag rises (and stays), the controller starts over,
    and every later conversion is read and delivered as before."""
    p = sim_params()
    n = int(p.get("samples", 60))
    tb = FrontendTB(dut, p, make_source(p, n + 10))
    await tb.reset()
    tb.pins.start()
    await with_timeout(tb.sink.run(n // 3), 10_000 * n, "ns")
    assert int(dut.timeout.value) == 0
    tb.adc.drop_eoc(1)
    await with_timeout(tb.sink.run(n), 20_000 * n, "ns")
    reads = [(r.channel, r.code) for r in tb.adc.reads]
    got = [(w["channel"], w["sample"]) for w in tb.sink.words]
    write_results(p, {"samples": len(got), "timeout_flag": int(dut.timeout.value), "eocs_dropped": tb.adc.eocs_dropped,
                      "mismatches": sum(a != b for a, b in zip(got, reads, strict=False))})
    assert tb.adc.eocs_dropped == 1 and int(dut.timeout.value) == 1
    assert got == reads[: len(got)] and len(got) >= n


@cocotb.test(**deadline(40, default_samples=60))
async def stuck_eoc_is_no_conversion(dut):
    """EOC stuck low (a fault on its line): only its falling edge ends a conversion, the level
    that stays does not. The timeout flag rises, no word comes while it stays low, and the
    reads resume, each with the code the ADC drove, once it is released."""
    p = sim_params()
    n = int(p.get("samples", 60))
    per = 6 if p.get("six") else 1
    tb = FrontendTB(dut, p, make_source(p, 4 * n))
    await tb.reset()
    tb.pins.start()
    collect = cocotb.start_soon(tb.sink.run(10 * n * per))

    async def words_reach(count):
        while len(tb.sink.words) < count:
            await Timer(1, "us")

    await with_timeout(words_reach(n // 3), 10_000 * n, "ns")
    tb.adc.stick_eoc()
    await Timer(20, "us")  # the conversion under way ends, EOC falls and stays low
    stuck_at = len(tb.sink.words)
    await Timer(200, "us")  # some 40 conversion times
    during = len(tb.sink.words) - stuck_at
    timeout = int(dut.timeout.value)
    tb.adc.stick_eoc(False)
    await with_timeout(words_reach(stuck_at + n // 3), 20_000 * n, "ns")
    collect.cancel()
    reads = [(r.channel, r.code) for r in tb.adc.reads]
    got = [(w["channel"], w["sample"]) for w in tb.sink.words]
    write_results(p, {"samples": len(got), "timeout_flag": timeout, "words_while_stuck": during,
                      "mismatches": sum(a != b for a, b in zip(got, reads, strict=False))})
    assert timeout == 1 and during == 0, f"{during} word(s) while EOC was stuck low, timeout flag {timeout}"
    assert got == reads[: len(got)]


@cocotb.test(**deadline(40, default_samples=60))
async def ready_does_not_pace_the_conversions(dut):
    """The consumer's ready, low at random while the output register is empty, slows nothing:
    the controller converts at its own rate (23 CLK periods a conversion with one read, 33 with
    six) as long as each word is taken before the next read."""
    p = sim_params()
    six = bool(p.get("six"))
    tb = FrontendTB(dut, {**p, "p_ready": 0.3}, make_source(p, 2000))
    await tb.reset()
    tb.pins.start()
    collect = cocotb.start_soon(tb.sink.run(100_000))
    await Timer(30, "us")  # past the reset sequence
    first = tb.adc.conversions
    span_us = 1000
    await Timer(span_us, "us")
    count = tb.adc.conversions - first
    collect.cancel()
    expected = span_us / ((33 if six else 23) * 0.2)  # CLK periods of 0.2 us (5 MHz)
    reads = [(r.channel, r.code) for r in tb.adc.reads]
    got = [(w["channel"], w["sample"]) for w in tb.sink.words]
    write_results(p, {"samples": len(got), "conversions": count, "expected_conversions": expected,
                      "mismatches": sum(a != b for a, b in zip(got, reads, strict=False))})
    assert abs(count - expected) <= 1, f"{count} conversions in {span_us} us, {expected:.1f} at the controller's own rate"
    assert got == reads[: len(got)]
