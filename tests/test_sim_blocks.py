"""Every block's testbench on both simulators, two configs, one and two lanes; waves; mutants.

Each run generates the RTL, builds it in build/<config>/<sim>/<module> and runs every cocotb
test of tb/<module>/test_<module>.py (bit-exact scoreboard, stalls, latency, corrupted model).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from gpf.config import load_config
from gpf.rtl.generate import TEMPLATE_DIR
from gpf.sim import run_sim
from gpf.toolchain import LZ4_HEADER, icarus_missing

pytestmark = [pytest.mark.sim, pytest.mark.slow]

SIMS = [
    pytest.param("verilator", id="verilator"),
    pytest.param("icarus", id="icarus", marks=pytest.mark.skipif(
        icarus_missing() is not None, reason=icarus_missing() or "")),
]


def waves_possible(sim: str) -> bool:
    return sim == "icarus" or LZ4_HEADER.exists()


MODULES = ["grng", "exp", "sqrt", "recip", "cordic_atan2"]


@pytest.mark.parametrize("sim", SIMS)
@pytest.mark.parametrize("config,lanes", [("bot", 1), ("bot", 2), ("odd", 1), ("odd", 2)])
@pytest.mark.parametrize("module", MODULES)
def test_block(module: str, sim: str, config: str, lanes: int) -> None:
    cfg = load_config(f"configs/{config}.toml", {"filter.lanes": lanes})
    waves = config == "bot" and lanes == 1 and waves_possible(sim)
    result = run_sim(cfg, module, sim, waves=waves, seed=1000 + lanes,
                     log_file=Path("build") / cfg.name / f"{module}-{sim}.log")
    assert result.passed, f"{result.failed}/{result.tests} failed: see {result.results_xml}"
    assert result.tests >= 6
    if waves:
        assert result.waves is not None and result.waves.stat().st_size > 0
        assert result.waves.with_suffix(".gtkw").exists()


# (module, template, text, replacement): one operator or constant changed in each
MUTANTS = {
    "grng-lfsr-xor": ("grng", "grng_lfsr258.sv.j2", "uniform_d = uniform_d ^ step[c];",
                 "uniform_d = uniform_d | step[c];"),
    "grng-horner-add": ("grng", "grng_icdf.sv.j2", ">>> XW) + {{ sext('c0_3_q'",
                   ">>> XW) - {{ sext('c0_3_q'"),
    "grng-rounding": ("grng", "grng_icdf.sv.j2", "(C2W+XW+1)'(1 <<< (XW-1))",
                      "(C2W+XW+1)'(1 <<< (XW-2))"),
    "grng-backpressure": ("grng", "grng.sv.j2", "assign advance = !m_axis_tvalid || m_axis_tready;",
                     "assign advance = !m_axis_tvalid | !m_axis_tready;"),
    "exp-interp-round": ("exp", "exp_lane.sv.j2", "(SW+RB+1)'(1 <<< (RB-1))",
                         "(SW+RB+1)'(1 <<< RB)"),
    "exp-underflow": ("exp", "exp_lane.sv.j2", "if (s > (NW+1)'($unsigned(MW))) begin",
                      "if (s >= (NW+1)'($unsigned(MW))) begin"),
    "exp-last": ("exp", "exp.sv.j2", "assign m_axis_tlast = last_q[LATENCY-1];",
                 "assign m_axis_tlast = last_q[LATENCY-2];"),
    "sqrt-digit-compare": ("sqrt", "sqrt_lane.sv.j2", "assign ge{{ k }} = p{{ k }} >= t{{ k }};",
                           "assign ge{{ k }} = p{{ k }} > t{{ k }};"),
    "recip-rounding": ("recip", "recip_lane.sv.j2",
                       "assign sum = {1'b0, quo_q} + {{ out_width + 1 }}'(rb_q);",
                       "assign sum = {1'b0, quo_q} + {{ out_width + 1 }}'(1'b0);"),
    # the last iteration only: its wrong turn moves the angle by 2 ANGLE[N-1], about 0.6 LSB
    "cordic-direction": ("cordic_atan2", "cordic_atan2_lane.sv.j2",
                         "assign up{{ i }} = y{{ i }}_q >= 0;",
                         "assign up{{ i }} = {{ '!' if loop.last else '' }}(y{{ i }}_q >= 0);"),
    "cordic-prerotation": ("cordic_atan2", "cordic_atan2_lane.sv.j2",
                           "(y[IW-1] ? MINUS_QUARTER : QUARTER)",
                           "(y[IW-1] ? QUARTER : MINUS_QUARTER)"),
    "cholesky-floor-compare": ("cholesky", "cholesky.sv.j2", "assign floored = dot < floor_v;",
                               "assign floored = dot <= floor_v;"),
    "cholesky-recip-rounding": ("cholesky", "cholesky.sv.j2",
                                "+ {{ qw + 1 }}'d1) >> 1);", "+ {{ qw + 1 }}'d0) >> 1);"),
    "cholesky-pivot-sub": ("cholesky", "cholesky.sv.j2",
                           "if (kk < int'(j_q)) dot = dot - ", "if (kk < int'(j_q)) dot = dot + "),
}


@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
@pytest.mark.parametrize("mutant", list(MUTANTS))
def test_mutated_template_fails(tmp_path: Path, mutant: str) -> None:
    module, template, old, new = MUTANTS[mutant]
    templates = tmp_path / "templates"
    shutil.copytree(TEMPLATE_DIR, templates)
    path = templates / template
    text = path.read_text()
    assert text.count(old) == 1, f"mutant {mutant}: '{old}' not found once in {template}"
    path.write_text(text.replace(old, new))
    result = run_sim(load_config("configs/bot.toml"), module, "icarus", seed=1,
                     template_dir=templates, build_root=tmp_path / "build",
                     log_file=tmp_path / "sim.log")
    assert result.tests > 0
    assert result.failed > 0, f"mutant {mutant} survived the {module} testbench"
