"""``kfpga evaluate NAME``: a source document's own evaluation, for every registered filter that has
one (its spec's ``evaluation``), over many seeds, with every claim of the document judged on all of
them."""

from __future__ import annotations

from kfpga.cli import options, output
from kfpga.core import registry
from kfpga.core.claims import claims_markdown, claims_table
from kfpga.core.errors import UsageError

#: Seeds of a run when neither ``--seed`` nor ``--seeds`` is given: 1 .. 20, the same on every
#: machine, so that the verdicts the manual quotes are the ones a reader gets.
DEFAULT_SEEDS = 20
#: The most seeds a run takes (each seed reruns the document's scenario).
MAX_SEEDS = 1000


def _examples():
    def evaluated(spec):
        return spec.evaluation is not None

    one, two, three = (registry.example(evaluated, skip=k) for k in range(3))
    return (f"examples:\n  kfpga evaluate {one}    # seeds 1..20, the claims table\n"
            f"  kfpga evaluate {two} --seeds 5 --json\n"
            f"  kfpga evaluate {three} --seed 7 --plot {three}.png   # replay seed 7 alone")


def add_parser(sub):
    p = sub.add_parser("evaluate", help="rerun a source document's own evaluation over many seeds: its scenario, "
                                        "table, claims with verdicts, and plot",
                       description="Rerun the evaluation of one of the source documents with its scenario and "
                                   "baselines over many seeds, print the table of the first seed and every claim of "
                                   "the document with its value, ours over the seeds, and a verdict (reproduced: it "
                                   "holds on every seed; not reproduced; not testable, with the reason).",
                       epilog=_examples(),
                       formatter_class=options.ExamplesFormatter)
    ev = p.add_subparsers(dest="evaluation", metavar="NAME", required=True)
    for spec in registry.specs():
        evaluation = spec.load_evaluation()
        if evaluation is None:
            continue
        q = ev.add_parser(spec.name, aliases=list(spec.docs.aliases), help=evaluation.summary,
                          description=evaluation.description, formatter_class=options.ExamplesFormatter,
                          epilog=f"examples:\n  kfpga evaluate {spec.name}                 # seeds 1..20 and the claims\n"
                                 f"  kfpga evaluate {spec.name} --seed 3 --plot build/{spec.name}.png")
        evaluation.add_arguments(q)
        q.add_argument("--seeds", type=options.int_at_least(1, "an integer >= 1"), metavar="N",
                       help=f"run N seeds, from --seed on (default: {DEFAULT_SEEDS} seeds, 1 .. {DEFAULT_SEEDS}; "
                            "with --seed alone, that seed only)")
        q.add_argument("--seed", type=options.seed_type, metavar="S",
                       help="the first seed (alone: replay that one seed)")
        options.add_json(q, "print the tables and the claims as JSON")
        q.add_argument("--markdown", action="store_true", help="print the claims alone, as a Markdown table")
        q.add_argument("--plot", metavar="PNG", help="draw the evaluation's figures (of the first seed)")
        options.add_quiet(q)
        q.set_defaults(func=run, spec_name=spec.name)


def seeds_of(args):
    """The seeds of a run: ``--seed S`` alone is S; ``--seeds N`` runs N from S (default 1)."""
    if args.seeds is None:
        return [args.seed] if args.seed is not None else list(range(1, DEFAULT_SEEDS + 1))
    if args.seeds > MAX_SEEDS:
        raise UsageError(f"--seeds must be at most {MAX_SEEDS}, not {args.seeds}")
    first = 1 if args.seed is None else args.seed
    return list(range(first, first + args.seeds))


def _runs_label(seeds):
    if seeds is None:
        return "the file's one run"
    if len(seeds) == 1:
        return f"1 seed ({seeds[0]}; a verdict needs many: drop --seed, or add --seeds N)"
    return f"{len(seeds)} seeds, {seeds[0]} .. {seeds[-1]}"


def _measures(evaluation, args, seeds, first):
    """``measure`` (or ``run``) on every seed, the first's full run reused; a bar on a terminal."""
    measure = evaluation.measure or evaluation.run
    out = []
    with output.progress_bar(args.quiet or len(seeds) == 1, total=len(seeds), desc="evaluate", unit="seed") as bar:
        for seed in seeds:
            out.append(first if evaluation.measure is None and seed == seeds[0] else measure(args, seed))
            bar.update(1)
    return out


def run(args):
    evaluation = registry.get(args.spec_name).load_evaluation()
    plot = options.check_plot(args.plot)
    if plot and evaluation.plot is None:
        options.not_with("--plot", f"evaluate {args.spec_name}", "this evaluation has no figures")
    if args.markdown and args.json:
        options.not_with("--markdown", "--json", "each prints the claims its own way")
    evaluation.check(args)
    if evaluation.seeded(args):
        seeds = seeds_of(args)
        output.info(f"seeds {seeds[0]} .. {seeds[-1]}" if len(seeds) > 1 else f"seed {seeds[0]}")
        result = evaluation.run(args, seeds[0])
        claims = evaluation.claims(args, result, _measures(evaluation, args, seeds, result))
    else:
        for option in ("seed", "seeds"):
            if getattr(args, option) is not None:
                raise UsageError(f"--{option} does not apply here: this run draws no random numbers (its data come "
                                 "from a file)")
        seeds = None
        result = evaluation.run(args, None)
        claims = evaluation.claims(args, result, [result])
    if plot:
        evaluation.plot(result, plot)
        output.info(f"plot: {plot}")
    if args.markdown:
        print(claims_markdown(claims, _runs_label(seeds)))
    elif args.json:
        output.emit_json(evaluation.summary_json(result) | {"seeds": seeds, "claims": [c.to_json() for c in claims]})
    else:
        print(evaluation.table(result))
        print()
        print(claims_table(claims, _runs_label(seeds)))
    return 0
