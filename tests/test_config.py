"""Config loading: the shipped configs load; every kind of bad input is one clear line."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from gpf.config import ConfigError, config_from_dict, load_config

CONFIGS = sorted(Path("configs").glob("*.toml"))


def base_doc() -> dict:
    return tomllib.loads(Path("configs/bot.toml").read_text())


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_shipped_configs_load(path: Path) -> None:
    cfg = load_config(path)
    assert cfg.name == path.stem
    assert cfg.particles % cfg.lanes == 0
    assert str(cfg.noise).startswith("s3.")


def test_seed002_word_lengths() -> None:
    uav = load_config("configs/uav.toml")
    # 20-bit states, an 18-bit weight from the full-flight study (README, "Robustness"); seed
    # 002's own in uav_seed002.toml
    assert [uav.formats[k].width for k in ("quaternion", "velocity", "weight")] == [20, 20, 18]
    seed002 = load_config("configs/uav_seed002.toml")
    assert [str(seed002.formats[k]) for k in ("quaternion", "velocity", "weight")] == [
        "s3.20", "s10.13", "u1.23"]
    assert uav.particles == 2048
    assert uav.app_params == {"sigma_omega_deg": 0.008, "sigma_a": 0.07, "sigma_v": 0.02,
                              "covariance": "block",
                              "sigma0_diag": [3.0e-4] * 4 + [9.0e-4] * 3}
    bot = load_config("configs/bot.toml")
    assert bot.app_params["x0"] == [1.0, 0.3, 3.0, 0.3]
    assert bot.dt == 1.0 and bot.steps == 50


def test_overrides_name_their_build_folder() -> None:
    cfg = load_config("configs/bot.toml", {"filter.lanes": 2})
    assert cfg.lanes == 2 and cfg.name == "bot-lanes2"
    assert cfg.overrides == {"filter.lanes": 2}


BAD = [
    # (section, key, value, words the message must contain)
    ("filter", "lanes", 3, ["filter.lanes = 3", "one of 1, 2, 4"]),
    ("filter", "lanes", "2", ["filter.lanes = '2'", "expected integer"]),
    ("filter", "lanes", True, ["filter.lanes = True", "expected integer"]),
    ("filter", "particles", 1, ["filter.particles = 1", "[2, 65536]"]),
    ("filter", "dt", -1.0, ["filter.dt = -1.0", "> 0"]),
    ("filter", "dt", float("nan"), ["filter.dt = nan"]),
    ("filter", "app", "sir", ["filter.app = 'sir'", "'bot', 'uav'"]),
    ("filter", "speed", 1, ["filter.speed: unknown key", "allowed keys are app"]),
    ("formats", "noise", "s3", ["formats.noise = 's3'", "sI.F"]),
    ("formats", "noise", "s4.14", ["formats.noise = 's4.14'", "s3.F"]),
    ("formats", "state", "s70.10", ["formats.state = 's70.10'", "at most 64 bits"]),
    ("formats", "weight", "s1.23", ["formats.weight = 's1.23'", "unsigned"]),
    ("formats", "quaternion", "s3.20", ["formats.quaternion", "not used by app 'bot'"]),
    ("grng", "octaves", 60, ["grng.octaves = 60", "[32, 48]"]),
    ("grng", "seed", -1, ["grng.seed = -1"]),
    ("bot", "x0", [1, 2, 3], ["bot.x0 = [1, 2, 3]", "list of 4"]),
    ("bot", "sigma0_diag", [1, 1, 0, 1], ["bot.sigma0_diag", "positive"]),
]


@pytest.mark.parametrize("section,key,value,words", BAD, ids=lambda v: str(v)[:20])
def test_bad_value_is_one_line(section, key, value, words) -> None:
    doc = base_doc()
    doc[section][key] = value
    with pytest.raises(ConfigError) as err:
        config_from_dict(doc, source="configs/x.toml")
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("configs/x.toml: ")
    for word in words:
        assert word in message


def test_structural_errors() -> None:
    doc = base_doc()
    doc["uav"] = {"sigma_v": 1.0}
    with pytest.raises(ConfigError, match=r"\[uav\] given for app 'bot'"):
        config_from_dict(doc)
    doc = base_doc()
    del doc["grng"]
    with pytest.raises(ConfigError, match=r"missing section \[grng\]"):
        config_from_dict(doc)
    doc = base_doc()
    doc["extra"] = {}
    with pytest.raises(ConfigError, match=r"unknown section \[extra\]"):
        config_from_dict(doc)
    doc = base_doc()
    del doc["filter"]["steps"]
    with pytest.raises(ConfigError, match="filter.steps: missing"):
        config_from_dict(doc)
    doc = base_doc()
    doc["filter"]["lanes"] = 4
    doc["filter"]["particles"] = 1022
    with pytest.raises(ConfigError, match="multiple of filter.lanes = 4"):
        config_from_dict(doc)


def run_gpf(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpf.cli", *args], capture_output=True,
                          text=True, cwd=cwd)


@pytest.mark.parametrize("text", [
    "[filter\napp = 'bot'",                      # not TOML
    "[filter]\napp = 'bot'\nlanes = 3\n",        # incomplete and wrong
    "",                                          # empty
])
def test_cli_bad_config_exits_2_with_one_line(tmp_path: Path, text: str) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "out"
    run = run_gpf("generate", "--config", str(bad), "--out", str(out))
    assert run.returncode == 2
    assert run.stdout == ""
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gpf: error: ")
    assert "Traceback" not in run.stderr
    assert not out.exists(), "a failed generate must write nothing"


@pytest.mark.parametrize("args", [
    ["generate", "--config", "nosuch"],
    ["generate", "--config", "bot", "--set", "filter.lanes=3"],
    ["generate", "--config", "bot", "--set", "lanes"],
    ["model", "grng", "--config", "bot", "--samples", "x", "--out", "z.npy"],
    ["model", "grng", "--config", "bot", "--samples", "0", "--out", "z.npy"],
    ["sim", "--sim", "modelsim"],
    ["frobnicate"],
])
def test_cli_bad_arguments_exit_2(tmp_path: Path, args: list[str]) -> None:
    run = run_gpf(*args, cwd=Path.cwd())
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gpf"), run.stderr
