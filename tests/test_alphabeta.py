# amaranth: UnusedElaboratable=no
"""The alpha-beta tracker (seeds/004): its parameters, its relations, its equality with the
steady-state Kalman filter, and the many-track core against the bit-accurate model.

The contract suite (``tests/contract``) runs the registered filter's core with its default
config; here: state in M4K block memory, any order of track ids, the same track back to back,
ids past the last track, the rate across tracks, and the M4K count.
"""

import math
import re

import numpy as np
import pytest
from amaranth.sim import Simulator

from kfpga.core.config import ConfigError, FilterConfig
from kfpga.core.fixedmodel import FixedModel
from kfpga.hw.alphabeta import SteadyCore, TrackerCore, tracker_m4k_blocks
from kfpga.hw.storage import m4k_blocks
from kfpga.model import alphabeta as ab
from kfpga.model.alphabeta import MAX_TRACKS
from kfpga.model.reference import KalmanParams, steady_state, steady_state_gain
from kfpga.sim.amaranth_streams import run_stream, run_with_deadline
from kfpga.sim.runner import SIMULATORS, build, run
from kfpga.sim.scoreboard import Scoreboard
from kfpga.sim.sources import stress_codes
from tests.helpers.simulators import need

CONFIG = FilterConfig(filter="alphabeta")  # each track from its first two plots (the default)
FROM_STATE = FilterConfig(filter="alphabeta", params=ab.AlphaBetaParams(init="state"))


# -- parameters -------------------------------------------------------------------------------

@pytest.mark.parametrize(("kwargs", "message"), [
    ({"alpha": 2.0}, "alpha must be in (0, 2) for a stable tracker, not 2.0"),
    ({"alpha": 0.0}, "alpha must be in (0, 2) for a stable tracker, not 0.0"),
    ({"alpha": -0.1}, "alpha must be in (0, 2) for a stable tracker, not -0.1"),
    ({"alpha": 0.5, "beta": 3.0}, "beta must be in (0, 4 - 2*alpha) = (0, 3) for a stable tracker with alpha = 0.5, "
                                  "not 3.0"),
    ({"beta": 0.0}, "beta must be in (0, 4 - 2*alpha) = (0, 3) for a stable tracker with alpha = 0.5, not 0.0"),
    ({"T": 0.0}, "T must be > 0, not 0.0"),
    ({"T": -1.0}, "T must be > 0, not -1.0"),
    ({"R": 0.0}, "R must be > 0, not 0.0"),
])
def test_bad_parameters_are_refused_naming_them(kwargs, message):
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        ab.AlphaBetaParams(**kwargs)


def test_bad_parameter_in_a_config_names_the_key():
    with pytest.raises(ConfigError, match=re.escape("model.beta must be in (0, 4 - 2*alpha) = (0, 2.6)")):
        FilterConfig.from_dict({"filter": {"name": "alphabeta"}, "model": {"alpha": 0.7, "beta": 2.6}})


def test_stability_region_is_the_loops_poles_inside_the_unit_circle(seed):
    """``stable`` against the eigenvalues of the loop's matrix (I - K H) F, on random pairs."""
    rng = np.random.default_rng(seed)
    f = np.array([[1.0, 1.0], [0.0, 1.0]])
    for _ in range(500):
        a, b = rng.uniform(-0.5, 2.5), rng.uniform(-0.5, 4.5)
        poles = np.linalg.eigvals((np.eye(2) - np.array([[a], [b]]) @ np.array([[1.0, 0.0]])) @ f)
        inside = bool(np.all(np.abs(poles) < 1 - 1e-9))
        if abs(np.max(np.abs(poles)) - 1) > 1e-6:  # off the boundary
            assert ab.stable(a, b) == inside, (a, b, poles)


def test_relations():
    assert ab.benedict_bordner(0.5) == pytest.approx(1 / 6)
    # critically damped: both poles of the loop at theta = sqrt(1 - alpha)
    beta = ab.critically_damped(0.5)
    f = np.array([[1.0, 1.0], [0.0, 1.0]])
    poles = np.linalg.eigvals((np.eye(2) - np.array([[0.5], [beta]]) @ np.array([[1.0, 0.0]])) @ f)
    assert np.allclose(poles, math.sqrt(0.5), atol=1e-6)
    assert ab.kalman_relation(0.5) == pytest.approx(0.5)  # the paper's stated pair
    with pytest.raises(ValueError, match="alpha must be in"):
        ab.critically_damped(1.5)


@pytest.mark.parametrize("q", [0.01, 0.3, 2.0, 50.0])
def test_the_steady_state_kalman_gain_is_a_benedict_bordner_pair(q):
    """The Riccati solution (model/reference.py) of this model lies on beta = alpha^2/(2 - alpha)."""
    (k1, k2), _ = steady_state_gain(1.0, q, 4.0)
    assert k2 == pytest.approx(ab.benedict_bordner(k1), rel=1e-9)


# -- equal to the steady-state Kalman filter -----------------------------------------------------

@pytest.mark.parametrize("params", [KalmanParams(), KalmanParams(T=0.5, Q=0.3, R=9.0, x0=(100.0, -2.0)),
                                    KalmanParams(T=0.3, Q=1.0, R=2.0)], ids=["paper", "T=0.5", "T=0.3"])
def test_alpha_beta_with_the_kalman_gain_is_the_steady_state_kalman_filter(params, seed):
    """alpha = K1, beta = T K2: the same integers sample for sample (x and x1, v and x2), and
    the same float filter, with the Kalman filter's formats."""
    kalman = FilterConfig(params=params)
    track = FilterConfig(filter="alphabeta", params=ab.from_kalman(params),
                         formats={n: f for n, f in kalman.formats.items() if n in ab.POINTS}, check_ranges=False)
    y = stress_codes(seed, 3000)
    a = FixedModel(kalman, variant="steady").run(y)
    b = FixedModel(track).run(y)
    np.testing.assert_array_equal(a.x1, b.x)
    np.testing.assert_array_equal(a.x2, b.v)
    np.testing.assert_array_equal(a.overflow, b.overflow)
    fa = steady_state(y.astype(float), params)
    fb = ab.reference(ab.from_kalman(params), "steady", y.astype(float))
    np.testing.assert_allclose(fb["x"], fa["x1"], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(fb["v"], fa["x2"], rtol=1e-12, atol=1e-9)


def test_reference_follows_its_equations():
    """Two steps by hand: x0 = (10, 1), T = 2, alpha = 0.5, beta = 0.4; z = 14, 15."""
    p = ab.AlphaBetaParams(alpha=0.5, beta=0.4, T=2.0, x0=(10.0, 1.0), init="state")
    out = ab.reference(p, "steady", np.array([14.0, 15.0]))
    # xp = 12, e = 2: x = 13, v = 1 + 0.2 * 2 = 1.4; xp = 15.8, e = -0.8: x = 15.4, v = 1.4 - 0.16
    np.testing.assert_allclose(out["x"], [13.0, 15.4])
    np.testing.assert_allclose(out["v"], [1.4, 1.24])


# -- the many-track core ----------------------------------------------------------------------

def _track_words(rng, n, tracks, *, repeats=False):
    """``n`` measurements of random tracks and axes; with ``repeats``, each (track, axis) 1 to 3
    times in a row (the read-after-write hazard)."""
    ids, axes = rng.integers(0, tracks, n), rng.integers(0, 2, n)
    if repeats:
        runs = rng.integers(1, 4, n)
        ids, axes = np.repeat(ids, runs)[:n], np.repeat(axes, runs)[:n]
    z = stress_codes(int(rng.integers(1 << 30)), n)
    return [{"track": int(t), "axis": int(a), "z": int(v)} for t, a, v in zip(ids, axes, z, strict=True)]


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


# -- the evaluation (kfpga evaluate alpha-beta) ------------------------------------------------

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


def test_evaluate_alpha_beta_cli(tmp_path, capsys, seed):
    import json

    from kfpga.cli import main

    plot = tmp_path / "ab.png"
    assert main(["evaluate", "alphabeta", "--targets", "3", "--seed", str(seed % 1000), "--json",
                 "--plot", str(plot)]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = {r["filter"]: r for r in out["rows"]}
    raw, paper = rows["raw plots"], rows["alpha-beta (paper)"]
    # every recursive filter starts a track from its first two plots: no start-up transient
    kalman = rows["Kalman (time-varying gain)"]
    # the filters smooth the plots; the Kalman filter, optimal for this noise, beats every fixed gain
    assert paper["position_rmse"] < raw["position_rmse"]
    assert all(kalman["position_rmse"] < r["position_rmse"] for n, r in rows.items() if n != kalman["filter"])
    # the bit-accurate tracker within 2 % of its float filter
    for r in out["rows"]:
        if "bit_accurate_position_rmse" in r:
            assert abs(r["bit_accurate_position_rmse"] / r["position_rmse"] - 1) < 0.02, r
    assert out["scenario"]["targets"] == 3 and out["seeds"] == [seed % 1000]
    assert len(out["claims"]) >= 3 and all(c["runs"] in (0, 1) for c in out["claims"])
    assert plot.stat().st_size > 10000


@pytest.mark.parametrize(("args", "message"), [
    (["--targets", "0"], "--targets must be 1..256 (the tracker's limit), not 0"),
    (["--targets", "257"], "--targets must be 1..256 (the tracker's limit), not 257"),
    (["--seed", "x"], "argument --seed: must be an integer >= 0, not 'x'"),
    (["--plot", "nowhere/ab.png"], "--plot nowhere/ab.png: the folder nowhere does not exist"),
])
def test_evaluate_alpha_beta_bad_input(args, message, capsys, tmp_path, monkeypatch):
    from kfpga.cli import main

    monkeypatch.chdir(tmp_path)
    try:
        code = main(["evaluate", "alphabeta", *args])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2 and err.endswith(message), err


def test_filter_tracks_replay_matches_the_tracker(tmp_path, capsys, seed):
    """``kfpga filter --tracks N``: each (track, axis) its own state, the hardware's mapping; the
    bit-accurate output equals the many-track core on the same plots."""
    import csv

    from kfpga.cli import main

    rng = np.random.default_rng(seed)
    words = _track_words(rng, 400, 5, repeats=True)
    src = tmp_path / "plots.csv"
    src.write_text("track,axis,z\n" + "".join(f"{w['track']},{w['axis']},{w['z']}\n" for w in words))
    assert main(["filter", "--filter", "alphabeta", "--tracks", "5", "--input", str(src),
                 "--output", str(tmp_path / "out.csv")]) == 0
    rows = list(csv.DictReader((tmp_path / "out.csv").open()))
    out = run_stream(TrackerCore(CONFIG, tracks=5), words, seed=seed, extra_cycles=20)
    fx, fv = CONFIG.formats["x1"], CONFIG.formats["x2"]
    assert len(rows) == len(words) == len(out)
    for row, o in zip(rows, out, strict=True):
        assert (int(row["track"]), int(row["axis"])) == (int(o.track), int(o.axis))
        assert float(row["x"]) == fx.to_float(np.int64(o.x)) and float(row["v"]) == fv.to_float(np.int64(o.v))


@pytest.mark.parametrize(("text", "args", "message"), [
    ("track,axis,z\n0,0,1\n3,1,2\n", ["--tracks", "3"], "line 3: track = 3 is outside 0..2 (--tracks 3)"),
    ("track,axis,z\n0,2,1\n", ["--tracks", "3"], "line 2: axis = 2 is outside 0..1"),
    ("track,z\n0,1\n", ["--tracks", "3"], "line 1: no column named 'axis' (the header has: track, z)"),
    ("track,axis,z\n0,0,1\n", ["--tracks", "300"], "--tracks must be 1..256 (the tracker's limit), not 300"),
])
def test_filter_tracks_bad_input(text, args, message, tmp_path, capsys):
    from kfpga.cli import main

    src = tmp_path / "plots.csv"
    src.write_text(text)
    out = tmp_path / "out.csv"
    assert main(["filter", "--filter", "alphabeta", *args, "--input", str(src), "--output", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(message) and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_filter_tracks_needs_the_alpha_beta_filter(tmp_path, capsys):
    from kfpga.cli import main

    src = tmp_path / "plots.csv"
    src.write_text("track,axis,y\n0,0,1\n")
    assert main(["filter", "--tracks", "2", "--input", str(src), "--output", str(tmp_path / "o.csv")]) == 2
    assert "--tracks applies to the alphabeta filter, not to kalman2" in capsys.readouterr().err
