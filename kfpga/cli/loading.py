"""The model a command runs on and the signal it runs: the config (file, preset or filter), its
scenario and sample period, the samples of a file or a scenario, and the run's size."""

from __future__ import annotations

import dataclasses
import os
import sys

from kfpga.cli.options import not_with
from kfpga.cli.output import info, pick_seed
from kfpga.core import registry
from kfpga.core.errors import UsageError


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


def describe_params(params):
    """``"threshold 500"``: a pre-filter's parameters in one phrase."""
    return ", ".join(f"{f.name} {getattr(params, f.name):g}" if isinstance(getattr(params, f.name), float | int)
                     else f"{f.name} {getattr(params, f.name)}" for f in dataclasses.fields(params))


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
