"""Stream payloads of every core, derived from its filter's spec: inputs, outputs, channel field."""

from __future__ import annotations

from amaranth import signed, unsigned
from amaranth.lib import data

__all__ = ["channel_bits", "input_layout", "output_layout"]


def channel_bits(channels):
    """Bits of the channel field: as many as ``channels`` need, at least one.

    One channel needs none, but a zero-width field becomes a ``wire [-1:0]`` in Verilog, which
    Verilog-2001 tools reject; one bit (always 0) is the narrowest legal field.
    """
    return max(1, (channels - 1).bit_length())


def input_layout(config, channels, bits=None, *, missing=False):
    """``channel`` (``bits`` wide, default :func:`channel_bits`) and one signed field per input of
    the filter (``y`` for one input): 16 bits, the ADC's code, or the config's wider input format;
    with ``missing``, a last bit that marks a sample with no measurement (its codes are not read)."""
    fields = {"channel": unsigned(channel_bits(channels) if bits is None else bits)}
    fields.update({name: signed(config.input_format.width) for name in config.inputs})
    if missing:
        fields["missing"] = unsigned(1)
    return data.StructLayout(fields)


def output_layout(config, channels, bits=None):
    """``channel``, every output field in its point's format, and the sample's ``overflow`` flag."""
    fields = {"channel": unsigned(channel_bits(channels) if bits is None else bits)}
    fields.update({o.name: signed(config.output_format(o.name).width) for o in config.outputs})
    fields["overflow"] = 1
    return data.StructLayout(fields)
