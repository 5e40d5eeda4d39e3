"""Checks shared by the filters' parameter dataclasses: ``TypeError`` for a wrong type,
``ValueError`` for a wrong value, each message starting with the field's name."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["number", "vector", "matrix", "check_measured_start", "USABLE", "MEASURED_LIMIT"]

#: The magnitudes a model number may have (besides 0): the fixed-point formats of wider spans
#: than this (100 orders of ten) cannot be held in 64-bit sums, and the float references lose
#: every digit of a sum of such terms.
USABLE = (1e-15, 1e15)

#: The largest start value of a state an observation measures, in ADC codes: four times the
#: 16-bit range (a start beyond it makes every format as wide as the start, for nothing).
MEASURED_LIMIT = 4 * 32768


def number(name, value, *, minimum=None, strict=False):
    """A finite real number, optionally ``>= minimum`` (``> minimum`` with ``strict``)."""
    if not isinstance(value, int | float | np.integer | np.floating) or isinstance(value, bool | np.bool_):
        raise TypeError(f"{name} must be a number, not {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, not {value!r}")
    if minimum is not None and (value <= minimum if strict else value < minimum):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {minimum:g}, not {value!r}")
    if value != 0 and not USABLE[0] <= abs(value) <= USABLE[1]:
        raise ValueError(f"{name} = {value:g} is outside the usable range: 0, or {USABLE[0]:g} to {USABLE[1]:g} in "
                         "magnitude")
    return value


def vector(name, value, length, *, each=None):
    """A tuple of ``length`` finite numbers (``each``: what one entry is for, named in the message)."""
    try:
        items = list(value)
    except TypeError:
        raise TypeError(f"{name} must be a list of {length} numbers, not {value!r}") from None
    if len(items) != length:
        per = f" (one per {each})" if each else ""
        raise ValueError(f"{name} must have {length} entries{per}, not {len(items)}: {value!r}")
    return tuple(number(f"{name}[{i}]", v) for i, v in enumerate(items))


def matrix(name, value, rows, cols, *, symmetric=False, positive_definite=False):
    """A ``rows x cols`` tuple of tuples of finite numbers, optionally symmetric positive definite."""
    try:
        lines = [list(r) for r in value]
    except TypeError:
        raise TypeError(f"{name} must be a {rows}x{cols} matrix (a list of rows), not {value!r}") from None
    if len(lines) != rows or any(len(r) != cols for r in lines):
        raise ValueError(f"{name} must be a {rows}x{cols} matrix, not {value!r}")
    out = tuple(tuple(number(f"{name}[{i}][{j}]", v) for j, v in enumerate(r)) for i, r in enumerate(lines))
    a = np.array(out)
    if symmetric and not np.array_equal(a, a.T):
        raise ValueError(f"{name} must be symmetric, not {value!r}")
    if positive_definite:
        eig = np.linalg.eigvalsh(a)
        if not np.all(eig > 0):
            raise ValueError(f"{name} must be positive definite, not {value!r} (eigenvalues {', '.join(f'{e:.4g}' for e in eig)})")
    return out


def check_measured_start(x0, h):
    """Refuse a start value of a measured state far beyond the ADC's range (``ValueError``
    naming ``x0[i]`` and the limit): a row of ``h`` with one nonzero entry ``h[j][i]`` measures
    state i, whose codes are then at most :data:`MEASURED_LIMIT` / ``|h[j][i]|``."""
    for row in h:
        nonzero = [i for i, v in enumerate(row) if v != 0]
        if len(nonzero) == 1:
            i = nonzero[0]
            limit = MEASURED_LIMIT / abs(row[i])
            if abs(x0[i]) > limit:
                raise ValueError(f"x0[{i}] = {x0[i]:g} is far beyond the ADC's range of the state an observation "
                                 f"measures (+-32768 codes): at most +-{limit:g}")
