"""``kfpga regs``: the register values of a programmable core for new parameters (new Q and R on
the bench, no new synthesis), and its register map."""

from __future__ import annotations

import dataclasses
import json
import tomllib

from kfpga.cli import loading, options, output
from kfpga.core.errors import ConfigError, UsageError

FORMATS = ("table", "c", "tcl", "json")


def add_parser(sub):
    p = sub.add_parser("regs", help="register values of a programmable core (--bus) for new Q, R, x0, P0: a table, "
                                    "a C header or a script of bus writes",
                       description="For a core generated with --bus (a folded core whose settings a bus writes at "
                                   "run time), compute every setting for new model parameters in the core's own "
                                   "formats: the steady gain from the Riccati equation, the Q and R terms, 1/T, x0 "
                                   "and P0, each quantised as the core holds it, and the bus writes that load them "
                                   "(every digit, then CONTROL.COMMIT: they take effect between two updates). A "
                                   "value that does not fit its format, or a change of the model's shape (an entry "
                                   "of F that is 0 or a shift, built into the core), is refused. --regmap writes the "
                                   "core's register map (SystemRDL, C header, Markdown).")
    options.add_filter_args(p)
    p.add_argument("--config", metavar="TOML", help="the core's config (the one it was generated from: its formats)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", dest="settings",
                   help="a new model parameter, the value in TOML (Q=1.5, R=[[16.0]], x0=[0.0, 1.0]); repeat for "
                        "several")
    p.add_argument("--missing", action="store_true", help="the core was generated with --missing")
    p.add_argument("--format", choices=FORMATS, default="table",
                   help="table (default), c (a C header of the writes), tcl (System Console master_write_32 "
                        "commands) or json")
    p.add_argument("--base", type=lambda t: int(t, 0), default=0, metavar="ADDR",
                   help="the slave's base address in your system, added to every byte offset of --format c and tcl "
                        "(default 0)")
    p.add_argument("--out", metavar="FILE", help="write to FILE instead of the standard output")
    p.add_argument("--regmap", metavar="DIR", help="also write the register map: DIR/kfpga_regs.rdl, .h and .md")
    p.set_defaults(func=run)


def _parse_settings(items, spec):
    known = [f.name for f in dataclasses.fields(spec.params)]
    out = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise UsageError(f"--set {item!r}: give NAME=VALUE (for example Q=1.5)")
        if name not in known:
            raise UsageError(f"--set {name}: the {spec.name} filter's parameters are {', '.join(known)}")
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            raise UsageError(f"--set {name}={text}: the value is not TOML (a number, or a list like [[1.0]])") from None
        out[name] = _tuples(value)
    return out


def _tuples(value):
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def run(args):
    from kfpga.core.paths import check_output_file
    from kfpga.flows.regs import bus_writes, program_for, settings_for

    if args.out:
        check_output_file(args.out, option="--out", inputs=(args.config,), extensions=(".h", ".tcl", ".txt", ".json",
                                                                                       ".md", ".csv"))
    config = loading.load_config(args, hardware=True)
    changes = _parse_settings(args.settings, config.spec)
    program = program_for(config, args.variant, missing=args.missing)
    if not program.settings:
        raise UsageError(f"the {config.filter} filter's {args.variant} core has no settings a bus can write")
    try:
        params = dataclasses.replace(config.params, **changes)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--set: {exc}") from None
    try:
        values = settings_for(config, args.variant, params, program=program)
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    writes = bus_writes(values, program, config, args.variant)
    text = {"table": _table, "c": _c, "tcl": _tcl, "json": _json}[args.format](config, args, values, writes)
    if args.regmap:
        from kfpga.hw.regmap import export, register_map

        export(register_map(program, config, args.variant), args.regmap)
    if args.out:
        from pathlib import Path

        Path(args.out).write_text(text)
        output.info(f"{len(writes)} bus writes for {', '.join(changes) or 'the config itself'} -> {args.out}")
    else:
        print(text, end="")
    return 0


def _what(changes):
    return ", ".join(f"{k} = {v}" for k, v in changes.items()) or "the config's own values"


def _table(config, args, values, writes):
    lines = [f"kfpga regs: {config.filter} filter, {args.variant} variant, programmable core; "
             f"{_what(_parse_settings(args.settings, config.spec))}",
             f"  {'setting':<22}{'value':>14}{'held as':>14}{'integer':>12}  {'format':<9} digits"]
    for sv in values:
        st = sv.setting
        digits = " ".join(f"0x{d & 0x3FFFF:05X}" for d in sv.digits)
        lines.append(f"  {st.label:<22}{sv.value:>14.6g}{sv.held:>14.6g}{sv.raw:>12}  {st.fmt!s:<9} {digits}")
    lines.append(f"  bus writes ({len(writes)}; word index, byte offset, value):")
    lines += [f"    {index:>4}  0x{4 * index:04X}  0x{value:08X}  {name}" for index, value, name in writes]
    return "\n".join(lines) + "\n"


def _c(config, args, values, writes):
    rows = ",\n".join(f"    {{0x{args.base + 4 * index:08X}u, 0x{value:08X}u}}  /* {name} */"
                      for index, value, name in writes)
    return (f"/* kfpga regs: {config.filter} {args.variant}, {_what(_parse_settings(args.settings, config.spec))}.\n"
            " * Write each value to its byte address in order (32-bit writes); the last, CONTROL.COMMIT, makes\n"
            " * them take effect between two updates. */\n"
            "#ifndef KFPGA_SETTINGS_H\n#define KFPGA_SETTINGS_H\n#include <stdint.h>\n\n"
            f"#define KFPGA_SETTINGS_COUNT {len(writes)}u\n"
            f"static const uint32_t kfpga_settings[KFPGA_SETTINGS_COUNT][2] = {{\n{rows}\n}};\n\n#endif\n")


def _tcl(config, args, values, writes):
    lines = [f"# kfpga regs: {config.filter} {args.variant}, {_what(_parse_settings(args.settings, config.spec))}",
             "# Intel System Console: source this with $m the claimed master service path, e.g.",
             "#   set m [lindex [get_service_paths master] 0]; open_service master $m",
             *(f"master_write_32 $m 0x{args.base + 4 * index:X} 0x{value:08X} ;# {name}" for index, value, name in writes)]
    return "\n".join(lines) + "\n"


def _json(config, args, values, writes):
    return json.dumps({"filter": config.filter, "variant": args.variant,
                       "settings": [{"name": sv.setting.name, "kind": "constant" if sv.setting.kind == "c" else "reset",
                                     "label": sv.setting.label, "value": sv.value, "held": sv.held, "raw": sv.raw,
                                     "format": str(sv.setting.fmt), "digits": list(sv.digits)} for sv in values],
                       "writes": [{"index": i, "offset": 4 * i, "value": v, "register": n} for i, v, n in writes]},
                      indent=2) + "\n"


#: The examples ending ``kfpga regs --help``.
EXAMPLES = (
    "kfpga regs --config tracker.toml --set 'Q=[[0.25]]' --set 'R=[[36.0]]'",
    "kfpga regs --set Q=1.0 --set R=6.0 --format tcl --base 0x8000 --out retune.tcl   # the paper's filter",
    "kfpga regs --config tracker.toml --regmap build/regmap --format c --out build/regmap/settings.h",
)
