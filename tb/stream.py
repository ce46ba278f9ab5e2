"""AXI4-Stream helpers for the testbenches: a random `tready` driver and a beat monitor.

Monitors sample after the rising edge once signals settle (ReadOnly) and record a beat only when
tvalid && tready, so the scoreboard sees what crossed the bus, not what a driver meant to send.

Every port a monitor here watches is also checked against the AXI4-Stream protocol (_Port): a
beat offered and not taken (tvalid high, tready low at a clock edge) must still be offered at
the next edge with the same tdata and tlast, until the handshake; tvalid is never X or Z after
reset, nor tdata or tlast while tvalid is high; and where the block is the slave, its tready is
never X or Z after reset. A violation raises ProtocolError (an AssertionError) in the monitor's
coroutine, naming the port, the cycle and the old and new values: cocotb 2.1 fails the running
test with an exception from any task started with cocotb.start_soon that nothing awaits (its
TestManager._task_done_callback aborts the test with it and cancels every other task).
"""

from __future__ import annotations

import logging
import random
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import NoReturn

import cocotb
from cocotb.handle import SimHandleBase
from cocotb.simtime import get_sim_time
from cocotb.triggers import Event, ReadOnly, RisingEdge, Trigger, ValueChange
from cocotb.types import Logic
from cocotb.utils import get_sim_steps

from gpf.tb.harness import CLOCK_NS


@dataclass
class Beat:
    data: int
    cycle: int
    last: bool = False


class ProtocolError(AssertionError):
    """An AXI4-Stream rule broken on a port (see the module's docstring)."""


# Logic values are singletons: `is` is the cheap test of a bit, == the general one (X, Z, or a
# one-bit array); the checks run on every clock of millions
_0, _1 = Logic(0), Logic(1)


class _Port:
    """One AXI4-Stream port `<prefix>.<name>_tvalid/tready/tdata/tlast` and its protocol checks.

    A monitor calls _offered on every clock it observes with tvalid high and _not_offered on
    every other one on which tvalid is not 0 or _held is set; it must observe the clock after
    one on which a beat stalled (tvalid high, tready low): _held is that beat, and the next
    observation is checked against it. Only a stalled clock reads more than the monitor reads
    anyway (tdata, tlast, rst and the time), so a flowing or idle port costs the checks next
    to nothing.

    `rst` is read at ReadOnly, after the testbench's writes of the clock: its value is what the
    coming edge samples. A beat stalled while rst is high may vanish at that edge (the block is
    reset), so it is not held; X or Z counts only while rst is low (after a reset: before the
    first, rst is X or the clock is not running). `restart` is a signal that, high at an edge,
    restarts the stream as rst does (a documented flush of what the port offers)."""

    def __init__(self, prefix: SimHandleBase, name: str, has_last: bool,
                 restart: SimHandleBase | None = None):
        self.tvalid = getattr(prefix, f"{name}_tvalid")
        self.tready = getattr(prefix, f"{name}_tready")
        self.tdata = getattr(prefix, f"{name}_tdata")
        self.tlast = getattr(prefix, f"{name}_tlast") if has_last else None
        self.rst = getattr(prefix, "rst", None)
        # an AMBA top (gpf_<app>_axi): its reset is aresetn, active low
        self.rst_n = getattr(prefix, "aresetn", None) if self.rst is None else None
        self.restart = restart
        self.port = f"{prefix._name}.{name}"
        # the beat stalled on the previous clock: tdata, tlast, its cycle
        self._held: tuple[int, bool, int] | None = None

    def _reset_next(self) -> bool:
        """Whether the coming clock edge resets the block (rst not plainly low) or restarts the
        stream (`restart` high)."""
        return (self.rst is not None and self.rst.value != 0) or \
            (self.rst_n is not None and self.rst_n.value != 1) or \
            (self.restart is not None and self.restart.value == 1)

    def _fail(self, cycle: int, what: str) -> NoReturn:
        raise ProtocolError(f"{self.port}: AXI4-Stream protocol violation at cycle {cycle} "
                            f"(t = {get_sim_time('ns'):g} ns): {what}")

    def _hex(self, word: int) -> str:
        return f"0x{word:0{(len(self.tdata) + 3) // 4}x}"

    def _beat(self, cycle: Callable[[], int]) -> tuple[int, bool]:
        """tdata and tlast of the beat offered (tvalid high): both defined, or a violation."""
        data = self.tdata.value
        try:
            word = data.to_unsigned()
        except ValueError:   # X or Z in it
            self._fail(cycle(), f"tdata is {data} (X or Z bits) while tvalid is high")
        if self.tlast is None:
            return word, False
        last = self.tlast.value
        if last is _0:
            return word, False
        if last is _1 or last == 1:
            return word, True
        if last != 0:
            self._fail(cycle(), f"tlast is {last} while tvalid is high")
        return word, False

    def _offered(self, ready: bool, cycle: Callable[[], int]) -> tuple[int, bool] | None:
        """At ReadOnly of a clock with tvalid high: the beat (tdata, tlast) if it is taken
        (tready high); checked against the beat stalled on the previous clock, and held for
        the next clock if it stalls now."""
        held = self._held
        if ready:
            beat = self._beat(cycle)
            if held is not None:
                self._held = None
                if beat[0] != held[0] or beat[1] != held[1]:
                    self._changed(held, beat, cycle())
            return beat
        reset = self._reset_next()
        if held is None and reset:
            return None
        beat = self._beat(cycle)
        now = cycle()
        if held is not None and (beat[0] != held[0] or beat[1] != held[1]):
            self._changed(held, beat, now)
        self._held = None if reset else (*beat, now)
        return None

    def _next_clock(self, held: tuple[int, bool, int], cycle: int) -> None:
        """A violation is one only on the clock right after the stall (else the monitor missed
        clocks: a testbench error, not the block's)."""
        if cycle != held[2] + 1:
            raise AssertionError(f"{self.port}: testbench error: a beat stalled at cycle "
                                 f"{held[2]}, the next clock observed was cycle {cycle}")

    def _changed(self, old: tuple[int, bool, int], new: tuple[int, bool], cycle: int
                 ) -> NoReturn:
        self._next_clock(old, cycle)
        what = []
        if new[0] != old[0]:
            diff = old[0] ^ new[0]
            bits = [str(i) for i in range(diff.bit_length()) if diff >> i & 1]
            where = ", ".join(bits[:8]) + (f" and {len(bits) - 8} more" if len(bits) > 8 else "")
            what.append(f"tdata {self._hex(old[0])} -> {self._hex(new[0])} (bit"
                        f"{'s' if len(bits) > 1 else ''} {where} of {len(self.tdata)})")
        if new[1] != old[1]:
            what.append(f"tlast {int(old[1])} -> {int(new[1])}")
        self._fail(cycle, f"{' and '.join(what)}: the beat offered at cycle {old[2]} was "
                          f"not taken (tvalid high, tready low) and must hold until it is")

    def _not_offered(self, valid: Logic, cycle: Callable[[], int]) -> None:
        """At ReadOnly of a clock with tvalid not high: no beat may have stalled on the previous
        clock, and tvalid is 0 after reset."""
        held = self._held
        if held is not None:
            c = cycle()
            self._next_clock(held, c)
            self._fail(c, f"tvalid fell to {valid} before the handshake: the beat offered at "
                          f"cycle {held[2]} (tdata {self._hex(held[0])}, tlast {int(held[1])}) "
                          f"was not taken (tready low) and must hold until it is")
        if valid != 0 and not self._reset_next():
            self._fail(cycle(), f"tvalid is {valid} (X or Z) after reset")

    def _ready_defined(self, ready: Logic, cycle: Callable[[], int]) -> None:
        """tready (the block's, where it is the slave) not 0 and not high: X or Z, a violation
        after reset."""
        if ready != 0 and ready != 1 and not self._reset_next():
            self._fail(cycle(), f"tready is {ready} (X or Z) after reset")


class ReadyDriver:
    """Drives `tready`: high with probability 1 - stall (a fresh random choice every clock)."""

    def __init__(self, clk: SimHandleBase, tready: SimHandleBase, stall: float,
                 rng: random.Random):
        self.clk, self.tready, self.stall, self.rng = clk, tready, stall, rng
        self.tready.value = 0 if stall >= 1 else 1
        self._task = cocotb.start_soon(self._run())

    async def _run(self) -> None:
        while True:
            await RisingEdge(self.clk)
            self.tready.value = 0 if self.rng.random() < self.stall else 1

    def stop(self, ready: int = 1) -> None:
        self._task.cancel()
        self.tready.value = ready


class StreamMonitor(_Port):
    """Records every beat (tvalid && tready) of one AXI4-Stream port into `beats`; checks the
    protocol (_Port) on every clock, on either side: tvalid, tdata and tlast held while a beat
    stalls, tvalid and tready never X or Z after reset (or a `restart`: see _Port)."""

    def __init__(self, clk: SimHandleBase, prefix: SimHandleBase, name: str,
                 has_last: bool = False, restart: SimHandleBase | None = None):
        super().__init__(prefix, name, has_last, restart)
        self.clk = clk
        self.beats: list[Beat] = []
        self.cycles = 0
        self.log = logging.getLogger(f"tb.{name}.mon")
        self._task = cocotb.start_soon(self._run())

    def _cycle(self) -> int:
        return self.cycles

    async def _run(self) -> None:
        edge, settle = RisingEdge(self.clk), ReadOnly()
        while True:
            await edge
            await settle
            self.cycles += 1
            valid, ready = self.tvalid.value, self.tready.value
            if ready is not _0 and ready is not _1:
                self._ready_defined(ready, self._cycle)
            if valid is _1 or (valid is not _0 and valid == 1):
                # X or Z in tdata or tlast is a violation, not a 0
                beat = self._offered(ready is _1 or (ready is not _0 and ready == 1),
                                     self._cycle)
                if beat is not None:
                    self.beats.append(Beat(beat[0], self.cycles, beat[1]))
            elif valid is not _0 or self._held is not None:
                self._not_offered(valid, self._cycle)

    def stop(self) -> None:
        self._task.cancel()


class StreamDriver:
    """Drives an AXI4-Stream slave port (`<name>_tvalid/tready/tdata/tlast`) with beats, idle
    for a random clock before a beat with probability `idle`; holds each beat until taken.

    A beat may carry a new value for the `op` port (per-step operands, which the block samples
    with the first beat of a step): it is driven as that beat is presented."""

    def __init__(self, clk: SimHandleBase, prefix: SimHandleBase, name: str, idle: float,
                 rng: random.Random, op: SimHandleBase | None = None, has_last: bool = True):
        self.port = _Port(prefix, name, has_last)   # its checks of the block's tready
        self.clk, self.idle, self.rng, self.op = clk, idle, rng, op
        self.tvalid, self.tready = self.port.tvalid, self.port.tready
        self.tdata, self.tlast = self.port.tdata, self.port.tlast
        self.tvalid.value = 0

    async def send(self, beats: list[tuple[int, bool]] | list[tuple[int, bool, int | None]]
                   ) -> None:
        for data, last, *op in beats:
            while self.rng.random() < self.idle:
                self.tvalid.value = 0
                await RisingEdge(self.clk)
            if op and op[0] is not None:
                assert self.op is not None, "operands given but no op port"
                self.op.value = op[0]
            self.tvalid.value = 1
            self.tdata.value = data
            if self.tlast is not None:
                self.tlast.value = int(last)
            while True:
                await ReadOnly()
                ready = self.tready.value
                taken = ready == 1
                if not taken:
                    self.port._ready_defined(ready, _clock_number)
                await RisingEdge(self.clk)
                if taken:
                    break
        self.tvalid.value = 0


def _clock_number() -> int:
    """The clock period the simulation is in (from time 0): where no monitor counts clocks."""
    return int(get_sim_time("ns") // CLOCK_NS)


# ---- one coroutine for every port of a testbench ---------------------------------------------
#
# The classes above run a coroutine each and wake on every clock. StreamLoop does their jobs
# for several ports in one coroutine (one RisingEdge and one ReadOnly per clock instead of
# about seven wake-ups), and sleeps through clocks on which no beat can cross: a beat needs
# tvalid && tready at ReadOnly, so while one of them is low and only the block can raise it,
# a value change of that signal is what to wait for. Cycle numbers come from the simulation
# time, so a beat's cycle is exact whether or not the clocks before it were watched.


AWAKE, WATCH, IDLE = "awake", "watch", "idle"   # what a port needs from StreamLoop


class Source(_Port):
    """Drives a slave port of the block like StreamDriver: before each beat a random idle
    clock with probability `idle` (repeated), then the beat held until taken. Checks the
    block's tready on every clock it observes: never X or Z after reset."""

    def __init__(self, prefix: SimHandleBase, name: str, idle: float, rng: random.Random,
                 beats: list[tuple[int, bool]] | list[tuple[int, bool, int | None]],
                 op: SimHandleBase | None = None, has_last: bool = True):
        super().__init__(prefix, name, has_last)
        self.idle, self.rng, self.op = idle, rng, op
        self.beats: list[Beat] = []   # what crossed the bus
        self.done = Event()           # set once every beat was taken
        # for functional coverage (tb/coverage.py): idle clocks the testbench put before each
        # beat, and clocks each beat waited for the block's tready
        self.gaps: Counter[int] = Counter()
        self.waits: Counter[int] = Counter()
        self._offered_at: int | None = None
        self._todo = iter(beats)
        self._gap = 0                 # idle clocks before the next beat is presented
        self._state = "next"          # next (draw a gap) | gap | presenting | done
        self.tvalid.value = self._valid = 0
        self.watch = self.tready   # what the block drives and a sleeping loop waits on

    def drive(self) -> None:
        """After a clock edge: move on if the beat was taken, present the next one."""
        if self._state == "next":
            self._gap = 0
            while self.rng.random() < self.idle:
                self._gap += 1
            self.gaps[self._gap] += 1
            self._state = "gap"
        if self._state != "gap":
            return
        if self._gap:
            self._gap -= 1
        elif (beat := next(self._todo, None)) is not None:
            self._present(*beat)
            return
        else:
            self._state = "done"
            self.done.set()
        if self._valid:   # writes only on a change: each one costs the simulator
            self.tvalid.value = self._valid = 0

    def _present(self, data: int, last: bool, op: int | None = None) -> None:
        if op is not None:
            assert self.op is not None, "operands given but no op port"
            self.op.value = op
        self.tvalid.value = self._valid = 1
        self.tdata.value = data
        if self.tlast is not None:
            self.tlast.value = int(last)
        self._state = "presenting"

    def settled(self, cycle: Callable[[], int]) -> str:
        """At ReadOnly: record a beat; say whether the port needs the next clock (AWAKE), a
        change of its `watch` signal (WATCH) or nothing more (IDLE)."""
        ready = self.tready.value
        if self._state == "presenting" and self._offered_at is None:
            self._offered_at = cycle()
        if ready is _1 or (ready is not _0 and ready == 1):
            if self._state == "presenting" and self.tvalid.value == 1:
                self.beats.append(Beat(self.tdata.value.to_unsigned(), cycle(),
                                       self.tlast is not None and self.tlast.value == 1))
                self.waits[self.beats[-1].cycle - self._offered_at] += 1
                self._offered_at = None
                self._state = "next"
        else:
            if ready is not _0:
                self._ready_defined(ready, cycle)
            if self._state == "presenting":
                return WATCH    # the beat is held until the block raises tready
        return IDLE if self._state == "done" else AWAKE


class Sink(_Port):
    """Takes beats from a master port of the block like ReadyDriver + StreamMonitor: `tready`
    low with probability `stall` on every clock on which tvalid is high. Checks the protocol
    (_Port): it stays AWAKE on every clock with tvalid high, so the clock after a stalled beat
    is always observed, and a clock it sleeps through never follows one with a beat held."""

    def __init__(self, prefix: SimHandleBase, name: str, stall: float, rng: random.Random,
                 has_last: bool = True, hold: int = 0):
        super().__init__(prefix, name, has_last)
        self.stall, self.rng = stall, rng
        self.beats: list[Beat] = []
        # for functional coverage (tb/coverage.py): clocks each beat was offered and not taken
        self.waits: Counter[int] = Counter()
        self._stalled = 0
        # `hold`: the first beat offered waits this many clocks untaken (a consumer that comes
        # late), then tready is random as above
        self._hold = hold
        self._ready = 0 if stall >= 1 or hold > 0 else 1
        self.tready.value = self._ready
        self._want, self._got = 0, Event()
        self.watch = self.tvalid

    def drive(self) -> None:
        ready = 0 if self._hold > 0 or self.rng.random() < self.stall else 1
        if ready != self._ready:
            self.tready.value = self._ready = ready

    def settled(self, cycle: Callable[[], int]) -> str:
        valid = self.tvalid.value
        if valid is _1 or (valid is not _0 and valid == 1):
            ready = self.tready.value
            # X or Z in tdata or tlast is a violation, not a 0
            beat = self._offered(ready is _1 or (ready is not _0 and ready == 1), cycle)
            if beat is None:
                self._stalled += 1
                self._hold = max(0, self._hold - 1)
            else:
                self.waits[self._stalled] += 1
                self._stalled = 0
                self.beats.append(Beat(beat[0], cycle(), beat[1]))
                if len(self.beats) >= self._want:
                    self._got.set()
            return AWAKE       # a new random tready every clock while a beat is offered
        if valid is not _0 or self._held is not None:
            self._not_offered(valid, cycle)
        # sleep only with tready high: a block may need it to move even with tvalid low
        return WATCH if self._ready or self.stall >= 1 else AWAKE

    def wait(self, n: int) -> Trigger:
        """Fires once n beats have been taken."""
        self._want, self._got = n, Event()
        if len(self.beats) >= n:
            self._got.set()
        return self._got.wait()


class StreamLoop:
    """Runs Sources and Sinks on one clock in one coroutine (see above) until stop()."""

    def __init__(self, clk: SimHandleBase, ports: list[Source | Sink],
                 period_ns: float = CLOCK_NS):
        self.clk, self.ports = clk, ports
        self.period = get_sim_steps(period_ns, "ns")
        self._wake = Event()
        self._asleep = [False] * len(ports)   # per port: waiting for its `watch` to change
        self._tasks = [cocotb.start_soon(self._run())]
        # one watcher per port rather than First(): First starts tasks on every call
        self._tasks += [cocotb.start_soon(self._watch(k)) for k in range(len(ports))]

    async def _watch(self, k: int) -> None:
        change = ValueChange(self.ports[k].watch)
        while True:
            await change
            if self._asleep[k]:
                self._wake.set()

    async def _run(self) -> None:
        edge, settle = RisingEdge(self.clk), ReadOnly()
        await edge
        start = get_sim_time("step") - self.period   # the first clock is cycle 1

        def cycle() -> int:
            return (get_sim_time("step") - start) // self.period

        while True:
            for port in self.ports:
                port.drive()
            await settle
            states = [port.settled(cycle) for port in self.ports]
            if AWAKE in states:
                await edge
            else:   # no beat can cross until a watched signal changes
                self._asleep = [state == WATCH for state in states]
                self._wake.clear()
                await self._wake.wait()
                self._asleep = [False] * len(self.ports)

    def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for port in self.ports:
            if isinstance(port, Sink):
                port.tready.value = 1
