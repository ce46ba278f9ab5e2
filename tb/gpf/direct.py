"""A whole-filter run without cocotb (`gpf run --direct`): the same checks, at the simulator's
pace.

gpf_<app>_direct (rtl/templates/gpf_direct.sv.j2) around gpf_<app>_harness is Verilated into a
binary of its own whose C++ loop turns the clock (direct_main.cpp): it resets the filter, loads
the seed, sends the init beat and runs the steps through the harness (stimulus from a file,
random gaps and stalls from a seed printed here, every output beat recorded to a file, the
AXI4-Stream protocol checked), then writes a summary. The binary runs in a process of its own;
this one computes the fixed-point model's steps and scores each step's records (filter.Scorer,
the cocotb run's scoring) as soon as its result is written, so the two share the machine's
cores and neither waits for the other's callbacks.

Not here (the cocotb run has them): waves, code and functional coverage, gate-level netlists,
the IP (gpf_<app>_axi), Icarus, a reset mid-step.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from gpf.config import Config
from gpf.model.fixed_gpf import FixedGPF
from gpf.model.grng import seed_words
from gpf.tb.gpf.feeds import Layout, Records, stall_level, write_stimulus
from gpf.tb.gpf.filter import (
    SHIFT,
    RunResult,
    RunSpec,
    Scorer,
    accuracy,
    check_particles,
    expected_taps,
    init_values,
    one_beat,
    run_inputs,
    step_limit,
    step_values,
    streams,
    wrong_order,
)
from gpf.tb.gpf.model_ahead import model_steps
from gpf.toolchain import sim_env, verilator_version

MAIN = Path(__file__).with_name("direct_main.cpp")
SEED_FILE, INIT_FILE = "gpf_direct_seed.hex", "gpf_direct_init.hex"
SUMMARY = "gpf_direct_summary.txt"
# the model's C++: the run the simulator paces. -O3 builds in about 18 s and ran 100 steps of
# N = 2048 (bot, LANES 1) in 0.65 s, -O2 in 16 s and 0.75 s, -O0 in 6 s and 4.3 s (measured
# side by side); GPF_DIRECT_OPT overrides it (the tests' short runs take -O0)
OPT_FAST = os.environ.get("GPF_DIRECT_OPT", "-O3")
POLL_SECONDS = 0.0005      # while the simulation is behind the model
SIM_NAME = "verilator direct"


class DirectError(AssertionError):
    """The run failed: a mismatch is counted, everything else (a hang, a protocol violation,
    a lost or extra beat, a build error) raises this."""


def build(cfg: Config, build_root: Path = Path("build"), log=None) -> Path:
    """The binary of gpf_<app>_direct for this config (built again only when its sources,
    switches or Verilator change)."""
    from gpf.rtl.generate import generate

    config_dir = (build_root / cfg.name).resolve()
    module = f"gpf_{cfg.app}"
    generated = generate(cfg, config_dir / "rtl")
    harness = generated.harnesses[module]
    sources = [*generated.files[module], harness, harness.with_name(f"{module}_direct.sv"),
               MAIN]
    out = config_dir / "verilator" / f"{module}_direct"
    binary = out / "Vdirect"
    args = ["--cc", "--exe", "--prefix", "Vdirect", "--top-module", f"{module}_direct",
            "+define+GPF_HARNESS_CLOCK_IN", "--output-split", "0", "--output-split-cfuncs", "0",
            "-Wno-fatal", "-Mdir", str(out / "obj"), "-o", str(binary)]
    env = sim_env()
    key = hashlib.sha256(json.dumps(
        [args, OPT_FAST, str(verilator_version(env)), shutil.which("verilator", path=env["PATH"]),
         [(p.name, p.read_text()) for p in sources]]).encode()).hexdigest()
    stamp = out / "sources.sha256"
    if binary.exists() and stamp.exists() and stamp.read_text() == key:
        return binary
    # from scratch: make would keep objects compiled with other flags
    shutil.rmtree(out / "obj", ignore_errors=True)
    out.mkdir(parents=True, exist_ok=True)
    stamp.unlink(missing_ok=True)
    for cmd in (["verilator", *args, *map(str, sources)],
                ["make", "-C", str(out / "obj"), "-f", "Vdirect.mk", f"OPT_FAST={OPT_FAST}",
                 f"-j{min(2, os.cpu_count() or 1)}"]):
        done = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if log is not None:
            log.write(done.stdout + done.stderr)
        if done.returncode:
            raise DirectError(f"building {module}_direct failed ({cmd[0]} exited with "
                              f"{done.returncode}): {(done.stderr or done.stdout)[-2000:]}")
    stamp.write_text(key)
    return binary


def stall_seed(seed: int) -> int:
    """The harness's stall seed of a run: from its seed, so the run repeats."""
    return random.Random(f"gpf-direct-stalls-{seed}").getrandbits(32)


def run(cfg: Config, spec: RunSpec, build_root: Path = Path("build"), corrupt: bool = False,
        log=None, limit: int | None = None) -> RunResult:
    """One run: every particle, weight and estimate checked against the model. Mismatches are
    counted in the result; anything else wrong raises DirectError. `log`: a text file for the
    build's and the simulation's output; `limit`: clocks a result may take (default
    filter.step_limit's)."""
    check_particles(spec, cfg, DirectError)
    binary = build(cfg, build_root, log)
    began = time.monotonic()
    gpf = FixedGPF(cfg, particles=spec.particles)
    s, lanes = streams(gpf), cfg.lanes
    beats = gpf.particles // lanes
    name, sc, (mu, chol, sigma, sigma0), raw_inputs = run_inputs(gpf, spec)
    steps = sc.steps
    res_out = RunResult(steps, gpf.particles, lanes, cfg.name, SIM_NAME, spec.seed, name)

    work = binary.parent / "run"
    work.mkdir(exist_ok=True)
    records = Records(Layout(s.cond, s.part, s.est, SHIFT, lanes), work)
    records.remove()
    (work / SUMMARY).unlink(missing_ok=True)
    words = write_inputs(work, gpf, spec, mu, sigma0, raw_inputs)
    limit = limit or step_limit(beats, spec.stall)
    seed = stall_seed(spec.seed)
    if log is not None:
        log.write(f"gpf run --direct: {binary} in {work}; harness stalls: probability "
                  f"{spec.stall:g}, seed 0x{seed:08x} (from --seed {spec.seed})\n")
        log.flush()
    cmd = [str(binary), f"+steps={steps}", f"+seed_words={len(words)}",
           f"+stall={stall_level(spec.stall)}", f"+stall_seed={seed}", f"+limit={limit}"]
    scorer = Scorer(gpf, s, spec, res_out, mu, corrupt)
    draw_chunks: list[np.ndarray] = []
    expected = model_steps(gpf, (mu, chol, sigma), raw_inputs,
                           spec.seed if spec.load_seed else None,
                           lambda res: expected_taps(res, lanes),
                           (lambda d: wrong_order(d, gpf.dp.n)) if corrupt else None, draw_chunks)
    sim = subprocess.Popen(cmd, cwd=work, stdout=log or subprocess.DEVNULL,
                           stderr=subprocess.STDOUT)
    try:
        opened = False
        for k in range(1, steps + 1):
            exp = next(expected)   # the model's step while the simulator runs it
            while records.results() < k:
                if sim.poll() is not None:
                    raise DirectError(f"step {k}: no result: {ending(work, sim.returncode)}")
                time.sleep(POLL_SECONDS)
            if not opened:
                records.open()
                opened = True
            try:
                scorer.check_step(k, records.read(k, beats), exp, beats, steps)
            except AssertionError as exc:   # a beat the scoring refuses (a wrong tlast, ...)
                raise DirectError(str(exc)) from exc
        sim.wait(timeout=60)
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait()
        records.close()
    summary = read_summary(work)
    check_summary(summary, steps, beats, sim.returncode, work)
    scorer.finish()
    res_out.wall_seconds = round(time.monotonic() - began, 3)
    acc = accuracy(gpf, sc, np.concatenate(draw_chunks), np.array(scorer.rtl_mu),
                   np.array(scorer.fixed_mu))
    res_out.rmse, res_out.metrics, res_out.lost_track = acc.rmse, acc.metrics, acc.lost
    res_out.quantisation_error, res_out.estimates = acc.quantisation, acc.estimates
    return res_out


def bare(cfg: Config, steps: int, particles: int, build_root: Path = Path("build"),
         seed: int = 1) -> float:
    """Seconds the binary alone takes for a run (nothing read or checked): the simulator's
    own speed on this RTL and harness."""
    binary = build(cfg, build_root)
    gpf = FixedGPF(cfg, particles=particles)
    spec = RunSpec(steps=steps, particles=particles, seed=seed)
    _, _, (mu, _, _, sigma0), raw_inputs = run_inputs(gpf, spec)
    work = binary.parent / "bare"
    work.mkdir(exist_ok=True)
    words = write_inputs(work, gpf, spec, mu, sigma0, raw_inputs)
    start = time.monotonic()
    done = subprocess.run([str(binary), f"+steps={steps}", f"+seed_words={len(words)}",
                           f"+limit={step_limit(particles // cfg.lanes, 0)}"], cwd=work,
                          capture_output=True, text=True)
    seconds = time.monotonic() - start
    check_summary(read_summary(work), steps, particles // cfg.lanes, done.returncode, work)
    return seconds


def write_inputs(work: Path, gpf: FixedGPF, spec: RunSpec, mu: np.ndarray, sigma0: np.ndarray,
                 raw_inputs: list[dict]) -> list[int]:
    """The files gpf_<app>_direct and its harness read: the seed words (returned), the init
    beat, the step beats."""
    s = streams(gpf)
    words = seed_words(spec.seed, gpf.dp.draws() * gpf.cfg.lanes) if spec.load_seed else []
    (work / SEED_FILE).write_text("".join(f"{w:016x}\n" for w in words) or "0\n")
    init_w = sum(f.fmt.width for f in s.init)
    init = one_beat(s.init, init_values(gpf, mu, sigma0, spec.init_particles))
    (work / INIT_FILE).write_text(f"{init:0{-(-init_w // 4)}x}\n")
    write_stimulus(work, [one_beat(s.step, step_values(gpf, r)) for r in raw_inputs],
                   sum(f.fmt.width for f in s.step))
    return words


def read_summary(work: Path) -> dict[str, list[int] | str]:
    """gpf_direct_summary.txt: `ended` (done, hang, seed, init) and the harness's counts."""
    path = work / SUMMARY
    if not path.exists():
        return {}
    out: dict[str, list[int] | str] = {}
    for line in path.read_text().splitlines():
        key, *values = line.split()
        out[key] = values[0] if key == "ended" else [int(v) for v in values]
    return out


def ending(work: Path, returncode: int | None) -> str:
    """Why the simulation stopped early, in a line."""
    summary = read_summary(work)
    ended = summary.get("ended")
    if ended is None:
        return f"the simulation exited with {returncode} and wrote no summary"
    counts = summary["counts"]
    return {
        "seed": "the filter did not take the seed words",
        "init": "the filter did not take the init beat",
        "hang": (f"no result for the limit of clocks ({counts[0]} step beats taken, "
                 f"{counts[1]} m_cond and {counts[2]} m_part beats out, {counts[3]} results)"),
    }.get(str(ended), f"the simulation ended: {ended}")


PORTS = ("m_cond", "m_part", "m_est", "s_step")


def check_summary(summary: dict, steps: int, beats: int, returncode: int | None,
                  work: Path) -> None:
    """The run ended as it should: every step's beats out and nothing more, no protocol
    violation."""
    if summary.get("ended") != "done" or returncode:
        raise DirectError(ending(work, returncode))
    violations, port, kind, cycle = summary["violations"]
    if violations:
        raise DirectError(f"gpf harness: {PORTS[port]}: {violations} AXI4-Stream protocol "
                          f"violation(s), the first at cycle {cycle} (kind {kind}; the log "
                          "has every one)")
    taken, cond, part, est = summary["counts"]
    if taken != steps:
        raise DirectError(f"{steps - taken} step beats left untaken")
    if est != steps:
        raise DirectError("extra result beats")
    if not cond == part == steps * beats:
        raise DirectError(f"m_cond {cond} and m_part {part} beats, expected {steps * beats}")
