"""Every explicit size cast N'(expr) in the generated RTL of a config, with the template line it
came from, the operand's width and the cast's width (the audit behind docs/casts.md).

    .venv/bin/python study/casts_scan.py bot uav odd uav_seed002 bot:lanes=4

Renders each config's modules from a copy of the templates in which every template line starts
with a marker (outside Jinja tags), so a cast in the output names its template line."""

from __future__ import annotations

import bisect
import re
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

from pyslang import ast, syntax

from gpf.config import load_config
from gpf.rtl import generate as gen

MARK = re.compile("\x01([^\x02]*)\x02")


def marked_templates(src: Path, dst: Path) -> None:
    """Copy the templates, each SystemVerilog template's line starting with \x01<name>:<n>\x02
    where the line starts outside a Jinja tag (a line inside one keeps the marker before it)."""
    closer = {"{{": "}}", "{%": "%}", "{#": "#}"}
    for path in src.glob("*.j2"):
        if not path.name.endswith(".sv.j2"):
            (dst / path.name).write_text(path.read_text())
            continue
        text, out, state, i, n = path.read_text(), [], None, 0, 1
        name = path.name.removesuffix(".sv.j2")
        out.append(f"\x01{name}:1\x02")
        quote = None
        while i < len(text):
            c, two = text[i], text[i:i + 2]
            if state is None and two in closer:
                state, i = closer[two], i + 2
                out.append(two)
                continue
            if state is not None:
                if state != "#}" and quote is None and c in "'\"":
                    quote = c
                elif quote is not None and c == quote:
                    quote = None
                elif quote is None and two == state:
                    state, i = None, i + 2
                    out.append(two)
                    continue
            out.append(c)
            i += 1
            if c == "\n":
                n += 1
                if state is None:
                    out.append(f"\x01{name}:{n}\x02")
        (dst / path.name).write_text("".join(out))


def strip(text: str) -> tuple[str, list[int], list[str]]:
    """The text without its markers, each marker's offset in it and its name."""
    clean, offs, marks, last = [], [], [], 0
    pos = 0
    for m in MARK.finditer(text):
        clean.append(text[last:m.start()])
        pos += m.start() - last
        offs.append(pos)
        marks.append(m.group(1))
        last = m.end()
    clean.append(text[last:])
    return "".join(clean), offs, marks


def scan(config: str) -> list[dict]:
    """`config`: a shipped config's name, or name:lanes=n for filter.lanes = n."""
    name, _, lanes = config.partition(":lanes=")
    cfg = load_config(f"configs/{name}.toml", {"filter.lanes": int(lanes)} if lanes else None)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tdir, odir = Path(tmp) / "t", Path(tmp) / "o"
        tdir.mkdir()
        marked_templates(gen.TEMPLATE_DIR, tdir)
        names = [n for n in gen.modules_for(cfg) if "example" not in n]
        gen.generate(cfg, odir, modules=names, template_dir=tdir)
        maps = {}
        for sv in odir.glob("*.sv"):
            clean, offs, marks = strip(sv.read_text())
            sv.write_text(clean)
            maps[sv.name] = (offs, marks)
        comp = ast.Compilation()
        trees = {}
        for sv in sorted(odir.glob("*.sv")):
            t = syntax.SyntaxTree.fromFile(str(sv))
            trees[sv.name] = t
            comp.addSyntaxTree(t)
        comp.getAllDiagnostics()
        sm = comp.sourceManager
        seen = set()

        def visit(node):
            if isinstance(node, ast.ConversionExpression) and \
                    node.conversionKind == ast.ConversionKind.Explicit and \
                    node.syntax is not None and \
                    node.syntax.kind == syntax.SyntaxKind.CastExpression:
                loc = node.sourceRange.start
                fname = Path(sm.getFileName(loc)).name
                off = loc.offset
                # once per place and widths (a module's instances may differ in parameters)
                key = (fname, off, node.type.bitWidth, node.operand.type.bitWidth)
                if key in seen:
                    return
                seen.add(key)
                offs, marks = maps[fname]
                i = bisect.bisect_right(offs, off) - 1
                text = str(node.syntax).strip()
                op = node.operand
                const = str(op.constant) if op.constant is not None else None
                rows.append(dict(config=config, file=fname, where=marks[i] if i >= 0 else "?",
                                 text=" ".join(text.split()), to=node.type.bitWidth,
                                 frm=op.type.bitWidth, signed=op.type.isSigned, const=const))

        for inst in comp.getRoot().topInstances:
            inst.visit(visit)   # every module is below a top (blocks' files are rendered whole)
    return rows


def locations(configs: list[str]) -> dict[str, list[dict]]:
    """Every cast of these configs, by template line ("<template>:<line>")."""
    out: dict[str, list[dict]] = defaultdict(list)
    for config in configs:
        for r in scan(config):
            out[r["where"]].append(r)
    return out


def main() -> None:
    out = locations(sys.argv[1:])
    for where in sorted(out, key=lambda w: (w.split(":")[0], int(w.split(":")[1]))):
        rs = out[where]
        kinds = sorted({(r["config"], r["frm"], r["to"], r["const"] is not None) for r in rs})
        narrow = any(r["frm"] > r["to"] for r in rs)
        print(f"{where:28} {'NARROW' if narrow else 'wide  '} n={len(rs):4} "
              f"{rs[0]['text'][:90]}")
        for k in kinds:
            if k[1] > k[2]:
                ex = [r for r in rs if (r["config"], r["frm"], r["to"]) == k[:3]][0]
                print(f"      {k[0]:12} {k[1]}->{k[2]} const={ex['const']} {ex['text'][:100]}")


if __name__ == "__main__":
    main()
