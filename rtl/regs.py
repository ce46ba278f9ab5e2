"""The AXI4-Lite register block of gpf_<app>_axi, from SystemRDL (templates/gpf_regs.rdl.j2).

PeakRDL compiles the description into the register block's SystemVerilog (peakrdl-regblock,
AXI4-Lite), a C header (peakrdl-cheader) and the register map (peakrdl-markdown). Two edits
make the register block readable by every tool the project uses: its structs become packed
(Yosys and Icarus take packed structs only; every member is a bit vector, so the layout is the
same) and its `automatic` locals in always_comb plain ones (each is assigned before it is read,
so nothing is kept between evaluations). Icarus 11 still cannot elaborate nested structs (an
assertion in its elab_type.cc), so gpf_<app>_axi runs on Verilator only (ICARUS_GAP).
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import jinja2
from peakrdl_cheader.exporter import CHeaderExporter
from peakrdl_markdown import MarkdownExporter
from peakrdl_regblock import RegblockExporter
from peakrdl_regblock.cpuif.axi4lite import AXI4Lite_Cpuif_flattened
from peakrdl_regblock.udps import ALL_UDPS
from systemrdl import RDLCompileError, RDLCompiler
from systemrdl.node import RootNode

# (PeakRDL's text, ours, how many times at least): an edit that stops matching fails generation
EDITS = [(r"\bstruct \{", "struct packed {", 1), (r"\bautomatic logic\b", "logic", 0)]
# What PeakRDL declares and never reads, by design, marked so for slang's analysis (rtl/lint.py)
# as the banner's lint_off does for Verilator: the AXI4-Lite PROT inputs, its address and access
# checks (it has none) and error decode, the package's size constants
UNUSED = "(* maybe_unused *) "
UNUSED_EDITS = {
    "": [(r"(input wire \[2:0\] s_axil_a[wr]prot\b)", UNUSED + r"\1", 2),
         (r"(logic (decoded_err|is_valid_addr|is_valid_rw);)", UNUSED + r"\1", 3)],
    "_pkg": [(r"(localparam \w+_(DATA_WIDTH|MIN_ADDR_WIDTH|SIZE) =)", UNUSED + r"\1", 3)],
}


ICARUS_GAP = "Icarus 11 cannot elaborate the register block's nested packed structs"
ADDR_W = 12   # a 4 KiB window, the least an AXI4-Lite slave takes in a Vivado address map


def regs_name(app: str) -> str:
    return f"gpf_{app}_regs"


def _edit(text: str, name: str, edits: list[tuple[str, str, int]] = EDITS) -> str:
    for pattern, repl, least in edits:
        text, count = re.subn(pattern, repl, text)
        if count < least:
            raise ValueError(f"{name}: PeakRDL's output changed: no {pattern!r} to edit")
    return text


def compile_rdl(path: Path) -> RootNode:
    """The elaborated register description (PeakRDL-regblock's own properties known)."""
    compiler = RDLCompiler()
    for udp in ALL_UDPS:   # the register block's own properties (buffer_writes, ...)
        compiler.register_udp(udp)
    try:
        compiler.compile_file(str(path))
        return compiler.elaborate()
    except RDLCompileError as err:   # the compiler printed where
        raise ValueError(f"{path.name}: SystemRDL errors (above)") from err


def register_files(env: jinja2.Environment, context: dict) -> dict[str, str]:
    """{file name: text} of the register block: .rdl, _pkg.sv, .sv, .h, .md."""
    name = regs_name(context["app"])
    rdl = env.get_template("gpf_regs.rdl.j2").render(module=name, **context)
    with tempfile.TemporaryDirectory(prefix="gpf-regs-") as tmp:
        folder = Path(tmp)
        (folder / f"{name}.rdl").write_text(rdl)
        root = compile_rdl(folder / f"{name}.rdl")
        RegblockExporter().export(root, str(folder), cpuif_cls=AXI4Lite_Cpuif_flattened,
                                  module_name=name, package_name=f"{name}_pkg",
                                  default_reset_activelow=True, default_reset_async=False,
                                  reuse_hwif_typedefs=False, address_width=ADDR_W)
        CHeaderExporter().export(root, str(folder / f"{name}.h"), reuse_typedefs=False)
        MarkdownExporter().export(root, str(folder / f"{name}.md"))
        texts = {f.name: f.read_text() for f in sorted(folder.iterdir())}
    # PeakRDL's logic leaves some of its own signals unused (awprot, an unused decode): waived
    # for its files alone, as our lint (Verilator -Wall) takes no warning from our own
    banner = (f"// Generated from {context['config_file']} by `gpf generate`: PeakRDL-regblock's "
              f"output of {name}.rdl, structs packed (rtl/regs.py).\n`timescale 1ns / 1ps\n"
              "/* verilator lint_off UNUSEDSIGNAL */\n/* verilator lint_off UNUSEDPARAM */\n")
    for suffix, unused_edits in UNUSED_EDITS.items():
        sv = f"{name}{suffix}.sv"
        texts[sv] = banner + _edit(texts[sv], sv, EDITS + unused_edits)
    return texts
