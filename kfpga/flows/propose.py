"""``kfpga propose``: per-point word lengths for a model, searched against stated constraints.

Every point keeps the integer bits of its analysed range (the default formats'). Its fraction
bits are then trimmed one point at a time, widest first, as far as the constraints allow:

* the fixed RMSE of the main output against truth stays within ``budget`` of float's, either
  way, on every signal given; every other output, which has no truth, keeps its fixed - float
  difference small enough that, added to the float filter's own steady-state error (the
  spec's ``error_std``, from the Lyapunov equation of the gain), its RMSE stays within budget;
* nothing overflows on the full-scale stress stimulus (full-scale steps from a settled state,
  a full-scale sine);
* no dead band or limit cycle on noise-free inputs exceeds one input LSB (one ADC code);
* every constant and reset value is held within 1 % (the config check).

When the starting formats fail a constraint, every point first gets fraction bits added, one
at a time, until they pass. The objective orders the trimming: ``multipliers`` first brings
every multiplier operand down to the embedded multiplier's 18 bits where the constraints allow
(each operand above 18 bits costs a second multiplier piece per product), then trims register
bits; ``bits`` trims the widest points first, whatever they are. A search takes one model run
per candidate: the signal, the stress rows and the noise-free rows all go through the batched
model at once.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from kfpga.core.config import ConfigError, FilterConfig
from kfpga.core.fixed import QFormat
from kfpga.core.fixedmodel import FixedModel
from kfpga.core.formats import MULTIPLIER_BITS
from kfpga.flows.analysis import compare, limit_cycles
from kfpga.model.ranges import full_scale_stimulus

__all__ = ["Proposal", "propose", "OBJECTIVES"]

OBJECTIVES = ("multipliers", "bits")
MAX_GROW = 12  # fraction bits added to every point at most when the start fails


@dataclass
class Proposal:
    """The proposed config and how it was found."""

    config: FilterConfig
    start: FilterConfig
    bound: dict  # point -> the constraint that stopped its trimming
    metrics: dict  # the final check: rmse ratio, limit cycle, overflows
    evaluations: int
    seconds: float
    multipliers: tuple = (0, 0)  # (start, proposed) embedded multiplier pieces
    register_bits: tuple = (0, 0)
    notes: list = field(default_factory=list)


def _stress(config):
    """Full-scale stress rows for every input, as int64 codes (``(rows, n)`` or ``{input: rows}``)."""
    r = np.atleast_2d(np.asarray(config.params.R, dtype=np.float64))
    rows = np.clip(np.round(full_scale_stimulus(float(np.max(np.diag(r))))), -32768, 32767).astype(np.int64)
    names = config.inputs
    if len(names) == 1:
        return rows
    return {name: np.roll(rows, 997 * j, axis=1) for j, name in enumerate(names)}


class _Judge:
    """Checks one candidate against every constraint; counts the evaluations."""

    def __init__(self, config, variant, signals, budget, settle):
        self.params, self.filter, self.variant = config.params, config.filter, variant
        self.signals, self.budget, self.settle = signals, budget, settle
        self.stress = _stress(config)
        self.error_std = config.spec.error_std(config.params) if config.spec.error_std else None
        self.evaluations = 0
        self.tick = lambda: None

    def config(self, formats):
        return FilterConfig(filter=self.filter, params=self.params, formats=formats)

    def __call__(self, formats):
        """``(None, metrics)`` when ``formats`` pass, else ``(the constraint that failed, metrics)``."""
        self.evaluations += 1
        self.tick()
        try:
            cfg = self.config(formats)
            cfg.require_variant(self.variant)
        except ConfigError as exc:
            return f"range or precision: {exc}", {}
        metrics = {}
        over = FixedModel(cfg, variant=self.variant).run(self.stress).overflow_points
        hit = sorted(name for name, flags in over.items() if flags.any())
        if hit:
            return f"overflow on full-scale stress at {', '.join(hit)}", {}
        worst = 0.0
        for label, (truth, y) in self.signals.items():
            m = compare(cfg, self.variant, y, truth, settle=self.settle, limit_cycle=False).metrics
            if m["overflows"]:
                return f"overflow on {label}", {}
            ratio = m["rmse_fixed_over_float"]
            worst = max(worst, abs(ratio - 1.0))
            metrics[label] = ratio
            if abs(ratio - 1.0) > self.budget:
                return f"RMSE budget on {label} ({100 * (ratio - 1):+.2f} % of float)", metrics
            # the outputs without a truth: their fixed - float difference, added to the float
            # filter's own steady-state error (uncorrelated), must keep it within the budget
            for name, std in (self.error_std or {}).items():
                if name == m["field"] or name not in m["fields"]:
                    continue
                allowed = std * math.sqrt((1.0 + self.budget) ** 2 - 1.0)
                got = m["fields"][name]["rms_fixed_minus_float"]
                if got > allowed:
                    return (f"RMSE budget of {name} on {label} (fixed - float {got:.3g} rms, at most {allowed:.3g} "
                            f"against its float error {std:.3g})"), metrics
        lc = limit_cycles(cfg, self.variant)
        metrics["limit_cycle_lsb"], metrics["dead_band_lsb"] = lc["limit_cycle_lsb"], lc["dead_band_lsb"]
        if max(lc["limit_cycle_lsb"], lc["dead_band_lsb"]) > 1.0:
            return (f"limit cycle {lc['limit_cycle_lsb']:.2f} LSB, dead band {lc['dead_band_lsb']:.2f} LSB "
                    "(at most 1 input LSB)"), metrics
        metrics["worst_rmse_change"] = worst
        return None, metrics


def _groups(config):
    """Points that share one format (``same_as``) are trimmed together: ``{leader: [members]}``."""
    points = config.spec.points
    groups = {}
    for name in config.formats:
        leader = points[name].same_as or name
        groups.setdefault(leader, []).append(name)
    return groups


def _with_frac(formats, members, frac):
    out = dict(formats)
    for name in members:
        f = out[name]
        out[name] = QFormat(f.int_bits, frac, f.rounding, f.overflow)
    return out


def _cost(config, variant):
    """(18 x 18 pieces the update's products take, one multiplier each; bits of every point)."""
    blocks = config.width_report(variant).blocks()
    bits = sum(config.formats[name].width for name in config.formats)
    return blocks, bits


def propose(config, variant, signals, *, budget=0.01, objective="multipliers", settle=None, progress=None):
    """Search per-point formats for ``config``'s model (its pinned formats are the start).

    ``signals``: ``{label: (truth, codes)}``, each checked against the RMSE budget.
    ``progress(text)`` is told each step. Returns a :class:`Proposal`.
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}, not {objective!r}")
    t0 = time.perf_counter()
    judge = _Judge(config, variant, signals, budget, settle)
    say = progress or (lambda text: None)
    if hasattr(progress, "tick"):
        judge.tick = progress.tick
    formats = dict(config.formats)
    groups = _groups(config)
    notes = []
    points = config.spec.points
    unused = [g for g in groups if points[g].variants and variant not in points[g].variants]
    used = [name for g in groups if g not in unused for name in groups[g]]
    failed, _ = judge(formats)
    first = failed
    grown = 0
    while failed and grown < MAX_GROW:
        grown += 1
        say(f"start fails ({failed}): every point +1 fraction bit")
        formats = {name: QFormat(f.int_bits, f.frac_bits + (name in used), f.rounding, f.overflow)
                   for name, f in formats.items()}
        failed, _ = judge(formats)
    if failed:
        raise ConfigError(f"no formats found: with {MAX_GROW} more fraction bits on every point, still {failed}")
    if grown:
        notes.append(f"the default formats failed ({first}); every point the variant uses got {grown} more "
                     "fraction bit(s) first")
    bound = {}
    for leader in unused:  # points the variant never writes keep their formats
        for name in groups[leader]:
            bound[name] = f"not used by the {variant} variant (kept)"
    order = sorted((g for g in groups if g not in unused), key=lambda g: -formats[g].width)
    if objective == "multipliers":
        operand = [g for g in order if config.spec.points[g].operand]
        order = operand + [g for g in order if g not in operand]
    for leader in order:
        members = groups[leader]
        f = formats[leader]
        lo = 0
        if objective == "multipliers" and config.spec.points[leader].operand and f.width > MULTIPLIER_BITS:
            say(f"{leader}: down to {MULTIPLIER_BITS} bits?")
            frac18 = max(MULTIPLIER_BITS - f.int_bits, 0)
            why, _ = judge(_with_frac(formats, members, frac18))
            if why is None:
                formats = _with_frac(formats, members, frac18)
                f = formats[leader]
        # binary search for the fewest fraction bits that still pass (each constraint gets
        # no better with fewer bits, so the passing fractions form a range up to the current)
        hi, reason = f.frac_bits, None
        while lo < hi:
            mid = (lo + hi) // 2
            say(f"{leader}: {f.int_bits}.{mid}?")
            why, _ = judge(_with_frac(formats, members, mid))
            if why is None:
                hi = mid
            else:
                lo, reason = mid + 1, why
        formats = _with_frac(formats, members, hi)
        for name in members:
            bound[name] = reason or "no fraction bits: none needed"
    final, metrics = judge(formats)
    if final is not None:  # the trims interact: put back bits on the last trimmed point until it passes
        raise ConfigError(f"the trimmed formats fail together: {final}")
    proposed = judge.config(formats)
    return Proposal(proposed, config, bound, metrics, judge.evaluations, time.perf_counter() - t0,
                    (_cost(config, variant)[0], _cost(proposed, variant)[0]),
                    (_cost(config, variant)[1], _cost(proposed, variant)[1]), notes)


def proposal_toml(proposal, ranges, *, variant, budget, objective, seconds):
    """The proposal as a commented TOML: each point's range, its bits, what bound it."""
    text = proposal.config.to_toml(formats=True)
    lines = []
    header = [f"# kfpga propose: {variant} variant, objective {objective}, budget {100 * budget:g} % of float's RMSE,",
              f"# no overflow on full-scale stress, limit cycles <= 1 input LSB; {proposal.evaluations} candidates "
              f"in {seconds:.1f} s.",
              f"# multiplier pieces {proposal.multipliers[0]} -> {proposal.multipliers[1]}, register bits "
              f"{proposal.register_bits[0]} -> {proposal.register_bits[1]} (from the default formats)."]
    for line in text.splitlines():
        lines.append(line)
        if line.startswith("[formats."):
            name = line.split("]", 1)[0].removeprefix("[formats.")
            fmt = proposal.config.formats[name]
            amax = ranges.get(name)
            reach = f"analysed max {amax:.6g}" if amax is not None else "no analysed range"
            lines.append(f"# {reach}; {fmt.width} bits; fraction bits bound by: {proposal.bound.get(name, '-')}")
    return "\n".join(header + lines) + "\n"
