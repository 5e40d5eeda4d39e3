"""``kfpga evaluate NAME``: a source document's own evaluation, for every registered filter that has
one (its spec's ``evaluation``)."""

from __future__ import annotations

from kfpga.cli import common
from kfpga.core import registry
from kfpga.core.errors import UsageError


def add_parser(sub):
    p = sub.add_parser("evaluate", help="rerun a source document's own evaluation: its scenario, table and plot",
                       description="Rerun the evaluation of one of the source documents with its scenario and "
                                   "baselines, print its table, and say how the figures compare with the document's "
                                   "conclusions.")
    ev = p.add_subparsers(dest="evaluation", metavar="NAME", required=True)
    for spec in registry.specs():
        evaluation = spec.load_evaluation()
        if evaluation is None:
            continue
        q = ev.add_parser(spec.name, aliases=list(spec.aliases), help=evaluation.summary,
                          description=evaluation.description)
        evaluation.add_arguments(q)
        q.add_argument("--seed", type=common.seed_type, metavar="S",
                       help="seed of the evaluation's random signals (default: random, printed)")
        common.add_json(q, "print the tables as JSON")
        q.add_argument("--plot", metavar="PNG", help="draw the evaluation's figures")
        q.set_defaults(func=run, spec_name=spec.name)


def run(args):
    evaluation = registry.get(args.spec_name).load_evaluation()
    plot = common.check_plot(args.plot)
    if plot and evaluation.plot is None:
        common.not_with("--plot", f"evaluate {args.spec_name}", "this evaluation has no figures")
    evaluation.check(args)
    if evaluation.seeded(args):
        seed = common.pick_seed(args.seed)
        common.info(f"seed {seed}")
    else:
        if args.seed is not None:
            raise UsageError("--seed does not apply here: this run draws no random numbers (its data come from a file)")
        seed = None
    result = evaluation.run(args, seed)
    if plot:
        evaluation.plot(result, plot)
        common.info(f"plot: {plot}")
    if args.json:
        common.emit_json(evaluation.summary_json(result))
    else:
        print(evaluation.table(result))
    return 0
