"""Static timing estimate for the Cyclone II EP2C20Q240C8 (speed grade -8), without Quartus.

# Ref: FloPoCo, src/Targets/CycloneII.hpp: per-element delays "obtained from Quartus II 11.1"
#      (Chip Planner and experiments); the speed grade is not stated.
# Ref: Cyclone II Device Handbook, vol. 1, ch. 5 "DC Characteristics and Timing Specifications"
#      (the per-grade -6/-7/-8 figures): its tables were not available here, so the FloPoCo
#      figures are scaled by DERATE_C8, an estimate, and the report says so.

The analysis runs on the carry-aware Yosys netlist that ``hw/resources.py`` builds: LUT4s from
ABC, adders and comparators kept whole (one carry chain each), products as 18x18 (or 9x9)
multiplier blocks, flip-flops. Arrival times are computed per net bit:

* a flip-flop's output arrives ``t_co`` after the clock edge; its input must arrive
  ``t_su`` before the next one;
* a LUT adds ``t_lut`` and the LUT-to-LUT routing ``t_route``;
* a carry chain: bit ``j`` of a sum or carry-out arrives at the latest over ``i <= j`` of
  (input bit ``i`` + ``t_lut`` into the chain + ``(j - i) * t_carry`` + ``t_carry_lab`` per LAB
  boundary crossed) + ``t_carry_sum`` + ``t_route``: a path through the low bits of a wide
  adder is short, one through its top is long;
* a multiplier: every output bit at the latest input + ``t_route_mul`` in, ``t_mul18`` (or
  ``t_mul9``), ``t_route_mul`` out (the blocks are unregistered in these designs).

Fan-out, placement and clock skew are not modelled; a Quartus timing report is the final word.
The worst register-to-register path gives the estimated Fmax; the I/O paths constrained in the
.sdc are reported apart, each against its own budget.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Delay", "DELAYS", "DERATE_C8", "delay", "TimingPath", "TimingReport", "analyse"]


@dataclass(frozen=True)
class Delay:
    """One figure of the delay model (ns, before derating)."""

    symbol: str
    description: str
    value: float
    source: str
    status: str  # "source" (a source's figure, its grade not stated) or "assumed"


#: The delay model, in one table (ns). Change a figure here and every report follows.
DELAYS = {
    d.symbol: d
    for d in (
        Delay("t_lut", "LUT4, input to output", 0.419, "FloPoCo CycloneII.hpp lutDelay_ (Quartus 11.1)", "source"),
        Delay("t_route", "routing between two LEs (LUT to LUT)", 0.450, "FloPoCo CycloneII.hpp lut2lutDelay_", "source"),
        Delay("t_carry", "carry chain, per bit", 0.071, "FloPoCo CycloneII.hpp fastcarryDelay_ (Chip Planner 11.1)",
              "source"),
        Delay("t_carry_lab", "carry chain, into the next LAB (every 16 bits)", 0.159,
              "FloPoCo CycloneII.hpp innerLABcarryDelay_ (Chip Planner 11.1)", "source"),
        Delay("t_carry_sum", "carry in to sum out", 0.410, "FloPoCo CycloneII.hpp carryInToSumOut_ (Chip Planner 11.1)",
              "source"),
        Delay("t_mul18", "18x18 embedded multiplier, unregistered", 2.499,
              "FloPoCo CycloneII.hpp multiplierDelay_[1] (Quartus 11.1)", "source"),
        Delay("t_mul9", "9x9 embedded multiplier, unregistered", 2.181, "FloPoCo CycloneII.hpp multiplierDelay_[0]",
              "source"),
        Delay("t_mul_reg", "a multiplier's own input or output register, clock to output (such a register costs no LE)",
              0.104, "FloPoCo CycloneII.hpp: the 18x18 figure \"contains the DSP output register = 0.104ns\"", "source"),
        Delay("t_route_mul", "routing between logic and a multiplier", 0.765, "FloPoCo CycloneII.hpp DSPToLogicWireDelay",
              "source"),
        Delay("t_m4k", "M4K read, clock to data", 3.245, "FloPoCo CycloneII.hpp RAMDelay_ (Quartus 11.1)", "source"),
        Delay("t_route_m4k", "routing between an M4K block and logic", 0.351,
              "FloPoCo CycloneII.hpp RAMToLogicWireDelay_", "source"),
        Delay("t_co", "LE register clock to output, with its net", 0.352, "FloPoCo CycloneII.hpp fdCtoQ_", "source"),
        Delay("t_su", "LE register setup", 0.084, "FloPoCo CycloneII.hpp ffDelay_", "source"),
        Delay("t_pad_in", "input pin to the first LE (3.3-V LVTTL)", 1.5,
              "not in the sources here: a conservative figure for an IOE input path", "assumed"),
        Delay("t_pad_out", "LE to output pin (3.3-V LVTTL)", 3.5,
              "not in the sources here: a conservative figure for an IOE output path", "assumed"),
    )
}

#: From the source's figures to the slowest grade, -8 (the EP2C20Q240C8). The source does not
#: state its grade; it is taken as the fastest (-6), and -8 as 1.4 times slower: the Cyclone II
#: handbook rates the multipliers "up to 250 MHz" and the M4K blocks "up to 260 MHz" at the
#: fastest grade, and each slower grade costs Altera's families of that era 15-20 %. An estimate.
DERATE_C8 = 1.40


def delay(symbol, derate=DERATE_C8):
    """A figure of :data:`DELAYS` in ns, derated to the -8 grade."""
    return DELAYS[symbol].value * derate


@dataclass
class TimingPath:
    """One path: where it starts and ends, and each cell on it with the delay it adds (ns)."""

    start: str
    end: str
    delay_ns: float
    steps: list = field(default_factory=list)  # (what, the net it drives, ns)
    kind: str = "reg2reg"  # "reg2reg", "input" or "output"
    budget_ns: float | None = None

    def as_dict(self):
        return {"kind": self.kind, "start": self.start, "end": self.end, "delay_ns": round(self.delay_ns, 3),
                "budget_ns": self.budget_ns, "steps": [{"cell": c, "drives": n, "ns": round(d, 3)} for c, n, d in self.steps]}


@dataclass
class TimingReport:
    """The estimate for the design's one clock domain, ``clk50``."""

    worst: TimingPath | None
    io_paths: list
    derate: float

    @property
    def worst_path_ns(self):
        return self.worst.delay_ns if self.worst else 0.0

    @property
    def fmax_mhz(self):
        return 1000.0 / self.worst_path_ns if self.worst_path_ns > 0 else math.inf

    def as_dict(self):
        return {"domain": "clk50", "worst_path_ns": round(self.worst_path_ns, 3),
                "fmax_mhz_estimate": round(self.fmax_mhz, 1), "derate": self.derate,
                "worst_path": self.worst.as_dict() if self.worst else None,
                "io_paths": [p.as_dict() for p in self.io_paths]}


def _is_ff(cell_type):
    return "dff" in cell_type.lower()


#: A block RAM left whole by ``hw/resources.py`` (an M4K block): its read data is registered
#: inside it and its inputs are sampled at the clock, so paths start and end at it.
MEMORY_CELL = "kfpga_mem"


def _is_sequential(cell_type):
    return _is_ff(cell_type) or cell_type == MEMORY_CELL


def _bits(cell, port):
    return cell["connections"].get(port, [])


def _ports(cell, direction):
    return [p for p, d in cell.get("port_directions", {}).items() if d == direction]


def _param(cell, name):
    value = str(cell["parameters"].get(name, "0"))
    return int(value, 2) if set(value) <= {"0", "1"} and len(value) > 8 else int(value)


class _Arrivals:
    """Arrival times of net bits: ``bit -> (ns, previous bit, cell)`` or ``None`` (not timed)."""

    def __init__(self, module, derate, input_delays):
        self.cells = module["cells"]
        self.derate = derate
        self.input_delays = input_delays
        self.driver, self.ff_q = {}, {}
        for name, cell in self.cells.items():
            table = self.ff_q if _is_sequential(cell["type"]) else self.driver
            for port in _ports(cell, "output"):
                for bit in _bits(cell, port):
                    if isinstance(bit, int):
                        table[bit] = name
        self.port_of = {bit: pname for pname, port in module["ports"].items() for bit in port["bits"]
                        if isinstance(bit, int)}
        self.names = {}
        for net, info in module["netnames"].items():
            for bit in info["bits"]:
                if isinstance(bit, int) and (bit not in self.names or _better(net, self.names[bit])):
                    self.names[bit] = net
        self.arrival = {}

    def d(self, symbol):
        return delay(symbol, self.derate)

    def name(self, bit):
        return self.names.get(bit, f"bit {bit}")

    def at(self, bit):
        if not isinstance(bit, int):
            return None  # a constant
        stack = [bit]
        while stack:
            b = stack[-1]
            if b in self.arrival:
                stack.pop()
            elif b in self.ff_q:
                memory = self.cells[self.ff_q[b]]["type"] == MEMORY_CELL
                self.arrival[b] = (self.d("t_m4k") + self.d("t_route_m4k") if memory else self.d("t_co"), None,
                                   self.ff_q[b])
            elif b not in self.driver:  # a port, or undriven
                port = self.port_of.get(b)
                timed = port in self.input_delays
                self.arrival[b] = (self.input_delays[port] + self.d("t_pad_in"), None, f"port {port}") if timed else None
            else:
                cell = self.cells[self.driver[b]]
                pending = [i for p in _ports(cell, "input") for i in _bits(cell, p)
                           if isinstance(i, int) and i not in self.arrival]
                if pending:
                    stack.extend(pending)
                else:
                    self._evaluate(self.driver[b])
        return self.arrival[bit]

    def _latest(self, bits):
        best = None
        for bit in bits:
            a = self.arrival.get(bit) if isinstance(bit, int) else None
            if a is not None and (best is None or a[0] > best[0]):
                best = (a[0], bit)
        return best

    def _evaluate(self, name):
        cell = self.cells[name]
        kind = cell["type"]
        outs = [b for p in _ports(cell, "output") for b in _bits(cell, p) if isinstance(b, int)]
        if kind == "$alu":
            self._carry_chain(name, cell)
            for bit in outs:
                self.arrival.setdefault(bit, None)
            return
        entry = self._latest([b for p in _ports(cell, "input") for b in _bits(cell, p)])
        if kind == "kfpga_mul":
            small = _param(cell, "A_WIDTH") <= 9 and _param(cell, "B_WIDTH") <= 9
            cost = 2 * self.d("t_route_mul") + self.d("t_mul9" if small else "t_mul18")
        elif kind == "$macc":  # a multi-operand adder: through its whole chain
            cost = self.d("t_lut") + len(outs) * self.d("t_carry") + self.d("t_carry_sum") + self.d("t_route")
        else:  # a LUT, or any gate ABC left: one logic level
            cost = self.d("t_lut") + self.d("t_route")
        for bit in outs:
            self.arrival[bit] = None if entry is None else (entry[0] + cost, entry[1], name)

    def _carry_chain(self, name, cell):
        a, b = _bits(cell, "A"), _bits(cell, "B")
        ci = [x for x in _bits(cell, "CI") if isinstance(x, int)]
        y, co, x = _bits(cell, "Y"), _bits(cell, "CO"), _bits(cell, "X")
        running = None  # (ns, bit): the carry into position j
        for j in range(max(len(a), len(b), len(y), 1)):
            if running is not None:
                lab = self.d("t_carry_lab") if j % 16 == 0 else 0.0
                running = (running[0] + self.d("t_carry") + lab, running[1])
            entry = self._latest([v[j] for v in (a, b) if j < len(v)] + (ci if j == 0 else []))
            if entry is not None and (running is None or entry[0] + self.d("t_lut") > running[0]):
                running = (entry[0] + self.d("t_lut"), entry[1])
            for bits in (y, co):
                if j < len(bits) and isinstance(bits[j], int):
                    self.arrival[bits[j]] = None if running is None else (
                        running[0] + self.d("t_carry_sum") + self.d("t_route"), running[1], name)
            if j < len(x) and isinstance(x[j], int):  # A xor B: a LUT beside the chain
                e = self._latest([v[j] for v in (a, b) if j < len(v)])
                self.arrival[x[j]] = None if e is None else (e[0] + self.d("t_lut") + self.d("t_route"), e[1], name)

    def path(self, bit, end, extra, kind, budget=None):
        """The path that sets ``bit``'s arrival, plus ``extra`` ns at its end."""
        steps, cur, start = [], bit, None
        while cur is not None:
            ns, prev, cell = self.arrival[cur]
            before = self.arrival[prev][0] if prev is not None else 0.0
            steps.append((self._what(cell), self.name(cur), ns - before))
            if prev is None:
                start = cell[5:] if cell.startswith("port ") else self.name(cur)
            cur = prev
        steps.reverse()
        steps.append(("setup" if kind != "output" else "pad + output delay", end, extra))
        return TimingPath(start, end, self.arrival[bit][0] + extra, steps, kind, budget)

    def _what(self, cell):
        if cell.startswith("port "):
            return "input delay + pad"
        kind = self.cells[cell]["type"]
        if _is_ff(kind):
            return "register"
        if kind == MEMORY_CELL:
            return "M4K read"
        return {"$lut": "LUT", "$alu": "carry chain", "kfpga_mul": "multiplier", "$macc": "adder"}.get(kind, kind)


def _better(new, old):
    """Prefer a name a user wrote (no ``$``), then the shorter."""
    if old.startswith("$") != new.startswith("$"):
        return old.startswith("$")
    return len(new) < len(old)


def _origin(arr, bit):
    cur = bit
    while True:
        a = arr.arrival[cur]
        if a[1] is None:
            return a[2]
        cur = a[1]


def _register_paths(arr, cell, worst, io, budget):
    """The paths into a register (or block memory) ``cell``: the worst register-to-register
    path so far, returned, and into ``io`` each input port's worst path (``budget(port)``: its
    time, ns)."""
    q = next((b for p in _ports(cell, "output") for b in _bits(cell, p) if isinstance(b, int)), None)
    # into an M4K block: the route to it, then its input register's setup
    setup = arr.d("t_su") + (arr.d("t_route_m4k") if cell["type"] == MEMORY_CELL else 0.0)
    for bit in (b for port in _ports(cell, "input") for b in _bits(cell, port)):
        if arr.at(bit) is None:
            continue
        total = arr.arrival[bit][0] + setup
        origin = _origin(arr, bit)
        end = arr.name(q) if q is not None else "register"
        if origin.startswith("port "):
            pname = origin[5:]
            if pname not in io or total > io[pname].delay_ns:
                io[pname] = arr.path(bit, end, setup, "input", budget(pname))
        elif worst is None or total > worst.delay_ns:
            worst = arr.path(bit, end, setup, "reg2reg")
    return worst


def analyse(module, *, period_ns=20.0, derate=DERATE_C8, input_delays=None, output_delays=None, multicycle=None):
    """The timing estimate of a Yosys JSON module (the carry-aware netlist).

    ``input_delays`` and ``output_delays`` map ports to their .sdc max delays (ns),
    ``multicycle`` input ports to their setup multicycle; other ports are not timed (the .sdc
    makes them false paths).
    """
    input_delays, output_delays, multicycle = dict(input_delays or {}), dict(output_delays or {}), dict(multicycle or {})
    arr = _Arrivals(module, derate, input_delays)
    worst, io = None, {}
    for cell in module["cells"].values():
        if _is_sequential(cell["type"]):
            worst = _register_paths(arr, cell, worst, io, lambda port: period_ns * multicycle.get(port, 1))
    for pname, port in module["ports"].items():
        if port["direction"] != "output" or pname not in output_delays:
            continue
        for bit in port["bits"]:
            if arr.at(bit) is None:
                continue
            extra = arr.d("t_pad_out") + output_delays[pname]
            if pname not in io or arr.arrival[bit][0] + extra > io[pname].delay_ns:
                io[pname] = arr.path(bit, pname, extra, "output", period_ns)
    return TimingReport(worst, sorted(io.values(), key=lambda p: -(p.delay_ns / p.budget_ns)), derate)
