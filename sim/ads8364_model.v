// Behavioural model of the TI ADS8364 with the datasheet timing checks, in plain Verilog-2001.
//
// Ref: Texas Instruments SBAS219C (ADS8364), Timing and control; Explanation of clock, reset
//      and EOC; Getting data (Figures 7, 9). The timing figures are parameters, in ns; kfpga
//      sets them from kfpga/ads8364.py (TIMING), where each figure has its source.
//
// The same behaviour as the Python model (sim/ads8364.py), for a controller that is synchronous
// to `clk`: its pins change only at rising edges of `clk`, so every time is a whole number of
// `clk` periods (SAMPLE_NS) and the model observes the pins once per period. It runs inside the
// simulator, with no call into Python per pin edge: this is what makes the whole design
// co-simulate at the speed of the simulator.
//
//  * A falling HOLDA/HOLDB/HOLDC samples its channel pair (the six codes come from `next_codes`,
//    and `take` asks for the next six); falls in the same period form one conversion. The
//    conversion counts CONV_CLOCKS rising CLK edges after HOLD fell, then stores the codes and
//    pulls EOC low until the next falling CLK edge.
//  * CS and RD low drive the code of channel A2..A0 on D15..D0, valid TACC_NS after the later of
//    the two falling edges (from the first `clk` edge strictly after that); 0 when not driven.
//  * RESET low clears the registers and aborts a conversion.
//
// Every violation increments `errors`, keeps the first one's number and time (`first_error`,
// `first_error_ns`) and prints one `ADS8364 timing:` line. The numbers (E_*) are the ones
// kfpga/sim/hdl.py names.
//
// EOC and D15..D0 are combinational from the pins and the model's state: an edge of CLK or RD
// at a `clk` edge is seen by the controller at the next `clk` edge, as with the real part.
`default_nettype none

module kfpga_ads8364_model #(
    parameter integer SAMPLE_NS   = 20,   // period of clk: the resolution of every check
    parameter integer TC1_NS      = 200,  // CLK period, min
    parameter integer TW1_NS      = 60,   // CLK high or low time, min
    parameter integer CONV_CLOCKS = 20,   // CLK rising edges from HOLD to the end of conversion
    parameter integer THOLDL_NS   = 20,   // HOLDx low width, min
    parameter integer THOLDH_NS   = 15,   // HOLDx high width between conversions, min
    parameter integer TW4_NS      = 20,   // RESET low width, min
    parameter integer TD2_NS      = 20,   // RESET high before the next HOLD falls, min
    parameter integer TD9_NS      = 10,   // A2..A0 setup before RD falls, min
    parameter integer TRDL_NS     = 40,   // RD low width, min
    parameter integer TACC_NS     = 40    // RD falling to data valid, max
) (
    input  wire        clk,
    // the ADC's pins, as the controller drives them
    input  wire        adc_clk,
    input  wire        hold_a_n,
    input  wire        hold_b_n,
    input  wire        hold_c_n,
    input  wire        reset_n,
    input  wire        wr_n,
    input  wire        cs_n,
    input  wire        rd_n,
    input  wire [2:0]  addr,
    output wire        eoc_n,
    output wire [15:0] data,
    // the analog inputs: the six codes of the next conversion (channel 0 in the low bits)
    input  wire [95:0] next_codes,
    output wire        take,             // next_codes are taken at this clk edge
    // what happened
    output wire        read_strobe,      // a read starts: read_channel, read_code, read_conversion
    output wire [2:0]  read_channel,
    output wire [15:0] read_code,
    output wire [31:0] read_conversion,  // the conversion the code came from (-1: none since reset)
    output reg  [31:0] conversions,
    output reg  [31:0] eoc_pulses,
    output reg  [31:0] errors,
    output reg  [7:0]  first_error,
    output reg  [63:0] first_error_ns
);
    localparam integer E_CLK_PERIOD = 1, E_CLK_LOW = 2, E_CLK_HIGH = 3, E_HOLD_LOW = 4, E_HOLD_HIGH = 5,
                       E_HOLD_RESET = 6, E_HOLD_IN_RESET = 7, E_HOLD_CONVERTING = 8, E_RESET_LOW = 9,
                       E_ADDR_RD_LOW = 10, E_ADDR_RD_RISE = 11, E_RD_LOW = 12, E_WR = 13, E_ADDR_SETUP = 14,
                       E_ADDR_MODE = 15;
    // pin levels one clk period ago: an edge is a difference, and it happened at the last clk edge.
    // Icarus interprets every statement it runs, so a period with no pin change does nothing but
    // count, and the times of events are timestamps (periods), not counters.
    wire [10:0] pins = {addr, rd_n, cs_n, wr_n, reset_n, hold_c_n, hold_b_n, hold_a_n, adc_clk};
    reg  [10:0] pins_q = 11'b000_1111_1110;  // idle levels, CLK low
    reg         started = 1'b0;  // the first period adopts the levels: they are not edges
    wire        clk_q = pins_q[0], reset_q = pins_q[4], wr_q = pins_q[5], cs_q = pins_q[6], rd_q = pins_q[7];
    wire [2:0]  hold = pins[3:1], hold_q = pins_q[3:1], addr_q = pins_q[10:8];
    wire        changed = started & (pins != pins_q);

    wire clk_rise = changed & adc_clk & ~clk_q;
    wire clk_fall = changed & ~adc_clk & clk_q;
    wire [2:0] hold_fall = {3{changed}} & hold_q & ~hold;
    wire [2:0] hold_rise = {3{changed}} & ~hold_q & hold;
    wire reset_fall = changed & reset_q & ~reset_n;
    wire reset_rise = changed & ~reset_q & reset_n;
    wire rd_rise = changed & ~rd_q & rd_n;
    wire rd_fall = changed & rd_q & ~rd_n;
    wire addr_change = changed & (addr != addr_q);
    wire reading = ~cs_n & ~rd_n;
    wire read_start = changed & reading & ~(~cs_q & ~rd_q);

    // the period count, and the period of the last clk edge before each event (0: never, which
    // measures as 2^40 periods and passes every minimum)
    reg [63:0] cycle = 64'd1 << 40;
    reg [63:0] t_clk_rise = 0, t_clk_fall = 0, t_reset_fall = 0, t_reset_rise = 0, t_rd_fall = 0, t_addr = 0,
               t_read = 0;
    reg [63:0] t_hold_fall [0:2];
    reg [63:0] t_hold_rise [0:2];

    reg        converting = 1'b0;
    reg [31:0] clocks = 0;  // CLK rising edges counted by the conversion in progress
    reg [95:0] held = 96'd0;
    reg [15:0] registers [0:5];
    reg [31:0] origin [0:5];
    reg        eoc_low = 1'b0;
    reg  [2:0] pairs = 3'b000;  // the pairs the conversion in progress samples
    reg [15:0] code_q = 16'd0;

    integer i;
    initial begin
        for (i = 0; i < 3; i = i + 1) begin
            t_hold_fall[i] = 0;
            t_hold_rise[i] = 0;
        end
        for (i = 0; i < 6; i = i + 1) begin
            registers[i] = 16'd0;
            origin[i] = 32'hffff_ffff;
        end
        conversions = 0;
        eoc_pulses = 0;
        errors = 0;
        first_error = 0;
        first_error_ns = 0;
    end

    wire starts = |hold_fall & ~converting;
    wire completes = converting & clk_rise & (clocks == CONV_CLOCKS - 1) & reset_n & ~reset_fall;
    assign take = starts;
    assign eoc_n = ~(reset_n & adc_clk & (eoc_low | completes));

    // the bus: the code latched when the read started, once TACC_NS have passed (strictly: a
    // controller sampling at the very instant would race the data)
    wire [15:0] start_code = (addr <= 3'd5) ? registers[addr] : 16'd0;  // 110, 111: no register
    wire [63:0] read_elapsed_ns = read_start ? SAMPLE_NS : (cycle - t_read + 1) * SAMPLE_NS;
    assign data = (reading && read_elapsed_ns > TACC_NS) ? (read_start ? start_code : code_q) : 16'd0;

    assign read_strobe = read_start & (addr <= 3'd5);
    assign read_channel = addr;
    assign read_code = start_code;
    assign read_conversion = (addr <= 3'd5) ? origin[addr] : 32'hffff_ffff;

    // the time in ns from an event (at the clk edge before period t) to the last clk edge
    function [63:0] since;
        input [63:0] t;
        since = (cycle - t) * SAMPLE_NS;
    endfunction

    task violation;
        input [7:0] code;
        input [63:0] measured_ns;
        input [31:0] limit_ns;
        begin
            errors = errors + 1;
            if (first_error == 0) begin
                first_error = code;
                first_error_ns = $time;
            end
            $display("ADS8364 timing: violation %0d at %0t (measured %0d, limit %0d)", code, $time, measured_ns,
                     limit_ns);
        end
    endtask

    integer p;
    always @(posedge clk) begin
        cycle <= cycle + 1;
        started <= 1'b1;
        pins_q <= pins;
        if (!wr_n && !started)
            violation(E_WR, 0, 0);
        if (changed) begin
            // -- checks (each against the figure it names) ---------------------------------
            if (clk_rise && since(t_clk_rise) < TC1_NS)
                violation(E_CLK_PERIOD, since(t_clk_rise), TC1_NS);
            if (clk_rise && since(t_clk_fall) < TW1_NS)
                violation(E_CLK_LOW, since(t_clk_fall), TW1_NS);
            if (clk_fall && since(t_clk_rise) < TW1_NS)
                violation(E_CLK_HIGH, since(t_clk_rise), TW1_NS);
            for (p = 0; p < 3; p = p + 1) begin
                if (hold_rise[p] && since(t_hold_fall[p]) < THOLDL_NS)
                    violation(E_HOLD_LOW, since(t_hold_fall[p]), THOLDL_NS);
                if (hold_fall[p]) begin
                    if (since(t_hold_rise[p]) < THOLDH_NS)
                        violation(E_HOLD_HIGH, since(t_hold_rise[p]), THOLDH_NS);
                    if (!reset_q || !reset_n)
                        violation(E_HOLD_IN_RESET, 0, 0);
                    else if (since(t_reset_rise) < TD2_NS)
                        violation(E_HOLD_RESET, since(t_reset_rise), TD2_NS);
                    if (converting)
                        violation(E_HOLD_CONVERTING, clocks, 0);
                end
                if (hold_fall[p]) t_hold_fall[p] <= cycle;
                if (hold_rise[p]) t_hold_rise[p] <= cycle;
            end
            if (reset_rise && since(t_reset_fall) < TW4_NS)
                violation(E_RESET_LOW, since(t_reset_fall), TW4_NS);
            if (addr_change && !rd_q && !rd_n && !cs_n)
                violation(E_ADDR_RD_LOW, addr_q, addr);
            if (addr_change && rd_rise)
                violation(E_ADDR_RD_RISE, addr_q, addr);
            if (rd_rise && since(t_rd_fall) < TRDL_NS)
                violation(E_RD_LOW, since(t_rd_fall), TRDL_NS);
            if (!wr_n && wr_q)
                violation(E_WR, 0, 0);
            if (read_start && (addr_change ? 0 : since(t_addr)) < TD9_NS)
                violation(E_ADDR_SETUP, addr_change ? 0 : since(t_addr), TD9_NS);
            if (read_start && addr > 3'd5)
                violation(E_ADDR_MODE, addr, 5);

            // -- behaviour -------------------------------------------------------------------
            if (reset_fall || !reset_n) begin
                converting <= 1'b0;
                eoc_low <= 1'b0;
                for (i = 0; i < 6; i = i + 1) begin
                    registers[i] <= 16'd0;
                    origin[i] <= 32'hffff_ffff;
                end
            end else begin
                if (starts) begin
                    converting <= 1'b1;
                    clocks <= 0;
                    conversions <= conversions + 1;
                    pairs <= hold_fall;
                    for (p = 0; p < 3; p = p + 1)
                        if (hold_fall[p]) held[32 * p +: 32] <= next_codes[32 * p +: 32];
                end else if (converting && clk_rise) begin
                    clocks <= clocks + 1;
                end
                if (completes) begin
                    converting <= 1'b0;
                    eoc_low <= 1'b1;
                    eoc_pulses <= eoc_pulses + 1;
                    for (i = 0; i < 6; i = i + 1)
                        if (pairs[i / 2]) begin
                            registers[i] <= held[16 * i +: 16];
                            origin[i] <= conversions - 1;
                        end
                end else if (clk_fall) begin
                    eoc_low <= 1'b0;
                end
            end
            if (read_start) begin
                code_q <= start_code;
                t_read <= cycle;
            end
            if (clk_rise) t_clk_rise <= cycle;
            if (clk_fall) t_clk_fall <= cycle;
            if (reset_fall) t_reset_fall <= cycle;
            if (reset_rise) t_reset_rise <= cycle;
            if (rd_fall) t_rd_fall <= cycle;
            if (addr_change) t_addr <= cycle;
        end
    end
endmodule

`default_nettype wire
