"""The GRNG's inversion (grng_icdf) against the model on uniforms a random stream almost never
draws: every leading-zero count of p (tb/grng/icdf_directed.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gpf.config import config_path, load_config
from gpf.tb.grng.icdf_directed import check
from gpf.toolchain import icarus_missing

pytestmark = pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")


def test_every_leading_zero_count_inverts_as_the_model(tmp_path: Path) -> None:
    problem = check(load_config(config_path("bot")), tmp_path)
    assert problem is None, problem
