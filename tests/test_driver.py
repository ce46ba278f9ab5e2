"""The C driver of the README (sw/gpf_bot_driver.c) against the generated header: it compiles
without a warning, its seed expansion gives the model's seed words, and the stream sizes it
assumes are the generated IP's."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from gpf.config import load_config
from gpf.model.formats import datapath
from gpf.model.grng import COMPONENTS, seed_words
from gpf.rtl.filter import axi_context
from gpf.rtl.generate import generate

DRIVER = Path("sw/gpf_bot_driver.c")


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_driver_compiles_and_seeds_as_the_model(tmp_path: Path) -> None:
    cfg = load_config("configs/bot.toml")
    rtl = generate(cfg, tmp_path / "rtl", modules=["gpf_bot_axi"]).out_dir
    exe = tmp_path / "driver"
    subprocess.run(["cc", "-std=c11", "-Wall", "-Wextra", "-Werror", "-DGPF_DRIVER_SELFTEST",
                    "-I", str(rtl), str(DRIVER), "-o", str(exe)], check=True)
    header = (rtl / "gpf_bot_regs.h").read_text()
    words = int(re.search(r"SEED_WORDS__COUNT_reset (0x[0-9a-f]+)", header)[1], 16)
    lanes = datapath(cfg).draws() * cfg.lanes
    assert words == COMPONENTS * lanes
    for seed in (1, 12345, 2**63 + 7):
        out = subprocess.run([str(exe), str(seed), str(words)], capture_output=True, text=True,
                             check=True).stdout.split()
        assert [int(w) for w in out] == seed_words(seed, lanes), seed


def test_driver_stream_sizes_are_the_ips() -> None:
    ctx = axi_context(load_config("configs/bot.toml"))
    text = DRIVER.read_text()
    sizes = {name: int(n) for name, n in re.findall(r"dma_\w+\((S_INIT|S_STEP|M_EST), \w+"
                                                    r"(?:\[k\])?, (\d+)\)", text)}
    assert sizes == {"S_INIT": ctx["init_bytes"], "S_STEP": ctx["step_bytes"],
                     "M_EST": ctx["est_bytes"]}
