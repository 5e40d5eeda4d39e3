"""``kfpga evaluate``: every source document's evaluation runs over many seeds and judges each claim
of the document on all of them; the verdict rule; the defects the review found."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.cli.evaluate import DEFAULT_SEEDS, seeds_of
from kfpga.core import registry
from kfpga.core.claims import NOT_REPRODUCED, NOT_TESTABLE, REPRODUCED, Claim, claims_table, spread

EVALUATED = [spec.name for spec in registry.specs() if spec.load_evaluation() is not None]
VERDICTS = {REPRODUCED, NOT_REPRODUCED, NOT_TESTABLE}


def test_every_source_document_has_an_evaluation():
    # the five source documents, each with its filter
    assert set(EVALUATED) >= {"kalman2", "roll", "lsfront", "alphabeta", "tukey53h"}


@pytest.mark.parametrize("name", EVALUATED)
def test_claims_over_five_seeds(name, capsys):
    assert main(["evaluate", name, "--seeds", "5", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["seeds"] == [1, 2, 3, 4, 5]
    claims = out["claims"]
    assert len(claims) >= 3
    for c in claims:
        assert c["verdict"] in VERDICTS and c["claim"] and c["document"], c
        if c["verdict"] == NOT_TESTABLE:
            assert c["held"] is None and c["reason"], c  # a claim not tested says why
        else:
            assert c["runs"] >= 1 and 0 <= c["held"] <= c["runs"]
            assert (c["verdict"] == REPRODUCED) == (c["held"] == c["runs"]), c
    # a per-seed claim is judged on each of the five seeds
    assert any(c["runs"] >= 5 for c in claims)


@pytest.mark.parametrize("name", EVALUATED)
def test_claims_table_text(name, capsys):
    assert main(["evaluate", name, "--seeds", "2", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "the source document's claims, over 2 seeds, 1 .. 2:" in out
    assert "verdict:" in out and "document:" in out
    assert "against the paper" not in out and "confirmed" not in out  # no verdict read off one seed


def test_seeds_of():
    def ns(seed=None, seeds=None):
        return argparse.Namespace(seed=seed, seeds=seeds)

    assert seeds_of(ns()) == list(range(1, DEFAULT_SEEDS + 1))
    assert seeds_of(ns(seed=7)) == [7]
    assert seeds_of(ns(seeds=3)) == [1, 2, 3]
    assert seeds_of(ns(seed=10, seeds=2)) == [10, 11]


def test_one_seed_is_labelled_as_such(capsys):
    assert main(["evaluate", "53h", "--seed", "4"]) == 0
    out = capsys.readouterr().out
    assert "over 1 seed (4; a verdict needs many" in out


def test_claim_verdicts():
    assert Claim("c", "d", [True, True]).verdict == REPRODUCED
    assert Claim("c", "d", [True, False, True]).verdict == NOT_REPRODUCED
    assert Claim("c", "d", [True, False, True]).held == 2
    untested = Claim("c", "d", None, reason="no data")
    assert untested.verdict == NOT_TESTABLE and untested.to_json()["runs"] == 0
    with pytest.raises(ValueError, match="no run to judge it on"):
        Claim("c", "d", [])
    text = claims_table([Claim("c", "d", [True, False], "x")], "2 seeds, 1 .. 2")
    assert "NOT REPRODUCED (holds on 1 of 2)" in text and "0 reproduced, 1 not reproduced, 0 not testable" in text
    assert spread([1.0, 2.0, 3.0], ".3g") == "2 ± 1 (1 .. 3)" and spread([5.0]) == "5"


@pytest.mark.parametrize(("argv", "message"), [
    (["alpha-beta", "--alpha", "2.5"], "--alpha/--beta: alpha must be in (0, 2)"),
    (["alpha-beta", "--glitch", "0.9"], "--glitch must be a share of the plots in 0..0.5, not 0.9"),
    (["ls-frontend", "--table", "0.1:30,x"], "--table must be threshold:Ns pairs"),
    (["ls-frontend", "--table", "0.1:30,0.3:2,inf:5"], "Ns must be an integer >= 3"),
    (["ls-frontend", "--noise", "0"], "--noise must be in (0, 10] m/s, not 0"),
    (["53h", "--a-max", "-1"], "--a-max must be in (0, 100], not -1"),
    (["53h", "--v-max", "0"], "--v-max must be in (0, 100], not 0"),
    (["53h", "--seeds", "1001"], "--seeds must be at most 1000, not 1001"),
    (["53h", "--seeds", "0"], "argument --seeds: must be an integer >= 1, not '0'"),
])
def test_bad_options(argv, message, capsys):
    try:
        code = main(["evaluate", *argv])
    except SystemExit as exc:  # argparse's own checks
        code = exc.code
    assert code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]  # argparse puts its usage above
    assert message in last, last


# -- the document parameters as options ------------------------------------------------------------


def test_roll_noise_and_printed_a_change_the_figures(capsys):
    figures = []
    for extra in ([], ["--noise", "0.1"], ["--a-printed"]):
        assert main(["evaluate", "roll", "--seed", "3", "--json", *extra]) == 0
        out = json.loads(capsys.readouterr().out)
        figures.append(next(r["rmse_deg"] for r in out["rows"] if r["data"].startswith("synthetic")
                            and r["form"].startswith("improved")))
    assert figures[1] > figures[0] * 1.5  # [Zhang]'s sensor noise: far above 0.2 deg
    assert figures[2] != figures[0]


def test_alphabeta_options_name_the_tracker(capsys):
    assert main(["evaluate", "alpha-beta", "--seed", "2", "--alpha", "0.27", "--beta", "0.042", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = {r["filter"]: r for r in out["rows"]}
    yours = rows["alpha-beta (yours)"]
    assert (yours["alpha"], yours["beta"]) == (0.27, 0.042) and "alpha-beta (paper)" not in rows
    # near the steady Kalman gains, the accuracy of the time-varying Kalman filter
    assert yours["position_rmse"] < 1.2 * rows["Kalman (time-varying gain)"]["position_rmse"]


# -- the defects ------------------------------------------------------------------------------------


@pytest.mark.parametrize("command", [["compare"], ["simulate", "--samples", "40", "--quiet"]])
def test_alphabeta_random_accel_runs(command, capsys):
    """Once an AttributeError ('AlphaBetaParams' has no Q): the scenario asks the model for its noise."""
    assert main([*command, "--filter", "alpha-beta", "--scenario", "random-accel", "--seed", "1"]) == 0
    if command[0] == "compare":
        assert "scenario random-accel" in capsys.readouterr().out


@pytest.mark.parametrize("command", [["compare"], ["simulate", "--samples", "40"]])
def test_roll_refuses_another_scenario(command, capsys):
    """The roll predictor has one scenario; another one is refused, never run as a different one."""
    assert main([*command, "--filter", "roll", "--scenario", "random-accel", "--seed", "1"]) == 2
    assert "--scenario: the roll filter's scenarios are roll, not 'random-accel'" in capsys.readouterr().err


def test_alpha_beta_tracks_start_from_their_first_two_plots():
    """The evaluation's trackers (float and bit-accurate) start each track from its first two
    plots: the velocity from scan 1 on is their difference, not 106 px/scan."""
    from kfpga.model import alphabeta as ab
    from kfpga.model.evaluations.alphabeta import AlphaBetaScenario, _tracker, _tracks

    _, _, plots, _ = _tracks(AlphaBetaScenario(targets=4), np.random.default_rng(5))
    z = plots.reshape(-1, plots.shape[-1])
    params = ab.AlphaBetaParams(alpha=0.5, beta=0.5, R=4.0, init="measurement")
    (x, v), (fx, fv) = _tracker(params, z)
    assert np.array_equal(x[:, 1], z[:, 1]) and np.array_equal(v[:, 1], z[:, 1] - z[:, 0])
    assert np.allclose(fx[:, 1], z[:, 1]) and np.allclose(fv[:, 1], z[:, 1] - z[:, 0], atol=0.01)
    assert np.max(np.abs(v[:, 1])) < 10  # a plot's noise, never the position itself


def _manual_claims(name):
    """``[(claim, verdict with its count), ...]`` of the claims block on the filter's page of the
    manual (docs/filters/NAME.md), or ``None`` without one."""
    import re
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "filters" / f"{name}.md").read_text()
    for block_name, body in re.findall(r"<!-- claims (\w+):.*?-->\n(.*?)<!-- /claims -->", text, flags=re.S):
        if block_name == name:
            rows = [line.split(" | ") for line in body.splitlines() if re.match(r"\| \d+ \| ", line)]
            return [(row[1], row[4].split(":")[0].rstrip(" |")) for row in rows]
    return None


@pytest.mark.parametrize("name", EVALUATED)
def test_manual_quotes_the_default_runs_verdicts(name, capsys):
    """The manual's verdicts are the default run's (20 seeds), claim by claim, count by count."""
    quoted = _manual_claims(name)
    assert quoted is not None, f"docs/filters/{name}.md has no claims block: kfpga evaluate {name} --markdown"
    assert main(["evaluate", name, "--markdown", "--quiet"]) == 0
    ours = [(row[1], row[4].split(":")[0].rstrip(" |")) for row in
            (line.split(" | ") for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and
             line.split(" | ")[0][2:].isdigit())]
    assert len(ours) >= 3 and quoted == ours, f"docs/filters/{name}.md's claims are stale: kfpga evaluate {name} --markdown"


def test_filter_tracks_start_each_track_from_its_first_two_plots(tmp_path, capsys):
    """``kfpga filter --tracks``: each (track, axis) starts from its own first two plots, in float
    and bit-accurate, whatever the order the plots come in."""
    import csv

    plots = [(0, 0, 100), (1, 0, -40), (0, 1, 500), (0, 0, 103), (1, 0, -37), (0, 1, 498), (0, 0, 106)]
    src = tmp_path / "tracks.csv"
    src.write_text("track,axis,z\n" + "\n".join(f"{t},{a},{z}" for t, a, z in plots) + "\n")
    for exact in ([], ["--float"]):
        out = tmp_path / "out.csv"
        assert main(["filter", "--filter", "alpha-beta", "--tracks", "2", "--input", str(src), "--output", str(out),
                     *exact]) == 0
        rows = list(csv.DictReader(out.open()))
        v = [float(r["v"]) for r in rows]
        x = [float(r["x"]) for r in rows]
        assert x[:6] == [100, -40, 500, 103, -37, 498]  # each track's first two plots taken as they are
        assert v[3] == 3 and v[4] == 3 and v[5] == -2  # the rate: the two plots' difference
        assert abs(x[6] - 106) < 1e-6  # then the loop: the prediction 106 meets the plot 106
    capsys.readouterr()
