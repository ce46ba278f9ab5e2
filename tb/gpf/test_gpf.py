"""cocotb testbench of the whole filter, gpf_bot or gpf_uav (tb/gpf/filter.py does the work),
inside its testbench harness gpf_<app>_harness (the steps' streams, stalls and protocol checks
in the simulator: tb/gpf/feeds.py).

test_filter: the run GPF_RUN describes (`gpf run`; a few steps by default), no stalls: every
  particle, weight and estimate bit-exact, and each step's cycle count equal to the measured
  period between result beats.
test_stalls: 50 % random stalls on every stream the testbench drives or reads (the harness's,
  from a seed the test prints), the same checks (nothing lost, duplicated or reordered).
test_reset_mid_step: a reset half-way through a step; what follows starts clean.
Every test checks that no output is X or Z after reset.
test_corrupted_model_is_caught: a model with its draws in the wrong order must fail.
"""

from __future__ import annotations

import cocotb
from cocotb.handle import SimHandleBase

from gpf.tb.gpf.filter import FilterBench, RunSpec, write_result
from gpf.tb.harness import bench


def check(res) -> None:
    assert res.particles_checked == res.steps * res.particles
    assert res.mismatches == 0, f"{res.mismatches} mismatches; first: {res.first_mismatch}"


@cocotb.test()
async def test_filter(dut: SimHandleBase) -> None:
    b = bench()
    spec = RunSpec.from_env(steps=2 if b.short else 4, particles=64 * b.cfg.lanes)
    fb = FilterBench(dut, b, spec)
    res = await fb.run()
    write_result(res, spec.out)
    if spec.bare:   # a measurement of the simulator alone (gpf bench --speed): nothing checked
        dut._log.info("bare: %d particles in %.3f s", res.particles_simulated,
                      res.stepping_seconds)
        return
    dut._log.info("%d steps x %d particles: %d values checked, %d mismatches; cycles %s",
                  res.steps, res.particles, res.values_checked, res.mismatches,
                  res.cycles_per_step)
    check(res)
    # nothing stalled: a step's count is the period of dependent steps
    if not spec.stall and not spec.est_hold:
        assert res.period_per_step == res.cycles_per_step[1:], \
            f"periods {res.period_per_step}, counts {res.cycles_per_step}"


@cocotb.test()
async def test_stalls(dut: SimHandleBase) -> None:
    b = bench()
    spec = RunSpec.from_env(steps=2, particles=32 * b.cfg.lanes)
    spec.stall, spec.out, spec.progress = 0.5, None, None
    fb = FilterBench(dut, b, spec)
    res = await fb.run()
    dut._log.info("stalls 0.5: %d values checked, %d mismatches", res.values_checked,
                  res.mismatches)
    check(res)


@cocotb.test()
async def test_reset_mid_step(dut: SimHandleBase) -> None:
    """A reset half-way through a step's particles: the run that follows (seed, init, steps) is
    bit-exact with the model started afresh, and nothing of the old step comes out."""
    b = bench()
    spec = RunSpec(steps=2, particles=32 * b.cfg.lanes, seed=b.seed % 1000 + 1)
    fb = FilterBench(dut, b, spec)
    await fb.interrupted_step()
    res = await fb.run()
    check(res)


@cocotb.test()
async def test_particle_count_out_of_range(dut: SimHandleBase) -> None:
    """An init with N outside [LANES, the config's maximum] runs the nearest count (N = 0:
    LANES particles, N too large: the maximum), one not a multiple of LANES the next multiple."""
    b = bench()
    lanes, most = b.cfg.lanes, b.cfg.particles
    width = most.bit_length()
    cases = [(0, lanes), ((1 << width) - 1, most)] + ([(lanes + 1, 2 * lanes)] if lanes > 1
                                                        else [])
    for case, (sent, runs) in enumerate(cases):
        spec = RunSpec(steps=1, particles=runs, init_particles=sent, seed=b.seed % 1000 + 2)
        res = await FilterBench(dut, b, spec, clock_running=case > 0).run()
        check(res)
        dut._log.info("init N = %d: ran %d particles", sent, res.particles)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    b = bench()
    spec = RunSpec(steps=1, particles=16 * b.cfg.lanes)
    fb = FilterBench(dut, b, spec, corrupt=True)
    res = await fb.run()
    assert res.mismatches > 0 and res.first_mismatch, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", res.first_mismatch)
