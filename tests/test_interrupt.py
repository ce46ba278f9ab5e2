"""SIGTERM or SIGINT to `gpf` alone stops its whole tree: the simulator's build (make, the
compiler) and the simulation end with it, and it exits with 128 + the signal."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gpf.interrupt import descendants

REPO = Path(__file__).resolve().parent.parent


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.sim
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_the_build_too(tmp_path: Path, sig: signal.Signals) -> None:
    # a fresh build folder: the Verilator build runs for many seconds, in child processes of
    # gpf run's simulation thread (which an interrupt of the main thread alone left running)
    proc = subprocess.Popen(
        [sys.executable, "-m", "gpf.cli", "run", "--config", str(REPO / "configs/bot.toml"),
         "--steps", "1", "--particles", "64", "--json", "r.json"], cwd=tmp_path,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        deadline = time.monotonic() + 60
        tree: list[int] = []
        while time.monotonic() < deadline and len(tree) < 2 and proc.poll() is None:
            time.sleep(0.2)
            tree = descendants(proc.pid)
        assert len(tree) >= 2, "the build never started child processes"
        os.kill(proc.pid, sig)
        code = proc.wait(timeout=30)
        stderr = proc.stderr.read()
        time.sleep(1)
        left = [pid for pid in tree if alive(pid)]
        assert not left, f"still running after {sig.name}: {left}"
        assert code == 128 + sig, (code, stderr)
        assert f"stopped by {sig.name}" in stderr
        assert not (tmp_path / "r.json").exists()
    finally:
        if proc.poll() is None:
            proc.kill()
