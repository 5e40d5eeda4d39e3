"""The shared configuration: model parameters and the format of every quantisation point.

One :class:`KalmanConfig` drives the bit-accurate model (``model/kalman.py``) and the RTL
(``hw/kalman.py``). It is built from defaults, a TOML file or keyword arguments, and it is
validated at once: a bad value raises :class:`ConfigError` naming the field and the value.

Default formats come from range analysis (``model/ranges.py``): integer bits cover the largest
magnitude a float run reaches, plus one guard bit; multiplier operands are 18 bits wide (Cyclone
II's embedded multipliers are 18x18). See :data:`POINTS` for what each point is.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kfpga.fixed import INT64_SAFE_BITS, QFormat, Rounding, bits_for
from kfpga.model.ranges import analyse_ranges
from kfpga.model.reference import KalmanParams, steady_state_gain

__all__ = ["ConfigError", "Point", "POINTS", "VARIANTS", "INPUT_FORMAT", "KalmanConfig", "default_formats"]

VARIANTS = ("steady", "full")
#: The ADS8364's output word: a signed 16-bit integer code.
INPUT_FORMAT = QFormat(16, 0)
#: Cyclone II embedded multiplier operand width.
MULTIPLIER_BITS = 18
#: Default fraction bits of registers that are not multiplier operands.
STATE_FRAC_BITS = 8
GUARD_BITS = 1


class ConfigError(ValueError):
    """A configuration value is invalid; the message names the field and the value."""


@dataclass(frozen=True)
class Point:
    """A quantisation point of the datapath."""

    name: str
    description: str
    variants: tuple
    operand: bool = False  # feeds an embedded multiplier: at most 18 bits
    constant: bool = False  # holds only constants: no guard bit needed


POINTS = {
    p.name: p
    for p in (
        Point("x1", "filtered position x1 (state, output)", VARIANTS),
        Point("xl1", "predicted position xl1 = x1 + v (output yhat)", VARIANTS),
        Point("v", "rate per sample v = T*x2 (state)", VARIANTS),
        Point("x2", "rate output x2 = v / T", VARIANTS),
        Point("e", "innovation e = y - xl1", VARIANTS, operand=True),
        Point("gain", "gains K1, T*K2 (constants, or the divider's quotients)", VARIANTS, operand=True),
        Point("p", "covariance p11, p12, p21, p22 (state)", ("full",)),
        Point("pl", "predicted covariance pl11..pl22", ("full",), operand=True),
        Point("s", "innovation covariance S = pl11 + R (divisor)", ("full",)),
        Point("inv_t", "1/T, when T is not a power of two", VARIANTS, operand=True, constant=True),
        Point("vt", "rate operand of x2 = v * (1/T), when T is not a power of two", VARIANTS, operand=True),
    )
}


def t_exponent(T):
    """``k`` if ``T == 2**k`` exactly, else ``None``."""
    mantissa, exponent = math.frexp(T)
    return exponent - 1 if mantissa == 0.5 else None


def analysed_ranges(params, stimulus=None):
    """Largest magnitude of each point over both variants (one config serves both)."""
    ranges = analyse_ranges(params, "steady", stimulus) if params.Q > 0 else {}
    for name, value in analyse_ranges(params, "full", stimulus).items():
        ranges[name] = max(value, ranges.get(name, 0.0))
    ranges["x1"] = max(ranges["x1"], ranges["xl1"])
    if t_exponent(params.T) is None:
        ranges["inv_t"] = 1.0 / params.T
        ranges["vt"] = ranges["v"]
    return ranges


def default_formats(params=None, *, ranges=None, operand_bits=MULTIPLIER_BITS, state_frac=STATE_FRAC_BITS):
    """Formats chosen by range analysis: analysed range + guard bit, operands ``operand_bits`` wide.

    A multiplier operand whose integer bits plus guard would leave it no fraction bit gives up
    the guard bit instead (the innovation ``e`` of a full-scale step is such a case); its
    saturation still raises the overflow flag.
    """
    params = KalmanParams() if params is None else params
    ranges = analysed_ranges(params) if ranges is None else ranges
    formats = {}

    def integer_bits(name, frac):
        point = POINTS[name]
        need = bits_for(ranges[name], frac)
        return need if point.constant else need + GUARD_BITS

    def operand_format(name):
        # integer bits for an operand_bits-wide word: the fraction bits shrink as they grow
        need = next(i for i in range(1, 64) if QFormat(i, max(operand_bits - i, 0)).covers(ranges[name]))
        guard = 0 if POINTS[name].constant else GUARD_BITS
        if need + guard > operand_bits - 1:
            guard = 0  # no room: keep the fraction bit, let saturation (flagged) cover the rest
        i = need + guard
        return QFormat(i, max(operand_bits - i, 0), Rounding.HALF_UP)

    for name in ("e", "gain", "pl", "inv_t", "vt"):
        if name in ranges:
            formats[name] = operand_format(name)
    frac_p = formats["pl"].frac_bits if "pl" in formats else 0
    for name, frac in (("x1", state_frac), ("v", state_frac), ("p", frac_p), ("s", frac_p)):
        if name in ranges:
            formats[name] = QFormat(integer_bits(name, frac), frac, Rounding.HALF_UP)
    formats["xl1"] = formats["x1"]
    k = t_exponent(params.T)
    fv = formats["v"]
    if k is not None and fv.int_bits - k >= 1 and fv.frac_bits + k >= 0:
        # x2 = v / 2**k: the same bits, the binary point moved (a free shift)
        formats["x2"] = QFormat(fv.int_bits - k, fv.frac_bits + k, Rounding.HALF_UP)
    else:
        formats["x2"] = QFormat(integer_bits("x2", state_frac), state_frac, Rounding.HALF_UP)
    return {name: formats[name] for name in POINTS if name in formats}


@dataclass(frozen=True)
class KalmanConfig:
    """Model parameters plus the format of every quantisation point; validated on creation.

    Parameters
    ----------
    params:
        The model (T, Q, R, P0, x0).
    formats:
        ``{point name: QFormat}``; points left out get their default from range analysis.
    check_ranges:
        Check each format against the analysed range (on by default; word-length sweeps turn
        it off to show what narrow formats do).
    max_operand_bits:
        Widest multiplier operand allowed (18: Cyclone II's embedded multipliers).
    """

    params: KalmanParams = field(default_factory=KalmanParams)
    formats: dict = field(default_factory=dict)
    check_ranges: bool = True
    max_operand_bits: int = MULTIPLIER_BITS

    def __post_init__(self):
        _validate_params(self.params)
        given = dict(self.formats)
        for name, fmt in given.items():
            if name not in POINTS:
                raise ConfigError(f"formats.{name}: unknown quantisation point; known: {', '.join(POINTS)}")
            if not isinstance(fmt, QFormat):
                raise ConfigError(f"formats.{name} must be a QFormat, not {fmt!r}")
        merged = default_formats(self.params)
        merged.update(given)
        object.__setattr__(self, "formats", {name: merged[name] for name in POINTS if name in merged})
        self._validate_formats()

    # -- derived quantities -------------------------------------------------------------
    @property
    def t_shift(self):
        """``k`` if ``T = 2**k`` (x2 = v >> k is a shift), else ``None`` (a constant multiply)."""
        return t_exponent(self.params.T)

    @property
    def steady_gain(self):
        """Float ``(K1, T*K2)`` of the steady-state filter, in datapath units."""
        (k1, k2), _ = steady_state_gain(self.params.T, self.params.Q, self.params.R)
        return k1, k2 * self.params.T

    def ranges(self):
        return analysed_ranges(self.params)

    # -- validation -------------------------------------------------------------------------
    def _validate_formats(self):
        f = self.formats
        for name, fmt in f.items():
            point = POINTS[name]
            if point.operand and fmt.width > self.max_operand_bits:
                raise ConfigError(
                    f"formats.{name} = {fmt} is {fmt.width} bits wide, but it feeds an embedded multiplier "
                    f"and Cyclone II's take at most {MULTIPLIER_BITS}x{MULTIPLIER_BITS} bits"
                )
        if self.check_ranges:
            ranges = self.ranges()
            for name in sorted(set(f) & set(ranges)):
                fmt = f[name]
                if not fmt.covers(ranges[name]):
                    raise ConfigError(
                        f"formats.{name} = {fmt} covers ±{fmt.max_value:g}, but the analysed range of "
                        f"{POINTS[name].description} reaches ±{ranges[name]:.6g}: it needs at least "
                        f"{bits_for(ranges[name], fmt.frac_bits)} integer bits"
                    )
        for desc, (width, names) in _intermediate_widths(f).items():
            if width > INT64_SAFE_BITS:
                involved = ", ".join(f"formats.{n} = {f[n]}" for n in names)
                raise ConfigError(
                    f"{desc} is {width} bits wide with {involved}; products and sums must stay within "
                    f"{INT64_SAFE_BITS} bits to be held exactly: narrow these formats"
                )
        divider_shift = f["gain"].frac_bits + f["s"].frac_bits - f["pl"].frac_bits
        if divider_shift < 0:
            raise ConfigError(
                f"formats: gain.frac_bits + s.frac_bits - pl.frac_bits = {divider_shift} must be >= 0 "
                f"so that the divider's dividend pl * 2**(...) is an exact integer"
            )
        scaled = self.params.scaled()
        for label, value, name in (
            ("R", self.params.R, "s"),
            ("T^2*Q", scaled.Q, "pl"),
            ("P0", np.max(np.abs(scaled.P0)), "p"),
            ("x0[0]", abs(scaled.x0[0]), "x1"),
            ("T*x0[1]", abs(scaled.x0[1]), "v"),
        ):
            if not f[name].covers(value):
                raise ConfigError(f"model.{label} = {value:g} does not fit formats.{name} = {f[name]} (max {f[name].max_value:g})")
        if f["s"].lsb / 2 > self.params.R:
            raise ConfigError(
                f"model.R = {self.params.R:g} rounds to 0 in formats.s = {f['s']} (LSB {f['s'].lsb:g}): "
                "the divisor S = pl11 + R could be 0; give s more fraction bits"
            )

    # -- TOML ---------------------------------------------------------------------------
    @classmethod
    def from_toml(cls, path):
        """Load a config file (see README for the layout)."""
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text())
        except FileNotFoundError:
            raise ConfigError(f"{path}: no such config file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not valid TOML: {exc}") from None
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_dict(cls, data, *, source="config"):
        unknown = set(data) - {"model", "formats"}
        if unknown:
            raise ConfigError(f"{source}: unknown section(s) {', '.join(sorted(unknown))}; expected [model] and [formats.*]")
        model = dict(data.get("model", {}))
        known = {"T", "Q", "R", "P0", "x0"}
        for key in model:
            if key not in known:
                raise ConfigError(f"{source}: unknown key model.{key}; known: {', '.join(sorted(known))}")
        for key in ("T", "Q", "R"):
            if key in model and (not isinstance(model[key], (int, float)) or isinstance(model[key], bool)):
                raise ConfigError(f"model.{key} must be a number, not {model[key]!r}")
        try:
            params = KalmanParams(**model)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{source}: model.P0 must be a 2x2 array and model.x0 a pair of numbers ({exc})") from None
        formats = {}
        for name, spec in dict(data.get("formats", {})).items():
            formats[name] = _format_from_toml(name, spec)
        return cls(params=params, formats=formats)

    def to_toml(self):
        """The config as TOML text, every format spelled out."""
        p = self.params
        lines = [
            "# kfpga configuration: model parameters and the format of every quantisation point.",
            "# Formats are Q<integer bits incl. sign>.<fraction bits>.",
            "[model]",
            f"T = {p.T!r}",
            f"Q = {p.Q!r}",
            f"R = {p.R!r}",
            f"P0 = [[{p.P0[0][0]!r}, {p.P0[0][1]!r}], [{p.P0[1][0]!r}, {p.P0[1][1]!r}]]",
            f"x0 = [{p.x0[0]!r}, {p.x0[1]!r}]",
        ]
        for name, fmt in self.formats.items():
            lines += [
                "",
                f"[formats.{name}]  # {POINTS[name].description}",
                f'format = "{fmt}"',
                f'rounding = "{fmt.rounding.value}"',
                f'overflow = "{fmt.overflow.value}"',
            ]
        return "\n".join(lines) + "\n"

    def require_variant(self, variant):
        if variant not in VARIANTS:
            raise ConfigError(f"variant must be one of {', '.join(VARIANTS)}, not {variant!r}")
        if variant == "steady" and not self.params.Q > 0:
            raise ConfigError(f"model.Q = {self.params.Q!r}: the steady-state variant needs Q > 0 (Q = 0 gives K_inf = 0)")


def _format_from_toml(name, spec):
    if isinstance(spec, str):
        spec = {"format": spec}
    if not isinstance(spec, dict):
        raise ConfigError(f"formats.{name} must be a string like \"Q18.8\" or a table, not {spec!r}")
    unknown = set(spec) - {"format", "int_bits", "frac_bits", "rounding", "overflow"}
    if unknown:
        raise ConfigError(f"formats.{name}: unknown key(s) {', '.join(sorted(unknown))}")
    try:
        rules = {k: spec[k] for k in ("rounding", "overflow") if k in spec}
        if "format" in spec:
            fmt = QFormat.parse(spec["format"], **rules)
        elif "int_bits" in spec and "frac_bits" in spec:
            fmt = QFormat(spec["int_bits"], spec["frac_bits"], **rules)
        else:
            raise ValueError("give format = \"Q<int>.<frac>\" or both int_bits and frac_bits")
    except ValueError as exc:
        raise ConfigError(f"formats.{name}: {exc}") from None
    return fmt


def _validate_params(p):
    if not isinstance(p, KalmanParams):
        raise ConfigError(f"params must be a KalmanParams, not {p!r}")
    if not (math.isfinite(p.T) and p.T > 0):
        raise ConfigError(f"model.T must be > 0, not {p.T!r}")
    if not (math.isfinite(p.Q) and p.Q >= 0):
        raise ConfigError(f"model.Q must be >= 0, not {p.Q!r}")
    if not (math.isfinite(p.R) and p.R > 0):
        raise ConfigError(f"model.R must be > 0, not {p.R!r}")
    p0 = np.array(p.P0, dtype=np.float64)
    if p0.shape != (2, 2) or not np.all(np.isfinite(p0)):
        raise ConfigError(f"model.P0 must be a finite 2x2 matrix, not {p.P0!r}")
    if p0[0, 1] != p0[1, 0]:
        raise ConfigError(f"model.P0 must be symmetric, not {p.P0!r}")
    if not np.all(np.linalg.eigvalsh(p0) > 0):
        raise ConfigError(f"model.P0 must be positive definite, not {p.P0!r} (eigenvalues {np.linalg.eigvalsh(p0)})")
    if len(p.x0) != 2 or not all(math.isfinite(v) for v in p.x0):
        raise ConfigError(f"model.x0 must be two finite numbers, not {p.x0!r}")


def _intermediate_widths(f):
    """``{description: (width in bits, points involved)}`` of each exact sum and product formed."""

    def aligned(*names):
        # every term is a point's format or a product of two; a sum carries one bit per addition
        terms = []
        for name in names:
            a, _, b = name.partition("*")
            fa = f[a] if a != "y" else INPUT_FORMAT
            terms.append((fa.int_bits + f[b].int_bits, fa.frac_bits + f[b].frac_bits) if b else (fa.int_bits, fa.frac_bits))
        frac = max(fb for _, fb in terms)
        ints = max(ib for ib, _ in terms) + len(terms) - 1
        return ints + frac

    sums = {
        "the sum xl1 = x1 + v": ("x1", "v"),
        "the difference y - xl1": ("y", "xl1"),
        "the sum x1 = xl1 + K1*e": ("xl1", "gain*e"),
        "the sum v = v + K2*e": ("v", "gain*e"),
        "the sum p = pl - K*pl": ("pl", "gain*pl"),
        "the sum pl11 = p11 + p12 + p21 + p22": ("p", "p", "p", "p"),
        "the sum S = pl11 + R": ("pl", "s"),
    }
    out = {desc: (aligned(*names), sorted({n.partition("*")[0] for n in names} | {n.partition("*")[2] for n in names} - {"", "y"}))
           for desc, names in sums.items()}
    g, pl, s = f["gain"], f["pl"], f["s"]
    out["the divider's dividend"] = (pl.width + g.frac_bits + s.frac_bits - pl.frac_bits + 1, ["gain", "pl", "s"])
    out["the divider's comparison"] = (s.width + g.width, ["gain", "s"])
    return out
