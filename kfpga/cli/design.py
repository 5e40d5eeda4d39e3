"""The hardware a command builds: the channel states and sensors, the board's rate, the
architecture (explored where not chosen), the register bus, the ADC channel and its source."""

from __future__ import annotations

from pathlib import Path

from kfpga.cli.loading import check_samples
from kfpga.cli.options import not_with
from kfpga.cli.output import info, pick_seed, progress_bar
from kfpga.core.errors import UsageError
from kfpga.hw import ads8364_timing
from kfpga.hw.cores import make_core


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
        ads8364_timing.check_rate(config.board, channels, getattr(args, "ratio", 10), sensors(args))
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


def check_bus_args(args, config):
    """``--missing`` on a variant that cannot predict only is refused."""
    if getattr(args, "missing", False) and config.spec.model.variants[args.variant].predict is None:
        raise UsageError(f"--missing: the {config.filter} filter's {args.variant} variant takes every sample as a "
                         "measurement (it has no update without one)")


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
