"""The project's Python files, each once: ``kfpga/hw``, ``kfpga/model`` and ``kfpga/sim`` link to
the top-level folders, so a walk of ``kfpga/`` skips them."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LINKED = ("model", "hw", "sim")


def python_files(*folders):
    """The ``*.py`` files under ``folders`` (relative to the root), the links not followed."""
    return [p for folder in folders for p in (ROOT / folder).rglob("*.py")
            if not (folder == "kfpga" and p.relative_to(ROOT / folder).parts[0] in LINKED)]
