"""Shared fixtures: every random source of a test is seeded from :func:`seed`, and the seed shown."""

import os
import zlib

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
