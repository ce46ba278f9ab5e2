"""`gpf mutants`: mutation testing of the generated SystemVerilog (gpf.rtl.mutate's mutants).

Each mutant belongs to one target: the first (block, config) whose generated RTL holds the
mutated text, or a whole filter (gpf_bot, gpf_uav) for the tops' own templates. It runs on
Icarus against that block's own cocotb testbench (the whole filter's short `gpf run` for the
tops, then its reset half-way through a step), each in a child process with a wall-clock
limit, at rising test levels while it survives, then against each other target whose RTL
holds the text while it still survives.
Verdicts: killed (a test failed, or an RTL check stopped the simulator with $fatal), survived,
stillborn (the template did not render or the RTL did not compile: not scored) and hung (the
wall clock ran out before the testbench's own timeouts saw anything: scored as a survivor).

Survivors listed in tests/data/mutants/equivalent.toml (id -> reason, with the text the mutant
replaces, so an entry goes stale when its line changes) are marked equivalent in the report.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import jinja2
import jinja2.meta

from gpf.config import config_path, load_config
from gpf.outputs import atomic_write_text
from gpf.rtl.generate import MODULES, TEMPLATE_DIR, generate
from gpf.rtl.mutate import Mutant, scan_dir

EQUIVALENT_FILE = Path(__file__).resolve().parent.parent / "tests/data/mutants/equivalent.toml"
# the configs a block's mutants may need: its application's default, then odd words (and, for
# bot, ecp5's shapes); the first whose RTL holds the mutated text is the mutant's
APP_CONFIGS = {"bot": ("bot", "odd"), "uav": ("uav", "uav_seed002")}
# the whole filter's runs for a top's mutant, each only if it survived the one before: a short
# run (as tests/test_sim_filter.py's mutants), then runs that raise the flags the first never
# does (every step below the ESS threshold, an outlier measurement, a target out of range, a
# bearing glitch whose weights collapse onto one particle: at N = 32 its ESS rounds to 1.0,
# exactly the LOW_ESS threshold N/32; a target near the rail, a few particles saturating; a
# saturation in sample_cond alone, at LANES 2; one in weight alone),
# two lanes (a lane's indexing is the same at LANES 1) and every stream stalled half the
# clocks (the handshakes): (scenario, config overrides, stall, particles). The far target and
# the rail run 512 particles, more than the pipeline holds, so saturations are flagged while
# particles still stream, not only after the last has left ctrl.
FILTER_RUN = {"steps": 5, "particles": 32}
FILTER_ESCALATION = ((None, {}, 0.0, 32), (None, {"filter.ess_min": 1}, 0.0, 32),
                     ("bot_outlier", {}, 0.0, 32), ("bot_bearing_glitch", {}, 0.0, 32),
                     ("bot_cond_rail", {"filter.lanes": 2}, 0.0, 32),
                     ("bot_far_observer", {}, 0.0, 32),
                     (None, {"filter.lanes": 2}, 0.0, 32), (None, {}, 0.5, 32),
                     ("bot_far_target", {}, 0.0, 512), ("bot_near_rail", {}, 0.0, 512))


def _bot_csv(cfg, path: Path, name: str, mean: tuple[float, ...],
             observer: tuple[float, float]) -> str:
    """A bot CSV scenario (written to `path`): the truth drawn around an initial mean (x, vx,
    y, vy), bearings from a fixed observer (seed 1)."""
    from gpf.model.scenarios import bot_still_observer, write_csv

    write_csv(bot_still_observer(cfg, FILTER_RUN["steps"], 1, name, mean, observer), path)
    return str(path)


def _edge(cfg) -> float:
    return float(cfg.formats["state"].max_real)


# scenarios the mutant runs write themselves (not shipped: each a test of one flag's path):
# bot_near_rail: the cloud 0.25 m inside x's top, a few of each step's particles saturating,
#   spread through the step (its second step at 512 particles, seed 1: 21 saturate among the
#   first 464, none among the last 48), so in some steps only particles that leave ctrl early do;
# bot_cond_rail: a target at x = E - 0.2 moving out, one particle in its first step saturating
#   in sample_cond and nowhere else (at LANES 2: one lane of one beat);
# bot_far_observer: the target and the observer 200 m apart in x, beyond weight's difference
#   format, so weight saturates every particle while nothing else does
GENERATED_SCENARIOS = {
    "bot_near_rail": lambda cfg, p: _bot_csv(cfg, p, "bot_near_rail",
                                             (_edge(cfg) - 0.25, 0.0, 1.0, 0.0), (0.0, 0.0)),
    "bot_cond_rail": lambda cfg, p: _bot_csv(cfg, p, "bot_cond_rail",
                                             (_edge(cfg) - 0.2, -3.0, 1.0, 0.0), (0.0, 0.0)),
    "bot_far_observer": lambda cfg, p: _bot_csv(cfg, p, "bot_far_observer",
                                                (100.0, 0.0, 1.0, 0.0), (-100.0, 0.0)),
}
SIM = "icarus"   # about 1 s to compile a block; a Verilator build costs 10 to 60 s a mutant


@dataclass(frozen=True)
class Target:
    module: str
    config: str
    lanes: int = 1

    @property
    def name(self) -> str:
        return f"{self.module}/{self.config}" + (f"/lanes{self.lanes}" if self.lanes > 1 else "")

    def load(self):
        return load_config(config_path(self.config), {"filter.lanes": self.lanes})

    @property
    def is_filter(self) -> bool:
        return MODULES[self.module].is_filter


def targets() -> list[Target]:
    """Every block with a testbench, in each of its configs, at LANES 2 where it has lanes (a
    mutant of one lane's indexing is equivalent at LANES 1), then the two whole filters."""
    out = []
    for name, mod in MODULES.items():
        if not mod.simulated or mod.made or mod.is_filter:
            continue
        out += [Target(name, c, 2 if mod.laned else 1) for app in mod.apps
                for c in APP_CONFIGS[app]]
    return out + [Target("gpf_bot", "bot"), Target("gpf_uav", "uav")]


def owned_templates(module: str, template_dir: Path = TEMPLATE_DIR) -> list[str]:
    """The templates a module renders for its own parts, and those they include or import
    (a block's used blocks and a filter's blocks own theirs)."""
    env = jinja2.Environment()
    mod = MODULES[module]
    todo = [f"{mod.template(part)}.sv.j2" for part in mod.parts]
    out: list[str] = []
    while todo:
        name = todo.pop(0)
        if name in out or not (template_dir / name).exists():
            continue
        out.append(name)
        ast = env.parse((template_dir / name).read_text())
        todo += [n for n in jinja2.meta.find_referenced_templates(ast) if n]
    return out


def _marker(k: int) -> str:
    return f"/*@MUTANT{k}@*/"


def assign_targets(mutants: list[Mutant], work: Path) -> dict[str, list[Target]]:
    """Each mutant's targets: every target owning its template whose RTL renders the mutated
    text, in targets()' order (found by rendering the template once per target with a comment
    marking every site); empty where no config reaches it. The first is the mutant's own (its
    row in the scores); a survivor there runs against the others (a shared template's line
    may matter in another config only: an N = 3 Cholesky core, a signed difference)."""
    by_template: dict[str, list[Mutant]] = {}
    for mu in mutants:
        by_template.setdefault(mu.template, []).append(mu)
    owners: dict[str, list[Target]] = {}
    for t in targets():
        for name in owned_templates(t.module):
            owners.setdefault(name, []).append(t)
    found: dict[str, list[Target]] = {mu.id: [] for mu in mutants}
    for name, group in by_template.items():
        offsets = sorted({mu.offset for mu in group})
        text = (TEMPLATE_DIR / name).read_text()
        for k in reversed(range(len(offsets))):
            text = text[:offsets[k]] + _marker(k) + text[offsets[k]:]
        marked = work / f"marked-{name}"
        shutil.rmtree(marked, ignore_errors=True)
        shutil.copytree(TEMPLATE_DIR, marked)
        (marked / name).write_text(text)
        for t in owners.get(name, []):
            rendered = _render(t, marked, work / "render")
            for k, offset in enumerate(offsets):
                if _marker(k) in rendered:
                    for mu in group:
                        if mu.offset == offset:
                            found[mu.id].append(t)
        shutil.rmtree(marked)
    return found


def _render(t: Target, template_dir: Path, out: Path) -> str:
    shutil.rmtree(out, ignore_errors=True)
    generated = generate(t.load(), out, modules=[t.module],
                         template_dir=template_dir)
    return "".join(p.read_text() for p in generated.files[t.module])


# ---- running one mutant (in a child process: a hung simulator is killed with its group)

@dataclass
class Verdict:
    id: str
    target: str
    status: str          # killed, survived, stillborn, hung
    detail: str = ""
    seconds: float = 0.0
    equivalent: str | None = None   # the reason, from EQUIVALENT_FILE
    before: str = ""
    after: str = ""
    cls: str = ""
    diff: str = ""


def run_one(t: Target, template_dir: Path, build_root: Path, log: Path,
            level: str) -> tuple[str, str]:
    """Simulate target `t` from `template_dir`: (status, detail). Runs in the child."""
    from gpf.run import RunArgs, run_filter
    from gpf.sim import run_sim, sim_build_dir

    cfg = t.load()
    shutil.rmtree(build_root, ignore_errors=True)
    os.environ["TEST_LEVEL"] = level
    try:
        if t.is_filter:
            runs = [r for r in FILTER_ESCALATION if r[0] is None or r[0].startswith(cfg.app)]
            for scenario, overrides, stall, particles in runs:
                run_cfg = load_config(config_path(t.config), {"filter.lanes": t.lanes,
                                                              **overrides})
                source = scenario
                if scenario in GENERATED_SCENARIOS:
                    source = GENERATED_SCENARIOS[scenario](run_cfg,
                                                           build_root.parent / f"{scenario}.csv")
                res = run_filter(run_cfg, RunArgs(FILTER_RUN["steps"], particles,
                                                  1, source, SIM, False, stall=stall),
                                 progress=False, build_root=build_root, template_dir=template_dir)
                if not res["passed"]:
                    return "killed", (f"scenario {scenario or 'default'} {overrides or ''}"
                                      f"{f' stall {stall}' if stall else ''}: "
                                      f"{res['mismatches']} mismatches, first: "
                                      f"{res.get('first_mismatch')}")
            # last, the testbench's reset half-way through a step (test_filter never resets
            # mid-run: a register left out of the reset survived every run above)
            res = run_sim(cfg, t.module, SIM, seed=1, testcase="test_reset_mid_step",
                          template_dir=template_dir, build_root=build_root, log_file=log,
                          all_modules=False, extra_env={"TEST_LEVEL": level, "GPF_FAIL_FAST": "1"})
            if res.failed:
                return "killed", "test_reset_mid_step failed"
            return "survived", f"the whole filter passed {len(runs)} runs and a reset mid-step"
        res = run_sim(cfg, t.module, SIM, seed=1, template_dir=template_dir,
                      build_root=build_root, log_file=log, all_modules=False,
                      extra_env={"TEST_LEVEL": level, "GPF_FAIL_FAST": "1"})
        if res.failed:
            return "killed", f"{res.failed} of {res.tests} tests failed"
        if t.module == "grng":   # the inversion's deep tail, which no random stream reaches
            from gpf.tb.grng.icdf_directed import check

            problem = check(cfg, build_root / "icdf", template_dir)
            if problem:
                return "killed", problem
            return "survived", f"{res.tests} tests and the inversion's directed words passed"
        return "survived", f"{res.tests} tests passed"
    except jinja2.TemplateError as exc:
        return "stillborn", f"render: {exc}"
    except Exception as exc:
        text = log.read_text(errors="replace") if log.exists() else ""
        vvp = sim_build_dir((build_root / cfg.name).resolve(), SIM, t.module) / "sim.vvp"
        if not vvp.exists():
            return "stillborn", f"compile: {_first_error(text) or exc}"
        if "FATAL" in text:
            return "killed", "an RTL check stopped the simulation ($fatal)"
        return "killed", f"the simulation failed: {type(exc).__name__}: {exc}"


def _first_error(log: str) -> str:
    for line in log.splitlines():
        if "error" in line.lower() or "syntax" in line.lower():
            return line.strip()[:200]
    return ""


def _child(argv: list[str]) -> int:
    spec = json.loads(argv[0])
    status, detail = run_one(Target(*spec["target"]), Path(spec["templates"]),
                             Path(spec["build"]), Path(spec["log"]), spec["level"])
    Path(spec["result"]).write_text(json.dumps({"status": status, "detail": detail}))
    return 0


def simulate(t: Target, template_dir: Path, work: Path, level: str,
             limit: float) -> tuple[str, str, float]:
    """run_one in a child process of its own group, stopped after `limit` seconds."""
    result = work / "result.json"
    result.unlink(missing_ok=True)
    spec = {"target": [t.module, t.config, t.lanes], "templates": str(template_dir),
            "build": str(work / "build"), "log": str(work / "sim.log"), "level": level,
            "result": str(result)}
    start = time.monotonic()
    child = subprocess.Popen([sys.executable, "-m", "gpf.mutants", json.dumps(spec)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    try:
        child.wait(timeout=limit)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()
        return "hung", f"no verdict in {limit:.0f} s (the testbench's timeouts saw nothing)", \
            time.monotonic() - start
    seconds = time.monotonic() - start
    if not result.exists():
        return "stillborn", f"the run itself failed (exit {child.returncode})", seconds
    verdict = json.loads(result.read_text())
    return verdict["status"], verdict["detail"], seconds


# ---- the campaign

@dataclass
class Campaign:
    verdicts: list[Verdict] = field(default_factory=list)
    unreached: int = 0          # sites no target's config renders
    total: int = 0              # mutants of the selected targets before sampling
    baseline: dict[str, float] = field(default_factory=dict)


def equivalents(path: Path = EQUIVALENT_FILE) -> dict[str, dict]:
    return tomllib.loads(path.read_text()) if path.exists() else {}


def _rank(salt: str, mutant_id: str) -> int:
    """A mutant's place in a seeded order from its id alone, so a sample or a shard keeps its
    mutants when a template edit adds or removes others elsewhere."""
    return int.from_bytes(hashlib.sha256(f"{salt}:{mutant_id}".encode()).digest()[:8], "big")


def select(mutants: list[Mutant], assigned: dict[str, list[Target]], module: str | None,
           ids: list[str] | None, sample: int | None, seed: int, shards: int,
           shard: int) -> list[Mutant]:
    """The mutants to run, in template order: the `sample` ranked first by the seed (all when
    None), then those of shard `shard` of `shards` (by id, whatever the sample)."""
    chosen = [mu for mu in mutants if assigned[mu.id]
              and (module is None or assigned[mu.id][0].module == module)
              and (not ids or mu.id in ids)]
    if sample is not None and sample < len(chosen):
        kept = {mu.id for mu in sorted(chosen, key=lambda mu: _rank(f"sample-{seed}", mu.id))
                [:sample]}
        chosen = [mu for mu in chosen if mu.id in kept]
    return [mu for mu in chosen if _rank("shard", mu.id) % shards == shard]


def unified_diff(mu: Mutant) -> str:
    import difflib

    text = (TEMPLATE_DIR / mu.template).read_text()
    return "".join(difflib.unified_diff(text.splitlines(True), mu.apply(text).splitlines(True),
                                        f"a/{mu.template}", f"b/{mu.template}", n=1))


# a block mutant runs at the campaign's level and, while it survives, at each level after it
# (tb/harness.py: quick a fiftieth of the random beats, short a fifth, default all); the beats
# relative to the level before set the hang limit. A top's mutants run the whole filter's
# escalation (FILTER_ESCALATION) at short, which has no quick level of its own.
LEVELS = ("quick", "short", "default")
LEVEL_BEATS = {"short": 10, "default": 5}


def first_level(t: Target, level: str) -> str:
    return "short" if t.is_filter and level == "quick" else level


def escalation(t: Target, level: str) -> tuple[str, ...]:
    return () if t.is_filter else LEVELS[LEVELS.index(level) + 1:]


def run_campaign(mutants: list[Mutant], assigned: dict[str, list[Target]], work: Path,
                 level: str = "quick", log=print, on_verdict=None) -> Campaign:
    camp = Campaign()
    templates = work / "templates"
    shutil.rmtree(templates, ignore_errors=True)
    shutil.copytree(TEMPLATE_DIR, templates)

    def baseline(t: Target) -> None:
        """The unmutated target's time at the first level (templates unmutated)."""
        status, detail, seconds = simulate(t, templates, work, first_level(t, level), 600)
        if status != "survived":
            raise RuntimeError(f"the unmutated {t.name} does not pass ({status}: "
                               f"{detail}); see {work / 'sim.log'}")
        camp.baseline[t.name] = round(seconds, 1)
        log(f"baseline {t.name}: passed in {seconds:.1f} s")

    def run(t: Target) -> tuple[str, str, float]:
        """One target, its levels while the mutant survives."""
        # the testbenches' own timeouts allow several times a run's length
        limit = max(60.0, 20 * camp.baseline[t.name])
        status, detail, seconds = simulate(t, templates, work, first_level(t, level), limit)
        for more_level in escalation(t, level):
            if status != "survived":
                break
            # fewer beats let it through: the next level (the testbench's own default run
            # last) decides; the hang limit scaled by the beats, generously
            limit *= LEVEL_BEATS[more_level]
            status, detail, more = simulate(t, templates, work, more_level, limit)
            detail += f" (at TEST_LEVEL={more_level}, after surviving {level})"
            seconds += more
        return status, detail, seconds

    for t in sorted({assigned[mu.id][0] for mu in mutants}, key=lambda t: t.name):
        baseline(t)
    for n, mu in enumerate(mutants, 1):
        t, others = assigned[mu.id][0], assigned[mu.id][1:]
        original = (TEMPLATE_DIR / mu.template).read_text()
        (templates / mu.template).write_text(mu.apply(original))
        try:
            status, detail, seconds = run(t)
            for other in others:
                if status != "survived":
                    break
                if other.name not in camp.baseline:   # its baseline runs unmutated, once
                    (templates / mu.template).write_text(original)
                    baseline(other)
                    (templates / mu.template).write_text(mu.apply(original))
                status, detail, more = run(other)
                detail = f"{other.name}: {detail} (after surviving {t.name})"
                seconds += more
        finally:
            (templates / mu.template).write_text(original)
        camp.verdicts.append(mark(Verdict(mu.id, t.name, status, detail, round(seconds, 1),
                                          None, mu.before, mu.after, mu.cls,
                                          unified_diff(mu) if status in ("survived", "hung")
                                          else "")))
        if on_verdict is not None:
            on_verdict(camp.verdicts[-1])
        reason = camp.verdicts[-1].equivalent
        log(f"[{n}/{len(mutants)}] {mu.id} ({t.name}): {status}"
            f"{' (equivalent)' if reason and not reason.startswith('STALE') else ''}"
            f" {seconds:.1f} s")
    shutil.rmtree(templates)
    return camp


def mark(v: Verdict, eq: dict[str, dict] | None = None) -> Verdict:
    """A survivor's reason from the reviewed list of equivalents (read afresh: entries are
    added while a campaign runs), flagged STALE if the entry's text is not the mutant's."""
    entry = (equivalents() if eq is None else eq).get(v.id)
    v.equivalent = None
    if entry and v.status in ("survived", "hung"):
        stale = entry.get("before") != v.before or entry.get("after") != v.after
        v.equivalent = ("STALE (the entry's text is not this mutant's): " if stale else "") + \
            entry["reason"]
    return v


def scores(camp: Campaign) -> dict[str, dict]:
    """Per target: counts and the score killed / (scored - equivalent)."""
    rows: dict[str, dict] = {}
    for v in camp.verdicts:
        r = rows.setdefault(v.target, {"mutants": 0, "killed": 0, "survived": 0, "hung": 0,
                                       "stillborn": 0, "equivalent": 0})
        r["mutants"] += 1
        r[v.status] += 1
        if v.status in ("survived", "hung") and v.equivalent and \
                not v.equivalent.startswith("STALE"):
            r["equivalent"] += 1
    total = {k: sum(r[k] for r in rows.values()) for k in
             ("mutants", "killed", "survived", "hung", "stillborn", "equivalent")}
    for r in [*rows.values(), total]:
        scored = r["mutants"] - r["stillborn"]
        r["killed_pct"] = round(100 * r["killed"] / scored, 1) if scored else None
        real = scored - r["equivalent"]
        r["score_pct"] = round(100 * r["killed"] / real, 1) if real else None
        r["unexplained"] = r["survived"] + r["hung"] - r["equivalent"]
    return {**dict(sorted(rows.items())), "all": total}


def write_report(camp: Campaign, out: Path, command: str) -> tuple[Path, Path]:
    table = scores(camp)
    out.mkdir(parents=True, exist_ok=True)
    data = {"command": command, "simulator": SIM, "total_mutants": camp.total,
            "unreached": camp.unreached, "baseline_seconds": camp.baseline, "scores": table,
            "verdicts": [asdict(v) for v in camp.verdicts]}
    json_path, md_path = out / "report.json", out / "report.md"
    atomic_write_text(json_path, json.dumps(data, indent=1))
    lines = ["# Mutants of the generated SystemVerilog\n", f"`{command}` on {SIM}: "
             f"{len(camp.verdicts)} of {camp.total} mutants run ({camp.unreached} more sites "
             "no config renders).\n",
             "score = killed / (run - stillborn - equivalent); killed % = killed / "
             "(run - stillborn)\n",
             "| target | mutants | killed | survived | hung | stillborn | equivalent | "
             "unexplained | killed % | score % |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in table.items():
        lines.append(f"| {name} | {r['mutants']} | {r['killed']} | {r['survived']} | "
                     f"{r['hung']} | {r['stillborn']} | {r['equivalent']} | {r['unexplained']} "
                     f"| {r['killed_pct']} | {r['score_pct']} |")
    for title, keep in (("Survivors not explained (test gaps)",
                         lambda v: not v.equivalent or v.equivalent.startswith("STALE")),
                        ("Equivalent survivors", lambda v: v.equivalent
                         and not v.equivalent.startswith("STALE"))):
        group = [v for v in camp.verdicts if v.status in ("survived", "hung") and keep(v)]
        lines += ["", f"## {title} ({len(group)})", ""]
        for v in group:
            lines += [f"### `{v.id}` ({v.target}, {v.status})", ""]
            if v.equivalent:
                lines += [f"Equivalent: {v.equivalent}", ""]
            lines += ["```diff", v.diff.rstrip(), "```", ""]
    stillborn = [v for v in camp.verdicts if v.status == "stillborn"]
    lines += ["", f"## Stillborn ({len(stillborn)})", ""]
    lines += [f"- `{v.id}` ({v.target}): {v.detail}" for v in stillborn]
    atomic_write_text(md_path, "\n".join(lines) + "\n")
    return json_path, md_path


def campaign(module: str | None = None, ids: list[str] | None = None,
             sample: int | None = None, seed: int = 1, shards: int = 1, shard: int = 0,
             level: str = "quick", out: Path = Path("build/mutants"), list_only: bool = False,
             command: str = "gpf mutants", log=print) -> Path | None:
    """Scan, assign, select, run and report; with `list_only`, print the selection only."""
    # a listing renders in a folder of its own (a campaign may be running in out/work)
    work = Path(tempfile.mkdtemp(prefix="gpf-mutants-")) if list_only else out / "work"
    work.mkdir(parents=True, exist_ok=True)
    # only the templates the selection can reach: a module's own, a mutant id's
    names = None
    if ids:
        names = sorted({i.split(":")[0] for i in ids})
    elif module:
        names = owned_templates(module)
    mutants = scan_dir(TEMPLATE_DIR, names)
    assigned = assign_targets(mutants, work)
    chosen = select(mutants, assigned, module, ids, sample, seed, shards, shard)
    if list_only:
        for mu in chosen:
            log(f"{mu.id}\t{' '.join(t.name for t in assigned[mu.id])}\t"
                f"{mu.before!r} -> {mu.after!r}")
        shutil.rmtree(work, ignore_errors=True)
        return None
    in_scope = [mu for mu in mutants if assigned[mu.id]
                and (module is None or assigned[mu.id][0].module == module)]
    unreached = sum(not a for a in assigned.values())
    log(f"gpf mutants: {len(chosen)} of {len(in_scope)} mutants ({unreached} sites of "
        f"{len(mutants)} rendered in no config), level {level}, {SIM}")
    partial = Campaign([], unreached, len(in_scope))

    def update(v: Verdict) -> None:   # the report rewritten after each: an interrupted run
        partial.verdicts.append(v)     # keeps what it did
        write_report(partial, out, command + f" (in progress: {len(partial.verdicts)} of "
                     f"{len(chosen)} run)")

    camp = run_campaign(chosen, assigned, work, level, log, on_verdict=update)
    camp.total = len(in_scope)
    camp.unreached = unreached
    json_path, md_path = write_report(camp, out, command)
    shutil.rmtree(work, ignore_errors=True)
    r = scores(camp)["all"]
    log(f"killed {r['killed']} of {r['mutants'] - r['stillborn']} ({r['killed_pct']} %), "
        f"equivalent {r['equivalent']}, score {r['score_pct']} %, unexplained "
        f"{r['unexplained']}, stillborn {r['stillborn']}")
    log(f"-> {md_path}, {json_path}")
    return md_path


def rerun_survivors(report: Path, level: str = "quick", log=print,
                    mark_only: bool = False) -> Path:
    """Run a report's survivors (and hung mutants) that the list of equivalents does not
    explain again, with the testbenches as they are now, and write the report back with their
    new verdicts and every survivor marked from the list (a killed mutant is not run again:
    strengthening a testbench adds checks, it removes none)."""
    data = json.loads(report.read_text())
    verdicts = [Verdict(**v) for v in data["verdicts"]]
    ids = [v.id for v in verdicts if v.status in ("survived", "hung")]
    if mark_only:   # the list of equivalents reviewed since: the report's marks again
        eq = equivalents()
        camp = Campaign([mark(v, eq) for v in verdicts], data["unreached"],
                        data["total_mutants"], data["baseline_seconds"])
        return write_report(camp, report.parent, data["command"])[1]
    # those the list explains would survive again: the others run
    eq = equivalents()
    ids = [i for i in ids if i not in eq]
    out = report.parent
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    mutants = scan_dir(TEMPLATE_DIR, sorted({i.split(":")[0] for i in ids}))
    by_id = {mu.id: mu for mu in mutants}
    missing = [i for i in ids if i not in by_id]
    if missing:
        raise RuntimeError(f"{report}: mutants no longer in the templates (a line changed; "
                           f"run the campaign again): {', '.join(missing)}")
    # the hung last: each may take its whole time limit
    hung = {v.id for v in verdicts if v.status == "hung"}
    chosen = sorted((by_id[i] for i in ids), key=lambda mu: mu.id in hung)
    assigned = assign_targets(chosen, work)
    log(f"gpf mutants: {len(chosen)} survivors of {report} again, level {level}, {SIM}")
    command = data["command"].split("; survivors run again")[0] + \
        f"; survivors run again: gpf mutants --survivors {report}"
    again: dict[str, Verdict] = {}

    def update(v: Verdict) -> None:   # the report rewritten after each: an interrupted run
        again[v.id] = v                # keeps what it did
        write_report(Campaign([mark(again.get(u.id, u)) for u in verdicts], data["unreached"],
                              data["total_mutants"], data["baseline_seconds"]), out, command)

    run_campaign(chosen, assigned, work, level, log, on_verdict=update)
    camp = Campaign([mark(again.get(v.id, v), eq) for v in verdicts], data["unreached"],
                    data["total_mutants"], data["baseline_seconds"])
    _, md_path = write_report(camp, out, command)
    shutil.rmtree(work, ignore_errors=True)
    return md_path


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1:]))
