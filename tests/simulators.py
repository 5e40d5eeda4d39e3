"""The one rule of every co-simulation test: a missing simulator skips it, with the reason;
under ``CI=true`` it fails instead (CI must run both)."""

import os

import pytest

from kfpga.tools import simulator_available


def need(simulator):
    ok, why = simulator_available(simulator)
    if not ok:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run both simulators: {why}")
        pytest.skip(why)
