"""Inputs as people write them are accepted, and outputs appear whole or not at all.

The refusals (one line, exit 2, nothing written) are in ``test_cli_errors.py``; here: the CSV
variants that must give the same samples as the plain file, the temporary names outputs are
written under (a failed or interrupted command leaves nothing, a rerun no stale file), and
``simulate --input`` with a truth column."""

import json

import numpy as np
import pytest

from kfpga.cli import main
from kfpga.core.csvio import read_samples, read_series
from kfpga.core.paths import TEMP_PREFIX, atomic_dir, atomic_file, check_output_dir
from tests.helpers.simulators import need

PLAIN = "y,truth\n-20,-19.5\n-15,-15.25\n3,2.5\n7,7.0\n"

VARIANTS = {
    "bom": "\ufeff" + PLAIN,
    "trailing-blank-lines": PLAIN + "\n\n  \n",
    "comments": "# recorded 2026-12-05\n# codes, truth in codes\n" + PLAIN.replace("3,2.5\n", "# a note\n3,2.5\n"),
    "semicolons": PLAIN.replace(",", ";"),
    "tabs": PLAIN.replace(",", "\t"),
    "crlf": PLAIN.replace("\n", "\r\n"),
    "spaces": PLAIN.replace(",", ", "),
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_csv_variants_read_as_the_plain_file(tmp_path, variant):
    plain, other = tmp_path / "plain.csv", tmp_path / "other.csv"
    plain.write_text(PLAIN)
    other.write_bytes(VARIANTS[variant].encode("utf-8"))
    a, b = read_samples(plain), read_samples(other)
    assert a.y.tolist() == b.y.tolist() == [-20, -15, 3, 7]
    assert a.truth.tolist() == b.truth.tolist() == [-19.5, -15.25, 2.5, 7.0]


def test_a_single_column_without_header_is_the_input(tmp_path):
    path = tmp_path / "codes.csv"
    path.write_text("-20\n-15\n3\n7\n\n")
    samples = read_samples(path)
    assert samples.y.tolist() == [-20, -15, 3, 7] and samples.truth is None
    assert read_series(path).tolist() == [-20.0, -15.0, 3.0, 7.0]


@pytest.mark.parametrize("variant", ["semicolons", "comments", "headerless"])
def test_filter_writes_the_same_output_for_every_variant(tmp_path, variant):
    plain = tmp_path / "plain.csv"
    plain.write_text(PLAIN)
    other = tmp_path / "other.csv"
    other.write_text("-20\n-15\n3\n7\n" if variant == "headerless" else VARIANTS[variant])
    assert main(["filter", "--input", str(plain), "--output", str(tmp_path / "a.csv")]) == 0
    assert main(["filter", "--input", str(other), "--output", str(tmp_path / "b.csv")]) == 0
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()


# -- outputs whole or not at all -----------------------------------------------------------------


def test_atomic_file_leaves_nothing_when_the_writer_fails(tmp_path):
    target = tmp_path / "new" / "deeper" / "out.csv"
    with pytest.raises(RuntimeError), atomic_file(target) as temp:
        temp.write_text("half")
        raise RuntimeError("the writer failed")
    assert list(tmp_path.iterdir()) == []  # neither the file nor the folders made for it
    with atomic_file(target) as temp:
        temp.write_text("whole")
        assert not target.exists()  # not there until complete
    assert target.read_text() == "whole" and sorted(p.name for p in target.parent.iterdir()) == ["out.csv"]


def test_atomic_dir_replaces_the_folder_whole(tmp_path):
    out = tmp_path / "gen"
    with atomic_dir(out) as folder:
        (folder / "a.v").write_text("1")
        (folder / "stale.vvp").write_text("old")
    with atomic_dir(out) as folder:
        (folder / "a.v").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == ["a.v"] and (out / "a.v").read_text() == "2"
    with pytest.raises(KeyboardInterrupt), atomic_dir(out) as folder:
        (folder / "a.v").write_text("3")
        raise KeyboardInterrupt
    assert (out / "a.v").read_text() == "2"  # as it was
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(TEMP_PREFIX)]


def test_a_folder_with_other_files_is_not_replaced(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep")
    with pytest.raises(ValueError, match="holds files this command did not write"):
        check_output_dir(out, option="--out", marker="manifest.json")
    assert check_output_dir(tmp_path / "empty", option="--out", marker="manifest.json")


def test_testbench_rerun_leaves_no_stale_file_and_an_interrupt_leaves_nothing(tmp_path, monkeypatch, capsys):
    out = tmp_path / "tb"
    argv = ["testbench", "--out", str(out), "--samples", "50", "--seed", "3", "--architecture", "parallel"]
    assert main(argv) == 0
    (out / "kfpga_tb.vvp").write_text("a compiled testbench of an earlier run")
    assert main(argv) == 0
    assert not (out / "kfpga_tb.vvp").exists()
    assert sorted(json.loads((out / "testbench.json").read_text())["files"]) == sorted(p.name for p in out.iterdir())
    import kfpga.sim.testbench as tb

    real = tb.write_testbench

    def interrupted(folder, *args, **kwargs):
        real(folder, *args, **kwargs)
        raise KeyboardInterrupt  # after every file is written, before the folder is renamed

    monkeypatch.setattr(tb, "write_testbench", interrupted)
    fresh = tmp_path / "fresh"
    assert main([*argv[:2], str(fresh), *argv[3:]]) == 130
    assert not fresh.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(TEMP_PREFIX)]
    assert "interrupted" in capsys.readouterr().err


def test_a_failed_plot_leaves_no_file(tmp_path, monkeypatch):
    import matplotlib.figure

    def broken(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", broken)
    plot = tmp_path / "c.png"
    with pytest.raises(OSError, match="disk full"):
        main(["compare", "--samples", "300", "--seed", "1", "--plot", str(plot)])
    assert list(tmp_path.iterdir()) == []


# -- simulate --input ----------------------------------------------------------------------------


@pytest.mark.cosim
def test_simulate_input_prints_no_seed_and_measures_the_truth(tmp_path, capsys):
    need("verilator")
    rng = np.random.default_rng(11)
    truth = 3000 * np.sin(np.arange(400) / 300)
    codes = np.round(truth + rng.normal(0, 30, 400)).astype(int)
    path = tmp_path / "rec.csv"
    path.write_text("# a recording\ny;truth\n" + "".join(f"{c};{t}\n" for c, t in zip(codes, truth, strict=True)))
    assert main(["simulate", "--input", str(path), "--architecture", "parallel", "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "seed" not in out + err and f"input {path}" in out
    assert "RMSE vs truth" in out
    assert main(["simulate", "--input", str(path), "--architecture", "parallel", "--quiet", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["seed"] is None
    raw = float(np.sqrt(np.mean((codes[40:] - truth[40:]) ** 2)))  # past each channel's first tenth
    assert report["rmse_raw"] == pytest.approx(raw, rel=1e-9)
    assert report["rmse_hw"] < report["rmse_raw"]
