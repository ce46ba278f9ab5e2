"""`gpf model run`: the JSON a script reads, plots, scenario files, and bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from gpf.config import load_config
from gpf.model.scenarios import bot_manoeuvring_observer, write_csv


def gpf(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpf.cli", *args], capture_output=True,
                          text=True)


def test_model_run_json_and_plots(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    run = gpf("model", "run", "--config", "bot", "--particles", "128", "--runs", "2",
              "--steps", "8", "--seed", "3", "--json", str(out), "--plot", str(tmp_path))
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    assert (doc["steps"], doc["particles"], doc["runs"], doc["seed"]) == (8, 128, 2, 3)
    assert set(doc["rmse"]) >= {"float", "fixed"}
    assert 0.5 < doc["rmse"]["fixed"] / doc["rmse"]["float"] < 2
    first = doc["per_step"]
    assert len(first["truth"]) == len(first["float"]) == len(first["fixed"]) == 9
    assert len(first["flags"]) == 9
    assert len(doc["plots"]) == 2
    for name in doc["plots"]:
        assert Path(name).parent == tmp_path and Path(name).stat().st_size > 1000


def test_model_run_reproducible(tmp_path: Path) -> None:
    docs = []
    for name in ("a", "b"):
        out = tmp_path / f"{name}.json"
        assert gpf("model", "run", "--config", "bot", "--particles", "64", "--steps", "5",
                   "--json", str(out)).returncode == 0
        docs.append(json.loads(out.read_text()))
    assert docs[0]["per_step"] == docs[1]["per_step"]


def test_model_run_scenario_file(tmp_path: Path) -> None:
    csv = tmp_path / "track.csv"
    write_csv(bot_manoeuvring_observer(load_config("configs/bot.toml"), 6, 2), csv)
    out = tmp_path / "r.json"
    run = gpf("model", "run", "--config", "bot", "--particles", "64", "--scenario", str(csv),
              "--json", str(out))
    assert run.returncode == 0, run.stderr
    assert json.loads(out.read_text())["steps"] == 6


def test_model_run_bad_input(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("k,t,z\n0,0,\n")
    for args in (["--particles", "0"], ["--scenario", "nosuch"], ["--scenario", str(bad)],
                 ["--runs", "-1"]):
        run = gpf("model", "run", "--config", "bot", "--json", str(tmp_path / "x.json"), *args)
        assert run.returncode == 2, (args, run.stderr)
        assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr


def test_sim_and_waves_reject_a_block_the_config_lacks() -> None:
    """An unknown block, or one of the other application's filter: one line, exit 2."""
    for args, says in ((["sim", "--module", "nope"], "unknown"),
                       (["sim", "--module", "weight_uav"], "CONFIG=uav"),
                       (["sim", "--module", "propagate_bot", "--config", "uav"], "CONFIG=bot"),
                       (["waves", "--module", "nope", "--no-launch"], "unknown")):
        run = gpf(*args)
        assert run.returncode == 2, (args, run.stderr)
        assert len(run.stderr.strip().splitlines()) == 1 and says in run.stderr, run.stderr
