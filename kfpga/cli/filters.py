"""``kfpga filters``: the registered filters."""

from __future__ import annotations

from kfpga.cli import options, output
from kfpga.core import registry


def add_parser(sub):
    p = sub.add_parser("filters", help="list the registered filters, their variants, inputs and outputs",
                       description="List every registered filter with its variants, its inputs and outputs, and "
                                   "the document it comes from. Any of them can be given to the other commands "
                                   "with --filter NAME, or by [filter] name in a config file.")
    options.add_json(p, "print the list as JSON")
    p.set_defaults(func=run)


def run(args):
    rows = [{"name": s.name, "aliases": list(s.docs.aliases), "summary": s.docs.summary,
             "variants": {n: v.summary for n, v in s.model.variants.items()},
             "inputs": [n for n, _ in s.inputs_for(s.params())],
             "outputs": [o.name for o in s.outputs_for(s.params())], "source": s.docs.source,
             "outputs_follow_the_model": callable(s.model.outputs),
             "presets": {n: summary for n, (summary, _) in s.model.presets.items()},
             "evaluation": s.evaluation is not None, "scenarios": list(s.model.scenarios),
             "default": s.name == registry.DEFAULT} for s in registry.specs()]
    if args.json:
        output.emit_json(rows)
        return 0
    for r in rows:
        also = f" (also: {', '.join(r['aliases'])})" if r["aliases"] else ""
        print(f"{r['name']:<10} {r['summary']}{' (default)' if r['default'] else ''}{also}")
        for name, summary in r["variants"].items():
            print(f"  --variant {name:<9} {summary}")
        outputs = (f"{', '.join(r['outputs'])} for the default model; in general x1..xn, yhat1..yhatm"
                   if r["outputs_follow_the_model"] else ", ".join(r["outputs"]))
        print(f"  inputs {', '.join(r['inputs'])}; outputs {outputs}; scenarios "
              f"{', '.join(r['scenarios'])}; source: {r['source']}")
        for name, summary in r["presets"].items():
            print(f"  --preset {name:<10} {summary}")
        if r["evaluation"]:
            print(f"  kfpga evaluate {r['name']}: its source document's evaluation")
    return 0


#: The examples ending ``kfpga filters --help``.
EXAMPLES = (
    'kfpga filters',
    'kfpga filters --json',
)
