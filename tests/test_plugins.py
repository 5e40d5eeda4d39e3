"""A filter is a plugin: what a filter owns lives in its own files, and a filter registered from
outside the package gets every generic command, ``kfpga evaluate`` and the contract suite.

* No package file outside a filter's own (``model/NAME.py``, ``hw/NAME.py``, ``model/evaluations/NAME.py``,
  any ``NAME_*.py``) and the registry names the filter or imports its modules: identifiers,
  imports and strings (docstrings and comments may mention it).
* Its tests are ``tests/test_model_NAME.py`` and ``tests/test_hw_NAME.py``.
* A toy filter (a one-state exponential smoother, ``tests/fixtures/toy_distribution``), installed
  through an entry point alone, runs through the commands and the contract checks with no package
  file edited.
"""

import ast
import json
import re
from pathlib import Path

import pytest

from kfpga.cli import main
from kfpga.core import registry
from tests.helpers.files import python_files

ROOT = Path(__file__).resolve().parent.parent
#: The package's files, each once (kfpga/model, hw and sim link to the top-level folders).
PACKAGE_FILES = python_files("kfpga", "model", "hw", "sim")


#: A word of a string: letters, digits and underscores, hyphens inside (``alpha-beta``, ``53h``).
WORD = re.compile(r"[A-Za-z0-9_]+(?:-[A-Za-z0-9_]+)*")


def _docstrings(tree):
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
                out.add(id(first.value))
    return out


def code_words(tree):
    """``(line, words)`` of every import, identifier, definition, argument and string (not a
    docstring) of a module; a dotted or ``module:attribute`` string gives its parts too."""
    skip = _docstrings(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, [*a.name.split("."), *([a.asname] if a.asname else [])]
        elif isinstance(node, ast.ImportFrom):
            yield node.lineno, [*(node.module or "").split("."), *(a.name for a in node.names)]
        elif isinstance(node, ast.Name):
            yield node.lineno, [node.id]
        elif isinstance(node, ast.FunctionDef | ast.ClassDef):
            yield node.lineno, [node.name]
        elif isinstance(node, ast.arg):
            yield node.lineno, [node.arg]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
            # every word of a string too: a help text, an example, a script kept in a string
            yield node.lineno, [node.value, *node.value.replace(":", ".").split("."), *WORD.findall(node.value)]


def own_file(path, name):
    return path.stem == name or path.stem.startswith(f"{name}_")


@pytest.mark.parametrize("name", registry.names())
def test_a_filter_is_named_only_in_its_own_files_and_the_registry(name):
    spec = registry.get(name)
    names = {spec.name, *spec.docs.aliases}
    found = []
    for path in PACKAGE_FILES:
        if own_file(path, name) or path == ROOT / "kfpga" / "core" / "registry.py":
            continue
        for line, words in code_words(ast.parse(path.read_text())):
            if names & set(words):
                found.append(f"{path.relative_to(ROOT)}:{line}")
    assert found == [], f"the {name} filter is named outside its own files: {found}"


@pytest.mark.parametrize("name", registry.names())
def test_a_filters_tests_are_named_by_layer(name):
    """``tests/test_model_NAME.py`` for its model and ``tests/test_hw_NAME.py`` for its cores, the
    stem of ``model/NAME.py``; no other test file is named after the filter alone."""
    tests = ROOT / "tests"
    assert (tests / f"test_model_{name}.py").is_file() and (tests / f"test_hw_{name}.py").is_file()
    assert (ROOT / "model" / f"{name}.py").is_file()
    assert not (tests / f"test_{name}.py").exists()


def test_the_check_finds_a_name():
    tree = ast.parse('"""kalman2 in a docstring is fine."""\nfrom kfpga.model import kalman2\nx = "tukey53h"\n'
                     'EXAMPLE = "kfpga evaluate alpha-beta --seeds 5 (53h, roll)"\n'
                     'SCRIPT = """\nfrom kfpga.hw.alphabeta import TrackerCore\nFilterConfig(filter=\'kalman\')\n"""\n')
    words = {w for _, ws in code_words(tree) for w in ws}
    assert {"kalman2", "tukey53h", "alpha-beta", "53h", "roll", "alphabeta", "kalman"} <= words
    assert "kalman2 in a docstring is fine." not in words and "docstring" not in words


# -- a toy filter, installed through an entry point --------------------------------------------


TOY_DISTRIBUTION = Path(__file__).parent / "fixtures" / "toy_distribution"


@pytest.fixture
def toy(tmp_path_factory):
    """The toy filter, installed as a user's distribution would be: its module and a
    ``.dist-info`` whose ``entry_points.txt`` names it in the ``kfpga.filters`` group, on ``sys.path``."""
    import shutil
    import sys

    site = tmp_path_factory.mktemp("site")
    shutil.copy(TOY_DISTRIBUTION / "kfpga_toy.py", site / "kfpga_toy.py")
    info = site / "kfpga_toy-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: kfpga-toy\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[{registry.GROUP}]\ntoy = kfpga_toy:SPEC\n")
    sys.path.insert(0, str(site))
    registry.reload()
    try:
        assert "toy" in registry.names()
        yield registry.get("toy")
    finally:
        sys.path.remove(str(site))
        sys.modules.pop("kfpga_toy", None)
        registry.reload()
        assert "toy" not in registry.names()


def test_a_toy_filter_gets_the_generic_commands(toy, tmp_path, capsys, seed):
    assert main(["filters", "--json"]) == 0
    assert "toy" in [r["name"] for r in json.loads(capsys.readouterr().out)]
    assert main(["compare", "--filter", "toy", "--samples", "3000", "--seed", str(seed), "--json"]) == 0
    m = json.loads(capsys.readouterr().out)
    assert m["overflows"] == 0 and abs(m["rmse_fixed_over_float"] - 1) < 0.01
    assert main(["formats", "--filter", "toy", "--json"]) == 0
    assert [r["point"] for r in json.loads(capsys.readouterr().out)] == ["x", "e", "a"]
    src, out = tmp_path / "in.csv", tmp_path / "out.csv"
    src.write_text("y\n" + "\n".join(str(v) for v in range(0, 400, 7)) + "\n")
    assert main(["filter", "--filter", "toy", "--input", str(src), "--output", str(out)]) == 0
    assert out.read_text().splitlines()[0].split(",")[:1] == ["x"]
    assert main(["generate", "--filter", "toy", "--out", str(tmp_path / "gen"), "--quiet"]) == 0
    assert (tmp_path / "gen" / "kfpga_top.v").exists()
    capsys.readouterr()
    assert main(["evaluate", "toy", "--seed", str(seed), "--seeds", "3", "--json"]) == 0
    claims = json.loads(capsys.readouterr().out)["claims"]
    assert claims[0]["verdict"] == "reproduced" and claims[0]["runs"] == 3


@pytest.mark.slow  # co-simulates the toy filter's core
def test_a_toy_filter_passes_the_contract(toy, tmp_path, seed):
    from tests.contract import test_contract as contract

    assert toy.architectures("steady", toy.params()) == ("folded",)
    contract.test_model_equals_the_exact_rational_spec("toy", "steady", seed)
    for channels in (1, 3):
        contract.test_rtl_equals_model_with_backpressure("toy", "steady", "folded", channels, seed)
    contract.test_declared_latency_and_cycles_per_update_are_measured("toy", "steady", "folded")
    contract.test_generated_verilog_parses_and_lints("toy", "steady", "folded", tmp_path)
