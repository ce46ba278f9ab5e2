"""gpf_<app>_axi as the testbench meets it: aclk and aresetn, the AXI4-Lite registers (read from
the generated SystemRDL, so no address or reset value is typed here), a real AXI4-Lite master
(cocotbext-axi) with its own protocol checks on all five channels."""

from __future__ import annotations

import logging
import os
import random
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cocotb
from cocotb.clock import Clock
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, RisingEdge
from cocotbext.axi import AxiLiteBus, AxiLiteMaster
from systemrdl.rdltypes import OnWriteType

from gpf.rtl.regs import compile_rdl, regs_name
from gpf.tb.harness import CLOCK_NS
from gpf.tb.protocol import HandshakeChecker


@dataclass(frozen=True)
class RegField:
    reg: str
    name: str
    address: int
    lsb: int
    width: int
    reset: int            # 0 where the description gives none
    writable: bool        # by software
    clear_on_one: bool    # woclr
    pulse: bool           # singlepulse: reads back 0
    hw_driven: bool       # the hardware writes it (status)

    @property
    def mask(self) -> int:
        return ((1 << self.width) - 1) << self.lsb


def register_map(app: str) -> dict[str, RegField]:
    """{"reg.field": RegField} from the .rdl `gpf generate` wrote beside the manifest."""
    rdl = Path(os.environ["GPF_MANIFEST"]).parent / f"{regs_name(app)}.rdl"
    out = {}
    for reg in compile_rdl(rdl).top.registers():
        for f in reg.fields():
            out[f"{reg.inst_name}.{f.inst_name}"] = RegField(
                reg.inst_name, f.inst_name, reg.absolute_address, f.lsb, f.width,
                f.get_property("reset") or 0, f.is_sw_writable,
                f.get_property("onwrite") == OnWriteType.woclr,
                bool(f.get_property("singlepulse")), f.is_hw_writable)
    return out


def registers(fields: dict[str, RegField]) -> dict[str, list[RegField]]:
    """The fields of each register, by its name."""
    out: dict[str, list[RegField]] = {}
    for f in fields.values():
        out.setdefault(f.reg, []).append(f)
    return out


# the five AXI4-Lite channels: (valid, ready, payload), names after s_axil_
AXIL_CHANNELS = [("awvalid", "awready", ["awaddr", "awprot"]),
                 ("wvalid", "wready", ["wdata", "wstrb"]),
                 ("bvalid", "bready", ["bresp"]),
                 ("arvalid", "arready", ["araddr", "arprot"]),
                 ("rvalid", "rready", ["rdata", "rresp"])]

_MASTERS: dict[int, Ip] = {}   # one master a test: its coroutines drive the bus


class Ip:
    """The wrapper's clock, reset and registers."""

    def __init__(self, dut: SimHandleBase, app: str):
        self.dut, self.clk = dut, dut.aclk
        self.fields = register_map(app)
        self.axil = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axil"), dut.aclk, dut.aresetn,
                                  reset_active_level=False)
        for side in (self.axil.write_if, self.axil.read_if):   # a line per access otherwise
            side.log.setLevel(logging.WARNING)
        self.checkers = [HandshakeChecker(dut.aclk, f"s_axil {v[:-5]}",
                                          getattr(dut, f"s_axil_{v}"), getattr(dut, f"s_axil_{r}"),
                                          [getattr(dut, f"s_axil_{p}") for p in payload],
                                          reset=dut.aresetn)
                         for v, r, payload in AXIL_CHANNELS]
        self._clock = cocotb.start_soon(Clock(self.clk, CLOCK_NS, unit="ns", impl="gpi").start())

    @classmethod
    def of(cls, dut: SimHandleBase, app: str) -> Ip:
        """The test's Ip (cocotb ends a test's tasks with it: the next test builds its own)."""
        ip = _MASTERS.get(id(dut))
        if ip is None or ip._clock.done():
            ip = _MASTERS[id(dut)] = cls(dut, app)
        return ip

    def stall(self, rng: random.Random, probability: float) -> None:
        """Random pauses on the master's five channels (valid low, or B/R ready low)."""
        def pauses() -> Iterator[bool]:
            while True:
                yield rng.random() < probability
        for ch in (self.axil.write_if.aw_channel, self.axil.write_if.w_channel,
                   self.axil.write_if.b_channel, self.axil.read_if.ar_channel,
                   self.axil.read_if.r_channel):
            ch.set_pause_generator(pauses() if probability else None)

    async def reset(self, cycles: int = 4) -> None:
        """aresetn low for a few clocks."""
        self.dut.aresetn.value = 0
        await ClockCycles(self.clk, cycles)
        self.dut.aresetn.value = 1
        await RisingEdge(self.clk)

    async def read(self, reg: str) -> int:
        return await self.axil.read_dword(self.address(reg))

    async def write(self, reg: str, value: int) -> None:
        await self.axil.write_dword(self.address(reg), value)

    async def field(self, name: str) -> int:
        f = self.fields[name]
        return (await self.read(f.reg) & f.mask) >> f.lsb

    def value(self, fields: dict[str, int]) -> int:
        """A register's word from field values: value({"ctrl.run": 1, "ctrl.taps": 1})."""
        word = 0
        for key, v in fields.items():
            f = self.fields[key]
            assert 0 <= v < 1 << f.width, f"{key} = {v} does not fit {f.width} bits"
            word |= v << f.lsb
        return word

    def address(self, reg: str) -> int:
        return next(f.address for f in self.fields.values() if f.reg == reg)

    async def load_seed(self, words: list[int]) -> None:
        for word in words:
            await self.write("seed_lo", word & 0xFFFF_FFFF)
            await self.write("seed_hi", word >> 32)   # sends the word
