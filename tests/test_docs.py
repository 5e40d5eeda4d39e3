"""The README and the manual (docs/, ``make docs``): short README, a page per filter, the examples
they show run as written, every command's help ends with examples."""

from __future__ import annotations

import argparse
import json
import re
import shlex
from pathlib import Path

import pytest

from kfpga.cli import build_parser, main
from kfpga.core import registry
from tests.helpers.files import python_files

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _block(text, lang):
    return text.split(f"```{lang}\n", 1)[1].split("```", 1)[0]


def test_readme_is_a_first_screen():
    assert len(README.splitlines()) <= 250
    assert "make demo" in README and "make test" in README


def test_readme_links_exist():
    for target in re.findall(r"\]\((docs/[^)#]+)", README):
        assert (ROOT / target).is_file(), target


@pytest.mark.parametrize("spec", registry.specs(), ids=lambda s: s.name)
def test_every_filter_has_its_page(spec):
    page = ROOT / "docs" / "filters" / f"{spec.name}.md"
    assert page.is_file(), f"docs/filters/{spec.name}.md is missing: every registered filter has a page"
    assert f"filters/{spec.name}\n" in (ROOT / "docs" / "index.md").read_text(), "not in the manual's contents"
    assert spec.name in page.read_text().splitlines()[0] or spec.docs.source.split(":")[0] in page.read_text()
    assert f"docs/filters/{spec.name}.md" in README


def _subcommands():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sub.choices.items():
        nested = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        yield name, p
        for inner, q in (nested[0].choices.items() if nested else ()):
            yield f"{name} {inner}", q


@pytest.mark.parametrize(("name", "parser"), list(_subcommands()), ids=lambda v: v if isinstance(v, str) else "")
def test_every_help_ends_with_examples(name, parser):
    text = parser.format_help().rstrip()
    tail = text.rsplit("examples:\n", 1)
    assert len(tail) == 2, f"kfpga {name} --help has no examples"
    lines = tail[1].splitlines()
    assert 1 <= len(lines) <= 3 and all(line.strip().startswith(f"kfpga {name.split()[0]}") for line in lines)
    assert "SPEC" not in text and "§" not in text  # no internal document


def _commands(block):
    return [" ".join(shlex.split(line.split("#", 1)[0])) for line in block.splitlines() if line.strip()]


def test_readme_example_is_the_manuals_and_runs(tmp_path, monkeypatch, capsys):
    """The README's ten-line example is the manual's worked example (docs/own-model.md, whose
    commands tests/test_cli.py and tests/test_own_model.py run as written): the same config, and
    each command there too; the one the manual does not show, the core alone, runs here."""
    import tomllib

    section = README.split("## Your own model", 1)[1]
    manual = (ROOT / "docs" / "own-model.md").read_text().split("## Worked example", 1)[1]
    assert tomllib.loads(_block(section, "toml")) == tomllib.loads(_block(manual, "toml"))
    shown = _commands(_block(manual, "sh"))
    ours = _commands(_block(section, "sh"))
    assert [c.split()[1] for c in ours] == ["compare", "generate", "simulate", "generate", "generate", "regs"]
    here = [c for c in ours if "--core-only" in c or c.split()[1] == "regs"]  # the core alone and its bus
    for command in ours:
        if command in here:
            continue
        assert any(other.startswith(command.split(" --plot")[0].split(" --samples")[0]) for other in shown), command
    monkeypatch.chdir(tmp_path)
    Path("tracker.toml").write_text(_block(section, "toml"))
    for command in here:
        argv = shlex.split(command)[1:]
        assert main([*argv, "--quiet"] if argv[0] == "generate" else argv) == 0, command
    capsys.readouterr()
    assert json.loads(Path("build/core/manifest.json").read_text())
    assert json.loads(Path("build/bus/manifest.json").read_text())["bus"] == "avalon"


def test_api_example_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    Path("tracker.toml").write_text(_block(README.split("## Your own model", 1)[1], "toml"))
    code = _block((ROOT / "docs" / "api.md").read_text(), "python")
    namespace = {}
    exec(compile(code, "docs/api.md", "exec"), namespace)  # the manual's own example
    assert namespace["core"].latency >= 1
    assert "[" in capsys.readouterr().out


def test_the_manuals_register_map_is_the_generated_one():
    """docs/programmable.md's table of the paper's filter's map: every row as hw/regmap.py makes it."""
    from kfpga.core.config import FilterConfig
    from kfpga.flows.regs import program_for
    from kfpga.hw.regmap import register_map

    page = (Path(__file__).parents[1] / "docs" / "programmable.md").read_text()
    block = page.split("<!-- register-map: kalman2 steady", 1)[1].split("<!-- end register-map -->", 1)[0]
    rows = [line for line in block.splitlines() if line.startswith("| `0x")]
    config = FilterConfig()
    want = [f"| `0x{r.offset:03X}` | `{r.name}` | {r.access} | {r.description} |"
            for r in register_map(program_for(config, "steady", missing=True), config, "steady")]
    assert rows == want


def test_the_code_cites_the_references_by_key():
    """The source documents are not in the repository: the code cites them by the keys of
    docs/references.md, never by a path; "the paper" in a file is the one document the file
    names by key, or [Zhong] where it names none, so a file that says it names at most one."""
    keys = set(re.findall(r"^\*\*\[(\w+)\]\*\*", (ROOT / "docs" / "references.md").read_text(), re.M))
    assert keys == {"Zhong", "Zhang", "Lu", "Fukuda", "Chen"}
    paths, ambiguous = [], []
    for path in sorted(python_files("kfpga", "hw", "model", "sim", "tests", "bench", "examples")):
        text = path.read_text()
        if re.search(r"seeds/\d", text):
            paths.append(path.relative_to(ROOT))
        named = set(re.findall(r"\[(" + "|".join(keys) + r")\]", text))
        if "the paper" in text and len(named) > 1:
            ambiguous.append(f"{path.relative_to(ROOT)}: {sorted(named)}")
    assert not paths, f"cite the document by its key in docs/references.md, not its path: {paths}"
    assert not ambiguous, f"'the paper' with more than one document named: {ambiguous}"
