"""The whole design with its ADS8364 in the simulator: the Verilog model, its wrappers, and the
files they read and write.

``sim/ads8364_model.v`` models the ADC with every datasheet timing check, clocked by the system
clock, so a co-simulation needs no call into Python per pin edge. Two wrappers put it next to
the generated ``kfpga_top``:

* :func:`cosim_wrapper` (``kfpga_cosim``, run by :mod:`kfpga.sim.system`): the six codes of each
  conversion stream in from ``codes.hex``; every read the ADC serves and every estimate on the
  output port stream out to ``reads.txt`` and ``outputs.txt``, which Python compares with the
  bit-accurate model after the run; ``summary.txt`` says how it ended. Its clock comes from
  ``cosim_main.cpp`` on Verilator and from :func:`clock_top` on Icarus.
* the self-checking testbench of ``kfpga testbench`` (:mod:`kfpga.sim.testbench`).
* :func:`check_harness`, which drives the model from a pin script for its own tests.

Both set the model's timing parameters from :data:`kfpga.hw.ads8364_timing.TIMING`.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from kfpga.core.board import SYSTEM_PERIOD_NS
from kfpga.hw.ads8364_timing import TIMING, figure

__all__ = ["MODEL_FILE", "MODEL_NAME", "COSIM_NAME", "ERRORS", "STATUS", "model_parameters", "model_instance",
           "dut_instance", "write_model", "cosim_wrapper", "clock_top", "write_codes", "read_log", "error_text",
           "CHECK_NAME", "check_harness"]

MODEL_FILE = "ads8364_model.v"
MODEL_NAME = "kfpga_ads8364_model"
COSIM_NAME = "kfpga_cosim"

#: The model's violation numbers (E_* in ads8364_model.v): the figure each checks and what it is.
ERRORS = {
    1: ("tC1", "CLK period below the minimum"),
    2: ("tW1", "CLK low time below the minimum"),
    3: ("tW1", "CLK high time below the minimum"),
    4: ("tHOLDL", "HOLDx low width below the minimum"),
    5: ("tHOLDH", "HOLDx high width between conversions below the minimum"),
    6: ("tD2", "HOLDx fell too soon after RESET rose"),
    7: ("", "HOLDx fell while RESET is low"),
    8: ("", "HOLDx fell during a conversion"),
    9: ("tW4", "RESET low width below the minimum"),
    10: ("", "A2..A0 changed while RD is low"),
    11: ("", "A2..A0 changed in the same instant RD rose"),
    12: ("tRDL", "RD low width below the minimum"),
    13: ("", "WR went low: the controller must not write to the ADC"),
    14: ("tD9", "A2..A0 setup before RD falls below the minimum"),
    15: ("", "address 110/111 (cycle/FIFO mode) is not used by this controller"),
}


def error_text(code, at_ns=None):
    symbol, text = ERRORS.get(int(code), ("", f"unknown violation {code}"))
    where = f" at {at_ns} ns" if at_ns is not None else ""
    return f"ADS8364{where}: {text}" + (f" ({symbol})" if symbol else "")


def model_parameters(sample_ns=SYSTEM_PERIOD_NS):
    """The model's parameters, in ns, from :data:`TIMING` (the CLK-period figures at 200 ns)."""
    ns = {"TC1_NS": "tC1", "TW1_NS": "tW1", "THOLDL_NS": "tHOLDL", "THOLDH_NS": "tHOLDH", "TW4_NS": "tW4",
          "TD2_NS": "tD2", "TD9_NS": "tD9", "TRDL_NS": "tRDL", "TACC_NS": "tACC"}
    out = {"SAMPLE_NS": int(sample_ns), "CONV_CLOCKS": int(TIMING["tCONV"].value)}
    for name, symbol in ns.items():
        value = figure(symbol)
        if value != int(value):
            raise ValueError(f"{symbol} = {value} ns: the Verilog model takes whole nanoseconds")
        out[name] = int(value)
    return out


def write_model(out_dir):
    """Copy ``ads8364_model.v`` into ``out_dir``; returns its path."""
    path = Path(out_dir) / MODEL_FILE
    path.write_text(resources.files("kfpga.sim").joinpath(MODEL_FILE).read_text())
    return path


def model_instance(indent="    "):
    """The instance of the model on the ``adc_*`` wires, with its parameters."""
    params = ",\n".join(f"{indent}    .{k}({v})" for k, v in model_parameters().items())
    return f"""{indent}{MODEL_NAME} #(
{params}
{indent}) adc (
{indent}    .clk(clk50), .adc_clk(adc_clk), .hold_a_n(adc_hold_a_n), .hold_b_n(adc_hold_b_n),
{indent}    .hold_c_n(adc_hold_c_n), .reset_n(adc_reset_n), .wr_n(adc_wr_n), .cs_n(adc_cs_n), .rd_n(adc_rd_n),
{indent}    .addr(adc_addr), .eoc_n(adc_eoc_n), .data(adc_data), .next_codes(next_codes), .take(take),
{indent}    .read_strobe(read_strobe), .read_channel(read_channel), .read_code(read_code),
{indent}    .read_conversion(read_conversion), .conversions(conversions), .eoc_pulses(eoc_pulses),
{indent}    .errors(errors), .first_error(first_error), .first_error_ns(first_error_ns)
{indent});"""


def dut_instance(top, out_width, indent="    ", sensors=1):
    """The generated top level on wires of the same names (with ``mux_sel`` and a wider
    ``out_channel`` for ``sensors`` on a multiplexer; ``mux_sel`` reads 0 without one)."""
    from kfpga.hw.top import port_widths

    ports = port_widths(sensors)
    sel = f"{indent}wire [{ports['mux_sel'][1] - 1}:0] mux_sel;\n" if sensors > 1 else f"{indent}wire [0:0] mux_sel = 1'b0;\n"
    return f"""{indent}wire adc_clk, adc_hold_a_n, adc_hold_b_n, adc_hold_c_n, adc_eoc_n, adc_cs_n, adc_rd_n, adc_wr_n;
{indent}wire adc_byte, adc_add, adc_reset_n, out_valid, out_overflow, out_timeout;
{indent}wire [2:0] adc_addr;
{indent}wire [{ports['out_channel'][1] - 1}:0] out_channel;
{sel}
{indent}wire [15:0] adc_data;
{indent}wire signed [{out_width - 1}:0] out_data;
{indent}{top} dut (
{indent}    .clk50(clk50), .rst_n(rst_n), .adc_clk(adc_clk), .adc_hold_a_n(adc_hold_a_n),
{indent}    .adc_hold_b_n(adc_hold_b_n), .adc_hold_c_n(adc_hold_c_n), .adc_eoc_n(adc_eoc_n), .adc_cs_n(adc_cs_n),
{indent}    .adc_rd_n(adc_rd_n), .adc_wr_n(adc_wr_n), .adc_byte(adc_byte), .adc_add(adc_add),
{indent}    .adc_reset_n(adc_reset_n), .adc_addr(adc_addr), .adc_data(adc_data), .out_data(out_data),
{indent}    .out_channel(out_channel), .out_valid(out_valid), .out_overflow(out_overflow), .out_timeout(out_timeout)""" + (
        ", .mux_sel(mux_sel)" if sensors > 1 else "") + f"""
{indent});
{indent}wire [95:0] next_codes;
{indent}wire take, read_strobe;
{indent}wire [2:0] read_channel;
{indent}wire [15:0] read_code;
{indent}wire [31:0] read_conversion, conversions, eoc_pulses, errors;
{indent}wire [7:0] first_error;
{indent}wire [63:0] first_error_ns;"""


#: Why a run of ``kfpga_cosim`` ended (the last field of its summary line).
STATUS = {0: "done", 1: "an ADS8364 timing violation", 2: "the ADC ran out of codes", 3: "the cycle limit"}


#: ``kfpga_cosim``, a ``str.format`` template (``{{`` and ``}}`` are Verilog's braces).
_COSIM_WRAPPER = """// The whole design with the ADS8364 model and file I/O, for the fast regressions
// (kfpga/sim/system.py). Generated by kfpga; see sim/hdl.py.
`timescale 1ns / 1ps
`default_nettype none
module {cosim_name} (
    input wire clk
);
    wire clk50 = clk;
    reg rst_n = 1'b0;
{dut}
{model}

    // codes.hex: one conversion per line, six 16-bit codes in hex (channel 0 first)
    integer fc, fr, fo, fs, got;
    reg [15:0] c0, c1, c2, c3, c4, c5;
    reg [95:0] codes_q = 96'd0;
    reg [8*1024:1] dir;
    reg [63:0] want, max_cycles, step, cycle = 0, n_out = 0, n_reads = 0;
    reg exhausted = 1'b0;
    reg signed [63:0] out_value, read_value, read_origin;
    reg [63:0] sel_at_hold = 0;
    assign next_codes = codes_q;
    initial begin
        if (!$value$plusargs("samples=%d", want)) want = 1000;
        if (!$value$plusargs("max_cycles=%d", max_cycles)) max_cycles = 1000 * want + 100000;
        if (!$value$plusargs("progress=%d", step)) step = 0;
        if (!$value$plusargs("dir=%s", dir)) dir = ".";
        fc = $fopen({{dir, "/codes.hex"}}, "r");
        fr = $fopen({{dir, "/reads.txt"}}, "w");
        fo = $fopen({{dir, "/outputs.txt"}}, "w");
        fs = $fopen({{dir, "/summary.txt"}}, "w");
        if (fc == 0 || fr == 0 || fo == 0 || fs == 0) begin
            $display("kfpga_cosim: cannot open the files in %0s", dir);
            $finish;
        end
        got = $fscanf(fc, "%h %h %h %h %h %h\\n", c0, c1, c2, c3, c4, c5);
        codes_q = {{c5, c4, c3, c2, c1, c0}};
    end

    task finish;
        input integer status;
        begin
            // n_out n_reads conversions eoc_pulses errors first_error first_error_ns exhausted
            // out_overflow out_timeout cycles time_ns status
            $fwrite(fs, "%0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d %0d\\n", n_out + out_valid,
                    n_reads + read_strobe, conversions,
                    eoc_pulses, errors, first_error, first_error_ns, exhausted, out_overflow, out_timeout, cycle,
                    $time, status);
            $fclose(fr);
            $fclose(fo);
            $fclose(fs);
            $finish;
        end
    endtask

    always @(posedge clk50) begin
        cycle <= cycle + 1;
        if (cycle == 3) rst_n <= 1'b1;
        if (take) begin
            sel_at_hold <= mux_sel;  // the sensor the multiplexer gives this conversion
            got = $fscanf(fc, "%h %h %h %h %h %h\\n", c0, c1, c2, c3, c4, c5);
            if (got != 6) exhausted <= 1'b1;
            codes_q <= {{c5, c4, c3, c2, c1, c0}};
        end
        // reads.txt: time (ns) channel code conversion mux_sel-at-its-HOLD; outputs.txt: time channel
        // value sticky-overflow
        if (read_strobe) begin
            read_value = $signed(read_code);
            read_origin = $signed(read_conversion);
            $fwrite(fr, "%0d %0d %0d %0d %0d\\n", $time, read_channel, read_value, read_origin, sel_at_hold);
            n_reads <= n_reads + 1;
        end
        if (out_valid) begin
            // through 64-bit signed variables: Verilator 5.048 printed a 26-bit $signed() argument of %d wrongly
            out_value = out_data;
            $fwrite(fo, "%0d %0d %0d %0d\\n", $time, out_channel, out_value, out_overflow);
            n_out <= n_out + 1;
            if (step != 0 && (n_out + 1) % step == 0) begin
                $display("progress %0d", n_out + 1);
                $fflush;
            end
        end
        if (out_valid && n_out + 1 >= want) finish(0);
        else if (errors != 0) finish(1);
        else if (exhausted) finish(2);
        else if (cycle >= max_cycles) finish(3);
    end
endmodule
`default_nettype wire
"""


def cosim_wrapper(top, out_width, sensors=1):
    """``kfpga_cosim``: the design and the ADC model with file I/O, for the fast regressions
    (:mod:`kfpga.sim.system`); its only port is the system clock.

    Plusargs: ``+samples=N`` (stop after the N-th estimate), ``+max_cycles=N`` (stop there: a
    design that stops answering ends the run), ``+progress=N`` (print ``progress K`` every N
    estimates), ``+dir=PATH`` (the folder of ``codes.hex``, where ``reads.txt``, ``outputs.txt``
    and ``summary.txt`` are written). The design is in reset for the first 4 cycles.
    """
    return _COSIM_WRAPPER.format(cosim_name=COSIM_NAME, dut=dut_instance(top, out_width, sensors=sensors),
                                 model=model_instance())


def clock_top(top=COSIM_NAME):
    """``<top>_clock``: ``top`` with its clock, for an event-driven simulator (Icarus)."""
    half = SYSTEM_PERIOD_NS / 2
    return f"""// The system clock for {top} in an event-driven simulator. Generated by kfpga.
`timescale 1ns / 1ps
module {top}_clock;
    reg clk = 1'b0;
    always #{half:g} clk = ~clk;
    {top} dut (.clk(clk));
endmodule
"""


def write_codes(path, codes):
    """``codes.hex``: the (conversions, 6) signed codes, one conversion per line, in hex."""
    # as bytes built with numpy (four hex digits and a separator per code): a million
    # conversions in a fraction of a second, where formatting each code takes seconds
    codes = np.asarray(codes, dtype=np.int64).reshape(-1, 6) & 0xFFFF
    digits = np.frombuffer(b"0123456789abcdef", dtype=np.uint8)
    out = np.empty((codes.shape[0], 6, 5), dtype=np.uint8)
    for j, shift in enumerate((12, 8, 4, 0)):
        out[:, :, j] = digits[(codes >> shift) & 0xF]
    out[:, :, 4] = ord(" ")
    out[:, -1, 4] = ord("\n")
    Path(path).write_bytes(out.tobytes())


def read_log(path, columns):
    """A log the wrappers write (whitespace-separated integers) as an ``(n, columns)`` int64 array."""
    text = Path(path).read_text()
    # numpy's C parser: splitting in Python costs seconds per million lines
    values = np.fromstring(text, dtype=np.int64, sep=" ") if text.strip() else np.zeros(0, dtype=np.int64)
    if values.size % columns:
        raise ValueError(f"{path}: {values.size} numbers, not a multiple of {columns}")
    return values.reshape(-1, columns)


CHECK_NAME = "kfpga_adc_check"


def check_harness():
    """``kfpga_adc_check``: the ADC model driven by a pin script, for the model's own tests.

    ``+script=PATH``: one line per system period, ``clk hold_a hold_b hold_c reset wr cs rd addr``
    (decimal), applied at that period's clock edge as a controller's registers would be.
    ``+out=PATH``: per period, ``EOC D15..D0`` as a controller samples them at that edge, then
    a last line ``errors first_error first_error_ns conversions``. The codes of conversion j
    are ``8 j + c + 100`` for channel c.
    """
    return f"""// The ADS8364 model driven by a pin script (tests/test_sim_ads8364.py). Generated by kfpga.
`timescale 1ns / 1ps
module {CHECK_NAME};
    reg clk50 = 1'b0;
    always #{SYSTEM_PERIOD_NS / 2:g} clk50 = ~clk50;
    reg adc_clk = 1'b0, adc_hold_a_n = 1'b1, adc_hold_b_n = 1'b1, adc_hold_c_n = 1'b1, adc_reset_n = 1'b1;
    reg adc_wr_n = 1'b1, adc_cs_n = 1'b1, adc_rd_n = 1'b1;
    reg [2:0] adc_addr = 3'd0;
    wire adc_eoc_n;
    wire [15:0] adc_data;
    wire [95:0] next_codes;
    wire take, read_strobe;
    wire [2:0] read_channel;
    wire [15:0] read_code;
    wire [31:0] read_conversion, conversions, eoc_pulses, errors;
    wire [7:0] first_error;
    wire [63:0] first_error_ns;
    genvar c;
    generate
        for (c = 0; c < 6; c = c + 1) begin : codes
            assign next_codes[16 * c +: 16] = conversions * 8 + c + 100;
        end
    endgenerate
{model_instance()}
    integer fs, fo, got;
    integer v_clk, v_ha, v_hb, v_hc, v_reset, v_wr, v_cs, v_rd, v_addr;
    reg [8*1024:1] script, out;
    initial begin
        if (!$value$plusargs("script=%s", script)) script = "script.txt";
        if (!$value$plusargs("out=%s", out)) out = "out.txt";
        fs = $fopen(script, "r");
        fo = $fopen(out, "w");
    end
    always @(posedge clk50) begin
        $fwrite(fo, "%0d %0d\\n", adc_eoc_n, adc_data);
        got = $fscanf(fs, "%d %d %d %d %d %d %d %d %d\\n", v_clk, v_ha, v_hb, v_hc, v_reset, v_wr, v_cs, v_rd, v_addr);
        if (got != 9) begin
            $fwrite(fo, "%0d %0d %0d %0d\\n", errors, first_error, first_error_ns, conversions);
            $fclose(fo);
            $finish;
        end
        adc_clk <= v_clk;
        adc_hold_a_n <= v_ha;
        adc_hold_b_n <= v_hb;
        adc_hold_c_n <= v_hc;
        adc_reset_n <= v_reset;
        adc_wr_n <= v_wr;
        adc_cs_n <= v_cs;
        adc_rd_n <= v_rd;
        adc_addr <= v_addr;
    end
endmodule
"""
