"""The whole-filter escalation runs of `gpf mutants` (gpf/mutants.py FILTER_ESCALATION) each aim at
one flag's path; checked here with the bit-exact model, so a change of config or model that
took a run's reason away fails here instead of letting its mutants survive unnoticed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gpf.config import config_path, load_config
from gpf.model.fixed_gpf import FixedGPF, ess_threshold, step_results
from gpf.model.scenarios import bot_bearing_glitch, read_csv
from gpf.mutants import FILTER_ESCALATION, FILTER_RUN, GENERATED_SCENARIOS

TAIL = 48   # particles still in flight when ctrl leaves S_RUN (at least the pipeline's depth)


def steps_of(cfg, scenario, particles: int) -> list:
    """Each step's model result with its particles' SAT taps (GRNG seed 1, as the runs)."""
    g = FixedGPF(cfg, particles)
    return list(step_results(g, scenario, g.draws(scenario.steps, 1), keep_particles=True))


def sat(r, tap: str) -> np.ndarray:
    """Per particle: the tap's SAT in any component."""
    a = np.asarray(r.particles[tap])
    return a.reshape(len(a), -1).any(axis=1)


def generated(name: str, tmp_path: Path, lanes: int = 1):
    cfg = load_config(config_path("bot"), {"filter.lanes": lanes})
    # as the mutant runs read it (gpf.run, no check of the initial state against the config:
    # these start at the rail on purpose)
    return cfg, read_csv(GENERATED_SCENARIOS[name](cfg, tmp_path / f"{name}.csv"))


def particles_of(name: str) -> int:
    return next(r[3] for r in FILTER_ESCALATION if r[0] == name)


def test_near_rail_saturates_only_early_particles_in_some_step(tmp_path: Path) -> None:
    cfg, sc = generated("bot_near_rail", tmp_path)
    n = particles_of("bot_near_rail")
    early_only = [k for k, r in enumerate(steps_of(cfg, sc, n))
                  if (sat(r, "cond_sat") | sat(r, "prop_sat"))[:n - TAIL].any()
                  and not (sat(r, "cond_sat") | sat(r, "prop_sat"))[n - TAIL:].any()]
    assert early_only, "no step saturates early particles only"


def test_cond_rail_saturates_in_sample_cond_alone(tmp_path: Path) -> None:
    cfg, sc = generated("bot_cond_rail", tmp_path, lanes=2)
    results = steps_of(cfg, sc, particles_of("bot_cond_rail"))
    alone = [k for k, r in enumerate(results) if sat(r, "cond_sat").any()
             and not sat(r, "prop_sat").any() and not sat(r, "weight_sat").any()]
    assert alone, "no step whose only saturation is sample_cond's"


def test_far_observer_saturates_in_weight_alone(tmp_path: Path) -> None:
    cfg, sc = generated("bot_far_observer", tmp_path)
    for r in steps_of(cfg, sc, particles_of("bot_far_observer")):
        assert sat(r, "weight_sat").all()
        assert not sat(r, "cond_sat").any() and not sat(r, "prop_sat").any()


@pytest.mark.parametrize("particles", [particles_of("bot_bearing_glitch")])
def test_bearing_glitch_puts_the_ess_on_the_threshold(particles: int) -> None:
    cfg = load_config(config_path("bot"))
    sc = bot_bearing_glitch(cfg, FILTER_RUN["steps"], 1)
    threshold = ess_threshold(FixedGPF(cfg, particles).dp, particles)
    assert any(r.ess == threshold for r in steps_of(cfg, sc, particles))
