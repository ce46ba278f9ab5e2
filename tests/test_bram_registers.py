"""The timing flow's block RAM output register packing (gpf.bram_registers): which flip-flops
behind a DP16KD's read it moves into the block, and which it must leave, on small netlists in
synth_ecp5's JSON form; and on a ROM Yosys itself maps, the read the templates write."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from gpf.bram_registers import pack_bram_registers
from gpf.synth import run_yosys

CLK, CE, RST, OTHER_CLK = 2, 3, 4, 6
WORD = 36


def flop(d: int, q: int, clk: int = CLK, ce: int | None = CE, lsr: int | None = None) -> dict:
    params = {"CLKMUX": "CLK", "CEMUX": "CE" if ce is not None else "1", "GSR": "DISABLED"}
    conns = {"CLK": [clk], "DI": [d], "Q": [q]}
    if ce is not None:
        conns["CE"] = [ce]
    if lsr is not None:
        conns["LSR"] = [lsr]
        params.update(LSRMUX="LSR", REGSET="RESET", SRMODE="LSR_OVER_CE")
    return {"type": "TRELLIS_FF", "parameters": params, "connections": conns,
            "port_directions": {"CLK": "input", "DI": "input", "CE": "input", "LSR": "input",
                                "Q": "output"}}


def rom_netlist(width: int = WORD) -> dict:
    """A DP16KD read through port B (36 bits: DOA and DOB carry one word), each data bit into
    its own flip-flop on the read clock and enable; the flip-flops drive the module's output."""
    pins = [f"DO{p}{i}" for p in "AB" for i in range(18)][:width] if width == WORD else \
        [f"DOB{i}" for i in range(width)]
    conns = {"CLKA": ["0"], "CLKB": [CLK], "CEA": ["0"], "CEB": [CE], "OCEA": ["0"],
             "OCEB": ["1"], "RSTA": ["0"], "RSTB": ["0"], "WEA": ["1"], "WEB": ["0"]}
    directions = {p: "input" for p in conns}
    cells: dict = {}
    for k, pin in enumerate(pins):
        conns[pin] = [100 + k]
        directions[pin] = "output"
        cells[f"word_q[{k}]"] = flop(100 + k, 200 + k)
    width_param = format(width, "032b")
    cells["rom_DP16KD"] = {"type": "DP16KD", "connections": conns, "port_directions": directions,
                           "parameters": {"DATA_WIDTH_A": width_param,
                                          "DATA_WIDTH_B": width_param,
                                          "REGMODE_A": "NOREG", "REGMODE_B": "NOREG"}}
    ports = {"word": {"direction": "output", "bits": [200 + k for k in range(len(pins))]}}
    return {"modules": {"top": {"cells": cells, "ports": ports}}}


def ram(netlist: dict) -> dict:
    return netlist["modules"]["top"]["cells"]["rom_DP16KD"]


def test_a_36_bit_read_takes_its_flops_as_one_output_register():
    netlist = rom_netlist()
    stats = pack_bram_registers(netlist)
    assert (stats.rams, stats.ports, stats.flops_removed) == (1, 1, WORD)
    cell = ram(netlist)
    assert cell["parameters"]["REGMODE_A"] == cell["parameters"]["REGMODE_B"] == "OUTREG"
    assert cell["connections"]["OCEA"] == cell["connections"]["OCEB"] == [CE]
    # each data pin now drives what its flip-flop drove; no flip-flop is left
    assert [cell["connections"][f"DOA{i}"][0] for i in range(18)] == list(range(200, 218))
    assert [cell["connections"][f"DOB{i}"][0] for i in range(18)] == list(range(218, 236))
    assert list(netlist["modules"]["top"]["cells"]) == ["rom_DP16KD"]


def test_an_18_bit_read_sets_its_own_port_only():
    netlist = rom_netlist(width=18)
    assert pack_bram_registers(netlist).ports == 1
    cell = ram(netlist)
    assert (cell["parameters"]["REGMODE_A"], cell["parameters"]["REGMODE_B"]) == ("NOREG",
                                                                                   "OUTREG")
    assert cell["connections"]["OCEA"] == ["0"] and cell["connections"]["OCEB"] == [CE]


def _read_by_logic(n: dict) -> None:
    n["modules"]["top"]["cells"]["lut"] = {"type": "LUT4", "connections": {"A": [105], "Z": [9]},
                                           "port_directions": {"A": "input", "Z": "output"},
                                           "parameters": {}}


def _reset_flop(n: dict) -> None:
    n["modules"]["top"]["cells"]["word_q[3]"] = flop(103, 203, lsr=RST)


def _other_clock(n: dict) -> None:
    n["modules"]["top"]["cells"]["word_q[7]"] = flop(107, 207, clk=OTHER_CLK)


def _other_enable(n: dict) -> None:
    n["modules"]["top"]["cells"]["word_q[8]"] = flop(108, 208, ce=None)


def _port_reset(n: dict) -> None:
    ram(n)["connections"]["RSTB"] = [RST]


@pytest.mark.parametrize("breakage", [_read_by_logic, _reset_flop, _other_clock, _other_enable,
                                      _port_reset])
def test_reads_whose_flops_the_register_cannot_stand_for_stay(breakage):
    netlist = rom_netlist()
    breakage(netlist)
    before = copy.deepcopy(netlist)
    stats = pack_bram_registers(netlist)
    assert stats.ports == 0 and stats.refused and netlist == before


def test_the_templates_rom_read_is_packed(tmp_path: Path):
    # what exp_lane and grng_icdf write: a ROM read on a stall enable, its word registered
    # again on the same enable, neither reset; synth_ecp5 maps it to a DP16KD without the
    # output register, the pass gives it one
    words = "".join(f"      9'd{k}: rom_d = 36'h{(k * 0x9E3779B1) % (1 << 36):09x};\n"
                    for k in range(512))
    (tmp_path / "rom.sv").write_text(f"""
module rom (input logic clk, en, input logic [8:0] a, output logic [35:0] word);
  logic [35:0] rom_d, rom_q;
  always_comb
    case (a)
{words}      default: rom_d = '0;
    endcase
  always_ff @(posedge clk) if (en) begin rom_q <= rom_d; word <= rom_q; end
endmodule
""")
    run_yosys("read_verilog -sv rom.sv\nsynth_ecp5 -top rom -json rom.json\n", tmp_path)
    netlist = json.loads((tmp_path / "rom.json").read_text())
    assert sum(c["type"] == "TRELLIS_FF" for c in netlist["modules"]["rom"]["cells"].values()) \
        == WORD
    stats = pack_bram_registers(netlist)
    assert (stats.rams, stats.ports, stats.flops_removed) == (1, 1, WORD), stats
