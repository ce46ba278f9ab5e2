"""cocotb testbench of `grng`: every sample of every lane checked bit-exactly against GrngModel.

The model is fed from the seed words seen on the seed bus (not from what the driver meant to
send), the samples from what crossed the output bus; the scoreboard compares them in order.
"""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, ReadOnly, RisingEdge

from gpf.model.fixed import shift_round
from gpf.model.grng import COMPONENTS, GrngModel, GrngStream
from gpf.tb import coverage
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field, Scoreboard, unpack
from gpf.tb.stream import ReadyDriver, StreamMonitor


def samples_per_lane(b: Bench) -> int:
    return 200_000 if b.long else 10_000


def scoreboard(b: Bench, expect_mismatch: bool = False) -> Scoreboard:
    return Scoreboard("grng", [Field("z", b.cfg.noise)], expect_mismatch=expect_mismatch)


async def load_seed(dut: SimHandleBase, words: list[int], rng, gap: float = 0.3) -> None:
    """Send seed words on the seed bus, with random idle cycles between them."""
    for word in words:
        while rng.random() < gap:
            dut.s_seed_tvalid.value = 0
            await RisingEdge(dut.clk)
        dut.s_seed_tvalid.value = 1
        dut.s_seed_tdata.value = word
        await RisingEdge(dut.clk)
    dut.s_seed_tvalid.value = 0


async def collect(mon: StreamMonitor, n: int, max_clocks: int | None = None) -> list[int]:
    """Wait for n beats; fail (instead of hanging) when the block stops producing."""
    limit = max_clocks if max_clocks is not None else 20 * n + 1_000
    clocks = 0
    while len(mon.beats) < n:
        await RisingEdge(mon.clk)
        clocks += 1
        assert clocks <= limit, f"only {len(mon.beats)} of {n} samples after {limit} clocks"
    return [beat.data for beat in mon.beats[:n]]


def check(sb: Scoreboard, b: Bench, expected_raw: np.ndarray, words: list[int]) -> None:
    actual = unpack(words, sb.fields, b.cfg.lanes)
    sb.compare({"z": expected_raw[: len(words)]}, actual)
    if not sb.expect_mismatch:
        coverage.sample_grng(b.cfg.app, b.cfg.lanes, b.cfg.noise.to_real(actual["z"]))


async def idle_inputs(dut: SimHandleBase) -> None:
    dut.s_seed_tvalid.value = 0
    dut.s_seed_tdata.value = 0
    dut.m_axis_tready.value = 1


@cocotb.test()
async def test_reset_latency_throughput(dut: SimHandleBase) -> None:
    """From reset: the config's seed, first sample after LATENCY clocks, then one per clock."""
    b = bench()
    latency = b.manifest["modules"]["grng"]["latency"]
    await idle_inputs(dut)
    mon = StreamMonitor(dut.clk, dut, "m_axis")
    await start(dut, hold_reset=True)
    dut.rst.value = 0
    clocks = 0
    while True:
        await RisingEdge(dut.clk)
        clocks += 1
        await ReadOnly()
        if dut.m_axis_tvalid.value == 1:
            break
        assert clocks < 10 * latency, "no sample after reset"
    assert clocks == latency, f"first sample after {clocks} clocks, manifest says {latency}"

    n = 2_000
    words = await collect(mon, n)
    mon.stop()
    # throughput: n samples in n consecutive clocks (n + latency from reset)
    span = mon.beats[n - 1].cycle - mon.beats[0].cycle + 1
    assert span == n, f"{n} samples took {span} clocks without stalls"
    sb = scoreboard(b)
    check(sb, b, GrngModel(b.cfg).normals_raw(n), words)
    dut._log.info(sb.summary())
    sb.assert_clean()


@cocotb.test()
async def test_full_rate_after_stall(dut: SimHandleBase) -> None:
    """After the output stalled long enough to fill the block, it gives a sample every clock
    again the moment tready returns (the filter's step starts so): no bubble while the sources
    restart behind the stored samples."""
    b = bench()
    await idle_inputs(dut)
    dut.m_axis_tready.value = 0
    mon = StreamMonitor(dut.clk, dut, "m_axis")
    await start(dut)
    await ClockCycles(dut.clk, 100)
    assert not mon.beats
    dut.m_axis_tready.value = 1
    n = 500
    await collect(mon, n)
    mon.stop()
    span = mon.beats[n - 1].cycle - mon.beats[0].cycle + 1
    assert span == n, f"{n} samples took {span} clocks after a stall"
    sb = scoreboard(b)
    check(sb, b, GrngModel(b.cfg).normals_raw(n), [beat.data for beat in mon.beats[:n]])
    sb.assert_clean()


@cocotb.test()
@cocotb.parametrize(stall=[0.0, 0.3, 0.8])
async def test_seeded_stalls(dut: SimHandleBase, stall: float) -> None:
    """Seed loaded at run time (SEED), random output stalls: every sample of every lane exact."""
    b = bench()
    n = samples_per_lane(b) if stall == 0.3 else samples_per_lane(b) // 5
    model = GrngModel(b.cfg)
    await idle_inputs(dut)
    seed_mon = StreamMonitor(dut.clk, dut, "s_seed")
    await start(dut)
    await load_seed(dut, model.seed_words(b.seed), b.rng(f"seed-gaps-{stall}"))
    await ClockCycles(dut.clk, 2)
    seen = [beat.data for beat in seed_mon.beats]
    seed_mon.stop()
    assert len(seen) == COMPONENTS * b.cfg.lanes

    ready = ReadyDriver(dut.clk, dut.m_axis_tready, stall, b.rng(f"stall-{stall}"))
    mon = StreamMonitor(dut.clk, dut, "m_axis")
    words = await collect(mon, n)
    ready.stop()
    mon.stop()
    sb = scoreboard(b)
    check(sb, b, model.normals_raw_from_words(seen, n), words)
    dut._log.info("stall %.1f: %s (%d lanes x %d samples)", stall, sb.summary(),
                  b.cfg.lanes, n)
    sb.assert_clean()


@cocotb.test()
async def test_reseed_mid_stream(dut: SimHandleBase) -> None:
    """A seed load while samples flow: the old sequence up to it, nothing during it, then the
    new sequence from its first sample."""
    b = bench()
    model = GrngModel(b.cfg)
    await idle_inputs(dut)
    # a seed load flushes the samples stored (grng.sv.j2): one offered and not yet taken is
    # withdrawn at the load's first word, as a reset would
    mon = StreamMonitor(dut.clk, dut, "m_axis", restart=dut.s_seed_tvalid)
    seed_mon = StreamMonitor(dut.clk, dut, "s_seed")  # same clock count as `mon`
    await start(dut)
    ready = ReadyDriver(dut.clk, dut.m_axis_tready, 0.5, b.rng("reseed-stall"))
    await ClockCycles(dut.clk, 300)
    await load_seed(dut, model.seed_words(b.seed + 1), b.rng("reseed"))
    await collect(mon, len(mon.beats) + 1_000)
    ready.stop()
    mon.stop()
    seed_mon.stop()
    first, last = seed_mon.beats[0].cycle, seed_mon.beats[-1].cycle
    old = [beat.data for beat in mon.beats if beat.cycle <= first]
    during = [beat for beat in mon.beats if first < beat.cycle <= last]
    new = [beat.data for beat in mon.beats if beat.cycle > last]
    assert not during, f"{len(during)} samples left the block during the seed load"
    sb = scoreboard(b)
    check(sb, b, model.normals_raw(len(old)), old)
    sb.compare({"z": model.normals_raw(len(new), seed=b.seed + 1)},
               unpack(new, sb.fields, b.cfg.lanes), first_beat=len(old))
    dut._log.info("%s (%d before the load, %d after)", sb.summary(), len(old), len(new))
    sb.assert_clean()


# the tail bands a seed search looks for, as the coverage bins them (sign, index into
# coverage.SIGMAS): |z| in [4, 5) and beyond 5, each sign (a fixed seed draws there once in
# 3.2e-5 and 2.9e-7 samples a side: random runs miss them)
TAIL_BANDS = {"+4-5": (False, 4), "-4-5": (True, 4), "+5+": (False, 5), "-5+": (True, 5)}
TAIL_DRAWS = 2_000           # per lane after each seed load
TAIL_SEARCH = 40_000         # seeds tried, 512 at a time, before the search gives up


def in_band(z: np.ndarray, band: str) -> np.ndarray:
    """Samples in a tail band (tb/coverage.py's bins)."""
    negative, k = coverage.z_band(z)
    return (negative == TAIL_BANDS[band][0]) & (k == TAIL_BANDS[band][1])


def tail_seeds(model: GrngModel, noise, first: int) -> dict[str, int]:
    """The first seed from `first` on whose first TAIL_DRAWS samples (any lane) fall in each
    tail band, found with the bit-exact model."""
    found: dict[str, int] = {}
    for chunk in range(first, first + TAIL_SEARCH, 512):
        z = noise.to_real(GrngStream(model, list(range(chunk, chunk + 512))).next(TAIL_DRAWS))
        for band in TAIL_BANDS:
            inside = in_band(z, band).any(axis=(1, 2))
            if band not in found and inside.any():
                found[band] = chunk + int(np.argmax(inside))
        if len(found) == len(TAIL_BANDS):
            return found
    missing = sorted(set(TAIL_BANDS) - set(found))
    raise AssertionError(f"no seed in {first}..{first + TAIL_SEARCH} draws in {missing}")


@cocotb.test()
async def test_tail_bands(dut: SimHandleBase) -> None:
    """Seeds whose first samples reach |z| in [4, 5) and >= 5 on each side (searched with the
    model from the run's seed): each loaded, its samples checked bit-exactly, and the tail
    values must come out of the RTL."""
    b = bench()
    model = GrngModel(b.cfg)
    seeds = tail_seeds(model, b.cfg.noise, b.seed)
    await idle_inputs(dut)
    seed_mon = StreamMonitor(dut.clk, dut, "s_seed")
    await start(dut)
    sb, reached = scoreboard(b), set()
    for band, seed in sorted(seeds.items(), key=lambda kv: kv[1]):
        if band in reached:
            continue
        loaded = len(seed_mon.beats)
        await load_seed(dut, model.seed_words(seed), b.rng(f"tail-{seed}"))
        await ClockCycles(dut.clk, 2)
        seen = [beat.data for beat in seed_mon.beats[loaded:]]
        mon = StreamMonitor(dut.clk, dut, "m_axis")
        words = await collect(mon, TAIL_DRAWS)
        mon.stop()
        check(sb, b, model.normals_raw_from_words(seen, TAIL_DRAWS), words)
        z = b.cfg.noise.to_real(unpack(words, sb.fields, b.cfg.lanes)["z"])
        reached |= {k for k in TAIL_BANDS if in_band(z, k).any()}
        dut._log.info("seed %d (for %s): %s", seed, band, sb.summary())
    seed_mon.stop()
    sb.assert_clean()
    assert reached == set(TAIL_BANDS), f"the RTL's samples reached only {sorted(reached)}"


class TruncatingModel(GrngModel):
    """Deliberately wrong: drops the guard bits by truncation instead of rounding half up."""

    def _horner(self, addr: np.ndarray, x: np.ndarray) -> np.ndarray:
        xw = self.seg.offset_bits
        s1 = self._s1(addr, x)
        s2 = shift_round(s1 * x, xw, "half_up", width=62) + self.lut[addr, 0]
        return np.maximum(shift_round(s2, self.guard_bits, "truncate", width=62), 0)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """The scoreboard must fail a model that is wrong by one LSB now and then."""
    b = bench()
    await idle_inputs(dut)
    mon = StreamMonitor(dut.clk, dut, "m_axis")
    await start(dut)
    words = await collect(mon, 2_000)
    mon.stop()
    for wrong in (TruncatingModel(b.cfg).normals_raw(2_000),
                  np.roll(GrngModel(b.cfg).normals_raw(2_000), 1, axis=0)):  # one beat late
        sb = scoreboard(b, expect_mismatch=True)
        check(sb, b, wrong, words)
        assert sb.mismatched > 0, "a corrupted model passed the scoreboard"
        assert sb.first_mismatch is not None and "field z [" in sb.first_mismatch
        dut._log.info("corrupted model caught: %s", sb.first_mismatch)
