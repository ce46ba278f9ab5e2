"""The whole filter (gpf_bot, gpf_uav) in RTL: short regressions on both simulators, `gpf run`
end to end, and template mutants of a block that the full-filter scoreboard must catch.

`make regress` runs the full 50-step regressions (tests marked `regress`).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from test_sim_blocks import MUTANTS, SIM_MARKS, waves_possible

from gpf.cli import main as gpf_main
from gpf.config import load_config
from gpf.rtl.generate import TEMPLATE_DIR
from gpf.sim import run_sim
from gpf.toolchain import icarus_missing

pytestmark = [pytest.mark.sim, pytest.mark.slow]

BUDGET = 256   # SPEC 9: a dependent step within N/LANES + 256 clocks

# (config, simulator, lanes, steps, particles): Verilator builds are slow and runs fast, Icarus
# the other way round
RUNS = [("bot", "verilator", 1, 5, 512), ("odd", "verilator", 2, 5, 512),
        ("uav", "verilator", 1, 5, 512), ("uav_seed002", "verilator", 2, 5, 512),
        ("bot", "icarus", 1, 3, 64), ("uav", "icarus", 2, 3, 64)]


def filter_run(config: str, sim: str, lanes: int, steps: int, particles: int,
               seed: int) -> tuple[object, dict]:
    cfg = load_config(f"configs/{config}.toml", {"filter.lanes": lanes})
    module = f"gpf_{cfg.app}"
    out = Path("build") / cfg.name / sim / module / "regression.json"
    out.unlink(missing_ok=True)
    spec = {"steps": steps, "particles": particles, "seed": seed, "out": str(out.resolve())}
    waves = config in ("bot", "uav") and lanes == 1 and waves_possible(sim) and steps < 10
    result = run_sim(cfg, module, sim, waves=waves, seed=seed,
                     extra_env={"GPF_RUN": json.dumps(spec)},
                     log_file=Path("build") / cfg.name / f"{module}-{sim}.log")
    return result, json.loads(out.read_text()) if out.exists() else {}


def check_run(result, res: dict, steps: int, particles: int, lanes: int) -> None:
    assert result.passed, f"{result.failed}/{result.tests} failed: see {result.results_xml}"
    assert result.tests == 3                     # filter, stalls, corrupted model
    assert res["mismatches"] == 0 and res["particles_checked"] == steps * particles
    assert len(res["cycles_per_step"]) == steps
    assert max(res["cycles_per_step"]) <= particles // lanes + BUDGET, res["cycles_per_step"]


@pytest.mark.parametrize("config,sim,lanes,steps,particles", [
    pytest.param(*run, marks=SIM_MARKS[run[1]], id=f"{run[0]}-lanes{run[2]}-{run[1]}")
    for run in RUNS])
def test_filter_short(config: str, sim: str, lanes: int, steps: int, particles: int) -> None:
    result, res = filter_run(config, sim, lanes, steps, particles, seed=7)
    check_run(result, res, steps, particles, lanes)


@pytest.mark.regress
@pytest.mark.parametrize("config,lanes,particles", [("bot", 1, 2048), ("bot", 2, 2048),
                                                   ("uav", 1, 2048), ("odd", 2, 1024),
                                                   ("uav_seed002", 2, 1024)])
def test_filter_regression(config: str, lanes: int, particles: int) -> None:
    result, res = filter_run(config, "verilator", lanes, 50, particles, seed=11)
    check_run(result, res, 50, particles, lanes)


@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
def test_gpf_run_cli(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r.json"
    # config odd: a build folder no other test of this file uses at the same time
    code = gpf_main(["run", "--config", "odd", "--sim", "icarus", "--steps", "2",
                     "--particles", "32", "--seed", "3", "--json", str(out),
                     "--plot", "build/plots"])   # CI keeps build/plots
    text = capsys.readouterr().out
    assert code == 0, text
    res = json.loads(out.read_text())
    assert res["steps"] == 2 and res["particles"] == 32 and res["particles_checked"] == 64
    assert res["mismatches"] == 0 and res["sim"] == "icarus" and res["seed"] == 3
    assert len(res["cycles_per_step"]) == 2
    assert set(res["rmse"]) == {"float", "fixed", "rtl"}
    assert res["rmse"]["rtl"] == res["rmse"]["fixed"]      # bit-exact estimates
    assert len(res["plots"]) == 2 and all(Path(p).stat().st_size > 0 for p in res["plots"])
    assert "mismatches 0" in text and "cycles per step" in text


@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
@pytest.mark.parametrize("mutant", ["moments-reference", "moments-mean-rounding"])
def test_block_mutant_fails_the_filter(tmp_path: Path, mutant: str) -> None:
    module, template, old, new = MUTANTS[mutant]
    templates = tmp_path / "templates"
    shutil.copytree(TEMPLATE_DIR, templates)
    path = templates / template
    path.write_text(path.read_text().replace(old, new))
    result = run_sim(load_config("configs/bot.toml"), "gpf_bot", "icarus", seed=1,
                     testcase="test_filter", template_dir=templates,
                     build_root=tmp_path / "build", log_file=tmp_path / "sim.log",
                     extra_env={"TEST_LEVEL": "short"})
    assert result.tests == 1
    assert result.failed == 1, f"mutant {mutant} of {module} survived the whole filter"
