# amaranth: UnusedElaboratable=no
"""The stream contract in full, for every registered core on every architecture it has, and for
the stream units the cores are built from (the divider, the square root):

1. **liveness under a slow receiver**: with ``o.ready`` held low and nothing pending, ``i.ready``
   is high (after the core's ``startup_cycles``); a sample taken while ``o.ready`` is low still
   makes ``o.valid`` rise at the declared latency, and the estimate holds until it is taken
   (:func:`kfpga.sim.amaranth_streams.check_liveness`), with states in registers and in block
   memory;
2. **a receiver that raises ready only after it sees valid** gets every estimate, each equal to
   the model's (a core that waits for ``o.ready`` before it puts out a word deadlocks there);
3. **port widths**: every payload field has the width the filter's spec declares (the channel
   field as many bits as the channel count needs, at least one; the inputs the ADC's 16 bits;
   each output its point's format; the overflow flag one bit), for 1, 2, 3, 4, 5 and 256
   channels where the core holds that many, and the many-track alpha-beta core's track field
   for as many tracks.

The expected widths are computed here from their definition, not read from ``hw/layouts.py``.
"""

import math
import random

import numpy as np
import pytest
from amaranth.lib import data
from test_contract import HW_CASES, codes, samples_for

from kfpga.core.config import FilterConfig
from kfpga.hw.alphabeta import TrackerCore
from kfpga.hw.cores import make_core
from kfpga.hw.divider import Divider
from kfpga.sim.amaranth_streams import AFTER_VALID, check_liveness, run_core, run_stream

COUNTS = [1, 2, 3, 4, 5, 256]


def index_bits(count):
    """Bits that number ``count`` things, at least one (a zero-width field is not Verilog-2001)."""
    return max(1, math.ceil(math.log2(count)))


def widths(port):
    """``{field: (width, signed)}`` of a stream port's payload."""
    layout = port.signature.members["payload"].shape
    out = {}
    for name, field in layout:
        shape = data.Layout.cast(field.shape).as_shape() if isinstance(field.shape, data.Layout) else field.shape
        shape = shape if hasattr(shape, "width") else data.Shape.cast(shape)
        out[name] = (shape.width, shape.signed)
    return out


def _core(name, variant, architecture, channels):
    config = FilterConfig(filter=name)
    return config, make_core(config, variant, channels=channels, architecture=architecture)


def _holds(name, variant, architecture, channels):
    config = FilterConfig(filter=name)
    _, dut = _core(name, variant, architecture, 1)
    return channels <= getattr(dut, "max_channels", 8), config


# -- 1. liveness -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 10], ids=["registers", "memory"])
@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_a_slow_receiver_does_not_stall_the_core(name, variant, architecture, channels):
    fits, config = _holds(name, variant, architecture, channels)
    if not fits:
        channels = 3  # this core keeps its states in registers only
    _, dut = _core(name, variant, architecture, channels)
    found = check_liveness(dut, {"channel": channels - 1, **dict.fromkeys(config.inputs, 1234)})
    assert found["latency"] == dut.latency


# -- 2. a receiver that waits for valid --------------------------------------------------------------------


@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_a_receiver_ready_only_after_valid_gets_every_estimate(name, variant, architecture, seed):
    config = FilterConfig(filter=name)
    rng = np.random.default_rng(seed)
    n = samples_for(config, variant, 60, 3, architecture, pysim=True)
    y = codes(rng, n) if len(config.inputs) == 1 else {k: codes(rng, n) for k in config.inputs}
    report = run_core(config, variant, y, seed=seed, channels=3, p_idle=0.2, p_ready=AFTER_VALID,
                      options={"architecture": architecture})
    assert report["compared"] == n and report["extra"] == 0


# -- the stream units --------------------------------------------------------------------------------------


def _divide(dividend, divisor, quotient_bits):
    """The divider's contract: the quotient, or all ones and the overflow flag when it does not fit."""
    if divisor == 0 or dividend >= divisor << quotient_bits:
        return (1 << quotient_bits) - 1, 1
    return dividend // divisor, 0


UNITS = {
    "divider-12-6-7": (lambda: Divider(dividend_bits=12, divisor_bits=6, quotient_bits=7),
                       lambda r: {"dividend": r.randrange(1 << 12), "divisor": r.randrange(1 << 6)},
                       lambda p: _divide(p["dividend"], p["divisor"], 7),
                       lambda o: (int(o.quotient), int(o.overflow))),
    "divider-5-5-5": (lambda: Divider(dividend_bits=5, divisor_bits=5, quotient_bits=5),
                      lambda r: {"dividend": r.randrange(1 << 5), "divisor": r.randrange(1 << 5)},
                      lambda p: _divide(p["dividend"], p["divisor"], 5),
                      lambda o: (int(o.quotient), int(o.overflow))),
}


@pytest.mark.parametrize("unit", list(UNITS))
def test_a_slow_receiver_does_not_stall_a_unit(unit, seed):
    make, draw, _, _ = UNITS[unit]
    dut = make()
    found = check_liveness(dut, draw(random.Random(seed)))
    assert found["latency"] == dut.latency


@pytest.mark.parametrize("policy", [AFTER_VALID, 0.3], ids=["after-valid", "random-ready"])
@pytest.mark.parametrize("unit", list(UNITS))
def test_a_unit_answers_every_request_whatever_its_receiver(unit, policy, seed):
    make, draw, expect, read = UNITS[unit]
    rng = random.Random(seed)
    requests = [draw(rng) for _ in range(80)]
    out = run_stream(make(), requests, seed=seed, p_idle=0.3, p_ready=policy, extra_cycles=30)
    assert [read(o) for o in out] == [expect(p) for p in requests]


# -- 3. port widths ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", COUNTS)
@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_port_widths_are_the_declared_ones(name, variant, architecture, channels):
    fits, config = _holds(name, variant, architecture, channels)
    if not fits:  # a core that holds fewer channels says so, rather than building a wrong one
        with pytest.raises(ValueError, match="channels must be an integer"):
            _core(name, variant, architecture, channels)
        return
    _, dut = _core(name, variant, architecture, channels)
    want_in = {"channel": (index_bits(channels), False), **dict.fromkeys(config.inputs, (16, True))}
    want_out = {"channel": (index_bits(channels), False),
                **{o.name: (config.output_format(o.name).width, True) for o in config.outputs}, "overflow": (1, False)}
    assert widths(dut.i) == want_in
    assert widths(dut.o) == want_out


@pytest.mark.parametrize("tracks", COUNTS)
def test_tracker_port_widths(tracks):
    config = FilterConfig(filter="alphabeta")
    dut = TrackerCore(config, tracks=tracks)
    assert widths(dut.i) == {"track": (index_bits(tracks), False), "axis": (1, False), "z": (16, True)}
    assert widths(dut.o) == {"track": (index_bits(tracks), False), "axis": (1, False),
                             **{o.name: (config.output_format(o.name).width, True) for o in config.outputs},
                             "overflow": (1, False)}
