"""cocotb testbench of gpf_bot_axi / gpf_uav_axi: the filter as an IP block.

The whole-filter tests of test_gpf run through the wrapper's ports (tb/gpf/filter.py sees the
wrapper: aclk/aresetn, the seed and N written over AXI4-Lite, RUN and TAPS set, TLAST and the
byte padding checked), bit-exact as on the core. The register tests drive a real AXI4-Lite
master (cocotbext-axi) with random pauses on its five channels, each channel's handshake rules
checked (tb/protocol.py), and take every address, reset value and access from the generated
SystemRDL:
test_register_reset_values: every register reads its reset value.
test_register_access: every register written with ones, zeros and random words reads back
  what its fields' access says (read-only kept, write-1-to-clear, single pulses reading 0).
test_run_status_and_interrupts: RUN holds and releases steps; STATUS, STEPS, FLAGS, CYCLES and
  ESS follow the results (checked against the m_est beats); the interrupts set, mask and clear;
  a soft reset clears the filter and the counters but no register.
"""

from __future__ import annotations

import cocotb
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, ReadOnly, RisingEdge

from gpf.model.blocks import Flag
from gpf.study.montecarlo import flag_names
from gpf.tb.gpf.filter import FilterBench, RunSpec
from gpf.tb.gpf.ip import Ip, registers
from gpf.tb.gpf.test_gpf import (  # noqa: F401  (cocotb collects them from this module)
    test_corrupted_model_is_caught,
    test_filter,
    test_particle_count_out_of_range,
    test_reset_mid_step,
    test_stalls,
)
from gpf.tb.harness import bench
from gpf.tb.scoreboard import unpack
from gpf.tb.stream import StreamDriver


async def ip_of(dut: SimHandleBase, stall: float = 0.3) -> Ip:
    b = bench()
    ip = Ip.of(dut, b.cfg.app)
    ip.stall(b.rng("axil"), stall)
    for name in ("s_init", "s_step"):
        getattr(dut, f"{name}_tvalid").value = 0
        getattr(dut, f"{name}_tlast").value = 0
    for name in ("m_est", "m_cond", "m_part"):
        getattr(dut, f"{name}_tready").value = 1
    await ip.reset()
    return ip


def reset_word(fields: list) -> int:
    return sum(f.reset << f.lsb for f in fields if not f.pulse)


def after_write(fields: list, old: int, written: int) -> int:
    """What a register reads after `written` landed on `old`, by its fields' access."""
    word = 0
    for f in fields:
        was, new = (old & f.mask) >> f.lsb, (written & f.mask) >> f.lsb
        if f.pulse:
            now = 0
        elif f.clear_on_one:
            now = was & ~new
        elif f.writable:
            now = new
        else:
            now = was
        word |= now << f.lsb
    return word


@cocotb.test()
async def test_register_reset_values(dut: SimHandleBase) -> None:
    ip = await ip_of(dut)
    for reg, fields in registers(ip.fields).items():
        got = await ip.read(reg)
        assert got == reset_word(fields), f"{reg}: reset {got:#x}, expected " \
                                          f"{reset_word(fields):#x}"
    assert dut.irq.value == 0


@cocotb.test()
async def test_register_access(dut: SimHandleBase) -> None:
    ip = await ip_of(dut)
    rng = bench().rng("access")
    checked = 0
    for reg, fields in registers(ip.fields).items():
        if any(f.hw_driven for f in fields if f.writable):
            continue   # interrupt status: its own test
        value = reset_word(fields)
        for written in (0xFFFF_FFFF, 0, rng.getrandbits(32), rng.getrandbits(32)):
            await ip.write(reg, written)
            value = after_write(fields, value, written)
            got = await ip.read(reg)
            assert got == value, f"{reg}: wrote {written:#x}, read {got:#x}, expected {value:#x}"
            checked += 1
    dut._log.info("%d register writes read back as their fields' access says", checked)
    assert checked >= 4 * 10
    assert not any(c.violations for c in ip.checkers)


async def wait_for(dut: SimHandleBase, signal: SimHandleBase, clocks: int,
                   capture: SimHandleBase | None = None) -> int:
    """Clocks until `signal` is high; `capture`'s value then."""
    for _ in range(clocks):
        await RisingEdge(dut.aclk)
        await ReadOnly()
        if signal.value == 1:
            value = capture.value.to_unsigned() if capture is not None else 0
            await RisingEdge(dut.aclk)
            return value
    raise AssertionError(f"{signal._name} not high within {clocks} clocks")


@cocotb.test()
async def test_run_status_and_interrupts(dut: SimHandleBase) -> None:
    b = bench()
    ip = await ip_of(dut)
    spec = RunSpec(steps=2, particles=16 * b.cfg.lanes, seed=b.seed % 1000 + 5)
    fb = FilterBench(dut, b, spec)
    assert await ip.field("status.initialised") == 0
    # a whole run through the wrapper (RUN and TAPS set by the bench), then its status
    res = await fb.run()
    assert res.mismatches == 0, res.first_mismatch
    est_fields = fb.s.est
    assert await ip.field("status.initialised") == 1
    assert await ip.field("status.busy") == 0
    assert await ip.field("steps.count") == spec.steps
    assert await ip.field("cycles.count") == res.cycles_per_step[-1]
    last = fb.gpf.to_real_ess(await ip.field("ess.value"))
    assert float(last) == res.ess[-1], (last, res.ess)
    assert flag_names(await ip.field("flags.last")) == res.flags[-1]
    sticky = sum({Flag[name.upper()] for step in res.flags for name in step})
    assert await ip.field("flags.sticky") == sticky, res.flags
    raised = any(res.flags)
    assert await ip.field("int_status.step_done") == 1
    assert await ip.field("int_status.flag") == int(raised)
    assert dut.irq.value == 0, "irq with every interrupt disabled"
    await ip.write("int_enable", ip.value({"int_enable.step_done": 1}))
    await ClockCycles(dut.aclk, 2)
    assert dut.irq.value == 1, "step done and enabled, no irq"
    await ip.write("int_status", ip.value({"int_status.step_done": 1}))   # write 1 to clear
    await ClockCycles(dut.aclk, 2)
    assert await ip.field("int_status.step_done") == 0
    assert dut.irq.value == 0, "irq after its status was cleared"

    # RUN low: a step waits, nothing is busy; RUN high: it runs (the taps off and stalled do not
    # hold it), and interrupts again
    await ip.write("ctrl", ip.value({"ctrl.run": 0, "ctrl.taps": 0}))
    dut.m_cond_tready.value = dut.m_part_tready.value = 0
    step = StreamDriver(dut.aclk, dut, "s_step", 0.0, b.rng("step"))
    sent = cocotb.start_soon(step.send([(0, True)]))   # one beat, held until taken
    await ClockCycles(dut.aclk, 50)
    assert not sent.done(), "a step taken with RUN low"
    assert await ip.field("status.busy") == 0
    await ip.write("ctrl", ip.value({"ctrl.run": 1}))
    await sent
    assert await ip.field("status.busy") == 1
    beat = await wait_for(dut, dut.m_est_tvalid, 20 * (spec.particles + 1000), dut.m_est_tdata)
    await ClockCycles(dut.aclk, 2)
    assert dut.irq.value == 1, "step done and enabled, no irq"
    assert await ip.field("steps.count") == spec.steps + 1
    assert await ip.field("status.busy") == 0
    est = unpack([beat], est_fields, 1)
    assert await ip.field("cycles.count") == int(est["cycles"][0, 0])
    assert await ip.field("flags.last") == int(est["flags"][0, 0])
    assert await ip.field("ess.value") == int(est["ess"][0, 0])

    # a soft reset: the filter and the counters clear, the registers keep their values
    kept = {reg: await ip.read(reg) for reg in ("particles", "int_enable", "seed_lo")}
    await ip.write("ctrl", ip.value({"ctrl.soft_reset": 1, "ctrl.run": 1}))
    await ClockCycles(dut.aclk, 4)
    assert await ip.field("steps.count") == 0
    assert await ip.field("status.initialised") == 0
    assert await ip.field("ctrl.run") == 1 and await ip.field("ctrl.soft_reset") == 0
    for reg, value in kept.items():
        assert await ip.read(reg) == value, f"{reg} changed by a soft reset"
    dut.s_step_tvalid.value = 1
    await ClockCycles(dut.aclk, 20)
    await ReadOnly()
    assert dut.s_step_tready.value == 0, "a step taken after a soft reset, before an init"
    await RisingEdge(dut.aclk)
    dut.s_step_tvalid.value = 0
    assert not any(c.violations for c in ip.checkers)
