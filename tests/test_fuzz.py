"""Generated inputs (Hypothesis) for the CSV reader, the config loader and the command line: no
input gives a traceback; every refusal is the user-error kind (one line, exit 2) and leaves no
file behind.

Hypothesis draws its examples from a seed of its own, printed with a failing example (and kept
in its database, which this suite turns off so every run is alike: ``derandomize``). The
example counts keep the whole file under half a minute on 2 cores."""

import os
import string

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from kfpga.cli import main
from kfpga.core.config import FilterConfig
from kfpga.core.csvio import read_samples, read_series
from kfpga.core.errors import USER_ERRORS, InputError

FUZZ = settings(derandomize=True, database=None, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# -- the CSV reader --------------------------------------------------------------------------------

CELL = st.one_of(
    st.integers(-40000, 40000).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", " ", "y", "truth", "x", "1e3", "-0", "0x10", "nan", "1,5", '"3"', "#", "\ufeff"]),
    st.text(alphabet=string.printable, max_size=6),
)
ROW = st.lists(CELL, min_size=0, max_size=4)
SEPARATOR = st.sampled_from([",", ";", "\t", " , "])
NEWLINE = st.sampled_from(["\n", "\r\n", "\r"])


@st.composite
def csv_text(draw):
    sep, nl = draw(SEPARATOR), draw(NEWLINE)
    header = draw(st.one_of(st.just(["y"]), st.just(["y", "truth"]), ROW))
    rows = draw(st.lists(ROW, max_size=8))
    lines = [sep.join(header)] + [sep.join(r) for r in rows]
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), "# " + draw(st.text(max_size=8)))
    text = nl.join(lines) + draw(st.sampled_from(["", nl, nl * 3]))
    prefix = draw(st.sampled_from(["", "\ufeff"]))
    return (prefix + text).encode("utf-8", errors="surrogatepass") if draw(st.booleans()) else \
        draw(st.binary(max_size=40))


@settings(FUZZ, max_examples=300)
@given(data=csv_text())
@example(data=b'y\n"\n0')  # a quote left open once swallowed the rows after it
def test_the_csv_reader_accepts_or_names_the_problem(tmp_path, data):
    path = tmp_path / "in.csv"
    try:
        path.write_bytes(data)
    except UnicodeEncodeError:
        return
    for read in (read_samples, lambda p: read_samples(p, columns=["y"]), read_series):
        try:
            result = read(path)
        except InputError as exc:
            assert str(exc).startswith(str(path)) and "\n" not in str(exc)
        else:
            assert len(result) >= 1


# -- the config loader -----------------------------------------------------------------------------

SCALAR = st.one_of(
    st.integers(-10**20, 10**20),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, 1e-300, 1e300, -1.0, 1e-16, 4.0, 0.01, 2.0]),
    st.booleans(),
    st.text(max_size=8),
    st.sampled_from(["kalman2", "kalman", "alphabeta", "53h", "roll", "lsfront", "Q18.8", "state", "measurement"]),
)
VALUE = st.recursive(SCALAR, lambda inner: st.lists(inner, max_size=3), max_leaves=9)
MODEL_KEYS = st.sampled_from(["T", "Q", "R", "P0", "x0", "init", "F", "G", "H", "alpha", "beta", "gain", "adc",
                              "observations", "threshold", "order", "nope"])
FORMAT = st.one_of(st.sampled_from(["Q18.8", "Q2.16", "Q0.0", "Q99.99", "18.8"]),
                   st.dictionaries(st.sampled_from(["format", "int_bits", "frac_bits", "rounding", "overflow", "x"]),
                                   SCALAR, max_size=3))


NUMBER = st.one_of(st.sampled_from([0.0, 1e-300, 1e300, -1.0, 1e-16, 4.0, 0.01, 2.0, 0.5, 10.0, 1e14]),
                   st.floats(-1e6, 1e6), st.integers(-5, 5))
MATRIX = st.integers(1, 3).flatmap(lambda n: st.lists(st.lists(NUMBER, min_size=n, max_size=n), min_size=n, max_size=n))
NUMERIC = st.one_of(NUMBER, st.lists(NUMBER, min_size=1, max_size=3), MATRIX)
NAMES = st.sampled_from(["kalman2", "kalman", "alphabeta", "53h", "roll", "lsfront"])


@st.composite
def config_tables(draw):
    """Mostly tables a person might write (a known filter, its keys, numbers of every size),
    some of them junk."""
    junk = draw(st.integers(0, 9)) == 0
    data = {}
    if draw(st.booleans()):
        data["filter"] = draw(VALUE) if junk else {"name": draw(NAMES)}
    if draw(st.integers(0, 3)):
        data["model"] = draw(VALUE) if junk else draw(st.dictionaries(MODEL_KEYS, st.one_of(NUMERIC, VALUE)
                                                                      if draw(st.booleans()) else NUMERIC,
                                                                      max_size=4))
    if draw(st.integers(0, 3)) == 0:
        data["formats"] = draw(st.dictionaries(st.sampled_from(["x1", "x2", "k1", "pl", "f", "zz"]), FORMAT,
                                               max_size=3))
    if draw(st.integers(0, 3)) == 0:
        data["board"] = draw(st.dictionaries(st.sampled_from(["sample_rate_hz", "clock_hz", "x"]), SCALAR, max_size=2))
    if junk and draw(st.booleans()):
        data[draw(st.text(max_size=5))] = draw(VALUE)
    return data


@settings(FUZZ, max_examples=300)
@given(data=config_tables())
def test_the_config_loader_accepts_or_names_the_problem(data):
    try:
        config = FilterConfig.from_dict(data)
        config.require_variant(config.spec.default_variant)
    except USER_ERRORS as exc:
        assert str(exc) and "\n" not in str(exc)


@settings(FUZZ, max_examples=150)
@given(text=st.text(alphabet=string.printable + "\ufeff", max_size=80))
def test_a_config_file_of_any_text_is_read_or_refused(tmp_path, text):
    path = tmp_path / "k.toml"
    path.write_text(text)
    try:
        FilterConfig.from_toml(path)
    except USER_ERRORS as exc:
        assert "\n" not in str(exc)


# -- the command line ------------------------------------------------------------------------------

GOOD_CSV = "y,truth\n" + "".join(f"{v},{v}.0\n" for v in range(0, 200, 10))
WORDS = ["--samples", "--seed", "--variant", "--filter", "--config", "--input", "--output", "--out-field",
         "--json", "--clip", "--settle", "--scenario", "--float", "--channels", "--channel", "--write", "--plot",
         "--pins", "--preset", "-h"]
VALUES = ["200", "0", "-1", "1e3", "abc", "", "steady", "full", "kalman2", "53h", "alphabeta", "in.csv", "k.toml",
          "out.csv", "x1", "6", "A0", "Z9", "sine", "p.png", "nofile.csv", "build", "1000000000000"]
COMMANDS = ["formats", "filters", "pins", "filter", "compare"]


@st.composite
def command_lines(draw):
    command = draw(st.sampled_from(COMMANDS))
    argv = [command]
    for _ in range(draw(st.integers(0, 5))):
        argv.append(draw(st.sampled_from(WORDS)))
        if draw(st.integers(0, 3)):
            argv.append(draw(st.sampled_from(VALUES)))
    if command == "compare" and "--samples" not in argv:  # keep each run short
        argv += ["--samples", "200"]
    if command == "filter" and draw(st.booleans()):
        argv += ["--input", "in.csv", "--output", "out.csv"]
    return argv


def _files(folder):
    return {os.path.relpath(os.path.join(d, f), folder) for d, _, fs in os.walk(folder) for f in fs} | \
        {os.path.relpath(os.path.join(d, s), folder) for d, subs, _ in os.walk(folder) for s in subs}


@settings(FUZZ, max_examples=60)
@given(argv=command_lines())
def test_the_command_line_answers_or_refuses_in_one_line(tmp_path_factory, argv, capsys):
    folder = tmp_path_factory.mktemp("cli")
    (folder / "in.csv").write_text(GOOD_CSV)
    (folder / "k.toml").write_text("[model]\nQ = 2.0\n")
    before = _files(folder)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: --help, or its own refusal
            code = exc.code
    finally:
        os.chdir(cwd)
    _, err = capsys.readouterr()
    assert "Traceback" not in err
    assert code in (0, 1, 2), (argv, code, err)
    if code == 2:
        lines = err.strip().splitlines()
        assert lines and (len(lines) == 1 or "usage:" in err), (argv, err)
        assert _files(folder) == before, (argv, "a refusal must leave no file")


@pytest.mark.parametrize("argv", [["compare", "--samples", "200", "--plot", "p.png", "--seed", "1"]])
def test_the_command_line_fuzz_sees_an_output(tmp_path, argv, monkeypatch):
    """The fuzz's file check would see a file a refusal left: a good run writes one."""
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 0 and (tmp_path / "p.png").is_file()
