"""Wave views: for each module, the signals grouped and fixed-point fields shown as decimals.

The .gtkw (and its translate filter files: named states, flags, stream handshakes) is written
next to the FST, in the waves run's own build folder (build/<config>/<sim>/<module>-waves/), by
`gpf sim --waves` / `gpf run --waves` and by `gpf waves`, which also opens GTKWave on it where
there is a display. A view opens on the first result (a whole filter) or first output beat (a
block), the primary marker on it.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

from gpf.config import Config
from gpf.model.blocks import Flag
from gpf.model.fixed import Format
from gpf.model.formats import SHIFT_BITS, datapath
from gpf.rtl.generate import (
    MODULES,
    TEMPLATE_DIR,
    cholesky_context,
    cordic_atan2_context,
    exp_context,
    grng_context,
    moments_context,
    propagate_bot_context,
    propagate_uav_context,
    recip_context,
    sample_cond_context,
    sigma_predict_context,
    sqrt_context,
)
from gpf.rtl.gtkw import Bits, Dump, Group, Names, Trace, Window, keep_declared, write_gtkw
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


def propagate_uav_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = propagate_uav_context(cfg)
    top, lane = "propagate_uav", "propagate_uav.g_lane[0].u_lane"
    xw, nw, gw, aw = k["x_width"], k["noise_width"], k["gyro_width"], k["accel_width"]
    names = ["q0", "q1", "q2", "q3", "vE", "vN", "vU"]
    x_fields = [(names[i], k["x_offsets"][i], k["x_widths"][i], dp.x[i].frac_bits)
                for i in range(7)]
    e_fields = [(f"e{j}", xw + nw * j, nw, dp.noise.frac_bits) for j in range(6)]
    out = _stream(top, "output x' (sat after each lane's state)", "m_axis", k["out_width"],
                  cfg.lanes, [(f"{n}'", off, w, f) for n, off, w, f in x_fields], signed=True)
    sat_bits = [k["out_width"] * i + xw for i in range(cfg.lanes)]
    out = Group(out.name, out.traces + [Trace(f"{top}.m_axis_tdata", bit, bit,
                                              label=f"lane{i} sat")
                                        for i, bit in enumerate(sat_bits)])

    def word(sig: str, width: int, frac: int, label: str) -> Trace:
        return Trace(f"{lane}.{sig}", width - 1, 0, label=label, signed=True, frac_bits=frac)

    def reg(base: str) -> str:
        """A rounded sum's register, or its first copy where only copies are kept."""
        return next((ln["dup"] for st in k["stages"] for ln in st
                     if ln.get("dup") and ln["d"] == f"{base}_d"), f"{base}_q")

    last = len(k["stages"])

    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        _stream(top, f"input x ({dp.x[0]}, {dp.x[4]}), e ({dp.noise})", "s_axis",
                k["in_width"], cfg.lanes, x_fields + e_fields, signed=True),
        Group(f"operands omega ({dp.gyro}), accel ({dp.accel})", [
            _bit(f"{top}.first_q", "next beat starts a step")] + [
            Trace(f"{top}.op_beat", gw * (m + 1) - 1, gw * m, label=f"omega{m} (this beat)",
                  signed=True, frac_bits=dp.gyro.frac_bits) for m in range(3)] + [
            Trace(f"{top}.op_beat", 3 * gw + aw * (m + 1) - 1, 3 * gw + aw * m,
                  label=f"accel{m} (this beat)", signed=True, frac_bits=dp.accel.frac_bits)
            for m in range(3)]),
        out,
        Group("lane 0 pipeline", [
            word(reg("w0"), gw, dp.gyro.frac_bits, "omega'0, stage 3"),
            word(reg("a2"), aw, dp.accel.frac_bits, "a'2, stage 3"),
            word(reg("c22"), dp.rot.width, dp.rot.frac_bits, "C22, stage 3"),
            word(reg("h0"), dp.word, dp.h_frac, "h0 = omega'0 dt/2, stage 6"),
            word(reg("f2"), aw, dp.accel.frac_bits, "fU = (C a' + g)U, stage 6"),
            word("y0_q", dp.x[0].width, dp.x[0].frac_bits, f"q'0, stage {last}"),
            word("y6_q", dp.x[6].width, dp.x[6].frac_bits, f"v'U, stage {last}"),
            Trace(f"{lane}.sat{last}_q", 0, 0, label=f"sat, stage {last}"),
        ]),
    ]


def _sat_bits(top: str, lanes: int, lane_width: int, offset: int) -> list[Trace]:
    """Each lane's sat bit of the output stream."""
    return [Trace(f"{top}.m_axis_tdata", lane_width * lane + offset, lane_width * lane + offset,
                  label=f"lane{lane} sat") for lane in range(lanes)]


def sample_cond_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = sample_cond_context(cfg)
    n, ew, ow = dp.n, dp.noise.width, k["out_width"]
    top, lane = "sample_cond", "sample_cond.g_lane[0].u_lane"
    row = k["rows"][n - 1]
    x_fields = [(f"x{i}", k["x_off"][i], dp.x[i].width, dp.x[i].frac_bits) for i in range(n)]
    stream_out = _stream(top, "output x, sat", "m_axis", ow, cfg.lanes, x_fields, signed=True)
    stream_out.traces.extend(_sat_bits(top, cfg.lanes, ow, k["x_width"]))
    op = [Trace(f"{top}.op_beat", k["mu_off"][i] + dp.x[i].width - 1, k["mu_off"][i],
                label=f"mu{i}", signed=True, frac_bits=dp.x[i].frac_bits) for i in range(n)]
    op += [Trace(f"{top}.op_beat", k["chol_off"][f"{i}_{i}"] + dp.chol[i].width - 1,
                 k["chol_off"][f"{i}_{i}"], label=f"L{i}{i}", signed=True,
                 frac_bits=dp.chol[i].frac_bits) for i in range(n)]
    pf = dp.chol[n - 1].frac_bits + dp.noise.frac_bits
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        _stream(top, f"input e ({dp.noise})", "s_axis", n * ew, cfg.lanes,
                [(f"e{j}", j * ew, ew, dp.noise.frac_bits) for j in range(n)], signed=True),
        Group("operands of the beat taken (mu, diagonal of L)",
              [_bit(f"{top}.first_q", "first beat of a step")] + op),
        stream_out,
        Group(f"lane 0, component {n - 1}", [
            Trace(f"{lane}.mu{n - 1}_q", dp.x[n - 1].width - 1, 0, label="mu", signed=True,
                  frac_bits=dp.x[n - 1].frac_bits),
            *([Trace(f"{lane}.ph{n - 1}_{n - 1}_q", row["prod_width"] - 1, 0,
                     label="L e (last), L's top bits", signed=True,
                     frac_bits=pf - row["split"]),
               Trace(f"{lane}.pl{n - 1}_{n - 1}_q", row["lo_prod_width"] - 1, 0,
                     label="L e (last), L's low bits", signed=True, frac_bits=pf)]
              if row["split"] else
              [Trace(f"{lane}.p{n - 1}_{n - 1}_q", row["prod_width"] - 1, 0,
                     label="L e (last)", signed=True, frac_bits=pf)]),
            Trace(f"{lane}.x{n - 1}_sum", row["width"] - 1, 0, label="sum + half LSB",
                  signed=True, frac_bits=pf),
            _bit(f"{lane}.x{n - 1}_ovf", "saturates"),
            Trace(f"{lane}.x{n - 1}_q", dp.x[n - 1].width - 1, 0, label="x", signed=True,
                  frac_bits=dp.x[n - 1].frac_bits),
        ]),
    ]


def propagate_bot_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = propagate_bot_context(cfg)
    xw, ew, fx, fe = dp.x[0].width, dp.noise.width, dp.x[0].frac_bits, dp.noise.frac_bits
    top, lane = "propagate_bot", "propagate_bot.g_lane[0].u_lane"
    names = ("px", "vx", "py", "vy")
    x_fields = [(name, i * xw, xw, fx) for i, name in enumerate(names)]
    stream_out = _stream(top, "output x', sat", "m_axis", k["out_width"], cfg.lanes,
                         x_fields, signed=True)
    stream_out.traces.extend(_sat_bits(top, cfg.lanes, k["out_width"], 4 * xw))
    pa = fe + k["consts"]["a"]["frac"]
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        _stream(top, f"input x ({dp.x[0]}), e ({dp.noise})", "s_axis", k["in_width"],
                cfg.lanes, x_fields + [("ex", 4 * xw, ew, fe), ("ey", 4 * xw + ew, ew, fe)],
                signed=True),
        stream_out,
        Group("lane 0, x axis", [
            Trace(f"{lane}.p0_q", xw - 1, 0, label="p", signed=True, frac_bits=fx),
            Trace(f"{lane}.tv0_q", xw + k["consts"]["T"]["width"] - 1, 0, label="T v",
                  signed=True, frac_bits=fx + k["consts"]["T"]["frac"]),
            Trace(f"{lane}.ea0_q", ew + k["consts"]["a"]["width"] - 1, 0, label="a e",
                  signed=True, frac_bits=pa),
            Trace(f"{lane}.pn0_sum", k["p"]["width"] - 1, 0, label="p sum + half LSB",
                  signed=True, frac_bits=fx + k["p"]["round_shift"]),
            _bit(f"{lane}.pn0_ovf", "p saturates"),
            Trace(f"{lane}.pn0_q", xw - 1, 0, label="p'", signed=True, frac_bits=fx),
            Trace(f"{lane}.vn0_q", xw - 1, 0, label="v'", signed=True, frac_bits=fx),
        ]),
    ]


def moments_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = moments_context(cfg)
    top, word, n = scope(sim, "moments"), k["word"], k["n"]
    xs = [(f"x{i}", i * word, word, dp.x[i].frac_bits) for i in range(n)]
    sig, off = [], n * word
    for d in k["sig"]:
        sig.append(Trace(f"{top}.m_axis_tdata", off + d["out_w"] - 1, off, signed=True,
                         label=f"Sigma{d['i']}{d['j']}", frac_bits=dp.cov_frac(d["i"], d["j"])))
        off += d["out_w"]
    inner = [_bit(f"{top}.busy_q", "busy (step taken, result pending)"),
             Trace(f"{top}.sh5_q", k["shw"] - 1, 0, label="rescale of this beat (shift)",
                   frac_bits=0),
             _bit(f"{top}.acc_reach_q", "a particle within reach"),
             _bit(f"{top}.fin_go_q", "sums complete"),
             Trace(f"{top}.fin_c_q", k["t_w"] - 1, 0, label="finalise clock", frac_bits=0),
             Trace(f"{top}.acc_w_q", k["ws_w"] - 1, 0, label="W = sum w",
                   frac_bits=dp.weight.frac_bits),
             Trace(f"{top}.acc_s1_0_q", k["s1_w"] - 1, 0, signed=True, label="S1_0",
                   frac_bits=dp.weight.frac_bits + dp.x[0].frac_bits),
             Trace(f"{top}.acc_ww_q", k["wws_w"] - 1, 0, label="sum w^2",
                   frac_bits=2 * dp.weight.frac_bits),
             Trace(f"{top}.m0", k["mean"][0]["qb"] - 1, 0, signed=True, label="m_0",
                   frac_bits=dp.chol[0].frac_bits)]
    if k["uav"]:
        inner += [Trace(f"{top}.norm2_q", k["n2_w"] - 1, 0, label="|q|^2",
                        frac_bits=2 * dp.x[0].frac_bits),
                  Trace(f"{top}.root_q", k["dg"] - 1, 0, label="isqrt", frac_bits=0)]
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        _stream(top, "input x, w", "s_axis", k["lane_w"], cfg.lanes,
                xs + [("w", n * word, k["ww"], dp.weight.frac_bits)], signed=True),
        Group("input shift", [Trace(f"{top}.s_axis_tdata", cfg.lanes * k["lane_w"] + k["shw"]
                                    - 1, cfg.lanes * k["lane_w"], label="shift (the beat's "
                                    "rescale)", frac_bits=0)]),
        Group("operands", [Trace(f"{top}.op", (i + 1) * word - 1, i * word, signed=True,
                                 label=f"ref{i}", frac_bits=dp.x[i].frac_bits)
                           for i in range(n)]),
        _stream(top, "output mu", "m_axis", k["out_w"], 1,
                [(f"mu{i}", i * word, word, dp.x[i].frac_bits) for i in range(n)], signed=True),
        Group("output Sigma, flags, ESS", sig + [
            Trace(f"{top}.m_axis_tdata", off + 2, off, label="flags (ZERO_WEIGHTS, SAT)"),
            Trace(f"{top}.m_axis_tdata", off + 2 + dp.ess.width, off + 3,
                  label=f"ESS ({dp.ess})", frac_bits=dp.ess.frac_bits)]),
        Group("accumulate and finalise", inner),
    ]


def _weight_stream(top: str, cfg: Config, side: str) -> Group:
    """A weight block's particles in or out (out: with w and sat beside each); the particle
    fields signed, w and sat not (so _stream's one `signed` does not fit)."""
    dp = datapath(cfg)
    word, n = dp.word, dp.n
    names = ["px", "vx", "py", "vy"] if dp.app == "bot" else ["q0", "q1", "q2", "q3", "vE",
                                                              "vN", "vU"]
    fields = [(name, word * i, word, dp.x[i].frac_bits, True) for i, name in enumerate(names)]
    width = word * n
    if side == "m_axis":
        fields += [("w", width, dp.weight.width, dp.weight.frac_bits, False),
                   ("sat", width + dp.weight.width, 1, None, False)]
        width += dp.weight.width + 1
    label = "input particles" if side == "s_axis" else \
        f"output particles, w ({dp.weight}), sat, the beat's shift"
    shift = [Trace(f"{top}.{side}_tdata", width * cfg.lanes + SHIFT_BITS - 1,
                   width * cfg.lanes, label="shift (rescale)", frac_bits=0)
             ] if side == "m_axis" else []
    return Group(label, [_bit(f"{top}.{side}_tvalid"), _bit(f"{top}.{side}_tready"),
                         _bit(f"{top}.{side}_tlast")] + [
        Trace(f"{top}.{side}_tdata", width * i + off + w - 1, width * i + off,
              label=f"lane{i} {name}", signed=signed, frac_bits=frac)
        for i in range(cfg.lanes) for name, off, w, frac, signed in fields] + shift)


def _weight_tail(lane: str, cfg: Config, terms: int) -> list[Trace]:
    dp = datapath(cfg)
    return [Trace(f"{lane}.u{k}_q", dp.u.width - 1, 0, label=f"u{k} ({dp.u})", signed=True,
                  frac_bits=dp.u.frac_bits) for k in range(terms)] + [
        Trace(f"{lane}.t_q", dp.t.width - 1, 0, label=f"t ({dp.t})", frac_bits=dp.t.frac_bits)]


def _relative(top: str, cfg: Config) -> Group:
    """Stage M: the step's running minimum of floor(t) and lane 0's t - R."""
    dp = datapath(cfg)
    rw = dp.t.width - dp.t.frac_bits
    return Group("relative weights (stage M)", [
        _bit(f"{top}.mfirst_q", "beat at the lanes' output starts a step"),
        Trace(f"{top}.r_q", rw - 1, 0, label="R: running minimum of floor(t)", frac_bits=0),
        Trace(f"{top}.shift_d", SHIFT_BITS - 1, 0, label="shift of this beat", frac_bits=0),
        Trace(f"{top}.trel_q", dp.t.width - 1, 0, label="lane 0 t - R",
              frac_bits=dp.t.frac_bits)])


def weight_bot_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    word, aw = dp.word, dp.angle_frac
    top, lane = "weight_bot", "weight_bot.g_lane[0].u_lane"
    frac = dp.x[0].frac_bits
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        Group("operands", [
            Trace(f"{top}.op", aw - 1, 0, label="z (turns)", signed=True, frac_bits=aw),
            Trace(f"{top}.op", aw + word - 1, aw, label="ox", signed=True, frac_bits=frac),
            Trace(f"{top}.op", aw + 2 * word - 1, aw + word, label="oy", signed=True,
                  frac_bits=frac),
            _bit(f"{top}.first_q", "next beat starts a step")]),
        _weight_stream(top, cfg, "s_axis"),
        _weight_stream(top, cfg, "m_axis"),
        Group("lane 0 pipeline", [
            Trace(f"{lane}.dx_q", word - 1, 0, label="dx", signed=True, frac_bits=frac),
            Trace(f"{lane}.dy_q", word - 1, 0, label="dy", signed=True, frac_bits=frac),
            Trace(f"{lane}.theta", aw - 1, 0, label="theta (turns)", signed=True, frac_bits=aw),
            Trace(f"{lane}.z", aw - 1, 0, label="z, stage A (turns)", signed=True,
                  frac_bits=aw),
            Trace(f"{lane}.d_q", aw - 1, 0, label="d = z - theta (turns)", signed=True,
                  frac_bits=aw),
        ] + _weight_tail(lane, cfg, 1)),
        _relative(top, cfg),
    ]


def weight_uav_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    word, fmt = dp.word, dp.x[4]
    top, lane = "weight_uav", "weight_uav.g_lane[0].u_lane"
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        Group("operands", [
            Trace(f"{top}.op", word * (k + 1) - 1, word * k, label=f"v_gps {name}", signed=True,
                  frac_bits=fmt.frac_bits) for k, name in enumerate(("E", "N", "U"))] + [
            _bit(f"{top}.first_q", "next beat starts a step")]),
        _weight_stream(top, cfg, "s_axis"),
        _weight_stream(top, cfg, "m_axis"),
        Group("lane 0 pipeline", [
            Trace(f"{lane}.dv{k}_q", word - 1, 0, label=f"dv{k}", signed=True,
                  frac_bits=fmt.frac_bits) for k in range(3)] + _weight_tail(lane, cfg, 3)),
        _relative(top, cfg),
    ]


def cholesky_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    core = "cholesky.u_core0"
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
        Group("schedule (core 0)", [
            _bit("cholesky.busy_q", "busy"), _bit(f"{core}.done_q", "core 0 done"),
            Trace(f"{core}.j_q", k["cores"][0]["jw"] - 1, 0, label="column j", frac_bits=0),
            Trace(f"{core}.c_q", k["cores"][0]["cw"] - 1, 0, label="clock c", frac_bits=0)]),
        Group("core 0's units (fractions of column 0)", [
            Trace(f"{core}.dot", k["acc_w"] - 1, 0, label="dot pipeline (pivot at c = P)",
                  signed=True, frac_bits=2 * f0),
            _bit(f"{core}.floored_q", "floored"),
            Trace(f"{core}.root_q", w - 1, 0, label="isqrt(4 d)", frac_bits=f0 + 1),
            Trace(f"{core}.den0_q", w - 1, 0, label="L_jj", frac_bits=f0),
            _bit(f"{core}.sat_q", "SAT so far"), _bit(f"{core}.notpd_q", "NOT_PD so far"),
        ]),
    ]


def sigma_predict_view(cfg: Config, sim: str) -> list[Group]:
    dp = datapath(cfg)
    k = sigma_predict_context(cfg)
    pairs = cholesky_context(cfg)["inputs"]
    sigma = [(f"Sigma_{x['i']}{x['j']}", x["off"], x["w"], dp.cov_frac(x["i"], x["j"]))
             for x in pairs if x["i"] == x["j"]]
    top = "sigma_predict"
    return [
        Group("clock and reset", [_bit(f"{top}.clk"), _bit(f"{top}.rst")]),
        _stream(top, "input Sigma (diagonal)", "s_axis", k["in_width"], 1, sigma, signed=True),
        _stream(top, "output predicted Sigma (diagonal)", "m_axis", k["out_width"], 1, sigma,
                signed=True),
        Group("the term program", [
            _bit(f"{top}.busy_q", "busy"),
            Trace(f"{top}.k_q", k["kw"] - 1, 0, label="term", frac_bits=0),
            # wider than 64 bits: GTKWave shows them in hex
            Trace(f"{top}.val_q", k["acc_w"] - 1, 0,
                  label=f"term, fraction {k['top']} (hex)", frac_bits=None),
            Trace(f"{top}.acc_q", k["acc_w"] - 1, 0,
                  label=f"entry's sum, fraction {k['top']} (hex)", frac_bits=None),
            _bit(f"{top}.sat_q", "SAT so far")]),
    ]


def _fields(path: str, fields: list, lanes: int = 1, only: set[str] | None = None
            ) -> list[Trace]:
    """Traces of the Fields (tb.scoreboard) packed LSB first in `path`, lanes concatenated."""
    lane_w = sum(f.fmt.width for f in fields)
    out = []
    for lane in range(lanes):
        off = lane * lane_w
        for f in fields:
            if only is None or f.name in only:
                out.append(Trace(path, off + f.fmt.width - 1, off, signed=f.fmt.signed,
                                 frac_bits=f.fmt.frac_bits,
                                 label=f"lane{lane} {f.name}" if lanes > 1 else f.name))
            off += f.fmt.width
    return out


# {tvalid, tready} of a stream, as one trace with named values (stall: valid, not ready)
HANDSHAKE = Names("handshake", ((0, "idle"), (1, "ready"), (2, "stall"), (3, "beat")))
# a step's flags (gpf.model.blocks.Flag) by name, the set bits joined by '+'
FLAGS = Names("flags", tuple((v, "+".join(f.name for f in reversed(Flag) if v & f) or "-")
                             for v in range(16)))


def _state_names(template: Path | None = None) -> Names:
    """ctrl's states by value, read from its template's `typedef enum ... state_t`."""
    text = (template or TEMPLATE_DIR / "ctrl.sv.j2").read_text()
    match = re.search(r"typedef enum logic \[(\d+):0\] \{(.*?)\} state_t;", text, re.S)
    if match is None:
        raise ValueError("ctrl.sv.j2: no `typedef enum logic [n:0] {...} state_t`")
    body = re.sub(r"//[^\n]*", "", match[2])
    states = [name.strip() for name in body.split(",")]
    if not all(re.fullmatch(r"S_\w+", name) for name in states) or \
            len(states) > 1 << (int(match[1]) + 1):
        raise ValueError(f"ctrl.sv.j2: state_t is not a list of S_ names: {states}")
    return Names("state", tuple(enumerate(states)))


def _handshake(label: str, valid: str, ready: str) -> Bits:
    return Bits(label, (valid, ready), HANDSHAKE)


def _stream_data(label: str, valid: str, ready: str, last: str | None, data: list[Trace],
                 ) -> Group:
    """One stream's handshake bits and fields."""
    return Group(label, [_bit(valid, "tvalid"), _bit(ready, "tready")]
                 + ([_bit(last, "tlast")] if last else []) + data)


def _step_fields(path: str, fields: list) -> list[Trace]:
    """A step input's fields, with their units (bot: the bearing, in units of pi rad)."""
    units = {"z": "bearing z (units of pi rad)", "ox": "observer x", "oy": "observer y"}
    units |= {f"omega{k}": f"omega{k} (rad/s)" for k in range(3)}
    units |= {f"accel{k}": f"accel{k} (m/s^2)" for k in range(3)}
    units |= {f"v{k}": f"v_gps{k} (m/s)" for k in range(3)}
    return [Trace(t.path, t.msb, t.lsb, label=units.get(t.label, t.label), signed=t.signed,
                  frac_bits=t.frac_bits) for t in _fields(path, fields)]


def _matrices(path: str, fields: list, only: str = "sl") -> list[Group]:
    """Sigma and L of a beat (fields s<i>_<j>, l<i>_<j>) in a group each, lower triangle."""
    groups = []
    for prefix, name in (("s", "Sigma"), ("l", "L")):
        if prefix not in only:
            continue
        traces = [Trace(t.path, t.msb, t.lsb, signed=t.signed, frac_bits=t.frac_bits,
                        label=f"{name}_{t.label[1:].replace('_', '')}")
                  for t in _fields(path, fields)
                  if re.fullmatch(rf"{prefix}\d+_\d+", t.label or "")]
        groups.append(Group(name, traces))
    return groups


def filter_view(cfg: Config, sim: str, top: str | None = None, clock: bool = True
                ) -> list[Group]:
    """gpf_<app> (or the core at `top`): the controller's state by name, every stream's
    handshake, the result (mu, Sigma, L, flags, ESS), the step input; folded: the init and seed
    streams, each stream's fields and both debug taps."""
    from gpf.model.fixed_gpf import FixedGPF
    from gpf.tb.gpf.filter import streams
    from gpf.tb.scoreboard import Field

    gpf = FixedGPF(cfg)
    dp, s, lanes = gpf.dp, streams(gpf), cfg.lanes
    top = top or scope(sim, f"gpf_{cfg.app}")
    n, draws = dp.n, dp.draws()
    ctrl = f"{top}.u_ctrl"

    def sig(name: str) -> str:
        return f"{top}.{name}"

    x = [f for f in s.cond if f.name != "sat"]
    e = [Field(f"e{j}", dp.noise) for j in range(draws)]
    xw = sum(f.fmt.width for f in x)
    mo = moments_context(cfg)
    ch = cholesky_context(cfg)
    sp = sigma_predict_context(cfg)

    # moments' result: mu, Sigma, flags (3 bits), ESS
    off = n * mo["word"]
    mo_fields = [Trace(sig("mo_m_data"), (i + 1) * mo["word"] - 1, i * mo["word"], signed=True,
                       label=f"mu{i}", frac_bits=dp.x[i].frac_bits) for i in range(n)]
    for d in mo["sig"]:
        mo_fields.append(Trace(sig("mo_m_data"), off + d["out_w"] - 1, off, signed=True,
                               label=f"Sigma_{d['i']}{d['j']}",
                               frac_bits=dp.cov_frac(d["i"], d["j"])))
        off += d["out_w"]
    mo_fields += [Trace(sig("mo_m_data"), off + 2, off, label="flags (ZERO_WEIGHTS, SAT)"),
                  Trace(sig("mo_m_data"), off + 2 + dp.ess.width, off + 3,
                        label=f"ESS ({dp.ess})", frac_bits=dp.ess.frac_bits)]

    def sigma_in(path: str) -> list[Trace]:
        return [Trace(path, p["off"] + p["w"] - 1, p["off"], signed=True,
                      label=f"Sigma_{p['i']}{p['j']}", frac_bits=dp.cov_frac(p["i"], p["j"]))
                for p in ch["inputs"]]

    def diagonal(path: str) -> list[Trace]:
        return [t for t in sigma_in(path) if t.label[-1] == t.label[-2]]

    l_w = ch["w"]
    chol_out = [Trace(sig("ch_m_data"), p["off"] + l_w - 1, p["off"], signed=True,
                      label=f"L_{p['i']}{p['j']}", frac_bits=dp.chol[p["i"]].frac_bits)
                for p in ch["outputs"]] + [
        Trace(sig("ch_m_data"), ch["out_width"] - 3, ch["out_width"] - 3, label="SAT"),
        Trace(sig("ch_m_data"), ch["out_width"] - 1, ch["out_width"] - 1, label="NOT_PD")]
    part_w = sum(f.fmt.width for f in s.part)
    mlw = xw + dp.weight.width

    handshakes = [
        _handshake("s_step -> ctrl", sig("s_step_tvalid"), sig("s_step_tready")),
        _handshake("grng -> sample_cond", sig("ss_valid"), sig("ss_ready")),
        _handshake("ctrl -> propagate (ref)", sig("ref_m_valid"), sig("pr_s_ready")),
        _handshake("sample_cond -> propagate", sig("pi_valid"), sig("pi_ready")),
        _handshake("propagate -> ctrl (ref)", sig("ref_s_valid"), sig("ref_s_ready")),
        _handshake("propagate -> weight", sig("wt_s_valid"), sig("wt_s_ready")),
        _handshake("weight -> moments", sig("mo_s_valid"), sig("mo_s_ready")),
        _handshake("moments -> ctrl", sig("mo_m_valid"), sig("mo_m_ready")),
        _handshake("ctrl -> sigma_predict", sig("pd_s_valid"), sig("pd_s_ready")),
        _handshake("sigma_predict -> ctrl", sig("pd_m_valid"), sig("pd_m_ready")),
        _handshake("ctrl -> cholesky", sig("ch_s_valid"), sig("ch_s_ready")),
        _handshake("cholesky -> ctrl", sig("ch_m_valid"), sig("ch_m_ready")),
        _handshake("ctrl -> m_est", sig("m_est_tvalid"), sig("m_est_tready")),
    ]
    data = [
        # e0..e<n-1> go to sample_cond, the rest (the process draws) to propagate
        _stream_data("grng -> sample_cond: draws", sig("ss_valid"), sig("ss_ready"),
                     sig("ss_last"),
                     _fields(sig("ss_data"), e, lanes)),
        _stream_data("ctrl -> propagate: reference mu", sig("ref_m_valid"),
                     sig("pr_s_ready"), None, _fields(sig("ref_m_data"), x)),
        # the step's reference first, then the particles
        _stream_data("sample_cond -> propagate: x, draws",
                     sig("pi_valid"), sig("pi_ready"), sig("pi_last"),
                     _fields(sig("pi_data"), x + e[n:], lanes)),
        _stream_data("propagate -> ctrl: reference", sig("ref_s_valid"),
                     sig("ref_s_ready"), None, _fields(sig("pq_data"), x)),
        _stream_data("propagate -> weight: x', sat", sig("wt_s_valid"), sig("wt_s_ready"),
                     sig("pq_last"), _fields(sig("pq_data"), s.cond, lanes)),
        _stream_data("weight -> moments: x, w, shift", sig("mo_s_valid"),
                     sig("mo_s_ready"), sig("wq_last"),
                     _fields(sig("mo_s_data"), s.part[:-1], lanes)
                     + [Trace(sig("mo_s_data"), lanes * mlw + SHIFT_BITS - 1, lanes * mlw,
                              label="shift (rescale)", frac_bits=0)]),
        _stream_data("moments -> ctrl: mu, Sigma, ESS", sig("mo_m_valid"),
                     sig("mo_m_ready"), sig("mo_m_last"), mo_fields),
        _stream_data("ctrl -> sigma_predict: Sigma diag.", sig("pd_s_valid"),
                     sig("pd_s_ready"), sig("pd_s_last"), diagonal(sig("pd_s_data"))),
        _stream_data("sigma_predict -> ctrl: Sigma diag.", sig("pd_m_valid"),
                     sig("pd_m_ready"), sig("pd_m_last"),
                     [t for t in diagonal(sig("pd_m_data")) if t.msb < sp["out_width"]]),
        _stream_data("ctrl -> cholesky: Sigma", sig("ch_s_valid"), sig("ch_s_ready"),
                     sig("ch_s_last"), sigma_in(sig("ch_s_data"))),
        _stream_data("cholesky -> ctrl: L, flags", sig("ch_m_valid"), sig("ch_m_ready"),
                     sig("ch_m_last"), chol_out),
    ]
    mu = [f for f in s.est if f.name.startswith("mu")]
    est = sig("m_est_tdata")
    labels = {"cycles": "clocks of the step", "ess": "ESS"}
    groups = [
        Group("controller", [
            Trace(f"{ctrl}.state_q", 3, 0, label="state", names=_state_names()),
            Trace(f"{ctrl}.left_q", cfg.particles.bit_length() - 1, 0,
                  label="particles left to send", frac_bits=0),
            Trace(f"{ctrl}.flags_q", 3, 0, label="flags so far", names=FLAGS),
            _bit(f"{ctrl}.pred_done_q", "predicted Sigma ready"),
            Trace(f"{ctrl}.cycles_q", 31, 0, label="clocks this step", frac_bits=0)]),
        Group("streams: valid and ready", handshakes),
        Group("result (m_est)", [
            *_fields(est, s.est, only={f.name for f in mu}),
            *_matrices(est, s.est),
            Trace(est, *_field_range(s.est, "flags"), label="flags", names=FLAGS),
            Trace(est, *_field_range(s.est, "sticky"), label="sticky flags", names=FLAGS),
            *[Trace(t.path, t.msb, t.lsb, label=labels[t.label], frac_bits=t.frac_bits)
              for t in _fields(est, s.est, only=set(labels))]]),
        Group("step input (s_step)", _step_fields(sig("s_step_tdata"), s.step)),
        Group("init (s_init): N, mu0, Sigma0", [
            _bit(sig("s_init_tvalid"), "tvalid"), _bit(sig("s_init_tready"), "tready"),
            *_fields(sig("s_init_tdata"), s.init, only={"particles"} | {f.name for f in mu}),
            *_matrices(sig("s_init_tdata"), s.init, only="s")], closed=True),
        Group("seed (s_seed)", [_bit(sig("s_seed_tvalid"), "tvalid"),
                                _bit(sig("s_seed_tready"), "tready"),
                                Trace(sig("s_seed_tdata"), 63, 0, label="seed word")],
              closed=True),
        Group("streams: fields", data, closed=True),
        Group("conditioning tap (m_cond)", [_bit(sig("m_cond_tvalid"), "tvalid"),
                                            _bit(sig("m_cond_tready"), "tready"),
                                            _bit(sig("m_cond_tlast"), "tlast")]
              + _fields(sig("m_cond_tdata"), s.cond, lanes), closed=True),
        Group("particle tap (m_part)", [_bit(sig("m_part_tvalid"), "tvalid"),
                                        _bit(sig("m_part_tready"), "tready"),
                                        _bit(sig("m_part_tlast"), "tlast")]
              + _fields(sig("m_part_tdata"), s.part, lanes)
              + [Trace(sig("m_part_tdata"), lanes * part_w + SHIFT_BITS - 1, lanes * part_w,
                       label="shift (rescale)", frac_bits=0)], closed=True),
    ]
    if clock:
        groups.append(Group("clock and reset", [_bit(sig("clk")), _bit(sig("rst"))]))
    return groups


def _field_range(fields: list, name: str) -> tuple[int, int]:
    """(msb, lsb) of the field `name` in fields packed LSB first."""
    off = 0
    for f in fields:
        if f.name == name:
            return off + f.fmt.width - 1, off
        off += f.fmt.width
    raise KeyError(name)


VIEWS: dict[str, Callable[[Config, str], list[Group]]] = {"grng": grng_view, "exp": exp_view}
VIEWS.update(sqrt=sqrt_view, recip=recip_view)
VIEWS.update(cordic_atan2=cordic_atan2_view)
VIEWS.update(propagate_uav=propagate_uav_view)
VIEWS.update(sample_cond=sample_cond_view, propagate_bot=propagate_bot_view)
VIEWS.update(moments=moments_view)
VIEWS.update(weight_bot=weight_bot_view, weight_uav=weight_uav_view)
VIEWS.update(cholesky=cholesky_view, sigma_predict=sigma_predict_view)


def harness_view(cfg: Config, sim: str) -> list[Group]:
    """gpf_<app> as simulated: the core inside its testbench harness (gpf_<app>_harness)."""
    return filter_view(cfg, sim, filter_core(f"gpf_{cfg.app}"))


def filter_core(module: str) -> str:
    """Where a whole filter's core is in a simulation of `module`: inside the IP's top or the
    testbench harness, or the top itself."""
    m = MODULES[module]
    if module.endswith("_axi"):
        return f"{m.top}.u_core"
    return f"{m.harness}.u_core" if m.harness else m.top


VIEWS.update(gpf_bot=harness_view, gpf_uav=harness_view)


def ip_view(cfg: Config, sim: str) -> list[Group]:
    """gpf_<app>_axi: its clock and resets, the AXI4-Lite channels, the control and status it
    keeps beside the register block, then the core's view."""
    top = scope(sim, f"gpf_{cfg.app}_axi")
    channels = [_bit(f"{top}.s_axil_{sig}") for sig in (
        "awvalid", "awready", "wvalid", "wready", "bvalid", "bready", "arvalid", "arready",
        "rvalid", "rready")]
    return [
        Group("clock and resets", [_bit(f"{top}.aclk"), _bit(f"{top}.aresetn"),
                                   _bit(f"{top}.rst_q", "the core's reset (with soft reset)")]),
        Group("AXI4-Lite", channels + [
            Trace(f"{top}.s_axil_awaddr", 11, 0, label="write address", frac_bits=0),
            Trace(f"{top}.s_axil_wdata", 31, 0, label="write data"),
            Trace(f"{top}.s_axil_araddr", 11, 0, label="read address", frac_bits=0),
            Trace(f"{top}.s_axil_rdata", 31, 0, label="read data")]),
        Group("control and status", [
            _bit(f"{top}.run", "CTRL.run"), _bit(f"{top}.taps", "CTRL.taps"),
            _bit(f"{top}.seed_valid_q", "seed word to the GRNG"),
            Trace(f"{top}.taken_q", 31, 0, label="steps taken", frac_bits=0),
            Trace(f"{top}.done_q", 31, 0, label="STEPS (results sent)", frac_bits=0),
            _bit(f"{top}.irq")]),
        *filter_view(cfg, sim, f"{top}.u_core", clock=False),
    ]


VIEWS.update(gpf_bot_axi=ip_view, gpf_uav_axi=ip_view)


def waves_dir(cfg: Config, sim: str, module: str, build_root: Path = Path("build")) -> Path:
    """Where a waves run of `module` builds and writes <module>.fst (its own folder, beside the
    run without waves: gpf.sim.sim_build_dir)."""
    from gpf.sim import sim_build_dir

    return sim_build_dir(build_root / cfg.name, sim, module, waves=True)


def view_window(cfg: Config, module: str, sim: str, dump: Dump) -> Window | None:
    """Where the view opens: a whole filter on its first step, from the step input to a while
    after the first result (the marker); a block from its first input beat to a few clocks past
    its first output beat (the marker). None when the dump shows no such beat."""
    clock = CLOCK_NS * 1000  # the dumps' time unit is 1 ps
    top = MODULES[module].top
    if MODULES[module].is_filter:
        core = filter_core(module)
        if f"{core}.m_est_tvalid" not in dump:   # a netlist runs without the harness
            core = top
        results = _beats(dump, core, "m_est")
        if not results:
            return None
        steps = [t for t in _beats(dump, core, "s_step") if t < results[0]]
        start = steps[-1] if steps else max(results[0] - 400 * clock, 0)
        span = results[0] - start
        return Window(start - span // 20, results[0] + span * 2 // 5, marker=results[0])
    outputs = _beats(dump, top, "m_axis")
    if not outputs:
        return None
    inputs = [t for t in _beats(dump, top, "s_axis") if t < outputs[0]]
    start = inputs[0] - 2 * clock if inputs else outputs[0] - 16 * clock
    return Window(max(start, 0), max(outputs[0] + 8 * clock, start + 24 * clock),
                  marker=outputs[0])


def _beats(dump: Dump, scope_: str, stream: str) -> list[int]:
    """When a stream's transfers start (tvalid and tready both high), [] where it has none."""
    valid, ready = f"{scope_}.{stream}_tvalid", f"{scope_}.{stream}_tready"
    if valid not in dump or ready not in dump:
        return []
    return dump.all_high(valid, ready)


def _without_harness(fst: Path, module: str) -> bool:
    try:
        return fst.exists() and f"{filter_core(module)}.m_est_tvalid" not in Dump(fst)
    except (ValueError, KeyError):
        return False


def write_view(cfg: Config, module: str, sim: str, fst: Path, netlist: bool = False) -> Path:
    """Write <fst>.gtkw (and its filter files) for the dump `fst`; return the .gtkw's path.

    A `netlist`'s dump keeps the ports but not every internal wire (synthesis merges and renames
    them): its view leaves out, and names, the signals the dump lacks."""
    gtkw = fst.with_suffix(".gtkw")
    groups = VIEWS[module](cfg, sim)
    if MODULES[module].harness and _without_harness(fst, module):
        groups = filter_view(cfg, sim)   # a netlist runs without the harness: the core is the top
    if netlist and fst.exists():
        groups, missing = keep_declared(groups, Dump(fst).declared())
        if missing:
            print(f"waves: {len(missing)} signals the netlist does not keep are left out of "
                  f"{gtkw.name}: {', '.join(missing)}")
    try:
        window = view_window(cfg, module, sim, Dump(fst)) if fst.exists() else None
    except (ValueError, KeyError):
        window = None
    if window is None:  # the first 24 clocks (a whole filter: 400, its first step)
        clocks = 400 if MODULES[module].is_filter else 24
        window = Window(0, clocks * CLOCK_NS * 1000)
    write_gtkw(gtkw, fst, groups, window)
    return gtkw


def has_display() -> bool:
    """Whether GTKWave can open a window: macOS, or an X11 / Wayland display named."""
    return sys.platform == "darwin" or bool(os.environ.get("DISPLAY")
                                            or os.environ.get("WAYLAND_DISPLAY"))


GTKWAVE_INSTALL = ("brew install --cask gtkwave" if sys.platform == "darwin"
                   else "apt-get install gtkwave")


def open_waves(cfg: Config, module: str, sim: str, launch: bool = True) -> int:
    """Write the view of the last waves run of `module` and open GTKWave on it (with `launch`,
    where there is a display)."""
    from gpf.config import regenerate_command

    fst = waves_dir(cfg, sim, module) / f"{module}.fst"
    if not fst.exists():
        run = regenerate_command(cfg).replace("gpf generate", "gpf sim", 1)
        raise ToolchainError(f"no waves at {fst}: run `{run} --module {module} --sim {sim} "
                             "--waves` first")
    gtkw = write_view(cfg, module, sim, fst)
    command = f"gtkwave {fst} {gtkw}"
    installed = shutil.which("gtkwave") is not None
    if launch and not has_display():
        print(f"waves: {fst}, view: {gtkw}; GTKWave needs a display (DISPLAY is unset): open "
              f"them where there is one ({command})"
              + ("" if installed else f"; GTKWave is not installed: {GTKWAVE_INSTALL}"))
        return 0
    print(f"waves: {fst}\nview:  {gtkw}")
    if not launch:
        return 0
    if not installed:
        raise ToolchainError(f"GTKWave not installed: {GTKWAVE_INSTALL} (then: {command})")
    status = subprocess.call(["gtkwave", str(fst), str(gtkw)])
    if status != 0:
        how = f"stopped by signal {-status}" if status < 0 else f"exit status {status}"
        raise ToolchainError(f"GTKWave failed ({how}): {command}")
    return 0
