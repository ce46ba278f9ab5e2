"""What every numeric input may be: the limits the fixed-point formats and the models set.

One layer, used by every command: `gpf.config.config_from_dict` (so `load_config`, and with it
every `--set` override) calls `check_config` after the schema and the formats; the scenario CSV
reader, given the config a recording is to be filtered with (`gpf.model.scenarios.read_csv`),
checks it with `input_limits`, `quaternion_problem` and `initial_state_problem`; `gpf run`,
`gpf model run` and `gpf model wordlength` check --particles with `check_particles` and a named
scenario with `check_scenario_name`. A value outside its limits is a ConfigError of one line
naming the key (or the CSV cell), the value and the range.

Two kinds of limit:
- per key (RULES): each bound follows from a format (its range 2^I, its LSB 2^-F) and what the
  models assume (an initial cloud of K_SIGMA sigma, the GRNG's reach |e| < 8, a unit
  quaternion); every command compares the value with `bounds()` of its rule;
- derived constants (datapath_problems): every constant the datapath computes
  from the keys is one 18-bit word with no negative fraction, and every exact sum of the model
  that takes one fits its 62-bit words. A refusal names the key whose change fixes it, with the
  range in which it does (found by bisection over the same check).

`limits_table()` is the README's section "Inputs and their limits" (`gpf limits` prints it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from gpf.config import (
    NOISE_FRAC_BITS,
    SCHEMA,
    WORD_BITS,
    Config,
    ConfigError,
    _show,
    config_path,
    load_config,
)
from gpf.model.blocks import MODEL_SUM_BITS
from gpf.model.fixed import Format
from gpf.model.formats import (
    CONST_WIDTH,
    UAV_ACCEL_INT_BITS,
    UAV_GYRO_INT_BITS,
    Datapath,
    datapath,
)

# The config keys each derived constant (and h, uav's rate step omega dt/2) is computed from,
# the key a refusal names first: gpf.limits names the first of them whose change fixes it.
CONST_KEYS = {
    "bot": {"T": ("filter.dt",), "T2": ("filter.dt",),
            "a": ("bot.process_var", "filter.dt"), "b": ("bot.process_var", "filter.dt"),
            "q_pp": ("bot.process_var", "filter.dt"), "q_pv": ("bot.process_var", "filter.dt"),
            "q_vv": ("bot.process_var", "filter.dt"), "c_u": ("bot.bearing_var",)},
    "uav": {"dt": ("filter.dt",), "dt2": ("filter.dt",), "h": ("filter.dt",),
            "s_w": ("uav.sigma_omega_deg",), "s_a": ("uav.sigma_a",),
            "q_q": ("uav.sigma_omega_deg", "filter.dt"), "q_v": ("uav.sigma_a", "filter.dt"),
            "c_u": ("uav.sigma_v",), "g0": (), "g1": (), "g2": ()},
}
def _sum_bits(terms: list[tuple[int, int]]) -> int:
    """Signed bits of an exact sum of terms (signed width, fraction bits) at the largest
    fraction, as blocks.round_sum forms it: the widest shifted term, a bit per doubling."""
    top = max(f for _, f in terms)
    return max(w + top - f for w, f in terms) + (len(terms) - 1).bit_length()


def datapath_problems(dp: Datapath) -> list[tuple[tuple[str, ...], str]]:
    """What of `dp`'s derived constants the models and the generator cannot represent, as
    (the constants involved, a one-line reason); empty when all fit. Each constant must be
    one 18-bit signed word with no negative fraction (|c| < 2^17: never a rescaled word); every
    exact sum of the fixed-point model that takes one must fit MODEL_SUM_BITS (the sums of
    blocks.propagate_bot and propagate_uav, mirrored here for operands anywhere in their
    formats); the whitening product d c_u must keep a fraction bit below u's LSB to round
    (the generator's weight block)."""
    out: list[tuple[tuple[str, ...], str]] = []
    c, w, ne = dp.consts, dp.word, dp.noise.width
    fe, cw = dp.noise.frac_bits, CONST_WIDTH
    for name, k in sorted(c.items()):
        if k.frac < 0:
            out.append(((name,), f"the constant {name} = {k.value:.4g} is not below "
                                 f"2^{cw - 1} (one {cw}-bit word would need a scale of "
                                 f"2^{-k.frac})"))

    def fits(names: tuple[str, ...], what: str, terms: list[tuple[int, int]]) -> None:
        bits = _sum_bits(terms)
        if bits > MODEL_SUM_BITS:
            at = ", ".join(f"{n} = {c[n].value:.4g}" if n in c else
                           f"h = omega dt/2 at {dp.h_frac} fraction bits" for n in names)
            out.append((names, f"{what} needs {bits}-bit exact sums ({at}); the model's sums "
                               f"hold {MODEL_SUM_BITS}"))

    if dp.app == "bot":
        fx = dp.x[0].frac_bits
        fits(("a", "T"), "propagate_bot's position sum",
             [(w, fx), (w + cw, fx + c["T"].frac), (ne + cw, fe + c["a"].frac)])
        fits(("b",), "propagate_bot's velocity sum", [(w, fx), (ne + cw, fe + c["b"].frac)])
        d_frac = dp.angle_frac
    else:
        fg, fa, fq = dp.gyro.frac_bits, dp.accel.frac_bits, dp.x[0].frac_bits
        fv = dp.x[4].frac_bits
        fits(("s_w",), "propagate_uav's body-rate sum",
             [(w, fg), (ne + cw, fe + c["s_w"].frac)])
        fits(("s_a",), "propagate_uav's specific-force sum",
             [(w, fa), (ne + cw, fe + c["s_a"].frac)])
        fits(("h",), "propagate_uav's quaternion update",
             [(w, fq)] + [(2 * w, dp.h_frac + fq)] * 3)
        fits(("dt",), "propagate_uav's velocity sum", [(w, fv), (w + cw, fa + c["dt"].frac)])
        d_frac = fv
    prod_frac = d_frac + c["c_u"].frac
    if prod_frac <= dp.u.frac_bits:
        out.append((("c_u",), f"the whitening product d c_u (c_u = {c['c_u'].value:.4g}) has "
                              f"{prod_frac} fraction bits; rounding it into u = {dp.u} needs "
                              f"at least {dp.u.frac_bits + 1}"))
    return out


K_SIGMA = 4        # the initial cloud is checked at 4 sigma of sigma0_diag
QUAT_TOL = 1e-3    # a unit quaternion: | |q| - 1 | <= QUAT_TOL
# filter.dt per app, in s: bot from 1 kHz to one step in 256 s (T^2 < 2^17: one 18-bit word);
# uav an IMU from 16 kHz to 8 Hz (|omega dt/2| <= 0.25 rad for the first-order q update)
DT_RANGE = {"bot": (2.0**-10, 2.0**8), "uav": (2.0**-14, 2.0**-3)}
BEARING_STD_MAX = 1.0   # rad: a bearing noisier than that carries next to no information
BEARING_TURN = 2 * math.pi   # |z| of a recorded bearing: at most one turn either way
# the smallest std a format resolves, in LSBs: half an LSB (the rounding's step); a noise or a
# spread below it rounds to the same value for most draws
RESOLVED = 0.5


# ---- the formats the rules speak of ----------------------------------------------------------
def _word(cfg: Config) -> int:
    return cfg.formats["state" if cfg.app == "bot" else "quaternion"].width


def gyro_format(cfg: Config) -> Format:
    """uav body rates (the gyro input), as gpf.model.formats.datapath builds it."""
    w = _word(cfg)
    return Format(True, UAV_GYRO_INT_BITS, w - 1 - UAV_GYRO_INT_BITS)


def accel_format(cfg: Config) -> Format:
    """uav specific force (the accelerometer input)."""
    w = _word(cfg)
    return Format(True, UAV_ACCEL_INT_BITS, w - 1 - UAV_ACCEL_INT_BITS)


def _reach(cfg: Config) -> float:
    """The GRNG's reach |e| < 8: the noise format's largest value."""
    return cfg.noise.max_real


def _bot_gains(cfg: Config) -> tuple[float, float]:
    """(a, b): one step's process noise on a position and a velocity, per unit draw."""
    s = math.sqrt(cfg.app_params["process_var"])
    return cfg.dt * cfg.dt / 2 * s, cfg.dt * s


def _uav_steps(cfg: Config) -> tuple[float, float]:
    """One step's process noise on a quaternion component (s_w dt/2) and a velocity (s_a dt)."""
    p = cfg.app_params
    return math.radians(p["sigma_omega_deg"]) * cfg.dt / 2, p["sigma_a"] * cfg.dt


def _sigma(cfg: Config, i: int) -> float:
    return math.sqrt(cfg.app_params["sigma0_diag"][i])


# ---- the headroom of an initial state (config x0, a recording's initial estimate) -----------
def state_bound(cfg: Config, mu: Sequence[float], i: int) -> float:
    """The largest |mu_i| whose cloud at K_SIGMA sigma, one step on, stays within the format:
    bot velocity |v| + K s_v + K b, position |p| + K s_p + dt (|v| + K s_v) + K a; uav
    quaternion |q_i| + K s_q + K s_w dt/2, velocity |v| + K s_v + K s_a dt."""
    k = K_SIGMA
    if cfg.app == "bot":
        top = cfg.formats["state"].max_real
        a, b = _bot_gains(cfg)
        if i % 2:
            return top - k * _sigma(cfg, i) - k * b
        return top - k * _sigma(cfg, i) - cfg.dt * (abs(mu[i + 1]) + k * _sigma(cfg, i + 1)) \
            - k * a
    q_step, v_step = _uav_steps(cfg)
    if i < 4:
        return cfg.formats["quaternion"].max_real - k * _sigma(cfg, i) - k * q_step
    return cfg.formats["velocity"].max_real - k * _sigma(cfg, i) - k * v_step


def _state_why(cfg: Config, i: int, name: str) -> str:
    if cfg.app == "bot":
        fmt = f"formats.state = '{cfg.formats['state']}'"
        motion = "" if i % 2 else f", moved one step (dt x {name}[{i + 1}] at 4 sigma)"
        return (f"its cloud at {K_SIGMA} sigma of sigma0_diag[{i}]{motion}, with one step's "
                f"process noise at {K_SIGMA} sigma, within {fmt} (|x| <= "
                f"{cfg.formats['state'].max_real:g})")
    key = "quaternion" if i < 4 else "velocity"
    return (f"its cloud at {K_SIGMA} sigma of sigma0_diag[{i}] and one step's process noise "
            f"at {K_SIGMA} sigma within formats.{key} = '{cfg.formats[key]}' (|x| <= "
            f"{cfg.formats[key].max_real:g})")


def _sigma0_bounds(cfg: Config, i: int) -> tuple[float, float]:
    """sigma0_diag[i]: a spread of at least half an LSB of the component's format, at most what
    leaves a centred cloud (x0 = 0; |q_i| = 1 for uav) within the format one step on."""
    k = K_SIGMA
    if cfg.app == "bot":
        fmt = cfg.formats["state"]
        a, b = _bot_gains(cfg)
        room = fmt.max_real - k * b if i % 2 else \
            fmt.max_real - cfg.dt * k * _sigma(cfg, i + 1) - k * a
    else:
        q_step, v_step = _uav_steps(cfg)
        fmt = cfg.formats["quaternion" if i < 4 else "velocity"]
        room = fmt.max_real - 1 - k * q_step if i < 4 else fmt.max_real - k * v_step
    hi = (room / k) ** 2 if room > 0 else -math.inf
    return (RESOLVED * fmt.lsb) ** 2, hi


def _sigma0_why(cfg: Config, i: int) -> str:
    if cfg.app == "bot":
        fmt = f"formats.state = '{cfg.formats['state']}'"
        motion = "" if i % 2 else f", moved one step (dt x 4 sigma of sigma0_diag[{i + 1}])"
        return (f"a spread of at least half an LSB; {K_SIGMA} sigma{motion} and one step's process "
                f"noise at {K_SIGMA} sigma within {fmt}")
    key = "quaternion" if i < 4 else "velocity"
    centre = "|q_i| = 1 + " if i < 4 else ""
    return (f"a spread of at least half an LSB; {centre}{K_SIGMA} sigma and one step's process "
            f"noise at {K_SIGMA} sigma within formats.{key} = '{cfg.formats[key]}'")


# ---- the rules, one per key ------------------------------------------------------------------
@dataclass(frozen=True)
class Rule:
    """The limits of one config key. `bounds(cfg, i)` is the allowed [lo, hi] of the value (of
    element i of a list; `symmetric`: |value| <= hi), given the config's other values."""

    key: str
    app: str
    rule: str                 # the README's statement of the rule
    why: str                  # and why
    units: tuple[str, ...]    # the value's unit; a list's, per element
    bounds: Callable[[Config, int | None], tuple[float, float]]
    explain: Callable[[Config, int | None], str]   # the reason, evaluated, for a refusal
    order: tuple[int, ...] = ()                    # list elements, in the order checked
    symmetric: bool = False

    def unit(self, i: int | None = None) -> str:
        return self.units[0 if i is None else i]


def _dt_rule(app: str, what: str) -> Rule:
    lo, hi = DT_RANGE[app]
    return Rule("filter.dt", app, f"2^{round(math.log2(lo))} <= dt <= 2^{round(math.log2(hi))} s",
                what, ("s",), lambda cfg, i: DT_RANGE[cfg.app],
                lambda cfg, i: f"{cfg.app}: {what}")


def _noise_rule(key: str, unit: str, to_value: Callable[[float], float], fmt_of, fmt_name: str,
                rule: str, why: str) -> Rule:
    """A noise std added to a value of format fmt_of(cfg) each step: at least half its LSB, at most
    its range over the GRNG's reach (8 sigma)."""
    def bounds(cfg: Config, i: int | None) -> tuple[float, float]:
        fmt = fmt_of(cfg)
        return to_value(RESOLVED * fmt.lsb), to_value(fmt.max_real / _reach(cfg))

    def explain(cfg: Config, i: int | None) -> str:
        return (f"at least half an LSB of {fmt_name} = '{fmt_of(cfg)}', at most its range over the "
                f"GRNG's reach {_reach(cfg):g} sigma")

    return Rule(key, key.split(".")[0], rule, why, (unit,), bounds, explain)


def _process_var_bounds(cfg: Config, i: int | None) -> tuple[float, float]:
    fmt, dt = cfg.formats["state"], cfg.dt
    top = fmt.max_real / (_reach(cfg) * dt * max(1.0, dt / 2))
    return (RESOLVED * fmt.lsb / dt) ** 2, top**2


def _bearing_bounds(cfg: Config, i: int | None) -> tuple[float, float]:
    return (RESOLVED * 2 * math.pi * 2.0 ** -_word(cfg)) ** 2, BEARING_STD_MAX**2


def _x0_bounds(cfg: Config, i: int | None) -> tuple[float, float]:
    assert i is not None
    b = state_bound(cfg, cfg.app_params["x0"], i)
    return -b, b


RULES: list[Rule] = [
    _dt_rule("bot", "T and T^2 are 18-bit constants (dt^2 < 2^17); a step of 1 ms to 256 s"),
    _dt_rule("uav", "an IMU period of 61 us to 125 ms: |omega dt/2| <= 0.25 rad (gyro range "
                    "4 rad/s) for the first-order quaternion update"),
    Rule("bot.process_var", "bot",
         "(LSB/2 / dt)^2 <= q <= (max / (E dt max(1, dt/2)))^2 of formats.state",
         "the velocity's noise a step, b = dt sqrt(q), is at least half an LSB (else it "
         "rounds away), and a step's noise at the GRNG's reach (a, b times E) stays within "
         "the range",
         ("m^2/s^3",), _process_var_bounds,
         lambda cfg, i: (f"dt sqrt(process_var) at least half an LSB of formats.state = "
                         f"'{cfg.formats['state']}' at filter.dt = {cfg.dt:g}, one step's noise "
                         f"at the GRNG's reach {_reach(cfg):g} sigma within its range")),
    Rule("bot.bearing_var", "bot", "(pi 2^-W)^2 <= R <= 1 rad^2",
         "a bearing noise of at least half an LSB of the W-bit binary angle (W the state word), "
         "at most 1 rad (57 deg: beyond it a wrapped bearing is no Gaussian measurement)",
         ("rad^2",), _bearing_bounds,
         lambda cfg, i: (f"a std of at least half an LSB of the {_word(cfg)}-bit binary angle, at "
                         f"most {BEARING_STD_MAX:g} rad")),
    _noise_rule("uav.sigma_omega_deg", "deg/s", math.degrees, gyro_format,
                "the gyro input format", "LSB/2 <= s_w <= max / E of the gyro format s2.(W-3)",
                "the gyro noise is added to the body rate each step: at least half an LSB, at "
                "the GRNG's reach within the range (4 rad/s)"),
    _noise_rule("uav.sigma_a", "m/s^2", lambda v: v, accel_format,
                "the accelerometer input format",
                "LSB/2 <= s_a <= max / E of the accelerometer format s6.(W-7)",
                "the accelerometer noise is added to the specific force each step: at least "
                "half an LSB, at the GRNG's reach within the range (64 m/s^2)"),
    _noise_rule("uav.sigma_v", "m/s", lambda v: v, lambda cfg: cfg.formats["velocity"],
                "formats.velocity", "LSB/2 <= sigma_v <= max / E of formats.velocity",
                "a GPS velocity noise the velocity format resolves, within its range at the "
                "GRNG's reach"),
    Rule("bot.sigma0_diag", "bot",
         "(LSB/2)^2 <= P_i; 4 sqrt(P_i) (+ dt 4 sqrt(P_v) + 4 a for a position, + 4 b for a "
         "velocity) <= max of formats.state",
         "the initial cloud is resolved by the state format and, centred, stays within it "
         "one step on (velocity entries checked first)", ("m^2", "(m/s)^2") * 2,
         lambda cfg, i: _sigma0_bounds(cfg, i or 0), lambda cfg, i: _sigma0_why(cfg, i or 0),
         order=(1, 3, 0, 2)),
    Rule("uav.sigma0_diag", "uav",
         "(LSB/2)^2 <= P_i; q: 1 + 4 sqrt(P_i) + 4 s_w dt/2 <= max of formats.quaternion; v: "
         "4 sqrt(P_i) + 4 s_a dt <= max of formats.velocity",
         "the initial cloud is resolved by its format and stays within it one step on",
         ("",) * 4 + ("(m/s)^2",) * 3, lambda cfg, i: _sigma0_bounds(cfg, i or 0),
         lambda cfg, i: _sigma0_why(cfg, i or 0), order=tuple(range(7))),
    Rule("bot.x0", "bot",
         "|x0_i| <= max - 4 sqrt(P_i) - (4 b | dt (|x0_v| + 4 sqrt(P_v)) + 4 a) of formats.state",
         "the initial cloud at 4 sigma, one step on (its motion and process noise), stays "
         "within the state format: no particle starts saturated", ("m", "m/s") * 2,
         _x0_bounds, lambda cfg, i: _state_why(cfg, i or 0, "x0"), order=(1, 3, 0, 2),
         symmetric=True),
]


# ---- checking --------------------------------------------------------------------------------
def _num(x: float, up: bool) -> str:
    """x to 4 significant digits, rounded towards the inside of a range (up for a lower
    bound), so that the printed bound itself is allowed."""
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    step = 10.0 ** (math.floor(math.log10(abs(x))) - 3)
    q = x / step
    q = round(q) if abs(q - round(q)) < 1e-6 else (math.ceil if up else math.floor)(q)
    return f"{q * step:.4g}"


def _range_text(lo: float, hi: float, symmetric: bool = False) -> str:
    if symmetric:
        return f"[-{_num(hi, False)}, {_num(hi, False)}]"
    return f"[{_num(lo, True)}, {_num(hi, False)}]"


def _value(cfg: Config, key: str) -> Any:
    return cfg.dt if key == "filter.dt" else cfg.app_params[key.split(".")[1]]


def _with(cfg: Config, key: str, value: float) -> Config:
    if key == "filter.dt":
        return replace(cfg, dt=value)
    return replace(cfg, app_params={**cfg.app_params, key.split(".")[1]: value})


def _constants_ok(cfg: Config, key: str) -> bool:
    """No derived constant that depends on `key` is out of its words."""
    try:
        problems = datapath_problems(datapath(cfg))
    except (ValueError, ArithmeticError):
        return False
    keys = CONST_KEYS[cfg.app]
    return not any(key in keys.get(n, ()) for names, _ in problems for n in names)


def _rule(cfg: Config, key: str) -> Rule | None:
    return next((r for r in RULES if r.key == key and r.app == cfg.app), None)


def key_range(cfg: Config, key: str) -> tuple[float, float] | None:
    """The values of a scalar key that its rule and the derived constants allow, the other
    keys as in `cfg`; None if none does. The constants' part by bisection in log2 of the value
    (every constant is a power of the key: the allowed set is one interval)."""
    rule = _rule(cfg, key)
    lo, hi = rule.bounds(cfg, None) if rule else (2.0**-1000, 2.0**1000)
    if not 0 < lo <= hi:
        return None

    def ok(e: float) -> bool:
        return _constants_ok(_with(cfg, key, 2.0**e), key)

    e_lo, e_hi = math.log2(lo), math.log2(hi)
    grid = [e_lo + (e_hi - e_lo) * k / 64 for k in range(65)]
    inside = [e for e in grid if ok(e)]
    if not inside:
        return None

    def edge(good: float, bad: float) -> float:
        for _ in range(40):
            mid = (good + bad) / 2
            good, bad = (mid, bad) if ok(mid) else (good, mid)
        return good

    first, last = inside[0], inside[-1]
    low = e_lo if ok(e_lo) else edge(first, max(e for e in grid if e < first))
    high = e_hi if ok(e_hi) else edge(last, min(e for e in grid if e > last))
    return max(lo, 2.0**low), min(hi, 2.0**high)


def _refuse_key(prefix: str, cfg: Config, rule: Rule, value: Any, i: int | None,
                lo: float, hi: float, detail: bool = True) -> ConfigError:
    elem = "" if i is None else f"{rule.key.split('.')[1]}[{i}] = {value[i]:g} "
    why = rule.explain(cfg, i)
    if detail and i is None and rule.key in CONST_KEYS_ALL:
        narrowed = key_range(cfg, rule.key)
        if narrowed is not None and narrowed != (lo, hi):
            lo, hi = narrowed
            why += "; the constants derived with the other values narrow it"
    fits = hi >= 0 if rule.symmetric else lo <= hi
    unit = f" {rule.unit(i)}" if rule.unit(i) else ""
    allowed = f"must lie in {_range_text(lo, hi, rule.symmetric)}{unit}" if fits else \
        "no value fits"
    return ConfigError(f"{prefix}{rule.key} = {_show(value)}: {elem}{allowed} ({why})")


CONST_KEYS_ALL = {k for app in CONST_KEYS.values() for keys in app.values() for k in keys}


def check_config(cfg: Config, prefix: str = "", detail: bool = True) -> None:
    """Every rule of cfg's app, in order, then the derived constants; the first problem is a
    ConfigError of one line starting with `prefix` (without `detail`, no bisection for the
    range the derived constants allow: what a bisection itself asks)."""
    for rule in RULES:
        if rule.app != cfg.app:
            continue
        value = _value(cfg, rule.key)
        for i in rule.order or (None,):
            v = value if i is None else value[i]
            lo, hi = rule.bounds(cfg, i)
            if not (abs(v) <= hi if rule.symmetric else lo <= v <= hi):
                raise _refuse_key(prefix, cfg, rule, value, i, lo, hi, detail)
    check_datapath(cfg, prefix=prefix, detail=detail)


def check_datapath(cfg: Config, word: int | None = None, prefix: str = "",
                   detail: bool = True) -> None:
    """The derived constants (datapath_problems) of cfg, or of its datapath
    resized to `word` bits (the word-length study); a problem names the key whose change fixes
    it and the range in which it does."""
    try:
        problems = datapath_problems(datapath(cfg, word))
    except (ValueError, ArithmeticError) as exc:
        raise ConfigError(f"{prefix}the datapath's constants cannot be computed: {exc}") \
            from None
    if not problems:
        return
    names, reason = problems[0]
    if word is not None or not detail:
        raise ConfigError(f"--word {word}: {prefix}{reason}" if word else f"{prefix}{reason}")
    keys = list(dict.fromkeys(k for n in names for k in CONST_KEYS[cfg.app].get(n, ())))
    for key in keys:
        allowed = key_range(cfg, key)
        if allowed is not None:
            rule = _rule(cfg, key)
            unit = f" {rule.unit()}" if rule else ""
            raise ConfigError(f"{prefix}{key} = {_show(_value(cfg, key))}: {reason}; with the "
                              f"other values as given it must lie in "
                              f"{_range_text(*allowed)}{unit}")
    what = keys[0] if keys else f"formats.{'state' if cfg.app == 'bot' else 'quaternion'}"
    value = _show(_value(cfg, what)) if keys else repr(str(cfg.formats[what.split('.')[1]]))
    raise ConfigError(f"{prefix}{what} = {value}: {reason}; no value of "
                      f"{', '.join(keys) or 'the noise keys'} fits these formats")


def check_particles(cfg: Config, n: int | None, name: str = "--particles") -> int:
    """The run-time N of every command (`gpf run`, `gpf model run`, `gpf model wordlength`):
    a multiple of filter.lanes in [2, filter.particles] (the ESS word and the RTL's counters
    are sized for filter.particles). None: filter.particles."""
    if n is None:
        return cfg.particles
    if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= cfg.particles \
            or n % cfg.lanes:
        raise ConfigError(f"{name} {n}: must be a multiple of filter.lanes = {cfg.lanes} in "
                          f"[2, {cfg.particles}] (filter.particles of {cfg.name}: the largest N "
                          "its datapath is sized for)")
    return n


# ---- recordings (scenario CSV files) ---------------------------------------------------------
def input_limits(cfg: Config) -> dict[str, tuple[float, float, str]]:
    """CSV input and measurement columns: (lo, hi, what) of the format each is quantised to."""
    def fmt(f: Format, what: str) -> tuple[float, float, str]:
        return f.min_real, f.max_real, f"{what} = '{f}'"

    if cfg.app == "bot":
        state = fmt(cfg.formats["state"], "formats.state")
        return {"z": (-BEARING_TURN, BEARING_TURN, "one turn either way (the binary angle wraps "
                      "modulo a turn)"), "ox": state, "oy": state}
    gyro = fmt(gyro_format(cfg), "the gyro format")
    accel = fmt(accel_format(cfg), "the accelerometer format")
    vel = fmt(cfg.formats["velocity"], "formats.velocity")
    return {"wx": gyro, "wy": gyro, "wz": gyro, "ax": accel, "ay": accel, "az": accel,
            "vgE": vel, "vgN": vel, "vgU": vel}


def quaternion_problem(q: Sequence[float]) -> str | None:
    norm = math.hypot(*(float(v) for v in q))   # no overflow on a 1e300 component
    if abs(norm - 1) <= QUAT_TOL:
        return None
    return (f"[{', '.join(f'{float(v):g}' for v in q)}] has norm {norm:.6g}; a quaternion must "
            f"have norm 1 within {QUAT_TOL:g}")


def initial_state_problem(cfg: Config, mu: Sequence[float], name: str,
                          columns: Sequence[str] | None = None) -> str | None:
    """The initial estimate `mu` (a recording's mu0, or its truth at k = 0: `columns` name its
    elements) against the same headroom as bot.x0; uav: its quaternion of unit norm."""
    def label(i: int) -> str:
        return f"{name}, column '{columns[i]}'" if columns else f"{name}[{i}]"

    if cfg.app == "uav":
        bad = quaternion_problem(mu[:4])
        if bad:
            return f"{name}{', columns q0..q3' if columns else '[0:4]'} = {bad}"
    for i in ((1, 3, 0, 2) if cfg.app == "bot" else range(7)):
        bound = state_bound(cfg, mu, i)
        if not abs(mu[i]) <= bound:
            allowed = f"must lie in {_range_text(-bound, bound, True)}" if bound >= 0 else \
                "no value fits"
            return (f"{label(i)} = {float(mu[i]):g} {allowed} "
                    f"({_state_why(cfg, i, columns[i] if columns else name.split()[-1])})")
    return None


# ---- the README's table ----------------------------------------------------------------------
SHIPPED = {"bot": ("bot", "odd"), "uav": ("uav", "uav_seed002")}

FORMAT_LIMITS = [
    ("formats.state, formats.quaternion, formats.velocity",
     f"signed sI.F, one datapath word of {WORD_BITS[0]} to {WORD_BITS[1]} bits (uav: "
     "quaternion and velocity as wide); the quaternion with at least one integer bit",
     f"below {WORD_BITS[0]} bits the weight's exponent has no fraction, above {WORD_BITS[1]} "
     "the CORDIC's and Cholesky's sums pass 63 bits; |q_i| <= 1"),
    ("formats.noise", f"s3.F, F in [{NOISE_FRAC_BITS[0]}, {NOISE_FRAC_BITS[1]}]",
     "N(0, 1) draws: the inversion GRNG reaches 7.9 sigma (E = the format's max); a draw is "
     "one 18-bit multiplier operand"),
    ("formats.weight", "u1.F", "weights 2^-t lie in (0, 1]"),
    ("any format", "sI.F or uI.F, at most 64 bits", ""),
]
RECORDING_LIMITS = [
    ("app", "the config's filter.app (its columns name it)", ""),
    ("dt (metadata or column t)", "filter.dt (relative 1e-9)",
     "the filter propagates with filter.dt"),
    ("every number", "finite", ""),
    ("z (bot)", "|z| <= 2 pi rad", "one turn either way; the binary angle wraps modulo a turn"),
    ("ox, oy (bot)", "within formats.state", "quantised to it"),
    ("wx, wy, wz (uav)", "within the gyro format s2.(W-3) (+-4 rad/s)", "quantised to it"),
    ("ax, ay, az (uav)", "within the accelerometer format s6.(W-7) (+-64 m/s^2)",
     "quantised to it"),
    ("vgE, vgN, vgU (uav)", "within formats.velocity", "quantised to it"),
    ("q0..q3 (uav truth, any row)", f"norm 1 within {QUAT_TOL:g}", "a unit quaternion"),
    ("initial estimate (metadata mu0; bot: else x0; uav: else the truth at k = 0)",
     "as bot.x0 (uav: quaternion of norm 1 within "
     f"{QUAT_TOL:g}, each component as x0 with its format)",
     "the filter starts there"),
]


def _shipped(name: str) -> Config:
    return load_config(config_path(name))


def _with_element(cfg: Config, key: str, i: int | None, v: float) -> Config:
    if i is None:
        return _with(cfg, key, v)
    values = list(_value(cfg, key))
    values[i] = v
    return replace(cfg, app_params={**cfg.app_params, key.split(".")[1]: values})


def accepted_range(cfg: Config, key: str, i: int | None = None) -> tuple[float, float]:
    """The values of `key` (element i of a list) that the whole check accepts, every other
    value as in cfg (which must pass): by bisection over check_config itself, from the value
    (accepted) to the far ends (2^+-300; for bot.x0, +-2 max of the state format)."""
    def ok(v: float) -> bool:
        try:
            check_config(_with_element(cfg, key, i, v), detail=False)
        except ConfigError:
            return False
        return True

    def edge(good: float, bad: float, to: Callable[[float], float]) -> float:
        if ok(to(bad)):
            return to(bad)
        for _ in range(48):
            mid = (good + bad) / 2
            good, bad = (mid, bad) if ok(to(mid)) else (good, mid)
        near = float(f"{to(good):.4g}")     # a bound the check itself accepts, printed as is
        return near if ok(near) else to(good)

    value = _value(cfg, key) if i is None else _value(cfg, key)[i]
    if key == "bot.x0":     # symmetric: |x0_i| <= its bound
        top = 2 * cfg.formats["state"].max_real
        hi = edge(abs(value), top, lambda v: v)
        return -hi, hi
    e = math.log2(value)
    return edge(e, -300.0, lambda v: 2.0**v), edge(e, 300.0, lambda v: 2.0**v)


def _evaluated(cfg: Config, rule: Rule) -> str:
    """What the check accepts for rule's key in cfg (its other values as shipped)."""
    if not rule.order:
        return _range_text(*accepted_range(cfg, rule.key))
    groups: dict[str, list[int]] = {}
    for i in sorted(rule.order):
        text = _range_text(*accepted_range(cfg, rule.key, i), rule.symmetric)
        groups.setdefault(text, []).append(i)
    return "; ".join(f"{','.join(map(str, idx))}: {text}" for text, idx in groups.items())


def _cell(text: str) -> str:
    """Markdown table cell text: a | of |x| escaped."""
    return text.replace("|", "\\|")


def limits_table() -> str:
    """The README's section "Inputs and their limits", generated from the checks themselves."""
    out = [
        "## Inputs and their limits",
        "",
        "Every command checks these when it loads a config (`gpf.config.load_config`, `--set` "
        "overrides included) and when it reads a scenario CSV; a value outside them ends in "
        "one line naming the key (or the CSV cell: row and column), the value and the allowed "
        "range, exit status 2. Generated by `gpf limits` from the code that checks "
        "(`gpf/limits.py`; `tests/test_validation.py` keeps this section equal to it).",
        "",
        f"Symbols: a format sI.F has LSB 2^-F and max 2^I - 2^-F; W is the datapath word; "
        f"K = {K_SIGMA} (the initial cloud is checked at {K_SIGMA} sigma); E is the GRNG's reach, "
        "the noise format's max (7.99 for s3.F); a = dt^2/2 sqrt(q), b = dt sqrt(q) (bot's "
        "process noise per draw); s_w, s_a the uav's gyro and accelerometer noise.",
        "",
        "| key | allowed | why |",
        "|---|---|---|",
    ]

    def row(key: str, allowed: str, why: str) -> str:
        return f"| {_cell(key)} | {_cell(allowed)} | {_cell(why)} |"

    for section, keys in SCHEMA.items():
        if section == "formats":
            out += [row(f"`{k}`", a, w) for k, a, w in FORMAT_LIMITS]
            continue
        for name, key in keys.items():
            dotted = f"{section}.{name}"
            rules = [r for r in RULES if r.key == dotted]
            if not rules:
                extra = ", a multiple of filter.lanes" if dotted == "filter.particles" else ""
                out.append(row(f"`{dotted}`", key.allowed + extra, ""))
                continue
            for r in rules:
                label = f"`{dotted}` ({r.app})" if dotted.startswith("filter.") else \
                    f"`{dotted}`"
                out.append(row(label, f"{key.allowed}; {r.rule}", r.why))
    out += [
        row("derived constants", f"each an 18-bit signed word with no negative fraction "
            f"(below 2^17); every exact sum of the model that takes one within "
            f"{MODEL_SUM_BITS} bits; the whitening product d c_u with a fraction bit below u's",
            "never a silently rescaled constant, never an overflowing model sum; a refusal "
            "names the key (process_var, bearing_var, sigma_*, dt) and the range that fits"),
        row("`--particles`", "a multiple of filter.lanes in [2, filter.particles]",
            "`gpf run`, `gpf model run` and `gpf model wordlength` alike: the ESS word and the "
            "RTL's counters are sized for filter.particles"),
        row("`--word`", f"as the derived constants (the model's sums within {MODEL_SUM_BITS} "
            "bits at that word)", "the word-length study resizes every line-rate word"),
        "",
        "A scenario CSV (`--scenario FILE.csv`):",
        "",
        "| column or field | allowed | why |",
        "|---|---|---|",
    ]
    out += [row(f"`{k}`", a, w) for k, a, w in RECORDING_LIMITS]
    for app, names in SHIPPED.items():
        cfgs = [_shipped(n) for n in names]
        out += ["", f"What the check accepts for each key of the shipped {app} configs, the "
                "config's other values as shipped (list entries by index; found by bisection "
                "over the check itself):", "",
                "| key | " + " | ".join(f"`configs/{n}.toml`" for n in names) + " |",
                "|---" * (len(names) + 1) + "|"]
        for rule in RULES:
            if rule.app == app:
                units = ", ".join(dict.fromkeys(u or "-" for u in rule.units))
                out.append(f"| `{rule.key}` ({units}) | "
                           + " | ".join(_evaluated(c, rule) for c in cfgs) + " |")
    return "\n".join(out) + "\n"


def check_scenario_name(cfg: Config, name: str | None) -> None:
    """A named scenario (not a CSV file) of cfg's app, for `gpf run` and `gpf model run` alike,
    before any work: one line, never a KeyError from inside a scenario."""
    if name is None or name.endswith(".csv"):
        return
    from gpf.study.montecarlo import SCENARIOS

    names = [s for s in SCENARIOS if s.startswith(cfg.app + "_")]
    if name not in names:
        what = f"a {name.split('_')[0]} scenario, config {cfg.name!r} is {cfg.app}" \
            if name in SCENARIOS else "unknown"
        raise ConfigError(f"--scenario {name}: {what}; choose one of {', '.join(names)} or "
                          "give a CSV file")
