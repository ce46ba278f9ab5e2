"""Running a block's cocotb testbench on Verilator or Icarus, each config in its own folder.

build/<config>/rtl/              generated SystemVerilog, file lists, manifest.json
build/<config>/<sim>/<module>/   simulator build, results.xml, sim.log
build/<config>/<sim>/<module>-waves/   the same, built with waves: <module>.fst and its .gtkw
build/<config>/<sim>/<module>-coverage/   Verilator with line and toggle coverage (its coverage.dat)
build/coverage/func/<test>.yml   each run's functional coverage (tb/coverage.py; gpf coverage)
build/coverage/code/dat/<test>.dat   each coverage build's run (gpf/code_coverage.py)
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from gpf.config import Config
from gpf.outputs import atomic_write_text
from gpf.rtl.generate import MODULES, TEMPLATE_DIR, generate
from gpf.toolchain import check_simulator, use_bundled_verilator, verilator_root, verilator_version

SIMULATORS = ("verilator", "icarus")
# C++ optimisation of the Verilated model (Verilator's default is -Os). Once the harness ran the
# streams (gpf_<app>_harness), the model set the pace: the whole bot filter, N = 2048, 100
# steps, the harness alone with no cocotb, took 1.13 s of CPU at -O1, 0.66 s at -O2, 0.60 s at
# -O3, 1.15 s at -Os; -O2 builds in 18 s, -O1 in 14 s. (Measured before, with cocotb's
# per-clock work setting the pace, on the uav filter: -O1 32 s and 5400 particles/s, -Os 45 s
# and 5200/s, -O0 23 s and 1900/s.) GPF_VERILATOR_OPT overrides it.
VERILATOR_OPT = "-O2"


@dataclass(frozen=True)
class SimResult:
    module: str
    sim: str
    seed: int
    tests: int
    failed: int
    results_xml: Path
    waves: Path | None

    @property
    def passed(self) -> bool:
        return self.tests > 0 and self.failed == 0


@contextmanager
def _make_variables(**variables: str) -> Iterator[None]:
    """Variables for the `make` the cocotb runner calls (MAKEFLAGS entries override the
    makefile's own assignments, as command-line ones do)."""
    old = os.environ.get("MAKEFLAGS")
    extra = " ".join(f"{k}={v}" for k, v in variables.items())
    os.environ["MAKEFLAGS"] = f"{old} {extra}" if old else extra
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MAKEFLAGS", None)
        else:
            os.environ["MAKEFLAGS"] = old


def _forget_objects_built_otherwise(build_dir: Path, opt: str) -> None:
    """make does not see a changed OPT_FAST: drop the model's objects built with another."""
    stamp = build_dir / ".opt_fast"
    if stamp.exists() and stamp.read_text() != opt:
        for obj in build_dir.glob("Vtop*.o"):
            obj.unlink()
    atomic_write_text(stamp, opt)


# Verilator's runtime (verilated.cpp, verilated_vpi.cpp, ...) is the same for every model built
# with the same switches, yet each build folder compiled it anew: half of a block's build time.
# The first build of a set of switches keeps its objects, partly linked into one; later builds
# link that (LOADLIBES) and build none (VM_GLOBAL_*: empty). It lives in build/ whatever the
# build root, so that tests building elsewhere share it too; GPF_VERILATOR_RUNTIME names another
# folder (the test suite's own build/, for the gpf it runs from other folders).
RUNTIME_CACHE = Path("build") / ".verilator-runtime"
RUNTIME_OBJECT = "verilated_runtime.o"


# switches that change the generated model and never the runtime's objects (with the number of
# values each takes): left out of the runtime's key, so a netlist's build shares the RTL's
MODEL_ONLY_SWITCHES = {"--output-split": 1, "--output-split-cfuncs": 1, "--x-assign": 1,
                       "--x-initial": 1}


def _runtime_switches(build_args: list[str]) -> list[str]:
    """The switches that may change the runtime's objects (tracing, coverage, timing, threads:
    anything not known to be the model's alone; warnings are the model's)."""
    kept, skip = [], 0
    for arg in build_args:
        if skip:
            skip -= 1
        elif arg in MODEL_ONLY_SWITCHES:
            skip = MODEL_ONLY_SWITCHES[arg]
        elif not arg.startswith("-W"):
            kept.append(arg)
    return kept


def _runtime_cache(build_args: list[str]) -> Path:
    """The folder for the runtime of this Verilator, these switches and this compiler."""
    build_args = _runtime_switches(build_args)
    root = verilator_root()
    config_h = root / "include" / "verilated_config.h" if root else None
    key = json.dumps([str(root), config_h.read_text() if config_h and config_h.exists() else "",
                      shutil.which("verilator"), verilator_version(), build_args,
                      shutil.which(os.environ.get("CXX", "g++")),
                      *(os.environ.get(v, "") for v in ("CXXFLAGS", "CPPFLAGS", "OPT_GLOBAL"))])
    cache = Path(os.environ.get("GPF_VERILATOR_RUNTIME") or RUNTIME_CACHE)
    return cache.resolve() / hashlib.sha256(key.encode()).hexdigest()[:16]


def _runtime_variables(cache: Path) -> dict[str, str]:
    """make variables that link the cached runtime instead of building it (none without one,
    or where a space in the path would split make's variable)."""
    runtime = cache / RUNTIME_OBJECT
    if not runtime.exists() or any(c.isspace() for c in str(runtime)):
        return {}
    return {"VM_GLOBAL_FAST": "", "VM_GLOBAL_SLOW": "", "LOADLIBES": str(runtime)}


def _keep_runtime(cache: Path, build_dir: Path) -> None:
    """Link a build's runtime objects into one for the next builds (renamed into place: builds
    running side by side under pytest -n never see half of one)."""
    objects = sorted(str(o) for o in build_dir.glob("verilated*.o"))
    if (cache / RUNTIME_OBJECT).exists() or not objects:
        return
    tmp = cache.parent / f"{cache.name}.{os.getpid()}"
    try:
        cache.parent.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        subprocess.run(["ld", "-r", "-o", str(tmp / RUNTIME_OBJECT), *objects], check=True,
                       capture_output=True)
        tmp.rename(cache)
    except (OSError, subprocess.CalledProcessError):   # another build kept one first, no ld,
        shutil.rmtree(tmp, ignore_errors=True)           # or build/ not writable: no cache


def sim_build_dir(config_dir: Path, sim: str, module: str, netlist: str | None = None,
                  waves: bool = False, code_coverage: bool = False) -> Path:
    """build/<config>/<sim>/<module>, or <sim>-<netlist kind>/ for a netlist (gate, gate-mutant);
    <module>-waves/ for a build with waves, so that switching waves on and off rebuilds neither
    (a model built with tracing is another model); <module>-coverage/ for one with Verilator's
    coverage counters (and -waves-coverage/ with both)."""
    return config_dir / (f"{sim}-{netlist}" if netlist else sim) / \
        (module + ("-waves" if waves else "") + ("-coverage" if code_coverage else ""))


CODE_COVERAGE_ENV = "GPF_CODE_COVERAGE"   # set (make COVERAGE=1): every Verilator run counts
COVERAGE_ARGS = ["--coverage-line", "--coverage-toggle"]


def code_coverage_wanted(sim: str) -> bool:
    return sim == "verilator" and os.environ.get(CODE_COVERAGE_ENV, "") not in ("", "0")


def coverage_name(cfg: Config, module: str, sim: str, seed: int, testcase: str | None) -> str:
    """A file name for one run's coverage: the pytest test that ran it (if any), the module,
    the config, the simulator, the seed and the test cases."""
    test = os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" ", 1)[0]
    test = test.split("::", 1)[-1] if test else "gpf"
    name = f"{test}--{module}-{cfg.name}-{sim}-seed{seed}" + (f"-{testcase}" if testcase else "")
    return re.sub(r"[^A-Za-z0-9_.,=+-]+", "_", name)[:200]


def test_module(module: str) -> str:
    return MODULES[module].testbench or f"gpf.tb.{module}.test_{module}"


def run_sim(cfg: Config, module: str, sim: str = "verilator", *, waves: bool = False,
            seed: int | None = None, testcase: str | None = None,
            extra_env: dict[str, str] | None = None,
            template_dir: Path | None = None, build_root: Path = Path("build"),
            log_file: Path | None = None, verilator_opt: str | None = None,
            gate: bool = False, netlist: Path | None = None,
            all_modules: bool = True) -> SimResult:
    """Generate the RTL, build it for `sim` and run the module's cocotb tests.

    `template_dir` and `build_root` let a test simulate mutated templates out of the way.
    With `log_file` the simulator's output goes there instead of the terminal.
    `verilator_opt`: the model's C++ optimisation (GPF_VERILATOR_OPT, if set, wins; default
    VERILATOR_OPT): -O0 where the build costs more than the run.
    `gate`: simulate the module's synthesized netlist (gpf.synth.gate_netlist), or `netlist`
    if given, with the same testbench and model.
    `all_modules=False`: generate the module (and those it uses) only, a tenth of the time: for
    a build root no other run shares (a mutant's), as the manifest then lists that module only.
    """
    if module not in MODULES:
        raise ValueError(f"unknown module {module!r}: choose one of {', '.join(MODULES)}")
    if cfg.app not in MODULES[module].apps:
        raise ValueError(f"module {module!r} belongs to the {'/'.join(MODULES[module].apps)} "
                         f"filter, not to config {cfg.name!r} (app {cfg.app})")
    if not MODULES[module].simulated:
        raise ValueError(f"module {module!r} is an example top for synthesis (gpf synth), "
                         "with no testbench")
    if sim == "icarus" and MODULES[module].icarus_gap:
        raise ValueError(f"module {module!r} runs on Verilator only: {MODULES[module].icarus_gap}")
    check_simulator(sim, waves)
    use_bundled_verilator()
    from cocotb_tools.runner import get_results, get_runner  # after PATH holds Verilator

    if seed is None:
        seed = int.from_bytes(os.urandom(4), "little")
    # coverage counts the shipped templates only (a mutant's run is not the design's)
    shipped = template_dir is None or Path(template_dir).resolve() == TEMPLATE_DIR.resolve()
    code_coverage = code_coverage_wanted(sim) and shipped and not gate and netlist is None
    cov_name = coverage_name(cfg, module, sim, seed, testcase)
    config_dir = (build_root / cfg.name).resolve()
    # every module, so the manifest is whole whichever module runs (runs share the folder)
    generated = generate(cfg, config_dir / "rtl", template_dir=template_dir or TEMPLATE_DIR,
                         **({} if all_modules else {"modules": [module]}))
    sources = generated.files[module]
    gate = gate or netlist is not None
    if gate:
        from gpf.synth import gate_netlist

        sources = [netlist or gate_netlist(cfg, module, build_root)]
    # a mutant's netlist (gate-mutant/) builds beside the real one's (gate/)
    build_dir = sim_build_dir(config_dir, sim, module,
                              sources[0].parent.parent.name if gate else None, waves=waves,
                              code_coverage=code_coverage)
    build_dir.mkdir(parents=True, exist_ok=True)
    top = MODULES[module].top
    # the testbench's harness around the top is the toplevel; not around a netlist (Verilator
    # 5.049 stopped on an internal error, a name hash, building the two together)
    harness = None if gate else generated.harnesses.get(module)
    if harness:
        sources = [*sources, harness]
        top = MODULES[module].harness
    runner = get_runner(sim)
    build_args = []
    if sim == "verilator":
        # one C++ file: the bundled verilated.mk cannot link a model split into several
        # (its precompiled-header flags are empty)
        build_args = ["--output-split", "0", "--output-split-cfuncs", "0"]
        # cocotb's runner makes every signal of the design public (--public-flat-rw): a model
        # several times the size, to compile and to run. The testbenches touch the toplevel's
        # ports only (waves trace every signal either way)
        build_args += ["--no-public-flat-rw", "--public-depth", "1"]
        if harness:   # it runs its own clock: timing, whose C++ coroutines g++ 12 enables only
            # with -fcoroutines (the bundled Verilator's makefile passes none)
            build_args += ["--timing", "-CFLAGS", "-fcoroutines"]
        if waves:
            build_args += ["--trace-fst", "--trace-structs"]
        if code_coverage:
            build_args += COVERAGE_ARGS
        if gate:
            # a netlist's bit-blasted vectors look circular to Verilator: a speed warning only
            # (Yosys `check -assert` has already refused real combinational loops). Every flop
            # starts random, as hardware does: a design that leans on an initial value fails.
            build_args += ["-Wno-UNOPTFLAT", "--x-assign", "unique", "--x-initial", "unique"]
    # a netlist's C++ is many times the RTL's: -O1 took g++ over 5 min and 4 GB on moments
    opt = os.environ.get("GPF_VERILATOR_OPT") or verilator_opt or ("-O0" if gate
                                                                    else VERILATOR_OPT)
    if sim == "verilator":
        _forget_objects_built_otherwise(build_dir, opt)
        runtime = _runtime_cache(build_args)
    variables = _runtime_variables(runtime) if sim == "verilator" else {}
    with _make_variables(OPT_FAST=opt, **variables):
        runner.build(sources=sources, hdl_toplevel=top, build_dir=build_dir,
                     always=True, waves=waves, build_args=build_args,
                     timescale=("1ns", "1ps"), log_file=log_file)
    if sim == "verilator":
        _keep_runtime(runtime, build_dir)
    waves_file = build_dir / f"{module}.fst"
    env = {
        "GPF_CONFIG": str(Path(cfg.source).resolve()),
        "GPF_OVERRIDES": json.dumps(cfg.overrides),
        "GPF_MANIFEST": str(generated.out_dir / "manifest.json"),
        "GPF_MODULE": module,
        "TEST_LEVEL": os.environ.get("TEST_LEVEL", "default"),
        **(extra_env or {}),
    }
    if shipped:
        func_dir = (build_root / "coverage" / "func").resolve()
        env["GPF_COVERAGE_FILE"] = str(func_dir / f"{cov_name}.yml")
        Path(env["GPF_COVERAGE_FILE"]).unlink(missing_ok=True)   # a run that samples nothing
    dat = build_dir / "coverage.dat"
    if code_coverage:
        dat.unlink(missing_ok=True)
    # cocotb's runner exits the process on failures when it sees pytest; we report instead
    hidden = os.environ.pop("PYTEST_CURRENT_TEST", None)
    try:
        xml = runner.test(
            test_module=test_module(module), hdl_toplevel=top, test_dir=build_dir,
            build_dir=build_dir, seed=seed, testcase=testcase, waves=waves,
            test_args=["--trace-file", str(waves_file)] if waves and sim == "verilator" else [],
            plusargs=([f"+dumpfile_path={waves_file}"] if waves and sim == "icarus" else [])
            # the flops' random start follows the run's seed (0 would mean the clock's)
            + (["+verilator+rand+reset+2", f"+verilator+seed+{1 + seed % 0x7FFFFFFE}"]
               if gate and sim == "verilator" else []),
            extra_env=env, results_xml=str(build_dir / "results.xml"), log_file=log_file)
    finally:
        if hidden is not None:
            os.environ["PYTEST_CURRENT_TEST"] = hidden
    if code_coverage and dat.exists():   # kept per run: gpf coverage merges them
        kept = (build_root / "coverage" / "code" / "dat" / f"{cov_name}.dat").resolve()
        kept.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(dat, kept)
    if waves:
        from gpf.rtl.waves import write_view

        write_view(cfg, module, sim, waves_file, netlist=gate)
    tests, failed = get_results(Path(xml))
    return SimResult(module, sim, seed, tests, failed, Path(xml), waves_file if waves else None)
