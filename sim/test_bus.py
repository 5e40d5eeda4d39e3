"""cocotb: a programmable core on its bus, new settings written mid-stream, against the model
(or a core with the missing bit alone: ``bus`` not given).

The core (a folded core with ``bus="avalon"`` or ``"axi4lite"`` and the missing bit) filters a
stream while a bus master, cocotbext-avalon's ``AvalonMMMasterBFM`` or cocotbext-axi's
``AxiLiteMaster``, writes the settings of each new phase (``kfpga regs``'s writes: every digit,
then ``CONTROL.COMMIT``) once a share of the estimates is out, waits for the commit and reads
``COMMITTED``: the sample from which the new settings apply. Every estimate is then compared
with the model that switches config at those samples (the state carried over), the samples
marked missing predicted only; ``UPDATES``, ``OVERFLOWS`` and ``ID`` with what the model and the
config say.
"""

import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.layouts import input_layout, output_layout
from kfpga.hw.regmap import COMMITTED, ID, OVERFLOWS, STATUS, STATUS_BITS, UPDATES
from kfpga.sim.bench import deadline, load_config, sim_params, write_results
from kfpga.sim.sources import stress_codes
from kfpga.sim.streams import StreamSink, StreamSource

#: Cycles a bus access may wait before the bench fails it (a commit waits for one update).
BUS_TIMEOUT_CYCLES = 200_000


class Bus:
    """Word-indexed reads and writes through the maintained bus model of ``kind``."""

    def __init__(self, dut, kind):
        self.kind = kind
        if kind == "avalon":
            from cocotbext.avalon import AvalonMMMasterBFM

            self.master = AvalonMMMasterBFM.from_prefix(dut, "avs", dut.clk, dut.rst)
            self.master.start()
        else:
            from cocotbext.axi import AxiLiteBus, AxiLiteMaster

            self.master = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axil"), dut.clk, dut.rst)

    async def write(self, index, value):
        if self.kind == "avalon":
            await self.master.write(index, value, timeout_cycles=BUS_TIMEOUT_CYCLES)
        else:
            await with_timeout(self.master.write_dword(4 * index, value), BUS_TIMEOUT_CYCLES * SYSTEM_PERIOD_NS, "ns")

    async def read(self, index):
        if self.kind == "avalon":
            return await self.master.read(index, timeout_cycles=BUS_TIMEOUT_CYCLES)
        return await with_timeout(self.master.read_dword(4 * index), BUS_TIMEOUT_CYCLES * SYSTEM_PERIOD_NS, "ns")


def point_counts(model, result):
    """``{point: writes that saturated}`` of a model's run: its sites' flags, summed by point."""
    points = dict(model.kernel(False).site_points)
    if model.predicts:
        points.update(model.kernel(False, predict=True).site_points)
    out = {}
    for site, flags in result.overflow_sites.items():
        out[points[site]] = out.get(points[site], 0) + int(np.count_nonzero(flags))
    return out


def expected(configs, variant, codes, missing, switches, counts=None):
    """The model's estimates: ``configs[j]`` from sample ``switches[j - 1]`` on, the state carried;
    ``counts``, a dict given, gets each point's saturated writes over the run."""
    cuts = [0, *switches, len(codes)]
    state, parts = None, []
    for config, lo, hi in zip(configs, cuts[:-1], cuts[1:], strict=True):
        model = FixedModel(config, variant=variant)
        res = model.run(codes[lo:hi], state, missing=missing[lo:hi])
        parts.append(res)
        state = res.state
        if counts is not None:
            for point, n in point_counts(model, res).items():
                counts[point] = counts.get(point, 0) + n
    names = parts[0].outputs.keys()
    return {**{n: np.concatenate([p.outputs[n] for p in parts]) for n in names},
            "overflow": np.concatenate([p.overflow for p in parts]).astype(int)}


async def read_counters(bus, counters):
    """``{point: count}`` of the core's overflow counters (``[[word index, point], ...]``)."""
    return {point: await bus.read(index) for index, point in counters}


async def write_phases(dut, bus, sink, phases, n):
    """Each phase's writes once its share of the estimates is out; then the commit awaited and
    ``COMMITTED`` read: the sample each phase starts at."""
    switches = []
    for j, phase in enumerate(phases):
        target = (j + 1) * n // (len(phases) + 1)
        while len(sink.words) < target:
            await RisingEdge(dut.clk)
        for index, value in phase["writes"]:
            await bus.write(index, value)
        for _ in range(BUS_TIMEOUT_CYCLES // 8):  # the commit waits for the update that runs
            if not (await bus.read(STATUS)) & (1 << STATUS_BITS["COMMIT_PENDING"]):
                break
            await ClockCycles(dut.clk, 4)
        else:
            raise AssertionError(f"phase {j}: the commit did not take effect")
        switches.append(await bus.read(COMMITTED))
    return switches


@cocotb.test(**deadline(200, default_samples=600))
async def settings_mid_stream(dut):
    """New settings at run time: every estimate equals the model's that switches at COMMITTED."""
    p = sim_params()
    seed, variant, n = p["seed"], p["variant"], int(p.get("samples", 600))
    dut._log.info(f"seed {seed}")
    config = load_config(p)
    phases = p.get("phases", [])
    configs = [config] + [load_config(ph) for ph in phases]
    rng = np.random.default_rng(seed)
    codes = np.array(p["codes"], dtype=np.int64)[:n] if "codes" in p else stress_codes(seed, n)
    n = len(codes)
    missing = rng.random(n) < float(p.get("missing", 0.0))
    Clock(dut.clk, SYSTEM_PERIOD_NS, unit="ns").start()
    source = StreamSource(dut, "i", dut.clk, input_layout(config, 1, missing=True), rng=random.Random(seed + 1),
                          p_idle=p.get("p_idle", 0.0))
    sink = StreamSink(dut, "o", dut.clk, output_layout(config, 1), rng=random.Random(seed + 2),
                      p_ready=p.get("p_ready", 1.0))
    dut.rst.value = 1
    bus = Bus(dut, p["bus"]) if p.get("bus") else None  # none: the missing bit alone
    await ClockCycles(dut.clk, 3)
    dut.rst.value = 0
    await RisingEdge(dut.clk)
    identity = await bus.read(ID) if bus else None
    words = [{"channel": 0, "y": int(c), "missing": int(m)} for c, m in zip(codes, missing, strict=True)]
    sending = cocotb.start_soon(source.send(words))
    collecting = cocotb.start_soon(sink.run(n))
    switches = await write_phases(dut, bus, sink, phases, n)
    per_sample = 20 * 5000  # ns: far more than any update of these models takes
    await with_timeout(collecting, n * per_sample + 100_000, "ns")
    await sending
    updates, overflows = (await bus.read(UPDATES), await bus.read(OVERFLOWS)) if bus else (n, None)
    counted = await read_counters(bus, p.get("counters", [])) if bus else {}
    counts = {}
    want = expected(configs, variant, codes, missing, switches, counts)
    # the new settings must change the estimates (else the check could not tell them apart), and
    # a switch one sample off must not give the same ones
    unchanged = expected(configs[:1], variant, codes, missing, [])
    early = expected(configs, variant, codes, missing, [s - 1 for s in switches]) if switches else unchanged
    measured = expected(configs, variant, codes, np.zeros(n, dtype=bool), switches)  # the missing bit ignored
    differ = {what: int(sum(np.count_nonzero(alt[k] != want[k]) for k in want))
              for what, alt in (("unswitched", unchanged), ("one_early", early), ("measured", measured))}
    mismatches = []
    for i, word in enumerate(sink.words):
        for name in (*want.keys(),):
            if int(word[name]) != int(want[name][i]):
                mismatches.append((i, name, int(word[name]), int(want[name][i])))
    report = {"ok": not mismatches and len(sink.words) == n, "samples": n, "compared": len(sink.words),
              "mismatches": len(mismatches), "first": mismatches[:5], "switches": switches,
              "missing": int(missing.sum()), "updates": updates, "overflows": overflows,
              "model_overflows": int(want["overflow"].sum()), "id": identity, "bus": p.get("bus"), "differ": differ,
              "counters": counted, "model_counts": counts}
    write_results(p, report)
    assert report["ok"], report
    assert all(0 < s < n for s in switches) and switches == sorted(switches), report
    if bus:
        assert updates == n and overflows == report["model_overflows"], report
        assert identity == p["id"], report
        assert counted == {point: counts.get(point, 0) for point in counted}, report
        assert set(counts) <= set(counted), report  # every point that can saturate has its counter
    assert not phases or (differ["unswitched"] and differ["one_early"]), report
    assert not missing.any() or differ["measured"], report


@cocotb.test(**deadline(200, default_samples=200))
async def reset_and_clear(dut):
    """A soft reset from new reset values: half the samples, then the new settings committed,
    ``CONTROL.RESET`` and ``CONTROL.CLEAR``; the second half must be the new config's model from its
    reset state, ``UPDATES`` count it alone, and the estimates before the reset the old model's."""
    from kfpga.hw.regmap import CONTROL, CONTROL_BITS

    p = sim_params()
    seed, variant, n = p["seed"], p["variant"], int(p.get("samples", 200))
    dut._log.info(f"seed {seed}")
    config, new = load_config(p), load_config(p["phases"][0])
    codes = stress_codes(seed, n)
    missing = np.random.default_rng(seed).random(n) < float(p.get("missing", 0.0))
    Clock(dut.clk, SYSTEM_PERIOD_NS, unit="ns").start()
    source = StreamSource(dut, "i", dut.clk, input_layout(config, 1, missing=True), rng=random.Random(seed + 1),
                          p_idle=p.get("p_idle", 0.0))
    sink = StreamSink(dut, "o", dut.clk, output_layout(config, 1), rng=random.Random(seed + 2),
                      p_ready=p.get("p_ready", 1.0))
    dut.rst.value = 1
    bus = Bus(dut, p["bus"])
    await ClockCycles(dut.clk, 3)
    dut.rst.value = 0
    await RisingEdge(dut.clk)
    words = [{"channel": 0, "y": int(c), "missing": int(m)} for c, m in zip(codes, missing, strict=True)]
    half = n // 2
    per_sample = 20 * 5000
    collecting = cocotb.start_soon(sink.run(n))
    await with_timeout(source.send(words[:half]), half * per_sample + 100_000, "ns")
    while len(sink.words) < half:
        await RisingEdge(dut.clk)
    before = await bus.read(UPDATES)
    for index, value in p["phases"][0]["writes"]:  # the digits, then COMMIT
        await bus.write(index, value)
    await bus.write(CONTROL, (1 << CONTROL_BITS["RESET"]) | (1 << CONTROL_BITS["CLEAR"]))
    for _ in range(BUS_TIMEOUT_CYCLES // 8):
        if not (await bus.read(STATUS)) & 0b11:  # neither the commit nor the reset pending
            break
        await ClockCycles(dut.clk, 4)
    else:
        raise AssertionError("the reset did not take effect")
    cleared = await bus.read(UPDATES)
    await with_timeout(source.send(words[half:]), (n - half) * per_sample + 100_000, "ns")
    await with_timeout(collecting, n * per_sample + 100_000, "ns")
    after = await bus.read(UPDATES)
    counted = await read_counters(bus, p.get("counters", []))
    first = FixedModel(config, variant=variant).run(codes[:half], missing=missing[:half])
    second_model = FixedModel(new, variant=variant)
    second = second_model.run(codes[half:], missing=missing[half:])  # from the new reset state
    counts = point_counts(second_model, second)
    want = {name: np.concatenate([first.outputs[name], second.outputs[name]]) for name in first.outputs}
    want["overflow"] = np.concatenate([first.overflow, second.overflow]).astype(int)
    mismatches = [(i, name, int(w[name]), int(want[name][i])) for i, w in enumerate(sink.words) for name in want
                  if int(w[name]) != int(want[name][i])]
    carried = FixedModel(new, variant=variant).run(codes[half:], first.state, missing=missing[half:])
    report = {"ok": not mismatches and len(sink.words) == n, "samples": n, "mismatches": len(mismatches),
              "first": mismatches[:5], "updates_before": before, "updates_cleared": cleared, "updates_after": after,
              "reset_matters": int(sum(np.count_nonzero(carried.outputs[k] != second.outputs[k]) for k in first.outputs)),
              "counters": counted, "model_counts": counts}
    write_results(p, report)
    assert report["ok"], report
    assert before == half and cleared == 0 and after == n - half, report
    assert report["reset_matters"], report
    assert counted == {point: counts.get(point, 0) for point in counted}, report
