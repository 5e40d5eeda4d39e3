"""The constant-velocity loop's core, shared by the paper's steady-state filter and the alpha-beta
tracker (``model/cvloop.py``): xl1 = x1 + v, e = y - xl1, the products K e, x1 = xl1 + k1 e and
v = v + k2 e, over L register stages with the channels interleaved.

The arithmetic between the registers is the model's own: the steps run the stage functions on
:class:`~kfpga.hw.arith.AmaranthOps`, so the RTL computes the model's integers by construction.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import ClassVar

from kfpga.hw.core import LoopPipeline
from kfpga.model import cvloop as eq
from kfpga.model import start

__all__ = ["ConstantGainLoop", "with_start", "STEADY_STEPS", "STEADY_READS", "CUTS", "steady_predict", "steady_innovation",
           "steady_products", "steady_correct"]


def steady_predict(ops, k, v):
    v["xl1"] = eq.predict(ops, v["x1"], v["v"])                         # xl1 = x1 + v
    return v


def steady_innovation(ops, k, v):
    v["e"] = eq.innovation(ops, v["y"], v["xl1"])                       # e = y - xl1
    return v


def steady_products(ops, k, v):
    v["k1e"], v["k2e"] = ops.mul(k["k1"], v["e"]), ops.mul(k["k2"], v["e"])  # K1 e, T K2 e
    return v


def steady_correct(ops, k, v):
    v["x1_next"] = eq.correct(ops, v["xl1"], v["k1e"], "x1")             # x1 = xl1 + K1 e
    v["v_next"] = eq.correct(ops, v["v"], v["k2e"], "v")                 # v = v + T K2 e
    return v


def with_start(correct, observation):
    """The last step ``correct`` followed by the start from the first measurements (``[model]
    init = "measurement"``, ``model/start.py``): x1 = y on a channel's samples 0 and 1, v = y1 - y0
    on sample 1, the channel's 2-bit count written back with its state. The model's own
    :func:`~kfpga.model.cvloop.measured_start`: two comparisons and three multiplexers, no
    arithmetic beyond one subtraction, in the loop's last stage."""

    def step(ops, k, v):
        v = correct(ops, k, v)
        state = {"x1": v["x1"], "v": v["v"], "start": v["start"]}
        x1, rate, count = eq.measured_start(ops, k, state, v[observation], v["x1_next"], v["v_next"])
        v.update(x1_next=x1, v_next=rate, start_next=count["start"])
        return v

    step.__name__ = f"{correct.__name__}_with_start"
    return step


#: The steady-state update as four steps of about one carry chain (or one multiplier) each;
#: ``CUTS[L]`` lists the steps a pipeline of L stages registers after (ConstantGainLoop).
STEADY_STEPS = (steady_predict, steady_innovation, steady_products, steady_correct)
#: What each step reads: a value no later step reads is not registered.
STEADY_READS = ({"x1", "v"}, {"y", "xl1"}, {"e"}, {"xl1", "v", "k1e", "k2e"})
CUTS = {1: (), 2: (2,), 3: (1, 3), 4: (1, 2, 3)}


class ConstantGainLoop(LoopPipeline):
    """The constant-gain loop x -> xl1 -> e -> K e -> x over
    ``stages`` register stages, channels interleaved (:class:`~kfpga.hw.core.LoopPipeline`).

    The update is the model's own (``model/cvloop.py``), split into four steps: xl1 = x1 + v;
    e = y - xl1; the products K1 e, T K2 e; x1 = xl1 + K1 e and v = v + T K2 e. A pipeline of
    L stages registers between them (:data:`CUTS`): L = 4 puts one carry chain, or one
    multiplier, between two registers. One channel: one sample every L cycles; C >= L channels
    in turn (the six ADS8364 channels): one sample per clock across them. Any order works; a
    channel repeated within L samples waits.

    The rate output x2 = v / T is a free shift when T = 2**k; otherwise it takes four more
    steps after the loop (the new v registered, rounded into the 18-bit operand vt, multiplied
    by 1/T, rounded into x2), which add latency, not cycles per update.

    Parameters
    ----------
    config:
        The shared :class:`~kfpga.core.config.FilterConfig` of a filter of this loop.
    channels:
        Independent channel states (1..8).
    stages:
        L, the register stages of the loop (1..4; default 4, the one that meets 50 MHz on the
        -8 part with margin: see ``kfpga resources``).

    Members
    -------
    i : In(stream.Signature(input_layout(config, channels)))
        Samples.
    o : Out(stream.Signature(output_layout(config, channels)))
        Estimates, one per sample.
    overflow : Out(1)
        Sticky: some write saturated (or wrapped) since reset.
    """

    steps = STEADY_STEPS
    reads = STEADY_READS
    cuts = CUTS
    writes: ClassVar[dict] = MappingProxyType({"x1": "x1_next", "v": "v_next"})

    #: The output field that carries the rate v / T (the steps below write it).
    rate_output = "x2"

    def __init__(self, config, *, channels=1, stages=4, index_bits=None):
        super().__init__(config, "steady", channels=channels, stages=stages, index_bits=index_bits)
        if start.measured(config.params):
            # each channel its own count: every channel (a track's axis, a sensor) starts on its own
            observation = config.inputs[0]
            self.steps = (*self.steps[:-1], with_start(self.steps[-1], observation))
            self.reads = (*self.reads[:-1], self.reads[-1] | {"x1", "start", observation})
            self.writes = {**self.writes, "start": "start_next"}

    def outputs(self, live):
        return {"x1": live["x1_next"], "yhat": live["xl1"], "x2": live["v_next"]}

    def output_steps(self):
        name = self.rate_output

        def on_rate(step):
            return lambda ops, k, out: {**out, name: step(ops, k, out[name])}

        if self.constants["t_shift"] is not None:
            return [on_rate(eq.rate)]
        # the loop's result registered first: each step then has a cycle to itself
        return [on_rate(lambda ops, k, v: v), on_rate(eq.rate_operand), on_rate(eq.rate_product),
                on_rate(eq.rate_write)]
