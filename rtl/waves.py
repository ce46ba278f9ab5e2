"""Wave views: for each module, the signals grouped and fixed-point fields shown as decimals.

The .gtkw is written next to the FST by `gpf sim --waves` and by `gpf waves`, which also opens
GTKWave on it.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

from gpf.config import Config
from gpf.model.formats import datapath
from gpf.rtl.generate import exp_context, grng_context
from gpf.rtl.gtkw import Group, Trace, write_gtkw
from gpf.tb.harness import CLOCK_NS
from gpf.toolchain import ToolchainError


def scope(sim: str, top: str) -> str:
    """The top module's scope in the FST (Verilator adds `$rootio` beside it, not above)."""
    return top


def _bit(path: str, label: str | None = None) -> Trace:
    return Trace(path, 0, 0, label=label)


def grng_view(cfg: Config, sim: str) -> list[Group]:
    top = scope(sim, "grng")
    w, frac = cfg.noise.width, cfg.noise.frac_bits
    groups = [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        Group("seed load", [_bit(f"{top}.s_seed_tvalid"), _bit(f"{top}.s_seed_tready"),
                            Trace(f"{top}.s_seed_tdata", 63, 0, label="seed word")]),
        Group(f"samples ({cfg.noise})", [_bit(f"{top}.m_axis_tvalid"),
                                          _bit(f"{top}.m_axis_tready")] + [
            Trace(f"{top}.m_axis_tdata", w * (lane + 1) - 1, w * lane, label=f"lane{lane} z",
                  signed=True, frac_bits=frac) for lane in range(cfg.lanes)]),
    ]
    icdf = f"{top}.g_lane[0].u_icdf"
    k = grng_context(cfg)  # the widths the RTL was generated with
    cf = k["coef_frac"]
    groups.append(Group("lane 0 inversion pipeline", [
        Trace(f"{top}.g_lane[0].u_uniform.uniform_q", 63, 0, label="uniform"),
        Trace(f"{icdf}.lzc", 5, 0, label="octave (leading zeros)", frac_bits=0),
        Trace(f"{icdf}.addr_q", k["addr_w"] - 1, 0, label="ROM address", frac_bits=0),
        Trace(f"{icdf}.x2_q", k["offset_bits"] - 1, 0, label="offset x",
              frac_bits=k["offset_bits"]),
        Trace(f"{icdf}.c0_3_q", k["c0_w"] - 1, 0, label="c0", signed=True, frac_bits=cf),
        Trace(f"{icdf}.s1_q", k["s1_w"] - 1, 0, label="s1 = c2 x + c1", signed=True,
              frac_bits=cf),
        Trace(f"{icdf}.s2_q", k["s2_w"] - 1, 0, label="s2 = s1 x + c0", signed=True,
              frac_bits=cf),
        Trace(f"{icdf}.sample_q", w - 1, 0, label="sample", signed=True, frac_bits=frac),
    ]))
    return groups


def exp_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = exp_context(cfg)
    iw, ow = k["in_width"], k["out_width"]
    lane = "exp.g_lane[0].u_lane"
    return [
        Group("clock and reset", [_bit("exp.clk"), _bit("exp.rst")]),
        Group(f"input t ({dp.t})", [_bit("exp.s_axis_tvalid"), _bit("exp.s_axis_tready"),
                                    _bit("exp.s_axis_tlast")] + [
            Trace("exp.s_axis_tdata", iw * (i + 1) - 1, iw * i, label=f"lane{i} t",
                  frac_bits=dp.t.frac_bits) for i in range(cfg.lanes)]),
        Group(f"output w ({dp.weight})", [_bit("exp.m_axis_tvalid"), _bit("exp.m_axis_tready"),
                                          _bit("exp.m_axis_tlast")] + [
            Trace("exp.m_axis_tdata", ow * (i + 1) - 1, ow * i, label=f"lane{i} w",
                  frac_bits=dp.weight.frac_bits) for i in range(cfg.lanes)]),
        Group("lane 0 pipeline", [
            Trace(f"{lane}.n1_q", iw - k["in_frac"] - 1, 0, label="n (integer part)",
                  frac_bits=0),
            Trace(f"{lane}.k1_q", k["k_width"] - 1, 0, label="segment k", frac_bits=0),
            Trace(f"{lane}.m_q", k["m_width"] - 1, 0, label="m = 2^-f",
                  frac_bits=k["m_width"] - 2),
            Trace(f"{lane}.w_q", ow - 1, 0, label="w", frac_bits=dp.weight.frac_bits),
        ]),
    ]


VIEWS: dict[str, Callable[[Config, str], list[Group]]] = {"grng": grng_view, "exp": exp_view}


def waves_dir(cfg: Config, sim: str, module: str, build_root: Path = Path("build")) -> Path:
    return build_root / cfg.name / sim / module


def write_view(cfg: Config, module: str, sim: str, fst: Path) -> Path:
    gtkw = fst.with_suffix(".gtkw")
    # open on the first 24 clocks: reset, pipeline fill, the first samples readable
    write_gtkw(gtkw, fst, VIEWS[module](cfg, sim), window_ps=24 * CLOCK_NS * 1000)
    return gtkw


def open_waves(cfg: Config, module: str, sim: str, launch: bool = True) -> int:
    fst = waves_dir(cfg, sim, module) / f"{module}.fst"
    if not fst.exists():
        raise ToolchainError(f"no waves at {fst}: run `make sim MODULE={module} "
                             f"CONFIG={cfg.name} SIM={sim} WAVES=1` first")
    gtkw = write_view(cfg, module, sim, fst)
    print(f"waves: {fst}\nview:  {gtkw}")
    if not launch:
        return 0
    if shutil.which("gtkwave") is None:
        raise ToolchainError("GTKWave not installed: apt-get install gtkwave "
                             f"(then: gtkwave {fst} {gtkw})")
    return subprocess.call(["gtkwave", str(fst), str(gtkw)])
