"""Mutation testing of the hardware blocks (``make mutate``): do the tests notice a wrong design?

For each block, Yosys's ``mutate -list N -seed S`` picks N single-bit changes in the block's
RTLIL (a cell's input or output bit tied to 0 or 1, or inverted; an output connected to
another wire). Each mutant is then run against two killers in turn:

1. the block's tests: its cocotb bench on the mutant's Verilog (Icarus), which checks every
   output against the bit-accurate model and every ADS8364 timing rule;
2. if it survives those, the block's formal properties (``kfpga/verify/properties.py``) on the same
   mutation of the property harness's copy of the block (SymbiYosys).

A mutant both miss is checked for equivalence with the original block (memories mapped to
registers, one per word): Yosys's ``equiv_induct`` with the registers matched by name, as
written, with constants folded, and, for a one-channel core, with the channel field held at 0
(its input contract: it takes channel numbers below its channel count), each with unused
names purged and with every name kept; then, for a change in
the logic that does not depend on the samples, an explicit-state search of that logic
(``kfpga/verify/reach.py``); then a miter of the two, proven equal by k-induction with SymbiYosys or,
for a miter of at most 11 register bits, by a bounded check from power-up as deep as it has
states (complete: every reachable state lies on a path that repeats none). A proof makes it
*equivalent* (no test could see it); otherwise it *survived*.
The score is killed / (mutants - equivalent), per block.

    python -m kfpga.verify.mutate [--mutants N] [--seed S] [--only BLOCK] [--json]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import re
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from amaranth.back import rtlil

from kfpga.core import registry
from kfpga.hw.cores import make_core
from kfpga.hw.generate import figures_only, plain_module_names
from kfpga.verify.formal import divider_widths, warm

__all__ = ["Block", "blocks", "main"]

ROOT = Path("build") / "mutate"


@dataclass
class Block:
    """A block to mutate: the design its bench runs, where the block sits in it, the bench, and
    its property harness."""

    name: str
    design: str  # the runner's design name (sim/runner.py)
    opts: dict
    make: object = field(repr=False)  # () -> the design's elaboratable
    toplevel: str = ""
    module: str = ""  # the block's module in the design's RTLIL ("" = the top)
    bench: str = ""
    params: dict = field(default_factory=dict)
    testcase: str | list | None = None
    formal: str | None = None  # the block's label in kfpga.verify.formal.jobs(), whose harness holds it as top.dut
    data: dict | None = None  # {port: [bit, ...]}: the input bits that carry samples (kfpga/verify/reach.py)
    tied: dict | None = None  # {port: [bit, ...]}: input bits that the block's input contract holds at 0

    @property
    def target(self):
        return self.module or self.toplevel


def blocks():

    from kfpga.core.config import FilterConfig
    from kfpga.hw.clockdiv import ClockDivider
    from kfpga.hw.divider import Divider
    from kfpga.hw.generate import TOP_NAME
    from kfpga.hw.top import AdcFrontend, FilterSystem

    config = FilterConfig()
    # the time-varying core's divider, at its widths, alone: its own bench drives every kind of
    # operand, where the core's bench reaches few of them
    widths = divider_widths()
    # each filter's cores on the core bench (its spec's ``mutation``); their formal harnesses hold
    # other instances (the defaults' widths and channels, narrow formats, the folded core's
    # handshake twin), where this instance's cells are not, so no property kills here
    cores = []
    for spec in registry.specs():
        for b in spec.hardware.mutation() if spec.hardware.mutation is not None else ():
            def make(b=b):
                return make_core(b.config, b.variant, channels=b.channels)
            cores.append(Block(b.label, "core", {"variant": b.variant, "channels": b.channels, "config": b.config}, make,
                               "kfpga_core", "", "test_core",
                               {"variant": b.variant, **b.signal, "channels": b.channels, "p_idle": 0.2, "p_ready": 0.7,
                                "config_toml": b.config.to_toml(), "check_ranges": b.config.check_ranges}, None, None,
                               sample_bits(make()), channel_bits_tied(make())))
    return [
        Block("clock divider", "divider", {"ratio": 10}, lambda: ClockDivider(ratio=10), "kfpga_divider", "",
              "test_clockdiv", {"ratio": 10}, None, "clock divider /10"),
        Block("ADS8364 controller", "frontend", {"six": False, "channel": 4},
              lambda: AdcFrontend(six_channel=False, channel=4), "kfpga_frontend", "kfpga_frontend.controller",
              "test_ads8364", {"samples": 30, "six": False, "channel": 4}, None, "controller C0"),
        Block("restoring divider", "restoring", widths, lambda: Divider(**widths), "kfpga_restoring", "",
              "test_restoring", {**widths, "samples": 1500, "p_idle": 0.2, "p_ready": 0.7}, None,
              f"divider {widths['dividend_bits']}/{widths['divisor_bits']}->{widths['quotient_bits']}"),
        Block("top level", "top", {"variant": "steady", "channel": 1},
              lambda: FilterSystem(config, variant="steady", channel=1), TOP_NAME, "", "test_top",
              {"variant": "steady", "samples": 60, "channel": 1, "scenario": "stress"},
              ["system_bit_exact", "reset_release_latency"]),
        *cores,
    ]


def sample_bits(core):
    """``{"i__payload": bits}``: the bits of a core's input word that carry samples (every field
    but the channel number)."""
    layout = figures_only(core).i.payload.shape()
    return {"i__payload": [f.offset + k for name, f in layout if name != "channel" for k in range(f.width)]}


def channel_bits_tied(core):
    """``{"i__payload": bits}``: the channel field's bits of a one-channel core's input word
    (``None`` for more channels). A core takes channel numbers below its channel count (its
    input contract); with one channel the field is one bit, always 0 (hw/layouts.py)."""
    core = figures_only(core)
    if core.channels != 1:
        return None
    field = dict(core.i.payload.shape())["channel"]
    return {"i__payload": list(range(field.offset, field.offset + field.width))}


def _tie(block, il_path, module, prefix=""):
    """Yosys commands that hold the inputs ``block.tied`` of ``module`` (in ``il_path``; its
    port names are the block's with ``prefix``) at 0, the rest free: each such port becomes an
    internal wire, driven bit by bit by 0 or by a new input ``free_<port>``."""
    lines = []
    for port, bits in (block.tied or {}).items():
        name = prefix + port
        width = _port_width(il_path, name)
        lines += [f"add -input free_{port} {width} {module}", f"delete -input {module}/w:{name}", f"cd {module}"]
        lines += [f"connect -nounset -set {name}[{k}] " + ("1'0" if k in bits else f"free_{port}[{k}]") for k in range(width)]
        lines.append("cd ..")
    return "\n".join(lines) + "\n" if lines else ""


def _port_width(il_path, wire):
    match = re.search(rf"^\s*wire width (\d+) input \d+\s+\\{re.escape(wire)}$", il_path.read_text(), re.M)
    if match is None:
        raise RuntimeError(f"no input {wire} in {il_path}")
    return int(match.group(1))


def _yosys(script, cwd, timeout=None):
    from kfpga.verify.formal import yosys

    return yosys(script, cwd, timeout)


#: Seconds one equiv_induct try may take (a few on most blocks; on a large core a try that
#: cannot succeed can run for many minutes, and the checks after it decide the mutant).
EQUIV_INDUCT_TIMEOUT_S = 120


def _bench(name, verilog_text, seed, out):
    """Child process: build the mutant for Icarus and run the block's bench; puts 'killed' or 'passed'."""
    from kfpga.sim.runner import SimulationFailed, build, run

    block = next(b for b in blocks() if b.name == name)
    try:
        built = build("icarus", block.design, root=ROOT / "sim", verilog_text=verilog_text, **block.opts)
        run(built, block.bench, testcase=block.testcase, params={**block.params, "seed": seed}, tag="mutant")
        out.put("passed")
    except (SimulationFailed, AssertionError, RuntimeError, OSError) as exc:
        out.put(f"killed: {str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__}")


def _run_bench(block, verilog_text, seed, timeout=300):
    queue = multiprocessing.get_context("spawn").Queue()
    proc = multiprocessing.get_context("spawn").Process(target=_bench, args=(block.name, verilog_text, seed, queue))
    proc.start()
    proc.join(timeout)
    if proc.is_alive():
        proc.kill()
        proc.join()
        return False, f"killed: the bench did not finish in {timeout} s (a hang)"
    result = queue.get() if not queue.empty() else "killed: the bench crashed"
    return result == "passed", result


#: Seconds an equivalence proof may take before the mutant counts as not proven equivalent.
EQUIVALENCE_TIMEOUT_S = 900


def _sby(folder, il_name, mode, depth, top="top"):
    """Prove the assertions of ``il_name`` (``mode`` prove or bmc, to ``depth``); the status word
    (ERROR after :data:`EQUIVALENCE_TIMEOUT_S`)."""
    from kfpga.verify.formal import PREP, sby, status

    (folder / "check.sby").write_text(f"[options]\nmode {mode}\ndepth {depth}\nmulticlock off\n\n"
                                      f"[engines]\nsmtbmc yices\n\n[script]\nread_rtlil {il_name}\n"
                                      f"{PREP.format(top=top)}\n[files]\n{il_name}\n")
    shutil.rmtree(folder / "check", ignore_errors=True)
    sby(folder, "check.sby", timeout=EQUIVALENCE_TIMEOUT_S)
    return status(folder / "check")


def run_block(block, count, seed, progress):
    folder = ROOT / re.sub(r"[^a-z0-9]+", "_", block.name.lower())
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    (folder / "design.il").write_text(rtlil.convert(block.make(), name=block.toplevel))
    from kfpga.verify import formal

    checks = [j for j in formal.jobs() if j.block == block.formal]
    ok, log = _yosys(f"read_rtlil design.il\nmutate -list {count} -seed {seed} -o mutations.ys {block.target}\n", folder)
    if not ok:
        raise RuntimeError(f"mutate -list failed for {block.name}:\n{log}")
    lines = [ln for ln in (folder / "mutations.ys").read_text().splitlines() if ln.startswith("mutate ")]
    _extract(block, "", folder, "gold")  # the original, through the same flow, for the equivalence checks
    # the unmutated design through the same flow must pass its bench, or no kill would mean anything
    base = folder / "original"
    base.mkdir()
    shutil.copy(folder / "design.il", base / "design.il")
    ok, log = _yosys("read_rtlil design.il\nproc -nomux -norom\nmemory_collect\nwrite_verilog -norename mutant.v\n", base)
    passed, why = _run_bench(block, plain_module_names((base / "mutant.v").read_text()), seed) if ok else (False, log)
    if not passed:
        raise RuntimeError(f"{block.name}: the unmutated design fails its bench through the mutation flow: {why}")
    rows = []
    for n, line in enumerate(lines, start=1):
        mdir = folder / f"m{n:03d}"
        mdir.mkdir()
        shutil.copy(folder / "design.il", mdir / "design.il")
        row = {"mutant": n, "mutation": line, "result": None, "by": None}
        ok, log = _yosys(f"read_rtlil design.il\n{line}\nproc -nomux -norom\nmemory_collect\n"
                         "write_verilog -norename mutant.v\n", mdir)
        if not ok:
            row.update(result="invalid", by=log.strip().splitlines()[-1] if log.strip() else "yosys failed")
            rows.append(row)
            progress(block, row)
            continue
        passed, why = _run_bench(block, plain_module_names((mdir / "mutant.v").read_text()), seed)
        if not passed:
            row.update(result="killed", by="tests", detail=why)
        elif (caught := _formal_kills(block, line, mdir, checks)):
            row.update(result="killed", by="formal", detail=caught)
        else:
            row.update(**_equivalence(block, line, mdir, folder))
        rows.append(row)
        progress(block, row)
    return rows


def _formal_kills(block, line, mdir, checks):
    """The first of the block's properties that the mutant breaks (a counterexample, or a cover
    it makes unreachable), or ``None``."""
    from kfpga.verify.formal import run_job

    mutated = line.replace(f"-module {block.target} ", "-module top.dut ")
    for job in checks:
        row = run_job(job, mdir / "formal", mutation=mutated)
        if not row["ok"]:
            return f"{job.prop}: {row['result']}"
    return None


def _extract(block, line, folder, name):
    """``folder/<name>.il``: the block's module of ``folder/design.il`` with the ``mutate`` line
    ``line`` applied ("" for none), processes lowered, flattened, renamed ``name``; whether it worked."""
    ok, _ = _yosys(f"read_rtlil design.il\n{line}\nhierarchy -top {block.target}\nproc -norom\nflatten\n"
                   f"rename {block.target} {name}\nwrite_rtlil {name}.il\n", folder)
    return ok


def _equivalence(block, line, mdir, folder):
    if not _extract(block, line, mdir, "gate"):
        return {"result": "survived", "by": None, "detail": "the mutant block could not be extracted"}
    shutil.copy(folder / "gold.il", mdir / "gold.il")
    ok, log = _yosys("read_rtlil gold.il\nread_rtlil gate.il\nmiter -equiv -flatten -make_assert -ignore_gold_x gold gate miter\n"
                     "hierarchy -top miter\nwrite_rtlil miter.il\n", mdir)
    if not ok:
        return {"result": "survived", "by": None, "detail": "no miter: " + log.strip()[-200:]}
    if block.tied:  # the inputs the block's contract holds at 0 are 0 in the miter too
        tie = _tie(block, mdir / "miter.il", "miter", "in_")
        ok, log = _yosys(f"read_rtlil miter.il\n{tie}hierarchy -top miter\nwrite_rtlil miter.il\n", mdir)
        if not ok:
            return {"result": "survived", "by": None, "detail": "no miter: " + log.strip()[-200:]}
    held = " (channel field at 0: a one-channel core's input contract)" if block.tied else ""
    if _touches_clock(line):
        # both checks below step every register on one clock: a mutant that inverts or moves a
        # clock changes when registers step, which they cannot see, so none may call it equivalent
        return {"result": "survived", "by": None, "detail": "a clock mutant: the equivalence checks model one clock"}
    if not _changes_memory_contents(line, folder) and (told := _matched_equivalence(block, mdir)) is not None:
        return {"result": "equivalent", "by": f"Yosys equiv_induct (registers matched{told})"}
    # a change in the logic that does not depend on the samples (a time-varying core's covariance
    # and gains): every reachable state of that logic, searched (kfpga/verify/reach.py)
    verdict = _data_independent(block, line, mdir) if block.data else None
    if verdict is not None and verdict.equivalent:
        return {"result": "equivalent", "by": f"explicit-state search of the data-independent logic: {verdict.why}"}
    status = _sby(mdir, "miter.il", "prove", 20, top="miter")
    if status == "PASS":
        return {"result": "equivalent", "by": f"SymbiYosys: k-induction on a miter{held}"}
    if status == "FAIL":
        return {"result": "survived", "by": None, "detail": "a difference exists (counterexample)"}
    # a small miter: every reachable state is reachable on a path that repeats no state, so a
    # bounded check from power-up as deep as there are states is a complete proof
    bits = _state_bits(mdir, "miter.il", "miter")
    if bits is not None and bits <= COMPLETE_BMC_BITS:
        depth = 2 ** bits + 1
        if _sby(mdir, "miter.il", "bmc", depth, top="miter") == "PASS":
            return {"result": "equivalent", "by": f"SymbiYosys: BMC of the miter to {depth} steps, complete for its "
                                                  f"{bits} register bits{held}"}
    return {"result": "survived", "by": None, "detail": "equivalence not proven"}


def _matched_equivalence(block, mdir):
    """The fast check of ``mdir/gold.il`` against ``mdir/gate.il``: the two designs' registers
    matched by name (Yosys's ``equiv_induct``); ``None`` if it fails, else what the proof
    assumed ("" for nothing, else "; ..."). Memories become registers, one per word
    (``memory_map``). It assumes that matched registers start equal, so it does not apply to a
    change of a memory's initial contents.

    It proves the mutants that change no reachable state, and those whose change goes nowhere.
    Tries, in turn: the designs as written; each design's constants folded first (Yosys's
    ``opt``: a register that holds a constant becomes that constant, so a change that only meets
    it goes nowhere); and, where the block's contract holds inputs at 0, those inputs held at 0
    in both designs before folding (a change that only shows with a channel number a
    one-channel core never takes is then no change). Each try runs twice: with the unused
    wires' names purged (logic that reaches no output goes: a changed bit of an unrouted field),
    then with every name kept (a mutation at a register's output can leave that register under
    another of its names in one design only, and ``equiv_make``, which matches by name, then
    finds no partner for it). A try stops after :data:`EQUIV_INDUCT_TIMEOUT_S` and fails."""
    tries = [("", ""), ("opt\n", "; constants folded")]
    if block.tied:
        held = "channel field at 0: a one-channel core's input contract"
        tries.append((_tie(block, mdir / "gold.il", "gold") + _tie(block, mdir / "gate.il", "gate") + "opt\n",
                      f"; constants folded, {held}"))
    for tie, told in tries:
        for clean in ("opt_clean -purge", "opt_clean"):
            ok, _ = _yosys(f"read_rtlil gold.il\nread_rtlil gate.il\n{tie}memory_collect\nmemory_map\n{clean}\n"
                           "equiv_make gold gate equiv\nhierarchy -top equiv\nasync2sync\nequiv_simple -seq 5\n"
                           "equiv_induct -seq 5\nequiv_status -assert\n", mdir, EQUIV_INDUCT_TIMEOUT_S)
            if ok:
                return told
    return None


def _changes_memory_contents(line, folder):
    """Whether the ``mutate`` line changes a memory's initial contents (a ``$meminit`` cell)."""
    cell = re.search(r"-cell (\S+)", line)
    text = (folder / "design.il").read_text()
    return bool(cell) and re.search(rf"^\s*cell \$meminit\S* {re.escape(cell.group(1))}$", text, re.M) is not None


def _data_independent(block, line, mdir):
    """:func:`kfpga.verify.reach.check` of the mutant against the original (``None`` when the netlists
    cannot be read).

    The mutation is made on the flattened original, so that every other cell keeps its name;
    where it does not apply there (a change at a submodule's port, or in logic that ``proc``
    folds to constants, such as a multiplexer of constants), both are flattened again from the
    block's RTLIL without that folding (``proc -noopt``), the mutation made before, and their
    generated names are matched by their order of creation."""
    from kfpga.verify import reach

    mutation = line.replace(f"-module {block.target} ", "-module gate ")
    ok, _ = _yosys(f"read_rtlil gold.il\nrename gold gate\n{mutation}\nwrite_rtlil gate_reach.il\n", mdir)
    gold = "gold.il"
    if not ok:
        gold = "gold_unfolded.il"
        for side, change in (("gold", ""), ("gate", f"{line}\n")):
            ok, _ = _yosys(f"read_rtlil design.il\n{change}hierarchy -top {block.target}\nproc -norom -noopt\nflatten\n"
                           f"rename {block.target} {side}\nwrite_rtlil {side}_unfolded.il\n", mdir)
            if not ok:
                return None
    try:
        return reach.check(reach.netlist_json(gold, "gate_reach.il" if gold == "gold.il" else "gate_unfolded.il", mdir),
                           block.data)
    except (RuntimeError, ValueError):  # a netlist the search cannot read: not decided here
        return None


def _touches_clock(line):
    """Whether a ``mutate`` line changes a clock: its port or wire is a clock (``clk`` in the
    name, or a flip-flop's clock input ``CLK``/``C``)."""
    words = line.split()
    names = [words[i + 1] for i, w in enumerate(words[:-1]) if w in ("-port", "-wire")]
    return any("clk" in n.lower() or n in ("CLK", "C") for n in names)


#: Miters with at most this many register bits get the complete bounded check (2^N + 1 steps).
COMPLETE_BMC_BITS = 11


def _state_bits(folder, il_name, top):
    """Register bits of ``top`` in ``il_name`` after the checks' preparation, or ``None``."""
    from kfpga.verify.formal import PREP

    ok, _ = _yosys(f"read_rtlil {il_name}\n{PREP.format(top=top)}flatten\nwrite_json state.json\n", folder)
    if not ok:
        return None
    design = json.loads((folder / "state.json").read_text())
    bits = 0
    for module in design["modules"].values():
        for cell in module["cells"].values():
            if "dff" in cell["type"] or cell["type"] in ("$ff", "$dlatch", "$adlatch"):
                bits += len(cell["connections"].get("Q", []))
    return bits


def summary(rows_by_block):
    out = []
    for name, rows in rows_by_block.items():
        valid = [r for r in rows if r["result"] != "invalid"]
        killed = sum(r["result"] == "killed" for r in valid)
        equivalent = sum(r["result"] == "equivalent" for r in valid)
        survived = sum(r["result"] == "survived" for r in valid)
        base = len(valid) - equivalent
        out.append({"block": name, "mutants": len(valid), "killed": killed,
                    "by_tests": sum(r["by"] == "tests" for r in valid), "by_formal": sum(r["by"] == "formal" for r in valid),
                    "equivalent": equivalent, "survived": survived,
                    "score": killed / base if base else 1.0})
    return out


def table(summary_rows):
    lines = ["| block | mutants | killed (tests / formal) | equivalent | survived | score |", "|---|---|---|---|---|---|"]
    for s in summary_rows:
        lines.append(f"| {s['block']} | {s['mutants']} | {s['killed']} ({s['by_tests']} / {s['by_formal']}) | "
                     f"{s['equivalent']} | {s['survived']} | {100 * s['score']:.1f} % |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="python -m kfpga.verify.mutate",
        description="Mutation testing of the hardware blocks: Yosys mutants of each block, killed by its cocotb "
                    "bench (Icarus) or its formal properties, survivors checked for equivalence with SymbiYosys. "
                    "Writes build/mutate/report.json and prints the score per block (goal: >= 95 %).")
    parser.add_argument("--mutants", type=int, default=20, help="mutants per block (default 20)")
    parser.add_argument("--seed", type=int, default=1, help="seed of Yosys's mutant selection and of the benches (default 1)")
    parser.add_argument("--only", metavar="TEXT", help="the blocks whose name contains TEXT")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    args = parser.parse_args(argv)
    if args.mutants < 1:
        parser.exit(2, f"{parser.prog}: error: --mutants must be >= 1, not {args.mutants}\n")
    from kfpga.hw.tools import simulator_available

    ok, why = simulator_available("icarus")
    if not ok:
        parser.exit(2, f"{parser.prog}: error: the benches run on Icarus: {why}\n")
    chosen = [b for b in blocks() if not args.only or args.only.lower() in b.name.lower()]
    if not chosen:
        parser.exit(2, f"{parser.prog}: error: no block matches --only {args.only!r}\n")
    print(f"seed {args.seed}, {args.mutants} mutants per block", file=sys.stderr)
    warm()
    t0 = time.perf_counter()

    def progress(block, row):
        print(f"{block.name} #{row['mutant']}: {row['result']}" + (f" ({row['by']})" if row.get("by") else "")
              + (f" - {row['detail']}" if row.get("detail") and row["result"] != "killed" else ""), file=sys.stderr,
              flush=True)

    rows = {}
    for b in chosen:
        t_block = time.perf_counter()
        rows[b.name] = run_block(b, args.mutants, args.seed, progress)
        # each block's report on its own too: blocks run one at a time keep theirs
        folder = ROOT / re.sub(r"[^a-z0-9]+", "_", b.name.lower())
        (folder / "report.json").write_text(json.dumps({
            "seed": args.seed, "mutants_per_block": args.mutants, "seconds": round(time.perf_counter() - t_block),
            "summary": summary({b.name: rows[b.name]}), "mutants": rows[b.name]}, indent=2))
    report = {"seed": args.seed, "mutants_per_block": args.mutants, "seconds": round(time.perf_counter() - t0),
              "summary": summary(rows), "mutants": rows}
    ROOT.mkdir(parents=True, exist_ok=True)
    (ROOT / "report.json").write_text(json.dumps(report, indent=2))
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(table(report["summary"]))
        print(f"\n{report['seconds']} s; mutants and their fates: {ROOT / 'report.json'}")
    return 0 if all(s["score"] >= 0.95 for s in report["summary"]) else 1


if __name__ == "__main__":
    sys.exit(main())
