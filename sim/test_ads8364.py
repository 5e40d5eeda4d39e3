"""cocotb: the ADS8364 controller's pin protocol (with its clock divider) against the ADC model.

The model checks every datasheet timing figure on every edge; the test checks that each
conversion yields its words, in order, with the codes the ADC drove.
"""

import cocotb
from cocotb.triggers import with_timeout

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
