"""The figures of a run (study/plots.py), read back as matplotlib objects, no pixels: one
style for `gpf model run` and `gpf run`, titles, axis labels with units, time in seconds, one
legend outside the axes, the quantisation visible (each filter minus float64), the observer,
uav attitude as labelled Euler angles, and nothing about truth when a recording has none."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gpf.config import load_config
from gpf.model.scenarios import bot_manoeuvring_observer, uav_flight
from gpf.study import plots
from gpf.study.plots import plot_files, plot_run, run_figures

REPO = Path(__file__).resolve().parents[1]
UNIT = re.compile(r"\((m|m/s|deg|s)\)$")


def estimates(app: str, steps: int, truth: bool = True, rtl: bool = True
              ) -> tuple[dict[str, np.ndarray], float, np.ndarray | None]:
    """A scenario's truth with made-up estimates near it: float64, fixed point (a few LSBs
    off float64), the RTL (equal to fixed point, as a bit-exact run)."""
    cfg = load_config(REPO / "configs" / f"{app}.toml")
    sc = (bot_manoeuvring_observer if app == "bot" else uav_flight)(cfg, steps, 1)
    rng = np.random.default_rng(0)
    flt = sc.truth + 0.05 * rng.standard_normal(sc.truth.shape)
    if app == "uav":
        flt[:, :4] /= np.linalg.norm(flt[:, :4], axis=1, keepdims=True)
    fixed = flt + 1e-3 * rng.standard_normal(flt.shape)
    est = {"truth": sc.truth if truth else np.full_like(sc.truth, np.nan), "float": flt,
           "fixed": fixed, **({"rtl": fixed.copy()} if rtl else {})}
    return est, cfg.dt, sc.inputs.get("observer")


def axes_of(fig: Any) -> list[Any]:
    return [ax for ax in fig.axes if ax.lines]


def line_labels(fig: Any) -> set[str]:
    return {line.get_label() for ax in fig.axes for line in ax.lines
            if not line.get_label().startswith("_")}


def legend_texts(fig: Any) -> list[str]:
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def check_common(fig: Any, dt: float, steps: int) -> None:
    """A title, every axis labelled with a unit, time in seconds, one figure legend and no
    legend inside any axes."""
    assert fig.get_suptitle().strip()
    for ax in axes_of(fig):
        assert UNIT.search(ax.get_ylabel()), ax.get_ylabel()
        shared_x = ax.get_shared_x_axes().get_siblings(ax)
        if ax.get_xlabel() == "time (s)" or any(a.get_xlabel() == "time (s)"
                                                for a in shared_x):
            right = max(np.nanmax(line.get_xdata()) for line in ax.lines)
            assert right == pytest.approx(steps * dt)     # seconds, not steps
        else:
            assert UNIT.search(ax.get_xlabel()), ax.get_xlabel()
        assert ax.get_legend() is None                    # the legend covers no data
    assert len(fig.legends) == 1


@pytest.mark.parametrize("app", ["bot", "uav"])
def test_rtl_run_figures(app: str) -> None:
    steps = 30
    est, dt, observer = estimates(app, steps)
    figs = run_figures(app, est, dt, "gpf run: test", observer)
    assert list(figs) == ["estimate", "error"]
    for fig in figs.values():
        check_common(fig, dt, steps)
    estimate, error = figs["estimate"], figs["error"]
    assert legend_texts(estimate) == ["truth", "float64", "fixed point", "RTL"] + (
        ["observer"] if app == "bot" else [])
    assert legend_texts(error) == ["float64", "fixed point", "RTL"]
    assert "bit for bit" in estimate.get_suptitle()      # RTL = fixed point here
    # the difference panels: each filter minus float64 on the same draws, per component
    diff = [ax for ax in estimate.axes if "difference" in ax.get_ylabel()]
    assert len(diff) == (4 if app == "bot" else 6)
    for ax in diff:
        assert [line.get_label() for line in ax.lines] == ["fixed point", "RTL"]
    if app == "bot":
        x = next(ax for ax in diff if ax.get_ylabel() == "x difference (m)")
        np.testing.assert_allclose(x.lines[1].get_ydata(), est["rtl"][:, 0] - est["float"][:, 0])
        track = next(ax for ax in estimate.axes if ax.get_xlabel() == "x (m)")
        assert "observer" in [line.get_label() for line in track.lines]
    else:
        labels = {ax.get_ylabel() for ax in estimate.axes}
        assert {"roll (deg)", "pitch (deg)", "yaw (deg)", "v east (m/s)", "v north (m/s)",
                "v up (m/s)"} <= labels
        assert not any(re.search(r"\bq[0-3]?\b|quaternion", label) for label in labels)
        v = next(ax for ax in diff if ax.get_ylabel() == "v east difference (m/s)")
        np.testing.assert_allclose(v.lines[0].get_ydata(),
                                   est["fixed"][:, 4] - est["float"][:, 4])
        for ax in estimate.axes:      # no unlabelled lines (four quaternion components)
            assert all(not line.get_label().startswith("_") for line in ax.lines)


@pytest.mark.parametrize("app", ["bot", "uav"])
def test_recording_without_truth_draws_no_truth(app: str, tmp_path: Path) -> None:
    steps = 12
    est, dt, observer = estimates(app, steps, truth=False, rtl=False)
    figs = run_figures(app, est, dt, "gpf model run: recording", observer)
    assert list(figs) == ["estimate"]                    # no error figure
    check_common(figs["estimate"], dt, steps)
    assert "truth" not in legend_texts(figs["estimate"]) + list(line_labels(figs["estimate"]))
    assert "nan" not in figs["estimate"].get_suptitle().lower()
    (tmp_path / "rec_error.png").write_bytes(b"an earlier run's, with truth")
    files = plot_run(app, est, dt, "recording", tmp_path, "rec", observer)
    assert files == plot_files(tmp_path, "rec")[:1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec_estimate.png"]


def test_truth_missing_at_k0_still_has_errors() -> None:
    est, dt, observer = estimates("bot", 8)
    est["truth"] = est["truth"].copy()
    est["truth"][0] = np.nan           # a recording whose truth starts at k = 1
    assert list(run_figures("bot", est, dt, "t", observer)) == ["estimate", "error"]


def test_yaw_is_drawn_continuous_through_180() -> None:
    """A heading that turns through +-180 deg: no 360-degree jumps in the yaw panel."""
    steps = 200
    est, dt, _ = estimates("uav", steps, rtl=False)
    yaw = np.radians(np.linspace(170, 190, steps + 1))
    for name in est:
        q = np.zeros((steps + 1, 4))
        q[:, 0], q[:, 3] = np.cos(yaw / 2), np.sin(yaw / 2)
        est[name] = est[name].copy()
        est[name][:, :4] = q
    fig = run_figures("uav", est, dt, "turn")["estimate"]
    ax = next(a for a in fig.axes if a.get_ylabel() == "yaw (deg)")
    for line in ax.lines:
        assert np.max(np.abs(np.diff(line.get_ydata()))) < 1.0


def test_model_run_and_rtl_run_draw_through_plot_run(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path) -> None:
    """One style: `gpf model run` and `gpf run` both hand their estimates to plot_run."""
    from gpf import cli
    from gpf.run import plot

    calls: list[tuple[str, list[str], str]] = []

    def record(app: str, est: dict, dt: float, title: str, *args: Any, **kw: Any) -> list[str]:
        calls.append((app, list(est), title))
        return []

    monkeypatch.setattr(plots, "plot_run", record)
    assert cli.main(["model", "run", "--config", "bot", "--steps", "3", "--particles", "64",
                     "--plot", str(tmp_path)]) == 0
    est, _, observer = estimates("bot", 3)
    res = {"config": "bot", "sim": "verilator", "particles": 64, "steps": 3, "seed": 1,
           "scenario": "bot_manoeuvring_observer",
           "estimates": {**{k: v.tolist() for k, v in est.items()},
                         "observer": observer[1:].tolist()}}
    plot(res, load_config(REPO / "configs" / "bot.toml"), tmp_path)
    assert [c[:2] for c in calls] == [("bot", ["truth", "float", "fixed"]),
                                      ("bot", ["truth", "float", "fixed", "rtl"])]
    assert calls[0][2].startswith("gpf model run: bot") and calls[1][2].startswith("gpf run: bot")
