"""`make bench`: cycles per dependent filter step over N x LANES, beside the published design,
and simulation speed (particles checked per second) on Verilator and Icarus.

Numbers come from the RTL under cocotb (gpf run's machinery), each run checked bit-exactly.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from gpf.config import load_config
from gpf.run import RunArgs, run_filter

SEED003_CYCLES = 3160       # seed 003's HLS design at N = 2048: 31.6 us at 100 MHz
BUDGET = 256                # SPEC 9: N / LANES + 256
PARTICLES = (512, 1024, 2048)
LANES = (1, 2, 4)


def _run(config: str, lanes: int, particles: int, steps: int, sim: str) -> dict[str, Any]:
    cfg = load_config(f"configs/{config}.toml", {"filter.lanes": lanes})
    res = run_filter(cfg, RunArgs(steps, particles, 1, None, sim, False), progress=False)
    if res["mismatches"] or not res["passed"]:
        raise SystemExit(f"bench: {config} N={particles} LANES={lanes} on {sim} failed: "
                         f"{res['first_mismatch']} (see {res['log']})")
    return res


def cycles_table(config: str, steps: int = 2) -> tuple[list[str], dict]:
    rows: dict[int, dict[int, int]] = {}
    for lanes in LANES:
        for n in PARTICLES:
            rows.setdefault(n, {})[lanes] = max(_run(config, lanes, n, steps,
                                                     "verilator")["cycles_per_step"])
    head = " | ".join(f"LANES {p}" for p in LANES)
    lines = [f"{config}: clocks per dependent step (bar: N/LANES + {BUDGET}; seed 003: "
             f"{SEED003_CYCLES} at N = 2048)", "", f"| N | {head} |",
             "|---" * (len(LANES) + 1) + "|"]
    for n, by_lanes in rows.items():
        cells = []
        for p in LANES:
            c = by_lanes[p]
            cells.append(f"{c} (N/P + {c - n // p})")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    best = rows[2048]
    lines.append("")
    ratios = ", ".join(f"LANES {p} {SEED003_CYCLES / best[p]:.2f}x" for p in LANES)
    lines.append(f"N = 2048: {ratios} fewer clocks per step than seed 003")
    return lines, rows


def speed_table(config: str = "bot", particles: int = 1024, steps: int = 4
                ) -> tuple[list[str], dict]:
    speed = {sim: _run(config, 1, particles, steps, sim)["particles_per_second"]
             for sim in ("verilator", "icarus")}
    lines = [f"simulation speed, {config}, N = {particles}, LANES 1, every particle checked:",
             "", "| simulator | particles checked / s |", "|---|---|"]
    lines += [f"| {sim} | {v:.0f} |" for sim, v in speed.items()]
    lines.append(f"\nVerilator / Icarus: {speed['verilator'] / speed['icarus']:.1f}x")
    return lines, speed


def main(out: Path = Path("build/bench.json")) -> int:
    report: dict[str, Any] = {}
    for config in ("bot", "uav"):
        lines, rows = cycles_table(config)
        report[config] = rows
        print("\n".join(lines), "\n", flush=True)
    lines, speed = speed_table()
    report["particles_per_second"] = speed
    print("\n".join(lines))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"\n-> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
