"""Outputs never harm inputs (issue #19): no --json/--out/--plot over the config or the
scenario file, every file renamed into place only when complete, strict JSON (no NaN), and
`gpf run`'s warnings beside its bit-exact verdict. Nothing here simulates the RTL: the model
runs are tiny and `gpf run`'s simulation is a stub."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import resource
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_fuzz_cli import StartedError, _started
from test_fuzz_cli import assert_refused as one_line

from gpf import cli, outputs
from gpf.config import load_config
from gpf.model.scenarios import bot_fixed_observer, write_csv

REPO = Path(__file__).resolve().parent.parent
BOT = REPO / "configs" / "bot.toml"
TINY = ["--particles", "64", "--runs", "1"]


def md5(path: Path) -> str:
    return hashlib.md5(path.read_bytes()).hexdigest()


def strict_json(path: Path) -> Any:
    """Parse as a strict reader does: NaN, Infinity and -Infinity are errors."""
    def refuse(token: str) -> None:
        raise ValueError(f"{path}: {token} is not JSON")

    return json.loads(path.read_text(), parse_constant=refuse)


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int | None, str, str]:
    capsys.readouterr()
    try:
        status = cli.main(argv)
    except StartedError:
        status = None
    got = capsys.readouterr()
    return status, got.out, got.err




def scenario_csv(path: Path, truth: str = "all") -> Path:
    """A 6-step bot scenario file: with truth, without any (a recording), or without k = 0's."""
    sc = bot_fixed_observer(load_config(BOT), 6, 1)
    t = sc.truth.copy()
    if truth == "none":
        t[:] = np.nan
    elif truth == "not_k0":
        t[0] = np.nan
    mu0 = sc.truth[0] if sc.mu0 is None else sc.mu0
    write_csv(dataclasses.replace(sc, truth=t, mu0=mu0), path)
    return path


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The model run, the simulation and the generator would start: StartedError."""
    import gpf.model.grng
    import gpf.run
    import gpf.study.montecarlo

    monkeypatch.setattr(gpf.study.montecarlo, "monte_carlo", _started)
    monkeypatch.setattr(gpf.run, "run_filter", _started)
    monkeypatch.setattr(gpf.model.grng.GrngModel, "normals", _started)
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")


# ---- outputs over inputs: refused before the work, the input unchanged ----

def test_json_over_the_config_or_the_scenario_is_refused(
        no_work: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "my.toml"
    config.write_text(BOT.read_text())
    csv = scenario_csv(tmp_path / "track.csv")
    (tmp_path / "link.toml").symlink_to(config.name)
    sums = {p: md5(p) for p in (config, csv)}
    cases = [
        (["model", "run", "--config", str(config), "--json", str(config)], config, "config"),
        (["model", "run", "--config", str(config), "--scenario", str(csv), "--json", str(csv)],
         csv, "scenario file"),
        # through a symlink and a `..` of a folder that does not exist
        (["model", "run", "--config", str(config), "--json",
          str(tmp_path / "nosuch" / ".." / "link.toml")], config, "config"),
        (["run", "--config", str(config), "--json", str(config)], config, "config"),
        (["run", "--config", str(config), "--scenario", str(csv), "--json", str(csv)], csv,
         "scenario file"),
        (["synth", "--config", str(config), "--json", str(config)], config, "config"),
    ]
    for argv, victim, what in cases:
        status, _, err = run_cli(argv, capsys)
        one_line(status, err, "--json", argv[argv.index("--json") + 1],
                 f"would overwrite the {what} {victim}")
        assert {p: md5(p) for p in sums} == sums, argv
    assert not (tmp_path / "nosuch").exists()


def test_grng_out_over_the_config_is_refused(no_work: None, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "bot.npy"   # an odd name, but a config file all the same
    config.write_text(BOT.read_text())
    before = md5(config)
    status, _, err = run_cli(["model", "grng", "--config", str(config), "--samples", "5",
                              "--out", str(tmp_path / "bot")], capsys)   # writes bot.npy
    one_line(status, err, "--out", str(config), "would overwrite the config")
    assert md5(config) == before


def test_generate_into_the_config_folder(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """--out the config's own folder: refused only when a written name is the config's."""
    config = tmp_path / "config.toml"     # generate writes config.toml (a copy) there
    config.write_text(BOT.read_text())
    before = md5(config)
    status, _, err = run_cli(["generate", "--config", str(config), "--out", str(tmp_path)],
                             capsys)
    one_line(status, err, "--out", str(config), "would overwrite the config")
    assert md5(config) == before and [p.name for p in tmp_path.iterdir()] == ["config.toml"]


def test_plot_and_json_of_one_file_refused(no_work: None, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    plot = tmp_path / "plots"
    status, _, err = run_cli(["model", "run", "--json",
                              str(plot / "bot_bot_fixed_observer_estimate.png"),
                              "--plot", str(plot)], capsys)
    one_line(status, err, "--plot", "is also the file --json writes")
    assert not plot.exists()


def test_check_outputs(tmp_path: Path) -> None:
    rtl = tmp_path / "rtl"
    inputs = [("the config", tmp_path / "a.toml"), ("the generated RTL in", rtl),
              ("the scenario file", None)]
    outputs.check_outputs([("--json", tmp_path / "a.json"), ("--plot", tmp_path / "p/x.png")],
                          inputs)
    for outs, words in (
            ([("--json", tmp_path / "x" / ".." / "a.toml")], "would overwrite the config"),
            ([("--json", rtl / "sub" / "r.json")], "would overwrite the generated RTL in"),
            ([("--json", tmp_path / "p"), ("--plot", tmp_path / "p" / "x.png")],
             "--json writes")):
        with pytest.raises(outputs.OutputError, match=words):
            outputs.check_outputs(outs, inputs)


# ---- atomic writes: the previous file intact, no temporary file left ----

def test_a_failed_write_keeps_the_previous_results(tmp_path: Path) -> None:
    """The file-size limit (ulimit -f) stops `gpf model run` part-way through its JSON."""
    out = tmp_path / "r.json"
    argv = [sys.executable, "-m", "gpf.cli", "model", "run", "--config", str(BOT),
            "--particles", "64", "--steps", "30", "--json", str(out)]
    first = subprocess.run([*argv, "--runs", "2"], capture_output=True, text=True, cwd=REPO)
    assert first.returncode == 0, first.stderr
    before = out.read_bytes()
    assert len(before) > 8192

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (8192, 8192))

    run = subprocess.run([*argv, "--runs", "3"], capture_output=True, text=True, cwd=REPO,
                         preexec_fn=limit)
    assert run.returncode == 2, run.stderr
    assert run.stderr.count("\n") == 1 and f"{out}: File too large" in run.stderr
    assert out.read_bytes() == before
    strict_json(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_atomic_write_interrupted_part_way(tmp_path: Path, error: BaseException) -> None:
    out = tmp_path / "r.json"
    out.write_text('{"previous": 1}\n')
    with pytest.raises(type(error)) as caught, outputs.atomic_path(out) as tmp:
        tmp.write_text('{"half": ')
        raise error
    if isinstance(error, OSError):
        assert caught.value.filename == str(out)     # the error names the target
    assert json.loads(out.read_text()) == {"previous": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_rename_failure_names_the_path_and_cleans_up(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    def fail(src: Any, dst: Any) -> None:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(outputs.os, "replace", fail)
    with pytest.raises(PermissionError) as caught:
        outputs.atomic_write_text(tmp_path / "a.sv", "module a; endmodule\n")
    assert caught.value.filename == str(tmp_path / "a.sv")
    assert list(tmp_path.iterdir()) == []


def test_atomic_write_keeps_the_mode_and_a_symlink(tmp_path: Path) -> None:
    real = tmp_path / "real.json"
    real.write_text("{}\n")
    os.chmod(real, 0o640)
    (tmp_path / "link.json").symlink_to(real.name)
    outputs.write_json(tmp_path / "link.json", {"a": 1})
    assert (tmp_path / "link.json").is_symlink()
    assert json.loads(real.read_text()) == {"a": 1}
    assert real.stat().st_mode & 0o777 == 0o640


# ---- strict JSON ----

def test_json_text_has_no_nan() -> None:
    doc = {"a": float("nan"), "b": [np.inf, 1.5, (np.float64("-inf"),)],
           "c": np.array([1.0, np.nan]), "d": np.float32(2.5), "e": None, "f": "NaN"}
    text = outputs.json_text(doc)
    assert json.loads(text) == {"a": None, "b": [None, 1.5, [None]], "c": [1.0, None],
                                "d": 2.5, "e": None, "f": "NaN"}
    assert outputs.fmt(float("nan")) == outputs.fmt(None) == "n/a"
    assert outputs.fmt(0.97614, ".4f") == "0.9761"


@pytest.mark.parametrize("truth", ["none", "not_k0"])
def test_model_run_without_truth_writes_strict_json(tmp_path: Path, truth: str,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    csv = scenario_csv(tmp_path / "rec.csv", truth)
    out = tmp_path / "r.json"
    status, text, err = run_cli(["model", "run", "--config", str(BOT), "--scenario", str(csv),
                                 *TINY, "--json", str(out)], capsys)
    assert status == 0, err
    assert "NaN" not in out.read_text() and "Infinity" not in out.read_text()
    doc = strict_json(out)
    assert "nan" not in text.lower().replace("n/a", "")
    assert "n/a" in text       # one run: no spread; no truth: no RMSE either
    if truth == "none":
        assert doc["rmse"] == {"float": None, "fixed": None, "float_numpy_draws": None}
        assert doc["ratio_fixed_float"] is None and doc["lost_tracks"] is None
        assert "RMSE n/a" in text
    else:
        assert doc["ratio_std_error"] is None and doc["per_step"]["error_fixed"][0] is None


# ---- the path printed is the path written ----

def test_grng_prints_the_file_it_writes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    status, text, err = run_cli(["model", "grng", "--config", str(BOT), "--samples", "10",
                                 "--out", "x"], capsys)
    assert status == 0, err
    assert text.split(":")[0] == "x.npy"
    assert [p.name for p in tmp_path.iterdir()] == ["x.npy"]
    assert np.load(tmp_path / "x.npy").shape == (10, 1)


# ---- gpf run: warnings beside the verdict ----

def run_result(**changes: Any) -> dict[str, Any]:
    steps = 8
    res = {"config": "bot", "sim": "verilator", "scenario": "bot_fixed_observer", "seed": 1,
           "steps": steps, "particles": 64, "lanes": 1, "particles_checked": 64 * steps,
           "values_checked": 1000, "mismatches": 0, "first_mismatch": None,
           "cycles_per_step": [90] * steps, "flags": [[] for _ in range(steps)],
           "ess": [40.0] * steps, "metrics": {}, "rmse": {"rtl": None, "fixed": None,
                                                      "float": None},
           "lost_track": False, "quantisation_error": [0.01] * steps,
           "particles_per_second": 1000.0, "wall_seconds": 1.0, "total_seconds": 2.0,
           "passed": True, "log": "build/x.log", "estimates": {}}
    return {**res, **changes}


def test_summary_warns_of_saturation_and_a_lost_track() -> None:
    from gpf.run import run_warnings, summary_lines

    assert run_warnings(run_result()) == []
    assert not any("WARNING" in line for line in summary_lines(run_result()))
    flags = [[], ["sat"], ["sat", "not_pd"], ["sat"], ["sat"], [], ["sat"], []]
    lines = summary_lines(run_result(flags=flags, lost_track=True))
    warnings = [line.strip() for line in lines if "WARNING" in line]
    assert warnings == [
        "WARNING: values saturated at steps 2-5, 7 (SAT): the fixed-point formats cannot hold "
        "this scenario",
        "WARNING: the filter lost track (its error over the last 20 % is above 3 x float64's "
        "on the same draws)"]


def test_summary_of_a_recording_says_n_a() -> None:
    from gpf.run import summary_lines

    res = run_result(ess=[None] * 8, quantisation_error=[None] * 8,
                     metrics={"position": {"unit": "m", "all": dict.fromkeys(
                         ("rtl", "fixed", "float")), "last20": dict.fromkeys(
                         ("rtl", "fixed", "float"))}})
    text = "\n".join(summary_lines(res))
    assert "nan" not in text.lower().replace("n/a", "") and "rtl n/a / n/a" in text
    assert "mean n/a, min n/a" in text and "max n/a" in text


def test_gpf_run_writes_warnings_and_keeps_passed(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    import gpf.run

    flags = [[], ["sat"], ["sat"], [], [], [], [], []]
    monkeypatch.setattr(gpf.run, "run_filter",
                        lambda *a, **k: run_result(flags=flags, ess=[float("nan")] + [40.0] * 7))
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")
    out = tmp_path / "r.json"
    status, text, err = run_cli(["run", "--config", str(BOT), "--steps", "8", "--particles",
                                 "64", "--json", str(out)], capsys)
    assert status == 0, err
    doc = strict_json(out)
    assert doc["warnings"] == ["WARNING: values saturated at steps 2-3 (SAT): the fixed-point "
                               "formats cannot hold this scenario"]
    assert doc["ess"][0] is None
    assert "  WARNING: values saturated at steps 2-3 (SAT)" in text
    assert f"-> {out}: PASSED" in text
