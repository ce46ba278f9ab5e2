"""Sum the stall campaign's pieces (build/campaign/piece-j-of-P.json, one a piece, written by
tests/test_sim_filter.py::test_stall_campaign) and fail unless every piece is there, none had
a mismatch or a failed run, and together they checked at least the particles asked for.

    python .ci/campaign_total.py FOLDER --particles N --pieces P
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def campaign_total(folder: Path, particles: int, pieces: int) -> list[str]:
    """Problems ([] when the campaign is complete and clean); prints a line a piece."""
    found = {}
    for path in sorted(folder.rglob("piece-*-of-*.json")):
        report = json.loads(path.read_text())
        found[report["piece"], report["pieces"]] = report
        print(f"piece {report['piece']} of {report['pieces']} ({report['seed']}): "
              f"{report['particles_checked']} particles in {report['runs']} runs, "
              f"{report['seconds']} s, {report['mismatches']} mismatches")
    problems = [f"piece {j} of {pieces}: no report" for j in range(pieces)
                if (j, pieces) not in found]
    problems += [f"piece {j} of {p}: not a piece of {pieces}" for j, p in found if p != pieces]
    problems += [f"piece {j}: {r['mismatches']} mismatches, {r['failed_runs']} failed runs"
                 for (j, _), r in found.items() if r["mismatches"] or r["failed_runs"]]
    total = sum(r["particles_checked"] for r in found.values())
    print(f"stall campaign: {total} particles checked by {len(found)} pieces "
          f"(asked: {particles} by {pieces})")
    if total < particles:
        problems.append(f"{total} particles checked, fewer than {particles}")
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--particles", type=int, required=True)
    parser.add_argument("--pieces", type=int, required=True)
    args = parser.parse_args()
    problems = campaign_total(args.folder, args.particles, args.pieces)
    for problem in problems:
        print(f"FAILED: {problem}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
