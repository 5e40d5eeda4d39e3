"""cocotb benches for the generated Verilog: one TB class per kind of DUT.

Each TB owns its clock, reset and bus models. Parameters come from the launcher
(``sim/runner.py``) as JSON in the ``KFPGA_SIM`` environment variable; results go back as
JSON to the file it names. Every random source is seeded from those parameters and the seed is
logged.
"""

from __future__ import annotations

import json
import os
import random
import tomllib
from pathlib import Path
from typing import NamedTuple

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, Edge, Event, FallingEdge, ReadOnly, RisingEdge, Timer

from kfpga.ads8364 import CODE_MAX, CODE_MIN
from kfpga.analysis import float_run, rmse, sqnr_db
from kfpga.board import SYSTEM_PERIOD_NS
from kfpga.config import FilterConfig
from kfpga.hw.ads8364 import SampleLayout
from kfpga.hw.layouts import input_layout, output_layout
from kfpga.sim.ads8364 import ADS8364
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.sources import csv_source, scenario_source
from kfpga.sim.streams import StreamSink, StreamSource

__all__ = ["sim_params", "deadline", "write_results", "AdcPins", "CoreTB", "SystemTB", "FrontendTB", "load_config"]

ENV = "KFPGA_SIM"


def sim_params():
    return json.loads(os.environ.get(ENV, "{}"))


def deadline(per_sample_us, *, default_samples, fixed_us=2000):
    """``cocotb.test`` keyword arguments: a simulated-time limit from the run's sample count
    (``per_sample_us`` each, ten times or more what a sample takes), so a bench whose design
    stops answering fails instead of running on."""
    n = max(int(sim_params().get("samples", default_samples)), default_samples)
    return {"timeout_time": per_sample_us * n + fixed_us, "timeout_unit": "us"}


def load_config(params):
    text = params.get("config_toml")
    if not text:
        return FilterConfig()
    return FilterConfig.from_dict(tomllib.loads(text), source="config")


def write_results(params, report):
    path = params.get("results")
    if path:
        Path(path).write_text(json.dumps(report, indent=2, default=str))


def now_ns():
    return get_sim_time("ns")


class AdcPins:
    """The ADS8364 model (``sim/ads8364.py``) wired to the ``adc_*`` pins of a DUT.

    On every edge of an ADC pin the levels of all of them go to the model with the time (the
    model raises on a timing violation, which fails the test); the model's EOC and data events
    drive the inputs, at once or after a ``Timer``.
    """

    def __init__(self, dut, adc):
        self.dut = dut
        self.adc = adc
        dut.adc_eoc_n.value = 1
        dut.adc_data.value = 0
        self.tasks = []

    def start(self):
        d = self.dut
        pins = {"clk": d.adc_clk, "hold_a": d.adc_hold_a_n, "hold_b": d.adc_hold_b_n, "hold_c": d.adc_hold_c_n,
                "reset": d.adc_reset_n, "wr": d.adc_wr_n, "cs": d.adc_cs_n, "addr": d.adc_addr, "rd": d.adc_rd_n}
        self.adc.adopt_levels({name: int(signal.value) for name, signal in pins.items()})
        for name, signal in pins.items():
            self.tasks.append(cocotb.start_soon(self._watch(name, signal)))

    async def _watch(self, pin, signal):
        # one watcher per pin, reporting only its own edge: a First() of all nine, or reading all
        # nine levels per edge, costs the simulators several times their own run time
        edge = Edge(signal)
        model_edge = self.adc.edge
        while True:
            await edge
            self._apply(model_edge(now_ns(), pin, int(signal.value)))

    def _apply(self, events):
        for t, name, value in events:
            delay = t - now_ns()
            if delay <= 0:
                self._drive(name, value)
            else:
                cocotb.start_soon(self._later(delay, name, value))

    async def _later(self, delay, name, value):
        await Timer(delay, unit="ns")
        self._drive(name, value)

    def _drive(self, name, value):
        if name == "eoc":
            self.dut.adc_eoc_n.value = value
        else:  # the bus: a code, or None when nobody drives it (modelled as 0)
            self.dut.adc_data.value = 0 if value is None else value & 0xFFFF

    def stop(self):
        for task in self.tasks:
            task.cancel()


def make_source(params, count):
    """The analog source named by the parameters (a scenario or a CSV replay), seeded."""
    glitches = {}
    if params.get("glitch"):
        # full-scale spikes on the filtered channels at a few conversions
        rng = random.Random(params["seed"])
        for k in rng.sample(range(5, max(count, 10)), min(5, max(count - 5, 1))):
            glitches[k] = (params.get("channel", 0) if not params.get("six") else rng.randrange(6),
                           rng.choice([CODE_MAX, CODE_MIN]))
    config = load_config(params)
    adc = params.get("adc") or [params.get("channel") or 0]
    if params.get("csv"):
        source = csv_source(params["csv"], clip=params.get("clip", False), config=config, adc=adc)
        source.glitches = glitches
        return source
    return scenario_source(params.get("scenario", "sine"), count, params["seed"], config.params, glitches=glitches,
                           config=config, adc=adc)


class CoreTB:
    """A filter core alone: stream source on ``i``, stream sink on ``o``, scoreboard."""

    def __init__(self, dut, params):
        self.dut = dut
        self.params = params
        self.config = load_config(params)
        self.variant = params["variant"]
        self.channels = int(params.get("channels", 1))
        seed = params["seed"]
        dut._log.info(f"seed {seed}")
        self.source = StreamSource(dut, "i", dut.clk, input_layout(self.config, self.channels),
                                   rng=random.Random(seed), p_idle=params.get("p_idle", 0.0))
        self.sink = StreamSink(dut, "o", dut.clk, output_layout(self.config, self.channels),
                               rng=random.Random(seed + 1), p_ready=params.get("p_ready", 1.0))
        self.scoreboard = Scoreboard(self.config, self.variant)
        Clock(dut.clk, SYSTEM_PERIOD_NS, unit="ns").start()

    async def reset(self):
        self.dut.rst.value = 1
        await ClockCycles(self.dut.clk, 3)
        self.dut.rst.value = 0
        await RisingEdge(self.dut.clk)


class FrontendTB:
    """Clock divider + ADS8364 controller with the ADC model on its pins."""

    def __init__(self, dut, params, source):
        self.dut = dut
        self.adc = ADS8364(source)
        self.pins = AdcPins(dut, self.adc)
        self.sink = StreamSink(dut, "o", dut.clk, SampleLayout, rng=random.Random(params["seed"]),
                               p_ready=params.get("p_ready", 1.0))
        Clock(dut.clk, SYSTEM_PERIOD_NS, unit="ns").start()

    async def reset(self):
        self.dut.rst.value = 1
        await ClockCycles(self.dut.clk, 3)
        self.dut.rst.value = 0


def _per_channel_float(config, variant, channels, codes, field):
    """The float filter's ``field`` for each sample, each channel filtered on its own from reset
    (``codes`` an array, or ``{input: array}``)."""
    out = np.zeros(len(channels))
    for ch in np.unique(channels):
        idx = np.flatnonzero(channels == ch)
        part = {k: v[idx] for k, v in codes.items()} if isinstance(codes, dict) else codes[idx]
        out[idx] = float_run(config, variant, part)[field]
    return out


class Update(NamedTuple):
    """The samples of one filter update: when the last came, its channel state, the codes
    (an int, or ``{input: code}``), the conversion."""

    time_ns: float
    channel: int
    codes: object
    conversion: int


def updates_of(reads, config, adc):
    """The updates the ADC reads make: one per read for a one-input filter; for several inputs
    one per conversion, of the reads of the inputs' channels ``adc``, when the last of them is
    read (the hardware's order). Its channel is the first input's ADC channel."""
    if len(config.inputs) == 1:
        return [Update(r.time_ns, r.channel, r.code, r.conversion) for r in reads]
    out, pending, conversion = [], {}, None
    last = max(adc)
    for r in reads:
        if r.conversion != conversion:
            pending, conversion = {}, r.conversion
        if r.channel in adc:
            pending[config.inputs[adc.index(r.channel)]] = r.code
        if r.channel == last and len(pending) == len(adc):
            out.append(Update(r.time_ns, adc[0], dict(pending), r.conversion))
    return out


class SystemTB:
    """The whole design: ADC model on the pins, output-port monitor, scoreboard.

    Every read the ADC model served is an input of the filter; every ``out_valid`` strobe is an
    output. A reset splits both at its time: estimates in flight at the reset are dropped and
    the model restarts from x0/P0, as the hardware does.
    """

    def __init__(self, dut, params, *, expected_conversions):
        self.dut = dut
        self.params = params
        self.config = load_config(params)
        self.variant = params["variant"]
        self.six = bool(params.get("six"))
        self.field = params.get("out_field") or self.config.spec.default_output
        self.adc_channels = list(params.get("adc") or [params.get("channel") or 0])
        dut._log.info(f"seed {params['seed']}")
        self.source = make_source(params, expected_conversions)
        self.adc = ADS8364(self.source)
        self.pins = AdcPins(dut, self.adc)
        self.outputs = []  # (time_ns, channel, out_data, sticky overflow flag)
        self.resets = []  # times rst_n fell
        self._want = 0
        self._enough = Event()
        self.progress_file = Path(params["results"] + ".progress") if params.get("results") else None
        dut.rst_n.value = 1
        Clock(dut.clk50, SYSTEM_PERIOD_NS, unit="ns").start()

    async def reset(self, cycles=4):
        self.resets.append(now_ns())
        self.dut.rst_n.value = 0
        await ClockCycles(self.dut.clk50, cycles)
        self.dut.rst_n.value = 1

    def start(self):
        self.pins.start()
        cocotb.start_soon(self._monitor())

    async def _monitor(self):
        rising = RisingEdge(self.dut.out_valid)
        falling = FallingEdge(self.dut.out_valid)
        step = max(self.params.get("samples", 1) // 100, 1)
        while True:
            await rising
            await ReadOnly()
            self.outputs.append((now_ns(), int(self.dut.out_channel.value), self.dut.out_data.value.to_signed(),
                                 int(self.dut.out_overflow.value)))
            n = len(self.outputs)
            if self.progress_file and n % step == 0:
                self.progress_file.write_text(str(n))
            if n >= self._want:
                self._enough.set()
            await falling

    async def wait_outputs(self, count):
        """Run until ``count`` estimates have come out."""
        self._want = count
        if len(self.outputs) >= count:
            return
        self._enough.clear()
        await self._enough.wait()

    def updates(self):
        """The filter updates of the reads so far (:func:`updates_of`)."""
        return updates_of(self.adc.reads, self.config, self.adc_channels)

    def _error_vs_float(self):
        """The hardware's output field against the float filter (and the truth) on the same samples."""
        ups = self.updates()
        n = min(len(self.outputs), len(ups))
        if n == 0:
            return {}
        reads = ups[:n]
        channels = np.array([r.channel for r in reads])
        if isinstance(reads[0].codes, dict):
            codes = {k: np.array([r.codes[k] for r in reads], dtype=np.int64) for k in self.config.inputs}
            measured = self.config.spec.measured_input(self.config.params)
            raw = codes[measured] if measured is not None else None
        else:
            codes = raw = np.array([r.codes for r in reads], dtype=np.int64)
        fmt = self.config.output_format(self.field)
        hw = fmt.to_float([o[2] for o in self.outputs[:n]])
        flt = _per_channel_float(self.config, self.variant, channels, codes, self.field)
        out = {
            "max_abs_hw_minus_float": float(np.max(np.abs(hw - flt))),
            "max_abs_hw_minus_float_lsb": float(np.max(np.abs(hw - flt)) / fmt.lsb),
            "sqnr_db": sqnr_db(flt, hw),
        }
        truth = getattr(self.source, "truth", None)
        if truth is not None:
            k = np.array([r.conversion for r in reads]) % truth.shape[1]
            t = truth[channels, k]
            # each channel settles on its own: skip the first samples of every channel, not of the
            # interleaved stream (which would leave five channels' starts in the figures)
            rank = np.zeros(n, dtype=int)
            for ch in np.unique(channels):
                idx = np.flatnonzero(channels == ch)
                rank[idx] = np.arange(len(idx))
            settle = min(100, int(np.min(np.bincount(channels)[np.unique(channels)])) // 10)
            w = rank >= settle
            out.update({"rmse_raw": rmse(raw[w], t[w]) if raw is not None else None, "rmse_float": rmse(flt[w], t[w]),
                        "rmse_hw": rmse(hw[w], t[w]), "settle_per_channel": settle})
        return out

    def report(self, wall_s, *, pending_allowed=2):
        """Scoreboard over everything so far, plus flags and speed."""
        sb = Scoreboard(self.config, self.variant)
        bounds = [*self.resets, float("inf")]
        reads = self.updates()
        outs = self.outputs
        i = j = 0
        for k, bound in enumerate(bounds):
            if k:
                sb.reset()
            while i < len(reads) and reads[i].time_ns < bound:
                sb.add_input(reads[i].channel, reads[i].codes)
                i += 1
            while j < len(outs) and outs[j][0] < bound:
                _, ch, value, sticky = outs[j]
                sb.add_output(channel=ch, sticky=sticky, **{self.field: value})
                j += 1
        result = sb.check(pending_allowed=pending_allowed)
        if not self.resets:
            result.update(self._error_vs_float())
        result.update({
            "samples": result["compared"],
            "conversions": self.adc.conversions,
            "eoc_pulses": self.adc.eoc_pulses,
            "eocs_dropped": self.adc.eocs_dropped,
            "timeout_flag": int(self.dut.out_timeout.value),
            "overflow_flag": int(self.dut.out_overflow.value),
            "resets": len(self.resets),
            "sim_time_us": now_ns() / 1000.0,
            "wall_s": wall_s,
            "samples_per_s": result["compared"] / wall_s if wall_s > 0 else None,
        })
        return result


