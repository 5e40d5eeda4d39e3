"""The register values of a programmable core for new parameters (``kfpga regs``).

A programmable core (a folded core with a bus, ``hw/regmap.py``) keeps its formats and its
update's shape; what changes at run time are its settings: the constants quantised into a
configurable point (the steady gain K, the F entries that are not shifts, the Q and R terms,
1/T) and the states' reset values (x0, P0). :func:`settings_for` takes the core's config and new
parameters, solves the model again in those formats (the steady gain from the Riccati equation,
as the config does), checks that the new model has the core's shape and that every value fits
its point, and gives each setting's integer and the digits the bus writes.
"""

from __future__ import annotations

from dataclasses import dataclass

from kfpga.core.errors import ConfigError
from kfpga.core.fixed import to_raw
from kfpga.core.spec import Constant
from kfpga.hw.microcode import compile_update, programmable_names, to_digits
from kfpga.hw.regmap import CONTROL, CONTROL_BITS, SETTINGS_BASE, register_map

__all__ = ["SettingValue", "settings_for", "bus_writes", "program_for", "new_config"]


@dataclass(frozen=True)
class SettingValue:
    """A setting's new value: the :class:`~kfpga.hw.microcode.Setting`, the real value asked for,
    the integer in its format, the real value that integer stands for, and the digits."""

    setting: object
    value: float
    raw: int
    held: float
    digits: tuple


def program_for(config, variant, *, missing=False):
    """The program of the programmable core of ``config``'s ``variant`` (its settings and map)."""
    return compile_update(config, variant, predict=missing, programmable=True)


def new_config(config, variant, params):
    """``config`` with new ``params`` in the core's formats; :class:`ConfigError` when the new model
    does not have the core's shape (a structural constant, a shift or a zero entry, differs)."""
    spec_variant = config.spec.model.variants[variant]
    why = spec_variant.applies(params)
    if why:
        raise ConfigError(why)
    try:
        new_c = spec_variant.constants(params)
    except (ValueError, TypeError, ArithmeticError) as exc:
        raise ConfigError(f"the new parameters: {exc}") from None
    old_c = config.constants(variant)
    if set(old_c) != set(new_c):
        gone, added = sorted(set(old_c) - set(new_c)), sorted(set(new_c) - set(old_c))
        what = "; ".join(x for x in (f"no longer has {', '.join(gone)}" if gone else "",
                                      f"has {', '.join(added)} that the core has not" if added else "") if x)
        raise ConfigError(f"the new model has another shape than the core's (it {what}): a zero entry, or one "
                          "that became 0, is built into the core; generate a core for it")
    settable = set(programmable_names(config, variant)[0])
    for name, c in old_c.items():
        if name in settable:
            continue
        other = new_c[name]
        same = (isinstance(c, Constant) and isinstance(other, Constant) and c.value == other.value
                and c.point == other.point) if isinstance(c, Constant) else c == other
        if not same:
            label = c.label if isinstance(c, Constant) and c.label else name
            raise ConfigError(f"{label} is built into the core (a shift, an exact constant or the model's "
                              "structure) and the new parameters change it; generate a core for them")
    if [n for n, _ in spec_variant.state_for(params)] != [n for n, _ in spec_variant.state_for(config.params)]:
        raise ConfigError("the new model has other states than the core's")
    try:
        return config.replace(params=params, formats=config.formats)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"the new parameters do not fit the core's formats: {exc}") from None


def settings_for(config, variant, params, *, program=None):
    """Every setting's new value (:class:`SettingValue`, in the map's order) for ``params`` on the
    programmable core of ``config``; :class:`ConfigError` names a value that does not fit."""
    program = program or program_for(config, variant)
    new = new_config(config, variant, params)
    constants, reset = new.constants(variant), new.reset_state(variant)
    points = dict(new.spec.model.variants[variant].state_for(new.params))
    out = []
    for st in program.settings:
        if st.kind == "c":
            value = float(constants[st.name].value)
            raw, over = to_raw(value, st.fmt)
            if over:
                raise ConfigError(f"{st.label} = {value:.6g} does not fit formats.{st.point} = {st.fmt} "
                                  f"(at most {st.fmt.to_float(st.fmt.max_raw):.6g}): the core cannot take it")
        else:
            value = float(new.spec.model.variants[variant].initial(new.params)[st.name])
            raw, over = to_raw(value, new.point_format(points[st.name]))
            if over:
                raise ConfigError(f"the reset value {st.name} = {value:.6g} does not fit formats.{st.point} = {st.fmt}")
            if int(raw) != reset[st.name]:
                raise AssertionError("reset value quantised twice differently")
        raw = int(raw)
        out.append(SettingValue(st, value, raw, float(st.fmt.to_float(raw)), tuple(to_digits(raw, st.digits))))
    return out


def bus_writes(values, program, config, variant):
    """``[(word index, 32-bit value, register name)]``: the digits of every setting, then
    ``CONTROL.COMMIT`` (the values take effect between two updates)."""
    names = {r.index: r.name for r in register_map(program, config, variant)}
    out = []
    for sv in values:
        for dgt, d in enumerate(sv.digits):
            index = SETTINGS_BASE + sv.setting.shadow + dgt
            out.append((index, d & 0xFFFFFFFF, names[index]))
    out.append((CONTROL, 1 << CONTROL_BITS["COMMIT"], "CONTROL"))
    return out
