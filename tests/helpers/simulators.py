"""The one rule of every co-simulation test: a missing simulator skips it, with the reason;
under ``CI=true`` it fails instead (CI must run both)."""

import os

import pytest

from kfpga.hw.tools import simulator_available


def need(simulator):
    ok, why = simulator_available(simulator)
    if not ok:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run both simulators: {why}")
        pytest.skip(why)


def core_is_bit_exact_on(simulator, config, variant, codes, seed, tag, channels=1):
    """The core bench (``sim/test_core.py``, ``core_bit_exact``) on ``codes`` (over ``channels``
    channels), with random valid/ready: every output is the model's, one per sample."""
    from kfpga.sim.runner import build, run

    need(simulator)
    result = run(build(simulator, "core", config=config, variant=variant, channels=channels), "test_core",
                 testcase="core_bit_exact",
                 params={"variant": variant, "seed": seed, "codes": [int(c) for c in codes], "samples": len(codes),
                         "channels": channels, "p_idle": 0.2, "p_ready": 0.7, "config_toml": config.to_toml()}, tag=tag)
    assert result["mismatches"] == 0 and result["ok"], result.get("first_mismatches")
    assert result["samples"] == len(codes)
    return result
