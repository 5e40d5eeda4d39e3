"""The least-squares front end's core against the bit-accurate model, through a deceleration."""

import pytest
from test_model_lsfront import _fixed

from kfpga.sim.runner import SIMULATORS
from tests.helpers.simulators import core_is_bit_exact_on


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
def test_core_is_bit_exact_through_a_deceleration(simulator, seed):
    """The generated Verilog of the front end and its filter on the patent's scenario (400 s: the
    cruise, the deceleration, the stop), with random valid/ready: the raw velocity at the start
    (m = 1) and every window of the table are used, and every output is the model's."""
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model.evaluations.lsfront import DecelerationScenario, deceleration_log
    from kfpga.model.scenarios import adc_codes

    config = _fixed()
    _, _, v, _ = deceleration_log(DecelerationScenario(seconds=400), seed)
    codes = adc_codes(v / config.params.lsb)
    used = set(FixedModel(config).run(codes).outputs["ns"].tolist())
    assert used == {0, *config.params.windows}, used
    core_is_bit_exact_on(simulator, config, "steady", codes, seed, "lsfront-deceleration")
