"""The whole design against the model: the records of a run and their check, and the fast
regressions, where the design and the Verilog ADS8364 model run in the simulator alone.

:class:`SystemRecords` holds what a whole-design run produced, in one form for both ways of
running it: the reads the ADC served (each an input of the filter) and the estimates on the
output port. Its :meth:`~SystemRecords.report` runs the scoreboard (every estimate against the
bit-accurate model) and the figures against float and the truth.

The cocotb bench (``sim/test_top.py``, :class:`kfpga.sim.bench.SystemTB`) runs the ADC as the
Python model, reacting to every pin edge: the way to reset at a chosen instant or drop an EOC.
The fast regressions (:func:`build`, :func:`run`) run ``kfpga_cosim`` (``sim/hdl.py``): the
generated top, the Verilog ADS8364 model with every datasheet timing check, and file I/O, with
the clock in the simulator (a C++ loop on Verilator, a Verilog clock on Icarus). Python writes
the codes of every conversion before the run and reads the ADC's reads and the estimates after
it. No Python runs per clock edge: this is what makes them fast.
"""

from __future__ import annotations

import collections
import hashlib
import os
import random
import shutil
import subprocess
import threading
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import numpy as np

from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.config import FilterConfig
from kfpga.flows.analysis import float_run, rmse, sqnr_db
from kfpga.hw.cores import make_core
from kfpga.sim.ads8364 import Read
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.sources import csv_source, scenario_source

__all__ = ["make_source", "Update", "updates_of", "conversions_for", "SystemRecords", "SystemBuild", "build", "run",
           "SystemRunFailed", "cycles_allowed"]

#: Codes from the truth beyond which an estimate counts as hit by a glitch, when no pre-filter
#: states its own bound: far beyond the scenarios' noise, far below a full-scale glitch.
GLITCH_BOUND = 500.0


def load_config(params, key="config_toml"):
    import tomllib

    text = params.get(key)
    if not text:
        return FilterConfig()
    # a bench of deliberately narrow formats (the mutation runs') says so: their ranges are not met
    return FilterConfig.from_dict(tomllib.loads(text), source="config", check_ranges=params.get("check_ranges", True))


def load_prefilter(params):
    """The pre-filter's config of a run (``prefilter_toml``), or ``None``."""
    return load_config(params, "prefilter_toml") if params.get("prefilter_toml") else None


def make_source(params, count):
    """The analog source named by the parameters (a scenario or a CSV replay), seeded."""
    glitches = {}
    if params.get("glitch"):
        # full-scale spikes on the filtered channels at a few conversions (5 unless told)
        rng = random.Random(params["seed"])
        wanted = int(params.get("glitches") or 5)
        for k in rng.sample(range(5, max(count, 10)), min(wanted, max(count - 5, 1))):
            glitches[k] = (params.get("channel", 0) if not params.get("six") else rng.randrange(6),
                           rng.choice([CODE_MAX, CODE_MIN]))
    config = load_config(params)
    adc = params.get("adc") or [params.get("channel") or 0]
    if params.get("scenario") == "stress":  # every code bit and both extremes, on every channel
        from kfpga.sim.sources import Source, stress_codes

        codes = np.stack([stress_codes(params["seed"] + 101 * c, max(count, 64)) for c in range(6)])
        return Source(codes, glitches=glitches, name=f"stress (seed {params['seed']})")
    sensors = params.get("sensors") or 1
    if params.get("csv"):
        source = csv_source(params["csv"], clip=params.get("clip", False), config=config, adc=adc, sensors=sensors)
        source.glitches = glitches
        return source
    return scenario_source(params.get("scenario") or config.spec.model.scenarios[0], count, params["seed"], config.params,
                           glitches=glitches, config=config, adc=adc, sensors=sensors)


def conversions_for(params, samples):
    """ADC conversions that make ``samples`` filter updates (one per conversion, or six in
    six-channel mode), with two to spare for the estimates in flight."""
    return samples // 6 + 2 if params.get("six") else samples + 2


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


def updates_of(reads, config, adc, sensors=1):
    """The updates the ADC reads make: one per read for a one-input filter (its channel the ADC
    channel, or with ``sensors`` on a multiplexer the select at the conversion's HOLD); for
    several inputs one per conversion, of the reads of the inputs' channels ``adc``, when the last
    of them is read (the hardware's order). Its channel is the first input's ADC channel."""
    if sensors > 1:
        return [Update(r.time_ns, r.sel, r.code, r.conversion) for r in reads]
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


def _settled(channels):
    """``(mask, settle)``: the estimates past each channel's first ``settle`` (each channel
    settles on its own from reset: skipping the first samples of the interleaved stream would
    leave five channels' starts in the figures)."""
    rank = np.zeros(len(channels), dtype=int)
    for ch in np.unique(channels):
        idx = np.flatnonzero(channels == ch)
        rank[idx] = np.arange(len(idx))
    settle = min(100, int(np.min(np.bincount(channels)[np.unique(channels)])) // 10)
    return rank >= settle, settle


class SystemRecords:
    """What a whole-design run produced: the reads the ADC served, the estimates on the output
    port, the resets; checked against the model by :meth:`report`.

    Every read is an input of the filter (:func:`updates_of` groups them into updates); every
    estimate an output. A reset splits both at its time: estimates in flight at the reset are
    dropped and the model restarts from x0/P0, as the hardware does.
    """

    def _setup_records(self, params, expected_conversions):
        self.params = params
        self.config = load_config(params)
        self.prefilter = load_prefilter(params)
        self.variant = params["variant"]
        self.six = bool(params.get("six"))
        self.field = params.get("out_field") or self.config.spec.model.default_output
        self.adc_channels = list(params.get("adc") or [params.get("channel") or 0])
        self.sensors = params.get("sensors") or 1
        self.source = make_source(params, expected_conversions)
        self.outputs = []  # (time_ns, channel, out_data, sticky overflow flag)
        self.resets = []  # times rst_n fell

    def updates(self):
        """The filter updates of the reads so far (:func:`updates_of`), computed once per count."""
        cached = getattr(self, "_updates", None)
        if cached is None or cached[0] is not self.adc.reads or cached[1] != len(self.adc.reads):
            self._updates = (self.adc.reads, len(self.adc.reads), updates_of(self.adc.reads, self.config,
                                                                              self.adc_channels, self.sensors))
        return self._updates[2]

    def mux_errors(self):
        """Reads whose multiplexer select at the HOLD was not the sensor whose turn it was (the
        reads since reset, counted modulo the sensors)."""
        bounds = [*self.resets, float("inf")]
        errors, k, index = 0, 0, 0
        for read in self.adc.reads:
            while read.time_ns >= bounds[k]:
                k, index = k + 1, 0
            errors += read.sel != index % self.sensors
            index += 1
        return errors

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
        if self.prefilter is not None:  # the float filter gets what the core got: the pre-filter's words
            codes = Scoreboard(self.config, self.variant, prefilter=self.prefilter).prefiltered(codes, channels)
        fmt = self.config.output_format(self.field)
        hw = fmt.to_float([o[2] for o in self.outputs[:n]])
        flt = _per_channel_float(self.config, self.variant, channels, codes, self.field)
        out = {
            "max_abs_hw_minus_float": float(np.max(np.abs(hw - flt))),
            "max_abs_hw_minus_float_lsb": float(np.max(np.abs(hw - flt)) / fmt.lsb),
            "sqnr_db": sqnr_db(flt, hw),
        }
        t = self._truth_of(reads, channels)
        if t is not None:
            w, settle = _settled(channels)
            out.update({"rmse_raw": rmse(raw[w], t[w]) if raw is not None else None, "rmse_float": rmse(flt[w], t[w]),
                        "rmse_hw": rmse(hw[w], t[w]), "settle_per_channel": settle})
        return out

    def _truth_of(self, reads, channels):
        """The truth of each estimate of ``reads`` (``None`` for a source without one): its
        conversion's, as many conversions before as the pre-filter delays each sample."""
        truth = getattr(self.source, "truth", None)
        if truth is None:
            return None
        late = self.prefilter.spec.hardware.prefilter.delay if self.prefilter is not None else 0
        return truth[channels, np.maximum(np.array([r.conversion for r in reads]) - late, 0) % truth.shape[1]]

    def glitch_figures(self):
        """The injected ADC glitches of a one-input filter's run, counted where they go: in the
        reads; in the pre-filter's words (its bit-accurate model on the same reads: the estimates
        equal the model chain's, so these are the hardware's); and in the estimates, those further
        than ``bound`` (the pre-filter's own, or :data:`GLITCH_BOUND`) from the truth."""
        glitches = getattr(self.source, "glitches", {})
        ups = self.updates()
        n = min(len(self.outputs), len(ups))
        if not glitches or n == 0 or isinstance(ups[0].codes, dict):
            return {}
        reads = ups[:n]
        hits = np.array([glitches.get(r.conversion, (None,))[0] == r.channel for r in reads])
        pre = None if self.prefilter is None else self.prefilter.spec.hardware.prefilter
        bound = pre.bound(self.prefilter.params) if pre is not None else GLITCH_BOUND
        out = {"glitches_injected": len(glitches), "glitches_in_reads": int(hits.sum()), "glitch_bound": bound}
        channels = np.array([r.channel for r in reads])
        clean = np.array([self.source.codes[r.channel, r.conversion % self.source.codes.shape[1]] for r in reads])
        if self.prefilter is not None:
            words = Scoreboard(self.config, self.variant, prefilter=self.prefilter).prefiltered(
                np.array([r.codes for r in reads], dtype=np.int64), channels)
            left = 0
            for ch in np.unique(channels):
                idx = np.flatnonzero(channels == ch)
                # word j of a channel decides its read j - delay
                delay = pre.delay
                left += int(np.sum(np.abs(words[idx][delay:] - clean[idx][:-delay]) > bound)) if len(idx) > delay else 0
            out["glitches_after_prefilter"] = left
        t = self._truth_of(reads, channels)
        if t is not None:
            fmt = self.config.output_format(self.field)
            hw = fmt.to_float([o[2] for o in self.outputs[:n]])
            settled, _ = _settled(channels)
            out["estimates_off_by_more_than_bound"] = int(np.sum((np.abs(hw - t) > bound) & settled))
        return out

    def report(self, wall_s, *, timeout_flag, overflow_flag, sim_time_us, pending_allowed=2):
        """Scoreboard over everything so far, plus the design's flags and the speed."""
        sb = Scoreboard(self.config, self.variant, prefilter=self.prefilter)
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
        if self.sensors > 1:  # the select takes each sensor in turn from reset: read k is sensor k mod N
            result["mux_errors"] = self.mux_errors()
            result["ok"] = result["ok"] and result["mux_errors"] == 0
        if not self.resets:
            result.update(self._error_vs_float())
            result.update(self.glitch_figures())
        result.update({
            "samples": result["compared"],
            "conversions": self.adc.conversions,
            "eoc_pulses": self.adc.eoc_pulses,
            "eocs_dropped": self.adc.eocs_dropped,
            "timeout_flag": int(timeout_flag),
            "overflow_flag": int(overflow_flag),
            "resets": len(self.resets),
            "sim_time_us": sim_time_us,
            "wall_s": wall_s,
            "samples_per_s": result["compared"] / wall_s if wall_s > 0 else None,
        })
        return result


# -- the fast regressions ----------------------------------------------------------------------

DEFAULT_ROOT = Path("build") / "sim"


class SystemRunFailed(AssertionError):
    """A fast regression stopped before its estimates: a timing violation, the codes ran out,
    the cycle limit, or the simulator failed; the message says which."""


@dataclass
class SystemBuild:
    simulator: str
    build_dir: Path
    command: list  # the simulation's command line, before the plusargs
    config: FilterConfig
    variant: str
    six: bool
    channel: int | None
    prefilter: FilterConfig | None = None
    architecture: str | None = None
    stages: int | None = None
    sensors: int = 1

    @property
    def core_options(self):
        return {"architecture": self.architecture, **({} if self.stages is None else {"stages": self.stages})}


def write_sources(out_dir, config, *, variant, six=False, channel=None, prefilter=None, architecture=None,
                  stages=None, sensors=1):
    """The generated top, the ADC model and ``kfpga_cosim`` (and its clock top) in ``out_dir``."""
    from kfpga.hw.generate import TOP_NAME, write_top
    from kfpga.hw.top import out_width
    from kfpga.sim import hdl

    out_dir = Path(out_dir)
    _, top = write_top(out_dir, config, variant=variant, six_channel=six, channel=channel, prefilter=prefilter,
                       architecture=architecture, stages=stages, sensors=sensors)
    hdl.write_model(out_dir)
    (out_dir / f"{hdl.COSIM_NAME}.v").write_text(hdl.cosim_wrapper(TOP_NAME, out_width(config, top.out_field),
                                                                   sensors))
    (out_dir / f"{hdl.COSIM_NAME}_clock.v").write_text(hdl.clock_top(hdl.COSIM_NAME))
    return sorted(out_dir.glob("*.v"))


def compile_cached(simulator, tag, write, top, *, root=DEFAULT_ROOT):
    """Compile the Verilog that ``write(folder)`` writes (it returns the files) with ``top`` as the
    top level, cached by content under ``build/sim/<simulator>/<tag>-<hash>``; returns
    ``(build folder, command line)``.

    Verilator builds ``top`` with the C++ clock loop of ``cosim_main.cpp``; Icarus builds
    ``<top>_clock``, which the files must hold, around it.
    """
    from kfpga.hw.tools import iverilog_path, simulator_available, verilator_env, verilator_root
    from kfpga.sim.runner import file_lock

    ok, why = simulator_available(simulator)
    if not ok:
        raise FileNotFoundError(why)
    root = Path(root).resolve()
    staging = root / "src" / f"{tag}-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    files = write(staging)
    main = resources.files("kfpga.sim").joinpath("cosim_main.cpp").read_bytes()
    digest = hashlib.sha1(b"".join(f.read_bytes() for f in files) + main + simulator.encode()).hexdigest()[:10]
    build_dir = root / simulator / f"{tag}-{digest}"
    with file_lock(root / simulator / f".{tag}-{digest}.lock"):
        src = build_dir / "src"
        stamp = build_dir / ".built"
        if not stamp.exists():
            shutil.rmtree(build_dir / "obj", ignore_errors=True)
            src.mkdir(parents=True, exist_ok=True)
            for f in staging.iterdir():
                shutil.copy2(f, src / f.name)
            verilog = [str(src / f.name) for f in files if f.name != f"{top}_clock.v"]
            if simulator == "verilator":
                (src / "cosim_main.cpp").write_bytes(main)
                cmd = [str(verilator_root() / "bin" / "verilator"), "--cc", "--exe", "--build", "-O3", "--x-assign",
                       "fast", "--x-initial", "fast", "-Wno-fatal", "-Wno-lint", "-Wno-style", "--timescale", "1ns/1ps",
                       "--top-module", top, "-Mdir", str(build_dir / "obj"), "-j", str(os.cpu_count() or 1),
                       "-CFLAGS", f"-DKFPGA_TOP=V{top}", str(src / "cosim_main.cpp"), *verilog]
                env = verilator_env()
            else:
                cmd = [iverilog_path(), "-g2005", "-o", str(build_dir / "sim.vvp"), "-s", f"{top}_clock",
                       str(src / f"{top}_clock.v"), *verilog]
                env = None
            done = subprocess.run(cmd, capture_output=True, text=True, env=env)
            (build_dir / "build.log").write_text(done.stdout + done.stderr)
            if done.returncode:
                raise SystemRunFailed(f"{simulator}: building {top} failed (exit {done.returncode}):\n"
                                      + "\n".join((done.stdout + done.stderr).splitlines()[-30:]))
            stamp.write_text("ok")
    shutil.rmtree(staging, ignore_errors=True)
    if simulator == "verilator":
        return build_dir, [str(build_dir / "obj" / f"V{top}")]
    return build_dir, [str(Path(iverilog_path()).with_name("vvp")), "-n", str(build_dir / "sim.vvp")]


def build(simulator, *, config=None, variant=None, six=False, channel=None, prefilter=None, architecture=None,
          stages=None, sensors=1, root=DEFAULT_ROOT):
    """Generate and compile ``kfpga_cosim`` for ``simulator`` (cached by content under
    ``build/sim/<simulator>/system-<hash>``); returns a :class:`SystemBuild`. ``prefilter``: the
    config of a filter between the controller and the core; ``architecture``: the core's;
    ``sensors``: more than one on a multiplexer in front of the ADC."""
    from kfpga.sim import hdl

    config = FilterConfig() if config is None else config
    variant = variant or config.spec.default_variant
    build_dir, command = compile_cached(
        simulator, "system", lambda folder: write_sources(folder, config, variant=variant, six=six, channel=channel,
                                                          prefilter=prefilter, architecture=architecture,
                                                          stages=stages, sensors=sensors),
        hdl.COSIM_NAME, root=root)
    return SystemBuild(simulator, build_dir, command, config, variant, bool(six), channel, prefilter, architecture,
                       stages, sensors)


class _Records(SystemRecords):
    def __init__(self, params, expected_conversions):
        self._setup_records(params, expected_conversions)


def run(built, *, params, samples, on_progress=None, tag=None, timeout_s=None):
    """Run ``samples`` estimates through ``built``; returns the report of
    :meth:`SystemRecords.report` (``mismatches`` 0: bit-exact), with the run's figures.

    ``params`` as for the cocotb bench (variant, seed, scenario or csv, six, channel, adc,
    config_toml). Every conversion's codes are drawn before the run. Raises
    :class:`SystemRunFailed` when the run stops early, with the reason.
    """
    from kfpga.sim import hdl

    params = {**params, "variant": built.variant, "six": built.six, "samples": samples, "sensors": built.sensors}
    if "config_toml" not in params:
        params["config_toml"] = built.config.to_toml()
    if built.prefilter is not None:
        params["prefilter_toml"] = built.prefilter.to_toml()
    conversions = conversions_for(params, samples) + 8
    records = _Records(params, conversions)
    run_dir = built.build_dir / "runs" / f"{tag or 'run'}-{os.getpid()}"
    shutil.rmtree(run_dir, ignore_errors=True)
    run_dir.mkdir(parents=True)
    t0 = time.perf_counter()
    codes = np.array([records.source.next() for _ in range(conversions)], dtype=np.int64)
    hdl.write_codes(run_dir / "codes.hex", codes)
    max_cycles = cycle_budget(built, records, samples)
    step = max(samples // 100, 1)
    cmd = [*built.command, f"+samples={samples}", f"+max_cycles={max_cycles}", f"+progress={step}", f"+dir={run_dir}"]
    t1 = time.perf_counter()
    if timeout_s is None:  # wall seconds: ten times what the slower simulator needs, and then some,
        # per sample and per cycle allowed: at a real sample rate (100 Hz: 500,000 cycles a sample)
        # the cycles, not the samples, take the time (Verilator ran the 3-state tracker's whole
        # design at 1.1e-7 s a cycle)
        icarus = built.simulator == "icarus"
        timeout_s = 120 + samples * (0.07 if icarus else 0.001) + max_cycles * (1e-4 if icarus else 1e-6)
    returncode, tail = _simulate(cmd, run_dir, timeout_s, on_progress, built.simulator)
    sim_wall = time.perf_counter() - t1
    (run_dir / "sim.log").write_text("\n".join(tail) + "\n")
    summary_path = run_dir / "summary.txt"
    if returncode or not summary_path.exists() or not summary_path.read_text().strip():
        raise SystemRunFailed(f"{built.simulator}: the simulation ended without a summary (exit {returncode}):\n"
                              + "\n".join(tail))
    (n_out, n_reads, conv_done, eoc_pulses, errors, first_error, first_error_ns, _exhausted, overflow, timeout,
     cycles, time_ns, status) = (int(v) for v in summary_path.read_text().split())
    if status:
        why = hdl.STATUS.get(status, f"status {status}")
        detail = (f"{errors} violation(s), the first: {hdl.error_text(first_error, first_error_ns)}" if status == 1
                  else f"{conversions} conversions written" if status == 2
                  else f"{max_cycles} cycles, {n_out} of {samples} estimates out")
        raise SystemRunFailed(f"{built.simulator}: the run stopped at {time_ns} ns on {why}: {detail}")
    reads = hdl.read_log(run_dir / "reads.txt", 5)
    outputs = hdl.read_log(run_dir / "outputs.txt", 4)
    if len(reads) != n_reads or len(outputs) != n_out:
        raise SystemRunFailed(f"{built.simulator}: the logs hold {len(reads)} reads and {len(outputs)} estimates, the "
                              f"counters {n_reads} and {n_out}")
    records.adc = _AdcCounts([Read(float(t), ch, code, conv, sel) for t, ch, code, conv, sel in reads.tolist()],
                             conv_done, eoc_pulses)
    records.outputs = [(float(t), ch, v, sticky) for t, ch, v, sticky in outputs.tolist()]
    report = records.report(sim_wall, timeout_flag=timeout, overflow_flag=overflow, sim_time_us=time_ns / 1000.0)
    report.update({"simulator": built.simulator, "cycles": cycles, "reads": n_reads, "eoc_pulses": eoc_pulses,
                   "adc_errors": errors, "wall_total_s": time.perf_counter() - t0, "run_dir": str(run_dir),
                   "updates": len(records.updates())})
    return report


def _simulate(cmd, run_dir, timeout_s, on_progress, simulator):
    """Run the simulator's ``cmd`` in ``run_dir``, its progress lines to ``on_progress``, killed
    after ``timeout_s`` wall seconds; ``(exit code, the last 40 other lines)``."""
    tail = collections.deque(maxlen=40)
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=run_dir) as proc:
        watchdog = threading.Timer(timeout_s, proc.kill)
        watchdog.start()
        try:
            for line in proc.stdout:
                if line.startswith("progress "):
                    if on_progress:
                        on_progress(int(line.split()[1]))
                else:
                    tail.append(line.rstrip())
            proc.wait()
        finally:
            expired = not watchdog.is_alive() and proc.returncode is not None and proc.returncode < 0
            watchdog.cancel()
    if expired:
        raise SystemRunFailed(f"{simulator}: no end after {timeout_s:.0f} s; stopped")
    return proc.returncode, tail


def cycle_budget(built, records, samples):
    """System cycles a run of ``built`` may take before it is stopped (:func:`cycles_allowed`)."""
    return cycles_allowed(built.config, built.variant, samples, six=built.six, sensors=built.sensors,
                          reads=len(records.adc_channels), core_options=built.core_options)


def cycles_allowed(config, variant, samples, *, six=False, sensors=1, reads=1, core_options=None):
    """System cycles a run of ``samples`` estimates may take before it is stopped: generous, as a
    conversion with one read takes 230 system cycles, six reads 380 (for six estimates); a core
    slower than that (the folded core: hundreds of cycles an update) paces the reads, and gets
    twice its own; a conversion timer adds its cycles to each conversion."""
    from kfpga.hw.generate import figures_only

    base = 600 if reads > 1 or six else 300
    core = figures_only(make_core(config, variant, channels=6 if six else sensors, **(core_options or {})))
    estimates = 6 if six else 1  # per conversion
    timer = config.board.conversion_cycles(sensors) or 0  # the conversion timer's
    per_conversion = max(base, estimates * (2 * core.cycles_per_update + 60)) + timer
    return per_conversion * -(-samples // estimates) + 20000


class _AdcCounts(NamedTuple):
    reads: list
    conversions: int
    eoc_pulses: int
    eocs_dropped: int = 0
