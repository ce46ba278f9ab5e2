"""The simulation-only checks of narrowing casts whose losslessness the generator proves (a
table's range, a sum's range): `ifndef SYNTHESIS` blocks in the templates that stop the
simulation ($fatal), naming the module and the signal, when the bits a cast drops are not copies
of the sign (or zeros). Each one is silent on its shipped config under random inputs, and fires
once a generator value is tweaked so that its proof no longer holds.

A lane (or a block's core) is simulated alone on Icarus under a testbench that drives every
input at random, or as a case's `drive` says (values that reach the check's corner). Checks whose
proof is the algorithm's own (a digit recurrence's remainder bound: no generator value in it) have
no tweak: they are only run silent (SILENT).
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


def exp_output_narrower(ctx: dict) -> dict:
    """w two bits narrower than round(m 2^-(n + G)) needs at n = 0 (m up to 2^(MW-1))."""
    ctx["out_width"] -= 2
    return ctx


def weight_square_narrower(ctx: dict) -> dict:
    """u^2's word three bits narrower than the square of u's range needs."""
    ctx["sq_width"] -= 3
    return ctx


def cholesky_quotient_shorter(ctx: dict) -> dict:
    """Six quotient bits fewer: |2 num + L_jj| >> QB below 2 L_jj (unsaturated) no longer fits
    the remainder's W + 3 bits."""
    ctx["qb"] -= 6
    return ctx


def moments_p_narrower(ctx: dict) -> dict:
    """p = round(w dx 2^-k) one bit narrower than its bound needs (the cast then narrows past
    the shift: the check is rendered)."""
    ctx["p_w"] -= 1
    return ctx


def moments_s1_narrower(ctx: dict) -> dict:
    """S1's sums eight bits narrower than N w |dx| needs: a long step's sum no longer fits."""
    ctx["s1_w"] -= 8
    return ctx


@dataclasses.dataclass(frozen=True)
class Case:
    module: str           # the generator's module
    part: str             # the file simulated (its one top module, and the module's other files)
    config: str
    tweak: Callable[[dict], dict] | None   # breaks the proof (None: SILENT only)
    message: str
    drive: dict[str, str] = dataclasses.field(default_factory=dict)   # port: SV statement
    clocks: int = CLOCKS


# a drive is an SV statement, formatted with the module's context (SV braces doubled)
# t's integer part 0 or 1 (a larger n shifts w far below its width)
EXP_DRIVE = {"t": "t = {{1'($urandom), {in_frac}'($urandom)}};"}
# a matrix started whenever the core is idle, taken when done; Sigma's entries within +-2^41
# (so that L_jj and 2 num + L_jj reach the divider's range without saturating)
CHOL_DRIVE = {"start": "start = !dut.busy_q;", "ack": "ack = done;",
              "s_flat": "for (int e = 0; e < {n} * {n}; e++) "
                        "s_flat[e*{sw} +: {sw}] = {sw}'($signed({{$urandom, $urandom}}) >>> 22);"}
# steps of about 64 beats, each beat's shift 0 (else the accumulators shrink at every beat)
MOMENTS_DRIVE = {"s_axis_tlast": "s_axis_tlast = $urandom % 64 == 0;",
                 "s_axis_tdata": "s_axis_tdata = {{{shw}'d0, {lane_w}'({{$urandom, $urandom, "
                                 "$urandom}})}};"}

CASES: dict[str, Case] = {
    "exp-m": Case("exp", "exp_lane", "bot", exp_bases_zero, "exp_lane: m_d = "),
    "exp-w": Case("exp", "exp_lane", "bot", exp_output_narrower, "exp_lane: (h + 1) >> 1 = ",
                  EXP_DRIVE),
    "grng-mag": Case("grng", "grng_icdf", "bot", grng_output_narrower, "grng_icdf: mag_wide = "),
    "propagate-uav-h": Case("propagate_uav", "propagate_uav_lane", "uav",
                            propagate_uav_h0_narrower, "propagate_uav_lane: h0_s >>> "),
    "weight-uav-square": Case("weight_uav", "weight_uav_lane", "uav", weight_square_narrower,
                              "weight_uav_lane: u0_hi^2 << 2 UK = "),
    "cholesky-mag": Case("cholesky", "cholesky_core", "bot", cholesky_quotient_shorter,
                         "cholesky_core4: mag[", CHOL_DRIVE, clocks=1200),
    "moments-p": Case("moments", "moments", "bot", moments_p_narrower, "moments: p_0_"),
    "moments-sum": Case("moments", "moments", "bot", moments_s1_narrower,
                        "moments: acc_s1_", MOMENTS_DRIVE, clocks=1500),
}
# checks of an algorithm's own invariant: silent under random inputs (no tweak breaks them)
SILENT: dict[str, Case] = {
    "recip": Case("recip", "recip_lane", "bot", None, ""),
    "sqrt": Case("sqrt", "sqrt_lane", "bot", None, ""),
    "sqrt-odd": Case("sqrt", "sqrt_lane", "odd", None, ""),
    "moments-uav": Case("moments", "moments", "uav", None, ""),   # and its |q| root's
}


def random_testbench(files: list[Path], part: Path, clocks: int, drive: dict[str, str]) -> str:
    """A testbench for the module of `part` (the module's other files beside it): reset for
    three clocks, then every input but the clock and reset random on every clock (`advance`
    held high; `drive` overrides a port's draw), for `clocks` clocks."""
    from pyslang import ast, syntax

    compilation = ast.Compilation()
    for f in files:
        compilation.addSyntaxTree(syntax.SyntaxTree.fromFile(str(f)))
    own = {m.header.name.value for m in syntax.SyntaxTree.fromFile(str(part)).root.members
           if m.kind == syntax.SyntaxKind.ModuleDeclaration}
    [inst] = [i for i in compilation.getRoot().topInstances if i.name in own]
    top = inst.name
    ports = {p.name: (p.direction, p.type.bitWidth) for p in inst.body.portList}
    decls = "".join(f"  logic [{w - 1}:0] {name};\n" for name, (_, w) in ports.items())
    driven = [(n, w) for n, (d, w) in ports.items()
              if d == ast.ArgumentDirection.In and n not in ("clk", "rst", "advance")]
    draws = "".join(
        f"      {drive[n]}\n" if n in drive else
        f"      {n} = {{{', '.join(['$urandom'] * ((w + 31) // 32))}}};\n" for n, w in driven)
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
    repeat ({clocks}) begin
      @(negedge clk);
{draws}    end
    $display("{DONE}");
    $finish;
  end
endmodule
"""


def simulate(tmp_path: Path, case: Case, broken: bool, monkeypatch) -> str:
    if broken:
        base = gen.MODULES[case.module]
        assert case.tweak is not None
        tweak = case.tweak
        monkeypatch.setitem(gen.MODULES, case.module, dataclasses.replace(
            base, context=lambda cfg: tweak(base.context(cfg))))
    cfg = load_config(f"configs/{case.config}.toml")
    made = gen.generate(cfg, tmp_path / "rtl", modules=[case.module])
    # the module's files but its top (the part's own module then the only one not instantiated)
    files = [f for f in made.files[case.module]
             if f.stem != gen.MODULES[case.module].top or f.stem == case.part]
    ctx = gen.MODULES[case.module].context(cfg)
    drive = {port: stmt.format(**ctx) for port, stmt in case.drive.items()}
    tb = tmp_path / "tb.sv"
    tb.write_text(random_testbench(files, tmp_path / "rtl" / f"{case.part}.sv", case.clocks,
                                   drive))
    vvp = tmp_path / "sim.vvp"
    subprocess.run(["iverilog", "-g2012", "-o", str(vvp), "-s", "tb", *map(str, files), str(tb)],
                   check=True, capture_output=True, text=True)
    run = subprocess.run(["vvp", "-n", str(vvp)], capture_output=True, text=True, timeout=300)
    return run.stdout + run.stderr


@pytest.mark.parametrize("case", list(CASES) + list(SILENT))
def test_cast_check_silent_when_proved(tmp_path: Path, case: str, monkeypatch) -> None:
    out = simulate(tmp_path, {**CASES, **SILENT}[case], broken=False, monkeypatch=monkeypatch)
    assert DONE in out and "FATAL" not in out, out[-2000:]


@pytest.mark.parametrize("case", list(CASES))
def test_cast_check_fires_when_proof_broken(tmp_path: Path, case: str, monkeypatch) -> None:
    out = simulate(tmp_path, CASES[case], broken=True, monkeypatch=monkeypatch)
    message = CASES[case].message
    assert "FATAL" in out and message in out and DONE not in out, out[-2000:]
