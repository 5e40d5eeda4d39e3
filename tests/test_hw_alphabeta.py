"""The alpha-beta tracker's cores (hw/alphabeta.py) against the bit-accurate model.

The contract suite (``tests/contract``) runs the registered filter's core with its default
config; here: state in M4K block memory, any order of track ids, the same track back to back,
ids past the last track, the rate across tracks, the M4K count and the operation counts."""

import math
import re

import numpy as np
import pytest
from amaranth.sim import Simulator
from test_model_alphabeta import CONFIG, _track_words

from kfpga.core.config import FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.alphabeta import SteadyCore, TrackerCore, tracker_m4k_blocks
from kfpga.hw.storage import m4k_blocks
from kfpga.model import alphabeta as ab
from kfpga.model.alphabeta import MAX_TRACKS
from kfpga.sim.amaranth_streams import run_stream, run_with_deadline
from kfpga.sim.runner import SIMULATORS, build, run
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.sources import stress_codes
from tests.helpers.simulators import need

FROM_STATE = FilterConfig(filter="alphabeta", params=ab.AlphaBetaParams(init="state"))


def _check_tracker(config, words, out, tracks):
    board = Scoreboard(config, "steady")
    stray = []
    for w in words:
        if w["track"] < tracks:
            board.add_input(2 * w["track"] + w["axis"], {"z": w["z"]})
    for w, o in zip(words, out, strict=True):
        assert (int(o.track), int(o.axis)) == (w["track"], w["axis"])
        if w["track"] < tracks:
            board.add_output(channel=2 * int(o.track) + int(o.axis), x=int(o.x), v=int(o.v), overflow=int(o.overflow))
        else:
            stray.append((w, o))
    report = board.assert_ok()
    # an id past the last track: the estimate of the reset (zero) state, which stays unchanged
    model = FixedModel(config)
    for w, o in stray:
        r = model.run(np.array([w["z"]]))
        assert (int(o.x), int(o.v)) == (int(r.x[0]), int(r.v[0])), w
    return report, len(stray)


@pytest.mark.parametrize("tracks", [1, 3, 4, 40, MAX_TRACKS])
def test_tracker_bit_exact_any_order_with_backpressure(tracks, seed):
    """Random track ids and axes (states in registers up to 4 tracks, else in block memory), runs of
    the same track back to back, random valid/ready both sides."""
    rng = np.random.default_rng(seed)
    n = 1500
    words = _track_words(rng, n, tracks, repeats=True)
    dut = TrackerCore(CONFIG, tracks=tracks)
    out = run_stream(dut, words, seed=seed, p_idle=0.2, p_ready=0.7, extra_cycles=30)
    report, _ = _check_tracker(CONFIG, words, out, tracks)
    assert report["compared"] == n


@pytest.mark.parametrize("tracks", [3, 5, 100])
def test_track_ids_past_the_last_track_change_nothing(tracks, seed):
    """A track field wider than the tracks need: ids past the last give the zero state's estimate
    and update no state (for one track, id 1)."""
    rng = np.random.default_rng(seed)
    bits = max(1, (tracks - 1).bit_length())
    words = _track_words(rng, 800, 1 << bits)
    dut = TrackerCore(CONFIG, tracks=tracks)
    out = run_stream(dut, words, seed=seed, p_idle=0.1, p_ready=0.8, extra_cycles=30)
    _, stray = _check_tracker(CONFIG, words, out, tracks)
    assert stray > 0


def _handshakes(dut, words, cycles):
    """Offer ``words`` back to back with the output always ready; the clock cycle of each accepted
    input and of each output."""
    accepted, produced = [], []

    async def bench(ctx):
        ctx.set(dut.o.ready, 1)
        k = 0
        for cycle in range(cycles):
            if k < len(words):
                ctx.set(dut.i.valid, 1)
                ctx.set(dut.i.payload, words[k])
            else:
                ctx.set(dut.i.valid, 0)
            _, _, ready, valid = await ctx.tick().sample(dut.i.ready, dut.o.valid)
            if k < len(words) and ready:
                accepted.append(cycle)
                k += 1
            if valid:
                produced.append(cycle)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    run_with_deadline(sim, cycles + 10)
    return accepted, produced


@pytest.mark.parametrize("tracks", [4, 64])
def test_one_measurement_per_clock_across_tracks(tracks):
    """Tracks in turn (both axes of each): one measurement accepted every clock, registers or memory."""
    words = [{"track": (k // 2) % tracks, "axis": k % 2, "z": 100 + k} for k in range(6 * tracks)]
    accepted, produced = _handshakes(TrackerCore(CONFIG, tracks=tracks), words, len(words) + 40)
    assert np.all(np.diff(accepted) == 1), accepted
    assert len(produced) == len(words)


@pytest.mark.parametrize(("tracks", "gap"), [(4, 4), (64, 5)])
def test_the_same_track_back_to_back_stalls(tracks, gap):
    """One track and axis only: L = 4 cycles between updates in registers, L + 1 in memory (the
    read-after-write hazard is stalled, not forwarded: an M4K read gives the old word)."""
    words = [{"track": 1, "axis": 0, "z": 1000 * k} for k in range(20)]
    dut = TrackerCore(CONFIG, tracks=tracks)
    accepted, _ = _handshakes(dut, words, 20 * gap + 40)
    # the second enters the input register at once and waits there; from then on one every gap
    assert set(np.diff(accepted)[1:]) == {gap}
    assert dut.core.cycles_per_update == gap
    out = run_stream(TrackerCore(CONFIG, tracks=tracks), words, seed=1, extra_cycles=20)
    report, _ = _check_tracker(CONFIG, words, out, tracks)
    assert report["compared"] == 20


def test_state_memory_m4k_blocks():
    """x1 (26 bits), v (26 bits: it holds the first two plots' difference) and the start's 2-bit
    count: 54-bit words. 512 words deep an M4K block is 9 bits wide."""
    width = CONFIG.formats["x1"].width + CONFIG.formats["v"].width + 2
    assert width == 54
    assert tracker_m4k_blocks(CONFIG, 2 * MAX_TRACKS) == math.ceil(54 / 9) == 6
    assert tracker_m4k_blocks(CONFIG, 2 * 64) == math.ceil(54 / 36) == 2
    assert tracker_m4k_blocks(CONFIG, 8) == 0  # registers
    assert m4k_blocks(4096, 1) == 1 and m4k_blocks(257, 18) == 2 and m4k_blocks(8192, 2) == 4
    assert tracker_m4k_blocks(CONFIG, 200) == math.ceil(54 / 18) == 3  # 256 deep: 18 bits per block
    # from x0, no count: x1 and v (25 bits), 51
    from_state = FilterConfig(filter="alphabeta", params=ab.AlphaBetaParams(init="state"))
    assert from_state.formats["x1"].width + from_state.formats["v"].width == 51
    assert tracker_m4k_blocks(from_state, 2 * MAX_TRACKS) == math.ceil(51 / 9) == 6


@pytest.mark.parametrize(("tracks", "error", "message"), [
    (0, ValueError, "tracks must be an integer 1..256, not 0"),
    (257, ValueError, "tracks must be an integer 1..256, not 257"),
    ("8", TypeError, "tracks must be an integer, not '8'"),
])
def test_bad_track_count(tracks, error, message):
    with pytest.raises(error, match="^" + re.escape(message) + "$"):
        TrackerCore(CONFIG, tracks=tracks)


def test_alpha_beta_core_states_in_memory_bit_exact(seed):
    """The registered core with 16 states (block memory), channels in random order: the generic path."""
    rng = np.random.default_rng(seed)
    y = stress_codes(seed, 1200)
    ch = rng.integers(0, 16, len(y))
    dut = SteadyCore(CONFIG, channels=16)
    out = run_stream(dut, [{"channel": int(c), "z": int(v)} for c, v in zip(ch, y, strict=True)], seed=seed,
                     p_idle=0.3, p_ready=0.6, extra_cycles=30)
    board = Scoreboard(CONFIG, "steady")
    for c, v in zip(ch, y, strict=True):
        board.add_input(int(c), {"z": int(v)})
    for o in out:
        board.add_output(channel=int(o.channel), x=int(o.x), v=int(o.v), overflow=int(o.overflow))
    assert board.assert_ok()["compared"] == len(y)


@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize("order", ["random", "runs"])
def test_tracker_cosimulation_256_tracks_bit_exact(simulator, order, seed):
    """The generated Verilog with 512 states (256 tracks of two axes) in block memory, in cocotb:
    random state order (the tracker's words: channel = {track, axis}), or runs of the same
    state back to back, random valid/ready on both sides; every integer the model's."""
    need(simulator)
    result = run(build(simulator, "core", config=CONFIG, variant="steady", channels=2 * MAX_TRACKS), "test_core",
                 testcase="core_bit_exact",
                 params={"variant": "steady", "seed": seed, "samples": 3000, "channels": 2 * MAX_TRACKS,
                         "order": order, "p_idle": 0.2, "p_ready": 0.7, "config_toml": CONFIG.to_toml()},
                 tag=f"tracker-{order}")
    assert result["mismatches"] == 0 and result["ok"], result.get("first_mismatches")
    assert result["samples"] == 3000


def test_operation_counts_are_the_equations():
    """Counted on the updates (CostOps) against the equations counted by hand:
    alpha-beta: xp = x + v, e = z - xp, x = xp + alpha e, v = v + beta e: 4 additions, 2 products
    (shifts when the gain is a power of two); the time-varying Kalman filter (model/kalman2.py):
    xl1 1, pl11 3, pl12 1, pl21 1, pl22 1, S 1, e 1, x1 1, v 1, p 4 = 15 additions, K1 e, K2 e
    and four K pl products = 6 multiplications, 2 divisions."""
    from kfpga.core.ops import update_cost

    none = {"square roots": 0, "comparisons": 0, "selections": 0}
    assert update_cost(FilterConfig(filter="alphabeta", params=ab.AlphaBetaParams(alpha=0.4, beta=0.1, init="state")),
                       "steady") == \
        {"additions": 4, "multiplications": 2, "shifts": 0, "divisions": 0, **none}
    assert update_cost(FROM_STATE, "steady") == {"additions": 4, "multiplications": 0, "shifts": 2, "divisions": 0, **none}
    # the start from the first two plots: one subtraction, two comparisons of the count and five selections
    # (two of the next count, one of x, two of v)
    assert update_cost(CONFIG, "steady") == {"additions": 5, "multiplications": 0, "shifts": 2, "divisions": 0,
                                             "square roots": 0, "comparisons": 2, "selections": 5}
    assert update_cost(FilterConfig(), "full") == {"additions": 15, "multiplications": 6, "shifts": 0, "divisions": 2, **none}
