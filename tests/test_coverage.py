"""Functional coverage (tb/coverage.py, gpf/coverage.py) and code coverage (gpf/code_coverage.py).

make test: a database written by the block sampler and merged, an unhit bin shown as a hole with
its reason, a hole without one failing `gpf coverage`; the code report's counts and holes from
coverage.dat files written here. make coverage-runs / make regress (marked `coverage`): the runs
that reach bins the other tests do not.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml

from gpf import code_coverage, coverage
from gpf.cli import main as gpf_main
from gpf.config import load_config
from gpf.model.fixed import Format
from gpf.tb import coverage as tb_coverage
from gpf.tb.scoreboard import Field
from gpf.tb.streaming import StreamBlock

S8 = Format(True, 3, 4)   # s3.4: raw -128 .. 127


class Recorded:
    """What a Source and a Sink of tb/stream.py record for coverage."""

    def __init__(self, gaps: dict[int, int], waits: dict[int, int]):
        self.gaps, self.waits = Counter(gaps), Counter(waits)


def selftest_block(name: str) -> StreamBlock:
    outs = [Field("x", S8), Field("sat", Format(False, 1, 0))]
    return StreamBlock(name, [Field("e", S8)], outs, 1, 1, model=lambda seen: seen)


def sample(block: StreamBlock, x: list[int], sat: list[int], lasts: list[bool]) -> None:
    got = {"x": np.array(x)[:, None], "sat": np.array(sat)[:, None]}
    tb_coverage.sample_block(block, "bot", 2, got, lasts, Recorded({0: 3, 2: 1}, {1: 1}),
                             Recorded({}, {0: 4}))


def test_database_written_merged_and_holes_explained(tmp_path: Path, monkeypatch) -> None:
    func = tmp_path / "cov" / "func"
    block = selftest_block("selftest_merge")
    monkeypatch.setenv(tb_coverage.FILE_ENV, str(func / "one.yml"))
    sample(block, [127, 5, 0, 3], [1, 0, 0, 0], [False, True, False, True])
    first = yaml.safe_load((func / "one.yml").read_text())
    assert first["selftest_merge.bot.rail"]["bins:_hits"] == {"x:max": 1, "x:min": 0}
    assert first["selftest_merge.bot.sat"]["bins:_hits"] == {"raised": 1, "cleared": 1}
    assert first["selftest_merge.bot.tlast"]["bins:_hits"]["2-8"] == 1
    # the second run's process database: the same groups, bins hit again and a new one
    monkeypatch.setenv(tb_coverage.FILE_ENV, str(func / "two.yml"))
    sample(block, [-128, 127, 1, 1], [0, 0, 0, 0], [True, True, True, True])

    holes = tmp_path / "holes.toml"
    holes.write_text('[holes]\n"selftest_merge.bot.lanes:lanes [14]" = "a self-test: '
                     'LANES 2 only"\n"selftest_merge.bot.stall.*" = "a self-test: no stalls"\n'
                     '"nothing.matches:this" = "stale"\n')
    groups = ["selftest_merge.bot", "selftest_absent.bot"]
    rep = coverage.build_report(tmp_path / "cov", holes, groups)
    hits = {b.key: b.hits for b in rep.bins}
    # merged = run one + run two, each file the cumulative database of its process
    assert hits["selftest_merge.bot.rail:x:max"] == 1 + 2
    assert hits["selftest_merge.bot.rail:x:min"] == 0 + 1
    assert hits["selftest_merge.bot.tlast:1"] == 0 + 1
    assert hits["selftest_merge.bot.lanes:lanes 2"] == 1 + 2
    holes_by_key = {b.key: b.reason for b in rep.holes}
    assert holes_by_key["selftest_merge.bot.lanes:lanes 4"] == "a self-test: LANES 2 only"
    assert holes_by_key["selftest_merge.bot.stall.s_axis:gap 1"] == "a self-test: no stalls"
    assert "selftest_merge.bot.stall.s_axis:backpressure" not in holes_by_key
    # a hole without a reason: the never-sampled group and the longest steps (this process's
    # database may hold the other self-test's group too)
    assert sorted(b.key for b in rep.unexplained if "_cli" not in b.key) == [
        "selftest_absent.bot:(never sampled)", "selftest_merge.bot.tlast:65+",
        "selftest_merge.bot.tlast:9-64"]
    assert rep.stale == ["nothing.matches:this"]
    assert rep.hit == len(rep.bins) - len(rep.holes) and rep.hit > 0

    md, js = coverage.write_report(rep, tmp_path / "cov", holes)
    assert "| `selftest_merge.bot.lanes:lanes 4` | a self-test: LANES 2 only |" in md.read_text()
    assert json.loads(js.read_text())["unexplained"] == [b.key for b in rep.unexplained]


def test_gpf_coverage_fails_on_a_hole_without_reason(tmp_path: Path, monkeypatch,
                                                     capsys) -> None:
    """The shipped expected groups are all missing from a database of one self-test block:
    every one needs a reason; an empty reason counts as none."""
    func = tmp_path / "cov" / "func"
    monkeypatch.setenv(tb_coverage.FILE_ENV, str(func / "run.yml"))
    sample(selftest_block("selftest_cli"), [0, 1], [0, 0], [False, True])
    holes = tmp_path / "holes.toml"
    holes.write_text('[holes]\n"*:(never sampled)" = "not run here"\n"selftest_*" = "ok"\n')
    args = ["coverage", "--dir", str(tmp_path / "cov"), "--holes", str(holes),
            "--code-holes", str(tmp_path / "none.toml")]
    assert gpf_main(args) == 0, capsys.readouterr().out
    holes.write_text('[holes]\n"*:(never sampled)" = "not run here"\n"selftest_merge.*" = "ok"\n'
                     '"selftest_cli.*" = " "\n')
    assert gpf_main(args) == 1
    out = capsys.readouterr().out
    assert "hole without a reason: selftest_cli.bot.lanes:lanes 1" in out
    report = (tmp_path / "cov" / "report.md").read_text()
    assert "## Holes without a reason" in report
    # make coverage-runs judges the code lines only: the same holes printed, not failed
    assert gpf_main([*args, "--judge", "code"]) == 0
    assert "hole without a reason: selftest_cli.bot.lanes:lanes 1" in capsys.readouterr().out


def dat_point(file: Path, line: int, kind: str, comment: str, inst: str) -> str:
    fields = {"f": str(file), "l": str(line), "n": "3", "t": kind, "page": f"v_{kind}/m",
              "o": comment, "h": inst}
    return "".join(f"\x01{k}\x02{v}" for k, v in fields.items())


def test_code_coverage_report(tmp_path: Path) -> None:
    """Two runs' coverage.dat: a line hit in one instance of one run counts as hit; a line hit
    nowhere is listed with its source text, explained or not; toggles counted apart."""
    src = tmp_path / "build" / "cfg" / "rtl" / "m.sv"
    src.parent.mkdir(parents=True)
    src.write_text("module m;\n  always_ff begin\n    a <= b;\n  end\n  $fatal(1, \"x\");\n"
                   "  c <= d;\nendmodule\n")
    dats = tmp_path / "cov" / "code" / "dat"
    dats.mkdir(parents=True)
    runs = [{(3, "line", "block", "u0"): 5, (3, "line", "block", "u1"): 0,
             (5, "line", "block", "u0"): 0, (6, "branch", "if", "u0"): 0,
             (1, "toggle", "a:0->1", "u0"): 2, (1, "toggle", "a:1->0", "u0"): 0},
            {(3, "line", "block", "u0"): 1, (5, "line", "block", "u0"): 0,
             (6, "branch", "if", "u0"): 0, (1, "toggle", "a:1->0", "u0"): 0}]
    for k, run in enumerate(runs):
        rows = [f"C '{dat_point(src, ln, kind, o, h)}' {c}\n"
                for (ln, kind, o, h), c in run.items()]
        (dats / f"r{k}.dat").write_text(code_coverage.DAT_HEADER + "".join(rows))
    holes = tmp_path / "code_holes.toml"
    holes.write_text('[[line]]\nfile = "*/rtl/m.sv"\ntext = "$fatal"\n'
                     'why = "a simulation-only check that never fires in a passing run"\n')
    rep = code_coverage.report(tmp_path / "cov", holes)
    assert rep is not None and rep.runs == 2
    assert (rep.lines_hit, rep.lines_total) == (1, 3)
    assert (rep.toggles_hit, rep.toggles_total) == (1, 2)
    assert [(u.line, u.reason is not None) for u in rep.unhit] == [(5, True), (6, False)]
    assert [u.file for u in rep.unexplained] == ["cfg/rtl/m.sv"]
    merged = code_coverage.read_dats([tmp_path / "cov" / "code" / "merged.dat"])
    assert merged[dat_point(src, 3, "line", "block", "u0")] == 6   # the runs' counts summed
    info = (tmp_path / "cov" / "code" / "coverage.info").read_text()
    assert f"SF:{src}" in info and "DA:3," in info
    assert "**not explained**" in (tmp_path / "cov" / "code" / "report.md").read_text()


def test_code_coverage_absent_without_runs(tmp_path: Path) -> None:
    assert code_coverage.report(tmp_path, tmp_path / "none.toml") is None


def test_particle_bins() -> None:
    from gpf.tb.gpf.coverage import particle_bins

    assert particle_bins(1, 1, 2048, None) == ["N = LANES"]
    assert particle_bins(68, 4, 2048, None) == ["N/LANES odd"]
    assert particle_bins(2048, 2, 2048, 4095) == ["N = maximum", "init N clamped down"]
    assert particle_bins(4, 4, 2048, 0) == ["N = LANES", "init N clamped up"]
    assert particle_bins(8, 4, 2048, 5) == ["N other", "init N rounded up"]


# ---- the runs added for coverage (make coverage-runs, make regress) ---------------------------

FILTER_TESTS = ("test_filter", "test_stalls", "test_reset_mid_step",
                "test_particle_count_out_of_range")
# (config, lanes, particles, steps): N / LANES odd at each LANES, and with the
# out-of-range test N = LANES and N = the maximum at LANES 2 and 4 too; 8 result beats for
# m_est's stalls (test_stalls stalls it half the clocks); the 24-bit uav config at the LANES its
# fault scenario runs, so its stall arms and init clamp are driven too
COVERAGE_RUNS = [("bot", 1, 33, 8), ("bot", 2, 34, 8), ("bot", 4, 68, 8),
                 ("uav", 1, 33, 8), ("uav", 2, 34, 8), ("uav", 4, 68, 8),
                 ("uav_seed002", 2, 34, 8)]
# whole-filter scenarios for the flags, the weights' collapse and the saturations
COVERAGE_FAULTS = [("bot", "bot_outlier"), ("bot", "bot_bearing_glitch"),
                   ("bot", "bot_far_target"), ("uav_seed002", "uav_gps_glitch")]


def _marks(config: str, lanes: int) -> list:
    from test_sim_filter import shared_build

    return [pytest.mark.regress, pytest.mark.coverage, pytest.mark.sim, pytest.mark.slow,
            *shared_build(config, "verilator", lanes)]


@pytest.mark.parametrize("config,lanes,particles,steps", [
    pytest.param(*run, marks=_marks(run[0], run[1]), id=f"{run[0]}-lanes{run[1]}-n{run[2]}")
    for run in COVERAGE_RUNS])
def test_coverage_filter_shapes(config: str, lanes: int, particles: int, steps: int) -> None:
    from test_sim_filter import SHORT_OPT, check_run, filter_run

    result, res = filter_run(config, "verilator", lanes, steps, particles, seed=21,
                             testcase=",".join(FILTER_TESTS), verilator_opt=SHORT_OPT)
    check_run(result, res, steps, particles, lanes, tests=len(FILTER_TESTS))


@pytest.mark.parametrize("config,scenario", [
    pytest.param(*f, marks=_marks(f[0], 1 if f[0] == "bot" else 2), id=f[1])
    for f in COVERAGE_FAULTS])
def test_coverage_filter_faults(config: str, scenario: str) -> None:
    from test_sim_filter import SHORT_OPT, check_run, filter_run

    lanes = 1 if config == "bot" else 2
    result, res = filter_run(config, "verilator", lanes, 6, 128, seed=1, scenario=scenario,
                             testcase="test_filter", verilator_opt=SHORT_OPT)
    check_run(result, res, 6, 128, lanes, tests=1)


@pytest.mark.parametrize("particles", [pytest.param(4, marks=_marks("bot", 1), id="bot-lanes1")])
def test_coverage_not_pd_recovers(particles: int) -> None:
    """NOT_PD raised and cleared in bot: four particles for four states (a weighted covariance
    of rank 3 at most, unless the weights spread it), so some steps regularise a pivot and the
    next need none. The flags are the RTL's, each checked against the model's."""
    from test_sim_filter import SHORT_OPT, check_run, filter_run

    result, res = filter_run("bot", "verilator", 1, 6, particles, seed=2,
                             scenario="bot_fixed_observer", testcase="test_filter",
                             verilator_opt=SHORT_OPT)
    check_run(result, res, 6, particles, 1, tests=1)
    not_pd = ["not_pd" in flags for flags in res["flags"]]
    assert any(a and not b for a, b in zip(not_pd, not_pd[1:], strict=False)), res["flags"]


@pytest.mark.parametrize("particles", [pytest.param(64, marks=_marks("bot", 1), id="bot-lanes1")])
def test_coverage_result_held(particles: int) -> None:
    """A result not taken for a whole step (ctrl's S_OUT wait): make test's
    test_result_held_a_whole_step, run here too for the coverage union."""
    from test_sim_filter import held_result_run

    held_result_run(particles)


# Targets at the edges of the bot state's format (a CSV scenario each, from the generator of
# bot_far_target): every component after sample_cond and after propagate at its top and its
# bottom, a saturation that clears (a target at the edge moving inward), and particles whose
# distance from the observer saturates up and down in x and y (the weight's own sat: observer
# and target on opposite edges). name: (initial mean (x, vx, y, vy), observer (x, y)) from the
# format's edge E.
EDGE_TARGETS = {
    "x-low": lambda e: ((-e + 6, -3.0, 1.0, 0.3), (0.0, 0.0)),
    "y-high": lambda e: ((1.0, 0.3, e - 6, 3.0), (0.0, 0.0)),
    "y-low": lambda e: ((1.0, 0.3, -e + 6, -3.0), (0.0, 0.0)),
    "vx-high-vy-low": lambda e: ((0.0, e - 0.01, 0.0, -e + 0.01), (0.0, 0.0)),
    "vx-low-vy-high": lambda e: ((0.0, -e + 0.01, 0.0, e - 0.01), (0.0, 0.0)),
    "x-inward": lambda e: ((e - 0.02, -3.0, 1.0, 0.3), (0.0, 0.0)),
    "observer-opposite": lambda e: ((e - 2, 0.3, e - 2, 0.3), (-e / 2, -e / 2)),
    "observer-opposite-low": lambda e: ((-e + 2, -0.3, -e + 2, -0.3), (e / 2, e / 2)),
}


@pytest.mark.parametrize("target", [pytest.param(t, marks=_marks("bot", 1))
                                    for t in EDGE_TARGETS])
def test_coverage_edge_targets(tmp_path: Path, target: str) -> None:
    from test_sim_filter import SHORT_OPT, check_run, filter_run

    from gpf.model.scenarios import bot_still_observer, write_csv

    cfg = load_config("configs/bot.toml")
    steps, edge = 4, float(cfg.formats["state"].max_real)
    mean, where = EDGE_TARGETS[target](edge)
    path = tmp_path / f"edge-{target}.csv"
    write_csv(bot_still_observer(cfg, steps, 5, f"edge-{target}", mean, where), path)
    result, res = filter_run("bot", "verilator", 1, steps, 64, seed=1, scenario=str(path),
                             testcase="test_filter", verilator_opt=SHORT_OPT)
    check_run(result, res, steps, 64, 1, tests=1)


# uav's velocities at the edges of their format (a CSV scenario each, built on uav_flight's
# noise-free shape): the attitude level and still (q = 1, no rotation), the accelerometer pushing
# the velocity out along (1, -1, 1) times `sign` with the GPS fix on the edge, then pulling it
# back in (a saturation that clears); or the particles on one edge and the GPS fix on the other
# (the weight's velocity difference saturates). name: (sign of the particles, of the GPS fix).
UAV_EDGES = {"uav-velocity-high": (1, 1), "uav-velocity-low": (-1, -1),
             "uav-gps-opposite": (-1, 1)}


def uav_edge_scenario(name: str, steps: int):
    from gpf.model.flight import G
    from gpf.model.scenarios import uav_flight

    cfg = load_config("configs/uav.toml")
    edge = float(cfg.formats["velocity"].max_real)
    part, gps = UAV_EDGES[name]
    d = np.array([1.0, -1.0, 1.0])
    sc = uav_flight(cfg, steps, 5)
    sc.mu0 = np.concatenate([[1.0, 0.0, 0.0, 0.0], part * d * (edge - 0.2)])
    lift = np.array([0.0, 0.0, G])           # what holds a level, still airframe up
    out = (np.arange(1, steps + 1) <= steps // 2) | (part != gps)
    sc.inputs["omega"][1:] = 0.0
    sc.inputs["accel"][1:] = np.where(out[:, None], part * 40.0, part * -60.0) * d + lift
    back = np.maximum(0, np.arange(1, steps + 1) - steps // 2) * 0.6 * (part == gps)
    sc.measurements["v_gps"][1:] = gps * d * (edge - back[:, None])
    sc.truth[:, :4] = [1.0, 0.0, 0.0, 0.0]
    sc.truth[1:, 4:] = sc.measurements["v_gps"][1:]
    sc.truth[0, 4:] = sc.mu0[4:]
    sc.meta.update(generator=f"edge-{name}")
    return sc


@pytest.mark.parametrize("name", [pytest.param(t, marks=_marks("uav", 2)) for t in UAV_EDGES])
def test_coverage_uav_edges(tmp_path: Path, name: str) -> None:
    from test_sim_filter import SHORT_OPT, check_run, filter_run

    from gpf.model.scenarios import write_csv

    steps = 6
    path = tmp_path / f"edge-{name}.csv"
    write_csv(uav_edge_scenario(name, steps), path)
    result, res = filter_run("uav", "verilator", 2, steps, 64, seed=1, scenario=str(path),
                             testcase="test_filter", verilator_opt=SHORT_OPT)
    check_run(result, res, steps, 64, 2, tests=1)


def laned_blocks() -> list:
    """(module, app, lanes): every laned block at LANES 4 in each application's config, and at
    LANES 1 in the second application's (the block matrix runs the first's at LANES 1 and 2,
    the second's at LANES 2)."""
    from gpf.rtl.generate import MODULES

    runs = [(name, app, lanes) for name, m in MODULES.items()
            if m.laned and not m.is_filter and m.simulated
            for k, app in enumerate(m.apps) for lanes in ((4,) if k == 0 else (1, 4))]
    return [pytest.param(*run, marks=[pytest.mark.regress, pytest.mark.coverage,
                                      pytest.mark.sim, pytest.mark.slow],
                         id=f"{run[0]}-{run[1]}-lanes{run[2]}") for run in runs]


@pytest.mark.parametrize("module,app,lanes", laned_blocks())
def test_coverage_block_lanes(module: str, app: str, lanes: int) -> None:
    """A laned block at a LANES the block matrix does not run for its application's default
    config (laned_blocks), a fifth of the beats."""
    from gpf.sim import run_sim

    cfg = load_config(f"configs/{app}.toml", {"filter.lanes": lanes})
    result = run_sim(cfg, module, "verilator", seed=1004,
                     log_file=Path("build") / cfg.name / f"{module}-verilator.log",
                     verilator_opt="-O0", extra_env={"TEST_LEVEL": "short"})
    assert result.passed, f"{result.failed}/{result.tests} failed: see {result.results_xml}"
