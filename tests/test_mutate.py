"""The mutation engine (gpf.rtl.mutate) and `gpf mutants`: mutants of literal SV only, stable ids,
a known mutant killed and a listed equivalent marked as such."""

from __future__ import annotations

import random
import re
from pathlib import Path

import jinja2
import pytest

from gpf.mutants import EQUIVALENT_FILE, campaign, equivalents
from gpf.rtl.generate import TEMPLATE_DIR
from gpf.rtl.mutate import Mutant, mask, scan, scan_dir
from gpf.toolchain import icarus_missing

SMALL = """{% set w = 4 %}
// a + b, in a comment
module m (
  input  logic [{{ w - 1 }}:0] a,
  input  logic clk, rst,
  output logic y_q
);
  assign y = a[0] & {{ "a[1] | a[2]" }};
`ifndef SYNTHESIS
  always @(posedge clk) if (a == 0) $fatal(1, "a + b");
`endif
  always_ff @(posedge clk) begin
    if (rst) y_q <= '0;
    else y_q <= a[1] + 1'b1;
  end
endmodule
"""


def test_small_template_mutants_are_exactly_the_literal_sites() -> None:
    found = {(mu.id, mu.before, mu.after) for mu in scan("t.sv.j2", SMALL)}
    assert found == {
        ("t.sv.j2:8:15:slice", "[0]", "[1]"),
        ("t.sv.j2:8:19:logic", "&", "|"),
        ("t.sv.j2:13:9:negate", "rst", "!(rst)"),     # its '0 is a reset value: not mutated
        ("t.sv.j2:14:17:reg-hold", "a[1] + 1'b1", "y_q"),
        ("t.sv.j2:14:18:slice", "[1]", "[2]"),
        ("t.sv.j2:14:18:slice:1", "[1]", "[0]"),
        ("t.sv.j2:14:22:arith", "+", "-"),
        ("t.sv.j2:14:27:const", "1", "0"),
    }


def test_a_functions_declared_ranges_are_not_mutated() -> None:
    """A function's return and input ranges are types, as a signal's are; its body is logic."""
    text = SMALL.replace("endmodule", """  function automatic logic [3:0] f(input logic [3:0] r);
    f = r + 4'd1;
  endfunction
endmodule""")
    lines = {int(mu.id.split(":")[1]) for mu in scan("t.sv.j2", text)}
    assert 16 not in lines and 17 in lines


def test_a_sample_and_a_shard_keep_their_mutants_when_others_change() -> None:
    """Removing mutants (a template edited elsewhere) leaves the rest of a sample and of each
    shard as they were; the shards split a selection exactly once."""
    from gpf.mutants import Target, select

    mutants = [Mutant("t.sv.j2", i, i, 1, "const", "1", "0") for i in range(1, 401)]
    assigned = {mu.id: [Target("sqrt", "bot")] for mu in mutants}

    def ids(ms, sample=None, shards=1, shard=0):
        return [mu.id for mu in select(ms, assigned, None, None, sample, 1, shards, shard)]

    sample = ids(mutants, 50)
    fewer = [mu for mu in mutants if mu.id not in sample[:3]]
    assert len(sample) == 50 and set(sample[3:]) <= set(ids(fewer, 50))
    shards = [ids(mutants, shards=4, shard=i) for i in range(4)]
    assert sorted(sum(shards, [])) == sorted(mu.id for mu in mutants)
    assert all(set(ids(fewer, shards=4, shard=i)) == set(shards[i]) - set(sample[:3])
               for i in range(4))


def _jinja_spans(text: str) -> list[tuple[int, int, str]]:
    return [(m.start(), m.end(), m.group()[:2])
            for m in re.finditer(r"\{\{.*?\}\}|\{%.*?%\}|\{#.*?#\}", text, re.S)]


def test_every_mutant_is_outside_jinja_and_comments_and_still_parses() -> None:
    env = jinja2.Environment(trim_blocks=True, lstrip_blocks=True)
    mutants = scan_dir(TEMPLATE_DIR)
    assert len(mutants) > 1000
    texts = {p.name: p.read_text() for p in TEMPLATE_DIR.glob("*.sv.j2")}
    spans = {name: _jinja_spans(text) for name, text in texts.items()}
    masks = {name: mask(text) for name, text in texts.items()}
    for mu in mutants:
        a, b = mu.offset, mu.offset + len(mu.before)
        start = masks[mu.template][a]
        assert start != " " and (start != "J" or mu.cls in ("reg-hold", "negate")), \
            f"{mu.id} starts in Jinja or a comment"
        for s, e, kind in spans[mu.template]:
            inside = s < b and a < e
            # a held register or a negated condition may contain a whole {{ expression }}
            whole = a <= s and e <= b and kind == "{{" and mu.cls in ("reg-hold", "negate")
            assert not inside or whole, f"{mu.id} edits Jinja: {mu.before!r}"
    for mu in random.Random(1).sample(mutants, 150):
        env.parse(mu.apply(texts[mu.template]))   # a mutant never breaks the template's syntax


def test_ids_are_stable() -> None:
    first = [mu.id for mu in scan_dir(TEMPLATE_DIR)]
    assert first == [mu.id for mu in scan_dir(TEMPLATE_DIR)]
    assert len(set(first)) == len(first)
    # a line added below a site leaves its id alone; one added above moves it a line down
    before = {mu.id for mu in scan("t.sv.j2", SMALL)}
    below = {mu.id for mu in scan("t.sv.j2", SMALL.replace("endmodule", "\nendmodule"))}
    assert before == below
    above = {mu.id for mu in scan("t.sv.j2", "\n" + SMALL)}
    assert {i.replace(":8:", ":9:", 1) for i in before if ":8:" in i} <= above


def test_equivalent_entries_name_existing_mutants() -> None:
    """Every reviewed entry still names a mutant of the templates, with its text."""
    mutants = {mu.id: mu for mu in scan_dir(TEMPLATE_DIR)}
    for key, entry in equivalents(EQUIVALENT_FILE).items():
        assert key in mutants, f"{key}: no such mutant (its line moved? re-review it)"
        assert (entry["before"], entry["after"]) == (mutants[key].before, mutants[key].after)
        assert len(entry["reason"]) > 20


@pytest.mark.sim
@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
def test_a_known_mutant_is_killed_and_a_listed_equivalent_is_marked(tmp_path: Path,
                                                                    monkeypatch) -> None:
    from gpf import mutants

    killed = "sqrt_lane.sv.j2:42:31:compare"      # a root digit's >= made >
    equivalent = "sqrt.sv.j2:40:32:arith"        # in equivalent.toml
    # the bot config only (the equivalent would run against each of the four sqrt configs)
    monkeypatch.setattr(mutants, "APP_CONFIGS", {"bot": ("bot",), "uav": ()})
    report = campaign(ids=[killed, equivalent], out=tmp_path, log=lambda *_: None)
    import json

    data = json.loads(report.with_suffix(".json").read_text())
    verdicts = {v["id"]: v for v in data["verdicts"]}
    assert verdicts[killed]["status"] == "killed"
    assert verdicts[equivalent]["status"] == "survived"
    assert verdicts[equivalent]["equivalent"] == equivalents()[equivalent]["reason"]
    assert data["scores"]["all"]["score_pct"] == 100.0
    assert "Equivalent survivors (1)" in report.read_text()


def test_a_survivor_runs_against_the_other_targets_rendering_it(tmp_path: Path,
                                                                monkeypatch) -> None:
    """run_campaign's order, with the simulator replaced: a mutant surviving its own target at
    every level runs against the next target that renders it, whose kill is the verdict (that
    target's baseline run first, unmutated, when first needed); a mutant killed at once runs
    nowhere else."""
    from gpf import mutants as m

    mu_a, mu_b = scan_dir(TEMPLATE_DIR, ["sqrt.sv.j2"])[:2]
    original = (TEMPLATE_DIR / "sqrt.sv.j2").read_text()
    applied = {original: "-", mu_a.apply(original): "a", mu_b.apply(original): "b"}
    first, second = m.Target("sqrt", "bot", 2), m.Target("sqrt", "uav", 2)
    calls = []

    def simulate(t, templates, work, level, limit):
        which = applied[(templates / "sqrt.sv.j2").read_text()]
        calls.append((t.config, level, which))
        if which == "b" or (which == "a" and t == second):
            return "killed", "1 of 8 tests failed", 1.0
        return "survived", "8 tests passed", 1.0

    monkeypatch.setattr(m, "simulate", simulate)
    camp = m.run_campaign([mu_a, mu_b], {mu_a.id: [first, second], mu_b.id: [first, second]},
                          tmp_path, "quick", log=lambda *_: None)
    a, b = camp.verdicts
    assert (a.status, a.target) == ("killed", first.name)
    assert a.detail == f"{second.name}: 1 of 8 tests failed (after surviving {first.name})"
    assert (b.status, b.detail) == ("killed", "1 of 8 tests failed")
    assert calls == [("bot", "quick", "-"),                              # the own baseline
                     ("bot", "quick", "a"), ("bot", "short", "a"), ("bot", "default", "a"),
                     ("uav", "quick", "-"),                              # when first needed
                     ("uav", "quick", "a"), ("bot", "quick", "b")]
