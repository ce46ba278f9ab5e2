"""Generator: config -> derived constants -> Jinja2 templates -> SystemVerilog + manifest.

Logic lives here and in the models; templates only place the numbers. The derived constants come
from the same model objects the testbenches check against, so no constant is typed twice.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2

from gpf.config import Config
from gpf.model import grng as grng_model
from gpf.model.fixed import Format
from gpf.model.formats import INV_GUARD, datapath
from gpf.model.formats import constants as datapath_constants
from gpf.model.primitives import Cordic, recip

TEMPLATE_DIR = Path(__file__).parent / "templates"


@dataclass(frozen=True)
class Module:
    """A block the user can simulate: its top, the templates it renders (dependencies first)
    and the modules whose lane parts it instantiates (rendered with their own contexts)."""

    top: str
    parts: tuple[str, ...]
    context: Callable[[Config], dict[str, Any]]
    uses: tuple[str, ...] = ()
    apps: tuple[str, ...] = ("bot", "uav")   # the applications whose filter has this block

    def files(self) -> list[str]:
        """Its SystemVerilog files, dependencies first: used modules' parts but their tops."""
        used = [part for name in self.uses for part in MODULES[name].files()
                if part != MODULES[name].top]
        return list(dict.fromkeys(used + list(self.parts)))


def grng_context(cfg: Config) -> dict[str, Any]:
    model = grng_model.GrngModel(cfg)
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
        "lanes": cfg.lanes,
        "lane_w": max(1, math.ceil(math.log2(cfg.lanes))),
        "out_fmt": str(cfg.noise),
        "out_w": cfg.noise.width,
        "latency": grng_model.LATENCY,
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
        "lanes": cfg.lanes, "latency": 4,
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
    """round(2^(2F+G) / L) = div_round(1, L, 2F + G): 1/L_jj with F + G fraction bits.

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


def cholesky_pairs(cfg: Config) -> list[tuple[int, int]]:
    """The Sigma entries the Cholesky reads (input beat order): cov_pairs of the config."""
    from gpf.model.blocks import cov_pairs

    return cov_pairs(datapath(cfg), cfg.app_params.get("covariance", "full"))


CHOL_DIGITS = 8   # root digits and quotient bits per clock in the Cholesky


def cholesky_context(cfg: Config) -> dict[str, Any]:
    """Serial L = chol(Sigma) (model: gpf.model.blocks.cholesky), one matrix per beat.

    Column j runs a fixed schedule of clocks (counter c): c = 0 the pivot d = Sigma_jj -
    sum_k<j L_jk^2 (n - 1 multipliers in parallel), its floor and the root's radicand; from
    c = 1 on, one a clock, the rows' dot products Sigma_ij - sum_k<j L_ik L_jk overlap SQ
    clocks of K root digits; one clock rounds L_jj; RQ clocks of K quotient bits of
    q = floor(2^(T+1) / L_jj) (T >= every S_j = 2 F_j + G; L_jj >= 16, so the division starts
    from the remainder 8 with quotient 0); one clock for 1/L_jj = ((q >> (T - S_j)) + 1) >> 1
    (floor(floor(x) / 2^k) = floor(x / 2^k): exactly round(2^S_j / L_jj)); then one clock per
    row below (L_ij = round(num_i / L_jj)). The last column stops after L_jj; one more clock
    loads the output register, and the next matrix is taken the clock after.
    """
    from gpf.model.formats import CHOL_FLOOR_LSB, CHOL_FLOOR_REL_BITS

    dp = datapath(cfg)
    n, w, k = dp.n, dp.word, CHOL_DIGITS
    pairs = cholesky_pairs(cfg)
    if any(f.width != w or not f.signed for f in dp.chol):
        raise ValueError("cholesky: every L format must be a signed state word")
    if CHOL_FLOOR_LSB < 16:
        raise ValueError("cholesky: the division starts from remainder 8 < L_jj")
    sigma_w = [dp.sigma(i, j).width for i, j in pairs]
    sw = max(sigma_w)
    acc_w = max(sw, 2 * w - 1) + max(1, math.ceil(math.log2(n))) + 1
    shifts = [2 * f.frac_bits + INV_GUARD for f in dp.chol]     # 1/L_jj = 2^S_j / L_jj
    sq = math.ceil(w / k)                       # root digits: W (the last is the rounding one)
    rq = math.ceil((max(shifts) - 2) / k)       # 2^(T+1) = 8 2^(T-2): T - 2 quotient bits
    s_top = rq * k + 2
    col = [3 + sq + rq + (n - 1 - j) for j in range(n - 1)] + [2 + sq]
    if n - 1 > 2 + sq + rq:                     # the rows' dot products end before scaling
        raise ValueError(f"cholesky: {n} rows do not fit the divider's schedule")
    latency = sum(col) + 2
    lower = [(i, j) for i in range(n) for j in range(i + 1)]
    offs = [sum(sigma_w[:t]) for t in range(len(pairs))]
    return {
        "lanes": cfg.lanes, "latency": latency, "interval": latency,
        "n": n, "w": w, "k": k, "sw": sw, "acc_w": acc_w, "sq": sq, "rq": rq,
        "qw": rq * k, "s_top": s_top, "shifts": shifts, "cols": col,
        "cw": max(col).bit_length(), "jw": max(1, (n - 1).bit_length()),
        "tw": (n * n - 1).bit_length(),
        "floor_min": CHOL_FLOOR_LSB**2, "floor_rel_bits": CHOL_FLOOR_REL_BITS,
        "in_width": sum(sigma_w), "out_width": len(lower) * w + 3,
        "inputs": [{"i": i, "j": j, "off": o, "w": v, "fmt": str(dp.sigma(i, j))}
                   for (i, j), o, v in zip(pairs, offs, sigma_w, strict=True)],
        "outputs": [{"i": i, "j": j, "off": t * w} for t, (i, j) in enumerate(lower)],
        "pair_mask": [[int((i, j) in pairs) for j in range(n)] for i in range(n)],
        "chol_fmts": [str(f) for f in dp.chol],
        "covariance": cfg.app_params.get("covariance", "full"),
    }


def _table_ends(depth: int, offset_bits: int) -> tuple[Any, Any]:
    import numpy as np

    addr = np.repeat(np.arange(depth), 2)
    x = np.tile([0, (1 << offset_bits) - 1], depth)
    return addr, x


def _twos(value: int, width: int) -> int:
    return value & ((1 << width) - 1)


MODULES: dict[str, Module] = {
    "grng": Module("grng", ("grng_lfsr258", "grng_icdf", "grng"), grng_context),
    "exp": Module("exp", ("exp_lane", "exp"), exp_context),
    "cordic_atan2": Module("cordic_atan2", ("cordic_atan2_lane", "cordic_atan2"),
                           cordic_atan2_context),
    "sqrt": Module("sqrt", ("sqrt_lane", "sqrt"), sqrt_context),
    "recip": Module("recip", ("recip_lane", "recip"), recip_context),
    "cholesky": Module("cholesky", ("cholesky",), cholesky_context),
}


def modules_for(cfg: Config) -> list[str]:
    """The modules a config generates: the blocks of its application's filter."""
    return [name for name, m in MODULES.items() if cfg.app in m.apps]


def _with_uses(names: list[str]) -> list[str]:
    """`names` and every module they use, each once, used ones first."""
    out: list[str] = []
    for name in names:
        out += [n for n in _with_uses(list(MODULES[name].uses)) + [name] if n not in out]
    return out


def _environment(template_dir: Path) -> jinja2.Environment:
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
    texts: dict[str, str] = {}
    files: dict[str, list[Path]] = {}
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
        for part in module.parts:
            texts[f"{part}.sv"] = env.get_template(f"{part}.sv.j2").render(
                module=part, config_file=config_file, config_name=cfg.name, **context)
        files[name] = [out_dir / f"{part}.sv" for part in module.files()]
        texts[f"{name}.f"] = "".join(f"{part}.sv\n" for part in module.files())
        manifest["modules"][name] = {
            "top": module.top,
            "files": [f"{part}.sv" for part in module.files()],
            "latency": context.get("latency"),
            "constants": {k: v for k, v in context.items()
                          if isinstance(v, int | str) and k not in ("lanes",)},
        }
    texts["manifest.json"] = json.dumps(manifest, indent=2, sort_keys=True) + "\n"
    if cfg.source:
        texts["config.toml"] = Path(cfg.source).read_text() + "".join(
            f"# overridden: {key} = {value!r}\n" for key, value in cfg.overrides.items())
    out_dir.mkdir(parents=True, exist_ok=True)
    for fname, text in texts.items():
        path = out_dir / fname
        if not path.exists() or path.read_text() != text:
            # atomic: simulations of other modules may be reading this folder right now
            tmp = path.with_name(f".{fname}.{os.getpid()}.tmp")
            tmp.write_text(text)
            os.replace(tmp, path)
    return Generated(out_dir, files, manifest)
