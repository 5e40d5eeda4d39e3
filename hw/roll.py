"""The core of the ship-roll predictor (``model/roll.py``): its update on the sequential core.

The predictor takes a sample every half second: its square-root update (one Potter
measurement update, six Givens rotations and a norm, eight square roots and sixteen
divisions) runs one operation at a time on :class:`~kfpga.hw.sequencer.SequentialCore`,
which computes the model's integers by construction. The two filters of the combined
interval predictor are its two channels, fed alternately.
"""

from __future__ import annotations

from kfpga.hw.sequencer import SequentialCore

__all__ = ["make_core"]


def make_core(config, variant, *, channels=2, stages=None):
    """The roll predictor's core (two channels: the pair of filters); ``stages`` does not apply."""
    if stages is not None:
        raise ValueError("stages applies to a steady-state loop; the roll predictor runs on the sequential core")
    return SequentialCore(config, variant, channels=channels)
