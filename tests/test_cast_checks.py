"""The simulation-only checks of narrowing casts whose losslessness the generator proves (a
table's range, a sum's range): `ifndef SYNTHESIS` blocks in the templates that stop the
simulation ($fatal), naming the module and the signal, when the bits a cast drops are not copies
of the sign (or zeros). Each one is silent on its shipped config under random inputs, and fires
once a generator value is tweaked so that its proof no longer holds.

A lane is simulated alone on Icarus under a testbench that drives every input at random.
"""

from __future__ import annotations

import dataclasses
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from gpf.config import load_config
from gpf.rtl import generate as gen
from gpf.toolchain import icarus_missing

pytestmark = pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")

CLOCKS = 400
DONE = "random stimulus done"


def exp_bases_zero(ctx: dict) -> dict:
    """Every BASE of the exponential's table 0: m = BASE + SLOPE r goes negative."""
    mask = (1 << ctx["m_width"]) - 1
    digits = len(ctx["rom"][0])
    ctx["rom"] = [f"{int(word, 16) & ~mask:0{digits}X}" for word in ctx["rom"]]
    return ctx


def grng_output_narrower(ctx: dict) -> dict:
    """The sample two bits narrower than the table's largest |z| needs."""
    ctx["out_w"] -= 2
    return ctx


def propagate_uav_h0_narrower(ctx: dict) -> dict:
    """h0's rounded sum kept two bits narrower than its range needs (no saturation)."""
    [line] = [r for stage in ctx["stages"] for r in stage if r.get("base") == "h0"]
    assert not line["sat"] and line["rw"] == line["ow"]
    line["rw"] -= 2
    return ctx


# name: (module, the lane simulated, config, the tweak that breaks the proof, the message)
CASES: dict[str, tuple[str, str, str, Callable[[dict], dict], str]] = {
    "exp-m": ("exp", "exp_lane", "bot", exp_bases_zero, "exp_lane: m_d = "),
    "grng-mag": ("grng", "grng_icdf", "bot", grng_output_narrower, "grng_icdf: mag_wide = "),
    "propagate-uav-h": ("propagate_uav", "propagate_uav_lane", "uav", propagate_uav_h0_narrower,
                        "propagate_uav_lane: h0_s >>> "),
}


def random_testbench(lane: Path, top: str) -> str:
    """A testbench for `top` (in the file `lane`): reset for three clocks, then every input but
    the clock and reset random on every clock (`advance` held high), for CLOCKS clocks."""
    from pyslang import ast, syntax

    compilation = ast.Compilation()
    compilation.addSyntaxTree(syntax.SyntaxTree.fromFile(str(lane)))
    [inst] = compilation.getRoot().topInstances
    ports = {p.name: (p.direction, p.type.bitWidth) for p in inst.body.portList}
    decls = "".join(f"  logic [{w - 1}:0] {name};\n" for name, (_, w) in ports.items())
    driven = [(n, w) for n, (d, w) in ports.items()
              if d == ast.ArgumentDirection.In and n not in ("clk", "rst", "advance")]
    draws = "".join(f"      {n} = {{{', '.join(['$urandom'] * ((w + 31) // 32))}}};\n"
                    for n, w in driven)
    rst = "rst = 1'b1; " if "rst" in ports else ""
    unrst = "rst = 1'b0; " if "rst" in ports else ""
    advance = "advance = 1'b1; " if "advance" in ports else ""
    return f"""module tb;
{decls}  {top} dut (.*);
  always #5 clk = !clk;
  initial begin
    clk = 1'b0; {rst}{advance}
{draws}    repeat (3) @(posedge clk);
    {unrst}
    repeat ({CLOCKS}) begin
      @(negedge clk);
{draws}    end
    $display("{DONE}");
    $finish;
  end
endmodule
"""


def simulate(tmp_path: Path, case: str, broken: bool, monkeypatch) -> str:
    module, top, config, tweak, _ = CASES[case]
    if broken:
        base = gen.MODULES[module]
        monkeypatch.setitem(gen.MODULES, module, dataclasses.replace(
            base, context=lambda cfg: tweak(base.context(cfg))))
    gen.generate(load_config(f"configs/{config}.toml"), tmp_path / "rtl", modules=[module])
    lane = tmp_path / "rtl" / f"{top}.sv"
    tb = tmp_path / "tb.sv"
    tb.write_text(random_testbench(lane, top))
    vvp = tmp_path / "sim.vvp"
    subprocess.run(["iverilog", "-g2012", "-o", str(vvp), "-s", "tb", str(lane), str(tb)],
                   check=True, capture_output=True, text=True)
    run = subprocess.run(["vvp", "-n", str(vvp)], capture_output=True, text=True, timeout=120)
    return run.stdout + run.stderr


@pytest.mark.parametrize("case", list(CASES))
def test_cast_check_silent_when_proved(tmp_path: Path, case: str, monkeypatch) -> None:
    out = simulate(tmp_path, case, broken=False, monkeypatch=monkeypatch)
    assert DONE in out and "FATAL" not in out, out[-2000:]


@pytest.mark.parametrize("case", list(CASES))
def test_cast_check_fires_when_proof_broken(tmp_path: Path, case: str, monkeypatch) -> None:
    out = simulate(tmp_path, case, broken=True, monkeypatch=monkeypatch)
    message = CASES[case][4]
    assert "FATAL" in out and message in out and DONE not in out, out[-2000:]
