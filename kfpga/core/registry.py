"""The registered filters. Adding a filter adds its files and one line to :data:`FILTERS`.

Every command (``--filter NAME``), the manifest, the scoreboard, the cocotb benches and the
contract tests iterate over this registry; nothing else lists the filters.
"""

from __future__ import annotations

import importlib

__all__ = ["FILTERS", "DEFAULT", "get", "names", "specs", "spec_for", "register", "unregister", "aliases",
           "canonical", "presets", "preset",
           "coasting", "example"]

#: ``name -> module`` whose ``SPEC`` is the filter's :class:`~kfpga.core.spec.FilterSpec`; imported on
#: use. The name is the stem of the filter's files in every layer (``model/NAME.py``, ``hw/NAME.py``,
#: its tests); a spec's ``aliases`` are the other spellings users type.
FILTERS = {
    "kalman2": "kfpga.model.kalman2",
    "kalman": "kfpga.model.kalman",
    "alphabeta": "kfpga.model.alphabeta",
    "tukey53h": "kfpga.model.tukey53h",
    "roll": "kfpga.model.roll",
    "lsfront": "kfpga.model.lsfront",
}
#: The paper's filter, used when a config or command names none.
DEFAULT = "kalman2"

_loaded = {}


def register(spec):
    """Add a filter at run time (a user's own spec); its name and aliases must be new."""
    taken = set(names()) | set(aliases())
    for name in (spec.name, *spec.aliases):
        if name in taken:
            raise ValueError(f"a filter named {name!r} is already registered")
    _loaded[spec.name] = spec


def unregister(name):
    """Remove a filter added with :func:`register` (the registry's own filters stay)."""
    if name in FILTERS:
        raise ValueError(f"{name!r} is one of the registry's own filters")
    _loaded.pop(name, None)


def _load(name):
    if name not in _loaded:
        _loaded[name] = importlib.import_module(FILTERS[name]).SPEC
    return _loaded[name]


def aliases():
    """``{alias: name}`` of every registered filter."""
    return {alias: spec.name for spec in specs() for alias in spec.aliases}


def canonical(name):
    """The registered name of ``name`` (itself, or the filter it is an alias of); ``KeyError``."""
    if name in _loaded or name in FILTERS:
        return name
    known = aliases()
    if name in known:
        return known[name]
    raise KeyError(f"no filter named {name!r}; registered: {', '.join(names())}")


def get(name):
    """The :class:`~kfpga.core.spec.FilterSpec` named ``name`` (or one of its aliases); ``KeyError``
    with the known names."""
    return _load(canonical(name))


def names():
    return list(dict.fromkeys([*FILTERS, *_loaded]))


def specs():
    return [_load(n) for n in names()]


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


def coasting():
    """The filters one of whose variants can predict only (a sample with no measurement)."""
    return [spec.name for spec in specs() if any(v.predict is not None for v in spec.variants.values())]


def example(has=lambda spec: True, skip=0):
    """The name of a registered filter for a command's examples: the first (after ``skip``) of
    those other than the default for which ``has(spec)`` holds, else the default."""
    found = [spec.name for spec in specs() if spec.name != DEFAULT and has(spec)]
    return found[skip] if len(found) > skip else DEFAULT


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
