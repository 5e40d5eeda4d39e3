"""What the commands share: argument types, option groups, loading the config, the signal of a
run, JSON output, and the pre-filter and filter-mode options every registered filter brings."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import secrets
import sys
from pathlib import Path

import numpy as np

from kfpga.core import registry
from kfpga.core.errors import UsageError
from kfpga.hw.cores import make_core

EXIT_USAGE = 2
PLOT_EXTENSIONS = (".png", ".svg", ".pdf")


def int_at_least(minimum, what):
    """An argparse type: an integer >= ``minimum``, described as ``what`` in the error."""

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"must be {what}, not {text!r}")
        return value

    return parse


positive_int = int_at_least(1, "a positive integer")
seed_type = int_at_least(0, "an integer >= 0")


def bit_range(text):
    try:
        lo, hi = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must look like 10:24, not {text!r}") from None
    if not 4 <= lo <= hi <= 32:
        raise argparse.ArgumentTypeError(f"needs 4 <= first <= last <= 32, not {text!r}")
    return list(range(lo, hi + 1))


def budget(text):
    """``--budget``: a share of the float RMSE, written ``1%`` or ``1`` (percent), in (0, 100]."""
    value = text.strip().removesuffix("%").strip()
    try:
        pct = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a percentage like 1% or 0.5%, not {text!r}") from None
    if not 0 < pct <= 100:
        raise argparse.ArgumentTypeError(f"must be more than 0 % and at most 100 %, not {text!r}")
    return pct / 100.0


def adc_channel(text):
    from kfpga.hw.ads8364_timing import CHANNELS

    if text.upper() in CHANNELS:
        return CHANNELS.index(text.upper())
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 5:
        raise argparse.ArgumentTypeError(f"must be 0..5 or one of {', '.join(CHANNELS)}, not {text!r}")
    return value


# -- the config -----------------------------------------------------------------------------------


def _filter_name(name):
    try:
        return registry.canonical(name)
    except KeyError:
        raise UsageError(f"--filter: no filter named {name!r}; registered: {', '.join(registry.names())}") from None


def _preset_config(args, preset, name):
    from kfpga.core.config import FilterConfig

    if args.config:
        raise UsageError(f"--preset and --config both give the model: use one (to edit the preset, write it with "
                         f"'kfpga formats --preset {preset} --toml > {preset}.toml' and pass --config {preset}.toml)")
    known = registry.presets()
    if preset not in known:
        raise UsageError(f"--preset: no preset named {preset!r}; presets: {', '.join(known)}")
    filter_name, params = registry.preset(preset)
    if name is not None and name != filter_name:
        raise UsageError(f"--filter {name} does not match --preset {preset}, a model of the {filter_name} filter")
    return FilterConfig(filter=filter_name, params=params)


def load_config(args, *, hardware=False):
    """The config of ``--config``, ``--preset`` and ``--filter`` (which must agree), with ``--variant``
    checked (``hardware``: and refused when it has no core for this model)."""
    from kfpga.core.config import FilterConfig

    name = getattr(args, "filter", None)
    name = None if name is None else _filter_name(name)
    preset = getattr(args, "preset", None)
    if preset is not None:
        config = _preset_config(args, preset, name)
    elif args.config:
        config = FilterConfig.from_toml(args.config)
        if name is not None and name != config.filter:
            raise UsageError(f"--filter {name} does not match {args.config}, whose [filter] name is {config.filter!r}")
    else:
        config = FilterConfig(filter=name or registry.DEFAULT)
    if hasattr(args, "variant"):
        if args.variant is None:
            args.variant = config.spec.default_variant
        (config.require_hardware if hardware else config.require_variant)(args.variant)
    _check_period(config)
    _scenario(args, config)
    return config


def _scenario(args, config):
    """``--scenario``: one the filter knows (its default when not given and no file is)."""
    if not hasattr(args, "scenario") or getattr(args, "input", None):
        return
    known = config.spec.model.scenarios
    if args.scenario is None:
        args.scenario = known[0]
    elif args.scenario not in known:
        raise UsageError(f"--scenario: the {config.filter} filter's scenarios are {', '.join(known)}, not "
                         f"{args.scenario!r}")


def _check_period(config):
    """A model's sample period against the board's rate: refused when the filter's arithmetic uses
    the period (a rate scaled by T would be wrong by their ratio), else a warning."""
    rate, spec = config.board.sample_rate_hz, config.spec
    if rate is None or spec.model.period is None:
        return
    seconds, used = spec.model.period(config.params)
    if abs(rate * seconds - 1.0) <= 0.01:
        return
    text = (f"[model] T = {seconds:g} s is a rate of {1 / seconds:g} Hz, but [board] sample_rate_hz = {rate:g}: "
            "the filter would update at another rate than its model's")
    if used:
        raise UsageError(text + "; make them agree")
    print(f"warning: {text} (its F holds T)", file=sys.stderr)


def warn_precision(config):
    """Warnings about output steps coarse against the float filter's noise, on stderr."""
    from kfpga.flows.analysis import precision_warnings

    for line in precision_warnings(config):
        print(f"warning: {line}", file=sys.stderr)


# -- output ---------------------------------------------------------------------------------------


def progress_bar(quiet=False, **options):
    """A tqdm progress bar on stderr, shown only on a terminal (a log file or a CI run gets no
    frames) and never with ``quiet``."""
    from tqdm import tqdm

    return tqdm(file=sys.stderr, disable=True if quiet else None, **options)


def pick_seed(seed):
    return secrets.randbelow(2**31) if seed is None else seed


def emit_json(obj):
    def clean(value):
        if isinstance(value, float) and not math.isfinite(value):
            return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, list | tuple):
            return [clean(v) for v in value]
        if isinstance(value, np.integer | np.floating):
            return clean(value.item())
        return value

    print(json.dumps(clean(obj), indent=2))


def info(text):
    print(text, file=sys.stderr)


def check_plot(path, option="--plot"):
    """``--plot FILE``: an image file matplotlib writes, in a folder that exists."""
    from kfpga.core.paths import check_output_file

    return None if path is None else str(check_output_file(path, option=option, extensions=PLOT_EXTENSIONS))


def not_with(option, other, why):
    """Refuse ``option`` (given) in combination with ``other``: it would be ignored."""
    raise UsageError(f"{option} does not apply with {other}: {why}")


# -- help texts from the registry -------------------------------------------------------------------


class ExamplesFormatter(argparse.HelpFormatter):
    """argparse's formatter, but an ``examples:`` epilog keeps its lines as written."""

    def _fill_text(self, text, width, indent):
        if text.startswith("examples:"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


def filter_help():
    aliases = registry.aliases()
    also = f"; also {', '.join(f'{a} ({n})' for a, n in aliases.items())}" if aliases else ""
    return f"the filter: {', '.join(registry.names())} (default: {registry.DEFAULT}{also}; see 'kfpga filters')"


def variant_help():
    parts = [f"{s.name}: {', '.join(s.model.variants)}" for s in registry.specs()]
    return f"the filter's variant ({'; '.join(parts)}; default: the first)"


def _fields(spec):
    """A filter's output fields for a help text: its own, or, where they follow the model (the
    general filter: one per state and observation), the pattern."""
    if callable(spec.model.outputs):
        return "x1..xn and yhat1..yhatm of its n states and m observations"
    return ", ".join(o.name for o in spec.outputs_for(spec.params()))


def out_field_help():
    parts = [f"{s.name}: {_fields(s)}, default {s.model.default_output}" for s in registry.specs()]
    return f"the output field that drives out_data ({'; '.join(parts)}); the pin table follows its width"


def preset_help():
    names = ", ".join(f"{n} ({f})" for n, (f, _) in registry.presets().items())
    return f"a named model instead of --config: {names}; 'kfpga filters' describes them"


# -- option groups ----------------------------------------------------------------------------------


def add_filter_args(p, variant=True):
    p.add_argument("--filter", metavar="NAME", help=filter_help())
    p.add_argument("--preset", metavar="NAME", help=preset_help())
    if variant:
        p.add_argument("--variant", metavar="NAME", help=variant_help())


def add_signal_args(p, *, files=False):
    """--scenario, --input (``files``: repeatable), --clip, --samples, --seed, --config, --settle."""
    add_filter_args(p)
    p.add_argument("--scenario", metavar="NAME",
                   help="test signal when --input is not given: sine (the paper's, plus white noise of variance R; "
                        "each axis its own), random-accel (a random-acceleration track), model (the model's own "
                        "process); a filter may have its own ('kfpga filters' lists them; default: its first)")
    if files:
        p.add_argument("--input", metavar="CSV", action="append",
                       help="a recording to use instead of a scenario: its input columns and its 'truth' (repeat "
                            "for several files)")
    else:
        p.add_argument("--input", metavar="CSV", help="use the input columns of CSV ('y', or the model's observation "
                                                      "names; and 'truth' if present) instead of a scenario")
    p.add_argument("--clip", action="store_true", help="with --input: saturate values outside the 16-bit range "
                                                        "instead of failing")
    p.add_argument("--samples", type=positive_int, metavar="N",
                   help="number of samples (default: 20000, or the whole --input; at most its rows)")
    p.add_argument("--seed", type=seed_type, metavar="S", help="noise seed of a scenario (default: random, printed)")
    p.add_argument("--config", metavar="TOML", help="model parameters and formats (default: built-in, see 'kfpga formats')")
    p.add_argument("--settle", type=int, metavar="N",
                   help="samples skipped by the RMSE figures (default: the start-up, at least 100)")


def add_design_args(p, channels_help):
    """--filter, --variant, --channels, --config, --architecture, --prefilter: the arguments of the
    commands that build hardware."""
    add_filter_args(p)
    p.add_argument("--channels", type=channels_type, default=1, metavar="N",
                   help=channels_help + "; any other N up to 256: N sensors taking turns on one ADC channel "
                        "(--channel) through an analog multiplexer, its select on the mux_sel pins, each sensor its "
                        "own channel state")
    p.add_argument("--config", metavar="TOML", help="model parameters, formats and [board] rate")
    p.add_argument("--architecture", choices=("auto", "parallel", "folded"), default="auto",
                   help="the core: parallel (the update over pipeline stages), folded (one multiply-accumulate step "
                        "at a time, from microcode), or auto: the cheapest design whose estimated Fmax is at least "
                        "1.25 x the clock and whose throughput covers the sample rate (see 'kfpga explore'; default: "
                        "auto)")
    p.add_argument("--stages", type=positive_int, metavar="N",
                   help="with --architecture parallel: the register stages of the filter's loop (default: the "
                        "core's; 'kfpga explore' lists what each gives)")
    add_prefilter_args(p)


def channels_type(text):
    """``--channels``: 1 (one ADC channel), 6 (the six) or 2..256 sensors on a multiplexer."""
    from kfpga.core.board import MAX_CHANNELS

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer 1..{MAX_CHANNELS}, not {text!r}") from None
    if not 1 <= value <= MAX_CHANNELS:
        raise argparse.ArgumentTypeError(f"must be an integer 1..{MAX_CHANNELS}, not {value}")
    return value


def sensors(args):
    """Sensors on a multiplexer in front of one ADC channel: ``--channels`` other than 1 and 6, else 1."""
    return args.channels if args.channels not in (1, 6) else 1


def check_sensors(args, pre=None):
    """Refuse what does not go with sensors on a multiplexer (``--channels`` other than 1 and 6)."""
    if sensors(args) > 1 and pre is not None:
        not_with("--prefilter", f"--channels {args.channels}",
                 "a pre-filter keeps a state per ADC channel, not per sensor on a multiplexer")


def check_rate(args, config):
    """The board's sample rate against what the ADS8364 converts for ``--channels`` (at
    ``--ratio`` where the command has it): one line, exit 2, when it cannot."""
    if config.input_format.width != 16:
        raise UsageError(f"input_bits = {config.input_format.width}: the board's ADS8364 gives 16-bit codes; wider "
                         "inputs are for the core alone (kfpga generate --core-only)")
    channels = 6 if args.channels == 6 or len(config.inputs) > 1 else 1
    try:
        config.board.check(channels, getattr(args, "ratio", 10), sensors(args))
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def core_prefix(args, config):
    """``--prefix`` of ``--core-only`` (default ``kfpga_FILTER``), checked."""
    from kfpga.flows.coreip import check_prefix

    prefix = args.prefix or f"kfpga_{config.filter}"
    try:
        return check_prefix(prefix)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def need_hz(config, channels):
    """Updates a second the core must make: the board's rate on every channel; 0 without one (the
    ADC then converts as fast as the core takes its samples: a slower core paces it)."""
    return (config.board.sample_rate_hz or 0.0) * channels


def explore(config, variant, channels, *, quiet=False, missing=False, bus=None):
    """Every candidate design (``kfpga.flows.explore``), with a progress bar."""
    from kfpga.flows.explore import candidates

    # no bar when stderr is not a terminal (a log, a test): only the line of the choice
    with progress_bar(quiet, desc="explore", unit="design") as bar:
        def progress(i, total, label):
            bar.total = total
            bar.n = i
            bar.set_postfix_str(f"{label} (yosys; the first run on a machine compiles it, ~35 s)")
            bar.refresh()

        found = candidates(config, variant, channels=channels, clock_hz=config.board.clock_hz,
                           need_hz=need_hz(config, channels), progress=progress, missing=missing, bus=bus)
        bar.n = len(found)
    return found


def check_architecture(args, config):
    """Refuse an ``--architecture`` that cannot run the variant, and ``--stages`` that does not
    apply or that the loop does not have (before anything is printed)."""
    if args.architecture != "auto":
        why = config.spec.why_not(args.variant, config.params, args.architecture)
        if why:
            raise UsageError(f"--architecture {args.architecture}: {why}")
    stages = getattr(args, "stages", None)
    if stages is None:
        return
    if args.architecture != "parallel":
        raise UsageError("--stages applies with --architecture parallel (the folded core has no stages; auto "
                         "chooses them)")
    from kfpga.hw.generate import figures_only

    try:
        figures_only(make_core(config, args.variant, architecture="parallel", stages=stages))
    except (ValueError, TypeError) as exc:
        raise UsageError(f"--stages: {exc}") from None


def architecture(args, config, channels):
    """The core's architecture of ``--architecture``: checked when given, chosen by :func:`explore`
    for ``auto`` (``UsageError`` when no design meets the clock and the rate)."""
    from kfpga.flows.explore import FMAX_MARGIN, choose

    chosen = args.architecture
    args.candidates = None
    missing, bus = getattr(args, "missing", False), getattr(args, "bus", None)
    if (missing or bus) and chosen == "parallel":
        raise UsageError(f"--architecture parallel: {'--bus' if bus else '--missing'} applies to the folded core")
    if chosen != "auto":
        check_architecture(args, config)
        return chosen
    found = explore(config, args.variant, channels, quiet=getattr(args, "quiet", False), missing=missing, bus=bus)
    args.candidates = found
    best = choose(found)
    if best is None and not any(c.fits for c in found):
        smallest = min(found, key=lambda c: (c.m4k_blocks, c.logic_cells))
        raise UsageError(f"no design of the {args.variant} variant fits the EP2C20: the smallest, {smallest.label}, "
                         f"takes {smallest.over_device}; see 'kfpga explore'")
    if best is None:
        fastest = max(found, key=lambda c: c.fmax_mhz)
        raise UsageError(f"no design of the {args.variant} variant meets the {config.board.clock_hz / 1e6:g} MHz clock "
                         f"and the rate: the fastest, {fastest.label}, is estimated at {fastest.fmax_mhz:g} MHz "
                         f"({fastest.worst_path}); see 'kfpga explore'")
    args.stages = best.stages
    margin = "" if best.meets else (f"; no design has the {FMAX_MARGIN:g} x margin over the clock, this one the "
                                    "most economical that meets it")
    info(f"architecture: {best.label} ({best.logic_cells} logic cells, {best.fmax_mhz:g} MHz estimated{margin}; "
         "'kfpga explore' lists the others)")
    return best.architecture


def add_bus_args(p):
    """--missing and --bus: the folded core's no-measurement bit and register bus."""
    p.add_argument("--missing", action="store_true",
                   help="the input's no-measurement bit: a sample with it set is predicted only (folded core; "
                        f"{', '.join(registry.coasting())})")
    p.add_argument("--bus", choices=("avalon", "axi4lite"),
                   help="a register slave on the folded core: the constants (K, F, Q, R terms) and reset values "
                        "written at run time (kfpga regs), a soft reset, counters")


def check_bus_args(args, config):
    """``--missing`` on a variant that cannot predict only is refused."""
    if getattr(args, "missing", False) and config.spec.model.variants[args.variant].predict is None:
        raise UsageError(f"--missing: the {config.filter} filter's {args.variant} variant takes every sample as a "
                         "measurement (it has no update without one)")


def add_json(p, what="print one JSON object"):
    p.add_argument("--json", action="store_true", help=what)


def add_quiet(p):
    p.add_argument("--quiet", action="store_true", help="no progress bar")


# -- the pre-filter -----------------------------------------------------------------------------------


def _prefilter_specs():
    return [s for s in registry.specs() if s.hardware.prefilter is not None]


def add_prefilter_args(p):
    """``--prefilter NAME`` and each pre-filter's own options (a filter whose spec has ``prefilter``)."""
    specs = _prefilter_specs()
    if not specs:
        return
    names = [s.name for s in specs] + [a for s in specs for a in s.docs.aliases]
    p.add_argument("--prefilter", choices=names, metavar="NAME",
                   help="put a filter between the ADS8364 controller and the core: "
                        + "; ".join(f"{s.name}: {s.hardware.prefilter.summary}" for s in specs))
    for s in specs:
        for option, kwargs in s.hardware.prefilter.options.items():
            p.add_argument(option, **{**kwargs, "help": f"with --prefilter {s.name}: {kwargs.get('help', '')}"})


def _option_dest(option):
    return option.lstrip("-").replace("-", "_")


def prefilter(args):
    """The pre-filter's config of ``--prefilter`` and its options, or ``None``."""
    from kfpga.core.config import FilterConfig

    name = getattr(args, "prefilter", None)
    chosen = None if name is None else registry.get(name)
    for spec in _prefilter_specs():
        for option in spec.hardware.prefilter.options:
            if getattr(args, _option_dest(option), None) is not None and (chosen is None or chosen.name != spec.name):
                raise UsageError(f"{option} applies with --prefilter {spec.name} only")
    if chosen is None:
        return None
    values = {_option_dest(o): getattr(args, _option_dest(o), None) for o in chosen.hardware.prefilter.options}
    try:
        params = chosen.hardware.prefilter.params(values)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--prefilter {chosen.name}: {exc}") from None
    return FilterConfig(filter=chosen.name, params=params)


def describe_params(params):
    """``"threshold 500"``: a pre-filter's parameters in one phrase."""
    return ", ".join(f"{f.name} {getattr(params, f.name):g}" if isinstance(getattr(params, f.name), float | int)
                     else f"{f.name} {getattr(params, f.name)}" for f in dataclasses.fields(params))


# -- the signal of compare, sweep and propose ------------------------------------------------------


def check_signal_args(args):
    """The options of the signal-driven commands that exclude each other."""
    if args.input:
        if args.seed is not None:
            not_with("--seed", "--input", "the samples come from the file, no noise is drawn")
        if args.scenario is not None:
            not_with("--scenario", "--input", "the samples come from the file")
    else:
        if args.clip:
            not_with("--clip", "a scenario", "scenarios stay within the 16-bit range; --clip is for --input files")


def _file_samples(args, config, command, need_truth, notes):
    from kfpga.core.csvio import read_samples

    samples = read_samples(args.input, clip=args.clip, columns=config.inputs, bits=config.input_format.width)
    y, truth = samples.y, samples.truth
    if args.samples:
        if args.samples > len(samples):
            raise UsageError(f"--samples {args.samples} is more than the {len(samples)} rows of {args.input}")
        y = {k: v[: args.samples] for k, v in y.items()} if isinstance(y, dict) else y[: args.samples]
        truth = truth[: args.samples] if truth is not None else None
    if samples.clipped:
        notes.append(f"{args.input}: {samples.clipped} value(s) outside the 16-bit range saturated (--clip)")
    if truth is None:
        if need_truth:
            raise UsageError(f"{command} needs a truth to measure RMSE: use a scenario or an --input with a 'truth' column")
        notes.append(f"{args.input}: no 'truth' column, so RMSE against truth is not reported")
    return truth, y, args.samples or len(samples)


def samples_for(args, config, *, command, need_truth=False):
    """``(truth, y, label)`` from ``--input`` or the chosen scenario.

    Everything is checked before anything is printed (the seed, notes about the file), so a
    bad invocation ends in one line: the error.
    """
    from kfpga.model import scenarios

    notes = []
    if args.input:
        truth, y, count = _file_samples(args, config, command, need_truth, notes)
    else:
        count = check_samples(args.samples or 20000)
    if count < 2:
        raise UsageError(f"{command} needs at least 2 samples, not {count}")
    if args.settle is not None and not 0 <= args.settle < count:
        raise UsageError(f"--settle must be between 0 and {count - 1}, not {args.settle}")
    if args.input:
        label = f"input {args.input}"
    else:
        args.seed = pick_seed(args.seed)
        notes.append(f"seed {args.seed} (replay with --seed {args.seed})")
        truth, y = scenarios.for_config(args.scenario, count, args.seed, config)
        rails = scenarios.check_rails(args.scenario, y)
        if rails:
            notes.append(f"scenario {args.scenario}: {rails} sample(s) at the ADC's rails (clipped)")
        label = f"scenario {args.scenario}"
    for note in notes:
        info(note)
    return truth, y, label


#: Memory a sample takes, in bytes, at most (measured: about 200 in compare on a 2-state and 260
#: on a 3-state model; about 430 in simulate, whose records are Python objects), with a margin.
BYTES_PER_SAMPLE = {"model": 512, "simulation": 2048}


def _memory_bytes():
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # not POSIX: assume a small machine
        return 4 << 30


def check_samples(count, *, kind="model", runs=1, option="--samples"):
    """Refuse, before anything is allocated, more samples than half this machine's memory holds
    (``runs`` sets of them at once), naming the largest count that fits."""
    per = BYTES_PER_SAMPLE[kind] * runs
    limit = _memory_bytes() // 2 // per
    if count > limit:
        raise UsageError(f"{option} {count} needs about {count * per / 2**30:,.0f} GiB of memory, more than half of "
                         f"this machine's {_memory_bytes() / 2**30:.0f} GiB: at most {limit}"
                         + (f" with {runs} runs" if runs > 1 else ""))
    return count


def require_word_lengths(config, command):
    """Refuse a filter whose formats have no word length to trade: no multiplier operand, no
    fraction bits of a state (a smoother that selects and averages its samples in their own 16 bits)."""
    spec = config.spec
    if not any(spec.model.points[name].operand for name in config.formats):
        raise UsageError(f"{command} does not apply to the {spec.name} filter: it has no multiplier operand and no "
                         "fraction bits to trade against error (see kfpga formats)")


# -- the ADC inputs of simulate and testbench -----------------------------------------------------------


def check_channel(args, config=None):
    """``--channel`` names the one channel of ``--channels 1``; with six it would be ignored, and
    a model that names its ADC channels (``model.adc``, or two observations) must agree.

    Sets ``args.adc`` to the ADC channel of each input (``None`` with six channels).
    """
    if args.channel is not None and args.channels == 6:
        not_with("--channel", "--channels 6", "all six channels are sampled and filtered")
    args.adc = None
    if config is None:
        return
    spec = config.spec
    if sensors(args) > 1 and len(config.inputs) > 1:
        raise UsageError(f"--channels {args.channels}: sensors on a multiplexer take turns on one ADC channel; this "
                         f"model reads {len(config.inputs)} ADC channels per update ({', '.join(config.inputs)})")
    if args.channels == 6:
        if len(config.inputs) > 1:
            raise UsageError(f"--channels 6 filters six channels of one input each; this model reads {len(config.inputs)} "
                             f"ADC channels per update ({', '.join(config.inputs)}): use --channels 1")
        if spec.model.adc is not None and spec.model.adc(config.params) is not None:
            raise UsageError("--channels 6 filters every ADC channel, so the model's adc would be ignored: remove "
                             "adc from [model], or use --channels 1")
        return
    try:
        args.adc = spec.adc_channels(config.params, args.channel)
    except ValueError as exc:
        raise UsageError(f"--channel: {exc}") from None


def add_adc_source_args(p):
    """--samples, --seed, --scenario, --input: the ADC inputs of simulate and testbench."""
    p.add_argument("--samples", type=positive_int, metavar="N",
                   help="estimates to check (default: 2000, or every row of --input; at most those)")
    p.add_argument("--seed", type=seed_type, metavar="S", help="noise seed of the ADC inputs (default: random, printed)")
    p.add_argument("--scenario", metavar="NAME", help="ADC input signal: sine, random-accel, model, or the filter's "
                                                      "own ('kfpga filters'; default: its first)")
    p.add_argument("--input", metavar="CSV", help="replay a CSV on the ADC inputs: y0..y5, or y on all six (sensors on "
                                                  "a multiplexer: y0..y<N-1>, a row a sample of each)")


def adc_source_params(args, config):
    """The ADC inputs of simulate and testbench: a scenario with a seed, or a CSV replay; sets
    ``args.samples`` (default 2000, or every row of the CSV) and ``args.seed``; returns the
    bench parameters."""
    if args.input:
        from kfpga.sim.sources import csv_source

        if args.seed is not None:
            not_with("--seed", "--input", "the ADC replays the file, no noise is drawn")
        if args.scenario is not None:
            not_with("--scenario", "--input", "the ADC replays the file")
        n = sensors(args)
        # fail early, with the file and line
        rows = csv_source(args.input, clip=False, sensors=n).codes.shape[1] // n
        limit = rows * (6 if args.channels == 6 else n)
        if args.samples is None:
            args.samples = limit
        if args.samples > limit:
            raise UsageError(f"--samples {args.samples} is more than the {limit} estimates the {rows} rows of "
                             f"{args.input} give")
        args.seed = None  # the source is the file: no noise is drawn, no seed to print
    else:
        args.samples = check_samples(2000 if args.samples is None else args.samples, kind="simulation")
        args.seed = pick_seed(args.seed)
        info(f"seed {args.seed} (replay with --seed {args.seed})")
    return {"variant": args.variant, "six": args.channels == 6, "channel": args.adc[0] if args.adc else None,
            "adc": list(args.adc) if args.adc else None, "samples": args.samples,
            "seed": 0 if args.seed is None else args.seed,  # a file's run: the glitches' positions only
            "scenario": args.scenario, "csv": str(Path(args.input).resolve()) if args.input else None,
            "config_toml": config.to_toml()}
