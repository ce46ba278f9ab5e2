"""ECP5 block RAMs with their output registers: the other pass Yosys 0.70's synth_ecp5 lacks.

synth_ecp5 maps every ROM read to a DP16KD with REGMODE "NOREG": the word leaves the block
5.8 ns after the clock (nextpnr's model of the read latch), so the flip-flops the templates put
right behind each ROM (the word "registered again", for the multipliers after it) get barely 1
ns of routing at 150 MHz. Lattice's flow packs such flip-flops into the block's output register
(REGMODE "OUTREG", clocked by the read clock, enabled by OCE); this pass does the same on the
JSON netlist before nextpnr, beside gpf.dsp_registers:

- a read port whose every used data bit goes to one flip-flop and nowhere else, the flip-flops
  on the port's own clock with one enable and no set or reset, takes them as its output
  register: REGMODE "OUTREG", OCE their enable; the flip-flops go;
- a 36-bit read (DATA_WIDTH 36: the word on both ports' DO pins, read through port B) moves as
  one: both ports' pins, both REGMODEs, both OCEs;
- only where the read port's reset is tied off: with a reset, the block's register and its
  read latch reset differently from two fabric flip-flops.

Timing flow only; the generic RTL, its simulation and the xc7 synthesis never see this.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gpf.dsp_registers import Netlist, param

DATA = 18                   # DO pins per port


@dataclass
class PackedRams:
    rams: int = 0
    ports: int = 0           # read ports given their output register
    flops_removed: int = 0
    refused: dict[str, int] = field(default_factory=dict)   # reason -> ports

    def refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1


def _register_flop(cell: dict) -> bool:
    """A flip-flop the block's output register stands in for: rising clock, no set or reset."""
    return (cell["type"] == "TRELLIS_FF" and param(cell, "CLKMUX", "CLK") == "CLK"
            and param(cell, "CEMUX", "1") in ("1", "CE")
            and cell["connections"].get("LSR", ["0"]) == ["0"])


def _read_ports(ram: dict) -> list[tuple[str, list[str]]]:
    """(the port whose clock reads, the DO pins carrying its word), per read port."""
    width = param(ram, "DATA_WIDTH_B", "18")      # Yosys writes an integer as 32 binary digits
    if int(width, 2 if len(width) == 32 else 10) == 36:
        return [("B", [f"DO{p}{i}" for p in "AB" for i in range(DATA)])]
    return [(p, [f"DO{p}{i}" for i in range(DATA)]) for p in "AB"]


def _pack_port(net: Netlist, ram: dict, port: str, pins: list[str], stats: PackedRams
               ) -> list[str]:
    """Give a read port its output register; returns the flip-flops that go (none: refused)."""
    conns = ram["connections"]
    if param(ram, f"REGMODE_{port}", "NOREG") != "NOREG":
        return []
    moves = []
    for pin in pins:
        bit = conns.get(pin, ["x"])[0]
        loads = net.loads.get(bit, []) if isinstance(bit, int) else []
        if not loads:
            continue
        if len(loads) != 1 or loads[0][1] != "DI":
            stats.refuse("DO: a data bit read by logic, not only by one flip-flop")
            return []
        flop = net.cells.get(loads[0][0])
        if flop is None or not _register_flop(flop):
            stats.refuse("DO: a data bit into a flip-flop with a set or a reset")
            return []
        moves.append((pin, loads[0][0], flop))
    if not moves:
        return []
    clocks = {str(f["connections"]["CLK"]) for _, _, f in moves}
    enables = {str(_enable(f)) for _, _, f in moves}
    if clocks != {str(conns[f"CLK{port}"])} or len(enables) != 1:
        stats.refuse("DO: flip-flops on another clock than the read's, or on several enables")
        return []
    if conns.get(f"RST{port}", ["0"]) != ["0"]:
        stats.refuse("DO: the read port has a reset")
        return []
    enable = _enable(moves[0][2])
    for pin, _, flop in moves:
        conns[pin] = flop["connections"]["Q"]
    for side in {pin[2] for pin in pins}:       # A, B: the ports whose pins carry the word
        ram["parameters"][f"REGMODE_{side}"] = "OUTREG"
        conns[f"OCE{side}"] = enable
    return [name for _, name, _ in moves]


def _enable(flop: dict) -> list:
    return flop["connections"]["CE"] if param(flop, "CEMUX", "1") == "CE" else ["1"]


def pack_bram_registers(netlist: dict) -> PackedRams:
    """Move the flip-flops behind each DP16KD's read into its output register, in place."""
    stats = PackedRams()
    for module in netlist["modules"].values():
        rams = [c for c in module["cells"].values() if c["type"] == "DP16KD"]
        stats.rams += len(rams)
        net = Netlist(module)
        gone: list[str] = []
        for ram in rams:
            for port, pins in _read_ports(ram):
                flops = _pack_port(net, ram, port, pins, stats)
                stats.ports += bool(flops)
                gone += flops
        for name in gone:
            del module["cells"][name]
        stats.flops_removed += len(gone)
    return stats
