"""The ADC's codes, the input of every filter: one conversion result of the ADS8364 is a signed
16-bit integer (the numbers the model and the cores take in; the converter's timing, which only the
hardware and its benches need, is in ``hw/ads8364_timing.py``).

# Ref: Texas Instruments SBAS219C, "ADS8364: 250kSPS, 16-bit, 6-channel simultaneous sampling
#      ADC"; [Zhong], section 4.2.1.
"""

from __future__ import annotations

from kfpga.core.fixed import QFormat

__all__ = ["OUTPUT_CODING", "CODE_FORMAT", "CODE_MIN", "CODE_MAX"]

#: Output coding: 16-bit binary two's complement ([Zhong] 4.2.1: "the MSB is the sign bit";
#: the sibling ADS8361's table, SBAS230E, lists 7FFFh..8000h for +FS..-FS).
OUTPUT_CODING = "twos_complement"
#: One conversion result as a fixed-point value: a signed 16-bit integer code.
CODE_FORMAT = QFormat(16, 0)
#: The code range, -32768..32767.
CODE_MIN, CODE_MAX = CODE_FORMAT.min_raw, CODE_FORMAT.max_raw
