"""``kfpga explore``: every design the tool can build for a config, and the one it chooses.

A filter's update runs on its parallel core (the update spread over L register stages, channels
interleaved; L from 1 to what the core allows) or on the folded core (one operation at a
time; every filter has it). Each candidate is synthesised with Yosys (``hw/resources.py``) for
its logic cells, multipliers, block-memory bits and estimated Fmax on the -8 part, and its
throughput comes from its cycles per update. The board needs ``sample_rate_hz`` updates a second
on every channel at ``clock_hz`` (without a stated rate nothing: the ADC then converts as fast
as the core takes its samples).

The choice (``--architecture auto``): the cheapest candidate (logic cells, then multipliers,
then M4K bits) whose estimated Fmax is at least :data:`FMAX_MARGIN` times the clock and whose
throughput covers the need; when none has that margin, the cheapest that meets the clock itself
(and the caller warns); when none meets the clock, none. A design past the EP2C20's logic
elements, multipliers or M4K blocks is never chosen. The architecture changes no integer:
every candidate computes the model's.

Estimates are cached by the Verilog's content under the user's cache folder, so a second run of
the same design costs no synthesis.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from kfpga.hw.cores import make_core

__all__ = ["Candidate", "candidates", "choose", "bus_cost", "FMAX_MARGIN", "MAX_STAGES", "BUS_GOAL_LOGIC_CELLS"]

#: The estimate must beat the clock by this factor: it is an estimate (FloPoCo's delays, no
#: place and route), and Quartus's router adds what the estimate cannot see.
FMAX_MARGIN = 1.25
#: Pipeline stages tried at most.
MAX_STAGES = 8
#: The register bus's goal: logic cells over the same folded core without it.
BUS_GOAL_LOGIC_CELLS = 150


@dataclass
class Candidate:
    """One design: its architecture and figures."""

    architecture: str
    stages: int | None
    channels: int
    logic_cells: int
    mul18: int
    memory_bits: int
    fmax_mhz: float
    cycles_per_update: int
    updates_per_s: float  # at the clock, over all channels together
    meets_clock: bool  # with the margin
    meets_rate: bool
    worst_path: str = ""
    chosen: bool = False
    clock_mhz: float = 50.0
    m4k_blocks: int = 0

    @property
    def over_device(self):
        """What passes the EP2C20's capacity, as ``"55 of 52 M4K blocks"`` (empty: it fits)."""
        from kfpga.hw.resources import EP2C20

        over = [f"{have} of {cap} {what}" for have, cap, what in (
            (self.logic_cells, EP2C20["logic_elements"], "logic elements"), (self.mul18, EP2C20["mul18"], "multipliers"),
            (self.m4k_blocks, EP2C20["m4k_blocks"], "M4K blocks")) if have > cap]
        return ", ".join(over)

    @property
    def fits(self):
        return not self.over_device

    @property
    def within_clock(self):
        """Estimated at least at the clock itself (no margin)."""
        return self.fmax_mhz >= self.clock_mhz

    @property
    def meets(self):
        return self.meets_clock and self.meets_rate and self.fits

    @property
    def label(self):
        return self.architecture + ("" if self.stages is None else f", {self.stages} stage{'s' if self.stages > 1 else ''}")

    def as_dict(self):
        return {**asdict(self), "meets": self.meets, "within_clock": self.within_clock, "fits": self.fits,
                "label": self.label}


def _cache_dir():
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "kfpga" / "estimates"


def _estimator_source():
    """The estimator's own source: a change to how figures are counted makes every cached one stale."""
    from kfpga.hw import resources, timing

    return b"".join(Path(module.__file__).read_bytes() for module in (resources, timing))


def _estimate(core, name):
    """Yosys's figures of ``core`` (cached by the Verilog's content)."""
    from kfpga.hw.generate import to_verilog
    from kfpga.hw.resources import estimate

    text = to_verilog(core, name)
    digest = hashlib.sha256(text.encode() + _estimator_source()).hexdigest()[:24]
    cache = _cache_dir() / f"{digest}.json"
    try:
        return json.loads(cache.read_text())
    except (OSError, ValueError):
        pass
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}.v"
        path.write_text(text)
        result = estimate(path, name)
    keep = {k: result[k] for k in ("logic_cells", "mul18", "memory_bits", "m4k_blocks", "fmax_mhz_estimate",
                                   "worst_path_ns")}
    path = result.get("worst_path") or {}
    keep["worst_path"] = f"{path.get('start', '?')} -> {path.get('end', '?')}" if path else ""
    try:
        cache.parent.mkdir(parents=True, exist_ok=True)
        cache.write_text(json.dumps(keep))
    except OSError:
        pass  # no cache folder: estimate again next time
    return keep


def _designs(config, variant, channels, missing=False, bus=None):
    """``[(architecture, stages, core)]``: every design of ``variant`` with ``channels`` states (with
    ``missing`` or ``bus``, the folded core's alone: the parallel cores have neither)."""
    from kfpga.hw.generate import figures_only

    spec = config.spec
    out = []
    options = {**({"missing": True} if missing else {}), **({"bus": bus} if bus else {})}
    for architecture in spec.architectures(variant, config.params):
        if architecture == "folded":
            out.append((architecture, None, figures_only(make_core(config, variant, channels=channels,
                                                                        architecture=architecture, **options))))
            continue
        if options:
            continue
        try:
            default = figures_only(make_core(config, variant, channels=channels, architecture=architecture))
        except ValueError:
            continue  # the parallel core does not hold this many channel states
        if not hasattr(default, "stages"):
            out.append((architecture, None, default))  # its figures read; built again when estimated
            continue
        for stages in range(1, MAX_STAGES + 1):
            try:
                core = make_core(config, variant, channels=channels, architecture=architecture, stages=stages)
            except ValueError:
                continue
            out.append((architecture, stages, figures_only(core)))
    return out


def candidates(config, variant, *, channels=1, clock_hz=50e6, need_hz, progress=None, missing=False, bus=None):
    """Every design with its figures; ``need_hz`` updates a second over all channels together
    (``missing``, ``bus``: the folded core with them)."""
    out = []
    designs = _designs(config, variant, channels, missing, bus)
    for i, (architecture, stages, core) in enumerate(designs):
        if progress:
            progress(i, len(designs), architecture + ("" if stages is None else f", {stages} stages"))
        est = _estimate(core, "kfpga_core")
        interleaved = min(channels, stages) if stages else 1  # a loop takes a channel per stage in turn
        updates = clock_hz * interleaved / core.cycles_per_update
        out.append(Candidate(architecture, stages, channels, est["logic_cells"], est["mul18"], est["memory_bits"],
                             est["fmax_mhz_estimate"], core.cycles_per_update, updates,
                             est["fmax_mhz_estimate"] >= FMAX_MARGIN * clock_hz / 1e6, updates >= need_hz,
                             est["worst_path"], clock_mhz=clock_hz / 1e6, m4k_blocks=est["m4k_blocks"]))
    return out


def choose(found):
    """The cheapest candidate that fits the device and meets the clock with the margin and the
    rate; else the cheapest that fits and meets the clock itself and the rate; marked ``chosen``.
    ``None`` when no candidate that fits meets the clock and the rate."""
    def cost(c):
        return c.logic_cells, c.mul18, c.memory_bits

    ok = [c for c in found if c.meets] or [c for c in found if c.within_clock and c.meets_rate and c.fits]
    if not ok:
        return None
    best = min(ok, key=cost)
    best.chosen = True
    return best


def bus_cost(config, variant, *, channels=1, missing=False, bus):
    """What the register bus ``bus`` costs the folded core: its figures with and without it (the
    programmable settings and the slave together), against :data:`BUS_GOAL_LOGIC_CELLS`."""
    from kfpga.hw.generate import figures_only

    plain = figures_only(make_core(config, variant, channels=channels, architecture="folded", missing=missing))
    with_bus = figures_only(make_core(config, variant, channels=channels, architecture="folded",
                                           missing=missing, bus=bus))
    a, b = _estimate(plain, "kfpga_core"), _estimate(with_bus, "kfpga_core")
    return {"bus": bus, "logic_cells": b["logic_cells"] - a["logic_cells"],
            "m4k_blocks": b["m4k_blocks"] - a["m4k_blocks"], "base_logic_cells": a["logic_cells"],
            "logic_cells_with_bus": b["logic_cells"], "fmax_mhz_estimate": b["fmax_mhz_estimate"],
            "worst_path": b["worst_path"], "goal_logic_cells": BUS_GOAL_LOGIC_CELLS,
            "within_goal": b["logic_cells"] - a["logic_cells"] <= BUS_GOAL_LOGIC_CELLS}
