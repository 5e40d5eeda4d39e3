// The clock loop of kfpga_cosim on Verilator: the system clock toggles here, in C++, with no
// VPI and no Python per edge. Everything else (stimulus, logs, when to stop) is in the Verilog
// (sim/hdl.py). Written by hand: Verilator needs a main loop, and this one is the whole of it.
#include <memory>

#include "Vkfpga_cosim.h"
#include "verilated.h"

#ifndef KFPGA_HALF_PERIOD_NS
#define KFPGA_HALF_PERIOD_NS 10
#endif

int main(int argc, char** argv) {
    const std::unique_ptr<VerilatedContext> context{new VerilatedContext};
    context->commandArgs(argc, argv);
    const std::unique_ptr<Vkfpga_cosim> top{new Vkfpga_cosim{context.get()}};
    // time advances in the precision unit (1 ps under `timescale 1ns / 1ps)
    uint64_t half = KFPGA_HALF_PERIOD_NS;
    for (int p = context->timeprecision(); p < -9; ++p) half *= 10;
    top->clk50 = 0;
    top->eval();
    while (!context->gotFinish()) {
        context->timeInc(half);
        top->clk50 = 1;
        top->eval();
        context->timeInc(half);
        top->clk50 = 0;
        top->eval();
    }
    top->final();
    return 0;
}
