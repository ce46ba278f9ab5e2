"""Every fixed-point format and constant of the GPF datapath, derived once from the config.

The fixed-point model computes with these, and the generator writes the same values into the
RTL. Line-rate operands are one datapath word (the state formats' width); constants are 18-bit
signed (one DSP48 operand); the serial finalisation (moments' divisions, Cholesky) is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

from gpf.config import Config
from gpf.model.fixed import Format
from gpf.model.primitives import Cordic, Exp2Neg

CONST_WIDTH = 18     # constants are one 18-bit DSP operand
CHOL_SHIFT = 3       # L entries carry up to 3 more fraction bits than the state they scale
CHOL_GUARD = 4       # and 4 bits more than a state word: L is one wide DSP48 operand (it only
L_WIDTH_MAX = 25     # multiplies 18-bit draws), and the quaternion's rank-deficient covariance
                     # (its norm direction) needs them: with L at the state's width, the
                     # Cholesky's rounding residue left the fixed-point uav filter unlike float64
INV_GUARD = 8        # extra fraction bits of 1/L_jj in the Cholesky
CHOL_FLOOR_LSB = 16  # regularisation: a Cholesky pivot below (16 LSB of L)^2 or below
CHOL_FLOOR_REL_BITS = 16  # 2^-16 of its diagonal entry is raised to that floor
ESS_FRAC = 4         # fraction bits of the effective sample size W^2 / sum w^2
# The exponent t of a weight 2^-t reaches as far as float64's own exp(-d^2/2) (which
# underflows near t = 1075): weights are relative to the best particle, so a cloud far from the
# measurement still needs its ordering. Beyond the reach (every t >= 2^T_INT_BITS - 1) the
# measurement is ignored.
T_INT_BITS = 10      # t < 1024: 37.7 sigma in one dimension
U_INT_BITS = 5       # u = whitened innovation, |u| < 32, so each u^2 < 1024
SHIFT_BITS = 7       # the rescale of a beat is at most 127 (it clears any accumulator)
UAV_GYRO_INT_BITS = 2    # body rates within +-4 rad/s
UAV_ACCEL_INT_BITS = 6   # specific force within +-64 m/s^2 (6.5 g)
GRAVITY = (0.0, 0.0, -9.8)


@dataclass(frozen=True)
class Const:
    """A real constant quantised to an 18-bit signed raw value with as many fraction bits as fit."""

    value: float
    raw: int
    frac: int

    @classmethod
    def of(cls, value: float, width: int = CONST_WIDTH) -> Const:
        if value == 0:
            return cls(value, 0, width - 1)
        # |value| < 2^int_bits (int_bits < 0 for small constants: more fraction bits)
        int_bits = math.floor(math.log2(abs(value))) + 1
        frac = width - 1 - int_bits
        raw = math.floor(value * 2.0**frac + 0.5)
        if not -(1 << (width - 1)) <= raw < 1 << (width - 1):  # rounded up to a power of 2
            frac -= 1
            raw = math.floor(value * 2.0**frac + 0.5)
        return cls(value, raw, frac)

    @property
    def real(self) -> float:
        return self.raw / 2**self.frac


def shifted(fmt: Format, shift: int) -> Format:
    """The same width with `shift` integer bits moved to the fraction."""
    return Format(fmt.signed, fmt.int_bits - shift, fmt.frac_bits + shift)


@dataclass(frozen=True)
class Datapath:
    """Formats per state component, the derived formats, constants and primitives."""

    app: str
    x: tuple[Format, ...]        # state components (particles, mu, ref, x - ref)
    chol: tuple[Format, ...]     # row i of L scales state i: CHOL_SHIFT + CHOL_GUARD more
                                 # fraction bits, one width for all (a state word + CHOL_GUARD)
    noise: Format
    weight: Format
    angle_frac: int              # bot: bearings in turns, one turn = 2^W: a W-bit binary
                                 # angle in [-1/2, 1/2) turn that wraps modulo one turn
    u: Format                    # whitened innovation
    t: Format                    # exponent of the weight, w = 2^-t
    consts: dict[str, Const]
    cordic: Cordic | None
    exp2: Exp2Neg
    gyro: Format | None = None    # uav inputs: body rates, rad/s
    accel: Format | None = None   # specific force, m/s^2 (also the C(q) a + g sum)
    rot: Format | None = None     # entries of C(q)
    h_frac: int = 0               # uav: h = omega dt/2 kept in one word with these fraction bits
    ess: Format = Format(False, 12, ESS_FRAC)   # W^2 / sum w^2: up to the config's maximum N
    ess_shift: int | None = None  # ESS below N / 2^ess_shift: degenerate weights (None: never)

    @property
    def n(self) -> int:
        return len(self.x)

    @property
    def word(self) -> int:
        return self.x[0].width

    def cov_frac(self, i: int, j: int) -> int:
        """Sigma_ij carries the fraction bits of L_i * L_j, so L = chol(Sigma) needs no shift."""
        return self.chol[i].frac_bits + self.chol[j].frac_bits

    def sigma(self, i: int, j: int) -> Format:
        """Sigma_ij: |Sigma_ij| <= max |dx_i| max |dx_j| < 2^(I_i + I_j) (Cauchy-Schwarz over
        saturated deviations), one more integer bit for rounding: 2W bits in all."""
        return self._sigma_formats[(i, j)]

    @cached_property
    def _sigma_formats(self) -> dict[tuple[int, int], Format]:
        """Every (i, j)'s Sigma format, built once: testbenches ask for them per matrix entry."""
        return {(i, j): Format(True, self.x[i].int_bits + self.x[j].int_bits + 1,
                               self.cov_frac(i, j))
                for i in range(self.n) for j in range(self.n)}

    def draws(self) -> int:
        return {"bot": 6, "uav": 13}[self.app]


def state_formats(cfg: Config) -> tuple[Format, ...]:
    f = cfg.formats
    if cfg.app == "bot":
        return (f["state"],) * 4
    return (f["quaternion"],) * 4 + (f["velocity"],) * 3


def with_word(fmt: Format, word: int) -> Format:
    """`fmt` resized to `word` bits, keeping its integer bits (the word-length study's knob)."""
    return Format(fmt.signed, fmt.int_bits, word - fmt.int_bits - (1 if fmt.signed else 0))


def datapath(cfg: Config, word: int | None = None) -> Datapath:
    """The datapath of `cfg`; `word` resizes every line-rate operand (state, L, weight)."""
    x = state_formats(cfg)
    weight = cfg.weight
    if word is not None:
        x = tuple(with_word(fmt, word) for fmt in x)
        weight = with_word(weight, word)
    w = x[0].width
    guard = max(0, min(CHOL_GUARD, L_WIDTH_MAX - w))
    chol = tuple(Format(True, fmt.int_bits - k, fmt.frac_bits + k + guard)
                 for fmt in x for k in [min(CHOL_SHIFT, fmt.int_bits)])
    u = Format(True, U_INT_BITS, w - 1 - U_INT_BITS)
    t = Format(False, T_INT_BITS, w - 8)           # W - 8 fraction bits, whatever the reach
    p = cfg.app_params
    log2e = math.log2(math.e)
    if cfg.app == "bot":
        q, dt = p["process_var"], cfg.dt
        consts = {
            "T": Const.of(dt),
            "a": Const.of(dt * dt / 2 * math.sqrt(q)),   # position gain of a process draw
            "b": Const.of(dt * math.sqrt(q)),            # velocity gain
            # u = d * c_u with d in turns: u^2 = d_rad^2 / (2 R) * log2(e)
            "c_u": Const.of(2 * math.pi * math.sqrt(log2e / (2 * p["bearing_var"]))),
            # the predicted covariance Phi Sigma Phi^T + Gamma Q Gamma^T (low ESS)
            "T2": Const.of(dt * dt),
            "q_pp": Const.of(q * dt**4 / 4), "q_pv": Const.of(q * dt**3 / 2),
            "q_vv": Const.of(q * dt * dt),
        }
        cordic = Cordic.for_widths(w, w)
        return Datapath(cfg.app, x, chol, cfg.noise, weight, w, u, t, consts, cordic,
                        _exp2(t, weight), ess=_ess(cfg), ess_shift=_ess_shift(cfg))
    dt = cfg.dt
    consts = {
        "c_u": Const.of(math.sqrt(log2e / 2) / p["sigma_v"]),
        "dt": Const.of(dt),
        "dt2": Const.of(dt / 2),
        "s_w": Const.of(math.radians(p["sigma_omega_deg"])),
        "s_a": Const.of(p["sigma_a"]),
        **{f"g{n}": Const.of(g) for n, g in enumerate(GRAVITY)},
        # the predicted covariance Sigma + Q, the IMU noise of one step (low ESS)
        "q_q": Const.of((dt / 2 * math.radians(p["sigma_omega_deg"])) ** 2),
        "q_v": Const.of((p["sigma_a"] * dt) ** 2),
    }
    gyro = Format(True, UAV_GYRO_INT_BITS, w - 1 - UAV_GYRO_INT_BITS)
    accel = Format(True, UAV_ACCEL_INT_BITS, w - 1 - UAV_ACCEL_INT_BITS)
    # |omega dt/2| < 2^(gyro int bits) * dt/2: as many fraction bits as one word then holds
    h_frac = w - 1 - UAV_GYRO_INT_BITS - (math.floor(math.log2(dt / 2)) + 1)
    return Datapath(cfg.app, x, chol, cfg.noise, weight, w, u, t, consts,
                    None, _exp2(t, weight), gyro=gyro, accel=accel,
                    rot=Format(True, 1, w - 2), h_frac=h_frac, ess=_ess(cfg),
                    ess_shift=_ess_shift(cfg))


def _ess_shift(cfg: Config) -> int | None:
    """filter.ess_min = 2^-k as k (None for 0: the rule is off)."""
    return None if cfg.ess_min == 0 else round(-math.log2(cfg.ess_min))


def _ess(cfg: Config) -> Format:
    """ESS <= N (Cauchy-Schwarz; the rescales' roundings can add a little: one more bit)."""
    return Format(False, cfg.particles.bit_length() + 1, ESS_FRAC)


def _exp2(t: Format, weight: Format) -> Exp2Neg:
    return Exp2Neg.for_formats(in_width=t.width, in_frac=t.frac_bits, out_frac=weight.frac_bits)


def constants(dp: Datapath) -> dict:
    """Everything the RTL of the filter blocks is generated from (JSON-able, for the manifest)."""
    out = {
        "app": dp.app,
        "state": [str(f) for f in dp.x],
        "chol": [str(f) for f in dp.chol],
        "noise": str(dp.noise), "weight": str(dp.weight), "u": str(dp.u), "t": str(dp.t),
        "angle_frac": dp.angle_frac,
        "consts": {k: {"value": c.value, "raw": c.raw, "frac": c.frac}
                   for k, c in sorted(dp.consts.items())},
        "chol_floor_lsb": CHOL_FLOOR_LSB, "chol_floor_rel_bits": CHOL_FLOOR_REL_BITS,
        "inv_guard": INV_GUARD, "ess": str(dp.ess), "ess_shift": dp.ess_shift,
        "exp2": dp.exp2.constants(),
    }
    if dp.cordic is not None:
        out["cordic"] = dp.cordic.constants()
    if dp.gyro is not None:
        out.update(gyro=str(dp.gyro), accel=str(dp.accel), rot=str(dp.rot), h_frac=dp.h_frac)
    return out
