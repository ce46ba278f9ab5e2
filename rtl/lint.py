"""Lint every generated module: Verilator -Wall, slang (pyslang, with its analysis pass) and
Icarus -g2012.

No waivers: a warning from any of the three is a lint failure.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

from gpf.config import load_config
from gpf.rtl.generate import MODULES, generate
from gpf.toolchain import check_verilator, icarus_missing, sim_env


def verilator_lint(files: list[Path], top: str) -> str:
    env = sim_env()
    run = subprocess.run(["verilator", "--lint-only", "-Wall", "--top-module", top,
                          *map(str, files)], capture_output=True, text=True, env=env)
    return (run.stdout + run.stderr).strip() if run.returncode else ""


# slang's analysis pass (after elaboration) finds what a compile cannot: a signal driven from two
# processes or by two continuous assignments, a signal never driven, one declared or set and never
# read, an unused port. Every diagnostic of these groups is an error; a signal unused by design
# says so where it is declared, `(* maybe_unused *)` (beside Verilator's lint_off UNUSEDSIGNAL).
SLANG_ANALYSIS_WARNINGS = ["default", "unused", "error"]


def slang_lint(files: list[Path], top: str) -> str:
    from pyslang import DiagnosticEngine, ast, syntax

    compilation = ast.Compilation()
    for path in files:
        compilation.addSyntaxTree(syntax.SyntaxTree.fromFile(str(path)))
    diags = compilation.getAllDiagnostics()   # every one of them, as before the analysis
    text = DiagnosticEngine.reportAll(compilation.sourceManager, diags).strip() if diags else ""
    tops = [inst.name for inst in compilation.getRoot().topInstances]
    if top not in tops:
        text += f"\nslang: top module {top} not elaborated (tops: {tops})"
    return (text + "\n" + slang_analysis(compilation)).strip()


def slang_analysis(compilation) -> str:
    """The analysis pass's findings on an elaborated compilation, as slang prints them."""
    from pyslang import DiagnosticEngine, TextDiagnosticClient, analysis

    options = analysis.AnalysisOptions()
    options.flags = analysis.AnalysisFlags.CheckUnused
    manager = analysis.AnalysisManager(options)
    compilation.freeze()   # the analysis requires it (slang's driver does the same)
    manager.analyze(compilation)
    compilation.unfreeze()
    engine = DiagnosticEngine(compilation.sourceManager)
    client = TextDiagnosticClient()
    client.showColors(False)
    engine.addClient(client)
    engine.setWarningOptions(SLANG_ANALYSIS_WARNINGS)
    for diag in manager.getDiagnostics():
        engine.issue(diag)
    return client.getString().strip()


def icarus_compile(files: list[Path], top: str) -> str:
    # Never "-o /dev/null": iverilog marks its output executable, and as root that turns
    # /dev/null into 0755, which breaks every program that writes there as another user (apt).
    with tempfile.TemporaryDirectory(prefix="gpf-lint-") as scratch:
        run = subprocess.run(["iverilog", "-g2012", "-o", str(Path(scratch) / "lint.vvp"),
                              "-s", top, *map(str, files)], capture_output=True, text=True)
    # Icarus reports what it cannot do as "sorry"; those are real gaps in its SV support
    text = (run.stdout + run.stderr).strip()
    return text if run.returncode or text else ""


def lint_files(files: list[Path], top: str, icarus: bool = True) -> dict[str, str]:
    """Problems per tool ('' when clean)."""
    results = {"verilator": verilator_lint(files, top), "slang": slang_lint(files, top)}
    if icarus and icarus_missing() is None:
        results["icarus"] = icarus_compile(files, top)
    return results


def lint_configs(paths: list[Path], lanes: list[int] | None = None,
                 build_root: Path = Path("build")) -> list[str]:
    """Generate every module of every config at each lane count and lint it; print a line each."""
    check_verilator()
    if icarus_missing():
        print(f"lint: Icarus skipped: {icarus_missing()}")
    problems: list[str] = []
    for path in paths:
        for lane_count in lanes or [1, 2, 4]:
            cfg = load_config(path, {"filter.lanes": lane_count})
            generated = generate(cfg, build_root / cfg.name / "rtl")
            for name, files in generated.files.items():
                module = MODULES[name]
                results = lint_files(files, module.top, icarus=module.icarus_gap is None)
                bad = {tool: text for tool, text in results.items() if text}
                tools = ", ".join(results)
                label = f"{cfg.name}: {name}"
                if bad:
                    for tool, text in bad.items():
                        problems.append(f"{label}: {tool}:\n{text}")
                        print(f"lint: {label}: {tool} FAILED\n{text}")
                else:
                    gap = f"; not Icarus: {module.icarus_gap}" if module.icarus_gap else ""
                    print(f"lint: {label}: clean ({tools}{gap})")
    width = shutil.get_terminal_size().columns
    print("-" * min(width, 60))
    print(f"lint: {len(problems)} problem(s)")
    return problems
