"""The code passes the curated ruff rules of pyproject.toml (no per-line exemptions, C901 at 12 and
PLR0915 included), the import-linter contracts, and no function is longer than a screen."""

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_ruff_clean():
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    result = subprocess.run([ruff, "check", str(ROOT)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_no_per_line_lint_exemptions():
    needle = "no" + "qa"  # spelled in two parts so that this file does not match itself
    offenders = [str(p.relative_to(ROOT)) for folder in ("kfpga", "model", "hw", "sim", "tests", "bench")
                 for p in (ROOT / folder).rglob("*.py") if needle in p.read_text()]
    assert offenders == [], offenders


def test_layers_import_only_downward():
    """The import-linter contracts of pyproject.toml: each layer imports only the layers below it."""
    lint = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    result = subprocess.run([lint, "--no-cache"], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stdout + result.stderr


def long_functions(paths, root=ROOT):
    """``[(file:line name, lines)]`` of the functions over 80 lines (an Amaranth ``elaborate`` over 120)."""
    import ast

    out = []
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = node.end_lineno - node.lineno + 1
                if length > (120 if node.name == "elaborate" else 80):
                    out.append((f"{path.relative_to(root)}:{node.lineno} {node.name}", length))
    return out


def test_functions_fit_on_a_screen():
    package = [p for folder in ("kfpga", "model", "hw", "sim") for p in sorted((ROOT / folder).rglob("*.py"))]
    assert long_functions(package) == []


def test_a_long_function_is_found(tmp_path):
    body = "\n".join(f"    x{k} = {k}" for k in range(85))
    (tmp_path / "a.py").write_text(f"def short():\n    return 1\n\n\ndef long():\n{body}\n")
    assert long_functions([tmp_path / "a.py"], root=tmp_path) == [("a.py:5 long", 86)]


def test_the_source_documents_are_cited_by_their_references():
    """The code and the manual cite a source document by its key in docs/references.md ([Zhong],
    [Zhang], [Lu], [Fukuda], [Chen]), never by a file of a folder that is not in the repository."""
    import re

    pattern = re.compile("seeds" + r"/\d{3}")  # in two parts so that this file does not match itself
    paths = [p for folder in ("kfpga", "model", "hw", "sim", "tests", "bench", "docs", "examples")
             for p in sorted((ROOT / folder).rglob("*")) if p.suffix in (".py", ".md", ".csv", ".toml", ".txt")]
    offenders = [str(p.relative_to(ROOT)) for p in [*paths, ROOT / "README.md"] if pattern.search(p.read_text())]
    assert offenders == [], offenders
    keys = set(re.findall(r"\*\*\[(\w+)\]\*\*", (ROOT / "docs" / "references.md").read_text()))
    assert keys == {"Zhong", "Zhang", "Lu", "Fukuda", "Chen"}


def test_quantise_is_spelled_one_way():
    """The glossary's spelling (quantise, quantisation) in the package, the docs and the README;
    the only others are the arguments of apytypes, the oracle the tests compare with."""
    import re

    spelled = re.compile("quanti" + "z", re.IGNORECASE)  # in two parts so that this file does not match itself
    paths = [p for folder in ("kfpga", "model", "hw", "sim", "docs") for p in sorted((ROOT / folder).rglob("*"))
             if p.suffix in (".py", ".md")] + [ROOT / "README.md"]
    offenders = [f"{p.relative_to(ROOT)}:{n}" for p in paths for n, line in enumerate(p.read_text().splitlines(), 1)
                 if spelled.search(line)]
    assert offenders == [], offenders
