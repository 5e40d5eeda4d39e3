"""The core of the least-squares front end and its filter (``model/lsfront.py``): its update on
the sequential core.

A speed log gives a sample a second: the whole update (every window's running sums, the fit of
the window in use, the steady-state filter with that mode's gains, the next window from the
innovation, the delay line of the last Ns samples) runs one operation at a time on
:class:`~kfpga.hw.sequencer.SequentialCore`, which computes the model's integers by
construction; the window's samples and sums are channel state in its block memory.
"""

from __future__ import annotations

from kfpga.hw.sequencer import SequentialCore

__all__ = ["make_core"]


def make_core(config, variant, *, channels=1, stages=None):
    """The front end's core (``channels`` speed logs); ``stages`` does not apply."""
    if stages is not None:
        raise ValueError("stages applies to a steady-state loop; the least-squares front end runs on the sequential core")
    return SequentialCore(config, variant, channels=channels)
