"""The `gpf` command: generate RTL, run models and simulations, lint, open waves.

Every user error (bad config, bad argument, missing tool) ends in one line on stderr and exit
status 2; a simulation or check that fails ends with status 1; an internal error (a bug) in one
line and status 3, its traceback with `gpf --debug`.
"""

from __future__ import annotations

import argparse
import os
import sys
import tomllib
from pathlib import Path
from typing import Any, NoReturn

from gpf.config import (
    APP_FORMATS,
    CONFIGS_DIR,
    WORD_BITS,
    ConfigError,
    config_path,
    load_config,
    shipped_configs,
)
from gpf.interrupt import Interrupted, stop_all_on_signal
from gpf.toolchain import ToolchainError, check_simulator, check_writable

EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_BUG = 3             # an internal error (a traceback with --debug)
BUILD = Path("build")
SEED_MAX = (1 << 32) - 1        # cocotb's and the scenarios' seeds (runs print 32-bit ones)
NEXTPNR_SEED_MAX = (1 << 31) - 1   # nextpnr's --seed is a C int
STEPS_MAX = 100_000             # as filter.steps
PARTICLES_MAX = 1 << 16         # as filter.particles
SAMPLES_MAX = 100_000_000


class UsageError(Exception):
    """Bad command-line input; str() is the one line shown."""


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        # argparse prints the whole usage block; one line is what scripts and people need
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


def parse_overrides(items: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or "." not in key:
            raise UsageError(f"--set {item!r}: expected SECTION.KEY=VALUE, e.g. filter.lanes=2")
        try:
            out[key.strip()] = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            out[key.strip()] = text  # a bare word is a string
    return out


def _config(args: argparse.Namespace):
    return load_config(config_path(args.config), parse_overrides(args.set))


def _rtl_config(args: argparse.Namespace):
    """The config, checked to generate (a valid config's derived datapath may not fit)."""
    cfg = _config(args)
    _check_generates(cfg)
    return cfg


def _check_generates(cfg) -> None:
    from gpf.rtl.generate import MODULES, modules_for

    try:
        for name in modules_for(cfg):
            MODULES[name].context(cfg)
    except (ValueError, ArithmeticError) as exc:
        raise ConfigError(f"{cfg.source or cfg.name}: the RTL of this config cannot be "
                          f"generated: {exc}") from None


def _range(name: str, value: int | None, lo: int, hi: int) -> None:
    if value is not None and not lo <= value <= hi:
        raise UsageError(f"{name} {value}: must be an integer in [{lo}, {hi}]")


def _check_word(word: int | None, cfg) -> None:
    """--word resizes the state and weight formats keeping their integer bits."""
    for name in (*APP_FORMATS[cfg.app], "weight"):
        fmt = cfg.formats[name]
        if word is not None and word < fmt.width - fmt.frac_bits:
            raise UsageError(f"--word {word}: narrower than the integer part of formats.{name} "
                             f"= '{fmt}' (needs at least {fmt.width - fmt.frac_bits} bits)")
    if word is not None:   # the datapath resized: its constants and sums as load_config's
        from gpf.limits import check_datapath

        check_datapath(cfg, word, prefix=f"{cfg.name}: ")


def _out_file(name: str, path: str) -> Path:
    """An output file the command writes at its end: checked before any work starts."""
    out = Path(path)
    if out.is_dir():
        raise UsageError(f"{name} {path}: is a folder; give a file name in it")
    check_writable(out.parent, f"choose another {name} or fix the folder's permissions")
    return out


def _out_dir(name: str, path: str | None) -> None:
    if path is not None:
        if Path(path).exists() and not Path(path).is_dir():
            raise UsageError(f"{name} {path}: is a file; give a folder")
        check_writable(Path(path), f"choose another {name} or fix the folder's permissions")


def _inputs(cfg, scenario: str | None = None) -> list[tuple[str, str | None]]:
    """The files a command reads: the config, a scenario CSV."""
    csv = scenario if scenario is not None and scenario.endswith(".csv") else None
    return [("the config", cfg.source or None), ("the scenario file", csv)]


def _no_clash(outputs: list[tuple[str, Any]], inputs: list[tuple[str, str | None]]) -> None:
    """Before any work: no output over an input (gpf.outputs.check_outputs), one line."""
    from gpf.outputs import OutputError, check_outputs

    try:
        check_outputs(outputs, inputs)
    except OutputError as exc:
        raise UsageError(str(exc)) from None


def _build_dir(cfg) -> Path:
    folder = BUILD / cfg.name
    check_writable(folder, "run gpf from the project folder as a user who can write build/, "
                   "or fix its permissions")
    return folder


def cmd_generate(args: argparse.Namespace) -> int:
    from gpf.rtl.generate import default_out_dir, generate

    cfg = _rtl_config(args)
    out_dir = Path(args.out) if args.out else default_out_dir(cfg)
    if out_dir.exists() and not out_dir.is_dir():
        raise UsageError(f"--out {out_dir}: is a file; give a folder")
    check_writable(out_dir, "choose another --out or fix the folder's permissions"
                   if args.out else "run gpf from a folder where it can write build/, or "
                   "give --out")
    from gpf.outputs import OutputError

    try:   # it renders first and refuses, before writing, a file name that is the config
        out = generate(cfg, out_dir)
    except OutputError as exc:
        raise UsageError(str(exc)) from None
    for files in out.files.values():
        for path in files:
            print(path)
    print(out.out_dir / "manifest.json")
    return 0


def cmd_model_grng(args: argparse.Namespace) -> int:
    import numpy as np

    from gpf.model.grng import GrngModel

    if args.samples < 1:
        raise UsageError(f"--samples {args.samples}: must be at least 1")
    _range("--samples", args.samples, 1, SAMPLES_MAX)
    _range("--seed", args.seed, 0, (1 << 64) - 1)   # a seed load: 64 bits, as grng.seed
    from gpf.outputs import atomic_path

    # numpy.save adds .npy to a name without it: that is the file written, checked, printed
    out = _out_file("--out", args.out)
    if not args.out.endswith(".npy"):
        out = _out_file("--out", f"{args.out}.npy")
    cfg = _config(args)
    _no_clash([("--out", out)], _inputs(cfg))
    samples = GrngModel(cfg).normals(args.samples, seed=args.seed)
    with atomic_path(out) as tmp:
        np.save(tmp, samples)
    print(f"{out}: {samples.shape[0]} x {samples.shape[1]} samples of {cfg.noise} "
          f"(seed {args.seed}), mean {samples.mean():+.5f}, std {samples.std():.5f}")
    return 0


def _scenario_arg(text: str | None, cfg=None):
    """A scenario name, or a CSV file (read once: every run filters the same data), checked
    against the config it is filtered with (gpf.limits)."""
    if text is None or not text.endswith(".csv"):
        return text
    from gpf.model.scenarios import read_csv

    try:
        return read_csv(text, cfg)
    except (OSError, ValueError) as exc:
        message = str(exc)   # the reader's messages start with the file's name
        raise UsageError(f"--scenario {message}" if message.startswith(f"{text}: ")
                         else f"--scenario {text}: {message}") from None


def _positive(name: str, value: int | None) -> None:
    if value is not None and value < 1:
        raise UsageError(f"{name} {value}: must be at least 1")


def cmd_model_run(args: argparse.Namespace) -> int:
    import numpy as np

    from gpf.study.montecarlo import monte_carlo
    from gpf.study.plots import plot_run

    for name in ("steps", "particles", "runs"):
        _positive(f"--{name}", getattr(args, name))
    _range("--steps", args.steps, 1, STEPS_MAX)
    _range("--seed", args.seed, 0, SEED_MAX)
    _range("--word", args.word, *WORD_BITS)
    out = _out_file("--json", args.json) if args.json else None
    _out_dir("--plot", args.plot)
    cfg = _config(args)
    from gpf.limits import check_particles, check_scenario_name

    check_particles(cfg, args.particles)   # as gpf run's: [2, filter.particles], x LANES
    check_scenario_name(cfg, args.scenario)
    _check_word(args.word, cfg)
    from gpf.outputs import write_json
    from gpf.study.montecarlo import DEFAULT_SCENARIO
    from gpf.study.plots import plot_files

    csv = args.scenario is not None and args.scenario.endswith(".csv")
    stem = f"{cfg.name}_{'file' if csv else args.scenario or DEFAULT_SCENARIO[cfg.app]}"
    _no_clash([*([("--json", out)] if out else []),
               *(("--plot", p) for p in (plot_files(args.plot, stem) if args.plot else []))],
              _inputs(cfg, args.scenario))
    scenario = _scenario_arg(args.scenario, cfg)
    try:
        if csv and args.steps is not None:    # a recording filtered in part: its first steps
            scenario = scenario.first(args.steps, args.scenario)
        mc = monte_carlo(cfg, runs=args.runs, steps=args.steps, particles=args.particles,
                         seed=args.seed, word=args.word, scenario=scenario)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    summary = mc.summary()
    label = Path(args.scenario).name if csv else mc.scenario
    if args.plot:
        first = {k: np.asarray(summary["per_step"][k], dtype=float) for k in ("float", "fixed")}
        est = {"truth": mc.truth[0], **first}
        runs = "1 run" if mc.runs == 1 else f"run 1 of {mc.runs}"
        summary["plots"] = plot_run(
            cfg.app, est, cfg.dt, f"gpf model run: {cfg.name}, {label}, N = {mc.particles}, "
            f"{runs}, seed {mc.seed}", args.plot, stem, mc.observer)
    if out:
        write_json(out, summary)   # strict: a value that could not be computed is null
    for line in model_run_lines(cfg.name, mc, summary, label):
        print(line)
    if out:
        print(f"  -> {out}")
    return 0


def model_run_lines(name: str, mc, summary: dict, scenario: str | None = None) -> list[str]:
    """`gpf model run`'s report: every metric (all steps, last 20 %), lost tracks, flags.
    Without truth (a recording) no error line: it says so once. One run has no spread."""
    from gpf.outputs import fmt

    lines = [f"{name} {scenario or mc.scenario}: {mc.runs} run{'' if mc.runs == 1 else 's'} x "
             f"{mc.steps} steps, N = {mc.particles}" + (f", word {mc.word}" if mc.word else "")]
    for metric, m in summary["metrics"].items():
        for window in ("all", "last20"):
            w = m[window]
            spread = " (1 run: spread n/a)" if mc.runs == 1 else \
                f" +- {fmt(w['ratio_std_error'], '.4f')}"
            lines.append(f"  {metric:8s} {'all steps' if window == 'all' else 'last 20 %':9s} "
                         f"RMSE ({m['unit']}): float {fmt(w['float'], '.5g')}, fixed "
                         f"{fmt(w['fixed'], '.5g')}, ratio {fmt(w['ratio'], '.4f')}{spread}; "
                         f"float on numpy's draws {fmt(w['float_numpy'], '.5g')}")
    if summary.get("lost_tracks") is not None:
        lines.append(f"  lost tracks (last 20 % > {summary['lost_factor']:g} x float64): "
                     f"{summary['lost_tracks']} of {mc.runs}"
                     + (f" (runs {summary['lost_runs']})" if summary["lost_runs"] else ""))
    else:
        lines.append("  no truth in the recording: errors not computed (RMSE n/a, ratio n/a, "
                     "lost tracks n/a)")
    q = summary.get("quantisation_max")
    if q is not None:
        lines.append(f"  fixed point vs float64 (same draws), {summary['primary_metric']} per "
                     f"step: max {fmt(q, '.3g')} {summary['rmse_unit']}")

    def counts(flags: dict[str, int]) -> str:
        return ", ".join(f"{k} {v}" for k, v in flags.items() if v) or "none"

    lines.append(f"  flagged steps, fixed point: {counts(summary['flag_steps'])}; float64: "
                 f"{counts(summary['float_flag_steps'])}; mean ESS fixed "
                 f"{fmt(summary['ess_mean']['fixed'], '.1f')}, float "
                 f"{fmt(summary['ess_mean']['float'], '.1f')}")
    return lines


def cmd_model_wordlength(args: argparse.Namespace) -> int:
    from gpf.outputs import fmt
    from gpf.study.metrics import METRICS
    from gpf.study.montecarlo import monte_carlo

    lo, _, rest = args.words.partition(":")
    hi, _, step = rest.partition(":")
    try:
        first, last, stride = int(lo), int(hi), int(step or 2)
    except ValueError:
        raise UsageError(f"--words {args.words!r}: expected FIRST:LAST[:STEP]") from None
    if not 12 <= first <= last <= WORD_BITS[1] or stride < 1:
        raise UsageError(f"--words {args.words!r}: widths must lie in [12, {WORD_BITS[1]}], "
                         "FIRST <= LAST, STEP >= 1")
    words = list(range(first, last + 1, stride))
    for name in ("runs", "steps", "particles"):
        _positive(f"--{name}", getattr(args, name))
    _range("--steps", args.steps, 1, STEPS_MAX)
    _range("--seed", args.seed, 0, SEED_MAX)
    cfgs = [load_config(config_path(name), parse_overrides(args.set))
            for name in args.config or ["bot", "uav"]]
    from gpf.limits import check_particles

    for cfg in cfgs:
        check_particles(cfg, args.particles)
        for word in words:
            _check_word(word, cfg)
    for cfg in cfgs:
        metrics = [m.name for m in METRICS[cfg.app][:3]]
        print(f"\n{cfg.name}: RMSE over the last 20 % of {args.runs} runs (all steps in "
              "brackets), float64 / fixed point / ratio")
        print("| word | " + " | ".join(metrics) + " | lost | flags (steps) |")
        print("|---" * (len(metrics) + 3) + "|")
        for word in words:
            mc = monte_carlo(cfg, runs=args.runs, steps=args.steps, particles=args.particles,
                             seed=args.seed, word=word)
            s = mc.summary()
            cells = []
            for name in metrics:
                m = s["metrics"][name]
                cells.append(f"{fmt(m['last20']['float'])} / {fmt(m['last20']['fixed'])} / "
                             f"{fmt(m['last20']['ratio'], '.3f')} "
                             f"({fmt(m['all']['ratio'], '.3f')})")
            flags = ", ".join(f"{k} {v}" for k, v in s["flag_steps"].items() if v) or "-"
            print(f"| {word} | " + " | ".join(cells) + f" | {s['lost_tracks']} | {flags} |",
                  flush=True)
    return 0


def _module(name: str, cfg) -> str:
    """A block `cfg` generates, or one clear line saying which would do."""
    from gpf.rtl.generate import MODULES

    if name not in MODULES:
        raise UsageError(f"--module {name!r}: unknown; choose one of {', '.join(MODULES)}")
    apps = MODULES[name].apps
    if cfg.app not in apps:
        raise UsageError(f"--module {name}: a block of the {'/'.join(apps)} filter; config "
                         f"{cfg.name!r} is {cfg.app} (e.g. CONFIG={apps[0]})")
    return name


def _check_gate_tools(gate: bool) -> None:
    """A gate-level run needs Yosys: said before any build, in one line."""
    if gate:
        from gpf.synth import yosys_command

        yosys_command()


def _hw_target(args: argparse.Namespace):
    """`gpf synth` and `gpf timing`: the config, the module (default: the whole filter)."""
    cfg = _rtl_config(args)
    module = _module(args.module or f"gpf_{cfg.app}", cfg)
    return cfg, module


def cmd_sim(args: argparse.Namespace) -> int:
    from gpf.sim import run_sim

    _range("--seed", args.seed, 0, SEED_MAX)
    cfg = _rtl_config(args)
    note = ""
    module = args.module
    if module is None:
        module = f"gpf_{cfg.app}"
        note = " (the whole filter's testbench; `gpf run` for a long run with a summary)"
    module = _module(module, cfg)
    check_simulator(args.sim, args.waves)
    _build_dir(cfg)
    gate = " gate-level netlist" if args.gate else ""
    print(f"gpf sim: {module}{gate} on {args.sim}, config {cfg.name}{note}", flush=True)
    _check_gate_tools(args.gate)
    if args.coverage:
        from gpf.sim import CODE_COVERAGE_ENV

        if args.sim != "verilator":
            raise UsageError("--coverage: Verilator only (its line and toggle counters)")
        os.environ[CODE_COVERAGE_ENV] = "1"
    result = run_sim(cfg, module, args.sim, waves=args.waves, seed=args.seed,
                     testcase=args.testcase, gate=args.gate)
    status = "PASSED" if result.passed else "FAILED"
    print(f"gpf sim: {module} on {args.sim}, config {cfg.name}: {result.tests - result.failed}"
          f"/{result.tests} tests passed, seed {result.seed} -> {status}")
    print(f"  results: {result.results_xml}")
    print(f"  SEED={result.seed} (replay: "
          f"{_make_command('sim', args, cfg, MODULE=module, SEED=result.seed)})")
    if result.waves:
        print(f"  waves:   {result.waves} ({_make_command('waves', args, cfg, MODULE=module)})")
    return 0 if result.passed else EXIT_FAILED


def _make_command(target: str, args: argparse.Namespace, cfg, **variables: Any) -> str:
    """The `make` line that repeats this run (the `gpf` one where make has no variable for an
    override)."""
    lanes = cfg.overrides.get("filter.lanes")
    others = {k: v for k, v in cfg.overrides.items() if k != "filter.lanes"}
    scenario, ip = getattr(args, "scenario", None), getattr(args, "ip", False)
    # make has no variable for these, and its Makefile is in the project folder: else the gpf
    # command
    if others or scenario or ip or Path.cwd().resolve() != CONFIGS_DIR.parent:
        command = "run" if target == "sim" and "MODULE" not in variables else target
        words = [f"gpf {command} --config {args.config}",
                 *(f"--set {k}={v}" for k, v in cfg.overrides.items())]
        flags = {"MODULE": "--module", "SEED": "--seed", "STEPS": "--steps",
                 "PARTICLES": "--particles"}
        words += [f"{flags[k]} {v}" for k, v in variables.items()]
        words += [f"--scenario {scenario}"] if scenario else []
        words += [f"--sim {args.sim}"] if args.sim != "verilator" else []
        words += ["--gate"] if getattr(args, "gate", False) else []
        words += ["--ip"] if ip else []
        words += ["--direct"] if getattr(args, "direct", False) else []
        return " ".join(words)
    words = [f"make {target}", f"CONFIG={args.config}"]
    if lanes is not None:
        words.append(f"LANES={lanes}")
    if args.sim != "verilator":
        words.append(f"SIM={args.sim}")
    words += [f"{k}={v}" for k, v in variables.items()]
    if getattr(args, "gate", False) and target == "sim":
        words.append("GATE=1")
    if getattr(args, "direct", False) and target == "sim":
        words.append("DIRECT=1")
    return " ".join(words)


def cmd_run(args: argparse.Namespace) -> int:
    from gpf.outputs import write_json
    from gpf.run import (
        RunArgs,
        SimulationError,
        plot,
        plot_paths,
        run_filter,
        run_warnings,
        summary_lines,
    )

    for name in ("steps", "particles"):
        _positive(f"--{name}", getattr(args, name))
    _range("--steps", args.steps, 1, STEPS_MAX)
    _range("--seed", args.seed, 0, SEED_MAX)
    out = _out_file("--json", args.json) if args.json else None
    _out_dir("--plot", args.plot)
    cfg = _rtl_config(args)
    from gpf.limits import check_particles, check_scenario_name

    particles = check_particles(cfg, args.particles)   # as gpf model run's
    scenario = args.scenario
    check_scenario_name(cfg, scenario)   # as gpf model run's
    steps = args.steps or cfg.steps
    if scenario is not None and scenario.endswith(".csv"):
        sc = _scenario_arg(scenario, cfg)
        if sc.app != cfg.app:
            raise UsageError(f"--scenario {scenario}: a {sc.app} scenario, config "
                             f"{cfg.name!r} is {cfg.app}")
        steps = sc.steps if args.steps is None else args.steps
        try:
            sc.first(steps, scenario)    # fewer: its first steps (run_filter); more: refused
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if args.ip and (args.gate or args.sim != "verilator"):
        raise UsageError("--ip: the IP block runs on Verilator, as RTL (not with --gate or "
                         "--sim icarus)")
    if args.direct and (args.ip or args.gate or args.waves or args.sim != "verilator"):
        raise UsageError("--direct: the core's RTL on Verilator without cocotb (not with --ip, "
                         "--gate, --waves or --sim icarus)")
    run_args = RunArgs(steps, particles, args.seed, scenario, args.sim, args.waves, args.gate,
                       args.ip, direct=args.direct)
    _no_clash([*([("--json", out)] if out else []),
               *(("--plot", p) for p in
                 (plot_paths(cfg, run_args, args.plot) if args.plot else []))],
              [*_inputs(cfg, scenario), ("the generated RTL in", BUILD / cfg.name / "rtl")])
    # here, not in the simulation's thread: a missing tool is one line, not a traceback
    check_simulator(args.sim, args.waves)
    _build_dir(cfg)
    _check_gate_tools(args.gate)
    try:
        res = run_filter(cfg, run_args)
    except SimulationError as exc:
        print(f"gpf run: FAILED: {exc}", file=sys.stderr)
        return EXIT_FAILED
    if args.plot:
        res["plots"] = plot(res, cfg, Path(args.plot))
    res["warnings"] = run_warnings(res)   # saturation, a lost track: beside the verdict
    if out:
        write_json(out, res)   # strict: a value that could not be computed is null
    for line in summary_lines(res):
        print(line)
    for path in res.get("plots", []):
        print(f"  plot: {path}")
    if res.get("waves"):
        hint = (f"gpf waves --config {args.config} --module gpf_{cfg.app}_axi" if args.ip
                else _make_command("waves", args, cfg))
        print(f"  waves:   {res['waves']} ({hint})")
    exact = res["passed"] and res["mismatches"] == 0
    ok = exact and not res["lost_track"]
    why = "" if ok else " (the RTL differs from the model)" if not exact else \
        " (bit-exact, but the filter lost track)"
    steps_given = {"STEPS": args.steps} if args.steps is not None else {}   # else the config's
    replay = _make_command("sim", args, cfg, **steps_given, PARTICLES=particles, SEED=args.seed)
    print(f"  SEED={args.seed} (replay: {replay})")
    print(f"  {f'-> {out}: ' if out else ''}{'PASSED' if ok else 'FAILED'}{why} "
          f"(log: {res['log']})")
    return 0 if ok else EXIT_FAILED


def cmd_lint(args: argparse.Namespace) -> int:
    from gpf.rtl.lint import lint_configs

    paths = [config_path(c) for c in args.config or shipped_configs()]
    # every config as written (its own lanes too, as every other command checks it), then at
    # every lane count, before the first lint starts
    for path in paths:
        _check_generates(load_config(path))
        for lanes in args.lanes or [1, 2, 4]:
            cfg = load_config(path, {"filter.lanes": lanes})
            _check_generates(cfg)
            _build_dir(cfg)
    from importlib.util import find_spec

    if find_spec("pyslang") is None:
        raise ToolchainError("pyslang not installed: run `make venv` (it installs the pinned "
                             "dev packages into .venv)")
    problems = lint_configs(paths, lanes=args.lanes)
    return EXIT_FAILED if problems else 0


def cmd_list(args: argparse.Namespace) -> int:
    from gpf.rtl.generate import MODULES

    for name in MODULES:
        print(name)
    return 0


def cmd_mutants(args: argparse.Namespace) -> int:
    from gpf.mutants import SIM, campaign, targets

    names = sorted({t.module for t in targets()})
    if args.module and args.module not in names:
        raise UsageError(f"--module {args.module!r}: choose one of {', '.join(names)}")
    if not 0 <= args.shard < args.shards:
        raise UsageError(f"--shard {args.shard}: choose 0 to {args.shards - 1} (--shards)")
    if args.sample is not None and args.sample < 1:
        raise UsageError(f"--sample {args.sample}: choose 1 or more")
    if not args.list:
        check_simulator(SIM, False)
    if args.survivors:
        from gpf.mutants import rerun_survivors

        if not Path(args.survivors).is_file():
            raise UsageError(f"--survivors {args.survivors}: no such report (report.json of "
                             "an earlier gpf mutants)")
        print(f"-> {rerun_survivors(Path(args.survivors), args.level, mark_only=args.mark_only)}")
        return 0
    command = "gpf mutants " + " ".join(sys.argv[2:] if len(sys.argv) > 2 else [])
    campaign(args.module, args.mutant, args.sample, args.seed, args.shards, args.shard,
             args.level, Path(args.out), args.list, command.strip())
    return 0


def cmd_limits(args: argparse.Namespace) -> int:
    """The README's "Inputs and their limits", from the code that checks them."""
    from gpf.config import limits_table

    print(limits_table(), end="")
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    from gpf.config import for_family
    from gpf.outputs import write_json
    from gpf.synth import SynthError, format_area, synthesize, yosys_command

    cfg, module = _hw_target(args)
    out = _out_file("--json", args.json) if args.json else None
    _no_clash([("--json", out)], [*_inputs(cfg), ("the generated RTL in",
                                                  BUILD / for_family(cfg, "xc7").name / "rtl")])
    _build_dir(cfg)
    yosys_command()     # installed, before the long part starts
    print(f"gpf synth: {module}, config {cfg.name}, LANES {cfg.lanes}: Yosys synth_xilinx "
          "-family xc7 (a whole filter takes minutes)", flush=True)
    try:
        area = synthesize(cfg, module)
    except SynthError as exc:
        print(f"gpf synth: FAILED: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_FAILED
    for line in format_area([area]):
        print(line)
    for warning in area.warnings:
        print(f"  yosys: {warning}")
    report = area.log.parent / "area.json"
    if out is not None:
        write_json(out, area.to_json())
        report = out
    print(f"  -> {report} (log: {area.log})")
    return 0


def cmd_timing(args: argparse.Namespace) -> int:
    from gpf.outputs import write_json
    from gpf.synth import SynthError, yosys_command
    from gpf.timing import nextpnr_command, place_and_route

    if not 1 <= args.freq <= 1000:
        raise UsageError(f"--freq {args.freq:g}: must lie in [1, 1000] MHz")
    _range("--seed", args.seed, 1, NEXTPNR_SEED_MAX)
    cfg, module = _hw_target(args)
    _build_dir(cfg)
    yosys_command()
    nextpnr_command()
    print(f"gpf timing: {module}, config {cfg.name}, LANES {cfg.lanes}: synth_ecp5 + "
          f"nextpnr-ecp5 (LFE5U-85F, out of context, target {args.freq:g} MHz); a whole filter "
          "takes tens of minutes", flush=True)
    try:
        t = place_and_route(cfg, module, target_mhz=args.freq,
                            timeout=args.timeout * 60 if args.timeout else None,
                            seed=args.seed, dsp_registers=not args.fabric_dsp_registers)
    except SynthError as exc:
        print(f"gpf timing: FAILED: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_FAILED
    report = t.log.parent / "timing.json"
    write_json(report, t.to_json())
    if t.dsp_registers:
        d = t.dsp_registers
        print(f"  DSP registers: {d['inputs']} operands and {d['outputs']} products of "
              f"{d['dsps']} MULT18X18D registered inside ({d['flops_removed']} flip-flops "
              "moved out of the fabric)")
    if t.bram_registers:
        r = t.bram_registers
        print(f"  block RAM registers: {r['ports']} of {r['rams']} DP16KD read with their output "
              f"register ({r['flops_removed']} flip-flops moved out of the fabric)")
    print(f"  Fmax {t.fmax_mhz:.1f} MHz (target {t.target_mhz:g}: "
          f"{'met' if t.fmax_mhz >= t.target_mhz else 'NOT met'})")
    print(f"  critical path: {t.path_from} -> {t.path_to}, {t.logic_cells} logic cells "
          "(each of a carry chain counts)")
    print(f"  late: {t.late} of {t.endpoints} register inputs arrive after "
          f"{1000 / t.target_mhz:.2f} ns")
    for name, count, worst in t.late_groups:
        print(f"    {name}: {count}, worst {worst:.2f} ns")
    used = ", ".join(f"{k} {u}/{a}" for k, (u, a) in t.utilisation.items())
    print(f"  ECP5 use: {used}")
    print(f"  -> {report} ({t.seconds:.0f} s; log: {t.log})")
    return 0


def cmd_coverage(args: argparse.Namespace) -> int:
    """Merge the runs' functional coverage (and the code coverage of COVERAGE=1 runs) into
    build/coverage/report.md; 1 if a hole has no reason (with --judge code: an unhit line only,
    the functional holes printed but not judged)."""
    from gpf import code_coverage, coverage

    cov_dir = Path(args.dir)
    rep = coverage.build_report(cov_dir, Path(args.holes))
    md, js = coverage.write_report(rep, cov_dir, Path(args.holes))
    print(rep.summary())
    for b in rep.unexplained:
        print(f"  hole without a reason: {b.key}")
    print(f"  -> {md}, {js}")
    code = code_coverage.report(cov_dir, Path(args.code_holes))
    if code is not None:
        print(code.summary())
        for line in code.unexplained:
            print(f"  line not hit and not explained: {line.where}")
        print(f"  -> {code.paths_text()}")
    if args.judge == "code" and rep.unexplained:
        print("  (functional holes not judged here: --judge code; the union of make regress's "
              "runs judges them)")
    failed = (args.judge == "all" and bool(rep.unexplained)) or bool(code and code.unexplained)
    return EXIT_FAILED if failed else 0


def cmd_waves(args: argparse.Namespace) -> int:
    from gpf.rtl.waves import open_waves

    cfg = _config(args)
    module = _module(args.module or f"gpf_{cfg.app}", cfg)
    return open_waves(cfg, module, args.sim, launch=not args.no_launch)


def _holes_default(name: str) -> Path:
    from gpf.coverage import HOLES

    return HOLES.parent / name


def build_parser() -> Parser:
    parser = Parser(prog="gpf", description=__doc__)
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an internal error (a bug in gpf)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    def with_config(p: argparse.ArgumentParser) -> None:
        p.add_argument("--config", default="bot",
                       help=f"a shipped config ({', '.join(shipped_configs())}) or a TOML "
                       "path (default: bot)")
        p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                       help="override one config value, e.g. filter.lanes=2 (repeatable)")

    def with_gate(p: argparse.ArgumentParser) -> None:
        p.add_argument("--gate", action="store_true", help="simulate the synthesized "
                       "gate-level netlist (Yosys) instead of the RTL")

    p = sub.add_parser("generate", help="write the SystemVerilog, file lists and manifest")
    with_config(p)
    p.add_argument("--out", help="output folder (default: build/<config>/rtl)")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("model", help="run a reference model")
    msub = p.add_subparsers(dest="model", required=True, parser_class=Parser)
    g = msub.add_parser("grng", help="normal samples from the bit-exact GRNG model (.npy)")
    with_config(g)
    g.add_argument("--samples", type=int, required=True, help="samples per lane")
    g.add_argument("--seed", type=int, default=None,
                   help="seed load as in the RTL (default: the config's reset seed)")
    g.add_argument("--out", required=True, help="output .npy: shape (samples, lanes), reals")
    g.set_defaults(func=cmd_model_grng)

    r = msub.add_parser("run", help="Monte Carlo runs of the fixed-point and float64 GPFs")
    with_config(r)
    r.add_argument("--steps", type=int, help="steps per run (default: the config's)")
    r.add_argument("--particles", type=int, help="N (default: the config's maximum)")
    r.add_argument("--runs", type=int, default=1,
                   help="Monte Carlo runs, each its own scenario and draws (default 1; judge "
                   "quality on 100 or more)")
    r.add_argument("--seed", type=int, default=1, help="run r uses seed + r")
    r.add_argument("--scenario", help="bot_fixed_observer (bot default), "
                   "bot_manoeuvring_observer, uav_flight (uav default), or a CSV file")
    r.add_argument("--word", type=int, help="resize every datapath word (word-length study)")
    r.add_argument("--plot", metavar="DIR", help="write PNGs of the first run there")
    r.add_argument("--json", metavar="OUT", help="also write the summary and per-step "
                   "results here (strict JSON: null where a value cannot be computed)")
    r.set_defaults(func=cmd_model_run)

    wl = msub.add_parser("wordlength", help="RMSE(fixed)/RMSE(float) per datapath word length")
    wl.add_argument("--config", action="append", default=[],
                    help="config (repeatable; default: bot and uav)")
    wl.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="override one config value (repeatable)")
    wl.add_argument("--words", default="14:28:2", help="FIRST:LAST[:STEP] (default 14:28:2)")
    wl.add_argument("--runs", type=int, default=20, help="Monte Carlo runs a word (default 20)")
    wl.add_argument("--steps", type=int, help="steps per run (default: the config's)")
    wl.add_argument("--particles", type=int, default=512, help="N (default 512)")
    wl.add_argument("--seed", type=int, default=1, help="run r uses seed + r (default 1)")
    wl.set_defaults(func=cmd_model_wordlength)

    p = sub.add_parser("sim", help="run a block's cocotb testbench")
    with_config(p)
    p.add_argument("--module", help="block to simulate (gpf list); default: the main job")
    p.add_argument("--sim", choices=["verilator", "icarus"], default="verilator",
                   help="simulator (default verilator)")
    p.add_argument("--waves", action="store_true", help="write an FST under build/")
    p.add_argument("--seed", type=int, help="replay a run (printed by every run)")
    p.add_argument("--testcase", help="run only this cocotb test")
    p.add_argument("--coverage", action="store_true", help="Verilator with line and toggle "
                   "coverage (its own build folder); `gpf coverage` reports it")
    with_gate(p)
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser("run", help="the whole filter in RTL, every particle checked against "
                       "the model")
    with_config(p)
    p.add_argument("--steps", type=int, help="filter steps (default: the config's)")
    p.add_argument("--particles", type=int, help="N (default: the config's maximum)")
    p.add_argument("--seed", type=int, default=1,
                   help="scenario seed and GRNG seed load (default 1)")
    p.add_argument("--scenario", help="bot_fixed_observer (bot default), "
                   "bot_manoeuvring_observer, uav_flight (uav default), or a CSV file")
    p.add_argument("--sim", choices=["verilator", "icarus"], default="verilator",
                   help="simulator (default verilator)")
    p.add_argument("--waves", action="store_true", help="write an FST under build/")
    p.add_argument("--plot", metavar="DIR", help="write PNGs of the estimates there")
    p.add_argument("--json", metavar="OUT", help="also write the summary, every estimate and "
                   "what was checked here (strict JSON: null where a value cannot be computed)")
    p.add_argument("--ip", action="store_true", help="through gpf_<app>_axi, the filter as an "
                   "IP block (seed and N over AXI4-Lite, byte-wide streams; Verilator)")
    p.add_argument("--direct", action="store_true", help="without cocotb: a Verilator binary "
                   "runs the steps, checked bit for bit as its records are written (several "
                   "times faster; no waves, coverage, --ip or --gate)")
    with_gate(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("synth", help="area of a block or a whole filter: Yosys synth_xilinx "
                       "(xc7), per block, as JSON")
    with_config(p)
    p.add_argument("--module", help="block (gpf list); default: the config's whole filter")
    p.add_argument("--json", metavar="OUT",
                   help="also write the report here (always: build/<config>/synth/<module>/"
                   "area.json)")
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser("timing", help="Fmax and critical path on an ECP5 (Yosys synth_ecp5, "
                       "nextpnr-ecp5)")
    with_config(p)
    p.add_argument("--module", help="block (gpf list); default: the config's whole filter")
    p.add_argument("--freq", type=float, default=125.0, help="target clock, MHz (default 125)")
    p.add_argument("--timeout", type=float, help="give up after this many minutes")
    p.add_argument("--seed", type=int, default=1,
                   help="nextpnr's placement seed (default 1; another seed places in "
                   "build/<config>/timing/<module>-seed<n>: several run side by side)")
    p.add_argument("--fabric-dsp-registers", action="store_true",
                   help="leave the multipliers' and block RAMs' registers in the fabric, as "
                   "synth_ecp5 maps them (default: moved into each MULT18X18D and DP16KD, as a "
                   "vendor flow does)")
    p.set_defaults(func=cmd_timing)

    p = sub.add_parser("lint", help="lint every generated file (Verilator, slang, Icarus)")
    p.add_argument("--config", action="append", default=[],
                   help="config to lint (repeatable; default: every shipped config)")
    p.add_argument("--lanes", type=int, action="append", choices=[1, 2, 4],
                   help="lane counts to generate (default: 1, 2 and 4)")
    p.set_defaults(func=cmd_lint)

    p = sub.add_parser("list", help="print every module name that `make sim MODULE=` accepts")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("mutants", help="mutation testing: mutants of the templates' literal "
                       "SystemVerilog, each against its block's testbench (Icarus)")
    p.add_argument("--module", help="only the mutants of this block or whole filter")
    p.add_argument("--mutant", action="append", help="only this mutant id (repeatable)")
    p.add_argument("--sample", type=int, help="a random subset of this many mutants")
    p.add_argument("--seed", type=int, default=1, help="the sample's seed (default 1)")
    p.add_argument("--shards", type=int, default=1, help="split the selection in k shards")
    p.add_argument("--shard", type=int, default=0, help="run shard i (from 0) of --shards")
    p.add_argument("--level", choices=["quick", "short", "default"], default="quick",
                   help="the block testbenches' first TEST_LEVEL (default quick: a fiftieth of "
                   "the random beats); a survivor runs again at each level after it, up to "
                   "default (a whole filter's mutants run at short)")
    p.add_argument("--out", default="build/mutants", help="report folder (default "
                   "build/mutants)")
    p.add_argument("--list", action="store_true", help="list the selected mutants, run none")
    p.add_argument("--survivors", metavar="REPORT_JSON", help="run the survivors of an "
                   "earlier report again (testbenches strengthened since) and update it")
    p.add_argument("--mark-only", action="store_true", help="with --survivors: run nothing, "
                   "mark the survivors from tests/data/mutants/equivalent.toml again")
    p.set_defaults(func=cmd_mutants)

    p = sub.add_parser("limits", help="print every input's validated range (the README's "
                       "\"Inputs and their limits\")")
    p.set_defaults(func=cmd_limits)

    p = sub.add_parser("coverage", help="merge the runs' functional and code coverage: "
                       "build/coverage/report.md, every bin and line, each hole's reason")
    p.add_argument("--dir", default="build/coverage", help="where the runs wrote theirs "
                   "(default build/coverage)")
    p.add_argument("--holes", default=str(_holes_default("holes.toml")),
                   help="the reviewed functional holes (bin pattern = reason)")
    p.add_argument("--code-holes", default=str(_holes_default("code_holes.toml")),
                   help="the reviewed unhit lines (file, text, reason)")
    p.add_argument("--judge", choices=("all", "code"), default="all",
                   help="what fails the command: every hole (default), or the code lines only "
                   "(make coverage-runs: its runs sample no block testbench, so the functional "
                   "union is make regress's to judge)")
    p.set_defaults(func=cmd_coverage)

    p = sub.add_parser("waves", help="open a module's last FST in GTKWave with a .gtkw")
    with_config(p)
    p.add_argument("--module", help="block (gpf list); default: the config's whole filter")
    p.add_argument("--sim", choices=["verilator", "icarus"], default="verilator",
                   help="simulator (default verilator)")
    p.add_argument("--no-launch", action="store_true", help="write the .gtkw, do not open it")
    p.set_defaults(func=cmd_waves)
    return parser


def _one_line(text: str) -> str:
    """A message with a user's newline (in a path, a --set value) still prints as one line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def main(argv: list[str] | None = None) -> int:
    try:
        for arg in sys.argv[1:] if argv is None else argv:
            if "\0" in arg:   # no path can hold it (only a caller from Python can pass it)
                raise UsageError(f"argument {arg!r}: contains a NUL byte")
        args = build_parser().parse_args(argv)
        with stop_all_on_signal():
            try:
                return args.func(args)
            except (UsageError, ConfigError, ToolchainError, OSError, KeyboardInterrupt):
                raise
            except Exception as exc:   # a bug, not the user's input: one line unless --debug
                if args.debug:
                    raise
                print(f"gpf: internal error: {type(exc).__name__}: {_one_line(str(exc))} (a "
                      "bug in gpf: `gpf --debug ...` shows where; please report it)",
                      file=sys.stderr)
                return EXIT_BUG
    except (UsageError, ConfigError, ToolchainError) as exc:
        print(f"gpf: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        # the checks above name the folder first; this is for a folder that changed since
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"gpf: error: {_one_line(f'{where}{exc.strerror or exc}')}: check the path and "
              "its permissions", file=sys.stderr)
        return EXIT_USAGE
    except Interrupted as exc:   # SIGINT or SIGTERM: the children stopped already
        print(f"gpf: stopped by {exc}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
