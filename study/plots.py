"""Figures of one run's estimates, the same for `gpf model run` (its first Monte Carlo run) and
`gpf run` (the RTL beside both models), in one style: every filter keeps its colour, line
style and marker in every figure, time is in seconds, every axis is labelled with its unit,
every figure has a title and one legend outside the axes.

estimate (always): bot, the track (truth, estimates, the observer; start and end marked) and
    each state's difference from the float64 filter on the same draws (x, y in m, vx, vy in
    m/s); uav, roll, pitch and yaw (deg) and the ENU velocity (m/s), each beside its difference
    from float64. The differences are the quantisation error: drawn on top of each other, the
    estimates hide it (it is centimetres, the track metres).
error (only with truth): the error of each filter against the truth, per metric (bot position;
    uav tilt, heading, velocity). A recording without truth gets no error figure and no
    "truth" in any legend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gpf.outputs import atomic_path
from gpf.study.metrics import METRICS, euler_deg

# colour, line style, marker (RTL: markers, so that it shows where it lies on the fixed-point
# model's line, as a bit-exact run does)
STYLE = {"truth": ("k", "-", None), "float": ("tab:blue", "--", None),
         "fixed": ("tab:green", "-.", None), "rtl": ("tab:red", ":", "x"),
         "float_numpy": ("tab:gray", "--", None)}
LABEL = {"truth": "truth", "float": "float64", "fixed": "fixed point", "rtl": "RTL",
         "float_numpy": "float64, numpy draws"}
OBSERVER = {"color": "tab:orange", "marker": "^", "ms": 3.5, "lw": 0.7, "alpha": 0.75}
KINDS = ("estimate", "error")
DPI = 110


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")   # files only, no display needed
    import matplotlib.pyplot as plt

    return plt


def _kw(name: str, rows: int) -> dict[str, Any]:
    colour, style, marker = STYLE[name]
    kw: dict[str, Any] = {"color": colour, "linestyle": style, "label": LABEL[name], "lw": 1.3}
    if marker:
        kw.update(marker=marker, ms=5, markevery=max(1, rows // 25))
    return kw


def _line(ax: Any, t: np.ndarray, y: np.ndarray, name: str) -> None:
    ax.plot(t, y, **_kw(name, len(t)))


def _legend(fig: Any, names: list[str], observer: bool = False) -> None:
    """One legend for the whole figure, below the axes: it covers no data."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], **_kw(name, 1)) for name in names]
    if observer:
        handles.append(Line2D([], [], label="observer", **OBSERVER))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=9,
               frameon=False)


def plot_files(directory: str | Path, stem: str) -> list[str]:
    """Every file plot_run(..., directory, stem) may write (the error figure needs truth)."""
    return [str(Path(directory) / f"{stem}_{kind}.png") for kind in KINDS]


def _save(plt: Any, fig: Any, path: str) -> None:
    """A temporary file renamed into place when complete (gpf.outputs)."""
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=DPI)
    finally:
        plt.close(fig)


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


def has_truth(est: dict[str, np.ndarray]) -> bool:
    """Truth known at every step k >= 1 (row 0 may lack it)."""
    return "truth" in est and bool(np.all(np.isfinite(np.asarray(est["truth"], float)[1:])))


def run_figures(app: str, est: dict[str, np.ndarray], dt: float, title: str,
                observer: np.ndarray | None = None) -> dict[str, Any]:
    """The figures (kind -> matplotlib Figure, KINDS order) of the estimates in `est`: rows
    k = 0..steps per filter ("truth" first if known, NaN where not; "float" required)."""
    plt = _pyplot()
    est = {k: np.asarray(v, dtype=float) for k, v in est.items()}
    truth = has_truth(est)
    shown = [k for k in est if k != "truth" or truth]
    others = [k for k in shown if k not in ("truth", "float")]   # against float64
    t = np.arange(len(est["float"])) * dt
    if "rtl" in est and "fixed" in est and np.array_equal(est["rtl"], est["fixed"],
                                                          equal_nan=True):
        title += " (RTL = fixed point, bit for bit)"
    figs = {"estimate": (_bot_estimate if app == "bot" else _uav_estimate)(
        plt, est, t, shown, others, title, observer)}
    if truth:
        figs["error"] = _errors(plt, app, est, t, [k for k in shown if k != "truth"], title)
    return figs


def plot_run(app: str, est: dict[str, np.ndarray], dt: float, title: str, directory: str | Path,
             stem: str, observer: np.ndarray | None = None) -> list[str]:
    """PNG files of run_figures(...) in `directory` (named as plot_files); returns their paths.
    A figure this run has not (the errors of a recording without truth) is removed if an
    earlier run left one under its name: the folder shows this run only."""
    plt = _pyplot()
    Path(directory).mkdir(parents=True, exist_ok=True)
    paths = dict(zip(KINDS, plot_files(directory, stem), strict=True))
    figs = run_figures(app, est, dt, title, observer)
    for kind, fig in figs.items():
        _save(plt, fig, paths[kind])
    for kind in set(KINDS) - set(figs):
        Path(paths[kind]).unlink(missing_ok=True)
    return [paths[kind] for kind in figs]


def _bot_estimate(plt: Any, est: dict[str, np.ndarray], t: np.ndarray, shown: list[str],
                  others: list[str], title: str, observer: np.ndarray | None) -> Any:
    fig = plt.figure(figsize=(13, 6.5), layout="constrained")
    grid = fig.add_gridspec(2, 3, width_ratios=(1.6, 1, 1))
    ax = fig.add_subplot(grid[:, 0])
    for name in shown:
        kw = _kw(name, len(t))
        ax.plot(est[name][:, 0], est[name][:, 2], **kw)
        ax.plot(est[name][0, 0], est[name][0, 2], "o", color=kw["color"], ms=5)
    if observer is not None and len(observer):
        obs = np.asarray(observer, dtype=float)
        ax.plot(obs[:, 0], obs[:, 1], label="observer", **OBSERVER)
        seen = obs[np.all(np.isfinite(obs), axis=1)]
        if len(seen):
            ax.plot(seen[0, 0], seen[0, 1], "o", color=OBSERVER["color"], ms=5)
    ref = est["truth" if "truth" in shown else "float"]
    for row, text in ((0, f"t = {t[0]:g} s"), (-1, f"t = {t[-1]:g} s")):
        ax.annotate(text, (ref[row, 0], ref[row, 2]), xytext=(6, -10), textcoords="offset points",
                    fontsize=8)
    ax.set(xlabel="x (m)", ylabel="y (m)", title="track (o: start)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    diff = {}
    for i, (col, what, unit) in enumerate(((0, "x", "m"), (2, "y", "m"), (1, "vx", "m/s"),
                                           (3, "vy", "m/s"))):
        d = fig.add_subplot(grid[i // 2, 1 + i % 2], sharex=diff.get(0))
        diff[i] = d
        for name in others:
            _line(d, t, est[name][:, col] - est["float"][:, col], name)
        d.set(ylabel=f"{what} difference ({unit})", title=f"{what} minus float64")
        _small_numbers(d)
        if i >= 2:
            d.set_xlabel("time (s)")
    fig.suptitle(f"{title}\nestimates, and their difference from float64 on the same draws "
                 "(quantisation)")
    _legend(fig, shown, observer is not None and len(observer) > 0)
    return fig


def _uav_estimate(plt: Any, est: dict[str, np.ndarray], t: np.ndarray, shown: list[str],
                  others: list[str], title: str, observer: np.ndarray | None) -> Any:
    fig, axes = plt.subplots(3, 4, figsize=(17, 8.5), sharex=True, layout="constrained")
    angles = {k: euler_deg(est[k]) for k in shown}
    ref = angles["float"]
    # yaw drawn continuous through +-180 deg: float64's unwrapped, the others near it
    ref_yaw = np.degrees(np.unwrap(np.radians(ref[:, 2])))
    for a in angles.values():
        a[:, 2] = ref_yaw + _wrap_deg(a[:, 2] - ref[:, 2])
    columns = (("attitude", "deg"), ("attitude minus float64", "deg"),
               ("velocity (ENU)", "m/s"), ("velocity minus float64", "m/s"))
    for j, (what, _) in enumerate(columns):
        axes[0, j].set_title(what)
    for i, what in enumerate(("roll", "pitch", "yaw")):
        for name in shown:
            _line(axes[i, 0], t, angles[name][:, i], name)
        for name in others:
            _line(axes[i, 1], t, _wrap_deg(angles[name][:, i] - ref[:, i]), name)
        axes[i, 0].set_ylabel(f"{what} (deg)")
        axes[i, 1].set_ylabel(f"{what} difference (deg)")
    for i, what in enumerate(("v east", "v north", "v up")):
        for name in shown:
            _line(axes[i, 2], t, est[name][:, 4 + i], name)
        for name in others:
            _line(axes[i, 3], t, est[name][:, 4 + i] - est["float"][:, 4 + i], name)
        axes[i, 2].set_ylabel(f"{what} (m/s)")
        axes[i, 3].set_ylabel(f"{what} difference (m/s)")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    for ax in axes[:, (1, 3)].flat:
        _small_numbers(ax)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"{title}\nattitude (roll, pitch, yaw) and velocity, and their difference from "
                 "float64 on the same draws (quantisation)")
    _legend(fig, shown)
    return fig


def _errors(plt: Any, app: str, est: dict[str, np.ndarray], t: np.ndarray, names: list[str],
            title: str) -> Any:
    metrics = METRICS[app][:3]
    fig, axes = plt.subplots(len(metrics), 1, figsize=(10, 2.4 * len(metrics) + 1.4),
                             sharex=True, squeeze=False, layout="constrained")
    for ax, m in zip(axes[:, 0], metrics, strict=True):
        for name in names:
            _line(ax, t[1:], m.error(est[name], est["truth"])[1:], name)
        ax.set_ylabel(f"{m.name} error ({m.unit})")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(f"{title}\nerror against the truth")
    _legend(fig, names)
    return fig


def _small_numbers(ax: Any) -> None:
    """Differences of a few LSBs: a shared power of ten above the axis, not 0.00012 ticks."""
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3), useMathText=True)
