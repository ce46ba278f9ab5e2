"""make regress SHARDS=k SHARD=i (conftest.py): the shards of k cover make regress's selection
exactly once, the tests of one shared build in one shard, and each shard has its two pieces of
the stall campaign. Collection only: nothing simulates."""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parent.parent


def regress_collected(shards: int | None = None, shard: int = 0) -> list[str]:
    """The node ids make regress (with SHARDS, SHARD) would run, as pytest collects them."""
    sharding = [f"SHARDS={shards}", f"SHARD={shard}"] if shards else []
    dry = subprocess.run(["make", "-n", "regress", "CAMPAIGN_PARTICLES=1000", *sharding],
                         capture_output=True, text=True, cwd=ROOT, check=True)
    [line] = [ln for ln in dry.stdout.replace("\\\n", " ").splitlines() if "pytest" in ln]
    argv = shlex.split(line)
    argv = argv[argv.index(next(a for a in argv if a.endswith("/pytest"))) + 1:]
    argv[argv.index("-n") + 1] = "0"   # collection only, in this process's pytest
    run = subprocess.run([sys.executable, "-m", "pytest", *argv, "--collect-only", "-q"],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    return [ln for ln in run.stdout.splitlines() if "::" in ln]


@pytest.mark.parametrize("shards", [4])
def test_shards_cover_the_regression_once(shards: int) -> None:
    whole = regress_collected()
    parts = [regress_collected(shards, i) for i in range(shards)]
    counts = Counter(node for part in parts for node in part)
    campaign = "test_stall_campaign"
    assert all(parts) and max(counts.values()) == 1
    # every test of the unsharded selection but its two campaign pieces, in exactly one shard
    assert {n for n in counts if campaign not in n} == {n for n in whole if campaign not in n}
    assert [sum(campaign in n for n in part) for part in parts] == [2] * shards
    assert sorted(n.split("[")[1] for n in counts if campaign in n) == sorted(
        f"{j}-of-{2 * shards}]" for j in range(2 * shards))


class Item:
    """What conftest.assign_shards reads of a collected test."""

    def __init__(self, nodeid: str, group: str | None = None, piece: tuple | None = None):
        self.nodeid, self.group = nodeid, group
        if piece:
            self.callspec = SimpleNamespace(params={"campaign_piece": piece})

    def get_closest_marker(self, name: str):
        return SimpleNamespace(args=(self.group,)) if name == "xdist_group" and self.group else None


def test_one_build_one_shard() -> None:
    """The tests of one xdist_group (one build folder) land in one shard; campaign piece j in
    shard j % k; the rest spread round-robin."""
    from conftest import assign_shards

    items = [Item(f"t{n}", group="gpf-bot-lanes1-verilator") for n in range(5)]
    items += [Item(f"u{n}") for n in range(6)]
    items += [Item(f"c[{j}]", piece=(j, 6)) for j in range(6)]
    owner = assign_shards(items, 3)
    assert len({owner[f"t{n}"] for n in range(5)}) == 1
    assert [owner[f"c[{j}]"] for j in range(6)] == [0, 1, 2, 0, 1, 2]
    assert sorted(Counter(owner[f"u{n}"] for n in range(6)).values()) == [2, 2, 2]


def test_shard_out_of_range_is_refused() -> None:
    run = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "--shards", "2",
                          "--shard", "2", "tests/test_config.py"],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode != 0 and "need 0 <= shard < shards" in run.stderr + run.stdout


def test_campaign_total(tmp_path: Path) -> None:
    """CI's sum of the pieces: passes only with every piece, no mismatch and enough particles."""
    script = [sys.executable, str(ROOT / ".ci" / "campaign_total.py"), str(tmp_path)]

    def write(piece: int, checked: int, mismatches: int = 0) -> None:
        (tmp_path / f"piece-{piece}-of-2.json").write_text(json.dumps({
            "piece": piece, "pieces": 2, "seed": f"campaign-{piece}-of-2", "budget": 50,
            "particles_checked": checked, "mismatches": mismatches, "runs": 1,
            "failed_runs": 0, "seconds": 1.0}))

    def passes(particles: int) -> bool:
        run = subprocess.run([*script, "--particles", str(particles), "--pieces", "2"],
                             capture_output=True, text=True)
        return run.returncode == 0

    write(0, 60)
    assert not passes(100)              # piece 1 missing
    write(1, 60)
    assert passes(100) and not passes(121)
    write(1, 60, mismatches=1)
    assert not passes(100)
