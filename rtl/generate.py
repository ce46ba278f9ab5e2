"""Generator: config -> derived constants -> Jinja2 templates -> SystemVerilog + manifest.

Logic lives here and in the models; templates only place the numbers. The derived constants come
from the same model objects the testbenches check against, so no constant is typed twice.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2

from gpf.config import Config, regenerate_command
from gpf.model import grng as grng_model
from gpf.model.blocks import (
    _OMEGA_Q,
    _ROT,
    cov_pairs,
    prediction_terms,
    product_guard,
    product_max,
    reach_top,
    term_frac,
)
from gpf.model.fixed import Format
from gpf.model.formats import CONST_WIDTH, INV_GUARD, SHIFT_BITS, datapath
from gpf.model.formats import constants as datapath_constants
from gpf.model.primitives import Cordic, recip
from gpf.outputs import atomic_write_text, check_outputs, json_text
from gpf.rtl.filter import axi_context, filter_context
from gpf.rtl.regs import ICARUS_GAP, register_files

TEMPLATE_DIR = Path(__file__).parent / "templates"
DSP_WIDTH = 18         # an ECP5 MULT18X18D operand
OUTBUF_LATENCY = 1     # a line-rate block's output buffer (gpf_outbuf) after its pipeline
# the widest signed operand one multiplier takes beside an 18-bit one, per FPGA family
# (config filter.family): a DSP48E1's 25 x 18, a MULT18X18D's 18 x 18
DSP_WIDE_OPERAND = {"xc7": 25, "ecp5": 18}


@dataclass(frozen=True)
class Module:
    """A block the user can simulate: its top, the templates it renders (dependencies first)
    and the modules whose lane parts it instantiates (rendered with their own contexts)."""

    top: str
    parts: tuple[str, ...]
    context: Callable[[Config], dict[str, Any]]
    uses: tuple[str, ...] = ()
    apps: tuple[str, ...] = ("bot", "uav")   # the applications whose filter has this block
    laned: bool = True    # False: one lane whatever LANES (a serial block)
    blocks: tuple[str, ...] = ()   # a filter top: the modules it instantiates whole
    templates: tuple[tuple[str, str], ...] = ()   # (part, template) where they differ
    testbench: str | None = None   # its cocotb test module (default gpf.tb.<top>.test_<top>)
    # files made by code rather than a template: (env, context) -> {file name: text}; the
    # parts among them (<part>.sv) are not rendered
    made: Callable[[jinja2.Environment, dict[str, Any]], dict[str, str]] | None = None
    icarus_gap: str | None = None   # why Icarus cannot run it (None: it can)
    simulated: bool = True          # False: a top for synthesis only (no testbench)
    # a testbench harness wrapping the top (rendered from gpf_harness.sv.j2 into tb/, in no file
    # list): the simulation's toplevel, so that the test's stream work runs in the simulator
    harness: str | None = None

    @property
    def is_filter(self) -> bool:
        return bool(self.blocks)

    def template(self, part: str) -> str:
        return dict(self.templates).get(part, part)

    def files(self) -> list[str]:
        """Its SystemVerilog files, dependencies first: used modules' parts but their tops,
        contained blocks whole."""
        used = [part for name in self.uses for part in MODULES[name].files()
                if part != MODULES[name].top]
        used += [part for name in self.blocks for part in MODULES[name].files()]
        return list(dict.fromkeys(used + list(self.parts)))


def grng_context(cfg: Config, lanes: int | None = None) -> dict[str, Any]:
    """The GRNG of `lanes` lanes (default cfg.lanes; the filter's has draws x LANES)."""
    model = grng_model.GrngModel(cfg, lanes)
    seg = model.seg
    c0_w, c1_w, c2_w = model.coef_widths
    s1_w, s2_w = model.sum_widths
    max_mag = int(model._horner(
        # |z| is largest at the far end of the table; checked here so the RTL never wraps
        *_table_ends(seg.depth, seg.offset_bits)).max())
    if max_mag > cfg.noise.max_raw:
        raise ValueError(f"grng: |z| reaches raw {max_mag}, beyond {cfg.noise}")
    rom_w = c0_w + c1_w + c2_w
    rom = []
    for c0, c1, c2 in model.lut.tolist():
        word = (_twos(c2, c2_w) << (c1_w + c0_w)) | (_twos(c1, c1_w) << c0_w) | _twos(c0, c0_w)
        rom.append(f"{word:0{(rom_w + 3) // 4}X}")
    return {
        "lanes": model.lanes,
        "lane_w": max(1, math.ceil(math.log2(model.lanes))),
        "out_fmt": str(cfg.noise),
        "out_w": cfg.noise.width,
        "latency": grng_model.LATENCY,
        # the output FIFO: a sample a clock in steady flow needs LATENCY places (start to take)
        # and the credit's margin of 4; after a stall it holds DEPTH - 2 samples, which must last
        # while the sources restart (the margin's clocks) and their first sample comes through
        # (LATENCY): DEPTH >= 2 LATENCY + 8 (32 for a latency of 12)
        "fifo_log2": math.ceil(math.log2(2 * grng_model.LATENCY + 8)),
        "components": grng_model.COMPONENTS,
        "seed": cfg.grng.seed,
        "reset_state": [f"{word:016X}" for word in model.reset_state()],
        "lfsr": [
            {"q": q, "s": s, "k": k, "mask_hex": f"{mask:016X}", "force_hex": f"{1 << bit:016X}"}
            for (q, s, k, mask), bit in zip(grng_model.LFSR258, grng_model.SEED_FORCE_BIT,
                                            strict=True)
        ],
        "octaves": seg.octaves,
        "segment_bits": seg.segment_bits,
        "offset_bits": seg.offset_bits,
        "guard_bits": model.guard_bits,
        "coef_frac": model.coef_frac,
        "depth": seg.depth,
        "addr_w": math.ceil(math.log2(seg.octaves)) + seg.segment_bits,
        "c0_w": c0_w,
        "c1_w": c1_w,
        "c2_w": c2_w,
        "s1_w": s1_w,
        "s2_w": s2_w,
        "rom_w": rom_w,
        "rom": rom,
    }


def exp_context(cfg: Config) -> dict[str, Any]:
    dp = datapath(cfg)
    e = dp.exp2
    if e.in_frac < e.lut_bits:
        raise ValueError(f"exp: {e} has fewer fraction bits than LUT bits (not generated)")
    m_width = e.out_frac + e.guard_bits + 1
    rom_width = e.slope_width + m_width
    rom = [f"{(_twos(slope, e.slope_width) << m_width) | base:0{(rom_width + 3) // 4}X}"
           for base, slope in zip(e.base, e.slope, strict=False)]
    return {
        "lanes": cfg.lanes, "latency": 7,
        "in_width": e.in_width, "in_frac": e.in_frac, "out_width": e.out_frac + 1,
        "t_fmt": str(dp.t), "w_fmt": str(dp.weight),
        "lut_bits": e.lut_bits, "rem_bits": e.rem_bits, "guard_bits": e.guard_bits,
        "m_width": m_width, "slope_width": e.slope_width,
        "k_width": max(1, e.lut_bits), "rom_width": rom_width, "rom": rom,
    }


def cordic_model(cfg: Config) -> Cordic:
    """The CORDIC of `cordic_atan2`: the datapath's (bot), else one for the state word, so that
    every config builds and tests the block (uav's filter has no atan2)."""
    dp = datapath(cfg)
    return dp.cordic if dp.cordic is not None else Cordic.for_widths(dp.word, dp.word)


def cordic_atan2_context(cfg: Config) -> dict[str, Any]:
    dp = datapath(cfg)
    c = cordic_model(cfg)
    if c.in_width != dp.word:
        raise ValueError(f"cordic_atan2: {c} does not take {dp.word}-bit state words")
    if c.iterations < 2:  # one iteration would leave the pre-rotated X unused
        raise ValueError(f"cordic_atan2: {c} has fewer than 2 iterations (not generated)")
    digits = (c.z_width + 3) // 4
    quarter = 1 << (c.z_width - 2)
    return {
        # stage 1 pre-rotation, one stage per iteration, the last one rounds
        "lanes": cfg.lanes, "latency": c.iterations + 2,
        "in_width": c.in_width, "in_fmt": str(dp.x[0]), "out_width": c.angle_frac,
        "iterations": c.iterations, "guard_bits": c.guard_bits,
        "xy_width": c.xy_width, "z_width": c.z_width,
        "quarter": f"{quarter:0{digits}X}",
        "minus_quarter": f"{_twos(-quarter, c.z_width):0{digits}X}",
        "angles": [f"{a:0{digits}X}" for a in c.angles],
    }


def sqrt_context(cfg: Config) -> dict[str, Any]:
    """round(sqrt(d)) of a Cholesky pivot d (fraction 2F) into L's format (fraction F).

    F and W are L_00's: dp.chol[0]. d is unsigned 2W bits; L unsigned W - 1 bits (L_jj >= 0,
    the same maximum as the signed L format). The width does not suffice for every d: any
    d >= (2^(W-1) - 1/2)^2 LSB^2 would round to 2^(W-1) or more, so L saturates to all ones
    and `sat` (a second output field, u1.0) says so, as the model's saturate() into dp.chol[j].
    The root runs over d < 2^(2W-2) (the top two bits of d saturate): W digit stages (the last
    is the rounding digit) and one rounding stage.
    """
    dp = datapath(cfg)
    chol = dp.chol[0]
    f, w = chol.frac_bits, chol.width
    if dp.cov_frac(0, 0) != 2 * f:
        raise ValueError(f"sqrt: Sigma_00 has fraction {dp.cov_frac(0, 0)}, not 2 x {f}")
    if w < 4:
        raise ValueError(f"sqrt: L format {chol} is too narrow (need >= 4 bits)")
    d_fmt = Format(False, 2 * w - 2 * f, 2 * f)
    l_fmt = Format(False, w - 1 - f, f)
    return {
        "lanes": cfg.lanes, "latency": w + 1, "digits": w,
        "in_width": d_fmt.width, "out_width": l_fmt.width, "lane_width": l_fmt.width + 1,
        "d_fmt": str(d_fmt), "l_fmt": str(l_fmt), "sat_fmt": "u1.0",
    }


def recip_context(cfg: Config) -> dict[str, Any]:
    """round(2^(2F+G) / L) = div_round(1, L, 2F + G): a fully pipelined reciprocal of an L_jj-like
    word with F + G fraction bits (a library block: the Cholesky divides each row directly).

    L is the sqrt block's output format (unsigned W - 1 bits, fraction F, from dp.chol[0]),
    G = INV_GUARD. The result is largest at the smallest valid input, L = 1: 2^(2F+G), so
    2F + G + 1 bits. L = 0 is not a valid input; its output is defined as all ones. A long
    divider of 2^(2F+G+1) by L: 2F + G + 2 quotient stages (the last is the rounding bit) and
    one rounding stage.
    """
    dp = datapath(cfg)
    chol = dp.chol[0]
    f = chol.frac_bits
    shift = 2 * f + INV_GUARD
    l_fmt = Format(False, chol.width - 1 - f, f)
    out_width = int(recip(1, shift)).bit_length()   # the largest result, at L = 1
    if any(int(recip(v, shift)) >> out_width for v in (1, 2, 3, l_fmt.max_raw)):
        raise AssertionError("recip: result wider than derived")  # recip is non-increasing
    inv_fmt = Format(False, out_width - (f + INV_GUARD), f + INV_GUARD)
    quotient_bits = out_width + 1
    return {
        "lanes": cfg.lanes, "latency": quotient_bits + 1, "quotient_bits": quotient_bits,
        "shift": shift, "inv_guard": INV_GUARD,
        "in_width": l_fmt.width, "out_width": inv_fmt.width,
        "l_fmt": str(l_fmt), "inv_fmt": str(inv_fmt), "zero_result": (1 << out_width) - 1,
    }


@dataclass(frozen=True)
class _Sig:
    """A signal of a generated datapath: its name, exact raw range and binary point."""

    name: str
    lo: int
    hi: int
    frac: int
    width: int = 0   # 0: the fewest signed bits that hold [lo, hi]

    @property
    def w(self) -> int:
        return self.width or _signed_bits(self.lo, self.hi)


def _signed_bits(lo: int, hi: int) -> int:
    return max(1, (-lo - 1).bit_length() + 1 if lo < 0 else 0, hi.bit_length() + 1)


def _word(name: str, fmt: Format) -> _Sig:
    return _Sig(name, fmt.min_raw, fmt.max_raw, fmt.frac_bits, fmt.width)


def _product(base: str, a: _Sig, b: _Sig) -> tuple[_Sig, dict[str, Any]]:
    """An exact product registered as `<base>_q`: its signal and the template's line."""
    ends = [x * y for x in (a.lo, a.hi) for y in (b.lo, b.hi)]
    w = max(_signed_bits(min(ends), max(ends)), a.w, b.w)
    p = _Sig(f"{base}_q", min(ends), max(ends), a.frac + b.frac, w)
    return p, {"name": p.name, "a": a.name, "aw": a.w, "b": b.name, "bw": b.w, "w": w}


def _round_sum(base: str, terms: list[tuple[int, _Sig]], width: int, frac: int
               ) -> tuple[_Sig, dict[str, Any]]:
    """round_sum() of the model, registered as `<base>_q`: sum of coef * term (coef +-2^k),
    rounded half up once to `width` signed bits with `frac` fraction bits, saturated. Widths
    come from the exact ranges; where the rounded sum always fits, no saturation logic."""
    top = max(t.frac for _, t in terms)
    shift = top - frac
    if shift < 0:
        raise ValueError(f"propagate_uav: {base} has more fraction bits than its terms")
    lo = hi = (1 << shift) >> 1   # the rounding half
    sw, parts = 0, []
    for coef, t in terms:
        k = abs(coef).bit_length() - 1
        if abs(coef) != 1 << k:
            raise ValueError(f"propagate_uav: coefficient {coef} of {base} is not +-2^k")
        ls = top - t.frac + k
        tlo, thi = (t.lo << ls, t.hi << ls) if coef > 0 else (-(t.hi << ls), -(t.lo << ls))
        lo, hi = lo + tlo, hi + thi
        sw = max(sw, t.w + ls + 1)
        if t.lo == t.hi == 0:
            continue   # a zero constant (g_E, g_N): its binary point still counts above
        parts.append({"neg": coef < 0, "name": t.name, "w": t.w, "shift": ls})
    sw = max(sw, _signed_bits(lo, hi))
    omin, omax = -(1 << (width - 1)), (1 << (width - 1)) - 1
    rlo, rhi = lo >> shift, hi >> shift
    r = _Sig(f"{base}_q", max(rlo, omin), min(rhi, omax), frac, width)
    sat = rlo < omin or rhi > omax
    # no saturation: the rounded sum is kept just as wide as the output (or sign-extended)
    rw = sw - shift if sat else min(sw - shift, width)
    return r, {"base": base, "terms": parts, "sw": sw, "shift": shift,
               "half": (1 << shift) >> 1, "rw": rw, "ow": width, "sat": sat,
               "copied": False}   # only copies registered (_operand_copies)


def _split_products(lines: list[dict[str, Any]], wide: int
                    ) -> tuple[list[dict], dict[str, list[tuple[str, int, int]]]]:
    """A stage of products as their parts, each registered: a_hi b_hi (a_hi, b_hi: the
    operands' signed top DSP_WIDTH bits) alone on its multiplier, the parts with the operands'
    low bits (k <= 2 bits) in shifted adds; and for each product (by its name) its parts
    (name, width, shift): the sums that take the product take its parts (_split_sum). A
    multiplier's output and an adder in one clock, and four multipliers per 20 x 20 product
    spread over the die, held propagate_uav to 54 MHz. With a wide port (`wide` bits, xc7's
    25), the operand with more low bits to spare goes on it whole: one shifted add at most."""
    pre, parts = [], {}
    for ln in lines:
        a, aw, b, bw, w = ln["a"], ln["aw"], ln["b"], ln["bw"], ln["w"]
        base = ln["name"].removesuffix("_q")
        ka, kb = max(0, aw - DSP_WIDTH), max(0, bw - DSP_WIDTH)
        if ka >= kb and aw <= wide:
            ka = 0
        elif bw <= wide:
            kb = 0
        if ka > 2 or kb > 2:     # (24-bit words): the whole product
            pre.append({"reg": f"{base}_h", "w": w, "expr": f"{w}'({a}) * {w}'({b})"})
            parts[ln["name"]] = [(f"{base}_h", w, 0)]
            continue
        ah = f"$signed({a}[{aw - 1}:{ka}])" if ka else a
        bh = f"$signed({b}[{bw - 1}:{kb}])" if kb else b
        hw = min(aw - ka + bw - kb, w)    # exact modulo 2^w: all the sum needs
        pre.append({"reg": f"{base}_h", "w": hw, "expr": f"{hw}'({ah}) * {hw}'({bh})"})
        terms = [(f"{base}_h", hw, ka + kb)]
        if kb:      # a_hi b_lo
            lw = aw - ka + kb + 1
            v = f"{lw}'({ah})"
            pre.append({"reg": f"{base}_lb", "w": lw, "expr": " + ".join(
                f"({b}[{j}] ? {_shl(v, j)} : {lw}'(0))" for j in range(kb))})
            terms.append((f"{base}_lb", lw, ka))
        if ka:      # a_lo b
            lw = bw + ka + 1
            v = f"{lw}'({b})"
            pre.append({"reg": f"{base}_la", "w": lw, "expr": " + ".join(
                f"({a}[{i}] ? {_shl(v, i)} : {lw}'(0))" for i in range(ka))})
            terms.append((f"{base}_la", lw, 0))
        parts[ln["name"]] = terms
    return pre, parts


def _operand_copies(prods: list[dict[str, Any]], before: list[dict[str, Any]]) -> None:
    """An operand that feeds several products (a' three, h_k and q_j four) gets a register of
    its own for each, kept apart by synthesis, in the stage `before` the products: one
    register driving multipliers and shifted adds across the die was the critical path."""
    sums = {ln["base"]: ln for ln in before if "base" in ln}
    uses: dict[str, int] = {}
    for ln in prods:
        for key in ("a", "b"):
            uses[ln[key]] = uses.get(ln[key], 0) + 1
    for ln in prods:
        base = ln["name"].removesuffix("_q")
        for key, wkey in (("a", "aw"), ("b", "bw")):
            src = ln[key]
            if uses[src] < 2:
                continue
            delay = re.fullmatch(r"([qv]\d)_d(\d+)", src)
            if src.endswith("_q") and src[:-2] in sums:
                d = f"{src[:-2]}_d"
                sums[src[:-2]]["copied"] = True
            elif delay and int(delay[2]) > 1:
                d = f"{delay[1]}_d{int(delay[2]) - 1}"
            else:
                continue
            ln[key] = f"{src}_{base}"
            before.append({"dup": ln[key], "w": ln[wkey], "d": d})


CSA_LEVELS = 3   # 3:2 levels a clock: after a multiplier's output (its route ~3 ns on ECP5), the
                 # 12 to 13 parts of C(q)'s entries and of q' took five in one clock (105 MHz)


def _split_sums(lines: list[dict[str, Any]], parts: dict[str, list[tuple[str, int, int]]]
                ) -> tuple[list[list[dict]], list[dict]]:
    """A stage of rounded sums as C stages and R: C, every term (a product: its parts) at the
    common fraction, a subtracted one as ~x (+1 in the constant), reduced carry-save to two
    words, at most CSA_LEVELS levels a clock (a sum with more is registered between: it takes
    more C stages, and so do the others of its stage, delayed), registered; R, their one carry
    chain, the rounding shift and the saturation. Widths and saturation come from the whole
    terms' exact ranges (the parts add up modulo 2^sw, and so does each carry-save stage)."""
    plans = []
    for ln in lines:
        ops = []
        for t in ln["terms"]:
            for name, w, sh in parts.get(t["name"], [(t["name"], t["w"], 0)]):
                ops.append({"neg": t["neg"], "name": name, "w": w, "shift": t["shift"] + sh})
        nneg = sum(p["neg"] for p in ops)
        const = ln["half"] + nneg
        for p in ops:
            p["fold"] = False
        # the constant in the zero low bits of an added term shifted past it, if there is one
        fold = (next((p for p in ops if not p["neg"] and const < 1 << p["shift"]), None)
                if const else None)
        if fold is not None:
            fold["fold"] = True
        ln.update({"terms": ops, "nneg": nneg, "const": const, "folded": fold is not None})
        plans.append(_csa_stages(len(ops) + (1 if const and fold is None else 0)))
    depth = max(len(plan) for plan in plans)
    stages: list[list[dict]] = [[] for _ in range(depth)]
    for head, plan in zip(lines, plans, strict=True):
        plan += [([], list(range(len(plan[-1][1]))))] * (depth - len(plan))   # registered again
        names = [f"{head['base']}_k{k}" for k in range(depth - 1)] + [head["base"]]
        c = {**head, "csa": plan[0][0], "final": plan[0][1], "base": names[0]}
        stages[0].append({"carry_save": c})
        for k in range(1, depth):
            terms = [{"neg": False, "name": f"{names[k - 1]}_c{j}_q", "w": head["sw"], "shift": 0,
                      "fold": False} for j in range(len(plan[k - 1][1]))]
            c = {**head, "terms": terms, "const": 0, "folded": False,   # the constant went in first
                 "csa": plan[k][0], "final": plan[k][1], "base": names[k]}
            stages[k].append({"carry_save": c})
        head["final"] = c["final"]
    return stages, lines


def _shl(expr: str, k: int) -> str:
    return f"({expr} <<< {k})" if k else expr


def _csa_stages(n: int) -> list[tuple[list[tuple[int, int, int, int, int]], list[int]]]:
    """Carry-save reduction of n operands to two (or one), three at a time, level by level,
    CSA_LEVELS levels a clock: per clock its steps (a, b, c, sum, carry; new operands numbered
    from the clock's count) and the operands it registers, the next clock's 0 .. k-1 in order."""
    out = []
    while True:
        ops, nxt, steps = list(range(n)), n, []
        for _ in range(CSA_LEVELS):
            if len(ops) <= 2:
                break
            new = []
            for g in range(0, len(ops) - len(ops) % 3, 3):
                steps.append((ops[g], ops[g + 1], ops[g + 2], nxt, nxt + 1))
                new += [nxt, nxt + 1]
                nxt += 2
            ops = new + ops[len(ops) - len(ops) % 3:]
        out.append((steps, ops))
        if len(ops) <= 2:
            return out
        n = len(ops)


def _to(fmt: Format) -> tuple[int, int]:
    return fmt.width, fmt.frac_bits


def _const(name: str, c: Any) -> _Sig:
    return _Sig(name, c.raw, c.raw, c.frac, CONST_WIDTH)


def propagate_uav_context(cfg: Config) -> dict[str, Any]:
    """q' = q + Omega(omega') q dt/2 and v' = v + (C(q) a' + g) dt, as blocks.propagate_uav.

    Six steps: 1 the noise products e s_w, e s_a and C(q)'s products q_a q_b (old q);
    2 omega', a' and C(q) rounded; 3 omega' dt/2 and C_nm a'_m; 4 h and f = C a' + g rounded;
    5 h_k q_j and f dt; 6 q' and v' rounded. A clock for a product step's parts, one or more
    for the following sums' carry-save reduction (the products' parts their terms), one for
    their rounding; the wrapper's output register one more (the context's latency).
    Every sum's signs and indices come from the model's own tables (_OMEGA_Q, _ROT), every
    width from the exact ranges of its terms.
    """
    dp = datapath(cfg)
    if dp.app != "uav" or dp.gyro is None or dp.accel is None or dp.rot is None:
        raise ValueError("propagate_uav: the uav application's block")
    c = dp.consts
    k_sw, k_sa, k_dt2, k_dt = (_const(f"C_{n.upper()}", c[n]) for n in ("s_w", "s_a", "dt2", "dt"))
    g = [_const(f"C_G{n}", c[f"g{n}"]) for n in range(3)]
    x = [_word(f"x{i}", fmt) for i, fmt in enumerate(dp.x)]
    e = [_word(f"e{j}", dp.noise) for j in range(6)]
    # stage 1: noise products and every distinct q_a q_b of C(q); operands copied
    s1, pe = [], []
    for j in range(6):
        p, line = _product(f"pe{j}", e[j], k_sw if j < 3 else k_sa)
        pe.append(p)
        s1.append(line)
    pq = {}
    for a, b in sorted({tuple(sorted((a, b))) for row in _ROT for entry in row
                        for _, a, b in entry}):
        pq[a, b], line = _product(f"pq{a}{b}", x[a], x[b])
        s1.append(line)
    omega = [_word(f"om{k}_q", dp.gyro) for k in range(3)]
    accel = [_word(f"ac{m}_q", dp.accel) for m in range(3)]
    # stage 2: omega' = omega + s_w e, a' = a + s_a e, C(q) entries: one rounding each
    s2, w2, a2, rot = [], [], [], {}
    for k in range(3):
        sig, line = _round_sum(f"w{k}", [(1, omega[k]), (1, pe[k])], *_to(dp.gyro))
        w2.append(sig)
        s2.append(line)
    for m in range(3):
        sig, line = _round_sum(f"a{m}", [(1, accel[m]), (1, pe[3 + m])], *_to(dp.accel))
        a2.append(sig)
        s2.append(line)
    for n, row in enumerate(_ROT):
        for m, entry in enumerate(row):
            terms = [(coef, pq[tuple(sorted((a, b)))]) for coef, a, b in entry]
            rot[n, m], line = _round_sum(f"c{n}{m}", terms, *_to(dp.rot))
            s2.append(line)
    # stage 3: omega' dt/2 and C_nm a'_m
    s3, ph, pca = [], [], {}
    for k in range(3):
        p, line = _product(f"ph{k}", w2[k], k_dt2)
        ph.append(p)
        s3.append(line)
    for (n, m), cnm in rot.items():
        pca[n, m], line = _product(f"pc{n}{m}", cnm, a2[m])
        s3.append(line)
    # stage 4: h = omega' dt/2 (one word, h_frac fraction bits), f = C a' + g
    s4, h4, f4 = [], [], []
    for k in range(3):
        sig, line = _round_sum(f"h{k}", [(1, ph[k])], dp.word, dp.h_frac)
        h4.append(sig)
        s4.append(line)
    for n in range(3):
        terms = [(1, pca[n, m]) for m in range(3)] + [(1, g[n])]
        sig, line = _round_sum(f"f{n}", terms, *_to(dp.accel))
        f4.append(sig)
        s4.append(line)
    stages: list[list[dict[str, Any]]] = []

    def add(prods: list[dict[str, Any]], sums: list[dict[str, Any]]) -> None:
        if stages:
            _operand_copies(prods, stages[-1])
        pre, parts = _split_products(prods, DSP_WIDE_OPERAND[cfg.family])
        carry_save, rounded = _split_sums(sums, parts)
        stages.extend([pre, *carry_save, rounded])

    add(s1, s2)
    add(s3, s4)
    # stage 5: h_k q_j and f dt, q delayed to its clock (d: the clocks before it)
    d = len(stages)
    s5, phq, pf = [], {}, []
    for row in _OMEGA_Q:
        for _, k, j in row:
            phq[k, j], line = _product(f"phq{k}{j}", h4[k], dataclasses.replace(
                x[j], name=f"q{j}_d{d}"))
            s5.append(line)
    for n in range(3):
        p, line = _product(f"pf{n}", f4[n], k_dt)
        pf.append(p)
        s5.append(line)
    # stage 6: q'_i = q_i + sum +-h_k q_j, v'_n = v_n + f_n dt (q, v delayed a clock more)
    s6 = []
    for i, row in enumerate(_OMEGA_Q):
        terms = [(1, dataclasses.replace(x[i], name=f"q{i}_d{d + 1}"))]
        terms += [(sign, phq[k, j]) for sign, k, j in row]
        s6.append(_round_sum(f"y{i}", terms, *_to(dp.x[i]))[1])
    for n in range(3):
        terms = [(1, dataclasses.replace(x[4 + n], name=f"v{n}_d{d + 1}")), (1, pf[n])]
        s6.append(_round_sum(f"y{4 + n}", terms, *_to(dp.x[4 + n]))[1])
    if len(set(dp.x[:4])) != 1 or len(set(dp.x[4:])) != 1:
        raise ValueError("propagate_uav: q (and v) components must share one format")
    widths = [fmt.width for fmt in dp.x]
    add(s5, s6)
    return {
        "lanes": cfg.lanes, "latency": len(stages) + OUTBUF_LATENCY,
        "lane_latency": len(stages),
        "x_fmts": [str(f) for f in dp.x], "x_widths": widths,
        "x_offsets": [sum(widths[:i]) for i in range(len(widths))], "x_width": sum(widths),
        "q_width": dp.x[0].width, "v_width": dp.x[4].width,
        "noise_width": dp.noise.width, "noise_fmt": str(dp.noise),
        "gyro_width": dp.gyro.width, "gyro_fmt": str(dp.gyro),
        "accel_width": dp.accel.width, "accel_fmt": str(dp.accel),
        "rot_fmt": str(dp.rot), "h_frac": dp.h_frac,
        "in_width": sum(widths) + 6 * dp.noise.width, "out_width": sum(widths) + 1,
        "op_width": 3 * dp.gyro.width + 3 * dp.accel.width,
        "consts": [{"name": s.name, "w": CONST_WIDTH, "hex": f"{_twos(s.lo, CONST_WIDTH):X}",
                    "value": v.value, "frac": v.frac}
                   for s, v in zip([k_sw, k_sa, k_dt2, k_dt, *g],
                                   [c["s_w"], c["s_a"], c["dt2"], c["dt"],
                                    *(c[f"g{n}"] for n in range(3))], strict=True)
                   if v.raw != 0],   # a zero g_n drops out of its sum
        "stages": stages,
        # per stage: its saturating sums (their flags registered, ORed into sat a clock later)
        "ovf": [[ln["base"] for ln in st if ln.get("sat") and "base" in ln] for st in stages],
        "q_delay": d + 1,
    }


def _signed_width(lo: int, hi: int) -> int:
    """Bits of the smallest two's complement word holding every value in [lo, hi]."""
    return max((-lo - 1).bit_length(), hi.bit_length()) + 1


def _product_range(a: Format, b: Format) -> tuple[int, int]:
    corners = [x * y for x in (a.min_raw, a.max_raw) for y in (b.min_raw, b.max_raw)]
    return min(corners), max(corners)


def _round_sum_plan(terms: list[tuple[int, int, int]], out: Format) -> dict[str, Any]:
    """The adder of model.blocks.round_sum: terms (least raw, greatest raw, fraction bits) at
    the largest fraction F (each term shifted left by F minus its own), the half-LSB added,
    an arithmetic shift by F - out.frac_bits, then saturation into `out`. The sum's width holds
    every reachable value and at least out.width + 1 bits after the shift, so saturation is a
    test of the bits above out's sign bit."""
    frac = max(f for _, _, f in terms)
    shift = frac - out.frac_bits
    if shift < 0:
        raise ValueError(f"round_sum into {out}: the terms have fewer fraction bits ({frac})")
    half = (1 << shift) >> 1
    lo = sum(t_lo << (frac - f) for t_lo, _, f in terms)
    hi = sum(t_hi << (frac - f) for _, t_hi, f in terms) + half
    width = max(_signed_width(lo, hi), out.width + shift + 1)
    return {"shifts": [frac - f for _, _, f in terms], "width": width, "round_shift": shift,
            "half": half, "out_width": out.width, "fmt": str(out)}


def _tree_node(name: str, ops: list[dict[str, Any]]) -> dict[str, Any]:
    """A registered sum of one or two operands, each at the common fraction (its `shift`,
    and `low`: a constant of `low_bits` bits appended below it); its range and width."""
    lo = sum(o["lo"] for o in ops)
    hi = sum(o["hi"] for o in ops)
    return {"name": name, "sig": f"{name}_q", "ops": ops, "lo": lo, "hi": hi,
            "width": _signed_width(lo, hi), "shift": 0, "low_bits": 0, "low": 0}


def _adder_tree(rows: list[list[dict[str, Any]]], prefix: str) -> list[list[list[dict]]]:
    """Pairwise sums of each row's operands, one level a clock, until every row is one sum:
    levels[level][row] = that level's nodes. Every row takes the same number of levels; an odd
    operand is carried by a one-operand node."""
    levels = []
    while any(len(r) > 1 for r in rows):
        lv = len(levels)
        rows = [[_tree_node(f"{prefix}{lv}_{i}_{k // 2}", r[k:k + 2])
                 for k in range(0, len(r), 2)] for i, r in enumerate(rows)]
        levels.append(rows)
    return levels


def sample_cond_context(cfg: Config) -> dict[str, Any]:
    """x_i = mu_i + sum_{j<=i} L_ij e_j (model.blocks.sample_cond), pipelined for a 125 MHz+
    ECP5 clock: the beat's operands registered (stage 0, a copy for each multiplier), every
    product registered straight out of 18 x 18 multipliers (stage 1: an L entry wider than 18
    bits split into its signed top 18 bits and its unsigned low bits, two products) and again
    (stage 2), each component's exact terms summed two by two, one level a clock, and the sum
    rounded half up and saturated (the last stage). On xc7 an L entry of up to 25 bits is one
    DSP48E1 product (L on its 25-bit port, e on the 18-bit one).
    The same exact sum and one rounding as the model: only where registers sit moves."""
    dp = datapath(cfg)
    n, noise = dp.n, dp.noise
    if noise.width > CONST_WIDTH:
        raise ValueError(f"sample_cond: the noise ({noise}) is wider than a multiplier operand")
    pairs = [(i, j) for i in range(n) for j in range(i + 1)]      # L's row order (the port)
    # a pair outside the covariance's blocks has L_ij = 0 (cholesky): no product for it
    kept = set(covariance_pairs(cfg))
    rows, leaves = [], []
    e_lo, e_hi = noise.min_raw, noise.max_raw
    for i in range(n):
        x, chol = dp.x[i], dp.chol[i]
        lo, hi = _product_range(chol, noise)
        terms = [(x.min_raw, x.max_raw, x.frac_bits)]
        js = [j for j in range(i + 1) if (i, j) in kept]
        terms += [(lo, hi, chol.frac_bits + noise.frac_bits)] * len(js)
        plan = _round_sum_plan(terms, x)
        mu_sh, p_sh = plan["shifts"][0], plan["shifts"][1]
        if mu_sh != plan["round_shift"]:
            raise ValueError("sample_cond: mu is not at the rounding's LSB")
        # L's low bits in a product of their own where one multiplier cannot take L whole
        split = max(0, chol.width - DSP_WIDE_OPERAND[cfg.family])
        # mu with the half LSB below it: the rounding constant costs no adder
        row = [{"sig": f"mu{i}_q", "width": x.width, "shift": 0, "low_bits": mu_sh,
                "low": plan["half"], "lo": (x.min_raw << mu_sh) + plan["half"],
                "hi": (x.max_raw << mu_sh) + plan["half"]}]
        for j in js:
            if split:
                h_lo, h_hi = chol.min_raw >> split, chol.max_raw >> split
                hc = [a * b for a in (h_lo, h_hi) for b in (e_lo, e_hi)]
                lc = [a * b for a in (0, (1 << split) - 1) for b in (e_lo, e_hi)]
                row.append({"sig": f"ph{i}_{j}_q", "width": _signed_width(min(hc), max(hc)),
                            "shift": p_sh + split, "low_bits": 0, "low": 0,
                            "lo": min(hc) << (p_sh + split), "hi": max(hc) << (p_sh + split)})
                row.append({"sig": f"pl{i}_{j}_q", "width": _signed_width(min(lc), max(lc)),
                            "shift": p_sh, "low_bits": 0, "low": 0,
                            "lo": min(lc) << p_sh, "hi": max(lc) << p_sh})
            else:
                row.append({"sig": f"p{i}_{j}_q", "width": _signed_width(lo, hi),
                            "shift": p_sh, "low_bits": 0, "low": 0,
                            "lo": lo << p_sh, "hi": hi << p_sh})
        leaves.append(row)
        rows.append({"js": js, "x_width": x.width, "x_fmt": str(x), "chol_width": chol.width,
                     "chol_fmt": str(chol), "prod_width": row[1]["width"],
                     "split": split, "hi_width": chol.width - split,
                     "lo_prod_width": row[2]["width"] if split else 0, **plan})
    levels = _adder_tree(leaves, "t")
    finals = [r[0] for r in levels[-1]]
    for row, total in zip(rows, finals, strict=True):
        # the split products' ranges, taken apart, may reach a bit past the whole sum's
        row["width"] = max(row["width"], total["width"])
    mu_off = [sum(dp.x[k].width for k in range(i)) for i in range(n)]
    mu_w = sum(f.width for f in dp.x)
    chol_off = {}
    offset = mu_w
    for i, j in pairs:
        chol_off[f"{i}_{j}"] = offset
        offset += dp.chol[i].width
    x_off = mu_off     # the output lane packs x like mu, then sat
    return {
        # the operands' registers, the products twice, the adder levels, the rounding
        "lanes": cfg.lanes, "lane_latency": len(levels) + 4,
        "latency": len(levels) + 4 + OUTBUF_LATENCY, "n": n,
        "noise_width": noise.width, "noise_fmt": str(noise),
        "in_width": n * noise.width, "out_width": mu_w + 1, "x_width": mu_w,
        "op_width": offset, "mu_width": mu_w, "chol_width": offset - mu_w,
        "rows": rows, "mu_off": mu_off, "chol_off": chol_off, "x_off": x_off,
        "pairs": pairs, "levels": levels, "finals": finals,
        "skipped": [f"L{i}{j}" for i, j in pairs if (i, j) not in kept],
        "family": cfg.family, "wide_port": DSP_WIDE_OPERAND[cfg.family],
    }


def _chol_issue_table(core: dict[str, Any]) -> list[dict[str, int]]:
    """The dot pipeline's issue for each column j and clock c of a Cholesky core (the template
    reads it as one case table of {j, c}: no adder or compare between the counters and the
    index registers). Row a = j + 1 + c against column j while c <= n - 1 - j (c = n - 1 - j:
    row j + 1 against itself, the next pivot's partial sum); each value at the template's widths.
    Sigma's and L's entry (a, b) sits at a n + b; the operands' rows as row numbers (arow,
    jrow: a row past the last reads as row 0), each operand k an n-way select of L_rk by them
    (no adder of a row's base and k in front of it)."""
    n, jw, cw, tw = core["n"], core["jw"], core["cw"], core["tw"]
    row_w = jw + 1

    def row_of(r: int) -> int:   # a row past the last reads as row 0
        r %= 1 << tw
        return r if r < n else 0

    table = []
    for j in range(n):
        left = (n - 1 - j) % (1 << row_w)
        for c in range(core["c_end"] + 1):
            part = left % (1 << cw) == c
            row = (j + 1 + (0 if part else c % (1 << row_w))) % (1 << row_w)
            col = (j + part) % (1 << row_w)
            table.append({"key": (j << cw) | c, "ok": int(j < n - 1 and c <= left % (1 << cw)),
                          "arow": row_of(row), "jrow": row_of(col),
                          "sidx": (row_of(row) * n + col % (1 << tw)) % (1 << tw)})
    return table


def propagate_bot_context(cfg: Config) -> dict[str, Any]:
    """p' = p + T v + a e, v' = v + b e per axis (model.blocks.propagate_bot): the constant
    products (stage 1), one exact sum per component (stage 2), rounded and saturated (stage 3)."""
    dp = datapath(cfg)
    if len(set(dp.x)) != 1:
        raise ValueError(f"propagate_bot: the state components have different formats {dp.x}")
    x, noise, c = dp.x[0], dp.noise, dp.consts

    def product(fmt: Format, name: str) -> tuple[int, int, int]:
        corners = [v * c[name].raw for v in (fmt.min_raw, fmt.max_raw)]
        return min(corners), max(corners), fmt.frac_bits + c[name].frac

    whole = (x.min_raw, x.max_raw, x.frac_bits)
    return {
        "lanes": cfg.lanes, "lane_latency": 3, "latency": 3 + OUTBUF_LATENCY,
        "x_width": x.width, "x_fmt": str(x), "noise_width": noise.width,
        "noise_fmt": str(noise),
        "in_width": 4 * x.width + 2 * noise.width, "out_width": 4 * x.width + 1,
        # each constant in the fewest signed bits that hold it (18 at most: one DSP operand)
        "consts": {k: {"raw": c[k].raw, "frac": c[k].frac, "value": c[k].value,
                       "width": _signed_width(c[k].raw, c[k].raw)} for k in ("T", "a", "b")},
        "p": _round_sum_plan([whole, product(x, "T"), product(noise, "a")], x),
        "v": _round_sum_plan([whole, product(noise, "b")], x),
    }


def _sbits(bound: int) -> int:
    """Signed width holding [-bound, bound]."""
    return bound.bit_length() + 1


def _div_params(num_w: int, den_w: int, shift: int, bound: int) -> dict[str, int]:
    """A serial divider q = div_round(num, den, shift), |q| <= bound: QB quotient bits (one a
    clock), the biased dividend N = 2 num 2^shift + den + 2^QB den (NNW bits, >= 0)."""
    if shift < 0:
        raise ValueError(f"moments: negative division shift {shift} (not generated)")
    qb = _sbits(bound)
    return {"num_w": num_w, "den_w": den_w, "shift": shift, "qb": qb,
            "dw": den_w + 1, "nnw": den_w + 1 + qb}


def moments_context(cfg: Config) -> dict[str, Any]:
    """W = sum w, S1_i = sum w dx_i, S2_ij = sum p_i dx_j accumulated exactly at line rate, then
    the model's finalise(): every division a serial restoring divider, all in parallel.

    Widths are bounds over cfg.particles particles with any input (w up to the weight format's
    maximum). Quotient bounds: S1_i / W and S2_ij / W are weighted means (w >= 0) of dx_i and
    p_i dx_j / w, so |m_i| <= 2^(W-1+s); p = round(w dx 2^-k) adds at most N 2^(W-2) / W to
    S2 / W when k > 0 (W >= 1 raw)."""
    dp = datapath(cfg)
    pairs = covariance_pairs(cfg)
    word, n, nmax = dp.word, dp.n, cfg.particles
    wmax, xmin = dp.weight.max_raw, -(1 << (word - 1))
    guard = product_guard(dp)
    k = dp.weight.frac_bits - guard                   # p = round(w dx 2^-k)
    wdx_w = _sbits(wmax * -xmin)
    p_max = product_max(dp, guard)
    p_w = _sbits(p_max)
    prod_w = _sbits(p_max * -xmin)
    ws_w = (nmax * wmax).bit_length()                 # unsigned sum of weights
    s1_w = _sbits(nmax * wmax * -xmin)
    s2_w = _sbits(nmax * p_max * -xmin)
    wws_w = (nmax * wmax * wmax).bit_length()        # unsigned sum of squared weights
    mean = []
    for i in range(n):
        # q_i = floor(S1_i 2^(s+1) / W): a plain floor division by W (not 2W), offset 2^(QB-1)
        s = dp.chol[i].frac_bits - dp.x[i].frac_bits
        qb = _sbits((1 << (word + s)) + 2)
        mean.append({"num_w": s1_w, "den_w": ws_w, "shift": s, "qb": qb, "dw": ws_w,
                     "nnw": ws_w + qb})               # a signed divider: QB - 1 bits and the sign
    sig = []
    for i, j in pairs:
        s = (dp.weight.frac_bits + dp.cov_frac(i, j) - dp.x[i].frac_bits - dp.x[j].frac_bits
             - guard)
        err = nmax << (word - 2) if k else 0
        bound = (((1 << (2 * word - 2 - k)) + err) << s) + 1 if k else (
            (1 << (2 * word - 2 + s)) + 1)
        # floor(S2 2^(s+1) / W), a signed divider (QB bits and the sign), then rounded: (q + 1) >> 1
        d = {"num_w": s2_w, "den_w": ws_w, "shift": s, "qb": _sbits(bound), "dw": ws_w,
             "nnw": ws_w + _sbits(bound) + 1}
        mm_w = mean[i]["qb"] + mean[j]["qb"]
        d.update(i=i, j=j, mm_w=mm_w, v_w=max(d["qb"], mm_w) + 1,
                 out_w=dp.sigma(i, j).width, fmt=str(dp.sigma(i, j)))
        sig.append(d)
    # ESS = div_round(W^2, sum w^2, F) <= N (Cauchy-Schwarz; the rescales' roundings add far
    # less than the format's extra integer bit): W^2 two bits a clock, then a divider
    sq_steps = -(-ws_w // 2)
    ess = _div_params(2 * ws_w, wws_w, dp.ess.frac_bits, dp.ess.max_raw)
    ess["qb"] = dp.ess.width                          # unsigned: the quotient is the field
    ess["nnw"] = ess["dw"] + ess["qb"]
    t_ess_div = sq_steps + 2                          # W^2 done, then its dividend registered
    t_ess = t_ess_div + 1 + ess["qb"]
    t_mean = max(d["qb"] for d in mean)               # quotients readable (finalise clocks)
    # m_i m_j, the pairs in turn through one multiplier: the pair's slot, its selects, its
    # operands picked, each DSP's own copy of them, the partial products, their middle sum, the
    # product: pair r's from c = t_mean + mm_lat + r
    mm_lat = 6
    # the quotient final at c = QB + 1, rounded a clock later; q - m_i m_j registered a clock
    # after both are final
    t_sig = 1 + max(max(2 + d["qb"], t_mean + mm_lat + r) for r, d in enumerate(sig))
    t_load = max(t_sig, t_ess)
    ctx: dict[str, Any] = {"uav": dp.app == "uav"}
    if dp.app == "uav":
        fq = dp.x[0].frac_bits
        g = dp.chol[0].frac_bits - fq
        n2_w = 2 * word + 1                           # sum of 4 squares <= 2^(2W)
        y_w = n2_w + 2 * g + 2                        # 4 X = norm2 2^(2g+2)
        rb = (y_w + 1) // 2                           # root bits, one a clock
        qbound = -(-(1 << (fq + g + 1)) // ((1 << (g + 1)) - 1)) + 1  # 2^fq / (1 - 2^-(g+1))
        qd = _div_params(word, rb, fq + g, qbound)
        # mu's sum registered before its saturation, mu registered, its copies beside the
        # squares' multipliers, the partial products, the squares, their sum
        t_sqrt = t_mean + 6
        dg = rb + rb % 2                              # root bits, two a clock (radix 4)
        t_qdiv = t_sqrt + 1 + dg // 2 + 1             # the dividends' norm terms registered
        t_load = max(t_load, t_qdiv + 2 + qd["qb"])     # the quotients registered once more
        # xc7: mu_i on the DSP48E1's wide port, one product a square (its top bits a shifted add)
        sq_wide = DSP_WIDTH < word <= DSP_WIDE_OPERAND[cfg.family]
        ctx.update(n2_w=n2_w, root_bits=rb, dg=dg, sq_shift=2 * g + 2, sq_wide=sq_wide,
                   qdiv=qd, t_sqrt=t_sqrt, t_qdiv=t_qdiv, q_fmt=str(dp.x[0]))
    # the flush, input, dx, w dx, p, p dx, its copy in the fabric, lane sums, the beat's x
    # registered beside the loop's coarse shift, the loop's fine shift and add, the two
    # accumulators read out (registered), their sum
    acc_stages = 13
    # p dx_j as DSP-sized partial products (one multiplier each, both operands within its
    # signed ports), summed with the lanes: p whole on the wide port (xc7: P_BITS fits the
    # DSP48E1's 25) or in unsigned pieces and a signed top (ECP5: 17 + 8 bits), dx whole or,
    # when wider than the 18-bit port, as its 17 unsigned low bits (bl) and a small signed
    # top (a shift-and-add, no multiplier)
    b_split, top = word > DSP_WIDTH, DSP_WIDE_OPERAND[cfg.family]
    step, bl = top - 1, DSP_WIDTH - 1
    pieces, lo = [], 0
    while p_w - lo > top:
        pieces.append({"lo": lo, "hi": lo + step, "signed": False})
        lo += step
    pieces.append({"lo": lo, "hi": p_w, "signed": True})
    for pc in pieces:
        aw = pc["hi"] - pc["lo"] + (0 if pc["signed"] else 1)
        pc["w"] = aw + (bl + 1 if b_split else word)  # exact signed product width
    # xc7: an 18-bit unsigned w (u1.17) is 19 bits signed, one past the DSP48E1's 18-bit port:
    # its top bit (set only for w = 1) apart, as a shifted add, where the other operand cannot
    # take that port (w dx with a 19..25-bit dx; w^2)
    ww = dp.weight.width
    w_top_apart = cfg.family == "xc7" and ww == DSP_WIDTH
    w_top = {"ww": w_top_apart,
             "wdx": w_top_apart and DSP_WIDTH < word <= DSP_WIDE_OPERAND["xc7"]}
    # neither operand of w dx on one multiplier (the ECP5's 18 x 18 with 19- and 20-bit ones): its
    # parts, summed a stage later with p's rounding half below the shifted part's zero bits
    w_top["split"] = (not w_top["wdx"] and ww == DSP_WIDTH
                      and word > DSP_WIDE_OPERAND[cfg.family] and 0 < k < ww)
    prod_plan = {"pieces": pieces, "b_split": b_split, "bl": bl,
                 "hb": word - bl if b_split else 0, "hw": p_w + word - bl if b_split else 0}
    ctx.update({
        "lanes": cfg.lanes, "n": n, "word": word, "ww": dp.weight.width,
        "x_fmts": [str(f) for f in dp.x], "w_fmt": str(dp.weight),
        "lane_w": n * word + dp.weight.width, "opw": n * word, "shw": SHIFT_BITS,
        "in_w": cfg.lanes * (n * word + dp.weight.width) + SHIFT_BITS,
        "out_w": n * word + sum(d["out_w"] for d in sig) + 3 + dp.ess.width,
        "wws_w": wws_w, "ess": ess, "ess_frac": dp.ess.frac_bits, "ess_fmt": str(dp.ess),
        "sq_steps": sq_steps, "t_ess_div": t_ess_div, "t_ess": t_ess,
        "pairs": [[i, j] for i, j in pairs], "npairs": len(pairs),
        "guard": guard, "k": k, "wdx_w": wdx_w, "p_w": p_w, "prod_w": prod_w,
        "ws_w": ws_w, "s1_w": s1_w, "s2_w": s2_w, "mean": mean, "sig": sig,
        "particles": nmax, "t_mean": t_mean, "t_sig": t_sig, "t_load": t_load,
        "t_w": max(1, (t_load + 1).bit_length()), "mm_lat": mm_lat,
        "prod_plan": prod_plan, "w_top": w_top,
        # the shared m_i m_j multiplier: the slots (pairs) in which mean i is operand a, b
        "mm_slots": {side: [[r for r, pr in enumerate(pairs) if pr[k] == i] for i in range(n)]
                     for k, side in enumerate("ab")},
        "dsp_w": DSP_WIDTH,
        # w dx split: its parts' copies in the fabric, a clock more
        "latency": acc_stages + w_top["split"] + t_load + 1, "covariance": cfg.covariance,
    })
    return ctx


def _whiten_context(cfg: Config, d_fracs: list[int]) -> dict[str, Any]:
    """Whitening u = sat(round(d c_u)), exponent t = min(round(sum u^2), t max) and the exp
    lane after them (model: blocks.whiten, exponent_from_u, Exp2Neg), for d in one word.

    d is signed W bits with fraction d_frac (the same for every term); the product with the
    18-bit constant is W + 18 bits, rounded by `whiten_shift`; u^2 is 2U bits (U = u's width),
    the sum of K squares 2U + ceil(log2 K) bits plus one for the rounding carry.
    """
    dp = datapath(cfg)
    c, u, t = dp.consts["c_u"], dp.u, dp.t
    ex = exp_context(cfg)
    if len(set(d_fracs)) != 1:
        raise ValueError(f"weight: innovation terms with different fractions {d_fracs}")
    whiten_shift = d_fracs[0] + c.frac - u.frac_bits
    t_shift = 2 * u.frac_bits - t.frac_bits
    if whiten_shift < 1 or t_shift < 1:
        raise ValueError(f"weight: shifts {whiten_shift}, {t_shift} must be >= 1 (not generated)")
    if (ex["in_width"], ex["out_width"]) != (t.width, dp.weight.width):
        raise ValueError(f"weight: exp takes {ex['in_width']} bits, gives {ex['out_width']}")
    terms = len(d_fracs)
    if terms not in (1, 3):
        raise ValueError(f"weight: {terms} innovation terms (the templates sum 1 or 3)")
    sq_width = 2 * u.width
    return {
        "word": dp.word, "x_fmt": [str(f) for f in dp.x], "terms": terms,
        "c_width": CONST_WIDTH, "c_u": f"{_twos(c.raw, CONST_WIDTH):X}", "c_u_real": c.real,
        "c_frac": c.frac, "prod_width": dp.word + CONST_WIDTH,
        "whiten_shift": whiten_shift, "u_width": u.width, "u_fmt": str(u),
        "sq_width": sq_width, "sum_width": sq_width + (terms - 1).bit_length() + 1,
        "t_shift": t_shift, "t_width": t.width, "t_fmt": str(t), "t_max": t.max_raw,
        "t_frac": t.frac_bits, "w_width": dp.weight.width, "w_fmt": str(dp.weight),
        # operands wider than a DSP's port: d c_u split (d on xc7's wide port whole), u^2 (u
        # on both ports) split past 18 bits (its parts summed in a stage D2 of its own)
        "d_split": max(0, dp.word - DSP_WIDE_OPERAND[cfg.family]),
        "u_split": max(0, u.width - DSP_WIDTH),
        # stages after the innovation d: product, u, squares (and D2), t
        "tail_latency": 4 + (u.width > DSP_WIDTH),
        # the block's relative weights: stage M (running minimum), then the exp lanes
        "reach_top": reach_top(dp), "shift_width": SHIFT_BITS,
        "shift_max": (1 << SHIFT_BITS) - 1, "exp_latency": ex["latency"],
    }


def _weight_block(cfg: Config, lane: dict[str, Any], lane_latency: int) -> dict[str, Any]:
    """A weight block's context: its lanes' (up to t), stage M and the exp lanes."""
    dp = datapath(cfg)
    lane_w = dp.n * dp.word + dp.weight.width + 1
    pipe_latency = lane_latency + 1 + lane["exp_latency"]
    return {**lane, "lanes": cfg.lanes, "components": dp.n, "lane_latency": lane_latency,
            "pipe_latency": pipe_latency, "latency": pipe_latency + OUTBUF_LATENCY,
            "out_width": cfg.lanes * lane_w + SHIFT_BITS}


def weight_bot_context(cfg: Config) -> dict[str, Any]:
    """w = 2^-t, t = (wrap(z - atan2(py - oy, px - ox)) c_u)^2 (model: blocks.weight_bot).

    Stage 1 the saturating dx, dy; the CORDIC lane; stage A the wrapped difference d (W-bit
    binary angles: the subtraction's natural wrap); then the whitening tail.
    """
    dp = datapath(cfg)
    cordic = cordic_atan2_context(cfg)
    if dp.cordic is None or dp.angle_frac != dp.word or cordic["out_width"] != dp.word:
        raise ValueError("weight_bot: bearings must be one datapath word")
    k = _whiten_context(cfg, [dp.angle_frac])
    z_delay = 1 + cordic["latency"]   # z meets the CORDIC's angle in stage A
    return {**_weight_block(cfg, k, z_delay + 1 + k["tail_latency"]),
            "angle_width": dp.angle_frac, "z_delay": z_delay}


def weight_uav_context(cfg: Config) -> dict[str, Any]:
    """w = 2^-t, t = sum_k ((v_gps,k - v_k) c_u)^2 (model: blocks.weight_uav): stage 1 the
    saturating differences, then the whitening tail."""
    dp = datapath(cfg)
    vel = dp.x[4:7]
    if dp.app != "uav" or len(set(vel)) != 1:
        raise ValueError("weight_uav: needs the uav state with one velocity format")
    k = _whiten_context(cfg, [f.frac_bits for f in vel])
    return {**_weight_block(cfg, k, 1 + k["tail_latency"]), "v_first": 4}


def covariance_pairs(cfg: Config) -> list[tuple[int, int]]:
    """The Sigma entries kept (cov_pairs of the config): those the moments compute, the
    Cholesky reads (its input beat order), and whose L entries sample_cond multiplies."""
    return cov_pairs(datapath(cfg), cfg.covariance)


def diagonal_blocks(n: int, pairs: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The covariance's diagonal blocks as (first row, size): rows joined by a kept pair belong
    to one block, and every pair inside a block must be kept (each block is a full Cholesky)."""
    blocks: list[tuple[int, int]] = []
    start = 0
    for i in range(1, n + 1):
        if i == n or not any((i, j) in pairs for j in range(start, i)):
            blocks.append((start, i - start))
            start = i
    kept = {(i, j) for s, m in blocks for i in range(s, s + m) for j in range(s, i + 1)}
    if kept != set(pairs):
        raise ValueError("cholesky: the covariance pairs are not whole diagonal blocks")
    return blocks


CHOL_PIVOT_CLOCKS = 3   # L_j,j-1 -> its square's parts -> two sums -> the pivot, registered
# (>= 3: the pivot floor, compared at c = 1 and selected at c = 2, is read at this clock)


def cholesky_context(cfg: Config) -> dict[str, Any]:
    """L = chol(Sigma) (model: gpf.model.blocks.cholesky_batch), one matrix per beat; one serial
    core per diagonal block of the covariance (uav "block": [q] and [v] side by side).

    A core runs column j on a fixed schedule of CLOCKS[j] clocks (counter c). The pivot
    Sigma_jj - sum_k<j L_jk^2 is the previous column's partial sum (k < j-1, from the dot
    pipeline) less L_j,j-1^2, squared and subtracted in CHOL_PIVOT_CLOCKS: so only that one
    product lies between a column's quotients and the next column's root. c = 0 .. n-2-j issue
    the rows' dot products Sigma_aj - sum_k<j L_ak L_jk into a pipeline of P clocks (operands,
    products, an adder tree), c = n-1-j row j+1's partial sum for the next pivot; c = PV floors
    the pivot and loads the root; SQ clocks of 2 root bits (radix 4, three trial subtractions
    in parallel); one clock rounds L_jj; one forms every row's 2 num + L_jj; QS clocks of 2
    quotient bits of floor(|2 num + L_jj| / 2 L_jj) in one divider per row (radix 4); one
    writes the rows: L_ij = round(num / L_jj), saturated. The last column stops after L_jj.
    """
    from gpf.model.formats import CHOL_FLOOR_LSB, CHOL_FLOOR_REL_BITS

    dp = datapath(cfg)
    n = dp.n
    pairs = covariance_pairs(cfg)
    if any(i < j for i, j in pairs):
        raise ValueError("cholesky: pairs must be the lower triangle (i >= j)")
    w = dp.chol[0].width                        # L's word
    if any(f.width != w or not f.signed for f in dp.chol):
        raise ValueError("cholesky: every L format must be signed and one width")
    if CHOL_FLOOR_LSB < 1:
        raise ValueError("cholesky: the pivot floor must keep L_jj > 0 (the divisor)")
    sigma_w = [dp.sigma(i, j).width for i, j in pairs]
    sw = max(sigma_w)
    acc_w = max(sw, 2 * w - 1) + max(1, math.ceil(math.log2(n))) + 1
    sq = math.ceil(w / 2)                       # root clocks: 2 SQ >= W root bits of 4 d
    qs = math.ceil((w - 1) / 2)                 # quotient clocks: |L_ij| < 2^(W-1) unsaturated
    # a W x W product: whole (W <= 18); on xc7 (W <= 25) a L_jk's two parts, unsigned low LO and
    # signed top bits, each times a whole (one DSP48E1 each); else four 18 x 18 parts
    if w <= DSP_WIDTH:
        parts = "whole"
    elif w <= DSP_WIDE_OPERAND[cfg.family]:
        parts = "two"
    else:
        parts = "four"
    cores = []
    for start, size in diagonal_blocks(n, pairs):
        # S_aj and the products' terms in the adder tree ("four": {hh, ll} one term)
        terms = 1 + (size - 1) * {"whole": 1, "two": 2, "four": 3}[parts]
        levels = max(1, math.ceil(math.log2(terms)))
        p = 4 + levels                          # indices, operands twice, products, the tree
        # L_jj when the root is done and the last row's dot product is in
        c_ljj = max(CHOL_PIVOT_CLOCKS + sq + 2, p + size - 2)
        c_end = c_ljj + qs + 2                  # the rows' L_ij
        clocks = [c_end + 1] * (size - 1) + [c_ljj + 1]
        cores.append({"start": start, "n": size, "p": p, "levels": levels,
                      "pv": CHOL_PIVOT_CLOCKS, "c_ljj": c_ljj, "c_load": c_ljj + 1,
                      "c_end": c_end,
                      "counts": [math.ceil(terms / 2**v) for v in range(levels + 1)],
                      "clocks": clocks, "latency": sum(clocks) + 2,
                      "cw": max(clocks).bit_length(), "jw": max(1, (size - 1).bit_length()),
                      "tw": max(size + 1, size * size - 1).bit_length()})
        cores[-1]["issue"] = _chol_issue_table(cores[-1])
    kinds = list({c["n"]: c for c in cores}.values())
    latency = max(c["latency"] for c in cores) + 1     # + the input register
    lower = [(i, j) for i in range(n) for j in range(i + 1)]
    offs = [sum(sigma_w[:t]) for t in range(len(pairs))]
    core_of = {i: c for c in cores for i in range(c["start"], c["start"] + c["n"])}
    return {
        "lanes": cfg.lanes, "latency": latency, "interval": latency,
        "n": n, "w": w, "sw": sw, "acc_w": acc_w, "dsp_w": DSP_WIDTH, "parts": parts,
        "sq": sq, "qs": qs,
        "dg": 2 * sq,
        "qb": 2 * qs, "cores": cores, "core_kinds": kinds,
        "floor_min": CHOL_FLOOR_LSB**2, "floor_rel_bits": CHOL_FLOOR_REL_BITS,
        "in_width": sum(sigma_w), "out_width": len(lower) * w + 3,
        "inputs": [{"i": i, "j": j, "off": o, "w": v, "fmt": str(dp.sigma(i, j)),
                    "core": cores.index(core_of[i]), "a": i - core_of[i]["start"],
                    "b": j - core_of[i]["start"]}
                   for (i, j), o, v in zip(pairs, offs, sigma_w, strict=True)],
        "outputs": [{"i": i, "j": j, "off": t * w, "core": cores.index(core_of[i]),
                     "a": i - core_of[i]["start"], "b": j - core_of[i]["start"],
                     "kept": (i, j) in pairs} for t, (i, j) in enumerate(lower)],
        "chol_fmts": [str(f) for f in dp.chol],
        "covariance": cfg.covariance,
    }


SIGMA_PREDICT_GROUP_BITS = 2   # the term program's first multiplexer: 4 terms, then the group


def sigma_predict_context(cfg: Config) -> dict[str, Any]:
    """The predicted covariance F Sigma F^T + Q (model: blocks.predicted_sigma) as a program of
    terms (blocks.prediction_terms), one a clock: every term's exact value brought to the largest
    fraction of any term, summed per entry from the entry's half LSB, rounded once (a shift).
    A term whose constant is a power of two is its Sigma entry shifted, a constant alone is a
    constant: both come out of the program's multiplexer at the common fraction, no multiplier
    and no shifter in the datapath. Only a term Sigma_ab c with any other c needs the multiplier
    (`has_mul`: one more stage; none in the shipped configs)."""
    dp = datapath(cfg)
    pairs = covariance_pairs(cfg)
    program = prediction_terms(dp, pairs)
    top = max(term_frac(dp, pairs, t) for terms in program for t in terms)
    sigma_w = [dp.sigma(i, j).width for i, j in pairs]
    sw = max(sigma_w)
    terms, ends = [], []
    for q, entry in enumerate(program):
        for k, (src, name) in enumerate(entry):
            coef = dp.consts[name].raw if name is not None else 1
            lsh = top - term_frac(dp, pairs, (src, name))
            ends.append((sw if src is not None else 2) + CONST_WIDTH + lsh)
            terms.append({"src": src, "coef": coef, "lsh": lsh, "first": k == 0,
                          "last": k == len(entry) - 1, "dest": q})
    acc_w = max(ends) + max(len(e) for e in program).bit_length() + 1
    entry_half = [(1 << (top - dp.cov_frac(i, j))) >> 1 for i, j in pairs]
    for t in terms:
        c = t["coef"]
        if t["src"] is None:                   # the constant alone, at the common fraction
            t["kind"], t["value"] = "const", f"{_twos(c << t['lsh'], acc_w):X}"
        elif c > 0 and c & (c - 1) == 0:       # Sigma_ab 2^m: Sigma_ab shifted
            t["kind"], t["shift"] = "shift", t["lsh"] + c.bit_length() - 1
        else:                                  # Sigma_ab c: through the multiplier
            t["kind"], t["shift"] = "mul", t["lsh"]
        t["mul_coef"] = f"{_twos(c if t['kind'] == 'mul' else 1, CONST_WIDTH):X}"
        # the rounding's half LSB starts the entry's sum
        t["init"] = f"{entry_half[t['dest']] if t['first'] else 0:X}"
    has_mul = any(t["kind"] == "mul" for t in terms)
    # the counter wide enough for its group bits and for one group above them
    kw = max(SIGMA_PREDICT_GROUP_BITS + 1, (len(terms) - 1).bit_length())
    offs = [sum(sigma_w[:q]) for q in range(len(pairs))]
    entries = [{"off": o, "w": w, "rsh": top - dp.cov_frac(i, j),
                "top": top - dp.cov_frac(i, j) + w - 1}     # the entry's sign bit in the sum
               for (i, j), o, w in zip(pairs, offs, sigma_w, strict=True)]
    inputs = [{"off": o, "w": w} for o, w in zip(offs, sigma_w, strict=True)]
    return {
        "lanes": cfg.lanes, "npairs": len(pairs), "in_width": sum(sigma_w),
        "out_width": sum(sigma_w) + 3, "sw": sw, "cw": CONST_WIDTH, "acc_w": acc_w,
        "top": top, "terms": terms, "entries": entries, "inputs": inputs, "has_mul": has_mul,
        "kw": kw, "gb": SIGMA_PREDICT_GROUP_BITS,
        "groups": math.ceil(len(terms) / 2**SIGMA_PREDICT_GROUP_BITS),
        "dest_w": max(1, (len(pairs) - 1).bit_length()),
        # the beat, every term through the program's two registers (and the multiplier's) and
        # the sum, the last sum's range flags, its rounding, the output register; the next
        # matrix a clock after the output is taken and another after every stage is empty
        # (s_axis_tready a register)
        "latency": len(terms) + 5 + has_mul, "interval": len(terms) + 7 + has_mul,
        "covariance": cfg.covariance,
    }


def _table_ends(depth: int, offset_bits: int) -> tuple[Any, Any]:
    import numpy as np

    addr = np.repeat(np.arange(depth), 2)
    x = np.tile([0, (1 << offset_bits) - 1], depth)
    return addr, x


def _twos(value: int, width: int) -> int:
    return value & ((1 << width) - 1)


def example_constraints(env: jinja2.Environment, context: dict[str, Any]) -> dict[str, str]:
    """The example top's XDC: its clock."""
    name = f"gpf_{context['app']}_axi_example"
    return {f"{name}.xdc": env.get_template("gpf_axi_example.xdc.j2").render(module=name,
                                                                            **context)}


MODULES: dict[str, Module] = {
    # the filter's blocks in stream order, then the primitives they instantiate
    "grng": Module("grng", ("grng_lfsr258", "grng_icdf", "gpf_fifo", "grng"), grng_context),
    "sample_cond": Module("sample_cond", ("gpf_outbuf", "sample_cond_lane", "sample_cond"),
                          sample_cond_context),
    "propagate_bot": Module("propagate_bot", ("gpf_outbuf", "propagate_bot_lane", "propagate_bot"),
                            propagate_bot_context, apps=("bot",)),
    "propagate_uav": Module("propagate_uav", ("gpf_outbuf", "propagate_uav_lane", "propagate_uav"),
                            propagate_uav_context, apps=("uav",)),
    "weight_bot": Module("weight_bot", ("gpf_outbuf", "weight_bot_lane", "weight_bot"), weight_bot_context,
                         uses=("cordic_atan2", "exp"), apps=("bot",)),
    "weight_uav": Module("weight_uav", ("gpf_outbuf", "weight_uav_lane", "weight_uav"), weight_uav_context,
                         uses=("exp",), apps=("uav",)),
    "moments": Module("moments", ("moments_div", "moments"), moments_context),
    "cholesky": Module("cholesky", ("cholesky_core", "cholesky"), cholesky_context, laned=False),
    "sigma_predict": Module("sigma_predict", ("sigma_predict",), sigma_predict_context,
                            laned=False),
    "cordic_atan2": Module("cordic_atan2", ("cordic_atan2_lane", "cordic_atan2"),
                           cordic_atan2_context),
    "exp": Module("exp", ("exp_lane", "exp"), exp_context),
    "sqrt": Module("sqrt", ("sqrt_lane", "sqrt"), sqrt_context),
    "recip": Module("recip", ("recip_lane", "recip"), recip_context),
    # the whole filters: their own GRNG (draws x LANES lanes), a FIFO, the controller, the top
    **{f"gpf_{app}": Module(
        f"gpf_{app}", ("gpf_grng", "gpf_fifo", "gpf_slice", "ctrl", f"gpf_{app}"), filter_context,
        uses=("grng",), apps=(app,), blocks=("sample_cond", f"propagate_{app}", f"weight_{app}",
                             "moments", "cholesky", "sigma_predict"),
        templates=(("gpf_grng", "grng"), (f"gpf_{app}", "gpf")), testbench="gpf.tb.gpf.test_gpf",
        harness=f"gpf_{app}_harness")
       for app in ("bot", "uav")},
    # the whole filters as IP: the core behind AXI4-Lite registers (PeakRDL) and byte-wide streams
    **{f"gpf_{app}_axi": Module(
        f"gpf_{app}_axi", (f"gpf_{app}_regs_pkg", f"gpf_{app}_regs", f"gpf_{app}_axi"),
        axi_context, uses=(f"gpf_{app}",), apps=(app,), blocks=(f"gpf_{app}",),
        templates=((f"gpf_{app}_axi", "gpf_axi"),), testbench="gpf.tb.gpf.test_gpf_axi",
        made=register_files, icarus_gap=ICARUS_GAP)
       for app in ("bot", "uav")},
    # an example top for a 7-series part, with its clock constraint: for synthesis only
    **{f"gpf_{app}_axi_example": Module(
        f"gpf_{app}_axi_example", (f"gpf_{app}_axi_example",), axi_context,
        uses=(f"gpf_{app}_axi",), apps=(app,), blocks=(f"gpf_{app}_axi",),
        templates=((f"gpf_{app}_axi_example", "gpf_axi_example"),), made=example_constraints,
        icarus_gap=ICARUS_GAP, simulated=False)
       for app in ("bot", "uav")},
}


def modules_for(cfg: Config) -> list[str]:
    """The modules a config generates: the blocks of its application's filter."""
    return [name for name, m in MODULES.items() if cfg.app in m.apps]


def _with_uses(names: list[str]) -> list[str]:
    """`names` and every module they use or contain, each once, those first (a filter's file
    list names its blocks' files: they are rendered with it)."""
    out: list[str] = []
    for name in names:
        inner = list(MODULES[name].uses) + list(MODULES[name].blocks)
        out += [n for n in _with_uses(inner) + [name] if n not in out]
    return out


@functools.lru_cache(maxsize=8)
def _environment(template_dir: Path) -> jinja2.Environment:
    """One per template folder: its compiled templates are kept for the next generate (a test
    suite generates hundreds of times)."""
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_dir)),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )


@dataclass(frozen=True)
class Generated:
    out_dir: Path
    files: dict[str, list[Path]]  # module -> its SystemVerilog files, dependencies first
    manifest: dict[str, Any]
    harnesses: dict[str, Path] = dataclasses.field(default_factory=dict)  # module -> its harness


def default_out_dir(cfg: Config) -> Path:
    return Path("build") / cfg.name / "rtl"


def generate(cfg: Config, out_dir: Path | None = None, modules: list[str] | None = None,
             template_dir: Path = TEMPLATE_DIR) -> Generated:
    """Render every module (or the named ones) for `cfg` into `out_dir`.

    Writes <part>.sv per template, <module>.f file lists, manifest.json and config.toml.
    Files are rendered in memory first, so a failure leaves nothing half-written.
    """
    out_dir = Path(out_dir) if out_dir is not None else default_out_dir(cfg)
    names = _with_uses(modules_for(cfg) if modules is None else modules)
    env = _environment(template_dir)
    config_file = Path(cfg.source).name if cfg.source else f"{cfg.name}.toml"
    regenerate = regenerate_command(cfg)
    texts: dict[str, str] = {}
    files: dict[str, list[Path]] = {}
    harnesses: dict[str, Path] = {}
    manifest: dict[str, Any] = {
        "config": {"name": cfg.name, "file": config_file},
        "app": cfg.app,
        "lanes": cfg.lanes,
        "particles": cfg.particles,
        "formats": {name: str(fmt) for name, fmt in cfg.formats.items()},
        # the filter datapath's derived formats, constants and primitive tables (model/)
        "datapath": datapath_constants(datapath(cfg)),
        "modules": {},
    }
    for name in names:
        module = MODULES[name]
        context = module.context(cfg)
        made = (module.made(env, {**context, "config_file": config_file,
                                  "regenerate": regenerate}) if module.made else {})
        texts |= made
        for part in module.parts:
            if f"{part}.sv" in made:
                continue
            # a part may have its own context (the filter's GRNG: more lanes than the block's)
            part_context = context.get("part_contexts", {}).get(part, context)
            texts[f"{part}.sv"] = env.get_template(f"{module.template(part)}.sv.j2").render(
                module=part, config_file=config_file, config_name=cfg.name,
                regenerate=regenerate, **part_context)
        files[name] = [out_dir / f"{part}.sv" for part in module.files()]
        texts[f"{name}.f"] = "".join(f"{part}.sv\n" for part in module.files())
        if module.harness:
            from gpf.rtl.filter import HARNESS_DIR, harness_context

            harness = f"{HARNESS_DIR}/{module.harness}.sv"
            texts[harness] = env.get_template("gpf_harness.sv.j2").render(
                module=module.harness, config_file=config_file, config_name=cfg.name,
                regenerate=regenerate, **harness_context(cfg))
            harnesses[name] = out_dir / harness
            # its cocotb-free toplevel (tb/gpf/direct.py), around the harness
            direct = f"{HARNESS_DIR}/{module.top}_direct.sv"
            texts[direct] = env.get_template("gpf_direct.sv.j2").render(
                module=f"{module.top}_direct", harness=module.harness, config_file=config_file,
                config_name=cfg.name, regenerate=regenerate, **harness_context(cfg))
        manifest["modules"][name] = {
            "top": module.top,
            "files": [f"{part}.sv" for part in module.files()],
            "latency": context.get("latency"),
            "constants": {k: v for k, v in context.items()
                          if isinstance(v, int | str) and k not in ("lanes",)},
        }
    texts["manifest.json"] = json_text(manifest, indent=2, sort_keys=True)
    if cfg.source:
        texts["config.toml"] = Path(cfg.source).read_text() + "".join(
            f"# overridden: {key} = {value!r}\n" for key, value in cfg.overrides.items())
    # nothing written yet: never over the config (a --out that is the config's folder)
    check_outputs([("--out", out_dir / fname) for fname in texts],
                  [("the config", cfg.source)] if cfg.source else [])
    out_dir.mkdir(parents=True, exist_ok=True)
    for fname, text in texts.items():
        path = out_dir / fname
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists() or path.read_text() != text:
            # atomic: simulations of other modules may be reading this folder right now
            atomic_write_text(path, text)
    return Generated(out_dir, files, manifest, harnesses)
