"""Synthesis (Yosys) and place-and-route (nextpnr-ecp5): the smoke checks make test can afford.

The whole filters' area and clock are `make synth`/`make timing`/`make bench`; here one small
block shows the flow works, that its counts add up, that a design problem stops it, and that
the block's gate-level netlist passes its testbench while a netlist with one gate inverted fails.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gpf.cli import main
from gpf.config import load_config
from gpf.sim import run_sim
from gpf.synth import (
    COLUMNS,
    SynthError,
    area_from_stat,
    design_problems,
    gate_netlist,
    synth_files,
    synthesize,
)

pytestmark = pytest.mark.slow

BLOCK = "exp"        # the smallest block with a DSP, a table and a pipeline


def _stat(modules: dict[str, dict[str, int]]) -> dict:
    return {"modules": {f"\\{name}": {"num_cells_by_type": cells}
                        for name, cells in modules.items()}}


def test_area_multiplies_instances_down_the_hierarchy() -> None:
    stat = _stat({"top": {"lane": 2, "FDRE": 3, "LUT2": 1},
                  "lane": {"leaf": 3, "LUT6": 5, "RAMB18E1": 1},
                  "leaf": {"DSP48E1": 1, "CARRY4": 2, "FDSE": 1}})
    total, blocks = area_from_stat(stat, "top")
    assert total["LUT"] == 2 * 5 + 1 and total["DSP48E1"] == 6 and total["CARRY4"] == 12
    assert total["FF"] == 3 + 2 * 3 and total["BRAM36"] == 1    # two RAMB18 = one BRAM36
    assert set(blocks) == {"lane", "(top)"}
    for col in COLUMNS:
        assert sum(b[col] for b in blocks.values()) == total[col], col


def test_parameterised_variants_count_as_their_module() -> None:
    """Yosys names a module with parameters `$paramod\\name\\P=value` (or `$paramod$hash\\name`):
    each such block is reported under its module's name, its variants added up."""
    stat = _stat({"top": {"$paramod\\slice\\WIDTH=s32'01": 1, "$paramod\\slice\\WIDTH=s32'10": 2,
                          "$paramod$1a2b\\div": 1},
                  "$paramod\\slice\\WIDTH=s32'01": {"FDRE": 1},
                  "$paramod\\slice\\WIDTH=s32'10": {"FDRE": 2, "LUT3": 1},
                  "$paramod$1a2b\\div": {"CARRY4": 1}})
    _, blocks = area_from_stat(stat, "top")
    assert set(blocks) == {"slice", "div", "(top)"}
    assert blocks["slice"]["FF"] == 1 + 2 * 2 and blocks["slice"]["LUT"] == 2


def test_a_cell_type_no_column_counts_is_refused() -> None:
    with pytest.raises(SynthError, match="unknown type"):
        area_from_stat(_stat({"top": {"LUT6": 1, "URAM288": 1}}), "top")


def test_problem_warnings_are_told_apart_from_the_others() -> None:
    log = ("Warning: Replacing memory \\x with list of registers. See a.sv:3\n"
           "Warning: multiple conflicting drivers for top.\\y [0]\n"
           "Lexer warning: keyword `bit' (at /share/abc9_map.v:35)\n"
           "Warning: Resizing cell port top.u.a from 8 bits to 4 bits.\n")
    problems, others = design_problems(log)
    assert len(problems) == 2 and all("Replacing memory" in w for w in others)


@pytest.mark.parametrize("body, what", [
    ("always_latch if (en) q = d;", "latch"),
    ("assign q = d; assign q = en;", "driver"),
])
def test_a_design_problem_stops_synthesis(tmp_path: Path, body: str, what: str) -> None:
    src = tmp_path / "bad.sv"
    src.write_text("module bad(input logic en, input logic d, output logic q);\n"
                   f"  {body}\nendmodule\n")
    with pytest.raises(SynthError, match=what):
        synth_files([src], "bad", tmp_path / "synth")


def test_a_block_synthesizes_with_its_area_per_part(tmp_path: Path) -> None:
    cfg = load_config("configs/bot.toml")
    area = synthesize(cfg, BLOCK, build_root=tmp_path)
    assert area.total["LUT"] > 0 and area.total["FF"] > 0 and area.total["DSP48E1"] >= 1
    assert not area.warnings or all("Warning" in w for w in area.warnings)
    for col in COLUMNS:
        assert sum(b[col] for b in area.blocks.values()) == area.total[col], col
    saved = json.loads((tmp_path / cfg.name / "synth" / BLOCK / "area.json").read_text())
    assert saved["total"] == area.total and saved["lanes"] == 1


def test_gate_level_netlist_passes_and_one_inverted_gate_fails(tmp_path: Path) -> None:
    cfg = load_config("configs/bot.toml")
    good = run_sim(cfg, BLOCK, "verilator", gate=True, seed=3, build_root=tmp_path,
                   log_file=tmp_path / "gate.log")
    assert good.passed, (tmp_path / "gate.log").read_text()[-3000:]
    # invert the gate that drives one bit of the output word: every result changes
    mutant = gate_netlist(cfg, BLOCK, tmp_path, mutation=(
        "mutate -list 1 -seed 1 -mode inv -wire m_axis_tdata -wirebit 3 -o mutation.ys\n"
        "script mutation.ys\n"))
    assert mutant.read_text() != gate_netlist(cfg, BLOCK, tmp_path).read_text()
    bad = run_sim(cfg, BLOCK, "verilator", netlist=mutant, seed=3, build_root=tmp_path,
                  log_file=tmp_path / "mutant.log", extra_env={"GPF_FAIL_FAST": "1"})
    assert not bad.passed, "a netlist with an inverted gate passed its testbench"


@pytest.mark.regress
def test_weight_netlist_equals_the_model(tmp_path: Path) -> None:
    """The netlist that once differed from its RTL: Yosys 0.70 read -PW'(1 <<< k) as +2^k, and
    every whitened u saturated (rtl/templates/_weight.sv.j2, U_MIN). make regress: a minute
    (Yosys 20 s, Verilator's build of the 20 MB of C++ 30 s), the whole bot filter's netlist
    there covers it too."""
    result = run_sim(load_config("configs/bot.toml"), "weight_bot", "verilator", gate=True,
                     seed=4, build_root=tmp_path, log_file=tmp_path / "gate.log",
                     extra_env={"GPF_FAIL_FAST": "1", "TEST_LEVEL": "short"})
    assert result.passed, (tmp_path / "gate.log").read_text()[-3000:]


def test_timing_reports_fmax_and_the_critical_path(tmp_path: Path) -> None:
    from gpf.timing import place_and_route

    t = place_and_route(load_config("configs/bot.toml"), BLOCK, build_root=tmp_path, seed=2)
    assert t.log.parent.name == f"{BLOCK}-seed2"   # another seed, another folder: side by side
    assert 1 < t.fmax_mhz < 1000 and t.path_from != "?.?" and t.path_to != "?.?"
    assert t.utilisation["TRELLIS_FF"][0] > 0
    assert t.dsp_registers["dsps"] == t.utilisation["MULT18X18D"][0] > 0   # each one seen
    assert t.endpoints > 0 and 0 <= t.late <= t.endpoints
    if t.late:   # an arrival past the period fails the clock (the converse allows for setup)
        assert t.fmax_mhz < t.target_mhz, (t.late, t.fmax_mhz)
    assert sum(count for _, count, _ in t.late_groups) <= t.late


def test_late_endpoints_grouped_by_register() -> None:
    from gpf.timing import late_endpoints

    net = {"endpoints": [
        {"cell": "u.acc_q[3]_TRELLIS_FF_Q_12", "delay": [1.0, 9.5]},
        {"cell": "u.acc_q[7]_TRELLIS_FF_Q_3", "delay": [1.0, 8.2]},
        {"cell": "u.sum_q_TRELLIS_FF_Q", "delay": 7.9},
        {"cell": "u.hh_q[0]_TRELLIS_FF_Q_DI_MULT18X18D_P5", "delay": [2.0, 8.1]}]}
    assert late_endpoints({"detailed_net_timings": [net]}, 8.0) == (
        4, 3, [("u.acc_q[#]", 2, 9.5), ("u.hh_q[#]", 1, 8.1)])


def test_a_design_over_the_device_is_refused_before_placement() -> None:
    from gpf.timing import DEVICE_CELLS, over_capacity

    def design(dsps: dict[str, int]) -> dict:
        cells = {f"{block}.p{i}": {"type": "MULT18X18D"} for block, n in dsps.items()
                 for i in range(n)}
        return {"modules": {"top": {"cells": cells | {"u_a.q": {"type": "TRELLIS_FF"}}}}}

    limit = DEVICE_CELLS["MULT18X18D"]
    assert over_capacity(design({"u_a": limit - 10, "u_b": 10})) is None
    why = over_capacity(design({"u_a": limit - 10, "u_b": 11}))
    assert why and f"{limit + 1} MULT18X18D of {limit}" in why
    assert f"u_a {limit - 10}, u_b 11" in why


@pytest.mark.parametrize("argv, words", [
    (["synth", "--module", "nope"], "unknown"),
    (["synth", "--config", "bot", "--module", "propagate_uav"], "uav"),
    (["timing", "--module", "exp", "--freq", "0"], "--freq"),
    (["timing", "--module", "exp", "--seed", "0"], "--seed"),
])
def test_synth_and_timing_refuse_bad_input(argv: list[str], words: str, capsys) -> None:
    assert main(argv) == 2
    assert words in capsys.readouterr().err
