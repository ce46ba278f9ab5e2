"""The whole filter under test: its streams' fields, the model it is checked against, and one
run (seed load, init, steps) with every particle, weight, mean, covariance and L entry compared
bit-exactly with gpf.model.fixed_gpf.FixedGPF.

The steps go through gpf_<app>_harness where it is the toplevel (feeds.HarnessFeed: the stream
work in the simulator, the beats read once a step), else through cocotb's own drivers and
monitors (feeds.StreamFeed: gpf_<app>_axi); the model and the scoring run in threads beside the
simulation (model_ahead.py).

A run is described by a RunSpec (from GPF_RUN, set by `gpf run` and the tests); its results go
to RunSpec.out as JSON for `gpf run` to report.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, ReadOnly, RisingEdge, SimTimeoutError, with_timeout

from gpf.config import Config
from gpf.model.fixed import Format
from gpf.model.fixed_gpf import FixedGPF, StepResult
from gpf.model.float_gpf import FloatGPF
from gpf.model.formats import SHIFT_BITS
from gpf.model.grng import seed_words
from gpf.model.scenarios import Scenario, read_csv
from gpf.outputs import write_json
from gpf.rtl.filter import CYCLES_W, HARNESS_STEPS_MAX, STEP_FIELDS
from gpf.study.metrics import run_metrics
from gpf.study.montecarlo import DEFAULT_SCENARIO, SCENARIOS, flag_names
from gpf.tb import coverage
from gpf.tb.gpf import coverage as filter_coverage
from gpf.tb.gpf.feeds import HarnessFeed, Layout, StepBeats, StreamFeed
from gpf.tb.gpf.ip import Ip
from gpf.tb.gpf.model_ahead import Checker, Expected, ModelAhead
from gpf.tb.harness import CLOCK_NS, Bench, reset, start
from gpf.tb.scoreboard import Field, Scoreboard, pack
from gpf.tb.stream import Sink, Source, StreamDriver, StreamLoop

# clocks a seed or init beat may wait for its tready: a whole step's and more (the filter takes
# an init while idle or ready, a seed word within a few clocks)
SEND_CLOCKS = 10_000

# every output port of gpf_<app>: defined (no X or Z) from reset on
OUTPUTS = ["s_init_tready", "s_step_tready", "m_est_tvalid", "m_est_tdata"] + [
    f"m_{tap}_{sig}" for tap in ("cond", "part") for sig in ("tvalid", "tdata", "tlast")]
CORE_OUTPUTS = ["s_seed_tready", *OUTPUTS]
# gpf_<app>_axi's: the streams' (TLAST on m_est too), the AXI4-Lite slave's, the interrupt
IP_OUTPUTS = [*OUTPUTS, "m_est_tlast", "irq"] + [
    f"s_axil_{sig}" for sig in ("awready", "wready", "bvalid", "bresp", "arready", "rvalid",
                                "rdata", "rresp")]
FLAGS = Format.parse("u4.0")
SAT = Format.parse("u1.0")
SHIFT = Field("shift", Format(False, SHIFT_BITS, 0))


QUIET = logging.getLogger("gpf.tb.checker")
QUIET.propagate = False
QUIET.addHandler(logging.NullHandler())


@dataclass
class RunSpec:
    steps: int = 3
    particles: int | None = None       # default: the config's maximum
    scenario: str | None = None        # a scenario name or a CSV file (default: the app's)
    seed: int = 1                      # scenario seed and GRNG seed load (None: reset state)
    load_seed: bool = True
    init_particles: int | None = None  # the N the init beat carries (default: particles)
    stall: float = 0.0                 # probability of a stall on every stream the tb drives
    harness: bool = True               # the steps through gpf_<app>_harness where it runs them
    est_hold: int = 0                  # clocks the first result waits untaken (cocotb's feed)
    bare: bool = False                 # the harness alone: no model, nothing read or checked
    out: str | None = None             # results JSON
    progress: str | None = None        # a file rewritten after every step: "step mismatches"

    @classmethod
    def from_env(cls, **defaults: Any) -> RunSpec:
        return cls(**{**defaults, **json.loads(os.environ.get("GPF_RUN", "{}"))})


@dataclass
class Streams:
    """Fields of every stream of gpf_<app> (LSB first, as ctrl and the top pack them)."""

    cond: list[Field]
    part: list[Field]      # per lane; then the beat's shift (SHIFT)
    est: list[Field]
    init: list[Field]
    step: list[Field]
    pairs: list[tuple[int, int]]
    lower: list[tuple[int, int]]


def streams(gpf: FixedGPF) -> Streams:
    dp = gpf.dp
    n = dp.n
    x = [Field(f"x{i}", dp.x[i]) for i in range(n)]
    lower = [(i, j) for i in range(n) for j in range(i + 1)]
    sig = [Field(f"s{i}_{j}", dp.sigma(i, j)) for i, j in gpf.pairs]
    mu = [Field(f"mu{i}", dp.x[i]) for i in range(n)]
    chol = [Field(f"l{i}_{j}", dp.chol[i]) for i, j in lower]
    if dp.app == "bot":
        step = [Field("z", Format(True, 0, dp.angle_frac - 1)), Field("ox", dp.x[0]),
                Field("oy", dp.x[2])]
    else:
        step = [Field(name, fmt) for name, fmt in zip(
            STEP_FIELDS["uav"], [dp.gyro] * 3 + [dp.accel] * 3 + list(dp.x[4:7]), strict=True)]
    return Streams(
        cond=x + [Field("sat", SAT)],
        part=x + [Field("w", dp.weight), Field("sat", SAT)],
        est=mu + sig + chol + [Field("flags", FLAGS), Field("sticky", FLAGS),
                               Field("cycles", Format(False, CYCLES_W, 0)),
                               Field("ess", dp.ess)],
        init=[Field("particles", Format(False, gpf.cfg.particles.bit_length(), 0))] + mu + sig,
        step=step, pairs=gpf.pairs, lower=lower)


def step_values(gpf: FixedGPF, raw: dict) -> dict[str, int]:
    """A step's raw inputs (FixedGPF.quantise_inputs) as s_step fields."""
    if gpf.dp.app == "bot":
        return {"z": raw["z"], "ox": raw["observer"][0], "oy": raw["observer"][1]}
    values = list(raw["omega"]) + list(raw["accel"]) + list(raw["v_gps"])
    return dict(zip(STEP_FIELDS["uav"], (int(v) for v in values), strict=True))


def one_beat(fields: list[Field], values: dict[str, int]) -> int:
    return pack(fields, {k: np.array([[v]]) for k, v in values.items()})[0]


def expected_taps(res: StepResult, lanes: int) -> tuple[dict, dict]:
    """(cond, part) raw fields, (beats, lanes), of one step's particles."""
    def beats(a: np.ndarray) -> np.ndarray:
        return np.asarray(a, dtype=np.int64).reshape(-1, lanes)

    t = res.particles
    n = t["cond"].shape[1]
    cond = {f"x{i}": beats(t["cond"][:, i]) for i in range(n)} | {"sat": beats(t["cond_sat"])}
    part = {f"x{i}": beats(t["prop"][:, i]) for i in range(n)}
    # the tap shows weight's own sat; propagate's reach the step's flags only
    part |= {"w": beats(t["weight"]), "sat": beats(t["weight_sat"]),
             "shift": np.asarray(t["shift"], dtype=np.int64)[:, None]}
    return cond, part


def wrong_order(draws: np.ndarray, n: int) -> np.ndarray:
    """The deliberately broken model's draws (steps, N, D): each particle's n conditioning
    draws in the wrong order."""
    draws = draws.copy()
    draws[:, :, :n] = draws[:, :, n - 1::-1]
    return draws


def expected_est(s: Streams, res: StepResult, sticky: int) -> dict[str, np.ndarray]:
    values = {f"mu{i}": int(v) for i, v in enumerate(res.mu)}
    values |= {f"s{i}_{j}": int(res.sigma[(i, j)]) for i, j in s.pairs}
    values |= {f"l{i}_{j}": int(res.chol[i, j]) for i, j in s.lower}
    values |= {"flags": res.flags, "sticky": sticky, "ess": res.ess}
    return {k: np.array([[v]], dtype=np.int64) for k, v in values.items()}


@dataclass
class RunResult:
    steps: int
    particles: int
    lanes: int
    config: str
    sim: str
    seed: int
    scenario: str
    particles_checked: int = 0
    values_checked: int = 0
    mismatches: int = 0
    first_mismatch: str | None = None
    cycles_per_step: list[int] = field(default_factory=list)
    period_per_step: list[int] = field(default_factory=list)  # clocks between result beats
    flags: list[list[str]] = field(default_factory=list)
    ess: list[float] = field(default_factory=list)             # per step, as m_est reports it
    rescales: int = 0          # beats after a step's first whose shift rescaled the sums
    rmse: dict[str, float] = field(default_factory=dict)       # the primary metric
    metrics: dict[str, Any] = field(default_factory=dict)      # every metric, all and last 20 %
    lost_track: bool = False       # the RTL's error over the last 20 % > 3 x float64's
    quantisation_error: list[float] = field(default_factory=list)  # rtl vs float64, per step
    estimates: dict[str, list] = field(default_factory=dict)
    wall_seconds: float = 0.0   # the simulation and its checks, the build excluded
    particles_simulated: int = 0       # a bare run's (RunSpec.bare): nothing checked
    stepping_seconds: float = 0.0      # a bare run's: from the first step beat to the last result


def scenario_of(gpf: FixedGPF, spec: RunSpec) -> tuple[str, Scenario]:
    if spec.scenario and spec.scenario.endswith(".csv"):
        sc = read_csv(spec.scenario)
        return Path(spec.scenario).name, sc
    name = spec.scenario or DEFAULT_SCENARIO[gpf.dp.app]
    return name, SCENARIOS[name](gpf.cfg, spec.steps, spec.seed)


class Scorer:
    """A run's steps scored against the model, one at a time in order (check_step), and what the
    run reports of them: cycle counts, flags, ESS, both estimates. No simulator handle: it runs
    in the checker's thread under cocotb, and in the cocotb-free run (direct.py)."""

    def __init__(self, gpf: FixedGPF, s: Streams, spec: RunSpec, res_out: RunResult,
                 mu0: np.ndarray, corrupt: bool = False, keep_beats: bool = False):
        self.gpf, self.s, self.spec, self.res_out = gpf, s, spec, res_out
        self.keep_beats = keep_beats
        # scored in the checker's thread, which must not log (cocotb's log handler asks the
        # simulator for the time): the first mismatch is logged after the run
        self.boards = {name: Scoreboard(f"gpf_{gpf.dp.app}.{name}", fields,
                                        expect_mismatch=corrupt, log=QUIET)
                       for name, fields in (("cond", s.cond), ("part", s.part + [SHIFT]),
                                            ("est", s.est))}
        self.sticky, self.est_cycles = 0, []
        self.scored: list[StepBeats] = []   # every step's beats, for functional coverage
        self.rtl_mu, self.fixed_mu = [gpf.to_real_mu(mu0)], [gpf.to_real_mu(mu0)]
        self.reported = time.monotonic()

    def check_step(self, k: int, got: StepBeats, exp: Expected, beats: int, steps: int) -> None:
        """Step k scored, and what the run reports of it."""
        gpf, res, res_out = self.gpf, exp.res, self.res_out
        self.sticky |= res.flags
        self.score_step(k, exp, got, beats, self.sticky)
        if self.keep_beats:
            self.scored.append(got)
        res_out.rescales += int(np.count_nonzero(res.particles["shift"][1:]))
        est = got.est
        self.est_cycles.append(got.est_cycle)
        res_out.cycles_per_step.append(int(est["cycles"][0, 0]))
        res_out.flags.append(flag_names(int(est["flags"][0, 0])))
        res_out.ess.append(float(gpf.to_real_ess(est["ess"][0, 0])))
        self.rtl_mu.append(gpf.to_real_mu(np.array([est[f"mu{i}"][0, 0]
                                                     for i in range(gpf.dp.n)])))
        self.fixed_mu.append(gpf.to_real_mu(res.mu))
        res_out.particles_checked += gpf.particles
        # a file written a few times a second: a write each step costs more than the step
        if self.spec.progress and (k == steps or time.monotonic() - self.reported > 0.25):
            Path(self.spec.progress).write_text(f"{k} {self.mismatches}\n")
            self.reported = time.monotonic()

    def score_step(self, k: int, exp: Expected, got: StepBeats, beats: int,
                   sticky: int) -> None:
        """Every particle's fields on both taps, each tap's tlast, the result (its cycle count
        aside: test_filter checks it against the period between results)."""
        lo = (k - 1) * beats
        for tap, fields in (("cond", exp.cond), ("part", exp.part)):
            lasts = got.lasts[tap]
            assert not lasts[:-1].any() and lasts[-1], f"step {k}: {tap} tlast wrong"
            self.boards[tap].compare(fields, got.taps[tap], first_beat=lo)
        exp_est = expected_est(self.s, exp.res, sticky)
        exp_est["cycles"] = got.est["cycles"]
        self.boards["est"].compare(exp_est, got.est, first_beat=k - 1)

    def finish(self) -> None:
        """The run's totals into its result (its first mismatch, the period between results)."""
        res_out = self.res_out
        res_out.values_checked = sum(b.matched + b.mismatched for b in self.boards.values())
        res_out.mismatches = self.mismatches
        res_out.first_mismatch = next((b.first_mismatch for b in self.boards.values()
                                       if b.first_mismatch), None)
        res_out.period_per_step = [b - a for a, b in zip(self.est_cycles, self.est_cycles[1:],
                                                         strict=False)]

    @property
    def mismatches(self) -> int:
        return sum(b.mismatched for b in self.boards.values())


def init_values(gpf: FixedGPF, mu: np.ndarray, sigma0: np.ndarray, sent: int | None
                ) -> dict[str, int]:
    """The init beat: N (`sent`, or the run's), the raw mu0 and the raw Sigma0 (real sigma0)."""
    out = {"particles": gpf.particles if sent is None else sent}
    out |= {f"mu{i}": int(v) for i, v in enumerate(mu)}
    return out | {f"s{i}_{j}": v for (i, j), v in gpf.quantise_sigma(sigma0).items()}


def run_inputs(gpf: FixedGPF, spec: RunSpec) -> tuple[str, Scenario, tuple, list[dict]]:
    """A run's scenario (its name), the model's start (mu, chol, sigma, and the real Sigma0)
    and every step's raw inputs."""
    name, sc = scenario_of(gpf, spec)
    mu0, sigma0 = FloatGPF(gpf.cfg, gpf.particles).initial(sc)
    mu, chol = gpf.init(mu0, sigma0)
    raw_inputs = [gpf.quantise_inputs(sc.step_inputs(k)) for k in range(1, sc.steps + 1)]
    return name, sc, (mu, chol, gpf.quantise_sigma(sigma0), sigma0), raw_inputs


def step_limit(beats: int, stall: float) -> int:
    """Clocks a result may take before the run calls it a hang (a lost beat): a step takes
    N / LANES + 236 or so clocks, a few times that with every stream stalled half the time."""
    return 10 * (beats + 300) * (1 + int(10 * stall))


def check_particles(spec: RunSpec, cfg: Config, error: type[Exception] = ValueError) -> None:
    """A run asks for at most the config's filter.particles (the RTL's buffers' size)."""
    if (spec.particles or 0) > cfg.particles:
        raise error(f"particles = {spec.particles}: more than the config's maximum "
                    f"filter.particles = {cfg.particles}")


class FilterBench:
    """Drives gpf_<app> through a run and scores every stream against the model."""

    def __init__(self, dut: SimHandleBase, b: Bench, spec: RunSpec, corrupt: bool = False,
                 clock_running: bool = False):
        self.dut, self.b, self.spec = dut, b, spec
        check_particles(spec, b.cfg)
        self.gpf = FixedGPF(b.cfg, particles=spec.particles)
        self.s = streams(self.gpf)
        self.corrupt = corrupt
        self.clock_running = clock_running   # another bench of this test started the clock
        # gpf_<app>_axi: aclk, aresetn, seed and N through registers, TLAST on m_est, padding
        self.ip = Ip.of(dut, self.gpf.dp.app) if hasattr(dut, "aresetn") else None
        self.clk = dut.aclk if self.ip else dut.clk
        # gpf_<app>_harness around the core: it runs the clock, and the run's steps (feeds.py)
        self.harness = hasattr(dut, "fast")
        self.scorer: Scorer | None = None   # the run's, from its first step on

    def idle(self) -> None:
        d = self.dut
        for name in ("s_init", "s_step") if self.ip else ("s_seed", "s_init", "s_step"):
            getattr(d, f"{name}_tvalid").value = 0
            getattr(d, f"{name}_tdata").value = 0
        for name in ("m_est", "m_cond", "m_part"):
            getattr(d, f"{name}_tready").value = 1
        if self.harness:   # the core's ports are cocotb's until a run hands them over
            d.fast.value = d.load.value = 0

    async def send(self, name: str, words: list[int], idle: float = 0.0, tag: str = "") -> None:
        """Beats on an input stream (seed, init, step inputs), each a packet. Into
        gpf_<app>_axi the seed goes through SEED_LO/HI and N through PARTICLES (the init beat's
        own particle field inverted, to show it is ignored)."""
        if self.ip and name == "s_seed":
            await self.ip.load_seed(words)
            return
        if self.ip and name == "s_init":
            field = self.ip.fields["particles.count"]
            particles = words[0] & ((1 << field.width) - 1)
            await self.ip.write("particles", particles)
            words = [w ^ ((1 << field.width) - 1) for w in words]
        drv = StreamDriver(self.clk, self.dut, name, idle, self.b.rng(f"{name}{tag}"),
                           has_last=bool(self.ip))
        # a filter that never takes a seed or init beat fails here, not at the wall clock
        limit = SEND_CLOCKS * (len(words) + 1) * (1 + int(10 * idle))
        try:
            await with_timeout(drv.send([(word, True) for word in words]), limit * CLOCK_NS,
                               "ns")
        except SimTimeoutError:
            raise AssertionError(f"{name}: {len(words)} beats not all taken in {limit} clocks"
                                 ) from None

    async def begin(self) -> None:
        """Idle inputs, then the clock (once) and a reset; every output defined after it."""
        self.idle()
        if self.ip:
            await self.ip.reset()
        elif self.clock_running or self.harness:   # the harness runs its own clock
            await reset(self.dut)
        else:
            await start(self.dut)
            self.clock_running = True
        await ReadOnly()
        undefined = [port for port in (IP_OUTPUTS if self.ip else CORE_OUTPUTS)
                     if not getattr(self.dut, port).value.is_resolvable]
        assert not undefined, f"X or Z after reset on {', '.join(undefined)}"
        # the GRNG runs from reset: by now its draws wait in the slices after it, which a seed
        # load must drop (a load right after reset, before any draw, would hide that)
        await ClockCycles(self.clk, 32)
        if self.ip:   # steps run, the taps carry every particle
            await self.ip.write("ctrl", self.ip.value({"ctrl.run": 1, "ctrl.taps": 1}))

    async def interrupted_step(self) -> None:
        """Seed, init, and a step reset half-way through its particles (taps stalled now and
        then): what follows must start clean."""
        d, gpf = self.dut, self.gpf
        await self.begin()
        await self.send("s_seed", seed_words(self.spec.seed + 1, gpf.dp.draws() * gpf.cfg.lanes))
        _, _, (mu, _, _, sigma0), raw_inputs = run_inputs(gpf, self.spec)
        await self.send("s_init", [one_beat(self.s.init, init_values(
            gpf, mu, sigma0, self.spec.init_particles))])
        raw = raw_inputs[0]
        rng = self.b.rng("interrupt")
        step_in = Source(d, "s_step", 0.0, rng, [(one_beat(self.s.step, step_values(gpf, raw)),
                                                  True)], has_last=bool(self.ip))
        cond, part = Sink(d, "m_cond", 0.0, rng), Sink(d, "m_part", 0.3, rng)
        loop = StreamLoop(self.clk, [step_in, cond, part])
        await cond.wait(gpf.particles // gpf.cfg.lanes // 2)
        await RisingEdge(self.clk)   # the wait ends in ReadOnly, where nothing may be written
        loop.stop()
        filter_coverage.sample_reset(self, len(cond.beats))

    async def run(self) -> RunResult:
        spec, gpf, s = self.spec, self.gpf, self.s
        lanes = gpf.cfg.lanes
        began = time.monotonic()
        name, sc, (mu, chol, sigma, sigma0), raw_inputs = run_inputs(gpf, spec)
        steps = sc.steps
        res_out = RunResult(steps, gpf.particles, lanes, gpf.cfg.name, cocotb.SIM_NAME,
                            spec.seed, name)
        await self.begin()
        stall = spec.stall
        if spec.load_seed:
            await self.send("s_seed", seed_words(spec.seed, gpf.dp.draws() * lanes), stall)
        await self.send("s_init", [one_beat(s.init, init_values(gpf, mu, sigma0,
                                                                spec.init_particles))], stall)
        step_words = [one_beat(s.step, step_values(gpf, r)) for r in raw_inputs]
        feed = self.feed(steps)
        await feed.start(step_words, sum(f.fmt.width for f in s.step))
        if spec.bare:
            return await self.bare(feed, res_out, began)
        # the model's steps in a thread while the simulator runs, its draws the GRNG model's
        # after the same seed load (or after reset)
        model = ModelAhead(gpf, mu, chol, sigma, raw_inputs,
                           spec.seed if spec.load_seed else None,
                           lambda res: expected_taps(res, lanes),
                           corrupt=(lambda d: wrong_order(d, gpf.dp.n)) if self.corrupt
                           else None)
        try:
            await self.steps(feed, model, steps, res_out, mu)
        finally:
            model.stop()
        await feed.finish(steps, gpf.particles // lanes)
        if self.spec.est_hold:
            self.check_held(feed.beats, gpf.particles // lanes)
        if self.ip:
            self.check_framing(feed.beats)
        scorer = self.scorer
        filter_coverage.sample_run(self, scorer.scored,
                                   [bt.last for bt in feed.beats["est"]] if self.ip else None,
                                   *feed.stalls)
        scorer.finish()
        res_out.wall_seconds = round(time.monotonic() - began, 3)
        acc = accuracy(gpf, sc, model.draws(), np.array(scorer.rtl_mu),
                       np.array(scorer.fixed_mu))
        res_out.rmse, res_out.metrics, res_out.lost_track = acc.rmse, acc.metrics, acc.lost
        res_out.quantisation_error, res_out.estimates = acc.quantisation, acc.estimates
        return res_out

    async def steps(self, feed: HarnessFeed | StreamFeed, model: ModelAhead, steps: int,
                    res_out: RunResult, mu0: np.ndarray) -> None:
        """Each step scored against the model's as its result comes out, in a thread (Checker)
        while the simulation goes on; what the run reports (cycle counts, flags, ESS, both
        estimates, the period between results)."""
        gpf = self.gpf
        beats = gpf.particles // gpf.cfg.lanes
        limit = step_limit(beats, self.spec.stall)
        self.scorer = scorer = Scorer(gpf, self.s, self.spec, res_out, mu0, self.corrupt,
                                      keep_beats=coverage.enabled())
        checker = Checker(lambda k: scorer.check_step(k, feed.read(k, beats), model.get(), beats,
                                                       steps))
        try:
            for k in range(1, steps + 1):
                await feed.wait(k, limit)
                checker.submit(k)
            checker.finish()
        finally:
            checker.stop()
            for board in scorer.boards.values():   # logged here, not from the checker's thread
                if board.first_mismatch:
                    report = self.dut._log.info if self.corrupt else self.dut._log.error
                    report("first mismatch: %s", board.first_mismatch)

    async def bare(self, feed: HarnessFeed, res_out: RunResult, began: float) -> RunResult:
        """The simulator's own speed on this RTL: the harness runs every step, Python only
        waits for the last result (RunResult.particles_simulated, nothing checked)."""
        assert isinstance(feed, HarnessFeed), "a bare run needs gpf_<app>_harness"
        stepping = time.monotonic()
        beats = self.gpf.particles // self.gpf.cfg.lanes
        await feed.wait(res_out.steps, 200 * (beats + 1000) * res_out.steps)
        res_out.stepping_seconds = round(time.monotonic() - stepping, 3)
        await feed.finish(res_out.steps, beats)
        res_out.particles_simulated = res_out.steps * res_out.particles
        res_out.wall_seconds = round(time.monotonic() - began, 3)
        return res_out

    def feed(self, steps: int) -> HarnessFeed | StreamFeed:
        """gpf_<app>_harness's streams where it runs them (RunSpec.harness, steps it holds),
        cocotb's drivers and monitors otherwise."""
        layout = Layout(self.s.cond, self.s.part, self.s.est, SHIFT, self.gpf.cfg.lanes)
        if self.harness and self.spec.harness and not self.spec.est_hold \
                and steps <= HARNESS_STEPS_MAX:
            seed = self.b.rng("harness-stalls").getrandbits(32)
            self.dut._log.info("harness stalls: probability %g, seed 0x%08x (from SEED=%d)",
                               self.spec.stall, seed, self.b.seed)
            return HarnessFeed(self.dut, layout, self.spec.stall, seed)
        return StreamFeed(self.dut, self.clk, layout, self.spec.stall, self.b.rng("streams"),
                          est_last=bool(self.ip), est_hold=self.spec.est_hold)

    @staticmethod
    def check_held(mons: dict[str, list], beats: int) -> None:
        """RunSpec.est_hold: the first result was still untaken when the second step's last
        particle left, so the controller held the second result back (its S_OUT wait)."""
        assert len(mons["part"]) >= 2 * beats, "est_hold needs two steps"
        taken, second = mons["est"][0].cycle, mons["part"][2 * beats - 1].cycle
        assert taken > second, (f"the first result was taken at clock {taken}, before the second "
                                f"step's last particle at {second}: est_hold too short")

    def check_framing(self, mons: dict[str, list]) -> None:
        """gpf_<app>_axi: every m_est beat a packet (TLAST), every stream's padding zero."""
        assert all(bt.last for bt in mons["est"]), "m_est: a beat without TLAST"
        widths = self.b.manifest["modules"][f"gpf_{self.gpf.dp.app}_axi"]["constants"]
        for k in ("est", "cond", "part"):
            padded = [bt for bt in mons[k] if bt.data >> widths[f"{k}_w"]]
            assert not padded, f"m_{k}: padding not zero in beat {padded[0]}"

    @property
    def mismatches(self) -> int:
        return self.scorer.mismatches if self.scorer else 0


@dataclass
class Accuracy:
    rmse: dict[str, float | None]     # the primary metric of rtl, fixed and float64 (all steps)
    metrics: dict[str, Any]           # study.metrics.run_metrics
    lost: bool
    quantisation: list[float]         # rtl vs float64 per step, primary metric
    estimates: dict[str, list]


def accuracy(gpf: FixedGPF, sc: Scenario, draws: np.ndarray, rtl_mu: np.ndarray,
             fixed_mu: np.ndarray) -> Accuracy:
    """The RTL's, the fixed-point model's (as the run computed them, step by step) and the
    float64 model's estimates (the float one driven by the same draws): every metric's RMSE
    over all steps and the last 20 %, whether the RTL lost track, its distance from the float64
    estimate per step (its quantisation error), the estimates."""
    floating = FloatGPF(gpf.cfg, gpf.particles).run(sc, draws=gpf.dp.noise.to_real(draws))
    report = run_metrics(gpf.dp.app, sc.truth, {"rtl": rtl_mu, "fixed": fixed_mu,
                                                "float": floating.mu})
    estimates = {"truth": [None if not np.all(np.isfinite(r)) else r for r in sc.truth.tolist()],
                 "float": floating.mu.tolist(), "fixed": fixed_mu.tolist(),
                 "rtl": rtl_mu.tolist()}
    if gpf.dp.app == "bot":
        estimates["observer"] = sc.inputs["observer"][1:].tolist()
    return Accuracy(report.rmse, report.metrics, report.lost, report.quantisation, estimates)


def write_result(res: RunResult, path: str | None) -> None:
    if path:
        write_json(path, asdict(res))   # strict JSON (NaN as null), renamed into place
