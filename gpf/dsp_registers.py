"""ECP5 multipliers with their own registers: the pass Yosys 0.70's synth_ecp5 lacks.

synth_ecp5 maps every product to a MULT18X18D with its input and output registers off, so the
flip-flops either side of a product sit in the fabric and each path pays the multiplier's
3.9 ns plus the routing to and from the DSP column (3-4.6 ns each way): no block with a product
times above ~130 MHz. Lattice's own flow, like Yosys's for Xilinx (xilinx_dsp), moves those
flip-flops into the DSP. This pass does the same on synth_ecp5's JSON netlist before nextpnr:

- an operand (A or B) whose every non-constant bit is a flip-flop's output, itself fed by a
  flip-flop, becomes the DSP's input register, fed from those flip-flops' inputs (the
  flip-flops stay if anything else reads them), when the other operand can too (nextpnr times
  a MULT18X18D with one input register as if it had none);
- a product whose every read bit goes to a flip-flop and nowhere else becomes the DSP's output
  register, and those flip-flops go.

Only flip-flops on one rising clock with one enable and one reset per port are moved, and only
where the DSP's register behaves exactly as they did: no set, a reset only synchronous and to 0
(over the enable, as the fabric's LSR_OVER_CE flip-flop and the DSP's RESETMODE "SYNC" register
both take it: a datapath register that stalls and resets moves), and no operand bit tied to 1
beside a reset (the DSP's register would clear it). Timing flow only; the generic RTL, its
simulation and the xc7 synthesis never see this.
"""

from __future__ import annotations

from dataclasses import dataclass, field

WIDTH = 18                  # MULT18X18D operand bits
PRODUCT = 36


@dataclass
class Packed:
    dsps: int = 0
    inputs: int = 0          # operand ports given their register
    outputs: int = 0         # products given their register
    flops_removed: int = 0
    refused: dict[str, int] = field(default_factory=dict)   # reason -> ports

    def refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1


def param(cell: dict, name: str, default: str = "") -> str:
    return str(cell["parameters"].get(name, default)).strip()


def _plain_flop(cell: dict) -> bool:
    """A flip-flop a DSP register can stand in for: rising clock, no set, and a reset (if
    any) synchronous, to 0 and over the enable."""
    if cell["type"] != "TRELLIS_FF" or param(cell, "CLKMUX", "CLK") != "CLK":
        return False
    enable = param(cell, "CEMUX", "1")
    if enable not in ("1", "CE"):
        return False
    if cell["connections"].get("LSR", ["0"]) == ["0"]:
        return True
    return (param(cell, "LSRMUX", "LSR") == "LSR"
            and param(cell, "REGSET", "RESET") == "RESET"
            and param(cell, "SRMODE", "LSR_OVER_CE") == "LSR_OVER_CE")


def _control(cell: dict) -> list:
    """What a DSP register must share with the flip-flop: clock, enable, reset."""
    enable = cell["connections"]["CE"] if param(cell, "CEMUX", "1") == "CE" else ["1"]
    return [cell["connections"]["CLK"], enable, cell["connections"].get("LSR", ["0"])]


def _from_a_flop(net: Netlist, flop: dict) -> bool:
    """The flip-flop's input is another flip-flop's output (or a constant): moving it into the
    DSP leaves a register-to-register hop to the DSP. With logic before it, the logic's path
    would end at the DSP column instead of beside the logic, and be the longer for it."""
    bit = flop["connections"]["DI"][0]
    if not isinstance(bit, int):
        return True
    name, port = net.driver.get(bit, ("", ""))
    return port == "Q" and net.cells.get(name, {}).get("type") == "TRELLIS_FF"


def _clears_a_one(control: list, bits: list) -> bool:
    """A reset would clear an operand bit tied to 1, which no fabric flip-flop holds."""
    return control[2] != ["0"] and "1" in bits


class Netlist:
    def __init__(self, module: dict):
        self.cells = module["cells"]
        self.driver: dict[int, tuple[str, str]] = {}
        self.loads: dict[int, list[tuple[str, str]]] = {}
        for name, cell in self.cells.items():
            directions = cell.get("port_directions", {})
            for port, bits in cell["connections"].items():
                for bit in bits:
                    if not isinstance(bit, int):
                        continue
                    if directions.get(port) == "output":
                        self.driver[bit] = (name, port)
                    else:
                        self.loads.setdefault(bit, []).append((name, port))
        for port in module.get("ports", {}).values():
            for bit in port["bits"]:
                if isinstance(bit, int) and port["direction"] != "input":
                    self.loads.setdefault(bit, []).append(("<port>", ""))

    def flop_driving(self, bit) -> dict | None:
        name, port = self.driver.get(bit, ("", ""))
        cell = self.cells.get(name)
        return cell if cell is not None and port == "Q" and _plain_flop(cell) else None


def _same(values: list) -> bool:
    return all(v == values[0] for v in values)


def _input_register(net: Netlist, dsp: dict, side: str, clock: list | None, stats: Packed
                    ) -> tuple[list, list[tuple[str, list, str]]] | None:
    """Whether operand `side` can take its register (on `clock`, if the DSP has one already):
    the register's (clock, enable, reset) and, per pin, the flip-flop input it would then read
    and the flip-flop it stands in for; None (the reason counted) if it cannot."""
    pins = [f"{side}{i}" for i in range(WIDTH)]
    bits = [dsp["connections"][p][0] for p in pins]
    live = [b for b in bits if isinstance(b, int)]
    flops = [net.flop_driving(b) for b in live]
    if not live or any(f is None for f in flops):
        stats.refuse(f"{side}: an operand bit from logic or a flip-flop with a set or an "
                     "unsupported reset")
        return None
    if any(not _from_a_flop(net, f) for f in flops):
        stats.refuse(f"{side}: logic before the operand flip-flops (it would then have to "
                     "reach the DSP)")
        return None
    controls = [_control(f) for f in flops]
    if not _same(controls) or (clock is not None and controls[0][0] != clock):
        stats.refuse(f"{side}: operand flip-flops on different clocks, enables or resets")
        return None
    if _clears_a_one(controls[0], bits):
        stats.refuse(f"{side}: an operand bit tied to 1 beside a reset")
        return None
    moves = []
    for pin, bit in zip(pins, bits, strict=True):
        if isinstance(bit, int):
            name = net.driver[bit][0]
            moves.append((pin, net.cells[name]["connections"]["DI"], name))
    return controls[0], moves


def _pack_output(net: Netlist, dsp: dict, stats: Packed) -> tuple[list | None, list[str]]:
    """Give the product its register; returns its (clock, enable) and the flip-flops to go."""
    moves = []
    for i in range(PRODUCT):
        bit = dsp["connections"][f"P{i}"][0]
        loads = net.loads.get(bit, []) if isinstance(bit, int) else []
        if not loads:
            continue
        if len(loads) != 1 or loads[0][1] != "DI":
            stats.refuse("P: a product bit read by logic, not only by one flip-flop")
            return None, []
        flop = net.cells.get(loads[0][0])
        if flop is None or not _plain_flop(flop):
            stats.refuse("P: a product bit into a flip-flop with a set or an unsupported reset")
            return None, []
        moves.append((i, loads[0][0], flop))
    if not moves:
        return None, []
    controls = [_control(f) for _, _, f in moves]
    if not _same(controls):
        stats.refuse("P: product flip-flops on different clocks, enables or resets")
        return None, []
    for i, _, flop in moves:
        dsp["connections"][f"P{i}"] = flop["connections"]["Q"]
    return controls[0], [name for _, name, _ in moves]


def pack_dsp_registers(netlist: dict) -> Packed:
    """Move the flip-flops around each MULT18X18D into it, in place, in every module.

    Products first: a product's flip-flops, once in its DSP, are no longer a flip-flop another
    DSP's operand could take. Then operands, from the netlist as the products left it; last,
    the operand flip-flops nothing reads any more."""
    stats = Packed()
    for module in netlist["modules"].values():
        dsps = [c for c in module["cells"].values() if c["type"] == "MULT18X18D"]
        stats.dsps += len(dsps)
        used: dict[int, list[tuple[str, list]]] = {id(d): [] for d in dsps}  # register, control
        net = Netlist(module)
        gone: set[str] = set()
        for dsp in dsps:
            reg, flops = _pack_output(net, dsp, stats)
            if reg is not None:
                used[id(dsp)].append(("OUTPUT", reg))
                gone.update(flops)
        for name in gone:
            del module["cells"][name]
        net = Netlist(module)
        sources: set[str] = set()
        for dsp in dsps:
            # both operands or neither: nextpnr times a MULT18X18D with one input register as
            # if it had none, so a single moved register would only lose its stage
            clock = used[id(dsp)][0][1][0] if used[id(dsp)] else None
            plans = [_input_register(net, dsp, side, clock, stats) for side in ("A", "B")]
            if all(plans) and plans[0][0][0] == plans[1][0][0]:
                for side, (control, moves) in zip(("A", "B"), plans, strict=True):
                    for pin, source, flop in moves:
                        dsp["connections"][pin] = source
                        sources.add(flop)
                    used[id(dsp)].append((f"INPUT{side}", control))
            elif any(plans):
                stats.refuse("A, B: one operand could take its register and the other not "
                             "(both kept in the fabric)")
            if used[id(dsp)]:
                _configure(dsp, used[id(dsp)])
            stats.inputs += sum(r != "OUTPUT" for r, _ in used[id(dsp)])
            stats.outputs += any(r == "OUTPUT" for r, _ in used[id(dsp)])
        net = Netlist(module)
        idle = {s for s in sources if not any(net.loads.get(b) for b in
                                              module["cells"][s]["connections"]["Q"])}
        for name in idle:
            del module["cells"][name]
        stats.flops_removed += len(gone) + len(idle)
    return stats


def _configure(dsp: dict, used: list[tuple[str, list]]) -> None:
    """Clock 0 for every register, and an enable and a reset slot each (synchronous resets)."""
    conns, params = dsp["connections"], dsp["parameters"]
    directions = dsp.setdefault("port_directions", {})
    conns["CLK0"] = used[0][1][0]
    directions["CLK0"] = "input"
    for slot, (register, (_, enable, reset)) in enumerate(used):
        params[f"REG_{register}_CLK"] = "CLK0"
        params[f"REG_{register}_CE"] = f"CE{slot}"
        params[f"REG_{register}_RST"] = f"RST{slot}"
        conns[f"CE{slot}"] = enable
        conns[f"RST{slot}"] = reset
        directions[f"CE{slot}"] = directions[f"RST{slot}"] = "input"
    params["RESETMODE"] = "SYNC"
    params["GSR"] = "DISABLED"
