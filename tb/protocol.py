"""A handshake rule checker for one valid/ready channel of any payload (each AXI4-Lite channel;
the AXI4-Stream ports have the same rules checked inside their monitors, tb/stream.py, which
observe every clock anyway).

Once valid is high and ready low at a clock edge, valid must stay high and the payload unchanged
at the next edge, until the handshake; valid, ready and (while valid) the payload are never X or
Z out of reset. A violation fails the running test (AssertionError in a cocotb task) and is kept
in `violations`. The checker sleeps while valid is low, so an idle channel costs nothing.
"""

from __future__ import annotations

import cocotb
from cocotb.handle import SimHandleBase
from cocotb.simtime import get_sim_time
from cocotb.triggers import ReadOnly, RisingEdge


class HandshakeChecker:
    def __init__(self, clk: SimHandleBase, name: str, valid: SimHandleBase,
                 ready: SimHandleBase, payload: list[SimHandleBase],
                 reset: SimHandleBase | None = None, reset_active: int = 0):
        self.clk, self.name, self.valid, self.ready = clk, name, valid, ready
        self.payload, self.reset, self.reset_active = payload, reset, reset_active
        self.violations: list[str] = []
        self._task = cocotb.start_soon(self._run())

    def _fail(self, what: str) -> None:
        message = f"{self.name}: {what} (at {get_sim_time('ns')} ns)"
        self.violations.append(message)
        raise AssertionError(message)

    def _in_reset(self) -> bool:
        return self.reset is not None and (not self.reset.value.is_resolvable
                                           or int(self.reset.value) == self.reset_active)

    async def _run(self) -> None:
        edge, settle = RisingEdge(self.clk), ReadOnly()
        held: list[int] | None = None   # the payload of a beat stalled at the last edge
        while True:
            await edge
            await settle
            if self._in_reset():
                held = None
                continue
            if not self.valid.value.is_resolvable or not self.ready.value.is_resolvable:
                self._fail(f"valid {self.valid.value} ready {self.ready.value} out of reset")
            valid = int(self.valid.value)
            if held is not None:
                if not valid:
                    self._fail("valid dropped before the handshake")
                now = [self._word(p) for p in self.payload]
                changed = [f"{p._name} {old:#x} -> {new:#x}"
                           for p, old, new in zip(self.payload, held, now, strict=True)
                           if old != new]
                if changed:
                    self._fail(f"payload changed during a stall: {', '.join(changed)}")
            if not valid:
                held = None
                await RisingEdge(self.valid)   # nothing to check until a beat is offered
                continue
            words = [self._word(p) for p in self.payload]
            held = None if int(self.ready.value) else words

    def _word(self, signal: SimHandleBase) -> int:
        if not signal.value.is_resolvable:
            self._fail(f"{signal._name} is {signal.value} while valid")
        return signal.value.to_unsigned()

    def stop(self) -> None:
        self._task.cancel()
