"""The shared configuration: a registered filter, its parameters, the format of every point.

One :class:`FilterConfig` drives the bit-accurate model (``kfpga/core/fixedmodel.py``) and the RTL
(the filter's core in ``hw/``). It is built from defaults, a TOML file or keyword arguments,
and validated at once: a bad value raises :class:`ConfigError` naming the field and the value.

Default formats come from range analysis (``model/ranges.py``) by the rules of
``kfpga/core/formats.py``, within the config's word budget (``max_word``): where an exact sum
would pass it, the cast points in it get formats of their own. Every format is then checked
against the analysed range and for the constants and reset values it must hold. No width is
refused: the model is exact at any width (``kfpga/core/compiled.py``), and so is the RTL.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import tomllib
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from kfpga.core.board import Board
from kfpga.core.codes import CODE_FORMAT
from kfpga.core.errors import ConfigError
from kfpga.core.fixed import QFormat, bits_for, to_raw
from kfpga.core.formats import (
    MAX_WORD,
    MULTIPLIER_BITS,
    PRECISION,
    STATE_FRAC_BITS,
    cast_formats,
    precision_frac_bits,
    register_formats,
)
from kfpga.core.ops import update_widths
from kfpga.core.spec import Constant

__all__ = ["ConfigError", "FilterConfig", "default_formats", "analysed_ranges", "input_format", "MULTIPLIER_BITS",
           "STATE_FRAC_BITS", "MAX_WORD", "EXACT"]

#: What a cast point is pinned to when it must keep its value exact (``format = "exact"``).
EXACT = "exact"


def _registry():
    from kfpga.core import registry

    return registry


@functools.lru_cache(maxsize=64)
def _cached_ranges(spec_name, params):
    return MappingProxyType(_registry().get(spec_name).model.ranges(params))


def analysed_ranges(params, stimulus=None, *, filter=None):
    """Largest magnitude of each point of the filter of ``params`` in float runs.

    ``stimulus`` (rows of ADC codes, or ``{input: rows}``) replaces the filter's full-scale
    stimulus.
    """
    spec = _registry().spec_for(params, filter)
    if stimulus is None:
        return dict(_cached_ranges(spec.name, params))
    if isinstance(stimulus, dict):
        return spec.model.ranges(params, {k: np.atleast_2d(np.asarray(v, dtype=np.float64)) for k, v in stimulus.items()})
    return spec.model.ranges(params, np.atleast_2d(np.asarray(stimulus, dtype=np.float64)))


def input_format(params):
    """The format of every input: the ADC's signed 16-bit code, or a wider integer where the
    filter's parameters ask for one (``input_bits``: data that are not an ADC code, such as a
    latitude in 1e-7 deg; the core alone takes them, the board's ADC cannot)."""
    bits = getattr(params, "input_bits", CODE_FORMAT.width)
    return CODE_FORMAT if bits == CODE_FORMAT.width else QFormat(bits, 0)


def default_formats(params, *, ranges=None, operand_bits=MULTIPLIER_BITS, state_frac=STATE_FRAC_BITS, filter=None,
                    max_word=MAX_WORD, pinned=None):
    """Formats chosen by range analysis (``kfpga/core/formats.py``): every point's, and the cast
    points' where an exact sum would pass ``max_word`` (``pinned``: formats given for some
    points, a cast point's may be :data:`EXACT`; they are taken as they are)."""
    spec = _registry().spec_for(params, filter)
    ranges = analysed_ranges(params, filter=spec.name) if ranges is None else ranges
    rules = spec.model.default_formats
    if rules is None:  # the register and operand rules alone
        formats = register_formats(spec, params, ranges, operand_bits=operand_bits, state_frac=state_frac, max_word=max_word)
    else:
        budget = {"max_word": max_word} if "max_word" in inspect.signature(rules).parameters else {}
        formats = rules(params, ranges, operand_bits=operand_bits, state_frac=state_frac, **budget)
    pinned = dict(pinned or {})
    formats.update({name: fmt for name, fmt in pinned.items() if fmt != EXACT})
    formats.update(cast_formats(spec, params, formats, ranges, max_word=max_word, input_format=input_format(params),
                                keep=pinned))
    return formats


@dataclass(frozen=True, kw_only=True)
class FilterConfig:
    """A filter, its parameters and the format of every quantisation point; validated on creation.

    Parameters
    ----------
    filter:
        Name of a registered filter (``kfpga filters``); by default the filter whose
        parameters ``params`` are, else the paper's 2-state filter.
    params:
        The filter's parameters (its ``Params`` dataclass; default: the source's values).
    formats:
        ``{point name: QFormat}``; points left out get their default from range analysis.
        Read-only once the config is made; :attr:`pinned` names the points given here.
    check_ranges:
        Check each format against the analysed range (on by default; word-length sweeps turn
        it off to show what narrow formats do).
    max_word:
        The word budget of the default formats (36: a product of up to 2 x 2 of Cyclone II's
        18 x 18 embedded multipliers): the widest an operand grows for noise, and the widest exact
        sum before its cast points get formats. A pinned format may pass it (the RTL builds it).
    board:
        The rate and clock the design runs at (:class:`~kfpga.core.board.Board`, ``[board]``).
    """

    filter: str | None = None
    params: object = None
    formats: object = field(default_factory=dict)
    check_ranges: bool = True
    max_word: int = MAX_WORD
    board: Board = field(default_factory=Board)
    #: The points whose formats were given (the rest are defaults), in datapath order.
    pinned: tuple = field(init=False, default=())

    def __post_init__(self):
        registry = _registry()
        if self.filter is not None and not isinstance(self.filter, str):
            raise TypeError(f"filter must be a filter name, not {self.filter!r}")
        if self.params is None:
            spec = registry.get(self.filter or registry.DEFAULT)
            object.__setattr__(self, "params", spec.params())
        else:
            spec = registry.spec_for(self.params, self.filter)
        object.__setattr__(self, "filter", spec.name)
        if not isinstance(self.check_ranges, bool):
            raise TypeError(f"check_ranges must be a bool, not {self.check_ranges!r}")
        if not isinstance(self.board, Board):
            raise TypeError(f"board must be a Board, not {self.board!r}")
        if not isinstance(self.max_word, int) or isinstance(self.max_word, bool) or self.max_word < 2:
            raise ConfigError(f"formats.max_word must be an integer >= 2 (bits), not {self.max_word!r}")
        given = dict(self.formats)
        names = list(spec.points_for(self.params))
        _check_given(spec, names, given)
        try:
            merged = default_formats(self.params, filter=spec.name, max_word=self.max_word, pinned=given)
        except ConfigError:
            raise
        except (ArithmeticError, ValueError) as exc:  # numbers no format or float iteration can hold
            raise ConfigError(f"the model's numbers are out of reach of its default formats ({exc}); bring "
                              "Q, R, P0 and T closer to the sizes of the ADC codes they describe") from None
        object.__setattr__(self, "formats", MappingProxyType({name: merged[name] for name in names if name in merged}))
        object.__setattr__(self, "pinned", tuple(name for name in names if name in given))
        self._validate_formats()

    # -- derived quantities -------------------------------------------------------------
    @property
    def spec(self):
        """The filter's :class:`~kfpga.core.spec.FilterSpec`."""
        return _registry().get(self.filter)

    def ranges(self):
        return analysed_ranges(self.params, filter=self.filter)

    # -- the model's interface ----------------------------------------------------------
    @property
    def input_format(self):
        """The format of every input (:func:`input_format`)."""
        return input_format(self.params)

    @property
    def casts(self):
        """The cast points of this model (a product's or a sum's own result format), in datapath
        order: ``{name: QFormat, or None where the value stays exact}``."""
        points = self.spec.model.points
        return {name: self.formats.get(name) for name in self.spec.points_for(self.params) if points[name].cast}

    @property
    def inputs(self):
        """The names of the samples of one update (``("y",)`` for one observation)."""
        return tuple(name for name, _ in self.spec.inputs_for(self.params))

    @property
    def outputs(self):
        """The output fields (:class:`~kfpga.core.spec.Output`), in order."""
        return self.spec.outputs_for(self.params)

    @property
    def output_names(self):
        return tuple(o.name for o in self.outputs)

    def output(self, name):
        """The output field ``name``; ``KeyError`` if this model has none."""
        for o in self.outputs:
            if o.name == name:
                return o
        raise KeyError(name)

    def output_format(self, name):
        return self.point_format(self.output(name).point)

    def constants(self, variant):
        """``{name: (value, point) | structural}`` of ``variant`` (see :class:`~kfpga.core.spec.Variant`)."""
        return self.spec.model.variants[variant].constants(self.params)

    def constant_raw(self, variant):
        """``{name: raw int}`` of the quantised constants of ``variant`` (structural entries left out)."""
        fmt = self.formats.get
        return {name: int(to_raw(c.value, fmt(c.point) if isinstance(c.point, str) else c.point)[0])
                for name, c in self.constants(variant).items() if isinstance(c, Constant)}

    def point_format(self, point):
        """The format of ``point``: a point name's in :attr:`formats`, or ``point`` itself when it
        is a structural :class:`~kfpga.core.fixed.QFormat` (a flag, not a configurable point)."""
        return point if isinstance(point, QFormat) else self.formats[point]

    def reset_state(self, variant):
        """``{state name: raw int}``: the reset state of ``variant`` in its points' formats."""
        v = self.spec.model.variants[variant]
        points = dict(v.state_for(self.params))
        return {name: int(to_raw(value, self.point_format(points[name]))[0]) for name, value in v.initial(self.params).items()}

    def replace(self, **changes):
        """A copy with some fields changed (validated again)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}
        if "params" in changes and "formats" not in changes:
            fields["formats"] = {}
        fields.update(changes)
        return FilterConfig(**fields)

    # -- validation -------------------------------------------------------------------------
    def _validate_formats(self):
        f, spec = self.formats, self.spec
        if self.check_ranges:
            ranges = self.ranges()
            for name in (n for n in f if n in ranges):
                fmt = f[name]
                reach = max([ranges[name]] + [ranges[n] for n in f if spec.model.points[n].same_as == name and n in ranges])
                if not fmt.covers(reach):
                    raise ConfigError(
                        f"formats.{name} = {fmt} covers ±{fmt.max_value:g}, but the analysed range of "
                        f"{spec.model.points[name].description} reaches ±{reach:.6g}: it needs at least "
                        f"{bits_for(reach, fmt.frac_bits)} integer bits"
                    )
        spec.model.validate(self)
        for variant in spec.model.variants:
            if spec.model.variants[variant].applies(self.params) is None:
                self._check_widths(variant)

    def width_report(self, variant):
        """What :class:`~kfpga.core.ops.WidthOps` finds in the update of ``variant``."""
        return update_widths(self.spec, self.params, self.formats, variant, self.input_format)

    def _check_widths(self, variant):
        """Formats the update cannot be built with (a division whose dividend would not be an exact
        integer): the widths themselves are never refused."""
        try:
            self.width_report(variant)
        except ValueError as exc:
            raise ConfigError(f"formats: {exc}") from None

    def over_budget(self, variant):
        """The intermediates of ``variant``'s update wider than the word budget, widest first (the
        datapath builds them; the report shows them)."""
        return self.width_report(variant).past(self.max_word)

    def require_variant(self, variant):
        """Refuse a variant the filter does not have, or that these parameters cannot use."""
        spec = self.spec
        if variant not in spec.model.variants:
            raise ConfigError(f"variant must be one of {', '.join(spec.model.variants)} for the {spec.name} filter, "
                              f"not {variant!r}")
        why = spec.model.variants[variant].applies(self.params)
        if why:
            raise ConfigError(why)
        if self.check_ranges:
            self._check_precision(variant)

    def _check_precision(self, variant):
        """Refuse a constant or reset value that its format holds as 0, or more than
        :data:`PRECISION` off: the model would compute with another filter than the one asked for."""
        v = self.spec.model.variants[variant]
        values = [(c.label or name, c.value, c.point) for name, c in self.constants(variant).items()
                  if isinstance(c, Constant)]
        points = dict(v.state_for(self.params))
        values += [(f"the reset value of {name}", value, points[name]) for name, value in v.initial(self.params).items()]
        values += [(f"the settled value {label}", value, point) for label, value, point in v.settled(self.params)]
        for label, value, point in values:
            if value == 0 or not isinstance(point, str):
                continue  # exact (a structural format is made for its value)
            fmt = self.formats[point]
            raw, _ = to_raw(value, fmt)
            held = raw * fmt.lsb
            error = abs(held - value) / abs(value)
            if raw != 0 and error <= PRECISION:
                continue
            need = precision_frac_bits(value, fmt.rounding)
            what = label if label.startswith(("the reset", "the settled")) else "the constant " + label
            how = (f"rounds to 0 in formats.{point} = {fmt} (LSB {fmt.lsb:.3g})" if raw == 0 else
                   f"is held as {held:.4g} in formats.{point} = {fmt}, {100 * error:.2g} % off")
            raise ConfigError(f"{what} = {value:.4g} {how}: {point} needs at least {need} fraction bits to hold it "
                              f"within {100 * PRECISION:g} % ({variant} variant)")

    def require_hardware(self, variant, architecture=None):
        """Refuse a variant, or an architecture that cannot run it with these parameters (the
        folded core runs every variant)."""
        self.require_variant(variant)
        if architecture is not None:
            why = self.spec.why_not(variant, self.params, architecture)
            if why:
                raise ConfigError(why)
        return self

    # -- TOML ---------------------------------------------------------------------------
    @classmethod
    def from_toml(cls, path):
        """Load a config file (see docs/own-model.md for the layout)."""
        from kfpga.core.paths import read_text

        text = read_text(path, what="config file")
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not valid TOML: {exc}") from None
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_dict(cls, data, *, source="config", check_ranges=True):
        """A config from the tables of a TOML file: ``[filter]``, ``[model]``, ``[formats.*]``
        (``check_ranges``: as :class:`FilterConfig`'s)."""
        registry = _registry()
        unknown = set(data) - {"filter", "model", "formats", "board"}
        if unknown:
            raise ConfigError(f"{source}: unknown section(s) {', '.join(sorted(unknown))}; expected [filter], [model], "
                              "[formats.*] and [board]")
        table = _table(data, "filter", source)
        extra = set(table) - {"name"}
        if extra:
            raise ConfigError(f"{source}: unknown key(s) filter.{', filter.'.join(sorted(extra))}; [filter] has only "
                              "name (the parameters go in [model])")
        name = table.get("name", registry.DEFAULT)
        if not isinstance(name, str):
            raise ConfigError(f"{source}: filter.name must be a string, not {name!r}")
        try:
            spec = registry.get(name)
        except KeyError as exc:
            raise ConfigError(f"{source}: filter.name: {exc.args[0]}") from None
        params = params_from_dict(spec, _table(data, "model", source), source)
        formats, budget = {}, {}
        for point, value in _table(data, "formats", source).items():
            if point == "max_word":
                budget["max_word"] = value
            else:
                formats[point] = format_from_toml(point, value)
        return cls(filter=spec.name, params=params, formats=formats, check_ranges=check_ranges,
                   board=board_from_dict(_table(data, "board", source), source), **budget)

    def to_toml(self, *, formats=True):
        """The config as TOML text; ``formats=False`` writes the default formats commented out
        (the formats this config pins stay settings).

        Commented-out formats document the defaults without pinning them, so that a changed
        parameter in the file still gets formats fitted to it.
        """
        spec = self.spec
        lines = [
            "# kfpga configuration: the filter, its parameters and the format of every quantisation point.",
            "# Formats are Q<integer bits incl. sign>.<fraction bits>.",
            "[filter]",
            f'name = "{spec.name}"  # {spec.docs.summary}',
            "",
            "[model]",
        ]
        for f in dataclasses.fields(self.params):
            value = getattr(self.params, f.name)
            # TOML has no null: an unset optional parameter is written as a comment
            lines.append(f"# {f.name} is not set" if value is None else f"{f.name} = {_toml_value(value)}")
        if self.board != Board():
            lines += ["", "[board]"]
            if self.board.sample_rate_hz is not None:
                lines.append(f"sample_rate_hz = {_toml_value(self.board.sample_rate_hz)}")
            lines.append(f"clock_hz = {_toml_value(self.board.clock_hz)}")
        lines += ["", "[formats]", f"max_word = {self.max_word}  # the word budget of the default formats (bits)"]
        if not formats:
            lines += ["", "# The formats below are the defaults for these parameters (uncomment one to pin it), or"
                          " the ones this config pins."]
        for name in spec.points_for(self.params):
            fmt = self.formats.get(name)
            if fmt is None and name not in self.pinned:
                continue  # a cast point that keeps its value exact by default
            mark = "" if formats or name in self.pinned else "# "
            lines += ["", f"{mark}[formats.{name}]  # {spec.model.points[name].description}"]
            if fmt is None:
                lines.append(f'{mark}format = "{EXACT}"')
                continue
            lines += [f'{mark}format = "{fmt}"', f'{mark}rounding = "{fmt.rounding.value}"',
                      f'{mark}overflow = "{fmt.overflow.value}"']
        return "\n".join(lines) + "\n"


def _check_given(spec, names, given):
    """Refuse a given format for a point the model does not have, or that is not a format."""
    for name, fmt in given.items():
        if name not in spec.model.points:
            known = [n for n in names if not spec.model.points[n].cast]
            casts = "" if len(known) == len(names) else " and its cast points (kfpga formats lists them)"
            raise ConfigError(f"formats.{name}: unknown quantisation point; this model has {', '.join(known)}{casts}")
        if name not in names:
            raise ConfigError(f"formats.{name}: this {spec.name} model has no point {name} "
                              f"({spec.model.points[name].description})")
        if fmt == EXACT and not spec.model.points[name].cast:
            raise ConfigError(f"formats.{name} = \"exact\": only a cast point (a product's or a sum's own format) "
                              f"can keep its value exact; {name} is a {spec.model.points[name].role}")
        if not isinstance(fmt, QFormat) and fmt != EXACT:
            raise ConfigError(f"formats.{name} must be a QFormat, not {fmt!r}")


def board_from_dict(table, source="config"):
    """The :class:`~kfpga.core.board.Board` of a ``[board]`` table."""
    extra = set(table) - {"sample_rate_hz", "clock_hz"}
    if extra:
        raise ConfigError(f"{source}: unknown key(s) board.{', board.'.join(sorted(extra))}; [board] has "
                          "sample_rate_hz and clock_hz")
    try:
        return Board(**table)
    except ValueError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def _table(data, name, source):
    value = data.get(name, {})
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: {name} must be a table ([{name}]), not {value!r}")
    return value


def _toml_value(value):
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value)


def params_from_dict(spec, model, source="config"):
    """The filter's parameters from a ``[model]`` table; errors name ``model.<field>``."""
    known = [f.name for f in dataclasses.fields(spec.params)]
    for key in model:
        if key not in known:
            raise ConfigError(f"{source}: unknown key model.{key}; the {spec.name} filter has: {', '.join(known)}")
    try:
        return spec.params(**model)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"model.{exc}") from None


def format_from_toml(name, spec):
    """A format from ``"Q18.8"`` or a table ``{format | int_bits + frac_bits, rounding, overflow}``;
    :data:`EXACT` (``"exact"``, or ``format = "exact"``) for a cast point that keeps its value exact.

    Omitted rules keep the defaults (``nearest``, ``saturate``).
    """
    from kfpga.core.fixed import Overflow, Rounding

    if isinstance(spec, str):
        spec = {"format": spec}
    if isinstance(spec, dict) and spec.get("format") == EXACT:
        if set(spec) != {"format"}:
            raise ConfigError(f"formats.{name}: an exact cast has no {', '.join(sorted(set(spec) - {'format'}))}")
        return EXACT
    if not isinstance(spec, dict):
        raise ConfigError(f"formats.{name} must be a string like \"Q18.8\" or a table, not {spec!r}")
    unknown = set(spec) - {"format", "int_bits", "frac_bits", "rounding", "overflow"}
    if unknown:
        raise ConfigError(f"formats.{name}: unknown key(s) {', '.join(sorted(unknown))}")
    if "format" in spec and ({"int_bits", "frac_bits"} & set(spec)):
        raise ConfigError(f"formats.{name}: give either format or int_bits and frac_bits, not both")
    try:
        rules = {"rounding": spec.get("rounding", Rounding.NEAREST.value),
                 "overflow": spec.get("overflow", Overflow.SATURATE.value)}
        if "format" in spec:
            fmt = QFormat.parse(spec["format"], **rules)
        elif "int_bits" in spec and "frac_bits" in spec:
            fmt = QFormat(spec["int_bits"], spec["frac_bits"], **rules)
        else:
            raise ValueError("give format = \"Q<int>.<frac>\" or both int_bits and frac_bits")
    except ValueError as exc:
        raise ConfigError(f"formats.{name}: {exc}") from None
    return fmt
