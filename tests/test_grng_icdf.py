"""The GRNG's inversion (grng_icdf) against the model on uniforms a random stream almost never
draws: every leading-zero count of p from 0 to 63 (a count of 16 or more comes once in 65,536
words), random bits below the leading one, both signs. Icarus, a plain SystemVerilog testbench
(the lane has no handshake: a word in every clock, its sample a fixed number of clocks later)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from gpf.config import config_path, load_config
from gpf.model.grng import GrngModel
from gpf.rtl.generate import generate
from gpf.toolchain import icarus_missing

pytestmark = pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")

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


def simulate(tmp_path: Path, words: np.ndarray) -> list[int | None]:
    cfg = load_config(config_path("bot"))
    rtl = generate(cfg, tmp_path / "rtl", modules=["grng"]).out_dir / "grng_icdf.sv"
    (tmp_path / "u.hex").write_text("".join(f"{int(w):016x}\n" for w in words))
    n = len(words)
    (tmp_path / "tb.sv").write_text(f"""`timescale 1ns/1ps
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
    subprocess.run(["iverilog", "-g2012", "-o", "sim.vvp", "tb.sv", str(rtl)], cwd=tmp_path,
                   check=True, capture_output=True, text=True)
    run = subprocess.run(["vvp", "-n", "sim.vvp"], cwd=tmp_path, capture_output=True, text=True)
    assert run.returncode == 0 and "FATAL" not in run.stdout, run.stdout[-2000:]
    # x until the pipeline (no reset) holds words
    return [None if "x" in v else int(v) for v in (tmp_path / "samples.txt").read_text().split()]


def test_every_leading_zero_count_inverts_as_the_model(tmp_path: Path) -> None:
    words = directed_uniforms()
    model = GrngModel(load_config(config_path("bot")), lanes=1)
    expected = model.from_uniforms(words).tolist()
    out = simulate(tmp_path, words)
    n = len(words)
    lags = [lag for lag in range(MAX_LAG) if out[lag:lag + n] == expected]
    assert len(lags) == 1, (
        "no clock offset gives the model's samples: first differences at offset 10: "
        + str([(k, out[10 + k], e) for k, e in enumerate(expected) if out[10 + k] != e][:5]))
