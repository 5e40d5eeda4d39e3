"""Shared fixtures: every random source of a test is seeded from :func:`seed`, and the seed shown."""

import fnmatch
import os
import zlib
from pathlib import Path

import pytest

SEED_KEY = pytest.StashKey[int]()


@pytest.fixture
def seed(request):
    """This test's seed: ``KFPGA_SEED`` if set, else a stable hash of the test's id.

    The report of the test shows it (a "seed" section, on failure and with ``-rA``), and
    ``KFPGA_SEED=<seed> pytest '<test id>'`` replays it. It is not printed while the test runs,
    so it never mixes with output a test captures and checks.
    """
    override = os.environ.get("KFPGA_SEED")
    value = int(override) if override else zlib.crc32(request.node.nodeid.encode()) & 0x7FFFFFFF
    request.node.stash[SEED_KEY] = value
    return value


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if SEED_KEY in item.stash and report.when == "call":
        value = item.stash[SEED_KEY]
        report.sections.append(("seed", f"seed {value} (replay: KFPGA_SEED={value} pytest '{item.nodeid}')"))
    return report


#: The fast tier (``make check``): lint, the unit tests and the models' tests, none of which builds a
#: simulator or runs a synthesis tool. A test of these files marked ``slow``, ``cosim``, ``long`` or
#: ``models`` stays out of it.
CHECK_FILES = ("test_lint.py", "test_layout.py", "test_config.py", "test_fixed.py", "test_ops.py", "test_fuzz.py", "test_golden.py",
               "test_analysis.py", "test_precision.py", "test_plugins.py", "test_cli_errors.py", "test_docs.py",
               "test_regs.py", "test_missing.py", "test_model_*.py")
_NOT_CHECK = {"slow", "cosim", "long", "models"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        name = Path(str(item.fspath)).name
        if any(fnmatch.fnmatch(name, pattern) for pattern in CHECK_FILES) and \
                not _NOT_CHECK & {mark.name for mark in item.iter_markers()}:
            item.add_marker(pytest.mark.check)
