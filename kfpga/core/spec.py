"""What a filter is: the description every layer (model, RTL, CLI, benches, tests) reads.

A filter is a :class:`FilterSpec` in the registry (``kfpga/core/registry.py``), in four parts: its
:class:`Docs` (names, summary, source), its :class:`Model` (points, state, update, float reference),
its :class:`Hardware` (resource goals, the designs of the mutation and formal runs, a pre-filter's
place on the board) and its :class:`Evaluation`. Its arithmetic is written once, as stage functions
over an ``ops`` object (``kfpga/core/ops.py``); everything else a small filter leaves out has a
default.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import NamedTuple

__all__ = ["Point", "Output", "Variant", "FilterSpec", "Docs", "Model", "Hardware", "Constant", "Evaluation", "Mode",
           "Prefilter", "MutationBlock", "Build", "resolve", "ARCHITECTURES"]

#: The architectures a core can have: ``parallel`` (a filter's own core: its update spread over
#: pipeline stages, channels interleaved) and ``folded`` (``hw/folded.py``: the update as microcode,
#: one multiply-accumulate step at a time on one 18 x 18 multiplier, the state in block memory).
ARCHITECTURES = ("parallel", "folded")


def resolve(target):
    """``target`` itself, or the object a ``"module:attribute"`` string names (an entry point's
    value, or an evaluation in its filter's own layer), imported on first use."""
    if not isinstance(target, str):
        return target
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


class Constant(NamedTuple):
    """A constant of an update: a real value, quantised once into the format of ``point`` (a point
    name or a :class:`~kfpga.core.fixed.QFormat`); ``label`` names it in messages (``T^2*Q``)."""

    value: float
    point: object
    label: str | None = None


@dataclass(frozen=True)
class Point:
    """A quantisation point: one format shared by every value written into it.

    Parameters
    ----------
    name, description:
        The point's name (``formats.<name>`` in a config) and what it holds.
    role:
        ``"register"`` (a state or output register: the analysed range plus a guard bit, and
        ``frac`` fraction bits), ``"operand"`` (feeds an embedded multiplier: as many
        fraction bits as an 18-bit word leaves) or ``"cast"`` (a product's or a sum's own result
        format, :meth:`~kfpga.core.ops.Ops.cast`: optional, the value stays exact without one; by
        default it gets one where the exact sum it enters would pass the word budget).
    variants:
        The variants that write it (empty: all).
    frac:
        Fraction bits of a register by default: an integer, or the name of a point to copy
        them from (``None``: the config's state fraction bits).
    same_as:
        The point shares this point's format (the range check covers both).
    constant:
        It holds only constants: no guard bit.
    """

    name: str
    description: str
    role: str = "register"
    variants: tuple = ()
    frac: int | str | None = None
    same_as: str | None = None
    constant: bool = False

    def __post_init__(self):
        if self.role not in ("register", "operand", "cast"):
            raise ValueError(f"role must be 'register', 'operand' or 'cast', not {self.role!r}")

    @property
    def operand(self):
        return self.role == "operand"

    @property
    def cast(self):
        """An optional result format of a product or a sum (no format: the value stays exact)."""
        return self.role == "cast"


@dataclass(frozen=True)
class Output:
    """An output field: a CSV column, a payload field of the core, a scoreboard field.

    ``point``: the quantisation point it is written in, or a structural
    :class:`~kfpga.core.fixed.QFormat` (a count, a mode: not a configurable point)."""

    name: str
    point: object
    description: str


@dataclass(frozen=True)
class Variant:
    """One form of a filter's update, run by the model and built by the core.

    Parameters
    ----------
    name, summary:
        The ``--variant`` name and a line for ``--help``.
    state:
        ``((name, point), ...)``: the registers the update carries from one sample to the
        next, each held in the format of its point; or ``state(params) -> that``.
    constants:
        ``constants(params) -> {name: Constant(value, point) | structural value}``: each
        :class:`Constant` is quantised once into the point's format, the same integers in the
        model and the RTL; other entries (a shift amount, a size, a flag) reach the update
        unchanged.
    initial:
        ``initial(params) -> {state name: real value}``: the state after reset.
    update:
        ``update(ops, k, x, u) -> (x_next, outputs)``: ``k`` the constants, ``x`` the state,
        ``u`` the inputs, all :class:`~kfpga.core.ops.Fx`; returns dicts of Fx.
    applies:
        ``applies(params) -> None | why not``: whether these parameters can use the variant.
    hardware:
        ``hardware(params) -> None | why not``: whether the filter's parallel core runs the
        variant with these parameters (the folded core runs every variant).
    settled:
        ``settled(params) -> [(label, value, point), ...]``: values the update settles to (the
        steady-state covariance of a time-varying gain), which, like the constants, their
        points must hold within 1 %.
    predict:
        ``predict(ops, k, x) -> (x_next, outputs)``: the update of a sample with no measurement
        (a lost sample: ``x = F x``, ``P = F P F' + G Q G'``), the same outputs; ``None``: every
        sample is a measurement.
    """

    name: str
    summary: str
    state: tuple
    constants: Callable
    initial: Callable
    update: Callable
    applies: Callable = field(default=lambda params: None)  # params -> None or why not
    hardware: Callable = field(default=lambda params: None)  # params -> None or why the parallel core cannot
    settled: Callable = field(default=lambda params: [])  # params -> [(label, value, point)]
    predict: Callable | None = None  # (ops, k, x) -> (x_next, outputs) with no measurement

    def state_for(self, params):
        """``((name, point), ...)`` of a model with these parameters."""
        return tuple(self.state(params) if callable(self.state) else self.state)


@dataclass(frozen=True)
class Evaluation:
    """A filter's evaluation of its source document: ``kfpga evaluate NAME``.

    Parameters
    ----------
    summary, description:
        A line for the list of evaluations, and the paragraph of its ``--help``.
    add_arguments:
        ``add_arguments(parser)``: its own options (the command adds ``--seed``, ``--json`` and
        ``--plot`` to every evaluation).
    run:
        ``run(options, seed) -> result``: a dict; ``options`` the parsed arguments. A bad option
        raises :class:`~kfpga.core.errors.UsageError` (or ``InputError`` for a file).
    table:
        ``table(result) -> str``: the report.
    summary_json:
        ``summary_json(result) -> dict``: what ``--json`` prints.
    claims:
        ``claims(options, result, measures) -> [Claim]``: every quantitative claim of the source
        document (:class:`~kfpga.core.claims.Claim`), judged on ``measures``, one per seed of the
        run (``result`` is the full run of the first seed); the command prints them and writes
        them under ``claims`` in ``--json``.
    measure:
        ``measure(options, seed) -> dict``: what the claims need from one seed, cheaper than a full
        ``run`` (the command calls it for every seed); ``None``: ``run`` itself.
    plot:
        ``plot(result, path)``: its figures; ``None`` if it has none.
    seeded:
        ``seeded(options) -> bool``: whether a run with these options draws random numbers
        (a run on a file may not); by default always.
    check:
        ``check(options)``: refuse bad options before anything runs or is printed (raises
        :class:`~kfpga.core.errors.UsageError`).
    """

    summary: str
    description: str
    add_arguments: Callable
    run: Callable
    table: Callable
    summary_json: Callable
    claims: Callable
    measure: Callable | None = None
    plot: Callable | None = None
    seeded: Callable = field(default=lambda options: True)
    check: Callable = field(default=lambda options: None)


@dataclass(frozen=True)
class Mode:
    """A form of ``kfpga filter`` that only this filter has, chosen by its own option.

    Parameters
    ----------
    option:
        The option (``--tracks``), added to ``kfpga filter`` with ``argument`` (argparse keywords);
        given for another filter it is refused.
    columns:
        ``columns(config, value) -> names``: the CSV columns it reads.
    run:
        ``run(config, variant, samples, value, *, exact, source) -> (columns, note)``: ``samples``
        ``{column: array}``; ``exact``: the bit-accurate model (else float); ``source``: the file's
        name for messages. Returns the output columns and a line for the report.
    example:
        The mode's arguments in the examples of ``kfpga filter --help`` (its option, the files).
    """

    option: str
    argument: Mapping
    columns: Callable
    run: Callable
    example: str = ""

    @property
    def dest(self):
        return self.option.lstrip("-").replace("-", "_")


@dataclass(frozen=True)
class Prefilter:
    """How a filter stands before another on the board, between the ADC controller and the core.

    Parameters
    ----------
    summary:
        What it does there (the help of ``--prefilter``).
    delay:
        Samples its output is late (the core's estimate of sample ``n`` comes ``delay`` later).
    options:
        ``{option: argparse keywords}``: its own options on the commands that take ``--prefilter``.
    params:
        ``params(values) -> its parameters`` from ``{option dest: value}`` (``None`` for an option
        not given); raises ``ValueError`` or ``TypeError`` for a bad value.
    bound:
        ``bound(params) -> codes``: the largest step it passes unchanged (glitches beyond it are
        replaced), the yardstick of the glitch counts.
    """

    summary: str
    delay: int
    options: Mapping
    params: Callable
    bound: Callable


@dataclass(frozen=True)
class MutationBlock:
    """A core of this filter for ``make mutate``: a config on the core bench.

    ``signal``: the bench's stimulus parameters (``samples``, or ``codes`` and ``order``);
    ``channels``: the core's channel states."""

    label: str
    config: object
    variant: str
    signal: Mapping
    channels: int = 1


class Build(NamedTuple):
    """A core to elaborate: ``config`` on ``variant`` with ``channels`` channel states, on
    ``architecture`` (``None``: each that runs it), ``options`` for the core (``stages``, ...)."""

    config: object
    variant: str
    channels: int = 1
    architecture: str | None = None
    options: Mapping = MappingProxyType({})


def _no_check(config):
    return None


@dataclass(frozen=True)
class Docs:
    """How a filter is named and described.

    Parameters
    ----------
    summary:
        One line for ``kfpga filters``.
    source:
        The document it comes from (a key of the manual's references, ``[Zhong]: ...``).
    aliases:
        Other names users type for it (``--filter``, ``[filter] name``, ``kfpga evaluate``).
    """

    summary: str
    source: str
    aliases: tuple = ()


@dataclass(frozen=True)
class Model:
    """A filter's bit-accurate model: its points, state, update and float reference.

    Required
    --------
    points:
        Its quantisation points (:class:`Point`), ``{name: Point}`` in datapath order.
    outputs:
        Its output fields (:class:`Output`), in order; or ``outputs(params) -> that``.
    variants:
        ``{name: Variant}``; the first is the default.
    reference:
        ``reference(params, variant, y) -> {output: float array}``: the float filter.
    ranges:
        ``ranges(params, stimulus=None) -> {point: largest magnitude}`` from float runs
        (``kfpga.model.ranges.float_ranges`` runs the variants on a stimulus).

    With defaults
    -------------
    inputs:
        ``((name, description), ...)``: the samples of one update, each a 16-bit ADC code; or
        ``inputs(params) -> that``. Default: one input ``y``.
    default_output:
        The output that drives ``out_data`` on the board; default: the first.
    points_for:
        ``points_for(params) -> names``: the points a config of these parameters has; default:
        every point.
    default_formats:
        ``default_formats(params, ranges, *, operand_bits, state_frac, max_word) -> {point: QFormat}``
        (``max_word``, the word budget, may be left out of the signature; the cast points' formats
        are the config's, from :func:`~kfpga.core.formats.cast_formats`); default: the register and
        operand rules of :func:`~kfpga.core.formats.register_formats`.
    validate:
        ``validate(config)``: checks beyond formats and widths (raises ``ConfigError``); default: none.
    random_params:
        ``random_params(rng) -> params``: valid random parameters for the contract tests' random
        configs (the formats around them are randomised by the tests); default: the defaults.
    scenario:
        ``scenario(name, n, seed, params) -> (truth of the default output, codes)``: the test
        signals of ``compare``, ``sweep`` and ``simulate`` (``codes`` an array for one input,
        else ``{input: array}``); ``None`` uses ``model/scenarios.py`` on one input.
    scenarios:
        The names its ``scenario`` hook (or the generic scenarios) knows, the default first.
    presets:
        ``{name: (summary, params factory)}``: named models, ``--preset NAME``.
    measured:
        ``measured(params) -> input name | None``: the input that observes the default output
        itself, whose error is the "raw" RMSE of ``compare``; ``None`` takes the only input of a
        one-input filter.
    adc:
        ``adc(params) -> (channel per input) | None``: the ADS8364 channels the parameters name
        for the inputs; ``None`` leaves them to the board's defaults.
    error_std:
        ``error_std(params) -> {output: std}``: the float filter's steady-state error of each
        output (input units), the yardstick of the outputs no truth comes with (``propose``).
    period:
        ``period(params) -> (seconds, used)``: the sample period the model is made for, and whether
        its arithmetic uses it (a rate scaled by T) or only describes it; ``None``: the model has
        no period (a board rate is then its own choice).
    modes:
        Its extra forms of ``kfpga filter`` (:class:`Mode`).
    """

    points: Mapping
    outputs: tuple
    variants: Mapping
    reference: Callable
    ranges: Callable
    inputs: tuple = (("y", "the sample (a 16-bit ADC code)"),)
    default_output: str | None = None
    points_for: Callable | None = None
    default_formats: Callable | None = None
    validate: Callable = _no_check
    random_params: Callable | None = None
    scenario: Callable | None = None
    scenarios: tuple = ("sine", "random-accel", "model")
    presets: Mapping = field(default_factory=dict)
    measured: Callable | None = None
    adc: Callable | None = None
    error_std: Callable | None = None
    period: Callable | None = None
    modes: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "points", MappingProxyType(dict(self.points)))
        object.__setattr__(self, "variants", MappingProxyType(dict(self.variants)))
        object.__setattr__(self, "presets", MappingProxyType(dict(self.presets)))


@dataclass(frozen=True)
class Hardware:
    """What the hardware layers need of a filter beyond its model; every part has a default.

    Its parallel core, if it has one, is an entry point of the ``kfpga.cores`` group naming the
    core's factory in ``hw/`` (``f(config, variant, *, channels)``); the folded core runs every
    filter (``kfpga.hw.cores.make_core`` builds either).

    Parameters
    ----------
    goals:
        ``goals(config, variant, channels) -> {"logic_cells": n, "mul18": n, "lut_levels": n}``: the
        resource goals of the core with ``channels`` channel states; ``None``: none beyond the device's.
    mutation:
        ``mutation() -> [MutationBlock, ...]``: its cores for ``make mutate``.
    formal_config:
        ``formal_config() -> FilterConfig``: a narrow instance for the formal stream-contract
        checks (``make formal``), for a core whose default datapath is too wide for the solver at
        the depth its pipeline needs; its handshake logic must not depend on the formats.
        ``None``: the default config.
    coverage:
        ``coverage() -> {label: FilterConfig | Build}``: designs beyond its defaults and presets
        whose cores take other branches (a sample period that is not a power of two, another core
        class), elaborated for the source-level mutants (``make mutate-source``): a config on every
        variant and architecture, a :class:`Build` as it is.
    prefilter:
        A :class:`Prefilter` if it can stand before another filter on the board.
    """

    goals: Callable | None = None
    mutation: Callable | None = None
    formal_config: Callable | None = None
    coverage: Callable | None = None
    prefilter: Prefilter | None = None


@dataclass(frozen=True)
class FilterSpec:
    """A registered filter (see ``kfpga/core/registry.py`` and the manual's "Add a filter", docs/filters/index.md).

    Parameters
    ----------
    name:
        ``--filter`` name (the stem of its files in every layer).
    params:
        Its parameters: a keyword-only dataclass that validates itself (``TypeError`` for a
        wrong type, ``ValueError`` for a wrong value). The defaults are the source's.
    docs:
        Its :class:`Docs`: summary, source document, aliases.
    model:
        Its :class:`Model`.
    hardware:
        Its :class:`Hardware` (default: none of its parts).
    evaluation:
        Its source document's evaluation: an :class:`Evaluation`, or ``"module:attribute"`` naming
        one in its own layer (imported when ``kfpga evaluate`` is run); ``None``: it has none.
    """

    name: str
    params: type
    docs: Docs
    model: Model
    hardware: Hardware = Hardware()
    evaluation: object = None

    def __post_init__(self):
        for part, kind in (("docs", Docs), ("model", Model), ("hardware", Hardware)):
            if not isinstance(getattr(self, part), kind):
                raise TypeError(f"{part} must be a {kind.__name__}, not {getattr(self, part)!r}")
        names = [o.name for o in self.outputs_for(self.params())]
        if self.model.default_output is None:
            object.__setattr__(self, "model", replace(self.model, default_output=names[0]))
        if self.model.default_output not in names:
            raise ValueError(f"default_output must be one of {', '.join(names)}, not {self.model.default_output!r}")

    def inputs_for(self, params):
        """``((name, description), ...)`` of a model with these parameters."""
        inputs = self.model.inputs
        return tuple(inputs(params) if callable(inputs) else inputs)

    def outputs_for(self, params):
        """The output fields of a model with these parameters."""
        outputs = self.model.outputs
        return tuple(outputs(params) if callable(outputs) else outputs)

    def points_for(self, params):
        """The names of the points a config of these parameters has."""
        model = self.model
        return list(model.points) if model.points_for is None else list(model.points_for(params))

    def random_params(self, rng):
        """Valid random parameters (the defaults when the model draws none)."""
        return self.params() if self.model.random_params is None else self.model.random_params(rng)

    def adc_channels(self, params, channel=None):
        """The ADC channel of each input on the board: the parameters' own, else ``channel``
        (default 0) for one input, 0, 1, ... for several. A ``channel`` that contradicts the
        parameters raises ``ValueError``."""
        given = self.model.adc(params) if self.model.adc is not None else None
        count = len(self.inputs_for(params))
        if given is not None:
            if channel is not None and tuple(given) != (channel,):
                raise ValueError(f"the model's adc = {list(given)} names the ADC channel(s) of its input(s); "
                                 f"channel {channel} contradicts it")
            return tuple(given)
        if count == 1:
            return (0 if channel is None else channel,)
        if channel is not None:
            raise ValueError(f"a model with {count} inputs reads one ADC channel each (model.adc, default "
                             f"{list(range(count))}); a single channel does not apply")
        return tuple(range(count))

    def measured_input(self, params):
        """The input that observes the default output directly, or ``None``."""
        if self.model.measured is not None:
            return self.model.measured(params)
        names = self.inputs_for(params)
        return names[0][0] if len(names) == 1 else None

    @property
    def default_variant(self):
        return next(iter(self.model.variants))

    @property
    def parallel(self):
        """Whether it has a parallel core of its own (an entry point of ``kfpga.cores``)."""
        from kfpga.core import registry  # the registry imports this module

        return registry.core_target(self.name) is not None

    def architectures(self, variant, params):
        """The architectures that run ``variant`` with ``params``, the parallel one first when it can."""
        parallel = self.parallel and self.model.variants[variant].hardware(params) is None
        return ("parallel", "folded") if parallel else ("folded",)

    def why_not(self, variant, params, architecture):
        """``None`` if ``architecture`` runs ``variant`` with ``params``, else why not."""
        if architecture not in ARCHITECTURES:
            return f"architecture must be one of {', '.join(ARCHITECTURES)}, not {architecture!r}"
        if architecture in self.architectures(variant, params):
            return None
        if not self.parallel:
            return f"the {self.name} filter has no parallel core: it runs on the folded core"
        return self.model.variants[variant].hardware(params)

    def load_evaluation(self):
        """Its :class:`Evaluation`, or ``None``."""
        return None if self.evaluation is None else resolve(self.evaluation)
