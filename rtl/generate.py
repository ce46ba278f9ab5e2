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
from gpf.model.formats import CONST_WIDTH, INV_GUARD, datapath
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
    sq_width = 2 * u.width
    return {
        "word": dp.word, "x_fmt": [str(f) for f in dp.x], "terms": terms,
        "c_width": CONST_WIDTH, "c_u": f"{_twos(c.raw, CONST_WIDTH):X}", "c_u_real": c.real,
        "c_frac": c.frac, "prod_width": dp.word + CONST_WIDTH,
        "whiten_shift": whiten_shift, "u_width": u.width, "u_fmt": str(u),
        "sq_width": sq_width, "sum_width": sq_width + (terms - 1).bit_length() + 1,
        "t_shift": t_shift, "t_width": t.width, "t_fmt": str(t), "t_max": t.max_raw,
        "w_width": dp.weight.width, "w_fmt": str(dp.weight),
        # stages after the innovation d: product, u, squares, t; then the exp lane
        "tail_latency": 4 + ex["latency"],
    }


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
    return {**k, "lanes": cfg.lanes, "angle_width": dp.angle_frac, "components": dp.n,
            "z_delay": z_delay, "latency": z_delay + 1 + k["tail_latency"]}


def weight_uav_context(cfg: Config) -> dict[str, Any]:
    """w = 2^-t, t = sum_k ((v_gps,k - v_k) c_u)^2 (model: blocks.weight_uav): stage 1 the
    saturating differences, then the whitening tail."""
    dp = datapath(cfg)
    vel = dp.x[4:7]
    if dp.app != "uav" or len(set(vel)) != 1:
        raise ValueError("weight_uav: needs the uav state with one velocity format")
    k = _whiten_context(cfg, [f.frac_bits for f in vel])
    return {**k, "lanes": cfg.lanes, "components": dp.n, "v_first": 4,
            "latency": 1 + k["tail_latency"]}


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
    "weight_bot": Module("weight_bot", ("weight_bot_lane", "weight_bot"), weight_bot_context,
                         uses=("cordic_atan2", "exp"), apps=("bot",)),
    "weight_uav": Module("weight_uav", ("weight_uav_lane", "weight_uav"), weight_uav_context,
                         uses=("exp",), apps=("uav",)),
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
