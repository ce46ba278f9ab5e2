"""Figures of one run's estimates, the same for `gpf model run` (its first Monte Carlo run) and
`gpf run` (the RTL beside both models): bot, the track with the observer and the position
error; uav, roll, pitch and yaw in degrees and the velocity, and the tilt, heading and velocity
errors. Time is in seconds; every filter keeps its colour and line style in every figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpf.outputs import atomic_path
from gpf.study.metrics import METRICS, euler_deg

STYLE = {"truth": ("k", "-"), "float": ("tab:blue", "--"), "fixed": ("tab:green", "-."),
         "rtl": ("tab:red", ":"), "float_numpy": ("tab:gray", "--")}
LABEL = {"truth": "truth", "float": "float64", "fixed": "fixed point", "rtl": "RTL",
         "float_numpy": "float64, numpy draws"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")   # files only, no display needed
    import matplotlib.pyplot as plt

    return plt


def _line(ax, t, y, name: str, **kw) -> None:
    colour, style = STYLE[name]
    ax.plot(t, y, color=colour, linestyle=style, label=LABEL[name], **kw)


def plot_files(directory: str | Path, stem: str) -> list[str]:
    """Every file plot_run(..., directory, stem) may write (the error figure needs truth)."""
    return [str(Path(directory) / f"{stem}_{kind}.png") for kind in ("estimate", "error")]


def _save(plt, fig, path: str) -> None:
    """A temporary file renamed into place when complete (gpf.outputs)."""
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)


def plot_run(app: str, est: dict[str, np.ndarray], dt: float, title: str, directory: str | Path,
             stem: str, observer: np.ndarray | None = None) -> list[str]:
    """PNG files of the estimates (rows k = 0..steps) of the filters in `est` (truth first if
    known); returns their paths."""
    plt = _pyplot()
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    est = {k: np.asarray(v, dtype=float) for k, v in est.items()}
    t = np.arange(len(next(iter(est.values())))) * dt
    has_truth = "truth" in est and np.all(np.isfinite(est["truth"][1:]))
    shown = [k for k in est if k != "truth" or has_truth]
    files = []
    if app == "bot":
        fig, ax = plt.subplots(figsize=(7, 5.5))
        for name in shown:
            colour, style = STYLE[name]
            ax.plot(est[name][:, 0], est[name][:, 2], color=colour, linestyle=style,
                    label=LABEL[name])
        if observer is not None:
            ax.plot(observer[:, 0], observer[:, 1], ".", color="tab:orange", ms=3,
                    label="observer")
        ax.set(xlabel="x (m)", ylabel="y (m)", title=f"{title}: track")
        ax.set_aspect("equal", adjustable="datalim")
    else:
        fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
        angles = {k: euler_deg(v) for k, v in est.items() if k in shown}
        for i, what in enumerate(("roll", "pitch", "yaw")):
            for name in shown:
                _line(axes[i, 0], t, angles[name][:, i], name)
            axes[i, 0].set_ylabel(f"{what} (deg)")
        for i, what in enumerate(("v east", "v north", "v up")):
            for name in shown:
                _line(axes[i, 1], t, est[name][:, 4 + i], name)
            axes[i, 1].set_ylabel(f"{what} (m/s)")
        for ax in axes[-1]:
            ax.set_xlabel("time (s)")
        fig.suptitle(f"{title}: attitude and velocity")
        ax = axes[0, 0]
    ax.legend(fontsize=8)
    fig.tight_layout()
    files.append(plot_files(out, stem)[0])
    _save(plt, fig, files[-1])
    if not has_truth:
        return files
    metrics = METRICS[app][:3]
    fig, axes = plt.subplots(len(metrics), 1, figsize=(9, 2.6 * len(metrics) + 0.6),
                             sharex=True, squeeze=False)
    for ax, m in zip(axes[:, 0], metrics, strict=True):
        for name in shown:
            if name != "truth":
                _line(ax, t[1:], m.error(est[name], est["truth"])[1:], name)
        ax.set_ylabel(f"{m.name} error ({m.unit})")
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].legend(fontsize=8)
    axes[0, 0].set_title(f"{title}: errors")
    fig.tight_layout()
    files.append(plot_files(out, stem)[1])
    _save(plt, fig, files[-1])
    return files
