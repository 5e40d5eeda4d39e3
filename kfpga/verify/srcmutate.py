"""Source-level mutation of the hardware's Python (``make mutate``, beside the netlist mutants of
:mod:`kfpga.verify.mutate`): do the tests notice a wrong line of ``hw/``?

The netlist mutants change one bit of a block as Yosys sees it; these change the Amaranth
source that builds it, the kind of slip a person makes:

* ``+`` and ``-`` swapped; ``&`` and ``|``; ``==`` and ``!=``; ``<`` and ``<=`` (``>`` and ``>=``);
* an integer constant one more or one less;
* the two data operands of a ``Mux`` swapped;
* a statement of the design dropped (an ``m.d.<domain> += ...``, or a call of its own);
* the condition of an ``m.If`` / ``m.Elif`` inverted.

Only lines of *RTL-building code* are mutated: every function and constant table of ``hw/*.py`` but the tools
that write files and estimate, the core factories and the tools' paths (:data:`NOT_RTL`: ``generate.py``,
``resources.py``, ``timing.py``, ``ip.py``, ``cores.py``, ``tools.py``), never a docstring, a message or an
argument check (an ``if`` that only raises).
Sites are drawn with a seeded generator, ``--mutants`` per file.

Each mutant runs the tests that execute its line (a line no test's context runs, module-level
code such as a constant table, runs the tests of its whole file): a first pass runs the fast tests of the
hardware (:data:`POOL`, the Amaranth-simulator ones) under ``coverage`` with a context per test,
which gives, for each line of ``hw/``, the tests that ran it. The mutant is written into a copy of
the source tree (``build/mutate/source/tree``; the working tree is never touched) and those tests
run on it (``pytest -x``): a failure kills it. A mutant no test runs, or that survives them, is
checked for equivalence: every design the tests build (each registered core on each of its
architectures with 1 and 3 channels, 10 where it keeps states in memory, a pipelined loop at
every stage count it takes, the divider, the square root, the many-track core and the board's
top) is elaborated from the original and from the mutated source (a design that no longer
elaborates kills the mutant: every test that builds it would fail; a line run at import, such as
a constant table, has no test context of its own), and Yosys compares each pair that differs
(``equiv_make``, ``equiv_simple``, ``equiv_induct``, ``equiv_status -assert``). When no design differs, or every pair that differs
is proven equal, the mutant is *equivalent* for those designs; otherwise it *survived*. The
score is killed / (mutants - equivalent), per file.

    python -m kfpga.verify.srcmutate [--mutants N] [--seed S] [--only TEXT] [--json]
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import json
import os
import random
import re
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

__all__ = ["Mutant", "sites", "mutants_of", "main"]

ROOT = Path("build") / "mutate" / "source"
#: The tests whose coverage says which test runs which line (the fast, Amaranth-simulator ones).
POOL = ["tests/contract/test_streams.py", "tests/contract/test_contract.py", "tests/test_hw_kalman.py",
        "tests/test_hw_kalman2.py", "tests/test_hw_divider.py", "tests/test_hw_top.py", "tests/test_hw_clockdiv.py",
        "tests/test_hw_ads8364.py", "tests/test_hw_folded.py", "tests/test_hw_alphabeta.py", "tests/test_hw_tukey53h.py",
        "tests/test_sensors.py", "tests/test_hw_generate.py"]
#: What the first pass leaves out: the co-simulations (their lines are run by the Amaranth tests too).
POOL_MARKS = "not cosim and not slow"
#: The files copied into the tree the mutants are written to.
TREE = ("kfpga", "hw", "model", "sim", "constraints", "tests", "pyproject.toml")
#: The files of ``hw/`` that build no logic: the Verilog and project writer, the synthesis and
#: timing estimates, the core factories for Amaranth users (which choose a core, and build no logic
#: of their own), and the tool paths.
NOT_RTL = ("hw/generate.py", "hw/resources.py", "hw/timing.py", "hw/ip.py", "hw/cores.py", "hw/tools.py", "hw/__init__.py")


@dataclass
class Mutant:
    """One change: the file, its line, the operator, the text before and after."""

    file: str
    line: int
    operator: str
    before: str
    after: str
    start: tuple  # (line, col) of the replaced text, 1-based line
    end: tuple
    result: str = ""
    by: str = ""
    tests: int = 0
    seconds: float = 0.0
    digest: str = ""  # of the file's source the mutant was drawn from
    context: str = ""  # of what else decides a verdict other than killed: the map's tests, the designs built

    @property
    def key(self):
        """What identifies the mutant's verdict: its file's source and the change."""
        return f"{self.file}|{self.digest}|{self.start}|{self.end}|{self.operator}|{self.after}"


def _functions(tree):
    """The functions, and the module's and classes' constant tables (``CUTS = {...}``): the code
    a mutation of the design can be in."""
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield node
        elif isinstance(node, ast.Module | ast.ClassDef):
            for stmt in node.body:
                if (isinstance(stmt, ast.Assign | ast.AnnAssign) and stmt.value is not None
                        and "__all__" not in ast.unparse(stmt)):
                    yield stmt


def _argument_check(node):
    """An ``if`` whose body only raises: its condition checks arguments, it builds no logic."""
    return isinstance(node, ast.If) and all(isinstance(b, ast.Raise) for b in node.body) and not node.orelse


def _skipped(node, parents):
    """Inside a docstring, a message, an assertion, a raise or a type check: not logic."""
    for p in parents:
        if isinstance(p, ast.JoinedStr | ast.Assert | ast.Raise | ast.arguments):  # a default too
            return True
        if isinstance(p, ast.Call) and isinstance(p.func, ast.Name) and p.func.id in ("isinstance", "ValueError",
                                                                                   "TypeError", "print"):
            return True
    return False


_SWAPS = {ast.Add: ("+/-", ast.Sub), ast.Sub: ("+/-", ast.Add), ast.BitAnd: ("&/|", ast.BitOr),
          ast.BitOr: ("&/|", ast.BitAnd)}
_COMPARE = {ast.Eq: ("==/!=", ast.NotEq), ast.NotEq: ("==/!=", ast.Eq), ast.Lt: ("</<=", ast.LtE),
            ast.LtE: ("</<=", ast.Lt), ast.Gt: ("</<=", ast.GtE), ast.GtE: ("</<=", ast.Gt)}


def _is_design_statement(stmt):
    """``m.d.<domain> += ...`` or a bare call (``self._wire(m)``, ``write(...)``)."""
    if isinstance(stmt, ast.AugAssign):
        return ".d." in ast.unparse(stmt.target) + "."
    return isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call)


def _site(node, parents):
    """The mutation of ``node`` (under ``parents``), ``(operator, node, replacement text)``, or
    None."""
    if isinstance(node, ast.BinOp) and type(node.op) in _SWAPS:
        name, op = _SWAPS[type(node.op)]
        return name, node, f"({ast.unparse(ast.BinOp(node.left, op(), node.right))})"
    if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _COMPARE:
        name, op = _COMPARE[type(node.ops[0])]
        return name, node, f"({ast.unparse(ast.Compare(node.left, [op()], node.comparators))})"
    if (isinstance(node, ast.Constant) and isinstance(node.value, int) and not isinstance(node.value, bool)
            and not (parents and isinstance(parents[-1], ast.Expr))):
        return "const+-1", node, repr(node.value + (1 if node.value % 2 == 0 else -1))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "Mux" and len(node.args) == 3:
        a, b, c = node.args
        return "Mux swap", node, f"Mux({ast.unparse(a)}, {ast.unparse(c)}, {ast.unparse(b)})"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("If", "Elif") \
            and node.args:
        cond = node.args[0]
        return "not", cond, f"~({ast.unparse(cond)})"
    if isinstance(node, ast.stmt) and _is_design_statement(node):
        return "drop", node, "pass"
    return None


def sites(path, source=None):
    """Every mutation of the RTL-building code of ``path``: ``[(operator, node, replacement text)]``,
    each replacement valid Python."""
    source = Path(path).read_text() if source is None else source
    tree = ast.parse(source)
    found, seen = [], set()
    for func in _functions(tree):
        stack = [(func, ())]
        while stack:
            node, parents = stack.pop()
            if _argument_check(node):
                continue
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.Expr) and isinstance(child.value, ast.Constant):
                    continue  # a docstring
                stack.append((child, (*parents, node)))
            if not _skipped(node, parents) and hasattr(node, "lineno"):
                site = _site(node, parents)
                if site is not None:
                    found.append(site)
    unique = []
    for operator, node, text in found:  # a nested function is walked with its parent too
        key = (operator, node.lineno, node.col_offset, node.end_lineno, node.end_col_offset)
        if key not in seen:
            seen.add(key)
            unique.append((operator, node, text))
    return sorted(unique, key=lambda s: (s[1].lineno, s[1].col_offset, s[0]))


def _replace(source, node, text):
    # ast's column offsets count UTF-8 bytes: characters in ASCII source, which mutants_of checks
    lines = source.splitlines(keepends=True)
    start = sum(len(x) for x in lines[: node.lineno - 1]) + node.col_offset
    end = sum(len(x) for x in lines[: node.end_lineno - 1]) + node.end_col_offset
    return source[:start] + text + source[end:]


def mutants_of(path, count, rng, root=Path(".")):
    """``count`` mutants of ``path`` (fewer if it has fewer sites), drawn with ``rng`` (a
    :class:`random.Random`, or a seed: the draw of a file then depends on the seed and the file's
    path only, so a run over some files draws what a run over all draws for them); each is valid
    Python and changes the file."""
    if not isinstance(rng, random.Random):
        rng = random.Random(f"{rng}:{path}")
    source = (root / path).read_text()
    if not source.isascii():
        raise ValueError(f"{path}: the mutation offsets assume ASCII source")
    candidates = sites(root / path, source)
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    rng.shuffle(candidates)
    out = []
    for operator, node, text in candidates:
        if len(out) == count:
            break
        new = _replace(source, node, text)
        if new == source:
            continue
        try:
            compile(new, str(path), "exec")
        except SyntaxError:
            continue
        before = ast.get_source_segment(source, node)
        out.append(Mutant(str(path), node.lineno, operator, before, text, (node.lineno, node.col_offset),
                          (node.end_lineno, node.end_col_offset), digest=digest))
    return out


def apply(mutant, root):
    """The mutated source of ``mutant``'s file under ``root``."""
    source = (root / mutant.file).read_text()
    node = type("Site", (), {"lineno": mutant.start[0], "col_offset": mutant.start[1], "end_lineno": mutant.end[0],
                             "end_col_offset": mutant.end[1]})
    return _replace(source, node, mutant.after)


# -- which tests run which line ------------------------------------------------------------------------


def line_tests(tree, progress=print, pool=POOL):
    """``{(file, line): {test node id, ...}}`` for the lines of ``hw/`` the tests of ``pool`` run,
    from ``coverage`` with a context per test (cached in ``build/mutate/source/coverage.json``)."""
    cache = ROOT / "coverage.json"
    digest = _tree_digest(tree, pool)
    if cache.exists():
        stored = json.loads(cache.read_text())
        if stored.get("digest") == digest:
            return {(f, int(n)): set(t) for f, lines in stored["lines"].items() for n, t in lines.items()}
    progress(f"coverage of {len(pool)} test files over hw/, a context per test (once per source state) ...")
    data_file = (ROOT / ".coverage").resolve()
    for old in ROOT.glob(".coverage*"):
        old.unlink()
    rc_file = ROOT.resolve() / "coveragerc"
    rc_file.write_text(f"[run]\ndata_file = {data_file}\ndynamic_context = test_function\nparallel = true\n"
                       "patch = subprocess\ninclude = hw/*\n")
    env = {**_env(tree), "COVERAGE_RCFILE": str(rc_file)}
    rc = subprocess.run([sys.executable, "-m", "coverage", "run", "-m", "pytest", "-q", "-p", "no:cacheprovider",
                         "-m", POOL_MARKS, "-o", "addopts=", "-n", "2", "--timeout=1200", *pool],
                        cwd=tree, env=env, capture_output=True, text=True)
    if rc.returncode not in (0, 1):
        raise RuntimeError(f"the coverage pass failed ({rc.returncode}): {rc.stdout[-2000:]}{rc.stderr[-2000:]}")
    subprocess.run([sys.executable, "-m", "coverage", "combine", "-q"], cwd=tree, env=env, check=True)
    import coverage

    cov = coverage.Coverage(data_file=str(data_file))
    cov.load()
    data = cov.get_data()
    lines = {}
    for measured in data.measured_files():
        rel = os.path.relpath(measured, tree)
        for number, contexts in data.contexts_by_lineno(measured).items():
            tests = {_node_id(c, pool) for c in contexts if c}
            if tests:
                lines.setdefault(rel, {})[str(number)] = sorted(tests)
    cache.write_text(json.dumps({"digest": digest, "lines": lines}))
    return {(f, int(n)): set(t) for f, ls in lines.items() for n, t in ls.items()}


def _node_id(context, pool):
    """A coverage test context (with ``dynamic_context = test_function``, the dotted name of the
    test function) as a pytest node id without parameters."""
    name = context.split("|")[-1]
    module, _, func = name.rpartition(".")
    for path in pool:
        if Path(path).stem == module.split(".")[-1]:
            return f"{path}::{func}"
    return name


def _env(tree):
    tree = Path(tree).resolve()
    return {**os.environ, "PYTHONPATH": f"{tree}{os.pathsep}{tree / 'tests'}", "PYTHONDONTWRITEBYTECODE": "1"}


def _context(tree, pool):
    """The digest of the test files that map lines to tests and of the designs the tool builds."""
    h = hashlib.sha256(ELABORATE.encode())
    for path in sorted(tree / p for p in pool):
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _tree_digest(tree, pool):
    h = hashlib.sha256()
    for path in sorted((tree / "hw").glob("*.py")) + [tree / p for p in pool]:
        h.update(path.read_bytes())
    return h.hexdigest()


def copy_tree(src, dst):
    """A copy of the source tree to write mutants into (the working tree is never changed)."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for name in TREE:
        s = src / name
        if s.is_dir():
            shutil.copytree(s, dst / name, symlinks=True, ignore=shutil.ignore_patterns("__pycache__", "build"))
        else:
            shutil.copy2(s, dst / name)
    return dst


# -- equivalence ------------------------------------------------------------------------------------


ELABORATE = r"""
import json, sys, warnings
warnings.simplefilter("ignore")
from amaranth.back import rtlil
from kfpga.core import registry
from kfpga.core.board import Board
from kfpga.core.spec import Build
from kfpga.hw.cores import build, make_core
from kfpga.core.config import FilterConfig
from kfpga.hw.divider import Divider
from kfpga.hw.top import FilterSystem
out = sys.argv[1]
designs = {"divider": lambda: Divider(dividend_bits=12, divisor_bits=6, quotient_bits=7),
           "top": lambda: FilterSystem(FilterConfig()),
           # the board's conversion timer (a [board] sample rate)
           "top-rate": lambda: FilterSystem(FilterConfig(board=Board(sample_rate_hz=50e6 / 600)))}
for spec in registry.specs():
    config = FilterConfig(filter=spec.name)
    for variant in spec.model.variants:
        for arch in spec.architectures(variant, spec.params()):
            for ch in (1, 3, 10):
                def make(spec=spec, config=config, variant=variant, arch=arch, ch=ch):
                    return make_core(config, variant, channels=ch, architecture=arch)
                designs[f"{spec.name}-{variant}-{arch}-{ch}"] = make
            if arch == "parallel":  # a pipelined loop at every register-stage count it takes
                for stages in range(1, 9):
                    def staged(spec=spec, config=config, variant=variant, stages=stages):
                        return make_core(config, variant, architecture="parallel", stages=stages)
                    designs[f"{spec.name}-{variant}-stages{stages}"] = staged
# the branches the defaults do not take: each preset, and each filter's own coverage designs
# (a config on one channel of every variant and architecture, or a core as it is)
models = {f"{spec.name}-{preset}": FilterConfig(filter=spec.name, params=params())
          for spec in registry.specs() for preset, (_, params) in (spec.model.presets or {}).items()}
for spec in registry.specs():
    for label, what in (spec.hardware.coverage() if spec.hardware.coverage is not None else {}).items():
        if isinstance(what, Build):
            designs[label] = lambda what=what: build(what)
        else:
            models[label] = what
for label, config in models.items():
    for variant in config.spec.model.variants:
        for arch in config.spec.architectures(variant, config.params):
            def one(config=config, variant=variant, arch=arch):
                return make_core(config, variant, architecture=arch)
            designs[f"{label}-{variant}-{arch}"] = one
done = {}
for name, make in designs.items():
    try:
        dut = make()
    except (ValueError, TypeError):
        continue  # more channels than this core holds, or a stage count (or stages at all) it does not take
    try:
        text = rtlil.convert(dut, name="top")
    except Exception as exc:  # the mutant breaks elaboration: a design that differs
        text = f"elaboration failed: {type(exc).__name__}: {exc}"
    with open(f"{out}/{name}.il", "w") as f:
        f.write(text)
    done[name] = True
json.dump(sorted(done), open(f"{out}/designs.json", "w"))
"""


def elaborate(tree, out):
    out.mkdir(parents=True, exist_ok=True)
    rc = subprocess.run([sys.executable, "-c", ELABORATE, str(out.resolve())], cwd=tree, env=_env(tree),
                        capture_output=True, text=True, timeout=1800)
    if rc.returncode != 0:
        return None, rc.stderr[-1500:]
    return json.loads((out / "designs.json").read_text()), ""


def _equal(gold, gate, folder):
    """Yosys's equivalence check of two RTLIL files' ``top`` modules; ``(proven, detail)``."""
    from kfpga.verify.mutate import _yosys

    script = (f"read_rtlil {gold.resolve()}\nrename top gold\nread_rtlil {gate.resolve()}\nrename top gate\n"
              "proc\nmemory_map\nopt_clean\nflatten\nequiv_make gold gate equiv\nhierarchy -top equiv\n"
              "equiv_simple -seq 5\nequiv_induct -seq 5\nequiv_status -assert\n")
    folder.mkdir(parents=True, exist_ok=True)
    try:
        code, log = _yosys(script, folder, timeout=600)
    except subprocess.TimeoutExpired:
        return False, "equivalence check timed out"
    return code == 0, "" if code == 0 else log.strip().splitlines()[-1][-200:] if log.strip() else "yosys failed"


def broken(original, mutant_dir):
    """The first design the tests build that the mutant no longer elaborates (or ``None``): a
    line run at import (a constant table, module-level code) is run by no test's context, but a
    design that cannot be built fails every test that builds it."""
    for p in sorted(original.glob("*.il")):
        gate = mutant_dir / p.name
        if not gate.exists() or gate.read_text().startswith("elaboration failed"):
            return p.name[:-3]
    return None


def equivalence(original, mutant_dir, folder):
    """``(equivalent, detail)`` of the designs elaborated in ``original`` and ``mutant_dir`` (every
    one of which elaborates: see :func:`broken`)."""
    differ = [p.name for p in sorted(original.glob("*.il"))
              if not (mutant_dir / p.name).exists() or (mutant_dir / p.name).read_text() != p.read_text()]
    if not differ:
        return True, "no design of the tool's set changes"
    for name in differ:
        gate = mutant_dir / name
        proven, why = _equal(original / name, gate, folder / name[:-3])
        if not proven:
            return False, f"{name[:-3]} differs ({why})"
    return True, f"{len(differ)} design(s) changed, each proven equal by Yosys equiv_induct"


# -- the run ------------------------------------------------------------------------------------------


def tests_of(covered, mutant):
    """The tests that run the mutant's lines; for a line no test's context runs (module-level code
    such as a constant table, run at import) every test that runs any line of its file."""
    lines = range(mutant.start[0], mutant.end[0] + 1)
    tests = set().union(*[covered.get((mutant.file, n), set()) for n in lines])
    if tests:
        return tests
    return set().union(*[t for (f, _), t in covered.items() if f == mutant.file])


def run_mutant(mutant, tree, tests, original, progress):
    path = tree / mutant.file
    source = path.read_text()
    path.write_text(apply(mutant, tree))
    try:
        mutant.tests = len(tests)
        if tests:
            rc = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-o", "addopts=",
                                 "-n", "2", "--timeout=600", *sorted(tests)], cwd=tree, env=_env(tree),
                                capture_output=True, text=True, timeout=7200)
            failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", rc.stdout, re.M)
            if failed:  # (with -x, xdist ends the run as interrupted: exit 2, not 1)
                mutant.result, mutant.by = "killed", failed[0]
                return mutant
            if rc.returncode not in (0, 5):
                last = (rc.stdout.strip().splitlines() or ["?"])[-1]
                mutant.result, mutant.by = "killed", f"pytest exit {rc.returncode}: {last[:160]}"
                return mutant
        folder = ROOT / "equiv" / f"{Path(mutant.file).stem}-{mutant.line}-{mutant.operator.replace('/', '')}"
        designs, why = elaborate(tree, folder / "mutant")
        if designs is None:
            mutant.result, mutant.by = "killed", f"elaboration fails: {why.strip().splitlines()[-1] if why else ''}"
            return mutant
        name = broken(original, folder / "mutant")
        if name is not None:
            mutant.result, mutant.by = "killed", f"{name} no longer elaborates (every test that builds it fails)"
            return mutant
        same, detail = equivalence(original, folder / "mutant", folder)
        mutant.result, mutant.by = ("equivalent" if same else "survived"), detail
        return mutant
    finally:
        path.write_text(source)


#: Every verdict measured, one JSON line a mutant, appended as it is measured.
VERDICTS = "verdicts.jsonl"


def _verdicts():
    """``{mutant key: fields}`` of the verdicts measured before (the last of each key)."""
    path = ROOT / VERDICTS
    if not path.exists():
        return {}
    out = {}
    for line in path.read_text().splitlines():
        try:
            fields = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interrupted run
        fields["start"], fields["end"] = tuple(fields["start"]), tuple(fields["end"])
        out[Mutant(**fields).key] = fields
    return out


def kept_verdicts(verdicts, context):
    """The verdicts an unchanged file's mutants keep: killed, or measured in the same ``context``."""
    return {key: fields for key, fields in verdicts.items()
            if fields["result"] == "killed" or fields.get("context") == context}


def summary(mutants):
    rows = {}
    for m in mutants:
        r = rows.setdefault(m.file, {"file": m.file, "mutants": 0, "killed": 0, "equivalent": 0, "survived": 0,
                                     "seconds": 0.0})
        r["mutants"] += 1
        r[m.result] += 1
        r["seconds"] += m.seconds
    for r in rows.values():
        scored = r["mutants"] - r["equivalent"]
        r["score"] = r["killed"] / scored if scored else 1.0
    return sorted(rows.values(), key=lambda r: r["file"])


def table(rows):
    lines = [f"{'file':<24} {'mutants':>7} {'killed':>6} {'equiv':>5} {'survived':>8} {'score':>7}"]
    for r in rows:
        lines.append(f"{r['file']:<24} {r['mutants']:>7} {r['killed']:>6} {r['equivalent']:>5} {r['survived']:>8} "
                     f"{100 * r['score']:>6.1f}%")
    return "\n".join(lines)


def markdown(rows):
    """The per-file table as Markdown (the manual's table)."""
    lines = ["| file | mutants | killed | equivalent | survived | score | minutes |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| `{r['file']}` | {r['mutants']} | {r['killed']} | {r['equivalent']} | {r['survived']} | "
              f"{100 * r['score']:.0f} % | {r['seconds'] / 60:.1f} |" for r in rows]
    return "\n".join(lines)


def _parser():
    parser = argparse.ArgumentParser(
        prog="python -m kfpga.verify.srcmutate",
        description="Source-level mutation of hw/: seeded mutants of the RTL-building Python (operators, constants, "
                    "Mux operands, dropped statements, inverted conditions), each run against the tests that execute "
                    "its line; survivors checked for equivalence with Yosys. Writes build/mutate/source/report.json "
                    "and prints the score per file (goal: >= 95 percent).",
        epilog="example: python -m kfpga.verify.srcmutate --mutants 3 --seed 1 --only divider")
    parser.add_argument("--mutants", type=int, default=3, help="mutants per file (default 3)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the sites' draw (default 1)")
    parser.add_argument("--only", metavar="TEXT", help="the files whose name contains TEXT (several: a,b,c)")
    parser.add_argument("--tests", nargs="+", metavar="FILE", default=POOL,
                        help="the test files that map lines to tests (default: the Amaranth-simulator tests of hw/)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--markdown", action="store_true", help="print the per-file table as Markdown")
    parser.add_argument("--fresh", action="store_true",
                        help="run every mutant again (by default a mutant of an unchanged file keeps its verdict from "
                             f"{ROOT / VERDICTS}, so an interrupted run resumes)")
    return parser


def main(argv=None):
    parser = _parser()
    args = parser.parse_args(argv)
    if args.mutants < 1:
        parser.exit(2, f"{parser.prog}: error: --mutants must be >= 1, not {args.mutants}\n")
    missing = [t for t in args.tests if not Path(t).is_file()]
    if missing:
        parser.exit(2, f"{parser.prog}: error: --tests: no such file {missing[0]}\n")
    here = Path.cwd()
    files = sorted(p.relative_to(here).as_posix() for p in (here / "hw").glob("*.py"))
    files = [f for f in files if f not in NOT_RTL]
    wanted = [t.strip().lower() for t in (args.only or "").split(",") if t.strip()]
    files = [f for f in files if not wanted or any(t in f.lower() for t in wanted)]
    if not files:
        parser.exit(2, f"{parser.prog}: error: no file of hw/ matches --only {args.only!r}\n")
    t0 = time.perf_counter()
    done = _run(args, here, files)
    rows = summary(done)
    report = {"seed": args.seed, "mutants_per_file": args.mutants, "seconds": round(time.perf_counter() - t0),
              "measured_seconds": round(sum(m.seconds for m in done)), "summary": rows,
              "mutants": [asdict(m) for m in done]}
    (ROOT / "report.json").write_text(json.dumps(report, indent=2))
    if args.json:
        print(json.dumps(report, indent=2))
    elif args.markdown:
        print(markdown(rows))
    else:
        print(table(rows))
        survivors = [m for m in done if m.result == "survived"]
        for m in survivors:
            print(f"survived: {m.file}:{m.line} {m.operator} `{m.before}` -> `{m.after}` ({m.by})")
        print(f"\n{report['seconds']} s this run, {report['measured_seconds']} s of mutant runs in all; every mutant "
              f"and its fate: {ROOT / 'report.json'}")
    return 0 if all(r["score"] >= 0.95 for r in rows) else 1


def _say(text):
    print(text, file=sys.stderr, flush=True)


def _run(args, here, files):
    """Every mutant of ``files`` drawn, run (or its verdict kept), in order."""
    _say(f"seed {args.seed} (replay with --seed {args.seed}), {args.mutants} mutants per file, {len(files)} files")
    ROOT.mkdir(parents=True, exist_ok=True)
    tree = copy_tree(here, ROOT / "tree")
    chosen = [m for f in files for m in mutants_of(f, args.mutants, args.seed, root=tree)]
    context = _context(tree, args.tests)
    # a killed mutant stays killed while its file is unchanged; any other verdict also needs the
    # same tests and the same designs (a new test may kill it)
    kept = {} if args.fresh else kept_verdicts(_verdicts(), context)
    # every verdict kept: no coverage pass needed
    covered = {} if all(m.key in kept for m in chosen) else line_tests(tree, _say, args.tests)
    _say("elaborating every design from the original source ...")
    original, why = elaborate(tree, ROOT / "original")
    if original is None:
        raise SystemExit(f"the original source does not elaborate: {why}")
    done = []
    for k, mutant in enumerate(chosen, 1):
        if mutant.key in kept:
            mutant = Mutant(**kept[mutant.key])
            note = "kept from an earlier run: its file is unchanged"
        else:
            t1 = time.perf_counter()
            run_mutant(mutant, tree, tests_of(covered, mutant), ROOT / "original", _say)
            mutant.seconds, mutant.context = round(time.perf_counter() - t1, 1), context
            with (ROOT / VERDICTS).open("a") as f:  # at once: an interrupted run keeps what it measured
                f.write(json.dumps(asdict(mutant)) + "\n")
            note = f"{mutant.seconds:.0f} s"
        done.append(mutant)
        _say(f"[{k}/{len(chosen)}] {mutant.file}:{mutant.line} {mutant.operator} `{mutant.before}` -> `{mutant.after}`: "
             f"{mutant.result} ({mutant.by}; {mutant.tests} test(s) run the line; {note})")
    return done


if __name__ == "__main__":
    sys.exit(main())
