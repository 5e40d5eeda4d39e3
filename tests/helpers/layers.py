"""The import-linter contracts of ``pyproject.toml`` over the package as it installs.

The repository keeps ``hw/``, ``model/`` and ``sim/`` at the top, each file once, and
``pyproject.toml`` installs them as ``kfpga.hw``, ``kfpga.model`` and ``kfpga.sim``. import-linter
(through grimp) walks the folder of the package it is given, so it runs on a view of the
installed layout under ``build/layers``: ``kfpga/`` whose entries link to the repository's
files, the mapped folders among them. Run ``python -m tests.helpers.layers`` (``make check``
and ``make test`` do); exit status is lint-imports'.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from kfpga.verify.srcmutate import package_dirs

ROOT = Path(__file__).resolve().parents[2]


def installed_view(root=ROOT, out=None):
    """``build/layers/kfpga``: the package laid out as it installs, of links into ``root``."""
    out = Path(out or root / "build" / "layers")
    if out.exists():
        shutil.rmtree(out)
    package = out / "kfpga"
    package.mkdir(parents=True)
    for entry in (root / "kfpga").iterdir():
        if entry.name != "__pycache__":
            (package / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    for name, folder in package_dirs(root).items():
        (out.joinpath(*name.split("."))).symlink_to(root / folder, target_is_directory=True)
    return out


def lint_imports(root=ROOT):
    """``(returncode, output)`` of lint-imports on the installed view, with ``root``'s contracts."""
    view = installed_view(root)
    lint = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    result = subprocess.run([lint, "--no-cache", str(root / "pyproject.toml")], capture_output=True,
                            text=True, cwd=view, env={"PATH": str(Path(sys.executable).parent), "PYTHONPATH": str(view)})
    return result.returncode, result.stdout + result.stderr


if __name__ == "__main__":
    code, text = lint_imports()
    print(text.rstrip())
    sys.exit(code)
