"""The filter core for Amaranth designs: :func:`filter_core`.

A core is a ``wiring.Component`` with two ``lib.stream`` ports and a flag:

* ``i``: ``In(stream.Signature(...))``, the samples: a ``channel`` field and one signed 16-bit
  field per input of the filter (``y`` for one input);
* ``o``: ``Out(stream.Signature(...))``, the estimates: ``channel``, every output field in its
  point's format, and the sample's ``overflow`` flag; one estimate per sample, in order;
* ``overflow``: ``Out(1)``, sticky since reset.

It runs in the ``sync`` domain; ``latency`` and ``cycles_per_update`` are attributes of the
returned object. ``examples/amaranth_core.py`` places one in a small design and simulates it.
"""

from __future__ import annotations

from pathlib import Path

from kfpga.hw.cores import make_core

__all__ = ["filter_core"]


def filter_core(config=None, *, filter=None, variant=None, channels=1, architecture=None, stages=None):
    """The core of a filter as an Amaranth ``wiring.Component``.

    Parameters
    ----------
    config:
        A :class:`~kfpga.core.config.FilterConfig`, the path of a TOML config, or ``None`` for
        the defaults of ``filter`` (default: the paper's ``kalman2``).
    variant:
        The filter's variant (default: its first, ``kfpga filters`` lists them).
    channels:
        Channel states, 1..the core's limit (samples carry their channel number).
    architecture:
        ``"parallel"`` or ``"folded"`` (default: the parallel core where it runs the variant);
        ``stages``: the register stages of a parallel loop.
    """
    from kfpga.core.config import FilterConfig

    if config is None:
        config = FilterConfig(filter=filter)
    elif isinstance(config, str | Path):
        config = FilterConfig.from_toml(config)
    elif filter is not None and filter != config.filter:
        raise ValueError(f"filter {filter!r} does not match the config's filter {config.filter!r}")
    variant = variant or config.spec.default_variant
    config.require_hardware(variant, architecture)
    options = {} if stages is None else {"stages": stages}
    return make_core(config, variant, channels=channels, architecture=architecture, **options)
