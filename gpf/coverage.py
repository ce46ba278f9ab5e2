"""`gpf coverage`: the functional coverage of every run merged, each bin with its hits, each
bin never hit with its reason from a reviewed file of known holes; and the code coverage of the
Verilator runs built with COVERAGE=1 (gpf/code_coverage.py).

build/coverage/func/*.yml   one per simulation run (tb/coverage.py), cocotb-coverage's YAML
build/coverage/merged.yml   cocotb-coverage's merge of them
build/coverage/report.md    every group, point and bin with its hits; the holes with their reasons
build/coverage/report.json  the same as data

The holes file (tests/data/coverage/holes.toml) maps a bin, `<point>:<bin>` with fnmatch
wildcards (`*`, `?`, `[...]`), to why it is unreachable or not yet exercised. A bin with no hit
and no reason fails the check (`gpf coverage` exits 1), as does an empty reason. A group that no
run sampled shows as one bin, `<group>:(never sampled)`.
"""

from __future__ import annotations

import fnmatch
import json
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

from gpf.outputs import atomic_write_text

DEFAULT_DIR = Path("build") / "coverage"
HOLES = Path(__file__).resolve().parent.parent / "tests" / "data" / "coverage" / "holes.toml"
NEVER = "(never sampled)"


def expected_groups() -> list[str]:
    """Every group a complete regression samples: the whole filter of each application and
    each block of it (tb/streaming.py's run_stream, and the GRNG's check)."""
    from gpf.rtl.generate import MODULES

    out = []
    for app in ("bot", "uav"):
        out.append(f"gpf.{app}")
        out += [f"{name}.{app}" for name, m in MODULES.items()
                if app in m.apps and m.simulated
                and not name.startswith("gpf_")]
    return out


@dataclass
class Bin:
    point: str
    name: str
    hits: int
    reason: str | None = None     # a hole's, from the holes file

    @property
    def key(self) -> str:
        return f"{self.point}:{self.name}"


@dataclass
class Report:
    runs: list[str]
    bins: list[Bin]
    stale: list[str] = field(default_factory=list)   # holes-file patterns no unhit bin matches

    @property
    def hit(self) -> int:
        return sum(b.hits > 0 for b in self.bins)

    @property
    def holes(self) -> list[Bin]:
        return [b for b in self.bins if b.hits == 0]

    @property
    def unexplained(self) -> list[Bin]:
        return [b for b in self.holes if not b.reason]

    def summary(self) -> str:
        total = len(self.bins)
        pct = 100.0 * self.hit / total if total else 0.0
        return (f"functional coverage: {self.hit} of {total} bins hit ({pct:.1f} %) from "
                f"{len(self.runs)} runs; holes {len(self.holes)}, "
                f"{len(self.holes) - len(self.unexplained)} with a reason, "
                f"{len(self.unexplained)} without")


def read_holes(path: Path) -> dict[str, str]:
    """Pattern -> reason from a holes file ([holes] table); reasons stripped."""
    if not path.exists():
        return {}
    data = tomllib.loads(path.read_text())
    holes = data.get("holes", {})
    bad = [k for k, v in holes.items() if not isinstance(v, str)]
    if bad:
        raise ValueError(f"{path}: the reason for {bad[0]!r} is not a string")
    return {k: v.strip() for k, v in holes.items()}


def merge(files: list[Path], out: Path) -> dict:
    """cocotb-coverage's merge of the runs' YAML databases, written to `out`, and read back."""
    import yaml
    from cocotb_coverage.coverage import merge_coverage

    out.parent.mkdir(parents=True, exist_ok=True)
    merge_coverage(lambda _msg: None, str(out), *(str(f) for f in files))
    return yaml.safe_load(out.read_text()) or {}


def bins_of(db: dict, groups: list[str]) -> list[Bin]:
    """Every cover point's bins (items with bins), and a NEVER bin per missing group."""
    out = []
    for name in sorted(db):
        hits = db[name].get("bins:_hits")
        if hits is not None:
            out += [Bin(name, str(b), int(h)) for b, h in hits.items()]
    sampled = {b.point for b in out}
    for g in groups:
        if not any(p == g or p.startswith(g + ".") for p in sampled):
            out.append(Bin(g, NEVER, 0))
    return out


def explain(bins: list[Bin], holes: dict[str, str]) -> list[str]:
    """Give each unhit bin the reason of the first pattern matching it; the patterns that match
    no unhit bin (stale: hit now, or gone)."""
    used = set()
    for b in bins:
        if b.hits:
            continue
        for pattern, reason in holes.items():
            if fnmatch.fnmatchcase(b.key, pattern):
                b.reason = reason or None
                used.add(pattern)
                break
    return [p for p in holes if p not in used]


def build_report(cov_dir: Path = DEFAULT_DIR, holes_file: Path = HOLES,
                 groups: list[str] | None = None) -> Report:
    files = sorted((cov_dir / "func").glob("*.yml"))
    db = merge(files, cov_dir / "merged.yml") if files else {}
    bins = bins_of(db, expected_groups() if groups is None else groups)
    stale = explain(bins, read_holes(holes_file))
    return Report([f.stem for f in files], bins, stale)


def markdown(rep: Report, holes_file: Path) -> str:
    lines = ["# Functional coverage", "", rep.summary() + ".", "",
             f"Holes explained by `{holes_file}`. Hits count sampling events (a batch of beats "
             "through a block, a whole-filter run), not beats.", ""]
    if rep.unexplained:
        lines += ["## Holes without a reason", ""]
        lines += [f"- `{b.key}`" for b in rep.unexplained] + [""]
    lines += ["## Holes", "", "| bin | reason |", "|---|---|"]
    lines += [f"| `{b.key}` | {b.reason or '**no reason**'} |" for b in rep.holes]
    if rep.stale:
        lines += ["", "## Holes-file entries matching no unhit bin (hit now, or gone)", ""]
        lines += [f"- `{p}`" for p in rep.stale]
    lines += ["", "## Every bin", "", "| point | bin | hits |", "|---|---|---:|"]
    lines += [f"| `{b.point}` | {b.name} | {b.hits} |" for b in rep.bins]
    lines += ["", f"Runs merged ({len(rep.runs)}):", ""] + [f"- {r}" for r in rep.runs]
    return "\n".join(lines) + "\n"


def write_report(rep: Report, cov_dir: Path, holes_file: Path) -> tuple[Path, Path]:
    md, js = cov_dir / "report.md", cov_dir / "report.json"
    cov_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(md, markdown(rep, holes_file))
    data = {"hit": rep.hit, "total": len(rep.bins), "holes": len(rep.holes),
            "unexplained": [b.key for b in rep.unexplained], "stale": rep.stale,
            "runs": rep.runs, "bins": [asdict(b) for b in rep.bins]}
    atomic_write_text(js, json.dumps(data, indent=1) + "\n")
    return md, js
