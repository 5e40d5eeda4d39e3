"""cocotb: the restoring divider alone (``hw/divider.py``), every quotient and flag against integer
division, with random idle cycles and backpressure.

The requests mix divisors of every size with the cases a divider gets wrong: divisor 0 and 1,
the largest operands, and dividends on both sides of ``divisor << quotient_bits`` (the first
that overflows and the last that does not).
"""

import random
import time

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.hw.divider import Divider
from kfpga.sim.bench import deadline, sim_params, write_results
from kfpga.sim.streams import StreamSink, StreamSource, pump


def expected(dividend, divisor, qbits):
    """``(quotient, overflow)`` of the divider's contract: floor division, saturated."""
    top = (1 << qbits) - 1
    if divisor == 0 or dividend // divisor > top:
        return top, 1
    return dividend // divisor, 0


def requests(rng, n, nb, db, qb):
    """``n`` requests: divisors of every size (log-uniform: a divisor of a few bits puts every
    remainder near it, where a wrong comparison shows), and the special operands."""
    out = []
    for _ in range(n):
        kind = rng.randrange(8)
        size = rng.randrange(1, db + 1)
        divisor = rng.randrange(1 << (size - 1), 1 << size)
        if kind == 0:
            divisor = rng.choice([0, 1, (1 << db) - 1])
            dividend = rng.randrange(1 << nb)
        elif kind in (1, 2):
            # on the overflow boundary: divisor << qb is the first dividend whose quotient does not fit
            edge = divisor << qb
            dividend = min(max(edge - rng.choice([1, 0]) - rng.randrange(3) * (kind == 2), 0), (1 << nb) - 1)
        elif kind == 3:
            dividend = rng.choice([0, (1 << nb) - 1, rng.randrange(1 << nb)])
            divisor = rng.choice([1, 2, 3, divisor | 1])
        else:
            # a quotient that fits, of any size
            dividend = rng.randrange(min(divisor << qb, 1 << nb)) >> rng.randrange(qb)
        out.append({"dividend": dividend, "divisor": divisor})
    return out


@cocotb.test(**deadline(5, default_samples=2000))
async def divider_matches_integer_division(dut):
    p = sim_params()
    n, nb, db, qb = int(p.get("samples", 2000)), int(p["dividend_bits"]), int(p["divisor_bits"]), int(p["quotient_bits"])
    seed = p["seed"]
    dut._log.info(f"seed {seed}")
    rng = random.Random(seed)
    div = Divider(dividend_bits=nb, divisor_bits=db, quotient_bits=qb)  # its stream layouts
    source = StreamSource(dut, "i", dut.clk, div.request_layout, rng=random.Random(seed + 1),
                          p_idle=float(p.get("p_idle", 0.2)))
    sink = StreamSink(dut, "o", dut.clk, div.result_layout, rng=random.Random(seed + 2),
                      p_ready=float(p.get("p_ready", 0.7)))
    Clock(dut.clk, SYSTEM_PERIOD_NS, unit="ns").start()
    dut.rst.value = 1
    await ClockCycles(dut.clk, 3)
    dut.rst.value = 0
    await RisingEdge(dut.clk)
    words = requests(rng, n, nb, db, qb)
    t0 = time.perf_counter()
    await with_timeout(pump(dut.clk, source, sink, words), 20 * n * (qb + 4) * 10 + 10000, "ns")
    await ClockCycles(dut.clk, qb + 10)
    extra = int(dut.o__valid.value)
    bad = [(w, r, expected(w["dividend"], w["divisor"], qb)) for w, r in zip(words, sink.words, strict=True)
           if (r["quotient"], r["overflow"]) != expected(w["dividend"], w["divisor"], qb)]
    overflows = sum(expected(w["dividend"], w["divisor"], qb)[1] for w in words)
    report = {"samples": len(sink.words), "mismatches": len(bad), "first_mismatches": [str(b) for b in bad[:5]],
              "overflows": overflows, "extra_after_end": extra, "wall_s": time.perf_counter() - t0}
    write_results(p, report)
    assert not bad and not extra and len(sink.words) == n, report
    assert 0 < overflows < n, report  # both kinds of result were asked for

