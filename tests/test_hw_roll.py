"""The ship-roll interval predictor's core against the bit-accurate model, in cocotb."""

import numpy as np
import pytest

from kfpga.model import roll
from kfpga.sim.runner import SIMULATORS
from tests.helpers.simulators import core_is_bit_exact_on


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", [pytest.param(s, marks=[pytest.mark.long] if s == "icarus" else []) for s in SIMULATORS])
def test_core_is_the_interval_predictor_in_cocotb(simulator, seed):
    """The generated Verilog of the roll core on a roll series ([Zhang]'s table 1, then a
    synthetic series), with random valid/ready: every output is the model's, which is the
    combined interval predictor's prediction of the sample 2 ahead (``predict_fixed``)."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model.scenarios import adc_codes

    config = FilterConfig(filter="roll")
    _, table = roll.table1()
    _, synthetic, _ = roll.synthetic_roll(90, seed)
    z = np.r_[table, synthetic]
    codes = adc_codes(z / config.params.lsb)
    pred, overflowed, _ = roll.predict_fixed(z, config)
    model = FixedModel(config).run(codes)
    np.testing.assert_array_equal(model.outputs["pred"] * config.formats["x1"].lsb * config.params.lsb, pred)
    assert overflowed == 0
    core_is_bit_exact_on(simulator, config, "sqrt", codes, seed, "roll-series")
