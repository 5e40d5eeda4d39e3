"""Scoreboard: the bit-accurate model on exactly the samples the DUT received, integer by integer.

One check for every simulator: the Amaranth unit tests and the cocotb benches both feed it.
"""

from __future__ import annotations

import numpy as np

from kfpga.core.fixedmodel import FixedModel

__all__ = ["Scoreboard"]


class Scoreboard:
    """Collect the DUT's inputs and outputs, then compare them with the model.

    Inputs are ``(channel, codes)`` in the order the filter received them (``codes`` an int for
    a one-input filter, else ``{input: int}``); outputs are dicts with ``channel`` and any of the
    filter's output fields, ``overflow`` (the sample's flag) and ``sticky`` (the OR of the flags
    since the last reset), as far as the DUT shows them. :meth:`reset` marks a reset of the
    DUT: the filter state returns to its reset value (as in the model from then on), and
    inputs that had not produced an output yet were in flight and are dropped (counted in the
    report).
    """

    def __init__(self, config, variant, *, prefilter=None):
        self.model = FixedModel(config, variant=variant)
        # a 53H pre-filter in front: each ADC channel's samples go through it first
        self.prefilter = None if prefilter is None else FixedModel(prefilter)
        self.fields = ("channel", *self.model.outputs, "overflow", "sticky")
        self.segments = [([], [])]

    def add_input(self, channel, codes):
        self.segments[-1][0].append((int(channel), codes))

    def add_output(self, **fields):
        unknown = set(fields) - set(self.fields)
        if unknown:
            raise KeyError(f"unknown output field(s) {', '.join(sorted(unknown))}; known: {', '.join(self.fields)}")
        self.segments[-1][1].append(fields)

    def reset(self):
        self.segments.append(([], []))

    @property
    def inputs(self):
        return sum(len(i) for i, _ in self.segments)

    @property
    def outputs(self):
        return sum(len(o) for _, o in self.segments)

    def expected(self, inputs):
        """The model's fields for a list of ``(channel, codes)``, in order, from the reset state."""
        channels = np.array([c for c, _ in inputs])
        names = self.model.inputs
        if len(names) == 1:
            codes = np.array([int(v) if not isinstance(v, dict) else int(v[names[0]]) for _, v in inputs], dtype=np.int64)
        else:
            codes = {n: np.array([int(v[n]) for _, v in inputs], dtype=np.int64) for n in names}
        if self.prefilter is not None:
            codes = self.prefiltered(codes, channels)
        outputs, overflow, _ = self.model.run_channels(codes, channels)
        return {"channel": channels, **outputs, "overflow": overflow.astype(int),
                "sticky": np.logical_or.accumulate(overflow).astype(int)}

    def prefiltered(self, codes, channels):
        """The codes as the pre-filter passes them on: one channel state per channel for one
        input, one per input (each has its ADC channel) for several. Its formats cannot overflow
        (:func:`kfpga.hw.top.prefilter_core` refuses others), so it adds no flag."""
        if isinstance(codes, dict):
            return {n: self.prefilter.run(a).y for n, a in codes.items()}
        outputs, _, _ = self.prefilter.run_channels(codes, channels)
        return outputs["y"]

    def check(self, *, pending_allowed=0):
        """Compare everything; returns a report dict (``mismatches`` 0 means bit-exact).

        ``pending_allowed``: inputs of the last segment that may still be in the pipeline when
        the simulation stops.
        """
        compared = mismatches = dropped = extra = 0
        first = []
        for k, (inputs, outputs) in enumerate(self.segments):
            last = k == len(self.segments) - 1
            if len(outputs) > len(inputs):
                extra += len(outputs) - len(inputs)
            if not last:
                dropped += len(inputs) - min(len(outputs), len(inputs))
            if not inputs:
                continue
            expected = self.expected(inputs)
            outs = outputs[: len(inputs)]
            compared += len(outs)
            # field by field over whole arrays: a million-sample run compares in a second
            wrong = np.zeros(len(outs), dtype=bool)
            keys = outs[0].keys() if outs else set()
            uniform = all(out.keys() == keys for out in outs)
            for f in self.fields:
                if uniform:
                    if f not in keys:
                        continue
                    idx = np.arange(len(outs))
                    got = np.fromiter((out[f] for out in outs), dtype=np.int64, count=len(outs))
                else:
                    idx = np.array([n for n, out in enumerate(outs) if f in out], dtype=np.int64)
                    got = np.array([int(outs[n][f]) for n in idx], dtype=np.int64)
                if idx.size:
                    wrong[idx[got != np.asarray(expected[f], dtype=np.int64)[idx]]] = True
            mismatches += int(wrong.sum())
            for n in np.flatnonzero(wrong)[: max(10 - len(first), 0)]:
                out = outs[n]
                bad = {f: (int(out[f]), int(expected[f][n])) for f in self.fields
                       if f in out and int(out[f]) != int(expected[f][n])}
                first.append({"segment": k, "index": int(n), "input": inputs[n], "dut_vs_model": bad})
        last_inputs, last_outputs = self.segments[-1]
        pending = max(len(last_inputs) - len(last_outputs), 0)
        missing = max(pending - pending_allowed, 0)
        return {
            "inputs": self.inputs,
            "outputs": self.outputs,
            "compared": compared,
            "mismatches": mismatches,
            "dropped_at_reset": dropped,
            "pending_at_end": pending,
            "missing": missing,
            "extra": extra,
            "first_mismatches": first,
            "ok": mismatches == 0 and missing == 0 and extra == 0 and compared > 0,
        }

    def assert_ok(self, **kwargs):
        """:meth:`check`, failing with the first mismatches when not bit-exact."""
        report = self.check(**kwargs)
        if not report["ok"]:
            raise AssertionError(
                f"DUT != model: {report['mismatches']} mismatch(es) in {report['compared']} compared, "
                f"{report['missing']} missing, {report['extra']} extra; first: {report['first_mismatches'][:3]}")
        return report
