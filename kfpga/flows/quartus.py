"""Quartus II 13.0sp1 project for the Cyclone II EP2C20Q240C8N: .qpf, .qsf, .sdc, manifest."""

from __future__ import annotations

import csv
import dataclasses
import importlib.metadata
import importlib.resources
import json
import re
from dataclasses import dataclass
from pathlib import Path
from string import Template

from kfpga import __version__
from kfpga.core.board import SYSTEM_MHZ, SYSTEM_PERIOD_NS
from kfpga.core.errors import InputError, PinError
from kfpga.core.paths import read_text
from kfpga.core.spec import Constant
from kfpga.hw.ads8364_timing import CHANNELS, figure
from kfpga.hw.generate import TOP_NAME, write_top
from kfpga.hw.top import PORTS, out_width, port_widths
from kfpga.hw.top import out_field as top_out_field

__all__ = ["FAMILY", "DEVICE", "DEVICE_ORDERING", "PinError", "PinRow", "load_pins", "port_bits", "check_pins", "io_timing",
           "write_project"]

FAMILY = "Cyclone II"
DEVICE = "EP2C20Q240C8"  # Quartus's name for the ordering code below
DEVICE_ORDERING = "EP2C20Q240C8N"
#: The skew bound for control outputs: half a system cycle (see the .sdc).
TCO_FRACTION = 0.5
BOARD_NS = 2.0
#: The assumed receiver of the filtered output bus (edit in the .sdc for a real one).
OUT_SETUP_NS, OUT_HOLD_NS = 5.0, 0.0
_PIN = re.compile(r"^PIN_(\d+)$")
#: Pins of the EP2C20Q240 (a 240-pin PQFP): PIN_1 .. PIN_240.
PACKAGE_PINS = 240


@dataclass(frozen=True)
class PinRow:
    port: str
    bit: int | None
    pin: str
    io_standard: str
    note: str
    line: int

    @property
    def target(self):
        return self.port if self.bit is None else f"{self.port}[{self.bit}]"


def _constraint_file(name):
    return importlib.resources.files("kfpga.constraints").joinpath(name)


def load_pins(path=None):
    """Rows of a pin table (default: ``constraints/pins.csv``); ``#`` lines are comments.

    A row whose pin is left empty is a bit still to be placed: :func:`check_pins` names it.
    """
    if path is None:
        text, label = _constraint_file("pins.csv").read_text(encoding="utf-8"), "constraints/pins.csv"
    else:
        try:
            text, label = read_text(path, what="pin table"), str(path)
        except InputError as exc:
            raise PinError(str(exc)) from None
    rows, header = [], None
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = next(csv.reader([line]))
        if header is None:
            header = [c.strip() for c in cells]
            if header[:4] != ["port", "bit", "pin", "io_standard"]:
                raise PinError(f"{label}: line {number}: the header must start with port,bit,pin,io_standard")
            continue
        if len(cells) < 4:
            raise PinError(f"{label}: line {number}: expected port,bit,pin,io_standard[,note]")
        port, bit, pin, standard = (c.strip() for c in cells[:4])
        if bit and not bit.isdigit():
            raise PinError(f"{label}: line {number}: bit must be empty or a number, not {bit!r}")
        match = _PIN.match(pin)
        if pin and not match:
            raise PinError(f"{label}: line {number}: pin must look like PIN_37, not {pin!r}")
        if match and not 1 <= int(match[1]) <= PACKAGE_PINS:
            raise PinError(f"{label}: line {number}: {pin} does not exist: the EP2C20Q240 has pins "
                           f"PIN_1..PIN_{PACKAGE_PINS}")
        rows.append(PinRow(port, int(bit) if bit else None, pin, standard or "3.3-V LVTTL",
                           cells[4].strip() if len(cells) > 4 else "", number))
    if not rows:
        raise PinError(f"{label}: the pin table has no rows")
    return rows


#: User I/O pins the built-in table keeps free for a wider ``out_data`` (bits 26 and up, in this
#: order): pins that Quartus II 13.0sp1 placed as 3.3-V LVTTL user I/O in a fit of the
#: EP2C20Q240C8 (its "Design Ports Information" table), none used by ``constraints/pins.csv``.
SPARE_OUT_PINS = (200, 232, 222, 230, 192, 237, 216, 236, 184, 195)
#: ``out_data`` bits the built-in table itself has rows for.
BUILTIN_OUT_BITS = 26


def board_rows(config, out_field=None, pins=None, sensors=1):
    """``(rows, label)`` of the pin table for this design: the file ``pins`` as it is, or the
    built-in table with ``out_data`` fitted to the field's width (rows beyond it dropped,
    :data:`SPARE_OUT_PINS` for bits past :data:`BUILTIN_OUT_BITS`), and for sensors on a
    multiplexer the spare pins left for the bits of ``out_channel`` past 3 and for ``mux_sel``
    (bits past the spare pins have no row: :func:`check_pins` names them)."""
    if pins is not None:
        return load_pins(pins), str(pins)
    width = out_width(config, out_field)
    rows = [r for r in load_pins() if r.port != "out_data" or r.bit < width]
    spare = list(SPARE_OUT_PINS)
    extra = [("out_data", bit) for bit in range(BUILTIN_OUT_BITS, width)]
    ports = port_widths(sensors)
    extra += [("out_channel", bit) for bit in range(PORTS["out_channel"][1], ports["out_channel"][1])]
    extra += [("mux_sel", bit) for bit in range(ports["mux_sel"][1])] if "mux_sel" in ports else []
    for (port, bit), pin in zip(extra, spare, strict=False):  # the bits past the spare pins have no row
        rows.append(PinRow(port, bit, f"PIN_{pin}", "3.3-V LVTTL", "spare user I/O of the built-in table", 0))
    return rows, "constraints/pins.csv"


def port_bits(config, out_field=None, sensors=1):
    """Every top-level port bit as ``(port, bit)`` (``bit`` None for 1-bit ports).

    ``out_data`` is as wide as the format of the output field on it (``out_field``); ``sensors``
    on a multiplexer add ``mux_sel`` and widen ``out_channel`` (:func:`~kfpga.hw.top.port_widths`).
    """
    bits = []
    for name, (_, width, _) in port_widths(sensors).items():
        width = out_width(config, out_field) if name == "out_data" else width
        bits += [(name, None)] if width == 1 else [(name, b) for b in range(width)]
    return bits


def check_pins(rows, config, label="pin table", out_field=None, sensors=1):
    """Map each port bit to its row; every bit exactly one pin, every pin used once."""
    wanted = set(port_bits(config, out_field, sensors))
    by_bit, by_pin = {}, {}
    for row in rows:
        key = (row.port, row.bit)
        if key not in wanted:
            raise PinError(f"{label}: line {row.line}: the design has no port bit {row.target}")
        if key in by_bit:
            raise PinError(f"{label}: line {row.line}: {row.target} already has {by_bit[key].pin} (line {by_bit[key].line})")
        if not row.pin:
            raise PinError(f"{label}: line {row.line}: {row.target} has no pin yet; give it one of your board's "
                           "free user I/O pins")
        if row.pin in by_pin:
            raise PinError(f"{label}: line {row.line}: {row.pin} is already used by {by_pin[row.pin].target}")
        by_bit[key], by_pin[row.pin] = row, row
    missing = [f"{p}[{b}]" if b is not None else p for p, b in port_bits(config, out_field, sensors)
               if (p, b) not in by_bit]
    if missing:
        raise PinError(f"{label}: no pin for {', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''} "
                       f"({len(missing)} port bit(s)); add rows for them")
    return by_bit


def pin_table(config, *, out_field=None, base=None, sensors=1):
    """The text of a pin table for this config: the rows of ``base`` (default: the built-in table)
    for every port bit the design has, and rows with an empty pin for bits it lacks.

    ``out_data`` follows the chosen field's width: a wider format needs rows the base table
    does not have (their pins are the user's to choose, as only the board says which are free),
    a narrower one drops rows.
    """
    rows, _ = board_rows(config, out_field, base, sensors)
    by_bit = {(r.port, r.bit): r for r in rows}
    lines = [
        f"# Pin table of {TOP_NAME} on the {DEVICE_ORDERING} for the {config.filter} filter, out_data = "
        f"{top_out_field(config, out_field)} ({out_width(config, out_field)} bits).",
        "# Edit it for your board: one row per port bit (bit empty for 1-bit ports). A row with an empty pin",
        "# still needs one of the board's free user I/O pins; kfpga generate refuses the table until it has one.",
        "port,bit,pin,io_standard,note",
    ]
    for port, bit in port_bits(config, out_field, sensors):
        row = by_bit.get((port, bit))
        if row is None:
            lines.append(f"{port},{'' if bit is None else bit},,3.3-V LVTTL,choose a free user I/O pin")
        else:
            note = f'"{row.note}"' if "," in row.note else row.note
            lines.append(f"{port},{'' if bit is None else bit},{row.pin},{row.io_standard},{note}")
    return "\n".join(lines) + "\n"


def _sdc_values(ratio):
    sys_period = SYSTEM_PERIOD_NS
    adc_period = sys_period * ratio
    if adc_period < figure("tC1") - 1e-9:
        raise PinError(f"--ratio {ratio} makes the ADC clock {1000 / adc_period:.3g} MHz; the ADS8364 allows "
                       f"{1000 / figure('tC1'):.3g} MHz at most (tC1 = {figure('tC1'):g} ns)")
    budget = sys_period * TCO_FRACTION
    return {
        "sys_mhz": f"{SYSTEM_MHZ:g}", "sys_period": f"{sys_period:.3f}", "ratio": ratio,
        "ratio_minus_1": ratio - 1, "ratio_minus_2": ratio - 2,
        "adc_mhz": f"{1000 / adc_period:g}", "adc_period": f"{adc_period:g}", "tc1": f"{figure('tC1'):g}",
        "td9": f"{figure('tD9'):g}", "addr_setup": f"{adc_period - sys_period:g}", "tco_budget": f"{budget:g}",
        "ctl_out_max": f"{sys_period - budget:.3f}", "tacc": f"{figure('tACC'):g}", "board": f"{BOARD_NS:g}",
        "data_in_max": f"{budget + figure('tACC') + BOARD_NS:.3f}",
        "out_setup": f"{OUT_SETUP_NS:.3f}", "out_hold": f"{OUT_HOLD_NS:.3f}",
        "out_min": f"{-OUT_HOLD_NS:.3f}" if OUT_HOLD_NS else "0.000",
    }


def _port_groups(ports):
    """``(control, outputs)``: the ADC's control outputs (timed against its clock) and the design's
    outputs (the output port and the multiplexer's select, timed as the output port)."""
    control = [n for n in ports if n.startswith("adc_") and ports[n][0] == "out" and n != "adc_clk"]
    outputs = [n for n in ports if n.startswith("out_") or n == "mux_sel"]
    return control, outputs


def io_timing(ratio=10, sensors=1):
    """The .sdc's I/O constraints as :func:`kfpga.hw.timing.analyse` takes them."""
    values = _sdc_values(ratio)
    control, outputs = _port_groups(port_widths(sensors))
    return {
        "period_ns": SYSTEM_PERIOD_NS,
        "input_delays": {"adc_data": float(values["data_in_max"])},
        "multicycle": {"adc_data": ratio - 1},
        "output_delays": {**dict.fromkeys(control, float(values["ctl_out_max"])),
                          **dict.fromkeys(outputs, float(values["out_setup"]))},
    }


def write_project(out_dir, config, *, variant=None, six_channel=False, channel=None, ratio=10, pins=None,
                  out_field=None, prefilter=None, architecture=None, stages=None, timing=None, sensors=1):
    """Write the Verilog and a complete Quartus II project into ``out_dir``; returns the manifest.
    ``prefilter``: the config of a filter between the controller and the core, or ``None``;
    ``architecture``, ``stages``: the core's (default: the parallel one where it runs); ``timing``:
    what the design's estimate says of the clock, recorded in the manifest; ``sensors``: more
    than one on a multiplexer in front of the ADC."""
    out_dir = Path(out_dir)
    variant = config.spec.default_variant if variant is None else variant
    out_field = top_out_field(config, out_field)
    rows, label = board_rows(config, out_field, pins, sensors)
    assigned = check_pins(rows, config, label, out_field, sensors)
    values = _sdc_values(ratio)
    verilog, top = write_top(out_dir, config, variant=variant, six_channel=six_channel, channel=channel, ratio=ratio,
                             out_field=out_field, prefilter=prefilter, architecture=architecture, stages=stages,
                             sensors=sensors)
    data_bits = out_width(config, out_field)
    ports = port_widths(sensors)
    control, outputs = _port_groups(ports)

    def port_list(names):
        return " ".join(f"{n}[*]" if (ports[n][1] or data_bits) != 1 else n for n in names)

    sdc = Template(_constraint_file("kfpga_top.sdc.in").read_text()).substitute(
        top=TOP_NAME, version=__version__, control_ports=port_list(control), output_ports=port_list(outputs),
        **values)
    (out_dir / f"{TOP_NAME}.sdc").write_text(sdc)

    pin_lines = []
    for _, row in sorted(assigned.items(), key=lambda kv: (list(ports).index(kv[0][0]), kv[0][1] or 0)):
        pin_lines.append(f"set_location_assignment {row.pin} -to {row.target}")
        pin_lines.append(f'set_instance_assignment -name IO_STANDARD "{row.io_standard}" -to {row.target}')
    qsf = Template(_constraint_file("kfpga_top.qsf.in").read_text()).substitute(
        top=TOP_NAME, version=__version__, pin_table=label, device=DEVICE, device_ordering=DEVICE_ORDERING,
        family=FAMILY, verilog=verilog.name, sdc=f"{TOP_NAME}.sdc", pins="\n".join(pin_lines))
    (out_dir / f"{TOP_NAME}.qsf").write_text(qsf)
    (out_dir / f"{TOP_NAME}_pins.tcl").write_text(f"# The pins of {TOP_NAME} ({label}), for FuseSoC's Quartus target\n"
                                                  + "\n".join(pin_lines) + "\n")
    (out_dir / f"{TOP_NAME}.core").write_text(board_fusesoc(config, verilog.name))
    (out_dir / f"{TOP_NAME}.qpf").write_text(
        f'# Quartus II project (kfpga {__version__})\nQUARTUS_VERSION = "13.0"\nPROJECT_REVISION = "{TOP_NAME}"\n')

    manifest = _manifest(config, variant, top, verilog, assigned, ports, out_field, data_bits, values,
                         six_channel=six_channel, sensors=sensors, ratio=ratio, prefilter=prefilter, timing=timing)
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    (out_dir / "README.txt").write_text(_readme(variant, six_channel, ratio, manifest))
    return manifest


def _manifest(config, variant, top, verilog, assigned, ports, out_field, data_bits, values, *, six_channel, sensors,
              ratio, prefilter, timing):
    """The project's ``manifest.json``: what was generated, from what, with which formats, ports and pins."""
    core = top.core
    manifest = {
        "generator": {"kfpga": __version__, "amaranth": importlib.metadata.version("amaranth")},
        "top": TOP_NAME, "family": FAMILY, "device": DEVICE, "device_ordering_code": DEVICE_ORDERING,
        "filter": config.filter, "variant": variant, "channels": 6 if six_channel else sensors,
        "sensors": sensors if sensors > 1 else None,
        "channel": None if six_channel else CHANNELS[top.channel],
        "adc_channels": None if six_channel else {name: CHANNELS[c] for name, c in zip(config.inputs, top.adc,
                                                                                      strict=True)},
        "out_data": {"field": out_field, "format": str(config.output_format(out_field)),
                     "width": data_bits},
        "clocks": {"system_mhz": SYSTEM_MHZ, "adc_mhz": float(values["adc_mhz"]), "ratio": ratio},
        "model": _jsonable(dataclasses.asdict(config.params)),
        "formats": {name: {"format": str(f), "width": f.width, "rounding": f.rounding.value,
                           "overflow": f.overflow.value} for name, f in config.formats.items()},
        "core": {"architecture": top.architecture, "stages": getattr(core, "stages", None),
                 "latency_cycles": core.latency, "cycles_per_update": core.cycles_per_update},
        "sample_rate_hz": config.board.actual_rate_hz(sensors),
        "conversion_cycles": config.board.conversion_cycles(sensors),
        "timing": timing,
        "prefilter": None if prefilter is None else {
            "filter": prefilter.filter, "model": _jsonable(dataclasses.asdict(prefilter.params)),
            "latency_cycles": top.prefilter.latency, "delay_samples": prefilter.spec.hardware.prefilter.delay,
            "channels": top.prefilter.channels},
        "controller": {"states": 22, "timeout_clk_periods": top.frontend.controller.timeout_periods},
        "ports": [{"name": n, "direction": d, "width": data_bits if n == "out_data" else w,
                   "pins": [assigned[(n, b)].pin for p, b in port_bits(config, out_field, sensors) if p == n],
                   "description": desc}
                  for n, (d, w, desc) in ports.items()],
        "files": sorted([verilog.name, f"{TOP_NAME}.qsf", f"{TOP_NAME}.sdc", f"{TOP_NAME}.qpf", "manifest.json",
                         "README.txt", "verilator_lint.vlt", f"{TOP_NAME}.core", f"{TOP_NAME}_pins.tcl"]),
    }
    raws = config.constant_raw(variant)
    manifest["constants"] = {name: {"value": c.value, "raw": raws[name],
                                    "format": str(config.formats[c.point] if isinstance(c.point, str) else c.point)}
                             for name, c in config.constants(variant).items() if isinstance(c, Constant)}
    return manifest


#: The board testbench's files that FuseSoC's simulation target takes from ``tb/`` (written by
#: ``kfpga generate`` with :func:`kfpga.sim.testbench.write_testbench`).
BOARD_TB_FILES = ("kfpga_tb.v", "ads8364_model.v")
BOARD_TB_DATA = ("codes.hex", "expected.hex")


def board_fusesoc(config, verilog):
    """``kfpga_top.core``: FuseSoC (CAPI2) for the board's design: the RTL, a ``synth`` target for
    Quartus with the device, the .sdc and the pins, and a ``sim`` target running the
    self-checking testbench of ``tb/`` on Icarus (default) or Verilator."""
    from kfpga.flows.coreip import fusesoc_core

    vlnv = f"kfpga:board:{TOP_NAME}"
    return fusesoc_core(
        vlnv=f"{vlnv}:1.0.0",
        comments=[f"FuseSoC core file of the board's design (kfpga {__version__}): {config.filter} filter on the "
                  f"{DEVICE_ORDERING}.",
                  f"  fusesoc --cores-root . run --target synth {vlnv}     (Quartus II)",
                  f"  fusesoc --cores-root . run --target sim {vlnv}       (Icarus; --tool verilator)"],
        description=f"{config.filter} filter, ADS8364 controller and clock divider for the {DEVICE_ORDERING}",
        rtl=[verilog], top=TOP_NAME, tb=[f"tb/{name}" for name in BOARD_TB_FILES], tb_top="kfpga_tb",
        data=[f"tb/{name}" for name in BOARD_TB_DATA],
        filesets=f"""  constraints:
    files:
      - {TOP_NAME}.sdc: {{file_type: SDC}}
      - {TOP_NAME}_pins.tcl: {{file_type: tclSource}}
""",
        targets=f"""  synth:
    default_tool: quartus
    filesets: [rtl, constraints]
    toplevel: {TOP_NAME}
    tools:
      quartus:
        family: {FAMILY}
        device: {DEVICE}
""")


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    return value


def _readme(variant, six_channel, ratio, manifest):
    adc = manifest["adc_channels"]
    sensors = manifest.get("sensors")
    where = "all six channels" if six_channel else (
        f"{sensors} sensors taking turns on channel {manifest['channel']} through an analog multiplexer (its select "
        f"on mux_sel, the sensor of each estimate on out_channel)" if sensors else
        f"channel {manifest['channel']}" if len(adc) == 1 else
        "channels " + ", ".join(f"{c} ({name})" for name, c in adc.items()) + ", one update per conversion")
    out = manifest["out_data"]
    rate = (f"a conversion every {manifest['conversion_cycles']} system cycles ({manifest['sample_rate_hz']:g} Hz"
            + (" each" if sensors else "") + ")"
            if manifest["sample_rate_hz"] else "the ADC converting as fast as the core takes samples")
    est = manifest.get("timing")
    timing = "" if not est else (
        f"\nEstimated Fmax {est['fmax_mhz_estimate']:g} MHz on the -8 part (Yosys and FloPoCo's delays, no place and "
        f"route)" + (": BELOW the clock, written anyway (--ignore-timing)" if est.get("ignored") else "") + ".")
    return f"""kfpga {__version__}: Quartus II 13.0sp1 project for the {DEVICE_ORDERING} (Cyclone II)

Design: ADS8364 controller + {manifest['filter']} filter, {variant} variant on the {manifest['core']['architecture']} core,
{where}, ADC clock = 50 MHz / {ratio}, {rate}.
out_data: {out['field']}, {out['format']} ({out['width']} bits).
Core latency {manifest['core']['latency_cycles']} cycles, {manifest['core']['cycles_per_update']} cycle(s) per update.{timing}

Compile (Quartus II 13.0sp1 is the last Quartus with Cyclone II):

    quartus_sh --flow compile {TOP_NAME}

Timing report:

    quartus_sta {TOP_NAME}

Files:
  {TOP_NAME}.v       the design, plain Verilog-2001
  {TOP_NAME}.qsf     device, top entity, sources, pins (from the pin table)
  {TOP_NAME}.sdc     clocks and I/O timing (the reasons are in its comments)
  {TOP_NAME}.qpf     the project
  manifest.json      formats, parameters, ports and pins, latency, generator version
  verilator_lint.vlt the lint waivers of the generated Verilog, each explained

Pins come from constraints/pins.csv; to use your own board, copy it, edit it and run
`kfpga generate ... --pins my_pins.csv`.
"""
