"""``kfpga propose``: per-point word lengths for a model, searched against stated constraints.

Every point keeps the integer bits of its analysed range (the default formats'). Its fraction
bits are then trimmed one point at a time, widest first, as far as the constraints allow, for
every variant asked for at once (one config serves them all):

* on every signal (each seed of a scenario, each file) the fixed RMSE of the main output against
  truth stays within the search's share of the budget of float's, either way; the rest of the
  budget (:data:`RESERVE`) is the margin for seeds the search did not see. Every other output,
  which has no truth, keeps its fixed - float difference small enough that, added to the float
  filter's own steady-state error (the spec's ``error_std``, from the Lyapunov equation of the
  gain), its RMSE stays within that share;
* nothing overflows on the full-scale stress stimulus (full-scale steps from a settled state,
  a full-scale sine);
* no dead band or limit cycle on noise-free inputs exceeds one input LSB (one ADC code);
* every constant and reset value is held within 1 % (the config check).

The formats the config pins are constraints: kept as they are, never trimmed. When the starting
formats fail a constraint, every other point first gets fraction bits added, one at a time,
until they pass. The objective orders the trimming: ``multipliers`` first brings every
multiplier operand down to the embedded multiplier's 18 bits where the constraints allow (each
operand above 18 bits costs a second multiplier piece per product), then trims register bits;
``bits`` trims the widest points first, whatever they are.

Speed: a candidate is one batched model run per variant and signal: the seeds of a scenario are
the rows of one batch (the compiled model's cost is per sample, nearly whatever the rows), the
stress rows and the noise-free rows another; the float runs are made once, before the search.
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
from kfpga.flows.analysis import float_run, limit_cycles
from kfpga.model.ranges import full_scale_stimulus

__all__ = ["Proposal", "Signal", "propose", "OBJECTIVES", "RESERVE"]

OBJECTIVES = ("multipliers", "bits")
MAX_GROW = 12  # fraction bits added to every point at most when the start fails
#: The share of the budget the search leaves unused: the worst of its seeds stays within
#: (1 - RESERVE) of the budget, so that seeds it did not see keep within the whole budget.
RESERVE = 0.25


@dataclass
class Signal:
    """One signal of the search: ``truth`` and ``codes`` with the seeds (or one file) as rows,
    ``(rows, n)``; ``codes`` may be ``{input: (rows, n)}``. ``labels`` names each row."""

    truth: np.ndarray
    codes: object
    labels: list


@dataclass
class Proposal:
    """The proposed config and how it was found."""

    config: FilterConfig
    start: FilterConfig
    bound: dict  # point -> the constraint that stopped its trimming
    metrics: dict  # the final check: the worst rmse ratio, per row; limit cycle; margin
    evaluations: int
    seconds: float
    multipliers: tuple = (0, 0)  # (start, proposed) embedded multiplier pieces
    register_bits: tuple = (0, 0)
    notes: list = field(default_factory=list)
    variants: tuple = ()


def _stress(config):
    """Full-scale stress rows for every input, as int64 codes (``(rows, n)`` or ``{input: rows}``)."""
    r = np.atleast_2d(np.asarray(config.params.R, dtype=np.float64))
    rows = np.clip(np.round(full_scale_stimulus(float(np.max(np.diag(r))))), -32768, 32767).astype(np.int64)
    names = config.inputs
    if len(names) == 1:
        return rows
    return {name: np.roll(rows, 997 * j, axis=1) for j, name in enumerate(names)}


def _row(codes, i):
    return {k: v[i] for k, v in codes.items()} if isinstance(codes, dict) else codes[i]


def _float_runs(config, variant, signal):
    """The float filter on every row of ``signal``: ``{output: (rows, n)}`` (made once)."""
    runs = [float_run(config, variant, _row(signal.codes, i)) for i in range(len(signal.labels))]
    return {name: np.stack([r[name] for r in runs]) for name in runs[0]}


class _Judge:
    """Checks one candidate against every constraint, for every variant; counts the evaluations."""

    def __init__(self, config, variants, signals, budget, settle):
        self.params, self.filter, self.variants = config.params, config.filter, tuple(variants)
        self.signals, self.budget, self.settle = signals, budget, settle
        self.limit = budget * (1.0 - RESERVE)
        self.stress = _stress(config)
        self.error_std = config.spec.model.error_std(config.params) if config.spec.model.error_std else None
        self.main = config.spec.model.default_output
        self.floats = {v: [_float_runs(config, v, s) for s in signals] for v in self.variants}
        self.noise_free = {}  # the float runs of the limit-cycle check, made once
        self.evaluations = 0
        self.tick = lambda: None

    def config(self, formats):
        return FilterConfig(filter=self.filter, params=self.params, formats=formats)

    def _settle(self, n):
        return min(100, n // 10) if self.settle is None else self.settle

    def _signal(self, model, variant, signal, flt, metrics):
        """The RMSE checks of one signal (its rows at once): the reason it fails, or ``None``."""
        res = model.run(signal.codes)
        if np.any(res.overflow):
            return f"overflow on {signal.labels[int(np.flatnonzero(np.any(np.atleast_2d(res.overflow), axis=-1))[0])]}"
        fixed = model.to_float(res)
        w = slice(self._settle(signal.truth.shape[-1]), None)
        fx, fl = np.atleast_2d(fixed[self.main])[:, w], flt[self.main][:, w]
        truth = np.atleast_2d(signal.truth)[:, w]
        ratios = np.sqrt(np.mean((fx - truth) ** 2, axis=-1)) / np.sqrt(np.mean((fl - truth) ** 2, axis=-1))
        for label, ratio in zip(signal.labels, ratios, strict=True):
            metrics[f"{variant}: {label}"] = float(ratio)
        k = int(np.argmax(np.abs(ratios - 1.0)))
        if abs(ratios[k] - 1.0) > self.limit:
            return f"RMSE budget on {signal.labels[k]} ({100 * (ratios[k] - 1):+.2f} % of float, {variant})"
        # the outputs without a truth: their fixed - float difference, added to the float
        # filter's own steady-state error (uncorrelated), must keep it within the budget
        for name, std in (self.error_std or {}).items():
            if name == self.main or name not in fixed:
                continue
            allowed = std * math.sqrt((1.0 + self.limit) ** 2 - 1.0)
            got = float(np.max(np.sqrt(np.mean((np.atleast_2d(fixed[name])[:, w] - flt[name][:, w]) ** 2, axis=-1))))
            if got > allowed:
                return (f"RMSE budget of {name} ({variant}: fixed - float {got:.3g} rms, at most {allowed:.3g} against "
                        f"its float error {std:.3g})")
        return None

    def _variant(self, cfg, variant, metrics):
        over = FixedModel(cfg, variant=variant).run(self.stress).overflow_points
        hit = sorted(name for name, flags in over.items() if flags.any())
        if hit:
            return f"overflow on full-scale stress at {', '.join(hit)} ({variant})"
        model = FixedModel(cfg, variant=variant)
        for signal, flt in zip(self.signals, self.floats[variant], strict=True):
            why = self._signal(model, variant, signal, flt, metrics)
            if why:
                return why
        lc = limit_cycles(cfg, variant, floats=self.noise_free)
        metrics["limit_cycle_lsb"] = max(metrics.get("limit_cycle_lsb", 0.0), lc["limit_cycle_lsb"])
        metrics["dead_band_lsb"] = max(metrics.get("dead_band_lsb", 0.0), lc["dead_band_lsb"])
        if max(lc["limit_cycle_lsb"], lc["dead_band_lsb"]) > 1.0:
            return (f"limit cycle {lc['limit_cycle_lsb']:.2f} LSB, dead band {lc['dead_band_lsb']:.2f} LSB "
                    f"(at most 1 input LSB; {variant})")
        return None

    def __call__(self, formats):
        """``(None, metrics)`` when ``formats`` pass, else ``(the constraint that failed, metrics)``."""
        self.evaluations += 1
        self.tick()
        try:
            cfg = self.config(formats)
            for variant in self.variants:
                cfg.require_variant(variant)
        except ConfigError as exc:
            return f"range or precision: {exc}", {}
        metrics = {}
        for variant in self.variants:
            why = self._variant(cfg, variant, metrics)
            if why:
                return why, metrics
        ratios = [v for k, v in metrics.items() if ":" in k]
        metrics["worst_rmse_change"] = max(abs(r - 1.0) for r in ratios)
        metrics["margin"] = self.budget - metrics["worst_rmse_change"]
        return None, metrics


def _groups(config):
    """Points that share one format (``same_as``) are trimmed together: ``{leader: [members]}``."""
    points = config.spec.model.points
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


def _cost(config, variants):
    """(18 x 18 pieces the update's products take, one multiplier each, the most of any variant;
    bits of every point)."""
    blocks = max(config.width_report(v).blocks() for v in variants)
    bits = sum(config.formats[name].width for name in config.formats)
    return blocks, bits


def _grow(judge, formats, free, say, notes):
    """Fraction bits added to every free point until the formats pass (the start failed)."""
    failed, _ = judge(formats)
    first, grown = failed, 0
    while failed and grown < MAX_GROW:
        grown += 1
        say(f"start fails ({failed}): every point +1 fraction bit")
        formats = {name: QFormat(f.int_bits, f.frac_bits + (name in free), f.rounding, f.overflow)
                   for name, f in formats.items()}
        failed, _ = judge(formats)
    if failed:
        raise ConfigError(f"no formats found: with {MAX_GROW} more fraction bits on every point, still {failed}")
    if grown:
        notes.append(f"the starting formats failed ({first}); every point the search may change got {grown} more "
                     "fraction bit(s) first")
    return formats


def _trim(judge, formats, members, objective, operand, say):
    """The fewest fraction bits of one group that still pass: ``(formats, what stopped it)``."""
    f = formats[members[0]]
    if objective == "multipliers" and operand and f.width > MULTIPLIER_BITS:
        say(f"{members[0]}: down to {MULTIPLIER_BITS} bits?")
        narrow = _with_frac(formats, members, max(MULTIPLIER_BITS - f.int_bits, 0))
        if judge(narrow)[0] is None:
            formats, f = narrow, narrow[members[0]]
    # binary search (each constraint gets no better with fewer bits, so the passing fractions
    # form a range up to the current)
    lo, hi, reason = 0, f.frac_bits, None
    while lo < hi:
        mid = (lo + hi) // 2
        say(f"{members[0]}: {f.int_bits}.{mid}?")
        why, _ = judge(_with_frac(formats, members, mid))
        if why is None:
            hi = mid
        else:
            lo, reason = mid + 1, why
    return _with_frac(formats, members, hi), reason or "no fraction bits: none needed"


def propose(config, variants, signals, *, budget=0.01, objective="multipliers", settle=None, progress=None):
    """Search per-point formats for ``config``'s model, for every variant of ``variants`` at once
    (the formats the config pins are kept).

    ``signals``: a list of :class:`Signal`, each row checked against the RMSE budget.
    ``progress(text)`` is told each step. Returns a :class:`Proposal`.
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}, not {objective!r}")
    variants = (variants,) if isinstance(variants, str) else tuple(variants)
    t0 = time.perf_counter()
    judge = _Judge(config, variants, signals, budget, settle)
    say = progress or (lambda text: None)
    if hasattr(progress, "tick"):
        judge.tick = progress.tick
    groups = _groups(config)
    points = config.spec.model.points
    unused = [g for g in groups if points[g].variants and not set(variants) & set(points[g].variants)]
    pinned = [g for g in groups if g not in unused and any(n in config.pinned for n in groups[g])]
    free = [name for g in groups if g not in unused and g not in pinned for name in groups[g]]
    notes = []
    formats = _grow(judge, dict(config.formats), free, say, notes)
    bound = {}
    for leader in unused:  # points no variant asked for writes keep their formats
        for name in groups[leader]:
            bound[name] = f"not used by the {', '.join(variants)} variant(s) (kept)"
    for leader in pinned:
        for name in groups[leader]:
            bound[name] = "pinned by the config (kept)"
    order = sorted((g for g in groups if g not in unused and g not in pinned), key=lambda g: -formats[g].width)
    if objective == "multipliers":
        operand = [g for g in order if points[g].operand]
        order = operand + [g for g in order if g not in operand]
    for leader in order:
        formats, reason = _trim(judge, formats, groups[leader], objective, points[leader].operand, say)
        for name in groups[leader]:
            bound[name] = reason
    final, metrics = judge(formats)
    if final is not None:  # pragma: no cover - each trim was checked with the others in place
        raise ConfigError(f"the trimmed formats fail together: {final}")
    proposed = config.replace(formats=formats)
    before, after = _cost(config, variants), _cost(proposed, variants)
    return Proposal(proposed, config, bound, metrics, judge.evaluations, time.perf_counter() - t0,
                    (before[0], after[0]), (before[1], after[1]), notes, variants)


def proposal_toml(proposal, ranges, *, budget, objective, seconds, signals=()):
    """The proposal as a commented TOML: what it was searched on (variants, seeds or files), its
    margin, and each point's range, its bits, what bound it."""
    text = proposal.config.to_toml(formats=True)
    lines = []
    m = proposal.metrics
    header = [f"# kfpga propose: {', '.join(proposal.variants)} variant(s), objective {objective}, budget "
              f"{100 * budget:g} % of float's RMSE,",
              f"# searched on: {'; '.join(signals) if signals else '-'}",
              f"# worst RMSE change {100 * m['worst_rmse_change']:.3f} % of float over those, margin "
              f"{100 * m['margin']:.3f} % of the budget's {100 * budget:g} %;",
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
