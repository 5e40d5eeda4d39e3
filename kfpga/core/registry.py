"""The registered filters. Adding a filter adds its files and one line to :data:`FILTERS`.

Every command (``--filter NAME``), the manifest, the scoreboard, the cocotb benches and the
contract tests iterate over this registry; nothing else lists the filters.
"""

from __future__ import annotations

import importlib

__all__ = ["FILTERS", "DEFAULT", "get", "names", "specs", "spec_for", "register", "presets", "preset"]

#: ``name -> module`` whose ``SPEC`` is the filter's :class:`~kfpga.core.spec.FilterSpec`; imported on use.
FILTERS = {
    "kalman2": "kfpga.model.kalman2",
    "kalman": "kfpga.model.kalman",
    "alpha-beta": "kfpga.model.alphabeta",
    "53h": "kfpga.model.tukey53h",
    "roll": "kfpga.model.roll",
    "ls-frontend": "kfpga.model.lsfront",
}
#: The paper's filter, used when a config or command names none.
DEFAULT = "kalman2"

_loaded = {}


def register(spec):
    """Add a filter at run time (a user's own spec); its name must be new."""
    if spec.name in FILTERS or spec.name in _loaded:
        raise ValueError(f"a filter named {spec.name!r} is already registered")
    _loaded[spec.name] = spec


def get(name):
    """The :class:`~kfpga.core.spec.FilterSpec` named ``name``; ``KeyError`` with the known names."""
    if name in _loaded:
        return _loaded[name]
    if name not in FILTERS:
        raise KeyError(f"no filter named {name!r}; registered: {', '.join(names())}")
    spec = importlib.import_module(FILTERS[name]).SPEC
    _loaded[name] = spec
    return spec


def names():
    return list(dict.fromkeys([*FILTERS, *_loaded]))


def specs():
    return [get(n) for n in names()]


def spec_for(params, filter=None):
    """The spec of ``filter`` (checking ``params`` are its parameters), else of ``params``' type."""
    if filter is not None:
        spec = get(filter)
        if not isinstance(params, spec.params):
            raise TypeError(f"params must be {spec.params.__name__} for the {spec.name} filter, not {params!r}")
        return spec
    for spec in specs():
        if type(params) is spec.params:
            return spec
    raise TypeError(f"params must be the parameters of a registered filter ({', '.join(names())}), not {params!r}")


def presets():
    """``{preset: (filter, summary)}`` over every registered filter, in registry order."""
    out = {}
    for spec in specs():
        for name, (summary, _) in spec.presets.items():
            if name in out:
                raise ValueError(f"preset {name!r} is defined by both the {out[name][0]} and the {spec.name} filter")
            out[name] = (spec.name, summary)
    return out


def preset(name):
    """``(filter, params)`` of the preset ``name``; ``KeyError`` with the known names."""
    known = presets()
    if name not in known:
        raise KeyError(f"no preset named {name!r}; presets: {', '.join(known)}")
    filter_name = known[name][0]
    return filter_name, get(filter_name).presets[name][1]()
