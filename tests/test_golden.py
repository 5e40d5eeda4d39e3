"""Golden integers of the paper's 2-state filter: the model and the RTL must never drift.

``golden/kalman2.npz`` holds inputs and outputs (x1, x2, yhat, per-sample and sticky overflow)
of six configs (the defaults; T = 0.3; T = 0.3 with Q = 1, R = 9; T = 0.5 with floor rounding
everywhere; narrow formats with wrap-around; a non-default P0 and x0), both variants, four
stimuli each (stress codes, the sine and random-acceleration scenarios, six interleaved
channels). They were recorded from the bit-accurate model and, for the stress and six-channel
stimuli and every stimulus of the default config, from the RTL in the Amaranth simulator, which
agreed on every integer. Every config names all its formats (those that were the defaults when
it was recorded), so a change of the default-format rules does not move them.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from kfpga.core.config import FilterConfig
from kfpga.core.fixed import QFormat
from kfpga.core.fixedmodel import FixedModel
from kfpga.model.reference import KalmanParams

GOLDEN = np.load(Path(__file__).parent / "golden" / "kalman2.npz")
CONFIGS = json.loads(str(GOLDEN["configs"]))
CASES = sorted({k.rsplit("/", 1)[0] for k in GOLDEN.files if k != "configs"})


def golden_config(name):
    spec = CONFIGS[name]
    formats = {n: QFormat.parse(f["format"], rounding=f["rounding"], overflow=f["overflow"])
               for n, f in spec["formats"].items()}
    return FilterConfig(params=KalmanParams(**spec["model"]), formats=formats, check_ranges=spec["check_ranges"])


@pytest.mark.parametrize("case", CASES)
def test_model_equals_golden(case):
    cname, variant, stimulus = case.split("/")
    model = FixedModel(golden_config(cname), variant=variant)
    y = GOLDEN[f"{case}/y"].astype(np.int64)
    if stimulus == "six":
        outputs, overflow, _ = model.run_channels(y, GOLDEN[f"{case}/channel"])
        got = {**outputs, "overflow": overflow}
    else:
        res = model.run(y)
        got = {**res.outputs, "overflow": res.overflow, "sticky": res.sticky}
    for field, value in got.items():
        np.testing.assert_array_equal(value, GOLDEN[f"{case}/{field}"], err_msg=f"{case}: {field}")
