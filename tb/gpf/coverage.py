"""Functional coverage of the whole filter: the group `gpf.<app>` (see tb/coverage.py).

Sampled once a run is over (FilterBench.run) from what the simulation carried, every value of
which the scoreboard has compared with the model: the m_est beats (each step's flags), the tap
beats (each particle after sample_cond and after propagate, its weight, the beat's shift) and
their tlast, the stall records (cocotb's stream drivers' or gpf_<app>_harness's counts); and by
a reset half-way through a step.

  lanes          LANES 1, 2, 4
  particles      the run's N: N = LANES, N / LANES odd (an odd number of beats a step, more than
                 one), N = the maximum, any other; an init N clamped up (below LANES), clamped
                 down (above the maximum), rounded up to a multiple of LANES
  shape          the cross of lanes and the particle kinds (N = LANES, odd, maximum)
  flags          each step flag raised (set, not set the step before) and cleared
  rail           each component after sample_cond (cond) and after propagate (prop) at its
                 format's top or bottom: its saturation, per direction
  weight         the normalisation path (a beat after a step's first whose shift rescaled the
                 sums; a step with no rescale), a collapse (LOW_ESS: the next step samples from
                 the predicted covariance), no particle within reach (ZERO_WEIGHTS), a saturated
                 weight
  tlast          on the cond and part taps: a step of one beat (tlast on it), of many (tlast on
                 the last only); on gpf_<app>_axi's m_est: every beat
  stall.<port>   s_step (tb idle gaps, the filter's backpressure), m_cond, m_part, m_est (clocks
                 a beat waited for tready)
  reset          a reset while a step's tap beats were part-way out, and a clean run after it
"""

from __future__ import annotations

import numpy as np

from gpf.model.blocks import Flag
from gpf.tb import coverage

KINDS = ("N = LANES", "N/LANES odd", "N = maximum")
PARTICLES = (*KINDS, "N other", "init N clamped up", "init N clamped down",
             "init N rounded up")
WEIGHT = ("rescale", "no rescale", "collapse (low_ess)", "no particle in reach (zero_weights)",
          "weight sat")
TLAST = ("cond: one-beat step", "cond: last of many", "part: one-beat step",
         "part: last of many", "est: every beat (axi)")
RESET = ("mid-step", "clean run after it")


def filter_group(app: str, n: int):
    g = coverage.group(f"gpf.{app}")
    g.point("lanes", (f"lanes {k}" for k in coverage.LANES))
    g.point("particles", PARTICLES)
    g.point("shape", (f"lanes {k} x {kind}" for k in coverage.LANES for kind in KINDS))
    g.point("flags", coverage.flag_bins())
    g.point("rail", (f"{tap} x{i}:{end}" for tap in ("cond", "prop") for i in range(n)
                     for end in ("max", "min")))
    g.point("weight", WEIGHT)
    g.point("tlast", TLAST)
    for port in ("s_step", "m_cond", "m_part", "m_est"):
        g.point(f"stall.{port}", coverage.SOURCE_BINS if port.startswith("s_")
                else coverage.SINK_BINS)
    g.point("reset", RESET)
    return g


def particle_bins(particles: int, lanes: int, most: int, sent: int | None) -> list[str]:
    beats = particles // lanes
    out = [kind for kind, hit in zip(KINDS, (beats == 1, beats > 1 and beats % 2 == 1,
                                             particles == most), strict=True) if hit]
    if not out:
        out.append("N other")
    if sent is not None:
        if sent < lanes:
            out.append("init N clamped up")
        elif sent > most:
            out.append("init N clamped down")
        elif sent % lanes:
            out.append("init N rounded up")
    return out


def sample_run(fb, got: list, est_lasts: list[bool] | None, step_source, sinks: dict) -> None:
    """A whole run of FilterBench (fb): `got` every step's beats as scored (feeds.StepBeats);
    m_est's tlast per beat where it has one (gpf_<app>_axi); the step stream's and the outputs'
    stall records (`gaps`, `waits`: Source, Sink or feeds.Stalls)."""
    if not coverage.enabled() or fb.corrupt or fb.mismatches or not got:
        return
    gpf, s, lanes = fb.gpf, fb.s, fb.gpf.cfg.lanes
    dp = gpf.dp
    g = filter_group(dp.app, dp.n)
    g.hit("lanes", f"lanes {lanes}")
    kinds = particle_bins(gpf.particles, lanes, gpf.cfg.particles, fb.spec.init_particles)
    g.hit("particles", *kinds)
    g.hit("shape", *(f"lanes {lanes} x {k}" for k in kinds if k in KINDS))
    def joined(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    est = joined([st.est for st in got])
    flags = est["flags"][:, 0]
    g.hit("flags", *coverage.flags_hit(flags))
    cond, part = (joined([st.taps[tap] for st in got]) for tap in ("cond", "part"))
    rails = coverage.rails_hit(s.cond[:dp.n], cond, "cond ")
    rails += coverage.rails_hit(s.part[:dp.n], part, "prop ")
    g.hit("rail", *rails)
    beats = gpf.particles // lanes
    shift = part["shift"][:, 0].reshape(-1, beats)
    later = shift[:, 1:] != 0
    weight = []
    if np.any(later):
        weight.append("rescale")
    if not np.all(np.any(later, axis=1)):
        weight.append("no rescale")
    if np.any(flags & int(Flag.LOW_ESS)):
        weight.append("collapse (low_ess)")
    if np.any(flags & int(Flag.ZERO_WEIGHTS)):
        weight.append("no particle in reach (zero_weights)")
    if np.any(part["sat"]):
        weight.append("weight sat")
    g.hit("weight", *weight)
    tlast = []
    for tap in ("cond", "part"):
        lasts = np.concatenate([st.lasts[tap] for st in got])
        if beats == 1 and lasts.all():
            tlast.append(f"{tap}: one-beat step")
        if beats > 1 and lasts.any():
            tlast.append(f"{tap}: last of many")
    if fb.ip and est_lasts and all(est_lasts):
        tlast.append("est: every beat (axi)")
    g.hit("tlast", *tlast)
    if hasattr(step_source, "gaps"):
        g.hit("stall.s_step", *coverage.source_bins(step_source.gaps, step_source.waits))
    for name, sink in sinks.items():
        if hasattr(sink, "waits"):
            g.hit(f"stall.m_{name}", *coverage.sink_bins(sink.waits))
    if getattr(fb, "interrupted", False):
        g.hit("reset", "clean run after it")
    coverage.save()


def sample_reset(fb, cond_beats: int) -> None:
    """A reset with `cond_beats` of a step's tap beats out (FilterBench.interrupted_step)."""
    if not coverage.enabled() or fb.corrupt:
        return
    dp, lanes = fb.gpf.dp, fb.gpf.cfg.lanes
    g = filter_group(dp.app, dp.n)
    if 0 < cond_beats < fb.gpf.particles // lanes:
        g.hit("reset", "mid-step")
        fb.interrupted = True
    coverage.save()
