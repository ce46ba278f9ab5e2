"""Time mul_round on an int64 format pair and on one that needs object arrays.

Run: python -m gpf.model.bench_fixed [-n COUNT] [--repeats R]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gpf.model.fixed import Format, mul_round

# (a, b, out): s3.20 products need 48 bits (int64); s30.30 products need 122 bits (object).
CASES = [("s3.20", "s3.20", "s3.20"), ("s30.30", "s30.30", "s30.30")]


def time_mul_round(fa: Format, fb: Format, out: Format, n: int, repeats: int) -> tuple[float, str]:
    """Best-of-`repeats` ns per element of mul_round on n random values; also the result dtype."""
    rng = np.random.default_rng(0)
    # Inputs drawn as int64, so the input formats must fit it; the products need not.
    a = rng.integers(fa.min_raw, fa.max_raw, size=n, endpoint=True, dtype=np.int64)
    b = rng.integers(fb.min_raw, fb.max_raw, size=n, endpoint=True, dtype=np.int64)
    best = float("inf")
    dtype = ""
    for _ in range(repeats):
        start = time.perf_counter()
        raw, _flag = mul_round(a, fa, b, fb, out, "half_up")
        best = min(best, time.perf_counter() - start)
        dtype = str(raw.dtype)
    return best / n * 1e9, dtype


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=1_000_000, help="values per call")
    parser.add_argument("--repeats", type=int, default=3, help="best of this many calls")
    args = parser.parse_args(argv)
    results = []
    for texts in CASES:
        fa, fb, out = (Format.parse(t) for t in texts)
        ns, dtype = time_mul_round(fa, fb, out, args.n, args.repeats)
        results.append(ns)
        print(f"mul_round {fa} x {fb} -> {out}: {ns:8.1f} ns/element ({dtype}, n={args.n})")
    print(f"ratio object / int64: {results[1] / results[0]:.1f}x")


if __name__ == "__main__":
    main()
