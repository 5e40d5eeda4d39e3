"""The options the commands share: argument types, option groups and their help (built from the
registry: every registered filter's names, variants, presets and pre-filter options), and the
checks that refuse an option that does not apply."""

from __future__ import annotations

import argparse

from kfpga.core import registry
from kfpga.core.errors import UsageError

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


def check_plot(path, option="--plot"):
    """``--plot FILE``: an image file matplotlib writes, in a folder that exists."""
    from kfpga.core.paths import check_output_file

    return None if path is None else str(check_output_file(path, option=option, extensions=PLOT_EXTENSIONS))


def not_with(option, other, why):
    """Refuse ``option`` (given) in combination with ``other``: it would be ignored."""
    raise UsageError(f"{option} does not apply with {other}: {why}")


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


def add_bus_args(p):
    """--missing and --bus: the folded core's no-measurement bit and register bus."""
    p.add_argument("--missing", action="store_true",
                   help="the input's no-measurement bit: a sample with it set is predicted only (folded core; "
                        f"{', '.join(registry.coasting())})")
    p.add_argument("--bus", choices=("avalon", "axi4lite"),
                   help="a register slave on the folded core: the constants (K, F, Q, R terms) and reset values "
                        "written at run time (kfpga regs), a soft reset, counters")


def add_json(p, what="print one JSON object"):
    p.add_argument("--json", action="store_true", help=what)


def add_quiet(p):
    p.add_argument("--quiet", action="store_true", help="no progress bar")


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


def add_adc_source_args(p):
    """--samples, --seed, --scenario, --input: the ADC inputs of simulate and testbench."""
    p.add_argument("--samples", type=positive_int, metavar="N",
                   help="estimates to check (default: 2000, or every row of --input; at most those)")
    p.add_argument("--seed", type=seed_type, metavar="S", help="noise seed of the ADC inputs (default: random, printed)")
    p.add_argument("--scenario", metavar="NAME", help="ADC input signal: sine, random-accel, model, or the filter's "
                                                      "own ('kfpga filters'; default: its first)")
    p.add_argument("--input", metavar="CSV", help="replay a CSV on the ADC inputs: y0..y5, or y on all six (sensors on "
                                                  "a multiplexer: y0..y<N-1>, a row a sample of each)")
