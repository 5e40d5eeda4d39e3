// The clock loop of the in-simulator benches on Verilator (kfpga_cosim, kfpga_core_cosim): the
// clock input `clk` toggles here, in C++, with no VPI and no Python per edge. Everything else
// (stimulus, logs, when to stop) is in the Verilog (sim/hdl.py, sim/corerun.py). Written by
// hand: Verilator needs a main loop, and this one is the whole of it. KFPGA_TOP names the
// Verilated class (-DKFPGA_TOP=Vkfpga_cosim).
#include <memory>

#ifndef KFPGA_TOP
#define KFPGA_TOP Vkfpga_cosim
#endif
#define KFPGA_STRINGIFY2(x) #x
#define KFPGA_STRINGIFY(x) KFPGA_STRINGIFY2(x)
#define KFPGA_HEADER(x) KFPGA_STRINGIFY(x.h)
#include KFPGA_HEADER(KFPGA_TOP)
#include "verilated.h"

#ifndef KFPGA_HALF_PERIOD_NS
#define KFPGA_HALF_PERIOD_NS 10
#endif

int main(int argc, char** argv) {
    const std::unique_ptr<VerilatedContext> context{new VerilatedContext};
    context->commandArgs(argc, argv);
    const std::unique_ptr<KFPGA_TOP> top{new KFPGA_TOP{context.get()}};
    // time advances in the precision unit (1 ps under `timescale 1ns / 1ps)
    uint64_t half = KFPGA_HALF_PERIOD_NS;
    for (int p = context->timeprecision(); p < -9; ++p) half *= 10;
    top->clk = 0;
    top->eval();
    while (!context->gotFinish()) {
        context->timeInc(half);
        top->clk = 1;
        top->eval();
        context->timeInc(half);
        top->clk = 0;
        top->eval();
    }
    top->final();
    return 0;
}
