"""The README's commands, run as a newcomer runs them: from a folder outside the clone.

Every command of every ```sh block is either run here (`make test` the quick ones, `make
regress` the slow ones) or listed with the reason it is not; a command added to the README
without a verdict fails `test_every_readme_command_has_a_verdict`. The summary `make sim` shows
in the README must have the shape of what `gpf run` prints.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
VENV_BIN = Path(sys.executable).parent

QUICK, SLOW = "make test", "make regress"
# Lines that set the shell up for the commands after them in their block: always run.
SETUP = ("mkdir ", "cd ", "source ", "export ", "cp ")
VERDICT = {
    "make": QUICK,
    "make sim": SLOW,
    "make test": "the suite itself",
    "gpf generate --config bot --out build/bot/rtl": QUICK,
    "gpf model grng --config bot --samples 1000000 --seed 7 --out z.npy": QUICK,
    "gpf model run --config bot --particles 1024 --runs 100 --plot build/plots --json out.json":
        SLOW,
    "gpf model wordlength --words 14:28:2 --runs 20": "an hour of Monte Carlo: the README's "
        "word-length table gives its own command and time",
    "gpf run --config bot --steps 20 --particles 2048 --json r.json": SLOW,
    "gpf run --config uav --steps 10 --set filter.lanes=2 --sim icarus --plot build/plots "
    "--json u.json": SLOW,
    "gpf run --config bot --scenario bot_manoeuvring_observer --json m.json": SLOW,
    "gpf run --config bot --ip --steps 5 --particles 512 --json ip.json": SLOW,
    "gpf run --config bot --steps 100 --particles 2048 --direct --json d.json": SLOW,
    "gpf sim --module grng --config odd --sim icarus --seed 42": SLOW,
    "gpf sim --module grng --set filter.lanes=2": SLOW,
    "gpf synth --config uav --set filter.lanes=2 --module moments --json area.json":
        "minutes of Yosys: tests/test_synth.py synthesizes a block in make test",
    "gpf timing --config bot --module sample_cond --freq 150":
        "minutes of place and route: tests/test_synth.py runs nextpnr on a block",
    "gpf sim --module moments --gate": "minutes of g++ on a 262,000-line netlist: make "
        "test runs exp's netlist, make regress weight_bot's and the whole filter's",
    "gpf run --gate --steps 3 --particles 256 --json g.json":
        "tests/test_sim_filter.py runs the whole bot netlist in make regress",
    "gpf lint": "tests/test_generate.py lints every config in make test",
    "gpf list": QUICK,
    "gpf sim --module grng --waves": SLOW,
    "gpf waves --module grng --no-launch": SLOW,
    "gpf model run --config bot --runs 2": QUICK,
    "gpf run --config bot --steps 3 --particles 64": QUICK,
    "gpf generate --config mine.toml": QUICK,
    ".venv/bin/fusesoc run --target=sim gpf": "tests/test_fusesoc.py runs it in make test",
    ".venv/bin/fusesoc run --target=lint gpf": "the IP's lint: gpf lint covers its files",
    ".venv/bin/fusesoc run --target=synth gpf": "minutes of Yosys (gpf synth)",
}


def readme_blocks() -> list[list[str]]:
    """The commands of each ```sh block: one per line or `;`, comments dropped."""
    blocks, block = [], None
    for line in README.read_text().splitlines():
        if line.startswith("```"):
            if block is None and line.strip() == "```sh":
                block = []
            elif block is not None:
                blocks.append(block)
                block = None
            continue
        if block is not None:
            code = line.split(" #")[0].strip()
            block += [c.strip() for c in code.split(" ; ") if c.strip() and not
                      c.startswith("#")]
    return blocks


def _is_setup(command: str) -> bool:
    return command.startswith(SETUP) and "gpf " not in command


def _verdict(command: str) -> str | None:
    if _is_setup(command):
        return "setup"
    return VERDICT.get(command.split(" && ")[-1] if command.startswith(SETUP) else command)


def test_every_readme_command_has_a_verdict() -> None:
    commands = [c for block in readme_blocks() for c in block]
    assert len(commands) > 20
    missing = [c for c in commands if _verdict(c) is None]
    assert not missing, f"README commands with no verdict in {__file__}: {missing}"
    stale = set(VERDICT) - {c.split(" && ")[-1] for c in commands}
    assert not stale, f"verdicts for commands the README no longer has: {stale}"


def _script(block: list[str], tier: str) -> str | None:
    """The block as a bash script of its setup lines and its commands of this tier."""
    chosen = [c for c in block if _verdict(c) == tier]
    if not chosen:
        return None
    lines = [c for c in block if _verdict(c) in ("setup", tier)]
    return "set -euo pipefail\n" + "\n".join(
        f"echo '$ {c}'\n" + (f"(cd {REPO} && {c})" if c.startswith("make") else c)
        for c in lines).replace("<clone>", str(REPO))


# make test's runs are a few steps of 64 particles: a Verilator model at -O0 builds in half the
# time and runs them as fast (gpf.sim.VERILATOR_OPT)
QUICK_BUILDS = {"GPF_VERILATOR_OPT": "-O0"}


def _run_blocks(tier: str, tmp_path: Path) -> str:
    """Each block's commands of this tier in a folder of its own (HOME: tmp_path); returns what
    they printed."""
    printed = ""
    env = {**os.environ, "HOME": str(tmp_path), "PATH": f"{VENV_BIN}:{os.environ['PATH']}",
           **(QUICK_BUILDS if tier == QUICK else {})}
    for i, block in enumerate(readme_blocks()):
        script = _script(block, tier)
        if script is None:
            continue
        folder = tmp_path / f"block{i}"
        folder.mkdir()
        run = subprocess.run(["bash", "-c", script], cwd=folder, env=env, text=True,
                             capture_output=True, timeout=3000)
        assert run.returncode == 0, f"README block {i}:\n{script}\n{run.stdout}\n{run.stderr}"
        assert "Traceback" not in run.stderr, run.stderr
        printed += run.stdout
    return printed


@pytest.mark.sim
@pytest.mark.slow
def test_quick_readme_commands(tmp_path: Path) -> None:
    printed = _run_blocks(QUICK, tmp_path)
    # from ~/gpf-try, outside the clone, without --json: the summaries, and no JSON written
    assert re.search(r"^bot \S+: 2 runs x .*\n(.*\n)*.* RMSE .*ratio", printed, re.M), printed
    assert re.search(r"^gpf run: bot on verilator.*\n(.*\n)*  PASSED", printed, re.M)
    here = tmp_path / "gpf-try"
    assert not [p for p in here.rglob("*.json") if "build" not in p.relative_to(here).parts]


@pytest.mark.sim
@pytest.mark.regress
def test_slow_readme_commands(tmp_path: Path) -> None:
    _run_blocks(SLOW, tmp_path)


def _shape(line: str) -> str:
    """A printed line as a pattern: numbers and paths may differ, the words may not."""
    out, pos = [], 0
    for m in re.finditer(r"(?:build|/)\S*|-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", line):
        out += [re.escape(line[pos:m.start()]), r"\S+" if m.group()[0] in "b/" else r"\S+?"]
        pos = m.end()
    return "".join(out + [re.escape(line[pos:])]) + "$"


def readme_sim_output() -> list[str]:
    text = README.read_text()
    sample = text.split("`make sim` prints what it checked and how the filter did:")[1]
    return sample.split("```")[1].strip("\n").splitlines()


@pytest.mark.sim
@pytest.mark.slow
# the clone's build/bot/verilator/gpf_bot: make regress's 50-step run of bot builds there too
@pytest.mark.xdist_group("gpf-bot-lanes1-verilator")
def test_readme_sim_output_is_what_gpf_run_prints(tmp_path: Path) -> None:
    """In the clone (the replay line says make sim), with make sim's options (--plot, --json),
    fewer particles."""
    run = subprocess.run([VENV_BIN / "gpf", "run", "--config", "bot", "--particles", "64",
                          "--plot", tmp_path / "plots", "--json", tmp_path / "sim-bot.json"],
                         cwd=REPO, text=True, capture_output=True,
                         env={**os.environ, **QUICK_BUILDS})
    assert run.returncode == 0, run.stdout + run.stderr
    printed = run.stdout.splitlines()
    shown = readme_sim_output()
    assert len(printed) == len(shown), (printed, shown)
    for want, got in zip(shown, printed, strict=True):
        assert re.match(_shape(want), got), f"README shows\n  {want}\ngpf run prints\n  {got}"
