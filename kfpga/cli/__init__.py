"""The ``kfpga`` command line: one module per command; what they share is in ``options`` (argument
types, option groups), ``loading`` (the config and the signal), ``design`` (the hardware's choices)
and ``output`` (progress, notes, JSON).

Every filter-specific option comes from the registry: a filter's evaluation (``kfpga evaluate
NAME``), its extra modes of ``kfpga filter`` and its pre-filter options are declared by its spec.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from kfpga import __version__
from kfpga.cli import (
    compare,
    evaluate,
    explore,
    filter,
    filters,
    formats,
    generate,
    options,
    pins,
    propose,
    regs,
    resources,
    simulate,
    sweep,
    testbench,
)

__all__ = ["main", "build_parser", "synopsis"]

#: The commands in the order ``kfpga --help`` lists them.
COMMANDS = (compare, sweep, propose, evaluate, filters, filter, formats, explore, generate, regs, pins, resources,
            simulate, testbench)


def build_parser():
    parser = argparse.ArgumentParser(
        prog="kfpga",
        description="Kalman-type filters for the Cyclone II: bit-accurate fixed-point model, Verilog and Quartus "
                    "project generation, co-simulation.",
        epilog="Run 'kfpga COMMAND --help' for the options of a command. Files a command makes without being "
               "told where (the sweep plot, simulation builds, waveforms) go under build/ in the current folder. "
               "A bad argument or input file is reported in one line, exit code 2.",
    )
    parser.add_argument("--version", action="version", version=f"kfpga {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
        examples = getattr(command, "EXAMPLES", None)
        if callable(examples):  # examples that name a registered filter, picked from the registry
            examples = examples()
        if examples:
            p = sub.choices[command.__name__.rsplit(".", 1)[1]]
            p.epilog = "examples:\n" + "\n".join(f"  {line}" for line in examples)
            p.formatter_class = options.ExamplesFormatter
    return parser


def _subparsers(parser):
    """``{command: its parser}``."""
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def _words(p):
    words = []
    for action in p._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        flag = max(action.option_strings, key=len)
        if action.nargs == 0:
            text = flag
        elif action.choices:
            text = f"{flag} {'|'.join(str(c) for c in action.choices)}"
        else:
            text = f"{flag} {action.metavar or action.dest.upper()}"
        words.append(text if action.required else f"[{text}]")
    return words


def synopsis(width=110):
    """The command synopsis of the manual (docs/cli.md), written from the parser (so the two cannot drift); a
    command with sub-commands (``evaluate``) gets a line per sub-command (aliases not repeated)."""
    lines = []

    def add(name, p):
        nested = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            seen = set()
            for sub, q in nested[0].choices.items():
                if id(q) not in seen:
                    seen.add(id(q))
                    add(f"{name} {sub}", q)
            return
        line = f"kfpga {name:<9}"
        for word in _words(p):
            if len(line) + 1 + len(word) > width:
                lines.append(line)
                line = " " * 15 + " " + word
            else:
                line += " " + word
        lines.append(line)

    for name, p in _subparsers(build_parser()).items():
        add(name, p)
    return "\n".join(lines)


def _terminated(signum, frame):
    raise KeyboardInterrupt


def main(argv=None):
    from kfpga.core.errors import USER_ERRORS

    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # report it as the command's error, under the command's usage
        _subparsers(parser)[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    if threading.current_thread() is threading.main_thread():
        # a kill (SIGTERM) unwinds like Ctrl-C, so an output being written is removed, not left half-written
        signal.signal(signal.SIGTERM, _terminated)
    try:
        return args.func(args)
    except USER_ERRORS as exc:
        print(f"kfpga {args.command}: error: {exc}", file=sys.stderr)
        return options.EXIT_USAGE
    except KeyboardInterrupt:
        print(f"kfpga {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (kfpga formats --json | head): stop quietly, as Unix tools do, and
        # keep Python from complaining again when it flushes stdout at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a writer killed by a closed pipe
