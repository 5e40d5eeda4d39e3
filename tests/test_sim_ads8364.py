"""The Verilog ADS8364 model (sim/ads8364_model.v) against the Python one (sim/ads8364.py).

Both models take the same pin scripts: legal conversions and reads, and each timing or protocol
violation a controller clocked at 50 MHz can make. Period by period, the EOC and D15..D0 that a
controller samples must be equal, and a violation must be flagged by both, at the same edge,
as the same rule. The Python model is the reference: it has its own unit tests
(tests/test_hw_ads8364.py) and checks edges in continuous time.

Four minimums cannot be broken at this resolution: tHOLDL and tW4 (20 ns), tHOLDH (15 ns) and
tD2 (20 ns) are met by any width of one system period (20 ns), the shortest a synchronous
controller can make; their zero-width cases (HOLD falling while RESET is low) are tested.
"""

import os
import subprocess
from pathlib import Path

import pytest

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.hw.tools import iverilog_path, verilator_env, verilator_root
from kfpga.sim import hdl
from kfpga.sim.ads8364 import ADS8364, TimingViolation
from tests.helpers.simulators import need

pytestmark = pytest.mark.cosim

P = SYSTEM_PERIOD_NS
FIRST_EDGE_NS = P // 2  # the harness's clock starts low
PINS = ("clk", "hold_a", "hold_b", "hold_c", "reset", "wr", "cs", "rd", "addr")
IDLE = {"clk": 0, "hold_a": 1, "hold_b": 1, "hold_c": 1, "reset": 1, "wr": 1, "cs": 1, "rd": 1, "addr": 0}


class Codes:
    """The harness's codes: ``8 j + c + 100`` for channel c of conversion j."""

    def __init__(self):
        self.j = 0

    def next(self):
        self.j += 1
        return [8 * (self.j - 1) + c + 100 for c in range(6)]


def clk_normal(k):
    return int(k % 10 >= 5)  # 200 ns period, 100 ns high


def legal_script(conversions=3, channels=(4,), clk=clk_normal):
    """Per system period, the pin levels of ``conversions`` conversions, each read on ``channels``:
    HOLD low one CLK period from a CLK falling edge, EOC after 20 CLK rising edges, then per
    channel CS low with the address, RD low 200 ns from a period later, RD up, CS up."""
    holds = sorted({f"hold_{'abc'[ch // 2]}" for ch in channels}) if len(channels) == 1 else ["hold_a", "hold_b",
                                                                                              "hold_c"]
    rows = [dict(IDLE) for _ in range(40)]
    for _ in range(conversions):
        while len(rows) % 10:
            rows.append(dict(IDLE, addr=rows[-1]["addr"]))
        addr = rows[-1]["addr"]
        rows += [dict(IDLE, addr=addr, **dict.fromkeys(holds, 0)) for _ in range(10)]
        rows += [dict(IDLE, addr=addr) for _ in range(200)]  # the conversion, EOC at its end
        for ch in channels:
            rows += [dict(IDLE, cs=0, addr=ch) for _ in range(10)]
            rows += [dict(IDLE, cs=0, rd=0, addr=ch) for _ in range(10)]
            rows += [dict(IDLE, cs=0, addr=ch), dict(IDLE, addr=ch)]
    rows += [dict(IDLE, addr=rows[-1]["addr"]) for _ in range(30)]
    for k, row in enumerate(rows):
        row["clk"] = clk(k)
    return rows


def python_model(script):
    """Run the Python model; ``(samples, violation)``: per period what a controller samples at
    that edge, and ``(period, message)`` of the first violation (or ``None``)."""
    adc = ADS8364(Codes())
    adc.adopt_levels(script[0])
    eoc, data, pending, samples = 1, 0, [], []
    for k, levels in enumerate(script):
        t = k * P
        for ev in sorted(e for e in pending if e[0] < t):
            if ev[1] == "eoc":
                eoc = ev[2]
            else:
                data = 0 if ev[2] is None else ev[2]
        pending = [e for e in pending if e[0] >= t]
        samples.append((eoc, data))
        if k == 0:
            continue
        try:
            pending += adc.pins(t, levels)
        except TimingViolation as exc:
            return samples, (k, str(exc))
    return samples, None


RULES = [("(tC1)", 1), ("CLK low time", 2), ("CLK high time", 3), ("(tHOLDL)", 4), ("(tHOLDH)", 5), ("(tD2)", 6),
         ("while RESET is low", 7), ("during a conversion", 8), ("(tW4)", 9), ("while RD is low", 10),
         ("same instant RD rose", 11), ("(tRDL)", 12), ("WR went low", 13), ("(tD9)", 14), ("cycle/FIFO mode", 15)]


def rule_of(message):
    return next(code for text, code in RULES if text in message)


@pytest.fixture(scope="module", params=["icarus", "verilator"])
def harness(request, tmp_path_factory):
    """The harness built for one simulator; returns ``run(script) -> (samples, errors, first, first_ns)``."""
    simulator = request.param
    need(simulator)
    folder = tmp_path_factory.mktemp(f"adc_{simulator}")
    hdl.write_model(folder)
    (folder / "check.v").write_text(hdl.check_harness())
    sources = [str(folder / "check.v"), str(folder / hdl.MODEL_FILE)]
    if simulator == "icarus":
        subprocess.run([iverilog_path(), "-g2005", "-o", str(folder / "check.vvp"), "-s", hdl.CHECK_NAME, *sources],
                       check=True, capture_output=True, timeout=120)
        command = [str(Path(iverilog_path()).with_name("vvp")), "-n", str(folder / "check.vvp")]
    else:
        subprocess.run([str(verilator_root() / "bin" / "verilator"), "--binary", "--timing", "-CFLAGS",
                        "-std=c++20 -fcoroutines", "-Wno-fatal", "-Wno-lint", "-Wno-style", "--top-module",
                        hdl.CHECK_NAME, "-Mdir", str(folder / "obj"), "-j", str(os.cpu_count() or 1), *sources],
                       check=True, capture_output=True, timeout=600, env=verilator_env())
        command = [str(folder / "obj" / f"V{hdl.CHECK_NAME}")]
    count = [0]

    def run(script):
        count[0] += 1
        path, out = folder / f"script{count[0]}.txt", folder / f"out{count[0]}.txt"
        path.write_text("".join(" ".join(str(row[p]) for p in PINS) + "\n" for row in script))
        subprocess.run([*command, f"+script={path}", f"+out={out}"], check=True, capture_output=True, timeout=60)
        lines = out.read_text().split("\n")
        rows = [tuple(int(v) for v in ln.split()) for ln in lines if ln.strip()]
        *samples, (errors, first, first_ns, conversions) = rows
        return samples, errors, first, first_ns, conversions

    return run


def compare(harness, script):
    """Both models on ``script``: the same samples up to the first violation, the same violation."""
    expected, violation = python_model(script)
    samples, errors, first, first_ns, conversions = harness(script)
    upto = len(expected)
    assert samples[:upto] == expected, next(
        f"period {k}: Verilog (EOC, D) {s}, Python {e}" for k, (s, e) in enumerate(zip(samples, expected, strict=False))
        if s != e)
    if violation is None:
        assert errors == 0, hdl.error_text(first, first_ns)
        return None, conversions
    period, message = violation
    assert errors >= 1, f"the Verilog model missed: {message}"
    assert (first, first_ns) == (rule_of(message), FIRST_EDGE_NS + (period + 1) * P), (
        f"Verilog: {hdl.error_text(first, first_ns)}; Python at period {period}: {message}")
    return first, conversions


@pytest.mark.parametrize("channels", [(4,), (0, 1, 2, 3, 4, 5), (1, 3)], ids=["one", "six", "two"])
def test_legal_conversions_and_reads_match(harness, channels):
    script = legal_script(conversions=3, channels=channels)
    first, conversions = compare(harness, script)
    assert first is None and conversions == 3
    # the reads saw the codes: D15..D0 carried 8 j + c + 100 for every channel read
    samples, *_ = harness(script)
    seen = {d for _, d in samples if d}
    assert seen == {8 * j + c + 100 for j in range(3) for c in channels}
    assert sum(1 for k in range(1, len(samples)) if samples[k][0] == 0 and samples[k - 1][0] == 1) == 3  # EOC pulses


def _block(script, start, levels):
    for k, v in enumerate(levels):
        script[start + k]["clk"] = v


def _first(script, pin, value, after=0):
    return next(k for k in range(after, len(script)) if script[k][pin] == value)


def _clk_period(s):
    _block(s, 300, [0, 0, 1, 1, 1, 0, 0, 0, 0, 0])  # rises 7 periods apart


def _clk_high(s):
    _block(s, 300, [0, 0, 0, 0, 0, 1, 1, 0, 0, 0])  # high for 40 ns


def _clk_low(s):
    _block(s, 300, [1, 1, 1, 1, 1, 1, 0, 0, 1, 1])  # low for 40 ns, period 260 ns


def _hold_converting(s):
    k = _first(s, "hold_c", 0) + 60
    s[k]["hold_c"] = 0


def _hold_in_reset(s):
    k = _first(s, "hold_c", 0)
    for j in range(k - 5, k + 3):
        s[j]["reset"] = 0


def _rd_short(s):
    k = _first(s, "rd", 0)
    for j in range(k + 1, k + 10):
        s[j]["rd"] = 1


def _addr_rd_low(s):
    k = _first(s, "rd", 0) + 4
    for j in range(k, k + 6):
        s[j]["addr"] = 5


def _addr_rd_rise(s):
    k = _first(s, "rd", 1, after=_first(s, "rd", 0))
    s[k]["addr"] = 5
    s[k + 1]["addr"] = 5


def _addr_setup(s):
    k = _first(s, "rd", 0)
    for j in range(k - 10, k):
        s[j]["addr"] = 2


def _wr_low(s):
    s[100]["wr"] = 0


def _addr_mode(s):
    k = _first(s, "cs", 0)
    for j in range(k, k + 22):
        s[j]["addr"] = 6


def violation_cases():
    """Each way to break the datasheet's timing: ``{name: edit of a legal script}``."""
    return {f.__name__[1:]: f for f in (_clk_period, _clk_high, _clk_low, _hold_converting, _hold_in_reset, _rd_short,
                                         _addr_rd_low, _addr_rd_rise, _addr_setup, _wr_low, _addr_mode)}


EXPECTED_RULE = {"clk_period": 1, "clk_high": 3, "clk_low": 2, "hold_converting": 8, "hold_in_reset": 7,
                 "rd_short": 12, "addr_rd_low": 10, "addr_rd_rise": 11, "addr_setup": 14, "wr_low": 13, "addr_mode": 15}


@pytest.mark.parametrize("case", list(EXPECTED_RULE))
def test_each_violation_is_flagged_by_both_models(harness, case):
    script = legal_script(conversions=2)
    violation_cases()[case](script)
    first, _ = compare(harness, script)
    assert first == EXPECTED_RULE[case], hdl.error_text(first)


def test_every_rule_a_controller_can_break_is_tested():
    """Every rule of the model is in a case above, except the four minimums a whole system
    period always meets (see the module's text)."""
    unbreakable = {4, 5, 6, 9}
    assert set(EXPECTED_RULE.values()) | unbreakable == set(hdl.ERRORS)
    assert all(v <= P for v in (hdl.model_parameters()[k] for k in ("THOLDL_NS", "THOLDH_NS", "TD2_NS", "TW4_NS")))
