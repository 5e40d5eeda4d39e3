"""A filter's core: :func:`make_core` builds its parallel core (its own, where it has one: an entry
point of the ``kfpga.cores`` group) or the folded core (``hw/folded.py``), which runs every filter."""

from __future__ import annotations

from kfpga.core import registry
from kfpga.core.spec import resolve

__all__ = ["make_core"]

#: options that only the folded core takes: the input's no-measurement bit and the register bus
FOLDED_ONLY = ("missing", "bus")


def make_core(config, variant, *, channels=1, architecture=None, **options):
    """The Amaranth core of ``variant`` on ``architecture`` (default: the parallel core where it
    runs, else the folded one); ``options`` go to the core (``stages=L`` for a pipelined loop;
    ``missing=True``, the input's no-measurement bit, and ``bus="avalon"`` or ``"axi4lite"``, the
    register slave: the folded core only)."""
    spec = config.spec
    folded_only = [name for name in FOLDED_ONLY if options.get(name)]
    if folded_only and architecture == "parallel":
        raise ValueError(f"{' and '.join(folded_only)} apply to the folded core, not the parallel one")
    if folded_only:
        architecture = "folded"
    else:
        options = {k: v for k, v in options.items() if k not in FOLDED_ONLY}
    architecture = architecture or spec.architectures(variant, config.params)[0]
    why = spec.why_not(variant, config.params, architecture)
    if why:
        raise ValueError(why)
    if architecture == "folded":
        from kfpga.hw.folded import make_core as folded  # Amaranth's microcode compiler: on first use

        return folded(config, variant, channels=channels, **options)
    return resolve(registry.core_target(spec.name))(config, variant, channels=channels, **options)


def build(what):
    """The core a :class:`~kfpga.core.spec.Build` describes."""
    return make_core(what.config, what.variant, channels=what.channels, architecture=what.architecture,
                     **what.options)
