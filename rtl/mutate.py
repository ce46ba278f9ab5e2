"""Mutants of the templates' literal SystemVerilog: the text outside Jinja and outside comments.

A template's text is masked first: Jinja expressions become runs of `J` (an identifier to the
scanner: `{{ name }}_q` reads as one name), Jinja statements and comments, SV comments, strings
and simulation-only checks (`ifndef SYNTHESIS ... `endif: verification, not the design) become
blanks. Every mutation site is then found in the masked text and applied to the template at the
same offsets, so a mutant never edits Jinja and the template still renders.

A mutant's id is `<template>:<line>:<column>:<class>[:<variant>]`, the site's place in the
unmutated template: stable while that line is not edited.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

CLASSES = ("arith", "logic", "shift", "compare", "const", "slice", "negate", "reg-hold")

_JINJA = re.compile(r"\{\{.*?\}\}|\{%.*?%\}|\{#.*?#\}", re.S)
_DECLARATION = re.compile(r"^\s*(?:input|output|inout|logic|wire|reg|bit|int|integer|"
                          r"localparam\s+(?:logic|bit)|parameter\s+(?:logic|bit)|"
                          r"function|task)\b")
_IDENT = r"[A-Za-z_$][\w$]*"
_WINDOW = 400   # how far back an lvalue or an operand is looked for


@dataclass(frozen=True)
class Mutant:
    template: str
    offset: int      # where `before` starts in the template
    line: int
    column: int
    cls: str
    before: str
    after: str
    variant: int = 0   # several mutants of one class at one site (a constant +1 and -1)

    @property
    def id(self) -> str:
        tail = f":{self.variant}" if self.variant else ""
        return f"{self.template}:{self.line}:{self.column}:{self.cls}{tail}"

    def apply(self, text: str) -> str:
        assert text[self.offset:self.offset + len(self.before)] == self.before, self.id
        return text[:self.offset] + self.after + text[self.offset + len(self.before):]


def mask(text: str) -> str:
    """The template with everything but literal SV blanked (newlines kept: offsets and lines
    stay those of the template); Jinja expressions as `J`s."""
    out = list(text)

    def blank(a: int, b: int, fill: str = " ") -> None:
        for i in range(a, b):
            if out[i] != "\n":
                out[i] = fill

    for m in _JINJA.finditer(text):
        blank(m.start(), m.end(), "J" if m.group().startswith("{{") else " ")
    masked = "".join(out)
    # SV comments, strings and `ifndef SYNTHESIS regions, on the Jinja-masked text
    i = 0
    while i < len(masked):
        if masked.startswith("//", i):
            end = masked.find("\n", i)
            end = len(masked) if end < 0 else end
        elif masked.startswith("/*", i):
            end = masked.find("*/", i + 2)
            end = len(masked) if end < 0 else end + 2
        elif masked[i] == '"':
            end = masked.find('"', i + 1)
            end = len(masked) if end < 0 else end + 1
        elif masked.startswith("`ifndef SYNTHESIS", i):
            end = _endif(masked, i)
        else:
            i += 1
            continue
        blank(i, end)
        i = end
    return "".join(out)


def _endif(text: str, start: int) -> int:
    """The end of the `ifdef/`ifndef block opened at `start` (nesting counted)."""
    depth = 0
    for m in re.compile(r"`(ifdef|ifndef|endif)\b").finditer(text, start):
        depth += -1 if m.group(1) == "endif" else 1
        if depth == 0:
            return m.end()
    return len(text)


def _brackets(masked: str) -> list[tuple[int, int]]:
    """The [..] ranges of declaration lines (widths: mutating them changes a type, not logic)."""
    spans = []
    pos = 0
    for line in masked.splitlines(keepends=True):
        if _DECLARATION.match(line):
            spans += [(pos + m.start(), pos + m.end()) for m in re.finditer(r"\[[^\]]*\]", line)]
        pos += len(line)
    return spans


def _cast_widths(masked: str) -> list[tuple[int, int]]:
    """The widths of casts, `(W+1)'(x)` and `8'(x)`: a type, not a value (a wider cast is
    truncated back where it is used; a narrower one is a different width, not logic)."""
    spans = []
    for m in re.finditer(r"'\(", masked):
        end = m.start()
        if masked[end - 1:end] == ")":
            start = _matching(masked, end - 1, -1)
            if start is not None:
                spans.append((start, end))
        else:
            size = re.search(r"\d+$", masked[max(0, end - 12):end])
            if size:
                spans.append((end - len(size.group()), end))
    return spans


def _nonblocking(masked: str, at: int) -> bool:
    """Whether the `<=` at `at` assigns (x_q <= ...) rather than compares: an lvalue (a name,
    indexed, or a concatenation) right after a statement's start."""
    before = masked[max(0, at - _WINDOW):at].rstrip()
    lvalue = re.search(r"(?:" + _IDENT + r"(?:\s*\[[^\]]*\])*|\{[^{}]*\})$", before)
    if not lvalue:
        return False
    head = before[:lvalue.start()].rstrip()
    return head == "" or bool(re.search(r"(?:[;)]|\bbegin|\bend|\belse|\bdefault\s*:)$", head))


_OPERATORS = [
    # (pattern on the masked text, class, replacements)
    (r"(?<![+<>=!&|^~*/%'])\+(?![+:=])", "arith", ["-"]),
    (r"(?<![-<>=!&|^~*/%'])-(?![-:=>])", "arith", ["+"]),
    (r"(?<![&|])&&(?![&])", "logic", ["||"]),
    (r"(?<![|&])\|\|(?![|])", "logic", ["&&"]),
    (r"(?<![&|~])&(?![&=])", "logic", ["|"]),
    (r"(?<![|&~])\|(?![|=])", "logic", ["&"]),
    (r"(?<![~])\^(?![~=])", "logic", ["|"]),
    (r"(?<![<])<<<(?![<=])", "shift", [">>>"]),
    (r"(?<![>])>>>(?![>=])", "shift", ["<<<", ">>"]),
    (r"(?<![<])<<(?![<=])", "shift", [">>"]),
    (r"(?<![>])>>(?![>=])", "shift", ["<<"]),
    (r"(?<![<>=!])==(?!=)", "compare", ["!="]),
    (r"!=(?!=)", "compare", ["=="]),
    (r"(?<![<>=!])>=", "compare", [">"]),
    (r"(?<![<>=!-])>(?![>=])", "compare", [">="]),
    (r"(?<![<>=!])<=", "compare", ["<"]),
    (r"(?<![<>=!])<(?![<=])", "compare", ["<="]),
]

_SIZED = re.compile(r"(?<![\w$])(\d+|J+)\s*'(s?)([dDbBhHoO])([0-9a-fA-F_]+)(?![\w$'])")
_UNSIZED = re.compile(r"(?<![\w$'.])'([01])(?![\w$'])")
_DECIMAL = re.compile(r"(?<![\w$'.])(\d+)(?![\w$'.])")
_SLICE = re.compile(r"(?<=[\w$\]])\[(\d+)(?::(\d+))?\]")
_BASES = {"d": 10, "b": 2, "h": 16, "o": 8}


def scan(name: str, text: str) -> list[Mutant]:
    """Every mutant of one template's literal SV, in the order of their sites."""
    masked = mask(text)
    decl = _brackets(masked) + _cast_widths(masked)
    resets = _reset_spans(masked)
    found: list[tuple[int, str, str, str]] = []   # offset, class, before, after

    declared = bytearray(len(masked) + 1)
    for a, b in decl:
        declared[a:b] = b"\x01" * (b - a)

    def in_decl(at: int) -> bool:
        return bool(declared[at])

    for pattern, cls, replacements in _OPERATORS:
        for m in re.finditer(pattern, masked):
            at = m.start()
            if in_decl(at) or _in_literal(masked, at):
                continue
            if m.group() == "<=" and _nonblocking(masked, at):
                continue
            for new in replacements:
                found.append((at, cls, m.group(), new))
    taken: set[int] = set()
    for m in _SIZED.finditer(masked):
        if in_decl(m.start()):
            continue
        width = int(m.group(1)) if m.group(1).isdigit() else None
        base = _BASES[m.group(3).lower()]
        digits = m.group(4).replace("_", "")
        value = int(digits, base)
        at = m.start(4)
        taken.update(range(m.start(), m.end()))
        for new in (value + 1, value - 1):
            limit = 2 ** width if width else None
            if new < 0 or (limit is not None and new >= limit):
                continue
            found.append((at, "const", m.group(4), _digits(new, base, len(digits))))
    for m in _UNSIZED.finditer(masked):
        if not in_decl(m.start()):
            found.append((m.start(), "const", m.group(), "'1" if m.group(1) == "0" else "'0"))
    slices = set()
    for m in _SLICE.finditer(masked):
        if in_decl(m.start()):
            continue
        slices.update(range(m.start(), m.end()))
        hi = int(m.group(1))
        lo = None if m.group(2) is None else int(m.group(2))
        for step in (1, -1):
            if hi + step < 0 or (lo is not None and lo + step < 0):
                continue
            new = f"[{hi + step}]" if lo is None else f"[{hi + step}:{lo + step}]"
            found.append((m.start(), "slice", m.group(), new))
    for m in _DECIMAL.finditer(masked):
        at = m.start()
        if at in taken or at in slices or in_decl(at) or _in_literal(masked, at):
            continue
        value = int(m.group(1))
        for new in (value + 1, value - 1):
            if new >= 0:
                found.append((at, "const", m.group(1), str(new)))
    found += _negations(masked, text)
    found += _register_holds(masked, text)
    # reset values are not mutated: a datapath register's reset value is overwritten before
    # any valid bit lets it out (a class of equivalent mutants, not of test gaps)
    in_reset = bytearray(len(masked) + 1)
    for a, b in resets:
        in_reset[a:b] = b"\x01" * (b - a)
    found = [f for f in found if f[1] != "const" or not in_reset[f[0]]]
    return _numbered(name, text, found)


def _reset_spans(masked: str) -> list[tuple[int, int]]:
    """The branches `if (rst) begin ... end` and `if (rst) stmt;`."""
    spans = []
    for m in re.finditer(r"\bif\s*\(\s*rst\s*\)\s*", masked):
        if masked.startswith("begin", m.end()):
            depth = 0
            for k in re.compile(r"\b(begin|end)\b").finditer(masked, m.end()):
                depth += 1 if k.group(1) == "begin" else -1
                if depth == 0:
                    spans.append((m.end(), k.end()))
                    break
        else:
            end = _statement_end(masked, m.end())
            if end is not None:
                spans.append((m.end(), end))
    return spans


def _in_literal(masked: str, at: int) -> bool:
    """Whether `at` is inside a based literal's digits (4'b1?0 is not an operator)."""
    m = re.search(r"'s?[dDbBhHoO][0-9a-fA-FxXzZ_?]*$", masked[max(0, at - 80):at + 1])
    return m is not None


def _digits(value: int, base: int, width: int) -> str:
    text = {10: str, 2: lambda v: format(v, "b"), 16: lambda v: format(v, "x"),
            8: lambda v: format(v, "o")}[base](value)
    return text.zfill(width) if base != 10 else text


def _negations(masked: str, text: str) -> list[tuple[int, str, str, str]]:
    """`if (c)` -> `if (!(c))`; `c ? a : b` -> `!(c) ? a : b` for c a (possibly indexed) name
    or a parenthesised expression right before the `?`."""
    out = []
    for m in re.finditer(r"\bif\s*\(", masked):
        close = _matching(masked, m.end() - 1)
        if close is None:
            continue
        inner = text[m.end():close]
        if _clean(text, m.end(), close):
            out.append((m.end(), "negate", inner, f"!({inner})"))
    for m in re.finditer(r"\?", masked):
        if _in_literal(masked, m.start()):
            continue
        end = len(masked[:m.start()].rstrip())
        if masked[end - 1] == ")":
            start = _matching(masked, end - 1, -1)
            if start is not None and masked[start - 1:start] == "'":
                continue   # a cast's operand: (W)'(x) ? -- its width is not negated
        else:
            base = max(0, end - _WINDOW)
            operand = re.search(r"(?:" + _IDENT + r"(?:\[[^\]\n]*\])*)$", masked[base:end])
            start = base + operand.start() if operand else None
        if start is None or start == end or not _clean(text, start, end):
            continue
        if re.match(r"\b(?:if|case)\b", masked[start:end]):
            continue
        unary, head = masked[start - 1:start], masked[:start - 1].rstrip()[-1:]
        if unary in "!~|&^" and unary and (not head or head in "(=?:,{"):
            if unary == "!":   # !c ? -> c ? (Icarus refuses !!(c))
                out.append((start - 1, "negate", text[start - 1:end], text[start:end]))
            else:              # a reduction: |x ? -> !(|x) ?
                out.append((start - 1, "negate", text[start - 1:end],
                            f"!({text[start - 1:end]})"))
            continue
        if unary in "!~|&^" and unary:
            continue
        out.append((start, "negate", text[start:end], f"!({text[start:end]})"))
    return out


def _register_holds(masked: str, text: str) -> list[tuple[int, str, str, str]]:
    """A registered `x_q <= expr;` whose expression is not a constant -> `x_q <= x_q;`: the
    register holds (a pipeline stage dropped from the data's path)."""
    out = []
    for m in re.finditer(r"<=", masked):
        at = m.start()
        if not _nonblocking(masked, at) or _in_literal(masked, at):
            continue
        base = max(0, at - _WINDOW)
        before = masked[base:at].rstrip()
        found = re.search(r"(?:" + _IDENT + r"(?:\s*\[[^\]]*\])*|\{[^{}]*\})$", before)
        lvalue = None if found is None else (base + found.start(), base + found.end())
        end = _statement_end(masked, m.end())
        if lvalue is None or end is None:
            continue
        start = m.end() + (len(masked[m.end():end]) - len(masked[m.end():end].lstrip()))
        rhs = masked[start:end].strip()
        if not rhs or re.fullmatch(r"(?:'[01]|\d*'s?[dbhoDBHO][0-9a-fA-F_]+|\d+|J+)", rhs):
            continue
        if not _clean(text, start, end) or not _clean(text, *lvalue):
            continue
        target = text[lvalue[0]:lvalue[1]]
        if target.strip() == text[start:end].strip():
            continue
        out.append((start, "reg-hold", text[start:end], target))
    return out


def _clean(text: str, a: int, b: int) -> bool:
    """Whether text[a:b] holds no Jinja statement or comment: replacing it must not cut an
    {% if %} from its {% endif %}."""
    span = text[a:b]
    return not any(tag in span for tag in ("{%", "%}", "{#", "#}"))


def _matching(masked: str, at: int, step: int = 1) -> int | None:
    """The parenthesis matching the one at `at`: searching forward from a "(" (step 1) or back
    from a ")" (step -1)."""
    inward, outward = ("(", ")") if step == 1 else (")", "(")
    depth = 0
    for i in range(at, len(masked) if step == 1 else -1, step):
        if masked[i] == inward:
            depth += 1
        elif masked[i] == outward:
            depth -= 1
            if depth == 0:
                return i
    return None


def _statement_end(masked: str, start: int) -> int | None:
    depth = 0
    for i in range(start, len(masked)):
        c = masked[i]
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == ";" and depth == 0:
            return i
    return None


def _numbered(name: str, text: str, found: list[tuple[int, str, str, str]]) -> list[Mutant]:
    out: list[Mutant] = []
    seen: dict[tuple[int, str], int] = {}
    for at, cls, before, after in sorted(found, key=lambda f: (f[0], CLASSES.index(f[1]))):
        if before == after:
            continue
        line = text.count("\n", 0, at) + 1
        column = at - (text.rfind("\n", 0, at) + 1) + 1
        variant = seen.get((at, cls), 0)
        seen[(at, cls)] = variant + 1
        out.append(Mutant(name, at, line, column, cls, before, after, variant))
    return out


def scan_dir(template_dir: Path, names: list[str] | None = None) -> list[Mutant]:
    """The mutants of every SV template in `template_dir` (or of the named ones)."""
    paths = sorted(template_dir.glob("*.sv.j2"))
    return [mu for p in paths if names is None or p.name in names
            for mu in scan(p.name, p.read_text())]
