"""One typed, validated design config, loaded from TOML.

Every key is declared once in the schema below; an unknown key, a wrong type or a value out of
range raises ConfigError with one line naming the key, the value and what is allowed.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from gpf.model.fixed import Format


class ConfigError(ValueError):
    """A config that cannot be used; str() is one line for the user."""


@dataclass(frozen=True)
class Key:
    """One config key: its type, what values are allowed, and its default (None: required)."""

    kind: type | tuple[type, ...]
    allowed: str
    check: Callable[[Any], bool] = lambda v: True
    default: Any = None


def _int_range(lo: int, hi: int, default: int | None = None) -> Key:
    return Key(int, f"an integer in [{lo}, {hi}]", lambda v: lo <= v <= hi, default)


def _choice(*options: Any, default: Any = None) -> Key:
    kind = type(options[0])
    return Key(kind, "one of " + ", ".join(repr(o) for o in options), lambda v: v in options,
               default)


def _finite(v: int | float) -> bool:
    """A number a float can hold (a 400-digit TOML integer cannot)."""
    try:
        return math.isfinite(v)
    except OverflowError:
        return False


def _positive_float(default: float | None = None) -> Key:
    return Key((int, float), "a number > 0", lambda v: _finite(v) and v > 0, default)


def _vector(n: int, positive: bool = False) -> Key:
    what = f"a list of {n} {'positive ' if positive else ''}numbers"
    return Key(list, what, lambda v: len(v) == n and all(
        isinstance(x, int | float) and not isinstance(x, bool) and _finite(x)
        and (x > 0 or not positive) for x in v))


def _format_key(default: str | None = None) -> Key:
    def ok(text: str) -> bool:
        try:
            fmt = Format.parse(text)
        except ValueError:
            return False
        return fmt.width <= 64

    return Key(str, "a fixed-point format sI.F or uI.F of at most 64 bits, e.g. 's3.20'", ok,
               default)


ESS_MIN_DEFAULT = 0.0


def _ess_fraction(v: int | float) -> bool:
    return _finite(v) and (v == 0 or any(v == 2.0**-k for k in range(17)))

SCHEMA: dict[str, dict[str, Key]] = {
    "filter": {
        "app": _choice("bot", "uav"),
        "particles": _int_range(2, 1 << 16),
        "lanes": _choice(1, 2, 4),
        "steps": _int_range(1, 100_000),
        "dt": _positive_float(),
        # a step whose effective sample size is below this fraction of N has degenerate
        # weights: the next step samples from the predicted covariance, not the weighted one.
        # A power of two (a shift of N in hardware), or 0: never.
        "ess_min": Key((int, float), "0 or a power of two 2^-k, k = 0 .. 16 (a fraction of N)",
                       _ess_fraction, default=ESS_MIN_DEFAULT),
        # the FPGA family the generated multipliers are shaped for: "xc7" (DSP48E1, 25 x 18
        # signed) or "ecp5" (MULT18X18D, 18 x 18). Same arithmetic, bit for bit; only how a
        # wide product is split into DSPs differs. `gpf synth` measures xc7, `gpf timing` ecp5.
        "family": _choice("xc7", "ecp5", default="xc7"),
    },
    "formats": {
        # bot: one format for the whole state [px, vx, py, vy]; uav: quaternion and velocity
        "state": _format_key(default=""),
        "quaternion": _format_key(default=""),
        "velocity": _format_key(default=""),
        "weight": _format_key(),
        "noise": _format_key(),
    },
    "grng": {
        "seed": _int_range(0, (1 << 64) - 1),
        # inversion LUT: octaves of the uniform's leading-zero count, segments per octave
        "octaves": _int_range(32, 48, default=48),  # 32: 6.3 sigma reachable, 48: 7.9
        "segment_bits": _int_range(2, 6, default=4),
        "offset_bits": _int_range(8, 17, default=17),
        "guard_bits": _int_range(0, 12, default=6),
    },
    "bot": {
        "process_var": _positive_float(),
        "bearing_var": _positive_float(),
        "x0": _vector(4),
        "sigma0_diag": _vector(4, positive=True),
    },
    "uav": {
        "sigma_omega_deg": _positive_float(),
        "sigma_a": _positive_float(),
        "sigma_v": _positive_float(),
        "covariance": _choice("full", "block"),
        # initial covariance diagonal for [q0, q1, q2, q3, vE, vN, vU]
        "sigma0_diag": _vector(7, positive=True),
    },
}

APP_FORMATS = {"bot": ("state",), "uav": ("quaternion", "velocity")}
# the noise format s3.F: the inversion GRNG reaches 7.9 sigma (three integer bits, signed), and
# a draw is one 18-bit multiplier operand (sample_cond's and the propagation's): F <= 14
NOISE_FRAC_BITS = (4, 14)
# the datapath word (the state formats' width) the generator can build: below 8 bits the
# weight's exponent has no fraction, above 30 the CORDIC's and Cholesky's sums pass 63 bits
WORD_BITS = (8, 30)


@dataclass(frozen=True)
class GrngConfig:
    seed: int
    octaves: int
    segment_bits: int
    offset_bits: int
    guard_bits: int


@dataclass(frozen=True)
class Config:
    """A validated design config. `name` is the config file's stem (the build folder's name)."""

    name: str
    source: str
    app: str
    particles: int
    lanes: int
    steps: int
    dt: float
    formats: dict[str, Format]
    ess_min: float
    family: str
    grng: GrngConfig
    app_params: dict[str, Any] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)  # 'section.key' -> value

    @property
    def noise(self) -> Format:
        return self.formats["noise"]

    @property
    def weight(self) -> Format:
        return self.formats["weight"]

    @property
    def covariance(self) -> str:
        """uav "block" (the [q] and [v] blocks of Sigma) or "full"; bot: "full"."""
        return self.app_params.get("covariance", "full")


def _type_name(kind: type | tuple[type, ...]) -> str:
    names = {int: "integer", float: "number", str: "string", list: "list"}
    if isinstance(kind, tuple):
        return " or ".join(names[k] for k in kind)
    return names[kind]


def _show(value: Any) -> str:
    """repr() cut to one short line: a message stays readable whatever the value."""
    text = repr(value)
    return text if len(text) <= 60 else text[:50] + "..." + text[-7:]


def _name(text: str) -> str:
    """A section, key or path as the user wrote it, quoted when it would break the line."""
    return text if text.isprintable() else repr(text)


def _check_key(where: str, key: Key, value: Any) -> Any:
    # bool is an int in Python; a config never means True for a number
    kinds = key.kind if isinstance(key.kind, tuple) else (key.kind,)
    if isinstance(value, bool) or not isinstance(value, kinds):
        raise ConfigError(f"{where} = {_show(value)}: expected {_type_name(key.kind)}, "
                          f"{key.allowed}")
    if not key.check(value):
        raise ConfigError(f"{where} = {_show(value)}: must be {key.allowed}")
    return value


def _read_sections(doc: dict[str, Any], prefix: str) -> dict[str, dict[str, Any]]:
    values: dict[str, dict[str, Any]] = {}
    for section in doc:
        if section not in SCHEMA and not isinstance(doc[section], dict):
            raise ConfigError(f"{prefix}{_name(section)} = {_show(doc[section])}: a key "
                              "outside any section; allowed sections are " + ", ".join(SCHEMA))
        if section not in SCHEMA:
            raise ConfigError(f"{prefix}unknown section [{_name(section)}]: allowed sections "
                              "are " + ", ".join(SCHEMA))
        if not isinstance(doc[section], dict):
            raise ConfigError(f"{prefix}{section} = {_show(doc[section])}: expected a "
                              f"[{section}] table")
    app = doc.get("filter", {}).get("app")
    for section, keys in SCHEMA.items():
        table = doc.get(section)
        if section in APP_FORMATS and section != app:
            if table is not None:
                raise ConfigError(f"{prefix}[{section}] given for app {app!r}: "
                                  f"only [{app}] is allowed")
            continue
        if table is None:
            raise ConfigError(f"{prefix}missing section [{section}]")
        for name in table:
            if name not in keys:
                raise ConfigError(f"{prefix}{section}.{_name(name)}: unknown key; allowed keys "
                                  "are " + ", ".join(keys))
        values[section] = {}
        for name, key in keys.items():
            if name in table:
                values[section][name] = _check_key(f"{prefix}{section}.{name}", key,
                                                   table[name])
            elif key.default is None:
                raise ConfigError(f"{prefix}{section}.{name}: missing; must be {key.allowed}")
            else:
                values[section][name] = key.default
    return values


def _check_formats(values: dict[str, dict[str, Any]], app: str, prefix: str) -> dict[str, Format]:
    fmts = values["formats"]
    needed = {*APP_FORMATS[app], "weight", "noise"}
    for name in fmts:
        if name not in needed and fmts[name]:
            raise ConfigError(f"{prefix}formats.{name} = {fmts[name]!r}: not used by app "
                              f"{app!r}; its formats are " + ", ".join(sorted(needed)))
    for name in needed:
        if not fmts[name]:
            raise ConfigError(f"{prefix}formats.{name}: missing; app {app!r} needs it")
    out = {name: Format.parse(fmts[name]) for name in sorted(needed)}
    noise = out["noise"]
    lo, hi = NOISE_FRAC_BITS
    if not (noise.signed and noise.int_bits == 3 and lo <= noise.frac_bits <= hi):
        raise ConfigError(f"{prefix}formats.noise = {fmts['noise']!r}: must be s3.F with "
                          f"F in [{lo}, {hi}] (N(0, 1) draws to 7.9 sigma, one 18-bit "
                          "multiplier operand)")
    if out["weight"].signed or out["weight"].int_bits != 1:
        raise ConfigError(f"{prefix}formats.weight = {fmts['weight']!r}: must be unsigned "
                          "with one integer bit, u1.F (weights 2^-t lie in (0, 1])")
    first = APP_FORMATS[app][0]
    lo, hi = WORD_BITS
    for name in APP_FORMATS[app]:
        width = out[name].width
        if not out[name].signed:
            raise ConfigError(f"{prefix}formats.{name} = {fmts[name]!r}: must be signed "
                              "(sI.F)")
        if not lo <= width <= hi:
            raise ConfigError(f"{prefix}formats.{name} = {fmts[name]!r}: {width} bits; the "
                              f"datapath word must be {lo} to {hi} bits")
        if width != out[first].width:
            raise ConfigError(f"{prefix}formats.{name} = {fmts[name]!r}: {width} bits; must "
                              f"be as wide as formats.{first} = {fmts[first]!r} "
                              f"({out[first].width} bits, one datapath word)")
    if app == "uav" and out["quaternion"].int_bits < 1:
        raise ConfigError(f"{prefix}formats.quaternion = {fmts['quaternion']!r}: must have at "
                          "least one integer bit (a unit quaternion's |q_i| reaches 1)")
    return out


def config_from_dict(doc: dict[str, Any], name: str = "config", source: str = "") -> Config:
    """Validate a parsed TOML document; raise ConfigError on the first problem."""
    prefix = f"{_name(source)}: " if source else ""
    values = _read_sections(doc, prefix)
    flt = values["filter"]
    if flt["particles"] % flt["lanes"]:
        raise ConfigError(f"{prefix}filter.particles = {flt['particles']}: must be a multiple "
                          f"of filter.lanes = {flt['lanes']}")
    formats = _check_formats(values, flt["app"], prefix)
    g = values["grng"]
    cfg = Config(
        name=name,
        source=source,
        app=flt["app"],
        particles=flt["particles"],
        lanes=flt["lanes"],
        steps=flt["steps"],
        dt=float(flt["dt"]),
        formats=formats,
        ess_min=float(flt["ess_min"]),
        family=flt["family"],
        grng=GrngConfig(**g),
        app_params=values[flt["app"]],
    )
    # every value against what the formats hold and the models assume (gpf/limits.py)
    from gpf.limits import check_config

    check_config(cfg, prefix)
    return cfg


# The shipped configs, found from the package (an editable install, `make venv`), so a bare name
# works from any folder; a path is read relative to the folder gpf runs in.
CONFIGS_DIR = Path(__file__).resolve().parent.parent / "configs"


def shipped_configs() -> list[str]:
    return sorted(p.stem for p in CONFIGS_DIR.glob("*.toml"))


def config_path(name: str | Path) -> Path:
    """`bot` -> the shipped configs/bot.toml; a path (a `.toml` or with a folder) as it is, and
    a bare `bot.toml` that is no file here falls back to the shipped one of that name."""
    path = Path(name)
    if len(path.parts) == 1 and path.suffix != ".toml":
        shipped = CONFIGS_DIR / f"{path.name}.toml"
        if not shipped.is_file():
            raise ConfigError(f"{_name(str(name))}: no such config: the shipped ones are "
                              f"{', '.join(shipped_configs())}; or give a path to a .toml file")
        return shipped
    if len(path.parts) == 1 and not path.exists() and (CONFIGS_DIR / path.name).is_file():
        return CONFIGS_DIR / path.name
    return path


def regenerate_command(cfg: Config) -> str:
    """The command that writes this config's RTL again, from any folder."""
    source = Path(cfg.source) if cfg.source else None
    if source is None or source.resolve().parent == CONFIGS_DIR:
        arg = source.stem if source is not None else cfg.name
    else:
        arg = str(source)
    sets = "".join(f" --set {k}={_toml_value(v)}" for k, v in cfg.overrides.items())
    return f"gpf generate --config {arg}{sets}"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value if value.replace("_", "").isalnum() else repr(value)
    return str(value)


def load_config(path: str | Path, overrides: dict[str, Any] | None = None) -> Config:
    """Load and validate a TOML config. `overrides` maps 'section.key' to a value."""
    path = Path(path)
    where = _name(str(path))
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{where}: cannot read config: {exc.strerror}") from None
    except ValueError:   # a NUL byte in the path (from Python; a shell cannot pass one)
        raise ConfigError(f"{where}: cannot read config: not a valid path") from None
    try:
        text = data.decode()
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{where}: not a UTF-8 text file (byte 0x{data[exc.start]:02x} at "
                          f"offset {exc.start}): a config is TOML text") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: not valid TOML: {exc}") from None
    overrides = overrides or {}
    for dotted, value in overrides.items():
        section, _, key = dotted.partition(".")
        table = doc.setdefault(section, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {_name(section)} = {_show(table)}: expected a "
                              f"[{_name(section)}] table")
        table[key] = value
    # each override set builds in its own folder: build/bot-lanes2/...
    name = path.stem + "".join(f"-{k.rpartition('.')[2]}{v}" for k, v in overrides.items())
    cfg = config_from_dict(doc, name=_safe_name(name), source=str(path))
    return replace(cfg, overrides=dict(overrides))


def for_family(cfg: Config, family: str) -> Config:
    """The same config with its multipliers shaped for another FPGA family (its own build
    folder, e.g. build/bot-familyecp5): how `gpf synth` (xc7) and `gpf timing` (ecp5) measure
    a config written for the other one, unless the user set the family."""
    if cfg.family == family or "filter.family" in cfg.overrides:
        return cfg
    return replace(cfg, family=family, name=_safe_name(f"{cfg.name}-family{family}"),
                   overrides={**cfg.overrides, "filter.family": family})


def _safe_name(name: str) -> str:
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    if len(safe) > 100:  # a folder name: long override values would pass the 255-byte limit
        import hashlib

        safe = safe[:80] + "-" + hashlib.sha1(safe.encode()).hexdigest()[:12]
    return safe


def limits_table() -> str:
    """The README's "Inputs and their limits": every validated range, from the code that checks
    them (gpf/limits.py); `gpf limits` and `python -m gpf.config` print it."""
    from gpf.limits import limits_table as table

    return table()


if __name__ == "__main__":
    print(limits_table(), end="")
