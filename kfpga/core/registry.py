"""The registered filters: every installed distribution's entry points in the ``kfpga.filters``
group, each ``NAME = "module:SPEC"`` naming the filter's :class:`~kfpga.core.spec.FilterSpec`
(kfpga's own in ``pyproject.toml``). Adding a filter adds its files and one entry point.

A filter with a parallel core of its own also names it in the ``kfpga.cores`` group,
``NAME = "module:make_core"`` (a factory in ``hw/``, imported only when hardware is built); the
folded core runs every filter.

Every command (``--filter NAME``), the manifest, the scoreboard, the cocotb benches and the
contract tests iterate over this registry; nothing else lists the filters.
"""

from __future__ import annotations

from importlib import metadata

from kfpga.core.spec import resolve

__all__ = ["GROUP", "CORES", "DEFAULT", "get", "names", "specs", "spec_for", "core_target", "register", "unregister",
           "aliases", "canonical", "presets", "preset", "coasting", "example", "reload"]

#: The entry-point group a distribution registers its filters in.
GROUP = "kfpga.filters"
#: The entry-point group of the filters' parallel cores.
CORES = "kfpga.cores"
#: The paper's filter, used when a config or command names none.
DEFAULT = "kalman2"

_targets = None  # name -> "module:attribute" of the installed filters, in the order they are found
_loaded = {}  # name -> FilterSpec: the specs imported so far, and those added by register()
_added = set()  # the names register() added
_cores = None  # name -> "module:attribute" of the parallel cores' factories (installed, then registered)
_added_cores = {}  # name -> the factory register() gave


def _installed():
    """``{name: "module:attribute"}`` of the entry points: the default filter, kfpga's other
    filters by name, then other distributions' by distribution and name."""
    global _targets
    if _targets is None:
        def order(ep):
            dist = ep.dist.name if ep.dist is not None else ""
            return ep.name != DEFAULT, dist != "kfpga", dist, ep.name

        found = sorted(metadata.entry_points(group=GROUP), key=order)
        _targets = {}
        for ep in found:
            if ep.name in _targets and _targets[ep.name] != ep.value:
                raise RuntimeError(f"two installed filters are named {ep.name!r}: {_targets[ep.name]} and {ep.value}")
            _targets[ep.name] = ep.value
        if DEFAULT not in _targets:
            raise RuntimeError(f"no {GROUP!r} entry point names the {DEFAULT} filter: kfpga is not installed "
                               "(pip install -e .)")
    return _targets


def core_target(name):
    """The factory of the parallel core of the filter ``name`` (a ``"module:attribute"`` string of
    the ``kfpga.cores`` group, or the callable :func:`register` was given), or ``None``."""
    global _cores
    if name in _added_cores:
        return _added_cores[name]
    if _cores is None:
        _cores = {ep.name: ep.value for ep in metadata.entry_points(group=CORES)}
    return _cores.get(name)


def reload():
    """Read the entry points again (a distribution installed or put on ``sys.path`` since); the
    filters added by :func:`register` stay."""
    global _targets, _cores
    _targets = _cores = None
    for name in [n for n in _loaded if n not in _added]:
        del _loaded[name]


def register(spec, *, core=None):
    """Add a filter at run time (a user's own spec); its name and aliases must be new. ``core``:
    the factory of its parallel core, if it has one (``f(config, variant, *, channels)``)."""
    taken = set(names()) | set(aliases())
    for name in (spec.name, *spec.docs.aliases):
        if name in taken:
            raise ValueError(f"a filter named {name!r} is already registered")
    _loaded[spec.name] = spec
    _added.add(spec.name)
    if core is not None:
        _added_cores[spec.name] = core


def unregister(name):
    """Remove a filter added with :func:`register` (the installed filters stay)."""
    if name in _installed():
        raise ValueError(f"{name!r} is an installed filter (an entry point of {GROUP!r})")
    _loaded.pop(name, None)
    _added.discard(name)
    _added_cores.pop(name, None)


def _load(name):
    if name not in _loaded:
        spec = resolve(_installed()[name])
        if spec.name != name:
            raise RuntimeError(f"the entry point {name!r} of {GROUP!r} names the spec of {spec.name!r}")
        _loaded[name] = spec
    return _loaded[name]


def aliases():
    """``{alias: name}`` of every registered filter."""
    return {alias: spec.name for spec in specs() for alias in spec.docs.aliases}


def canonical(name):
    """The registered name of ``name`` (itself, or the filter it is an alias of); ``KeyError``."""
    if name in _loaded or name in _installed():
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
    return list(dict.fromkeys([*_installed(), *_added]))


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
    return [spec.name for spec in specs() if any(v.predict is not None for v in spec.model.variants.values())]


def example(has=lambda spec: True, skip=0):
    """The name of a registered filter for a command's examples: the first (after ``skip``) of
    those other than the default for which ``has(spec)`` holds, else the default."""
    found = [spec.name for spec in specs() if spec.name != DEFAULT and has(spec)]
    return found[skip] if len(found) > skip else DEFAULT


def presets():
    """``{preset: (filter, summary)}`` over every registered filter, in registry order."""
    out = {}
    for spec in specs():
        for name, (summary, _) in spec.model.presets.items():
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
    return filter_name, get(filter_name).model.presets[name][1]()
