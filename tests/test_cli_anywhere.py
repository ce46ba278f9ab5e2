"""gpf from any folder: shipped configs by name, the generated files' `Regenerate with:` line,
and the replay line every simulation prints."""

from __future__ import annotations

import argparse
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
    for path in rtl.iterdir():
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
