"""The core of the ship-roll predictor (``model/roll.py``): its update on the sequential core.

The predictor takes a sample every half second: its square-root update (one Potter
measurement update, six Givens rotations and a norm, eight square roots and sixteen
divisions) runs one operation at a time on :class:`~kfpga.hw.sequencer.SequentialCore`,
which computes the model's integers by construction. The two filters of the combined
interval predictor are one channel's state (``model/roll.py``: each sample goes to the filter
whose turn it is); a channel is one roll sensor.
"""

from __future__ import annotations

from kfpga.hw.sequencer import SequentialCore

__all__ = ["make_core"]


def make_core(config, variant, *, channels=1, stages=None):
    """The roll predictor's core (``channels`` roll sensors, each a pair of filters); ``stages``
    does not apply."""
    if stages is not None:
        raise ValueError("stages applies to a steady-state loop; the roll predictor runs on the sequential core")
    return SequentialCore(config, variant, channels=channels)
