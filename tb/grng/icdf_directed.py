"""The GRNG's inversion (grng_icdf) against the model on uniforms a random stream almost never
draws: every leading-zero count of p from 0 to 63 (a count of 16 or more comes once in 65,536
words), random bits below the leading one, both signs. Icarus, a plain SystemVerilog bench (the
lane has no handshake: a word in every clock, its sample a fixed number of clocks later).
tests/test_grng_icdf.py runs it in make test; `gpf mutants` runs it for the GRNG's mutants after
the block's cocotb testbench (a mutant of the deep tail survives any random stream)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from gpf.config import Config
from gpf.model.grng import GrngModel
from gpf.rtl.generate import generate

PER_COUNT = 6       # words per leading-zero count and sign
MAX_LAG = 24        # clocks searched for the lane's latency


def directed_uniforms(seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    words = []
    for lz in range(64):
        for _ in range(PER_COUNT):
            for sign in (0, 1):
                lead = 1 << (62 - lz) if lz < 63 else 0
                below = int(rng.integers(0, 1 << 62, dtype=np.uint64)) & (lead - 1) if lead else 0
                words.append((sign << 63) | lead | below)
    return np.array(words, dtype=np.uint64)


def simulate(cfg: Config, work: Path, words: np.ndarray,
             template_dir: Path | None = None) -> list[int | None]:
    """grng_icdf's samples, one a clock, for `words` (then the first MAX_LAG again): None while
    the pipeline (no reset) still holds x."""
    kw = {} if template_dir is None else {"template_dir": template_dir}
    rtl = generate(cfg, work / "rtl", modules=["grng"], **kw).out_dir / "grng_icdf.sv"
    (work / "u.hex").write_text("".join(f"{int(w):016x}\n" for w in words))
    n = len(words)
    (work / "tb.sv").write_text(f"""`timescale 1ns/1ps
module tb;
  logic clk = 1'b0;
  logic [63:0] mem [{n}];
  logic [63:0] uniform;
  logic signed [{cfg.noise.width - 1}:0] sample;
  integer f, k;
  grng_icdf dut (.clk(clk), .uniform(uniform), .sample(sample));
  initial begin
    $readmemh("u.hex", mem);
    f = $fopen("samples.txt", "w");
    for (k = 0; k < {n + MAX_LAG}; k++) begin
      uniform = k < {n} ? mem[k] : mem[k % {n}];
      #5 clk = 1'b1;
      #5 clk = 1'b0;
      $fwrite(f, "%0d\\n", sample);
    end
    $fclose(f);
    $finish;
  end
endmodule
""")
    subprocess.run(["iverilog", "-g2012", "-o", "sim.vvp", "tb.sv", str(rtl.resolve())], cwd=work,
                   check=True, capture_output=True, text=True)
    run = subprocess.run(["vvp", "-n", "sim.vvp"], cwd=work, capture_output=True, text=True)
    if run.returncode != 0 or "FATAL" in run.stdout:
        raise AssertionError(run.stdout[-2000:])
    return [None if "x" in v else int(v) for v in (work / "samples.txt").read_text().split()]


def check(cfg: Config, work: Path, template_dir: Path | None = None) -> str | None:
    """None when some clock offset gives the model's sample for every directed word; else what
    differs."""
    work.mkdir(parents=True, exist_ok=True)
    words = directed_uniforms()
    expected = GrngModel(cfg, lanes=1).from_uniforms(words).tolist()
    out = simulate(cfg, work, words, template_dir)
    n = len(words)
    lags = [lag for lag in range(MAX_LAG) if out[lag:lag + n] == expected]
    if len(lags) == 1:
        return None
    # the lane's latency: the offset that matches the most words
    best = max(range(MAX_LAG), key=lambda lag: sum(a == e for a, e in
                                                  zip(out[lag:lag + n], expected, strict=True)))
    diff = [(k, int(words[k]), out[best + k], e) for k, e in enumerate(expected)
            if out[best + k] != e]
    return (f"grng_icdf's directed words: {len(diff)} of {n} differ from the model at the "
            f"best clock offset {best}; first (index, word, RTL, model): {diff[:3]}")
