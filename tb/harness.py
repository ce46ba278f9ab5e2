"""What every cocotb testbench needs: its config, model inputs, clock, reset and seed."""

from __future__ import annotations

import functools
import json
import logging
import os
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cocotb
import cocotb.regression
from cocotb.clock import Clock
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, RisingEdge

from gpf.config import Config, load_config
from gpf.model.blocks import cov_pairs
from gpf.model.formats import Datapath, datapath

CLOCK_NS = 10


@dataclass(frozen=True)
class Bench:
    """The run's settings, passed by the runner in GPF_* environment variables."""

    cfg: Config
    manifest: dict[str, Any]
    seed: int
    long: bool
    short: bool = False   # TEST_LEVEL=short (or quick): a fifth of the default beats
    quick: bool = False   # TEST_LEVEL=quick (Icarus, mutants): a fiftieth of the random beats

    @functools.cached_property
    def dp(self) -> Datapath:
        """datapath(cfg), built once: it builds the primitives' tables, milliseconds a call."""
        return datapath(self.cfg)

    @functools.cached_property
    def pairs(self) -> list[tuple[int, int]]:
        """The covariance's Sigma entries (cov_pairs): what moments, cholesky and sample_cond
        compute with."""
        return cov_pairs(self.dp, self.cfg.covariance)

    def rng(self, salt: str) -> random.Random:
        """An independent, replayable random stream for one purpose (stalls, stimulus, ...)."""
        return random.Random(f"{self.seed}:{salt}")


def _failures_so_far() -> int:
    """Tests failed so far in this simulation (cocotb's regression manager: private, so 0 if
    it moved, and GPF_FAIL_FAST then merely runs everything)."""
    manager = getattr(cocotb.regression, "_manager_inst", None)
    return getattr(manager, "failures", 0)


def bench() -> Bench:
    """The run's settings. With GPF_FAIL_FAST set (template mutants: one failure is the verdict)
    every test after a failed one is skipped."""
    if os.environ.get("GPF_FAIL_FAST") and _failures_so_far() > 0:
        import pytest  # cocotb records pytest's skip as a skipped test

        pytest.skip("an earlier test failed (GPF_FAIL_FAST)")
    overrides = json.loads(os.environ.get("GPF_OVERRIDES", "{}"))
    cfg = load_config(os.environ["GPF_CONFIG"], overrides)
    manifest = json.loads(Path(os.environ["GPF_MANIFEST"]).read_text())
    level = os.environ.get("TEST_LEVEL", "default")
    # the run's seed as the user gave it (cocotb.RANDOM_SEED is re-mixed per test)
    seed = int(os.environ["COCOTB_RANDOM_SEED"])
    logging.getLogger("tb").info("SEED=%d (replay: make sim MODULE=%s CONFIG=%s SEED=%d)",
                                 seed, os.environ.get("GPF_MODULE", "?"), cfg.name, seed)
    return Bench(cfg, manifest, seed, level == "long", level in ("short", "quick"),
                 level == "quick")


async def start(dut: SimHandleBase, reset_cycles: int = 4, hold_reset: bool = False) -> None:
    """Start the clock and apply the synchronous reset for a few cycles.

    With hold_reset the reset is still high on return (the caller releases it and counts).
    """
    cocotb.start_soon(Clock(dut.clk, CLOCK_NS, unit="ns", impl="gpi").start())
    await reset(dut, reset_cycles, hold_reset)


async def reset(dut: SimHandleBase, reset_cycles: int = 4, hold_reset: bool = False) -> None:
    """The synchronous reset for a few cycles of a running clock."""
    dut.rst.value = 1
    await ClockCycles(dut.clk, reset_cycles)
    if not hold_reset:
        dut.rst.value = 0
        await RisingEdge(dut.clk)
