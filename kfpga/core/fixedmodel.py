"""The bit-accurate model of any registered filter: the integers its RTL core computes.

:class:`FixedModel` runs a variant's update function (``kfpga/core/spec.py``), traced once per config
into a compiled sample loop (``kfpga/core/compiled.py``): the scalar form for one channel, the numpy
form for a batch of channels (on int64 arrays, or on arrays of Python ints where an intermediate
can pass int64: exact at any width either way). :meth:`FixedModel.run_ops` runs the same update through
:class:`~kfpga.core.ops.IntOps` directly, sample by sample, and :meth:`FixedModel.run_exact` through
exact rationals (:class:`~kfpga.core.ops.FractionOps`); the tests hold all of them equal.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from kfpga.core.codes import CODE_FORMAT
from kfpga.core.compiled import compile_stage
from kfpga.core.config import FilterConfig
from kfpga.core.ops import FractionOps, IntOps

__all__ = ["FixedModel", "ModelState", "ModelResult"]


@dataclass(frozen=True)
class ModelState:
    """The registers of one channel (ints) or of a batch (int64 arrays), and the sticky flag."""

    values: MappingProxyType
    sticky: object = False

    def __getattr__(self, name):
        try:
            return self.__dict__["values"][name]
        except KeyError:
            raise AttributeError(name) from None


@dataclass(frozen=True)
class ModelResult:
    """Raw outputs (int64 arrays shaped like the input), flags and the state after the last sample.

    ``outputs`` maps each output field to its raw integers, in its point's format;
    ``overflow`` is the per-sample flag, ``sticky`` its running OR (from the state's sticky
    flag on), ``overflow_sites`` the per-sample flag of each write that can overflow, and
    ``overflow_points`` the same per quantisation point (the OR of the writes into it).
    Output fields also read as attributes (``result.x1``).
    """

    outputs: MappingProxyType
    overflow: np.ndarray
    sticky: np.ndarray
    state: ModelState
    overflow_sites: MappingProxyType
    overflow_points: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))

    def __getattr__(self, name):
        try:
            return self.__dict__["outputs"][name]
        except KeyError:
            raise AttributeError(name) from None


def _array(values, dtype):
    """``values`` (ints, int64 or Python-int arrays) as an array of ``dtype``."""
    a = np.asarray(values)
    return a.astype(dtype) if a.dtype != dtype else a


def _narrow(a, width):
    """``a`` as int64 when values of ``width`` bits fit it, else as Python ints (``dtype=object``)."""
    return a.astype(np.int64) if width <= 63 else a.astype(object)


class FixedModel:
    """The bit-accurate filter of one variant for one config.

    Parameters
    ----------
    config:
        The :class:`~kfpga.core.config.FilterConfig` (default: the paper's filter, default formats).
    variant:
        One of the filter's variants (default: its first).
    """

    def __init__(self, config=None, *, variant=None):
        self.config = FilterConfig() if config is None else config
        self.spec = self.config.spec
        self.variant = self.spec.default_variant if variant is None else variant
        self.config.require_variant(self.variant)
        self._v = self.spec.model.variants[self.variant]
        self.inputs = self.config.inputs
        self.outputs = self.config.output_names
        self.state = self._v.state_for(self.config.params)
        self.state_names = tuple(name for name, _ in self.state)
        self.reset = self.config.reset_state(self.variant)
        self.constants = self.config.constants(self.variant)
        self._kernels = {}

    # -- compiled loops --------------------------------------------------------------------
    def kernel(self, vector=False, *, predict=False):
        """The compiled loop (see :func:`kfpga.core.compiled.compile_stage`); built on first use.
        ``predict``: the loop of samples with no measurement (the variant's ``predict``)."""
        key = (vector, predict)
        if key not in self._kernels:
            update = self._v.update
            if predict:
                coast = self.require_predict()

                def update(ops, k, x, u):
                    return coast(ops, k, x)
                update.__name__ = coast.__name__
            self._kernels[key] = compile_stage(
                update, self.config.formats, constants=self.constants, state=self.state,
                inputs=tuple((name, self.config.input_format) for name in self.inputs), outputs=self.outputs, vector=vector)
        return self._kernels[key]

    @property
    def predicts(self):
        """Whether the variant takes samples with no measurement (``run(..., missing=)``)."""
        return self._v.predict is not None

    def require_predict(self):
        """The variant's ``predict``; ``ValueError`` naming the filter when it has none."""
        if self._v.predict is None:
            raise ValueError(f"the {self.spec.name} filter's {self.variant} variant takes every sample as a "
                             "measurement: it has no update without one (missing samples do not apply)")
        return self._v.predict

    def initial_state(self, batch_shape=()):
        """The state after reset, for one channel or a batch."""
        if batch_shape == ():
            return ModelState(MappingProxyType(dict(self.reset)), False)
        points = dict(self.state)
        values = {n: _narrow(np.full(batch_shape, v, dtype=object), self.config.point_format(points[n]).width)
                  for n, v in self.reset.items()}
        return ModelState(MappingProxyType(values), np.zeros(batch_shape, dtype=bool))

    def _codes(self, y):
        """The input codes as ``{input name: int64 array}``, checked."""
        if not isinstance(y, dict):
            if len(self.inputs) != 1:
                raise TypeError(f"y must map each input ({', '.join(self.inputs)}) to its codes, not {type(y).__name__}")
            y = {self.inputs[0]: y}
        if set(y) != set(self.inputs):
            raise ValueError(f"y must give the inputs {', '.join(self.inputs)}, not {', '.join(y)}")
        out = {}
        for name in self.inputs:
            a = np.asarray(y[name])
            if a.dtype.kind not in "iu":
                raise TypeError(f"{name} must hold integer ADC codes, not {a.dtype}")
            fmt = self.config.input_format
            if a.size and (a.min() < fmt.min_raw or a.max() > fmt.max_raw):
                what = "the signed 16-bit ADC range" if fmt == CODE_FORMAT else f"the signed {fmt.width}-bit inputs"
                raise ValueError(f"{name} must be within {what} [{fmt.min_raw}, {fmt.max_raw}]")
            out[name] = a.astype(np.int64)
        shapes = {a.shape for a in out.values()}
        if len(shapes) != 1:
            raise ValueError(f"the inputs must have one shape, not {', '.join(map(str, shapes))}")
        return out

    def run(self, y, state=None, *, missing=None):
        """Filter raw ADC codes ``y`` (shape ``(n,)``, or ``(..., n)`` for a batch; time last).

        ``y`` is an array for a one-input filter, else ``{input name: array}``. ``state``
        continues a previous run (its :attr:`ModelResult.state`); by default every channel
        starts from the reset state. ``missing``: booleans shaped like ``y`` (one channel),
        true where a sample has no measurement: that update only predicts (its codes are not
        read). Nothing passed in is changed.
        """
        if missing is not None:
            mask = np.asarray(missing, dtype=bool)
            if mask.any():
                return self._run_missing(y, state, mask)
        return self._run(y, state)

    def _run_missing(self, y, state, mask):
        """:meth:`run` with samples that have no measurement: the runs of measured and of missing
        samples each through their own compiled loop, the state carried from one to the next."""
        self.require_predict()
        codes = self._codes(y)
        first = next(iter(codes.values()))
        if first.ndim != 1 or mask.shape != first.shape:
            raise ValueError(f"missing must be one flag per sample of one channel, shape {first.shape}, "
                             f"not {mask.shape}")
        cuts = [0, *(np.flatnonzero(mask[1:] != mask[:-1]) + 1).tolist(), len(mask)]
        parts = []
        for lo, hi in itertools.pairwise(cuts):
            part = self._run({name: a[lo:hi] for name, a in codes.items()}, state, predict=bool(mask[lo]))
            parts.append(part)
            state = part.state
        outputs = {name: np.concatenate([p.outputs[name] for p in parts]) for name in self.outputs}

        def joined(attr):
            names = dict.fromkeys(name for p in parts for name in getattr(p, attr))
            return {name: np.concatenate([getattr(p, attr).get(name, np.zeros(len(p.overflow), dtype=bool))
                                          for p in parts]) for name in names}
        return ModelResult(MappingProxyType(outputs), np.concatenate([p.overflow for p in parts]),
                           np.concatenate([p.sticky for p in parts]), state, MappingProxyType(joined("overflow_sites")),
                           MappingProxyType(joined("overflow_points")))

    def _run(self, y, state, *, predict=False):
        codes = self._codes(y)
        first = next(iter(codes.values()))
        n = first.shape[-1]
        batch = first.shape[:-1]
        state = self.initial_state(batch) if state is None else state
        regs = [state.values[name] for name in self.state_names]
        sticky0 = np.asarray(state.sticky, dtype=bool)
        if first.ndim == 1:
            k = self.kernel(False, predict=predict)
            outs = [[0] * n for _ in self.outputs]
            sites = [[] for _ in k.sites]
            columns = [codes[name].tolist() for name in self.inputs]
            ys = columns[0] if len(columns) == 1 else list(zip(*columns, strict=True))
            final = k.function(ys, *regs, *outs, *(s.append for s in sites))
            arrays = [np.array(o, dtype=np.int64 if self.output_format(name).width <= 63 else object)
                      for o, name in zip(outs, self.outputs, strict=True)]
            flags = []
            for hits in sites:
                f = np.zeros(n, dtype=bool)
                f[hits] = True
                flags.append(f)
        else:
            # time first while running: each step then writes contiguous rows
            k = self.kernel(True, predict=predict)
            arrays = [np.empty((n, *batch), dtype=k.dtype) for _ in self.outputs]
            flags = [np.zeros((n, *batch), dtype=bool) for _ in k.sites]
            ys = [np.moveaxis(codes[name], -1, 0).astype(k.dtype) for name in self.inputs]
            final = k.function(ys, *(_array(r, k.dtype) for r in regs), *arrays, *flags)
            if k.wide:
                arrays = [_narrow(a, self.output_format(name).width) for a, name in zip(arrays, self.outputs, strict=True)]
                final = [_narrow(np.asarray(v, dtype=object), self.config.point_format(point).width)
                         for v, (_, point) in zip(final, self.state, strict=True)]
        overflow = np.zeros((n, *batch), dtype=bool)
        for f in flags:
            overflow |= f
        sticky = np.logical_or.accumulate(overflow, axis=0) | sticky0 if n else overflow.copy()
        end = ModelState(MappingProxyType(dict(zip(self.state_names, final, strict=True))),
                         sticky[-1].copy() if n else sticky0)
        site_flags = {}
        for name, f in zip(k.sites, flags, strict=True):
            site_flags[name] = site_flags[name] | f if name in site_flags else f
        if first.ndim > 1:
            arrays = [np.moveaxis(a, 0, -1) for a in arrays]
            overflow, sticky = np.moveaxis(overflow, 0, -1), np.moveaxis(sticky, 0, -1)
            site_flags = {name: np.moveaxis(f, 0, -1) for name, f in site_flags.items()}
        point_flags = {}
        for name, f in site_flags.items():
            point = k.site_points[name]
            point_flags[point] = point_flags[point] | f if point in point_flags else f
        return ModelResult(MappingProxyType(dict(zip(self.outputs, arrays, strict=True))), overflow, sticky, end,
                           MappingProxyType(site_flags), MappingProxyType(point_flags))

    def run_ops(self, y, state=None, *, missing=None):
        """The same as :meth:`run`, through :class:`~kfpga.core.ops.IntOps` one sample at a time (slow)."""
        return self._step(IntOps, lambda ops, v: v.raw, y, state, missing)

    def run_exact(self, y, *, missing=None):
        """The exact-rational spec (:class:`~kfpga.core.ops.FractionOps`), one channel, from reset.

        Every value is a ``Fraction`` written once into its point's format: no shift, alignment
        or rounding code is shared with :meth:`run`, only the equations. Very slow; for tests.
        """
        return self._step(FractionOps, lambda ops, v: ops.raw_of(v), y, None, missing)

    def _step(self, backend, raw_of, y, state, missing=None):
        codes = self._codes(y)
        first = next(iter(codes.values()))
        state = self.initial_state(first.shape[:-1]) if state is None else state
        points = dict(self.state)
        x = dict(state.values)
        if first.ndim > 1:  # a batch on Python ints: the direct backend is exact at any width too
            codes = {name: a.astype(object) for name, a in codes.items()}
            x = {name: np.asarray(v).astype(object) for name, v in x.items()}
        outs = {name: [] for name in self.outputs}
        overflow = []
        for t in range(first.shape[-1]):
            ops = backend(self.config.formats)
            k = ops.constants(self.constants)
            xs = {name: ops.input(x[name], points[name], name) for name in self.state_names}
            u = {name: ops.input(codes[name][..., t], self.config.input_format, name) for name in self.inputs}
            if missing is not None and missing[t]:
                nxt, o = self.require_predict()(ops, k, xs)
            else:
                nxt, o = self._v.update(ops, k, xs, u)
            x = {name: raw_of(ops, nxt[name]) for name in self.state_names}
            for name in self.outputs:
                outs[name].append(raw_of(ops, o[name]))
            overflow.append(ops.overflow())
        arrays = {name: np.moveaxis(_narrow(np.array(v, dtype=object), self.output_format(name).width), 0, -1)
                  for name, v in outs.items()}
        if first.ndim > 1:
            x = {name: _narrow(np.asarray(v, dtype=object), self.config.point_format(points[name]).width)
                 for name, v in x.items()}
        ovf = np.moveaxis(np.array(overflow, dtype=bool), 0, -1)
        sticky = np.logical_or.accumulate(ovf, axis=-1) | np.asarray(state.sticky, dtype=bool)[..., None]
        end = ModelState(MappingProxyType(x), sticky[..., -1].copy())
        return ModelResult(MappingProxyType(arrays), ovf, sticky, end, MappingProxyType({}))

    def run_channels(self, y, channel, states=None, *, missing=None):
        """Filter an interleaved multi-channel stream: each channel keeps its own state.

        Returns ``(outputs, overflow, states)``: ``{field: raw array}`` and the per-sample flag
        in input order, and a new ``{channel: ModelState}`` (``states`` is not changed);
        ``missing`` as in :meth:`run`, in input order.
        """
        codes = self._codes(y)
        channel = np.asarray(channel)
        missing = np.zeros(len(channel), dtype=bool) if missing is None else np.asarray(missing, dtype=bool)
        n = len(channel)
        states = dict(states or {})
        outs = {name: np.zeros(n, dtype=np.int64) for name in self.outputs}
        overflow = np.zeros(n, dtype=bool)
        for ch in np.unique(channel):
            idx = np.flatnonzero(channel == ch)
            res = self.run({name: a[idx] for name, a in codes.items()}, states.get(int(ch)), missing=missing[idx])
            states[int(ch)] = res.state
            for name in self.outputs:
                outs[name][idx] = res.outputs[name]
            overflow[idx] = res.overflow
        return outs, overflow, states

    def output_format(self, name):
        return self.config.output_format(name)

    def to_float(self, result):
        """``{output: float array}`` of a result, in input units."""
        return {name: self.output_format(name).to_float(result.outputs[name]) for name in self.outputs}
