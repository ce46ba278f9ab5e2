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
from gpf.model.fixed import Format
from gpf.model.formats import datapath
from gpf.rtl.generate import (
    cholesky_context,
    cordic_atan2_context,
    exp_context,
    grng_context,
    recip_context,
    sqrt_context,
)
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


def _stream(top: str, label: str, side: str, width: int, lanes: int,
            fields: list[tuple[str, int, int, int | None]], signed: bool = False) -> Group:
    """One AXI4-Stream side: handshake bits and each lane's fields (name, offset, width, frac)."""
    return Group(label, [_bit(f"{top}.{side}_tvalid"), _bit(f"{top}.{side}_tready"),
                         _bit(f"{top}.{side}_tlast")] + [
        Trace(f"{top}.{side}_tdata", width * i + off + w - 1, width * i + off,
              label=f"lane{i} {name}", signed=signed, frac_bits=frac)
        for i in range(lanes) for name, off, w, frac in fields])


def exp_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = exp_context(cfg)
    iw, ow = k["in_width"], k["out_width"]
    lane = "exp.g_lane[0].u_lane"
    return [
        Group("clock and reset", [_bit("exp.clk"), _bit("exp.rst")]),
        _stream("exp", f"input t ({dp.t})", "s_axis", iw, cfg.lanes,
                [("t", 0, iw, dp.t.frac_bits)]),
        _stream("exp", f"output w ({dp.weight})", "m_axis", ow, cfg.lanes,
                [("w", 0, ow, dp.weight.frac_bits)]),
        Group("lane 0 pipeline", [
            Trace(f"{lane}.n1_q", iw - k["in_frac"] - 1, 0, label="n (integer part)",
                  frac_bits=0),
            Trace(f"{lane}.k1_q", k["k_width"] - 1, 0, label="segment k", frac_bits=0),
            Trace(f"{lane}.m_q", k["m_width"] - 1, 0, label="m = 2^-f",
                  frac_bits=k["m_width"] - 2),
            Trace(f"{lane}.w_q", ow - 1, 0, label="w", frac_bits=dp.weight.frac_bits),
        ]),
    ]


def cordic_atan2_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = cordic_atan2_context(cfg)
    iw, aw, g, n = k["in_width"], k["out_width"], k["guard_bits"], k["iterations"]
    xyw, zw, frac = k["xy_width"], k["z_width"], dp.x[0].frac_bits
    top, lane = "cordic_atan2", "cordic_atan2.g_lane[0].u_lane"
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        _stream(top, f"input x, y ({dp.x[0]})", "s_axis", 2 * iw, cfg.lanes,
                [("x", 0, iw, frac), ("y", iw, iw, frac)], signed=True),
        _stream(top, "output angle (turns)", "m_axis", aw, cfg.lanes,
                [("angle", 0, aw, aw)], signed=True),
        Group("lane 0 pipeline", [
            Trace(f"{lane}.zero_q", 0, 0, label="x = y = 0, stage 1"),
            Trace(f"{lane}.x0_q", xyw - 1, 0, label="X, pre-rotated", signed=True,
                  frac_bits=frac + g),
            Trace(f"{lane}.y0_q", xyw - 1, 0, label="Y, pre-rotated", signed=True,
                  frac_bits=frac + g),
            Trace(f"{lane}.z0_q", zw - 1, 0, label="z, pre-rotation (turns)", signed=True,
                  frac_bits=zw),
            Trace(f"{lane}.z{n}_q", zw - 1, 0, label=f"z, iteration {n - 1} (turns)",
                  signed=True, frac_bits=zw),
            Trace(f"{lane}.zero_q", n, n, label=f"x = y = 0, stage {n + 1}"),
            Trace(f"{lane}.angle_q", aw - 1, 0, label="angle (turns)", signed=True,
                  frac_bits=aw),
        ]),
    ]


def sqrt_view(cfg: Config, sim: str) -> list[Group]:
    k = sqrt_context(cfg)
    d_fmt, l_fmt = Format.parse(k["d_fmt"]), Format.parse(k["l_fmt"])
    iw, ow, n = k["in_width"], k["out_width"], k["digits"]
    lane = "sqrt.g_lane[0].u_lane"
    mid = n // 2
    return [
        Group("clock and reset", [_bit("sqrt.clk"), _bit("sqrt.rst")]),
        _stream("sqrt", f"input d ({d_fmt})", "s_axis", iw, cfg.lanes,
                [("d", 0, iw, d_fmt.frac_bits)]),
        _stream("sqrt", f"output L ({l_fmt}), sat", "m_axis", k["lane_width"], cfg.lanes,
                [("L", 0, ow, l_fmt.frac_bits), ("sat", ow, 1, None)]),
        Group("lane 0 digit recurrence", [
            Trace(f"{lane}.q1_q", 0, 0, label="root, stage 1"),
            Trace(f"{lane}.q{mid}_q", mid - 1, 0, label=f"root, stage {mid}", frac_bits=0),
            Trace(f"{lane}.rem{mid}_q", mid, 0, label=f"remainder, stage {mid}", frac_bits=0),
            Trace(f"{lane}.root_q", n - 2, 0, label="floor(sqrt(d))",
                  frac_bits=l_fmt.frac_bits),
            _bit(f"{lane}.rb_q", "rounding bit"),
            Trace(f"{lane}.l_q", ow - 1, 0, label="L", frac_bits=l_fmt.frac_bits),
            _bit(f"{lane}.sat_q", "sat"),
        ]),
    ]


def recip_view(cfg: Config, sim: str) -> list[Group]:
    k = recip_context(cfg)
    l_fmt, inv_fmt = Format.parse(k["l_fmt"]), Format.parse(k["inv_fmt"])
    iw, ow, s = k["in_width"], k["out_width"], k["quotient_bits"]
    lane = "recip.g_lane[0].u_lane"
    mid = s // 2
    return [
        Group("clock and reset", [_bit("recip.clk"), _bit("recip.rst")]),
        _stream("recip", f"input L ({l_fmt})", "s_axis", iw, cfg.lanes,
                [("L", 0, iw, l_fmt.frac_bits)]),
        _stream("recip", f"output 1/L ({inv_fmt})", "m_axis", ow, cfg.lanes,
                [("inv", 0, ow, inv_fmt.frac_bits)]),
        Group("lane 0 long division", [
            Trace(f"{lane}.l{mid}_q", iw - 1, 0, label=f"divisor, stage {mid}",
                  frac_bits=l_fmt.frac_bits),
            Trace(f"{lane}.q{mid}_q", mid - 1, 0, label=f"quotient, stage {mid}", frac_bits=0),
            Trace(f"{lane}.rem{mid}_q", min(mid, iw) - 1, 0, label=f"remainder, stage {mid}",
                  frac_bits=0),
            Trace(f"{lane}.quo_q", ow - 1, 0, label="floor(2^shift / L)",
                  frac_bits=inv_fmt.frac_bits),
            _bit(f"{lane}.rb_q", "rounding bit"),
            Trace(f"{lane}.inv_q", ow - 1, 0, label="1/L", frac_bits=inv_fmt.frac_bits),
        ]),
    ]


def cholesky_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = cholesky_context(cfg)
    w, f0 = k["w"], dp.chol[0].frac_bits
    sigma = [(f"Sigma_{x['i']}{x['j']}", x["off"], x["w"], dp.cov_frac(x["i"], x["j"]))
             for x in k["inputs"] if x["i"] == x["j"] or x["j"] == 0]
    chol = [(f"L_{x['i']}{x['j']}", x["off"], w, dp.chol[x["i"]].frac_bits)
            for x in k["outputs"]]
    return [
        Group("clock and reset", [_bit("cholesky.clk"), _bit("cholesky.rst")]),
        _stream("cholesky", "input Sigma (diagonal, column 0)", "s_axis", k["in_width"], 1,
                sigma, signed=True),
        _stream("cholesky", "output L", "m_axis", k["out_width"], 1, chol, signed=True),
        Group("output flags", [
            Trace("cholesky.m_axis_tdata", k["out_width"] - 3, k["out_width"] - 3, label="SAT"),
            Trace("cholesky.m_axis_tdata", k["out_width"] - 1, k["out_width"] - 1,
                  label="NOT_PD")]),
        Group("schedule", [
            _bit("cholesky.busy_q", "busy"), _bit("cholesky.fin_q", "done"),
            Trace("cholesky.j_q", k["jw"] - 1, 0, label="column j", frac_bits=0),
            Trace("cholesky.c_q", k["cw"] - 1, 0, label="clock c", frac_bits=0)]),
        Group("column 0's units (fractions of column 0)", [
            Trace("cholesky.dot", k["acc_w"] - 1, 0, label="dot unit (pivot at c = 0)",
                  signed=True, frac_bits=2 * f0),
            _bit("cholesky.floored_q", "floored"),
            Trace("cholesky.root_q", w - 1, 0, label="isqrt(4 d)", frac_bits=f0 + 1),
            Trace("cholesky.den_q", w - 1, 0, label="L_jj", frac_bits=f0),
            Trace("cholesky.quo_q", k["qw"] - 1, 0, label="floor(2^(S+1) / L_jj)",
                  frac_bits=0),
            Trace("cholesky.inv_q", k["qw"] - 1, 0, label="1/L_jj",
                  frac_bits=k["shifts"][0] - f0),
            _bit("cholesky.sat_q", "SAT so far"), _bit("cholesky.notpd_q", "NOT_PD so far"),
        ]),
    ]


VIEWS: dict[str, Callable[[Config, str], list[Group]]] = {"grng": grng_view, "exp": exp_view}
VIEWS.update(sqrt=sqrt_view, recip=recip_view)
VIEWS.update(cordic_atan2=cordic_atan2_view)
VIEWS.update(cholesky=cholesky_view)


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
