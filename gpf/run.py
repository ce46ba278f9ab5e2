"""`gpf run`: the whole filter in RTL under cocotb, every particle and estimate checked against
the fixed-point model, and a summary (JSON, plots) of what was checked, how fast and how well.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from gpf.config import Config
from gpf.sim import run_sim


@dataclass(frozen=True)
class RunArgs:
    steps: int
    particles: int
    seed: int
    scenario: str | None
    sim: str
    waves: bool


def run_filter(cfg: Config, args: RunArgs, progress: bool = True,
               build_root: Path = Path("build")) -> dict[str, Any]:
    """Run gpf_<app>'s test_filter with these settings; return its results with the run's
    settings, wall time and speed added."""
    module = f"gpf_{cfg.app}"
    work = (build_root / cfg.name / args.sim / module).resolve()
    work.mkdir(parents=True, exist_ok=True)
    out, progress_file = work / "run.json", work / "progress"
    for stale in (out, progress_file):
        stale.unlink(missing_ok=True)
    spec = {"steps": args.steps, "particles": args.particles, "seed": args.seed,
            "scenario": str(Path(args.scenario).resolve()) if args.scenario and
            args.scenario.endswith(".csv") else args.scenario,
            "out": str(out), "progress": str(progress_file)}
    log = build_root / cfg.name / f"{module}-{args.sim}.log"
    result: dict[str, Any] = {}

    def simulate() -> None:
        result["sim"] = run_sim(cfg, module, args.sim, waves=args.waves, seed=args.seed,
                                testcase="test_filter", extra_env={"GPF_RUN": json.dumps(spec)},
                                log_file=log, build_root=build_root)

    start = time.monotonic()
    worker = threading.Thread(target=simulate, daemon=True)
    worker.start()
    bar = tqdm(total=args.steps, desc=f"{module} {cfg.name} N={args.particles} {args.sim}",
               unit="step", disable=None if progress else True)   # None: only on a terminal
    while worker.is_alive():
        worker.join(0.5)
        done = _progress(progress_file)
        if done is not None:
            bar.update(done[0] - bar.n)
            bar.set_postfix(mismatches=done[1])
    bar.close()
    if "sim" not in result:
        raise RuntimeError(f"the simulation did not run: see {log}")
    sim = result["sim"]
    if not out.exists():
        raise RuntimeError(f"the testbench wrote no results ({sim.failed}/{sim.tests} tests "
                           f"failed): see {log}")
    res = json.loads(out.read_text())
    wall = time.monotonic() - start
    res.update(sim=args.sim, total_seconds=round(wall, 2), passed=sim.passed, log=str(log),
               particles_per_second=round(res["particles_checked"] / res["wall_seconds"], 1),
               waves=str(sim.waves) if sim.waves else None)
    return res


def _progress(path: Path) -> tuple[int, int] | None:
    try:
        step, mismatches = path.read_text().split()
        return int(step), int(mismatches)
    except (OSError, ValueError):
        return None


def summary_lines(res: dict[str, Any]) -> list[str]:
    cycles = res["cycles_per_step"]
    rmse = res["rmse"]
    unit = "m" if "observer" in res["estimates"] else "deg"
    lines = [
        f"gpf run: {res['config']} on {res['sim']}, scenario {res['scenario']}, seed "
        f"{res['seed']}: {res['steps']} steps x {res['particles']} particles "
        f"({res['lanes']} lane(s))",
        f"  particles checked {res['particles_checked']} (conditioning, propagated, weight), "
        f"values checked {res['values_checked']}, mismatches {res['mismatches']}",
        f"  RMSE ({unit}) rtl {rmse['rtl']:.6g}, fixed {rmse['fixed']:.6g}, float "
        f"{rmse['float']:.6g}; rtl vs float64 (same draws) per step: max "
        f"{max(res['quantisation_error']):.3g} {unit}",
        f"  cycles per step: min {min(cycles)}, max {max(cycles)} (N/LANES + "
        f"{max(cycles) - res['particles'] // res['lanes']})",
        f"  {res['particles_per_second']:.0f} particles checked/s ({res['wall_seconds']:.1f} s "
        f"simulating and checking, {res['total_seconds']:.1f} s with the build)",
    ]
    if res["first_mismatch"]:
        lines.append(f"  first mismatch: {res['first_mismatch']}")
    return lines


def plot(res: dict[str, Any], directory: Path) -> list[str]:
    """Truth against the RTL's, the fixed-point model's and the float64 model's estimates, and
    the error per step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from gpf.model.study import error_per_step

    directory.mkdir(parents=True, exist_ok=True)
    est = {k: np.array(v) for k, v in res["estimates"].items()}
    app = "bot" if "observer" in est else "uav"
    stem = f"{res['config']}_{res['sim']}"
    files = []
    fig, ax = plt.subplots(figsize=(7, 5))
    if app == "bot":
        ax.plot(est["truth"][:, 0], est["truth"][:, 2], "k-", label="truth")
        for name, style in (("float", "b--"), ("fixed", "g-."), ("rtl", "r:")):
            ax.plot(est[name][:, 0], est[name][:, 2], style, label=name)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    else:
        t = np.arange(len(est["truth"]))
        for i in range(4):
            ax.plot(t, est["truth"][:, i], "k-", lw=1, label="truth" if i == 0 else None)
            ax.plot(t, est["rtl"][:, i], "r:", label="rtl" if i == 0 else None)
        ax.set_xlabel("step")
        ax.set_ylabel("attitude quaternion")
    ax.set_title(f"{res['config']}: {res['steps']} steps, N = {res['particles']} "
                 f"({res['sim']})")
    ax.legend()
    files.append(str(directory / f"{stem}_estimate.png"))
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 4))
    for name, style in (("float", "b-"), ("fixed", "g-."), ("rtl", "r:")):
        ax.plot(error_per_step(app, est[name], est["truth"]), style, label=name)
    ax.set_xlabel("step")
    ax.set_ylabel("position error (m)" if app == "bot" else "attitude error (deg)")
    ax.legend()
    files.append(str(directory / f"{stem}_error.png"))
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)
    return files
