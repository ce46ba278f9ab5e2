"""Recordings (scenario CSV files) through `gpf model run` and `gpf run` (issue #15): a file
filtered in part (`--steps` fewer than it has; more refused), a file without truth (no
error lines, no error plot, strict JSON with null), one Monte Carlo run (no spread), and
messages that never show a numpy repr (`np.float64(2.5)`)."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gpf import cli
from gpf.config import ConfigError, load_config
from gpf.model.scenarios import (
    bot_manoeuvring_observer,
    read_csv,
    uav_flight,
    write_csv,
)
from gpf.toolchain import icarus_missing

REPO = Path(__file__).resolve().parents[1]
BOT = REPO / "configs" / "bot.toml"
NUMPY_REPR = re.compile(r"np\.|numpy|array\(|float64\(|int64\(")


def strict_json(path: Path) -> Any:
    """As a strict reader parses: NaN, Infinity, -Infinity are errors."""
    def refuse(token: str) -> None:
        raise ValueError(f"{path}: {token} is not JSON")

    return json.loads(path.read_text(), parse_constant=refuse)


def recording(path: Path, steps: int = 10, truth: bool = True, config: Path = BOT) -> Path:
    """A bot recording (the manoeuvring observer) written by the scenario code; without truth
    its truth columns are empty, as recorded data's are."""
    sc = bot_manoeuvring_observer(load_config(config), steps, 1)
    if not truth:
        sc = dataclasses.replace(sc, truth=np.full_like(sc.truth, np.nan))
    write_csv(sc, path)
    return path


def gpf(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    capsys.readouterr()
    try:
        status = cli.main(argv)
    except SystemExit as exc:
        status = int(exc.code or 0)
    got = capsys.readouterr()
    return status, got.out, got.err


def model_run(csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], *more: str
              ) -> tuple[int, str, str, Path]:
    out = tmp_path / "r.json"
    out.unlink(missing_ok=True)
    status, text, err = gpf(["model", "run", "--config", "bot", "--particles", "64",
                             "--scenario", str(csv), "--json", str(out), *more], capsys)
    return status, text, err, out


# ---- --steps on a recording ----

def test_scenario_first_steps(tmp_path: Path) -> None:
    sc = read_csv(recording(tmp_path / "r.csv", 10))
    part = sc.first(4)
    assert part.steps == 4 and part.t.tolist() == sc.t[:5].tolist()
    np.testing.assert_array_equal(part.measurements["z"], sc.measurements["z"][:5])
    np.testing.assert_array_equal(part.inputs["observer"], sc.inputs["observer"][:5])
    np.testing.assert_array_equal(part.truth, sc.truth[:5])
    assert (part.mu0 == sc.mu0).all() and part.meta == sc.meta and sc.steps == 10
    assert sc.first(10).steps == 10
    with pytest.raises(ValueError, match=r"--steps 11: x\.csv has 10 steps"):
        sc.first(11, "x.csv")


def test_model_run_filters_the_first_steps(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "track.csv", 10)
    status, text, err, out = model_run(csv, tmp_path, capsys)
    assert status == 0, err
    whole = strict_json(out)
    status, text, err, out = model_run(csv, tmp_path, capsys, "--steps", "5")
    assert status == 0, err
    part = strict_json(out)
    assert part["steps"] == 5 and len(part["per_step"]["fixed"]) == 6
    assert "track.csv: 1 run x 5 steps" in text
    # the same draws, the same data: the first 5 steps of the whole file's run
    for key in ("truth", "float", "fixed"):
        assert part["per_step"][key] == whole["per_step"][key][:6]


def test_model_run_refuses_more_steps_than_the_recording(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "track.csv", 10)
    status, text, err, out = model_run(csv, tmp_path, capsys, "--steps", "11")
    assert status == 2 and not out.exists()
    assert err.strip().splitlines() == [
        f"gpf: error: --steps 11: {csv} has 10 steps (k = 1..10); give --steps 1 to 10, or "
        "leave it out to filter them all"]


# ---- a recording without truth ----

def test_model_run_without_truth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "rec.csv", 10, truth=False)
    plots = tmp_path / "plots"
    status, text, err, out = model_run(csv, tmp_path, capsys, "--plot", str(plots))
    assert status == 0, err
    doc = strict_json(out)        # no NaN token anywhere
    assert doc["rmse"] == {"float": None, "fixed": None, "float_numpy_draws": None}
    assert doc["metrics"] == {} and doc["ratio_fixed_float"] is None
    assert doc["ratio_std_error"] is None and doc["lost_tracks"] is None
    assert all(r is None for r in doc["per_step"]["truth"])
    assert doc["quantisation_max"] > 0          # fixed point vs float64: known without truth
    assert "nan" not in text.lower().replace("n/a", "")
    assert text.count("no truth in the recording: errors not computed") == 1
    assert not re.search(r"RMSE \(|ratio \d", text)      # no error line at all
    assert "fixed point vs float64 (same draws), position per step: max" in text
    assert sorted(p.name for p in plots.iterdir()) == ["bot_file_estimate.png"]
    assert doc["plots"] == [str(plots / "bot_file_estimate.png")]


def test_one_run_has_no_spread(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "track.csv", 6)
    status, text, err, out = model_run(csv, tmp_path, capsys)
    assert status == 0, err
    doc = strict_json(out)
    assert doc["ratio_std_error"] is None
    assert all(m[w]["ratio_std_error"] is None for m in doc["metrics"].values()
               for w in ("all", "last20"))
    ratios = re.findall(r"ratio (\S+)( \(1 run: spread n/a\)| \+-)", text)
    assert ratios and all(kind == " (1 run: spread n/a)" for _, kind in ratios)
    assert "+-" not in text and "nan" not in text.lower().replace("n/a", "")


def test_two_runs_have_a_spread(capsys: pytest.CaptureFixture[str]) -> None:
    status, text, err = gpf(["model", "run", "--config", "bot", "--particles", "64",
                             "--steps", "5", "--runs", "2"], capsys)
    assert status == 0, err
    assert "2 runs x 5 steps" in text and re.search(r"ratio \d\.\d{4} \+- \d\.\d{4}", text)


# ---- gpf run: the same, the simulation stubbed ----

@pytest.fixture
def fake_rtl(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list:
    """gpf run without a simulator: run_filter answers as the testbench does for a recording
    without truth (run_metrics: no metrics, no RMSE, lost track unknown)."""
    import gpf.run
    from gpf.study.metrics import run_metrics

    calls: list = []

    def run_filter(cfg: Any, args: Any, **kw: Any) -> dict[str, Any]:
        calls.append(args)
        sc = read_csv(gpf.run._recording(Path(args.scenario), args.steps, tmp_path / "work"))
        est = {"rtl": np.ones_like(sc.truth), "fixed": np.ones_like(sc.truth),
               "float": np.full_like(sc.truth, 1.001)}
        report = run_metrics(cfg.app, sc.truth, est)
        steps = sc.steps
        return {"config": cfg.name, "sim": "verilator", "scenario": Path(args.scenario).name,
                "seed": args.seed, "steps": steps, "particles": args.particles, "lanes": 1,
                "particles_checked": steps * args.particles, "values_checked": 10,
                "mismatches": 0, "first_mismatch": None, "cycles_per_step": [300] * steps,
                "flags": [[] for _ in range(steps)], "ess": [40.0] * steps,
                "metrics": report.metrics, "rmse": report.rmse, "lost_track": report.lost,
                "quantisation_error": report.quantisation, "particles_per_second": 1.0,
                "wall_seconds": 1.0, "total_seconds": 2.0, "passed": True, "log": "x.log",
                "app": cfg.app, "primary_metric": "position", "rmse_unit": "m",
                "estimates": {"truth": [None] * (steps + 1), "observer":
                              sc.inputs["observer"][1:].tolist(),
                              **{k: v.tolist() for k, v in est.items()}}}

    monkeypatch.setattr(gpf.run, "run_filter", run_filter)
    monkeypatch.setattr(cli, "check_simulator", lambda *a: None)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")
    return calls


def test_gpf_run_recording_in_part_and_without_truth(
        fake_rtl: list, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "rec.csv", 10, truth=False)
    out, plots = tmp_path / "r.json", tmp_path / "plots"
    status, text, err = gpf(["run", "--config", "bot", "--scenario", str(csv), "--steps", "4",
                             "--particles", "64", "--json", str(out), "--plot", str(plots)],
                            capsys)
    assert status == 0, err
    assert fake_rtl[0].steps == 4
    doc = strict_json(out)
    assert doc["steps"] == 4 and doc["lost_track"] is None and doc["metrics"] == {}
    assert doc["rmse"] == {"rtl": None, "fixed": None, "float": None}
    assert text.count("no truth in the recording: errors not computed") == 1
    assert "RMSE (" not in text and "nan" not in text.lower().replace("n/a", "")
    assert "rtl vs float64 (same draws), position per step: max 0.00141 m" in text
    assert sorted(p.name for p in plots.iterdir()) == ["bot_verilator_estimate.png"]
    # without --json: no JSON, the same summary
    status, text2, err = gpf(["run", "--config", "bot", "--scenario", str(csv), "--steps", "4",
                              "--particles", "64"], capsys)
    assert status == 0, err
    assert "no truth in the recording" in text2


def test_gpf_run_refuses_more_steps_than_the_recording(
        fake_rtl: list, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "rec.csv", 10)
    status, _, err = gpf(["run", "--config", "bot", "--scenario", str(csv), "--steps", "12",
                          "--particles", "64"], capsys)
    assert status == 2 and not fake_rtl
    assert err.strip().splitlines() == [
        f"gpf: error: --steps 12: {csv} has 10 steps (k = 1..10); give --steps 1 to 10, or "
        "leave it out to filter them all"]


def test_testbench_reads_the_first_steps_exactly(tmp_path: Path) -> None:
    """gpf run hands the testbench (which filters a whole file) the recording's first steps:
    the file's own lines, byte for byte, under the same name."""
    from gpf.run import _recording

    csv = recording(tmp_path / "rec.csv", 10)
    assert _recording(csv, 10, tmp_path / "work") == csv.resolve()
    part = _recording(csv, 3, tmp_path / "work")
    assert part.name == "rec.csv" and part != csv.resolve()
    assert part.read_text().splitlines() == csv.read_text().splitlines()[:5 + 4]
    assert read_csv(part).steps == 3


# ---- messages: plain numbers, never a numpy repr ----

def test_csv_time_error_is_plain(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "track.csv", 6)
    lines = csv.read_text().splitlines()
    i = next(j for j, line in enumerate(lines) if line.startswith("3,"))
    lines[i] = "3,2.5," + lines[i].split(",", 2)[2]
    csv.write_text("\n".join(lines) + "\n")
    status, _, err, _ = model_run(csv, tmp_path, capsys)
    assert status == 2 and not NUMPY_REPR.search(err), err
    assert f"row 3 (line {i + 1}), column 't': 2.5, expected t_0 + k dt = 3.0" in err
    # without the metadata dt, a negative step
    body = [line for line in lines if not line.startswith("# dt")]
    j = next(j for j, line in enumerate(body) if line.startswith("1,"))
    body[j] = "1,-1.0," + body[j].split(",", 2)[2]
    csv.write_text("\n".join(body) + "\n")
    status, _, err, _ = model_run(csv, tmp_path, capsys)
    assert status == 2 and not NUMPY_REPR.search(err), err
    assert "column 't': -1.0 after t_0 = 0.0: the step dt = -1.0 (from rows 0 and 1)" in err


@pytest.mark.parametrize("app", ["bot", "uav"])
def test_no_recording_message_shows_a_numpy_repr(app: str, tmp_path: Path) -> None:
    """Every cell of a short recording set to a wrong value in turn: each message plain."""
    cfg = load_config(REPO / "configs" / f"{app}.toml")
    sc = (bot_manoeuvring_observer if app == "bot" else uav_flight)(cfg, 3, 1)
    base = tmp_path / "base.csv"
    write_csv(sc, base)
    lines = base.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    messages = []
    path = tmp_path / "m.csv"
    for r in range(head + 1, len(lines)):
        cells = lines[r].split(",")
        for c in range(len(cells)):
            for value in ("2.5", "-7", "100", "1e-300", "1e300", "x", ""):
                changed = cells.copy()
                changed[c] = value
                path.write_text("\n".join([*lines[:r], ",".join(changed), *lines[r + 1:]])
                                + "\n")
                try:
                    read_csv(path, cfg)
                except ConfigError as exc:
                    messages.append(str(exc))
    for meta in ("# dt: 0.5", "# mu0: [2, 0, 0, 0, 0, 0, 0]", "# mu0: [1000, 0, 1000, 0]",
                 "# mu0: [1, 0, 0, 0, 0, 0, 1000]"):
        key = meta[:6]
        path.write_text("\n".join([meta, *(line for line in lines if not line.startswith(key))])
                        + "\n")
        try:
            read_csv(path, cfg)
        except ConfigError as exc:
            messages.append(str(exc))
    assert len(messages) > 50
    bad = [m for m in messages if NUMPY_REPR.search(m)]
    assert not bad, bad[:5]


# ---- gpf run end to end (a real simulation): a recording without truth, in part ----

@pytest.mark.sim
@pytest.mark.slow
@pytest.mark.xdist_group("gpf-odd-lanes2-icarus")       # test_sim_filter's build of odd
@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
def test_gpf_run_recording_without_truth_in_rtl(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    csv = recording(tmp_path / "rec.csv", 4, truth=False, config=REPO / "configs" / "odd.toml")
    out, plots = tmp_path / "r.json", tmp_path / "plots"
    status, text, err = gpf(["run", "--config", "odd", "--sim", "icarus", "--steps", "2",
                             "--particles", "32", "--scenario", str(csv), "--json", str(out),
                             "--plot", str(plots)], capsys)
    assert status == 0, text + err
    doc = strict_json(out)
    assert doc["steps"] == 2 and doc["mismatches"] == 0 and doc["scenario"] == "rec.csv"
    assert len(doc["estimates"]["rtl"]) == 3 and doc["metrics"] == {}
    assert doc["rmse"] == {"rtl": None, "fixed": None, "float": None}
    assert doc["lost_track"] is None
    assert text.count("no truth in the recording: errors not computed") == 1
    assert "nan" not in text.lower().replace("n/a", "")
    assert [Path(p).name for p in doc["plots"]] == ["odd_icarus_estimate.png"]
