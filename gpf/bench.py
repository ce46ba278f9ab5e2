"""`make bench`: cycles per dependent filter step over N x LANES, beside the published design;
area (Yosys, xc7) beside seed 002's; Fmax (nextpnr-ecp5) and so time per step in microseconds
beside seed 003's; simulation speed: particles checked per second beside the bare simulator's
on the same RTL (`make bench PART=speed`, a few minutes; the whole bench runs place and route).

Cycle numbers come from the RTL under cocotb (gpf run's machinery), each run checked
bit-exactly; area and clock from gpf.synth and gpf.timing on the same generated RTL.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gpf.config import config_path, load_config
from gpf.outputs import write_json
from gpf.run import RunArgs, run_filter

SEED003_CYCLES = 3160       # seed 003's HLS design at N = 2048: 31.6 us at 100 MHz
SEED003_US = 31.6
# seed 002's whole GPF (uav, N = 2048, 24-bit words, Zynq 7z020), its Table of resources
SEED002_AREA = {"LUT": 10764, "FF": 16767, "DSP48E1": 89, "BRAM36": 6}
TIMING_MINUTES = 30         # a whole filter's place and route; past it, no Fmax is claimed
BUDGET = 256                # SPEC 9: N / LANES + 256
PARTICLES = (512, 1024, 2048)
LANES = (1, 2, 4)


def _run(config: str, lanes: int, particles: int, steps: int, sim: str,
         direct: bool = False) -> dict[str, Any]:
    cfg = load_config(config_path(config), {"filter.lanes": lanes})
    res = run_filter(cfg, RunArgs(steps, particles, 1, None, sim, False, direct=direct),
                     progress=False)
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


SPEED_PARTICLES, SPEED_STEPS = 2048, 100   # the whole bot filter's checking speed
ICARUS_PARTICLES, ICARUS_STEPS = 256, 3


def direct_bare_speed(config: str, lanes: int, particles: int, steps: int) -> float:
    """Particles a second of the direct run's binary alone (gpf_<app>_direct, nothing read or
    checked): the simulator's own speed on this RTL and harness."""
    from gpf.tb.gpf import direct

    cfg = load_config(config_path(config), {"filter.lanes": lanes})
    return steps * particles / direct.bare(cfg, steps, particles)


def bare_speed(config: str, lanes: int, particles: int, steps: int) -> float:
    """Particles a second of the simulator alone on the same RTL and harness: no model, nothing
    read or checked, cocotb only waiting for the last result (RunSpec.bare)."""
    cfg = load_config(config_path(config), {"filter.lanes": lanes})
    res = run_filter(cfg, RunArgs(steps, particles, 1, None, "verilator", False, bare=True),
                     progress=False)
    if not res["passed"] or res["particles_simulated"] != steps * particles:
        raise SystemExit(f"bench: the bare run of {config} LANES={lanes} failed (see "
                         f"{res['log']})")
    return res["particles_simulated"] / res["wall_seconds"]


def speed_table(config: str = "bot", particles: int = SPEED_PARTICLES,
                steps: int = SPEED_STEPS) -> tuple[list[str], dict]:
    """Particles checked a second (every particle, weight and estimate bit-exact), beside the
    bare simulator's speed on the same RTL, at LANES 1, 2 and 4 on Verilator: the direct run
    (no cocotb) and its binary alone, the cocotb run and the harness alone under cocotb; Icarus
    at LANES 1 on a short run."""
    rows = {}
    for lanes in LANES:
        checked = _run(config, lanes, particles, steps, "verilator", direct=True)
        bare = direct_bare_speed(config, lanes, particles, steps)
        cocotb = _run(config, lanes, particles, steps, "verilator")["particles_per_second"]
        cocotb_bare = bare_speed(config, lanes, particles, steps)
        rows[lanes] = {"checked": round(checked["particles_per_second"]), "bare": round(bare),
                       "ratio": round(checked["particles_per_second"] / bare, 3),
                       "cocotb_checked": round(cocotb), "cocotb_bare": round(cocotb_bare)}
    icarus = _run(config, 1, ICARUS_PARTICLES, ICARUS_STEPS, "icarus")["particles_per_second"]
    lines = [f"simulation speed, {config}, N = {particles}, {steps} steps, every particle, "
             "weight and estimate checked bit for bit (Verilator). Direct: gpf run --direct, "
             "no cocotb; bare: its binary alone, nothing checked; cocotb: gpf run, and the "
             "harness alone under cocotb:", "",
             "| LANES | direct, particles checked / s | bare simulator, particles / s | "
             "direct / bare | cocotb, checked / s | cocotb, harness alone / s |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {lanes} | {r['checked']} | {r['bare']} | {r['ratio']:.2f} | "
              f"{r['cocotb_checked']} | {r['cocotb_bare']} |" for lanes, r in rows.items()]
    lines.append(f"\nIcarus, N = {ICARUS_PARTICLES}, {ICARUS_STEPS} steps, LANES 1: "
                 f"{icarus:.0f} particles checked / s")
    return lines, {"verilator": rows, "icarus": round(icarus)}


def area_table(configs: tuple[str, ...] = ("bot", "uav")) -> tuple[list[str], dict]:
    from gpf.synth import COLUMNS, format_area, synthesize

    cfgs = [load_config(config_path(c)) for c in configs]
    areas = [synthesize(cfg, f"gpf_{cfg.app}") for cfg in cfgs]
    lines = ["area, Yosys synth_xilinx -family xc7, LANES 1, per block:", ""]
    lines += format_area(areas)
    lines.append("| seed 002 (uav, N = 2048, 24-bit) | 1 | whole GPF | " + " | ".join(
        f"{SEED002_AREA[c]}" if c in SEED002_AREA else "-" for c in COLUMNS) + " | |")
    return lines, {a.config: a.to_json() for a in areas}


def clock_table(cycles: dict[str, dict]) -> tuple[list[str], dict]:
    """Fmax of each whole filter at LANES 1 on the ECP5, and time per step at N = 2048."""
    from gpf.synth import SynthError
    from gpf.timing import place_and_route

    lines = ["clock, nextpnr-ecp5 (LFE5U-85F, out of context), LANES 1; time per step at "
             f"N = 2048 = clocks / Fmax (seed 003: {SEED003_US} us):", "",
             "| config | Fmax MHz | critical path | clocks per step | us per step | "
             "vs seed 003 |", "|---|---|---|---|---|---|"]
    out = {}
    for config, rows in cycles.items():
        cfg = load_config(config_path(config))
        clocks = rows[2048][1]
        try:
            t = place_and_route(cfg, f"gpf_{cfg.app}", timeout=TIMING_MINUTES * 60)
        except SynthError as exc:
            lines.append(f"| {config} | - ({str(exc)[:60]}) | | {clocks} | - | - |")
            continue
        us = clocks / t.fmax_mhz
        out[config] = {**t.to_json(), "clocks": clocks, "us_per_step": round(us, 2)}
        lines.append(f"| {config} | {t.fmax_mhz:.1f} | {t.path_from} -> {t.path_to} | "
                     f"{clocks} | {us:.1f} | {SEED003_US / us:.2f}x |")
    return lines, out


PARTS = ("cycles", "area", "clock", "speed")


def main(argv: list[str] | None = None, out: Path = Path("build/bench.json")) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m gpf.bench", description=__doc__)
    parser.add_argument("--part", choices=PARTS, action="append",
                        help="only this part (repeatable; default: all; clock needs cycles)")
    parts = parser.parse_args(argv).part or list(PARTS)
    report: dict[str, Any] = {}
    if "cycles" in parts or "clock" in parts:
        for config in ("bot", "uav"):
            lines, rows = cycles_table(config)
            report[config] = rows
            print("\n".join(lines), "\n", flush=True)
    if "area" in parts:
        lines, report["area"] = area_table()
        print("\n".join(lines), "\n", flush=True)
    if "clock" in parts:
        lines, report["clock"] = clock_table({c: report[c] for c in ("bot", "uav")})
        print("\n".join(lines), "\n", flush=True)
    if "speed" in parts:
        lines, report["particles_per_second"] = speed_table()
        print("\n".join(lines))
    if parts != list(PARTS):   # a part alone: its own file, the whole bench's left as it is
        out = out.with_name(f"bench-{'-'.join(parts)}.json")
    write_json(out, report)
    print(f"\n-> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
