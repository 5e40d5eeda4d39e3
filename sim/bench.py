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
from pathlib import Path

import cocotb
from cocotb.clock import Clock
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, Edge, Event, FallingEdge, ReadOnly, RisingEdge, Timer

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.hw.ads8364 import SampleLayout
from kfpga.hw.layouts import input_layout, output_layout
from kfpga.sim.ads8364 import ADS8364
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.streams import StreamSink, StreamSource
from kfpga.sim.system import SystemRecords, load_config, make_source, updates_of

__all__ = ["sim_params", "deadline", "write_results", "AdcPins", "CoreTB", "SystemTB", "FrontendTB", "load_config",
           "make_source", "updates_of"]

ENV = "KFPGA_SIM"


def sim_params():
    return json.loads(os.environ.get(ENV, "{}"))


def deadline(per_sample_us, *, default_samples, fixed_us=2000):
    """``cocotb.test`` keyword arguments: a simulated-time limit from the run's sample count
    (``per_sample_us`` each, ten times or more what a sample takes), so a bench whose design
    stops answering fails instead of running on."""
    n = max(int(sim_params().get("samples", default_samples)), default_samples)
    return {"timeout_time": per_sample_us * n + fixed_us, "timeout_unit": "us"}


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


class SystemTB(SystemRecords):
    """The whole design with the Python ADC model on the pins and an output-port monitor; the
    records and their check are :class:`~kfpga.sim.system.SystemRecords`'."""

    def __init__(self, dut, params, *, expected_conversions):
        self._setup(dut, params, expected_conversions)
        self.adc = ADS8364(self.source)
        self.pins = AdcPins(dut, self.adc)
        self._want = 0
        self._enough = Event()
        dut.rst_n.value = 1
        Clock(dut.clk50, SYSTEM_PERIOD_NS, unit="ns").start()

    def _setup(self, dut, params, expected_conversions):
        self.dut = dut
        dut._log.info(f"seed {params['seed']}")
        self._setup_records(params, expected_conversions)
        self.progress_file = Path(params["results"] + ".progress") if params.get("results") else None

    async def reset(self, cycles=4):
        self.resets.append(now_ns())
        self.dut.rst_n.value = 0
        await ClockCycles(self.dut.clk50, cycles)
        self.dut.rst_n.value = 1

    def start(self):
        self.pins.start()
        cocotb.start_soon(self._monitor())
        cocotb.start_soon(self._static_pins())

    async def _static_pins(self):
        """(BYTE, ADD, WR) at every read (RD falling): pins the ADC model does not watch."""
        self.pin_levels = []
        falling = FallingEdge(self.dut.adc_rd_n)
        while True:
            await falling
            self.pin_levels.append((int(self.dut.adc_byte.value), int(self.dut.adc_add.value),
                                    int(self.dut.adc_wr_n.value)))

    async def _monitor(self):
        self.valid_high_ns = []
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
            risen = self.outputs[-1][0]
            await falling
            self.valid_high_ns.append(now_ns() - risen)  # a one-cycle strobe per estimate

    async def wait_outputs(self, count):
        """Run until ``count`` estimates have come out."""
        self._want = count
        if len(self.outputs) >= count:
            return
        self._enough.clear()
        await self._enough.wait()

    def report(self, wall_s, *, pending_allowed=2):
        """The records' check (:meth:`SystemRecords.report`) with the design's flags as they are now."""
        return super().report(wall_s, timeout_flag=int(self.dut.out_timeout.value),
                              overflow_flag=int(self.dut.out_overflow.value), sim_time_us=now_ns() / 1000.0,
                              pending_allowed=pending_allowed)
