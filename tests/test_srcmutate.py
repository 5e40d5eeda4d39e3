"""The source-level mutation of ``make mutate`` (``kfpga/verify/srcmutate.py``): its operators
change what they say, in logic only, and every mutant it draws is valid Python that differs."""

import ast
import random
import textwrap
from pathlib import Path

import pytest

from kfpga.verify.srcmutate import NOT_RTL, apply, mutants_of, sites

SOURCE = textwrap.dedent('''\
    """A block."""
    from amaranth import Module, Mux


    def elaborate(self, width=4):
        """The logic."""
        if width < 2:
            raise ValueError(f"width must be >= 2, not {width + 0}")
        m = Module()
        with m.If(self.a == self.b):
            m.d.sync += self.x.eq(self.a + 1)
        with m.Elif(self.a < self.b):
            m.d.comb += self.y.eq(Mux(self.s, self.a, self.b) & self.c)
        self._wire(m)
        return m
''')


@pytest.fixture
def block(tmp_path):
    path = tmp_path / "block.py"
    path.write_text(SOURCE)
    return path


def test_every_operator_has_its_site(block):
    found = {(op, text) for op, _, text in sites(block)}
    assert ("==/!=", "(self.a != self.b)") in found
    assert ("</<=", "(self.a <= self.b)") in found
    assert ("+/-", "(self.a - 1)") in found
    assert ("&/|", "(Mux(self.s, self.a, self.b) | self.c)") in found
    assert ("Mux swap", "Mux(self.s, self.b, self.a)") in found
    assert ("const+-1", "0") in found  # the 1 of a + 1
    assert ("not", "~(self.a == self.b)") in found and ("not", "~(self.a < self.b)") in found
    drops = [node for op, node, _ in sites(block) if op == "drop"]
    assert sorted(n.lineno for n in drops) == [11, 13, 14]


def test_no_site_in_a_check_a_message_a_default_or_a_docstring(block):
    lines = {node.lineno for _, node, _ in sites(block)}
    assert not lines & {1, 5, 6, 7, 8}  # the docstrings, the default width=4, the check and its message


def test_each_mutant_is_valid_python_that_differs(block):
    mutants = mutants_of(block.name, 100, random.Random(3), root=block.parent)
    assert len(mutants) == len(sites(block))
    for m in mutants:
        new = apply(m, block.parent)
        assert new != SOURCE
        ast.parse(new)
        changed = [k + 1 for k, (a, b) in enumerate(zip(SOURCE.splitlines(), new.splitlines(), strict=True)) if a != b]
        assert changed and changed[0] == m.line


def test_the_draw_is_seeded(block):
    one = [(m.line, m.operator) for m in mutants_of(block.name, 4, random.Random(7), root=block.parent)]
    two = [(m.line, m.operator) for m in mutants_of(block.name, 4, random.Random(7), root=block.parent)]
    assert one == two and len(one) == 4


def test_a_files_draw_depends_on_the_seed_and_its_path_only(block):
    """So ``--only`` batches draw the mutants the whole run draws for their files."""
    other = block.parent / "other.py"
    other.write_text(SOURCE)
    alone = mutants_of(block.name, 3, 5, root=block.parent)
    mutants_of(other.name, 3, 5, root=block.parent)
    again = mutants_of(block.name, 3, 5, root=block.parent)
    assert [(m.line, m.after) for m in alone] == [(m.line, m.after) for m in again]
    assert {(m.line, m.after) for m in alone} != {(m.line, m.after) for m in mutants_of(block.name, 3, 6, root=block.parent)}


def test_every_rtl_file_of_hw_has_three_sites_at_least():
    root = Path(__file__).parents[1]
    for path in sorted((root / "hw").glob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel in NOT_RTL:
            continue
        assert len(mutants_of(rel, 3, random.Random(1), root=root)) == 3, rel


def test_a_design_that_no_longer_elaborates_kills_the_mutant(tmp_path):
    """A constant table is run at import, by no test's context: its mutant is judged on the designs
    the tests build, and one that no longer elaborates is killed, not a survivor."""
    from kfpga.verify.srcmutate import broken, equivalence

    original, mutant = tmp_path / "original", tmp_path / "mutant"
    original.mkdir()
    mutant.mkdir()
    for name in ("a", "b"):
        (original / f"{name}.il").write_text(f"module {name}\n")
    (mutant / "a.il").write_text("module a\n")
    (mutant / "b.il").write_text("elaboration failed: IndexError: tuple index out of range")
    assert broken(original, mutant) == "b"
    (mutant / "b.il").write_text("module b\n")
    assert broken(original, mutant) is None
    assert equivalence(original, mutant, tmp_path / "eq") == (True, "no design of the tool's set changes")


def test_the_designs_take_the_branches_the_defaults_do_not(tmp_path):
    """An equivalent verdict is only as wide as the designs compared: besides each core at its
    defaults (T = 1, x0 = 0, a free-running ADC), the set has each preset, the two models whose
    period is not a power of two (x2 = v / T in more steps, F's constants multiplied), the board's
    conversion timer and states in block memory that start from a negative x0."""
    from kfpga.verify.srcmutate import elaborate

    designs, why = elaborate(Path.cwd(), tmp_path)
    assert designs is not None, why
    for name in ("kalman2-T0.3-full-parallel", "kalman2-T0.3-steady-parallel", "kalman-tracker-T0.01-steady-parallel",
                 "kalman-tracker-T0.01-full-folded", "kalman-ca3-steady-parallel", "alphabeta-ab-bb-steady-parallel",
                 "tukey53h-53h-attitude-online-parallel", "top-rate", "kalman-ca3-x0-steady-parallel-9"):
        assert name in designs, name


def test_a_line_run_at_import_gets_the_tests_of_its_file():
    from kfpga.verify.srcmutate import Mutant, tests_of

    covered = {("hw/a.py", 10): {"t1"}, ("hw/a.py", 12): {"t2"}, ("hw/b.py", 3): {"t3"}}
    inside = Mutant("hw/a.py", 10, "+/-", "a + b", "a - b", (10, 4), (10, 9))
    table = Mutant("hw/a.py", 2, "const+-1", "3", "4", (2, 8), (2, 9))
    assert tests_of(covered, inside) == {"t1"}
    assert tests_of(covered, table) == {"t1", "t2"}  # no test runs line 2: its file's tests


def test_a_verdict_is_kept_while_its_file_is_unchanged(block, tmp_path, monkeypatch):
    """An interrupted run resumes: the verdicts written as they are measured are read back for
    the same change of the same source, and not once the file changes."""
    import json
    from dataclasses import asdict

    from kfpga.verify import srcmutate

    monkeypatch.setattr(srcmutate, "ROOT", tmp_path / "out")
    (tmp_path / "out").mkdir()
    first = mutants_of(block.name, 2, 1, root=block.parent)
    first[0].result, first[0].by, first[0].seconds = "killed", "tests/x.py::test_y", 12.5
    lines = [json.dumps(asdict(first[0])), '{"cut short']
    (tmp_path / "out" / srcmutate.VERDICTS).write_text("\n".join(lines) + "\n")
    kept = srcmutate._verdicts()
    again = mutants_of(block.name, 2, 1, root=block.parent)
    assert again[0].key in kept and kept[again[0].key]["result"] == "killed"
    assert again[1].key not in kept
    block.write_text(SOURCE.replace("width=4", "width=5"))
    assert all(m.key not in kept for m in mutants_of(block.name, 2, 1, root=block.parent))


def test_the_per_file_table():
    from kfpga.verify.srcmutate import Mutant, markdown, summary

    done = [Mutant("hw/a.py", 1, "+/-", "a", "b", (1, 0), (1, 1), result=r, seconds=60.0)
            for r in ("killed", "killed", "equivalent")]
    done.append(Mutant("hw/b.py", 2, "drop", "x", "pass", (2, 0), (2, 1), result="survived", seconds=30.0))
    rows = summary(done)
    assert [(r["file"], r["killed"], r["equivalent"], r["survived"], r["score"]) for r in rows] == [
        ("hw/a.py", 2, 1, 0, 1.0), ("hw/b.py", 0, 0, 1, 0.0)]
    text = markdown(rows).splitlines()
    assert text[2] == "| `hw/a.py` | 3 | 2 | 1 | 0 | 100 % | 3.0 |"
    assert text[3] == "| `hw/b.py` | 1 | 0 | 0 | 1 | 0 % | 0.5 |"


def test_only_a_kill_outlives_a_change_of_the_tests():
    from kfpga.verify.srcmutate import kept_verdicts

    verdicts = {"a": {"result": "killed", "context": "old"}, "b": {"result": "equivalent", "context": "old"},
                "c": {"result": "survived", "context": "new"}, "d": {"result": "equivalent"}}
    assert set(kept_verdicts(verdicts, "new")) == {"a", "c"}
    assert set(kept_verdicts(verdicts, "old")) == {"a", "b"}
