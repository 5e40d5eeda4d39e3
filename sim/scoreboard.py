"""Scoreboard: the bit-accurate model on exactly the samples the DUT received, integer by integer."""

from __future__ import annotations

import numpy as np

from kfpga.model.kalman import FixedKalman

__all__ = ["Scoreboard"]

FIELDS = ("channel", "x1", "x2", "yhat", "overflow", "sticky")


class Scoreboard:
    """Collect the DUT's inputs and outputs, then compare them with the model.

    Inputs are ``(channel, code)`` in the order the filter received them; outputs are dicts
    with ``channel`` and ``x1`` and, when the DUT shows them, ``x2``, ``yhat``, ``overflow``
    (the sample's flag) and ``sticky`` (the OR of the flags since the last reset).
    :meth:`reset` marks a reset of the DUT: the filter state returns to x0/P0 (as in the
    model from then on), and inputs that had not produced an output yet were in flight and
    are dropped (counted in the report).
    """

    def __init__(self, config, variant):
        self.model = FixedKalman(config, variant=variant)
        self.segments = [([], [])]

    def add_input(self, channel, code):
        self.segments[-1][0].append((int(channel), int(code)))

    def add_output(self, **fields):
        self.segments[-1][1].append(fields)

    def reset(self):
        self.segments.append(([], []))

    @property
    def inputs(self):
        return sum(len(i) for i, _ in self.segments)

    @property
    def outputs(self):
        return sum(len(o) for _, o in self.segments)

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
            channels = np.array([c for c, _ in inputs])
            codes = np.array([v for _, v in inputs], dtype=np.int64)
            x1, x2, yhat, ovf = self.model.run_channels(codes, channels)
            expected = {"channel": channels, "x1": x1, "x2": x2, "yhat": yhat, "overflow": ovf.astype(int),
                        "sticky": np.logical_or.accumulate(ovf).astype(int)}
            for n, out in enumerate(outputs[: len(inputs)]):
                compared += 1
                bad = {f: (out[f], int(expected[f][n])) for f in FIELDS if f in out and int(out[f]) != int(expected[f][n])}
                if bad:
                    mismatches += 1
                    if len(first) < 10:
                        first.append({"segment": k, "index": n, "input": inputs[n], "dut_vs_model": bad})
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
