"""Model speed: particle-steps per second of the fixed-point and float64 GPFs, and GRNG samples
per second. Run: python -m gpf.model.bench_models [--particles N] [--steps K] [--repeat R]

Figures are printed, never asserted: tests check behaviour, this measures it.
"""

from __future__ import annotations

import argparse
import time

from gpf.config import load_config
from gpf.model.fixed_gpf import FixedGPF, run
from gpf.model.float_gpf import FloatGPF
from gpf.model.grng import GrngModel
from gpf.study.montecarlo import DEFAULT_SCENARIO, SCENARIOS


def best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=2048)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    n, steps = args.particles, args.steps
    print("| model | app | N | steps | particle-steps/s | draws included |")
    print("|---|---|---|---|---|---|")
    for name in ("bot", "uav"):
        cfg = load_config(f"configs/{name}.toml")
        sc = SCENARIOS[DEFAULT_SCENARIO[cfg.app]](cfg, steps, 1)
        fixed = FixedGPF(cfg, particles=n)
        draws = fixed.draws(steps, seed=1)
        run(fixed, sc, draws=draws)  # warm: LUTs and jump tables are built once
        t_fixed = best_of(args.repeat, lambda f=fixed, s=sc, d=draws: run(f, s, draws=d))
        t_draws = best_of(args.repeat, lambda f=fixed: f.draws(steps, seed=2))
        real = fixed.dp.noise.to_real(draws)
        flt = FloatGPF(cfg, n)
        t_float = best_of(args.repeat, lambda f=flt, s=sc, d=real: f.run(s, draws=d))
        work = n * steps
        print(f"| fixed point | {name} | {n} | {steps} | {work / t_fixed:,.0f} | no |")
        print(f"| fixed point | {name} | {n} | {steps} | {work / (t_fixed + t_draws):,.0f} "
              f"| yes (GRNG model) |")
        print(f"| float64 | {name} | {n} | {steps} | {work / t_float:,.0f} | no |")
    grng = GrngModel(load_config("configs/bot.toml"), lanes=6)
    grng.normals_raw(1 << 17)
    samples = 6 * 200_000
    t = best_of(args.repeat, lambda: grng.normals_raw(samples // 6))
    print(f"\nGRNG model: {samples / t:,.0f} samples/s (6 lanes)")


if __name__ == "__main__":
    main()
