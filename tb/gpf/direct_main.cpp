// The clock of a whole-filter run without cocotb (tb/gpf/direct.py): gpf_<app>_direct, Verilated
// with --prefix Vdirect, turned clock by clock until it raises `done` (or calls $finish).
// No timing scheduler: each half period is one eval of the model.
#include <memory>

#include "Vdirect.h"
#include "verilated.h"

int main(int argc, char** argv) {
    const std::unique_ptr<VerilatedContext> context{new VerilatedContext};
    context->commandArgs(argc, argv);
    const std::unique_ptr<Vdirect> top{new Vdirect{context.get()}};
    top->clk = 0;
    top->eval();
    while (!top->done && !context->gotFinish()) {
        context->timeInc(5);   // ns: the 10 ns clock of the cocotb testbenches
        top->clk = 1;
        top->eval();
        context->timeInc(5);
        top->clk = 0;
        top->eval();
    }
    top->final();
    return top->done ? 0 : 1;
}
