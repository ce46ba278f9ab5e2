"""slang's analysis pass in `gpf lint` (rtl/lint.py): design problems no compile reports, each a
lint failure, on small files of one problem each; and the control that passes."""

from __future__ import annotations

from pathlib import Path

import pytest

from gpf.rtl.lint import slang_lint

FIXTURES = Path(__file__).parent / "data" / "lint"


@pytest.mark.parametrize("name,finding", [
    ("multi_driven", "[-Wmultiple-always-assigns]"),
    ("unused", "[-Wunused-but-set-variable]"),
    ("undriven", "[-Wunassigned-variable]"),
])
def test_slang_reports_design_problem(name: str, finding: str) -> None:
    text = slang_lint([FIXTURES / f"{name}.sv"], name)
    assert "error: " in text and finding in text, text


def test_slang_passes_the_control() -> None:
    assert slang_lint([FIXTURES / "clean.sv"], "clean") == ""
