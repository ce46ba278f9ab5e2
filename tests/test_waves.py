"""Tests of the wave views (gpf.rtl.waves) and of where waves runs build and write their dumps
(gpf.sim): nothing here simulates or opens a window."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

import gpf.rtl.waves as waves
import gpf.sim
from gpf import cli
from gpf.config import load_config
from gpf.model.formats import datapath
from gpf.rtl.generate import generate
from gpf.rtl.gtkw import Bits, Dump, Group, Trace, Window
from gpf.sim import SimResult, run_sim, sim_build_dir
from gpf.tb.harness import CLOCK_NS
from gpf.toolchain import ToolchainError

BOT = load_config(Path("configs/bot.toml"))
UAV = load_config(Path("configs/uav.toml"))
CLOCK = CLOCK_NS * 1000  # ps


def traces(groups: list) -> list:
    out = []
    for item in groups:
        out += traces(item.traces) if isinstance(item, Group) else [item]
    return out


def group(groups: list, name: str) -> Group:
    for item in groups:
        if isinstance(item, Group):
            if item.name == name:
                return item
            try:
                return group(item.traces, name)
            except KeyError:
                pass
    raise KeyError(name)


# --- the build folder of a waves run -------------------------------------------------------------


@pytest.mark.parametrize("sim", ["verilator", "icarus"])
def test_waves_build_apart_from_the_plain_build(sim):
    # one folder for both rebuilt the model each time waves were switched on or off
    plain = sim_build_dir(Path("build/bot"), sim, "moments")
    waved = sim_build_dir(Path("build/bot"), sim, "moments", waves=True)
    assert plain == Path(f"build/bot/{sim}/moments")
    assert waved == Path(f"build/bot/{sim}/moments-waves")
    assert sim_build_dir(Path("c"), sim, "exp", "gate", waves=True) == \
        Path(f"c/{sim}-gate/exp-waves")
    assert waves.waves_dir(BOT, sim, "moments") == Path(f"build/bot/{sim}/moments-waves")


@pytest.mark.parametrize("sim", ["verilator", "icarus"])
@pytest.mark.parametrize("with_waves", [False, True])
def test_run_sim_builds_and_dumps_where_waves_looks(monkeypatch, tmp_path, sim, with_waves):
    """run_sim with a fake cocotb runner: the folder it builds in, and the dump it reports is the
    one `gpf waves` opens."""
    built: list[Path] = []

    class Runner:
        def build(self, *, build_dir, waves, build_args, **kw):
            built.append(Path(build_dir))
            assert waves == with_waves
            assert ("--trace-fst" in build_args) == (with_waves and sim == "verilator")

        def test(self, *, build_dir, test_args, plusargs, results_xml, **kw):
            return results_xml

    import cocotb_tools.runner

    monkeypatch.setattr(cocotb_tools.runner, "get_runner", lambda name: Runner())
    monkeypatch.setattr(cocotb_tools.runner, "get_results", lambda xml: (1, 0))
    monkeypatch.setattr(gpf.sim, "check_simulator", lambda *a: None)
    monkeypatch.setattr(gpf.sim, "generate", lambda cfg, out, template_dir: SimpleNamespace(
        files={"moments": [out / "moments.sv"]}, out_dir=out, harnesses={}))
    monkeypatch.setattr(gpf.sim, "_runtime_cache", lambda args: tmp_path / "runtime")
    monkeypatch.setattr(gpf.sim, "_keep_runtime", lambda *a: None)
    views: list[Path] = []
    monkeypatch.setattr(waves, "write_view",
                        lambda cfg, module, sim, fst, netlist=False: views.append(fst))
    result = run_sim(BOT, "moments", sim, waves=with_waves, seed=1, build_root=tmp_path)
    expected = sim_build_dir((tmp_path / "bot").resolve(), sim, "moments", waves=with_waves)
    assert built == [expected]
    if with_waves:
        fst = waves.waves_dir(BOT, sim, "moments", tmp_path).resolve() / "moments.fst"
        assert result.waves == fst and views == [fst]
    else:
        assert result.waves is None and views == []


# --- the hints printed around a waves run --------------------------------------------------------


def test_sim_hint_names_the_simulator(monkeypatch, tmp_path, capsys):
    # `make waves` without SIM= opens Verilator's waves: an Icarus run must say SIM=icarus
    fst = tmp_path / "moments.fst"
    monkeypatch.setattr(gpf.sim, "run_sim", lambda cfg, module, sim, **kw: SimResult(
        module, sim, 7, 1, 0, tmp_path / "results.xml", fst))
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")
    for sim, word in (("icarus", "icarus"), ("verilator", None)):
        assert cli.main(["sim", "--config", "bot", "--module", "moments", "--sim", sim,
                         "--waves"]) == 0
        (line,) = [ln for ln in capsys.readouterr().out.splitlines() if "waves:" in ln]
        assert str(fst) in line
        if word:
            assert "SIM=icarus" in line or "--sim icarus" in line
        else:
            assert "icarus" not in line


def test_lz4_message_offers_icarus(monkeypatch, tmp_path):
    import gpf.toolchain

    monkeypatch.setattr(gpf.toolchain, "verilator_version", lambda: (9, 0))
    monkeypatch.setattr(gpf.toolchain, "LZ4_HEADER", tmp_path / "missing" / "lz4.h")
    with pytest.raises(ToolchainError) as err:
        gpf.toolchain.check_verilator(waves=True)
    assert "liblz4-dev" in str(err.value) and "SIM=icarus" in str(err.value)


# --- gpf waves: finding the dump, a display, GTKWave ---------------------------------------------


@pytest.fixture
def last_run(monkeypatch, tmp_path) -> tuple[Path, Path]:
    """A waves run's dump where `gpf waves` looks (run from tmp_path); the view is a stub."""
    monkeypatch.chdir(tmp_path)
    fst = waves.waves_dir(BOT, "icarus", "moments") / "moments.fst"
    fst.parent.mkdir(parents=True)
    fst.write_bytes(b"")
    gtkw = fst.with_suffix(".gtkw")
    monkeypatch.setattr(waves, "write_view", lambda cfg, module, sim, path: gtkw)
    return fst, gtkw


def no_gtkwave_call(*args, **kwargs):
    raise AssertionError("GTKWave started without a display: it prints its usage and exits 0")


@pytest.mark.parametrize("installed", [True, False])
def test_no_display_no_gtkwave(monkeypatch, capsys, last_run, installed):
    fst, gtkw = last_run
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.setattr(waves.shutil, "which", lambda name: "/usr/bin/gtkwave" if installed
                        else None)
    monkeypatch.setattr(subprocess, "call", no_gtkwave_call)
    assert waves.open_waves(BOT, "moments", "icarus") == 0
    (line,) = capsys.readouterr().out.splitlines()  # one line
    assert str(fst) in line and str(gtkw) in line and "needs a display" in line
    assert ("apt-get install gtkwave" in line) != installed


def test_no_launch_writes_the_view_only(monkeypatch, capsys, last_run):
    fst, gtkw = last_run
    monkeypatch.setattr(subprocess, "call", no_gtkwave_call)
    assert waves.open_waves(BOT, "moments", "icarus", launch=False) == 0
    assert capsys.readouterr().out.split() == ["waves:", str(fst), "view:", str(gtkw)]


@pytest.mark.parametrize(("platform", "display"), [("linux", ":0"), ("darwin", None)])
def test_display_opens_gtkwave_and_reports_its_failure(monkeypatch, last_run, platform,
                                                       display):
    fst, gtkw = last_run
    monkeypatch.setattr(sys, "platform", platform)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if display:
        monkeypatch.setenv("DISPLAY", display)
    else:
        monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.setattr(waves.shutil, "which", lambda name: "/usr/bin/gtkwave")
    calls = []
    status = 0
    monkeypatch.setattr(subprocess, "call", lambda argv: calls.append(argv) or status)
    assert waves.open_waves(BOT, "moments", "icarus") == 0
    assert calls == [["gtkwave", str(fst), str(gtkw)]]
    status = 1
    with pytest.raises(ToolchainError, match="exit status 1"):
        waves.open_waves(BOT, "moments", "icarus")


def test_display_without_gtkwave_says_how_to_install(monkeypatch, last_run):
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.setattr(waves.shutil, "which", lambda name: None)
    with pytest.raises(ToolchainError, match="apt-get install gtkwave"):
        waves.open_waves(BOT, "moments", "icarus")


def test_no_dump_says_which_run_makes_it(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ToolchainError) as err:
        waves.open_waves(BOT, "moments", "icarus")
    message = str(err.value)
    assert "moments-waves" in message and "--sim icarus" in message and "--waves" in message


# --- the whole filter's view ---------------------------------------------------------------------


def test_state_names_from_ctrl_template():
    names = waves._state_names()
    values = dict(names.values)
    assert values[0] == "S_IDLE" and "S_OUT" in values.values()
    assert sorted(values) == list(range(len(values)))
    assert all(re.fullmatch(r"S_[A-Z_]+", name) for name in values.values())


def test_state_names_reject_a_changed_enum(tmp_path):
    bad = tmp_path / "ctrl.sv.j2"
    bad.write_text("typedef enum logic [3:0] { IDLE = 4'd3, RUN } state_t;")
    with pytest.raises(ValueError, match="S_ names"):
        waves._state_names(bad)
    bad.write_text("typedef enum { A } other_t;")
    with pytest.raises(ValueError, match="state_t"):
        waves._state_names(bad)


@pytest.mark.parametrize("cfg", [BOT, UAV], ids=["bot", "uav"])
def test_filter_view_holds_what_a_debugger_needs(cfg):
    view = waves.filter_view(cfg, "verilator")
    dp = datapath(cfg)
    pairs = dp.n * (dp.n + 1) // 2
    assert len(group(view, "L").traces) == pairs
    assert len(group(view, "Sigma").traces) == len(
        [t for t in traces([group(view, "init (s_init): N, mu0, Sigma0")])
         if t.label.startswith("Sigma")])
    assert all(t.frac_bits is not None for t in group(view, "Sigma").traces + group(
        view, "L").traces)
    (state,) = [t for t in traces(view) if isinstance(t, Trace) and t.label == "state"]
    assert state.path.endswith("u_ctrl.state_q") and state.names == waves._state_names()
    streams = group(view, "streams: valid and ready").traces
    assert all(isinstance(b, Bits) and b.names == waves.HANDSHAKE for b in streams)
    labels = [b.label for b in streams]
    for a, b in [("grng", "sample_cond"), ("sample_cond", "propagate"),
                 ("propagate", "weight"), ("weight", "moments"), ("moments", "ctrl"),
                 ("ctrl", "cholesky"), ("cholesky", "ctrl"), ("ctrl", "sigma_predict")]:
        assert f"{a} -> {b}" in labels
    for name in ("init (s_init): N, mu0, Sigma0", "seed (s_seed)"):
        assert group(view, name).traces
    assert [g.name for g in view][:3] == ["controller", "streams: valid and ready",
                                          "result (m_est)"]


def test_bearing_has_a_unit():
    (z,) = [t for t in traces(group(waves.filter_view(BOT, "icarus"), "step input (s_step)")
                              .traces) if t.label.startswith("bearing")]
    assert "pi rad" in z.label
    dp = datapath(BOT)
    # the raw bearing is in turns at angle_frac fraction bits: shown / 2^(aw-1) = rad / pi
    assert z.frac_bits == dp.angle_frac - 1 and z.signed


@pytest.mark.parametrize("cfg", [BOT, UAV], ids=["bot", "uav"])
def test_filter_view_signals_exist_in_the_generated_rtl(cfg, tmp_path):
    """Every signal the view names is declared in gpf_<app>.sv or ctrl.sv as generated."""
    generate(cfg, tmp_path, modules=[f"gpf_{cfg.app}"])
    top = f"gpf_{cfg.app}"
    sources = {top: (tmp_path / f"{top}.sv").read_text(),
               f"{top}.u_ctrl": (tmp_path / "ctrl.sv").read_text()}
    paths = set()
    for item in traces(waves.filter_view(cfg, "verilator")):
        paths |= set(item.paths) if isinstance(item, Bits) else {item.path}
    for path in paths:
        where, _, name = path.rpartition(".")
        declared = rf"\b(input|output|logic|state_t)\b[^;]*\b{name}\b"
        assert re.search(declared, sources[where]), path


def test_ip_view_holds_the_core_once():
    view = waves.ip_view(BOT, "verilator")
    names = [g.name for g in view]
    assert names.count("controller") == 1 and "clock and reset" not in names
    (state,) = [t for t in traces(view) if isinstance(t, Trace) and t.label == "state"]
    assert state.path == "gpf_bot_axi.u_core.u_ctrl.state_q"


FILTER_VCD = """$timescale 1ps $end
$scope module gpf_bot_harness $end
$scope module u_core $end
$var wire 1 ! s_step_tvalid $end
$var wire 1 " s_step_tready $end
$var wire 1 # m_est_tvalid $end
$var wire 1 $ m_est_tready $end
$upscope $end
$upscope $end
$enddefinitions $end
#0
0!
0"
0#
1$
#1000
1!
#2000
1"
#2010
0"
#6000
1#
1"
#6010
0#
0"
"""


def test_filter_view_opens_on_its_first_result(tmp_path):
    dump = tmp_path / "gpf_bot.vcd"
    dump.write_text(FILTER_VCD)
    window = waves.view_window(BOT, "gpf_bot", "verilator", Dump(dump))
    # the step accepted at 2000, its result at 6000 (a next step accepted with it)
    assert window == Window(2000 - 4000 // 20, 6000 + 4000 * 2 // 5, marker=6000)


BLOCK_VCD = """$timescale 1ps $end
$scope module exp $end
$var wire 1 ! s_axis_tvalid $end
$var wire 1 " s_axis_tready $end
$var wire 1 # m_axis_tvalid $end
$var wire 1 $ m_axis_tready $end
$upscope $end
$enddefinitions $end
#0
0!
1"
0#
1$
#50000
1!
#120000
1#
"""


def test_block_view_opens_on_its_first_output(tmp_path):
    dump = tmp_path / "exp.vcd"
    dump.write_text(BLOCK_VCD)
    window = waves.view_window(BOT, "exp", "verilator", Dump(dump))
    assert window.marker == 120000
    assert window.start == 50000 - 2 * CLOCK
    assert window.end == max(120000 + 8 * CLOCK, window.start + 24 * CLOCK)
    empty = tmp_path / "none.vcd"
    empty.write_text(BLOCK_VCD.split("#50000")[0])
    assert waves.view_window(BOT, "exp", "verilator", Dump(empty)) is None
