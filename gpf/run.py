"""`gpf run`: the whole filter in RTL under cocotb, every particle and estimate checked against
the fixed-point model, and a summary (JSON, plots) of what was checked, how fast and how well.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from gpf.config import Config
from gpf.outputs import fmt
from gpf.sim import run_sim, sim_build_dir


@dataclass(frozen=True)
class RunArgs:
    steps: int
    particles: int
    seed: int
    scenario: str | None
    sim: str
    waves: bool
    gate: bool = False      # the synthesized netlist instead of the RTL
    ip: bool = False        # through gpf_<app>_axi: AXI4-Lite registers, byte-wide streams
    bare: bool = False      # the harness alone, nothing checked: the simulator's own speed
    stall: float = 0.0      # each stream stalled (gaps in, tready low out) this often a clock
    direct: bool = False    # without cocotb: a Verilator binary, checked as it runs (direct.py)


def run_filter(cfg: Config, args: RunArgs, progress: bool = True,
               build_root: Path = Path("build"),
               template_dir: Path | None = None) -> dict[str, Any]:
    """Run gpf_<app>'s test_filter with these settings; return its results with the run's
    settings, wall time and speed added. `template_dir`: other templates (a mutant's), built
    in a `build_root` of their own: only the filter's modules are generated."""
    module = f"gpf_{cfg.app}_axi" if args.ip else f"gpf_{cfg.app}"
    if args.direct and (args.ip or args.gate or args.waves or args.sim != "verilator"):
        raise ValueError("a direct run is the core's RTL on Verilator, without waves")
    work = sim_build_dir((build_root / cfg.name).resolve(), args.sim,
                         module + ("_direct" if args.direct else ""),
                         "gate" if args.gate else None)
    work.mkdir(parents=True, exist_ok=True)
    out, progress_file = work / "run.json", work / "progress"
    for stale in (out, progress_file):
        stale.unlink(missing_ok=True)
    scenario = args.scenario
    if scenario and scenario.endswith(".csv"):
        scenario = str(_recording(Path(scenario), args.steps, work))
    spec = {"steps": args.steps, "particles": args.particles, "seed": args.seed,
            "scenario": scenario, "out": str(out), "progress": str(progress_file),
            "bare": args.bare, "stall": args.stall}
    log = build_root / cfg.name / (f"{module}-{args.sim}{'-gate' if args.gate else ''}"
                                   f"{'-direct' if args.direct else ''}.log")
    result: dict[str, Any] = {}

    def simulate() -> None:
        if args.direct:
            result["sim"] = run_direct(cfg, spec, build_root, log)
            return
        result["sim"] = run_sim(cfg, module, args.sim, waves=args.waves, seed=args.seed,
                                testcase="test_filter", extra_env={"GPF_RUN": json.dumps(spec)},
                                log_file=log, build_root=build_root, gate=args.gate,
                                template_dir=template_dir, all_modules=template_dir is None)

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
        if getattr(sim, "error", None):
            raise SimulationError(f"{sim.error} (see {log})")
        error = SimulationError if sim.failed else RuntimeError   # a check, or the tool
        raise error(f"the testbench wrote no results ({sim.failed}/{sim.tests} tests failed): "
                    f"see {log}")
    res = json.loads(out.read_text())
    wall = time.monotonic() - start
    from gpf.study.metrics import PRIMARY, metric

    primary = metric(cfg.app, PRIMARY[cfg.app])
    res.update(sim=sim_label(args), app=cfg.app, primary_metric=primary.name,
               rmse_unit=primary.unit,
               total_seconds=round(wall, 2), passed=sim.passed, log=str(log),
               particles_per_second=round(res["particles_checked"] / res["wall_seconds"], 1),
               waves=str(sim.waves) if sim.waves else None)
    return res


class SimulationError(RuntimeError):
    """A run that stopped on a check before its results (a hang, a protocol violation, a lost
    beat): the design's failure, not the tool's."""


@dataclass(frozen=True)
class DirectResult:
    """What a direct run reports in place of cocotb's results: passed, or why not."""

    passed: bool
    failed: int
    tests: int = 1
    waves: None = None
    error: str | None = None


def run_direct(cfg: Config, spec: dict[str, Any], build_root: Path, log: Path) -> DirectResult:
    """A cocotb-free run (gpf.tb.gpf.direct) with test_filter's checks: every value equal,
    every particle checked, each step's cycle count the period between results (no stalls)."""
    from gpf.tb.gpf import direct
    from gpf.tb.gpf.filter import RunSpec, write_result

    run_spec = RunSpec(**spec)
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("w") as f:
        try:
            res = direct.run(cfg, run_spec, build_root, log=f)
        except direct.DirectError as exc:
            f.write(f"FAILED: {exc}\n")
            return DirectResult(False, 1, error=str(exc))
        write_result(res, run_spec.out)
        why = ("mismatches" if res.mismatches else
               "particles not all checked" if res.particles_checked != res.steps * res.particles
               else "cycle counts differ from the period between results"
               if not run_spec.stall and res.period_per_step != res.cycles_per_step[1:] else None)
        f.write(f"{'FAILED: ' + why if why else 'PASSED'}: {res.particles_checked} particles, "
                f"{res.mismatches} mismatches\n")
    return DirectResult(why is None, int(why is not None), error=why)


def _recording(path: Path, steps: int, work: Path) -> Path:
    """The CSV the testbench reads (it filters a whole file): the recording itself, or, for
    fewer steps than it has, its first `steps` in a file of the same name in the run's build
    folder (exact: write_csv keeps every float's shortest repr and the metadata)."""
    from gpf.model.scenarios import read_csv, write_csv

    sc = read_csv(path)
    if steps >= sc.steps:
        return path.resolve()
    part = work / "recording" / path.name
    part.parent.mkdir(parents=True, exist_ok=True)
    write_csv(sc.first(steps), part)
    return part.resolve()


def sim_label(args: RunArgs) -> str:
    return args.sim + (" gate-level" if args.gate else "") + (" direct" if args.direct else "")


def plot_paths(cfg: Config, args: RunArgs, directory: str | Path) -> list[str]:
    """The files plot() may write for this run (checked against the inputs first)."""
    from gpf.study.plots import plot_files

    return plot_files(directory, f"{cfg.name}_{sim_label(args)}")


def _progress(path: Path) -> tuple[int, int] | None:
    try:
        step, mismatches = path.read_text().split()
        return int(step), int(mismatches)
    except (OSError, ValueError):
        return None


def _ranges(steps: list[int]) -> str:
    """[2, 3, 4, 5, 9] -> "2-5, 9"."""
    runs: list[list[int]] = []
    for k in steps:
        if runs and k == runs[-1][1] + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def run_warnings(res: dict[str, Any]) -> list[str]:
    """What a bit-exact run may still hide: saturated values (flag `sat` in any step's flags,
    step k = 1.. in order) and a lost track; one line each, for the summary and the JSON."""
    out = []
    sat = [k for k, flags in enumerate(res.get("flags") or [], start=1) if "sat" in flags]
    if sat:
        out.append(f"WARNING: values saturated at step{'s' if len(sat) > 1 else ''} "
                   f"{_ranges(sat)} (SAT): the fixed-point formats cannot hold this scenario")
    if res.get("lost_track"):
        out.append("WARNING: the filter lost track (its error over the last 20 % is above 3 x "
                   "float64's on the same draws)")
    return out


def summary_lines(res: dict[str, Any]) -> list[str]:
    cycles = res["cycles_per_step"]
    lines = [
        f"gpf run: {res['config']} on {res['sim']}, scenario {res['scenario']}, seed "
        f"{res['seed']}: {res['steps']} steps x {res['particles']} particles "
        f"({res['lanes']} lane(s))",
        f"  particles checked {res['particles_checked']} (conditioning, propagated, weight), "
        f"values checked {res['values_checked']}, mismatches {res['mismatches']}",
    ]
    for name, m in res["metrics"].items():
        lines.append(f"  {name} RMSE ({m['unit']}), all / last 20 %: " + ", ".join(
            f"{k} {fmt(m['all'][k])} / {fmt(m['last20'][k])}" for k in ("rtl", "fixed", "float")))
    quantisation = _known(res["quantisation_error"])
    unit = f" {res['rmse_unit']}" if res.get("rmse_unit") and quantisation else ""
    versus = (f"rtl vs float64 (same draws), {res.get('primary_metric', 'error')} per step: "
              f"max {fmt(max(quantisation, default=None), '.3g')}{unit}")
    if res["metrics"]:
        lines.append(f"  lost track (last 20 % > 3 x float64): "
                     f"{'YES' if res['lost_track'] else 'no'}; {versus}")
    else:
        lines += ["  no truth in the recording: errors not computed (RMSE n/a, lost track n/a)",
                  f"  {versus}"]
    ess = _known(res["ess"])
    flagged = {f: sum(f in flags for flags in res["flags"]) for f in
               ("sat", "zero_weights", "not_pd", "low_ess")}
    lines += [
        f"  effective sample size: mean {fmt(sum(ess) / len(ess) if ess else None, '.1f')}, "
        f"min {fmt(min(ess, default=None), '.1f')}; steps flagged: "
        + (", ".join(f"{k} {v}" for k, v in flagged.items() if v) or "none"),
        f"  cycles per step: min {min(cycles)}, max {max(cycles)} (N/LANES + "
        f"{max(cycles) - res['particles'] // res['lanes']})",
        f"  {res['particles_per_second']:.0f} particles checked/s ({res['wall_seconds']:.1f} s "
        f"simulating and checking, {res['total_seconds']:.1f} s with the build)",
    ]
    if res["first_mismatch"]:
        lines.append(f"  first mismatch: {res['first_mismatch']}")
    return lines + [f"  {w}" for w in run_warnings(res)]


def _known(values: list) -> list[float]:
    """The values that could be computed (null in JSON, NaN in memory: left out)."""
    return [v for v in values if v is not None and math.isfinite(v)]


def plot(res: dict[str, Any], cfg: Config, directory: Path) -> list[str]:
    """Truth against the RTL's, the fixed-point model's and the float64 model's estimates, and
    the errors (study.plots, as `gpf model run` draws them)."""
    import numpy as np

    from gpf.study.plots import plot_run

    est = {k: np.array([[np.nan] * len(res["estimates"]["float"][0]) if r is None else r
                        for r in v]) for k, v in res["estimates"].items() if k != "observer"}
    observer = res["estimates"].get("observer")
    title = (f"gpf run: {res['config']} on {res['sim']}, {res['scenario']}, N = "
             f"{res['particles']}, {res['steps']} steps, seed {res['seed']}")
    return plot_run(cfg.app, {k: est[k] for k in ("truth", "float", "fixed", "rtl")}, cfg.dt,
                    title, directory, f"{res['config']}_{res['sim']}",
                    None if observer is None else np.array(observer))
