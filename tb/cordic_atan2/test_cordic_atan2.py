"""cocotb testbench of `cordic_atan2` (angle = atan2(y, x) in turns): every lane of every beat
against the Cordic model the block was generated from."""

from __future__ import annotations

import dataclasses

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.fixed import Format
from gpf.model.formats import datapath
from gpf.model.primitives import Cordic
from gpf.rtl.generate import cordic_model
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field
from gpf.tb.streaming import (
    Inputs,
    StreamBlock,
    check_latency_and_throughput,
    check_random_beats,
    idle_inputs,
    run_stream,
)


class Turns(Format):
    """A W-bit two's complement binary angle, one turn = 2^W: the raw bits of s0.(W-1) (half
    turns), shown by the scoreboard in turns."""

    def to_real(self, raw):
        return super().to_real(raw) / 2

    def __str__(self) -> str:
        return f"angle{self.width} (turns)"


def turns(width: int) -> Turns:
    return Turns(True, 0, width - 1)


def model_of(b: Bench) -> Cordic:
    """The block's model, checked against the constants the RTL was generated with."""
    c = cordic_model(b.cfg)
    k = b.manifest["modules"]["cordic_atan2"]["constants"]
    got = (k["in_width"], k["out_width"], k["iterations"], k["guard_bits"])
    assert got == (c.in_width, c.angle_frac, c.iterations, c.guard_bits), (got, c)
    assert c.in_width == datapath(b.cfg).x[0].width
    return c


def block(b: Bench, model: Cordic | None = None) -> StreamBlock:
    cordic = model or model_of(b)
    fmt = datapath(b.cfg).x[0]
    return StreamBlock(
        "cordic_atan2", [Field("x", fmt), Field("y", fmt)],
        [Field("angle", turns(cordic.angle_frac))], b.cfg.lanes,
        b.manifest["modules"]["cordic_atan2"]["latency"],
        lambda seen: {"angle": np.asarray(cordic.atan2(seen["y"], seen["x"]), dtype=np.int64)})


def random_xy(b: Bench, fmt: Format, n: int, tag: str) -> dict[str, np.ndarray]:
    """A third uniform over the whole plane; a third with x and y of independent random
    magnitudes (every bit length: near-axis angles, tiny vectors); a third sharing one random
    bit length (every angle at every vector length)."""
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    shape = (n, b.cfg.lanes)
    lo, hi = fmt.min_raw, fmt.max_raw

    def scaled(bits: np.ndarray) -> np.ndarray:  # uniform in [-2^bits, 2^bits), clipped
        top = np.left_shift(np.int64(1), bits)
        return np.clip(rng.integers(-top, top), lo, hi)

    kind = rng.integers(0, 3, size=shape)
    common = rng.integers(0, fmt.width, size=shape)
    out = {}
    for name in ("x", "y"):
        wide = rng.integers(lo, hi + 1, size=shape)
        own = scaled(rng.integers(0, fmt.width, size=shape))
        out[name] = np.choose(kind, [wide, own, scaled(common)])
    return out


def corner_pairs(fmt: Format) -> list[tuple[int, int]]:
    """(x, y): the origin, both axes both ways, x or y the most negative value, the extremes
    together, the diagonals, every vector with |x|, |y| <= 2."""
    lo, hi = fmt.min_raw, fmt.max_raw
    pairs = [(0, 0)]
    for m in (1, 2, 3, 1000, hi - 1, hi, lo):
        pairs += [(m, 0), (0, m), (-m, 0), (0, -m)] if m != lo else [(m, 0), (0, m)]
    for v in (0, 1, -1, 2, hi, lo, hi // 3, lo // 3):
        pairs += [(lo, v), (v, lo)]
    pairs += [(hi, hi), (lo, lo), (hi, lo), (lo, hi), (hi, hi - 1), (hi - 1, hi)]
    for m in (1, 2, 3, 7, 1000, hi // 2, hi):
        pairs += [(m, m), (m, -m), (-m, m), (-m, -m)]
    pairs += [(lo + 1, lo + 1), (lo + 1, hi), (hi, lo + 1)]
    pairs += [(x, y) for x in range(-2, 3) for y in range(-2, 3)]
    return list(dict.fromkeys(pairs))


def exact_angle(x: int, y: int, width: int) -> int | None:
    """The exact binary angle of (x, y) on an axis or diagonal (a multiple of 1/8 turn), else
    None; (0, 0) gives 0."""
    if x == 0 and y == 0:
        return 0
    if not (x == 0 or y == 0 or abs(x) == abs(y)):
        return None
    eighths = {(1, 0): 0, (1, 1): 1, (0, 1): 2, (-1, 1): 3, (-1, 0): -4, (-1, -1): -3,
               (0, -1): -2, (1, -1): -1}[(int(np.sign(x)), int(np.sign(y)))]
    return eighths << (width - 3)


def random_inputs(b: Bench, blk: StreamBlock) -> Inputs:
    """The random stimulus of the random-beats and throughput tests."""

    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        return random_xy(b, blk.fields_in[0].fmt, n, tag)

    return inputs


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random (x, y) with random input gaps and output stalls: every angle bit-exact, tlast
    carried."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b, blk), stalls)


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """Corner vectors, each in every lane; axes and diagonals also against their exact angle."""
    b = bench()
    blk = block(b)
    fmt, width = blk.fields_in[0].fmt, blk.fields_out[0].fmt.width
    pairs = corner_pairs(fmt)
    lanes = b.cfg.lanes
    # beat i, lane l carries pair (i + l) mod P: every lane sees every pair
    idx = (np.arange(len(pairs))[:, None] + np.arange(lanes)[None, :]) % len(pairs)
    xy = np.array(pairs, dtype=np.int64)
    inputs = {"x": xy[idx, 0], "y": xy[idx, 1]}
    idle_inputs(dut)
    await start(dut)
    sb, _, out = await run_stream(dut, blk, b, inputs, [False] * (len(pairs) - 1) + [True],
                                  0.2, 0.2, "cordic-corners")
    sb.assert_clean()
    checked = 0
    for beat_no, beat in enumerate(out.beats):
        for lane in range(lanes):
            x, y = pairs[idx[beat_no, lane]]
            want = exact_angle(x, y, width)
            if want is None:
                continue
            mask = (1 << width) - 1
            got = (beat.data >> (width * lane)) & mask
            assert got == want & mask, (
                f"atan2({y}, {x}) in lane {lane}: 0x{got:x}, exactly 0x{want & mask:x}")
            checked += 1
    dut._log.info("%d corner vectors, %d against their exact angle", len(pairs), checked)


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    blk = block(b)
    await check_latency_and_throughput(dut, blk, b, random_inputs(b, blk))


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """A deliberately wrong model, one iteration short (off by at most about one LSB)."""
    b = bench()
    good = model_of(b)
    blk = block(b, dataclasses.replace(good, iterations=good.iterations - 1))
    n = 1_000
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, random_xy(b, blk.fields_in[0].fmt, n, "bad"),
                                [False] * (n - 1) + [True], 0.2, 0.2, "cordic-bad",
                                expect_mismatch=True)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)
