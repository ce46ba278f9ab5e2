"""Property tests of bad input: random TOML, mutated configs, --set overrides and argument
values. Each must end in a Config (or a started command) or in ONE line on stderr and exit
status 2 -- never a traceback, never a half-written output folder.

Nothing here simulates: run_sim, run_filter, monte_carlo, the GRNG model and generate() are
replaced by a stub that raises StartedError, so a property only sees what happens before the work.
"""

from __future__ import annotations

import json
import math
import shutil
import tomllib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpf import cli
from gpf.config import SCHEMA, ConfigError, config_from_dict, load_config

FAST = settings(max_examples=60, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])
SHIPPED = {app: tomllib.loads(Path(f"configs/{app}.toml").read_text()) for app in ("bot", "uav")}


class StartedError(BaseException):
    """The command got past its checks and would now do its work."""


def _started(*args: Any, **kwargs: Any) -> None:
    raise StartedError


@pytest.fixture
def stubbed(monkeypatch: pytest.MonkeyPatch) -> None:
    import gpf.model.grng
    import gpf.rtl.generate
    import gpf.run
    import gpf.sim
    import gpf.study.montecarlo

    for module, name in ((gpf.sim, "run_sim"), (gpf.run, "run_filter"),
                         (gpf.study.montecarlo, "monte_carlo"), (gpf.rtl.generate, "generate")):
        monkeypatch.setattr(module, name, _started)
    monkeypatch.setattr(gpf.model.grng.GrngModel, "normals", _started)


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int | None, str]:
    """(exit status, stderr); status None when the command started its work."""
    capsys.readouterr()
    try:
        status = cli.main(argv)
    except StartedError:
        status = None
    return status, capsys.readouterr().err


def assert_one_line(status: int | None, err: str, *words: str) -> str:
    """Exit 2 and one line from gpf holding every word; returns the line."""
    assert status == 2, (status, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("gpf"), err
    for word in words:
        assert word in lines[0], (word, err)
    return lines[0]


def assert_refused(status: int | None, err: str, *words: str) -> str:
    """As assert_one_line, the line a user error's: `gpf: error: ...`."""
    line = assert_one_line(status, err, *words)
    assert line.startswith("gpf: error: "), err
    return line


# ---- a TOML writer for generated documents (tomllib only reads) ----

def toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else
                                            "-inf" if v == -math.inf else repr(v))
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + "}"


def toml_doc(doc: dict[str, Any]) -> str:
    lines = [f"{json.dumps(k)} = {toml_value(v)}" for k, v in doc.items()
             if not isinstance(v, dict)]
    for section, table in doc.items():
        if isinstance(table, dict):
            lines.append(f"[{json.dumps(section)}]")
            lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def fmt_text() -> st.SearchStrategy[str]:
    """Fixed-point format strings: mostly well-formed (in range or not), some garbage."""
    good = st.builds(lambda s, i, f: f"{s}{i}.{f}", st.sampled_from("su"),
                     st.integers(0, 40), st.integers(0, 40))
    return st.one_of(good, good, st.text(max_size=8), st.just(""), st.just("s3"))


SCALARS = st.one_of(
    st.integers(-3, 70), st.integers(), st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
    st.sampled_from(["bot", "uav", "full", "block", "sir", ""]), fmt_text(), st.text(max_size=12))
VALUES = st.one_of(SCALARS, st.lists(SCALARS, max_size=8),
                   st.dictionaries(st.text(max_size=5), SCALARS, max_size=2))
KEYS = st.one_of(st.sampled_from(sorted({k for keys in SCHEMA.values() for k in keys})),
                 st.text(max_size=10))
SECTIONS = st.one_of(st.sampled_from([*SCHEMA, "extra"]), st.text(max_size=8))


@st.composite
def mutated_doc(draw: st.DrawFn) -> dict[str, Any]:
    """A shipped config with 1 to 4 things changed: a value, a key dropped or added, a section
    dropped, added or replaced by a scalar."""
    doc = json.loads(json.dumps(SHIPPED[draw(st.sampled_from(["bot", "uav"]))]))
    for _ in range(draw(st.integers(1, 4))):
        what = draw(st.sampled_from(["set", "set", "set", "drop_key", "add_key",
                                     "drop_section", "add_section", "scalar_section"]))
        section = draw(st.sampled_from(sorted(doc)) if doc and what != "add_section"
                       else SECTIONS)
        if what == "set" and isinstance(doc.get(section), dict):
            key = draw(st.sampled_from(sorted(SCHEMA.get(section, {"x": 0}))))
            doc[section][key] = draw(VALUES)
        elif what == "drop_key" and isinstance(doc.get(section), dict) and doc[section]:
            del doc[section][draw(st.sampled_from(sorted(doc[section])))]
        elif what == "add_key" and isinstance(doc.get(section), dict):
            doc[section][draw(KEYS)] = draw(VALUES)
        elif what == "drop_section":
            doc.pop(section, None)
        elif what == "add_section":
            doc[section] = draw(st.dictionaries(KEYS, VALUES, max_size=3))
        elif what == "scalar_section":
            doc[section] = draw(SCALARS)
    return doc


def check_load(path: Path) -> None:
    """load_config gives a Config or one ConfigError line; a Config the generator cannot
    build is one ConfigError line too (what `gpf generate/sim/run/lint` check first)."""
    try:
        cfg = load_config(path)
    except ConfigError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(str(path)), str(exc)
        return
    assert cfg.particles % cfg.lanes == 0
    try:
        cli._check_generates(cfg)
    except ConfigError as exc:
        assert "\n" not in str(exc) and "cannot be generated" in str(exc)


@FAST
@given(data=st.binary(max_size=200))
def test_random_bytes_as_a_config(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "random.toml"
    path.write_bytes(data)
    with pytest.raises(ConfigError):
        load_config(path)
    check_load(path)


@FAST
@given(text=st.text(alphabet=st.sampled_from(list("[]=\"'.,{}#\n \tabcfilterbotuav0123-+e")),
                    max_size=120))
def test_random_toml_like_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "text.toml"
    path.write_text(text)
    check_load(path)


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(doc=mutated_doc())
def test_mutated_configs(tmp_path: Path, doc: dict[str, Any]) -> None:
    path = tmp_path / "mutated.toml"
    path.write_text(toml_doc(doc))
    check_load(path)
    # the same document handed over from Python: one line, the key named, never another error
    try:
        parsed = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError:
        return   # the writer above cannot spell every generated key (load_config said so)
    try:
        config_from_dict(parsed, source="x.toml")
    except ConfigError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("x.toml: ")


@FAST
@given(doc=mutated_doc())
def test_generate_with_a_mutated_config(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        doc: dict[str, Any]) -> None:
    """The real generate: exit 0 with files, or one line, exit 2 and no output folder."""
    path, out = tmp_path / "mutated.toml", tmp_path / "out"
    path.write_text(toml_doc(doc))
    status, err = run_cli(["generate", "--config", str(path), "--out", str(out)], capsys)
    if status == 0:
        assert (out / "manifest.json").exists()
        shutil.rmtree(out)   # the next example's folder must not exist
    else:
        assert_one_line(status, err, "gpf: error: ")
        assert not out.exists()


OVERRIDE_KEYS = st.one_of(
    st.sampled_from([f"{s}.{k}" for s, keys in SCHEMA.items() for k in keys]),
    st.text(max_size=12))


@FAST
@given(key=OVERRIDE_KEYS, value=st.one_of(st.text(max_size=12), SCALARS.map(toml_value)),
       config=st.sampled_from(["bot", "uav", "odd"]))
def test_set_overrides(stubbed: None, capsys: pytest.CaptureFixture[str], tmp_path: Path,
                       key: str, value: str, config: str) -> None:
    status, err = run_cli(["generate", "--config", config, "--set", f"{key}={value}",
                           "--out", str(tmp_path / "out")], capsys)
    if status is not None:
        assert_one_line(status, err, "gpf: error: ")
    assert not (tmp_path / "out").exists()


NUMBER = st.one_of(st.integers(-5, 5), st.integers(-(2**70), 2**70), st.integers(0, 200_000))
ARG = st.one_of(NUMBER.map(str), st.text(max_size=6), st.just(""), st.just("1e3"))


def expect(status: int | None, err: str, ok: bool) -> None:
    if ok:
        assert status is None, (status, err)
    else:
        assert_one_line(status, err)


def as_int(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


@FAST
@given(steps=ARG, particles=ARG, seed=ARG, sim=st.sampled_from(["verilator", "icarus"]))
def test_run_numbers(stubbed: None, capsys: pytest.CaptureFixture[str], tmp_path: Path,
                     monkeypatch: pytest.MonkeyPatch, steps: str, particles: str, seed: str,
                     sim: str) -> None:
    """`gpf run`: steps in [1, 100000], particles a multiple of LANES up to the config's,
    seed in [0, 2^32); checked before the toolchain (stubbed here) and the simulation."""
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")
    status, err = run_cli(["run", "--config", "odd", "--steps", steps, "--particles",
                           particles, "--seed", seed, "--sim", sim,
                           "--json", str(tmp_path / "r.json")], capsys)
    s, p, n = as_int(steps), as_int(particles), as_int(seed)
    ok = (s is not None and 1 <= s <= 100_000 and p is not None and 1 <= p <= 1020
          and p % 2 == 0 and n is not None and 0 <= n < 2**32)
    expect(status, err, ok)


@FAST
@given(seed=ARG, module=st.one_of(st.sampled_from(["grng", "exp", "gpf_bot", "weight_uav"]),
                                  st.text(max_size=8)))
def test_sim_seed_and_module(stubbed: None, capsys: pytest.CaptureFixture[str],
                             tmp_path: Path, monkeypatch: pytest.MonkeyPatch, seed: str,
                             module: str) -> None:
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")
    status, err = run_cli(["sim", "--config", "bot", "--module", module, "--seed", seed],
                          capsys)
    n = as_int(seed)
    ok = n is not None and 0 <= n < 2**32 and module in ("grng", "exp", "gpf_bot")
    expect(status, err, ok)


SCENARIOS = st.one_of(st.sampled_from(["bot_fixed_observer", "bot_manoeuvring_observer",
                                       "uav_flight", "nosuch", "nosuch.csv"]),
                      st.text(max_size=10))


@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(scenario=SCENARIOS, config=st.sampled_from(["bot", "uav"]))
def test_run_scenario(stubbed: None, capsys: pytest.CaptureFixture[str], tmp_path: Path,
                      monkeypatch: pytest.MonkeyPatch, scenario: str, config: str) -> None:
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")
    status, err = run_cli(["run", "--config", config, "--scenario", scenario,
                           "--json", str(tmp_path / "r.json")], capsys)
    ok = scenario.startswith(config) and scenario in ("bot_fixed_observer",
                                                      "bot_manoeuvring_observer", "uav_flight")
    expect(status, err, ok)


@FAST
@given(steps=ARG, particles=ARG, seed=ARG, runs=ARG, word=ARG)
def test_model_run_numbers(stubbed: None, capsys: pytest.CaptureFixture[str], tmp_path: Path,
                           steps: str, particles: str, seed: str, runs: str,
                           word: str) -> None:
    status, err = run_cli(["model", "run", "--config", "odd", "--steps", steps, "--particles",
                           particles, "--seed", seed, "--runs", runs, "--word", word,
                           "--json", str(tmp_path / "r.json")], capsys)
    s, p, n, r, w = map(as_int, (steps, particles, seed, runs, word))
    # N as gpf run's: a multiple of LANES up to the config's filter.particles (1020)
    ok = (s is not None and 1 <= s <= 100_000 and p is not None and 2 <= p <= 1020
          and p % 2 == 0 and n is not None and 0 <= n < 2**32 and r is not None and r >= 1
          and w is not None and 8 <= w <= 30)
    expect(status, err, ok)
    assert not (tmp_path / "r.json").exists()


@FAST
@given(samples=ARG, seed=ARG)
def test_model_grng_numbers(stubbed: None, capsys: pytest.CaptureFixture[str], tmp_path: Path,
                            samples: str, seed: str) -> None:
    status, err = run_cli(["model", "grng", "--samples", samples, "--seed", seed,
                           "--out", str(tmp_path / "z.npy")], capsys)
    m, n = as_int(samples), as_int(seed)
    ok = m is not None and 1 <= m <= 10**8 and n is not None and 0 <= n < 2**64
    expect(status, err, ok)


@FAST
@given(words=st.one_of(st.builds(lambda a, b, c: f"{a}:{b}:{c}", NUMBER, NUMBER, NUMBER),
                       st.builds(lambda a, b: f"{a}:{b}", NUMBER, NUMBER), st.text(max_size=8)),
       particles=ARG)
def test_wordlength_arguments(stubbed: None, capsys: pytest.CaptureFixture[str], words: str,
                              particles: str) -> None:
    status, err = run_cli(["model", "wordlength", "--config", "odd", "--words", words,
                           "--particles", particles], capsys)
    if status is not None:
        assert_one_line(status, err)


@FAST
@given(name=st.text(max_size=20))
def test_any_config_name(stubbed: None, capsys: pytest.CaptureFixture[str], tmp_path: Path,
                         name: str) -> None:
    status, err = run_cli(["generate", "--config", name, "--out", str(tmp_path / "o")], capsys)
    if status is not None:
        assert_one_line(status, err, "gpf: error: ")


def test_config_paths_that_are_not_files(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty.toml").write_text("")
    (tmp_path / "latin1.toml").write_bytes("[filter]\napp = 'b\xf6t'\n".encode("latin-1"))
    (tmp_path / "top.toml").write_text("app = 'bot'\n")
    for config, words in ((str(tmp_path), "cannot read config: Is a directory"),
                          (str(tmp_path / "nosuch.toml"), "No such file"),
                          ("nosuch", "nosuch: no such config: the shipped ones are bot,"),
                          (str(tmp_path / "empty.toml"), "missing section [filter]"),
                          (str(tmp_path / "latin1.toml"), "not a UTF-8 text file (byte 0xf6"),
                          (str(tmp_path / "top.toml"), "app = 'bot': a key outside any "
                           "section")):
        out = tmp_path / "out"
        status, err = run_cli(["generate", "--config", config, "--out", str(out)], capsys)
        assert_one_line(status, err, words)
        assert not out.exists()


@pytest.mark.parametrize("override,words", [
    ("bot.x0=[1" + "0" * 400 + ", 1, 1, 1]", ["bot.x0 = [1000", "list of 4 numbers"]),
    ("filter.dt=1" + "0" * 400, ["filter.dt = 1000", "...", "a number > 0"]),
    ("formats.weight=u0.17", ["formats.weight = 'u0.17'", "u1.F"]),
    ("formats.state=s3.3", ["formats.state = 's3.3'", "7 bits", "8 to 30 bits"]),
    ("formats.state=s20.20", ["'s20.20': 41 bits", "8 to 30 bits"]),
    ("formats.state=u7.10", ["formats.state = 'u7.10'", "signed"]),
    # below half an LSB of the state a step: refused by every command (gpf/limits.py), where
    # it once built a model whose sums overflowed int64
    ("bot.process_var=1e-30", ["bot.process_var = 1e-30", "must lie in"]),
    ("bot.process_var=1e-5", []),       # valid and buildable: the stub starts
])
def test_values_the_generator_cannot_build(stubbed: None, capsys: pytest.CaptureFixture[str],
                                           override: str, words: list[str]) -> None:
    status, err = run_cli(["generate", "--config", "bot", "--set", override], capsys)
    if words:
        assert_one_line(status, err, *words)
    else:
        assert status is None


def test_uav_formats_must_share_one_word(capsys: pytest.CaptureFixture[str]) -> None:
    quaternion = load_config("configs/uav.toml").formats["quaternion"]
    status, err = run_cli(["generate", "--config", "uav", "--set", "formats.velocity=s6.17"],
                          capsys)
    assert_one_line(status, err, "formats.velocity = 's6.17': 24 bits; must be as wide as "
                    f"formats.quaternion = '{quaternion}' ({quaternion.width} bits")
    status, err = run_cli(["generate", "--config", "uav", "--set", "uav.sigma_v=1e-12"], capsys)
    # refused when the config loads (every command alike), no longer by the generator alone
    assert_one_line(status, err, "configs/uav.toml: uav.sigma_v = 1e-12: must lie in")


def test_failed_generate_leaves_the_folder_unchanged(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rtl"
    out.mkdir()
    (out / "keep.sv").write_text("module keep; endmodule\n")
    for override in ("filter.lanes=3", "uav.sigma_v=1e-12", "formats.state=s40.1"):
        status, err = run_cli(["generate", "--config", "uav" if "uav" in override else "bot",
                               "--set", override, "--out", str(out)], capsys)
        assert_one_line(status, err)
        assert [p.name for p in out.iterdir()] == ["keep.sv"]


def test_output_paths_checked_before_the_work(stubbed: None, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    a_file = tmp_path / "file"
    a_file.write_text("")
    for argv, words in (
            (["model", "run", "--json", str(tmp_path)], "--json " + str(tmp_path) + ": is a "
             "folder"),
            (["model", "run", "--json", str(a_file / "r.json")], "is not a folder"),
            (["model", "run", "--json", "r.json", "--plot", str(a_file)], "is a file"),
            (["model", "grng", "--samples", "9", "--out", str(tmp_path)], "is a folder"),
            (["run", "--json", str(tmp_path)], "is a folder"),
            (["run", "--json", str(a_file / "x.json")], "is not a folder"),
            (["generate", "--out", str(a_file)], "is a file"),
            (["model", "run", "--json", "r.json", "--word", "12", "--config", "uav",
              "--set", "formats.velocity=s12.5", "--set", "formats.quaternion=s1.16"],
             "--word 12: narrower than the integer part of formats.velocity")):
        status, err = run_cli(argv, capsys)
        assert_one_line(status, err, words)
