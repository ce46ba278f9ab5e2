"""What both weight testbenches share: the model run step by step (the operands are per step,
and the weights are relative to the best particle of the step so far) with each particle's
flags and each beat's rescale shift, and the corner runner."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import Flag
from gpf.model.fixed import Format
from gpf.model.formats import SHIFT_BITS, Const, Datapath, datapath
from gpf.tb.harness import Bench, start
from gpf.tb.scoreboard import Field
from gpf.tb.streaming import STEP, StreamBlock, idle_inputs, run_stream

# (particles (rows, n) in beat order, the step's operands) -> (raw weights (rows,), shift per
# beat (rows / lanes,), flags per particle (rows,)): the model block with per_particle=True
WeightFn = Callable[[np.ndarray, dict[str, int]], tuple[np.ndarray, np.ndarray, np.ndarray]]
SAT = Field("sat", Format(False, 1, 0))
SHIFT = Field("shift", Format(False, SHIFT_BITS, 0))


def step_model(fn: WeightFn, n: int, op_names: list[str]
               ) -> Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]:
    """The StreamBlock model: each step's particles (every lane) through `fn` with the step's
    operands; x0 .. x(n-1) passed through, w and sat per particle, the shift per beat."""

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        steps = seen[STEP]
        x = np.stack([seen[f"x{i}"] for i in range(n)], axis=-1)   # (beats, lanes, n)
        beats, lanes = x.shape[:2]
        w = np.zeros((beats, lanes), dtype=np.int64)
        sat = np.zeros((beats, lanes), dtype=np.int64)
        shift = np.zeros((beats, 1), dtype=np.int64)
        for s in np.unique(steps):
            idx = np.nonzero(steps == s)[0]
            rows = x[idx].reshape(-1, n)
            ops = {k: int(seen[k][idx[0]]) for k in op_names}
            weights, shifts, flags = fn(rows, ops)
            w[idx] = np.asarray(weights, dtype=np.int64).reshape(len(idx), lanes)
            shift[idx, 0] = shifts
            sat[idx] = (flags & Flag.SAT != 0).reshape(len(idx), lanes)
        return {**{f"x{i}": seen[f"x{i}"] for i in range(n)}, "w": w, "sat": sat,
                "shift": shift}

    return model


async def run_steps(dut: SimHandleBase, blk: StreamBlock, b: Bench,
                    steps: list[tuple[np.ndarray, dict[str, int]]], tag: str
                    ) -> dict[str, np.ndarray]:
    """Each step's particles (beats, lanes, n) with its operands through the block (bit-exact,
    light stalls); returns the model's outputs (beats, lanes) for the caller's own checks."""
    n = len(blk.fields_in)
    x = np.concatenate([rows for rows, _ in steps])
    lasts = []
    for rows, _ in steps:
        lasts += [False] * (len(rows) - 1) + [True]
    ops = {f.name: np.array([o[f.name] for _, o in steps], dtype=np.int64)
           for f in blk.fields_op}
    inputs = {f"x{i}": x[:, :, i] for i in range(n)}
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, inputs, lasts, 0.2, 0.2, tag, ops=ops)
    sb.assert_clean()
    step_no = np.repeat(np.arange(len(steps)), [len(rows) for rows, _ in steps])
    seen = dict(inputs, **{STEP: step_no}, **{k: v[step_no] for k, v in ops.items()})
    return blk.model(seen)


def spread_lanes(rows: np.ndarray, lanes: int) -> np.ndarray:
    """(k, n) particles as (k, lanes, n) beats: lane l carries the rows rotated by l, so every
    lane sees every particle."""
    k = len(rows)
    idx = (np.arange(k)[:, None] + np.arange(lanes)[None, :]) % k
    return rows[idx]


def wrong_c_u(dp: Datapath) -> Datapath:
    """The corrupted model's datapath: c_u one LSB too large."""
    c = dp.consts["c_u"]
    return dataclasses.replace(dp, consts={**dp.consts, "c_u": Const(c.value, c.raw + 1, c.frac)})


async def check_weights_span(dut: SimHandleBase, blk: StreamBlock, b: Bench, sc,
                             steps: int) -> None:
    """Steps of 32 random beats through the block (bit-exact), then the shares of the model's
    outputs on those beats: weights 0, strictly between, above 1/2, saturation, and rescales
    (a new best particle after the first beat) all occur."""
    lasts = ([False] * 31 + [True]) * steps
    ops = sc.operands(sum(lasts), "span")
    seen = sc.inputs(len(lasts), "span")
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, seen, lasts, 0.1, 0.1, f"{blk.name}-span", ops=ops)
    sb.assert_clean()
    step_no = np.repeat(np.arange(steps), 32)
    exp = blk.model({**seen, STEP: step_no, **{k: v[step_no] for k, v in ops.items()}})
    one_w, wv = 1 << datapath(b.cfg).weight.frac_bits, exp["w"]
    rescale = exp["shift"][:, 0].reshape(steps, 32)[:, 1:] > 0
    shares = {"zero": (wv == 0).mean(), "mid": ((wv > 0) & (wv < one_w)).mean(),
              "above_half": (wv > one_w // 2).mean(), "sat": exp["sat"].mean(),
              "rescale": rescale.mean()}
    dut._log.info("weight shares: %s", {k: round(float(v), 3) for k, v in shares.items()})
    assert shares["zero"] > 0.05 and shares["mid"] > 0.1 and shares["above_half"] > 0.01
    assert shares["sat"] > 0.001 and shares["rescale"] > 0.01
