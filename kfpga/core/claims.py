"""A source document's claims, measured over many seeds: ``kfpga evaluate NAME`` prints them as a
table and writes them under ``claims`` in its ``--json``.

A claim is judged on every seed of the run, never on one: it is *reproduced* when it holds on every
seed, *not reproduced* when it fails on one or more (the table says on how many it holds), and *not
testable* when nothing this project has can measure it (the reason says why: the document's data
are not available, it gives curves and no figures, ...).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Claim", "spread", "claims_table", "claims_markdown", "REPRODUCED", "NOT_REPRODUCED", "NOT_TESTABLE"]

REPRODUCED, NOT_REPRODUCED, NOT_TESTABLE = "reproduced", "not reproduced", "not testable"


def spread(values, fmt=".4g"):
    """``mean ± standard deviation (min .. max)`` of one figure over the seeds; the value alone for
    one seed."""
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if len(v) == 0:
        return "-"
    if len(v) == 1:
        return format(float(v[0]), fmt)
    return (f"{format(float(v.mean()), fmt)} ± {format(float(v.std(ddof=1)), fmt)} "
            f"({format(float(v.min()), fmt)} .. {format(float(v.max()), fmt)})")


@dataclass
class Claim:
    """One quantitative claim of a source document and what the runs measured.

    Parameters
    ----------
    claim:
        What the document says, in a line.
    document:
        The document's value (a figure, a comparison, a table cell), as text.
    holds:
        Whether the claim held, one entry per seed (or one for a run on a file); ``None`` when it
        cannot be tested (``reason`` says why).
    ours:
        Our value, as text (see :func:`spread` for a figure over the seeds).
    reason:
        Why it is not testable, or what decides it (a note printed with the verdict).
    """

    claim: str
    document: str
    holds: list | None
    ours: str = ""
    reason: str = ""
    seeds: int = field(init=False, default=0)

    def __post_init__(self):
        if self.holds is not None:
            self.holds = [bool(h) for h in self.holds]
            if not self.holds:
                raise ValueError(f"claim {self.claim!r}: no run to judge it on")
        self.seeds = 0 if self.holds is None else len(self.holds)

    @property
    def held(self):
        """On how many of the runs the claim held (``None`` when not testable)."""
        return None if self.holds is None else sum(self.holds)

    @property
    def verdict(self):
        if self.holds is None:
            return NOT_TESTABLE
        return REPRODUCED if all(self.holds) else NOT_REPRODUCED

    def to_json(self):
        return {"claim": self.claim, "document": self.document, "ours": self.ours, "verdict": self.verdict,
                "held": self.held, "runs": self.seeds, "reason": self.reason}


def claims_table(claims, runs_label):
    """The claims as text: each with the document's value, ours, and the verdict with the count of
    runs it held on. ``runs_label`` says what the runs were (``"20 seeds, 1 .. 20"``)."""
    lines = [f"the source document's claims, over {runs_label}:"]
    for i, c in enumerate(claims, 1):
        count = "" if c.holds is None else f" (holds on {c.held} of {c.seeds})"
        lines += [f"{i:>2}. {c.claim}",
                  f"    document: {c.document}",
                  f"    ours:     {c.ours or '-'}",
                  f"    verdict:  {c.verdict.upper()}{count}" + (f"; {c.reason}" if c.reason else "")]
    counts = {v: sum(c.verdict == v for c in claims) for v in (REPRODUCED, NOT_REPRODUCED, NOT_TESTABLE)}
    lines.append("    " + ", ".join(f"{n} {v}" for v, n in counts.items()))
    return "\n".join(lines)


def claims_markdown(claims, runs_label):
    """The claims as a Markdown table (the manual quotes the default run's, checked by the tests)."""

    def cell(text):
        return str(text).replace("|", "\\|")

    lines = [f"Over {runs_label}:", "", "| # | claim | document | ours | verdict |", "| --- | --- | --- | --- | --- |"]
    for i, c in enumerate(claims, 1):
        count = "" if c.holds is None else f" ({c.held} of {c.seeds})"
        reason = f": {c.reason}" if c.reason and c.holds is None else ""
        lines.append(f"| {i} | {cell(c.claim)} | {cell(c.document)} | {cell(c.ours)} | "
                     f"**{c.verdict}**{count}{cell(reason)} |")
    return "\n".join(lines)
