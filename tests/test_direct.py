"""The whole filter without cocotb (`gpf run --direct`, tb/gpf/direct.py): bit-exact with the
model, and each way it must fail does."""

from __future__ import annotations

from pathlib import Path

import pytest

from gpf.cli import main as gpf_main
from gpf.config import load_config
from gpf.run import RunArgs, run_filter
from gpf.tb.gpf import direct
from gpf.tb.gpf.filter import RunSpec

pytestmark = [pytest.mark.sim, pytest.mark.slow, pytest.mark.xdist_group("gpf-bot-direct")]


@pytest.fixture(scope="module")
def bot():
    """bot at LANES 1, built at -O0: these runs are a few steps, the build is most of it."""
    cfg = load_config("configs/bot.toml", {"filter.lanes": 1})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(direct, "OPT_FAST", "-O0")
        direct.build(cfg)
        yield cfg


def test_direct_run_is_bit_exact(bot) -> None:
    """gpf run's own path: every particle checked, each step's cycle count the period between
    results, the result JSON as the cocotb run writes it."""
    res = run_filter(bot, RunArgs(4, 256, 3, None, "verilator", False, direct=True),
                     progress=False)
    assert res["passed"] and res["mismatches"] == 0, res["first_mismatch"]
    assert res["particles_checked"] == 4 * 256 and res["values_checked"] > 4 * 256 * 5
    assert res["cycles_per_step"][1:] == res["period_per_step"]
    assert res["sim"] == "verilator direct" and res["metrics"]


def test_direct_stalls_repeat_from_the_seed(bot) -> None:
    """Half the clocks stalled on every stream: still bit-exact, slower, and the same seed
    stalls the same clocks again."""
    spec = RunSpec(steps=2, particles=128, seed=5, stall=0.5)
    first, again = direct.run(bot, spec), direct.run(bot, spec)
    calm = direct.run(bot, RunSpec(steps=2, particles=128, seed=5))
    assert first.mismatches == again.mismatches == 0
    assert first.cycles_per_step == again.cycles_per_step
    assert min(first.cycles_per_step) > max(calm.cycles_per_step)


def test_direct_catches_a_wrong_model(bot) -> None:
    res = direct.run(bot, RunSpec(steps=1, particles=64), corrupt=True)
    assert res.mismatches > 0 and "gpf_bot.cond" in res.first_mismatch


def test_direct_stops_on_a_hang(bot) -> None:
    """A result that does not come within the limit stops the run with what was seen."""
    with pytest.raises(direct.DirectError, match="no result for the limit of clocks"):
        direct.run(bot, RunSpec(steps=2, particles=64), limit=40)


def test_direct_refuses_what_it_cannot_run(capsys) -> None:
    for flags in (["--ip"], ["--gate"], ["--waves"], ["--sim", "icarus"]):
        assert gpf_main(["run", "--config", "bot", "--direct", "--json",
                         str(Path("build") / "unused.json"), *flags]) == 2
        assert "--direct" in capsys.readouterr().err


def test_direct_failure_is_a_verdict(bot, monkeypatch, capsys) -> None:
    """A run that stops on a check (here a hang) ends gpf run with FAILED, the reason and exit
    status 1, not an internal error."""
    monkeypatch.setattr(direct, "step_limit", lambda beats, stall: 40)
    assert gpf_main(["run", "--config", "bot", "--set", "filter.lanes=1", "--steps", "2",
                     "--particles", "64", "--direct", "--json",
                     str(Path("build") / "hang.json")]) == 1
    err = capsys.readouterr().err
    assert "FAILED" in err and "no result for the limit of clocks" in err
