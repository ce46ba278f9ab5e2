"""The whole filter (gpf_bot, gpf_uav) in RTL: short regressions on both simulators, `gpf run`
end to end, and template mutants of a block that the full-filter scoreboard must catch.

`make regress` runs the full 50-step regressions (tests marked `regress`).
"""

from __future__ import annotations

import json
import os
import random
import shutil
import time
from pathlib import Path

import pytest
import yaml
from test_sim_blocks import (
    MUTANTS,
    SIM_MARKS,
    mutant_params,
    mutated_templates,
    run_mutant,
    waves_possible,
)

from gpf.cli import main as gpf_main
from gpf.config import load_config
from gpf.sim import run_sim
from gpf.toolchain import icarus_missing

pytestmark = [pytest.mark.sim, pytest.mark.slow]

BUDGET = 256   # SPEC 9: a dependent step within N/LANES + 256 clocks

# (config, simulator, lanes, steps, particles): Verilator builds are slow and runs fast, Icarus
# the other way round. Short runs and faults build at -O0 (4-5 s less a build, the runs last a
# second) and share the build of their (config, LANES, simulator) on one pytest -n worker.
# Verilator builds the two whose builds the faults share; `odd` at LANES 2 and `uav` at LANES 1
# run all five tests in make regress (test_filter_regression, 50 steps); in make test `odd` at
# LANES 2 runs on Icarus (the faults), the uav filter at LANES 2 on both simulators.
SHORT_OPT = "-O0"
RUNS = [("bot", "verilator", 1, 5, 512), ("uav_seed002", "verilator", 2, 5, 512),
        ("bot", "icarus", 1, 3, 64), ("uav", "icarus", 2, 3, 64)]


def filter_run(config: str, sim: str, lanes: int, steps: int, particles: int, seed: int,
               scenario: str | None = None, testcase: str | None = None,
               build_root: Path = Path("build"), stall: float = 0.0,
               overrides: dict | None = None,
               verilator_opt: str | None = None, gate: bool = False,
               ip: bool = False, spec: dict | None = None) -> tuple[object, dict]:
    """`ip`: through gpf_<app>_axi, the filter as an IP block (AXI4-Lite, byte-wide streams);
    `spec`: more of the run's RunSpec fields."""
    cfg = load_config(f"configs/{config}.toml", {"filter.lanes": lanes, **(overrides or {})})
    module = f"gpf_{cfg.app}_axi" if ip else f"gpf_{cfg.app}"
    out = (build_root / cfg.name / sim / module / "regression.json").resolve()
    out.unlink(missing_ok=True)
    spec = {"steps": steps, "particles": particles, "seed": seed, "out": str(out),
            "scenario": scenario, "stall": stall, **(spec or {})}
    # the faults trace too: they share the short run's build, and Verilator rebuilds the
    # whole model (20 s) when --trace comes or goes
    waves = config in ("bot", "uav") and lanes == 1 and waves_possible(sim) and steps < 10 \
        and not ip
    result = run_sim(cfg, module, sim, waves=waves, seed=seed, testcase=testcase,
                     extra_env={"GPF_RUN": json.dumps(spec)}, build_root=build_root,
                     log_file=build_root / cfg.name / f"{module}-{sim}.log",
                     verilator_opt=verilator_opt, gate=gate)
    return result, json.loads(out.read_text()) if out.exists() else {}


def check_run(result, res: dict, steps: int, particles: int, lanes: int, tests: int = 5,
              stalled: bool = False) -> None:
    assert result.passed, f"{result.failed}/{result.tests} failed: see {result.results_xml}"
    assert result.tests == tests   # filter, stalls, reset mid-step, bad N, corrupted model
    assert res["mismatches"] == 0 and res["particles_checked"] == steps * particles
    assert len(res["cycles_per_step"]) == steps
    if not stalled:   # stalls stretch a step as long as they like
        assert max(res["cycles_per_step"]) <= particles // lanes + BUDGET, res["cycles_per_step"]


FILTER_TESTS = ("test_filter", "test_stalls", "test_reset_mid_step",
                "test_particle_count_out_of_range", "test_corrupted_model_is_caught")
# An N beyond the maximum runs a step of N = 2048: on Icarus the uav filter took 27 s for it
# in a make test, 57 % of that run. The bot filter on Icarus and both on Verilator run it.
SHORT_SKIPS = {("uav", "icarus", "test_particle_count_out_of_range")}


def build_group(config: str, sim: str, lanes: int) -> str:
    """The pytest -n group (--dist loadgroup) of the runs that share one build folder."""
    return f"gpf-{config}-lanes{lanes}-{sim}"


def shared_build(config: str, sim: str, lanes: int) -> list:
    """The marks that put the runs of one build on one pytest -n worker."""
    marks = [pytest.mark.xdist_group(build_group(config, sim, lanes))]
    return [*marks, SIM_MARKS[sim]] if SIM_MARKS[sim] else marks


@pytest.mark.parametrize("config,sim,lanes,steps,particles", [
    pytest.param(*run, marks=shared_build(*run[:3]), id=f"{run[0]}-lanes{run[2]}-{run[1]}")
    for run in RUNS])
def test_filter_short(config: str, sim: str, lanes: int, steps: int, particles: int) -> None:
    tests = [t for t in FILTER_TESTS if (config, sim, t) not in SHORT_SKIPS]
    began = time.time()
    result, res = filter_run(config, sim, lanes, steps, particles, seed=7,
                             testcase=",".join(tests), verilator_opt=SHORT_OPT)
    check_run(result, res, steps, particles, lanes, tests=len(tests))
    # the run's functional coverage (tb/gpf/coverage.py), for gpf coverage to merge: this
    # run's database (a name under another pytest -n grouping may be left from an older run)
    [db] = [p for p in Path("build/coverage/func").glob(
        f"test_filter_short*--gpf_*-{config}-lanes{lanes}-{sim}-seed7-*.yml")
        if p.stat().st_mtime >= began]
    app = load_config(f"configs/{config}.toml").app
    points = yaml.safe_load(db.read_text())

    def hits(point: str) -> dict[str, int]:
        return points[f"gpf.{app}.{point}"]["bins:_hits"]

    assert hits("lanes")[f"lanes {lanes}"] > 0, hits("lanes")
    # test_stalls' stall records (the harness's counts) and each tap's tlast reach their bins
    for port in ("m_cond", "m_part"):
        assert hits(f"stall.{port}")["wait 1"] > 0, hits(f"stall.{port}")
    assert hits("stall.s_step")["backpressure"] > 0, hits("stall.s_step")
    assert hits("tlast")["cond: last of many"] and hits("tlast")["part: last of many"]


# gpf_<app>_axi: the same whole-filter tests through the AXI4-Lite registers and the byte-wide
# streams, and its register tests (tb/gpf/test_gpf_axi.py); Verilator only (Icarus 11 cannot
# elaborate PeakRDL's structs)
IP_TESTS = FILTER_TESTS + ("test_register_reset_values", "test_register_access",
                           "test_run_status_and_interrupts")


@pytest.mark.xdist_group("gpf-ip-bot")
def test_ip_short() -> None:
    result, res = filter_run("bot", "verilator", 1, 3, 256, seed=7, verilator_opt=SHORT_OPT,
                             ip=True)
    check_run(result, res, 3, 256, 1, tests=len(IP_TESTS))


@pytest.mark.regress
@pytest.mark.parametrize("config,lanes,particles", [
    pytest.param("bot", 1, 2048, marks=pytest.mark.xdist_group("gpf-ip-bot")),
    pytest.param("uav", 2, 512, marks=pytest.mark.xdist_group("gpf-ip-uav"))])
def test_ip_regression(config: str, lanes: int, particles: int) -> None:
    result, res = filter_run(config, "verilator", lanes, 50, particles, seed=13, ip=True)
    check_run(result, res, 50, particles, lanes, tests=len(IP_TESTS))


# Each run shares its build folder (and the harness's record files in it) with the other runs
# of its config, LANES and simulator: shared_build keeps them on one pytest -n worker, one at a
# time (two at once in one folder read each other's records)
@pytest.mark.regress
@pytest.mark.parametrize("config,lanes,particles", [
    pytest.param(*run, marks=shared_build(run[0], "verilator", run[1]))
    for run in [("bot", 1, 2048), ("bot", 2, 2048), ("uav", 1, 2048), ("odd", 2, 1020),
                ("uav_seed002", 2, 1024)]])
def test_filter_regression(config: str, lanes: int, particles: int) -> None:
    result, res = filter_run(config, "verilator", lanes, 50, particles, seed=11)
    check_run(result, res, 50, particles, lanes)


# A long uav flight in RTL (make regress): bit-exact, and as good as float64 on the same draws
# over its last 20 % (README, "Robustness"); the seed is one the shipped words meet the bound on
LONG_UAV = {"steps": 3000, "particles": 256, "seed": 3}
LONG_RATIO_MAX = 1.05


@pytest.mark.regress
@pytest.mark.xdist_group(build_group("uav", "verilator", 1))
def test_uav_long_flight_quality() -> None:
    spec = LONG_UAV
    result, res = filter_run("uav", "verilator", 1, spec["steps"], spec["particles"],
                             seed=spec["seed"], testcase="test_filter")
    check_run(result, res, spec["steps"], spec["particles"], 1, tests=1)
    last = {name: res["metrics"][name]["last20"] for name in ("tilt", "velocity")}
    for name, m in last.items():
        assert m["rtl"] == m["fixed"], name
        assert m["rtl"] <= LONG_RATIO_MAX * m["float"], f"{name}: {m}"
    assert not res["lost_track"]


@pytest.mark.regress
def test_filter_gate_level_netlist() -> None:
    """The whole bot filter synthesized (Yosys, flattened generic gates, no initial values,
    flops starting random), under the same testbench: every particle bit-exact."""
    result, res = filter_run("bot", "verilator", 1, 3, 256, seed=5, testcase="test_filter",
                             gate=True)
    check_run(result, res, 3, 256, 1, tests=1)


# config odd (LANES 2) on Icarus: the build of the odd faults, so on their worker, one at a time
# (two workers building and running one folder at once broke a run)
@pytest.mark.xdist_group(build_group("odd", "icarus", 2))
@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
def test_gpf_run_cli(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r.json"
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


# Faults (SPEC 10): (config, scenario, lanes, particles, simulator, the flags expected at each
# step 1..5, config overrides). RTL and model must agree on estimates and flags (mismatches 0)
# and the filter must run to the end; the flags expected here follow from how each scenario is
# built.
ZW, SAT, NPD, LOW = "zero_weights", "sat", "not_pd", "low_ess"
FAULTS = {
    # one bearing a quarter turn off at step 3: no particle within reach there (equal weights,
    # a prediction), normal again after
    "bot-outlier": ("bot", "bot_outlier", 1, 128, "verilator", [[], [], [ZW], [], []], {}),
    "bot-outlier-icarus": ("odd", "bot_outlier", 2, 64, "icarus", [[], [], [ZW], [], []], {}),
    "uav-gps-glitch": ("uav_seed002", "uav_gps_glitch", 2, 128, "verilator",
                       [[], [], [ZW], [], []], {}),
    # a bearing 10 sigma off at step 3, within reach: the weights collapse onto a few
    # particles, the next step samples from the predicted covariance
    "bot-bearing-glitch": ("bot", "bot_bearing_glitch", 1, 128, "verilator",
                           [[], [], [LOW], [], []], {}),
    "bot-bearing-glitch-icarus": ("odd", "bot_bearing_glitch", 2, 64, "icarus",
                                  [[], [], [LOW], [LOW], []], {}),
    # positions beyond the format from step 2: saturated, then a collapsed (singular) spread
    "bot-far-target": ("bot", "bot_far_target", 1, 128, "verilator",
                       [[], [SAT], [SAT, NPD], [SAT, NPD], [SAT, NPD]], {}),
    # two particles: a rank-1 covariance every step (an ESS of 1 or 2 is not below N / 8)
    "uav-two-particles": ("uav_seed002", "uav_flight", 2, 2, "verilator", [[NPD]] * 5, {}),
}


@pytest.mark.parametrize("fault", [
    pytest.param(f, marks=shared_build(FAULTS[f][0], FAULTS[f][4], FAULTS[f][2])) for f in FAULTS])
def test_fault_flagged_and_survived(fault: str) -> None:
    config, scenario, lanes, particles, sim, flags, overrides = FAULTS[fault]
    result, res = filter_run(config, sim, lanes, 5, particles, seed=1, scenario=scenario,
                             testcase="test_filter", overrides=overrides,
                             verilator_opt=SHORT_OPT)
    check_run(result, res, 5, particles, lanes, tests=1)
    assert [sorted(f) for f in res["flags"]] == [sorted(f) for f in flags], res["flags"]
    if scenario == "bot_bearing_glitch":   # the glitch step's best particles come one by one
        assert res["rescales"] > 0, "no beat after a step's first brought a new best particle"


# bot's first result not taken for three steps' time (a step is N + about 300 clocks)
HELD = {"steps": 3, "seed": 3}


def held_spec(particles: int) -> dict:
    return {**HELD, "particles": particles, "est_hold": 3 * (particles + 300)}


def held_result_run(particles: int = 64) -> None:
    """bot's first result not taken for three steps' time: the second result waits in the
    controller (its S_OUT wait) until the first is taken, and every value is still right (the
    testbench checks that the hold did outlast the second step: FilterBench.check_held)."""
    spec = held_spec(particles)
    result, res = filter_run("bot", "verilator", 1, spec["steps"], particles, seed=spec["seed"],
                             testcase="test_filter", verilator_opt=SHORT_OPT,
                             spec={"est_hold": spec["est_hold"]})
    check_run(result, res, spec["steps"], particles, 1, tests=1, stalled=True)


@pytest.mark.xdist_group(build_group("bot", "verilator", 1))
def test_result_held_a_whole_step() -> None:
    held_result_run()


@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
def test_result_held_catches_a_controller_that_does_not_wait(tmp_path: Path) -> None:
    """The same hold against a ctrl whose S_OUT loads the output register without waiting for
    the held result (est_q's load enable, out_load_q's copy): the held beat changes under the
    testbench (an AXI4-Stream violation), or ctrl's simulation check of the copy stops it."""
    templates = mutated_templates(tmp_path, "ctrl-out-no-wait", "ctrl.sv.j2",
                                  "est_load_q <= out_load_d;", "est_load_q <= nx_out;")
    spec = held_spec(64)
    result = run_mutant("ctrl-out-no-wait", load_config("configs/bot.toml"), "gpf_bot", "icarus",
                        seed=spec["seed"], testcase="test_filter", template_dir=templates,
                        build_root=tmp_path / "build", log_file=tmp_path / "sim.log",
                        extra_env={"TEST_LEVEL": "short", "GPF_RUN": json.dumps(spec)})
    assert result is None or result.failed == 1, "a controller that does not wait passed"


# (module, template, text, replacement, scenario, config overrides[, testcase]): blocks'
# mutants the whole filter must catch as well, and the controller's and the top's own
FILTER_MUTANTS = {
    "moments-reference": (*MUTANTS["moments-reference"], None, {}),
    "moments-mean-rounding": (*MUTANTS["moments-mean-rounding"], None, {}),
    "weight-absolute-bot": ("weight_bot", "_weight.sv.j2",
                            *MUTANTS["weight-absolute"][2:], None, {}),
    # the moments' reference beat through propagate with a draw at its most negative, not zero
    "top-reference-noise": ("gpf_bot", "gpf.sv.j2", "{PEW'(0), ref_m_data}",
                            "{1'b1, (PEW-1)'(0), ref_m_data}", None, {}),
    "ctrl-result-reset": ("ctrl", "ctrl.sv.j2", "      est_q <= '0;\n", "", None, {}),  # X
    # the frozen posterior: a low-ESS step keeps the previous Sigma instead of its prediction
    "ctrl-low-ess-frozen": ("ctrl", "ctrl.sv.j2", "sigma_new_q <= sigma_pred_q;",
                            "sigma_new_q <= sigma_q;", None,
                            {"filter.ess_min": 1}),
    "ctrl-sticky": ("ctrl", "ctrl.sv.j2", "        sticky_q <= sticky_q | flags_q;",
                    "        sticky_q <= flags_q;", "bot_outlier", {}),
    # a register slice between blocks loses the beat it holds in its skid under backpressure
    "slice-skid": ("gpf_slice", "gpf_slice.sv.j2", "m_data <= skid_q ? skid_data_q : s_data;",
                   "m_data <= s_data;", None, {}, "test_stalls"),
    # the draws FIFO too shallow for sample_cond's beats: unchecked (CHECKED 0), it overwrites a
    # particle's process draws; the simulation-only check of its flags stops it ($fatal)
    "draws-fifo-depth": ("gpf_bot", "gpf.sv.j2", ".DEPTH_LOG2({{ fifo_depth_log2 }})",
                         ".DEPTH_LOG2(2)", None, {}),
    # AXI4-Stream protocol (tb/stream.py's checks): the estimate's LSB flipped only while m_est
    # is offered and not taken; every value checked at the handshake is right. test_stalls
    # stalls m_est half the clocks: five steps (a scenario given) for a result beat that stalls
    # (seed 1: the third; two steps would leave a quarter of seeds none)
    "ctrl-stall-est": ("ctrl", "ctrl.sv.j2", "assign m_est_tdata = est_q;",
                       "assign m_est_tdata = est_q ^ {{ est_w }}'(m_est_tvalid && !m_est_tready);",
                       "bot_fixed_observer", {}, "test_stalls"),
    # an X in the conditioning tap's last beat of a step while it is offered (Icarus keeps it):
    # the harness's check of tdata while tvalid is high
    "top-tap-x": ("gpf_bot", "gpf.sv.j2", "assign m_cond_tdata = sq_data;",
                  "assign m_cond_tdata = sq_data ^ {{ lanes * cond_lane_w }}'(sq_last ? 1'bx "
                  ": 1'b0);", None, {}),
    # the handshakes as flip-flops: the step's ready raised without the beat seen offered, so
    # ctrl takes a step nobody sent (a result too many, inputs that are not the step's)
    "ctrl-step-unseen": ("ctrl", "ctrl.sv.j2", "nx_ready && s_step_tvalid && !s_step_tready",
                         "nx_ready && !s_step_tready", None, {}),
    # a next-state flag that stays up as the state leaves (the simulation check against state_d)
    "ctrl-next-flag": ("ctrl", "ctrl.sv.j2", "(state_q == S_CHOL_WAIT && !chol_fire)",
                       "(state_q == S_CHOL_WAIT)", None, {}),
    # L taken without its last flag seen: the state moves on a beat the Cholesky never offered
    "ctrl-chol-unseen": ("ctrl", "ctrl.sv.j2", "assign chol_fire = s_chol_tready && chol_last_q;",
                         "assign chol_fire = (state_q == S_CHOL_WAIT || state_q == S_INIT_WAIT) "
                         "&& chol_last_q;", None, {}),
}


# make regress only (as the blocks' MUTANTS_IN_REGRESS): make test keeps a block's arithmetic
# and rounding seen through the filter, the controller's result reset and sticky flags, a slice's
# skid and the draws FIFO's depth under stalls
FILTER_MUTANTS_IN_REGRESS = ("weight-absolute-bot", "top-reference-noise", "top-tap-x",
                             "ctrl-low-ess-frozen", "ctrl-next-flag", "ctrl-stall-est",
                             "ctrl-chol-unseen", "ctrl-step-unseen")


@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
@pytest.mark.parametrize("mutant", mutant_params(FILTER_MUTANTS, FILTER_MUTANTS_IN_REGRESS))
def test_mutant_fails_the_filter(tmp_path: Path, mutant: str) -> None:
    module, template, old, new, scenario, overrides, *testcase = FILTER_MUTANTS[mutant]
    templates = mutated_templates(tmp_path, mutant, template, old, new)
    spec = {"steps": 5, "particles": 32, "scenario": scenario} if scenario else {}
    result = run_mutant(mutant, load_config("configs/bot.toml", overrides), "gpf_bot", "icarus",
                        seed=1, testcase=testcase[0] if testcase else "test_filter",
                        template_dir=templates, build_root=tmp_path / "build",
                        log_file=tmp_path / "sim.log",
                        extra_env={"TEST_LEVEL": "short", "GPF_RUN": json.dumps(spec)})
    if result is None:
        return
    assert result.tests == 1
    assert result.failed == 1, f"mutant {mutant} of {module} survived the whole filter"


# gpf_<app>_axi's mutants (template, old, new, the test that must fail): each must fail the IP's
# own checks (framing, registers, side effects) while the core is untouched
IP_MUTANTS = {
    "ip-est-tlast": ("gpf_axi.sv.j2", "assign m_est_tlast = 1'b1;",
                     "assign m_est_tlast = 1'b0;", "test_filter"),
    "ip-padding": ("gpf_axi.sv.j2",
                   "assign m_est_tdata = {{ padded('c_est_data', est_w, est_bytes) }};",
                   "assign m_est_tdata = {{ est_bytes * 8 }}'(c_est_data) | (1 << {{ est_w }});",
                   "test_filter"),   # bot's m_est: 849 bits in 107 bytes
    "ip-seed-stale": ("gpf_axi.sv.j2", "if (seed_push_q) begin",
                      "if (hwif_out.seed_hi.value.swmod) begin", "test_filter"),
    "ip-particles-from-stream": (
        "gpf_axi.sv.j2", "({s_init_tdata[{{ init_w - 1 }}:PW], hwif_out.particles.count.value})",
        "(s_init_tdata[{{ init_w - 1 }}:0])", "test_filter"),
    "ip-run-ignored": ("gpf_axi.sv.j2", "assign c_step_valid = s_step_tvalid && run;",
                       "assign c_step_valid = s_step_tvalid;", "test_run_status_and_interrupts"),
    "ip-soft-reset-unwired": ("gpf_axi.sv.j2",
                              "rst_q <= !aresetn || hwif_out.ctrl.soft_reset.value;",
                              "rst_q <= !aresetn;", "test_run_status_and_interrupts"),
    "ip-irq-unmasked": ("gpf_regs.rdl.j2",
                        "int_status.step_done->enable = int_enable.step_done;", "",
                        "test_run_status_and_interrupts"),
}


# make test: one of each kind (framing, the seed's path, the register description); make regress:
# the rest (a Verilator build each)
IP_MUTANTS_IN_TEST = ("ip-est-tlast", "ip-seed-stale", "ip-irq-unmasked")


@pytest.mark.parametrize("mutant", [
    pytest.param(m, marks=[] if m in IP_MUTANTS_IN_TEST else [pytest.mark.regress])
    for m in IP_MUTANTS])
def test_mutant_fails_the_ip(tmp_path: Path, mutant: str) -> None:
    template, old, new, testcase = IP_MUTANTS[mutant]
    templates = mutated_templates(tmp_path, mutant, template, old, new)
    spec = {"steps": 2, "particles": 32}
    result = run_sim(load_config("configs/bot.toml"), "gpf_bot_axi", "verilator", seed=1,
                     testcase=testcase, template_dir=templates, build_root=tmp_path / "build",
                     log_file=tmp_path / "sim.log", verilator_opt=SHORT_OPT,
                     extra_env={"TEST_LEVEL": "short", "GPF_RUN": json.dumps(spec)})
    assert result.tests == 1
    assert result.failed == 1, f"mutant {mutant} of gpf_bot_axi survived its tests"


# The stall campaign: GPF_CAMPAIGN_PARTICLES particles (make regress CAMPAIGN_PARTICLES=n), or
# 10^7 at TEST_LEVEL=long, split in pieces (conftest.py: two a shard of make regress SHARDS=k)
CAMPAIGN_PARTICLES = int(os.environ.get("GPF_CAMPAIGN_PARTICLES", "0")) or (
    10_000_000 if os.environ.get("TEST_LEVEL") == "long" else 0)
CONFIGS = ("bot", "odd", "uav", "uav_seed002")


@pytest.mark.campaign
@pytest.mark.skipif(not CAMPAIGN_PARTICLES,
                    reason="GPF_CAMPAIGN_PARTICLES (make regress CAMPAIGN_PARTICLES=) or "
                           "TEST_LEVEL=long only")
def test_stall_campaign(tmp_path: Path, campaign_piece: tuple[int, int]) -> None:
    """50 % random stalls on every stream of the whole filter, random configs (config, LANES,
    N, steps, seed, drawn from a generator seeded by the piece): nothing lost, duplicated or
    reordered, every particle bit-exact. Piece j of P checks ceil(CAMPAIGN_PARTICLES / P)
    particles and writes its count to build/campaign/piece-j-of-P.json."""
    piece, pieces = campaign_piece
    seed_text = f"campaign-{piece}-of-{pieces}"
    rng = random.Random(seed_text)
    budget = -(-CAMPAIGN_PARTICLES // pieces)
    summary = {"piece": piece, "pieces": pieces, "seed": seed_text, "budget": budget,
               "particles_checked": 0, "mismatches": 0, "runs": 0, "failed_runs": 0,
               "seconds": 0.0}
    report = Path("build") / "campaign" / f"piece-{piece}-of-{pieces}.json"
    report.parent.mkdir(parents=True, exist_ok=True)
    print(f"stall campaign piece {piece} of {pieces}: seed {seed_text!r}, {budget} particles",
          flush=True)
    start = time.monotonic()
    while summary["particles_checked"] < budget:
        config, lanes = rng.choice(CONFIGS), rng.choice((1, 2, 4))
        cfg = load_config(f"configs/{config}.toml", {"filter.lanes": lanes})
        # big runs: a Verilator build costs as much as checking ~150,000 particles
        particles = lanes * rng.randint(cfg.particles // lanes // 4, cfg.particles // lanes)
        steps = min(250, 500_000 // particles)
        seed = rng.randrange(1 << 30)
        run_dir = tmp_path / str(summary["runs"])
        result, res = filter_run(config, "verilator", lanes, steps, particles, seed,
                                 testcase="test_filter", build_root=run_dir, stall=0.5)
        summary["runs"] += 1
        summary["particles_checked"] += res.get("particles_checked", 0)
        summary["mismatches"] += res.get("mismatches", 0)
        summary["failed_runs"] += not result.passed
        summary["seconds"] = round(time.monotonic() - start, 1)
        # written after every run, a failed one too: CI sums what each piece got through
        report.write_text(json.dumps(summary, indent=1) + "\n")
        print(f"campaign piece {piece} of {pieces}: run {summary['runs']} {cfg.name} "
              f"N={particles} x {steps} steps seed {seed}: {res.get('particles_checked', 0)} "
              f"particles, total {summary['particles_checked']}", flush=True)
        check_run(result, res, steps, particles, lanes, tests=1, stalled=True)
        shutil.rmtree(run_dir, ignore_errors=True)
    rate = summary["particles_checked"] / max(summary["seconds"], 1e-9)
    print(f"stall campaign piece {piece} of {pieces}: {summary['particles_checked']} particles "
          f"checked in {summary['runs']} runs, {summary['seconds']} s ({rate:.0f} a second, "
          "builds included), 0 mismatches")
