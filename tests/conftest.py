"""Shared fixtures: every random source of a test is seeded from :func:`seed`, and the seed printed."""

import os
import sys
import zlib
from pathlib import Path

import pytest

# the Amaranth test helpers shared by the unit tests (tests/*_harness.py)
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def seed(request):
    """This test's seed: ``KFPGA_SEED`` if set, else a stable hash of the test's id.

    It is printed, so a failure shows it; ``KFPGA_SEED=<seed> pytest '<test id>'`` replays it.
    """
    override = os.environ.get("KFPGA_SEED")
    value = int(override) if override else zlib.crc32(request.node.nodeid.encode()) & 0x7FFFFFFF
    print(f"seed {value} (replay: KFPGA_SEED={value} pytest '{request.node.nodeid}')")
    return value
