"""The command line: reports, JSON, files written, and one-line errors for bad input."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.core.fixedmodel import FixedModel
from tests.helpers.expected import FILTERS, REGISTERED

COMPARE_KEYS = {"variant", "samples", "seed", "rmse_raw", "rmse_float", "rmse_fixed",
                "max_abs_fixed_minus_float_lsb", "sqnr_db", "overflows"}


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("variant", ["steady", "full"])
def test_compare_json_default_scenario(capsys, variant):
    code, out, err = run_cli(capsys, "compare", "--variant", variant, "--seed", "7", "--json")
    assert code == 0
    m = json.loads(out)
    assert set(m) >= COMPARE_KEYS
    assert (m["variant"], m["samples"], m["seed"]) == (variant, 20000, 7)
    assert m["rmse_fixed"] <= 1.01 * m["rmse_float"] and m["overflows"] == 0
    assert "seed 7" in err


def test_compare_prints_a_random_seed_that_replays(capsys):
    code, out1, err = run_cli(capsys, "compare", "--samples", "500", "--json")
    assert code == 0
    seed = json.loads(out1)["seed"]
    assert f"seed {seed}" in err
    _, out2, _ = run_cli(capsys, "compare", "--samples", "500", "--json", "--seed", str(seed))
    assert json.loads(out1)["rmse_fixed"] == json.loads(out2)["rmse_fixed"]


def test_compare_report_and_plot(capsys, tmp_path):
    png = tmp_path / "c.png"
    code, out, _ = run_cli(capsys, "compare", "--scenario", "random-accel", "--samples", "3000", "--seed", "1",
                           "--plot", str(png))
    assert code == 0
    assert "RMSE of x1 vs truth" in out and "SQNR" in out and "overflows" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def write_csv(path, header, rows):
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


def test_filter_one_row_per_input_row_bit_exact(capsys, tmp_path):
    rng = np.random.default_rng(3)
    y = np.clip(np.round(np.cumsum(rng.normal(0, 50, 700))), -32768, 32767).astype(int)
    src = write_csv(tmp_path / "in.csv", ["t", "y"], [[i, v] for i, v in enumerate(y)])
    dst = tmp_path / "out.csv"
    code, _, err = run_cli(capsys, "filter", "--input", str(src), "--output", str(dst), "--variant", "full")
    assert code == 0 and "700 samples filtered" in err
    rows = list(csv.DictReader(dst.open()))
    assert len(rows) == 700 and list(rows[0]) == ["x1", "x2", "yhat", "overflow"]
    model = FixedModel(variant="full")
    expected = model.to_float(model.run(y))
    for field in ("x1", "x2", "yhat"):
        np.testing.assert_array_equal([float(r[field]) for r in rows], expected[field])


def test_filter_float(capsys, tmp_path):
    src = write_csv(tmp_path / "in.csv", ["y"], [[v] for v in (0, 10, 20, 30)])
    dst = tmp_path / "out.csv"
    assert run_cli(capsys, "filter", "--input", str(src), "--output", str(dst), "--float")[0] == 0
    rows = list(csv.DictReader(dst.open()))
    assert len(rows) == 4 and list(rows[0]) == ["x1", "x2", "yhat"]


BAD_INPUTS = [
    (["y"], [["1"], ["abc"]], "line 3: y = 'abc' is not a number"),
    (["y"], [["1"], ["nan"]], "line 3: y is NaN"),
    (["y"], [], "no data rows after the header"),
    (["x", "z"], [["1", "2"]], "line 1: no column named 'y' (the header has: x, z)"),
    (["y"], [["5"], ["40000"]], "line 3: y = 40000 is outside the signed 16-bit range [-32768, 32767] (use --clip"),
    (["y"], [["-32769"]], "line 2: y = -32769 is outside"),
    (["y"], [["1.5"]], "line 2: y = 1.5 is not an integer ADC code"),
    (["t", "y"], [["1", "2"], ["2"]], "line 3: no value in column 'y'"),
]
#: An empty code cell is a sample with no measurement for ``kfpga filter`` (tests/test_missing.py);
#: ``compare`` measures every sample.
FILTER_TAKES = {"line 3: no value in column 'y'"}


@pytest.mark.parametrize(("command", "header", "rows", "message"),
                         [(c, *case) for c in ("filter", "compare") for case in BAD_INPUTS
                          if not (c == "filter" and case[2] in FILTER_TAKES)])
def test_bad_input_is_one_clear_line(capsys, tmp_path, header, rows, message, command):
    src = write_csv(tmp_path / "bad.csv", header, rows)
    argv = [command, "--input", str(src)] + (["--output", str(tmp_path / "o.csv")] if command == "filter" else [])
    code, _, err = run_cli(capsys, *argv)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in err
    assert not (tmp_path / "o.csv").exists()


def test_empty_file_and_missing_file(capsys, tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    code, _, err = run_cli(capsys, "filter", "--input", str(empty), "--output", str(tmp_path / "o.csv"))
    assert code == 2 and "the file is empty" in err
    code, _, err = run_cli(capsys, "filter", "--input", str(tmp_path / "nope.csv"), "--output", str(tmp_path / "o.csv"))
    assert code == 2 and "no such file" in err


def test_clip_saturates_and_reports(capsys, tmp_path):
    src = write_csv(tmp_path / "in.csv", ["y"], [["40000"], ["5"], ["-99999"], ["7"]])
    dst = tmp_path / "out.csv"
    code, _, err = run_cli(capsys, "filter", "--input", str(src), "--output", str(dst), "--clip")
    assert code == 0 and "2 input value(s) saturated" in err
    assert len(list(csv.DictReader(dst.open()))) == 4


def test_bad_config_is_one_clear_line(capsys, tmp_path):
    cfg = tmp_path / "k.toml"
    cfg.write_text("[model]\nR = -4.0\n")
    code, _, err = run_cli(capsys, "compare", "--config", str(cfg), "--samples", "100")
    assert code == 2 and err.strip() == "kfpga compare: error: model.R must be > 0, not -4.0"


def test_sweep_table_png_and_narrowest(capsys, tmp_path):
    png = tmp_path / "s.png"
    code, out, _ = run_cli(capsys, "sweep", "--bits", "9:16", "--samples", "4000", "--seed", "2", "--json",
                           "--plot", str(png), "--quiet")
    assert code == 0
    res = json.loads(out)
    rows = res["rows"]
    assert [r["bits"] for r in rows] == list(range(9, 17)) and res["budget"] == 0.01
    for r in rows:  # within the budget either way, nothing overflowed
        assert r["passes"] == (abs(r["rmse_fixed"] / r["rmse_float"] - 1) <= 0.01 and r["overflows"] == 0), r
    narrowest = res["narrowest_within_budget"]
    assert narrowest is not None
    assert all(r["passes"] for r in rows if r["bits"] >= narrowest)
    below = [r for r in rows if r["bits"] == narrowest - 1]
    assert not below or not below[0]["passes"]
    # the formats actually used: the operand e follows the width, the gain is N bits from the width
    # that holds its settled time-varying values within a quarter of 1 % (9 fraction bits) on
    assert [r["formats"]["gain"] for r in rows] == ["Q1.9", "Q1.9"] + [f"Q2.{n - 2}" for n in range(11, 17)]
    assert len({r["formats"]["e"] for r in rows}) == len(rows)
    assert png.stat().st_size > 1000
    # the answer does not depend on how far the range reaches below it
    code, out, _ = run_cli(capsys, "sweep", "--bits", f"{narrowest}:16", "--samples", "4000", "--seed", "2", "--json",
                           "--plot", str(png), "--quiet")
    assert json.loads(out)["narrowest_within_budget"] == narrowest
    code, out, _ = run_cli(capsys, "sweep", "--bits", "9:16", "--samples", "4000", "--seed", "2", "--budget", "50%",
                           "--json", "--plot", str(png), "--quiet")
    assert json.loads(out)["narrowest_within_budget"] == 9


def test_formats_table_and_toml(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "formats")
    assert code == 0 and "Q18.8" in out and "multiplier operand" in out
    code, out, _ = run_cli(capsys, "formats", "--toml")
    path = tmp_path / "k.toml"
    path.write_text(out)
    code, out2, _ = run_cli(capsys, "formats", "--config", str(path))
    assert code == 0 and "Q17.1" in out2


def test_console_script_help_and_usage_errors():
    exe = [sys.executable, "-m", "kfpga.cli"]
    out = subprocess.run([*exe, "--help"], capture_output=True, text=True, check=True).stdout
    for command in ("compare", "sweep", "filter", "filters", "formats", "generate", "simulate", "resources"):
        assert command in out
    bad = subprocess.run([*exe, "compare", "--samples", "-3"], capture_output=True, text=True)
    assert bad.returncode == 2 and "must be a positive integer" in bad.stderr and "Traceback" not in bad.stderr


def test_filters_lists_the_registry(capsys):
    code, out, _ = run_cli(capsys, "filters")
    assert code == 0
    assert out.splitlines()[0].startswith("kalman2    the paper's 2-state Kalman filter")
    assert "--variant steady" in out and "--variant full" in out and "outputs x1, x2, yhat" in out
    code, out, _ = run_cli(capsys, "filters", "--json")
    rows = json.loads(out)
    assert [r["name"] for r in rows] == list(FILTERS) and rows[0]["default"] and not rows[1]["default"]


def test_filter_option_and_config_must_agree(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "compare", "--filter", "kalman2", "--samples", "300", "--seed", "1", "--json")
    assert code == 0 and json.loads(out)["filter"] == "kalman2"
    code, _, err = run_cli(capsys, "compare", "--filter", "nosuch", "--samples", "300")
    assert code == 2 and err.strip() == ("kfpga compare: error: --filter: no filter named 'nosuch'; "
                                         "registered: " + REGISTERED)
    code, _, err = run_cli(capsys, "compare", "--variant", "fast", "--samples", "300")
    assert code == 2 and err.strip() == ("kfpga compare: error: variant must be one of steady, full for the kalman2 "
                                         "filter, not 'fast'")


def test_manual_synopsis_is_the_parsers():
    from pathlib import Path

    from kfpga.cli import synopsis

    page = (Path(__file__).parents[1] / "docs" / "cli.md").read_text()
    block = page.split("# Command line\n\n```\n", 1)[1].split("```", 1)[0]
    assert block.rstrip("\n") == synopsis(), "docs/cli.md's command synopsis differs from the parser: regenerate it"


def test_pins_write_follows_the_out_field_width(capsys, tmp_path):
    from kfpga.flows.quartus import BUILTIN_OUT_BITS, SPARE_OUT_PINS, load_pins

    # 28 bits: the two bits past the built-in 26 take the first spare pins of the board
    cfg = tmp_path / "wide.toml"
    cfg.write_text('[formats.x1]\nformat = "Q18.10"\n[formats.xl1]\nformat = "Q18.10"\n')
    table = tmp_path / "wide_pins.csv"
    code, _, err = run_cli(capsys, "pins", "--config", str(cfg), "--write", str(table))
    assert code == 0 and err.strip() == f"wrote {table}"
    data = [r for r in load_pins(table) if r.port == "out_data"]
    assert [r.bit for r in data] == list(range(28))
    assert [r.pin for r in data[BUILTIN_OUT_BITS:]] == [f"PIN_{p}" for p in SPARE_OUT_PINS[:2]]
    assert len({r.pin for r in load_pins(table)}) == len(load_pins(table)), "a pin is used twice"
    # 40 bits: past the spare pins, the last four rows need the user's pins
    cfg.write_text('[formats.x1]\nformat = "Q30.10"\n[formats.xl1]\nformat = "Q30.10"\n')
    code, _, err = run_cli(capsys, "pins", "--config", str(cfg), "--write", str(table))
    assert code == 0 and err.strip() == f"wrote {table}; 4 port bit(s) still need a pin of your board"
    data = [r for r in load_pins(table) if r.port == "out_data"]
    assert [r.bit for r in data] == list(range(40)) and [r.pin for r in data[36:]] == [""] * 4
    code, _, err = run_cli(capsys, "generate", "--config", str(cfg), "--pins", str(table), "--out", str(tmp_path / "o"),
                           "--no-lint")
    assert code == 2 and "out_data[36] has no pin yet; give it one of your board's free user I/O pins" in err
    # x2 on out_data: 25 bits, the default table's extra rows dropped
    code, out, _ = run_cli(capsys, "pins", "--out-field", "x2")
    assert code == 0 and sum(1 for line in out.splitlines() if line.startswith("out_data,")) == 25


def test_a_byte_order_mark_is_fine_everywhere(capsys, tmp_path):
    bom = b"\xef\xbb\xbf"
    src = tmp_path / "in.csv"
    src.write_bytes(bom + b"y\r\n1\r\n2\r\n3\r\n")
    dst = tmp_path / "out.csv"
    assert run_cli(capsys, "filter", "--input", str(src), "--output", str(dst))[0] == 0
    assert len(list(csv.DictReader(dst.open()))) == 3
    cfg = tmp_path / "k.toml"
    cfg.write_bytes(bom + b"[model]\nR = 9.0\n")
    code, out, _ = run_cli(capsys, "formats", "--config", str(cfg), "--json")
    assert code == 0 and json.loads(out)
    pins = tmp_path / "p.csv"
    code, out, _ = run_cli(capsys, "pins")
    pins.write_bytes(bom + out.encode())
    code, _, err = run_cli(capsys, "generate", "--pins", str(pins), "--out", str(tmp_path / "g"), "--no-lint")
    assert code == 0, err


def test_formats_toml_leaves_the_formats_to_the_parameters(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "formats", "--toml")
    assert code == 0 and '# format = "Q18.8"' in out and '\nformat = "' not in out
    path = tmp_path / "k.toml"
    path.write_text(out.replace("R = 4.0", "R = 400.0"))
    code, out2, err = run_cli(capsys, "formats", "--config", str(path), "--json")
    assert code == 0, err  # the formats follow the new R instead of failing on the old defaults
    assert {r["point"]: r["format"] for r in json.loads(out2)}["s"] != "Q7.11"
    code, out3, _ = run_cli(capsys, "formats", "--toml", "--pin-formats")
    assert '\nformat = "Q18.8"' in out3


def test_one_output_row_per_input_row_or_an_error(capsys, tmp_path):
    """A blank line in the middle is an error, never a dropped row; a final newline is not a row."""
    src = write_csv(tmp_path / "in.csv", ["y"], [[v] for v in range(5)])
    dst = tmp_path / "out.csv"
    assert run_cli(capsys, "filter", "--input", str(src), "--output", str(dst))[0] == 0
    assert len(list(csv.DictReader(dst.open()))) == 5


def test_manual_worked_example_runs_as_written(capsys, tmp_path, monkeypatch):
    """The manual's worked example (docs/own-model.md, a 3-state tracker at T = 0.01 s): its config
    file and its commands, in its order, in a fresh folder; the compare figure it prints is the run's."""
    import shlex
    from pathlib import Path

    page = (Path(__file__).parents[1] / "docs" / "own-model.md").read_text()
    section = page.split("## Worked example: your own tracker at T = 0.01 s", 1)[1]
    toml = section.split("```toml\n", 1)[1].split("```", 1)[0]
    block = section.split("```sh\n", 1)[1].split("```", 1)[0]
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()]
    commands = [shlex.split(line) for line in lines if line]
    assert [c[1] for c in commands] == ["formats", "compare", "explore", "generate", "simulate", "simulate"]
    monkeypatch.chdir(tmp_path)
    Path("tracker.toml").write_text(toml)
    Path("build").mkdir()
    formats, compare_, _, generate = commands[:4]  # explore and simulate: tests/test_own_model.py
    assert run_cli(capsys, *formats[1:])[0] == 0
    code, out, _ = run_cli(capsys, *compare_[1:], "--json")
    m = json.loads(out)
    assert code == 0 and m["filter"] == "kalman" and m["overflows"] == 0 and (tmp_path / "build" / "tracker.png").is_file()
    assert abs(m["rmse_fixed_over_float"] - 1) <= 0.01, m["rmse_fixed_over_float"]
    printed = section.split("fixed model      ", 1)[1].split("codes", 1)[0].split()[0]
    assert f"{m['rmse_fixed']:.4f}" == printed, "docs/own-model.md's compare output is stale"
    code, _, err = run_cli(capsys, *generate[1:], "--no-lint", "--quiet")
    assert code == 0 and (tmp_path / "build" / "tracker" / "kfpga_top.v").is_file(), err

