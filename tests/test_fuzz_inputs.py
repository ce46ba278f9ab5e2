"""Property-based fuzzing of what a user feeds `gpf` end to end (nothing stubbed): mutated
configs, mutated scenario recordings (CSV) and output paths that collide with the inputs.

For every example: exit 0 with strictly parsable JSON whose numbers are all finite, or exit 2
with one line on stderr and no traceback; and no file but the requested output changed (every
other file in the folder keeps its checksum; a refused or failed command leaves even the
requested output as it was). `make test` runs a bounded, derandomized search (its examples
replay exactly); `make regress` a longer random one, with `gpf run` on tiny sizes.
Every finding of the bad-input issue is a named example (@example).
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from test_fuzz_cli import toml_doc

from gpf import cli
from gpf.config import load_config
from gpf.model.scenarios import TRUTH, write_csv
from gpf.study.montecarlo import SCENARIOS

SHIPPED = {app: tomllib.loads(Path(f"configs/{app}.toml").read_text()) for app in ("bot", "uav")}
SCENARIO = {"bot": "bot_fixed_observer", "uav": "uav_flight"}
STEPS = 4
BOUNDED = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                   suppress_health_check=[HealthCheck.function_scoped_fixture,
                                          HealthCheck.too_slow])
LONG = settings(max_examples=400, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

# what a CSV cell or a config value may become
ODD_NUMBERS = [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e30, -1e30, 1e-300, 0.0, -0.0,
               1e6, -1e6, 2.0**63, 7.0]
ODD_TEXT = ["", "abc", "1,2", "0x10", "nan", "inf", "1e999", " 3 ", "\u00e9", "--"]


@dataclass
class Case:
    app: str
    config: dict[str, Any] = field(default_factory=dict)   # "section.key" -> value
    cells: list[tuple[int, int, Any]] = field(default_factory=list)   # (row, column, value)
    drop_columns: list[int] = field(default_factory=list)
    truthless: bool = False
    scenario: str = "csv"     # "csv": the recording; else a scenario name
    json_to: str = "new"      # new | existing | config | csv | folder | missing-folder
    args: list[str] = field(default_factory=list)
    expect: str | None = None   # a word the refusal must name; "ok": must succeed

    def refusals(self) -> list[str] | None:
        """Words of which a refusal must name one ([]: any refusal; None: it may succeed)."""
        words = [self.expect] if self.expect and self.expect != "ok" else []
        if self.json_to in ("config", "folder") or (self.json_to == "csv"
                                                    and self.scenario == "csv"):
            words.append("--json")
        if self.scenario != "csv" and not self.scenario.startswith(self.app):
            words.append("scenario")
        if not words:
            return None
        # with a mutated input too, that may be what the refusal names first
        return [] if (self.config or self.cells or self.drop_columns) and not self.expect \
            else words


def _checksums(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _strict(text: str) -> Any:
    def refuse(token: str) -> None:
        raise ValueError(f"non-standard JSON token {token}")
    doc = json.loads(text, parse_constant=refuse)

    def walk(x: Any) -> None:
        if isinstance(x, float):
            assert math.isfinite(x), x
        elif isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)
    walk(doc)
    return doc


def _write_inputs(case: Case, folder: Path) -> tuple[Path, Path]:
    doc = json.loads(json.dumps(SHIPPED[case.app]))
    for key, value in case.config.items():
        section, name = key.split(".")
        doc.setdefault(section, {})[name] = value
    config = folder / "my.toml"
    config.write_text(toml_doc(doc))
    cfg = load_config(f"configs/{case.app}.toml")
    sc = SCENARIOS[SCENARIO[case.app]](cfg, STEPS, 3)
    csv = folder / "recording.csv"
    write_csv(sc, csv)
    lines = csv.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    rows = [line.split(",") for line in lines[head:]]
    if case.truthless:   # a recording: the truth columns empty
        truth = [j for j, name in enumerate(rows[0]) if name in TRUTH[case.app]]
        for r in rows[1:]:
            for j in truth:
                r[j] = ""
    for r, c, value in case.cells:
        row = rows[1 + r % (len(rows) - 1)]
        row[c % len(row)] = value if isinstance(value, str) else repr(value)
    for c in sorted({c % len(rows[0]) for c in case.drop_columns}, reverse=True):
        for r in rows:
            del r[c]
    csv.write_text("\n".join(lines[:head] + [",".join(r) for r in rows]) + "\n")
    return config, csv


def _json_path(case: Case, folder: Path, config: Path, csv: Path) -> Path:
    existing = folder / "previous.json"
    existing.write_text('{"previous": true}\n')
    return {"new": folder / "out.json", "existing": existing, "config": config, "csv": csv,
            "folder": folder, "missing-folder": folder / "no" / "such" / "out.json"}[case.json_to]


def check_command(case: Case, folder: Path, capsys: pytest.CaptureFixture[str],
                  rtl: bool = False) -> None:
    """`gpf model run` (or with `rtl`, `gpf run`) on the case's inputs: see the docstring."""
    config, csv = _write_inputs(case, folder)
    out = _json_path(case, folder, config, csv)
    before = _checksums(folder)
    scenario = str(csv) if case.scenario == "csv" else case.scenario
    command = ["run"] if rtl else ["model", "run", "--runs", "1"]
    if case.scenario != "csv":   # a named scenario: as short as the recording
        command += ["--steps", str(STEPS)]
    argv = [*command, "--config", str(config), "--scenario", scenario, "--particles", "16",
            "--json", str(out), *case.args]
    capsys.readouterr()
    status = cli.main(argv)
    stdout, err = capsys.readouterr()
    assert "Traceback" not in err + stdout, err
    after = _checksums(folder)
    written = str(out.relative_to(folder)) if out.is_relative_to(folder) else None
    changed = {name for name in before.keys() | after.keys()
               if before.get(name) != after.get(name)}
    refusals = case.refusals()
    if refusals is not None:
        assert status == 2 and (not refusals or any(w in err for w in refusals)), \
            (status, refusals, err)
    if case.expect == "ok":
        assert status == 0, err
    if status == 0:
        assert changed <= {written}, f"files changed beside the output: {changed - {written}}"
        _strict(out.read_text())
    else:
        assert status == 2, (status, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gpf"), err
        assert not changed, f"a refused command changed {changed}"


CELL = st.tuples(st.integers(0, STEPS), st.integers(0, 30),
                 st.one_of(st.sampled_from(ODD_NUMBERS), st.sampled_from(ODD_TEXT),
                           st.floats(-1e6, 1e6)))
CONFIG_KEYS = {
    "bot": ["bot.x0", "bot.sigma0_diag", "bot.process_var", "bot.bearing_var", "filter.dt",
            "filter.particles", "filter.lanes"],
    "uav": ["uav.sigma0_diag", "uav.sigma_a", "uav.sigma_v", "uav.sigma_omega_deg",
            "filter.dt", "filter.particles"],
}


@st.composite
def cases(draw: st.DrawFn) -> Case:
    app = draw(st.sampled_from(["bot", "uav"]))
    config = {}
    some = st.sampled_from([0, 0, 1, 2])   # half the cases leave a part as shipped
    for key in draw(st.lists(st.sampled_from(CONFIG_KEYS[app]), max_size=draw(some),
                             unique=True)):
        current = SHIPPED[app][key.split(".")[0]].get(key.split(".")[1])
        number = st.sampled_from(ODD_NUMBERS) | st.floats(-1e4, 1e4)
        config[key] = ([draw(number) for _ in current] if isinstance(current, list)
                       else draw(number))
    return Case(app, config,
                draw(st.lists(CELL, max_size=draw(some))),
                draw(st.lists(st.integers(0, 30), max_size=1)), draw(st.booleans()),
                draw(st.sampled_from(["csv", "csv", "csv", "bot_fixed_observer", "uav_flight"])),
                draw(st.sampled_from(["new", "new", "existing", "config", "csv", "folder",
                                      "missing-folder"])))


@pytest.mark.slow
@BOUNDED
@given(case=cases())
# the findings, each a named example
@example(case=Case("bot", json_to="config"))                 # --json over the config
@example(case=Case("bot", json_to="csv"))                    # --json over the recording
@example(case=Case("bot", config={"bot.x0": [1000.0, 0.0, 0.0, 0.0]}, expect="x0"))  # s7.10
@example(case=Case("bot", cells=[(1, 3, 1e300)], expect="row 1"))   # a measurement of 1e300
@example(case=Case("bot", truthless=True, expect="ok"))      # a recording without truth
@example(case=Case("bot", scenario="uav_flight"))            # a scenario of the other app
@example(case=Case("uav", scenario="bot_fixed_observer"))
@example(case=Case("uav", config={"uav.sigma_a": 1e30}, expect="sigma_a"))   # absurd noise
@example(case=Case("bot", config={"bot.process_var": 1e30}, expect="process_var"))
@example(case=Case("bot", config={"bot.process_var": 1e300}, expect="process_var"))  # 2^481
@example(case=Case("bot", config={"bot.bearing_var": 1e-12}, expect="bearing_var"))
@example(case=Case("bot", config={"filter.lanes": 64}, expect="lanes"))
@example(case=Case("bot", args=["--particles", "4096"], expect="--particles"))
def test_model_run_bad_inputs(tmp_path_factory: pytest.TempPathFactory,
                              capsys: pytest.CaptureFixture[str], case: Case) -> None:
    check_command(case, tmp_path_factory.mktemp("fuzz"), capsys)


@pytest.mark.regress
@LONG
@given(case=cases())
def test_model_run_bad_inputs_long(tmp_path_factory: pytest.TempPathFactory,
                                   capsys: pytest.CaptureFixture[str], case: Case) -> None:
    check_command(case, tmp_path_factory.mktemp("fuzz"), capsys)


@st.composite
def rtl_cases(draw: st.DrawFn) -> Case:
    """Recordings and output paths only, on the shipped bot config: one Verilator build."""
    case = draw(cases())
    return Case("bot", {}, case.cells, case.drop_columns, case.truthless,
                case.scenario if case.scenario != "uav_flight" else "csv", case.json_to)


@pytest.mark.regress
@pytest.mark.sim
@settings(LONG, max_examples=30)
@given(case=rtl_cases())
@example(case=Case("bot", json_to="csv"))
@example(case=Case("bot", cells=[(1, 3, 1e300)], expect="row 1"))
@example(case=Case("bot", truthless=True, expect="ok"))
def test_rtl_run_bad_inputs(tmp_path_factory: pytest.TempPathFactory,
                            capsys: pytest.CaptureFixture[str], case: Case) -> None:
    check_command(case, tmp_path_factory.mktemp("fuzz"), capsys, rtl=True)


def test_internal_error_one_line_and_traceback_with_debug(monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str],
                                                         tmp_path: Path) -> None:
    """A bug (not the user's input) is one line and status 3; --debug shows its traceback."""
    import gpf.rtl.generate

    def bug(*args: Any, **kwargs: Any) -> None:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(gpf.rtl.generate, "generate", bug)
    argv = ["generate", "--config", "bot", "--out", str(tmp_path / "rtl")]
    assert cli.main(argv) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error: ZeroDivisionError: a bug" in err
    with pytest.raises(ZeroDivisionError):
        cli.main(["--debug", *argv])
