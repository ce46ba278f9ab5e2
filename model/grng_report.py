"""Measured quality of the GRNG, as a markdown table for the README.

    python -m gpf.model.grng_report [--samples N] [--seed S] [--config bot --config odd]

One column per config (default: configs/bot.toml and configs/odd.toml, both run with 2 lanes so
that cross-lane correlation can be measured). The static rows come from the LUT itself, the
error rows from every offset of every segment (the worst case over all uniform words above the
tail clamp), the statistical rows from N samples per lane of the bit-exact model. Needs scipy
(a dev dependency). Takes about 20 s for the two default configs.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy import special, stats

from gpf.config import config_path, load_config
from gpf.model.grng import COMPONENTS, LFSR258, GrngModel

DEFAULT_CONFIGS = ("bot", "odd")
SIGN = np.uint64(1 << 63)
LAGS = range(1, 9)
CROSS_LAGS = range(-2, 3)


def lfsr_period_log2() -> float:
    """log2 of the period of the combined generator: prod(2^k_j - 1) over the components."""
    degrees = [64 - (mask ^ ((1 << 64) - 1)).bit_length() for *_, mask in LFSR258]
    return sum(math.log2(2.0 ** k - 1) for k in degrees)


def sweep_lut(model: GrngModel) -> tuple[float, int, int]:
    """Every offset of every segment: (worst |error| in LSBs over any p in each offset's bin,
    number of places where |z| grows with p, by how many LSBs at most)."""
    seg, frac = model.seg, model.out.frac_bits
    size = 1 << seg.offset_bits
    xs = np.arange(size, dtype=np.int64)
    edges = np.arange(size + 1) / size
    worst, reversals, biggest, previous = 0.0, 0, 0, None
    # p increases with the address within an octave and towards octave 0
    for k in reversed(range(seg.octaves)):
        for j in range(1 << seg.segment_bits):
            addr = k << seg.segment_bits | j
            mag = model._horner(np.full(size, addr), xs)
            p = 2.0 ** -(k + 1) * (1 + (j + edges) / (1 << seg.segment_bits))
            exact = -special.ndtri(p / 2) * (1 << frac)
            err = np.maximum(np.abs(mag - exact[:-1]), np.abs(mag - exact[1:]))
            worst = max(worst, float(err.max()))
            steps = np.diff(mag if previous is None else np.concatenate([[previous], mag]))
            reversals += int(np.count_nonzero(steps > 0))
            biggest = max(biggest, int(steps.max()))
            previous = mag[-1]
    return worst, reversals, biggest


def autocorrelation(x: np.ndarray, lags: range) -> float:
    xc = x - x.mean()
    den = float(np.dot(xc, xc))
    return max(abs(float(np.dot(xc[:-k], xc[k:]))) / den for k in lags)


def cross_correlation(a: np.ndarray, b: np.ndarray, lags: range) -> float:
    ac, bc = a - a.mean(), b - b.mean()
    den = math.sqrt(float(np.dot(ac, ac)) * float(np.dot(bc, bc)))
    n, out = a.size, 0.0
    for k in lags:
        dot = np.dot(ac[: n - k], bc[k:]) if k >= 0 else np.dot(ac[-k:], bc[: n + k])
        out = max(out, abs(float(dot)) / den)
    return out


def measure(name: str, samples: int, seed: int | None) -> dict[str, str]:
    cfg = load_config(config_path(name), {"filter.lanes": 2})
    model = GrngModel(cfg)
    seg, fmt = model.seg, model.out
    widths = model.coef_widths
    top = int(model.from_uniforms(np.array([0], dtype=np.uint64))[0])  # p = 0: the clamp
    z_max = top * fmt.lsb
    worst, reversals, biggest = sweep_lut(model)
    points = seg.depth << seg.offset_bits

    used_seed = cfg.grng.seed if seed is None else seed
    z = model.normals(samples, seed=used_seed)
    pooled = z.ravel()
    rng = np.random.default_rng(used_seed)
    deq = pooled + rng.uniform(-fmt.lsb / 2, fmt.lsb / 2, size=pooled.shape)
    ks = stats.kstest(deq, "norm")
    beyond = int(np.count_nonzero(np.abs(pooled) > 4.0))
    expected = pooled.size * 2 * stats.norm.sf(4.0)
    auto = max(autocorrelation(z[:, i], LAGS) for i in range(z.shape[1]))
    cross = max(cross_correlation(z[:, a], z[:, b], CROSS_LAGS)
                for a in range(z.shape[1]) for b in range(a + 1, z.shape[1]))
    scale = 1 / math.sqrt(samples)

    return {
        "Config": f"`{Path(cfg.source).name}`",
        "Output format": f"{fmt} (LSB 2^-{fmt.frac_bits})",
        "LUT: octaves x segments = words": (f"{seg.octaves} x {1 << seg.segment_bits} = "
                                            f"{seg.depth}"),
        "Offset bits / guard bits": f"{seg.offset_bits} / {model.guard_bits}",
        "ROM word: c0 + c1 + c2 bits": f"{widths[0]} + {widths[1]} + {widths[2]} = {sum(widths)}",
        "Per sample": "1 LUT read, 2 multiplies, no log/sqrt/sin/cos",
        "Max error, 64 offsets per segment (`max_abs_error`)":
            f"{model.max_abs_error():.3f} LSB",
        "Max error, every offset, any p in its bin": f"{worst:.3f} LSB",
        "\\|z\\| growing with p (all offsets)":
            f"{reversals} of {points:.2e} steps, each <= {biggest} LSB",
        "Largest reachable \\|z\\| (p < 2^-K clamped)":
            f"{z_max:.3f} sigma (N(0,1) mass beyond: {2 * stats.norm.sf(z_max):.1e})",
        "Uniform source": (f"LFSR258 per lane ({COMPONENTS} components), period "
                           f"2^{lfsr_period_log2():.1f}"),
        "Samples": f"{samples:,} x {z.shape[1]} lanes (seed {used_seed})",
        "Mean": f"{pooled.mean():+.5f} (sd of estimate {1 / math.sqrt(pooled.size):.5f})",
        "Std": f"{pooled.std():.5f}",
        "KS D (p-value), dequantised": f"{ks.statistic:.5f} ({ks.pvalue:.2f})",
        "Beyond 4 sigma: observed / expected": f"{beyond} / {expected:.1f}",
        "Max \\|autocorrelation\\|, lags 1..8": f"{auto:.5f} (1/sqrt(n) = {scale:.5f})",
        "Max \\|cross-lane correlation\\|, lags -2..2": f"{cross:.5f} (1/sqrt(n) = {scale:.5f})",
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m gpf.model.grng_report",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000, help="samples per lane")
    parser.add_argument("--seed", type=int, default=None,
                        help="seed load of the model (default: each config's reset seed)")
    parser.add_argument("--config", action="append", default=[],
                        help="config name in configs/ or a TOML path (repeatable)")
    args = parser.parse_args(argv)
    if args.samples < 10:
        parser.error(f"--samples {args.samples}: must be at least 10")
    columns = [measure(c, args.samples, args.seed) for c in args.config or DEFAULT_CONFIGS]
    rows = list(columns[0])
    print("| " + " | ".join(["Quantity"] + [c[rows[0]] for c in columns]) + " |")
    print("|" + " --- |" * (len(columns) + 1))
    for row in rows[1:]:
        print("| " + " | ".join([row] + [c[row] for c in columns]) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
