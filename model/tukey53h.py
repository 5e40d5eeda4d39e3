"""Tukey's 53H outlier smoother ([Lu]): its equations, its online and offline forms, its spec.

For a series ``x``:

1. ``x1`` = running median of 5 of ``x``;
2. ``x2`` = running median of 3 of ``x1``;
3. ``x3(l) = x2(l-1)/4 + x2(l)/2 + x2(l+1)/4`` (Hanning);
4. where ``|x(l) - x3(l)| > threshold``, ``x(l)`` is replaced by ``x3(l)``.

**Online** (:data:`SPEC`, the model and the core): one output per input, 4 samples late: the
output for the input ``x[n]`` is the decision on ``x[n-4]`` (the Hanning value centred there needs
``x[n-8..n]``). The state carries what the next decision needs: the last four samples, the last
two medians of 5 and the last two medians of 3. The first sample of a channel fills them all with
itself, which is the series extended to the left by copies of its first sample: the first four
outputs are that sample, and no reset value enters a median.

**Offline** (:func:`offline`, the paper's improved version for the ends): the online smoother
leaves the first and last four points without a centred window. The first 8 and the last 8
points are reversed, the smoother runs again, and its decisions for the points that now lie
inside (the paper's ``x'3(5..8)`` and ``x'3(l-7..l-4)``) replace those of the first and last 4.
The same threshold test decides them as every other point (the paper says "replace"; a point
within the threshold of its smoothed value is kept, as everywhere else). It needs at least 16
points, so that the two reversed blocks do not overlap.

**Fixed point.** Medians select samples, so they are exact in the samples' format (point ``x``,
by default the 16-bit code itself). The Hanning weights are exact shifts: ``(a + 2 b + c) / 4``
is formed exactly with two more fraction bits and written once into point ``x3`` with its
rounding rule; by default ``x3`` is a 16-bit code rounded to the nearest, ties up
(``floor(v + 1/2)``): a convex combination of codes rounded so stays within the codes, so it
cannot overflow. The test ``|x - x3| > threshold`` is exact (the threshold is a constant of
point ``threshold``), and the output ``y`` (point ``y``) is either the sample or ``x3``.

**Angles** (``turn``, the codes of a full turn: 36000 for a heading in 0.01 deg codes): the
window and the medians are kept in the frame of the channel's newest sample. When a sample is
more than half a turn from the one before (a heading crossing +-180 deg), every stored value of
the channel moves by a full turn with it (:func:`frame_shift`), so the medians, the Hanning value
and the threshold test see a continuous angle; the output is brought back into
``[-turn/2, turn/2)``. A heading crossing +-180 deg passes unchanged (a code of exactly
``+turn/2``, +180.00 deg, comes out as ``-turn/2``, the same angle), and an outlier next to
the crossing is found as anywhere else. The stored values then need 18 bits (point ``x``).

**Thresholds from physical limits** (the paper, §3): a velocity cannot change by more than
``a_max * T`` in one sample, an attitude angle by more than ``omega_max * T``
(:func:`velocity_threshold`, :func:`attitude_threshold`, in codes of a given LSB).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from kfpga.core.board import WORST_PATH_GOAL_NS
from kfpga.core.fixed import QFormat, Rounding
from kfpga.core.formats import MAX_WORD, precision_frac_bits
from kfpga.core.params import number
from kfpga.core.spec import Constant, Docs, FilterSpec, Hardware, Mode, Model, MutationBlock, Output, Point, Prefilter, Variant

__all__ = ["Tukey53HParams", "SPEC", "POINTS", "FLAG", "DELAY", "MIN_OFFLINE", "update", "median5", "median3",
           "MEDIAN5", "MEDIAN3", "network_layer", "network_reads", "hanning_partial", "hanning", "residual", "decide",
           "window_step", "primed_line", "reference", "offline", "velocity_threshold", "attitude_threshold",
           "position_threshold", "turn_format", "MAX_INPUT_BITS"]

#: Samples from an input to the output that decides it.
DELAY = 4
#: The shortest series :func:`offline` takes (its two reversed blocks of 8 must not overlap).
MIN_OFFLINE = 16
#: The format of the "primed" flag of a channel's state (0 after reset, 1 once a sample came).
FLAG = QFormat(2, 0)
def turn_format(params):
    """The format of a full turn of an angle (``turn``) and of the stored values it moves:
    two bits above the samples'."""
    return QFormat(params.input_bits + 2, 0)
#: The widest samples (``input_bits``): a latitude or longitude in 1e-7 deg needs 32.
MAX_INPUT_BITS = 32


def velocity_threshold(a_max, T, lsb):
    """``a_max * T`` in codes of ``lsb`` (the velocity a code stands for): the largest change of
    a velocity in one sample (the paper: ``Tp = a_max T``)."""
    for name, value in (("a_max", a_max), ("T", T), ("lsb", lsb)):
        number(name, value, minimum=0.0, strict=True)
    return a_max * T / lsb


def position_threshold(v_max, T, lsb, radius=6371000.0):
    """``V_max T / R`` in codes of ``lsb`` degrees (a latitude or a longitude): the largest change
    of a position angle in one sample at the ship's largest speed ``v_max`` (m/s) on a sphere of
    ``radius`` metres (the paper: ``Tp = V_max / R``, with T = 1 s). A longitude moves faster by
    1/cos(latitude): divide by it for a ship far from the equator."""
    for name, value in (("v_max", v_max), ("T", T), ("lsb", lsb), ("radius", radius)):
        number(name, value, minimum=0.0, strict=True)
    return np.degrees(v_max * T / radius) / lsb


def attitude_threshold(omega_max, T, lsb):
    """``omega_max * T`` in codes of ``lsb`` (the angle a code stands for): the largest change of
    an attitude angle in one sample (the paper: ``T_phi = omega_max T``)."""
    for name, value in (("omega_max", omega_max), ("T", T), ("lsb", lsb)):
        number(name, value, minimum=0.0, strict=True)
    return omega_max * T / lsb


@dataclass(frozen=True, kw_only=True)
class Tukey53HParams:
    """Parameters of the 53H smoother (default: a ship's velocity in mm/s codes at 1 Hz, a_max = 0.5 m/s^2).

    Parameters
    ----------
    threshold:
        A sample further than this from its smoothed value (in input units: codes) is an
        outlier and is replaced; > 0 and at most 65535 (two codes differ by no more).
    turn:
        For an angle, the codes of a full turn (36000 for 0.01 deg codes, 65536 for a binary
        angle): an even integer from 4 to 2**input_bits, the threshold below a quarter of it; a
        heading that crosses half a turn then passes unchanged (module docstring). ``None`` (the
        default): not an angle.
    input_bits:
        The samples' width, 16 (an ADC code, the default) to 32: navigation data that are not an
        ADC code, such as a latitude or a longitude in 1e-7 deg (32 bits; the paper's threshold
        ``V_max T / R``, :func:`position_threshold`). The core alone takes them; the board's ADC
        gives 16.

    Raises ``TypeError`` for a value of the wrong type and ``ValueError`` for a wrong value.
    """

    threshold: float = 500.0
    turn: float | None = None
    input_bits: int = 16

    def __post_init__(self):
        bits = self.input_bits
        if not isinstance(bits, int) or isinstance(bits, bool) or not 16 <= bits <= MAX_INPUT_BITS:
            raise ValueError(f"input_bits must be an integer 16..{MAX_INPUT_BITS}, not {bits!r}")
        value = number("threshold", self.threshold)
        largest = float((1 << bits) - 1)
        if not 0 < value <= largest:
            raise ValueError(f"threshold must be > 0 (in codes) and at most {largest:g}, the largest difference "
                             f"of two {bits}-bit samples, not {self.threshold!r}")
        object.__setattr__(self, "threshold", value)
        if self.turn is not None:
            turn = number("turn", self.turn)
            if turn != int(turn) or int(turn) % 2 or not 4 <= turn <= 1 << bits:
                raise ValueError(f"turn must be an even integer 4..{1 << bits} (the codes of a full turn), not "
                                 f"{self.turn!r}")
            if value >= turn / 4:
                raise ValueError(f"threshold must be below a quarter of the turn ({turn / 4:g} codes), not "
                                 f"{value:g}: an angle's outlier test needs the window within half a turn")
            object.__setattr__(self, "turn", float(turn))


POINTS = {
    "x": Point("x", "a stored sample (the window, the medians of 5 and of 3)", frac=0),
    "x3": Point("x3", "the Hanning value x3 = x2(l-1)/4 + x2(l)/2 + x2(l+1)/4", frac=0),
    "y": Point("y", "the output: the sample, or x3 in its place", frac=0),
    "threshold": Point("threshold", "the outlier threshold", constant=True),
}

STATE = (("w1", "x"), ("w2", "x"), ("w3", "x"), ("w4", "x"), ("a1", "x"), ("a2", "x"), ("b1", "x"), ("b2", "x"),
         ("primed", FLAG))


# -- the stages, one set for the model and the core ----------------------------------------------


#: The median-of-5 selection network, layer by layer (the comparators of a layer run side by
#: side): ``("sort", i, j)`` puts the smaller of values i, j at i and the larger at j;
#: ``("min", i, j)`` only the smaller at i, ``("max", i, j)`` only the larger at j (the other
#: output no later comparator reads). 7 comparators, 5 layers; the median ends at position 2.
MEDIAN5 = (
    (("sort", 0, 1), ("sort", 3, 4)),
    (("max", 0, 3), ("min", 1, 4)),  # v0 is the smallest of four and v4 the largest: both out
    (("sort", 1, 2),),
    (("min", 2, 3),),
    (("max", 1, 2),),
)
#: The median of 3: ``max(min(a, b), min(max(a, b), c))``; 3 comparators, 3 layers, at position 1.
MEDIAN3 = (
    (("sort", 0, 1),),
    (("min", 1, 2),),
    (("max", 0, 1),),
)


def network_layer(ops, values, layer):
    """One layer of a comparator network over the list ``values``; returns the new list."""
    out = list(values)
    for kind, i, j in layer:
        if kind == "sort":
            out[i], out[j] = ops.sort2(values[i], values[j])
        elif kind == "min":
            out[i] = ops.min(values[i], values[j])
        else:
            out[j] = ops.max(values[i], values[j])
    return out


def network_reads(layers, result):
    """``[positions read from layer n on]`` for n = 0..len(layers): what a pipeline register
    after layer n - 1 must hold (the last entry: the result alone)."""
    reads = [{result}]
    for layer in reversed(layers):
        reads.insert(0, reads[0] | {p for _, i, j in layer for p in (i, j)})
    return [sorted(r) for r in reads]


def median5(ops, a, b, c, d, e):
    """The median of five (:data:`MEDIAN5`)."""
    values = [a, b, c, d, e]
    for layer in MEDIAN5:
        values = network_layer(ops, values, layer)
    return values[2]


def median3(ops, a, b, c):
    """The median of three (:data:`MEDIAN3`)."""
    values = [a, b, c]
    for layer in MEDIAN3:
        values = network_layer(ops, values, layer)
    return values[1]


def hanning_partial(ops, before, centre):
    """``before + 2 centre``: the first addition of the Hanning value (a shift, exact)."""
    return ops.add(before, ops.shift(centre, 1))


def hanning(ops, partial, after):
    """``x3 = (partial + after) / 4 = before/4 + centre/2 + after/4``, exact until it is written
    once into point ``x3``."""
    return ops.rq(ops.shift(ops.add(partial, after), -2), "x3")


def residual(ops, sample, x3):
    """``|sample - x3|``, exact."""
    return ops.abs(ops.sub(sample, x3))


def decide(ops, k, sample, x3, distance):
    """``y = x3`` where ``distance = |sample - x3| > threshold``, else the sample (for an angle,
    brought back into the codes' half turns)."""
    return ops.rq(wrapped(ops, k, ops.select(ops.gt(distance, k["threshold"]), x3, sample)), "y")


def frame_shift(ops, k, sample, previous):
    """For an angle (``turn``): the full turn by which the channel's stored values move to the
    frame of ``sample``, +turn when it is more than half a turn above ``previous`` (the stored
    newest sample), -turn when more than half a turn below, else 0; ``None`` without a turn."""
    if "turn" not in k:
        return None
    d = ops.sub(sample, previous)
    return ops.select(ops.gt(d, k["half_turn"]), k["turn"],
                      ops.select(ops.gt(k["minus_half_turn"], d), k["minus_turn"], k["no_turn"]))


def shifted(ops, value, shift):
    """A stored value moved by the frame shift (unchanged without a turn)."""
    return value if shift is None else ops.rq(ops.add(value, shift), "x", "turned")


def wrapped(ops, k, value):
    """For an angle: ``value`` brought into ``[-turn/2, turn/2)`` (unchanged without one)."""
    if "turn" not in k:
        return value
    return ops.select(ops.gt(value, k["half_turn_less"]), ops.sub(value, k["turn"]),
                      ops.select(ops.gt(k["minus_half_turn"], value), ops.add(value, k["turn"]), value))


def window_step(ops, k, x, sample):
    """``(first, window, shift)``: whether this is the channel's first sample (its state then
    fills with it), the window ``[sample, w1, w2, w3, w4]``, newest first (for an angle, in the
    sample's frame), and the frame shift the channel's other stored values take (``None``
    without a turn)."""
    first = ops.gt(ops.const(1, FLAG, "1"), x["primed"])
    s = ops.rq(sample, "x", "sample")
    shift = frame_shift(ops, k, s, x["w1"])
    return first, [s] + [ops.select(first, s, shifted(ops, x[f"w{i}"], shift)) for i in range(1, 5)], shift


def primed_line(ops, first, value, line, shift=None):
    """The delay line ``line`` (the previous values, newest first), filled with ``value`` on a
    channel's first sample; moved by the frame shift of an angle."""
    return [ops.select(first, value, shifted(ops, held, shift)) for held in line]


def update(ops, k, x, u):
    """One sample in, the decision on the sample 4 before out: ``(next state, outputs)``."""
    first, window, shift = window_step(ops, k, x, u["y"])
    m5 = median5(ops, *window)
    a1, a2 = primed_line(ops, first, m5, [x["a1"], x["a2"]], shift)
    m3 = median3(ops, m5, a1, a2)
    b1, b2 = primed_line(ops, first, m3, [x["b1"], x["b2"]], shift)
    x3 = hanning(ops, hanning_partial(ops, b2, b1), m3)
    y = decide(ops, k, window[4], x3, residual(ops, window[4], x3))
    nxt = {"w1": window[0], "w2": window[1], "w3": window[2], "w4": window[3], "a1": m5, "a2": a1, "b1": m3, "b2": b1,
           "primed": ops.const(1, FLAG, "1")}
    return nxt, {"y": y}


def _constants(params):
    k = {"threshold": Constant(params.threshold, "threshold", "threshold")}
    if params.turn is not None:
        p, turn = params.turn, turn_format(params)
        k.update(turn=Constant(p, turn, "turn"), minus_turn=Constant(-p, turn, "-turn"),
                 half_turn=Constant(p / 2, turn, "turn/2"), minus_half_turn=Constant(-p / 2, turn, "-turn/2"),
                 half_turn_less=Constant(p / 2 - 1, turn, "turn/2 - 1"), no_turn=Constant(0.0, turn, "0"))
    return k


def _initial(params):
    return {name: 0.0 for name, _ in STATE}


VARIANTS = {
    "online": Variant("online", "one sample in, the decision on the sample 4 before out; the first sample fills the "
                                "window", STATE, _constants, _initial, update),
}


# -- float -----------------------------------------------------------------------------------------------


def _online_float(x, threshold, x3_round=None):
    """The online smoother on floats along the last axis, from the windows' definition (numpy's
    median over sliding windows of the series extended by copies of its first sample):
    ``(y, x3)``, each sample's decision and Hanning value 4 samples late. ``x3_round`` rounds
    the Hanning values (the fixed-point rule), ``None`` keeps them exact."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    if n == 0:
        return x.copy(), x.copy()
    pad = np.concatenate([np.repeat(x[..., :1], 2 * DELAY, axis=-1), x], axis=-1)
    m5 = np.median(sliding_window_view(pad, 5, axis=-1), axis=-1)  # [j]: centred on pad[j + 2]
    m3 = np.median(sliding_window_view(m5, 3, axis=-1), axis=-1)  # [j]: centred on pad[j + 3]
    x3 = m3[..., :-2] / 4 + m3[..., 1:-1] / 2 + m3[..., 2:] / 4  # [j]: centred on pad[j + 4]
    if x3_round is not None:
        x3 = x3_round(x3)
    centre = pad[..., DELAY:DELAY + n]
    return np.where(np.abs(centre - x3) > threshold, x3, centre), x3


def reference(params, variant, y):
    """The float online smoother along the last axis of ``y``: ``{"y"}`` (exact Hanning values).
    For an angle the series is unwrapped first (numpy's ``unwrap`` over the turn) and the
    output wrapped back into ``[-turn/2, turn/2)``."""
    if params.turn is None:
        return {"y": _online_float(y, params.threshold)[0]}
    p = params.turn
    out = _online_float(np.unwrap(np.asarray(y, dtype=np.float64), period=p, axis=-1), params.threshold)[0]
    return {"y": (out + p / 2) % p - p / 2}


def offline(x, params=None, *, run=None):
    """The improved offline 53H of a whole series (the last axis): every point decided, the ends
    from the reversed run (module docstring). ``run(series) -> online outputs`` is the online
    smoother to use: by default the float one with ``params``; the bit-accurate one is
    ``lambda s: FixedModel(config).run(s).y``. Raises ``ValueError`` for fewer than 16 points."""
    x = np.asarray(x)
    n = x.shape[-1] if x.ndim else 0
    if n < MIN_OFFLINE:
        raise ValueError(f"the offline 53H needs at least {MIN_OFFLINE} points (it reverses the first and the last 8), "
                         f"not {n}")
    if run is None:
        if params is None:
            raise TypeError("offline needs params (the float smoother) or run")
        threshold = params.threshold

        def run(s):
            return _online_float(s, threshold)[0]

    y = np.asarray(run(x))
    out = np.empty(y.shape, dtype=y.dtype)
    out[..., DELAY:n - DELAY] = y[..., 2 * DELAY:]  # a centred window inside the series
    flipped = x.copy()
    flipped[..., :8] = x[..., :8][..., ::-1]
    flipped[..., n - 8:] = x[..., n - 8:][..., ::-1]
    yr = np.asarray(run(flipped))
    # x(3..0) now lie at 4..7 and x(n-1..n-4) at n-8..n-5, inside: their decisions come 4 later
    out[..., :DELAY] = yr[..., 11:7:-1]
    out[..., n - DELAY:] = yr[..., n - 1:n - 5:-1]
    return out


# -- the spec's hooks ----------------------------------------------------------------------------------------


def _points_for(params):
    return list(POINTS)


def _ranges(params, stimulus=None):
    # a median selects a sample, a Hanning value lies between samples: nothing leaves the codes;
    # an angle's frame moves its stored values by up to a turn
    top = float((1 << (params.input_bits - 1)) - 1)
    stored = top if params.turn is None else top + params.turn
    return {"x": stored, "x3": stored, "y": top, "threshold": params.threshold}


def _default_formats(params, ranges, *, operand_bits, state_frac, max_word=MAX_WORD):
    """The samples' own 16 bits everywhere; x3 rounded to the nearest code; the threshold in as
    many bits as it needs, and the fraction bits that hold it within 1 %."""
    frac = precision_frac_bits(params.threshold)
    int_bits = next(i for i in range(2, 20) if QFormat(i, frac).covers(params.threshold))
    bits = params.input_bits if params.turn is None else turn_format(params).int_bits
    return {"x": QFormat(bits, 0), "x3": QFormat(bits, 0, Rounding.NEAREST), "y": QFormat(params.input_bits, 0),
            "threshold": QFormat(int_bits, frac, Rounding.NEAREST)}


def _validate(config):
    return None


def _random_params(rng):
    if rng.random() < 0.25:  # an angle: a heading in 0.01 deg codes, a binary angle, a small turn
        turn = float(rng.choice([36000, 65536, 2 * int(rng.integers(200, 20000))]))
        return Tukey53HParams(threshold=float(rng.uniform(0.3, turn / 5)), turn=turn)
    return Tukey53HParams(threshold=float(rng.choice([rng.uniform(0.3, 20.0), rng.uniform(20.0, 5000.0)])))


def _goals(config, variant, channels=1):
    """No multiplier; 1,400 logic cells for one channel (11 comparators and their multiplexers,
    14 pipeline stages), each further channel about two cells per state bit (its registers,
    their read multiplexer and write enable: 260 for the 8 samples and the flag); every path
    within the board's timing goal (62.5 MHz estimated). An angle (``turn``) stores 18-bit values
    and moves them by a turn (eight adders and their multiplexers, the turn's tests, the output's
    wrap): 2,000 cells and 300 per further channel."""
    if config.params.turn is not None:
        return {"logic_cells": 2000 + 300 * (channels - 1), "mul18": 0, "lut_levels": 12,
                "worst_path_ns": WORST_PATH_GOAL_NS}
    return {"logic_cells": 1400 + 260 * (channels - 1), "mul18": 0, "lut_levels": 10, "worst_path_ns": WORST_PATH_GOAL_NS}


def _scenario(name, n, seed, params):
    """The test signals of ``compare``/``simulate``: the named scenario (with noise of variance
    4) and seeded outliers (:func:`inject_outliers`); the truth is the clean signal, 4 samples
    late as the output is."""
    from kfpga.model.scenarios import random_accel, sine

    if name == "sine":
        truth, codes = sine(n, seed, noise_var=4.0)
    elif name == "random-accel":
        truth, codes = random_accel(n, seed, q=2.0, noise_var=4.0, T=1.0)
    else:
        raise ValueError(f"scenario must be one of sine, random-accel, not {name!r}")
    # the output for input n decides sample n - 4: its truth is the clean signal 4 samples before
    late = np.concatenate([np.repeat(truth[..., :1], DELAY, axis=-1), truth[..., :-DELAY]], axis=-1)[..., :n]
    return late, inject_outliers(codes, seed, params.threshold)


def inject_outliers(codes, seed, threshold, *, density=0.01, sizes=(3.0, 10.0, 50.0), burst=(1, 2), bits=16):
    """``codes`` with seeded outliers: at ``density`` of the samples, a run of ``burst`` samples
    (each run's length drawn from it) offset by ``size * threshold`` (a size drawn from
    ``sizes``, either sign), saturated to the ``bits``-bit samples."""
    rng = np.random.default_rng([seed, 53])
    out = np.array(codes, dtype=np.int64)
    n = out.shape[-1]
    starts = np.flatnonzero(rng.random(n) < density)
    for s in starts:
        length = int(rng.choice(burst))
        offset = float(rng.choice(sizes)) * threshold * rng.choice([-1.0, 1.0])
        out[..., s:s + length] = np.clip(np.round(out[..., s:s + length] + offset), -(1 << (bits - 1)),
                                         (1 << (bits - 1)) - 1)
    return out


def _formal_config():
    """3-bit samples for the formal stream checks: the core's handshake (one enable for every
    stage, the valid bits) does not depend on the widths, and 16-bit comparator networks over
    the 36 cycles that fill its 15 registers take the solver beyond a quarter of an hour."""
    from kfpga.core.config import FilterConfig

    narrow = QFormat(3, 0)
    return FilterConfig(filter="tukey53h", params=Tukey53HParams(threshold=1.0), check_ranges=False,
                        formats={"x": narrow, "x3": QFormat(3, 0, Rounding.NEAREST), "y": narrow, "threshold": narrow})


def _offline_mode(config, variant, samples, value, *, exact, source):
    """``kfpga filter --offline``: the offline 53H of the whole file, every row decided in place."""
    from kfpga.core.errors import InputError
    from kfpga.core.fixedmodel import FixedModel

    y = samples[config.inputs[0]]
    if len(y) < MIN_OFFLINE:
        raise InputError(f"{source}: {len(y)} rows; the offline 53H needs at least {MIN_OFFLINE} (it reverses the "
                         "first and the last 8)")
    what = f"{len(y)} samples (offline)"
    if not exact:
        return {"y": offline(y, config.params)}, what
    model = FixedModel(config, variant=variant)
    out = offline(y, run=lambda x: model.run(x).y)
    # each row's flag from the run that decided it: the same mapping as the values
    flags = offline(y, run=lambda x: model.run(x).overflow)
    return {"y": model.output_format("y").to_float(out), "overflow": flags}, what


OFFLINE = Mode(
    option="--offline",
    argument={"action": "store_true",
              "help": "the offline 53H smoother of the whole file, every row decided in place (the first and last 4 "
                      "from the reversed ends, as the paper's improved 53H); at least 16 rows. Without it, row n holds "
                      "the online decision on row n - 4"},
    columns=lambda config, value: config.inputs,
    run=_offline_mode,
)


def _prefilter_params(values):
    threshold = values.get("threshold")
    return Tukey53HParams() if threshold is None else Tukey53HParams(threshold=threshold)


#: Before another filter on the board: every ADC channel its own window, glitches replaced.
PREFILTER = Prefilter(
    summary="Tukey's 53H outlier smoother between the ADS8364 controller and the core: every ADC channel gets its own "
            "window, glitches are replaced, each sample reaches the core 4 samples late",
    delay=DELAY,
    options={"--threshold": {"type": float, "metavar": "CODES",
                             "help": "the 53H pre-filter's outlier threshold in ADC codes (default: 500; a physical "
                                     "limit such as a_max*T or omega_max*T in codes)"}},
    params=_prefilter_params,
    bound=lambda params: params.threshold,
)


def _mutation():
    """``make mutate``: two channels (the channel pipeline then carries a bit), on stress codes and
    spikes at the threshold's boundary, both signs."""
    from kfpga.core.config import FilterConfig
    from kfpga.model.scenarios import stress_codes, threshold_codes

    config = FilterConfig(filter=SPEC.name)
    codes = [int(c) for c in np.r_[stress_codes(1, 300), threshold_codes(1, 480, config.params.threshold, hold=24)]]
    return [MutationBlock("tukey53h core", config, "online", {"codes": codes, "order": "round-robin"}, channels=2)]


SPEC = FilterSpec(
    name="tukey53h",
    params=Tukey53HParams,
    docs=Docs(
        summary="Tukey's 53H outlier smoother (medians of 5 and 3, Hanning, threshold test); 4 samples late",
        source="[Lu]: Lü and Geng 2019, online smoothing of ship integrated-navigation data by 53H filtering",
        aliases=("53h",),
    ),
    model=Model(
        points=POINTS,
        inputs=(("y", "the sample (a 16-bit ADC code)"),),
        outputs=(Output("y", "y", "the sample 4 before, or its smoothed value where it is an outlier"),),
        variants=VARIANTS,
        reference=reference,
        ranges=_ranges,
        default_output="y",
        points_for=_points_for,
        default_formats=_default_formats,
        validate=_validate,
        random_params=_random_params,
        scenario=_scenario,
        scenarios=("sine", "random-accel"),
        presets={
            "53h-velocity": ("a ship's velocity in mm/s codes at T = 1 s: threshold a_max*T with a_max = 0.5 m/s^2 "
                             "(500 codes)", Tukey53HParams),
            "53h-attitude": ("an attitude angle in 0.01 deg codes at T = 1 s: threshold omega_max*T with omega_max = "
                             "3 deg/s (300 codes)", lambda: Tukey53HParams(threshold=attitude_threshold(3.0, 1.0, 0.01))),
        },
        modes=(OFFLINE,),
    ),
    hardware=Hardware(
        goals=_goals,
        mutation=_mutation,
        formal_config=_formal_config,
        prefilter=PREFILTER,
    ),
    evaluation="kfpga.model.evaluations.tukey53h:EVALUATION",
)
