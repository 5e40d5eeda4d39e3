"""Every user error is one clear line: exit code 2, no traceback, nothing written or changed.

One table of bad invocations across every command. Each row gives the arguments, the files the
folder holds before the call, and the line stderr must end with. The test runs each in a fresh
folder and checks the exit code, that stderr is one line (argparse's usage block aside) naming
the problem, and that no file was created or changed.
"""

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from kfpga.cli import main
from tests.helpers.expected import REGISTERED

GOOD_CSV = "y,truth\n" + "".join(f"{v},{v}.0\n" for v in (0, 10, 20, 30, 40, 50))
LATIN1 = "y\n\xe9\n".encode("latin-1")
BOM_CSV = b"\xef\xbb\xbfy\n1\n2\n3\n"

# (id, argv, files {name: text or bytes}, the end of the error line)
CASES = [
    ("compare-one-sample", ["compare", "--samples", "1", "--seed", "1"], {}, "compare needs at least 2 samples, not 1"),
    ("compare-config-dir", ["compare", "--config", "cfgdir"], {"cfgdir/x": ""}, "cfgdir: is a directory, not a config file"),
    ("compare-config-latin1", ["compare", "--config", "k.toml"], {"k.toml": b"[model]\n# \xe9\n"},
     "k.toml: line 2: byte 0xe9 is not UTF-8; save the config file as UTF-8"),
    ("compare-config-missing", ["compare", "--config", "nope.toml"], {}, "nope.toml: no such config file"),
    ("toml-model-5", ["compare", "--config", "k.toml"], {"k.toml": "model = 5\n"},
     "k.toml: model must be a table ([model]), not 5"),
    ("toml-formats-5", ["compare", "--config", "k.toml"], {"k.toml": "formats = 5\n"},
     "k.toml: formats must be a table ([formats]), not 5"),
    ("toml-filter-name", ["compare", "--config", "k.toml"], {"k.toml": '[filter]\nname = "nope"\n'},
     "k.toml: filter.name: no filter named 'nope'; registered: " + REGISTERED),
    ("toml-bad-format", ["formats", "--config", "k.toml"], {"k.toml": '[formats.x1]\nformat = "18.8"\n'},
     "formats.x1: format must look like 'Q18.8' (integer bits incl. sign . fraction bits), not '18.8'"),
    ("toml-format-and-bits", ["formats", "--config", "k.toml"],
     {"k.toml": '[formats.x1]\nformat = "Q18.8"\nint_bits = 18\n'},
     "formats.x1: give either format or int_bits and frac_bits, not both"),
    ("toml-syntax", ["formats", "--config", "k.toml"], {"k.toml": "[model\n"}, None),
    ("filter-output-dir", ["filter", "--input", "in.csv", "--output", "outdir"], {"in.csv": GOOD_CSV, "outdir/x": ""},
     "--output outdir: is a directory; give a file name"),
    ("filter-output-no-parent", ["filter", "--input", "in.csv", "--output", "no/such/out.csv"], {"in.csv": GOOD_CSV},
     "--output no/such/out.csv: the folder no/such does not exist"),
    ("filter-output-is-input", ["filter", "--input", "in.csv", "--output", "in.csv"], {"in.csv": GOOD_CSV},
     "--output in.csv: is also an input; write to another file"),
    ("filter-output-ext", ["filter", "--input", "in.csv", "--output", "out.png"], {"in.csv": GOOD_CSV},
     "--output out.png: the extension must be .csv or .txt, not '.png'"),
    ("filter-input-latin1", ["filter", "--input", "in.csv", "--output", "o.csv"], {"in.csv": LATIN1},
     "in.csv: line 2: byte 0xe9 is not UTF-8; save the file as UTF-8"),
    ("filter-input-dir", ["filter", "--input", "d", "--output", "o.csv"], {"d/x": ""}, "d: is a directory, not a file"),
    # a blank line is a sample with no measurement for a filter that can coast, else refused
    ("filter-blank-line", ["filter", "--filter", "tukey53h", "--input", "in.csv", "--output", "o.csv"],
     {"in.csv": "y\n1\n\n2\n"},
     "in.csv: line 3: a blank line; every row is a sample (delete the line, or give it a value) (the tukey53h "
     "filter's online variant takes every sample as a measurement: it cannot coast over an empty one)"),
    ("filter-duplicate-column", ["filter", "--input", "in.csv", "--output", "o.csv"], {"in.csv": "y,y\n1,2\n"},
     "in.csv: line 1: the header names column 'y' twice"),
    ("filter-bad-value", ["filter", "--input", "in.csv", "--output", "o.csv"], {"in.csv": "y\n1\nabc\n"},
     "in.csv: line 3: y = 'abc' is not a number"),
    ("filter-variant", ["filter", "--input", "in.csv", "--output", "o.csv", "--variant", "fast"], {"in.csv": GOOD_CSV},
     "variant must be one of steady, full for the kalman2 filter, not 'fast'"),
    ("plot-ext", ["compare", "--samples", "300", "--seed", "1", "--plot", "x.xyz"], {},
     "--plot x.xyz: the extension must be .png or .svg or .pdf, not '.xyz'"),
    ("plot-no-ext", ["compare", "--samples", "300", "--seed", "1", "--plot", "plots/noext"], {"plots/keep": ""},
     "--plot plots/noext: the extension must be .png or .svg or .pdf, not 'none'"),
    ("plot-dir", ["compare", "--samples", "300", "--seed", "1", "--plot", "out.png"], {"out.png/x": ""},
     "--plot out.png: is a directory; give a file name"),
    ("sweep-plot-no-parent", ["sweep", "--samples", "300", "--seed", "1", "--plot", "a/b.png", "--quiet"], {},
     "--plot a/b.png: the folder a does not exist"),
    ("samples-more-than-rows", ["compare", "--input", "in.csv", "--samples", "5000"], {"in.csv": GOOD_CSV},
     "--samples 5000 is more than the 6 rows of in.csv"),
    ("seed-with-input", ["compare", "--input", "in.csv", "--seed", "3"], {"in.csv": GOOD_CSV},
     "--seed does not apply with --input: the samples come from the file, no noise is drawn"),
    ("scenario-with-input", ["compare", "--input", "in.csv", "--scenario", "sine"], {"in.csv": GOOD_CSV},
     "--scenario does not apply with --input: the samples come from the file"),
    ("clip-without-input", ["compare", "--clip", "--samples", "300"], {},
     "--clip does not apply with a scenario: scenarios stay within the 16-bit range; --clip is for --input files"),
    ("settle-too-big", ["compare", "--samples", "300", "--seed", "1", "--settle", "300"], {},
     "--settle must be between 0 and 299, not 300"),
    ("sweep-pinned-formats", ["sweep", "--config", "k.toml", "--samples", "300", "--quiet"],
     {"k.toml": '[formats.x1]\nformat = "Q18.9"\n'},
     "sweep sets every format itself, so the formats k.toml pins would be ignored (x1): remove its [formats] tables, "
     "or use compare"),
    ("sweep-no-truth", ["sweep", "--input", "in.csv", "--quiet"], {"in.csv": "y\n1\n2\n3\n"},
     "sweep needs a truth to measure RMSE: use a scenario or an --input with a 'truth' column"),
    ("generate-out-under-file", ["generate", "--out", "f/sub"], {"f": "a file"}, "--out f/sub: f is a file, not a folder"),
    ("generate-channel-six", ["generate", "--out", "o", "--channels", "6", "--channel", "B1"], {},
     "--channel does not apply with --channels 6: all six channels are sampled and filtered"),
    ("generate-out-field", ["generate", "--out", "o", "--out-field", "x9"], {},
     "--out-field: out_field must be one of x1, x2, yhat for the kalman2 filter, not 'x9'"),
    ("generate-ratio", ["generate", "--out", "o", "--ratio", "1"], {}, "--ratio must be >= 2, not 1"),
    ("generate-ratio-fast-adc", ["generate", "--out", "o", "--ratio", "8", "--no-lint"], {},
     "--ratio 8 makes the ADC clock 6.25 MHz; the ADS8364 allows 5 MHz at most (tC1 = 200 ns)"),
    ("pins-999", ["generate", "--out", "o", "--pins", "p.csv", "--no-lint"],
     {"p.csv": "port,bit,pin,io_standard\nclk50,,PIN_999,3.3-V LVTTL\n"},
     "p.csv: line 2: PIN_999 does not exist: the EP2C20Q240 has pins PIN_1..PIN_240"),
    ("pins-missing-bit", ["generate", "--out", "o", "--pins", "p.csv", "--no-lint"],
     {"p.csv": "port,bit,pin,io_standard\nclk50,,PIN_34,3.3-V LVTTL\n"}, None),
    ("pins-wide-x1", ["generate", "--out", "o", "--config", "k.toml", "--no-lint"],
     {"k.toml": '[formats.x1]\nformat = "Q30.10"\n[formats.xl1]\nformat = "Q30.10"\n'}, None),
    ("va2-full-generate", ["generate", "--preset", "va2", "--variant", "full", "--architecture", "parallel",
                           "--out", "o"], {},
     "--architecture parallel: the parallel time-varying core takes one observation, not 2: the folded core "
     "runs this model"),
    ("va2-full-simulate", ["simulate", "--preset", "va2", "--variant", "full", "--architecture", "parallel"], {},
     "--architecture parallel: the parallel time-varying core takes one observation, not 2: the folded core "
     "runs this model"),
    ("pins-write-dir", ["pins", "--write", "d"], {"d/x": ""}, "--write d: is a directory; give a file name"),
    ("formats-toml-and-json", ["formats", "--toml", "--json"], {}, "--toml and --json are two ways to print the same: choose one"),
    ("formats-pin-without-toml", ["formats", "--pin-formats"], {},
     "--pin-formats does not apply with the table: it says how --toml writes the formats"),
    ("filter-name", ["formats", "--filter", "nope"], {},
     "--filter: no filter named 'nope'; registered: " + REGISTERED),
    ("config-unknown-key", ["compare", "--config", "k.toml"], {"k.toml": "[model]\nP1 = 3\n"},
     "k.toml: unknown key model.P1; the kalman2 filter has: T, Q, R, P0, x0, init"),
    ("simulate-channel-six", ["simulate", "--channels", "6", "--channel", "A1"], {},
     "--channel does not apply with --channels 6: all six channels are sampled and filtered"),
    ("simulate-samples-vs-input", ["simulate", "--input", "in.csv", "--samples", "50"], {"in.csv": GOOD_CSV},
     "--samples 50 is more than the 6 estimates the 6 rows of in.csv give"),
    ("simulate-seed-with-input", ["simulate", "--input", "in.csv", "--seed", "1"], {"in.csv": GOOD_CSV},
     "--seed does not apply with --input: the ADC replays the file, no noise is drawn"),
    ("resources-variant", ["resources", "--variant", "slow"], {},
     "variant must be one of steady, full for the kalman2 filter, not 'slow'"),
    ("model-q0-steady", ["compare", "--config", "k.toml", "--samples", "300"], {"k.toml": "[model]\nQ = 0.0\n"},
     "model.Q = 0.0: the steady-state variant needs Q > 0 (Q = 0 gives K_inf = 0)"),
    ("argparse-samples", ["compare", "--samples", "-3"], {}, "argument --samples: must be a positive integer, not '-3'"),
    ("argparse-choice", ["simulate", "--simulator", "modelsim"], {}, None),
    ("sweep-budget-zero", ["sweep", "--budget", "0%"], {}, "argument --budget: must be more than 0 % and at most 100 %, not '0%'"),
    ("sweep-budget-text", ["sweep", "--budget", "one"], {}, "argument --budget: must be a percentage like 1% or 0.5%, not 'one'"),
    ("argparse-unknown", ["filters", "--verbose"], {}, "kfpga filters: error: unrecognized arguments: --verbose"),
    # outputs that cannot be written, checked before the work starts
    ("generate-out-proc", ["generate", "--out", "/proc/x/gen"], {}, None),
    ("generate-out-file", ["generate", "--out", "f.txt"], {"f.txt": "x"}, "--out f.txt: is a file; give a folder"),
    ("generate-out-foreign", ["generate", "--out", "d"], {"d/mine.txt": "x"},
     "--out d: the folder holds files this command did not write (no manifest.json); give a new or empty folder"),
    ("testbench-out-proc", ["testbench", "--out", "/proc/x/tb"], {}, None),
    ("testbench-out-under-file", ["testbench", "--out", "f.txt/tb"], {"f.txt": "x"},
     "--out f.txt/tb: f.txt is a file, not a folder"),
    ("compare-plot-proc", ["compare", "--plot", "/proc/x.png", "--samples", "100", "--seed", "1"], {}, None),
    ("propose-out-proc", ["propose", "--out", "/proc/x.toml", "--samples", "100"], {}, None),
    ("filter-output-dir", ["filter", "--input", "in.csv", "--output", "d"], {"in.csv": GOOD_CSV, "d/x": ""},
     "--output d: is a directory; give a file name"),
    # sample counts beyond what the machine holds, refused before anything is allocated
    ("compare-huge", ["compare", "--samples", "1000000000000", "--seed", "1"], {}, None),
    ("simulate-huge", ["simulate", "--samples", "1000000000000", "--seed", "1"], {}, None),
    ("testbench-huge", ["testbench", "--samples", "1000000000000", "--seed", "1", "--out", "tb"], {}, None),
    ("propose-huge", ["propose", "--samples", "10000000", "--seeds", "1000", "--seed", "1"], {}, None),
    # numbers no format holds
    ("model-q-huge", ["compare", "--config", "k.toml"], {"k.toml": "[model]\nQ = 1e300\n"},
     "model.Q = 1e+300 is outside the usable range: 0, or 1e-15 to 1e+15 in magnitude"),
    ("model-r-tiny", ["compare", "--config", "k.toml"], {"k.toml": "[model]\nR = 1e-300\n"},
     "model.R = 1e-300 is outside the usable range: 0, or 1e-15 to 1e+15 in magnitude"),
    ("model-p0-huge", ["compare", "--config", "k.toml"], {"k.toml": "[model]\nP0 = [[1e300, 0.0], [0.0, 1.0]]\n"},
     "model.P0[0][0] = 1e+300 is outside the usable range: 0, or 1e-15 to 1e+15 in magnitude"),
    ("model-x0-far", ["compare", "--config", "k.toml"], {"k.toml": "[model]\nx0 = [1e9, 0.0]\n"},
     "model.x0[0] = 1e+09 is far beyond the ADC's range of the state an observation measures (+-32768 codes): "
     "at most +-131072"),
    ("model-r-out-of-reach", ["compare", "--config", "k.toml"], {"k.toml": "[model]\nR = 1e14\n"}, None),
    # CSV files: what is still refused, with its line
    ("csv-half-empty", ["filter", "--config", "k.toml", "--input", "i.csv", "--output", "o.csv"],
     {"k.toml": "[filter]\nname = \"kalman\"\n[model]\nF = [[1.0, 1.0], [0.0, 1.0]]\nG = [[0.5], [1.0]]\n"
                "Q = [[1.0]]\nH = [[1.0, 0.0], [0.0, 1.0]]\nR = [[4.0, 0.0], [0.0, 4.0]]\n",
      "i.csv": "y1,y2\n1,2\n,3\n"},
     "i.csv: line 3: y2 given but y1 empty: a sample with no measurement leaves every input cell empty"),
    ("csv-headerless-two", ["filter", "--input", "i.csv", "--output", "o.csv"], {"i.csv": "1,2\n3,4\n"},
     "i.csv: line 1: no header line; name the 2 columns in a first line (for example y,truth)"),
    ("csv-semicolon-missing", ["filter", "--input", "i.csv", "--output", "o.csv"], {"i.csv": "y;truth\n1;2\n3\n"},
     "i.csv: line 3: no value in column 'truth'"),
    ("csv-comment-then-text", ["filter", "--input", "i.csv", "--output", "o.csv"], {"i.csv": "# log\ny\n1\nabc\n"},
     "i.csv: line 4: y = 'abc' is not a number"),
]

# cases whose error line is only checked for its subject (the exact text is tested elsewhere)
SUBJECTS = {
    "toml-syntax": "k.toml: not valid TOML: ",
    "pins-missing-bit": "p.csv: no pin for rst_n, adc_clk",
    "pins-wide-x1": "no pin for out_data[36], out_data[37], out_data[38], out_data[39]",
    "argparse-choice": "argument --simulator: invalid choice: 'modelsim'",
    "generate-out-proc": "--out /proc/x/gen: cannot write into /proc (",
    "testbench-out-proc": "--out /proc/x/tb: cannot write into /proc (",
    "compare-plot-proc": "--plot /proc/x.png: cannot write into /proc (",
    "propose-out-proc": "--out /proc/x.toml: cannot write into /proc (",
    "compare-huge": "--samples 1000000000000 needs about ",
    "simulate-huge": "--samples 1000000000000 needs about ",
    "testbench-huge": "--samples 1000000000000 needs about ",
    "propose-huge": "--samples 10000000 needs about ",
    # no width is refused: the formats take R = 1e14, and its noise drives the ADC to its rails
    "model-r-out-of-reach": "scenario sine drives the ADC to its rails",
}


def snapshot(folder):
    """Every file (its hash) and folder (``None``) under ``folder``."""
    return {p.relative_to(folder): hashlib.sha1(p.read_bytes()).hexdigest() if p.is_file() else None
            for p in folder.rglob("*")}


@pytest.mark.parametrize(("argv", "files", "message"), [pytest.param(a, f, m, id=i) for i, a, f, m in CASES])
def test_bad_invocation_is_one_line_and_changes_nothing(argv, files, message, tmp_path, monkeypatch, capsys, request):
    for name, content in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    monkeypatch.chdir(tmp_path)
    before = snapshot(tmp_path)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    last = lines[-1]
    if "usage:" not in err:
        assert len(lines) == 1, err  # one line, unless argparse puts its usage block above it
    expected = message if message is not None else SUBJECTS[request.node.callspec.id]
    if message is not None:
        assert last.endswith(expected), last
    else:
        assert expected in last, last
    assert snapshot(tmp_path) == before, "a failed command must not create or change files"


def test_table_covers_every_command():
    commands = {argv[0] for _, argv, _, _ in CASES}
    assert commands >= {"compare", "sweep", "filter", "filters", "formats", "generate", "pins", "resources", "simulate"}
    assert len(CASES) >= 40


def test_broken_pipe_is_quiet(tmp_path):
    """`kfpga formats --json | head -1`: the reader stops early; no traceback."""
    code = ("import sys; from kfpga.cli import main; sys.exit(main(['formats', '--json']))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.readline()
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert "Traceback" not in err and "BrokenPipe" not in err, err


def test_argparse_errors_end_with_the_one_line_error():
    result = subprocess.run([sys.executable, "-m", "kfpga.cli", "compare", "--bogus"], capture_output=True, text=True)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith("usage: kfpga compare") and lines[-1] == "kfpga compare: error: unrecognized arguments: --bogus"


@pytest.mark.slow
def test_the_tool_runs_from_an_unactivated_venv(tmp_path):
    """No venv on PATH (a user runs .venv/bin/kfpga): Yosys still comes from the interpreter's package.
    The fresh HOME keeps the machine's YoWASP cache (compiling Yosys' WebAssembly again takes
    about 40 s and tests nothing of ours)."""
    import platformdirs

    from kfpga.hw.tools import yosys_command

    cache = os.environ.get("YOWASP_CACHE_DIR", platformdirs.user_cache_dir("YoWASP", appauthor=False))
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "YOWASP_CACHE_DIR": cache}
    result = subprocess.run(yosys_command("-q", "-p", "help"), capture_output=True, text=True, env=env, cwd=tmp_path,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    exe = Path(sys.executable).parent / "kfpga"
    if exe.exists():
        result = subprocess.run([str(exe), "filters"], capture_output=True, text=True, env=env, timeout=120)
        assert result.returncode == 0 and "kalman2" in result.stdout, result.stderr
