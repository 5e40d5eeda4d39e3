"""The register map of a programmable core, written once: its SystemRDL, C header and Markdown.

A folded core built with a bus (``bus="avalon"`` or ``"axi4lite"``, :class:`~kfpga.hw.folded.FoldedCore`)
has the registers below; :func:`register_map` describes them for one program, :func:`systemrdl`
writes that description as SystemRDL, and :func:`export` compiles it with the SystemRDL compiler
and writes the C header (PeakRDL ``cheader``) and the Markdown table (PeakRDL ``markdown``) from
it. The core's decoder (``hw/folded.py``) and ``kfpga regs`` read the same :class:`Register` list,
so the three never disagree.

Every register is 32 bits; Avalon-MM addresses words (``avs_address`` = offset / 4), AXI4-Lite
bytes. A setting (a constant of the update, or a state's reset value) is held in *digits*: the
register-file words of radix 2**17 the microcode reads (``hw/microcode.py``), the lower digits
``0 .. 2**17 - 1`` and the top one signed 18 bits (sign-extended to 32 on the bus). Writes to the
settings go to shadow words and take effect when ``CONTROL.COMMIT`` is written: the core copies
them between two updates, never inside one, and records the update count in ``COMMITTED``; the
first sample taken after that runs with them. The reset values take effect at the next
``CONTROL.RESET`` (after a commit).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Register", "register_map", "identity", "identity_text", "systemrdl", "export", "SETTINGS_BASE",
           "VERSION", "COUNT_BITS", "COUNTER_BITS", "counters_base", "CONTROL_BITS", "STATUS_BITS", "ID", "INFO",
           "CONTROL", "STATUS", "UPDATES", "OVERFLOWS", "COMMITTED"]

#: The map's version, in ``INFO``.
VERSION = 1
#: The word index of the first setting's first digit (the fixed registers are below).
SETTINGS_BASE = 16
#: Bits of the counters UPDATES, OVERFLOWS and COMMITTED (a 16-bit counter costs half a 32-bit one's
#: logic cells; UPDATES and COMMITTED wrap, and are read as differences modulo 2**16).
COUNT_BITS = 16
#: Word indices of the fixed registers.
ID, INFO, CONTROL, STATUS, UPDATES, OVERFLOWS, COMMITTED = range(7)
#: ``CONTROL``'s bits (write 1 to act; a read gives the commit and reset still pending).
CONTROL_BITS = {"COMMIT": 0, "RESET": 1, "CLEAR": 2}
#: ``STATUS``'s bits.
STATUS_BITS = {"COMMIT_PENDING": 0, "RESET_PENDING": 1, "OVERFLOW": 2, "RUNNING": 3, "CLEAR_PENDING": 4}
#: Bits of an overflow counter (a register-file word's low digit).
COUNTER_BITS = 17


def counters_base(program):
    """The word index of the first overflow counter: after the settings."""
    return SETTINGS_BASE + program.shadow_words


@dataclass(frozen=True)
class Register:
    """One 32-bit register: its name, word index, access (``r``, ``w``, ``rw``), description and
    fields ``((name, lsb, width, description), ...)``; ``setting``/``digit``: the setting and the
    digit it holds (a settings register)."""

    name: str
    index: int
    access: str
    description: str
    fields: tuple = ()
    setting: object = None
    digit: int = 0

    @property
    def title(self):
        """A short name: the description up to its first colon or parenthesis."""
        cut = min((i for i in (self.description.find(":"), self.description.find(" (")) if i > 0),
                  default=len(self.description))
        return self.description[:cut]

    @property
    def offset(self):
        """Its byte offset."""
        return 4 * self.index


def identity_text(config, variant):
    """What ``ID`` hashes: the filter, the variant and every format (a core with other widths has
    another ID)."""
    formats = " ".join(f"{name}={fmt}" for name, fmt in sorted(config.formats.items()))
    return f"{config.spec.name} {variant} input={config.input_format} {formats}"


def identity(config, variant):
    """``ID``: the CRC-32 of :func:`identity_text`."""
    return zlib.crc32(identity_text(config, variant).encode())


def _c_name(text):
    out = "".join(ch if ch.isalnum() else "_" for ch in text).strip("_").upper()
    return out or "X"


def register_map(program, config, variant):
    """The :class:`Register` list of a programmable core of ``program``."""
    regs = [
        Register("ID", 0, "r", f"Identity: CRC-32 of the filter, variant and formats ({config.spec.name}, {variant})",
                 (("ID", 0, 32, "CRC-32 of the identity text"),)),
        Register("INFO", 1, "r", "The map's version, the channels and the settings' digits",
                 (("VERSION", 0, 8, "register map version"), ("CHANNELS", 8, 8, "channel states less one"),
                  ("DIGITS", 16, 16, "settings digits (registers from SETTINGS_BASE)"))),
        Register("CONTROL", 2, "rw", "Write 1 to act, between two updates; reads the actions still pending",
                 (("COMMIT", 0, 1, "copy the written settings in before the next update"),
                  ("RESET", 1, 1, "run the reset routine of every channel (from the committed reset values)"),
                  ("CLEAR", 2, 1, "clear UPDATES, OVERFLOWS, COMMITTED, the OVF counters and STATUS.OVERFLOW"))),
        Register("STATUS", 3, "r", "The core's state",
                 (("COMMIT_PENDING", 0, 1, "a commit waits for the end of an update"),
                  ("RESET_PENDING", 1, 1, "a reset waits"),
                  ("OVERFLOW", 2, 1, "an estimate saturated (or wrapped) since CLEAR"),
                  ("RUNNING", 3, 1, "a routine runs"),
                  ("CLEAR_PENDING", 4, 1, "the counters' clear waits"))),
        Register("UPDATES", 4, "r", f"Samples taken since CLEAR (wraps at 2**{COUNT_BITS})",
                 (("COUNT", 0, COUNT_BITS, "samples"),)),
        Register("OVERFLOWS", 5, "r", f"Estimates with the overflow flag since CLEAR (holds at 2**{COUNT_BITS} - 1)",
                 (("COUNT", 0, COUNT_BITS, "estimates"),)),
        Register("COMMITTED", 6, "r", "UPDATES when the last commit took effect: that sample and the later ones "
                 "ran with the new settings", (("COUNT", 0, COUNT_BITS, "samples"),)),
    ]
    for st in program.settings:
        what = "constant" if st.kind == "c" else "reset value of state"
        for dgt in range(st.digits):
            top = dgt == st.digits - 1
            name = f"{'K' if st.kind == 'c' else 'X0'}_{_c_name(st.name)}_D{dgt}"
            regs.append(Register(
                name, SETTINGS_BASE + st.shadow + dgt, "w",
                f"{what} {st.name} ({st.label}, {st.fmt}): digit {dgt} of {st.digits}, "
                + ("signed 18 bits" if top else "bits [16:0] of its 17-bit slice"),
                (("DIGIT", 0, 18 if top else 17, "the digit"),), st, dgt))
    base = counters_base(program)
    for j, point in enumerate(program.counters):
        regs.append(Register(f"OVF_{_c_name(str(point))}", base + j, "r",
                             f"Writes into point {point} that saturated (or wrapped) since CLEAR (wraps at "
                             f"2**{COUNTER_BITS})", (("COUNT", 0, COUNTER_BITS, "writes"),), point))
    return regs


def systemrdl(regs, name="kfpga_regs"):
    """The SystemRDL of ``regs``: one ``addrmap`` of 32-bit registers."""
    sw = {"r": "r", "w": "w", "rw": "rw"}
    lines = [f"addrmap {name} {{", '    name = "kfpga programmable core";',
             "    default regwidth = 32;", "    default accesswidth = 32;"]
    for reg in regs:
        lines.append("    reg {")
        lines.append(f'        desc = "{_rdl_text(reg.description)}";')
        for field, lsb, width, desc in reg.fields:
            hw = "hw = w;" if "r" in reg.access and reg.access != "rw" else "hw = r;"
            if reg.access == "rw":
                lines.append(f'        field {{ sw = rw; hw = rw; singlepulse; desc = "{_rdl_text(desc)}"; }} '
                             f"{field}[{lsb + width - 1}:{lsb}] = 0;")
            else:
                lines.append(f'        field {{ sw = {sw[reg.access]}; {hw} desc = "{_rdl_text(desc)}"; }} '
                             f"{field}[{lsb + width - 1}:{lsb}];")
        lines.append(f"    }} {reg.name} @ 0x{reg.offset:X};")
    lines.append("};")
    return "\n".join(lines) + "\n"


def _rdl_text(text):
    return text.replace("\\", "\\\\").replace('"', "'")


def export(regs, out_dir, name="kfpga_regs"):
    """Write ``NAME.rdl``, the C header ``NAME.h`` and the Markdown table ``NAME.md`` (both from the
    compiled SystemRDL, through PeakRDL) under ``out_dir``; returns their paths."""
    from peakrdl_cheader.exporter import CHeaderExporter
    from peakrdl_markdown import MarkdownExporter
    from systemrdl import RDLCompiler

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rdl = out_dir / f"{name}.rdl"
    rdl.write_text(systemrdl(regs, name))
    compiler = RDLCompiler()
    compiler.compile_file(str(rdl))
    root = compiler.elaborate(name)
    header, table = out_dir / f"{name}.h", out_dir / f"{name}.md"
    CHeaderExporter().export(root.top, str(header))
    MarkdownExporter().export(root.top, str(table), rename=name)
    return rdl, header, table
