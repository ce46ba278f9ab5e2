"""One validation layer (gpf/limits.py): every command refuses the same inputs, in one line
naming the key (or the CSV cell), the value and the allowed range -- before any work.

Nothing here simulates: the commands' work (generate, the models, the simulations, lint,
synthesis, place and route, waves) is replaced by a stub that raises StartedError.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_fuzz_cli import _started, run_cli
from test_fuzz_cli import assert_refused as refused

from gpf import cli
from gpf.config import ConfigError, limits_table, load_config
from gpf.limits import RULES, accepted_range, check_config, datapath_problems
from gpf.model import blocks
from gpf.model.blocks import MODEL_SUM_BITS
from gpf.model.formats import datapath
from gpf.model.scenarios import TRUTH, bot_fixed_observer, read_csv, uav_flight, write_csv
from gpf.study.montecarlo import SCENARIOS

CONFIGS = ("bot", "odd", "uav", "uav_seed002")


@pytest.fixture
def stubbed(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import gpf.model.grng
    import gpf.rtl.generate
    import gpf.rtl.lint
    import gpf.rtl.waves
    import gpf.run
    import gpf.sim
    import gpf.study.montecarlo
    import gpf.synth
    import gpf.timing

    for module, name in ((gpf.sim, "run_sim"), (gpf.run, "run_filter"),
                         (gpf.study.montecarlo, "monte_carlo"), (gpf.rtl.generate, "generate"),
                         (gpf.rtl.lint, "lint_configs"), (gpf.synth, "synthesize"),
                         (gpf.timing, "place_and_route"), (gpf.rtl.waves, "open_waves")):
        monkeypatch.setattr(module, name, _started)
    monkeypatch.setattr(gpf.model.grng.GrngModel, "normals", _started)
    for name in ("check_simulator", "_check_gate_tools"):
        monkeypatch.setattr(cli, name, lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")



def write_config(tmp_path: Path, app: str = "bot", **changes: Any) -> Path:
    """The shipped config of `app` with section.key = value changes (key 'section__key')."""
    text = Path(f"configs/{app}.toml").read_text()
    for dotted, value in changes.items():
        _, key = dotted.split("__")
        toml = repr(value).replace("'", '"') if not isinstance(value, list) else \
            "[" + ", ".join(repr(v) for v in value) + "]"
        text, n = re.subn(rf"(?m)^{key} = .*$", f"{key} = {toml}", text)
        assert n == 1, dotted
    path = tmp_path / f"my{app}.toml"
    path.write_text(text)
    return path


def every_command(config: Path, tmp_path: Path, app: str = "bot") -> list[list[str]]:
    c = str(config)
    return [
        ["generate", "--config", c, "--out", str(tmp_path / "rtl")],
        ["model", "run", "--config", c, "--particles", "64", "--json", str(tmp_path / "m.json")],
        ["model", "grng", "--config", c, "--samples", "10", "--out", str(tmp_path / "z.npy")],
        ["model", "wordlength", "--config", c, "--runs", "1", "--words", "18:18"],
        ["run", "--config", c, "--particles", "64", "--json", str(tmp_path / "r.json")],
        ["sim", "--config", c],
        ["lint", "--config", c],
        ["synth", "--config", c],
        ["timing", "--config", c],
        ["waves", "--config", c, "--no-launch"],
    ]


# ---- the config: the same refusal from every command ------------------------------------------
def test_x0_outside_its_format_refused_by_every_command(
        stubbed: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """bot.x0 = 1000 m in s7.10 (|x| < 128): `model run` once printed fixed 872 m against float
    0.28 m and `gpf run` PASSED on an equally saturated model."""
    config = write_config(tmp_path, bot__x0=[1000.0, 0.3, 3.0, 0.3])
    lines = set()
    for argv in every_command(config, tmp_path):
        status, err = run_cli(argv, capsys)
        lines.add(refused(status, err, f"{config}: bot.x0 = [1000.0, 0.3, 3.0, 0.3]: ",
                          "x0[0] = 1000 must lie in [-126.9, 126.9] m", "formats.state = 's7.10'"))
    assert len(lines) == 1, lines          # word for word the same from every command
    assert not (tmp_path / "rtl").exists() and not (tmp_path / "build").exists()


@pytest.mark.parametrize("app,override,words", [
    ("bot", "bot.process_var=1e30", ["bot.process_var = 1e+30: must lie in [2.385e-07, 256]"]),
    ("bot", "bot.process_var=1e300", ["bot.process_var = 1e+300: must lie in"]),
    ("bot", "filter.dt=1e6", ["filter.dt = 1000000.0: must lie in"]),
    ("bot", "bot.sigma0_diag=[1e6, 1e6, 1e6, 1e6]", ["sigma0_diag[1] = 1e+06 must lie in"]),
    ("bot", "bot.bearing_var=1e-12", ["bot.bearing_var = 1e-12: must lie in"]),
    ("uav", "uav.sigma_a=1e30", ["uav.sigma_a = 1e+30: must lie in [6.104e-05, 8] m/s^2"]),
    ("uav", "uav.sigma_v=1e-12", ["uav.sigma_v = 1e-12: must lie in"]),
    ("uav", "filter.dt=1.0", ["filter.dt = 1.0: must lie in [6.104e-05, 0.125] s"]),
])
def test_absurd_values_refused_alike(stubbed: None, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str], app: str,
                                     override: str, words: list[str]) -> None:
    """Finite but absurd: refused by `generate` and `model run` (and with them every command)
    in the same line; the bearing variance no longer by `generate` alone."""
    lines = set()
    for argv in (["generate", "--config", app, "--out", str(tmp_path / "rtl")],
                 ["model", "run", "--config", app, "--json", str(tmp_path / "m.json")],
                 ["run", "--config", app, "--json", str(tmp_path / "r.json")]):
        status, err = run_cli([*argv, "--set", override], capsys)
        lines.add(refused(status, err, f"configs/{app}.toml: ", *words))
    assert len(lines) == 1, lines


def test_no_silently_rescaled_constant() -> None:
    """A derived constant that one 18-bit word cannot hold is refused, naming the key that
    fixes it and the range in which it does (here the 30-bit state's model sums)."""
    with pytest.raises(ConfigError) as err:
        load_config("configs/bot.toml", {"formats.state": "s7.22", "formats.noise": "s3.14",
                                         "bot.process_var": 1e-12})
    message = str(err.value)
    assert "\n" not in message
    assert "bot.process_var = 1e-12: propagate_bot's position sum needs 63-bit" in message
    assert f"the model's sums hold {MODEL_SUM_BITS}" in message and "must lie in [" in message


def test_uav_word_too_wide_for_the_model(capsys: pytest.CaptureFixture[str],
                                         stubbed: None) -> None:
    """--word 30 on uav once ended in 'raw value of a signed 62-bit input ... is outside'."""
    status, err = run_cli(["model", "run", "--config", "uav", "--word", "30", "--json",
                           "m.json"], capsys)
    refused(status, err, "--word 30: uav: propagate_uav's quaternion update needs 66-bit")
    status, err = run_cli(["model", "run", "--config", "uav", "--word", "28", "--json",
                           "m.json"], capsys)
    assert status is None, err


def test_lint_refuses_what_every_command_refuses(stubbed: None, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """`gpf lint` overrode the config's lanes with 1, 2, 4 and called a 64-lane config clean."""
    config = write_config(tmp_path, filter__lanes=64)
    for argv in (["lint", "--config", str(config)], ["generate", "--config", str(config)],
                 ["model", "run", "--config", str(config), "--json", "m.json"]):
        status, err = run_cli(argv, capsys)
        refused(status, err, "filter.lanes = 64: must be one of 1, 2, 4")
    status, err = run_cli(["lint", "--config", "odd"], capsys)
    assert status is None, err


def test_particles_one_rule(stubbed: None, tmp_path: Path,
                           capsys: pytest.CaptureFixture[str]) -> None:
    """`gpf run`, `gpf model run` and `gpf model wordlength` take the same N: a multiple of
    LANES in [2, filter.particles] (once 1 was a run's and 65536 a model's)."""
    json = ["--json", str(tmp_path / "x.json")]
    for n in ("1", "1021", "2048"):
        lines = set()
        for argv in (["run", "--config", "odd", *json], ["model", "run", "--config", "odd", *json],
                     ["model", "wordlength", "--config", "odd", "--words", "20:20"]):
            status, err = run_cli([*argv, "--particles", n], capsys)
            lines.add(refused(status, err, f"--particles {n}: must be a multiple of "
                              "filter.lanes = 2 in [2, 1020]"))
        assert len(lines) == 1
    for argv in (["run", "--config", "odd", *json], ["model", "run", "--config", "odd", *json]):
        status, err = run_cli([*argv, "--particles", "1020"], capsys)
        assert status is None, err


# ---- recordings --------------------------------------------------------------------------------
def _recording(tmp_path: Path, app: str, change: Any = None) -> Path:
    cfg = load_config(f"configs/{app}.toml")
    sc = (bot_fixed_observer if app == "bot" else uav_flight)(cfg, 5, 1)
    if change:
        change(sc)
    path = tmp_path / f"{app}.csv"
    write_csv(sc, path)
    return path


def test_csv_cell_of_1e300_refused_naming_row_and_column(
        stubbed: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Once an OverflowError traceback (model run) or a RuntimeError (gpf run)."""
    def big(sc: Any) -> None:
        sc.measurements["z"][2] = 1e300

    csv = _recording(tmp_path, "bot", big)
    line = 4 + 1 + 1 + 2     # 4 metadata lines, the header, rows 0 and 1
    lines = set()
    for argv in (["model", "run", "--json", str(tmp_path / "m.json")],
                 ["run", "--json", str(tmp_path / "r.json")]):
        status, err = run_cli([*argv, "--config", "bot", "--scenario", str(csv)], capsys)
        lines.add(refused(status, err, f"row 2 (line {line}), column 'z': 1e+300 is outside "
                          "[-6.28319, 6.28319]"))
    assert len(lines) == 1
    cfg = load_config("configs/bot.toml")
    with pytest.raises(ConfigError, match=r"row 2 \(line 8\), column 'z'"):
        read_csv(csv, cfg)
    read_csv(csv)      # without a config: only its own form is checked

    def far(sc: Any) -> None:
        sc.inputs["observer"][3, 1] = 500.0   # beyond s7.10

    status, err = run_cli(["model", "run", "--config", "bot", "--scenario",
                           str(_recording(tmp_path, "bot", far)), "--json", "m.json"], capsys)
    refused(status, err, "row 3 (line 9), column 'oy': 500.0 is outside [-128, 127.999], "
            "formats.state = 's7.10'")


def test_scenario_of_the_other_app_refused_in_one_line(
        stubbed: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Once KeyError: 'x0' (uav_flight on bot) and numpy's 'operands could not be broadcast'
    (the reverse)."""
    json = ["--json", str(tmp_path / "x.json")]
    for config, scenario, csv_app in (("bot", "uav_flight", "uav"),
                                      ("uav", "bot_fixed_observer", "bot")):
        for command in (["model", "run"], ["run"]):
            status, err = run_cli([*command, "--config", config, "--scenario", scenario, *json],
                                  capsys)
            refused(status, err, scenario)
            csv = str(_recording(tmp_path, csv_app))
            status, err = run_cli([*command, "--config", config, "--scenario", csv, *json],
                                  capsys)
            refused(status, err, f"a {csv_app} recording (its columns), config {config!r} is "
                    f"{config}")
        cfg = load_config(f"configs/{config}.toml")
        with pytest.raises(ConfigError) as err:
            SCENARIOS[scenario](cfg, 3, 1)
        assert str(err.value) == (f"scenario {scenario} is for app {csv_app!r}; config "
                                  f"{config!r} is {config!r}")


def test_uav_quaternion_of_unit_norm(stubbed: None, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    """The initial estimate's quaternion (mu0's q0..q3) and every truth quaternion: norm 1
    within 1e-3."""
    def scaled(sc: Any) -> None:
        sc.mu0[:4] *= 1.01

    status, err = run_cli(["model", "run", "--config", "uav", "--scenario",
                           str(_recording(tmp_path, "uav", scaled)), "--json", "m.json"], capsys)
    refused(status, err, "metadata mu0[0:4] = [", "has norm 1.01; a quaternion must have norm 1 "
            "within 0.001")

    def truth(sc: Any) -> None:
        sc.truth[4, :4] = [1.0, 0.1, 0.0, 0.0]

    status, err = run_cli(["run", "--config", "uav", "--scenario",
                           str(_recording(tmp_path, "uav", truth)), "--json", "r.json"], capsys)
    refused(status, err, "row 4 (line 10), columns q0..q3: [1, 0.1, 0, 0] has norm 1.00499")

    def no_mu0(sc: Any) -> None:   # the truth at k = 0 is then the initial estimate
        sc.mu0 = None
        sc.truth[0, :4] = [0.0, 0.0, 0.0, 0.5]

    status, err = run_cli(["model", "run", "--config", "uav", "--scenario",
                           str(_recording(tmp_path, "uav", no_mu0)), "--json", "m.json"], capsys)
    refused(status, err, "row 0 (line 5), columns q0..q3: [0, 0, 0, 0.5] has norm 0.5")
    assert TRUTH["uav"][:4] == ("q0", "q1", "q2", "q3")


def test_recording_at_another_step_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"metadata dt = 1.0, config filter.dt = 0.5"):
        read_csv(_recording(tmp_path, "bot"),
                 load_config("configs/bot.toml", {"filter.dt": 0.5}))


# ---- the limits themselves ---------------------------------------------------------------------
@pytest.mark.parametrize("name", CONFIGS)
def test_shipped_configs_within_their_limits(name: str) -> None:
    check_config(load_config(f"configs/{name}.toml"))


def _exact_propagate_bot(dp: Any, x: np.ndarray, e: np.ndarray) -> np.ndarray:
    """blocks.propagate_bot in Python integers (exact at any width)."""
    c, fx, fe = dp.consts, dp.x[0].frac_bits, dp.noise.frac_bits
    out = []
    for row, draw in zip(x.tolist(), e.tolist(), strict=True):
        new = []
        for axis in range(2):
            p, v, d = row[2 * axis], row[2 * axis + 1], draw[axis]
            for terms in ([(p, fx), (v * c["T"].raw, fx + c["T"].frac),
                           (d * c["a"].raw, fe + c["a"].frac)],
                          [(v, fx), (d * c["b"].raw, fe + c["b"].frac)]):
                top = max(f for _, f in terms)
                total = sum(r << (top - f) for r, f in terms)
                shift = top - fx
                value = (total + ((1 << shift) >> 1)) >> shift
                new.append(min(max(value, dp.x[0].min_raw), dp.x[0].max_raw))
        out.append([new[0], new[1], new[2], new[3]])
    return np.array(out, dtype=object)


@pytest.mark.parametrize("name", ["bot", "odd"])
@pytest.mark.parametrize("key", ["bot.process_var", "filter.dt"])
def test_accepted_edges_keep_the_model_exact(name: str, key: str) -> None:
    """At both ends of what the check accepts (also with the widest words) the model's int64
    propagation equals exact integer arithmetic for operands anywhere in their formats, and
    the generator builds every block."""
    for overrides in ({}, {"formats.state": "s7.22", "formats.noise": "s3.14"}):
        cfg = load_config(f"configs/{name}.toml", overrides)
        for value in accepted_range(cfg, key):
            edge = load_config(f"configs/{name}.toml", {**overrides, key: value})
            dp = datapath(edge)
            x_fmt, n_fmt = dp.x[0], dp.noise
            corners = [x_fmt.min_raw, -1, 0, x_fmt.max_raw]
            x = np.array([[p, v, p, v] for p in corners for v in corners], dtype=np.int64)
            e = np.array([[n_fmt.max_raw if k % 2 else n_fmt.min_raw] * 2
                          for k in range(len(x))], dtype=np.int64)
            got, _ = blocks.propagate_bot(dp, x, e)
            assert (got.astype(object) == _exact_propagate_bot(dp, x, e)).all(), (key, value)
            cli._check_generates(edge)


@pytest.mark.parametrize("name", ["uav", "uav_seed002"])
def test_uav_accepted_edges_run(name: str) -> None:
    """uav at the accepted ends of its noise keys and dt: the generator builds every block and
    three model steps run (a sum past 62 bits would raise)."""
    from gpf.model.fixed_gpf import FixedGPF, run

    cfg = load_config(f"configs/{name}.toml")
    for key in ("filter.dt", "uav.sigma_omega_deg", "uav.sigma_a", "uav.sigma_v"):
        for value in accepted_range(cfg, key):
            edge = load_config(f"configs/{name}.toml", {key: value})
            cli._check_generates(edge)
            gpf = FixedGPF(edge, particles=16)
            run(gpf, uav_flight(edge, 3, 1))


def test_every_rule_has_a_range_for_the_shipped_configs() -> None:
    for rule in RULES:
        for name in CONFIGS:
            cfg = load_config(f"configs/{name}.toml")
            if cfg.app == rule.app:
                for i in rule.order or (None,):
                    lo, hi = accepted_range(cfg, rule.key, i)
                    value = cfg.dt if i is None and rule.key == "filter.dt" else (
                        cfg.app_params[rule.key.split(".")[1]] if i is None else
                        cfg.app_params[rule.key.split(".")[1]][i])
                    assert lo <= value <= hi, (rule.key, i, lo, value, hi)


def test_quaternion_format_needs_an_integer_bit() -> None:
    with pytest.raises(ConfigError, match=r"formats.quaternion = 's0.19': must have at least "
                                          "one integer bit"):
        load_config("configs/uav.toml", {"formats.quaternion": "s0.19"})


def test_readme_section_is_the_generated_table() -> None:
    """README.md's "Inputs and their limits" is limits_table()'s output, word for word
    (regenerate: `gpf limits`)."""
    readme = Path("README.md").read_text()
    start = readme.index("## Inputs and their limits\n")
    end = readme.index("\n## ", start + 1) + 1
    assert readme[start:end] == limits_table() + "\n"


def test_gpf_limits_prints_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["limits"]) == 0
    assert capsys.readouterr().out == limits_table()


def log2_uniform(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi).map(lambda e: 2.0**e)


# each key from a little below to a little beyond what any word accepts
RANGES = {"bot": {"filter.dt": (-8, 6), "bot.process_var": (-40, 9),
                  "bot.bearing_var": (-32, 1)},
          "uav": {"filter.dt": (-14, -3), "uav.sigma_omega_deg": (-16, 5),
                  "uav.sigma_a": (-20, 4), "uav.sigma_v": (-16, 4)}}


@st.composite
def wide_configs(draw: st.DrawFn) -> tuple[str, dict[str, Any]]:
    app = draw(st.sampled_from(["bot", "uav"]))
    word = draw(st.integers(8, 30))
    if app == "bot":
        overrides: dict[str, Any] = {"formats.state": f"s7.{word - 8}"}
    else:
        overrides = {"formats.quaternion": f"s1.{word - 2}", "formats.velocity": f"s6.{word - 7}"}
    overrides["formats.noise"] = f"s3.{draw(st.integers(4, 14))}"
    for key, (lo, hi) in RANGES[app].items():
        overrides[key] = draw(log2_uniform(lo, hi))
    return app, overrides


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(case=wide_configs())
def test_a_config_that_loads_builds(case: tuple[str, dict[str, Any]]) -> None:
    """Whatever the words, the step and the noises: a config that loads has its constants
    within their words and generates (what every command checks is what the generator needs)."""
    app, overrides = case
    try:
        cfg = load_config(f"configs/{app}.toml", overrides)
    except ConfigError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(f"configs/{app}.toml: ")
        return
    assert not datapath_problems(datapath(cfg))
    cli._check_generates(cfg)
