"""The example models of ``examples/models`` at their own sample periods, with their default formats
and with the formats ``kfpga propose`` found for them (``<model>.proposed.toml``, searched on seeds
1..4): every variant's fixed-point RMSE within 1 % of float's on five seeds the search did not see,
and the design ``--architecture auto`` chooses at the model's ``[board]`` rate bit-exact against the
model on Verilator and Icarus, with random backpressure.

The models tier: ``make models`` (about 10 minutes on 2 cores; not part of ``make test``).
"""

from pathlib import Path

import pytest

from kfpga.core.config import FilterConfig
from kfpga.flows.analysis import compare
from kfpga.flows.explore import candidates, choose
from kfpga.model import scenarios
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.simulators import need

pytestmark = [pytest.mark.models, pytest.mark.slow]

MODELS = Path(__file__).resolve().parents[1] / "examples" / "models"
#: the seeds propose searched (bench/bench_models.py) and the ones it did not see
SEARCH_SEEDS = (1, 2, 3, 4)
UNSEEN_SEEDS = (1001, 1002, 1003, 1004, 1005)
NAMES = sorted(p.stem for p in MODELS.glob("*.toml") if not p.stem.endswith(".proposed"))


def _config(name, formats):
    path = MODELS / (f"{name}.proposed.toml" if formats == "proposed" else f"{name}.toml")
    assert path.exists(), f"{path.name} is missing: python bench/bench_models.py --only {name} writes it"
    return FilterConfig.from_toml(path)


def _cases():
    for name in NAMES:
        config = FilterConfig.from_toml(MODELS / f"{name}.toml")
        for variant, v in config.spec.model.variants.items():
            if v.applies(config.params) is None:
                for formats in ("default", "proposed"):
                    yield pytest.param(name, formats, variant, id=f"{name}-{formats}-{variant}")


CASES = list(_cases())


def test_every_model_has_both_variants_and_a_proposal():
    assert {"tracker", "ca3-100hz", "paper-1khz", "cv4-50hz", "walk1"} <= set(NAMES)
    for name in NAMES:
        assert {c.values[2] for c in CASES if c.values[0] == name} == {"steady", "full"}, name
        assert (MODELS / f"{name}.proposed.toml").exists(), name


@pytest.mark.parametrize(("name", "formats", "variant"), CASES)
def test_fixed_point_stays_within_one_percent_of_float_on_unseen_seeds(name, formats, variant):
    config = _config(name, formats)
    scenario = config.spec.model.scenarios[0]
    for seed in UNSEEN_SEEDS:
        assert seed not in SEARCH_SEEDS
        truth, y = scenarios.for_config(scenario, 20000, seed, config)
        m = compare(config, variant, y, truth, limit_cycle=False).metrics
        print(f"{name} {formats} {variant} seed {seed}: fixed RMSE / float's = {m['rmse_fixed_over_float']:.5f}")
        assert abs(m["rmse_fixed_over_float"] - 1) <= 0.01, (seed, m["rmse_fixed_over_float"])
        assert m["overflows"] == 0, (seed, m["overflow_points"])


@pytest.mark.cosim
@pytest.mark.timeout(900)
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("name", "formats", "variant"), CASES)
def test_the_chosen_design_is_bit_exact(name, formats, variant, simulator, seed):
    need(simulator)
    config = _config(name, formats)
    best = choose(candidates(config, variant, channels=1, clock_hz=config.board.clock_hz,
                             need_hz=config.board.sample_rate_hz))
    assert best.meets, best.as_dict()
    options = {"architecture": best.architecture, **({} if best.stages is None else {"stages": best.stages})}
    samples = 300 if simulator == "verilator" else 120
    result = run(build(simulator, "core", config=config, variant=variant, channels=1, **options), "test_core",
                 testcase="core_bit_exact",
                 params={"variant": variant, "seed": seed, "samples": samples, "channels": 1, "p_idle": 0.2,
                         "p_ready": 0.6, "config_toml": config.to_toml(), **options}, tag=f"models-{name}-{variant}")
    print(f"{name} {formats} {variant} on {simulator}: {best.label}, {result.get('samples')} samples")
    assert result["ok"] and result["mismatches"] == 0, result.get("first_mismatches")
    assert result["samples"] >= samples
