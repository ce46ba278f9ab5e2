"""Model speed: particle-steps per second of the fixed-point and float64 GPFs, and GRNG samples
per second. Run: python -m gpf.model.bench_models [--particles N] [--steps K] [--runs R]

The Monte Carlo studies step R runs at once (FixedGPF.step_batch: every line-rate block runs
once over all R x N particles), so that is what is timed, with and without the GRNG model's
draws; one run at a time is timed too. Figures are printed, never asserted: tests check
behaviour, this measures it.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gpf.config import config_path, load_config
from gpf.model.fixed_gpf import FixedGPF
from gpf.model.float_gpf import FloatGPF
from gpf.model.grng import GrngModel, GrngStream
from gpf.model.scenarios import bot_fixed_observer, uav_flight


def best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def batch_run(gpf: FixedGPF, scs: list, stream: GrngStream | None, draws: np.ndarray | None
              ) -> None:
    """Every run of `scs` stepped together, the draws from `stream` a step at a time (or the
    given ones)."""
    flt = FloatGPF(gpf.cfg, gpf.particles)
    init = [gpf.init(*flt.initial(sc)) for sc in scs]
    mu = np.stack([m for m, _ in init])
    chol = np.stack([c for _, c in init])
    sigma = np.array([[gpf.quantise_sigma(flt.initial(sc)[1])[p] for p in gpf.pairs]
                      for sc in scs])
    real = {k: np.stack([{**sc.inputs, **sc.measurements}[k][1:] for sc in scs])
            for k in {**scs[0].inputs, **scs[0].measurements}}
    raw = gpf.quantise_batch(real)
    beats = gpf.particles // gpf.cfg.lanes
    for k in range(scs[0].steps):
        e = draws[:, k] if draws is not None else stream.next(beats).reshape(
            len(scs), gpf.particles, -1)
        res = gpf.step_batch(mu, chol, sigma, {key: a[:, k] for key, a in raw.items()}, e)
        mu, chol, sigma = res.mu, res.chol, res.sigma


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=512)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    n, steps, runs = args.particles, args.steps, args.runs
    print("| model | app | runs at once | N | steps | particle-steps/s |")
    print("|---|---|---|---|---|---|")
    for name, make in (("bot", bot_fixed_observer), ("uav", uav_flight)):
        cfg = load_config(config_path(name))
        gpf = FixedGPF(cfg, particles=n)
        scs = [make(cfg, steps, 1 + r) for r in range(runs)]
        grng = GrngModel(cfg, lanes=gpf.dp.draws() * cfg.lanes)
        draws = np.stack([gpf.draws(steps, seed=1 + r) for r in range(runs)], axis=0)
        batch_run(gpf, scs, None, draws)   # warm: LUTs and jump tables are built once
        work = runs * n * steps
        t_given = best_of(args.repeat, lambda g=gpf, s=scs, d=draws: batch_run(g, s, None, d))
        t_grng = best_of(args.repeat, lambda g=gpf, s=scs, m=grng: batch_run(
            g, s, GrngStream(m, list(range(1, runs + 1))), None))
        t_one = best_of(args.repeat, lambda g=gpf, s=scs, d=draws: [
            batch_run(g, [sc], None, d[r:r + 1]) for r, sc in enumerate(s[:4])])
        flt = FloatGPF(cfg, n)
        real = gpf.dp.noise.to_real(draws)
        t_float = best_of(args.repeat, lambda f=flt, s=scs, d=real: [
            f.run(sc, draws=d[r]) for r, sc in enumerate(s[:4])])
        print(f"| fixed point, draws given | {name} | {runs} | {n} | {steps} | "
              f"{work / t_given:,.0f} |")
        print(f"| fixed point with its GRNG draws | {name} | {runs} | {n} | {steps} | "
              f"{work / t_grng:,.0f} |")
        print(f"| fixed point, draws given | {name} | 1 | {n} | {steps} | "
              f"{4 * n * steps / t_one:,.0f} |")
        print(f"| float64, draws given | {name} | 1 | {n} | {steps} | "
              f"{4 * n * steps / t_float:,.0f} |")
    grng = GrngModel(load_config(config_path("bot")), lanes=6)
    stream = GrngStream(grng, list(range(runs)))
    stream.next(1 << 10)
    samples = 6 * runs * 20_000
    t = best_of(args.repeat, lambda: stream.next(20_000))
    print(f"\nGRNG model: {samples / t:,.0f} samples/s ({runs} generators x 6 lanes at once)")


if __name__ == "__main__":
    main()
